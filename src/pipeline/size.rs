//! The body's size from one frame.
//!
//! A body model of the wrong size puts every joint off: fitted to a 1.60 m subject, a
//! 1.75 m body stands its hips too low or its head too high and stretches its limbs
//! past the hands and feet. From scratch the subject's size is unknown, so the best fit
//! of the search is refitted with the body scaled uniformly to sizes in a range
//! around the model's (1 ± k·`size_step`, up to ± `size_range`), and the size whose fit
//! explains the observed depth best is kept: the depth discrepancy of the rendered body
//! plus the rest-pose penalty, the measure by which poses compete everywhere in the
//! pipeline. A smaller body leaves observed pixels unexplained, a larger one covers
//! pixels off the person, so the discrepancy has its minimum near the subject's size.

use super::estimator::{Estimator, Frame};
use crate::body::{BodyModel, Pose, NUM_SHAPE_FACTORS};
use crate::error::Result;
use crate::fit::{FitConfig, FitResult};
use rayon::prelude::*;

/// A fit and the body it was made with.
#[derive(Debug, Clone)]
pub struct SizedFit {
    pub fit: FitResult,
    /// Its depth discrepancy.
    pub score: f64,
    /// The body's size relative to the estimator's model.
    pub scale: f64,
    /// The body.
    pub model: BodyModel,
}

/// How many steps of `step` the sizes 1 ± k·`step` may take on each side of 1 within
/// `range` (a little tolerance for rounding); 0 when either is not positive.
pub fn size_steps(range: f64, step: f64) -> usize {
    if !(range > 0.0 && step > 0.0) {
        return 0;
    }
    ((range + 1e-9) / step).floor() as usize
}

impl Estimator {
    /// `fit` (the search's best, made with the estimator's model, `score` its
    /// discrepancy) with the body's size found when `search` (see the module docs),
    /// labelled at every pixel with the body kept.
    ///
    /// The sizes are walked outward from 1 in rounds of two fits run in parallel: the
    /// nearest two first, then, while the best size is the outermost tried, the next two
    /// on its side. The discrepancy is smooth in the size and has one minimum near the
    /// subject's, so the walk finds the grid's best in two rounds where trying every
    /// size would take three or more.
    pub(crate) fn fit_size(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
        search: bool,
    ) -> Result<SizedFit> {
        let cfg = self.config();
        let steps = if search {
            size_steps(cfg.size_range, cfg.size_step)
        } else {
            0
        };
        let mut best = SizedFit {
            fit,
            score,
            scale: 1.0,
            model: self.model().clone(),
        };
        if steps > 0 {
            let mut rank = self.rank(best.score, &best.fit.pose);
            // One short EM from the fitted pose per size: it is on the body already.
            let config = cfg.short_refit();
            let start = best.fit.pose;
            let step = cfg.size_step;
            let mut round = vec![1.0 - step, 1.0 + step];
            let mut reached = 1;
            while !round.is_empty() {
                let tried = self.fits_at_sizes(frame, &config, &start, &round)?;
                let mut moved = None;
                for t in tried {
                    let r = self.rank(t.score, &t.fit.pose);
                    if r < rank {
                        rank = r;
                        moved = Some(t.scale);
                        best = t;
                    }
                }
                // Walk on only while the best is the outermost size tried on its side.
                let side = match moved {
                    Some(s) if ((s - 1.0).abs() - reached as f64 * step).abs() < 1e-9 => {
                        (s - 1.0).signum()
                    }
                    _ => break,
                };
                round = (reached + 1..=(reached + 2).min(steps))
                    .map(|k| 1.0 + side * k as f64 * step)
                    .collect();
                reached += round.len();
            }
        }
        best.fit = self.label_all(frame, best.fit, &best.model)?;
        Ok(best)
    }

