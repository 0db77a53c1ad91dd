//! Disjoint sets with union by size and path halving (the `UnionFind` of seed
//! 004_815695db12a6b16c.txt Algorithm 4.1, line 5; Tarjan \[52\]): each `find`/`union` costs
//! O(α(n)) amortised, so segmenting n points stays effectively linear (ch. 4.2).
//!
//! Layout for large clouds, where the forest no longer fits in the cache and every access in
//! the colour-sorted edge order is a likely miss: one `u32` per vertex holds either the parent
//! or, at a root, the set size with the top bit set (4 bytes per vertex, so the array a `find`
//! walks stays cache-resident longer), and a per-root payload `P` (the segmentation keeps the
//! internal weights of eq. (4.3) there) sits in its own array, read only for the edges whose
//! endpoints lie in different sets.

/// Top bit of an entry: set at a root, whose lower bits are the set size.
const ROOT: u32 = 1 << 31;

/// Largest number of vertices (sizes and indices need 31 bits).
pub const MAX_VERTICES: usize = (ROOT - 1) as usize;

/// A union–find forest over `0..n` that also keeps every root's set size and a payload `P`.
#[derive(Debug, Clone)]
pub struct UnionFind<P: Copy = ()> {
    /// Parent, or `ROOT | size` at a root.
    entry: Vec<u32>,
    /// Payload, meaningful at roots.
    data: Vec<P>,
}

impl UnionFind<()> {
    /// `n` singletons without payload. `n` must be at most [`MAX_VERTICES`] (callers check).
    pub fn new(n: usize) -> Self {
        Self::with_data(n, ())
    }
}

impl<P: Copy> UnionFind<P> {
    /// `n` singletons, each root's payload `init`. `n` must be at most [`MAX_VERTICES`]
    /// (callers check).
    pub fn with_data(n: usize, init: P) -> Self {
        Self {
            entry: vec![ROOT | 1; n],
            data: vec![init; n],
        }
    }

    /// The representative of `x`'s set (path halving).
    #[inline]
    pub fn find(&mut self, mut x: u32) -> u32 {
        loop {
            let p = self.entry[x as usize];
            if p & ROOT != 0 {
                return x;
            }
            let gp = self.entry[p as usize];
            if gp & ROOT != 0 {
                return p;
            }
            self.entry[x as usize] = gp;
            x = gp;
        }
    }

    /// Joins the sets with roots `a` and `b` (both must be roots, `a != b`); returns the new
    /// root. The larger set's root survives; ties keep `a`, so results are deterministic. The
    /// payload of the new root is left as the survivor's; set it with [`Self::data_mut`].
    #[inline]
    pub fn union_roots(&mut self, a: u32, b: u32) -> u32 {
        let (sa, sb) = (self.size(a), self.size(b));
        let (big, small) = if sa >= sb { (a, b) } else { (b, a) };
        self.entry[small as usize] = big;
        self.entry[big as usize] = ROOT | (sa + sb);
        big
    }

    /// The raw entry of `x` (its parent, or its size at a root). Reading it ahead of time
    /// starts the cache miss that the coming `find(x)` would otherwise wait for.
    #[inline]
    pub fn entry_of(&self, x: u32) -> u32 {
        self.entry[x as usize]
    }

    /// Size of the set whose root is `root`.
    #[inline]
    pub fn size(&self, root: u32) -> u32 {
        self.entry[root as usize] & !ROOT
    }

    /// Payload of the set whose root is `root`.
    #[inline]
    pub fn data(&self, root: u32) -> &P {
        &self.data[root as usize]
    }

    /// Mutable payload of the set whose root is `root`.
    #[inline]
    pub fn data_mut(&mut self, root: u32) -> &mut P {
        &mut self.data[root as usize]
    }

    /// Compact labels `0..k` numbered by first occurrence (deterministic), and `k`.
    pub fn labels(&mut self) -> (Vec<u32>, usize) {
        let n = self.entry.len();
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
