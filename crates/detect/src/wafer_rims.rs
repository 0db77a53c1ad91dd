//! Wafer rims from general ellipse detections: the two rims of a wafer paired and labelled by
//! geometry alone (issue 42, part 2; the upper and lower rim of 000_3b1454b2b2194811.txt
//! Fig. 3.2), never by which side is brighter.
//!
//! A wafer of radius `R` and thickness `h` is a short cylinder. Seen from a camera at
//! elevation `φ` above the wafer plane (distance `Z`, focal length `f`), each rim circle
//! images, to first order (weak perspective, `k = f/Z` pixels per mm), as an ellipse with
//! semi-major axis `a = kR` and semi-minor axis `b = kR·sin φ`; the wafer's axis (length `h`)
//! images along the ellipse's minor axis with length `kh·cos φ`. So the upper rim's centre is
//! the lower rim's moved along the minor axis, toward the image's `up` direction, by
//!
//! `s = (h/R) · a · √(1 − (b/a)²)`,
//!
//! and both rims have the same axes (to `h/Z`, under 0.3 % at 0.4 m). Perspective changes the
//! offset by up to the wafer's relative depth span `R/Z`; [`RIM_OFFSET_TOLERANCE`] allows
//! that. Which rim is upper follows from `up` alone.
//!
//! Candidates are the detections of [`crate::ellipse_detection::detect_ellipses`] (edges of
//! either polarity) and thin lines: two edges of opposite polarity closer than `0.75 s` (a
//! line narrower than the rim separation: each rim drawn as a thin curve) are one rim on the
//! line's centre. A wafer whose edge face is a band brighter or darker than its surroundings
//! gives the two rims as the band's two edges (opposite polarities, `s` apart); a wafer drawn as
//! two thin lines gives two line centres `s` apart. Pairs of lines are taken first (they use
//! four edges that could otherwise pair as two same-polarity edge pairs of the lines' sides),
//! then pairs of edges, each greedily by increasing normalised offset error, each edge in one
//! rim at most.

// `!(x <= y)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Point2, Vector2};

use crate::edges::{GrayView, Pixel};
use crate::ellipse_detection::refine::{OPERATOR_REACH, median_distance};
use crate::ellipse_detection::ridges::{detect_signed_lines, ridge_scale};
use crate::ellipse_detection::{EllipseDetectParams, EllipseDetection, detect_ellipses};
use crate::wafers::{RimKind, WaferEdge};
use crate::{DetectError, Result};

/// Relative tolerance of the rim offset `s`: perspective changes it by up to the wafer's depth
/// span over its distance, `R/Z` (0.19 for a 150 mm wafer at 0.4 m); 0.3 covers `Z ≥ 0.25 m`.
pub const RIM_OFFSET_TOLERANCE: f64 = 0.3;
/// Bias (pixels) a rim's fitted centre may carry beyond its covariance where the two rims are
/// closer than the edge operator's reach ([`crate::ellipse_detection::refine::OPERATOR_REACH`]):
/// their edges pull each other's points along the whole arc, which no point selection removes
/// (measured 0.2–1 px on 1.5 px bands). Added to the offset tolerance so such a wafer still
/// pairs; the neighbouring wafer's rims are `pitch/h` (10–20) offsets away.
pub const RIM_CENTRE_BIAS: f64 = 1.0;
/// Largest difference of the two rims' semi-axes beyond their fits' 3σ, relative to the
/// semi-major axis `a`. The rims are one circle seen from heights `h` apart: the far rim's
/// elevation differs by `h·cos φ/Z` and its distance by `h·sin φ`, which changes
/// `b = a·sin φ` by `a·(h/Z)·(cos²φ − sin²φ)` (see [`narrow_band_rims`]) — a multiple of `a`,
/// not of `b` (1.1 px at `a` = 446 px for 1 mm at 0.4 m, i.e. 2 % of a
/// 53 px semi-minor axis) — and `a` by `a·h/Z` at most. 0.02 covers `Z ≥ 50 h` and the fits'
/// bias on partial arcs.
pub const RIM_AXIS_TOLERANCE: f64 = 0.02;
/// Widest rim drawn as a line (pixels) that [`detect_wafer_rims`] finds on its centre line
/// ([`crate::ellipse_detection::ridges`], derivative scale 0.81 px) when the options give no
/// `max_line_width`: the two edges of a narrower line lie within each other's
/// [`OPERATOR_REACH`] on both sides, so the edge path cannot place them (measured on the
/// thin-line family of `autoteach.sim.appearance`, 0.6–1.5 px lines 2–5 px apart).
pub const RIM_LINE_WIDTH: f64 = 2.8;
/// Lines narrower than this fraction of the rim offset `s` count as one rim drawn as a line.
const LINE_FRACTION: f64 = 0.75;

