//! The settings of the shape calibration.

use crate::error::{ensure, Result};
use crate::fit::em::EmConfig;
use crate::fit::terms::PointCost;
use crate::fit::FitConfig;

/// Settings of [`fit_shape`](super::fit_shape) and [`shape_lm`](super::shape_lm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeConfig {
    /// The per-frame pose fits (hard EM) and the CRF neighbourhood; the shape step uses
    /// the same σ, loss and truncation at the final outlier distance.
    pub fit: FitConfig,
    /// At most this many rounds of pose/label step + shape step.
    pub rounds: usize,
    /// At most this many LM iterations per shape step.
    pub lm_iterations: usize,
    /// Bounds of every shape factor (0 < lower ≤ 1 ≤ upper).
    pub lower: f64,
    pub upper: f64,
    /// Weight w of the prior ½·w·Σ(s − 1)² (≥ 0): keeps factors the data hardly
    /// constrain (e.g. the depth of the torso seen from the front) near the base shape.
    /// Default 1e5: on the shared synthetic sequences (a mesh body, not ellipsoids) a
    /// weaker prior (1e3) trades joint accuracy for surface fit (docs/design.md).
    pub prior_weight: f64,
    /// Stop when a round lowers the energy by less than this fraction.
    pub tolerance: f64,
}

impl Default for ShapeConfig {
    fn default() -> Self {
        ShapeConfig {
            fit: FitConfig::default(),
            rounds: 3,
            lm_iterations: 20,
            lower: 0.7,
            upper: 1.4,
            prior_weight: 1e5,
            tolerance: 1e-4,
        }
    }
}

impl ShapeConfig {
    /// Checks every field, naming the bad one.
    pub fn validate(&self) -> Result<()> {
        self.fit.em.validate()?;
        ensure(self.rounds > 0, "rounds", || "must be at least 1".into())?;
        ensure(self.lm_iterations > 0, "lm_iterations", || {
            "must be at least 1".into()
        })?;
        ensure(
            self.lower.is_finite() && self.lower > 0.0 && self.lower <= 1.0,
            "lower",
            || format!("must be within (0, 1], got {}", self.lower),
        )?;
        ensure(self.upper.is_finite() && self.upper >= 1.0, "upper", || {
            format!("must be finite and >= 1, got {}", self.upper)
        })?;
        ensure(
            self.prior_weight.is_finite() && self.prior_weight >= 0.0,
            "prior_weight",
            || format!("must be finite and >= 0, got {}", self.prior_weight),
        )?;
        ensure(
            self.tolerance.is_finite() && self.tolerance >= 0.0,
            "tolerance",
            || format!("must be finite and >= 0, got {}", self.tolerance),
        )
    }

    /// The per-point cost of the shape step (final outlier distance).
    pub fn point_cost(&self) -> PointCost {
        point_cost(&self.fit.em)
    }
}

pub(super) fn point_cost(em: &EmConfig) -> PointCost {
    PointCost {
        sigma: em.sigma,
        loss: em.loss,
        truncation: em.truncation_factor * em.outlier_distance,
    }
}
