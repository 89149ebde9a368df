//! `experts.csv`, one quality row per panel answer in `demos.jsonl`. A row is written before its
//! demonstration, so that a process killed between the two leaves a row too many, never one too
//! few; the next expert to become active cuts the file back to the panel answers that
//! `demos.jsonl` holds ([`trim`]), and a demonstration a full disk refused takes its row back
//! ([`cut_back`]).

use std::path::Path;

use alfd_common::environment_loop::panel_expert::PanelLog;
use alfd_demonstrators::demo_log;

/// Appends one row (`line`, its line ending included), the header first when the file is new
/// or empty, whole (a row cut short by a full disk is taken back); the file's length before
/// it, for [`cut_back`].
pub(crate) fn append(path: &Path, line: &str) -> std::io::Result<u64> {
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    let before = file.metadata()?.len();
    let text = if before == 0 {
        format!("{}{line}", PanelLog::CSV_HEADER)
    } else {
        line.to_owned()
    };
    alfd_harness::append_whole(&mut file, text.as_bytes(), false)?;
    Ok(before)
}

/// Takes back what [`append`] wrote after `len` bytes (its demonstration was not kept).
pub(crate) fn cut_back(path: &Path, len: u64) {
    let cut = std::fs::OpenOptions::new()
        .write(true)
        .open(path)
        .and_then(|f| f.set_len(len));
    if let Err(e) = cut {
        tracing::warn!(
            "cannot take back the last row of {}: {e}; it has a row without its demonstration",
            path.display()
        );
    }
}

/// Cuts `experts` back to one row per panel answer (a line with a `cost`) of `demos`: rows
/// past them are of answers whose demonstration a killed process never wrote. Nothing when the
/// file is missing or not longer.
pub(crate) fn trim(experts: &Path, demos: &Path) -> std::io::Result<()> {
    let Ok(csv) = std::fs::read_to_string(experts) else {
        return Ok(());
    };
    let answers = demo_log::panel_answers(&std::fs::read_to_string(demos).unwrap_or_default());
    if let Some(kept) = first_rows(&csv, answers) {
        tracing::warn!(
            answers,
            "{} held rows past the panel answers of {} (a process killed between the two \
             writes): cut back",
            experts.display(),
            demos.display()
        );
        alfd_harness::write_atomically(experts, kept.as_bytes())
            .map_err(|e| std::io::Error::other(e.to_string()))?;
    }
    Ok(())
}

/// `csv` (a header line, then rows) with its first `n` rows only, if it has more.
fn first_rows(csv: &str, n: usize) -> Option<String> {
    let whole: Vec<&str> = csv.split_inclusive('\n').collect();
    (whole.len() > n + 1).then(|| whole[..n + 1].concat())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_past_the_panel_answers_is_cut_and_a_refused_one_taken_back() {
        let dir = alfd_harness::test_dir("quality-file");
        let (experts, demos) = (
            dir.path().join("experts.csv"),
            dir.path().join("demos.jsonl"),
        );
        let at = append(&experts, "1,a,1,0.5,0,1\n").unwrap();
        assert_eq!(at, 0, "the header came first");
        let at = append(&experts, "2,b,1,0.5,0,1\n").unwrap();
        cut_back(&experts, at);
        let one = format!("{}1,a,1,0.5,0,1\n", PanelLog::CSV_HEADER);
        assert_eq!(std::fs::read_to_string(&experts).unwrap(), one);
        // Two rows, one panel answer (and one answer of a single expert, without a cost).
        append(&experts, "3,c,1,0.5,0,1\n").unwrap();
        std::fs::write(&demos, "{\"index\":0,\"cost\":2.0}\n{\"index\":1}\n").unwrap();
        trim(&experts, &demos).unwrap();
        assert_eq!(std::fs::read_to_string(&experts).unwrap(), one);
        // As many rows as answers, or no file: left alone.
        trim(&experts, &demos).unwrap();
        assert_eq!(std::fs::read_to_string(&experts).unwrap(), one);
        trim(&dir.path().join("none.csv"), &demos).unwrap();
        assert!(!dir.path().join("none.csv").exists());
    }

    #[test]
    fn first_rows_keeps_the_header_and_n_rows() {
        assert_eq!(first_rows("h\na\nb\n", 1).as_deref(), Some("h\na\n"));
        assert_eq!(first_rows("h\na\nb\n", 0).as_deref(), Some("h\n"));
        assert_eq!(first_rows("h\na\n", 1), None);
        assert_eq!(first_rows("h\na\n", 3), None);
    }
}
