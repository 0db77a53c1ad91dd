//! Pairing of the upper and lower rim of one wafer, shared-shape and joint refits, wafer
//! numbering (seed 000_3b1454b2b2194811.txt §3.2, Fig. 3.2).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;

/// Pairs upper and lower rims and numbers the wafers.
pub(super) fn pair_rims<T: Pixel>(
    image: &GrayView<'_, T>,
    candidates: Vec<Candidate>,
    up: Vector2<f64>,
    params: &DetectParams,
) -> Result<Vec<WaferEdge>> {
    let uppers: Vec<usize> = (0..candidates.len())
        .filter(|&i| candidates[i].kind == RimKind::Upper)
        .collect();
    let lowers: Vec<usize> = (0..candidates.len())
        .filter(|&i| candidates[i].kind == RimKind::Lower)
        .collect();
    let mut cost = DMatrix::from_element(uppers.len(), lowers.len(), f64::INFINITY);
    for (r, &i) in uppers.iter().enumerate() {
        for (c, &j) in lowers.iter().enumerate() {
            let (eu, el) = (
                &candidates[i].seg.fit.ellipse,
                &candidates[j].seg.fit.ellipse,
            );
            let d = Vector2::new(el.cx - eu.cx, el.cy - eu.cy);
            let (da, db) = ((el.a - eu.a).abs(), (el.b - eu.b).abs());
            let tol = params.max_rim_axis_difference;
            if d.norm() <= params.max_rim_offset
                && d.dot(&up) <= 0.0
                && da <= tol * eu.a.max(el.a) + 1.0
                && db <= tol * eu.b.max(el.b) + 1.0
            {
                cost[(r, c)] = d.norm() + da + db;
            }
        }
    }
    let miss = 2.0 * params.max_rim_offset + 10.0;
    let assignment = crate::assignment::solve_assignment_with_unassigned(
        &cost,
        &vec![miss; uppers.len()],
        &vec![miss; lowers.len()],
    )?;
    // Groups: pairs, then the unpaired rims.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut grouped = vec![false; candidates.len()];
    for (r, c) in assignment.pairs() {
        groups.push(vec![uppers[r], lowers[c]]);
        grouped[uppers[r]] = true;
        grouped[lowers[c]] = true;
    }
    for (i, g) in grouped.iter().enumerate() {
        if !g {
            groups.push(vec![i]);
        }
    }
    // Image order along `up`: topmost wafer first.
    let height = |g: &Vec<usize>| {
        let e = &candidates[g[0]].seg.fit.ellipse;
        -(e.cx * up.x + e.cy * up.y)
    };
    groups.sort_by(|x, y| height(x).total_cmp(&height(y)));
    let mut slots: Vec<Option<Candidate>> = candidates.into_iter().map(Some).collect();
    for g in &groups {
        if let [u, l] = g[..] {
            trim_close_ends(&mut slots, u, l, params);
            trim_close_ends(&mut slots, l, u, params);
            if params.share_rim_shape {
                share_shape(&mut slots, u, l, up, params);
            }
            if params.joint_band_fit {
                joint_partner(image, &mut slots, u, l, up, params);
            }
        }
    }
    let mut out = Vec::new();
    for (wafer_id, g) in groups.iter().enumerate() {
        for &i in g {
            if let Some(c) = slots[i].take() {
                let fit = c.seg.fit;
                out.push(WaferEdge {
                    ellipse: fit.ellipse,
                    points: c.seg.points.iter().map(|p| Point2::new(p.x, p.y)).collect(),
                    residual: fit.residual_mean,
                    covariance: fit.covariance,
                    kind: c.kind,
                    wafer_id,
                });
            }
        }
    }
    Ok(out)
}

/// Fraction of 36 equal sectors of eccentric angle on `e` that hold at least one of `points`.
fn angular_coverage(e: &Ellipse, points: &[Vector2<f64>]) -> f64 {
    let (s, c) = e.theta.sin_cos();
    let mut bins = [false; 36];
    for p in points {
        let (dx, dy) = (p.x - e.cx, p.y - e.cy);
        let (xl, yl) = (dx * c + dy * s, -dx * s + dy * c);
        let t = (yl / e.b).atan2(xl / e.a);
        let k = ((t + std::f64::consts::PI) / std::f64::consts::TAU * 36.0) as usize;
        if let Some(b) = bins.get_mut(k.min(35)) {
            *b = true;
        }
    }
    bins.iter().filter(|b| **b).count() as f64 / 36.0
}

