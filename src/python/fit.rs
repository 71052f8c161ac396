//! Model fitting for Python: `FitConfig`, `FitResult`, `fit_pose`, `pose_from_joints`.

use super::body::{pose_arg, poses_arg};
use super::convert::{
    array_like, body_model, bool_array, camera as camera_arg, check_fit_points, depth_array,
    f64_array, fit_config, invalid, joints_to_numpy, object, to_numpy, wrong_type, Flag, Int, Real,
    Text,
};
use super::keywords::keywords;
use super::native;
use crate::body::{BodyModel, NUM_JOINTS, NUM_PARAMS, NUM_SEGMENTS, PART_NAMES};
use crate::camera::Camera;
use crate::cloud::Connectivity;
use crate::error::{brief, Error};
use crate::fit::{self, EmConfig, FitConfig, Loss, PosePrior, MAX_STRIDE};
use nalgebra::Vector3;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::HashMap;

/// Settings of `fit_pose` (see the Rust docs of `depthpose::fit::em::EmConfig`).
#[pyclass(name = "FitConfig", module = "depthpose._core", get_all, eq)]
#[derive(Clone, PartialEq)]
pub struct PyFitConfig {
    sigma: f64,
    loss: String,
    loss_scale: f64,
    potts: f64,
    contrast_weight: f64,
    contrast_sigma: f64,
    outlier_distance: f64,
    outlier_distance_start: f64,
    anneal_iterations: usize,
    adaptive_anneal: bool,
    settled_joint_motion: f64,
    truncation_factor: f64,
    max_iterations: usize,
    label_change_tolerance: f64,
    energy_tolerance: f64,
    expansion_cycles: usize,
    free_space_weight: f64,
    free_space_margin: f64,
    free_space_truncation: f64,
    lm_max_iterations: usize,
    connectivity: u32,
    stride: usize,
    label_all_pixels: bool,
    full_resolution_iterations: usize,
    recentred_start: bool,
    swapped_limb_starts: bool,
}

impl PyFitConfig {
    /// The Python view of a Rust config.
    pub(crate) fn from_rust(c: &FitConfig) -> Self {
        let (loss, loss_scale) = match c.em.loss {
            Loss::Squared => ("squared", DEFAULT_LOSS_SCALE),
            Loss::Huber(s) => ("huber", s),
            Loss::Cauchy(s) => ("cauchy", s),
        };
        let e = &c.em;
        PyFitConfig {
            sigma: e.sigma,
            loss: loss.to_string(),
            loss_scale,
            potts: e.potts,
            contrast_weight: e.contrast_weight,
            contrast_sigma: e.contrast_sigma,
            outlier_distance: e.outlier_distance,
            outlier_distance_start: e.outlier_distance_start,
            anneal_iterations: e.anneal_iterations,
            adaptive_anneal: e.adaptive_anneal,
            settled_joint_motion: e.settled_joint_motion,
            truncation_factor: e.truncation_factor,
            max_iterations: e.max_iterations,
            label_change_tolerance: e.label_change_tolerance,
            energy_tolerance: e.energy_tolerance,
            expansion_cycles: e.expansion_cycles,
            free_space_weight: e.free_space_weight,
            free_space_margin: e.free_space_margin,
            free_space_truncation: e.free_space_truncation,
            lm_max_iterations: e.lm.max_iterations,
            connectivity: c.connectivity.neighbours(),
            stride: c.stride,
            label_all_pixels: c.label_all_pixels,
            full_resolution_iterations: c.full_resolution_iterations,
            recentred_start: c.recentred_start,
            swapped_limb_starts: c.swapped_limb_starts,
        }
    }

