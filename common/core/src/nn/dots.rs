//! The thin products' dot products and the bias gradients' column sums, in the order of
//! [`dot4`], [`dot`] and [`sum`] (eight lanes of partial sums over the batch, folded as a tree,
//! then the tail): the same order with AVX2 (four or eight sums at a time in registers, folded
//! with the same additions) as element by element.

/// `out = a^T b` for column-major `a` `(m, k)`, `b` `(m, n)` and `out` `(k, n)`: `out[r + c k]`
/// is [`dot4`] of columns `r..r + 4` of `a` (blocks of four) or [`dot`] of column `r` (the last
/// `k % 4`) with column `c` of `b`.
///
/// Panics if a slice is too short for its shape.
pub(crate) fn tr_dots((m, k, n): (usize, usize, usize), a: &[f32], b: &[f32], out: &mut [f32]) {
    assert!(a.len() >= m * k && b.len() >= m * n && out.len() >= k * n);
    if m == 0 {
        out[..k * n].fill(0.0);
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if super::gemm::simd() {
        x86::tr_dots((m, k, n), a, b, out, None);
        return;
    }
    for (out_col, b_col) in out[..k * n]
        .chunks_exact_mut(k.max(1))
        .zip(b.chunks_exact(m))
    {
        tr_dots_column((m, k), a, b_col, out_col);
    }
}

/// [`tr_dots`] and the [`column_sums`] of `b` (into `sums`, `n` values) together: with the wide
/// kernels, one pass over `b` gives both, each with the bits it has alone.
///
/// Panics if a slice is too short for its shape.
pub(crate) fn tr_dots_and_sums(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: &[f32],
    out: &mut [f32],
    sums: &mut [f32],
) {
    assert!(sums.len() >= n && b.len() >= m * n);
    #[cfg(target_arch = "x86_64")]
    if super::gemm::simd() && m > 0 {
        x86::tr_dots((m, k, n), a, b, out, Some(&mut sums[..n]));
        return;
    }
    tr_dots((m, k, n), a, b, out);
    column_sums(m, &b[..m * n], &mut sums[..n]);
}

/// One column of [`tr_dots`], element by element.
#[inline(always)]
fn tr_dots_column((m, k): (usize, usize), a: &[f32], b_col: &[f32], out_col: &mut [f32]) {
    // Four columns of `a` against the same column of `b`.
    let mut outs = out_col.chunks_exact_mut(4);
    let mut blocks = a[..m * k].chunks_exact(4 * m);
    for (o, block) in (&mut outs).zip(&mut blocks) {
        let (a0, rest) = block.split_at(m);
        let (a1, rest) = rest.split_at(m);
        let (a2, a3) = rest.split_at(m);
        o.copy_from_slice(&dot4([a0, a1, a2, a3], b_col));
    }
    for (o, a_col) in outs
        .into_remainder()
        .iter_mut()
        .zip(blocks.remainder().chunks_exact(m))
    {
        *o = dot(a_col, b_col);
    }
}

/// `out[j] = sum(column j)` ([`sum`]) of the column-major matrix `data` with `rows` rows.
pub(crate) fn column_sums(rows: usize, data: &[f32], out: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if super::gemm::simd() && rows > 0 {
        x86::column_sums(rows, data, out);
        return;
    }
    for (o, col) in out.iter_mut().zip(data.chunks_exact(rows.max(1))) {
        *o = sum(col);
    }
}

/// Four dot products with the same `x`.
#[inline(always)]
pub(crate) fn dot4(w: [&[f32]; 4], x: &[f32]) -> [f32; 4] {
    let n = x.len();
    let full = n - n % 8;
    let mut acc = [[0.0f32; 8]; 4];
    let mut i = 0;
    while i < full {
        let xs = lanes(&x[i..i + 8]);
        for (acc, w) in acc.iter_mut().zip(&w) {
            let ws = lanes(&w[i..i + 8]);
            for ((s, w), x) in acc.iter_mut().zip(ws).zip(xs) {
                *s += w * x;
            }
        }
        i += 8;
    }
    let mut out = [0.0f32; 4];
    for ((o, a), w) in out.iter_mut().zip(&acc).zip(&w) {
        let t: f32 = w[full..n].iter().zip(&x[full..]).map(|(w, x)| w * x).sum();
        *o = ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7])) + t;
    }
    out
}

