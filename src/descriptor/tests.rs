use super::config::DescriptorConfig;
use super::context::{
    splitmix, surface_context_from_points, surface_context_with_relief, LogPolarBins,
    SurfaceContext,
};
use super::distance::{descriptor_distance, squared_distance, squared_distances_x4};
use super::silhouette::{surface_context_from_depth, Silhouette};
use crate::body::BodyModel;
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::error::Error;

fn render(pose: &crate::body::Pose, cam: &Camera) -> Vec<f32> {
    BodyModel::default().render_depth(pose, cam).0
}

fn context(depth: &[f32], cam: &Camera, cfg: &DescriptorConfig) -> SurfaceContext {
    let view = DepthView::new(depth, cam.height, cam.width, "depth").unwrap();
    surface_context_from_depth(&view, cam, None, cfg).unwrap()
}

/// Mean over samples of the distance to the nearest-position sample of `b`.
fn mean_nearest(a: &SurfaceContext, b: &SurfaceContext) -> f32 {
    let mut total = 0.0;
    for i in 0..a.len() {
        let pa = a.positions[i];
        let j = (0..b.len())
            .min_by(|&x, &y| {
                let dx = (b.positions[x][0] - pa[0]).hypot(b.positions[x][1] - pa[1]);
                let dy = (b.positions[y][0] - pa[0]).hypot(b.positions[y][1] - pa[1]);
                dx.total_cmp(&dy)
            })
            .unwrap();
        total += descriptor_distance(a.descriptor(i), b.descriptor(j));
    }
    total / a.len() as f32
}

fn arm_raised() -> crate::body::Pose {
    let mut p = BodyModel::neutral_pose();
    p[crate::body::param::R_SHOULDER + 1] = 1.5;
    p[crate::body::param::L_SHOULDER] = 1.4;
    p
}

#[test]
fn shape_and_count() {
    let cam = Camera::itop();
    let cfg = DescriptorConfig::default();
    let sc = context(&render(&BodyModel::neutral_pose(), &cam), &cam, &cfg);
    assert_eq!(sc.dim, 180);
    assert_eq!(sc.descriptors.len(), sc.len() * 180);
    assert!((90..=110).contains(&sc.len()), "{}", sc.len());
    // The normal sums over all bins never exceed the share of points (≤ 1).
    for i in 0..sc.len() {
        let mag: f32 = sc
            .descriptor(i)
            .chunks(3)
            .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
            .sum();
        assert!(mag <= 1.0 + 1e-4 && mag > 0.05, "{mag}");
    }
    // Positions are normalised: their mean pairwise distance is ≈ 1.
    let n = sc.len();
    let mut t = 0.0;
    for i in 0..n {
        for j in i + 1..n {
            t += (sc.positions[i][0] - sc.positions[j][0])
                .hypot(sc.positions[i][1] - sc.positions[j][1]);
        }
    }
    assert!((t / (n * (n - 1) / 2) as f32 - 1.0).abs() < 1e-3);
}

#[test]
fn deterministic_for_a_seed_and_varies_with_it() {
    let cam = Camera::itop();
    let d = render(&arm_raised(), &cam);
    let cfg = DescriptorConfig::default();
    assert_eq!(context(&d, &cam, &cfg), context(&d, &cam, &cfg));
    let other = context(&d, &cam, &DescriptorConfig { seed: 7, ..cfg });
    assert_ne!(other.pixels, context(&d, &cam, &cfg).pixels);
}

#[test]
fn invariant_to_point_order() {
    let cam = Camera::itop();
    let d = render(&arm_raised(), &cam);
    let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
    let sil = Silhouette::from_depth(&view, &cam, None, 2).unwrap();
    let (px, nm) = (sil.pixels(), sil.normals.clone());
    let cfg = DescriptorConfig::default();
    let a = surface_context_from_points(&px, &nm, &cfg).unwrap();
    // A fixed pseudo-random permutation.
    let mut idx: Vec<usize> = (0..px.len()).collect();
    let mut s = 99u64;
    for i in (1..idx.len()).rev() {
        let j = (splitmix(&mut s) * (i + 1) as f64) as usize;
        idx.swap(i, j);
    }
    let px2: Vec<_> = idx.iter().map(|&i| px[i]).collect();
    let nm2: Vec<_> = idx.iter().map(|&i| nm[i]).collect();
    let b = surface_context_from_points(&px2, &nm2, &cfg).unwrap();
    assert_eq!(a.pixels, b.pixels);
    for (x, y) in a.descriptors.iter().zip(&b.descriptors) {
        assert!((x - y).abs() < 1e-6);
    }
}

