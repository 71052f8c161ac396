//! Model fitting (paper Section II-D): CRF body-part labelling and Levenberg–Marquardt
//! in a hard EM loop ([`em`]), inverse kinematics from joints ([`ik`]) and body-shape
//! calibration ([`shape`]).
//!
//! [`fit_pose`] is the one-call entry: depth image + camera + initial pose → pose,
//! joints, per-pixel part labels and diagnostics.

pub mod em;
pub mod ik;
pub mod lm;
pub mod noise;
pub mod shape;
pub mod start;
pub mod system;
pub mod terms;

/// The data term ([`terms::data`]).
pub use terms::data as objective;
pub use terms::free_space;

use crate::body::{pose_from_slice, BodyModel, Pose, NUM_JOINTS, NUM_SEGMENTS};
use crate::camera::Camera;
use crate::cloud::{neighbour_graph, Cloud, Connectivity, DepthView, PixelGraph};
use crate::error::{Error, Result};
use nalgebra::Vector3;
use rayon::prelude::*;
use terms::free_space::{FreeSpaceImage, FreeSpaceTerm};

pub use em::{
    hard_em, hard_em_from, label_points, EmConfig, EmOptions, EmResult, EmResume, EmTermination,
    PointLabels, UnaryAt, OUTLIER,
};
pub use ik::pose_from_joints;
pub use lm::{LevenbergMarquardt, LmConfig, LmReport, Termination};
pub use noise::DepthNoise;
pub use shape::{fit_shape, shape_lm, ShapeConfig, ShapeFrame, ShapeResult};
pub use terms::Loss;
pub use terms::PosePrior;

/// Fewer foreground points than this cannot constrain 22 parameters.
pub const MIN_POINTS: usize = 50;

/// Settings of [`fit_pose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitConfig {
    pub em: EmConfig,
    /// Pixel neighbourhood of the CRF.
    pub connectivity: Connectivity,
    /// EM runs on every `stride`-th pixel of every `stride`-th row (1 = all pixels;
    /// 2 = a quarter of the points, about 3× faster), then the full-resolution pixels
    /// are labelled once for the final pose. See [`fit_pose`].
    pub stride: usize,
    /// With a stride: label every full-resolution pixel for the final pose (true), or
    /// return the EM's own labels at the sub-sampled pixels only, every other pixel −1,
    /// with the sub-sampled energy (false: no full-resolution E-step, for brief fits
    /// whose pose is all that counts, or that are continued at the same stride).
    pub label_all_pixels: bool,
    /// With a stride and `label_all_pixels`: after the strided EM and its
    /// full-resolution labelling, at most this many more EM iterations on every pixel,
    /// continued from that pose and labelling (coarse to fine; 0 = none). They stop
    /// early when the full-resolution EM converges; the result's `energy_trace` is
    /// theirs (full-resolution energies), `iterations` counts both stages.
    pub full_resolution_iterations: usize,
    /// A fresh fit (not a continued one) also starts from the given pose translated so
    /// that its visible surface's centroid lies on the observed points' (see
    /// [`start`]), when that moves it by at least 1 cm, and keeps the lower-energy EM.
    pub recentred_start: bool,
    /// A fresh fit also starts from the given pose with the left and right legs'
    /// angles exchanged, and with the arms' exchanged (each also recentred when
    /// `recentred_start` is on), and keeps the lowest-energy EM: up to 3× the work, for
    /// starts that may have a limb on the wrong side (off by default).
    pub swapped_limb_starts: bool,
    /// The sensor's depth noise when it grows with depth (a stereo pair): each point's
    /// data terms are weighted by how precisely its depth is known ([`noise`]). None:
    /// every point alike.
    pub depth_noise: Option<DepthNoise>,
}

/// Largest accepted [`FitConfig::stride`].
pub const MAX_STRIDE: usize = 8;

/// Largest accepted [`FitConfig::full_resolution_iterations`].
pub const MAX_FULL_RESOLUTION_ITERATIONS: usize = 1000;

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            em: EmConfig::default(),
            connectivity: Connectivity::Four,
            stride: 1,
            label_all_pixels: true,
            full_resolution_iterations: 0,
            recentred_start: true,
            swapped_limb_starts: false,
            depth_noise: None,
        }
    }
}

