use super::depth::{first_bad_depth, DepthView};
use super::graph::{neighbour_graph, neighbour_graph_into, Connectivity, PixelGraph};
use super::normals::{
    cross, facing_normal, normalize, normals_from_depth, normals_into, sub, surface_jump,
    NormalConfig,
};
use super::points::Cloud;
use crate::camera::Camera;

#[test]
fn first_bad_depth_finds_the_first_bad_value_across_chunks() {
    let n = 3 * 512 + 7;
    let clean: Vec<f32> = (0..n).map(|k| (k % 5) as f32 * 0.5).collect();
    assert_eq!(first_bad_depth(&clean), None);
    let mut with_nan = clean.clone();
    with_nan[3] = f32::NAN; // NaN means "no reading", not an error
    assert_eq!(first_bad_depth(&with_nan), None);
    for &first in &[0, 1, 511, 512, 513, 1024, n - 1] {
        for bad in [-0.001f32, f32::INFINITY, f32::NEG_INFINITY] {
            let mut d = clean.clone();
            d[first] = bad;
            if first + 600 < n {
                d[first + 600] = -1.0; // a later bad value does not win
            }
            assert_eq!(first_bad_depth(&d), Some(first), "bad {bad} at {first}");
        }
    }
}

fn cam() -> Camera {
    Camera::new(300.0, 300.0, 79.5, 59.5, 160, 120).unwrap()
}

/// Depth image of the plane n·p = d (camera frame).
fn plane_depth(cam: &Camera, n: [f64; 3], d: f64) -> Vec<f32> {
    let mut out = vec![0.0f32; cam.width * cam.height];
    for row in 0..cam.height {
        for col in 0..cam.width {
            let r = cam.back_project(col as f64, row as f64, 1.0);
            let t = d / (n[0] * r.x + n[1] * r.y + n[2] * r.z);
            out[row * cam.width + col] = t as f32; // r.z = 1 so t is the depth
        }
    }
    out
}

/// Depth image of a sphere (centre c, radius rad); 0 off the sphere.
fn sphere_depth(cam: &Camera, c: [f64; 3], rad: f64) -> Vec<f32> {
    let mut out = vec![0.0f32; cam.width * cam.height];
    for row in 0..cam.height {
        for col in 0..cam.width {
            let r = cam.back_project(col as f64, row as f64, 1.0);
            // |t r - c|² = rad²  →  t²|r|² − 2t r·c + |c|² − rad² = 0
            let a = r.norm_squared();
            let b = r.x * c[0] + r.y * c[1] + r.z * c[2];
            let cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2] - rad * rad;
            let disc = b * b - a * cc;
            if disc >= 0.0 {
                out[row * cam.width + col] = ((b - disc.sqrt()) / a) as f32;
            }
        }
    }
    out
}

#[test]
fn back_projection_lies_on_plane_and_normals_match() {
    let cam = cam();
    let n = nalgebra::Vector3::new(0.2, -0.3, -1.0).normalize();
    let d = -2.0; // n·p = d with n pointing to the camera
    let depth = plane_depth(&cam, [n.x, n.y, n.z], d);
    let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
    let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
    assert_eq!(cloud.len(), cam.width * cam.height);
    let normals = normals_from_depth(&view, &cam, &cloud, &NormalConfig::default());
    for (p, m) in cloud.points.iter().zip(&normals) {
        let on = n.x * p[0] as f64 + n.y * p[1] as f64 + n.z * p[2] as f64;
        assert!((on - d).abs() < 1e-5, "point off the plane by {}", on - d);
        let dot = n.x * m[0] as f64 + n.y * m[1] as f64 + n.z * m[2] as f64;
        assert!(
            dot > 0.9999,
            "normal off by {} deg",
            dot.acos().to_degrees()
        );
    }
}

