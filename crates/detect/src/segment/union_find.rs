//! Disjoint sets with union by size and path halving (the `UnionFind` of seed
//! 004_815695db12a6b16c.txt Algorithm 4.1, line 5; Tarjan \[52\]): each `find`/`union` costs
//! O(α(n)) amortised, so segmenting n points stays effectively linear (ch. 4.2).

/// A union–find forest over `0..n` that also keeps every root's set size.
#[derive(Debug, Clone)]
pub struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    /// `n` singletons. `n` must fit in `u32` (callers check).
    pub fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    /// The representative of `x`'s set (path halving).
    #[inline]
    pub fn find(&mut self, mut x: u32) -> u32 {
        loop {
            let p = self.parent[x as usize];
            if p == x {
                return x;
            }
            let gp = self.parent[p as usize];
            self.parent[x as usize] = gp;
            x = gp;
        }
    }

    /// Joins the sets with roots `a` and `b` (both must be roots, `a != b`); returns the new
    /// root. The larger set's root survives; ties keep `a`, so results are deterministic.
    #[inline]
    pub fn union_roots(&mut self, a: u32, b: u32) -> u32 {
        let (big, small) = if self.size[a as usize] >= self.size[b as usize] {
            (a, b)
        } else {
            (b, a)
        };
        self.parent[small as usize] = big;
        self.size[big as usize] += self.size[small as usize];
        big
    }

    /// Size of the set whose root is `root`.
    #[inline]
    pub fn size(&self, root: u32) -> u32 {
        self.size[root as usize]
    }

    /// Compact labels `0..k` numbered by first occurrence (deterministic), and `k`.
    pub fn labels(&mut self) -> (Vec<u32>, usize) {
        let n = self.parent.len();
        let mut map = vec![u32::MAX; n];
        let mut out = Vec::with_capacity(n);
        let mut next = 0u32;
        for i in 0..n as u32 {
            let r = self.find(i) as usize;
            if map[r] == u32::MAX {
                map[r] = next;
                next += 1;
            }
            out.push(map[r]);
        }
        (out, next as usize)
    }
}
