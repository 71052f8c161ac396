//! The compact layout of arcs and nodes: packed head words, parent markers, time
//! stamps, and finding an arc's reverse.

use super::capacity::Capacity;
use std::fmt::Debug;

/// Bits of a packed arc head word that hold the head node; the top four bits hold the
/// sister hint (see [`Graph`]'s layout notes).
pub(super) const HEAD_BITS: u32 = 28;
pub(super) const HEAD_MASK: u32 = (1 << HEAD_BITS) - 1;
/// Sister hint meaning "look the sister up in the overflow table".
pub(super) const HINT_OVERFLOW: u32 = 15;
/// Largest number of nodes (node indices must fit the 28 head bits).
pub const MAX_NODES: usize = HEAD_MASK as usize;
/// Largest number of arcs (arc indices must stay below the parent markers).
pub(super) const MAX_ARCS: usize = 0x7FFF_FFF0;

/// Parent words: an arc index (towards the parent) or a marker, with the tree in bit 31
/// (set = sink tree). A free node has exactly `FREE` (bit 31 clear).
pub(super) const SINK_BIT: u32 = 1 << 31;
pub(super) const FREE: u32 = 0x7FFF_FFFF;
pub(super) const TERMINAL: u32 = 0x7FFF_FFFE;
pub(super) const ORPHAN: u32 = 0x7FFF_FFFD;
/// Marks an edge of the edge index that is a self-loop (no arcs).
pub(super) const NO_ARC: u32 = u32::MAX;
/// Distance meaning "not connected to a terminal" during adoption.
pub(super) const INFINITE_DIST: u32 = u32::MAX;
/// Time stamps live in the upper 16 bits of a node's `tsd` word; on overflow all stamps
/// are cleared and the clock restarts (once every 65,535 augmentations).
pub(super) const MAX_TIME: u32 = 0xFFFF;

/// One arc: its packed head word and its residual capacity side by side, so that the
/// scans reading both touch one cache line. Packed to 4-byte alignment: 12 bytes for
/// 8-byte capacities (x86-64 and aarch64 read unaligned words at full speed).
#[derive(Clone, Copy)]
#[repr(C, packed(4))]
pub(super) struct ArcRec<C> {
    /// Head node (low `HEAD_BITS`) and sister hint (high bits).
    pub(super) hw: u32,
    /// Residual capacity.
    pub(super) cap: C,
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
    pub(super) fn cap(&self) -> C {
        self.cap
    }
}

/// A node: its first arc and search state, 20 bytes for 8-byte capacities (packed to
/// 4-byte alignment). The first arc sits with the state because finding an arc's
/// reverse needs the head's first arc right when the head's state is read.
#[derive(Clone, Copy, Debug)]
#[repr(C, packed(4))]
pub(super) struct Node<C> {
    /// Residual terminal capacity: `> 0` from the source, `< 0` to the sink.
    pub(super) tr: C,
    /// Parent word (arc to the parent in the search tree, or a marker; bit 31 = tree).
    pub(super) parent: u32,
    /// Time stamp (high 16 bits) and distance to the terminal (low 16 bits) of the
    /// adoption heuristic. The distance saturates at `u16::MAX`: it only steers
    /// heuristics, the adoption walk never relies on exact values for correctness.
    pub(super) tsd: u32,
    /// CSR: the arcs of node `i` are `nodes[i].first..nodes[i + 1].first`.
    pub(super) first: u32,
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
pub(super) fn pack_tsd(ts: u32, dist: u32) -> u32 {
    (ts << 16) | dist.min(0xFFFF)
}

#[inline(always)]
pub(super) fn ts_of(tsd: u32) -> u32 {
    tsd >> 16
}

#[inline(always)]
pub(super) fn dist_of(tsd: u32) -> u32 {
    tsd & 0xFFFF
}

/// True if parent word `p` is an arc (not free, terminal or orphan).
#[inline(always)]
pub(super) fn is_arc(p: u32) -> bool {
    (p & !SINK_BIT) < ORPHAN
}

/// Reverse arc of arc `a` whose packed head word is `hw`: the head's first arc plus the
/// hint, or the overflow table (sorted by arc) when the hint does not fit.
#[inline(always)]
pub(super) fn sister_of<C: Copy>(
    nodes: &[Node<C>],
    overflow: &[(u32, u32)],
    a: usize,
    hw: u32,
) -> usize {
    sister_at(nodes[(hw & HEAD_MASK) as usize].first, overflow, a, hw)
}

/// [`sister_of`] given the head's first arc (read by the caller with the head's record).
#[inline(always)]
pub(super) fn sister_at(head_first: u32, overflow: &[(u32, u32)], a: usize, hw: u32) -> usize {
    let h = hw >> HEAD_BITS;
    if h != HINT_OVERFLOW {
        head_first as usize + h as usize
    } else {
        let k = overflow.partition_point(|&(x, _)| (x as usize) < a);
        overflow[k].1 as usize
    }
}
