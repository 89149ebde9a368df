//! The AVX2 loops of the SMO solver: the working-pair search and the gradient update four
//! variables to a register, the kernel rows read through gathers. Each variable gets the
//! operations of the portable loops in the same order, and each lane of a search keeps the
//! last position attaining its best ([`LaneBest`]), so the pair chosen and every gradient are
//! the same bits.

use std::arch::x86_64::*;

use super::{Active, LaneBest, TAU};

/// Lanes of an AVX2 register of `f64`.
const V: usize = 4;
/// Registers of the search for the largest violation, side by side so that each compares
/// against its own best (one alone would wait on its last comparison every four variables).
const UP_REGS: usize = 4;
/// Its lanes: variable p in lane `p % UP_LANES`.
pub(super) const UP_LANES: usize = UP_REGS * V;
/// Registers of the search for the partner: two keep up with its divisions.
const LOW_REGS: usize = 2;
pub(super) const LOW_LANES: usize = LOW_REGS * V;

pub(super) fn available() -> bool {
    crate::cpu::avx2_fma()
}

/// Whether the active set's arrays have its length and its rows are below the lengths of
/// `rows` (so each array can be read four at a time and each row gathered).
fn readable(a: &Active, rows: &[&[f64]]) -> bool {
    let n = a.len();
    let lengths = [
        a.row.len(),
        a.y.len(),
        a.diag.len(),
        a.grad.len(),
        a.up.len(),
        a.low.len(),
    ];
    lengths.iter().all(|&len| len == n) && rows.iter().all(|r| r.len() >= a.row_bound)
}

/// See [`super::max_violation`].
pub(super) fn max_violation(a: &Active) -> LaneBest<UP_LANES> {
    assert!(available() && readable(a, &[]));
    // SAFETY: the CPU has AVX2 and the arrays have the active set's length (asserted).
    unsafe { max_violation_avx2(a) }
}

/// See [`super::best_partner`]: the largest y G over I_low, and the lanes' best partners.
pub(super) fn best_partner(
    a: &Active,
    gmax: f64,
    di: f64,
    ki: &[f64],
) -> (f64, LaneBest<LOW_LANES>) {
    assert!(available() && readable(a, &[ki]));
    // SAFETY: the CPU has AVX2, the arrays have the active set's length and every active row
    // is below `ki`'s length (asserted).
    unsafe { best_partner_avx2(a, gmax, di, ki) }
}

/// See [`super::move_gradient`].
pub(super) fn move_gradient(a: &mut Active, i: (f64, &[f64], f64), j: (f64, &[f64], f64)) {
    assert!(available() && readable(a, &[i.1, j.1]));
    // SAFETY: as for `best_partner`, with both rows.
    unsafe { move_gradient_avx2(a, i, j) }
}

/// The lanes of `flags[q..q + 4]` (bools, one byte each) as all ones or zero.
///
/// # Safety
/// The CPU has AVX2; `q + 4 <= flags.len()`.
#[target_feature(enable = "avx2")]
unsafe fn mask(flags: &[bool], q: usize) -> __m256d {
    // SAFETY: four bytes from `q` are within `flags` (the caller's promise).
    let bytes = unsafe { (flags.as_ptr().add(q) as *const i32).read_unaligned() };
    let wide = _mm256_cvtepu8_epi64(_mm_cvtsi32_si128(bytes));
    _mm256_castsi256_pd(_mm256_cmpgt_epi64(wide, _mm256_setzero_si256()))
}

/// `U` registers of a search's bests, each lane with the start of the block of `U · 4`
/// variables where it was attained (−1: none yet).
struct Bests<const U: usize> {
    value: [__m256d; U],
    block: [__m256i; U],
}

impl<const U: usize> Bests<U> {
    #[target_feature(enable = "avx2")]
    fn new(worst: f64) -> Bests<U> {
        Bests {
            value: [_mm256_set1_pd(worst); U],
            block: [_mm256_set1_epi64x(-1); U],
        }
    }

