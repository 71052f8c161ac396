//! Neutral-body starts, for a body in an orientation and pose no template resembles.
//!
//! The templates hold standing bodies. Rolled views reach a standing body at any roll,
//! but an airborne, tucked or split body (a flip, a cartwheel) resembles none of them,
//! and the descriptor match and the start discrepancy then rank templates that lead the
//! EM astray. The neutral body (upright, arms down) facing each quarter turn and rolled
//! by every eighth of a turn ([`rolled_neutral_bodies`]) is a start within 22.5° of any
//! trunk's roll and 45° of its turn about its own axis, and the EM bends the limbs onto
//! the body. A neutral start is far from the body's limbs, so it needs a longer EM than
//! a template start: every start gets a short EM at twice the final stride, and the
//! `finals` that explain the depth best a full EM, as the template search continues its
//! best candidates.

use super::estimator::{stable_order, Estimator, Frame};
use super::hypotheses::rolled_neutral_bodies;
use super::orientation::every_roll;
use crate::body::Pose;
use crate::error::Result;
use crate::fit::FitResult;

impl Estimator {
    /// The best fit from the rolled neutral bodies (see the module docs), with its depth
    /// discrepancy. The fit has its EM's labels only.
    pub(crate) fn search_neutral(&self, frame: &mut Frame) -> Result<(FitResult, f64)> {
        let cfg = self.config();
        let mut brief = cfg.fit_with(
            Some(cfg.track_iterations),
            2 * cfg.final_stride,
            Some(false),
        );
        let starts = self.better_placed(frame, &brief, rolled_neutral_bodies(&every_roll()))?;
        brief.recentred_start = false;
        let fits = self.fits(frame, &brief, &starts, None, None)?;
        let poses: Vec<Pose> = fits.iter().map(|f| f.pose).collect();
        let scores = self.discrepancies(frame, &poses)?;
        let winners: Vec<Pose> = stable_order(&self.rankings(&scores, &poses))
            .into_iter()
            .take(cfg.finals.max(1))
            .map(|i| poses[i])
            .collect();
        let full = cfg.fit_with(cfg.final_iterations, cfg.final_stride, Some(false));
        let finals = self.fits(frame, &full, &winners, None, None)?;
        let (best, score, _) = self.best_ranked(frame, finals)?;
        Ok((best, score))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::rotation::rotation_vector;
    use crate::body::{param, BodyModel};
    use crate::camera::Camera;
    use crate::pipeline::config::PipelineConfig;
    use crate::pipeline::hypotheses::turned;
    use crate::pipeline::orientation::rotate_about_optical_axis;
    use crate::pipeline::tests::{estimator, rendered_person};
    use std::f64::consts::PI;

    #[test]
    fn a_body_no_template_resembles_is_found_from_the_neutral_bodies() {
        // Airborne, rolled past horizontal and half turned away, one leg tucked, the
        // other out sideways, arms raised in a V: a standing template fits none of it.
        let model = BodyModel::default();
        let camera = Camera::itop();
        let mut upright = BodyModel::neutral_pose();
        upright[param::ROOT_T + 2] = 3.0;
        upright[param::R_SHOULDER + 1] = 2.4;
        upright[param::L_SHOULDER + 1] = 2.4;
        upright[param::R_HIP] = 1.6;
        upright[param::R_KNEE] = 1.9;
        upright[param::L_HIP + 1] = 1.0;
        let pose = rotate_about_optical_axis(&turned(&upright, 0.5), 2.2);
        let (depth, mask) = rendered_person(&model, &pose, &camera);
        let est = estimator(&camera, PipelineConfig::default());
        let (fit, score) = crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, Some(&mask), None)?;
            est.search_neutral(&mut frame)
        })
        .unwrap();
        let (a, b) = (model.joints(&fit.pose), model.joints(&pose));
        let error = a.iter().zip(&b).map(|(x, y)| (x - y).norm()).sum::<f64>() / a.len() as f64;
        assert!(error < 0.06, "mean joint error {error}");
        assert!(score < 0.3, "discrepancy {score}");
    }

    #[test]
    fn the_neutral_bodies_cover_every_roll_and_turn() {
        let starts = rolled_neutral_bodies(&every_roll());
        assert_eq!(starts.len(), 32);
        let rotation = |p: &Pose| crate::body::root_rotation(p);
        // (`angle_to` is NaN at a half turn.)
        let apart =
            |a: &Pose, b: &Pose| rotation_vector(&(rotation(a).inverse() * rotation(b))).norm();
        let neutral = BodyModel::neutral_pose();
        for (i, a) in starts.iter().enumerate() {
            // Limbs as the neutral body's.
            assert_eq!(a[param::NECK..], neutral[param::NECK..]);
            for b in &starts[i + 1..] {
                let apart = apart(a, b);
                assert!(apart > PI / 4.0 - 1e-9, "two starts {apart} rad apart");
            }
        }
        for k in 0..200 {
            let (roll, turn) = (k as f64 * 0.731, k as f64 * 1.377);
            let body = rotate_about_optical_axis(&turned(&neutral, turn), roll);
            let nearest = starts
                .iter()
                .map(|s| apart(s, &body))
                .fold(f64::INFINITY, f64::min);
            // At most an eighth of a turn of roll and a quarter turn's half of turn.
            assert!(
                nearest <= 3.0 * PI / 8.0 + 1e-9,
                "roll {roll}, turn {turn}: {nearest} rad"
            );
        }
    }
}
