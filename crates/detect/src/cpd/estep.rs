//! The CPD E-step (000_3b1454b2b2194811.txt eq. (3.12)–(3.13); Myronenko & Song 2010, Fig. 2),
//! fused: the posteriors `p_mn` are never stored. One pass over the rows `x_n` of X computes,
//! for the moved source points `t_m = T(y_m)`,
//!
//! ```text
//! k_mn = exp(−‖x_n − t_m‖² / 2σ²),   p_mn = k_mn / (Σ_k k_kn + c),
//! c    = (2πσ²)^{D/2} · w/(1−w) · M/N                    (uniform outlier component)
//! P1_m = Σ_n p_mn,   Pt1_n = Σ_m p_mn,   PX_m = Σ_n p_mn x_n,   N_P = Σ_m P1_m.
//! ```
//!
//! A row whose kernel values all underflow is evaluated relative to its nearest source point
//! (`k_mn·exp(d²_min/2σ²)`, the log-sum-exp shift), so a row never becomes `0/0` however small
//! σ² is: with `w = 0` every `x_n` keeps unit mass, as the mixture model says.
//!
//! The moved sources are held coordinate by coordinate (structure of arrays) and every row is
//! two straight passes over contiguous runs of them — kernel values (with a lane-parallel sum)
//! and the scatter into `P1`, `PX` — written so that they vectorise. The passes run under
//! runtime instruction-set dispatch (`pulp`): on x86-64 with AVX2 + FMA (x86-64-v3) they use
//! 4-wide vectors and fused multiply–adds, elsewhere the baseline instructions. The exponential
//! is [`exp_neg`] (relative error below 1e−14 on both paths).
//!
//! Three evaluation strategies give the same sums (the last two to a stated accuracy):
//! - dense: every pair, rows split into a fixed number of blocks, one set of
//!   `(P1, PX)` accumulators per block, summed in a fixed order (deterministic);
//! - grid truncation ("tiles"): a uniform cell grid over the moved source points with cell
//!   size `h = σ·√(4L)`, `L = ln(1/ε)`, `ε = 1e−8`; the sources are sorted by cell and the
//!   rows of X grouped by cell, so the 3^D neighbouring cells of a row's cell are 3^{D−1}
//!   contiguous runs of sorted sources, evaluated with the same vector passes as the dense
//!   strategy. Every source within `h` of `x_n` lies in those cells. A row whose nearest
//!   source point lies within `σ·√(2L)` then loses only terms below `ε` times its largest
//!   term. A row with no source point that close is either negligible against the outlier
//!   constant `c` (its posteriors are below `1e−6/M`, set to 0) or evaluated exactly against
//!   all points. Used automatically when the neighbouring runs hold under half of the pairs
//!   (large sets late in the iteration, when σ is small);
//! - above 10⁶ pairs (e.g. N = M = 2000) whenever its estimated cost is under half of the exact
//!   strategy's, the fast Gauss transform of the `fgt` module: separable tensor Chebyshev
//!   interpolation of the kernel, over the whole bounding box at large σ or piecewise on boxes
//!   a few σ wide (interacting with neighbours up to 7.1σ away) in the middle range, in
//!   `O((N + M) p^D)` plus the node-grid products; kernel values to ~1e−10.

// Loops over the D ≤ 3 coordinates index several arrays at once; ranges read clearest.
#![allow(clippy::needless_range_loop)]

use pulp::{Simd, WithSimd};
use rayon::prelude::*;

pub(crate) use super::kernel::{EStepSums, exp_neg};
use super::kernel::{exp_neg_f, madd};

/// `L = ln(1/ε)` with `ε = 1e−8`: the truncation depth of the grid strategy.
const TRUNC_L: f64 = 18.420_680_743_952_367;

/// Vector width of the row passes (two AVX2 registers of f64).
const LANES: usize = 8;

