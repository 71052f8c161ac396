//! Model fitting for Python: `FitConfig`, `FitResult`, `fit_pose`, `pose_from_joints`.

use super::arrays::{bool_array, depth_array, f64_array, to_numpy};
use super::body::{pose_arg, poses_arg, PyBodyModel};
use super::camera::PyCamera;
use super::native;
use crate::body::{
    BodyModel, NUM_JOINTS, NUM_PARAMS, NUM_SEGMENTS, NUM_SHAPE_FACTORS, PART_NAMES,
    SHAPE_FACTOR_NAMES,
};
use crate::cloud::Connectivity;
use crate::error::Error;
use crate::fit::{self, EmConfig, FitConfig, Loss, PosePrior, MAX_STRIDE};
use nalgebra::Vector3;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
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
        let loss = match self.loss.as_str() {
            "squared" => Loss::Squared,
            "huber" => Loss::Huber(self.loss_scale),
            "cauchy" => Loss::Cauchy(self.loss_scale),
            other => {
                return Err(Error::invalid(
                    "loss",
                    format!("must be 'squared', 'huber' or 'cauchy', got {other:?}"),
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
        };
        cfg.validate()?;
        Ok(cfg)
    }
}

const DEFAULT_LOSS_SCALE: f64 = 0.03;

#[pymethods]
impl PyFitConfig {
    /// All keyword arguments; defaults are the Rust defaults. Invalid values raise
    /// `InvalidInputError` naming the field.
    #[new]
    #[pyo3(signature = (*, sigma=None, loss="squared", loss_scale=DEFAULT_LOSS_SCALE, potts=None,
        contrast_weight=None, contrast_sigma=None, outlier_distance=None,
        outlier_distance_start=None, anneal_iterations=None, adaptive_anneal=None,
        settled_joint_motion=None, truncation_factor=None,
        max_iterations=None, label_change_tolerance=None, energy_tolerance=None,
        expansion_cycles=None, free_space_weight=None, free_space_margin=None,
        free_space_truncation=None, lm_max_iterations=None, connectivity=4, stride=1,
        label_all_pixels=true, full_resolution_iterations=0, recentred_start=true,
        swapped_limb_starts=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        sigma: Option<f64>,
        loss: &str,
        loss_scale: f64,
        potts: Option<f64>,
        contrast_weight: Option<f64>,
        contrast_sigma: Option<f64>,
        outlier_distance: Option<f64>,
        outlier_distance_start: Option<f64>,
        anneal_iterations: Option<i128>,
        adaptive_anneal: Option<bool>,
        settled_joint_motion: Option<f64>,
        truncation_factor: Option<f64>,
        max_iterations: Option<i128>,
        label_change_tolerance: Option<f64>,
        energy_tolerance: Option<f64>,
        expansion_cycles: Option<i128>,
        free_space_weight: Option<f64>,
        free_space_margin: Option<f64>,
        free_space_truncation: Option<f64>,
        lm_max_iterations: Option<i128>,
        connectivity: i128,
        stride: i128,
        label_all_pixels: bool,
        full_resolution_iterations: i128,
        recentred_start: bool,
        swapped_limb_starts: bool,
    ) -> PyResult<Self> {
        let d = EmConfig::default();
        let count = |v: Option<i128>, default: usize, name: &str| -> PyResult<usize> {
            Ok(super::arrays::count_opt(v, name)?.unwrap_or(default))
        };
        let cfg = PyFitConfig {
            sigma: sigma.unwrap_or(d.sigma),
            loss: loss.to_string(),
            loss_scale,
            potts: potts.unwrap_or(d.potts),
            contrast_weight: contrast_weight.unwrap_or(d.contrast_weight),
            contrast_sigma: contrast_sigma.unwrap_or(d.contrast_sigma),
            outlier_distance: outlier_distance.unwrap_or(d.outlier_distance),
            outlier_distance_start: outlier_distance_start.unwrap_or(d.outlier_distance_start),
            anneal_iterations: count(anneal_iterations, d.anneal_iterations, "anneal_iterations")?,
            adaptive_anneal: adaptive_anneal.unwrap_or(d.adaptive_anneal),
            settled_joint_motion: settled_joint_motion.unwrap_or(d.settled_joint_motion),
            truncation_factor: truncation_factor.unwrap_or(d.truncation_factor),
            max_iterations: count(max_iterations, d.max_iterations, "max_iterations")?,
            label_change_tolerance: label_change_tolerance.unwrap_or(d.label_change_tolerance),
            energy_tolerance: energy_tolerance.unwrap_or(d.energy_tolerance),
            expansion_cycles: count(expansion_cycles, d.expansion_cycles, "expansion_cycles")?,
            free_space_weight: free_space_weight.unwrap_or(d.free_space_weight),
            free_space_margin: free_space_margin.unwrap_or(d.free_space_margin),
            free_space_truncation: free_space_truncation.unwrap_or(d.free_space_truncation),
            lm_max_iterations: count(lm_max_iterations, d.lm.max_iterations, "lm_max_iterations")?,
            connectivity: super::arrays::connectivity(connectivity)?.neighbours(),
            stride: usize::try_from(stride)
                .ok()
                .filter(|s| (1..=MAX_STRIDE).contains(s))
                .ok_or_else(|| {
                    Error::invalid("stride", format!("must be 1..={MAX_STRIDE}, got {stride}"))
                })?,
            label_all_pixels,
            full_resolution_iterations: count(
                Some(full_resolution_iterations),
                0,
                "full_resolution_iterations",
            )?,
            recentred_start,
            swapped_limb_starts,
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
    fn pose<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        to_numpy(py, self.result.pose.to_vec(), &[NUM_PARAMS])
    }
    /// The 15 joints (15, 3), camera frame, ITOP order.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        let v = self
            .result
            .joints
            .iter()
            .flat_map(|j| [j.x, j.y, j.z])
            .collect();
        to_numpy(py, v, &[NUM_JOINTS, 3])
    }
    /// Part labels (H, W) int16: segment 0..15, −1 = background or outlier.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<i16>> {
        to_numpy(py, self.result.labels.clone(), &[self.height, self.width])
    }
    #[getter]
    fn energy(&self) -> f64 {
        self.result.energy
    }
    #[getter]
    fn energy_trace<'py>(&self, py: Python<'py>) -> F64Array<'py> {
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

