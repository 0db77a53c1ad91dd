//! Rigid transforms on SO(3) and SE(3): exponential and logarithm maps, the ⊕/⊖ operators
//! and their Jacobians.
//!
//! Tangent vectors of SE(3) are ordered rotation first, ξ = [ω; ρ]. ⊕ is the right
//! perturbation X ⊕ δ = X·Exp(δ) and Y ⊖ X = Log(X⁻¹·Y), after Solà, Deray and Atchuthan,
//! "A micro Lie theory for state estimation in robotics" (arXiv:1812.01537), which the seed
//! 000_3b1454b2b2194811.txt uses at eq. (5.11).
#![allow(clippy::many_single_char_names)]

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6};

/// Below this angle (rad) the closed forms are replaced by their Taylor series.
const SMALL_ANGLE: f64 = 0.3;
/// Below this angle (rad) `sin θ/θ` and `(1 − cos θ)/θ²` use their series.
const TINY_ANGLE: f64 = 1e-4;

/// The skew-symmetric matrix `[v]×` with `[v]× u = v × u` (Solà eq. (135) ff.).
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Inverse of [`hat`]: the vector of the skew-symmetric part of `m`.
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)] - m[(1, 2)], m[(0, 2)] - m[(2, 0)], m[(1, 0)] - m[(0, 1)]) * 0.5
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
/// `[θ]×²` in the inverse SO(3) Jacobians (Solà eqs. (144), (146)).
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
/// `Q` block (Solà eq. (180)).
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
/// the SE(3) `Q` block (Solà eq. (180)).
fn q_coeff3(t: f64) -> f64 {
    if t.abs() < SMALL_ANGLE {
        const C: [f64; 6] = [
            1.0 / 120.0,
            -2.0 / 5040.0,
            3.0 / 362_880.0,
            -4.0 / 39_916_800.0,
            5.0 / 6_227_020_800.0,
            -6.0 / 1_307_674_368_000.0,
        ];
        horner(t * t, &C)
    } else {
        let t2 = t * t;
        (2.0 * t - 3.0 * t.sin() + t * t.cos()) / (2.0 * t2 * t2 * t)
    }
}

/// Exponential map of SO(3) as a unit quaternion, q = [cos(θ/2), sin(θ/2) ω/θ]
/// (Solà eq. (148)); exact to rounding for every angle, series near zero.
pub fn quat_exp(w: &Vector3<f64>) -> UnitQuaternion<f64> {
    let t = w.norm();
    let h = 0.5 * t;
    // sin(θ/2)/θ = ½ sinc(θ/2)
    let k = 0.5 * sinc(h);
    UnitQuaternion::new_unchecked(Quaternion::from_parts(h.cos(), w * k))
}

/// Logarithm map of SO(3) from a unit quaternion (Solà eq. (149)); the result has norm ≤ π.
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
/// (Solà eq. (143)), with series near θ = 0.
pub fn so3_exp(w: &Vector3<f64>) -> Rotation3<f64> {
    let t = w.norm();
    let wx = hat(w);
    let m = Matrix3::identity() + wx * sinc(t) + wx * wx * one_minus_cos_sq(t);
    Rotation3::from_matrix_unchecked(m)
}

/// Logarithm map of SO(3) (Solà eq. (144)); the result has norm θ ∈ [0, π].
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
/// (Solà eq. (145)), series near zero.
pub fn so3_left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let t = w.norm();
    let wx = hat(w);
    Matrix3::identity() + wx * one_minus_cos_sq(t) + wx * wx * theta_minus_sin_cu(t)
}

/// Inverse SO(3) left Jacobian J_l⁻¹(θ) = I − ½[θ]× + (1/θ² − (1 + cos θ)/(2θ sin θ)) [θ]×²
/// (Solà eq. (146)), series near zero. Singular at θ = 2π (never reached by [`so3_log`]).
pub fn so3_left_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let t = w.norm();
    let wx = hat(w);
    Matrix3::identity() - wx * 0.5 + wx * wx * jinv_coeff(t)
}

/// SO(3) right Jacobian J_r(θ) = J_l(−θ) = I − (1 − cos θ)/θ² [θ]× + (θ − sin θ)/θ³ [θ]×²
/// (Solà eq. (143)), series near zero.
pub fn so3_right_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(&-w)
}

/// Inverse SO(3) right Jacobian J_r⁻¹(θ) = I + ½[θ]× + (1/θ² − (1 + cos θ)/(2θ sin θ)) [θ]×²
/// (Solà eq. (144)), series near zero.
pub fn so3_right_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian_inv(&-w)
}

/// Splits ξ = [ω; ρ].
fn split(xi: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (xi.fixed_rows::<3>(0).into_owned(), xi.fixed_rows::<3>(3).into_owned())
}

/// Exponential map of SE(3) for ξ = [ω; ρ]: rotation Exp(ω), translation V(ω)ρ = J_l(ω)ρ
/// (Solà eq. (172)); it builds the homogeneous transform of seed eq. (2.1).
pub fn se3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let (w, rho) = split(xi);
    let t = so3_left_jacobian(&w) * rho;
    Isometry3::from_parts(Translation3::from(t), quat_exp(&w))
}

/// Logarithm map of SE(3), returning ξ = [ω; ρ] with ω = Log(R) (‖ω‖ ≤ π) and
/// ρ = J_l⁻¹(ω) t (Solà eq. (173)).
pub fn se3_log(x: &Isometry3<f64>) -> Vector6<f64> {
    let w = quat_log(&x.rotation);
    let rho = so3_left_jacobian_inv(&w) * x.translation.vector;
    Vector6::new(w.x, w.y, w.z, rho.x, rho.y, rho.z)
}

/// Right ⊕ on SO(3): X ⊕ δ = X·Exp(δ) (Solà eq. (25)).
pub fn so3_plus(x: &Rotation3<f64>, d: &Vector3<f64>) -> Rotation3<f64> {
    x * so3_exp(d)
}

/// Right ⊖ on SO(3): Y ⊖ X = Log(Xᵀ·Y) (Solà eq. (26)).
pub fn so3_minus(y: &Rotation3<f64>, x: &Rotation3<f64>) -> Vector3<f64> {
    so3_log(&(x.inverse() * y))
}

/// Right ⊕ on SE(3): X ⊕ ξ = X·Exp(ξ) (Solà eq. (25)), the chain of seed eq. (2.2).
pub fn se3_plus(x: &Isometry3<f64>, xi: &Vector6<f64>) -> Isometry3<f64> {
    x * se3_exp(xi)
}

/// Right ⊖ on SE(3): Y ⊖ X = Log(X⁻¹·Y) (Solà eq. (26)); the residual of seed eq. (5.11).
pub fn se3_minus(y: &Isometry3<f64>, x: &Isometry3<f64>) -> Vector6<f64> {
    se3_log(&(x.inverse() * y))
}