/// How the E-step sums are evaluated (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EStep {
    /// The cheapest by estimated cost: grid truncation when it pays off (neighbouring cells
    /// hold under half of the pairs), every pair otherwise, and, above 10⁶ pairs, the fast
    /// Gauss transform (one box or boxes a few σ wide) when it is at least ~2× cheaper than
    /// the exact strategy it replaces. Full-rank non-rigid CPD also applies its kernel `G`
    /// by the transform when that is cheaper than the dense product.
    #[default]
    Auto,
    /// Every pair (exact); full-rank non-rigid CPD also stores and multiplies the exact `G`.
    Dense,
    /// Grid truncation whenever σ allows a grid (to ε = 1e−8 of each row's largest term).
    Truncated,
    /// The fast Gauss transform of the `fgt` module (kernel values to ~1e−10) whenever σ
    /// allows it (at most 72 interpolation nodes per box and axis, a node grid of at most
    /// 2²² values), dense otherwise.
    FastGauss,
}

/// `Auto` considers the fast Gauss transform above this many pairs (below it the exact
/// strategies are cheap and the transform's one-off node-count search would dominate).
const AUTO_FGT_PAIRS: usize = 1_000_000;

/// A run of rows of X (positions `rows` in the row order) evaluated against the source runs
/// `ranges[cand]` (positions in the sorted sources).
#[derive(Debug, Clone)]
struct Run {
    rows: std::ops::Range<usize>,
    cand: std::ops::Range<usize>,
    /// Whether the rows may fall back to every source (tile runs: rows far from all sources).
    tile: bool,
}

/// Per-block accumulators (positions in the sorted sources) and the row buffer.
struct Block<const D: usize> {
    buf: Vec<f64>,
    p1: Vec<f64>,
    px: [Vec<f64>; D],
}

/// Reusable E-step state: blocks, sorted sources and the grid, allocated once per
/// registration.
pub(crate) struct EStepWork<const D: usize> {
    blocks: Vec<Block<D>>,
    grid: Grid<D>,
    mode: EStep,
    arch: pulp::Arch,
    /// Sorted sources, coordinate by coordinate.
    ts: [Vec<f64>; D],
    /// Sorted position → source index.
    tperm: Vec<u32>,
    /// Row order of X (row position → index) and its grouping into runs.
    xorder: Vec<u32>,
    xkeys: Vec<([i64; D], u32)>,
    runs: Vec<Run>,
    ranges: Vec<(usize, usize)>,
}

/// Squared distance.
#[inline(always)]
fn dist2<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut s = 0.0;
    for d in 0..D {
        let e = a[d] - b[d];
        s += e * e;
    }
    s
}

/// Row-pass constants.
#[derive(Clone, Copy)]
struct RowCtx {
    inv2s2: f64,
    c: f64,
    h2: f64,
    /// Bound on the summed kernel values of a row with no source within `σ√(2L)`.
    far_bound: f64,
}

impl<const D: usize> EStepWork<D> {
    /// Workspace for N target and M source points.
    pub fn new(n: usize, m: usize, mode: EStep) -> Self {
        // A fixed number of blocks (not per thread: the sums must not depend on the thread
        // count), none smaller than 64 rows.
        let nblocks = super::REDUCTION_BLOCKS.min(n.div_ceil(64)).max(1);
        let blocks = (0..nblocks)
            .map(|_| Block {
                buf: vec![0.0; m],
                p1: vec![0.0; m],
                px: std::array::from_fn(|_| vec![0.0; m]),
            })
            .collect();
        Self {
            blocks,
            grid: Grid::default(),
            mode,
            arch: pulp::Arch::new(),
            ts: std::array::from_fn(|_| Vec::with_capacity(m)),
            tperm: Vec::with_capacity(m),
            xorder: Vec::with_capacity(n),
            xkeys: Vec::with_capacity(n),
            runs: Vec::new(),
            ranges: Vec::new(),
        }
    }

