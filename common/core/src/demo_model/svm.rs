//! Kernel SVM demonstration model (paper section 3.4): scikit-learn's
//! `SVC(C=10, kernel='rbf', gamma=0.1, probability=True)` for two actions, with libsvm's SMO
//! solver (the core's own, [`super::smo`]) and Platt scaling fitted on cross-validated decision
//! values.
//!
//! Conventions:
//! - the decision value `f(s) = sum_i coef_i k(s, x_i) - rho` is positive for action 1, negative
//!   for action 0 (scikit-learn's `decision_function` for classes `[0, 1]`);
//! - `p(1|s) = 1 / (1 + exp(A f(s) + B))`, with `(A, B)` fitted by Newton's method with
//!   backtracking (Lin, Lin & Weng 2007, the algorithm libsvm uses) on out-of-fold decision values
//!   of a deterministic, stratified 5-fold split (seeded with `rng::seeded(0)`). As in
//!   scikit-learn, the sigmoid is fitted on other models' outputs than the final one, so
//!   `p(1|s) > 0.5` can disagree with `f(s) > 0` near the boundary.
//!
//! Degenerate demonstrations:
//! - every demonstration chose the same action: no SVM can be fitted; the model gives p = 1 to that
//!   action everywhere, and its decision value is the constant +1 (action 1) or -1 (action 0), as
//!   libsvm does for a one-class fold;
//! - an action demonstrated only once: cross-validation would train folds without that action, so
//!   the sigmoid is fitted on the final model's in-sample decision values instead.

use std::sync::OnceLock;

use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};

use super::lanes::{queue, Lanes, Serial};
use super::smo::KernelRows;
use super::{rbf, rbf_row, smo, validate, DemoModelError};
use crate::{math, rng};

/// The SVM's penalty on margin violations.
pub const C: f64 = 10.0;
/// Folds of the cross-validation whose decision values the sigmoid is fitted on.
pub const PLATT_FOLDS: usize = 5;
/// Stopping tolerance of the SMO solver (maximal violating pair), tighter than libsvm's 1e-3.
pub const SOLVER_EPS: f64 = 1e-7;
/// The SMO solver's iteration limit (libsvm's).
pub const SOLVER_MAX_ITER: usize = 10_000_000;
/// Seed of the shuffle that assigns demonstrations to folds.
pub const FOLD_SEED: u64 = 0;

/// Platt's sigmoid `p(positive | f) = 1 / (1 + exp(a f + b))`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Platt {
    pub a: f64,
    pub b: f64,
}

/// Platt's objective: the cross-entropy of the sigmoid `(a, b)` against `targets`, computed
/// without overflow.
fn platt_objective(decision: &[f64], targets: &[f64], a: f64, b: f64) -> f64 {
    decision
        .iter()
        .zip(targets)
        .map(|(&f, &t)| {
            let z = a * f + b;
            if z >= 0.0 {
                t * z + math::ln_1p(math::exp(-z))
            } else {
                (t - 1.0) * z + math::ln_1p(math::exp(z))
            }
        })
        .sum()
}

/// A gradient `(g1, g2)` and a Hessian `(h11, h22, h21)`.
type Derivatives = ((f64, f64), (f64, f64, f64));

/// The gradient and Hessian (plus `sigma` on the diagonal) of [`platt_objective`] at `(a, b)`.
fn platt_derivatives(decision: &[f64], targets: &[f64], a: f64, b: f64, sigma: f64) -> Derivatives {
    let (mut h11, mut h22, mut h21) = (sigma, sigma, 0.0);
    let (mut g1, mut g2) = (0.0, 0.0);
    for (&f, &t) in decision.iter().zip(targets) {
        let z = a * f + b;
        let (p, q) = if z >= 0.0 {
            let e = math::exp(-z);
            (e / (1.0 + e), 1.0 / (1.0 + e))
        } else {
            let e = math::exp(z);
            (1.0 / (1.0 + e), e / (1.0 + e))
        };
        let d2 = p * q;
        h11 += f * f * d2;
        h22 += d2;
        h21 += f * d2;
        let d1 = t - p;
        g1 += f * d1;
        g2 += d1;
    }
    ((g1, g2), (h11, h22, h21))
}

