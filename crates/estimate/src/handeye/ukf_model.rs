//! The UKF auto-teaching model of 000_3b1454b2b2194811.txt §5.2, eqs. (5.1)–(5.2).

use autoteach_geometry::lie::{so3_exp, so3_log};
use autoteach_geometry::robot::{Blade, Joints, WaferRobot, wrap_angle};
use nalgebra::{
    DMatrix, DVector, DVectorView, Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3,
};

use crate::ukf::UkfModel;
use crate::{EstimateError, Result};

/// Joints whose zero offsets the UKF estimates: θ1, θ2 and θ4 (the revolute joints that move
/// the blade-2 camera; θ3 drives blade 1 and the lift offset is not observable from motion
/// increments, see the module docs of [`super`]).
pub const UKF_OFFSET_JOINTS: [usize; 3] = [0, 1, 3];

/// Joints measured by the model (`z`): θ1, θ2, θ4 and the lift `h`.
pub const UKF_MEASURED_JOINTS: [usize; 4] = [0, 1, 3, 4];

/// Noise levels of eq. (5.2) (standard deviations, SI units), the defaults of the filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UkfNoise {
    /// `Var{w_T}^½`: process noise of the translation per step (m), x, y, z.
    pub w_t: [f64; 3],
    /// `Var{w_E}^½`: process noise of the rotation per step (rad).
    pub w_e: [f64; 3],
    /// `Var{v_T}^½`: measurement noise of the camera translation fed to the IK (m).
    pub v_t: [f64; 3],
    /// `Var{v_E}^½`: measurement noise of the camera rotation fed to the IK (rad).
    pub v_e: [f64; 3],
    /// `Var{v_θ}^½`: encoder noise of θ1, θ2, θ4 (rad) and of the lift (m).
    pub v_theta: [f64; 4],
}

impl Default for UkfNoise {
    /// The tuned values printed in eq. (5.2) (the lift, absent from the seed: 0.05 mm).
    fn default() -> Self {
        let deg = std::f64::consts::PI / 180.0;
        Self {
            w_t: [0.030, 0.030, 0.0015],
            w_e: [0.2 * deg; 3],
            v_t: [0.002, 0.002, 0.0005],
            v_e: [1.0 * deg; 3],
            v_theta: [0.05 * deg, 0.05 * deg, 0.05 * deg, 5e-5],
        }
    }
}

impl UkfNoise {
    /// Q (9×9, state order `[T; E; θ0]`): `w_T`, `w_E` and a zero block for the offsets
    /// ("there is no processing noise on the joint zeroing error"; 1e-24 keeps the augmented
    /// sigma-point covariance positive definite).
    pub fn q(&self) -> DMatrix<f64> {
        let mut d = DVector::from_element(9, 1e-24);
        for i in 0..3 {
            d[i] = self.w_t[i] * self.w_t[i];
            d[3 + i] = self.w_e[i] * self.w_e[i];
        }
        DMatrix::from_diagonal(&d)
    }

    /// R of the augmented measurement noise `v = [v_T; v_E; v_θ]` (10×10).
    pub fn r(&self) -> DMatrix<f64> {
        let mut d = DVector::zeros(10);
        for i in 0..3 {
            d[i] = self.v_t[i] * self.v_t[i];
            d[3 + i] = self.v_e[i] * self.v_e[i];
        }
        for i in 0..4 {
            d[6 + i] = self.v_theta[i] * self.v_theta[i];
        }
        DMatrix::from_diagonal(&d)
    }

    /// Checks that every value is finite and positive.
    pub fn validate(&self) -> Result<()> {
        let all = self
            .w_t
            .iter()
            .chain(&self.w_e)
            .chain(&self.v_t)
            .chain(&self.v_e)
            .chain(&self.v_theta);
        for v in all {
            if !(v.is_finite() && *v > 0.0) {
                return Err(EstimateError::InvalidParameter {
                    name: "UKF noise standard deviation",
                    value: *v,
                    reason: "must be finite and positive",
                });
            }
        }
        Ok(())
    }
}

