//! The simulated joint plants of 000_3b1454b2b2194811.txt ch. 2.5 ("since the robot dynamics
//! is non-linear, the frequency responses of the motors will change at different robot
//! poses"): a motor driving a link through a compliant gear (two-mass model), a structural
//! bending mode and the current loop, with the link inertia following the pose through the
//! arm's mass distribution (ch. 2.2, Fig. 2.5), and their noisy sine-sweep measurements
//! (Fig. 2.13).
//!
//! Two-mass model (motor side, gear ratio `N`): `J_m θ̈_m = τ − b_m θ̇_m − k(θ_m−θ_l) − c(θ̇_m−θ̇_l)`,
//! `J_l θ̈_l = k(θ_m−θ_l) + c(θ̇_m−θ̇_l)` with `J_l = J_link(q)/N²`, so
//! `θ_m/τ = (J_l s² + c s + k)/Δ`, `θ_l/τ = (c s + k)/Δ`,
//! `Δ = (J_m s² + (b_m+c) s + k)(J_l s² + c s + k) − (c s + k)²` (which has a root at 0).
//! The measured output is the joint angle at the motor encoder `θ_m/N`; the hand moves with the
//! link angle `θ_l/N`.
//!
//! The link inertia about a joint axis, with the other joints locked, is the sum over the
//! bodies beyond it of `I_c + m |c − p_joint|²` (the diagonal of the arm's mass matrix, the
//! reflected load of the drive). Masses and drive constants are documented defaults of a
//! 300 mm wafer-handling robot, not measurements of the seed's robot.

use autoteach_geometry::robot::{Joints, RobotParams};
use nalgebra::Vector2;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::poly::{self, C64};
use super::tf::TransferFunction;
use crate::{EstimateError, Result};

/// The two joints tuned in ch. 2.5.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Joint {
    /// Shoulder (θ1).
    Jt2,
    /// Elbow (θ2).
    Jt4,
}

/// Masses (kg) of the arm's bodies; links and blades are uniform rods, the wrist a point mass.
#[derive(Debug, Clone, Copy)]
pub struct ArmMasses {
    /// Upper arm (shoulder to elbow).
    pub upper_arm: f64,
    /// Forearm (elbow to wrist).
    pub forearm: f64,
    /// Wrist housing with the two wrist motors (at the wrist axis).
    pub wrist: f64,
    /// Each blade with its wafer.
    pub blade: f64,
}

impl Default for ArmMasses {
    fn default() -> Self {
        Self {
            upper_arm: 6.0,
            forearm: 4.0,
            wrist: 3.0,
            blade: 0.8,
        }
    }
}

/// Drive constants of one joint (motor side).
#[derive(Debug, Clone, Copy)]
pub struct Drive {
    /// Motor rotor inertia (kg m²).
    pub motor_inertia: f64,
    /// Gear ratio `N` (motor turns per joint turn).
    pub gear_ratio: f64,
    /// Gear/belt stiffness seen at the motor (N m/rad).
    pub stiffness: f64,
    /// Gear/belt damping seen at the motor (N m s/rad).
    pub damping: f64,
    /// Motor viscous friction including back-EMF damping (N m s/rad).
    pub motor_friction: f64,
    /// Structural bending mode: resonance frequency (Hz), seen at the motor encoder.
    pub mode_hz: f64,
    /// Its anti-resonance as a fraction of the resonance.
    pub mode_anti_ratio: f64,
    /// Damping ratio of the bending mode's resonance and anti-resonance.
    pub mode_zeta: f64,
    /// Current-loop bandwidth (Hz), a second-order low-pass with ζ = 0.7.
    pub current_loop_hz: f64,
}

impl Drive {
    /// Documented defaults for JT2 and JT4.
    pub fn default_for(joint: Joint) -> Self {
        match joint {
            Joint::Jt2 => Self {
                motor_inertia: 3e-4,
                gear_ratio: 50.0,
                stiffness: 8.0,
                damping: 6e-3,
                motor_friction: 1.5e-3,
                mode_hz: 110.0,
                mode_anti_ratio: 0.8,
                mode_zeta: 0.03,
                current_loop_hz: 400.0,
            },
            Joint::Jt4 => Self {
                motor_inertia: 2e-4,
                gear_ratio: 30.0,
                stiffness: 9.0,
                damping: 4e-3,
                motor_friction: 1e-3,
                mode_hz: 150.0,
                mode_anti_ratio: 0.8,
                mode_zeta: 0.03,
                current_loop_hz: 400.0,
            },
        }
    }
}

