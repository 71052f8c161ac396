//! Depth → points, normals, neighbour graph and foreground, for Python.

use super::arrays::{bool_array, count, depth_array, to_numpy};
use super::camera::PyCamera;
use super::native;
use crate::camera::Camera;
use crate::cloud::{
    foreground_mask as fg_mask, neighbour_graph, normals_from_depth, Cloud, DepthView,
    ForegroundConfig, NormalConfig,
};
use crate::segment::{segment_person, SegmentConfig};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;
type I32Array<'py> = Bound<'py, PyArrayDyn<i32>>;

fn cloud_of(
    depth: &[f32],
    shape: &[usize],
    camera: &PyCamera,
    mask: Option<&[bool]>,
) -> PyResult<Cloud> {
    let view = DepthView::new(depth, shape[0], shape[1], "depth")?;
    Ok(Cloud::from_depth(&view, &camera.inner, mask)?)
}

fn mask_arg(mask: Option<&Bound<PyAny>>, shape: &[usize]) -> PyResult<Option<Vec<bool>>> {
    mask.map(|m| bool_array(m, "mask", shape)).transpose()
}

/// Points (N, 3) float32 of the pixels with a reading (and in `mask`), and their pixel
/// coordinates (N, 2) int32 as [row, col].
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None))]
fn depth_to_points<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &PyCamera,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<(F32Array<'py>, I32Array<'py>)> {
    let d = depth_array(depth, "depth")?;
    let m = mask_arg(mask, &d.shape)?;
    let cloud = native(py, || cloud_of(&d.data, &d.shape, camera, m.as_deref()))?;
    let n = cloud.len();
    let pix: Vec<i32> = (0..n)
        .flat_map(|k| {
            let (r, c) = cloud.pixel(k);
            [r as i32, c as i32]
        })
        .collect();
    let pts: Vec<f32> = cloud.points.into_iter().flatten().collect();
    Ok((to_numpy(py, pts, &[n, 3]), to_numpy(py, pix, &[n, 2])))
}

/// Unit normals (N, 3), facing the camera, for the points of `depth_to_points`.
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None, radius=2))]
fn surface_normals<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &PyCamera,
    mask: Option<&Bound<'py, PyAny>>,
    radius: i128,
) -> PyResult<F32Array<'py>> {
    let radius = count(radius, "radius")?;
    let d = depth_array(depth, "depth")?;
    let m = mask_arg(mask, &d.shape)?;
    if radius == 0 || radius > 32 {
        return Err(
            crate::Error::invalid("radius", format!("must be in 1..=32, got {radius}")).into(),
        );
    }
    let normals = native(py, || -> PyResult<Vec<[f32; 3]>> {
        let cloud = cloud_of(&d.data, &d.shape, camera, m.as_deref())?;
        let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
        let cfg = NormalConfig {
            radius,
            ..Default::default()
        };
        Ok(normals_from_depth(&view, &camera.inner, &cloud, &cfg))
    })?;
    let n = normals.len();
    Ok(to_numpy(
        py,
        normals.into_iter().flatten().collect(),
        &[n, 3],
    ))
}

/// The neighbourhood graph between valid (masked) pixels: edges (E, 2) int32 of point
/// indices (as in `depth_to_points`), 3-D distance (E,) and depth difference z_j − z_i (E,).
#[pyfunction]
#[pyo3(signature = (depth, camera, mask=None, connectivity=4))]
fn pixel_graph<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &PyCamera,
    mask: Option<&Bound<'py, PyAny>>,
    connectivity: i128,
) -> PyResult<(I32Array<'py>, F32Array<'py>, F32Array<'py>)> {
    let d = depth_array(depth, "depth")?;
    let m = mask_arg(mask, &d.shape)?;
    let conn = super::arrays::connectivity(connectivity)?;
    let g = native(py, || -> PyResult<_> {
        let cloud = cloud_of(&d.data, &d.shape, camera, m.as_deref())?;
        Ok(neighbour_graph(&cloud, conn))
    })?;
    let e = g.len();
    let edges: Vec<i32> = g.edges.into_iter().flatten().map(|v| v as i32).collect();
    Ok((
        to_numpy(py, edges, &[e, 2]),
        to_numpy(py, g.distance, &[e]),
        to_numpy(py, g.depth_diff, &[e]),
    ))
}

/// The person's pixels (H, W) bool. See `depthpose.foreground_mask`.
#[pyfunction]
#[pyo3(signature = (depth, background=None, *, camera=None, min_depth=0.3, max_depth=8.0,
                    bg_tolerance=0.025, bg_tolerance_quadratic=0.003, max_step=0.25,
                    min_component=40, large_share=0.3))]
#[allow(clippy::too_many_arguments)]
fn foreground_mask<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    background: Option<&Bound<'py, PyAny>>,
    camera: Option<&PyCamera>,
    min_depth: f32,
    max_depth: f32,
    bg_tolerance: f32,
    bg_tolerance_quadratic: f32,
    max_step: f32,
    min_component: i128,
    large_share: f32,
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    let min_component = count(min_component, "min_component")?;
    let d = depth_array(depth, "depth")?;
    let bg = background
        .map(|b| depth_array(b, "background"))
        .transpose()?;
    let cfg = ForegroundConfig {
        min_depth,
        max_depth,
        bg_tolerance,
        bg_tolerance_quadratic,
        max_step,
        min_component,
        large_share,
        ..Default::default()
    };
    let (h, w) = (d.shape[0], d.shape[1]);
    let camera = match camera {
        Some(c) => c.inner,
        None => Camera::nominal(w, h)?,
    };
    let mask = native(py, || -> PyResult<Vec<bool>> {
        let view = DepthView::new(&d.data, h, w, "depth")?;
        match &bg {
            Some(b) => {
                let bgv = DepthView::new(&b.data, b.shape[0], b.shape[1], "background")?;
                Ok(fg_mask(&view, Some(&bgv), &cfg)?)
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
    Ok(to_numpy(py, mask, &d.shape))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(depth_to_points, m)?)?;
    m.add_function(wrap_pyfunction!(surface_normals, m)?)?;
    m.add_function(wrap_pyfunction!(pixel_graph, m)?)?;
    m.add_function(wrap_pyfunction!(foreground_mask, m)?)?;
    Ok(())
}