/// The UKF auto-teaching model, eq. (5.1).
///
/// State `X = [T; φ; θ0]` (9): camera translation `T` (world, m), camera rotation `R_wc` as
/// a rotation vector `φ` (the seed writes Euler angles `E`; a rotation vector with the
/// manifold hooks of [`UkfModel`] avoids their singularities and is the same state), and the
/// joint zero offsets `θ0` of θ1, θ2, θ4. Process (input `u = [u_T; u_R]`, the visual-odometry
/// increment: translation change in the world frame and incremental rotation in the camera
/// frame): `T' = T + u_T + w_T`, `R' = R·Exp(u_R)·Exp(w_E)`, `θ0' = θ0`. Measurement: the
/// encoder readings `y = f_k⁻¹(T + v_T, R·Exp(v_E)) + θ0 + v_θ` of θ1, θ2, θ4 and the lift,
/// where `f_k⁻¹` is the robot's closed-form inverse kinematics for the camera pose (eq. (2.2)
/// solved for blade 2). (The seed's `− θ0` is `+ θ0` in autoteach's encoder convention
/// `q_enc = q_true + δ`.)
///
/// The IK needs a reachable blade orientation `Rz(ψ)·Ry(α2)`; sigma points carry roll/pitch
/// perturbations, so the blade yaw `ψ` is taken from the blade's x axis and the orientation is
/// projected onto the reachable set before solving. The elbow branch is the one of the
/// encoders (`elbow`), and the angles are unwrapped next to `reference` (the latest reading).
#[derive(Debug, Clone, PartialEq)]
pub struct AutoTeachUkfModel {
    /// The robot with its (known) base pose `T_wb`.
    pub robot: WaferRobot,
    /// Sign of θ2 of the IK branch to follow.
    pub elbow: f64,
    /// Angles are unwrapped next to this measurement (θ1, θ2, θ4, h).
    pub reference: [f64; 4],
}

impl AutoTeachUkfModel {
    /// A model for `robot` following the IK branch of `first_reading` (encoders, 5 joints).
    pub fn new(robot: WaferRobot, first_reading: &Joints) -> Result<Self> {
        if let Some((i, v)) = first_reading
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
        {
            return Err(EstimateError::NonFiniteInput {
                what: "encoder reading".into(),
                index: i,
                value: *v,
            });
        }
        let mut m = Self {
            robot,
            elbow: if first_reading[1] >= 0.0 { 1.0 } else { -1.0 },
            reference: [0.0; 4],
        };
        m.set_reference(first_reading);
        Ok(m)
    }

    /// Sets the unwrapping reference from an encoder reading (5 joints).
    pub fn set_reference(&mut self, reading: &Joints) {
        for (k, &j) in UKF_MEASURED_JOINTS.iter().enumerate() {
            self.reference[k] = reading[j];
        }
    }

    /// The camera pose of a state vector.
    pub fn state_pose(x: DVectorView<'_, f64>) -> Isometry3<f64> {
        let r = so3_exp(&Vector3::new(x[3], x[4], x[5]));
        Isometry3::from_parts(
            Translation3::new(x[0], x[1], x[2]),
            UnitQuaternion::from_rotation_matrix(&r),
        )
    }

    /// The state `[T; φ; θ0]` of a camera pose and offsets (θ1, θ2, θ4).
    pub fn state_of(t_wc: &Isometry3<f64>, offsets: &[f64; 3]) -> DVector<f64> {
        let phi = so3_log(&t_wc.rotation.to_rotation_matrix());
        let t = t_wc.translation.vector;
        DVector::from_vec(vec![
            t.x, t.y, t.z, phi.x, phi.y, phi.z, offsets[0], offsets[1], offsets[2],
        ])
    }