    /// Dense plan: sources in input order, rows in input order, one run per block.
    fn plan_dense(&mut self, x: &[[f64; D]], t: &[[f64; D]]) {
        let (n, m) = (x.len(), t.len());
        for d in 0..D {
            self.ts[d].clear();
            self.ts[d].extend(t.iter().map(|p| p[d]));
        }
        self.tperm.clear();
        self.tperm.extend(0..m as u32);
        self.xorder.clear();
        self.xorder.extend(0..n as u32);
        self.ranges.clear();
        self.ranges.push((0, m));
        self.runs.clear();
        let per = n.div_ceil(self.blocks.len());
        for b in 0..self.blocks.len() {
            let rows = (b * per).min(n)..((b + 1) * per).min(n);
            self.runs.push(Run {
                rows,
                cand: 0..1,
                tile: false,
            });
        }
    }

    /// Tile plan over the grid just built on `t` (sources sorted by cell); returns the number
    /// of pairs it evaluates.
    fn plan_tiles(&mut self, x: &[[f64; D]], t: &[[f64; D]]) -> usize {
        let g = &self.grid;
        for d in 0..D {
            self.ts[d].clear();
            self.ts[d].extend(g.order.iter().map(|&i| t[i as usize][d]));
        }
        self.tperm.clear();
        self.tperm.extend_from_slice(&g.order);
        self.xkeys.clear();
        self.xkeys
            .extend(x.iter().enumerate().map(|(i, p)| (g.key(p), i as u32)));
        self.xkeys.sort_unstable();
        self.xorder.clear();
        self.xorder.extend(self.xkeys.iter().map(|&(_, i)| i));
        self.runs.clear();
        self.ranges.clear();
        let mut pairs = 0usize;
        let mut start = 0usize;
        let n = self.xkeys.len();
        // Rows per run: small enough that the blocks balance.
        let max_rows = n.div_ceil(8 * self.blocks.len()).max(16);
        while start < n {
            let key = self.xkeys[start].0;
            let mut end = start + 1;
            while end < n && self.xkeys[end].0 == key {
                end += 1;
            }
            let first = self.ranges.len();
            let mut cand = 0usize;
            g.neighbour_runs(&key, |a, b| {
                self.ranges.push((a, b));
                cand += b - a;
            });
            let last = self.ranges.len();
            pairs += (end - start) * cand;
            let mut s = start;
            while s < end {
                let e = (s + max_rows).min(end);
                self.runs.push(Run {
                    rows: s..e,
                    cand: first..last,
                    tile: true,
                });
                s = e;
            }
            start = end;
        }
        pairs
    }

