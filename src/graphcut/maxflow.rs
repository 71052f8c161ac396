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
//! Layout: nodes are structure-of-arrays with `u32` indices; arcs are one array grouped by
//! tail (CSR), built once from the edge list on the first solve. Each edge gives two
//! arcs that know each other (`sister`). Terminal arcs are folded into one signed
//! residual per node (`> 0`: from the source, `< 0`: to the sink).

use crate::error::{Error, Result};
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
}

impl Capacity for i64 {
    const ZERO: Self = 0;
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
}

/// "No node / no arc" and the special parent markers (indices are `u32`).
const NONE: u32 = u32::MAX;
const TERMINAL: u32 = u32::MAX - 1;
const ORPHAN: u32 = u32::MAX - 2;
/// Largest usable node or arc index (the top values are markers).
const MAX_INDEX: usize = (u32::MAX - 3) as usize;
/// Distance meaning "not connected to a terminal" during adoption.
const INFINITE_DIST: u32 = u32::MAX;

const FLAG_SINK: u8 = 1;
const FLAG_CHANGED: u8 = 2;

/// Search state of a node.
#[derive(Clone, Copy, Debug)]
struct Node<C> {
    /// Residual terminal capacity: `> 0` from the source, `< 0` to the sink.
    tr: C,
    /// Arc to the parent in the search tree, or `NONE` (free), `TERMINAL`, `ORPHAN`.
    parent: u32,
    /// Active queue as a linked list (`NONE` = not queued, self = last).
    next: u32,
    /// Time stamp and distance to the terminal of the adoption heuristic.
    ts: u32,
    /// Saturates at `u16::MAX`: the distance only steers heuristics (see `sat16`).
    dist: u16,
    flags: u8,
}

/// A distance stored in 16 bits (keeps a node record at 24 bytes for `f64`). Saturation
/// only weakens the shortest-path preference on paths longer than 65,535 nodes; the
/// adoption walk never relies on exact values for correctness.
#[inline(always)]
fn sat16(d: u32) -> u16 {
    d.min(u32::from(u16::MAX)) as u16
}

impl<C: Capacity> Default for Node<C> {
    fn default() -> Self {
        Node {
            tr: C::ZERO,
            parent: NONE,
            next: NONE,
            ts: 0,
            dist: 0,
            flags: 0,
        }
    }
}

/// One direction of an edge: its head, its reverse arc and its residual capacity.
#[derive(Clone, Copy, Debug, Default)]
struct Arc<C> {
    head: u32,
    sister: u32,
    cap: C,
}

/// A directed graph with two terminals, for max-flow / min-cut.
///
/// Build with [`Graph::add_edge`] / [`Graph::add_tweights`] (or their batch forms),
/// solve with [`Graph::maxflow`], read the cut with [`Graph::is_sink_side`]. After a
/// solve, terminal capacities may be changed ([`Graph::update_tweights`],
/// [`Graph::set_tweights`]) and `maxflow` called again: it reuses the residual graph
/// and the search trees.
#[derive(Clone, Debug)]
pub struct Graph<C: Capacity> {
    n: usize,
    /// Edges added since the last build: (i, j, cap i→j, cap j→i).
    pending: Vec<(u32, u32, C, C)>,
    /// CSR: arcs of node `i` are `arcs[first[i]..first[i + 1]]`.
    first: Vec<u32>,
    arcs: Vec<Arc<C>>,
    /// Arc i→j of edge `k` (in order of addition), `NONE` for self-loops; kept only
    /// after [`Graph::keep_edge_index`] (4 bytes per edge).
    edge_arc: Vec<u32>,
    index_edges: bool,
    /// Edges in the built arc arrays (including self-loops, which have no arcs).
    n_edges: usize,
    /// Per-node search state (one record per node, so a visit touches one cache line).
    nodes: Vec<Node<C>>,
    /// Nodes whose terminal capacities changed since the last solve.
    changed: Vec<u32>,
    /// Accumulated terminal capacities per node, kept only for `set_tweights`.
    terminal_caps: Option<Vec<[C; 2]>>,
    flow: C,
    time: u32,
    queue_first: u32,
    queue_last: u32,
    orphans: VecDeque<u32>,
    /// True once `maxflow` ran and the trees describe the residual graph.
    trees_valid: bool,
}