/// Physical wafer geometry and the camera prior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaferGeometry {
    /// Wafer radius (mm). Default 75 (150 mm wafers).
    pub radius: f64,
    /// Wafer thickness (mm). Default 0.775 (SEMI 150 mm wafers are 0.675 mm; the project's
    /// renderer uses 0.775). Only the ratio `thickness/radius` matters.
    pub thickness: f64,
    /// Image direction of the wafers' upward normal (pixels, any length; default `(0, −1)`,
    /// image up), from the rough camera pose.
    pub up: [f64; 2],
    /// Accepted range of the semi-major axis (pixels), from the rough camera pose; `None`
    /// (default) for any.
    pub semi_major: Option<(f64, f64)>,
    /// Focal length (pixels) of the intrinsics, if known: it predicts the difference of the two
    /// rims' semi-minor axes where the band is too narrow to measure it (see
    /// [`narrow_band_rims`]). `None` (default): the edges' own difference is kept.
    pub focal_length: Option<f64>,
}

impl Default for WaferGeometry {
    fn default() -> Self {
        Self {
            radius: 75.0,
            thickness: 0.775,
            up: [0.0, -1.0],
            semi_major: None,
            focal_length: None,
        }
    }
}

impl WaferGeometry {
    fn validate(&self) -> Result<Vector2<f64>> {
        let bad = |what, value, reason| {
            Err(DetectError::InvalidParameter {
                what,
                value,
                reason,
            })
        };
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return bad("radius", self.radius, "must be finite and positive");
        }
        if !(self.thickness > 0.0 && self.thickness < self.radius) {
            return bad(
                "thickness",
                self.thickness,
                "must be positive and under the radius",
            );
        }
        if let Some(f) = self.focal_length
            && !(f > 0.0 && f.is_finite())
        {
            return bad("focal_length", f, "must be finite and positive");
        }
        let up = Vector2::new(self.up[0], self.up[1]);
        let n = up.norm();
        if !(n > 0.0 && n.is_finite()) {
            return bad("up", n, "must be a finite non-zero direction");
        }
        if let Some((lo, hi)) = self.semi_major
            && !(lo >= 0.0 && hi >= lo && hi.is_finite())
        {
            return bad("semi_major", hi, "must be a finite range lo <= hi");
        }
        Ok(up / n)
    }
}

/// A rim candidate: one edge, or the centre of a thin line (two edges).
struct Candidate {
    ellipse: Ellipse,
    /// For a line: `+1` brighter than its surroundings, `−1` darker, 0 unknown (and edges).
    brightness: i8,
    edges: Vec<usize>,
    covariance: Option<Matrix5<f64>>,
    residual: f64,
}

/// Variance of the centre (`σ²_cx + σ²_cy`) from a covariance, 0 without one.
fn centre_var(c: &Option<Matrix5<f64>>) -> f64 {
    c.map_or(0.0, |c| (c[(0, 0)] + c[(1, 1)]).max(0.0))
}

/// The expected offset vector (pixels) from the lower rim's centre to the upper rim's of a wafer
/// imaged as `e` (see the module documentation), or `None` when the minor axis is
/// perpendicular to `up` (no image direction tells the rims apart).
pub fn rim_offset(e: &Ellipse, thickness_ratio: f64, up: &Vector2<f64>) -> Option<Vector2<f64>> {
    let (s, c) = e.theta.sin_cos();
    let mut minor = Vector2::new(-s, c);
    let along = minor.dot(up);
    if along.abs() < 0.1 {
        return None;
    }
    if along < 0.0 {
        minor = -minor;
    }
    let q = (e.b / e.a).min(1.0);
    Some(minor * (thickness_ratio * e.a * (1.0 - q * q).sqrt()))
}

/// The parameter-wise mean of two nearly equal ellipses (the first one's orientation): the
/// centre line of a band or line whose two edges they are.
fn mean_ellipse(p: &Ellipse, q: &Ellipse) -> Option<Ellipse> {
    Ellipse::new(
        0.5 * (p.cx + q.cx),
        0.5 * (p.cy + q.cy),
        0.5 * (p.a + q.a),
        0.5 * (p.b + q.b),
        p.theta,
    )
    .ok()
}

