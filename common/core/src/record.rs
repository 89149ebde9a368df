//! What a run records: one [`EpisodeRecord`] per training episode (the rows of `episodes.csv`,
//! the same type in one process and in many) and summary statistics of returns.

/// One training episode, as `episodes.csv` records it. Plain numbers in a fixed layout
/// (`repr(C)`), so the actor processes send it to the launcher as it is.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeRecord {
    /// The environment's undiscounted return (never the shaped one).
    pub ret: f64,
    /// Mean JS divergence over the episode's steps (0 with one head).
    pub mean_js: f64,
    /// The run's global environment steps at the end of the episode.
    pub total_steps: u64,
    /// Mean return of the greedy evaluation after this episode (NaN: no evaluation then).
    pub eval_return: f64,
    /// 0-based episode index in the run.
    pub episode: u32,
    pub length: u32,
    /// Demonstrations used so far in the run (cumulative).
    pub demos_used: u32,
    /// Queries answered during this episode.
    pub queries: u32,
    /// Steps whose reward was shaped during this episode.
    pub shaped_steps: u32,
    /// The actor that played it (0 in a single-process run).
    pub actor: u16,
}

/// The header of `episodes.csv`.
pub const CSV_HEADER: &str =
    "episode,return,length,demos_used,mean_js,queries,shaped_steps,total_steps,actor,eval_return";

impl Default for EpisodeRecord {
    fn default() -> Self {
        Self {
            ret: 0.0,
            mean_js: 0.0,
            total_steps: 0,
            eval_return: f64::NAN,
            episode: 0,
            length: 0,
            demos_used: 0,
            queries: 0,
            shaped_steps: 0,
            actor: 0,
        }
    }
}

impl EpisodeRecord {
    /// One CSV row (no newline); floats in Rust's shortest round-trip form, so rows are
    /// byte-identical for identical runs.
    pub fn csv_row(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{}",
            self.episode,
            self.ret,
            self.length,
            self.demos_used,
            self.mean_js,
            self.queries,
            self.shaped_steps,
            self.total_steps,
            self.actor,
            if self.eval_return.is_nan() {
                String::new()
            } else {
                self.eval_return.to_string()
            }
        )
    }
}

/// `episodes.csv` as text.
pub fn episodes_csv(records: &[EpisodeRecord]) -> String {
    let mut out = String::with_capacity(64 * (records.len() + 1));
    out.push_str(CSV_HEADER);
    out.push('\n');
    for r in records {
        out.push_str(&r.csv_row());
        out.push('\n');
    }
    out
}

/// Why `episodes.csv` text cannot be read back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EpisodesCsvError {
    #[error("episodes.csv is empty (no header line)")]
    NoHeader,
    #[error("episodes.csv has no `{0}` column")]
    MissingColumn(&'static str),
    #[error("episodes.csv line {line}, column `{column}`: cannot read {value:?}")]
    BadValue {
        /// 1-based line number (the header is line 1).
        line: usize,
        column: &'static str,
        value: String,
    },
}

/// Reads `episodes.csv` text back into records, the inverse of [`episodes_csv`]. Columns are found
/// by their header name, so files of an older layout read too: `episode`, `return`, `length` and
/// `demos_used` are required, the others take [`EpisodeRecord::default`]'s values when absent;
/// an empty `eval_return` is NaN (no evaluation). Blank lines are skipped.
pub fn parse_episodes_csv(text: &str) -> Result<Vec<EpisodeRecord>, EpisodesCsvError> {
    let mut lines = text.lines().enumerate();
    let header: Vec<&str> = match lines.next() {
        Some((_, h)) if !h.trim().is_empty() => h.split(',').map(str::trim).collect(),
        _ => return Err(EpisodesCsvError::NoHeader),
    };
    let col = |name: &str| header.iter().position(|h| *h == name);
    let need = |name: &'static str| col(name).ok_or(EpisodesCsvError::MissingColumn(name));
    let (episode, ret, length, demos_used) = (
        need("episode")?,
        need("return")?,
        need("length")?,
        need("demos_used")?,
    );
    let (mean_js, queries, shaped_steps) = (col("mean_js"), col("queries"), col("shaped_steps"));
    let (total_steps, actor, eval_return) = (col("total_steps"), col("actor"), col("eval_return"));
    let mut records = Vec::new();
    for (i, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let n = i + 1;
        let d = EpisodeRecord::default();
        let eval = match eval_return.and_then(|c| fields.get(c)) {
            Some(v) if !v.is_empty() => value(&fields, eval_return, "eval_return", n)?,
            _ => None,
        };
        records.push(EpisodeRecord {
            episode: value(&fields, Some(episode), "episode", n)?.unwrap_or_default(),
            ret: value(&fields, Some(ret), "return", n)?.unwrap_or_default(),
            length: value(&fields, Some(length), "length", n)?.unwrap_or_default(),
            demos_used: value(&fields, Some(demos_used), "demos_used", n)?.unwrap_or_default(),
            mean_js: value(&fields, mean_js, "mean_js", n)?.unwrap_or(d.mean_js),
            queries: value(&fields, queries, "queries", n)?.unwrap_or(d.queries),
            shaped_steps: value(&fields, shaped_steps, "shaped_steps", n)?
                .unwrap_or(d.shaped_steps),
            total_steps: value(&fields, total_steps, "total_steps", n)?.unwrap_or(d.total_steps),
            actor: value(&fields, actor, "actor", n)?.unwrap_or(d.actor),
            eval_return: eval.unwrap_or(d.eval_return),
        });
    }
    Ok(records)
}

