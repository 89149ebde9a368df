//! What this process's CPU offers the vector kernels: AVX2 with FMA, and AVX-512F, each only
//! when the portable kernels were not asked for ([`use_portable_kernels`], which the binaries
//! call when `ALFD_PORTABLE_KERNELS=1`). The products (`nn`), the demonstration model's solvers
//! (`demo_model`) and `math`'s vector `exp` all ask here, so one switch sends every one of them
//! down its portable path.

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by [`use_portable_kernels`].
static PORTABLE: AtomicBool = AtomicBool::new(false);

/// Makes this process use the portable kernels (no AVX2, `f32::mul_add` per element) even on a
/// CPU that has AVX2 and FMA: to check that they give the same numbers. Slow: every fused
/// multiply-add is a software one.
pub fn use_portable_kernels(yes: bool) {
    PORTABLE.store(yes, Ordering::Relaxed);
}

fn portable() -> bool {
    PORTABLE.load(Ordering::Relaxed)
}

/// Whether the AVX2+FMA kernels may run: the CPU has both and the portable kernels were not
/// asked for.
pub fn avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::sync::OnceLock;
        static DETECTED: OnceLock<bool> = OnceLock::new();
        !portable()
            && *DETECTED.get_or_init(|| {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            })
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether the AVX-512 kernels may run: [`avx2_fma`] and the CPU has AVX-512F.
pub fn avx512f() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::sync::OnceLock;
        static DETECTED: OnceLock<bool> = OnceLock::new();
        avx2_fma() && *DETECTED.get_or_init(|| std::arch::is_x86_feature_detected!("avx512f"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}