    /// The sums for targets `x`, moved sources `t`, variance `sigma2`, outlier weight `w`.
    pub fn run(&mut self, x: &[[f64; D]], t: &[[f64; D]], sigma2: f64, w: f64) -> EStepSums<D> {
        let (n, m) = (x.len(), t.len());
        let c = outlier_constant(sigma2, w, m, n, D);
        let inv2s2 = 0.5 / sigma2;
        let h2 = 2.0 * sigma2 * 2.0 * TRUNC_L;
        let use_grid = match self.mode {
            EStep::Dense | EStep::FastGauss => false,
            EStep::Truncated => {
                self.grid.build(t, h2.sqrt()) && {
                    self.plan_tiles(x, t);
                    true
                }
            }
            // The cheapest of: every pair, the grid truncation (when its neighbouring runs
            // hold under half of the pairs), and (above 10⁷ pairs) the fast Gauss transform
            // when its estimated cost is under half of the cheaper exact strategy.
            EStep::Auto => {
                let tiles = (n * m > 250_000
                    && self.grid.build(t, h2.sqrt())
                    && self.grid.cells.len() > 3usize.pow(D as u32))
                .then(|| self.plan_tiles(x, t))
                .filter(|&pairs| pairs * 2 < n * m);
                if n * m > AUTO_FGT_PAIRS {
                    let exact = tiles.unwrap_or(n * m);
                    let budget = exact.saturating_mul(super::fgt::PAIR_COST) / 2;
                    if let Some(plan) = super::fgt::Plan::new(x, t, sigma2, budget)
                        && let Some(sums) = plan.estep(x, t, sigma2, c, self.arch)
                    {
                        return sums;
                    }
                }
                tiles.is_some()
            }
        };
        if !use_grid {
            if self.mode == EStep::FastGauss
                && let Some(plan) = super::fgt::Plan::new(x, t, sigma2, usize::MAX)
                && let Some(sums) = plan.estep(x, t, sigma2, c, self.arch)
            {
                return sums;
            }
            self.plan_dense(x, t);
        }
        let ctx = RowCtx {
            inv2s2,
            c,
            h2,
            far_bound: m as f64 * (-TRUNC_L).exp(),
        };
        // Assign runs to blocks: contiguous, balanced by the number of pairs.
        let cost = |r: &Run| {
            r.rows.len()
                * (self.ranges[r.cand.clone()]
                    .iter()
                    .map(|(a, b)| b - a)
                    .sum::<usize>()
                    + 16)
        };
        let total: usize = self.runs.iter().map(cost).sum();
        let nb = self.blocks.len();
        let mut bounds = vec![0usize; nb + 1];
        {
            let mut acc = 0usize;
            let mut b = 1;
            for (i, r) in self.runs.iter().enumerate() {
                acc += cost(r);
                while b < nb && acc * nb >= total * b {
                    bounds[b] = i + 1;
                    b += 1;
                }
            }
            while b <= nb {
                bounds[b] = self.runs.len();
                b += 1;
            }
        }
        // Pᵀ1 in row order, split like the blocks (runs cover the rows in order).
        let mut pt1_sorted = vec![0.0; n];
        let mut parts: Vec<&mut [f64]> = Vec::with_capacity(nb);
        let mut rest: &mut [f64] = &mut pt1_sorted;
        let mut row0 = 0usize;
        for b in 0..nb {
            let row1 = if bounds[b + 1] > bounds[b] {
                self.runs[bounds[b + 1] - 1].rows.end
            } else {
                row0
            };
            let (head, tail) = rest.split_at_mut(row1 - row0);
            parts.push(head);
            rest = tail;
            row0 = row1;
        }
        let arch = self.arch;
        let runs = &self.runs;
        let ranges = &self.ranges;
        let ts = &self.ts;
        let xorder = &self.xorder;
        self.blocks
            .par_iter_mut()
            .zip(parts.into_par_iter())
            .enumerate()
            .for_each(|(b, (block, pt1_part))| {
                block.p1.fill(0.0);
                for d in 0..D {
                    block.px[d].fill(0.0);
                }
                let my_runs = &runs[bounds[b]..bounds[b + 1]];
                let base = my_runs.first().map_or(0, |r| r.rows.start);
                arch.dispatch(BlockOp {
                    x,
                    xorder,
                    ts,
                    runs: my_runs,
                    ranges,
                    base,
                    ctx,
                    block,
                    pt1: pt1_part,
                });
            });
        let mut p1s = vec![0.0; m];
        let mut pxs: [Vec<f64>; D] = std::array::from_fn(|_| vec![0.0; m]);
        for b in &self.blocks {
            for (acc, v) in p1s.iter_mut().zip(&b.p1) {
                *acc += v;
            }
            for d in 0..D {
                for (acc, v) in pxs[d].iter_mut().zip(&b.px[d]) {
                    *acc += v;
                }
            }
        }
        let mut p1 = vec![0.0; m];
        let mut px = vec![[0.0; D]; m];
        for (j, &orig) in self.tperm.iter().enumerate() {
            p1[orig as usize] = p1s[j];
            for d in 0..D {
                px[orig as usize][d] = pxs[d][j];
            }
        }
        let mut pt1 = vec![0.0; n];
        for (i, &orig) in self.xorder.iter().enumerate() {
            pt1[orig as usize] = pt1_sorted[i];
        }
        let np = p1.iter().sum();
        EStepSums { p1, pt1, px, np }
    }
}

/// The uniform-component constant `c` of eq. (3.13) with outliers (Myronenko & Song eq. (7)).
pub(crate) fn outlier_constant(sigma2: f64, w: f64, m: usize, n: usize, d: usize) -> f64 {
    if w <= 0.0 {
        return 0.0;
    }
    (2.0 * std::f64::consts::PI * sigma2).powf(d as f64 / 2.0) * w / (1.0 - w) * m as f64 / n as f64
}