impl Platt {
    /// Fits `(a, b)` to decision values and labels (`true` = positive) by Newton's method with
    /// backtracking line search, minimising the cross-entropy against Platt's regularised targets
    /// `(N+ + 1) / (N+ + 2)` and `1 / (N- + 2)` (Lin, Lin & Weng 2007, Algorithm 1).
    pub fn fit(decision: &[f64], positive: &[bool]) -> Platt {
        const MAX_ITER: usize = 100;
        const MIN_STEP: f64 = 1e-10;
        const SIGMA: f64 = 1e-12; // added to the Hessian's diagonal
        const EPS: f64 = 1e-5; // gradient tolerance

        let n_pos = positive.iter().filter(|&&p| p).count() as f64;
        let n_neg = positive.len() as f64 - n_pos;
        let hi = (n_pos + 1.0) / (n_pos + 2.0);
        let lo = 1.0 / (n_neg + 2.0);
        let targets: Vec<f64> = positive.iter().map(|&p| if p { hi } else { lo }).collect();

        let objective = |a: f64, b: f64| platt_objective(decision, &targets, a, b);

        let mut a = 0.0;
        let mut b = math::ln((n_neg + 1.0) / (n_pos + 1.0));
        let mut fval = objective(a, b);
        let mut iter = 0;
        while iter < MAX_ITER {
            let ((g1, g2), (h11, h22, h21)) = platt_derivatives(decision, &targets, a, b, SIGMA);
            if g1.abs() < EPS && g2.abs() < EPS {
                break;
            }
            // Newton direction, then backtracking until the sufficient-decrease condition holds.
            let det = h11 * h22 - h21 * h21;
            let da = -(h22 * g1 - h21 * g2) / det;
            let db = -(-h21 * g1 + h11 * g2) / det;
            let gd = g1 * da + g2 * db;
            let mut step = 1.0;
            while step >= MIN_STEP {
                let (na, nb) = (a + step * da, b + step * db);
                let nf = objective(na, nb);
                if nf < fval + 1e-4 * step * gd {
                    (a, b, fval) = (na, nb, nf);
                    break;
                }
                step /= 2.0;
            }
            if step < MIN_STEP {
                tracing::debug!(
                    iter,
                    a,
                    b,
                    "Platt scaling: line search failed, keeping the last sigmoid"
                );
                break;
            }
            iter += 1;
        }
        if iter == MAX_ITER {
            tracing::debug!(
                a,
                b,
                "Platt scaling: reached the maximal number of iterations"
            );
        }
        Platt { a, b }
    }

    /// `p(positive | f)`.
    pub fn prob(&self, f: f64) -> f64 {
        let z = self.a * f + self.b;
        if z >= 0.0 {
            let e = math::exp(-z);
            e / (1.0 + e)
        } else {
            1.0 / (1.0 + math::exp(z))
        }
    }
}

/// A fitted two-class SVM in plain data: `f(s) = sum_i coef_i k(s, support_i) - rho`, positive
/// for action 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Svc {
    /// Support vectors, row-major, `coef.len() * state_dim`.
    support: Vec<f64>,
    /// `alpha_i y_i` of each support vector (y = +1 for action 1).
    coef: Vec<f64>,
    rho: f64,
}

/// The RBF kernel of the demonstrations a row at a time: computed when a solve first reads it
/// (on whichever lane), then kept for the final SVM and every fold's. `rbf` is symmetric to the
/// bit, so a row is also the column.
struct Gram<'a> {
    flat: &'a [f64],
    state_dim: usize,
    rows: Vec<OnceLock<Box<[f64]>>>,
}

