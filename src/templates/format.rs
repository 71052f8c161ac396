//! The database as flat arrays (the file format) and the template settings as
//! numbers.

use super::catalogue::{NUM_TEMPLATES, NUM_VIEWS};
use super::database::{TemplateDatabase, FORMAT_VERSION};
use super::template::Template;
use super::TemplateConfig;
use super::TemplateRenderer;
use crate::body::superquadric::MeshConfig;
use crate::body::{BodyModel, NUM_JOINTS, NUM_PARAMS};
use crate::descriptor::{DescriptorConfig, SurfaceContext};
use crate::error::{ensure, Result};

/// A database as flat arrays (what the Python layer stores in a file).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TemplateArrays {
    pub format_version: u32,
    pub hash: u64,
    /// Model shape, [`crate::body::SHAPE_PARAM_NAMES`] order.
    pub shape: Vec<f64>,
    /// [`TemplateConfig`] as numbers (see [`config_to_vec`]).
    pub config: Vec<f64>,
    pub poses: Vec<f64>,
    pub views: Vec<i64>,
    pub joints: Vec<f64>,
    pub centroids: Vec<f64>,
    pub sizes: Vec<f64>,
    /// Samples per template.
    pub counts: Vec<i64>,
    pub context_scale: Vec<f64>,
    pub context_centroid: Vec<f64>,
    pub context_points: Vec<i64>,
    /// All templates' samples concatenated: pixels (S×2), positions (S×2),
    /// descriptors (S×dim).
    pub sample_pixels: Vec<f32>,
    pub sample_positions: Vec<f32>,
    pub descriptors: Vec<f32>,
}

/// Number of values of [`config_to_vec`].
pub const CONFIG_VALUES: usize = 16;
/// Largest seed that survives the trip through f64.
pub const MAX_SEED: u64 = 1 << 53;

/// [`TemplateConfig`] as numbers: width, height, distance, field_height, renderer
/// (0 super-quadric, 1 ellipsoid), mesh rings, sectors, then the descriptor's samples,
/// radial_bins, angular_bins, inner_radius, outer_radius, cells_per_sample, seed,
/// normal_radius, depth_weight.
pub fn config_to_vec(c: &TemplateConfig) -> [f64; CONFIG_VALUES] {
    let d = &c.descriptor;
    [
        c.width as f64,
        c.height as f64,
        c.distance,
        c.field_height,
        match c.renderer {
            TemplateRenderer::Superquadric => 0.0,
            TemplateRenderer::Ellipsoid => 1.0,
        },
        c.mesh.rings as f64,
        c.mesh.sectors as f64,
        d.samples as f64,
        d.radial_bins as f64,
        d.angular_bins as f64,
        d.inner_radius,
        d.outer_radius,
        d.cells_per_sample,
        d.seed as f64,
        d.normal_radius as f64,
        d.depth_weight,
    ]
}

/// The inverse of [`config_to_vec`] (validated).
pub fn config_from_vec(v: &[f64]) -> Result<TemplateConfig> {
    ensure(v.len() == CONFIG_VALUES, "config", || {
        format!("needs {CONFIG_VALUES} values, got {}", v.len())
    })?;
    let int = |x: f64, name: &str| -> Result<usize> {
        ensure(
            x.is_finite() && x >= 0.0 && x.fract() == 0.0 && x < 1e15,
            name,
            || format!("must be a whole number, got {x}"),
        )?;
        Ok(x as usize)
    };
    let renderer = match int(v[4], "renderer")? {
        0 => TemplateRenderer::Superquadric,
        1 => TemplateRenderer::Ellipsoid,
        r => {
            return Err(crate::Error::invalid(
                "renderer",
                format!("unknown renderer {r}"),
            ))
        }
    };
    let c = TemplateConfig {
        width: int(v[0], "width")?,
        height: int(v[1], "height")?,
        distance: v[2],
        field_height: v[3],
        renderer,
        mesh: MeshConfig {
            rings: int(v[5], "rings")?,
            sectors: int(v[6], "sectors")?,
        },
        descriptor: DescriptorConfig {
            samples: int(v[7], "samples")?,
            radial_bins: int(v[8], "radial_bins")?,
            angular_bins: int(v[9], "angular_bins")?,
            inner_radius: v[10],
            outer_radius: v[11],
            cells_per_sample: v[12],
            seed: int(v[13], "seed")? as u64,
            normal_radius: int(v[14], "normal_radius")?,
            depth_weight: v[15],
        },
    };
    c.validate()?;
    Ok(c)
}

impl TemplateDatabase {
    /// The database as flat arrays.
    pub fn to_arrays(&self) -> TemplateArrays {
        let mut a = TemplateArrays {
            format_version: FORMAT_VERSION,
            hash: self.hash(),
            shape: self.model.shape.to_vec().to_vec(),
            config: config_to_vec(&self.config).to_vec(),
            ..Default::default()
        };
        for t in &self.templates {
            a.poses.extend_from_slice(&t.pose);
            a.views.push(t.view as i64);
            a.joints.extend(t.joints.iter().flatten());
            a.centroids.extend_from_slice(&t.centroid);
            a.sizes.push(t.size);
            a.counts.push(t.context.len() as i64);
            a.context_scale.push(t.context.scale);
            a.context_centroid.extend_from_slice(&t.context.centroid);
            a.context_points.push(t.context.points as i64);
            a.sample_pixels.extend(t.context.pixels.iter().flatten());
            a.sample_positions
                .extend(t.context.positions.iter().flatten());
            a.descriptors.extend_from_slice(&t.context.descriptors);
        }
        a
    }

