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

    /// `n` singleton sets, of the elements 0..n.
    pub(crate) fn singletons(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    /// The set of each element, the sets numbered from 0 in the order of their first
    /// element, and the number of sets.
    pub(crate) fn numbered_sets(&mut self) -> (Vec<usize>, usize) {
        let n = self.len();
        let mut id_of_root = vec![usize::MAX; n];
        let mut sets = 0;
        let set = (0..n)
            .map(|k| {
                let r = self.find(k);
                if id_of_root[r] == usize::MAX {
                    id_of_root[r] = sets;
                    sets += 1;
                }
                id_of_root[r]
            })
            .collect();
        (set, sets)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sets_are_numbered_in_the_order_of_their_first_element() {
        let mut sets = UnionFind::singletons(6);
        sets.union(3, 1);
        sets.union(5, 0);
        sets.union(4, 1);
        assert_eq!(sets.numbered_sets(), (vec![0, 1, 2, 1, 1, 0], 3));
        assert_eq!(UnionFind::singletons(0).numbered_sets(), (vec![], 0));
    }
}
