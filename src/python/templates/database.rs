//! `TemplateDatabase`: the 768 rendered template poses with their surface-context
//! descriptors, built, matched against depth images, saved and loaded.

use super::super::body::check_mesh_bytes;
use super::super::camera::PyCamera;
use super::super::convert::{
    bool_array, camera as camera_arg, check_fit_points, counts, depth_array, f32_array, invalid,
    object, to_numpy, Flag, Int, PathArg, Real, Text,
};
use super::super::keywords::keywords;
use super::super::native;
use super::candidate::PyCandidate;
use super::{check_database_bytes, files, model_arg, ImageKeywords, Settings};
use crate::body::superquadric::MeshConfig;
use crate::body::{BodyModel, NUM_JOINTS, NUM_PARAMS, NUM_SHAPE_PARAMS};
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::templates::{
    template_pose, MatchConfig, TemplateConfig, TemplateDatabase, ARM_POSE_NAMES, LEG_POSE_NAMES,
    NUM_TEMPLATES, VIEW_NAMES,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::sync::Arc;

keywords! {
    /// The keyword-only arguments of `TemplateDatabase.match`.
    struct MatchKeywords {
        shortlist: Int = Int::new(16),
        representatives: Int = Int::new(8),
        location_weight: Real = Real::new(0.1),
        dummy_cost: Real = Real::new(0.15),
        rerank: Int = Int::new(0),
    }
}

/// (vertices, faces) of a mesh.
type MeshArrays<'py> = (Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<i64>>);

/// A progress bar over the templates on stderr (`depthpose._progress.progress_bar`:
/// tqdm, drawn only when stderr is a terminal).
pub(super) struct ProgressBar(Py<PyAny>);

impl ProgressBar {
    fn new(py: Python<'_>) -> PyResult<Self> {
        let kwargs = PyDict::new(py);
        kwargs.set_item("unit", "template")?;
        let bar = py.import("depthpose._progress")?.call_method(
            "progress_bar",
            (NUM_TEMPLATES, "templates"),
            Some(&kwargs),
        )?;
        Ok(ProgressBar(bar.unbind()))
    }

    /// Shows `done` of `total` templates; closes the bar when all are done.
    fn report(&self, py: Python<'_>, done: usize, total: usize) -> PyResult<()> {
        let bar = self.0.bind(py);
        bar.setattr("total", total)?;
        let shown: usize = bar.getattr("n")?.extract()?;
        bar.call_method1("update", (done.saturating_sub(shown),))?;
        if done >= total {
            bar.call_method0("close")?;
        }
        Ok(())
    }
}

/// The database of `model` and `cfg`, rendered by Rust or (`trimesh`) ray cast by
/// trimesh, with a progress bar when `progress`.
pub(super) fn build_database(
    py: Python<'_>,
    model: &BodyModel,
    cfg: &TemplateConfig,
    trimesh: bool,
    progress: bool,
) -> PyResult<TemplateDatabase> {
    let bar = progress.then(|| ProgressBar::new(py)).transpose()?;
    if trimesh {
        let depths = raycast_depths(py, model, cfg, bar.as_ref())?;
        if let Some(bar) = &bar {
            bar.report(py, NUM_TEMPLATES, NUM_TEMPLATES)?;
        }
        return from_depths(py, model, cfg, &depths);
    }
    let mut bar_error: Option<PyErr> = None;
    let db = native(py, || {
        TemplateDatabase::build_with_progress(model, cfg, |done, total| {
            if let (Some(bar), None) = (&bar, &bar_error) {
                bar_error = Python::attach(|py| bar.report(py, done, total)).err();
            }
        })
    })?;
    bar_error.map_or(Ok(db), Err)
}

/// Template depth images (768, H, W) of `cfg`'s camera, ray cast by trimesh
/// (`depthpose.templates._raycast_depths`); `bar` advances by one per template.
fn raycast_depths<'py>(
    py: Python<'py>,
    model: &BodyModel,
    cfg: &TemplateConfig,
    bar: Option<&ProgressBar>,
) -> PyResult<Bound<'py, PyAny>> {
    let shape = to_numpy(py, model.shape.to_vec().to_vec(), &[NUM_SHAPE_PARAMS])?;
    let camera = PyCamera {
        inner: cfg.camera()?,
    };
    py.import("depthpose.templates")?.call_method1(
        "_raycast_depths",
        (
            NUM_TEMPLATES,
            shape,
            camera,
            cfg.distance,
            bar.map(|b| b.0.clone_ref(py)),
        ),
    )
}

