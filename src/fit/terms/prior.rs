//! A soft prior toward a pose.

use crate::body::rotation::rotation_vector;
use crate::body::{root_rotation, Pose};
use crate::fit::system::{N, NN};
use nalgebra::{Rotation3, Vector3};

/// Soft prior toward a pose: cost ½ Σ wᵢ (θᵢ − θ_prior,ᵢ)², where for the root rotation
/// the difference is the body-frame rotation log(R_priorᵀ R) (its Jacobian with respect
/// to ω is taken as the identity, exact at the prior; the LM's cost test uses the exact
/// cost, so this only affects the step, not the monotonicity).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PosePrior {
    pub pose: Pose,
    /// One weight per parameter (≥ 0).
    pub weights: [f64; N],
}

impl PosePrior {
    /// The same weight for translation (per m²), rotation and angles (per rad²).
    pub fn uniform(pose: Pose, translation_weight: f64, angle_weight: f64) -> Self {
        let mut weights = [angle_weight; N];
        weights[..3].fill(translation_weight);
        PosePrior { pose, weights }
    }

    fn residuals(&self, pose: &Pose) -> [f64; N] {
        let mut r = [0.0; N];
        for i in 0..N {
            r[i] = pose[i] - self.pose[i];
        }
        let rel: Rotation3<f64> = root_rotation(&self.pose).inverse() * root_rotation(pose);
        let w: Vector3<f64> = rotation_vector(&rel);
        r[3..6].copy_from_slice(w.as_slice());
        r
    }

    /// The prior's cost.
    pub fn cost(&self, pose: &Pose) -> f64 {
        let r = self.residuals(pose);
        0.5 * r
            .iter()
            .zip(&self.weights)
            .map(|(r, w)| w * r * r)
            .sum::<f64>()
    }

    /// Adds the prior's Gauss–Newton terms; returns its cost.
    pub fn add_to(&self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
        let r = self.residuals(pose);
        let mut cost = 0.0;
        for i in 0..N {
            h[i * N + i] += self.weights[i];
            g[i] += self.weights[i] * r[i];
            cost += 0.5 * self.weights[i] * r[i] * r[i];
        }
        cost
    }
}
