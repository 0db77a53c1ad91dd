//! Rims cut by the image border: two arcs of one rim far apart because the part of the ellipse
//! between them lies outside the image (seed 000_3b1454b2b2194811.txt §3.2, the combination
//! rule of Algorithms 1–2, and the robustness scenes of ch. 3.5).
//!
//! A disturbance wafer high above the camera shows only the two side arcs of its rims: their
//! front arc, between them, runs above the image top. The arcs are several hundred pixels apart,
//! far beyond the assembly's gap limit ([`AssemblyParams::max_gap`]), which is what keeps
//! unrelated arcs of the many close, similar ellipses of a carrier from being joined. The gap is
//! allowed here only where it is explained: the union of the two arcs passes the whole
//! combination rule of §3.2 (polarity, quadrant classes and positions, residual threshold, no
//! overlap), both arcs end at the image border, and the part of the fitted ellipse between their
//! facing ends lies outside the image. The segments then go through the same validation as the
//! assembled ones (coverage, reflections, band refinement, pairing, unpaired-rim residual).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::f64::consts::TAU;

use super::*;
use crate::assembly::{combine_arcs, extent};

/// Distance (pixels) from the image border within which an arc end counts as at the border, and
/// a point of the ellipse as outside the image: the edge detector's 3 × 3 Sobel and
/// non-maximum suppression find no edgel in the outermost pixels, so a rim running out of the
/// image ends its arc 1–2 px inside it.
const BORDER: f64 = 3.0;

/// Points of the unseen part of the ellipse tested for lying outside the image.
const GAP_SAMPLES: usize = 64;

/// Whether `p` lies within [`BORDER`] of the border of a `width` × `height` image, or outside it.
fn at_border(p: &Vector2<f64>, width: f64, height: f64) -> bool {
    !(p.x >= BORDER && p.y >= BORDER && p.x <= width - 1.0 - BORDER && p.y <= height - 1.0 - BORDER)
}

/// Whether the part of `e` from eccentric angle `start` over `len` (radians) lies outside the
/// image: every one of [`GAP_SAMPLES`] points strictly inside the interval is at or beyond the
/// border (see [`at_border`]).
fn hidden(e: &Ellipse, start: f64, len: f64, width: f64, height: f64) -> bool {
    len > 0.0
        && (1..GAP_SAMPLES).all(|k| {
            let t = start + len * k as f64 / GAP_SAMPLES as f64;
            at_border(&e.point_at(t), width, height)
        })
}

/// Pairs of the arcs `rest` (left over by the assembly) that are one rim cut by the image
/// border: each arc has an end at the border, the two are farther apart than
/// `params.max_gap` (closer pairs were already judged by the assembly), their union passes the
/// combination rule of §3.2 with no gap limit, and one of the two parts of the fitted ellipse
/// between the arcs lies outside the `width` × `height` image. Each arc joins at most one pair,
/// lowest residual first. Returns the pairs as segments.
pub(super) fn border_cut_pairs(
    arcs: &[Arc],
    rest: &[usize],
    width: usize,
    height: usize,
    params: &AssemblyParams,
) -> Vec<Segment> {
    let (w, h) = (width as f64, height as f64);
    let ends_at_border = |k: usize| {
        arcs.get(k).is_some_and(|a| {
            [a.points.first(), a.points.last()]
                .into_iter()
                .flatten()
                .any(|p| at_border(p, w, h))
        })
    };
    let cands: Vec<usize> = rest
        .iter()
        .copied()
        .filter(|&k| ends_at_border(k))
        .collect();
    let wide = AssemblyParams {
        max_gap: f64::INFINITY,
        ..*params
    };
    let mut found: Vec<(f64, usize, usize, EllipseFit)> = Vec::new();
    for (x, &i) in cands.iter().enumerate() {
        for &j in &cands[x + 1..] {
            let (a, b) = (&arcs[i], &arcs[j]);
            if !(end_gap(a, b) > params.max_gap) {
                continue;
            }
            let Some((fit, ts)) = combine_arcs(a, b, &wide) else {
                continue;
            };
            let (ta, tb) = ts.split_at(a.points.len());
            let ((sa, la), (sb, lb)) = (extent(ta), extent(tb));
            let e = &fit.ellipse;
            // The two unseen parts: from the end of a to the start of b, and back.
            let after_a = (sb - (sa + la)).rem_euclid(TAU);
            let after_b = (sa - (sb + lb)).rem_euclid(TAU);
            if hidden(e, sa + la, after_a, w, h) || hidden(e, sb + lb, after_b, w, h) {
                found.push((fit.residual_mean, i, j, fit));
            }
        }
    }
    found.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut used = std::collections::HashSet::new();
    let mut out = Vec::new();
    for (_, i, j, fit) in found {
        if used.contains(&i) || used.contains(&j) {
            continue;
        }
        used.insert(i);
        used.insert(j);
        out.push(Segment::of_pair(arcs, i, j, fit));
    }
    out
}

