//! Rigid transforms on SO(3) and SE(3): exponential and logarithm maps, the ⊕/⊖ operators
//! with their Jacobians, unit quaternions and Euler angles.
//!
//! # Conventions
//!
//! * Poses are [`nalgebra::Isometry3<f64>`], the homogeneous transforms of seed
//!   000_3b1454b2b2194811.txt eq. (2.1). `T_ab` maps coordinates in frame `b` into frame `a`.
//! * Composition and inverse are nalgebra's own `*` and `.inverse()`: the chain of seed
//!   eq. (2.2) is `t_wb * t_be * t_ec`, and a point maps as in eq. (2.3) with
//!   `t_wc * point` (or `t_wc.transform_point(&p)`); `to_homogeneous()` gives the 4×4 matrix.
//! * Tangent vectors of SE(3) are ordered rotation first, ξ = [ω; ρ].
//! * ⊕ is the right perturbation X ⊕ δ = X·Exp(δ) and Y ⊖ X = Log(X⁻¹·Y), and every Jacobian
//!   is taken with respect to right perturbations of its manifold arguments, after Solà,
//!   Deray and Atchuthan, "A micro Lie theory for state estimation in robotics"
//!   (arXiv:1812.01537, cited below as "Solà"): Sec. III-A (⊕/⊖), Sec. III-B (adjoint),
//!   Sec. IV-B (Jacobians of ⊕/⊖), App. B (SO(3)) and App. D (SE(3)). The seed uses these
//!   operators in the robot-motion residual of eq. (5.11) and takes the Jacobians from its
//!   ref. [112] (Solà, "Quaternion kinematics for the error-state Kalman filter").
//! * Unit quaternions are Hamilton quaternions; arrays list them w first.
//!
//! Functions here take nalgebra values and do not validate finiteness (they are on the
//! solver's inner loop): NaN in gives NaN out. Validate user data at the boundary with
//! [`crate::error::check_finite`]; [`quat_from_wxyz`] is the one checked constructor.
//!
//! # Example
//!
//! ```
//! use autoteach_geometry::lie::{se3_exp, se3_log, se3_minus, se3_plus, se3_plus_jacobians};
//! use nalgebra::{Isometry3, Point3, Vector3, Vector6};
//!
//! // A chain of transforms (seed eq. (2.2)) is composition with `*`, the inverse is `.inverse()`.
//! let t_wb = Isometry3::new(Vector3::new(1.0, 0.0, 0.5), Vector3::new(0.0, 0.0, 0.3));
//! let t_bc = se3_exp(&Vector6::new(0.1, -0.2, 0.05, 0.3, 0.0, 0.1));
//! let t_wc = t_wb * t_bc;
//! let p_w = t_wc * Point3::new(0.0, 0.0, 1.0); // seed eq. (2.3)
//! assert!((t_wc.inverse() * p_w - Point3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
//!
//! // Exp and Log are inverse to each other, and ⊖ undoes ⊕.
//! let xi = Vector6::new(0.4, 0.1, -0.3, 1.0, 2.0, -0.5);
//! assert!((se3_log(&se3_exp(&xi)) - xi).norm() < 1e-12);
//! let y = se3_plus(&t_wc, &xi);
//! assert!((se3_minus(&y, &t_wc) - xi).norm() < 1e-12);
//!
//! // Jacobians of X ⊕ δ with respect to X and δ, for a least-squares solver.
//! let (j_x, j_d) = se3_plus_jacobians(&t_wc, &xi);
//! assert_eq!((j_x.nrows(), j_d.ncols()), (6, 6));
//! ```
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3,
    Vector6,
};

use crate::Result;
use crate::error::GeometryError;

/// Below this angle (rad) the closed forms are replaced by their Taylor series.
const SMALL_ANGLE: f64 = 0.3;
/// Below this angle (rad) `sin θ/θ` and `(1 − cos θ)/θ²` use their series.
const TINY_ANGLE: f64 = 1e-4;

/// Above this ‖ω‖ the product `[ω]×²` would overflow: the exponential maps and the left
/// Jacobian then work with the unit axis and the angle (see [`angle_axis`]).
const HUGE_ANGLE: f64 = 1e150;

