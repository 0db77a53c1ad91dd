//! Elliptic-segment assembly: the two-arc combination rule, Algorithms 1 and 2
//! (seed 000_3b1454b2b2194811.txt ch. 3.2, "Robust Elliptic Segments Detection Modifications").
//!
//! Arcs (from [`crate::edges::split_arcs`]) are combined in pairs: a pair is a candidate when
//! the arcs are of different quadrants, do not overlap when projected onto the ellipse fitted to
//! their union, and that fit's mean orthogonal residual `r(i, j)` is under the threshold (the
//! three rejection conditions of §3.2). Two cheap necessary conditions prune the pairs before
//! any fit: equal polarity (an ellipse's edge has one contrast sign all round; this is what
//! keeps the upper rim of a wafer, brighter outside, apart from its lower rim, brighter inside)
//! and the relative position of the quadrants (Fornaciari et al. 2014: a quadrant-II arc lies
//! left of a quadrant-I arc, above a quadrant-III arc, …), plus an optional largest gap.
//!
//! [`merge_arcs`] is Algorithm 1: bipartite matching (the Jonker–Volgenant solver of
//! [`crate::assignment`], with the dummy arc `v₀` of eq. (3.4) priced at the residual threshold)
//! on every connected component of the candidate graph, giving the valid elliptic segments
//! `S₀` and the remaining arcs `V₀`. [`merge_segments`] is Algorithm 2: segments are matched
//! against the remaining arcs and the other segments with the same rule, merged, refitted, and
//! the matching repeated until nothing merges. [`assemble`] runs both.

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::f64::consts::TAU;

use autoteach_geometry::conic::Ellipse;
use nalgebra::{DMatrix, Vector2};

use crate::assignment::solve_assignment_with_unassigned;
use crate::edges::{Arc, Quadrant};
use crate::ellipse::{EllipseFit, GeometricFitOptions, fit_screened};
use crate::{DetectError, Result};
use rayon::prelude::*;

/// Options of the assembly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssemblyParams {
    /// Largest mean orthogonal residual (pixels) of a combination (`threshold` of Algorithms
    /// 1–2). Default 0.25.
    pub residual_threshold: f64,
    /// Largest gap (pixels) between the nearest end points of two arcs or segments that are
    /// combined; `f64::INFINITY` for no limit. Default 60.
    pub max_gap: f64,
    /// Largest fraction of the points of either part that may project inside the other part's
    /// angular extent on the fitted ellipse before the parts count as overlapping. Default 0.05.
    pub max_overlap: f64,
    /// Largest semi-major axis (pixels) of a fitted ellipse; larger fits of short, flat pieces
    /// are rejected. Default 5000.
    pub max_semi_major: f64,
    /// Most iterations of Algorithm 2. Default 10.
    pub max_iterations: usize,
    /// Levenberg–Marquardt iterations of each fit. Default 20.
    pub fit_iterations: usize,
}

impl Default for AssemblyParams {
    fn default() -> Self {
        Self {
            residual_threshold: 0.25,
            max_gap: 60.0,
            max_overlap: 0.05,
            max_semi_major: 5000.0,
            max_iterations: 10,
            fit_iterations: 20,
        }
    }
}

impl AssemblyParams {
    fn validate(&self) -> Result<()> {
        let pos = [
            ("residual_threshold", self.residual_threshold),
            ("max_gap", self.max_gap),
            ("max_semi_major", self.max_semi_major),
        ];
        for (what, value) in pos {
            if !(value > 0.0) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "must be positive",
                });
            }
        }
        if !(self.max_overlap >= 0.0 && self.max_overlap < 1.0) {
            return Err(DetectError::InvalidParameter {
                what: "max_overlap",
                value: self.max_overlap,
                reason: "must be in [0, 1)",
            });
        }
        if self.fit_iterations == 0 {
            return Err(DetectError::InvalidParameter {
                what: "fit_iterations",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        Ok(())
    }
}

/// An elliptic segment: arcs that belong to one ellipse, with the fit of their union.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Indices of the arcs (into the slice given to [`assemble`]).
    pub arcs: Vec<usize>,
    /// The points of all arcs.
    pub points: Vec<Vector2<f64>>,
    /// The geometric fit of `points`.
    pub fit: EllipseFit,
    /// Polarity shared by the arcs (see [`Arc::polarity`]).
    pub polarity: i8,
}

