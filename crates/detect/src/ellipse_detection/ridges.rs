//! Thin lines found on their centre line: Steger's curvilinear-structure detector (Steger
//! 1998, "An unbiased detector of curvilinear structures", IEEE PAMI 20(2)) feeding the same
//! arcs, Algorithms 1–2 and a-contrario validation as the edges of [`super::detect_ellipses`].
//!
//! A curve drawn as a line narrower than about 2 px (a wafer rim seen as a thin bright curve,
//! a wire, a scratch) has two edges of opposite polarity within the reach of any edge operator:
//! their gradients overlap and the edge points interfere (issue 42: most missed rims are such
//! lines). Its centre is instead where the second derivative across it is extreme and the first
//! derivative vanishes, which the scale-`σ` Gaussian derivatives of the image give directly:
//!
//! - the Hessian `H = [[r_xx, r_xy], [r_xy, r_yy]]` splits into its mean `m = (r_xx + r_yy)/2`
//!   and its anisotropic part `q = √(((r_xx − r_yy)/2)² + r_xy²)`; the eigenvalue of largest
//!   magnitude is `m + sign(m)·q` and its unit eigenvector `n` is the line's normal;
//! - a bright line has that eigenvalue negative, a dark line positive (the ridge's `sign`);
//! - along `n`, the Taylor polynomial `r + t·(∇r·n) + ½t²λ` has its extremum at
//!   `t = −(∇r·n)/λ`; the pixel holds a centre point when that lies inside it
//!   (`|t·n_x|, |t·n_y| ≤ ½`), at the sub-pixel position `p + t·n`.
//!
//! **Thresholds from the image's noise.** Under white pixel noise of standard deviation `σ_n`
//! (from [`super::noise::gradient_noise`], `σ_n = σ_g/√(12/64)`), `(r_xx − r_yy)/2` and `r_xy`
//! are independent zero-mean Gaussians of equal variance (exactly for continuous Gaussian
//! derivatives; the sampled kernels' two variances are averaged), so `q` is Rayleigh with scale
//! `s_q`: the hysteresis thresholds on `q` are its tails at [`super::P_HIGH`] and
//! [`super::P_LOW`], as the Canny thresholds of the edges are.
//!
//! **A-contrario test on the Hessian.** A pixel on a candidate ellipse is *aligned* when
//! `q ≥ ρ` (the low threshold), its largest-magnitude eigenvalue has the ridge's sign and its
//! eigenvector is within `±π/8` of the ellipse's normal (directions modulo π). Under the noise
//! model the trace and the anisotropic part are independent, the sign is + or − with
//! probability ½ each (the distribution of `H` is symmetric under `H → −H`) and the
//! eigenvector's orientation is uniform modulo π, so the probability is `½ · ¼ = 1/8`: the
//! same [`super::a_contrario::ALIGNMENT_PROBABILITY`] as for gradients, and the same NFA.
//! Neighbouring pixels' Hessians share pixels (more than the 3×3 Sobel's do); the pure-noise
//! test of this module measures the false alarms that leaves.
//!
//! **Linking.** The normal is defined modulo π; each centre point carries it turned into the
//! lower half plane (`n_y > 0`, or `n_x > 0` on the horizontal) as the pseudo-gradient that
//! [`crate::edges::link_edges`] follows. A closed curve's chain therefore breaks where its
//! tangent is vertical, which is also where [`crate::edges::split_arcs`] cuts it into quadrant
//! arcs, so nothing is lost. All arcs of one ridge sign take polarity `+1` for the assembly;
//! the detections report polarity `0` (the centre of a thin line).
//!
//! **Scale.** A bar profile of width `w` has a single centre extremum for `σ ≥ w/(2√3)`;
//! two lines `d` apart stay separate for `d ≳ 2.5σ`. [`ridge_scale`] takes the smallest scale
//! that covers the widest line asked for, floored at [`MIN_RIDGE_SCALE`].

// `!(x > y)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::f64::consts::PI;

