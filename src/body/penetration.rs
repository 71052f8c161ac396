//! How deep a pose's arms pass into its trunk.
//!
//! The body's ellipsoids may overlap where real bodies touch (an arm resting against
//! the side, a hand on the belly), but an arm whose axis runs through the torso is a
//! pose no body takes. Such an arm is hidden inside the trunk in every view, so it
//! contradicts no observed pixel: a reading that hides a limb there competes on
//! equal terms with one that puts it where the depth shows it, and wins on its smaller
//! rest-pose penalty. The measure below lets poses that compete be charged for it.

use super::kinematics::Kinematics;
use super::{seg, BodyModel, Pose};
use nalgebra::Vector3;

/// Each arm's upper arm, forearm and hand segments (right, left): their frames' origins
/// are the shoulder, the elbow and the wrist.
const ARMS: [[usize; 3]; 2] = [
    [seg::R_UPPER_ARM, seg::R_FOREARM, seg::R_HAND],
    [seg::L_UPPER_ARM, seg::L_FOREARM, seg::L_HAND],
];
/// The trunk's segments: torso and pelvis.
const TRUNK: [usize; 2] = [seg::TORSO, seg::PELVIS];

impl BodyModel {
    /// Σ over both arms' axis points (mid upper arm and elbow, on the upper arm; mid
    /// forearm and wrist, on the forearm) of how far each lies inside the torso or
    /// pelvis ellipsoid beyond its own segment's smallest radius (metres, the deeper
    /// of the two; 0 when it is nearer the surface). An arm lying against the trunk has
    /// its axis about one radius outside; allowing as much inside takes in soft
    /// contact and the ellipsoids' departure from a real body, but not an arm through
    /// the trunk.
    pub fn arm_trunk_penetration(&self, pose: &Pose) -> f64 {
        let kin = Kinematics::new(self, pose);
        let placed = self.placed_ellipsoids(&kin);
        let origin = |k: usize| kin.frames[k].translation.vector;
        let radius = |k: usize| placed[k].prepared.radii().min();
        let mut total = 0.0;
        for [upper, fore, hand] in ARMS {
            let (s, e, w) = (origin(upper), origin(fore), origin(hand));
            let points: [(Vector3<f64>, f64); 4] = [
                ((s + e) * 0.5, radius(upper)),
                (e, radius(upper)),
                ((e + w) * 0.5, radius(fore)),
                (w, radius(fore)),
            ];
            for (p, r) in &points {
                let inside = TRUNK
                    .iter()
                    .map(|&k| -placed[k].signed_distance(p))
                    .fold(f64::MIN, f64::max);
                total += (inside - r).max(0.0);
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::param;

    #[test]
    fn hanging_and_raised_arms_do_not_penetrate() {
        let model = BodyModel::default();
        let mut pose = BodyModel::neutral_pose();
        pose[2] = 3.0;
        assert_eq!(model.arm_trunk_penetration(&pose), 0.0);
        pose[param::R_SHOULDER] = 2.9;
        pose[param::L_SHOULDER + 1] = 1.45;
        assert_eq!(model.arm_trunk_penetration(&pose), 0.0);
    }

    #[test]
    fn an_arm_swung_into_the_trunk_penetrates_by_its_depth_inside() {
        let model = BodyModel::default();
        let mut pose = BodyModel::neutral_pose();
        pose[2] = 3.0;
        // The left arm swung across the body (abduction −0.45): it runs through the trunk.
        pose[param::L_SHOULDER + 1] = -0.45;
        pose[param::L_ELBOW] = 0.0;
        let inside = model.arm_trunk_penetration(&pose);
        assert!(inside > 0.03, "penetration {inside}");
        // Brute force: the same sum from the ITOP joints (shoulder, elbow, wrist) and the
        // signed distances to the torso and pelvis ellipsoids.
        let kin = Kinematics::new(&model, &pose);
        let placed = model.placed_ellipsoids(&kin);
        let j = model.joints(&pose);
        let mut want = 0.0;
        for ([a, b, c], [upper, fore]) in [
            ([2, 4, 6], [seg::R_UPPER_ARM, seg::R_FOREARM]),
            ([3, 5, 7], [seg::L_UPPER_ARM, seg::L_FOREARM]),
        ] {
            let ru = placed[upper].prepared.radii().min();
            let rf = placed[fore].prepared.radii().min();
            for (p, r) in [
                ((j[a] + j[b]) * 0.5, ru),
                (j[b], ru),
                ((j[b] + j[c]) * 0.5, rf),
                (j[c], rf),
            ] {
                let d = placed[seg::TORSO]
                    .signed_distance(&p)
                    .min(placed[seg::PELVIS].signed_distance(&p));
                want += (-d - r).max(0.0);
            }
        }
        assert!((inside - want).abs() < 1e-12);
    }
}
