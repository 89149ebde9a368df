//! Percentile-bootstrap confidence intervals over seeds (the practice of rliable, Agarwal et al.
//! 2021): the seeds of a method are resampled with replacement, a statistic is recomputed on each
//! resample, and its 2.5th and 97.5th percentiles bound the 95% interval. The resamples come from
//! one fixed-seed ChaCha8 stream (`alfd_common::rng`), so a sweep re-run reports the same
//! intervals. Pure functions, tested here.

use alfd_common::query::percentile;
use alfd_common::rng;
use rand::Rng as _;

/// Resamples drawn per interval.
pub const RESAMPLES: usize = 2000;
/// The seed of every bootstrap stream (each statistic derives its own with [`rng::derive_seed`]).
const SEED: u64 = 0x0a1f_d5ee_d000_0001;
/// The interval's percentiles: 95% two-sided.
const LOW: f64 = 2.5;
const HIGH: f64 = 97.5;

/// A closed interval `[low, high]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    pub low: f64,
    pub high: f64,
}

/// A statistic of the seeds and its 95% bootstrap interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub value: f64,
    pub ci: Interval,
}

/// The 95% bootstrap interval of a curve's first crossing of a threshold. A bound is `None`
/// ("not reached") when the resampled curves that never cross are too many for it: the upper bound
/// when more than 2.5% of them never cross, the lower bound when more than 97.5% do not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrossingCi {
    pub low: Option<f64>,
    pub high: Option<f64>,
    /// The share of resamples whose mean curve never crosses.
    pub never: f64,
}

/// `RESAMPLES` draws of `n` seed indices with replacement, from the stream named `stream`.
#[derive(Debug, Clone)]
pub struct Resamples {
    n: usize,
    draws: Vec<Vec<usize>>,
}

impl Resamples {
    pub fn new(n: usize, stream: &str) -> Self {
        Self::with_count(n, RESAMPLES, stream)
    }

    pub fn with_count(n: usize, resamples: usize, stream: &str) -> Self {
        let mut rng = rng::seeded(rng::derive_seed(SEED, stream));
        let draws = (0..resamples)
            .map(|_| (0..n).map(|_| rng.random_range(0..n)).collect())
            .collect();
        Self { n, draws }
    }

    /// `stat` of `values` (one per seed) and its interval over the resamples.
    pub fn estimate(&self, values: &[f64], stat: impl Fn(&[f64]) -> f64) -> Estimate {
        assert_eq!(values.len(), self.n, "one value per seed");
        let mut buf = vec![0.0; self.n];
        let stats: Vec<f64> = self
            .draws
            .iter()
            .map(|draw| {
                for (b, &i) in buf.iter_mut().zip(draw) {
                    *b = values[i];
                }
                stat(&buf)
            })
            .collect();
        Estimate {
            value: stat(values),
            ci: percentile_interval(&stats),
        }
    }

    /// A time that may never come (`stat` of the seeds drawn, by index: `None` for never) and
    /// the interval of its resamples, a resample whose time never comes counting as +∞ (the
    /// quantiles of [`crossing_interval`]).
    pub fn time(&self, stat: impl Fn(&[usize]) -> Option<f64>) -> (Option<f64>, CrossingCi) {
        let all: Vec<usize> = (0..self.n).collect();
        let times: Vec<Option<f64>> = self.draws.iter().map(|d| stat(d)).collect();
        (stat(&all), crossing_interval(&times))
    }

