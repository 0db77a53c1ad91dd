//! Refinement of the accepted detections (stage 4b of [`super::detect_ellipses`]): one
//! detection per ellipse, and a support free of points that belong to other curves.
//!
//! 1. **Split arcs are merged.** Algorithm 2 (000_3b1454b2b2194811.txt §3.2) can leave two
//!    segments of one ellipse apart (e.g. the left and right halves of a rim's front arc, when
//!    the arc between them is shared or interrupted). Two detections of one polarity are one
//!    ellipse when the geometric fit of their joint support passes the seed's combination rule:
//!    mean orthogonal residual under the combination threshold (the `threshold` of
//!    Algorithms 1–2). Each support alone determines a poor ellipse on a short arc, so the merge
//!    is what makes the axes accurate.
//! 2. **Points within the edge operator's reach of another curve are left out of the fit.**
//!    A sub-pixel edge point comes from the 3×3 Sobel gradient at its pixel and the two
//!    neighbours of Devernay's parabola, i.e. from pixels up to [`OPERATOR_REACH`] = 2 px away
//!    along the normal. Where another detected curve passes closer than that — the two rims of a
//!    thin wafer where they converge at the tips, neighbouring rims of a stack, a reflection —
//!    the two edges' gradients overlap and pull each other's points by up to a pixel
//!    (measured on `autoteach.sim.appearance` scenes: 0.2–2 px near the tips, under 0.05 px
//!    elsewhere). On a partial arc the tips decide the centre, so a few such points move it by
//!    more than the noise. Where every point of a support is that close (a band narrower than
//!    the reach everywhere), nothing is left out: no point is better than another.
//! 3. **Robust refit.** Points farther from the refitted ellipse than 3σ̂ are outliers (a chain
//!    that ran onto another curve where two curves cross), with σ̂ the robust spread
//!    (1.4826·MAD) of the distances, floored at the image's edge noise; until the inliers stay
//!    the same (at most ten rounds).
//!
//! Each refined detection is validated again by the a-contrario test, so its score belongs to
//! its final ellipse.

// `!(x <= y)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use autoteach_geometry::conic::Ellipse;
use nalgebra::Vector2;

use super::EllipseDetection;
use crate::ellipse::{EllipseFit, GeometricFitOptions, fit_ellipse_geometric};

/// How far (pixels) along the normal an edge point's position draws on the image: the 3×3
/// Sobel window (±1 px) at Devernay's three samples (±1 px).
pub const OPERATOR_REACH: f64 = 2.0;
/// Robust rejection at `3σ̂`.
const REJECT_SIGMAS: f64 = 3.0;
/// Rounds of the robust refit.
const ROBUST_ROUNDS: usize = 10;
/// Fewest points a trimmed support keeps (else the whole support is used).
const MIN_SUPPORT: usize = 20;
/// Smallest fraction of its points a trimmed support keeps (else the whole support is used):
/// a curve that is near another along most of its length is not helped by leaving that out.
const MIN_KEPT_FRACTION: f64 = 0.3;

/// The geometric fit of `points` started from `start`, or `None` when it fails.
fn refit(points: &[Vector2<f64>], start: &Ellipse) -> Option<EllipseFit> {
    fit_ellipse_geometric(points, Some(*start), &GeometricFitOptions::default())
        .ok()
        .filter(|f| f.ellipse.a.is_finite() && f.ellipse.b > 0.0)
}

/// Unsigned orthogonal distance of `p` to `e`, computed exactly only where the cheap Sampson
/// distance says `p` may be within `reach` (Sampson underestimates near the tips of flat
/// ellipses, hence the factor 2).
fn near_distance(e: &Ellipse, p: &Vector2<f64>, reach: f64) -> f64 {
    let s = e.sampson_distance(p);
    if !(s <= 2.0 * reach + 1.0) {
        return f64::INFINITY;
    }
    e.orthogonal_distance(p).abs()
}

/// Axis-aligned bounding box of an ellipse, `(xmin, ymin, xmax, ymax)`, grown by `margin`.
fn bounds(e: &Ellipse, margin: f64) -> [f64; 4] {
    let (s, c) = e.theta.sin_cos();
    let hx = ((e.a * c).powi(2) + (e.b * s).powi(2)).sqrt() + margin;
    let hy = ((e.a * s).powi(2) + (e.b * c).powi(2)).sqrt() + margin;
    [e.cx - hx, e.cy - hy, e.cx + hx, e.cy + hy]
}

fn inside(b: &[f64; 4], p: &Vector2<f64>) -> bool {
    p.x >= b[0] && p.x <= b[2] && p.y >= b[1] && p.y <= b[3]
}

/// The union of two supports without repeated points (arcs shared by two segments give
/// bit-identical points).
fn union(a: &[Vector2<f64>], b: &[Vector2<f64>]) -> Vec<Vector2<f64>> {
    let mut all: Vec<Vector2<f64>> = a.iter().chain(b).copied().collect();
    all.sort_by(|p, q| p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)));
    all.dedup();
    all
}

