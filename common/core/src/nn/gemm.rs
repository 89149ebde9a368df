//! The wide products of the MLP, `C = A B + beta C` (beta 0 or 1), in one fixed order of
//! operations whatever the CPU: every element of `C` is accumulated from zero over `k` in order
//! with fused multiply-adds, `acc = fma(a[i][p], b[p][j], acc)`, and then `beta C` is added. That
//! is the order of matrixmultiply's FMA kernels, which this replaces: on a CPU with FMA the
//! results are the same to the bit, and on one without, `f32::mul_add` (a correctly rounded
//! software FMA) gives them again, slower, instead of the different roundings of a multiply and
//! an add.
//!
//! With AVX2 and FMA (detected at run time) a block of 16 rows by 6 columns of `C` stays in
//! registers over the whole `k` loop (with AVX-512, 32 rows by 4 or 6 columns:
//! `gemm/avx512.rs`); the rows are contiguous (column-major `A`, packed first when it is a
//! transposed view), the elements of `B` are broadcast. Vectorising over rows leaves each
//! element's order of operations as the scalar loop's, so the tails and the fallback give the
//! same bits. The layers' bias, ReLU and ReLU's backward mask are applied as a block is stored
//! ([`Epi`]), with the operations and order of the separate passes they replace. The thin
//! products ([`thin`]: a dimension of 5 or less) use the same blocks with a rounded multiply and
//! an add in place of each fused multiply-add: the order of the axpys they were before.

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

/// What becomes of an element's products, `acc`, at `(i, j)` of `C` (column-major, leading
/// dimension `m`). In [`gemm`], `acc` is the fused sum from zero and then:
#[derive(Debug, Clone, Copy)]
pub(crate) enum Epi<'a> {
    /// `c = acc` (`beta = 0`: `c` is not read).
    Set,
    /// `c = acc + c` (`beta = 1`).
    #[cfg_attr(not(test), allow(dead_code))]
    Add,
    /// `c = acc + bias[j]`, then `max(c, 0)` if the flag says so: the same numbers as filling
    /// `c` with the bias, [`Epi::Add`], then a ReLU pass.
    Bias(&'a [f32], bool),
    /// `c = acc` where `h[i + j m] > 0`, else `0`: [`Epi::Set`] then ReLU's backward mask.
    Mask(&'a [f32]),
}

impl Epi<'_> {
    fn check(&self, m: usize, n: usize) {
        match self {
            Epi::Bias(bias, _) => assert!(bias.len() >= n, "bias is too short"),
            Epi::Mask(h) => assert!(h.len() >= m * n, "mask is too short"),
            Epi::Set | Epi::Add => {}
        }
    }

    /// Where a sum of products starts in [`thin`]: `0`, `c` or the bias.
    #[inline(always)]
    fn start(&self, c: f32, j: usize) -> f32 {
        match self {
            Epi::Set | Epi::Mask(_) => 0.0,
            Epi::Add => c,
            Epi::Bias(bias, _) => bias[j],
        }
    }

    /// The last step of [`thin`] (the ReLU or its mask).
    #[inline(always)]
    fn finish(&self, y: f32, i: usize, j: usize, m: usize) -> f32 {
        match self {
            // `y.max(0.0)` as it compiles on x86 (`maxps y, 0`), spelt out: 0 for a NaN and -0.
            Epi::Bias(_, true) => {
                if y > 0.0 {
                    y
                } else {
                    0.0
                }
            }
            Epi::Mask(h) if h[i + j * m] > 0.0 => y,
            Epi::Mask(_) => 0.0,
            _ => y,
        }
    }

    /// The end of [`gemm`]'s element: `acc` plus `c` or the bias, then the ReLU or its mask.
    #[inline(always)]
    fn fused(&self, acc: f32, c: f32, i: usize, j: usize, m: usize) -> f32 {
        let y = match self {
            Epi::Set | Epi::Mask(_) => acc,
            Epi::Add => acc + c,
            Epi::Bias(bias, _) => acc + bias[j],
        };
        self.finish(y, i, j, m)
    }
}

