//! Arc-level validation of assembled segments: leave-one-out and outlier-arc checks
//! (seed 000_3b1454b2b2194811.txt §3.2).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;

/// A segment without one of its arcs: the remaining arc indices, their points and their fit.
type LeftOut = (Vec<usize>, Vec<Vector2<f64>>, EllipseFit);

/// Leave-one-out check of a segment of three or more arcs: for each arc, the other arcs are
/// refitted (orthogonal-distance LM from the segment's ellipse) and the arc's median distance
/// to that fit taken. A clutter arc a few pixels off a rim (a slot-tooth edge, the other rim's
/// back silhouette) bends the fit of the union toward itself, so its distance to the union's
/// fit can stay under [`DetectParams::max_arc_deviation`]; to the fit of the others it cannot.
/// The arc farthest from its leave-one-out fit is dropped when that distance exceeds
/// `max_arc_deviation` and the union's mean residual exceeds
/// [`DetectParams::max_arc_residual_ratio`] × the others' (an arc of the same ellipse hardly
/// changes the residual, even where the others extrapolate poorly); repeated while three or
/// more arcs remain.
pub(super) fn drop_inconsistent_arcs(seg: &mut Segment, arcs: &[Arc], params: &DetectParams) {
    let (limit, ratio) = (params.max_arc_deviation, params.max_arc_residual_ratio);
    if !(limit > 0.0 && ratio > 0.0) {
        return;
    }
    while seg.arcs.len() >= 3 {
        let mut worst: Option<(f64, LeftOut)> = None;
        for (slot, &k) in seg.arcs.iter().enumerate() {
            let Some(arc) = arcs.get(k) else { return };
            let Some((kept, points, fit)) = refit_without_arc(seg, arcs, slot) else {
                continue;
            };
            if !(seg.fit.residual_mean > ratio * fit.residual_mean) {
                continue;
            }
            let m = median_abs_distance(&fit.ellipse, &arc.points);
            if m > limit && worst.as_ref().is_none_or(|w| m > w.0) {
                worst = Some((m, (kept, points, fit)));
            }
        }
        let Some((_, (kept, points, fit))) = worst else {
            return;
        };
        seg.arcs = kept;
        seg.points = points;
        seg.fit = fit;
    }
}

/// The arc indices of `seg` without the one in position `slot`, and their edge points.
fn without_arc(seg: &Segment, arcs: &[Arc], slot: usize) -> (Vec<usize>, Vec<Vector2<f64>>) {
    let kept: Vec<usize> = seg
        .arcs
        .iter()
        .enumerate()
        .filter(|&(s, _)| s != slot)
        .map(|(_, &k)| k)
        .collect();
    let points = kept
        .iter()
        .filter_map(|&k| arcs.get(k))
        .flat_map(|a| a.points.iter().copied())
        .collect();
    (kept, points)
}

/// [`without_arc`] refitted: the orthogonal-distance LM fit of the remaining points, started
/// from the segment's current ellipse; `None` when the fit fails.
fn refit_without_arc(seg: &Segment, arcs: &[Arc], slot: usize) -> Option<LeftOut> {
    let (kept, points) = without_arc(seg, arcs, slot);
    let fit = crate::ellipse::fit_ellipse_geometric(
        &points,
        Some(seg.fit.ellipse),
        &crate::ellipse::GeometricFitOptions::default(),
    )
    .ok()?;
    Some((kept, points, fit))
}

/// Median absolute orthogonal distance of `points` to `e`.
fn median_abs_distance(e: &Ellipse, points: &[Vector2<f64>]) -> f64 {
    let mut d = e.orthogonal_distances(points);
    d.iter_mut().for_each(|x| *x = x.abs());
    median(&mut d)
}

/// Drops, worst first, the arcs of `seg` whose median orthogonal distance to the segment's
/// ellipse exceeds [`DetectParams::max_arc_deviation`], refitting the remaining arcs
/// (orthogonal-distance LM from the current ellipse) after each drop; stops when every arc
/// agrees, one arc is left, or a refit fails (the segment is then left as it was last).
pub(super) fn drop_outlier_arcs(seg: &mut Segment, arcs: &[Arc], params: &DetectParams) {
    let limit = params.max_arc_deviation;
    if !(limit > 0.0) {
        return;
    }
    while seg.arcs.len() > 1 {
        let e = seg.fit.ellipse;
        let mut worst: Option<(usize, f64)> = None;
        for (slot, &k) in seg.arcs.iter().enumerate() {
            let Some(arc) = arcs.get(k) else { return };
            let m = median_abs_distance(&e, &arc.points);
            if worst.is_none_or(|(_, w)| m > w) {
                worst = Some((slot, m));
            }
        }
        let Some((slot, m)) = worst else { return };
        if !(m > limit) {
            return;
        }
        let Some((kept, points, fit)) = refit_without_arc(seg, arcs, slot) else {
            return;
        };
        seg.arcs = kept;
        seg.points = points;
        seg.fit = fit;
    }
}

/// Median of `v` (reordered); NaN for an empty slice.
pub(super) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}
