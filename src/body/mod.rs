//! The articulated body model: skeleton, shape, pose parameters and limits.
//!
//! # Segments
//! [`NUM_SEGMENTS`] = 16 rigid segments, each carrying one ellipsoid for fitting (see
//! [`PART_NAMES`]): head, neck, torso, pelvis and per side upper arm, forearm, hand,
//! thigh, shin, foot. Hands move with forearms, feet with shins, the head with the neck
//! and the torso with the pelvis, so there are 10 joints and 22 degrees of freedom.
//!
//! # Frames
//! The body (root) frame sits at the hip centre (midpoint of the two hip joint centres).
//! Its axes: **x = the subject's left, y = down (feet), z = the subject's back**. The
//! neutral pose ([`BodyModel::neutral_pose`]) has a zero root rotation, so the body frame
//! is then parallel to the camera frame (x right, y down, z forward): the subject stands
//! upright facing the camera, their right side at the image left. Every segment frame is
//! parallel to the body frame when all joint angles are zero, with its origin at the
//! segment's proximal joint (see [`kinematics`]); limbs hang along +y.
//!
//! # Pose parameters ([`NUM_PARAMS`] = 22, see [`PARAM_NAMES`])
//! 0..3 root translation = hip centre in the camera frame (m); 3..6 root rotation vector
//! (axis-angle, body→camera); then joint angles in radians. Every angle is anatomical
//! and means the same motion on both sides:
//! - neck: flexion (head forward/down, about body +x), lateral bend (head toward the
//!   subject's left, about +z);
//! - shoulder: flexion (arm forward), abduction (arm sideways away from the body),
//!   internal rotation (about the upper-arm axis); R = R_flex · R_abd · R_twist;
//! - elbow: flexion (forearm forward);
//! - hip: flexion (thigh forward), abduction (leg sideways away); R = R_flex · R_abd;
//! - knee: flexion (shin backward).
//!
//! # Root rotation increments
//! The least-squares Jacobians ([`BodyModel::residuals_and_jacobian`],
//! [`BodyModel::joints_jacobian`]) give columns 3..6 with respect to a **local rotation
//! increment** ω (body-frame axes): R ← R · exp(\[ω\]×), not with respect to the rotation
//! vector itself. Apply an LM step to a pose with [`pose_with_root_increment`].

pub mod ellipsoid;
pub mod kinematics;
pub mod penetration;
pub mod residuals;
pub mod rotation;
pub mod superquadric;

use crate::error::{Error, Result};
use nalgebra::{Rotation3, Vector3};

pub use ellipsoid::{closest_point_on_ellipsoid, signed_distance_to_ellipsoid, EllipsoidDistance};
pub use kinematics::{Kinematics, PoseFrames};

/// Number of rigid segments (ellipsoids).
pub const NUM_SEGMENTS: usize = 16;
/// Number of pose parameters.
pub const NUM_PARAMS: usize = 22;
/// Number of output joints (ITOP order).
pub const NUM_JOINTS: usize = 15;

/// A pose: the 22 parameters described in the module docs.
pub type Pose = [f64; NUM_PARAMS];

/// Segment (part) names, in label order.
pub const PART_NAMES: [&str; NUM_SEGMENTS] = [
    "head",
    "neck",
    "torso",
    "pelvis",
    "r_upper_arm",
    "r_forearm",
    "r_hand",
    "l_upper_arm",
    "l_forearm",
    "l_hand",
    "r_thigh",
    "r_shin",
    "r_foot",
    "l_thigh",
    "l_shin",
    "l_foot",
];

/// Segment indices.
pub mod seg {
    pub const HEAD: usize = 0;
    pub const NECK: usize = 1;
    pub const TORSO: usize = 2;
    pub const PELVIS: usize = 3;
    pub const R_UPPER_ARM: usize = 4;
    pub const R_FOREARM: usize = 5;
    pub const R_HAND: usize = 6;
    pub const L_UPPER_ARM: usize = 7;
    pub const L_FOREARM: usize = 8;
    pub const L_HAND: usize = 9;
    pub const R_THIGH: usize = 10;
    pub const R_SHIN: usize = 11;
    pub const R_FOOT: usize = 12;
    pub const L_THIGH: usize = 13;
    pub const L_SHIN: usize = 14;
    pub const L_FOOT: usize = 15;
}

