//! Arc-level validation of assembled segments: leave-one-out and outlier-arc checks
//! (seed 000_3b1454b2b2194811.txt §3.2).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;
use nalgebra::Vector5;

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
        let screen = LeaveOneOutScreen::new(seg, arcs);
        let mut worst: Option<(f64, LeftOut)> = None;
        for (slot, &k) in seg.arcs.iter().enumerate() {
            let Some(arc) = arcs.get(k) else { return };
            let predicted = screen.as_ref().and_then(|s| s.predict(slot));
            if let Some((pm, pmean)) = predicted
                && clearly_consistent(pm, pmean, seg.fit.residual_mean, limit, ratio)
            {
                continue;
            }
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

/// Safety factors of the linearised screen of [`drop_inconsistent_arcs`]: a leave-one-out
/// refit is skipped only when its predicted median distance of the left-out arc is under
/// `max_arc_deviation / DISTANCE_MARGIN`, or the predicted residual ratio (union over the
/// others) under `max_arc_residual_ratio / RATIO_MARGIN`. On the benchmark scenes the
/// one-step prediction is within ≈ 12 % of the converged refit for the mean residual and
/// ≈ 25 % for the median distance of the left-out arc (it extrapolates the others' fit).
const DISTANCE_MARGIN: f64 = 2.0;
/// See [`DISTANCE_MARGIN`].
const RATIO_MARGIN: f64 = 1.25;

/// Whether the linearised prediction `(median distance of the left-out arc, mean residual of
/// the others)` of a leave-one-out fit is so far inside the keep region of
/// [`drop_inconsistent_arcs`] that the exact refit cannot drop the arc.
fn clearly_consistent(m: f64, mean: f64, union_mean: f64, limit: f64, ratio: f64) -> bool {
    m < limit / DISTANCE_MARGIN || union_mean * RATIO_MARGIN < ratio * mean
}

/// The Gauss–Newton linearisation of a segment's orthogonal distances at its fitted ellipse,
/// per arc, for predicting its leave-one-out fits without refitting (see
/// [`LeaveOneOutScreen::predict`]).
struct LeaveOneOutScreen {
    /// Per point: signed orthogonal distance `r` and its gradient with respect to
    /// `(cx, cy, a, b, θ)`, arc after arc in the order of `Segment::arcs`.
    rows: Vec<(f64, Vector5<f64>)>,
    /// Per arc: the range of its points in `rows`, and its `JᵀJ` and `Jᵀr`.
    arcs: Vec<(std::ops::Range<usize>, Matrix5<f64>, Vector5<f64>)>,
    /// `JᵀJ` and `Jᵀr` of all points.
    total: (Matrix5<f64>, Vector5<f64>),
}

impl LeaveOneOutScreen {
    /// Linearises the distances of the points of `seg`'s arcs at `seg.fit.ellipse`: at the
    /// foot point `x' = c + R(θ)·[a cos t, b sin t]ᵀ` (eq. 3.2) with outward unit normal `n̂`,
    /// `r = n̂·(p − x')` and `∂r/∂q = −n̂·∂x'/∂q` (the foot angle's own variation is orthogonal
    /// to `n̂`; Ahn, Rauh & Warnecke 2001). `None` if an arc index is out of range.
    fn new(seg: &Segment, arcs: &[Arc]) -> Option<Self> {
        let e = &seg.fit.ellipse;
        let mut rows = Vec::with_capacity(seg.points.len());
        let mut per_arc = Vec::with_capacity(seg.arcs.len());
        let (mut h, mut g) = (Matrix5::zeros(), Vector5::zeros());
        for &k in &seg.arcs {
            let arc = arcs.get(k)?;
            let start = rows.len();
            let (mut ha, mut ga) = (Matrix5::<f64>::zeros(), Vector5::<f64>::zeros());
            for p in &arc.points {
                let (r, j) = crate::ellipse::point_distance_and_gradient(e, p);
                ha += j * j.transpose();
                ga += j * r;
                rows.push((r, j));
            }
            h += ha;
            g += ga;
            per_arc.push((start..rows.len(), ha, ga));
        }
        Some(Self {
            rows,
            arcs: per_arc,
            total: (h, g),
        })
    }

    /// The Gauss–Newton step of the fit without arc `slot` from the segment's ellipse,
    /// `δ = −(JₖᵀJₖ)⁻¹Jₖᵀrₖ` over the kept points, and the predicted distances `r + Jδ`
    /// there: `(median |r + Jδ| of the left-out arc, mean |r + Jδ| of the kept points)`.
    /// `None` if the kept points do not determine the step.
    fn predict(&self, slot: usize) -> Option<(f64, f64)> {
        let (range, ha, ga) = self.arcs.get(slot)?;
        let h = self.total.0 - ha;
        let g = self.total.1 - ga;
        let delta = h.cholesky()?.solve(&(-g));
        if !delta.iter().all(|x| x.is_finite()) {
            return None;
        }
        let moved = |(r, j): &(f64, Vector5<f64>)| (r + j.dot(&delta)).abs();
        let mut left: Vec<f64> = self.rows[range.clone()].iter().map(moved).collect();
        let kept = self.rows.len() - range.len();
        let sum: f64 = self.rows[..range.start]
            .iter()
            .chain(&self.rows[range.end..])
            .map(moved)
            .sum();
        Some((median(&mut left), sum / kept.max(1) as f64))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::edges::Quadrant;

    fn arc(points: Vec<Vector2<f64>>) -> Arc {
        Arc {
            normals: vec![Vector2::new(0.0, 1.0); points.len()],
            points,
            contrast: 50.0,
            quadrant: Quadrant::III,
            polarity: -1,
            curvature: 0.01,
            turn: 1.0,
        }
    }

    /// Points of `e` at eccentric angles `t0..t1`, shifted by `shift` along v, with a
    /// deterministic ±0.05 px wobble.
    fn on(e: &Ellipse, t0: f64, t1: f64, n: usize, shift: f64) -> Vec<Vector2<f64>> {
        (0..n)
            .map(|k| {
                let t = t0 + (t1 - t0) * k as f64 / (n - 1) as f64;
                let wobble = 0.05 * (((k * 7919) % 11) as f64 / 5.0 - 1.0);
                e.point_at(t) + Vector2::new(0.0, shift + wobble)
            })
            .collect()
    }

    fn segment(e: &Ellipse, arcs: &[Arc]) -> Segment {
        let points: Vec<Vector2<f64>> = arcs.iter().flat_map(|a| a.points.clone()).collect();
        let fit = crate::ellipse::fit_ellipse_geometric(
            &points,
            Some(*e),
            &crate::ellipse::GeometricFitOptions::default(),
        )
        .unwrap();
        Segment {
            arcs: (0..arcs.len()).collect(),
            points,
            fit,
            polarity: -1,
        }
    }

    #[test]
    fn screen_rows_are_orthogonal_distances_and_their_gradients() {
        // r against the geometry crate's exact distance, ∂r/∂q against central differences.
        let e = Ellipse::new(600.0, 300.0, 280.0, 30.0, 0.07).unwrap();
        let h = std::f64::consts::FRAC_PI_2;
        let arcs = vec![
            arc(on(&e, h + 0.1, h + 1.0, 40, 0.3)),
            arc(on(&e, -h - 0.5, -h + 0.5, 40, -0.4)),
        ];
        let seg = segment(&e, &arcs);
        let f = seg.fit.ellipse;
        let screen = LeaveOneOutScreen::new(&seg, &arcs).unwrap();
        let points: Vec<Vector2<f64>> = arcs.iter().flat_map(|a| a.points.clone()).collect();
        assert_eq!(screen.rows.len(), points.len());
        for (p, (r, j)) in points.iter().zip(&screen.rows) {
            assert!((r - f.orthogonal_distance(p)).abs() < 1e-9, "{r}");
            let q = [f.cx, f.cy, f.a, f.b, f.theta];
            for k in 0..5 {
                let step = 1e-6 * (1.0 + q[k].abs());
                let at = |sign: f64| {
                    let mut v = q;
                    v[k] += sign * step;
                    Ellipse::new(v[0], v[1], v[2], v[3], v[4])
                        .unwrap()
                        .orthogonal_distance(p)
                };
                let fd = (at(1.0) - at(-1.0)) / (2.0 * step);
                assert!(
                    (fd - j[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "k={k}: {fd} vs {}",
                    j[k]
                );
            }
        }
    }

    #[test]
    fn screen_predicts_the_leave_one_out_refits() {
        // Two front arcs and a third arc: a true back arc (consistent) or a clutter arc 3 px off
        // the rim. The one-step prediction of each leave-one-out fit (mean residual of the
        // others, median distance of the left-out arc) is compared with the converged refit,
        // and the screen never skips a refit that drops the arc.
        let e = Ellipse::new(600.0, 300.0, 280.0, 30.0, 0.0).unwrap();
        let h = std::f64::consts::FRAC_PI_2;
        let params = DetectParams::default();
        for (third, clutter) in [
            (on(&e, -h - 0.6, -h + 0.6, 150, 0.0), false),
            (on(&e, h + 0.9, h + 1.1, 60, -3.0), true),
        ] {
            let arcs = vec![
                arc(on(&e, h + 0.01, h + 1.2, 300, 0.0)),
                arc(on(&e, h - 1.2, h - 0.01, 300, 0.0)),
                arc(third),
            ];
            let seg = segment(&e, &arcs);
            let screen = LeaveOneOutScreen::new(&seg, &arcs).unwrap();
            let mut skipped = 0;
            for slot in 0..3 {
                let (pm, pmean) = screen.predict(slot).unwrap();
                let (limit, ratio) = (params.max_arc_deviation, params.max_arc_residual_ratio);
                let skip = clearly_consistent(pm, pmean, seg.fit.residual_mean, limit, ratio);
                skipped += usize::from(skip);
                // Without a front arc, the other front arc and the short clutter arc determine
                // no ellipse: the refit fails and the slot cannot drop its arc either way.
                let Some((_, _, fit)) = refit_without_arc(&seg, &arcs, slot) else {
                    assert!(clutter && slot < 2, "slot {slot}");
                    continue;
                };
                let m = median_abs_distance(&fit.ellipse, &arcs[slot].points);
                assert!(
                    (pmean - fit.residual_mean).abs() < 0.1 * fit.residual_mean,
                    "slot {slot}: predicted mean {pmean} vs {}",
                    fit.residual_mean
                );
                assert!(
                    (pm - m).abs() < 0.25 * m.max(0.05),
                    "slot {slot}: predicted {pm} vs {m}"
                );
                let drops = seg.fit.residual_mean > ratio * fit.residual_mean && m > limit;
                assert!(
                    !(skip && drops),
                    "slot {slot}: a dropping refit was screened out"
                );
                // The clutter arc is a drop candidate; no arc of the true ellipse is.
                if !clutter || slot == 2 {
                    assert_eq!(drops, clutter, "slot {slot}");
                }
            }
            // The consistent arcs of the true ellipse need no refit at all.
            if !clutter {
                assert_eq!(skipped, 3);
            }
        }
    }
}