impl Segment {
    /// The segment of the two arcs `i` and `j` of `arcs` with the fit `fit` of their union
    /// (points in that order; the polarity is the arcs' shared one).
    pub(crate) fn of_pair(arcs: &[Arc], i: usize, j: usize, fit: EllipseFit) -> Self {
        let mut points = arcs[i].points.clone();
        points.extend_from_slice(&arcs[j].points);
        Self {
            arcs: vec![i, j],
            points,
            fit,
            polarity: arcs[i].polarity,
        }
    }
}

/// A part being combined: an arc or a segment.
struct Part<'a> {
    points: &'a [Vector2<f64>],
    polarity: i8,
    quadrant: Option<Quadrant>,
    /// End points of the member arcs.
    ends: Vec<Vector2<f64>>,
    lo: Vector2<f64>,
    hi: Vector2<f64>,
    /// A segment's ellipse, for the cheap pre-check of Algorithm 2.
    ellipse: Option<Ellipse>,
}

impl<'a> Part<'a> {
    fn new(points: &'a [Vector2<f64>], polarity: i8, quadrant: Option<Quadrant>) -> Self {
        let mut lo = Vector2::repeat(f64::INFINITY);
        let mut hi = Vector2::repeat(f64::NEG_INFINITY);
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let ends = vec![
            points.first().copied().unwrap_or_default(),
            points.last().copied().unwrap_or_default(),
        ];
        Self {
            points,
            polarity,
            quadrant,
            ends,
            lo,
            hi,
            ellipse: None,
        }
    }
}

/// Tolerance (pixels) of the quadrant position constraints.
const POSITION_TOL: f64 = 2.0;

/// Fornaciari et al. (2014) relative positions of arcs of two quadrants of one ellipse: the
/// quarters are separated by the u of the top/bottom points and the v of the left/right points.
fn positions_compatible(a: &Part<'_>, b: &Part<'_>) -> bool {
    let (Some(qa), Some(qb)) = (a.quadrant, b.quadrant) else {
        return true;
    };
    let (ua, va) = qa.bulge();
    let (ub, vb) = qb.bulge();
    // Same side in u, different in v: the upper one (bulge −v) is above.
    if ua == ub && va != vb {
        let (up, down) = if va < 0.0 { (a, b) } else { (b, a) };
        return up.hi.y <= down.lo.y + POSITION_TOL;
    }
    // Same side in v, different in u: the left one is left.
    if va == vb && ua != ub {
        let (left, right) = if ua < 0.0 { (a, b) } else { (b, a) };
        return left.hi.x <= right.lo.x + POSITION_TOL;
    }
    // Opposite quarters: no cheap constraint (the fit decides).
    true
}

/// Smallest distance between the end points of two parts.
fn gap(a: &Part<'_>, b: &Part<'_>) -> f64 {
    let mut d = f64::INFINITY;
    for p in &a.ends {
        for q in &b.ends {
            d = d.min((p - q).norm());
        }
    }
    d
}

/// Angular extent `(start, length)` (eccentric angle, length in `[0, 2π)`) of an ordered run
/// of points given by their eccentric angles `ts` on the fitted ellipse, unwrapped along the
/// run.
pub(crate) fn extent(ts: &[f64]) -> (f64, f64) {
    let Some(&first) = ts.first() else {
        return (0.0, 0.0);
    };
    let mut t_prev = first;
    let mut acc = 0.0;
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for &t in &ts[1..] {
        let mut d = t - t_prev;
        d -= TAU * (d / TAU).round();
        acc += d;
        lo = lo.min(acc);
        hi = hi.max(acc);
        t_prev = t;
    }
    let start = first + lo;
    (start.rem_euclid(TAU), (hi - lo).min(TAU))
}

/// Fraction of the points with eccentric angles `ts` strictly inside the angular extent
/// `(start, len)` (with a margin of 1 % of the extent).
fn inside_fraction(ts: &[f64], (start, len): (f64, f64)) -> f64 {
    let margin = 0.01 * len;
    let n = ts
        .iter()
        .filter(|&&t| {
            let d = (t - start).rem_euclid(TAU);
            d > margin && d < len - margin
        })
        .count();
    n as f64 / ts.len().max(1) as f64
}