/// Output joint names, ITOP order.
pub const JOINT_NAMES: [&str; NUM_JOINTS] = [
    "Head",
    "Neck",
    "RShoulder",
    "LShoulder",
    "RElbow",
    "LElbow",
    "RHand",
    "LHand",
    "Torso",
    "RHip",
    "LHip",
    "RKnee",
    "LKnee",
    "RFoot",
    "LFoot",
];

/// Each output joint is the origin of one segment frame: Head = head centre, Neck = base
/// of the neck, Hand = wrist, Foot = ankle, Torso = mid-spine.
pub const JOINT_SEGMENT: [usize; NUM_JOINTS] = [
    seg::HEAD,
    seg::NECK,
    seg::R_UPPER_ARM,
    seg::L_UPPER_ARM,
    seg::R_FOREARM,
    seg::L_FOREARM,
    seg::R_HAND,
    seg::L_HAND,
    seg::TORSO,
    seg::R_THIGH,
    seg::L_THIGH,
    seg::R_SHIN,
    seg::L_SHIN,
    seg::R_FOOT,
    seg::L_FOOT,
];

/// Pose parameter names, in order.
pub const PARAM_NAMES: [&str; NUM_PARAMS] = [
    "root_tx",
    "root_ty",
    "root_tz",
    "root_rx",
    "root_ry",
    "root_rz",
    "neck_flexion",
    "neck_lateral",
    "r_shoulder_flexion",
    "r_shoulder_abduction",
    "r_shoulder_rotation",
    "r_elbow_flexion",
    "l_shoulder_flexion",
    "l_shoulder_abduction",
    "l_shoulder_rotation",
    "l_elbow_flexion",
    "r_hip_flexion",
    "r_hip_abduction",
    "r_knee_flexion",
    "l_hip_flexion",
    "l_hip_abduction",
    "l_knee_flexion",
];

/// Parameter indices.
pub mod param {
    pub const ROOT_T: usize = 0;
    pub const ROOT_R: usize = 3;
    pub const NECK: usize = 6;
    pub const R_SHOULDER: usize = 8;
    pub const R_ELBOW: usize = 11;
    pub const L_SHOULDER: usize = 12;
    pub const L_ELBOW: usize = 15;
    pub const R_HIP: usize = 16;
    pub const R_KNEE: usize = 18;
    pub const L_HIP: usize = 19;
    pub const L_KNEE: usize = 21;
}

/// Biomechanical limits of the joint angles (radians), from standard range-of-motion
/// tables (e.g. AAOS / Norkin & White), slightly widened so real poses are not clipped.
/// Pairs of (lower, upper) for parameters 6..22.
const JOINT_LIMITS: [(f64, f64); NUM_PARAMS - 6] = [
    (-1.0, 1.2), // neck flexion (extension is negative)
    (-0.8, 0.8), // neck lateral bend
    (-1.1, 3.1), // r shoulder flexion (extension ~60°, flexion ~180°)
    (-0.6, 3.1), // r shoulder abduction (adduction across the body ~30°)
    (-1.6, 1.6), // r shoulder internal(+)/external(−) rotation
    (0.0, 2.6),  // r elbow flexion (~150°)
    (-1.1, 3.1), // l shoulder flexion
    (-0.6, 3.1), // l shoulder abduction
    (-1.6, 1.6), // l shoulder rotation
    (0.0, 2.6),  // l elbow
    (-0.6, 2.3), // r hip flexion (extension ~30°, flexion ~125°)
    (-0.6, 1.3), // r hip abduction
    (0.0, 2.6),  // r knee flexion
    (-0.6, 2.3), // l hip flexion
    (-0.6, 1.3), // l hip abduction
    (0.0, 2.6),  // l knee flexion
];

/// Shoulder abduction of the neutral pose: arms hang down, just clear of the torso.
const NEUTRAL_ARM_ABDUCTION: f64 = 0.12;
/// Elbow flexion of the neutral pose (a relaxed arm is slightly bent).
const NEUTRAL_ELBOW_FLEXION: f64 = 0.1;
/// Distance of the neutral pose's hip centre from the camera (m).
const NEUTRAL_DISTANCE: f64 = 3.0;

