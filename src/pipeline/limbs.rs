//! Limb hypotheses: each limb of a fit tried in the poses people take.
//!
//! The template catalogue combines four poses per limb, so a fit found from it can miss
//! a limb whose pose is not among them (an arm overhead, a kick, a leg out sideways)
//! and the EM, being local, rarely moves the limb that far. Here each limb of the fit
//! is set in turn to each pose of a wider set, the rest of the body kept, and the limb
//! pose whose body explains the observed depth best (depth discrepancy plus rest-pose
//! penalty, as everywhere poses compete) is kept when it beats the limb as fitted. A
//! body changed so is refitted, and the refit replaces the fit only when it explains
//! the depth better. Rendering a pose costs far less than fitting one, so the whole
//! set is scored and only a few short EMs run: from the body with every limb's best
//! pose, and from the best-ranked other poses scored (see [`REFITTED_STARTS`]).

use super::estimator::{Estimator, Frame};
use crate::body::{param, seg, Pose, NUM_SEGMENTS};
use crate::error::Result;
use crate::fit::FitResult;

/// Shoulder flexion, abduction, rotation and elbow flexion of the arm poses tried.
pub const ARM_POSES: [[f64; 4]; 11] = [
    [0.0, 0.12, 0.0, 0.1],  // hanging
    [0.0, 1.45, 0.0, 0.1],  // out sideways
    [1.45, 0.1, 0.0, 0.1],  // forward, pointing
    [0.8, 0.1, 0.0, 0.1],   // forward and down
    [0.25, 0.35, 0.0, 1.7], // forearm forward and up
    [2.9, 0.2, 0.0, 0.1],   // overhead
    [0.3, 2.4, 0.0, 0.1],   // raised in a V
    [-0.7, 0.1, 0.0, 0.2],  // back
    [0.9, 0.3, 0.0, 2.3],   // guard, fist by the face
    [1.4, -0.5, 0.0, 0.3],  // across the body
    [0.0, 1.45, 0.0, 1.6],  // out sideways, forearm bent
];

/// Hip flexion, abduction and knee flexion of the leg poses tried.
pub const LEG_POSES: [[f64; 3]; 10] = [
    [0.0, 0.04, 0.0],   // standing
    [0.45, 0.04, 0.15], // step forward
    [-0.35, 0.04, 0.4], // step back
    [1.4, 0.04, 1.6],   // knee raised
    [1.5, 0.04, 0.1],   // kick forward
    [2.1, 0.04, 0.05],  // high kick
    [0.1, 1.2, 0.1],    // out sideways
    [-0.6, 0.04, 0.2],  // kick back
    [0.0, 0.04, 1.6],   // heel raised behind
    [1.8, 0.2, 2.4],    // crouched
];

/// How many starts the limb poses refit: the body with every limb's best pose, and the
/// best-ranked other bodies scored. A start ranks before its fit, and the start that
/// ranks best is not always the one that fits best: an arm hidden behind the body
/// saves its rest-pose penalty and contradicts no pixel, where the arm's true pose,
/// set from a list, lies a little off the observed arm until the EM moves it there.
pub const REFITTED_STARTS: usize = 3;

/// The limbs: first angle of each in the pose, and whether it is an arm. Opposite
/// limbs are neighbours (right, then left), so limb `k`'s opposite is `k ^ 1`.
pub(crate) const LIMBS: [(usize, bool); 4] = [
    (param::R_SHOULDER, true),
    (param::L_SHOULDER, true),
    (param::R_HIP, false),
    (param::L_HIP, false),
];

/// The body segments of each limb of [`LIMBS`], in its order: the limb's root segment
/// (upper arm, thigh), then its end (forearm and hand, shin and foot).
pub(crate) const LIMB_SEGMENTS: [[usize; 3]; 4] = [
    [seg::R_UPPER_ARM, seg::R_FOREARM, seg::R_HAND],
    [seg::L_UPPER_ARM, seg::L_FOREARM, seg::L_HAND],
    [seg::R_THIGH, seg::R_SHIN, seg::R_FOOT],
    [seg::L_THIGH, seg::L_SHIN, seg::L_FOOT],
];

