//! Surface-context descriptors and the template database, for Python: the settings
//! the builders share and `surface_context` here, the `TemplateDatabase` class in
//! [`database`], its files and the per-process default database in [`files`], the
//! matched `Candidate` in [`candidate`].

mod candidate;
mod database;
mod files;

pub use database::PyTemplateDatabase;

use super::body::PyBodyModel;
use super::convert::{
    bool_array, camera as camera_arg, check_fit_points, check_result_bytes, depth_array, f64_array,
    invalid, object, to_numpy, type_name, wrong_type, Int, Real, Text,
};
use super::keywords::{check_names, keywords};
use super::native;
use crate::body::{BodyModel, BodyShape};
use crate::cloud::DepthView;
use crate::descriptor::{surface_context_from_depth, DescriptorConfig};
use crate::templates::{TemplateConfig, TemplateRenderer, MAX_SEED, NUM_TEMPLATES};
use numpy::{PyArrayDyn, PyUntypedArray};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The body model of a `model` argument: None (the default model), a
/// `depthpose.BodyModel`, or its 27 shape values (a numpy array).
fn model_arg(model: Option<&Bound<PyAny>>) -> PyResult<BodyModel> {
    match model.filter(|m| !m.is_none()) {
        None => Ok(BodyModel::default()),
        Some(m) if m.is_instance_of::<PyBodyModel>() => {
            Ok(object::<PyBodyModel>(m, "model", "a BodyModel")?
                .inner
                .clone())
        }
        Some(m) if m.cast::<PyUntypedArray>().is_ok() => {
            let a = f64_array(m, "model", Some(1), true)?;
            Ok(BodyModel::with_shape(BodyShape::from_vec(&a.data)?))
        }
        Some(m) => Err(wrong_type(
            "model",
            "a depthpose.BodyModel or its 27 shape values (a numpy array)",
            &type_name(m),
        )),
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

/// The template settings as Python passes them (see `TemplateDatabase.build`).
#[derive(Default)]
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

    /// Whether the templates are to be ray cast by trimesh (`renderer="trimesh"`).
    fn trimesh(&self) -> bool {
        matches!(&self.renderer, Some(r) if r.get("renderer").ok() == Some("trimesh"))
    }

    /// The checked configuration. `renderer` is "superquadric" (the default),
    /// "ellipsoid", or with `trimesh` also "trimesh" (trimesh ray casting of the
    /// super-quadric meshes, which the configuration records as "superquadric").
    fn config(&self, trimesh: bool) -> PyResult<TemplateConfig> {
        let renderer = match &self.renderer {
            None => TemplateRenderer::Superquadric,
            Some(r) => match r.get("renderer")? {
                "superquadric" => TemplateRenderer::Superquadric,
                "trimesh" if trimesh => TemplateRenderer::Superquadric,
                "ellipsoid" => TemplateRenderer::Ellipsoid,
                other => {
                    return Err(invalid(
                        "renderer",
                        format!(
                            "must be {}, got {}",
                            if trimesh {
                                "'superquadric', 'ellipsoid' or 'trimesh'"
                            } else {
                                "'superquadric' or 'ellipsoid'"
                            },
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
}

/// Fails unless the descriptors of a whole database of `c` fit `MAX_RESULT_BYTES`.
fn check_database_bytes(c: &TemplateConfig) -> PyResult<()> {
    let bytes = NUM_TEMPLATES
        .checked_mul(c.descriptor.samples)
        .and_then(|n| n.checked_mul(c.descriptor.dim() * 4 + 16));
    check_result_bytes(bytes, "samples", "the template descriptors")
}

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

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(surface_context, m)?)?;
    m.add_class::<PyTemplateDatabase>()?;
    m.add_class::<candidate::PyCandidate>()?;
    Ok(())
}