/// Reference height of the proportions below (the shared synthetic body is 1.75 m).
pub const REFERENCE_HEIGHT: f64 = 1.75;

/// Body shape: segment lengths and ellipsoid radii (metres), symmetric left/right.
///
/// Proportions at 1.75 m come from the shared realistic synthetic body
/// (`shared/data/synth/README.md` and the median joint positions of its sequences,
/// relative to the hip centre): upper arm 0.239, forearm 0.238, thigh 0.443,
/// knee→ankle 0.401, shoulder width 0.352, hip width 0.232, hip centre→shoulder line
/// 0.505, shoulder line→neck base 0.068, neck base→head centre 0.19, mid-spine 0.327
/// above the hip centre, ankle 0.066 above the floor. Radii, hand and foot sizes are
/// adult-male anthropometric averages (half breadths/depths, e.g. NASA-STD-3000 /
/// Dreyfuss tables) at 1.75 m. Other heights scale everything uniformly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyShape {
    /// Hip centre → shoulder line, along the body's vertical axis.
    pub torso_length: f64,
    /// Shoulder line → base of the neck (the Neck joint).
    pub neck_length: f64,
    /// Base of the neck → head centre (the Head joint).
    pub head_offset: f64,
    /// Hip centre → mid-spine (the Torso joint).
    pub spine_offset: f64,
    /// Distance between the two shoulder joint centres.
    pub shoulder_width: f64,
    /// Distance between the two hip joint centres.
    pub hip_width: f64,
    pub upper_arm_length: f64,
    pub forearm_length: f64,
    /// Wrist → fingertips.
    pub hand_length: f64,
    pub thigh_length: f64,
    /// Knee → ankle.
    pub shin_length: f64,
    /// Ankle → floor.
    pub ankle_height: f64,
    /// Heel → toe.
    pub foot_length: f64,
    /// Head half-axes (left-right, vertical, front-back).
    pub head_radius_x: f64,
    pub head_radius_y: f64,
    pub head_radius_z: f64,
    pub neck_radius: f64,
    /// Chest half-breadth and half-depth.
    pub chest_radius_x: f64,
    pub chest_radius_z: f64,
    /// Pelvis half-breadth and half-depth.
    pub pelvis_radius_x: f64,
    pub pelvis_radius_z: f64,
    pub upper_arm_radius: f64,
    pub forearm_radius: f64,
    /// Hand half-breadth.
    pub hand_radius: f64,
    pub thigh_radius: f64,
    pub shin_radius: f64,
    /// Foot half-breadth.
    pub foot_radius: f64,
}

/// Names of the shape parameters, the order of [`BodyShape::to_vec`].
pub const SHAPE_PARAM_NAMES: [&str; 27] = [
    "torso_length",
    "neck_length",
    "head_offset",
    "spine_offset",
    "shoulder_width",
    "hip_width",
    "upper_arm_length",
    "forearm_length",
    "hand_length",
    "thigh_length",
    "shin_length",
    "ankle_height",
    "foot_length",
    "head_radius_x",
    "head_radius_y",
    "head_radius_z",
    "neck_radius",
    "chest_radius_x",
    "chest_radius_z",
    "pelvis_radius_x",
    "pelvis_radius_z",
    "upper_arm_radius",
    "forearm_radius",
    "hand_radius",
    "thigh_radius",
    "shin_radius",
    "foot_radius",
];

/// Number of shape parameters.
pub const NUM_SHAPE_PARAMS: usize = SHAPE_PARAM_NAMES.len();

impl Default for BodyShape {
    fn default() -> Self {
        BodyShape::from_height(REFERENCE_HEIGHT).expect("reference height is valid")
    }
}

