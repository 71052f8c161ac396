//! Run-time choice of the AVX-512 kernels: the body model's distance stream, the template
//! matching's cost matrices and the assignment's row relaxation.

/// Whether the AVX-512 kernels may run: the CPU has AVX-512F and the environment
/// variable `DEPTHPOSE_NO_AVX512` is not set, so that tests and benchmarks can take the
/// AVX2 paths on an AVX-512 machine. Decided once per process; the one place that reads
/// the variable.
#[inline]
pub(crate) fn avx512() -> bool {
    use std::sync::OnceLock;
    static ALLOWED: OnceLock<bool> = OnceLock::new();
    *ALLOWED.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!("avx512f")
                && std::env::var_os("DEPTHPOSE_NO_AVX512").is_none()
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    })
}

/// Whether the AVX2 builds of the stereo window sums may run: the CPU has AVX2 and the
/// environment variable `DEPTHPOSE_NO_AVX2` is not set (so that tests can compare them
/// with the portable build). Decided once per process.
#[inline]
pub(crate) fn avx2() -> bool {
    use std::sync::OnceLock;
    static ALLOWED: OnceLock<bool> = OnceLock::new();
    *ALLOWED.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!("avx2")
                && std::env::var_os("DEPTHPOSE_NO_AVX2").is_none()
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    })
}
