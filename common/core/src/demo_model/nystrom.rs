//! Kernel Ridge Regression on Nyström landmarks, for more demonstrations than the exact model
//! takes: the regression is restricted to the span of the kernel at `m` landmark states (the
//! "subset of regressors" form of Williams & Seeger's Nyström method), which are the first `m`
//! demonstrations. With `K_nm` the kernel between the n demonstrations and the landmarks,
//!
//! `β = (K_mn K_nm + α K_mm)⁻¹ K_mn Y`, `f(x) = k_m(x)ᵀ β`,
//!
//! so the model holds `m` states and `m × actions` coefficients whatever n is, a demonstration
//! adds `k k ᵀ` to an `m × m` sum (O(m²)), and a solve is O(m³). With n ≤ m every demonstration is
//! a landmark and the model is the exact KRR's, up to rounding. Its agreement with the exact model
//! against B is measured by `common/core/examples/nystrom_agreement.rs` (BENCHMARKS.md).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::krr::{KernelRidge, ALPHA};
use super::{check_demo, rbf, rbf_row, validate, DemoModelError};

/// The landmarks of the approximate model: its first demonstrations.
pub const LANDMARKS: usize = 512;

/// The most demonstrations the approximate model is fitted on (it keeps only its landmarks; the
/// limit keeps a run's `demos.jsonl` and its reading back within reason).
pub const MAX_APPROX_DEMOS: usize = 1_000_000;

/// Added to the diagonal of the system, relative to its mean diagonal: two equal landmark states
/// make `K_mm` singular; this splits their weight rather than failing.
const JITTER: f64 = 1e-10;

/// A fitted Nyström KRR: the regression over the kernel at the landmarks (a [`KernelRidge`]
/// whose states are the landmarks), and the demonstrations it was fitted on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NystromRidge {
    over_landmarks: KernelRidge,
    demos: usize,
}

impl NystromRidge {
    /// Fits the model on the demonstrations (pushed one at a time, then solved once).
    pub fn fit<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
    ) -> Result<NystromRidge, DemoModelError> {
        NystromFactor::fit(states, actions, num_actions)?.model()
    }

    pub fn num_actions(&self) -> usize {
        self.over_landmarks.num_actions()
    }

    pub fn state_dim(&self) -> usize {
        self.over_landmarks.state_dim()
    }

    pub fn num_demos(&self) -> usize {
        self.demos
    }

    /// The regression outputs at `s`, one per action.
    pub fn raw(&self, s: &[f64]) -> Vec<f64> {
        self.over_landmarks.raw(s)
    }

    /// p(a|s) from the outputs, as the exact KRR's.
    pub fn probs(&self, s: &[f64]) -> Vec<f64> {
        self.over_landmarks.probs(s)
    }
}

/// The sums a [`NystromRidge`] is solved from, grown one demonstration at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct NystromFactor {
    state_dim: usize,
    num_actions: usize,
    /// Landmark states so far (the first demonstrations), row-major, and their actions.
    landmarks: Vec<f64>,
    landmark_actions: Vec<usize>,
    /// `K_mm`, the kernel between the landmarks, `LANDMARKS × LANDMARKS` row-major.
    kmm: Vec<f64>,
    /// `K_mn K_nm`, `LANDMARKS × LANDMARKS` row-major, the rows and columns of landmarks to
    /// come still zero.
    gram: Vec<f64>,
    /// `K_mn Y`, `LANDMARKS × num_actions` row-major.
    rhs: Vec<f64>,
    demos: usize,
}

impl NystromFactor {
    /// An empty factor for states of `state_dim` values and `num_actions` actions.
    fn new(state_dim: usize, num_actions: usize) -> Self {
        Self {
            state_dim,
            num_actions,
            landmarks: Vec::with_capacity(LANDMARKS * state_dim),
            landmark_actions: Vec::with_capacity(LANDMARKS),
            kmm: vec![0.0; LANDMARKS * LANDMARKS],
            gram: vec![0.0; LANDMARKS * LANDMARKS],
            rhs: vec![0.0; LANDMARKS * num_actions],
            demos: 0,
        }
    }

