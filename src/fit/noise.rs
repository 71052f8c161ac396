//! How precisely each point's depth is known, and the weights that follow.
//!
//! A triangulating sensor (a stereo pair, a structured-light camera) measures disparity
//! to about the same precision everywhere, δ pixels; depth is Z = f·B/d, so its error
//! grows as σ_Z = Z²·δ/(f·B). Within one person a stereo rig at 3 m sees points from
//! 2.7 to 3.5 m, whose depth errors differ by a factor of 1.7. The fit weighs each
//! point's data terms by the inverse of its variance, σ² + σ_Z², where σ is the fit's
//! own residual scale ([`crate::fit::EmConfig::sigma`]: how far the ellipsoid body lies
//! from a real one); the weights are normalised to a mean of 1 over the points, so
//! they decide which points the fit trusts, not how much the data weigh against the
//! smoothness and the priors (which `sigma` sets).
//!
//! The same noise makes even a well-fitted body explain the depth less well: its
//! [`DepthNoise::discrepancy_added`] is what a tracker's lost test allows for.

use crate::error::{ensure_positive, Result};

/// Depth noise of a triangulating sensor: σ_Z = Z²·δ/(f·B).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthNoise {
    /// Focal length times baseline, f·B (pixels · metres): Z = f·B / d.
    pub focal_baseline: f64,
    /// The disparity's standard deviation δ (pixels).
    pub disparity_sigma: f64,
}

impl DepthNoise {
    pub fn validate(&self) -> Result<()> {
        ensure_positive(self.focal_baseline, "focal_baseline")?;
        ensure_positive(self.disparity_sigma, "disparity_sigma")
    }

    /// The depth's standard deviation σ_Z (metres) at depth `z` (metres).
    #[inline]
    pub fn depth_sigma(&self, z: f64) -> f64 {
        z * z * self.disparity_sigma / self.focal_baseline
    }

    /// Each point's weight 1/(σ² + σ_Z²), normalised to a mean of 1 (camera-frame
    /// points, z the depth; `sigma` the fit's residual scale, metres). Empty for no
    /// points.
    pub fn point_weights(&self, points: &[[f32; 3]], sigma: f64) -> Vec<f32> {
        let raw: Vec<f64> = points
            .iter()
            .map(|p| 1.0 / (sigma * sigma + self.depth_sigma(p[2] as f64).powi(2)))
            .collect();
        let mean = raw.iter().sum::<f64>() / raw.len().max(1) as f64;
        raw.iter().map(|&w| (w / mean) as f32).collect()
    }