/// Whether two parts overlap when projected onto the fitted ellipse (the first rejection
/// condition of §3.2), from the eccentric angles of their points' foot points on it (`ta`,
/// `tb`: the same as [`Ellipse::parameter_of`] of each point).
fn overlap(ta: &[f64], tb: &[f64], max_overlap: f64) -> bool {
    inside_fraction(tb, extent(ta)) > max_overlap || inside_fraction(ta, extent(tb)) > max_overlap
}

/// Fits the union of two parts and applies the combination rule; the fit if accepted.
fn combine(a: &Part<'_>, b: &Part<'_>, params: &AssemblyParams) -> Option<(EllipseFit, f64)> {
    if a.polarity != b.polarity {
        return None;
    }
    if a.quadrant.is_some() && a.quadrant == b.quadrant {
        return None;
    }
    if !positions_compatible(a, b) || !(gap(a, b) <= params.max_gap) {
        return None;
    }
    // Algorithm 2 pre-check: a single arc far from a segment's ellipse cannot join it. (Two
    // segments are always fitted: each may extrapolate poorly over the other's extent.)
    let single = |p: &Part<'_>| p.ellipse.is_none();
    for (s, other) in [(a, b), (b, a)] {
        if let (Some(e), true) = (&s.ellipse, single(other)) {
            let far = other
                .points
                .iter()
                .step_by(4)
                .filter(|p| e.sampson_distance(p).abs() > 4.0 + 10.0 * params.residual_threshold)
                .count();
            if far * 4 > other.points.len() {
                return None;
            }
        }
    }
    let mut pts = Vec::with_capacity(a.points.len() + b.points.len());
    pts.extend_from_slice(a.points);
    pts.extend_from_slice(b.points);
    let opts = GeometricFitOptions {
        max_iterations: params.fit_iterations,
        ..GeometricFitOptions::default()
    };
    // The direct (algebraic) fit screens first: it is biased on partial arcs, but a
    // combination it fits worse than a few times the threshold is not an ellipse. The
    // geometric fit then starts from it (one preparation of the points for both).
    let (fit, angles) = fit_screened(&pts, 4.0 * params.residual_threshold, &opts).ok()??;
    let r = fit.residual_mean;
    if !(r < params.residual_threshold) || !(fit.ellipse.a <= params.max_semi_major) {
        return None;
    }
    let ts: Vec<f64> = angles.iter().map(|&(s, c)| s.atan2(c)).collect();
    let (ta, tb) = ts.split_at(a.points.len());
    if overlap(ta, tb, params.max_overlap) {
        return None;
    }
    Some((fit, r))
}

/// The combination rule of [`merge_arcs`] for two single arcs (polarity, quadrant classes and
/// relative position, gap up to `params.max_gap`, residual threshold, no overlap on the fitted
/// ellipse): the geometric fit of their union and the eccentric angle of each point on it
/// (first `a`'s points, then `b`'s), if the pair is accepted.
pub(crate) fn combine_arcs(
    a: &Arc,
    b: &Arc,
    params: &AssemblyParams,
) -> Option<(EllipseFit, Vec<f64>)> {
    let pa = Part::new(&a.points, a.polarity, Some(a.quadrant));
    let pb = Part::new(&b.points, b.polarity, Some(b.quadrant));
    let (fit, _) = combine(&pa, &pb, params)?;
    let ts = a
        .points
        .iter()
        .chain(&b.points)
        .map(|p| fit.ellipse.parameter_of(p))
        .collect();
    Some((fit, ts))
}

/// Union–find root.
fn root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Pairs chosen by a matching of the symmetric candidate costs of one component: the
/// assignment (rows and columns = the component's parts, dummy `v₀` at `threshold`) and, since
/// a symmetric problem may map `i → j → k`, the assigned pairs taken in order of cost with each
/// part used once.
fn match_component(
    members: &[usize],
    cost: &dyn Fn(usize, usize) -> Option<f64>,
    threshold: f64,
) -> Result<Vec<(usize, usize)>> {
    let n = members.len();
    let mut c = DMatrix::from_element(n, n, f64::INFINITY);
    for (r, &i) in members.iter().enumerate() {
        for (k, &j) in members.iter().enumerate() {
            if r == k {
                continue;
            }
            if let Some(v) = cost(i, j) {
                c[(r, k)] = v;
            }
        }
    }
    let dummy = vec![threshold; n];
    let a = solve_assignment_with_unassigned(&c, &dummy, &dummy)?;
    let mut chosen: Vec<(f64, usize, usize)> = a
        .pairs()
        .into_iter()
        .map(|(r, k)| (c[(r, k)], members[r], members[k]))
        .collect();
    chosen.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut used = std::collections::HashSet::new();
    let mut out = Vec::new();
    for (_, i, j) in chosen {
        if !used.contains(&i) && !used.contains(&j) {
            used.insert(i);
            used.insert(j);
            out.push((i, j));
        }
    }
    Ok(out)
}