/// The value in column `at` (if the file has that column) of a row's `fields`.
fn value<T: std::str::FromStr>(
    fields: &[&str],
    at: Option<usize>,
    column: &'static str,
    line: usize,
) -> Result<Option<T>, EpisodesCsvError> {
    let Some(c) = at else { return Ok(None) };
    let v = fields.get(c).copied().unwrap_or_default();
    v.parse().map(Some).map_err(|_| EpisodesCsvError::BadValue {
        line,
        column,
        value: v.to_owned(),
    })
}

/// Mean of the last (at most) 50 returns, as run summaries report it (0 with no episodes).
pub fn mean_return_last_50(returns: &[f64]) -> f64 {
    let tail = &returns[returns.len().saturating_sub(50)..];
    tail.iter().sum::<f64>() / tail.len().max(1) as f64
}

/// What a finished run reports, in one process or many (`summary.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunSummary {
    /// Episodes recorded in `episodes.csv`.
    pub episodes: usize,
    pub mean_return_last_50: f64,
    /// Demonstrations used by the run (`demos_used` of the last episode recorded).
    pub demos_used: u32,
    pub wall_clock_s: f64,
    /// CliffWalk: value at S of the learned greedy policy, and of the optimal one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub greedy_value_at_start: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optimal_value_at_start: Option<f64>,
    /// Environment steps taken (every actor's; the episode a step limit cut short included).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub env_steps: Option<u64>,
    /// The learner's updates (neural agents).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub updates: Option<u64>,
    /// Their rates: over the time the actors ran in a multi-process run, over the training
    /// loop's wall-clock in a single-process one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub env_steps_per_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub updates_per_s: Option<f64>,
    /// A multi-process run's own numbers.
    #[serde(default, flatten, skip_serializing_if = "Option::is_none")]
    pub runtime: Option<RuntimeSummary>,
}

/// What a multi-process run adds to its [`RunSummary`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RuntimeSummary {
    pub run_id: String,
    /// Lines of `demos.jsonl`: every demonstration the expert gave, including those asked in
    /// episodes still running when the run stopped.
    pub demos: usize,
    pub actor_restarts: u32,
    pub expert_swaps: u32,
    /// Times the expert was restarted after its process died.
    #[serde(default)]
    pub expert_restarts: u32,
    /// Times the learner was restarted from its checkpoint after its process died.
    #[serde(default)]
    pub learner_restarts: u32,
    /// The run was stopped by Ctrl-C (or SIGTERM) before its last episode.
    pub interrupted: bool,
    /// Demonstrations an expert on another host wrote that `demos.jsonl` did not take (refused,
    /// or lost with a host that stopped before they reached this one). 0 in a sound run.
    #[serde(default)]
    pub demos_refused: u64,
    /// Answers with a demonstration that came after their actor stopped waiting (its query
    /// timeout): the demonstration is in `demos.jsonl` and the model, the actor acted alone.
    #[serde(default)]
    pub answers_late: u64,
    /// The most demonstrations any of the run's experts counted (what it read back and what it
    /// wrote): `demos` is at least this in a sound run, else the run fails.
    #[serde(default)]
    pub demos_experts_wrote: u64,
    /// Episode records an actor played that never reached the launcher (each actor's records
    /// are numbered, so a gap shows): the run counts them played, `episodes.csv` lacks their
    /// rows. 0 in a sound run.
    #[serde(default)]
    pub episodes_lost: u64,
}

impl RunSummary {
    /// The summary of `records` (in order), `wall_clock_s` long.
    pub fn of(records: &[EpisodeRecord], wall_clock_s: f64) -> Self {
        let returns: Vec<f64> = records.iter().map(|r| r.ret).collect();
        Self {
            episodes: records.len(),
            mean_return_last_50: mean_return_last_50(&returns),
            demos_used: records.last().map_or(0, |r| r.demos_used),
            wall_clock_s,
            greedy_value_at_start: None,
            optimal_value_at_start: None,
            env_steps: None,
            updates: None,
            env_steps_per_s: None,
            updates_per_s: None,
            runtime: None,
        }
    }
}

/// Mean, median and (population) standard deviation of returns, as `alfd expert eval` prints them.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReturnStats {
    pub mean: f64,
    pub median: f64,
    pub std: f64,
}