impl FitConfig {
    /// Checks every field, naming the bad one.
    pub fn validate(&self) -> Result<()> {
        self.em.validate()?;
        if let Some(n) = &self.depth_noise {
            n.validate()?;
        }
        if self.stride == 0 || self.stride > MAX_STRIDE {
            return Err(Error::invalid(
                "stride",
                format!("must be 1..={MAX_STRIDE}, got {}", self.stride),
            ));
        }
        if self.full_resolution_iterations > MAX_FULL_RESOLUTION_ITERATIONS {
            return Err(Error::invalid(
                "full_resolution_iterations",
                format!(
                    "must be 0..={MAX_FULL_RESOLUTION_ITERATIONS}, got {}",
                    self.full_resolution_iterations
                ),
            ));
        }
        Ok(())
    }
}

/// Every `s`-th pixel of every `s`-th row of `depth` (and `mask`), and the camera of that
/// sub-image: pixel (r, c) of it is pixel (s·r, s·c) of the original, so with pixel
/// centres at integer coordinates the intrinsics simply scale by 1/s.
fn subsample(
    depth: &[f32],
    camera: &Camera,
    mask: Option<&[bool]>,
    s: usize,
) -> (Vec<f32>, Option<Vec<bool>>, Camera) {
    let (w, h) = (camera.width, camera.height);
    let (sw, sh) = (w.div_ceil(s), h.div_ceil(s));
    let pick = |r: usize, c: usize| full_resolution_pixel(r * sw + c, sw, s, w);
    let sub_depth = (0..sh)
        .flat_map(|r| (0..sw).map(move |c| depth[pick(r, c)]))
        .collect();
    let sub_mask = mask.map(|m| {
        (0..sh)
            .flat_map(|r| (0..sw).map(move |c| m[pick(r, c)]))
            .collect()
    });
    let sf = s as f64;
    let cam = Camera {
        fx: camera.fx / sf,
        fy: camera.fy / sf,
        cx: camera.cx / sf,
        cy: camera.cy / sf,
        width: sw,
        height: sh,
    };
    (sub_depth, sub_mask, cam)
}

/// The index in the W-wide full-resolution image of pixel `px` of the `sub_width`-wide
/// image [`subsample`] made with stride `s`: (r, c) ↦ (s·r, s·c).
#[inline]
fn full_resolution_pixel(px: usize, sub_width: usize, s: usize, w: usize) -> usize {
    let (r, c) = (px / sub_width, px % sub_width);
    s * r * w + s * c
}

/// The H×W image of per-point labels (−1 where no point).
fn label_image(cloud: &Cloud, labels: &[i32]) -> Vec<i16> {
    let mut image = vec![-1i16; cloud.width * cloud.height];
    for (&px, &l) in cloud.pixels.iter().zip(labels) {
        image[px as usize] = l as i16;
    }
    image
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
    /// Where the EM cut its annealing short ([`EmResult::anneal_cut`]).
    pub anneal_cut: Option<usize>,
    /// Points labelled with each segment.
    pub part_counts: [usize; NUM_SEGMENTS],
    /// Foreground points labelled outlier.
    pub outliers: usize,
}

impl FitResult {
    /// The result of an EM run as it stands, with `labels` its H×W label image.
    fn from_em(model: &BodyModel, em: EmResult, labels: Vec<i16>) -> Self {
        FitResult {
            pose: em.pose,
            joints: model.joints(&em.pose),
            labels,
            energy: em.energy,
            energy_trace: em.energy_trace,
            iterations: em.iterations,
            termination: em.termination,
            anneal_cut: em.anneal_cut,
            part_counts: em.part_counts,
            outliers: em.outliers,
        }
    }

    pub fn converged(&self) -> bool {
        self.termination != EmTermination::MaxIterations
    }
}

/// The data of a fit, built once per depth image: the foreground cloud and its CRF
/// graph, and with a stride the sub-sampled cloud, camera and graph. Any number of
/// start poses can then be fitted to it ([`FitProblem::fit`]), concurrently.
pub struct FitProblem {
    camera: Camera,
    config: FitConfig,
    cloud: Cloud,
    graph: PixelGraph,
    /// The whole depth image (background included) for the free-space term; empty
    /// when the term is off.
    depth: Vec<f32>,
    /// With `stride > 1` (and enough sub-sampled points): the sub-sampled cloud, its
    /// camera and graph, and the sub-sampled depth image (empty when the free-space
    /// term is off).
    sub: Option<(Cloud, Camera, PixelGraph, Vec<f32>)>,
    /// With [`FitConfig::depth_noise`]: the weights of the points of `cloud` and of the
    /// sub-sampled cloud (see [`DepthNoise::point_weights`]); else empty.
    weights: PointWeights,
}

