//! More starts for a fit: the given start pose moved onto the observed body, and
//! (optionally) with its left and right limbs exchanged.
//!
//! EM converges only from near the truth, and the translation is what a rough start
//! gets wrong most harmfully: a body 5–10 cm off in depth or sideways is labelled
//! badly in the first E-step (limbs take torso points, the torso takes background-side
//! points) and the fit settles far away, with an energy tens of times the right one.
//! Moving the start so that the centroid of its visible surface lands on the centroid
//! of the observed points fixes that; the fit runs from both starts and keeps the one
//! with the lower energy (the move can also hurt, when the start's limbs are misplaced
//! and pull its centroid).

use crate::body::{param, BodyModel, Pose};
use crate::camera::Camera;
use crate::cloud::{Cloud, DepthView};
use nalgebra::Vector3;

/// `pose` with the angles of the left and right legs exchanged (`legs`) and/or those of
/// the arms (`arms`). The joint limits are symmetric, so the result is within them.
pub fn limbs_swapped(pose: &Pose, legs: bool, arms: bool) -> Pose {
    let mut out = *pose;
    let mut swap = |right: usize, left: usize, n: usize| {
        out[right..right + n].copy_from_slice(&pose[left..left + n]);
        out[left..left + n].copy_from_slice(&pose[right..right + n]);
    };
    if legs {
        swap(param::R_HIP, param::L_HIP, 3);
    }
    if arms {
        swap(param::R_SHOULDER, param::L_SHOULDER, 4);
    }
    out
}

/// Below this shift (m) the moved start is not worth a second fit.
pub const MIN_SHIFT: f64 = 0.01;

/// The model's visible surface is rendered at this fraction of the image size.
const RENDER_SCALE: f64 = 0.5;

/// Rounds of rendering and moving: perspective makes the rendered centroid move a
/// little less or more than the body, a second round takes up most of the remainder.
const ROUNDS: usize = 2;

/// Centroid of the points of a depth image's readings (z > 0), back-projected as the
/// fit's own cloud is, so rendered and observed centroids are alike.
fn depth_centroid(depth: &[f32], camera: &Camera) -> Option<Vector3<f64>> {
    let view = DepthView::new(depth, camera.height, camera.width, "depth").ok()?;
    Cloud::from_depth(&view, camera, None).ok()?.centroid()
}