/// `(θ, u)` with `ω = θ·u`, ‖u‖ = 1, computed without overflowing ‖ω‖² (θ saturates at
/// `f64::MAX`). Angles this large carry no fractional turn in f64: the maps return the exact
/// rotation by the angle as the float holds it, finite and orthonormal.
fn angle_axis(w: &Vector3<f64>) -> (f64, Vector3<f64>) {
    let s = w.amax();
    let u = w / s;
    let n = u.norm();
    ((s * n).min(f64::MAX), u / n)
}

/// The skew-symmetric matrix `[v]×` with `[v]× u = v × u` (Solà App. B, "hat" operator of so(3)).
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Inverse of [`hat`]: the vector of the skew-symmetric part of `m`.
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    ) * 0.5
}

/// `sin θ / θ`.
fn sinc(t: f64) -> f64 {
    if t.abs() < TINY_ANGLE {
        let t2 = t * t;
        1.0 - t2 / 6.0 * (1.0 - t2 / 20.0)
    } else {
        t.sin() / t
    }
}

/// `(1 − cos θ) / θ²`, computed as `2 sin²(θ/2)/θ²` to avoid cancellation.
fn one_minus_cos_sq(t: f64) -> f64 {
    if t.abs() < TINY_ANGLE {
        let t2 = t * t;
        0.5 - t2 / 24.0 * (1.0 - t2 / 30.0)
    } else {
        let s = (0.5 * t).sin();
        2.0 * s * s / (t * t)
    }
}

/// Evaluates `Σ c_k x^k` by Horner's rule.
fn horner(x: f64, c: &[f64]) -> f64 {
    c.iter().rev().fold(0.0, |acc, &ck| acc * x + ck)
}

/// `(θ − sin θ) / θ³` = Σ (−1)^k θ^{2k} / (2k+3)!.
fn theta_minus_sin_cu(t: f64) -> f64 {
    if t.abs() < SMALL_ANGLE {
        const C: [f64; 6] = [
            1.0 / 6.0,
            -1.0 / 120.0,
            1.0 / 5040.0,
            -1.0 / 362_880.0,
            1.0 / 39_916_800.0,
            -1.0 / 6_227_020_800.0,
        ];
        horner(t * t, &C)
    } else {
        (t - t.sin()) / (t * t * t)
    }
}

/// `1/θ² − (1 + cos θ) / (2 θ sin θ)` = (1 − (θ/2) cot(θ/2)) / θ², the coefficient of
/// `[θ]×²` in the inverse SO(3) Jacobians (Solà App. B).
fn jinv_coeff(t: f64) -> f64 {
    if t.abs() < SMALL_ANGLE {
        const C: [f64; 6] = [
            1.0 / 12.0,
            1.0 / 720.0,
            1.0 / 30_240.0,
            1.0 / 1_209_600.0,
            1.0 / 47_900_160.0,
            691.0 / 1_307_674_368_000.0,
        ];
        horner(t * t, &C)
    } else {
        let h = 0.5 * t;
        (1.0 - h * h.cos() / h.sin()) / (t * t)
    }
}

/// `(θ² + 2 cos θ − 2) / (2 θ⁴)` = Σ (−1)^k θ^{2k} / (2k+4)!, second coefficient of the SE(3)
/// `Q` block (Solà App. D, after Barfoot and Furgale 2014).
fn q_coeff2(t: f64) -> f64 {
    if t.abs() < SMALL_ANGLE {
        const C: [f64; 6] = [
            1.0 / 24.0,
            -1.0 / 720.0,
            1.0 / 40_320.0,
            -1.0 / 3_628_800.0,
            1.0 / 479_001_600.0,
            -1.0 / 87_178_291_200.0,
        ];
        horner(t * t, &C)
    } else {
        let s = (0.5 * t).sin();
        let t2 = t * t;
        (t2 - 4.0 * s * s) / (2.0 * t2 * t2)
    }
}

/// `(2θ − 3 sin θ + θ cos θ) / (2 θ⁵)` = Σ (−1)^k (k+1) θ^{2k} / (2k+5)!, third coefficient of
/// the SE(3) `Q` block (Solà App. D, after Barfoot and Furgale 2014).
///
/// The closed form loses about 60 ε/θ⁴ to cancellation, so the series (nine terms, truncation
/// below 1e-19 relative) is used up to θ = 1.
fn q_coeff3(t: f64) -> f64 {
    if t.abs() < 1.0 {
        const C: [f64; 9] = [
            1.0 / 120.0,
            -2.0 / 5040.0,
            3.0 / 362_880.0,
            -4.0 / 39_916_800.0,
            5.0 / 6_227_020_800.0,
            -6.0 / 1_307_674_368_000.0,
            7.0 / 355_687_428_096_000.0,
            -8.0 / 121_645_100_408_832_000.0,
            9.0 / 51_090_942_171_709_440_000.0,
        ];
        horner(t * t, &C)
    } else {
        let t2 = t * t;
        (2.0 * t - 3.0 * t.sin() + t * t.cos()) / (2.0 * t2 * t2 * t)
    }
}