/// `c = a b + beta c` and the other endings of [`Epi`], `a` of shape `(m, k)`, `b` of shape
/// `(k, n)`, `c` column-major `(m, n)` with leading dimension `m`. `pack` is scratch space for
/// `a` when its rows are not contiguous.
///
/// Panics if a slice is too short for its shape.
pub(crate) fn gemm(
    (m, k, n): (usize, usize, usize),
    a: MatRef<'_>,
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
    pack: &mut Vec<f32>,
) {
    assert!(c.len() >= m * n, "c is too short");
    epi.check(m, n);
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
            return gemm_packed((m, k, n), pack, b, epi, c);
        }
        for (p, col) in pack.chunks_exact_mut(m).enumerate() {
            let src = &a.data[p * a.cs..];
            for (i, out) in col.iter_mut().enumerate() {
                *out = src[i * a.rs];
            }
        }
        pack
    };
    gemm_packed((m, k, n), a_cols, b, epi, c);
}

/// [`gemm`] once `a` is column-major with contiguous columns.
fn gemm_packed(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
) {
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        avx512::gemm::<true>((m, k, n), a, b, epi, c);
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        x86::gemm::<true>((m, k, n), a, b, epi, c);
        return;
    }
    gemm_portable((m, k, n), a, b, epi, c);
}

/// [`gemm_packed`] one element at a time.
fn gemm_portable(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
) {
    for j in 0..n {
        for i in 0..m {
            let mut acc = 0.0f32;
            for p in 0..k {
                acc = a[i + p * m].mul_add(b.at(p, j), acc);
            }
            let out = &mut c[i + j * m];
            *out = epi.fused(acc, *out, i, j, m);
        }
    }
}

/// The thin products' order (a dimension of 5 or less; see `nn::mlp`): every element of `C`
/// starts where [`Epi::start`] says (`0`, `c` or the bias) and adds the products one by one,
/// `y = y + b[p][j] * a[i][p]` over `p` in order, each product rounded (no fused multiply-add),
/// then the ReLU or its mask. `a` is column-major `(m, k)` with leading dimension `m`.
///
/// Panics if a slice is too short for its shape.
pub(crate) fn thin(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
) {
    assert!(c.len() >= m * n, "c is too short");
    epi.check(m, n);
    if m == 0 || n == 0 {
        return;
    }
    if k > 0 {
        assert!(a.len() >= m * k, "a is too short");
        assert!(
            b.data.len() > (k - 1) * b.rs + (n - 1) * b.cs,
            "b is too short"
        );
    }
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        avx512::gemm::<false>((m, k, n), a, b, epi, c);
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        x86::gemm::<false>((m, k, n), a, b, epi, c);
        return;
    }
    thin_portable((m, k, n), a, b, epi, c);
}

/// [`thin`] one element at a time.
fn thin_portable(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
) {
    for j in 0..n {
        for i in 0..m {
            let out = &mut c[i + j * m];
            let mut y = epi.start(*out, j);
            for p in 0..k {
                y += b.at(p, j) * a[i + p * m];
            }
            *out = epi.finish(y, i, j, m);
        }
    }
}

/// Whether the AVX2+FMA kernels run (the CPU has them and the portable ones were not asked for).
pub(crate) fn simd() -> bool {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return true;
    }
    false
}

/// The single-core FMA peak probe of the benchmarks: `rounds` rounds of 12 independent chains of
/// fused multiply-adds as wide as the products' kernels use ([`fma_peak_flops_per_round`]);
/// returns a value that depends on all of them. `None` without AVX2 and FMA.
pub fn fma_peak_probe(rounds: u64) -> Option<f32> {
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        return Some(avx512::probe(rounds));
    }
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return Some(x86::probe(rounds));
    }
    let _ = rounds;
    None
}

/// The floating-point operations of one round of [`fma_peak_probe`]: `12 * 16 * 2 = 384` where
/// the products use AVX-512, `12 * 8 * 2 = 192` where they use AVX2; `None` without either.
pub fn fma_peak_flops_per_round() -> Option<u64> {
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        return Some(avx512::PROBE_FLOPS);
    }
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return Some(x86::PROBE_FLOPS);
    }
    None
}

/// Whether the products and the Cholesky tile use AVX-512: the CPU has AVX-512F besides AVX2
/// and FMA, and the portable kernels were not asked for.
pub(crate) fn avx512_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return avx512::available();
    #[cfg(not(target_arch = "x86_64"))]
    false
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

