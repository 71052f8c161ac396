//! Forward kinematics, output joints and their Jacobian.
//!
//! Segment frames (all parallel to the body frame at zero joint angles; y down):
//! - pelvis = body frame (origin hip centre); torso: origin mid-spine,
//!   `spine_offset` above the hip centre;
//! - neck: origin at the base of the neck, `torso_length + neck_length` above the hip
//!   centre, rotated by the neck joint; head: origin at the head centre, `head_offset`
//!   above the neck base in the neck frame;
//! - upper arm: origin at the shoulder (±shoulder_width/2 in x, right = −x,
//!   `torso_length` up), rotated by the shoulder; forearm: origin at the elbow,
//!   `upper_arm_length` along the upper arm's +y, rotated by the elbow; hand: origin at
//!   the wrist, `forearm_length` along the forearm's +y;
//! - thigh: origin at the hip joint (±hip_width/2 in x), rotated by the hip; shin:
//!   origin at the knee, rotated by the knee; foot: origin at the ankle.

use super::{
    param, root_rotation, seg, BodyModel, Pose, JOINT_SEGMENT, NUM_JOINTS, NUM_PARAMS, NUM_SEGMENTS,
};
use nalgebra::{Isometry3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};

/// Which side a limb is on: the subject's right is at body −x.
#[derive(Clone, Copy)]
enum Side {
    Right,
    Left,
}

impl Side {
    /// Sign of body x on this side.
    fn sign(self) -> f64 {
        match self {
            Side::Right => -1.0,
            Side::Left => 1.0,
        }
    }
}

/// Local joint axes (body-frame directions at zero angles), chosen so a positive angle
/// is the same anatomical motion on both sides (see the module docs of [`super`]).
const NECK_FLEXION_AXIS: [f64; 3] = [1.0, 0.0, 0.0];
const NECK_LATERAL_AXIS: [f64; 3] = [0.0, 0.0, 1.0];
const LIMB_FLEXION_AXIS: [f64; 3] = [-1.0, 0.0, 0.0];
const KNEE_FLEXION_AXIS: [f64; 3] = [1.0, 0.0, 0.0];

fn abduction_axis(side: Side) -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -side.sign())
}

fn internal_rotation_axis(side: Side) -> Vector3<f64> {
    Vector3::new(0.0, side.sign(), 0.0)
}

/// The frames and degrees of freedom of one pose: everything the distances, the
/// Jacobians and the renderer need.
#[derive(Debug, Clone)]
pub struct Kinematics {
    /// Segment frame → camera.
    pub frames: [Isometry3<f64>; NUM_SEGMENTS],
    /// Per parameter: for the root translation the unit direction of motion, for every
    /// rotation the unit axis in the camera frame (for the root rotation: the body-frame
    /// increment axes R·e_i).
    pub dof_axis: [Vector3<f64>; NUM_PARAMS],
    /// Per rotation parameter: a point on its axis (the joint centre), camera frame.
    pub dof_pivot: [Vector3<f64>; NUM_PARAMS],
}

/// Bit masks of the parameters that move each segment.
pub const SEGMENT_DOFS: [u32; NUM_SEGMENTS] = segment_dofs();

const fn bits(from: usize, to: usize) -> u32 {
    let mut m = 0u32;
    let mut i = from;
    while i < to {
        m |= 1 << i;
        i += 1;
    }
    m
}

const fn segment_dofs() -> [u32; NUM_SEGMENTS] {
    let root = bits(0, 6);
    let neck = root | bits(param::NECK, param::NECK + 2);
    let r_sh = root | bits(param::R_SHOULDER, param::R_SHOULDER + 3);
    let r_el = r_sh | bits(param::R_ELBOW, param::R_ELBOW + 1);
    let l_sh = root | bits(param::L_SHOULDER, param::L_SHOULDER + 3);
    let l_el = l_sh | bits(param::L_ELBOW, param::L_ELBOW + 1);
    let r_hip = root | bits(param::R_HIP, param::R_HIP + 2);
    let r_kn = r_hip | bits(param::R_KNEE, param::R_KNEE + 1);
    let l_hip = root | bits(param::L_HIP, param::L_HIP + 2);
    let l_kn = l_hip | bits(param::L_KNEE, param::L_KNEE + 1);
    [
        neck, neck, root, root, r_sh, r_el, r_el, l_sh, l_el, l_el, r_hip, r_kn, r_kn, l_hip, l_kn,
        l_kn,
    ]
}