/// `init` translated so that the centroid of its visible surface (rendered through
/// `camera` at half resolution) lies at `target`, the centroid of the observed points
/// ([`Cloud::centroid`]).
/// None when the model is out of view, or the move is under [`MIN_SHIFT`].
pub fn recentred(
    model: &BodyModel,
    init: &Pose,
    camera: &Camera,
    target: &Vector3<f64>,
) -> Option<Pose> {
    let small = camera.scaled(RENDER_SCALE).ok()?;
    let mut pose = *init;
    let mut depth = vec![0.0f32; small.width * small.height];
    let mut labels = vec![0i16; depth.len()];
    for _ in 0..ROUNDS {
        depth.fill(0.0);
        model
            .render_depth_into(&pose, &small, &mut depth, &mut labels)
            .ok()?;
        let shift = target - depth_centroid(&depth, &small)?;
        for (k, d) in shift.iter().enumerate() {
            pose[param::ROOT_T + k] += d;
        }
    }
    let moved = Vector3::from_fn(|k, _| pose[param::ROOT_T + k] - init[param::ROOT_T + k]);
    (moved.iter().all(|v| v.is_finite()) && moved.norm() >= MIN_SHIFT).then_some(pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random poses in view (joint angles ±0.6 rad around neutral, the root turned up
    /// to ±0.3 rad, 2.2–4 m away), started up to 0.1 m off on each axis: the moved start
    /// lands within 2 cm of the true translation, within 5 mm in the median. (The visible
    /// surface changes a little as the body moves, so the centroids are not rigid.)
    #[test]
    fn recentring_recovers_random_translated_poses() {
        let model = BodyModel::default();
        let cam = Camera::itop();
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = |lo: f64, hi: f64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((state >> 11) as f64 / (1u64 << 53) as f64)
        };
        let mut errors = Vec::new();
        for _ in 0..60 {
            let mut truth = BodyModel::neutral_pose();
            for v in truth[6..].iter_mut() {
                *v += uniform(-0.6, 0.6);
            }
            for k in 0..3 {
                truth[param::ROOT_R + k] = uniform(-0.3, 0.3);
            }
            truth[param::ROOT_T] = uniform(-0.4, 0.4);
            truth[param::ROOT_T + 1] = uniform(-0.2, 0.2);
            truth[param::ROOT_T + 2] = uniform(2.2, 4.0);
            let truth = BodyModel::clamp_pose(&truth);
            let (depth, _) = model.render_depth(&truth, &cam);
            let target = depth_centroid(&depth, &cam).unwrap();
            let mut init = truth;
            for k in 0..3 {
                init[param::ROOT_T + k] += uniform(-0.1, 0.1);
            }
            let moved = recentred(&model, &init, &cam, &target).unwrap_or(init);
            let err = Vector3::from_fn(|k, _| moved[param::ROOT_T + k] - truth[param::ROOT_T + k]);
            errors.push(err.norm());
        }
        errors.sort_by(f64::total_cmp);
        assert!(errors[errors.len() - 1] < 0.02, "{errors:?}");
        assert!(errors[errors.len() / 2] < 0.005, "{errors:?}");
    }

    #[test]
    fn limbs_swapped_exchanges_sides_and_undoes_itself() {
        let mut p = BodyModel::neutral_pose();
        for (k, v) in p.iter_mut().enumerate() {
            *v += 0.01 * k as f64;
        }
        let q = limbs_swapped(&p, true, true);
        assert_eq!(
            q[param::R_HIP..param::R_HIP + 3],
            p[param::L_HIP..param::L_HIP + 3]
        );
        assert_eq!(
            q[param::L_HIP..param::L_HIP + 3],
            p[param::R_HIP..param::R_HIP + 3]
        );
        assert_eq!(
            q[param::R_SHOULDER..param::R_ELBOW + 1],
            p[param::L_SHOULDER..param::L_ELBOW + 1]
        );
        assert_eq!(q[..param::R_SHOULDER], p[..param::R_SHOULDER]);
        assert_eq!(limbs_swapped(&q, true, true), p);
        assert_eq!(limbs_swapped(&p, false, false), p);
        let legs = limbs_swapped(&p, true, false);
        assert_eq!(legs[..param::R_HIP], p[..param::R_HIP]);
        assert_eq!(BodyModel::clamp_pose(&q), q);
    }

    /// The model rendered at a known pose, started 8 cm off: the moved start lands
    /// within a few millimetres of the true translation; a start already in place gets
    /// no second start.
    #[test]
    fn recentring_recovers_a_translated_start() {
        let model = BodyModel::default();
        let cam = Camera::itop();
        let mut truth = BodyModel::neutral_pose();
        truth[param::ROOT_T + 2] = 3.0;
        truth[param::ROOT_R + 1] = 0.4;
        let (depth, _) = model.render_depth(&truth, &cam);
        let target = depth_centroid(&depth, &cam).unwrap();
        for offset in [[0.08, 0.0, 0.0], [0.0, -0.06, 0.0], [0.03, 0.04, -0.08]] {
            let mut init = truth;
            for k in 0..3 {
                init[param::ROOT_T + k] += offset[k];
            }
            let moved = recentred(&model, &init, &cam, &target).expect("moved");
            for k in 0..3 {
                let err = (moved[param::ROOT_T + k] - truth[param::ROOT_T + k]).abs();
                assert!(err < 0.006, "offset {offset:?}: axis {k} off by {err}");
            }
            assert_eq!(moved[param::ROOT_T + 3..], truth[param::ROOT_T + 3..]);
        }
        assert!(recentred(&model, &truth, &cam, &target).is_none());
        // Out of view: nothing rendered, no second start.
        let mut behind = truth;
        behind[param::ROOT_T + 2] = -3.0;
        assert!(recentred(&model, &behind, &cam, &target).is_none());
    }
}
