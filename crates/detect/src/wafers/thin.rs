//! Level wafers: one intensity fit of both rims of a wafer, column by column (seed
//! 000_3b1454b2b2194811.txt §3.2, Fig. 3.2: the two rims are the images of two parallel circles
//! one wafer thickness apart; §3.5: disturbance wafers a few slots from the camera's height) —
//! thin wafers, whose side band lies a few pixels from the face's silhouette
//! ([`Model::Thin`]), and wider ones ([`Model::Band`], last section).
//!
//! A wafer near the camera's height images as two flat ellipses (`b` 1–9 px for `a` ≈ 300 px)
//! whose front arcs bound a bright band 2–4 px high, and, for a wafer seen from above, the dark
//! top face inside the upper rim (from below: the bottom face inside the lower rim). There the
//! edge-point fits are biased by several per cent in `b`: the blurred edges of band and face
//! push each other's gradient maxima apart, and each rim's front arc alone (a flat half
//! ellipse) lets centre, `a` and `b` trade off. This module fits the image itself instead, one
//! column at a time (the rims of a flat ellipse with a near-horizontal major axis cross every
//! column once on each arc, at slopes under 3 %, so a column is a profile across them): in
//! column `x`, rows `y`,
//!
//! `I(y) = L₀ + Σⱼ (Lⱼ₊₁ − Lⱼ)·Φ((y − Eⱼ(x))/σ)`,  `j = 1, 2, 3`,
//!
//! with the three edges `Eⱼ(x)` (in image order) where the column meets the back arc of the
//! face rim (the face's silhouette) and the front arcs of the two rims, four grey levels `Lⱼ`
//! per column (background, face, band, background: solved linearly for each column at every
//! step — variable projection) and one blur `σ`. The rims are tied by the wafer's geometry (the
//! rim offset prior, [`RimOffsetPrior`], `rim_prior.rs`): the lower rim is the image of the
//! upper rim's circle moved by the wafer's thickness against its normal, computed exactly from
//! the upper rim's ellipse, the focal length and the principal point ([`RimMap`], the exact form
//! of `rim_prior.rs`: the circle's pose from its image, then the moved circle's image). So six
//! parameters `(cx, cy, a, b, θ, σ)` of the upper rim describe both, and the face's silhouette
//! fixes `b` through the rim's full height where the background behind differs from the face.
//! (Before the exact map, the lower rim was the upper one moved by the offset (∗) with the same
//! `a`, `θ` and centre column and `b` changed by `(t/R)·a²/f`: off by up to 0.3 px in `cy` and
//! `b` on the benchmark's views, and by 0.07 px in `b` — 2 % of a thin rim's — for wafers seen
//! from above. The exact map raised the benchmark's recall with the prior from 0.9609 to 0.9653
//! on seed 3 and from 0.9544 to 0.9574 on seed 4, precision from 0.9866 to 0.9911 and from
//! 0.9804 to 0.9834.)
//!
//! Columns that the model does not describe (clutter behind the band, a neighbouring edge in
//! the window) are found by their residual and left out (two rounds), and the fit is accepted
//! only when the residual of the columns kept is at the image's noise level.
//!
//! **Wider wafers** ([`Model::Band`], `b` from [`MAX_B`]). The edge-point fits
//! of these rims are off in `b` by ≈ 0.1 px (sd over the benchmark's matched rims, flat in `b`
//! from 9 to 400 px), also on noise-free renders with 16×16 anti-aliasing: the per-profile
//! band fits along the normals (`band.rs`, `refine.rs`) leave a bias of the narrow band's near
//! edge that the reference rim's fit, and through the prior its partner's, inherits (seed 3
//! image 123, noise-free: the upper rim's front-arc bottom 0.20 px high, `b` −1.15 %). For
//! `b` of 9–25 px 1 % is 0.09–0.25 px, so these rims failed the benchmark's 1 % criterion and
//! were also its false positives. The same column model with the two front arcs only (two
//! edges, three levels per column: face, band, background, in image order from above; the
//! face's silhouette is far from the band) measures them to a few hundredths of a pixel (same image: `b` −0.09 % and
//! −0.02 %). Wafers seen from below too since the exact map: with the closed form (∗), whose
//! offset is 0–10 % off for them, the fit moved as many such rims out of the criterion as into
//! it; with the exact map it gains 24 rims and loses 2 on seed 3 (22 and 3 on seed 4; the
//! losses are wafers seen from below with `b` ≈ 10 px, fitted 1.0–1.3 % high), and recall with
//! the prior rose from 0.9653 to 0.9740 (seed 3) and from 0.9574 to 0.9632 (seed 4).
//!
//! **The edge profile** ([`EdgeProfile`]). `Φ` above is a camera's: the optics blur before the
//! pixels integrate, so the profile is the same at every sub-pixel position of the edge. The
//! simulator's renderer integrates the pixels first and blurs after with a Gaussian sampled on
//! the pixel grid: its PSF is a staircase and its profile `Σₖ wₖ·clamp(y − E − k + ½, 0, 1)`
//! piecewise linear in `E`. Fitted to such columns, `Φ` leaves residuals of 2 grey levels on
//! noise-free renders and moves the edges by up to 0.05 px with their sub-pixel phase (seed 3
//! image 87, three columns at the front arc's apex: the band's edges −0.05 / +0.02 px off;
//! with the staircase profile 0.01 px, σ 0.80 — the renderer's — and residuals of 0.1–0.3,
//! the u8 rounding). Near an arc's apex the phase is the same over many columns, so the error
//! does not average out and goes into `b`: the wafers seen from below with `b` ≈ 10 px fitted
//! 1.0–1.3 % high were this. [`EdgeProfile::PixelGrid`] models it (σ still fitted): the
//! benchmark's recall with the prior rose from 0.9740 to 0.9768 (seed 3) and from 0.9632 to
//! 0.9721 (seed 4), precision from 0.9941 to 0.9941 and from 0.9894 to 0.9985.
//!
//! **Wafers seen edge-on** (`b` 1–4 px; found by `sliver.rs`, which also measures the ends of
//! their band, the rims' tips `cx ± a`, to ≈ 0.1 px). Fitted from the truth with all six
//! parameters free, the tips' columns let `a` run 0.2–0.9 % long and the centre slide by up to
//! 2 px; with `cx` and `a` held at the truth, `b` came out up to 1.8 % off on the noisy renders but
//! within 0.4 % on noise-free ones with the same screening, and within 1.2 % noise-free when the
//! screening was told the noisy images' noise level: the columns near the band's ends, in front of
//! the carrier (slot ridges in the window, their mirror images in the faces), are 1–2 grey levels
//! RMS off the model, under one column's noise but coherent over tens of columns, and move the
//! band's edges there by 0.05–0.15 px. So such a fit holds `cx` and `a` at the measured ends and
//! screens the columns also in runs of 21 ([`quiet_runs`]: a run's pooled mean square residual
//! against the median column's, within 3 standard errors). From the truth with held ends the run
//! screen brought the benchmark's edge-on wafers (seeds 3 and 4, nine wafers) from 10 of 18 rims
//! within 1 % to 16 of 18. The run screen on every thin fit (free `cx`, `a`) cost recall instead
//! (seed 3 0.9797 → 0.9768, seed 4 0.9721 → 0.9691): it stays with the held ends.
//!
//! Both models: an edge crossing a column at slope `s` is blurred along the column by
//! `σ·√(1 + s²)` (for the staircase, its kernel's σ); clipped samples (a saturated band) are censored — they stay out of the
//! levels' solve and only require the model to reach the clip level; the Jacobian is
//! Kaufman's (the derivative at fixed levels projected onto the complement of the levels'
//! basis), with the edges' derivatives analytic ([`arc_row`]). The solves before the last run
//! on an even subset of at most [`MAX_FIT_COLUMNS`] columns (speed); the screening and the
//! last solve use all columns.