impl BodyShape {
    /// The reference proportions scaled to a subject `height` metres tall (0.5–2.5 m).
    pub fn from_height(height: f64) -> Result<Self> {
        if !(height.is_finite() && (0.5..=2.5).contains(&height)) {
            return Err(Error::invalid(
                "height",
                format!("must be a body height in metres within 0.5..2.5, got {height}"),
            ));
        }
        let k = height / REFERENCE_HEIGHT;
        let reference = [
            0.505, 0.068, 0.19, 0.327, 0.352, 0.232, 0.239, 0.238, 0.185, 0.443, 0.401, 0.066,
            0.26, 0.078, 0.113, 0.098, 0.058, 0.165, 0.105, 0.170, 0.110, 0.046, 0.038, 0.045,
            0.075, 0.052, 0.047,
        ];
        let mut v = [0.0; NUM_SHAPE_PARAMS];
        for (o, r) in v.iter_mut().zip(reference) {
            *o = r * k;
        }
        BodyShape::from_vec(&v)
    }

    /// The parameters in [`SHAPE_PARAM_NAMES`] order.
    pub fn to_vec(&self) -> [f64; NUM_SHAPE_PARAMS] {
        [
            self.torso_length,
            self.neck_length,
            self.head_offset,
            self.spine_offset,
            self.shoulder_width,
            self.hip_width,
            self.upper_arm_length,
            self.forearm_length,
            self.hand_length,
            self.thigh_length,
            self.shin_length,
            self.ankle_height,
            self.foot_length,
            self.head_radius_x,
            self.head_radius_y,
            self.head_radius_z,
            self.neck_radius,
            self.chest_radius_x,
            self.chest_radius_z,
            self.pelvis_radius_x,
            self.pelvis_radius_z,
            self.upper_arm_radius,
            self.forearm_radius,
            self.hand_radius,
            self.thigh_radius,
            self.shin_radius,
            self.foot_radius,
        ]
    }

    /// A shape from parameters in [`SHAPE_PARAM_NAMES`] order; each must be finite and
    /// within 1 mm .. 2 m.
    pub fn from_vec(v: &[f64]) -> Result<Self> {
        if v.len() != NUM_SHAPE_PARAMS {
            return Err(Error::invalid(
                "shape",
                format!("needs {NUM_SHAPE_PARAMS} values, got {}", v.len()),
            ));
        }
        if let Some(i) = v
            .iter()
            .position(|x| !(x.is_finite() && (MIN_SHAPE_VALUE..=MAX_SHAPE_VALUE).contains(x)))
        {
            return Err(Error::invalid(
                "shape",
                format!(
                    "{} must be within {MIN_SHAPE_VALUE}..{MAX_SHAPE_VALUE} m, got {}",
                    SHAPE_PARAM_NAMES[i], v[i]
                ),
            ));
        }
        Ok(BodyShape {
            torso_length: v[0],
            neck_length: v[1],
            head_offset: v[2],
            spine_offset: v[3],
            shoulder_width: v[4],
            hip_width: v[5],
            upper_arm_length: v[6],
            forearm_length: v[7],
            hand_length: v[8],
            thigh_length: v[9],
            shin_length: v[10],
            ankle_height: v[11],
            foot_length: v[12],
            head_radius_x: v[13],
            head_radius_y: v[14],
            head_radius_z: v[15],
            neck_radius: v[16],
            chest_radius_x: v[17],
            chest_radius_z: v[18],
            pelvis_radius_x: v[19],
            pelvis_radius_z: v[20],
            upper_arm_radius: v[21],
            forearm_radius: v[22],
            hand_radius: v[23],
            thigh_radius: v[24],
            shin_radius: v[25],
            foot_radius: v[26],
        })
    }

    /// Height of the subject standing in the neutral pose: floor → top of the head.
    pub fn standing_height(&self) -> f64 {
        self.thigh_length
            + self.shin_length
            + self.ankle_height
            + self.torso_length
            + self.neck_length
            + self.head_offset
            + (1.0 - HEAD_ELLIPSOID_DROP) * self.head_radius_y
    }
}

/// Names of the shape factors: a small symmetric (left = right) parameterisation of the
/// body shape for calibration, each a scale factor of a group of [`BodyShape`]
/// parameters relative to a base shape (see [`BodyShape::scaled`]).
pub const SHAPE_FACTOR_NAMES: [&str; NUM_SHAPE_FACTORS] = [
    "torso_length",
    "torso_width",
    "torso_depth",
    "head_neck",
    "upper_arm",
    "forearm",
    "thigh",
    "shin",
    "shoulder_width",
    "hip_width",
    "arm_radius",
    "leg_radius",
];

