//! A blocked Cholesky factorisation for the large kernel matrices of KRR: right-looking, in
//! blocks of [`BLOCK`] columns. Each block's panel is factored in chunks of rows that stay in
//! cache, and the O(n³) update of the columns after it runs over register tiles of 8 rows × 6
//! columns against a packed copy of the panel, in row blocks that stay in the L2 cache, the
//! columns dealt in turn to the lanes the caller passes (`lanes.rs`). Plain multiplications and
//! subtractions in a fixed order per element (no fused multiply-add; wider registers where the
//! CPU has AVX2 or AVX-512 change the speed, never a bit), so the same binary gives the same
//! bits on every x86-64 CPU and on any lanes.

use super::lanes::{share, Lanes, Serial};

/// Columns per block.
pub const BLOCK: usize = 256;

/// Rows of a register tile of the trailing update (two AVX2 registers of f64).
const TILE_ROWS: usize = 8;

/// Columns of a register tile of the trailing update: with 8 rows, twelve AVX2 accumulators,
/// the most that leave registers for the operands (in the same sitting on an AMD EPYC core, 8 × 6
/// does a fifth more multiply-subtractions per second than 8 × 4, 12 × 4 half as many).
const TILE_COLS: usize = 6;

/// Row tiles per row block of the trailing update: 128 rows, whose packed panel (256 KB) stays
/// in the L2 cache while every column tile is updated over them.
const ROW_TILES: usize = 16;

/// Rows per chunk when a panel is factored below its diagonal block.
const PANEL_ROWS: usize = 256;

/// From this many rows below a block on, its work is shared among the lanes.
const THREADED_FROM: usize = 512;

/// Factors the symmetric positive-definite `a` (column-major, `n × n`; only its lower triangle is
/// read) in place into its lower Cholesky factor L, `a = L Lᵀ`, the large updates shared among
/// `lanes`. `false` if `a` is not positive definite (a pivot is not positive); `a` is
/// then partly overwritten. Only the lower triangle is written.
///
/// Every element of L is `(a_ij - l_i0 l_j0 - l_i1 l_j1 - ...) / l_jj`, the products subtracted
/// in that order: the bits of nalgebra's factorisation, and of a factor grown one row at a time
/// (`krr::KrrFactor`).
///
/// # Panics
/// If `a.len() != n * n`.
pub fn factor(a: &mut [f64], n: usize, lanes: &dyn Lanes) -> bool {
    assert_eq!(a.len(), n * n, "the matrix must hold n * n values");
    let mut kb = 0;
    while kb < n {
        let end = (kb + BLOCK).min(n);
        let lanes = if n - end >= THREADED_FROM {
            lanes
        } else {
            &Serial
        };
        if !factor_panel(a, n, kb, end, lanes) {
            return false;
        }
        if end < n {
            update_trailing(a, n, kb, end, lanes);
        }
        kb = end;
    }
    true
}

/// Columns `kb..end` of L: the diagonal block column by column, then the rows below it in chunks
/// of [`PANEL_ROWS`] (dealt to the lanes), each column of a chunk minus the block's columns before
/// it, in order, then divided by its diagonal.
fn factor_panel(a: &mut [f64], n: usize, kb: usize, end: usize, lanes: &dyn Lanes) -> bool {
    let w = end - kb;
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
        let (left, right) = a.split_at_mut(j * n);
        let lj: Vec<f64> = (kb..j).map(|p| left[j + p * n]).collect();
        let cols: Vec<&[f64]> = (kb..j).map(|p| &left[p * n + j + 1..p * n + end]).collect();
        crate::nn::wide(|| subtract_then_divide(&mut right[j + 1..end], &cols, &lj, d));
    }
    // L[kb..end, kb..end] row by row.
    let diag: Vec<f64> = (kb..end)
        .flat_map(|j| (kb..end).map(move |p| (j, p)))
        .map(|(j, p)| a[j + p * n])
        .collect();
    let by_column = diag_by_column(&diag, w);
    let mut chunks: Vec<(usize, Vec<f64>)> = (end..n)
        .step_by(PANEL_ROWS)
        .map(|r0| {
            let r1 = (r0 + PANEL_ROWS).min(n);
            let copy = (kb..end).flat_map(|p| a[p * n + r0..p * n + r1].iter().copied());
            (r0, copy.collect())
        })
        .collect();
    share(&mut chunks, lanes, |lane| {
        for (_, c) in lane.iter_mut() {
            panel_chunk(c, &diag, &by_column, w);
        }
    });
    for (r0, c) in &chunks {
        let m = c.len() / w;
        for (p, col) in (kb..end).zip(c.chunks_exact(m)) {
            a[p * n + r0..p * n + r0 + m].copy_from_slice(col);
        }
    }
    true
}

