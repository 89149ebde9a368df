//! The demonstration model of the paper (section 3.4): p(a|s) learned from the demonstrated
//! (state, action) pairs, by Kernel Ridge Regression or by a kernel SVM with Platt scaling.
//!
//! The model is renewed whenever a demonstration arrives (KRR by one more row of its kept
//! Cholesky factor, [`krr::KrrFactor`]; the SVM fitted anew); it is published from the expert
//! process to the actors as postcard bytes, so every fitted model is plain data
//! (`Serialize`/`Deserialize`, no solver state) and exactly reproducible: the same demonstrations
//! always give the same model, bit for bit, however it was reached.
//!
//! Both models use the RBF kernel `k(x, y) = exp(-gamma |x - y|^2)` with `gamma = 0.1`, as the
//! paper (and the scikit-learn reference `kernel_models.json`) does.

mod cholesky;
pub mod krr;
pub mod lanes;
pub mod nystrom;
mod pages;
pub mod smo;
mod substitution;
pub mod svm;

pub use krr::KernelRidge;
pub use nystrom::NystromRidge;
pub use svm::{KernelSvm, Platt};

use serde::{Deserialize, Serialize};

use krr::KrrFactor;
use lanes::{Lanes, Serial};

/// The RBF kernel width used by both models, `k(x, y) = exp(-GAMMA |x - y|^2)`.
pub const GAMMA: f64 = 0.1;

/// The most demonstrations a model is fitted on. A fit holds the `n × n` kernel matrix
/// (10,000 demonstrations: 800 MB; KRR keeps half of it, its factor, for the rest of the run);
/// many more would exhaust memory (50,000: 20 GB).
pub const MAX_DEMOS: usize = 10_000;

/// The most actions a model gives probabilities for (the environments have at most 4).
pub const MAX_ACTIONS: usize = 1024;

/// Which demonstration model to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DemoModelKind {
    /// Kernel Ridge Regression on one-hot actions (RBF gamma 0.1, alpha 0.1).
    Krr,
    /// Kernel SVM (C = 10, RBF gamma 0.1) with Platt-scaled probabilities; two actions only.
    Svm,
    /// KRR on the first 512 demonstrations as Nyström landmarks, for up to 1,000,000
    /// demonstrations (`nystrom.rs`).
    Nystrom,
}

impl DemoModelKind {
    /// The lowercase name used in configs and on the command line (`krr`, `svm`).
    pub fn name(self) -> &'static str {
        match self {
            DemoModelKind::Krr => "krr",
            DemoModelKind::Svm => "svm",
            DemoModelKind::Nystrom => "nystrom",
        }
    }
}

impl std::fmt::Display for DemoModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for DemoModelKind {
    type Err = DemoModelError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "krr" => Ok(DemoModelKind::Krr),
            "svm" => Ok(DemoModelKind::Svm),
            "nystrom" => Ok(DemoModelKind::Nystrom),
            _ => Err(DemoModelError::UnknownKind(s.to_string())),
        }
    }
}

/// Why a demonstration model could not be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DemoModelError {
    #[error("no demonstrations: a demonstration model needs at least one (state, action) pair")]
    NotEnoughDemos,
    #[error("{states} states but {actions} actions: every demonstration needs both")]
    LengthMismatch { states: usize, actions: usize },
    #[error("demonstration {row}: the state is empty")]
    EmptyState { row: usize },
    #[error("demonstration {row}: the state has {found} components, expected {expected} (as demonstration 0)")]
    DimensionMismatch {
        row: usize,
        expected: usize,
        found: usize,
    },
    #[error("demonstration {row}: state component {column} is {value} (NaN or infinite)")]
    NonFinite {
        row: usize,
        column: usize,
        value: f64,
    },
    #[error(
        "demonstration {row}: action {action} is outside the action space {{0..{num_actions}}}"
    )]
    ActionOutOfRange {
        row: usize,
        action: usize,
        num_actions: usize,
    },
    #[error("the number of actions must be at least 1, got {0}")]
    NoActions(usize),
    #[error("{0} actions: a demonstration model handles at most {MAX_ACTIONS}")]
    TooManyActions(usize),
    #[error("{0} demonstrations: a demonstration model is fitted on at most {MAX_DEMOS} (its kernel matrix holds n × n numbers)")]
    TooManyDemos(usize),
    #[error("{0} demonstrations: the Nyström model is fitted on at most {max}", max = nystrom::MAX_APPROX_DEMOS)]
    TooManyApproxDemos(usize),
    #[error("unsupported: {0}")]
    Unsupported(String),
    #[error("{0}")]
    Weights(String),
    #[error("the SVM solver failed: {0}")]
    Solver(String),
    #[error("unknown demonstration model kind {0:?} (expected \"krr\", \"svm\" or \"nystrom\")")]
    UnknownKind(String),
}

