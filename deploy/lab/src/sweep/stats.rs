//! Statistics of a sweep, as point estimates: the curve of returns across seeds (mean, standard
//! deviation, median), its first crossing of a threshold, its normalised area, the mean of its last
//! episodes, the interquartile mean, and the curves of returns over environment steps. Their
//! bootstrap intervals are in [`bootstrap`]. Pure functions, tested here.

use alfd_common::query::percentile;

pub mod bootstrap;

/// One x of a method's curve, over the seeds that reached it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    /// The episode (0-based) or the environment step.
    pub x: f64,
    pub mean: f64,
    /// Population standard deviation (divides by the count, as NumPy's default).
    pub std: f64,
    pub median: f64,
    pub count: usize,
}

/// The curve of returns: `runs[i][k]` is the return of seed `i` at `xs[k]`. Runs may be shorter
/// than `xs`; each x aggregates the runs that reached it.
pub fn curve(xs: &[f64], runs: &[Vec<f64>]) -> Vec<CurvePoint> {
    xs.iter()
        .enumerate()
        .map_while(|(k, &x)| {
            let values: Vec<f64> = runs.iter().filter_map(|r| r.get(k).copied()).collect();
            let m = mean(&values);
            let var = values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / values.len() as f64;
            Some(CurvePoint {
                x,
                mean: m,
                std: var.sqrt(),
                median: percentile(&values, 50.0)?,
                count: values.len(),
            })
        })
        .collect()
}

/// The episodes `0..n` as an x axis.
pub fn episodes(n: usize) -> Vec<f64> {
    (0..n).map(|e| e as f64).collect()
}

/// The mean of `v` (NaN when empty).
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The interquartile mean as rliable computes it (`scipy.stats.trim_mean(v, 0.25)`): sorted, then
/// `floor(n / 4)` values cut from each end, and the mean of the rest.
pub fn iqm(v: &[f64]) -> f64 {
    let mut sorted = v.to_vec();
    sorted.sort_by(f64::total_cmp);
    let cut = v.len() / 4;
    mean(&sorted[cut..v.len() - cut])
}

/// The first x at which `values` (along `xs`) is at least `threshold`.
pub fn crossing(xs: &[f64], values: &[f64], threshold: f64) -> Option<f64> {
    xs.iter()
        .zip(values)
        .find(|(_, v)| **v >= threshold)
        .map(|(x, _)| *x)
}

/// The area under `values` along `xs` (trapezoids) divided by the x range: the curve's average
/// height. With one x, the value there.
pub fn auc(xs: &[f64], values: &[f64]) -> f64 {
    let (Some(lo), Some(hi)) = (xs.first(), xs.last()) else {
        return f64::NAN;
    };
    if hi <= lo {
        return values[0];
    }
    let area: f64 = xs
        .windows(2)
        .zip(values.windows(2))
        .map(|(x, v)| (x[1] - x[0]) * (v[0] + v[1]) / 2.0)
        .sum();
    area / (hi - lo)
}

/// Each run's final value: the mean of its last 10% of points (rounded up, at least one).
pub fn final_values(runs: &[Vec<f64>]) -> Vec<f64> {
    runs.iter()
        .map(|r| mean(&r[r.len() - r.len().div_ceil(10)..]))
        .collect()
}

/// The mean of the curve's mean over its last `last` points (all of them if fewer).
pub fn tail_mean(curve: &[CurvePoint], last: usize) -> f64 {
    let tail = &curve[curve.len().saturating_sub(last)..];
    tail.iter().map(|p| p.mean).sum::<f64>() / tail.len().max(1) as f64
}

