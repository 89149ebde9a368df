//! The AVX-512 kernels of [`super::gemm`] and [`super::thin`]: the AVX2 kernels' blocks with 16
//! rows to a register instead of 8 (blocks of 32 rows by [`block_width`] columns in registers
//! over the whole `k` loop, then 16, the last 1-15 rows under a mask). Each element gets the
//! operations of the AVX2 kernel in the same order, so the same bits; only more elements go at
//! once, and how many does not change any element's result. Also [`wide`]: Adam's
//! element-wise step compiled for AVX-512 ([`super::widest`]).

use std::arch::x86_64::*;
use std::sync::OnceLock;

use super::{Epi, MatRef};

/// Whether the CPU has AVX-512 (foundation) besides AVX2 and FMA, and the portable kernels were
/// not asked for.
pub(super) fn available() -> bool {
    crate::cpu::avx512f()
}

/// [`super::widest`] once [`available`] said yes.
#[inline(always)]
pub(super) fn wide<R>(f: impl FnOnce() -> R) -> R {
    assert!(available());
    // SAFETY: the CPU has AVX-512F and AVX2 (asserted).
    unsafe { wide_inner(f) }
}

/// # Safety
/// The CPU has AVX-512F and AVX2 (the only caller, [`wide`], asserts it).
#[target_feature(enable = "avx512f,avx2")]
unsafe fn wide_inner<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// [`gemm_avx512`] once [`available`] said yes: [`super::gemm`]'s order when `FMA`,
/// [`super::thin`]'s when not.
pub(super) fn gemm<const FMA: bool>(
    mkn: (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
) {
    gemm_in_blocks_of::<FMA>(block_width(), mkn, a, b, epi, c);
}

/// [`gemm`] with blocks of `width` columns (1-6) whatever the CPU.
pub(super) fn gemm_in_blocks_of<const FMA: bool>(
    width: usize,
    mkn: (usize, usize, usize),
    a: &[f32],
    b: MatRef<'_>,
    epi: Epi<'_>,
    c: &mut [f32],
) {
    assert!(available());
    assert!((1..=6).contains(&width), "blocks of 1-6 columns");
    // SAFETY: the CPU has AVX-512F, AVX2 and FMA (asserted); the caller checked the shapes.
    unsafe { gemm_avx512::<FMA>(width, mkn, a, b, epi, c) }
}

/// How many columns a block holds in registers: 4 on AMD's cores, 6 on others. Zen 4 runs a
/// 16-lane fused multiply-add as two 8-lane halves, one 16-lane operation a cycle, so 8
/// accumulators (32 rows by 4 columns) keep it busy; Intel's cores start two 16-lane fused
/// multiply-adds a cycle and take four cycles to finish one, so 8 would only just keep up and
/// 12 (32 by 6) leave room. Timed with the train step (`train_steps`): on Zen 4, 4 columns
/// beat 2, 3, 5, 6, 8 and 12; on Intel, 8 and 12 columns and 64 rows by 6 were no faster than
/// 32 by 6 (4 was not timed there).
fn block_width() -> usize {
    static WIDTH: OnceLock<usize> = OnceLock::new();
    *WIDTH.get_or_init(|| if amd() { 4 } else { 6 })
}

/// Whether the CPU's vendor is AMD (`cpuid` leaf 0: "AuthenticAMD").
fn amd() -> bool {
    let id = std::arch::x86_64::__cpuid(0);
    [id.ebx, id.edx, id.ecx]
        .iter()
        .flat_map(|r| r.to_le_bytes())
        .eq(*b"AuthenticAMD")
}

/// The flops of a round of [`probe`]: 12 chains of 16-lane fused multiply-adds.
pub(super) const PROBE_FLOPS: u64 = 12 * 16 * 2;

/// One core's f32 FMA peak probe with 16-lane registers: 12 independent chains
/// ([`PROBE_FLOPS`] a round).
pub(super) fn probe(rounds: u64) -> f32 {
    assert!(available());
    // SAFETY: the CPU has AVX-512F (asserted).
    unsafe { probe_avx512(rounds) }
}

/// # Safety
/// The CPU has AVX-512F (the only caller, [`probe`], asserts it).
#[target_feature(enable = "avx512f")]
unsafe fn probe_avx512(rounds: u64) -> f32 {
    let mut acc = [_mm512_set1_ps(1.0); 12];
    let x = _mm512_set1_ps(0.999_999);
    let y = _mm512_set1_ps(1e-7);
    for _ in 0..rounds {
        for a in &mut acc {
            *a = _mm512_fmadd_ps(*a, x, y);
        }
    }
    let mut sum = _mm512_setzero_ps();
    for a in acc {
        sum = _mm512_add_ps(sum, a);
    }
    let mut out = [0.0f32; 16];
    // SAFETY: `out` holds 16 floats.
    unsafe { _mm512_storeu_ps(out.as_mut_ptr(), sum) };
    out.iter().sum()
}

/// `C` with AVX-512: blocks of `widest` columns (then fewer), and in each, blocks of 32 rows
/// (then 16), accumulated in registers over the whole `k` loop, the elements of `B` broadcast;
/// the last 1-15 rows under a mask, in the same order.
///
/// # Safety
/// The CPU has AVX-512F, AVX2 and FMA, and `a`, `b` and `c` hold `m × k`, `k × n` and `m × n`
/// values (the caller, [`gemm`], asserts the features; its callers check the shapes).
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn gemm_avx512<const FMA: bool>(
    widest: usize,
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
        let width = (n - j).min(widest);
        let mut i = 0;
        // SAFETY: every block reads rows i..i + 16 V (<= m, or fewer under the mask) of the k
        // columns of `a` (m * k values), elements (p, j..j + width) of `b` (p < k,
        // j + width <= n: within `b`'s slice, as the caller checked), the same elements of `c`
        // and of a mask (m * n values, checked), `bias[j..j + width]` (n values, checked), and
        // writes `c`'s rows i..i + 16 V (or the masked ones) of those columns.
        unsafe {
            while i + 32 <= m {
                widths!(2, false, i, width, j, 16);
                i += 32;
            }
            while i + 16 <= m {
                widths!(1, false, i, width, j, 16);
                i += 16;
            }
            if i < m {
                widths!(1, true, i, width, j, m - i);
            }
        }
        j += width;
    }
}

