//! Surface-context descriptors and the template database, for Python.

use super::arrays::{
    bool_array, count, depth_array, f32_array, f64_array, i64_array, seed as arg_seed, to_numpy,
};
use super::camera::PyCamera;
use super::native;
use crate::body::superquadric::MeshConfig;
use crate::body::{BodyModel, BodyShape, NUM_JOINTS, NUM_PARAMS, NUM_SHAPE_PARAMS};
use crate::cloud::DepthView;
use crate::descriptor::{surface_context_from_depth, DescriptorConfig};
use crate::templates::{
    config_from_vec, template_pose, MatchConfig, TemplateArrays, TemplateConfig, TemplateDatabase,
    TemplateRenderer, MAX_SEED, NUM_TEMPLATES,
};
use crate::Error;
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

#[allow(clippy::too_many_arguments)]
fn config_of(
    width: i128,
    height: i128,
    distance: f64,
    field_height: f64,
    renderer: &str,
    samples: i128,
    radial_bins: i128,
    angular_bins: i128,
    seed: i128,
    depth_weight: f64,
) -> PyResult<TemplateConfig> {
    let (width, height) = (count(width, "width")?, count(height, "height")?);
    let samples = count(samples, "samples")?;
    let radial_bins = count(radial_bins, "radial_bins")?;
    let angular_bins = count(angular_bins, "angular_bins")?;
    let seed = arg_seed(seed, "seed")?;
    let renderer = match renderer {
        "superquadric" => TemplateRenderer::Superquadric,
        "ellipsoid" => TemplateRenderer::Ellipsoid,
        other => {
            return Err(Error::invalid(
                "renderer",
                format!("must be 'superquadric' or 'ellipsoid', got {other:?}"),
            )
            .into())
        }
    };
    if seed >= MAX_SEED {
        return Err(Error::invalid("seed", format!("must be < 2**53, got {seed}")).into());
    }
    let d = TemplateConfig::default();
    let c = TemplateConfig {
        width,
        height,
        distance,
        field_height,
        renderer,
        descriptor: DescriptorConfig {
            samples,
            radial_bins,
            angular_bins,
            seed,
            depth_weight,
            ..d.descriptor
        },
        ..d
    };
    c.validate()?;
    Ok(c)
}

/// (vertices, faces) of a mesh.
type MeshArrays<'py> = (Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<i64>>);

