//! The two triangular solves of a grown KRR factor ([`super::krr::KrrFactor`]): forward
//! substitution for the new row of L a demonstration adds, back substitution for the dual
//! coefficients. Each is O(n²) and reads L from memory once, so one core's memory bandwidth
//! bounds it. On lanes that run two jobs at once ([`Lanes::concurrent`]) every row of L is split
//! at [`split_at`] (about half its length) so that both cores read their own half of it: a
//! leader solves the rows with the part of each row next to the diagonal, a helper takes the
//! products of the part before the split, and the two hand each other values as they come.
//! Every value takes the same products in the same order either way (the forward sums in
//! increasing column, the back sums in decreasing row), so the results are the same bits.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use super::lanes::Lanes;

/// Below this many rows the solves run on the caller's thread whatever lanes they are given:
/// the two threads' start and hand-overs cost more than the half of a pass over a small factor
/// they save.
pub const SPLIT_FROM: usize = 2048;

/// Values per segment of the back substitution: a block's rows of L over it stay in the L1
/// cache for every action's column.
const BACK_SEGMENT: usize = 512;

/// Rows of L per group of the forward substitution and per block of the back substitution.
const ROWS: usize = 4;

/// L's rows up to the diagonal, one after another: row i is `i + 1` values from `i (i + 1) / 2`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rows<'a>(pub &'a [f64]);

impl<'a> Rows<'a> {
    pub(crate) fn row(self, i: usize) -> &'a [f64] {
        let start = i * (i + 1) / 2;
        &self.0[start..start + i + 1]
    }
}

/// Whether the solves of `n` rows are split between two lanes.
fn split(lanes: &dyn Lanes, n: usize) -> bool {
    lanes.concurrent() && lanes.width() >= 2 && n >= SPLIT_FROM
}

/// Where the rows from `i` on are split between the helper (columns before) and the leader
/// (columns from): about half of `i`, on a multiple of 64. It never decreases in `i`, so a
/// column passes from one lane to the other once, and it moves every 128 rows, so that the
/// back substitution's leader may run up to 32 blocks ahead of its helper.
fn split_at(i: usize) -> usize {
    i / 128 * 64
}

/// `z = L⁻¹ k` over the first `k.len()` rows of L: `z_i = (k_i − Σ_{j<i} l_ij z_j) / l_ii`, the
/// products subtracted in increasing j.
pub(crate) fn forward(l: Rows, k: &[f64], lanes: &dyn Lanes) -> Vec<f64> {
    let n = k.len();
    if !split(lanes, n) {
        let mut z = vec![0.0; n];
        crate::nn::wide(|| forward_rows(l, k, &mut z, |_| 0, None));
        return z;
    }
    // The helper sums each group's columns before the split and hands the sums over; the
    // leader takes the rest off and hands the solved values back. The helper only needs values
    // from half as far, so it runs ahead and the leader seldom waits.
    let mut z = vec![0.0; n];
    let (sums, solved) = (Handoff::new(n, lanes), Handoff::new(n, lanes));
    let (sums, solved, z_out) = (&sums, &solved, &mut z);
    lanes.run(vec![
        Box::new(move || {
            let _done = solved.finish_on_drop();
            crate::nn::wide(|| forward_rows(l, k, z_out, split_at, Some((sums, solved))));
        }),
        Box::new(move || {
            let _done = sums.finish_on_drop();
            crate::nn::wide(|| forward_helper(l, k, solved, sums));
        }),
    ]);
    z
}

