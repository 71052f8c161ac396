//! Disjoint sets with path halving and union by size: the connected components of the
//! foreground mask (`cloud::foreground`) and of the stereo segment filter (`stereo`).

/// Disjoint sets of elements 0..len.
#[derive(Default)]
pub(crate) struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    /// A new singleton set; returns its element.
    pub(crate) fn push(&mut self) -> usize {
        let x = self.parent.len();
        self.parent.push(x as u32);
        self.size.push(1);
        x
    }

    pub(crate) fn len(&self) -> usize {
        self.parent.len()
    }

    /// The representative of `x`'s set.
    pub(crate) fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] as usize != x {
            let p = self.parent[x] as usize;
            self.parent[x] = self.parent[p];
            x = self.parent[x] as usize;
        }
        x
    }

    /// Merges the sets of `a` and `b`.
    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a as u32;
        self.size[a] += self.size[b];
    }
}
