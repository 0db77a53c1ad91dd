//! Splitting edge chains into arcs that each lie in one quadrant of their ellipse, with the
//! quadrant class, curvature and noise of each arc (Fornaciari, Prati & Cucchiara 2014; seed
//! 000_3b1454b2b2194811.txt §3.2); step 3 of the pipeline in [`crate::edges`].

#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;

/// Options of [`split_arcs`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcParams {
    /// Tolerance (pixels) of the polygonal approximation. Default 1.
    pub polygon_tolerance: f64,
    /// Turn (radians) between consecutive polygon sides above which the chain is cut (a
    /// corner). Default 50°.
    pub corner_angle: f64,
    /// Fewest edge points of an arc. Default 16.
    pub min_points: usize,
    /// An arc whose points all lie within this distance (pixels) of its chord is straight and
    /// rejected. Default 1.5.
    pub straight_tolerance: f64,
    /// Largest mean curvature (1/pixels) of an arc; higher is clutter. Default 0.25 (radius
    /// 4 px).
    pub max_curvature: f64,
    /// Placement of inflections: when the polygon's turn changes sign at a vertex and the
    /// points since the vertex of the last turn already bend the new way by more than this
    /// many standard errors of the chain's edge noise (a parabola fitted to them), the cut goes
    /// at that earlier vertex instead (see [`split_arcs`]). 0 always cuts at the later vertex
    /// (the plain polygon rule). Default 0 (off): at 3 it recovers rims on the wafer benchmark
    /// (recall 0.8249 → 0.8350 on seed 3, 0.7941 → 0.8074 on seed 4) but most recovered thin
    /// disturbance rims (b 5–10 px) still fit 0.5–1.5 % wide in `a`, so precision drops
    /// (0.9048 → 0.8877, 0.8955 → 0.8855); switch it on once those rims fit within 1 %.
    pub inflection_sigmas: f64,
    /// A vertex where the chain is cut (corner, inflection or quadrant change) starts a new
    /// piece, and its turn — the turn between the two pieces, not one inside the new piece —
    /// is not what the next vertex's turn is compared with for an inflection (see
    /// [`split_arcs`]). Without it, where a foreign contour joins a rim at the rim's tip (a thin
    /// rim's edge running on into a slot tooth's edge: a quadrant change at the junction), the
    /// junction's turn, opposite to the rim's, makes the rim's first own vertex an
    /// "inflection", and the side between them is cut off (and dropped as straight on a flat
    /// rim). Default true: on the wafer benchmark it recovers rims (recall 0.8698 → 0.8857 on
    /// seed 3, 0.8500 → 0.8662 on seed 4), but many recovered thin disturbance rims (b 5–10 px,
    /// seen along the front arc only) fit 1–5 % off in `b`, so on its own precision drops
    /// (0.9435 → 0.9301, 0.9398 → 0.9320); with the `σ_b` test of
    /// `DetectParams::max_relative_sigma_b` (which rejects most of those near-misses) both rise.
    pub restart_turn_at_cuts: bool,
    /// Straightness is a property of a convex run, not of one quadrant piece of it: a piece
    /// within `straight_tolerance` of its chord is kept when a cut that is only a quadrant
    /// change (no corner, no inflection) joins it to a neighbouring piece of the same chain
    /// that is kept as an arc, and its points bend the run's way significantly (the parabola
    /// test of the inflection rule at [`KEPT_FLAT_PIECE_SIGMAS`] standard errors of the
    /// chain's edge noise). On a flat rim (b/a ≲ 0.1) the half of the front arc between its
    /// lowest point and a foreign contour's junction sags only 0.5–1.5 px: dropped as straight
    /// it left the rim one arc, and a lone arc makes no segment (on the wafer benchmark, 8 of
    /// the 11 missed target lower rims of seed 3 and 8 of 12 of seed 4). Default true.
    pub keep_flat_run_pieces: bool,
}

/// Significance (standard errors of the chain's edge noise) of the bend of a flat piece kept
/// by [`ArcParams::keep_flat_run_pieces`].
pub const KEPT_FLAT_PIECE_SIGMAS: f64 = 3.0;

impl Default for ArcParams {
    fn default() -> Self {
        Self {
            polygon_tolerance: 1.0,
            corner_angle: 50f64.to_radians(),
            min_points: 16,
            straight_tolerance: 1.5,
            max_curvature: 0.25,
            inflection_sigmas: 0.0,
            restart_turn_at_cuts: true,
            keep_flat_run_pieces: true,
        }
    }
}

