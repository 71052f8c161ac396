//! The template database that finds the initial pose (paper Section II-C).
//!
//! 768 templates: 4 poses per arm (down, raised sideways, forward, bent) and per leg
//! (standing, step forward, step back, knee raised), 4⁴ = 256 body poses, each seen from
//! 3 directions (front, left side, right side). Each template's depth image is rendered
//! from the super-quadric body (eq. 1, [`crate::body::superquadric`]) by a z-buffer
//! rasteriser of its meshes (or from the ellipsoids by [`crate::render`], or supplied
//! by the caller, e.g. trimesh ray casting from Python), and described by surface
//! contexts ([`crate::descriptor`]).
//!
//! Matching a depth image: a pruning stage scores every template by representative
//! descriptors (Mori, Belongie and Malik 2005: a few query samples, each matched to its
//! nearest template descriptor), then an exact one-to-one assignment with outliers
//! ([`crate::assignment`]) ranks the short list. The cost of a pair of samples is the
//! L2 distance of their descriptors plus `location_weight` times the distance of their
//! normalised positions (an extension: it keeps a left hand from matching a right one).
//! Both stages run in parallel over templates.

mod catalogue;
mod columns;
mod cost;
mod cost_kernel;
mod database;
#[cfg(test)]
mod eval;
mod format;
mod matching;
mod prune;
mod raster;
mod template;
#[cfg(test)]
mod tests;

pub use catalogue::{
    template_code, template_pose, ARM_POSE_NAMES, LEG_POSE_NAMES, LIMB_POSES, NUM_TEMPLATES,
    NUM_VIEWS, VIEW_NAMES,
};
pub use columns::QueryColumns;
pub use cost::matching_cost;
pub use database::{TemplateDatabase, FORMAT_VERSION};
pub use format::{config_from_vec, config_to_vec, TemplateArrays, CONFIG_VALUES, MAX_SEED};
pub use matching::{Candidate, MatchConfig, MatchResult};
pub use raster::{rasterize_meshes_into, render_template};
pub use template::Template;

use crate::body::superquadric::MeshConfig;
use crate::camera::Camera;
use crate::descriptor::DescriptorConfig;
use crate::error::{ensure, Result};

/// How template depth images are rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TemplateRenderer {
    /// Z-buffer rasterisation of the super-quadric meshes (paper eq. 1), in Rust.
    Superquadric,
    /// Analytic ray casting of the fitting ellipsoids ([`crate::render`]).
    Ellipsoid,
}

/// Settings of the template database.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemplateConfig {
    /// Template image size (pixels).
    pub width: usize,
    pub height: usize,
    /// Camera → hip centre distance of every template (m).
    pub distance: f64,
    /// Height of the scene covered by the image at `distance` (m); sets the focal length.
    pub field_height: f64,
    pub renderer: TemplateRenderer,
    pub mesh: MeshConfig,
    pub descriptor: DescriptorConfig,
}

impl Default for TemplateConfig {
    fn default() -> Self {
        TemplateConfig {
            width: 96,
            height: 96,
            distance: 3.0,
            field_height: 2.4,
            renderer: TemplateRenderer::Superquadric,
            mesh: MeshConfig {
                rings: 16,
                sectors: 20,
            },
            descriptor: DescriptorConfig::default(),
        }
    }
}

impl TemplateConfig {
    pub fn validate(&self) -> Result<()> {
        self.descriptor.validate()?;
        ensure(
            (16..=1024).contains(&self.width) && (16..=1024).contains(&self.height),
            "width/height",
            || {
                format!(
                    "template images must be 16..=1024 pixels a side, got {}x{}",
                    self.width, self.height
                )
            },
        )?;
        crate::error::ensure_positive(self.distance, "distance")?;
        crate::error::ensure_positive(self.field_height, "field_height")?;
        let divisions = 3..=crate::body::superquadric::MAX_MESH_DIVISIONS;
        ensure(
            divisions.contains(&self.mesh.rings) && divisions.contains(&self.mesh.sectors),
            "mesh",
            || format!("rings and sectors must be within {divisions:?}"),
        )
    }

    /// The camera the templates are rendered with.
    pub fn camera(&self) -> Result<Camera> {
        let f = self.height as f64 * self.distance / self.field_height;
        Camera::new(
            f,
            f,
            0.5 * (self.width as f64 - 1.0),
            0.5 * (self.height as f64 - 1.0),
            self.width,
            self.height,
        )
    }
}

#[cfg(test)]
mod format_fuzz;
