//! A per-limb test of a fit, and the re-initialisation of the limbs it finds lost.
//!
//! A limb is lost when most of it, as the fitted body renders it, lies off the person:
//! outside the person's mask, where the camera sees no person, or more than
//! [`DISCREPANCY_CAP`] from the observed depth, where the camera sees something nearer
//! or farther. Most means more than half of the limb's own pixels, so the test does not
//! depend on the limb's size in the image. A tracked limb gets lost when it moves
//! faster than the motion model follows, or when a lost frame's search keeps a body
//! whose torso is right but whose limbs come from another pose.
//!
//! Each lost limb is set in turn to the poses of [`super::limbs`] and to the pose of
//! the opposite limb (its mirror image), the rest of the body kept, and takes the one
//! that ranks best when it ranks better than the limb as it was. A body changed so is
//! refitted briefly, beside the next best-ranked poses scored
//! ([`super::limbs::REFITTED_STARTS`] in all), and the best-ranked refit replaces the
//! fit only when it ranks better by
//! `switch_margin`, as any reading the motion does not support, and draws each
//! re-initialised limb on the person: a limb hidden in the body, or still off the
//! person, is not found. (Hiding a limb costs the discrepancy little where the limb it
//! replaces was off the person anyway.) Limbs that lie on the person are never moved.

use super::estimator::{Estimator, Frame, DISCREPANCY_CAP};
use super::limbs::{LimbSearch, LIMBS, LIMB_SEGMENTS};
use crate::body::{Pose, NUM_SEGMENTS};
use crate::error::Result;
use crate::fit::FitResult;
use crate::render::BACKGROUND_LABEL;

/// The limb of each body segment (an index into [`LIMBS`]); `usize::MAX` for the head,
/// neck, torso and pelvis.
const LIMB_OF_SEGMENT: [usize; NUM_SEGMENTS] = {
    let mut limb_of = [usize::MAX; NUM_SEGMENTS];
    let mut limb = 0;
    while limb < LIMB_SEGMENTS.len() {
        let mut k = 0;
        while k < LIMB_SEGMENTS[limb].len() {
            limb_of[LIMB_SEGMENTS[limb][k]] = limb;
            k += 1;
        }
        limb += 1;
    }
    limb_of
};

/// Where a limb lies in the body rendered at a fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LimbState {
    /// Not drawn: the rest of the body hides it. Nothing of it contradicts the data.
    Hidden,
    /// Drawn, at least half of it on the person.
    OnThePerson,
    /// Drawn, more than half of it off the person.
    Lost,
}

/// Where each limb (right arm, left arm, right leg, left leg: the order of [`LIMBS`])
/// lies in the body rendered at a fit (`rendered` depth, metres, 0 = none; `labels`,
/// its part labels). A pixel of a limb is off the person when it is outside `mask` or
/// more than `cap` metres from the observed `depth`.
pub(crate) fn limb_states(
    rendered: &[f32],
    labels: &[i16],
    depth: &[f32],
    mask: &[bool],
    cap: f64,
) -> [LimbState; 4] {
    let (mut drawn, mut off) = ([0usize; 4], [0usize; 4]);
    for (((&label, &r), &d), &m) in labels.iter().zip(rendered).zip(depth).zip(mask) {
        if label == BACKGROUND_LABEL {
            continue;
        }
        let limb = LIMB_OF_SEGMENT[label as usize];
        if limb != usize::MAX {
            drawn[limb] += 1;
            let observed = d > 0.0 && d.is_finite();
            off[limb] += usize::from(!m || (observed && f64::from((r - d).abs()) > cap));
        }
    }
    std::array::from_fn(|k| match (drawn[k], 2 * off[k] > drawn[k]) {
        (0, _) => LimbState::Hidden,
        (_, true) => LimbState::Lost,
        (_, false) => LimbState::OnThePerson,
    })
}

impl Estimator {
    /// `fit` (with `score`, its depth discrepancy) with its lost limbs re-initialised
    /// where that explains the depth better and draws them on the person (see the
    /// module docs). Returns the fit kept, its discrepancy and whether it changed.
    pub(crate) fn refind_lost_limbs(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
    ) -> Result<(FitResult, f64, bool)> {
        let states = self.limb_states_at(frame, &fit.pose);
        let limbs: Vec<usize> = (0..LIMBS.len())
            .filter(|&k| states[k] == LimbState::Lost)
            .collect();
        if limbs.is_empty() {
            return Ok((fit, score, false));
        }
        // A tracked body's limbs are where its motion put them: a limb from elsewhere
        // replaces them only when clearly better, by `switch_margin`.
        let search = LimbSearch {
            limbs: &limbs,
            mirrored: true,
            margin: self.config().switch_margin,
        };
        let old = fit.clone();
        let (refit, refit_score, changed) = self.repose(frame, fit, score, &search)?;
        if !changed {
            return Ok((refit, refit_score, false));
        }
        // A limb hidden in the body, or still drawn off the person, is not found.
        let states = self.limb_states_at(frame, &refit.pose);
        if limbs.iter().all(|&k| states[k] == LimbState::OnThePerson) {
            Ok((refit, refit_score, true))
        } else {
            Ok((old, score, false))
        }
    }

