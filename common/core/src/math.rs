//! The core's transcendental functions, the same to the bit on every x86-64 CPU.
//!
//! `f64::exp`, `ln`, `powf`, `sin` and `cos` call the platform's libm, and glibc picks among
//! its implementations at run time by the CPU's features: on a CPU with FMA it runs
//! `__ieee754_exp_fma`, `__ieee754_log_fma`, `__ieee754_pow_fma` and `__sin_fma`, elsewhere other
//! variants, and their results differ in the last bit for some arguments. The learning dynamics
//! amplify one bit into different curves (masking FMA from glibc alone,
//! `GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F,-FMA4`, changed a CartPole run from episode
//! 129). These come instead from the `libm` crate (a port of musl's), plain Rust compiled once for
//! the x86-64 baseline, so they do not depend on the CPU. The tidy test
//! `the_core_calls_no_platform_transcendentals` keeps the core on them.
//!
//! [`exp_in_place`] gives [`exp`]'s bits four at a time: the same operations of musl's
//! (FreeBSD's) `exp` (a reduction by `k ln 2` in two parts, a rational approximation, scaling by
//! `2^k`), each a correctly rounded multiply, add, subtract or divide whether done on one lane or
//! four, on AVX2 where the CPU has it; a group of four with an argument where the scalar function
//! takes another path (|x| ≥ 704, NaN) is done one at a time.

/// e^x.
#[inline]
pub fn exp(x: f64) -> f64 {
    libm::exp(x)
}

/// `xs[i] = exp(xs[i])` for every `i`, the bits of [`exp`] (see the module's docs).
pub fn exp_in_place(xs: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if x86::available() {
        return x86::exp_in_place(xs);
    }
    xs.iter_mut().for_each(|x| *x = exp(*x));
}

/// The natural logarithm.
#[inline]
pub fn ln(x: f64) -> f64 {
    libm::log(x)
}

/// ln(1 + x), accurate near 0.
#[inline]
pub fn ln_1p(x: f64) -> f64 {
    libm::log1p(x)
}

/// x^y.
#[inline]
pub fn powf(x: f64, y: f64) -> f64 {
    libm::pow(x, y)
}

/// The sine (radians).
#[inline]
pub fn sin(x: f64) -> f64 {
    libm::sin(x)
}

/// The cosine (radians).
#[inline]
pub fn cos(x: f64) -> f64 {
    libm::cos(x)
}