/// Algorithm 1 (arc merging, 000_3b1454b2b2194811.txt §3.2, eq. 3.4): the candidate graph of
/// arc pairs under the combination rule, decomposed into connected components, each solved as a
/// bipartite matching with a dummy arc `v₀` at the residual threshold. Returns the valid
/// elliptic segments `S₀` and the indices of the remaining arcs `V₀`.
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters.
pub fn merge_arcs(arcs: &[Arc], params: &AssemblyParams) -> Result<(Vec<Segment>, Vec<usize>)> {
    params.validate()?;
    let parts: Vec<Part<'_>> = arcs
        .iter()
        .map(|a| Part::new(&a.points, a.polarity, Some(a.quadrant)))
        .collect();
    let n = parts.len();
    // The combination tests of all pairs are independent: evaluated in parallel (rayon),
    // collected in the sequential order (i, then j), so the graph is built as before.
    let accepted: Vec<((usize, usize), (EllipseFit, f64))> = (0..n)
        .into_par_iter()
        .flat_map_iter(|i| {
            let parts = &parts;
            (i + 1..n)
                .filter_map(move |j| combine(&parts[i], &parts[j], params).map(|f| ((i, j), f)))
        })
        .collect();
    let mut fits = std::collections::HashMap::new();
    let mut parent: Vec<usize> = (0..n).collect();
    for ((i, j), f) in accepted {
        fits.insert((i, j), f);
        let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
        parent[ri] = rj;
    }
    let mut components: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for i in 0..n {
        let r = root(&mut parent, i);
        components.entry(r).or_default().push(i);
    }
    let mut matched = Vec::new();
    {
        let cost = |i: usize, j: usize| fits.get(&(i.min(j), i.max(j))).map(|(_, r)| *r);
        for members in components.values().filter(|m| m.len() >= 2) {
            matched.extend(match_component(members, &cost, params.residual_threshold)?);
        }
    }
    let mut used = vec![false; n];
    let mut segments = Vec::new();
    {
        for (i, j) in matched {
            let Some((fit, _)) = fits.remove(&(i.min(j), i.max(j))) else {
                continue;
            };
            used[i] = true;
            used[j] = true;
            segments.push(Segment::of_pair(arcs, i, j, fit));
        }
    }
    let rest = (0..n).filter(|&i| !used[i]).collect();
    Ok((segments, rest))
}