/// The limbs of [`LIMBS`] whose end (forearm and hand, shin and foot) explains no point
/// of a fit with `part_counts` (the points labelled with each segment): the depth holds
/// nothing of where they are, so their angles are the start's and the rest-pose
/// penalty's.
pub(crate) fn unseen_limbs(part_counts: &[usize; NUM_SEGMENTS]) -> Vec<usize> {
    (0..LIMBS.len())
        .filter(|&k| LIMB_SEGMENTS[k][1..].iter().all(|&s| part_counts[s] == 0))
        .collect()
}

/// `pose` with the limb whose angles start at `first` set to `angles`.
fn with_limb(pose: &Pose, first: usize, angles: &[f64]) -> Pose {
    let mut out = *pose;
    out[first..first + angles.len()].copy_from_slice(angles);
    out
}

/// The pose of `pose` with limb `k` of [`LIMBS`] set to the angles of the opposite
/// limb: its mirror image (the joint angles of both sides share one convention).
fn mirrored_limb(pose: &Pose, k: usize) -> Pose {
    let (first, arm) = LIMBS[k];
    let (other, _) = LIMBS[k ^ 1];
    let n = if arm {
        ARM_POSES[0].len()
    } else {
        LEG_POSES[0].len()
    };
    let mut out = *pose;
    out[first..first + n].copy_from_slice(&pose[other..other + n]);
    out
}

/// Which limbs are re-posed, from which poses, and by how much the refit must win.
pub(crate) struct LimbSearch<'a> {
    /// Indices into [`LIMBS`].
    pub limbs: &'a [usize],
    /// Also try each limb in the opposite limb's pose (its mirror image).
    pub mirrored: bool,
    /// The refit replaces the fit when it ranks lower by this share.
    pub margin: f64,
}

/// The poses [`best_limbs`] found.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LimbStarts {
    /// The pose with each limb at its best-ranked pose.
    pub pose: Pose,
    /// Its rank.
    pub rank: f64,
    /// Whether any limb changed.
    pub changed: bool,
    /// Every other pose scored that ranked below the pose it started from, best first,
    /// with its rank.
    pub others: Vec<(f64, Pose)>,
}

impl LimbStarts {
    /// The starts to refit: the pose, then the best-ranked others, `n` in all.
    pub fn starts(&self, n: usize) -> Vec<Pose> {
        std::iter::once(self.pose)
            .chain(self.others.iter().map(|&(_, p)| p))
            .take(n)
            .collect()
    }
}

