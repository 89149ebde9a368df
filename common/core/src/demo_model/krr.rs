//! Kernel Ridge Regression on one-hot actions (paper section 3.4), as scikit-learn's
//! `KernelRidge(alpha=0.1, kernel='rbf', gamma=0.1)`: dual coefficients `(K + alpha I)^-1 Y` by
//! Cholesky, outputs `f(x) = k(x, X) dual_coef`. Up to [`BLOCKED_FROM`] demonstrations the
//! factorisation is nalgebra's; from there the blocked one of `cholesky.rs`, several times faster
//! on large matrices (BENCHMARKS.md) and equal to it within rounding.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::{rbf, validate, DemoModelError};

/// The ridge penalty added to the kernel's diagonal.
pub const ALPHA: f64 = 0.1;

/// From this many demonstrations on, the kernel matrix is factored by the blocked Cholesky
/// (below it, by nalgebra's, whose numbers every run with fewer demonstrations keeps).
pub const BLOCKED_FROM: usize = 512;

/// Below this total of clipped outputs (more than two actions), the outputs are taken to have
/// vanished (the state is far from every demonstration) and p(a|s) is uniform.
pub const VANISHING: f64 = 1e-12;

/// A fitted Kernel Ridge Regression: the demonstrated states and one dual coefficient per
/// (demonstration, action).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KernelRidge {
    state_dim: usize,
    num_actions: usize,
    /// Demonstrated states, row-major, `num_demos * state_dim`.
    states: Vec<f64>,
    /// Dual coefficients, row-major, `num_demos * num_actions`.
    dual_coef: Vec<f64>,
}

impl KernelRidge {
    /// Fits on one-hot targets: row i of Y has a 1 in column `actions[i]`.
    pub fn fit<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
    ) -> Result<KernelRidge, DemoModelError> {
        let (flat, state_dim) = validate(states, actions, num_actions)?;
        let n = actions.len();
        let row = |i: usize| &flat[i * state_dim..(i + 1) * state_dim];

        let mut k = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in 0..=i {
                let v = rbf(row(i), row(j));
                k[(i, j)] = v;
                k[(j, i)] = v;
            }
            k[(i, i)] += ALPHA;
        }
        let mut y = DMatrix::<f64>::zeros(n, num_actions);
        for (i, &a) in actions.iter().enumerate() {
            y[(i, a)] = 1.0;
        }
        let coef = solve_spd(k, y)?;
        let mut dual_coef = Vec::with_capacity(n * num_actions);
        for i in 0..n {
            for a in 0..num_actions {
                dual_coef.push(coef[(i, a)]);
            }
        }
        tracing::debug!(
            demos = n,
            state_dim,
            num_actions,
            "fitted kernel ridge regression"
        );
        Ok(KernelRidge {
            state_dim,
            num_actions,
            states: flat,
            dual_coef,
        })
    }

    pub fn num_actions(&self) -> usize {
        self.num_actions
    }

    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    pub fn num_demos(&self) -> usize {
        self.states.len() / self.state_dim
    }

    /// The regression outputs `f_a(s)`, one per action.
    ///
    /// # Panics
    /// If `s.len() != self.state_dim()`.
    pub fn raw(&self, s: &[f64]) -> Vec<f64> {
        assert_eq!(
            s.len(),
            self.state_dim,
            "state of length {} queried, model fitted on length {}",
            s.len(),
            self.state_dim
        );
        let mut f = vec![0.0; self.num_actions];
        for (x, coef) in self
            .states
            .chunks_exact(self.state_dim)
            .zip(self.dual_coef.chunks_exact(self.num_actions))
        {
            let k = rbf(s, x);
            for (fa, c) in f.iter_mut().zip(coef) {
                *fa += k * c;
            }
        }
        f
    }

    /// p(a|s). Two actions: `p(a) = clip(0.5 + (f_a - f_other) / 2, 0, 1)`. More: the outputs
    /// clipped to [0, 1] and renormalised, uniform where they vanish (total below [`VANISHING`]).
    ///
    /// # Panics
    /// If `s.len() != self.state_dim()`.
    pub fn probs(&self, s: &[f64]) -> Vec<f64> {
        probs_from_outputs(&self.raw(s))
    }
}

/// `k⁻¹ y` for the symmetric positive-definite kernel matrix `k`, by Cholesky.
fn solve_spd(k: DMatrix<f64>, y: DMatrix<f64>) -> Result<DMatrix<f64>, DemoModelError> {
    let not_pd = || DemoModelError::Solver("K + alpha I is not positive definite".to_string());
    let n = k.nrows();
    if n < BLOCKED_FROM {
        return Ok(k.cholesky().ok_or_else(not_pd)?.solve(&y));
    }
    let cols = y.ncols();
    let mut l: Vec<f64> = k.data.into();
    if !super::cholesky::factor(&mut l, n) {
        return Err(not_pd());
    }
    let mut x: Vec<f64> = y.data.into();
    super::cholesky::solve(&l, n, &mut x);
    Ok(DMatrix::from_vec(n, cols, x))
}

