//! The template database's `.npz` files and the per-process default database.
//!
//! A file holds the arrays of [`TemplateArrays`] as numpy arrays (`format_version` an
//! integer and `hash` a hex string, both 0-d). numpy writes the archive
//! (`numpy.savez`, to a temporary file then renamed); `depthpose.io.read_npz` reads it
//! without pickles and refuses a truncated or corrupt archive. Every entry that is not
//! what the format says is a `FileFormatError` naming the file and the entry.

use super::super::convert::{f32_array, f64_array, i64_array, invalid, to_numpy, Int};
use super::super::{native, FileFormatError};
use super::database::{build_database, PyTemplateDatabase};
use super::Settings;
use crate::body::{BodyModel, NUM_JOINTS, NUM_PARAMS, NUM_SHAPE_PARAMS};
use crate::templates::{TemplateArrays, TemplateConfig, TemplateDatabase};
use numpy::{PyArrayDescrMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::sync::MutexExt;
use pyo3::types::PyDict;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The default databases loaded in this process, by cache path: every estimator made
/// without `templates=` shares one instead of loading its own (~0.35 s and ~60 MB).
static DEFAULTS: Mutex<BTreeMap<PathBuf, Py<PyTemplateDatabase>>> = Mutex::new(BTreeMap::new());

/// Writes `db` to `path` as an `.npz` file: to `<path>.tmp.npz` first, then renamed, so
/// that a reader never sees half a file.
pub(super) fn save(py: Python<'_>, db: &TemplateDatabase, path: &Path) -> PyResult<()> {
    let Some(name) = path.file_name() else {
        let shown = path.display().to_string();
        return Err(invalid("path", format!("{shown:?} names no file")));
    };
    let mut tmp_name = name.to_os_string();
    tmp_name.push(".tmp.npz");
    let tmp = path.with_file_name(tmp_name);
    py.import("numpy")?
        .call_method("savez", (&tmp,), Some(&arrays(py, db)?))?;
    py.import("os")?.call_method1("replace", (tmp, path))?;
    Ok(())
}

/// The database in the `.npz` file at `path`. With `expected` given, a database of
/// another model or other settings is refused.
pub(super) fn load(
    py: Python<'_>,
    path: &Path,
    expected: Option<&(BodyModel, TemplateConfig)>,
) -> PyResult<TemplateDatabase> {
    let entries = py
        .import("depthpose.io")?
        .call_method1("read_npz", (path, "a template database"))?;
    let source = path.display().to_string();
    let a = template_arrays(entries.cast::<PyDict>()?, &source)?;
    native(py, || {
        TemplateDatabase::from_arrays(&a, expected.map(|(m, c)| (m, c)), &source)
    })
}

/// Where the default database is cached: `$DEPTHPOSE_CACHE` (or `~/.cache/depthpose`)
/// `/templates-<hash>.npz`, named by the hash of the default model and settings.
pub(super) fn default_path(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let path = py.import("pathlib")?.getattr("Path")?;
    let root = match py
        .import("os")?
        .getattr("environ")?
        .call_method1("get", ("DEPTHPOSE_CACHE",))?
    {
        r if r.is_none() => path
            .call_method0("home")?
            .call_method1("joinpath", (".cache", "depthpose"))?,
        r => path.call1((r,))?,
    };
    let (model, cfg) = default_settings()?;
    let digest = TemplateDatabase::settings_hash(&model, &cfg);
    root.call_method1("joinpath", (format!("templates-{digest:016x}.npz"),))
}

/// The default model and template settings.
fn default_settings() -> PyResult<(BodyModel, TemplateConfig)> {
    Ok((BodyModel::default(), Settings::default().config(false)?))
}

/// The database of the default model and settings, cached at [`default_path`]: built
/// (and saved) on first use, loaded once per process and cache path.
pub(super) fn default(py: Python<'_>, progress: bool) -> PyResult<Py<PyTemplateDatabase>> {
    let path: PathBuf = default_path(py)?.extract()?;
    let mut loaded = DEFAULTS
        .lock_py_attached(py)
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(db) = loaded.get(&path) {
        return Ok(db.clone_ref(py));
    }
    let db = Py::new(
        py,
        PyTemplateDatabase::new(load_or_build(py, &path, progress)?),
    )?;
    loaded.insert(path, db.clone_ref(py));
    Ok(db)
}

/// The default database from `path`, or built and saved there when the file is
/// missing, stale or corrupt.
fn load_or_build(py: Python<'_>, path: &Path, progress: bool) -> PyResult<TemplateDatabase> {
    let settings = default_settings()?;
    if path.exists() {
        match load(py, path, Some(&settings)) {
            Ok(db) => return Ok(db),
            Err(e) if e.is_instance_of::<FileFormatError>(py) => {}
            Err(e) => return Err(e),
        }
    }
    let (model, cfg) = settings;
    let db = build_database(py, &model, &cfg, false, progress)?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    save(py, &db, path)?;
    Ok(db)
}

/// The entries of `db`'s file.
fn arrays<'py>(py: Python<'py>, db: &TemplateDatabase) -> PyResult<Bound<'py, PyDict>> {
    let a = db.to_arrays();
    let t = db.len();
    let s = a.counts.iter().sum::<i64>() as usize;
    let dim = db.config.descriptor.dim();
    let d = PyDict::new(py);
    d.set_item("format_version", a.format_version)?;
    d.set_item("hash", format!("{:016x}", a.hash))?;
    d.set_item("shape", to_numpy(py, a.shape, &[NUM_SHAPE_PARAMS])?)?;
    let nc = a.config.len();
    d.set_item("config", to_numpy(py, a.config, &[nc])?)?;
    d.set_item("poses", to_numpy(py, a.poses, &[t, NUM_PARAMS])?)?;
    d.set_item("views", to_numpy(py, a.views, &[t])?)?;
    d.set_item("joints", to_numpy(py, a.joints, &[t, NUM_JOINTS, 3])?)?;
    d.set_item("centroids", to_numpy(py, a.centroids, &[t, 3])?)?;
    d.set_item("sizes", to_numpy(py, a.sizes, &[t])?)?;
    d.set_item("counts", to_numpy(py, a.counts, &[t])?)?;
    d.set_item("context_scale", to_numpy(py, a.context_scale, &[t])?)?;
    d.set_item(
        "context_centroid",
        to_numpy(py, a.context_centroid, &[t, 2])?,
    )?;
    d.set_item("context_points", to_numpy(py, a.context_points, &[t])?)?;
    d.set_item("sample_pixels", to_numpy(py, a.sample_pixels, &[s, 2])?)?;
    d.set_item(
        "sample_positions",
        to_numpy(py, a.sample_positions, &[s, 2])?,
    )?;
    d.set_item("descriptors", to_numpy(py, a.descriptors, &[s, dim])?)?;
    Ok(d)
}

