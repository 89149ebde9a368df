//! Durable files: a file is written whole or not at all.

use std::io::Write as _;
use std::path::Path;
use std::time::Duration;

use crate::bad_input::{Result, What as _};

/// Writes `bytes` to `path` whole: a temporary file beside it, fsync, rename, fsync of the
/// directory. A crash leaves either the old file or the new one, never half of one; every error
/// is returned, and a write that fails (a full disk) removes its temporary file.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomically_with_mode(path, bytes, 0o644)
}

/// How long the files a run ends with wait for room on a full disk (a disk being freed) before
/// the run fails on them: [`write_atomically_patiently`]'s usual patience.
pub const DISK_FULL_PATIENCE: Duration = Duration::from_secs(60);

/// [`write_atomically`], waiting out a full disk: a write refused for lack of space (ENOSPC) is
/// tried again every 200 ms for at most `patience` (room being made), the first refusal said in
/// the log; any other error, or a disk still full after that, is returned. For the files a run
/// ends with (its weights, `summary.json`), which a short-lived full disk must not cost.
pub fn write_atomically_patiently(path: &Path, bytes: &[u8], patience: Duration) -> Result<()> {
    let deadline = std::time::Instant::now() + patience;
    let mut said = false;
    loop {
        match write_atomically(path, bytes) {
            Err(e) if disk_full(&e) && std::time::Instant::now() < deadline => {
                if !said {
                    tracing::warn!(
                        "{}; trying again while the disk is full",
                        crate::describe(&e)
                    );
                    said = true;
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            other => return other,
        }
    }
}

/// Whether `e` is, anywhere in its chain, a file system out of space (ENOSPC).
pub fn disk_full(e: &(dyn std::error::Error + 'static)) -> bool {
    crate::chain(e).any(|e| {
        e.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.raw_os_error() == Some(28))
    })
}

/// [`write_atomically`] into a file only its owner can read and write (mode 0600 from its
/// creation on): for secrets such as the human expert's page token.
pub fn write_private(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomically_with_mode(path, bytes, 0o600)
}

fn write_atomically_with_mode(path: &Path, bytes: &[u8], mode: u32) -> Result<()> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| crate::BadInput(format!("{} names no file", path.display())))?;
    let tmp = dir.join(format!(".{}.tmp", name.to_string_lossy()));
    let _ = std::fs::remove_file(&tmp);
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .open(&tmp)
        .what(|| format!("cannot write {}", tmp.display()))?;
    let written = f.write_all(bytes).and_then(|()| f.sync_all());
    drop(f);
    if let Err(e) = written.and_then(|()| std::fs::rename(&tmp, path)) {
        // A full disk (ENOSPC) must not stay full of our half-written file: the old file is
        // untouched, the temporary one goes.
        let _ = std::fs::remove_file(&tmp);
        return Err(e).what(|| format!("cannot write {}", path.display()));
    }
    std::fs::File::open(dir)
        .and_then(|d| d.sync_all())
        .what(|| format!("cannot sync directory {}", dir.display()))?;
    Ok(())
}

/// Appends `line` to `file` whole (and with `sync`, waits until it is on disk): a write that
/// fails part-way (a full disk) is taken back, so a file of lines never ends in half of one.
pub fn append_whole(file: &mut std::fs::File, line: &[u8], sync: bool) -> std::io::Result<()> {
    use std::io::Seek as _;
    let before = file.metadata()?.len();
    let written = file
        .write_all(line)
        .and_then(|()| if sync { file.sync_data() } else { Ok(()) });
    if written.is_err() {
        // Back to where the line began, for the next append too (a file not opened in append
        // mode writes at its position).
        let _ = file.set_len(before);
        let _ = file.seek(std::io::SeekFrom::Start(before));
    }
    written
}

/// A test's scratch directory `alfd-NAME-XXXXXX` in the system's temporary directory, removed
/// with everything in it when dropped (also while a failed test unwinds); kept, and named on
/// stderr, when `ALFD_KEEP_TEST_DIRS=1`. The one helper every crate's tests use, behind the `testing`
/// feature (which their dev-dependencies turn on).
#[cfg(any(test, feature = "testing"))]
pub fn test_dir(name: &str) -> tempfile::TempDir {
    let keep = std::env::var_os("ALFD_KEEP_TEST_DIRS").is_some_and(|v| v == "1");
    let dir = tempfile::Builder::new()
        .prefix(&format!("alfd-{name}-"))
        .disable_cleanup(keep)
        .tempdir()
        .expect("a temporary directory");
    if keep {
        // Straight to stderr: libtest's capture would hide it for a test that passes.
        let _ = writeln!(
            std::io::stderr(),
            "ALFD_KEEP_TEST_DIRS: keeping {}",
            dir.path().display()
        );
    }
    dir
}

