//! The expansion moves of [`CrfSolver`]: one cycle over the labels, the candidate
//! sets of the exact pruning, and the construction and solve of one move.

use super::problem::Cost;
#[cfg(test)]
use super::problem::CrfProblem;
use super::problem::{Checked, Energy};
use super::solver::{CrfSolver, ExpansionRun};
use crate::graphcut::bitset::BitSet;
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};

// Node and label indices address several parallel arrays at once in these loops.
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

#[allow(clippy::needless_range_loop)]
impl<C: Cost> CrfSolver<C> {
    /// One cycle of expansion moves over every label; whether a move was accepted (then
    /// `accepted`, if given, is raised at the first).
    pub(super) fn expansion_cycle(
        &mut self,
        c: &Checked<C>,
        run: &mut ExpansionRun<C>,
        accepted: Option<&AtomicBool>,
    ) -> bool {
        // `version` counts accepted moves; a label whose move failed at the current
        // version would fail again (same input), so it is skipped. An accepted move
        // carries a failed label on to the new version when its switched nodes and
        // their neighbours stay clear of that label's last move (see
        // `still_failing`): the label's move would be the same max-flow problem again.
        let mut improved = false;
        for alpha in 0..c.l {
            if !c.allowed_somewhere[alpha] || run.failed_at[alpha] == run.version {
                continue;
            }
            run.tried += 1;
            let new_e = self.expansion_move(c, &run.labels, alpha as i32, &run.e);
            if new_e.lt(&run.e) {
                if !improved {
                    if let Some(flag) = accepted {
                        flag.store(true, AtomicOrdering::Relaxed);
                    }
                }
                std::mem::swap(&mut run.labels, &mut self.candidate);
                // The proposal is the labelling again (see `candidate`).
                for &i in &self.free {
                    self.candidate[i as usize] = alpha as i32;
                }
                self.add_switched_candidates(c, alpha);
                run.e = new_e;
                run.trace.push(run.e.value());
                let version = run.version;
                for (beta, f) in run.failed_at.iter_mut().enumerate() {
                    if *f == version && self.still_failing(c, beta) {
                        *f = version + 1;
                    }
                }
                run.version += 1;
                improved = true;
            } else {
                for &i in &self.free {
                    self.candidate[i as usize] = run.labels[i as usize];
                }
                run.failed_at[alpha] = run.version;
            }
        }
        improved
    }

    /// After an accepted move (its switched nodes in `self.free`, their new candidate
    /// sets added), whether the move of `beta`, which failed before it, is sure to
    /// fail again. After a failed move a label's candidate set is exactly that move's
    /// free nodes (the others leave it, see `expansion_move`). If no switched node and
    /// no neighbour of one is in that set now, then the free nodes, their labels and
    /// their neighbours' labels are what they were, so the move would build the same
    /// graph, find the same cut and bring the same (non-negative) change again.
    pub(super) fn still_failing(&self, c: &Checked<C>, beta: usize) -> bool {
        let set = &self.candidates[beta];
        self.free.iter().all(|&iu| {
            let i = iu as usize;
            let (lo, hi) = (self.adj_start[i] as usize, self.adj_start[i + 1] as usize);
            !set.get(i)
                && self.adj[lo..hi].iter().all(|&k| {
                    let [p, q] = c.edges[k as usize];
                    !set.get(if p as usize == i { q } else { p } as usize)
                })
        })
    }

    /// Per-problem set-up of the expansion moves: each node's sum of edge weights.
    pub(super) fn prepare_expansion(&mut self, c: &Checked<C>, same_structure: bool) {
        // The edges are the solver's; with the weights of the last call the sums are
        // those already there (the EM's E-steps all have the same weights).
        if same_structure || self.weights_of_sums.as_deref() == Some(c.weights) {
            return;
        }
        let kept = self.weights_of_sums.get_or_insert_with(Vec::new);
        kept.clear();
        kept.extend_from_slice(c.weights);
        self.incident_weight.fill(Some(C::ZERO));
        for (&[i, j], &w) in c.edges.iter().zip(c.weights) {
            if i != j {
                for x in [i as usize, j as usize] {
                    self.incident_weight[x] =
                        self.incident_weight[x].and_then(|s| s.checked_add(w));
                }
            }
        }
        self.weights_finite = self.incident_weight.iter().all(Option::is_some);
    }

    /// Whether every node's candidate labels are its [`potts_candidate_mask`] (the
    /// fast path of `add_candidate` for every node).
    pub(super) fn masks_apply(&self, c: &Checked<C>) -> bool {
        self.prune && c.potts && c.big == C::ZERO && c.l <= 64 && self.weights_finite
    }

    /// The candidate sets an expansion of `problem` from `labels` collects, as the
    /// words [`Self::expansion_with`] takes (for tests of callers that compute them).
    #[cfg(test)]
    pub(crate) fn collected_candidate_words(
        &mut self,
        problem: &CrfProblem<C>,
        labels: &[i32],
    ) -> Vec<u64> {
        let c = self.check(problem, true).unwrap();
        assert!(self.prune && c.potts);
        self.prepare_expansion(&c, false);
        self.collect_candidates(&c, labels);
        let n_words = c.n.div_ceil(64);
        (0..n_words * c.l)
            .map(|k| self.candidates[k % c.l].word(k / c.l))
            .collect()
    }

