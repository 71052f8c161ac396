//! Move-making minimisation of a pairwise CRF energy
//!
//! E(l) = Σ_i U(i, l_i) + Σ_{e=(i,j)} w_e · V(l_i, l_j)
//!
//! by alpha-expansion (metric V) and alpha-beta swap (semi-metric V) (Boykov, Veksler &
//! Zabih, PAMI 2001). Each move is a binary problem solved exactly by one min cut, with
//! the construction of Kolmogorov & Zabih (PAMI 2004): a pairwise term with values
//! A = E(0,0), B = E(0,1), C = E(1,0), D = E(1,1) becomes the unary parts A(1−x_i) + C·x_i
//! and C(1−x_j) + D·x_j (up to a constant) plus an arc i→j of capacity B + C − A − D ≥ 0.
//!
//! A move is kept only if it lowers the energy, so the energy never increases, and the
//! result is deterministic. A unary cost equal to [`Cost::FORBIDDEN`] (`f64::INFINITY`,
//! `i64::MAX`) forbids that label at that node: energies are compared first by the
//! number of forbidden assignments, then by the finite sum.
//!
//! [`CrfSolver`] builds the graph structure once and reuses it (and all buffers) across
//! moves and calls; the free functions are one-shot conveniences.

mod moves;
mod problem;
mod solver;
mod swap;
#[cfg(test)]
mod tests;

pub use moves::potts_candidate_mask;
pub(crate) use problem::potts_energy;
pub use problem::{energy, Cost, CrfProblem, Labelling, MoveConfig, DEFAULT_MAX_CYCLES};
pub use solver::{alpha_beta_swap, alpha_expansion, CrfSolver};
pub(crate) use solver::{ExpansionHints, NO_WORK_BESIDE};