impl ArcParams {
    fn validate(&self) -> Result<()> {
        let checks = [
            ("polygon_tolerance", self.polygon_tolerance, 0.0, 100.0),
            ("corner_angle", self.corner_angle, 0.0, std::f64::consts::PI),
            ("straight_tolerance", self.straight_tolerance, 0.0, 1e6),
            ("max_curvature", self.max_curvature, 0.0, 1e6),
        ];
        for (what, value, lo, hi) in checks {
            if !(value > lo && value <= hi) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "out of range",
                });
            }
        }
        if !(self.inflection_sigmas >= 0.0 && self.inflection_sigmas.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what: "inflection_sigmas",
                value: self.inflection_sigmas,
                reason: "must be finite and >= 0",
            });
        }
        if self.min_points < 5 {
            return Err(DetectError::InvalidParameter {
                what: "min_points",
                value: self.min_points as f64,
                reason: "an arc needs at least 5 points to constrain an ellipse",
            });
        }
        Ok(())
    }
}

/// The quadrant class of an arc (Fornaciari et al. 2014): which quarter of an ellipse, in the
/// displayed image (u right, v down), it can belong to. `I` is the upper-right quarter, `II`
/// the upper-left, `III` the lower-left, `IV` the lower-right (counter-clockwise on screen).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quadrant {
    /// Upper-right quarter: bulges toward +u and −v.
    I,
    /// Upper-left quarter: bulges toward −u and −v.
    II,
    /// Lower-left quarter: bulges toward −u and +v.
    III,
    /// Lower-right quarter: bulges toward +u and +v.
    IV,
}

impl Quadrant {
    /// `(sign u, sign v)` of the direction in which the arc bulges (away from its ellipse's
    /// centre).
    pub fn bulge(self) -> (f64, f64) {
        match self {
            Quadrant::I => (1.0, -1.0),
            Quadrant::II => (-1.0, -1.0),
            Quadrant::III => (-1.0, 1.0),
            Quadrant::IV => (1.0, 1.0),
        }
    }
}

/// An arc: edge points of one convex, single-quadrant piece of an edge chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Arc {
    /// Sub-pixel edge points, in chain order.
    pub points: Vec<Vector2<f64>>,
    /// Unit gradient directions (dark → bright) at the points.
    pub normals: Vec<Vector2<f64>>,
    /// Mean gradient magnitude (grey levels per pixel): the contrast of the edge.
    pub contrast: f64,
    /// The quadrant class.
    pub quadrant: Quadrant,
    /// `+1` if the gradient points to the convex side (away from the centre of curvature,
    /// brighter outside), `−1` if it points to the concave side.
    pub polarity: i8,
    /// Mean curvature (1/pixels): total turn of the polygon over its length.
    pub curvature: f64,
    /// Total turn of the arc's tangent (radians).
    pub turn: f64,
}

/// Ramer–Douglas–Peucker simplification: indices of the kept vertices (first and last always).
fn rdp(points: &[Vector2<f64>], tol: f64) -> Vec<usize> {
    let n = points.len();
    if n < 3 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let (a, b) = (points[i], points[j]);
        let d = b - a;
        let len = d.norm();
        let mut best = (0.0, i);
        for (k, p) in points.iter().enumerate().take(j).skip(i + 1) {
            let dist = if len > 0.0 {
                ((p - a).perp(&d) / len).abs()
            } else {
                (p - a).norm()
            };
            if dist > best.0 {
                best = (dist, k);
            }
        }
        if best.0 > tol {
            keep[best.1] = true;
            stack.push((i, best.1));
            stack.push((best.1, j));
        }
    }
    (0..n).filter(|&k| keep[k]).collect()
}

