//! Points + normals + neighbour graph of a 640×480 frame (the first stage of every frame).

use criterion::{criterion_group, criterion_main, Criterion};
use depthpose::cloud::{
    foreground_mask, neighbour_graph, neighbour_graph_into, normals_from_depth, normals_into,
    Cloud, Connectivity, DepthView, ForegroundConfig, NormalConfig, PixelGraph,
};
use depthpose::Camera;
use std::hint::black_box;

/// A 640×480 frame: a wall at 4 m with a body-sized blob of spheres in front at ~2.5 m.
fn frame(cam: &Camera) -> Vec<f32> {
    let mut d = vec![4.0f32; cam.width * cam.height];
    for row in 0..cam.height {
        for col in 0..cam.width {
            let (x, y) = (col as f32 - 320.0, row as f32 - 240.0);
            let r2 = (x / 90.0).powi(2) + (y / 200.0).powi(2);
            if r2 < 1.0 {
                d[row * cam.width + col] = 2.5 - 0.2 * (1.0 - r2).sqrt();
            }
            if (row * 7 + col * 13) % 97 == 0 {
                d[row * cam.width + col] = 0.0; // dropouts
            }
        }
    }
    d
}

fn bench_cloud(c: &mut Criterion) {
    let cam = Camera::kinect_v1();
    let depth = frame(&cam);
    let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
    // Every pixel with a reading (307k points), fresh buffers each call.
    c.bench_function("cloud_640x480_points_normals_graph8", |b| {
        b.iter(|| {
            let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
            let normals = normals_from_depth(&view, &cam, &cloud, &NormalConfig::default());
            let graph = neighbour_graph(&cloud, Connectivity::Eight);
            black_box((cloud.len(), normals.len(), graph.len()))
        })
    });
    // The same with the buffers kept from frame to frame, as a tracker does.
    let mut cloud = Cloud::default();
    let mut normals = Vec::new();
    let mut graph = PixelGraph::default();
    let mut steady = |name: &str, mask: Option<&[bool]>| {
        c.bench_function(name, |b| {
            b.iter(|| {
                cloud.fill_from_depth(&view, &cam, mask).unwrap();
                normals.resize(cloud.len(), [0.0f32; 3]);
                normals_into(&view, &cam, &cloud, &NormalConfig::default(), &mut normals);
                neighbour_graph_into(&cloud, Connectivity::Eight, &mut graph);
                black_box((cloud.len(), normals.len(), graph.len()))
            })
        });
    };
    steady("cloud_640x480_points_normals_graph8_reused", None);
    // Only the body (the foreground mask of a real frame): ~57k points.
    let body: Vec<bool> = depth.iter().map(|&z| z > 0.0 && z < 3.0).collect();
    steady(
        "cloud_640x480_body_points_normals_graph8_reused",
        Some(&body),
    );
}

/// Foreground extraction of a 320×240 frame (every frame of the tracker): the blob in
/// front of a wall at 4 m, with and without the empty scene as background.
fn bench_foreground(c: &mut Criterion) {
    let cam = Camera::kinect_v1_qvga();
    let depth = frame(&Camera::kinect_v1())
        .chunks_exact(640)
        .step_by(2)
        .flat_map(|row| row.iter().step_by(2).copied())
        .collect::<Vec<f32>>();
    let background = vec![4.0f32; depth.len()];
    let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
    let bg = DepthView::new(&background, cam.height, cam.width, "background").unwrap();
    let config = ForegroundConfig::default();
    c.bench_function("foreground_320x240_background", |b| {
        b.iter(|| black_box(foreground_mask(&view, Some(&bg), &config).unwrap()))
    });
    c.bench_function("foreground_320x240_no_background", |b| {
        b.iter(|| black_box(foreground_mask(&view, None, &config).unwrap()))
    });
}

criterion_group!(benches, bench_cloud, bench_cloud_steps, bench_foreground);
criterion_main!(benches);

/// Each step of the reused path alone, to see where the time goes: the full frame, then
/// the body only.
fn bench_cloud_steps(c: &mut Criterion) {
    let cam = Camera::kinect_v1();
    let depth = frame(&cam);
    let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
    let body: Vec<bool> = depth.iter().map(|&z| z > 0.0 && z < 3.0).collect();
    for (prefix, mask) in [("cloud_step", None), ("cloud_step_body", Some(&body[..]))] {
        let mut cloud = Cloud::default();
        cloud.fill_from_depth(&view, &cam, mask).unwrap();
        let mut normals = vec![[0.0f32; 3]; cloud.len()];
        let mut graph = PixelGraph::default();
        c.bench_function(&format!("{prefix}_points"), |b| {
            b.iter(|| cloud.fill_from_depth(&view, &cam, mask).unwrap())
        });
        c.bench_function(&format!("{prefix}_normals"), |b| {
            b.iter(|| normals_into(&view, &cam, &cloud, &NormalConfig::default(), &mut normals))
        });
        c.bench_function(&format!("{prefix}_graph8"), |b| {
            b.iter(|| neighbour_graph_into(&cloud, Connectivity::Eight, &mut graph))
        });
    }
}
