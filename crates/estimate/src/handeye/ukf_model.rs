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

/// The odometry fed to the UKF as the process input `u` of eq. (5.1) and the model of its errors.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum UkfOdometry {
    /// Eq. (5.1) read literally: `u_T` is the change of the camera translation in the world
    /// frame, `u_R` the incremental rotation in the camera frame, and their errors are white per
    /// step (`w_T`, `w_E` of [`UkfNoise`]). State `[T; φ; θ0]` (9).
    #[default]
    World,
    /// Relative poses `S(k)⁻¹·S(k+1)` of a visual SLAM with a map (the seed's ORB-SLAM2, §5.2):
    /// `u_T` in the camera frame of `k`. The SLAM localises every frame against its map, so its
    /// position error `e(k) = m(k) + l(k)` does not accumulate: `l` white (localisation), `m` a
    /// first-order Gauss–Markov map error. The state is augmented by `m` and `l`
    /// (`[T; φ; θ0; m; l]`, 15) so that the filter uses exactly this error model.
    Slam(SlamNoise),
}

/// Error model of [`UkfOdometry::Slam`] (standard deviations in SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlamNoise {
    /// Std of the white position error of every SLAM pose (m).
    pub loc_t: f64,
    /// Std of the white orientation error of every SLAM pose (rad); the incremental rotation
    /// carries `√2·loc_r` of white noise.
    pub loc_r: f64,
    /// Stationary std of the map's position error (m).
    pub map_t: f64,
    /// Correlation of the map error from one frame to the next, `a ∈ [0, 1)`:
    /// `m(k+1) = a·m(k) + N(0, (1 − a²)·map_t²)`.
    pub map_step: f64,
}

impl SlamNoise {
    /// Checks the values: finite, stds ≥ 0 with `loc_t > 0`, `0 ≤ map_step < 1`.
    pub fn validate(&self) -> Result<()> {
        for (name, v, min) in [
            ("SLAM loc_t", self.loc_t, f64::MIN_POSITIVE),
            ("SLAM loc_r", self.loc_r, 0.0),
            ("SLAM map_t", self.map_t, 0.0),
            ("SLAM map_step", self.map_step, 0.0),
        ] {
            if !(v.is_finite() && v >= min) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be finite and non-negative (loc_t positive)",
                });
            }
        }
        if self.map_step >= 1.0 {
            return Err(EstimateError::InvalidParameter {
                name: "SLAM map_step",
                value: self.map_step,
                reason: "the map-error correlation per frame must be < 1 (a stationary error)",
            });
        }
        Ok(())
    }

    /// Q of the augmented process noise `w = [w_m; w_l; w_R]` (9×9, diagonal).
    pub fn q(&self) -> DMatrix<f64> {
        let wm = (self.map_t * (1.0 - self.map_step * self.map_step).sqrt()).max(1e-12);
        let wr = (std::f64::consts::SQRT_2 * self.loc_r).max(1e-12);
        let mut d = DVector::zeros(9);
        for i in 0..3 {
            d[i] = wm * wm;
            d[3 + i] = self.loc_t * self.loc_t;
            d[6 + i] = wr * wr;
        }
        DMatrix::from_diagonal(&d)
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
    /// The odometry and its error model (default [`UkfOdometry::World`]).
    pub odometry: UkfOdometry,
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
            odometry: UkfOdometry::World,
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

    /// The camera orientation's deviation from the orientations the robot can reach (roll and
    /// pitch of the blade frame, rad): `Log(R_proj⁻¹·R_be2)` x and y, with `R_proj` the
    /// projection used by [`Self::inverse_kinematics`]. The encoders and the kinematics fix
    /// them (the robot cannot roll or pitch the blade), so the SLAM mode measures them as zero.
    pub fn reachability_residual(&self, t_wc: &Isometry3<f64>) -> [f64; 2] {
        let t_be2 = self.robot.base.inverse() * t_wc * self.robot.camera_mount().inverse();
        let r = t_be2.rotation.to_rotation_matrix();
        let x_axis = r.matrix().column(0);
        let psi = x_axis.y.atan2(x_axis.x);
        let proj = Rotation3::from_axis_angle(&Vector3::z_axis(), psi)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), self.robot.params.alpha2);
        let d = so3_log(&(proj.transpose() * r));
        [d.x, d.y]
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
        if out.len() == 6 {
            let d = self.reachability_residual(&pose);
            out[4] = d[0];
            out[5] = d[1];
        }
        Ok(())
    }
}