/// Exponential map of SO(3) as a unit quaternion, q = [cos(θ/2), sin(θ/2) ω/θ]
/// (Solà App. B, "unit quaternions"; seed ref. [112] Sec. 2.4); exact to rounding for
/// every angle, with the series of sin(θ/2)/θ near zero.
pub fn quat_exp(w: &Vector3<f64>) -> UnitQuaternion<f64> {
    let t = w.norm();
    if t > HUGE_ANGLE {
        let (t, u) = angle_axis(w);
        let h = 0.5 * t;
        return UnitQuaternion::new_unchecked(Quaternion::from_parts(h.cos(), u * h.sin()));
    }
    let h = 0.5 * t;
    // sin(θ/2)/θ = ½ sinc(θ/2)
    let k = 0.5 * sinc(h);
    UnitQuaternion::new_unchecked(Quaternion::from_parts(h.cos(), w * k))
}

/// Logarithm map of SO(3) from a unit quaternion (Solà App. B, "unit quaternions"; seed
/// ref. [112] Sec. 2.4); the result has norm ≤ π.
///
/// Uses θ = 2 atan2(‖v‖, |w|) on the hemisphere w ≥ 0, which is accurate at every angle
/// including θ = π.
pub fn quat_log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (mut w, mut v) = (q.w, q.imag());
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let n = v.norm();
    if n < TINY_ANGLE * w {
        // θ/‖v‖ = 2 atan(x)/(x w) with x = ‖v‖/w small: 2/w (1 − x²/3 + x⁴/5).
        let x2 = (n / w) * (n / w);
        v * (2.0 / w * (1.0 - x2 / 3.0 + x2 * x2 / 5.0))
    } else {
        v * (2.0 * n.atan2(w) / n)
    }
}

/// Exponential map of SO(3), the Rodrigues formula R = I + sin θ [u]× + (1 − cos θ)[u]×²
/// (Solà App. B, Exp map), with series near θ = 0.
pub fn so3_exp(w: &Vector3<f64>) -> Rotation3<f64> {
    let t = w.norm();
    if t > HUGE_ANGLE {
        let (t, u) = angle_axis(w);
        let ux = hat(&u);
        return Rotation3::from_matrix_unchecked(
            Matrix3::identity() + ux * t.sin() + ux * ux * (1.0 - t.cos()),
        );
    }
    let wx = hat(w);
    let m = Matrix3::identity() + wx * sinc(t) + wx * wx * one_minus_cos_sq(t);
    Rotation3::from_matrix_unchecked(m)
}

/// Logarithm map of SO(3) (Solà App. B, Log map); the result has norm θ ∈ [0, π].
///
/// θ = atan2(‖vee(R − Rᵀ)/2‖, (tr R − 1)/2). For cos θ ≥ 0 the axis comes from the
/// antisymmetric part (with the series of θ/sin θ near zero). For cos θ < 0 it comes from the
/// symmetric part (R + Rᵀ)/2 − cos θ·I = (1 − cos θ) u uᵀ, taking its column of largest
/// diagonal, with the sign set by the antisymmetric part; this stays accurate up to and at
/// θ = π, where either sign is a valid logarithm.
pub fn so3_log(r: &Rotation3<f64>) -> Vector3<f64> {
    let m = r.matrix();
    let c = ((m.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
    let v = vee(m);
    let s = v.norm();
    let t = s.atan2(c);
    if c >= 0.0 {
        return v / sinc(t);
    }
    let b = (m + m.transpose()) * 0.5 - Matrix3::identity() * c;
    let i = if b[(0, 0)] >= b[(1, 1)] && b[(0, 0)] >= b[(2, 2)] {
        0
    } else if b[(1, 1)] >= b[(2, 2)] {
        1
    } else {
        2
    };
    let col = b.column(i).into_owned();
    let mut u = col / col.norm();
    if u.dot(&v) < 0.0 {
        u = -u;
    }
    u * t
}

/// SO(3) left Jacobian J_l(θ) = I + (1 − cos θ)/θ² [θ]× + (θ − sin θ)/θ³ [θ]×²
/// (Solà App. B, left Jacobian), series near zero. It is also the `V(ω)` of [`se3_exp`].
pub fn so3_left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let t = w.norm();
    if t > HUGE_ANGLE {
        let (t, u) = angle_axis(w);
        let ux = hat(&u);
        return Matrix3::identity() + ux * ((1.0 - t.cos()) / t) + ux * ux * (1.0 - t.sin() / t);
    }
    let wx = hat(w);
    Matrix3::identity() + wx * one_minus_cos_sq(t) + wx * wx * theta_minus_sin_cu(t)
}

/// Inverse SO(3) left Jacobian J_l⁻¹(θ) = I − ½[θ]× + (1/θ² − (1 + cos θ)/(2θ sin θ)) [θ]×²
/// (Solà App. B, inverse left Jacobian), series near zero. Singular at θ = 2π (never
/// reached by [`so3_log`]).
pub fn so3_left_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let t = w.norm();
    let wx = hat(w);
    Matrix3::identity() - wx * 0.5 + wx * wx * jinv_coeff(t)
}

