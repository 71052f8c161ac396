//! The pipeline for Python: `PipelineConfig`, `PoseResult`, and the native estimator
//! and tracker that `depthpose.PoseEstimator` / `depthpose.PoseTracker` wrap. Each
//! `estimate` and `update` is one native call with the GIL released.

use super::body::{pose_arg, poses_arg, PyBodyModel};
use super::camera::PyCamera;
use super::convert::{
    bool_array, camera as camera_arg, depth_array, f64_array, object, to_numpy, Flag, Int, Real,
};
use super::fit::{PyFitConfig, PyShapeFitResult};
use super::native;
use super::segment::{PyCluster, PyPlane};
use super::templates::PyTemplateDatabase;
use crate::body::{pose_from_slice, BodyModel, Pose, JOINT_NAMES, NUM_JOINTS, NUM_PARAMS};
use crate::error::Error;
use crate::pipeline::{
    mirror_view as mirror, rest_pose_penalty as penalty, swap_limbs as swap, Estimator,
    PipelineConfig, PoseResult, Tracker,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

type F64Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Settings of the estimator and the tracker (see the Rust docs of
/// `depthpose::pipeline::PipelineConfig`); keyword arguments, defaults from Rust.
#[pyclass(name = "PipelineConfig", module = "depthpose._core", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyPipelineConfig {
    pub inner: PipelineConfig,
}

fn int_field(value: &Bound<PyAny>, name: &str) -> PyResult<usize> {
    value.extract::<Int>()?.count(name)
}

fn bool_field(value: &Bound<PyAny>, name: &str) -> PyResult<bool> {
    if !value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(Error::invalid(
            name,
            format!("expected True or False, got {}", short(value)),
        )
        .into());
    }
    value.extract()
}

fn real_field(value: &Bound<PyAny>, name: &str) -> PyResult<f64> {
    value.extract::<Real>()?.get(name)
}

/// A value for an error message, at most 60 characters.
fn short(value: &Bound<PyAny>) -> String {
    let s = value
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "?".into());
    if s.chars().count() > 60 {
        format!("{}…", s.chars().take(57).collect::<String>())
    } else {
        s
    }
}