#[test]
fn invariant_to_translation_and_scale() {
    // The paper's normals-only descriptor, and with the relief channel.
    for depth_weight in [0.0, 3.0] {
        let cfg = DescriptorConfig {
            depth_weight,
            ..Default::default()
        };
        invariances_hold(&cfg);
    }
}

fn invariances_hold(cfg: &DescriptorConfig) {
    let cfg = *cfg;
    let cam = Camera::itop();
    let pose = arm_raised();
    let base = context(&render(&pose, &cam), &cam, &cfg);
    assert_eq!(base.dim, cfg.dim());
    assert_eq!(base.descriptors.len(), base.len() * cfg.dim());
    // Shifted in the image by an exact number of pixels: principal point moved.
    let shifted_cam = Camera::new(
        cam.fx,
        cam.fy,
        cam.cx + 23.0,
        cam.cy - 11.0,
        cam.width,
        cam.height,
    )
    .unwrap();
    let shifted = context(&render(&pose, &shifted_cam), &shifted_cam, &cfg);
    assert_eq!(shifted.points, base.points);
    for (a, b) in shifted.positions.iter().zip(&base.positions) {
        assert!((a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4);
    }
    for (a, b) in shifted.descriptors.iter().zip(&base.descriptors) {
        assert!((a - b).abs() < 1e-5);
    }
    // The same body farther away (fewer pixels) and a different pose.
    let mut far = pose;
    far[2] = 4.2;
    let far = context(&render(&far, &cam), &cam, &cfg);
    assert!(far.points < base.points * 6 / 10);
    let other = context(&render(&BodyModel::neutral_pose(), &cam), &cam, &cfg);
    let same = mean_nearest(&base, &far);
    let diff = mean_nearest(&base, &other);
    let typical: f32 = (0..base.len())
        .map(|i| base.descriptor(i).iter().map(|v| v * v).sum::<f32>().sqrt())
        .sum::<f32>()
        / base.len() as f32;
    assert!(
        same < 0.25 * typical,
        "scale change moved descriptors by {same} of {typical} ({cfg:?})"
    );
    assert!(diff > 1.5 * same, "same {same} other pose {diff} ({cfg:?})");
}

#[test]
fn squared_distance_is_exact() {
    for n in [0usize, 3, 8, 13, 180] {
        let a: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..n).map(|i| (i as f32 * 0.11).cos()).collect();
        let want: f64 = a
            .iter()
            .zip(&b)
            .map(|(x, y)| ((x - y) as f64).powi(2))
            .sum();
        assert!((squared_distance(&a, &b) as f64 - want).abs() < 1e-4 * (1.0 + want));
    }
}

