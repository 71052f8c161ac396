//! The M-step: Levenberg–Marquardt on the labelled points with the pose-only terms,
//! also run ahead beside an E-step for the labels it is likely to end with.

use crate::body::Pose;
use crate::fit::lm::{LevenbergMarquardt, LmReport};
use crate::fit::system::PoseObjective;
use crate::fit::terms::data::PointObjective;
use crate::fit::terms::free_space::FreeSpaceTerm;
use crate::fit::terms::{PointCost, PosePrior, WithPrior};
use std::sync::atomic::AtomicBool;

/// The terms of the energy that depend on the pose alone: a prior and the free space.
#[derive(Clone, Copy, Default)]
pub(super) struct PoseTerms<'t> {
    pub prior: Option<&'t PosePrior>,
    pub free_space: Option<&'t FreeSpaceTerm<'t>>,
}

impl PoseTerms<'_> {
    /// Their cost at `pose`.
    pub fn cost(&self, pose: &Pose) -> f64 {
        self.prior.map_or(0.0, |pr| pr.cost(pose)) + self.free_space.map_or(0.0, |f| f.cost(pose))
    }
}

/// One M-step: LM from `start` on the objective's labels (with the pose-only terms).
pub(super) fn m_step(
    lm: &mut LevenbergMarquardt,
    objective: &mut PointObjective,
    terms: PoseTerms<'_>,
    start: &Pose,
) -> (Pose, LmReport) {
    let mut pose = *start;
    let mut with_prior = WithPrior {
        objective,
        prior: terms.prior,
        free_space: terms.free_space,
    };
    let report = lm.minimize(&mut with_prior, &mut pose);
    (pose, report)
}

/// [`m_step`] for the labels `labels` at `point_cost`, run ahead beside an E-step:
/// abandoned (`None`) once `abandon` is raised.
fn m_step_ahead(
    lm: &mut LevenbergMarquardt,
    objective: &mut PointObjective,
    (labels, point_cost): (&[i32], PointCost),
    terms: PoseTerms<'_>,
    start: &Pose,
    abandon: &AtomicBool,
) -> Option<(Pose, LmReport)> {
    objective.relabel(labels, point_cost);
    // The distances at the start even if abandoned: the M-step that is used starts
    // here too, with mostly the same labels, and takes them from here (see
    // `PointObjective`), so this is work off its path on the thread the E-step's cycle
    // leaves idle.
    objective.cost(start);
    let mut pose = *start;
    let mut with_prior = WithPrior {
        objective,
        prior: terms.prior,
        free_space: terms.free_space,
    };
    let report = lm.minimize_unless(&mut with_prior, &mut pose, abandon)?;
    Some((pose, report))
}

/// The next M-step (from `start`, at `point_cost`) as the work beside an expansion's
/// cycles, for the labels each cycle starts from (see `EStep::expand_beside`); counts
/// its runs in `runs`. Its free-space term is its own (see `EmRun::free_space_ahead`).
pub(super) fn m_step_beside<'s, 'd: 's>(
    lm: &'s mut LevenbergMarquardt,
    objective: &'s mut PointObjective<'d>,
    free_space: &'s mut Option<FreeSpaceTerm<'d>>,
    prior: Option<&'s PosePrior>,
    (start, point_cost): (Pose, PointCost),
    runs: &'s mut usize,
) -> impl FnMut(&[i32], &AtomicBool) -> Option<(Pose, LmReport)> + Send + use<'s, 'd> {
    move |seen, abandon| {
        *runs += 1;
        let terms = PoseTerms {
            prior,
            free_space: free_space.as_mut().map(|f| &*f),
        };
        m_step_ahead(lm, objective, (seen, point_cost), terms, &start, abandon)
    }
}

/// M-steps run beside an E-step, and how many of them were used (they had the labels
/// the E-step ended with); the others were discarded or abandoned.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub(super) struct MStepsAhead {
    pub run: usize,
    pub used: usize,
    /// Of those used, the ones run beside an expansion's last cycle.
    pub used_beside_last_cycle: usize,
}

/// An M-step run beside an E-step, for the labels the E-step started from or for
/// those it ended with.
pub(super) enum RunAhead {
    ForOldLabels((Pose, LmReport)),
    ForNewLabels((Pose, LmReport)),
}