/// Number of shape factors.
pub const NUM_SHAPE_FACTORS: usize = 12;

/// Shape factors in [`SHAPE_FACTOR_NAMES`] order (1 = the base shape).
pub type ShapeFactors = [f64; NUM_SHAPE_FACTORS];

/// The [`BodyShape`] parameters (indices into [`SHAPE_PARAM_NAMES`]) each shape factor
/// scales. Every shape parameter belongs to exactly one factor.
pub const SHAPE_FACTOR_GROUPS: [&[usize]; NUM_SHAPE_FACTORS] = [
    &[0, 3],                 // torso_length: hip centre → shoulder line, mid-spine offset
    &[17, 19],               // torso_width: chest and pelvis half-breadths
    &[18, 20],               // torso_depth: chest and pelvis half-depths
    &[1, 2, 13, 14, 15, 16], // head_neck: neck length, head offset, head radii, neck radius
    &[6],                    // upper_arm length
    &[7, 8],                 // forearm + hand length
    &[9],                    // thigh length
    &[10, 11, 12],           // shin + ankle height + foot length
    &[4],                    // shoulder_width
    &[5],                    // hip_width
    &[21, 22, 23],           // arm radii: upper arm, forearm, hand
    &[24, 25, 26],           // leg radii: thigh, shin, foot
];

impl BodyShape {
    /// This shape with every parameter of factor j's group multiplied by `factors[j]`.
    /// Factors must be finite and positive, and the result must pass
    /// [`BodyShape::from_vec`].
    pub fn scaled(&self, factors: &[f64]) -> Result<BodyShape> {
        if factors.len() != NUM_SHAPE_FACTORS {
            return Err(Error::invalid(
                "factors",
                format!(
                    "needs {NUM_SHAPE_FACTORS} shape factors, got {}",
                    factors.len()
                ),
            ));
        }
        if let Some(i) = factors.iter().position(|f| !(f.is_finite() && *f > 0.0)) {
            return Err(Error::invalid(
                "factors",
                format!(
                    "{} must be finite and > 0, got {}",
                    SHAPE_FACTOR_NAMES[i], factors[i]
                ),
            ));
        }
        let mut v = self.to_vec();
        for (group, f) in SHAPE_FACTOR_GROUPS.iter().zip(factors) {
            for &i in *group {
                v[i] *= f;
            }
        }
        BodyShape::from_vec(&v)
    }
}

/// Smallest and largest admissible shape parameter (m).
const MIN_SHAPE_VALUE: f64 = 1e-3;
const MAX_SHAPE_VALUE: f64 = 2.0;

/// An ellipsoid in a segment frame: centre and half-axes along the frame's x, y, z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentEllipsoid {
    pub centre: Vector3<f64>,
    pub radii: Vector3<f64>,
}

/// Limb ellipsoids reach this fraction of the bone length beyond each joint, so that
/// consecutive segments overlap instead of pinching to a point at the joint.
const LIMB_OVERHANG: f64 = 0.1;

/// Torso ellipsoid: from this fraction of `torso_length` above the hip centre (the
/// waist) up to this fraction (over the shoulders).
const TORSO_BOTTOM: f64 = 0.30;
const TORSO_TOP: f64 = 1.08;
/// Pelvis ellipsoid: from this fraction of `torso_length` below the hip centre (the
/// crotch) up to this fraction above it.
const PELVIS_BOTTOM: f64 = 0.22;
const PELVIS_TOP: f64 = 0.46;
/// Neck ellipsoid: from this fraction of `neck_length` below the neck base (into the
/// shoulders) up to the centre of the head ellipsoid.
const NECK_BOTTOM: f64 = 0.5;
/// The head ellipsoid's centre sits this fraction of `head_radius_y` below the Head
/// joint (the rig's head-bone midpoint is 7.7 cm under the crown at 1.75 m, less than
/// the head's half-height).
const HEAD_ELLIPSOID_DROP: f64 = 0.3;
/// Forward (−z) shift of the trunk and head ellipsoids from the joint line, as a
/// fraction of their front-back half-axis: the joints of the realistic body (spine,
/// head bone) sit toward the back of the trunk and head (without the shift, the model
/// surface of the shared synthetic sequences' front views sits 3–6 cm behind the real
/// chest, belly and face).
const TORSO_FORWARD: f64 = 0.3;
const PELVIS_FORWARD: f64 = 0.25;
const NECK_FORWARD: f64 = 0.2;
const HEAD_FORWARD: f64 = 0.5;
/// Same for the legs, as a fraction of the limb radius: the thigh's bulk lies in front
/// of the hip–knee line, the calf behind the knee–ankle line.
const THIGH_FORWARD: f64 = 0.25;
const SHIN_FORWARD: f64 = -0.35;
/// Hand thickness relative to its breadth; foot height relative to ankle height.
const HAND_THICKNESS: f64 = 0.5;
const FOOT_HEIGHT: f64 = 0.55;
/// Share of the foot length behind the ankle (the heel).
const HEEL_SHARE: f64 = 0.22;

