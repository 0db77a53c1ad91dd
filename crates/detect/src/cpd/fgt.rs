//! A fast Gauss transform for the CPD E-step (000_3b1454b2b2194811.txt eq. (3.13);
//! Myronenko & Song 2010 §5 use the fast Gauss transform for the same sums): the Gaussian
//! kernel `k(x, t) = Π_d g(x_d − t_d)`, `g(u) = exp(−u²/2σ²)`, is separable, and each factor
//! is replaced by its Chebyshev interpolant in both arguments,
//!
//! ```text
//! g(x_d − t_d) ≈ Σ_i Σ_j S_i(x_d) · g(ξ_i − ξ_j) · S_j(t_d),
//! ```
//!
//! with `S_i` the barycentric Lagrange basis on `p` Chebyshev–Lobatto nodes `ξ_i`. The nodes
//! are either those of the whole extent of the sets along the axis (one box: large σ), or
//! piecewise, `p` nodes in each of the boxes of a uniform partition of the axis into boxes a
//! few σ wide (the middle range of σ, where one interpolant over the extent would need more
//! than [`MAX_NODES`] nodes). The node sets of the axes span a tensor grid; a Gauss transform
//! `f(x_n) = Σ_m q_m k(x_n, t_m)` spreads the weights onto the `p^D` nodes of each source's
//! boxes, applies the node matrices `g(ξ_i − ξ_j)` along each axis (block-banded in the
//! piecewise case: boxes more than `r = ⌈7.12σ / width⌉` boxes apart along an axis are at
//! least 7.12σ apart, where `g < 1e−11`, and are skipped), and interpolates at the targets —
//! a single-level "black-box" fast multipole scheme (Fong & Darve 2009) with the Gaussian's
//! tail truncated as in the improved fast Gauss transform. Cost
//! `O((N + M) p^D + nodes · Σ_d (2r + 1) p)` instead of `O(N M)`. The E-step needs two
//! transforms: the row sums `s_n = Σ_m k_mn` (weights 1 at the sources `t_m`), then `P1`, `PX`
//! with the weights `1/(s_n + c)` and `x_n/(s_n + c)` at the sources `x_n`. [`Plan::new`]
//! picks the cheapest layout (one box, or boxes 1.5–6σ wide) by its multiply–add count.
//!
//! Accuracy: `p` is chosen per box width as the smallest size whose interpolant of `g(x − t)`
//! over a box, for centres `t` in the box and the adjacent ones, has a maximum error below
//! `1e−11` on a test grid four times finer than the nodes (times the Lebesgue-constant bound
//! for interpolating in both arguments; farther boxes see smaller, smoother values — checked
//! in the tests), so every kernel value is within about `D·1e−10` of the exact one. A row
//! whose interpolated sum is not above `1e6 · M ·` that error (a target far from every source)
//! is evaluated exactly instead, so each row's posteriors carry a relative error below 1e−6,
//! and far below it where the transform is used (rows summing many kernel values). When σ
//! is small against the extent the node grid grows as `(extent/σ)^D` and the transform is not
//! used (the grid truncation of the `estep` module takes over).

// Loops over the D ≤ 3 axes index several arrays at once; ranges read clearest.
#![allow(clippy::needless_range_loop)]

use pulp::{Simd, WithSimd};
use rayon::prelude::*;

use super::kernel::{EStepSums, exp_neg};

/// Kernel-value accuracy the node count is chosen for (1e−11: the posteriors of a row keep a
/// relative error below 1e−6 through the exact-row threshold of [`Plan::estep`], and a whole
/// fit moves the points as the dense E-step does to ~1e−9; 1e−13 cost ~25 % more nodes).
const KERNEL_TOL: f64 = 1e-11;

/// Largest node count per box and axis considered.
const MAX_NODES: usize = 72;

/// Box widths (in units of σ) tried for the piecewise scheme (the cost model picks the
/// cheapest per E-step; 0.5σ rungs, so the chosen width tracks the estimated optimum).
const BOX_WIDTHS: [f64; 9] = [1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0];

/// Truncation radius of the piecewise scheme in units of σ, `√(2 ln(1/KERNEL_TOL))`: kernel
/// values between points farther apart than this along one axis (`< 10⁻¹¹`) are dropped.
const TRUNC_SIGMAS: f64 = 7.1173;

/// Most node-grid values (nodes × weights) one transform may hold.
const MAX_GRID: usize = 1 << 22;

/// Cost of one exactly evaluated pair in multiply–adds of the transform (distance, exponential,
/// posterior scatter), for choosing between the strategies.
pub(crate) const PAIR_COST: usize = 16;