    /// The factor of the demonstrations, pushed in order.
    pub fn fit<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
    ) -> Result<NystromFactor, DemoModelError> {
        let n = states.len();
        if actions.len() != n {
            return Err(DemoModelError::LengthMismatch {
                states: n,
                actions: actions.len(),
            });
        }
        if n > MAX_APPROX_DEMOS {
            return Err(DemoModelError::TooManyApproxDemos(n));
        }
        // The first demonstration sets the state's length; `push` checks every one.
        let (_, dim) = validate(&states[..n.min(1)], &actions[..n.min(1)], num_actions)?;
        let mut f = NystromFactor::new(dim, num_actions);
        for (s, &a) in states.iter().zip(actions) {
            f.push(s.as_ref(), a)?;
        }
        Ok(f)
    }

    /// Demonstrations pushed.
    pub fn len(&self) -> usize {
        self.demos
    }

    pub fn is_empty(&self) -> bool {
        self.demos == 0
    }

    fn num_landmarks(&self) -> usize {
        self.landmarks.len() / self.state_dim
    }

    /// Adds a demonstration: a landmark while there are fewer than [`LANDMARKS`] (its row and
    /// column of the sum over the demonstrations before it, which are all landmarks), then its
    /// `k kᵀ` and `k yᵀ`. A state or action the factor cannot take is refused and changes nothing.
    pub fn push(&mut self, state: &[f64], action: usize) -> Result<(), DemoModelError> {
        check_demo(self.demos, state, action, self.state_dim, self.num_actions)?;
        if self.demos + 1 > MAX_APPROX_DEMOS {
            return Err(DemoModelError::TooManyApproxDemos(self.demos + 1));
        }
        let d = self.state_dim;
        let m = self.num_landmarks();
        // The kernel between the landmarks and the new state (and itself, if it becomes one).
        let mut k = vec![0.0; m];
        rbf_row(state, &self.landmarks[..m * d], &mut k);
        if m < LANDMARKS {
            // Every demonstration so far is a landmark: the new landmark's entries of the sum
            // are over them.
            for (l, kl) in k.iter().enumerate() {
                self.kmm[m * LANDMARKS + l] = *kl;
                self.kmm[l * LANDMARKS + m] = *kl;
            }
            self.kmm[m * LANDMARKS + m] = rbf(state, state);
            for l in 0..m {
                let row = &self.kmm[l * LANDMARKS..l * LANDMARKS + m];
                let v: f64 = row.iter().zip(&k).map(|(a, b)| a * b).sum();
                self.gram[m * LANDMARKS + l] = v;
                self.gram[l * LANDMARKS + m] = v;
            }
            self.gram[m * LANDMARKS + m] = k.iter().map(|v| v * v).sum();
            for (kl, &a) in k.iter().zip(&self.landmark_actions) {
                self.rhs[m * self.num_actions + a] += kl;
            }
            self.landmarks.extend_from_slice(state);
            self.landmark_actions.push(action);
            k.push(self.kmm[m * LANDMARKS + m]);
        }
        for (i, ki) in k.iter().enumerate() {
            let row = &mut self.gram[i * LANDMARKS..i * LANDMARKS + k.len()];
            for (g, kj) in row.iter_mut().zip(&k) {
                *g += ki * kj;
            }
            self.rhs[i * self.num_actions + action] += ki;
        }
        self.demos += 1;
        Ok(())
    }

    /// The model solved from the sums: `(K_mn K_nm + α K_mm + δ I) β = K_mn Y` by Cholesky.
    pub fn model(&self) -> Result<NystromRidge, DemoModelError> {
        let (m, d, a) = (self.num_landmarks(), self.state_dim, self.num_actions);
        if m == 0 {
            return Err(DemoModelError::NotEnoughDemos);
        }
        let mut sys = DMatrix::<f64>::zeros(m, m);
        for i in 0..m {
            for j in 0..=i {
                let v = self.gram[i * LANDMARKS + j] + ALPHA * self.kmm[i * LANDMARKS + j];
                sys[(i, j)] = v;
                sys[(j, i)] = v;
            }
        }
        let mean_diag = (0..m).map(|i| sys[(i, i)]).sum::<f64>() / m as f64;
        for i in 0..m {
            sys[(i, i)] += JITTER * mean_diag;
        }
        let chol = sys.cholesky().ok_or_else(|| {
            DemoModelError::Solver("the Nyström system is not positive definite".into())
        })?;
        let rhs = DMatrix::from_row_slice(m, a, &self.rhs[..m * a]);
        let beta = chol.solve(&rhs);
        let mut coef = vec![0.0; m * a];
        for i in 0..m {
            for j in 0..a {
                coef[i * a + j] = beta[(i, j)];
            }
        }
        Ok(NystromRidge {
            over_landmarks: KernelRidge::over(d, a, self.landmarks.clone(), coef),
            demos: self.demos,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo_model::KernelRidge;

    /// States spread over a few units (the kernel's width is about 3), actions by a line.
    fn demos(n: usize, seed: u64) -> (Vec<[f64; 3]>, Vec<usize>) {
        let mut x = seed;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64) * 8.0 - 4.0
        };
        let states: Vec<[f64; 3]> = (0..n).map(|_| [next(), next(), next()]).collect();
        let actions = states
            .iter()
            .map(|s| usize::from(s[0] + 0.5 * s[1] > 0.0))
            .collect();
        (states, actions)
    }

    #[test]
    fn with_every_demonstration_a_landmark_it_is_the_exact_krr() {
        let (states, actions) = demos(200, 1);
        let exact = KernelRidge::fit(&states, &actions, 2).unwrap();
        let approx = NystromRidge::fit(&states, &actions, 2).unwrap();
        let (probe, _) = demos(50, 2);
        // Equal in exact arithmetic; the Nyström system, K (K + αI), is the worse conditioned
        // (the product of the two conditions), so the two agree to about 1e-5 here.
        for s in &probe {
            let (a, b) = (exact.raw(s), approx.raw(s));
            for (a, b) in a.iter().zip(&b) {
                assert!((a - b).abs() < 1e-4, "{a} {b}");
            }
        }
    }

    #[test]
    fn beyond_the_landmarks_it_agrees_with_the_exact_model_on_new_states() {
        let n = LANDMARKS * 3;
        let (states, actions) = demos(n, 3);
        let exact = KernelRidge::fit(&states, &actions, 2).unwrap();
        let approx = NystromRidge::fit(&states, &actions, 2).unwrap();
        assert_eq!(approx.num_demos(), n);
        let (probe, _) = demos(1000, 4);
        let greedy = |p: Vec<f64>| usize::from(p[1] > p[0]);
        let agree = probe
            .iter()
            .filter(|s| greedy(exact.probs(s.as_slice())) == greedy(approx.probs(s.as_slice())))
            .count();
        assert!(agree >= 980, "{agree} of 1000");
    }

    #[test]
    fn grown_a_demonstration_at_a_time_across_the_landmarks_it_is_the_fitted_one() {
        let n = LANDMARKS + 40;
        let (states, actions) = demos(n, 5);
        let mut grown = NystromFactor::fit(&states[..1], &actions[..1], 2).unwrap();
        for i in 1..n {
            grown.push(&states[i], actions[i]).unwrap();
            if [10, LANDMARKS - 1, LANDMARKS, n - 1].contains(&i) {
                let fitted = NystromFactor::fit(&states[..=i], &actions[..=i], 2).unwrap();
                assert_eq!(grown, fitted, "{} demonstrations", i + 1);
                assert_eq!(grown.model(), fitted.model());
            }
        }
    }

    #[test]
    fn bad_demonstrations_are_refused_and_equal_states_do_not_break_the_solve() {
        let mut f = NystromFactor::fit(&[[0.0, 0.0]], &[1], 2).unwrap();
        let before = f.clone();
        assert!(matches!(
            f.push(&[1.0], 0),
            Err(DemoModelError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            f.push(&[1.0, 2.0], 2),
            Err(DemoModelError::ActionOutOfRange { action: 2, .. })
        ));
        assert!(f.push(&[f64::NAN, 0.0], 0).is_err());
        assert_eq!(f, before);
        // The same state again with the other action: two equal landmarks, an even split.
        f.push(&[0.0, 0.0], 0).unwrap();
        let p = f.model().unwrap().probs(&[0.0, 0.0]);
        assert!((p[0] - 0.5).abs() < 1e-6, "{p:?}");
        assert!(matches!(
            NystromFactor::fit(&[[0.0]; 0], &[], 2),
            Err(DemoModelError::NotEnoughDemos)
        ));
    }
}