/// SO(3) right Jacobian J_r(θ) = J_l(−θ) = I − (1 − cos θ)/θ² [θ]× + (θ − sin θ)/θ³ [θ]×²
/// (Solà App. B, right Jacobian), series near zero.
pub fn so3_right_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(&-w)
}

/// Inverse SO(3) right Jacobian J_r⁻¹(θ) = I + ½[θ]× + (1/θ² − (1 + cos θ)/(2θ sin θ)) [θ]×²
/// (Solà App. B, inverse right Jacobian), series near zero.
pub fn so3_right_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian_inv(&-w)
}

/// Splits ξ = [ω; ρ].
fn split(xi: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (
        xi.fixed_rows::<3>(0).into_owned(),
        xi.fixed_rows::<3>(3).into_owned(),
    )
}

/// Exponential map of SE(3) for ξ = [ω; ρ]: rotation Exp(ω), translation V(ω)ρ = J_l(ω)ρ
/// (Solà App. D, Exp map); it builds the homogeneous transform of seed eq. (2.1).
pub fn se3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let (w, rho) = split(xi);
    let t = so3_left_jacobian(&w) * rho;
    Isometry3::from_parts(Translation3::from(t), quat_exp(&w))
}

/// Logarithm map of SE(3), returning ξ = [ω; ρ] with ω = Log(R) (‖ω‖ ≤ π) and
/// ρ = J_l⁻¹(ω) t (Solà App. D, Log map).
pub fn se3_log(x: &Isometry3<f64>) -> Vector6<f64> {
    let w = quat_log(&x.rotation);
    let rho = so3_left_jacobian_inv(&w) * x.translation.vector;
    Vector6::new(w.x, w.y, w.z, rho.x, rho.y, rho.z)
}

/// Right ⊕ on SO(3): X ⊕ δ = X·Exp(δ) (Solà Sec. III-A, right-⊕), used for the SO(3)
/// operators of seed eq. (5.11).
pub fn so3_plus(x: &Rotation3<f64>, d: &Vector3<f64>) -> Rotation3<f64> {
    x * so3_exp(d)
}

/// Right ⊖ on SO(3): Y ⊖ X = Log(Xᵀ·Y) (Solà Sec. III-A, right-⊖), as in seed eq. (5.11).
pub fn so3_minus(y: &Rotation3<f64>, x: &Rotation3<f64>) -> Vector3<f64> {
    so3_log(&(x.inverse() * y))
}

/// Right ⊕ on SE(3): X ⊕ ξ = X·Exp(ξ) (Solà Sec. III-A, right-⊕): a chain of transforms as
/// in seed eq. (2.2), used for x_t ⊕ r_t in seed eq. (5.11).
pub fn se3_plus(x: &Isometry3<f64>, xi: &Vector6<f64>) -> Isometry3<f64> {
    x * se3_exp(xi)
}

/// Right ⊖ on SE(3): Y ⊖ X = Log(X⁻¹·Y) (Solà Sec. III-A, right-⊖); the residual of seed
/// eq. (5.11).
pub fn se3_minus(y: &Isometry3<f64>, x: &Isometry3<f64>) -> Vector6<f64> {
    se3_log(&(x.inverse() * y))
}