use super::band::{cdf_and_density, cholesky_solve};
use super::joint::ray_hit;
use super::rim_prior::{RimMap, RimOffsetPrior};
use super::{GrayView, Pixel, RimKind, WaferEdge};
use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Matrix6, SMatrix, SVector, Vector2, Vector6};

/// Largest semi-minor axis (pixels, of either rim's edge-point fit) of a rim pair refitted
/// here: the band is then a few pixels from the face's silhouette, and the front arcs' slopes
/// stay small. Wider rims are measured by the edge-point fits. On the wafer benchmark (pixel-grid
/// edge profile, seed 3 / seed 4 recall and precision) 9 px is the best of 8, 9 and 10 px:
/// 0.9768 / 0.9941, 0.9721 / 0.9985 (the sweeps: docs/design/wafer-rims.md).
pub(super) const MAX_B: f64 = 9.0;
/// [`MAX_B`] for a wafer seen from above (the lower rim's `b` the larger): there the face's
/// silhouette still pins `b` where the front arcs alone leave it to trade off with `a` and the
/// centre (seed 3 image 143, `b` 8.3 / 9.0 px: the band model 1.75 % high from the truth, the
/// thin model 0.05 %). One limit of 9.5 px for both sides lost wafers seen from below with `b`
/// 8.4–9.3 px (thin fits 1.0–1.3 % off; seed 3 images 44, 63, 164): seed 3 0.9725 / 0.9897.
/// Split (seed 3, seed 4 recall / precision, pixel-grid profile): 9 px from below, 9.5, 10 or
/// 12 px from above 0.9797 / 0.9971, 0.9721 / 0.9985 (8.5 px from below the same).
const MAX_B_ABOVE: f64 = 10.0;

/// Whether the pair `upper`, `lower` is thin ([`Model::Thin`]): both rims' `b` under
/// [`MAX_B_ABOVE`] for a wafer seen from above, under [`MAX_B`] from below.
fn is_thin(upper: &Ellipse, lower: &Ellipse) -> bool {
    let limit = if lower.b > upper.b {
        MAX_B_ABOVE
    } else {
        MAX_B
    };
    upper.b.max(lower.b) < limit
}
/// Largest `|sin θ|` of the rims' major axis and `|up_x|` for the column model.
const MAX_TILT: f64 = 0.05;
/// Columns left out at each end of the rims' edge points (the tips, where the column model's
/// premise of a crossing at a small slope fails).
const END_COLUMNS: f64 = 3.0;
/// Rows beyond the outermost edges in each column window.
const WINDOW_MARGIN: f64 = 3.0;
/// Fewest columns for a fit.
const MIN_COLUMNS: usize = 60;
/// A column whose RMS residual exceeds this multiple of the larger of the median column RMS and
/// the image noise is left out in the next round.
const COLUMN_OUTLIER: f64 = 2.0;
/// Rounds of column screening after the first fit.
const ROUNDS: usize = 2;
/// Accepted RMS residual of the kept columns, as a multiple of the image noise.
const MAX_RMS_OVER_NOISE: f64 = 1.5;
/// Smallest fraction of the columns kept.
const MIN_KEPT: f64 = 0.6;
/// Largest move of the centre (pixels) and relative change of `b` from the edge-point fit.
const MAX_CENTRE_MOVE: f64 = 3.0;
const MAX_B_CHANGE: f64 = 0.25;
/// Largest relative change of `a` from the edge-point fit for [`Model::Band`]: the band fit
/// sharpens the band's rows, while `a` of a wider rim is fixed by its edge points to ≈ 0.1 %
/// (benchmark, seeds 3 and 4, 456 accepted band fits: |Δa| median 0.04 %, 99th percentile
/// 0.6 %). The two accepted fits beyond 1 % (seed 3 images 80 and 143, Δa 1.5 % and 1.4 %)
/// had moved to a different ellipse: a second pairing of a target's rims 1 px off, and a thin
/// disturbance wafer's rims with `b` 7 % off, both at a residual 1.4–1.5× the noise.
const MAX_A_CHANGE_BAND: f64 = 0.01;
/// Levenberg–Marquardt iterations per round.
const MAX_ITER: usize = 40;
/// Convergence of Levenberg–Marquardt, in units of the residual variance `σ̂² = RSS/n`: a solve
/// stops when the decrease that the linearised model predicts for the next step (or the decrease
/// a step achieved) is below `TOL·σ̂²`. The predicted decrease of a Gauss–Newton step is
/// `δᵀJᵀJδ`, i.e. `σ̂²` times the squared distance to the optimum in standard deviations, so
/// the last solve ends within `√FINAL_TOL` ≈ 0.3 standard deviations of its optimum, and the
/// solves on the column subset before it (which only screen the columns and start the next
/// solve) within `√SUBSET_TOL` = 1. A relative threshold of 10⁻⁷ of the RSS (0.01–0.03 standard
/// deviations) gives the same benchmark figures at twice the evaluations.
const FINAL_TOL: f64 = 0.1;
const SUBSET_TOL: f64 = 1.0;
/// Most columns of the first solve of a fit (an even subset; the screening rounds use all).
const MAX_FIT_COLUMNS: usize = 150;
/// Rows of the image summed by [`noise_sigma`]: every this many.
const NOISE_ROW_STRIDE: usize = 16;
/// The parameters held at the seed's values when the fit is told the band's ends
/// ([`refit_pair`]'s `ends`): `cx` and `a`.
const HELD_BY_ENDS: [usize; 2] = [0, 2];
/// Half-width (columns) of the runs of [`quiet_runs`].
const RUN_HALF: usize = 10;
/// Standard errors of a run's mean square residual over the reference in [`quiet_runs`].
const RUN_KAPPA: f64 = 3.0;
/// Floor (grey levels) of the noise estimate used as a scale.
const MIN_NOISE: f64 = 0.5;
/// A sample at or above this grey level counts as clipped (censored), as in `band.rs`.
const CLIP: f64 = 254.5;
/// The clip level that a censored sample's model has to reach.
const CLIP_LEVEL: f64 = 255.0;