/// Segment frames only (the cheap part of [`Kinematics`]).
pub type PoseFrames = [Isometry3<f64>; NUM_SEGMENTS];

fn rot(axis: Vector3<f64>, angle: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Unit::new_unchecked(axis), angle)
}

fn trans(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity())
}

fn with_rotation(q: UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::identity(), q)
}

/// Records a rotation degree of freedom: its camera-frame axis and pivot.
fn record(k: &mut Kinematics, index: usize, frame: &Isometry3<f64>, local_axis: Vector3<f64>) {
    k.dof_axis[index] = frame.rotation * local_axis;
    k.dof_pivot[index] = frame.translation.vector;
}

impl Kinematics {
    /// Forward kinematics of `pose` (assumed finite; see [`super::pose_from_slice`]).
    pub fn new(model: &BodyModel, pose: &Pose) -> Self {
        let s = &model.shape;
        let mut k = Kinematics {
            frames: [Isometry3::identity(); NUM_SEGMENTS],
            dof_axis: [Vector3::zeros(); NUM_PARAMS],
            dof_pivot: [Vector3::zeros(); NUM_PARAMS],
        };
        let rr: Rotation3<f64> = root_rotation(pose);
        let t = Vector3::new(pose[0], pose[1], pose[2]);
        let root = Isometry3::from_parts(
            Translation3::from(t),
            UnitQuaternion::from_rotation_matrix(&rr),
        );
        for i in 0..3 {
            k.dof_axis[param::ROOT_T + i] = Vector3::ith(i, 1.0);
            k.dof_axis[param::ROOT_R + i] = rr * Vector3::ith(i, 1.0);
            k.dof_pivot[param::ROOT_R + i] = t;
        }
        k.frames[seg::PELVIS] = root;
        k.frames[seg::TORSO] = root * trans(0.0, -s.spine_offset, 0.0);

        // Neck (flexion then lateral bend) carrying the head.
        let neck_base = root * trans(0.0, -(s.torso_length + s.neck_length), 0.0);
        let a_flex = Vector3::from(NECK_FLEXION_AXIS);
        let a_lat = Vector3::from(NECK_LATERAL_AXIS);
        record(&mut k, param::NECK, &neck_base, a_flex);
        let after_flex = neck_base * with_rotation(rot(a_flex, pose[param::NECK]));
        record(&mut k, param::NECK + 1, &after_flex, a_lat);
        let neck = after_flex * with_rotation(rot(a_lat, pose[param::NECK + 1]));
        k.frames[seg::NECK] = neck;
        k.frames[seg::HEAD] = neck * trans(0.0, -s.head_offset, 0.0);

        for side in [Side::Right, Side::Left] {
            let (sh_p, el_p, segs) = match side {
                Side::Right => (
                    param::R_SHOULDER,
                    param::R_ELBOW,
                    [seg::R_UPPER_ARM, seg::R_FOREARM, seg::R_HAND],
                ),
                Side::Left => (
                    param::L_SHOULDER,
                    param::L_ELBOW,
                    [seg::L_UPPER_ARM, seg::L_FOREARM, seg::L_HAND],
                ),
            };
            let shoulder = root * trans(side.sign() * 0.5 * s.shoulder_width, -s.torso_length, 0.0);
            let axes = [
                Vector3::from(LIMB_FLEXION_AXIS),
                abduction_axis(side),
                internal_rotation_axis(side),
            ];
            let mut f = shoulder;
            for (j, a) in axes.iter().enumerate() {
                record(&mut k, sh_p + j, &f, *a);
                f *= with_rotation(rot(*a, pose[sh_p + j]));
            }
            k.frames[segs[0]] = f;
            let elbow = f * trans(0.0, s.upper_arm_length, 0.0);
            let a_el = Vector3::from(LIMB_FLEXION_AXIS);
            record(&mut k, el_p, &elbow, a_el);
            let forearm = elbow * with_rotation(rot(a_el, pose[el_p]));
            k.frames[segs[1]] = forearm;
            k.frames[segs[2]] = forearm * trans(0.0, s.forearm_length, 0.0);
        }

        for side in [Side::Right, Side::Left] {
            let (hip_p, kn_p, segs) = match side {
                Side::Right => (
                    param::R_HIP,
                    param::R_KNEE,
                    [seg::R_THIGH, seg::R_SHIN, seg::R_FOOT],
                ),
                Side::Left => (
                    param::L_HIP,
                    param::L_KNEE,
                    [seg::L_THIGH, seg::L_SHIN, seg::L_FOOT],
                ),
            };
            let hip = root * trans(side.sign() * 0.5 * s.hip_width, 0.0, 0.0);
            let axes = [Vector3::from(LIMB_FLEXION_AXIS), abduction_axis(side)];
            let mut f = hip;
            for (j, a) in axes.iter().enumerate() {
                record(&mut k, hip_p + j, &f, *a);
                f *= with_rotation(rot(*a, pose[hip_p + j]));
            }
            k.frames[segs[0]] = f;
            let knee = f * trans(0.0, s.thigh_length, 0.0);
            let a_kn = Vector3::from(KNEE_FLEXION_AXIS);
            record(&mut k, kn_p, &knee, a_kn);
            let shin = knee * with_rotation(rot(a_kn, pose[kn_p]));
            k.frames[segs[1]] = shin;
            k.frames[segs[2]] = shin * trans(0.0, s.shin_length, 0.0);
        }
        k
    }

