//! The divergence queue `U_queue` of Algorithm 1 and its `p_r` percentile threshold, NumPy's
//! linear interpolation.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// Percentile of `values` with linear interpolation between closest ranks, NumPy's default
/// (`np.percentile(values, p)`, method `"linear"`). `p` is in `[0, 100]`. `None` when empty.
pub fn percentile(values: &[f64], p: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(|a, b| a.total_cmp(b));
    percentile_of_sorted(&sorted, p)
}

/// [`percentile`] of values already sorted by `f64::total_cmp`.
fn percentile_of_sorted(sorted: &[f64], p: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (p / 100.0) * (sorted.len() - 1) as f64;
    let lo = rank.floor() as usize;
    let hi = rank.ceil() as usize;
    let frac = rank - lo as f64;
    Some(sorted[lo] + (sorted[hi] - sorted[lo]) * frac)
}

/// The divergence queue `U_queue` and the percentile threshold of Algorithm 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PercentileGate {
    /// `L_q`: how many past divergences are remembered.
    queue_len: usize,
    /// `p_r`: the percentile, in `[0, 100]`, the current divergence must exceed.
    percentile: f64,
    queue: VecDeque<f64>,
    /// The same values sorted by `total_cmp`, kept up to date on every push and pop so that the
    /// threshold costs no sort (the act step's hot path).
    sorted: Vec<f64>,
}

impl PercentileGate {
    /// `queue_len` must be at least 1 and `percentile` in `[0, 100]` (the config checks this).
    pub fn new(queue_len: usize, percentile: f64) -> Self {
        assert!(queue_len >= 1, "L_q must be at least 1");
        assert!(
            (0.0..=100.0).contains(&percentile),
            "p_r must be in [0, 100]"
        );
        Self {
            queue_len,
            percentile,
            queue: VecDeque::with_capacity(queue_len),
            sorted: Vec::with_capacity(queue_len),
        }
    }

    /// Algorithm 1 lines 4-7: the threshold is the percentile of the queue *before* `u` is pushed;
    /// `u` is then pushed (dropping the oldest value beyond `L_q`); the rule fires when
    /// `u > threshold`. An empty queue has no threshold, and the rule does not fire.
    pub fn observe(&mut self, u: f64) -> bool {
        let threshold = self.threshold();
        if self.queue.len() == self.queue_len {
            if let Some(old) = self.queue.pop_front() {
                // `old` is in `sorted`: total_cmp finds that very value (NaN and -0.0 included).
                if let Ok(i) = self.sorted.binary_search_by(|x| x.total_cmp(&old)) {
                    self.sorted.remove(i);
                }
            }
        }
        self.queue.push_back(u);
        let at = self.sorted.partition_point(|x| x.total_cmp(&u).is_lt());
        self.sorted.insert(at, u);
        matches!(threshold, Some(t) if u > t)
    }

    /// The current threshold `U_threshold`, `None` while the queue is empty: [`percentile`] of
    /// the queue, without sorting it again.
    pub fn threshold(&self) -> Option<f64> {
        percentile_of_sorted(&self.sorted, self.percentile)
    }

    pub fn len(&self) -> usize {
        self.queue.len()
    }

    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_matches_numpy_linear() {
        // np.percentile([1, 2, 3, 4], 50) == 2.5; 90 -> 3.7; 0 -> 1; 100 -> 4
        let v = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(percentile(&v, 50.0), Some(2.5));
        assert!((percentile(&v, 90.0).unwrap() - 3.7).abs() < 1e-12);
        assert_eq!(percentile(&v, 0.0), Some(1.0));
        assert_eq!(percentile(&v, 100.0), Some(4.0));
        assert_eq!(percentile(&[], 50.0), None);
        // np.percentile([0.5], 70) == 0.5
        assert_eq!(percentile(&[0.5], 70.0), Some(0.5));
    }

    #[test]
    fn rule_compares_with_queue_before_push() {
        let mut rule = PercentileGate::new(3, 50.0);
        assert!(!rule.observe(1.0), "empty queue never fires");
        assert!(rule.observe(2.0), "2 > median([1])");
        assert!(
            !rule.observe(1.5),
            "1.5 < median([1, 2]) = 1.5 is not strictly greater"
        );
        // queue is [1, 2, 1.5]; median 1.5; 1.6 fires, and 1 drops out
        assert!(rule.observe(1.6));
        assert_eq!(rule.len(), 3);
        // queue is [2, 1.5, 1.6]; median 1.6
        assert!(!rule.observe(1.55));
        // queue is now [1.5, 1.6, 1.55]
        assert!((rule.threshold().unwrap() - 1.55).abs() < 1e-12);
    }

    #[test]
    fn percentile_100_never_fires_and_0_fires_above_minimum() {
        let mut never = PercentileGate::new(10, 100.0);
        let mut often = PercentileGate::new(10, 0.0);
        let mut fired_never = 0;
        let mut fired_often = 0;
        for i in 0..100 {
            let u = (i as f64 * 0.37).sin().abs();
            fired_never += never.observe(u) as u32;
            fired_often += often.observe(u) as u32;
        }
        // p = 100 fires only on a new maximum of the last 10; p = 0 on anything above their minimum.
        assert!(fired_never < 30, "{fired_never}");
        assert!(fired_often > 70, "{fired_often}");
    }

    #[test]
    fn incremental_threshold_equals_percentile_of_the_queue() {
        let mut rule = PercentileGate::new(7, 35.0);
        let mut window: VecDeque<f64> = VecDeque::new();
        for i in 0..200 {
            // Repeated values, signed zeros and a NaN now and then.
            let u = match i % 23 {
                0 => f64::NAN,
                1 => -0.0,
                2 => 0.0,
                _ => ((i * 7919) % 13) as f64 * 0.25,
            };
            let expected = percentile(window.make_contiguous(), 35.0);
            let got = rule.threshold();
            assert!(
                got == expected
                    || (got.is_some_and(f64::is_nan) && expected.is_some_and(f64::is_nan)),
                "step {i}: {got:?} vs {expected:?}"
            );
            let fired = rule.observe(u);
            assert_eq!(fired, matches!(expected, Some(t) if u > t), "step {i}");
            if window.len() == 7 {
                window.pop_front();
            }
            window.push_back(u);
            assert_eq!(rule.len(), window.len());
        }
    }
}