/// p(a|s) from the regression outputs, as described at [`KernelRidge::probs`].
pub fn probs_from_outputs(f: &[f64]) -> Vec<f64> {
    match f.len() {
        0 => Vec::new(),
        1 => vec![1.0],
        2 => {
            let p0 = (0.5 + (f[0] - f[1]) / 2.0).clamp(0.0, 1.0);
            vec![p0, 1.0 - p0]
        }
        n => {
            let clipped: Vec<f64> = f.iter().map(|v| v.clamp(0.0, 1.0)).collect();
            let total: f64 = clipped.iter().sum();
            if total < VANISHING {
                vec![1.0 / n as f64; n]
            } else {
                clipped.iter().map(|v| v / total).collect()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_action_probabilities_follow_the_paper() {
        assert_eq!(
            probs_from_outputs(&[0.8, 0.2]),
            vec![0.8, 0.19999999999999996]
        );
        assert_eq!(probs_from_outputs(&[1.5, -0.4]), vec![1.0, 0.0]);
        assert_eq!(probs_from_outputs(&[0.0, 0.0]), vec![0.5, 0.5]);
    }

    #[test]
    fn many_action_probabilities_clip_renormalise_and_fall_back_to_uniform() {
        let p = probs_from_outputs(&[0.6, -0.2, 0.2]);
        assert!((p[0] - 0.75).abs() < 1e-15 && p[1] == 0.0 && (p[2] - 0.25).abs() < 1e-15);
        assert_eq!(probs_from_outputs(&[-0.1, 0.0, 1e-14]), vec![1.0 / 3.0; 3]);
        assert_eq!(probs_from_outputs(&[2.0, 3.0, -1.0]), vec![0.5, 0.5, 0.0]);
    }

    #[test]
    fn one_demo_is_solved_exactly() {
        // K = [1], so the dual coefficient is y / (1 + alpha) and f(x) at the demo is 1/1.1.
        let m = KernelRidge::fit(&[[0.0, 0.0]], &[1], 2).unwrap();
        let f = m.raw(&[0.0, 0.0]);
        assert_eq!(f[0], 0.0);
        assert!((f[1] - 1.0 / 1.1).abs() < 1e-15);
        let far = m.probs(&[100.0, 100.0]);
        assert_eq!(far, vec![0.5, 0.5]);
    }

    #[test]
    fn fit_reproduces_the_training_actions() {
        let states: Vec<[f64; 2]> = (0..20).map(|i| [i as f64 * 0.5 - 5.0, 0.0]).collect();
        let actions: Vec<usize> = states.iter().map(|s| usize::from(s[0] > 0.0)).collect();
        let m = KernelRidge::fit(&states, &actions, 2).unwrap();
        for (s, &a) in states.iter().zip(&actions) {
            assert!(
                m.probs(s)[a] > 0.5,
                "state {s:?} action {a}: {:?}",
                m.probs(s)
            );
        }
    }

    #[test]
    fn the_blocked_solve_of_many_demonstrations_matches_nalgebra_s() {
        let n = BLOCKED_FROM + 40;
        let states: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                [
                    ((i * 7919) % 997) as f64 / 50.0,
                    ((i * 104_729) % 991) as f64 / 50.0,
                ]
            })
            .collect();
        let actions: Vec<usize> = (0..n).map(|i| i % 3).collect();
        let m = KernelRidge::fit(&states, &actions, 3).unwrap();
        let k = DMatrix::from_fn(n, n, |i, j| {
            rbf(&states[i], &states[j]) + if i == j { ALPHA } else { 0.0 }
        });
        let y = DMatrix::from_fn(n, 3, |i, a| f64::from(u8::from(actions[i] == a)));
        let expected = k.cholesky().unwrap().solve(&y);
        for i in 0..n {
            for a in 0..3 {
                let got = m.dual_coef[i * 3 + a];
                assert!((got - expected[(i, a)]).abs() < 1e-8, "coef {i},{a}");
            }
        }
    }

    #[test]
    fn three_actions_far_from_the_data_are_uniform() {
        let m = KernelRidge::fit(&[[0.0], [1.0], [2.0]], &[0, 1, 2], 3).unwrap();
        assert_eq!(m.probs(&[1e3]), vec![1.0 / 3.0; 3]);
        let p = m.probs(&[0.0]);
        assert!(p[0] > p[1] && p[1] > p[2], "{p:?}");
        assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