/// Adjoint matrix of an SE(3) element for ξ = [ω; ρ]: Ad_X = [[R, 0], [[t]×R, R]], so that
/// X·Exp(ξ)·X⁻¹ = Exp(Ad_X ξ) (Solà Sec. III-B and App. D, reordered rotation first).
pub fn se3_adjoint(x: &Isometry3<f64>) -> Matrix6<f64> {
    let r = x.rotation.to_rotation_matrix().into_inner();
    block_lower(&r, &(hat(&x.translation.vector) * r))
}

/// The coupling block Q(ω, ρ) of the SE(3) left Jacobian (Solà App. D, after Barfoot and
/// Furgale 2014), with the coefficients c₁ = `theta_minus_sin_cu`, c₂ = `q_coeff2` and
/// c₃ = `q_coeff3`:
///
/// ```text
/// Q = ½[ρ]× + c₁([ω]×[ρ]× + [ρ]×[ω]× + [ω]×[ρ]×[ω]×)
///   + c₂([ω]×²[ρ]× + [ρ]×[ω]×² − 3[ω]×[ρ]×[ω]×)
///   + c₃([ω]×[ρ]×[ω]×² + [ω]×²[ρ]×[ω]×)
/// ```
fn se3_q(w: &Vector3<f64>, rho: &Vector3<f64>) -> Matrix3<f64> {
    let t = w.norm();
    let wx = hat(w);
    let rx = hat(rho);
    let wr = wx * rx;
    let rw = rx * wx;
    let wrw = wr * wx;
    let wwr = wx * wr;
    let rww = rw * wx;
    rx * 0.5
        + (wr + rw + wrw) * theta_minus_sin_cu(t)
        + (wwr + rww - wrw * 3.0) * q_coeff2(t)
        + (wrw * wx + wx * wrw) * q_coeff3(t)
}

/// Assembles the block lower-triangular 6×6 matrix [[a, 0], [b, a]].
fn block_lower(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(a);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(b);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(a);
    m
}

/// SE(3) left Jacobian for ξ = [ω; ρ]: [[J_l(ω), 0], [Q(ω, ρ), J_l(ω)]] (Solà App. D,
/// reordered rotation first), with series for small angles. Exp(ξ + δ) ≈ Exp(J_l δ)·Exp(ξ).
pub fn se3_left_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    let (w, rho) = split(xi);
    block_lower(&so3_left_jacobian(&w), &se3_q(&w, &rho))
}

/// Inverse SE(3) left Jacobian: [[J_l⁻¹, 0], [−J_l⁻¹ Q J_l⁻¹, J_l⁻¹]] (Solà App. D).
pub fn se3_left_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    let (w, rho) = split(xi);
    let ji = so3_left_jacobian_inv(&w);
    block_lower(&ji, &(-ji * se3_q(&w, &rho) * ji))
}

/// SE(3) right Jacobian J_r(ξ) = J_l(−ξ) = [[J_r(ω), 0], [Q(−ω, −ρ), J_r(ω)]] (Solà App. D),
/// so that Exp(ξ + δ) ≈ Exp(ξ)·Exp(J_r δ).
pub fn se3_right_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    se3_left_jacobian(&-xi)
}

/// Inverse SE(3) right Jacobian J_r⁻¹(ξ) = J_l⁻¹(−ξ) (Solà App. D).
pub fn se3_right_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    se3_left_jacobian_inv(&-xi)
}

/// Jacobians of X ⊕ δ = X·Exp(δ) on SO(3): (d/dX, d/dδ) = (Exp(δ)ᵀ, J_r(δ))
/// (Solà Sec. IV-B, Jacobians of right-⊕; the Jacobians of seed eq. (5.11)).
pub fn so3_plus_jacobians(_x: &Rotation3<f64>, d: &Vector3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    (so3_exp(d).into_inner().transpose(), so3_right_jacobian(d))
}

/// Jacobians of Y ⊖ X = Log(Xᵀ·Y) on SO(3): (d/dY, d/dX) = (J_r⁻¹(τ), −J_l⁻¹(τ)) with
/// τ = Y ⊖ X (Solà Sec. IV-B, Jacobians of right-⊖; the Jacobians of seed eq. (5.11)).
pub fn so3_minus_jacobians(y: &Rotation3<f64>, x: &Rotation3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let tau = so3_minus(y, x);
    (so3_right_jacobian_inv(&tau), -so3_left_jacobian_inv(&tau))
}