    /// A database from [`Self::to_arrays`] output. `source` names the file in errors.
    /// Refuses another format version, arrays that do not fit together, and — when
    /// `expected` is given — a database of another model or other template settings
    /// (by [`Self::settings_hash`]); all as [`crate::Error::File`].
    pub fn from_arrays(
        a: &TemplateArrays,
        expected: Option<(&BodyModel, &TemplateConfig)>,
        source: &str,
    ) -> Result<Self> {
        let bad = |msg: String| crate::Error::file(source, msg);
        if a.format_version != FORMAT_VERSION {
            return Err(bad(format!(
                "template format version {} but this depthpose reads version {FORMAT_VERSION}; rebuild the database",
                a.format_version
            )));
        }
        let model = BodyModel::with_shape(
            crate::body::BodyShape::from_vec(&a.shape)
                .map_err(|e| bad(format!("bad model shape: {e}")))?,
        );
        let config =
            config_from_vec(&a.config).map_err(|e| bad(format!("bad template settings: {e}")))?;
        let hash = Self::settings_hash(&model, &config);
        if hash != a.hash {
            return Err(bad(format!(
                "content hash {:016x} does not match its settings ({hash:016x}); the file is corrupt or from another template definition",
                a.hash
            )));
        }
        if let Some((m, c)) = expected {
            let want = Self::settings_hash(m, c);
            if want != hash {
                return Err(bad(
                    "the templates were built for another body model or other template settings; rebuild them"
                        .to_string(),
                ));
            }
        }
        let t = NUM_TEMPLATES;
        let dim = config.descriptor.dim();
        // Checked: counts from a file may sum (or multiply) past i64; -1 fits no array.
        let total = (a.counts.iter())
            .try_fold(0i64, |s, &c| s.checked_add(c))
            .unwrap_or(-1);
        let sizes_ok = a.poses.len() == t * NUM_PARAMS
            && a.views.len() == t
            && a.joints.len() == t * NUM_JOINTS * 3
            && a.centroids.len() == t * 3
            && a.sizes.len() == t
            && a.counts.len() == t
            && a.context_scale.len() == t
            && a.context_centroid.len() == t * 2
            && a.context_points.len() == t
            && a.counts.iter().all(|&c| c >= 2)
            && Some(a.sample_pixels.len() as i64) == total.checked_mul(2)
            && Some(a.sample_positions.len() as i64) == total.checked_mul(2)
            && Some(a.descriptors.len() as i64) == total.checked_mul(dim as i64);
        if !sizes_ok {
            return Err(bad(
                "the arrays do not fit together (truncated or corrupt file)".to_string(),
            ));
        }
        let finite = a
            .poses
            .iter()
            .chain(&a.joints)
            .chain(&a.centroids)
            .chain(&a.sizes)
            .all(|v| v.is_finite())
            && a.descriptors
                .iter()
                .chain(&a.sample_positions)
                .all(|v| v.is_finite());
        if !finite {
            return Err(bad("non-finite values (corrupt file)".to_string()));
        }
        let mut templates = Vec::with_capacity(t);
        let mut off = 0usize;
        for i in 0..t {
            let n = a.counts[i] as usize;
            let mut pose = [0.0; NUM_PARAMS];
            pose.copy_from_slice(&a.poses[i * NUM_PARAMS..(i + 1) * NUM_PARAMS]);
            let view = a.views[i];
            if !(0..NUM_VIEWS as i64).contains(&view) {
                return Err(bad(format!("template {i} has view {view}")));
            }
            let pair = |v: &[f32], k: usize| [v[2 * k], v[2 * k + 1]];
            templates.push(Template {
                pose,
                view: view as usize,
                joints: std::array::from_fn(|j| {
                    let b = (i * NUM_JOINTS + j) * 3;
                    [a.joints[b], a.joints[b + 1], a.joints[b + 2]]
                }),
                centroid: [
                    a.centroids[3 * i],
                    a.centroids[3 * i + 1],
                    a.centroids[3 * i + 2],
                ],
                size: a.sizes[i],
                context: SurfaceContext {
                    dim,
                    pixels: (off..off + n).map(|k| pair(&a.sample_pixels, k)).collect(),
                    positions: (off..off + n)
                        .map(|k| pair(&a.sample_positions, k))
                        .collect(),
                    descriptors: a.descriptors[off * dim..(off + n) * dim].to_vec(),
                    scale: a.context_scale[i],
                    centroid: [a.context_centroid[2 * i], a.context_centroid[2 * i + 1]],
                    points: a.context_points[i].max(0) as usize,
                },
            });
            off += n;
        }
        Ok(TemplateDatabase::new(model, config, templates))
    }
}