#[pymethods]
impl PyPipelineConfig {
    #[new]
    #[pyo3(signature = (**kwargs))]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut c = PipelineConfig::default();
        if let Some(kw) = kwargs {
            for (key, value) in kw.iter() {
                let name: String = key.extract()?;
                let n = name.as_str();
                match n {
                    "candidates" => c.candidates = int_field(&value, n)?,
                    "hypotheses" => c.hypotheses = int_field(&value, n)?,
                    "back_views" => c.back_views = bool_field(&value, n)?,
                    "any_roll" => c.any_roll = bool_field(&value, n)?,
                    "limb_poses" => c.limb_poses = bool_field(&value, n)?,
                    "candidate_iterations" => c.candidate_iterations = int_field(&value, n)?,
                    "finals" => c.finals = int_field(&value, n)?,
                    "final_iterations" => {
                        c.final_iterations = if value.is_none() {
                            None
                        } else {
                            Some(int_field(&value, n)?)
                        }
                    }
                    "candidate_stride" => c.candidate_stride = int_field(&value, n)?,
                    "final_stride" => c.final_stride = int_field(&value, n)?,
                    "prior_weight" => c.prior_weight = real_field(&value, n)?,
                    "track_iterations" => c.track_iterations = int_field(&value, n)?,
                    "track_stride" => c.track_stride = int_field(&value, n)?,
                    "velocity_damping" => c.velocity_damping = real_field(&value, n)?,
                    "min_inlier_share" => c.min_inlier_share = real_field(&value, n)?,
                    "lost_ratio" => c.lost_ratio = real_field(&value, n)?,
                    "lost_discrepancy" => c.lost_discrepancy = real_field(&value, n)?,
                    "recheck_every" => c.recheck_every = int_field(&value, n)?,
                    "recheck_hypotheses" => c.recheck_hypotheses = int_field(&value, n)?,
                    "lost_hypotheses" => c.lost_hypotheses = int_field(&value, n)?,
                    "switch_margin" => c.switch_margin = real_field(&value, n)?,
                    "pose_prior_weight" => c.pose_prior_weight = real_field(&value, n)?,
                    "size_range" => c.size_range = real_field(&value, n)?,
                    "size_step" => c.size_step = real_field(&value, n)?,
                    "calibration_frames" => c.calibration_frames = int_field(&value, n)?,
                    "calibration_every" => c.calibration_every = int_field(&value, n)?,
                    "calibration_prior_weight" => {
                        c.calibration_prior_weight = real_field(&value, n)?
                    }
                    "calibration_rounds" => c.calibration_rounds = int_field(&value, n)?,
                    "learn_background" => c.learn_background = bool_field(&value, n)?,
                    "working_focal" => c.working_focal = real_field(&value, n)?,
                    "fit" => c.fit = fit_config_of(&value)?,
                    other => {
                        return Err(Error::invalid(
                            other,
                            "not a PipelineConfig setting (see help(depthpose.PipelineConfig))",
                        )
                        .into())
                    }
                }
            }
        }
        c.validate()?;
        Ok(PyPipelineConfig { inner: c })
    }

    /// This config with some settings changed (keyword arguments as for the
    /// constructor).
    #[pyo3(signature = (**kwargs))]
    fn replace(&self, py: Python<'_>, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let all = self.as_dict(py)?;
        if let Some(kw) = kwargs {
            all.update(kw.as_mapping())?;
        }
        Self::new(Some(&all))
    }

    /// Every setting by name (`fit` as a FitConfig).
    fn as_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = &self.inner;
        let d = PyDict::new(py);
        d.set_item("candidates", c.candidates)?;
        d.set_item("hypotheses", c.hypotheses)?;
        d.set_item("back_views", c.back_views)?;
        d.set_item("any_roll", c.any_roll)?;
        d.set_item("limb_poses", c.limb_poses)?;
        d.set_item("candidate_iterations", c.candidate_iterations)?;
        d.set_item("finals", c.finals)?;
        d.set_item("final_iterations", c.final_iterations)?;
        d.set_item("candidate_stride", c.candidate_stride)?;
        d.set_item("final_stride", c.final_stride)?;
        d.set_item("prior_weight", c.prior_weight)?;
        d.set_item("track_iterations", c.track_iterations)?;
        d.set_item("track_stride", c.track_stride)?;
        d.set_item("velocity_damping", c.velocity_damping)?;
        d.set_item("min_inlier_share", c.min_inlier_share)?;
        d.set_item("lost_ratio", c.lost_ratio)?;
        d.set_item("lost_discrepancy", c.lost_discrepancy)?;
        d.set_item("recheck_every", c.recheck_every)?;
        d.set_item("recheck_hypotheses", c.recheck_hypotheses)?;
        d.set_item("lost_hypotheses", c.lost_hypotheses)?;
        d.set_item("switch_margin", c.switch_margin)?;
        d.set_item("pose_prior_weight", c.pose_prior_weight)?;
        d.set_item("size_range", c.size_range)?;
        d.set_item("size_step", c.size_step)?;
        d.set_item("calibration_frames", c.calibration_frames)?;
        d.set_item("calibration_every", c.calibration_every)?;
        d.set_item("calibration_prior_weight", c.calibration_prior_weight)?;
        d.set_item("calibration_rounds", c.calibration_rounds)?;
        d.set_item("learn_background", c.learn_background)?;
        d.set_item("working_focal", c.working_focal)?;
        d.set_item("fit", PyFitConfig::from_rust(&c.fit))?;
        Ok(d)
    }

    fn __getattr__(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyAny>> {
        let d = self.as_dict(py)?;
        match d.get_item(name)? {
            Some(v) => Ok(v.unbind()),
            None => Err(pyo3::exceptions::PyAttributeError::new_err(format!(
                "PipelineConfig has no setting {name:?}"
            ))),
        }
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let d = self.as_dict(py)?;
        let mut parts = Vec::new();
        for (k, v) in d.iter() {
            parts.push(format!("{}={}", k, v.repr()?));
        }
        Ok(format!("PipelineConfig({})", parts.join(", ")))
    }
}