    pub(crate) fn to_rust(&self) -> crate::Result<FitConfig> {
        self.check_magnitudes()?;
        let loss = match self.loss.as_str() {
            "squared" => Loss::Squared,
            "huber" => Loss::Huber(self.loss_scale),
            "cauchy" => Loss::Cauchy(self.loss_scale),
            other => {
                return Err(Error::invalid(
                    "loss",
                    format!(
                        "must be 'squared', 'huber' or 'cauchy', got {}",
                        crate::error::brief_text(other)
                    ),
                ))
            }
        };
        let d = EmConfig::default();
        let em = EmConfig {
            sigma: self.sigma,
            loss,
            potts: self.potts,
            contrast_weight: self.contrast_weight,
            contrast_sigma: self.contrast_sigma,
            outlier_distance: self.outlier_distance,
            outlier_distance_start: self.outlier_distance_start,
            anneal_iterations: self.anneal_iterations,
            adaptive_anneal: self.adaptive_anneal,
            settled_joint_motion: self.settled_joint_motion,
            truncation_factor: self.truncation_factor,
            max_iterations: self.max_iterations,
            label_change_tolerance: self.label_change_tolerance,
            energy_tolerance: self.energy_tolerance,
            expansion_cycles: self.expansion_cycles,
            free_space_weight: self.free_space_weight,
            free_space_margin: self.free_space_margin,
            free_space_truncation: self.free_space_truncation,
            lm: fit::LmConfig {
                max_iterations: self.lm_max_iterations,
                ..d.lm
            },
        };
        if !(self.loss_scale.is_finite() && self.loss_scale > 0.0) {
            return Err(Error::invalid(
                "loss_scale",
                format!("must be finite and > 0, got {}", self.loss_scale),
            ));
        }
        em.validate().map_err(|e| match e {
            Error::InvalidArgument { name, message } if name == "max_iterations" => {
                Error::invalid("lm_max_iterations", message)
            }
            other => other,
        })?;
        let cfg = FitConfig {
            em,
            connectivity: Connectivity::from_int(self.connectivity)?,
            stride: self.stride,
            label_all_pixels: self.label_all_pixels,
            full_resolution_iterations: self.full_resolution_iterations,
            recentred_start: self.recentred_start,
            swapped_limb_starts: self.swapped_limb_starts,
            // Set by the stereo pipeline from its rig (`disparity_sigma`, `weigh_points`).
            depth_noise: None,
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// Refuses values so large (or lengths so small) that the fit's sums would
    /// overflow or its loops run without end: lengths within [`MIN_LENGTH`,
    /// `MAX_LENGTH`] metres, weights and factors up to [`MAX_WEIGHT`], iteration counts
    /// up to [`MAX_ITERATIONS`]. The finer checks are `EmConfig::validate`'s.
    fn check_magnitudes(&self) -> crate::Result<()> {
        for (v, name) in [
            (self.sigma, "sigma"),
            (self.loss_scale, "loss_scale"),
            (self.contrast_sigma, "contrast_sigma"),
            (self.outlier_distance, "outlier_distance"),
            (self.outlier_distance_start, "outlier_distance_start"),
            (self.free_space_truncation, "free_space_truncation"),
        ] {
            if v.is_finite() && v > 0.0 && !(MIN_LENGTH..=MAX_LENGTH).contains(&v) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "must be in [{}, {}] metres, got {}",
                        brief(MIN_LENGTH),
                        brief(MAX_LENGTH),
                        brief(v)
                    ),
                ));
            }
        }
        for (v, name, max) in [
            (self.free_space_margin, "free_space_margin", MAX_LENGTH),
            (
                self.settled_joint_motion,
                "settled_joint_motion",
                MAX_LENGTH,
            ),
            (self.potts, "potts", MAX_WEIGHT),
            (self.contrast_weight, "contrast_weight", MAX_WEIGHT),
            (self.free_space_weight, "free_space_weight", MAX_WEIGHT),
            (self.truncation_factor, "truncation_factor", MAX_WEIGHT),
        ] {
            if v.is_finite() && v > max {
                return Err(Error::invalid(
                    name,
                    format!("must be at most {}, got {}", brief(max), brief(v)),
                ));
            }
        }
        for (v, name) in [
            (self.anneal_iterations, "anneal_iterations"),
            (self.max_iterations, "max_iterations"),
            (self.expansion_cycles, "expansion_cycles"),
            (self.lm_max_iterations, "lm_max_iterations"),
            (
                self.full_resolution_iterations,
                "full_resolution_iterations",
            ),
        ] {
            if v > MAX_ITERATIONS {
                return Err(Error::invalid(
                    name,
                    format!("must be at most {MAX_ITERATIONS}, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

const DEFAULT_LOSS_SCALE: f64 = 0.03;
/// Smallest length setting (metres) of `FitConfig`.
const MIN_LENGTH: f64 = 1e-6;
/// Largest length setting (metres) of `FitConfig`.
const MAX_LENGTH: f64 = 1e3;
/// Largest weight or factor of `FitConfig`.
const MAX_WEIGHT: f64 = 1e9;
/// Largest iteration count of `FitConfig`.
const MAX_ITERATIONS: usize = 100_000;

keywords! {
    /// The keyword arguments of `FitConfig(...)`: None (or absent) takes the Rust
    /// default.
    struct FitConfigKeywords {
        sigma: Option<Real> = None,
        loss: Option<Text> = None,
        loss_scale: Real = Real::new(DEFAULT_LOSS_SCALE),
        potts: Option<Real> = None,
        contrast_weight: Option<Real> = None,
        contrast_sigma: Option<Real> = None,
        outlier_distance: Option<Real> = None,
        outlier_distance_start: Option<Real> = None,
        anneal_iterations: Option<Int> = None,
        adaptive_anneal: Option<Flag> = None,
        settled_joint_motion: Option<Real> = None,
        truncation_factor: Option<Real> = None,
        max_iterations: Option<Int> = None,
        label_change_tolerance: Option<Real> = None,
        energy_tolerance: Option<Real> = None,
        expansion_cycles: Option<Int> = None,
        free_space_weight: Option<Real> = None,
        free_space_margin: Option<Real> = None,
        free_space_truncation: Option<Real> = None,
        lm_max_iterations: Option<Int> = None,
        connectivity: Int = Int::new(4),
        stride: Int = Int::new(1),
        label_all_pixels: Flag = Flag::new(true),
        full_resolution_iterations: Int = Int::new(0),
        recentred_start: Flag = Flag::new(true),
        swapped_limb_starts: Flag = Flag::new(false),
    }
}

#[pymethods]
impl PyFitConfig {
    /// All keyword arguments; defaults are the Rust defaults. Invalid values raise
    /// `InvalidInputError` naming the field.
    #[new]
    #[pyo3(signature = (**kwargs), text_signature = "(*, sigma=None, loss='squared', \
        loss_scale=0.03, potts=None, contrast_weight=None, contrast_sigma=None, \
        outlier_distance=None, outlier_distance_start=None, anneal_iterations=None, \
        adaptive_anneal=None, settled_joint_motion=None, truncation_factor=None, \
        max_iterations=None, label_change_tolerance=None, energy_tolerance=None, \
        expansion_cycles=None, free_space_weight=None, free_space_margin=None, \
        free_space_truncation=None, lm_max_iterations=None, connectivity=4, stride=1, \
        label_all_pixels=True, full_resolution_iterations=0, recentred_start=True, \
        swapped_limb_starts=False)")]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let FitConfigKeywords {
            sigma,
            loss,
            loss_scale,
            potts,
            contrast_weight,
            contrast_sigma,
            outlier_distance,
            outlier_distance_start,
            anneal_iterations,
            adaptive_anneal,
            settled_joint_motion,
            truncation_factor,
            max_iterations,
            label_change_tolerance,
            energy_tolerance,
            expansion_cycles,
            free_space_weight,
            free_space_margin,
            free_space_truncation,
            lm_max_iterations,
            connectivity,
            stride,
            label_all_pixels,
            full_resolution_iterations,
            recentred_start,
            swapped_limb_starts,
        } = FitConfigKeywords::parse("FitConfig.__new__", kwargs)?;
        let d = EmConfig::default();
        let count = |v: Option<Int>, default: usize, name: &str| -> PyResult<usize> {
            v.map_or(Ok(default), |v| v.count(name))
        };
        let real = |v: Option<Real>, default: f64, name: &str| -> PyResult<f64> {
            v.map_or(Ok(default), |v| v.get(name))
        };
        let flag = |v: Option<Flag>, default: bool, name: &str| -> PyResult<bool> {
            v.map_or(Ok(default), |v| v.get(name))
        };
        let cfg = PyFitConfig {
            sigma: real(sigma, d.sigma, "sigma")?,
            loss: match &loss {
                Some(l) => l.get("loss")?.to_string(),
                None => "squared".to_string(),
            },
            loss_scale: loss_scale.get("loss_scale")?,
            potts: real(potts, d.potts, "potts")?,
            contrast_weight: real(contrast_weight, d.contrast_weight, "contrast_weight")?,
            contrast_sigma: real(contrast_sigma, d.contrast_sigma, "contrast_sigma")?,
            outlier_distance: real(outlier_distance, d.outlier_distance, "outlier_distance")?,
            outlier_distance_start: real(
                outlier_distance_start,
                d.outlier_distance_start,
                "outlier_distance_start",
            )?,
            anneal_iterations: count(anneal_iterations, d.anneal_iterations, "anneal_iterations")?,
            adaptive_anneal: flag(adaptive_anneal, d.adaptive_anneal, "adaptive_anneal")?,
            settled_joint_motion: real(
                settled_joint_motion,
                d.settled_joint_motion,
                "settled_joint_motion",
            )?,
            truncation_factor: real(truncation_factor, d.truncation_factor, "truncation_factor")?,
            max_iterations: count(max_iterations, d.max_iterations, "max_iterations")?,
            label_change_tolerance: real(
                label_change_tolerance,
                d.label_change_tolerance,
                "label_change_tolerance",
            )?,
            energy_tolerance: real(energy_tolerance, d.energy_tolerance, "energy_tolerance")?,
            expansion_cycles: count(expansion_cycles, d.expansion_cycles, "expansion_cycles")?,
            free_space_weight: real(free_space_weight, d.free_space_weight, "free_space_weight")?,
            free_space_margin: real(free_space_margin, d.free_space_margin, "free_space_margin")?,
            free_space_truncation: real(
                free_space_truncation,
                d.free_space_truncation,
                "free_space_truncation",
            )?,
            lm_max_iterations: count(lm_max_iterations, d.lm.max_iterations, "lm_max_iterations")?,
            connectivity: super::convert::connectivity(&connectivity)?.neighbours(),
            stride: stride.in_range(1, MAX_STRIDE as i128, "stride")? as usize,
            label_all_pixels: label_all_pixels.get("label_all_pixels")?,
            full_resolution_iterations: full_resolution_iterations
                .count("full_resolution_iterations")?,
            recentred_start: recentred_start.get("recentred_start")?,
            swapped_limb_starts: swapped_limb_starts.get("swapped_limb_starts")?,
        };
        cfg.to_rust()?;
        Ok(cfg)
    }

    fn __repr__(&self) -> String {
        format!(
            "FitConfig(sigma={}, loss={:?}, potts={}, contrast_weight={}, outlier_distance={}, max_iterations={}, stride={}, label_all_pixels={}, full_resolution_iterations={}, recentred_start={}, swapped_limb_starts={})",
            self.sigma, self.loss, self.potts, self.contrast_weight, self.outlier_distance,
            self.max_iterations, self.stride, if self.label_all_pixels { "True" } else { "False" },
            self.full_resolution_iterations,
            if self.recentred_start { "True" } else { "False" },
            if self.swapped_limb_starts { "True" } else { "False" }
        )
    }
}

type F64Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Outcome of `fit_pose`.
#[pyclass(name = "FitResult", module = "depthpose._core")]
pub struct PyFitResult {
    result: fit::FitResult,
    height: usize,
    width: usize,
}

#[pymethods]
impl PyFitResult {
    /// The fitted pose (22,).
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, self.result.pose.to_vec(), &[NUM_PARAMS])
    }
    /// The 15 joints (15, 3), camera frame, ITOP order.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        joints_to_numpy(py, &self.result.joints, &[NUM_JOINTS, 3])
    }
    /// Part labels (H, W) int16: segment 0..15, −1 = background or outlier.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i16>>> {
        to_numpy(py, self.result.labels.clone(), &[self.height, self.width])
    }
    #[getter]
    fn energy(&self) -> f64 {
        self.result.energy
    }
    #[getter]
    fn energy_trace<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let n = self.result.energy_trace.len();
        to_numpy(py, self.result.energy_trace.clone(), &[n])
    }
    #[getter]
    fn iterations(&self) -> usize {
        self.result.iterations
    }
    #[getter]
    fn converged(&self) -> bool {
        self.result.converged()
    }
    /// Why the EM loop stopped: "converged", "stationary" or "max_iterations".
    #[getter]
    fn reason(&self) -> &'static str {
        self.result.termination.name()
    }
    /// The iteration after which the outlier distance jumped to its final value (the
    /// fit's labels and joints had settled while it was still annealing;
    /// `FitConfig.adaptive_anneal`), or None.
    #[getter]
    fn anneal_cut(&self) -> Option<usize> {
        self.result.anneal_cut
    }
    /// Points per part, keyed by part name.
    #[getter]
    fn part_counts(&self) -> HashMap<&'static str, usize> {
        (0..NUM_SEGMENTS)
            .map(|k| (PART_NAMES[k], self.result.part_counts[k]))
            .collect()
    }
    /// Foreground points labelled outlier.
    #[getter]
    fn outliers(&self) -> usize {
        self.result.outliers
    }
    fn __repr__(&self) -> String {
        format!(
            "FitResult(energy={:.4}, iterations={}, reason={:?})",
            self.result.energy,
            self.result.iterations,
            self.result.termination.name()
        )
    }
}

