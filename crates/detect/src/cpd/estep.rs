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
//! Each row is evaluated relative to its nearest source point (`k_mn·exp(d²_min/2σ²)`, the
//! log-sum-exp shift), so a row never underflows to `0/0` however small σ² is: with `w = 0`
//! every `x_n` keeps unit mass, as the mixture model says.
//!
//! Two evaluation strategies give the same sums:
//! - dense: every pair, rows split over the rayon pool, one reusable M-length buffer and one
//!   set of `(P1, PX)` accumulators per worker block;
//! - grid truncation: a uniform cell grid over the moved source points with cell size
//!   `h = σ·√(4L)`, `L = ln(1/ε)`, `ε = 1e−8`. A row whose nearest source point lies within
//!   `σ·√(2L)` sums every pair within `h` (the 3^D neighbouring cells): the dropped terms are
//!   below `ε` times the row's largest term. A row with no source point that close is either
//!   negligible against the outlier constant `c` (its posteriors are below `1e−6/M`, set to 0)
//!   or evaluated exactly against all points. Used automatically when the cells are small
//!   against the extent of the point sets (large sets late in the iteration, when σ is small).

// Loops over the D ≤ 3 coordinates index several arrays at once; ranges read clearest.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

/// `L = ln(1/ε)` with `ε = 1e−8`: the truncation depth of the grid strategy.
const TRUNC_L: f64 = 18.420_680_743_952_367;

/// Vectorisable `exp(x)` for `x ≤ 0`, relative error below 1e−14 (Cody–Waite reduction
/// `x = k·ln2 + r`, `|r| ≤ ln2/2`, degree-11 Taylor polynomial, `2^k` assembled in the exponent
/// bits). Arguments below −708 return ≈ 2.2e−308 instead of 0, which no sum here can notice.
#[inline(always)]
pub(crate) fn exp_neg(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    // 1.5·2^52: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let x = x.max(-708.0);
    let t = x * LOG2E + MAGIC;
    let k = t - MAGIC;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    // Horner on the Taylor coefficients 1/11!, …, 1/1!, 1 (a fixed-length loop the compiler
    // unrolls).
    const C: [f64; 12] = [
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
    let mut p = C[0];
    for c in &C[1..] {
        p = p * r + c;
    }
    let bits = t.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(1023) << 52;
    p * f64::from_bits(bits)
}

/// The sums of one E-step.
#[derive(Debug, Clone)]
pub(crate) struct EStepSums<const D: usize> {
    /// `P1 = P·1`, length M.
    pub p1: Vec<f64>,
    /// `Pᵀ1`, length N.
    pub pt1: Vec<f64>,
    /// `P·X`, M rows.
    pub px: Vec<[f64; D]>,
    /// `N_P = 1ᵀP1`.
    pub np: f64,
}

/// How the E-step sums are evaluated (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EStep {
    /// Grid truncation when it pays off (cells small against the extent), dense otherwise.
    #[default]
    Auto,
    /// Every pair (exact).
    Dense,
    /// Grid truncation whenever σ allows a grid (to ε = 1e−8 of each row's largest term).
    Truncated,
}

/// Per-worker accumulators and the reusable row buffer.
struct Block<const D: usize> {
    rows: std::ops::Range<usize>,
    buf: Vec<f64>,
    p1: Vec<f64>,
    px: Vec<[f64; D]>,
}

/// Reusable E-step state: worker blocks and the grid, allocated once per registration.
pub(crate) struct EStepWork<const D: usize> {
    blocks: Vec<Block<D>>,
    grid: Grid<D>,
    mode: EStep,
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

impl<const D: usize> EStepWork<D> {
    /// Workspace for N target and M source points.
    pub fn new(n: usize, m: usize, mode: EStep) -> Self {
        let workers = rayon::current_num_threads().max(1);
        // A few blocks per worker for load balance, none smaller than 64 rows.
        let nblocks = (workers * 2).min(n.div_ceil(64)).max(1);
        let per = n.div_ceil(nblocks);
        let blocks = (0..nblocks)
            .map(|b| Block {
                rows: (b * per).min(n)..((b + 1) * per).min(n),
                buf: vec![0.0; m],
                p1: vec![0.0; m],
                px: vec![[0.0; D]; m],
            })
            .collect();
        Self {
            blocks,
            grid: Grid::default(),
            mode,
        }
    }

