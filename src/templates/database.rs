//! The template database: templates described from their depth images, built,
//! and identified by a hash of everything they depend on.

use super::catalogue::{template_code, template_pose, NUM_TEMPLATES};
use super::prune::PruneIndex;
use super::raster::render_template;
use super::template::Template;
use super::TemplateConfig;
use super::TemplateRenderer;
use crate::body::BodyModel;
use crate::error::{ensure, Result};
use rayon::prelude::*;

/// Version of the template file format and of the template definition; bump when
/// either changes so stale caches are rebuilt.
pub const FORMAT_VERSION: u32 = 3;

/// The template database.
#[derive(Debug, Clone, PartialEq)]
pub struct TemplateDatabase {
    pub model: BodyModel,
    pub config: TemplateConfig,
    pub templates: Vec<Template>,
    /// The pruning stage's lower bounds, derived from `templates` when the database is
    /// made.
    pub(super) prune: PruneIndex,
}
/// FNV-1a over the 64-bit words that identify a database.
pub(super) fn fnv1a(words: impl IntoIterator<Item = u64>) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for w in words {
        for b in w.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

impl TemplateDatabase {
    /// A database of described templates (derives the pruning stage's bounds).
    pub fn new(model: BodyModel, config: TemplateConfig, templates: Vec<Template>) -> Self {
        let prune = PruneIndex::new(&templates);
        TemplateDatabase {
            model,
            config,
            templates,
            prune,
        }
    }

    /// Renders and describes all templates. `progress(done, total)` is called on the
    /// calling thread after each chunk.
    pub fn build_with_progress(
        model: &BodyModel,
        config: &TemplateConfig,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Self> {
        config.validate()?;
        const CHUNK: usize = 64;
        let cam = config.camera()?;
        let mut templates = Vec::with_capacity(NUM_TEMPLATES);
        for start in (0..NUM_TEMPLATES).step_by(CHUNK) {
            let stop = (start + CHUNK).min(NUM_TEMPLATES);
            let chunk: Vec<Template> = (start..stop)
                .into_par_iter()
                .map(|i| {
                    let depth = render_template(model, config, i)?;
                    let pose = template_pose(i, config.distance);
                    Template::from_depth(
                        model,
                        &pose,
                        template_code(i).1,
                        &depth,
                        &cam,
                        &config.descriptor,
                    )
                })
                .collect::<Result<_>>()?;
            templates.extend(chunk);
            progress(stop, NUM_TEMPLATES);
        }
        Ok(TemplateDatabase::new(model.clone(), *config, templates))
    }

    /// [`Self::build_with_progress`] without a progress report.
    pub fn build(model: &BodyModel, config: &TemplateConfig) -> Result<Self> {
        Self::build_with_progress(model, config, |_, _| {})
    }

    /// A database from depth images rendered elsewhere (e.g. trimesh ray casting):
    /// `depths` holds [`NUM_TEMPLATES`] images of `config.camera()`, in template order.
    pub fn from_depths(model: &BodyModel, config: &TemplateConfig, depths: &[f32]) -> Result<Self> {
        config.validate()?;
        let cam = config.camera()?;
        let n = cam.width * cam.height;
        ensure(depths.len() == n * NUM_TEMPLATES, "depths", || {
            format!(
                "needs {NUM_TEMPLATES} images of {}x{} ({} values), got {}",
                cam.height,
                cam.width,
                n * NUM_TEMPLATES,
                depths.len()
            )
        })?;
        let templates = depths
            .par_chunks(n)
            .enumerate()
            .map(|(i, d)| {
                let pose = template_pose(i, config.distance);
                Template::from_depth(
                    model,
                    &pose,
                    template_code(i).1,
                    d,
                    &cam,
                    &config.descriptor,
                )
            })
            .collect::<Result<_>>()?;
        Ok(TemplateDatabase::new(model.clone(), *config, templates))
    }

    /// A hash of everything a database depends on: format version, model shape,
    /// template settings (descriptor settings included) and the pose table.
    pub fn settings_hash(model: &BodyModel, config: &TemplateConfig) -> u64 {
        let d = &config.descriptor;
        let renderer = match config.renderer {
            TemplateRenderer::Superquadric => 0u64,
            TemplateRenderer::Ellipsoid => 1,
        };
        let mut words: Vec<u64> = vec![FORMAT_VERSION as u64];
        words.extend(model.shape.to_vec().iter().map(|v| v.to_bits()));
        words.extend([
            config.width as u64,
            config.height as u64,
            config.distance.to_bits(),
            config.field_height.to_bits(),
            renderer,
            config.mesh.rings as u64,
            config.mesh.sectors as u64,
            d.samples as u64,
            d.radial_bins as u64,
            d.angular_bins as u64,
            d.inner_radius.to_bits(),
            d.outer_radius.to_bits(),
            d.cells_per_sample.to_bits(),
            d.seed,
            d.normal_radius as u64,
            d.depth_weight.to_bits(),
        ]);
        for i in 0..NUM_TEMPLATES {
            words.extend(
                template_pose(i, config.distance)
                    .iter()
                    .map(|v| v.to_bits()),
            );
        }
        fnv1a(words)
    }

    /// This database's [`Self::settings_hash`].
    pub fn hash(&self) -> u64 {
        Self::settings_hash(&self.model, &self.config)
    }

    pub fn len(&self) -> usize {
        self.templates.len()
    }

    pub fn is_empty(&self) -> bool {
        self.templates.is_empty()
    }
}
