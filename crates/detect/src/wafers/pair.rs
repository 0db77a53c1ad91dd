//! Pairing of the upper and lower rim of one wafer, shared-shape and joint refits, wafer
//! numbering (seed 000_3b1454b2b2194811.txt §3.2, Fig. 3.2).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;

use super::joint_refit::{JOINT_REFIT_RESIDUAL_FACTOR, front_side, joint_covariance};
use super::rim_shared;

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
            // Only the lower rim of a wafer seen from above (the rounder one) is trimmed (see
            // `trim_close_ends`).
            let minor = |k: usize| {
                slots
                    .get(k)
                    .and_then(|c| c.as_ref())
                    .map(|c| c.seg.fit.ellipse.b)
            };
            if let (Some(bu), Some(bl)) = (minor(u), minor(l))
                && bl > bu
            {
                trim_close_ends(&mut slots, l, u, params);
            }
            if params.share_rim_shape {
                share_shape(&mut slots, u, l, up, params);
            }
            if params.joint_band_fit {
                joint_partner(image, &mut slots, u, l, up, params);
            }
            if params.share_rim_shape && params.share_rim_centre {
                refit_front_arc_pair(&mut slots, u, l, up, params);
            }
        }
    }
    let mut out = Vec::new();
    for (wafer_id, g) in groups.iter().enumerate() {
        for &i in g {
            if let Some(c) = slots[i].take() {
                // A lone rim that stands on its own (`drop_unconfirmed` keeps it): its partner
                // sought along the side band (`seek.rs`).
                let partner = (g.len() == 1
                    && params.seek_missing_partner
                    && c.seg.fit.residual_mean < params.max_unpaired_residual)
                    .then(|| super::seek::seek_partner(image, &c, up, params))
                    .flatten()
                    .map(|p| WaferEdge { wafer_id, ..p });
                let fit = c.seg.fit;
                let own = WaferEdge {
                    ellipse: fit.ellipse,
                    points: c.seg.points.iter().map(|p| Point2::new(p.x, p.y)).collect(),
                    residual: fit.residual_mean,
                    covariance: fit.covariance,
                    kind: c.kind,
                    wafer_id,
                };
                // Upper before lower.
                match partner {
                    Some(p) if p.kind == RimKind::Upper => out.extend([p, own]),
                    Some(p) => out.extend([own, p]),
                    None => out.push(own),
                }
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
///
/// [`pair_rims`] applies it only to the lower rim of a wafer seen from above (the lower rim's
/// image is then the rounder one): that rim is the far edge of the side band, and toward the
/// ends of its visible arc the outer edge of the band is the wafer's side contour rather than
/// the rim. The upper rim of such a wafer is the outline of the top face all round, its points
/// already re-located by the two-edge band model ([`refine_band_edges`]): its points near the
/// ends of the front arc are the ones that fix its centre and semi-major axis, and without them
/// the back arc's few points (some on a carrier slot tooth's edge, 0.5–1 px off the rim) weigh
/// too much. Measured with ground truth on the benchmark (210 images, seed 3; stage trace):
/// trimming the upper rims moved 8 target and 9 disturbance upper rims from within 1 px / 1 %
/// to near-misses (b +1.2 … +1.8 % and −1.1 … −2.7 %), and trimming the lower rim of a wafer
/// seen from below (the near edge there) 5 disturbance lower rims; trimming the far upper rim of
/// a wafer seen from below instead lost rims too (5 disturbance hits fewer). Recall / precision
/// (seed 3), with the joint-fit roles of [`partner_roles`]: lower rim only 0.8191 / 0.8628,
/// lower rim seen from above only 0.8249 / 0.8689; the rule before (both rims, old roles)
/// 0.7742 / 0.8155
/// (seed 7: 0.8015 / 0.8646 and 0.8029 / 0.8661; before 0.7693 / 0.8299).
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

/// Which rim of a pair is the reference of [`joint_partner`]: `Some(true)` for the first
/// (coverage `ci`, upper rim of a wafer seen from above `ki`), `Some(false)` for the second,
/// `None` to leave the pair as it is. The better covered rim when the coverages differ by more
/// than 0.15; otherwise the upper rim of a wafer seen from above (the lower rim is then the far
/// edge of the side band, the case the joint model is built for); otherwise (a wafer seen from
/// below with both rims seen along the front arc only) none. Measured on the benchmark's 210
/// images (seed 3), refitting the lower rim of such a pair against its upper rim, as the rule
/// did before for a tie between two rims neither of which is the upper rim seen from above,
/// turned 10 disturbance lower rims that were within 1 px / 1 % into near-misses
/// (b −1.3 … −3.4 %).
fn partner_roles(ci: f64, ki: bool, cj: f64, kj: bool) -> Option<bool> {
    if ci > cj + 0.15 {
        Some(true)
    } else if cj > ci + 0.15 {
        Some(false)
    } else if ki && !kj {
        Some(true)
    } else if kj && !ki {
        Some(false)
    } else {
        None
    }
}

/// Standard deviation of the position of a rim's ends along its major axis, `√(σ_a² + a²·σ_θ²)`
/// (first order in `a` and `θ`), from the covariance `cov` of `(cx, cy, a, b, θ)`: how well the
/// rim's fit determines the two parameters a joint or shared refit copies to its partner. `+∞`
/// without a covariance or when it is not finite.
fn tip_sigma(e: &Ellipse, cov: Option<&Matrix5<f64>>) -> f64 {
    cov.map(|m| (m[(2, 2)] + e.a * e.a * m[(4, 4)]).sqrt())
        .filter(|s| s.is_finite())
        .unwrap_or(f64::INFINITY)
}

/// The reference of [`joint_partner`] chosen by conditioning: when [`partner_roles`] gives the
/// pair roles (`role`: `Some(true)` for the first rim), the reference is the rim whose `a` and
/// `θ` are the better determined ([`tip_sigma`] `si`, `sj`; a tie keeps `role`), since the
/// joint model copies them to the other rim; `None` stays `None`.
///
/// Measured with ground truth on the benchmark (210 images; rule `ArcParams::inflection_sigmas`
/// = 3, which finds thin disturbance rims, b 5–10 px): the upper rim of a thin wafer seen from
/// above has its edge chain run past the tips onto the carrier's slot teeth, and its own fit
/// came out with `a` +0.7…+1.5 % (its band-refined points run 0.7–2.3 px past the tips) and,
/// on image 65 (seed 3), a tip σ of 0.34 px against its lower rim's 0.16 px (`a` +0.1 %); refit
/// against the upper rim the lower rim took its `a` (a near-miss: `a` +1.09 %, `b` +3.5 %), as
/// the reference it keeps its own fit (a hit). Seed 3 recall /
/// precision 0.8466 / 0.9000 → 0.8480 / 0.9015, seed 4 0.8279 / 0.9081 → 0.8309 / 0.9113; with
/// the rule off (default) unchanged on both seeds (0.8365 / 0.9175, 0.8147 / 0.9187).
fn reference_by_conditioning(role: Option<bool>, si: f64, sj: f64) -> Option<bool> {
    match role? {
        true if sj < si => Some(false),
        false if si < sj => Some(true),
        first => Some(first),
    }
}

/// Refits one rim of the pair `(i, j)` with [`joint::fit_partner`] against the other one, the
/// reference: the rim with the larger angular coverage when the two differ by more than 0.15
/// (as in [`share_shape`]), else (both rims seen along the front arc only) the upper rim of a
/// wafer seen from above, whose edge against the dark top face is the sharper one; the lower
/// rim is then the far edge of the side band (seen from above: the lower rim's image is the
/// rounder one); otherwise the pair is left as it is ([`partner_roles`]); of a pair with roles,
/// the rim whose `a` and `θ` are the better determined is the reference
/// ([`reference_by_conditioning`]). The refit is kept
/// when it moved the rim by less than 2 px and 5 % of `b` and the rim's own points still fit it
/// (mean orthogonal distance under the residual threshold); the rim's points are kept as they
/// are and its residual is re-measured on them (limit: [`JOINT_REFIT_RESIDUAL_FACTOR`] × the
/// assembly's residual threshold). Covariance: the joint fit's `(s, b)` covariance
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
    let from_above = seen_from_above(slots, i, j, up);
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
    let role = reference_by_conditioning(
        partner_roles(ci, ki, cj, kj),
        tip_sigma(&ei.0, ei.1.as_ref()),
        tip_sigma(&ej.0, ej.1.as_ref()),
    );
    let ((reference, reference_cov), target) = match role {
        Some(true) => (ei, j),
        Some(false) => (ej, i),
        None => return,
    };
    let Some(c) = slots.get_mut(target).and_then(|c| c.as_mut()) else {
        return;
    };
    let current = c.seg.fit.ellipse;
    // The offset prior (`rim_prior.rs`), for the lower rim of a wafer seen from above only (the
    // view its perspective error was measured for): its centre lies `offset` against `up` from
    // the upper rim's.
    let prior = params
        .rim_offset
        .filter(|_| from_above && c.kind == RimKind::Lower)
        .map(|p| joint::OffsetPrior {
            mean: -p.offset(reference.a),
            sigma: p.sigma(reference.a),
        });
    let Some(fit) = joint::fit_partner(
        image,
        &reference,
        &current,
        &c.seg.points,
        up,
        0.9,
        prior,
        joint::MAX_FAR_SIDE_STEP,
    ) else {
        return;
    };
    let e = fit.ellipse;
    if !near_own_fit(&e, &current) {
        return;
    }
    take_refit(
        c,
        e,
        joint_covariance(&fit, up, reference_cov.as_ref()),
        JOINT_REFIT_RESIDUAL_FACTOR * params.assembly.residual_threshold,
    );
}

/// Whether the wafer of the rim pair in slots `(i, j)` (one upper, one lower, either order) is
/// seen from above: its rims' points lie, on balance, on the side of their centres against `up`
/// ([`front_side`] summed over both rims; a rim seen all round contributes ≈ 0, a front arc seen
/// from above ≈ −0.8, one seen from below ≈ +0.8). This reads the view off where the rims are
/// seen, not off their fitted minor axes: b/a is the sine of the view elevation and the lower
/// rim of a wafer seen from above is the rounder one, but the two minor axes differ by only
/// 1–3 % (0.3–1 px), as much as the error of a front-arc fit, so comparing them flipped the view
/// of 6 target wafers of the benchmark (210 images, seed 3) whose lower rim's `b` came out
/// 1.9–3.9 % low, and those then got no joint fit. `false` when the pair is not one upper and
/// one lower rim.
fn seen_from_above(slots: &[Option<Candidate>], i: usize, j: usize, up: Vector2<f64>) -> bool {
    let (u, l) = if rim(slots, i, RimKind::Upper).is_some() {
        (i, j)
    } else {
        (j, i)
    };
    let get =
        |k: usize, kind: RimKind| rim(slots, k, kind).map(|c| (c.seg.fit.ellipse, &c.seg.points));
    match (get(u, RimKind::Upper), get(l, RimKind::Lower)) {
        (Some((eu, pu)), Some((el, pl))) => view_from_above(&eu, pu, &el, pl, up),
        _ => false,
    }
}

/// The rule of [`seen_from_above`] for an upper rim `eu` (points `pu`) and a lower rim `el`
/// (points `pl`).
fn view_from_above(
    eu: &Ellipse,
    pu: &[Vector2<f64>],
    el: &Ellipse,
    pl: &[Vector2<f64>],
    up: Vector2<f64>,
) -> bool {
    front_side(eu, pu, up) + front_side(el, pl, up) < 0.0
}

/// The candidate in slot `k` if it is a rim of kind `kind`.
fn rim(slots: &[Option<Candidate>], k: usize, kind: RimKind) -> Option<&Candidate> {
    slots
        .get(k)
        .and_then(|c| c.as_ref())
        .filter(|c| c.kind == kind)
}

/// Whether a refit `e` of a rim stays within 2 px (centre) and 5 % of `b` of the rim's own fit
/// `own`: a shared or joint model that moves a rim farther does not describe it.
fn near_own_fit(e: &Ellipse, own: &Ellipse) -> bool {
    (e.cx - own.cx).hypot(e.cy - own.cy) < 2.0 && (e.b - own.b).abs() < 0.05 * own.b
}

/// Gives rim `c` the refitted ellipse `e` (covariance `covariance`) when its own points still
/// fit it (mean orthogonal distance under `gate` pixels: the assembly's residual threshold, or
/// [`JOINT_REFIT_RESIDUAL_FACTOR`] times it for a joint band refit); the points are kept as they
/// are and the residuals re-measured on them.
fn take_refit(c: &mut Candidate, e: Ellipse, covariance: Matrix5<f64>, gate: f64) {
    let d = e.orthogonal_distances(&c.seg.points);
    let n = d.len().max(1) as f64;
    let residual_mean = d.iter().map(|x| x.abs()).sum::<f64>() / n;
    if !(residual_mean < gate) {
        return;
    }
    let residual_rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    c.seg.fit = EllipseFit {
        ellipse: e,
        residual_mean,
        residual_rms,
        covariance: Some(covariance),
        iterations: 0,
        converged: true,
    };
}

/// Refits the lower rim `l` of the pair `(u, l)` with [`rim_shared::fit_rim_pair`] (both rims'
/// points, shared `a`, `θ` and centre line along `up`) when the wafer is seen from below (its
/// rims' points lie on the `up` side of their centres, [`front_side`]) and neither rim is seen
/// beyond its front arc (angular coverages within 0.15 of each other, the case
/// [`partner_roles`] leaves alone). The refit is kept when it moved the rim by less than 2 px
/// and 5 % of `b` and its own points still fit it (mean orthogonal distance under the residual
/// threshold), and the shared fit's upper rim is as near its own fit (else the shared model does
/// not describe the pair); the rim's points are kept and its residual is re-measured on them; its
/// covariance is the shared fit's, mapped to the lower rim ([`RimPairFit::lower_covariance`]).
///
/// The upper rim keeps its own fit. Measured with the simulator's truth on the benchmark's 210
/// images (seed 3): these are disturbance wafers above the camera, both rims seen along the
/// front arc only; the lower rim's own fit had `a` 0.3–1.5 % and `b` 1–4.5 % too large (19
/// near-misses), and the shared fit turned 8 of them into hits (1 px / 1 %) and lost none; taking
/// the upper rim from the shared fit too moved 7 upper rims that were hits to `b` +1.5…+2.7 %
/// (recall 0.8249 → 0.8365 lower only, 0.8263 both).
///
/// [`RimPairFit::lower_covariance`]: rim_shared::RimPairFit::lower_covariance
fn refit_front_arc_pair(
    slots: &mut [Option<Candidate>],
    u: usize,
    l: usize,
    up: Vector2<f64>,
    params: &DetectParams,
) {
    let get =
        |k: usize, kind: RimKind| rim(slots, k, kind).map(|c| (c.seg.fit.ellipse, &c.seg.points));
    let (Some((eu, pu)), Some((el, pl))) = (get(u, RimKind::Upper), get(l, RimKind::Lower)) else {
        return;
    };
    let from_below = front_side(&eu, pu, up) + front_side(&el, pl, up) > 0.0;
    let tie = (angular_coverage(&eu, pu) - angular_coverage(&el, pl)).abs() <= 0.15;
    if !(from_below && tie) {
        return;
    }
    let Some(fit) = rim_shared::fit_rim_pair(pu, pl, &eu, &el, up) else {
        return;
    };
    // Both rims must stay near their own fits, else the shared model does not describe the pair.
    if !(near_own_fit(&fit.upper, &eu) && near_own_fit(&fit.lower, &el)) {
        return;
    }
    if let Some(c) = slots.get_mut(l).and_then(|c| c.as_mut()) {
        take_refit(
            c,
            fit.lower,
            fit.lower_covariance(),
            params.assembly.residual_threshold,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::render::Rim;

    /// The values the generator of `benchmarks/wafer_detection.py` drew for one scene: camera
    /// position `(x, y, z)` (metres, `z` above the target slot), yaw and pitch-down (degrees),
    /// gain, lighting gradient and noise seed.
    type Scenario = (f64, f64, f64, f64, f64, f64, [f64; 2], u64);

    /// Benchmark image 3 (seed 3; disturbance 4 slots above, above the camera).
    const IMAGE_3: Scenario = (
        -0.48872974352636195,
        0.027327700964881643,
        0.02151730038312356,
        1.2417905739337414,
        6.871219167392354,
        0.5908527135042578,
        [0.0963000404567369, 0.2588783128448127],
        2513255689,
    );

    /// Renders one benchmark scene (target in slot 5, a disturbance `k` slots above, 10 mm
    /// pitch) and detects its rims. Returns the detections and the renderer's true ellipses
    /// `(wafer, rim, ellipse)`.
    fn benchmark_scene(k: usize, s: Scenario) -> (Vec<WaferEdge>, Vec<(usize, Rim, Ellipse)>) {
        benchmark_scene_with(k, s, &DetectParams::default())
    }

    /// [`benchmark_scene`] with `params`.
    fn benchmark_scene_with(
        k: usize,
        s: Scenario,
        params: &DetectParams,
    ) -> (Vec<WaferEdge>, Vec<(usize, Rim, Ellipse)>) {
        let (x, y, z, yaw, down, gain, gradient, seed) = s;
        let (data, w, h, rims) =
            super::super::tests::benchmark_scene(k, (x, y, z), yaw, down, gain, gradient, seed);
        let view = GrayView::new(&data, w, h).unwrap();
        let dets = detect_wafers(&view, params).unwrap();
        let truth = rims.into_iter().map(|(w, r, e, _)| (w, r, e)).collect();
        (dets, truth)
    }

    /// The benchmark's rule: centre within 1 px, both semi-axes within 1 %.
    fn assert_found(
        dets: &[WaferEdge],
        truth: &[(usize, Rim, Ellipse)],
        wafer: usize,
        rim: Rim,
        what: &str,
    ) {
        let e = truth
            .iter()
            .find(|t| t.0 == wafer && t.1 == rim)
            .map(|t| t.2)
            .unwrap();
        let hit = dets
            .iter()
            .any(|d| super::super::tests::matches_rim(d, rim, &e, 1.0, 0.01, 0.01));
        assert!(
            hit,
            "{what}: wafer {wafer} {rim:?} {e:?} not within 1 px / 1 % in {dets:#?}"
        );
    }

    #[test]
    fn lower_rims_whose_a_differs_from_the_reference_are_recovered() {
        // Benchmark images whose target lower rim, with the reference's `a` copied, traded its
        // offset against `b` (a near-miss, `b` 1.0–1.2 % off): seed 3 image 129, seed 4 images
        // 54 and 178 (clipped band). The joint fit's `δa` (`joint::PARTNER_A_SIGMA`) takes the
        // ends of the front arc.
        for (what, k, s) in [
            (
                "seed 3 image 129",
                10,
                (
                    -0.5425593708144107,
                    -0.006148618808287411,
                    0.030857929249103223,
                    1.351070569232192,
                    8.05799942486017,
                    1.4362948917973783,
                    [0.11351282875031143, -0.14958753277998607],
                    1544779414,
                ),
            ),
            (
                "seed 4 image 54",
                15,
                (
                    -0.5030461006486473,
                    -0.04966215426675306,
                    0.042951513712110596,
                    1.0524040012485862,
                    6.000336714710295,
                    0.6827729717822332,
                    [-0.08181234281486363, 0.23904915098535068],
                    1786864036,
                ),
            ),
            (
                "seed 4 image 178",
                19,
                (
                    -0.5454966571293337,
                    0.01759327356602486,
                    0.025172591018541485,
                    -0.3195808803439739,
                    7.609333271056408,
                    1.2957522492957196,
                    [-0.05091365021067318, -0.23712297737600935],
                    708666406,
                ),
            ),
        ] {
            let (dets, truth) = benchmark_scene(k, s);
            assert_found(&dets, &truth, 0, Rim::Lower, what);
            assert_found(&dets, &truth, 0, Rim::Upper, what);
        }
    }

    #[test]
    fn partner_roles_follow_coverage_then_view() {
        assert_eq!(partner_roles(0.9, false, 0.5, true), Some(true));
        assert_eq!(partner_roles(0.5, true, 0.9, false), Some(false));
        assert_eq!(partner_roles(0.5, true, 0.45, false), Some(true));
        assert_eq!(partner_roles(0.45, false, 0.5, true), Some(false));
        // A wafer seen from below, both rims along the front arc only: left as it is.
        assert_eq!(partner_roles(0.5, false, 0.45, false), None);
        assert_eq!(partner_roles(0.45, false, 0.5, false), None);
    }

    /// Benchmark image 146, seed 3: a target wafer seen from above (the camera 5 cm above it)
    /// whose rims are both seen along the front arc mainly (coverages 0.50 and 0.64, a tie for
    /// [`partner_roles`]). The rims' own fits (no joint fit) have the lower rim's `b` under the
    /// upper rim's — comparing them called the wafer seen from below, and it got no joint fit;
    /// where the rims' points lie ([`view_from_above`]) says from above. The disturbance wafer
    /// of benchmark image 3 (above the camera, seen from below) is called so.
    #[test]
    fn view_is_read_from_where_the_rims_are_seen_not_from_their_minor_axes() {
        let pair = |k, s: Scenario, wafer_kind: usize| {
            let (x, y, z, yaw, down, gain, gradient, seed) = s;
            let (data, w, h, rims) =
                super::super::tests::benchmark_scene(k, (x, y, z), yaw, down, gain, gradient, seed);
            let view = GrayView::new(&data, w, h).unwrap();
            let params = DetectParams {
                joint_band_fit: false,
                ..DetectParams::default()
            };
            let dets = detect_wafers(&view, &params).unwrap();
            let truth = |rim: Rim| {
                rims.iter()
                    .find(|t| t.0 == wafer_kind && t.1 == rim)
                    .map(|t| t.2)
                    .unwrap()
            };
            let find = |rim: Rim| {
                let e = truth(rim);
                dets.iter()
                    .find(|d| super::super::tests::matches_rim(d, rim, &e, 3.0, 0.05, 0.05))
                    .map(|d| {
                        let pts: Vec<Vector2<f64>> =
                            d.points.iter().map(|p| Vector2::new(p.x, p.y)).collect();
                        (d.ellipse, pts)
                    })
                    .unwrap()
            };
            (find(Rim::Upper), find(Rim::Lower))
        };
        let up = Vector2::new(0.0, -1.0);
        let ((eu, pu), (el, pl)) = pair(
            7,
            (
                -0.4497423255503169,
                -0.020169922510899187,
                0.05011292818882443,
                1.6906696185250647,
                6.696811423945695,
                0.5318927948541543,
                [-0.2990387049380343, 0.17360943225992198],
                2879535493,
            ),
            0,
        );
        assert!(
            el.b < eu.b,
            "image 146: the minor axes no longer mislead: {eu:?} {el:?}"
        );
        assert!(view_from_above(&eu, &pu, &el, &pl, up), "image 146");
        let ((eu, pu), (el, pl)) = pair(4, IMAGE_3, 1);
        assert!(!view_from_above(&eu, &pu, &el, &pl, up), "image 3");
    }

    /// Benchmark images 56 and 93, seed 3: target wafers seen from above whose lower rim (the
    /// far edge of the side band) the joint band fit alone leaves at `b` −1.27 % (image 56, with
    /// the far-side screen of `joint.rs`) and left at −1.17 % before that screen (image 93):
    /// the offset along `up` and `b` trade off at the ends of the front arc. With the offset
    /// prior of the renderer's wafer (1 mm thick, 150 mm radius: `t/R` = 1/150) and the
    /// benchmark camera's focal length (1000 px) both lower rims are within 1 px / 1 %. (Image
    /// 106, this test's first image before the far-side screen, has a clipped band: its lower
    /// rim went from `b` +0.98 % to +1.10 % with the prior when the screen came in.)
    #[test]
    fn offset_prior_pins_the_lower_rim_of_a_wafer_seen_from_above() {
        let params = DetectParams {
            rim_offset: Some(RimOffsetPrior {
                thickness_ratio: 0.001 / 0.150,
                focal_length: 1000.0,
                principal_point: None,
            }),
            ..DetectParams::default()
        };
        for (what, k, s) in [
            (
                "image 56",
                17,
                (
                    -0.4780911365701077,
                    0.04096762530949988,
                    0.05503014697972426,
                    -1.3141524305174141,
                    8.2429166969731,
                    0.6193955851213215,
                    [-0.0006631933354358521, -0.14206975841335132],
                    3120300780,
                ),
            ),
            (
                "image 93",
                14,
                (
                    -0.49299830047038806,
                    -0.02023804503614586,
                    0.05626041231316177,
                    0.8256314660152717,
                    5.358307195531723,
                    0.7992901910534789,
                    [-0.1997063240449976, -0.002732079848713709],
                    2515536331,
                ),
            ),
        ] {
            let (x, y, z, yaw, down, gain, gradient, seed) = s;
            let (data, w, h, rims) =
                super::super::tests::benchmark_scene(k, (x, y, z), yaw, down, gain, gradient, seed);
            let view = GrayView::new(&data, w, h).unwrap();
            let dets = detect_wafers(&view, &params).unwrap();
            let truth = rims
                .into_iter()
                .map(|(w, r, e, _)| (w, r, e))
                .collect::<Vec<_>>();
            assert_found(&dets, &truth, 0, Rim::Lower, what);
            assert_found(&dets, &truth, 0, Rim::Upper, what);
        }
    }

    #[test]
    fn reference_is_the_better_conditioned_rim_of_a_pair_with_roles() {
        assert_eq!(reference_by_conditioning(Some(true), 0.3, 0.1), Some(false));
        assert_eq!(reference_by_conditioning(Some(true), 0.1, 0.3), Some(true));
        assert_eq!(reference_by_conditioning(Some(false), 0.1, 0.3), Some(true));
        assert_eq!(
            reference_by_conditioning(Some(false), 0.3, 0.1),
            Some(false)
        );
        // Ties and missing covariances keep the roles; no roles stays no roles.
        assert_eq!(
            reference_by_conditioning(Some(false), 0.2, 0.2),
            Some(false)
        );
        assert_eq!(
            reference_by_conditioning(Some(true), f64::INFINITY, f64::INFINITY),
            Some(true)
        );
        assert_eq!(reference_by_conditioning(None, 0.3, 0.1), None);
        // σ of the tips: √(σ_a² + a²σ_θ²); no (or a non-finite) covariance is +∞.
        let e = Ellipse::new(0.0, 0.0, 300.0, 10.0, 0.0).unwrap();
        let mut cov = Matrix5::<f64>::zeros();
        cov[(2, 2)] = 0.09;
        cov[(4, 4)] = (0.4f64 / 300.0).powi(2);
        assert!((tip_sigma(&e, Some(&cov)) - 0.5).abs() < 1e-12);
        assert_eq!(tip_sigma(&e, None), f64::INFINITY);
        cov[(2, 2)] = f64::NAN;
        assert_eq!(tip_sigma(&e, Some(&cov)), f64::INFINITY);
    }

    /// Benchmark image 65, seed 3, with `ArcParams::inflection_sigmas` = 3: a thin disturbance
    /// wafer (b ≈ 7–8 px) seen from above, both rims along the front arc only. Its upper rim's
    /// own fit has `a` +1.05 % (tip σ 0.34 px), its lower rim's +0.13 % (0.16 px); with the
    /// upper rim as the joint fit's reference (the view rule alone) the lower rim took its `a`
    /// and was a near-miss (`a` +1.09 %, `b` +3.5 %); chosen by conditioning
    /// ([`reference_by_conditioning`]) the lower rim is the reference and within 1 px / 1 %.
    #[test]
    fn joint_fit_reference_is_the_better_conditioned_rim() {
        let (data, w, h, rims) = super::super::tests::benchmark_scene(
            6,
            (
                -0.44806472914135775,
                0.01397790093460538,
                0.06863822820913892,
            ),
            -0.15138645862105005,
            9.265992778210911,
            1.321817588561834,
            [0.05202649397102094, 0.003805290843493181],
            2275528539,
        );
        let view = GrayView::new(&data, w, h).unwrap();
        let mut params = DetectParams::default();
        params.arcs.inflection_sigmas = 3.0;
        let dets = detect_wafers(&view, &params).unwrap();
        let truth: Vec<(usize, Rim, Ellipse)> =
            rims.into_iter().map(|(w, r, e, _)| (w, r, e)).collect();
        assert_found(&dets, &truth, 1, Rim::Lower, "image 65");
    }

    /// Benchmark images 202 (target upper rim) and 164 (disturbance upper rim), seed 3: with
    /// the upper rim trimmed by `trim_close_ends` their minor axes were off by +1.81 % and
    /// −1.76 % (near-misses); untrimmed, +0.11 % and +0.08 %. (The thin disturbance rim of image
    /// 164, b ≈ 9 px along the front arc only, has a standard deviation of `b` of 0.59 % of `b`
    /// from its fit and is dropped by the default `max_relative_sigma_b`: its fit is checked
    /// with that test off.)
    #[test]
    fn upper_rims_keep_their_points_near_the_ends_of_the_front_arc() {
        let (dets, truth) = benchmark_scene(
            3,
            (
                -0.4556736037009983,
                0.020027790409608504,
                0.0324012128091943,
                -2.8123982513937715,
                8.717924285334124,
                1.4782937847386552,
                [-0.22158947814237367, 0.2901817030783746],
                2530503124,
            ),
        );
        assert_found(&dets, &truth, 0, Rim::Upper, "image 202");
        let (dets, truth) = benchmark_scene_with(
            5,
            (
                -0.511389048509057,
                0.031134867391389903,
                0.036420462664987226,
                -1.4118049838374738,
                7.386529171965108,
                0.9054343139357517,
                [0.27486913828129195, 0.23941915311242962],
                2770340650,
            ),
            &DetectParams {
                max_relative_sigma_b: f64::INFINITY,
                ..DetectParams::default()
            },
        );
        assert_found(&dets, &truth, 1, Rim::Upper, "image 164");
    }

    /// Benchmark images 87 and 103, seed 3: disturbance wafers seen from below. With their lower
    /// rim (the near edge there) trimmed by `trim_close_ends`, b was off by +1.65 % and +1.23 %
    /// (near-misses); untrimmed, +0.27 % and +0.58 %.
    #[test]
    fn lower_rim_of_a_wafer_seen_from_below_is_not_trimmed() {
        let (dets, truth) = benchmark_scene(
            8,
            (
                -0.46593878656019727,
                -0.011484691342305196,
                0.06730416333993018,
                -2.572005097706816,
                6.802864841164729,
                1.2674501184822347,
                [-0.06466245702859719, -0.022518481938991475],
                504927809,
            ),
        );
        assert_found(&dets, &truth, 1, Rim::Lower, "image 87");
        let (dets, truth) = benchmark_scene(
            4,
            (
                -0.43610780187106046,
                0.022261981000538084,
                0.02534691218840245,
                -0.3161589207127813,
                8.78655278743248,
                1.054029558743697,
                [-0.2647372453066521, 0.15832066022769892],
                4201362658,
            ),
        );
        assert_found(&dets, &truth, 1, Rim::Lower, "image 103");
    }

    /// Benchmark image 3, seed 3, and the camera and lighting of benchmark image 63 with the
    /// disturbance wafer 5 slots above the target (image 63 itself has it 4 slots above):
    /// disturbance wafers above the camera (seen from below), both rims seen along the front arc
    /// only. The lower rim's own fit had `a` +1.07 %
    /// and +0.82 %, `b` +3.05 % and +3.07 % (near-misses); the shared fit of both rims
    /// ([`refit_front_arc_pair`]) brings both within 1 px / 1 %, and the upper rims stay hits.
    #[test]
    fn lower_rim_of_a_front_arc_pair_seen_from_below_is_fitted_with_its_upper_rim() {
        for (what, k, s) in [
            ("image 3", 4, IMAGE_3),
            (
                "image 63's camera, k = 5",
                5,
                (
                    -0.5494853343534937,
                    0.028933117966190566,
                    0.02375913851535775,
                    -2.7627343084874805,
                    9.830202924314332,
                    1.0167395803716541,
                    [0.25725036209038504, 0.2382549816426625],
                    2064011278,
                ),
            ),
        ] {
            let (dets, truth) = benchmark_scene(k, s);
            assert_found(&dets, &truth, 1, Rim::Lower, what);
            assert_found(&dets, &truth, 1, Rim::Upper, what);
            // The refitted rim carries the shared fit's covariance: positive variances, with the
            // minor axis determined to a fraction of the 1 % tolerance.
            let lower = dets
                .iter()
                .filter(|d| d.kind == RimKind::Lower)
                .min_by(|x, y| {
                    let t = truth
                        .iter()
                        .find(|t| t.0 == 1 && t.1 == Rim::Lower)
                        .unwrap()
                        .2;
                    let dist = |d: &WaferEdge| (d.ellipse.cx - t.cx).hypot(d.ellipse.cy - t.cy);
                    dist(x).total_cmp(&dist(y))
                })
                .unwrap();
            let cov = lower.covariance.unwrap();
            assert!((0..5).all(|i| cov[(i, i)] > 0.0), "{what}: {cov}");
            assert!(
                cov[(3, 3)].sqrt() < 0.005 * lower.ellipse.b,
                "{what}: σ_b {}",
                cov[(3, 3)].sqrt()
            );
        }
    }

    /// Benchmark images 28 and 86, seed 3: disturbance wafers seen from below with both rims
    /// along the front arc only. Refitting the lower rim against the upper one by the joint band
    /// model gave b −2.98 % and −1.34 % (near-misses); left as it is, +0.46 % and +0.14 %.
    #[test]
    fn lower_rim_of_a_wafer_seen_from_below_is_not_refit_against_its_upper_rim() {
        let (dets, truth) = benchmark_scene(
            9,
            (
                -0.532491578187832,
                0.012486874884693314,
                0.06462761644052728,
                -1.798347720494136,
                7.073706085378962,
                1.213155187563605,
                [0.14286155754266505, -0.029293303992410313],
                641603352,
            ),
        );
        assert_found(&dets, &truth, 1, Rim::Lower, "image 28");
        let (dets, truth) = benchmark_scene(
            7,
            (
                -0.4560212902567305,
                0.043300705759804575,
                0.04921475461913303,
                -2.979296689897285,
                6.632017561571265,
                1.240524705442664,
                [-0.09437970001231469, 0.09477306299654287],
                2561372883,
            ),
        );
        assert_found(&dets, &truth, 1, Rim::Lower, "image 86");
    }
}
