//! What a hard-EM run returns, and what it needs to be continued.

use crate::body::{Pose, NUM_SEGMENTS};

/// Why the EM loop stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EmTermination {
    /// Labels and energy settled.
    Converged,
    /// An iteration changed neither labels nor pose.
    Stationary,
    /// `max_iterations` reached.
    MaxIterations,
}

impl EmTermination {
    pub fn name(self) -> &'static str {
        match self {
            EmTermination::Converged => "converged",
            EmTermination::Stationary => "stationary",
            EmTermination::MaxIterations => "max_iterations",
        }
    }
}

/// Outcome of [`hard_em`](super::hard_em).
#[derive(Debug, Clone, PartialEq)]
pub struct EmResult {
    pub pose: Pose,
    /// Per point: segment 0..15 or −1 (outlier).
    pub labels: Vec<i32>,
    /// Final energy.
    pub energy: f64,
    /// Energy after the initial E-step and after every M- and E-step (non-increasing;
    /// while τ anneals, an M-step's entry is already at the next E-step's τ).
    pub energy_trace: Vec<f64>,
    pub iterations: usize,
    pub termination: EmTermination,
    /// Some(k): the fit had settled at iteration k while τ was still annealing, and τ
    /// took its final value from iteration k + 1 on ([`EmConfig::adaptive_anneal`]; a
    /// resumed run continues so).
    ///
    /// [`EmConfig::adaptive_anneal`]: super::EmConfig::adaptive_anneal
    pub anneal_cut: Option<usize>,
    /// Points per segment.
    pub part_counts: [usize; NUM_SEGMENTS],
    /// Points labelled outlier.
    pub outliers: usize,
}

/// An EM run to continue (see [`hard_em_from`]): the per-point labels it ended with
/// (segment 0..15 or [`OUTLIER`]), the iterations it ran and where its annealing was
/// cut ([`EmResult::anneal_cut`]).
///
/// [`hard_em_from`]: super::hard_em_from
/// [`OUTLIER`]: super::OUTLIER
#[derive(Debug, Clone, Copy)]
pub struct EmResume<'a> {
    pub labels: &'a [i32],
    pub iterations: usize,
    pub anneal_cut: Option<usize>,
}
