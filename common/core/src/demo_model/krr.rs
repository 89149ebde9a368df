//! Kernel Ridge Regression on one-hot actions (paper section 3.4), as scikit-learn's
//! `KernelRidge(alpha=0.1, kernel='rbf', gamma=0.1)`: dual coefficients `(K + alpha I)^-1 Y` by
//! Cholesky, outputs `f(x) = k(x, X) dual_coef`.
//!
//! The Cholesky factor L is kept ([`KrrFactor`]) so that a new demonstration adds one row to it,
//! O(n²) instead of the O(n³) of a new factorisation. Every way of computing L — nalgebra's (up to
//! [`BLOCKED_FROM`] demonstrations), the blocked one of `cholesky.rs` (from there on, several times
//! faster on large matrices, BENCHMARKS.md), and a row at a time — subtracts the same products in
//! the same order, so a model grown one demonstration at a time is the model fitted on all of
//! them at once, bit for bit.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::lanes::{share, Lanes, Serial};
use super::substitution::{self, Rows};
use super::{check_demo, rbf, rbf_row, validate, DemoModelError, MAX_DEMOS};

/// The ridge penalty added to the kernel's diagonal.
pub const ALPHA: f64 = 0.1;

/// From this many demonstrations on, the kernel matrix is factored by the blocked Cholesky
/// (below it, by nalgebra's, whose numbers every run with fewer demonstrations keeps).
pub const BLOCKED_FROM: usize = 512;