/// Noise standard deviation (grey levels) of an image by Immerkær's estimator (1996, "Fast
/// noise variance estimation"): `σ = √(π/2)/(6·N)·Σ|I ∗ N|` over `N` pixels, with the
/// Laplacian difference mask `N = [1 −2 1; −2 4 −2; 1 −2 1]`, which cancels locally linear image
/// content. The sum runs over every [`NOISE_ROW_STRIDE`]-th row (a 1280×720 image still gives
/// 5.7·10⁴ terms: a relative standard error of 0.45 % on pure Gaussian noise, measured; every
/// fourth row gives 0.2 % at 4× the time, ≈ 1 ms of a frame). Edges raise it
/// slightly; the result is used as a scale, not a test statistic.
pub(super) fn noise_sigma<T: Pixel>(image: &GrayView<'_, T>) -> f64 {
    let (w, h) = (image.width(), image.height());
    if w < 3 || h < 3 {
        return 0.0;
    }
    let d = image.data();
    // The mask is separable, `[1 −2 1]ᵀ ⊗ [1 −2 1]`: the row's second differences of the three
    // rows, then their vertical second difference. Four partial sums keep the loop vectorised
    // (the terms are integers for integer pixels, so the order does not change the sum).
    let second = |y: usize, out: &mut Vec<f64>| {
        out.clear();
        out.extend(d[y * w..(y + 1) * w].windows(3).map(|t| {
            f64::from(t[0].grey()) - 2.0 * f64::from(t[1].grey()) + f64::from(t[2].grey())
        }));
    };
    let (mut above, mut row, mut below) = (Vec::new(), Vec::new(), Vec::new());
    let mut sum = 0.0;
    let mut count = 0usize;
    for y in (1..h - 1).step_by(NOISE_ROW_STRIDE) {
        second(y - 1, &mut above);
        second(y, &mut row);
        second(y + 1, &mut below);
        let mut part = [0.0f64; 4];
        let chunks = above
            .chunks_exact(4)
            .zip(row.chunks_exact(4))
            .zip(below.chunks_exact(4));
        for ((a, r), b) in chunks {
            for k in 0..4 {
                part[k] += (a[k] - 2.0 * r[k] + b[k]).abs();
            }
        }
        let tail = (w - 2) / 4 * 4;
        for k in tail..w - 2 {
            part[0] += (above[k] - 2.0 * row[k] + below[k]).abs();
        }
        sum += (part[0] + part[1]) + (part[2] + part[3]);
        count += w - 2;
    }
    (std::f64::consts::FRAC_PI_2).sqrt() * sum / (6.0 * count as f64)
}

/// The row where column `x` meets the arc of `e` on the side `side` (+1: larger `y`) of its
/// major axis ([`ray_hit`] of the vertical line, the root nearest to a point beyond the
/// ellipse on that side), and its derivatives with respect to `e`'s `(cx, cy, a, b, θ)`;
/// `None` beyond the ellipse's extent. [`ray_hit`] gives those of `(cx, cy, b, a)`; the one of
/// `θ` follows the same way: in the ellipse frame the row's point `(x', y')` turns with `θ` as
/// `∂x'/∂θ = y'`, `∂y'/∂θ = −x'`, so `∂F/∂θ = 2x'y'(1/a² − 1/b²)`. The slope of the arc in
/// the column direction is `−∂y/∂cx`.
pub(super) fn arc_row(e: &[f64; 5], x: f64, side: f64) -> Option<(f64, [f64; 5])> {
    let [cx, cy, a, b, theta] = *e;
    let ellipse = Ellipse {
        cx,
        cy,
        a,
        b,
        theta,
    };
    let beyond = cy + side * 2.0 * (a.abs() + b.abs());
    let (y, d) = ray_hit(
        &ellipse,
        Vector2::new(x, 0.0),
        Vector2::new(0.0, 1.0),
        beyond,
    )?;
    let (s, c) = theta.sin_cos();
    let (dx, dy) = (x - cx, y - cy);
    let (xl, yl) = (c * dx + s * dy, -s * dx + c * dy);
    let (a2, b2) = (a * a, b * b);
    let f_t = 2.0 * (xl * s / a2 + yl * c / b2);
    let f_theta = 2.0 * xl * yl * (1.0 / a2 - 1.0 / b2);
    Some((y, [d[0], d[1], d[3], d[2], -f_theta / f_t]))
}

/// The geometry of the pair: the map from the upper rim `(cx, cy, a, b, θ)` to the lower one
/// and the side of the front arcs.
struct Pair {
    /// The map; its side ([`RimMap::front`]) is +1 when the band lies below the centre in the
    /// image (the wafer seen from above, `up` pointing to −y), −1 when above (seen from below).
    map: RimMap,
    /// The edges' profile along a column.
    profile: EdgeProfile,
}