/// The rows of one block, run under the dispatched instruction set.
struct BlockOp<'a, const D: usize> {
    x: &'a [[f64; D]],
    xorder: &'a [u32],
    ts: &'a [Vec<f64>; D],
    runs: &'a [Run],
    ranges: &'a [(usize, usize)],
    /// Row position of the block's first row (`pt1[0]`).
    base: usize,
    ctx: RowCtx,
    block: &'a mut Block<D>,
    pt1: &'a mut [f64],
}

impl<const D: usize> WithSimd for BlockOp<'_, D> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        // Fused multiply–adds only where the dispatched instruction set has them (4-wide f64
        // vectors: x86-64-v3; aarch64 always has them).
        if S::F64_LANES >= 4 || cfg!(target_arch = "aarch64") {
            self.rows::<true>();
        } else {
            self.rows::<false>();
        }
    }
}

impl<const D: usize> BlockOp<'_, D> {
    #[inline(always)]
    fn rows<const FMA: bool>(self) {
        let all = [(0usize, self.ts[0].len())];
        for run in self.runs {
            let ranges = &self.ranges[run.cand.clone()];
            for pos in run.rows.clone() {
                let xn = &self.x[self.xorder[pos] as usize];
                let v = if run.tile {
                    tile_row::<D, FMA>(xn, self.ts, ranges, &all, self.ctx, self.block)
                } else {
                    dense_row::<D, FMA>(xn, self.ts, ranges, self.ctx, self.block)
                };
                self.pt1[pos - self.base] = v;
            }
        }
    }
}

/// Pass 1 over the source runs: `buf[i] = exp((shift − ‖x − t_i‖²)/2σ²)` for the concatenated
/// runs; returns `(Σ buf, min ‖x − t_i‖², count)`.
#[inline(always)]
fn kernel_pass<const D: usize, const FMA: bool>(
    xn: &[f64; D],
    ts: &[Vec<f64>; D],
    ranges: &[(usize, usize)],
    shift: f64,
    inv2s2: f64,
    buf: &mut [f64],
) -> (f64, f64, usize) {
    let mut acc = [0.0; LANES];
    let mut mn = [f64::INFINITY; LANES];
    let mut o = 0usize;
    for &(a, b) in ranges {
        let len = b - a;
        let full = len / LANES * LANES;
        let out = &mut buf[o..o + len];
        let mut i = 0;
        while i < full {
            let mut d2 = [0.0; LANES];
            for d in 0..D {
                let Some(c) = ts[d].get(a + i..a + i + LANES) else {
                    return (f64::NAN, f64::NAN, 0);
                };
                for l in 0..LANES {
                    let e = c[l] - xn[d];
                    d2[l] = madd::<FMA>(e, e, d2[l]);
                }
            }
            let chunk = &mut out[i..i + LANES];
            for l in 0..LANES {
                mn[l] = mn[l].min(d2[l]);
                let k = exp_neg_f::<FMA>((shift - d2[l]) * inv2s2);
                chunk[l] = k;
                acc[l] += k;
            }
            i += LANES;
        }
        for (j, slot) in out.iter_mut().enumerate().skip(full) {
            let mut d2 = 0.0;
            for d in 0..D {
                let e = ts[d][a + j] - xn[d];
                d2 = madd::<FMA>(e, e, d2);
            }
            mn[0] = mn[0].min(d2);
            let k = exp_neg_f::<FMA>((shift - d2) * inv2s2);
            *slot = k;
            acc[0] += k;
        }
        o += len;
    }
    let sum = acc.iter().sum();
    let dmin = mn.iter().fold(f64::INFINITY, |a, &b| a.min(b));
    (sum, dmin, o)
}