/// Jacobians of X ⊕ ξ = X·Exp(ξ) on SE(3): (d/dX, d/dξ) = (Ad_{Exp(ξ)}⁻¹, J_r(ξ))
/// (Solà Sec. IV-B, Jacobians of right-⊕; the Jacobians of seed eq. (5.11)).
///
/// Exp(−ξ) = (Rᵀ, −J_r(ω)ρ) and J_r(ξ) share J_r(ω) = J_l(−ω), which is computed once.
pub fn se3_plus_jacobians(_x: &Isometry3<f64>, xi: &Vector6<f64>) -> (Matrix6<f64>, Matrix6<f64>) {
    let (w, rho) = split(xi);
    let (nw, nrho) = (-w, -rho);
    let jr = so3_left_jacobian(&nw);
    let rt = so3_exp(&nw).into_inner();
    let ad_inv = block_lower(&rt, &(hat(&(jr * nrho)) * rt));
    (ad_inv, block_lower(&jr, &se3_q(&nw, &nrho)))
}

/// Jacobians of Y ⊖ X = Log(X⁻¹·Y) on SE(3): (d/dY, d/dX) = (J_r⁻¹(τ), −J_l⁻¹(τ)) with
/// τ = Y ⊖ X (Solà Sec. IV-B, Jacobians of right-⊖; the Jacobians of seed eq. (5.11)).
pub fn se3_minus_jacobians(y: &Isometry3<f64>, x: &Isometry3<f64>) -> (Matrix6<f64>, Matrix6<f64>) {
    let tau = se3_minus(y, x);
    (se3_right_jacobian_inv(&tau), -se3_left_jacobian_inv(&tau))
}

/// Right ⊕ on unit quaternions: q ⊕ δ = q ⊗ Exp(δ), with the same tangent as SO(3)
/// (Solà Sec. III-A and App. B; seed ref. [112]).
pub fn quat_plus(q: &UnitQuaternion<f64>, d: &Vector3<f64>) -> UnitQuaternion<f64> {
    q * quat_exp(d)
}

/// Right ⊖ on unit quaternions: p ⊖ q = Log(q⁻¹ ⊗ p), equal to the SO(3) [`so3_minus`] of the
/// corresponding rotations (the shorter of the two quaternion arcs is taken).
pub fn quat_minus(y: &UnitQuaternion<f64>, x: &UnitQuaternion<f64>) -> Vector3<f64> {
    quat_log(&(x.inverse() * y))
}

/// Smallest quaternion norm accepted by [`quat_from_wxyz`].
pub const MIN_QUATERNION_NORM: f64 = 1e-12;

/// Builds a unit quaternion from Hamilton components `[w, x, y, z]`, normalising it.
///
/// # Errors
/// [`GeometryError::NonFinite`] for NaN or infinite components and
/// [`GeometryError::DegenerateQuaternion`] when the norm is below [`MIN_QUATERNION_NORM`].
pub fn quat_from_wxyz(wxyz: &[f64; 4]) -> Result<UnitQuaternion<f64>> {
    crate::error::check_finite("quaternion", wxyz)?;
    let [w, x, y, z] = *wxyz;
    // Scale by the largest magnitude first so that huge components cannot overflow the norm.
    let scale = wxyz.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let scaled_norm = if scale > 0.0 {
        (Quaternion::new(w, x, y, z) / scale).norm()
    } else {
        0.0
    };
    let norm = scale * scaled_norm;
    if norm < MIN_QUATERNION_NORM {
        return Err(GeometryError::DegenerateQuaternion { w, x, y, z, norm });
    }
    Ok(UnitQuaternion::new_unchecked(
        Quaternion::new(w, x, y, z) / scale / scaled_norm,
    ))
}

/// Hamilton components `[w, x, y, z]` of a unit quaternion, as stored (no sign change).
pub fn quat_to_wxyz(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Rotation about x by `a` (rad).
fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Rotation about y by `a` (rad).
fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// Rotation about z by `a` (rad).
fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Below this value of cos(pitch) (resp. cos of the middle angle) Euler extraction treats
/// the rotation as gimbal-locked and fixes the last angle to zero.
const GIMBAL_LOCK_COS: f64 = 1e-12;

/// Rotation from yaw–pitch–roll angles, R = Rz(yaw)·Ry(pitch)·Rx(roll) (intrinsic z-y'-x'',
/// scipy's `"ZYX"`), the rotation blocks of the homogeneous transforms of seed eq. (2.1).
pub fn rotation_from_euler_zyx(yaw: f64, pitch: f64, roll: f64) -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(rot_z(yaw) * rot_y(pitch) * rot_x(roll))
}

