//! Depth sequences for Python: `open_sequence`, the `Sequence` it returns and the
//! iterator of `Sequence.iter_frames` (`depthpose.sequence` re-exports them;
//! `_core.pyi` documents them). Arguments are checked here, the camera resolved (a
//! `Camera`, a Python function of the frames' shape, or intrinsics); the files are read
//! by [`crate::sequence`] with the GIL released.

use super::camera::PyCamera;
use super::checks;
use super::convert::{
    array_like, f64_array, invalid, to_numpy, type_name, wrong_type, PathArg, Real,
};
use super::{native, DepthPoseError};
use crate::io::{MAX_DEPTH_SCALE, MIN_DEPTH_SCALE};
use crate::sequence::{self, intrinsics_of, Kind, Options, Sequence, Values};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::path::PathBuf;
use std::sync::Arc;

/// A depth sequence on disk (see `_core.pyi`): what its files say, and its frames on
/// demand.
#[pyclass(name = "Sequence", module = "depthpose._core", frozen)]
pub struct PySequence {
    inner: Arc<Sequence>,
    camera: Py<PyCamera>,
    path: Py<PyAny>,
    files: Py<PyAny>,
    background: Py<PyAny>,
    gt_joints: Py<PyAny>,
}

/// A `pathlib.Path`.
fn pathlib<'py>(py: Python<'py>, path: &std::path::Path) -> PyResult<Bound<'py, PyAny>> {
    py.import("pathlib")?.getattr("Path")?.call1((path,))
}

/// Values as a numpy array of their shape, or `None`.
fn optional_array<'py, T: numpy::Element + Clone>(
    py: Python<'py>,
    values: Option<&Values<T>>,
) -> PyResult<Py<PyAny>> {
    Ok(match values {
        Some(v) => to_numpy(py, v.data.clone(), &v.shape)?.into_any().unbind(),
        None => py.None(),
    })
}

/// A frame index argument (an integer >= 0) as a `usize` (the largest for one beyond
/// it, which the frame count then bounds).
fn index(value: &Bound<'_, PyAny>, name: &str) -> PyResult<usize> {
    let v = checks::integer(value, name, Some(0), None)?;
    Ok(v.extract::<usize>().unwrap_or(usize::MAX))
}

/// The frame range [start, stop) of the arguments.
fn range(
    seq: &Sequence,
    start: &Bound<'_, PyAny>,
    stop: Option<&Bound<'_, PyAny>>,
) -> PyResult<(usize, usize)> {
    let start = index(start, "start")?;
    let stop = stop.map(|s| index(s, "stop")).transpose()?;
    Ok(seq.range(start, stop)?)
}

/// What the camera of a sequence is resolved from.
struct CameraSource<'a, 'py> {
    /// The `camera` argument: a `Camera` or a function of the shape (H, W).
    camera: Option<&'a Bound<'py, PyAny>>,
    /// The `intrinsics` argument.
    intrinsics: Option<&'a Bound<'py, PyAny>>,
    /// The intrinsics the files hold, if any (an error when they are unusable).
    held: crate::Result<Option<[f64; 4]>>,
}

/// The camera of frames of `shape` (height, width) at `path`: the one given (or that
/// the function given returns for the shape), which must be of that shape; else one of
/// the intrinsics given, or of those the files hold.
fn camera_of(
    py: Python<'_>,
    source: CameraSource<'_, '_>,
    (h, w): (usize, usize),
    path: &str,
) -> PyResult<Py<PyCamera>> {
    if let Some(camera) = source.camera {
        if source.intrinsics.is_some() {
            return Err(invalid(
                "camera",
                "give either camera or intrinsics, not both",
            ));
        }
        let cam = if camera.is_instance_of::<PyCamera>() {
            camera.clone()
        } else if camera.is_callable() {
            camera.call1(((h, w),))?
        } else {
            return Err(wrong_type(
                "camera",
                "a depthpose.Camera or a function of the image shape (H, W) returning one",
                &type_name(camera),
            ));
        };
        let Ok(cam) = cam.cast::<PyCamera>() else {
            return Err(wrong_type("camera", "a depthpose.Camera", &type_name(&cam)));
        };
        let inner = &cam.get().inner;
        if (inner.height, inner.width) != (h, w) {
            return Err(invalid(
                "camera",
                format!(
                    "the camera is {}x{} pixels but {path} is {w}x{h}",
                    inner.width, inner.height
                ),
            ));
        }
        return Ok(cam.clone().unbind());
    }
    let k = match source.intrinsics {
        Some(given) => {
            let values = f64_array(&array_like(given, "intrinsics")?, "intrinsics", None, true)?;
            intrinsics_of(&values.data)?
        }
        None => source.held?.ok_or_else(|| {
            invalid(
                "intrinsics",
                format!("{path} has no camera intrinsics; pass --intrinsics fx fy cx cy"),
            )
        })?,
    };
    Py::new(py, PyCamera::from_values(k, (h, w))?)
}

