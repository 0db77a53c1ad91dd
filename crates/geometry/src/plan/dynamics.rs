//! Inverse dynamics of the five-joint wafer robot, 000_3b1454b2b2194811.txt ch. 2.2,
//! eqs. (2.8)–(2.9).
//!
//! In the absolute link angles `φ = (θ1, θ12, θ123, θ124)` every body's centre of mass is
//! `Σ_k a_k e(φ_k)` with constant lever arms `a_k` and `e(φ) = (cos φ, sin φ)`, so the kinetic
//! energy of eq. (2.9) is `T = ½ Σ_jk M_jk φ̇_j φ̇_k + ½ m_tot ḣ²` with
//! `M_jk = K_jk cos(φ_j − φ_k) + δ_jk J_k`, `K_jk = Σ_bodies m a_j a_k` and `J_k` the bodies'
//! own inertias about their vertical axes. The Euler–Lagrange equations in `φ` are then
//! `Q_i = Σ_j M_ij φ̈_j + Σ_j K_ij sin(φ_i − φ_j) φ̇_j²`, and `m_tot (ḧ + g)` for the lift.
//! The joint torques are `τ = Aᵀ Q` with `φ = A q`.
//!
//! Slip in the printed (2.8): the matrix mapping `d/dt ∂L/∂q̇' − ∂L/∂q'` to τ is printed as
//! `[[1,1,1,0,0],[0,1,1,0,0],…]`; with `θ124 = θ1 + θ2 + θ4` the shoulder and elbow also carry
//! blade 2's generalised force, so the first two rows are `[1,1,1,1,0]` and `[0,1,1,1,0]`
//! (`Aᵀ`). The test `euler_lagrange_finite_differences_match` derives τ numerically from the
//! Lagrangian built on the robot's forward kinematics and confirms the corrected rows.
//!
//! The bodies (masses and inertias are documented defaults, [`DynamicsParams`]): upper arm,
//! forearm, blade 1 with the carried wafer, blade 2 with the camera, and the lifted column.

use crate::robot::{Joints, RobotParams};

use super::workspace::CarriedWafer;

/// Standard gravity (m/s²).
pub const GRAVITY: f64 = 9.80665;

/// Masses (kg), centre-of-mass distances along each link (m) and inertias about the centre of
/// mass (kg·m², vertical axis). The seed does not print them; the defaults are those of a
/// 300 mm wafer robot of the size of [`RobotParams::default`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicsParams {
    /// Upper-arm mass.
    pub m1: f64,
    /// Forearm mass.
    pub m2: f64,
    /// Blade-1 mass.
    pub m3: f64,
    /// Blade-2 mass.
    pub m4: f64,
    /// Lifted column mass (moves with `h` only).
    pub m_column: f64,
    /// Camera mass.
    pub m_camera: f64,
    /// Wafer mass (0.128 kg for a 300 mm silicon wafer), used when a wafer is carried.
    pub m_wafer: f64,
    /// Centre-of-mass distance of the upper arm from the shoulder axis.
    pub c1: f64,
    /// Centre-of-mass distance of the forearm from the elbow axis.
    pub c2: f64,
    /// Centre-of-mass distance of blade 1 from the wrist axis.
    pub c3: f64,
    /// Centre-of-mass distance of blade 2 from the wrist axis.
    pub c4: f64,
    /// Inertias of the upper arm, forearm, blade 1, blade 2 about their centres of mass.
    pub inertia: [f64; 4],
}

impl Default for DynamicsParams {
    /// Aluminium links: upper arm 6 kg, forearm 4 kg, blades 0.8 kg, column 15 kg, camera
    /// 0.1 kg, a 128 g wafer; centres at mid-link; rod inertias `m l² / 12`.
    fn default() -> Self {
        let p = RobotParams::default();
        let rod = |m: f64, l: f64| m * l * l / 12.0;
        Self {
            m1: 6.0,
            m2: 4.0,
            m3: 0.8,
            m4: 0.8,
            m_column: 15.0,
            m_camera: 0.1,
            m_wafer: 0.128,
            c1: 0.5 * p.l1,
            c2: 0.5 * p.l2,
            c3: 0.5 * p.l3,
            c4: 0.5 * p.l4,
            inertia: [
                rod(6.0, p.l1),
                rod(4.0, p.l2),
                rod(0.8, p.l3),
                rod(0.8, p.l4),
            ],
        }
    }
}

/// The inverse-dynamics model (constant matrices `K`, `J` and the total lifted mass).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dynamics {
    k: [[f64; 4]; 4],
    j: [f64; 4],
    m_total: f64,
}