/// Piecewise Chebyshev interpolation on one axis: `nb` boxes of equal width, each with its own
/// `p` Chebyshev–Lobatto nodes; boxes interact with their `r` neighbours on either side.
#[derive(Debug, Clone)]
struct Axis {
    lo: f64,
    width: f64,
    nb: usize,
    r: usize,
    /// Node positions within a box, in `[0, width]`.
    local: Vec<f64>,
    /// Barycentric weights.
    bw: Vec<f64>,
    /// Node matrices `g(ξ_i − ξ_j − o·width)` for box offsets `o = −r..=r`, row-major `p × p`
    /// each, offset-major.
    g: Vec<f64>,
}

/// Chebyshev–Lobatto nodes of `[0, width]` and their barycentric weights.
fn lobatto(width: f64, p: usize) -> (Vec<f64>, Vec<f64>) {
    let nodes = (0..p)
        .map(|i| 0.5 * width * (1.0 + (std::f64::consts::PI * i as f64 / (p - 1) as f64).cos()))
        .collect();
    let bw = (0..p)
        .map(|i| {
            let s = if i % 2 == 0 { 1.0 } else { -1.0 };
            if i == 0 || i == p - 1 { 0.5 * s } else { s }
        })
        .collect();
    (nodes, bw)
}

/// The barycentric Lagrange basis at `x` (local coordinate) into `out`.
#[inline]
fn basis_at(nodes: &[f64], bw: &[f64], x: f64, out: &mut [f64]) {
    let mut den = 0.0;
    for (i, (&xi, &w)) in nodes.iter().zip(bw).enumerate() {
        let d = x - xi;
        if d == 0.0 {
            out.fill(0.0);
            out[i] = 1.0;
            return;
        }
        let v = w / d;
        out[i] = v;
        den += v;
    }
    let inv = 1.0 / den;
    for o in out.iter_mut() {
        *o *= inv;
    }
}

/// Largest error of the interpolant on `p` nodes of `u ↦ exp(−(u − t)²/2)` (σ = 1) over a box
/// `[0, width]`, for centres `t` in the box and, when `neighbours`, in the adjacent boxes
/// (the farther boxes see smaller kernel values); test grids 4p wide per box.
fn interp_error(width: f64, p: usize, neighbours: bool) -> f64 {
    let (nodes, bw) = lobatto(width, p);
    let q = 4 * p;
    let xs: Vec<f64> = (0..q)
        .map(|i| width * (i as f64 + 0.37) / q as f64)
        .collect();
    let span = if neighbours { 3 } else { 1 };
    let ts: Vec<f64> = (0..2 * p * span)
        .map(|i| {
            let u = (i as f64 + 0.5) / (2 * p * span) as f64;
            if neighbours {
                width * (3.0 * u - 1.0)
            } else {
                width * u
            }
        })
        .collect();
    // The basis at every test point, computed once (row-major, p per point).
    let mut basis = vec![0.0; q * p];
    for (&x, s) in xs.iter().zip(basis.chunks_exact_mut(p)) {
        basis_at(&nodes, &bw, x, s);
    }
    let mut worst: f64 = 0.0;
    for &t in &ts {
        let at_nodes: Vec<f64> = nodes
            .iter()
            .map(|&xi| exp_neg(-0.5 * (xi - t) * (xi - t)))
            .collect();
        for (&x, s) in xs.iter().zip(basis.chunks_exact(p)) {
            let approx: f64 = s.iter().zip(&at_nodes).map(|(a, b)| a * b).sum();
            let exact = exp_neg(-0.5 * (x - t) * (x - t));
            worst = worst.max((approx - exact).abs());
        }
    }
    worst
}

