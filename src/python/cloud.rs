//! Depth → points, normals, neighbour graph and foreground, for Python.

use super::convert::{bool_array, camera as camera_arg, depth_array, invalid, to_numpy, Int, Real};
use super::keywords::keywords;
use super::native;
use crate::camera::Camera;
use crate::cloud::{
    foreground_mask as fg_mask, neighbour_graph, normals_from_depth, Cloud, DepthView,
    ForegroundConfig, NormalConfig,
};
use crate::segment::{segment_person, SegmentConfig};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;
type I32Array<'py> = Bound<'py, PyArrayDyn<i32>>;

/// Largest radius of the normal estimation window, in pixels.
const MAX_NORMAL_RADIUS: i128 = 32;

fn cloud_of(
    depth: &[f32],
    shape: &[usize],
    camera: &Camera,
    mask: Option<&[bool]>,
) -> crate::Result<Cloud> {
    let view = DepthView::new(depth, shape[0], shape[1], "depth")?;
    Cloud::from_depth(&view, camera, mask)
}

/// The depth, camera and mask arguments the cloud functions share, checked.
struct CloudArgs {
    depth: Vec<f32>,
    shape: Vec<usize>,
    camera: Camera,
    mask: Option<Vec<bool>>,
}

impl CloudArgs {
    fn parse(
        depth: &Bound<PyAny>,
        camera: &Bound<PyAny>,
        mask: Option<&Bound<PyAny>>,
    ) -> PyResult<Self> {
        let camera = camera_arg(camera, "camera")?;
        let d = depth_array(depth, "depth")?;
        let mask = mask.map(|m| bool_array(m, "mask", &d.shape)).transpose()?;
        Ok(CloudArgs {
            depth: d.data,
            shape: d.shape,
            camera,
            mask,
        })
    }

    fn cloud(&self) -> crate::Result<Cloud> {
        cloud_of(&self.depth, &self.shape, &self.camera, self.mask.as_deref())
    }
}

/// Points (N, 3) float32 of the pixels with a reading (and in `mask`), and their pixel
/// coordinates (N, 2) int32 as [row, col].
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None))]
fn depth_to_points<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<(F32Array<'py>, I32Array<'py>)> {
    let a = CloudArgs::parse(depth, camera, mask)?;
    let cloud = native(py, || a.cloud())?;
    let n = cloud.len();
    let pix: Vec<i32> = (0..n)
        .flat_map(|k| {
            let (r, c) = cloud.pixel(k);
            [r as i32, c as i32]
        })
        .collect();
    let pts: Vec<f32> = cloud.points.into_iter().flatten().collect();
    Ok((to_numpy(py, pts, &[n, 3])?, to_numpy(py, pix, &[n, 2])?))
}

/// Unit normals (N, 3), facing the camera, for the points of `depth_to_points`.
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None, radius=Int::new(2)),
       text_signature = "(depth, camera, mask=None, radius=2)")]
fn surface_normals<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    mask: Option<&Bound<'py, PyAny>>,
    radius: Int,
) -> PyResult<F32Array<'py>> {
    let radius = radius.in_range(1, MAX_NORMAL_RADIUS, "radius")? as usize;
    let a = CloudArgs::parse(depth, camera, mask)?;
    let normals = native(py, || -> crate::Result<Vec<[f32; 3]>> {
        let cloud = a.cloud()?;
        let view = DepthView::new(&a.depth, a.shape[0], a.shape[1], "depth")?;
        let cfg = NormalConfig {
            radius,
            ..Default::default()
        };
        Ok(normals_from_depth(&view, &a.camera, &cloud, &cfg))
    })?;
    let n = normals.len();
    to_numpy(py, normals.into_iter().flatten().collect(), &[n, 3])
}

/// The neighbourhood graph between valid (masked) pixels: edges (E, 2) int32 of point
/// indices (as in `depth_to_points`), 3-D distance (E,) and depth difference z_j − z_i (E,).
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None, connectivity=Int::new(4)),
       text_signature = "(depth, camera, mask=None, connectivity=4)")]
