//! Band-model refinement of a rim's edge points (seed 000_3b1454b2b2194811.txt §3.2, Fig. 3.2:
//! the bright side band of a wafer forms two edges).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;

/// Most profiles used to estimate the blur σ of a rim (first pass of [`refine_band_edges`]).
const SIGMA_PROFILES: usize = 48;
/// Most points of a rim re-located by [`refine_band_edges`] (evenly spread; the refit uses
/// these): 240 points at ≈ 0.05 px edge noise determine the ellipse far below the 0.3 px goal.
const BAND_POINTS: usize = 240;

/// Moves each point of `seg` to the edge position of the two-edge band model ([`band`]) fitted
/// to the image profile along the ellipse normal through it, then refits the ellipse
/// (orthogonal-distance LM from the current one) and keeps the refit when its mean residual is
/// under `threshold`. At most [`BAND_POINTS`] evenly spread points are used (they replace the
/// segment's points); the profiles are fitted in parallel (rayon).
///
/// First pass: σ (the blur) is fitted freely on up to [`SIGMA_PROFILES`] evenly spread
/// profiles and its median over the unclipped ones (all, if fewer than 5) taken for the rim; second pass: every profile is fitted with σ
/// fixed to it (five parameters: two edges and three levels; a free σ per profile would trade
/// off against the clipped band level). A point is moved only when its profile is a band —
/// both edges within the window, `|t₁| ≤ 1.5 px`, the band at least 8 grey levels above both
/// sides — and otherwise keeps its Canny position (a lone step, whose Sobel maximum is
/// unbiased).
pub fn refine_band_edges<T: Pixel>(image: &GrayView<'_, T>, seg: &mut Segment, threshold: f64) {
    let e = seg.fit.ellipse;
    let normal = |p: &Vector2<f64>| level_set_normal(&e, p);
    let n = seg.points.len();
    if n < 10 {
        return;
    }
    let mut buf = Vec::new();
    let mut sigmas = Vec::new();
    let mut clipped_sigmas = Vec::new();
    let stride = (n / SIGMA_PROFILES).max(1);
    for p in seg.points.iter().step_by(stride) {
        let Some(nv) = normal(p) else { continue };
        if band::profile(image, *p, nv, &mut buf).is_none() {
            continue;
        }
        let Some(p0) = band::start(&buf) else {
            continue;
        };
        if let Some((q, _)) = band::fit(&buf, p0, true)
            && is_band(&q)
        {
            if buf.iter().any(|s| s.1.is_infinite()) {
                clipped_sigmas.push(q[5]);
            } else {
                sigmas.push(q[5]);
            }
        }
    }
    // σ from unclipped profiles (on clipped ones it trades off against the unseen band level);
    // all of them only when too few are unclipped.
    if sigmas.len() < 5 {
        sigmas.append(&mut clipped_sigmas);
    }
    if sigmas.len() < 5 {
        return;
    }
    let sigma = median(&mut sigmas);
    let stride = n.div_ceil(BAND_POINTS);
    let picked: Vec<Vector2<f64>> = seg.points.iter().step_by(stride).copied().collect();
    // Each point: its band-model position and the fit's RMS residual, or its Canny position
    // (`None`) when the profile is no band.
    let located: Vec<(Vector2<f64>, Option<f64>)> = picked
        .par_iter()
        // One sample buffer per rayon work split (`map_init`), not one allocation per point.
        .map_init(Vec::new, |buf, p| {
            let Some(nv) = normal(p) else {
                return (*p, None);
            };
            let Some(d) = band::profile(image, *p, nv, buf) else {
                return (*p, None);
            };
            let Some(mut p0) = band::start(buf) else {
                return (*p, None);
            };
            p0[5] = sigma;
            match band::fit(buf, p0, false) {
                Some((q, rms)) if is_band(&q) => (p + d * q[3], Some(rms)),
                _ => (*p, None),
            }
        })
        .collect();
    let moved = screen_band_points(&located);
    let Ok(fit) = crate::ellipse::fit_ellipse_geometric(
        &moved,
        Some(e),
        &crate::ellipse::GeometricFitOptions::default(),
    ) else {
        return;
    };
    if fit.residual_mean < threshold {
        seg.points = moved;
        seg.fit = fit;
    }
}

/// The unit normal at `p` of the level set of `e`'s implicit function through `p` (the
/// direction of its gradient, outward), `None` at the centre.
pub(super) fn level_set_normal(e: &Ellipse, p: &Vector2<f64>) -> Option<Vector2<f64>> {
    let (st, ct) = e.theta.sin_cos();
    let (dx, dy) = (p.x - e.cx, p.y - e.cy);
    let (xl, yl) = (dx * ct + dy * st, -dx * st + dy * ct);
    let (gx, gy) = (xl / (e.a * e.a), yl / (e.b * e.b));
    let n = Vector2::new(gx * ct - gy * st, gx * st + gy * ct);
    let len = n.norm();
    (len > 0.0).then(|| n / len)
}

/// Smallest fraction of a rim's profiles that must be bands for [`screen_band_points`] to drop
/// the others.
const MIN_BAND_FRACTION: f64 = 0.6;
/// A band profile whose RMS residual exceeds this multiple of the rim's median band RMS is
/// taken for clutter across the profile (see [`screen_band_points`]).
const MAX_BAND_RMS_RATIO: f64 = 2.5;

/// The points kept for the refit of [`refine_band_edges`] from `(position, band-fit RMS or
/// None)`. When most profiles of the rim (at least [`MIN_BAND_FRACTION`]) are bands, the rim
/// *is* a band and a point whose profile is not one, or whose band fit leaves an RMS over
/// [`MAX_BAND_RMS_RATIO`] × the median (structure across the profile that the model lacks: the
/// rim crossing the carrier's slot teeth near the ends of the front arc, where the dark level
/// outside the rim is replaced by a tooth's grey edge), has a position biased by up to ≈ 0.4 px
/// (the Canny maximum of a band edge is pushed outward, and a wrong far level drags `t₁`): it is
/// dropped. Otherwise every point is kept (a rim seen as a lone step: its Sobel maximum is
/// unbiased).
pub(super) fn screen_band_points(located: &[(Vector2<f64>, Option<f64>)]) -> Vec<Vector2<f64>> {
    let mut rms: Vec<f64> = located.iter().filter_map(|(_, r)| *r).collect();
    if (rms.len() as f64) < MIN_BAND_FRACTION * located.len() as f64 {
        return located.iter().map(|(p, _)| *p).collect();
    }
    let limit = MAX_BAND_RMS_RATIO * median(&mut rms);
    located
        .iter()
        .filter(|(_, r)| r.is_some_and(|r| r <= limit))
        .map(|(p, _)| *p)
        .collect()
}

/// Whether fitted band-model parameters describe a band at the edge point (see
/// [`refine_band_edges`]).
pub(super) fn is_band(q: &[f64; 6]) -> bool {
    let [l0, lb, l2, t1, t2, _] = *q;
    t1.abs() <= 1.5
        && t2 > t1
        && t2 < band::T_MAX
        && lb - l0 >= 8.0
        && lb - l2 >= 8.0
        && q.iter().all(|x| x.is_finite())
}
