//! General elliptic-arc detection with an a-contrario acceptance test
//! (000_3b1454b2b2194811.txt ch. 3.2: the arc-based framework of Fig. 3.1/3.3, the two-arc
//! combination rule, Algorithms 1 and 2), with no knowledge of wafers: for anyone who
//! detects ellipses (rims, pipes, coins, markers, cells).
//!
//! Stages, each a function of this crate:
//! 1. Gradient noise `σ_g` estimated from the image ([`noise::gradient_noise`]); the Canny
//!    hysteresis thresholds are the gradient magnitudes that noise exceeds with probabilities
//!    [`P_HIGH`] and [`P_LOW`] per pixel (Rayleigh tail), not grey levels tuned to one camera.
//! 2. Sub-pixel edges, chains and convex single-quadrant arcs ([`crate::edges::detect_arcs`]).
//!    The chains follow both contrast signs: each arc carries its polarity (brighter outside
//!    or inside), so a dark ellipse on a bright ground is found like a bright one on dark.
//! 3. Algorithms 1 and 2 ([`crate::assembly::assemble`]): two arcs combine when they are of
//!    different quadrants, have one polarity, do not overlap on the fitted ellipse and that
//!    fit's mean orthogonal residual is under the threshold; Hungarian matching per connected
//!    component, then iterated segment merging. The residual threshold is 3 times the median
//!    edge noise of the arcs (each arc's points measured against their neighbours' chord),
//!    floored at [`MIN_RESIDUAL`].
//! 4. Validation ([`a_contrario`]): every segment's ellipse is accepted only if its number of
//!    false alarms (aligned gradient orientations along the arc it covers against a binomial
//!    tail, as in LSD/ELSD) is at most `max_nfa` (default 1: under 1 false detection per image
//!    of noise on average).
//! 5. Optionally ([`EllipseDetectParams::max_line_width`]), thin lines are found on their
//!    centre lines by the Hessian of the image ([`ridges`], Steger's detector feeding stages 2–4
//!    with an a-contrario test on the Hessian's orientation), and two opposite-polarity edges of
//!    a line that was not found so become one detection on the line's centre ([`lines`]).
//!
//! ```
//! use autoteach_detect::edges::GrayView;
//! use autoteach_detect::ellipse_detection::{detect_ellipses, EllipseDetectParams};
//!
//! // A dark ellipse (a = 60, b = 35) on a bright ground, antialiased.
//! let (w, h) = (200usize, 160usize);
//! let mut img = vec![0u8; w * h];
//! for y in 0..h {
//!     for x in 0..w {
//!         let mut inside = 0.0;
//!         for j in 0..4 {
//!             for i in 0..4 {
//!                 let u = x as f64 - 0.375 + 0.25 * i as f64 - 100.0;
//!                 let v = y as f64 - 0.375 + 0.25 * j as f64 - 80.0;
//!                 if (u / 60.0).powi(2) + (v / 35.0).powi(2) <= 1.0 {
//!                     inside += 1.0 / 16.0;
//!                 }
//!             }
//!         }
//!         img[y * w + x] = (200.0 - 150.0 * inside) as u8;
//!     }
//! }
//! let found = detect_ellipses(&GrayView::new(&img, w, h)?, &EllipseDetectParams::default())?;
//! assert_eq!(found.len(), 1);
//! let e = &found[0].ellipse;
//! assert!((e.cx - 100.0).abs() < 0.2 && (e.a - 60.0).abs() < 0.3 && (e.b - 35.0).abs() < 0.3);
//! assert!(found[0].score > 10.0); // NFA < 1e-10
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Known limitations: an arc within one quadrant of its ellipse (under about 90°) makes no
//! segment on its own (Algorithm 1 pairs arcs), so it is not reported; two ellipses whose
//! edges are under about 2 px apart interfere in the Sobel/Canny stage.

// `!(x > y)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod a_contrario;
pub mod lines;
pub mod noise;
pub mod refine;
pub mod ridges;
#[cfg(test)]
mod tests;

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Vector2};
use rayon::prelude::*;

use crate::assembly::{AssemblyParams, Segment, assemble};
use crate::edges::{ArcParams, CannyParams, GrayView, LinkParams, Pixel, chain_noise, detect_arcs};
use crate::{DetectError, Result};