/// The comparison bins against the logarithm and arc-tangent formulas, on offsets
/// spread over the disc (and on the axes and the zero offset): equal wherever the
/// offset is not within rounding of a bin edge.
#[test]
fn log_polar_bins_equal_the_formulas() {
    let config = DescriptorConfig::default();
    let scale = 37.5;
    let bins = LogPolarBins::new(&config, scale);
    let (nr, na) = (config.radial_bins, config.angular_bins);
    let inner = (config.inner_radius * scale) as f32;
    let outer = (config.outer_radius * scale) as f32;
    let mut s = 3u64;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    let mut offsets: Vec<(f32, f32)> = (0..20_000)
        .map(|_| (outer * next(), outer * next()))
        .collect();
    offsets.extend([
        (0.0, 0.0),
        (3.0, 0.0),
        (-3.0, 0.0),
        (0.0, 3.0),
        (0.0, -3.0),
        (-3.0, -0.0),
    ]);
    let (mut checked, mut near_edge) = (0, 0);
    for (du, dv) in offsets {
        let r2 = du * du + dv * dv;
        if r2 >= bins.outer2 {
            continue;
        }
        let ring = (((0.5 * r2.ln() - inner.ln()) * nr as f32 / (outer / inner).ln()).max(0.0)
            as usize)
            .min(nr - 1);
        let theta = dv.atan2(du) + std::f32::consts::PI;
        let sector = ((theta * na as f32 / std::f32::consts::TAU) as usize) % na;
        // Within rounding of an edge, either bin is right.
        let ring_pos = (0.5 * r2.ln() - inner.ln()) * nr as f32 / (outer / inner).ln();
        let sector_pos = theta * na as f32 / std::f32::consts::TAU;
        let near = |x: f32| (x - x.round()).abs() < 1e-4;
        if (near(ring_pos) && ring_pos > 0.5) || (near(sector_pos) && r2 > 0.0) {
            near_edge += 1;
            continue;
        }
        assert_eq!(bins.ring(r2), ring, "ring of ({du}, {dv})");
        assert_eq!(bins.sector(du, dv), sector, "sector of ({du}, {dv})");
        checked += 1;
    }
    assert!(
        checked > 10_000 && near_edge < 50,
        "{checked} checked, {near_edge} near an edge"
    );
}

#[test]
fn four_distances_equal_single_ones() {
    let mut s = 99u64;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
    for len in [0usize, 3, 8, 13, 180] {
        let a: Vec<f32> = (0..len).map(|_| next()).collect();
        let b: Vec<Vec<f32>> = (0..4).map(|_| (0..len).map(|_| next()).collect()).collect();
        let four = squared_distances_x4(&a, std::array::from_fn(|k| &b[k][..]));
        for k in 0..4 {
            assert_eq!(four[k].to_bits(), squared_distance(&a, &b[k]).to_bits());
        }
    }
}

#[test]
fn bad_input_is_rejected() {
    let cfg = DescriptorConfig::default();
    let px = vec![[1.0f32, 2.0]; 50];
    let nm = vec![[0.0f32, 0.0, -1.0]; 49];
    assert!(matches!(
        surface_context_from_points(&px, &nm, &cfg),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(matches!(
        surface_context_from_points(&px[..5], &nm[..5], &cfg),
        Err(Error::NoBody(_))
    ));
    let bad = DescriptorConfig {
        radial_bins: 0,
        ..cfg
    };
    assert!(bad.validate().is_err());
    let bad = DescriptorConfig {
        inner_radius: 3.0,
        ..cfg
    };
    assert!(bad.validate().is_err());
    for w in [-1.0, f64::NAN, 1e3] {
        let bad = DescriptorConfig {
            depth_weight: w,
            ..cfg
        };
        assert!(bad.validate().is_err(), "depth_weight {w}");
    }
    // The relief channel needs depth: bare pixels and normals cannot give it.
    let relief = DescriptorConfig {
        depth_weight: 1.0,
        ..cfg
    };
    let nm50 = vec![[0.0f32, 0.0, -1.0]; 50];
    assert!(matches!(
        surface_context_from_points(&px, &nm50, &relief),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(matches!(
        surface_context_with_relief(&px, &nm50, Some(&[0.0; 49]), &relief),
        Err(Error::InvalidArgument { .. })
    ));
    let cam = Camera::itop();
    let empty = vec![0.0f32; cam.width * cam.height];
    let view = DepthView::new(&empty, cam.height, cam.width, "depth").unwrap();
    assert!(matches!(
        surface_context_from_depth(&view, &cam, None, &cfg),
        Err(Error::NoBody(_))
    ));
    let mask = vec![false; 3];
    let d = render(&BodyModel::neutral_pose(), &cam);
    let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
    assert!(surface_context_from_depth(&view, &cam, Some(&mask), &cfg).is_err());
}