    /// The sums for targets `x`, moved sources `t`, variance `sigma2`, outlier weight `w`.
    pub fn run(&mut self, x: &[[f64; D]], t: &[[f64; D]], sigma2: f64, w: f64) -> EStepSums<D> {
        let (n, m) = (x.len(), t.len());
        let c = outlier_constant(sigma2, w, m, n, D);
        let inv2s2 = 0.5 / sigma2;
        let h2 = 2.0 * sigma2 * 2.0 * TRUNC_L;
        let use_grid = match self.mode {
            EStep::Dense => false,
            EStep::Truncated => self.grid.build(t, h2.sqrt(), usize::MAX),
            // Pays off when the 3^D neighbourhood is a small part of the occupied cells.
            EStep::Auto => {
                n * m > 250_000 && self.grid.build(t, h2.sqrt(), 8 * 3usize.pow(D as u32))
            }
        };
        let grid = if use_grid { Some(&self.grid) } else { None };
        let mut pt1 = vec![0.0; n];
        // Pt1 is written per row: split it like the blocks.
        let mut pt1_parts: Vec<&mut [f64]> = Vec::with_capacity(self.blocks.len());
        let mut rest: &mut [f64] = &mut pt1;
        for b in &self.blocks {
            let (head, tail) = rest.split_at_mut(b.rows.len());
            pt1_parts.push(head);
            rest = tail;
        }
        self.blocks
            .par_iter_mut()
            .zip(pt1_parts.into_par_iter())
            .for_each(|(block, pt1_part)| {
                block.p1.fill(0.0);
                block.px.fill([0.0; D]);
                let rows = block.rows.clone();
                for (local, xn) in x[rows].iter().enumerate() {
                    pt1_part[local] = match grid {
                        None => dense_row(xn, t, inv2s2, c, block),
                        Some(g) => grid_row(xn, t, inv2s2, c, h2, g, block),
                    };
                }
            });
        let mut p1 = vec![0.0; m];
        let mut px = vec![[0.0; D]; m];
        for b in &self.blocks {
            for j in 0..m {
                p1[j] += b.p1[j];
                for d in 0..D {
                    px[j][d] += b.px[j][d];
                }
            }
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

/// One dense row: fills the block accumulators, returns `Pt1_n`.
#[inline]
fn dense_row<const D: usize>(
    xn: &[f64; D],
    t: &[[f64; D]],
    inv2s2: f64,
    c: f64,
    block: &mut Block<D>,
) -> f64 {
    let buf = &mut block.buf;
    // One fused pass without a shift; a row whose kernel values all underflow (the point is
    // far from every source point at this σ) is recomputed relative to its nearest point.
    let mut sum = 0.0;
    for (b, tm) in buf.iter_mut().zip(t) {
        let k = exp_neg(-dist2(xn, tm) * inv2s2);
        *b = k;
        sum += k;
    }
    let mut shift = 0.0;
    if !(sum > 1e-250) {
        let mut dmin = f64::INFINITY;
        for tm in t {
            dmin = dmin.min(dist2(xn, tm));
        }
        sum = 0.0;
        for (b, tm) in buf.iter_mut().zip(t) {
            let k = exp_neg(-(dist2(xn, tm) - dmin) * inv2s2);
            *b = k;
            sum += k;
        }
        shift = dmin * inv2s2;
    }
    let denom = if c > 0.0 {
        if shift > 700.0 {
            return 0.0;
        }
        sum + c * shift.exp()
    } else {
        sum
    };
    let inv = 1.0 / denom;
    for ((k, p1), px) in buf.iter().zip(block.p1.iter_mut()).zip(block.px.iter_mut()) {
        let p = k * inv;
        *p1 += p;
        for d in 0..D {
            px[d] += p * xn[d];
        }
    }
    sum * inv
}

/// One grid-truncated row (see the module docs): returns `Pt1_n`.
#[inline]
fn grid_row<const D: usize>(
    xn: &[f64; D],
    t: &[[f64; D]],
    inv2s2: f64,
    c: f64,
    h2: f64,
    grid: &Grid<D>,
    block: &mut Block<D>,
) -> f64 {
    // Pass 1: d² of the candidates within h, in traversal order, and the nearest distance.
    let m = t.len();
    let buf = &mut block.buf;
    let mut cand = 0usize;
    let mut dmin = f64::INFINITY;
    grid.for_neighbours(xn, |j| {
        let d = dist2(xn, &t[j]);
        if d <= h2 {
            buf[cand] = d;
            cand += 1;
            dmin = dmin.min(d);
        }
    });
    if !(dmin <= 0.5 * h2) {
        // Row far from every source point: every kernel value is below e^{−L}.
        let bound = m as f64 * (-TRUNC_L).exp();
        if c > 1e6 * bound {
            return 0.0;
        }
        return dense_row(xn, t, inv2s2, c, block);
    }
    // Pass 2: kernel values relative to the nearest point.
    let mut sum = 0.0;
    for v in buf[..cand].iter_mut() {
        *v = exp_neg(-(*v - dmin) * inv2s2);
        sum += *v;
    }
    let shift = dmin * inv2s2;
    let denom = if c > 0.0 {
        if shift > 700.0 {
            return 0.0;
        }
        sum + c * shift.exp()
    } else {
        sum
    };
    let inv = 1.0 / denom;
    // Pass 3: the same traversal (same filter, same order) scatters the posteriors.
    let mut i = 0usize;
    grid.for_neighbours(xn, |j| {
        if dist2(xn, &t[j]) <= h2 {
            let p = block.buf[i] * inv;
            i += 1;
            block.p1[j] += p;
            for k in 0..D {
                block.px[j][k] += p * xn[k];
            }
        }
    });
    sum * inv
}

/// A uniform grid of cells of side `h` over points, stored as (cell key, index) sorted by key.
struct Grid<const D: usize> {
    h: f64,
    origin: [f64; D],
    /// Sorted cell keys of the occupied cells and, per cell, the range into `order`.
    cells: Vec<([i64; D], u32, u32)>,
    /// Point indices grouped by cell.
    order: Vec<u32>,
}

impl<const D: usize> Default for Grid<D> {
    fn default() -> Self {
        Self {
            h: 0.0,
            origin: [0.0; D],
            cells: Vec::new(),
            order: Vec::new(),
        }
    }
}

impl<const D: usize> Grid<D> {
    /// Rebuilds the grid for `pts` with cell side `h`; returns false (and leaves the grid
    /// unusable) when the cell count would overflow or fewer than `min_cells` cells are
    /// occupied (the grid would not prune enough to pay off).
    fn build(&mut self, pts: &[[f64; D]], h: f64, min_cells: usize) -> bool {
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
        let mut keyed: Vec<([i64; D], u32)> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| (self.key(p), i as u32))
            .collect();
        keyed.sort_unstable();
        let mut start = 0usize;
        for i in 1..=keyed.len() {
            if i == keyed.len() || keyed[i].0 != keyed[start].0 {
                self.cells.push((keyed[start].0, start as u32, i as u32));
                start = i;
            }
        }
        self.order = keyed.into_iter().map(|(_, i)| i).collect();
        if min_cells != usize::MAX && self.cells.len() < min_cells {
            self.cells.clear();
            self.order.clear();
            return false;
        }
        true
    }

    #[inline]
    fn key(&self, p: &[f64; D]) -> [i64; D] {
        let mut k = [0i64; D];
        for d in 0..D {
            k[d] = ((p[d] - self.origin[d]) / self.h).floor() as i64;
        }
        k
    }

    /// Calls `f(j)` for every point in the 3^D cells around `q`, in a fixed order.
    #[inline]
    fn for_neighbours(&self, q: &[f64; D], mut f: impl FnMut(usize)) {
        let base = self.key(q);
        let total = 3usize.pow(D as u32);
        for code in 0..total {
            let mut key = base;
            let mut c = code;
            for k in key.iter_mut() {
                *k += (c % 3) as i64 - 1;
                c /= 3;
            }
            if let Ok(pos) = self.cells.binary_search_by(|cell| cell.0.cmp(&key)) {
                let (_, s, e) = self.cells[pos];
                for &j in &self.order[s as usize..e as usize] {
                    f(j as usize);
                }
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
