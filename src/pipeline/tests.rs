//! The estimator and the tracker on scenes rendered from the body model: a room (floor
//! and back wall) with the body standing in it.

use super::*;
use crate::body::{BodyModel, Pose};
use crate::camera::Camera;
use crate::render::BACKGROUND_LABEL;
use crate::templates::{TemplateConfig, TemplateDatabase};
use nalgebra::Vector3;
use std::sync::{Arc, OnceLock};

/// The default template database, built once per test run.
pub(crate) fn default_templates() -> Arc<TemplateDatabase> {
    static DB: OnceLock<Arc<TemplateDatabase>> = OnceLock::new();
    DB.get_or_init(|| {
        Arc::new(
            TemplateDatabase::build(&BodyModel::default(), &TemplateConfig::default()).unwrap(),
        )
    })
    .clone()
}

/// The floor 1 m below the camera and a wall 5 m away, seen by the ITOP camera.
pub(crate) fn room(camera: &Camera) -> Vec<f32> {
    let mut out = vec![0.0f32; camera.width * camera.height];
    for row in 0..camera.height {
        for col in 0..camera.width {
            let ry = (row as f64 - camera.cy) / camera.fy;
            let mut z = 5.0f64;
            if ry > 0.0 {
                z = z.min(1.0 / ry);
            }
            out[row * camera.width + col] = z as f32;
        }
    }
    out
}

/// A walking pose at phase `t` (radians), standing on the floor 3 m away.
pub(crate) fn walking(model: &BodyModel, t: f64) -> Pose {
    let mut p = BodyModel::neutral_pose();
    p[2] = 3.0;
    p[16] = 0.4 * t.sin(); // right hip flexion
    p[19] = -0.4 * t.sin();
    p[18] = 0.1 + 0.5 * (t + 0.8).sin().max(0.0); // right knee
    p[21] = 0.1 + 0.5 * (-(t + 0.8).sin()).max(0.0);
    p[8] = -0.3 * t.sin(); // right shoulder flexion
    p[12] = 0.3 * t.sin();
    let lowest = model
        .joints(&p)
        .iter()
        .map(|j| j[1])
        .fold(f64::MIN, f64::max);
    p[1] = 1.0 - lowest - 0.08;
    p
}

/// The room with the body rendered into it at walking phase `t`: the camera, the depth
/// image and the pose.
pub(crate) fn room_with_body(t: f64) -> (Camera, Vec<f32>, Pose) {
    room_with(&BodyModel::default(), t)
}

/// [`room_with_body`] with the body `model`.
pub(crate) fn room_with(model: &BodyModel, t: f64) -> (Camera, Vec<f32>, Pose) {
    let camera = Camera::itop();
    let pose = walking(model, t);
    let scene = room_posed(model, &pose);
    (camera, scene, pose)
}

/// The room seen by [`Camera::itop`] with the body `model` rendered into it at `pose`.
pub(crate) fn room_posed(model: &BodyModel, pose: &Pose) -> Vec<f32> {
    let camera = Camera::itop();
    let mut scene = room(&camera);
    let (body, _) = model.render_depth(pose, &camera);
    for (s, &b) in scene.iter_mut().zip(&body) {
        if b > 0.0 && b < *s {
            *s = b;
        }
    }
    scene
}

fn mean_joint_error(a: &PoseResult, pose: &Pose) -> f64 {
    mean_joint_error_of(&BodyModel::default(), a, pose)
}

/// `pose` rendered with `model` by `camera` with nothing behind it: the depth (0 off
/// the body) and the body's pixels, the person's mask.
pub(crate) fn rendered_person(
    model: &BodyModel,
    pose: &Pose,
    camera: &Camera,
) -> (Vec<f32>, Vec<bool>) {
    let (depth, labels) = model.render_depth(pose, camera);
    let mask = labels.iter().map(|&l| l != BACKGROUND_LABEL).collect();
    (depth, mask)
}

