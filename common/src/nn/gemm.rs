//! The wide products of the MLP, `C = A B + beta C` (beta 0 or 1), in one fixed order of
//! operations whatever the CPU: every element of `C` is accumulated from zero over `k` in order
//! with fused multiply-adds, `acc = fma(a[i][p], b[p][j], acc)`, and then `beta C` is added. That
//! is the order of matrixmultiply's FMA kernels, which this replaces: on a CPU with FMA the
//! results are the same to the bit, and on one without, `f32::mul_add` (a correctly rounded
//! software FMA) gives them again, slower, instead of the different roundings of a multiply and
//! an add.
//!
//! With AVX2 and FMA (detected at run time) a block of 16 rows by 4 columns of `C` stays in
//! registers over the whole `k` loop; the rows are contiguous (column-major `A`, packed first when
//! it is a transposed view), the elements of `B` are broadcast. Vectorising over rows leaves each
//! element's order of operations as the scalar loop's, so the tails and the fallback give the
//! same bits.

/// A matrix as a slice and strides: element `(i, j)` is `data[i * rs + j * cs]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MatRef<'a> {
    pub data: &'a [f32],
    pub rs: usize,
    pub cs: usize,
}

impl MatRef<'_> {
    #[inline(always)]
    pub(crate) fn at(&self, i: usize, j: usize) -> f32 {
        self.data[i * self.rs + j * self.cs]
    }
}

/// `c = a b + beta c`, `a` of shape `(m, k)`, `b` of shape `(k, n)`, `c` column-major `(m, n)`
/// with leading dimension `m`; `beta` is 0 (then `c` is not read) or 1. `pack` is scratch space
/// for `a` when its rows are not contiguous.
///
/// Panics if a slice is too short for its shape or `beta` is neither 0 nor 1.
pub(crate) fn gemm(
    (m, k, n): (usize, usize, usize),
    a: MatRef<'_>,
    b: MatRef<'_>,
    beta: f32,
    c: &mut [f32],
    pack: &mut Vec<f32>,
) {
    assert!(beta == 0.0 || beta == 1.0, "beta must be 0 or 1");
    assert!(c.len() >= m * n, "c is too short");
    if m == 0 || n == 0 {
        return;
    }
    if k > 0 {
        assert!(
            a.data.len() > (m - 1) * a.rs + (k - 1) * a.cs,
            "a is too short"
        );
        assert!(
            b.data.len() > (k - 1) * b.rs + (n - 1) * b.cs,
            "b is too short"
        );
    }
    // Column-major with contiguous columns: `a[(i, p)]` at `i + p * m`.
    let a_cols: &[f32] = if a.rs == 1 && a.cs == m {
        &a.data[..m * k]
    } else {
        pack.resize(m * k, 0.0);
        #[cfg(target_arch = "x86_64")]
        if a.cs == 1 && x86::available() {
            x86::pack_transposed(a, (m, k), pack);
            return gemm_packed((m, k, n), pack, b, beta, c);
        }
        for (p, col) in pack.chunks_exact_mut(m).enumerate() {
            let src = &a.data[p * a.cs..];
            for (i, out) in col.iter_mut().enumerate() {
                *out = src[i * a.rs];
            }
        }
        pack
    };
    gemm_packed((m, k, n), a_cols, b, beta, c);
}

/// [`gemm`] once `a` is column-major with contiguous columns.
fn gemm_packed(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    beta: f32,
    c: &mut [f32],
) {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        x86::gemm((m, k, n), a, b, beta, c);
        return;
    }
    gemm_scalar((m, k, n), a, b, beta, c, 0, 0);
}

/// Set by [`use_portable_kernels`].
static PORTABLE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Makes this process use the portable kernels (no AVX2, `f32::mul_add` per element) even on a
/// CPU that has AVX2 and FMA: to check that they give the same numbers (the binaries call it
/// when `ALFD_PORTABLE_KERNELS=1`). Slow: every fused multiply-add is a software one.
pub fn use_portable_kernels(yes: bool) {
    PORTABLE.store(yes, std::sync::atomic::Ordering::Relaxed);
}

