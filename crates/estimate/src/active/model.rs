//! The linearised observation model of the hand-eye system and its Kalman-filter estimator,
//! 000_3b1454b2b2194811.txt ch. 6.3, eqs. (6.11)–(6.15).
//!
//! Parameters (the full set, in this order; [`ParamMask`] picks the estimated subset):
//!
//! | index | name | perturbation |
//! |---|---|---|
//! | 0–2 | `opening_r{x,y,z}_deg` | object rotation `δR_s`: `R_wo ← R_wo · Exp(δ)` (right, object frame) |
//! | 3–5 | `opening_{x,y,z}_mm` | object translation `δt_s`: `t_wo ← t_wo + δ` (world frame) |
//! | 6–8 | `camera_{x,y,z}_mm` | camera mount translation `δt_c`: `t_e2c ← t_e2c + δ` (blade-2 frame) |
//! | 9–13 | `joint{1..4}_deg`, `lift_mm` | joint zero offsets `δθ`: `q_true = q_enc − δθ` |
//!
//! The names carry the units used in reports; internally everything is SI (radians, metres).
//! The camera mount rotation (`Q_1` of (6.11)) is pre-calibrated and fixed, as in the seed.

use autoteach_geometry::camera::Camera;
use autoteach_geometry::lie;
use autoteach_geometry::robot::{Blade, Joints, WaferRobot};
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix2x3, Matrix3, SymmetricEigen, Translation3, UnitQuaternion,
    Vector2, Vector3,
};

use super::design::{self, ObservabilityIndices};
use crate::{EstimateError, Result};

/// Number of parameters of the full hand-eye error model.
pub const N_FULL: usize = 14;

/// Names of the full parameter vector (units in the suffix), see the module table.
pub const PARAM_NAMES: [&str; N_FULL] = [
    "opening_rx_deg",
    "opening_ry_deg",
    "opening_rz_deg",
    "opening_x_mm",
    "opening_y_mm",
    "opening_z_mm",
    "camera_x_mm",
    "camera_y_mm",
    "camera_z_mm",
    "joint1_deg",
    "joint2_deg",
    "joint3_deg",
    "joint4_deg",
    "lift_mm",
];

/// Factor from SI units to the reporting unit of parameter `i` (degrees or millimetres).
pub fn report_scale(i: usize) -> f64 {
    match i {
        0..=2 | 9..=12 => 180.0 / std::f64::consts::PI,
        _ => 1000.0,
    }
}

/// Which parameters of the full model are estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamMask(pub [bool; N_FULL]);

impl Default for ParamMask {
    /// The planner's estimation variable of the seed, `x = [δR_s, δT_s, δT_c]` (ch. 6.3), with
    /// the vertical camera offset left out: the camera only yaws, so `δt_c,z` and the opening
    /// height `δt_s,z` enter every observation through their difference and cannot be separated
    /// (Table 6.4 reports no camera Z either).
    fn default() -> Self {
        let mut m = [false; N_FULL];
        m[..8].iter_mut().for_each(|v| *v = true);
        Self(m)
    }
}

impl ParamMask {
    /// The mask estimating the named parameters (names of [`PARAM_NAMES`]).
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Result<Self> {
        let mut m = [false; N_FULL];
        for n in names {
            let Some(i) = PARAM_NAMES.iter().position(|p| *p == n.as_ref()) else {
                return Err(EstimateError::InvalidProblem(format!(
                    "unknown hand-eye parameter {:?}; expected one of {PARAM_NAMES:?}",
                    n.as_ref()
                )));
            };
            m[i] = true;
        }
        let mask = Self(m);
        mask.check()?;
        Ok(mask)
    }

    /// Indices of the estimated parameters in the full vector.
    pub fn indices(&self) -> Vec<usize> {
        (0..N_FULL).filter(|&i| self.0[i]).collect()
    }

    /// Names of the estimated parameters.
    pub fn names(&self) -> Vec<&'static str> {
        self.indices().into_iter().map(|i| PARAM_NAMES[i]).collect()
    }

    /// Number of estimated parameters.
    pub fn len(&self) -> usize {
        self.0.iter().filter(|v| **v).count()
    }

    /// Whether no parameter is estimated.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn check(&self) -> Result<()> {
        if self.is_empty() {
            return Err(EstimateError::InvalidProblem(
                "the parameter mask selects no parameter".into(),
            ));
        }
        Ok(())
    }
}