/// The arguments `fit_pose`, `fit_poses` and `label_all_pixels` share, checked.
struct FitArgs {
    depth: Vec<f32>,
    height: usize,
    width: usize,
    camera: Camera,
    mask: Option<Vec<bool>>,
    config: FitConfig,
    prior: Option<PosePrior>,
    model: BodyModel,
}

keywords! {
    /// The keyword arguments `fit_pose`, `fit_poses` and `label_all_pixels` share.
    struct FitOptions<'py> {
        model: Option<Bound<'py, PyAny>> = None,
        mask: Option<Bound<'py, PyAny>> = None,
        config: Option<Bound<'py, PyAny>> = None,
        prior: Option<Bound<'py, PyAny>> = None,
        prior_weight: Real = Real::new(100.0),
    }
}

impl FitArgs {
    fn parse(
        depth: &Bound<'_, PyAny>,
        camera: &Bound<'_, PyAny>,
        options: &FitOptions<'_>,
    ) -> PyResult<Self> {
        let camera = camera_arg(camera, "camera")?;
        let model = body_model(options.model.as_ref(), "model")?;
        let config = fit_config(options.config.as_ref(), "config")?;
        let prior_weight = options.prior_weight.get("prior_weight")?;
        let d = depth_array(depth, "depth")?;
        let (height, width) = (d.shape[0], d.shape[1]);
        camera.check_image("depth", height, width)?;
        let mask = options
            .mask
            .as_ref()
            .map(|m| bool_array(m, "mask", &[height, width]))
            .transpose()?;
        check_fit_points(&d.data, mask.as_deref(), 0, "depth")?;
        let prior = match &options.prior {
            Some(p) => {
                let prior = pose_arg(&array_like(p, "prior")?, "prior")?;
                if !(prior_weight.is_finite() && (0.0..=MAX_PRIOR_WEIGHT).contains(&prior_weight)) {
                    return Err(invalid(
                        "prior_weight",
                        format!(
                            "must be finite and in [0, {}], got {}",
                            brief(MAX_PRIOR_WEIGHT),
                            brief(prior_weight)
                        ),
                    ));
                }
                Some(PosePrior::uniform(prior, prior_weight, prior_weight))
            }
            None => None,
        };
        Ok(FitArgs {
            depth: d.data,
            height,
            width,
            camera,
            mask,
            config,
            prior,
            model,
        })
    }