/// The diagonal block's rows (row-major `w × w`) packed for the register tile: for each tile of
/// [`TILE_COLS`] rows j, `packed[tile][p][j]` = L[j, p], zeros past `w`.
fn diag_by_column(diag: &[f64], w: usize) -> Vec<f64> {
    let mut packed = vec![0.0; w.div_ceil(TILE_COLS) * w * TILE_COLS];
    for j in 0..w {
        let (t, c) = (j / TILE_COLS, j % TILE_COLS);
        for p in 0..j {
            packed[(t * w + p) * TILE_COLS + c] = diag[j * w + p];
        }
    }
    packed
}

/// A chunk of rows below the diagonal block (column-major, `w` columns), solved against the
/// diagonal block `diag` (row-major `w × w`, L's values; `by_column` the same packed by
/// [`diag_by_column`]). Rows go [`TILE_ROWS`] at a time: each tile of [`TILE_COLS`] columns
/// takes the products of the columns before it in a register tile, then those among its own
/// columns, then divides; the rows left over go column by column. Either way every element
/// subtracts its products in order of the column, then divides.
fn panel_chunk(c: &mut [f64], diag: &[f64], by_column: &[f64], w: usize) {
    let m = c.len() / w;
    let full = m - m % TILE_ROWS;
    let mut x = vec![0.0; w * TILE_ROWS];
    for r0 in (0..full).step_by(TILE_ROWS) {
        for (p, xp) in x.chunks_exact_mut(TILE_ROWS).enumerate() {
            xp.copy_from_slice(&c[p * m + r0..p * m + r0 + TILE_ROWS]);
        }
        crate::nn::wide(|| panel_tile_rows(&mut x, diag, by_column, w));
        for (p, xp) in x.chunks_exact(TILE_ROWS).enumerate() {
            c[p * m + r0..p * m + r0 + TILE_ROWS].copy_from_slice(xp);
        }
    }
    if full == m {
        return;
    }
    for j in 0..w {
        let (left, right) = c.split_at_mut(j * m);
        let cols: Vec<&[f64]> = left.chunks_exact(m).map(|col| &col[full..]).collect();
        let lj = &diag[j * w..j * w + j];
        let d = diag[j * w + j];
        crate::nn::wide(|| subtract_then_divide(&mut right[full..m], &cols, lj, d));
    }
}

/// [`TILE_ROWS`] rows of a panel chunk, `x[p * 8 + r]` (row r, column p), solved in place.
#[inline(always)]
fn panel_tile_rows(x: &mut [f64], diag: &[f64], by_column: &[f64], w: usize) {
    for j0 in (0..w).step_by(TILE_COLS) {
        let cols = TILE_COLS.min(w - j0);
        let mut acc = [0.0f64; TILE_ROWS * TILE_COLS];
        acc[..cols * TILE_ROWS].copy_from_slice(&x[j0 * TILE_ROWS..(j0 + cols) * TILE_ROWS]);
        let packed = &by_column[j0 * w..];
        tile_update(&mut acc, &x[..j0 * TILE_ROWS], &packed[..j0 * TILE_COLS]);
        for k in 0..cols {
            let j = j0 + k;
            let (done, acc_k) = (
                &x[..j * TILE_ROWS],
                &mut acc[k * TILE_ROWS..(k + 1) * TILE_ROWS],
            );
            for p in j0..j {
                let l = diag[j * w + p];
                for (a, v) in acc_k
                    .iter_mut()
                    .zip(&done[p * TILE_ROWS..(p + 1) * TILE_ROWS])
                {
                    *a -= v * l;
                }
            }
            let d = diag[j * w + j];
            for a in acc_k.iter_mut() {
                *a /= d;
            }
            x[j * TILE_ROWS..(j + 1) * TILE_ROWS].copy_from_slice(acc_k);
        }
    }
}