/// Solves the rows of `z` in groups of four: each row's sum from `start(i)` (`k_i` minus
/// nothing when that is 0; else the helper's sum over the columns before it, from `hand.0`),
/// minus its products up to the diagonal; each solved value handed on to `hand.1`.
#[inline(always)]
fn forward_rows(
    l: Rows,
    k: &[f64],
    z: &mut [f64],
    start: impl Fn(usize) -> usize,
    hand: Option<(&Handoff, &Handoff)>,
) {
    let n = z.len();
    let mut i = 0;
    while i < n {
        let g = (n - i).min(ROWS);
        let c = start(i);
        if let Some((sums, _)) = hand {
            sums.wait(i + g);
        }
        let mut s = [0.0; ROWS];
        for (t, v) in s[..g].iter_mut().enumerate() {
            *v = hand.map_or(k[i + t], |(sums, _)| sums.get(i + t));
        }
        subtract_columns(l, i, &mut s[..g], c..i, &z[c..i]);
        // The group's own triangle, in increasing column as well.
        for t in 0..g {
            let row = l.row(i + t);
            for u in 0..t {
                s[t] -= row[i + u] * z[i + u];
            }
            z[i + t] = s[t] / row[i + t];
        }
        if let Some((_, solved)) = hand {
            for (t, v) in z.iter().enumerate().skip(i).take(g) {
                solved.put(t, *v);
            }
            solved.ready(i + g);
        }
        i += g;
    }
}

/// The sums of rows `i..i + s.len()` (at most four) minus their products with `z` over the
/// columns `cols` (`z[0]` the value of column `cols.start`), each in increasing column: four
/// rows at once, so that no chain of subtractions waits on the last.
#[inline(always)]
fn subtract_columns(l: Rows, i: usize, s: &mut [f64], cols: std::ops::Range<usize>, z: &[f64]) {
    if let Ok(s) = <&mut [f64; ROWS]>::try_from(&mut *s) {
        let rows: [&[f64]; ROWS] = std::array::from_fn(|t| &l.row(i + t)[cols.clone()]);
        subtract_four(s, rows, z);
        return;
    }
    for (t, v) in s.iter_mut().enumerate() {
        for (lj, zj) in l.row(i + t)[cols.clone()].iter().zip(z) {
            *v -= lj * zj;
        }
    }
}

/// Four sums, each minus its row's products with `z` in order.
#[inline(always)]
fn subtract_four(s: &mut [f64; ROWS], rows: [&[f64]; ROWS], z: &[f64]) {
    let [r0, r1, r2, r3] = rows;
    for ((((&zk, l0), l1), l2), l3) in z.iter().zip(r0).zip(r1).zip(r2).zip(r3) {
        s[0] -= l0 * zk;
        s[1] -= l1 * zk;
        s[2] -= l2 * zk;
        s[3] -= l3 * zk;
    }
}

/// The forward helper: each group of rows' sum over the columns before [`split_at`], handed
/// over, once the leader has handed over the values of those columns.
fn forward_helper(l: Rows, k: &[f64], solved: &Handoff, sums: &Handoff) {
    let n = k.len();
    let mut z: Vec<f64> = Vec::with_capacity(n / 2);
    let mut i = 0;
    while i < n {
        let (g, c) = ((n - i).min(ROWS), split_at(i));
        if z.len() < c {
            solved.wait(c);
            z.extend((z.len()..c).map(|j| solved.get(j)));
        }
        let mut s = [0.0; ROWS];
        s[..g].copy_from_slice(&k[i..i + g]);
        subtract_columns(l, i, &mut s[..g], 0..c, &z[..c]);
        for (t, v) in s[..g].iter().enumerate() {
            sums.put(i + t, *v);
        }
        sums.ready(i + g);
        i += g;
    }
}

/// Solves `Lᵀ X = W` in place for every column of `cols` (column-major, `n` values each) over
/// the first `n` rows of L: back substitution from the last row up, each value minus its
/// products in decreasing row, then divided by its diagonal.
pub(crate) fn back(l: Rows, cols: &mut [f64], n: usize, lanes: &dyn Lanes) {
    let mut cols: Vec<&mut [f64]> = cols.chunks_exact_mut(n).collect();
    if !split(lanes, n) {
        crate::nn::wide(|| back_rows(l, &mut cols, |_| 0, None));
        return;
    }
    // Block by block from the last row: the leader solves the block and takes its products off
    // the values from the split on, the helper (on its own copy) off the values before it. As
    // the split comes down, the helper hands the values it has finished with to the leader.
    let first = split_at(n - ROWS);
    let low: Vec<Vec<f64>> = cols.iter().map(|c| c[..first].to_vec()).collect();
    let (passed, solved) = (
        Handoff::new(first * cols.len(), lanes),
        Handoff::new(n * cols.len(), lanes),
    );
    let (passed, solved, cols) = (&passed, &solved, &mut cols);
    lanes.run(vec![
        Box::new(move || {
            let _done = solved.finish_on_drop();
            crate::nn::wide(|| back_rows(l, cols, split_at, Some((passed, solved))));
        }),
        Box::new(move || {
            let _done = passed.finish_on_drop();
            crate::nn::wide(|| back_helper(l, low, n, solved, passed));
        }),
    ]);
}