impl<'a> Gram<'a> {
    fn new(flat: &'a [f64], state_dim: usize) -> Gram<'a> {
        let n = flat.len() / state_dim;
        Gram {
            flat,
            state_dim,
            rows: (0..n).map(|_| OnceLock::new()).collect(),
        }
    }

    fn state(&self, i: usize) -> &[f64] {
        &self.flat[i * self.state_dim..(i + 1) * self.state_dim]
    }

    /// `K(x_i, x_j)`, from row j.
    fn at(&self, i: usize, j: usize) -> f64 {
        self.row(j)[i]
    }
}

impl KernelRows for Gram<'_> {
    fn row(&self, r: usize) -> &[f64] {
        self.rows[r].get_or_init(|| {
            let mut row = vec![0.0; self.rows.len()].into_boxed_slice();
            rbf_row(self.state(r), self.flat, &mut row);
            row
        })
    }

    fn diag(&self, r: usize) -> f64 {
        rbf(self.state(r), self.state(r))
    }
}

/// An SVM fitted on some of the demonstrations, with the rows its support vectors are.
struct FoldFit {
    svc: Svc,
    support_rows: Vec<usize>,
}

impl FoldFit {
    /// The decision value at demonstration `i`, from the Gram matrix: the same sum, in the same
    /// order, as [`Svc::decision_value`] of its state.
    fn decision_at(&self, gram: &Gram, i: usize) -> f64 {
        let sum: f64 = self
            .support_rows
            .iter()
            .zip(&self.svc.coef)
            .map(|(&j, c)| c * gram.at(i, j))
            .sum();
        sum - self.svc.rho
    }
}

impl Svc {
    /// Solves the C-SVC dual on the rows `idx` of `flat` (row-major, `state_dim` wide) with the
    /// core's SMO ([`super::smo`]), their kernel taken from `gram`. Both labels must be present
    /// among `idx`.
    fn fit(
        gram: &Gram,
        flat: &[f64],
        state_dim: usize,
        idx: &[usize],
        positive: &[bool],
    ) -> Result<FoldFit, DemoModelError> {
        let row = |i: usize| &flat[i * state_dim..(i + 1) * state_dim];
        let labels: Vec<bool> = idx.iter().map(|&i| positive[i]).collect();
        let dual = smo::solve_on(gram, idx, &labels, C, SOLVER_EPS, SOLVER_MAX_ITER);
        if !dual.rho.is_finite() || dual.coef.iter().any(|c| !c.is_finite()) {
            return Err(DemoModelError::Solver(format!(
                "the SMO solver ended with a non-finite solution after {} iterations",
                dual.iterations
            )));
        }
        tracing::trace!(iterations = dual.iterations, rho = dual.rho, "SMO solved");

        let mut support = Vec::new();
        let mut support_rows = Vec::new();
        let mut coef = Vec::new();
        for (&i, &c) in idx.iter().zip(&dual.coef) {
            if c != 0.0 {
                support.extend_from_slice(row(i));
                support_rows.push(i);
                coef.push(c);
            }
        }
        let svc = Svc {
            support,
            coef,
            rho: dual.rho,
        };
        Ok(FoldFit { svc, support_rows })
    }

    fn decision_value(&self, s: &[f64]) -> f64 {
        let mut k = vec![0.0; self.coef.len()];
        rbf_row(s, &self.support, &mut k);
        let sum: f64 = k.iter().zip(&self.coef).map(|(kx, c)| c * kx).sum();
        sum - self.rho
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
enum SvmFit {
    /// Every demonstration chose `action`: p(action|s) = 1 everywhere.
    SingleAction { action: usize },
    /// Both actions were demonstrated.
    TwoActions { svc: Svc, platt: Platt },
}

/// A fitted kernel SVM with Platt-scaled probabilities, for two actions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KernelSvm {
    state_dim: usize,
    num_demos: usize,
    fit: SvmFit,
}

impl KernelSvm {
    /// Fits the SVM (action 1 positive) and the Platt sigmoid; see the module documentation for
    /// the degenerate cases. More than two actions is [`DemoModelError::Unsupported`].
    pub fn fit<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
    ) -> Result<KernelSvm, DemoModelError> {
        KernelSvm::fit_on(states, actions, num_actions, &Serial)
    }