/// Median Sampson distance of (about 32 of) `pts` to `e`; infinite for no points.
pub(crate) fn median_distance(e: &Ellipse, pts: &[Vector2<f64>]) -> f64 {
    let mut d: Vec<f64> = pts
        .iter()
        .step_by((pts.len() / 32).max(1))
        .map(|p| e.sampson_distance(p))
        .collect();
    let mid = d.len() / 2;
    if d.is_empty() {
        return f64::INFINITY;
    }
    d.select_nth_unstable_by(mid, f64::total_cmp);
    d[mid]
}

/// Step 1: merges detections of one polarity whose joint support fits one ellipse with a mean
/// residual at most `threshold`. `found` is sorted by decreasing score; a merged detection
/// takes the place of the higher-scored one. Returns the detections and whether each was
/// changed (its score must be recomputed).
pub(crate) fn merge_split(
    mut found: Vec<EllipseDetection>,
    threshold: f64,
) -> Vec<(EllipseDetection, bool)> {
    let mut changed = vec![false; found.len()];
    let mut alive = vec![true; found.len()];
    loop {
        let mut merged_any = false;
        for i in 0..found.len() {
            if !alive[i] {
                continue;
            }
            for j in i + 1..found.len() {
                if !alive[j] || found[i].polarity != found[j].polarity {
                    continue;
                }
                let (ei, ej) = (found[i].ellipse, found[j].ellipse);
                // Cheap gate: the two ellipses must be close where the other's points are.
                let gate = median_distance;
                if found[j].points.is_empty()
                    || found[i].points.is_empty()
                    || !(gate(&ei, &found[j].points).min(gate(&ej, &found[i].points))
                        <= 10.0 * threshold)
                {
                    continue;
                }
                let pts = union(&found[i].points, &found[j].points);
                let Some(fit) = refit(&pts, &ei) else {
                    continue;
                };
                if !(fit.residual_mean <= threshold) {
                    continue;
                }
                let d = &mut found[i];
                d.ellipse = fit.ellipse;
                d.covariance = fit.covariance;
                d.residual = fit.residual_mean;
                d.points = pts;
                changed[i] = true;
                alive[j] = false;
                merged_any = true;
            }
        }
        if !merged_any {
            break;
        }
    }
    found
        .into_iter()
        .zip(changed)
        .zip(alive)
        .filter_map(|((d, c), a)| a.then_some((d, c)))
        .collect()
}

/// Steps 2 and 3 for detection `i` of `all`: the support without points within `reach` of
/// another detection's ellipse, robustly refitted. `edge_noise` floors the robust spread.
/// `None` when nothing changes (no point left out) or a fit fails.
pub(crate) fn trim_and_refit(
    all: &[EllipseDetection],
    boxes: &[[f64; 4]],
    i: usize,
    reach: f64,
    edge_noise: f64,
) -> Option<EllipseDetection> {
    let det = &all[i];
    let pts = &det.points;
    let far: Vec<bool> = pts
        .iter()
        .map(|p| {
            all.iter().enumerate().all(|(j, other)| {
                j == i || !inside(&boxes[j], p) || near_distance(&other.ellipse, p, reach) >= reach
            })
        })
        .collect();
    let kept = far.iter().filter(|&&f| f).count();
    let base: Vec<Vector2<f64>> =
        if kept >= MIN_SUPPORT && kept as f64 >= MIN_KEPT_FRACTION * pts.len() as f64 {
            pts.iter()
                .zip(&far)
                .filter(|(_, f)| **f)
                .map(|(p, _)| *p)
                .collect()
        } else {
            pts.clone()
        };
    // The detection's own fit stands for the untrimmed support: no refit unless something
    // is left out (most detections: one pass of distances, no fit).
    let mut fit: Option<EllipseFit> = if base.len() == pts.len() {
        None
    } else {
        Some(refit(&base, &det.ellipse)?)
    };
    let mut support = base.clone();
    for _ in 0..ROBUST_ROUNDS {
        let current = fit.as_ref().map_or(det.ellipse, |f| f.ellipse);
        // Inliers are chosen among all of `base` each round, so a point rejected against an
        // early, outlier-pulled fit comes back once the fit has moved.
        let d: Vec<f64> = base
            .iter()
            .map(|p| current.orthogonal_distance(p))
            .collect();
        let mut abs: Vec<f64> = d.iter().map(|v| v.abs()).collect();
        let mid = abs.len() / 2;
        abs.select_nth_unstable_by(mid, f64::total_cmp);
        let spread = (1.4826 * abs[mid]).max(edge_noise);
        let inliers: Vec<Vector2<f64>> = base
            .iter()
            .zip(&d)
            .filter(|(_, v)| v.abs() <= REJECT_SIGMAS * spread)
            .map(|(p, _)| *p)
            .collect();
        if inliers.len() < MIN_SUPPORT || inliers == support {
            break;
        }
        fit = Some(refit(&inliers, &current)?);
        support = inliers;
    }
    let fit = fit?;
    Some(EllipseDetection {
        ellipse: fit.ellipse,
        points: support,
        covariance: fit.covariance,
        residual: fit.residual_mean,
        score: det.score,
        polarity: det.polarity,
    })
}