/// The database of template depth images `depths` (768, H, W) float32 metres rendered
/// for `cfg`'s camera, in template order.
fn from_depths(
    py: Python<'_>,
    model: &BodyModel,
    cfg: &TemplateConfig,
    depths: &Bound<'_, PyAny>,
) -> PyResult<TemplateDatabase> {
    let d = f32_array(depths, "depths", Some(3), false)?;
    let (height, width) = (cfg.height, cfg.width);
    if d.shape != [NUM_TEMPLATES, height, width] {
        return Err(invalid(
            "depths",
            format!(
                "expected shape ({NUM_TEMPLATES}, {height}, {width}), got {:?}",
                d.shape
            ),
        ));
    }
    native(py, || TemplateDatabase::from_depths(model, cfg, &d.data))
}

/// 768 rendered template poses with their surface-context descriptors.
#[pyclass(name = "TemplateDatabase", module = "depthpose._core", frozen)]
pub struct PyTemplateDatabase {
    pub(super) inner: Arc<TemplateDatabase>,
}

impl PyTemplateDatabase {
    pub(super) fn new(db: TemplateDatabase) -> Self {
        PyTemplateDatabase {
            inner: Arc::new(db),
        }
    }

    /// The database, shared (an estimator keeps it without copying it).
    pub(crate) fn shared(&self) -> Arc<TemplateDatabase> {
        self.inner.clone()
    }

    /// The cached default database ([`files::default`]), shared.
    pub(crate) fn default_shared(py: Python<'_>) -> PyResult<Arc<TemplateDatabase>> {
        Ok(files::default(py, true)?.get().shared())
    }

    /// The candidates and the short list of the body in `depth`.
    fn candidates(
        &self,
        py: Python<'_>,
        frame: (
            &Bound<'_, PyAny>,
            &Bound<'_, PyAny>,
            Option<&Bound<'_, PyAny>>,
        ),
        top_k: &Int,
        matching: Option<&Bound<'_, PyDict>>,
        function: &str,
    ) -> PyResult<(Vec<PyCandidate>, Vec<usize>)> {
        let (depth, camera, mask) = frame;
        let k = MatchKeywords::parse(function, matching)?;
        let cam = camera_arg(camera, "camera")?;
        let top_k = top_k.count("top_k")?;
        let rerank = k.rerank.count("rerank")?;
        let cfg = MatchConfig {
            top_k,
            shortlist: k.shortlist.count("shortlist")?.max(top_k).max(rerank),
            representatives: k.representatives.count("representatives")?,
            location_weight: k.location_weight.get("location_weight")?,
            dummy_cost: k.dummy_cost.get("dummy_cost")?,
            rerank,
        };
        cfg.validate()?;
        let d = depth_array(depth, "depth")?;
        let m = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
        check_fit_points(&d.data, m.as_deref(), 0, "depth")?;
        let r = native(py, || -> crate::Result<_> {
            let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
            self.inner.match_depth(&view, &cam, m.as_deref(), &cfg)
        })?;
        let found = r
            .candidates
            .into_iter()
            .map(|inner| PyCandidate { inner })
            .collect();
        Ok((found, r.shortlist))
    }
}

