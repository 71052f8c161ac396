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

use crate::assignment::{assignment_with_outliers, AssignmentWorkspace};
use crate::body::superquadric::{Mesh, MeshConfig};
use crate::body::{param, BodyModel, Pose, NUM_JOINTS, NUM_PARAMS};
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::descriptor::{DescriptorConfig, Silhouette, SurfaceContext};
use crate::error::{ensure, Result};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;

/// Version of the template file format and of the template definition; bump when
/// either changes so stale caches are rebuilt.
pub const FORMAT_VERSION: u32 = 3;

/// Poses per limb and view directions.
pub const LIMB_POSES: usize = 4;
pub const NUM_VIEWS: usize = 3;
/// Total number of templates: 4⁴ body poses × 3 views.
pub const NUM_TEMPLATES: usize = LIMB_POSES * LIMB_POSES * LIMB_POSES * LIMB_POSES * NUM_VIEWS;

pub const ARM_POSE_NAMES: [&str; LIMB_POSES] = ["down", "raised_sideways", "forward", "bent"];
pub const LEG_POSE_NAMES: [&str; LIMB_POSES] =
    ["standing", "step_forward", "step_back", "knee_raised"];
pub const VIEW_NAMES: [&str; NUM_VIEWS] = ["front", "left_side", "right_side"];

/// Shoulder (flexion, abduction, rotation) and elbow flexion of each arm pose.
const ARM_POSES: [[f64; 4]; LIMB_POSES] = [
    [0.0, 0.12, 0.0, 0.1],  // down
    [0.0, 1.45, 0.0, 0.1],  // raised sideways (near horizontal)
    [1.45, 0.1, 0.0, 0.1],  // forward (near horizontal)
    [0.25, 0.35, 0.0, 1.7], // bent (forearm forward and up)
];
/// Hip (flexion, abduction) and knee flexion of each leg pose.
const LEG_POSES: [[f64; 3]; LIMB_POSES] = [
    [0.0, 0.04, 0.0],   // standing
    [0.45, 0.04, 0.15], // step forward
    [-0.35, 0.04, 0.4], // step back
    [1.4, 0.04, 1.6],   // knee raised
];
/// Yaw (about the body's vertical axis) of each view: +90° turns the subject's left
/// side toward the camera.
const VIEW_YAW: [f64; NUM_VIEWS] = [
    0.0,
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
];

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

/// Arm, arm, leg, leg pose codes (right arm, left arm, right leg, left leg) and view of
/// template `index` (`index = view·256 + r_arm·64 + l_arm·16 + r_leg·4 + l_leg`).
pub fn template_code(index: usize) -> ([usize; 4], usize) {
    let view = index / 256;
    let rest = index % 256;
    ([rest / 64, (rest / 16) % 4, (rest / 4) % 4, rest % 4], view)
}

/// The pose of template `index`, hip centre `distance` m straight ahead.
pub fn template_pose(index: usize, distance: f64) -> Pose {
    let ([ra, la, rl, ll], view) = template_code(index);
    let mut p = [0.0; NUM_PARAMS];
    p[param::ROOT_T + 2] = distance;
    p[param::ROOT_R + 1] = VIEW_YAW[view];
    let arm = |p: &mut Pose, sh: usize, el: usize, code: usize| {
        p[sh..sh + 3].copy_from_slice(&ARM_POSES[code][..3]);
        p[el] = ARM_POSES[code][3];
    };
    arm(&mut p, param::R_SHOULDER, param::R_ELBOW, ra);
    arm(&mut p, param::L_SHOULDER, param::L_ELBOW, la);
    let leg = |p: &mut Pose, hip: usize, knee: usize, code: usize| {
        p[hip..hip + 2].copy_from_slice(&LEG_POSES[code][..2]);
        p[knee] = LEG_POSES[code][2];
    };
    leg(&mut p, param::R_HIP, param::R_KNEE, rl);
    leg(&mut p, param::L_HIP, param::L_KNEE, ll);
    p
}