/// One joint plant at one pose.
#[derive(Debug, Clone)]
pub struct JointPlant {
    /// Motor torque (N m) → joint angle at the motor encoder (rad).
    pub motor: TransferFunction,
    /// Motor torque (N m) → link (hand-side) joint angle (rad).
    pub link: TransferFunction,
    /// Link inertia about the joint axis (kg m², joint side).
    pub link_inertia: f64,
    /// The pose.
    pub pose: Joints,
}

fn unit(a: f64) -> Vector2<f64> {
    Vector2::new(a.cos(), a.sin())
}

/// Link inertia about the axis of `joint` at pose `q` with the other joints locked (kg m²).
pub fn link_inertia(params: &RobotParams, masses: &ArmMasses, q: &Joints, joint: Joint) -> f64 {
    let (t1, t12) = (q[0], q[0] + q[1]);
    let (t123, t124) = (t12 + q[2], t12 + q[3]);
    let elbow = params.l1 * unit(t1);
    let wrist = elbow + params.l2 * unit(t12);
    let pivot = match joint {
        Joint::Jt2 => Vector2::zeros(),
        Joint::Jt4 => elbow,
    };
    let rod = |m: f64, len: f64, centre: Vector2<f64>| {
        m * len * len / 12.0 + m * (centre - pivot).norm_squared()
    };
    let mut j = rod(
        masses.forearm,
        params.l2,
        elbow + 0.5 * params.l2 * unit(t12),
    ) + masses.wrist * (wrist - pivot).norm_squared()
        + rod(
            masses.blade,
            params.l3,
            wrist + 0.5 * params.l3 * unit(t123),
        )
        + rod(
            masses.blade,
            params.l4,
            wrist + 0.5 * params.l4 * unit(t124),
        );
    if joint == Joint::Jt2 {
        j += rod(masses.upper_arm, params.l1, 0.5 * elbow);
    }
    j
}

/// The plant of `joint` at pose `q`.
pub fn joint_plant(
    params: &RobotParams,
    masses: &ArmMasses,
    drive: &Drive,
    q: &Joints,
    joint: Joint,
) -> Result<JointPlant> {
    for (name, v) in [
        ("motor_inertia", drive.motor_inertia),
        ("gear_ratio", drive.gear_ratio),
        ("stiffness", drive.stiffness),
        ("mode_hz", drive.mode_hz),
        ("current_loop_hz", drive.current_loop_hz),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name,
                value: v,
                reason: "drive constants must be finite and > 0",
            });
        }
    }
    let jl_link = link_inertia(params, masses, q, joint);
    let n = drive.gear_ratio;
    let jl = jl_link / (n * n);
    let (jm, k, c, b) = (
        drive.motor_inertia,
        drive.stiffness,
        drive.damping,
        drive.motor_friction,
    );
    let motor_side = [jm, b + c, k];
    let load_side = [jl, c, k];
    let coupling = [c, k];
    let delta = poly::add(
        &poly::mul(&motor_side, &load_side),
        &poly::scale(&poly::mul(&coupling, &coupling), -1.0),
    );
    // Δ(0) = k² − k² = 0: divide by s exactly.
    let delta_over_s = &delta[..delta.len() - 1];
    let wp = 2.0 * std::f64::consts::PI * drive.mode_hz;
    let wz = wp * drive.mode_anti_ratio;
    let z = drive.mode_zeta;
    // Bending mode with unit DC gain: (s²/wz² + 2z s/wz + 1)/(s²/wp² + 2z s/wp + 1).
    let mode_num = [1.0 / (wz * wz), 2.0 * z / wz, 1.0];
    let mode_den = [1.0 / (wp * wp), 2.0 * z / wp, 1.0];
    let wa = 2.0 * std::f64::consts::PI * drive.current_loop_hz;
    let cl_num = [wa * wa];
    let cl_den = [1.0, 1.4 * wa, wa * wa];
    let common_den = poly::mul(
        &poly::mul(&poly::mul(delta_over_s, &[1.0, 0.0]), &mode_den),
        &cl_den,
    );
    let motor_num = poly::scale(
        &poly::mul(&poly::mul(&load_side, &mode_num), &cl_num),
        1.0 / n,
    );
    let link_num = poly::scale(
        &poly::mul(&poly::mul(&coupling, &mode_num), &cl_num),
        1.0 / n,
    );
    Ok(JointPlant {
        motor: TransferFunction::new(&motor_num, &common_den)?,
        link: TransferFunction::new(&link_num, &common_den)?,
        link_inertia: jl_link,
        pose: *q,
    })
}

