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

use super::bitset::BitSet;
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Neg, Sub, SubAssign};

/// A capacity type: `f64` or `i64` (integers give exact answers).
pub trait Capacity:
    Copy
    + PartialOrd
    + Debug
    + Default
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    /// Zero.
    const ZERO: Self;
    /// Integers: sums are exact but wrap past the type's range, so callers bound them
    /// (floats round instead, and overflow only to a non-finite value).
    const EXACT: bool;
    /// Exact types: the largest sum of magnitudes a graph may hold (the type's maximum).
    const EXACT_LIMIT: u128;
    /// True for a usable capacity or cost: finite (floats) and not NaN.
    fn is_finite_value(self) -> bool;
    /// Lossy conversion for reporting.
    fn to_f64(self) -> f64;
    /// Conversion from a count or small constant.
    fn from_i32(v: i32) -> Self;
    /// Addition that reports overflow (integers) or a non-finite result (floats).
    fn checked_add(self, other: Self) -> Option<Self>;
    /// Multiplication that reports overflow (integers) or a non-finite result (floats).
    fn checked_mul(self, other: Self) -> Option<Self>;
    /// |self| as a wide integer for the overflow budget of exact types (0 for floats).
    fn exact_magnitude(self) -> u128;
    /// The smaller of two values.
    #[inline(always)]
    fn min_of(self, other: Self) -> Self {
        if other < self {
            other
        } else {
            self
        }
    }
}

impl Capacity for f64 {
    const ZERO: Self = 0.0;
    const EXACT: bool = false;
    const EXACT_LIMIT: u128 = u128::MAX;
    #[inline(always)]
    fn is_finite_value(self) -> bool {
        self.is_finite()
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn from_i32(v: i32) -> Self {
        v as f64
    }
    fn checked_add(self, other: Self) -> Option<Self> {
        let s = self + other;
        s.is_finite().then_some(s)
    }
    fn checked_mul(self, other: Self) -> Option<Self> {
        let s = self * other;
        s.is_finite().then_some(s)
    }
    fn exact_magnitude(self) -> u128 {
        0
    }
}

impl Capacity for i64 {
    const ZERO: Self = 0;
    const EXACT: bool = true;
    const EXACT_LIMIT: u128 = i64::MAX as u128;
    #[inline(always)]
    fn is_finite_value(self) -> bool {
        true
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_i32(v: i32) -> Self {
        v as i64
    }
    fn checked_add(self, other: Self) -> Option<Self> {
        i64::checked_add(self, other)
    }
    fn checked_mul(self, other: Self) -> Option<Self> {
        i64::checked_mul(self, other)
    }
    fn exact_magnitude(self) -> u128 {
        self.unsigned_abs() as u128
    }
}

/// Bits of a packed arc head word that hold the head node; the top four bits hold the
/// sister hint (see [`Graph`]'s layout notes).
const HEAD_BITS: u32 = 28;
const HEAD_MASK: u32 = (1 << HEAD_BITS) - 1;
/// Sister hint meaning "look the sister up in the overflow table".
const HINT_OVERFLOW: u32 = 15;
/// Largest number of nodes (node indices must fit the 28 head bits).
pub const MAX_NODES: usize = HEAD_MASK as usize;
/// Largest number of arcs (arc indices must stay below the parent markers).
const MAX_ARCS: usize = 0x7FFF_FFF0;

/// Parent words: an arc index (towards the parent) or a marker, with the tree in bit 31
/// (set = sink tree). A free node has exactly `FREE` (bit 31 clear).
const SINK_BIT: u32 = 1 << 31;
const FREE: u32 = 0x7FFF_FFFF;
const TERMINAL: u32 = 0x7FFF_FFFE;
const ORPHAN: u32 = 0x7FFF_FFFD;
/// Marks an edge of the edge index that is a self-loop (no arcs).
const NO_ARC: u32 = u32::MAX;
/// Distance meaning "not connected to a terminal" during adoption.
const INFINITE_DIST: u32 = u32::MAX;
/// Time stamps live in the upper 16 bits of a node's `tsd` word; on overflow all stamps
/// are cleared and the clock restarts (once every 65,535 augmentations).
const MAX_TIME: u32 = 0xFFFF;

/// One arc: its packed head word and its residual capacity side by side, so that the
/// scans reading both touch one cache line. Packed to 4-byte alignment: 12 bytes for
/// 8-byte capacities (x86-64 and aarch64 read unaligned words at full speed).
#[derive(Clone, Copy)]
#[repr(C, packed(4))]
struct ArcRec<C> {
    /// Head node (low `HEAD_BITS`) and sister hint (high bits).
    hw: u32,
    /// Residual capacity.
    cap: C,
}

impl<C: Copy + Debug> Debug for ArcRec<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (hw, cap) = (self.hw, self.cap);
        f.debug_struct("ArcRec")
            .field("hw", &hw)
            .field("cap", &cap)
            .finish()
    }
}

impl<C: Copy> ArcRec<C> {
    /// The residual capacity (by value: a packed field cannot be borrowed).
    #[inline(always)]
    fn cap(&self) -> C {
        self.cap
    }
}

/// A node: its first arc and search state, 20 bytes for 8-byte capacities (packed to
/// 4-byte alignment). The first arc sits with the state because finding an arc's
/// reverse needs the head's first arc right when the head's state is read.
#[derive(Clone, Copy, Debug)]
#[repr(C, packed(4))]
struct Node<C> {
    /// Residual terminal capacity: `> 0` from the source, `< 0` to the sink.
    tr: C,
    /// Parent word (arc to the parent in the search tree, or a marker; bit 31 = tree).
    parent: u32,
    /// Time stamp (high 16 bits) and distance to the terminal (low 16 bits) of the
    /// adoption heuristic. The distance saturates at `u16::MAX`: it only steers
    /// heuristics, the adoption walk never relies on exact values for correctness.
    tsd: u32,
    /// CSR: the arcs of node `i` are `nodes[i].first..nodes[i + 1].first`.
    first: u32,
}

impl<C: Capacity> Default for Node<C> {
    fn default() -> Self {
        Node {
            tr: C::ZERO,
            parent: FREE,
            tsd: 0,
            first: 0,
        }
    }
}

#[inline(always)]
fn pack_tsd(ts: u32, dist: u32) -> u32 {
    (ts << 16) | dist.min(0xFFFF)
}

#[inline(always)]
fn ts_of(tsd: u32) -> u32 {
    tsd >> 16
}

#[inline(always)]
fn dist_of(tsd: u32) -> u32 {
    tsd & 0xFFFF
}

/// True if parent word `p` is an arc (not free, terminal or orphan).
#[inline(always)]
fn is_arc(p: u32) -> bool {
    (p & !SINK_BIT) < ORPHAN
}

/// Reverse arc of arc `a` whose packed head word is `hw`: the head's first arc plus the
/// hint, or the overflow table (sorted by arc) when the hint does not fit.
#[inline(always)]
fn sister_of<C: Copy>(nodes: &[Node<C>], overflow: &[(u32, u32)], a: usize, hw: u32) -> usize {
    sister_at(nodes[(hw & HEAD_MASK) as usize].first, overflow, a, hw)
}

/// [`sister_of`] given the head's first arc (read by the caller with the head's record).
#[inline(always)]
fn sister_at(head_first: u32, overflow: &[(u32, u32)], a: usize, hw: u32) -> usize {
    let h = hw >> HEAD_BITS;
    if h != HINT_OVERFLOW {
        head_first as usize + h as usize
    } else {
        let k = overflow.partition_point(|&(x, _)| (x as usize) < a);
        overflow[k].1 as usize
    }
}

/// The FIFO of active nodes. A fresh solve activates every node with a terminal arc at
/// once; instead of queueing them all (4 bytes per node), a cursor sweeps the nodes in
/// index order and takes those marked `initial`, before the ring of nodes activated
/// later. A node activated while the sweep is still before it is marked for the sweep
/// too, not put in the ring: when the short-path pass leaves few roots, the trees grow
/// over most of the graph during the sweep, and a ring holding all those nodes cost up
/// to 3 bytes per node more. Otherwise the order is a FIFO's.
#[derive(Clone, Debug, Default)]
struct ActiveQueue {
    sweep: usize,
    n: usize,
    initial: BitSet,
    queued: BitSet,
    ring: VecDeque<u32>,
}

impl ActiveQueue {
    fn new(n: usize) -> Self {
        ActiveQueue {
            sweep: n,
            n,
            initial: BitSet::new(n),
            queued: BitSet::new(n),
            ring: VecDeque::new(),
        }
    }

    /// Empties the queue.
    fn clear(&mut self) {
        if self.sweep < self.n {
            self.initial.clear_all();
        }
        self.sweep = self.n;
        while let Some(i) = self.ring.pop_front() {
            self.queued.clear(i as usize);
        }
    }

    /// Marks `i` as active from the start of a fresh solve (call in index order, after
    /// `clear`, then `start_sweep`).
    #[inline(always)]
    fn mark_initial(&mut self, i: usize) {
        self.initial.set(i);
    }

    fn start_sweep(&mut self) {
        self.sweep = 0;
    }

    #[inline(always)]
    fn push(&mut self, i: u32) {
        let iu = i as usize;
        if self.queued.get(iu) {
            return;
        }
        if iu >= self.sweep {
            // Still ahead of the sweep: it takes the node on its way.
            self.initial.set(iu);
            return;
        }
        self.queued.set(iu);
        self.ring.push_back(i);
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<u32> {
        while self.sweep < self.n {
            let w = self.initial.word(self.sweep >> 6) >> (self.sweep & 63);
            if w == 0 {
                self.sweep = (self.sweep | 63) + 1;
                continue;
            }
            let i = self.sweep + w.trailing_zeros() as usize;
            if i >= self.n {
                break;
            }
            self.initial.clear(i);
            self.sweep = i + 1;
            return Some(i as u32);
        }
        self.sweep = self.n;
        let i = self.ring.pop_front()?;
        self.queued.clear(i as usize);
        Some(i)
    }

    fn bytes(&self) -> usize {
        self.initial.bytes() + self.queued.bytes() + self.ring.capacity() * 4
    }
}

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
/// beyond it they would wrap (the Python binding enforces this; `docs/graphcut.md`).
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

impl<C: Capacity> Graph<C> {
    /// A graph of `n_nodes` nodes and no edges.
    pub fn new(n_nodes: usize) -> Self {
        Self::with_capacity(n_nodes, 0)
    }

    /// Like [`Graph::new`], reserving room for `edge_hint` edges.
    pub fn with_capacity(n_nodes: usize, edge_hint: usize) -> Self {
        match Self::try_with_capacity(n_nodes.min(MAX_NODES), edge_hint) {
            Ok(g) => g,
            Err(e) => panic!("{e}"),
        }
    }

    /// Like [`Graph::with_capacity`], but fails (instead of aborting) when `n_nodes`
    /// exceeds [`MAX_NODES`] or the memory cannot be had.
    pub fn try_with_capacity(n_nodes: usize, edge_hint: usize) -> Result<Self> {
        if n_nodes > MAX_NODES {
            return Err(Error::invalid(
                "n_nodes",
                format!("{n_nodes} nodes exceed the maximum of {MAX_NODES}"),
            ));
        }
        let oom = |what: &str| Error::invalid(what, "not enough memory for the requested size");
        let mut pending = Vec::new();
        pending
            .try_reserve_exact(edge_hint.min(MAX_ARCS / 2))
            .map_err(|_| oom("edge_hint"))?;
        // One record more than nodes: its `first` ends the last node's arcs.
        let mut nodes = Vec::new();
        nodes
            .try_reserve_exact(n_nodes + 1)
            .map_err(|_| oom("n_nodes"))?;
        nodes.resize(n_nodes + 1, Node::default());
        Ok(Graph {
            n: n_nodes,
            pending,
            arcs: Vec::new(),
            overflow: Vec::new(),
            edge_arc: Vec::new(),
            index_edges: false,
            n_edges: 0,
            nodes,
            changed: Vec::new(),
            changed_bits: BitSet::new(n_nodes),
            terminal_caps: None,
            exact_total: 0,
            flow: C::ZERO,
            time: 0,
            max_time: MAX_TIME,
            active: ActiveQueue::new(n_nodes),
            orphans: VecDeque::new(),
            trees_valid: false,
            clean: true,
            bounded: true,
            bandwidth: 0,
            max_threads: 0,
            #[cfg(test)]
            parts_override: None,
        })
    }