/// Robust standard deviation (pixels) of a chain's edge points across the chain: the median
/// absolute distance of each point to the chord of its neighbours three points away, scaled to
/// a Gaussian σ (1.4826 · MAD; for independent noise that distance has variance 1.5 σ²).
/// Floored at 0.01 px.
pub(crate) fn chain_noise(pts: &[Vector2<f64>]) -> f64 {
    const K: usize = 3;
    if pts.len() < 2 * K + 1 {
        return 0.01;
    }
    let mut d: Vec<f64> = (K..pts.len() - K)
        .filter_map(|i| {
            let chord = pts[i + K] - pts[i - K];
            let len = chord.norm();
            (len > 0.0).then(|| (chord.perp(&(pts[i] - pts[i - K])) / len).abs())
        })
        .collect();
    if d.is_empty() {
        return 0.01;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    (1.4826 * *m / 1.5f64.sqrt()).max(0.01)
}

/// Whether the points `pts[i..=j]` bend significantly toward `sign` (+1: to the left of the
/// chord `pts[j] − pts[i]`, the side a positive polygon turn bends to): the quadratic
/// coefficient of the least-squares parabola `across = c₀ + c₁ s + c₂ s²` in the chord frame
/// (`s` ∈ [−1, 1] along the chord) has that sign and exceeds `sigmas` of its standard error
/// `σ √((XᵀX)⁻¹)₂₂` under edge noise `sigma`. A local model over the whole side, not the
/// turn at one polygon vertex (which the noise of that one point moves by a degree or two on
/// a nearly straight arc).
pub(super) fn side_bends(
    pts: &[Vector2<f64>],
    i: usize,
    j: usize,
    sign: f64,
    sigma: f64,
    sigmas: f64,
) -> bool {
    let Some(side) = pts.get(i..=j) else {
        return false;
    };
    let a = pts[i];
    let chord = pts[j] - a;
    let len2 = chord.norm_squared();
    if !(len2 > 0.0) || side.len() < 5 {
        return false;
    }
    let len = len2.sqrt();
    let mut xtx = Matrix3::<f64>::zeros();
    let mut xty = Vector3::<f64>::zeros();
    for p in side {
        let s = 2.0 * (p - a).dot(&chord) / len2 - 1.0;
        let across = chord.perp(&(p - a)) / len;
        let x = Vector3::new(1.0, s, s * s);
        xtx += x * x.transpose();
        xty += x * across;
    }
    let Some(inv) = xtx.try_inverse() else {
        return false;
    };
    let c2 = (inv * xty)[2];
    let se = sigma * inv[(2, 2)].max(0.0).sqrt();
    c2 * sign > sigmas * se
}

/// Splits edge chains into arcs and classifies them (000_3b1454b2b2194811.txt §3.2, first
/// stage: "extracts arcs from the edge image and filters out short and non-convex arcs"; the
/// quadrant classes of [37, 40] from "gradients and difference between areas over and under
/// the arc"; "curvature estimation for outlier rejection", Fig. 3.3).
///
/// Each chain is approximated by a polygon (Ramer–Douglas–Peucker, `polygon_tolerance`) and
/// cut at vertices where the turn exceeds `corner_angle` (corners), where the turn changes sign
/// (inflections, so arcs are convex; the cut goes at the earlier of the two vertices bounding
/// the sign change when the points between them already bend the new way, tested against the
/// chain's edge noise with `inflection_sigmas`: on a nearly straight arc the polygon's first
/// vertex after a foreign contour's junction turns the arc's way by only a few degrees, and
/// cutting there lost the side to a piece rejected as straight), and where the direction of
/// the sides changes quadrant
/// (the extreme points of an ellipse, so arcs are monotone in u and v). With
/// `restart_turn_at_cuts`, the turn at a cut vertex lies between two pieces and does not count
/// toward the next piece's convexity: an inflection is a sign change between two vertices
/// inside one piece. The curvature of each
/// piece (total turn over length) rejects pieces curved more than `max_curvature` (texture,
/// noise); pieces with fewer than `min_points` points or within `straight_tolerance` of their
/// chord (lines, e.g. the carrier's ridges) are dropped. The quadrant follows from the sign of
/// the chord's slope and of the area between arc and chord; the polarity from the mean
/// gradient relative to the bulge direction.
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters.
pub fn split_arcs(map: &EdgeMap, chains: &[Vec<u32>], params: &ArcParams) -> Result<Vec<Arc>> {
    params.validate()?;
    let mut arcs = Vec::new();
    for chain in chains {
        if chain.len() < params.min_points {
            continue;
        }
        let pts: Vec<Vector2<f64>> = chain.iter().map(|&k| map.edgels[k as usize].pos).collect();
        let verts = rdp(&pts, params.polygon_tolerance);
        let sigma = if params.inflection_sigmas > 0.0 {
            chain_noise(&pts)
        } else {
            0.0
        };
        // Cut points (indices into `pts`), and per cut the turn sign of the convex run it
        // splits when it is only a quadrant change (`None`: the run ends there).
        let mut cuts = vec![0usize];
        let mut run_turn: Vec<Option<f64>> = vec![None];
        let mut last_turn_sign = 0.0;
        // The vertex (index into `pts`) that set `last_turn_sign`.
        let mut last_vertex: Option<usize> = None;
        for w in verts.windows(3) {
            let d0 = pts[w[1]] - pts[w[0]];
            let d1 = pts[w[2]] - pts[w[1]];
            let turn = d0.perp(&d1).atan2(d0.dot(&d1));
            let sign = turn.signum();
            let corner = turn.abs() > params.corner_angle;
            let inflection = last_turn_sign != 0.0 && sign != last_turn_sign && turn.abs() > 1e-9;
            // Quadrant change: a component of the side direction changes sign.
            let quadrant_change = d0.x * d1.x < 0.0 || d0.y * d1.y < 0.0;
            // The inflection lies between the vertex of the last turn and this one. When the
            // points between them already bend this vertex's way, the chain changed convexity
            // at the earlier vertex (a foreign contour meeting the arc there): cut there, so
            // the side goes with the arc it belongs to.
            let earlier = match last_vertex {
                Some(v) if inflection && params.inflection_sigmas > 0.0 => {
                    side_bends(&pts, v, w[1], sign, sigma, params.inflection_sigmas).then_some(v)
                }
                _ => None,
            };
            if let Some(v) = earlier {
                if cuts.last().is_some_and(|&c| v > c) {
                    cuts.push(v);
                    run_turn.push(None);
                }
                if quadrant_change {
                    cuts.push(w[1]);
                    run_turn.push((!corner).then_some(sign));
                }
            } else if corner || inflection || quadrant_change {
                cuts.push(w[1]);
                run_turn.push((quadrant_change && !corner && !inflection).then_some(sign));
            }
            // A cut at this vertex (not moved to an earlier one) starts a new piece here.
            let cut_here = corner || quadrant_change || (inflection && earlier.is_none());
            if corner || (params.restart_turn_at_cuts && cut_here) {
                last_turn_sign = 0.0;
                last_vertex = None;
            } else if quadrant_change || turn.abs() > 1e-9 {
                last_turn_sign = sign;
                last_vertex = Some(w[1]);
            }
        }
        cuts.push(pts.len() - 1);
        run_turn.push(None);
        // Pieces `(start, end)`; consecutive pieces do not share their cut point.
        let pieces: Vec<(usize, usize)> = cuts
            .windows(2)
            .enumerate()
            .map(|(k, win)| (if k == 0 { win[0] } else { win[0] + 1 }, win[1]))
            .collect();
        let long = |&(s, e): &(usize, usize)| e >= s && e + 1 - s >= params.min_points;
        let mut made: Vec<Option<Arc>> = pieces
            .iter()
            .map(|p| {
                long(p)
                    .then(|| make_arc(map, chain, &pts, p.0, p.1, params, false))
                    .flatten()
            })
            .collect();
        if params.keep_flat_run_pieces {
            let mut noise = None;
            for k in 0..pieces.len() {
                if made[k].is_some() || !long(&pieces[k]) {
                    continue;
                }
                // The run's turn sign across the cut before (after) piece `k`, when the
                // neighbour there is an arc.
                let before = run_turn[k].filter(|_| k > 0 && made[k - 1].is_some());
                let after =
                    run_turn[k + 1].filter(|_| made.get(k + 1).is_some_and(Option::is_some));
                let Some(sign) = before.or(after) else {
                    continue;
                };
                let sigma = *noise.get_or_insert_with(|| chain_noise(&pts));
                let (s, e) = pieces[k];
                if side_bends(&pts, s, e, sign, sigma, KEPT_FLAT_PIECE_SIGMAS) {
                    made[k] = make_arc(map, chain, &pts, s, e, params, true);
                }
            }
        }
        arcs.extend(made.into_iter().flatten());
    }
    Ok(arcs)
}

/// Builds and screens the arc `pts[s..=e]` (`flat_ok`: without the straightness test, for a
/// piece of a curved run, see [`ArcParams::keep_flat_run_pieces`]).
fn make_arc(
    map: &EdgeMap,
    chain: &[u32],
    pts: &[Vector2<f64>],
    s: usize,
    e: usize,
    params: &ArcParams,
    flat_ok: bool,
) -> Option<Arc> {
    let points = pts[s..=e].to_vec();
    let (a, b) = (points[0], points[points.len() - 1]);
    let chord = b - a;
    let len = chord.norm();
    if !(len > 0.0) {
        return None;
    }
    // Signed distances to the chord; area between arc and chord (trapezoids).
    let mut max_dev: f64 = 0.0;
    let mut area = 0.0;
    let mut prev: Option<(f64, f64)> = None;
    for p in &points {
        let along = (p - a).dot(&chord) / len;
        let across = chord.perp(&(p - a)) / len;
        max_dev = max_dev.max(across.abs());
        if let Some((pa, pc)) = prev {
            area += 0.5 * (across + pc) * (along - pa);
        }
        prev = Some((along, across));
    }
    if max_dev < params.straight_tolerance && !flat_ok {
        return None;
    }
    // Bulge direction: the unit normal of the chord on the side where the area between arc
    // and chord is (`across` is the signed distance along `left`).
    let left = Vector2::new(-chord.y, chord.x) / len;
    let bulge = if area > 0.0 { left } else { -left };
    let quadrant = match (bulge.x >= 0.0, bulge.y >= 0.0) {
        (true, false) => Quadrant::I,
        (false, false) => Quadrant::II,
        (false, true) => Quadrant::III,
        (true, true) => Quadrant::IV,
    };
    // Curvature and turn from a coarse polygon of the arc.
    let verts = rdp(&points, params.polygon_tolerance * 0.5);
    let mut turn = 0.0;
    let mut length = 0.0;
    for k in 1..verts.len() {
        length += (points[verts[k]] - points[verts[k - 1]]).norm();
    }
    for k in 1..verts.len().saturating_sub(1) {
        let d0 = points[verts[k]] - points[verts[k - 1]];
        let d1 = points[verts[k + 1]] - points[verts[k]];
        turn += d0.perp(&d1).atan2(d0.dot(&d1)).abs();
    }
    // A single side: the turn is at least the sagitta angle.
    let turn = turn.max(4.0 * max_dev / len);
    let curvature = if length > 0.0 { turn / length } else { 0.0 };
    if curvature > params.max_curvature {
        return None;
    }
    let mut normals = Vec::with_capacity(points.len());
    let mut contrast = 0.0;
    let mut pol = 0.0;
    for &k in &chain[s..=e] {
        let g = map.edgels[k as usize].grad;
        let gn = g.norm();
        contrast += gn;
        let u = if gn > 0.0 { g / gn } else { Vector2::zeros() };
        pol += u.dot(&bulge);
        normals.push(u);
    }
    contrast /= points.len() as f64;
    Some(Arc {
        points,
        normals,
        contrast,
        quadrant,
        polarity: if pol >= 0.0 { 1 } else { -1 },
        curvature,
        turn,
    })
}

thread_local! {
    /// The [`EdgeWorkspace`] of [`detect_arcs`] on this thread.
    static EDGE_WORKSPACE: std::cell::RefCell<EdgeWorkspace> =
        std::cell::RefCell::new(EdgeWorkspace::new());
}

/// [`canny`], [`link_edges`] and [`split_arcs`] with the given parameters.
///
/// The edge map comes from an [`EdgeWorkspace`] kept per thread (the whole-image buffers are
/// allocated once per thread and image size, not per call; same result as [`canny`]); a nested
/// call on the same thread (a rayon worker that picks up another detection while this one
/// waits) uses a fresh workspace. [`detect_arcs_with`] takes the workspace from the caller.
///
/// # Errors
/// As the three steps.
pub fn detect_arcs<T: Pixel>(
    image: &GrayView<'_, T>,
    canny_params: &CannyParams,
    link_params: &LinkParams,
    arc_params: &ArcParams,
) -> Result<Vec<Arc>> {
    EDGE_WORKSPACE.with(|cell| match cell.try_borrow_mut() {
        Ok(mut ws) => detect_arcs_with(&mut ws, image, canny_params, link_params, arc_params),
        Err(_) => detect_arcs_with(
            &mut EdgeWorkspace::new(),
            image,
            canny_params,
            link_params,
            arc_params,
        ),
    })
}

/// [`detect_arcs`] with the edge map computed in `workspace` ([`EdgeWorkspace::canny`]).
///
/// # Errors
/// As the three steps.
pub fn detect_arcs_with<T: Pixel>(
    workspace: &mut EdgeWorkspace,
    image: &GrayView<'_, T>,
    canny_params: &CannyParams,
    link_params: &LinkParams,
    arc_params: &ArcParams,
) -> Result<Vec<Arc>> {
    let map = workspace.canny(image, canny_params)?;
    let chains = link_edges(map, link_params)?;
    split_arcs(map, &chains, arc_params)
}