/// `x = (x - cols[0] lj[0] - cols[1] lj[1] - ...) / d`, element by element, the products
/// subtracted in order of the columns: [`SUBTRACT_ROWS`] elements at a time held in registers
/// over every column, the last few one by one.
#[inline(always)]
fn subtract_then_divide(x: &mut [f64], cols: &[&[f64]], lj: &[f64], d: f64) {
    let full = x.len() - x.len() % SUBTRACT_ROWS;
    for i in (0..full).step_by(SUBTRACT_ROWS) {
        let v: &mut [f64; SUBTRACT_ROWS] = (&mut x[i..i + SUBTRACT_ROWS]).try_into().unwrap();
        let mut acc = *v;
        for (col, &c) in cols.iter().zip(lj) {
            let col: &[f64; SUBTRACT_ROWS] = col[i..i + SUBTRACT_ROWS].try_into().unwrap();
            for (a, l) in acc.iter_mut().zip(col) {
                *a -= l * c;
            }
        }
        for (v, a) in v.iter_mut().zip(acc) {
            *v = a / d;
        }
    }
    for (i, v) in x.iter_mut().enumerate().skip(full) {
        let mut a = *v;
        for (col, &c) in cols.iter().zip(lj) {
            a -= col[i] * c;
        }
        *v = a / d;
    }
}

/// Rows held in registers by [`subtract_then_divide`] (four AVX2 registers of f64).
const SUBTRACT_ROWS: usize = 16;

/// The columns after the block minus the block's contribution, `a[i, j] -= Σ_p L[i, p] L[j, p]`
/// for `i ≥ j ≥ end`, p from `kb` to `end` in order. The panel's rows from `end` on are packed
/// twice: in tiles of [`TILE_ROWS`] rows (`packed[tile][p][row]`, zeros past `n`) and of
/// [`TILE_COLS`] (the same values for the column tiles); the columns go in tiles of
/// [`TILE_COLS`], dealt to the lanes in turn.
fn update_trailing(a: &mut [f64], n: usize, kb: usize, end: usize, lanes: &dyn Lanes) {
    let w = end - kb;
    let tiles = (n - end).div_ceil(TILE_ROWS);
    let mut packed = vec![0.0; tiles * w * TILE_ROWS];
    let mut by_column = vec![0.0; (n - end).div_ceil(TILE_COLS) * w * TILE_COLS];
    for p in 0..w {
        let col = &a[(kb + p) * n + end..(kb + p + 1) * n];
        for (i, v) in col.iter().enumerate() {
            packed[(i / TILE_ROWS * w + p) * TILE_ROWS + i % TILE_ROWS] = *v;
            by_column[(i / TILE_COLS * w + p) * TILE_COLS + i % TILE_COLS] = *v;
        }
    }
    let panel = Panel {
        packed: &packed,
        columns: &by_column,
        w,
        n,
        end,
        tiles,
    };
    let mut columns: Vec<(usize, &mut [f64])> = a[end * n..]
        .chunks_mut(TILE_COLS * n)
        .enumerate()
        .map(|(t, cols)| (end + t * TILE_COLS, cols))
        .collect();
    share(&mut columns, lanes, |lane| panel.update(lane));
}

/// The packed rows of a panel below its block (see [`update_trailing`]).
struct Panel<'a> {
    packed: &'a [f64],
    /// The same values packed for the column tiles: `columns[tile][p][column]`, zeros past `n`.
    columns: &'a [f64],
    /// The block's width.
    w: usize,
    n: usize,
    /// The first row (and column) after the block.
    end: usize,
    tiles: usize,
}

impl Panel<'_> {
    /// One tile of packed rows.
    #[inline(always)]
    fn tile(&self, t: usize) -> &[f64] {
        let size = self.w * TILE_ROWS;
        &self.packed[t * size..(t + 1) * size]
    }

    /// Updates these column tiles (first column, its values), a block of row tiles at a time.
    #[inline(always)]
    fn update(&self, columns: &mut [&mut (usize, &mut [f64])]) {
        for block in (0..self.tiles).step_by(ROW_TILES) {
            let block_end = (block + ROW_TILES).min(self.tiles);
            for (j0, cols) in columns.iter_mut().map(|c| (c.0, &mut *c.1)) {
                let jt = (j0 - self.end) / TILE_ROWS;
                if jt >= block_end {
                    continue;
                }
                let size = self.w * TILE_COLS;
                let ct = (j0 - self.end) / TILE_COLS;
                let lj = &self.columns[ct * size..(ct + 1) * size];
                for t in block.max(jt)..block_end {
                    self.update_tile(t, lj, j0, cols);
                }
            }
        }
    }

    /// Rows of tile `t` of the columns `j0..` held in `cols` (column-major, up to [`TILE_COLS`]
    /// of them), in registers, written back on and below the diagonal.
    #[inline(always)]
    fn update_tile(&self, t: usize, lj: &[f64], j0: usize, cols: &mut [f64]) {
        let row0 = self.end + t * TILE_ROWS;
        let rows = TILE_ROWS.min(self.n - row0);
        let ncols = cols.len() / self.n;
        let mut acc = [0.0f64; TILE_ROWS * TILE_COLS];
        for (c, acc_c) in acc.chunks_exact_mut(TILE_ROWS).enumerate().take(ncols) {
            acc_c[..rows].copy_from_slice(&cols[c * self.n + row0..c * self.n + row0 + rows]);
        }
        tile_update(&mut acc, self.tile(t), lj);
        for (c, acc_c) in acc.chunks_exact(TILE_ROWS).enumerate().take(ncols) {
            let first = (j0 + c).max(row0) - row0;
            if first < rows {
                cols[c * self.n + row0 + first..c * self.n + row0 + rows]
                    .copy_from_slice(&acc_c[first..rows]);
            }
        }
    }
}