/// Values of the hand-eye parameters (true, nominal or estimated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandEyeParams {
    /// Pose of the object (chamber opening) in the world, `T_wo`.
    pub opening: Isometry3<f64>,
    /// Camera mount translation `t_e2c` in the blade-2 frame.
    pub camera_translation: Vector3<f64>,
    /// Joint zero offsets (encoder = true + offset).
    pub joint_offsets: Joints,
}

impl HandEyeParams {
    /// The nominal parameters: the given opening pose, the robot's nominal camera mount and zero
    /// joint offsets.
    pub fn nominal(robot: &WaferRobot, opening: Isometry3<f64>) -> Self {
        Self {
            opening,
            camera_translation: robot.camera_mount().translation.vector,
            joint_offsets: Joints::zeros(),
        }
    }

    /// `self ⊞ δ`: applies a full-length (14) perturbation with the conventions of the module
    /// table.
    pub fn plus_full(&self, delta: &[f64; N_FULL]) -> Self {
        let w = Vector3::new(delta[0], delta[1], delta[2]);
        let rot = self.opening.rotation * UnitQuaternion::from_scaled_axis(w);
        let t = self.opening.translation.vector + Vector3::new(delta[3], delta[4], delta[5]);
        Self {
            opening: Isometry3::from_parts(Translation3::from(t), rot),
            camera_translation: self.camera_translation
                + Vector3::new(delta[6], delta[7], delta[8]),
            joint_offsets: self.joint_offsets
                + Joints::new(delta[9], delta[10], delta[11], delta[12], delta[13]),
        }
    }

    /// `self ⊞ δ` for a perturbation of the masked parameters only.
    pub fn plus(&self, mask: &ParamMask, delta: &[f64]) -> Result<Self> {
        let idx = mask.indices();
        if delta.len() != idx.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "parameter perturbation".into(),
                expected: vec![idx.len()],
                got: vec![delta.len()],
            });
        }
        let mut full = [0.0; N_FULL];
        for (k, &i) in idx.iter().enumerate() {
            full[i] = delta[k];
        }
        Ok(self.plus_full(&full))
    }

    /// `other ⊟ self` in the full parameterisation: the perturbation taking `self` to `other`
    /// (rotation `Log(R_selfᵀ R_other)`, differences of the rest).
    pub fn minus_full(&self, other: &Self) -> [f64; N_FULL] {
        let w = lie::so3_log(
            &(self.opening.rotation.inverse() * other.opening.rotation).to_rotation_matrix(),
        );
        let t = other.opening.translation.vector - self.opening.translation.vector;
        let c = other.camera_translation - self.camera_translation;
        let o = other.joint_offsets - self.joint_offsets;
        [
            w.x, w.y, w.z, t.x, t.y, t.z, c.x, c.y, c.z, o[0], o[1], o[2], o[3], o[4],
        ]
    }
}

/// The observation model of 000_3b1454b2b2194811.txt eqs. (6.11)–(6.14): the pixels of the
/// object's corner points seen by the blade camera at given encoder readings.
#[derive(Debug, Clone)]
pub struct HandEyeModel {
    /// The robot (nominal kinematics and base pose).
    pub robot: WaferRobot,
    /// The calibrated camera intrinsics.
    pub camera: Camera,
    /// Corner points `X_j` of the object in its own frame.
    pub corners: Vec<Vector3<f64>>,
    /// Estimated parameters.
    pub mask: ParamMask,
}