    fn result(&self, result: fit::FitResult) -> PyFitResult {
        PyFitResult {
            result,
            height: self.height,
            width: self.width,
        }
    }

    /// Refuses an earlier result of an image of another size.
    fn check_same_image(&self, result: &PyFitResult, name: &str) -> PyResult<()> {
        if (result.height, result.width) != (self.height, self.width) {
            return Err(invalid(
                name,
                format!(
                    "is a result on a {}x{} image, but depth is {}x{} (a result can only \
                     resume or label the image it was fitted to)",
                    result.height, result.width, self.height, self.width
                ),
            ));
        }
        Ok(())
    }
}

/// Largest `prior_weight` (a weight per squared radian or metre).
const MAX_PRIOR_WEIGHT: f64 = 1e12;

fn fit_result<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<PyRef<'py, PyFitResult>> {
    object::<PyFitResult>(obj, name, "a depthpose.FitResult")
}

/// Fits the body to the depth image from `init_pose` (hard EM: CRF labels + LM);
/// with `resume` (an earlier result on this image) the EM continues from its labels
/// and iteration count.
#[pyfunction]
#[pyo3(signature = (depth, camera, init_pose, *, resume=None, **options),
       text_signature = "(depth, camera, init_pose, *, model=None, mask=None, config=None, \
                         prior=None, prior_weight=100.0, resume=None)")]
