//! The arguments the pose classes share: the camera, the body model, the template
//! database, the settings and a frame's depth and mask, converted and checked, each
//! error naming its argument.

use super::super::body::PyBodyModel;
use super::super::convert::{
    array_like, bool_array, camera as camera_arg, depth_array, f64_array, invalid, object, Flag,
};
use super::super::templates::PyTemplateDatabase;
use super::config::PyPipelineConfig;
use crate::body::{pose_from_slice, BodyModel, Pose, NUM_PARAMS};
use crate::camera::Camera;
use crate::pipeline::{Estimator, PipelineConfig};
use crate::templates::TemplateDatabase;
use pyo3::prelude::*;
use std::sync::Arc;

/// The arguments every pose class is made from, as Python passes them.
pub(in crate::python) struct EstimatorArgs<'a, 'py> {
    pub camera: &'a Bound<'py, PyAny>,
    pub model: Option<&'a Bound<'py, PyAny>>,
    pub templates: Option<&'a Bound<'py, PyAny>>,
    pub config: Option<&'a Bound<'py, PyAny>>,
}

/// An estimator's parts, converted: camera, templates, model and config.
pub(in crate::python) struct EstimatorParts {
    pub camera: Camera,
    pub templates: Arc<TemplateDatabase>,
    pub model: BodyModel,
    pub config: PipelineConfig,
    /// No model given: the body's size is searched from scratch.
    pub size_search: bool,
}

impl EstimatorParts {
    /// The parts, checked in the order camera, model, config, templates.
    pub fn of(a: &EstimatorArgs) -> PyResult<Self> {
        let camera = camera_arg(a.camera, "camera")?;
        let model = match a.model {
            None => BodyModel::default(),
            Some(m) => object::<PyBodyModel>(m, "model", "a BodyModel")?
                .inner
                .clone(),
        };
        let config = match a.config {
            None => PipelineConfig::default(),
            Some(c) => object::<PyPipelineConfig>(c, "config", "a PipelineConfig")?
                .inner
                .clone(),
        };
        let templates = templates_arg(a.camera.py(), a.templates)?;
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

/// The native database of `templates`, a `depthpose.TemplateDatabase` (None: the
/// cached default database, `TemplateDatabase.default()`).
fn templates_arg(
    py: Python<'_>,
    templates: Option<&Bound<'_, PyAny>>,
) -> PyResult<Arc<TemplateDatabase>> {
    match templates {
        None => PyTemplateDatabase::default_shared(py),
        Some(t) => Ok(object::<PyTemplateDatabase>(t, "templates", "a TemplateDatabase")?.shared()),
    }
}

/// Whether a tracker calibrates the body's shape: `calibrate`, else (None) when no
/// model is given.
pub(in crate::python) fn calibrate_arg(
    calibrate: Option<&Flag>,
    model: Option<&Bound<'_, PyAny>>,
) -> PyResult<bool> {
    Ok(Flag::optional(calibrate, "calibrate")?.unwrap_or(model.is_none()))
}

/// The estimator of the depth classes, with the empty scene's depth `background`
/// (H, W) when given.
pub(super) fn estimator_of(
    a: &EstimatorArgs,
    background: Option<&Bound<'_, PyAny>>,
) -> PyResult<Estimator> {
    let parts = EstimatorParts::of(a)?;
    let bg = background
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
pub(super) struct FrameArgs {
    pub depth: Vec<f32>,
    pub mask: Option<Vec<bool>>,
    pub shape: [usize; 2],
}

impl FrameArgs {
    pub fn of(
        camera: &Camera,
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
}

/// The poses of an array of N × 22 values, (N, 22) or (22,), read row by row (a list
/// or tuple as `numpy.asarray` reads it); a bad row is named `name[k]`.
pub(super) fn pose_rows(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Pose>> {
    let a = f64_array(&array_like(obj, name)?, name, None, false)?;
    if a.data.len() % NUM_PARAMS != 0 {
        return Err(invalid(
            name,
            format!(
                "expected shape (N, {NUM_PARAMS}) or ({NUM_PARAMS},), got {:?}",
                a.shape
            ),
        ));
    }
    Ok(a.data
        .chunks(NUM_PARAMS)
        .enumerate()
        .map(|(k, row)| pose_from_slice(row, &format!("{name}[{k}]")))
        .collect::<crate::Result<Vec<_>>>()?)
}