impl HandEyeModel {
    /// Creates a model after validating the corners (at least one, finite) and the mask.
    pub fn new(
        robot: WaferRobot,
        camera: Camera,
        corners: Vec<Vector3<f64>>,
        mask: ParamMask,
    ) -> Result<Self> {
        if corners.is_empty() {
            return Err(EstimateError::DimensionMismatch {
                what: "object corner points".into(),
                expected: vec![1, 3],
                got: vec![0, 3],
            });
        }
        for (j, c) in corners.iter().enumerate() {
            if let Some((k, &v)) = c.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(EstimateError::NonFiniteInput {
                    what: "object corner points".into(),
                    index: 3 * j + k,
                    value: v,
                });
            }
        }
        mask.check()?;
        Ok(Self {
            robot,
            camera,
            corners,
            mask,
        })
    }

    /// The mount `T_e2c` with the parameters' camera translation and the fixed rotation `Q_1`.
    pub fn mount(&self, params: &HandEyeParams) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(params.camera_translation),
            self.robot.camera_mount().rotation,
        )
    }

    /// World camera pose `T_wc = T_wb · T_be2(q_enc − δθ) · T_e2c`, eq. (2.2).
    pub fn camera_pose(&self, params: &HandEyeParams, q_enc: &Joints) -> Isometry3<f64> {
        let q = q_enc - params.joint_offsets;
        self.robot.base * self.robot.blade_pose(&q, Blade::Two) * self.mount(params)
    }

    /// Corner points in the camera frame.
    pub fn corners_in_camera(&self, params: &HandEyeParams, q_enc: &Joints) -> Vec<Vector3<f64>> {
        let t_cw = self.camera_pose(params, q_enc).inverse();
        self.corners
            .iter()
            .map(|x| (t_cw * (params.opening * nalgebra::Point3::from(*x))).coords)
            .collect()
    }

    /// Pixels of every corner (`None` where the corner cannot be projected, e.g. behind the
    /// camera).
    pub fn project(
        &self,
        params: &HandEyeParams,
        q_enc: &Joints,
    ) -> Result<Vec<Option<Vector2<f64>>>> {
        check_joints(q_enc)?;
        Ok(self
            .corners_in_camera(params, q_enc)
            .iter()
            .map(|p| self.camera.project(p).ok())
            .collect())
    }

    /// The observation matrix of eq. (6.14) for the full parameter set: pixels of the corners
    /// and `∂pixel/∂γ` (`2m × 14`, rows `u_j, v_j` per corner), both measured image axes playing
    /// the role of the normal `â`.
    ///
    /// Per corner with `p_c = T_wc⁻¹ (R_wo X + t_wo)` and `∂x/∂p_c = (K_12 − x K_3)/(K_3 p_c)`
    /// (from the camera model):
    /// `∂p_c/∂δR_s = −R_wcᵀ R_wo [X]×`, `∂p_c/∂δt_s = R_wcᵀ`, `∂p_c/∂δt_c = −Q_1ᵀ` and
    /// `∂p_c/∂δθ = Q_1ᵀ R_beᵀ (J_pos + [e_z × (P_b − t_be)] J_yaw)` (the `J + dRX/dθ` of (6.11)
    /// and (6.13); `J` the blade Jacobian (2.5), `P_b` the corner in the base frame).
    ///
    /// Errors: a corner that cannot be projected (behind the camera), non-finite joints.
    pub fn full_jacobian(
        &self,
        params: &HandEyeParams,
        q_enc: &Joints,
    ) -> Result<(Vec<Vector2<f64>>, DMatrix<f64>)> {
        check_joints(q_enc)?;
        let q = q_enc - params.joint_offsets;
        let t_be = self.robot.blade_pose(&q, Blade::Two);
        let mount = self.mount(params);
        let r_wb = self.robot.base.rotation.to_rotation_matrix().into_inner();
        let r_be = t_be.rotation.to_rotation_matrix().into_inner();
        let r_ec = mount.rotation.to_rotation_matrix().into_inner();
        let r_wc = r_wb * r_be * r_ec;
        let r_wo = params.opening.rotation.to_rotation_matrix().into_inner();
        let j_blade = self.robot.jacobian(&q, Blade::Two);
        let t_wc = self.camera_pose(params, q_enc);
        let m = self.corners.len();
        let mut pixels = Vec::with_capacity(m);
        let mut c = DMatrix::zeros(2 * m, N_FULL);
        for (j, x) in self.corners.iter().enumerate() {
            let p_w = params.opening * nalgebra::Point3::from(*x);
            let p_c = (t_wc.inverse() * p_w).coords;
            let (px, jp, _) = self.camera.project_jacobians(&p_c)?;
            pixels.push(px);
            let jp: Matrix2x3<f64> = jp;
            let p_b = self.robot.base.inverse() * p_w;
            let lever = p_b.coords - t_be.translation.vector;
            let ez_lever = Vector3::z().cross(&lever);
            let mut dq = DMatrix::<f64>::zeros(3, 5);
            for col in 0..5 {
                let v = Vector3::new(j_blade[(0, col)], j_blade[(1, col)], j_blade[(2, col)])
                    + ez_lever * j_blade[(3, col)];
                let d = -(r_ec.transpose() * r_be.transpose() * v);
                dq.fixed_view_mut::<3, 1>(0, col).copy_from(&d);
            }
            let blocks: [DMatrix<f64>; 4] = [
                to_dyn(&(-(r_wc.transpose() * r_wo * lie::hat(x)))),
                to_dyn(&r_wc.transpose()),
                to_dyn(&(-r_ec.transpose())),
                -dq, // offsets: q = q_enc − δθ
            ];
            let jp_dyn = DMatrix::from_column_slice(2, 3, jp.as_slice());
            let mut col = 0;
            for b in &blocks {
                let v = &jp_dyn * b;
                c.view_mut((2 * j, col), (2, v.ncols())).copy_from(&v);
                col += v.ncols();
            }
        }
        Ok((pixels, c))
    }

    /// Pixels and the observation matrix `C` (eq. (6.14)) restricted to the estimated
    /// parameters (`2m × k`).
    pub fn linearize(
        &self,
        params: &HandEyeParams,
        q_enc: &Joints,
    ) -> Result<(Vec<Vector2<f64>>, DMatrix<f64>)> {
        let (px, full) = self.full_jacobian(params, q_enc)?;
        Ok((px, full.select_columns(self.mask.indices().iter())))
    }
}

