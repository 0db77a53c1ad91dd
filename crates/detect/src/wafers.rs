//! Wafer rims: detection of the elliptic edge segments of wafers in an image, pairing of the
//! upper and lower rim of one wafer, rejection of reflections (seed 000_3b1454b2b2194811.txt
//! ch. 3.1–3.2, 3.5).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Point2};

/// Which surface of a wafer an elliptic edge segment belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RimKind {
    /// The rim of the upper surface of the wafer.
    Upper,
    /// The rim of the lower surface of the wafer.
    Lower,
}

impl RimKind {
    /// `"upper"` or `"lower"`.
    pub fn as_str(self) -> &'static str {
        match self {
            RimKind::Upper => "upper",
            RimKind::Lower => "lower",
        }
    }
}

/// One detected elliptic edge segment of a wafer rim.
#[derive(Debug, Clone, PartialEq)]
pub struct WaferEdge {
    /// The fitted ellipse (pixels).
    pub ellipse: Ellipse,
    /// The edge points that support it (pixels, (u, v)).
    pub points: Vec<Point2<f64>>,
    /// Mean orthogonal distance of the points to the ellipse (pixels).
    pub residual: f64,
    /// Covariance of (cx, cy, a, b, theta), when the fit provides it.
    pub covariance: Option<Matrix5<f64>>,
    /// Upper or lower rim.
    pub kind: RimKind,
    /// Groups the two rims of one wafer within one image (0, 1, … in image order).
    pub wafer_id: usize,
}

use crate::assembly::{AssemblyParams, Segment, assemble};
use crate::edges::{ArcParams, CannyParams, GrayView, LinkParams, Pixel, detect_arcs};
use crate::{DetectError, Result};
use nalgebra::{DMatrix, Vector2};

/// Optional prior on the wafer rims in the image (for example from the expected wafer radius
/// and a rough camera pose): fitted ellipses outside these ranges are rejected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaferPrior {
    /// Accepted range of the semi-major axis (pixels).
    pub semi_major: (f64, f64),
    /// Accepted range of the semi-minor axis (pixels).
    pub semi_minor: (f64, f64),
}

/// Parameters of [`detect_wafers`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectParams {
    /// Edge detection.
    pub canny: CannyParams,
    /// Edge linking.
    pub link: LinkParams,
    /// Arc splitting and screening.
    pub arcs: ArcParams,
    /// Algorithms 1–2.
    pub assembly: AssemblyParams,
    /// Image direction (need not be unit) in which the wafer's upper surface lies relative to
    /// its lower surface, i.e. the projected wafer normal: `(0, −1)` (up in the image) for an
    /// upright camera. It decides which rim is "upper".
    pub up: [f64; 2],
    /// Largest distance (pixels) between the centres of the upper and lower rim of one wafer.
    /// Default 10.
    pub max_rim_offset: f64,
    /// Largest relative difference of the semi-axes of the two rims of one wafer. Default 0.03.
    pub max_rim_axis_difference: f64,
    /// A segment whose edge contrast is under this fraction of the strongest contrast among
    /// the rims of about the same size (semi-major within 10 %) is taken for a reflection of a
    /// neighbouring wafer in a mirror-like wafer face and rejected. 0 disables. Default 0.45.
    pub min_contrast_ratio: f64,
    /// Smallest fraction of the fitted ellipse's perimeter covered by the segment's arcs (the
    /// validation stage of §3.2: a fit supported by too little of its ellipse is a chance
    /// alignment, e.g. of two straight-ish clutter arcs). Default 0.15.
    pub min_coverage: f64,
    /// Rim points whose distance to the other rim of their wafer is under this fraction of the
    /// widest distance are dropped and the rim refitted: where the bright side face between the
    /// rims narrows toward the ends of the front arc, the blurred edges of the two rims push
    /// each other apart and bias the fit. 0 disables. Default 0.5.
    pub min_rim_separation: f64,
    /// Optional size prior.
    pub prior: Option<WaferPrior>,
}

impl Default for DetectParams {
    fn default() -> Self {
        Self {
            canny: CannyParams::default(),
            link: LinkParams::default(),
            arcs: ArcParams::default(),
            assembly: AssemblyParams::default(),
            up: [0.0, -1.0],
            max_rim_offset: 10.0,
            max_rim_axis_difference: 0.03,
            min_contrast_ratio: 0.45,
            min_coverage: 0.15,
            min_rim_separation: 0.5,
            prior: None,
        }
    }
}