impl<C: Capacity> Graph<C> {
    /// A graph of `n_nodes` nodes and no edges.
    pub fn new(n_nodes: usize) -> Self {
        Self::with_capacity(n_nodes, 0)
    }

    /// Like [`Graph::new`], reserving room for `edge_hint` edges.
    pub fn with_capacity(n_nodes: usize, edge_hint: usize) -> Self {
        match Self::try_with_capacity(n_nodes.min(MAX_INDEX), edge_hint) {
            Ok(g) => g,
            Err(e) => panic!("{e}"),
        }
    }

    /// Like [`Graph::with_capacity`], but fails (instead of aborting) when `n_nodes` is
    /// too large for `u32` indices or the memory cannot be had.
    pub fn try_with_capacity(n_nodes: usize, edge_hint: usize) -> Result<Self> {
        if n_nodes > MAX_INDEX {
            return Err(Error::invalid(
                "n_nodes",
                format!("{n_nodes} nodes exceed the u32 index range"),
            ));
        }
        let oom = |what: &str| Error::invalid(what, "not enough memory for the requested size");
        let mut pending = Vec::new();
        pending
            .try_reserve_exact(edge_hint)
            .map_err(|_| oom("edge_hint"))?;
        let mut first = Vec::new();
        first
            .try_reserve_exact(n_nodes + 1)
            .map_err(|_| oom("n_nodes"))?;
        first.resize(n_nodes + 1, 0);
        let mut nodes = Vec::new();
        nodes
            .try_reserve_exact(n_nodes)
            .map_err(|_| oom("n_nodes"))?;
        nodes.resize(n_nodes, Node::default());
        Ok(Graph {
            n: n_nodes,
            pending,
            first,
            arcs: Vec::new(),
            edge_arc: Vec::new(),
            index_edges: false,
            n_edges: 0,
            nodes,
            changed: Vec::new(),
            terminal_caps: None,
            flow: C::ZERO,
            time: 0,
            queue_first: NONE,
            queue_last: NONE,
            orphans: VecDeque::new(),
            trees_valid: false,
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

    /// Heap bytes held by the graph's node and arc arrays.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.first.capacity() * 4
            + self.arcs.capacity() * size_of::<Arc<C>>()
            + self.edge_arc.capacity() * 4
            + self.pending.capacity() * size_of::<(u32, u32, C, C)>()
            + self.nodes.capacity() * size_of::<Node<C>>()
            + self.changed.capacity() * 4
            + self
                .terminal_caps
                .as_ref()
                .map_or(0, |t| t.capacity() * 2 * size_of::<C>())
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

    /// Adds an edge with capacity `cap` from `i` to `j` and `rev_cap` from `j` to `i`.
    /// Parallel edges add up; self-loops are ignored. Returns the edge's index.
    pub fn add_edge(&mut self, i: usize, j: usize, cap: C, rev_cap: C) -> Result<usize> {
        self.check_node(i, "i")?;
        self.check_node(j, "j")?;
        Self::check_cap(cap, "cap")?;
        Self::check_cap(rev_cap, "rev_cap")?;
        if self.n_edges() >= MAX_INDEX / 2 {
            return Err(Error::invalid(
                "edges",
                "too many edges for u32 arc indices",
            ));
        }
        self.pending.push((i as u32, j as u32, cap, rev_cap));
        Ok(self.n_edges() - 1)
    }

    /// Adds many edges at once (all arrays of one length); nothing is added on error.
    pub fn add_edges(&mut self, src: &[u32], dst: &[u32], cap: &[C], rev_cap: &[C]) -> Result<()> {
        let m = src.len();
        for (name, len) in [
            ("dst", dst.len()),
            ("cap", cap.len()),
            ("rev_cap", rev_cap.len()),
        ] {
            if len != m {
                return Err(Error::invalid(
                    name,
                    format!("length {len} does not match src length {m}"),
                ));
            }
        }
        for (name, idx) in [("src", src), ("dst", dst)] {
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
        for (name, c) in [("cap", cap), ("rev_cap", rev_cap)] {
            if let Some(k) = c
                .iter()
                .position(|&v| !(v.is_finite_value() && v >= C::ZERO))
            {
                return Err(Error::invalid(
                    name,
                    format!(
                        "capacities must be finite and non-negative, got {:?} at position {k}",
                        c[k]
                    ),
                ));
            }
        }
        if self.n_edges() + m > MAX_INDEX / 2 {
            return Err(Error::invalid("src", "too many edges for u32 arc indices"));
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
        let m = nodes.len();
        for (name, len) in [
            ("source_cap", source_cap.len()),
            ("sink_cap", sink_cap.len()),
        ] {
            if len != m {
                return Err(Error::invalid(
                    name,
                    format!("length {len} does not match nodes length {m}"),
                ));
            }
        }
        if let Some(k) = nodes.iter().position(|&v| v as usize >= self.n) {
            return Err(Error::invalid(
                "nodes",
                format!(
                    "node index {} at position {k} out of range for {} nodes",
                    nodes[k], self.n
                ),
            ));
        }
        for (name, c) in [("source_cap", source_cap), ("sink_cap", sink_cap)] {
            if let Some(k) = c
                .iter()
                .position(|&v| !(v.is_finite_value() && v >= C::ZERO))
            {
                return Err(Error::invalid(
                    name,
                    format!(
                        "capacities must be finite and non-negative, got {:?} at position {k}",
                        c[k]
                    ),
                ));
            }
        }
        for k in 0..m {
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
        if let Some(t) = &self.terminal_caps {
            let [s, k] = t[i];
            if s + delta_source < C::ZERO || k + delta_sink < C::ZERO {
                return Err(Error::invalid(
                    "delta_source",
                    "the change would make a terminal capacity negative",
                ));
            }
        }
        self.update_tweights_unchecked(i, delta_source, delta_sink);
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
        self.update_tweights_unchecked(i, source_cap - s, sink_cap - k);
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
        if self.trees_valid && self.nodes[i].flags & FLAG_CHANGED == 0 {
            self.nodes[i].flags |= FLAG_CHANGED;
            self.changed.push(i as u32);
        }
    }

    /// Builds the CSR arc arrays from all edges (keeping residuals of existing arcs).
    fn build(&mut self) {
        let mut edges: Vec<(u32, u32, C, C)> = Vec::with_capacity(self.n_edges());
        if self.index_edges {
            for &a in &self.edge_arc {
                if a == NONE {
                    edges.push((0, 0, C::ZERO, C::ZERO));
                    continue;
                }
                let arc = self.arcs[a as usize];
                let sis = self.arcs[arc.sister as usize];
                edges.push((sis.head, arc.head, arc.cap, sis.cap));
            }
        } else {
            // Without an index, recover each built edge from its lower-numbered arc.
            for i in 0..self.n {
                for a in self.first[i]..self.first[i + 1] {
                    let arc = self.arcs[a as usize];
                    if a < arc.sister {
                        let sis = self.arcs[arc.sister as usize];
                        edges.push((i as u32, arc.head, arc.cap, sis.cap));
                    }
                }
            }
        }
        let n_edges = self.n_edges + self.pending.len();
        edges.append(&mut self.pending);
        self.pending = Vec::new();
        let n = self.n;
        let mut deg = vec![0u32; n + 1];
        for &(i, j, _, _) in &edges {
            if i != j {
                deg[i as usize] += 1;
                deg[j as usize] += 1;
            }
        }
        let mut first = vec![0u32; n + 1];
        let mut acc = 0u32;
        for i in 0..n {
            first[i] = acc;
            acc += deg[i];
        }
        first[n] = acc;
        // Each node's arcs are filled from the end, so the most recently added edge is
        // scanned first (like the linked arc lists of the reference implementation; the
        // scan order shapes the search trees and measurably affects speed on grids).
        let mut pos: Vec<u32> = first[1..].to_vec();
        let mut arcs = vec![Arc::default(); acc as usize];
        let keep = self.index_edges;
        let mut edge_arc = Vec::with_capacity(if keep { edges.len() } else { 0 });
        for &(i, j, c, r) in &edges {
            if i == j {
                if keep {
                    edge_arc.push(NONE);
                }
                continue;
            }
            pos[i as usize] -= 1;
            let a = pos[i as usize];
            pos[j as usize] -= 1;
            let b = pos[j as usize];
            arcs[a as usize] = Arc {
                head: j,
                sister: b,
                cap: c,
            };
            arcs[b as usize] = Arc {
                head: i,
                sister: a,
                cap: r,
            };
            if keep {
                edge_arc.push(a);
            }
        }
        self.n_edges = n_edges;
        self.first = first;
        self.arcs = arcs;
        self.edge_arc = edge_arc;
        self.trees_valid = false;
    }

    /// Builds the arc arrays now (otherwise done by the first [`Graph::maxflow`]), so
    /// that [`Graph::set_edge_caps`] can be used.
    pub fn finalize(&mut self) {
        if !self.pending.is_empty() || self.index_edges && self.edge_arc.len() != self.n_edges {
            self.build();
        }
    }

    /// Clears all flow, capacities and search trees, keeping the structure (for reuse
    /// with new capacities: [`Graph::set_edge_caps`], [`Graph::add_tweights`]).
    pub fn reset(&mut self) {
        self.finalize();
        for a in &mut self.arcs {
            a.cap = C::ZERO;
        }
        for v in &mut self.nodes {
            v.tr = C::ZERO;
        }
        if let Some(t) = &mut self.terminal_caps {
            t.fill([C::ZERO; 2]);
        }
        for &i in &self.changed {
            self.nodes[i as usize].flags &= !FLAG_CHANGED;
        }
        self.changed.clear();
        self.flow = C::ZERO;
        self.trees_valid = false;
    }

    /// Sets the capacities of edge `k` (its index from [`Graph::add_edge`] or the order of
    /// the batch), for a graph that was [`Graph::reset`] or finalized and not yet solved.
    pub(crate) fn set_edge_caps_unchecked(&mut self, k: usize, cap: C, rev_cap: C) {
        let a = self.edge_arc[k];
        if a != NONE {
            let arc = &mut self.arcs[a as usize];
            arc.cap = cap;
            let s = arc.sister as usize;
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
        self.set_edge_caps_unchecked(k, cap, rev_cap);
        Ok(())
    }

    /// True if node `i` is on the sink side of the minimum cut found by the last
    /// [`Graph::maxflow`] (nodes that can reach the sink in the residual graph).
    #[inline]
    pub fn is_sink_side(&self, i: usize) -> bool {
        self.nodes[i].parent != NONE && self.nodes[i].flags & FLAG_SINK != 0
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
        if a == NONE {
            return Some((C::ZERO, C::ZERO));
        }
        let arc = self.arcs[a as usize];
        Some((arc.cap, self.arcs[arc.sister as usize].cap))
    }

    /// The signed residual terminal capacity of `i` (> 0 source→i, < 0 i→sink).
    pub fn terminal_residual(&self, i: usize) -> C {
        self.nodes[i].tr
    }

    // ----- the active queue -----

    #[inline(always)]
    fn activate(&mut self, i: u32) {
        push_active(
            &mut self.nodes,
            &mut self.queue_first,
            &mut self.queue_last,
            i,
        );
    }

    #[inline(always)]
    fn pop_active(&mut self) -> Option<u32> {
        let i = self.queue_first;
        if i == NONE {
            return None;
        }
        let nx = self.nodes[i as usize].next;
        if nx == i {
            self.queue_first = NONE;
            self.queue_last = NONE;
        } else {
            self.queue_first = nx;
        }
        self.nodes[i as usize].next = NONE;
        Some(i)
    }

    #[inline(always)]
    fn is_sink(&self, i: usize) -> bool {
        self.nodes[i].flags & FLAG_SINK != 0
    }

    #[inline(always)]
    fn set_tree(&mut self, i: usize, sink: bool) {
        if sink {
            self.nodes[i].flags |= FLAG_SINK;
        } else {
            self.nodes[i].flags &= !FLAG_SINK;
        }
    }

    #[inline(always)]
    fn make_orphan(&mut self, i: u32) {
        self.nodes[i as usize].parent = ORPHAN;
        self.orphans.push_back(i);
    }

    fn init_fresh(&mut self) {
        self.queue_first = NONE;
        self.queue_last = NONE;
        self.orphans.clear();
        self.time = 0;
        for i in 0..self.n {
            self.nodes[i].next = NONE;
            self.nodes[i].ts = 0;
            self.nodes[i].flags &= !FLAG_CHANGED;
            let t = self.nodes[i].tr;
            if t > C::ZERO {
                self.set_tree(i, false);
                self.nodes[i].parent = TERMINAL;
                self.nodes[i].dist = 1;
                self.activate(i as u32);
            } else if t < C::ZERO {
                self.set_tree(i, true);
                self.nodes[i].parent = TERMINAL;
                self.nodes[i].dist = 1;
                self.activate(i as u32);
            } else {
                self.nodes[i].parent = NONE;
                self.nodes[i].dist = 0;
            }
        }
        self.changed.clear();
    }

    /// Repairs the trees of the previous solve around nodes whose terminal capacities
    /// changed: such a node becomes a root of the tree its residual points to (switching
    /// trees orphans its old children), or an orphan if it lost its terminal arc.
    fn init_reuse(&mut self) {
        self.queue_first = NONE;
        self.queue_last = NONE;
        self.orphans.clear();
        self.time = self.time.wrapping_add(1);
        let changed = std::mem::take(&mut self.changed);
        for &iu in &changed {
            let i = iu as usize;
            self.nodes[i].flags &= !FLAG_CHANGED;
            let t = self.nodes[i].tr;
            let in_tree = self.nodes[i].parent != NONE;
            if t == C::ZERO {
                if self.nodes[i].parent == TERMINAL {
                    self.make_orphan(iu);
                } else if in_tree {
                    self.activate(iu);
                }
                continue;
            }
            let want_sink = t < C::ZERO;
            if in_tree && self.is_sink(i) != want_sink {
                // Children in the old tree lose their parent, and every tree neighbour
                // is re-activated: those of the old tree may have to grow into `i`
                // again once it leaves the new tree.
                for a in self.first[i]..self.first[i + 1] {
                    let j = self.arcs[a as usize].head as usize;
                    let p = self.nodes[j].parent;
                    if p != NONE {
                        self.activate(j as u32);
                    }
                    if p != NONE
                        && p != TERMINAL
                        && p != ORPHAN
                        && self.arcs[p as usize].head as usize == i
                    {
                        self.make_orphan(j as u32);
                    }
                }
            }
            self.set_tree(i, want_sink);
            self.nodes[i].parent = TERMINAL;
            self.nodes[i].ts = self.time;
            self.nodes[i].dist = 1;
            self.activate(iu);
        }
        self.changed = changed;
        self.changed.clear();
        self.adopt();
    }

    /// Computes the maximum flow (and so the minimum cut) and returns its value. Called
    /// again after terminal capacity changes, it continues from the previous state.
    pub fn maxflow(&mut self) -> C {
        if !self.pending.is_empty() || self.index_edges && self.edge_arc.len() != self.n_edges {
            self.build();
        }
        if self.trees_valid {
            self.init_reuse();
        } else {
            self.init_fresh();
        }
        self.run();
        self.trees_valid = true;
        self.flow
    }

    fn run(&mut self) {
        let mut current = NONE;
        loop {
            let i = if current != NONE && self.nodes[current as usize].parent != NONE {
                current
            } else {
                match self.pop_active() {
                    None => break,
                    Some(i) if self.nodes[i as usize].parent == NONE => continue,
                    Some(i) => i,
                }
            };
            current = NONE;
            let mid = self.grow(i as usize);
            if mid != NONE {
                self.time = self.time.wrapping_add(1);
                // Keep scanning `i` after the augmentation: it may have more paths.
                current = i;
                self.augment(mid);
                self.adopt();
            }
        }
    }

    /// Grows the tree of `i` by one step over its arcs; returns the arc (S side → T side)
    /// of a path found, or `NONE`.
    #[inline]
    fn grow(&mut self, i: usize) -> u32 {
        // Local slices let the optimiser keep the array pointers in registers.
        let arcs: &[Arc<C>] = &self.arcs;
        let nodes: &mut [Node<C>] = &mut self.nodes;
        let (mut qf, mut ql) = (self.queue_first, self.queue_last);
        let (lo, hi) = (self.first[i] as usize, self.first[i + 1] as usize);
        let ni = nodes[i];
        let (ts_i, dist_i) = (ni.ts, u32::from(ni.dist));
        let d1 = sat16(dist_i + 1);
        let sink = ni.flags & FLAG_SINK != 0;
        let mut found = NONE;
        for (k, arc) in arcs[lo..hi].iter().enumerate() {
            // Residual capacity away from the root: i→j in S, j→i in T.
            let open = if sink {
                arcs[arc.sister as usize].cap > C::ZERO
            } else {
                arc.cap > C::ZERO
            };
            if !open {
                continue;
            }
            let j = arc.head as usize;
            let nj = &mut nodes[j];
            if nj.parent == NONE {
                nj.flags = if sink {
                    nj.flags | FLAG_SINK
                } else {
                    nj.flags & !FLAG_SINK
                };
                nj.parent = arc.sister;
                nj.ts = ts_i;
                nj.dist = d1;
                push_active(nodes, &mut qf, &mut ql, j as u32);
            } else if (nj.flags & FLAG_SINK != 0) != sink {
                found = if sink { arc.sister } else { (lo + k) as u32 };
                break;
            } else if nj.ts <= ts_i && u32::from(nj.dist) > dist_i {
                // Shortcut: `i` gives `j` a shorter, as fresh path to the root.
                nj.parent = arc.sister;
                nj.ts = ts_i;
                nj.dist = d1;
            }
        }
        self.queue_first = qf;
        self.queue_last = ql;
        found
    }

    /// Pushes the bottleneck flow along source → … → tail(mid) → head(mid) → … → sink;
    /// nodes whose tree arc saturates become orphans (queued at the front, so those
    /// nearer the terminals, found last, are adopted first).
    fn augment(&mut self, mid: u32) {
        let arcs: &mut [Arc<C>] = &mut self.arcs;
        let nodes: &mut [Node<C>] = &mut self.nodes;
        let orphans = &mut self.orphans;
        let m = arcs[mid as usize];
        let u = arcs[m.sister as usize].head as usize;
        let v = m.head as usize;
        let mut f = m.cap;
        let mut x = u;
        loop {
            let p = nodes[x].parent;
            if p == TERMINAL {
                f = f.min_of(nodes[x].tr);
                break;
            }
            let arc = arcs[p as usize];
            f = f.min_of(arcs[arc.sister as usize].cap);
            x = arc.head as usize;
        }
        x = v;
        loop {
            let p = nodes[x].parent;
            if p == TERMINAL {
                f = f.min_of(-nodes[x].tr);
                break;
            }
            let arc = arcs[p as usize];
            f = f.min_of(arc.cap);
            x = arc.head as usize;
        }
        arcs[mid as usize].cap -= f;
        arcs[m.sister as usize].cap += f;
        x = u;
        loop {
            let p = nodes[x].parent;
            if p == TERMINAL {
                nodes[x].tr -= f;
                if nodes[x].tr <= C::ZERO {
                    nodes[x].parent = ORPHAN;
                    orphans.push_front(x as u32);
                }
                break;
            }
            let arc = arcs[p as usize];
            let s = arc.sister as usize;
            arcs[s].cap -= f;
            arcs[p as usize].cap += f;
            if arcs[s].cap <= C::ZERO {
                nodes[x].parent = ORPHAN;
                orphans.push_front(x as u32);
            }
            x = arc.head as usize;
        }
        x = v;
        loop {
            let p = nodes[x].parent;
            if p == TERMINAL {
                nodes[x].tr += f;
                if nodes[x].tr >= C::ZERO {
                    nodes[x].parent = ORPHAN;
                    orphans.push_front(x as u32);
                }
                break;
            }
            let arc = arcs[p as usize];
            arcs[p as usize].cap -= f;
            arcs[arc.sister as usize].cap += f;
            if arcs[p as usize].cap <= C::ZERO {
                nodes[x].parent = ORPHAN;
                orphans.push_front(x as u32);
            }
            x = arc.head as usize;
        }
        self.flow += f;
    }

    fn adopt(&mut self) {
        while let Some(i) = self.orphans.pop_front() {
            // A queued orphan may have been made a root since (dynamic updates).
            if self.nodes[i as usize].parent != ORPHAN {
                continue;
            }
            self.process_orphan(i as usize);
        }
    }

    fn process_orphan(&mut self, i: usize) {
        let arcs: &[Arc<C>] = &self.arcs;
        let nodes: &mut [Node<C>] = &mut self.nodes;
        let time = self.time;
        let sink = nodes[i].flags & FLAG_SINK != 0;
        let (lo, hi) = (self.first[i] as usize, self.first[i + 1] as usize);
        let mut best = NONE;
        let mut best_d = INFINITE_DIST;
        for a in lo..hi {
            let arc = arcs[a];
            // Residual capacity from the candidate parent towards `i` (S) or from `i`
            // towards the candidate (T).
            let ok = if sink {
                arc.cap > C::ZERO
            } else {
                arcs[arc.sister as usize].cap > C::ZERO
            };
            if !ok {
                continue;
            }
            let j = arc.head as usize;
            let nj = nodes[j];
            if nj.parent == NONE || (nj.flags & FLAG_SINK != 0) != sink {
                continue;
            }
            let d = origin_distance(arcs, nodes, time, j);
            if d < best_d {
                best = a as u32;
                best_d = d;
            }
        }
        if best != NONE {
            nodes[i].parent = best;
            nodes[i].ts = time;
            nodes[i].dist = sat16(best_d + 1);
            return;
        }
        // No parent: `i` becomes free; its children become orphans and neighbours that
        // could grow into it become active.
        nodes[i].parent = NONE;
        let (mut qf, mut ql) = (self.queue_first, self.queue_last);
        for a in lo..hi {
            let arc = arcs[a];
            let j = arc.head as usize;
            let p = nodes[j].parent;
            if p == NONE || (nodes[j].flags & FLAG_SINK != 0) != sink {
                continue;
            }
            let can_grow = if sink {
                arc.cap > C::ZERO
            } else {
                arcs[arc.sister as usize].cap > C::ZERO
            };
            if can_grow {
                push_active(nodes, &mut qf, &mut ql, j as u32);
            }
            if p != TERMINAL && p != ORPHAN && arcs[p as usize].head as usize == i {
                nodes[j].parent = ORPHAN;
                self.orphans.push_back(j as u32);
            }
        }
        self.queue_first = qf;
        self.queue_last = ql;
    }
}

/// Appends `i` to the active queue (a linked list through `next`) unless queued.
#[inline(always)]
fn push_active<C: Capacity>(nodes: &mut [Node<C>], first: &mut u32, last: &mut u32, i: u32) {
    let iu = i as usize;
    if nodes[iu].next == NONE {
        nodes[iu].next = i;
        if *last == NONE {
            *first = i;
        } else {
            nodes[*last as usize].next = i;
        }
        *last = i;
    }
}

/// Distance from `j` to its tree's terminal, following parents, or `INFINITE_DIST` if
/// the path ends at an orphan. Marks the nodes it verifies with `time`, recording their
/// distances for later searches.
#[inline]
fn origin_distance<C: Capacity>(
    arcs: &[Arc<C>],
    nodes: &mut [Node<C>],
    time: u32,
    j: usize,
) -> u32 {
    let mut d = 0u32;
    let mut k = j;
    loop {
        let nk = nodes[k];
        if nk.ts == time {
            d += u32::from(nk.dist);
            break;
        }
        let p = nk.parent;
        d += 1;
        if p == TERMINAL {
            nodes[k].ts = time;
            nodes[k].dist = 1;
            break;
        }
        if p == ORPHAN {
            return INFINITE_DIST;
        }
        k = arcs[p as usize].head as usize;
    }
    let mut dd = d;
    k = j;
    while nodes[k].ts != time {
        nodes[k].ts = time;
        nodes[k].dist = sat16(dd);
        dd -= 1;
        k = arcs[nodes[k].parent as usize].head as usize;
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
    if h.checked_mul(w).is_none_or(|n| n > MAX_INDEX) {
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
            let mut q = p.clone();
            for &(i, s, t) in &changes {
                let i = i % p.n;
                q.terms[i] = (s, t);
                g.set_tweights(i, s, t).unwrap();
            }
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

    #[test]
    fn grid_graph_memory_per_node() {
        // 4 arcs of 16 bytes, a 24-byte node record and a 4-byte arc offset per node.
        let (h, w) = (64, 64);
        let e = grid_edges(h, w, 4).unwrap();
        let (s, d): (Vec<u32>, Vec<u32>) = e.iter().map(|&[i, j]| (i, j)).unzip();
        let c = vec![1.0; e.len()];
        let mut g = Graph::<f64>::with_capacity(h * w, e.len());
        g.add_edges(&s, &d, &c, &c).unwrap();
        g.add_tweights(0, 1.0, 0.0).unwrap();
        g.add_tweights(h * w - 1, 0.0, 1.0).unwrap();
        assert_eq!(g.maxflow(), 1.0);
        let per_node = g.memory_bytes() as f64 / (h * w) as f64;
        assert!(per_node <= 92.0, "{per_node} bytes per node");
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