/// Z-buffer rasterisation of triangle meshes into `depth` (H×W metres, 0 = empty):
/// pixel centres inside a projected triangle take the perspective-correct depth
/// (1/z interpolated linearly in the image); the nearest surface wins.
pub fn rasterize_meshes_into(meshes: &[Mesh], camera: &Camera, depth: &mut [f32]) -> Result<()> {
    let (w, h) = (camera.width, camera.height);
    ensure(depth.len() == w * h, "depth", || {
        format!(
            "buffer has {} values, the camera needs {h}x{w}",
            depth.len()
        )
    })?;
    depth.fill(0.0);
    const NEAR: f64 = 1e-3;
    for mesh in meshes {
        let proj: Vec<[f64; 3]> = mesh
            .vertices
            .iter()
            .map(|v| {
                let z = v[2];
                [
                    camera.fx * v[0] / z + camera.cx,
                    camera.fy * v[1] / z + camera.cy,
                    z,
                ]
            })
            .collect();
        for f in &mesh.faces {
            let [a, b, c] = f.map(|i| proj[i as usize]);
            if a[2] <= NEAR || b[2] <= NEAR || c[2] <= NEAR {
                continue;
            }
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if area.abs() < 1e-12 {
                continue;
            }
            let u0 = a[0].min(b[0]).min(c[0]).ceil().max(0.0);
            let u1 = a[0].max(b[0]).max(c[0]).floor().min((w - 1) as f64);
            let v0 = a[1].min(b[1]).min(c[1]).ceil().max(0.0);
            let v1 = a[1].max(b[1]).max(c[1]).floor().min((h - 1) as f64);
            if u0 > u1 || v0 > v1 {
                continue;
            }
            let inv = 1.0 / area;
            let (ia, ib, ic) = (1.0 / a[2], 1.0 / b[2], 1.0 / c[2]);
            for row in v0 as usize..=v1 as usize {
                let y = row as f64;
                for col in u0 as usize..=u1 as usize {
                    let x = col as f64;
                    let wa = ((b[0] - x) * (c[1] - y) - (b[1] - y) * (c[0] - x)) * inv;
                    let wb = ((c[0] - x) * (a[1] - y) - (c[1] - y) * (a[0] - x)) * inv;
                    let wc = 1.0 - wa - wb;
                    if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                        continue;
                    }
                    let z = (1.0 / (wa * ia + wb * ib + wc * ic)) as f32;
                    let d = &mut depth[row * w + col];
                    if *d == 0.0 || z < *d {
                        *d = z;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Renders the depth image of template `index` (H×W metres of `config.camera()`).
pub fn render_template(
    model: &BodyModel,
    config: &TemplateConfig,
    index: usize,
) -> Result<Vec<f32>> {
    ensure(index < NUM_TEMPLATES, "index", || {
        format!("must be < {NUM_TEMPLATES}, got {index}")
    })?;
    let cam = config.camera()?;
    let pose = template_pose(index, config.distance);
    let mut depth = vec![0.0f32; cam.width * cam.height];
    match config.renderer {
        TemplateRenderer::Superquadric => {
            let meshes = model.superquadric_meshes(&pose, &config.mesh)?;
            rasterize_meshes_into(&meshes, &cam, &mut depth)?;
        }
        TemplateRenderer::Ellipsoid => {
            let mut labels = vec![0i16; depth.len()];
            model.render_depth_into(&pose, &cam, &mut depth, &mut labels)?;
        }
    }
    Ok(depth)
}

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

fn metric_size(context: &SurfaceContext, centroid: &Vector3<f64>, camera: &Camera) -> f64 {
    context.scale * centroid.z / (camera.fx * camera.fy).sqrt()
}

/// Settings of [`TemplateDatabase::match_depth`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchConfig {
    /// Candidates returned.
    pub top_k: usize,
    /// Templates kept by the pruning stage for the exact assignment.
    pub shortlist: usize,
    /// Query samples used as representatives in the pruning stage.
    pub representatives: usize,
    /// Weight of the normalised-position distance in a pair's cost.
    pub location_weight: f64,
    /// Cost of leaving a sample unmatched.
    pub dummy_cost: f64,
    /// Re-rank the exact stage's best this-many templates (0 or 1 = off; at most the
    /// short list counts) by how well each, placed at the observed body, explains the
    /// depth in 3-D: the fit's data and free-space terms at the placed pose (see
    /// [`TemplateDatabase::match_depth`]). Off by default: it costs about 0.22 ms per
    /// candidate and improves the placed pose, not the fit that follows
    /// (docs/templates.md).
    pub rerank: usize,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            top_k: 5,
            shortlist: 16,
            representatives: 8,
            location_weight: 0.1,
            dummy_cost: 0.15,
            rerank: 0,
        }
    }
}

impl MatchConfig {
    pub fn validate(&self) -> Result<()> {
        ensure((1..=NUM_TEMPLATES).contains(&self.top_k), "top_k", || {
            format!("must be in 1..={NUM_TEMPLATES}, got {}", self.top_k)
        })?;
        // Before the short list, which the Python layer grows to `rerank`.
        ensure(self.rerank <= NUM_TEMPLATES, "rerank", || {
            format!("must be in 0..={NUM_TEMPLATES}, got {}", self.rerank)
        })?;
        ensure(
            (1..=NUM_TEMPLATES).contains(&self.shortlist),
            "shortlist",
            || format!("must be in 1..={NUM_TEMPLATES}, got {}", self.shortlist),
        )?;
        ensure(self.representatives >= 1, "representatives", || {
            "must be >= 1".to_string()
        })?;
        ensure(
            self.location_weight.is_finite() && self.location_weight >= 0.0,
            "location_weight",
            || format!("must be finite and >= 0, got {}", self.location_weight),
        )?;
        crate::error::ensure_positive(self.dummy_cost, "dummy_cost")
    }
}

/// A template matched to a depth image.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Template index (see [`template_code`]).
    pub index: usize,
    pub view: usize,
    /// Initial pose: the template placed at the observed body.
    pub pose: Pose,
    /// Joints of `pose` (camera frame).
    pub joints: [[f64; 3]; NUM_JOINTS],
    /// Mean cost per sample of the exact assignment.
    pub cost: f64,
    /// Pruning-stage score.
    pub prune_cost: f64,
    /// Observed body size over the template body size (≈ subject height / model height).
    pub scale: f64,
}

/// The result of a match: candidates best first, plus the full pruning ranking.
#[derive(Debug, Clone, PartialEq)]
pub struct MatchResult {
    pub candidates: Vec<Candidate>,
    /// Templates in the short list, best pruning score first.
    pub shortlist: Vec<usize>,
}

/// The template database.
#[derive(Debug, Clone, PartialEq)]
pub struct TemplateDatabase {
    pub model: BodyModel,
    pub config: TemplateConfig,
    pub templates: Vec<Template>,
    /// The pruning stage's lower bounds, derived from `templates` when the database is
    /// made.
    prune: PruneIndex,
}

/// The re-ranking ([`MatchConfig::rerank`]) scores every this-many-th observed point
/// (in pixel order): 2,000 of a typical 8,000-point body.
const RERANK_POINT_STEP: usize = 4;

/// The points the re-ranking scores: every [`RERANK_POINT_STEP`]-th point of the body
/// the descriptors saw.
fn rerank_points(sil: &Silhouette) -> Vec<[f32; 3]> {
    sil.cloud
        .points
        .iter()
        .step_by(RERANK_POINT_STEP)
        .copied()
        .collect()
}

/// Principal directions kept for the pruning stage's lower bound.
const PRUNE_DIRECTIONS: usize = 32;
/// Every this-many-th template sample goes into the principal-direction estimate.
const PRUNE_SAMPLE_STEP: usize = 32;

/// Lower bounds on descriptor distances for the pruning stage.
///
/// An orthonormal basis P of the templates' leading principal descriptor directions,
/// and every template sample t described by its coordinates P·t plus the length of its
/// remainder ‖t − PᵀP·t‖. By Pythagoras and the reverse triangle inequality,
/// ‖q − t‖² ≥ ‖P·q − P·t‖² + (‖rem q‖ − ‖rem t‖)², which is the squared distance of
/// the two descriptions: a sample whose bound already exceeds the best cost so far
/// cannot improve it and is skipped without reading its full descriptor. 32 of the 180
/// directions hold about 92 % of the templates' descriptor variance.
#[derive(Debug, Clone, PartialEq, Default)]
struct PruneIndex {
    /// Directions × descriptor values, row-major; rows orthonormal.
    basis: Vec<f64>,
    /// Values per descriptor.
    dim: usize,
    directions: usize,
    /// Values per description: the directions' coordinates, then the remainder's length.
    components: usize,
    /// Per template: its samples' projections, component-major (components × samples,
    /// each component's row padded with zeros to [`prune_stride`] samples) so that one
    /// query's bounds against all samples vectorise.
    projected: Vec<Vec<f32>>,
}

impl PruneIndex {
    fn new(templates: &[Template]) -> Self {
        let Some(dim) = templates.first().map(|t| t.context.dim) else {
            return PruneIndex::default();
        };
        let directions = PRUNE_DIRECTIONS.min(dim);
        let components = directions + 1;
        // Covariance of a deterministic subset of the samples.
        let rows: Vec<&[f32]> = templates
            .iter()
            .flat_map(|t| (0..t.context.len()).map(move |j| t.context.descriptor(j)))
            .step_by(PRUNE_SAMPLE_STEP)
            .collect();
        let m = rows.len();
        let mut mean = vec![0.0f64; dim];
        for r in &rows {
            for (a, &v) in mean.iter_mut().zip(r.iter()) {
                *a += v as f64;
            }
        }
        mean.iter_mut().for_each(|a| *a /= m.max(1) as f64);
        // Lower triangle of the scatter matrix. (A matrix product over a centred copy
        // was no faster here, and left matching ~8 ms slower per frame afterwards in
        // the same process, for reasons not pinned down; see docs/templates.md.)
        let mut scatter = vec![0.0f64; dim * dim];
        let mut c = vec![0.0f64; dim];
        for r in &rows {
            for (ci, (&v, &a)) in c.iter_mut().zip(r.iter().zip(&mean)) {
                *ci = v as f64 - a;
            }
            for a in 0..dim {
                let ca = c[a];
                for (sab, &cb) in scatter[a * dim..a * dim + a + 1].iter_mut().zip(&c) {
                    *sab += ca * cb;
                }
            }
        }
        let cov = nalgebra::DMatrix::from_fn(dim, dim, |a, b| {
            scatter[a.max(b) * dim + a.min(b)] / m.max(1) as f64
        });
        let eigen = nalgebra::SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..dim).collect();
        order.sort_by(|&a, &b| {
            eigen.eigenvalues[b]
                .total_cmp(&eigen.eigenvalues[a])
                .then(a.cmp(&b))
        });
        let mut basis = Vec::with_capacity(directions * dim);
        for &k in &order[..directions] {
            basis.extend(eigen.eigenvectors.column(k).iter());
        }
        let mut index = PruneIndex {
            basis,
            dim,
            directions,
            components,
            projected: Vec::new(),
        };
        index.projected = templates
            .par_iter()
            .map(|t| {
                let (n, stride) = (t.context.len(), prune_stride(t.context.len()));
                let mut one = vec![0.0f32; components];
                let mut p = vec![0.0f32; stride * components];
                for j in 0..n {
                    index.project(t.context.descriptor(j), &mut one);
                    for (c, &v) in one.iter().enumerate() {
                        p[c * stride + j] = v;
                    }
                }
                p
            })
            .collect();
        index
    }

    /// Writes the description of one descriptor into `out` (`components` values): its
    /// coordinates along the directions, then the length of the rest of it.
    fn project(&self, descriptor: &[f32], out: &mut [f32]) {
        // Independent partial sums (a single running f64 sum would stay sequential).
        fn dot(a: &[f64], b: &[f32]) -> f64 {
            let mut acc = [0.0f64; 8];
            let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
            let tail: f64 = ca
                .remainder()
                .iter()
                .zip(cb.remainder())
                .map(|(&x, &y)| x * y as f64)
                .sum();
            for (x, y) in ca.zip(cb) {
                for k in 0..8 {
                    acc[k] += x[k] * y[k] as f64;
                }
            }
            acc.iter().sum::<f64>() + tail
        }
        let mut kept = 0.0f64;
        for (o, row) in out.iter_mut().zip(self.basis.chunks_exact(self.dim)) {
            let c = dot(row, descriptor);
            kept += c * c;
            *o = c as f32;
        }
        let all: f64 = descriptor.iter().map(|&d| d as f64 * d as f64).sum();
        out[self.directions] = (all - kept).max(0.0).sqrt() as f32;
    }
}

/// Row length of a template's stored projections: its sample count rounded up to a
/// multiple of 8, so that the bounds' vectorised loop has no scalar leftover.
fn prune_stride(samples: usize) -> usize {
    samples.next_multiple_of(8)
}

