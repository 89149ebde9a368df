//! What the integration tests share: the repository and the binaries, temporary directories that
//! remove themselves (also when a test panics), a run in the background stopped when dropped, and
//! the time each test took.
//!
//! Order matters in a test that starts processes: declare the directory first, then the process,
//! so that the process (dropped first) is stopped before its directory is removed.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The repository's root.
pub(crate) fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .unwrap()
        .to_path_buf()
}

/// The directory holding `alfd` and the process binaries. `cargo test` builds only this
/// package's binary, so the process binaries are built here once (same profile, same target
/// directory, the workspace's features), unless `ALFD_BIN_DIR` points at them.
pub(crate) fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        if let Some(d) = std::env::var_os("ALFD_BIN_DIR") {
            return PathBuf::from(d);
        }
        let dir = Path::new(env!("CARGO_BIN_EXE_alfd"))
            .parent()
            .unwrap()
            .to_path_buf();
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let mut cmd = Command::new(cargo);
        // The whole workspace with the same targets as `deploy/test.sh` builds: cargo unifies
        // the dev-dependencies' features only when tests are built, so `--bins` alone would
        // build every process binary anew, with other features, while the tests run.
        cmd.args(["build", "--workspace", "--lib", "--bins", "--tests"])
            .current_dir(repo());
        // Without the variables cargo sets for this test binary: a build script that watches
        // one (ring's watches CARGO_MANIFEST_DIR) would otherwise see it change and rebuild its
        // crate and everything above it, here and again at the next `deploy/test.sh`.
        for (key, _) in std::env::vars_os() {
            let key = key.to_string_lossy();
            let set_for_tests = key.starts_with("CARGO_PKG_")
                || key.starts_with("CARGO_BIN_EXE_")
                || [
                    "CARGO_MANIFEST_DIR",
                    "CARGO_MANIFEST_PATH",
                    "CARGO_CRATE_NAME",
                    "CARGO_PRIMARY_PACKAGE",
                    "CARGO_TARGET_TMPDIR",
                ]
                .contains(&key.as_ref());
            if set_for_tests {
                cmd.env_remove(key.as_ref());
            }
        }
        if dir.ends_with("release") {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("cargo runs");
        assert!(status.success(), "cannot build the process binaries");
        dir
    })
}

/// `alfd`, run from the repository's root, finding the process binaries in [`bin_dir`].
pub(crate) fn alfd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_alfd"));
    c.env("ALFD_BIN_DIR", bin_dir()).current_dir(repo());
    c
}

/// A process's exit status, stdout and stderr, for an assertion's message.
pub(crate) fn text(o: &Output) -> String {
    format!(
        "status {:?}\nstdout: {}\nstderr: {}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A fresh, empty directory `alfd-NAME-XXXXXX` in the system's temporary directory, removed
/// with everything in it when dropped (see [`TestDir`]).
pub(crate) fn tmp(name: &str) -> TestDir {
    TestDir(alfd_harness::test_dir(name))
}

/// A test's temporary directory: used as a [`Path`], removed when dropped, also while a failed
/// test unwinds (after the tail of every log in it is written to stderr, which the test harness
/// shows with the failure); kept (and named on stderr) when `ALFD_KEEP_TEST_DIRS=1`.
#[derive(Debug)]
pub(crate) struct TestDir(tempfile::TempDir);

impl Drop for TestDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            log_tails(self.0.path(), 3);
        }
    }
}

/// The last 20 lines of every `*.log` file under `dir` (down to `depth` levels), on stderr.
fn log_tails(dir: &Path, depth: usize) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut paths: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    paths.sort();
    for path in paths {
        if path.is_dir() && depth > 0 {
            log_tails(&path, depth - 1);
        } else if path.extension().is_some_and(|e| e == "log") {
            let text = std::fs::read_to_string(&path).unwrap_or_default();
            let lines: Vec<&str> = text.lines().collect();
            let tail = &lines[lines.len().saturating_sub(20)..];
            eprintln!("--- the last {} lines of {}", tail.len(), path.display());
            for line in tail {
                eprintln!("{line}");
            }
        }
    }
}

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<std::ffi::OsStr> for TestDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.path().as_os_str()
    }
}

/// A run in the background; stopped with SIGINT when dropped (so a failed test leaves no
/// processes behind): waits up to 30 s for it to end, then kills it.
pub(crate) struct Background(pub(crate) Option<Child>);

