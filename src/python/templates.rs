//! Surface-context descriptors and the template database, for Python.

use super::body::check_mesh_bytes;
use super::camera::PyCamera;
use super::convert::{
    bool_array, camera as camera_arg, check_fit_points, check_result_bytes, counts, depth_array,
    f32_array, f64_array, i64_array, invalid, to_numpy, wrong_type, Int, Real, Text,
};
use super::keywords::{check_names, keywords};
use super::native;
use crate::body::superquadric::MeshConfig;
use crate::body::{BodyModel, BodyShape, NUM_JOINTS, NUM_PARAMS, NUM_SHAPE_PARAMS};
use crate::cloud::DepthView;
use crate::descriptor::{surface_context_from_depth, DescriptorConfig};
use crate::templates::{
    config_from_vec, template_pose, MatchConfig, TemplateArrays, TemplateConfig, TemplateDatabase,
    TemplateRenderer, MAX_SEED, NUM_TEMPLATES,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn model_of(shape: Option<&Bound<PyAny>>) -> PyResult<BodyModel> {
    match shape {
        None => Ok(BodyModel::default()),
        Some(s) => {
            let a = f64_array(s, "model_shape", Some(1), true)?;
            Ok(BodyModel::with_shape(BodyShape::from_vec(&a.data)?))
        }
    }
}

keywords! {
    /// The template image settings, keyword arguments of the template database's
    /// builders (see `TemplateDatabase.build`).
    struct ImageKeywords {
        width: Int = Int::new(96),
        height: Int = Int::new(96),
        distance: Real = Real::new(3.0),
        field_height: Real = Real::new(2.4),
    }
}

keywords! {
    /// The surface-context settings, keyword arguments of `surface_context` and of the
    /// template database's builders.
    struct DescriptorKeywords {
        samples: Int = Int::new(100),
        radial_bins: Int = Int::new(5),
        angular_bins: Int = Int::new(12),
        seed: Int = Int::new(0),
        depth_weight: Real = Real::new(0.0),
    }
}

keywords! {
    /// The keyword arguments of `_TemplateDatabase.match_depth`.
    struct MatchKeywords {
        top_k: Int = Int::new(5),
        shortlist: Int = Int::new(16),
        representatives: Int = Int::new(8),
        location_weight: Real = Real::new(0.1),
        dummy_cost: Real = Real::new(0.15),
        rerank: Int = Int::new(0),
    }
}

/// The template settings as Python passes them (see `TemplateDatabase.build`).
struct Settings {
    image: ImageKeywords,
    renderer: Option<Text>,
    descriptor: DescriptorKeywords,
}

impl Settings {
    /// The image and descriptor settings in `kwargs` (`function`'s keyword arguments
    /// besides `renderer`).
    fn parse(
        function: &str,
        renderer: Option<Text>,
        kwargs: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        check_names(
            function,
            kwargs,
            &[ImageKeywords::NAMES, DescriptorKeywords::NAMES],
        )?;
        Ok(Settings {
            image: ImageKeywords::take(kwargs)?,
            renderer,
            descriptor: DescriptorKeywords::take(kwargs)?,
        })
    }

    /// The checked configuration.
    fn config(&self) -> PyResult<TemplateConfig> {
        let renderer = match &self.renderer {
            None => TemplateRenderer::Superquadric,
            Some(r) => match r.get("renderer")? {
                "superquadric" => TemplateRenderer::Superquadric,
                "ellipsoid" => TemplateRenderer::Ellipsoid,
                other => {
                    return Err(invalid(
                        "renderer",
                        format!(
                            "must be 'superquadric' or 'ellipsoid', got {}",
                            crate::error::brief_text(other)
                        ),
                    ))
                }
            },
        };
        let (image, descriptor) = (&self.image, &self.descriptor);
        let seed = descriptor.seed.in_range(0, MAX_SEED as i128 - 1, "seed")? as u64;
        let d = TemplateConfig::default();
        let c = TemplateConfig {
            width: image.width.count("width")?,
            height: image.height.count("height")?,
            distance: image.distance.get("distance")?,
            field_height: image.field_height.get("field_height")?,
            renderer,
            descriptor: DescriptorConfig {
                samples: descriptor.samples.count("samples")?,
                radial_bins: descriptor.radial_bins.count("radial_bins")?,
                angular_bins: descriptor.angular_bins.count("angular_bins")?,
                seed,
                depth_weight: descriptor.depth_weight.get("depth_weight")?,
                ..d.descriptor
            },
            ..d
        };
        c.validate()?;
        Ok(c)
    }

    /// [`Self::config`] for a whole database, whose descriptors must fit
    /// `MAX_RESULT_BYTES`.
    fn database_config(&self) -> PyResult<TemplateConfig> {
        let c = self.config()?;
        let bytes = NUM_TEMPLATES
            .checked_mul(c.descriptor.samples)
            .and_then(|n| n.checked_mul(c.descriptor.dim() * 4 + 16));
        check_result_bytes(bytes, "samples", "the template descriptors")?;
        Ok(c)
    }
}

/// (vertices, faces) of a mesh.
type MeshArrays<'py> = (Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<i64>>);

/// Three float32 arrays.
type F32Arrays<'py> = (
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
);