/// Outcome of `BodyModel.fit_shape`: the calibrated model, its shape factors and the
/// fitted poses of the calibration frames.
#[pyclass(name = "ShapeFitResult", module = "depthpose._core")]
pub struct PyShapeFitResult {
    pub(crate) result: fit::ShapeResult,
    pub(crate) height: usize,
    pub(crate) width: usize,
}

#[pymethods]
impl PyShapeFitResult {
    /// The base model with the fitted shape.
    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.result.model.clone(),
        }
    }
    /// The shape factors (12,) relative to the base model, `factor_names` order.
    #[getter]
    fn factors<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        to_numpy(py, self.result.factors.to_vec(), &[NUM_SHAPE_FACTORS])
    }
    /// Names of the shape factors.
    #[getter]
    fn factor_names(&self) -> Vec<&'static str> {
        SHAPE_FACTOR_NAMES.to_vec()
    }
    /// The factors as a {name: value} dict.
    fn factors_dict(&self) -> HashMap<&'static str, f64> {
        SHAPE_FACTOR_NAMES
            .iter()
            .copied()
            .zip(self.result.factors)
            .collect()
    }
    /// The fitted pose of every frame (F, 22).
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        let n = self.result.poses.len();
        let v = self.result.poses.iter().flatten().copied().collect();
        to_numpy(py, v, &[n, NUM_PARAMS])
    }
    /// The joints of every frame (F, 15, 3) with the fitted model, camera frame.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        let n = self.result.joints.len();
        let v = self
            .result
            .joints
            .iter()
            .flatten()
            .flat_map(|j| [j.x, j.y, j.z])
            .collect();
        to_numpy(py, v, &[n, NUM_JOINTS, 3])
    }
    /// Part labels of every frame (F, H, W) int16: segment 0..15, −1 = background or
    /// outlier.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<i16>> {
        let n = self.result.labels.len();
        let v = self.result.labels.iter().flatten().copied().collect();
        to_numpy(py, v, &[n, self.height, self.width])
    }
    /// The final energy (sum over the frames plus the shape prior).
    #[getter]
    fn energy(&self) -> f64 {
        self.result.energy
    }
    /// The energy after every pose/label step and every shape step (non-increasing).
    #[getter]
    fn energy_trace<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        let n = self.result.energy_trace.len();
        to_numpy(py, self.result.energy_trace.clone(), &[n])
    }
    /// Rounds of pose/label step + shape step run.
    #[getter]
    fn rounds(&self) -> usize {
        self.result.rounds
    }
    fn __repr__(&self) -> String {
        let f: Vec<String> = SHAPE_FACTOR_NAMES
            .iter()
            .zip(self.result.factors)
            .map(|(n, v)| format!("{n}={v:.3}"))
            .collect();
        format!(
            "ShapeFitResult(frames={}, energy={:.4}, rounds={}, {})",
            self.result.poses.len(),
            self.result.energy,
            self.result.rounds,
            f.join(", ")
        )
    }
}

