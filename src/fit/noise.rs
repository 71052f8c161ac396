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