/// The AVX2 form of [`exp_in_place`]: unsafe code of the core (the intrinsics' loads and
/// stores, and calling a function compiled for a feature checked at run time).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use std::arch::x86_64::*;

    /// musl's constants (`src/math/exp.c`), by their bits.
    const LN2HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    const INVLN2: f64 = f64::from_bits(0x3ff7_1547_652b_82fe);
    const P1: f64 = f64::from_bits(0x3fc5_5555_5555_553e);
    const P2: f64 = f64::from_bits(0xbf66_c16c_16be_bd93);
    const P3: f64 = f64::from_bits(0x3f11_566a_af25_de2c);
    const P4: f64 = f64::from_bits(0xbebb_bd41_c5d2_6bf1);
    const P5: f64 = f64::from_bits(0x3e66_3769_72be_a4d0);
    /// Below this |x| the scalar function's only path is the one done here, and `2^k` with
    /// `y 2^k` are normal numbers.
    const VECTOR_BELOW: f64 = 704.0;

    /// The CPU has AVX2 and the portable kernels were not asked for (as for the products:
    /// `ALFD_PORTABLE_KERNELS=1` runs every value through [`super::exp`]).
    pub(super) fn available() -> bool {
        crate::cpu::avx2_fma()
    }

    pub(super) fn exp_in_place(xs: &mut [f64]) {
        assert!(available());
        let mut fours = xs.chunks_exact_mut(4);
        for four in &mut fours {
            // SAFETY: the CPU has AVX2 (asserted); `four` holds 4 values.
            if !unsafe { exp4_avx2(four) } {
                four.iter_mut().for_each(|x| *x = super::exp(*x));
            }
        }
        for x in fours.into_remainder() {
            *x = super::exp(*x);
        }
    }

    /// `four[i] = exp(four[i])` when every |x| < [`VECTOR_BELOW`] (returns true), else leaves
    /// `four` as it is (returns false). Each line is the scalar function's, on four lanes:
    /// `hx` is the high word of |x|, `k` the multiple of ln 2 taken off (0 for
    /// |x| ≤ 0.5 ln 2, ±1 up to 1.5 ln 2, else `(INVLN2 x ± 0.5)` truncated), and below 2^-28
    /// the result is `1 + x`. With `k = 0` the general lines give the scalar's `hi = x`,
    /// `lo = 0` bit for bit (`x - 0 ln2hi = x`, `0 ln2lo = 0`).
    ///
    /// # Safety
    /// The CPU has AVX2; `four` holds 4 values.
    #[target_feature(enable = "avx2")]
    unsafe fn exp4_avx2(four: &mut [f64]) -> bool {
        let x = _mm256_loadu_pd(four.as_ptr());
        let abs = _mm256_andnot_pd(_mm256_set1_pd(-0.0), x);
        let inside = _mm256_cmp_pd::<_CMP_LT_OQ>(abs, _mm256_set1_pd(VECTOR_BELOW));
        if _mm256_movemask_pd(inside) != 0b1111 {
            return false;
        }
        let hx = _mm256_srli_epi64::<32>(_mm256_castpd_si256(abs));
        let above =
            |word: i64| _mm256_castsi256_pd(_mm256_cmpgt_epi64(hx, _mm256_set1_epi64x(word)));
        let negative = _mm256_cmp_pd::<_CMP_LT_OQ>(x, _mm256_setzero_pd());
        let half = _mm256_blendv_pd(_mm256_set1_pd(0.5), _mm256_set1_pd(-0.5), negative);
        let one = _mm256_blendv_pd(_mm256_set1_pd(1.0), _mm256_set1_pd(-1.0), negative);
        // k as i32 truncates, as `_mm256_cvttpd_epi32` does; back to f64 exactly.
        let far = _mm256_cvtepi32_pd(_mm256_cvttpd_epi32(_mm256_add_pd(
            _mm256_mul_pd(_mm256_set1_pd(INVLN2), x),
            half,
        )));
        let k = _mm256_blendv_pd(one, far, above(0x3ff0_a2b1));
        let k = _mm256_and_pd(k, above(0x3fd6_2e42));
        let hi = _mm256_sub_pd(x, _mm256_mul_pd(k, _mm256_set1_pd(LN2HI)));
        let lo = _mm256_mul_pd(k, _mm256_set1_pd(LN2LO));
        let r = _mm256_sub_pd(hi, lo);
        let rr = _mm256_mul_pd(r, r);
        let poly =
            |p: f64, rest: __m256d| _mm256_add_pd(_mm256_set1_pd(p), _mm256_mul_pd(rr, rest));
        // P1 + xx (P2 + xx (P3 + xx (P4 + xx P5))), innermost first.
        let inner = poly(P1, poly(P2, poly(P3, poly(P4, _mm256_set1_pd(P5)))));
        let c = _mm256_sub_pd(r, _mm256_mul_pd(rr, inner));
        let q = _mm256_div_pd(_mm256_mul_pd(r, c), _mm256_sub_pd(_mm256_set1_pd(2.0), c));
        let y = _mm256_add_pd(_mm256_set1_pd(1.0), _mm256_add_pd(_mm256_sub_pd(q, lo), hi));
        // 2^k: k + 1023 in the exponent's bits (k is within ±1016 here).
        let ki = _mm256_cvtepi32_epi64(_mm256_cvtpd_epi32(k));
        let scale = _mm256_slli_epi64::<52>(_mm256_add_epi64(ki, _mm256_set1_epi64x(1023)));
        let y = _mm256_mul_pd(y, _mm256_castsi256_pd(scale));
        let tiny = _mm256_add_pd(_mm256_set1_pd(1.0), x);
        let out = _mm256_blendv_pd(tiny, y, above(0x3e30_0000));
        // SAFETY: `four` holds 4 values (the caller's contract).
        unsafe { _mm256_storeu_pd(four.as_mut_ptr(), out) };
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agrees_with_the_platform_to_an_ulp_and_exactly_where_both_are_exact() {
        // Both are faithfully rounded (under 1 ulp), so they can differ in the last bit and no more.
        let ulp = |a: f64, b: f64| (a.to_bits() as i64 - b.to_bits() as i64).abs();
        for i in 0..20_000 {
            let x = (i as f64 - 10_000.0) * 0.00137;
            assert!(ulp(exp(x), x.exp()) <= 1, "exp({x})");
            assert!(ulp(sin(x), x.sin()) <= 1, "sin({x})");
            assert!(ulp(cos(x), x.cos()) <= 1, "cos({x})");
            let y = x.abs() + 1e-3;
            assert!(ulp(ln(y), y.ln()) <= 1, "ln({y})");
            assert!(ulp(ln_1p(y), y.ln_1p()) <= 1, "ln_1p({y})");
            assert!(ulp(powf(0.999, y * 100.0), 0.999f64.powf(y * 100.0)) <= 1);
        }
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(ln(1.0), 0.0);
        assert_eq!(powf(2.0, 10.0), 1024.0);
        assert_eq!(sin(0.0), 0.0);
        assert_eq!(cos(0.0), 1.0);
        assert_eq!(exp(f64::NEG_INFINITY), 0.0);
        assert!(ln(-1.0).is_nan());
    }

    #[test]
    fn exp_in_place_gives_the_bits_of_exp_on_every_path() {
        let mut r = crate::rng::seeded(7);
        let mut xs: Vec<f64> = (0..40_000)
            .map(|i| {
                let u: f64 = rand::Rng::random(&mut r);
                // Spread over every branch: tiny, within 0.5 ln 2, within 1.5 ln 2, far,
                // near the vector range's edge and beyond it (the scalar paths).
                let scale = [1e-9, 0.3, 1.0, 5.0, 60.0, 703.9, 720.0, 1e4][i % 8];
                (2.0 * u - 1.0) * scale
            })
            .collect();
        // The branches' edges, on both sides, as bits.
        for word in [0x3e30_0000u64, 0x3fd6_2e42, 0x3ff0_a2b2] {
            for low in [0u64, 1, 0xffff_ffff] {
                for sign in [0u64, 1 << 63] {
                    xs.push(f64::from_bits(sign | word << 32 | low));
                    xs.push(f64::from_bits(sign | (word - 1) << 32 | low));
                }
            }
        }
        xs.extend([
            0.0,
            -0.0,
            704.0,
            -704.0,
            703.999,
            -703.999,
            709.9,
            -746.0,
            f64::NAN,
        ]);
        xs.extend([f64::INFINITY, f64::NEG_INFINITY, 1e-320, -1e-320, 1.0, -1.0]);
        let mut got = xs.clone();
        exp_in_place(&mut got);
        for (x, y) in xs.iter().zip(&got) {
            assert_eq!(
                y.to_bits(),
                exp(*x).to_bits(),
                "exp({x:e}) ({:#x})",
                x.to_bits()
            );
        }
    }
}
