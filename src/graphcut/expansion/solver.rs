//! [`CrfSolver`]: the reusable move-making solver, its state and the entry points of
//! alpha-expansion.

use super::problem::{check_problem, Checked, Energy};
use super::problem::{Cost, CrfProblem, Labelling, MoveConfig};
use crate::error::{ensure, Error, Result};
use crate::graphcut::bitset::BitSet;
use crate::graphcut::maxflow::Graph;
use std::sync::atomic::AtomicBool;

/// The state of one `alpha_expansion` call between its cycles.
pub(super) struct ExpansionRun<C: Cost> {
    pub(super) labels: Vec<i32>,
    pub(super) e: Energy<C>,
    pub(super) trace: Vec<C>,
    /// Accepted moves so far.
    pub(super) version: usize,
    /// Per label: the version at which its move last failed.
    pub(super) failed_at: Vec<usize>,
    pub(super) tried: usize,
}

/// What a caller inside the crate may know about an expansion's problem and so spare
/// the solver from working out again (see [`CrfSolver::expansion_with`]). Wrong hints
/// give a wrong labelling; each is checked in debug builds.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ExpansionHints<'a, C> {
    /// The per-label candidate sets the expansion starts from, computed by the caller
    /// (in parallel, where it computes the unary terms): for each block of 64 nodes
    /// `w` and label `a`, `candidates[w * l + a]` has bit `b` set where node `64w +
    /// b`'s [`potts_candidate_mask`] (of its unary row, its `init` label and its sum of
    /// edge weights in edge order) has bit `a` set. Used when the problem takes that
    /// form (Potts, nothing forbidden, at most 64 labels, pruning on, finite weight
    /// sums), else the sets are collected by the solver.
    pub candidates: Option<&'a [u64]>,
    /// E(init), as [`potts_energy`] gives it for this problem (bit for bit); used when
    /// nothing is forbidden.
    pub init_energy: Option<C>,
    /// The problem's edges and weights are, value for value, those of this solver's
    /// last expansion that returned `Ok` (an E-step's neighbourhood graph and weights
    /// stay the same across its frame's EM iterations): their checks, the edge
    /// comparison and the weight sums are not redone.
    pub same_structure: bool,
}

impl<C> Default for ExpansionHints<'_, C> {
    fn default() -> Self {
        ExpansionHints {
            candidates: None,
            init_energy: None,
            same_structure: false,
        }
    }
}

/// No work beside an expansion's cycles (for [`CrfSolver::expansion_with`]).
pub(crate) const NO_WORK_BESIDE: Option<&mut fn(&[i32], &AtomicBool)> = None;

/// Move-making solver for a fixed node set and edge list: the move graph is built once
/// and only its capacities are reset for each move; buffers are reused across calls
/// (the E-step calls it several times per frame on the same neighbourhood graph).
#[derive(Clone, Debug)]
pub struct CrfSolver<C: Cost> {
    pub(super) graph: Graph<C>,
    pub(super) edges: Vec<[u32; 2]>,
    /// Per-node move costs for "keep" (x = 0, source side) and "switch" (x = 1).
    pub(super) e0: Vec<C>,
    pub(super) e1: Vec<C>,
    /// Per node: the sum of its edges' weights, `None` on overflow (see
    /// `expansion_move`).
    pub(super) incident_weight: Vec<Option<C>>,
    /// Every `incident_weight` is finite (set with it).
    pub(super) weights_finite: bool,
    /// The edge weights `incident_weight` was summed from (none yet).
    pub(super) weights_of_sums: Option<Vec<C>>,
    /// Per node, in the current expansion move: may switch to α (not labelled α, not
    /// pruned). Only free nodes are in the cut. All false between moves.
    pub(super) is_free: Vec<bool>,
    /// Per label α, during one `alpha_expansion` call: a bit set of every node that
    /// could be free in α's move (a superset: each node that passed the pruning test for
    /// α at the start of the call or when it last switched label), so that a move visits
    /// these instead of every node. A bit set iterates in ascending node order and holds
    /// no duplicates for free; sorted lists cost a sort per move, which on dense
    /// problems (most nodes candidates for most labels) took longer than the full scan
    /// they replace.
    pub(super) candidates: Vec<BitSet>,
    /// The free nodes of the current move, ascending; then those that switched.
    pub(super) free: Vec<u32>,
    /// Node → incident edges (CSR, ascending edge index, self-loops left out).
    pub(super) adj_start: Vec<u32>,
    pub(super) adj: Vec<u32>,
    /// Edges and nodes given capacities since the graph was last cleared, and whether
    /// that list is complete (a swap move clears the whole graph instead).
    pub(super) touched_edges: Vec<u32>,
    pub(super) touched_nodes: Vec<u32>,
    pub(super) touched_valid: bool,
    /// Whether expansion moves leave provably fixed nodes out of the cut.
    pub(super) prune: bool,
    /// The labels a move proposes: equal to the labels it starts from except at the
    /// nodes it switches (and restored there when the move is rejected).
    pub(super) candidate: Vec<i32>,
}