/// Eight values as an array, so that the compiler sees the length.
#[inline(always)]
fn lanes(v: &[f32]) -> [f32; 8] {
    let mut out = [0.0f32; 8];
    out.copy_from_slice(v);
    out
}

/// Dot product with sixteen independent accumulators, so that it vectorises and the additions
/// do not wait on one another.
#[inline(always)]
pub(crate) fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 16];
    let ca = a.chunks_exact(16);
    let cb = b.chunks_exact(16);
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for ((s, &x), &y) in acc.iter_mut().zip(x).zip(y) {
            *s += x * y;
        }
    }
    let mut half = [0.0f32; 8];
    for (h, (&lo, &hi)) in half.iter_mut().zip(acc[..8].iter().zip(&acc[8..])) {
        *h = lo + hi;
    }
    ((half[0] + half[4]) + (half[1] + half[5])) + ((half[2] + half[6]) + (half[3] + half[7])) + tail
}

/// Sum with eight independent accumulators, so that it vectorises.
#[inline(always)]
pub(crate) fn sum(a: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let chunks = a.chunks_exact(8);
    let tail: f32 = chunks.remainder().iter().sum();
    for x in chunks {
        for (s, &x) in acc.iter_mut().zip(x) {
            *s += x;
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// The AVX2 versions (unsafe: intrinsics on raw pointers, called once the CPU's features
/// were checked).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use std::arch::x86_64::*;

    use super::{dot, sum};

    /// [`super::tr_dots`], and [`super::tr_dots_and_sums`] when `sums` is given, once the CPU
    /// was found to have AVX2 and FMA, `m > 0`.
    pub(super) fn tr_dots(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        sums: Option<&mut [f32]>,
    ) {
        check(mkn, a, b, out, sums.as_deref());
        // SAFETY: the CPU has AVX2 and the slices hold their shapes (checked).
        unsafe { tr_dots_avx2(mkn, a, b, out, sums) }
    }

    /// Asserts what [`tr_dots_avx2`] needs: AVX2 and FMA, `m > 0`, and slices that hold
    /// their shapes.
    fn check(
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &[f32],
        sums: Option<&[f32]>,
    ) {
        assert!(super::super::gemm::simd() && m > 0);
        assert!(a.len() >= m * k && b.len() >= m * n && out.len() >= k * n);
        assert!(sums.is_none_or(|s| s.len() >= n));
    }

    /// [`super::tr_dots`], and the column sums of `b` into `sums` when given: while the
    /// first four columns of `a` meet each group of columns of `b` (or alone when `k < 4`).
    /// Groups of four columns where the CPU has AVX-512VL (its 32 registers hold their 16
    /// sums), of two elsewhere.
    ///
    /// # Safety
    /// The CPU has AVX2; `a`, `b` and `out` hold `m k`, `m n` and `k n` values, `sums` `n`,
    /// `m > 0`.
    unsafe fn tr_dots_avx2(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        sums: Option<&mut [f32]>,
    ) {
        // SAFETY: as this function's, and AVX-512VL where it is called.
        unsafe {
            if thirty_two_registers() {
                tr_dots_groups_of_4(mkn, a, b, out, sums);
            } else {
                tr_dots_groups_of_2(mkn, a, b, out, sums);
            }
        }
    }

    /// [`super::tr_dots_and_sums`] in groups of 2 columns whatever the CPU (for the tests: a
    /// CPU with AVX-512VL runs groups of 4).
    #[cfg(test)]
    pub(super) fn tr_dots_and_sums_in_pairs(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        sums: &mut [f32],
    ) {
        check(mkn, a, b, out, Some(sums));
        // SAFETY: the CPU has AVX2 and the slices hold their shapes (checked).
        unsafe { tr_dots_groups_of_2(mkn, a, b, out, Some(sums)) }
    }

    /// Whether the CPU has AVX-512F and AVX-512VL (and the products use AVX-512).
    fn thirty_two_registers() -> bool {
        static DETECTED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        super::super::gemm::avx512_available()
            && *DETECTED.get_or_init(|| std::arch::is_x86_feature_detected!("avx512vl"))
    }

    /// # Safety
    /// As [`tr_dots_avx2`]'s, and the CPU has AVX-512F and AVX-512VL.
    #[target_feature(enable = "avx2,avx512f,avx512vl")]
    unsafe fn tr_dots_groups_of_4(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        sums: Option<&mut [f32]>,
    ) {
        // SAFETY: as this function's.
        unsafe { tr_dots_groups::<4>(mkn, a, b, out, sums) }
    }

    /// # Safety
    /// As [`tr_dots_avx2`]'s.
    #[target_feature(enable = "avx2")]
    unsafe fn tr_dots_groups_of_2(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        sums: Option<&mut [f32]>,
    ) {
        // SAFETY: as this function's.
        unsafe { tr_dots_groups::<2>(mkn, a, b, out, sums) }
    }

    /// [`tr_dots_avx2`] with groups of up to `G` (2 or 4) columns of `b`.
    ///
    /// # Safety
    /// As [`tr_dots_avx2`]'s; inlined into a function compiled for AVX2.
    #[inline(always)]
    unsafe fn tr_dots_groups<const G: usize>(
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        mut sums: Option<&mut [f32]>,
    ) {
        let k4 = k - k % 4;
        if k4 == 0 {
            if let Some(sums) = sums.take() {
                column_sums_avx2(m, &b[..m * n], &mut sums[..n]);
            }
        }
        let mut c = 0;
        while c < n {
            let group = [G, 2, 1].into_iter().find(|&g| c + g <= n).unwrap_or(1);
            for r in (0..k4).step_by(4) {
                let sums = sums.as_deref_mut().filter(|_| r == 0);
                // SAFETY: columns r..r + 4 <= k of `a`, c..c + group <= n of `b`, and the
                // same elements of `out` (and of `sums`).
                unsafe {
                    let none: &mut [f32] = &mut [];
                    match (group, sums) {
                        (4, Some(s)) if G == 4 => dot4x::<4, true>(m, k, a, b, out, r, c, s),
                        (4, None) if G == 4 => dot4x::<4, false>(m, k, a, b, out, r, c, none),
                        (2, Some(s)) => dot4x::<2, true>(m, k, a, b, out, r, c, s),
                        (2, None) => dot4x::<2, false>(m, k, a, b, out, r, c, none),
                        (_, Some(s)) => dot4x::<1, true>(m, k, a, b, out, r, c, s),
                        (_, None) => dot4x::<1, false>(m, k, a, b, out, r, c, none),
                    }
                }
            }
            for c in c..c + group {
                let b_col = &b[c * m..(c + 1) * m];
                for r in k4..k {
                    out[r + c * k] = dot(&a[r * m..(r + 1) * m], b_col);
                }
            }
            c += group;
        }
    }

    /// [`super::dot4`] of columns `r..r + 4` of `a` with columns `c..c + C` of `b`, into
    /// `out[r..r + 4 + (c + q) k]`; with `SUM`, also [`super::sum`] of those columns of `b`
    /// into `sums[c..c + C]` (as [`column_sums_avx2`] adds them: the same loads, another
    /// accumulator).
    ///
    /// # Safety
    /// The CPU has AVX2; `r + 4 <= k`, `c + C <= n`, and the slices hold their shapes (`sums`
    /// `n` values when `SUM`); inlined into a function compiled for AVX2.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn dot4x<const C: usize, const SUM: bool>(
        m: usize,
        k: usize,
        a: &[f32],
        b: &[f32],
        out: &mut [f32],
        r: usize,
        c: usize,
        sums: &mut [f32],
    ) {
        let full = m - m % 8;
        // SAFETY: columns r..r + 4 of `a` and c..c + C of `b` start inside their slices
        // (`r + 4 <= k`, `c + C <= n`, the slices hold `m × k` and `m × n` values).
        let a_cols: [*const f32; 4] =
            std::array::from_fn(|o| unsafe { a.as_ptr().add((r + o) * m) });
        // SAFETY: as above.
        let b_cols: [*const f32; C] =
            std::array::from_fn(|q| unsafe { b.as_ptr().add((c + q) * m) });
        let mut acc = [[_mm256_setzero_ps(); 4]; C];
        let mut col_sums = [_mm256_setzero_ps(); C];
        for i in (0..full).step_by(8) {
            // SAFETY: i + 8 <= m within each column.
            unsafe {
                let w: [__m256; 4] = std::array::from_fn(|o| _mm256_loadu_ps(a_cols[o].add(i)));
                for ((acc, b_col), col_sum) in acc.iter_mut().zip(b_cols).zip(&mut col_sums) {
                    let x = _mm256_loadu_ps(b_col.add(i));
                    if SUM {
                        *col_sum = _mm256_add_ps(*col_sum, x);
                    }
                    for (s, w) in acc.iter_mut().zip(w) {
                        *s = _mm256_add_ps(*s, _mm256_mul_ps(w, x));
                    }
                }
            }
        }
        if SUM {
            // Folded four at a time as `column_sums_avx2` folds them (each lane on its own).
            let folded = fold4(std::array::from_fn(|q| col_sums[q % C]));
            let totals = if full < m {
                let t: [f32; 4] = std::array::from_fn(|q| {
                    b[(c + q % C) * m + full..(c + q % C + 1) * m].iter().sum()
                });
                // SAFETY: `t` holds 4 floats.
                _mm_add_ps(folded, unsafe { _mm_loadu_ps(t.as_ptr()) })
            } else {
                folded
            };
            sums[c..c + C].copy_from_slice(&to_array(totals)[..C]);
        }
        for (q, acc) in acc.iter().enumerate() {
            let folded = fold4(*acc);
            // The tails as `dot4` adds them. An empty one is left out: the lanes start at +0,
            // so `folded` is never −0, and adding a zero of either sign to it changes nothing.
            let sums = if full < m {
                let b_col = &b[(c + q) * m..(c + q + 1) * m];
                let t: [f32; 4] = std::array::from_fn(|o| {
                    let w = &a[(r + o) * m..(r + o + 1) * m];
                    w[full..m]
                        .iter()
                        .zip(&b_col[full..])
                        .map(|(w, x)| w * x)
                        .sum()
                });
                // SAFETY: `t` holds 4 floats.
                _mm_add_ps(folded, unsafe { _mm_loadu_ps(t.as_ptr()) })
            } else {
                folded
            };
            let at = r + (c + q) * k;
            out[at..at + 4].copy_from_slice(&to_array(sums));
        }
    }

    /// `((a0 + a4) + (a1 + a5)) + ((a2 + a6) + (a3 + a7))` of each of four vectors, as
    /// [`super::dot4`] and [`super::sum`] fold their lanes.
    #[inline(always)]
    fn fold4(acc: [__m256; 4]) -> __m128 {
        // SAFETY (of the intrinsics): the callers are compiled for AVX2.
        unsafe {
            // (a0 + a4, a1 + a5, a2 + a6, a3 + a7) of vectors 0 and 1, then 2 and 3.
            let b01 = _mm256_add_ps(
                _mm256_permute2f128_ps::<0x20>(acc[0], acc[1]),
                _mm256_permute2f128_ps::<0x31>(acc[0], acc[1]),
            );
            let b23 = _mm256_add_ps(
                _mm256_permute2f128_ps::<0x20>(acc[2], acc[3]),
                _mm256_permute2f128_ps::<0x31>(acc[2], acc[3]),
            );
            // [c0, d0, c2, d2 | c1, d1, c3, d3] with c = (a0 + a4) + (a1 + a5), d = the rest.
            let h = _mm256_hadd_ps(b01, b23);
            // [c0 + d0, c2 + d2, .. | c1 + d1, c3 + d3, ..]
            let h = _mm256_hadd_ps(h, h);
            _mm_unpacklo_ps(_mm256_castps256_ps128(h), _mm256_extractf128_ps::<1>(h))
        }
    }

    #[inline(always)]
    fn to_array(v: __m128) -> [f32; 4] {
        let mut out = [0.0f32; 4];
        // SAFETY: `out` holds 4 floats.
        unsafe { _mm_storeu_ps(out.as_mut_ptr(), v) };
        out
    }

    /// [`super::column_sums`] once the CPU was found to have AVX2, `rows > 0`.
    pub(super) fn column_sums(rows: usize, data: &[f32], out: &mut [f32]) {
        assert!(super::super::gemm::simd() && rows > 0);
        // SAFETY: the CPU has AVX2 (asserted).
        unsafe { column_sums_avx2(rows, data, out) }
    }

    #[target_feature(enable = "avx2")]
    fn column_sums_avx2(rows: usize, data: &[f32], out: &mut [f32]) {
        let cols = out.len().min(data.len() / rows);
        let full = rows - rows % 8;
        let mut j = 0;
        while j + 4 <= cols {
            let col = |q: usize| &data[(j + q) * rows..(j + q + 1) * rows];
            let mut acc = [_mm256_setzero_ps(); 4];
            for i in (0..full).step_by(8) {
                for (q, s) in acc.iter_mut().enumerate() {
                    let x = &col(q)[i..i + 8];
                    // SAFETY: `x` holds 8 floats.
                    *s = _mm256_add_ps(*s, unsafe { _mm256_loadu_ps(x.as_ptr()) });
                }
            }
            // As in `dot4x`, an empty tail adds nothing.
            let sums = if full < rows {
                let t: [f32; 4] = std::array::from_fn(|q| col(q)[full..].iter().sum());
                // SAFETY: `t` holds 4 floats.
                _mm_add_ps(fold4(acc), unsafe { _mm_loadu_ps(t.as_ptr()) })
            } else {
                fold4(acc)
            };
            out[j..j + 4].copy_from_slice(&to_array(sums));
            j += 4;
        }
        for (o, col) in out[j..cols]
            .iter_mut()
            .zip(data[j * rows..].chunks_exact(rows))
        {
            *o = sum(col);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng as _;

    #[test]
    fn columns_of_negative_zeros_sum_as_element_by_element() {
        // The wide loops leave out an empty tail; the lanes start at +0, so a folded sum is
        // never −0 and adding the tail's zero (either sign) would change nothing.
        let (m, k, n) = (64, 4, 4);
        let zeros = vec![-0.0f32; m * k.max(n)];
        let mut sums = vec![1.0f32; n];
        column_sums(m, &zeros[..m * n], &mut sums);
        let mut dots = vec![1.0f32; k * n];
        let ones = vec![1.0f32; m * n];
        tr_dots((m, k, n), &zeros[..m * k], &ones, &mut dots);
        let expected = sum(&zeros[..m]);
        assert_eq!(expected.to_bits(), 0.0f32.to_bits());
        assert!(sums
            .iter()
            .chain(&dots)
            .all(|v| v.to_bits() == expected.to_bits()));
    }

    #[test]
    fn tr_dots_and_column_sums_give_the_element_by_element_order_to_the_bit() {
        let mut rng = crate::rng::seeded(12);
        let mut rand = |len: usize| -> Vec<f32> {
            (0..len)
                .map(|i| match i % 29 {
                    0 => 0.0,
                    1 => -0.0,
                    _ => rng.random_range(-1.0f32..1.0),
                })
                .collect()
        };
        for (m, k, n) in [
            (64, 64, 4),
            (64, 4, 64),
            (64, 128, 4),
            (60, 4, 64),
            (64, 8, 6),
            (64, 3, 5),
            (13, 7, 3),
            (67, 5, 2),
            (5, 4, 1),
            (1, 9, 6),
            (8, 4, 4),
            (0, 4, 3),
        ] {
            let (a, b) = (rand(m * k), rand(m * n));
            let mut expected = vec![f32::NAN; k * n];
            if m == 0 {
                expected.fill(0.0);
            } else {
                for (out_col, b_col) in expected.chunks_exact_mut(k).zip(b.chunks_exact(m)) {
                    tr_dots_column((m, k), &a, b_col, out_col);
                }
            }
            let mut out = vec![f32::NAN; k * n];
            tr_dots((m, k, n), &a, &b, &mut out);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&out), bits(&expected), "tr_dots {m}x{k}x{n}");
            let mut sums = vec![f32::NAN; n];
            let mut both = vec![f32::NAN; k * n];
            tr_dots_and_sums((m, k, n), &a, &b, &mut both, &mut sums);
            assert_eq!(bits(&both), bits(&expected), "tr_dots_and_sums {m}x{k}x{n}");
            #[cfg(target_arch = "x86_64")]
            if super::super::gemm::simd() && m > 0 {
                let (mut pairs, mut pair_sums) = (vec![f32::NAN; k * n], vec![f32::NAN; n]);
                x86::tr_dots_and_sums_in_pairs((m, k, n), &a, &b, &mut pairs, &mut pair_sums);
                assert_eq!(bits(&pairs), bits(&expected), "in pairs {m}x{k}x{n}");
                assert_eq!(bits(&pair_sums), bits(&sums), "in pairs' sums {m}x{n}");
            }
            if m > 0 {
                let expected: Vec<f32> = b.chunks_exact(m).map(sum).collect();
                let mut out = vec![f32::NAN; n];
                column_sums(m, &b, &mut out);
                assert_eq!(bits(&out), bits(&expected), "column_sums {m}x{n}");
                assert_eq!(
                    bits(&sums),
                    bits(&expected),
                    "tr_dots_and_sums' sums {m}x{n}"
                );
            }
        }
    }
}