/// The two rims of a wafer whose edge face is a band narrower than the edge operator's reach
/// ([`OPERATOR_REACH`]): its two edges pull each other's points along the whole arc (the
/// upper edge down, the lower edge up, by up to a pixel), so their separation is not
/// measurable, but the pull is symmetric and the band's centre line — the mean of the two edge
/// ellipses — is not biased. The rims are that centre line moved by `∓s/2` along the rim
/// offset `s` of [`rim_offset`] (error: its perspective tolerance times `s/2`, under 0.3 px
/// for such bands), with the same semi-major axis and, when the focal length `f` is known,
/// semi-minor axes `b̄ ± Δb/2` with the far rim's excess `Δb = (h/R)·(a²/f)·(1 − 2(b/a)²)`.
/// That is `b = a·sin φ` differentiated over the rims' height difference `h` at distance `Z`:
/// the far rim's elevation is larger by `h·cos φ/Z` (`+a·(h/Z)·cos²φ`) and it is farther by
/// `h·sin φ`, which shrinks `a` by `a·(h/Z)·sin φ` (`−a·(h/Z)·sin²φ`), with
/// `h/Z = (h/R)(a/f)`. The far rim is the lower one for a camera above the wafers, i.e. when
/// the lower edge's support lies on the far side of its centre from `up`. Without `f` the
/// edges' own semi-minor axes are kept.
fn narrow_band_rims(
    lower: &Candidate,
    upper: &Candidate,
    lower_points: &[Vector2<f64>],
    ratio: f64,
    up: &Vector2<f64>,
    focal_length: Option<f64>,
) -> Option<(Ellipse, Ellipse)> {
    let (l, u) = (&lower.ellipse, &upper.ellipse);
    let mean = mean_ellipse(l, u)?;
    let s = rim_offset(&mean, ratio, up)?;
    if !(s.norm() < OPERATOR_REACH) {
        return None;
    }
    let (bl, bu) = match focal_length {
        Some(f) => {
            let db = far_rim_excess(&mean, ratio, f);
            let sign = if far_is_lower(l, lower_points, up) {
                1.0
            } else {
                -1.0
            };
            (mean.b + sign * 0.5 * db, mean.b - sign * 0.5 * db)
        }
        None => (l.b, u.b),
    };
    let lo = Ellipse::new(
        mean.cx - 0.5 * s.x,
        mean.cy - 0.5 * s.y,
        mean.a,
        bl.min(mean.a),
        mean.theta,
    )
    .ok()?;
    let hi = Ellipse::new(
        mean.cx + 0.5 * s.x,
        mean.cy + 0.5 * s.y,
        mean.a,
        bu.min(mean.a),
        mean.theta,
    )
    .ok()?;
    Some((lo, hi))
}

/// Whether the lower rim is the far one (camera above the wafers): its support, the front arc,
/// lies on the far side of its centre from `up`.
fn far_is_lower(l: &Ellipse, lower_points: &[Vector2<f64>], up: &Vector2<f64>) -> bool {
    let n = lower_points.len().max(1) as f64;
    let side: f64 = lower_points
        .iter()
        .map(|p| (p.x - l.cx) * up.x + (p.y - l.cy) * up.y)
        .sum::<f64>()
        / n;
    side < 0.0
}

/// The far rim's excess semi-minor axis `Δb = (h/R)·(a²/f)·(1 − 2(b/a)²)` of a wafer imaged as
/// `e` (see [`narrow_band_rims`]).
fn far_rim_excess(e: &Ellipse, ratio: f64, focal_length: f64) -> f64 {
    let q = (e.b / e.a).min(1.0);
    ratio * e.a * e.a / focal_length * (1.0 - 2.0 * q * q)
}

/// Signed distance (Sampson's first-order approximation) of `p` to `e` and its unit gradient
/// direction with respect to `p`.
fn signed_distance(e: &Ellipse, p: &Vector2<f64>) -> Option<(f64, Vector2<f64>)> {
    let (st, ct) = e.theta.sin_cos();
    let d = p - Vector2::new(e.cx, e.cy);
    let (x, y) = (ct * d.x + st * d.y, -st * d.x + ct * d.y);
    let f = (x / e.a).powi(2) + (y / e.b).powi(2) - 1.0;
    let (gx, gy) = (2.0 * x / (e.a * e.a), 2.0 * y / (e.b * e.b));
    let g = Vector2::new(ct * gx - st * gy, st * gx + ct * gy);
    let n = g.norm();
    (n > 0.0).then(|| (f / n, g / n))
}

/// The rim `shape` moved to fit `points` (its centre by Gauss–Newton on the signed distances;
/// axes and orientation fixed): the rim of a wafer whose support is a short arc, fitted with
/// the shape of its better-determined partner. Returns the ellipse and the mean absolute
/// distance.
fn translate_fit(shape: &Ellipse, points: &[Vector2<f64>]) -> Option<(Ellipse, f64)> {
    if points.len() < 5 {
        return None;
    }
    let mut e = *shape;
    for _ in 0..20 {
        let (mut jtj, mut jtr) = (nalgebra::Matrix2::<f64>::zeros(), Vector2::<f64>::zeros());
        for p in points {
            let (d, g) = signed_distance(&e, p)?;
            // ∂d/∂c ≈ −g (the point moves by −δc relative to the ellipse).
            jtj += g * g.transpose();
            jtr += -g * d;
        }
        let step = jtj.try_inverse()? * (-jtr);
        e = Ellipse::new(e.cx + step.x, e.cy + step.y, e.a, e.b, e.theta).ok()?;
        if step.norm() < 1e-4 {
            break;
        }
    }
    let mean = points
        .iter()
        .map(|p| signed_distance(&e, p).map_or(f64::INFINITY, |(d, _)| d.abs()))
        .sum::<f64>()
        / points.len() as f64;
    mean.is_finite().then_some((e, mean))
}