/// The single-core FMA peak probe of the benchmarks: `rounds` rounds of 12 independent chains of
/// 8-wide fused multiply-adds (`12 * 8 * 2 = 192` floating-point operations a round); returns a
/// value that depends on all of them. `None` without AVX2 and FMA.
pub fn fma_peak_probe(rounds: u64) -> Option<f32> {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return Some(x86::probe(rounds));
    }
    let _ = rounds;
    None
}

/// Runs `f` compiled for AVX2 when the CPU has it (and the portable kernels were not asked for), else as
/// it is: for element-wise loops and reductions whose order the source fixes, so that wider
/// registers change their speed, never their results (Rust never fuses a multiply and an add on
/// its own). `f` should be small and `#[inline(always)]` inside, so that it is compiled into the
/// AVX2 function.
#[inline(always)]
pub(crate) fn wide<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return x86::avx2(f);
    }
    f()
}

/// The reference order for rows `i0..m` of columns `j0..n` (all of `C` from `(0, 0)`).
#[inline(always)]
fn gemm_scalar(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    beta: f32,
    c: &mut [f32],
    i0: usize,
    j0: usize,
) {
    for j in j0..n {
        for i in i0..m {
            let mut acc = 0.0f32;
            for p in 0..k {
                acc = a[i + p * m].mul_add(b.at(p, j), acc);
            }
            let out = &mut c[i + j * m];
            *out = if beta == 0.0 { acc } else { acc + *out };
        }
    }
}