/// Per-pixel probability that noise alone exceeds the high Canny threshold (Rayleigh tail of
/// the gradient magnitude): `σ_g·√(2 ln 1/P_HIGH) ≈ 4.0 σ_g`.
pub const P_HIGH: f64 = 3.4e-4;
/// Per-pixel probability that noise alone exceeds the low Canny threshold, `≈ 2.5 σ_g`; also
/// the gradient magnitude under which a pixel's orientation counts as undefined in the
/// a-contrario test (LSD's `ρ`).
pub const P_LOW: f64 = 0.044;
/// Lowest residual threshold (pixels) of the arc combination: the localisation bias of a
/// sub-pixel edge point on the pixel grid (Devernay's parabola, ≈ 0.1 px each side).
pub const MIN_RESIDUAL: f64 = 0.2;

/// Options of [`detect_ellipses`]. Every field has a physical or statistical meaning; the
/// defaults suit any 8-bit or float image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllipseDetectParams {
    /// Fewest edge points of an arc. Default 12.
    pub min_arc_points: usize,
    /// Smallest semi-minor axis (pixels) reported. Default 2.
    pub min_semi_minor: f64,
    /// Largest semi-major axis (pixels) reported; `None` (default) for twice the image
    /// diagonal.
    pub max_semi_major: Option<f64>,
    /// Largest gap (pixels) between the end points of two arcs or segments that are combined
    /// (occlusions shorter than this are bridged). `None` (default) for half the image
    /// diagonal.
    pub max_gap: Option<f64>,
    /// Standard deviation (pixels) of a Gaussian pre-blur; 0 (default) for none. Helps very
    /// noisy images at the cost of thin lines.
    pub blur_sigma: f64,
    /// Largest number of false alarms of an accepted ellipse (the `ε` of the a-contrario test).
    /// Default 1.
    pub max_nfa: f64,
    /// When set, lines up to this many pixels wide are reported on their centre lines
    /// (polarity 0): found by the Hessian ([`ridges`]), or as two validated edges of opposite
    /// polarity at most this far apart ([`lines`]). Default `None` (edges only).
    pub max_line_width: Option<f64>,
    /// Gradient noise `σ_g` (grey levels per pixel, Sobel normalised by 1/8); `None` (default)
    /// estimates it from the image ([`noise::gradient_noise`]).
    pub gradient_noise: Option<f64>,
}

impl Default for EllipseDetectParams {
    fn default() -> Self {
        Self {
            min_arc_points: 12,
            min_semi_minor: 2.0,
            max_semi_major: None,
            max_gap: None,
            blur_sigma: 0.0,
            max_nfa: 1.0,
            max_line_width: None,
            gradient_noise: None,
        }
    }
}

impl EllipseDetectParams {
    fn validate(&self) -> Result<()> {
        let bad = |what, value, reason| {
            Err(DetectError::InvalidParameter {
                what,
                value,
                reason,
            })
        };
        if self.min_arc_points < 5 {
            return bad(
                "min_arc_points",
                self.min_arc_points as f64,
                "must be at least 5",
            );
        }
        if !(self.min_semi_minor >= 0.0 && self.min_semi_minor.is_finite()) {
            return bad(
                "min_semi_minor",
                self.min_semi_minor,
                "must be finite and >= 0",
            );
        }
        for (what, v) in [
            ("max_semi_major", self.max_semi_major),
            ("max_gap", self.max_gap),
            ("max_line_width", self.max_line_width),
            ("gradient_noise", self.gradient_noise),
        ] {
            if let Some(v) = v
                && !(v > 0.0 && v.is_finite())
            {
                return bad(what, v, "must be finite and positive");
            }
        }
        if !(self.blur_sigma >= 0.0 && self.blur_sigma <= 20.0) {
            return bad("blur_sigma", self.blur_sigma, "must be in [0, 20] pixels");
        }
        if !(self.max_nfa > 0.0 && self.max_nfa.is_finite()) {
            return bad("max_nfa", self.max_nfa, "must be finite and positive");
        }
        Ok(())
    }
}

/// One detected ellipse (or elliptic arc).
#[derive(Debug, Clone, PartialEq)]
pub struct EllipseDetection {
    /// The geometric (orthogonal-distance) fit of the support (`a ≥ b`).
    pub ellipse: Ellipse,
    /// The supporting sub-pixel edge points (pixels, `(u, v)`).
    pub points: Vec<Vector2<f64>>,
    /// Covariance of `(cx, cy, a, b, θ)` from the fit (see
    /// [`crate::ellipse::EllipseFit::covariance`]).
    pub covariance: Option<Matrix5<f64>>,
    /// Mean orthogonal distance of the points to the ellipse (pixels).
    pub residual: f64,
    /// `−log₁₀ NFA` of the a-contrario test (higher is more significant; at least
    /// `−log₁₀ max_nfa`).
    pub score: f64,
    /// `+1`: brighter outside, `−1`: brighter inside, `0`: the centre of a thin line.
    pub polarity: i8,
}