/// A fitted demonstration model: p(a|s) for every state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DemoModel {
    Krr(KernelRidge),
    Svm(KernelSvm),
    Nystrom(NystromRidge),
}

impl DemoModel {
    /// Fits a model of `kind` on the demonstrations (`states[i]`, `actions[i]`), actions in
    /// `0..num_actions`.
    ///
    /// Errors on no demonstrations, states of different or zero length, NaN or infinite state
    /// components, actions out of range, and (SVM only) more than two actions.
    pub fn fit<S: AsRef<[f64]>>(
        kind: DemoModelKind,
        states: &[S],
        actions: &[usize],
        num_actions: usize,
    ) -> Result<DemoModel, DemoModelError> {
        DemoModel::fit_on(kind, states, actions, num_actions, &Serial)
    }

    /// [`DemoModel::fit`] with the large fits' independent work shared among `lanes` (the same
    /// model, bit for bit).
    pub fn fit_on<S: AsRef<[f64]>>(
        kind: DemoModelKind,
        states: &[S],
        actions: &[usize],
        num_actions: usize,
        lanes: &dyn Lanes,
    ) -> Result<DemoModel, DemoModelError> {
        match kind {
            DemoModelKind::Krr => KrrFactor::fit_on(states, actions, num_actions, lanes)
                .map(|f| DemoModel::Krr(f.model_on(lanes))),
            DemoModelKind::Svm => {
                KernelSvm::fit_on(states, actions, num_actions, lanes).map(DemoModel::Svm)
            }
            DemoModelKind::Nystrom => {
                NystromRidge::fit(states, actions, num_actions).map(DemoModel::Nystrom)
            }
        }
    }

    /// [`DemoModel::fit_on`] with a weight ≥ 0 for each demonstration, as a run fits it: KRR
    /// weighs them ([`KrrFactor::fit_weighted`]); the SVM and the Nyström model do not.
    pub fn fit_weighted_on<S: AsRef<[f64]>>(
        kind: DemoModelKind,
        (states, actions, weights): (&[S], &[usize], &[f64]),
        num_actions: usize,
        lanes: &dyn Lanes,
    ) -> Result<DemoModel, DemoModelError> {
        match kind {
            DemoModelKind::Krr => {
                KrrFactor::fit_weighted(states, actions, weights, num_actions, lanes)
                    .map(|f| DemoModel::Krr(f.model_on(lanes)))
            }
            _ => DemoModel::fit_on(kind, states, actions, num_actions, lanes),
        }
    }

    pub fn kind(&self) -> DemoModelKind {
        match self {
            DemoModel::Krr(_) => DemoModelKind::Krr,
            DemoModel::Svm(_) => DemoModelKind::Svm,
            DemoModel::Nystrom(_) => DemoModelKind::Nystrom,
        }
    }

    /// Number of actions the model gives probabilities for.
    pub fn num_actions(&self) -> usize {
        match self {
            DemoModel::Krr(m) => m.num_actions(),
            DemoModel::Svm(m) => m.num_actions(),
            DemoModel::Nystrom(m) => m.num_actions(),
        }
    }

    /// Length of the states the model was fitted on.
    pub fn state_dim(&self) -> usize {
        match self {
            DemoModel::Krr(m) => m.state_dim(),
            DemoModel::Svm(m) => m.state_dim(),
            DemoModel::Nystrom(m) => m.state_dim(),
        }
    }

    /// Number of demonstrations the model was fitted on.
    pub fn num_demos(&self) -> usize {
        match self {
            DemoModel::Krr(m) => m.num_demos(),
            DemoModel::Svm(m) => m.num_demos(),
            DemoModel::Nystrom(m) => m.num_demos(),
        }
    }

    /// The model's raw outputs at `s`: the KRR regression outputs, one per action, or the SVM
    /// decision value (one value, positive means action 1).
    ///
    /// # Panics
    /// If `s.len() != self.state_dim()`; check untrusted input with [`DemoModel::check_state`].
    pub fn raw(&self, s: &[f64]) -> Vec<f64> {
        match self {
            DemoModel::Krr(m) => m.raw(s),
            DemoModel::Svm(m) => vec![m.decision_value(s)],
            DemoModel::Nystrom(m) => m.raw(s),
        }
    }