    /// `f_k⁻¹`: true joints (θ1, θ2, θ4, h) of a camera pose, projected onto the reachable
    /// orientations (see the type docs).
    pub fn inverse_kinematics(&self, t_wc: &Isometry3<f64>) -> Result<[f64; 4]> {
        let t_be2 = self.robot.base.inverse() * t_wc * self.robot.camera_mount().inverse();
        let r = t_be2.rotation.to_rotation_matrix();
        let x_axis = r.matrix().column(0);
        let psi = x_axis.y.atan2(x_axis.x);
        let proj = Isometry3::from_parts(
            t_be2.translation,
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), psi)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), self.robot.params.alpha2),
        );
        let sols = self.robot.inverse_kinematics(&proj, Blade::Two, 0.0)?;
        let q = sols
            .iter()
            .find(|s| s[1] * self.elbow >= 0.0)
            .or(sols.first())
            .ok_or_else(|| EstimateError::Model {
                function: "hx",
                step: 0,
                message: "inverse kinematics returned no solution".into(),
            })?;
        let mut out = [0.0; 4];
        for (k, &j) in UKF_MEASURED_JOINTS.iter().enumerate() {
            out[k] = if k < 3 {
                self.reference[k] + wrap_angle(q[j] - self.reference[k])
            } else {
                q[j]
            };
        }
        Ok(out)
    }

    fn measure(
        &self,
        x: DVectorView<'_, f64>,
        v: Option<DVectorView<'_, f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let mut pose = Self::state_pose(x);
        if let Some(v) = v {
            let rot = pose.rotation.to_rotation_matrix() * so3_exp(&Vector3::new(v[3], v[4], v[5]));
            pose = Isometry3::from_parts(
                Translation3::from(pose.translation.vector + Vector3::new(v[0], v[1], v[2])),
                UnitQuaternion::from_rotation_matrix(&rot),
            );
        }
        let q = self
            .inverse_kinematics(&pose)
            .map_err(|e| EstimateError::Model {
                function: "hx",
                step: 0,
                message: e.to_string(),
            })?;
        for k in 0..4 {
            out[k] = q[k] + if k < 3 { x[6 + k] } else { 0.0 } + v.map_or(0.0, |v| v[6 + k]);
        }
        Ok(())
    }
}

fn rot(x: DVectorView<'_, f64>) -> Rotation3<f64> {
    so3_exp(&Vector3::new(x[3], x[4], x[5]))
}

impl UkfModel for AutoTeachUkfModel {
    fn dim_x(&self) -> usize {
        9
    }

    fn dim_z(&self) -> usize {
        4
    }

    fn dim_u(&self) -> usize {
        6
    }

    fn dim_v(&self) -> usize {
        10
    }

    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        _dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.copy_from(&x);
        if let Some(u) = u {
            if u.len() != 6 {
                return Err(EstimateError::DimensionMismatch {
                    what: "visual-odometry increment u".into(),
                    expected: vec![6],
                    got: vec![u.len()],
                });
            }
            for i in 0..3 {
                out[i] += u[i];
            }
            let r = rot(x) * so3_exp(&Vector3::new(u[3], u[4], u[5]));
            let phi = so3_log(&r);
            out[3] = phi.x;
            out[4] = phi.y;
            out[5] = phi.z;
        }
        Ok(())
    }

    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        self.measure(x, None, out)
    }

    fn hx_noise(
        &self,
        x: DVectorView<'_, f64>,
        v: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        self.measure(x, Some(v), out)
    }

    fn x_add(
        &self,
        x: DVectorView<'_, f64>,
        dx: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.copy_from(&x);
        for i in [0, 1, 2, 6, 7, 8] {
            out[i] += dx[i];
        }
        let phi = so3_log(&(rot(x) * so3_exp(&Vector3::new(dx[3], dx[4], dx[5]))));
        out[3] = phi.x;
        out[4] = phi.y;
        out[5] = phi.z;
        Ok(())
    }

    fn x_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.copy_from(&a);
        *out -= b;
        let d = so3_log(&(rot(b).inverse() * rot(a)));
        out[3] = d.x;
        out[4] = d.y;
        out[5] = d.z;
        Ok(())
    }

    fn x_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        *out = sigmas * wm;
        // Rotation: iterative weighted mean on SO(3) from the first sigma point.
        let mut r = rot(sigmas.column(0));
        for _ in 0..5 {
            let mut acc = Vector3::zeros();
            for (i, w) in wm.iter().enumerate() {
                acc += so3_log(&(r.inverse() * rot(sigmas.column(i)))) * *w;
            }
            r *= so3_exp(&acc);
            if acc.norm() < 1e-14 {
                break;
            }
        }
        let phi = so3_log(&r);
        out[3] = phi.x;
        out[4] = phi.y;
        out[5] = phi.z;
        Ok(())
    }

    fn z_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        for k in 0..4 {
            let d = a[k] - b[k];
            out[k] = if k < 3 { wrap_angle(d) } else { d };
        }
        Ok(())
    }
}

