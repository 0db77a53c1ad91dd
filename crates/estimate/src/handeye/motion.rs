//! The robot motion factor of 000_3b1454b2b2194811.txt eqs. (5.10)–(5.12) between the free
//! camera poses of consecutive frames, with analytic Jacobians, and the conic edge factor of
//! eq. (5.13) on a free camera pose.

use autoteach_geometry::lie::{se3_adjoint, se3_log, se3_right_jacobian_inv};
use autoteach_geometry::robot::{Joints, RobotParams, WaferRobot};
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Matrix6, Matrix6x5, Vector2, Vector5, Vector6,
};

use super::factors::{EdgeJacobians, conic_edge_residuals};
use super::wafer::{Rim, WaferGeometry};
use crate::lsq::{Residual, se3_from_params};
use crate::{EstimateError, Result};

/// The relative robot motion `r_t = T_wc(t)·T_wc(t+1)⁻¹ = T_wb·A_t·T_wb⁻¹` of eq. (5.10), with
/// `A_t = T_bc(q_t − δ)·T_bc(q_{t+1} − δ)⁻¹` from the forward kinematics and the encoder
/// readings `q` (the camera mount `T_ec` cancels), and its error against the free camera poses
/// `x_t = T_wc(t)`:
///
/// `e_r = W · Log(r_t⁻¹ · x_t · x_{t+1}⁻¹)` (eq. (5.11) with the ⊕/⊖ of Solà's micro Lie theory;
/// zero when the camera motion equals the robot's), a function of `x_t, x_{t+1}, T_wb` and the
/// joint zero offsets `δ` as in eq. (5.12). `W = diag(1/σ)` whitens it with the robot's
/// precision (`σ` = `[σ_ω (3, rad); σ_ρ (3, m)]`, the information `Ω_t^r` of eq. (5.6) in the
/// 6-dimensional tangent instead of position + quaternion).
///
/// Blocks: `[x_t (Se3), x_{t+1} (Se3), T_wb (Se3), δ_j (Euclidean 1) for each estimated joint]`.
/// Jacobians (right perturbations, `M = r⁻¹x_t x_{t+1}⁻¹`, `e = Log M`, `J = J_r⁻¹(e)`):
/// `∂e/∂x_t = J·Ad(x_{t+1})`, `∂e/∂x_{t+1} = −J·Ad(x_{t+1})`,
/// `∂e/∂β = J·Ad(P⁻¹)·(Ad(A_t) − I)` with `P = T_wb⁻¹·x_t·x_{t+1}⁻¹`, and
/// `∂e/∂δ = −J·Ad(M⁻¹·T_wb)·Ad(T_bc(t+1))·(D_t − D_{t+1})` with `D = ∂(T_bc ⊕ ·)/∂δ = −J_cam`.
#[derive(Debug, Clone)]
pub struct RobotMotionResidual {
    /// Robot geometry (the base pose is a block).
    pub params: RobotParams,
    /// Encoder readings of frame t.
    pub q_t: Joints,
    /// Encoder readings of frame t+1.
    pub q_next: Joints,
    /// Offsets of the joints that are not estimated.
    pub fixed_offsets: Joints,
    /// Joints whose offsets are blocks (in block order after the base).
    pub offset_joints: Vec<usize>,
    /// `[σ_ω (3); σ_ρ (3)]` of the robot motion.
    pub sigma: [f64; 6],
}

