//! The template catalogue: the limb poses and views the templates combine, and the
//! pose of each template.

use crate::body::{param, Pose, NUM_PARAMS};

/// Poses per limb and view directions.
pub const LIMB_POSES: usize = 4;
pub const NUM_VIEWS: usize = 3;
/// Total number of templates: 4⁴ body poses × 3 views.
pub const NUM_TEMPLATES: usize = LIMB_POSES * LIMB_POSES * LIMB_POSES * LIMB_POSES * NUM_VIEWS;

pub const ARM_POSE_NAMES: [&str; LIMB_POSES] = ["down", "raised_sideways", "forward", "bent"];
pub const LEG_POSE_NAMES: [&str; LIMB_POSES] =
    ["standing", "step_forward", "step_back", "knee_raised"];
pub const VIEW_NAMES: [&str; NUM_VIEWS] = ["front", "left_side", "right_side"];

/// Shoulder (flexion, abduction, rotation) and elbow flexion of each arm pose.
pub(super) const ARM_POSES: [[f64; 4]; LIMB_POSES] = [
    [0.0, 0.12, 0.0, 0.1],  // down
    [0.0, 1.45, 0.0, 0.1],  // raised sideways (near horizontal)
    [1.45, 0.1, 0.0, 0.1],  // forward (near horizontal)
    [0.25, 0.35, 0.0, 1.7], // bent (forearm forward and up)
];
/// Hip (flexion, abduction) and knee flexion of each leg pose.
pub(super) const LEG_POSES: [[f64; 3]; LIMB_POSES] = [
    [0.0, 0.04, 0.0],   // standing
    [0.45, 0.04, 0.15], // step forward
    [-0.35, 0.04, 0.4], // step back
    [1.4, 0.04, 1.6],   // knee raised
];
/// Yaw (about the body's vertical axis) of each view: +90° turns the subject's left
/// side toward the camera.
pub(super) const VIEW_YAW: [f64; NUM_VIEWS] = [
    0.0,
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
];

/// Arm, arm, leg, leg pose codes (right arm, left arm, right leg, left leg) and view of
/// template `index` (`index = view·256 + r_arm·64 + l_arm·16 + r_leg·4 + l_leg`).
pub fn template_code(index: usize) -> ([usize; 4], usize) {
    let view = index / 256;
    let rest = index % 256;
    ([rest / 64, (rest / 16) % 4, (rest / 4) % 4, rest % 4], view)
}

/// The pose of template `index`, hip centre `distance` m straight ahead.
pub fn template_pose(index: usize, distance: f64) -> Pose {
    let ([ra, la, rl, ll], view) = template_code(index);
    let mut p = [0.0; NUM_PARAMS];
    p[param::ROOT_T + 2] = distance;
    p[param::ROOT_R + 1] = VIEW_YAW[view];
    let arm = |p: &mut Pose, sh: usize, el: usize, code: usize| {
        p[sh..sh + 3].copy_from_slice(&ARM_POSES[code][..3]);
        p[el] = ARM_POSES[code][3];
    };
    arm(&mut p, param::R_SHOULDER, param::R_ELBOW, ra);
    arm(&mut p, param::L_SHOULDER, param::L_ELBOW, la);
    let leg = |p: &mut Pose, hip: usize, knee: usize, code: usize| {
        p[hip..hip + 2].copy_from_slice(&LEG_POSES[code][..2]);
        p[knee] = LEG_POSES[code][2];
    };
    leg(&mut p, param::R_HIP, param::R_KNEE, rl);
    leg(&mut p, param::L_HIP, param::L_KNEE, ll);
    p
}