/// The two rims of a wafer are images of two parallel circles one wafer thickness apart:
/// their semi-major axes differ by the relative depth change `t·sin(pitch)/depth` (≈ 0.03 %
/// for 1 mm at 0.5 m) and their orientations agree to the same order, while their minor axes
/// and centres differ visibly (the view elevation changes). One rim of a pair is usually seen
/// all round (the rim of the face turned to the camera: its back arc is a silhouette) and the
/// other only along the front arc, where `a`, `b` and the centre of a 40 % arc trade off
/// against each other. When one rim's angular coverage exceeds the other's by more than 0.15,
/// the other is refitted with `a` and `θ` fixed to the first one's
/// ([`crate::ellipse::fit_ellipse_geometric_masked`], `cx`, `cy`, `b` free), keeping the refit
/// when its mean residual is under the threshold.
///
/// With [`DetectParams::share_rim_centre`] the refit's centre is also held on the line through
/// the reference centre along `up`: the centres of the two circles' images are the images of
/// two points one thickness apart along the wafer normal, so their offset points to the
/// vanishing point of the normal, i.e. along the projected normal `up` (for a camera without
/// roll the deviation is `offset·|cx − u₀|/|v_vp − cy|`, ≲ 0.05 px for the 2 px offset of a
/// 0.8 mm wafer at 0.5 m); the free parameters are then the offset along `up` and `b`. The fit
/// runs in a frame rotated so that `up` is `(0, −1)` (an isometry: orthogonal distances are
/// unchanged) with `cx` held, and the ellipse and its covariance are rotated back.
///
/// Covariance: that of the free parameters with the held ones exact, plus the reference rim's
/// covariance of the held parameters (`a`, `θ`, and the centre's variance across `up`) on their
/// own rows and columns — a first-order account that leaves out how the free parameters move
/// with the held ones (so it is a lower bound on the coupling, not on the variances).
fn share_shape(
    slots: &mut [Option<Candidate>],
    i: usize,
    j: usize,
    up: Vector2<f64>,
    params: &DetectParams,
) {
    let cover = |slots: &[Option<Candidate>], k: usize| {
        slots.get(k).and_then(|c| c.as_ref()).map(|c| {
            (
                angular_coverage(&c.seg.fit.ellipse, &c.seg.points),
                (c.seg.fit.ellipse, c.seg.fit.covariance),
            )
        })
    };
    let (Some((ci, ei)), Some((cj, ej))) = (cover(slots, i), cover(slots, j)) else {
        return;
    };
    let (reference, target) = if ci > cj + 0.15 {
        (ei, j)
    } else if cj > ci + 0.15 {
        (ej, i)
    } else {
        return;
    };
    let Some(c) = slots.get_mut(target).and_then(|c| c.as_mut()) else {
        return;
    };
    let (reference, reference_cov) = reference;
    let fit = if params.share_rim_centre {
        shared_centre_fit(&c.seg.points, &reference, &c.seg.fit.ellipse, up).map(|mut f| {
            // The held parameters are the reference's: their variances (cx and cy for the
            // centre's component across `up`, which the rotation mixes) are added.
            if let (Some(cov), Some(rc)) = (f.covariance.as_mut(), reference_cov) {
                let across = Vector2::new(-up.y, up.x);
                let c2 = rc.fixed_view::<2, 2>(0, 0);
                let var_across = (across.transpose() * c2 * across)[0].max(0.0);
                let block = across * across.transpose() * var_across;
                for r in 0..2 {
                    for k in 0..2 {
                        cov[(r, k)] += block[(r, k)];
                    }
                }
                for (r, k) in [(2, 2), (2, 4), (4, 2), (4, 4)] {
                    cov[(r, k)] += rc[(r, k)];
                }
            }
            f
        })
    } else {
        let start = Ellipse {
            a: reference.a,
            theta: reference.theta,
            ..c.seg.fit.ellipse
        };
        crate::ellipse::fit_ellipse_geometric_masked(
            &c.seg.points,
            start,
            [true, true, false, true, false],
            &crate::ellipse::GeometricFitOptions::default(),
        )
        .ok()
        .map(|mut f| {
            if let (Some(cov), Some(rc)) = (f.covariance.as_mut(), reference_cov) {
                for (r, k) in [(2, 2), (2, 4), (4, 2), (4, 4)] {
                    cov[(r, k)] += rc[(r, k)];
                }
            }
            f
        })
    };
    if let Some(fit) = fit
        && fit.residual_mean < params.assembly.residual_threshold
    {
        c.seg.fit = fit;
    }
}

