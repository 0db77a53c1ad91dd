//! The kinematic chain of the hand-eye system as a function of the calibration parameters
//! (000_3b1454b2b2194811.txt eqs. (5.9)–(5.10)), with analytic Jacobians.

use autoteach_geometry::lie::se3_adjoint;
use autoteach_geometry::robot::{Joints, RobotParams, WaferRobot};
use nalgebra::{Isometry3, Matrix6, Matrix6x5};

use crate::{EstimateError, Result};

/// Which joint zero offsets exist in the joint vector `(θ1, θ2, θ3, θ4, h)` (indices 0..5).
pub const N_JOINTS: usize = 5;

/// Names of the joints in the order of [`Joints`].
pub const JOINT_NAMES: [&str; N_JOINTS] = ["joint1", "joint2", "joint3", "joint4", "lift"];

/// Camera pose through the kinematic chain, eq. (5.9): `T_wc = T_wb · T_be2(q) · T_e2c` with
/// the true joints `q = q_enc − δ` (encoders read `q_true + δ`, see
/// [`autoteach_geometry::robot::joints_from_encoders`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraChain {
    /// The robot (its `base` is `T_wb`).
    pub robot: WaferRobot,
    /// Joint zero offsets `δ` (radians; the lift offset in metres).
    pub offsets: Joints,
}

/// The camera pose of one frame and its derivatives (right perturbations, `[ω; ρ]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainEval {
    /// `T_wc` of eq. (5.9).
    pub t_wc: Isometry3<f64>,
    /// `∂ε/∂β` where `T_wc ⊕ ε` results from `T_wb ⊕ β`: `Ad(T_bc⁻¹)`.
    pub d_base: Matrix6<f64>,
    /// `∂ε/∂δ_j` (column j) for the joint zero offsets: `−J_cam(q)` (more encoder offset means
    /// a smaller true joint angle).
    pub d_offsets: Matrix6x5<f64>,
}

impl CameraChain {
    /// A chain from robot parameters, the base pose and the offsets (all validated).
    pub fn new(params: RobotParams, base: Isometry3<f64>, offsets: Joints) -> Result<Self> {
        let robot = WaferRobot::new(params, base)?;
        if let Some((i, v)) = offsets.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: "joint offsets".into(),
                index: i,
                value: *v,
            });
        }
        Ok(Self { robot, offsets })
    }

    /// True joints `q_enc − δ`.
    pub fn true_joints(&self, q_enc: &Joints) -> Joints {
        q_enc - self.offsets
    }

    /// `T_wc(q_enc)` of eq. (5.9).
    pub fn camera_pose(&self, q_enc: &Joints) -> Isometry3<f64> {
        self.robot.camera_pose(&self.true_joints(q_enc))
    }

    /// `T_wc(q_enc)` with its Jacobians with respect to the base pose and the offsets.
    ///
    /// `T_wb·Exp(β)·T_bc = T_wc·Exp(Ad(T_bc⁻¹)β)`; the offsets enter through `q = q_enc − δ`
    /// and the body-frame camera Jacobian of [`WaferRobot::camera_jacobian`].
    pub fn evaluate(&self, q_enc: &Joints) -> ChainEval {
        let q = self.true_joints(q_enc);
        let t_bc = self.robot.camera_pose_in_base(&q);
        ChainEval {
            t_wc: self.robot.base * t_bc,
            d_base: se3_adjoint(&t_bc.inverse()),
            d_offsets: -self.robot.camera_jacobian(&q),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::lie::{se3_minus, se3_plus};
    use nalgebra::{Translation3, UnitQuaternion, Vector6};

    fn chain() -> CameraChain {
        let base = Isometry3::from_parts(
            Translation3::new(-1.0, 0.03, -0.45),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 0.026),
        );
        CameraChain::new(
            RobotParams::default(),
            base,
            Joints::new(0.01, -0.012, 0.005, 0.008, 0.0),
        )
        .unwrap()
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let c = chain();
        let q = Joints::new(0.4, 1.3, -0.2, -1.6, 0.12);
        let ev = c.evaluate(&q);
        let h = 1e-7;
        for i in 0..6 {
            let mut b = Vector6::zeros();
            b[i] = h;
            let mut c2 = c;
            c2.robot.base = se3_plus(&c.robot.base, &b);
            let fd = se3_minus(&c2.camera_pose(&q), &ev.t_wc) / h;
            assert!(
                (fd - ev.d_base.column(i)).norm() < 1e-6,
                "base {i}: {fd} vs {}",
                ev.d_base.column(i)
            );
        }
        for j in 0..5 {
            let mut c2 = c;
            c2.offsets[j] += h;
            let fd = se3_minus(&c2.camera_pose(&q), &ev.t_wc) / h;
            assert!((fd - ev.d_offsets.column(j)).norm() < 1e-6, "offset {j}");
        }
    }

    #[test]
    fn blade_one_wrist_offset_does_not_move_the_camera() {
        let c = chain();
        let ev = c.evaluate(&Joints::new(0.4, 1.3, -0.2, -1.6, 0.12));
        assert_eq!(ev.d_offsets.column(2).norm(), 0.0);
    }
}