    /// Fits from `start` with the body scaled uniformly to each of `scales`, in
    /// parallel, each with its depth discrepancy.
    fn fits_at_sizes(
        &self,
        frame: &mut Frame,
        config: &FitConfig,
        start: &Pose,
        scales: &[f64],
    ) -> Result<Vec<SizedFit>> {
        let models = scales
            .iter()
            .map(|&s| self.model().with_shape_factors(&[s; NUM_SHAPE_FACTORS]))
            .collect::<Result<Vec<_>>>()?;
        let fits = {
            let problem = &*self.problem(frame, config)?;
            models
                .par_iter()
                .map(|m| problem.fit_from(m, start, None, None))
                .collect::<Result<Vec<_>>>()?
        };
        let frame = &*frame;
        Ok(fits
            .into_par_iter()
            .zip(models)
            .zip(scales)
            .map(|((fit, model), &scale)| {
                let score = self.discrepancy_with(frame, &model, &fit.pose).0;
                SizedFit {
                    fit,
                    score,
                    scale,
                    model,
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::pipeline::tests::{estimator, mean_joint_error_of, room_with};
    use crate::pipeline::{PipelineConfig, Tracker};

    #[test]
    fn a_short_subject_is_fitted_at_its_size() {
        // A 1.60 m body (0.914 of the 1.75 m model) walking in the room.
        let subject = BodyModel::new(1.60).unwrap();
        let (camera, depth, pose) = room_with(&subject, 0.6);
        let sized = estimator(&camera, PipelineConfig::default());
        let fixed = sized.clone().with_size_search(false);
        let (a, b) =
            crate::pool::on_worker(|| (sized.estimate(&depth, None), fixed.estimate(&depth, None)));
        let (a, b) = (a.unwrap(), b.unwrap());
        let height = a.shape.standing_height() / BodyModel::default().shape.standing_height();
        assert!((0.875..=0.955).contains(&height), "relative size {height}");
        let (ea, eb) = (
            mean_joint_error_of(&subject, &a, &pose),
            mean_joint_error_of(&subject, &b, &pose),
        );
        assert!(ea < 0.04 && ea < eb, "sized {ea}, fixed {eb}");
        assert!(a.discrepancy < b.discrepancy);
        // Sizes are not searched when the estimator is told the shape.
        assert_eq!(b.shape, BodyModel::default().shape);
    }

    #[test]
    fn a_tracker_sizes_the_body_once_and_calibrates_from_there() {
        let subject = BodyModel::new(1.90).unwrap();
        let config = PipelineConfig {
            calibration_frames: 3,
            ..PipelineConfig::default()
        };
        let mut tracker = Tracker::new(estimator(&Camera::itop(), config), true);
        for k in 0..5 {
            let (_, depth, pose) = room_with(&subject, 0.3 * k as f64);
            let r = crate::pool::on_worker(|| tracker.update(&depth, None)).unwrap();
            let err = mean_joint_error_of(&subject, &r, &pose);
            assert!(err < 0.05, "frame {k}: mean joint error {err}");
        }
        let size = tracker.size().expect("sized on the first frame");
        assert!((1.05..=1.15).contains(&size), "{size}");
        // The calibrated factors are relative to the base model, the size included.
        let factors = tracker.shape_factors().expect("calibrated");
        let mean = factors.iter().sum::<f64>() / factors.len() as f64;
        assert!((mean - 1.9 / 1.75).abs() < 0.06, "{factors:?}");
        tracker.reset(true);
        assert_eq!(tracker.size(), None);
        assert_eq!(tracker.model(), tracker.base_model());
    }

    #[test]
    fn size_steps_stay_within_the_range() {
        assert_eq!(size_steps(0.0, 0.05), 0);
        assert_eq!(size_steps(0.1, 0.0), 0);
        // 0.15 / 0.05 is 2.999… in floating point: the tolerance counts it as 3.
        assert_eq!(size_steps(0.15, 0.05), 3);
        assert_eq!(size_steps(0.12, 0.05), 2);
    }
}