    /// The 15 output joints (ITOP order), camera frame.
    pub fn joints(&self) -> [Vector3<f64>; NUM_JOINTS] {
        std::array::from_fn(|j| self.frames[JOINT_SEGMENT[j]].translation.vector)
    }

    /// Velocity of a point `p` rigidly attached to a segment moved by parameter `dof`
    /// (the Jacobian column of the point for that parameter).
    #[inline]
    pub fn point_velocity(&self, dof: usize, p: &Vector3<f64>) -> Vector3<f64> {
        if dof < param::ROOT_R {
            self.dof_axis[dof]
        } else {
            self.dof_axis[dof].cross(&(p - self.dof_pivot[dof]))
        }
    }

    /// d(joints)/d(pose) into `out`: (15·3)×22 row-major, row 3·j + c. Root rotation
    /// columns are with respect to the body-frame increment ω (see [`super`]).
    pub fn joints_jacobian(&self, out: &mut [f64; NUM_JOINTS * 3 * NUM_PARAMS]) {
        out.fill(0.0);
        let joints = self.joints();
        for (j, p) in joints.iter().enumerate() {
            let mask = SEGMENT_DOFS[JOINT_SEGMENT[j]];
            for dof in 0..NUM_PARAMS {
                if mask & (1 << dof) == 0 {
                    continue;
                }
                // A joint is the origin of its segment, which its own joint's rotation
                // does not move (p = pivot gives zero), so the mask can include it.
                let v = self.point_velocity(dof, p);
                for c in 0..3 {
                    out[(3 * j + c) * NUM_PARAMS + dof] = v[c];
                }
            }
        }
    }
}

impl BodyModel {
    /// Forward kinematics: every segment frame → camera.
    pub fn segment_transforms(&self, pose: &Pose) -> PoseFrames {
        Kinematics::new(self, pose).frames
    }

    /// The 15 output joints (ITOP order) in the camera frame.
    pub fn joints(&self, pose: &Pose) -> [Vector3<f64>; NUM_JOINTS] {
        Kinematics::new(self, pose).joints()
    }