/// Solves the columns a block of rows at a time from the last: the block's own triangle, then
/// every value from `start(top)` to the block minus the block's products. With `hand`, the
/// values before the split are the helper's: each block first takes over those it has finished
/// with (from `hand.0`, column a's value j at `a * first + j`, `first` the first block's
/// split), and hands its solved values on (`hand.1`, row i of column a at `a * n + i`).
#[inline(always)]
fn back_rows(
    l: Rows,
    cols: &mut [&mut [f64]],
    start: impl Fn(usize) -> usize,
    hand: Option<(&Handoff, &Handoff)>,
) {
    let n = cols[0].len();
    let first = start(n.saturating_sub(ROWS));
    let (mut taken, mut end) = (first, n);
    let mut xs = Vec::with_capacity(cols.len());
    while end > 0 {
        let top = end.saturating_sub(ROWS);
        let c = start(top);
        if let Some((passed, _)) = hand.filter(|_| c < taken) {
            passed.wait(first - c);
            for (a, col) in cols.iter_mut().enumerate() {
                for (j, v) in col[c..taken].iter_mut().enumerate() {
                    *v = passed.get(a * first + c + j);
                }
            }
            taken = c;
        }
        for col in cols.iter_mut() {
            back_triangle(l, col, top, end);
        }
        if let Some((_, solved)) = hand {
            for (a, col) in cols.iter().enumerate() {
                for i in top..end {
                    solved.put(a * n + i, col[i]);
                }
            }
            solved.ready(n - top);
        }
        if top > c {
            xs.clear();
            xs.extend(cols.iter().map(|col| block_values(top, end, |i| col[i])));
            subtract_block(l, cols, c, top - c, top..end, &xs);
        }
        end = top;
    }
}

/// A block's solved values, the last row's first (a short block's missing ones repeat its
/// first row's, never used).
#[inline(always)]
fn block_values(top: usize, end: usize, x: impl Fn(usize) -> f64) -> [f64; ROWS] {
    std::array::from_fn(|r| x((end - 1 - r).max(top)))
}

/// Rows `top..end` of the back substitution of one column among themselves: each row's value,
/// and its products taken off the rows of the block above it, the last row first.
#[inline(always)]
fn back_triangle(l: Rows, col: &mut [f64], top: usize, end: usize) {
    for i in (top..end).rev() {
        let row = l.row(i);
        let xi = col[i] / row[i];
        col[i] = xi;
        for (v, lv) in col[top..i].iter_mut().zip(&row[top..i]) {
            *v -= lv * xi;
        }
    }
}

/// Values `c0..c0 + width` of every column minus the products of the rows `rows` (their solved
/// values in `xs[a]`, the last row's first), in decreasing row: a full block's four rows held
/// in registers over a segment of the columns at a time, so that the block's part of L is read
/// once for every column.
#[inline(always)]
fn subtract_block(
    l: Rows,
    cols: &mut [&mut [f64]],
    c0: usize,
    width: usize,
    rows: std::ops::Range<usize>,
    xs: &[[f64; ROWS]],
) {
    let (top, end, span) = (rows.start, rows.end, c0..c0 + width);
    if end - top == ROWS {
        let rows: [&[f64]; ROWS] = std::array::from_fn(|r| &l.row(end - 1 - r)[span.clone()]);
        for j in (0..width).step_by(BACK_SEGMENT) {
            let seg = j..(j + BACK_SEGMENT).min(width);
            for (col, x) in cols.iter_mut().zip(xs) {
                let col = &mut col[span.clone()][seg.clone()];
                back_segment(col, rows.map(|r| &r[seg.clone()]), *x);
            }
        }
        return;
    }
    for (col, x) in cols.iter_mut().zip(xs) {
        for (r, i) in (top..end).rev().enumerate() {
            for (v, lv) in col[span.clone()].iter_mut().zip(&l.row(i)[span.clone()]) {
                *v -= lv * x[r];
            }
        }
    }
}