fn pixel_graph<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    mask: Option<&Bound<'py, PyAny>>,
    connectivity: Int,
) -> PyResult<(I32Array<'py>, F32Array<'py>, F32Array<'py>)> {
    let conn = super::convert::connectivity(&connectivity)?;
    let a = CloudArgs::parse(depth, camera, mask)?;
    let g = native(py, || -> crate::Result<_> {
        Ok(neighbour_graph(&a.cloud()?, conn))
    })?;
    let e = g.len();
    let edges: Vec<i32> = g.edges.into_iter().flatten().map(|v| v as i32).collect();
    Ok((
        to_numpy(py, edges, &[e, 2])?,
        to_numpy(py, g.distance, &[e])?,
        to_numpy(py, g.depth_diff, &[e])?,
    ))
}

keywords! {
    /// The keyword arguments of `foreground_mask`.
    struct ForegroundKeywords<'py> {
        camera: Option<Bound<'py, PyAny>> = None,
        min_depth: Real = Real::new(0.3),
        max_depth: Real = Real::new(8.0),
        bg_tolerance: Real = Real::new(0.025),
        bg_tolerance_quadratic: Real = Real::new(0.003),
        max_step: Real = Real::new(0.25),
        min_component: Int = Int::new(40),
        large_share: Real = Real::new(0.3),
        attach_depth: Real = Real::new(0.5),
        min_joined_piece: Int = Int::new(0),
    }
}

/// The person's pixels (H, W) bool. See `depthpose.foreground_mask`.
#[pyfunction]
#[pyo3(signature = (depth, background=None, **options),
       text_signature = "(depth, background=None, *, camera=None, min_depth=0.3, max_depth=8.0, \
                         bg_tolerance=0.025, bg_tolerance_quadratic=0.003, max_step=0.25, \
                         min_component=40, large_share=0.3, attach_depth=0.5, \
                         min_joined_piece=0)")]
fn foreground_mask<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    background: Option<&Bound<'py, PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    let o = ForegroundKeywords::parse("foreground_mask", options)?;
    let cfg = ForegroundConfig {
        min_depth: o.min_depth.get_f32("min_depth")?,
        max_depth: o.max_depth.get_f32("max_depth")?,
        bg_tolerance: o.bg_tolerance.get_f32("bg_tolerance")?,
        bg_tolerance_quadratic: o.bg_tolerance_quadratic.get_f32("bg_tolerance_quadratic")?,
        max_step: o.max_step.get_f32("max_step")?,
        min_component: o.min_component.count("min_component")?,
        large_share: o.large_share.get_f32("large_share")?,
        attach_depth: o.attach_depth.get_f32("attach_depth")?,
        min_joined_piece: o.min_joined_piece.count("min_joined_piece")?,
    };
    let d = depth_array(depth, "depth")?;
    let bg = background
        .map(|b| depth_array(b, "background"))
        .transpose()?;
    if let Some(b) = &bg {
        if b.shape != d.shape {
            return Err(invalid(
                "background",
                format!("shape {:?} does not match depth {:?}", b.shape, d.shape),
            ));
        }
    }
    let (h, w) = (d.shape[0], d.shape[1]);
    let camera = match &o.camera {
        Some(c) => camera_arg(c, "camera")?,
        None => Camera::nominal(w, h)?,
    };
    let mask = native(py, || -> crate::Result<Vec<bool>> {
        let view = DepthView::new(&d.data, h, w, "depth")?;
        match &bg {
            Some(b) => {
                let bgv = DepthView::new(&b.data, b.shape[0], b.shape[1], "background")?;
                fg_mask(&view, Some(&bgv), &cfg)
            }
            None => {
                let config = SegmentConfig {
                    foreground: cfg,
                    ..Default::default()
                };
                Ok(segment_person(&view, &camera, None, &config, None)?.mask)
            }
        }
    })?;
    to_numpy(py, mask, &d.shape)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(depth_to_points, m)?)?;
    m.add_function(wrap_pyfunction!(surface_normals, m)?)?;
    m.add_function(wrap_pyfunction!(pixel_graph, m)?)?;
    m.add_function(wrap_pyfunction!(foreground_mask, m)?)?;
    Ok(())
}