    /// p(a|s) for every action: each in [0, 1], summing to 1.
    ///
    /// # Panics
    /// If `s.len() != self.state_dim()`; check untrusted input with [`DemoModel::check_state`].
    pub fn probs(&self, s: &[f64]) -> Vec<f64> {
        match self {
            DemoModel::Krr(m) => m.probs(s),
            DemoModel::Svm(m) => m.probs(s),
            DemoModel::Nystrom(m) => m.probs(s),
        }
    }

    /// p(a|s) for one action.
    ///
    /// # Panics
    /// If `a >= self.num_actions()` or `s.len() != self.state_dim()`.
    pub fn prob(&self, s: &[f64], a: usize) -> f64 {
        self.probs(s)[a]
    }

    /// Checks that `s` can be queried: the right length and finite components.
    pub fn check_state(&self, s: &[f64]) -> Result<(), DemoModelError> {
        check_row(0, s, self.state_dim())
    }
}

/// The RBF kernel `exp(-GAMMA |x - y|^2)`.
pub(crate) fn rbf(x: &[f64], y: &[f64]) -> f64 {
    let d2: f64 = x.iter().zip(y).map(|(a, b)| (a - b) * (a - b)).sum();
    crate::math::exp(-GAMMA * d2)
}

/// `out[t] = rbf(x, y_t)` for the rows `y_t` of `flat` (row-major, `x.len()` values each):
/// the bits of [`rbf`] (whose arguments commute to the bit), the exponentials taken four at a
/// time ([`crate::math::exp_in_place`]).
pub(crate) fn rbf_row(x: &[f64], flat: &[f64], out: &mut [f64]) {
    let d = x.len();
    assert_eq!(
        flat.len(),
        out.len() * d,
        "rows and outputs differ in number"
    );
    for (t, o) in out.iter_mut().enumerate() {
        let y = &flat[t * d..(t + 1) * d];
        let d2: f64 = x.iter().zip(y).map(|(a, b)| (a - b) * (a - b)).sum();
        *o = -GAMMA * d2;
    }
    crate::math::exp_in_place(out);
}

fn check_row(row: usize, s: &[f64], dim: usize) -> Result<(), DemoModelError> {
    if s.len() != dim {
        return Err(DemoModelError::DimensionMismatch {
            row,
            expected: dim,
            found: s.len(),
        });
    }
    if let Some((column, &value)) = s.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(DemoModelError::NonFinite { row, column, value });
    }
    Ok(())
}

/// Checks demonstration `row`: its state (`dim` finite values) and its action (below
/// `num_actions`).
pub(crate) fn check_demo(
    row: usize,
    s: &[f64],
    action: usize,
    dim: usize,
    num_actions: usize,
) -> Result<(), DemoModelError> {
    check_row(row, s, dim)?;
    if action >= num_actions {
        return Err(DemoModelError::ActionOutOfRange {
            row,
            action,
            num_actions,
        });
    }
    Ok(())
}

