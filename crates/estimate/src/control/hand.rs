//! Hand vibration on an S-curve move (000_3b1454b2b2194811.txt ch. 2.5, Table 2.4): each
//! tuned joint follows a cycloidal S-curve through its closed loop, the link angles (the hand
//! side of the compliant drive) are simulated exactly (ZOH), and the acceleration of the
//! blade-1 tip follows from the planar kinematics of eqs. 2.4–2.6,
//! `a = Σ_k l_k (φ̈_k e⊥(φ_k) − φ̇_k² e(φ_k))` with `φ₁ = θ₁, φ₂ = θ₁+θ₂, φ₃ = θ₁+θ₂+θ₃`,
//! expressed in the blade frame (forward along the blade, lateral across it).
//!
//! Known limitation: the model is planar (JT3, the lift, is not simulated), so the vertical
//! (Z) column of Table 2.4 has no counterpart here.

use autoteach_geometry::robot::{Joints, RobotParams};

use super::poly;
use super::sim::lsim;
use super::tf::TransferFunction;
use crate::{EstimateError, Result};

/// Cycloidal S-curve of `distance` over `duration`, held for `settle` seconds, sampled at `dt`:
/// `x(t) = D (t/T − sin(2πt/T)/(2π))`. Returns (position, velocity, acceleration).
pub fn s_curve(
    distance: f64,
    duration: f64,
    settle: f64,
    dt: f64,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    for (name, v) in [("duration", duration), ("dt", dt)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name,
                value: v,
                reason: "must be finite and > 0",
            });
        }
    }
    if !(distance.is_finite() && settle.is_finite() && settle >= 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "distance/settle",
            value: distance + settle,
            reason: "must be finite (settle ≥ 0)",
        });
    }
    let n = ((duration + settle) / dt).round() as usize + 1;
    let tau = 2.0 * std::f64::consts::PI;
    let mut x = Vec::with_capacity(n);
    let mut v = Vec::with_capacity(n);
    let mut a = Vec::with_capacity(n);
    for k in 0..n {
        let t = (k as f64 * dt).min(duration);
        let moving = (k as f64 * dt) < duration;
        let u = t / duration;
        x.push(distance * (u - (tau * u).sin() / tau));
        v.push(if moving {
            distance / duration * (1.0 - (tau * u).cos())
        } else {
            0.0
        });
        a.push(if moving {
            distance * tau / (duration * duration) * (tau * u).sin()
        } else {
            0.0
        });
    }
    Ok((x, v, a))
}

/// Closed-loop response of a joint's link angle to the reference `r`: angle, rate and
/// acceleration, from `T_l = C P_l / (1 + C P_m)` and `s T_l`, `s² T_l` (exact ZOH).
pub fn link_response(
    motor: &TransferFunction,
    link: &TransferFunction,
    controller: &TransferFunction,
    r: &[f64],
    dt: f64,
) -> Result<[Vec<f64>; 3]> {
    // P_m and P_l over a common denominator.
    let den_p = poly::mul(motor.den(), link.den());
    let num_m = poly::mul(motor.num(), link.den());
    let num_l = poly::mul(link.num(), motor.den());
    let char_poly = poly::add(
        &poly::mul(controller.den(), &den_p),
        &poly::mul(controller.num(), &num_m),
    );
    let num = poly::mul(controller.num(), &num_l);
    let t = TransferFunction::new(&num, &char_poly)?;
    t.require_stable("closed loop of the joint")?;
    Ok([
        lsim(&t, r, dt)?,
        lsim(&t.times_s_power(1), r, dt)?,
        lsim(&t.times_s_power(2), r, dt)?,
    ])
}

/// Hand (blade-1 tip) acceleration in the blade frame, `(forward, lateral)` per sample, for
/// JT2 and JT4 angles `θ₁(t) = q0₁ + d₁(t)`, `θ₂(t) = q0₂ + d₂(t)` (each as angle, rate,
/// acceleration) with the wrist held.
pub fn hand_acceleration(
    params: &RobotParams,
    q0: &Joints,
    jt2: &[Vec<f64>; 3],
    jt4: &[Vec<f64>; 3],
) -> Result<Vec<(f64, f64)>> {
    let n = jt2[0].len();
    if jt2.iter().chain(jt4.iter()).any(|v| v.len() != n) {
        return Err(EstimateError::DimensionMismatch {
            what: "joint trajectories".into(),
            expected: vec![n],
            got: vec![jt4[0].len()],
        });
    }
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let phi = [
            q0[0] + jt2[0][k],
            q0[0] + q0[1] + jt2[0][k] + jt4[0][k],
            q0[0] + q0[1] + q0[2] + jt2[0][k] + jt4[0][k],
        ];
        let rate = [jt2[1][k], jt2[1][k] + jt4[1][k], jt2[1][k] + jt4[1][k]];
        let acc = [jt2[2][k], jt2[2][k] + jt4[2][k], jt2[2][k] + jt4[2][k]];
        let lens = [params.l1, params.l2, params.l3];
        let (mut ax, mut ay) = (0.0, 0.0);
        for i in 0..3 {
            let (s, c) = phi[i].sin_cos();
            ax += lens[i] * (-acc[i] * s - rate[i] * rate[i] * c);
            ay += lens[i] * (acc[i] * c - rate[i] * rate[i] * s);
        }
        let (s3, c3) = phi[2].sin_cos();
        out.push((ax * c3 + ay * s3, -ax * s3 + ay * c3));
    }
    Ok(out)
}

/// Root mean square.
pub fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn s_curve_derivatives_are_consistent() {
        let dt = 1e-4;
        let (x, v, a) = s_curve(1.0, 0.5, 0.1, dt).unwrap();
        assert!((x[x.len() - 1] - 1.0).abs() < 1e-12);
        for k in 1..4000 {
            assert!(((x[k + 1] - x[k - 1]) / (2.0 * dt) - v[k]).abs() < 1e-5);
            assert!(((v[k + 1] - v[k - 1]) / (2.0 * dt) - a[k]).abs() < 1e-3);
        }
    }

    #[test]
    fn rigid_rotation_gives_centripetal_acceleration() {
        // Only JT2 turning at constant rate ω with a stretched arm: the tip (radius R) has
        // −ω² R forward (towards the shoulder) and 0 lateral.
        let p = RobotParams::default();
        let q0 = Joints::new(0.4, 0.0, 0.0, 0.0, 0.0);
        let w = 2.0;
        let jt2 = [vec![0.0], vec![w], vec![0.0]];
        let jt4 = [vec![0.0], vec![0.0], vec![0.0]];
        let a = hand_acceleration(&p, &q0, &jt2, &jt4).unwrap();
        let r = p.l1 + p.l2 + p.l3;
        assert!((a[0].0 + w * w * r).abs() < 1e-12 && a[0].1.abs() < 1e-12);
    }
}