impl BodyShape {
    /// The ellipsoid of each segment, in that segment's frame (see [`kinematics`] for
    /// the frames).
    pub fn ellipsoids(&self) -> [SegmentEllipsoid; NUM_SEGMENTS] {
        let e = |c: [f64; 3], r: [f64; 3]| SegmentEllipsoid {
            centre: Vector3::from(c),
            radii: Vector3::from(r),
        };
        let limb = |len: f64, r: f64, forward: f64| {
            e(
                [0.0, 0.5 * len, -forward * r],
                [r, (0.5 + LIMB_OVERHANG) * len, r],
            )
        };
        let l = self.torso_length;
        // Torso frame origin: mid-spine, spine_offset above the hip centre.
        let torso_lo = -TORSO_BOTTOM * l + self.spine_offset;
        let torso_hi = -TORSO_TOP * l + self.spine_offset;
        let torso = e(
            [
                0.0,
                0.5 * (torso_lo + torso_hi),
                -TORSO_FORWARD * self.chest_radius_z,
            ],
            [
                self.chest_radius_x,
                0.5 * (torso_lo - torso_hi),
                self.chest_radius_z,
            ],
        );
        let pelvis = e(
            [
                0.0,
                0.5 * (PELVIS_BOTTOM - PELVIS_TOP) * l,
                -PELVIS_FORWARD * self.pelvis_radius_z,
            ],
            [
                self.pelvis_radius_x,
                0.5 * (PELVIS_BOTTOM + PELVIS_TOP) * l,
                self.pelvis_radius_z,
            ],
        );
        // Neck frame origin: base of the neck.
        let neck_lo = NECK_BOTTOM * self.neck_length;
        let neck_hi = -(self.head_offset - HEAD_ELLIPSOID_DROP * self.head_radius_y);
        let neck = e(
            [
                0.0,
                0.5 * (neck_lo + neck_hi),
                -NECK_FORWARD * self.neck_radius,
            ],
            [
                self.neck_radius,
                0.5 * (neck_lo - neck_hi),
                self.neck_radius,
            ],
        );
        let head = e(
            [
                0.0,
                HEAD_ELLIPSOID_DROP * self.head_radius_y,
                -HEAD_FORWARD * self.head_radius_z,
            ],
            [self.head_radius_x, self.head_radius_y, self.head_radius_z],
        );
        let hand = e(
            [0.0, 0.5 * self.hand_length, 0.0],
            [
                self.hand_radius,
                0.5 * self.hand_length,
                HAND_THICKNESS * self.hand_radius,
            ],
        );
        let foot_h = FOOT_HEIGHT * self.ankle_height;
        let foot = e(
            [
                0.0,
                self.ankle_height - foot_h,
                -(0.5 - HEEL_SHARE) * self.foot_length,
            ],
            [self.foot_radius, foot_h, 0.5 * self.foot_length],
        );
        let upper_arm = limb(self.upper_arm_length, self.upper_arm_radius, 0.0);
        let forearm = limb(self.forearm_length, self.forearm_radius, 0.0);
        let thigh = limb(self.thigh_length, self.thigh_radius, THIGH_FORWARD);
        let shin = limb(self.shin_length, self.shin_radius, SHIN_FORWARD);
        [
            head, neck, torso, pelvis, upper_arm, forearm, hand, upper_arm, forearm, hand, thigh,
            shin, foot, thigh, shin, foot,
        ]
    }
}