/// Values of a column minus a block's products, the last row's first (`rows[0]`, `x[0]`), held
/// in a register between them.
#[inline(always)]
fn back_segment(col: &mut [f64], rows: [&[f64]; ROWS], x: [f64; ROWS]) {
    let [r0, r1, r2, r3] = rows;
    for ((((v, l0), l1), l2), l3) in col.iter_mut().zip(r0).zip(r1).zip(r2).zip(r3) {
        let mut c = *v;
        c -= l0 * x[0];
        c -= l1 * x[1];
        c -= l2 * x[2];
        c -= l3 * x[3];
        *v = c;
    }
}

/// The back helper: the values before each block's split (its copy `low`, the first block's
/// split long), minus the block's products once the leader has handed its solved values over;
/// the values the split has passed handed to the leader before each block.
fn back_helper(l: Rows, mut low: Vec<Vec<f64>>, n: usize, solved: &Handoff, passed: &Handoff) {
    let first = low[0].len();
    let (mut owned, mut end) = (first, n);
    let mut cols: Vec<&mut [f64]> = low.iter_mut().map(|c| &mut c[..]).collect();
    let mut xs = Vec::with_capacity(cols.len());
    while owned > 0 {
        let top = end.saturating_sub(ROWS);
        let c = split_at(top);
        if c < owned {
            for (a, col) in cols.iter().enumerate() {
                for (j, v) in col[c..owned].iter().enumerate() {
                    passed.put(a * first + c + j, *v);
                }
            }
            passed.ready(first - c);
            owned = c;
        }
        if c > 0 {
            solved.wait(n - top);
            xs.clear();
            xs.extend((0..cols.len()).map(|a| block_values(top, end, |i| solved.get(a * n + i))));
            subtract_block(l, &mut cols, 0, c, top..end, &xs);
        }
        end = top;
    }
}

/// Values handed from one lane to the other: stored one by one, then marked ready up to a
/// count (release), read after the count is seen (acquire).
struct Handoff<'l> {
    values: Vec<AtomicU64>,
    ready: AtomicUsize,
    /// The lanes the two sides run on, whose way of pausing a wait uses.
    lanes: &'l dyn Lanes,
}

impl<'l> Handoff<'l> {
    fn new(len: usize, lanes: &'l dyn Lanes) -> Handoff<'l> {
        Handoff {
            values: (0..len).map(|_| AtomicU64::new(0)).collect(),
            ready: AtomicUsize::new(0),
            lanes,
        }
    }

    fn put(&self, at: usize, v: f64) {
        self.values[at].store(v.to_bits(), Ordering::Relaxed);
    }

    fn get(&self, at: usize) -> f64 {
        f64::from_bits(self.values[at].load(Ordering::Relaxed))
    }

    /// The values counted up to `count` are stored.
    fn ready(&self, count: usize) {
        self.ready.store(count, Ordering::Release);
    }

    /// Waits until the values counted up to `count` are stored: spinning a while, then
    /// pausing as the lanes do ([`Lanes::pause`]).
    fn wait(&self, count: usize) {
        let mut spins = 0u32;
        while self.ready.load(Ordering::Acquire) < count {
            if spins < 1 << 12 {
                std::hint::spin_loop();
                spins += 1;
            } else {
                self.lanes.pause();
            }
        }
    }

    /// Marks every value ready when dropped, so that the other lane never waits on one that
    /// stopped (a panic, which the lanes pass on once both jobs end).
    fn finish_on_drop(&self) -> impl Drop + '_ {
        struct Finish<'a, 'l>(&'a Handoff<'l>);
        impl Drop for Finish<'_, '_> {
            fn drop(&mut self) {
                self.0.ready(usize::MAX);
            }
        }
        Finish(self)
    }
}

#[cfg(test)]
mod tests {
    use super::super::lanes::{Backwards, Serial};
    use super::*;