/// A FitConfig, a dict of its keyword arguments, or None (the defaults).
fn fit_config_of(value: &Bound<PyAny>) -> PyResult<crate::fit::FitConfig> {
    if value.is_none() {
        return Ok(crate::fit::FitConfig::default());
    }
    if let Ok(c) = value.cast::<PyFitConfig>() {
        return Ok(c.borrow().to_rust()?);
    }
    if let Ok(d) = value.cast::<PyDict>() {
        let ty = value.py().get_type::<PyFitConfig>();
        let c = ty.call((), Some(d))?;
        let c = c.cast::<PyFitConfig>()?;
        return Ok(c.borrow().to_rust()?);
    }
    Err(super::convert::wrong_type(
        "fit",
        "a FitConfig, a dict or None",
        &short(value),
    ))
}

/// The pose of one frame.
#[pyclass(name = "PoseResult", module = "depthpose._core", frozen)]
pub struct PyPoseResult {
    pub(super) inner: PoseResult,
    pub(super) shape: [usize; 2],
}

#[pymethods]
impl PyPoseResult {
    /// The 22 pose parameters.
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, self.inner.pose.to_vec(), &[NUM_PARAMS])
    }
    /// The 15 joints (15, 3), camera frame, metres.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let v = self
            .inner
            .joints
            .iter()
            .flat_map(|j| [j.x, j.y, j.z])
            .collect();
        to_numpy(py, v, &[NUM_JOINTS, 3])
    }
    #[getter]
    fn joint_names(&self) -> Vec<&'static str> {
        JOINT_NAMES.to_vec()
    }
    /// The body model the pose was fitted with (its shape).
    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: BodyModel::with_shape(self.inner.shape),
        }
    }
    /// The shape parameters of that model (`BodyModel.shape_names` order).
    #[getter]
    fn shape<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let v = self.inner.shape.to_vec().to_vec();
        let n = v.len();
        to_numpy(py, v, &[n])
    }
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i16>>> {
        to_numpy(py, self.inner.labels.clone(), &self.shape)
    }
    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        to_numpy(py, self.inner.mask.clone(), &self.shape)
    }
    #[getter]
    fn energy(&self) -> f64 {
        self.inner.energy
    }
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    #[getter]
    fn confidence<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, self.inner.confidence.to_vec(), &[NUM_JOINTS])
    }
    /// Milliseconds per stage, and `total` for the whole call.
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.inner.timings.stages {
            d.set_item(k, v)?;
        }
        d.set_item("total", self.inner.timings.total)?;
        Ok(d)
    }
    #[getter]
    fn source(&self) -> &'static str {
        self.inner.source.name()
    }
    #[getter]
    fn discrepancy(&self) -> f64 {
        self.inner.discrepancy
    }
    /// How the person was found: "background", "planes", "learned" (a tracker's learned
    /// background), or None for a given mask.
    #[getter]
    fn segmentation_method(&self) -> Option<&'static str> {
        self.inner.segmentation.as_ref().map(|s| s.method.name())
    }
    /// The support planes removed to find the person.
    #[getter]
    fn planes(&self) -> Vec<PyPlane> {
        self.inner
            .segmentation
            .as_ref()
            .map(|s| s.planes.iter().map(|&p| PyPlane::from(p)).collect())
            .unwrap_or_default()
    }
    /// Other person-like objects seen.
    #[getter]
    fn others(&self) -> Vec<PyCluster> {
        self.inner
            .segmentation
            .as_ref()
            .map(|s| s.others.iter().map(|&c| PyCluster::from(c)).collect())
            .unwrap_or_default()
    }

    /// JSON-ready (labels and mask left out; they are images).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = &self.inner;
        let d = PyDict::new(py);
        d.set_item("pose", r.pose.to_vec())?;
        let joints: Vec<[f64; 3]> = r.joints.iter().map(|j| [j.x, j.y, j.z]).collect();
        d.set_item("joints", joints)?;
        d.set_item("joint_names", JOINT_NAMES.to_vec())?;
        d.set_item("shape", r.shape.to_vec().to_vec())?;
        d.set_item("energy", r.energy)?;
        d.set_item("iterations", r.iterations)?;
        d.set_item("converged", r.converged)?;
        d.set_item("confidence", r.confidence.to_vec())?;
        d.set_item("timings", self.timings(py)?)?;
        d.set_item("source", r.source.name())?;
        d.set_item(
            "discrepancy",
            r.discrepancy.is_finite().then_some(r.discrepancy),
        )?;
        d.set_item("segmentation", self.segmentation_method())?;
        Ok(d)
    }

    /// `to_dict` as a JSON string.
    fn to_json(&self, py: Python<'_>) -> PyResult<String> {
        let json = py.import("json")?;
        json.call_method1("dumps", (self.to_dict(py)?,))?.extract()
    }

    fn __repr__(&self) -> String {
        format!(
            "PoseResult(source={:?}, discrepancy={:.3}, iterations={}, total={:.1} ms)",
            self.inner.source.name(),
            self.inner.discrepancy,
            self.inner.iterations,
            self.inner.timings.total
        )
    }
}

