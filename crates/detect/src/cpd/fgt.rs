//! A fast Gauss transform for the CPD E-step at large σ (000_3b1454b2b2194811.txt eq. (3.13);
//! Myronenko & Song 2010 §5 use the fast Gauss transform for the same sums): the Gaussian
//! kernel `k(x, t) = Π_d g(x_d − t_d)`, `g(u) = exp(−u²/2σ²)`, is separable, and on the
//! bounding box of both point sets each factor is replaced by its tensor Chebyshev interpolant
//! in both arguments,
//!
//! ```text
//! g(x_d − t_d) ≈ Σ_i Σ_j S_i(x_d) · g(ξ_i − ξ_j) · S_j(t_d),
//! ```
//!
//! with `S_i` the barycentric Lagrange basis on `p` Chebyshev–Lobatto nodes `ξ_i` of the
//! interval (a single-level "black-box" fast multipole scheme). A Gauss transform
//! `f(x_n) = Σ_m q_m k(x_n, t_m)` then costs `O((N + M) p^D + D p^{D+1})` instead of `O(N M)`:
//! spread the weights onto the `p^D` nodes, apply the `p × p` node matrix along each axis,
//! interpolate at the targets. The E-step needs two transforms: the row sums
//! `s_n = Σ_m k_mn` (weights 1 at the sources `t_m`), then `P1`, `PX` with the weights
//! `1/(s_n + c)` and `x_n/(s_n + c)` at the sources `x_n`.
//!
//! Accuracy: `p` is chosen per axis as the smallest size whose interpolant of `g(x − t)` over
//! the box has a maximum error below `1e−13` on a test grid four times finer than the nodes
//! (times the Lebesgue-constant bound for interpolating in both arguments), so every kernel
//! value is within about `D·1e−12` of the exact one. A row whose interpolated sum is not
//! above `1e6 · M ·` that error (a target far from every source) is evaluated exactly instead,
//! so each row's posteriors carry a relative error below 1e−6, and far below it in the
//! regime where the transform is used (rows summing many kernel values, σ comparable with the
//! extent of the sets). When σ is small against the box the node count grows as `(extent/σ)^D`
//! and the transform is not used (the grid truncation of the `estep` module takes over).

// Loops over the D ≤ 3 axes index several arrays at once; ranges read clearest.
#![allow(clippy::needless_range_loop)]

use pulp::{Simd, WithSimd};
use rayon::prelude::*;

use super::estep::{EStepSums, exp_neg};

/// Kernel-value accuracy the node count is chosen for.
const KERNEL_TOL: f64 = 1e-13;

/// Largest node count per axis considered.
const MAX_NODES: usize = 72;

/// Chebyshev interpolation on one axis.
#[derive(Debug, Clone)]
struct Axis {
    lo: f64,
    hi: f64,
    /// Nodes, mapped to `[lo, hi]`.
    nodes: Vec<f64>,
    /// Barycentric weights.
    bw: Vec<f64>,
    /// Node matrix `g(ξ_i − ξ_j)`, row-major `p × p`.
    g: Vec<f64>,
}

