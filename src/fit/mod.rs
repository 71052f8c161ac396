//! Model fitting (paper Section II-D): CRF body-part labelling and Levenberg–Marquardt
//! in a hard EM loop ([`em`]), inverse kinematics from joints ([`ik`]) and body-shape
//! calibration ([`shape`]).
//!
//! [`fit_pose`] is the one-call entry: depth image + camera + initial pose → pose,
//! joints, per-pixel part labels and diagnostics.

pub mod em;
pub mod ik;
pub mod lm;
pub mod objective;
pub mod shape;

use crate::body::{pose_from_slice, BodyModel, Pose, NUM_JOINTS, NUM_SEGMENTS};
use crate::camera::Camera;
use crate::cloud::{neighbour_graph, Cloud, Connectivity, DepthView};
use crate::error::{Error, Result};
use nalgebra::Vector3;

pub use em::{hard_em, EmConfig, EmResult, EmTermination};
pub use ik::pose_from_joints;
pub use lm::{LevenbergMarquardt, LmConfig, LmReport, PosePrior, Termination};
pub use objective::Loss;
pub use shape::{fit_shape, shape_lm, ShapeConfig, ShapeFrame, ShapeResult};

/// Fewer foreground points than this cannot constrain 22 parameters.
pub const MIN_POINTS: usize = 50;

/// Settings of [`fit_pose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitConfig {
    pub em: EmConfig,
    /// Pixel neighbourhood of the CRF.
    pub connectivity: Connectivity,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            em: EmConfig::default(),
            connectivity: Connectivity::Four,
        }
    }
}

/// Outcome of [`fit_pose`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult {
    pub pose: Pose,
    /// The 15 joints (ITOP order), camera frame.
    pub joints: [Vector3<f64>; NUM_JOINTS],
    /// H×W part labels: segment 0..15, −1 = background or outlier.
    pub labels: Vec<i16>,
    pub energy: f64,
    pub energy_trace: Vec<f64>,
    pub iterations: usize,
    pub termination: EmTermination,
    /// Points labelled with each segment.
    pub part_counts: [usize; NUM_SEGMENTS],
    /// Foreground points labelled outlier.
    pub outliers: usize,
}

impl FitResult {
    pub fn converged(&self) -> bool {
        self.termination != EmTermination::MaxIterations
    }
}

/// Fits `model` to the foreground of `depth` (H×W metres, row-major; `mask` selects the
/// person's pixels, None = every reading) starting from `init_pose`, with an optional
/// prior toward a pose.
pub fn fit_pose(
    depth: &[f32],
    camera: &Camera,
    init_pose: &[f64],
    model: &BodyModel,
    mask: Option<&[bool]>,
    prior: Option<&PosePrior>,
    config: &FitConfig,
) -> Result<FitResult> {
    let init = pose_from_slice(init_pose, "init_pose")?;
    config.em.validate()?;
    let view = DepthView::new(depth, camera.height, camera.width, "depth")?;
    let cloud = Cloud::from_depth(&view, camera, mask)?;
    if cloud.len() < MIN_POINTS {
        return Err(Error::NoBody(format!(
            "the foreground has {} points, at least {MIN_POINTS} are needed",
            cloud.len()
        )));
    }
    let graph = neighbour_graph(&cloud, config.connectivity);
    let em = hard_em(model, &cloud.points, &graph, &init, prior, &config.em)?;
    let mut labels = vec![-1i16; depth.len()];
    for (&px, &l) in cloud.pixels.iter().zip(&em.labels) {
        labels[px as usize] = l as i16;
    }
    Ok(FitResult {
        pose: em.pose,
        joints: model.joints(&em.pose),
        labels,
        energy: em.energy,
        energy_trace: em.energy_trace,
        iterations: em.iterations,
        termination: em.termination,
        part_counts: em.part_counts,
        outliers: em.outliers,
    })
}

#[cfg(test)]
mod tests;
