//! `experts-added.jsonl`: the experts `alfd expert add` gave a live run, one `[[experts]]` entry
//! per line (name, cost, label), appended before the swap that brings each in, so that every
//! expert process of the run (a restart too) finds what each name it hosts costs.

use std::path::Path;

use alfd_common::config::PanelEntry;
use alfd_harness::BadInput;

/// The file's name in the run directory.
pub const ADDED_EXPERTS: &str = "experts-added.jsonl";

/// The entries in `run_dir`'s file, oldest first (none when there is no file).
pub fn read(run_dir: &Path) -> Result<Vec<PanelEntry>, BadInput> {
    let path = run_dir.join(ADDED_EXPERTS);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(BadInput(format!("cannot read {}: {e}", path.display()))),
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .map_err(|e| BadInput(format!("{} line {}: {e}", path.display(), i + 1)))
        })
        .collect()
}

/// Appends `entry` to `run_dir`'s file, the line whole and on disk.
pub fn append(run_dir: &Path, entry: &PanelEntry) -> std::io::Result<()> {
    let mut line = serde_json::to_vec(entry).map_err(std::io::Error::other)?;
    line.push(b'\n');
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(run_dir.join(ADDED_EXPERTS))?;
    alfd_harness::append_whole(&mut file, &line, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_read_back_in_order_and_a_bad_line_is_named() {
        let dir = alfd_harness::test_dir("added-experts");
        assert_eq!(read(dir.path()).unwrap(), Vec::new(), "no file: none");
        let entry = |name: &str, cost| PanelEntry {
            name: name.into(),
            cost,
            label: Some(format!("{name} label")),
            becomes: None,
            after: None,
        };
        append(dir.path(), &entry("acrobot-fair", 3.0)).unwrap();
        append(dir.path(), &entry("acrobot-good", 8.0)).unwrap();
        let back = read(dir.path()).unwrap();
        assert_eq!(
            back,
            [entry("acrobot-fair", 3.0), entry("acrobot-good", 8.0)]
        );
        std::fs::write(dir.path().join(ADDED_EXPERTS), "{\"name\": 3}\n").unwrap();
        let e = read(dir.path()).unwrap_err().0;
        assert!(e.contains("line 1"), "{e}");
    }
}
