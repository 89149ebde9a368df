//! `demos.jsonl` as the bridges handle it: the hub appends a remote expert's demonstrations to
//! the run's file (flushed and fsync'd before the answer goes on, as the expert process does on
//! one host), a remote expert's host reads what its expert appended, and gets the run's file
//! whole before its expert becomes active.

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

/// Appends `lines` to the file at `path` and waits until they are on disk. The caller decides
/// that they are the file's next lines ([`ExpertDesk::demos`](crate::desk::ExpertDesk::demos));
/// a line that is not one line is refused, and nothing is written.
pub(crate) fn append_lines(path: &Path, lines: &[String]) -> Result<()> {
    if let Some(bad) = lines.iter().position(|l| l.contains('\n')) {
        return Err(BridgeError::Demos(format!(
            "a demonstration of {} lines for {}",
            lines[bad].lines().count(),
            path.display()
        )));
    }
    let mut text = String::with_capacity(lines.iter().map(|l| l.len() + 1).sum());
    for l in lines {
        text.push_str(l);
        text.push('\n');
    }
    let mut file = OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| BridgeError::Demos(format!("cannot open {}: {e}", path.display())))?;
    file.write_all(text.as_bytes())
        .and_then(|()| file.sync_data())
        .map_err(|e| BridgeError::Demos(format!("cannot append to {}: {e}", path.display())))
}

/// The file at `path` from byte `offset` on ("" when it does not exist or is shorter).
pub(crate) fn read_from(path: &Path, offset: u64) -> Result<String> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let fail =
        |e: std::io::Error| BridgeError::Demos(format!("cannot read {}: {e}", path.display()));
    let mut file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(String::new()),
        Err(e) => return Err(fail(e)),
    };
    if file.metadata().map_err(fail)?.len() <= offset {
        return Ok(String::new());
    }
    file.seek(SeekFrom::Start(offset)).map_err(fail)?;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes).map_err(fail)?;
    // A line being written may end inside a character: only whole lines are used.
    let whole = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    bytes.truncate(whole);
    String::from_utf8(bytes).map_err(|e| BridgeError::Demos(format!("{}: {e}", path.display())))
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
        assert_eq!(read_from(&path, 0).unwrap(), "");
        append_lines(&path, &[r#"{"index":0}"#.to_owned()]).unwrap();
        append_lines(&path, &["b".to_owned(), "c".to_owned()]).unwrap();
        // Not one line: refused, and nothing of the call is written.
        let e = append_lines(&path, &["d".to_owned(), "a\nb".to_owned()]).unwrap_err();
        assert!(matches!(e, BridgeError::Demos(_)), "{e}");
        assert_eq!(read(&path).unwrap(), "{\"index\":0}\nb\nc\n");
        // From an offset: whole lines only.
        assert_eq!(read_from(&path, 12).unwrap(), "b\nc\n");
        std::fs::write(&path, "a\nhalf").unwrap();
        assert_eq!(read_from(&path, 0).unwrap(), "a\n");
        assert_eq!(read_from(&path, 2).unwrap(), "");
        assert_eq!(read_from(&path, 99).unwrap(), "");
        replace(&path, "x\n").unwrap();
        assert_eq!(read(&path).unwrap(), "x\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
