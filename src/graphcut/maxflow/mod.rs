//! Boykov–Kolmogorov max-flow / min-cut ("An experimental comparison of min-cut/max-flow
//! algorithms for energy minimization in vision", PAMI 2004), written from the paper.
//!
//! Two search trees grow from the source (S) and the sink (T); when they touch, flow is
//! pushed along the path found (augmentation), saturated tree arcs turn their children
//! into orphans, and orphans look for a new parent in their own tree (adoption) using the
//! paper's distance / timestamp heuristic, or become free. The trees survive between
//! calls, so after changing terminal capacities [`Graph::maxflow`] resumes from the
//! residual graph (dynamic cuts, Kohli & Torr 2005).
//!
//! A fresh solve of a large graph whose edges join nearby node indices (a row-major
//! pixel grid) is split into bands of node indices solved on separate threads, then
//! finished by one search over the whole graph that starts from the bands' trees
//! ([`Graph::parallel_parts`]; Liu & Sun's bottom-up merging with a single merge).
//!
//! Layout (compact, see [`Graph`]): arcs are one array grouped by tail (CSR), built once
//! from the edge list (right away by a batch [`Graph::add_edges`] on an empty graph,
//! otherwise on the first solve), each a record of a packed `u32` head word and its
//! residual capacity; the reverse arc is found from the head's first arc (kept in the
//! head's node record) and a 4-bit hint.
//! Terminal arcs are folded into one signed residual per node (`> 0`: from the source,
//! `< 0`: to the sink). For a 4-connected grid with `f64` or `i64` capacities this takes
//! about 68.5 bytes per node (measured by [`Graph::memory_bytes`]).

mod build;
mod capacity;
mod graph;
mod grid;
mod layout;
mod parts;
mod queue;
mod search;
mod solve;
#[cfg(test)]
mod tests;

pub use capacity::Capacity;
pub use grid::grid_edges;
pub use layout::MAX_NODES;

use crate::graphcut::bitset::BitSet;
use layout::{ArcRec, Node};
use queue::ActiveQueue;
use std::collections::VecDeque;

/// A directed graph with two terminals, for max-flow / min-cut.
///
/// Build with [`Graph::add_edge`] / [`Graph::add_tweights`] (or their batch forms),
/// solve with [`Graph::maxflow`], read the cut with [`Graph::is_sink_side`]. After a
/// solve, terminal capacities may be changed ([`Graph::update_tweights`],
/// [`Graph::set_tweights`]) and `maxflow` called again: it reuses the residual graph
/// and the search trees.
///
/// Integer capacities (`Graph<i64>`) are exact: the graph keeps the sum of the
/// magnitudes of every capacity and every change given to it since the last
/// [`Graph::reset`], and refuses (with an error naming the argument, changing nothing) a
/// call that would take that sum past `i64::MAX`. Every residual, excess and flow value
/// the solver forms is bounded by that sum, so nothing can wrap.
///
/// Layout (per node 20 bytes plus 12 per arc for 8-byte capacities, see
/// [`Graph::memory_bytes`]): arcs are grouped by tail (CSR), each a 12-byte record of a
/// packed head word (`u32`: head node in the low 28 bits, sister hint in the top 4) and
/// its residual capacity. An arc's reverse ("sister") is the arc at
/// `head.first + hint`; the few arcs whose sister is the 15th or later arc of its node
/// keep it in a small overflow table. Nodes are 20-byte records (terminal residual,
/// parent word with the tree bit, packed time stamp and distance, first arc), plus one
/// record that ends the last node's arcs.
///
/// Integer capacities: the caller keeps the sum of every capacity added (and every
/// |change|) within the type's range; it bounds every flow and residual sum formed, and
/// beyond it they would wrap (the Python binding enforces this; `docs/design.md`).
#[derive(Clone, Debug)]
pub struct Graph<C: Capacity> {
    n: usize,
    /// Edges added since the last build: (i, j, cap i→j, cap j→i).
    pending: Vec<(u32, u32, C, C)>,
    /// Arcs: packed head word and residual capacity.
    arcs: Vec<ArcRec<C>>,
    /// (arc, sister) for arcs with the hint `HINT_OVERFLOW`, sorted by arc.
    overflow: Vec<(u32, u32)>,
    /// Arc i→j of edge `k` (in order of addition), `NO_ARC` for self-loops; kept only
    /// after [`Graph::keep_edge_index`] (4 bytes per edge).
    edge_arc: Vec<u32>,
    index_edges: bool,
    /// Edges in the built arc arrays (including self-loops, which have no arcs).
    n_edges: usize,
    nodes: Vec<Node<C>>,
    /// Nodes whose terminal capacities changed since the last solve (and their bits).
    changed: Vec<u32>,
    changed_bits: BitSet,
    /// Accumulated terminal capacities per node, kept only for `set_tweights`.
    terminal_caps: Option<Vec<[C; 2]>>,
    /// Exact (integer) types: the sum of the magnitudes of every capacity and every
    /// change given to the public methods since the last [`Graph::reset`]. Every
    /// residual, node excess and the flow stay within it, so keeping it within the
    /// type's range rules out wrapping. Unused (0) for floats.
    exact_total: u128,
    flow: C,
    time: u32,
    /// The clock restarts after this many ticks (`MAX_TIME` outside tests).
    max_time: u32,
    active: ActiveQueue,
    orphans: VecDeque<u32>,
    /// True once `maxflow` ran and the trees describe the residual graph.
    trees_valid: bool,
    /// Every node is free with a zero time stamp and distance (the state a fresh solve
    /// gives a node without a terminal arc), so [`Graph::maxflow_seeded`] need visit
    /// only the nodes with terminal capacity.
    clean: bool,
    /// Every node that is not free was put in a search tree by a solve since the last
    /// reset (and so is an end of an edge or a node with capacity since then):
    /// [`Graph::reset_touched`] then leaves the graph clean.
    bounded: bool,
    /// The largest index difference of an edge's two ends (the width of a row-major
    /// grid), set by the build; it decides whether a fresh solve is split into parts.
    bandwidth: u32,
    /// Most threads a fresh solve may use (0: all of the rayon pool's).
    max_threads: usize,
    /// Tests: the number of parts for every fresh solve, whatever the graph's size.
    #[cfg(test)]
    parts_override: Option<usize>,
}