/// Algorithm 2 (ellipse merging, 000_3b1454b2b2194811.txt §3.2): each iteration matches the
/// segments against the remaining arcs and the other segments (combination rule without the
/// quadrant condition, which only applies to single arcs; cost = residual of the union's fit;
/// dummy at the threshold), merges the matched pairs and refits them, until an iteration merges
/// nothing or `max_iterations` is reached. Returns the final segments and remaining arcs.
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters.
pub fn merge_segments(
    arcs: &[Arc],
    mut segments: Vec<Segment>,
    mut rest: Vec<usize>,
    params: &AssemblyParams,
) -> Result<(Vec<Segment>, Vec<usize>)> {
    params.validate()?;
    // Combination results by (arcs of the segment, arcs of the other part, whether that part is
    // a segment): a pair that is unchanged from one iteration to the next gives the same result
    // (the parts' points, ends and ellipses follow from their arcs), so it is not refitted.
    type Key = (Vec<usize>, Vec<usize>, bool);
    let mut cache: std::collections::HashMap<Key, Option<(EllipseFit, f64)>> =
        std::collections::HashMap::new();
    for _ in 0..params.max_iterations {
        let ns = segments.len();
        // Parts 0..ns are segments, ns.. the remaining arcs.
        let mut parts: Vec<Part<'_>> = segments
            .iter()
            .map(|s| {
                let mut p = Part::new(&s.points, s.polarity, None);
                p.ellipse = Some(s.fit.ellipse);
                p.ends = s
                    .arcs
                    .iter()
                    .flat_map(|&k| {
                        let q = &arcs[k].points;
                        [q[0], q[q.len() - 1]]
                    })
                    .collect();
                p
            })
            .collect();
        parts.extend(
            rest.iter()
                .map(|&k| Part::new(&arcs[k].points, arcs[k].polarity, None)),
        );
        let n = parts.len();
        let pairs: Vec<(usize, usize, Key)> = (0..ns)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .map(|(i, j)| {
                let other = if j < ns {
                    segments[j].arcs.clone()
                } else {
                    vec![rest[j - ns]]
                };
                (i, j, (segments[i].arcs.clone(), other, j < ns))
            })
            .collect();
        // The pairs not in the cache are combined in parallel (rayon), then cached.
        let missing: Vec<&(usize, usize, Key)> = pairs
            .iter()
            .filter(|(_, _, k)| !cache.contains_key(k))
            .collect();
        let computed: Vec<Option<(EllipseFit, f64)>> = missing
            .par_iter()
            .map(|&&(i, j, _)| combine(&parts[i], &parts[j], params))
            .collect();
        for (&(_, _, k), r) in missing.iter().zip(computed) {
            cache.insert(k.clone(), r);
        }
        let mut fits = std::collections::HashMap::new();
        let mut parent: Vec<usize> = (0..n).collect();
        for (i, j, k) in &pairs {
            if let Some(Some(f)) = cache.get(k) {
                fits.insert((*i, *j), f.clone());
                let (ri, rj) = (root(&mut parent, *i), root(&mut parent, *j));
                parent[ri] = rj;
            }
        }
        if fits.is_empty() {
            break;
        }
        let mut components: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
        for i in 0..n {
            let r = root(&mut parent, i);
            components.entry(r).or_default().push(i);
        }
        let mut matched = Vec::new();
        {
            let cost = |i: usize, j: usize| fits.get(&(i.min(j), i.max(j))).map(|(_, r)| *r);
            for members in components.values().filter(|m| m.len() >= 2) {
                matched.extend(match_component(members, &cost, params.residual_threshold)?);
            }
        }
        let mut new_segments = Vec::new();
        let mut consumed = vec![false; n];
        {
            for (i, j) in matched {
                let (i, j) = (i.min(j), i.max(j));
                let Some((fit, _)) = fits.remove(&(i, j)) else {
                    continue;
                };
                consumed[i] = true;
                consumed[j] = true;
                let mut ids = segments[i].arcs.clone();
                let mut points = segments[i].points.clone();
                if j < ns {
                    ids.extend_from_slice(&segments[j].arcs);
                    points.extend_from_slice(&segments[j].points);
                } else {
                    let k = rest[j - ns];
                    ids.push(k);
                    points.extend_from_slice(&arcs[k].points);
                }
                new_segments.push(Segment {
                    arcs: ids,
                    points,
                    fit,
                    polarity: segments[i].polarity,
                });
            }
        }
        if new_segments.is_empty() {
            break;
        }
        let mut next: Vec<Segment> = new_segments;
        for (i, s) in segments.into_iter().enumerate() {
            if !consumed[i] {
                next.push(s);
            }
        }
        rest = rest
            .iter()
            .enumerate()
            .filter(|(k, _)| !consumed[ns + k])
            .map(|(_, &a)| a)
            .collect();
        segments = next;
    }
    Ok((segments, rest))
}

