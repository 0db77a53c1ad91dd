//! A rim's motion between frames: constant-velocity extrapolation of its ellipse and the
//! world-frame circle from the candidate pairs of its recent views.

use super::*;

/// Whether the rim has a recent previous observation to estimate its image velocity from.
pub(super) fn has_velocity(rim: &RimState) -> bool {
    rim.prev
        .is_some_and(|(f0, _)| (1..=3).contains(&rim.frame.saturating_sub(f0)))
}

/// Constant-velocity extrapolation of a rim's ellipse parameters to `frame`.
pub(super) fn extrapolate(rim: &RimState, frame: usize) -> Ellipse {
    let e1 = rim.edge.ellipse;
    let Some((f0, e0)) = rim.prev else {
        return e1;
    };
    let dt_obs = rim.frame.saturating_sub(f0);
    if dt_obs == 0 || dt_obs > 3 {
        return e1;
    }
    let s = frame.saturating_sub(rim.frame) as f64 / dt_obs as f64;
    let mut dth = e1.theta - e0.theta;
    while dth > std::f64::consts::FRAC_PI_2 {
        dth -= std::f64::consts::PI;
    }
    while dth <= -std::f64::consts::FRAC_PI_2 {
        dth += std::f64::consts::PI;
    }
    // Near-circular ellipses have an ill-defined orientation: do not extrapolate it.
    if (e1.a - e1.b) < 0.05 * e1.a || (e0.a - e0.b) < 0.05 * e0.a {
        dth = 0.0;
    }
    Ellipse::new(
        e1.cx + s * (e1.cx - e0.cx),
        e1.cy + s * (e1.cy - e0.cy),
        e1.a + s * (e1.a - e0.a),
        e1.b + s * (e1.b - e0.b),
        e1.theta + s * dth,
    )
    .unwrap_or(e1)
}

/// World-frame circle of a rim from the candidate pairs of its recent views: per view the
/// candidate whose normal is closest to `normal_prior`, or, without a prior, closest to the
/// reference that makes the oldest and newest views agree best; then the mean centre and the
/// sign-aligned mean normal. `None` for a single view without a prior (ambiguous).
pub(super) fn estimate_circle(
    candidates: &VecDeque<[Circle3; 2]>,
    normal_prior: Option<&Vector3<f64>>,
) -> Option<Circle3> {
    let first = candidates.front()?;
    let chosen: Vec<Circle3> = match normal_prior {
        Some(n) => candidates
            .iter()
            .map(|c| {
                if c[0].normal.dot(n).abs() >= c[1].normal.dot(n).abs() {
                    c[0]
                } else {
                    c[1]
                }
            })
            .collect(),
        None => {
            if candidates.len() < 2 {
                return None;
            }
            let last = candidates.back()?;
            let mut best = (f64::INFINITY, first[0]);
            for a in first {
                for b in last {
                    let d = (a.center - b.center).norm();
                    if d < best.0 {
                        best = (d, *a);
                    }
                }
            }
            let r = best.1;
            candidates
                .iter()
                .map(|c| {
                    if (c[0].center - r.center).norm() <= (c[1].center - r.center).norm() {
                        c[0]
                    } else {
                        c[1]
                    }
                })
                .collect()
        }
    };
    let n = chosen.len() as f64;
    let center = chosen.iter().map(|c| c.center).sum::<Vector3<f64>>() / n;
    let reference = chosen[0].normal;
    let normal_sum: Vector3<f64> = chosen
        .iter()
        .map(|c| {
            if c.normal.dot(&reference) < 0.0 {
                -c.normal
            } else {
                c.normal
            }
        })
        .sum();
    let len = normal_sum.norm();
    (len > 0.0 && center.iter().all(|v| v.is_finite())).then(|| Circle3 {
        center,
        normal: normal_sum / len,
        radius: chosen[0].radius,
    })
}
