//! Native objects as arguments (a camera, a body model) and the settings built from
//! them or from a dict of keyword arguments (a fit config).

use super::{invalid, type_name, wrong_type};
use crate::camera::Camera;
use crate::python::body::PyBodyModel;
use crate::python::camera::PyCamera;
use crate::python::fit::PyFitConfig;
use crate::python::InvalidTypeError;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyMapping, PyString};
use pyo3::{PyClass, PyTypeInfo};

/// `obj` as the native class `T` (`what` describes it in the error).
pub fn object<'py, T: PyClass + PyTypeInfo>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    what: &str,
) -> PyResult<PyRef<'py, T>> {
    let bound = obj
        .cast::<T>()
        .map_err(|_| wrong_type(name, what, &type_name(obj)))?;
    bound
        .try_borrow()
        .map_err(|_| invalid(name, "is being changed by another call"))
}

/// A `depthpose.Camera` argument.
pub fn camera(obj: &Bound<PyAny>, name: &str) -> PyResult<Camera> {
    Ok(object::<PyCamera>(obj, name, "a depthpose.Camera")?.inner)
}

/// An optional `depthpose.BodyModel` argument (None: the default model).
pub fn body_model(obj: Option<&Bound<PyAny>>, name: &str) -> PyResult<crate::body::BodyModel> {
    match obj {
        None => Ok(crate::body::BodyModel::default()),
        Some(m) => Ok(
            object::<PyBodyModel>(m, name, "a depthpose.BodyModel or None")?
                .inner
                .clone(),
        ),
    }
}

/// An optional `depthpose.FitConfig` argument: a FitConfig, a mapping of its keyword
/// arguments, or None (the defaults).
pub fn fit_config(obj: Option<&Bound<PyAny>>, name: &str) -> PyResult<crate::fit::FitConfig> {
    let Some(obj) = obj.filter(|c| !c.is_none()) else {
        return Ok(crate::fit::FitConfig::default());
    };
    if obj.is_instance_of::<PyFitConfig>() {
        return Ok(object::<PyFitConfig>(obj, name, "a FitConfig")?.to_rust()?);
    }
    let Ok(mapping) = obj.cast::<PyMapping>() else {
        return Err(wrong_type(
            name,
            "a FitConfig, a dict or None",
            &type_name(obj),
        ));
    };
    let py = obj.py();
    let settings = PyDict::new(py);
    settings.update(mapping)?;
    if let Some(key) = settings
        .keys()
        .iter()
        .find(|k| !k.is_instance_of::<PyString>())
    {
        return Err(PyErr::new::<InvalidTypeError, _>(format!(
            "{name}: keys must be setting names, got {}",
            key.repr()?
        )));
    }
    let config = py
        .get_type::<PyFitConfig>()
        .call((), Some(&settings))
        .map_err(|e| {
            if e.is_instance_of::<PyTypeError>(py) && !e.is_instance_of::<InvalidTypeError>(py) {
                PyErr::new::<InvalidTypeError, _>(format!("{name}: {}", e.value(py)))
            } else {
                e
            }
        })?;
    Ok(object::<PyFitConfig>(&config, name, "a FitConfig")?.to_rust()?)
}