/// Smallest distance between the end points of two arcs.
fn end_gap(a: &Arc, b: &Arc) -> f64 {
    let ends = |x: &Arc| [x.points.first().copied(), x.points.last().copied()];
    let mut d = f64::INFINITY;
    for p in ends(a).into_iter().flatten() {
        for q in ends(b).into_iter().flatten() {
            d = d.min((p - q).norm());
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::edges::Quadrant;
    use autoteach_geometry::render::Rim;

    /// Points of `e` for eccentric angles `t0..t1` with a small deterministic wobble.
    fn arc_of(e: &Ellipse, t0: f64, t1: f64, quadrant: Quadrant) -> Arc {
        let n = ((t1 - t0).abs() * e.a).round() as usize;
        let points: Vec<Vector2<f64>> = (0..n)
            .map(|k| {
                let t = t0 + (t1 - t0) * k as f64 / (n - 1) as f64;
                e.point_at(t) + Vector2::repeat(0.04 * (((k * 7919) % 13) as f64 / 6.0 - 1.0))
            })
            .collect();
        crate::assembly::tests::arc_from_points(points, quadrant, -1)
    }

    #[test]
    fn side_arcs_join_only_when_the_part_between_them_is_outside_the_image() {
        // Upper half of an ellipse (v down: t in (−π, 0)); the side arcs run from the lateral
        // ends up to where the ellipse leaves the image at v = 2 (its top is at v = −6).
        let e = Ellipse::new(640.0, 40.0, 340.0, 46.0, 0.0).unwrap();
        let top = |e: &Ellipse| {
            // Eccentric angle where the upper half reaches v = 2 on the right side.
            -((e.cy - 2.0) / e.b).asin()
        };
        let t = top(&e);
        let arcs = vec![
            arc_of(&e, -0.05, t, Quadrant::I),
            arc_of(
                &e,
                -std::f64::consts::PI - t,
                -std::f64::consts::PI + 0.05,
                Quadrant::II,
            ),
        ];
        let params = AssemblyParams::default();
        assert!(end_gap(&arcs[0], &arcs[1]) > 300.0);
        let found = border_cut_pairs(&arcs, &[0, 1], 1280, 720, &params);
        assert_eq!(found.len(), 1);
        let f = &found[0].fit.ellipse;
        assert!(
            (f.cx - e.cx).abs() < 0.5 && (f.cy - e.cy).abs() < 0.5,
            "{f:?}"
        );
        assert!(
            (f.a - e.a).abs() < 0.01 * e.a && (f.b - e.b).abs() < 0.01 * e.b,
            "{f:?}"
        );
        // The same arcs in a taller image (shifted down 100 px): the part between them is now
        // inside the image, unseen for no reason; they are not joined (nor are arcs whose ends
        // are away from the border).
        let shift = |a: &Arc| Arc {
            points: a
                .points
                .iter()
                .map(|p| p + Vector2::new(0.0, 100.0))
                .collect(),
            ..a.clone()
        };
        let moved = vec![shift(&arcs[0]), shift(&arcs[1])];
        assert!(border_cut_pairs(&moved, &[0, 1], 1280, 720, &params).is_empty());
        // Arcs of different polarity, or only one of them offered, are not joined either.
        let mut other = arcs.clone();
        other[1].polarity = 1;
        assert!(border_cut_pairs(&other, &[0, 1], 1280, 720, &params).is_empty());
        assert!(border_cut_pairs(&arcs, &[0], 1280, 720, &params).is_empty());
    }

    #[test]
    fn rim_cut_by_the_image_top_is_found() {
        // Image 31 of the wafer benchmark (seed 3): the disturbance wafer 12 slots above is seen
        // from below; its upper rim's front arc runs out of the image top, leaving two side arcs
        // ≈ 250 px apart (beyond the assembly's 60 px gap).
        let (data, w, h, rims) = super::super::tests::benchmark_scene(
            12,
            (
                -0.47197498048280606,
                -0.0014891594708802414,
                0.06102880611972025,
            ),
            -1.741774142352327,
            9.389679157029404,
            0.9639515153969921,
            [0.18472008714083266, 0.1812483690833539],
            852002133,
        );
        let view = GrayView::new(&data, w, h).unwrap();
        let (_, _, e, _) = rims
            .iter()
            .find(|(wafer, rim, _, _)| *wafer == 1 && *rim == Rim::Upper)
            .unwrap();
        assert!(e.cy - e.b < 0.0, "{e:?}");
        let run = |join: bool| {
            let params = DetectParams {
                join_border_cut_arcs: join,
                ..DetectParams::default()
            };
            let dets = detect_wafers(&view, &params).unwrap();
            super::super::tests::hit_and_wrong(&dets, &rims, 1, Rim::Upper)
        };
        assert_eq!(run(false), (false, 0));
        assert_eq!(run(true), (true, 0));
    }
}