    /// Jacobian of the joints, (15·3)×22 row-major (see [`Kinematics::joints_jacobian`]).
    pub fn joints_jacobian(&self, pose: &Pose, out: &mut [f64; NUM_JOINTS * 3 * NUM_PARAMS]) {
        Kinematics::new(self, pose).joints_jacobian(out);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::super::*;
    use super::*;

    fn random_pose(seed: u64) -> Pose {
        // Small deterministic generator: tests need no external randomness.
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64) / ((1u64 << 53) as f64)
        };
        let (lo, hi) = (BodyModel::lower_bounds(), BodyModel::upper_bounds());
        let mut p = [0.0; NUM_PARAMS];
        for i in 0..NUM_PARAMS {
            p[i] = if i < 3 {
                [0.3, -0.2, 3.0][i] + 0.2 * (next() - 0.5)
            } else if i < 6 {
                2.0 * (next() - 0.5)
            } else {
                lo[i] + (hi[i] - lo[i]) * next()
            };
        }
        p
    }

    pub(crate) fn pose_for_tests(seed: u64) -> Pose {
        random_pose(seed)
    }

    #[test]
    fn neutral_pose_proportions() {
        let m = BodyModel::new(1.75).unwrap();
        let p = BodyModel::neutral_pose();
        let j = m.joints(&p);
        let name = |n: &str| j[JOINT_NAMES.iter().position(|x| *x == n).unwrap()];
        let hipc = (name("RHip") + name("LHip")) / 2.0;
        assert!((hipc - Vector3::new(0.0, 0.0, 3.0)).norm() < 1e-12);
        // Right side at image left (camera −x), head up (camera −y).
        assert!(name("RShoulder").x < 0.0 && name("LShoulder").x > 0.0);
        assert!(name("RHip").x < 0.0 && name("RHand").x < 0.0 && name("RFoot").x < 0.0);
        assert!(name("Head").y < name("Neck").y && name("Neck").y < name("Torso").y);
        assert!(((name("LShoulder") - name("RShoulder")).norm() - 0.352).abs() < 1e-12);
        assert!(((name("LHip") - name("RHip")).norm() - 0.232).abs() < 1e-12);
        assert!(((name("RElbow") - name("RShoulder")).norm() - 0.239).abs() < 1e-12);
        assert!(((name("RHand") - name("RElbow")).norm() - 0.238).abs() < 1e-12);
        assert!(((name("RKnee") - name("RHip")).norm() - 0.443).abs() < 1e-12);
        assert!(((name("RFoot") - name("RKnee")).norm() - 0.401).abs() < 1e-12);
        // Standing: the feet are 0.844 m below the hips, shoulders 0.505 m above.
        assert!((name("RFoot").y - 0.844).abs() < 1e-12);
        assert!((name("RShoulder").y + 0.505).abs() < 1e-12);
        assert!((name("Neck").y + 0.573).abs() < 1e-12);
        // Floor to head top ≈ the height.
        assert!((m.shape.standing_height() - 1.75).abs() < 0.03);
        // Mirror symmetry of the neutral pose.
        for (r, l) in [
            ("RShoulder", "LShoulder"),
            ("RHand", "LHand"),
            ("RFoot", "LFoot"),
        ] {
            let (a, b) = (name(r), name(l));
            assert!((a.x + b.x).abs() < 1e-12 && (a.y - b.y).abs() < 1e-12);
            assert!((a.z - b.z).abs() < 1e-12);
        }
    }

    #[test]
    fn scales_with_height() {
        let a = BodyModel::new(1.75).unwrap();
        let b = BodyModel::new(1.4).unwrap();
        let mut p = BodyModel::neutral_pose();
        p[2] = 0.0;
        let (ja, jb) = (a.joints(&p), b.joints(&p));
        for j in 0..NUM_JOINTS {
            assert!((ja[j] * 0.8 - jb[j]).norm() < 1e-12);
        }
        assert!(BodyModel::new(0.1).is_err() && BodyModel::new(f64::NAN).is_err());
    }

    #[test]
    fn positive_angles_mean_the_same_motion_on_both_sides() {
        let m = BodyModel::default();
        let base = BodyModel::neutral_pose();
        let j0 = m.joints(&base);
        let moved = |i: usize, v: f64| {
            let mut p = base;
            p[i] = v;
            m.joints(&p)
        };
        // Shoulder flexion: hands go forward (toward the camera, −z).
        let j = moved(param::R_SHOULDER, 1.2);
        assert!(j[6].z < j0[6].z - 0.2);
        let j = moved(param::L_SHOULDER, 1.2);
        assert!(j[7].z < j0[7].z - 0.2);
        // Abduction: arms go outward.
        let j = moved(param::R_SHOULDER + 1, 1.2);
        assert!(j[6].x < j0[6].x - 0.2);
        let j = moved(param::L_SHOULDER + 1, 1.2);
        assert!(j[7].x > j0[7].x + 0.2);
        // Elbow flexion: hand forward. Knee flexion: foot backward (+z).
        let j = moved(param::R_ELBOW, 1.5);
        assert!(j[6].z < j0[6].z - 0.15);
        let j = moved(param::L_KNEE, 1.5);
        assert!(j[14].z > j0[14].z + 0.2);
        // Hip flexion forward, abduction outward.
        let j = moved(param::R_HIP, 1.0);
        assert!(j[11].z < j0[11].z - 0.2);
        let j = moved(param::L_HIP + 1, 0.8);
        assert!(j[12].x > j0[12].x + 0.2);
        let j = moved(param::R_HIP + 1, 0.8);
        assert!(j[11].x < j0[11].x - 0.2);
        // Neck flexion: head forward and down.
        let j = moved(param::NECK, 0.8);
        assert!(j[0].z < j0[0].z - 0.05 && j[0].y > j0[0].y);
        // Internal rotation with a bent elbow brings the hand toward the midline.
        let mut p = base;
        p[param::R_ELBOW] = 1.5;
        p[param::L_ELBOW] = 1.5;
        let bent = m.joints(&p);
        p[param::R_SHOULDER + 2] = 0.8;
        p[param::L_SHOULDER + 2] = 0.8;
        let rotated = m.joints(&p);
        assert!(rotated[6].x > bent[6].x + 0.05 && rotated[7].x < bent[7].x - 0.05);
    }

    #[test]
    fn limits_are_ordered_and_neutral_inside() {
        let (lo, hi) = (BodyModel::lower_bounds(), BodyModel::upper_bounds());
        let n = BodyModel::neutral_pose();
        for i in 0..NUM_PARAMS {
            assert!(lo[i] < hi[i]);
            assert!(lo[i] <= n[i] && n[i] <= hi[i]);
            if i < 6 {
                assert!(lo[i].is_infinite() && hi[i].is_infinite());
            }
        }
        let mut wild = n;
        wild[param::R_ELBOW] = -1.0;
        wild[param::L_KNEE] = 9.0;
        let c = BodyModel::clamp_pose(&wild);
        assert_eq!(c[param::R_ELBOW], 0.0);
        assert_eq!(c[param::L_KNEE], hi[param::L_KNEE]);
    }

    #[test]
    fn joints_jacobian_matches_finite_differences() {
        let m = BodyModel::default();
        for seed in 0..5 {
            let p = random_pose(seed);
            let mut jac = [0.0; NUM_JOINTS * 3 * NUM_PARAMS];
            m.joints_jacobian(&p, &mut jac);
            let h = 1e-6;
            for dof in 0..NUM_PARAMS {
                let (plus, minus) = if (3..6).contains(&dof) {
                    let mut w = Vector3::zeros();
                    w[dof - 3] = h;
                    (
                        pose_with_root_increment(&p, &w),
                        pose_with_root_increment(&p, &-w),
                    )
                } else {
                    let (mut a, mut b) = (p, p);
                    a[dof] += h;
                    b[dof] -= h;
                    (a, b)
                };
                let (ja, jb) = (m.joints(&plus), m.joints(&minus));
                for j in 0..NUM_JOINTS {
                    let fd = (ja[j] - jb[j]) / (2.0 * h);
                    for c in 0..3 {
                        let an = jac[(3 * j + c) * NUM_PARAMS + dof];
                        assert!(
                            (an - fd[c]).abs() < 1e-6 * (1.0 + fd[c].abs()),
                            "joint {j} coord {c} dof {dof}: {an} vs {}",
                            fd[c]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn root_increment_composes_on_the_right() {
        let p = random_pose(3);
        let w = Vector3::new(0.1, -0.2, 0.05);
        let q = pose_with_root_increment(&p, &w);
        let expect = root_rotation(&p) * Rotation3::from_scaled_axis(w);
        assert!((root_rotation(&q).matrix() - expect.matrix()).norm() < 1e-12);
    }
}
