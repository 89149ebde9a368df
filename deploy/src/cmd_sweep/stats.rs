//! Statistics of a sweep: per-episode mean, standard deviation and median of the return across
//! seeds, the first episode at which the mean reaches a threshold, and the mean of the last
//! episodes. Pure functions, tested here.

use alfd_common::query::percentile;

/// One episode of a method's curve, over the seeds that reached it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    pub episode: u32,
    pub mean: f64,
    /// Population standard deviation (divides by the count, as NumPy's default).
    pub std: f64,
    pub median: f64,
    pub count: usize,
}

/// The curve of returns over episodes: `runs[i][e]` is the return of seed `i` at episode `e`.
/// Runs may have different lengths; each episode aggregates the runs that reached it.
pub fn curve(runs: &[Vec<f64>]) -> Vec<CurvePoint> {
    let len = runs.iter().map(Vec::len).max().unwrap_or(0);
    (0..len)
        .map(|e| {
            let values: Vec<f64> = runs.iter().filter_map(|r| r.get(e).copied()).collect();
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
            CurvePoint {
                episode: e as u32,
                mean,
                std: var.sqrt(),
                median: percentile(&values, 50.0).expect("at least one run reached the episode"),
                count: values.len(),
            }
        })
        .collect()
}

/// The first episode at which the mean return is at least `threshold`.
pub fn crossing(curve: &[CurvePoint], threshold: f64) -> Option<u32> {
    curve
        .iter()
        .find(|p| p.mean >= threshold)
        .map(|p| p.episode)
}

/// The mean of the curve's mean over its last `last` episodes (all of them if fewer).
pub fn tail_mean(curve: &[CurvePoint], last: usize) -> f64 {
    let tail = &curve[curve.len().saturating_sub(last)..];
    tail.iter().map(|p| p.mean).sum::<f64>() / tail.len().max(1) as f64
}

/// A centred moving average of width `window` (shrinking at the ends), for plots.
pub fn smooth(values: &[f64], window: usize) -> Vec<f64> {
    if window <= 1 {
        return values.to_vec();
    }
    let half = window / 2;
    (0..values.len())
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + window - half).min(values.len());
            values[lo..hi].iter().sum::<f64>() / (hi - lo) as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_aggregates_across_seeds() {
        let runs = vec![vec![1.0, 10.0, 5.0], vec![3.0, 20.0], vec![2.0, 60.0]];
        let c = curve(&runs);
        assert_eq!(c.len(), 3);
        assert_eq!(c[0].mean, 2.0);
        assert!((c[0].std - (2.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(c[0].median, 2.0);
        assert_eq!(c[1].mean, 30.0);
        assert_eq!(c[1].median, 20.0);
        assert_eq!(c[2].count, 1);
        assert_eq!(c[2].std, 0.0);
        // Even counts: the median interpolates.
        let c = curve(&[vec![1.0], vec![4.0]]);
        assert_eq!(c[0].median, 2.5);
        assert_eq!(c[0].std, 1.5);
    }

    #[test]
    fn crossing_is_the_first_episode_at_or_above() {
        let c = curve(&[vec![5.0, 99.9, 100.0, 50.0, 200.0]]);
        assert_eq!(crossing(&c, 100.0), Some(2));
        assert_eq!(crossing(&c, 5.0), Some(0));
        assert_eq!(crossing(&c, 200.5), None);
    }

    #[test]
    fn tail_mean_takes_the_last_episodes() {
        let c = curve(&[vec![1.0, 2.0, 3.0, 4.0]]);
        assert_eq!(tail_mean(&c, 2), 3.5);
        assert_eq!(tail_mean(&c, 50), 2.5);
    }

    #[test]
    fn smoothing_is_centred_and_keeps_the_length() {
        assert_eq!(smooth(&[1.0, 2.0, 3.0], 1), vec![1.0, 2.0, 3.0]);
        assert_eq!(smooth(&[0.0, 3.0, 6.0, 9.0], 3), vec![1.5, 3.0, 6.0, 7.5]);
    }
}