/// Pass 2: `P1 += buf/denom`, `PX += x·buf/denom` over the same runs.
#[inline(always)]
fn scatter_pass<const D: usize>(
    xn: &[f64; D],
    ranges: &[(usize, usize)],
    inv: f64,
    block: &mut Block<D>,
) {
    let mut o = 0usize;
    for &(a, b) in ranges {
        let len = b - a;
        let k = &block.buf[o..o + len];
        for (acc, kv) in block.p1[a..b].iter_mut().zip(k) {
            *acc += kv * inv;
        }
        for d in 0..D {
            let s = xn[d] * inv;
            for (acc, kv) in block.px[d][a..b].iter_mut().zip(k) {
                *acc += kv * s;
            }
        }
        o += len;
    }
}

/// One row against the given source runs (every pair): fills the block accumulators,
/// returns `Pt1_n`.
#[inline(always)]
fn dense_row<const D: usize, const FMA: bool>(
    xn: &[f64; D],
    ts: &[Vec<f64>; D],
    ranges: &[(usize, usize)],
    ctx: RowCtx,
    block: &mut Block<D>,
) -> f64 {
    // One pass without a shift; a row whose kernel values all underflow (the point is far
    // from every source point at this σ) is recomputed relative to its nearest point.
    let (mut sum, dmin, _) = kernel_pass::<D, FMA>(xn, ts, ranges, 0.0, ctx.inv2s2, &mut block.buf);
    let mut shift = 0.0;
    if !(sum > 1e-250) {
        if !dmin.is_finite() {
            return 0.0;
        }
        sum = kernel_pass::<D, FMA>(xn, ts, ranges, dmin, ctx.inv2s2, &mut block.buf).0;
        shift = dmin * ctx.inv2s2;
    }
    let denom = if ctx.c > 0.0 {
        if shift > 700.0 {
            return 0.0;
        }
        sum + ctx.c * shift.exp()
    } else {
        sum
    };
    let inv = 1.0 / denom;
    scatter_pass::<D>(xn, ranges, inv, block);
    sum * inv
}

/// One row against the neighbouring source runs of its cell (see the module docs):
/// returns `Pt1_n`.
#[inline(always)]
fn tile_row<const D: usize, const FMA: bool>(
    xn: &[f64; D],
    ts: &[Vec<f64>; D],
    ranges: &[(usize, usize)],
    all: &[(usize, usize)],
    ctx: RowCtx,
    block: &mut Block<D>,
) -> f64 {
    let (sum, dmin, _) = kernel_pass::<D, FMA>(xn, ts, ranges, 0.0, ctx.inv2s2, &mut block.buf);
    if !(dmin <= 0.5 * ctx.h2) {
        // Row far from every source point: every kernel value is below e^{−L}.
        if ctx.c > 1e6 * ctx.far_bound {
            return 0.0;
        }
        return dense_row::<D, FMA>(xn, ts, all, ctx, block);
    }
    // The nearest source is within σ√(2L): its kernel value is at least e^{−L}, no underflow.
    let inv = 1.0 / (sum + ctx.c);
    scatter_pass::<D>(xn, ranges, inv, block);
    sum * inv
}

/// A uniform grid of cells of side `h` over points: the occupied cells sorted by key, each
/// with its range in `order` (point indices grouped by cell, in key order).
struct Grid<const D: usize> {
    h: f64,
    origin: [f64; D],
    /// Sorted cell keys of the occupied cells and, per cell, the range into `order`.
    cells: Vec<([i64; D], u32, u32)>,
    /// Point indices grouped by cell.
    order: Vec<u32>,
    keyed: Vec<([i64; D], u32)>,
}

impl<const D: usize> Default for Grid<D> {
    fn default() -> Self {
        Self {
            h: 0.0,
            origin: [0.0; D],
            cells: Vec::new(),
            order: Vec::new(),
            keyed: Vec::new(),
        }
    }
}