    /// [`limb_states`] of the body at `pose` on `frame`.
    fn limb_states_at(&self, frame: &Frame, pose: &Pose) -> [LimbState; 4] {
        let (rendered, labels) = self.model().render_depth(pose, &self.resolution().working);
        limb_states(
            &rendered,
            &labels,
            &frame.depth,
            &frame.mask,
            DISCREPANCY_CAP,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{param, BodyModel, Pose};
    use crate::camera::Camera;
    use crate::pipeline::limbs::ARM_POSES;
    use crate::pipeline::tests::{
        estimator, mean_joint_distance, rendered_person, room, room_posed, walking,
    };
    use crate::pipeline::PipelineConfig;

    /// `pose` with its right arm out sideways.
    fn arm_out(pose: &Pose) -> Pose {
        let mut out = *pose;
        out[param::R_SHOULDER..param::R_SHOULDER + 4].copy_from_slice(&ARM_POSES[1]);
        out
    }

    #[test]
    fn a_limb_drawn_off_the_person_is_lost_and_the_others_are_not() {
        // The person: the body walking, right arm down. A fit with the right arm out
        // sideways draws it where the camera sees no person.
        use LimbState::{Hidden, Lost, OnThePerson};
        let model = BodyModel::default();
        let camera = Camera::itop();
        let truth = walking(&model, 0.0);
        let (depth, mask) = rendered_person(&model, &truth, &camera);
        let states = |pose: &Pose| {
            let (rendered, labels) = model.render_depth(pose, &camera);
            limb_states(&rendered, &labels, &depth, &mask, DISCREPANCY_CAP)
        };
        assert_eq!(states(&truth), [OnThePerson; 4]);
        assert_eq!(
            states(&arm_out(&truth)),
            [Lost, OnThePerson, OnThePerson, OnThePerson]
        );
        // The body 30 cm nearer: on the mask, off the depth; every limb is lost.
        let mut nearer = truth;
        nearer[param::ROOT_T + 2] -= 0.3;
        assert_eq!(states(&nearer), [Lost; 4]);
        // Nothing drawn: every limb hidden.
        let none = vec![BACKGROUND_LABEL; mask.len()];
        assert_eq!(
            limb_states(&depth, &none, &depth, &mask, DISCREPANCY_CAP),
            [Hidden; 4]
        );
    }

    #[test]
    fn a_lost_arm_is_found_again_and_the_rest_of_the_body_kept() {
        let model = BodyModel::default();
        let truth = walking(&model, 0.0);
        let depth = room_posed(&model, &truth);
        let camera = Camera::itop();
        let est = estimator(&camera, PipelineConfig::default()).with_size_search(false);
        let (lost, kept) = crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, None, None)?;
            let config = est.config().short_refit();
            let mut run = |start: &Pose| {
                // A fit's result with its pose set to `start`: a fit that kept the arm.
                let mut fit =
                    est.problem(&mut frame, &config)?
                        .fit_from(est.model(), start, None, None)?;
                fit.pose = *start;
                let score = est.discrepancy(&frame, start).0;
                est.refind_lost_limbs(&mut frame, fit, score)
            };
            Ok::<_, crate::error::Error>((run(&arm_out(&truth))?, run(&truth)?))
        })
        .unwrap();
        let (fit, _, changed) = lost;
        assert!(changed);
        let error = mean_joint_distance(&model.joints(&fit.pose), &model.joints(&truth));
        assert!(error < 0.03, "mean joint error {error}");
        // No limb lost: the fit comes back as it was.
        let (fit, _, changed) = kept;
        assert!(!changed);
        assert_eq!(fit.pose, truth);
    }

    #[test]
    fn a_limb_is_found_only_on_the_person() {
        // The person with no right arm in the image (its pixels show the room): a fit
        // with the arm out sideways has it lost, and an arm the refit hides in the
        // body or leaves off the person is not taken for it.
        let model = BodyModel::default();
        let camera = Camera::itop();
        let truth = walking(&model, 0.0);
        let mut depth = room_posed(&model, &truth);
        let empty = room(&camera);
        let (_, labels) = model.render_depth(&truth, &camera);
        let arm = LIMB_SEGMENTS[0].map(|s| s as i16);
        for ((d, &e), l) in depth.iter_mut().zip(&empty).zip(&labels) {
            if arm.contains(l) {
                *d = e;
            }
        }
        let est = estimator(&camera, PipelineConfig::default()).with_size_search(false);
        let start = arm_out(&truth);
        let (fit, changed, before, after) = crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, None, None)?;
            let config = est.config().short_refit();
            let mut fit =
                est.problem(&mut frame, &config)?
                    .fit_from(est.model(), &start, None, None)?;
            fit.pose = start;
            let score = est.discrepancy(&frame, &start).0;
            let before = est.limb_states_at(&frame, &start);
            let (fit, _, changed) = est.refind_lost_limbs(&mut frame, fit, score)?;
            let after = est.limb_states_at(&frame, &fit.pose);
            Ok::<_, crate::error::Error>((fit, changed, before, after))
        })
        .unwrap();
        assert_eq!(before[0], LimbState::Lost);
        if changed {
            assert_eq!(after[0], LimbState::OnThePerson, "{:?}", fit.pose);
        } else {
            assert_eq!(fit.pose, start);
        }
    }
}
