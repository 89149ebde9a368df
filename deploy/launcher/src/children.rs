//! The launcher's view of its child processes: pinning them to CPUs, describing how one ended,
//! the error it printed last, and the rates the learner reports.

use std::collections::VecDeque;
use std::fs::File;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use tracing::debug;

use super::Kind;

/// Gives the learner (the bottleneck: one train step per environment step) a CPU of its own, and
/// the other processes the rest, so that waking an actor never preempts the learner. Best effort:
/// without `taskset` or with one CPU, nothing is pinned.
pub(super) fn pin(pid: u32, learner: bool) {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cpus < 2 {
        return;
    }
    let list = if learner {
        "0".to_owned()
    } else {
        format!("1-{}", cpus - 1)
    };
    let done = Command::new("taskset")
        .args(["-pc", &list, &pid.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    if !matches!(done, Ok(s) if s.success()) {
        debug!(pid, "cannot pin the process to CPUs {list} (no taskset?)");
    }
}

/// The binary a process runs, for messages.
pub(super) fn proc_binary(kind: &Kind, name: &str) -> String {
    match kind {
        Kind::Learner { .. } => "alfd-learner".to_owned(),
        Kind::Expert { .. } => format!("alfd-expert ({name})"),
        Kind::Actor { .. } => format!("alfd-actor ({name})"),
    }
}

/// "exited with status 1", "was killed by signal 9".
pub fn describe(status: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt as _;
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exited with status {c}"),
        (None, Some(s)) => format!("was killed by signal {s}"),
        _ => "exited".to_owned(),
    }
}

/// Environment steps and updates per second over the last few seconds.
#[derive(Debug, Default)]
pub(super) struct RateMeter {
    samples: VecDeque<(Instant, u64, u64)>,
}

impl RateMeter {
    pub(super) fn observe(&mut self, steps: u64, updates: u64) {
        let now = Instant::now();
        self.samples.push_back((now, steps, updates));
        while self
            .samples
            .front()
            .is_some_and(|s| now.duration_since(s.0) > Duration::from_secs(5))
        {
            self.samples.pop_front();
        }
    }

    /// Forgets the samples (the learner was restarted).
    pub(super) fn reset(&mut self) {
        self.samples.clear();
    }

    pub(super) fn rates(&self) -> (f64, f64) {
        match (self.samples.front(), self.samples.back()) {
            (Some(a), Some(b)) if b.0 > a.0 => {
                let dt = b.0.duration_since(a.0).as_secs_f64();
                // Saturating: a learner restored from its checkpoint counts from there again.
                (
                    b.1.saturating_sub(a.1) as f64 / dt,
                    b.2.saturating_sub(a.2) as f64 / dt,
                )
            }
            _ => (0.0, 0.0),
        }
    }
}

/// The pid of a running `binary` whose command line holds every one of `args` (as whole
/// arguments), found in `/proc`: how the chaos run and the tests find a run's processes (by
/// `--run-id=ID`, `--actor-id=N`).
pub fn find_process(binary: &str, args: &[&str]) -> Option<u32> {
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let parts: Vec<String> = cmdline
            .split(|&b| b == 0)
            .map(|p| String::from_utf8_lossy(p).into_owned())
            .collect();
        if parts.first().is_some_and(|p| p.ends_with(binary))
            && args.iter().all(|a| parts.iter().any(|p| p == a))
        {
            return Some(pid);
        }
    }
    None
}

/// The error a process printed last in its log (`alfd-expert: error: ...`), if any; only the
/// end of the log is read.
pub(super) fn last_error(log: &Path) -> Option<String> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    const TAIL: u64 = 64 * 1024;
    let mut file = File::open(log).ok()?;
    let len = file.metadata().ok()?.len();
    file.seek(SeekFrom::Start(len.saturating_sub(TAIL))).ok()?;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes).ok()?;
    error_line(&String::from_utf8_lossy(&bytes))
}

/// The message of the last `<binary>: error: <message>` line of a log.
fn error_line(log: &str) -> Option<String> {
    log.lines().rev().find_map(|l| {
        let (binary, message) = l.split_once(": error: ")?;
        binary
            .starts_with("alfd-")
            .then(|| message.trim().to_owned())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_error_of_a_log_is_its_reason() {
        let log = "2026-01-01T00:00:00Z  INFO alfd_expert: expert starting\n\
                   alfd-expert: error: old trouble\n\
                   2026-01-01T00:00:01Z  INFO alfd_expert: expert starting\n\
                   alfd-expert: error: /r/demos.jsonl line 79: not a demonstration record: EOF\n\
                   2026-01-01T00:00:02Z  WARN some: other line\n";
        assert_eq!(
            error_line(log).as_deref(),
            Some("/r/demos.jsonl line 79: not a demonstration record: EOF")
        );
        assert_eq!(error_line("INFO nothing wrong\n"), None);
        let tmp = alfd_harness::test_dir("last-error");
        let dir = tmp.path();
        let path = dir.join("expert-2.log");
        std::fs::write(&path, log).unwrap();
        assert!(last_error(&path).unwrap().contains("line 79"));
        assert_eq!(last_error(&dir.join("missing.log")), None);
    }
}