/// How the image forms an edge's profile across it: what the column fits model. See
/// [`DetectParams::edge_profile`](super::DetectParams::edge_profile).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EdgeProfile {
    /// The optics blur the scene before the pixels integrate it (a camera): a Gaussian PSF of
    /// σ, the pixel's box folded into σ (its 1/12 px² variance), so a straight edge at `E`
    /// gives `Φ((y − E)/σ)` across it, the same at every sub-pixel position of the edge.
    #[default]
    Optical,
    /// The pixels integrate the scene first and a Gaussian of σ sampled on the pixel grid
    /// blurs the image after (a digital blur; the renderer of `autoteach_geometry::render`,
    /// whose images the simulator and the benchmarks use). The PSF is then a staircase
    /// `Σₖ wₖ·box(t − k)`, `wₖ ∝ exp(−k²/2σ²)`, and the profile
    /// `Σₖ wₖ·clamp(y − E − k + ½, 0, 1)` is piecewise linear in the edge's position: a
    /// Gaussian profile fitted to it is off by up to ≈ 0.05 px, by the edge's sub-pixel phase.
    PixelGrid,
}

/// Taps each side of the sampled kernel of [`EdgeProfile::PixelGrid`] (`wₖ` is under 10⁻⁵
/// of `w₀` beyond for σ up to 0.85 px; the renderer's kernel has `⌈3σ⌉` taps each side).
const PIXEL_TAPS: usize = 4;

/// One edge's profile across a column at one parameter set: `Φ(t)`, `dΦ/dt` and `dΦ/dσ`
/// (`t = y − E`, σ the edge's blur along the column). Built on the stack per column and edge
/// (no allocation), hence the variants' different sizes.
#[allow(clippy::large_enum_variant)]
enum Profile {
    /// `1/σ` of the Gaussian profile.
    Optical(f64),
    /// The cumulative weights `Σ_{j<k} wⱼ`, the weights and their derivatives by σ, for
    /// `k = −PIXEL_TAPS..=PIXEL_TAPS` (index `k + PIXEL_TAPS`).
    PixelGrid {
        cum: [f64; 2 * PIXEL_TAPS + 1],
        w: [f64; 2 * PIXEL_TAPS + 1],
        cum_ds: [f64; 2 * PIXEL_TAPS + 1],
        w_ds: [f64; 2 * PIXEL_TAPS + 1],
    },
}

impl Profile {
    fn new(kind: EdgeProfile, sigma: f64) -> Self {
        match kind {
            EdgeProfile::Optical => Self::Optical(1.0 / sigma),
            EdgeProfile::PixelGrid => {
                const N: usize = 2 * PIXEL_TAPS + 1;
                // gₖ = q^(k²), q = exp(−1/2σ²); ∂gₖ/∂σ = gₖ·k²/σ³.
                let q = (-0.5 / (sigma * sigma)).exp();
                let g: [f64; N] = std::array::from_fn(|i| {
                    let k = i as i32 - PIXEL_TAPS as i32;
                    q.powi(k * k)
                });
                let g_ds: [f64; N] = std::array::from_fn(|i| {
                    let k = (i as f64 - PIXEL_TAPS as f64).powi(2);
                    g[i] * k / (sigma * sigma * sigma)
                });
                let (sum, sum_ds): (f64, f64) = (g.iter().sum(), g_ds.iter().sum());
                let w: [f64; N] = std::array::from_fn(|i| g[i] / sum);
                let w_ds: [f64; N] = std::array::from_fn(|i| (g_ds[i] - w[i] * sum_ds) / sum);
                let (mut cum, mut cum_ds) = ([0.0; N], [0.0; N]);
                for i in 1..N {
                    cum[i] = cum[i - 1] + w[i - 1];
                    cum_ds[i] = cum_ds[i - 1] + w_ds[i - 1];
                }
                Self::PixelGrid {
                    cum,
                    w,
                    cum_ds,
                    w_ds,
                }
            }
        }
    }

    /// `(Φ(t), dΦ/dt, dΦ/dσ)` of the profile of blur `σ·widen` (an edge crossing the column at
    /// a slope: `widen = √(1 + s²)`), for this profile of blur `sigma`: exact for the Gaussian;
    /// for the staircase the weights to first order in `δ = σ·(widen − 1)` (the slopes of the
    /// column fits' edges are under 0.1, so `δ` < 0.004 px and the error under 10⁻⁵ of an
    /// edge's step), which spares a table per edge and column.
    #[inline]
    fn widened(&self, t: f64, sigma: f64, widen: f64) -> (f64, f64, f64) {
        match self {
            Self::Optical(inv) => {
                let inv = inv / widen;
                let (cdf, d) = cdf_and_density(t * inv);
                (cdf, d * inv, -d * t * inv * inv)
            }
            Self::PixelGrid {
                cum,
                w,
                cum_ds,
                w_ds,
            } => {
                // Only the tap k whose box holds t (|t − k| < ½) is partly covered.
                let k = (t + 0.5).floor();
                let r = PIXEL_TAPS as f64;
                if k < -r {
                    (0.0, 0.0, 0.0)
                } else if k > r {
                    (1.0, 0.0, 0.0)
                } else {
                    let i = (k + r) as usize;
                    let frac = t - k + 0.5;
                    let delta = sigma * (widen - 1.0);
                    let wi = w[i] + w_ds[i] * delta;
                    (
                        cum[i] + cum_ds[i] * delta + wi * frac,
                        wi,
                        cum_ds[i] + w_ds[i] * frac,
                    )
                }
            }
        }
    }

    /// `(Φ(t), dΦ/dt, dΦ/dσ)` of this profile.
    #[cfg(test)]
    fn at(&self, t: f64) -> (f64, f64, f64) {
        self.widened(t, 0.0, 1.0)
    }
}

/// The edges a column crosses: [`Model::Thin`] the face's silhouette and both front arcs
/// (three edges, four levels), [`Model::Band`] the two front arcs only (two edges, three
/// levels).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Model {
    /// A thin wafer (`b` < [`MAX_B`]): the face's silhouette lies within a few pixels of the
    /// band and is one more edge of the column.
    Thin,
    /// A wider level wafer: the column crosses the side band alone.
    Band,
}

