//! One template: its pose and joints, its descriptors, and where its body sits.

use crate::body::{BodyModel, Pose, NUM_JOINTS};
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::descriptor::{DescriptorConfig, Silhouette, SurfaceContext};
use crate::error::Result;
use nalgebra::Vector3;

/// One template: its pose, joints and descriptors, and where its body sits.
#[derive(Debug, Clone, PartialEq)]
pub struct Template {
    /// Pose as rendered (hip centre `distance` m straight ahead).
    pub pose: Pose,
    pub view: usize,
    /// Joints of `pose` (camera frame of the template camera).
    pub joints: [[f64; 3]; NUM_JOINTS],
    /// 3-D centroid of the visible surface.
    pub centroid: [f64; 3],
    /// Metric size of the silhouette: the descriptor scale (mean pairwise sample
    /// distance) in metres at the centroid's depth.
    pub size: f64,
    pub context: SurfaceContext,
}

impl Template {
    /// Describes a template from its depth image.
    pub fn from_depth(
        model: &BodyModel,
        pose: &Pose,
        view: usize,
        depth: &[f32],
        camera: &Camera,
        descriptor: &DescriptorConfig,
    ) -> Result<Self> {
        let view_ = DepthView::new(depth, camera.height, camera.width, "depth")?;
        let sil = Silhouette::from_depth(&view_, camera, None, descriptor.normal_radius)?;
        let context = sil.surface_context(descriptor)?;
        let size = metric_size(&context, &sil.centroid, camera);
        Ok(Template {
            pose: *pose,
            view,
            joints: model.joints(pose).map(|j| [j.x, j.y, j.z]),
            centroid: [sil.centroid.x, sil.centroid.y, sil.centroid.z],
            size,
            context,
        })
    }
}

/// The metric size of a body described by `context` whose visible surface has its
/// centroid at `centroid`: the descriptor scale in metres at the centroid's depth.
pub(super) fn metric_size(
    context: &SurfaceContext,
    centroid: &Vector3<f64>,
    camera: &Camera,
) -> f64 {
    context.scale * centroid.z / (camera.fx * camera.fy).sqrt()
}