#[pyfunction]
#[pyo3(signature = (path, *, intrinsics=None, depth_scale=Real::new(0.001), camera=None, pattern=None),
       text_signature = "(path, *, intrinsics=None, depth_scale=0.001, camera=None, pattern=None)")]
fn open_sequence(
    py: Python<'_>,
    path: PathArg,
    intrinsics: Option<Bound<'_, PyAny>>,
    depth_scale: Real,
    camera: Option<Bound<'_, PyAny>>,
    pattern: Option<Bound<'_, PyAny>>,
) -> PyResult<PySequence> {
    let given = path.get("path")?;
    let depth_scale = checks::number(
        depth_scale,
        "depth_scale",
        (Some(MIN_DEPTH_SCALE), Some(MAX_DEPTH_SCALE)),
        false,
    )?;
    let pattern = pattern
        .map(|p| {
            p.extract::<String>()
                .map_err(|_| wrong_type("pattern", "a glob pattern (str)", &type_name(&p)))
        })
        .transpose()?;
    // The path as pathlib spells it, so that messages and `path` agree.
    let path_obj = pathlib(py, &given)?;
    let path: PathBuf = path_obj.extract()?;
    let seq = native(py, || {
        let options = Options {
            depth_scale,
            pattern: pattern.as_deref(),
        };
        sequence::open(&path, &options)
    })?;
    let source = CameraSource {
        camera: camera.as_ref(),
        intrinsics: intrinsics.as_ref(),
        held: seq.intrinsics(),
    };
    let camera = camera_of(py, source, seq.shape, &path_obj.str()?.to_string())?;
    let files = PyList::empty(py);
    for f in &seq.files {
        files.append(pathlib(py, f)?)?;
    }
    Ok(PySequence {
        camera,
        path: path_obj.unbind(),
        files: files.into_any().unbind(),
        background: optional_array(py, seq.background.as_ref())?,
        gt_joints: optional_array(py, seq.gt_joints.as_ref())?,
        inner: Arc::new(seq),
    })
}

/// The camera of frames of `shape` (height, width) at `path`, as `open_sequence`
/// resolves it from `camera` or `intrinsics` (for the stereo sequences).
#[pyfunction]
#[pyo3(signature = (shape, path, *, camera=None, intrinsics=None))]
fn _sequence_camera(
    py: Python<'_>,
    shape: (usize, usize),
    path: PathArg,
    camera: Option<Bound<'_, PyAny>>,
    intrinsics: Option<Bound<'_, PyAny>>,
) -> PyResult<Py<PyCamera>> {
    let path = path.get("path")?;
    let source = CameraSource {
        camera: camera.as_ref(),
        intrinsics: intrinsics.as_ref(),
        held: Ok(None),
    };
    camera_of(py, source, shape, &pathlib(py, &path)?.str()?.to_string())
}

/// The stereo pairs of a folder and its empty-scene pair, as `pathlib.Path`s (for
/// `depthpose.stereo_sequence`).
#[pyfunction]
fn _stereo_pairs(py: Python<'_>, folder: PathArg) -> PyResult<(Py<PyList>, Py<PyAny>)> {
    let folder = folder.get("folder")?;
    let (pairs, bg) = native(py, || sequence::stereo::folder_pairs(&folder))?;
    let pair = |(l, r): &(PathBuf, PathBuf)| -> PyResult<Py<PyAny>> {
        Ok((pathlib(py, l)?, pathlib(py, r)?)
            .into_pyobject(py)?
            .into_any()
            .unbind())
    };
    let list = PyList::empty(py);
    for p in &pairs {
        list.append(pair(p)?)?;
    }
    let bg = match &bg {
        Some(p) => pair(p)?,
        None => py.None(),
    };
    Ok((list.unbind(), bg))
}