    /// The candidate sets from the caller's words (see [`Self::expansion_with`]).
    pub(super) fn set_candidates(&mut self, c: &Checked<C>, words: &[u64]) {
        self.candidates.resize_with(c.l, || BitSet::new(c.n));
        for (a, set) in self.candidates.iter_mut().enumerate() {
            for (w, block) in words.chunks_exact(c.l).enumerate() {
                set.set_word(w, block[a]);
            }
        }
    }

    /// Whether node `i`, labelled `fi` (≠ α), must be in the cut of α's move: the exact
    /// pruning test of [`Self::expansion_move`] does not fix it.
    #[inline(always)]
    pub(super) fn may_switch(&self, c: &Checked<C>, i: usize, fi: usize, a: usize) -> bool {
        if !self.prune {
            return true;
        }
        match self.incident_weight[i].and_then(|w| w.mul(c.v[fi * c.l + a])) {
            Some(slack) => c.u_graph(i, a) - c.u_graph(i, fi) <= slack,
            None => true, // overflow: no pruning for this node
        }
    }

    /// The per-label candidate sets of one `alpha_expansion` call: one pass over the
    /// nodes' unary rows instead of one per move.
    pub(super) fn collect_candidates(&mut self, c: &Checked<C>, labels: &[i32]) {
        self.candidates.resize_with(c.l, || BitSet::new(c.n));
        self.candidates.iter_mut().for_each(BitSet::clear_all);
        for (i, &fi) in labels.iter().enumerate() {
            self.add_candidate(c, i, fi as usize);
        }
    }

    /// After an accepted move of `alpha`: the nodes that switched (`self.free`) join
    /// the sets of the labels they may now switch to.
    pub(super) fn add_switched_candidates(&mut self, c: &Checked<C>, alpha: usize) {
        for k in 0..self.free.len() {
            self.add_candidate(c, self.free[k] as usize, alpha);
        }
    }

    /// Puts node `i`, labelled `fi`, in the set of every other label it may switch to.
    #[inline]
    pub(super) fn add_candidate(&mut self, c: &Checked<C>, i: usize, fi: usize) {
        // Potts without forbidden costs (the EM's case): V(f_i, α) = 1 and the graph's
        // unary is the unary, so the test of `may_switch` is U_i(α) − U_i(f_i) ≤ W_i
        // for every α at once, as a bit mask (same arithmetic, same outcome).
        if self.prune && c.potts && c.big == C::ZERO && c.l <= 64 {
            if let Some(slack) = self.incident_weight[i] {
                let mut mask = potts_candidate_mask(&c.unary[i * c.l..(i + 1) * c.l], fi, slack);
                while mask != 0 {
                    self.candidates[mask.trailing_zeros() as usize].set(i);
                    mask &= mask - 1;
                }
                return;
            }
        }
        for a in 0..c.l {
            if a != fi && self.may_switch(c, i, fi, a) {
                self.candidates[a].set(i);
            }
        }
    }