/// FNV-1a over the 64-bit words that identify a database.
fn fnv1a(words: impl IntoIterator<Item = u64>) -> u64 {
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

    /// Matches the (masked) body of a depth image against every template: pruning, the
    /// exact assignment on the short list, each candidate placed at the observed body,
    /// and with [`MatchConfig::rerank`] the best few re-ordered by their placed fit
    /// energy (which sees depth the normals-only descriptor cannot: an arm held toward
    /// the camera against one hanging in front of the body).
    pub fn match_depth(
        &self,
        depth: &DepthView,
        camera: &Camera,
        mask: Option<&[bool]>,
        config: &MatchConfig,
    ) -> Result<MatchResult> {
        config.validate()?;
        let d = &self.config.descriptor;
        let sil = Silhouette::from_depth(depth, camera, mask, d.normal_radius)?;
        let query = sil.surface_context(d)?;
        let rerank = config.rerank.min(config.shortlist);
        let wide = MatchConfig {
            top_k: config.top_k.max(rerank),
            ..*config
        };
        let mut result = self.match_context(&query, &wide)?;
        let size = metric_size(&query, &sil.centroid, camera);
        for c in result.candidates.iter_mut() {
            self.place(c, &sil, size);
        }
        if rerank > 1 {
            let points = rerank_points(&sil);
            let n = result.candidates.len().min(rerank);
            let energies: Vec<f64> = result.candidates[..n]
                .iter()
                .map(|c| self.placed_energy(&points, depth.data, camera, &c.pose))
                .collect();
            let mut order: Vec<usize> = (0..n).collect();
            order.sort_by(|&a, &b| energies[a].total_cmp(&energies[b]).then(a.cmp(&b)));
            let reordered: Vec<Candidate> = order
                .iter()
                .map(|&k| result.candidates[k].clone())
                .collect();
            result.candidates.splice(..n, reordered);
        }
        result.candidates.truncate(config.top_k);
        Ok(result)
    }

    /// Ranks the templates for a query's descriptors (candidate poses stay the
    /// templates' own; [`Self::match_depth`] places them).
    pub fn match_context(
        &self,
        query: &SurfaceContext,
        config: &MatchConfig,
    ) -> Result<MatchResult> {
        config.validate()?;
        ensure(!self.templates.is_empty(), "templates", || {
            "the database is empty".to_string()
        })?;
        ensure(query.dim == self.templates[0].context.dim, "query", || {
            format!(
                "descriptors have {} values, the templates {}",
                query.dim, self.templates[0].context.dim
            )
        })?;
        let reps = Representatives::new(&self.prune, query, config.representatives);
        let lw = config.location_weight as f32;
        // Early give-up, exact: a template's sum over the representatives only grows
        // (every pair cost is ≥ 0, and adding a non-negative f32 never lowers a sum), so
        // once its partial sum exceeds the sum of the `keep`-th best template finished
        // so far, `keep` templates score strictly lower and it cannot make the short
        // list. Most templates are far worse than the short list and stop after a few
        // representatives. The finished sums' `keep` smallest live in a shared heap; the
        // current limit is read lock-free (f32 bits of non-negative sums order as u32).
        let keep = config.shortlist.min(self.templates.len());
        let best_sums = std::sync::Mutex::new(std::collections::BinaryHeap::<u32>::new());
        let limit = std::sync::atomic::AtomicU32::new(f32::INFINITY.to_bits());
        let finished = |sum: f32| {
            let bits = sum.to_bits();
            let mut heap = best_sums.lock().unwrap_or_else(|e| e.into_inner());
            if heap.len() < keep {
                heap.push(bits);
            } else if heap.peek().is_some_and(|&top| bits < top) {
                heap.pop();
                heap.push(bits);
            }
            if heap.len() == keep {
                if let Some(&top) = heap.peek() {
                    limit.fetch_min(top, std::sync::atomic::Ordering::Relaxed);
                }
            }
        };
        let n_reps = reps.samples.len() as f32;
        let mut scores: Vec<(f64, usize)> = self
            .templates
            .par_iter()
            .zip(&self.prune.projected)
            .enumerate()
            .map_init(Vec::new, |scratch, (t, (tpl, projected))| {
                let give_up = f32::from_bits(limit.load(std::sync::atomic::Ordering::Relaxed));
                let sum = prune_sum(query, &reps, &tpl.context, projected, lw, give_up, scratch)?;
                finished(sum);
                Some(((sum / n_reps) as f64, t))
            })
            .flatten()
            .collect();
        scores.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let shortlist: Vec<usize> = scores[..config.shortlist.min(scores.len())]
            .iter()
            .map(|s| s.1)
            .collect();
        let prune_of: std::collections::HashMap<usize, f64> =
            scores.iter().map(|&(s, t)| (t, s)).collect();
        let columns = QueryColumns::new(query);
        let mut exact: Vec<(f64, usize)> = shortlist
            .par_iter()
            .map_init(
                || (AssignmentWorkspace::default(), Vec::new(), Vec::new()),
                |(ws, cost, assign), &t| {
                    let c = matching_cost_with(
                        query,
                        &columns,
                        &self.templates[t].context,
                        config.location_weight,
                        config.dummy_cost,
                        ws,
                        cost,
                        assign,
                    );
                    (c, t)
                },
            )
            .collect();
        exact.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let candidates = exact
            .iter()
            .take(config.top_k)
            .map(|&(cost, t)| {
                let tpl = &self.templates[t];
                Candidate {
                    index: t,
                    view: tpl.view,
                    pose: tpl.pose,
                    joints: tpl.joints,
                    cost,
                    prune_cost: prune_of[&t],
                    scale: 1.0,
                }
            })
            .collect();
        Ok(MatchResult {
            candidates,
            shortlist,
        })
    }

    /// How well `pose` explains the observed `points` (a sub-sample of the body's) and
    /// the free space of `depth`: the data terms of the fit's energy (default
    /// [`crate::fit::em::EmConfig`], outlier distance at its starting value) with every
    /// point at its cheapest label, pairwise terms left out, per point.
    fn placed_energy(
        &self,
        points: &[[f32; 3]],
        depth: &[f32],
        camera: &Camera,
        pose: &Pose,
    ) -> f64 {
        use crate::fit::em::{unary_costs, EmConfig, NUM_LABELS};
        use crate::fit::free_space::FreeSpaceTerm;
        let cfg = EmConfig::default();
        let mut unary = vec![0.0; points.len() * NUM_LABELS];
        unary_costs(
            &self.model,
            points,
            pose,
            &cfg,
            cfg.outlier_distance_start,
            &mut unary,
        );
        let data: f64 = unary
            .chunks_exact(NUM_LABELS)
            .map(|row| row.iter().copied().fold(f64::INFINITY, f64::min))
            .sum();
        // The free-space samples weigh against the full point set: its weight shrinks
        // with the points kept (1 / step), as a strided fit's does (1 / stride²).
        let weight_scale = 1.0 / RERANK_POINT_STEP as f64;
        let free_space = FreeSpaceTerm::new(
            &self.model,
            depth,
            camera,
            cfg.free_space_cost(weight_scale),
        );
        (data + free_space.cost(pose)) / points.len().max(1) as f64
    }

    /// Moves a candidate's template onto the observed body: the template's visible
    /// centroid goes to the observed one, its view relative to the line of sight is
    /// kept, and the hip sits at the template's centroid → hip offset (which carries
    /// the body's half thickness behind the visible surface) scaled by the size ratio.
    fn place(&self, c: &mut Candidate, sil: &Silhouette, size: f64) {
        let tpl = &self.templates[c.index];
        let ct = Vector3::from(tpl.centroid);
        let align_t = crate::descriptor::line_of_sight_alignment(&ct.normalize());
        // Template camera → query camera rotation.
        let m: Rotation3<f64> = sil.alignment.inverse() * align_t;
        let scale = size / tpl.size;
        let hip = Vector3::new(
            tpl.pose[param::ROOT_T],
            tpl.pose[param::ROOT_T + 1],
            tpl.pose[param::ROOT_T + 2],
        );
        let t = sil.centroid + m * (hip - ct) * scale;
        let r = m * crate::body::root_rotation(&tpl.pose);
        let mut pose = tpl.pose;
        pose[param::ROOT_T..param::ROOT_T + 3].copy_from_slice(t.as_slice());
        pose[param::ROOT_R..param::ROOT_R + 3].copy_from_slice(r.scaled_axis().as_slice());
        c.pose = pose;
        c.joints = self.model.joints(&pose).map(|j| [j.x, j.y, j.z]);
        c.scale = scale;
    }
}

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

/// `count` query samples spread over the body: farthest-point order from the sample
/// nearest the centroid.
fn representatives(query: &SurfaceContext, count: usize) -> Vec<usize> {
    let n = query.len();
    let count = count.min(n);
    let d2 = |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let first = (0..n)
        .min_by(|&a, &b| {
            d2(query.positions[a], [0.0; 2]).total_cmp(&d2(query.positions[b], [0.0; 2]))
        })
        .unwrap_or(0);
    let mut chosen = vec![first];
    let mut nearest: Vec<f32> = (0..n)
        .map(|i| d2(query.positions[i], query.positions[first]))
        .collect();
    while chosen.len() < count {
        let next = (0..n)
            .max_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(b.cmp(&a)))
            .unwrap_or(0);
        chosen.push(next);
        let pn = query.positions[next];
        for (d, p) in nearest.iter_mut().zip(&query.positions) {
            *d = d.min(d2(*p, pn));
        }
    }
    chosen
}

/// Cost of pairing query sample i with template sample j.
#[inline]
fn pair_cost(q: &SurfaceContext, i: usize, t: &SurfaceContext, j: usize, lw: f32) -> f32 {
    let (a, b) = (q.positions[i], t.positions[j]);
    crate::descriptor::descriptor_distance(q.descriptor(i), t.descriptor(j))
        + lw * planar_distance(a, b)
}

/// Distance of two normalised sample positions (a plain square root: vectorises,
/// unlike `hypot`, and the positions are of order 1, far from overflow).
#[inline]
fn planar_distance(a: [f32; 2], b: [f32; 2]) -> f32 {
    ((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1])).sqrt()
}

/// The query samples the pruning stage scores with, and their projections onto the
/// [`PruneIndex`] basis (samples × components).
struct Representatives {
    samples: Vec<usize>,
    projected: Vec<f32>,
    components: usize,
}