/// The mean distance between two sets of joints.
pub(crate) fn mean_joint_distance(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q).norm()).sum::<f64>() / a.len() as f64
}

/// The mean distance of `a`'s joints from those of `model` at `pose`.
pub(crate) fn mean_joint_error_of(model: &BodyModel, a: &PoseResult, pose: &Pose) -> f64 {
    mean_joint_distance(&a.joints, &model.joints(pose))
}

pub(crate) fn estimator(camera: &Camera, config: PipelineConfig) -> Estimator {
    Estimator::new(
        camera,
        BodyModel::default(),
        default_templates(),
        config,
        None,
    )
    .unwrap()
}

#[test]
fn the_estimator_finds_a_body_in_a_room_without_a_background() {
    let (camera, depth, pose) = room_with_body(0.6);
    let est = estimator(&camera, PipelineConfig::default());
    let r = crate::pool::on_worker(|| est.estimate(&depth, None)).unwrap();
    let err = mean_joint_error(&r, &pose);
    assert!(err < 0.05, "mean joint error {err}");
    assert_eq!(r.source, Source::Templates);
    assert!(r.discrepancy < 0.2, "{}", r.discrepancy);
    let seg = r.segmentation.as_ref().unwrap();
    assert_eq!(seg.method, crate::segment::Method::Planes);
    assert_eq!(seg.planes.len(), 2);
    assert_eq!(r.labels.len(), depth.len());
    for stage in ["foreground", "templates", "fit"] {
        assert!(r.timings.get(stage).is_some(), "{stage}");
    }
    // A body explained well does not run the wide search.
    assert!(r.timings.get("wide").is_none());
    let sum: f64 = r.timings.stages.iter().map(|s| s.1).sum();
    assert!(r.timings.total >= sum);
}

#[test]
fn the_tracker_follows_a_walk() {
    let camera = Camera::itop();
    let config = PipelineConfig {
        calibration_frames: 0,
        ..PipelineConfig::default()
    };
    let mut tracker = Tracker::new(estimator(&camera, config), false);
    let mut sources = Vec::new();
    for k in 0..8 {
        let (_, depth, pose) = room_with_body(0.3 * k as f64);
        let r = crate::pool::on_worker(|| tracker.update(&depth, None)).unwrap();
        let err = mean_joint_error(&r, &pose);
        assert!(err < 0.06, "frame {k}: mean joint error {err}");
        sources.push(r.source);
    }
    assert_eq!(sources[0], Source::Templates);
    assert!(
        sources[1..]
            .iter()
            .filter(|&&s| s == Source::Tracking)
            .count()
            >= 5
    );
}

#[test]
fn a_large_image_runs_at_the_working_resolution_and_answers_at_its_own() {
    // The same scene seen by a 640×480 camera of twice the focal length.
    let small = Camera::itop();
    let large = Camera::new(
        2.0 * small.fx,
        2.0 * small.fy,
        2.0 * (small.cx + 0.5) - 0.5,
        2.0 * (small.cy + 0.5) - 0.5,
        640,
        480,
    )
    .unwrap();
    let model = BodyModel::default();
    let pose = walking(&model, 0.6);
    let mut scene = room(&large);
    let (body, _) = model.render_depth(&pose, &large);
    for (s, &b) in scene.iter_mut().zip(&body) {
        if b > 0.0 && b < *s {
            *s = b;
        }
    }
    let est = estimator(&large, PipelineConfig::default());
    assert_eq!(est.resolution().factor, 2);
    let r = crate::pool::on_worker(|| est.estimate(&scene, None)).unwrap();
    assert!(mean_joint_error(&r, &pose) < 0.05);
    assert_eq!(r.labels.len(), 640 * 480);
    // The labels lie on the body at the input's resolution.
    let on_body = r
        .labels
        .iter()
        .zip(&body)
        .filter(|(&l, _)| l >= 0)
        .filter(|(_, &b)| b > 0.0)
        .count();
    let labelled = r.labels.iter().filter(|&&l| l >= 0).count();
    assert!(on_body as f64 > 0.95 * labelled as f64);
}