    /// Register u's lanes take `v` (attained in the block starting at `block`) where `take`.
    #[target_feature(enable = "avx2")]
    fn offer(&mut self, u: usize, block: __m256i, take: __m256d, v: __m256d) {
        self.value[u] = _mm256_blendv_pd(self.value[u], v, take);
        let kept = _mm256_castsi256_pd(self.block[u]);
        self.block[u] =
            _mm256_castpd_si256(_mm256_blendv_pd(kept, _mm256_castsi256_pd(block), take));
    }

    /// Into lanes `u 4 + k` of `out`, with each block start turned into the position.
    #[target_feature(enable = "avx2")]
    fn store<const W: usize>(&self, out: &mut LaneBest<W>) {
        let mut value = [0.0; W];
        let mut block = [0i64; W];
        for u in 0..U {
            // SAFETY: lanes u 4 .. u 4 + 4 of arrays of W = U · 4 values.
            unsafe {
                _mm256_storeu_pd(value.as_mut_ptr().add(u * V), self.value[u]);
                _mm256_storeu_si256(block.as_mut_ptr().add(u * V) as *mut __m256i, self.block[u]);
            }
        }
        for l in 0..W {
            out.value[l] = value[l];
            out.at[l] = usize::try_from(block[l]).map_or(usize::MAX, |b| b + l);
        }
    }
}

/// # Safety
/// The CPU has AVX2; the active set's arrays have its length.
#[target_feature(enable = "avx2")]
unsafe fn max_violation_avx2(a: &Active) -> LaneBest<UP_LANES> {
    let n = a.len();
    let body = n - n % UP_LANES;
    let mut bests = Bests::<UP_REGS>::new(f64::NEG_INFINITY);
    let sign = _mm256_set1_pd(-0.0);
    for base in (0..body).step_by(UP_LANES) {
        let block = _mm256_set1_epi64x(base as i64);
        for u in 0..UP_REGS {
            let q = base + u * V;
            // SAFETY: q + 4 <= body <= n, the arrays' length.
            let (y, g, up) = unsafe {
                let y = _mm256_loadu_pd(a.y.as_ptr().add(q));
                (y, _mm256_loadu_pd(a.grad.as_ptr().add(q)), mask(&a.up, q))
            };
            let v = _mm256_mul_pd(_mm256_xor_pd(y, sign), g);
            let take = _mm256_and_pd(up, _mm256_cmp_pd::<_CMP_GE_OQ>(v, bests.value[u]));
            bests.offer(u, block, take, v);
        }
    }
    let mut best = LaneBest::new(f64::NEG_INFINITY);
    bests.store(&mut best);
    super::max_violation_from(a, body, &mut best);
    best
}