/// Smallest node count per box (≤ [`MAX_NODES`]) whose two-sided interpolation error bound
/// (`error · (1 + Lebesgue constant)`) is below [`KERNEL_TOL`] for boxes `width_sigma` σ wide,
/// with the bound; memoised on a 5 % ladder of widths (rounded up, so the count is safe).
fn nodes_for(width_sigma: f64, neighbours: bool) -> Option<(usize, f64)> {
    use std::collections::HashMap;
    use std::sync::atomic::{AtomicI64, Ordering};
    use std::sync::{Mutex, OnceLock};
    type Table = HashMap<(i64, bool), Option<(usize, f64)>>;
    static CACHE: OnceLock<Mutex<Table>> = OnceLock::new();
    if !(width_sigma > 0.0) || !width_sigma.is_finite() || width_sigma > 1e4 {
        return None;
    }
    let rung = (width_sigma.ln() / 1.05f64.ln()).ceil() as i64;
    // The error grows with the width: a rung at or above one where even MAX_NODES failed
    // fails too (σ shrinking over the iterations reaches a new rung every few steps).
    static FAILED: [AtomicI64; 2] = [AtomicI64::new(i64::MAX), AtomicI64::new(i64::MAX)];
    let failed = &FAILED[usize::from(neighbours)];
    if rung >= failed.load(Ordering::Relaxed) {
        return None;
    }
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Ok(c) = cache.lock()
        && let Some(v) = c.get(&(rung, neighbours))
    {
        return *v;
    }
    let w = 1.05f64.powi(rung as i32);
    let bound = |p: usize| {
        let lebesgue = 2.0 / std::f64::consts::PI * (p as f64).ln() + 1.0;
        interp_error(w, p, neighbours) * (1.0 + lebesgue)
    };
    // Doubling, then binary search on p (the error falls with p; the doubling keeps the
    // costly large-p evaluations away from widths that need few nodes); None when even
    // MAX_NODES fails. The doubling starts at p ≥ width/σ, where the test grids (4p points
    // per box) resolve the Gaussian: on a coarser grid a wide box could pass spuriously.
    let start = (w.ceil() as usize).clamp(4, MAX_NODES);
    let (mut lo, mut hi) = (start - 1, start);
    while hi < MAX_NODES && bound(hi) >= KERNEL_TOL {
        lo = hi;
        hi = (2 * hi).min(MAX_NODES);
    }
    let result = if hi == MAX_NODES && bound(MAX_NODES) >= KERNEL_TOL {
        failed.fetch_min(rung, Ordering::Relaxed);
        None
    } else {
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if bound(mid) < KERNEL_TOL {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some((hi, bound(hi)))
    };
    if let Ok(mut c) = cache.lock() {
        c.insert((rung, neighbours), result);
    }
    result
}

impl Axis {
    fn new(lo: f64, width: f64, nb: usize, r: usize, p: usize, inv2s2: f64) -> Self {
        let (local, bw) = lobatto(width, p);
        let mut g = vec![0.0; (2 * r + 1) * p * p];
        for o in 0..2 * r + 1 {
            let shift = (o as f64 - r as f64) * width;
            for i in 0..p {
                for j in 0..p {
                    let u = local[i] - local[j] - shift;
                    g[(o * p + i) * p + j] = exp_neg(-u * u * inv2s2);
                }
            }
        }
        Self {
            lo,
            width,
            nb,
            r,
            local,
            bw,
            g,
        }
    }

    fn p(&self) -> usize {
        self.local.len()
    }

    /// Nodes on the axis (`nb · p`).
    fn len(&self) -> usize {
        self.nb * self.p()
    }

    /// The box of `x` and the Lagrange basis values `S_i(x)` of that box into `out`.
    #[inline]
    fn basis(&self, x: f64, out: &mut [f64]) -> usize {
        let u = ((x - self.lo) / self.width).floor();
        let b = if u > 0.0 {
            (u as usize).min(self.nb - 1)
        } else {
            0
        };
        let xl = x - (self.lo + b as f64 * self.width);
        basis_at(&self.local, &self.bw, xl, out);
        b
    }
}

/// The interpolation scheme for one E-step.
pub(crate) struct Plan<const D: usize> {
    axes: [Axis; D],
    /// Bound on the error of one kernel value.
    kernel_err: f64,
}

impl<const D: usize> Plan<D> {
    /// The cheapest scheme for the bounding box of `x ∪ t` at variance `sigma2` — one box per
    /// axis (the whole extent) or boxes [`BOX_WIDTHS`] σ wide — whose estimated cost (in
    /// multiply–adds, both transforms of an E-step) is at most `max_cost`; `None` when none is.
    pub fn new(x: &[[f64; D]], t: &[[f64; D]], sigma2: f64, max_cost: usize) -> Option<Self> {
        // Weights carried: 1 (row sums) and D + 1 (P1, PX).
        Self::with_weights(x, t, sigma2, D + 2, max_cost)
    }

    /// [`Plan::new`] for transforms carrying `weights` weight vectors in all (the cost model).
    fn with_weights(
        x: &[[f64; D]],
        t: &[[f64; D]],
        sigma2: f64,
        weights: usize,
        max_cost: usize,
    ) -> Option<Self> {
        let inv2s2 = 0.5 / sigma2;
        let sigma = sigma2.sqrt();
        if !inv2s2.is_finite() || !(sigma > 0.0) || x.is_empty() || t.is_empty() {
            return None;
        }
        let mut lo = [f64::INFINITY; D];
        let mut hi = [f64::NEG_INFINITY; D];
        for p in x.iter().chain(t) {
            for d in 0..D {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        let ext: [(f64, f64); D] = std::array::from_fn(|d| {
            if hi[d] > lo[d] {
                (lo[d], hi[d] - lo[d])
            } else {
                (lo[d] - 1.0, 2.0)
            }
        });
        let points = x.len() + t.len();
        // Per axis (lo, width, boxes, band r, nodes p); the best as (cost, shape, kernel error).
        type Shape<const D: usize> = [(f64, f64, usize, usize, usize); D];
        let mut best: Option<(usize, Shape<D>, f64)> = None;
        let mut consider = |shape: [(f64, f64, usize, usize, usize); D], err: f64| {
            let pd: usize = shape.iter().map(|s| s.4).product();
            let nodes = shape
                .iter()
                .try_fold(1usize, |a, s| a.checked_mul(s.2.checked_mul(s.4)?))?;
            if nodes.checked_mul(D + 1)? > MAX_GRID {
                return None;
            }
            let per_point = pd * weights + shape.iter().map(|s| 8 * s.4).sum::<usize>();
            let band: usize = shape.iter().map(|s| (2 * s.3 + 1) * s.4).sum();
            let cost = points
                .checked_mul(per_point)?
                .checked_add(nodes.checked_mul(band)?.checked_mul(weights)?)?;
            if cost <= max_cost && best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, shape, err));
            }
            Some(())
        };
        // One box per axis.
        let mut global = [(0.0, 0.0, 1usize, 0usize, 0usize); D];
        let mut err = 0.0;
        let mut ok = true;
        for d in 0..D {
            match nodes_for(ext[d].1 / sigma, false) {
                Some((p, e)) => {
                    global[d] = (ext[d].0, ext[d].1, 1, 0, p);
                    err += e;
                }
                None => ok = false,
            }
        }
        if ok {
            let _ = consider(global, err);
        }
        // Boxes a few σ wide.
        for &w in &BOX_WIDTHS {
            let Some((p, e)) = nodes_for(w, true) else {
                continue;
            };
            let width = w * sigma;
            let r = (TRUNC_SIGMAS / w).ceil() as usize;
            let mut shape = [(0.0, 0.0, 1usize, 0usize, 0usize); D];
            let mut several = false;
            for d in 0..D {
                let nb = (ext[d].1 / width).ceil().clamp(1.0, 1e9) as usize;
                several |= nb > 1;
                shape[d] = (ext[d].0, width, nb, r.min(nb - 1), p);
            }
            if several {
                // Interpolation error per axis plus the dropped tail.
                let _ = consider(shape, D as f64 * e + KERNEL_TOL);
            }
        }
        let (_, shape, kernel_err) = best?;
        let axes = shape.map(|(lo, width, nb, r, p)| Axis::new(lo, width, nb, r, p, inv2s2));
        Some(Self { axes, kernel_err })
    }

    /// Number of nodes of the grid.
    pub fn nodes(&self) -> usize {
        self.axes.iter().map(Axis::len).product()
    }

    /// Nodes per axis of the row-major node grid.
    fn dims(&self) -> [usize; D] {
        std::array::from_fn(|d| self.axes[d].len())
    }

    /// Spreads `K` weight vectors (`weights(i, &mut [f64; K])` for point `i`) at `pts` onto the
    /// node grids (K grids, node-major: `grid[node * K + k]`), in parallel with a fixed
    /// chunking (deterministic).
    fn spread<const K: usize>(
        &self,
        pts: &[[f64; D]],
        weights: &(impl Fn(usize, &mut [f64; K]) + Sync),
        arch: pulp::Arch,
    ) -> Vec<f64> {
        let nn = self.nodes();
        // Partial grids over a fixed number of chunks, summed in order: thread-count independent.
        let chunk = pts.len().div_ceil(super::REDUCTION_BLOCKS).max(256);
        let parts: Vec<Vec<f64>> = pts
            .par_chunks(chunk)
            .enumerate()
            .map(|(c, part)| {
                let mut grid = vec![0.0; nn * K];
                arch.dispatch(SpreadOp::<D, K, _> {
                    plan: self,
                    pts: part,
                    offset: c * chunk,
                    weights,
                    grid: &mut grid,
                });
                grid
            })
            .collect();
        let mut out = vec![0.0; nn * K];
        for p in &parts {
            for (o, v) in out.iter_mut().zip(p) {
                *o += v;
            }
        }
        out
    }

    /// Applies the (banded, box-blocked) node matrices along every axis, `K` interleaved grids.
    fn transform<const K: usize>(&self, grid: &mut Vec<f64>) {
        let dims = self.dims();
        for axis in 0..D {
            let ax = &self.axes[axis];
            let (p, nb, r) = (ax.p(), ax.nb, ax.r);
            let len = dims[axis];
            let inner: usize = dims[axis + 1..].iter().product::<usize>() * K;
            let outer: usize = dims[..axis].iter().product();
            let mut out = vec![0.0; grid.len()];
            let src_all: &[f64] = grid;
            if axis == D - 1 {
                // Innermost axis (`inner = K`): weight-major copy of each node row, then
                // contiguous dot products of length p.
                out.par_chunks_mut(len * K)
                    .zip(src_all.par_chunks(len * K))
                    .for_each_init(
                        || vec![0.0; len * K],
                        |tk, (dst, src)| {
                            for (node, v) in src.chunks_exact(K).enumerate() {
                                for k in 0..K {
                                    tk[k * len + node] = v[k];
                                }
                            }
                            for a in 0..nb {
                                let b_lo = a.saturating_sub(r);
                                let b_hi = (a + r).min(nb - 1);
                                for i in 0..p {
                                    for k in 0..K {
                                        let mut acc = 0.0;
                                        for bx in b_lo..=b_hi {
                                            let o = bx + r - a;
                                            let gblk = &ax.g[(o * p + i) * p..(o * p + i + 1) * p];
                                            let sv = &tk[k * len + bx * p..k * len + (bx + 1) * p];
                                            acc += dot(gblk, sv);
                                        }
                                        dst[(a * p + i) * K + k] = acc;
                                    }
                                }
                            }
                        },
                    );
                *grid = out;
                continue;
            }
            out.par_chunks_mut(len * inner)
                .zip(src_all.par_chunks(len * inner))
                .take(outer)
                .for_each(|(dst_all, src)| {
                    for a in 0..nb {
                        let b_lo = a.saturating_sub(r);
                        let b_hi = (a + r).min(nb - 1);
                        for i in 0..p {
                            let row = a * p + i;
                            let dst = &mut dst_all[row * inner..(row + 1) * inner];
                            for bx in b_lo..=b_hi {
                                let o = bx + r - a;
                                let gblk = &ax.g[(o * p + i) * p..(o * p + i + 1) * p];
                                for (j, &gij) in gblk.iter().enumerate() {
                                    let col = bx * p + j;
                                    let sv = &src[col * inner..(col + 1) * inner];
                                    for (dv, s) in dst.iter_mut().zip(sv) {
                                        *dv += gij * s;
                                    }
                                }
                            }
                        }
                    }
                });
            *grid = out;
        }
    }

    /// Interpolates the `K` grids at `pts`: `out(i, values)`.
    fn interpolate<const K: usize>(
        &self,
        grid: &[f64],
        pts: &[[f64; D]],
        arch: pulp::Arch,
    ) -> Vec<[f64; K]> {
        let mut out = vec![[0.0; K]; pts.len()];
        // Each output depends on its own point only, so any chunking gives the same values.
        let chunk = pts.len().div_ceil(super::REDUCTION_BLOCKS).max(256);
        out.par_chunks_mut(chunk)
            .zip(pts.par_chunks(chunk))
            .for_each(|(o, p)| {
                arch.dispatch(InterpOp::<D, K> {
                    plan: self,
                    grid,
                    pts: p,
                    out: o,
                });
            });
        out
    }

    /// `Σ_n inv_n k(t_m, x_n)` and `Σ_n inv_n x_n k(t_m, x_n)` at every target `t_m` through one
    /// spread/transform/interpolate pass with `K ≥ 1 + D` weights per source.
    fn weighted_moments<const K: usize>(
        &self,
        x: &[[f64; D]],
        inv: &[f64],
        t: &[[f64; D]],
        arch: pulp::Arch,
    ) -> (Vec<f64>, Vec<[f64; D]>) {
        let w = |i: usize, w: &mut [f64; K]| {
            w[0] = inv[i];
            for d in 0..D.min(K - 1) {
                w[1 + d] = inv[i] * x[i][d];
            }
        };
        let mut g = self.spread::<K>(x, &w, arch);
        self.transform::<K>(&mut g);
        let v = self.interpolate::<K>(&g, t, arch);
        let p1: Vec<f64> = v.iter().map(|a| a[0]).collect();
        let px: Vec<[f64; D]> = v
            .iter()
            .map(|a| std::array::from_fn(|d| a[1 + d]))
            .collect();
        (p1, px)
    }

    /// The E-step sums (see the module docs); `None` when more than 5 % of the rows need an
    /// exact evaluation (the transform does not pay off).
    pub fn estep(
        &self,
        x: &[[f64; D]],
        t: &[[f64; D]],
        sigma2: f64,
        c: f64,
        arch: pulp::Arch,
    ) -> Option<EStepSums<D>> {
        let (n, m) = (x.len(), t.len());
        let inv2s2 = 0.5 / sigma2;
        // Row sums s_n.
        let mut grid = self.spread::<1>(t, &|_, w| w[0] = 1.0, arch);
        self.transform::<1>(&mut grid);
        let s: Vec<f64> = self
            .interpolate::<1>(&grid, x, arch)
            .into_iter()
            .map(|v| v[0])
            .collect();
        let trust = 1e6 * m as f64 * self.kernel_err.max(f64::MIN_POSITIVE);
        let exact: Vec<usize> = (0..n).filter(|&i| !(s[i] > trust)).collect();
        if exact.len() * 20 > n {
            return None;
        }
        let mut is_exact = vec![false; n];
        for &i in &exact {
            is_exact[i] = true;
        }
        // P1 and PX: weights 1/(s_n + c) and x_n/(s_n + c) at the sources x_n.
        let inv: Vec<f64> = (0..n)
            .map(|i| if is_exact[i] { 0.0 } else { 1.0 / (s[i] + c) })
            .collect();
        let mut pt1: Vec<f64> = (0..n).map(|i| s[i] * inv[i]).collect();
        // K = 1 + D weights (P1 and the D columns of PX); D = 2 runs at K = 3, else K = 4.
        let (mut p1, mut px) = match D {
            2 => self.weighted_moments::<3>(x, &inv, t, arch),
            _ => self.weighted_moments::<4>(x, &inv, t, arch),
        };
        // Rows far from every source: exact, relative to the nearest source.
        let mut k = vec![0.0; m];
        for &i in &exact {
            let xn = &x[i];
            let mut dmin = f64::INFINITY;
            for (kv, tm) in k.iter_mut().zip(t) {
                let mut d2 = 0.0;
                for d in 0..D {
                    let e = xn[d] - tm[d];
                    d2 += e * e;
                }
                *kv = d2;
                dmin = dmin.min(d2);
            }
            let mut sum = 0.0;
            for kv in k.iter_mut() {
                *kv = exp_neg(-(*kv - dmin) * inv2s2);
                sum += *kv;
            }
            let shift = dmin * inv2s2;
            let denom = if c > 0.0 {
                if shift > 700.0 {
                    pt1[i] = 0.0;
                    continue;
                }
                sum + c * shift.exp()
            } else {
                sum
            };
            let a = 1.0 / denom;
            for (j, kv) in k.iter().enumerate() {
                let pv = kv * a;
                p1[j] += pv;
                for d in 0..D {
                    px[j][d] += pv * xn[d];
                }
            }
            pt1[i] = sum * a;
        }
        let np = p1.iter().sum();
        Some(EStepSums { p1, pt1, px, np })
    }
}