/// The register tile: `acc[c * 8 + r] -= li[8 p + r] * lj[6 p + c]` for every p in order (`li`
/// holds the panel's values of the tile's 8 rows per p, `lj` those of its 6 columns).
/// AVX-512 or AVX2 where the CPU has it; the same operations, so the same bits, without.
fn tile_update(acc: &mut [f64; TILE_ROWS * TILE_COLS], li: &[f64], lj: &[f64]) {
    let w = li.len() / TILE_ROWS;
    assert!(lj.len() >= w * TILE_COLS);
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return x86::tile_update(acc, li, lj, w, crate::nn::avx512_available());
    }
    tile_update_portable(acc, li, lj, w);
}

/// [`tile_update`] without AVX2 or AVX-512: the same operations in the same order.
fn tile_update_portable(acc: &mut [f64; TILE_ROWS * TILE_COLS], li: &[f64], lj: &[f64], w: usize) {
    for p in 0..w {
        let li = &li[p * TILE_ROWS..(p + 1) * TILE_ROWS];
        for (c, acc_c) in acc.chunks_exact_mut(TILE_ROWS).enumerate() {
            let x = lj[p * TILE_COLS + c];
            for (v, l) in acc_c.iter_mut().zip(li) {
                *v -= l * x;
            }
        }
    }
}

