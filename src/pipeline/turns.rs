//! Turns: a fit tried from the other sides of the body.
//!
//! The templates hold three views (front, left side, right side) and the hypotheses add
//! their back views, so a body seen obliquely starts an eighth of a turn or more from
//! the nearest template, and the EM, being local, can settle on a reading turned the
//! wrong way: the body facing away instead of toward the camera, or its near side read
//! as its far side. Front and back are resolved explicitly: every fit is also tried
//! turned half a turn about its own vertical axis, with its limbs as fitted and
//! exchanged, since a body and the same body facing the other way draw about mirrored
//! silhouettes that the search's starts hardly tell apart. Left and right are resolved
//! explicitly too: every fit is also tried with its limbs exchanged where it stands,
//! all of them, only the arms and only the legs ([`exchanges`]): in a side view the
//! near and far limbs draw about the same silhouette, and a raised arm is easily read
//! as the other one. When a fit explains the depth badly
//! ([`Estimator::explains_badly`]), it is turned by every other eighth of a turn as
//! well. Each turned start gets a short EM, also from the start recentred on the
//! observed points (a turned body shows the camera its other side); an exchange at the
//! same turn shows the camera the same side and gets its short EM as it is (but for a
//! fit explaining the depth badly, which may stand off the body). A limb whose end
//! explains no point of the fit (`limbs::unseen_limbs`: an arm hidden behind the
//! body) was placed by the start and the rest-pose penalty, not by the depth; turned
//! half a turn it stands in front of the body, where the depth contradicts it and the
//! short EM rarely moves it far enough. So, where the half turn is the only turn (the
//! fit does not explain the depth badly), the half turn (limbs as they are) is moved
//! onto the observed body and its unseen limbs take their best-ranked poses of
//! [`super::limbs`] before its refit: a body facing the camera with its forearms
//! pointing at it, read facing away with the arms hidden behind the back, is found so.
//! The refit that ranks best replaces the fit when it ranks better. From scratch the
//! turns run before the body's size is searched; when the size search changes the
//! body, they run again with the sized body (`Estimator::turned_at_size`): a subject
//! far from the model's size may be read the wrong way round at the model's size only.
//! Every size search does so: the first search's, and those of the searches that run
//! when it explains the depth badly.

use super::estimator::{Estimator, Frame};
use super::hypotheses::{swap_limbs, turn_around, turned};
use super::limbs::{best_limbs, unseen_limbs, LimbSearch};
use super::size::SizedFit;
use crate::body::Pose;
use crate::error::Result;
use crate::fit::start::limbs_swapped;
use crate::fit::{FitConfig, FitResult};
use std::f64::consts::FRAC_PI_4;

/// `pose` turned about its own vertical axis by every eighth of a turn but none, each
/// with its limbs as they are and exchanged ([`swap_limbs`]): 14 poses.
pub fn turned_starts(pose: &Pose) -> Vec<Pose> {
    (1..8)
        .flat_map(|k| {
            let t = turned(pose, k as f64 * FRAC_PI_4);
            [t, swap_limbs(&t)]
        })
        .collect()
}

/// `pose` with its limbs exchanged where it stands: all of them ([`swap_limbs`]), only
/// the arms and only the legs ([`limbs_swapped`]).
pub fn exchanges(pose: &Pose) -> [Pose; 3] {
    [
        swap_limbs(pose),
        limbs_swapped(pose, false, true),
        limbs_swapped(pose, true, false),
    ]
}

/// `pose` turned half a turn about its own vertical axis ([`turn_around`]), with its
/// limbs as they are and exchanged: the readings of the body facing the other way.
/// Both are among [`turned_starts`].
pub fn half_turns(pose: &Pose) -> [Pose; 2] {
    let t = turn_around(pose);
    [t, swap_limbs(&t)]
}

impl Estimator {
    /// `fit` (with `score`, its depth discrepancy) or the best of its turned and
    /// exchanged refits where that ranks better: half a turn and the exchanges always,
    /// every eighth of a turn when it explains the depth badly (see the module docs).
    /// Returns the fit kept and its discrepancy.
    pub(crate) fn try_turns(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
    ) -> Result<(FitResult, f64)> {
        let unseen = unseen_limbs(&fit.part_counts);
        Ok(self
            .better_turn(frame, &fit.pose, score, &unseen)?
            .unwrap_or((fit, score)))
    }