/// The support points of a candidate: its edges' points.
fn support(dets: &[EllipseDetection], c: &Candidate) -> Vec<Vector2<f64>> {
    c.edges
        .iter()
        .flat_map(|&k| dets[k].points.iter().copied())
        .collect()
}

/// The two rims of a wafer are one circle seen from heights `h` apart: the same semi-major
/// axis and orientation, semi-minor axes `Δb` apart ([`far_rim_excess`], when the focal length
/// is known). Where one rim's centre is much less certain than the other's (a front arc only,
/// as the lower rim of a wafer seen from above usually is: a short arc of a flat ellipse leaves
/// its centre and `b` coupled), that rim is refitted with the better rim's shape, only its
/// centre free ([`translate_fit`]). Kept when the refit's mean distance stays within twice the
/// free fit's plus 0.1 px (a wrong partner's shape does not fit). `(lower, upper)`.
fn shared_shape_rims(
    dets: &[EllipseDetection],
    lower: &Candidate,
    upper: &Candidate,
    ratio: f64,
    up: &Vector2<f64>,
    geometry: &WaferGeometry,
) -> Option<(Ellipse, Ellipse)> {
    let (vl, vu) = (centre_var(&lower.covariance), centre_var(&upper.covariance));
    let lower_is_worse = vl > vu;
    let (worse, better) = if lower_is_worse {
        (lower, upper)
    } else {
        (upper, lower)
    };
    let (vw, vb) = if lower_is_worse { (vl, vu) } else { (vu, vl) };
    if !(vw > 4.0 * vb) {
        return None;
    }
    let worse_points = support(dets, worse);
    let b = better.ellipse;
    let db = geometry.focal_length.map_or(0.0, |f| {
        let far_lower = far_is_lower(&lower.ellipse, &support(dets, lower), up);
        let worse_is_far = far_lower == lower_is_worse;
        if worse_is_far {
            far_rim_excess(&b, ratio, f)
        } else {
            -far_rim_excess(&b, ratio, f)
        }
    });
    // Start at the centre the rim offset predicts from the better rim.
    let s = rim_offset(&b, ratio, up)?;
    let sign = if lower_is_worse { -1.0 } else { 1.0 };
    let start = Ellipse::new(
        b.cx + sign * s.x,
        b.cy + sign * s.y,
        b.a,
        (b.b + db).min(b.a),
        b.theta,
    )
    .ok()?;
    let (fitted, mean) = translate_fit(&start, &worse_points)?;
    if !(mean <= 2.0 * worse.residual + 0.1) {
        return None;
    }
    Some(if lower_is_worse {
        (fitted, b)
    } else {
        (b, fitted)
    })
}

/// Normalised misfit (≤ 1 accepted) of `lower`/`upper` as the two rims of one wafer.
fn pair_cost(lower: &Candidate, upper: &Candidate, ratio: f64, up: &Vector2<f64>) -> Option<f64> {
    let (l, u) = (&lower.ellipse, &upper.ellipse);
    let mean = mean_ellipse(l, u)?;
    let expected = rim_offset(&mean, ratio, up)?;
    let delta = Vector2::new(u.cx - l.cx, u.cy - l.cy);
    let sigma = (centre_var(&lower.covariance) + centre_var(&upper.covariance)).sqrt();
    let tol = RIM_OFFSET_TOLERANCE * expected.norm() + 3.0 * sigma + RIM_CENTRE_BIAS;
    let err = (delta - expected).norm();
    if !(err <= tol) {
        return None;
    }
    for k in [2usize, 3] {
        let (x, y) = if k == 2 { (l.a, u.a) } else { (l.b, u.b) };
        let var = |c: &Option<Matrix5<f64>>| c.map_or(0.0, |c| c[(k, k)].max(0.0));
        let tol_k = RIM_AXIS_TOLERANCE * l.a.max(u.a)
            + 3.0 * (var(&lower.covariance) + var(&upper.covariance)).sqrt();
        if !((x - y).abs() <= tol_k) {
            return None;
        }
    }
    Some(err / tol.max(1e-9))
}