impl Pair {
    /// The upper rim `u`, its lower rim and `∂(lower)/∂(upper)` ([`RimMap::lower_rim`]): what
    /// [`Pair::edges`] needs in every column, computed once per parameter set; `None` where
    /// the map does not recover the wafer's pose.
    fn rims(&self, u: &[f64; 5]) -> Option<Rims> {
        let (lower, chain) = self.map.lower_rim(u)?;
        Some(Rims {
            upper: *u,
            lower,
            chain,
        })
    }

    /// The `E` edges of column `x` in image order and their derivatives with respect to the
    /// upper rim's `(cx, cy, a, b, θ)`: with `E = 3` the face's silhouette (the back arc of
    /// the upper rim seen from above, of the lower rim from below) and the two front arcs,
    /// with `E = 2` the two front arcs.
    fn edges<const E: usize>(&self, r: &Rims, x: f64) -> Option<[(f64, [f64; 5]); E]> {
        let (u, l) = (&r.upper, &r.lower);
        // Derivatives of a lower-rim row chained through the prior.
        let chain = |(y, d): (f64, [f64; 5])| {
            let row = nalgebra::RowVector5::from_row_slice(&d) * r.chain;
            (y, [row[0], row[1], row[2], row[3], row[4]])
        };
        let mut e = [(0.0, [0.0; 5]); E];
        let fronts = [
            arc_row(u, x, self.map.front())?,
            chain(arc_row(l, x, self.map.front())?),
        ];
        match E {
            2 => e.copy_from_slice(&fronts),
            3 => {
                e[0] = if self.map.front() > 0.0 {
                    arc_row(u, x, -self.map.front())?
                } else {
                    chain(arc_row(l, x, -self.map.front())?)
                };
                e[1..].copy_from_slice(&fronts);
            }
            _ => return None,
        }
        e.sort_by(|p, q| p.0.total_cmp(&q.0));
        Some(e)
    }
}

/// Both rims of a parameter set (see [`Pair::rims`]).
struct Rims {
    upper: [f64; 5],
    lower: [f64; 5],
    chain: Matrix5<f64>,
}

/// One column: its `x` and the grey levels of its window rows `y0, y0 + 1, …`.
struct Column {
    x: f64,
    y0: f64,
    grey: Vec<f64>,
}

/// The basis of the `L = E + 1` levels of a sample whose profiles across the `E` edges (in
/// image order) are `phi`: level `j` weighs `Φⱼ₋₁ − Φⱼ` (`Φ₋₁ = 1`, `Φ_E = 0`).
fn level_basis<const E: usize, const L: usize>(phi: &[f64; E]) -> SVector<f64, L> {
    let mut b = SVector::<f64, L>::zeros();
    b[0] = 1.0 - phi[0];
    for j in 1..E {
        b[j] = phi[j - 1] - phi[j];
    }
    b[E] = phi[E - 1];
    b
}

/// The sums of one column at a parameter set: `JᵀJ` and `Jᵀr` of its samples (zero when the
/// Jacobian was not asked for), the residual sum of squares and the sample count.
#[derive(Clone, Copy)]
struct ColumnSums {
    jtj: Matrix6<f64>,
    jtr: Vector6<f64>,
    ss: f64,
    n: usize,
}

impl ColumnSums {
    fn rms(&self) -> f64 {
        (self.ss / self.n.max(1) as f64).sqrt()
    }
}

/// An [`evaluate`]: the sums of every column (`None` where left out).
type Evaluation = Vec<Option<ColumnSums>>;

/// `JᵀJ`, `Jᵀr`, the residual sum of squares and the residual count over the columns of `e`.
fn totals(e: &Evaluation) -> (Matrix6<f64>, Vector6<f64>, f64, usize) {
    let mut jtj = Matrix6::zeros();
    let mut jtr = Vector6::zeros();
    let (mut ss, mut n) = (0.0, 0);
    for c in e.iter().flatten() {
        jtj += c.jtj;
        jtr += c.jtr;
        ss += c.ss;
        n += c.n;
    }
    (jtj, jtr, ss, n)
}

