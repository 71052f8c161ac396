//! The search trees of one solve: growth, augmentation and adoption.

use super::capacity::Capacity;
use super::layout::{
    dist_of, is_arc, pack_tsd, sister_at, ts_of, ArcRec, Node, FREE, HEAD_MASK, INFINITE_DIST,
    ORPHAN, SINK_BIT, TERMINAL,
};
use super::queue::ActiveQueue;
use std::collections::VecDeque;

/// The node index of head word `hw` relative to `node_base` (wraps to a huge value
/// below it, so that `nodes.get` rejects it like an index past the end).
#[inline(always)]
pub(super) fn local(hw: u32, node_base: u32) -> usize {
    (hw & HEAD_MASK).wrapping_sub(node_base) as usize
}

/// The global index of the reverse of global arc `a` (whose head is in the range).
#[inline(always)]
pub(super) fn sister_in<C: Copy>(
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
pub(super) struct Search<'g, C: Capacity, const PART: bool> {
    /// The range's node records; the whole graph's end record may follow them.
    pub(super) nodes: &'g mut [Node<C>],
    /// The arcs of the range's nodes.
    pub(super) arcs: &'g mut [ArcRec<C>],
    pub(super) overflow: &'g [(u32, u32)],
    /// Global index of `nodes[0]` and of `arcs[0]`.
    pub(super) node_base: u32,
    pub(super) arc_base: u32,
    /// Global index where the arcs of the range's last node end.
    pub(super) arc_end: u32,
    /// Nodes in the range.
    pub(super) n: usize,
    pub(super) active: ActiveQueue,
    pub(super) orphans: VecDeque<u32>,
    pub(super) time: u32,
    pub(super) max_time: u32,
    pub(super) flow: C,
    /// The clock restarted: nodes outside the trees may hold a time stamp.
    pub(super) restarted: bool,
}

impl<C: Capacity, const PART: bool> Search<'_, C, PART> {
    /// Global index of the range's first node (0 for the whole graph, known at compile
    /// time there: the whole-graph search pays nothing for the parts).
    #[inline(always)]
    pub(super) fn node_base(&self) -> u32 {
        if PART {
            self.node_base
        } else {
            0
        }
    }

    /// Global index of the range's first arc.
    #[inline(always)]
    pub(super) fn arc_base(&self) -> u32 {
        if PART {
            self.arc_base
        } else {
            0
        }
    }

    /// The arcs of local node `i`, as local arc indices.
    #[inline(always)]
    pub(super) fn arc_range(
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
    pub(super) fn make_orphan(&mut self, i: u32) {
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
    pub(super) fn tick(&mut self) {
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
    pub(super) fn start_fresh(&mut self) {
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
    pub(super) fn push_short_paths(&mut self, i: usize) {
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
    pub(super) fn start_root(&mut self, i: usize) -> bool {
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

    pub(super) fn run(&mut self) {
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
    pub(super) fn grow(&mut self, i: usize) -> u32 {
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
    pub(super) fn augment(&mut self, mid: usize) {
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

    pub(super) fn adopt(&mut self) {
        while let Some(i) = self.orphans.pop_front() {
            // A queued orphan may have been made a root since (dynamic updates).
            if self.nodes[i as usize].parent & !SINK_BIT != ORPHAN {
                continue;
            }
            self.process_orphan(i as usize);
        }
    }

    pub(super) fn process_orphan(&mut self, i: usize) {
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
pub(super) fn origin_distance<C: Capacity>(
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
