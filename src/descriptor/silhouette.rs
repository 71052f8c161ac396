//! A silhouette from a depth image, its normals turned to the line of sight.

use super::config::{DescriptorConfig, MAX_DEPTH_FROM_MEDIAN, MIN_POINTS};
use super::context::{surface_context_with_relief, SurfaceContext};
use crate::camera::Camera;
use crate::cloud::{normals_from_depth, Cloud, DepthView, NormalConfig};
use crate::error::{Error, Result};
use nalgebra::{Rotation3, Vector3};

/// The rotation taking the unit line of sight `dir` to +z (the shortest arc).
pub fn line_of_sight_alignment(dir: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::rotation_between(dir, &Vector3::z()).unwrap_or_else(Rotation3::identity)
}

/// A silhouette ready to describe: its cloud, normals (aligned to the line of sight)
/// and 3-D centroid.
#[derive(Debug, Clone)]
pub struct Silhouette {
    pub cloud: Cloud,
    /// Unit normals, rotated by `alignment`.
    pub normals: Vec<[f32; 3]>,
    /// Mean of the 3-D points (camera frame).
    pub centroid: Vector3<f64>,
    /// Rotation taking the line of sight to the centroid onto +z.
    pub alignment: Rotation3<f64>,
}

impl Silhouette {
    /// Back-projects the masked depth pixels and estimates their normals.
    pub fn from_depth(
        depth: &DepthView,
        camera: &Camera,
        mask: Option<&[bool]>,
        normal_radius: usize,
    ) -> Result<Self> {
        let mut cloud = Cloud::from_depth(depth, camera, mask)?;
        // Masks from background subtraction or ground truth can hold a few pixels of
        // the floor or wall behind the body: drop points far from the median depth.
        if !cloud.is_empty() {
            let mut z: Vec<f32> = cloud.points.iter().map(|p| p[2]).collect();
            let mid = z.len() / 2;
            let median = *z.select_nth_unstable_by(mid, f32::total_cmp).1;
            let far = |p: &[f32; 3]| (p[2] - median).abs() > MAX_DEPTH_FROM_MEDIAN;
            if cloud.points.iter().any(far) {
                let mut keep = vec![false; depth.data.len()];
                for (p, &i) in cloud.points.iter().zip(&cloud.pixels) {
                    keep[i as usize] = !far(p);
                }
                cloud = Cloud::from_depth(depth, camera, Some(&keep))?;
            }
        }
        let centroid = match cloud.centroid() {
            Some(c) if cloud.len() >= MIN_POINTS => c,
            _ => {
                return Err(Error::NoBody(format!(
                    "only {} foreground pixels with depth; at least {MIN_POINTS} are needed",
                    cloud.len()
                )))
            }
        };
        let mut normals = normals_from_depth(
            depth,
            camera,
            &cloud,
            &NormalConfig {
                radius: normal_radius,
                ..Default::default()
            },
        );
        let alignment = line_of_sight_alignment(&centroid.normalize());
        let r = alignment.matrix().cast::<f32>();
        for n in normals.iter_mut() {
            let v = r * Vector3::from(*n);
            *n = [v.x, v.y, v.z];
        }
        Ok(Silhouette {
            cloud,
            normals,
            centroid,
            alignment,
        })
    }

    /// Pixel positions (u, v) of the points.
    pub fn pixels(&self) -> Vec<[f32; 2]> {
        (0..self.cloud.len())
            .map(|k| {
                let (r, c) = self.cloud.pixel(k);
                [c as f32, r as f32]
            })
            .collect()
    }

    /// Each point's relief: its depth relative to the centroid along the line of sight,
    /// in units of the RMS distance of the points from the centroid across it (see
    /// [`DescriptorConfig::depth_weight`]).
    pub fn relief(&self) -> Vec<f32> {
        let r = self.alignment.matrix();
        let local: Vec<Vector3<f64>> = self
            .cloud
            .points
            .iter()
            .map(|p| r * (Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) - self.centroid))
            .collect();
        let across = local.iter().map(|v| v.x * v.x + v.y * v.y).sum::<f64>();
        let rms = (across / local.len().max(1) as f64).sqrt().max(1e-9);
        local.iter().map(|v| (v.z / rms) as f32).collect()
    }

    /// Its surface-context descriptors.
    pub fn surface_context(&self, config: &DescriptorConfig) -> Result<SurfaceContext> {
        let relief = (config.depth_weight > 0.0).then(|| self.relief());
        surface_context_with_relief(&self.pixels(), &self.normals, relief.as_deref(), config)
    }
}

/// Surface-context descriptors of the (masked) body in a depth image (metres, H×W).
pub fn surface_context_from_depth(
    depth: &DepthView,
    camera: &Camera,
    mask: Option<&[bool]>,
    config: &DescriptorConfig,
) -> Result<SurfaceContext> {
    config.validate()?;
    Silhouette::from_depth(depth, camera, mask, config.normal_radius)?.surface_context(config)
}
