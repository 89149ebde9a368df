//! The C-SVC dual solved by sequential minimal optimisation, as libsvm (and so scikit-learn's
//! `SVC`) solves it: the working-set selection by second-order information of Fan, Chen & Lin
//! (2005, "WSS 2"), libsvm's clipped two-variable update, and its rule for the offset `rho`.
//!
//! Written here rather than taken from a crate so that every number comes from the core's own
//! arithmetic: the RBF kernel through `crate::math::exp`, the same bits on every CPU (a
//! crate calling the platform's `exp` would not give them). libsvm's shrinking: every
//! [`SHRINK_EVERY`] iterations the variables at a bound that the maximal violating pair says will
//! stay there leave the active set, which the working-pair search and the gradient update then
//! cover alone; `grad_bar` (the gradient's part from variables at C) rebuilds their gradient
//! when the active set is optimal, and all come back once the violation is within ten times the
//! tolerance, as in libsvm. The kernel's rows come from [`KernelRows`], which the SVM computes
//! when a working pair first needs them and keeps for the final SVM and every fold's (libsvm's
//! kernel cache, with room for every row); the columns the updates need are read as rows.
//!
//! The problem, with `y_i = ±1`, `Q_ij = y_i y_j K(x_i, x_j)`:
//! minimise `½ αᵀQα − Σ α_i` subject to `0 ≤ α_i ≤ C` and `Σ y_i α_i = 0`.
//! The decision value is `f(x) = Σ y_i α_i K(x_i, x) − rho`.

/// A solved dual: `coef_i = y_i α_i` for every training row (0 for non-support rows), and `rho`.
#[derive(Debug, Clone, PartialEq)]
pub struct Dual {
    pub coef: Vec<f64>,
    pub rho: f64,
    /// Iterations the solver took.
    pub iterations: usize,
    /// The most variables shrunk out of the active set at once.
    pub shrunk_peak: usize,
}

/// libsvm's floor on the curvature of a working pair.
const TAU: f64 = 1e-12;

/// The curvature of the objective along a pair, `K_ii + K_jj − 2 K_ij`, floored at [`TAU`].
fn curvature(kii: f64, kjj: f64, kij: f64) -> f64 {
    let a = kii + kjj - 2.0 * kij;
    if a > 0.0 {
        a
    } else {
        TAU
    }
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86;

/// The best candidate of a search kept in lanes (position p in lane `p % W`), each lane's the
/// last position that attained it; [`LaneBest::finish`] gives what one pass over the positions
/// in order, keeping the last of equals, would have ended with.
struct LaneBest<const W: usize> {
    value: [f64; W],
    at: [usize; W],
}

impl<const W: usize> LaneBest<W> {
    fn new(worst: f64) -> LaneBest<W> {
        LaneBest {
            value: [worst; W],
            at: [usize::MAX; W],
        }
    }

    fn offer(&mut self, lane: usize, p: usize, take: bool, v: f64) {
        if take {
            self.value[lane] = v;
            self.at[lane] = p;
        }
    }

    /// The best over the lanes by `better` (strict), the latest position among equals; None
    /// when no lane has a candidate.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    fn finish(&self, better: impl Fn(f64, f64) -> bool) -> Option<(f64, usize)> {
        let mut best: Option<(f64, usize)> = None;
        for (&v, &at) in self.value.iter().zip(&self.at) {
            if at == usize::MAX {
                continue;
            }
            best = match best {
                Some((b, bat)) if better(b, v) || (!better(v, b) && bat > at) => Some((b, bat)),
                _ => Some((v, at)),
            };
        }
        best
    }
}

/// The variable in I_up with the largest −y_t G_t (the last position on ties) and that value;
/// None when I_up is empty.
fn max_violation(a: &Active) -> Option<(f64, usize)> {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return x86::max_violation(a).finish(|x, y| x > y);
    }
    max_violation_portable(a)
}

fn max_violation_portable(a: &Active) -> Option<(f64, usize)> {
    let mut best = LaneBest::<1>::new(f64::NEG_INFINITY);
    max_violation_from(a, 0, &mut best);
    (best.at[0] != usize::MAX).then_some((best.value[0], best.at[0]))
}