#[pymethods]
impl PySequence {
    #[getter]
    fn path(&self, py: Python<'_>) -> Py<PyAny> {
        self.path.clone_ref(py)
    }

    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    #[getter]
    fn kind(&self) -> &'static str {
        self.inner.kind.name()
    }

    #[getter]
    fn n_frames(&self) -> usize {
        self.inner.n_frames
    }

    #[getter]
    fn camera(&self, py: Python<'_>) -> Py<PyCamera> {
        self.camera.clone_ref(py)
    }

    #[getter]
    fn depth_scale(&self) -> f64 {
        self.inner.depth_scale
    }

    #[getter]
    fn background(&self, py: Python<'_>) -> Py<PyAny> {
        self.background.clone_ref(py)
    }

    #[getter]
    fn gt_joints(&self, py: Python<'_>) -> Py<PyAny> {
        self.gt_joints.clone_ref(py)
    }

    #[getter]
    fn fps(&self) -> f64 {
        self.inner.fps
    }

    #[getter]
    fn files(&self, py: Python<'_>) -> Py<PyAny> {
        self.files.clone_ref(py)
    }

    #[pyo3(signature = (start=None, stop=None), text_signature = "($self, start=0, stop=None)")]
    fn frames<'py>(
        &self,
        py: Python<'py>,
        start: Option<Bound<'py, PyAny>>,
        stop: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let zero = 0usize.into_pyobject(py)?.into_any();
        let (start, stop) = range(&self.inner, start.as_ref().unwrap_or(&zero), stop.as_ref())?;
        let seq = Arc::clone(&self.inner);
        let frames = native(py, move || seq.frames(start, Some(stop)))?;
        Ok(to_numpy(py, frames.data, &frames.shape)?.into_any())
    }

    #[pyo3(signature = (start=None, stop=None), text_signature = "($self, start=0, stop=None)")]
    fn iter_frames<'py>(
        &self,
        py: Python<'py>,
        start: Option<Bound<'py, PyAny>>,
        stop: Option<Bound<'py, PyAny>>,
    ) -> PyResult<PyFrames> {
        let zero = 0usize.into_pyobject(py)?.into_any();
        let (start, stop) = range(&self.inner, start.as_ref().unwrap_or(&zero), stop.as_ref())?;
        Ok(PyFrames {
            seq: Arc::clone(&self.inner),
            start,
            next: start,
            stop,
            npz: None,
        })
    }

    fn frame_name(&self, k: i64) -> String {
        self.inner.frame_name(k)
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "Sequence(path={}, kind={:?}, n_frames={}, camera={})",
            self.path.bind(py).repr()?,
            self.inner.kind.name(),
            self.inner.n_frames,
            self.camera.bind(py).repr()?
        ))
    }
}

/// The frames of a sequence one by one: (index, frame or the error reading it raised).
#[pyclass(name = "SequenceFrames", module = "depthpose._core")]
pub struct PyFrames {
    seq: Arc<Sequence>,
    start: usize,
    next: usize,
    stop: usize,
    /// The frames of a `.npz`, read at once on the first step.
    npz: Option<Values<f32>>,
}

#[pymethods]
impl PyFrames {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<(usize, Py<PyAny>)>> {
        let k = self.next;
        if k >= self.stop {
            return Ok(None);
        }
        let (h, w) = self.seq.shape;
        if self.seq.kind == Kind::Npz {
            if self.npz.is_none() {
                let (seq, start, stop) = (Arc::clone(&self.seq), self.start, self.stop);
                self.npz = Some(native(py, move || seq.frames(start, Some(stop)))?);
            }
            let at = (k - self.start) * h * w;
            let frame = self
                .npz
                .as_ref()
                .and_then(|f| f.data.get(at..at + h * w))
                .map(<[f32]>::to_vec)
                .unwrap_or_default();
            self.next += 1;
            return Ok(Some((k, to_numpy(py, frame, &[h, w])?.into_any().unbind())));
        }
        self.next += 1;
        let seq = Arc::clone(&self.seq);
        let item = match native(py, move || seq.frame(k)) {
            Ok(d) => to_numpy(py, d.data, &[h, w])?.into_any().unbind(),
            // A frame's own error is the item, so that the others are read.
            Err(e) if e.is_instance_of::<DepthPoseError>(py) => e.into_value(py).into_any(),
            Err(e) => return Err(e),
        };
        Ok(Some((k, item)))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySequence>()?;
    m.add_class::<PyFrames>()?;
    m.add_function(wrap_pyfunction!(open_sequence, m)?)?;
    m.add_function(wrap_pyfunction!(_sequence_camera, m)?)?;
    m.add_function(wrap_pyfunction!(_stereo_pairs, m)?)?;
    Ok(())
}