    /// [`KernelSvm::fit`], the six independent solves (the final SVM's and the five folds')
    /// shared among `lanes` (the same model, bit for bit).
    pub fn fit_on<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
        lanes: &dyn Lanes,
    ) -> Result<KernelSvm, DemoModelError> {
        let (flat, state_dim) = validate(states, actions, num_actions)?;
        if num_actions != 2 {
            return Err(DemoModelError::Unsupported(format!(
                "the SVM demonstration model handles exactly 2 actions, got {num_actions}; use the KRR model"
            )));
        }
        let num_demos = actions.len();
        let positive: Vec<bool> = actions.iter().map(|&a| a == 1).collect();
        let n_pos = positive.iter().filter(|&&p| p).count();
        let n_neg = num_demos - n_pos;
        if n_pos == 0 || n_neg == 0 {
            let action = usize::from(n_pos > 0);
            tracing::debug!(
                num_demos,
                action,
                "SVM: one action demonstrated, p = 1 for it"
            );
            return Ok(KernelSvm {
                state_dim,
                num_demos,
                fit: SvmFit::SingleAction { action },
            });
        }

        let gram = Gram::new(&flat, state_dim);
        let cross_validated = n_pos.min(n_neg) >= 2;
        let (fitted, decision) = if cross_validated {
            fit_with_folds(&gram, &flat, state_dim, &positive, lanes)?
        } else {
            tracing::debug!(
                n_pos,
                n_neg,
                "SVM: an action demonstrated once, Platt fitted in-sample"
            );
            let all: Vec<usize> = (0..num_demos).collect();
            let fitted = Svc::fit(&gram, &flat, state_dim, &all, &positive)?;
            let decision = all.iter().map(|&i| fitted.decision_at(&gram, i)).collect();
            (fitted, decision)
        };
        let svc = fitted.svc;
        let platt = Platt::fit(&decision, &positive);
        tracing::debug!(
            num_demos,
            support = svc.coef.len(),
            a = platt.a,
            b = platt.b,
            "fitted kernel SVM"
        );
        Ok(KernelSvm {
            state_dim,
            num_demos,
            fit: SvmFit::TwoActions { svc, platt },
        })
    }

    pub fn num_actions(&self) -> usize {
        2
    }

    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    pub fn num_demos(&self) -> usize {
        self.num_demos
    }

    /// Number of support vectors (0 when a single action was demonstrated).
    pub fn num_support(&self) -> usize {
        match &self.fit {
            SvmFit::SingleAction { .. } => 0,
            SvmFit::TwoActions { svc, .. } => svc.coef.len(),
        }
    }

    /// The Platt sigmoid, if both actions were demonstrated.
    pub fn platt(&self) -> Option<Platt> {
        match &self.fit {
            SvmFit::SingleAction { .. } => None,
            SvmFit::TwoActions { platt, .. } => Some(*platt),
        }
    }

    /// The decision value at `s`: positive means action 1.
    ///
    /// # Panics
    /// If `s.len() != self.state_dim()`.
    pub fn decision_value(&self, s: &[f64]) -> f64 {
        assert_eq!(
            s.len(),
            self.state_dim,
            "state of length {} queried, model fitted on length {}",
            s.len(),
            self.state_dim
        );
        match &self.fit {
            SvmFit::SingleAction { action } => {
                if *action == 1 {
                    1.0
                } else {
                    -1.0
                }
            }
            SvmFit::TwoActions { svc, .. } => svc.decision_value(s),
        }
    }

    /// `[p(0|s), p(1|s)]`.
    ///
    /// # Panics
    /// If `s.len() != self.state_dim()`.
    pub fn probs(&self, s: &[f64]) -> Vec<f64> {
        let p1 = match &self.fit {
            SvmFit::SingleAction { action } => *action as f64,
            SvmFit::TwoActions { platt, .. } => platt.prob(self.decision_value(s)),
        };
        vec![1.0 - p1, p1]
    }
}

