//! Run-time choice of the SIMD builds: the AVX-512 kernels (the body model's distance
//! stream, the template matching's cost matrices, the assignment's row relaxation) and
//! the AVX2 builds (`avx2_dispatch!`, the stereo correlations).

use std::sync::OnceLock;

/// Whether the AVX-512 kernels may run: the CPU has AVX-512F and the environment
/// variable `DEPTHPOSE_NO_AVX512` is not set, so that tests and benchmarks can take the
/// AVX2 paths on an AVX-512 machine. Decided once per process; the one place that reads
/// the variable.
#[inline]
pub(crate) fn avx512() -> bool {
    static ALLOWED: OnceLock<bool> = OnceLock::new();
    allowed(&ALLOWED, "DEPTHPOSE_NO_AVX512", || {
        #[cfg(target_arch = "x86_64")]
        return std::arch::is_x86_feature_detected!("avx512f");
        #[cfg(not(target_arch = "x86_64"))]
        false
    })
}

/// Whether the AVX2 builds may run: the CPU has AVX2 and the environment variable
/// `DEPTHPOSE_NO_AVX2` is not set (so that tests can compare them with the portable
/// builds). Decided once per process; the one place that reads the variable.
#[inline]
pub(crate) fn avx2() -> bool {
    static ALLOWED: OnceLock<bool> = OnceLock::new();
    allowed(&ALLOWED, "DEPTHPOSE_NO_AVX2", || {
        #[cfg(target_arch = "x86_64")]
        return std::arch::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        false
    })
}

/// The decision kept in `cell`: the CPU has the feature (`detected`) and the
/// environment variable `off` is not set.
#[inline]
fn allowed(cell: &OnceLock<bool>, off: &str, detected: fn() -> bool) -> bool {
    *cell.get_or_init(|| detected() && std::env::var_os(off).is_none())
}