use autoteach_geometry::conic::Ellipse;
use nalgebra::Vector2;
use rayon::prelude::*;

use super::a_contrario::{self, Alignment};
use super::{EllipseDetectParams, EllipseDetection, MIN_RESIDUAL, P_HIGH, P_LOW, noise};
use crate::Result;
use crate::assembly::{AssemblyParams, assemble};
use crate::edges::{ArcParams, EdgeMap, Edgel, GrayView, LinkParams, Pixel};
use crate::edges::{chain_noise, link_edges, split_arcs};

/// Smallest derivative scale (pixels): below it the sampled Gaussian is no longer smooth and
/// the second derivatives alias.
pub const MIN_RIDGE_SCALE: f64 = 0.6;

/// The derivative scale for lines up to `max_width` pixels wide: `max(w/(2√3), MIN_RIDGE_SCALE)`.
pub fn ridge_scale(max_width: f64) -> f64 {
    (max_width / (2.0 * 3f64.sqrt())).max(MIN_RIDGE_SCALE)
}

/// Largest Taylor step (pixels, per coordinate) accepted from a pixel: Steger's `½` plus
/// 0.15 px, so that where a line crosses the boundary between two pixels and both steps
/// overshoot it slightly (the quadratic model's bias on a narrow line) the point is still
/// found; farther steps are too biased to use (0.5–1 px on a 1 px line at `σ` = 0.8).
const STEP_MARGIN: f32 = 0.65;

/// No centre point at this pixel.
const NONE: u32 = u32::MAX;

/// The scale-`σ` Gaussian derivatives of an image (grey levels per pixel and per pixel²).
pub struct RidgeField {
    width: usize,
    height: usize,
    rx: Vec<f32>,
    ry: Vec<f32>,
    rxx: Vec<f32>,
    rxy: Vec<f32>,
    ryy: Vec<f32>,
    /// Scale `s_q` of the Rayleigh distribution of the anisotropic part `q` under the image's
    /// noise.
    pub noise: f64,
}

/// Sampled Gaussian, first- and second-derivative correlation kernels on `[−r, r]`, normalised
/// so that a constant, a ramp `x` and a parabola `x²` give exactly 1, 1 and 2.
fn kernels(sigma: f64) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let r = (4.0 * sigma).ceil() as i64;
    let ks: Vec<f64> = (-r..=r).map(|k| k as f64).collect();
    let g: Vec<f64> = ks
        .iter()
        .map(|k| (-k * k / (2.0 * sigma * sigma)).exp())
        .collect();
    let sg: f64 = g.iter().sum();
    let g: Vec<f64> = g.iter().map(|v| v / sg).collect();
    let d1: Vec<f64> = ks.iter().zip(&g).map(|(k, v)| k * v).collect();
    let s1: f64 = ks.iter().zip(&d1).map(|(k, v)| k * v).sum();
    let d1: Vec<f64> = d1.iter().map(|v| v / s1).collect();
    let d2: Vec<f64> = ks
        .iter()
        .zip(&g)
        .map(|(k, v)| (k * k - sigma * sigma) * v)
        .collect();
    let c: f64 = d2.iter().sum();
    let d2: Vec<f64> = d2.iter().zip(&g).map(|(v, gv)| v - c * gv).collect();
    let s2: f64 = ks.iter().zip(&d2).map(|(k, v)| k * k * v).sum();
    let d2: Vec<f64> = d2.iter().map(|v| 2.0 * v / s2).collect();
    let f = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
    (f(g), f(d1), f(d2))
}

/// Correlation of `src` (rows of `w`) with `kernel` along x, clamped borders.
fn correlate_x(src: &[f32], w: usize, kernel: &[f32]) -> Vec<f32> {
    let r = kernel.len() / 2;
    let mut out = vec![0.0f32; src.len()];
    out.par_chunks_mut(w)
        .zip(src.par_chunks(w))
        .for_each(|(o, row)| {
            for (x, ov) in o.iter_mut().enumerate() {
                *ov = if x >= r && x + r < w {
                    let win = &row[x - r..=x + r];
                    win.iter().zip(kernel).map(|(p, k)| p * k).sum()
                } else {
                    kernel
                        .iter()
                        .enumerate()
                        .map(|(k, kv)| kv * row[(x + k).saturating_sub(r).min(w - 1)])
                        .sum()
                };
            }
        });
    out
}

