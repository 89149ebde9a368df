//! A run directory belongs to one run. A new run (`alfd run`, `alfd local`) refuses a directory
//! that already holds a run, before touching anything in it, and holds an OS lock on
//! `RUN_DIR/.lock` for its whole life, so that a second launcher started at the same moment is
//! refused too. `alfd swap-expert` takes `RUN_DIR/.swap.lock` the same way, so swap requests are
//! serialized. The locks are `flock`s: the OS releases them when their holder exits, however it
//! exits, so a crashed run never leaves a directory locked.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read as _, Seek as _, SeekFrom, Write as _};
use std::path::{Path, PathBuf};

use crate::{BadInput, Result, What as _};

/// Bad input: the user's to fix (exit code 2).
fn usage(msg: String) -> crate::HarnessError {
    BadInput(msg).into()
}

/// The files that make a directory a run's: any one of them and the directory is taken.
pub const RUN_FILES: [&str; 5] = [
    "config.toml",
    "episodes.csv",
    "run.json",
    "summary.json",
    "demos.jsonl",
];

/// Held by the run that owns the directory.
pub const LOCK_FILE: &str = ".lock";
/// Held by the `alfd swap-expert` in progress.
pub const SWAP_LOCK_FILE: &str = ".swap.lock";

/// An OS lock on a file of a run directory, released when dropped (or when the process ends).
#[derive(Debug)]
pub struct DirLock {
    _file: File,
}

/// The run files `dir` holds (none if it does not exist).
pub fn run_files(dir: &Path) -> Vec<&'static str> {
    RUN_FILES
        .into_iter()
        .filter(|f| dir.join(f).exists())
        .collect()
}

/// Claims `dir` for a new run, whose `--out` it is: refused (bad input, exit code 2) if it holds a
/// run already or another process holds its lock. Nothing in a refused directory is touched.
pub fn claim_new(dir: &Path) -> Result<DirLock> {
    refuse_a_run(dir)?;
    std::fs::create_dir_all(dir)
        .what(|| format!("cannot create run directory {}", dir.display()))?;
    let lock = lock(dir)?;
    // A run may have written its files between the first look and the lock.
    refuse_a_run(dir)?;
    Ok(lock)
}

/// Locks `dir` (created if missing) for one run: refused if another process holds the lock.
/// `alfd sweep` takes this lock (without [`claim_new`]'s check) to re-run an unfinished run of its
/// own in place.
pub fn lock(dir: &Path) -> Result<DirLock> {
    std::fs::create_dir_all(dir)
        .what(|| format!("cannot create run directory {}", dir.display()))?;
    try_lock(&dir.join(LOCK_FILE))?.map_err(|holder| {
        usage(format!(
            "{} is in use by another run{holder} (it holds {}): wait for that run to end, or \
             choose a new --out",
            dir.display(),
            dir.join(LOCK_FILE).display()
        ))
    })
}

/// Takes the swap lock of the run in `dir`: refused at once if another `alfd swap-expert` of that
/// run is in progress.
pub fn lock_swaps(dir: &Path) -> Result<DirLock> {
    try_lock(&dir.join(SWAP_LOCK_FILE))?.map_err(|holder| {
        usage(format!(
            "another `alfd swap-expert`{holder} is in progress for the run in {}: swaps are made \
             one at a time; try again when it is done",
            dir.display()
        ))
    })
}

fn refuse_a_run(dir: &Path) -> Result<()> {
    let found = run_files(dir);
    if found.is_empty() {
        return Ok(());
    }
    Err(usage(format!(
        "{} already holds a run ({}); a run directory belongs to one run, so nothing in it was \
         touched: choose a new --out, e.g. --out {}",
        dir.display(),
        found.join(", "),
        free_sibling(dir).display()
    )))
}

/// `DIR-2`, `DIR-3`, ...: the first that does not exist.
fn free_sibling(dir: &Path) -> PathBuf {
    let base = dir.as_os_str().to_string_lossy();
    let base = base.trim_end_matches('/');
    (2..)
        .map(|n| PathBuf::from(format!("{base}-{n}")))
        .find(|p| !p.exists())
        .expect("some name is free")
}

/// Locks `path` (created if missing) and writes our pid in it. `Ok(Err(holder))` when another
/// process holds it; `holder` says which (" (pid N)"), if it could be read.
fn try_lock(path: &Path) -> Result<Result<DirLock, String>> {
    let mut file = OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(path)
        .what(|| format!("cannot open {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let mut pid = String::new();
            let _ = file.read_to_string(&mut pid);
            let holder = match pid.trim().parse::<u32>() {
                Ok(pid) => format!(" (pid {pid})"),
                Err(_) => String::new(),
            };
            return Ok(Err(holder));
        }
        Err(TryLockError::Error(e)) => {
            return Err(e).what(|| format!("cannot lock {}", path.display()))
        }
    }
    // Who holds it, for the message of whoever is refused; the lock itself is the flock, so a
    // pid that cannot be written (a full disk) costs only that message its "(pid N)".
    let said = file
        .set_len(0)
        .and_then(|()| file.seek(SeekFrom::Start(0)))
        .and_then(|_| writeln!(file, "{}", std::process::id()));
    if let Err(e) = said {
        tracing::debug!("{} holds no pid: {e}", path.display());
    }
    Ok(Ok(DirLock { _file: file }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_dir;

    fn is_usage_error(e: &crate::HarnessError) -> bool {
        e.is_bad_input()
    }

    #[test]
    fn a_directory_holding_a_run_is_refused_untouched() {
        let root = test_dir("run-dir");
        let d = root.path().join("taken");
        // A new or empty directory is free.
        drop(claim_new(&d).unwrap());
        assert!(d.join(LOCK_FILE).is_file());
        assert!(claim_new(&d).is_ok());
        for f in RUN_FILES {
            let other = root.path().join(format!("taken-{f}"));
            std::fs::create_dir_all(&other).unwrap();
            std::fs::write(other.join(f), "x").unwrap();
            let e = claim_new(&other).unwrap_err();
            assert!(is_usage_error(&e), "{}", crate::describe(&e));
            let msg = crate::describe(&e);
            assert!(
                msg.contains(&other.display().to_string())
                    && msg.contains(f)
                    && msg.contains(&format!("--out {}-2", other.display())),
                "{msg}"
            );
            // Not even a lock file was added.
            let names: Vec<_> = std::fs::read_dir(&other)
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .collect();
            assert_eq!(names, vec![std::ffi::OsString::from(f)]);
        }
    }

    #[test]
    fn a_locked_directory_is_refused_and_free_again_once_released() {
        let root = test_dir("run-dir");
        let d = root.path().join("locked");
        let held = claim_new(&d).unwrap();
        // A second run (another open file description: as another process would be) is refused.
        let e = claim_new(&d).unwrap_err();
        assert!(is_usage_error(&e));
        let msg = crate::describe(&e);
        assert!(
            msg.contains("in use by another run")
                && msg.contains(&format!("(pid {})", std::process::id())),
            "{msg}"
        );
        assert!(lock(&d).is_err(), "a sweep cannot take it either");
        drop(held);
        drop(lock(&d).unwrap());

        let swap = lock_swaps(&d).unwrap();
        let e = lock_swaps(&d).unwrap_err();
        assert!(
            crate::describe(&e).contains("another `alfd swap-expert`"),
            "{}",
            crate::describe(&e)
        );
        drop(swap);
        assert!(lock_swaps(&d).is_ok());
    }
}