/// The AVX2 and AVX-512 register tiles of [`tile_update`]: multiplications and subtractions,
/// never fused.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use std::arch::x86_64::*;

    use super::{TILE_COLS, TILE_ROWS};

    pub(super) fn available() -> bool {
        crate::cpu::avx2_fma()
    }

    /// # Safety
    /// The CPU has AVX-512F; `li` holds `w * 8` values and `lj` at least `w * 6`.
    #[target_feature(enable = "avx512f")]
    unsafe fn tile_update_avx512(
        acc: &mut [f64; TILE_ROWS * TILE_COLS],
        li: &[f64],
        lj: &[f64],
        w: usize,
    ) {
        let a = acc.as_mut_ptr();
        let (pi, pj) = (li.as_ptr(), lj.as_ptr());
        // SAFETY: every offset below is within `acc` (48 values), `li` (p * 8 + 8 <= w * 8) and
        // `lj` (p * 6 + 6 <= w * 6).
        unsafe {
            let mut r: [__m512d; TILE_COLS] =
                std::array::from_fn(|c| _mm512_loadu_pd(a.add(TILE_ROWS * c)));
            for p in 0..w {
                let rows = _mm512_loadu_pd(pi.add(p * TILE_ROWS));
                for (c, r) in r.iter_mut().enumerate() {
                    let x = _mm512_set1_pd(*pj.add(p * TILE_COLS + c));
                    *r = _mm512_sub_pd(*r, _mm512_mul_pd(rows, x));
                }
            }
            for (c, v) in r.into_iter().enumerate() {
                _mm512_storeu_pd(a.add(TILE_ROWS * c), v);
            }
        }
    }

    /// See [`super::tile_update`]; `li` holds `w * 8` values, `lj` at least `w * 6`. With
    /// `avx512`, each column's 8 rows in one AVX-512 register, else in two AVX2 registers.
    pub(super) fn tile_update(
        acc: &mut [f64; TILE_ROWS * TILE_COLS],
        li: &[f64],
        lj: &[f64],
        w: usize,
        avx512: bool,
    ) {
        assert!(available() && li.len() >= w * TILE_ROWS);
        assert!(lj.len() >= w * TILE_COLS);
        assert!(!avx512 || crate::nn::avx512_available());
        // SAFETY: the CPU has AVX2, and AVX-512F when `avx512` (asserted); the lengths are
        // checked above.
        unsafe {
            if avx512 {
                tile_update_avx512(acc, li, lj, w)
            } else {
                tile_update_avx2(acc, li, lj, w)
            }
        }
    }

    /// # Safety
    /// The CPU has AVX2; `li` holds `w * 8` values and `lj` at least `w * 6`.
    #[target_feature(enable = "avx2")]
    unsafe fn tile_update_avx2(
        acc: &mut [f64; TILE_ROWS * TILE_COLS],
        li: &[f64],
        lj: &[f64],
        w: usize,
    ) {
        let a = acc.as_mut_ptr();
        let (pi, pj) = (li.as_ptr(), lj.as_ptr());
        // SAFETY: every offset below is within `acc` (48 values), `li` (p * 8 + 8 <= w * 8) and
        // `lj` (p * 6 + 6 <= w * 6).
        unsafe {
            let mut r: [__m256d; 12] = std::array::from_fn(|q| _mm256_loadu_pd(a.add(4 * q)));
            for p in 0..w {
                let lo = _mm256_loadu_pd(pi.add(p * TILE_ROWS));
                let hi = _mm256_loadu_pd(pi.add(p * TILE_ROWS + 4));
                for c in 0..TILE_COLS {
                    let x = _mm256_broadcast_sd(&*pj.add(p * TILE_COLS + c));
                    r[2 * c] = _mm256_sub_pd(r[2 * c], _mm256_mul_pd(lo, x));
                    r[2 * c + 1] = _mm256_sub_pd(r[2 * c + 1], _mm256_mul_pd(hi, x));
                }
            }
            for (q, v) in r.into_iter().enumerate() {
                _mm256_storeu_pd(a.add(4 * q), v);
            }
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
    use super::super::lanes::Backwards;
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
        assert!(factor(&mut a, 2, &Serial));
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
        assert!(factor(&mut a, n, &Serial));
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
    fn any_lanes_give_the_same_bits_and_only_the_lower_triangle_changes() {
        let n = BLOCK + THREADED_FROM + 2 * TILE_ROWS + 3;
        let k = kernel(n);
        let mut one = k.as_slice().to_vec();
        assert!(factor(&mut one, n, &Serial));
        for width in [2, 3] {
            let mut many = k.as_slice().to_vec();
            assert!(factor(&mut many, n, &Backwards(width)));
            assert!(one
                .iter()
                .zip(&many)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        for j in 0..n {
            for i in 0..j {
                assert_eq!(one[i + j * n], k[(i, j)], "upper triangle at ({i}, {j})");
            }
        }
        let l = k.cholesky().unwrap().l();
        for j in 0..n {
            for i in j..n {
                assert!((one[i + j * n] - l[(i, j)]).abs() < 1e-12, "L[{i}, {j}]");
            }
        }
    }

    #[test]
    fn the_avx2_and_avx512_register_tiles_give_the_portable_tile_s_bits() {
        #[cfg(target_arch = "x86_64")]
        if x86::available() {
            let w = 37;
            let v = |k: usize| ((k * 7919 % 1013) as f64 - 500.0) / 97.0;
            let li: Vec<f64> = (0..w * TILE_ROWS).map(v).collect();
            let lj: Vec<f64> = (0..w * TILE_COLS).map(|k| v(k + 3)).collect();
            let start: [f64; TILE_ROWS * TILE_COLS] = std::array::from_fn(|k| v(k + 11));
            let mut portable = start;
            tile_update_portable(&mut portable, &li, &lj, w);
            assert_ne!(portable, start);
            for avx512 in [false, true] {
                if avx512 && !crate::nn::avx512_available() {
                    continue;
                }
                let mut wide = start;
                x86::tile_update(&mut wide, &li, &lj, w, avx512);
                assert!(
                    wide.iter()
                        .zip(&portable)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "avx512: {avx512}"
                );
            }
        }
    }

    #[test]
    fn a_matrix_that_is_not_positive_definite_is_refused() {
        let mut a = vec![1.0, 2.0, 2.0, 1.0];
        assert!(!factor(&mut a, 2, &Serial));
    }
}