/// Surface-context descriptors of the (masked) body in `depth`: (descriptors (N, 3·bins,
/// or 4·bins with `depth_weight` > 0)
/// float32, sample pixels (N, 2) float32 as [u, v], normalised positions (N, 2)).
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None, **descriptor),
       text_signature = "(depth, camera, mask=None, *, samples=100, radial_bins=5, \
                         angular_bins=12, seed=0, depth_weight=0.0)")]
fn surface_context<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    mask: Option<&Bound<'py, PyAny>>,
    descriptor: Option<&Bound<'py, PyDict>>,
) -> PyResult<F32Arrays<'py>> {
    let k = DescriptorKeywords::parse("surface_context", descriptor)?;
    let cam = camera_arg(camera, "camera")?;
    let cfg = DescriptorConfig {
        samples: k.samples.count("samples")?,
        radial_bins: k.radial_bins.count("radial_bins")?,
        angular_bins: k.angular_bins.count("angular_bins")?,
        seed: k.seed.seed("seed")?,
        depth_weight: k.depth_weight.get("depth_weight")?,
        ..Default::default()
    };
    cfg.validate()?;
    let d = depth_array(depth, "depth")?;
    let m = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
    check_fit_points(&d.data, m.as_deref(), 0, "depth")?;
    let sc = native(py, || -> crate::Result<_> {
        let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
        surface_context_from_depth(&view, &cam, m.as_deref(), &cfg)
    })?;
    let n = sc.len();
    Ok((
        to_numpy(py, sc.descriptors, &[n, sc.dim])?,
        to_numpy(py, sc.pixels.into_iter().flatten().collect(), &[n, 2])?,
        to_numpy(py, sc.positions.into_iter().flatten().collect(), &[n, 2])?,
    ))
}

/// The native template database (see `depthpose.templates.TemplateDatabase`).
#[pyclass(name = "_TemplateDatabase", module = "depthpose._core", frozen)]
pub struct PyTemplateDatabase {
    inner: std::sync::Arc<TemplateDatabase>,
}

impl PyTemplateDatabase {
    /// The database, shared (an estimator keeps it without copying it).
    pub(crate) fn shared(&self) -> std::sync::Arc<TemplateDatabase> {
        self.inner.clone()
    }
}

