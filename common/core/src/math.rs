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

/// e^x.
#[inline]
pub fn exp(x: f64) -> f64 {
    libm::exp(x)
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
}
