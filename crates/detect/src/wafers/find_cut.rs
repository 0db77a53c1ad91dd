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

/// Pairs of arcs that are one rim cut by the image border: each arc has an end at the border,
/// the two are farther apart than `params.max_gap` (closer pairs were already judged by the
/// assembly), their union passes the combination rule of §3.2 with no gap limit, and one of the
/// two parts of the fitted ellipse between the arcs lies outside the `width` × `height` image.
///
/// The arcs offered are those the assembly left over (`rest`) and those of its two-arc
/// segments (`segments`): the assembly judged only the pairs within its gap limit, so an arc at
/// the border may have been matched with a nearby piece of clutter (a short foreign arc with a
/// residual of 0.1–0.2 px) while its own rim's other arc lies across the image. A pair that
/// takes an arc of a two-arc segment must fit better (a lower mean residual) than that segment,
/// the rule by which Algorithm 1 chooses between the pairs of an arc; the segment is then
/// dissolved. Each arc joins at most one pair, lowest residual first. Returns the pairs as
/// segments and the indices (into `segments`) of the dissolved ones.
pub(super) fn border_cut_pairs(
    arcs: &[Arc],
    rest: &[usize],
    segments: &[Segment],
    width: usize,
    height: usize,
    params: &AssemblyParams,
) -> (Vec<Segment>, Vec<usize>) {
    let (w, h) = (width as f64, height as f64);
    let ends_at_border = |k: usize| {
        arcs.get(k).is_some_and(|a| {
            [a.points.first(), a.points.last()]
                .into_iter()
                .flatten()
                .any(|p| at_border(p, w, h))
        })
    };
    // Per offered arc: the two-arc segment it belongs to (index, residual), if any.
    let mut owner = std::collections::HashMap::<usize, (usize, f64)>::new();
    for (s, seg) in segments.iter().enumerate() {
        if seg.arcs.len() == 2 {
            for &k in &seg.arcs {
                owner.insert(k, (s, seg.fit.residual_mean));
            }
        }
    }
    let mut cands: Vec<usize> = rest
        .iter()
        .copied()
        .chain(owner.keys().copied())
        .filter(|&k| ends_at_border(k))
        .collect();
    cands.sort_unstable();
    cands.dedup();
    let wide = AssemblyParams {
        max_gap: f64::INFINITY,
        ..*params
    };
    let beats_owner = |k: usize, r: f64| owner.get(&k).is_none_or(|&(_, rs)| r < rs);
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
            let r = fit.residual_mean;
            if !(beats_owner(i, r) && beats_owner(j, r)) {
                continue;
            }
            let (ta, tb) = ts.split_at(a.points.len());
            let ((sa, la), (sb, lb)) = (extent(ta), extent(tb));
            let e = &fit.ellipse;
            // The two unseen parts: from the end of a to the start of b, and back.
            let after_a = (sb - (sa + la)).rem_euclid(TAU);
            let after_b = (sa - (sb + lb)).rem_euclid(TAU);
            if hidden(e, sa + la, after_a, w, h) || hidden(e, sb + lb, after_b, w, h) {
                found.push((r, i, j, fit));
            }
        }
    }
    found.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut used = std::collections::HashSet::new();
    let mut dissolved = Vec::new();
    let mut out = Vec::new();
    for (_, i, j, fit) in found {
        // An arc of a dissolved segment stays free for another pair.
        if used.contains(&i) || used.contains(&j) {
            continue;
        }
        used.insert(i);
        used.insert(j);
        for k in [i, j] {
            if let Some(&(s, _)) = owner.get(&k) {
                dissolved.push(s);
            }
        }
        out.push(Segment::of_pair(arcs, i, j, fit));
    }
    dissolved.sort_unstable();
    dissolved.dedup();
    (out, dissolved)
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

    /// The upper half of an ellipse (v down: t in (−π, 0)) whose top is at v = −6, and its two
    /// side arcs from the lateral ends up to where the ellipse leaves the image at v = 2 (right
    /// arc first).
    fn top_cut_side_arcs() -> (Ellipse, Vec<Arc>) {
        let e = Ellipse::new(640.0, 40.0, 340.0, 46.0, 0.0).unwrap();
        // Eccentric angle where the upper half reaches v = 2 on the right side.
        let t = -((e.cy - 2.0) / e.b).asin();
        let arcs = vec![
            arc_of(&e, -0.05, t, Quadrant::I),
            arc_of(
                &e,
                -std::f64::consts::PI - t,
                -std::f64::consts::PI + 0.05,
                Quadrant::II,
            ),
        ];
        (e, arcs)
    }

    #[test]
    fn side_arcs_join_only_when_the_part_between_them_is_outside_the_image() {
        let (e, arcs) = top_cut_side_arcs();
        let params = AssemblyParams::default();
        assert!(end_gap(&arcs[0], &arcs[1]) > 300.0);
        let (found, dissolved) = border_cut_pairs(&arcs, &[0, 1], &[], 1280, 720, &params);
        assert!(dissolved.is_empty());
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
        assert!(
            border_cut_pairs(&moved, &[0, 1], &[], 1280, 720, &params)
                .0
                .is_empty()
        );
        // Arcs of different polarity, or only one of them offered, are not joined either.
        let mut other = arcs.clone();
        other[1].polarity = 1;
        assert!(
            border_cut_pairs(&other, &[0, 1], &[], 1280, 720, &params)
                .0
                .is_empty()
        );
        assert!(
            border_cut_pairs(&arcs, &[0], &[], 1280, 720, &params)
                .0
                .is_empty()
        );
    }

    #[test]
    fn a_border_pair_takes_its_arc_back_from_a_worse_assembled_pair() {
        // The two side arcs of a rim cut by the image top (as above), and the assembly's
        // segment of the right arc with a nearby foreign arc (residual `r`).
        let (e, mut arcs) = top_cut_side_arcs();
        let clutter_ellipse = Ellipse::new(900.0, 60.0, 120.0, 30.0, 0.3).unwrap();
        arcs.push(arc_of(&clutter_ellipse, 0.3, 1.0, Quadrant::IV));
        let params = AssemblyParams::default();
        let assembled = |r: f64| {
            let mut points = arcs[0].points.clone();
            points.extend_from_slice(&arcs[2].points);
            let mut fit =
                crate::ellipse::fit_ellipse(&points, crate::ellipse::FitMethod::Geometric).unwrap();
            fit.residual_mean = r;
            vec![Segment::of_pair(&arcs, 0, 2, fit)]
        };
        // The border pair fits to ≈ 0.03 px: it beats a segment at 0.15 px and dissolves it.
        let (found, dissolved) =
            border_cut_pairs(&arcs, &[1], &assembled(0.15), 1280, 720, &params);
        assert_eq!(found.len(), 1);
        assert_eq!(dissolved, vec![0]);
        let mut pair = found[0].arcs.clone();
        pair.sort_unstable();
        assert_eq!(pair, vec![0, 1]);
        let f = &found[0].fit.ellipse;
        assert!((f.a - e.a).abs() < 0.01 * e.a && (f.b - e.b).abs() < 0.01 * e.b);
        // Against a segment that fits better, the assembly's choice stands.
        let (found, dissolved) =
            border_cut_pairs(&arcs, &[1], &assembled(1e-4), 1280, 720, &params);
        assert!(found.is_empty() && dissolved.is_empty());
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
        // Without the join, the partner search (`seek.rs`) would find the upper rim from the
        // lower one: off here, so that only this rule is compared.
        let run = |join: bool| {
            let params = DetectParams {
                join_border_cut_arcs: join,
                seek_missing_partner: join,
                ..DetectParams::default()
            };
            let dets = detect_wafers(&view, &params).unwrap();
            super::super::tests::hit_and_wrong(&dets, &rims, 1, Rim::Upper)
        };
        assert_eq!(run(false), (false, 0));
        assert_eq!(run(true), (true, 0));
    }

    /// Image 70 of the wafer benchmark, seed 4: the disturbance wafer 11 slots above, seen from
    /// below, both rims cut by the image top.
    fn seed4_image70() -> super::super::tests::Rendered {
        super::super::tests::benchmark_scene(
            11,
            (
                -0.4801409477299735,
                0.013631179810025928,
                0.04411365827789297,
            ),
            1.0468379615662577,
            9.169027578698064,
            0.5740540256967773,
            [-0.09573189222721662, -0.1806774082749862],
            313652561,
        )
    }

    #[test]
    fn rims_cut_by_the_image_top_with_little_coverage_are_found() {
        // The lower rim's right arc was matched by the assembly with a short foreign arc below
        // it (a segment with a ≈ 122 px, residual 0.106 px); the border pair of the rim's two
        // arcs fits to 0.045 px and takes it back. The upper rim's two arcs cover under 0.15 of
        // its perimeter (the former coverage floor).
        let (data, w, h, rims) = seed4_image70();
        let view = GrayView::new(&data, w, h).unwrap();
        // The partner search (`seek.rs`) finds the upper rim from the lower one too: off with the
        // former floor, so that only this rule is compared.
        let run = |min_coverage: f64| {
            let params = DetectParams {
                min_coverage,
                seek_missing_partner: min_coverage < 0.15,
                ..DetectParams::default()
            };
            let dets = detect_wafers(&view, &params).unwrap();
            (
                super::super::tests::hit_and_wrong(&dets, &rims, 1, Rim::Upper),
                super::super::tests::hit_and_wrong(&dets, &rims, 1, Rim::Lower),
            )
        };
        assert_eq!(run(0.08), ((true, 0), (true, 0)));
        assert_eq!(run(0.15), ((false, 0), (true, 0)));
    }
}
