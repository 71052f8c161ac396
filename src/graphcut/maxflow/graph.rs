//! Making a [`Graph`] and giving it edges and terminal capacities, with the checks
//! that keep integer capacities exact.

use super::capacity::Capacity;
use super::layout::{ArcRec, Node, MAX_ARCS, MAX_NODES, MAX_TIME};
use super::queue::ActiveQueue;
use super::Graph;
use crate::error::{Error, Result};
use crate::graphcut::bitset::BitSet;
use std::collections::VecDeque;

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

    pub(super) fn check_node(&self, i: usize, name: &str) -> Result<()> {
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

    pub(super) fn check_cap(c: C, name: &str) -> Result<()> {
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
    pub(super) fn check_batch(
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
    pub(super) fn check_values(arrays: &[(&str, &[C])], capacities: bool) -> Result<()> {
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
    pub(super) fn charged(&self, name: &str, values: impl Iterator<Item = C>) -> Result<u128> {
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
}