    /// Builds and solves the expansion move of `alpha` from `labels`, whose energy is
    /// `e`; leaves the moved labelling in `self.candidate` (which must hold `labels`
    /// on entry; only the switched nodes, left in `self.free`, are written) and returns
    /// its energy.
    ///
    /// Only the free nodes (see below) and their edges are visited: the move costs
    /// O(N) for the unary terms plus work proportional to the free nodes' edges, not a
    /// pass over every edge. The new energy is `e` plus the change on the nodes that
    /// switched and their edges.
    pub(super) fn expansion_move(
        &mut self,
        c: &Checked<C>,
        labels: &[i32],
        alpha: i32,
        e: &Energy<C>,
    ) -> Energy<C> {
        let a = alpha as usize;
        if self.touched_valid {
            self.graph
                .reset_touched(&self.touched_edges, &self.touched_nodes);
        } else {
            self.graph.reset();
        }
        self.touched_edges.clear();
        self.touched_nodes.clear();
        self.touched_valid = true;
        // Pruning (exact). Take any optimal move in which node i (label f_i ≠ α) switches
        // to α and switch i back: its unary term drops by U_i(α) − U_i(f_i), and each
        // edge term w·V(α, x_j) becomes w·V(f_i, x_j) ≤ w·V(f_i, α) + w·V(α, x_j)
        // (triangle inequality), so the edges rise by at most slack_i = Σ_j w_ij·V(f_i, α)
        // = V(f_i, α)·W_i with W_i the sum of i's edge weights (computed once per call).
        // Where U_i(α) − U_i(f_i) > slack_i that would lower an optimal energy, so i keeps
        // f_i in every optimal move and can be left out of the cut. On the EM's body
        // parts this removes most nodes from most moves (points far from segment α).
        // The nodes left, not labelled α, are the free ones.
        // Only α's candidates can pass (see `candidates`); visited in ascending order, so
        // the move is the one a scan over every node would build. A candidate that is
        // not free leaves α's set: it can become free only by switching label, which
        // puts it back (`add_switched_candidates`).
        self.free.clear();
        let mut candidates = std::mem::take(&mut self.candidates[a]);
        let this = &mut *self;
        candidates.retain(|i| {
            let fi = labels[i];
            let free = fi != alpha && this.may_switch(c, i, fi as usize, a);
            if free {
                this.e0[i] = c.u_graph(i, fi as usize);
                this.e1[i] = c.u_graph(i, a);
                this.is_free[i] = true;
                this.free.push(i as u32);
            }
            free
        });
        self.candidates[a] = candidates;
        // Edge terms, x = 1 meaning "switch to α", fixed nodes at x = 0 and α nodes at
        // α either way. Each free node adds its own terms, edge by edge in ascending
        // order; an edge between two free nodes gets its capacity from its first end.
        for &iu in &self.free {
            let i = iu as usize;
            let (lo, hi) = (self.adj_start[i] as usize, self.adj_start[i + 1] as usize);
            for &ku in &self.adj[lo..hi] {
                let k = ku as usize;
                let [p, q] = c.edges[k];
                let (p, q) = (p as usize, q as usize);
                let (fp, fq) = (labels[p], labels[q]);
                let i_is_p = p == i;
                let other = if i_is_p { q } else { p };
                if labels[other] == alpha {
                    // x_i = 0 keeps (f_i, α); x_i = 1 gives (α, α) = 0.
                    self.e0[i] += if i_is_p {
                        c.pair(k, fp, alpha)
                    } else {
                        c.pair(k, alpha, fq)
                    };
                } else if !self.is_free[other] {
                    // The other end stays: (f_p, f_q) or i's side at α.
                    self.e0[i] += c.pair(k, fp, fq);
                    self.e1[i] += if i_is_p {
                        c.pair(k, alpha, fq)
                    } else {
                        c.pair(k, fp, alpha)
                    };
                } else {
                    // Both free: E(0,0) = A, E(0,1) = B, E(1,0) = C, E(1,1) = 0; p pays
                    // A or C by x_p, q pays C for x_q = 0 and p→q carries B + C − A.
                    let ea = c.pair(k, fp, fq);
                    let ec = c.pair(k, alpha, fq);
                    if i_is_p {
                        self.e0[i] += ea;
                        self.e1[i] += ec;
                        let eb = c.pair(k, fp, alpha);
                        // ≥ 0 by the triangle inequality (clamped against float rounding).
                        let mut cap = eb + ec - ea;
                        if cap < C::ZERO {
                            cap = C::ZERO;
                        }
                        self.graph.set_edge_caps_unchecked(k, cap, C::ZERO);
                        self.touched_edges.push(ku);
                    } else {
                        self.e0[i] += ec;
                    }
                }
            }
        }
        for &iu in &self.free {
            let i = iu as usize;
            let (x0, x1) = (self.e0[i], self.e1[i]);
            let m = x0.min_of(x1);
            // Source side (x = 0, keep) pays the sink arc and vice versa.
            self.graph.update_tweights_unchecked(i, x1 - m, x0 - m);
        }
        self.touched_nodes.extend_from_slice(&self.free);
        // Only the free nodes have terminal arcs (and edges): the solve visits them alone.
        self.graph.maxflow_seeded(&self.free);
        // The switched nodes: free and on the sink side.
        for &i in &self.free {
            self.is_free[i as usize] = false;
        }
        let graph = &self.graph;
        self.free.retain(|&i| graph.is_sink_side(i as usize));
        for &i in &self.free {
            self.candidate[i as usize] = alpha;
        }
        // The energy change: unary terms of the switched nodes, then every edge with a
        // switched end once (from its first end when both switched).
        let mut forbidden = e.forbidden as isize;
        let mut sum = e.sum;
        for &iu in &self.free {
            let i = iu as usize;
            let old = c.u(i, labels[i] as usize);
            let new = c.u(i, a);
            if old == C::FORBIDDEN {
                forbidden -= 1;
            } else {
                sum -= old;
            }
            if new == C::FORBIDDEN {
                forbidden += 1;
            } else {
                sum += new;
            }
            let (lo, hi) = (self.adj_start[i] as usize, self.adj_start[i + 1] as usize);
            for &ku in &self.adj[lo..hi] {
                let k = ku as usize;
                let [p, q] = c.edges[k];
                let (p, q) = (p as usize, q as usize);
                let other = if p == i { q } else { p };
                if self.candidate[other] != labels[other] && p != i {
                    continue; // both switched: counted from p
                }
                sum += c.pair(k, self.candidate[p], self.candidate[q]);
                sum -= c.pair(k, labels[p], labels[q]);
            }
        }
        Energy {
            forbidden: forbidden as usize,
            sum,
        }
    }
}
