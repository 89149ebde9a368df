//! A run's TensorBoard event files, `RUN_DIR/tb/events.out.tfevents.<seconds>.<host>.<process>`:
//! one file per process of the run, appended to as the run goes (the encoding is
//! `alfd_common::tensorboard`'s). `tensorboard --logdir RUN_DIR/tb` shows them; a sweep's
//! directory shows one sub-run per method and seed.

use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use std::time::Instant;

use alfd_common::config::ExperimentConfig;
use alfd_common::record::EpisodeRecord;
use alfd_common::tensorboard::{file_version_event, scalars_event, EpisodeScalars};

/// The directory of a run's event files.
pub const TB_DIR: &str = "tb";

/// One process's event file, open for appending.
#[derive(Debug)]
pub struct EventWriter {
    file: File,
    path: PathBuf,
}

fn now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_owned())
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".to_owned())
}

impl EventWriter {
    /// A new event file of `process` (`local`, `launcher`, `learner`, ...) in `run_dir/tb/`.
    pub fn create(run_dir: &Path, process: &str) -> std::io::Result<Self> {
        let dir = run_dir.join(TB_DIR);
        std::fs::create_dir_all(&dir)?;
        let wall = now();
        let name = format!("events.out.tfevents.{}.{}.{process}", wall as u64, host());
        let path = dir.join(name);
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)?;
        file.write_all(&file_version_event(wall))?;
        Ok(Self { file, path })
    }

    /// Appends the scalars `values` at `step`, stamped with the wall-clock now.
    pub fn scalars(&mut self, step: u64, values: &[(String, f32)]) -> std::io::Result<()> {
        if values.is_empty() {
            return Ok(());
        }
        self.file.write_all(&scalars_event(now(), step, values))
    }

    /// Where the file is.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// What a process of a run shows TensorBoard: the scalars of its episodes and of the learner's
/// reports, written as they come. A file that cannot be written is warned about once and the
/// run goes on without it.
#[derive(Debug)]
pub struct Board {
    writer: Option<EventWriter>,
    /// Where the file goes once there is something to write (none is made for a run refused
    /// before its first episode): the run directory and the process's name.
    pending: Option<(PathBuf, String)>,
    scalars: EpisodeScalars,
    start: Instant,
    /// The learner's last report: when, and its updates then.
    last_learner: Option<(f64, u64)>,
}

impl Board {
    /// The board of `process` in `run_dir`; writes nothing when `logging.tensorboard` is off.
    pub fn open(run_dir: &Path, process: &str, cfg: &ExperimentConfig) -> Self {
        let pending = cfg
            .logging
            .tensorboard
            .then(|| (run_dir.to_path_buf(), process.to_owned()));
        Self {
            writer: None,
            pending,
            scalars: EpisodeScalars::new(cfg.budget()),
            start: Instant::now(),
            last_learner: None,
        }
    }

    /// The scalars after episode `r`.
    pub fn episode(&mut self, r: &EpisodeRecord) {
        if !self.on() {
            return;
        }
        let values = self.scalars.after(r, self.start.elapsed().as_secs_f64());
        self.write(r.total_steps, &values);
    }

    /// Scalars of this process's own at `step`.
    pub fn scalars(&mut self, step: u64, values: &[(String, f32)]) {
        self.write(step, values);
    }

    /// The learner's report: its last TD loss and mean Q-value (NaN: none yet) and its update
    /// rate since its previous report, at the environment step it has learned from.
    pub fn learner(&mut self, env_steps: u64, updates: u64, loss: f64, q_mean: f64) {
        if !self.on() {
            return;
        }
        let now = self.start.elapsed().as_secs_f64();
        let mut values = Vec::new();
        if !loss.is_nan() {
            values.push(("learner/td_loss".to_owned(), loss as f32));
        }
        if !q_mean.is_nan() {
            values.push(("learner/q_mean".to_owned(), q_mean as f32));
        }
        if let Some((then, before)) = self.last_learner {
            if now > then && updates >= before {
                let rate = (updates - before) as f64 / (now - then);
                values.push(("learner/updates_per_s".to_owned(), rate as f32));
            }
        }
        values.push(("learner/updates".to_owned(), updates as f32));
        self.last_learner = Some((now, updates));
        self.write(env_steps, &values);
    }

    /// Whether scalars are written; the file is made at the first call.
    fn on(&mut self) -> bool {
        if let Some((dir, process)) = self.pending.take() {
            self.writer = EventWriter::create(&dir, &process)
                .map_err(|e| tracing::warn!("no TensorBoard event file in {}: {e}", dir.display()))
                .ok();
        }
        self.writer.is_some()
    }

    fn write(&mut self, step: u64, values: &[(String, f32)]) {
        if !self.on() {
            return;
        }
        if let Some(w) = &mut self.writer {
            if let Err(e) = w.scalars(step, values) {
                tracing::warn!(
                    "the TensorBoard event file {} stops here: {e}",
                    w.path().display()
                );
                self.writer = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_event_file_starts_with_its_version_and_grows_by_whole_records() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = EventWriter::create(dir.path(), "local").unwrap();
        let name = w.path().file_name().unwrap().to_str().unwrap().to_owned();
        assert!(name.starts_with("events.out.tfevents.") && name.ends_with(".local"));
        let first = std::fs::metadata(w.path()).unwrap().len();
        assert_eq!(first as usize, file_version_event(0.0).len());
        w.scalars(5, &[("a".to_owned(), 1.0)]).unwrap();
        w.scalars(6, &[]).unwrap();
        let grown = std::fs::metadata(w.path()).unwrap().len() - first;
        assert_eq!(
            grown as usize,
            scalars_event(0.0, 5, &[("a".to_owned(), 1.0)]).len()
        );
    }
}
