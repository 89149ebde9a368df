//! `demos.jsonl`: the run's demonstrations, one JSON object per line (the core's
//! [`DemoRecord`]: `index`, `state`, `action`, `step`, `expert`). The expert appends each answered
//! demonstration, flushed and fsync'd before the answer goes out; a new expert reads the file back.

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

use alfd_common::agent::DemoRecord;

/// A `demos.jsonl` that cannot be used as it is. Nothing is ever removed from the file.
#[derive(Debug, thiserror::Error)]
pub enum DemoLogError {
    /// The I/O error is in the message (not a `source`, which a report printing the chain
    /// would repeat).
    #[error("cannot read {path}: {io}")]
    Read { path: PathBuf, io: std::io::Error },
    #[error("cannot append to {path}: {io}")]
    Write { path: PathBuf, io: std::io::Error },
    #[error("{path} line {line}: {reason}")]
    Malformed {
        path: PathBuf,
        line: usize,
        reason: String,
    },
}

/// Reads every demonstration of `path` (none if the file does not exist). Each line must be a
/// [`DemoRecord`] whose `index` is its 0-based line number, and the file must end with a newline.
impl DemoLogError {
    /// Whether a write was refused for want of space (ENOSPC).
    pub fn is_disk_full(&self) -> bool {
        matches!(self, DemoLogError::Write { io, .. } if io.raw_os_error() == Some(28))
    }
}

pub fn read(path: &Path) -> Result<Vec<DemoRecord>, DemoLogError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(io) => {
            return Err(DemoLogError::Read {
                path: path.to_owned(),
                io,
            })
        }
    };
    parse(&text, path)
}

/// The demonstrations of `text`, the contents of the file `path` (named in errors): see [`read`].
pub fn parse(text: &str, path: &Path) -> Result<Vec<DemoRecord>, DemoLogError> {
    let malformed = |line: usize, reason: String| DemoLogError::Malformed {
        path: path.to_owned(),
        line,
        reason,
    };
    let mut records = Vec::new();
    for (i, raw) in text.split_inclusive('\n').enumerate() {
        let line = i + 1;
        if !raw.ends_with('\n') {
            return Err(malformed(
                line,
                "incomplete last line (no newline at its end): the file was cut while being written"
                    .to_owned(),
            ));
        }
        let record: DemoRecord = serde_json::from_str(raw.trim_end())
            .map_err(|e| malformed(line, format!("not a demonstration record: {e}")))?;
        if record.index as usize != records.len() {
            return Err(malformed(
                line,
                format!(
                    "demonstration index {} where {} was expected (lines must be in order, none missing or repeated)",
                    record.index,
                    records.len()
                ),
            ));
        }
        records.push(record);
    }
    Ok(records)
}

/// Checks that every record of `path` fits the run's environment: a state of `obs_dim` finite
/// values and an action below `actions`. The error names the line.
pub fn check_fits(
    records: &[DemoRecord],
    path: &Path,
    obs_dim: usize,
    actions: usize,
) -> Result<(), DemoLogError> {
    for (i, r) in records.iter().enumerate() {
        let reason = if r.state.len() != obs_dim {
            format!(
                "state of {} values where the environment has {obs_dim}",
                r.state.len()
            )
        } else if r.state.iter().any(|x| !x.is_finite()) {
            "state with a value that is not finite".to_owned()
        } else if r.action >= actions {
            format!(
                "action {} where the environment has {actions} actions",
                r.action
            )
        } else {
            continue;
        };
        return Err(DemoLogError::Malformed {
            path: path.to_owned(),
            line: i + 1,
            reason,
        });
    }
    Ok(())
}

/// One line of `demos.jsonl`, its newline included: the record, and with several experts
/// (`panel`: the answer's cost and whether its state was asked twice) `cost` and `double_asked`.
pub fn line(record: &DemoRecord, panel: Option<(f64, bool)>) -> Vec<u8> {
    #[derive(serde::Serialize)]
    struct Line<'a> {
        #[serde(flatten)]
        record: &'a DemoRecord,
        cost: f64,
        double_asked: bool,
    }
    let mut out = match panel {
        Some((cost, double_asked)) => serde_json::to_vec(&Line {
            record,
            cost,
            double_asked,
        }),
        None => serde_json::to_vec(record),
    }
    .expect("a DemoRecord always serialises");
    out.push(b'\n');
    out
}

