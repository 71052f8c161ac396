//! Body-shape calibration: the shape factors ([`crate::body::SHAPE_FACTOR_NAMES`]) and
//! the poses of one or several frames, fitted together.
//!
//! # Objective
//! The same energy as the pose fit ([`super::em`]), summed over the frames, at the final
//! outlier distance τ, plus a weak quadratic prior on the shape factors:
//!
//! E(s, Θ, V) = Σ_f E_f(s, θ_f, V_f) + ½·w·Σ_j (s_j − 1)²
//!
//! where s are the factors of the base model's shape ([`crate::body::BodyShape::scaled`]),
//! θ_f the pose and V_f the part labels of frame f.
//!
//! # Algorithm ([`fit_shape`])
//! Rounds of two steps, each of which never increases E:
//! 1. *Pose/label step*: every frame is refitted by hard EM ([`super::hard_em`]) with the
//!    current shape from its current pose; the new pose and labels replace the old ones
//!    only if they lower E_f (hard EM restarts its outlier schedule and labelling, so it
//!    may end above the previous state).
//! 2. *Shape step* ([`shape_lm`]): for fixed labels, Levenberg–Marquardt over the shape
//!    factors jointly with every frame's pose, minimising Σ ρ(min(|d|, T))/σ² over the
//!    labelled points (d = signed point-to-ellipsoid distance: exactly the E1 part of
//!    E_f; the pairwise part does not depend on s or θ) plus the prior. Bounds: factors
//!    within [`ShapeConfig::lower`]..[`ShapeConfig::upper`], joint angles within their
//!    limits (projected LM with an active set, as in [`super::lm`]); a step is kept only
//!    if it lowers the cost.
//!
//! # Jacobian
//! Analytic for both parts. Pose columns: −n·v (n the outward normal at the closest
//! point, v the velocity of the point under the parameter), as in the pose fit. Shape
//! columns: with the pose fixed, every placed ellipsoid's centre c (camera frame) and
//! half-axes r are *linear* in the factors (segment lengths only translate frames), so
//! their derivatives dc/ds_j, dr/ds_j are taken exactly as central differences of the
//! placed ellipsoids (16 ellipsoids, once per frame and factor, not per point). Per
//! point, d(d)/dc = −n and d(d)/dr_i = −n_i·x_i/r_i (x the closest point and n the
//! normal in the ellipsoid frame: the surface's normal speed when r_i grows).
//!
//! Deterministic: frames are accumulated independently and summed in frame order.

mod calibrate;
mod config;
mod lm;
mod system;
#[cfg(test)]
mod tests;

/// Why [`shape_lm`] stopped (same meanings as [`crate::fit::Termination`]).
pub use crate::fit::lm::Termination as ShapeTermination;
pub use calibrate::{fit_shape, ShapeFrame, ShapeResult};
pub use config::ShapeConfig;
pub use lm::{shape_lm, ShapeLmReport};
pub use system::LabelledFrame;