/// Assigns every demonstration to one of [`PLATT_FOLDS`] folds: each label's demonstrations are
/// shuffled (seeded with [`FOLD_SEED`]) and dealt in turn, so the folds are stratified and every
/// training split holds both labels when each label occurs at least twice.
pub fn stratified_folds(positive: &[bool]) -> Vec<usize> {
    let mut rng = rng::seeded(FOLD_SEED);
    let mut fold = vec![0; positive.len()];
    let mut dealt = 0;
    for label in [true, false] {
        let mut members: Vec<usize> = (0..positive.len())
            .filter(|&i| positive[i] == label)
            .collect();
        members.shuffle(&mut rng);
        for i in members {
            fold[i] = dealt % PLATT_FOLDS;
            dealt += 1;
        }
    }
    fold
}

/// The SVM on every demonstration, and the out-of-fold decision values (for each fold, an SVM
/// fitted on the other folds evaluates it): six independent solves of unequal length, which the
/// lanes take in turn as they finish.
fn fit_with_folds(
    gram: &Gram,
    flat: &[f64],
    state_dim: usize,
    positive: &[bool],
    lanes: &dyn Lanes,
) -> Result<(FoldFit, Vec<f64>), DemoModelError> {
    let n = positive.len();
    let fold = stratified_folds(positive);
    // Job 0 trains on every row; job k + 1 on all but fold k.
    type Job = (Vec<usize>, Option<Result<FoldFit, DemoModelError>>);
    let mut jobs: Vec<Job> = (0..=PLATT_FOLDS)
        .map(|job| {
            let train = (0..n).filter(|&i| job == 0 || fold[i] != job - 1).collect();
            (train, None)
        })
        .collect();
    // The final SVM's job, the longest, first; the lanes then take the folds as they finish.
    queue(&mut jobs, lanes, |(train, out)| {
        *out = Some(Svc::fit(gram, flat, state_dim, train, positive));
    });
    let mut fits = jobs.into_iter().map(|(_, out)| out.expect("every job ran"));
    let fitted = fits.next().expect("the final SVM's job")?;
    let mut decision = vec![0.0; n];
    for (k, fit) in fits.enumerate() {
        let fit = fit?;
        for i in (0..n).filter(|&i| fold[i] == k) {
            decision[i] = fit.decision_at(gram, i);
        }
    }
    Ok((fitted, decision))
}

#[cfg(test)]
mod tests {
    use super::super::lanes::Backwards;
    use super::*;

    #[test]
    fn platt_recovers_a_known_sigmoid() {
        // Labels drawn from p = 1/(1 + exp(-2 f)): the fit must find a near -2, b near 0.
        let mut r = rng::seeded(3);
        let decision: Vec<f64> = (0..4000).map(|i| (i as f64 / 4000.0) * 6.0 - 3.0).collect();
        let positive: Vec<bool> = decision
            .iter()
            .map(|&f| rand::Rng::random::<f64>(&mut r) < 1.0 / (1.0 + (-2.0 * f).exp()))
            .collect();
        let platt = Platt::fit(&decision, &positive);
        assert!((platt.a + 2.0).abs() < 0.2, "{platt:?}");
        assert!(platt.b.abs() < 0.15, "{platt:?}");
        assert!((platt.prob(0.0) - 0.5).abs() < 0.05);
        assert!(platt.prob(3.0) > 0.99 && platt.prob(-3.0) < 0.01);
    }