/// The output of [`run_autoteach_ukf`]: the filtered state and covariance after every frame.
#[derive(Debug, Clone, PartialEq)]
pub struct UkfRun {
    /// Camera poses `T_wc` fused from visual odometry and encoders, one per frame.
    pub poses: Vec<Isometry3<f64>>,
    /// Offsets (θ1, θ2, θ4) after every frame (rad).
    pub offsets: Vec<[f64; 3]>,
    /// Their standard deviations after every frame (rad).
    pub offset_std: Vec<[f64; 3]>,
    /// The final 9×9 covariance of `[T; φ; θ0]`.
    pub covariance: DMatrix<f64>,
}

/// Runs the UKF of eqs. (5.1)–(5.2) over a session: frame 0 initialises the camera pose from
/// the encoders with zero offsets (the uncalibrated robot), each later frame predicts with the
/// visual-odometry increment from the previous frame and updates with its encoder reading.
///
/// `encoders`: `F` readings; `increments`: `F − 1` increments `[u_T; u_R]`; `offset_std0`:
/// prior standard deviation of each offset (rad). Errors: length mismatches, non-finite
/// inputs, unreachable poses and filter failures, each naming the frame.
pub fn run_autoteach_ukf(
    robot: WaferRobot,
    encoders: &[Joints],
    increments: &[[f64; 6]],
    noise: &UkfNoise,
    offset_std0: f64,
) -> Result<UkfRun> {
    use crate::ukf::{MerweScaledSigmaPoints, NoiseForm, SigmaPointFilter, UnscentedKalmanFilter};
    noise.validate()?;
    if encoders.is_empty() || increments.len() + 1 != encoders.len() {
        return Err(EstimateError::DimensionMismatch {
            what: "visual-odometry increments (one per frame after the first)".into(),
            expected: vec![encoders.len().saturating_sub(1)],
            got: vec![increments.len()],
        });
    }
    if !(offset_std0.is_finite() && offset_std0 > 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "offset_std0",
            value: offset_std0,
            reason: "the prior standard deviation of the offsets must be positive",
        });
    }
    for (f, inc) in increments.iter().enumerate() {
        if let Some((i, v)) = inc.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: format!("increment {f}"),
                index: i,
                value: *v,
            });
        }
    }
    let model = AutoTeachUkfModel::new(robot, &encoders[0])?;
    let t0 = robot.camera_pose(&encoders[0]);
    let mut ukf =
        UnscentedKalmanFilter::new(model, MerweScaledSigmaPoints::new(9, 0.5, 2.0, 0.0)?)?
            .with_noise(NoiseForm::Augmented)?;
    ukf.set_x(AutoTeachUkfModel::state_of(&t0, &[0.0; 3]))?;
    let mut p0 = DVector::zeros(9);
    // The initial pose is the uncalibrated forward kinematics: its error is the offsets' effect
    // (up to ~1.5 m lever arm times the offsets, and a rotation of up to three offsets).
    for i in 0..3 {
        p0[i] = (noise.v_t[i] * 5.0).max(1.5 * offset_std0).powi(2);
        p0[3 + i] = noise.v_e[i].max(3.0 * offset_std0).powi(2);
        p0[6 + i] = offset_std0 * offset_std0;
    }
    ukf.set_p(DMatrix::from_diagonal(&p0))?;
    ukf.set_q(noise.q())?;
    ukf.set_r(noise.r())?;
    let mut run = UkfRun {
        poses: Vec::new(),
        offsets: Vec::new(),
        offset_std: Vec::new(),
        covariance: DMatrix::zeros(9, 9),
    };
    let record = |ukf: &UnscentedKalmanFilter<AutoTeachUkfModel>, run: &mut UkfRun| {
        let x = ukf.x();
        let p = ukf.p();
        run.poses.push(AutoTeachUkfModel::state_pose(x.column(0)));
        run.offsets.push([x[6], x[7], x[8]]);
        run.offset_std.push([
            p[(6, 6)].max(0.0).sqrt(),
            p[(7, 7)].max(0.0).sqrt(),
            p[(8, 8)].max(0.0).sqrt(),
        ]);
    };
    let z_of = |q: &Joints| DVector::from_iterator(4, UKF_MEASURED_JOINTS.iter().map(|&j| q[j]));
    ukf.model_mut().set_reference(&encoders[0]);
    ukf.update(&z_of(&encoders[0]), None)
        .map_err(|e| frame_error(0, e))?;
    record(&ukf, &mut run);
    for (f, q) in encoders.iter().enumerate().skip(1) {
        if let Some((i, v)) = q.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: format!("encoder reading of frame {f}"),
                index: i,
                value: *v,
            });
        }
        let u = DVector::from_column_slice(&increments[f - 1]);
        ukf.predict(1.0, Some(&u)).map_err(|e| frame_error(f, e))?;
        ukf.model_mut().set_reference(q);
        ukf.update(&z_of(q), None).map_err(|e| frame_error(f, e))?;
        record(&ukf, &mut run);
    }
    run.covariance = ukf.p();
    Ok(run)
}