/// The arguments both native classes are made from, as Python passes them.
pub(super) struct EstimatorArgs<'a, 'py> {
    pub camera: &'a Bound<'py, PyAny>,
    pub templates: &'a Bound<'py, PyAny>,
    pub model: Option<&'a Bound<'py, PyAny>>,
    pub config: Option<&'a Bound<'py, PyAny>>,
    pub background: Option<&'a Bound<'py, PyAny>>,
}

/// An estimator's parts, converted: camera, templates, model and config.
pub(super) struct EstimatorParts {
    pub camera: crate::camera::Camera,
    pub templates: std::sync::Arc<crate::templates::TemplateDatabase>,
    pub model: BodyModel,
    pub config: PipelineConfig,
    /// No model given: the body's size is searched from scratch.
    pub size_search: bool,
}

impl EstimatorParts {
    pub fn of(a: &EstimatorArgs) -> PyResult<Self> {
        let camera = camera_arg(a.camera, "camera")?;
        let templates =
            object::<PyTemplateDatabase>(a.templates, "templates", "a native template database")?
                .shared();
        let model = match a.model {
            None => BodyModel::default(),
            Some(m) => object::<PyBodyModel>(m, "model", "a depthpose.BodyModel or None")?
                .inner
                .clone(),
        };
        let config = match a.config {
            None => PipelineConfig::default(),
            Some(c) => {
                object::<PyPipelineConfig>(c, "config", "a depthpose.PipelineConfig or None")?
                    .inner
                    .clone()
            }
        };
        Ok(EstimatorParts {
            camera,
            templates,
            model,
            config,
            size_search: a.model.is_none(),
        })
    }

    /// The estimator, with `background` (metres, the camera's size) when given.
    pub fn estimator(self, background: Option<&[f32]>) -> PyResult<Estimator> {
        Ok(Estimator::new(
            &self.camera,
            self.model,
            self.templates,
            self.config,
            background,
        )?
        .with_size_search(self.size_search))
    }
}

/// The estimator both native depth classes are made from.
fn estimator_of(a: &EstimatorArgs) -> PyResult<Estimator> {
    let parts = EstimatorParts::of(a)?;
    let bg = a
        .background
        .map(|b| depth_array(b, "background"))
        .transpose()?;
    if let Some(b) = &bg {
        parts
            .camera
            .check_image("background", b.shape[0], b.shape[1])?;
    }
    parts.estimator(bg.as_ref().map(|b| b.data.as_slice()))
}

/// A frame's depth (metres), optional mask and (height, width), checked against the
/// camera.
struct FrameArgs {
    depth: Vec<f32>,
    mask: Option<Vec<bool>>,
    shape: [usize; 2],
}

fn frame_args(
    camera: &crate::camera::Camera,
    depth: &Bound<PyAny>,
    mask: Option<&Bound<PyAny>>,
) -> PyResult<FrameArgs> {
    let d = depth_array(depth, "depth")?;
    camera.check_image("depth", d.shape[0], d.shape[1])?;
    let mask = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
    Ok(FrameArgs {
        shape: [d.shape[0], d.shape[1]],
        depth: d.data,
        mask,
    })
}

/// Pose from scratch, one frame per call (see `depthpose.PoseEstimator`).
#[pyclass(name = "_PoseEstimator", module = "depthpose._core", frozen)]
pub struct PyPoseEstimator {
    inner: Estimator,
}

#[pymethods]
impl PyPoseEstimator {
    #[new]
    #[pyo3(signature = (camera, templates, *, model=None, config=None, background=None))]
    fn new(
        camera: &Bound<'_, PyAny>,
        templates: &Bound<'_, PyAny>,
        model: Option<&Bound<'_, PyAny>>,
        config: Option<&Bound<'_, PyAny>>,
        background: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let args = EstimatorArgs {
            camera,
            templates,
            model,
            config,
            background,
        };
        Ok(PyPoseEstimator {
            inner: estimator_of(&args)?,
        })
    }

