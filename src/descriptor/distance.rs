//! Distances between descriptors, with their SIMD kernel.

/// L2 distance between two descriptors.
#[inline]
pub fn descriptor_distance(a: &[f32], b: &[f32]) -> f32 {
    squared_distance(a, b).sqrt()
}

/// Lanes of the distance accumulator: independent partial sums let the compiler
/// vectorise (a single running f32 sum must stay sequential).
pub(super) const LANES: usize = 8;

/// Squared L2 distance (the inner loop of matching).
#[inline]
pub fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f32; LANES];
    let mut ca = a.chunks_exact(LANES);
    let mut cb = b.chunks_exact(LANES);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for k in 0..LANES {
            let d = x[k] - y[k];
            acc[k] += d * d;
        }
    }
    let mut total: f32 = acc.iter().sum();
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        total += (x - y) * (x - y);
    }
    total
}

/// [`squared_distance`] of `a` to four descriptors at once, each bit for bit the same
/// value (same lane sums in the same order).
///
/// Each distance is one dependent chain of adds, so computing one at a time waits on
/// the adder's latency; four independent chains keep it busy and load each chunk of
/// `a` once for four. With AVX2 (detected at run time) the chains are written with
/// intrinsics: left to itself, the compiler vectorised across the four distances
/// instead of along the lanes.
#[inline]
pub fn squared_distances_x4(a: &[f32], b: [&[f32]; 4]) -> [f32; 4] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && b.iter().all(|b| b.len() == a.len()) {
        // SAFETY: the CPU supports AVX2 (checked just above); lengths checked too.
        return unsafe { squared_distances_x4_avx2(a, b) };
    }
    b.map(|b| squared_distance(a, b))
}

/// [`squared_distances_x4`] with AVX2; every `b[k]` as long as `a`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn squared_distances_x4_avx2(a: &[f32], b: [&[f32]; 4]) -> [f32; 4] {
    use std::arch::x86_64::*;
    let full = a.len() / LANES * LANES;
    let mut acc = [_mm256_setzero_ps(); 4];
    for c in (0..full).step_by(LANES) {
        // SAFETY: c + LANES <= full <= the length of `a` and of every `b[k]`.
        let x = _mm256_loadu_ps(a.as_ptr().add(c));
        for (acc, b) in acc.iter_mut().zip(&b) {
            let d = _mm256_sub_ps(x, _mm256_loadu_ps(b.as_ptr().add(c)));
            *acc = _mm256_add_ps(*acc, _mm256_mul_ps(d, d));
        }
    }
    std::array::from_fn(|k| {
        let mut lanes = [0.0f32; LANES];
        _mm256_storeu_ps(lanes.as_mut_ptr(), acc[k]);
        let mut total: f32 = lanes.iter().sum();
        for (x, y) in a[full..].iter().zip(&b[k][full..]) {
            total += (x - y) * (x - y);
        }
        total
    })
}
