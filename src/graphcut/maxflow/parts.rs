//! Parallel fresh solves: the graph split into bands of node indices solved on
//! separate threads, then one search over the whole graph.

use super::capacity::Capacity;
use super::layout::{ArcRec, Node, FREE};
use super::queue::ActiveQueue;
use super::search::Search;
use super::Graph;
use rayon::prelude::*;
use std::collections::VecDeque;

/// Fewest nodes per part of a parallel fresh solve ([`Graph::parallel_parts`]).
pub(super) const MIN_PART_NODES: usize = 16_384;
/// A part of a parallel fresh solve spans at least this many times the graph's
/// bandwidth, so that few of its nodes have arcs into other parts.
pub(super) const PART_BANDWIDTHS: usize = 32;
/// Most parts of a parallel fresh solve: the last, whole-graph search grows with the
/// number of borders.
pub(super) const MAX_PARTS: usize = 8;
impl<C: Capacity> Graph<C> {
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
    pub(super) fn force_parts(&mut self, k: usize) {
        self.parts_override = Some(k);
    }

    /// A fresh solve in `k` parts (see [`Graph::parallel_parts`]).
    pub(super) fn solve_in_parts(&mut self, k: usize) {
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
}