/// The weights of a fit problem's points (empty without depth noise).
#[derive(Default)]
struct PointWeights {
    full: Vec<f32>,
    sub: Vec<f32>,
}

impl PointWeights {
    fn new(config: &FitConfig, cloud: &Cloud, sub: Option<&Cloud>) -> Self {
        let Some(noise) = &config.depth_noise else {
            return PointWeights::default();
        };
        let sigma = config.em.sigma;
        PointWeights {
            full: noise.point_weights(&cloud.points, sigma),
            sub: sub.map_or_else(Vec::new, |c| noise.point_weights(&c.points, sigma)),
        }
    }
}

/// The farthest depth reading a fit takes (metres): far beyond any sensor, and near
/// enough that squared distances between its points stay finite in `f32`.
pub const MAX_FIT_DEPTH: f32 = 1.0e6;

/// `weights` as a fit takes them (None when empty).
fn weights_of(weights: &[f32]) -> Option<&[f32]> {
    (!weights.is_empty()).then_some(weights)
}

impl FitProblem {
    /// The foreground of `depth` (H×W metres, row-major; `mask` selects the person's
    /// pixels, None = every reading) under `config`.
    pub fn new(
        depth: &[f32],
        camera: &Camera,
        mask: Option<&[bool]>,
        config: &FitConfig,
    ) -> Result<Self> {
        config.validate()?;
        let view = DepthView::new(depth, camera.height, camera.width, "depth")?;
        let cloud = Cloud::from_depth(&view, camera, mask)?;
        if let Some(z) = cloud
            .points
            .iter()
            .map(|p| p[2])
            .find(|z| *z > MAX_FIT_DEPTH)
        {
            return Err(Error::invalid(
                "depth",
                format!(
                    "a foreground reading of {} m; a fit takes readings up to {} m",
                    crate::error::brief(z),
                    crate::error::brief(MAX_FIT_DEPTH)
                ),
            ));
        }
        if cloud.len() < MIN_POINTS {
            return Err(Error::NoBody(format!(
                "the foreground has {} points, at least {MIN_POINTS} are needed",
                cloud.len()
            )));
        }
        let graph = neighbour_graph(&cloud, config.connectivity);
        let s = config.stride;
        let sub = if s > 1 {
            let (sub_depth, sub_mask, sub_cam) = subsample(depth, camera, mask, s);
            let sub_view = DepthView::new(&sub_depth, sub_cam.height, sub_cam.width, "depth")?;
            let sub_cloud = Cloud::from_depth(&sub_view, &sub_cam, sub_mask.as_deref())?;
            (sub_cloud.len() >= MIN_POINTS).then(|| {
                let sub_graph = neighbour_graph(&sub_cloud, config.connectivity);
                let sub_depth = if config.em.free_space_weight > 0.0 {
                    sub_depth
                } else {
                    Vec::new()
                };
                (sub_cloud, sub_cam, sub_graph, sub_depth)
            })
        } else {
            None
        };
        let free_space = config.em.free_space_weight > 0.0;
        let weights = PointWeights::new(config, &cloud, sub.as_ref().map(|s| &s.0));
        Ok(FitProblem {
            camera: *camera,
            config: *config,
            weights,
            cloud,
            graph,
            depth: if free_space {
                depth.to_vec()
            } else {
                Vec::new()
            },
            sub,
        })
    }

    /// Replaces the fit settings by `config`, keeping the cloud and graphs: allowed when
    /// the stride, the connectivity and whether the free-space term is on are the same
    /// (they decide what was built). Errors otherwise, or when `config` is invalid.
    pub fn set_config(&mut self, config: &FitConfig) -> Result<()> {
        config.validate()?;
        let same = config.stride == self.config.stride
            && config.connectivity == self.config.connectivity
            && (config.em.free_space_weight > 0.0) == (self.config.em.free_space_weight > 0.0);
        if !same {
            return Err(Error::invalid(
                "config",
                "a fit problem keeps its stride, connectivity and free-space term",
            ));
        }
        if config.depth_noise != self.config.depth_noise || config.em.sigma != self.config.em.sigma
        {
            let sub = self.sub.as_ref().map(|s| &s.0);
            self.weights = PointWeights::new(config, &self.cloud, sub);
        }
        self.config = *config;
        Ok(())
    }

    /// `init` moved onto the observed body (see [`start::recentred`]): None when the
    /// move is negligible or the body is out of view.
    pub fn recentred(&self, model: &BodyModel, init: &Pose) -> Option<Pose> {
        let target = self.cloud.centroid()?;
        start::recentred(model, init, &self.camera, &target)
    }