fn rot(x: DVectorView<'_, f64>) -> Rotation3<f64> {
    so3_exp(&Vector3::new(x[3], x[4], x[5]))
}

impl UkfModel for AutoTeachUkfModel {
    fn dim_x(&self) -> usize {
        match self.odometry {
            UkfOdometry::World => 9,
            UkfOdometry::Slam(_) => 15,
        }
    }

    fn dim_w(&self) -> usize {
        9
    }

    fn dim_z(&self) -> usize {
        match self.odometry {
            UkfOdometry::World => 4,
            // The SLAM increments turn the camera-frame u_T with the state's orientation, so
            // its roll and pitch must be pinned: two more components, measured as zero.
            UkfOdometry::Slam(_) => 6,
        }
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
            let r0 = rot(x);
            match self.odometry {
                UkfOdometry::World => {
                    for i in 0..3 {
                        out[i] += u[i];
                    }
                }
                UkfOdometry::Slam(n) => {
                    // t(k+1) = t(k) + R(k)·u_T − (e(k+1) − e(k)), e = m + l; mean of e(k+1): a·m(k).
                    let step = r0 * Vector3::new(u[0], u[1], u[2]);
                    for i in 0..3 {
                        out[i] += step[i] + x[12 + i] + (1.0 - n.map_step) * x[9 + i];
                        out[9 + i] = n.map_step * x[9 + i];
                        out[12 + i] = 0.0;
                    }
                }
            }
            let r = r0 * so3_exp(&Vector3::new(u[3], u[4], u[5]));
            let phi = so3_log(&r);
            out[3] = phi.x;
            out[4] = phi.y;
            out[5] = phi.z;
        }
        Ok(())
    }

    fn fx_noise(
        &self,
        x: DVectorView<'_, f64>,
        w: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let mut fx = DVector::zeros(self.dim_x());
        self.fx(x, dt, u, &mut fx)?;
        match self.odometry {
            UkfOdometry::World => self.x_add(fx.column(0), w, out),
            UkfOdometry::Slam(_) => {
                // w = [w_m; w_l; w_R]: m(k+1) = a·m + w_m, l(k+1) = w_l, both subtracted from t.
                let mut d = DVector::zeros(15);
                for i in 0..3 {
                    d[i] = -(w[i] + w[3 + i]);
                    d[3 + i] = w[6 + i];
                    d[9 + i] = w[i];
                    d[12 + i] = w[3 + i];
                }
                self.x_add(fx.column(0), d.column(0), out)
            }
        }
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
        for i in (0..x.len()).filter(|i| !(3..6).contains(i)) {
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
        for k in 0..a.len() {
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
    /// Whether each offset (θ1, θ2, θ4) is observable with this odometry. An unobservable one
    /// (θ1 with [`UkfOdometry::Slam`]) is not estimated: it stays at the prior mean 0 and its
    /// `offset_std` is the prior's.
    pub observable: [bool; 3],
}

/// Runs the UKF of eqs. (5.1)–(5.2) over a session with the odometry of eq. (5.1) read
/// literally ([`UkfOdometry::World`]); see [`run_autoteach_ukf_with`].
pub fn run_autoteach_ukf(
    robot: WaferRobot,
    encoders: &[Joints],
    increments: &[[f64; 6]],
    noise: &UkfNoise,
    offset_std0: f64,
) -> Result<UkfRun> {
    run_autoteach_ukf_with(
        robot,
        encoders,
        increments,
        noise,
        UkfOdometry::World,
        offset_std0,
    )
}

/// The prior of the state at frame 0: the uncalibrated forward kinematics `FK(q_enc(0))` (zero
/// offsets, "two trajectories start from the same beginning", §5.2) and its covariance, which
/// follows from the offsets' prior through the kinematics: every revolute joint turns about the
/// base z axis `z_w`, so `∂t/∂δ_j = −z_w × (t − p_j)` (`p_j` on joint j's axis: the base origin,
/// the elbow, the wrist) and `∂φ/∂δ_j = −Rᵀz_w`; `P0 = J·P_δ·Jᵀ` with the cross terms `J·P_δ`,
/// plus the encoder noise (`v_θ`) and the IK input noise (`v_T`, `v_E`) on the pose.
fn initial_prior(
    robot: &WaferRobot,
    q0: &Joints,
    noise: &UkfNoise,
    odometry: UkfOdometry,
    offset_std0: f64,
) -> (DVector<f64>, DMatrix<f64>) {
    let t0 = robot.camera_pose(q0);
    let dim = match odometry {
        UkfOdometry::World => 9,
        UkfOdometry::Slam(_) => 15,
    };
    let mut x = DVector::zeros(dim);
    x.rows_mut(0, 9)
        .copy_from(&AutoTeachUkfModel::state_of(&t0, &[0.0; 3]));
    let p = &robot.params;
    let base = &robot.base;
    let z = base.rotation * Vector3::z();
    let t = t0.translation.vector;
    let r = t0.rotation.to_rotation_matrix();
    let (t1, t12) = (q0[0], q0[0] + q0[1]);
    let elbow = Vector3::new(p.l1 * t1.cos(), p.l1 * t1.sin(), 0.0);
    let wrist = elbow + Vector3::new(p.l2 * t12.cos(), p.l2 * t12.sin(), 0.0);
    // Pose derivatives w.r.t. (θ1, θ2, θ4, h) of the true joints.
    let mut jq = DMatrix::zeros(6, 4);
    for (j, pj) in [Vector3::zeros(), elbow, wrist].iter().enumerate() {
        let pw = base * nalgebra::Point3::from(*pj);
        jq.view_mut((0, j), (3, 1))
            .copy_from(&z.cross(&(t - pw.coords)));
        jq.view_mut((3, j), (3, 1)).copy_from(&(r.transpose() * z));
    }
    jq.view_mut((0, 3), (3, 1)).copy_from(&z);
    // An unobservable offset is pinned at its prior mean: a rigid turn of the whole trajectory
    // that the data cannot see, so pinning it leaves the other estimates unchanged, while a 2°
    // spread of sigma points along that curved direction would read the curvature as data.
    let var = DMatrix::from_diagonal(&DVector::from_iterator(
        3,
        observable(odometry)
            .iter()
            .map(|&o| if o { offset_std0 * offset_std0 } else { 1e-18 }),
    ));
    let mut pm = DMatrix::zeros(dim, dim);
    // Offsets: pose = FK(q_enc − δ) ⇒ ∂pose/∂δ = −jq[:, ..3].
    let jd = -jq.columns(0, 3);
    let jv = &jd * &var;
    pm.view_mut((0, 0), (6, 6))
        .copy_from(&(&jv * jd.transpose()));
    pm.view_mut((0, 6), (6, 3)).copy_from(&jv);
    pm.view_mut((6, 0), (3, 6)).copy_from(&jv.transpose());
    for i in 0..3 {
        pm[(6 + i, 6 + i)] = var[(i, i)];
        pm[(i, i)] += noise.v_t[i] * noise.v_t[i];
        pm[(3 + i, 3 + i)] += noise.v_e[i] * noise.v_e[i];
    }
    let venc = DMatrix::from_diagonal(&DVector::from_iterator(
        4,
        noise.v_theta.iter().map(|v| v * v),
    ));
    let enc = &jq * venc * jq.transpose();
    let mut pose_block = pm.view_mut((0, 0), (6, 6));
    pose_block += enc;
    if let UkfOdometry::Slam(n) = odometry {
        for i in 0..3 {
            pm[(9 + i, 9 + i)] = (n.map_t * n.map_t).max(1e-24);
            pm[(12 + i, 12 + i)] = n.loc_t * n.loc_t;
        }
    }
    (x, pm)
}

/// Which offsets (θ1, θ2, θ4) the odometry can observe: all with world-frame increments; with
/// relative poses ([`UkfOdometry::Slam`]) not θ1, whose axis passes through the base origin
/// along the base z axis, so that it turns the whole trajectory rigidly.
pub fn observable(odometry: UkfOdometry) -> [bool; 3] {
    match odometry {
        UkfOdometry::World => [true; 3],
        UkfOdometry::Slam(_) => [false, true, true],
    }
}

/// Runs the UKF of eqs. (5.1)–(5.2) over a session: frame 0 initialises the camera pose from
/// the encoders with zero offsets (the uncalibrated robot) and the covariance those offsets
/// imply ([`initial_prior`]), each later frame predicts with the odometry increment from the
/// previous frame and updates with its encoder reading.
///
/// `encoders`: `F` readings; `increments`: `F − 1` increments `[u_T; u_R]` (their frame and
/// error model: `odometry`); `offset_std0`: prior standard deviation of each offset (rad).
/// With [`UkfOdometry::Slam`] the offset θ1 is not observable (its axis passes through the
/// base origin along the base z axis, so it turns the whole trajectory rigidly, which relative
/// poses cannot see): its estimate stays at the prior. Errors: length mismatches, non-finite
/// inputs, bad noise values, unreachable poses and filter failures, each naming the frame.
pub fn run_autoteach_ukf_with(
    robot: WaferRobot,
    encoders: &[Joints],
    increments: &[[f64; 6]],
    noise: &UkfNoise,
    odometry: UkfOdometry,
    offset_std0: f64,
) -> Result<UkfRun> {
    use crate::ukf::{MerweScaledSigmaPoints, NoiseForm, SigmaPointFilter, UnscentedKalmanFilter};
    noise.validate()?;
    if let UkfOdometry::Slam(n) = &odometry {
        n.validate()?;
    }
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
    let mut model = AutoTeachUkfModel::new(robot, &encoders[0])?;
    model.odometry = odometry;
    let (dim, dim_z) = (model.dim_x(), model.dim_z());
    let (x0, p0) = initial_prior(&robot, &encoders[0], noise, odometry, offset_std0);
    let mut ukf =
        UnscentedKalmanFilter::new(model, MerweScaledSigmaPoints::new(dim, 0.5, 2.0, 0.0)?)?
            .with_noise(NoiseForm::Augmented)?;
    ukf.set_x(x0)?;
    ukf.set_p(p0)?;
    ukf.set_q(match odometry {
        UkfOdometry::World => noise.q(),
        UkfOdometry::Slam(n) => n.q(),
    })?;
    ukf.set_r(noise.r())?;
    let mut run = UkfRun {
        poses: Vec::new(),
        offsets: Vec::new(),
        offset_std: Vec::new(),
        covariance: DMatrix::zeros(9, 9),
        observable: observable(odometry),
    };
    let record = |ukf: &UnscentedKalmanFilter<AutoTeachUkfModel>, run: &mut UkfRun| {
        let x = ukf.x();
        let p = ukf.p();
        run.poses.push(AutoTeachUkfModel::state_pose(x.column(0)));
        run.offsets.push([x[6], x[7], x[8]]);
        let sd = |k: usize| {
            if run.observable[k] {
                p[(6 + k, 6 + k)].max(0.0).sqrt()
            } else {
                offset_std0
            }
        };
        let row = [sd(0), sd(1), sd(2)];
        run.offset_std.push(row);
    };
    let z_of = |q: &Joints| {
        let mut z = DVector::zeros(dim_z);
        for (k, &j) in UKF_MEASURED_JOINTS.iter().enumerate() {
            z[k] = q[j];
        }
        z
    };
    // Frame 0's reading is already in the prior.
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
    run.covariance = ukf.p().view((0, 0), (9, 9)).into_owned();
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

    fn robot() -> WaferRobot {
        WaferRobot::new(
            RobotParams::default(),
            Isometry3::translation(-1.0, 0.03, -0.45)
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.026),
        )
        .unwrap()
    }

    #[test]
    fn initial_prior_cross_covariance_is_the_kinematic_jacobian() {
        // P0[pose, δ] = J·σ² with J = ∂(pose state)/∂δ: compare with central differences of
        // the forward kinematics FK(q − δ) in the state's tangent (t, right rotation vector).
        let robot = robot();
        let q = Joints::new(0.2, 1.4, 0.3, -1.5, 0.1);
        let noise = UkfNoise::default();
        let s0 = 0.01;
        let (x0, p0) = initial_prior(&robot, &q, &noise, UkfOdometry::World, s0);
        let m = AutoTeachUkfModel::new(robot, &q).unwrap();
        let h = 1e-6;
        for (k, &j) in UKF_OFFSET_JOINTS.iter().enumerate() {
            let mut qp = q;
            let mut qm = q;
            qp[j] -= h;
            qm[j] += h;
            let xp = AutoTeachUkfModel::state_of(&robot.camera_pose(&qp), &[0.0; 3]);
            let xm = AutoTeachUkfModel::state_of(&robot.camera_pose(&qm), &[0.0; 3]);
            let mut dp = DVector::zeros(9);
            let mut dm = DVector::zeros(9);
            m.x_residual(xp.column(0), x0.column(0), &mut dp).unwrap();
            m.x_residual(xm.column(0), x0.column(0), &mut dm).unwrap();
            for i in 0..6 {
                let fd = (dp[i] - dm[i]) / (2.0 * h);
                let an = p0[(i, 6 + k)] / (s0 * s0);
                assert!((fd - an).abs() < 1e-7, "joint {j} row {i}: fd {fd} vs {an}");
            }
        }
    }

    #[test]
    fn slam_process_reproduces_the_motion_and_subtracts_the_error_states() {
        // With the SLAM's position error e(k) = m(k) + l(k) in the state, the relative pose
        // S(k)⁻¹S(k+1) of the SLAM poses S = (t + e, R) maps the true t(k) to the true t(k+1).
        let robot = robot();
        let q0 = Joints::new(0.2, 1.4, 0.3, -1.5, 0.1);
        let q1 = Joints::new(0.22, 1.37, 0.3, -1.46, 0.12);
        let (c0, c1) = (robot.camera_pose(&q0), robot.camera_pose(&q1));
        let n = SlamNoise {
            loc_t: 1e-4,
            loc_r: 1e-4,
            map_t: 2e-5,
            map_step: 0.98,
        };
        let mut m = AutoTeachUkfModel::new(robot, &q0).unwrap();
        m.odometry = UkfOdometry::Slam(n);
        let (m0, l0) = (
            Vector3::new(1e-5, -2e-5, 3e-5),
            Vector3::new(-5e-5, 4e-5, 1e-4),
        );
        let (w_m, w_l) = (
            Vector3::new(3e-6, 1e-6, -2e-6),
            Vector3::new(2e-5, -7e-5, 1e-5),
        );
        let m1 = m0 * n.map_step + w_m;
        let s0 = c0.translation.vector + m0 + l0;
        let s1 = c1.translation.vector + m1 + w_l;
        let r0 = c0.rotation.to_rotation_matrix();
        let u_t = r0.transpose() * (s1 - s0);
        let u_r = so3_log(&(r0.transpose() * c1.rotation.to_rotation_matrix()));
        let u = DVector::from_vec(vec![u_t.x, u_t.y, u_t.z, u_r.x, u_r.y, u_r.z]);
        let mut x = DVector::zeros(15);
        x.rows_mut(0, 9)
            .copy_from(&AutoTeachUkfModel::state_of(&c0, &[0.0; 3]));
        x.rows_mut(9, 3).copy_from(&m0);
        x.rows_mut(12, 3).copy_from(&l0);
        let w = DVector::from_vec(vec![
            w_m.x, w_m.y, w_m.z, w_l.x, w_l.y, w_l.z, 0.0, 0.0, 0.0,
        ]);
        let mut out = DVector::zeros(15);
        m.fx_noise(x.column(0), w.column(0), 1.0, Some(&u), &mut out)
            .unwrap();
        let pose = AutoTeachUkfModel::state_pose(out.column(0));
        assert!((pose.translation.vector - c1.translation.vector).norm() < 1e-12);
        assert!(pose.rotation.angle_to(&c1.rotation) < 1e-12);
        assert!((out.rows(9, 3) - m1).norm() < 1e-15);
        assert!((out.rows(12, 3) - w_l).norm() < 1e-15);
    }

    #[test]
    fn bad_slam_noise_is_rejected() {
        let robot = robot();
        let enc = vec![Joints::new(0.2, 1.4, 0.3, -1.5, 0.1); 2];
        let inc = vec![[0.0; 6]];
        for bad in [
            SlamNoise {
                loc_t: 0.0,
                loc_r: 1e-4,
                map_t: 0.0,
                map_step: 0.5,
            },
            SlamNoise {
                loc_t: 1e-4,
                loc_r: 1e-4,
                map_t: 0.0,
                map_step: 1.0,
            },
            SlamNoise {
                loc_t: 1e-4,
                loc_r: f64::NAN,
                map_t: 0.0,
                map_step: 0.5,
            },
        ] {
            let r = run_autoteach_ukf_with(
                robot,
                &enc,
                &inc,
                &UkfNoise::default(),
                UkfOdometry::Slam(bad),
                0.01,
            );
            assert!(
                matches!(r, Err(EstimateError::InvalidParameter { .. })),
                "{bad:?}"
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