#[pymethods]
impl PyTemplateDatabase {
    /// Renders and describes all templates; `progress(done, total)` is called after
    /// each chunk.
    #[staticmethod]
    #[pyo3(signature = (model_shape=None, *, renderer=None, progress=None, **settings),
           text_signature = "(model_shape=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric', samples=100, \
                             radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0, \
                             progress=None)")]
    fn build(
        py: Python<'_>,
        model_shape: Option<&Bound<PyAny>>,
        renderer: Option<Text>,
        progress: Option<Py<PyAny>>,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<Self> {
        let model = model_of(model_shape)?;
        let cfg =
            Settings::parse("_TemplateDatabase.build", renderer, settings)?.database_config()?;
        if let Some(cb) = &progress {
            if !cb.bind(py).is_callable() {
                return Err(wrong_type(
                    "progress",
                    "a callable or None",
                    &cb.bind(py)
                        .get_type()
                        .name()
                        .map(|n| n.to_string())
                        .unwrap_or_default(),
                ));
            }
        }
        let mut callback_error: Option<PyErr> = None;
        let db = native(py, || {
            TemplateDatabase::build_with_progress(&model, &cfg, |done, total| {
                if let (Some(cb), None) = (&progress, &callback_error) {
                    Python::attach(|py| {
                        if let Err(e) = cb.call1(py, (done, total)) {
                            callback_error = Some(e);
                        }
                    });
                }
            })
        })?;
        if let Some(e) = callback_error {
            return Err(e);
        }
        Ok(PyTemplateDatabase {
            inner: std::sync::Arc::new(db),
        })
    }

    /// A database from template depth images rendered elsewhere: `depths` (768, H, W)
    /// float32 metres for the camera of the settings, in template order.
    #[staticmethod]
    #[pyo3(signature = (depths, model_shape=None, **settings),
           text_signature = "(depths, model_shape=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, samples=100, radial_bins=5, angular_bins=12, \
                             seed=0, depth_weight=0.0)")]
    fn from_depths(
        py: Python<'_>,
        depths: &Bound<PyAny>,
        model_shape: Option<&Bound<PyAny>>,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<Self> {
        let model = model_of(model_shape)?;
        let cfg =
            Settings::parse("_TemplateDatabase.from_depths", None, settings)?.database_config()?;
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
        let db = native(py, || TemplateDatabase::from_depths(&model, &cfg, &d.data))?;
        Ok(PyTemplateDatabase {
            inner: std::sync::Arc::new(db),
        })
    }

    /// Depth image (H, W) float32 of template `index` rendered in Rust.
    #[staticmethod]
    #[pyo3(signature = (index, model_shape=None, *, renderer=None, **image),
           text_signature = "(index, model_shape=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric')")]
    fn render_template<'py>(
        py: Python<'py>,
        index: Int,
        model_shape: Option<&Bound<'py, PyAny>>,
        renderer: Option<Text>,
        image: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let image = ImageKeywords::parse("_TemplateDatabase.render_template", image)?;
        let index = index.in_range(0, NUM_TEMPLATES as i128 - 1, "index")? as usize;
        let model = model_of(model_shape)?;
        let cfg = Settings {
            image,
            renderer,
            descriptor: DescriptorKeywords::default(),
        }
        .config()?;
        let depth = native(py, || {
            crate::templates::render_template(&model, &cfg, index)
        })?;
        to_numpy(py, depth, &[cfg.height, cfg.width])
    }

    /// Super-quadric meshes of template `index` (all segments in one mesh, template
    /// camera frame): (vertices (V, 3) float64, faces (F, 3) int64).
    #[staticmethod]
    #[pyo3(signature = (index, model_shape=None, *, distance=Real::new(3.0), rings=Int::new(16),
                        sectors=Int::new(20)),
           text_signature = "(index, model_shape=None, *, distance=3.0, rings=16, sectors=20)")]
    fn template_mesh<'py>(
        py: Python<'py>,
        index: Int,
        model_shape: Option<&Bound<'py, PyAny>>,
        distance: Real,
        rings: Int,
        sectors: Int,
    ) -> PyResult<MeshArrays<'py>> {
        let index = index.in_range(0, NUM_TEMPLATES as i128 - 1, "index")? as usize;
        let (rings, sectors) = (rings.count("rings")?, sectors.count("sectors")?);
        check_mesh_bytes(rings, sectors, crate::body::NUM_SEGMENTS)?;
        let distance = distance.get("distance")?;
        crate::error::ensure_positive(distance, "distance")?;
        let model = model_of(model_shape)?;
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

    /// Matches the body in `depth` (H, W) metres; candidates best first, as dicts with
    /// index, view, pose (22,), joints (15, 3), cost, prune_cost, scale; and the short
    /// list of the pruning stage.
    #[pyo3(signature = (depth, camera, mask=None, **matching),
           text_signature = "($self, depth, camera, mask=None, *, top_k=5, shortlist=16, \
                             representatives=8, location_weight=0.1, dummy_cost=0.15, \
                             rerank=0)")]
    fn match_depth<'py>(
        &self,
        py: Python<'py>,
        depth: &Bound<'py, PyAny>,
        camera: &Bound<'py, PyAny>,
        mask: Option<&Bound<'py, PyAny>>,
        matching: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<(Vec<Bound<'py, PyDict>>, Vec<usize>)> {
        let MatchKeywords {
            top_k,
            shortlist,
            representatives,
            location_weight,
            dummy_cost,
            rerank,
        } = MatchKeywords::parse("_TemplateDatabase.match_depth", matching)?;
        let cam = camera_arg(camera, "camera")?;
        let top_k = top_k.count("top_k")?;
        let rerank = rerank.count("rerank")?;
        let shortlist = shortlist.count("shortlist")?;
        let cfg = MatchConfig {
            top_k,
            shortlist: shortlist.max(top_k).max(rerank),
            representatives: representatives.count("representatives")?,
            location_weight: location_weight.get("location_weight")?,
            dummy_cost: dummy_cost.get("dummy_cost")?,
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
        let mut out = Vec::with_capacity(r.candidates.len());
        for c in r.candidates {
            let dict = PyDict::new(py);
            dict.set_item("index", c.index)?;
            dict.set_item("view", c.view)?;
            dict.set_item("pose", to_numpy(py, c.pose.to_vec(), &[NUM_PARAMS])?)?;
            dict.set_item(
                "joints",
                to_numpy(
                    py,
                    c.joints.iter().flatten().copied().collect(),
                    &[NUM_JOINTS, 3],
                )?,
            )?;
            dict.set_item("cost", c.cost)?;
            dict.set_item("prune_cost", c.prune_cost)?;
            dict.set_item("scale", c.scale)?;
            out.push(dict);
        }
        Ok((out, r.shortlist))
    }

    /// Exact matching costs of the body in `depth` against the given templates (no
    /// pruning): for measuring the pruning stage.
    #[pyo3(signature = (depth, camera, indices, mask=None, *, location_weight=Real::new(0.1),
                        dummy_cost=Real::new(0.15)),
           text_signature = "($self, depth, camera, indices, mask=None, *, location_weight=0.1, \
                             dummy_cost=0.15)")]
    fn exact_costs(
        &self,
        depth: &Bound<PyAny>,
        camera: &Bound<PyAny>,
        indices: &Bound<PyAny>,
        mask: Option<&Bound<PyAny>>,
        location_weight: Real,
        dummy_cost: Real,
    ) -> PyResult<Vec<f64>> {
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
        let r = native(depth.py(), || -> crate::Result<Vec<f64>> {
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
        Ok(r)
    }

    /// The database as a dict of numpy arrays (for saving).
    fn to_arrays<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let a = self.inner.to_arrays();
        let t = self.inner.len();
        let s = a.counts.iter().sum::<i64>() as usize;
        let dim = self.inner.config.descriptor.dim();
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

    /// A database from `to_arrays` output; `source` names the file in errors. With
    /// `model_shape`/`config` given, refuses a database built for another model or
    /// other settings (FileFormatError). Every entry must be a numpy array (or, for
    /// `format_version` and `hash`, an integer and a hex string): anything else is a
    /// FileFormatError naming the entry.
    #[staticmethod]
    #[pyo3(signature = (arrays, source, model_shape=None, config=None))]
    fn from_arrays(
        py: Python<'_>,
        arrays: &Bound<PyAny>,
        source: Text,
        model_shape: Option<&Bound<PyAny>>,
        config: Option<&Bound<PyAny>>,
    ) -> PyResult<Self> {
        let source = source.get("source")?.to_string();
        let arrays = arrays.cast::<PyDict>().map_err(|_| {
            wrong_type(
                "arrays",
                "a dict of numpy arrays",
                &arrays
                    .get_type()
                    .name()
                    .map(|n| n.to_string())
                    .unwrap_or_default(),
            )
        })?;
        let file_err = |msg: String| -> PyErr { crate::Error::file(&source, msg).into() };
        let get = |k: &str| -> PyResult<Bound<PyAny>> {
            arrays
                .get_item(k)?
                .ok_or_else(|| file_err(format!("missing entry {k:?}")))
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
        let i64s = |k: &str| -> PyResult<Vec<i64>> {
            Ok(i64_array(&get(k)?, k, None).map_err(entry)?.data)
        };
        let version = get("format_version")?
            .extract::<Int>()
            .map_err(|_| file_err("format_version is not an integer".into()))?
            .in_range(0, i128::from(u32::MAX), "format_version")
            .map_err(entry)?;
        let hash_s: String = get("hash")?
            .extract()
            .map_err(|_| file_err("hash is not a string".into()))?;
        let hash = u64::from_str_radix(&hash_s, 16).map_err(|_| {
            file_err(format!(
                "hash {:?} is not hexadecimal",
                hash_s.chars().take(40).collect::<String>()
            ))
        })?;
        let a = TemplateArrays {
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
        };
        let expected = match (model_shape, config) {
            (Some(s), Some(c)) => {
                let model = model_of(Some(s))?;
                let cfg = config_from_vec(&f64_array(c, "config", Some(1), true)?.data)?;
                Some((model, cfg))
            }
            (None, None) => None,
            _ => return Err(invalid("model_shape/config", "give both or neither")),
        };
        let db = native(py, || {
            TemplateDatabase::from_arrays(&a, expected.as_ref().map(|(m, c)| (m, c)), &source)
        })?;
        Ok(PyTemplateDatabase {
            inner: std::sync::Arc::new(db),
        })
    }

    /// The settings hash this database's model and settings give (hex).
    #[staticmethod]
    #[pyo3(signature = (model_shape=None, *, renderer=None, **settings),
           text_signature = "(model_shape=None, *, width=96, height=96, distance=3.0, \
                             field_height=2.4, renderer='superquadric', samples=100, \
                             radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0)")]
    fn settings(
        py: Python<'_>,
        model_shape: Option<&Bound<PyAny>>,
        renderer: Option<Text>,
        settings: Option<&Bound<PyDict>>,
    ) -> PyResult<(String, Py<PyAny>)> {
        let model = model_of(model_shape)?;
        let cfg = Settings::parse("_TemplateDatabase.settings", renderer, settings)?.config()?;
        let v = crate::templates::config_to_vec(&cfg).to_vec();
        let n = v.len();
        Ok((
            format!("{:016x}", TemplateDatabase::settings_hash(&model, &cfg)),
            to_numpy(py, v, &[n])?.into_any().unbind(),
        ))
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

    /// Template poses (768, 22) as rendered.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let v: Vec<f64> = self.inner.templates.iter().flat_map(|t| t.pose).collect();
        to_numpy(py, v, &[self.inner.len(), NUM_PARAMS])
    }

    /// Template joints (768, 15, 3), template camera frame.
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

    /// View of each template (0 front, 1 left side, 2 right side).
    #[getter]
    fn views(&self) -> Vec<usize> {
        self.inner.templates.iter().map(|t| t.view).collect()
    }

    /// The camera the templates were rendered with.
    #[getter]
    fn camera(&self) -> PyResult<PyCamera> {
        Ok(PyCamera {
            inner: self.inner.config.camera()?,
        })
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }
}

/// Shape parameters (27,) of the default body model.
#[pyfunction]
fn _default_model_shape(py: Python<'_>) -> PyResult<Bound<'_, PyArrayDyn<f64>>> {
    to_numpy(
        py,
        BodyModel::default().shape.to_vec().to_vec(),
        &[NUM_SHAPE_PARAMS],
    )
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_default_model_shape, m)?)?;
    m.add_function(wrap_pyfunction!(surface_context, m)?)?;
    m.add_class::<PyTemplateDatabase>()?;
    Ok(())
}