/// The sweep poses of a joint (`count` ≥ 2, six in the demo): JT2 from stretched to folded
/// (θ2 from 0.2 to 2.7 rad, the wrists turning the blades from outward to inward), JT4 over the
/// wrist angles θ3 = θ4 from 0 to 3 rad.
pub fn demo_poses_n(joint: Joint, count: usize) -> Vec<Joints> {
    let count = count.max(2);
    (0..count)
        .map(|i| {
            let f = i as f64 / (count - 1) as f64;
            match joint {
                Joint::Jt2 => {
                    let t2 = 0.2 + 2.5 * f;
                    let t3 = -0.5 * t2 + 3.0 * f;
                    Joints::new(0.0, t2, t3, t3, 0.0)
                }
                Joint::Jt4 => Joints::new(0.0, 1.2, 3.0 * f, 3.0 * f, 0.0),
            }
        })
        .collect()
}

/// The six sweep poses of the demo ([`demo_poses_n`] with 6).
pub fn demo_poses(joint: Joint) -> Vec<Joints> {
    demo_poses_n(joint, 6)
}

/// Stepped-sine sweep: `G(jω_k)(1 + σ(n₁ + j n₂)/√2)` with standard normal `n₁, n₂`, i.e. a
/// relative complex measurement noise of RMS `σ` at each of the log-spaced frequencies.
pub fn sine_sweep<R: Rng>(
    g: &TransferFunction,
    w: &[f64],
    noise: f64,
    rng: &mut R,
) -> Result<Vec<C64>> {
    if !(noise.is_finite() && noise >= 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "noise",
            value: noise,
            reason: "must be finite and ≥ 0",
        });
    }
    let k = noise / 2f64.sqrt();
    Ok(w.iter()
        .map(|&x| {
            let n1: f64 = StandardNormal.sample(rng);
            let n2: f64 = StandardNormal.sample(rng);
            g.freq_resp(x) * C64::new(1.0 + k * n1, k * n2)
        })
        .collect())
}

/// `n` log-spaced angular frequencies (rad/s) from `f_lo` to `f_hi` Hz.
pub fn log_grid_hz(f_lo: f64, f_hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (f_lo.log10(), f_hi.log10());
    (0..n)
        .map(|i| {
            2.0 * std::f64::consts::PI * 10f64.powf(a + (b - a) * i as f64 / (n.max(2) - 1) as f64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plant_low_frequency_is_rigid_body() {
        // Below the resonances the motor sees the total inertia: |G(jω)| ≈ 1/(N (J_m+J_l) ω²).
        let p = RobotParams::default();
        let m = ArmMasses::default();
        let d = Drive::default_for(Joint::Jt2);
        let q = demo_poses(Joint::Jt2)[0];
        let plant = joint_plant(&p, &m, &d, &q, Joint::Jt2).unwrap();
        let jt = d.motor_inertia + plant.link_inertia / (d.gear_ratio * d.gear_ratio);
        let w = 5.0; // rad/s: above b/J ≈ 0.75 rad/s, far below the anti-resonance
        let rigid = 1.0 / (d.gear_ratio * jt * w * w);
        let g = plant.motor.freq_resp(w).norm();
        assert!((g / rigid - 1.0).abs() < 0.05, "{g} vs {rigid}");
        assert!(plant.motor.require_proper("p").is_ok());
    }

    #[test]
    fn inertia_of_point_masses_matches_hand_sum() {
        let p = RobotParams::default();
        let m = ArmMasses {
            upper_arm: 0.0,
            forearm: 0.0,
            wrist: 2.0,
            blade: 0.0,
        };
        // Stretched arm: the wrist is at l1 + l2 from the shoulder, l2 from the elbow.
        let q = Joints::new(0.3, 0.0, 0.0, 0.0, 0.0);
        let j2 = link_inertia(&p, &m, &q, Joint::Jt2);
        let j4 = link_inertia(&p, &m, &q, Joint::Jt4);
        assert!((j2 - 2.0 * (p.l1 + p.l2).powi(2)).abs() < 1e-12);
        assert!((j4 - 2.0 * p.l2 * p.l2).abs() < 1e-12);
    }
}