/// Detects ellipses and elliptic arcs in a grayscale image (see the module documentation).
/// Sorted by decreasing score. Deterministic (the parallel stages keep their order).
///
/// Returns an empty list for an image without edges (constant or saturated).
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad options or an image smaller than 5×5 pixels.
pub fn detect_ellipses<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &EllipseDetectParams,
) -> Result<Vec<EllipseDetection>> {
    params.validate()?;
    let (w, h) = (image.width(), image.height());
    if w < 5 || h < 5 {
        return Err(DetectError::InvalidParameter {
            what: "image size",
            value: (w.min(h)) as f64,
            reason: "the image must be at least 5x5 pixels",
        });
    }
    if params.blur_sigma > 0.0 {
        let mut grey: Vec<f32> = image.data().par_iter().map(|p| p.grey()).collect();
        crate::edges::gaussian_blur(&mut grey, w, h, params.blur_sigma);
        let unit: Vec<f32> = grey.par_iter().map(|g| g / 255.0).collect();
        let blurred = GrayView::new(&unit, w, h)?;
        return rayon::scope(|_| detect_on_pool(&blurred, params));
    }
    // One move onto rayon's pool for the whole detection (see `wafers::detect_wafers`).
    rayon::scope(|_| detect_on_pool(image, params))
}

/// The canny thresholds of the image's gradient noise `sigma_g`.
pub fn canny_params(sigma_g: f64) -> CannyParams {
    CannyParams {
        low: noise::rayleigh_quantile(sigma_g, P_LOW),
        high: noise::rayleigh_quantile(sigma_g, P_HIGH),
        blur_sigma: 0.0,
    }
}

/// [`detect_ellipses`] on a worker of rayon's pool, on the (possibly blurred) image.
fn detect_on_pool<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &EllipseDetectParams,
) -> Result<Vec<EllipseDetection>> {
    let (w, h) = (image.width(), image.height());
    let diagonal = ((w * w + h * h) as f64).sqrt();
    let sigma_g = params
        .gradient_noise
        .unwrap_or_else(|| noise::gradient_noise(image, 3));
    let canny = canny_params(sigma_g);
    let arc_params = ArcParams {
        min_points: params.min_arc_points,
        ..ArcParams::default()
    };
    let arcs = detect_arcs(image, &canny, &LinkParams::default(), &arc_params)?;
    if arcs.len() < 2 {
        return Ok(Vec::new());
    }
    let mut noise: Vec<f64> = arcs.iter().map(|a| chain_noise(&a.points)).collect();
    let mid = noise.len() / 2;
    let (_, edge_noise, _) = noise.select_nth_unstable_by(mid, f64::total_cmp);
    let max_semi_major = params.max_semi_major.unwrap_or(2.0 * diagonal);
    let assembly = AssemblyParams {
        residual_threshold: (3.0 * *edge_noise).max(MIN_RESIDUAL),
        max_gap: params.max_gap.unwrap_or(0.5 * diagonal),
        max_semi_major,
        ..AssemblyParams::default()
    };
    let segments = assemble(&arcs, &assembly)?;
    let log_nt = a_contrario::log10_tests(w, h);
    let min_score = -params.max_nfa.log10();
    let rho = canny.low;
    let mut found: Vec<EllipseDetection> = segments
        .par_iter()
        .filter_map(|s| {
            let det = validate(image, s, log_nt, rho)?;
            let e = &det.ellipse;
            (det.score >= min_score && e.b >= params.min_semi_minor && e.a <= max_semi_major)
                .then_some(det)
        })
        .collect();
    sort_by_score(&mut found);
    let found = drop_duplicates(found, assembly.residual_threshold);
    let refine_at = RefineAt {
        threshold: assembly.residual_threshold,
        edge_noise: *edge_noise,
        log_nt,
        rho,
        min_score,
    };
    let mut found = refine_all(image, found, &refine_at);
    sort_by_score(&mut found);
    let found = drop_duplicates(found, assembly.residual_threshold);
    let mut found: Vec<EllipseDetection> = found
        .into_iter()
        .filter(|d| d.score >= min_score && d.ellipse.b >= params.min_semi_minor)
        .collect();
    sort_by_score(&mut found);
    let mut found = match params.max_line_width {
        Some(width) => {
            let centres = ridges::detect_line_ellipses(image, params, ridges::ridge_scale(width))?;
            // A line found on its centre and by its two sides is one line: the centre stays.
            let mut all: Vec<EllipseDetection> = lines::pair_line_edges(found, width)
                .into_iter()
                .filter(|d| {
                    d.polarity != 0 || !centres.iter().any(|c| lines::same_line(c, d, width))
                })
                .collect();
            all.extend(centres);
            all
        }
        None => found,
    };
    sort_by_score(&mut found);
    Ok(found)
}

