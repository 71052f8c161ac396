//! Rendering of a template's depth image: the z-buffer rasteriser of the
//! super-quadric meshes, or the ellipsoid ray caster.

use super::catalogue::{template_pose, NUM_TEMPLATES};
use super::TemplateConfig;
use super::TemplateRenderer;
use crate::body::superquadric::Mesh;
use crate::body::BodyModel;
use crate::camera::Camera;
use crate::error::{ensure, Result};

/// Z-buffer rasterisation of triangle meshes into `depth` (H×W metres, 0 = empty):
/// pixel centres inside a projected triangle take the perspective-correct depth
/// (1/z interpolated linearly in the image); the nearest surface wins.
pub fn rasterize_meshes_into(meshes: &[Mesh], camera: &Camera, depth: &mut [f32]) -> Result<()> {
    let (w, h) = (camera.width, camera.height);
    ensure(depth.len() == w * h, "depth", || {
        format!(
            "buffer has {} values, the camera needs {h}x{w}",
            depth.len()
        )
    })?;
    depth.fill(0.0);
    const NEAR: f64 = 1e-3;
    for mesh in meshes {
        let proj: Vec<[f64; 3]> = mesh
            .vertices
            .iter()
            .map(|v| {
                let z = v[2];
                [
                    camera.fx * v[0] / z + camera.cx,
                    camera.fy * v[1] / z + camera.cy,
                    z,
                ]
            })
            .collect();
        for f in &mesh.faces {
            let [a, b, c] = f.map(|i| proj[i as usize]);
            if a[2] <= NEAR || b[2] <= NEAR || c[2] <= NEAR {
                continue;
            }
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if area.abs() < 1e-12 {
                continue;
            }
            let u0 = a[0].min(b[0]).min(c[0]).ceil().max(0.0);
            let u1 = a[0].max(b[0]).max(c[0]).floor().min((w - 1) as f64);
            let v0 = a[1].min(b[1]).min(c[1]).ceil().max(0.0);
            let v1 = a[1].max(b[1]).max(c[1]).floor().min((h - 1) as f64);
            if u0 > u1 || v0 > v1 {
                continue;
            }
            let inv = 1.0 / area;
            let (ia, ib, ic) = (1.0 / a[2], 1.0 / b[2], 1.0 / c[2]);
            for row in v0 as usize..=v1 as usize {
                let y = row as f64;
                for col in u0 as usize..=u1 as usize {
                    let x = col as f64;
                    let wa = ((b[0] - x) * (c[1] - y) - (b[1] - y) * (c[0] - x)) * inv;
                    let wb = ((c[0] - x) * (a[1] - y) - (c[1] - y) * (a[0] - x)) * inv;
                    let wc = 1.0 - wa - wb;
                    if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                        continue;
                    }
                    let z = (1.0 / (wa * ia + wb * ib + wc * ic)) as f32;
                    let d = &mut depth[row * w + col];
                    if *d == 0.0 || z < *d {
                        *d = z;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Renders the depth image of template `index` (H×W metres of `config.camera()`).
pub fn render_template(
    model: &BodyModel,
    config: &TemplateConfig,
    index: usize,
) -> Result<Vec<f32>> {
    ensure(index < NUM_TEMPLATES, "index", || {
        format!("must be < {NUM_TEMPLATES}, got {index}")
    })?;
    let cam = config.camera()?;
    let pose = template_pose(index, config.distance);
    let mut depth = vec![0.0f32; cam.width * cam.height];
    match config.renderer {
        TemplateRenderer::Superquadric => {
            let meshes = model.superquadric_meshes(&pose, &config.mesh)?;
            rasterize_meshes_into(&meshes, &cam, &mut depth)?;
        }
        TemplateRenderer::Ellipsoid => {
            let mut labels = vec![0i16; depth.len()];
            model.render_depth_into(&pose, &cam, &mut depth, &mut labels)?;
        }
    }
    Ok(depth)
}