/// Bounding boxes of every detection's ellipse, grown by `reach`.
pub(crate) fn boxes(all: &[EllipseDetection], reach: f64) -> Vec<[f64; 4]> {
    all.iter().map(|d| bounds(&d.ellipse, reach)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(e: Ellipse, t0: f64, t1: f64, n: usize, polarity: i8) -> EllipseDetection {
        let points = e.sample(n, t0, t1).expect("valid arc");
        EllipseDetection {
            ellipse: e,
            points,
            covariance: None,
            residual: 0.0,
            score: 10.0,
            polarity,
        }
    }

    #[test]
    fn split_halves_of_one_ellipse_merge_and_others_do_not() {
        let e = Ellipse::new(200.0, 150.0, 120.0, 40.0, 0.1).expect("ellipse");
        // Two quarter arcs, each fitted badly on its own (axes off by 3 %).
        let mut left = det(e, 1.6, 3.0, 200, 1);
        left.ellipse = Ellipse::new(201.0, 149.0, 116.0, 41.0, 0.1).expect("ellipse");
        let right = det(e, 0.1, 1.5, 200, 1);
        // Another curve 6 px away, and the same curve with the other polarity.
        let other = det(
            Ellipse::new(200.0, 156.0, 120.0, 40.0, 0.1).expect("ellipse"),
            0.1,
            3.0,
            300,
            1,
        );
        let flipped = det(e, 0.1, 3.0, 300, -1);
        let out = merge_split(vec![left, right, other, flipped], 0.2);
        assert_eq!(out.len(), 3);
        let (merged, changed) = &out[0];
        assert!(*changed);
        assert_eq!(merged.points.len(), 400);
        let m = merged.ellipse;
        assert!((m.cx - e.cx).hypot(m.cy - e.cy) < 1e-6, "{m:?}");
        assert!((m.a - e.a).abs() < 1e-6 && (m.b - e.b).abs() < 1e-6);
        assert!(!out[1].1 && !out[2].1);
    }

    #[test]
    fn points_near_another_curve_leave_the_fit() {
        // A front arc whose points near its ends are pulled 1 px toward a second curve that
        // converges there (as the two rims of a thin wafer at the tips).
        let e = Ellipse::new(300.0, 200.0, 200.0, 50.0, 0.0).expect("ellipse");
        let partner = Ellipse::new(300.0, 203.0, 200.0, 50.0, 0.0).expect("ellipse");
        let mut d = det(e, 0.0, std::f64::consts::PI, 600, 1);
        for p in d.points.iter_mut() {
            if partner.orthogonal_distance(p).abs() < OPERATOR_REACH {
                // pulled toward the partner by a pixel
                let q = partner.closest_point(p);
                *p += (q - *p).normalize() * 1.0;
            }
        }
        let biased = refit(&d.points, &e).expect("fit").ellipse;
        assert!(
            (biased.cy - e.cy).abs() > 0.1,
            "the pull must matter: {biased:?}"
        );
        let all = vec![d, det(partner, 0.0, std::f64::consts::PI, 600, -1)];
        let b = boxes(&all, OPERATOR_REACH);
        let out = trim_and_refit(&all, &b, 0, OPERATOR_REACH, 0.01).expect("refit");
        let f = out.ellipse;
        assert!((f.cx - e.cx).hypot(f.cy - e.cy) < 0.05, "{f:?}");
        assert!((f.a / e.a - 1.0).abs() < 1e-3 && (f.b / e.b - 1.0).abs() < 1e-3);
        assert!(out.points.len() < 600);
    }

    #[test]
    fn a_chain_that_ran_onto_another_curve_is_cut_by_the_robust_refit() {
        let e = Ellipse::new(300.0, 200.0, 150.0, 60.0, 0.0).expect("ellipse");
        let mut d = det(e, 0.2, 2.9, 400, 1);
        // 12 points 2.5 px outside the tip (on a crossing curve; measured on rims: 1–2 %).
        let extra: Vec<Vector2<f64>> = e
            .sample(12, 3.0, 3.2)
            .expect("arc")
            .into_iter()
            .map(|p| p + Vector2::new(-2.5, 0.0))
            .collect();
        d.points.extend(extra);
        d.ellipse = refit(&d.points, &e).expect("fit").ellipse;
        let all = vec![d];
        let b = boxes(&all, OPERATOR_REACH);
        let out = trim_and_refit(&all, &b, 0, OPERATOR_REACH, 0.05).expect("refit");
        let f = out.ellipse;
        assert!((f.cx - e.cx).hypot(f.cy - e.cy) < 1e-3, "{f:?}");
        assert!(
            (f.a - e.a).abs() < 1e-3 && (f.b - e.b).abs() < 1e-3,
            "{f:?}"
        );
        assert!(out.points.len() >= 390, "{}", out.points.len());
        assert!(
            out.points
                .iter()
                .all(|p| e.orthogonal_distance(p).abs() < 0.5)
        );
    }
}