/// The line candidates: pairs of opposite-polarity edges closer than `LINE_FRACTION` of the
/// rim offset of their ellipse (as in [`crate::ellipse_detection::lines`], but every such pair
/// is offered; the rim pairing decides).
fn line_candidates(dets: &[EllipseDetection], ratio: f64, up: &Vector2<f64>) -> Vec<Candidate> {
    let mut out = Vec::new();
    for i in 0..dets.len() {
        for j in i + 1..dets.len() {
            let (p, q) = (&dets[i], &dets[j]);
            if p.polarity * q.polarity != -1 {
                continue;
            }
            let (e, f) = (&p.ellipse, &q.ellipse);
            let Some(s) = rim_offset(e, ratio, up).map(|v| v.norm()) else {
                continue;
            };
            let dc = ((e.cx - f.cx).powi(2) + (e.cy - f.cy).powi(2)).sqrt();
            let width = (e.a - f.a).abs().max((e.b - f.b).abs());
            if !(width < LINE_FRACTION * s && dc < 0.5 * LINE_FRACTION * s + 0.5) {
                continue;
            }
            let Some(ellipse) = mean_ellipse(e, f) else {
                continue;
            };
            // The outer side of a bright line is brighter inside (polarity −1).
            let outer = if e.a >= f.a { p.polarity } else { q.polarity };
            out.push(Candidate {
                ellipse,
                brightness: -outer,
                edges: vec![i, j],
                covariance: match (p.covariance, q.covariance) {
                    (Some(a), Some(b)) => Some((a + b) * 0.25),
                    _ => None,
                },
                residual: 0.5 * (p.residual + q.residual),
            });
        }
    }
    out
}

/// Whether two rim ellipses are one: centres within [`OPERATOR_REACH`]/2 and semi-axes within
/// [`RIM_AXIS_TOLERANCE`] of the semi-major axis.
fn same_rim(e: &Ellipse, f: &Ellipse) -> bool {
    let tol = RIM_AXIS_TOLERANCE * e.a.max(f.a);
    (e.cx - f.cx).hypot(e.cy - f.cy) <= 0.5 * OPERATOR_REACH
        && (e.a - f.a).abs() <= tol
        && (e.b - f.b).abs() <= tol
}

/// Whether the edge `d` runs along the line `e`: its points' median distance to `e` is within
/// the edge operator's reach ([`OPERATOR_REACH`]).
fn side_of(d: &EllipseDetection, e: &Ellipse) -> bool {
    median_distance(e, &d.points) <= OPERATOR_REACH
}

/// Whether the centre line `e` is the middle of a band wider than [`RIM_LINE_WIDTH`] whose
/// two edges were detected: a pair of opposite-polarity edges on either side of `e` (their
/// mean is `e` within half a pixel of centre and 2 % of the axes) more than that far apart. A
/// wafer's edge face seen as such a band has its rims on the edges, not at its middle.
fn band_centre(dets: &[EllipseDetection], e: &Ellipse) -> bool {
    let near: Vec<&EllipseDetection> = dets
        .iter()
        .filter(|d| {
            d.polarity != 0
                && (d.ellipse.cx - e.cx).hypot(d.ellipse.cy - e.cy) <= RIM_LINE_WIDTH + 1.0
                && (d.ellipse.a - e.a).abs() <= RIM_AXIS_TOLERANCE * e.a + RIM_LINE_WIDTH
        })
        .collect();
    near.iter().enumerate().any(|(i, p)| {
        near[i + 1..].iter().any(|q| {
            p.polarity * q.polarity == -1
                && mean_ellipse(&p.ellipse, &q.ellipse).is_some_and(|m| {
                    (m.cx - e.cx).hypot(m.cy - e.cy) <= 0.5
                        && (m.b - e.b).abs() <= RIM_AXIS_TOLERANCE * e.a
                })
                && (p.ellipse.cx - q.ellipse.cx).hypot(p.ellipse.cy - q.ellipse.cy) > RIM_LINE_WIDTH
        })
    })
}

/// The line candidates: the detected centre lines (polarity 0, e.g. from
/// [`crate::ellipse_detection::ridges`]) first, then the edge-pair lines that are not one of
/// them (the same line seen by its two sides).
fn with_centre_lines(
    dets: &[EllipseDetection],
    brightness: &[i8],
    pairs: Vec<Candidate>,
) -> Vec<Candidate> {
    let mut out: Vec<Candidate> = dets
        .iter()
        .enumerate()
        .filter(|(_, d)| d.polarity == 0 && !band_centre(dets, &d.ellipse))
        .map(|(i, d)| Candidate {
            ellipse: d.ellipse,
            brightness: brightness.get(i).copied().unwrap_or(0),
            edges: vec![i],
            covariance: d.covariance,
            residual: d.residual,
        })
        .collect();
    let centres = out.len();
    for c in pairs {
        if !out[..centres]
            .iter()
            .any(|l| same_rim(&l.ellipse, &c.ellipse))
        {
            out.push(c);
        }
    }
    out
}