// Node and label indices address several parallel arrays at once in these loops.
#[allow(clippy::needless_range_loop)]
impl<C: Cost> CrfSolver<C> {
    /// A solver for `n_nodes` nodes joined by `edges`.
    pub fn new(n_nodes: usize, edges: &[[u32; 2]]) -> Result<Self> {
        if let Some(k) = edges
            .iter()
            .position(|e| e[0] as usize >= n_nodes || e[1] as usize >= n_nodes)
        {
            return Err(Error::invalid(
                "edges",
                format!(
                    "edge {k} = {:?} has a node index out of range for {n_nodes} nodes",
                    edges[k]
                ),
            ));
        }
        let mut graph = Graph::with_capacity(n_nodes, edges.len());
        graph.keep_edge_index();
        for &[i, j] in edges {
            graph.add_edge(i as usize, j as usize, C::ZERO, C::ZERO)?;
        }
        graph.finalize();
        let mut adj_start = vec![0u32; n_nodes + 1];
        for &[i, j] in edges {
            if i != j {
                adj_start[i as usize + 1] += 1;
                adj_start[j as usize + 1] += 1;
            }
        }
        for i in 0..n_nodes {
            adj_start[i + 1] += adj_start[i];
        }
        let mut pos = adj_start.clone();
        let mut adj = vec![0u32; adj_start[n_nodes] as usize];
        for (k, &[i, j]) in edges.iter().enumerate() {
            if i != j {
                for x in [i as usize, j as usize] {
                    adj[pos[x] as usize] = k as u32;
                    pos[x] += 1;
                }
            }
        }
        Ok(CrfSolver {
            graph,
            edges: edges.to_vec(),
            e0: vec![C::ZERO; n_nodes],
            e1: vec![C::ZERO; n_nodes],
            incident_weight: vec![None; n_nodes],
            weights_finite: false,
            weights_of_sums: None,
            is_free: vec![false; n_nodes],
            candidates: Vec::new(),
            free: Vec::new(),
            adj_start,
            adj,
            touched_edges: Vec::new(),
            touched_nodes: Vec::new(),
            touched_valid: true,
            prune: true,
            candidate: vec![0; n_nodes],
        })
    }

    /// Turns on (the default) or off the exact pruning of expansion moves: a node whose
    /// switch to α costs more unary than all its edges could ever give back keeps its
    /// label in every optimal move, so it is left out of the cut. Off gives the plain
    /// construction (same move energies; only ties may resolve differently).
    pub fn set_pruning(&mut self, on: bool) {
        self.prune = on;
    }