/// The fit of [`share_shape`] with the centre on the line through `reference`'s centre along
/// the unit direction `up`: `a`, `θ` of `reference`, free `b` and offset along `up`, starting
/// from `current`'s `b` and offset. `None` if the fit fails.
pub(super) fn shared_centre_fit(
    points: &[Vector2<f64>],
    reference: &Ellipse,
    current: &Ellipse,
    up: Vector2<f64>,
) -> Option<crate::ellipse::EllipseFit> {
    // R maps `up` to (0, −1): R = [[c, −s], [s, c]] with c = −up.y, s = −up.x.
    let (c, s) = (-up.y, -up.x);
    let rot = |p: &Vector2<f64>| Vector2::new(c * p.x - s * p.y, s * p.x + c * p.y);
    let unrot = |p: &Vector2<f64>| Vector2::new(c * p.x + s * p.y, -s * p.x + c * p.y);
    let phi = s.atan2(c);
    let rotated: Vec<Vector2<f64>> = points.iter().map(rot).collect();
    let rc = rot(&Vector2::new(reference.cx, reference.cy));
    let cc = rot(&Vector2::new(current.cx, current.cy));
    let start = Ellipse::new(rc.x, cc.y, reference.a, current.b, reference.theta + phi).ok()?;
    let mut fit = crate::ellipse::fit_ellipse_geometric_masked(
        &rotated,
        start,
        [false, true, false, true, false],
        &crate::ellipse::GeometricFitOptions::default(),
    )
    .ok()?;
    let e = fit.ellipse;
    let centre = unrot(&Vector2::new(e.cx, e.cy));
    fit.ellipse = Ellipse::new(centre.x, centre.y, e.a, e.b, e.theta - phi).ok()?;
    if let Some(cov) = fit.covariance {
        // d(centre)/d(centre') = Rᵀ; a, b, θ unchanged (θ shifts by a constant).
        let mut j = Matrix5::<f64>::identity();
        j[(0, 0)] = c;
        j[(0, 1)] = s;
        j[(1, 0)] = -s;
        j[(1, 1)] = c;
        fit.covariance = Some(j * cov * j.transpose());
    }
    Some(fit)
}

/// Near the ends of the visible front arc the bright side face between the two rims of a wafer
/// narrows to a few pixels; there the blurred edges of both rims push each other apart and bias
/// the fits (centre and minor axis). Drops the points of rim `i` whose distance to the other
/// rim `j`'s ellipse is under [`DetectParams::min_rim_separation`] × the largest such distance
/// and refits the rest
/// (orthogonal-distance LM from the current ellipse), keeping the refit only when enough points
/// remain and its residual is under the threshold.
fn trim_close_ends(slots: &mut [Option<Candidate>], i: usize, j: usize, params: &DetectParams) {
    let sep = params.min_rim_separation;
    if !(sep > 0.0) {
        return;
    }
    let Some(other) = slots
        .get(j)
        .and_then(|c| c.as_ref())
        .map(|c| c.seg.fit.ellipse)
    else {
        return;
    };
    let Some(c) = slots.get_mut(i).and_then(|c| c.as_mut()) else {
        return;
    };
    let dist: Vec<f64> = c
        .seg
        .points
        .iter()
        .map(|p| other.orthogonal_distance(p).abs())
        .collect();
    let widest = dist.iter().copied().fold(0.0, f64::max);
    let cut = sep * widest;
    let kept: Vec<Vector2<f64>> = c
        .seg
        .points
        .iter()
        .zip(&dist)
        .filter(|(_, d)| **d >= cut)
        .map(|(p, _)| *p)
        .collect();
    let n = c.seg.points.len();
    if kept.len() == n || kept.len() < 20 || (kept.len() as f64) < 0.5 * n as f64 {
        return;
    }
    let Ok(fit) = crate::ellipse::fit_ellipse_geometric(
        &kept,
        Some(c.seg.fit.ellipse),
        &crate::ellipse::GeometricFitOptions::default(),
    ) else {
        return;
    };
    if fit.residual_mean < params.assembly.residual_threshold {
        c.seg.points = kept;
        c.seg.fit = fit;
    }
}