#[test]
fn a_bad_config_is_refused_naming_the_field() {
    let config = PipelineConfig {
        finals: 0,
        ..PipelineConfig::default()
    };
    let err = Estimator::new(
        &Camera::itop(),
        BodyModel::default(),
        default_templates(),
        config,
        None,
    )
    .unwrap_err();
    assert!(err.to_string().starts_with("finals:"), "{err}");
}

#[test]
fn the_tracker_learns_the_room_behind_a_walk_across_it() {
    let camera = Camera::itop();
    let model = BodyModel::default();
    let empty = room(&camera);
    let config = PipelineConfig {
        calibration_frames: 0,
        learn_background: true,
        background_model: crate::segment::BackgroundModelConfig {
            frames: 4,
            ..Default::default()
        },
        ..PipelineConfig::default()
    };
    let mut tracker = Tracker::new(estimator(&camera, config.clone()), false);
    let mut methods = Vec::new();
    for k in 0..14 {
        // Walking in place while moving right across the room.
        let mut pose = walking(&model, 0.3 * k as f64);
        pose[0] = -0.7 + 0.1 * k as f64;
        let depth = room_posed(&model, &pose);
        let r = crate::pool::on_worker(|| tracker.update(&depth, None)).unwrap();
        let err = mean_joint_error(&r, &pose);
        assert!(err < 0.06, "frame {k}: mean joint error {err}");
        let seg = r.segmentation.as_ref().unwrap();
        methods.push(seg.method);
        let (body, _) = model.render_depth(&pose, &camera);
        let truth: Vec<bool> = body.iter().map(|&b| b > 0.0).collect();
        let inter = r.mask.iter().zip(&truth).filter(|(&a, &b)| a && b).count();
        let union = r.mask.iter().zip(&truth).filter(|(&a, &b)| a || b).count();
        let iou = inter as f64 / union as f64;
        assert!(iou > 0.9, "frame {k}: mask IoU {iou}");
    }
    use crate::segment::Method;
    assert_eq!(methods[0], Method::Planes);
    assert!(
        methods[8..].iter().all(|&m| m == Method::Learned),
        "{methods:?}"
    );
    let m = tracker.background_model().unwrap();
    assert!(m.learned_share() > 0.8, "{}", m.learned_share());
    for (&b, &z) in m.background().iter().zip(&empty) {
        assert!(
            b == 0.0 || (b - z).abs() < 0.01,
            "learned {b} where the room is {z}"
        );
    }
    // With a frame of the empty scene nothing is learned.
    let est = Estimator::new(
        &camera,
        BodyModel::default(),
        default_templates(),
        config,
        Some(&empty),
    )
    .unwrap();
    assert!(Tracker::new(est, false).background_model().is_none());
}

/// A hypothesis off to the side of the body is replaced by its copy moved onto the
/// body, which explains the depth better; the true pose, already on the body, stays.
#[test]
fn hypotheses_start_from_their_better_placed_copy() {
    let (camera, depth, pose) = room_with_body(0.6);
    let est = estimator(&camera, PipelineConfig::default());
    let mut frame = est.prepare(&depth, None, None).unwrap();
    let config = est.config().fit_with(Some(2), 2, Some(false));
    let mut off = pose;
    off[0] += 0.25;
    off[2] += 0.3;
    let placed = est
        .better_placed(&mut frame, &config, vec![off, pose])
        .unwrap();
    let gap = |p: &Pose| ((p[0] - pose[0]).powi(2) + (p[2] - pose[2]).powi(2)).sqrt();
    assert!(
        gap(&placed[0]) < 0.1,
        "moved to within {} m",
        gap(&placed[0])
    );
    assert_eq!(&placed[0][3..], &off[3..], "only the translation moves");
    let scores = est.discrepancies(&frame, &[off, placed[0]]).unwrap();
    assert!(scores[1] < scores[0], "{scores:?}");
    assert_eq!(placed[1], pose);
}

