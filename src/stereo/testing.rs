//! Helpers of the stereo filters' tests.

/// Whether two disparity maps agree: equal values, NaN (unmatched) alike.
pub(crate) fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
}

/// `n` disparities in [0, `max`), about a share `holes` of them unmatched (NaN), from
/// a fixed linear congruential generator: deterministic for each `seed`.
pub(crate) fn random_disparities(n: usize, holes: f64, max: f64, seed: u64) -> Vec<f32> {
    let mut state = seed;
    let mut uniform = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            if uniform() < holes {
                f32::NAN
            } else {
                (uniform() * max) as f32
            }
        })
        .collect()
}