#[test]
fn sphere_normals_are_radial_even_at_the_silhouette() {
    let cam = cam();
    let c = [0.05, -0.02, 1.5];
    let rad = 0.2;
    let depth = sphere_depth(&cam, c, rad);
    let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
    let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
    assert!(cloud.len() > 1000);
    let normals = normals_from_depth(&view, &cam, &cloud, &NormalConfig::default());
    let mut worst_inner = 0.0f64;
    for (p, m) in cloud.points.iter().zip(&normals) {
        let radial =
            nalgebra::Vector3::new(p[0] as f64 - c[0], p[1] as f64 - c[1], p[2] as f64 - c[2]);
        assert!((radial.norm() - rad).abs() < 1e-4);
        let radial = radial.normalize();
        let dot = radial.x * m[0] as f64 + radial.y * m[1] as f64 + radial.z * m[2] as f64;
        // Facing the camera always; accurate where the surface is not grazing.
        assert!(dot > 0.0);
        let facing = -(radial.x * p[0] as f64 + radial.y * p[1] as f64 + radial.z * p[2] as f64)
            / (p[0] as f64).hypot(p[1] as f64).hypot(p[2] as f64);
        if facing > 0.5 {
            worst_inner = worst_inner.max(dot.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    assert!(worst_inner < 2.0, "worst normal error {worst_inner} deg");
}

#[test]
fn graph_edges_and_attributes() {
    let cam = Camera::new(100.0, 100.0, 2.0, 1.5, 5, 4).unwrap();
    let mut depth = vec![1.0f32; 20];
    depth[7] = 0.0; // a hole
    depth[12] = 1.5; // a step
    let view = DepthView::new(&depth, 4, 5, "depth").unwrap();
    let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
    assert_eq!(cloud.len(), 19);
    let g4 = neighbour_graph(&cloud, Connectivity::Four);
    // A full 5x4 grid has 4·4 + 5·3 = 31 4-edges; the hole removes its 4.
    assert_eq!(g4.len(), 27);
    let g8 = neighbour_graph(&cloud, Connectivity::Eight);
    // plus 2·4·3 = 24 diagonals, minus the hole's 4.
    assert_eq!(g8.len(), 27 + 20);
    for (k, &[a, b]) in g8.edges.iter().enumerate() {
        let (p, q) = (cloud.points[a as usize], cloud.points[b as usize]);
        assert!((g8.depth_diff[k] - (q[2] - p[2])).abs() < 1e-7);
        let d = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt();
        assert!((g8.distance[k] - d).abs() < 1e-6);
    }
    assert!(g4.depth_diff.iter().any(|&d| (d - 0.5).abs() < 1e-6));
}

#[test]
fn reused_buffers_give_the_same_cloud_and_graph_as_fresh_ones() {
    let cam = cam();
    let sphere = sphere_depth(&cam, [0.05, -0.02, 1.5], 0.2);
    let plane = plane_depth(&cam, [0.2, -0.3, -1.0], -2.0);
    let mut cloud = Cloud::default();
    let mut graph = PixelGraph::default();
    let mut normals = Vec::new();
    // The full plane first (large buffers), then the smaller sphere with a mask.
    for (depth, masked) in [(&plane, false), (&sphere, true), (&plane, false)] {
        let view = DepthView::new(depth, cam.height, cam.width, "depth").unwrap();
        let mask: Vec<bool> = (0..depth.len()).map(|i| i % 7 != 0).collect();
        let mask = masked.then_some(mask.as_slice());
        let fresh = Cloud::from_depth(&view, &cam, mask).unwrap();
        cloud.fill_from_depth(&view, &cam, mask).unwrap();
        assert_eq!(cloud.points, fresh.points);
        assert_eq!(cloud.pixels, fresh.pixels);
        assert_eq!(cloud.point_of_pixel, fresh.point_of_pixel);
        assert_eq!(cloud.row_start, fresh.row_start);
        for (k, &i) in fresh.pixels.iter().enumerate() {
            assert_eq!(fresh.point_of_pixel[i as usize], k as i32);
        }
        let cfg = NormalConfig::default();
        normals.resize(cloud.len(), [0.0; 3]);
        normals_into(&view, &cam, &cloud, &cfg, &mut normals);
        assert_eq!(normals, normals_from_depth(&view, &cam, &fresh, &cfg));
        neighbour_graph_into(&cloud, Connectivity::Eight, &mut graph);
        let g = neighbour_graph(&fresh, Connectivity::Eight);
        assert_eq!(graph.edges, g.edges);
        assert_eq!(graph.distance, g.distance);
        assert!(
            graph.edges.windows(2).all(|e| e[0] < e[1]),
            "edges in pixel order"
        );
    }
}

/// The cloud, normals and graph computed the plain way: one pixel at a time, on one
/// thread, with every neighbour looked up through bounds checks. The fast paths must
/// give exactly this (same values, same order).
mod reference {
    use super::*;

    pub fn cloud(depth: &DepthView, cam: &Camera, mask: Option<&[bool]>) -> Cloud {
        let (w, h) = (depth.width, depth.height);
        let (fx, fy, cx, cy) = (cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32);
        let mut c = Cloud {
            width: w,
            height: h,
            point_of_pixel: vec![-1; w * h],
            row_start: vec![0],
            ..Default::default()
        };
        for row in 0..h {
            for col in 0..w {
                let i = row * w + col;
                let z = depth.data[i];
                if z > 0.0 && mask.is_none_or(|m| m[i]) {
                    c.point_of_pixel[i] = c.points.len() as i32;
                    c.points
                        .push([(col as f32 - cx) * z / fx, (row as f32 - cy) / fy * z, z]);
                    c.pixels.push(i as u32);
                }
            }
            c.row_start.push(c.points.len() as u32);
        }
        c
    }

    pub fn normals(
        depth: &DepthView,
        cam: &Camera,
        cloud: &Cloud,
        config: &NormalConfig,
    ) -> Vec<[f32; 3]> {
        let r = config.radius.max(1) as isize;
        let (w, h) = (depth.width as isize, depth.height as isize);
        let (inv_fx, inv_fy) = (1.0 / cam.fx as f32, 1.0 / cam.fy as f32);
        let (cx, cy) = (cam.cx as f32, cam.cy as f32);
        let point_at = |row: isize, col: isize| -> Option<[f32; 3]> {
            if row < 0 || col < 0 || row >= h || col >= w {
                return None;
            }
            let z = depth.data[(row * w + col) as usize];
            (z > 0.0).then_some([
                (col as f32 - cx) * z * inv_fx,
                (row as f32 - cy) * z * inv_fy,
                z,
            ])
        };
        (0..cloud.len())
            .map(|k| {
                let p = cloud.points[k];
                let (row, col) = cloud.pixel(k);
                let (row, col) = (row as isize, col as isize);
                let jump = surface_jump(p[2]) * config.jump_scale * r as f32;
                let near = |q: Option<[f32; 3]>| q.filter(|q| (q[2] - p[2]).abs() <= jump);
                let tangent = |a, b| match (near(a), near(b)) {
                    (Some(a), Some(b)) => Some(sub(b, a)),
                    (Some(a), None) => Some(sub(p, a)),
                    (None, Some(b)) => Some(sub(b, p)),
                    (None, None) => None,
                };
                let tu = tangent(point_at(row, col - r), point_at(row, col + r));
                let tv = tangent(point_at(row - r, col), point_at(row + r, col));
                match (tu, tv) {
                    (Some(tu), Some(tv)) => facing_normal(cross(tu, tv), p),
                    _ => None,
                }
                .unwrap_or_else(|| normalize([-p[0], -p[1], -p[2]]))
            })
            .collect()
    }

    pub fn graph(cloud: &Cloud, connectivity: Connectivity) -> PixelGraph {
        let offsets: &[(usize, isize)] = match connectivity {
            Connectivity::Four => &[(0, 1), (1, 0)],
            Connectivity::Eight => &[(0, 1), (1, -1), (1, 0), (1, 1)],
        };
        let (w, h) = (cloud.width, cloud.height);
        let mut g = PixelGraph::default();
        for row in 0..h {
            for col in 0..w {
                let a = cloud.point_of_pixel[row * w + col];
                if a < 0 {
                    continue;
                }
                for &(dr, dc) in offsets {
                    let (r2, c2) = (row + dr, col as isize + dc);
                    if r2 >= h || c2 < 0 || c2 >= w as isize {
                        continue;
                    }
                    let b = cloud.point_of_pixel[r2 * w + c2 as usize];
                    if b >= 0 {
                        let (p, q) = (cloud.points[a as usize], cloud.points[b as usize]);
                        let d = sub(q, p);
                        g.edges.push([a as u32, b as u32]);
                        g.distance
                            .push((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
                        g.depth_diff.push(d[2]);
                    }
                }
            }
        }
        g
    }
}

/// Bit patterns, so that the comparison is exact (and NaN-safe).
fn bits<const N: usize>(v: &[[f32; N]]) -> Vec<[u32; N]> {
    v.iter().map(|a| a.map(f32::to_bits)).collect()
}

fn scalar_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// A depth image of a few slanted planes at different depths with holes (0 and NaN),
/// so that it has silhouette edges, depth steps and missing neighbours everywhere.
fn random_depth(h: usize, w: usize, seed: u64, holes: f64) -> (Vec<f32>, Vec<bool>) {
    let mut state = seed | 1;
    let mut next = move || {
        // xorshift64*
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    };
    let (a, b, split) = (next() - 0.5, next() - 0.5, next());
    let mut depth = Vec::with_capacity(h * w);
    let mut mask = Vec::with_capacity(h * w);
    for row in 0..h {
        for col in 0..w {
            let (u, v) = (col as f64 / w as f64, row as f64 / h as f64);
            let base = if u + 0.3 * v < split { 1.2 } else { 3.5 };
            let mut z = base + a * u + b * v + 0.01 * next();
            let roll = next();
            if roll < holes * 0.5 {
                z = 0.0;
            } else if roll < holes {
                z = f64::NAN;
            } else if roll > 0.995 {
                z = 0.05 * next(); // a stray reading very close to the camera
            }
            depth.push(z as f32);
            mask.push(next() < 0.8 || base < 2.0);
        }
    }
    (depth, mask)
}

fn check_against_reference(h: usize, w: usize, seed: u64, holes: f64, radius: usize) {
    let cam = Camera::new(
        500.0 + w as f64,
        480.0 + h as f64,
        w as f64 / 2.0 - 0.5,
        h as f64 / 2.0 + 0.25,
        w,
        h,
    )
    .unwrap();
    let (depth, mask) = random_depth(h, w, seed, holes);
    let view = DepthView::new(&depth, h, w, "depth").unwrap();
    let cfg = NormalConfig {
        radius,
        jump_scale: 1.3,
    };
    // Reused buffers, grown on a larger image first, as a tracker keeps them.
    let mut cloud = Cloud::default();
    let mut graph = PixelGraph::default();
    let mut normals = vec![[9.0f32; 3]; 4 * h * w];
    let big = vec![2.0f32; 4 * h * w];
    let big_view = DepthView::new(&big, 2 * h, 2 * w, "depth").unwrap();
    let big_cam = Camera::new(500.0, 500.0, w as f64, h as f64, 2 * w, 2 * h).unwrap();
    cloud.fill_from_depth(&big_view, &big_cam, None).unwrap();
    neighbour_graph_into(&cloud, Connectivity::Eight, &mut graph);
    for m in [None, Some(mask.as_slice())] {
        let want = reference::cloud(&view, &cam, m);
        cloud.fill_from_depth(&view, &cam, m).unwrap();
        let fresh = Cloud::from_depth(&view, &cam, m).unwrap();
        for got in [&cloud, &fresh] {
            assert_eq!((got.width, got.height), (w, h));
            assert_eq!(bits(&got.points), bits(&want.points));
            assert_eq!(got.pixels, want.pixels);
            assert_eq!(got.point_of_pixel, want.point_of_pixel);
            assert_eq!(got.row_start, want.row_start);
        }
        let want_normals = reference::normals(&view, &cam, &want, &cfg);
        normals.resize(cloud.len(), [9.0; 3]);
        normals_into(&view, &cam, &cloud, &cfg, &mut normals);
        assert_eq!(bits(&normals), bits(&want_normals));
        let fresh_normals = normals_from_depth(&view, &cam, &fresh, &cfg);
        assert_eq!(bits(&fresh_normals), bits(&want_normals));
        for connectivity in [Connectivity::Four, Connectivity::Eight] {
            let want = reference::graph(&want, connectivity);
            neighbour_graph_into(&cloud, connectivity, &mut graph);
            for got in [&graph, &neighbour_graph(&fresh, connectivity)] {
                assert_eq!(got.edges, want.edges);
                assert_eq!(scalar_bits(&got.distance), scalar_bits(&want.distance));
                assert_eq!(scalar_bits(&got.depth_diff), scalar_bits(&want.depth_diff));
            }
        }
    }
}

#[test]
fn fast_paths_match_the_serial_reference_on_a_vga_frame() {
    check_against_reference(480, 640, 7, 0.1, 2);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]

    #[test]
    fn fast_paths_match_the_serial_reference(
        h in 1usize..40,
        w in 1usize..40,
        seed in proptest::prelude::any::<u64>(),
        holes in 0.0f64..0.9,
        radius in 0usize..4,
    ) {
        check_against_reference(h, w, seed, holes, radius);
    }
}

#[test]
fn bad_depth_is_rejected_with_its_pixel() {
    let mut d = vec![1.0f32; 6];
    d[4] = -1.0;
    let e = DepthView::new(&d, 2, 3, "depth").unwrap_err().to_string();
    assert!(e.contains("depth") && e.contains("row 1, col 1"), "{e}");
    d[4] = f32::INFINITY;
    assert!(DepthView::new(&d, 2, 3, "depth").is_err());
    d[4] = f32::NAN;
    assert_eq!(DepthView::new(&d, 2, 3, "depth").unwrap().count_valid(), 5);
    assert!(DepthView::new(&d, 3, 3, "depth").is_err());
    assert!(DepthView::new(&[], 0, 3, "depth").is_err());
}