impl DetectParams {
    fn validate(&self) -> Result<Vector2<f64>> {
        let up = Vector2::new(self.up[0], self.up[1]);
        let n = up.norm();
        if !(n > 0.0 && n.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what: "up",
                value: n,
                reason: "must be a finite non-zero direction",
            });
        }
        for (what, value) in [
            ("max_rim_offset", self.max_rim_offset),
            ("max_rim_axis_difference", self.max_rim_axis_difference),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "must be positive and finite",
                });
            }
        }
        if !(self.min_coverage >= 0.0 && self.min_coverage <= 1.0) {
            return Err(DetectError::InvalidParameter {
                what: "min_coverage",
                value: self.min_coverage,
                reason: "must be in [0, 1]",
            });
        }
        if !(self.min_rim_separation >= 0.0 && self.min_rim_separation < 1.0) {
            return Err(DetectError::InvalidParameter {
                what: "min_rim_separation",
                value: self.min_rim_separation,
                reason: "must be in [0, 1)",
            });
        }
        if !(self.min_contrast_ratio >= 0.0 && self.min_contrast_ratio <= 1.0) {
            return Err(DetectError::InvalidParameter {
                what: "min_contrast_ratio",
                value: self.min_contrast_ratio,
                reason: "must be in [0, 1]",
            });
        }
        if let Some(p) = &self.prior {
            for (what, (lo, hi)) in [
                ("prior semi_major", p.semi_major),
                ("prior semi_minor", p.semi_minor),
            ] {
                if !(lo >= 0.0 && hi >= lo && hi.is_finite()) {
                    return Err(DetectError::InvalidParameter {
                        what,
                        value: lo,
                        reason: "must be a range 0 <= low <= high < inf",
                    });
                }
            }
        }
        Ok(up / n)
    }
}

/// A validated rim candidate.
struct Candidate {
    seg: Segment,
    kind: RimKind,
    contrast: f64,
}

/// Detects the elliptic edge segments of wafer rims in a grayscale image
/// (000_3b1454b2b2194811.txt ch. 3.2, Fig. 3.3, validated in ch. 3.5).
///
/// 1. Arcs: [`crate::edges::detect_arcs`] (Canny with sub-pixel edgels, linking, splitting,
///    short/straight/curvature rejection, quadrant classes).
/// 2. Elliptic segments: [`crate::assembly::assemble`] (combination rule, Algorithms 1–2).
/// 3. Validation: each segment is refitted (orthogonal-distance LM, with covariance) and
///    checked against the residual threshold and the optional [`WaferPrior`].
/// 4. Rims (§3.2, Fig. 3.2: "the bright boundary of the wafer forms two edges: an upper one
///    corresponding to the upper surface and lower one corresponding to the lower surface"):
///    the bright side face lies below the upper rim and above the lower rim, so a segment whose
///    gradient (dark → bright) points against `up` is an upper rim, otherwise a lower rim.
///    Reflections of neighbouring wafers in the mirror-like faces have a fraction of the rim
///    contrast and are rejected (`min_contrast_ratio`). Upper and lower rims are paired by a
///    minimum-cost assignment (centre offset + axis differences, the lower rim's centre
///    displaced against `up`, within `max_rim_offset` and `max_rim_axis_difference`); the two
///    rims of a pair share a `wafer_id`, unpaired rims get their own. Wafer ids are numbered in
///    image order along `up` (topmost first), upper before lower.
///
/// Returns an empty list when nothing is found (blank, black or saturated images).
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters (image errors are caught by
/// [`GrayView::new`]).
pub fn detect_wafers<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &DetectParams,
) -> Result<Vec<WaferEdge>> {
    let up = params.validate()?;
    let arcs = detect_arcs(image, &params.canny, &params.link, &params.arcs)?;
    let segments = assemble(&arcs, &params.assembly)?;
    let mut candidates = Vec::new();
    for seg in segments {
        // The assembly's fit of the union is the final estimate (with its covariance).
        let fit = seg.fit.clone();
        if !(fit.residual_mean < params.assembly.residual_threshold) {
            continue;
        }
        if let Some(p) = &params.prior {
            let e = &fit.ellipse;
            if e.a < p.semi_major.0
                || e.a > p.semi_major.1
                || e.b < p.semi_minor.0
                || e.b > p.semi_minor.1
            {
                continue;
            }
        }
        let covered: f64 = seg
            .arcs
            .iter()
            .map(|&k| {
                arcs[k]
                    .points
                    .windows(2)
                    .map(|w| (w[1] - w[0]).norm())
                    .sum::<f64>()
            })
            .sum();
        if !(covered >= params.min_coverage * fit.ellipse.perimeter()) {
            continue;
        }
        let mut s = 0.0;
        let mut contrast = 0.0;
        let mut count = 0usize;
        for &k in &seg.arcs {
            let arc = &arcs[k];
            s += arc.normals.iter().map(|n| -n.dot(&up)).sum::<f64>();
            contrast += arc.contrast * arc.points.len() as f64;
            count += arc.points.len();
        }
        let kind = if s > 0.0 {
            RimKind::Upper
        } else {
            RimKind::Lower
        };
        candidates.push(Candidate {
            seg,
            kind,
            contrast: contrast / count.max(1) as f64,
        });
    }
    reject_reflections(&mut candidates, params.min_contrast_ratio);
    pair_rims(candidates, up, params)
}

/// Drops candidates whose contrast is under `ratio` × the strongest contrast among candidates
/// with a semi-major axis within 10 %.
fn reject_reflections(candidates: &mut Vec<Candidate>, ratio: f64) {
    if ratio <= 0.0 {
        return;
    }
    let keep: Vec<bool> = candidates
        .iter()
        .map(|c| {
            let a = c.seg.fit.ellipse.a;
            let strongest = candidates
                .iter()
                .filter(|o| (o.seg.fit.ellipse.a - a).abs() <= 0.1 * a)
                .map(|o| o.contrast)
                .fold(0.0, f64::max);
            c.contrast >= ratio * strongest
        })
        .collect();
    let mut k = 0;
    candidates.retain(|_| {
        k += 1;
        keep[k - 1]
    });
}