fn fit_pose<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    init_pose: &Bound<'py, PyAny>,
    resume: Option<&Bound<'py, PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<PyFitResult> {
    let options = FitOptions::parse("fit_pose", options)?;
    let args = FitArgs::parse(depth, camera, &options)?;
    let init = pose_arg(&array_like(init_pose, "init_pose")?, "init_pose")?;
    let resume = resume.map(|r| fit_result(r, "resume")).transpose()?;
    if let Some(r) = &resume {
        args.check_same_image(r, "resume")?;
    }
    let resume = resume.as_ref().map(|r| &r.result);
    let result = native(py, || {
        fit::FitProblem::new(
            &args.depth,
            &args.camera,
            args.mask.as_deref(),
            &args.config,
        )?
        .fit_from(&args.model, &init, resume, args.prior.as_ref())
    })?;
    Ok(args.result(result))
}

/// `fit_pose` from each row of `init_poses` (K, 22) on the same image, in parallel
/// (with `resume`, K earlier results, each continued); a list of K results, each
/// identical to its own `fit_pose` call.
#[pyfunction]
#[pyo3(signature = (depth, camera, init_poses, *, resume=None, **options),
       text_signature = "(depth, camera, init_poses, *, model=None, mask=None, config=None, \
                         prior=None, prior_weight=100.0, resume=None)")]