/// [`wide`], with AVX-512 where the CPU has it: for Adam's step, whose divisions and square
/// roots take as long in 16 lanes as in two times 8 on Zen 4 but whose other operations take
/// half the instructions (its time in `train_steps parts` is shorter so).
#[inline(always)]
pub(crate) fn widest<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        return avx512::wide(f);
    }
    wide(f)
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx512;

/// The AVX2+FMA kernels: unsafe code of the core, with `dots.rs`'s AVX2 dot products (the
/// intrinsics' loads and stores, and calling functions compiled for features that were checked
/// at run time).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use std::arch::x86_64::*;

    use super::{Epi, MatRef};

    /// Whether the CPU has AVX2 and FMA and the portable kernels were not asked for
    /// ([`crate::cpu::avx2_fma`]).
    pub(super) fn available() -> bool {
        crate::cpu::avx2_fma()
    }

    /// `pack[i + p m] = a(i, p)` for `a` whose rows are contiguous (`a.cs == 1`): the
    /// transposition of the weight gradients' operand, by blocks of 8 x 8 in registers, the
    /// edges one by one.
    pub(super) fn pack_transposed(a: MatRef<'_>, (m, k): (usize, usize), pack: &mut [f32]) {
        assert!(available() && a.cs == 1 && pack.len() >= m * k);
        if m == 0 || k == 0 {
            return;
        }
        assert!(a.data.len() >= (m - 1) * a.rs + k);
        // SAFETY: the CPU has AVX2 (asserted); the lengths are checked above.
        unsafe { pack_transposed_avx2(a, (m, k), pack) }
    }

    /// # Safety
    /// The CPU has AVX2; `a.data` holds rows `0..m` of `k` values at stride `a.rs`, `pack`
    /// holds `m * k` values.
    #[target_feature(enable = "avx2")]
    unsafe fn pack_transposed_avx2(a: MatRef<'_>, (m, k): (usize, usize), pack: &mut [f32]) {
        let src = a.data.as_ptr();
        let out = pack.as_mut_ptr();
        let (m8, k8) = (m - m % 8, k - k % 8);
        for i in (0..m8).step_by(8) {
            for p in (0..k8).step_by(8) {
                // SAFETY: rows i..i + 8 <= m, values p..p + 8 <= k of each; the columns
                // p..p + 8 of `pack` hold rows i..i + 8 (i + 8 <= m).
                unsafe {
                    let r: [__m256; 8] =
                        std::array::from_fn(|q| _mm256_loadu_ps(src.add((i + q) * a.rs + p)));
                    let t0 = _mm256_unpacklo_ps(r[0], r[1]);
                    let t1 = _mm256_unpackhi_ps(r[0], r[1]);
                    let t2 = _mm256_unpacklo_ps(r[2], r[3]);
                    let t3 = _mm256_unpackhi_ps(r[2], r[3]);
                    let t4 = _mm256_unpacklo_ps(r[4], r[5]);
                    let t5 = _mm256_unpackhi_ps(r[4], r[5]);
                    let t6 = _mm256_unpacklo_ps(r[6], r[7]);
                    let t7 = _mm256_unpackhi_ps(r[6], r[7]);
                    let s0 = _mm256_shuffle_ps::<0x44>(t0, t2);
                    let s1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
                    let s2 = _mm256_shuffle_ps::<0x44>(t1, t3);
                    let s3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
                    let s4 = _mm256_shuffle_ps::<0x44>(t4, t6);
                    let s5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
                    let s6 = _mm256_shuffle_ps::<0x44>(t5, t7);
                    let s7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
                    let cols = [
                        _mm256_permute2f128_ps::<0x20>(s0, s4),
                        _mm256_permute2f128_ps::<0x20>(s1, s5),
                        _mm256_permute2f128_ps::<0x20>(s2, s6),
                        _mm256_permute2f128_ps::<0x20>(s3, s7),
                        _mm256_permute2f128_ps::<0x31>(s0, s4),
                        _mm256_permute2f128_ps::<0x31>(s1, s5),
                        _mm256_permute2f128_ps::<0x31>(s2, s6),
                        _mm256_permute2f128_ps::<0x31>(s3, s7),
                    ];
                    for (q, col) in cols.into_iter().enumerate() {
                        _mm256_storeu_ps(out.add(i + (p + q) * m), col);
                    }
                }
            }
        }
        for i in 0..m {
            let ps = if i < m8 { k8..k } else { 0..k };
            for p in ps {
                // SAFETY: i < m and p < k.
                unsafe { *out.add(i + p * m) = *src.add(i * a.rs + p) };
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

    /// # Safety
    /// The CPU has AVX2 (the only caller, [`avx2`], asserts it).
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

    /// The flops of a round of [`probe`]: 12 chains of 8-lane fused multiply-adds.
    pub(super) const PROBE_FLOPS: u64 = 12 * 8 * 2;

    /// # Safety
    /// The CPU has AVX2 and FMA (the only caller, [`probe`], asserts it).
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

    /// [`gemm_avx2_fma`] once [`available`] said yes: [`super::gemm`]'s order when `FMA`,
    /// [`super::thin`]'s when not.
    pub(super) fn gemm<const FMA: bool>(
        mkn: (usize, usize, usize),
        a: &[f32],
        b: MatRef<'_>,
        epi: Epi<'_>,
        c: &mut [f32],
    ) {
        assert!(available());
        // SAFETY: the CPU has AVX2 and FMA (asserted); the caller checked the shapes.
        unsafe { gemm_avx2_fma::<FMA>(mkn, a, b, epi, c) }
    }

    /// `C` with AVX2 and FMA: blocks of 6 columns (then fewer), and in each, blocks of 16 rows
    /// (then 8), all accumulated in registers over the whole `k` loop, the elements of `B`
    /// broadcast from where they are; the last 1-7 rows under a mask, in the same order.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA, and `a`, `b` and `c` hold `m × k`, `k × n` and `m × n` values
    /// (the caller, [`gemm`], asserts the features; its callers check the shapes).
    #[target_feature(enable = "avx2,fma")]
    unsafe fn gemm_avx2_fma<const FMA: bool>(
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: MatRef<'_>,
        epi: Epi<'_>,
        c: &mut [f32],
    ) {
        macro_rules! widths {
            ($v:literal, $masked:literal, $i:expr, $width:expr, $j:expr, $last:expr) => {
                match $width {
                    6 => block::<$v, 6, $masked, FMA>(m, k, a, b, epi, c, $i, $j, $last),
                    5 => block::<$v, 5, $masked, FMA>(m, k, a, b, epi, c, $i, $j, $last),
                    4 => block::<$v, 4, $masked, FMA>(m, k, a, b, epi, c, $i, $j, $last),
                    3 => block::<$v, 3, $masked, FMA>(m, k, a, b, epi, c, $i, $j, $last),
                    2 => block::<$v, 2, $masked, FMA>(m, k, a, b, epi, c, $i, $j, $last),
                    _ => block::<$v, 1, $masked, FMA>(m, k, a, b, epi, c, $i, $j, $last),
                }
            };
        }
        let mut j = 0;
        while j < n {
            let width = (n - j).min(6);
            let mut i = 0;
            // SAFETY: every block reads rows i..i + 8 V (<= m, or fewer under the mask) of the k
            // columns of `a` (m * k values), elements (p, j..j + width) of `b` (p < k,
            // j + width <= n: within `b`'s slice, as the caller checked), the same elements
            // of `c` and of a mask (m * n values, checked), `bias[j..j + width]` (n values,
            // checked), and writes `c`'s rows i..i + 8 V (or the masked ones) of those columns.
            unsafe {
                while i + 16 <= m {
                    widths!(2, false, i, width, j, 8);
                    i += 16;
                }
                while i + 8 <= m {
                    widths!(1, false, i, width, j, 8);
                    i += 8;
                }
                if i < m {
                    widths!(1, true, i, width, j, m - i);
                }
            }
            j += width;
        }
    }

    /// Rows `i..i + 8 (V - 1) + last` of columns `j..j + W`: the last vector of rows holds
    /// `last` (1-8) rows, loaded and stored under a mask when `MASKED`. With `FMA`, each
    /// element is `fma`'d from zero and then ends as [`Epi::fused`]; without, it starts at
    /// [`Epi::start`], adds rounded products and ends as [`Epi::finish`].
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `i + 8 (V - 1) + last <= m`; `a` holds `m * k` values; `b`
    /// holds element `(k - 1, j + W - 1)` and every one before; `c` (and a mask) hold
    /// `m * (j + W)` values, a bias `j + W`.
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn block<const V: usize, const W: usize, const MASKED: bool, const FMA: bool>(
        m: usize,
        k: usize,
        a: &[f32],
        b: MatRef<'_>,
        epi: Epi<'_>,
        c: &mut [f32],
        i: usize,
        j: usize,
        last: usize,
    ) {
        debug_assert!((1..=8).contains(&last) && i + 8 * (V - 1) + last <= m);
        debug_assert!(MASKED || last == 8);
        debug_assert!(a.len() >= m * k && c.len() >= m * (j + W));
        let lanes: [i32; 8] = std::array::from_fn(|l| if l < last { -1 } else { 0 });
        let t = Tile {
            m,
            i,
            j,
            mask: _mm256_loadu_si256(lanes.as_ptr().cast()),
        };
        let c = c.as_mut_ptr();
        let mut acc = if FMA {
            [[_mm256_setzero_ps(); V]; W]
        } else {
            t.start::<V, W, MASKED>(epi, c)
        };
        let a = a.as_ptr().add(i);
        let b_cols: [*const f32; W] = std::array::from_fn(|q| b.data.as_ptr().add((j + q) * b.cs));
        for p in 0..k {
            let col = a.add(p * m);
            let mut av = [_mm256_setzero_ps(); V];
            for (v, x) in av.iter_mut().enumerate() {
                *x = t.load::<V, MASKED>(col.add(8 * v), v);
            }
            for (acc, b_col) in acc.iter_mut().zip(b_cols) {
                let bb = _mm256_broadcast_ss(&*b_col.add(p * b.rs));
                for v in 0..V {
                    acc[v] = if FMA {
                        _mm256_fmadd_ps(av[v], bb, acc[v])
                    } else {
                        _mm256_add_ps(acc[v], _mm256_mul_ps(bb, av[v]))
                    };
                }
            }
        }
        t.end::<V, W, MASKED, FMA>(&acc, epi, c);
    }

    /// Where a [`block`] sits in `c` (`m` rows, column-major): rows from `i`, columns from `j`;
    /// `mask` the lanes of its last vector of rows that a `MASKED` block loads and stores.
    #[derive(Clone, Copy)]
    struct Tile {
        m: usize,
        i: usize,
        j: usize,
        mask: __m256i,
    }

    impl Tile {
        /// The index in `c` of row vector `v` of column `j + q`.
        fn at(self, q: usize, v: usize) -> usize {
            self.i + 8 * v + (self.j + q) * self.m
        }

        /// Eight values from `ptr`, under the mask for the last vector `v` of a `MASKED` block.
        ///
        /// # Safety
        /// The CPU has AVX2; `ptr` holds the eight values (the masked ones where masked).
        #[target_feature(enable = "avx2,fma")]
        #[inline]
        unsafe fn load<const V: usize, const MASKED: bool>(
            self,
            ptr: *const f32,
            v: usize,
        ) -> __m256 {
            if MASKED && v + 1 == V {
                _mm256_maskload_ps(ptr, self.mask)
            } else {
                _mm256_loadu_ps(ptr)
            }
        }

        /// Column `j + q`'s bias in every lane, or zeros without a bias.
        ///
        /// # Safety
        /// The CPU has AVX2; a bias holds `j + q + 1` values.
        #[target_feature(enable = "avx2,fma")]
        #[inline]
        unsafe fn bias(self, epi: Epi<'_>, q: usize) -> __m256 {
            match epi {
                Epi::Bias(bias, _) => _mm256_broadcast_ss(&bias[self.j + q]),
                _ => _mm256_setzero_ps(),
            }
        }

        /// The sums of a block without `FMA` as they start: at `c` or the bias ([`Epi::start`]).
        ///
        /// # Safety
        /// As [`block`]'s.
        #[target_feature(enable = "avx2,fma")]
        #[inline]
        unsafe fn start<const V: usize, const W: usize, const MASKED: bool>(
            self,
            epi: Epi<'_>,
            c: *const f32,
        ) -> [[__m256; V]; W] {
            std::array::from_fn(|q| {
                std::array::from_fn(|v| match epi {
                    Epi::Add => self.load::<V, MASKED>(c.add(self.at(q, v)), v),
                    Epi::Bias(..) => self.bias(epi, q),
                    Epi::Set | Epi::Mask(_) => _mm256_setzero_ps(),
                })
            })
        }

        /// Ends a block's sums as [`Epi::fused`] (with `FMA`) or [`Epi::finish`] and stores them.
        ///
        /// # Safety
        /// As [`block`]'s.
        #[target_feature(enable = "avx2,fma")]
        #[inline]
        unsafe fn end<const V: usize, const W: usize, const MASKED: bool, const FMA: bool>(
            self,
            acc: &[[__m256; V]; W],
            epi: Epi<'_>,
            c: *mut f32,
        ) {
            let zero = _mm256_setzero_ps();
            for (q, acc) in acc.iter().enumerate() {
                for (v, &x) in acc.iter().enumerate() {
                    let out = c.add(self.at(q, v));
                    let x = match epi {
                        _ if !FMA => x,
                        Epi::Set | Epi::Mask(_) => x,
                        Epi::Add => _mm256_add_ps(x, self.load::<V, MASKED>(out, v)),
                        Epi::Bias(..) => _mm256_add_ps(x, self.bias(epi, q)),
                    };
                    let x = match epi {
                        // `max` returns its second operand (0) for a NaN and for -0:
                        // `f32::max(y, 0)` as it compiles on x86, and `Epi::finish`.
                        Epi::Bias(_, true) => _mm256_max_ps(x, zero),
                        Epi::Mask(h) => {
                            let h = self.load::<V, MASKED>(h.as_ptr().add(self.at(q, v)), v);
                            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(h, zero), x)
                        }
                        _ => x,
                    };
                    if MASKED && v + 1 == V {
                        _mm256_maskstore_ps(out, self.mask, x);
                    } else {
                        _mm256_storeu_ps(out, x);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng as _;

    /// The reference of [`gemm`]: one element at a time, `acc = fma(a, b, acc)` over `k` in
    /// order from zero, then the ending.
    fn reference(
        (m, k, n): (usize, usize, usize),
        a: MatRef<'_>,
        b: MatRef<'_>,
        epi: Epi<'_>,
        c: &[f32],
    ) -> Vec<f32> {
        let relu = |y: f32| if y > 0.0 { y } else { 0.0 };
        let mut out = c.to_vec();
        for j in 0..n {
            for i in 0..m {
                let mut acc = 0.0f32;
                for p in 0..k {
                    acc = a.at(i, p).mul_add(b.at(p, j), acc);
                }
                out[i + j * m] = match epi {
                    Epi::Set => acc,
                    Epi::Add => acc + c[i + j * m],
                    Epi::Bias(bias, false) => acc + bias[j],
                    Epi::Bias(bias, true) => relu(acc + bias[j]),
                    Epi::Mask(h) => {
                        if h[i + j * m] > 0.0 {
                            acc
                        } else {
                            0.0
                        }
                    }
                };
            }
        }
        out
    }

    /// The reference of [`thin`]: from the start value, `y += b * a` in order (as `nn::mlp`'s
    /// axpys did), then the ReLU (a pass of `max(y, 0)`) or its mask.
    fn reference_thin(
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: MatRef<'_>,
        epi: Epi<'_>,
        c: &[f32],
    ) -> Vec<f32> {
        let mut out = c.to_vec();
        for j in 0..n {
            for i in 0..m {
                let mut y = match epi {
                    Epi::Set | Epi::Mask(_) => 0.0,
                    Epi::Add => c[i + j * m],
                    Epi::Bias(bias, _) => bias[j],
                };
                for p in 0..k {
                    y += b.at(p, j) * a[i + p * m];
                }
                out[i + j * m] = y;
            }
        }
        match epi {
            Epi::Bias(_, true) => wide(|| out.iter_mut().for_each(|v| *v = v.max(0.0))),
            Epi::Mask(h) => {
                for (v, &h) in out.iter_mut().zip(h) {
                    *v = if h > 0.0 { *v } else { 0.0 };
                }
            }
            _ => {}
        }
        out
    }

    type Kernel = fn((usize, usize, usize), &[f32], MatRef<'_>, Epi<'_>, &mut [f32]);

    /// The SIMD kernels this CPU runs (name, fused order, thin order), each of them whichever
    /// the dispatch picks, so that every one is compared with the references.
    fn simd_kernels() -> Vec<(&'static str, Kernel, Kernel)> {
        let mut kernels: Vec<(&'static str, Kernel, Kernel)> = Vec::new();
        #[cfg(target_arch = "x86_64")]
        if x86::available() {
            kernels.push(("AVX2", x86::gemm::<true>, x86::gemm::<false>));
        }
        #[cfg(target_arch = "x86_64")]
        if avx512::available() {
            kernels.push(("AVX-512", avx512::gemm::<true>, avx512::gemm::<false>));
            // The block widths of AMD's and Intel's cores, whichever this one is.
            kernels.push((
                "AVX-512, blocks of 4 columns",
                |mkn, a, b, epi, c| avx512::gemm_in_blocks_of::<true>(4, mkn, a, b, epi, c),
                |mkn, a, b, epi, c| avx512::gemm_in_blocks_of::<false>(4, mkn, a, b, epi, c),
            ));
            kernels.push((
                "AVX-512, blocks of 6 columns",
                |mkn, a, b, epi, c| avx512::gemm_in_blocks_of::<true>(6, mkn, a, b, epi, c),
                |mkn, a, b, epi, c| avx512::gemm_in_blocks_of::<false>(6, mkn, a, b, epi, c),
            ));
        }
        kernels
    }

    fn same_bits(x: &[f32], y: &[f32]) -> bool {
        x.len() == y.len() && x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    #[test]
    fn every_shape_layout_and_ending_gives_the_reference_order_to_the_bit() {
        let mut rng = crate::rng::seeded(11);
        let mut rand =
            |len: usize| -> Vec<f32> { (0..len).map(|_| rng.random_range(-1.0f32..1.0)).collect() };
        let mut pack = Vec::new();
        for (m, k, n) in [
            (64, 64, 64),
            (64, 4, 64),
            (64, 64, 4),
            (17, 9, 5),
            (33, 64, 7),
            (8, 1, 4),
            (128, 128, 6),
            (64, 128, 128),
            (128, 64, 128),
            (1, 3, 1),
            (5, 0, 3),
            (5, 4, 16),
            (23, 17, 13),
            (48, 9, 7),
            (31, 8, 3),
        ] {
            let (a_data, b_data, c0) = (rand(m * k), rand(k * n), rand(m * n));
            // Exact zeros of both signs and a NaN where the endings look.
            let mut bias = rand(n);
            bias[0] = -0.0;
            if n > 2 {
                bias[1] = f32::NAN;
                bias[2] = 0.0;
            }
            let mut h = rand(m * n);
            for (x, v) in h
                .iter_mut()
                .step_by(3)
                .zip([0.0, -0.0, f32::NAN].iter().cycle())
            {
                *x = *v;
            }
            let endings = [
                Epi::Set,
                Epi::Add,
                Epi::Bias(&bias, false),
                Epi::Bias(&bias, true),
                Epi::Mask(&h),
            ];
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
                    for epi in endings {
                        let what =
                            format!("{m}x{k}x{n}, a ({ars}, {acs}), b ({brs}, {bcs}), {epi:?}");
                        let expected = reference((m, k, n), a, b, epi, &c0);
                        let mut c = c0.clone();
                        gemm((m, k, n), a, b, epi, &mut c, &mut pack);
                        assert!(same_bits(&c, &expected), "gemm {what}");
                        if ars != 1 {
                            continue;
                        }
                        let mut c = c0.clone();
                        gemm_portable((m, k, n), a.data, b, epi, &mut c);
                        assert!(same_bits(&c, &expected), "portable gemm {what}");
                        let thin_expected = reference_thin((m, k, n), a.data, b, epi, &c0);
                        for (name, fused, thin_order) in simd_kernels() {
                            let mut c = c0.clone();
                            fused((m, k, n), a.data, b, epi, &mut c);
                            assert!(same_bits(&c, &expected), "{name} gemm {what}");
                            let mut c = c0.clone();
                            thin_order((m, k, n), a.data, b, epi, &mut c);
                            assert!(same_bits(&c, &thin_expected), "{name} thin {what}");
                        }
                        let expected = thin_expected;
                        let mut c = c0.clone();
                        thin((m, k, n), a.data, b, epi, &mut c);
                        assert!(same_bits(&c, &expected), "thin {what}");
                        let mut c = c0.clone();
                        thin_portable((m, k, n), a.data, b, epi, &mut c);
                        assert!(same_bits(&c, &expected), "portable thin {what}");
                    }
                }
            }
        }
    }
}