impl Axis {
    fn new(lo: f64, hi: f64, p: usize, inv2s2: f64) -> Self {
        let nodes: Vec<f64> = (0..p)
            .map(|i| {
                let c = (std::f64::consts::PI * i as f64 / (p - 1) as f64).cos();
                0.5 * (lo + hi) + 0.5 * (hi - lo) * c
            })
            .collect();
        let bw = (0..p)
            .map(|i| {
                let s = if i % 2 == 0 { 1.0 } else { -1.0 };
                if i == 0 || i == p - 1 { 0.5 * s } else { s }
            })
            .collect();
        let mut g = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                let u = nodes[i] - nodes[j];
                g[i * p + j] = exp_neg(-u * u * inv2s2);
            }
        }
        Self {
            lo,
            hi,
            nodes,
            bw,
            g,
        }
    }

    fn p(&self) -> usize {
        self.nodes.len()
    }

    /// The Lagrange basis values `S_i(x)` into `out` (length p).
    #[inline]
    fn basis(&self, x: f64, out: &mut [f64]) {
        let mut den = 0.0;
        for (i, (&xi, &w)) in self.nodes.iter().zip(&self.bw).enumerate() {
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

    /// Largest error of the interpolant of `g(x − t)` in `x` over the interval, for `t` on
    /// the same test grid, on a test grid 4p points wide.
    fn error(&self, inv2s2: f64) -> f64 {
        let p = self.p();
        let q = 4 * p;
        let mut s = vec![0.0; p];
        let mut worst: f64 = 0.0;
        let pts: Vec<f64> = (0..q)
            .map(|i| self.lo + (self.hi - self.lo) * (i as f64 + 0.37) / q as f64)
            .collect();
        for &t in &pts {
            let at_nodes: Vec<f64> = self
                .nodes
                .iter()
                .map(|&xi| exp_neg(-(xi - t) * (xi - t) * inv2s2))
                .collect();
            for &x in &pts {
                self.basis(x, &mut s);
                let approx: f64 = s.iter().zip(&at_nodes).map(|(a, b)| a * b).sum();
                let exact = exp_neg(-(x - t) * (x - t) * inv2s2);
                worst = worst.max((approx - exact).abs());
            }
        }
        worst
    }
}

/// The interpolation scheme for one E-step.
pub(crate) struct Plan<const D: usize> {
    axes: [Axis; D],
    /// Bound on the error of one kernel value.
    kernel_err: f64,
}

impl<const D: usize> Plan<D> {
    /// The scheme for the bounding box of `x ∪ t` at variance `sigma2`, or `None` when some
    /// axis would need more than [`MAX_NODES`] nodes or more than `max_nodes` nodes overall.
    pub fn new(x: &[[f64; D]], t: &[[f64; D]], sigma2: f64, max_nodes: usize) -> Option<Self> {
        let inv2s2 = 0.5 / sigma2;
        if !inv2s2.is_finite() || x.is_empty() || t.is_empty() {
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
        let mut axes = Vec::with_capacity(D);
        let mut total = 1usize;
        let mut err_sum = 0.0;
        for d in 0..D {
            let (a, b) = if hi[d] > lo[d] {
                (lo[d], hi[d])
            } else {
                (lo[d] - 1.0, lo[d] + 1.0)
            };
            // Start from the size a Gaussian of this width over this interval needs roughly
            // (√(2γ·ln(1/tol)), γ = (half-length)²/2σ²), then grow until the test passes.
            let gamma = 0.25 * (b - a) * (b - a) * inv2s2;
            let mut p = ((2.0 * gamma * 30.0).sqrt() * 0.6).ceil().max(6.0) as usize;
            let axis = loop {
                if p > MAX_NODES {
                    return None;
                }
                let axis = Axis::new(a, b, p, inv2s2);
                let lebesgue = 2.0 / std::f64::consts::PI * (p as f64).ln() + 1.0;
                let err = axis.error(inv2s2) * (1.0 + lebesgue);
                if err < KERNEL_TOL {
                    err_sum += err;
                    break axis;
                }
                p += 2;
            };
            total = total.saturating_mul(axis.p());
            if total > max_nodes {
                return None;
            }
            axes.push(axis);
        }
        let axes: [Axis; D] = axes.try_into().ok()?;
        Some(Self {
            axes,
            kernel_err: err_sum,
        })
    }

    /// Number of nodes `p^D`.
    pub fn nodes(&self) -> usize {
        self.axes.iter().map(Axis::p).product()
    }

    /// Strides of the row-major node grid.
    fn dims(&self) -> [usize; D] {
        std::array::from_fn(|d| self.axes[d].p())
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
        let chunk = pts
            .len()
            .div_ceil(rayon::current_num_threads().max(1) * 2)
            .max(256);
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

    /// Applies the node matrices along every axis (in place, `K` interleaved grids).
    fn transform<const K: usize>(&self, grid: &mut Vec<f64>) {
        let dims = self.dims();
        for axis in 0..D {
            let p = dims[axis];
            let inner: usize = dims[axis + 1..].iter().product::<usize>() * K;
            let outer: usize = dims[..axis].iter().product();
            let g = &self.axes[axis].g;
            let mut out = vec![0.0; grid.len()];
            for o in 0..outer {
                let base = o * p * inner;
                for i in 0..p {
                    let dst = &mut out[base + i * inner..base + (i + 1) * inner];
                    for j in 0..p {
                        let gij = g[i * p + j];
                        let src = &grid[base + j * inner..base + (j + 1) * inner];
                        for (dv, sv) in dst.iter_mut().zip(src) {
                            *dv += gij * sv;
                        }
                    }
                }
            }
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
        let chunk = pts
            .len()
            .div_ceil(rayon::current_num_threads().max(1) * 2)
            .max(256);
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
        let (p1, mut px) = match D {
            2 => {
                let w = |i: usize, w: &mut [f64; 3]| {
                    w[0] = inv[i];
                    w[1] = inv[i] * x[i][0];
                    w[2] = inv[i] * x[i][1];
                };
                let mut g = self.spread::<3>(x, &w, arch);
                self.transform::<3>(&mut g);
                let v = self.interpolate::<3>(&g, t, arch);
                let p1: Vec<f64> = v.iter().map(|a| a[0]).collect();
                let px: Vec<[f64; D]> = v
                    .iter()
                    .map(|a| std::array::from_fn(|d| a[1 + d]))
                    .collect();
                (p1, px)
            }
            _ => {
                let w = |i: usize, w: &mut [f64; 4]| {
                    w[0] = inv[i];
                    for d in 0..D.min(3) {
                        w[1 + d] = inv[i] * x[i][d];
                    }
                };
                let mut g = self.spread::<4>(x, &w, arch);
                self.transform::<4>(&mut g);
                let v = self.interpolate::<4>(&g, t, arch);
                let p1: Vec<f64> = v.iter().map(|a| a[0]).collect();
                let px: Vec<[f64; D]> = v
                    .iter()
                    .map(|a| std::array::from_fn(|d| a[1 + d]))
                    .collect();
                (p1, px)
            }
        };
        let mut p1 = p1;
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

/// Spreading of one chunk of points, under the dispatched instruction set.
struct SpreadOp<'a, const D: usize, const K: usize, W> {
    plan: &'a Plan<D>,
    pts: &'a [[f64; D]],
    offset: usize,
    weights: &'a W,
    grid: &'a mut [f64],
}

impl<const D: usize, const K: usize, W: Fn(usize, &mut [f64; K]) + Sync> WithSimd
    for SpreadOp<'_, D, K, W>
{
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        let plan = self.plan;
        let dims = plan.dims();
        let mut s: [Vec<f64>; D] = std::array::from_fn(|d| vec![0.0; dims[d]]);
        let last = dims[D - 1];
        let mut w = [0.0; K];
        // Weighted basis of the last axis, K interleaved: row[j * K + k] = w_k · S_j.
        let mut row = vec![0.0; last * K];
        for (i, p) in self.pts.iter().enumerate() {
            for d in 0..D {
                plan.axes[d].basis(p[d], &mut s[d]);
            }
            (self.weights)(self.offset + i, &mut w);
            for (j, sv) in s[D - 1].iter().enumerate() {
                for k in 0..K {
                    row[j * K + k] = w[k] * sv;
                }
            }
            // Outer axes: every combination of the first D − 1 node indices.
            let outer: usize = dims[..D - 1].iter().product();
            for o in 0..outer {
                let mut f = 1.0;
                let mut rem = o;
                for d in (0..D - 1).rev() {
                    f *= s[d][rem % dims[d]];
                    rem /= dims[d];
                }
                let dst = &mut self.grid[o * last * K..(o + 1) * last * K];
                for (dv, rv) in dst.iter_mut().zip(&row) {
                    *dv += f * rv;
                }
            }
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
        let mut s: [Vec<f64>; D] = std::array::from_fn(|d| vec![0.0; dims[d]]);
        let last = dims[D - 1];
        let outer: usize = dims[..D - 1].iter().product();
        // Σ over the outer axes of f_o · grid row o, then the dot with the last axis basis.
        let mut acc = vec![0.0; last * K];
        for (p, o_val) in self.pts.iter().zip(self.out.iter_mut()) {
            for d in 0..D {
                plan.axes[d].basis(p[d], &mut s[d]);
            }
            acc.fill(0.0);
            for o in 0..outer {
                let mut f = 1.0;
                let mut rem = o;
                for d in (0..D - 1).rev() {
                    f *= s[d][rem % dims[d]];
                    rem /= dims[d];
                }
                let src = &self.grid[o * last * K..(o + 1) * last * K];
                for (av, gv) in acc.iter_mut().zip(src) {
                    *av += f * gv;
                }
            }
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

    fn check<const D: usize>(sigma2: f64, w: f64) {
        let x = cloud::<D>(700, 1, 4.0);
        let mut t = cloud::<D>(600, 2, 4.0);
        // A far-away source and target exercise the exact-row path.
        t.push([40.0; D]);
        let mut x = x;
        x.push([-30.0; D]);
        let c = super::super::estep::outlier_constant(sigma2, w, t.len(), x.len(), D);
        let plan = Plan::<D>::new(&x, &t, sigma2, usize::MAX).expect("plan");
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
    }

    #[test]
    fn fast_gauss_matches_dense_sums() {
        // The box is ~70 wide (far points): only large σ keep the node count small, so the
        // far rows go through the exact path and the rest through the transform.
        for (s2, w) in [(60.0, 0.0), (30.0, 0.2)] {
            check::<2>(s2, w);
            check::<3>(s2, w);
        }
    }

    #[test]
    fn node_count_grows_as_sigma_shrinks_and_is_capped() {
        let x = cloud::<2>(50, 3, 10.0);
        let a = Plan::<2>::new(&x, &x, 4.0, usize::MAX).expect("plan");
        let b = Plan::<2>::new(&x, &x, 0.5, usize::MAX).expect("plan");
        assert!(b.nodes() > a.nodes());
        assert!(a.kernel_err < 1e-12);
        assert!(Plan::<2>::new(&x, &x, 1e-4, usize::MAX).is_none());
        assert!(Plan::<2>::new(&x, &x, 0.5, 10).is_none());
    }
}