fn to_dyn(m: &Matrix3<f64>) -> DMatrix<f64> {
    DMatrix::from_column_slice(3, 3, m.as_slice())
}

fn check_joints(q: &Joints) -> Result<()> {
    match q.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        Some((index, &value)) => Err(EstimateError::NonFiniteInput {
            what: "joints".into(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// Summary of one [`HandEyeEstimator::update`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpdateSummary {
    /// Corners used (detected and projectable under the estimate).
    pub used: usize,
    /// Gauss–Newton iterations of the iterated update.
    pub iterations: usize,
    /// RMS pixel residual after the update.
    pub rms_px: f64,
}

/// The Kalman filter of the static calibration state, 000_3b1454b2b2194811.txt eq. (6.15):
/// `x(k+1) = x(k)`, `y(k) = C(k) x(k) + v`, `P⁻¹(k+1) = P⁻¹(k) + Cᵀ(k) V⁻¹ C(k)`, with the
/// nonlinear projection handled by an iterated (Gauss–Newton) measurement update.
#[derive(Debug, Clone)]
pub struct HandEyeEstimator {
    /// The observation model.
    pub model: HandEyeModel,
    /// The current estimate.
    pub estimate: HandEyeParams,
    /// Information matrix `P⁻¹` of the estimated parameters (`k × k`).
    information: DMatrix<f64>,
    /// Pixel noise standard deviation `σ` (`V = σ² I`).
    pub sigma_px: f64,
}

impl HandEyeEstimator {
    /// Starts from `estimate` with the prior standard deviations (SI units, one per estimated
    /// parameter) and pixel noise `sigma_px`.
    pub fn new(
        model: HandEyeModel,
        estimate: HandEyeParams,
        prior_sigmas: &[f64],
        sigma_px: f64,
    ) -> Result<Self> {
        let k = model.mask.len();
        if prior_sigmas.len() != k {
            return Err(EstimateError::DimensionMismatch {
                what: "prior standard deviations".into(),
                expected: vec![k],
                got: vec![prior_sigmas.len()],
            });
        }
        if let Some(&s) = prior_sigmas.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(EstimateError::InvalidParameter {
                name: "prior sigma",
                value: s,
                reason: "prior standard deviations must be positive and finite",
            });
        }
        if !(sigma_px.is_finite() && sigma_px > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "sigma_px",
                value: sigma_px,
                reason: "pixel noise must be positive and finite",
            });
        }
        let info = DMatrix::from_diagonal(&DVector::from_iterator(
            k,
            prior_sigmas.iter().map(|s| 1.0 / (s * s)),
        ));
        Ok(Self {
            model,
            estimate,
            information: info,
            sigma_px,
        })
    }

    /// The information matrix `P⁻¹` (the FIM of the measurements so far plus the prior).
    pub fn information(&self) -> &DMatrix<f64> {
        &self.information
    }

    /// Replaces the information matrix (validated symmetric positive definite).
    pub fn set_information(&mut self, info: DMatrix<f64>) -> Result<()> {
        let k = self.model.mask.len();
        if info.nrows() != k || info.ncols() != k {
            return Err(EstimateError::DimensionMismatch {
                what: "information matrix".into(),
                expected: vec![k, k],
                got: vec![info.nrows(), info.ncols()],
            });
        }
        design::cholesky("information matrix", &info)?;
        self.information = design::symmetric("information matrix", &info)?;
        Ok(())
    }

    /// The covariance `P` (inverse of the information, by Cholesky).
    pub fn covariance(&self) -> Result<DMatrix<f64>> {
        let ch = design::cholesky("information matrix", &self.information)?;
        Ok(ch.inverse())
    }

    /// Observability indices (Table 6.2) of the current information matrix.
    pub fn indices(&self, power: f64) -> Result<ObservabilityIndices> {
        design::observability_indices(&self.information, power)
    }

    /// The measurement update with detected corner pixels at encoder readings `q_enc`
    /// (`detections[j]` for corner `j`, `None` when not detected).
    ///
    /// Iterated EKF: Gauss–Newton on `½‖δ‖²_{P⁻¹} + ½‖y − h(x̂ ⊞ δ)‖²_{V⁻¹}` (at most 10
    /// iterations), then `x̂ ← x̂ ⊞ δ` and `P⁻¹ ← P⁻¹ + CᵀV⁻¹C` with `C` at the updated estimate
    /// (eq. (6.15)). With no usable detection the state is unchanged.
    pub fn update(
        &mut self,
        q_enc: &Joints,
        detections: &[Option<Vector2<f64>>],
    ) -> Result<UpdateSummary> {
        check_joints(q_enc)?;
        if detections.len() != self.model.corners.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "detections".into(),
                expected: vec![self.model.corners.len()],
                got: vec![detections.len()],
            });
        }
        for (j, d) in detections.iter().enumerate() {
            if let Some(d) = d
                && let Some((k, &v)) = d.iter().enumerate().find(|(_, v)| !v.is_finite())
            {
                return Err(EstimateError::NonFiniteInput {
                    what: "detections".into(),
                    index: 2 * j + k,
                    value: v,
                });
            }
        }
        let k = self.model.mask.len();
        let prior = self.estimate;
        let mut delta = DVector::zeros(k);
        let inv_var = 1.0 / (self.sigma_px * self.sigma_px);
        let mut iterations = 0;
        let mut last: Option<(DMatrix<f64>, DVector<f64>)> = None;
        for it in 0..10 {
            iterations = it + 1;
            let x = prior.plus(&self.model.mask, delta.as_slice())?;
            let Some((h, r)) = self.stacked(&x, q_enc, detections)? else {
                return Ok(UpdateSummary {
                    used: 0,
                    iterations: 0,
                    rms_px: f64::NAN,
                });
            };
            let lhs = &self.information + h.transpose() * &h * inv_var;
            let rhs = h.transpose() * &r * inv_var - &self.information * &delta;
            let ch = design::cholesky("posterior information", &lhs)?;
            let step = ch.solve(&rhs);
            delta += &step;
            last = Some((h, r));
            if step.norm() < 1e-10 * (1.0 + delta.norm()) {
                break;
            }
        }
        self.estimate = prior.plus(&self.model.mask, delta.as_slice())?;
        // Information at the final estimate (6.15).
        let (h, r) = match self.stacked(&self.estimate, q_enc, detections)? {
            Some(v) => v,
            None => last.unwrap_or_else(|| (DMatrix::zeros(0, k), DVector::zeros(0))),
        };
        self.information = design::symmetric(
            "posterior information",
            &(&self.information + h.transpose() * &h * inv_var),
        )?;
        Ok(UpdateSummary {
            used: r.len() / 2,
            iterations,
            rms_px: (r.norm_squared() / r.len().max(1) as f64).sqrt(),
        })
    }

    /// Stacked Jacobian and residual `y − h(x)` of the detected, projectable corners.
    fn stacked(
        &self,
        x: &HandEyeParams,
        q_enc: &Joints,
        detections: &[Option<Vector2<f64>>],
    ) -> Result<Option<(DMatrix<f64>, DVector<f64>)>> {
        let cam = self.model.corners_in_camera(x, q_enc);
        let usable: Vec<usize> = (0..detections.len())
            .filter(|&j| detections[j].is_some() && self.model.camera.project(&cam[j]).is_ok())
            .collect();
        if usable.is_empty() {
            return Ok(None);
        }
        let (px, c) = self.model.linearize_subset(x, q_enc, &usable)?;
        let mut r = DVector::zeros(2 * usable.len());
        for (row, (&j, p)) in usable.iter().zip(&px).enumerate() {
            if let Some(d) = detections[j] {
                r[2 * row] = d.x - p.x;
                r[2 * row + 1] = d.y - p.y;
            }
        }
        Ok(Some((c, r)))
    }

    /// Smallest and largest eigenvalue of the covariance, for diagnostics.
    pub fn covariance_range(&self) -> Result<(f64, f64)> {
        let p = self.covariance()?;
        let ev = SymmetricEigen::new(p).eigenvalues;
        Ok((ev.min(), ev.max()))
    }
}