/// The residuals of every kept column, and with `jac` their Jacobian with respect to
/// `(cx, cy, a, b, θ, σ)` with the levels projected out (Kaufman's variable projection), as
/// per-column sums ([`ColumnSums`]), for the model of `E` edges and `L = E + 1` levels; `None`
/// where a column's edges do not exist (a parameter set beyond the rims' extent) or its levels
/// are singular.
///
/// An edge crossing the column at slope `s` (`dEⱼ/dx`) is a straight edge blurred by σ along
/// its normal, i.e. by `σ·√(1 + s²)` along the column. A clipped sample (at or above
/// [`CLIP`]) is censored: it does not enter the levels' solve, and its residual is
/// `min(model − 255, 0)` (the model has to reach the clip level there, nothing more).
///
/// Kaufman's Jacobian row of an unclipped sample is the model's derivative `g` at fixed levels
/// minus its least-squares fit by the levels' basis `b` (what the levels cannot absorb):
/// `ĝ = g − Wᵀb` with `W = M⁻¹C`ᵀ, `C = Σ g bᵀ` and `M = Σ b bᵀ` over the unclipped samples.
/// Its sums follow from per-column sums without storing the rows: `Σ ĝĝᵀ = Σ ggᵀ − CW − WᵀCᵀ +
/// WᵀMW` and `Σ ĝr = Σ gr − WᵀΣ br` (a censored sample's row is `g`, unprojected).
fn evaluate<const E: usize, const L: usize>(
    pair: &Pair,
    p: &Vector6<f64>,
    columns: &[Column],
    kept: &[bool],
    jac: bool,
) -> Option<Evaluation> {
    debug_assert_eq!(L, E + 1);
    let u = [p[0], p[1], p[2], p[3], p[4]];
    let sigma = p[5];
    if !(sigma > 0.05 && u[2] > 0.0 && u[3] > 0.0) {
        return None;
    }
    let mut out = Vec::with_capacity(columns.len());
    let mut basis = Vec::new();
    let rims = pair.rims(&u)?;
    let profile = Profile::new(pair.profile, sigma);
    for (c, &keep) in columns.iter().zip(kept) {
        if !keep {
            out.push(None);
            continue;
        }
        let rows = pair.edges::<E>(&rims, c.x)?;
        let e: [f64; E] = std::array::from_fn(|j| rows[j].0);
        let de: [[f64; 5]; E] = std::array::from_fn(|j| rows[j].1);
        // Blur along the column of each edge, from its slope `dEⱼ/dx = −∂Eⱼ/∂cx`: σ·widen[j].
        let widen: [f64; E] = std::array::from_fn(|j| (1.0 + de[j][0] * de[j][0]).sqrt());
        // Basis of the levels and the normal equations of the unclipped samples.
        basis.clear();
        let mut btb = SMatrix::<f64, L, L>::zeros();
        let mut rhs = SVector::<f64, L>::zeros();
        for (i, &g) in c.grey.iter().enumerate() {
            let y = c.y0 + i as f64;
            let mut phi = [0.0; E];
            let mut dens = [0.0; E];
            let mut dsig = [0.0; E];
            for j in 0..E {
                let (cdf, d, ds) = profile.widened(y - e[j], sigma, widen[j]);
                phi[j] = cdf;
                dens[j] = d;
                dsig[j] = ds * widen[j];
            }
            let b = level_basis::<E, L>(&phi);
            if g < CLIP {
                btb.ger(1.0, &b, &b, 1.0);
                rhs += b * g;
            }
            basis.push((b, dens, dsig));
        }
        // The closed-form inverse of the small matrix (L ≤ 4): one per column serves the
        // levels and the projection.
        let inv_m = (btb + SMatrix::<f64, L, L>::identity() * 1e-6).try_inverse()?;
        let levels = inv_m * rhs;
        let mut sums = ColumnSums {
            jtj: Matrix6::zeros(),
            jtr: Vector6::zeros(),
            ss: 0.0,
            n: c.grey.len(),
        };
        let mut gtb = SMatrix::<f64, 6, L>::zeros();
        let mut btr = SVector::<f64, L>::zeros();
        for ((b, dens, dsig), &g) in basis.iter().zip(&c.grey) {
            let model = levels.dot(b);
            let unclipped = g < CLIP;
            let r = if unclipped {
                model - g
            } else {
                (model - CLIP_LEVEL).min(0.0)
            };
            sums.ss += r * r;
            if jac && (unclipped || r < 0.0) {
                let mut grad = Vector6::zeros();
                for j in 0..E {
                    let step = levels[j + 1] - levels[j];
                    // ∂/∂Eⱼ of step·Φ(y − Eⱼ; σⱼ), and ∂/∂σ (σⱼ = σ·widenⱼ).
                    let d_edge = -step * dens[j];
                    for k in 0..5 {
                        grad[k] += d_edge * de[j][k];
                    }
                    grad[5] += step * dsig[j];
                }
                sums.jtj.ger(1.0, &grad, &grad, 1.0);
                sums.jtr += grad * r;
                if unclipped {
                    gtb.ger(1.0, &grad, b, 1.0);
                    btr += b * r;
                }
            }
        }
        if jac {
            let w = inv_m * gtb.transpose();
            let cw = gtb * w;
            sums.jtj += w.transpose() * btb * w - cw - cw.transpose();
            sums.jtr -= w.transpose() * btr;
        }
        out.push(Some(sums));
    }
    Some(out)
}

