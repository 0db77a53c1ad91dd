//! What the pairing and the partner search share about a rim's joint refit (seed
//! 000_3b1454b2b2194811.txt §3.2): the covariance of a partner rim fitted jointly with its
//! reference, the residual gate a joint band refit must pass, and the side of its centre on which
//! a rim is seen.

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Vector2};

use super::joint;

/// Covariance of `(cx, cy, a, b, θ)` of a rim fitted by [`joint::fit_partner`]: the joint
/// fit's `(s, b)` covariance mapped to `(cx, cy, b)` (`(cx, cy) = reference centre + s·up`),
/// plus the reference's covariance `reference_cov` of the shared parameters (its centre, `a`,
/// `θ`).
pub(super) fn joint_covariance(
    fit: &joint::PartnerFit,
    up: Vector2<f64>,
    reference_cov: Option<&Matrix5<f64>>,
) -> Matrix5<f64> {
    let mut jac = nalgebra::SMatrix::<f64, 5, 2>::zeros();
    jac[(0, 0)] = up.x;
    jac[(1, 0)] = up.y;
    jac[(3, 1)] = 1.0;
    let mut cov = jac * fit.covariance * jac.transpose();
    if let Some(rc) = reference_cov {
        for (r, k) in [
            (0, 0),
            (0, 1),
            (1, 0),
            (1, 1),
            (2, 2),
            (2, 4),
            (4, 2),
            (4, 4),
        ] {
            cov[(r, k)] += rc[(r, k)];
        }
    }
    cov
}

/// How much farther than the assembly's residual threshold the rim's own points may lie, in the
/// mean, from a joint band refit (`pair::joint_partner`) that is kept. The own points are the Canny
/// edge points of a narrow band, whose two edges pull each other's gradient maxima apart
/// (`super::band`); on clipped bands they lie 0.3–0.56 px from the refit in the mean (images
/// 33, 105, 115, 118 and 189 of the benchmark, seed 3, whose refits are within 0.3 px and 1 % of
/// the truth), and the threshold of 0.25 px rejected these refits for the own fit (`b` 1.4–2.7 %
/// off). Measured on the benchmark (210 images, with pixel profiles for clipped bands): factor
/// 2 → recall 0.8741, 3 or 4 → 0.8755 (seed 3).
pub(super) const JOINT_REFIT_RESIDUAL_FACTOR: f64 = 3.0;

/// Mean of `(p − c)·up / b` over `points` (`c`, `b` of `e`): the side of the centre on which a
/// rim is seen. A front arc seen from above lies against `up` (≈ −0.8 for half an ellipse), seen
/// from below along `up` (≈ +0.8); a rim seen all round gives ≈ 0.
pub(super) fn front_side(e: &Ellipse, points: &[Vector2<f64>], up: Vector2<f64>) -> f64 {
    let n = points.len().max(1) as f64;
    points
        .iter()
        .map(|p| ((p.x - e.cx) * up.x + (p.y - e.cy) * up.y) / e.b)
        .sum::<f64>()
        / n
}
