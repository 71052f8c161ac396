//! Body model hot paths: distances of 10,000 points to every segment ellipsoid, the
//! residual Jacobian of 10,000 labelled points, and rendering a 320×240 depth image.

use criterion::{criterion_group, criterion_main, Criterion};
use depthpose::body::{BodyModel, NUM_PARAMS, NUM_SEGMENTS};
use depthpose::Camera;
use std::hint::black_box;

const N_POINTS: usize = 10_000;

/// A walking-like pose and 10,000 points of its rendered surface (as a depth camera
/// would see them), with their part labels.
fn scene() -> (BodyModel, [f64; NUM_PARAMS], Vec<[f32; 3]>, Vec<i32>) {
    let model = BodyModel::default();
    let mut pose = BodyModel::neutral_pose();
    pose[8] = 0.6; // right shoulder flexion
    pose[11] = 0.8; // right elbow
    pose[16] = 0.4; // right hip flexion
    pose[18] = 0.5; // right knee
    pose[4] = 0.3; // some yaw
    let cam = Camera::kinect_v1();
    let (depth, labels) = model.render_depth(&pose, &cam);
    let mut pts = Vec::new();
    let mut labs = Vec::new();
    for (i, (&z, &l)) in depth.iter().zip(&labels).enumerate() {
        if z > 0.0 {
            let p = cam.back_project((i % cam.width) as f64, (i / cam.width) as f64, z as f64);
            pts.push([p.x as f32, p.y as f32, p.z as f32]);
            labs.push(l as i32);
        }
    }
    let step = (pts.len() as f64 / N_POINTS as f64).max(1.0);
    let idx: Vec<usize> = (0..N_POINTS)
        .map(|k| ((k as f64 * step) as usize).min(pts.len() - 1))
        .collect();
    let pts = idx.iter().map(|&i| pts[i]).collect();
    let labs = idx.iter().map(|&i| labs[i]).collect();
    (model, pose, pts, labs)
}

fn bench_body(c: &mut Criterion) {
    let (model, pose, pts, labels) = scene();
    let mut out = vec![0.0f32; pts.len() * NUM_SEGMENTS];
    c.bench_function("body_distances_10k_points_x16", |b| {
        b.iter(|| {
            model.distances(&pts, &pose, &mut out).unwrap();
            black_box(out[0])
        })
    });
    c.bench_function("body_distances_capped_0.3m_10k_points_x16", |b| {
        b.iter(|| {
            model.distances_capped(&pts, &pose, 0.3, &mut out).unwrap();
            black_box(out[0])
        })
    });
    let (mut res, mut jac) = (vec![0.0; pts.len()], vec![0.0; pts.len() * NUM_PARAMS]);
    c.bench_function("body_residuals_jacobian_10k_points", |b| {
        b.iter(|| {
            model
                .residuals_and_jacobian(&pts, &labels, &pose, &mut res, &mut jac)
                .unwrap();
            black_box(jac[0])
        })
    });
    let cam = Camera::itop();
    let n = cam.width * cam.height;
    let (mut depth, mut labs) = (vec![0.0f32; n], vec![0i16; n]);
    c.bench_function("body_render_320x240", |b| {
        b.iter(|| {
            model
                .render_depth_into(&pose, &cam, &mut depth, &mut labs)
                .unwrap();
            black_box(depth[0])
        })
    });
}

criterion_group!(benches, bench_body);
criterion_main!(benches);
