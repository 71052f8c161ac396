//! The settings of hard EM and the costs they define.

use crate::error::{ensure, Result};
use crate::fit::lm::LmConfig;
use crate::fit::terms::free_space::FreeSpaceCost;
use crate::fit::terms::{Loss, PointCost};

/// Default weight of the free-space term ([`EmConfig::free_space_weight`]).
pub const DEFAULT_FREE_SPACE_WEIGHT: f64 = 3.0;

/// Settings of [`hard_em`](super::hard_em).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmConfig {
    /// Residual scale σ (m) of the unary term.
    pub sigma: f64,
    /// Loss of the point residuals.
    pub loss: Loss,
    /// Generalised Potts weight K (eq. 8).
    pub potts: f64,
    /// Weight c of the depth-contrast term (eq. 9).
    pub contrast_weight: f64,
    /// Depth-difference scale σ_c (m) of the contrast term.
    pub contrast_sigma: f64,
    /// Final outlier distance τ (m).
    pub outlier_distance: f64,
    /// Outlier distance at the first iteration (≥ `outlier_distance`).
    pub outlier_distance_start: f64,
    /// τ reaches its final value after this many iterations.
    pub anneal_iterations: usize,
    /// Once the fit has settled while τ is still annealing (at most
    /// `label_change_tolerance` of the labels changed and no joint moved more than
    /// `settled_joint_motion` in an iteration), τ jumps to its final value for the next
    /// iteration instead of stepping down to it over the remaining ones: a settled fit
    /// needs no more gradual tightening, and a fit still moving anneals as before
    /// ([`EmResult::anneal_cut`](super::EmResult::anneal_cut)).
    pub adaptive_anneal: bool,
    /// See `adaptive_anneal` (m).
    pub settled_joint_motion: f64,
    /// Residuals beyond this multiple of τ are truncated (≥ 1).
    pub truncation_factor: f64,
    /// At most this many E/M iterations.
    pub max_iterations: usize,
    /// Converged when at most this fraction of the labels changed ...
    pub label_change_tolerance: f64,
    /// ... and the energy dropped by at most this fraction in the last iteration.
    pub energy_tolerance: f64,
    /// Alpha-expansion cycles per E-step.
    pub expansion_cycles: usize,
    /// Weight λ of the free-space term (one surface sample against one point; 0 turns
    /// it off; see [`crate::fit::terms::free_space`]). Used when the fit has the depth image.
    pub free_space_weight: f64,
    /// Depth (m) a model sample may lie in front of the observed surface for free.
    pub free_space_margin: f64,
    /// Truncation (m) of the free-space residuals.
    pub free_space_truncation: f64,
    /// The M-step's LM settings.
    pub lm: LmConfig,
}

impl Default for EmConfig {
    fn default() -> Self {
        EmConfig {
            sigma: 0.02,
            loss: Loss::Squared,
            potts: 0.3,
            contrast_weight: 1.0,
            contrast_sigma: 0.02,
            outlier_distance: 0.1,
            outlier_distance_start: 0.2,
            anneal_iterations: 6,
            adaptive_anneal: true,
            settled_joint_motion: 1e-3,
            truncation_factor: 2.0,
            max_iterations: 20,
            label_change_tolerance: 0.002,
            energy_tolerance: 1e-4,
            expansion_cycles: 3,
            free_space_weight: DEFAULT_FREE_SPACE_WEIGHT,
            free_space_margin: 0.03,
            free_space_truncation: 0.05,
            lm: LmConfig {
                // The EM loop re-linearises after every E-step anyway; a few LM
                // iterations per M-step fit the shared sequences better and faster than
                // a full solve (docs/design.md).
                max_iterations: 3,
                cost_tolerance: 1e-5,
                ..LmConfig::default()
            },
        }
    }
}

