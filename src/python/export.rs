//! Exports for Python (`depthpose.export` re-exports these; `_core.pyi` documents
//! them): BVH motion and JSON lines, written by [`crate::export`].

use super::body::PyBodyModel;
use super::convert::{
    array_like, f64_array, invalid, object, type_name, wrong_type, PathArg, Real,
};
use super::native;
use crate::body::{Pose, NUM_JOINTS, NUM_PARAMS};
use crate::export::{self, BvhMotion, Json, BVH_NAMES, BVH_PARENTS};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

/// Rows of `n` values of an (T, n) array argument.
fn rows<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    finite: bool,
) -> PyResult<Vec<[f64; N]>> {
    let a = f64_array(&array_like(obj, name)?, name, None, finite)?;
    if a.shape.len() != 2 || a.shape[1] != N {
        return Err(invalid(
            name,
            format!(
                "expected (T, {N}), got shape {}",
                crate::io::npy::shape_text(&a.shape)
            ),
        ));
    }
    Ok(a.data
        .chunks_exact(N)
        .map(|r| std::array::from_fn(|k| r[k]))
        .collect())
}

#[pyfunction]
#[pyo3(signature = (path, model, poses, fps=Real::new(30.0), *, confidence=None),
       text_signature = "(path, model, poses, fps=30.0, *, confidence=None)")]
fn write_bvh(
    py: Python<'_>,
    path: PathArg,
    model: &Bound<'_, PyAny>,
    poses: &Bound<'_, PyAny>,
    fps: Real,
    confidence: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let path = path.get("path")?;
    let model = object::<PyBodyModel>(model, "model", "a depthpose.BodyModel")?
        .inner
        .clone();
    let fps = fps.get("fps")?;
    let poses: Vec<Pose> = rows::<NUM_PARAMS>(poses, "poses", false)?;
    let confidence = match confidence {
        Some(c) if !c.is_none() => Some(rows::<NUM_JOINTS>(c, "confidence", true)?),
        _ => None,
    };
    let motion = BvhMotion {
        poses: &poses,
        fps,
        confidence: confidence.as_deref(),
    };
    native(py, || export::write_bvh(&path, &model, &motion))
}

/// A value of a result's `to_dict()` as JSON: dicts with string keys, lists, tuples,
/// strings, numbers (numpy's too), bools and None.
fn json(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Json> {
    if obj.is_none() {
        Ok(Json::Null)
    } else if obj.is_instance_of::<PyBool>() {
        Ok(Json::Bool(obj.is_truthy()?))
    } else if obj.is_instance_of::<PyInt>() {
        obj.extract::<i128>()
            .map(Json::Int)
            .or_else(|_| Ok(Json::Number(obj.extract::<f64>()?)))
    } else if obj.is_instance_of::<PyFloat>() {
        Ok(Json::Number(obj.extract()?))
    } else if let Ok(s) = obj.cast::<PyString>() {
        Ok(Json::Text(s.to_str()?.to_string()))
    } else if let Ok(d) = obj.cast::<PyDict>() {
        let mut items = Vec::with_capacity(d.len());
        for (k, v) in d.iter() {
            let key = k
                .cast::<PyString>()
                .map_err(|_| wrong_type(name, "a dict with string keys", &type_name(&k)))?
                .to_str()?
                .to_string();
            items.push((key, json(&v, name)?));
        }
        Ok(Json::Object(items))
    } else if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        obj.try_iter()?
            .map(|v| json(&v?, name))
            .collect::<PyResult<_>>()
            .map(Json::List)
    } else if let Ok(v) = obj.call_method0("tolist") {
        // A numpy scalar or array.
        json(&v, name)
    } else {
        Err(wrong_type(name, "values JSON can hold", &type_name(obj)))
    }
}

#[pyfunction]
fn write_jsonl(py: Python<'_>, path: PathArg, results: &Bound<'_, PyAny>) -> PyResult<()> {
    let path = path.get("path")?;
    let items = results
        .try_iter()
        .map_err(|_| {
            wrong_type(
                "results",
                "a sequence of PoseResult or None",
                &type_name(results),
            )
        })?
        .collect::<PyResult<Vec<_>>>()?;
    let mut records = Vec::with_capacity(items.len());
    for (k, r) in items.iter().enumerate() {
        let name = format!("results[{k}]");
        let mut record = vec![("frame".to_string(), Json::Int(k as i128))];
        if r.is_none() {
            record.push(("joints".into(), Json::Null));
        } else {
            let to_dict = r
                .getattr("to_dict")
                .ok()
                .filter(|f| f.is_callable())
                .ok_or_else(|| wrong_type(&name, "a PoseResult or None", &type_name(r)))?;
            match json(&to_dict.call0()?, &name)? {
                Json::Object(items) => {
                    record.retain(|_| !items.iter().any(|(key, _)| key == "frame"));
                    record.extend(items);
                }
                _ => return Err(invalid(&name, "to_dict() did not return a dict")),
            }
        }
        records.push(Json::Object(record));
    }
    native(py, || export::write_jsonl(&path, &records))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(write_bvh, m)?)?;
    m.add_function(wrap_pyfunction!(write_jsonl, m)?)?;
    let py = m.py();
    let parents = PyDict::new(py);
    for (segment, parent) in BVH_PARENTS {
        parents.set_item(segment, parent)?;
    }
    let names = PyDict::new(py);
    for (segment, name) in BVH_NAMES {
        names.set_item(segment, name)?;
    }
    m.add("BVH_PARENTS", parents)?;
    m.add("BVH_NAMES", names)
}
