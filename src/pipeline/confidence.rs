//! How much of the data supports each output joint.

use crate::body::{seg, BodyModel, Pose, NUM_JOINTS, NUM_SEGMENTS};
use crate::camera::Camera;
use nalgebra::Vector3;

/// The segments whose points witness each joint (ITOP joint order).
const JOINT_PARTS: [&[usize]; NUM_JOINTS] = [
    &[seg::HEAD],
    &[seg::NECK, seg::TORSO],
    &[seg::TORSO, seg::R_UPPER_ARM],
    &[seg::TORSO, seg::L_UPPER_ARM],
    &[seg::R_UPPER_ARM, seg::R_FOREARM],
    &[seg::L_UPPER_ARM, seg::L_FOREARM],
    &[seg::R_FOREARM, seg::R_HAND],
    &[seg::L_FOREARM, seg::L_HAND],
    &[seg::TORSO, seg::PELVIS],
    &[seg::PELVIS, seg::R_THIGH],
    &[seg::PELVIS, seg::L_THIGH],
    &[seg::R_THIGH, seg::R_SHIN],
    &[seg::L_THIGH, seg::L_SHIN],
    &[seg::R_SHIN, seg::R_FOOT],
    &[seg::L_SHIN, seg::L_FOOT],
];

/// A joint none of whose parts is visible in the fitted body's rendering gets this: it
/// rests on the kinematic chain alone.
pub const HIDDEN_JOINT_CONFIDENCE: f64 = 0.3;

/// Per-joint confidence in [0, 1]: the share of the fitted body's visible surface
/// around the joint (its parts in `rendered`, the body's own rendering at `pose`) that
/// the data labelled as those parts (`labels`); [`HIDDEN_JOINT_CONFIDENCE`] for a joint
/// whose parts are all hidden, 0 for a joint outside the image.
pub fn joint_confidence(
    joints: &[Vector3<f64>; NUM_JOINTS],
    labels: &[i16],
    rendered: &[i16],
    camera: &Camera,
) -> [f64; NUM_JOINTS] {
    let count = |image: &[i16]| {
        let mut n = [0u64; NUM_SEGMENTS];
        for &l in image {
            if l >= 0 && (l as usize) < NUM_SEGMENTS {
                n[l as usize] += 1;
            }
        }
        n
    };
    let (seen, expect) = (count(labels), count(rendered));
    std::array::from_fn(|j| {
        let inside = camera.project(&joints[j]).is_some_and(|(u, v)| {
            u >= 0.0 && u < camera.width as f64 && v >= 0.0 && v < camera.height as f64
        });
        if !inside {
            return 0.0;
        }
        let e: u64 = JOINT_PARTS[j].iter().map(|&p| expect[p]).sum();
        let s: u64 = JOINT_PARTS[j].iter().map(|&p| seen[p]).sum();
        if e > 0 {
            (s as f64 / e as f64).min(1.0)
        } else {
            HIDDEN_JOINT_CONFIDENCE
        }
    })
}

/// [`joint_confidence`] of `model` at `pose`, rendering it.
pub fn pose_confidence(
    model: &BodyModel,
    pose: &Pose,
    labels: &[i16],
    camera: &Camera,
) -> [f64; NUM_JOINTS] {
    let (_, rendered) = model.render_depth(pose, camera);
    joint_confidence(&model.joints(pose), labels, &rendered, camera)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fully_labelled_body_is_certain_and_an_unlabelled_one_is_not() {
        let model = BodyModel::new(1.75).unwrap();
        let camera = Camera::itop();
        let pose = BodyModel::neutral_pose();
        let (_, rendered) = model.render_depth(&pose, &camera);
        let full = pose_confidence(&model, &pose, &rendered, &camera);
        assert!(full.iter().all(|&c| c == 1.0), "{full:?}");
        let none = vec![-1i16; rendered.len()];
        let empty = pose_confidence(&model, &pose, &none, &camera);
        assert!(empty.iter().all(|&c| c == 0.0), "{empty:?}");
        // Half of the head labelled as head.
        let mut half = none.clone();
        let mut k = 0;
        for (h, &r) in half.iter_mut().zip(&rendered) {
            if r == seg::HEAD as i16 {
                k += 1;
                if k % 2 == 0 {
                    *h = r;
                }
            }
        }
        let c = pose_confidence(&model, &pose, &half, &camera);
        assert!((c[0] - (k / 2) as f64 / k as f64).abs() < 1e-12, "{}", c[0]);
    }

    #[test]
    fn a_joint_outside_the_image_has_none() {
        let model = BodyModel::new(1.75).unwrap();
        let camera = Camera::itop();
        let mut pose = BodyModel::neutral_pose();
        pose[0] = 2.2; // the body half out of the image to the right
        let (_, rendered) = model.render_depth(&pose, &camera);
        let c = pose_confidence(&model, &pose, &rendered, &camera);
        let joints = model.joints(&pose);
        for (j, p) in joints.iter().enumerate() {
            let u = camera.fx * p.x / p.z + camera.cx;
            if u >= camera.width as f64 {
                assert_eq!(c[j], 0.0);
            }
        }
        assert!(c.contains(&0.0));
    }
}
