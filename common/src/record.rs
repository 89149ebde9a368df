//! What a run records: one [`EpisodeRecord`] per training episode (the rows of `episodes.csv`,
//! the same type in one process and in many) and summary statistics of returns.

/// One training episode, as `episodes.csv` records it. Plain numbers in a fixed layout
/// (`repr(C)`), so the actor processes send it to the launcher as it is.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct EpisodeRecord {
    /// The environment's undiscounted return (never the shaped one).
    pub ret: f64,
    /// Mean JS divergence over the episode's steps (0 with one head).
    pub mean_js: f64,
    /// The run's global environment steps at the end of the episode.
    pub total_steps: u64,
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
    "episode,return,length,demos_used,mean_js,queries,shaped_steps,total_steps,actor";

impl EpisodeRecord {
    /// One CSV row (no newline); floats in Rust's shortest round-trip form, so rows are
    /// byte-identical for identical runs.
    pub fn csv_row(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{}",
            self.episode,
            self.ret,
            self.length,
            self.demos_used,
            self.mean_js,
            self.queries,
            self.shaped_steps,
            self.total_steps,
            self.actor
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

/// Mean of the last (at most) 50 returns, as run summaries report it (0 with no episodes).
pub fn mean_return_last_50(returns: &[f64]) -> f64 {
    let tail = &returns[returns.len().saturating_sub(50)..];
    tail.iter().sum::<f64>() / tail.len().max(1) as f64
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
        };
        assert_eq!(r.csv_row(), "3,12.5,12,4,0.1,2,7,99,5");
        assert_eq!(
            r.csv_row().split(',').count(),
            CSV_HEADER.split(',').count()
        );
        assert_eq!(
            episodes_csv(&[r, r]),
            format!("{CSV_HEADER}\n3,12.5,12,4,0.1,2,7,99,5\n3,12.5,12,4,0.1,2,7,99,5\n")
        );
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