    /// `sized` or, when its body's size differs from `turned` (the size whose turns ran
    /// already) and one of its turned refits made with that body ranks better
    /// ([`Self::better_turn`]), that refit.
    pub(crate) fn turned_at_size(
        &self,
        frame: &mut Frame,
        sized: SizedFit,
        turned: f64,
    ) -> Result<SizedFit> {
        if sized.scale == turned {
            return Ok(sized);
        }
        let mut at_size = self.clone();
        at_size.set_model(sized.model.clone());
        let unseen = unseen_limbs(&sized.fit.part_counts);
        Ok(
            match at_size.better_turn(frame, &sized.fit.pose, sized.score, &unseen)? {
                Some((fit, score)) => SizedFit {
                    fit,
                    score,
                    ..sized
                },
                None => sized,
            },
        )
    }

    /// The best-ranked of the turned and exchanged refits of `pose` (with `score`, its
    /// depth discrepancy, and `unseen`, the limbs its fit leaves unseen:
    /// [`unseen_limbs`]) and its discrepancy, when it ranks better than `pose`.
    pub(crate) fn better_turn(
        &self,
        frame: &mut Frame,
        pose: &Pose,
        score: f64,
        unseen: &[usize],
    ) -> Result<Option<(FitResult, f64)>> {
        let short = self.config().short_refit();
        // A turned body shows the camera its other side, whose visible surface lies
        // elsewhere: each turned start is also tried recentred on the observed points,
        // like the search's. An exchange at the same turn shows the same side, but for
        // a fit explaining the depth badly, which may stand off the body too.
        let (turns, exchanged) = if self.explains_badly(frame, score) {
            let mut all = turned_starts(pose);
            all.extend(exchanges(pose));
            (all, Vec::new())
        } else {
            let mut halves = half_turns(pose);
            halves[0] = self.reposed_turn(frame, &short, halves[0], unseen)?;
            (halves.to_vec(), exchanges(pose).to_vec())
        };
        let recentred = FitConfig {
            recentred_start: true,
            ..short
        };
        let mut fits = self.fits(frame, &recentred, &turns, None, None)?;
        fits.extend(self.fits(frame, &short, &exchanged, None, None)?);
        let (best, best_score, best_rank) = self.best_ranked(frame, fits)?;
        Ok((best_rank < self.rank(score, pose)).then_some((best, best_score)))
    }