/// Algorithms 1 and 2 of 000_3b1454b2b2194811.txt §3.2: [`merge_arcs`] then
/// [`merge_segments`]. Returns the elliptic segments (each of at least two arcs).
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters.
pub fn assemble(arcs: &[Arc], params: &AssemblyParams) -> Result<Vec<Segment>> {
    let (s0, v0) = merge_arcs(arcs, params)?;
    let (segments, _) = merge_segments(arcs, s0, v0, params)?;
    Ok(segments)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::edges::Quadrant;

    /// A synthetic arc of `points` (unit normals along +y, contrast 50, curvature 0.01, turn 1).
    pub(crate) fn arc_from_points(
        points: Vec<Vector2<f64>>,
        quadrant: Quadrant,
        polarity: i8,
    ) -> Arc {
        Arc {
            normals: vec![Vector2::new(0.0, 1.0); points.len()],
            points,
            contrast: 50.0,
            quadrant,
            polarity,
            curvature: 0.01,
            turn: 1.0,
        }
    }

    /// Quarter arc `[t0, t1]` (eccentric angle) of `e` with a small deterministic wobble.
    fn arc(e: &Ellipse, t0: f64, t1: f64, quadrant: Quadrant, polarity: i8) -> Arc {
        let n = 150;
        let points: Vec<Vector2<f64>> = (0..n)
            .map(|i| {
                let t = t0 + (t1 - t0) * i as f64 / (n - 1) as f64;
                let p = e.point_at(t);
                let w = 0.05 * ((i * 7919) % 13) as f64 / 13.0 - 0.025;
                p + Vector2::new(w, -w)
            })
            .collect();
        arc_from_points(points, quadrant, polarity)
    }

    #[test]
    fn fig_3_6_two_close_ellipses_are_assembled_correctly() {
        // Two concentric-ish elliptic segments 0.6 px apart, each broken into two quarter arcs
        // (lower-left III and lower-right IV in the image, v down), all of one polarity: every
        // cross combination also fits with a small residual; the matching must pick the true
        // pairs (Fig. 3.6 of the seed).
        let e1 = Ellipse::new(400.0, 200.0, 300.0, 60.0, 0.01).unwrap();
        let e2 = Ellipse::new(400.0, 200.6, 300.2, 60.5, 0.01).unwrap();
        let h = std::f64::consts::FRAC_PI_2;
        let arcs = vec![
            arc(&e1, h + 0.01, h + 1.2, Quadrant::III, 1),
            arc(&e2, h - 1.2, h - 0.01, Quadrant::IV, 1),
            arc(&e2, h + 0.01, h + 1.2, Quadrant::III, 1),
            arc(&e1, h - 1.2, h - 0.01, Quadrant::IV, 1),
        ];
        let params = AssemblyParams::default();
        let (s0, rest) = merge_arcs(&arcs, &params).unwrap();
        assert!(rest.is_empty());
        let mut pairs: Vec<Vec<usize>> = s0
            .iter()
            .map(|s| {
                let mut a = s.arcs.clone();
                a.sort();
                a
            })
            .collect();
        pairs.sort();
        assert_eq!(pairs, vec![vec![0, 3], vec![1, 2]]);
        for s in &s0 {
            let truth = if s.arcs.contains(&0) { e1 } else { e2 };
            assert!(
                (s.fit.ellipse.cy - truth.cy).abs() < 0.2,
                "{:?}",
                s.fit.ellipse
            );
        }
        // Algorithm 2 has nothing to merge: the segments overlap on either ellipse.
        let (s, _) = merge_segments(&arcs, s0, rest, &params).unwrap();
        assert_eq!(s.len(), 2);
    }

    #[test]
    fn same_quadrant_opposite_polarity_and_overlap_are_rejected() {
        let e = Ellipse::new(400.0, 200.0, 300.0, 60.0, 0.0).unwrap();
        let h = std::f64::consts::FRAC_PI_2;
        let same_quadrant = vec![
            arc(&e, h + 0.01, h + 0.6, Quadrant::III, 1),
            arc(&e, h + 0.6, h + 1.2, Quadrant::III, 1),
        ];
        let p = AssemblyParams::default();
        assert!(merge_arcs(&same_quadrant, &p).unwrap().0.is_empty());
        let polarity = vec![
            arc(&e, h + 0.01, h + 1.2, Quadrant::III, 1),
            arc(&e, h - 1.2, h - 0.01, Quadrant::IV, -1),
        ];
        assert!(merge_arcs(&polarity, &p).unwrap().0.is_empty());
        let overlapping = vec![
            arc(&e, h - 0.3, h + 1.2, Quadrant::III, 1),
            arc(&e, h - 1.2, h + 0.3, Quadrant::IV, 1),
        ];
        let relaxed = AssemblyParams {
            max_gap: f64::INFINITY,
            ..p
        };
        assert!(merge_arcs(&overlapping, &relaxed).unwrap().0.is_empty());
        let good = vec![
            arc(&e, h + 0.01, h + 1.2, Quadrant::III, 1),
            arc(&e, h - 1.2, h - 0.01, Quadrant::IV, 1),
        ];
        assert_eq!(merge_arcs(&good, &p).unwrap().0.len(), 1);
        let bad = AssemblyParams {
            residual_threshold: -1.0,
            ..p
        };
        assert!(merge_arcs(&good, &bad).is_err());
    }
}