/// The search of [`max_violation`] over the positions from `from` on, position p in lane
/// `p % W` of `best` (the portable loop, and the wide loops' tail).
fn max_violation_from<const W: usize>(a: &Active, from: usize, best: &mut LaneBest<W>) {
    for p in from..a.len() {
        let (l, v) = (p % W, -a.y[p] * a.grad[p]);
        best.offer(l, p, a.up[p] && v >= best.value[l], v);
    }
}

/// For the first variable of a pair (its violation `gmax`, `K_ii` and kernel row), over I_low:
/// the largest y_t G_t, and the position whose pair decreases the objective most, `−b² /
/// curvature` with `b = gmax + y_t G_t > 0` (the last on ties; `usize::MAX` when none does).
fn best_partner(a: &Active, gmax: f64, di: f64, ki: &[f64]) -> (f64, usize) {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        let (gmax2, best) = x86::best_partner(a, gmax, di, ki);
        return (
            gmax2,
            best.finish(|x, y| x < y).map_or(usize::MAX, |(_, j)| j),
        );
    }
    best_partner_portable(a, gmax, di, ki)
}

fn best_partner_portable(a: &Active, gmax: f64, di: f64, ki: &[f64]) -> (f64, usize) {
    let mut gmax2 = f64::NEG_INFINITY;
    let mut best = LaneBest::<1>::new(f64::INFINITY);
    best_partner_from(a, 0, (gmax, di, ki), &mut best, &mut gmax2);
    (gmax2, best.at[0])
}

/// The search of [`best_partner`] over the positions from `from` on, for the first variable
/// `(gmax, K_ii, its kernel row)`, position p in lane `p % W` of `best`, the largest y G into
/// `gmax2` (the portable loop, and the wide loops' tail).
fn best_partner_from<const W: usize>(
    a: &Active,
    from: usize,
    (gmax, di, ki): (f64, f64, &[f64]),
    best: &mut LaneBest<W>,
    gmax2: &mut f64,
) {
    for p in from..a.len() {
        if !a.low[p] {
            continue;
        }
        let yg = a.y[p] * a.grad[p];
        if yg >= *gmax2 {
            *gmax2 = yg;
        }
        let b = gmax + yg;
        if b > 0.0 {
            let (l, gain) = (p % W, -(b * b) / curvature(di, a.diag[p], ki[a.row[p]]));
            best.offer(l, p, gain <= best.value[l], gain);
        }
    }
}

/// G += y (y_i K_i Δα_i + y_j K_j Δα_j) on the active set, for the pair's two variables given
/// as (y, kernel row, Δα).
fn move_gradient(a: &mut Active, i: (f64, &[f64], f64), j: (f64, &[f64], f64)) {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return x86::move_gradient(a, i, j);
    }
    move_gradient_portable(a, i, j)
}

fn move_gradient_portable(a: &mut Active, i: (f64, &[f64], f64), j: (f64, &[f64], f64)) {
    let ((yi, ki, di), (yj, kj, dj)) = (i, j);
    for ((g, &y), &r) in a.grad.iter_mut().zip(&a.y).zip(&a.row) {
        *g += y * (yi * ki[r] * di + yj * kj[r] * dj);
    }
}

/// Rows of a symmetric kernel matrix, given on demand.
pub trait KernelRows: Sync {
    /// Row `r` (its column too).
    fn row(&self, r: usize) -> &[f64];
    /// `K(x_r, x_r)`.
    fn diag(&self, r: usize) -> f64;
}

/// A whole kernel matrix: row-major, `n × n`.
pub struct Dense<'k> {
    pub k: &'k [f64],
    pub n: usize,
}

impl KernelRows for Dense<'_> {
    fn row(&self, r: usize) -> &[f64] {
        &self.k[r * self.n..(r + 1) * self.n]
    }
    fn diag(&self, r: usize) -> f64 {
        self.k[r * self.n + r]
    }
}