    /// How much this noise raises the depth discrepancy
    /// ([`crate::render::depth_discrepancy`], differences capped at `cap` metres) of a
    /// body that fits as well as the model can, its own residuals of scale `sigma`
    /// (metres; the fit's [`crate::fit::EmConfig::sigma`]): the mean over the observed
    /// pixels (in `mask`, with a finite positive depth) of
    /// (E[min(|r|, cap)] − E[min(|m|, cap)]) / cap, with m ~ N(0, σ²) the model's
    /// residual and r ~ N(0, σ² + σ_Z²) the residual with the noise added. 0 when no
    /// pixel is observed.
    pub fn discrepancy_added(&self, depth: &[f32], mask: &[bool], sigma: f64, cap: f64) -> f64 {
        let model = expected_capped_error(sigma, cap);
        let (mut sum, mut n) = (0.0, 0usize);
        for (&z, &m) in depth.iter().zip(mask) {
            if m && z > 0.0 && z.is_finite() {
                let noise = self.depth_sigma(z as f64);
                sum += expected_capped_error(sigma.hypot(noise), cap) - model;
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            sum / (n as f64 * cap)
        }
    }
}

/// E[min(|e|, c)] for e ~ N(0, σ²): σ·√(2/π)·(1 − exp(−c²/2σ²)) + c·erfc(c/(σ√2)),
/// the mean of |e| below the cap plus the cap times the chance of reaching it.
fn expected_capped_error(sigma: f64, cap: f64) -> f64 {
    if sigma <= 0.0 {
        return 0.0;
    }
    let r = cap / sigma;
    sigma * (2.0 / std::f64::consts::PI).sqrt() * (1.0 - (-0.5 * r * r).exp())
        + cap * libm::erfc(r / std::f64::consts::SQRT_2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_error_grows_as_depth_squared() {
        let n = DepthNoise {
            focal_baseline: 570.0 * 0.12,
            disparity_sigma: 0.25,
        };
        // A quarter pixel at 3 m with f·B = 68.4: 9·0.25/68.4 m.
        assert!((n.depth_sigma(3.0) - 9.0 * 0.25 / 68.4).abs() < 1e-12);
        assert!((n.depth_sigma(4.0) / n.depth_sigma(2.0) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn weights_are_inverse_variances_with_mean_one() {
        let n = DepthNoise {
            focal_baseline: 68.4,
            disparity_sigma: 0.25,
        };
        let sigma = 0.02;
        let points = [[0.0, 0.0, 2.0], [0.1, 0.0, 3.0], [0.0, 0.2, 4.0]];
        let w = n.point_weights(&points, sigma);
        let mean = w.iter().map(|&v| v as f64).sum::<f64>() / 3.0;
        assert!((mean - 1.0).abs() < 1e-6);
        let var = |z: f64| sigma * sigma + n.depth_sigma(z).powi(2);
        // Ratios of the weights are ratios of inverse variances.
        assert!((w[0] as f64 / w[2] as f64 - var(4.0) / var(2.0)).abs() < 1e-4);
        assert!(w[0] > w[1] && w[1] > w[2]);
        assert!(n.point_weights(&[], sigma).is_empty());
    }

    /// E[min(|e|, c)] = ∫₀^c P(|e| > t) dt, by the trapezoid rule on a grid fine
    /// against σ.
    fn capped_error_by_quadrature(sigma: f64, cap: f64) -> f64 {
        let n = (2000.0 * cap / sigma).max(20_000.0) as usize;
        let tail = |t: f64| libm::erfc(t / (sigma * std::f64::consts::SQRT_2));
        let h = cap / n as f64;
        (0..n)
            .map(|i| 0.5 * h * (tail(i as f64 * h) + tail((i + 1) as f64 * h)))
            .sum()
    }

    #[test]
    fn capped_error_matches_quadrature() {
        for sigma in [0.001, 0.01, 0.03, 0.1, 0.5] {
            for cap in [0.05, 0.1, 0.3] {
                let want = capped_error_by_quadrature(sigma, cap);
                let got = expected_capped_error(sigma, cap);
                assert!(
                    (got - want).abs() < 1e-5 * want,
                    "σ {sigma}, cap {cap}: {got} vs {want}"
                );
            }
        }
        // Small noise: the mean absolute error σ·√(2/π); huge noise: the cap.
        let s = 1e-4;
        assert!(
            (expected_capped_error(s, 0.1) - s * (2.0 / std::f64::consts::PI).sqrt()).abs() < 1e-12
        );
        assert!((expected_capped_error(1e3, 0.1) - 0.1).abs() < 1e-4);
        assert_eq!(expected_capped_error(0.0, 0.1), 0.0);
    }

    #[test]
    fn discrepancy_added_averages_the_observed_pixels() {
        let n = DepthNoise {
            focal_baseline: 68.4,
            disparity_sigma: 0.25,
        };
        let (sigma, cap) = (0.02, 0.1);
        let depth = [2.0f32, 4.0, 3.0, 0.0, f32::NAN];
        let mask = [true, true, false, true, true];
        let added = |z: f64| {
            expected_capped_error((sigma * sigma + n.depth_sigma(z).powi(2)).sqrt(), cap)
                - expected_capped_error(sigma, cap)
        };
        let want = (added(2.0) + added(4.0)) / (2.0 * cap);
        let got = n.discrepancy_added(&depth, &mask, sigma, cap);
        assert!((got - want).abs() < 1e-12);
        // Farther is noisier; a model that already misses by more gains less.
        let near = n.discrepancy_added(&[2.0], &[true], sigma, cap);
        let far = n.discrepancy_added(&[4.0], &[true], sigma, cap);
        assert!(0.0 < near && near < far && far < 1.0);
        assert!(n.discrepancy_added(&[4.0], &[true], 0.05, cap) < far);
        // With a perfect model it is the noise's own discrepancy.
        let alone = n.discrepancy_added(&[3.0], &[true], 0.0, cap);
        assert!((alone - expected_capped_error(n.depth_sigma(3.0), cap) / cap).abs() < 1e-12);
        assert_eq!(n.discrepancy_added(&depth, &[false; 5], sigma, cap), 0.0);
    }

    #[test]
    fn bad_settings_name_the_field() {
        let bad = DepthNoise {
            focal_baseline: 0.0,
            disparity_sigma: 0.25,
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("focal_baseline"));
        let bad = DepthNoise {
            focal_baseline: 1.0,
            disparity_sigma: f64::NAN,
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("disparity_sigma"));
    }
}
