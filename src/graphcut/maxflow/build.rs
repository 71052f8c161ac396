//! Building the arc arrays from the edge list, resetting a graph for reuse, and
//! reading the cut and residuals.

use super::capacity::Capacity;
use super::layout::{
    sister_of, ArcRec, FREE, HEAD_BITS, HEAD_MASK, HINT_OVERFLOW, NO_ARC, SINK_BIT,
};
use super::Graph;
use crate::error::{Error, Result};

impl<C: Capacity> Graph<C> {
    /// The reverse arc of arc `a`.
    #[inline(always)]
    pub(super) fn sister(&self, a: usize) -> usize {
        sister_of(&self.nodes, &self.overflow, a, self.arcs[a].hw)
    }

    /// Builds the CSR arc arrays from all edges (keeping residuals of existing arcs).
    pub(super) fn build(&mut self) {
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
    pub(super) fn build_from(&mut self, m: usize, edge: impl Fn(usize) -> (u32, u32, C, C)) {
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

    pub(super) fn needs_build(&self) -> bool {
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
    pub(super) fn forget_solve(&mut self) {
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
    pub(super) fn free_node(&mut self, i: usize) {
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
}
