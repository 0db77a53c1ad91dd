//! Disjoint sets with union by size and path halving (the `UnionFind` of seed
//! 004_815695db12a6b16c.txt Algorithm 4.1, line 5; Tarjan \[52\]): each `find`/`union` costs
//! O(α(n)) amortised, so segmenting n points stays effectively linear (ch. 4.2).
//!
//! Each vertex's parent, set size and a per-root payload `P` (the segmentation keeps the two
//! internal weights of eq. (4.3) there) share one record, so a `find` that ends at a root has
//! already loaded everything the threshold test reads: one cache miss per endpoint instead of
//! one per array, which is what keeps the time per point flat once the cloud outgrows the cache.

/// One vertex: parent, size (valid at roots) and the root payload.
#[derive(Debug, Clone, Copy)]
struct Node<P> {
    parent: u32,
    size: u32,
    data: P,
}

/// A union–find forest over `0..n` that also keeps every root's set size and a payload `P`.
#[derive(Debug, Clone)]
pub struct UnionFind<P: Copy = ()> {
    nodes: Vec<Node<P>>,
}

impl UnionFind<()> {
    /// `n` singletons without payload. `n` must fit in `u32` (callers check).
    pub fn new(n: usize) -> Self {
        Self::with_data(n, ())
    }
}

impl<P: Copy> UnionFind<P> {
    /// `n` singletons, each root's payload `init`. `n` must fit in `u32` (callers check).
    pub fn with_data(n: usize, init: P) -> Self {
        Self {
            nodes: (0..n as u32)
                .map(|parent| Node {
                    parent,
                    size: 1,
                    data: init,
                })
                .collect(),
        }
    }

    /// The representative of `x`'s set (path halving).
    #[inline]
    pub fn find(&mut self, mut x: u32) -> u32 {
        loop {
            let p = self.nodes[x as usize].parent;
            if p == x {
                return x;
            }
            let gp = self.nodes[p as usize].parent;
            self.nodes[x as usize].parent = gp;
            x = gp;
        }
    }

    /// Joins the sets with roots `a` and `b` (both must be roots, `a != b`); returns the new
    /// root. The larger set's root survives; ties keep `a`, so results are deterministic. The
    /// payload of the new root is left as the survivor's; set it with [`Self::data_mut`].
    #[inline]
    pub fn union_roots(&mut self, a: u32, b: u32) -> u32 {
        let (big, small) = if self.nodes[a as usize].size >= self.nodes[b as usize].size {
            (a, b)
        } else {
            (b, a)
        };
        self.nodes[small as usize].parent = big;
        self.nodes[big as usize].size += self.nodes[small as usize].size;
        big
    }

    /// Size of the set whose root is `root`.
    #[inline]
    pub fn size(&self, root: u32) -> u32 {
        self.nodes[root as usize].size
    }

    /// Payload of the set whose root is `root`.
    #[inline]
    pub fn data(&self, root: u32) -> &P {
        &self.nodes[root as usize].data
    }

    /// Mutable payload of the set whose root is `root`.
    #[inline]
    pub fn data_mut(&mut self, root: u32) -> &mut P {
        &mut self.nodes[root as usize].data
    }

    /// Compact labels `0..k` numbered by first occurrence (deterministic), and `k`.
    pub fn labels(&mut self) -> (Vec<u32>, usize) {
        let n = self.nodes.len();
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