impl Representatives {
    /// `count` samples of `query` spread over the body ([`representatives`]), projected
    /// onto `index`'s basis.
    fn new(index: &PruneIndex, query: &SurfaceContext, count: usize) -> Self {
        let samples = representatives(query, count);
        let k = index.components;
        let mut projected = vec![0.0f32; samples.len() * k];
        for (&i, out) in samples.iter().zip(projected.chunks_exact_mut(k.max(1))) {
            index.project(query.descriptor(i), out);
        }
        Representatives {
            samples,
            projected,
            components: k,
        }
    }
}

avx2_dispatch! {
    /// Pruning score × the number of representatives: the sum over representatives of
    /// the cost of their nearest template sample, or `None` as soon as the partial sum
    /// exceeds `give_up` (representatives in order; the sum only grows).
    ///
    /// Exact, but pruned. Per representative, vectorised passes over all template samples
    /// give each pair a lower bound of its cost: the position term plus the bound of the
    /// descriptor distance from the short descriptions ([`PruneIndex`]). Four pairs of
    /// low bound (the least among them) are costed in full first, then only the pairs
    /// whose bounds are below the best cost so far, four at a time: on the default
    /// database about 4 template samples in 100 have a bound below the best (about 7 in
    /// 100 with 24 directions in index order, 85 in 100 by the position term alone).
    /// `t_projected` is the template's component-major description; `scratch` is reused
    /// storage.
    fn prune_sum(
        q: &SurfaceContext,
        reps: &Representatives,
        t: &SurfaceContext,
        t_projected: &[f32],
        lw: f32,
        give_up: f32,
        scratch: &mut Vec<f32>,
    ) -> Option<f32> {
        let (k, n, stride) = (reps.components, t.len(), prune_stride(t.len()));
        scratch.clear();
        scratch.resize(stride + n, 0.0);
        let (lower, location) = scratch.split_at_mut(stride);
        let mut total = 0.0;
        for (r, &i) in reps.samples.iter().enumerate() {
            let pi = q.positions[i];
            for (l, pj) in location.iter_mut().zip(&t.positions) {
                *l = (pi[0] - pj[0]) * (pi[0] - pj[0]) + (pi[1] - pj[1]) * (pi[1] - pj[1]);
            }
            // lw·√(squared distance): the same arithmetic as `pair_cost`.
            location.iter_mut().for_each(|l| *l = lw * l.sqrt());
            squared_projection_distances(&reps.projected[r * k..(r + 1) * k], t_projected, lower);
            // Lower bounds of the pair costs. They come from rounded descriptions: the
            // margin lies well above that rounding, so no bound exceeds its pair's cost.
            for (lo, &l) in lower.iter_mut().zip(location.iter()) {
                *lo = l + ((*lo - PRUNE_BOUND_SLACK).max(0.0) / PRUNE_BOUND_MARGIN).sqrt();
            }
            lower[n..].fill(f32::INFINITY);
            // Four pairs of low bound first (the least of all among them; usually the
            // best pair too), then every other pair whose bound is below the best cost
            // so far (any other costs at least its bound, so cannot improve it).
            // Distances four at a time: four cost little more than one, and computing
            // a few pairs the scan would have skipped does not change the least cost.
            let qd = q.descriptor(i);
            let cost4 = |js: [usize; 4]| {
                let d2 = crate::descriptor::squared_distances_x4(qd, js.map(|j| t.descriptor(j)));
                (0..4)
                    .map(|k| d2[k].sqrt() + location[js[k]])
                    .fold(f32::INFINITY, f32::min)
            };
            let firsts = four_low(lower);
            let lower = &mut lower[..n];
            let mut best = cost4(firsts);
            for &j in &firsts {
                lower[j] = f32::INFINITY;
            }
            let (mut batch, mut pending) = ([0usize; 4], 0);
            for (j, &b) in lower.iter().enumerate() {
                if b < best {
                    batch[pending] = j;
                    pending += 1;
                    if pending == 4 {
                        best = best.min(cost4(batch));
                        pending = 0;
                    }
                }
            }
            if pending > 0 {
                // Pad the last batch with repeats of its last pair.
                let last = batch[pending - 1];
                batch[pending..].fill(last);
                best = best.min(cost4(batch));
            }
            total += best;
            if total > give_up {
                return None;
            }
        }
        Some(total)
    }
}

/// `out[j]` = Σ_c (query[c] − projected[c·n + j])² over the components c of one
/// representative's description against every template sample's (component-major
/// `projected` with rows of n = `out.len()` values, a multiple of 8), summed in
/// component order.
///
/// 32 samples at a time (8 at the end) with the components inside, so the sums stay
/// in registers (a pass per component would read and write all n sums each time), as
/// four independent chains of adds. Inlined into `prune_sum`'s AVX2 build.
#[inline(always)]
fn squared_projection_distances(query: &[f32], projected: &[f32], out: &mut [f32]) {
    #[inline(always)]
    fn block<const B: usize>(query: &[f32], projected: &[f32], n: usize, j0: usize) -> [f32; B] {
        let mut acc = [0.0f32; B];
        for (c, &qc) in query.iter().enumerate() {
            let row = &projected[c * n + j0..c * n + j0 + B];
            for (a, &v) in acc.iter_mut().zip(row) {
                *a += (qc - v) * (qc - v);
            }
        }
        acc
    }
    let n = out.len();
    debug_assert_eq!(n % 8, 0);
    let mut j0 = 0;
    while j0 + 32 <= n {
        out[j0..j0 + 32].copy_from_slice(&block::<32>(query, projected, n, j0));
        j0 += 32;
    }
    while j0 + 8 <= n {
        out[j0..j0 + 8].copy_from_slice(&block::<8>(query, projected, n, j0));
        j0 += 8;
    }
}

/// Indices of four low values of `values` (length a multiple of 8, not empty): the
/// least of each of the 8 interleaved lanes (j mod 8) is found in one vectorised
/// pass, and the four least of those are returned. The least value overall is among
/// them.
#[inline(always)]
fn four_low(values: &[f32]) -> [usize; 4] {
    let mut least = [f32::INFINITY; 8];
    let mut at = [0u32; 8];
    for (c, chunk) in values.chunks_exact(8).enumerate() {
        for l in 0..8 {
            let better = chunk[l] < least[l];
            least[l] = if better { chunk[l] } else { least[l] };
            at[l] = if better { (c * 8 + l) as u32 } else { at[l] };
        }
    }
    let mut lanes: [usize; 8] = std::array::from_fn(|l| l);
    lanes.sort_by(|&a, &b| least[a].total_cmp(&least[b]).then(a.cmp(&b)));
    std::array::from_fn(|k| at[lanes[k]] as usize)
}

/// Relative and absolute margins on the pruning stage's squared bounds (see
/// [`prune_sum`]), far above the rounding of the descriptions and sums (~1e-6
/// relative) and far below the squared costs that matter (~1e-3).
const PRUNE_BOUND_MARGIN: f32 = 1.001;
const PRUNE_BOUND_SLACK: f32 = 1e-8;

/// A query's descriptors and positions laid out for the exact stage's cost matrices:
/// value `d` of sample `i` at `d · stride + i`, positions as two rows, every row
/// zero-padded to `stride` (the sample count rounded up to 32), so that a vector
/// holds one value of 8 (AVX2) or 16 (AVX-512) consecutive samples. Made once per
/// query.
pub struct QueryColumns {
    values: Vec<f32>,
    x: Vec<f32>,
    y: Vec<f32>,
    stride: usize,
}

impl QueryColumns {
    pub fn new(q: &SurfaceContext) -> Self {
        let (n, dim) = (q.len(), q.dim);
        // A multiple of 32: the AVX-512 kernel reads two 16-lane vectors per block.
        let stride = n.next_multiple_of(32);
        let mut values = vec![0.0f32; dim * stride];
        for i in 0..n {
            for (d, &v) in q.descriptor(i).iter().enumerate() {
                values[d * stride + i] = v;
            }
        }
        let mut x = vec![0.0f32; stride];
        let mut y = vec![0.0f32; stride];
        for (i, p) in q.positions.iter().enumerate() {
            (x[i], y[i]) = (p[0], p[1]);
        }
        QueryColumns {
            values,
            x,
            y,
            stride,
        }
    }
}

/// The `pair_cost` of every template sample (rows) with every query sample (columns),
/// row-major into `cost` (m × n: the assignment is the same problem transposed).
///
/// With AVX2 and FMA (detected at run time): a vector holds 8 query samples
/// ([`QueryColumns`]), so the squared differences accumulate along the descriptor
/// with no sums across lanes, and 4 template samples × 16 query samples give 8
/// independent chains of fused multiply-adds. The values differ from `pair_cost`
/// only by rounding (the order of the sum and the fused multiply-add; tested to
/// 1e-5 relative).
fn cost_matrix(
    q: &SurfaceContext,
    columns: &QueryColumns,
    t: &SurfaceContext,
    lw: f32,
    cost: &mut Vec<f64>,
) {
    let (n, m) = (q.len(), t.len());
    cost.clear();
    cost.resize(n * m, 0.0);
    let mut from = 0;
    #[cfg(target_arch = "x86_64")]
    if q.dim == t.dim {
        if crate::cpu::avx512() {
            // SAFETY: the CPU supports AVX-512F (checked by `avx512`).
            from = unsafe { cost_rows_avx512(columns, t, lw, n, cost) };
        } else if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            from = unsafe { cost_rows_fma(columns, t, lw, n, cost) };
        }
    }
    let _ = columns; // read by the x86_64 kernel only
    for j in from..m {
        for i in 0..n {
            cost[j * n + i] = pair_cost(q, i, t, j, lw) as f64;
        }
    }
}