impl HandEyeModel {
    /// [`HandEyeModel::linearize`] for a subset of the corners (rows of the chosen corners only).
    pub fn linearize_subset(
        &self,
        params: &HandEyeParams,
        q_enc: &Joints,
        corners: &[usize],
    ) -> Result<(Vec<Vector2<f64>>, DMatrix<f64>)> {
        let sub = HandEyeModel {
            robot: self.robot,
            camera: self.camera.clone(),
            corners: corners
                .iter()
                .map(|&j| {
                    self.corners
                        .get(j)
                        .copied()
                        .ok_or_else(|| EstimateError::DimensionMismatch {
                            what: format!("corner index {j}"),
                            expected: vec![self.corners.len()],
                            got: vec![j],
                        })
                })
                .collect::<Result<_>>()?,
            mask: self.mask,
        };
        sub.linearize(params, q_enc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    pub(crate) fn test_model(mask: ParamMask) -> (HandEyeModel, HandEyeParams, Joints) {
        let robot = WaferRobot::default();
        let camera = Camera::pinhole(900.0, 900.0, 639.5, 479.5, 1280, 960).unwrap();
        let corners = vec![
            Vector3::new(0.0, 0.17, 0.025),
            Vector3::new(0.0, -0.17, 0.025),
            Vector3::new(0.0, -0.17, -0.025),
            Vector3::new(0.0, 0.17, -0.025),
        ];
        let model = HandEyeModel::new(robot, camera, corners, mask).unwrap();
        let q = Joints::new(-0.9, 1.7, 0.0, -0.75, 0.05);
        let t_wc = robot.camera_pose(&q);
        // Put the opening 0.5 m in front of the camera, facing it roughly.
        let centre = t_wc * nalgebra::Point3::new(0.03, -0.02, 0.5);
        let yaw = (t_wc.rotation * Vector3::z())
            .y
            .atan2((t_wc.rotation * Vector3::z()).x);
        let opening = Isometry3::from_parts(
            Translation3::from(centre.coords),
            UnitQuaternion::from_euler_angles(0.01, -0.02, yaw + 0.1),
        );
        let mut params = HandEyeParams::nominal(&robot, opening);
        params.camera_translation += Vector3::new(0.004, -0.003, 0.002);
        params.joint_offsets = Joints::new(0.01, -0.02, 0.003, 0.015, 0.002);
        (model, params, q)
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let mut all = ParamMask([true; N_FULL]);
        all.0[11] = true;
        let (model, params, q) = test_model(all);
        let (px, c) = model.full_jacobian(&params, &q).unwrap();
        let h = 1e-6;
        for i in 0..N_FULL {
            let mut d = [0.0; N_FULL];
            d[i] = h;
            let plus = model.project(&params.plus_full(&d), &q).unwrap();
            d[i] = -h;
            let minus = model.project(&params.plus_full(&d), &q).unwrap();
            for j in 0..4 {
                let num = (plus[j].unwrap() - minus[j].unwrap()) / (2.0 * h);
                let scale = c.column(i).amax().max(1.0);
                assert!(
                    (num.x - c[(2 * j, i)]).abs() < 1e-5 * scale
                        && (num.y - c[(2 * j + 1, i)]).abs() < 1e-5 * scale,
                    "param {} corner {j}: numeric {num:?}, analytic ({}, {})",
                    PARAM_NAMES[i],
                    c[(2 * j, i)],
                    c[(2 * j + 1, i)]
                );
            }
            let _ = &px;
        }
        // Blade-1 wrist (joint3) does not move the camera.
        assert!(c.column(11).amax() < 1e-12);
    }

    #[test]
    fn joint_columns_agree_with_the_camera_jacobian() {
        // With the nominal mount the joint block equals −∂x/∂p_c [[p_c]×, −I] J_cam.
        let (model, mut params, q) = test_model(ParamMask([true; N_FULL]));
        params.camera_translation = model.robot.camera_mount().translation.vector;
        params.joint_offsets = Joints::zeros();
        let (_, c) = model.full_jacobian(&params, &q).unwrap();
        let jc = model.robot.camera_jacobian(&q);
        let cam = model.corners_in_camera(&params, &q);
        for (j, p_c) in cam.iter().enumerate() {
            let (_, jp, _) = model.camera.project_jacobians(p_c).unwrap();
            let mut g = nalgebra::Matrix3x6::zeros();
            g.fixed_view_mut::<3, 3>(0, 0).copy_from(&lie::hat(p_c));
            g.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&(-Matrix3::identity()));
            let expected = -(jp * g * jc);
            for col in 0..5 {
                assert_relative_eq!(
                    c[(2 * j, 9 + col)],
                    expected[(0, col)],
                    epsilon = 1e-8,
                    max_relative = 1e-8
                );
                assert_relative_eq!(
                    c[(2 * j + 1, 9 + col)],
                    expected[(1, col)],
                    epsilon = 1e-8,
                    max_relative = 1e-8
                );
            }
        }
    }

    #[test]
    fn iterated_update_converges_to_truth_with_noise_free_views() {
        let mask = ParamMask::default();
        let (model, truth, _) = test_model(mask);
        // Perturb the estimated parameters away from the truth.
        let start = truth
            .plus(
                &mask,
                &[0.01, -0.01, 0.02, 0.01, -0.015, 0.005, 0.01, -0.01],
            )
            .unwrap();
        let start = HandEyeParams {
            camera_translation: Vector3::new(
                start.camera_translation.x,
                start.camera_translation.y,
                truth.camera_translation.z,
            ),
            ..start
        };
        // A weak prior, so that the MAP estimate is the noise-free truth up to ~1e-8.
        let sig = [1.0; 8];
        let mut est = HandEyeEstimator::new(model.clone(), start, &sig, 0.5).unwrap();
        // Views from several blade yaws and positions.
        let base_q = Joints::new(-0.9, 1.7, 0.0, -0.75, 0.05);
        for (k, dyaw) in [-0.25, 0.0, 0.25, -0.15, 0.15, 0.3].iter().enumerate() {
            let mut q = base_q;
            q[3] += dyaw;
            q[0] += 0.05 * k as f64 - 0.1;
            q[1] -= 0.08 * (k % 2) as f64;
            let det = model.project(&truth, &q).unwrap();
            est.update(&q, &det).unwrap();
        }
        let err = est.estimate.minus_full(&truth);
        for i in mask.indices() {
            assert!(err[i].abs() < 1e-6, "{}: {}", PARAM_NAMES[i], err[i]);
        }
        let ind = est.indices(2.0).unwrap();
        assert!(ind.o3 > 0.0);
    }

    #[test]
    fn bad_inputs_are_rejected() {
        let (model, params, q) = test_model(ParamMask::default());
        assert!(ParamMask::from_names(&["nope"]).is_err());
        assert!(ParamMask::from_names::<&str>(&[]).is_err());
        assert!(HandEyeEstimator::new(model.clone(), params, &[1.0; 3], 0.5).is_err());
        assert!(HandEyeEstimator::new(model.clone(), params, &[1.0; 8], 0.0).is_err());
        let mut est = HandEyeEstimator::new(model.clone(), params, &[0.01; 8], 0.5).unwrap();
        assert!(est.update(&q, &[None; 3]).is_err());
        assert!(
            est.update(&q, &[Some(Vector2::new(f64::NAN, 0.0)), None, None, None])
                .is_err()
        );
        let mut bad = q;
        bad[0] = f64::INFINITY;
        assert!(model.project(&params, &bad).is_err());
        // No detection: unchanged state.
        let before = est.information().clone();
        let s = est.update(&q, &[None; 4]).unwrap();
        assert_eq!(s.used, 0);
        assert_eq!(&before, est.information());
    }
}