    /// `turned`, a fit's half turn, moved onto the observed body where that explains
    /// the depth better and with the fit's `unseen` limbs set to their best-ranked poses
    /// ([`best_limbs`]) when any ranks better than the limbs as they are; `turned`
    /// itself otherwise (and without `limb_poses`).
    fn reposed_turn(
        &self,
        frame: &mut Frame,
        config: &FitConfig,
        turned: Pose,
        unseen: &[usize],
    ) -> Result<Pose> {
        if unseen.is_empty() || !self.config().limb_poses {
            return Ok(turned);
        }
        let placed = self.better_placed(frame, config, vec![turned])?[0];
        let current = self.rankings(&self.discrepancies(frame, &[placed])?, &[placed])[0];
        let search = LimbSearch {
            limbs: unseen,
            mirrored: false,
            margin: 0.0,
        };
        let found = best_limbs(&placed, current, &search, |poses| {
            Ok(self.rankings(&self.discrepancies(frame, poses)?, poses))
        })?;
        Ok(if found.changed { found.pose } else { turned })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{param, root_rotation, BodyModel, NUM_SHAPE_FACTORS};
    use crate::camera::Camera;
    use crate::pipeline::tests::{estimator, mean_joint_distance, rendered_person, walking};
    use crate::pipeline::PipelineConfig;
    use nalgebra::Vector3;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn turned_starts_are_the_other_eighths_of_a_turn_with_limbs_as_they_are_and_exchanged() {
        let pose = turned(&walking(&BodyModel::default(), 0.7), 0.3);
        let starts = turned_starts(&pose);
        assert_eq!(starts.len(), 14);
        assert_eq!(starts[6..8], half_turns(&pose));
        let r = root_rotation(&pose);
        // Entry i of (turn k, limbs exchanged) in order is (i / 2 + 1, i odd).
        for (i, s) in starts.iter().enumerate() {
            let (k, swapped) = (i / 2 + 1, i % 2 == 1);
            // The turn relative to the body is about its own vertical axis.
            let rel = r.inverse() * root_rotation(s);
            let expected =
                nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), k as f64 * FRAC_PI_4);
            assert!(rel.angle_to(&expected) < 1e-9, "start {i}");
            assert_eq!(&s[..3], &pose[..3], "the hip centre stays");
            let limbs = if swapped { swap_limbs(&pose) } else { pose };
            assert_eq!(&s[6..], &limbs[6..], "start {i}");
        }
    }

    #[test]
    fn exchanges_keep_the_root_and_exchange_all_limbs_the_arms_or_the_legs() {
        let mut pose = turned(&walking(&BodyModel::default(), 0.7), 0.3);
        pose[param::R_ELBOW] = 1.1;
        let [all, arms, legs] = exchanges(&pose);
        assert_eq!(all, swap_limbs(&pose));
        for s in [all, arms, legs] {
            assert_eq!(&s[..6], &pose[..6], "the root stays");
        }
        let (r_arm, l_arm, r_leg, l_leg) = (
            param::R_SHOULDER,
            param::L_SHOULDER,
            param::R_HIP,
            param::L_HIP,
        );
        assert_eq!(arms[r_arm..r_arm + 4], pose[l_arm..l_arm + 4]);
        assert_eq!(arms[r_leg..r_leg + 3], pose[r_leg..r_leg + 3]);
        assert_eq!(legs[r_arm..r_arm + 4], pose[r_arm..r_arm + 4]);
        assert_eq!(legs[r_leg..r_leg + 3], pose[l_leg..l_leg + 3]);
    }

    /// A walker seen obliquely.
    fn oblique_walker() -> Pose {
        turned(&walking(&BodyModel::default(), 0.9), 0.8)
    }

    /// `pose` seen by [`Camera::itop`], its mask, and the short fit from `start` on that
    /// frame (with `full`, the whole EM of the fit settings, its start recentred):
    /// (pose, fit, its discrepancy, estimator, frame) to `check`.
    fn fitted_from(
        pose: Pose,
        full: bool,
        start: impl Fn(&Pose) -> Pose + Sync,
        check: impl FnOnce(&Pose, FitResult, f64, &Estimator, &mut Frame) + Send,
    ) {
        let model = BodyModel::default();
        let camera = Camera::itop();
        let (depth, mask) = rendered_person(&model, &pose, &camera);
        let est = estimator(&camera, PipelineConfig::default());
        crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, Some(&mask), None).unwrap();
            let config = if full {
                est.config().fit
            } else {
                est.config().short_refit()
            };
            let fit = est
                .fits(&mut frame, &config, &[start(&pose)], None, None)
                .unwrap()
                .pop()
                .unwrap();
            let (score, _) = est.discrepancy(&frame, &fit.pose);
            check(&pose, fit, score, &est, &mut frame);
        });
    }

    /// The mean joint error of `fit` against `pose`, then [`Estimator::try_turns`] on
    /// it: (the error before, the error after, the discrepancy after).
    fn turned_errors(
        pose: &Pose,
        fit: FitResult,
        score: f64,
        est: &Estimator,
        frame: &mut Frame,
    ) -> (f64, f64, f64) {
        let model = est.model();
        let error = |p: &Pose| mean_joint_distance(&model.joints(p), &model.joints(pose));
        let before = error(&fit.pose);
        let (turned, turned_score) = est.try_turns(frame, fit, score).unwrap();
        (before, error(&turned.pose), turned_score)
    }

    #[test]
    fn a_fit_turned_the_wrong_way_is_turned_back() {
        // A fit facing five eighths of a turn away with its limbs exchanged: the short
        // EM alone does not turn it back; the turns do.
        let wrong = |p: &Pose| swap_limbs(&turned(p, 5.0 * FRAC_PI_4));
        fitted_from(
            oblique_walker(),
            false,
            wrong,
            |pose, fit, score, est, frame| {
                assert!(est.explains_badly(frame, score), "discrepancy {score}");
                let (before, after, turned_score) = turned_errors(pose, fit, score, est, frame);
                assert!(before > 0.1, "error {before}");
                assert!(turned_score < score, "{turned_score} against {score}");
                assert!(after < 0.04, "mean joint error {after}");
            },
        );
    }

    #[test]
    fn a_fit_facing_away_that_explains_the_depth_well_is_turned_around() {
        // A walker facing the camera, an elbow bent. The fit starts facing away with its
        // limbs exchanged, so that each limb lies on its own side of the image, and its
        // EM makes it explain the depth well: only the half turn finds the body.
        for elbow in [0.6, 0.8] {
            let mut pose = walking(&BodyModel::default(), 0.9);
            pose[param::R_ELBOW] = elbow;
            let away = |p: &Pose| swap_limbs(&turn_around(p));
            fitted_from(pose, true, away, |pose, fit, score, est, frame| {
                assert!(!est.explains_badly(frame, score), "discrepancy {score}");
                let (before, after, turned_score) = turned_errors(pose, fit, score, est, frame);
                assert!(before > 0.25, "error {before}");
                assert!(turned_score < score, "{turned_score} against {score}");
                assert!(after < 0.06, "elbow {elbow}: mean joint error {after}");
            });
        }
    }

    #[test]
    fn a_side_view_with_its_arms_exchanged_is_exchanged_back() {
        // A walker seen from its side at several turns and steps, the right arm raised
        // forward, read with its arms exchanged: the raised arm drawn on the far side.
        // That reading explains the depth fairly (not badly, so no turn but the half
        // turn runs); the exchanges find the body.
        let model = BodyModel::default();
        let camera = Camera::itop();
        let est = estimator(&camera, PipelineConfig::default());
        for yaw in [1.2, FRAC_PI_2, 2.0] {
            for t in [0.3, 0.9] {
                let mut pose = turned(&walking(&model, t), yaw);
                pose[param::R_SHOULDER] = 0.9;
                pose[param::R_ELBOW] = 0.8;
                let wrong = limbs_swapped(&pose, false, true);
                let (depth, mask) = rendered_person(&model, &pose, &camera);
                let error = |p: &Pose| mean_joint_distance(&model.joints(p), &model.joints(&pose));
                crate::pool::on_worker(|| {
                    let mut frame = est.prepare(&depth, Some(&mask), None).unwrap();
                    let score = est.discrepancy(&frame, &wrong).0;
                    assert!(!est.explains_badly(&frame, score), "discrepancy {score}");
                    assert!(error(&wrong) > 0.07, "error {}", error(&wrong));
                    let (fit, fit_score) = est
                        .better_turn(&mut frame, &wrong, score, &[])
                        .unwrap()
                        .expect("a refit ranks better");
                    assert!(
                        fit_score < 0.05,
                        "yaw {yaw}, step {t}: discrepancy {fit_score}"
                    );
                    let e = error(&fit.pose);
                    assert!(e < 0.005, "yaw {yaw}, step {t}: mean joint error {e}");
                });
            }
        }
    }

    #[test]
    fn a_fit_that_explains_the_depth_well_is_kept_as_it_is() {
        fitted_from(
            oblique_walker(),
            false,
            |p| *p,
            |_, fit, score, est, frame| {
                let kept = fit.pose;
                let (out, out_score) = est.try_turns(frame, fit, score).unwrap();
                assert_eq!(out.pose, kept);
                assert_eq!(out_score, score);
            },
        );
    }

    #[test]
    fn a_sized_fit_facing_away_is_turned_around_with_its_own_body() {
        // A subject 10 % larger than the model, facing the camera, and its fit facing
        // away with the limbs exchanged, made with the subject's body as the size
        // search leaves it. Its half turns are refitted with that body.
        let mut pose = walking(&BodyModel::default(), 0.9);
        pose[param::R_ELBOW] = 0.7;
        let subject = BodyModel::default()
            .with_shape_factors(&[1.1; NUM_SHAPE_FACTORS])
            .unwrap();
        let camera = Camera::itop();
        let (depth, mask) = rendered_person(&subject, &pose, &camera);
        let est = estimator(&camera, PipelineConfig::default());
        crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, Some(&mask), None).unwrap();
            let mut sized_est = est.clone();
            sized_est.set_model(subject.clone());
            let away = swap_limbs(&turn_around(&pose));
            let config = est.config().fit;
            let fit = sized_est
                .fits(&mut frame, &config, &[away], None, None)
                .unwrap()
                .pop()
                .unwrap();
            let (score, _) = sized_est.discrepancy(&frame, &fit.pose);
            let error = |p: &Pose| mean_joint_distance(&subject.joints(p), &subject.joints(&pose));
            assert!(error(&fit.pose) > 0.25, "error {}", error(&fit.pose));
            let sized = SizedFit {
                fit,
                score,
                scale: 1.1,
                lean: 1,
                model: subject.clone(),
            };
            // At the size whose turns ran already: kept as it is.
            let same = est.turned_at_size(&mut frame, sized.clone(), 1.1).unwrap();
            assert_eq!(same.fit.pose, sized.fit.pose);
            let out = est.turned_at_size(&mut frame, sized, 1.0).unwrap();
            assert!(out.score < score, "{} against {score}", out.score);
            assert_eq!(out.scale, 1.1);
            assert!(
                error(&out.fit.pose) < 0.08,
                "mean joint error {}",
                error(&out.fit.pose)
            );
        });
    }
}