fn frame_error(frame: usize, e: EstimateError) -> EstimateError {
    EstimateError::Model {
        function: "autoteach UKF",
        step: frame,
        message: format!("frame {frame}: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::robot::RobotParams;

    #[test]
    fn measurement_inverts_forward_kinematics_with_offsets() {
        let robot = WaferRobot::new(
            RobotParams::default(),
            Isometry3::translation(-1.0, 0.03, -0.45),
        )
        .unwrap();
        let q = Joints::new(0.2, 1.4, 0.3, -1.5, 0.1);
        let off = [0.01, -0.004, 0.007];
        let m = AutoTeachUkfModel::new(robot, &q).unwrap();
        let x = AutoTeachUkfModel::state_of(&robot.camera_pose(&q), &off);
        let mut z = DVector::zeros(4);
        m.hx(x.column(0), &mut z).unwrap();
        let expect = [q[0] + off[0], q[1] + off[1], q[3] + off[2], q[4]];
        for k in 0..4 {
            assert!(
                (z[k] - expect[k]).abs() < 1e-9,
                "{k}: {} vs {}",
                z[k],
                expect[k]
            );
        }
    }

    #[test]
    fn manifold_hooks_are_consistent() {
        let robot = WaferRobot::default();
        let m = AutoTeachUkfModel::new(robot, &Joints::new(0.2, 1.4, 0.3, -1.5, 0.1)).unwrap();
        let x = DVector::from_vec(vec![0.1, 0.2, 0.3, 3.0, -0.2, 0.4, 0.01, 0.02, 0.03]);
        let d = DVector::from_vec(vec![0.01, -0.02, 0.03, 0.05, 0.2, -0.1, 0.001, 0.0, -0.002]);
        let mut y = DVector::zeros(9);
        m.x_add(x.column(0), d.column(0), &mut y).unwrap();
        let mut back = DVector::zeros(9);
        m.x_residual(y.column(0), x.column(0), &mut back).unwrap();
        assert!((back - d).norm() < 1e-12);
    }
}