impl EmConfig {
    /// Checks every field, naming the bad one.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        ensure(pos(self.sigma), "sigma", || {
            format!("must be finite and > 0, got {}", self.sigma)
        })?;
        match self.loss {
            Loss::Squared => {}
            Loss::Huber(d) | Loss::Cauchy(d) => ensure(pos(d), "loss", || {
                format!("robust loss scale must be finite and > 0, got {d}")
            })?,
        }
        ensure(nonneg(self.potts), "potts", || {
            format!("must be finite and >= 0, got {}", self.potts)
        })?;
        ensure(nonneg(self.contrast_weight), "contrast_weight", || {
            format!("must be finite and >= 0, got {}", self.contrast_weight)
        })?;
        ensure(pos(self.contrast_sigma), "contrast_sigma", || {
            format!("must be finite and > 0, got {}", self.contrast_sigma)
        })?;
        ensure(pos(self.outlier_distance), "outlier_distance", || {
            format!("must be finite and > 0, got {}", self.outlier_distance)
        })?;
        ensure(
            self.outlier_distance_start.is_finite()
                && self.outlier_distance_start >= self.outlier_distance,
            "outlier_distance_start",
            || {
                format!(
                    "must be finite and >= outlier_distance ({}), got {}",
                    self.outlier_distance, self.outlier_distance_start
                )
            },
        )?;
        ensure(
            self.truncation_factor.is_finite() && self.truncation_factor >= 1.0,
            "truncation_factor",
            || format!("must be >= 1, got {}", self.truncation_factor),
        )?;
        ensure(self.max_iterations > 0, "max_iterations", || {
            "must be at least 1".to_string()
        })?;
        ensure(
            (0.0..=1.0).contains(&self.label_change_tolerance),
            "label_change_tolerance",
            || format!("must be within 0..1, got {}", self.label_change_tolerance),
        )?;
        ensure(
            nonneg(self.settled_joint_motion),
            "settled_joint_motion",
            || format!("must be finite and >= 0, got {}", self.settled_joint_motion),
        )?;
        ensure(nonneg(self.energy_tolerance), "energy_tolerance", || {
            format!("must be finite and >= 0, got {}", self.energy_tolerance)
        })?;
        ensure(self.expansion_cycles > 0, "expansion_cycles", || {
            "must be at least 1".to_string()
        })?;
        ensure(nonneg(self.free_space_weight), "free_space_weight", || {
            format!("must be finite and >= 0, got {}", self.free_space_weight)
        })?;
        ensure(nonneg(self.free_space_margin), "free_space_margin", || {
            format!("must be finite and >= 0, got {}", self.free_space_margin)
        })?;
        ensure(
            pos(self.free_space_truncation),
            "free_space_truncation",
            || format!("must be finite and > 0, got {}", self.free_space_truncation),
        )?;
        self.lm.validate()
    }

    /// Whether iteration `it`'s E-step (0: the initial one) has the final τ in a run
    /// whose annealing was cut after iteration `cut` ([`EmResult::anneal_cut`]).
    ///
    /// [`EmResult::anneal_cut`]: super::EmResult::anneal_cut
    pub fn annealed_in(&self, it: usize, cut: Option<usize>) -> bool {
        it >= self.anneal_iterations || cut.is_some_and(|k| k < it)
    }

    /// τ of iteration `it`'s E-step in a run whose annealing was cut after iteration
    /// `cut`: the final value once [`Self::annealed_in`], else
    /// [`Self::outlier_distance_at`].
    pub fn outlier_distance_in(&self, it: usize, cut: Option<usize>) -> f64 {
        if self.annealed_in(it, cut) {
            self.outlier_distance
        } else {
            self.outlier_distance_at(it)
        }
    }

    /// τ at iteration `it` (0-based): geometric from the start value to the final one.
    pub fn outlier_distance_at(&self, it: usize) -> f64 {
        if self.anneal_iterations == 0 || it >= self.anneal_iterations {
            return self.outlier_distance;
        }
        let t = it as f64 / self.anneal_iterations as f64;
        self.outlier_distance_start.powf(1.0 - t) * self.outlier_distance.powf(t)
    }

    /// The per-point cost at outlier distance `tau`: residuals truncated at
    /// `truncation_factor`·τ.
    pub(crate) fn point_cost(&self, tau: f64) -> PointCost {
        PointCost {
            sigma: self.sigma,
            loss: self.loss,
            truncation: self.truncation_factor * tau,
        }
    }

    /// The free-space term's settings, its weight scaled by `weight_scale` (a
    /// sub-sampled fit has fewer points per sample).
    pub fn free_space_cost(&self, weight_scale: f64) -> FreeSpaceCost {
        FreeSpaceCost {
            weight: self.free_space_weight * weight_scale,
            margin: self.free_space_margin,
            sigma: self.sigma,
            truncation: self.free_space_truncation,
        }
    }

    /// The unary cost of the outlier label at outlier distance `tau`.
    pub(crate) fn outlier_cost(&self, tau: f64) -> f64 {
        self.loss.rho(tau) / (self.sigma * self.sigma)
    }
}