fn fit_poses<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    init_poses: &Bound<'py, PyAny>,
    resume: Option<&Bound<'py, PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Vec<PyFitResult>> {
    let options = FitOptions::parse("fit_poses", options)?;
    let args = FitArgs::parse(depth, camera, &options)?;
    let inits = poses_arg(&array_like(init_poses, "init_poses")?, "init_poses")?;
    if inits.len() > MAX_START_POSES {
        return Err(super::convert::too_large(
            "init_poses",
            format!("{} start poses; at most {MAX_START_POSES}", inits.len()),
        ));
    }
    let resume: Option<Vec<PyRef<PyFitResult>>> = match resume {
        None => None,
        Some(r) => {
            let Ok(items) = r.try_iter() else {
                return Err(wrong_type(
                    "resume",
                    "a list of depthpose.FitResult",
                    &r.get_type()
                        .name()
                        .map(|n| n.to_string())
                        .unwrap_or_default(),
                ));
            };
            let mut out = Vec::new();
            for (k, item) in items.enumerate() {
                if k >= MAX_START_POSES {
                    return Err(invalid("resume", "has more results than start poses"));
                }
                let item = item?;
                let res = fit_result(&item, &format!("resume[{k}]"))?;
                args.check_same_image(&res, &format!("resume[{k}]"))?;
                out.push(res);
            }
            Some(out)
        }
    };
    let resume: Option<Vec<&fit::FitResult>> = resume
        .as_ref()
        .map(|r| r.iter().map(|x| &x.result).collect());
    let results = native(py, || {
        fit::FitProblem::new(
            &args.depth,
            &args.camera,
            args.mask.as_deref(),
            &args.config,
        )?
        .fit_each(&args.model, &inits, resume.as_deref(), args.prior.as_ref())
    })?;
    Ok(results.into_iter().map(|r| args.result(r)).collect())
}