impl Dynamics {
    /// Builds the model from the kinematics, the mass properties and the carried wafer.
    pub fn new(robot: &RobotParams, d: &DynamicsParams, wafer: Option<&CarriedWafer>) -> Self {
        let (l1, l2) = (robot.l1, robot.l2);
        // (mass, lever arms along φ1..φ4, own inertia, which φ it turns with)
        let mut bodies: Vec<(f64, [f64; 4], f64, usize)> = vec![
            (d.m1, [d.c1, 0.0, 0.0, 0.0], d.inertia[0], 0),
            (d.m2, [l1, d.c2, 0.0, 0.0], d.inertia[1], 1),
            (d.m3, [l1, l2, d.c3, 0.0], d.inertia[2], 2),
            (d.m4, [l1, l2, 0.0, d.c4], d.inertia[3], 3),
            (d.m_camera, [l1, l2, 0.0, robot.l4 - robot.cam_d], 0.0, 3),
        ];
        if let Some(w) = wafer {
            let disc = 0.5 * d.m_wafer * w.radius * w.radius;
            bodies.push((d.m_wafer, [l1, l2, robot.l3 - w.setback, 0.0], disc, 2));
        }
        let mut k = [[0.0; 4]; 4];
        let mut j = [0.0; 4];
        let mut m_total = d.m_column;
        for (m, a, inertia, axis) in &bodies {
            for r in 0..4 {
                for c in 0..4 {
                    k[r][c] += m * a[r] * a[c];
                }
            }
            j[*axis] += inertia;
            m_total += m;
        }
        Self { k, j, m_total }
    }

    /// Total mass moved by the lift (kg).
    pub fn lifted_mass(&self) -> f64 {
        self.m_total
    }

    /// Joint torques (N·m) and lift force (N) `τ(q, q̇, q̈)`, eqs. (2.8)–(2.9) with the
    /// corrected `Aᵀ` (module docs).
    pub fn torques(&self, q: &Joints, dq: &Joints, ddq: &Joints) -> Joints {
        let phi = [q[0], q[0] + q[1], q[0] + q[1] + q[2], q[0] + q[1] + q[3]];
        let dphi = [
            dq[0],
            dq[0] + dq[1],
            dq[0] + dq[1] + dq[2],
            dq[0] + dq[1] + dq[3],
        ];
        let ddphi = [
            ddq[0],
            ddq[0] + ddq[1],
            ddq[0] + ddq[1] + ddq[2],
            ddq[0] + ddq[1] + ddq[3],
        ];
        let mut qf = [0.0; 4];
        for i in 0..4 {
            let mut s = self.j[i] * ddphi[i];
            for jj in 0..4 {
                let (sn, cs) = (phi[i] - phi[jj]).sin_cos();
                s += self.k[i][jj] * (cs * ddphi[jj] + sn * dphi[jj] * dphi[jj]);
            }
            qf[i] = s;
        }
        Joints::new(
            qf[0] + qf[1] + qf[2] + qf[3],
            qf[1] + qf[2] + qf[3],
            qf[2],
            qf[3],
            self.m_total * (ddq[4] + GRAVITY),
        )
    }