/// Correlation of `src` (rows of `w`, `h` rows) with `kernel` along y, clamped borders: whole
/// rows at a time (vector code).
fn correlate_y(src: &[f32], w: usize, h: usize, kernel: &[f32]) -> Vec<f32> {
    let r = kernel.len() / 2;
    let mut out = vec![0.0f32; src.len()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        for (k, &kv) in kernel.iter().enumerate() {
            let yy = (y + k).saturating_sub(r).min(h - 1);
            let row = &src[yy * w..(yy + 1) * w];
            for (ov, p) in o.iter_mut().zip(row) {
                *ov += kv * p;
            }
        }
    });
    out
}

impl RidgeField {
    /// The derivatives of `image` at scale `sigma`, with the noise scale from the gradient noise
    /// `sigma_g` (Sobel/8 per component, [`super::noise::gradient_noise`]).
    pub fn new<T: Pixel>(image: &GrayView<'_, T>, sigma: f64, sigma_g: f64) -> Self {
        let (w, h) = (image.width(), image.height());
        let grey: Vec<f32> = image.data().par_iter().map(|p| p.grey()).collect();
        let (g, d1, d2) = kernels(sigma);
        let tg = correlate_x(&grey, w, &g);
        let t1 = correlate_x(&grey, w, &d1);
        let t2 = correlate_x(&grey, w, &d2);
        let rx = correlate_y(&t1, w, h, &g);
        let rxy = correlate_y(&t1, w, h, &d1);
        let rxx = correlate_y(&t2, w, h, &g);
        let ry = correlate_y(&tg, w, h, &d1);
        let ryy = correlate_y(&tg, w, h, &d2);
        let sq = |v: &[f32]| v.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>();
        let cross: f64 = d2.iter().zip(&g).map(|(a, b)| f64::from(a * b)).sum();
        let var_xy = sq(&d1).powi(2);
        let var_aniso = 0.5 * (sq(&d2) * sq(&g) - cross * cross);
        let sigma_n = sigma_g / (12.0f64 / 64.0).sqrt();
        Self {
            width: w,
            height: h,
            rx,
            ry,
            rxx,
            rxy,
            ryy,
            noise: sigma_n * (0.5 * (var_xy + var_aniso)).sqrt(),
        }
    }

    /// The unit normal of a line of `sign` (−1 bright, +1 dark) at pixel `k`, its eigenvalue
    /// and `q`, when the largest-magnitude eigenvalue has that sign and `q ≥ rho`.
    #[inline]
    fn normal(&self, k: usize, sign: f32, rho: f32) -> Option<(Vector2<f32>, f32, f32)> {
        let (a, b, c) = (self.rxx[k], self.rxy[k], self.ryy[k]);
        let m = 0.5 * (a + c);
        let half = 0.5 * (a - c);
        let q2 = half * half + b * b;
        if !(m * sign > 0.0 && q2 >= rho * rho && q2 > 0.0) {
            return None;
        }
        let q = q2.sqrt();
        let lambda = m + sign * q;
        // Eigenvector of λ: (b, λ − a) or (λ − c, b), whichever is longer (both are exact).
        let (u, v) = (Vector2::new(b, lambda - a), Vector2::new(lambda - c, b));
        let e = if u.norm_squared() >= v.norm_squared() {
            u
        } else {
            v
        };
        let n = e.norm();
        (n > 0.0).then(|| (e / n, lambda, q))
    }