/// Below this many demonstrations a fit runs on the caller's thread whatever lanes it is given:
/// on the 2-core benchmark machine a second lane saved nothing there (2,000 demonstrations:
/// 0.176 s on two threads, 0.174 s on one) and, its core shared, sometimes cost half again
/// (1,000: 0.063 s against 0.042 s; medians of one five-round sitting of `deploy/bench/core.sh`).
pub const LANES_FROM: usize = 2048;

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
        Ok(KrrFactor::fit(states, actions, num_actions)?.model())
    }

    /// The regression over the kernel at `states` (row-major) with these coefficients
    /// (row-major, `states × num_actions`): how the Nyström model answers, over its landmarks.
    pub(crate) fn over(
        state_dim: usize,
        num_actions: usize,
        states: Vec<f64>,
        dual_coef: Vec<f64>,
    ) -> KernelRidge {
        KernelRidge {
            state_dim,
            num_actions,
            states,
            dual_coef,
        }
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
        const CHUNK: usize = 64;
        let mut f = vec![0.0; self.num_actions];
        let mut k = [0.0; CHUNK];
        for (xs, coefs) in self
            .states
            .chunks(CHUNK * self.state_dim)
            .zip(self.dual_coef.chunks(CHUNK * self.num_actions))
        {
            let k = &mut k[..xs.len() / self.state_dim];
            rbf_row(s, xs, k);
            for (kx, coef) in k.iter().zip(coefs.chunks_exact(self.num_actions)) {
                for (fa, c) in f.iter_mut().zip(coef) {
                    *fa += kx * c;
                }
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

/// The square roots of `n` weights, each finite and ≥ 0.
fn square_roots(weights: &[f64], n: usize) -> Result<Vec<f64>, DemoModelError> {
    if weights.len() != n {
        return Err(DemoModelError::Weights(format!(
            "{} weights for {n} demonstrations",
            weights.len()
        )));
    }
    weights
        .iter()
        .map(|&w| match w.is_finite() && w >= 0.0 {
            true => Ok(w.sqrt()),
            false => Err(DemoModelError::Weights(format!(
                "a demonstration's weight is {w}: weights are finite and >= 0"
            ))),
        })
        .collect()
}

fn not_positive_definite() -> DemoModelError {
    DemoModelError::Solver("K + alpha I is not positive definite".to_string())
}

/// L of `S K S + alpha I` by nalgebra's Cholesky (below [`BLOCKED_FROM`] demonstrations), rows
/// up to the diagonal; `S` the diagonal of `sw`, the square roots of the weights.
fn small_factor(flat: &[f64], state_dim: usize, sw: &[f64]) -> Result<Vec<f64>, DemoModelError> {
    let n = flat.len() / state_dim;
    let row = |i: usize| &flat[i * state_dim..(i + 1) * state_dim];
    let mut k = DMatrix::<f64>::zeros(n, n);
    let mut kx = vec![0.0; n];
    for i in 0..n {
        rbf_row(row(i), &flat[..(i + 1) * state_dim], &mut kx[..=i]);
        for (j, &v) in kx[..=i].iter().enumerate() {
            let v = v * (sw[i] * sw[j]);
            k[(i, j)] = v;
            k[(j, i)] = v;
        }
        k[(i, i)] += ALPHA;
    }
    let full = k.cholesky().ok_or_else(not_positive_definite)?.l();
    Ok((0..n)
        .flat_map(|i| (0..=i).map(move |j| (i, j)))
        .map(|(i, j)| full[(i, j)])
        .collect())
}

/// L of `S K S + alpha I` by the blocked Cholesky, rows up to the diagonal: the kernel's lower
/// triangle built column by column (columns dealt to the lanes in turn), factored, then turned
/// into rows in the same buffer ([`rows_in_place`]), so that no second matrix is touched.
fn large_factor(
    flat: &[f64],
    state_dim: usize,
    sw: &[f64],
    lanes: &dyn Lanes,
) -> Result<Vec<f64>, DemoModelError> {
    let n = flat.len() / state_dim;
    let row = |i: usize| &flat[i * state_dim..(i + 1) * state_dim];
    let mut k = super::pages::zeroed(n * n);
    let mut columns: Vec<(usize, &mut [f64])> = k.chunks_mut(n).enumerate().collect();
    share(&mut columns, lanes, |lane| {
        for (j, col) in lane.iter_mut() {
            rbf_row(row(*j), &flat[*j * state_dim..], &mut col[*j..]);
            for (i, v) in col[*j..].iter_mut().enumerate() {
                *v *= sw[*j + i] * sw[*j];
            }
            col[*j] += ALPHA;
        }
    });
    if !super::cholesky::factor(&mut k, n, lanes) {
        return Err(not_positive_definite());
    }
    rows_in_place(&mut k, n);
    Ok(k)
}

/// The column-major lower triangle of an `n × n` matrix (`a[i + j * n]`, `i >= j`) as its rows up
/// to the diagonal, one after another (`a[i * (i + 1) / 2 + j]`), in the same buffer, truncated
/// to them. First the strict lower triangle is mirrored into the upper one in square tiles (so
/// that neither direction is walked across), which puts row i in column i's first `i + 1` values;
/// then the rows move to the front in order: row i's place ends before row i + 1's source starts.
fn rows_in_place(a: &mut Vec<f64>, n: usize) {
    const T: usize = 64;
    for jb in (0..n).step_by(T) {
        for ib in (jb..n).step_by(T) {
            for j in jb..(jb + T).min(n) {
                for i in ib.max(j + 1)..(ib + T).min(n) {
                    a[j + i * n] = a[i + j * n];
                }
            }
        }
    }
    for i in 1..n {
        a.copy_within(i * n..i * n + i + 1, i * (i + 1) / 2);
    }
    a.truncate(n * (n + 1) / 2);
    // The square's other half stays the buffer's capacity, its pages given back: rows pushed
    // later fill it (to about 1.4 n rows) without moving the factor.
    super::pages::release_spare(a);
}

/// The Cholesky factor L of `K + alpha I` over the demonstrations so far, with them: what a
/// [`KernelRidge`] is solved from, grown by one row per demonstration ([`KrrFactor::push`]).
#[derive(Debug, Clone, PartialEq)]
pub struct KrrFactor {
    state_dim: usize,
    num_actions: usize,
    /// Demonstrated states, row-major, `n * state_dim`.
    states: Vec<f64>,
    actions: Vec<usize>,
    /// L row by row: row i holds its `i + 1` values up to the diagonal.
    l: Vec<f64>,
    /// `L⁻¹ S Y`, row-major `n × actions`, Y the one-hot actions: the forward half of the solve
    /// for the model, grown with L (a new row of it is O(n) per action).
    w: Vec<f64>,
    /// The square roots of the demonstrations' weights (1 each unless weighted).
    sw: Vec<f64>,
}

impl KrrFactor {
    /// Factors the kernel matrix of the demonstrations (nalgebra's Cholesky below
    /// [`BLOCKED_FROM`] of them, the blocked one from there), on the caller's thread.
    pub fn fit<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
    ) -> Result<KrrFactor, DemoModelError> {
        KrrFactor::fit_on(states, actions, num_actions, &Serial)
    }

    /// [`KrrFactor::fit`], the large factorisations' work shared among `lanes` (the same bits).
    pub fn fit_on<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        num_actions: usize,
        lanes: &dyn Lanes,
    ) -> Result<KrrFactor, DemoModelError> {
        KrrFactor::fit_weighted(
            states,
            actions,
            &vec![1.0; actions.len()],
            num_actions,
            lanes,
        )
    }

    /// [`KrrFactor::fit_on`] with a weight ≥ 0 for each demonstration, as scikit-learn's
    /// `KernelRidge.fit(X, y, sample_weight)`: `S K S + αI` factored, `S` the weights' square
    /// roots, for dual coefficients `S (S K S + αI)⁻¹ S Y`. Weights of 1 give
    /// [`KrrFactor::fit_on`]'s bits.
    pub fn fit_weighted<S: AsRef<[f64]>>(
        states: &[S],
        actions: &[usize],
        weights: &[f64],
        num_actions: usize,
        lanes: &dyn Lanes,
    ) -> Result<KrrFactor, DemoModelError> {
        let (flat, state_dim) = validate(states, actions, num_actions)?;
        let sw = square_roots(weights, actions.len())?;
        let n = actions.len();
        let lanes = if n < LANES_FROM { &Serial } else { lanes };
        let l = if n < BLOCKED_FROM {
            small_factor(&flat, state_dim, &sw)?
        } else {
            large_factor(&flat, state_dim, &sw, lanes)?
        };
        tracing::debug!(
            demos = n,
            state_dim,
            num_actions,
            "factored the kernel matrix"
        );
        let mut f = KrrFactor {
            state_dim,
            num_actions,
            states: flat,
            actions: Vec::with_capacity(n),
            l,
            w: Vec::with_capacity(n * num_actions),
            sw: Vec::with_capacity(n),
        };
        for (&a, &s) in actions.iter().zip(&sw) {
            f.sw.push(s);
            f.forward_row(a);
            f.actions.push(a);
        }
        Ok(f)
    }

    /// Appends row `n` of `w = L⁻¹ S Y` for the demonstration of `action` whose row of L and
    /// weight are the last: `w_n = (s_n y_n − Σ_j l_nj w_j) / l_nn`, the products subtracted in
    /// order of j.
    fn forward_row(&mut self, action: usize) {
        let (n, m) = (self.w.len() / self.num_actions, self.num_actions);
        let row = Rows(&self.l).row(n);
        for a in 0..m {
            let mut v = if a == action { self.sw[n] } else { 0.0 };
            for (l, w) in row[..n].iter().zip(self.w.iter().skip(a).step_by(m)) {
                v -= l * w;
            }
            self.w.push(v / row[n]);
        }
    }

    /// Demonstrations factored.
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// Row `i` of L up to the diagonal.
    fn row(&self, i: usize) -> &[f64] {
        Rows(&self.l).row(i)
    }

    /// Adds a demonstration: one new row of L, by forward substitution against the rows before
    /// it (O(n²)). A state or action the factor cannot take is refused and changes nothing.
    pub fn push(&mut self, state: &[f64], action: usize) -> Result<(), DemoModelError> {
        self.push_on(state, action, &Serial)
    }

    /// [`KrrFactor::push`], the forward substitution split between two lanes that run at once
    /// when `lanes` has them (the same bits).
    pub fn push_on(
        &mut self,
        state: &[f64],
        action: usize,
        lanes: &dyn Lanes,
    ) -> Result<(), DemoModelError> {
        self.push_weighted(state, action, 1.0, lanes)
    }

    /// [`KrrFactor::push_on`] with the demonstration's weight (≥ 0; see
    /// [`KrrFactor::fit_weighted`]): the same factor as fitting them all with their weights.
    pub fn push_weighted(
        &mut self,
        state: &[f64],
        action: usize,
        weight: f64,
        lanes: &dyn Lanes,
    ) -> Result<(), DemoModelError> {
        let n = self.len();
        check_demo(n, state, action, self.state_dim, self.num_actions)?;
        if n + 1 > MAX_DEMOS {
            return Err(DemoModelError::TooManyDemos(n + 1));
        }
        let s = square_roots(&[weight], 1)?[0];
        let mut kx = vec![0.0; n];
        rbf_row(state, &self.states, &mut kx);
        for (k, &si) in kx.iter_mut().zip(&self.sw) {
            *k *= si * s;
        }
        let mut z = substitution::forward(Rows(&self.l), &kx, lanes);
        let mut d = rbf(state, state) * (s * s) + ALPHA;
        for zp in &z {
            d -= zp * zp;
        }
        if d <= 0.0 || d.is_nan() {
            return Err(not_positive_definite());
        }
        z.push(d.sqrt());
        self.l.extend_from_slice(&z);
        self.sw.push(s);
        self.forward_row(action);
        self.states.extend_from_slice(state);
        self.actions.push(action);
        Ok(())
    }

    /// The regression on the demonstrations factored: `L Lᵀ C = Y` solved for the dual
    /// coefficients, O(n²) per action: by nalgebra below [`BLOCKED_FROM`] demonstrations (the
    /// numbers every smaller run keeps), from there on by back substitution from the kept
    /// `L⁻¹ Y` (`KrrFactor::back_solve`).
    pub fn model(&self) -> KernelRidge {
        self.model_on(&Serial)
    }

    /// [`KrrFactor::model`], the back substitution split between two lanes that run at once
    /// when `lanes` has them (the same bits).
    pub fn model_on(&self, lanes: &dyn Lanes) -> KernelRidge {
        let (n, m) = (self.len(), self.num_actions);
        if n >= BLOCKED_FROM {
            return self.with_coef(self.back_solve(lanes));
        }
        let mut coef = vec![0.0; n * m];
        for (i, &a) in self.actions.iter().enumerate() {
            coef[i * m + a] = self.sw[i];
        }
        let mut l = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for (j, v) in self.row(i).iter().enumerate() {
                l[(i, j)] = *v;
            }
        }
        let mut y = DMatrix::from_row_slice(n, m, &coef);
        l.solve_lower_triangular_unchecked_mut(&mut y);
        l.ad_solve_lower_triangular_unchecked_mut(&mut y);
        for i in 0..n {
            for a in 0..m {
                coef[i * m + a] = y[(i, a)] * self.sw[i];
            }
        }
        self.with_coef(coef)
    }

    fn with_coef(&self, dual_coef: Vec<f64>) -> KernelRidge {
        KernelRidge::over(
            self.state_dim,
            self.num_actions,
            self.states.clone(),
            dual_coef,
        )
    }

    /// `Lᵀ X = W` for the dual coefficients X (row-major `n × actions`), W = L⁻¹ Y being kept
    /// ([`KrrFactor::forward_row`]): back substitution from the last row up, each action's
    /// column apart ([`substitution::back`]); every coefficient takes the same products in the
    /// same order as a row-major back substitution.
    fn back_solve(&self, lanes: &dyn Lanes) -> Vec<f64> {
        let (n, m) = (self.len(), self.num_actions);
        let mut cols = vec![0.0; n * m];
        for (i, w) in self.w.chunks_exact(m).enumerate() {
            for (a, v) in w.iter().enumerate() {
                cols[a * n + i] = *v;
            }
        }
        substitution::back(Rows(&self.l), &mut cols, n, lanes);
        let mut x = vec![0.0; n * m];
        for (a, col) in cols.chunks_exact(n).enumerate() {
            for (i, v) in col.iter().enumerate() {
                x[i * m + a] = *v * self.sw[i];
            }
        }
        x
    }
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
    use super::super::lanes::Backwards;
    use super::*;

    #[test]
    fn rows_in_place_reads_the_lower_triangle_out_row_by_row() {
        for n in [0, 1, 2, 7, 64, 65, 130] {
            // Lower values name their place; the upper triangle holds what must not be read.
            let mut a: Vec<f64> = (0..n * n)
                .map(|p| {
                    let (i, j) = (p % n, p / n);
                    if i >= j {
                        (i * 1000 + j) as f64
                    } else {
                        -1.0
                    }
                })
                .collect();
            rows_in_place(&mut a, n);
            let want: Vec<f64> = (0..n)
                .flat_map(|i| (0..=i).map(move |j| (i * 1000 + j) as f64))
                .collect();
            assert_eq!(a, want, "n = {n}");
        }
    }

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
    fn a_factor_fitted_on_lanes_is_the_one_fitted_in_turn() {
        let (states, actions) = scattered(LANES_FROM + super::super::cholesky::BLOCK + 30);
        let serial = KrrFactor::fit(&states, &actions, 3).unwrap();
        let on_lanes = KrrFactor::fit_on(&states, &actions, 3, &Backwards(2)).unwrap();
        assert!(on_lanes == serial);
    }

    /// `n` scattered two-dimensional demonstrations of three actions.
    fn scattered(n: usize) -> (Vec<[f64; 2]>, Vec<usize>) {
        let states = (0..n)
            .map(|i| {
                [
                    ((i * 7919) % 997) as f64 / 50.0,
                    ((i * 104_729) % 991) as f64 / 50.0,
                ]
            })
            .collect();
        (states, (0..n).map(|i| (i * 7) % 3).collect())
    }

    #[test]
    fn a_model_grown_a_demonstration_at_a_time_is_the_fitted_one_bit_for_bit() {
        // Across the switch to the blocked factorisation, and past several of its blocks.
        let n = BLOCKED_FROM + 2 * super::super::cholesky::BLOCK + 7;
        let (states, actions) = scattered(n);
        let mut grown = KrrFactor::fit(&states[..3], &actions[..3], 3).unwrap();
        for i in 3..n {
            grown.push(&states[i], actions[i]).unwrap();
            if [10, BLOCKED_FROM - 1, BLOCKED_FROM, n - 1].contains(&i) {
                let fitted = KrrFactor::fit(&states[..=i], &actions[..=i], 3).unwrap();
                assert_eq!(grown, fitted, "the factor of {} demonstrations", i + 1);
                assert_eq!(grown.model(), fitted.model(), "{} demonstrations", i + 1);
            }
        }
    }

    #[test]
    fn a_fitted_factor_takes_new_rows_without_moving() {
        let n = BLOCKED_FROM + 40;
        let (states, actions) = scattered(n);
        let mut grown = KrrFactor::fit(&states[..n - 3], &actions[..n - 3], 3).unwrap();
        let start = grown.l.as_ptr();
        for i in n - 3..n {
            grown.push(&states[i], actions[i]).unwrap();
        }
        assert_eq!(
            grown.l.as_ptr(),
            start,
            "new rows fill the fit's spare capacity"
        );
        assert!(grown == KrrFactor::fit(&states, &actions, 3).unwrap());
    }

    #[test]
    fn the_solve_on_the_kept_rows_agrees_with_the_column_solve() {
        let n = BLOCKED_FROM + 9;
        let (states, actions) = scattered(n);
        let f = KrrFactor::fit(&states, &actions, 3).unwrap();
        let mut l = vec![0.0; n * n];
        for i in 0..n {
            for (j, v) in f.row(i).iter().enumerate() {
                l[i + j * n] = *v;
            }
        }
        let mut y = vec![0.0; n * 3];
        for (i, &a) in actions.iter().enumerate() {
            y[i + a * n] = 1.0;
        }
        super::super::cholesky::solve(&l, n, &mut y);
        let m = f.model();
        for i in 0..n {
            for a in 0..3 {
                let (got, want) = (m.dual_coef[i * 3 + a], y[i + a * n]);
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                    "{i},{a}: {got} {want}"
                );
            }
        }
    }

    #[test]
    fn the_back_substitution_is_the_row_major_one_to_the_bit() {
        for m in [2, 3] {
            let n = BLOCKED_FROM + 37;
            let (states, actions) = scattered(n);
            let actions: Vec<usize> = actions.iter().map(|a| a % m).collect();
            let f = KrrFactor::fit(&states, &actions, m).unwrap();
            // Row-major, one row of L at a time, each product subtracted as it comes.
            let mut x = f.w.clone();
            for i in (0..n).rev() {
                let row = f.row(i);
                for a in 0..m {
                    x[i * m + a] /= row[i];
                }
                for k in 0..i {
                    for a in 0..m {
                        x[k * m + a] -= row[k] * x[i * m + a];
                    }
                }
            }
            let got = f.back_solve(&Serial);
            let same = got.iter().zip(&x).all(|(g, w)| g.to_bits() == w.to_bits());
            assert!(same, "{m} actions");
        }
    }

    #[test]
    fn a_demonstration_the_factor_cannot_take_is_refused_and_changes_nothing() {
        let mut f = KrrFactor::fit(&[[0.0, 0.0]], &[1], 2).unwrap();
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
        // The same state again: K + alpha I stays positive definite (the ridge).
        assert_eq!(f, before);
        f.push(&[0.0, 0.0], 0).unwrap();
        assert_eq!(f.len(), 2);
        // Two equal states with opposite actions: each output is 1 / (2 + alpha).
        let out = f.model().raw(&[0.0, 0.0]);
        assert!(
            (out[0] - 1.0 / 2.1).abs() < 1e-15 && (out[1] - 1.0 / 2.1).abs() < 1e-15,
            "{out:?}"
        );
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
