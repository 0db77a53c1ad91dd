//! The missing rim of a wafer of which only one rim was assembled (000_3b1454b2b2194811.txt
//! §3.2, Fig. 3.2: "the bright boundary of the wafer forms two edges: an upper one corresponding
//! to the upper surface and lower one corresponding to the lower surface").
//!
//! Every rim seen along its front arc has the wafer's bright side band next to it, and the
//! band's far edge *is* the other rim. When the assembly found only one of them (the other's
//! edge chain was split, taken by a wrong assembly, or too short to be an arc), the other rim
//! is sought where the band says it is: per-profile band fits ([`band::fit`]) along the found
//! rim's front arc give the band's width, which places a first guess of the partner (the found
//! rim moved by that width against or along `up`), and the joint band model of both rims
//! ([`joint::fit_partner`]) fits it. The partner is reported only when that fit stays near the
//! guess, its measured far edges fit it, and (later, as for every rim) its covariance passes
//! [`super::DetectParams::max_relative_sigma_b`] and `max_centre_sigma`.

use super::band;
use super::joint::{self, OffsetPrior};
use super::joint_refit::{JOINT_REFIT_RESIDUAL_FACTOR, front_side, joint_covariance};
use super::refine::{is_band, level_set_normal};
use super::{Candidate, DetectParams, GrayView, Pixel, RimKind, Vector2, WaferEdge, median};
use autoteach_geometry::conic::Ellipse;
use nalgebra::Point2;

/// Most band profiles fitted one by one along the found rim's front arc.
const PROFILES: usize = 48;
/// Fewest per-profile band fits (with the band on the partner's side) for a partner to be
/// sought.
const MIN_BANDS: usize = 8;

/// The partner rim of the lone rim `c` (see the module doc), or `None`.
pub(super) fn seek_partner<T: Pixel>(
    image: &GrayView<'_, T>,
    c: &Candidate,
    up: Vector2<f64>,
    params: &DetectParams,
) -> Option<WaferEdge> {
    let e = c.seg.fit.ellipse;
    let points = &c.seg.points;
    // The partner lies against `up` from an upper rim, along `up` from a lower one; the band
    // between them on the front arc, which is the side of the centre against `up` for a wafer
    // seen from above. A rim seen all round is the rim of the face turned to the camera.
    let toward = if c.kind == RimKind::Upper { -up } else { up };
    let side = front_side(&e, points, up);
    let from_above = if side.abs() > 0.3 {
        side < 0.0
    } else {
        c.kind == RimKind::Upper
    };
    let front = if from_above { -up } else { up };
    let centre = Vector2::new(e.cx, e.cy);
    let on_front: Vec<Vector2<f64>> = points
        .iter()
        .filter(|p| (*p - centre).dot(&front) > 0.0)
        .copied()
        .collect();
    if on_front.len() < 2 * MIN_BANDS {
        return None;
    }
    // Per-profile band fits: the far edges (measured positions of the partner) and the band
    // widths near the middle of the front arc.
    let stride = (on_front.len() / PROFILES).max(1);
    let mut buf = Vec::new();
    let mut far = Vec::new();
    let mut widths = Vec::new();
    for p in on_front.iter().step_by(stride) {
        let Some(n) = level_set_normal(&e, p) else {
            continue;
        };
        let Some(d) = band::profile(image, *p, n, &mut buf) else {
            continue;
        };
        if !(d.dot(&toward) > 0.0) {
            continue;
        }
        let Some(p0) = band::start(&buf) else {
            continue;
        };
        if let Some((q, _)) = band::fit(&buf, p0, true)
            && is_band(&q)
        {
            far.push(p + d * q[4]);
            // Where the normal runs along `up` (the middle of the front arc) the band's width
            // is the rims' separation.
            if d.dot(&toward) > 0.9 {
                widths.push(q[4] - q[3]);
            }
        }
    }
    if far.len() < MIN_BANDS || widths.len() < 3 {
        return None;
    }
    let width = median(&mut widths);
    let sign = toward.dot(&up).signum();
    let guess = Ellipse::new(
        e.cx + sign * width * up.x,
        e.cy + sign * width * up.y,
        e.a,
        e.b,
        e.theta,
    )
    .ok()?;
    let kind = match c.kind {
        RimKind::Upper => RimKind::Lower,
        RimKind::Lower => RimKind::Upper,
    };
    // The offset prior as in the joint refit of a pair: for the lower rim of a wafer seen from
    // above.
    let prior = params
        .rim_offset
        .filter(|_| from_above && kind == RimKind::Lower)
        .map(|p| OffsetPrior {
            mean: -p.offset(e.a),
            sigma: p.sigma(e.a),
        });
    let fit = joint::fit_partner(
        image,
        &e,
        &guess,
        &on_front,
        up,
        0.9,
        prior,
        joint::MAX_FAR_SIDE_STEP,
    )?;
    let found = fit.ellipse;
    let s = (found.cx - e.cx) * up.x + (found.cy - e.cy) * up.y;
    let moved = (found.cx - guess.cx).hypot(found.cy - guess.cy);
    // Within 2 px of the guess, on the partner's side, and its minor axis within the pairing's
    // tolerance of the found rim's (as in the pairing of two found rims).
    let db = (found.b - e.b).abs();
    if !(s * sign > 0.0
        && moved < 2.0
        && db <= params.max_rim_axis_difference * found.b.max(e.b) + 1.0)
    {
        return None;
    }
    let residual = found
        .orthogonal_distances(&far)
        .iter()
        .map(|d| d.abs())
        .sum::<f64>()
        / far.len() as f64;
    if !(residual < JOINT_REFIT_RESIDUAL_FACTOR * params.assembly.residual_threshold) {
        return None;
    }
    Some(WaferEdge {
        ellipse: found,
        points: far.iter().map(|p| Point2::new(p.x, p.y)).collect(),
        residual,
        covariance: Some(joint_covariance(&fit, up, c.seg.fit.covariance.as_ref())),
        kind,
        wafer_id: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::super::tests::{benchmark_scene, hit_and_wrong};
    use super::super::{DetectParams, GrayView, detect_wafers};
    use autoteach_geometry::render::Rim;

    #[test]
    fn lower_rims_left_unassembled_are_found_along_the_band() {
        // Image 141 of the wafer benchmark (seed 4; clipped bands, gain 1.5): the upper rims of
        // both wafers are assembled, their lower rims are not (no segment). Sought along the
        // side band, both lower rims come out within 1 px and 1 % of the simulator's truth.
        let (data, w, h, rims) = benchmark_scene(
            2,
            (
                -0.460_836_052_357_211_4,
                0.032_336_906_063_990_95,
                0.051_961_535_760_909,
            ),
            0.355_038_998_730_860_2,
            9.462_889_374_368_551,
            1.497_139_851_298_646_5,
            [0.232_267_016_752_935_2, 0.223_110_926_695_261_06],
            2_185_131_162,
        );
        let view = GrayView::new(&data, w, h).unwrap();
        let run = |seek_missing_partner: bool| {
            let params = DetectParams {
                seek_missing_partner,
                ..DetectParams::default()
            };
            let dets = detect_wafers(&view, &params).unwrap();
            [
                (0, Rim::Upper),
                (0, Rim::Lower),
                (1, Rim::Upper),
                (1, Rim::Lower),
            ]
            .map(|(wafer, rim)| hit_and_wrong(&dets, &rims, wafer, rim))
        };
        assert_eq!(run(false), [(true, 0), (false, 0), (true, 0), (false, 0)]);
        assert_eq!(run(true), [(true, 0), (true, 0), (true, 0), (true, 0)]);
    }
}
