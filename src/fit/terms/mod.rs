//! The terms of the fit's energy in the pose: the data term of labelled points
//! ([`data`]), the free-space term ([`free_space`]), a pose prior ([`prior`]), and
//! their sum as one objective ([`WithPrior`]).

pub mod data;
pub mod free_space;
pub mod loss;
pub mod prior;

pub use loss::{Loss, PointCost};
pub use prior::PosePrior;

use crate::body::Pose;
use crate::fit::system::{PoseObjective, N, NN};
use free_space::FreeSpaceTerm;

/// An objective plus an optional prior and an optional free-space term.
pub struct WithPrior<'a, O: PoseObjective> {
    pub objective: &'a mut O,
    pub prior: Option<&'a PosePrior>,
    pub free_space: Option<&'a FreeSpaceTerm<'a>>,
}

/// The free-space term is evaluated beside the objective (its samples are a serial
/// loop that would otherwise follow the objective's parallel one) and added after it,
/// in the same order as one after the other, so the sums are the same bit for bit.
impl<O: PoseObjective + Send> PoseObjective for WithPrior<'_, O> {
    fn cost(&mut self, pose: &Pose) -> f64 {
        let (c, free_space) = match self.free_space.filter(|f| f.active()) {
            Some(f) => rayon::join(|| self.objective.cost(pose), || f.cost(pose)),
            None => (self.objective.cost(pose), 0.0),
        };
        c + self.prior.map_or(0.0, |p| p.cost(pose)) + free_space
    }
    fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
        let (c, free_space) = match self.free_space.filter(|f| f.active()) {
            Some(f) => {
                let (c, system) = rayon::join(
                    || self.objective.normal_equations(pose, h, g),
                    || f.system(pose),
                );
                (c, Some((f, system)))
            }
            None => (self.objective.normal_equations(pose, h, g), None),
        };
        c + self.prior.map_or(0.0, |p| p.add_to(pose, h, g))
            + free_space.map_or(0.0, |(f, system)| f.add_system(pose, &system, h, g))
    }
}