impl RobotMotionResidual {
    /// Validates `sigma` (finite, positive) and the joint indices.
    pub fn new(
        params: RobotParams,
        q_t: Joints,
        q_next: Joints,
        fixed_offsets: Joints,
        offset_joints: Vec<usize>,
        sigma: [f64; 6],
    ) -> Result<Self> {
        if let Some(s) = sigma.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(EstimateError::InvalidParameter {
                name: "robot motion sigma",
                value: *s,
                reason: "must be finite and positive",
            });
        }
        if let Some(&j) = offset_joints.iter().find(|&&j| j >= 5) {
            return Err(EstimateError::InvalidParameter {
                name: "offset joint",
                value: j as f64,
                reason: "joint indices are 0..5",
            });
        }
        Ok(Self {
            params,
            q_t,
            q_next,
            fixed_offsets,
            offset_joints,
            sigma,
        })
    }

    fn offsets(&self, params: &[&[f64]]) -> Joints {
        let mut d = self.fixed_offsets;
        for (i, &j) in self.offset_joints.iter().enumerate() {
            d[j] = params[3 + i][0];
        }
        d
    }

    /// `A_t`, `T_bc(t+1)` and `D_t − D_{t+1}` at the given offsets.
    fn relative(&self, offsets: &Joints) -> (Isometry3<f64>, Isometry3<f64>, Matrix6x5<f64>) {
        let robot = WaferRobot {
            params: self.params,
            base: Isometry3::identity(),
        };
        let (qa, qb) = (self.q_t - offsets, self.q_next - offsets);
        let (ta, tb) = (
            robot.camera_pose_in_base(&qa),
            robot.camera_pose_in_base(&qb),
        );
        let dd = robot.camera_jacobian(&qb) - robot.camera_jacobian(&qa);
        (ta * tb.inverse(), tb, dd)
    }
}

impl Residual for RobotMotionResidual {
    fn dim(&self) -> usize {
        6
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let (x_t, x_n, base) = (
            se3_from_params(params[0]),
            se3_from_params(params[1]),
            se3_from_params(params[2]),
        );
        let offsets = self.offsets(params);
        let (a, t_bc_next, dd) = self.relative(&offsets);
        let r = base * a * base.inverse();
        let m = r.inverse() * x_t * x_n.inverse();
        let e = se3_log(&m);
        let w = Matrix6::from_diagonal(&Vector6::from_iterator(self.sigma.iter().map(|s| 1.0 / s)));
        residual.copy_from_slice((w * e).as_slice());
        if let Some(jac) = jacobians {
            let jr = w * se3_right_jacobian_inv(&e);
            let ad_n = se3_adjoint(&x_n);
            jac[0].copy_from(&to_dmatrix(&(jr * ad_n)));
            jac[1].copy_from(&to_dmatrix(&(-jr * ad_n)));
            let p = base.inverse() * x_t * x_n.inverse();
            let jb = jr * se3_adjoint(&p.inverse()) * (se3_adjoint(&a) - Matrix6::identity());
            jac[2].copy_from(&to_dmatrix(&jb));
            // D = −J_cam, so D_t − D_{t+1} = J_cam(t+1) − J_cam(t) = dd.
            let g = se3_adjoint(&(m.inverse() * base)) * se3_adjoint(&t_bc_next);
            for (i, &j) in self.offset_joints.iter().enumerate() {
                let col = dd.column(j).into_owned();
                let d = -(jr * g * col);
                jac[3 + i].set_column(0, &DVector::from_column_slice(d.as_slice()));
            }
        }
        Ok(())
    }
}

fn to_dmatrix(m: &Matrix6<f64>) -> DMatrix<f64> {
    DMatrix::from_column_slice(6, 6, m.as_slice())
}

/// The conic edge factor of eq. (5.13) on a free camera pose `x_t = T_wc` (free-camera mode):
/// blocks `[x_t (Se3), wafer (Euclidean 5)]`.
#[derive(Debug, Clone)]
pub struct FreeCameraEdgeResidual {
    /// Pinhole intrinsics.
    pub k: Matrix3<f64>,
    /// Wafer radius and thickness.
    pub geometry: WaferGeometry,
    /// Which rim the points belong to.
    pub rim: Rim,
    /// Edge points (pixels).
    pub points: Vec<Vector2<f64>>,
    /// Edge-point standard deviation (pixels).
    pub sigma: f64,
}