/// The mean over the runs of each run's mean return over its own last `last` episodes. With runs
/// of equal length this is [`tail_mean`] of their mean curve (and computed that way, so the
/// numbers stay those of the episode curves); with runs of different lengths (runs limited in
/// environment steps) the last episodes of the mean curve would be those of the runs with the
/// most, shortest, episodes only, so each run counts its own last episodes instead.
pub fn runs_tail_mean(returns: &[Vec<f64>], last: usize) -> f64 {
    let longest = returns.iter().map(Vec::len).max().unwrap_or(0);
    if returns.iter().all(|r| r.len() == longest) {
        return tail_mean(&curve(&episodes(longest), returns), last);
    }
    let own: Vec<f64> = returns
        .iter()
        .filter(|r| !r.is_empty())
        .map(|r| {
            let tail = &r[r.len().saturating_sub(last)..];
            tail.iter().sum::<f64>() / tail.len() as f64
        })
        .collect();
    own.iter().sum::<f64>() / own.len().max(1) as f64
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

/// One run's episodes as a function of environment steps: `(total_steps, return)` of each
/// finished episode.
pub type StepRun = [(f64, f64)];

/// The common grid of environment steps of a method's runs: `points` evenly spaced steps (rounded
/// to whole steps, without repeats) from the first step at which every run has finished an episode
/// to the last step every run reached (the smallest of the runs' final `total_steps`), so that
/// every run has a value at every point and no run's mean is taken beyond its end.
pub fn step_grid(runs: &[&StepRun], points: usize) -> Vec<f64> {
    let first_end = |r: &StepRun| r.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let last_end = |r: &StepRun| r.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let lo = runs
        .iter()
        .map(|r| first_end(r))
        .fold(f64::NEG_INFINITY, f64::max);
    let hi = runs
        .iter()
        .map(|r| last_end(r))
        .fold(f64::INFINITY, f64::min);
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo || points < 2 {
        return if lo.is_finite() { vec![lo] } else { Vec::new() };
    }
    let mut grid: Vec<f64> = (0..points)
        .map(|k| (lo + (hi - lo) * k as f64 / (points - 1) as f64).round())
        .collect();
    grid.dedup();
    grid
}

/// A run's return at each step of `grid`: the return of the last episode finished by that step
/// (NaN before its first episode ends).
pub fn on_grid(run: &StepRun, grid: &[f64]) -> Vec<f64> {
    let mut ends = run.to_vec();
    ends.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut next = 0;
    let mut value = f64::NAN;
    grid.iter()
        .map(|&s| {
            while next < ends.len() && ends[next].0 <= s {
                value = ends[next].1;
                next += 1;
            }
            value
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_aggregates_across_seeds() {
        let runs = vec![vec![1.0, 10.0, 5.0], vec![3.0, 20.0], vec![2.0, 60.0]];
        let c = curve(&episodes(3), &runs);
        assert_eq!(c.len(), 3);
        assert_eq!(c[0].mean, 2.0);
        assert!((c[0].std - (2.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(c[0].median, 2.0);
        assert_eq!(c[1].mean, 30.0);
        assert_eq!(c[1].median, 20.0);
        assert_eq!((c[2].x, c[2].count, c[2].std), (2.0, 1, 0.0));
        // Even counts: the median interpolates.
        let c = curve(&[5.0], &[vec![1.0], vec![4.0]]);
        assert_eq!((c[0].x, c[0].median, c[0].std), (5.0, 2.5, 1.5));
    }

    #[test]
    fn crossing_is_the_first_x_at_or_above() {
        let xs = episodes(5);
        let v = [5.0, 99.9, 100.0, 50.0, 200.0];
        assert_eq!(crossing(&xs, &v, 100.0), Some(2.0));
        assert_eq!(crossing(&xs, &v, 5.0), Some(0.0));
        assert_eq!(crossing(&xs, &v, 200.5), None);
        assert_eq!(crossing(&[10.0, 20.0], &[0.0, 7.0], 7.0), Some(20.0));
    }

    #[test]
    fn the_interquartile_mean_trims_a_quarter_each_side() {
        // 1..=8: two cut at each end, the mean of 3, 4, 5, 6.
        let v: Vec<f64> = (1..=8).rev().map(f64::from).collect();
        assert_eq!(iqm(&v), 4.5);
        // n = 5: floor(5/4) = 1 cut each side: the mean of 2, 3, 4 (the outlier is gone).
        assert_eq!(iqm(&[100.0, 1.0, 2.0, 3.0, 4.0]), 3.0);
        // Fewer than 4 values: nothing is cut.
        assert_eq!(iqm(&[1.0, 2.0, 9.0]), 4.0);
        assert_eq!(iqm(&[7.0]), 7.0);
    }

    #[test]
    fn the_area_is_the_average_height() {
        assert_eq!(auc(&episodes(4), &[3.0; 4]), 3.0);
        assert_eq!(auc(&[0.0, 5.0, 10.0], &[0.0, 5.0, 10.0]), 5.0);
        // Uneven x: 10 · 1 + 30 · (1 + 5) / 2 = 100 over 40.
        assert_eq!(auc(&[0.0, 10.0, 40.0], &[1.0, 1.0, 5.0]), 2.5);
        assert_eq!(auc(&[3.0], &[8.0]), 8.0);
    }

    #[test]
    fn final_values_are_each_runs_last_tenth() {
        let run: Vec<f64> = (0..20).map(f64::from).collect();
        // 10% of 20 = the last 2 (18, 19); of 5, rounded up to 1.
        assert_eq!(
            final_values(&[run, vec![1.0, 2.0, 3.0, 4.0, 9.0]]),
            vec![18.5, 9.0]
        );
    }

    #[test]
    fn tail_mean_takes_the_last_points() {
        let c = curve(&episodes(4), &[vec![1.0, 2.0, 3.0, 4.0]]);
        assert_eq!(tail_mean(&c, 2), 3.5);
        assert_eq!(tail_mean(&c, 50), 2.5);
        // Runs of different lengths: each counts its own last 2 episodes, (15 + 20) / 2 and
        // (1 + 1) / 2, then their mean 9.25 (the mean curve's last 2 points would be 2 and 1).
        let runs = vec![vec![10.0, 15.0, 20.0], vec![0.0, 1.0, 1.0, 1.0, 1.0]];
        assert_eq!(runs_tail_mean(&runs, 2), 9.25);
        // Equal lengths: the mean curve's tail.
        let equal = vec![vec![1.0, 2.0, 3.0], vec![3.0, 4.0, 5.0]];
        assert_eq!(runs_tail_mean(&equal, 2), 3.5);
    }

    #[test]
    fn smoothing_is_centred_and_keeps_the_length() {
        assert_eq!(smooth(&[1.0, 2.0, 3.0], 1), vec![1.0, 2.0, 3.0]);
        assert_eq!(smooth(&[0.0, 3.0, 6.0, 9.0], 3), vec![1.5, 3.0, 6.0, 7.5]);
    }

    #[test]
    fn two_episode_runs_on_a_step_grid() {
        // Run a: episode 0 (return 10) ends at step 10, episode 1 (return 30) at step 40.
        // Run b: episode 0 (return 0) ends at step 20, episode 1 (return 50) at step 30.
        let a = [(10.0, 10.0), (40.0, 30.0)];
        let b = [(20.0, 0.0), (30.0, 50.0)];
        // From 20 (both have finished an episode) to 30 (b's last step).
        let grid = step_grid(&[&a, &b], 3);
        assert_eq!(grid, vec![20.0, 25.0, 30.0]);
        assert_eq!(on_grid(&a, &grid), vec![10.0, 10.0, 10.0]);
        assert_eq!(on_grid(&b, &grid), vec![0.0, 0.0, 50.0]);
        // Run a alone: 10 to 40; before its first episode ends it has no return.
        let grid = step_grid(&[&a], 4);
        assert_eq!(grid, vec![10.0, 20.0, 30.0, 40.0]);
        assert_eq!(on_grid(&a, &grid), vec![10.0, 10.0, 10.0, 30.0]);
        assert!(on_grid(&a, &[9.0])[0].is_nan());
        // Whole steps, no repeats: 11 points over 4 steps are 5.
        assert_eq!(
            step_grid(&[&[(2.0, 1.0), (6.0, 1.0)]], 11),
            vec![2.0, 3.0, 4.0, 5.0, 6.0]
        );
        // Runs that share no range: the grid is the one step every run has finished by.
        assert_eq!(step_grid(&[&b, &[(35.0, 1.0), (50.0, 1.0)]], 3), vec![35.0]);
    }
}