/// Yaw, pitch, roll of `r` with R = Rz(yaw)·Ry(pitch)·Rx(roll); pitch ∈ [−π/2, π/2], yaw and
/// roll ∈ (−π, π].
///
/// Yaw comes from the first column; roll and pitch are then read from Rz(yaw)ᵀ·R, so that the
/// angles reproduce `r` to rounding even close to gimbal lock. At gimbal lock
/// (cos pitch < 1e-12, pitch = ±π/2) only yaw ∓ roll is defined: the result has roll = 0.
pub fn euler_zyx(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    let cp = m[(0, 0)].hypot(m[(1, 0)]);
    if cp < GIMBAL_LOCK_COS {
        // R = [[0, −sin y, ·], [0, cos y, ·], [∓1, 0, 0]] with roll = 0.
        let yaw = (-m[(0, 1)]).atan2(m[(1, 1)]);
        let pitch = (-m[(2, 0)]).atan2(cp);
        return (yaw, pitch, 0.0);
    }
    let yaw = m[(1, 0)].atan2(m[(0, 0)]);
    // M = Rz(yaw)ᵀ R = Ry(pitch) Rx(roll) = [[cp, sp sr, sp cr], [0, cr, −sr], [−sp, cp sr, cp cr]]
    let k = rot_z(yaw).transpose() * m;
    let roll = (-k[(1, 2)]).atan2(k[(1, 1)]);
    let pitch = (-k[(2, 0)]).atan2(k[(0, 0)]);
    (yaw, pitch, roll)
}

/// Rotation from angles about x, y, z, R = Rx(a)·Ry(b)·Rz(c) (intrinsic x-y'-z'', scipy's
/// `"XYZ"`), the rotation blocks of the homogeneous transforms of seed eq. (2.1).
pub fn rotation_from_euler_xyz(a: f64, b: f64, c: f64) -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(rot_x(a) * rot_y(b) * rot_z(c))
}

/// Angles (a, b, c) of `r` with R = Rx(a)·Ry(b)·Rz(c); b ∈ [−π/2, π/2], a and c ∈ (−π, π].
///
/// a comes from the last column; b and c are then read from Rx(a)ᵀ·R. At gimbal lock
/// (cos b < 1e-12, b = ±π/2) the result has c = 0, as scipy does.
pub fn euler_xyz(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    let cb = m[(1, 2)].hypot(m[(2, 2)]);
    if cb < GIMBAL_LOCK_COS {
        // R = Rx(a) Ry(±π/2): column 1 is (0, cos a, sin a).
        let a = m[(2, 1)].atan2(m[(1, 1)]);
        let b = m[(0, 2)].atan2(cb);
        return (a, b, 0.0);
    }
    let a = (-m[(1, 2)]).atan2(m[(2, 2)]);
    // M = Rx(a)ᵀ R = Ry(b) Rz(c) = [[cb cc, −cb sc, sb], [sc, cc, 0], [−sb cc, sb sc, cb]]
    let k = rot_x(a).transpose() * m;
    let c = k[(1, 0)].atan2(k[(1, 1)]);
    let b = k[(0, 2)].atan2(k[(2, 2)]);
    (a, b, c)
}

/// Pose x ↦ R x + t from `[r₀, r₁, r₂, t₀, t₁, t₂]`, R = Exp(r) with r a rotation vector
/// (OpenCV's `rvec`/`tvec`), the parameterisation used by bundle adjustment; seed eq. (2.1).
pub fn isometry_from_rotvec_translation(p: &[f64; 6]) -> Isometry3<f64> {
    let [r0, r1, r2, t0, t1, t2] = *p;
    Isometry3::from_parts(
        Translation3::new(t0, t1, t2),
        quat_exp(&Vector3::new(r0, r1, r2)),
    )
}

/// Inverse of [`isometry_from_rotvec_translation`]: `[rotation vector (‖r‖ ≤ π), translation]`.
pub fn rotvec_translation(x: &Isometry3<f64>) -> [f64; 6] {
    let r = quat_log(&x.rotation);
    let t = x.translation.vector;
    [r.x, r.y, r.z, t.x, t.y, t.z]
}

#[cfg(test)]
mod tests;