/// The arguments `fit_pose` and `fit_poses` share, checked.
struct FitArgs {
    depth: Vec<f32>,
    height: usize,
    width: usize,
    mask: Option<Vec<bool>>,
    config: FitConfig,
    prior: Option<PosePrior>,
    model: BodyModel,
}

impl FitArgs {
    fn parse(
        depth: &Bound<'_, PyAny>,
        camera: &PyCamera,
        model: Option<&PyBodyModel>,
        mask: Option<&Bound<'_, PyAny>>,
        config: Option<&PyFitConfig>,
        prior: Option<&Bound<'_, PyAny>>,
        prior_weight: f64,
    ) -> PyResult<Self> {
        let d = depth_array(depth, "depth")?;
        let (height, width) = (d.shape[0], d.shape[1]);
        camera.inner.check_image("depth", height, width)?;
        let mask = mask
            .map(|m| bool_array(m, "mask", &[height, width]))
            .transpose()?;
        let config = match config {
            Some(c) => c.to_rust()?,
            None => FitConfig::default(),
        };
        let prior = match prior {
            Some(p) => {
                let prior = pose_arg(p, "prior")?;
                if !(prior_weight.is_finite() && prior_weight >= 0.0) {
                    return Err(Error::invalid(
                        "prior_weight",
                        format!("must be finite and >= 0, got {prior_weight}"),
                    )
                    .into());
                }
                Some(PosePrior::uniform(prior, prior_weight, prior_weight))
            }
            None => None,
        };
        Ok(FitArgs {
            depth: d.data,
            height,
            width,
            mask,
            config,
            prior,
            model: model.map_or_else(BodyModel::default, |m| m.inner.clone()),
        })
    }

    fn result(&self, result: fit::FitResult) -> PyFitResult {
        PyFitResult {
            result,
            height: self.height,
            width: self.width,
        }
    }
}

/// Fits the body to the depth image from `init_pose` (hard EM: CRF labels + LM);
/// with `resume` (an earlier result on this image) the EM continues from its labels
/// and iteration count.
#[pyfunction]
#[pyo3(signature = (depth, camera, init_pose, *, model=None, mask=None, config=None, prior=None, prior_weight=100.0, resume=None))]
#[allow(clippy::too_many_arguments)]
fn fit_pose(
    py: Python<'_>,
    depth: &Bound<'_, PyAny>,
    camera: &PyCamera,
    init_pose: &Bound<'_, PyAny>,
    model: Option<&PyBodyModel>,
    mask: Option<&Bound<'_, PyAny>>,
    config: Option<&PyFitConfig>,
    prior: Option<&Bound<'_, PyAny>>,
    prior_weight: f64,
    resume: Option<PyRef<'_, PyFitResult>>,
) -> PyResult<PyFitResult> {
    let args = FitArgs::parse(depth, camera, model, mask, config, prior, prior_weight)?;
    let init = pose_arg(init_pose, "init_pose")?;
    let cam = camera.inner;
    let resume = resume.as_ref().map(|r| &r.result);
    let result = native(py, || {
        fit::FitProblem::new(&args.depth, &cam, args.mask.as_deref(), &args.config)?.fit_from(
            &args.model,
            &init,
            resume,
            args.prior.as_ref(),
        )
    })?;
    Ok(args.result(result))
}