/// Pairs the detections into wafers (see the module documentation). Returns the rims, the
/// two of each wafer with one `wafer_id`, wafers numbered from the topmost (along `up`).
///
/// # Errors
/// [`DetectError::InvalidParameter`] for a bad geometry.
pub fn pair_rims(dets: &[EllipseDetection], geometry: &WaferGeometry) -> Result<Vec<WaferEdge>> {
    pair_rims_with(dets, &[], geometry)
}

/// [`pair_rims`] where `brightness[i]` is the brightness of the line detection `dets[i]`
/// (polarity 0): `+1` brighter than its surroundings, `−1` darker, 0 (or missing) unknown. The
/// two rims of one wafer drawn as lines have one brightness: a bright line beside a dark
/// one is a rim beside the gap between two rims, not a wafer.
///
/// # Errors
/// As [`pair_rims`].
pub fn pair_rims_with(
    dets: &[EllipseDetection],
    brightness: &[i8],
    geometry: &WaferGeometry,
) -> Result<Vec<WaferEdge>> {
    let up = geometry.validate()?;
    let ratio = geometry.thickness / geometry.radius;
    let in_range = |e: &Ellipse| {
        geometry
            .semi_major
            .is_none_or(|(lo, hi)| e.a >= lo && e.a <= hi)
    };
    let edges: Vec<Candidate> = dets
        .iter()
        .enumerate()
        .filter(|(_, d)| d.polarity != 0)
        .map(|(i, d)| Candidate {
            ellipse: d.ellipse,
            brightness: 0,
            edges: vec![i],
            covariance: d.covariance,
            residual: d.residual,
        })
        .collect();
    let lines = with_centre_lines(dets, brightness, line_candidates(dets, ratio, &up));
    let mut used = vec![false; dets.len()];
    let mut wafers: Vec<(usize, &Candidate, &Candidate)> = Vec::new();
    for (kind, set) in [(0usize, &lines), (1, &edges)] {
        let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
        for (i, l) in set.iter().enumerate() {
            if !in_range(&l.ellipse) {
                continue;
            }
            for (j, u) in set.iter().enumerate() {
                if i == j
                    || l.edges.iter().any(|k| u.edges.contains(k))
                    || l.brightness * u.brightness < 0
                {
                    continue;
                }
                if let Some(c) = pair_cost(l, u, ratio, &up) {
                    pairs.push((c, i, j));
                }
            }
        }
        pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
        for (_, i, j) in pairs {
            let (l, u) = (&set[i], &set[j]);
            if l.edges.iter().chain(&u.edges).any(|&k| used[k]) {
                continue;
            }
            for &k in l.edges.iter().chain(&u.edges) {
                used[k] = true;
            }
            wafers.push((kind, l, u));
        }
        if kind == 0 {
            // The sides of a rim drawn as a line are not rims of their own.
            for (k, d) in dets.iter().enumerate() {
                if !used[k]
                    && d.polarity != 0
                    && wafers
                        .iter()
                        .any(|w| side_of(d, &w.1.ellipse) || side_of(d, &w.2.ellipse))
                {
                    used[k] = true;
                }
            }
        }
    }
    // One wafer once: a band's two edges can pair again as two lines' sides.
    let mut distinct: Vec<(usize, &Candidate, &Candidate)> = Vec::with_capacity(wafers.len());
    for w in wafers {
        if !distinct
            .iter()
            .any(|d| same_rim(&d.1.ellipse, &w.1.ellipse) && same_rim(&d.2.ellipse, &w.2.ellipse))
        {
            distinct.push(w);
        }
    }
    let mut wafers = distinct;
    // Topmost first: decreasing position of the upper rim's centre along `up`.
    let height = |c: &Candidate| c.ellipse.cx * up.x + c.ellipse.cy * up.y;
    wafers.sort_by(|x, y| height(y.2).total_cmp(&height(x.2)));
    let mut out = Vec::with_capacity(2 * wafers.len());
    for (id, (kind_of_pair, lower, upper)) in wafers.into_iter().enumerate() {
        // Edge pairs (not lines) of a band narrower than the operator's reach: the centre line.
        // Rims drawn as lines: the short one takes the long one's shape (edge bands keep their
        // own fits: a band's two edges pull each other, so neither shape is the rim's).
        let narrow = if kind_of_pair == 1 {
            narrow_band_rims(
                lower,
                upper,
                &support(dets, lower),
                ratio,
                &up,
                geometry.focal_length,
            )
        } else {
            shared_shape_rims(dets, lower, upper, ratio, &up, geometry)
        };
        for (kind, c) in [(RimKind::Upper, upper), (RimKind::Lower, lower)] {
            let points = c
                .edges
                .iter()
                .flat_map(|&k| dets[k].points.iter().map(|p| Point2::new(p.x, p.y)))
                .collect();
            let ellipse = match (narrow, kind) {
                (Some((_, hi)), RimKind::Upper) => hi,
                (Some((lo, _)), _) => lo,
                (None, _) => c.ellipse,
            };
            out.push(WaferEdge {
                ellipse,
                points,
                residual: c.residual,
                covariance: c.covariance,
                kind,
                wafer_id: id,
            });
        }
    }
    Ok(out)
}

