//! Thin lines: a bright (or dark) curve of small width has two edges of opposite polarity,
//! one on each side, and the curve is their centre, not either edge (issue 42; the seed's
//! Fig. 3.2 shows the same two-edge structure for a wafer's bright boundary).
//!
//! Two validated elliptic edges are the two sides of one line when their polarities are
//! opposite and their ellipses are offset by at most the line width: centres within half of
//! it and both semi-axes within it (the two sides of a line of width `w` centred on an
//! ellipse `(c, a, b)` are close to `(c, a ± w/2, b ± w/2)`). Pairs are taken greedily in
//! increasing order of that offset (each edge joins at most one line), so the result does
//! not depend on the detection order.

use autoteach_geometry::conic::Ellipse;
use std::f64::consts::PI;

use super::EllipseDetection;

/// How far apart (pixels) the two edge ellipses are: the largest of the centre distance
/// (doubled: each side is offset by half the width) and the semi-axis differences. `None`
/// for equal polarities.
fn offset(p: &EllipseDetection, q: &EllipseDetection) -> Option<f64> {
    if p.polarity == 0 || q.polarity == 0 || p.polarity == q.polarity {
        return None;
    }
    let (e, f) = (&p.ellipse, &q.ellipse);
    let dc = ((e.cx - f.cx).powi(2) + (e.cy - f.cy).powi(2)).sqrt();
    let d = (2.0 * dc).max((e.a - f.a).abs()).max((e.b - f.b).abs());
    // Orientations must agree unless the ellipses are nearly circles (θ then undetermined).
    let round = (e.a - e.b) < 0.05 * e.a && (f.a - f.b) < 0.05 * f.a;
    let mut dt = (e.theta - f.theta).rem_euclid(PI);
    if dt > PI / 2.0 {
        dt = PI - dt;
    }
    if !round && dt * e.a.max(f.a) > d.max(1.0) {
        return None;
    }
    Some(d)
}

/// The centre line of two edges of opposite polarity: the mean ellipse (θ of `q` unwrapped
/// to within π/2 of `p`'s), the union of the supports, covariance `(C_p + C_q)/4` (two
/// independent estimates averaged), the mean residual and the smaller score; polarity 0.
fn centre_line(p: &EllipseDetection, q: &EllipseDetection) -> Option<EllipseDetection> {
    let (e, f) = (&p.ellipse, &q.ellipse);
    let mut tq = f.theta;
    while tq - e.theta > PI / 2.0 {
        tq -= PI;
    }
    while e.theta - tq > PI / 2.0 {
        tq += PI;
    }
    let ellipse = Ellipse::new(
        0.5 * (e.cx + f.cx),
        0.5 * (e.cy + f.cy),
        0.5 * (e.a + f.a),
        0.5 * (e.b + f.b),
        0.5 * (e.theta + tq),
    )
    .ok()?;
    let mut points = p.points.clone();
    points.extend_from_slice(&q.points);
    let covariance = match (p.covariance, q.covariance) {
        (Some(a), Some(b)) => Some((a + b) * 0.25),
        _ => None,
    };
    Some(EllipseDetection {
        ellipse,
        points,
        covariance,
        residual: 0.5 * (p.residual + q.residual),
        score: p.score.min(q.score),
        polarity: 0,
    })
}

/// Replaces each pair of opposite-polarity edges at most `max_width` pixels apart (see the
/// module documentation) by the centre line; the other detections are kept as they are.
pub fn pair_line_edges(dets: Vec<EllipseDetection>, max_width: f64) -> Vec<EllipseDetection> {
    let n = dets.len();
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            if let Some(d) = offset(&dets[i], &dets[j])
                && d <= max_width
            {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let mut used = vec![false; n];
    let mut out = Vec::with_capacity(n);
    for (_, i, j) in pairs {
        if used[i] || used[j] {
            continue;
        }
        if let Some(line) = centre_line(&dets[i], &dets[j]) {
            used[i] = true;
            used[j] = true;
            out.push(line);
        }
    }
    out.extend(
        dets.into_iter()
            .zip(used)
            .filter(|(_, u)| !u)
            .map(|(d, _)| d),
    );
    out
}

/// Whether two line detections (polarity 0) are one line of width at most `width`: centres
/// within `width/2` and semi-axes within `width/2` of each other.
pub fn same_line(p: &EllipseDetection, q: &EllipseDetection, width: f64) -> bool {
    let (e, f) = (&p.ellipse, &q.ellipse);
    let tol = 0.5 * width;
    (e.cx - f.cx).hypot(e.cy - f.cy) <= tol && (e.a - f.a).abs() <= tol && (e.b - f.b).abs() <= tol
}