/// The Gaussian kernel matrix `G` of a fixed point set (`g_ij = exp(−‖y_i − y_j‖²/2β²)`,
/// 000_3b1454b2b2194811.txt eq. (3.17)) applied to weight vectors by the transform of this
/// module, without forming `G`: `(G v)_i = Σ_j g_ij v_j` through spreading `v` onto the node
/// grid, the node matrices and the interpolation back at the same points, i.e.
/// `G ≈ Bᵀ K B` with `B` the tensor Lagrange basis at the points and `K` the Kronecker
/// product of the per-axis node matrices. The approximation is symmetric positive
/// semi-definite (`K` is a Gaussian kernel matrix on distinct nodes, positive definite), so
/// conjugate gradients on a system built from it behave as with the exact `G`; each entry of
/// `G` is within the plan's kernel error (about `D · 10⁻¹¹`) of the exact value.
pub(crate) struct KernelTransform<const D: usize> {
    plan: Plan<D>,
    arch: pulp::Arch,
}

impl<const D: usize> KernelTransform<D> {
    /// The transform for the points `y` and kernel width `beta` when its estimated cost per
    /// product with `D` weight vectors is at most `max_cost` multiply–adds; `None` otherwise.
    pub fn new(y: &[[f64; D]], beta: f64, max_cost: usize) -> Option<Self> {
        let plan = Plan::with_weights(y, y, beta * beta, D, max_cost)?;
        Some(Self {
            plan,
            arch: pulp::Arch::new(),
        })
    }

