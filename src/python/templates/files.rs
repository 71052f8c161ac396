//! The template database's `.npz` files and the per-process default database.
//!
//! A file holds the arrays of [`TemplateArrays`] as numpy arrays (`format_version` an
//! integer and `hash` a hex string, both 0-d). [`crate::io::npz`] writes the archive
//! (to a temporary file, then renamed) and reads it, refusing a truncated or corrupt
//! archive; the entries reach the checks below as numpy arrays, so that a file numpy
//! wrote with other dtypes or layouts loads too. Every entry that is not what the
//! format says is a `FileFormatError` naming the file and the entry.

use super::super::convert::{f32_array, f64_array, i64_array, Int};
use super::super::io::read_npz_dict;
use super::super::{native, FileFormatError};
use super::database::{build_database, PyTemplateDatabase};
use super::Settings;
use crate::body::{BodyModel, NUM_JOINTS, NUM_PARAMS, NUM_SHAPE_PARAMS};
use crate::io::npy::{Array, Dtype};
use crate::io::npz;
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

/// Writes `db` to `path` as an `.npz` file (atomically: see [`npz::write`]).
pub(super) fn save(py: Python<'_>, db: &TemplateDatabase, path: &Path) -> PyResult<()> {
    let entries = arrays(db);
    let refs: Vec<(&str, &Array)> = entries.iter().map(|(k, a)| (*k, a)).collect();
    native(py, || npz::write(path, &refs))
}

/// The database in the `.npz` file at `path`. With `expected` given, a database of
/// another model or other settings is refused.
pub(super) fn load(
    py: Python<'_>,
    path: &Path,
    expected: Option<&(BodyModel, TemplateConfig)>,
) -> PyResult<TemplateDatabase> {
    let entries = read_npz_dict(py, path.to_path_buf(), "a template database", None)?;
    let source = path.display().to_string();
    let a = template_arrays(&entries, &source)?;
    native(py, || {
        TemplateDatabase::from_arrays(&a, expected.map(|(m, c)| (m, c)), &source)
    })
}

/// Where the default database is cached: `$DEPTHPOSE_CACHE` (or `~/.cache/depthpose`)
/// `/templates-<hash>.npz`, named by the hash of the default model and settings.
pub(super) fn default_path() -> PyResult<PathBuf> {
    let root = match std::env::var_os("DEPTHPOSE_CACHE") {
        Some(r) => PathBuf::from(r),
        None => std::env::home_dir()
            .ok_or_else(|| {
                PyErr::new::<pyo3::exceptions::PyRuntimeError, _>(
                    "no home folder for the template cache; set DEPTHPOSE_CACHE",
                )
            })?
            .join(".cache")
            .join("depthpose"),
    };
    let (model, cfg) = default_settings()?;
    let digest = TemplateDatabase::settings_hash(&model, &cfg);
    Ok(root.join(format!("templates-{digest:016x}.npz")))
}

/// The default model and template settings.
fn default_settings() -> PyResult<(BodyModel, TemplateConfig)> {
    Ok((BodyModel::default(), Settings::default().config(false)?))
}

/// The database of the default model and settings, cached at [`default_path`]: built
/// (and saved) on first use, loaded once per process and cache path.
pub(super) fn default(py: Python<'_>, progress: bool) -> PyResult<Py<PyTemplateDatabase>> {
    let path = default_path()?;
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

/// The entries of `db`'s file, by key.
fn arrays(db: &TemplateDatabase) -> Vec<(&'static str, Array)> {
    let a = db.to_arrays();
    let t = db.len();
    let s = a.counts.iter().sum::<i64>() as usize;
    let dim = db.config.descriptor.dim();
    let f64s = |v: &[f64], shape: Vec<usize>| Array::of(Dtype::F64, shape, v, f64::to_le_bytes);
    let f32s = |v: &[f32], shape: Vec<usize>| Array::of(Dtype::F32, shape, v, f32::to_le_bytes);
    let i64s = |v: &[i64], shape: Vec<usize>| Array::of(Dtype::I64, shape, v, i64::to_le_bytes);
    vec![
        (
            "format_version",
            i64s(&[i64::from(a.format_version)], vec![]),
        ),
        ("hash", Array::text(&format!("{:016x}", a.hash))),
        ("shape", f64s(&a.shape, vec![NUM_SHAPE_PARAMS])),
        ("config", f64s(&a.config, vec![a.config.len()])),
        ("poses", f64s(&a.poses, vec![t, NUM_PARAMS])),
        ("views", i64s(&a.views, vec![t])),
        ("joints", f64s(&a.joints, vec![t, NUM_JOINTS, 3])),
        ("centroids", f64s(&a.centroids, vec![t, 3])),
        ("sizes", f64s(&a.sizes, vec![t])),
        ("counts", i64s(&a.counts, vec![t])),
        ("context_scale", f64s(&a.context_scale, vec![t])),
        ("context_centroid", f64s(&a.context_centroid, vec![t, 2])),
        ("context_points", i64s(&a.context_points, vec![t])),
        ("sample_pixels", f32s(&a.sample_pixels, vec![s, 2])),
        ("sample_positions", f32s(&a.sample_positions, vec![s, 2])),
        ("descriptors", f32s(&a.descriptors, vec![s, dim])),
    ]
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