/// The body model: a shape plus the fixed skeleton topology.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BodyModel {
    pub shape: BodyShape,
}

impl BodyModel {
    /// The model of a subject `height` metres tall.
    pub fn new(height: f64) -> Result<Self> {
        Ok(BodyModel {
            shape: BodyShape::from_height(height)?,
        })
    }

    /// A model with an explicit shape.
    pub fn with_shape(shape: BodyShape) -> Self {
        BodyModel { shape }
    }

    /// A model whose shape is this one's scaled by shape `factors` (see
    /// [`BodyShape::scaled`]).
    pub fn with_shape_factors(&self, factors: &[f64]) -> Result<Self> {
        Ok(BodyModel {
            shape: self.shape.scaled(factors)?,
        })
    }

    /// Pose parameter names.
    pub fn param_names() -> &'static [&'static str; NUM_PARAMS] {
        &PARAM_NAMES
    }

    /// Lower bounds of the pose parameters (−inf for the free root).
    pub fn lower_bounds() -> Pose {
        let mut b = [f64::NEG_INFINITY; NUM_PARAMS];
        for (o, l) in b[6..].iter_mut().zip(JOINT_LIMITS) {
            *o = l.0;
        }
        b
    }

    /// Upper bounds of the pose parameters (+inf for the free root).
    pub fn upper_bounds() -> Pose {
        let mut b = [f64::INFINITY; NUM_PARAMS];
        for (o, l) in b[6..].iter_mut().zip(JOINT_LIMITS) {
            *o = l.1;
        }
        b
    }

    /// Upright, facing the camera, arms down, hip centre 3 m in front of the camera.
    pub fn neutral_pose() -> Pose {
        let mut p = [0.0; NUM_PARAMS];
        p[param::ROOT_T + 2] = NEUTRAL_DISTANCE;
        p[param::R_SHOULDER + 1] = NEUTRAL_ARM_ABDUCTION;
        p[param::L_SHOULDER + 1] = NEUTRAL_ARM_ABDUCTION;
        p[param::R_ELBOW] = NEUTRAL_ELBOW_FLEXION;
        p[param::L_ELBOW] = NEUTRAL_ELBOW_FLEXION;
        p
    }

    /// `pose` with every joint angle clamped into the limits.
    pub fn clamp_pose(pose: &Pose) -> Pose {
        let (lo, hi) = (Self::lower_bounds(), Self::upper_bounds());
        let mut p = *pose;
        for i in 0..NUM_PARAMS {
            p[i] = p[i].clamp(lo[i], hi[i]);
        }
        p
    }
}

/// Checks a pose slice: 22 finite values.
pub fn pose_from_slice(values: &[f64], name: &str) -> Result<Pose> {
    if values.len() != NUM_PARAMS {
        return Err(Error::invalid(
            name,
            format!("a pose has {NUM_PARAMS} parameters, got {}", values.len()),
        ));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            name,
            format!("{} is not finite ({})", PARAM_NAMES[i], values[i]),
        ));
    }
    let mut p = [0.0; NUM_PARAMS];
    p.copy_from_slice(values);
    Ok(p)
}

/// The root rotation (body → camera) of a pose.
pub fn root_rotation(pose: &Pose) -> Rotation3<f64> {
    Rotation3::from_scaled_axis(Vector3::new(
        pose[param::ROOT_R],
        pose[param::ROOT_R + 1],
        pose[param::ROOT_R + 2],
    ))
}

/// `pose` with its root rotation R replaced by R · exp(\[omega\]×) (a body-frame
/// increment, the meaning of the Jacobian's columns 3..6) and written back as a
/// rotation vector.
pub fn pose_with_root_increment(pose: &Pose, omega: &Vector3<f64>) -> Pose {
    let r = root_rotation(pose) * Rotation3::from_scaled_axis(*omega);
    let v = rotation::rotation_vector(&r);
    let mut p = *pose;
    p[param::ROOT_R..param::ROOT_R + 3].copy_from_slice(v.as_slice());
    p
}