    /// The centre points of lines of `sign` after hysteresis on `q` (`low`, `high`), as an
    /// [`EdgeMap`] whose `grad` is the normal turned into the lower half plane, of length `q`.
    pub fn centre_points(&self, sign: f32, low: f64, high: f64) -> EdgeMap {
        let (w, h) = (self.width, self.height);
        let (low, high) = (low as f32, high as f32);
        // Per row, the extrema near their pixel: (point, |t|, q).
        let rows: Vec<Vec<(Edgel, f32, f32)>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut out = Vec::new();
                for x in 0..w {
                    let k = y * w + x;
                    let Some((n, lambda, q)) = self.normal(k, sign, low) else {
                        continue;
                    };
                    let t = -(self.rx[k] * n.x + self.ry[k] * n.y) / lambda;
                    let (ox, oy) = (t * n.x, t * n.y);
                    if !(ox.abs() <= STEP_MARGIN && oy.abs() <= STEP_MARGIN) {
                        continue;
                    }
                    let canon = if n.y > 0.0 || (n.y == 0.0 && n.x > 0.0) {
                        n
                    } else {
                        -n
                    };
                    let pos = Vector2::new(x as f64 + f64::from(ox), y as f64 + f64::from(oy));
                    let (tx, ty) = (pos.x.round(), pos.y.round());
                    if tx < 0.0 || ty < 0.0 || tx >= w as f64 || ty >= h as f64 {
                        continue;
                    }
                    let grad = Vector2::new(f64::from(canon.x), f64::from(canon.y)) * f64::from(q);
                    let (px, py) = (tx as u32, ty as u32);
                    out.push((Edgel { pos, grad, px, py }, t.abs(), q));
                }
                out
            })
            .collect();
        // Each point goes to the pixel that contains it (Steger's `|t·n| ≤ ½`, with the
        // margin of `STEP_MARGIN`); of several estimates of one pixel the one with the smallest
        // step is kept.
        let all: Vec<(Edgel, f32, f32)> = rows.into_iter().flatten().collect();
        let mut best = vec![NONE; w * h];
        for (i, (e, t, _)) in all.iter().enumerate() {
            let j = e.py as usize * w + e.px as usize;
            if best[j] == NONE || *t < all[best[j] as usize].1 {
                best[j] = i as u32;
            }
        }
        // Hysteresis: keep the points 8-connected to a strong one.
        let mut keep = vec![false; w * h];
        let mut stack: Vec<usize> = Vec::new();
        for (j, &i) in best.iter().enumerate() {
            if i != NONE && all[i as usize].2 >= high {
                keep[j] = true;
                stack.push(j);
            }
        }
        while let Some(k) = stack.pop() {
            let (x, y) = (k % w, k / w);
            for qy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for qx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    let j = qy * w + qx;
                    if !keep[j] && best[j] != NONE {
                        keep[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        let mut index = vec![NONE; w * h];
        let mut edgels = Vec::new();
        for (j, &i) in best.iter().enumerate() {
            if keep[j] {
                index[j] = edgels.len() as u32;
                edgels.push(all[i as usize].0);
            }
        }
        EdgeMap {
            width: w,
            height: h,
            edgels,
            index,
        }
    }

    /// The anisotropic part `q` at every `stride`-th pixel of every `stride`-th row, away
    /// from the border by the kernel's radius (for the noise model's test).
    pub fn anisotropy_sample(&self, stride: usize) -> Vec<f64> {
        let (w, h) = (self.width, self.height);
        let m = 8;
        let mut out = Vec::new();
        for y in (m..h.saturating_sub(m)).step_by(stride.max(1)) {
            for x in (m..w.saturating_sub(m)).step_by(stride.max(1)) {
                let k = y * w + x;
                let half = 0.5 * (self.rxx[k] - self.ryy[k]);
                out.push(f64::from((half * half + self.rxy[k] * self.rxy[k]).sqrt()));
            }
        }
        out
    }

    /// The a-contrario counts of a line of `sign` along the arc of `ellipse` from eccentric
    /// angle `start` over `length` radians (see the module documentation); pixels visited as in
    /// [`a_contrario::count_alignment`].
    pub fn count_alignment(
        &self,
        ellipse: &Ellipse,
        extent: (f64, f64),
        sign: f32,
        rho: f64,
    ) -> Alignment {
        let cos_tol = (PI / 8.0).cos() as f32;
        let mut out = Alignment { n: 0, k: 0 };
        for (px, py, normal) in
            a_contrario::distinct_pixels(ellipse, extent, self.width, self.height)
        {
            out.n += 1;
            if let Some((n, _, _)) = self.normal(py * self.width + px, sign, rho as f32) {
                let dot = n.x * normal.x as f32 + n.y * normal.y as f32;
                if dot.abs() >= cos_tol {
                    out.k += 1;
                }
            }
        }
        out
    }

    /// `−log₁₀ NFA` of a line of `sign` on `e` over the extent its `points` cover.
    fn score(
        &self,
        e: &Ellipse,
        points: &[Vector2<f64>],
        sign: f32,
        log_nt: f64,
        rho: f64,
    ) -> Option<f64> {
        a_contrario::score_support(e, points, log_nt, |extent| {
            self.count_alignment(e, extent, sign, rho)
        })
    }
}

/// Ratio of the second derivative's side lobe to its centre for a Gaussian-blurred line: the
/// positive lobe of `(x²/σ² − 1)·e^{−x²/2σ²}` peaks at `x = √3σ` with `2e^{−3/2}` = 0.446.
const SIDE_LOBE: f64 = 0.446;

/// The points of `map` that are not a side lobe of a line of the opposite sign in `other`:
/// a point within `reach` (the kernels' support) of an opposite point whose `q` exceeds its
/// own by more than the side lobe's ratio ([`SIDE_LOBE`]) is the ghost of that line (a strong
/// bright line has a faint "dark line" on each side, where the smoothed profile flattens into
/// the background and the lobe's tail still exceeds the noise), not a line of its own. A true
/// valley between two lines has the sum of their lobes, about twice that.
fn without_side_lobes(map: &EdgeMap, other: &EdgeMap, reach: f64) -> EdgeMap {
    let (w, h) = (map.width, map.height);
    let r = reach.ceil() as i64;
    let keep = |e: &Edgel| {
        let q = e.grad.norm();
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (i64::from(e.px) + dx, i64::from(e.py) + dy);
                if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                    continue;
                }
                let j = other.index[y as usize * w + x as usize];
                if j == NONE {
                    continue;
                }
                let f = &other.edgels[j as usize];
                if (f.pos - e.pos).norm() <= reach && q < SIDE_LOBE * f.grad.norm() {
                    return false;
                }
            }
        }
        true
    };
    let mut index = vec![NONE; w * h];
    let mut edgels = Vec::with_capacity(map.edgels.len());
    for e in map.edgels.iter().filter(|e| keep(e)) {
        index[e.py as usize * w + e.px as usize] = edgels.len() as u32;
        edgels.push(*e);
    }
    EdgeMap {
        width: w,
        height: h,
        edgels,
        index,
    }
}