    pub(super) fn check<'a>(
        &self,
        problem: &CrfProblem<'a, C>,
        metric: bool,
    ) -> Result<Checked<'a, C>> {
        self.check_hinted(problem, metric, false)
    }

    /// Whether to take [`ExpansionHints::same_structure`] (`hinted`) for `problem`: only
    /// where an expansion has summed its weights and the lengths agree.
    pub(super) fn structure_known(&self, problem: &CrfProblem<C>, hinted: bool) -> bool {
        hinted
            && self.weights_of_sums.is_some()
            && problem.edges.len() == self.edges.len()
            && problem.weights.len() == self.edges.len()
    }

    /// [`Self::check`], with the edges and weights not checked again where
    /// `same_structure` (from [`Self::structure_known`]).
    pub(super) fn check_hinted<'a>(
        &self,
        problem: &CrfProblem<'a, C>,
        metric: bool,
        same_structure: bool,
    ) -> Result<Checked<'a, C>> {
        debug_assert!(
            !same_structure
                || (problem.edges == self.edges.as_slice()
                    && self.weights_of_sums.as_deref() == Some(problem.weights)),
            "ExpansionHints::same_structure given for a different structure"
        );
        // The solver's own edges were checked against its node count when it was
        // built; equal edges and node count need no second range check.
        let same_edges = same_structure || problem.edges == self.edges.as_slice();
        let n = problem.unary.len() / problem.n_labels.max(1);
        let c = check_problem(
            problem,
            metric,
            same_edges && n == self.graph.n_nodes(),
            same_structure,
        )?;
        ensure(c.n == self.graph.n_nodes(), "unary", || {
            format!(
                "{} nodes, but the solver was built for {}",
                c.n,
                self.graph.n_nodes()
            )
        })?;
        ensure(same_edges, "edges", || {
            "differ from the edges the solver was built with".into()
        })?;
        Ok(c)
    }

    /// Alpha-expansion: for each label α in turn, every node may switch to α in one
    /// min-cut move; repeats until a cycle brings no improvement or `max_cycles`.
    pub fn alpha_expansion(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
    ) -> Result<Labelling<C>> {
        self.expansion_with(
            problem,
            init,
            config,
            ExpansionHints::default(),
            NO_WORK_BESIDE,
        )
        .map(|(labelling, _)| labelling)
    }

    /// [`Self::alpha_expansion`] with `beside` run on another worker of rayon's pool
    /// beside every cycle, for the labelling that cycle starts from. The expansion
    /// ends with a cycle that accepts no move, so the labelling that cycle starts from
    /// is usually the result: `beside` can start the work that needs the result
    /// before the last cycle has confirmed it (beside the first cycle, for the case
    /// that the starting labelling is already the result). Returns `beside`'s
    /// output for the cycle that ended the solve when it accepted no move (its
    /// labelling is then exactly the result's), else `None`. The flag passed to
    /// `beside` is raised as soon as its cycle accepts a move: its output will be
    /// dropped, and it may stop early. The labelling is the same as
    /// [`Self::alpha_expansion`]'s.
    pub fn alpha_expansion_beside<R, F>(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
        beside: &mut F,
    ) -> Result<(Labelling<C>, Option<R>)>
    where
        R: Send,
        F: FnMut(&[i32], &AtomicBool) -> R + Send,
    {
        self.expansion_with(
            problem,
            init,
            config,
            ExpansionHints::default(),
            Some(beside),
        )
    }

    /// [`Self::alpha_expansion`] (with `beside`, [`Self::alpha_expansion_beside`]),
    /// sparing the work `hints` make unneeded. Wrong hints give a wrong labelling,
    /// hence crate-only.
    pub(crate) fn expansion_with<R, F>(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
        hints: ExpansionHints<C>,
        mut beside: Option<&mut F>,
    ) -> Result<(Labelling<C>, Option<R>)>
    where
        R: Send,
        F: FnMut(&[i32], &AtomicBool) -> R + Send,
    {
        let same_structure = self.structure_known(problem, hints.same_structure);
        let c = self.check_hinted(problem, true, same_structure)?;
        let labels = c.check_init(init)?;
        self.prepare_expansion(&c, same_structure);
        match hints.candidates {
            Some(words)
                if self.masks_apply(&c)
                    && init.is_some()
                    && words.len() == c.n.div_ceil(64) * c.l =>
            {
                self.set_candidates(&c, words)
            }
            _ => self.collect_candidates(&c, &labels),
        }
        self.candidate.copy_from_slice(&labels);
        let e = match hints.init_energy {
            Some(sum) if c.big == C::ZERO => {
                debug_assert!(
                    c.energy(&labels).sum == sum,
                    "ExpansionHints::init_energy differs from the energy"
                );
                Energy { forbidden: 0, sum }
            }
            _ => c.energy(&labels),
        };
        let mut run = ExpansionRun {
            labels,
            e,
            trace: vec![e.value()],
            version: 0,
            failed_at: vec![usize::MAX; c.l],
            tried: 0,
        };
        let mut cycles = 0;
        let mut beside_output = None;
        // The labelling the work beside a cycle sees (a copy: the cycle changes its own).
        let mut seen = Vec::new();
        while cycles < config.max_cycles {
            cycles += 1;
            let improved = match beside.as_deref_mut() {
                Some(work) => {
                    seen.clone_from(&run.labels);
                    let accepted = AtomicBool::new(false);
                    let (improved, output) = rayon::join(
                        || self.expansion_cycle(&c, &mut run, Some(&accepted)),
                        || work(&seen, &accepted),
                    );
                    if !improved {
                        beside_output = Some(output);
                    }
                    improved
                }
                None => self.expansion_cycle(&c, &mut run, None),
            };
            if !improved {
                break;
            }
        }
        // The moves update the energy by differences; the result is summed afresh so
        // that it equals `energy(labels)` exactly (floats may differ in the last bits
        // from the running value, which the trace keeps). With no move accepted the
        // labels are the start's, whose energy was summed so.
        let energy = if run.version == 0 {
            run.e.value()
        } else {
            c.energy(&run.labels).value()
        };
        let labelling = Labelling {
            labels: run.labels,
            energy,
            trace: run.trace,
            cycles,
            moves_tried: run.tried,
        };
        Ok((labelling, beside_output))
    }
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