/// The database's arrays from the entries of its file (`source` names it in errors).
fn template_arrays(entries: &Bound<PyDict>, source: &str) -> PyResult<TemplateArrays> {
    let py = entries.py();
    let file_err = |msg: String| -> PyErr { crate::Error::file(source, msg).into() };
    let get = |k: &str| -> PyResult<Bound<PyAny>> {
        entries
            .get_item(k)?
            .ok_or_else(|| file_err(format!("missing entry '{k}'; not a template database")))
    };
    // An entry that is not what the format says is the file's fault: its message
    // (without the exception's class) goes into a FileFormatError.
    let entry = |e: PyErr| file_err(e.value(py).to_string());
    let f64s = |k: &str| -> PyResult<Vec<f64>> {
        Ok(f64_array(&get(k)?, k, None, true).map_err(entry)?.data)
    };
    let f32s = |k: &str| -> PyResult<Vec<f32>> {
        Ok(f32_array(&get(k)?, k, None, true).map_err(entry)?.data)
    };
    let i64s =
        |k: &str| -> PyResult<Vec<i64>> { Ok(i64_array(&get(k)?, k, None).map_err(entry)?.data) };
    // A 0-d array of one of the dtype `kinds`, as a Python scalar.
    let scalar = |k: &str, kinds: &[u8], what: &str| -> PyResult<Bound<PyAny>> {
        let v = get(k)?;
        match v.cast::<PyUntypedArray>() {
            Ok(a) if a.ndim() == 0 && kinds.contains(&a.dtype().kind()) => v.call_method0("item"),
            _ => Err(file_err(format!("{k} is not {what}"))),
        }
    };
    let version = scalar("format_version", b"iu", "an integer")?
        .extract::<Int>()
        .map_err(|_| file_err("format_version is not an integer".into()))?
        .in_range(0, i128::from(u32::MAX), "format_version")
        .map_err(entry)?;
    let hash_s: String = scalar("hash", b"U", "a string")?.extract()?;
    let hash = u64::from_str_radix(&hash_s, 16).map_err(|_| {
        file_err(format!(
            "hash {:?} is not hexadecimal",
            hash_s.chars().take(40).collect::<String>()
        ))
    })?;
    Ok(TemplateArrays {
        format_version: version as u32,
        hash,
        shape: f64s("shape")?,
        config: f64s("config")?,
        poses: f64s("poses")?,
        views: i64s("views")?,
        joints: f64s("joints")?,
        centroids: f64s("centroids")?,
        sizes: f64s("sizes")?,
        counts: i64s("counts")?,
        context_scale: f64s("context_scale")?,
        context_centroid: f64s("context_centroid")?,
        context_points: i64s("context_points")?,
        sample_pixels: f32s("sample_pixels")?,
        sample_positions: f32s("sample_positions")?,
        descriptors: f32s("descriptors")?,
    })
}