    /// Keeps each node's accumulated terminal capacities so that [`Graph::set_tweights`]
    /// can replace them later (costs two capacities per node). Call before adding any.
    pub fn track_terminal_caps(&mut self) {
        if self.terminal_caps.is_none() {
            self.terminal_caps = Some(vec![[C::ZERO; 2]; self.n]);
        }
    }

    /// Keeps the arc of every edge so that edges can be addressed by index later
    /// ([`Graph::set_edge_caps`], [`Graph::edge_residual`]). Call before the first solve.
    pub fn keep_edge_index(&mut self) {
        self.index_edges = true;
    }

    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.n
    }

    /// Number of edges added (including self-loops, which never matter to a cut).
    pub fn n_edges(&self) -> usize {
        self.n_edges + self.pending.len()
    }

    /// The flow value of the last [`Graph::maxflow`] (plus capacity pushed directly
    /// from source to sink through single nodes).
    pub fn flow(&self) -> C {
        self.flow
    }

    /// Heap bytes held by the graph: the arc records (packed head word and residual
    /// capacity), the sister overflow table, the node records (with the CSR offsets), the
    /// active-queue bits and ring, the orphan queue, the changed-node list and bits, and
    /// the optional edge index, terminal capacities and not yet built edges. Computed
    /// from the allocated capacities of these arrays, not from a formula.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.arcs.capacity() * size_of::<ArcRec<C>>()
            + self.overflow.capacity() * 8
            + self.edge_arc.capacity() * 4
            + self.pending.capacity() * size_of::<(u32, u32, C, C)>()
            + self.nodes.capacity() * size_of::<Node<C>>()
            + self.changed.capacity() * 4
            + self.changed_bits.bytes()
            + self
                .terminal_caps
                .as_ref()
                .map_or(0, |t| t.capacity() * 2 * size_of::<C>())
            + self.active.bytes()
            + self.orphans.capacity() * 4
    }

    fn check_node(&self, i: usize, name: &str) -> Result<()> {
        if i < self.n {
            Ok(())
        } else {
            Err(Error::invalid(
                name,
                format!(
                    "node index {i} out of range for a graph of {} nodes",
                    self.n
                ),
            ))
        }
    }

    fn check_cap(c: C, name: &str) -> Result<()> {
        if c.is_finite_value() && c >= C::ZERO {
            Ok(())
        } else {
            Err(Error::invalid(
                name,
                format!("capacities must be finite and non-negative, got {c:?}"),
            ))
        }
    }

    /// Batch arguments: every array in `others` has the length of `first` (named
    /// `first_name`), every index array names nodes of the graph.
    fn check_batch(
        &self,
        (first_name, first): (&str, &[u32]),
        others: &[(&str, usize)],
        more_indices: &[(&str, &[u32])],
    ) -> Result<()> {
        let m = first.len();
        if let Some(&(name, len)) = others.iter().find(|&&(_, len)| len != m) {
            return Err(Error::invalid(
                name,
                format!("length {len} does not match {first_name} length {m}"),
            ));
        }
        for &(name, idx) in std::iter::once(&(first_name, first)).chain(more_indices) {
            if let Some(k) = idx.iter().position(|&v| v as usize >= self.n) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "node index {} at position {k} out of range for {} nodes",
                        idx[k], self.n
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Batch values: finite everywhere, and non-negative if they are capacities (not
    /// changes).
    fn check_values(arrays: &[(&str, &[C])], capacities: bool) -> Result<()> {
        for &(name, c) in arrays {
            let bad = |v: &C| !v.is_finite_value() || capacities && *v < C::ZERO;
            if let Some(k) = c.iter().position(bad) {
                let what = if capacities {
                    "capacities must be finite and non-negative"
                } else {
                    "must be finite"
                };
                return Err(Error::invalid(
                    name,
                    format!("{what}, got {:?} at position {k}", c[k]),
                ));
            }
        }
        Ok(())
    }

    /// Exact types: `exact_total` after adding the magnitudes of `values`, refused
    /// (naming `name`) beyond the type's range. Callers validate everything else first
    /// and store the result only when they go ahead, so a refused call changes nothing.
    fn charged(&self, name: &str, values: impl Iterator<Item = C>) -> Result<u128> {
        if !C::EXACT {
            return Ok(0);
        }
        let total = values.fold(self.exact_total, |t, v| {
            t.saturating_add(v.exact_magnitude())
        });
        if total > C::EXACT_LIMIT {
            return Err(Error::invalid(
                name,
                format!(
                    "integer capacities would add up to {total}, beyond {} (the largest \
                     value of the capacity type), so the flow could overflow; use smaller \
                     units or float capacities",
                    C::EXACT_LIMIT
                ),
            ));
        }
        Ok(total)
    }

    /// Adds an edge with capacity `cap` from `i` to `j` and `rev_cap` from `j` to `i`.
    /// Parallel edges add up; self-loops are ignored. Returns the edge's index.
    pub fn add_edge(&mut self, i: usize, j: usize, cap: C, rev_cap: C) -> Result<usize> {
        self.check_node(i, "i")?;
        self.check_node(j, "j")?;
        Self::check_cap(cap, "cap")?;
        Self::check_cap(rev_cap, "rev_cap")?;
        if self.n_edges() >= MAX_ARCS / 2 {
            return Err(Error::invalid(
                "edges",
                "too many edges for u32 arc indices",
            ));
        }
        self.exact_total = self.charged("cap", [cap, rev_cap].into_iter())?;
        self.pending.push((i as u32, j as u32, cap, rev_cap));
        Ok(self.n_edges() - 1)
    }

    /// Adds many edges at once (all arrays of one length); nothing is added on error.
    /// On a graph without edges the arc arrays are built right away from the arrays.
    pub fn add_edges(&mut self, src: &[u32], dst: &[u32], cap: &[C], rev_cap: &[C]) -> Result<()> {
        let m = src.len();
        self.check_batch(
            ("src", src),
            &[
                ("dst", dst.len()),
                ("cap", cap.len()),
                ("rev_cap", rev_cap.len()),
            ],
            &[("dst", dst)],
        )?;
        Self::check_values(&[("cap", cap), ("rev_cap", rev_cap)], true)?;
        if self.n_edges() + m > MAX_ARCS / 2 {
            return Err(Error::invalid("src", "too many edges for u32 arc indices"));
        }
        self.exact_total = self.charged("cap", cap.iter().chain(rev_cap).copied())?;
        if self.n_edges() == 0 && !self.trees_valid {
            self.pending = Vec::new();
            self.build_from(m, |k| (src[k], dst[k], cap[k], rev_cap[k]));
            return Ok(());
        }
        self.pending.reserve(m);
        for k in 0..m {
            self.pending.push((src[k], dst[k], cap[k], rev_cap[k]));
        }
        Ok(())
    }

    /// Adds `source_cap` to the arc source→i and `sink_cap` to i→sink (both ≥ 0).
    /// After a solve, use [`Graph::update_tweights`] for changes that may decrease.
    pub fn add_tweights(&mut self, i: usize, source_cap: C, sink_cap: C) -> Result<()> {
        self.check_node(i, "i")?;
        Self::check_cap(source_cap, "source_cap")?;
        Self::check_cap(sink_cap, "sink_cap")?;
        self.exact_total = self.charged("source_cap", [source_cap, sink_cap].into_iter())?;
        self.update_tweights_unchecked(i, source_cap, sink_cap);
        Ok(())
    }

    /// Adds terminal capacities to many nodes (arrays of one length).
    pub fn add_tweights_batch(
        &mut self,
        nodes: &[u32],
        source_cap: &[C],
        sink_cap: &[C],
    ) -> Result<()> {
        self.check_batch(
            ("nodes", nodes),
            &[
                ("source_cap", source_cap.len()),
                ("sink_cap", sink_cap.len()),
            ],
            &[],
        )?;
        Self::check_values(&[("source_cap", source_cap), ("sink_cap", sink_cap)], true)?;
        self.exact_total =
            self.charged("source_cap", source_cap.iter().chain(sink_cap).copied())?;
        for k in 0..nodes.len() {
            self.update_tweights_unchecked(nodes[k] as usize, source_cap[k], sink_cap[k]);
        }
        Ok(())
    }

    /// Changes the terminal capacities of `i` by `delta_source` and `delta_sink` (either
    /// may be negative, as long as the resulting capacities stay ≥ 0; this is not checked
    /// unless capacities are tracked). Works before and after a solve; a later
    /// [`Graph::maxflow`] reuses the previous search trees.
    pub fn update_tweights(&mut self, i: usize, delta_source: C, delta_sink: C) -> Result<()> {
        self.check_node(i, "i")?;
        for (name, d) in [("delta_source", delta_source), ("delta_sink", delta_sink)] {
            if !d.is_finite_value() {
                return Err(Error::invalid(name, format!("must be finite, got {d:?}")));
            }
        }
        // Charged first: within the budget, the sums below cannot overflow.
        let total = self.charged("delta_source", [delta_source, delta_sink].into_iter())?;
        if let Some(t) = &self.terminal_caps {
            let [s, k] = t[i];
            if s + delta_source < C::ZERO || k + delta_sink < C::ZERO {
                return Err(Error::invalid(
                    "delta_source",
                    "the change would make a terminal capacity negative",
                ));
            }
        }
        self.exact_total = total;
        self.update_tweights_unchecked(i, delta_source, delta_sink);
        Ok(())
    }

    /// [`Graph::update_tweights`] for many nodes (arrays of one length; a node may
    /// appear more than once, its changes add up). All or nothing: every change is
    /// checked before any is applied.
    pub fn update_tweights_batch(
        &mut self,
        nodes: &[u32],
        delta_source: &[C],
        delta_sink: &[C],
    ) -> Result<()> {
        let m = nodes.len();
        self.check_batch(
            ("nodes", nodes),
            &[
                ("delta_source", delta_source.len()),
                ("delta_sink", delta_sink.len()),
            ],
            &[],
        )?;
        Self::check_values(
            &[("delta_source", delta_source), ("delta_sink", delta_sink)],
            false,
        )?;
        // Charged first: within the budget, the running sums below cannot overflow.
        let total = self.charged(
            "delta_source",
            delta_source.iter().chain(delta_sink).copied(),
        )?;
        if let Some(t) = &self.terminal_caps {
            // Running capacities of the nodes named, so repeated nodes are checked on
            // their sum.
            let mut after: std::collections::HashMap<u32, [C; 2]> = Default::default();
            for k in 0..m {
                let caps = after.entry(nodes[k]).or_insert(t[nodes[k] as usize]);
                caps[0] += delta_source[k];
                caps[1] += delta_sink[k];
                if caps[0] < C::ZERO || caps[1] < C::ZERO {
                    return Err(Error::invalid(
                        "delta_source",
                        format!(
                            "the change at position {k} would make a terminal capacity negative"
                        ),
                    ));
                }
            }
        }
        self.exact_total = total;
        for k in 0..m {
            self.update_tweights_unchecked(nodes[k] as usize, delta_source[k], delta_sink[k]);
        }
        Ok(())
    }

    /// Replaces the terminal capacities of `i` (needs [`Graph::track_terminal_caps`]).
    pub fn set_tweights(&mut self, i: usize, source_cap: C, sink_cap: C) -> Result<()> {
        self.check_node(i, "i")?;
        Self::check_cap(source_cap, "source_cap")?;
        Self::check_cap(sink_cap, "sink_cap")?;
        let Some(t) = &self.terminal_caps else {
            return Err(Error::invalid(
                "set_tweights",
                "call track_terminal_caps() before adding terminal capacities",
            ));
        };
        let [s, k] = t[i];
        // Both sides are ≥ 0, so the differences cannot overflow.
        let (ds, dk) = (source_cap - s, sink_cap - k);
        self.exact_total = self.charged("source_cap", [ds, dk].into_iter())?;
        self.update_tweights_unchecked(i, ds, dk);
        Ok(())
    }

    /// Folds a change of both terminal capacities into the node's signed residual.
    /// With `rs`, `rt` the residual source / sink capacities after the change, the common
    /// part `min(rs, rt)` is either pushed straight through (positive) or, if negative, a
    /// reparametrisation that adds the same amount to both terminal arcs, which shifts
    /// every cut by that amount (Kohli & Torr): in both cases it goes into the flow.
    #[inline]
    pub(crate) fn update_tweights_unchecked(&mut self, i: usize, d_source: C, d_sink: C) {
        if let Some(t) = &mut self.terminal_caps {
            t[i][0] += d_source;
            t[i][1] += d_sink;
        }
        let tr = self.nodes[i].tr;
        let (mut rs, mut rt) = if tr > C::ZERO {
            (tr, C::ZERO)
        } else {
            (C::ZERO, -tr)
        };
        rs += d_source;
        rt += d_sink;
        self.flow += rs.min_of(rt);
        self.nodes[i].tr = rs - rt;
        if self.trees_valid && !self.changed_bits.get(i) {
            self.changed_bits.set(i);
            self.changed.push(i as u32);
        }
    }

    /// The reverse arc of arc `a`.
    #[inline(always)]
    fn sister(&self, a: usize) -> usize {
        sister_of(&self.nodes, &self.overflow, a, self.arcs[a].hw)
    }

    /// Builds the CSR arc arrays from all edges (keeping residuals of existing arcs).
    fn build(&mut self) {
        let mut edges: Vec<(u32, u32, C, C)> = Vec::with_capacity(self.n_edges());
        if self.index_edges {
            for &a in &self.edge_arc {
                if a == NO_ARC {
                    edges.push((0, 0, C::ZERO, C::ZERO));
                    continue;
                }
                let a = a as usize;
                let s = self.sister(a);
                let head = |x: usize| self.arcs[x].hw & HEAD_MASK;
                edges.push((head(s), head(a), self.arcs[a].cap(), self.arcs[s].cap()));
            }
        } else {
            // Without an index, recover each built edge from its lower-numbered arc.
            for i in 0..self.n {
                for a in self.nodes[i].first as usize..self.nodes[i + 1].first as usize {
                    let s = self.sister(a);
                    if a < s {
                        let j = self.arcs[a].hw & HEAD_MASK;
                        edges.push((i as u32, j, self.arcs[a].cap(), self.arcs[s].cap()));
                    }
                }
            }
        }
        edges.append(&mut self.pending);
        self.pending = Vec::new();
        self.build_from(edges.len(), |k| edges[k]);
    }

    /// Builds the CSR arc arrays from `m` edges given by `edge(k)`.
    fn build_from(&mut self, m: usize, edge: impl Fn(usize) -> (u32, u32, C, C)) {
        let n = self.n;
        let mut first = vec![0u32; n + 1];
        for k in 0..m {
            let (i, j, _, _) = edge(k);
            if i != j {
                first[i as usize] += 1;
                first[j as usize] += 1;
            }
        }
        let mut acc = 0u32;
        for f in first.iter_mut() {
            let d = *f;
            *f = acc;
            acc += d;
        }
        // Each node's arcs are filled from the end, so the most recently added edge is
        // scanned first (like the linked arc lists of the reference implementation; the
        // scan order shapes the search trees and measurably affects speed on grids).
        let mut pos: Vec<u32> = first[1..].to_vec();
        let n_arcs = acc as usize;
        let mut arcs = vec![
            ArcRec {
                hw: 0,
                cap: C::ZERO
            };
            n_arcs
        ];
        let mut overflow = Vec::new();
        let keep = self.index_edges;
        let mut edge_arc = Vec::with_capacity(if keep { m } else { 0 });
        // The head word of arc `x` into `head`, whose reverse is arc `y` of `head`'s list.
        let link = |x: u32, y: u32, head: u32, overflow: &mut Vec<(u32, u32)>| {
            let rank = y - first[head as usize];
            let hint = if rank < HINT_OVERFLOW {
                rank
            } else {
                overflow.push((x, y));
                HINT_OVERFLOW
            };
            head | (hint << HEAD_BITS)
        };
        let mut bandwidth = 0u32;
        for k in 0..m {
            let (i, j, c, r) = edge(k);
            bandwidth = bandwidth.max(i.abs_diff(j));
            if i == j {
                if keep {
                    edge_arc.push(NO_ARC);
                }
                continue;
            }
            pos[i as usize] -= 1;
            let a = pos[i as usize];
            pos[j as usize] -= 1;
            let b = pos[j as usize];
            arcs[a as usize] = ArcRec {
                hw: link(a, b, j, &mut overflow),
                cap: c,
            };
            arcs[b as usize] = ArcRec {
                hw: link(b, a, i, &mut overflow),
                cap: r,
            };
            if keep {
                edge_arc.push(a);
            }
        }
        overflow.sort_unstable();
        overflow.shrink_to_fit();
        self.n_edges = m;
        self.bandwidth = bandwidth;
        for (v, &f) in self.nodes.iter_mut().zip(&first) {
            v.first = f;
        }
        self.arcs = arcs;
        self.overflow = overflow;
        self.edge_arc = edge_arc;
        self.trees_valid = false;
    }

    fn needs_build(&self) -> bool {
        !self.pending.is_empty() || self.index_edges && self.edge_arc.len() != self.n_edges
    }

    /// Builds the arc arrays now (otherwise done by the first [`Graph::maxflow`]), so
    /// that [`Graph::set_edge_caps`] can be used.
    pub fn finalize(&mut self) {
        if self.needs_build() {
            self.build();
        }
    }

    /// Clears all flow, capacities and search trees, keeping the structure (for reuse
    /// with new capacities: [`Graph::set_edge_caps`], [`Graph::add_tweights`]).
    pub fn reset(&mut self) {
        self.finalize();
        for arc in &mut self.arcs {
            arc.cap = C::ZERO;
        }
        for v in &mut self.nodes {
            v.tr = C::ZERO;
        }
        if let Some(t) = &mut self.terminal_caps {
            t.fill([C::ZERO; 2]);
        }
        self.exact_total = 0;
        // Search states of earlier solves stay where they were, at nodes no later
        // `reset_touched` list needs to name.
        self.bounded = self.clean;
        self.forget_solve();
    }

    /// The part of a reset shared by [`Graph::reset`] and [`Graph::reset_touched`]:
    /// no pending terminal changes, no flow, no search trees.
    fn forget_solve(&mut self) {
        for &i in &self.changed {
            self.changed_bits.clear(i as usize);
        }
        self.changed.clear();
        self.flow = C::ZERO;
        self.trees_valid = false;
    }

    /// [`Graph::reset`] for a graph whose only capacities since the last reset were
    /// set on `edges` (through [`Graph::set_edge_caps_unchecked`]) and `nodes` (terminal
    /// capacities): clears just those. Flow moves only along arcs with a residual and
    /// changes only the terminal residuals of path ends, so nothing else can be non-zero.
    /// Needs the edge index ([`Graph::keep_edge_index`]).
    pub(crate) fn reset_touched(&mut self, edges: &[u32], nodes: &[u32]) {
        self.finalize();
        for &k in edges {
            self.set_edge_caps_unchecked(k as usize, C::ZERO, C::ZERO);
            // A solve can put a node in a tree only through a terminal arc or an arc
            // with capacity, so these ends and `nodes` hold every non-free state.
            let a = self.edge_arc[k as usize];
            if a != NO_ARC {
                let a = a as usize;
                let s = self.sister(a);
                for x in [self.arcs[a].hw & HEAD_MASK, self.arcs[s].hw & HEAD_MASK] {
                    self.free_node(x as usize);
                }
            }
        }
        for &i in nodes {
            self.nodes[i as usize].tr = C::ZERO;
            self.free_node(i as usize);
            if let Some(t) = &mut self.terminal_caps {
                t[i as usize] = [C::ZERO; 2];
            }
        }
        self.clean = self.bounded;
        self.forget_solve();
    }

    #[inline(always)]
    fn free_node(&mut self, i: usize) {
        let v = &mut self.nodes[i];
        v.parent = FREE;
        v.tsd = 0;
    }

    /// Sets the capacities of edge `k` (its index from [`Graph::add_edge`] or the order of
    /// the batch), for a graph that was [`Graph::reset`] or finalized and not yet solved.
    pub(crate) fn set_edge_caps_unchecked(&mut self, k: usize, cap: C, rev_cap: C) {
        let a = self.edge_arc[k];
        if a != NO_ARC {
            let a = a as usize;
            self.arcs[a].cap = cap;
            let s = self.sister(a);
            self.arcs[s].cap = rev_cap;
        }
    }

    /// Sets the capacities of edge `k` after [`Graph::reset`] (before any solve).
    pub fn set_edge_caps(&mut self, k: usize, cap: C, rev_cap: C) -> Result<()> {
        if !self.index_edges {
            return Err(Error::invalid(
                "k",
                "edges are not indexed; call keep_edge_index() before building",
            ));
        }
        self.finalize();
        if k >= self.n_edges {
            return Err(Error::invalid(
                "k",
                format!("edge index {k} out of range for {} edges", self.n_edges),
            ));
        }
        if self.trees_valid {
            return Err(Error::invalid(
                "k",
                "edge capacities can only be set after reset(), not on a solved graph",
            ));
        }
        Self::check_cap(cap, "cap")?;
        Self::check_cap(rev_cap, "rev_cap")?;
        self.exact_total = self.charged("cap", [cap, rev_cap].into_iter())?;
        self.set_edge_caps_unchecked(k, cap, rev_cap);
        Ok(())
    }

    /// True if node `i` is on the sink side of the minimum cut found by the last
    /// [`Graph::maxflow`] (nodes that can reach the sink in the residual graph).
    #[inline]
    pub fn is_sink_side(&self, i: usize) -> bool {
        let p = self.nodes[i].parent;
        p != FREE && p & SINK_BIT != 0
    }

    /// The side of every node (true = sink side), see [`Graph::is_sink_side`].
    pub fn segments(&self) -> Vec<bool> {
        (0..self.n).map(|i| self.is_sink_side(i)).collect()
    }

    /// Writes the sides into `out` (length `n_nodes`).
    pub fn segments_into(&self, out: &mut [bool]) {
        for (i, o) in out.iter_mut().enumerate().take(self.n) {
            *o = self.is_sink_side(i);
        }
    }

    /// The residual capacity of edge `k` in both directions (i→j, j→i); `None` unless
    /// the graph was built after [`Graph::keep_edge_index`].
    pub fn edge_residual(&self, k: usize) -> Option<(C, C)> {
        let a = *self.edge_arc.get(k)?;
        if a == NO_ARC {
            return Some((C::ZERO, C::ZERO));
        }
        let a = a as usize;
        Some((self.arcs[a].cap(), self.arcs[self.sister(a)].cap()))
    }

    /// The signed residual terminal capacity of `i` (> 0 source→i, < 0 i→sink).
    pub fn terminal_residual(&self, i: usize) -> C {
        self.nodes[i].tr
    }

    /// Makes the adoption clock restart every `max_time` ticks instead of 65,535, so
    /// tests can exercise the restart on small graphs.
    #[cfg(test)]
    fn set_max_time(&mut self, max_time: u32) {
        self.max_time = max_time.clamp(1, MAX_TIME);
    }

    /// Runs `f` on the search over the whole graph, then keeps its clock and flow.
    fn with_search<R>(&mut self, f: impl FnOnce(&mut Search<'_, C, false>) -> R) -> R {
        let arc_end = self.arcs.len() as u32;
        let mut s = Search {
            nodes: &mut self.nodes,
            arcs: &mut self.arcs,
            overflow: &self.overflow,
            node_base: 0,
            arc_base: 0,
            arc_end,
            n: self.n,
            // Moved in and back out: one indirection less in the hot loops.
            active: std::mem::take(&mut self.active),
            orphans: std::mem::take(&mut self.orphans),
            time: self.time,
            max_time: self.max_time,
            flow: self.flow,
            restarted: false,
        };
        let r = f(&mut s);
        let Search {
            time,
            flow,
            restarted,
            active,
            orphans,
            ..
        } = s;
        self.active = active;
        self.orphans = orphans;
        self.time = time;
        self.flow = flow;
        if restarted {
            // Free nodes outside this solve's trees now hold a state too.
            self.bounded = false;
        }
        r
    }

    fn init_fresh(&mut self) {
        self.forget_search();
        self.with_search(|s| s.start_fresh());
    }

    /// The part of a fresh solve's start shared by [`Self::init_fresh`] and
    /// [`Self::init_seeded`]: no active nodes, orphans, clock or pending changes.
    fn forget_search(&mut self) {
        self.active.clear();
        self.orphans.clear();
        self.time = 0;
        for &i in &self.changed {
            self.changed_bits.clear(i as usize);
        }
        self.changed.clear();
    }

    /// [`Self::init_fresh`] on a clean graph whose terminal arcs are all at `seeds`:
    /// every other node is already free, so only the seeds are visited. The active
    /// nodes are swept in index order whatever the order of `seeds`.
    fn init_seeded(&mut self, seeds: &[u32]) {
        self.forget_search();
        self.with_search(|s| {
            for &i in seeds {
                s.start_root(i as usize);
            }
        });
        debug_assert!(
            (0..self.n).all(|i| {
                let v = self.nodes[i];
                let (tr, parent, tsd) = (v.tr, v.parent, v.tsd);
                if tr != C::ZERO {
                    parent & !SINK_BIT == TERMINAL
                } else {
                    parent == FREE && tsd == 0
                }
            }),
            "maxflow_seeded: a node outside the seeds has terminal capacity or a search state"
        );
        self.active.start_sweep();
    }

    /// Repairs the trees of the previous solve around nodes whose terminal capacities
    /// changed: such a node becomes a root of the tree its residual points to (switching
    /// trees orphans its old children), or an orphan if it lost its terminal arc.
    fn init_reuse(&mut self) {
        self.active.clear();
        self.orphans.clear();
        let changed = std::mem::take(&mut self.changed);
        self.with_search(|s| {
            s.tick();
            for &iu in &changed {
                let i = iu as usize;
                let t = s.nodes[i].tr;
                let p = s.nodes[i].parent;
                let in_tree = p != FREE;
                if t == C::ZERO {
                    if p & !SINK_BIT == TERMINAL {
                        s.make_orphan(iu);
                    } else if in_tree {
                        s.active.push(iu);
                    }
                    continue;
                }
                let want_sink = t < C::ZERO;
                if in_tree && (p & SINK_BIT != 0) != want_sink {
                    // Children in the old tree lose their parent, and every tree
                    // neighbour is re-activated: those of the old tree may have to grow
                    // into `i` again once it leaves the new tree.
                    for a in s.nodes[i].first as usize..s.nodes[i + 1].first as usize {
                        let j = (s.arcs[a].hw & HEAD_MASK) as usize;
                        let pj = s.nodes[j].parent;
                        if pj != FREE {
                            s.active.push(j as u32);
                        }
                        if is_arc(pj)
                            && (s.arcs[(pj & !SINK_BIT) as usize].hw & HEAD_MASK) as usize == i
                        {
                            s.make_orphan(j as u32);
                        }
                    }
                }
                s.nodes[i].parent = TERMINAL | if want_sink { SINK_BIT } else { 0 };
                s.nodes[i].tsd = pack_tsd(s.time, 1);
                s.active.push(iu);
            }
            s.adopt();
        });
        for &i in &changed {
            self.changed_bits.clear(i as usize);
        }
        self.changed = changed;
        self.changed.clear();
    }

    /// Computes the maximum flow (and so the minimum cut) and returns its value. Called
    /// again after terminal capacity changes, it continues from the previous state.
    ///
    /// A fresh solve of a large graph whose edges join only nodes with nearby indices
    /// (a pixel grid in row-major order) runs on several threads: see
    /// [`Graph::parallel_parts`]. The cut is the same as a one-thread solve's; with `f64`
    /// capacities the flow value may differ in the last bits (another summation order).
    pub fn maxflow(&mut self) -> C {
        self.solve(None)
    }

    /// [`Graph::maxflow`] for a graph in which only `seeds` may have terminal
    /// capacity: when the graph is clean (after [`Graph::reset_touched`] of a solved
    /// graph, or new) a fresh solve visits just `seeds` instead of every node, so a
    /// small problem on a large graph (an expansion move with few free nodes) costs
    /// only its own size. Same flow and cut as `maxflow`.
    pub(crate) fn maxflow_seeded(&mut self, seeds: &[u32]) -> C {
        self.solve(Some(seeds))
    }

    fn solve(&mut self, seeds: Option<&[u32]>) -> C {
        if self.needs_build() {
            self.build();
        }
        if self.trees_valid {
            self.init_reuse();
        } else {
            // Only the trees of this solve are not free from here on.
            self.bounded = true;
            let parts = if seeds.is_none() {
                self.parallel_parts()
            } else {
                1
            };
            match seeds {
                Some(seeds) if self.clean => self.init_seeded(seeds),
                None if parts > 1 => {
                    self.clean = false;
                    self.solve_in_parts(parts);
                    self.trees_valid = true;
                    return self.flow;
                }
                _ => self.init_fresh(),
            }
        }
        self.clean = false;
        self.with_search(|s| s.run());
        self.trees_valid = true;
        self.flow
    }

    /// How many parts a fresh [`Graph::maxflow`] splits the graph into, one per thread
    /// of the rayon pool (at most 8 and [`Graph::set_max_threads`]); 1 for
    /// a one-thread solve.
    ///
    /// The parts are ranges of node indices. Each part is solved on its own thread with
    /// the arcs between parts left out; then one search over the whole graph resumes
    /// from the parts' flows and search trees, starting from the nodes at the parts'
    /// borders, and finds the flow that must cross them (Liu and Sun, "Parallel
    /// graph-cuts by adaptive bottom-up merging", CVPR 2010, with one merge). On image
    /// grids most augmenting paths are short and local, so the parts find nearly all the
    /// flow (more than 99.9 % on the peer benchmark's graphs) and the last search is
    /// short (0.05–0.1 ms there). It pays only when few arcs cross the borders, so a
    /// part must hold at least 16,384 nodes and 32 times the graph's bandwidth (the
    /// largest index difference of an edge's ends: the grid's width). While the parts
    /// are solved, each holds its own active queue and orphan list (about 0.25 bytes
    /// per node), released at the end.
    pub fn parallel_parts(&self) -> usize {
        #[cfg(test)]
        if let Some(k) = self.parts_override {
            return k.clamp(1, self.n.max(1));
        }
        let bandwidth = self.bandwidth as usize;
        let min_part = MIN_PART_NODES.max(PART_BANDWIDTHS.saturating_mul(bandwidth));
        let by_size = self.n / min_part;
        let threads = match self.max_threads {
            0 => rayon::current_num_threads(),
            t => t.min(rayon::current_num_threads()),
        };
        threads.min(MAX_PARTS).min(by_size).max(1)
    }

    /// Lets fresh solves use at most `threads` threads (0: all of the rayon pool's, the
    /// default; 1: solve on the calling thread).
    pub fn set_max_threads(&mut self, threads: usize) {
        self.max_threads = threads;
    }

    /// Splits every solve of a fresh graph into `k` parts whatever its size (tests).
    #[cfg(test)]
    fn force_parts(&mut self, k: usize) {
        self.parts_override = Some(k);
    }

    /// A fresh solve in `k` parts (see [`Graph::parallel_parts`]).
    fn solve_in_parts(&mut self, k: usize) {
        self.forget_search();
        let n = self.n;
        let bounds: Vec<usize> = (0..=k).map(|p| p * n / k).collect();
        let firsts: Vec<u32> = bounds.iter().map(|&b| self.nodes[b].first).collect();
        // Disjoint slices of the node and arc records, one pair per part; the last part
        // keeps the end record.
        let mut parts = Vec::with_capacity(k);
        let mut nodes_rest: &mut [Node<C>] = &mut self.nodes;
        let mut arcs_rest: &mut [ArcRec<C>] = &mut self.arcs;
        for p in 0..k {
            let len = bounds[p + 1] - bounds[p];
            let n_arcs = (firsts[p + 1] - firsts[p]) as usize;
            let (nodes, arcs) = if p + 1 < k {
                let (nh, nt) = std::mem::take(&mut nodes_rest).split_at_mut(len);
                let (ah, at) = std::mem::take(&mut arcs_rest).split_at_mut(n_arcs);
                nodes_rest = nt;
                arcs_rest = at;
                (nh, ah)
            } else {
                (
                    std::mem::take(&mut nodes_rest),
                    std::mem::take(&mut arcs_rest),
                )
            };
            parts.push((nodes, arcs, p, len));
        }
        let overflow: &[(u32, u32)] = &self.overflow;
        let max_time = self.max_time;
        let results: Vec<(C, u32, bool)> = parts
            .into_par_iter()
            .map(|(nodes, arcs, p, len)| {
                let mut s = Search::<C, true> {
                    nodes,
                    arcs,
                    overflow,
                    node_base: bounds[p] as u32,
                    arc_base: firsts[p],
                    arc_end: firsts[p + 1],
                    n: len,
                    active: ActiveQueue::new(len),
                    orphans: VecDeque::new(),
                    time: 0,
                    max_time,
                    flow: C::ZERO,
                    restarted: false,
                };
                s.start_fresh();
                s.run();
                (s.flow, s.time, s.restarted)
            })
            .collect();
        for &(flow, time, restarted) in &results {
            self.flow += flow;
            // The whole-graph search goes on with a clock no part's stamps are ahead of:
            // its first adoption comes after a tick, so every stamp it trusts is fresh.
            self.time = self.time.max(time);
            if restarted {
                self.bounded = false;
            }
        }
        // The parts left every tree node scanned except across the borders: activate
        // the tree nodes that may have an arc over one (within a bandwidth of it).
        let bandwidth = self.bandwidth as usize;
        for &b in &bounds[1..k] {
            for i in b.saturating_sub(bandwidth)..(b + bandwidth).min(n) {
                if self.nodes[i].parent != FREE {
                    self.active.push(i as u32);
                }
            }
        }
        self.with_search(|s| s.run());
    }

    /// Asserts that every tree node's parent path reaches its tree's terminal without
    /// a cycle, an orphan or a free node on the way (tests only).
    #[cfg(test)]
    fn check_trees(&self) {
        for s in 0..self.n {
            let mut k = s;
            let mut steps = 0;
            loop {
                let p = self.nodes[k].parent;
                if p == FREE {
                    assert_eq!(k, s, "path from {s} reaches free node {k}");
                    break;
                }
                let pb = p & !SINK_BIT;
                assert!(pb != ORPHAN, "orphan {k} after adoption");
                if pb == TERMINAL {
                    break;
                }
                let q = (self.arcs[pb as usize].hw & HEAD_MASK) as usize;
                assert_eq!(
                    self.nodes[q].parent & SINK_BIT,
                    p & SINK_BIT,
                    "tree mismatch"
                );
                k = q;
                steps += 1;
                assert!(steps <= self.n, "cycle through {s} (time {})", self.time);
            }
        }
    }
}

/// Fewest nodes per part of a parallel fresh solve ([`Graph::parallel_parts`]).
const MIN_PART_NODES: usize = 16_384;
/// A part of a parallel fresh solve spans at least this many times the graph's
/// bandwidth, so that few of its nodes have arcs into other parts.
const PART_BANDWIDTHS: usize = 32;
/// Most parts of a parallel fresh solve: the last, whole-graph search grows with the
/// number of borders.
const MAX_PARTS: usize = 8;

/// The node index of head word `hw` relative to `node_base` (wraps to a huge value
/// below it, so that `nodes.get` rejects it like an index past the end).
#[inline(always)]
fn local(hw: u32, node_base: u32) -> usize {
    (hw & HEAD_MASK).wrapping_sub(node_base) as usize
}

/// The global index of the reverse of global arc `a` (whose head is in the range).
#[inline(always)]
fn sister_in<C: Copy>(
    nodes: &[Node<C>],
    arcs: &[ArcRec<C>],
    overflow: &[(u32, u32)],
    node_base: u32,
    arc_base: usize,
    a: usize,
) -> usize {
    let hw = arcs[a - arc_base].hw;
    sister_at(nodes[local(hw, node_base)].first, overflow, a, hw)
}

/// The search state of one solve over a range of node indices: the whole graph, or one
/// part of a parallel fresh solve ([`Graph::parallel_parts`]). Node indices in here
/// (loop variables, the active queue, the orphans) are local to the range; arc indices
/// (in parent words and from [`sister_at`]) stay global, so a part's trees are valid
/// trees of the whole graph. An arc whose head is outside the range is passed over as if
/// it had no residual capacity either way.
struct Search<'g, C: Capacity, const PART: bool> {
    /// The range's node records; the whole graph's end record may follow them.
    nodes: &'g mut [Node<C>],
    /// The arcs of the range's nodes.
    arcs: &'g mut [ArcRec<C>],
    overflow: &'g [(u32, u32)],
    /// Global index of `nodes[0]` and of `arcs[0]`.
    node_base: u32,
    arc_base: u32,
    /// Global index where the arcs of the range's last node end.
    arc_end: u32,
    /// Nodes in the range.
    n: usize,
    active: ActiveQueue,
    orphans: VecDeque<u32>,
    time: u32,
    max_time: u32,
    flow: C,
    /// The clock restarted: nodes outside the trees may hold a time stamp.
    restarted: bool,
}

impl<C: Capacity, const PART: bool> Search<'_, C, PART> {
    /// Global index of the range's first node (0 for the whole graph, known at compile
    /// time there: the whole-graph search pays nothing for the parts).
    #[inline(always)]
    fn node_base(&self) -> u32 {
        if PART {
            self.node_base
        } else {
            0
        }
    }

    /// Global index of the range's first arc.
    #[inline(always)]
    fn arc_base(&self) -> u32 {
        if PART {
            self.arc_base
        } else {
            0
        }
    }

    /// The arcs of local node `i`, as local arc indices.
    #[inline(always)]
    fn arc_range(
        nodes: &[Node<C>],
        i: usize,
        arc_end: u32,
        arc_base: u32,
    ) -> std::ops::Range<usize> {
        let end = if PART {
            match nodes.get(i + 1) {
                Some(v) => v.first,
                None => arc_end,
            }
        } else {
            nodes[i + 1].first
        };
        (nodes[i].first - arc_base) as usize..(end - arc_base) as usize
    }

    #[inline(always)]
    fn make_orphan(&mut self, i: u32) {
        let p = &mut self.nodes[i as usize].parent;
        *p = ORPHAN | (*p & SINK_BIT);
        self.orphans.push_back(i);
    }

    /// Advances the clock of the adoption heuristic; restarts it when the 16 bits run
    /// out (every `max_time` ticks).
    ///
    /// Why the restart sets every distance to the same value: the shortcut in `grow`
    /// (re-hang `j` below `i` when `ts_j <= ts_i && dist_j > dist_i`) cannot close a cycle
    /// only while the key (ts, −dist) never decreases from a child to its parent. Keeping
    /// the old distances with the stamps cleared breaks that (a child stamped earlier may
    /// hold a smaller distance than its parent) and the trees can grow a cycle: on a
    /// 640×480 segmentation the solver then looped for ever. Distance 1 for the roots
    /// and one large constant for all other nodes keeps the order non-decreasing (and
    /// the roots out of reach of the shortcut); fresh stamps rebuild it.
    #[inline]
    fn tick(&mut self) {
        self.time += 1;
        if self.time > self.max_time {
            for v in self.nodes.iter_mut() {
                // Roots keep distance 1, the least: a root must never be re-hung.
                let root = v.parent & !SINK_BIT == TERMINAL;
                v.tsd = pack_tsd(0, if root { 1 } else { 0xFFFF });
            }
            self.restarted = true;
            self.time = 1;
        }
    }

    /// A fresh solve's start over the range: the short paths, then every node with a
    /// terminal residual an active root, every other node free. The active queue and
    /// the orphans must be empty and the clock at 0.
    fn start_fresh(&mut self) {
        for i in 0..self.n {
            self.push_short_paths(i);
        }
        for i in 0..self.n {
            if !self.start_root(i) {
                let v = &mut self.nodes[i];
                v.parent = FREE;
                v.tsd = 0;
            }
        }
        self.active.start_sweep();
    }

    /// Before a fresh solve's search: if node `i` has residual capacity from the
    /// source, pushes flow along every path source → i → j → sink through its arcs
    /// (as much as each path's bottleneck allows). These are the shortest augmenting
    /// paths a search can find; one pass over the nodes saves the trees the work of
    /// growing, augmenting and adopting for each of them, and the search then starts
    /// with fewer roots. Only residuals change, so the flow stays a valid flow and the
    /// maximum and the cut (the nodes the source reaches) are those of the plain search.
    #[inline(always)]
    fn push_short_paths(&mut self, i: usize) {
        let mut tr = self.nodes[i].tr;
        if tr <= C::ZERO {
            return;
        }
        let (nb, ab) = (self.node_base(), self.arc_base());
        let range = Self::arc_range(self.nodes, i, self.arc_end, ab);
        let nodes: &mut [Node<C>] = self.nodes;
        let arcs: &mut [ArcRec<C>] = self.arcs;
        let overflow: &[(u32, u32)] = self.overflow;
        let mut pushed = C::ZERO;
        for a in range {
            let hw = arcs[a].hw;
            let Some(&nj) = nodes.get(local(hw, nb)) else {
                continue;
            };
            let (tj, cap) = (nj.tr, arcs[a].cap());
            if tj >= C::ZERO || cap <= C::ZERO {
                continue;
            }
            let f = tr.min_of(cap).min_of(-tj);
            let s = sister_at(nj.first, overflow, a + ab as usize, hw) - ab as usize;
            arcs[a].cap = cap - f;
            arcs[s].cap = arcs[s].cap() + f;
            nodes[local(hw, nb)].tr = tj + f;
            tr -= f;
            pushed += f;
            if tr <= C::ZERO {
                break;
            }
        }
        nodes[i].tr = tr;
        self.flow += pushed;
    }

    /// A fresh solve's start of node `i`: with a terminal residual it becomes an active
    /// root of the source or sink tree (returns true); otherwise it is left as it is.
    #[inline(always)]
    fn start_root(&mut self, i: usize) -> bool {
        let v = &mut self.nodes[i];
        let tr = v.tr;
        let parent = if tr > C::ZERO {
            TERMINAL
        } else if tr < C::ZERO {
            TERMINAL | SINK_BIT
        } else {
            return false;
        };
        v.parent = parent;
        v.tsd = pack_tsd(0, 1);
        self.active.mark_initial(i);
        true
    }

    fn run(&mut self) {
        let mut current = FREE;
        loop {
            let i = if current != FREE && self.nodes[current as usize].parent != FREE {
                current
            } else {
                match self.active.pop() {
                    None => break,
                    Some(i) if self.nodes[i as usize].parent == FREE => continue,
                    Some(i) => i,
                }
            };
            current = FREE;
            let mid = self.grow(i as usize);
            if mid != FREE {
                self.tick();
                // Keep scanning `i` after the augmentation: it may have more paths.
                current = i;
                self.augment(mid as usize);
                self.adopt();
            }
        }
    }

    /// Grows the tree of `i` by one step over its arcs; returns the arc (S side → T side,
    /// global index) of a path found, or `FREE`.
    #[inline]
    fn grow(&mut self, i: usize) -> u32 {
        let (nb, ab) = (self.node_base(), self.arc_base() as usize);
        let range = Self::arc_range(self.nodes, i, self.arc_end, self.arc_base());
        // Local slices let the optimiser keep the array pointers in registers.
        let arcs: &[ArcRec<C>] = self.arcs;
        let overflow: &[(u32, u32)] = self.overflow;
        let nodes: &mut [Node<C>] = self.nodes;
        let active = &mut self.active;
        let lo = range.start + ab;
        let ni = nodes[i];
        let tree = ni.parent & SINK_BIT;
        let sink = tree != 0;
        let ts_i = ts_of(ni.tsd);
        let dist_i = dist_of(ni.tsd);
        let child_tsd = pack_tsd(ts_i, dist_i + 1);
        if !sink {
            for (k, arc) in arcs[range].iter().enumerate() {
                // Residual i→j (sequential in the arc array: checked first).
                if arc.cap() <= C::ZERO {
                    continue;
                }
                let a = lo + k;
                let hw = arc.hw;
                let j = local(hw, nb);
                let Some(&nj) = nodes.get(j) else {
                    continue;
                };
                if nj.parent == FREE {
                    let s = sister_at(nj.first, overflow, a, hw);
                    nodes[j].parent = s as u32 | tree;
                    nodes[j].tsd = child_tsd;
                    active.push(j as u32);
                } else if nj.parent & SINK_BIT != tree {
                    return a as u32;
                } else if ts_of(nj.tsd) <= ts_i && dist_of(nj.tsd) > dist_i {
                    // Shortcut: `i` gives `j` a shorter, as fresh path to the root.
                    nodes[j].parent = sister_at(nj.first, overflow, a, hw) as u32 | tree;
                    nodes[j].tsd = child_tsd;
                }
            }
        } else {
            for (k, arc) in arcs[range].iter().enumerate() {
                let hw = arc.hw;
                // The residual j→i sits in j's arc list (a random read), so the
                // neighbour's state is checked first: most neighbours of a tree node
                // are in its own tree and need no capacity.
                let a = lo + k;
                let j = local(hw, nb);
                let Some(&nj) = nodes.get(j) else {
                    continue;
                };
                let same_tree = nj.parent != FREE && nj.parent & SINK_BIT == tree;
                let shortcut = ts_of(nj.tsd) <= ts_i && dist_of(nj.tsd) > dist_i;
                if same_tree && !shortcut {
                    continue;
                }
                let s = sister_at(nj.first, overflow, a, hw);
                if arcs[s - ab].cap() <= C::ZERO {
                    continue;
                }
                if same_tree {
                    nodes[j].parent = s as u32 | tree;
                    nodes[j].tsd = child_tsd;
                } else if nj.parent == FREE {
                    nodes[j].parent = s as u32 | tree;
                    nodes[j].tsd = child_tsd;
                    active.push(j as u32);
                } else {
                    return s as u32;
                }
            }
        }
        FREE
    }

    /// Pushes the bottleneck flow along source → … → tail(mid) → head(mid) → … → sink
    /// (`mid` a global arc index); nodes whose tree arc saturates become orphans (queued
    /// at the front, so those nearer the terminals, found last, are adopted first).
    fn augment(&mut self, mid: usize) {
        let (nb, ab) = (self.node_base(), self.arc_base() as usize);
        let overflow: &[(u32, u32)] = self.overflow;
        let arcs: &mut [ArcRec<C>] = self.arcs;
        let nodes: &mut [Node<C>] = self.nodes;
        let orphans = &mut self.orphans;
        let sis = |arcs: &[ArcRec<C>], nodes: &[Node<C>], a: usize| {
            sister_in(nodes, arcs, overflow, nb, ab, a)
        };
        let head = |arcs: &[ArcRec<C>], a: usize| local(arcs[a - ab].hw, nb);
        let mid_s = sis(arcs, nodes, mid);
        let u = head(arcs, mid_s);
        let v = head(arcs, mid);
        let mut f = arcs[mid - ab].cap();
        // Bottleneck: S side (arcs parent → x), then T side (arcs x → parent).
        let mut x = u;
        loop {
            let p = nodes[x].parent & !SINK_BIT;
            if p == TERMINAL {
                f = f.min_of(nodes[x].tr);
                break;
            }
            let p = p as usize;
            f = f.min_of(arcs[sis(arcs, nodes, p) - ab].cap());
            x = head(arcs, p);
        }
        x = v;
        loop {
            let p = nodes[x].parent & !SINK_BIT;
            if p == TERMINAL {
                f = f.min_of(-nodes[x].tr);
                break;
            }
            let p = p as usize;
            f = f.min_of(arcs[p - ab].cap());
            x = head(arcs, p);
        }
        arcs[mid - ab].cap = arcs[mid - ab].cap() - f;
        arcs[mid_s - ab].cap = arcs[mid_s - ab].cap() + f;
        x = u;
        loop {
            let p = nodes[x].parent;
            let pb = p & !SINK_BIT;
            if pb == TERMINAL {
                let tr = nodes[x].tr - f;
                nodes[x].tr = tr;
                if tr <= C::ZERO {
                    nodes[x].parent = ORPHAN | (p & SINK_BIT);
                    orphans.push_front(x as u32);
                }
                break;
            }
            let pb = pb as usize;
            let s = sis(arcs, nodes, pb) - ab;
            arcs[s].cap = arcs[s].cap() - f;
            arcs[pb - ab].cap = arcs[pb - ab].cap() + f;
            if arcs[s].cap() <= C::ZERO {
                nodes[x].parent = ORPHAN | (p & SINK_BIT);
                orphans.push_front(x as u32);
            }
            x = head(arcs, pb);
        }
        x = v;
        loop {
            let p = nodes[x].parent;
            let pb = p & !SINK_BIT;
            if pb == TERMINAL {
                let tr = nodes[x].tr + f;
                nodes[x].tr = tr;
                if tr >= C::ZERO {
                    nodes[x].parent = ORPHAN | (p & SINK_BIT);
                    orphans.push_front(x as u32);
                }
                break;
            }
            let pb = pb as usize;
            arcs[pb - ab].cap = arcs[pb - ab].cap() - f;
            let s = sis(arcs, nodes, pb) - ab;
            arcs[s].cap = arcs[s].cap() + f;
            if arcs[pb - ab].cap() <= C::ZERO {
                nodes[x].parent = ORPHAN | (p & SINK_BIT);
                orphans.push_front(x as u32);
            }
            x = head(arcs, pb);
        }
        self.flow += f;
    }

    fn adopt(&mut self) {
        while let Some(i) = self.orphans.pop_front() {
            // A queued orphan may have been made a root since (dynamic updates).
            if self.nodes[i as usize].parent & !SINK_BIT != ORPHAN {
                continue;
            }
            self.process_orphan(i as usize);
        }
    }

    fn process_orphan(&mut self, i: usize) {
        let (nb, ab) = (self.node_base(), self.arc_base() as usize);
        let range = Self::arc_range(self.nodes, i, self.arc_end, self.arc_base());
        let overflow: &[(u32, u32)] = self.overflow;
        let arcs: &[ArcRec<C>] = self.arcs;
        let nodes: &mut [Node<C>] = self.nodes;
        let time = self.time;
        let tree = nodes[i].parent & SINK_BIT;
        let sink = tree != 0;
        // Residual capacity from the neighbour `j` towards `i` (S) or from `i` towards
        // `j` (T): the direction in which `i` could hang below it (`a` local).
        let open = |a: usize, hw: u32, j_first: u32| {
            if sink {
                arcs[a].cap() > C::ZERO
            } else {
                arcs[sister_at(j_first, overflow, a + ab, hw) - ab].cap() > C::ZERO
            }
        };
        let mut best = FREE;
        let mut best_d = INFINITE_DIST;
        for a in range.clone() {
            let hw = arcs[a].hw;
            let j = local(hw, nb);
            let Some(&nj) = nodes.get(j) else {
                continue;
            };
            if nj.parent == FREE || nj.parent & SINK_BIT != tree || !open(a, hw, nj.first) {
                continue;
            }
            let d = origin_distance(arcs, nodes, nb, ab, time, j);
            if d < best_d {
                best = (a + ab) as u32;
                best_d = d;
            }
        }
        if best != FREE {
            nodes[i].parent = best | tree;
            nodes[i].tsd = pack_tsd(time, best_d + 1);
            return;
        }
        // No parent: `i` becomes free; its children become orphans and neighbours that
        // could grow into it become active.
        nodes[i].parent = FREE;
        for a in range {
            let hw = arcs[a].hw;
            let j = local(hw, nb);
            let Some(&nj) = nodes.get(j) else {
                continue;
            };
            let pj = nj.parent;
            if pj == FREE || pj & SINK_BIT != tree {
                continue;
            }
            if open(a, hw, nj.first) {
                self.active.push(j as u32);
            }
            if is_arc(pj) && local(arcs[(pj & !SINK_BIT) as usize - ab].hw, nb) == i {
                nodes[j].parent = ORPHAN | tree;
                self.orphans.push_back(j as u32);
            }
        }
    }
}

/// Distance from local node `j` to its tree's terminal, following parents, or
/// `INFINITE_DIST` if the path ends at an orphan. Marks the nodes it verifies with
/// `time`, recording their distances for later searches.
#[inline]
fn origin_distance<C: Capacity>(
    arcs: &[ArcRec<C>],
    nodes: &mut [Node<C>],
    node_base: u32,
    arc_base: usize,
    time: u32,
    j: usize,
) -> u32 {
    let mut d = 0u32;
    let mut k = j;
    loop {
        let tsd = nodes[k].tsd;
        if ts_of(tsd) == time {
            d += dist_of(tsd);
            break;
        }
        let p = nodes[k].parent & !SINK_BIT;
        d += 1;
        if p == TERMINAL {
            nodes[k].tsd = pack_tsd(time, 1);
            break;
        }
        if p == ORPHAN {
            return INFINITE_DIST;
        }
        k = local(arcs[p as usize - arc_base].hw, node_base);
    }
    let mut dd = d;
    k = j;
    while ts_of(nodes[k].tsd) != time {
        nodes[k].tsd = pack_tsd(time, dd);
        dd -= 1;
        k = local(
            arcs[(nodes[k].parent & !SINK_BIT) as usize - arc_base].hw,
            node_base,
        );
    }
    d
}

/// Edges of an `h`×`w` pixel grid (row-major node ids), 4- or 8-connected: right, down
/// (and the two down-diagonals for 8). Returns pairs `[i, j]`.
pub fn grid_edges(h: usize, w: usize, connectivity: u8) -> Result<Vec<[u32; 2]>> {
    if connectivity != 4 && connectivity != 8 {
        return Err(Error::invalid(
            "connectivity",
            format!("must be 4 or 8, got {connectivity}"),
        ));
    }
    if h.checked_mul(w).is_none_or(|n| n > MAX_NODES) {
        return Err(Error::invalid("h", "grid too large for u32 node indices"));
    }
    let per = if connectivity == 4 { 2 } else { 4 };
    let mut out = Vec::with_capacity(h * w * per);
    for r in 0..h {
        for c in 0..w {
            let i = (r * w + c) as u32;
            if c + 1 < w {
                out.push([i, i + 1]);
            }
            if r + 1 < h {
                out.push([i, i + w as u32]);
                if connectivity == 8 {
                    if c + 1 < w {
                        out.push([i, i + w as u32 + 1]);
                    }
                    if c > 0 {
                        out.push([i, i + w as u32 - 1]);
                    }
                }
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A random small graph: n nodes, edges (i, j, c, r), terminal caps (s, t).
    #[derive(Clone, Debug)]
    struct Problem {
        n: usize,
        edges: Vec<(usize, usize, i64, i64)>,
        terms: Vec<(i64, i64)>,
    }

    fn problem(max_n: usize) -> impl Strategy<Value = Problem> {
        (1..=max_n).prop_flat_map(|n| {
            let edges = prop::collection::vec((0..n, 0..n, 0i64..10, 0i64..10), 0..(3 * n));
            let terms = prop::collection::vec((0i64..12, 0i64..12), n);
            (Just(n), edges, terms).prop_map(|(n, edges, terms)| Problem { n, edges, terms })
        })
    }

    fn cut_value(p: &Problem, sink_side: &[bool]) -> i64 {
        let mut v = 0;
        for (i, &(s, t)) in p.terms.iter().enumerate() {
            v += if sink_side[i] { s } else { t };
        }
        for &(i, j, c, r) in &p.edges {
            if !sink_side[i] && sink_side[j] {
                v += c;
            }
            if sink_side[i] && !sink_side[j] {
                v += r;
            }
        }
        v
    }

    fn brute_min_cut(p: &Problem) -> i64 {
        (0..1u32 << p.n)
            .map(|mask| {
                let side: Vec<bool> = (0..p.n).map(|i| mask >> i & 1 == 1).collect();
                cut_value(p, &side)
            })
            .min()
            .unwrap()
    }

    fn graph_of(p: &Problem) -> Graph<i64> {
        let mut g = Graph::new(p.n);
        g.track_terminal_caps();
        g.keep_edge_index();
        for &(i, j, c, r) in &p.edges {
            g.add_edge(i, j, c, r).unwrap();
        }
        for (i, &(s, t)) in p.terms.iter().enumerate() {
            g.add_tweights(i, s, t).unwrap();
        }
        g
    }

    /// Replaces the terminal capacities of nodes `i % n` in `g` (a dynamic update) and
    /// returns the problem with the same changes.
    fn set_terminals(p: &Problem, g: &mut Graph<i64>, changes: &[(usize, i64, i64)]) -> Problem {
        let mut q = p.clone();
        for &(i, s, t) in changes {
            let i = i % p.n;
            q.terms[i] = (s, t);
            g.set_tweights(i, s, t).unwrap();
        }
        q
    }

    /// Flow on every edge from residuals must respect capacities and conservation.
    /// After a dynamic update the flow is one of the reparametrised graph (both terminal
    /// arcs of a node raised alike), so terminal feasibility is only checked when fresh.
    fn check_flow(p: &Problem, g: &Graph<i64>, fresh: bool) {
        let mut net_out = vec![0i64; p.n]; // net flow leaving each node over edges
        for (k, &(i, j, c, r)) in p.edges.iter().enumerate() {
            let (rc, rr) = g.edge_residual(k).unwrap();
            if i == j {
                continue;
            }
            // Residuals sum to the total capacity; flow i→j = c - rc = rr - r.
            assert_eq!(rc + rr, c + r);
            let f = c - rc;
            assert!(-r <= f && f <= c, "edge flow {f} outside [-{r}, {c}]");
            net_out[i] += f;
            net_out[j] -= f;
        }
        // Terminal flows: s_i - t_i = net_out_i with 0 ≤ s_i ≤ cs, 0 ≤ t_i ≤ ct, and the
        // residual tr = cs - ct - net_out.
        let mut total = 0;
        for i in 0..p.n {
            let (cs, ct) = p.terms[i];
            assert_eq!(g.terminal_residual(i), cs - ct - net_out[i]);
            if !fresh {
                continue;
            }
            // Feasible split with s_i ≤ cs and t_i ≤ ct.
            let t_i = ct.min(cs - net_out[i]);
            let s_i = t_i + net_out[i];
            assert!(s_i >= 0 && s_i <= cs && t_i >= 0 && t_i <= ct);
            total += s_i;
        }
        if fresh {
            assert_eq!(total, g.flow());
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]

        #[test]
        fn maxflow_equals_brute_force_min_cut(p in problem(9)) {
            let mut g = graph_of(&p);
            let f = g.maxflow();
            let best = brute_min_cut(&p);
            prop_assert_eq!(f, best);
            prop_assert_eq!(cut_value(&p, &g.segments()), best);
            check_flow(&p, &g, true);
        }

        #[test]
        fn dynamic_resolve_equals_fresh(p in problem(8), changes in prop::collection::vec((0usize..8, 0i64..12, 0i64..12), 1..6)) {
            let mut g = graph_of(&p);
            g.maxflow();
            let q = set_terminals(&p, &mut g, &changes);
            let f = g.maxflow();
            let mut fresh = graph_of(&q);
            let f2 = fresh.maxflow();
            prop_assert_eq!(f, f2);
            prop_assert_eq!(f, brute_min_cut(&q));
            prop_assert_eq!(cut_value(&q, &g.segments()), f);
            check_flow(&q, &g, false);
        }

        #[test]
        fn float_maxflow_matches_integer(p in problem(8)) {
            let mut gi = graph_of(&p);
            let mut gf = Graph::<f64>::new(p.n);
            for &(i, j, c, r) in &p.edges {
                gf.add_edge(i, j, c as f64, r as f64).unwrap();
            }
            for (i, &(s, t)) in p.terms.iter().enumerate() {
                gf.add_tweights(i, s as f64, t as f64).unwrap();
            }
            prop_assert_eq!(gi.maxflow() as f64, gf.maxflow());
            prop_assert_eq!(cut_value(&p, &gf.segments()), gi.flow());
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// The adoption clock restarting after every 1–3 augmentations (instead of
        /// 65,535) must leave the trees acyclic and the flow exact; before the restart was
        /// fixed, parent cycles made the solver loop for ever.
        #[test]
        fn clock_restarts_keep_maxflow_exact(
            p in problem(9),
            max_time in 1u32..4,
            changes in prop::collection::vec((0usize..9, 0i64..12, 0i64..12), 1..4),
        ) {
            let mut g = graph_of(&p);
            g.set_max_time(max_time);
            prop_assert_eq!(g.maxflow(), brute_min_cut(&p));
            check_flow(&p, &g, true);
            g.check_trees();
            let q = set_terminals(&p, &mut g, &changes);
            prop_assert_eq!(g.maxflow(), brute_min_cut(&q));
            prop_assert_eq!(cut_value(&q, &g.segments()), g.flow());
            g.check_trees();
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]

        /// A fresh solve split into 2–4 parts (each part solved alone, then one search
        /// over the whole graph from the parts' trees) gives the exact maximum flow and
        /// cut and valid trees, which a dynamic re-solve then reuses; also with the
        /// adoption clock restarting after every 1–3 augmentations. Random graphs have
        /// arcs between any parts.
        #[test]
        fn parts_solve_equals_brute_force_min_cut(
            p in problem(9),
            k in 2usize..5,
            max_time in prop::sample::select(vec![1u32, 2, 3, MAX_TIME]),
            changes in prop::collection::vec((0usize..9, 0i64..12, 0i64..12), 1..4),
        ) {
            let mut g = graph_of(&p);
            g.force_parts(k);
            g.set_max_time(max_time);
            let best = brute_min_cut(&p);
            prop_assert_eq!(g.maxflow(), best);
            prop_assert_eq!(cut_value(&p, &g.segments()), best);
            check_flow(&p, &g, true);
            g.check_trees();
            let q = set_terminals(&p, &mut g, &changes);
            prop_assert_eq!(g.maxflow(), brute_min_cut(&q));
            prop_assert_eq!(cut_value(&q, &g.segments()), g.flow());
            check_flow(&q, &g, false);
            g.check_trees();
        }
    }

    /// A random grid problem: `h`×`w`, 4- or 8-connected, integer capacities below
    /// `cap` on the edges and below `tcap` on the terminal arcs.
    fn grid_problem(h: usize, w: usize, conn: u8, seed: u64, cap: i64, tcap: i64) -> Problem {
        let mut rng = seed | 1;
        let mut next = move |m: i64| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng % m as u64) as i64
        };
        let edges = grid_edges(h, w, conn).unwrap();
        Problem {
            n: h * w,
            edges: edges
                .iter()
                .map(|&[i, j]| (i as usize, j as usize, next(cap), next(cap)))
                .collect(),
            terms: (0..h * w).map(|_| (next(tcap), next(tcap))).collect(),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(60))]

        /// On grids (the case the parts are for: arcs only between neighbouring rows) a
        /// solve in 2–6 parts gives the one-thread solve's flow and the same cut, valid
        /// trees and a conserved flow, and a dynamic re-solve after it matches too.
        #[test]
        fn parts_solve_on_grids_equals_one_part(
            h in 2usize..40,
            w in 2usize..50,
            conn in prop::sample::select(vec![4u8, 8]),
            k in 2usize..7,
            seed in any::<u64>(),
            changes in prop::collection::vec((0usize..2000, 0i64..30, 0i64..30), 1..20),
        ) {
            let p = grid_problem(h, w, conn, seed, 20, 30);
            let mut one = graph_of(&p);
            one.force_parts(1);
            let f = one.maxflow();
            let mut g = graph_of(&p);
            g.force_parts(k);
            prop_assert_eq!(g.maxflow(), f);
            prop_assert_eq!(g.segments(), one.segments());
            check_flow(&p, &g, true);
            g.check_trees();
            let q = set_terminals(&p, &mut g, &changes);
            set_terminals(&p, &mut one, &changes);
            prop_assert_eq!(g.maxflow(), one.maxflow());
            prop_assert_eq!(g.segments(), one.segments());
            check_flow(&q, &g, false);
            g.check_trees();
        }
    }

    /// The default split: a 256×256 grid is solved in parts when the pool has several
    /// threads (65,536 nodes, bandwidth 256), a graph of the same size with long edges
    /// and a small grid are not; the split solve matches the one-part solve, in `i64`
    /// and `f64`.
    #[test]
    fn large_grids_are_split_by_default() {
        let p = grid_problem(256, 256, 4, 7, 50, 60);
        let mut g = graph_of(&p);
        g.finalize();
        let threads = rayon::current_num_threads();
        assert_eq!(g.parallel_parts(), threads.clamp(1, 4));
        let mut one = graph_of(&p);
        one.force_parts(1);
        assert_eq!(g.maxflow(), one.maxflow());
        assert_eq!(g.segments(), one.segments());
        g.check_trees();
        let mut gf = Graph::<f64>::new(p.n);
        for &(i, j, c, r) in &p.edges {
            gf.add_edge(i, j, c as f64, r as f64).unwrap();
        }
        for (i, &(s, t)) in p.terms.iter().enumerate() {
            gf.add_tweights(i, s as f64, t as f64).unwrap();
        }
        assert_eq!(gf.maxflow(), one.flow() as f64);
        assert_eq!(gf.segments(), one.segments());

        let mut long = graph_of(&p);
        long.add_edge(0, p.n - 1, 1, 1).unwrap();
        long.finalize();
        assert_eq!(long.parallel_parts(), 1);
        let mut small = graph_of(&grid_problem(100, 100, 4, 3, 5, 5));
        small.finalize();
        assert_eq!(small.parallel_parts(), 1);
    }

    /// The pass over short paths before the search is greedy: here it sends a's unit to
    /// b (a → b is the last edge added, so a's first arc scanned), which leaves d no
    /// short path. The search must then undo part of it through the reverse residual of
    /// a → b: s → d → b → a → c → t.
    #[test]
    fn greedy_short_paths_are_rerouted_by_the_search() {
        let (a, b, c, d) = (0, 1, 2, 3);
        let p = Problem {
            n: 4,
            edges: vec![(a, c, 1, 0), (d, b, 1, 0), (a, b, 1, 0)],
            terms: vec![(1, 0), (0, 1), (0, 1), (1, 0)],
        };
        let mut g = graph_of(&p);
        assert_eq!(g.maxflow(), 2);
        assert_eq!(brute_min_cut(&p), 2);
        let side: Vec<bool> = (0..4).map(|i| g.is_sink_side(i)).collect();
        assert_eq!(cut_value(&p, &side), 2);
        // The maximum flow saturates a → c and d → b and leaves a → b unused (its
        // unit came back); every terminal arc is saturated.
        assert_eq!(g.edge_residual(0), Some((0, 1)));
        assert_eq!(g.edge_residual(1), Some((0, 1)));
        assert_eq!(g.edge_residual(2), Some((1, 0)));
        for i in 0..4 {
            assert_eq!(g.terminal_residual(i), 0, "node {i}");
        }
    }

    /// A grid large enough for thousands of augmentations, solved with the clock
    /// restarting every few of them and without restarts: same flow, same cut value.
    #[test]
    fn clock_restarts_on_a_grid() {
        let (h, w) = (48usize, 64usize);
        let mut rng = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move |m: i64| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng % m as u64) as i64
        };
        let edges = grid_edges(h, w, 8).unwrap();
        let p = Problem {
            n: h * w,
            edges: edges
                .iter()
                .map(|&[i, j]| (i as usize, j as usize, next(20), next(20)))
                .collect(),
            terms: (0..h * w).map(|_| (next(30), next(30))).collect(),
        };
        let mut plain = graph_of(&p);
        let f = plain.maxflow();
        for max_time in [1, 2, 5, 97] {
            let mut g = graph_of(&p);
            g.set_max_time(max_time);
            assert_eq!(g.maxflow(), f, "max_time {max_time}");
            g.check_trees();
            assert_eq!(cut_value(&p, &g.segments()), f);
            check_flow(&p, &g, true);
        }
    }

    /// Problems with a hub: most edges touch node 0 (degrees above the 15 arcs that a
    /// sister hint covers, so the overflow table is used), with parallel edges,
    /// self-loops and isolated nodes.
    fn hub_problem() -> impl Strategy<Value = Problem> {
        (3usize..=9).prop_flat_map(|n| {
            let spoke = (0..n, 0i64..6, 0i64..6, any::<bool>());
            let edges = prop::collection::vec(spoke, 16..48);
            let extra = prop::collection::vec((0..n, 0..n, 0i64..6, 0i64..6), 0..6);
            let terms = prop::collection::vec((0i64..15, 0i64..15), n);
            (Just(n), edges, extra, terms).prop_map(|(n, spokes, extra, terms)| {
                let mut edges: Vec<_> = spokes
                    .into_iter()
                    .map(|(j, c, r, flip)| if flip { (j, 0, c, r) } else { (0, j, c, r) })
                    .collect();
                edges.extend(extra);
                Problem { n, edges, terms }
            })
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn hub_graphs_match_brute_force(p in hub_problem(), changes in prop::collection::vec((0usize..9, 0i64..15, 0i64..15), 1..4)) {
            let mut g = graph_of(&p);
            prop_assert_eq!(g.maxflow(), brute_min_cut(&p));
            prop_assert_eq!(cut_value(&p, &g.segments()), g.flow());
            check_flow(&p, &g, true);
            // Dynamic changes on top, and a graph built by the batch call.
            let q = set_terminals(&p, &mut g, &changes);
            prop_assert_eq!(g.maxflow(), brute_min_cut(&q));
            check_flow(&q, &g, false);
            let mut b = Graph::<i64>::new(p.n);
            let src: Vec<u32> = p.edges.iter().map(|e| e.0 as u32).collect();
            let dst: Vec<u32> = p.edges.iter().map(|e| e.1 as u32).collect();
            let cap: Vec<i64> = p.edges.iter().map(|e| e.2).collect();
            let rev: Vec<i64> = p.edges.iter().map(|e| e.3).collect();
            b.add_edges(&src, &dst, &cap, &rev).unwrap();
            for (i, &(s, t)) in p.terms.iter().enumerate() {
                b.add_tweights(i, s, t).unwrap();
            }
            prop_assert_eq!(b.maxflow(), brute_min_cut(&p));
            // Split into parts: arcs whose sister sits in the overflow table, across
            // and within parts.
            for k in 2..4 {
                let mut g = graph_of(&p);
                g.force_parts(k);
                prop_assert_eq!(g.maxflow(), brute_min_cut(&p));
                check_flow(&p, &g, true);
                g.check_trees();
            }
        }
    }

    #[test]
    fn hub_graph_uses_the_overflow_table() {
        let n = 40;
        let mut g = Graph::<i64>::new(n);
        for j in 1..n {
            g.add_edge(0, j, 1, 1).unwrap();
        }
        g.add_tweights(0, 100, 0).unwrap();
        for j in 1..n {
            g.add_tweights(j, 0, 1).unwrap();
        }
        assert_eq!(g.maxflow(), (n - 1) as i64);
        assert!(!g.overflow.is_empty());
        // Every arc's reverse points back to it.
        for a in 0..g.arcs.len() {
            assert_eq!(g.sister(g.sister(a)), a);
        }
    }

    #[test]
    fn edges_added_after_solve_are_used() {
        let mut g = Graph::<i64>::new(3);
        g.add_tweights(0, 5, 0).unwrap();
        g.add_tweights(2, 0, 5).unwrap();
        g.add_edge(0, 1, 3, 0).unwrap();
        assert_eq!(g.maxflow(), 0);
        g.add_edge(1, 2, 2, 0).unwrap();
        assert_eq!(g.maxflow(), 2);
        assert!(!g.is_sink_side(0) && g.is_sink_side(2));
    }

    proptest! {
        /// Rounds as an expansion solver runs them on one graph: capacities on a subset
        /// of the nodes and the edges inside it, a seeded solve, `reset_touched`. Every
        /// round's flow and cut equal the brute-force minimum cut of its capacities,
        /// also with an occasional full `reset` and the adoption clock restarting.
        #[test]
        fn seeded_solves_after_touched_resets_match_brute_force(
            p in problem(9),
            rounds in prop::collection::vec(
                (any::<u16>(), prop::collection::vec((0i64..12, 0i64..12, 0i64..10, 0i64..10), 9), any::<bool>()),
                1..6,
            ),
            max_time in 1u32..40,
        ) {
            let mut g = Graph::<i64>::new(p.n);
            g.keep_edge_index();
            g.set_max_time(max_time);
            for &(i, j, _, _) in &p.edges {
                g.add_edge(i, j, 0, 0).unwrap();
            }
            g.finalize();
            for (mask, caps, full_reset) in rounds {
                let seeds: Vec<u32> = (0..p.n as u32).filter(|&i| mask >> i & 1 == 1).collect();
                let inside = |i: usize| mask >> i & 1 == 1;
                let mut q = Problem { n: p.n, edges: Vec::new(), terms: vec![(0, 0); p.n] };
                let mut touched = Vec::new();
                for (k, &(i, j, _, _)) in p.edges.iter().enumerate() {
                    if inside(i) && inside(j) && i != j {
                        let (c, r) = (caps[i].2, caps[j].3);
                        g.set_edge_caps_unchecked(k, c, r);
                        touched.push(k as u32);
                        q.edges.push((i, j, c, r));
                    }
                }
                for &i in &seeds {
                    let (s, t, _, _) = caps[i as usize];
                    g.update_tweights_unchecked(i as usize, s, t);
                    q.terms[i as usize] = (s, t);
                }
                prop_assert_eq!(g.maxflow_seeded(&seeds), brute_min_cut(&q));
                prop_assert_eq!(cut_value(&q, &g.segments()), g.flow());
                g.check_trees();
                if full_reset {
                    g.reset();
                } else {
                    g.reset_touched(&touched, &seeds);
                }
            }
        }
    }

    #[test]
    fn reset_and_reuse_structure() {
        let p = Problem {
            n: 4,
            edges: vec![(0, 1, 2, 1), (1, 2, 3, 0), (2, 3, 1, 4), (0, 3, 2, 2)],
            terms: vec![(4, 0), (1, 2), (0, 3), (2, 2)],
        };
        let mut g = graph_of(&p);
        let f = g.maxflow();
        g.reset();
        for (k, &(_, _, c, r)) in p.edges.iter().enumerate() {
            g.set_edge_caps(k, c, r).unwrap();
        }
        for (i, &(s, t)) in p.terms.iter().enumerate() {
            g.add_tweights(i, s, t).unwrap();
        }
        assert_eq!(g.maxflow(), f);
        assert_eq!(f, brute_min_cut(&p));
    }

    #[test]
    fn bad_input_is_rejected() {
        let mut g = Graph::<f64>::new(2);
        assert!(g.add_edge(0, 2, 1.0, 1.0).is_err());
        assert!(g.add_edge(0, 1, -1.0, 1.0).is_err());
        assert!(g.add_edge(0, 1, f64::NAN, 1.0).is_err());
        assert!(g.add_tweights(0, f64::INFINITY, 0.0).is_err());
        assert!(g.add_edges(&[0], &[1, 0], &[1.0], &[1.0]).is_err());
        assert!(g.set_tweights(0, 1.0, 1.0).is_err()); // not tracked
        assert!(grid_edges(2, 2, 6).is_err());
    }

    /// Integer capacities whose sum could pass `i64::MAX` are refused by every entry
    /// point, naming the argument and changing nothing (they used to wrap: three
    /// terminal arcs of 2^62 gave a flow of −2^62).
    #[test]
    fn integer_sums_past_int64_are_refused_and_change_nothing() {
        let big = 1i64 << 62;
        let name_of = |r: Result<()>| match r {
            Err(Error::InvalidArgument { name, .. }) => name,
            other => panic!("expected a refusal, got {other:?}"),
        };
        let mut g = Graph::<i64>::new(3);
        g.track_terminal_caps();
        g.keep_edge_index();
        g.add_tweights_batch(&[0, 1], &[big / 2, big / 2], &[0, 0])
            .unwrap();
        assert_eq!(name_of(g.add_tweights(2, big, 0)), "source_cap");
        assert_eq!(
            name_of(g.add_tweights_batch(&[2], &[0], &[big])),
            "source_cap"
        );
        assert_eq!(name_of(g.add_edge(0, 1, big, 0).map(|_| ())), "cap");
        assert_eq!(name_of(g.add_edges(&[0], &[2], &[0], &[big])), "cap");
        assert_eq!(name_of(g.update_tweights(2, big, 0)), "delta_source");
        // All or nothing: the first change fits, the second would not.
        assert_eq!(
            name_of(g.update_tweights_batch(&[2, 2], &[1, big], &[0, 0])),
            "delta_source"
        );
        assert_eq!(name_of(g.set_tweights(2, 0, big)), "source_cap");
        g.add_tweights(2, 0, big / 2).unwrap();
        g.add_edge(0, 2, big / 4, 0).unwrap();
        // Negative deltas count by their magnitude too (the sum is now 1.75 · 2^62):
        // the budget bounds every intermediate value, not only the final capacities.
        assert_eq!(name_of(g.update_tweights(0, -(big / 2), 0)), "delta_source");
        assert_eq!(g.maxflow(), big / 4); // the refused calls left the graph unchanged
                                          // Edge capacities set after a reset are charged from zero again.
        g.reset();
        assert_eq!(name_of(g.set_edge_caps(0, big, big)), "cap");
        g.set_edge_caps(0, big / 2, 0).unwrap();
        g.add_tweights(0, big / 4, 0).unwrap();
        g.add_tweights(2, 0, big / 8).unwrap();
        assert_eq!(g.maxflow(), big / 8);
        // With tracked capacities the budget is checked before the new capacity is
        // formed: 2^62 + (2^62 + 2^61) would overflow (a panic in debug builds).
        let mut t = Graph::<i64>::new(1);
        t.track_terminal_caps();
        t.add_tweights(0, big, 0).unwrap();
        let huge = big + big / 2;
        assert_eq!(name_of(t.update_tweights(0, huge, 0)), "delta_source");
        assert_eq!(
            name_of(t.update_tweights_batch(&[0], &[huge], &[0])),
            "delta_source"
        );
        // Floats have no such budget (they round, and overflow only to infinity).
        let mut f = Graph::<f64>::new(2);
        for _ in 0..4 {
            f.add_tweights(0, 4.0e18, 0.0).unwrap();
        }
    }

    #[test]
    fn terminal_changes_in_a_batch_are_checked_on_their_sum() {
        let mut g = Graph::<i64>::new(2);
        g.track_terminal_caps();
        g.add_tweights(0, 3, 0).unwrap();
        g.add_edge(0, 1, 5, 0).unwrap();
        g.add_tweights(1, 0, 4).unwrap();
        // Each change alone keeps node 0's source capacity ≥ 0; together they do not.
        assert!(g
            .update_tweights_batch(&[0, 0], &[-2, -2], &[0, 0])
            .is_err());
        assert!(g.update_tweights_batch(&[0], &[1], &[0, 0]).is_err()); // lengths
        assert!(g.update_tweights_batch(&[2], &[1], &[0]).is_err()); // node index
        assert_eq!(g.maxflow(), 3); // unchanged by the refused batches
        g.update_tweights_batch(&[0, 0, 1], &[-1, 2], &[0, 0])
            .unwrap_err(); // lengths again (3 nodes, 2 deltas)
        g.update_tweights_batch(&[0, 0], &[-1, 2], &[0, 0]).unwrap();
        assert_eq!(g.maxflow(), 4); // source capacity 4, sink capacity 4
        let mut f = Graph::<f64>::new(1);
        assert!(f.update_tweights_batch(&[0], &[f64::NAN], &[0.0]).is_err());
    }

    /// Bytes per node of a solved 4-connected `h`×`w` grid graph with capacities `C`,
    /// from [`Graph::memory_bytes`]; also checks the cut and returns the graph.
    fn grid_memory<C: Capacity>(h: usize, w: usize, one: C) -> (f64, Graph<C>) {
        let e = grid_edges(h, w, 4).unwrap();
        let (s, d): (Vec<u32>, Vec<u32>) = e.iter().map(|&[i, j]| (i, j)).unzip();
        let c = vec![one; e.len()];
        let mut g = Graph::<C>::with_capacity(h * w, e.len());
        g.add_edges(&s, &d, &c, &c).unwrap();
        // Unary terms on every node (like a segmentation), one seed on each side.
        for i in 0..h * w {
            let (a, b) = if (i / w + i % w).is_multiple_of(3) {
                (one, C::ZERO)
            } else {
                (C::ZERO, one)
            };
            g.add_tweights(i, a, b).unwrap();
        }
        g.maxflow();
        (g.memory_bytes() as f64 / (h * w) as f64, g)
    }

    #[test]
    fn grid_graph_memory_per_node() {
        // Bytes per node = everything the graph holds after a solve (arcs: 4-byte head
        // + 8-byte residual, ~4 per node; node record 16; CSR offset 4; bit sets and
        // queues), divided by the node count. Must stay within 70 bytes for 8-byte
        // capacities of both kinds.
        let (h, w) = (120, 160);
        let (pf, gf) = grid_memory::<f64>(h, w, 1.0);
        let (pi, gi) = grid_memory::<i64>(h, w, 1);
        assert_eq!(gf.flow(), gi.flow() as f64);
        for per_node in [pf, pi] {
            assert!(per_node <= 70.0, "{per_node} bytes per node");
            // A real size: at least the arcs, node records and offsets themselves.
            let arcs = 2 * grid_edges(h, w, 4).unwrap().len();
            let floor = (arcs * 12 + h * w * 20) as f64 / (h * w) as f64;
            assert!(per_node >= floor, "{per_node} < {floor}");
        }
        // The same graph solved again after a change still fits (queues are reused).
        let mut g = gf;
        g.update_tweights(5, 3.0, 0.0).unwrap();
        g.maxflow();
        assert!(g.memory_bytes() as f64 / (h * w) as f64 <= 70.0);
    }

    #[test]
    fn grid_edges_count() {
        assert_eq!(grid_edges(3, 4, 4).unwrap().len(), 3 * 3 + 2 * 4);
        assert_eq!(
            grid_edges(3, 4, 8).unwrap().len(),
            3 * 3 + 2 * 4 + 2 * 2 * 3
        );
    }

    #[test]
    fn grid_segmentation_matches_brute_force() {
        // 3×4 grid with random-ish integer data: 12 nodes, exhaustive check.
        let (h, w) = (3, 4);
        for conn in [4u8, 8] {
            let e = grid_edges(h, w, conn).unwrap();
            let p = Problem {
                n: h * w,
                edges: e
                    .iter()
                    .enumerate()
                    .map(|(k, &[i, j])| {
                        (
                            i as usize,
                            j as usize,
                            (k * 7 % 5) as i64,
                            (k * 3 % 4) as i64,
                        )
                    })
                    .collect(),
                terms: (0..h * w)
                    .map(|i| ((i * 5 % 9) as i64, (i * 11 % 7) as i64))
                    .collect(),
            };
            let mut g = graph_of(&p);
            assert_eq!(g.maxflow(), brute_min_cut(&p));
            check_flow(&p, &g, true);
        }
    }
}