/// Surface-context descriptors of the (masked) body in `depth`: (descriptors (N, 3·bins,
/// or 4·bins with `depth_weight` > 0)
/// float32, sample pixels (N, 2) float32 as [u, v], normalised positions (N, 2)).
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None, *, samples=100, radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn surface_context<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &PyCamera,
    mask: Option<&Bound<'py, PyAny>>,
    samples: i128,
    radial_bins: i128,
    angular_bins: i128,
    seed: i128,
    depth_weight: f64,
) -> PyResult<(
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
)> {
    let d = depth_array(depth, "depth")?;
    let m = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
    let cfg = DescriptorConfig {
        samples: count(samples, "samples")?,
        radial_bins: count(radial_bins, "radial_bins")?,
        angular_bins: count(angular_bins, "angular_bins")?,
        seed: arg_seed(seed, "seed")?,
        depth_weight,
        ..Default::default()
    };
    let sc = native(py, || -> crate::Result<_> {
        let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
        surface_context_from_depth(&view, &camera.inner, m.as_deref(), &cfg)
    })?;
    let n = sc.len();
    Ok((
        to_numpy(py, sc.descriptors, &[n, sc.dim]),
        to_numpy(py, sc.pixels.into_iter().flatten().collect(), &[n, 2]),
        to_numpy(py, sc.positions.into_iter().flatten().collect(), &[n, 2]),
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
    #[pyo3(signature = (model_shape=None, *, width=96, height=96, distance=3.0, field_height=2.4,
                        renderer="superquadric", samples=100, radial_bins=5, angular_bins=12,
                        seed=0, depth_weight=0.0, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn build(
        py: Python<'_>,
        model_shape: Option<&Bound<PyAny>>,
        width: i128,
        height: i128,
        distance: f64,
        field_height: f64,
        renderer: &str,
        samples: i128,
        radial_bins: i128,
        angular_bins: i128,
        seed: i128,
        depth_weight: f64,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Self> {
        let model = model_of(model_shape)?;
        let cfg = config_of(
            width,
            height,
            distance,
            field_height,
            renderer,
            samples,
            radial_bins,
            angular_bins,
            seed,
            depth_weight,
        )?;
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
    #[pyo3(signature = (depths, model_shape=None, *, width=96, height=96, distance=3.0,
                        field_height=2.4, samples=100, radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn from_depths(
        py: Python<'_>,
        depths: &Bound<PyAny>,
        model_shape: Option<&Bound<PyAny>>,
        width: i128,
        height: i128,
        distance: f64,
        field_height: f64,
        samples: i128,
        radial_bins: i128,
        angular_bins: i128,
        seed: i128,
        depth_weight: f64,
    ) -> PyResult<Self> {
        let model = model_of(model_shape)?;
        let cfg = config_of(
            width,
            height,
            distance,
            field_height,
            "superquadric",
            samples,
            radial_bins,
            angular_bins,
            seed,
            depth_weight,
        )?;
        let d = f32_array(depths, "depths", Some(3), false)?;
        let (height, width) = (cfg.height, cfg.width);
        if d.shape != [NUM_TEMPLATES, height, width] {
            return Err(Error::invalid(
                "depths",
                format!(
                    "expected shape ({NUM_TEMPLATES}, {height}, {width}), got {:?}",
                    d.shape
                ),
            )
            .into());
        }
        let db = native(py, || TemplateDatabase::from_depths(&model, &cfg, &d.data))?;
        Ok(PyTemplateDatabase {
            inner: std::sync::Arc::new(db),
        })
    }

    /// Depth image (H, W) float32 of template `index` rendered in Rust.
    #[staticmethod]
    #[pyo3(signature = (index, model_shape=None, *, width=96, height=96, distance=3.0,
                        field_height=2.4, renderer="superquadric"))]
    #[allow(clippy::too_many_arguments)]
    fn render_template<'py>(
        py: Python<'py>,
        index: i128,
        model_shape: Option<&Bound<'py, PyAny>>,
        width: i128,
        height: i128,
        distance: f64,
        field_height: f64,
        renderer: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let model = model_of(model_shape)?;
        let d = TemplateConfig::default();
        let cfg = config_of(
            width,
            height,
            distance,
            field_height,
            renderer,
            d.descriptor.samples as i128,
            d.descriptor.radial_bins as i128,
            d.descriptor.angular_bins as i128,
            d.descriptor.seed as i128,
            d.descriptor.depth_weight,
        )?;
        let index = count(index, "index")?;
        let depth = native(py, || {
            crate::templates::render_template(&model, &cfg, index)
        })?;
        Ok(to_numpy(py, depth, &[cfg.height, cfg.width]))
    }

    /// Super-quadric meshes of template `index` (all segments in one mesh, template
    /// camera frame): (vertices (V, 3) float64, faces (F, 3) int64).
    #[staticmethod]
    #[pyo3(signature = (index, model_shape=None, *, distance=3.0, rings=16, sectors=20))]
    fn template_mesh<'py>(
        py: Python<'py>,
        index: i128,
        model_shape: Option<&Bound<'py, PyAny>>,
        distance: f64,
        rings: i128,
        sectors: i128,
    ) -> PyResult<MeshArrays<'py>> {
        let index = count(index, "index")?;
        let (rings, sectors) = (count(rings, "rings")?, count(sectors, "sectors")?);
        if index >= NUM_TEMPLATES {
            return Err(
                Error::invalid("index", format!("must be < {NUM_TEMPLATES}, got {index}")).into(),
            );
        }
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
        Ok((to_numpy(py, v, &[nv, 3]), to_numpy(py, f, &[nf, 3])))
    }

    /// Matches the body in `depth` (H, W) metres; candidates best first, as dicts with
    /// index, view, pose (22,), joints (15, 3), cost, prune_cost, scale; and the short
    /// list of the pruning stage.
    #[pyo3(signature = (depth, camera, mask=None, *, top_k=5, shortlist=16, representatives=8,
                        location_weight=0.1, dummy_cost=0.15, rerank=0))]
    #[allow(clippy::too_many_arguments)]
    fn match_depth<'py>(
        &self,
        py: Python<'py>,
        depth: &Bound<'py, PyAny>,
        camera: &PyCamera,
        mask: Option<&Bound<'py, PyAny>>,
        top_k: i128,
        shortlist: i128,
        representatives: i128,
        location_weight: f64,
        dummy_cost: f64,
        rerank: i128,
    ) -> PyResult<(Vec<Bound<'py, PyDict>>, Vec<usize>)> {
        let top_k = count(top_k, "top_k")?;
        let rerank = count(rerank, "rerank")?;
        let shortlist = count(shortlist, "shortlist")?;
        let representatives = count(representatives, "representatives")?;
        let d = depth_array(depth, "depth")?;
        if d.shape.len() != 2 {
            return Err(Error::invalid("depth", "must be a 2-D image").into());
        }
        let m = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
        let cfg = MatchConfig {
            top_k,
            shortlist: shortlist.max(top_k).max(rerank),
            representatives,
            location_weight,
            dummy_cost,
            rerank,
        };
        let r = native(py, || -> crate::Result<_> {
            let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
            self.inner
                .match_depth(&view, &camera.inner, m.as_deref(), &cfg)
        })?;
        let mut out = Vec::with_capacity(r.candidates.len());
        for c in r.candidates {
            let dict = PyDict::new(py);
            dict.set_item("index", c.index)?;
            dict.set_item("view", c.view)?;
            dict.set_item("pose", to_numpy(py, c.pose.to_vec(), &[NUM_PARAMS]))?;
            dict.set_item(
                "joints",
                to_numpy(
                    py,
                    c.joints.iter().flatten().copied().collect(),
                    &[NUM_JOINTS, 3],
                ),
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
    #[pyo3(signature = (depth, camera, indices, mask=None, *, location_weight=0.1, dummy_cost=0.15))]
    #[allow(clippy::too_many_arguments)]
    fn exact_costs(
        &self,
        py: Python<'_>,
        depth: &Bound<PyAny>,
        camera: &PyCamera,
        indices: Vec<usize>,
        mask: Option<&Bound<PyAny>>,
        location_weight: f64,
        dummy_cost: f64,
    ) -> PyResult<Vec<f64>> {
        let d = depth_array(depth, "depth")?;
        let m = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
        if let Some(&bad) = indices.iter().find(|&&i| i >= self.inner.len()) {
            return Err(Error::invalid("indices", format!("{bad} is not a template")).into());
        }
        let r = native(py, || -> crate::Result<Vec<f64>> {
            use rayon::prelude::*;
            let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
            let dc = &self.inner.config.descriptor;
            let sil = crate::descriptor::Silhouette::from_depth(
                &view,
                &camera.inner,
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
        d.set_item("shape", to_numpy(py, a.shape, &[NUM_SHAPE_PARAMS]))?;
        let nc = a.config.len();
        d.set_item("config", to_numpy(py, a.config, &[nc]))?;
        d.set_item("poses", to_numpy(py, a.poses, &[t, NUM_PARAMS]))?;
        d.set_item("views", to_numpy(py, a.views, &[t]))?;
        d.set_item("joints", to_numpy(py, a.joints, &[t, NUM_JOINTS, 3]))?;
        d.set_item("centroids", to_numpy(py, a.centroids, &[t, 3]))?;
        d.set_item("sizes", to_numpy(py, a.sizes, &[t]))?;
        d.set_item("counts", to_numpy(py, a.counts, &[t]))?;
        d.set_item("context_scale", to_numpy(py, a.context_scale, &[t]))?;
        d.set_item(
            "context_centroid",
            to_numpy(py, a.context_centroid, &[t, 2]),
        )?;
        d.set_item("context_points", to_numpy(py, a.context_points, &[t]))?;
        d.set_item("sample_pixels", to_numpy(py, a.sample_pixels, &[s, 2]))?;
        d.set_item(
            "sample_positions",
            to_numpy(py, a.sample_positions, &[s, 2]),
        )?;
        d.set_item("descriptors", to_numpy(py, a.descriptors, &[s, dim]))?;
        Ok(d)
    }

    /// A database from `to_arrays` output; `source` names the file in errors. With
    /// `model_shape`/`config` given, refuses a database built for another model or
    /// other settings (FileFormatError).
    #[staticmethod]
    #[pyo3(signature = (arrays, source, model_shape=None, config=None))]
    fn from_arrays(
        py: Python<'_>,
        arrays: &Bound<PyDict>,
        source: &str,
        model_shape: Option<&Bound<PyAny>>,
        config: Option<&Bound<PyAny>>,
    ) -> PyResult<Self> {
        let file_err = |msg: String| -> PyErr { Error::file(source, msg).into() };
        let get = |k: &str| -> PyResult<Bound<PyAny>> {
            arrays
                .get_item(k)?
                .ok_or_else(|| file_err(format!("missing entry {k:?}")))
        };
        let f64s = |k: &str| -> PyResult<Vec<f64>> {
            Ok(f64_array(&get(k)?, k, None, true)
                .map_err(|e| file_err(e.to_string()))?
                .data)
        };
        let f32s = |k: &str| -> PyResult<Vec<f32>> {
            Ok(f32_array(&get(k)?, k, None, true)
                .map_err(|e| file_err(e.to_string()))?
                .data)
        };
        let i64s = |k: &str| -> PyResult<Vec<i64>> {
            Ok(i64_array(&get(k)?, k, None)
                .map_err(|e| file_err(e.to_string()))?
                .data)
        };
        let version: u32 = get("format_version")?
            .extract()
            .map_err(|_| file_err("format_version is not an integer".into()))?;
        let hash_s: String = get("hash")?
            .extract()
            .map_err(|_| file_err("hash is not a string".into()))?;
        let hash = u64::from_str_radix(&hash_s, 16)
            .map_err(|_| file_err(format!("hash {hash_s:?} is not hexadecimal")))?;
        let a = TemplateArrays {
            format_version: version,
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
            _ => return Err(Error::invalid("model_shape/config", "give both or neither").into()),
        };
        let db = native(py, || {
            TemplateDatabase::from_arrays(&a, expected.as_ref().map(|(m, c)| (m, c)), source)
        })?;
        Ok(PyTemplateDatabase {
            inner: std::sync::Arc::new(db),
        })
    }

    /// The settings hash this database's model and settings give (hex).
    #[staticmethod]
    #[pyo3(signature = (model_shape=None, *, width=96, height=96, distance=3.0, field_height=2.4,
                        renderer="superquadric", samples=100, radial_bins=5, angular_bins=12, seed=0, depth_weight=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn settings(
        py: Python<'_>,
        model_shape: Option<&Bound<PyAny>>,
        width: i128,
        height: i128,
        distance: f64,
        field_height: f64,
        renderer: &str,
        samples: i128,
        radial_bins: i128,
        angular_bins: i128,
        seed: i128,
        depth_weight: f64,
    ) -> PyResult<(String, Py<PyAny>)> {
        let model = model_of(model_shape)?;
        let cfg = config_of(
            width,
            height,
            distance,
            field_height,
            renderer,
            samples,
            radial_bins,
            angular_bins,
            seed,
            depth_weight,
        )?;
        let v = crate::templates::config_to_vec(&cfg).to_vec();
        let n = v.len();
        Ok((
            format!("{:016x}", TemplateDatabase::settings_hash(&model, &cfg)),
            to_numpy(py, v, &[n]).into_any().unbind(),
        ))
    }

    #[getter]
    fn hash(&self) -> String {
        format!("{:016x}", self.inner.hash())
    }

    #[getter]
    fn model_shape<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        to_numpy(
            py,
            self.inner.model.shape.to_vec().to_vec(),
            &[NUM_SHAPE_PARAMS],
        )
    }

    /// Template poses (768, 22) as rendered.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        let v: Vec<f64> = self.inner.templates.iter().flat_map(|t| t.pose).collect();
        to_numpy(py, v, &[self.inner.len(), NUM_PARAMS])
    }

    /// Template joints (768, 15, 3), template camera frame.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
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
fn _default_model_shape(py: Python<'_>) -> Bound<'_, PyArrayDyn<f64>> {
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