/// Pairs upper and lower rims and numbers the wafers.
fn pair_rims(
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

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::camera::Camera;
    use autoteach_geometry::render::{self, Carrier, RenderOptions, Rim, Scene};
    use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

    /// Camera at `(x, y, z)` (world, metres) looking along +x, yawed by `yaw` and pitched down
    /// by `down` (radians).
    fn camera_pose(x: f64, y: f64, z: f64, yaw: f64, down: f64) -> Isometry3<f64> {
        let axes = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
            * Rotation3::from_matrix_unchecked(axes)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), -down);
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_rotation_matrix(&r),
        )
    }

    /// Renders target slot 5 and a disturbance `k` slots above; returns the image, the visible
    /// true rims `(wafer, rim, ellipse, visible fraction)`.
    type Rendered = (Vec<u8>, usize, usize, Vec<(usize, Rim, Ellipse, f64)>);

    /// Renders target slot 5 and a disturbance `k` slots above.
    pub(crate) fn scene(k: usize, gain: f64, seed: u64) -> Rendered {
        let carrier = Carrier::default();
        let scene = Scene::new(vec![carrier.slot_pose(5), carrier.slot_pose(5 + k)]);
        let camera = Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).unwrap();
        let t_wc = camera_pose(-0.48, 0.02, 0.09, 0.03, 0.14);
        let opts = RenderOptions {
            gain,
            seed,
            ..RenderOptions::default()
        };
        let img = render::render(&scene, &camera, &t_wc, &opts).unwrap();
        let truth = render::rim_visibility(&scene, &camera, &t_wc, 720).unwrap();
        let rims = truth
            .into_iter()
            .filter_map(|t| t.ellipse.map(|e| (t.wafer, t.rim, e, t.fraction)))
            .collect();
        (img.data, img.width, img.height, rims)
    }

    #[test]
    fn rendered_target_and_disturbance_rims_are_found() {
        for k in [1usize, 2] {
            let (data, w, h, rims) = scene(k, 1.0, 7);
            let view = GrayView::new(&data, w, h).unwrap();
            let edges = detect_wafers(&view, &DetectParams::default()).unwrap();
            // Every visible rim of both wafers is found with the right kind, centre within
            // 1 px, semi-major axis within 1 % and semi-minor within 2 % (on these flat rims,
            // b ≈ 22–35 px, the minor axis of a 40 % front arc is the least determined
            // parameter: 1 % is 0.2–0.35 px); the two rims of a wafer share an id.
            let mut ids = Vec::new();
            for (wafer, rim, e, fraction) in &rims {
                if *fraction < 0.3 {
                    continue;
                }
                let kind = if *rim == Rim::Upper {
                    RimKind::Upper
                } else {
                    RimKind::Lower
                };
                let hit = edges.iter().find(|d| {
                    d.kind == kind
                        && (d.ellipse.cx - e.cx).hypot(d.ellipse.cy - e.cy) < 1.0
                        && (d.ellipse.a - e.a).abs() < 0.01 * e.a
                        && (d.ellipse.b - e.b).abs() < 0.02 * e.b
                });
                let hit = hit.unwrap_or_else(|| {
                    panic!("k={k}: wafer {wafer} {rim:?} {e:?} missing in {edges:#?}")
                });
                ids.push((*wafer, hit.wafer_id));
                assert!(hit.residual < 0.15 && hit.covariance.is_some());
            }
            assert_eq!(ids.len(), 4, "k={k}");
            assert_eq!(ids[0].1, ids[1].1);
            assert_eq!(ids[2].1, ids[3].1);
            assert_ne!(ids[0].1, ids[2].1);
            assert_eq!(edges.len(), 4, "k={k}: {edges:#?}");
        }
    }

    #[test]
    fn blank_images_give_no_rims_and_bad_params_are_errors() {
        for v in [0u8, 255] {
            let data = vec![v; 320 * 240];
            let view = GrayView::new(&data, 320, 240).unwrap();
            assert!(
                detect_wafers(&view, &DetectParams::default())
                    .unwrap()
                    .is_empty()
            );
        }
        let data = vec![0u8; 64];
        let view = GrayView::new(&data, 8, 8).unwrap();
        let bad = DetectParams {
            up: [0.0, 0.0],
            ..DetectParams::default()
        };
        assert!(detect_wafers(&view, &bad).is_err());
        let bad = DetectParams {
            min_coverage: 2.0,
            ..DetectParams::default()
        };
        assert!(detect_wafers(&view, &bad).is_err());
        for sep in [-0.1, 1.0, f64::NAN] {
            let bad = DetectParams {
                min_rim_separation: sep,
                ..DetectParams::default()
            };
            assert!(detect_wafers(&view, &bad).is_err());
        }
    }
}