/// Refits one rim of the pair `(i, j)` with [`joint::fit_partner`] against the other one, the
/// reference: the rim with the larger angular coverage when the two differ by more than 0.15
/// (as in [`share_shape`]), else (both rims seen along the front arc only) the upper rim of a
/// wafer seen from above, whose edge against the dark top face is the sharper one; the lower
/// rim is then the far edge of the side band (seen from above: the lower rim's image is the
/// rounder one); otherwise the pair is left as it is. The refit is kept
/// when it moved the rim by less than 2 px and 5 % of `b` and the rim's own points still fit it
/// (mean orthogonal distance under the residual threshold); the rim's points are kept as they
/// are and its residual is re-measured on them. Covariance: the joint fit's `(s, b)` covariance
/// mapped to `(cx, cy, b)`, plus the reference's covariance of the shared parameters (its
/// centre, `a`, `θ`).
fn joint_partner<T: Pixel>(
    image: &GrayView<'_, T>,
    slots: &mut [Option<Candidate>],
    i: usize,
    j: usize,
    up: Vector2<f64>,
    params: &DetectParams,
) {
    // A wafer seen from above has its lower rim farther below the camera than its upper rim:
    // the lower rim's image is the rounder one (b/a is the sine of the view elevation).
    let minor = |k: usize, kind: RimKind| {
        slots
            .get(k)
            .and_then(|c| c.as_ref())
            .filter(|c| c.kind == kind)
            .map(|c| c.seg.fit.ellipse.b)
    };
    let from_above = match (minor(i, RimKind::Upper), minor(j, RimKind::Lower)) {
        (Some(bu), Some(bl)) => bl > bu,
        _ => {
            matches!((minor(j, RimKind::Upper), minor(i, RimKind::Lower)), (Some(bu), Some(bl)) if bl > bu)
        }
    };
    // Per rim: coverage, whether it is the upper rim of a wafer seen from above, ellipse and
    // covariance.
    let cover = |slots: &[Option<Candidate>], k: usize| {
        slots.get(k).and_then(|c| c.as_ref()).map(|c| {
            (
                angular_coverage(&c.seg.fit.ellipse, &c.seg.points),
                c.kind == RimKind::Upper && from_above,
                (c.seg.fit.ellipse, c.seg.fit.covariance),
            )
        })
    };
    let (Some((ci, ki, ei)), Some((cj, kj, ej))) = (cover(slots, i), cover(slots, j)) else {
        return;
    };
    let ((reference, reference_cov), target) = if ci > cj + 0.15 || (ci >= cj - 0.15 && ki >= kj) {
        (ei, j)
    } else {
        (ej, i)
    };
    let Some(c) = slots.get_mut(target).and_then(|c| c.as_mut()) else {
        return;
    };
    let current = c.seg.fit.ellipse;
    let Some(fit) = joint::fit_partner(image, &reference, &current, &c.seg.points, up, 0.9) else {
        return;
    };
    let e = fit.ellipse;
    if !((e.cx - current.cx).hypot(e.cy - current.cy) < 2.0
        && (e.b - current.b).abs() < 0.05 * current.b)
    {
        return;
    }
    let d = e.orthogonal_distances(&c.seg.points);
    let n = d.len().max(1) as f64;
    let residual_mean = d.iter().map(|x| x.abs()).sum::<f64>() / n;
    if !(residual_mean < params.assembly.residual_threshold) {
        return;
    }
    let residual_rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    // (cx, cy, b) = (rcx + s·up.x, rcy + s·up.y, b): J maps (s, b).
    let mut jac = nalgebra::SMatrix::<f64, 5, 2>::zeros();
    jac[(0, 0)] = up.x;
    jac[(1, 0)] = up.y;
    jac[(3, 1)] = 1.0;
    let mut cov = jac * fit.covariance * jac.transpose();
    if let Some(rc) = reference_cov {
        for (r, k) in [
            (0, 0),
            (0, 1),
            (1, 0),
            (1, 1),
            (2, 2),
            (2, 4),
            (4, 2),
            (4, 4),
        ] {
            cov[(r, k)] += rc[(r, k)];
        }
    }
    c.seg.fit = EllipseFit {
        ellipse: e,
        residual_mean,
        residual_rms,
        covariance: Some(cov),
        iterations: 0,
        converged: true,
    };
}