    /// `G v` for `v` (M × k, M the points of [`KernelTransform::new`], given again as `y`),
    /// up to three columns per pass.
    pub fn apply(&self, y: &[[f64; D]], v: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
        let mut out = nalgebra::DMatrix::zeros(v.nrows(), v.ncols());
        let mut c = 0;
        while c < v.ncols() {
            let k = (v.ncols() - c).min(3);
            let part = v.columns(c, k).into_owned();
            let gv = match k {
                1 => self.apply_k::<1>(y, &part),
                2 => self.apply_k::<2>(y, &part),
                _ => self.apply_k::<3>(y, &part),
            };
            out.columns_mut(c, k).copy_from(&gv);
            c += k;
        }
        out
    }

    fn apply_k<const K: usize>(
        &self,
        y: &[[f64; D]],
        v: &nalgebra::DMatrix<f64>,
    ) -> nalgebra::DMatrix<f64> {
        let w = |i: usize, w: &mut [f64; K]| {
            for k in 0..K {
                w[k] = v[(i, k)];
            }
        };
        let mut g = self.plan.spread::<K>(y, &w, self.arch);
        self.plan.transform::<K>(&mut g);
        let out = self.plan.interpolate::<K>(&g, y, self.arch);
        nalgebra::DMatrix::from_fn(y.len(), K, |i, k| out[i][k])
    }
}