/// `a * *b` in every lane (a rounded multiplication), the broadcast folded into the multiply's
/// operand (`{1to16}`): on Zen 4 a thin block's step is faster so than with the element first
/// broadcast into a register, which competes with the block's multiplications and additions
/// (timed with `train_steps parts`: its forward pass). The compiler folds a broadcast into its
/// use only where it has one use, and a block uses each twice.
///
/// # Safety
/// The CPU has AVX-512F; `b` points to a readable `f32`.
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn mul_by_broadcast(a: __m512, b: *const f32) -> __m512 {
    let product: __m512;
    // SAFETY: `b` is readable (the caller's contract); the instruction reads 4 bytes there and
    // writes only `product`.
    unsafe {
        std::arch::asm!(
            "vmulps {product}, {a}, dword ptr [{b}]{{1to16}}",
            product = lateout(zmm_reg) product,
            a = in(zmm_reg) a,
            b = in(reg) b,
            options(pure, readonly, nostack, preserves_flags),
        );
    }
    product
}

/// Rows `i..i + 16 (V - 1) + last` of columns `j..j + W`: the last vector of rows holds `last`
/// (1-16) rows, loaded and stored under a mask when `MASKED`. With `FMA`, each element is
/// `fma`'d from zero and then ends as [`Epi::fused`]; without, it starts at [`Epi::start`], adds
/// rounded products and ends as [`Epi::finish`]: the AVX2 block's operations.
///
/// # Safety
/// The CPU has AVX-512F; `i + 16 (V - 1) + last <= m`; `a` holds `m * k` values; `b` holds
/// element `(k - 1, j + W - 1)` and every one before; `c` (and a mask) hold `m * (j + W)`
/// values, a bias `j + W`.
#[target_feature(enable = "avx512f,avx2,fma")]
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
    debug_assert!((1..=16).contains(&last) && i + 16 * (V - 1) + last <= m);
    debug_assert!(MASKED || last == 16);
    debug_assert!(a.len() >= m * k && c.len() >= m * (j + W));
    let t = Tile {
        m,
        i,
        j,
        mask: ((1u32 << last) - 1) as u16,
    };
    let c = c.as_mut_ptr();
    let mut acc = if FMA {
        [[_mm512_setzero_ps(); V]; W]
    } else {
        t.start::<V, W, MASKED>(epi, c)
    };
    let a = a.as_ptr().add(i);
    let b_cols: [*const f32; W] = std::array::from_fn(|q| b.data.as_ptr().add((j + q) * b.cs));
    for p in 0..k {
        let col = a.add(p * m);
        let mut av = [_mm512_setzero_ps(); V];
        for (v, x) in av.iter_mut().enumerate() {
            *x = t.load::<V, MASKED>(col.add(16 * v), v);
        }
        for (acc, b_col) in acc.iter_mut().zip(b_cols) {
            let b_at = b_col.add(p * b.rs);
            if FMA {
                let bb = _mm512_set1_ps(*b_at);
                for v in 0..V {
                    acc[v] = _mm512_fmadd_ps(av[v], bb, acc[v]);
                }
            } else {
                for v in 0..V {
                    acc[v] = _mm512_add_ps(acc[v], mul_by_broadcast(av[v], b_at));
                }
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
    mask: __mmask16,
}

impl Tile {
    /// The index in `c` of row vector `v` of column `j + q`.
    fn at(self, q: usize, v: usize) -> usize {
        self.i + 16 * v + (self.j + q) * self.m
    }

    /// Sixteen values from `ptr`, under the mask for the last vector `v` of a `MASKED` block.
    ///
    /// # Safety
    /// The CPU has AVX-512F; `ptr` holds the sixteen values (the masked ones where masked).
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    unsafe fn load<const V: usize, const MASKED: bool>(self, ptr: *const f32, v: usize) -> __m512 {
        if MASKED && v + 1 == V {
            _mm512_maskz_loadu_ps(self.mask, ptr)
        } else {
            _mm512_loadu_ps(ptr)
        }
    }

    /// Column `j + q`'s bias in every lane, or zeros without a bias.
    ///
    /// # Safety
    /// The CPU has AVX-512F; a bias holds `j + q + 1` values.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    unsafe fn bias(self, epi: Epi<'_>, q: usize) -> __m512 {
        match epi {
            Epi::Bias(bias, _) => _mm512_set1_ps(bias[self.j + q]),
            _ => _mm512_setzero_ps(),
        }
    }

    /// The sums of a block without `FMA` as they start: at `c` or the bias ([`Epi::start`]).
    ///
    /// # Safety
    /// As [`block`]'s.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    unsafe fn start<const V: usize, const W: usize, const MASKED: bool>(
        self,
        epi: Epi<'_>,
        c: *const f32,
    ) -> [[__m512; V]; W] {
        std::array::from_fn(|q| {
            std::array::from_fn(|v| match epi {
                Epi::Add => self.load::<V, MASKED>(c.add(self.at(q, v)), v),
                Epi::Bias(..) => self.bias(epi, q),
                Epi::Set | Epi::Mask(_) => _mm512_setzero_ps(),
            })
        })
    }

    /// Ends a block's sums as [`Epi::fused`] (with `FMA`) or [`Epi::finish`] and stores them.
    ///
    /// # Safety
    /// As [`block`]'s.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    unsafe fn end<const V: usize, const W: usize, const MASKED: bool, const FMA: bool>(
        self,
        acc: &[[__m512; V]; W],
        epi: Epi<'_>,
        c: *mut f32,
    ) {
        let zero = _mm512_setzero_ps();
        for (q, acc) in acc.iter().enumerate() {
            for (v, &x) in acc.iter().enumerate() {
                let out = c.add(self.at(q, v));
                let x = match epi {
                    _ if !FMA => x,
                    Epi::Set | Epi::Mask(_) => x,
                    Epi::Add => _mm512_add_ps(x, self.load::<V, MASKED>(out, v)),
                    Epi::Bias(..) => _mm512_add_ps(x, self.bias(epi, q)),
                };
                let x = match epi {
                    // `max` returns its second operand (0) for a NaN and for -0, as the AVX2
                    // block's `maxps` does.
                    Epi::Bias(_, true) => _mm512_max_ps(x, zero),
                    Epi::Mask(h) => {
                        let h = self.load::<V, MASKED>(h.as_ptr().add(self.at(q, v)), v);
                        _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(h, zero), x)
                    }
                    _ => x,
                };
                if MASKED && v + 1 == V {
                    _mm512_mask_storeu_ps(out, self.mask, x);
                } else {
                    _mm512_storeu_ps(out, x);
                }
            }
        }
    }
}
