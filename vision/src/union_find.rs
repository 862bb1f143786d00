//! Disjoint sets over `0..n`, for grouping things that touch (segments into facets, facets
//! into objects).

/// Union-find with path halving; every set's representative is its smallest member, so the
/// groups come out in a deterministic order whatever the order of the unions.
#[derive(Debug, Clone)]
pub(crate) struct UnionFind(Vec<usize>);

impl UnionFind {
    /// `n` singletons.
    pub fn new(n: usize) -> Self {
        Self((0..n).collect())
    }

    /// The representative (smallest member) of `i`'s set.
    pub fn find(&mut self, mut i: usize) -> usize {
        while self.0[i] != i {
            self.0[i] = self.0[self.0[i]];
            i = self.0[i];
        }
        i
    }

    /// Joins the sets of `a` and `b`.
    pub fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.0[a.max(b)] = a.min(b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::UnionFind;

    #[test]
    fn representatives_are_the_smallest_members() {
        let mut uf = UnionFind::new(6);
        uf.union(4, 2);
        uf.union(5, 4);
        uf.union(3, 1);
        assert_eq!([0, 1, 2, 1, 2, 2].to_vec(), (0..6).map(|i| uf.find(i)).collect::<Vec<_>>());
        uf.union(5, 3);
        assert!((1..6).all(|i| uf.find(i) == 1) && uf.find(0) == 0);
    }
}