/// Options of [`detect_wafer_rims`]: the wafer geometry and the ellipse detector's options.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WaferRimParams {
    /// Physical geometry and camera prior.
    pub geometry: WaferGeometry,
    /// Options of [`detect_ellipses`]. Its `max_line_width` is the widest rim drawn as a line
    /// that is found on its centre line (default [`RIM_LINE_WIDTH`]); edge pairs narrower than
    /// the rim offset are lines too, formed by the pairing.
    pub ellipses: EllipseDetectParams,
}

/// Wafer rims by [`detect_ellipses`] and [`pair_rims`]: the same [`WaferEdge`] type as
/// [`crate::wafers::detect_wafers`], with no assumption on the image's appearance.
///
/// # Errors
/// As [`detect_ellipses`] and [`pair_rims`].
pub fn detect_wafer_rims<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &WaferRimParams,
) -> Result<Vec<WaferEdge>> {
    params.geometry.validate()?;
    let opts = EllipseDetectParams {
        max_line_width: None,
        ..params.ellipses
    };
    let mut dets = detect_ellipses(image, &opts)?;
    let mut brightness = vec![0i8; dets.len()];
    let width = params.ellipses.max_line_width.unwrap_or(RIM_LINE_WIDTH);
    for (d, b) in detect_signed_lines(image, &opts, ridge_scale(width))? {
        dets.push(d);
        brightness.push(b);
    }
    pair_rims_with(&dets, &brightness, &params.geometry)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(e: Ellipse, polarity: i8) -> EllipseDetection {
        EllipseDetection {
            ellipse: e,
            points: e.sample(20, 0.0, 3.0).unwrap(),
            covariance: None,
            residual: 0.05,
            score: 20.0,
            polarity,
        }
    }

    #[test]
    fn rim_offset_is_the_projected_thickness() {
        // Seen at elevation 30°: b/a = 1/2, the axis projects with cos 30°.
        let e = Ellipse::new(0.0, 0.0, 200.0, 100.0, 0.0).unwrap();
        let v = rim_offset(&e, 1.0 / 75.0, &Vector2::new(0.0, -1.0)).unwrap();
        let truth = 200.0 / 75.0 * (30f64.to_radians()).cos();
        assert!((v.y + truth).abs() < 1e-12 && v.x.abs() < 1e-12);
        // Up along +y flips the direction; a minor axis across `up` has no answer.
        assert!(rim_offset(&e, 0.01, &Vector2::new(0.0, 1.0)).unwrap().y > 0.0);
        assert!(rim_offset(&e, 0.01, &Vector2::new(1.0, 0.0)).is_none());
    }

    #[test]
    fn band_edges_pair_and_label_by_up_not_polarity() {
        let g = WaferGeometry::default();
        let lower = Ellipse::new(300.0, 200.0, 240.0, 40.0, 0.0).unwrap();
        let s = rim_offset(&lower, g.thickness / g.radius, &Vector2::new(0.0, -1.0)).unwrap();
        let upper = Ellipse::new(300.0 + s.x, 200.0 + s.y, 240.0, 40.0, 0.0).unwrap();
        // A clutter ellipse and both polarity assignments.
        let clutter = Ellipse::new(100.0, 50.0, 30.0, 20.0, 0.3).unwrap();
        for (pu, pl) in [(1i8, -1i8), (-1, 1)] {
            let dets = vec![det(clutter, 1), det(lower, pl), det(upper, pu)];
            let rims = pair_rims(&dets, &g).unwrap();
            assert_eq!(rims.len(), 2);
            assert_eq!(rims[0].kind, RimKind::Upper);
            assert!((rims[0].ellipse.cy - upper.cy).abs() < 1e-12);
            assert!((rims[1].ellipse.cy - lower.cy).abs() < 1e-12);
        }
    }

    #[test]
    fn thin_lines_pair_on_their_centres() {
        let g = WaferGeometry::default();
        let lower = Ellipse::new(300.0, 200.0, 400.0, 60.0, 0.0).unwrap();
        let s = rim_offset(&lower, g.thickness / g.radius, &Vector2::new(0.0, -1.0)).unwrap();
        let upper = Ellipse::new(300.0 + s.x, 200.0 + s.y, 400.0, 60.0, 0.0).unwrap();
        let side = |e: &Ellipse, d: f64| Ellipse::new(e.cx, e.cy, e.a + d, e.b + d, 0.0).unwrap();
        let dets = vec![
            det(side(&lower, 0.6), -1),
            det(side(&lower, -0.6), 1),
            det(side(&upper, 0.6), -1),
            det(side(&upper, -0.6), 1),
        ];
        let rims = pair_rims(&dets, &g).unwrap();
        assert_eq!(rims.len(), 2, "{rims:?}");
        assert!((rims[0].ellipse.cy - upper.cy).abs() < 1e-9);
        assert!((rims[0].ellipse.b - upper.b).abs() < 1e-9);
        assert!((rims[1].ellipse.cy - lower.cy).abs() < 1e-9);
    }

    /// The exact rims of a wafer (radius 75 mm, thickness `h`) seen by a pinhole camera
    /// (`f` = 1000 px, principal point (640, 360)) from `distance` mm at `elevation` (degrees):
    /// (upper, lower), by `project_circle_world`, independent of this module's formulas.
    fn exact_rims(h: f64, distance: f64, elevation: f64) -> (Ellipse, Ellipse) {
        use autoteach_geometry::conic::project_circle_world;
        use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
        let k = Matrix3::new(1000.0, 0.0, 640.0, 0.0, 1000.0, 360.0, 0.0, 0.0, 1.0);
        let phi = elevation.to_radians();
        let eye = Vector3::new(0.0, -distance * phi.cos(), distance * phi.sin());
        let z = (-eye).normalize();
        let x = z.cross(&Vector3::z()).normalize();
        let y = z.cross(&x);
        let r_wc = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
        let t_wc = Isometry3::from_parts(
            Translation3::from(eye),
            UnitQuaternion::from_rotation_matrix(&r_wc),
        );
        let t_cw = t_wc.inverse();
        let rim = |zc: f64| {
            project_circle_world(&k, &t_cw, &Vector3::new(0.0, 0.0, zc), &Vector3::z(), 75.0)
                .expect("rim image")
        };
        (rim(0.5 * h), rim(-0.5 * h))
    }

    #[test]
    fn narrow_band_rims_recover_the_exact_rims_from_symmetrically_pulled_edges() {
        for (h, distance, elevation) in [(0.6, 400.0, 12.0), (0.5, 450.0, 25.0), (0.7, 380.0, 8.0)]
        {
            let (upper, lower) = exact_rims(h, distance, elevation);
            let offset = Vector2::new(upper.cx - lower.cx, upper.cy - lower.cy);
            assert!(
                offset.norm() < OPERATOR_REACH,
                "a narrow band: {}",
                offset.norm()
            );
            // Each edge pulled 0.4 px toward the other, the semi-minor axes toward each other too.
            let pull = offset.normalize() * 0.4;
            let moved = |e: &Ellipse, d: Vector2<f64>, db: f64| {
                Ellipse::new(e.cx + d.x, e.cy + d.y, e.a - 0.2, e.b + db, e.theta).expect("ellipse")
            };
            let lo = moved(&lower, pull, -0.3);
            let hi = moved(&upper, -pull, 0.3);
            let cand = |e: Ellipse| Candidate {
                brightness: 0,
                ellipse: e,
                edges: vec![0],
                covariance: None,
                residual: 0.05,
            };
            // The lower rim's visible arc (camera above): the half away from `up`.
            let front = lower
                .sample(100, 0.2, std::f64::consts::PI - 0.2)
                .expect("arc");
            let ratio = h / 75.0;
            let up = Vector2::new(0.0, -1.0);
            let (l, u) = narrow_band_rims(&cand(lo), &cand(hi), &front, ratio, &up, Some(1000.0))
                .expect("narrow band");
            for (got, truth) in [(l, lower), (u, upper)] {
                let dc = (got.cx - truth.cx).hypot(got.cy - truth.cy);
                assert!(dc < 0.3, "centre {dc} at {elevation}°");
                assert!(
                    (got.b / truth.b - 1.0).abs() < 0.01,
                    "b {} vs {}",
                    got.b,
                    truth.b
                );
                assert!((got.a / truth.a - 1.0).abs() < 0.01);
            }
            // The far (lower) rim's excess semi-minor axis is predicted within 25 %.
            let excess = (l.b - u.b) / (lower.b - upper.b);
            assert!((excess - 1.0).abs() < 0.25, "Δb ratio {excess}");
            // Without the focal length the edges' own semi-minor axes stay.
            let (l2, _) =
                narrow_band_rims(&cand(lo), &cand(hi), &front, ratio, &up, None).expect("band");
            assert_eq!(l2.b, lo.b);
        }
    }

    #[test]
    fn bad_geometry_is_an_error() {
        let g = WaferGeometry {
            up: [0.0, 0.0],
            ..WaferGeometry::default()
        };
        assert!(pair_rims(&[], &g).is_err());
    }
}