/// Most start poses of one `fit_poses` call.
const MAX_START_POSES: usize = 4096;

/// `result` (a fit of this image with `config`, made with `label_all_pixels` off)
/// labelled at every pixel, as the fit with `label_all_pixels` on would have been.
#[pyfunction]
#[pyo3(signature = (depth, camera, result, **options),
       text_signature = "(depth, camera, result, *, model=None, mask=None, config=None, \
                         prior=None, prior_weight=100.0)")]
fn label_all_pixels<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    result: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<PyFitResult> {
    let options = FitOptions::parse("label_all_pixels", options)?;
    let args = FitArgs::parse(depth, camera, &options)?;
    let result = fit_result(result, "result")?;
    args.check_same_image(&result, "result")?;
    let fit = &result.result;
    let labelled = native(py, || {
        fit::FitProblem::new(
            &args.depth,
            &args.camera,
            args.mask.as_deref(),
            &args.config,
        )?
        .label_all(&args.model, fit, args.prior.as_ref())
    })?;
    Ok(args.result(labelled))
}

/// The pose (22,) whose joints best match `joints` (15, 3) (NaN rows are skipped).
#[pyfunction]
#[pyo3(signature = (joints, model=None, init=None))]
fn pose_from_joints<'py>(
    py: Python<'py>,
    joints: &Bound<'py, PyAny>,
    model: Option<&Bound<'py, PyAny>>,
    init: Option<&Bound<'py, PyAny>>,
) -> PyResult<F64Array<'py>> {
    let model = body_model(model, "model")?;
    let a = f64_array(&array_like(joints, "joints")?, "joints", Some(2), false)?;
    if a.shape != [NUM_JOINTS, 3] {
        return Err(invalid(
            "joints",
            format!("expected shape ({NUM_JOINTS}, 3), got {:?}", a.shape),
        ));
    }
    if let Some(i) = a.data.iter().position(|v| v.is_infinite()) {
        return Err(invalid(
            "joints",
            format!("infinite value at flat index {i}"),
        ));
    }
    if let Some(i) = a.data.iter().position(|v| v.abs() > MAX_COORDINATE) {
        return Err(invalid(
            "joints",
            format!(
                "{} m at flat index {i} is beyond {} m from the camera",
                brief(a.data[i]),
                brief(MAX_COORDINATE)
            ),
        ));
    }
    let init = init
        .map(|p| pose_arg(&array_like(p, "init")?, "init"))
        .transpose()?;
    let j: [Vector3<f64>; NUM_JOINTS] =
        std::array::from_fn(|k| Vector3::new(a.data[3 * k], a.data[3 * k + 1], a.data[3 * k + 2]));
    let pose = native(py, || fit::pose_from_joints(&model, &j, init.as_ref()))?;
    to_numpy(py, pose.to_vec(), &[NUM_PARAMS])
}

/// Largest joint coordinate `pose_from_joints` takes (metres): beyond it the inverse
/// kinematics has nothing meaningful to fit.
const MAX_COORDINATE: f64 = 1e6;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyFitConfig>()?;
    m.add_class::<PyFitResult>()?;
    m.add_function(wrap_pyfunction!(fit_pose, m)?)?;
    m.add_function(wrap_pyfunction!(fit_poses, m)?)?;
    m.add_function(wrap_pyfunction!(label_all_pixels, m)?)?;
    m.add_function(wrap_pyfunction!(pose_from_joints, m)?)?;
    Ok(())
}