/// `Σ a_i b_i` with four partial sums (vectorises).
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for l in 0..4 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        s += x * y;
    }
    s
}

/// Spreading of one chunk of points, under the dispatched instruction set.
struct SpreadOp<'a, const D: usize, const K: usize, W> {
    plan: &'a Plan<D>,
    pts: &'a [[f64; D]],
    offset: usize,
    weights: &'a W,
    grid: &'a mut [f64],
}

/// Offsets into the row-major node grid of the `Π_{d<D−1} p_d` node rows a point in the boxes
/// `boxes` touches (first node of its last-axis box), with the product of the outer basis
/// values for each.
#[inline(always)]
fn outer_rows<const D: usize>(
    plan: &Plan<D>,
    dims: &[usize; D],
    boxes: &[usize; D],
    s: &[Vec<f64>; D],
    mut f: impl FnMut(usize, f64),
) {
    let last = &plan.axes[D - 1];
    let row_len = dims[D - 1];
    let last_off = boxes[D - 1] * last.p();
    let count: usize = plan.axes[..D - 1].iter().map(Axis::p).product();
    for o in 0..count {
        let mut rem = o;
        let mut idx = 0usize;
        let mut fac = 1.0;
        // Decode the local indices, most significant axis first.
        let mut locals = [0usize; D];
        for d in (0..D - 1).rev() {
            let p = plan.axes[d].p();
            locals[d] = rem % p;
            rem /= p;
        }
        for d in 0..D - 1 {
            let p = plan.axes[d].p();
            idx = idx * dims[d] + boxes[d] * p + locals[d];
            fac *= s[d][locals[d]];
        }
        f(idx * row_len + last_off, fac);
    }
}