/// The lines of `demos.jsonl` text that are answers of several experts' (those [`line`] wrote
/// with a `cost`).
pub fn panel_answers(text: &str) -> usize {
    text.lines()
        .filter(|l| {
            serde_json::from_str::<serde_json::Value>(l).is_ok_and(|v| v.get("cost").is_some())
        })
        .count()
}

/// `demos.jsonl`, open for appending.
#[derive(Debug)]
pub struct DemoLog {
    file: File,
    path: PathBuf,
}

impl DemoLog {
    /// Opens (creating it if needed) `path` for appending.
    pub fn open(path: &Path) -> Result<Self, DemoLogError> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|source| DemoLogError::Write {
                path: path.to_owned(),
                io: source,
            })?;
        Ok(Self {
            file,
            path: path.to_owned(),
        })
    }

    /// Appends `record` as one line and waits until it is on disk (fsync). A write that fails
    /// (a full disk) takes back what it wrote of the line, so the file stays whole lines and the
    /// next expert reads it.
    pub fn append(&mut self, record: &DemoRecord) -> Result<(), DemoLogError> {
        self.append_line(line(record, None))
    }

    /// [`DemoLog::append`] for a run with several experts: the line also says what the answer
    /// cost and whether its state was asked of two experts.
    pub fn append_of(
        &mut self,
        record: &DemoRecord,
        cost: f64,
        double_asked: bool,
    ) -> Result<(), DemoLogError> {
        self.append_line(line(record, Some((cost, double_asked))))
    }

    fn append_line(&mut self, line: Vec<u8>) -> Result<(), DemoLogError> {
        alfd_harness::append_whole(&mut self.file, &line, true).map_err(|io| DemoLogError::Write {
            path: self.path.clone(),
            io,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_disk_is_an_error_naming_the_file() {
        // Writes to /dev/full fail with ENOSPC, as on a full disk.
        let mut log = DemoLog::open(Path::new("/dev/full")).unwrap();
        let e = log.append(&record(0)).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("/dev/full"), "{text}");
        assert!(
            matches!(&e, DemoLogError::Write { io, .. } if io.raw_os_error() == Some(28)),
            "{e:?}"
        );
        assert!(e.is_disk_full());
        let other = DemoLogError::Write {
            path: "x".into(),
            io: std::io::Error::from_raw_os_error(5),
        };
        assert!(!other.is_disk_full(), "EIO is not a full disk");
    }

    #[test]
    fn panel_answers_counts_the_lines_written_with_a_cost() {
        let mut text = Vec::new();
        text.extend(line(&record(0), Some((2.0, false))));
        text.extend(line(&record(1), None));
        text.extend(line(&record(2), Some((1.0, true))));
        assert_eq!(panel_answers(std::str::from_utf8(&text).unwrap()), 2);
        assert_eq!(panel_answers(""), 0);
    }

    fn record(index: u32) -> DemoRecord {
        DemoRecord {
            index,
            state: vec![0.1, -0.2, 0.03, index as f64],
            action: (index % 2) as usize,
            step: 10 * u64::from(index),
            expert: "cartpole-perfect".to_owned(),
            weight: 1.0,
        }
    }

    use alfd_harness::test_dir;

    #[test]
    fn appended_records_read_back_identical() {
        let d = test_dir("demo-log");
        let path = d.path().join("demos.jsonl");
        assert!(
            read(&path).unwrap().is_empty(),
            "a missing file holds no demos"
        );
        let mut log = DemoLog::open(&path).unwrap();
        for i in 0..3 {
            log.append(&record(i)).unwrap();
        }
        drop(log);
        // A second writer appends after the first (the next expert of a swap).
        DemoLog::open(&path).unwrap().append(&record(3)).unwrap();
        let back = read(&path).unwrap();
        assert_eq!(back, (0..4).map(record).collect::<Vec<_>>());
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.lines().count(), 4);
        assert!(text
            .lines()
            .next()
            .unwrap()
            .contains("\"expert\":\"cartpole-perfect\""));
    }

    #[test]
    fn a_malformed_line_is_named_and_nothing_is_lost() {
        let d = test_dir("demo-log");
        let path = d.path().join("demos.jsonl");
        let good = |i| serde_json::to_string(&record(i)).unwrap();
        let text = format!(
            "{}\n{}\n{{\"index\": 2, \"state\": oops}}\n{}\n",
            good(0),
            good(1),
            good(3)
        );
        std::fs::write(&path, &text).unwrap();
        let err = read(&path).unwrap_err().to_string();
        assert!(
            err.contains("line 3") && err.contains("not a demonstration record"),
            "{err}"
        );
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            text,
            "the file is untouched"
        );

        std::fs::write(&path, format!("{}\n{}\n", good(0), good(2))).unwrap();
        let err = read(&path).unwrap_err().to_string();
        assert!(
            err.contains("line 2") && err.contains("index 2 where 1 was expected"),
            "{err}"
        );

        std::fs::write(&path, format!("{}\n{}", good(0), &good(1)[..10])).unwrap();
        let err = read(&path).unwrap_err().to_string();
        assert!(
            err.contains("line 2") && err.contains("incomplete last line"),
            "{err}"
        );
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        fn good_lines(n: u32) -> String {
            (0..n)
                .map(|i| serde_json::to_string(&record(i)).unwrap() + "\n")
                .collect()
        }

        fn check(text: &str) -> Result<(), TestCaseError> {
            match parse(text, Path::new("demos.jsonl")) {
                Ok(records) => {
                    prop_assert_eq!(records.len(), text.lines().count());
                    for (i, r) in records.iter().enumerate() {
                        prop_assert_eq!(r.index as usize, i);
                    }
                }
                Err(e) => {
                    let malformed = matches!(e, DemoLogError::Malformed { .. });
                    prop_assert!(malformed);
                    prop_assert!(e.to_string().contains(" line "), "{}", e);
                }
            }
            Ok(())
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            /// Arbitrary lines: never a panic; an error names the line.
            #[test]
            fn fuzz_demo_log_arbitrary(lines in proptest::collection::vec("[ -~]{0,40}", 0..5)) {
                check(&lines.iter().map(|l| format!("{l}\n")).collect::<String>())?;
                check(&lines.concat())?;
            }

            /// Valid lines with a few characters changed, deleted or inserted.
            #[test]
            fn fuzz_demo_log_mutated(
                n in 1u32..5,
                edits in proptest::collection::vec(
                    (any::<prop::sample::Index>(), 0usize..3, "[ -~\n]{0,3}"),
                    1..4,
                ),
            ) {
                let mut text: Vec<char> = good_lines(n).chars().collect();
                for (at, del, ins) in edits {
                    let a = at.index(text.len() + 1);
                    let b = (a + del).min(text.len());
                    text.splice(a..b, ins.chars());
                }
                check(&text.into_iter().collect::<String>())?;
            }
        }

        // Regression (fuzz): a record of another state size or an action out of range parsed
        // and reached the demonstration model; it is refused naming the line.
        #[test]
        fn a_record_that_does_not_fit_the_environment_is_named() {
            let path = Path::new("demos.jsonl");
            let mut records = parse(&good_lines(3), path).unwrap();
            assert!(check_fits(&records, path, 4, 3).is_ok());
            records[1].state.pop();
            let e = check_fits(&records, path, 4, 3).unwrap_err().to_string();
            assert!(e.contains("line 2") && e.contains("3 values"), "{e}");
            records[1].state.push(f64::NAN);
            let e = check_fits(&records, path, 4, 3).unwrap_err().to_string();
            assert!(e.contains("line 2") && e.contains("not finite"), "{e}");
            records[1].state[3] = 0.0;
            records[2].action = 3;
            let e = check_fits(&records, path, 4, 3).unwrap_err().to_string();
            assert!(e.contains("line 3") && e.contains("action 3"), "{e}");
        }
    }
}