/// `fit_pose` from each row of `init_poses` (K, 22) on the same image, in parallel
/// (with `resume`, K earlier results, each continued); a list of K results, each
/// identical to its own `fit_pose` call.
#[pyfunction]
#[pyo3(signature = (depth, camera, init_poses, *, model=None, mask=None, config=None, prior=None, prior_weight=100.0, resume=None))]
#[allow(clippy::too_many_arguments)]
fn fit_poses(
    py: Python<'_>,
    depth: &Bound<'_, PyAny>,
    camera: &PyCamera,
    init_poses: &Bound<'_, PyAny>,
    model: Option<&PyBodyModel>,
    mask: Option<&Bound<'_, PyAny>>,
    config: Option<&PyFitConfig>,
    prior: Option<&Bound<'_, PyAny>>,
    prior_weight: f64,
    resume: Option<Vec<PyRef<'_, PyFitResult>>>,
) -> PyResult<Vec<PyFitResult>> {
    let args = FitArgs::parse(depth, camera, model, mask, config, prior, prior_weight)?;
    let inits = poses_arg(init_poses, "init_poses")?;
    let cam = camera.inner;
    let resume: Option<Vec<&fit::FitResult>> = resume
        .as_ref()
        .map(|r| r.iter().map(|x| &x.result).collect());
    let results = native(py, || {
        fit::fit_poses(
            &args.depth,
            &cam,
            &inits,
            resume.as_deref(),
            &args.model,
            args.mask.as_deref(),
            args.prior.as_ref(),
            &args.config,
        )
    })?;
    Ok(results.into_iter().map(|r| args.result(r)).collect())
}

/// `result` (a fit of this image with `config`, made with `label_all_pixels` off)
/// labelled at every pixel, as the fit with `label_all_pixels` on would have been.
#[pyfunction]
#[pyo3(signature = (depth, camera, result, *, model=None, mask=None, config=None, prior=None, prior_weight=100.0))]
#[allow(clippy::too_many_arguments)]
fn label_all_pixels(
    py: Python<'_>,
    depth: &Bound<'_, PyAny>,
    camera: &PyCamera,
    result: PyRef<'_, PyFitResult>,
    model: Option<&PyBodyModel>,
    mask: Option<&Bound<'_, PyAny>>,
    config: Option<&PyFitConfig>,
    prior: Option<&Bound<'_, PyAny>>,
    prior_weight: f64,
) -> PyResult<PyFitResult> {
    let args = FitArgs::parse(depth, camera, model, mask, config, prior, prior_weight)?;
    let cam = camera.inner;
    let fit = &result.result;
    let labelled = native(py, || {
        fit::FitProblem::new(&args.depth, &cam, args.mask.as_deref(), &args.config)?.label_all(
            &args.model,
            fit,
            args.prior.as_ref(),
        )
    })?;
    Ok(args.result(labelled))
}

/// The pose (22,) whose joints best match `joints` (15, 3) (NaN rows are skipped).
#[pyfunction]
#[pyo3(signature = (joints, model=None, init=None))]
fn pose_from_joints<'py>(
    py: Python<'py>,
    joints: &Bound<'py, PyAny>,
    model: Option<&PyBodyModel>,
    init: Option<&Bound<'py, PyAny>>,
) -> PyResult<F64Array<'py>> {
    let a = f64_array(joints, "joints", Some(2), false)?;
    if a.shape != [NUM_JOINTS, 3] {
        return Err(Error::invalid(
            "joints",
            format!("expected shape ({NUM_JOINTS}, 3), got {:?}", a.shape),
        )
        .into());
    }
    if let Some(i) = a.data.iter().position(|v| v.is_infinite()) {
        return Err(Error::invalid("joints", format!("infinite value at flat index {i}")).into());
    }
    let init = init.map(|p| pose_arg(p, "init")).transpose()?;
    let j: [Vector3<f64>; NUM_JOINTS] =
        std::array::from_fn(|k| Vector3::new(a.data[3 * k], a.data[3 * k + 1], a.data[3 * k + 2]));
    let model = model.map_or_else(BodyModel::default, |m| m.inner.clone());
    let pose = native(py, || fit::pose_from_joints(&model, &j, init.as_ref()))?;
    Ok(to_numpy(py, pose.to_vec(), &[NUM_PARAMS]))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyFitConfig>()?;
    m.add_class::<PyFitResult>()?;
    m.add_class::<PyShapeFitResult>()?;
    m.add_function(wrap_pyfunction!(fit_pose, m)?)?;
    m.add_function(wrap_pyfunction!(fit_poses, m)?)?;
    m.add_function(wrap_pyfunction!(label_all_pixels, m)?)?;
    m.add_function(wrap_pyfunction!(pose_from_joints, m)?)?;
    Ok(())
}
