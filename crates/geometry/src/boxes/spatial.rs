//! Spatial distributions of a probabilistic box: `p_G(u)` (eq. 8.3) and `P_PDQ(u)` (eq. 8.2).
//!
//! Two evaluations of eq. 8.3:
//! - **moments** (Appendix A): `p_G(u) = ∫_{v₀∈B(y*)} p_{V(v₀,Y)}(u) dv₀` with `V(v₀, Y)`
//!   approximated by a Gaussian with the moments of [`super::moments`], the `v₀` integral by the
//!   midpoint rule on an `n×n` lattice of the unit box. Each lattice point also carries a spread
//!   of `v₀` of 0.6 lattice cells (mapped by the mean box), so a deterministic box gives a smooth
//!   approximation of its uniform density (edges blurred by ~0.6 cell) instead of `n²` spikes. Smooth, good for plots and query points; `O(n²)` Gaussians per query point.
//! - **sampled** (the second line of eq. 8.3, `∫ 1[u∈B(y)]/A(y) p(y) dy`, by Monte Carlo):
//!   `S` boxes `y_s = ȳ + L z_s` from a fixed table of antithetic standard normal vectors `z_s`
//!   (`L Lᵀ = Σ`), each rasterised uniformly on the grid. On a grid the area `A(y_s)` is the
//!   number of cell centres inside `B(y_s)`, so every sample carries mass exactly `1/S`: the
//!   result is eq. 8.3 for the counting measure of the grid, which is what the discrete
//!   Jaccard index (eq. 8.4 on samples) integrates. A rasterised box costs `O(rows)` (one
//!   interval per row, written into a difference array), so this is the fast path of JIoU.
//!   Samples with a non-positive length or width (possible for wide Gaussians) are skipped.
//!
//! `P_PDQ(u) = Pr(u ∈ B(Y))` (eq. 8.2) is the same Monte Carlo without the `1/A` factor.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::moments::BoxMoments;
use super::{BEV_PARAMS, Box2, Cov5, check_covariance};
use crate::{GeometryError, Result};

/// A regular BEV grid of `nx × ny` cells; cell `(iy, ix)` has centre
/// `(x0 + (ix + ½)·dx, y0 + (iy + ½)·dy)`. Values on it are row-major `[iy·nx + ix]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid2 {
    /// Left edge.
    pub x0: f64,
    /// Bottom edge.
    pub y0: f64,
    /// Cell width.
    pub dx: f64,
    /// Cell height.
    pub dy: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
}

impl Grid2 {
    /// A grid; fails for non-finite edges, non-positive cell sizes or zero cells.
    pub fn new(x0: f64, y0: f64, dx: f64, dy: f64, nx: usize, ny: usize) -> Result<Self> {
        crate::error::check_finite("grid", &[x0, y0, dx, dy])?;
        if dx <= 0.0 || dy <= 0.0 {
            return Err(GeometryError::InvalidParameter {
                what: "grid cell size",
                value: dx.min(dy),
                reason: "cell sizes must be positive",
            });
        }
        if nx == 0 || ny == 0 {
            return Err(GeometryError::InvalidParameter {
                what: "grid cells",
                value: (nx.min(ny)) as f64,
                reason: "a grid needs at least one cell along each axis",
            });
        }
        Ok(Self {
            x0,
            y0,
            dx,
            dy,
            nx,
            ny,
        })
    }