    /// The bootstrap of a mean curve: `runs[i][k]` is seed `i`'s value at `xs[k]` (every run as
    /// long as `xs`). Each resample's mean curve gives a value at every x, an area and, for each
    /// threshold, its first crossing.
    pub fn curve(&self, xs: &[f64], runs: &[Vec<f64>], thresholds: &[f64]) -> CurveCi {
        assert_eq!(runs.len(), self.n, "one run per seed");
        assert!(runs.iter().all(|r| r.len() == xs.len()), "runs span the x");
        let b = self.draws.len();
        let mut band = Vec::with_capacity(xs.len());
        let mut means = vec![0.0; b];
        let mut previous = vec![0.0; b];
        let mut area = vec![0.0; b];
        let mut first: Vec<Vec<Option<f64>>> = vec![vec![None; b]; thresholds.len()];
        for (k, &x) in xs.iter().enumerate() {
            for (m, draw) in means.iter_mut().zip(&self.draws) {
                *m = draw.iter().map(|&i| runs[i][k]).sum::<f64>() / self.n as f64;
            }
            if k > 0 {
                let dx = x - xs[k - 1];
                for ((a, m), p) in area.iter_mut().zip(&means).zip(&previous) {
                    *a += dx * (m + p) / 2.0;
                }
            }
            for (t, first) in thresholds.iter().zip(&mut first) {
                for (f, m) in first.iter_mut().zip(&means) {
                    if f.is_none() && *m >= *t {
                        *f = Some(x);
                    }
                }
            }
            band.push(percentile_interval(&means));
            previous.copy_from_slice(&means);
        }
        let auc = match (xs.first(), xs.last()) {
            (Some(lo), Some(hi)) if hi > lo => {
                let areas: Vec<f64> = area.iter().map(|a| a / (hi - lo)).collect();
                percentile_interval(&areas)
            }
            // One x: the area is the value there.
            _ => percentile_interval(&previous),
        };
        CurveCi {
            band,
            auc,
            crossings: first.iter().map(|f| crossing_interval(f)).collect(),
        }
    }
}

/// What [`Resamples::curve`] gives.
#[derive(Debug, Clone, PartialEq)]
pub struct CurveCi {
    /// The interval of the mean at each x.
    pub band: Vec<Interval>,
    /// The interval of the normalised area under the mean curve.
    pub auc: Interval,
    /// Per threshold, the interval of the first crossing.
    pub crossings: Vec<CrossingCi>,
}

/// The 2.5th and 97.5th percentiles of `stats` (NumPy's linear interpolation, as rliable's
/// percentile intervals).
fn percentile_interval(stats: &[f64]) -> Interval {
    let mut sorted = stats.to_vec();
    sorted.sort_by(f64::total_cmp);
    Interval {
        low: percentile(&sorted, LOW).unwrap_or(f64::NAN),
        high: percentile(&sorted, HIGH).unwrap_or(f64::NAN),
    }
}