impl Background {
    pub(crate) fn child(&mut self) -> &mut Child {
        self.0.as_mut().expect("running")
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = Command::new("kill")
                .args(["-INT", &child.id().to_string()])
                .status();
            let start = Instant::now();
            while matches!(child.try_wait(), Ok(None)) && start.elapsed() < Duration::from_secs(30)
            {
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Records the enclosing test's time: `let _time = timed!();` as the test's first line (dropped
/// last, so the time includes stopping its processes and removing its directories).
macro_rules! timed {
    () => {
        $crate::support::TestTime::start({
            fn f() {}
            std::any::type_name_of_val(&f)
        })
    };
}
pub(crate) use timed;

/// Appends "NAME SECONDS" to `$ALFD_TEST_TIMES/times.txt` when dropped (after a failure too);
/// does nothing when `ALFD_TEST_TIMES` is unset. `deploy/test.sh` sets it and prints the slowest.
#[derive(Debug)]
pub(crate) struct TestTime {
    name: String,
    start: Instant,
}

impl TestTime {
    /// `path` is `CRATE::MODULE::TEST::f` (see [`timed!`]); the name kept is libtest's,
    /// `MODULE::TEST`.
    pub(crate) fn start(path: &str) -> TestTime {
        let path = path.strip_suffix("::f").unwrap_or(path);
        let name = path.split_once("::").map_or(path, |(_, rest)| rest);
        TestTime {
            name: name.to_owned(),
            start: Instant::now(),
        }
    }
}

impl Drop for TestTime {
    fn drop(&mut self) {
        let Some(dir) = std::env::var_os("ALFD_TEST_TIMES") else {
            return;
        };
        let line = format!("{} {:.1}\n", self.name, self.start.elapsed().as_secs_f64());
        let dir = PathBuf::from(dir);
        let _ = std::fs::create_dir_all(&dir);
        // One short write in append mode: lines of tests running in parallel do not mix.
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join("times.txt"))
        {
            let _ = f.write_all(line.as_bytes());
        }
    }
}

/// A small file system mounted on a directory for the test's life (unmounted when dropped).
pub(crate) struct Tmpfs<'a>(&'a Path);

impl<'a> Tmpfs<'a> {
    /// Mounts a tmpfs of `mb` MB on `dir` if this process may (root); `None` otherwise.
    pub(crate) fn mount(dir: &'a Path, mb: u32) -> Option<Self> {
        let root = std::process::Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
        let mounted = root
            && std::process::Command::new("mount")
                .args(["-t", "tmpfs", "-o", &format!("size={mb}m"), "tmpfs"])
                .arg(dir)
                .status()
                .is_ok_and(|s| s.success());
        mounted.then_some(Tmpfs(dir))
    }
}

impl Drop for Tmpfs<'_> {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(self.0).status();
    }
}

/// Whether the tests run under CI (`CI` set, and not to `false` or `0`): a test that cannot run
/// there fails instead of skipping.
/// [`Tmpfs::mount`] for a test that needs it: `None` when no tmpfs can be mounted (not root), after
/// saying the test `what` did not run; under CI (which runs as root) that fails the test instead.
pub(crate) fn tmpfs_or_skip<'a>(dir: &'a Path, mb: u32, what: &str) -> Option<Tmpfs<'a>> {
    let disk = Tmpfs::mount(dir, mb);
    if disk.is_none() {
        assert!(
            !under_ci(),
            "CI is set and no tmpfs could be mounted (needs root): the test cannot run"
        );
        eprintln!("\n*** SKIPPED: no tmpfs (needs root); {what} did not run ***\n");
    }
    disk
}

/// Fills the file system of `path` to the last byte with the file `path`; room comes back when
/// the returned file is dropped and removed.
pub(crate) fn fill_up(path: &Path) -> std::fs::File {
    use std::io::Write as _;
    let mut f = std::fs::File::create(path).unwrap();
    let block = vec![0u8; 1 << 16];
    while f.write_all(&block).is_ok() {}
    for small in [4096, 512, 64, 1] {
        while f.write_all(&block[..small]).is_ok() {}
    }
    f
}

pub(crate) fn under_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0")
}

/// The project's Python (`.venv/`, installed by `deploy/python/setup-venv.sh` as `alfd` does).
pub(crate) fn project_python() -> String {
    let setup = std::process::Command::new("bash")
        .arg(repo().join("deploy/python/setup-venv.sh"))
        .output()
        .unwrap();
    assert!(setup.status.success(), "{}", text(&setup));
    String::from_utf8(setup.stdout).unwrap().trim().to_owned()
}

/// What `dir` holds, for telling whether anything in it changed: each entry's name, bytes
/// (a directory, such as `tb/`, by the bytes of its files in name order) and modification time.
pub(crate) fn dir_snapshot(dir: &Path) -> Vec<(String, Vec<u8>, std::time::SystemTime)> {
    let bytes = |p: &Path| -> Vec<u8> {
        if !p.is_dir() {
            return std::fs::read(p).unwrap();
        }
        let mut inner: Vec<_> = std::fs::read_dir(p)
            .unwrap()
            .map(|f| f.unwrap().path())
            .collect();
        inner.sort();
        inner
            .iter()
            .flat_map(|f| std::fs::read(f).unwrap())
            .collect()
    };
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                bytes(&e.path()),
                e.metadata().unwrap().modified().unwrap(),
            )
        })
        .collect();
    files.sort();
    files
}