/// The AVX2+FMA kernels: the only unsafe code of the core (the intrinsics' loads and stores,
/// and calling functions compiled for features that were checked at run time).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use std::arch::x86_64::*;
    use std::sync::OnceLock;

    use super::MatRef;

    /// Whether the CPU has AVX2 and FMA and the portable kernels were not asked for
    /// ([`super::use_portable_kernels`]).
    pub(super) fn available() -> bool {
        static DETECTED: OnceLock<bool> = OnceLock::new();
        !super::PORTABLE.load(std::sync::atomic::Ordering::Relaxed)
            && *DETECTED.get_or_init(|| {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            })
    }

    /// `pack[i + p m] = a(i, p)` for `a` whose rows are contiguous (`a.cs == 1`): the source read
    /// row by row, written with raw pointers (the transposition of the weight gradients' operand).
    pub(super) fn pack_transposed(a: MatRef<'_>, (m, k): (usize, usize), pack: &mut [f32]) {
        assert!(a.cs == 1 && pack.len() >= m * k);
        if m == 0 || k == 0 {
            return;
        }
        assert!(a.data.len() >= (m - 1) * a.rs + k);
        let out = pack.as_mut_ptr();
        for i in 0..m {
            let row = &a.data[i * a.rs..i * a.rs + k];
            for (p, &v) in row.iter().enumerate() {
                // SAFETY: i < m and p < k, so i + p m < m k <= pack.len().
                unsafe { *out.add(i + p * m) = v };
            }
        }
    }

    /// [`super::wide`] once [`available`] said yes.
    #[inline(always)]
    pub(super) fn avx2<R>(f: impl FnOnce() -> R) -> R {
        assert!(available());
        // SAFETY: the CPU has AVX2 (asserted).
        unsafe { avx2_inner(f) }
    }

    #[target_feature(enable = "avx2")]
    unsafe fn avx2_inner<R>(f: impl FnOnce() -> R) -> R {
        f()
    }

    /// [`super::fma_peak_probe`] once [`available`] said yes.
    pub(super) fn probe(rounds: u64) -> f32 {
        assert!(available());
        // SAFETY: the CPU has AVX2 and FMA (asserted).
        unsafe { probe_avx2_fma(rounds) }
    }

    #[target_feature(enable = "avx2,fma")]
    unsafe fn probe_avx2_fma(rounds: u64) -> f32 {
        let mut acc = [_mm256_set1_ps(1.0); 12];
        let x = _mm256_set1_ps(0.999_999);
        let y = _mm256_set1_ps(1e-7);
        for _ in 0..rounds {
            for a in &mut acc {
                *a = _mm256_fmadd_ps(*a, x, y);
            }
        }
        let mut sum = _mm256_setzero_ps();
        for a in acc {
            sum = _mm256_add_ps(sum, a);
        }
        let mut out = [0.0f32; 8];
        // SAFETY: `out` holds 8 floats.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), sum) };
        out.iter().sum()
    }

    /// [`gemm_avx2_fma`] once [`available`] said yes.
    pub(super) fn gemm(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: MatRef<'_>,
        beta: f32,
        c: &mut [f32],
    ) {
        assert!(available());
        // SAFETY: the CPU has AVX2 and FMA (asserted); the caller checked the shapes.
        unsafe { gemm_avx2_fma(mkn, a, b, beta, c) }
    }

    /// `C` with AVX2 and FMA: blocks of 6 columns (then 4), and in each, blocks of 16 rows
    /// (then 8), all accumulated in registers over the whole `k` loop, the elements of `B`
    /// broadcast from where they are; the remaining rows and columns element by element, in the
    /// same order.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn gemm_avx2_fma(
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: MatRef<'_>,
        beta: f32,
        c: &mut [f32],
    ) {
        // Blocks of 6 columns (the last one narrower), and in each, blocks of 16 rows, then 8,
        // then the last 1-7 rows under a mask.
        let mut j = 0;
        while j < n {
            let width = (n - j).min(6);
            let mut i = 0;
            // SAFETY: every block reads rows i..i + 8 V (<= m, or fewer under the mask) of the k
            // columns of `a` (m * k values), elements (p, j..j + width) of `b` (p < k,
            // j + width <= n: within `b`'s slice, as `gemm` checked), and writes `c`'s rows
            // i..i + 8 V (or the masked ones) of those columns.
            unsafe {
                while i + 16 <= m {
                    match width {
                        6 => block::<2, 6, false>(m, k, a, b, beta, c, i, j, 8),
                        5 => block::<2, 5, false>(m, k, a, b, beta, c, i, j, 8),
                        4 => block::<2, 4, false>(m, k, a, b, beta, c, i, j, 8),
                        3 => block::<2, 3, false>(m, k, a, b, beta, c, i, j, 8),
                        2 => block::<2, 2, false>(m, k, a, b, beta, c, i, j, 8),
                        _ => block::<2, 1, false>(m, k, a, b, beta, c, i, j, 8),
                    }
                    i += 16;
                }
                while i + 8 <= m {
                    match width {
                        6 => block::<1, 6, false>(m, k, a, b, beta, c, i, j, 8),
                        5 => block::<1, 5, false>(m, k, a, b, beta, c, i, j, 8),
                        4 => block::<1, 4, false>(m, k, a, b, beta, c, i, j, 8),
                        3 => block::<1, 3, false>(m, k, a, b, beta, c, i, j, 8),
                        2 => block::<1, 2, false>(m, k, a, b, beta, c, i, j, 8),
                        _ => block::<1, 1, false>(m, k, a, b, beta, c, i, j, 8),
                    }
                    i += 8;
                }
                if i < m {
                    let rows = m - i;
                    match width {
                        6 => block::<1, 6, true>(m, k, a, b, beta, c, i, j, rows),
                        5 => block::<1, 5, true>(m, k, a, b, beta, c, i, j, rows),
                        4 => block::<1, 4, true>(m, k, a, b, beta, c, i, j, rows),
                        3 => block::<1, 3, true>(m, k, a, b, beta, c, i, j, rows),
                        2 => block::<1, 2, true>(m, k, a, b, beta, c, i, j, rows),
                        _ => block::<1, 1, true>(m, k, a, b, beta, c, i, j, rows),
                    }
                }
            }
            j += width;
        }
    }

    /// Rows `i..i + 8 (V - 1) + last` of columns `j..j + W`: the last vector of rows holds
    /// `last` (1-8) rows, loaded and stored under a mask when `MASKED`.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `i + 8 (V - 1) + last <= m`; `a` holds `m * k` values; `b`
    /// holds element `(k - 1, j + W - 1)` and every one before; `c` holds `m * (j + W)` values.
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn block<const V: usize, const W: usize, const MASKED: bool>(
        m: usize,
        k: usize,
        a: &[f32],
        b: MatRef<'_>,
        beta: f32,
        c: &mut [f32],
        i: usize,
        j: usize,
        last: usize,
    ) {
        debug_assert!((1..=8).contains(&last) && i + 8 * (V - 1) + last <= m);
        debug_assert!(MASKED || last == 8);
        debug_assert!(a.len() >= m * k && c.len() >= m * (j + W));
        let lanes: [i32; 8] = std::array::from_fn(|l| if l < last { -1 } else { 0 });
        let mask = _mm256_loadu_si256(lanes.as_ptr().cast());
        let load = |ptr: *const f32, v: usize| {
            if MASKED && v + 1 == V {
                _mm256_maskload_ps(ptr, mask)
            } else {
                _mm256_loadu_ps(ptr)
            }
        };
        let mut acc = [[_mm256_setzero_ps(); V]; W];
        let a = a.as_ptr().add(i);
        let b_cols: [*const f32; W] = std::array::from_fn(|q| b.data.as_ptr().add((j + q) * b.cs));
        for p in 0..k {
            let col = a.add(p * m);
            let mut av = [_mm256_setzero_ps(); V];
            for (v, x) in av.iter_mut().enumerate() {
                *x = load(col.add(8 * v), v);
            }
            for (acc, b_col) in acc.iter_mut().zip(b_cols) {
                let bb = _mm256_broadcast_ss(&*b_col.add(p * b.rs));
                for v in 0..V {
                    acc[v] = _mm256_fmadd_ps(av[v], bb, acc[v]);
                }
            }
        }
        let c = c.as_mut_ptr();
        for (q, acc) in acc.iter().enumerate() {
            for (v, &x) in acc.iter().enumerate() {
                let out = c.add(i + 8 * v + (j + q) * m);
                let x = if beta == 0.0 {
                    x
                } else {
                    _mm256_add_ps(x, load(out, v))
                };
                if MASKED && v + 1 == V {
                    _mm256_maskstore_ps(out, mask, x);
                } else {
                    _mm256_storeu_ps(out, x);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng as _;

    /// The reference: one element at a time, `acc = fma(a, b, acc)` over `k` in order.
    fn reference(
        (m, k, n): (usize, usize, usize),
        a: MatRef<'_>,
        b: MatRef<'_>,
        beta: f32,
        c: &[f32],
    ) -> Vec<f32> {
        let mut out = c.to_vec();
        for j in 0..n {
            for i in 0..m {
                let mut acc = 0.0f32;
                for p in 0..k {
                    acc = a.at(i, p).mul_add(b.at(p, j), acc);
                }
                out[i + j * m] = if beta == 0.0 { acc } else { acc + c[i + j * m] };
            }
        }
        out
    }

    #[test]
    fn every_shape_and_layout_gives_the_reference_order_to_the_bit() {
        let mut rng = crate::rng::seeded(11);
        let mut rand =
            |len: usize| -> Vec<f32> { (0..len).map(|_| rng.random_range(-1.0f32..1.0)).collect() };
        let mut pack = Vec::new();
        for (m, k, n) in [
            (64, 64, 64),
            (64, 4, 64),
            (17, 9, 5),
            (33, 64, 7),
            (8, 1, 4),
            (128, 128, 6),
            (64, 128, 128),
            (128, 64, 128),
            (1, 3, 1),
            (5, 0, 3),
        ] {
            let (a_data, b_data, c0) = (rand(m * k), rand(k * n), rand(m * n));
            // `a` column-major or as a transposed view; `b` column-major or transposed.
            let a_layouts = [(1, m), (k, 1)];
            let b_layouts = [(1, k), (n, 1)];
            for (ars, acs) in a_layouts {
                for (brs, bcs) in b_layouts {
                    let a = MatRef {
                        data: &a_data,
                        rs: ars,
                        cs: acs,
                    };
                    let b = MatRef {
                        data: &b_data,
                        rs: brs,
                        cs: bcs,
                    };
                    for beta in [0.0, 1.0] {
                        let mut c = c0.clone();
                        gemm((m, k, n), a, b, beta, &mut c, &mut pack);
                        let expected = reference((m, k, n), a, b, beta, &c0);
                        let same = c
                            .iter()
                            .zip(&expected)
                            .all(|(x, y)| x.to_bits() == y.to_bits());
                        assert!(
                            same,
                            "{m}x{k}x{n}, a ({ars}, {acs}), b ({brs}, {bcs}), beta {beta}"
                        );
                    }
                }
            }
        }
    }
}
