//! Polygon (chamber-opening) detection by Hough voting and IRLS (seed 000_3b1454b2b2194811.txt
//! §3.3, "Detection of Chamber Openings in RGB image", eq. (3.5)–(3.10), Figs. 3.7–3.8).
//!
//! 1. Line segments of the image ([`detect_segments`]), or given by the caller.
//! 2. Their end points are transferred to the reference plane by the plane homography, eq. (3.8)
//!    (`H` maps reference-plane points to pixels, so the transfer applies `H⁻¹`).
//! 3. Every segment votes, for every template edge it could lie on and every discretised scale,
//!    for the line of potential polygon centres of eq. (3.9) (the polygon slides along the
//!    segment; a mismatch of `ε·l` at either end is allowed). The rotation is fixed by the
//!    segment direction (one Hough dimension fewer), and binned. The Hough space is
//!    `(rotation, scale, centre x, centre y)`; a vote weighs the segment length supported.
//! 4. The best cell is the coarse pose; segments lying on an edge of the placed polygon are its
//!    support.
//! 5. Iteratively reweighted least squares (3.10) on the support: each segment's line
//!    `a_j x + b_j y + c_j = 0` (unit normal oriented like the matched edge's outward normal)
//!    must pass at distance `(1 + ε)·d⁰_j` from the centre `(x, y)`, where `d⁰_j` is the distance
//!    of the template edge line from the template origin — linear in `(x, y, ε)` — and the
//!    rotation is the robust mean of the angle differences between the segment and template
//!    normals. Tukey weights (scale from the MAD) times segment length; support is re-collected
//!    once with the refined pose.
//!
//! The template is a simple polygon around its origin (the "centre"); it is made
//! counter-clockwise, and an opening is assumed *darker* than its surroundings, so with
//! `oriented = true` a segment (dark side on its left, see [`detect_segments`]) can only lie on
//! an edge running the same way.

mod segments;

pub use segments::{SegmentOptions, detect_segments};

use std::f64::consts::PI;

use autoteach_geometry::render::GrayImage;
use nalgebra::{Matrix3, Vector2, Vector3};

use crate::{DetectError, Result};

/// A line segment `a → b` (image or reference-plane coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Start point.
    pub a: Vector2<f64>,
    /// End point.
    pub b: Vector2<f64>,
}

impl Segment {
    /// Length.
    pub fn length(&self) -> f64 {
        (self.b - self.a).norm()
    }
}

/// Pose of the template in the reference plane: `p = centre + scale · R(rotation) · v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolygonPose {
    /// Centre (template origin) in the reference plane.
    pub centre: Vector2<f64>,
    /// Rotation, radians.
    pub rotation: f64,
    /// Uniform scale `1 + ε`.
    pub scale: f64,
}

/// Options of [`detect_polygon`] (lengths in reference-plane units).
#[derive(Debug, Clone, PartialEq)]
pub struct PolygonOptions {
    /// Centre cell size of the Hough space.
    pub cell: f64,
    /// Expected rotation of the template in the reference plane.
    pub rotation_nominal: f64,
    /// Largest rotation deviation searched (|θ − nominal| ≤ range).
    pub rotation_range: f64,
    /// Rotation bin width.
    pub rotation_step: f64,
    /// Smallest scale searched.
    pub scale_min: f64,
    /// Largest scale searched.
    pub scale_max: f64,
    /// Scale step.
    pub scale_step: f64,
    /// Allowed length mismatch `ε` of eq. (3.9), as a fraction of the edge length.
    pub epsilon: f64,
    /// Reference-plane segments shorter than this do not vote.
    pub min_segment_length: f64,
    /// Largest end-point distance from a placed edge for a segment to support it.
    pub support_distance: f64,
    /// Largest angle between a segment and a placed edge for support.
    pub support_angle: f64,
    /// Segments are oriented with the opening (dark side) on their left.
    pub oriented: bool,
    /// IRLS iterations per round.
    pub irls_iterations: usize,
}