/// Validates demonstrations and returns them as one row-major matrix, with the state dimension.
pub(crate) fn validate<S: AsRef<[f64]>>(
    states: &[S],
    actions: &[usize],
    num_actions: usize,
) -> Result<(Vec<f64>, usize), DemoModelError> {
    if states.len() != actions.len() {
        return Err(DemoModelError::LengthMismatch {
            states: states.len(),
            actions: actions.len(),
        });
    }
    if states.is_empty() {
        return Err(DemoModelError::NotEnoughDemos);
    }
    if num_actions == 0 {
        return Err(DemoModelError::NoActions(num_actions));
    }
    if num_actions > MAX_ACTIONS {
        return Err(DemoModelError::TooManyActions(num_actions));
    }
    if states.len() > MAX_DEMOS {
        return Err(DemoModelError::TooManyDemos(states.len()));
    }
    let dim = states[0].as_ref().len();
    if dim == 0 {
        return Err(DemoModelError::EmptyState { row: 0 });
    }
    let mut flat = Vec::with_capacity(states.len() * dim);
    for (row, (s, &action)) in states.iter().zip(actions).enumerate() {
        let s = s.as_ref();
        check_demo(row, s, action, dim, num_actions)?;
        flat.extend_from_slice(s);
    }
    Ok((flat, dim))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kind_parses_and_prints() {
        assert_eq!("krr".parse::<DemoModelKind>(), Ok(DemoModelKind::Krr));
        assert_eq!("SVM".parse::<DemoModelKind>(), Ok(DemoModelKind::Svm));
        assert!(matches!(
            "gp".parse::<DemoModelKind>(),
            Err(DemoModelError::UnknownKind(_))
        ));
        assert_eq!(DemoModelKind::Svm.to_string(), "svm");
    }

    #[test]
    fn validation_names_the_row() {
        let states = vec![vec![0.0, 1.0], vec![0.0, f64::NAN]];
        let err = validate(&states, &[0, 1], 2).unwrap_err();
        assert!(
            matches!(
                err,
                DemoModelError::NonFinite {
                    row: 1,
                    column: 1,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("demonstration 1"));

        let states = vec![vec![0.0, 1.0], vec![0.0]];
        let err = validate(&states, &[0, 1], 2).unwrap_err();
        assert_eq!(
            err,
            DemoModelError::DimensionMismatch {
                row: 1,
                expected: 2,
                found: 1
            }
        );

        let states = vec![vec![0.0], vec![1.0]];
        let err = validate(&states, &[0, 2], 2).unwrap_err();
        assert_eq!(
            err,
            DemoModelError::ActionOutOfRange {
                row: 1,
                action: 2,
                num_actions: 2
            }
        );

        let empty: Vec<Vec<f64>> = vec![];
        assert_eq!(
            validate(&empty, &[], 2).unwrap_err(),
            DemoModelError::NotEnoughDemos
        );
        assert_eq!(
            validate(&[vec![1.0]], &[0, 1], 2).unwrap_err(),
            DemoModelError::LengthMismatch {
                states: 1,
                actions: 2
            }
        );
        assert_eq!(
            validate(&[vec![1.0]], &[0], 0).unwrap_err(),
            DemoModelError::NoActions(0)
        );
    }

    #[test]
    fn sizes_beyond_the_limits_are_refused_before_anything_is_allocated() {
        // 10^11 actions would ask for an 800 GB matrix of targets.
        let e = validate(&[vec![1.0]], &[0], 100_000_000_000).unwrap_err();
        assert_eq!(e, DemoModelError::TooManyActions(100_000_000_000));
        assert_eq!(
            e.to_string(),
            "100000000000 actions: a demonstration model handles at most 1024"
        );
        assert!(validate(&[vec![1.0]], &[0], MAX_ACTIONS).is_ok());
        let states = vec![vec![0.0]; MAX_DEMOS + 1];
        let actions = vec![0; MAX_DEMOS + 1];
        let e = DemoModel::fit(DemoModelKind::Krr, &states, &actions, 2).unwrap_err();
        assert_eq!(e, DemoModelError::TooManyDemos(MAX_DEMOS + 1));
        assert!(e.to_string().contains("at most 10000"), "{e}");
    }

    #[test]
    fn validate_flattens_row_major() {
        let (flat, dim) = validate(&[[1.0, 2.0], [3.0, 4.0]], &[0, 1], 2).unwrap();
        assert_eq!(dim, 2);
        assert_eq!(flat, vec![1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn a_row_of_the_kernel_has_the_bits_of_rbf_either_way_round() {
        let mut r = crate::rng::seeded(3);
        let flat: Vec<f64> = (0..4 * 203)
            .map(|i| (rand::Rng::random::<f64>(&mut r) - 0.5) * [0.1, 6.0, 40.0][i % 3])
            .collect();
        let x = [0.3, -1.7, 25.0, 0.01];
        let mut row = vec![0.0; 203];
        rbf_row(&x, &flat, &mut row);
        for (t, (y, k)) in flat.chunks_exact(4).zip(&row).enumerate() {
            assert_eq!(k.to_bits(), rbf(&x, y).to_bits(), "row {t}");
            assert_eq!(k.to_bits(), rbf(y, &x).to_bits(), "row {t}, swapped");
        }
        // Far states give zeros (the scalar path of the exponential) and the same bits.
        rbf_row(&[1e3; 4], &flat, &mut row);
        assert!(row.iter().all(|&k| k == 0.0));
    }

    #[test]
    fn rbf_matches_its_definition() {
        assert_eq!(rbf(&[1.0, 2.0], &[1.0, 2.0]), 1.0);
        let expected = (-0.1f64 * (1.0 + 4.0)).exp();
        assert!((rbf(&[0.0, 0.0], &[1.0, 2.0]) - expected).abs() < 1e-15);
    }
}
