//! A set of node indices as one bit per node.

/// A bit per node.
#[derive(Clone, Debug, Default)]
pub(crate) struct BitSet(Vec<u64>);

impl BitSet {
    pub(crate) fn new(n: usize) -> Self {
        BitSet(vec![0; n.div_ceil(64)])
    }
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> bool {
        self.0[i >> 6] >> (i & 63) & 1 != 0
    }
    #[inline(always)]
    pub(crate) fn set(&mut self, i: usize) {
        self.0[i >> 6] |= 1 << (i & 63);
    }
    #[inline(always)]
    pub(crate) fn clear(&mut self, i: usize) {
        self.0[i >> 6] &= !(1 << (i & 63));
    }
    /// Bits 64·k to 64·k + 63, lowest first.
    #[inline(always)]
    pub(crate) fn word(&self, k: usize) -> u64 {
        self.0[k]
    }
    #[inline(always)]
    pub(crate) fn set_word(&mut self, k: usize, bits: u64) {
        self.0[k] = bits;
    }
    pub(crate) fn clear_all(&mut self) {
        self.0.fill(0);
    }
    /// Visits the members in ascending order and removes those for which `keep` is
    /// false.
    #[inline]
    pub(crate) fn retain(&mut self, mut keep: impl FnMut(usize) -> bool) {
        for (w, word) in self.0.iter_mut().enumerate() {
            let mut bits = *word;
            while bits != 0 {
                let b = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if !keep(w * 64 + b) {
                    *word &= !(1 << b);
                }
            }
        }
    }
    pub(crate) fn bytes(&self) -> usize {
        self.0.capacity() * 8
    }
}