/// Writes a cost-rows kernel for one vector width: 4 template samples × 2 vectors of
/// query samples give 8 independent FMA chains along the descriptor. Every lane sums in
/// the same order with the same fused operations whatever the width, so the kernels
/// agree bit for bit (tested). Returns the number of rows written, a multiple of 4 (the
/// rest are left to the caller).
macro_rules! cost_rows_kernel {
    (
        $(#[$doc:meta])*
        $name:ident, $feature:literal, $lanes:literal,
        zero: $zero:ident, set1: $set1:ident, load: $load:ident, store: $store:ident,
        sub: $sub:ident, add: $add:ident, mul: $mul:ident, fmadd: $fmadd:ident,
        sqrt: $sqrt:ident
    ) => {
        $(#[$doc])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        unsafe fn $name(
            columns: &QueryColumns,
            t: &SurfaceContext,
            lw: f32,
            n: usize,
            cost: &mut [f64],
        ) -> usize {
            use std::arch::x86_64::*;
            const LANES: usize = $lanes;
            let (stride, dim) = (columns.stride, t.dim);
            assert!(
                columns.values.len() >= dim * stride
                    && stride >= n
                    && stride.is_multiple_of(2 * LANES)
                    && columns.x.len() >= stride
                    && columns.y.len() >= stride
                    && cost.len() >= n * t.len()
            );
            let quads = t.len() / 4 * 4;
            let lwv = $set1(lw);
            let mut out = [0.0f32; LANES];
            for j0 in (0..quads).step_by(4) {
                let b: [&[f32]; 4] = std::array::from_fn(|k| t.descriptor(j0 + k));
                for i0 in (0..n).step_by(2 * LANES) {
                    let mut acc = [[$zero(); 2]; 4];
                    for d in 0..dim {
                        // SAFETY: d·stride + i0 + 2·LANES <= dim·stride (i0 < n <=
                        // stride, stride a multiple of 2·LANES), asserted above.
                        let col = columns.values.as_ptr().add(d * stride + i0);
                        let q = [$load(col), $load(col.add(LANES))];
                        for (acc, b) in acc.iter_mut().zip(&b) {
                            let bd = $set1(*b.get_unchecked(d));
                            for (a, &q) in acc.iter_mut().zip(&q) {
                                let e = $sub(q, bd);
                                *a = $fmadd(e, e, *a);
                            }
                        }
                    }
                    for (k, acc) in acc.iter().enumerate() {
                        let j = j0 + k;
                        let (tx, ty) = ($set1(t.positions[j][0]), $set1(t.positions[j][1]));
                        for (h, &a) in acc.iter().enumerate() {
                            let i = i0 + LANES * h;
                            if i >= n {
                                break;
                            }
                            // SAFETY: i + LANES <= stride <= the lengths of x and y.
                            let dx = $sub($load(columns.x.as_ptr().add(i)), tx);
                            let dy = $sub($load(columns.y.as_ptr().add(i)), ty);
                            let loc = $sqrt($add($mul(dx, dx), $mul(dy, dy)));
                            let c = $add($sqrt(a), $mul(lwv, loc));
                            $store(out.as_mut_ptr(), c);
                            let row = &mut cost[j * n + i..j * n + n.min(i + LANES)];
                            for (o, &v) in row.iter_mut().zip(&out) {
                                *o = v as f64;
                            }
                        }
                    }
                }
            }
            quads
        }
    };
}

cost_rows_kernel!(
    /// The rows of [`cost_matrix`] for the template samples in groups of 4, with AVX2
    /// and FMA (8 query samples per vector).
    cost_rows_fma, "avx2,fma", 8,
    zero: _mm256_setzero_ps, set1: _mm256_set1_ps, load: _mm256_loadu_ps,
    store: _mm256_storeu_ps, sub: _mm256_sub_ps, add: _mm256_add_ps,
    mul: _mm256_mul_ps, fmadd: _mm256_fmadd_ps, sqrt: _mm256_sqrt_ps
);

cost_rows_kernel!(
    /// [`cost_rows_fma`] with AVX-512: 16 query samples per vector.
    cost_rows_avx512, "avx512f", 16,
    zero: _mm512_setzero_ps, set1: _mm512_set1_ps, load: _mm512_loadu_ps,
    store: _mm512_storeu_ps, sub: _mm512_sub_ps, add: _mm512_add_ps,
    mul: _mm512_mul_ps, fmadd: _mm512_fmadd_ps, sqrt: _mm512_sqrt_ps
);

/// Mean cost per sample of the best one-to-one assignment with outliers.
pub fn matching_cost(
    q: &SurfaceContext,
    t: &SurfaceContext,
    location_weight: f64,
    dummy_cost: f64,
    ws: &mut AssignmentWorkspace,
    cost: &mut Vec<f64>,
    assign: &mut Vec<Option<usize>>,
) -> f64 {
    let columns = QueryColumns::new(q);
    matching_cost_with(
        q,
        &columns,
        t,
        location_weight,
        dummy_cost,
        ws,
        cost,
        assign,
    )
}

/// [`matching_cost`] with the query's [`QueryColumns`] made already.
#[allow(clippy::too_many_arguments)]
fn matching_cost_with(
    q: &SurfaceContext,
    columns: &QueryColumns,
    t: &SurfaceContext,
    location_weight: f64,
    dummy_cost: f64,
    ws: &mut AssignmentWorkspace,
    cost: &mut Vec<f64>,
    assign: &mut Vec<Option<usize>>,
) -> f64 {
    let (n, m) = (q.len(), t.len());
    cost_matrix(q, columns, t, location_weight as f32, cost);
    // Template samples as rows: the optimal total is the same either way round.
    let total = assignment_with_outliers(cost, m, n, dummy_cost, ws, assign)
        .expect("cost matrix sized and finite by construction");
    total / n.max(m) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_cover_all_templates_once() {
        let mut seen = std::collections::HashSet::new();
        for i in 0..NUM_TEMPLATES {
            let (c, v) = template_code(i);
            assert!(c.iter().all(|&x| x < LIMB_POSES) && v < NUM_VIEWS);
            assert!(seen.insert((c, v)));
        }
        assert_eq!(NUM_TEMPLATES, 768);
    }

    #[test]
    fn views_turn_the_named_side_to_the_camera() {
        let model = BodyModel::default();
        let j = |i: usize| model.joints(&template_pose(i, 3.0));
        let (rs, ls) = (2, 3); // RShoulder, LShoulder
        let front = j(0);
        assert!((front[rs].z - front[ls].z).abs() < 1e-9 && front[rs].x < front[ls].x);
        let left = j(256);
        assert!(left[ls].z < left[rs].z - 0.2);
        let right = j(512);
        assert!(right[rs].z < right[ls].z - 0.2);
        // Right arm raised sideways: the right hand at shoulder height, far to the side.
        let raised = j(64);
        assert!((raised[6].y - raised[rs].y).abs() < 0.1 && raised[6].x < raised[rs].x - 0.4);
        // Right knee raised: knee well in front of (closer than) the hip.
        let knee = j(3 * 4);
        assert!(knee[11].z < knee[9].z - 0.3);
    }

    #[test]
    fn rasterizer_matches_the_ray_cast_ellipsoids() {
        // The ellipsoid super-quadric (d = 2, s = 0) mesh rasterised vs the analytic
        // ray cast of the same ellipsoid.
        let cam = Camera::new(150.0, 150.0, 31.5, 31.5, 64, 64).unwrap();
        let shape = crate::body::superquadric::SuperquadricShape {
            taper: 0.0,
            exponent: 2.0,
        };
        let cfg = MeshConfig {
            rings: 60,
            sectors: 80,
        };
        let mut mesh =
            crate::body::superquadric::superquadric_mesh(0.2, 0.15, 0.6, &shape, &cfg).unwrap();
        // Centre it at (0.05, 0, 2.5), long axis along y.
        for v in mesh.vertices.iter_mut() {
            *v = [v[0] + 0.05, v[2] - 0.3, v[1] + 2.5];
        }
        let mut raster = vec![0.0; 64 * 64];
        rasterize_meshes_into(&[mesh], &cam, &mut raster).unwrap();
        let e = crate::body::ellipsoid::PlacedEllipsoid {
            centre: Vector3::new(0.05, 0.0, 2.5),
            rotation: nalgebra::Matrix3::identity(),
            prepared: crate::body::ellipsoid::Prepared::new(&Vector3::new(0.2, 0.3, 0.15)),
        };
        let (mut exact, mut labels) = (vec![0.0; 64 * 64], vec![0i16; 64 * 64]);
        crate::render::render_ellipsoids_into(&[e], &[0], &cam, &mut exact, &mut labels).unwrap();
        let (mut both, mut differ) = (0, 0);
        for (r, x) in raster.iter().zip(&exact) {
            match (*r > 0.0, *x > 0.0) {
                (true, true) => {
                    both += 1;
                    assert!((r - x).abs() < 0.01, "{r} vs {x}");
                }
                (false, false) => {}
                _ => differ += 1,
            }
        }
        assert!(both > 300 && differ * 20 < both, "{both} {differ}");
        assert!(rasterize_meshes_into(&[], &cam, &mut [0.0; 3]).is_err());
    }

    #[test]
    fn template_retrieves_itself_and_is_placed_at_the_body() {
        let db = super::eval::database();
        assert_eq!(db.len(), NUM_TEMPLATES);
        let model = BodyModel::default();
        let cam = Camera::itop();
        for &(t, x) in &[
            (0usize, 0.3),
            (77, -0.8),
            (300, 0.6),
            (555, -0.7),
            (700, 0.5),
            (520, -0.5),
        ] {
            let mut pose = template_pose(t, 3.0);
            pose[0] = x;
            pose[1] = 0.1;
            pose[2] = 3.4;
            let (d, _) = model.render_depth(&pose, &cam);
            let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
            let r = db
                .match_depth(&view, &cam, None, &MatchConfig::default())
                .unwrap();
            assert_eq!(r.candidates.len(), 5);
            let best = &r.candidates[0];
            let joints = model.joints(&pose);
            let err: f64 = best
                .joints
                .iter()
                .zip(&joints)
                .map(|(a, b)| (Vector3::from(*a) - b).norm())
                .sum::<f64>()
                / NUM_JOINTS as f64;
            assert!(
                err < 0.1,
                "template {t}: best {} mean joint error {err}",
                best.index
            );
            assert!((best.scale - 1.0).abs() < 0.15, "{}", best.scale);
        }
    }

    #[test]
    fn arrays_round_trip_and_refuse_mismatches() {
        let db = super::eval::database();
        let a = db.to_arrays();
        let back = TemplateDatabase::from_arrays(&a, Some((&db.model, &db.config)), "f").unwrap();
        assert_eq!(&back, db);
        let mut v = a.clone();
        v.format_version += 1;
        assert!(matches!(
            TemplateDatabase::from_arrays(&v, None, "f"),
            Err(crate::Error::File { .. })
        ));
        let other = BodyModel::new(1.6).unwrap();
        assert!(matches!(
            TemplateDatabase::from_arrays(&a, Some((&other, &db.config)), "f"),
            Err(crate::Error::File { .. })
        ));
        let mut v = a.clone();
        v.descriptors.pop();
        assert!(TemplateDatabase::from_arrays(&v, None, "f").is_err());
        let mut v = a.clone();
        v.shape[0] += 0.01;
        assert!(TemplateDatabase::from_arrays(&v, None, "f").is_err());
        assert_eq!(
            config_from_vec(&config_to_vec(&db.config)).unwrap(),
            db.config
        );
    }

    /// The pruning score against brute force, for a template's own descriptors and for
    /// perturbed noisy renders (no exact twin in the database), over many templates.
    #[test]
    fn pruned_score_equals_brute_force() {
        let db = super::eval::database();
        let cam = Camera::itop();
        let mut rng = super::eval::Rng(7);
        let mut queries = vec![db.templates[123].context.clone()];
        for t in [5usize, 300, 700] {
            queries.push(super::eval::query_context(db, t, &mut rng, &cam));
        }
        for q in &queries {
            let reps = Representatives::new(&db.prune, q, 8);
            let samples = &reps.samples;
            for t in (0..db.len()).step_by(17).chain([123, 767]) {
                let tc = &db.templates[t].context;
                for lw in [0.0f32, 0.1, 1.0] {
                    let brute: f32 = samples
                        .iter()
                        .map(|&i| {
                            (0..tc.len())
                                .map(|j| pair_cost(q, i, tc, j, lw))
                                .fold(f32::INFINITY, f32::min)
                        })
                        .sum::<f32>()
                        / samples.len() as f32;
                    let projected = &db.prune.projected[t];
                    let sum =
                        prune_sum(q, &reps, tc, projected, lw, f32::INFINITY, &mut Vec::new());
                    let fast = sum.unwrap() / samples.len() as f32;
                    // Giving up below the sum stops; at the sum (or above) it does not.
                    let s = sum.unwrap();
                    let at = prune_sum(q, &reps, tc, projected, lw, s, &mut Vec::new());
                    assert_eq!(at, Some(s));
                    if s > 0.0 {
                        let below =
                            prune_sum(q, &reps, tc, projected, lw, s * 0.999, &mut Vec::new());
                        assert_eq!(below, None);
                    }
                    assert!(
                        (fast - brute).abs() <= 1e-5 * (1.0 + brute),
                        "template {t}, lw {lw}: {fast} vs {brute}"
                    );
                }
            }
        }
    }

    #[test]
    fn four_low_includes_the_least() {
        let v = [
            5.0f32, 1.0, 7.0, 0.5, 3.0, 0.75, 9.0, 2.0, 8.0, 0.25, 6.0, 6.0, 6.0, 6.0, 6.0, 6.0,
        ];
        let mut got = four_low(&v);
        got.sort();
        // Lane minima: 5 (0), 0.25 (9), 6 (10), 0.5 (3), 3 (4), 0.75 (5), 6 (14), 2 (7).
        assert_eq!(got, [3, 5, 7, 9]);
    }

    /// The cost matrix (template samples × query samples) holds `pair_cost` of every
    /// pair to rounding, for sample counts that are and are not multiples of the
    /// vector blocks.
    #[test]
    fn cost_matrix_equals_pair_costs() {
        let db = super::eval::database();
        let cam = Camera::itop();
        let mut rng = super::eval::Rng(11);
        let q = super::eval::query_context(db, 42, &mut rng, &cam);
        let columns = QueryColumns::new(&q);
        let mut cost = Vec::new();
        for t in [0usize, 42, 301, 767] {
            let tc = &db.templates[t].context;
            for lw in [0.0f32, 0.1] {
                cost_matrix(&q, &columns, tc, lw, &mut cost);
                assert_eq!(cost.len(), q.len() * tc.len());
                for j in 0..tc.len() {
                    for i in 0..q.len() {
                        let want = pair_cost(&q, i, tc, j, lw) as f64;
                        let got = cost[j * q.len() + i];
                        assert!(
                            (got - want).abs() <= 1e-5 * want + 1e-6,
                            "{i} {j}: {got} vs {want}"
                        );
                    }
                }
            }
        }
        assert!(
            db.templates
                .iter()
                .any(|t| !t.context.len().is_multiple_of(4))
                && !q.len().is_multiple_of(16),
            "no template or query exercises the leftover rows and columns"
        );
    }

    /// The AVX-512 and AVX2 cost kernels write the same rows, bit for bit (where the
    /// CPU has both).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn cost_kernels_agree_bit_for_bit() {
        if !(std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma"))
        {
            eprintln!("skipped: this CPU lacks AVX-512F, AVX2 or FMA");
            return;
        }
        let db = super::eval::database();
        let cam = Camera::itop();
        let mut rng = super::eval::Rng(5);
        for query in [7usize, 300, 600] {
            let q = super::eval::query_context(db, query, &mut rng, &cam);
            let columns = QueryColumns::new(&q);
            for t in [0usize, 42, 301, 767] {
                let tc = &db.templates[t].context;
                let n = q.len();
                let (mut a, mut b) = (vec![-1.0; n * tc.len()], vec![-1.0; n * tc.len()]);
                // SAFETY: the CPU has the features (checked above).
                let rows_a = unsafe { cost_rows_avx512(&columns, tc, 0.1, n, &mut a) };
                let rows_b = unsafe { cost_rows_fma(&columns, tc, 0.1, n, &mut b) };
                assert_eq!(rows_a, rows_b);
                assert_eq!(
                    a[..rows_a * n],
                    b[..rows_b * n],
                    "query {query}, template {t}"
                );
            }
        }
    }

    /// The short list with the early give-up is the exhaustive ranking's: the best
    /// `shortlist` templates by the full pruning score (ties by index), with the same
    /// scores.
    #[test]
    fn shortlist_with_give_up_equals_full_ranking() {
        let db = super::eval::database();
        let cam = Camera::itop();
        let mut rng = super::eval::Rng(11);
        for t in [17usize, 260, 600, 750] {
            let q = super::eval::query_context(db, t, &mut rng, &cam);
            for shortlist in [1usize, 5, 16, 40] {
                let config = MatchConfig {
                    shortlist,
                    top_k: shortlist,
                    ..Default::default()
                };
                let reps = Representatives::new(&db.prune, &q, config.representatives);
                let samples = &reps.samples;
                let lw = config.location_weight as f32;
                let mut full: Vec<(f64, usize)> = (0..db.len())
                    .map(|t| {
                        let tc = &db.templates[t].context;
                        let sum = prune_sum(
                            &q,
                            &reps,
                            tc,
                            &db.prune.projected[t],
                            lw,
                            f32::INFINITY,
                            &mut Vec::new(),
                        );
                        ((sum.unwrap() / samples.len() as f32) as f64, t)
                    })
                    .collect();
                full.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                let want: Vec<usize> = full[..shortlist].iter().map(|s| s.1).collect();
                let got = db.match_context(&q, &config).unwrap();
                assert_eq!(got.shortlist, want, "query {t}, shortlist {shortlist}");
                for c in &got.candidates {
                    let score = full.iter().find(|s| s.1 == c.index).unwrap().0;
                    assert_eq!(c.prune_cost, score);
                }
            }
        }
    }

    /// The pruning basis is orthonormal, so the descriptions' distances never exceed
    /// the descriptors' own.
    #[test]
    fn prune_projection_is_a_lower_bound() {
        let db = super::eval::database();
        let (k, dim) = (db.prune.components, db.config.descriptor.dim());
        let directions = db.prune.directions;
        assert_eq!(directions, PRUNE_DIRECTIONS.min(dim));
        assert_eq!(k, directions + 1);
        for a in 0..directions {
            for b in 0..directions {
                let dot: f64 = (0..dim)
                    .map(|d| db.prune.basis[a * dim + d] * db.prune.basis[b * dim + d])
                    .sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-9, "rows {a}, {b}: {dot}");
            }
        }
        let (ta, tb) = (&db.templates[10], &db.templates[500]);
        let (pa, pb) = (&db.prune.projected[10], &db.prune.projected[500]);
        let (na, nb) = (ta.context.len(), tb.context.len());
        let (sa, sb) = (prune_stride(na), prune_stride(nb));
        let mut tight = 0.0f64;
        let mut one = vec![0.0f32; k];
        for i in 0..na {
            // Stored projections are the basis applied to the descriptor.
            db.prune.project(ta.context.descriptor(i), &mut one);
            assert!((0..k).all(|c| one[c] == pa[c * sa + i]));
            for j in 0..nb {
                let full = crate::descriptor::squared_distance(
                    ta.context.descriptor(i),
                    tb.context.descriptor(j),
                );
                let lower: f32 = (0..k)
                    .map(|c| (pa[c * sa + i] - pb[c * sb + j]).powi(2))
                    .sum();
                assert!(lower <= full * 1.0001 + 1e-8, "{lower} > {full}");
                tight += (lower / full.max(1e-12)) as f64;
            }
        }
        // And the bound is useful: it holds most of the distance.
        let mean = tight / (ta.context.len() * tb.context.len()) as f64;
        eprintln!("mean bound / squared distance: {mean:.3}");
        assert!(mean > 0.7, "projected share of squared distance {mean}");
    }

    /// The re-ranking re-orders the exact stage's best `rerank` candidates by their
    /// placed energy and nothing else; on perturbed front-view renders (where the
    /// normals cannot tell an arm toward the camera from one hanging down) its first
    /// candidates' joints lie nearer the truth than the descriptors' own.
    #[test]
    fn rerank_orders_the_best_candidates_by_their_placed_energy() {
        let db = super::eval::database();
        let cam = Camera::itop();
        let mut rng = super::eval::Rng(7);
        let truncated = |c: MatchConfig| MatchConfig { top_k: 10, ..c };
        let plain_cfg = truncated(MatchConfig::default());
        let rerank_cfg = MatchConfig {
            rerank: 10,
            ..plain_cfg
        };
        let (mut err_plain, mut err_rerank) = (0.0, 0.0);
        let queries = 12;
        for q in 0..queries {
            // Front views: templates 0..256.
            let t = (rng.uniform() * 256.0) as usize;
            let (d, pose) = super::eval::query(t, &mut rng, &cam, 0.1);
            let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
            let plain = db.match_depth(&view, &cam, None, &plain_cfg).unwrap();
            let rr = db.match_depth(&view, &cam, None, &rerank_cfg).unwrap();
            // A permutation of the same ten, the short list untouched.
            let mut a: Vec<usize> = plain.candidates.iter().map(|c| c.index).collect();
            let mut b: Vec<usize> = rr.candidates.iter().map(|c| c.index).collect();
            assert_eq!(plain.shortlist, rr.shortlist);
            if q == 0 {
                assert_ne!(a, b, "the first query's order should change");
            }
            a.sort_unstable();
            b.sort_unstable();
            assert_eq!(a, b);
            // In ascending placed energy.
            let dc = &db.config.descriptor;
            let sil = Silhouette::from_depth(&view, &cam, None, dc.normal_radius).unwrap();
            let pts = rerank_points(&sil);
            let energies: Vec<f64> = rr
                .candidates
                .iter()
                .map(|c| db.placed_energy(&pts, &d, &cam, &c.pose))
                .collect();
            assert!(energies.windows(2).all(|w| w[0] <= w[1]), "{energies:?}");
            // A shorter list is the head of the re-ranked one; rerank 0 and 1 are off.
            let head = db
                .match_depth(
                    &view,
                    &cam,
                    None,
                    &MatchConfig {
                        top_k: 3,
                        ..rerank_cfg
                    },
                )
                .unwrap();
            assert_eq!(head.candidates[..], rr.candidates[..3]);
            for off in [0, 1] {
                let same = db
                    .match_depth(
                        &view,
                        &cam,
                        None,
                        &MatchConfig {
                            rerank: off,
                            ..plain_cfg
                        },
                    )
                    .unwrap();
                assert_eq!(same, plain);
            }
            let truth = db.model.joints(&pose);
            let err = |c: &Candidate| {
                c.joints
                    .iter()
                    .zip(&truth)
                    .map(|(j, t)| (Vector3::from(*j) - t).norm())
                    .sum::<f64>()
                    / NUM_JOINTS as f64
            };
            err_plain += err(&plain.candidates[0]) / queries as f64;
            err_rerank += err(&rr.candidates[0]) / queries as f64;
        }
        eprintln!("mean joint error of the first candidate: descriptors {err_plain:.4} m, re-ranked {err_rerank:.4} m");
        assert!(err_rerank < err_plain, "{err_rerank} vs {err_plain}");
        let bad = MatchConfig {
            rerank: NUM_TEMPLATES + 1,
            ..plain_cfg
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn hash_depends_on_model_and_settings() {
        let m = BodyModel::default();
        let c = TemplateConfig::default();
        let h = TemplateDatabase::settings_hash(&m, &c);
        assert_eq!(h, TemplateDatabase::settings_hash(&m, &c));
        assert_ne!(
            h,
            TemplateDatabase::settings_hash(&BodyModel::new(1.6).unwrap(), &c)
        );
        let c2 = TemplateConfig { width: 80, ..c };
        assert_ne!(h, TemplateDatabase::settings_hash(&m, &c2));
    }
}

#[cfg(test)]
mod eval {
    //! Retrieval accuracy on perturbed, noisy renders of the template poses.
    use super::*;
    use std::sync::OnceLock;

    pub(super) fn database() -> &'static TemplateDatabase {
        static DB: OnceLock<TemplateDatabase> = OnceLock::new();
        DB.get_or_init(|| {
            let renderer = if std::env::var("DEPTHPOSE_EVAL_ELLIPSOID").is_ok() {
                TemplateRenderer::Ellipsoid
            } else {
                TemplateRenderer::Superquadric
            };
            // The relief channel's weight (docs/templates.md compares 0 and 3).
            let depth_weight = std::env::var("DEPTHPOSE_EVAL_DEPTH_WEIGHT")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(0.0);
            let d = TemplateConfig::default();
            let cfg = TemplateConfig {
                renderer,
                descriptor: DescriptorConfig {
                    depth_weight,
                    ..d.descriptor
                },
                ..d
            };
            TemplateDatabase::build(&BodyModel::default(), &cfg).unwrap()
        })
    }

    pub(super) struct Rng(pub(super) u64);
    impl Rng {
        pub(super) fn uniform(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        pub(super) fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.uniform()
        }
        /// Approximately normal (sum of 4 uniforms), unit variance.
        pub(super) fn normal(&mut self) -> f64 {
            ((0..4).map(|_| self.uniform()).sum::<f64>() - 2.0) * 3f64.sqrt()
        }
    }

    /// A perturbed, noisy depth image of template `t` and its true pose.
    pub(super) fn query(
        t: usize,
        rng: &mut Rng,
        cam: &Camera,
        joint_noise: f64,
    ) -> (Vec<f32>, Pose) {
        let model = BodyModel::default();
        let mut pose = template_pose(t, 3.0);
        for v in pose[6..].iter_mut() {
            *v += rng.range(-joint_noise, joint_noise);
        }
        pose[param::ROOT_R + 1] += rng.range(-joint_noise, joint_noise);
        pose = BodyModel::clamp_pose(&pose);
        pose[0] = rng.range(-0.4, 0.4);
        pose[1] = rng.range(-0.1, 0.2);
        pose[2] = rng.range(2.6, 4.0);
        let (mut d, _) = model.render_depth(&pose, cam);
        for z in d.iter_mut() {
            if *z > 0.0 {
                if rng.uniform() < 0.01 {
                    *z = 0.0;
                } else {
                    *z += (0.005 * rng.normal()) as f32;
                }
            }
        }
        (d, pose)
    }

    /// The surface contexts of [`query`]'s depth image of template `t` (joints perturbed
    /// by up to 0.1 rad).
    pub(super) fn query_context(
        db: &TemplateDatabase,
        t: usize,
        rng: &mut Rng,
        cam: &Camera,
    ) -> SurfaceContext {
        let (depth, _) = query(t, rng, cam, 0.1);
        let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
        let d = &db.config.descriptor;
        let sil = Silhouette::from_depth(&view, cam, None, d.normal_radius).unwrap();
        sil.surface_context(d).unwrap()
    }

    #[test]
    #[ignore = "evaluation: cargo test --lib templates::eval -- --ignored --nocapture"]
    fn retrieval_accuracy() {
        let db = database();
        let cam = Camera::itop();
        let mut rng = Rng(42);
        let n = std::env::var("EVAL_N")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(60usize);
        let (mut top1, mut top10, mut joints_ok, mut top1_tied) = (0, 0, 0, 0);
        const TIE: f64 = 1e-9;
        let env = |k: &str, d: f64| {
            std::env::var(k)
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(d)
        };
        let base = MatchConfig::default();
        let cfg = MatchConfig {
            top_k: 10,
            location_weight: env("EVAL_LW", base.location_weight),
            dummy_cost: env("EVAL_DUMMY", base.dummy_cost),
            rerank: env("EVAL_RERANK", base.rerank as f64) as usize,
            ..base
        };
        for _ in 0..n {
            let t = (rng.uniform() * NUM_TEMPLATES as f64) as usize;
            let (d, pose) = query(t, &mut rng, &cam, env("EVAL_JOINT_NOISE", 0.1));
            let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
            let r = db.match_depth(&view, &cam, None, &cfg).unwrap();
            let rank = r.candidates.iter().position(|c| c.index == t);
            top1 += (rank == Some(0)) as usize;
            top10 += rank.is_some() as usize;
            // Tied with the winner: the image cannot tell the two apart (e.g. the far
            // arm hidden behind the body in a side view gives identical descriptors).
            let tied = rank.is_some_and(|k| r.candidates[k].cost <= r.candidates[0].cost + TIE);
            top1_tied += tied as usize;
            let truth = db.model.joints(&pose);
            let pck = r.candidates[0]
                .joints
                .iter()
                .zip(&truth)
                .filter(|(a, b)| (Vector3::from(**a) - *b).norm() < 0.1)
                .count();
            joints_ok += pck;
            if rank != Some(0) {
                println!(
                    "t {t} {:?} got {} {:?} rank {rank:?} cost {:.4} vs best {:.4}",
                    template_code(t),
                    r.candidates[0].index,
                    template_code(r.candidates[0].index),
                    r.candidates
                        .iter()
                        .find(|c| c.index == t)
                        .map(|c| c.cost)
                        .unwrap_or(f64::NAN),
                    r.candidates[0].cost
                );
            }
        }
        let pck = joints_ok as f64 / (n * NUM_JOINTS) as f64;
        println!("top1 {top1}/{n} (tied with the winner: {top1_tied}/{n}) top10 {top10}/{n} pck {pck:.3}");
        // What the descriptors reach (see docs/templates.md); the targets are
        // 95% / 99%.
        assert!(top1_tied as f64 >= 0.55 * n as f64, "top-1 {top1_tied}/{n}");
        assert!(top10 as f64 >= 0.95 * n as f64, "top-10 {top10}/{n}");
        assert!(pck > 0.85, "PCK {pck}");
    }
}

#[cfg(test)]
mod format_fuzz {
    //! The database file format against corrupt content: `from_arrays` refuses it with
    //! an error and never panics (no wrapped-around counts, no capacity overflow).
    use super::*;
    use proptest::prelude::*;

    /// A well-formed database of `count` samples per template (no rendering needed).
    fn arrays(count: i64) -> TemplateArrays {
        let model = BodyModel::default();
        let config = TemplateConfig::default();
        let t = NUM_TEMPLATES;
        let s = t * count as usize;
        let dim = config.descriptor.dim();
        TemplateArrays {
            format_version: FORMAT_VERSION,
            hash: TemplateDatabase::settings_hash(&model, &config),
            shape: model.shape.to_vec().to_vec(),
            config: config_to_vec(&config).to_vec(),
            poses: vec![0.0; t * NUM_PARAMS],
            views: (0..t as i64).map(|i| i % NUM_VIEWS as i64).collect(),
            joints: vec![0.5; t * NUM_JOINTS * 3],
            centroids: vec![0.0; t * 3],
            sizes: vec![1.0; t],
            counts: vec![count; t],
            context_scale: vec![1.0; t],
            context_centroid: vec![0.0; t * 2],
            context_points: vec![100; t],
            sample_pixels: vec![1.0; 2 * s],
            sample_positions: vec![0.1; 2 * s],
            descriptors: vec![0.01; dim * s],
        }
    }

    #[test]
    fn well_formed_arrays_load_and_wrapped_counts_do_not() {
        assert!(TemplateDatabase::from_arrays(&arrays(2), None, "f").is_ok());
        // Counts that sum past i64 to the right total once wrapped around:
        // 2 (i64::MAX) + 8 + 765 · 2 = 2 · 768 (mod 2^64).
        let mut a = arrays(2);
        a.counts[0] = i64::MAX;
        a.counts[1] = i64::MAX;
        a.counts[2] = 8;
        let r = TemplateDatabase::from_arrays(&a, None, "f");
        assert!(matches!(r, Err(crate::Error::File { .. })), "{r:?}");
    }

    /// Which array a case corrupts, and how.
    #[derive(Debug, Clone)]
    enum Corruption {
        Count {
            index: usize,
            value: i64,
        },
        Truncate {
            field: usize,
            keep: usize,
        },
        Value {
            field: usize,
            index: usize,
            value: f64,
        },
        View {
            index: usize,
            value: i64,
        },
        Config {
            index: usize,
            value: f64,
        },
    }

    fn corruption() -> impl Strategy<Value = Corruption> {
        let big = prop_oneof![
            any::<i64>(),
            Just(i64::MAX),
            Just(i64::MIN),
            -3i64..5,
            Just(i64::MAX / 2 + 1)
        ];
        let value = prop_oneof![
            any::<f64>(),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(1e300),
            Just(-1.0)
        ];
        prop_oneof![
            (0usize..NUM_TEMPLATES, big.clone())
                .prop_map(|(index, value)| Corruption::Count { index, value }),
            (0usize..6, any::<usize>())
                .prop_map(|(field, keep)| Corruption::Truncate { field, keep }),
            (0usize..4, any::<usize>(), value.clone()).prop_map(|(field, index, value)| {
                Corruption::Value {
                    field,
                    index,
                    value,
                }
            }),
            (0usize..NUM_TEMPLATES, big)
                .prop_map(|(index, value)| Corruption::View { index, value }),
            (0usize..CONFIG_VALUES, value)
                .prop_map(|(index, value)| Corruption::Config { index, value }),
        ]
    }

    fn apply(a: &mut TemplateArrays, c: &Corruption) {
        fn cut<T>(v: &mut Vec<T>, keep: usize) {
            let n = v.len();
            v.truncate(keep % (n + 1));
        }
        fn set<T>(v: &mut [T], index: usize, value: T) {
            if !v.is_empty() {
                let n = v.len();
                v[index % n] = value;
            }
        }
        match *c {
            Corruption::Count { index, value } => set(&mut a.counts, index, value),
            Corruption::Truncate { field, keep } => match field {
                0 => cut(&mut a.poses, keep),
                1 => cut(&mut a.counts, keep),
                2 => cut(&mut a.descriptors, keep),
                3 => cut(&mut a.sample_pixels, keep),
                4 => cut(&mut a.views, keep),
                _ => cut(&mut a.config, keep),
            },
            Corruption::Value {
                field,
                index,
                value,
            } => {
                let v = match field {
                    0 => &mut a.poses,
                    1 => &mut a.joints,
                    2 => &mut a.shape,
                    _ => &mut a.sizes,
                };
                set(v, index, value);
            }
            Corruption::View { index, value } => set(&mut a.views, index, value),
            Corruption::Config { index, value } => set(&mut a.config, index, value),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(crate::io::tests::fuzz_cases(48)))]

        /// Any corruption gives a database or a `File` error, never a panic.
        #[test]
        fn corrupt_arrays_are_refused_not_panicked_on(
            count in 2i64..4,
            cs in proptest::collection::vec(corruption(), 1..4),
        ) {
            let mut a = arrays(count);
            for c in &cs {
                apply(&mut a, c);
            }
            match TemplateDatabase::from_arrays(&a, None, "fuzz") {
                Ok(db) => prop_assert_eq!(db.len(), NUM_TEMPLATES),
                Err(crate::Error::File { path, .. }) => prop_assert_eq!(path, "fuzz"),
                Err(e) => prop_assert!(false, "unexpected error {e:?}"),
            }
        }
    }
}