/// Solves the C-SVC dual for the kernel matrix `k` (row-major, `n × n`, symmetric) and labels
/// `positive` (`y = +1` when true), to the stopping tolerance `eps` on the maximal violating pair
/// (libsvm's `-e`), in at most `max_iter` iterations (then it stops where it is, as libsvm does).
pub fn solve(k: &[f64], positive: &[bool], c: f64, eps: f64, max_iter: usize) -> Dual {
    let n = positive.len();
    assert_eq!(k.len(), n * n, "the kernel matrix is n × n");
    let rows: Vec<usize> = (0..n).collect();
    solve_on(&Dense { k, n }, &rows, positive, c, eps, max_iter)
}

/// [`solve`] on the rows `rows` of the kernel `k`: the problem of those rows, in their order,
/// `positive` giving their labels.
pub fn solve_on(
    k: &dyn KernelRows,
    rows: &[usize],
    positive: &[bool],
    c: f64,
    eps: f64,
    max_iter: usize,
) -> Dual {
    let n = positive.len();
    assert_eq!(rows.len(), n, "one label per row");
    let problem = Problem {
        k,
        rows,
        n,
        diag: rows.iter().map(|&r| k.diag(r)).collect(),
        y: positive
            .iter()
            .map(|&p| if p { 1.0 } else { -1.0 })
            .collect(),
        c,
    };
    let mut st = SolverState {
        alpha: vec![0.0; n],
        // The objective's gradient Qα − e, at α = 0.
        grad: vec![-1.0; n],
        grad_bar: vec![0.0; n],
        active: Active::default(),
        unshrunk: false,
    };
    problem.activate(&mut st, (0..n).collect());
    let (mut iterations, mut shrunk_peak) = (0, 0);
    let mut counter = n.min(SHRINK_EVERY) + 1;
    while iterations < max_iter {
        counter -= 1;
        if counter == 0 {
            counter = n.min(SHRINK_EVERY);
            problem.shrink(&mut st, eps);
            shrunk_peak = shrunk_peak.max(n - st.active.len());
        }
        let pair = match problem.working_pair(&st, eps) {
            Some(pair) => pair,
            None => {
                // Optimal on the active set: on every variable?
                problem.reconstruct_gradient(&mut st);
                let Some(pair) = problem.working_pair(&st, eps) else {
                    break;
                };
                counter = 1;
                pair
            }
        };
        iterations += 1;
        problem.step(&mut st, pair);
    }
    if iterations == max_iter {
        tracing::debug!(max_iter, "SMO: reached the maximal number of iterations");
    }
    problem.reconstruct_gradient(&mut st);
    st.write_back();
    let rho = problem.rho(&st.alpha, &st.grad);
    let coef = st
        .alpha
        .iter()
        .zip(&problem.y)
        .map(|(a, y)| a * y)
        .collect();
    Dual {
        coef,
        rho,
        iterations,
        shrunk_peak,
    }
}

/// Iterations between two shrinkings (libsvm's; fewer variables than this: their number).
pub const SHRINK_EVERY: usize = 1000;

/// The solver's variables: α, the gradient, `grad_bar` (for each variable,
/// `Σ_{j: α_j = C} C Q_ij`), and the active set with the gradient of its variables.
struct SolverState {
    alpha: Vec<f64>,
    /// The gradient of every variable; an active variable's is [`Active::grad`]'s, written back
    /// here before the active set changes ([`SolverState::write_back`]).
    grad: Vec<f64>,
    grad_bar: Vec<f64>,
    active: Active,
    /// Whether every variable came back once the violation was near the tolerance.
    unshrunk: bool,
}

/// The active set in ascending order, what the working-pair search and the gradient update
/// read of each of its variables laid out side by side (position p, not the variable's
/// index), so that both walk contiguous arrays.
#[derive(Default, Clone)]
struct Active {
    /// The variables.
    t: Vec<usize>,
    /// Their rows of the kernel.
    row: Vec<usize>,
    y: Vec<f64>,
    diag: Vec<f64>,
    grad: Vec<f64>,
    /// Whether each is in I_up, in I_low (kept with α).
    up: Vec<bool>,
    low: Vec<bool>,
    /// One more than the largest of `row` (0 when empty): kernel rows at least this long can
    /// be read at every active row.
    row_bound: usize,
}

