//! The free blocks of a problem and which of them the Schur complement eliminates first.

use super::manifold::Manifold;
use super::problem::Problem;

/// The free blocks of a problem and the elimination candidates (no normal-matrix pattern).
#[derive(Clone)]
pub(crate) struct Layout {
    /// Per block: its index among the free blocks.
    pub free_index: Vec<Option<usize>>,
    /// Free index → block.
    pub free_blocks: Vec<usize>,
    /// Scalar offset of each free block.
    pub col_offset: Vec<usize>,
    /// Tangent dimension of each free block.
    pub dims: Vec<usize>,
    /// Scalar dimension.
    pub n: usize,
    /// Per free block: eliminated first (Schur).
    pub eliminated: Vec<bool>,
}

impl Layout {
    /// Free blocks in insertion order; elimination candidates are the blocks marked with
    /// `Problem::set_eliminate(b, Some(true))` and, unless marked otherwise, the free
    /// `Euclidean(3)` blocks (points) none of whose residuals touches another candidate.
    pub fn new(p: &Problem) -> Self {
        let mut free_index = vec![None; p.blocks.len()];
        let mut free_blocks = Vec::new();
        let mut col_offset = Vec::new();
        let mut dims = Vec::new();
        let mut n = 0;
        for (i, b) in p.blocks.iter().enumerate() {
            if !b.fixed {
                free_index[i] = Some(free_blocks.len());
                free_blocks.push(i);
                col_offset.push(n);
                dims.push(b.manifold.tangent_dim());
                n += b.manifold.tangent_dim();
            }
        }
        let nf = free_blocks.len();
        let mut cand: Vec<bool> = free_blocks
            .iter()
            .map(|&b| {
                let blk = &p.blocks[b];
                blk.eliminate
                    .unwrap_or(blk.manifold == Manifold::Euclidean(3))
            })
            .collect();
        let explicit: Vec<bool> = free_blocks
            .iter()
            .map(|&b| p.blocks[b].eliminate == Some(true))
            .collect();
        let mut conflict = vec![false; nf];
        for r in &p.residuals {
            let is_cand = |b: &super::problem::BlockId| free_index[b.0].filter(|&f| cand[f]);
            if r.blocks.iter().filter_map(is_cand).nth(1).is_some() {
                r.blocks
                    .iter()
                    .filter_map(is_cand)
                    .for_each(|f| conflict[f] = true);
            }
        }
        for f in 0..nf {
            if conflict[f] && !explicit[f] {
                cand[f] = false;
            }
        }
        Self {
            free_index,
            free_blocks,
            col_offset,
            dims,
            n,
            eliminated: cand,
        }
    }

    /// Scalar unknowns of the eliminated blocks.
    pub fn eliminated_dim(&self) -> usize {
        self.eliminated
            .iter()
            .zip(&self.dims)
            .filter(|(e, _)| **e)
            .map(|(_, d)| d)
            .sum()
    }
}
