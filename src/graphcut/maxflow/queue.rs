//! The queue of active nodes of a search.

use crate::graphcut::bitset::BitSet;
use std::collections::VecDeque;
use std::fmt::Debug;

/// The FIFO of active nodes. A fresh solve activates every node with a terminal arc at
/// once; instead of queueing them all (4 bytes per node), a cursor sweeps the nodes in
/// index order and takes those marked `initial`, before the ring of nodes activated
/// later. A node activated while the sweep is still before it is marked for the sweep
/// too, not put in the ring: when the short-path pass leaves few roots, the trees grow
/// over most of the graph during the sweep, and a ring holding all those nodes cost up
/// to 3 bytes per node more. Otherwise the order is a FIFO's.
#[derive(Clone, Debug, Default)]
pub(super) struct ActiveQueue {
    pub(super) sweep: usize,
    pub(super) n: usize,
    pub(super) initial: BitSet,
    pub(super) queued: BitSet,
    pub(super) ring: VecDeque<u32>,
}

impl ActiveQueue {
    pub(super) fn new(n: usize) -> Self {
        ActiveQueue {
            sweep: n,
            n,
            initial: BitSet::new(n),
            queued: BitSet::new(n),
            ring: VecDeque::new(),
        }
    }

    /// Empties the queue.
    pub(super) fn clear(&mut self) {
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
    pub(super) fn mark_initial(&mut self, i: usize) {
        self.initial.set(i);
    }

    pub(super) fn start_sweep(&mut self) {
        self.sweep = 0;
    }

    #[inline(always)]
    pub(super) fn push(&mut self, i: u32) {
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
    pub(super) fn pop(&mut self) -> Option<u32> {
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

    pub(super) fn bytes(&self) -> usize {
        self.initial.bytes() + self.queued.bytes() + self.ring.capacity() * 4
    }
}