/// Elliptic curves drawn as thin lines, bright and dark, found on their centre lines at
/// derivative scale `sigma` (see the module documentation), with `params`' arc length, size
/// limits, gap and `max_nfa`. Polarity 0; sorted by decreasing score.
///
/// # Errors
/// As [`super::detect_ellipses`].
pub fn detect_line_ellipses<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &EllipseDetectParams,
    sigma: f64,
) -> Result<Vec<EllipseDetection>> {
    Ok(detect_signed_lines(image, params, sigma)?
        .into_iter()
        .map(|(d, _)| d)
        .collect())
}

/// [`detect_line_ellipses`] with each line's brightness: `+1` brighter than its surroundings,
/// `−1` darker.
///
/// # Errors
/// As [`super::detect_ellipses`].
pub fn detect_signed_lines<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &EllipseDetectParams,
    sigma: f64,
) -> Result<Vec<(EllipseDetection, i8)>> {
    let (w, h) = (image.width(), image.height());
    let diagonal = ((w * w + h * h) as f64).sqrt();
    let sigma_g = params
        .gradient_noise
        .unwrap_or_else(|| noise::gradient_noise(image, 3));
    let field = RidgeField::new(image, sigma, sigma_g);
    let low = noise::rayleigh_quantile(field.noise, P_LOW);
    let high = noise::rayleigh_quantile(field.noise, P_HIGH);
    let log_nt = a_contrario::log10_tests(w, h);
    let min_score = -params.max_nfa.log10();
    let max_semi_major = params.max_semi_major.unwrap_or(2.0 * diagonal);
    let arc_params = ArcParams {
        min_points: params.min_arc_points,
        ..ArcParams::default()
    };
    let bright = field.centre_points(-1.0, low, high);
    let dark = field.centre_points(1.0, low, high);
    // The kernels' support (4σ) plus the largest Taylor step.
    let support = 4.0 * sigma + 1.0;
    let maps = [
        without_side_lobes(&bright, &dark, support),
        without_side_lobes(&dark, &bright, support),
    ];
    let reach = 2.5 * sigma;
    let mut found = Vec::new();
    for (sign, map) in [-1.0f32, 1.0].into_iter().zip(maps) {
        let chains = link_edges(&map, &LinkParams::default())?;
        let mut arcs = split_arcs(&map, &chains, &arc_params)?;
        if arcs.len() < 2 {
            continue;
        }
        for a in &mut arcs {
            a.polarity = 1;
        }
        let mut noise: Vec<f64> = arcs.iter().map(|a| chain_noise(&a.points)).collect();
        let mid = noise.len() / 2;
        let (_, edge_noise, _) = noise.select_nth_unstable_by(mid, f64::total_cmp);
        let assembly = AssemblyParams {
            residual_threshold: (3.0 * *edge_noise).max(MIN_RESIDUAL),
            max_gap: params.max_gap.unwrap_or(0.5 * diagonal),
            max_semi_major,
            ..AssemblyParams::default()
        };
        let segments = assemble(&arcs, &assembly)?;
        let mut dets: Vec<EllipseDetection> = segments
            .par_iter()
            .filter_map(|s| {
                let e = s.fit.ellipse;
                let score = field.score(&e, &s.points, sign, log_nt, low)?;
                (score >= min_score && e.b >= params.min_semi_minor && e.a <= max_semi_major).then(
                    || EllipseDetection {
                        ellipse: e,
                        points: s.points.clone(),
                        covariance: s.fit.covariance,
                        residual: s.fit.residual_mean,
                        score,
                        polarity: 1,
                    },
                )
            })
            .collect();
        super::sort_by_score(&mut dets);
        let dets = super::drop_duplicates(dets, assembly.residual_threshold);
        let merged = super::refine::merge_split(dets, assembly.residual_threshold);
        let dets: Vec<EllipseDetection> = merged
            .into_iter()
            .filter_map(|(mut d, changed)| {
                if changed {
                    d.score = field.score(&d.ellipse, &d.points, sign, log_nt, low)?;
                }
                (d.score >= min_score).then_some(d)
            })
            .collect();
        // Points where another line of this sign passes within the derivative kernel's reach
        // (two rims converging at their tips) are left out of the fit, as for edges.
        let boxes = super::refine::boxes(&dets, reach);
        let refined: Vec<EllipseDetection> = (0..dets.len())
            .into_par_iter()
            .map(|i| {
                super::refine::trim_and_refit(&dets, &boxes, i, reach, *edge_noise)
                    .and_then(|mut d| {
                        d.score = field.score(&d.ellipse, &d.points, sign, log_nt, low)?;
                        (d.score >= min_score).then_some(d)
                    })
                    .unwrap_or_else(|| dets[i].clone())
            })
            .collect();
        let brightness = if sign < 0.0 { 1 } else { -1 };
        found.extend(refined.into_iter().filter_map(|mut d| {
            d.polarity = 0;
            (d.ellipse.b >= params.min_semi_minor).then_some((d, brightness))
        }));
    }
    found.sort_by(|p, q| super::by_score(&p.0, &q.0));
    Ok(found)
}