impl<const D: usize> Grid<D> {
    /// Rebuilds the grid for `pts` with cell side `h`; returns false (and leaves the grid
    /// unusable) when the cell count would overflow.
    fn build(&mut self, pts: &[[f64; D]], h: f64) -> bool {
        self.cells.clear();
        self.order.clear();
        if !(h > 0.0) || !h.is_finite() || pts.is_empty() || pts.len() > u32::MAX as usize {
            return false;
        }
        let mut lo = [f64::INFINITY; D];
        let mut hi = [f64::NEG_INFINITY; D];
        for p in pts {
            for d in 0..D {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        for d in 0..D {
            if (hi[d] - lo[d]) / h > 1e15 {
                return false;
            }
        }
        self.h = h;
        self.origin = lo;
        let mut keyed = std::mem::take(&mut self.keyed);
        keyed.clear();
        keyed.extend(pts.iter().enumerate().map(|(i, p)| (self.key(p), i as u32)));
        keyed.sort_unstable();
        let mut start = 0usize;
        for i in 1..=keyed.len() {
            if i == keyed.len() || keyed[i].0 != keyed[start].0 {
                self.cells.push((keyed[start].0, start as u32, i as u32));
                start = i;
            }
        }
        self.order.extend(keyed.iter().map(|&(_, i)| i));
        self.keyed = keyed;
        true
    }

    #[inline]
    fn key(&self, p: &[f64; D]) -> [i64; D] {
        let mut k = [0i64; D];
        for d in 0..D {
            // Saturating float → int conversion: points far outside the grid get extreme keys.
            k[d] = ((p[d] - self.origin[d]) / self.h).floor() as i64;
        }
        k
    }

    /// Calls `f(a, b)` with the ranges of `order` (positions) covering the 3^D cells around the
    /// cell `key`: one contiguous range per combination of the first D − 1 offsets.
    fn neighbour_runs(&self, key: &[i64; D], mut f: impl FnMut(usize, usize)) {
        let total = 3usize.pow(D as u32 - 1);
        for code in 0..total {
            let mut lo = *key;
            let mut c = code;
            for k in lo.iter_mut().take(D - 1) {
                *k = k.saturating_add((c % 3) as i64 - 1);
                c /= 3;
            }
            let mut hi = lo;
            lo[D - 1] = key[D - 1].saturating_sub(1);
            hi[D - 1] = key[D - 1].saturating_add(1);
            let a = self.cells.partition_point(|cell| cell.0 < lo);
            let b = self.cells.partition_point(|cell| cell.0 <= hi);
            if a < b {
                f(self.cells[a].1 as usize, self.cells[b - 1].2 as usize);
            }
        }
    }
}

/// The full posterior matrix `P` (M×N, row m = source point) for the given state: only built
/// on request, after the iteration.
pub(crate) fn posterior_matrix<const D: usize>(
    x: &[[f64; D]],
    t: &[[f64; D]],
    sigma2: f64,
    w: f64,
) -> nalgebra::DMatrix<f64> {
    let (n, m) = (x.len(), t.len());
    let c = outlier_constant(sigma2, w, m, n, D);
    let inv2s2 = 0.5 / sigma2;
    // Column n of P is row x_n: compute columns in parallel into a column-major buffer.
    let mut data = vec![0.0; n * m];
    data.par_chunks_mut(m.max(1))
        .zip(x.par_iter())
        .for_each(|(col, xn)| {
            let mut dmin = f64::INFINITY;
            for (v, tm) in col.iter_mut().zip(t) {
                *v = dist2(xn, tm);
                dmin = dmin.min(*v);
            }
            let mut sum = 0.0;
            for v in col.iter_mut() {
                *v = exp_neg(-(*v - dmin) * inv2s2);
                sum += *v;
            }
            let shift = dmin * inv2s2;
            let denom = if c > 0.0 {
                if shift > 700.0 {
                    col.fill(0.0);
                    return;
                }
                sum + c * shift.exp()
            } else {
                sum
            };
            for v in col.iter_mut() {
                *v /= denom;
            }
        });
    nalgebra::DMatrix::from_vec(m, n, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_matches_std() {
        let mut worst: f64 = 0.0;
        let mut x = 0.0;
        while x > -700.0 {
            let rel = (exp_neg(x) - x.exp()).abs() / x.exp();
            worst = worst.max(rel);
            x -= 0.001_37;
        }
        assert!(worst < 1e-14, "worst relative error {worst:e}");
        assert_eq!(exp_neg(0.0), 1.0);
        assert!(exp_neg(-1e6) < 1e-300);
    }
}