/// Writes `state` to `path` whole in the core's checkpoint format, tied to the run's config
/// (`config.toml`'s text); returns its size in bytes.
pub fn save_checkpoint<T: serde::Serialize>(
    path: &Path,
    state: &T,
    config_toml: &str,
) -> Result<usize> {
    use alfd_common::checkpoint::{config_hash, encode};
    let bytes = encode(state, config_hash(config_toml));
    write_atomically(path, &bytes)?;
    Ok(bytes.len())
}

/// Reads a checkpoint written by [`save_checkpoint`], if there is one. One that cannot be trusted
/// (truncated, corrupt, of another version or another config) is [`crate::BadInput`] saying which
/// and what was not done (`refused`), and the file is left as it is.
pub fn load_checkpoint<T: serde::de::DeserializeOwned>(
    path: &Path,
    config_toml: &str,
    refused: &str,
) -> Result<Option<T>> {
    use alfd_common::checkpoint::{config_hash, decode};
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => {
            return Err(crate::BadInput(format!("cannot read {}: {e}", path.display())).into())
        }
    };
    decode(&bytes, config_hash(config_toml))
        .map(Some)
        .map_err(|e| {
            crate::BadInput(format!(
                "{}: {e}; {refused} and the file was left as it is",
                path.display()
            ))
            .into()
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_replaced_whole_and_errors_are_returned() {
        let tmp = test_dir("fs");
        let dir = tmp.path();
        let path = dir.join("x.json");
        write_atomically(&path, b"first").unwrap();
        write_atomically(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        let names: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(
            names,
            vec![std::ffi::OsString::from("x.json")],
            "no temporary left"
        );
        let e = write_atomically(&dir.join("missing/y.json"), b"z").unwrap_err();
        assert!(format!("{e:#}").contains("missing"), "{e:#}");
    }

    #[test]
    fn lines_are_appended_whole_and_a_full_disk_is_the_error() {
        let tmp = test_dir("fs-append");
        let path = tmp.path().join("lines.txt");
        let mut f = std::fs::File::create(&path).unwrap();
        append_whole(&mut f, b"one\n", true).unwrap();
        append_whole(&mut f, b"two\n", false).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"one\ntwo\n");
        // Writes to /dev/full fail with ENOSPC, as on a full disk.
        let mut full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let e = append_whole(&mut full, b"x\n", true).unwrap_err();
        assert_eq!(e.raw_os_error(), Some(28), "{e}");
    }

    #[test]
    fn a_write_that_fails_leaves_no_temporary_file_behind() {
        let tmp = test_dir("fs-fail");
        let dir = tmp.path();
        // The rename cannot replace a directory holding a file (as a full disk fails the
        // write): an error naming the path, the directory as it was, no `.NAME.tmp` left.
        let target = dir.join("state");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("inside"), b"kept").unwrap();
        let e = write_atomically(&target, b"new").unwrap_err();
        assert!(format!("{e:#}").contains("cannot write"), "{e:#}");
        let mut names: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, vec!["state".to_owned()]);
        assert_eq!(std::fs::read(target.join("inside")).unwrap(), b"kept");
    }

    #[test]
    fn a_full_disk_is_told_apart_from_other_errors_anywhere_in_the_chain() {
        let full = crate::HarnessError::Failed {
            what: "cannot write x".into(),
            source: Box::new(std::io::Error::from_raw_os_error(28)),
        };
        assert!(disk_full(&full));
        let denied = crate::HarnessError::Failed {
            what: "cannot write x".into(),
            source: Box::new(std::io::Error::from_raw_os_error(13)),
        };
        assert!(!disk_full(&denied));
        // Not a full disk: the error comes back as it is (no waiting for room).
        let e = write_atomically_patiently(
            Path::new("/proc/alfd-no-such-dir/x"),
            b"x",
            Duration::from_secs(30),
        )
        .unwrap_err();
        assert!(!disk_full(&e), "{e}");
        assert!(e.to_string().contains("alfd-no-such-dir"), "{e}");
    }
}