impl Active {
    fn len(&self) -> usize {
        self.t.len()
    }
}

impl SolverState {
    /// The active variables' gradient written back to `grad`.
    fn write_back(&mut self) {
        for (&t, &g) in self.active.t.iter().zip(&self.active.grad) {
            self.grad[t] = g;
        }
    }
}

/// The dual's data: the kernel matrix of its rows, the labels `y = ±1` and the box `[0, C]`.
struct Problem<'k> {
    k: &'k dyn KernelRows,
    /// The problem's rows of it.
    rows: &'k [usize],
    n: usize,
    /// `K_tt`, kept apart: read at every candidate of every working pair.
    diag: Vec<f64>,
    y: Vec<f64>,
    c: f64,
}

impl Problem<'_> {
    fn kij(&self, i: usize, j: usize) -> f64 {
        self.row(i)[self.rows[j]]
    }

    /// Row `i` of the whole kernel matrix (its column too: the matrix is symmetric), to be read
    /// at the problem's rows.
    fn row(&self, i: usize) -> &[f64] {
        self.k.row(self.rows[i])
    }

    /// Whether α_t may move up along y_t (the set I_up).
    fn up(&self, t: usize, a: f64) -> bool {
        if self.y[t] > 0.0 {
            a < self.c
        } else {
            a > 0.0
        }
    }

    /// Whether α_t may move down along y_t (the set I_low).
    fn low(&self, t: usize, a: f64) -> bool {
        if self.y[t] > 0.0 {
            a > 0.0
        } else {
            a < self.c
        }
    }

    /// The active set `list` (ascending), its arrays gathered from the state's.
    fn activate(&self, st: &mut SolverState, list: Vec<usize>) {
        let a = &mut st.active;
        a.row = list.iter().map(|&t| self.rows[t]).collect();
        a.y = list.iter().map(|&t| self.y[t]).collect();
        a.diag = list.iter().map(|&t| self.diag[t]).collect();
        a.grad = list.iter().map(|&t| st.grad[t]).collect();
        a.up = list.iter().map(|&t| self.up(t, st.alpha[t])).collect();
        a.low = list.iter().map(|&t| self.low(t, st.alpha[t])).collect();
        a.row_bound = a.row.iter().max().map_or(0, |&r| r + 1);
        a.t = list;
    }

    /// WSS 2 over the active set: i, the position in it of the variable in I_up with the
    /// largest −y_t G_t; j, of the variable in I_low whose pair with i decreases the objective
    /// most. None once the maximal violation is below `eps`.
    fn working_pair(&self, st: &SolverState, eps: f64) -> Option<(usize, usize)> {
        let a = &st.active;
        let (gmax, i) = max_violation(a)?;
        let (gmax2, j) = best_partner(a, gmax, a.diag[i], self.k.row(a.row[i]));
        (gmax + gmax2 >= eps && j != usize::MAX).then_some((i, j))
    }

    /// One iteration on the pair at positions (i, j) of the active set: α, the active gradient,
    /// and `grad_bar` where α_i or α_j reached or left C.
    fn step(&self, st: &mut SolverState, (pi, pj): (usize, usize)) {
        let (i, j) = (st.active.t[pi], st.active.t[pj]);
        let (old_i, old_j) = (st.alpha[i], st.alpha[j]);
        self.update_pair(
            &mut st.alpha,
            (st.active.grad[pi], st.active.grad[pj]),
            i,
            j,
        );
        let (di, dj) = (st.alpha[i] - old_i, st.alpha[j] - old_j);
        let a = &mut st.active;
        let (yi, ki) = (a.y[pi], self.k.row(a.row[pi]));
        let (yj, kj) = (a.y[pj], self.k.row(a.row[pj]));
        move_gradient(a, (yi, ki, di), (yj, kj, dj));
        for (p, t) in [(pi, i), (pj, j)] {
            st.active.up[p] = self.up(t, st.alpha[t]);
            st.active.low[p] = self.low(t, st.alpha[t]);
        }
        for (t, old) in [(i, old_i), (j, old_j)] {
            let (was, is) = (old >= self.c, st.alpha[t] >= self.c);
            if was != is {
                let c = if is { self.c } else { -self.c };
                let (yt, kt) = (self.y[t], self.row(t));
                for ((gb, &yk), &r) in st.grad_bar.iter_mut().zip(&self.y).zip(self.rows) {
                    *gb += c * (yt * yk * kt[r]);
                }
            }
        }
    }

    /// libsvm's shrinking: the largest violations of each side over the active set; once they
    /// are within ten times `eps`, every variable back (once); then the variables at a bound
    /// whose gradient says they stay there leave the active set.
    fn shrink(&self, st: &mut SolverState, eps: f64) {
        st.write_back();
        let (mut gmax1, mut gmax2) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        for &t in &st.active.t {
            let (a, yg) = (st.alpha[t], self.y[t] * st.grad[t]);
            if self.up(t, a) {
                gmax1 = gmax1.max(-yg);
            }
            if self.low(t, a) {
                gmax2 = gmax2.max(yg);
            }
        }
        if !st.unshrunk && gmax1 + gmax2 <= eps * 10.0 {
            st.unshrunk = true;
            self.reconstruct_gradient(st);
        }
        let (alpha, grad) = (&st.alpha, &st.grad);
        let mut list = std::mem::take(&mut st.active.t);
        list.retain(|&t| {
            // At a bound it is in I_up or I_low alone, and leaves when no member of the other
            // side can make a violating pair with it: in I_up alone when −y G is below −gmax2,
            // in I_low alone when y G is below −gmax1.
            let yg = self.y[t] * grad[t];
            let leaves = match (self.up(t, alpha[t]), self.low(t, alpha[t])) {
                (true, false) => yg > gmax2,
                (false, true) => -yg > gmax1,
                _ => false,
            };
            !leaves
        });
        self.activate(st, list);
    }

    /// The gradient of the variables outside the active set, from `grad_bar` and the free
    /// variables (all of which are active); then every variable is active again.
    fn reconstruct_gradient(&self, st: &mut SolverState) {
        if st.active.len() == self.n {
            return;
        }
        st.write_back();
        let mut is_active = vec![false; self.n];
        for &t in &st.active.t {
            is_active[t] = true;
        }
        let inactive: Vec<usize> = (0..self.n).filter(|&t| !is_active[t]).collect();
        for &t in &inactive {
            st.grad[t] = st.grad_bar[t] - 1.0;
        }
        for &j in &st.active.t {
            let a = st.alpha[j];
            if a > 0.0 && a < self.c {
                let (yj, kj) = (self.y[j], self.row(j));
                for &t in &inactive {
                    st.grad[t] += a * (self.y[t] * yj * kj[self.rows[t]]);
                }
            }
        }
        self.activate(st, (0..self.n).collect());
    }

    /// The two-variable subproblem on (i, j), clipped to the box (libsvm's update, with
    /// C_i = C_j = C).
    fn update_pair(&self, alpha: &mut [f64], (gi, gj): (f64, f64), i: usize, j: usize) {
        let c = self.c;
        let curvature = curvature(self.diag[i], self.diag[j], self.kij(i, j));
        if self.y[i] != self.y[j] {
            let delta = (-gi - gj) / curvature;
            let diff = alpha[i] - alpha[j];
            alpha[i] += delta;
            alpha[j] += delta;
            if diff > 0.0 {
                if alpha[j] < 0.0 {
                    alpha[j] = 0.0;
                    alpha[i] = diff;
                }
            } else if alpha[i] < 0.0 {
                alpha[i] = 0.0;
                alpha[j] = -diff;
            }
            if diff > 0.0 {
                if alpha[i] > c {
                    alpha[i] = c;
                    alpha[j] = c - diff;
                }
            } else if alpha[j] > c {
                alpha[j] = c;
                alpha[i] = c + diff;
            }
        } else {
            let delta = (gi - gj) / curvature;
            let sum = alpha[i] + alpha[j];
            alpha[i] -= delta;
            alpha[j] += delta;
            if sum > c {
                if alpha[i] > c {
                    alpha[i] = c;
                    alpha[j] = sum - c;
                }
            } else if alpha[j] < 0.0 {
                alpha[j] = 0.0;
                alpha[i] = sum;
            }
            if sum > c {
                if alpha[j] > c {
                    alpha[j] = c;
                    alpha[i] = sum - c;
                }
            } else if alpha[i] < 0.0 {
                alpha[i] = 0.0;
                alpha[j] = sum;
            }
        }
    }

    /// rho: the mean of y_t G_t over the free α; without any, the middle of its feasible range.
    fn rho(&self, alpha: &[f64], grad: &[f64]) -> f64 {
        let (mut upper, mut lower) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut free, mut free_sum) = (0usize, 0.0);
        for t in 0..self.n {
            let yg = self.y[t] * grad[t];
            let at_upper = alpha[t] >= self.c;
            let at_lower = alpha[t] <= 0.0;
            if at_upper == at_lower {
                free += 1;
                free_sum += yg;
            } else if at_upper == (self.y[t] < 0.0) {
                upper = upper.min(yg);
            } else {
                lower = lower.max(yg);
            }
        }
        if free > 0 {
            free_sum / free as f64
        } else {
            (upper + lower) / 2.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rbf_matrix(x: &[[f64; 2]], gamma: f64) -> Vec<f64> {
        let mut k = Vec::new();
        for a in x {
            for b in x {
                let d2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                k.push(crate::math::exp(-gamma * d2));
            }
        }
        k
    }

    /// An active set of `n` variables over a kernel of `rows` rows, with few distinct values
    /// (so that ties are common), and two kernel rows.
    fn random_active(n: usize, rows: usize, seed: u64) -> (Active, Vec<f64>, Vec<f64>) {
        let mut rng = crate::rng::seeded(seed);
        let mut pick = |k: u64| rand::Rng::random_range(&mut rng, 0..k);
        let mut a = Active::default();
        for t in 0..n {
            a.t.push(t);
            a.row.push(pick(rows as u64) as usize);
            a.y.push(if pick(2) == 0 { 1.0 } else { -1.0 });
            a.diag.push(1.0);
            a.grad
                .push([-1.0, -0.5, 0.0, -0.0, 0.25, 0.5][pick(6) as usize]);
            a.up.push(pick(3) > 0);
            a.low.push(pick(3) > 0);
        }
        a.row_bound = a.row.iter().max().map_or(0, |&r| r + 1);
        let mut row = || {
            (0..rows)
                .map(|_| [0.0, 0.5, 1.0, 0.25][pick(4) as usize])
                .collect()
        };
        let (ki, kj) = (row(), row());
        (a, ki, kj)
    }

    #[test]
    fn the_wide_loops_choose_the_pair_and_move_the_gradient_as_the_portable_ones() {
        if !cfg!(target_arch = "x86_64") || !crate::cpu::avx2_fma() {
            eprintln!("skipped: the CPU has no AVX2");
            return;
        }
        let mut pairs = 0;
        for (case, n) in (0..40).chain([100, 333, 1000]).enumerate() {
            let (mut a, ki, kj) = random_active(n, 50, case as u64);
            let wide = max_violation(&a);
            assert_eq!(
                wide.map(|(v, i)| (v.to_bits(), i)),
                max_violation_portable(&a).map(|(v, i)| (v.to_bits(), i)),
                "case {case}"
            );
            for gmax in [0.0, 0.3, 1.0] {
                let (g2, j) = best_partner(&a, gmax, 1.0, &ki);
                let (pg2, pj) = best_partner_portable(&a, gmax, 1.0, &ki);
                // The largest y G may differ in the sign of a zero (only its sum with gmax
                // is compared with the tolerance); the partner must be the same.
                assert_eq!((g2, j), (pg2, pj), "case {case}, gmax {gmax}");
                pairs += usize::from(j != usize::MAX);
            }
            let mut b = a.clone();
            move_gradient(&mut a, (1.0, &ki, 0.3), (-1.0, &kj, 0.7));
            move_gradient_portable(&mut b, (1.0, &ki, 0.3), (-1.0, &kj, 0.7));
            let bits = |g: &[f64]| g.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.grad), bits(&b.grad), "case {case}");
        }
        assert!(pairs > 60, "only {pairs} of 129 searches found a partner");
    }

    #[test]
    fn two_points_split_halfway_with_equal_weights() {
        // Linear kernel on x = -1 and x = +1: the maximal margin puts the boundary at 0,
        // α = 1/2 each (w = 1, margin 1), rho = 0.
        let k = [1.0, -1.0, -1.0, 1.0];
        let d = solve(&k, &[false, true], 10.0, 1e-9, 1000);
        assert!(
            (d.coef[0] + 0.5).abs() < 1e-9 && (d.coef[1] - 0.5).abs() < 1e-9,
            "{d:?}"
        );
        assert!(d.rho.abs() < 1e-9);
    }

    /// `n` points on two crossing curves, labelled by a product with a wiggle.
    fn crossing(n: usize) -> (Vec<[f64; 2]>, Vec<bool>) {
        let mut x = Vec::new();
        let mut positive = Vec::new();
        for i in 0..n {
            let t = i as f64 * 0.7;
            let p = [3.0 * crate::math::sin(t), 3.0 * crate::math::cos(1.3 * t)];
            positive.push(p[0] * p[1] + 0.5 * crate::math::sin(5.0 * t) > 0.0);
            x.push(p);
        }
        (x, positive)
    }

    /// Σ y α = 0 and every variable within `tol` of its KKT condition.
    fn assert_kkt(d: &Dual, k: &[f64], positive: &[bool], c: f64, tol: f64) {
        let n = positive.len();
        let sum: f64 = d.coef.iter().sum();
        assert!(sum.abs() < 1e-9, "Σ y α = {sum}");
        let f = |i: usize| (0..n).map(|j| d.coef[j] * k[i * n + j]).sum::<f64>() - d.rho;
        for (i, &pos) in positive.iter().enumerate() {
            let y = if pos { 1.0 } else { -1.0 };
            let a = d.coef[i] * y;
            assert!((-1e-12..=c + 1e-12).contains(&a));
            let margin = y * f(i);
            // α = 0 → margin ≥ 1, α = C → margin ≤ 1, else margin = 1.
            if a <= 0.0 {
                assert!(margin >= 1.0 - tol, "{i}: α 0, margin {margin}");
            } else if a >= c {
                assert!(margin <= 1.0 + tol, "{i}: α C, margin {margin}");
            } else {
                assert!((margin - 1.0).abs() < tol, "{i}: free, margin {margin}");
            }
        }
    }

    #[test]
    fn the_solution_meets_the_kkt_conditions_and_the_equality_constraint() {
        let (x, positive) = crossing(60);
        let k = rbf_matrix(&x, 0.5);
        let d = solve(&k, &positive, 10.0, 1e-7, 1_000_000);
        assert!(d.iterations > 10);
        assert_kkt(&d, &k, &positive, 10.0, 1e-6);
    }

    #[test]
    fn a_shrunk_solve_meets_the_kkt_conditions_on_every_variable() {
        // Many iterations on 400 points: the active set shrinks, and the gradient rebuilt at the
        // end must still show every variable optimal.
        let (x, positive) = crossing(400);
        let k = rbf_matrix(&x, 2.0);
        let d = solve(&k, &positive, 100.0, 1e-7, 10_000_000);
        assert!(
            d.iterations > 400 && d.shrunk_peak > 0,
            "{} iterations, {} shrunk",
            d.iterations,
            d.shrunk_peak
        );
        assert_kkt(&d, &k, &positive, 100.0, 1e-6);
    }
}