/// The 2.5% and 97.5% quantiles of first crossings, a resample that never crosses counting as
/// crossing at +∞. Quantiles of the empirical distribution (the smallest value whose cumulative
/// share reaches q, NumPy's `inverted_cdf`), so that a bound is an x some resample crossed at, and
/// the upper bound is infinite ("not reached") exactly when more than 2.5% never cross.
fn crossing_interval(first: &[Option<f64>]) -> CrossingCi {
    let mut sorted: Vec<f64> = first.iter().map(|f| f.unwrap_or(f64::INFINITY)).collect();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let quantile = |q: f64| -> Option<f64> {
        if n == 0 {
            return None;
        }
        // The smallest m with m / n ≥ q (a small tolerance against 0.975 * n rounding up).
        let m = ((q * n as f64) - 1e-9).ceil().max(1.0) as usize;
        Some(sorted[m.min(n) - 1]).filter(|v| v.is_finite())
    };
    CrossingCi {
        low: quantile(LOW / 100.0),
        high: quantile(HIGH / 100.0),
        never: first.iter().filter(|f| f.is_none()).count() as f64 / n.max(1) as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::super::{iqm, mean};
    use super::*;

    fn width(ci: Interval) -> f64 {
        ci.high - ci.low
    }

    #[test]
    fn the_interval_of_a_constant_sample_is_a_point() {
        let r = Resamples::new(7, "test");
        let e = r.estimate(&[3.5; 7], mean);
        assert_eq!(e.value, 3.5);
        assert_eq!(
            e.ci,
            Interval {
                low: 3.5,
                high: 3.5
            }
        );
        let e = r.estimate(&[3.5; 7], iqm);
        assert_eq!(
            e.ci,
            Interval {
                low: 3.5,
                high: 3.5
            }
        );
    }

    #[test]
    fn the_interval_of_a_mean_holds_it_and_narrows_as_seeds_grow() {
        // Values 0..9 repeated: mean 4.5, population std sqrt(8.25) = 2.87; the normal
        // approximation of the interval is mean ± 1.96 · 2.87 / sqrt(n).
        let sample = |n: usize| -> Vec<f64> { (0..n).map(|i| (i % 10) as f64).collect() };
        let small = Resamples::new(10, "test").estimate(&sample(10), mean);
        let large = Resamples::new(1000, "test").estimate(&sample(1000), mean);
        for e in [small, large] {
            assert_eq!(e.value, 4.5);
            assert!(e.ci.low < 4.5 && 4.5 < e.ci.high, "{e:?}");
        }
        // 2 · 1.96 · 2.87 / sqrt(10) = 3.56 and / sqrt(1000) = 0.356.
        assert!((3.0..4.1).contains(&width(small.ci)), "{small:?}");
        assert!((0.32..0.40).contains(&width(large.ci)), "{large:?}");
        // The same stream gives the same interval.
        assert_eq!(
            Resamples::new(10, "test").estimate(&sample(10), mean),
            small
        );
    }

    #[test]
    fn a_crossing_every_seed_shares_has_a_point_interval() {
        // Four seeds, each below 5 before episode 7 and at least 10 from it on: every resampled
        // mean curve crosses 8 at episode 7, and crosses 0 at episode 0.
        let xs: Vec<f64> = (0..12).map(f64::from).collect();
        let runs: Vec<Vec<f64>> = (0..4)
            .map(|s| {
                (0..12)
                    .map(|e| {
                        if e < 7 {
                            f64::from(s)
                        } else {
                            10.0 + f64::from(s)
                        }
                    })
                    .collect()
            })
            .collect();
        let ci = Resamples::new(4, "test").curve(&xs, &runs, &[8.0, 0.0, 100.0]);
        let exact = |x| CrossingCi {
            low: Some(x),
            high: Some(x),
            never: 0.0,
        };
        assert_eq!(ci.crossings[0], exact(7.0));
        assert_eq!(ci.crossings[1], exact(0.0));
        let never = CrossingCi {
            low: None,
            high: None,
            never: 1.0,
        };
        assert_eq!(ci.crossings[2], never);
        // Before episode 7 the mean of a resample lies in [0, 3], after it in [10, 13].
        assert!(
            ci.band[0].low >= 0.0 && ci.band[0].high <= 3.0,
            "{:?}",
            ci.band[0]
        );
        assert!(ci.band[11].low >= 10.0 && ci.band[11].high <= 13.0);
    }

    #[test]
    fn a_crossing_many_resamples_miss_has_no_upper_bound() {
        // Two of four seeds jump to 10 at episode 3, two stay at 0: a resample's mean reaches 4
        // only if it holds two or more jumping seeds, which misses with probability
        // P(Binomial(4, 1/2) ≤ 1) = 5/16 = 31%: more than 2.5%, so the upper bound is not reached.
        let xs: Vec<f64> = (0..6).map(f64::from).collect();
        let jump: Vec<f64> = (0..6).map(|e| if e < 3 { 0.0 } else { 10.0 }).collect();
        let runs = vec![jump.clone(), vec![0.0; 6], jump, vec![0.0; 6]];
        let ci = Resamples::new(4, "test").curve(&xs, &runs, &[4.0]);
        let c = ci.crossings[0];
        assert_eq!(c.low, Some(3.0));
        assert_eq!(c.high, None);
        assert!((0.28..0.35).contains(&c.never), "{c:?}");
    }

    #[test]
    fn crossing_bounds_follow_the_share_that_never_crosses() {
        let with_never = |k: usize| -> Vec<Option<f64>> {
            (0..2000)
                .map(|i| if i < k { None } else { Some((i % 7) as f64) })
                .collect()
        };
        // 50 of 2000 never cross: exactly 2.5%, not more, so the upper bound is reached (6).
        assert_eq!(crossing_interval(&with_never(50)).high, Some(6.0));
        assert_eq!(crossing_interval(&with_never(51)).high, None);
        assert_eq!(crossing_interval(&with_never(51)).low, Some(0.0));
        assert_eq!(crossing_interval(&with_never(1951)).low, None);
        // 1950 never: the lower bound is the largest of the 50 that cross.
        assert_eq!(crossing_interval(&with_never(1950)).low, Some(6.0));
    }

    #[test]
    fn the_area_interval_of_constant_curves_is_the_constant() {
        let xs = [0.0, 10.0, 40.0];
        let ci = Resamples::new(3, "test").curve(&xs, &vec![vec![2.5; 3]; 3], &[]);
        assert_eq!(
            ci.auc,
            Interval {
                low: 2.5,
                high: 2.5
            }
        );
        // One x: the area is the value.
        let ci = Resamples::new(2, "test").curve(&[5.0], &[vec![1.0], vec![3.0]], &[]);
        assert!(ci.auc.low >= 1.0 && ci.auc.high <= 3.0 && ci.auc.low < ci.auc.high);
    }
}