/// `depth` with zero-mean Gaussian noise of `noise`'s σ_Z at each depth (Box–Muller on
/// a fixed linear congruential generator: deterministic).
pub(crate) fn with_depth_noise(
    depth: &[f32],
    noise: &crate::fit::DepthNoise,
    mut state: u64,
) -> Vec<f32> {
    let mut uniform = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    depth
        .iter()
        .map(|&z| {
            let normal =
                (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
            (z as f64 + noise.depth_sigma(z as f64) * normal) as f32
        })
        .collect()
}

#[test]
fn the_lost_test_allows_for_the_known_depth_noise() {
    // Stereo-like noise: 0.15 px of disparity with f·B = 0.12·fx, about 4 cm at the
    // body's 3 m. The body is the model itself, so without noise its discrepancy is
    // 0.01–0.04; with it 0.35–0.40, over the threshold of 0.3. For a model whose own
    // residuals have the fit's 2 cm scale the noise adds about 0.18.
    let camera = Camera::itop();
    let noise = crate::fit::DepthNoise {
        focal_baseline: camera.fx * 0.12,
        disparity_sigma: 0.15,
    };
    let config = PipelineConfig {
        calibration_frames: 0,
        lost_discrepancy: 0.3,
        ..PipelineConfig::default()
    };
    let frames: Vec<(Vec<f32>, Pose)> = (0..6)
        .map(|k| {
            let (_, depth, pose) = room_with_body(0.3 * k as f64);
            (with_depth_noise(&depth, &noise, k as u64 + 1), pose)
        })
        .collect();
    let run = |known: Option<crate::fit::DepthNoise>| {
        let mut tracker = Tracker::new(estimator(&camera, config.clone()), false);
        tracker.set_depth_noise(known);
        tracker.start_from(&frames[0].1).unwrap();
        for (k, (depth, pose)) in frames.iter().enumerate() {
            let r = crate::pool::on_worker(|| tracker.update(depth, None)).unwrap();
            let err = mean_joint_error(&r, pose);
            assert!(err < 0.08, "frame {k}: mean joint error {err}");
        }
        tracker.lost_frames
    };
    // Unaware of the noise, every frame looks lost and searches; aware of it, none
    // does.
    assert_eq!(run(None), frames.len());
    assert_eq!(run(Some(noise)), 0);
}

#[test]
fn a_body_upside_down_is_found_by_the_wide_search() {
    // A handstand 3 m away, legs apart, arms out: about vertical, so the first views
    // search it only as it is (upright templates), which explains it badly.
    let model = BodyModel::default();
    let camera = Camera::itop();
    let mut upright = BodyModel::neutral_pose();
    upright[2] = 3.0;
    upright[9] = 1.2; // right shoulder abduction
    upright[13] = 1.2;
    upright[17] = 0.35; // right hip abduction
    upright[20] = 0.35;
    let pose = orientation::rotate_about_optical_axis(&upright, std::f64::consts::PI - 0.1);
    let (depth, mask) = rendered_person(&model, &pose, &camera);
    let est = estimator(&camera, PipelineConfig::default());
    let r = crate::pool::on_worker(|| {
        let mut frame = est.prepare(&depth, Some(&mask), None)?;
        let (_, first) = est.search(&mut frame, &[], est.config().hypotheses, None)?;
        assert!(
            first > est.config().lost_discrepancy,
            "the first views explain it with discrepancy {first}"
        );
        est.estimate(&depth, Some(&mask))
    })
    .unwrap();
    assert!(r.timings.get("wide").is_some(), "the wide search ran");
    let err = mean_joint_error(&r, &pose);
    assert!(err < 0.06, "mean joint error {err}");
    assert!(r.discrepancy < 0.3, "{}", r.discrepancy);
}
