//! `demos.jsonl` as the bridges handle it: the hub appends a remote expert's demonstrations to
//! the run's file (flushed and fsync'd before the answer goes on, as the expert process does on
//! one host), and a remote expert's host gets the run's file whole before its expert becomes
//! active.

use std::fs::OpenOptions;
use std::io::Write as _;
use std::path::Path;

use crate::error::{BridgeError, Result};

/// The file's text ("" when it does not exist yet).
pub(crate) fn read(path: &Path) -> Result<String> {
    match std::fs::read_to_string(path) {
        Ok(t) => Ok(t),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(String::new()),
        Err(e) => Err(BridgeError::Demos(format!(
            "cannot read {}: {e}",
            path.display()
        ))),
    }
}

/// Appends `line`, demonstration `index`, to the file at `path` and waits until it is on disk.
/// `index` must be the file's line count (the run's next demonstration): anything else would
/// break the file (a demonstration repeated or missing), and is refused.
pub(crate) fn append(path: &Path, index: u32, line: &str) -> Result<()> {
    let have = read(path)?.lines().count();
    if index as usize != have || line.contains('\n') {
        return Err(BridgeError::Demos(format!(
            "demonstration {index} where {} holds {have}",
            path.display()
        )));
    }
    let mut file = OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| BridgeError::Demos(format!("cannot open {}: {e}", path.display())))?;
    file.write_all(format!("{line}\n").as_bytes())
        .and_then(|()| file.sync_data())
        .map_err(|e| BridgeError::Demos(format!("cannot append to {}: {e}", path.display())))
}

/// Replaces the file at `path` with `text`, whole (a temporary file, fsync'd, renamed).
pub(crate) fn replace(path: &Path, text: &str) -> Result<()> {
    let tmp = path.with_extension("jsonl.part");
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| BridgeError::Demos(format!("cannot write {}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demonstrations_are_appended_in_order_only_and_a_file_is_replaced_whole() {
        let dir = std::env::temp_dir().join(format!("alfd-bridge-demos-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("demos.jsonl");
        let _ = std::fs::remove_file(&path);
        assert_eq!(read(&path).unwrap(), "");
        append(&path, 0, r#"{"index":0}"#).unwrap();
        append(&path, 1, r#"{"index":1}"#).unwrap();
        // Repeated, skipped, or not one line: refused, and the file is unchanged.
        for (i, l) in [(1, r#"{"index":1}"#), (3, r#"{"index":3}"#), (2, "a\nb")] {
            let e = append(&path, i, l).unwrap_err();
            assert!(matches!(e, BridgeError::Demos(_)), "{e}");
        }
        assert_eq!(read(&path).unwrap().lines().count(), 2);
        replace(&path, "x\n").unwrap();
        assert_eq!(read(&path).unwrap(), "x\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