impl Default for PolygonOptions {
    fn default() -> Self {
        Self {
            cell: 2.0,
            rotation_nominal: 0.0,
            rotation_range: 0.2,
            rotation_step: 0.02,
            scale_min: 0.9,
            scale_max: 1.1,
            scale_step: 0.025,
            epsilon: 0.1,
            min_segment_length: 6.0,
            support_distance: 3.0,
            support_angle: 0.1,
            oriented: true,
            irls_iterations: 30,
        }
    }
}

/// The centre vote map of the best (rotation, scale) slice.
#[derive(Debug, Clone, PartialEq)]
pub struct VoteMap {
    /// Votes, row-major `rows × cols`; row `r`, column `c` is the cell centred at
    /// `origin + cell·(c + ½, r + ½)`.
    pub data: Vec<f32>,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Reference-plane position of the map's corner.
    pub origin: Vector2<f64>,
    /// Cell size.
    pub cell: f64,
}

/// Result of [`detect_polygon`].
#[derive(Debug, Clone, PartialEq)]
pub struct PolygonDetection {
    /// Refined pose (IRLS, eq. 3.10) in the reference plane.
    pub pose: PolygonPose,
    /// Pose of the best Hough cell.
    pub coarse: PolygonPose,
    /// Votes of the best cell (supported edge length, reference units).
    pub votes: f64,
    /// Supporting segments: (index into `segments`, template edge index).
    pub support: Vec<(usize, usize)>,
    /// The image segments used (detected or given), image coordinates.
    pub segments: Vec<Segment>,
    /// Image position of the refined centre, `H · centre`.
    pub centre_image: Vector2<f64>,
    /// RMS distance (reference units) of the support's end points from the refined polygon.
    pub rms: f64,
    /// The vote map of the best (rotation, scale) slice.
    pub vote_map: VoteMap,
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

fn validate_options(o: &PolygonOptions) -> Result<()> {
    let bad = |what, value: f64, reason| {
        Err(DetectError::InvalidParameter {
            what,
            value,
            reason,
        })
    };
    let pos = [
        ("cell", o.cell),
        ("rotation_step", o.rotation_step),
        ("scale_min", o.scale_min),
        ("scale_step", o.scale_step),
        ("support_distance", o.support_distance),
        ("support_angle", o.support_angle),
    ];
    for (what, v) in pos {
        if !(v.is_finite() && v > 0.0) {
            return bad(what, v, "must be positive and finite");
        }
    }
    for (what, v) in [
        ("rotation_nominal", o.rotation_nominal),
        ("rotation_range", o.rotation_range),
        ("epsilon", o.epsilon),
        ("min_segment_length", o.min_segment_length),
    ] {
        if !(v.is_finite() && v >= 0.0 || what == "rotation_nominal" && v.is_finite()) {
            return bad(what, v, "must be finite and non-negative");
        }
    }
    if !(o.scale_max.is_finite() && o.scale_max >= o.scale_min) {
        return bad(
            "scale_max",
            o.scale_max,
            "must be finite and at least scale_min",
        );
    }
    if o.rotation_range > PI {
        return bad("rotation_range", o.rotation_range, "must be at most π");
    }
    Ok(())
}

/// The template made counter-clockwise (positive signed area); errors for fewer than 3
/// vertices, NaN, zero-length edges or zero area.
fn normalise_template(t: &[Vector2<f64>]) -> Result<Vec<Vector2<f64>>> {
    if t.len() < 3 {
        return Err(DetectError::TooFewPoints {
            what: "template",
            got: t.len(),
            needed: 3,
        });
    }
    for (i, v) in t.iter().enumerate() {
        for c in [v.x, v.y] {
            if !c.is_finite() {
                return Err(DetectError::NonFinite {
                    what: "template",
                    index: i,
                    value: c,
                });
            }
        }
    }
    let n = t.len();
    let mut area = 0.0;
    for k in 0..n {
        let (a, b) = (t[k], t[(k + 1) % n]);
        if (b - a).norm() == 0.0 {
            return Err(DetectError::Degenerate {
                reason: format!("template vertices {k} and {} coincide", (k + 1) % n),
            });
        }
        area += a.x * b.y - b.x * a.y;
    }
    if area.abs() < 1e-12 {
        return Err(DetectError::Degenerate {
            reason: "the template polygon has zero area".into(),
        });
    }
    let mut out = t.to_vec();
    if area < 0.0 {
        out.reverse();
    }
    Ok(out)
}

/// Applies a homography to a point (`None` at infinity or on non-finite results).
fn apply_h(h: &Matrix3<f64>, p: &Vector2<f64>) -> Option<Vector2<f64>> {
    let q = h * Vector3::new(p.x, p.y, 1.0);
    let r = Vector2::new(q.x / q.z, q.y / q.z);
    (q.z.abs() > 1e-300 && r.x.is_finite() && r.y.is_finite()).then_some(r)
}

/// Transfers image segments to the reference plane (eq. 3.8), keeping the dark side on the
/// left (end points are swapped where `H⁻¹` reverses orientation). `None` entries for segments
/// that do not map (behind the plane's horizon).
fn to_reference(segs: &[Segment], hinv: &Matrix3<f64>) -> Vec<Option<Segment>> {
    segs.iter()
        .map(|s| {
            let a = apply_h(hinv, &s.a)?;
            let b = apply_h(hinv, &s.b)?;
            // Orientation of H⁻¹ at the midpoint: sign of the Jacobian determinant, from the
            // images of a small right-handed pair of offsets.
            let m = (s.a + s.b) * 0.5;
            let d = (s.b - s.a).norm().max(1e-9) * 1e-3;
            let o = apply_h(hinv, &m)?;
            let ex = apply_h(hinv, &(m + Vector2::new(d, 0.0)))? - o;
            let ey = apply_h(hinv, &(m + Vector2::new(0.0, d)))? - o;
            Some(if ex.x * ey.y - ex.y * ey.x >= 0.0 {
                Segment { a, b }
            } else {
                Segment { a: b, b: a }
            })
        })
        .collect()
}

/// Template geometry: edge `k` runs from `v[k]` to `v[k+1]`.
struct Edge {
    v: Vector2<f64>,
    len: f64,
    angle: f64,
    /// Outward unit normal (right of the CCW edge direction).
    normal: Vector2<f64>,
    /// Signed distance of the edge line from the template origin along `normal`.
    d0: f64,
}

fn edges(t: &[Vector2<f64>]) -> Vec<Edge> {
    let n = t.len();
    (0..n)
        .map(|k| {
            let (a, b) = (t[k], t[(k + 1) % n]);
            let d = b - a;
            let len = d.norm();
            let u = d / len;
            let normal = Vector2::new(u.y, -u.x);
            Edge {
                v: a,
                len,
                angle: d.y.atan2(d.x),
                normal,
                d0: normal.dot(&a),
            }
        })
        .collect()
}

fn rot(a: f64, v: &Vector2<f64>) -> Vector2<f64> {
    let (s, c) = a.sin_cos();
    Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

/// The Hough accumulator over (rotation, scale, y, x).
struct Hough {
    n_rot: usize,
    n_scale: usize,
    rows: usize,
    cols: usize,
    origin: Vector2<f64>,
    data: Vec<f32>,
}

impl Hough {
    fn slice(&self, r: usize, s: usize) -> &[f32] {
        let n = self.rows * self.cols;
        let off = (r * self.n_scale + s) * n;
        &self.data[off..off + n]
    }
}

/// Rotation bins and scales of the search.
fn grids(o: &PolygonOptions) -> (usize, Vec<f64>) {
    let n_rot = ((2.0 * o.rotation_range / o.rotation_step).ceil() as usize).max(1);
    let n_scale = ((o.scale_max - o.scale_min) / o.scale_step).round() as usize + 1;
    (
        n_rot,
        (0..n_scale)
            .map(|k| o.scale_min + k as f64 * o.scale_step)
            .collect(),
    )
}

/// Voting of eq. (3.9) into the discretised Hough space.
fn vote(refs: &[Option<Segment>], e: &[Edge], o: &PolygonOptions) -> Result<Hough> {
    let (n_rot, scales) = grids(o);
    let radius = e.iter().map(|x| x.v.norm()).fold(0.0, f64::max) * o.scale_max;
    let (mut lo, mut hi) = (
        Vector2::repeat(f64::INFINITY),
        Vector2::repeat(f64::NEG_INFINITY),
    );
    for s in refs.iter().flatten() {
        for p in [s.a, s.b] {
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
    }
    if !lo.x.is_finite() {
        return Err(DetectError::TooFewPoints {
            what: "segments",
            got: 0,
            needed: 1,
        });
    }
    let origin = lo - Vector2::repeat(radius + 2.0 * o.cell);
    let ext = hi + Vector2::repeat(radius + 2.0 * o.cell) - origin;
    let (cols_f, rows_f) = ((ext.x / o.cell).ceil(), (ext.y / o.cell).ceil());
    // The size in f64, written so that NaN fails: a `usize` product of huge extents would
    // saturate, then wrap, and pass the limit.
    let total = n_rot as f64 * scales.len() as f64 * rows_f * cols_f;
    if total.is_nan() || total > 2e8 {
        return Err(DetectError::InvalidParameter {
            what: "cell",
            value: o.cell,
            reason: "the Hough space would exceed 2·10⁸ cells; enlarge cell or the steps, or narrow the ranges",
        });
    }
    let (cols, rows) = (cols_f as usize, rows_f as usize);
    let mut h = Hough {
        n_rot,
        n_scale: scales.len(),
        rows,
        cols,
        origin,
        data: vec![0f32; n_rot * scales.len() * rows * cols],
    };
    let theta0 = o.rotation_nominal - o.rotation_range;
    let plane = rows * cols;
    for seg in refs.iter().flatten() {
        let l1 = seg.length();
        if l1 < o.min_segment_length {
            continue;
        }
        let orientations: &[bool] = if o.oriented { &[false] } else { &[false, true] };
        for &flip in orientations {
            let (p1, p2) = if flip { (seg.b, seg.a) } else { (seg.a, seg.b) };
            let u = (p2 - p1) / l1;
            let phi = u.y.atan2(u.x);
            for edge in e {
                let theta = o.rotation_nominal + wrap(phi - edge.angle - o.rotation_nominal);
                let pos = (theta - theta0) / o.rotation_step;
                if pos < 0.0 || pos >= n_rot as f64 {
                    continue;
                }
                // The bin holding θ and its nearer neighbour (a rotation cluster cut by a bin
                // boundary still meets in one bin).
                let rb = pos.floor() as usize;
                let nb = if pos - rb as f64 >= 0.5 {
                    rb + 1
                } else {
                    rb.wrapping_sub(1)
                };
                let vert = rot(theta, &edge.v);
                for (si, &s) in scales.iter().enumerate() {
                    let l = s * edge.len;
                    if l1 > (1.0 + o.epsilon) * l {
                        continue;
                    }
                    // Eq. (3.9): ends of the line of potential centres.
                    let c1 = p1 + u * (l1 - (1.0 + o.epsilon) * l) - vert * s;
                    let c2 = p1 + u * (o.epsilon * l) - vert * s;
                    let weight = l1.min(l) as f32;
                    for r in [rb, nb] {
                        if r >= n_rot {
                            continue;
                        }
                        let base = (r * scales.len() + si) * plane;
                        rasterise(
                            &mut h.data[base..base + plane],
                            rows,
                            cols,
                            &origin,
                            o.cell,
                            &c1,
                            &c2,
                            weight,
                        );
                    }
                }
            }
        }
    }
    Ok(h)
}

/// Adds `w` once to every cell the segment `c1 → c2` passes through.
#[allow(clippy::too_many_arguments)]
fn rasterise(
    map: &mut [f32],
    rows: usize,
    cols: usize,
    origin: &Vector2<f64>,
    cell: f64,
    c1: &Vector2<f64>,
    c2: &Vector2<f64>,
    w: f32,
) {
    let len = (c2 - c1).norm();
    let steps = ((len / (0.25 * cell)).ceil() as usize).max(1);
    let mut last = usize::MAX;
    for k in 0..=steps {
        let p = c1 + (c2 - c1) * (k as f64 / steps as f64) - origin;
        let (cx, cy) = ((p.x / cell).floor(), (p.y / cell).floor());
        if cx < 0.0 || cy < 0.0 || cx >= cols as f64 || cy >= rows as f64 {
            continue;
        }
        let idx = cy as usize * cols + cx as usize;
        if idx != last {
            map[idx] += w;
            last = idx;
        }
    }
}

/// Best cell: the maximum of the 2×2-cell box sum over centres (a peak cut by a cell boundary
/// counts whole), per (rotation, scale) slice.
fn best_cell(h: &Hough, o: &PolygonOptions) -> Option<(usize, usize, Vector2<f64>, f64)> {
    let mut best: Option<(usize, usize, Vector2<f64>, f64)> = None;
    for r in 0..h.n_rot {
        for s in 0..h.n_scale {
            let m = h.slice(r, s);
            for y in 0..h.rows.saturating_sub(1) {
                for x in 0..h.cols.saturating_sub(1) {
                    let i = y * h.cols + x;
                    let v = (m[i] + m[i + 1] + m[i + h.cols] + m[i + h.cols + 1]) as f64;
                    if v > best.map_or(0.0, |b| b.3) {
                        let centre =
                            h.origin + Vector2::new((x + 1) as f64, (y + 1) as f64) * o.cell;
                        best = Some((r, s, centre, v));
                    }
                }
            }
        }
    }
    best.map(|(r, s, c, v)| (r, s, c, v / 4.0))
}

/// Segments lying on an edge of the placed template: (segment index, edge index).
fn support(
    refs: &[Option<Segment>],
    e: &[Edge],
    pose: &PolygonPose,
    o: &PolygonOptions,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (j, seg) in refs.iter().enumerate() {
        let Some(seg) = seg else { continue };
        let l1 = seg.length();
        if l1 < o.min_segment_length {
            continue;
        }
        let mut best: Option<(usize, f64)> = None;
        for (k, edge) in e.iter().enumerate() {
            let a = pose.centre + rot(pose.rotation, &edge.v) * pose.scale;
            let dir = rot(
                pose.rotation,
                &Vector2::new(edge.angle.cos(), edge.angle.sin()),
            );
            let n = Vector2::new(dir.y, -dir.x);
            let l = edge.len * pose.scale;
            let u = (seg.b - seg.a) / l1;
            let cosang = u.dot(&dir);
            let ok_angle = if o.oriented {
                cosang >= o.support_angle.cos()
            } else {
                cosang.abs() >= o.support_angle.cos()
            };
            if !ok_angle {
                continue;
            }
            let da = (seg.a - a).dot(&n).abs();
            let db = (seg.b - a).dot(&n).abs();
            if da > o.support_distance || db > o.support_distance {
                continue;
            }
            let (ta, tb) = ((seg.a - a).dot(&dir), (seg.b - a).dot(&dir));
            let (tmin, tmax) = (ta.min(tb), ta.max(tb));
            if tmin < -o.epsilon * l - o.support_distance
                || tmax > (1.0 + o.epsilon) * l + o.support_distance
            {
                continue;
            }
            let d = da + db;
            if best.is_none_or(|b| d < b.1) {
                best = Some((k, d));
            }
        }
        if let Some((k, _)) = best {
            out.push((j, k));
        }
    }
    out
}

/// IRLS of eq. (3.10) on the support, from `start`.
fn irls(
    refs: &[Option<Segment>],
    e: &[Edge],
    sup: &[(usize, usize)],
    start: &PolygonPose,
    o: &PolygonOptions,
) -> Result<PolygonPose> {
    // Line of each supporting segment: unit normal oriented like the edge's placed outward
    // normal, offset c with n·p + c = 0.
    let mut lines = Vec::with_capacity(sup.len());
    for &(j, k) in sup {
        let Some(seg) = refs[j] else { continue };
        let u = (seg.b - seg.a) / seg.length();
        let mut n = Vector2::new(u.y, -u.x);
        if n.dot(&rot(start.rotation, &e[k].normal)) < 0.0 {
            n = -n;
        }
        let m = (seg.a + seg.b) * 0.5;
        let theta_j = wrap(n.y.atan2(n.x) - e[k].normal.y.atan2(e[k].normal.x));
        lines.push((n, -n.dot(&m), e[k].d0, seg.length(), theta_j));
    }
    if lines.is_empty() {
        return Err(DetectError::TooFewPoints {
            what: "matched segments",
            got: 0,
            needed: 2,
        });
    }
    let mut pose = *start;
    let mut w_dist = vec![1.0; lines.len()];
    let mut w_ang = vec![1.0; lines.len()];
    let total_len: f64 = lines.iter().map(|l| l.3).sum();
    for _ in 0..o.irls_iterations.max(1) {
        // Rotation: weighted circular mean of the angle differences (the rotation term of 3.10).
        let (mut sx, mut sy) = (0.0, 0.0);
        for (l, w) in lines.iter().zip(&w_ang) {
            sx += w * l.3 * l.4.cos();
            sy += w * l.3 * l.4.sin();
        }
        let theta = if sx == 0.0 && sy == 0.0 {
            pose.rotation
        } else {
            sy.atan2(sx)
        };
        // (x, y, ε): rows [−a, −b, −d0]·[x, y, ε] = c + d0 ... from n·c_centre + c_j + d0(1+ε) = 0.
        // A tiny prior towards the coarse pose keeps the system solvable when the support does
        // not constrain every direction (e.g. only parallel edges); it is 10⁻⁶ of the data weight.
        let prior = 1e-6 * total_len;
        let mut ata = nalgebra::Matrix3::<f64>::identity() * prior;
        let mut atb = Vector3::new(start.centre.x, start.centre.y, start.scale - 1.0) * prior;
        for (l, w) in lines.iter().zip(&w_dist) {
            let row = Vector3::new(l.0.x, l.0.y, l.2);
            let rhs = -l.1 - l.2;
            let wt = w * l.3;
            ata += row * row.transpose() * wt;
            atb += row * (rhs * wt);
        }
        let sol = ata.cholesky().ok_or(DetectError::RankDeficient {
            reason: "IRLS normal equations of (x, y, ε) are not positive definite".into(),
        })?;
        let x = sol.solve(&atb);
        let new = PolygonPose {
            centre: Vector2::new(x[0], x[1]),
            rotation: theta,
            scale: 1.0 + x[2],
        };
        // Residuals and Tukey weights (scale from the MAD, floored).
        let rd: Vec<f64> = lines
            .iter()
            .map(|l| l.0.dot(&new.centre) + l.1 + l.2 * new.scale)
            .collect();
        let ra: Vec<f64> = lines.iter().map(|l| wrap(l.4 - theta)).collect();
        tukey(&rd, 0.05, &mut w_dist);
        tukey(&ra, 0.002, &mut w_ang);
        let change = (new.centre - pose.centre).norm()
            + (new.scale - pose.scale).abs()
            + (new.rotation - pose.rotation).abs();
        pose = new;
        if change < 1e-10 {
            break;
        }
    }
    if !(pose.centre.x.is_finite()
        && pose.centre.y.is_finite()
        && pose.scale.is_finite()
        && pose.scale > 0.0)
    {
        return Err(DetectError::Degenerate {
            reason: format!("IRLS diverged to {pose:?}"),
        });
    }
    Ok(pose)
}

/// Tukey biweight weights with `c = 4.685 · max(1.4826·MAD, floor)`.
fn tukey(r: &[f64], floor: f64, w: &mut [f64]) {
    let mut a: Vec<f64> = r.iter().map(|x| x.abs()).collect();
    a.sort_by(f64::total_cmp);
    let mad = a.get(a.len() / 2).copied().unwrap_or(0.0);
    let c = 4.685 * (1.4826 * mad).max(floor);
    for (wi, ri) in w.iter_mut().zip(r) {
        let u = ri / c;
        *wi = if u.abs() < 1.0 {
            (1.0 - u * u).powi(2)
        } else {
            0.0
        };
    }
}

/// Input of [`detect_polygon`]: an image (segments are detected) or segments.
#[derive(Debug, Clone, Copy)]
pub enum PolygonInput<'a> {
    /// A grey image and the segment detector's options.
    Image(&'a GrayImage, &'a SegmentOptions),
    /// Image segments (oriented with the dark side on the left if `PolygonOptions::oriented`).
    Segments(&'a [Segment]),
}

/// Detects the template polygon (seed §3.3, eq. (3.8)–(3.10)); see the module docs.
/// `homography` maps reference-plane points to pixels; `template` holds the polygon's vertices
/// relative to its centre, in reference units.
///
/// Errors: template with fewer than 3 vertices, NaN, repeated vertices or zero area; singular or
/// non-finite homography; invalid options; no segment (`TooFewPoints`); no vote (`Degenerate`).
pub fn detect_polygon(
    input: PolygonInput<'_>,
    template: &[Vector2<f64>],
    homography: &Matrix3<f64>,
    opts: &PolygonOptions,
) -> Result<PolygonDetection> {
    validate_options(opts)?;
    let t = normalise_template(template)?;
    for (i, &v) in homography.iter().enumerate() {
        if !v.is_finite() {
            return Err(DetectError::NonFinite {
                what: "homography",
                index: i,
                value: v,
            });
        }
    }
    let hinv = homography
        .try_inverse()
        .filter(|m| m.iter().all(|v| v.is_finite()))
        .ok_or_else(|| DetectError::Degenerate {
            reason: format!(
                "the homography is singular (det = {:e})",
                homography.determinant()
            ),
        })?;
    let segs: Vec<Segment> = match input {
        PolygonInput::Image(img, so) => detect_segments(img, so)?,
        PolygonInput::Segments(s) => {
            for (i, seg) in s.iter().enumerate() {
                for v in [seg.a.x, seg.a.y, seg.b.x, seg.b.y] {
                    if !v.is_finite() {
                        return Err(DetectError::NonFinite {
                            what: "segments",
                            index: i,
                            value: v,
                        });
                    }
                }
            }
            s.to_vec()
        }
    };
    if segs.is_empty() {
        return Err(DetectError::TooFewPoints {
            what: "segments",
            got: 0,
            needed: 1,
        });
    }
    let refs = to_reference(&segs, &hinv);
    let e = edges(&t);
    let hough = vote(&refs, &e, opts)?;
    let (r, s, centre, votes) = best_cell(&hough, opts).ok_or_else(|| DetectError::Degenerate {
        reason: "no segment matched any template edge".into(),
    })?;
    let (_, scales) = grids(opts);
    let coarse = PolygonPose {
        centre,
        rotation: opts.rotation_nominal - opts.rotation_range
            + (r as f64 + 0.5) * opts.rotation_step,
        scale: scales[s],
    };
    // Two rounds: support from the coarse pose, IRLS, support again from the refined pose, IRLS.
    let coarse_opts = PolygonOptions {
        support_distance: opts.support_distance.max(1.5 * opts.cell),
        ..opts.clone()
    };
    let mut sup = support(&refs, &e, &coarse, &coarse_opts);
    let mut pose = irls(&refs, &e, &sup, &coarse, opts)?;
    let sup2 = support(&refs, &e, &pose, opts);
    if sup2.len() >= 2 {
        sup = sup2;
        pose = irls(&refs, &e, &sup, &pose, opts)?;
    }
    let mut ss = 0.0;
    let mut cnt = 0usize;
    for &(j, k) in &sup {
        if let Some(seg) = refs[j] {
            let n = rot(pose.rotation, &e[k].normal);
            for p in [seg.a, seg.b] {
                let d = n.dot(&(p - pose.centre)) - pose.scale * e[k].d0;
                ss += d * d;
                cnt += 1;
            }
        }
    }
    let centre_image =
        apply_h(homography, &pose.centre).ok_or_else(|| DetectError::Degenerate {
            reason: "the detected centre maps to infinity".into(),
        })?;
    Ok(PolygonDetection {
        pose,
        coarse,
        votes,
        support: sup,
        segments: segs,
        centre_image,
        rms: if cnt > 0 {
            (ss / cnt as f64).sqrt()
        } else {
            0.0
        },
        vote_map: VoteMap {
            data: hough.slice(r, s).to_vec(),
            rows: hough.rows,
            cols: hough.cols,
            origin: hough.origin,
            cell: opts.cell,
        },
    })
}

#[cfg(test)]
mod tests;