/// # Safety
/// The CPU has AVX2; the active set's arrays have its length, its rows are below `ki.len()`.
#[target_feature(enable = "avx2")]
unsafe fn best_partner_avx2(
    a: &Active,
    gmax: f64,
    di: f64,
    ki: &[f64],
) -> (f64, LaneBest<LOW_LANES>) {
    let n = a.len();
    let body = n - n % LOW_LANES;
    let mut bests = Bests::<LOW_REGS>::new(f64::INFINITY);
    let mut g2 = _mm256_set1_pd(f64::NEG_INFINITY);
    let (vgmax, vdi, two) = (
        _mm256_set1_pd(gmax),
        _mm256_set1_pd(di),
        _mm256_set1_pd(2.0),
    );
    let (tau, zero, sign) = (
        _mm256_set1_pd(TAU),
        _mm256_setzero_pd(),
        _mm256_set1_pd(-0.0),
    );
    let none = _mm256_set1_pd(f64::NEG_INFINITY);
    for base in (0..body).step_by(LOW_LANES) {
        let block = _mm256_set1_epi64x(base as i64);
        for u in 0..LOW_REGS {
            let q = base + u * V;
            // SAFETY: q + 4 <= body <= n, the arrays' length; the active rows are below
            // `ki.len()`.
            let (low, y, g, dp, kip) = unsafe {
                let rows = _mm256_loadu_si256(a.row.as_ptr().add(q) as *const __m256i);
                (
                    mask(&a.low, q),
                    _mm256_loadu_pd(a.y.as_ptr().add(q)),
                    _mm256_loadu_pd(a.grad.as_ptr().add(q)),
                    _mm256_loadu_pd(a.diag.as_ptr().add(q)),
                    _mm256_i64gather_pd::<8>(ki.as_ptr(), rows),
                )
            };
            let yg = _mm256_mul_pd(y, g);
            g2 = _mm256_max_pd(g2, _mm256_blendv_pd(none, yg, low));
            let b = _mm256_add_pd(vgmax, yg);
            let curv = _mm256_sub_pd(_mm256_add_pd(vdi, dp), _mm256_mul_pd(two, kip));
            let curv = _mm256_blendv_pd(tau, curv, _mm256_cmp_pd::<_CMP_GT_OQ>(curv, zero));
            let gain = _mm256_div_pd(_mm256_xor_pd(_mm256_mul_pd(b, b), sign), curv);
            let decreases = _mm256_and_pd(low, _mm256_cmp_pd::<_CMP_GT_OQ>(b, zero));
            let take = _mm256_and_pd(decreases, _mm256_cmp_pd::<_CMP_LE_OQ>(gain, bests.value[u]));
            bests.offer(u, block, take, gain);
        }
    }
    let mut best = LaneBest::new(f64::INFINITY);
    bests.store(&mut best);
    let mut gmax2 = [0.0; V];
    // SAFETY: four values into an array of four.
    unsafe { _mm256_storeu_pd(gmax2.as_mut_ptr(), g2) };
    let mut gmax2 = gmax2.into_iter().fold(f64::NEG_INFINITY, f64::max);
    super::best_partner_from(a, body, (gmax, di, ki), &mut best, &mut gmax2);
    (gmax2, best)
}

/// # Safety
/// The CPU has AVX2; the active set's arrays have its length, its rows are below the lengths
/// of both kernel rows.
#[target_feature(enable = "avx2")]
unsafe fn move_gradient_avx2(
    a: &mut Active,
    (yi, ki, di): (f64, &[f64], f64),
    (yj, kj, dj): (f64, &[f64], f64),
) {
    let n = a.len();
    let body = n - n % V;
    let (vyi, vdi) = (_mm256_set1_pd(yi), _mm256_set1_pd(di));
    let (vyj, vdj) = (_mm256_set1_pd(yj), _mm256_set1_pd(dj));
    for q in (0..body).step_by(V) {
        // SAFETY: q + 4 <= body <= n, the arrays' length; the active rows are below both
        // kernel rows' lengths.
        unsafe {
            let rows = _mm256_loadu_si256(a.row.as_ptr().add(q) as *const __m256i);
            let kir = _mm256_i64gather_pd::<8>(ki.as_ptr(), rows);
            let kjr = _mm256_i64gather_pd::<8>(kj.as_ptr(), rows);
            let from_i = _mm256_mul_pd(_mm256_mul_pd(vyi, kir), vdi);
            let from_j = _mm256_mul_pd(_mm256_mul_pd(vyj, kjr), vdj);
            let y = _mm256_loadu_pd(a.y.as_ptr().add(q));
            let step = _mm256_mul_pd(y, _mm256_add_pd(from_i, from_j));
            let g = a.grad.as_mut_ptr().add(q);
            _mm256_storeu_pd(g, _mm256_add_pd(_mm256_loadu_pd(g), step));
        }
    }
    for p in body..n {
        let r = a.row[p];
        a.grad[p] += a.y[p] * (yi * ki[r] * di + yj * kj[r] * dj);
    }
}