impl<const D: usize, const K: usize, W: Fn(usize, &mut [f64; K]) + Sync> WithSimd
    for SpreadOp<'_, D, K, W>
{
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        let plan = self.plan;
        let dims = plan.dims();
        let mut s: [Vec<f64>; D] = std::array::from_fn(|d| vec![0.0; plan.axes[d].p()]);
        let pl = plan.axes[D - 1].p();
        let mut w = [0.0; K];
        // Weighted basis of the last axis, K interleaved: row[j * K + k] = w_k · S_j.
        let mut row = vec![0.0; pl * K];
        let mut boxes = [0usize; D];
        for (i, p) in self.pts.iter().enumerate() {
            for d in 0..D {
                boxes[d] = plan.axes[d].basis(p[d], &mut s[d]);
            }
            (self.weights)(self.offset + i, &mut w);
            for (j, sv) in s[D - 1].iter().enumerate() {
                for k in 0..K {
                    row[j * K + k] = w[k] * sv;
                }
            }
            let grid = &mut *self.grid;
            outer_rows(plan, &dims, &boxes, &s, |start, f| {
                let dst = &mut grid[start * K..(start + pl) * K];
                for (dv, rv) in dst.iter_mut().zip(&row) {
                    *dv += f * rv;
                }
            });
        }
    }
}

/// Interpolation at one chunk of points, under the dispatched instruction set.
struct InterpOp<'a, const D: usize, const K: usize> {
    plan: &'a Plan<D>,
    grid: &'a [f64],
    pts: &'a [[f64; D]],
    out: &'a mut [[f64; K]],
}