#[pymethods]
impl PyTemplateDatabase {
    #[classattr]
    #[pyo3(name = "ARM_POSES")]
    fn arm_poses(py: Python<'_>) -> PyResult<Bound<'_, PyTuple>> {
        PyTuple::new(py, ARM_POSE_NAMES)
    }

    #[classattr]
    #[pyo3(name = "LEG_POSES")]
    fn leg_poses(py: Python<'_>) -> PyResult<Bound<'_, PyTuple>> {
        PyTuple::new(py, LEG_POSE_NAMES)
    }

    #[classattr]
    #[pyo3(name = "VIEWS")]
    fn views_names(py: Python<'_>) -> PyResult<Bound<'_, PyTuple>> {
        PyTuple::new(py, VIEW_NAMES)
    }

    #[staticmethod]
    #[pyo3(signature = (model=None, camera=None, *, renderer=None, progress=Flag::new(true),
                        **settings),
           text_signature = "(model=None, camera=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric', samples=100, \
                             radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0, \
                             progress=True)")]
    fn build(
        py: Python<'_>,
        model: Option<&Bound<PyAny>>,
        camera: Option<&Bound<PyAny>>,
        renderer: Option<Text>,
        progress: Flag,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<Self> {
        let camera: Option<Camera> = camera
            .filter(|c| !c.is_none())
            .map(|c| object::<PyCamera>(c, "camera", "a depthpose.Camera or None").map(|c| c.inner))
            .transpose()?;
        let progress = progress.get("progress")?;
        let model = model_arg(model)?;
        let mut s = Settings::parse("TemplateDatabase.build", renderer, settings)?;
        if let Some(c) = camera {
            s.image.width = Int::new(c.width as i128);
            s.image.height = Int::new(c.height as i128);
        }
        let cfg = s.config(true)?;
        check_database_bytes(&cfg)?;
        Ok(Self::new(build_database(
            py,
            &model,
            &cfg,
            s.trimesh(),
            progress,
        )?))
    }

    #[staticmethod]
    #[pyo3(signature = (depths, model=None, **settings),
           text_signature = "(depths, model=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, samples=100, radial_bins=5, angular_bins=12, \
                             seed=0, depth_weight=0.0)")]
    fn from_depths(
        py: Python<'_>,
        depths: &Bound<PyAny>,
        model: Option<&Bound<PyAny>>,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<Self> {
        let model = model_arg(model)?;
        let cfg = Settings::parse("TemplateDatabase.from_depths", None, settings)?.config(false)?;
        check_database_bytes(&cfg)?;
        Ok(Self::new(from_depths(py, &model, &cfg, depths)?))
    }

    #[staticmethod]
    #[pyo3(signature = (index, model=None, *, renderer=None, **image),
           text_signature = "(index, model=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric')")]
    fn render_template<'py>(
        py: Python<'py>,
        index: Int,
        model: Option<&Bound<'py, PyAny>>,
        renderer: Option<Text>,
        image: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let image = ImageKeywords::parse("TemplateDatabase.render_template", image)?;
        let index = index.in_range(0, NUM_TEMPLATES as i128 - 1, "index")? as usize;
        let model = model_arg(model)?;
        let cfg = Settings {
            image,
            renderer,
            ..Settings::default()
        }
        .config(false)?;
        let depth = native(py, || {
            crate::templates::render_template(&model, &cfg, index)
        })?;
        to_numpy(py, depth, &[cfg.height, cfg.width])
    }

    #[staticmethod]
    #[pyo3(signature = (index, model=None, *, distance=Real::new(3.0), rings=Int::new(16),
                        sectors=Int::new(20)),
           text_signature = "(index, model=None, *, distance=3.0, rings=16, sectors=20)")]
    fn template_mesh<'py>(
        py: Python<'py>,
        index: Int,
        model: Option<&Bound<'py, PyAny>>,
        distance: Real,
        rings: Int,
        sectors: Int,
    ) -> PyResult<MeshArrays<'py>> {
        let index = index.in_range(0, NUM_TEMPLATES as i128 - 1, "index")? as usize;
        let (rings, sectors) = (rings.count("rings")?, sectors.count("sectors")?);
        check_mesh_bytes(rings, sectors, crate::body::NUM_SEGMENTS)?;
        let distance = distance.get("distance")?;
        crate::error::ensure_positive(distance, "distance")?;
        let model = model_arg(model)?;
        let meshes = native(py, || {
            model.superquadric_meshes(
                &template_pose(index, distance),
                &MeshConfig { rings, sectors },
            )
        })?;
        let (mut v, mut f) = (Vec::new(), Vec::new());
        for m in &meshes {
            let base = (v.len() / 3) as i64;
            v.extend(m.vertices.iter().flatten());
            f.extend(m.faces.iter().flatten().map(|&i| base + i as i64));
        }
        let (nv, nf) = (v.len() / 3, f.len() / 3);
        Ok((to_numpy(py, v, &[nv, 3])?, to_numpy(py, f, &[nf, 3])?))
    }

    #[pyo3(name = "match",
           signature = (depth, camera, mask=None, top_k=Int::new(5), **matching),
           text_signature = "($self, depth, camera, mask=None, top_k=5, *, shortlist=16, \
                             representatives=8, location_weight=0.1, dummy_cost=0.15, \
                             rerank=0)")]
    fn match_depth(
        &self,
        py: Python<'_>,
        depth: &Bound<'_, PyAny>,
        camera: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
        top_k: Int,
        matching: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Vec<PyCandidate>> {
        let frame = (depth, camera, mask);
        Ok(self
            .candidates(py, frame, &top_k, matching, "TemplateDatabase.match")?
            .0)
    }

    #[pyo3(signature = (depth, camera, mask=None, top_k=Int::new(5), **matching),
           text_signature = "($self, depth, camera, mask=None, top_k=5, *, shortlist=16, \
                             representatives=8, location_weight=0.1, dummy_cost=0.15, \
                             rerank=0)")]
    fn match_with_shortlist(
        &self,
        py: Python<'_>,
        depth: &Bound<'_, PyAny>,
        camera: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
        top_k: Int,
        matching: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<(Vec<PyCandidate>, Vec<usize>)> {
        let frame = (depth, camera, mask);
        let function = "TemplateDatabase.match_with_shortlist";
        self.candidates(py, frame, &top_k, matching, function)
    }

    #[pyo3(signature = (depth, camera, indices, mask=None, *, location_weight=Real::new(0.1),
                        dummy_cost=Real::new(0.15)),
           text_signature = "($self, depth, camera, indices, mask=None, *, location_weight=0.1, \
                             dummy_cost=0.15)")]
    fn exact_costs<'py>(
        &self,
        depth: &Bound<'py, PyAny>,
        camera: &Bound<'py, PyAny>,
        indices: &Bound<'py, PyAny>,
        mask: Option<&Bound<'py, PyAny>>,
        location_weight: Real,
        dummy_cost: Real,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let py = depth.py();
        let cam = camera_arg(camera, "camera")?;
        let (location_weight, dummy_cost) = (
            location_weight.get("location_weight")?,
            dummy_cost.get("dummy_cost")?,
        );
        MatchConfig {
            location_weight,
            dummy_cost,
            ..MatchConfig::default()
        }
        .validate()?;
        let indices = counts(indices, "indices")?;
        if let Some(&bad) = indices.iter().find(|&&i| i >= self.inner.len()) {
            return Err(invalid("indices", format!("{bad} is not a template")));
        }
        let d = depth_array(depth, "depth")?;
        let m = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
        check_fit_points(&d.data, m.as_deref(), 0, "depth")?;
        let costs = native(py, || -> crate::Result<Vec<f64>> {
            use rayon::prelude::*;
            let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
            let dc = &self.inner.config.descriptor;
            let sil = crate::descriptor::Silhouette::from_depth(
                &view,
                &cam,
                m.as_deref(),
                dc.normal_radius,
            )?;
            let q = sil.surface_context(dc)?;
            Ok(indices
                .par_iter()
                .map_init(
                    || (Default::default(), Vec::new(), Vec::new()),
                    |(ws, c, a), &t| {
                        crate::templates::matching_cost(
                            &q,
                            &self.inner.templates[t].context,
                            location_weight,
                            dummy_cost,
                            ws,
                            c,
                            a,
                        )
                    },
                )
                .collect())
        })?;
        let n = costs.len();
        to_numpy(py, costs, &[n])
    }

    fn save(&self, py: Python<'_>, path: PathArg) -> PyResult<()> {
        files::save(py, &self.inner, &path.get("path")?)
    }

    #[staticmethod]
    #[pyo3(signature = (path, model=None, *, renderer=None, **settings),
           text_signature = "(path, model=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric', samples=100, \
                             radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0)")]
    fn load(
        py: Python<'_>,
        path: PathArg,
        model: Option<&Bound<PyAny>>,
        renderer: Option<Text>,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<Self> {
        let path = path.get("path")?;
        let given = model.is_some_and(|m| !m.is_none())
            || renderer.is_some()
            || settings.is_some_and(|s| !s.is_empty());
        let s = Settings::parse("TemplateDatabase.load", renderer, settings)?;
        let expected = if given {
            Some((model_arg(model)?, s.config(false)?))
        } else {
            None
        };
        Ok(Self::new(files::load(py, &path, expected.as_ref())?))
    }

    #[staticmethod]
    fn default_path() -> PyResult<std::path::PathBuf> {
        files::default_path()
    }

    #[staticmethod]
    #[pyo3(signature = (*, progress=Flag::new(true)), text_signature = "(*, progress=True)")]
    fn default(py: Python<'_>, progress: Flag) -> PyResult<Py<Self>> {
        files::default(py, progress.get("progress")?)
    }

    /// The settings hash of a database of `model` and the settings (hex), as
    /// `TemplateDatabase.hash` gives it.
    #[staticmethod]
    #[pyo3(signature = (model=None, *, renderer=None, **settings),
           text_signature = "(model=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric', samples=100, \
                             radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0)")]
    fn _settings_hash(
        model: Option<&Bound<PyAny>>,
        renderer: Option<Text>,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<String> {
        let model = model_arg(model)?;
        let s = Settings::parse("TemplateDatabase._settings_hash", renderer, settings)?;
        let cfg = s.config(true)?;
        Ok(format!(
            "{:016x}",
            TemplateDatabase::settings_hash(&model, &cfg)
        ))
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    #[getter]
    fn hash(&self) -> String {
        format!("{:016x}", self.inner.hash())
    }

    #[getter]
    fn model_shape<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(
            py,
            self.inner.model.shape.to_vec().to_vec(),
            &[NUM_SHAPE_PARAMS],
        )
    }

    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let v: Vec<f64> = self.inner.templates.iter().flat_map(|t| t.pose).collect();
        to_numpy(py, v, &[self.inner.len(), NUM_PARAMS])
    }

    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let v: Vec<f64> = self
            .inner
            .templates
            .iter()
            .flat_map(|t| t.joints.iter().flatten().copied().collect::<Vec<_>>())
            .collect();
        to_numpy(py, v, &[self.inner.len(), NUM_JOINTS, 3])
    }

    #[getter]
    fn views(&self) -> Vec<usize> {
        self.inner.templates.iter().map(|t| t.view).collect()
    }

    #[getter]
    fn camera(&self) -> PyResult<PyCamera> {
        Ok(PyCamera {
            inner: self.inner.config.camera()?,
        })
    }

    fn __repr__(&self) -> String {
        let c = &self.inner.config;
        format!(
            "TemplateDatabase({} templates, {}x{} pixels, {} samples, hash {:016x})",
            self.inner.len(),
            c.width,
            c.height,
            c.descriptor.samples,
            self.inner.hash()
        )
    }
}