    #[test]
    fn platt_on_separable_values_stays_finite() {
        // Separable data: Platt's targets (2/3, 1/3 here) keep the sigmoid from diverging.
        let platt = Platt::fit(&[-1.0, 1.0], &[false, true]);
        assert!(platt.a.is_finite() && platt.a < 0.0, "{platt:?}");
        assert!(
            (platt.prob(1.0) - 2.0 / 3.0).abs() < 1e-4,
            "{}",
            platt.prob(1.0)
        );
        assert!(
            (platt.prob(-1.0) - 1.0 / 3.0).abs() < 1e-4,
            "{}",
            platt.prob(-1.0)
        );
    }

    #[test]
    fn folds_are_stratified_and_deterministic() {
        let positive: Vec<bool> = (0..23).map(|i| i % 3 == 0).collect();
        let fold = stratified_folds(&positive);
        assert_eq!(fold, stratified_folds(&positive));
        for k in 0..PLATT_FOLDS {
            let pos = (0..23).filter(|&i| fold[i] == k && positive[i]).count();
            let neg = (0..23).filter(|&i| fold[i] == k && !positive[i]).count();
            // 8 positives and 15 negatives over 5 folds.
            assert!((1..=2).contains(&pos), "fold {k}: {pos} positives");
            assert_eq!(neg, 3, "fold {k}");
        }
    }

    #[test]
    fn the_svm_fitted_on_lanes_is_the_one_fitted_in_turn() {
        let mut rng = rng::seeded(8);
        let states: Vec<[f64; 2]> = (0..90)
            .map(|_| std::array::from_fn(|_| rand::Rng::random_range(&mut rng, -2.0..2.0)))
            .collect();
        let actions: Vec<usize> = states
            .iter()
            .map(|s| usize::from(s[0] * s[1] > 0.1))
            .collect();
        let serial = KernelSvm::fit(&states, &actions, 2).unwrap();
        for width in [2, 4] {
            let on_lanes = KernelSvm::fit_on(&states, &actions, 2, &Backwards(width)).unwrap();
            assert_eq!(on_lanes, serial, "{width} lanes");
        }
        assert!(serial.platt().is_some() && serial.num_support() > 0);
    }

    #[test]
    fn the_gram_matrix_gives_the_decision_values_of_the_states_to_the_bit() {
        let mut rng = rng::seeded(5);
        let states: Vec<Vec<f64>> = (0..60)
            .map(|_| {
                (0..4)
                    .map(|_| rand::Rng::random_range(&mut rng, -2.0..2.0))
                    .collect()
            })
            .collect();
        let positive: Vec<bool> = states.iter().map(|s| s[0] + 0.5 * s[1] > 0.0).collect();
        let flat: Vec<f64> = states.concat();
        let gram = Gram::new(&flat, 4);
        for i in 0..60 {
            for j in 0..60 {
                assert_eq!(
                    gram.at(i, j).to_bits(),
                    rbf(&states[i], &states[j]).to_bits()
                );
            }
        }
        let train: Vec<usize> = (0..60).filter(|i| i % 3 != 0).collect();
        let fitted = Svc::fit(&gram, &flat, 4, &train, &positive).unwrap();
        for (i, s) in states.iter().enumerate() {
            let from_state = fitted.svc.decision_value(s);
            assert_eq!(fitted.decision_at(&gram, i).to_bits(), from_state.to_bits());
        }
    }

    #[test]
    fn separates_a_line() {
        let states: Vec<[f64; 1]> = (0..30).map(|i| [i as f64 * 0.4 - 6.0]).collect();
        let actions: Vec<usize> = states.iter().map(|s| usize::from(s[0] > 0.0)).collect();
        let m = KernelSvm::fit(&states, &actions, 2).unwrap();
        assert!(m.decision_value(&[-3.0]) < -0.5 && m.decision_value(&[3.0]) > 0.5);
        assert!(m.probs(&[-3.0])[0] > 0.8 && m.probs(&[3.0])[1] > 0.8);
        assert!(
            m.num_support() > 0 && m.num_support() < 30,
            "{}",
            m.num_support()
        );
    }
}