    #[pyo3(signature = (depth, mask=None))]
    fn estimate(
        &self,
        py: Python<'_>,
        depth: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyPoseResult> {
        let a = frame_args(self.inner.camera(), depth, mask)?;
        let r = native(py, || self.inner.estimate(&a.depth, a.mask.as_deref()))?;
        Ok(PyPoseResult {
            inner: r,
            shape: a.shape,
        })
    }

    /// The depth discrepancy of each of `poses` (N, 22) on a frame (`mask`: the
    /// person's pixels, else segmented).
    #[pyo3(signature = (poses, depth, mask=None))]
    fn discrepancies<'py>(
        &self,
        py: Python<'py>,
        poses: &Bound<'py, PyAny>,
        depth: &Bound<'py, PyAny>,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<F64Array<'py>> {
        let poses = poses_arg(poses, "poses")?;
        let a = frame_args(self.inner.camera(), depth, mask)?;
        let v = native(py, || -> crate::Result<Vec<f64>> {
            let frame = self.inner.prepare(&a.depth, a.mask.as_deref(), None)?;
            self.inner.discrepancies(&frame, &poses)
        })?;
        let n = v.len();
        to_numpy(py, v, &[n])
    }

    /// The rest-pose penalty of each of `poses` with this config's weight.
    fn penalty<'py>(&self, py: Python<'py>, poses: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
        let poses = poses_arg(poses, "poses")?;
        let v: Vec<f64> = poses.iter().map(|p| self.inner.penalty(p)).collect();
        let n = v.len();
        to_numpy(py, v, &[n])
    }

    /// The person's pixels of a frame as the estimator finds them.
    fn person_mask<'py>(
        &self,
        py: Python<'py>,
        depth: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        let a = frame_args(self.inner.camera(), depth, None)?;
        let m = native(py, || -> crate::Result<Vec<bool>> {
            let frame = self.inner.prepare(&a.depth, None, None)?;
            Ok(self.inner.resolution().upsample(&frame.mask, false))
        })?;
        to_numpy(py, m, &a.shape)
    }

    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.inner.model().clone(),
        }
    }
    #[getter]
    fn config(&self) -> PyPipelineConfig {
        PyPipelineConfig {
            inner: self.inner.config().clone(),
        }
    }
    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            inner: *self.inner.camera(),
        }
    }
    /// The camera the pipeline works with (the input's, reduced for large images).
    #[getter]
    fn working_camera(&self) -> PyCamera {
        PyCamera {
            inner: self.inner.resolution().working,
        }
    }
}

/// Pose through a video, one frame per call (see `depthpose.PoseTracker`).
#[pyclass(name = "_PoseTracker", module = "depthpose._core")]
pub struct PyPoseTracker {
    inner: Tracker,
}

#[pymethods]
impl PyPoseTracker {
    #[new]
    #[pyo3(signature = (camera, templates, *, model=None, config=None, background=None, calibrate=None))]
    fn new(
        camera: &Bound<'_, PyAny>,
        templates: &Bound<'_, PyAny>,
        model: Option<&Bound<'_, PyAny>>,
        config: Option<&Bound<'_, PyAny>>,
        background: Option<&Bound<'_, PyAny>>,
        calibrate: Option<Flag>,
    ) -> PyResult<Self> {
        let calibrate = match &calibrate {
            Some(c) => c.get("calibrate")?,
            None => model.is_none(),
        };
        let args = EstimatorArgs {
            camera,
            templates,
            model,
            config,
            background,
        };
        Ok(PyPoseTracker {
            inner: Tracker::new(estimator_of(&args)?, calibrate),
        })
    }