/// Sorts by decreasing score (ties by centre, so the order is deterministic).
pub(crate) fn sort_by_score(found: &mut [EllipseDetection]) {
    found.sort_by(by_score);
}

/// The order of [`sort_by_score`].
pub(crate) fn by_score(p: &EllipseDetection, q: &EllipseDetection) -> std::cmp::Ordering {
    q.score
        .total_cmp(&p.score)
        .then(p.ellipse.cx.total_cmp(&q.ellipse.cx))
        .then(p.ellipse.cy.total_cmp(&q.ellipse.cy))
}

/// Two segments of one ellipse that Algorithm 2 left apart (their union failed the overlap
/// rule where their arcs share pixels) are one detection: a detection whose points lie, on
/// average, within the combination threshold of a higher-scored detection's ellipse of the
/// same polarity is dropped. `found` is sorted by decreasing score.
pub(crate) fn drop_duplicates(
    found: Vec<EllipseDetection>,
    threshold: f64,
) -> Vec<EllipseDetection> {
    let mut kept: Vec<EllipseDetection> = Vec::with_capacity(found.len());
    for d in found {
        let duplicate = kept.iter().any(|k| {
            k.polarity == d.polarity && {
                let n = d.points.len().max(1) as f64;
                let mean: f64 = d
                    .points
                    .iter()
                    .map(|p| k.ellipse.sampson_distance(p))
                    .sum::<f64>()
                    / n;
                mean <= threshold
            }
        });
        if !duplicate {
            kept.push(d);
        }
    }
    kept
}

/// The constants of stage 4b: the combination threshold, the median edge noise (pixels), the
/// a-contrario test's `log₁₀ N_tests` and `ρ`, and the lowest accepted score.
struct RefineAt {
    threshold: f64,
    edge_noise: f64,
    log_nt: f64,
    rho: f64,
    min_score: f64,
}

/// Stage 4b ([`refine`]): split arcs merged, supports trimmed of points within the edge
/// operator's reach of other curves, robust refits, each refined detection validated again
/// (a refinement whose test fails leaves the detection as it was).
fn refine_all<T: Pixel>(
    image: &GrayView<'_, T>,
    found: Vec<EllipseDetection>,
    at: &RefineAt,
) -> Vec<EllipseDetection> {
    let (log_nt, rho) = (at.log_nt, at.rho);
    let merged = refine::merge_split(found, at.threshold);
    let found: Vec<EllipseDetection> = merged
        .into_iter()
        .map(|(mut d, changed)| {
            if changed {
                d.score = score_of(image, &d.ellipse, &d.points, d.polarity, log_nt, rho)
                    .unwrap_or(f64::NEG_INFINITY);
            }
            d
        })
        .collect();
    let boxes = refine::boxes(&found, refine::OPERATOR_REACH);
    (0..found.len())
        .into_par_iter()
        .map(|i| {
            let original = &found[i];
            refine::trim_and_refit(&found, &boxes, i, refine::OPERATOR_REACH, at.edge_noise)
                .and_then(|mut d| {
                    d.score = score_of(image, &d.ellipse, &d.points, d.polarity, log_nt, rho)?;
                    (d.score >= at.min_score).then_some(d)
                })
                .unwrap_or_else(|| original.clone())
        })
        .collect()
}

/// `−log₁₀ NFA` of the ellipse `e` over the angular extent its `points` cover, or `None` when
/// that extent covers no pixels.
fn score_of<T: Pixel>(
    image: &GrayView<'_, T>,
    e: &Ellipse,
    points: &[Vector2<f64>],
    polarity: i8,
    log_nt: f64,
    rho: f64,
) -> Option<f64> {
    a_contrario::score_support(e, points, log_nt, |extent| {
        a_contrario::count_alignment(image, e, extent, polarity, rho)
    })
}

/// The a-contrario test of one segment: its detection with the score, or `None` when the
/// segment covers no pixels.
pub(crate) fn validate<T: Pixel>(
    image: &GrayView<'_, T>,
    segment: &Segment,
    log_nt: f64,
    rho: f64,
) -> Option<EllipseDetection> {
    let e = segment.fit.ellipse;
    let score = score_of(image, &e, &segment.points, segment.polarity, log_nt, rho)?;
    Some(EllipseDetection {
        ellipse: e,
        points: segment.points.clone(),
        covariance: segment.fit.covariance,
        residual: segment.fit.residual_mean,
        score,
        polarity: segment.polarity,
    })
}
