//! Graph cuts: a Boykov–Kolmogorov max-flow ([`maxflow`]) and the move-making CRF
//! solvers built on it ([`expansion`]: alpha-expansion and alpha-beta swap), used by the
//! E-step of the pose fit to label points with body parts.

mod bitset;
pub mod expansion;
pub mod maxflow;

pub use expansion::{
    alpha_beta_swap, alpha_expansion, energy, Cost, CrfProblem, CrfSolver, Labelling, MoveConfig,
};
pub use maxflow::{grid_edges, Capacity, Graph};