    /// The `n×n` grid spanning the bounding rectangle of the corners of `boxes`.
    pub fn covering<'a>(boxes: impl IntoIterator<Item = &'a Box2>, n: usize) -> Result<Self> {
        Self::covering_corners(boxes.into_iter().map(|b| b.corners()), n)
    }

    /// [`Grid2::covering`] with each box's `(sin r, cos r)` given (one `sin_cos` per box
    /// instead of one per corner; the same corners bit for bit).
    pub(crate) fn covering_trig<'a>(
        boxes: impl Iterator<Item = (&'a Box2, &'a (f64, f64))>,
        n: usize,
    ) -> Result<Self> {
        Self::covering_corners(boxes.map(|(b, &sc)| corners_trig(b, sc)), n)
    }

    fn covering_corners(corners: impl Iterator<Item = [[f64; 2]; 4]>, n: usize) -> Result<Self> {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for cs in corners {
            for c in cs {
                for k in 0..2 {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
        }
        if !(lo[0].is_finite() && hi[0] > lo[0] && hi[1] > lo[1]) {
            return Err(GeometryError::InvalidParameter {
                what: "boxes",
                value: 0.0,
                reason: "no box to cover",
            });
        }
        Self::new(
            lo[0],
            lo[1],
            (hi[0] - lo[0]) / n as f64,
            (hi[1] - lo[1]) / n as f64,
            n,
            n,
        )
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// Whether the grid has no cell (never, for a grid built by [`Grid2::new`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cell centres, row-major.
    pub fn centres(&self) -> Vec<[f64; 2]> {
        let mut out = Vec::with_capacity(self.len());
        for iy in 0..self.ny {
            for ix in 0..self.nx {
                out.push([
                    self.x0 + (ix as f64 + 0.5) * self.dx,
                    self.y0 + (iy as f64 + 0.5) * self.dy,
                ]);
            }
        }
        out
    }
}

/// `1.5·2⁵²`: for `|v| < 2⁵¹`, `v + ROUND_MAGIC` rounds `v` to the nearest integer (the sum's
/// unit in the last place is 1) and holds it in the low bits of its pattern, two's complement.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

/// `⌊v⌋` for `|v| < 2³¹`: the nearest integer, less one where it lies above `v`. Exact, with no
/// libm call and no conversion instruction, so the row loop of [`box_spans`] vectorises.
#[inline(always)]
fn floor_small(v: f64) -> i32 {
    let t = v + ROUND_MAGIC;
    t.to_bits() as i32 - i32::from(t - ROUND_MAGIC > v)
}

/// `⌈v⌉` for `|v| < 2³¹` (see [`floor_small`]).
#[inline(always)]
fn ceil_small(v: f64) -> i32 {
    let t = v + ROUND_MAGIC;
    t.to_bits() as i32 + i32::from(t - ROUND_MAGIC < v)
}

/// The corners of `b` as [`Box2::corners`] computes them, given `(sin r, cos r)`.
fn corners_trig(b: &Box2, (s, c): (f64, f64)) -> [[f64; 2]; 4] {
    [[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]].map(|v0: [f64; 2]| {
        let (a, w) = (b.l * v0[0], b.w * v0[1]);
        [b.cx + c * a - s * w, b.cy + s * a + c * w]
    })
}

/// `(sin r, cos r)` of each box into `out` (cleared first).
pub(crate) fn trig_into(boxes: &[Box2], out: &mut Vec<(f64, f64)>) {
    out.clear();
    out.extend(boxes.iter().map(|b| b.r.sin_cos()));
}

/// For the grid rows from the returned `r0` on, the inclusive range of cells whose centres lie
/// inside `b`, into `first` and `last` (`last < first` for an empty row); returns `(r0, number
/// of cells)`.
///
/// The box is `{p : |(p − c)·e₁| ≤ l/2, |(p − c)·e₂| ≤ w/2}` with `e₁ = (cos r, sin r)`,
/// `e₂ = (−sin r, cos r)`. At a row's height `y` each slab with `e_x ≠ 0` is the x-interval
/// `c_x − (y − c_y)·e_y/e_x ± h/|e_x|`; the row's span is the intersection of the two (a slab
/// with `e_x = 0` only bounds y, which the row range already does). Two multiply-adds per row,
/// no division and no branch.
fn box_spans(
    b: &Box2,
    (s, c): (f64, f64),
    g: &Grid2,
    first: &mut Vec<i32>,
    last: &mut Vec<i32>,
) -> (usize, usize) {
    first.clear();
    last.clear();
    // (e_y / e_x, h / |e_x|) of the two slabs; an unbounded slab contributes (0, ∞).
    let slab = |ex: f64, ey: f64, h: f64| {
        if ex.abs() > 1e-12 {
            (ey / ex, h / ex.abs())
        } else {
            (0.0, f64::INFINITY)
        }
    };
    let (k1, h1) = slab(c, s, 0.5 * b.l);
    let (k2, h2) = slab(-s, c, 0.5 * b.w);
    let half_y = 0.5 * (b.l * s.abs() + b.w * c.abs());
    let (ymin, ymax) = (b.cy - half_y, b.cy + half_y);
    // Rows whose centre y lies in [ymin, ymax] (clamped to [−1, ny] first, which leaves the
    // clipped range unchanged and keeps the rounding helpers in their domain).
    let ny = g.ny as f64;
    let (lo, hi) = ((ymin - g.y0) / g.dy - 0.5, (ymax - g.y0) / g.dy - 0.5);
    if lo.is_nan() || hi.is_nan() {
        return (0, 0);
    }
    let r0 = ceil_small(lo.clamp(-1.0, ny)).max(0);
    let r1 = floor_small(hi.clamp(-1.0, ny)).min(g.ny as i32 - 1);
    if r1 < r0 {
        return (0, 0);
    }
    let (r0, rows) = (r0 as usize, (r1 - r0 + 1) as usize);
    first.resize(rows, 0);
    last.resize(rows, 0);
    // Everything per row in grid units (`(x − x₀)/dx − ½`, so a cell index is an integer):
    // one multiply-add per slab and row, and no division in the loop.
    let inv_dx = 1.0 / g.dx;
    let base = (b.cx - g.x0) * inv_dx - 0.5;
    let (q1, q2) = (k1 * inv_dx, k2 * inv_dx);
    let (hh1, hh2) = (h1 * inv_dx, h2 * inv_dx);
    let nx = g.nx as f64;
    let end = g.nx as i32 - 1;
    let mut count = 0i64;
    for (i, (f, l)) in first.iter_mut().zip(last.iter_mut()).enumerate() {
        let t = g.y0 + ((r0 + i) as f64 + 0.5) * g.dy - b.cy;
        let (u1, u2) = (base - t * q1, base - t * q2);
        // Clamped to [−1, nx] (the span may reach far outside the grid); an empty span
        // (`xr < xl`) gives `last < first`.
        let s0 = fmin(fmax(fmax(u1 - hh1, u2 - hh2), -1.0), nx);
        let s1 = fmin(fmax(fmin(u1 + hh1, u2 + hh2), -1.0), nx);
        let (c0, c1) = (ceil_small(s0).max(0), floor_small(s1).min(end));
        count += i64::from((c1 - c0 + 1).max(0));
        (*f, *l) = (c0, c1);
    }
    (r0, count as usize)
}

/// `max(a, b)` for non-NaN values (a single `maxsd`, without `f64::max`'s NaN handling).
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// `min(a, b)` for non-NaN values.
#[inline(always)]
fn fmin(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// How each rasterised box is weighted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weighting {
    /// `p_G` (eq. 8.3): each box spread uniformly over the cells it covers (mass = its weight).
    Density,
    /// `P_PDQ` (eq. 8.2): each box adds its weight to every cell it covers.
    Indicator,
}

/// Rasterises the mixture `Σ_s ω_s · (box s)` on `grid` (row-major, `grid.len()` values) and
/// returns it with the number of boxes that cover no cell centre (skipped).
pub fn rasterize(
    boxes: &[Box2],
    weights: &[f64],
    grid: &Grid2,
    weighting: Weighting,
) -> Result<(Vec<f64>, usize)> {
    if boxes.len() != weights.len() {
        return Err(GeometryError::WrongLength {
            what: "weights",
            got: weights.len(),
            expected: boxes.len(),
        });
    }
    if let Some(&w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(GeometryError::InvalidParameter {
            what: "mixture weight",
            value: w,
            reason: "weights must be finite and non-negative",
        });
    }
    let mut scratch = RasterScratch::default();
    let mut trig = Vec::new();
    trig_into(boxes, &mut trig);
    let skipped = rasterize_into(
        boxes,
        &trig,
        weights.iter().copied(),
        grid,
        weighting,
        &mut scratch,
    );
    Ok((scratch.out, skipped))
}

/// Buffers reused by [`rasterize_into`] (one per thread in batch evaluations).
#[derive(Debug, Default)]
pub(crate) struct RasterScratch {
    diff: Vec<f64>,
    first: Vec<i32>,
    last: Vec<i32>,
    /// The rasterised distribution, row-major.
    pub(crate) out: Vec<f64>,
}

/// [`rasterize`] without validation into `scratch.out`, given each box's `(sin r, cos r)`
/// ([`trig_into`]); returns the number of skipped boxes.
pub(crate) fn rasterize_into(
    boxes: &[Box2],
    trig: &[(f64, f64)],
    weights: impl Iterator<Item = f64>,
    grid: &Grid2,
    weighting: Weighting,
    scratch: &mut RasterScratch,
) -> usize {
    let (nx, ny) = (grid.nx, grid.ny);
    // Difference array: one extra column per row.
    let diff = &mut scratch.diff;
    diff.clear();
    diff.resize(ny * (nx + 1), 0.0);
    let mut skipped = 0;
    for ((b, &sc), w) in boxes.iter().zip(trig).zip(weights) {
        let (r0, n) = box_spans(b, sc, grid, &mut scratch.first, &mut scratch.last);
        if n == 0 {
            skipped += 1;
            continue;
        }
        let v = match weighting {
            Weighting::Density => w / n as f64,
            Weighting::Indicator => w,
        };
        let rows = diff[r0 * (nx + 1)..].chunks_exact_mut(nx + 1);
        for (drow, (&a, &z)) in rows.zip(scratch.first.iter().zip(&scratch.last)) {
            if z >= a {
                drow[a as usize] += v;
                drow[z as usize + 1] -= v;
            }
        }
    }
    let out = &mut scratch.out;
    out.clear();
    out.resize(nx * ny, 0.0);
    for (orow, drow) in out.chunks_exact_mut(nx).zip(diff.chunks_exact(nx + 1)) {
        let mut acc = 0.0;
        for (o, &d) in orow.iter_mut().zip(drow) {
            acc += d;
            // Cancellation can leave −1e−17 where the density is zero.
            *o = if acc.abs() < 1e-14 * (1.0 + acc.abs()) {
                0.0
            } else {
                acc.max(0.0)
            };
        }
    }
    skipped
}

/// `S` standard normal vectors in ℝ⁵: `S/2` drawn from `Pcg64(seed)` and their negatives
/// (antithetic pairs, so the sample mean is exactly zero).
pub fn normal_table(samples: usize, seed: u64) -> Vec<[f64; BEV_PARAMS]> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let half = samples.div_ceil(2);
    let mut out = Vec::with_capacity(2 * half);
    for _ in 0..half {
        let mut z = [0.0; BEV_PARAMS];
        for v in z.iter_mut() {
            *v = StandardNormal.sample(&mut rng);
        }
        out.push(z);
    }
    for k in 0..half {
        let z = out[k];
        out.push(z.map(|v| -v));
    }
    out.truncate(samples);
    out
}

/// Boxes `y_s = ȳ + L z_s` for the vectors `table` (`L` from [`check_covariance`]); samples
/// with a non-positive size are dropped. A deterministic box gives itself once.
pub fn sample_boxes(mean: &Box2, cov: &Cov5, table: &[[f64; BEV_PARAMS]]) -> Result<Vec<Box2>> {
    if super::is_deterministic(cov) {
        return Ok(vec![*mean]);
    }
    let mut out = Vec::with_capacity(table.len());
    sample_boxes_into(mean, cov, table, &mut out)?;
    Ok(out)
}

/// [`sample_boxes`] appending to `out` (cleared first).
pub(crate) fn sample_boxes_into(
    mean: &Box2,
    cov: &Cov5,
    table: &[[f64; BEV_PARAMS]],
    out: &mut Vec<Box2>,
) -> Result<()> {
    out.clear();
    if super::is_deterministic(cov) {
        out.push(*mean);
        return Ok(());
    }
    let l = check_covariance(cov)?;
    let mu = mean.params();
    for z in table {
        let mut y = mu;
        for i in 0..BEV_PARAMS {
            for j in 0..BEV_PARAMS {
                y[i] += l[i][j] * z[j];
            }
        }
        if y[2] > 0.0 && y[3] > 0.0 {
            out.push(Box2 {
                cx: y[0],
                cy: y[1],
                l: y[2],
                w: y[3],
                r: y[4],
            });
        }
    }
    Ok(())
}

/// Sampled `p_G` (or `P_PDQ`) of the Gaussian box on `grid` (see the module docs).
pub fn sampled_on_grid(
    mean: &Box2,
    cov: &Cov5,
    grid: &Grid2,
    table: &[[f64; BEV_PARAMS]],
    weighting: Weighting,
) -> Result<Vec<f64>> {
    let boxes = sample_boxes(mean, cov, table)?;
    let w = vec![1.0 / boxes.len().max(1) as f64; boxes.len()];
    Ok(rasterize(&boxes, &w, grid, weighting)?.0)
}

/// `P_PDQ(u)` (eq. 8.2) at points `u`: the fraction of the sampled boxes containing `u`.
pub fn pdq_at(
    mean: &Box2,
    cov: &Cov5,
    points: &[[f64; 2]],
    table: &[[f64; BEV_PARAMS]],
) -> Result<Vec<f64>> {
    let boxes = sample_boxes(mean, cov, table)?;
    let n = boxes.len().max(1) as f64;
    Ok(points
        .iter()
        .map(|u| boxes.iter().filter(|b| b.contains(*u)).count() as f64 / n)
        .collect())
}

/// `p_G(u)` (eq. 8.3) at points `u` by the Appendix A moment approximation with an `n×n`
/// lattice of `v₀` (see the module docs). Integrates to 1 over the plane.
pub fn pg_moments_at(
    mean: &Box2,
    cov: &Cov5,
    points: &[[f64; 2]],
    lattice: usize,
) -> Result<Vec<f64>> {
    check_covariance(cov)?;
    if lattice == 0 {
        return Err(GeometryError::InvalidParameter {
            what: "lattice",
            value: 0.0,
            reason: "need at least one v₀ per axis",
        });
    }
    let mom = BoxMoments::new(mean, cov);
    let h = 1.0 / lattice as f64;
    // Spread of v₀ around each lattice point, mapped by the mean box: R diag(l,w) (κh)² diag(l,w) Rᵀ
    // with κ = 0.6: a sum of Gaussians spaced h apart is flat to 2·exp(−2π²κ²) ≈ 0.2 % only when
    // their standard deviation is at least ~0.6 h (the uniform cell's own h/√12 ≈ 0.29 h leaves
    // a 40 % ripple).
    let (s, c) = mean.r.sin_cos();
    let k2 = (0.6 * h) * (0.6 * h);
    let (a, b) = (mean.l * mean.l * k2, mean.w * mean.w * k2);
    let cell = [
        [c * c * a + s * s * b, c * s * (a - b)],
        [c * s * (a - b), s * s * a + c * c * b],
    ];
    let n_comps = crate::alloc::checked_count("p_G lattice components", lattice, lattice)?;
    let mut comps = crate::alloc::try_with_capacity("p_G lattice components", n_comps)?;
    for i in 0..lattice {
        for j in 0..lattice {
            let v0 = [-0.5 + (i as f64 + 0.5) * h, -0.5 + (j as f64 + 0.5) * h];
            let (m, mut k) = mom.point(v0);
            for p in 0..2 {
                for q in 0..2 {
                    k[p][q] += cell[p][q];
                }
            }
            let det = k[0][0] * k[1][1] - k[0][1] * k[1][0];
            let inv = [
                [k[1][1] / det, -k[0][1] / det],
                [-k[1][0] / det, k[0][0] / det],
            ];
            let norm = 1.0 / (2.0 * std::f64::consts::PI * det.sqrt());
            comps.push((m, inv, norm));
        }
    }
    let weight = 1.0 / comps.len() as f64;
    Ok(points
        .iter()
        .map(|u| {
            comps
                .iter()
                .map(|(m, inv, norm)| {
                    let (dx, dy) = (u[0] - m[0], u[1] - m[1]);
                    let q = inv[0][0] * dx * dx + 2.0 * inv[0][1] * dx * dy + inv[1][1] * dy * dy;
                    // The form is positive definite: NaN only comes from ∞ − ∞ when the squares
                    // overflow (a point ~1e154 away), where the density is 0.
                    if q.is_nan() {
                        0.0
                    } else {
                        norm * (-0.5 * q).exp()
                    }
                })
                .sum::<f64>()
                * weight
        })
        .collect())
}

#[cfg(test)]
mod rounding_tests {
    use super::{ceil_small, floor_small};

    /// The rounding-constant floor and ceil equal libm's on integers, half-integers, their
    /// neighbouring floats and a dense sweep of the span domain [−1, n].
    #[test]
    fn floor_and_ceil_match_libm() {
        let mut values = vec![-1.0, -0.5, -0.0, 0.0, 0.5, 29.5, 30.0, 1e9, -1e9];
        for k in -2..=40 {
            let v = f64::from(k);
            for x in [v, v + 0.5, v - 0.5] {
                values.extend([x, x.next_up(), x.next_down()]);
            }
        }
        values.extend((0..100_000).map(|i| -1.0 + 41.0 * f64::from(i) / 100_000.0));
        for v in values {
            assert_eq!(floor_small(v), v.floor() as i32, "floor {v:e}");
            assert_eq!(ceil_small(v), v.ceil() as i32, "ceil {v:e}");
        }
    }
}