/// Levenberg–Marquardt on the six parameters from `p` (whose evaluation on the kept columns is
/// `start`, when known) until the decrease is below `tol` residual variances (see
/// [`FINAL_TOL`]); the parameters, the residual sum of squares, the residual count and `JᵀJ` at
/// the optimum.
fn solve<const E: usize, const L: usize>(
    pair: &Pair,
    mut p: Vector6<f64>,
    columns: &[Column],
    kept: &[bool],
    start: Option<Evaluation>,
    tol: f64,
    held: &[usize],
) -> Option<(Vector6<f64>, f64, usize, Matrix6<f64>)> {
    let mut lambda = 1e-3;
    let first = match start {
        Some(e) => e,
        None => evaluate::<E, L>(pair, &p, columns, kept, true)?,
    };
    let (mut jtj, mut jtr, mut c0, n) = totals(&first);
    let n_f = n.max(1) as f64;
    for _ in 0..MAX_ITER {
        let threshold = tol * c0 / n_f;
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj;
            for k in 0..6 {
                a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let mut g = jtr;
            for &k in held {
                a.row_mut(k).fill(0.0);
                a.column_mut(k).fill(0.0);
                a[(k, k)] = 1.0;
                g[k] = 0.0;
            }
            let step = cholesky_solve::<6>(&a, &(-g))?;
            // The decrease the linearised model predicts for the step: when it is below the
            // convergence threshold, no trial is worth its evaluation (at the optimum every
            // trial fails, and ten of them would only raise λ).
            let predicted = -(step.dot(&g) * 2.0 + step.dot(&(jtj * step)));
            if predicted <= threshold {
                break;
            }
            let trial = p + step;
            if let Some(t) = evaluate::<E, L>(pair, &trial, columns, kept, true) {
                let (jtj1, jtr1, c1, _) = totals(&t);
                if c1 < c0 {
                    let small = c0 - c1 <= threshold;
                    p = trial;
                    (jtj, jtr, c0) = (jtj1, jtr1, c1);
                    lambda = (lambda * 0.3).max(1e-9);
                    improved = !small;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Some((p, c0, n, jtj))
}

/// The parameters, the residual sum of squares, the residual count, `JᵀJ` and the number of
/// columns kept of a column fit.
type ColumnFit = (Vector6<f64>, f64, usize, Matrix6<f64>, usize);

/// The fit of [`refit_pair`] with `E` edges per column: Levenberg–Marquardt from the rims'
/// edge-point fit `u0`, then [`ROUNDS`] rounds of column screening; the parameters, the
/// residual sum of squares, the residual count, `JᵀJ` and the number of columns kept.
fn fit_columns<const E: usize, const L: usize>(
    pair: &Pair,
    u0: [f64; 5],
    columns: &[Column],
    noise: f64,
    ends: bool,
) -> Option<ColumnFit> {
    let held: &[usize] = if ends { &HELD_BY_ENDS } else { &[] };
    let noise = noise.max(MIN_NOISE);
    // The solves before the last (from the edge-point fit, then after the first screening)
    // run on an even subset of at most MAX_FIT_COLUMNS columns; the screening and the last
    // solve use all columns.
    let stride = columns.len().div_ceil(MAX_FIT_COLUMNS).max(1);
    let subset = |i: usize| i.is_multiple_of(stride);
    let mut kept: Vec<bool> = (0..columns.len()).map(subset).collect();
    let mut p = Vector6::new(u0[0], u0[1], u0[2], u0[3], u0[4], 0.85);
    let all = vec![true; columns.len()];
    let mut start = None;
    for round in 0..=ROUNDS {
        let tol = if round == ROUNDS {
            FINAL_TOL
        } else {
            SUBSET_TOL
        };
        let (q, ss, n, jtj) = solve::<E, L>(pair, p, columns, &kept, start.take(), tol, held)?;
        p = q;
        if round == ROUNDS {
            let count = kept.iter().filter(|&&k| k).count();
            return Some((p, ss, n, jtj, count));
        }
        // The screening before the last solve evaluates the Jacobian too: the last solve
        // starts from its kept columns' part.
        let last = round + 1 == ROUNDS;
        let evaluation = evaluate::<E, L>(pair, &p, columns, &all, last)?;
        let column_rms: Vec<f64> = evaluation
            .iter()
            .map(|c| c.map_or(f64::NAN, |c| c.rms()))
            .collect();
        let mut finite: Vec<f64> = column_rms
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        finite.sort_by(f64::total_cmp);
        let median = *finite.get(finite.len() / 2)?;
        let limit = COLUMN_OUTLIER * median.max(noise);
        let runs = if ends {
            quiet_runs(&evaluation, noise)
        } else {
            vec![true; evaluation.len()]
        };
        kept = column_rms
            .iter()
            .enumerate()
            .map(|(i, &v)| v <= limit && runs[i] && (last || subset(i)))
            .collect();
        if last {
            // The kept columns' part.
            let part = evaluation
                .into_iter()
                .zip(&kept)
                .map(|(c, &k)| c.filter(|_| k))
                .collect();
            start = Some(part);
        }
    }
    None
}

/// The covariance of a fit whose `cx` and `a` ([`HELD_BY_ENDS`]) were held at values measured
/// elsewhere — the band's two ends, each to a standard deviation `end_sd` (so `cx` and `a`, their
/// mean and half difference, to `end_sd/√2` each, uncorrelated): the free parameters' conditional
/// covariance `H_ff⁻¹·s²` plus the held ones' propagated through the optimum's shift
/// `G = −H_ff⁻¹·H_fh` (`H` = `JᵀJ`, `s²` the residual variance); `None` when `H_ff` is
/// singular.
pub(super) fn held_covariance(jtj: &Matrix6<f64>, s2: f64, end_sd: f64) -> Option<Matrix6<f64>> {
    const FREE: [usize; 4] = [1, 3, 4, 5];
    let hff = SMatrix::<f64, 4, 4>::from_fn(|i, j| jtj[(FREE[i], FREE[j])]);
    let hfh = SMatrix::<f64, 4, 2>::from_fn(|i, j| jtj[(FREE[i], HELD_BY_ENDS[j])]);
    let inv = hff.try_inverse()?;
    let g = -inv * hfh;
    let var_held = 0.5 * end_sd * end_sd;
    let cff = inv * s2 + g * g.transpose() * var_held;
    let cfh = g * var_held;
    let mut cov = Matrix6::zeros();
    for i in 0..4 {
        for j in 0..4 {
            cov[(FREE[i], FREE[j])] = cff[(i, j)];
        }
        for j in 0..2 {
            cov[(FREE[i], HELD_BY_ENDS[j])] = cfh[(i, j)];
            cov[(HELD_BY_ENDS[j], FREE[i])] = cfh[(i, j)];
        }
    }
    for j in 0..2 {
        cov[(HELD_BY_ENDS[j], HELD_BY_ENDS[j])] = var_held;
    }
    Some(cov)
}

/// Whether the columns around each column of `e` are at the noise level: the pooled mean
/// square residual of the columns within [`RUN_HALF`] of it, against the median column's
/// (floored at `noise²`), within [`RUN_KAPPA`] standard errors of a mean of that many squared
/// Gaussian residuals (`√(2/n)`). Clutter behind a wafer seen edge-on (the carrier's slot
/// ridges and their mirror images in the faces, near the band's ends) moves the band's edges by
/// 0.05–0.15 px in columns whose residual is only 1–2 grey levels RMS, under the noise of one
/// column but coherent over tens of columns; the tips' columns are the ones that fix `b` there.
fn quiet_runs(e: &Evaluation, noise: f64) -> Vec<bool> {
    let mut ms: Vec<f64> = e
        .iter()
        .flatten()
        .map(|c| c.ss / c.n.max(1) as f64)
        .collect();
    ms.sort_by(f64::total_cmp);
    let Some(&median) = ms.get(ms.len() / 2) else {
        return vec![true; e.len()];
    };
    let reference = median.max(noise * noise);
    (0..e.len())
        .map(|i| {
            let run = &e[i.saturating_sub(RUN_HALF)..(i + RUN_HALF + 1).min(e.len())];
            let (ss, n) = run
                .iter()
                .flatten()
                .fold((0.0, 0usize), |(s, n), c| (s + c.ss, n + c.n));
            n == 0 || ss / n as f64 <= reference * (1.0 + RUN_KAPPA * (2.0 / n as f64).sqrt())
        })
        .collect()
}

/// Refits the two rims `upper` and `lower` of one level wafer with `model` (module doc) on
/// `image`, whose noise is `noise` grey levels; `None` when the pair does not suit the model
/// (`Thin`: both rims' `b` under [`MAX_B`]; `Band`: wider), is not level enough for
/// the column model, or the fit is not accepted. The rims keep their edge points; their
/// residuals are recomputed against the new ellipses and their covariances are the fit's
/// (scaled by its residual variance), propagated to the lower rim through the prior. The side
/// of the front arcs (+1: the band below the centre, the wafer seen from above) is `front`
/// when given, else the side of the rims' points' median row. With `ends` (the standard
/// deviation, pixels, of the band's two ends measured in the image: a wafer seen edge-on,
/// `sliver.rs`) `cx` and `a` are held at the seed's values ([`HELD_BY_ENDS`]), the columns are
/// also screened in runs ([`quiet_runs`]), and the covariance carries the ends' uncertainty
/// ([`held_covariance`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn refit_pair<T: Pixel>(
    image: &GrayView<'_, T>,
    upper: &WaferEdge,
    lower: &WaferEdge,
    up: Vector2<f64>,
    prior: &RimOffsetPrior,
    noise: f64,
    model: Model,
    profile: EdgeProfile,
    front: Option<f64>,
    ends: Option<f64>,
) -> Option<(WaferEdge, WaferEdge)> {
    let eu = &upper.ellipse;
    // An upright camera and level rims: the column model's premises (NaN fails).
    let level = up.x.abs() < MAX_TILT
        && up.y < 0.0
        && eu.theta.sin().abs() < MAX_TILT
        && lower.ellipse.theta.sin().abs() < MAX_TILT;
    let thin = is_thin(eu, &lower.ellipse);
    if !(level && thin == (model == Model::Thin)) {
        return None;
    }
    let points: Vec<_> = upper.points.iter().chain(&lower.points).collect();
    if points.len() < MIN_COLUMNS {
        return None;
    }
    let mut ys: Vec<f64> = points.iter().map(|p| p.y).collect();
    ys.sort_by(f64::total_cmp);
    let front = front.unwrap_or(if ys[ys.len() / 2] > eu.cy { 1.0 } else { -1.0 });
    let pair = Pair {
        map: RimMap::new(prior, image.width(), image.height(), front, up),
        profile,
    };
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in &points {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
    }
    let u0 = [eu.cx, eu.cy, eu.a, eu.b, eu.theta];
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let mut columns = Vec::new();
    let rims0 = pair.rims(&u0)?;
    let mut x = (x0 + END_COLUMNS).ceil();
    while x <= x1 - END_COLUMNS {
        let rows = match model {
            Model::Thin => pair.edges::<3>(&rims0, x).map(|e| (e[0].0, e[2].0)),
            Model::Band => pair.edges::<2>(&rims0, x).map(|e| (e[0].0, e[1].0)),
        };
        if x >= 0.0
            && x < w as f64
            && let Some((first, last)) = rows
        {
            let top = (first - WINDOW_MARGIN).floor();
            let bottom = (last + WINDOW_MARGIN).ceil();
            if top >= 0.0 && bottom < h as f64 {
                let xi = x as usize;
                let grey = (top as usize..=bottom as usize)
                    .map(|y| f64::from(data[y * w + xi].grey()))
                    .collect();
                columns.push(Column { x, y0: top, grey });
            }
        }
        x += 1.0;
    }
    if columns.len() < MIN_COLUMNS {
        return None;
    }
    let (p, ss, n, jtj, kept_count) = match model {
        Model::Thin => fit_columns::<3, 4>(&pair, u0, &columns, noise, ends.is_some())?,
        Model::Band => fit_columns::<2, 3>(&pair, u0, &columns, noise, ends.is_some())?,
    };
    let rms = (ss / n.max(1) as f64).sqrt();
    let u = [p[0], p[1], p[2], p[3], p[4]];
    if !(rms <= MAX_RMS_OVER_NOISE * noise.max(MIN_NOISE))
        || (kept_count as f64) < MIN_KEPT * columns.len() as f64
        || !((u[0] - u0[0]).hypot(u[1] - u0[1]) <= MAX_CENTRE_MOVE)
        || !((u[3] - u0[3]).abs() <= MAX_B_CHANGE * u0[3])
        || (model == Model::Band && !((u[2] - u0[2]).abs() <= MAX_A_CHANGE_BAND * u0[2]))
        || !p.iter().all(|v| v.is_finite())
    {
        return None;
    }
    let levels = match model {
        Model::Thin => 4,
        Model::Band => 3,
    };
    let held = if ends.is_some() {
        HELD_BY_ENDS.len()
    } else {
        0
    };
    let s2 = ss / (n.saturating_sub(6 - held + levels * kept_count)).max(1) as f64;
    let cov6 = match ends {
        None => jtj.try_inverse().map(|c| c * s2),
        Some(sd) => held_covariance(&jtj, s2, sd),
    }?;
    let cov_u: Matrix5<f64> = cov6.fixed_view::<5, 5>(0, 0).into_owned();
    let rims = pair.rims(&u)?;
    let cov_l = rims.chain * cov_u * rims.chain.transpose();
    let l = rims.lower;
    let make = |e: [f64; 5], cov: Matrix5<f64>, old: &WaferEdge, kind: RimKind| {
        let ellipse = Ellipse::new(e[0], e[1], e[2], e[3], e[4]).ok()?;
        let pts: Vec<Vector2<f64>> = old.points.iter().map(|p| p.coords).collect();
        let d = ellipse.orthogonal_distances(&pts);
        let residual = d.iter().map(|v| v.abs()).sum::<f64>() / d.len().max(1) as f64;
        Some(WaferEdge {
            ellipse,
            points: old.points.clone(),
            residual,
            covariance: Some(cov),
            kind,
            wafer_id: old.wafer_id,
        })
    };
    Some((
        make(u, cov_u, upper, RimKind::Upper)?,
        make(l, cov_l, lower, RimKind::Lower)?,
    ))
}

/// [`refit_pair`] with `model` for every wafer of `edges` with both rims that suits it (thin
/// pairs for [`Model::Thin`], wider ones for [`Model::Band`]); the image's noise is estimated
/// once into `noise`, when there is a pair to refit. The rims of an accepted fit replace the
/// pair's.
pub(super) fn refit_level_wafers<T: Pixel>(
    image: &GrayView<'_, T>,
    mut edges: Vec<WaferEdge>,
    up: Vector2<f64>,
    prior: &RimOffsetPrior,
    model: Model,
    profile: EdgeProfile,
    noise: &mut Option<f64>,
) -> Vec<WaferEdge> {
    for i in 0..edges.len() {
        if edges[i].kind != RimKind::Upper {
            continue;
        }
        let Some(j) = (0..edges.len())
            .find(|&j| edges[j].kind == RimKind::Lower && edges[j].wafer_id == edges[i].wafer_id)
        else {
            continue;
        };
        let thin = is_thin(&edges[i].ellipse, &edges[j].ellipse);
        if thin != (model == Model::Thin) {
            continue;
        }
        let sigma = *noise.get_or_insert_with(|| noise_sigma(image));
        if let Some((u, l)) = refit_pair(
            image, &edges[i], &edges[j], up, prior, sigma, model, profile, None, None,
        ) {
            edges[i] = u;
            edges[j] = l;
        }
    }
    edges
}

#[cfg(test)]
pub(super) mod tests;