impl ReturnStats {
    pub fn of(returns: &[f64]) -> Self {
        assert!(!returns.is_empty(), "no returns to summarise");
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        let median = crate::query::percentile(returns, 50.0).expect("non-empty");
        Self { mean, median, std }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_has_one_value_per_header_column_in_shortest_round_trip_form() {
        let r = EpisodeRecord {
            episode: 3,
            ret: 12.5,
            length: 12,
            demos_used: 4,
            mean_js: 0.1,
            queries: 2,
            shaped_steps: 7,
            total_steps: 99,
            actor: 5,
            eval_return: f64::NAN,
        };
        assert_eq!(r.csv_row(), "3,12.5,12,4,0.1,2,7,99,5,");
        let evaluated = EpisodeRecord {
            eval_return: 950.5,
            ..r
        };
        assert_eq!(evaluated.csv_row(), "3,12.5,12,4,0.1,2,7,99,5,950.5");
        assert_eq!(
            r.csv_row().split(',').count(),
            CSV_HEADER.split(',').count()
        );
        assert_eq!(
            episodes_csv(&[r, r]),
            format!("{CSV_HEADER}\n3,12.5,12,4,0.1,2,7,99,5,\n3,12.5,12,4,0.1,2,7,99,5,\n")
        );
    }

    #[test]
    fn episodes_csv_reads_back_what_it_wrote_and_older_layouts_too() {
        let r = |episode, ret, eval_return| EpisodeRecord {
            episode,
            ret,
            length: 12,
            demos_used: episode * 2,
            mean_js: 0.125,
            queries: 1,
            shaped_steps: episode,
            total_steps: u64::from(episode) * 12 + 12,
            actor: 1,
            eval_return,
        };
        let records = [r(0, 12.5, f64::NAN), r(1, -3.0, 950.5), r(2, 0.1, f64::NAN)];
        let text = episodes_csv(&records);
        let back = parse_episodes_csv(&text).unwrap();
        // NaN is not equal to itself: compare the rows.
        assert_eq!(episodes_csv(&back), text);
        assert!(back[0].eval_return.is_nan() && back[1].eval_return == 950.5);
        // Blank lines are skipped; a file with only its header has no records.
        assert_eq!(parse_episodes_csv(&format!("{text}\n\n")).unwrap().len(), 3);
        assert_eq!(
            parse_episodes_csv(&format!("{CSV_HEADER}\n")).unwrap(),
            vec![]
        );
        // An older layout, columns in another order, some missing: defaults.
        let old = parse_episodes_csv("return,episode,length,demos_used\n7,4,7,3\n").unwrap();
        assert_eq!(
            (old[0].episode, old[0].ret, old[0].length, old[0].demos_used),
            (4, 7.0, 7, 3)
        );
        assert!(old[0].eval_return.is_nan() && old[0].total_steps == 0);
        // Errors say where.
        assert_eq!(parse_episodes_csv(""), Err(EpisodesCsvError::NoHeader));
        assert_eq!(
            parse_episodes_csv("episode,return,length\n"),
            Err(EpisodesCsvError::MissingColumn("demos_used"))
        );
        let bad = format!("{CSV_HEADER}\n0,1,2,3,0.1,0,0,12,0,\n1,x,2,3,0.1,0,0,12,0,\n");
        assert_eq!(
            parse_episodes_csv(&bad),
            Err(EpisodesCsvError::BadValue {
                line: 3,
                column: "return",
                value: "x".into()
            })
        );
        assert!(parse_episodes_csv(&format!("{CSV_HEADER}\n0,1\n")).is_err());
    }

    #[test]
    fn a_summary_reads_back_with_or_without_the_runtime_part() {
        let r = |ret, demos_used| EpisodeRecord {
            ret,
            demos_used,
            ..EpisodeRecord::default()
        };
        let mut s = RunSummary::of(&[r(1.0, 0), r(3.0, 2)], 1.5);
        assert_eq!(
            (s.episodes, s.mean_return_last_50, s.demos_used),
            (2, 2.0, 2)
        );
        let json = serde_json::to_string(&s).unwrap();
        assert!(
            !json.contains("run_id") && !json.contains("greedy"),
            "{json}"
        );
        assert_eq!(serde_json::from_str::<RunSummary>(&json).unwrap(), s);
        s.env_steps = Some(40);
        s.updates_per_s = Some(39.0);
        s.runtime = Some(RuntimeSummary {
            run_id: "r1".into(),
            demos: 3,
            actor_restarts: 0,
            expert_swaps: 1,
            expert_restarts: 2,
            learner_restarts: 1,
            interrupted: false,
            demos_refused: 0,
            answers_late: 2,
            demos_experts_wrote: 3,
            episodes_lost: 0,
        });
        let json = serde_json::to_string(&s).unwrap();
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(
            (v["demos"].as_u64(), v["expert_swaps"].as_u64()),
            (Some(3), Some(1))
        );
        assert_eq!(
            (v["env_steps"].as_u64(), v.get("updates")),
            (Some(40), None)
        );
        assert_eq!(serde_json::from_str::<RunSummary>(&json).unwrap(), s);
    }

    #[test]
    fn the_last_50_mean_uses_what_there_is() {
        assert_eq!(mean_return_last_50(&[]), 0.0);
        assert_eq!(mean_return_last_50(&[1.0, 3.0]), 2.0);
        let many: Vec<f64> = (0..100).map(f64::from).collect();
        assert_eq!(
            mean_return_last_50(&many),
            (50..100).sum::<i32>() as f64 / 50.0
        );
    }
}