    /// A lower triangle of `n` rows with a diagonal near 1 and small scattered values below it,
    /// so that the solves neither grow nor vanish.
    fn triangle(n: usize) -> Vec<f64> {
        let scale = 1.0 / (n as f64).sqrt();
        (0..n)
            .flat_map(|i| (0..=i).map(move |j| (i, j)))
            .map(|(i, j)| {
                let h = ((i * 7919 + j * 104_729) % 1009) as f64 / 1009.0 - 0.5;
                if i == j {
                    1.0 + h / 4.0
                } else {
                    h * scale
                }
            })
            .collect()
    }

    /// Sizes from which two lanes would split the solves, and one below.
    const SIZES: [usize; 3] = [SPLIT_FROM + 37, SPLIT_FROM + 2 * 128 + 2, SPLIT_FROM - 1];

    #[test]
    fn the_forward_substitution_is_the_row_by_row_one_to_the_bit() {
        for n in SIZES {
            let l = triangle(n);
            let rows = Rows(&l);
            let k: Vec<f64> = (0..n)
                .map(|i| ((i * 31) % 17) as f64 / 17.0 - 0.4)
                .collect();
            // One row at a time, each product subtracted as it comes.
            let mut want = vec![0.0; n];
            for (i, &ki) in k.iter().enumerate() {
                let mut s = ki;
                for (lj, wj) in rows.row(i).iter().zip(&want[..i]) {
                    s -= lj * wj;
                }
                want[i] = s / rows.row(i)[i];
            }
            assert!(want.iter().all(|v| v.is_finite() && v.abs() < 1e3));
            let got = forward(rows, &k, &Serial);
            let same = got
                .iter()
                .zip(&want)
                .all(|(g, w)| g.to_bits() == w.to_bits());
            assert!(same, "{n} rows");
        }
    }

    #[test]
    fn the_back_substitution_is_the_row_by_row_one_to_the_bit() {
        for (n, m) in SIZES.into_iter().zip([2, 3, 1]) {
            let l = triangle(n);
            let rows = Rows(&l);
            let w: Vec<f64> = (0..n * m)
                .map(|p| ((p * 13) % 29) as f64 / 29.0 - 0.5)
                .collect();
            // Row-major from the last row, each product subtracted as it comes.
            let mut want = w.clone();
            for i in (0..n).rev() {
                for a in 0..m {
                    want[a * n + i] /= rows.row(i)[i];
                }
                for k in 0..i {
                    for a in 0..m {
                        want[a * n + k] -= rows.row(i)[k] * want[a * n + i];
                    }
                }
            }
            assert!(want.iter().all(|v| v.is_finite() && v.abs() < 1e3));
            let mut got = w.clone();
            back(rows, &mut got, n, &Serial);
            let same = got
                .iter()
                .zip(&want)
                .all(|(g, w)| g.to_bits() == w.to_bits());
            assert!(same, "{n} rows, {m} columns");
        }
    }

    /// Lanes that say they run their jobs at once (for the choice alone: the split solves on
    /// threads are checked against the fitted factor by `alfd_harness::Threads`'s tests).
    struct Claims(usize);

    impl Lanes for Claims {
        fn width(&self) -> usize {
            self.0
        }
        fn run<'a>(&self, _: Vec<Box<dyn FnOnce() + Send + 'a>>) {
            unreachable!("only asked whether it would split")
        }
        fn concurrent(&self) -> bool {
            true
        }
    }

    #[test]
    fn only_lanes_that_run_at_once_and_enough_rows_are_split() {
        assert!(split(&Claims(2), SPLIT_FROM));
        assert!(!split(&Claims(2), SPLIT_FROM - 1));
        assert!(!split(&Claims(1), SPLIT_FROM));
        // Lanes that run their jobs one after another would leave a helper waiting forever.
        assert!(!split(&Backwards(2), SPLIT_FROM));
        assert!(!split(&Serial, SPLIT_FROM));
    }

    #[test]
    fn the_split_never_passes_its_rows_and_never_moves_back() {
        let mut last = 0;
        for i in 0..5000 {
            let c = split_at(i);
            assert!(c <= i / 2 && c >= last && c.is_multiple_of(8), "{i}: {c}");
            last = c;
        }
    }
}
