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

pub use problem::{Cost, CrfProblem, Labelling, MoveConfig};
pub use solver::CrfSolver;
pub(crate) use solver::{ExpansionHints, NO_WORK_BESIDE};

use crate::error::{ensure, Error, Result};
use problem::{check_problem, Checked};

/// Default number of cycles over all labels (or label pairs).
pub const DEFAULT_MAX_CYCLES: usize = 20;
/// Below this many nodes, the energy is summed on one thread (rayon does not pay).
const PARALLEL_MIN_NODES: usize = 65_536;
/// Chunk size of the parallel energy sum (fixed, so float sums are deterministic).
const ENERGY_CHUNK: usize = 16_384;
/// Relative tolerance of the float triangle-inequality check on `pairwise`.
const METRIC_RTOL: f64 = 1e-12;

/// The energy of `labels` (with `unary` N×L etc. as in [`CrfProblem`]).
/// Returns [`Cost::FORBIDDEN`] if a node has a forbidden label.
pub fn energy<C: Cost>(problem: &CrfProblem<C>, labels: &[i32]) -> Result<C> {
    let c = check_problem(problem, false, false, false)?;
    ensure(labels.len() == c.n, "labels", || {
        format!("length {} does not match {} nodes", labels.len(), c.n)
    })?;
    if let Some(i) = labels.iter().position(|&a| a < 0 || a as usize >= c.l) {
        return Err(Error::invalid(
            "labels",
            format!("label {} at node {i} is not in 0..{}", labels[i], c.l),
        ));
    }
    Ok(c.energy(labels).value())
}

/// The energy of `labels` under Potts costs (`pairwise` None), unchecked: the sum
/// [`CrfSolver`] computes (same order, so the same bits), which lets a caller that
/// tracks energies hand one to [`ExpansionHints::init_energy`] or compare it with a
/// [`Labelling`]'s. Sizes and labels must be in range (panics otherwise); a forbidden
/// label gives [`Cost::FORBIDDEN`].
pub(crate) fn potts_energy<C: Cost>(
    unary: &[C],
    n_labels: usize,
    edges: &[[u32; 2]],
    weights: &[C],
    labels: &[i32],
) -> C {
    let c = Checked {
        n: labels.len(),
        l: n_labels,
        unary,
        edges,
        weights,
        // Potts: `pair` reads neither; `energy` needs neither.
        v: Vec::new(),
        potts: true,
        big: C::ZERO,
        allowed_somewhere: Vec::new(),
    };
    c.energy(labels).value()
}

/// Alpha-expansion (metric `pairwise`), one shot. See [`CrfSolver`] to reuse storage.
pub fn alpha_expansion<C: Cost>(
    problem: &CrfProblem<C>,
    init: Option<&[i32]>,
    config: &MoveConfig,
) -> Result<Labelling<C>> {
    let n = problem.unary.len() / problem.n_labels.max(1);
    CrfSolver::new(n, problem.edges)?.alpha_expansion(problem, init, config)
}

/// Alpha-beta swap (semi-metric `pairwise`), one shot.
pub fn alpha_beta_swap<C: Cost>(
    problem: &CrfProblem<C>,
    init: Option<&[i32]>,
    config: &MoveConfig,
) -> Result<Labelling<C>> {
    let n = problem.unary.len() / problem.n_labels.max(1);
    CrfSolver::new(n, problem.edges)?.alpha_beta_swap(problem, init, config)
}

/// The labels a node labelled `own`, with unary row `row` and sum of edge weights
/// `slack`, may switch to in an expansion move on a Potts problem with nothing
/// forbidden (bit per label): those whose unary exceeds its own by at most `slack`,
/// the exact pruning test of the moves (`CrfSolver::expansion_move`).
#[inline(always)]
pub fn potts_candidate_mask<C: Cost>(row: &[C], own: usize, slack: C) -> u64 {
    let base = row[own];
    let mask = row
        .iter()
        .enumerate()
        .fold(0u64, |m, (a, &u)| m | (((u - base <= slack) as u64) << a));
    mask & !(1u64 << own)
}