    /// The fit settings.
    pub fn config(&self) -> &FitConfig {
        &self.config
    }

    /// The whole full-resolution image for the free-space term (None when it is off).
    fn free_space_image(&self) -> Option<FreeSpaceImage<'_>> {
        (!self.depth.is_empty()).then_some(FreeSpaceImage {
            depth: &self.depth,
            camera: &self.camera,
            weight_scale: 1.0,
        })
    }

    /// Fits `model` from `init` with an optional prior toward a pose.
    pub fn fit(
        &self,
        model: &BodyModel,
        init: &Pose,
        prior: Option<&PosePrior>,
    ) -> Result<FitResult> {
        self.fit_from(model, init, None, prior)
    }

    /// The labels of `previous` (a fit of this image) for the points the EM runs on
    /// (the sub-sampled ones with a stride): its label at each point's pixel, the
    /// outlier label where it has none.
    fn resume_labels(&self, previous: &FitResult) -> Result<Vec<i32>> {
        let (w, h) = (self.camera.width, self.camera.height);
        if previous.labels.len() != w * h {
            return Err(Error::invalid(
                "resume",
                format!(
                    "its labels have {} pixels, this {h}x{w} image {}",
                    previous.labels.len(),
                    w * h
                ),
            ));
        }
        let label = |px: usize| match previous.labels[px] {
            l if l < 0 => OUTLIER,
            l => l as i32,
        };
        Ok(match &self.sub {
            None => self
                .cloud
                .pixels
                .iter()
                .map(|&px| label(px as usize))
                .collect(),
            Some((sub_cloud, sub_cam, _, _)) => {
                let s = self.config.stride;
                let sw = sub_cam.width;
                sub_cloud
                    .pixels
                    .iter()
                    .map(|&px| label(full_resolution_pixel(px as usize, sw, s, w)))
                    .collect()
            }
        })
    }

    /// [`Self::fit_from`] from each of `inits`, in parallel (each fit's own work is
    /// mostly sequential, the graph cuts above all, so this uses the cores far better
    /// than fitting one start after another); with `resume`, one earlier result per
    /// start, each continued. Results in the order of `inits`, each identical to its
    /// own [`Self::fit_from`] call.
    pub fn fit_each(
        &self,
        model: &BodyModel,
        inits: &[Pose],
        resume: Option<&[&FitResult]>,
        prior: Option<&PosePrior>,
    ) -> Result<Vec<FitResult>> {
        if let Some(r) = resume {
            if r.len() != inits.len() {
                return Err(Error::invalid(
                    "resume",
                    format!("has {} results for {} start poses", r.len(), inits.len()),
                ));
            }
        }
        crate::pool::on_worker(|| {
            inits
                .par_iter()
                .enumerate()
                .map(|(k, init)| self.fit_from(model, init, resume.map(|r| r[k]), prior))
                .collect()
        })
    }

    /// [`Self::fit`], or with `resume` (an earlier fit of this image, e.g. a brief
    /// one) the continuation of its EM from `init` (normally `resume`'s pose) with its
    /// labels and iteration count (see [`em::hard_em_from`]): `max_iterations` then
    /// counts its iterations too. A fresh fit with [`FitConfig::recentred_start`] (or
    /// [`FitConfig::swapped_limb_starts`]) runs EMs from those starts too and returns
    /// the lowest-energy one.
    pub fn fit_from(
        &self,
        model: &BodyModel,
        init: &Pose,
        resume: Option<&FitResult>,
        prior: Option<&PosePrior>,
    ) -> Result<FitResult> {
        let config = &self.config;
        let resume_labels = resume.map(|r| self.resume_labels(r)).transpose()?;
        let resume = resume_labels
            .as_deref()
            .zip(resume)
            .map(|(labels, r)| EmResume {
                labels,
                iterations: r.iterations,
                anneal_cut: r.anneal_cut,
            });
        // A fresh fit also starts from `init` moved onto the observed body, and with its
        // limbs swapped if asked (see [`start`]); the EMs run in parallel and the first
        // of the lowest energy is kept (so the given start wins ties).
        let mut starts = vec![BodyModel::clamp_pose(init)];
        if resume.is_none() {
            if config.swapped_limb_starts {
                starts.push(start::limbs_swapped(&starts[0], true, false));
                starts.push(start::limbs_swapped(&starts[0], false, true));
            }
            if config.recentred_start {
                if let Some(target) = self.cloud.centroid() {
                    let moved: Vec<Pose> = starts
                        .iter()
                        .filter_map(|s| start::recentred(model, s, &self.camera, &target))
                        .collect();
                    starts.extend(moved);
                }
            }
        }
        let em = if starts.len() == 1 {
            self.em(model, init, resume, prior)?
        } else {
            let ems = starts
                .par_iter()
                .map(|s| self.em(model, s, None, prior))
                .collect::<Result<Vec<_>>>()?;
            ems.into_iter()
                .reduce(|best, e| if e.energy < best.energy { e } else { best })
                .expect("at least two starts")
        };
        let Some((sub_cloud, sub_cam, _, _)) = &self.sub else {
            let labels = label_image(&self.cloud, &em.labels);
            return Ok(FitResult::from_em(model, em, labels));
        };
        if !config.label_all_pixels {
            // The EM's labels where its points are: sub-sampled pixel (r, c) is pixel
            // (s·r, s·c), the one `resume_labels` reads back.
            let (w, sw, s) = (self.camera.width, sub_cam.width, config.stride);
            let mut labels = vec![-1i16; w * self.camera.height];
            for (&px, &l) in sub_cloud.pixels.iter().zip(&em.labels) {
                labels[full_resolution_pixel(px as usize, sw, s, w)] = l as i16;
            }
            return Ok(FitResult::from_em(model, em, labels));
        }
        self.label_every_pixel(model, (sub_cloud, sub_cam), em, prior)
    }

    /// The EM from `init` on the points the fit runs on: every foreground point, or with
    /// a stride the sub-sampled ones.
    fn em(
        &self,
        model: &BodyModel,
        init: &Pose,
        resume: Option<EmResume<'_>>,
        prior: Option<&PosePrior>,
    ) -> Result<EmResult> {
        let config = &self.config;
        let Some((sub_cloud, sub_cam, sub_graph, sub_depth)) = &self.sub else {
            let free_space = self.free_space_image();
            let options = EmOptions {
                resume,
                prior,
                free_space,
                point_weights: weights_of(&self.weights.full),
            };
            return hard_em_from(
                model,
                &self.cloud.points,
                &self.graph,
                init,
                options,
                &config.em,
            );
        };
        // EM on the sub-sampled cloud. The data term sums over s² times fewer points, so
        // the prior weight shrinks by s² to keep the balance of the full-resolution fit.
        let s = config.stride;
        let scaled_prior = prior.map(|p| PosePrior {
            weights: p.weights.map(|w| w / (s * s) as f64),
            ..*p
        });
        // The same for the free-space term: its samples do not thin out with the stride.
        let free_space = (!sub_depth.is_empty()).then_some(FreeSpaceImage {
            depth: sub_depth,
            camera: sub_cam,
            weight_scale: 1.0 / (s * s) as f64,
        });
        let options = EmOptions {
            resume,
            prior: scaled_prior.as_ref(),
            free_space,
            point_weights: weights_of(&self.weights.sub),
        };
        hard_em_from(
            model,
            &sub_cloud.points,
            sub_graph,
            init,
            options,
            &config.em,
        )
    }

    /// `result`, a fit of this image at this problem's stride that kept the EM's
    /// labels only (`label_all_pixels` off, e.g. the best of several candidate fits),
    /// labelled at every pixel: the same result as that fit with `label_all_pixels` on.
    /// A result already labelled at every pixel, or a problem without a stride, gives
    /// `result` unchanged. (`prior`: the fit's prior, for the energy.)
    pub fn label_all(
        &self,
        model: &BodyModel,
        result: &FitResult,
        prior: Option<&PosePrior>,
    ) -> Result<FitResult> {
        let Some((sub_cloud, sub_cam, _, _)) = &self.sub else {
            return Ok(result.clone());
        };
        let labels = self.resume_labels(result)?;
        // Labels off the sub-sampled pixels (s·r, s·c): labelled at every pixel already.
        let (w, s) = (self.camera.width, self.config.stride);
        let off_grid = |px: usize| !(px / w).is_multiple_of(s) || !(px % w).is_multiple_of(s);
        if result
            .labels
            .iter()
            .enumerate()
            .any(|(px, &l)| l >= 0 && off_grid(px))
        {
            return Ok(result.clone());
        }
        let em = EmResult {
            pose: result.pose,
            labels,
            energy: result.energy,
            energy_trace: result.energy_trace.clone(),
            iterations: result.iterations,
            termination: result.termination,
            anneal_cut: result.anneal_cut,
            part_counts: result.part_counts,
            outliers: result.outliers,
        };
        self.label_every_pixel(model, (sub_cloud, sub_cam), em, prior)
    }

    /// The end of a strided fit with `label_all_pixels`: the EM's result `em` on the
    /// sub-sampled cloud, labelled at every full-resolution pixel.
    fn label_every_pixel(
        &self,
        model: &BodyModel,
        (sub_cloud, sub_cam): (&Cloud, &Camera),
        em: EmResult,
        prior: Option<&PosePrior>,
    ) -> Result<FitResult> {
        let (cloud, graph, config) = (&self.cloud, &self.graph, &self.config);
        let s = config.stride;
        // Then every full-resolution pixel: starting from the label of its sub-sampled
        // pixel (the one at the top-left of its s×s block) or, without one (no reading
        // there), the outlier label, one E-step for the final pose at the final outlier
        // distance; the expansion moves such pixels to a part where that is cheaper.
        let mut block_label = vec![-2i32; sub_cam.width * sub_cam.height];
        for (&px, &l) in sub_cloud.pixels.iter().zip(&em.labels) {
            block_label[px as usize] = l;
        }
        let w = self.camera.width;
        let init_labels: Vec<i32> = cloud
            .pixels
            .iter()
            .map(|&px| {
                let (r, c) = (px as usize / w, px as usize % w);
                match block_label[(r / s) * sub_cam.width + c / s] {
                    l if l < 0 => OUTLIER, // no sub-sampled point, or labelled outlier
                    l => l,
                }
            })
            .collect();
        let tau = config.em.outlier_distance_in(em.iterations, em.anneal_cut);
        // One expansion cycle: the start is already the sub-sampled EM's labelling.
        let final_em = EmConfig {
            expansion_cycles: 1,
            ..config.em
        };
        let at = UnaryAt {
            model,
            points: &cloud.points,
            weights: weights_of(&self.weights.full),
            pose: &em.pose,
            config: &final_em,
            tau,
        };
        let (final_labels, crf) = label_points(&at, graph, &init_labels)?;
        if config.full_resolution_iterations > 0 {
            // Coarse to fine: the EM goes on at full resolution from the strided pose and
            // this labelling (τ continues its annealing at the strided EM's count).
            let labels: Vec<i32> = final_labels
                .labels
                .iter()
                .map(|&l| if l < 0 { OUTLIER } else { l })
                .collect();
            let fine_config = EmConfig {
                max_iterations: em.iterations + config.full_resolution_iterations,
                ..config.em
            };
            let free_space = self.free_space_image();
            let resume = EmResume {
                labels: &labels,
                iterations: em.iterations,
                anneal_cut: em.anneal_cut,
            };
            let options = EmOptions {
                resume: Some(resume),
                prior,
                free_space,
                point_weights: weights_of(&self.weights.full),
            };
            let fine = hard_em_from(model, &cloud.points, graph, &em.pose, options, &fine_config)?;
            // The fine stage is a bounded refinement: spending its budget says nothing
            // about the EM's convergence, which the strided stage reports.
            let termination = match fine.termination {
                EmTermination::MaxIterations => em.termination,
                t => t,
            };
            let labels = label_image(cloud, &fine.labels);
            return Ok(FitResult {
                termination,
                ..FitResult::from_em(model, fine, labels)
            });
        }
        // The full-resolution labelling's energy and counts replace the EM's.
        let free_space = self.free_space_image().map(|f| {
            let cost = config.em.free_space_cost(1.0);
            FreeSpaceTerm::new(model, f.depth, f.camera, cost).cost(&em.pose)
        });
        let energy = crf + prior.map_or(0.0, |p| p.cost(&em.pose)) + free_space.unwrap_or(0.0);
        let labels = label_image(cloud, &final_labels.labels);
        Ok(FitResult {
            energy,
            part_counts: final_labels.part_counts,
            outliers: final_labels.outliers,
            ..FitResult::from_em(model, em, labels)
        })
    }
}

/// Fits `model` to the foreground of `depth` (H×W metres, row-major; `mask` selects the
/// person's pixels, None = every reading) starting from `init_pose`, with an optional
/// prior toward a pose. Runs on a worker of rayon's pool ([`crate::pool::on_worker`]).
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
    crate::pool::on_worker(|| {
        FitProblem::new(depth, camera, mask, config)?.fit(model, &init, prior)
    })
}

#[cfg(test)]
mod tests;