impl<const D: usize, const K: usize> WithSimd for InterpOp<'_, D, K> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        let plan = self.plan;
        let dims = plan.dims();
        let mut s: [Vec<f64>; D] = std::array::from_fn(|d| vec![0.0; plan.axes[d].p()]);
        let pl = plan.axes[D - 1].p();
        // Σ over the outer node rows of f_o · grid row o, then the dot with the last-axis basis.
        let mut acc = vec![0.0; pl * K];
        let mut boxes = [0usize; D];
        for (p, o_val) in self.pts.iter().zip(self.out.iter_mut()) {
            for d in 0..D {
                boxes[d] = plan.axes[d].basis(p[d], &mut s[d]);
            }
            acc.fill(0.0);
            let grid = self.grid;
            outer_rows(plan, &dims, &boxes, &s, |start, f| {
                let src = &grid[start * K..(start + pl) * K];
                for (av, gv) in acc.iter_mut().zip(src) {
                    *av += f * gv;
                }
            });
            let mut v = [0.0; K];
            for (j, sv) in s[D - 1].iter().enumerate() {
                for k in 0..K {
                    v[k] += sv * acc[j * K + k];
                }
            }
            *o_val = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpd::estep::{EStep, EStepWork};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn cloud<const D: usize>(n: usize, seed: u64, scale: f64) -> Vec<[f64; D]> {
        let mut rng = Pcg64::seed_from_u64(seed);
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.random::<f64>() * scale))
            .collect()
    }

    /// The transform's sums against every pair; returns the boxes per axis of the plan used.
    fn check<const D: usize>(sigma2: f64, w: f64, far: bool) -> usize {
        let mut x = cloud::<D>(700, 1, 4.0);
        let mut t = cloud::<D>(600, 2, 4.0);
        if far {
            // A far-away source and target exercise the exact-row path.
            t.push([40.0; D]);
            x.push([-30.0; D]);
        }
        let c = super::super::estep::outlier_constant(sigma2, w, t.len(), x.len(), D);
        let plan = Plan::<D>::new(&x, &t, sigma2, usize::MAX).expect("plan");
        let boxes = plan.axes[0].nb;
        let fast = plan
            .estep(&x, &t, sigma2, c, pulp::Arch::new())
            .expect("estep");
        let mut work = EStepWork::<D>::new(x.len(), t.len(), EStep::Dense);
        let exact = work.run(&x, &t, sigma2, w);
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-3);
        let mut worst: f64 = 0.0;
        for j in 0..t.len() {
            worst = worst.max(rel(fast.p1[j], exact.p1[j]));
            for d in 0..D {
                worst = worst.max(rel(fast.px[j][d], exact.px[j][d]));
            }
        }
        for i in 0..x.len() {
            worst = worst.max(rel(fast.pt1[i], exact.pt1[i]));
        }
        assert!(
            worst < 1e-8,
            "D = {D}, σ² = {sigma2}: worst relative error {worst:e}"
        );
        assert!(rel(fast.np, exact.np) < 1e-9);
        boxes
    }

    #[test]
    fn fast_gauss_matches_dense_sums() {
        // The box is ~70 wide (far points): at large σ the far rows go through the exact path
        // and the rest through the transform.
        for (s2, w) in [(60.0, 0.0), (30.0, 0.2)] {
            check::<2>(s2, w, true);
            check::<3>(s2, w, true);
        }
    }

    #[test]
    fn piecewise_fast_gauss_matches_dense_sums() {
        // σ small against the extent: boxes a few σ wide.
        assert!(check::<2>(0.3, 0.0, false) > 1);
        assert!(check::<2>(0.3, 0.1, true) > 1);
        assert!(check::<2>(0.05, 0.1, false) > 1);
        assert!(check::<3>(0.25, 0.0, false) > 1);
    }

    #[test]
    fn farther_boxes_interpolate_no_worse_than_adjacent_ones() {
        // The node count is chosen for centres up to one box away; the kernel seen from
        // farther boxes is smaller and smoother: check offsets up to 4 boxes.
        for &w in &BOX_WIDTHS {
            let (p, bound) = nodes_for(w, true).expect("node count");
            let (nodes, bw) = lobatto(w, p);
            let mut s = vec![0.0; p];
            let mut worst: f64 = 0.0;
            for k in 0..400 {
                let t = w * (2.0 + 3.0 * k as f64 / 400.0);
                for q in 0..97 {
                    let x = w * (q as f64 + 0.5) / 97.0;
                    basis_at(&nodes, &bw, x, &mut s);
                    let approx: f64 = s
                        .iter()
                        .zip(&nodes)
                        .map(|(a, xi)| a * (-0.5 * (xi - t) * (xi - t)).exp())
                        .sum();
                    worst = worst.max((approx - (-0.5 * (x - t) * (x - t)).exp()).abs());
                }
            }
            assert!(worst < bound, "width {w}σ, p = {p}: {worst:e} vs {bound:e}");
            assert!(bound < KERNEL_TOL);
        }
    }

    #[test]
    fn node_count_grows_as_sigma_shrinks_and_is_capped() {
        let x = cloud::<2>(50, 3, 10.0);
        let a = Plan::<2>::new(&x, &x, 4.0, usize::MAX).expect("plan");
        let b = Plan::<2>::new(&x, &x, 0.5, usize::MAX).expect("plan");
        assert!(b.nodes() > a.nodes());
        assert!(a.kernel_err < 1e-10);
        // Boxes of a few σ at σ = 0.01 over a 10-wide set: too many nodes.
        assert!(Plan::<2>::new(&x, &x, 1e-4, usize::MAX).is_none());
        assert!(Plan::<2>::new(&x, &x, 0.5, 10).is_none());
    }
}