impl Residual for FreeCameraEdgeResidual {
    fn dim(&self) -> usize {
        self.points.len()
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let t_wc = se3_from_params(params[0]);
        let w = Vector5::from_column_slice(params[1]);
        let n = self.points.len();
        let mut ej = jacobians.as_ref().map(|_| EdgeJacobians {
            camera: DMatrix::zeros(n, 6),
            wafer: DMatrix::zeros(n, 5),
        });
        conic_edge_residuals(
            &self.k,
            &t_wc,
            &w,
            self.rim,
            self.geometry.radius,
            self.geometry.thickness,
            &self.points,
            self.sigma,
            residual,
            ej.as_mut(),
        )?;
        if let (Some(jac), Some(ej)) = (jacobians, ej) {
            jac[0].copy_from(&ej.camera);
            jac[1].copy_from(&ej.wafer);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lsq::se3_to_params;
    use autoteach_geometry::lie::se3_plus;
    use nalgebra::{Translation3, UnitQuaternion};

    fn base() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(-1.0, 0.03, -0.45),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 0.026),
        )
    }

    fn residual() -> RobotMotionResidual {
        RobotMotionResidual::new(
            RobotParams::default(),
            Joints::new(0.4, 1.3, -0.2, -1.6, 0.12),
            Joints::new(0.43, 1.25, -0.2, -1.55, 0.125),
            Joints::new(0.01, 0.0, 0.005, 0.0, 0.0),
            vec![1, 3],
            [1e-3, 2e-3, 1.5e-3, 1e-4, 2e-4, 3e-4],
        )
        .unwrap()
    }

    /// Camera poses consistent with the robot (plus a perturbation), and the blocks' values.
    fn values(perturb: f64) -> Vec<Vec<f64>> {
        let r = residual();
        let b = base();
        let mut off = r.fixed_offsets;
        off[1] = -0.012;
        off[3] = 0.008;
        let robot = WaferRobot {
            params: r.params,
            base: b,
        };
        let x_t = robot.camera_pose(&(r.q_t - off));
        let x_n = se3_plus(
            &robot.camera_pose(&(r.q_next - off)),
            &Vector6::new(1.0, -2.0, 0.5, 3.0, 1.0, -2.0).scale(perturb),
        );
        vec![
            se3_to_params(&x_t).to_vec(),
            se3_to_params(&x_n).to_vec(),
            se3_to_params(&b).to_vec(),
            vec![off[1]],
            vec![off[3]],
        ]
    }

    fn eval(r: &RobotMotionResidual, v: &[Vec<f64>], jac: bool) -> (Vec<f64>, Vec<DMatrix<f64>>) {
        let p: Vec<&[f64]> = v.iter().map(|x| x.as_slice()).collect();
        let mut res = vec![0.0; 6];
        let mut j = vec![
            DMatrix::zeros(6, 6),
            DMatrix::zeros(6, 6),
            DMatrix::zeros(6, 6),
            DMatrix::zeros(6, 1),
            DMatrix::zeros(6, 1),
        ];
        r.evaluate(&p, &mut res, if jac { Some(&mut j) } else { None })
            .unwrap();
        (res, j)
    }

    #[test]
    fn zero_when_the_cameras_follow_the_robot() {
        let (res, _) = eval(&residual(), &values(0.0), false);
        assert!(res.iter().all(|v| v.abs() < 1e-8), "{res:?}");
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let r = residual();
        let v = values(1e-3);
        let (r0, j) = eval(&r, &v, true);
        let h = 1e-7;
        for (blk, dim) in [(0usize, 6usize), (1, 6), (2, 6), (3, 1), (4, 1)] {
            for c in 0..dim {
                let mut v2 = v.clone();
                if dim == 6 {
                    let mut d = Vector6::zeros();
                    d[c] = h;
                    v2[blk] = se3_to_params(&se3_plus(&se3_from_params(&v[blk]), &d)).to_vec();
                } else {
                    v2[blk][0] += h;
                }
                let (r1, _) = eval(&r, &v2, false);
                for (row, (a, b)) in r1.iter().zip(&r0).enumerate() {
                    let fd = (a - b) / h;
                    let an = j[blk][(row, c)];
                    assert!(
                        (fd - an).abs() < 1e-4 * (1.0 + an.abs()),
                        "block {blk} row {row} col {c}: fd {fd} vs {an}"
                    );
                }
            }
        }
    }

    #[test]
    fn invalid_sigma_is_an_error() {
        let r = RobotMotionResidual::new(
            RobotParams::default(),
            Joints::zeros(),
            Joints::zeros(),
            Joints::zeros(),
            vec![],
            [0.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        );
        assert!(r.is_err());
    }
}
