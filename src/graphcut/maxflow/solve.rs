//! A solve: fresh, seeded or resumed from the residual graph of the last one.

use super::capacity::Capacity;
use super::layout::{is_arc, pack_tsd, FREE, HEAD_MASK, SINK_BIT, TERMINAL};
#[cfg(test)]
use super::layout::{MAX_TIME, ORPHAN};
use super::search::Search;
use super::Graph;

impl<C: Capacity> Graph<C> {
    /// Makes the adoption clock restart every `max_time` ticks instead of 65,535, so
    /// tests can exercise the restart on small graphs.
    #[cfg(test)]
    pub(super) fn set_max_time(&mut self, max_time: u32) {
        self.max_time = max_time.clamp(1, MAX_TIME);
    }

    /// Runs `f` on the search over the whole graph, then keeps its clock and flow.
    pub(super) fn with_search<R>(&mut self, f: impl FnOnce(&mut Search<'_, C, false>) -> R) -> R {
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

    pub(super) fn init_fresh(&mut self) {
        self.forget_search();
        self.with_search(|s| s.start_fresh());
    }

    /// The part of a fresh solve's start shared by [`Self::init_fresh`] and
    /// [`Self::init_seeded`]: no active nodes, orphans, clock or pending changes.
    pub(super) fn forget_search(&mut self) {
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
    pub(super) fn init_seeded(&mut self, seeds: &[u32]) {
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
    pub(super) fn init_reuse(&mut self) {
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

    pub(super) fn solve(&mut self, seeds: Option<&[u32]>) -> C {
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

    /// Asserts that every tree node's parent path reaches its tree's terminal without
    /// a cycle, an orphan or a free node on the way (tests only).
    #[cfg(test)]
    pub(super) fn check_trees(&self) {
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
