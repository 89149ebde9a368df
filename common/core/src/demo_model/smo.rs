//! The C-SVC dual solved by sequential minimal optimisation, as libsvm (and so scikit-learn's
//! `SVC`) solves it: the working-set selection by second-order information of Fan, Chen & Lin
//! (2005, "WSS 2"), libsvm's clipped two-variable update, and its rule for the offset `rho`.
//!
//! Written here rather than taken from a crate so that every number comes from the core's own
//! arithmetic: the RBF kernel through `crate::math::exp`, the same bits on every CPU (a
//! crate calling the platform's `exp` would not give them). No shrinking; the kernel's rows come
//! from [`KernelRows`], which the SVM computes when a working pair first needs them and keeps
//! for the final SVM and every fold's (libsvm's kernel cache, with room for every row), and the
//! columns the gradient update needs are read as rows.
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
}

/// libsvm's floor on the curvature of a working pair.
const TAU: f64 = 1e-12;

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
    let mut alpha = vec![0.0; n];
    // The objective's gradient Qα − e, at α = 0.
    let mut grad = vec![-1.0; n];
    let mut iterations = 0;
    while iterations < max_iter {
        let Some((i, j)) = problem.working_pair(&alpha, &grad, eps) else {
            break;
        };
        iterations += 1;
        let (old_i, old_j) = (alpha[i], alpha[j]);
        problem.update_pair(&mut alpha, &grad, i, j);
        problem.move_gradient(&mut grad, (i, alpha[i] - old_i), (j, alpha[j] - old_j));
    }
    if iterations == max_iter {
        tracing::debug!(max_iter, "SMO: reached the maximal number of iterations");
    }
    let rho = problem.rho(&alpha, &grad);
    let coef = alpha.iter().zip(&problem.y).map(|(a, y)| a * y).collect();
    Dual {
        coef,
        rho,
        iterations,
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

    /// The curvature of the objective along the pair (i, j), floored at TAU.
    fn curvature(&self, i: usize, j: usize) -> f64 {
        self.curvature_with(i, j, self.kij(i, j))
    }

    /// [`Problem::curvature`] given `K_ij`.
    fn curvature_with(&self, i: usize, j: usize, kij: f64) -> f64 {
        let a = self.diag[i] + self.diag[j] - 2.0 * kij;
        if a > 0.0 {
            a
        } else {
            TAU
        }
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

    /// WSS 2: i, the index in I_up with the largest −y_t G_t; j, the index in I_low whose pair
    /// with i decreases the objective most. None once the maximal violation is below `eps`.
    fn working_pair(&self, alpha: &[f64], grad: &[f64], eps: f64) -> Option<(usize, usize)> {
        let (y, n) = (&self.y, self.n);
        let mut gmax = f64::NEG_INFINITY;
        let mut i = usize::MAX;
        for t in 0..n {
            if self.up(t, alpha[t]) && -y[t] * grad[t] >= gmax {
                gmax = -y[t] * grad[t];
                i = t;
            }
        }
        if i == usize::MAX {
            return None;
        }
        // gmax2: the largest y_t G_t over I_low.
        let mut gmax2 = f64::NEG_INFINITY;
        let mut j = usize::MAX;
        let mut best = f64::INFINITY;
        let ki = self.row(i);
        for t in (0..n).filter(|&t| self.low(t, alpha[t])) {
            let yg = y[t] * grad[t];
            if yg >= gmax2 {
                gmax2 = yg;
            }
            let b = gmax + yg;
            if b > 0.0 {
                let gain = -(b * b) / self.curvature_with(i, t, ki[self.rows[t]]);
                if gain <= best {
                    best = gain;
                    j = t;
                }
            }
        }
        (gmax + gmax2 >= eps && j != usize::MAX).then_some((i, j))
    }

    /// The two-variable subproblem on (i, j), clipped to the box (libsvm's update, with
    /// C_i = C_j = C).
    fn update_pair(&self, alpha: &mut [f64], grad: &[f64], i: usize, j: usize) {
        let c = self.c;
        let curvature = self.curvature(i, j);
        if self.y[i] != self.y[j] {
            let delta = (-grad[i] - grad[j]) / curvature;
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
            let delta = (grad[i] - grad[j]) / curvature;
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

    /// G += Q[:, i] Δα_i + Q[:, j] Δα_j (columns i and j read as rows: the matrix is
    /// symmetric).
    fn move_gradient(&self, grad: &mut [f64], (i, di): (usize, f64), (j, dj): (usize, f64)) {
        let y = &self.y;
        let (yi, yj) = (y[i], y[j]);
        let (ki, kj) = (self.row(i), self.row(j));
        for ((g, &yt), &r) in grad.iter_mut().zip(y).zip(self.rows) {
            *g += yt * (yi * ki[r] * di + yj * kj[r] * dj);
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

    #[test]
    fn the_solution_meets_the_kkt_conditions_and_the_equality_constraint() {
        let mut x = Vec::new();
        let mut positive = Vec::new();
        for i in 0..60 {
            let t = i as f64 * 0.7;
            let p = [3.0 * crate::math::sin(t), 3.0 * crate::math::cos(1.3 * t)];
            positive.push(p[0] * p[1] + 0.5 * crate::math::sin(5.0 * t) > 0.0);
            x.push(p);
        }
        let k = rbf_matrix(&x, 0.5);
        let c = 10.0;
        let d = solve(&k, &positive, c, 1e-7, 1_000_000);
        assert!(d.iterations > 10);
        let sum: f64 = d.coef.iter().sum();
        assert!(sum.abs() < 1e-9, "Σ y α = {sum}");
        let f = |i: usize| {
            (0..x.len())
                .map(|j| d.coef[j] * k[i * x.len() + j])
                .sum::<f64>()
                - d.rho
        };
        for (i, &pos) in positive.iter().enumerate() {
            let y = if pos { 1.0 } else { -1.0 };
            let a = d.coef[i] * y;
            assert!((-1e-12..=c + 1e-12).contains(&a));
            let margin = y * f(i);
            // KKT within the tolerance: α = 0 → margin ≥ 1, α = C → margin ≤ 1, else margin = 1.
            if a <= 0.0 {
                assert!(margin >= 1.0 - 1e-6, "{i}: α 0, margin {margin}");
            } else if a >= c {
                assert!(margin <= 1.0 + 1e-6, "{i}: α C, margin {margin}");
            } else {
                assert!((margin - 1.0).abs() < 1e-6, "{i}: free, margin {margin}");
            }
        }
    }
}