    /// The inertial part `τ(q, q̇, q̈) − τ(q, 0, 0)` (what scales by `1/λ²` when the time is
    /// stretched by `λ`) and the static part `τ(q, 0, 0)` (gravity on the lift).
    pub fn split(&self, q: &Joints, dq: &Joints, ddq: &Joints) -> (Joints, Joints) {
        let stat = self.torques(q, &Joints::zeros(), &Joints::zeros());
        (self.torques(q, dq, ddq) - stat, stat)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{Blade, WaferRobot};
    use nalgebra::{Point3, Vector3};

    /// The Lagrangian `T − V` built from the bodies' world positions given by the robot's
    /// forward kinematics (blade poses, camera pose), differentiated numerically in time.
    fn lagrangian(
        robot: &WaferRobot,
        d: &DynamicsParams,
        w: &CarriedWafer,
        q: &Joints,
        dq: &Joints,
    ) -> f64 {
        let p = &robot.params;
        let pos = |q: &Joints| -> Vec<(f64, Vector3<f64>)> {
            let b1 = robot.blade_pose(q, Blade::One);
            let b2 = robot.blade_pose(q, Blade::Two);
            let at = |t: &nalgebra::Isometry3<f64>, x: f64| (t * Point3::new(x, 0.0, 0.0)).coords;
            let e1 = Vector3::new(q[0].cos(), q[0].sin(), 0.0);
            let e12 = Vector3::new((q[0] + q[1]).cos(), (q[0] + q[1]).sin(), 0.0);
            vec![
                (d.m1, e1 * d.c1 + Vector3::z() * q[4]),
                (d.m2, e1 * p.l1 + e12 * d.c2 + Vector3::z() * q[4]),
                (d.m3, at(&b1, d.c3 - p.l3)),
                (d.m4, at(&b2, d.c4 - p.l4)),
                (d.m_camera, robot.camera_pose(q).translation.vector),
                (d.m_wafer, at(&b1, -w.setback)),
                (d.m_column, Vector3::z() * q[4]),
            ]
        };
        let eps = 1e-6;
        let (a, b) = (pos(&(q + dq * eps)), pos(&(q - dq * eps)));
        let mut t = 0.0;
        let mut v = 0.0;
        for ((m, pa), (_, pb)) in a.iter().zip(&b) {
            let vel = (pa - pb) / (2.0 * eps);
            t += 0.5 * m * vel.norm_squared();
        }
        for (m, p0) in pos(q) {
            v += m * GRAVITY * p0.z;
        }
        let rates = [dq[0] + dq[1], dq[0] + dq[1] + dq[2], dq[0] + dq[1] + dq[3]];
        t += 0.5 * d.inertia[0] * dq[0] * dq[0];
        t += 0.5 * d.inertia[1] * rates[0] * rates[0];
        t += 0.5 * (d.inertia[2] + 0.5 * d.m_wafer * w.radius * w.radius) * rates[1] * rates[1];
        t += 0.5 * d.inertia[3] * rates[2] * rates[2];
        t - v
    }

    #[test]
    fn euler_lagrange_finite_differences_match() {
        let robot = WaferRobot::default();
        let d = DynamicsParams::default();
        let w = CarriedWafer::default();
        let dyn_ = Dynamics::new(&robot.params, &d, Some(&w));
        let q0 = Joints::new(0.3, 1.1, -0.7, 2.0, 0.12);
        let v0 = Joints::new(0.8, -1.2, 1.5, -0.6, 0.2);
        let a0 = Joints::new(2.0, 3.0, -4.0, 30.0, -0.5);
        let traj = |t: f64| (q0 + v0 * t + a0 * (0.5 * t * t), v0 + a0 * t);
        let dl_ddq = |t: f64, i: usize| {
            let (q, dq) = traj(t);
            let h = 1e-4;
            let mut p = dq;
            let mut m = dq;
            p[i] += h;
            m[i] -= h;
            (lagrangian(&robot, &d, &w, &q, &p) - lagrangian(&robot, &d, &w, &q, &m)) / (2.0 * h)
        };
        let (q, dq) = traj(0.0);
        let tau = dyn_.torques(&q, &dq, &a0);
        let mut els = [0.0; 5];
        for i in 0..5 {
            let ht = 1e-3;
            let ddt = (dl_ddq(ht, i) - dl_ddq(-ht, i)) / (2.0 * ht);
            let h = 1e-5;
            let mut p = q;
            let mut m = q;
            p[i] += h;
            m[i] -= h;
            let dl_dq = (lagrangian(&robot, &d, &w, &p, &dq) - lagrangian(&robot, &d, &w, &m, &dq))
                / (2.0 * h);
            let el = ddt - dl_dq;
            els[i] = el;
            assert!(
                (el - tau[i]).abs() < 2e-3 * (1.0 + tau[i].abs()),
                "joint {i}: {el} vs {}",
                tau[i]
            );
        }
        // The printed rows of (2.8) omit blade 2's generalised force Q4 = τ4 from the shoulder
        // and elbow torques: that does not match the Euler–Lagrange derivation.
        for i in 0..2 {
            let printed = tau[i] - tau[3];
            assert!(
                (els[i] - printed).abs() > 10.0 * 2e-3 * (1.0 + tau[i].abs()),
                "{i} {} {printed}",
                els[i]
            );
        }
    }

    #[test]
    fn static_lift_force_is_weight() {
        let d = DynamicsParams::default();
        let dy = Dynamics::new(&RobotParams::default(), &d, None);
        let t = dy.torques(
            &Joints::new(0.1, 0.2, 0.3, 0.4, 0.1),
            &Joints::zeros(),
            &Joints::zeros(),
        );
        let m = d.m1 + d.m2 + d.m3 + d.m4 + d.m_column + d.m_camera;
        assert!((t[4] - m * GRAVITY).abs() < 1e-9);
        assert!(t.rows(0, 4).norm() < 1e-12);
    }
}