/// `pose` with each of `search.limbs` set, one after the other, to the pose of the set
/// (and, when `search.mirrored`, to the opposite limb's pose) that ranks best by `rank`
/// when it ranks below the current one; and the other poses scored that ranked below
/// `current`.
pub(crate) fn best_limbs(
    pose: &Pose,
    current: f64,
    search: &LimbSearch,
    mut rank: impl FnMut(&[Pose]) -> Result<Vec<f64>>,
) -> Result<LimbStarts> {
    let (mut pose, mut best, mut changed) = (*pose, current, false);
    let mut scored: Vec<(f64, Pose)> = Vec::new();
    for &k in search.limbs {
        let (first, arm) = LIMBS[k];
        let mut starts: Vec<Pose> = if arm {
            ARM_POSES
                .iter()
                .map(|a| with_limb(&pose, first, a))
                .collect()
        } else {
            LEG_POSES
                .iter()
                .map(|a| with_limb(&pose, first, a))
                .collect()
        };
        if search.mirrored {
            starts.push(mirrored_limb(&pose, k));
        }
        let ranks = rank(&starts)?;
        for (start, r) in starts.into_iter().zip(ranks) {
            if r < current {
                scored.push((r, start));
            }
            if r < best {
                (pose, best, changed) = (start, r, true);
            }
        }
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut others: Vec<(f64, Pose)> = Vec::new();
    for (r, p) in scored {
        if p != pose && !others.iter().any(|(_, q)| *q == p) {
            others.push((r, p));
        }
    }
    Ok(LimbStarts {
        pose,
        rank: best,
        changed,
        others,
    })
}

impl Estimator {
    /// `fit` (with `score`, its depth discrepancy) with its limbs re-posed where that
    /// explains the depth better (see the module docs). Returns the fit kept and its
    /// discrepancy.
    pub(crate) fn repose_limbs(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
    ) -> Result<(FitResult, f64)> {
        if !self.config().limb_poses {
            return Ok((fit, score));
        }
        let search = LimbSearch {
            limbs: &[0, 1, 2, 3],
            mirrored: false,
            margin: 0.0,
        };
        let (fit, score, _) = self.repose(frame, fit, score, &search)?;
        Ok((fit, score))
    }

    /// `fit` (with `score`, its depth discrepancy) with the limbs of `search` set to
    /// their best-ranked poses ([`best_limbs`]) and refitted briefly (the rest of the
    /// body is fitted already), with the next best-ranked starts ([`REFITTED_STARTS`]
    /// in all); the best-ranked refit is kept when it ranks lower by `search.margin`.
    /// Returns the fit kept, its discrepancy and whether it changed.
    pub(crate) fn repose(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
        search: &LimbSearch,
    ) -> Result<(FitResult, f64, bool)> {
        let current = self.rank(score, &fit.pose);
        let found = best_limbs(&fit.pose, current, search, |poses| {
            Ok(self.rankings(&self.discrepancies(frame, poses)?, poses))
        })?;
        if !found.changed {
            return Ok((fit, score, false));
        }
        let config = self.config().short_refit();
        let refits = self.fits(frame, &config, &found.starts(REFITTED_STARTS), None, None)?;
        let (refit, refit_score, refit_rank) = self.best_ranked(frame, refits)?;
        if refit_rank < current * (1.0 - search.margin) {
            Ok((refit, refit_score, true))
        } else {
            Ok((fit, score, false))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyModel;
    use crate::camera::Camera;
    use crate::pipeline::tests::{
        estimator, mean_joint_error_of, rendered_person, room_posed, walking,
    };
    use crate::pipeline::PipelineConfig;

    #[test]
    fn a_kick_and_an_arm_overhead_are_found_from_scratch() {
        // Neither pose is in the template catalogue: a leg kicking forward at hip
        // height and an arm straight up, seen from the front at 3 m.
        let model = BodyModel::default();
        let mut pose = walking(&model, 0.0);
        pose = with_limb(&pose, param::R_HIP, &[1.5, 0.04, 0.1]);
        pose = with_limb(&pose, param::L_SHOULDER, &[2.9, 0.2, 0.0, 0.1]);
        let depth = room_posed(&model, &pose);
        let camera = Camera::itop();
        let on = estimator(&camera, PipelineConfig::default()).with_size_search(false);
        let off = estimator(
            &camera,
            PipelineConfig {
                limb_poses: false,
                ..PipelineConfig::default()
            },
        )
        .with_size_search(false);
        let (a, b) =
            crate::pool::on_worker(|| (on.estimate(&depth, None), off.estimate(&depth, None)));
        let (a, b) = (a.unwrap(), b.unwrap());
        let (ea, eb) = (
            mean_joint_error_of(&model, &a, &pose),
            mean_joint_error_of(&model, &b, &pose),
        );
        assert!(ea < 0.05 && ea <= eb, "with limb poses {ea}, without {eb}");
    }

    #[test]
    fn a_limb_is_unseen_when_its_end_explains_no_point() {
        let mut counts = [10; NUM_SEGMENTS];
        assert!(unseen_limbs(&counts).is_empty());
        // The right forearm and hand explain nothing; the left hand alone neither.
        counts[seg::R_FOREARM] = 0;
        counts[seg::R_HAND] = 0;
        counts[seg::L_HAND] = 0;
        assert_eq!(unseen_limbs(&counts), [0]);
        // Upper arms and thighs do not count: both legs' ends explain nothing.
        for s in [seg::R_SHIN, seg::R_FOOT, seg::L_SHIN, seg::L_FOOT] {
            counts[s] = 0;
        }
        counts[seg::R_UPPER_ARM] = 0;
        assert_eq!(unseen_limbs(&counts), [0, 2, 3]);
        assert_eq!(unseen_limbs(&[0; NUM_SEGMENTS]), [0, 1, 2, 3]);
    }

    #[test]
    fn limb_poses_are_within_the_joint_limits() {
        let p = BodyModel::neutral_pose();
        for (first, arm) in LIMBS {
            let n = if arm {
                ARM_POSES.len()
            } else {
                LEG_POSES.len()
            };
            for k in 0..n {
                let angles: &[f64] = if arm { &ARM_POSES[k] } else { &LEG_POSES[k] };
                let q = with_limb(&p, first, angles);
                assert_eq!(BodyModel::clamp_pose(&q), q, "limb at {first}, pose {k}");
            }
        }
    }

    #[test]
    fn each_limb_takes_the_best_ranked_pose_and_only_when_it_ranks_lower() {
        // A rank with its minimum at the right arm overhead and the left leg kicking.
        let target = with_limb(
            &with_limb(&BodyModel::neutral_pose(), param::R_SHOULDER, &ARM_POSES[5]),
            param::L_HIP,
            &LEG_POSES[4],
        );
        let dist = |p: &Pose| -> f64 { p.iter().zip(&target).map(|(a, b)| (a - b).abs()).sum() };
        let rank = |poses: &[Pose]| Ok(poses.iter().map(dist).collect());
        let start = BodyModel::neutral_pose();
        let all = LimbSearch {
            limbs: &[0, 1, 2, 3],
            mirrored: false,
            margin: 0.0,
        };
        let found = best_limbs(&start, dist(&start), &all, rank).unwrap();
        assert!(found.changed);
        assert_eq!(found.pose, target);
        assert!(found.rank.abs() < 1e-12);
        // The others: every other pose scored below the start's rank, best first, each
        // once, the best pose not among them.
        assert!(!found.others.is_empty());
        assert!(found.others.windows(2).all(|w| w[0].0 <= w[1].0));
        assert!(found
            .others
            .iter()
            .all(|(r, p)| *r < dist(&start) && *p != target));
        assert!(found.others.iter().all(|(r, p)| *r == dist(p)));
        let starts = found.starts(3);
        assert_eq!(starts[0], target);
        assert_eq!(starts[1..], [found.others[0].1, found.others[1].1]);
        // Nothing ranks below the target itself: it stays as it is.
        let same = best_limbs(&target, 0.0, &all, rank).unwrap();
        assert!(!same.changed);
        assert_eq!(same.pose, target);
        assert!(same.others.is_empty());
    }

    #[test]
    fn a_guard_arm_seen_from_behind_is_found_among_the_refitted_starts() {
        // Seen from behind and to the side (150°), the right arm in a guard (fist by the
        // face) shows the camera little. An arm hidden behind the body ranks
        // best before any fit (it saves the rest-pose penalty), but the guard, which
        // ranks next, fits better: only refitting more than the best start finds it.
        let model = BodyModel::default();
        let camera = Camera::itop();
        let mut pose = BodyModel::neutral_pose();
        pose[param::ROOT_R + 1] = 150f64.to_radians();
        pose = with_limb(&pose, param::R_SHOULDER, &ARM_POSES[8]);
        pose = with_limb(&pose, param::L_SHOULDER, &[0.4, 0.6, 0.0, 0.3]);
        pose = with_limb(&pose, param::R_HIP, &[0.1, 0.5, 0.1]);
        let (depth, mask) = rendered_person(&model, &pose, &camera);
        let est = estimator(&camera, PipelineConfig::default()).with_size_search(false);
        let res = crate::pool::on_worker(|| est.estimate(&depth, Some(&mask))).unwrap();
        let error = mean_joint_error_of(&model, &res, &pose);
        assert!(error < 0.02, "mean joint error {error}");
    }

    #[test]
    fn the_mirrored_limb_takes_the_opposite_limbs_angles() {
        let mut pose = BodyModel::neutral_pose();
        pose[param::L_HIP..param::L_HIP + 3].copy_from_slice(&[1.2, 0.3, 0.9]);
        let m = mirrored_limb(&pose, 2);
        assert_eq!(m[param::R_HIP..param::R_HIP + 3], [1.2, 0.3, 0.9]);
        assert_eq!(m[param::L_HIP..param::L_HIP + 3], [1.2, 0.3, 0.9]);
        let mut rest = m;
        rest[param::R_HIP..param::R_HIP + 3].copy_from_slice(&pose[param::R_HIP..param::R_HIP + 3]);
        assert_eq!(rest, pose);
    }
}
