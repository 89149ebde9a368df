//! A blocked Cholesky factorisation for the large kernel matrices of KRR: right-looking, in
//! blocks of [`BLOCK`] columns, so that the O(n³) trailing update streams through memory a block
//! at a time instead of once per column. Plain multiplications and additions in a fixed order
//! (no fused multiply-add, no run-time choice of kernel), so the same binary gives the same bits
//! on every x86-64 CPU.

/// Columns per block.
pub const BLOCK: usize = 96;

/// Factors the symmetric positive-definite `a` (column-major, `n × n`; only its lower triangle is
/// read) in place into its lower Cholesky factor L, `a = L Lᵀ`. `false` if `a` is not positive
/// definite (a pivot is not positive); `a` is then partly overwritten.
///
/// # Panics
/// If `a.len() != n * n`.
pub fn factor(a: &mut [f64], n: usize) -> bool {
    assert_eq!(a.len(), n * n, "the matrix must hold n * n values");
    let mut kb = 0;
    while kb < n {
        let end = (kb + BLOCK).min(n);
        if !factor_panel(a, n, kb, end) {
            return false;
        }
        for j in end..n {
            update_column(a, n, j, kb, end);
        }
        kb = end;
    }
    true
}

/// Columns `kb..end` of L: the diagonal block left-looking, and the rows below it.
fn factor_panel(a: &mut [f64], n: usize, kb: usize, end: usize) -> bool {
    for j in kb..end {
        let mut d = a[j + j * n];
        for p in kb..j {
            let l = a[j + p * n];
            d -= l * l;
        }
        if d <= 0.0 || d.is_nan() {
            return false;
        }
        let d = d.sqrt();
        a[j + j * n] = d;
        for i in j + 1..n {
            let mut s = a[i + j * n];
            for p in kb..j {
                s -= a[i + p * n] * a[j + p * n];
            }
            a[i + j * n] = s / d;
        }
    }
    true
}

/// Column `j` (below the block) minus the contribution of block columns `kb..end`:
/// `a[j.., j] -= L[j.., kb..end] L[j, kb..end]ᵀ`, four columns of L per pass over the column but
/// one subtraction at a time in column order, so that every element of L is
/// `(a_ij - l_i0 l_j0 - l_i1 l_j1 - ...) / l_jj` in that order: the bits of nalgebra's
/// factorisation, and of a factor grown one row at a time (`krr::KrrFactor`).
fn update_column(a: &mut [f64], n: usize, j: usize, kb: usize, end: usize) {
    let (left, right) = a.split_at_mut(j * n);
    let col = &mut right[j..n];
    let l = |p: usize| &left[p * n + j..(p + 1) * n];
    let mut p = kb;
    while p + 4 <= end {
        let (l0, l1, l2, l3) = (l(p), l(p + 1), l(p + 2), l(p + 3));
        let (c0, c1, c2, c3) = (l0[0], l1[0], l2[0], l3[0]);
        for (i, x) in col.iter_mut().enumerate() {
            *x = (((*x - l0[i] * c0) - l1[i] * c1) - l2[i] * c2) - l3[i] * c3;
        }
        p += 4;
    }
    for p in p..end {
        let l0 = l(p);
        let c0 = l0[0];
        for (x, v) in col.iter_mut().zip(l0) {
            *x -= v * c0;
        }
    }
}

/// Solves `L Lᵀ x = b` in place for each column of `b` (column-major, `n × m`), with `l` from
/// [`factor`]. The reference for `KrrFactor`'s solve, which reads L where it keeps it.
#[cfg(test)]
pub fn solve(l: &[f64], n: usize, b: &mut [f64]) {
    for col in b.chunks_exact_mut(n) {
        for j in 0..n {
            let x = col[j] / l[j + j * n];
            col[j] = x;
            for i in j + 1..n {
                col[i] -= l[i + j * n] * x;
            }
        }
        for j in (0..n).rev() {
            let mut s = col[j];
            for i in j + 1..n {
                s -= l[i + j * n] * col[i];
            }
            col[j] = s / l[j + j * n];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// A kernel matrix plus a ridge: what KRR factors.
    fn kernel(n: usize) -> DMatrix<f64> {
        let x: Vec<f64> = (0..n).map(|i| ((i * 7919) % 1000) as f64 / 100.0).collect();
        DMatrix::from_fn(n, n, |i, j| {
            (-0.1 * (x[i] - x[j]).powi(2)).exp() + if i == j { 0.1 } else { 0.0 }
        })
    }

    #[test]
    fn a_two_by_two_factor_is_the_hand_computed_one() {
        // [[4, 2], [2, 5]] = L Lᵀ with L = [[2, 0], [1, 2]].
        let mut a = vec![4.0, 2.0, 2.0, 5.0];
        assert!(factor(&mut a, 2));
        assert_eq!((a[0], a[1], a[3]), (2.0, 1.0, 2.0));
        // 4x + 2y = 8 and 2x + 5y = 9: y = 1.25, x = 1.375.
        let mut b = vec![8.0, 9.0];
        solve(&a, 2, &mut b);
        assert_eq!(b, vec![1.375, 1.25]);
    }

    #[test]
    fn the_blocked_factor_and_solve_match_nalgebra_across_several_blocks() {
        let n = 2 * BLOCK + 37;
        let k = kernel(n);
        let mut a = k.as_slice().to_vec();
        assert!(factor(&mut a, n));
        let l = k.clone().cholesky().unwrap().l();
        for j in 0..n {
            for i in j..n {
                assert!((a[i + j * n] - l[(i, j)]).abs() < 1e-12, "L[{i}, {j}]");
            }
        }
        let y = DMatrix::from_fn(n, 2, |i, c| f64::from(u8::from(i % 2 == c)));
        let expected = k.cholesky().unwrap().solve(&y);
        let mut b = y.as_slice().to_vec();
        solve(&a, n, &mut b);
        for (got, want) in b.iter().zip(expected.as_slice()) {
            assert!((got - want).abs() < 1e-9, "{got} against {want}");
        }
    }

    #[test]
    fn a_matrix_that_is_not_positive_definite_is_refused() {
        let mut a = vec![1.0, 2.0, 2.0, 1.0];
        assert!(!factor(&mut a, 2));
    }
}