    #[pyo3(signature = (depth, mask=None))]
    fn update(
        &mut self,
        py: Python<'_>,
        depth: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyPoseResult> {
        let a = frame_args(self.inner.estimator().camera(), depth, mask)?;
        let tracker = &mut self.inner;
        let r = native(py, || tracker.update(&a.depth, a.mask.as_deref()))?;
        Ok(PyPoseResult {
            inner: r,
            shape: a.shape,
        })
    }

    #[pyo3(signature = (shape=Flag::new(false)))]
    fn reset(&mut self, shape: Flag) -> PyResult<()> {
        self.inner.reset(shape.get("shape")?);
        Ok(())
    }

    fn start_from(&mut self, pose: &Bound<'_, PyAny>) -> PyResult<()> {
        let p = pose_arg(pose, "pose")?;
        Ok(self.inner.start_from(&p)?)
    }

    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.inner.model().clone(),
        }
    }
    #[getter]
    fn base_model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.inner.base_model().clone(),
        }
    }
    #[getter]
    fn config(&self) -> PyPipelineConfig {
        PyPipelineConfig {
            inner: self.inner.estimator().config().clone(),
        }
    }
    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            inner: *self.inner.estimator().camera(),
        }
    }
    #[getter]
    fn lost_frames(&self) -> usize {
        self.inner.lost_frames
    }
    #[getter]
    fn switches(&self) -> usize {
        self.inner.switches
    }
    #[getter]
    fn calibrating(&self) -> bool {
        self.inner.calibrating()
    }
    #[getter]
    fn calibrated(&self) -> bool {
        self.inner.calibration().result.is_some()
    }
    #[getter]
    fn shape_factors<'py>(&self, py: Python<'py>) -> PyResult<Option<F64Array<'py>>> {
        self.inner
            .shape_factors()
            .map(|f| {
                let n = f.len();
                to_numpy(py, f.to_vec(), &[n])
            })
            .transpose()
    }
    #[getter]
    fn calibration(&self) -> Option<PyShapeFitResult> {
        let cam = self.inner.estimator().resolution().working;
        self.inner
            .calibration()
            .result
            .clone()
            .map(|result| PyShapeFitResult {
                result,
                height: cam.height,
                width: cam.width,
            })
    }
    #[getter]
    fn calibration_error(&self) -> Option<String> {
        self.inner.calibration().error.clone()
    }
    #[getter]
    fn calibration_frame(&self) -> Option<usize> {
        self.inner.calibration().frame
    }
}

/// The left/right-swapped pose (see `depthpose.swap_limbs`).
#[pyfunction]
fn swap_limbs<'py>(py: Python<'py>, pose: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
    let p = pose_arg(pose, "pose")?;
    to_numpy(py, swap(&p).to_vec(), &[NUM_PARAMS])
}

/// The mirror image of the pose in the camera's vertical plane through the hip centre.
#[pyfunction]
fn mirror_view<'py>(py: Python<'py>, pose: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
    let p = pose_arg(pose, "pose")?;
    to_numpy(py, mirror(&p).to_vec(), &[NUM_PARAMS])
}

/// `weight` × Σ θ² over the 14 limb angles of each pose: (N, 22) → (N,), (22,) → (1,).
#[pyfunction]
fn rest_pose_penalty<'py>(
    py: Python<'py>,
    poses: &Bound<'py, PyAny>,
    weight: Real,
) -> PyResult<F64Array<'py>> {
    let weight = weight.get("weight")?;
    if !(weight.is_finite() && weight >= 0.0) {
        return Err(
            Error::invalid("weight", format!("must be finite and >= 0, got {weight}")).into(),
        );
    }
    let a = f64_array(poses, "poses", None, false)?;
    let rows = match a.shape.as_slice() {
        [NUM_PARAMS] => 1,
        [n, NUM_PARAMS] => *n,
        other => {
            return Err(Error::invalid(
                "poses",
                format!("expected shape ({NUM_PARAMS},) or (N, {NUM_PARAMS}), got {other:?}"),
            )
            .into())
        }
    };
    let poses: Vec<Pose> = (0..rows)
        .map(|k| pose_from_slice(&a.data[k * NUM_PARAMS..][..NUM_PARAMS], "poses"))
        .collect::<crate::Result<_>>()?;
    let v: Vec<f64> = poses.iter().map(|p| penalty(p, weight)).collect();
    let n = v.len();
    to_numpy(py, v, &[n])
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPipelineConfig>()?;
    m.add_class::<PyPoseResult>()?;
    m.add_class::<PyPoseEstimator>()?;
    m.add_class::<PyPoseTracker>()?;
    m.add_function(wrap_pyfunction!(swap_limbs, m)?)?;
    m.add_function(wrap_pyfunction!(mirror_view, m)?)?;
    m.add_function(wrap_pyfunction!(rest_pose_penalty, m)?)?;
    m.add("JOINT_NAMES", JOINT_NAMES.to_vec())?;
    Ok(())
}
