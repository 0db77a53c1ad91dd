//! Kinematics of the dual-blade wafer-handling robot with its blade-mounted camera
//! (000_3b1454b2b2194811.txt ch. 2.2, eqs. (2.1)–(2.7)).
//!
//! The robot is a SCARA-like arm: a vertical column lifted by `h` (joint JT3), a shoulder
//! `θ1` (JT2), an elbow `θ2` (JT4) and two independent wrists `θ3` (JT6, blade 1) and `θ4`
//! (JT7, blade 2) that share the forearm. All revolute axes are vertical, so the arm moves
//! in the XY plane of the base frame and the blades are lifted together by `h`. A camera
//! sits on blade 2, just behind its tip, looking forward along the blade and tilted down.
//!
//! Frames (all poses are `T_ab`, mapping coordinates in frame `b` into frame `a`):
//! * `w` world, `b` robot base (`T_wb` = [`WaferRobot::base`]),
//! * `e1`, `e2` the blade (end-effector) frames at the blade tips: x along the blade,
//!   z up when the blade is level ([`WaferRobot::blade_pose`]),
//! * `c` the camera frame in the OpenCV convention: z forward (optical axis), x right,
//!   y down ([`WaferRobot::camera_mount`]).
//!
//! ```
//! use autoteach_geometry::robot::{Blade, Joints, WaferRobot};
//! let robot = WaferRobot::default();
//! let q = Joints::new(0.3, 1.1, -0.4, 0.6, 0.05);
//! let t_be = robot.blade_pose(&q, Blade::One);
//! let solutions = robot.inverse_kinematics(&t_be, Blade::One, q[3]).unwrap();
//! assert_eq!(solutions.len(), 2); // elbow up and elbow down
//! assert!(solutions.iter().any(|s| (s - q).norm() < 1e-9));
//! ```

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{
    Isometry3, Matrix3, Matrix4x5, Matrix6x5, Rotation3, Translation3, UnitQuaternion, Vector3,
    Vector4, Vector5,
};
use rayon::prelude::*;

use crate::error::check_finite;
use crate::{GeometryError, Result};

/// Joint vector `(θ1, θ2, θ3, θ4, h)` of 000_3b1454b2b2194811.txt ch. 2.2: shoulder (JT2),
/// elbow (JT4), blade-1 wrist (JT6), blade-2 wrist (JT7) in radians and column lift (JT3) in
/// metres. The blade yaws are `θ123 = θ1+θ2+θ3` (blade 1) and `θ124 = θ1+θ2+θ4` (blade 2).
pub type Joints = Vector5<f64>;

/// Number of scalar parameters in [`RobotParams`] (length of [`RobotParams::to_array`]).
pub const N_PARAMS: usize = 11;

/// Batches larger than this are evaluated in parallel by [`WaferRobot::camera_poses`].
const PARALLEL_BATCH: usize = 256;

/// Tolerance (radians) on the roll/pitch mismatch of a requested blade orientation.
const ORIENTATION_TOL: f64 = 1e-6;

/// Two inverse-kinematics solutions closer than this (radians, per joint) are one solution.
const DUPLICATE_TOL: f64 = 1e-9;

/// Geometric parameters of the robot, 000_3b1454b2b2194811.txt ch. 2.2, Fig. 2.5 and eqs.
/// (2.4), (2.7). Lengths in metres, angles in radians.
///
/// The documented field order (used by [`RobotParams::to_array`] / [`RobotParams::from_slice`]
/// and the Python bindings) is the declaration order: `l1, l2, l3, l4, h01, h02, alpha1,
/// alpha2, beta_c, cam_d, cam_h` (see [`RobotParams::NAMES`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotParams {
    /// Upper-arm length: shoulder (JT2) to elbow (JT4) axis.
    pub l1: f64,
    /// Forearm length: elbow (JT4) to wrist (JT6/JT7) axis.
    pub l2: f64,
    /// Blade-1 length: wrist axis to the blade-1 tip (origin of the blade-1 frame).
    pub l3: f64,
    /// Blade-2 length: wrist axis to the blade-2 tip (origin of the blade-2 frame).
    pub l4: f64,
    /// Height of the blade-1 frame over the lifted column `h` (`h01` of eq. (2.4)).
    pub h01: f64,
    /// Height of the blade-2 frame over the lifted column `h`.
    pub h02: f64,
    /// Pitch of blade 1 (`α` of eq. (2.4)): rotation about the blade's y axis, 0 = level.
    pub alpha1: f64,
    /// Pitch of blade 2 (`β` of ch. 2.2): rotation about the blade's y axis, 0 = level.
    pub alpha2: f64,
    /// Downward tilt `β_c` of the camera's optical axis from the blade-2 x axis (eq. (2.7)).
    pub beta_c: f64,
    /// Distance `d` of the camera centre behind the blade-2 tip, along the blade (eq. (2.7)).
    pub cam_d: f64,
    /// Height `h` of the camera centre above the blade-2 frame (eq. (2.7)).
    pub cam_h: f64,
}

impl Default for RobotParams {
    /// Nominal dimensions of a 300 mm wafer-handling robot with a blade camera.
    fn default() -> Self {
        Self {
            l1: 0.36,
            l2: 0.36,
            l3: 0.32,
            l4: 0.32,
            h01: 0.25,
            h02: 0.29,
            alpha1: 0.0,
            alpha2: 0.0,
            beta_c: 8f64.to_radians(),
            cam_d: 0.06,
            cam_h: 0.035,
        }
    }
}

impl RobotParams {
    /// Parameter names in the documented order of [`RobotParams::to_array`].
    pub const NAMES: [&'static str; N_PARAMS] = [
        "l1", "l2", "l3", "l4", "h01", "h02", "alpha1", "alpha2", "beta_c", "cam_d", "cam_h",
    ];

    /// Checks that every value is finite, the link and blade lengths `l1..l4` are positive and
    /// the camera tilt satisfies `|β_c| < 90°`.
    pub fn validate(&self) -> Result<()> {
        for (name, value) in Self::NAMES.iter().zip(self.to_array()) {
            if !value.is_finite() {
                return Err(GeometryError::NonFinite { what: name, value });
            }
        }
        for (name, value) in [
            ("l1", self.l1),
            ("l2", self.l2),
            ("l3", self.l3),
            ("l4", self.l4),
        ] {
            if value <= 0.0 {
                return Err(GeometryError::InvalidParameter {
                    what: name,
                    value,
                    reason: "link and blade lengths must be positive",
                });
            }
        }
        if self.beta_c.abs() >= FRAC_PI_2 {
            return Err(GeometryError::InvalidParameter {
                what: "beta_c",
                value: self.beta_c,
                reason: "camera tilt must satisfy |beta_c| < pi/2",
            });
        }
        Ok(())
    }

    /// The parameters as an array in the documented order [`RobotParams::NAMES`].
    pub fn to_array(&self) -> [f64; N_PARAMS] {
        [
            self.l1,
            self.l2,
            self.l3,
            self.l4,
            self.h01,
            self.h02,
            self.alpha1,
            self.alpha2,
            self.beta_c,
            self.cam_d,
            self.cam_h,
        ]
    }

    /// Builds and validates parameters from a slice in the order [`RobotParams::NAMES`].
    pub fn from_slice(values: &[f64]) -> Result<Self> {
        let &[l1, l2, l3, l4, h01, h02, alpha1, alpha2, beta_c, cam_d, cam_h] = values else {
            return Err(GeometryError::WrongLength {
                what: "robot parameters",
                got: values.len(),
                expected: N_PARAMS,
            });
        };
        let params = Self {
            l1,
            l2,
            l3,
            l4,
            h01,
            h02,
            alpha1,
            alpha2,
            beta_c,
            cam_d,
            cam_h,
        };
        params.validate()?;
        Ok(params)
    }
}

/// Which of the two blades (end effectors) of the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Blade {
    /// Blade 1, driven by `θ3` (JT6).
    One,
    /// Blade 2, driven by `θ4` (JT7); it carries the camera.
    Two,
}

/// Converts encoder readings to true joint values.
///
/// Encoder convention used throughout autoteach (UKF, SLAM-MOT): each encoder reads the true
/// joint value plus its zero offset, `q_enc = q_true + δ`, so `q_true = q_enc − δ`. The offsets
/// `δ` are ordered like [`Joints`] (the last one is the lift offset in metres).
pub fn joints_from_encoders(q_enc: &Joints, offsets: &Joints) -> Joints {
    q_enc - offsets
}

/// Inverse of [`joints_from_encoders`]: the encoder readings `q_true + δ` of true joints.
pub fn encoders_from_joints(q_true: &Joints, offsets: &Joints) -> Joints {
    q_true + offsets
}

/// Wraps an angle to `(−π, π]`.
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// The wafer-handling robot: geometric parameters and the base pose in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaferRobot {
    /// Geometric parameters.
    pub params: RobotParams,
    /// Pose of the robot base in the world, `T_wb` of eq. (2.2).
    pub base: Isometry3<f64>,
}

impl Default for WaferRobot {
    /// Default parameters with the base at the world origin.
    fn default() -> Self {
        Self {
            params: RobotParams::default(),
            base: Isometry3::identity(),
        }
    }
}

/// The per-blade quantities that differ between blade 1 and blade 2.
struct BladeGeom {
    /// Blade length (`l3` or `l4`).
    len: f64,
    /// Height of the blade frame over the column (`h01` or `h02`).
    height: f64,
    /// Blade pitch (`alpha1` or `alpha2`).
    pitch: f64,
    /// Index of the wrist joint driving this blade (2 for θ3, 3 for θ4).
    wrist: usize,
}

impl WaferRobot {
    /// Creates a robot after validating the parameters and the base pose.
    pub fn new(params: RobotParams, base: Isometry3<f64>) -> Result<Self> {
        params.validate()?;
        check_finite("base translation", base.translation.vector.as_slice())?;
        check_finite("base rotation", base.rotation.coords.as_slice())?;
        Ok(Self { params, base })
    }

    fn geom(&self, blade: Blade) -> BladeGeom {
        let p = &self.params;
        match blade {
            Blade::One => BladeGeom {
                len: p.l3,
                height: p.h01,
                pitch: p.alpha1,
                wrist: 2,
            },
            Blade::Two => BladeGeom {
                len: p.l4,
                height: p.h02,
                pitch: p.alpha2,
                wrist: 3,
            },
        }
    }

    /// Planar link angles `(θ1, θ12, ψ)` where `ψ` is the yaw of `blade`.
    fn link_angles(q: &Joints, g: &BladeGeom) -> (f64, f64, f64) {
        let t1 = q[0];
        let t12 = t1 + q[1];
        (t1, t12, t12 + q[g.wrist])
    }

    /// Forward kinematics `T_be` of one blade (base → blade frame), 000_3b1454b2b2194811.txt
    /// eq. (2.4) with the blade yaw restored.
    ///
    /// Translation `(l1 cos θ1 + l2 cos θ12 + l3 cos θ123, l1 sin θ1 + l2 sin θ12 + l3 sin θ123,
    /// h + h01)` and rotation `Rz(θ123)·Ry(α)` for blade 1; blade 2 uses `l4`, `θ124 = θ1+θ2+θ4`,
    /// `h02` and `alpha2`.
    ///
    /// Correction of the printed equation: (2.4) prints the rotation block as `Ry(α)` alone,
    /// i.e. a blade that always points along the base x axis whatever the joint angles. The
    /// translation printed next to it, the Jacobian (2.5) (whose last row is the yaw rate
    /// `θ̇123`), the camera mount (2.7) ("points the same direction as the blade") and any
    /// inverse kinematics need the blade to turn with its arm, so the rotation is derived from
    /// the described geometry: all joints JT2/JT4/JT6/JT7 turn about vertical axes, giving the
    /// yaw `Rz(θ123)`, followed by the fixed blade pitch `Ry(α)` about the blade's own y axis.
    /// The blade-tip offset is horizontal (`l3` in the XY plane) exactly as printed.
    pub fn blade_pose(&self, q: &Joints, blade: Blade) -> Isometry3<f64> {
        let g = self.geom(blade);
        let (t1, t12, psi) = Self::link_angles(q, &g);
        let p = &self.params;
        let translation = Translation3::new(
            p.l1 * t1.cos() + p.l2 * t12.cos() + g.len * psi.cos(),
            p.l1 * t1.sin() + p.l2 * t12.sin() + g.len * psi.sin(),
            q[4] + g.height,
        );
        Isometry3::from_parts(translation, yaw_pitch(psi, g.pitch))
    }

    /// The camera mount `T_e2c` (blade-2 frame → camera frame), derived from the geometry of
    /// 000_3b1454b2b2194811.txt ch. 2.2 around eq. (2.7).
    ///
    /// The camera centre is at `(−cam_d, 0, cam_h)` in the blade-2 frame (a distance `d` behind
    /// the tip and `h` above the blade). It looks forward along the blade and is tilted DOWN by
    /// `β_c`; the image x axis points to the blade's right and the image y axis down. In
    /// blade-2 coordinates the camera axes are `z_c = (cos β_c, 0, −sin β_c)`,
    /// `x_c = (0, −1, 0)` and `y_c = z_c × x_c = (−sin β_c, 0, −cos β_c)`.
    ///
    /// Relation to the printed (2.7): the printed matrix has the rows `(0, −1, 0)`,
    /// `(sin β_c, 0, −cos β_c)`, `(cos β_c, 0, sin β_c)` and translation
    /// `(0, d sin β_c + h cos β_c, d cos β_c − h sin β_c)`. Its rows are camera axes and its
    /// translation is the blade origin in camera coordinates, so it maps blade coordinates into
    /// the camera, i.e. it is `T_ce`, the inverse of `T_ec` in the convention of (2.2)/(2.3)
    /// (the chain `T_wc = T_wb·T_be·T_ec` needs the camera-to-blade map). It also makes the
    /// optical axis `(cos β_c, 0, sin β_c)` rise for positive `β_c`, while the text says the
    /// camera tilts downward. This function returns exactly `(printed (2.7) at −β_c)⁻¹`: the same
    /// camera centre `(−d, 0, h)` and axes, with the tilt pointing down. The unit test
    /// `camera_mount_matches_printed_eq_2_7_up_to_inverse_and_tilt_sign` checks this relation.
    pub fn camera_mount(&self) -> Isometry3<f64> {
        let p = &self.params;
        let (s, c) = p.beta_c.sin_cos();
        let x_c = Vector3::new(0.0, -1.0, 0.0);
        let z_c = Vector3::new(c, 0.0, -s);
        let y_c = z_c.cross(&x_c);
        let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x_c, y_c, z_c]));
        Isometry3::from_parts(
            Translation3::new(-p.cam_d, 0.0, p.cam_h),
            UnitQuaternion::from_rotation_matrix(&r),
        )
    }

    /// Camera pose in the robot base, `T_bc = T_be2 · T_e2c` (eq. (2.2) without `T_wb`).
    pub fn camera_pose_in_base(&self, q: &Joints) -> Isometry3<f64> {
        self.blade_pose(q, Blade::Two) * self.camera_mount()
    }

    /// Camera pose in the world, `T_wc = T_wb · T_be2 · T_e2c`, 000_3b1454b2b2194811.txt
    /// eq. (2.2) (and eq. (5.9)).
    pub fn camera_pose(&self, q: &Joints) -> Isometry3<f64> {
        self.base * self.camera_pose_in_base(q)
    }

    /// Batched camera forward kinematics: `T_wc` of eq. (2.2) for every joint vector.
    ///
    /// The constant part `Ry(α2)·T_e2c` is computed once; batches of more than 256 joint vectors
    /// are evaluated in parallel with rayon. Non-finite joints give non-finite poses (validate
    /// the input first where it comes from users).
    pub fn camera_poses(&self, qs: &[Joints]) -> Vec<Isometry3<f64>> {
        let p = &self.params;
        let mount = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), p.alpha2),
        ) * self.camera_mount();
        let one = |q: &Joints| {
            let t1 = q[0];
            let t12 = t1 + q[1];
            let psi = t12 + q[3];
            let (s1, c1) = t1.sin_cos();
            let (s12, c12) = t12.sin_cos();
            let (sp, cp) = psi.sin_cos();
            let (sh, ch) = (0.5 * psi).sin_cos();
            let t_be2_yaw = Isometry3::from_parts(
                Translation3::new(
                    p.l1 * c1 + p.l2 * c12 + p.l4 * cp,
                    p.l1 * s1 + p.l2 * s12 + p.l4 * sp,
                    q[4] + p.h02,
                ),
                UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(ch, 0.0, 0.0, sh)),
            );
            self.base * t_be2_yaw * mount
        };
        if qs.len() > PARALLEL_BATCH {
            qs.par_iter().map(one).collect()
        } else {
            qs.iter().map(one).collect()
        }
    }

    /// Blade Jacobian, 000_3b1454b2b2194811.txt eq. (2.5): `d(v_x, v_y, v_z, ω_z) /
    /// d(θ̇1, θ̇2, θ̇3, θ̇4, ḣ)` of the blade-frame origin and yaw rate, in the base frame.
    ///
    /// (2.5) first writes the velocity in the link-angle rates `(θ̇1, θ̇12, θ̇123, ḣ)` and then
    /// chains the triangular matrix mapping the joint rates to them; the product is returned
    /// here, extended to five joints (the column of the other blade's wrist is zero). The
    /// printed first factor has `θ1` where `θ̇1` is meant.
    pub fn jacobian(&self, q: &Joints, blade: Blade) -> Matrix4x5<f64> {
        let g = self.geom(blade);
        let (t1, t12, psi) = Self::link_angles(q, &g);
        let p = &self.params;
        // Columns of the link-angle-rate Jacobian (v_x, v_y) for θ̇1, θ̇12, ψ̇.
        let (a1, b1) = (-p.l1 * t1.sin(), p.l1 * t1.cos());
        let (a2, b2) = (-p.l2 * t12.sin(), p.l2 * t12.cos());
        let (a3, b3) = (-g.len * psi.sin(), g.len * psi.cos());
        let mut j = Matrix4x5::zeros();
        j[(0, 0)] = a1 + a2 + a3;
        j[(1, 0)] = b1 + b2 + b3;
        j[(0, 1)] = a2 + a3;
        j[(1, 1)] = b2 + b3;
        j[(0, g.wrist)] = a3;
        j[(1, g.wrist)] = b3;
        j[(2, 4)] = 1.0;
        j[(3, 0)] = 1.0;
        j[(3, 1)] = 1.0;
        j[(3, g.wrist)] = 1.0;
        j
    }

    /// Blade acceleration `(a_x, a_y, a_z, ω̇_z)` in the base frame, 000_3b1454b2b2194811.txt
    /// eq. (2.6): `J(q)·q̈ + J̇(q, q̇)·q̇`.
    ///
    /// The velocity-product term is the centripetal acceleration of each link,
    /// `−l_k (cos φ_k, sin φ_k) φ̇_k²` with `φ = (θ1, θ12, θ123)` (or `θ124` for blade 2). The
    /// printed (2.6) multiplies that matrix by the accelerations again (and has `θ1` for `θ̈1` in
    /// the first product); it is derived here by differentiating (2.5) in time.
    pub fn acceleration(
        &self,
        q: &Joints,
        qd: &Joints,
        qdd: &Joints,
        blade: Blade,
    ) -> Vector4<f64> {
        let g = self.geom(blade);
        let (t1, t12, psi) = Self::link_angles(q, &g);
        let p = &self.params;
        let w1 = qd[0];
        let w12 = w1 + qd[1];
        let w_psi = w12 + qd[g.wrist];
        let centripetal_x = -(p.l1 * t1.cos() * w1 * w1
            + p.l2 * t12.cos() * w12 * w12
            + g.len * psi.cos() * w_psi * w_psi);
        let centripetal_y = -(p.l1 * t1.sin() * w1 * w1
            + p.l2 * t12.sin() * w12 * w12
            + g.len * psi.sin() * w_psi * w_psi);
        self.jacobian(q, blade) * qdd + Vector4::new(centripetal_x, centripetal_y, 0.0, 0.0)
    }

    /// Jacobian of the world camera pose `T_wc(q)` of eq. (2.2) with respect to the joints, as
    /// right-perturbation (body-frame) twists `[ω; ρ]`: column `j` is the vee of
    /// `T_wc(q)⁻¹ · ∂T_wc/∂q_j`, so `T_wc(q + ε e_j) ≈ T_wc(q) ⊕ ε J_j`. Used by the
    /// Fisher-information view planner (000_3b1454b2b2194811.txt eqs. (6.11)–(6.14)).
    ///
    /// Derivation: the body twist of `T_be2 = (p(q), Rz(ψ)·Ry(α2))` is
    /// `ω = Ry(α2)ᵀ e_z ∂ψ/∂q_j`, `ρ = Rᵀ ∂p/∂q_j`; `T_wb` is constant and the constant mount
    /// `X = T_e2c` maps it by `Ad(X⁻¹)`: `ω_c = R_Xᵀ ω`, `ρ_c = R_Xᵀ (ρ + ω × t_X)`.
    pub fn camera_jacobian(&self, q: &Joints) -> Matrix6x5<f64> {
        let j_pos = self.jacobian(q, Blade::Two);
        let t_be2 = self.blade_pose(q, Blade::Two);
        let r_be2 = t_be2.rotation.to_rotation_matrix();
        let mount = self.camera_mount();
        let r_x = mount.rotation.to_rotation_matrix();
        let t_x = mount.translation.vector;
        // Yaw axis seen from the blade frame: Ry(α2)ᵀ e_z.
        let (sa, ca) = self.params.alpha2.sin_cos();
        let yaw_axis = Vector3::new(-sa, 0.0, ca);
        let mut out = Matrix6x5::zeros();
        for col in 0..5 {
            let omega = yaw_axis * j_pos[(3, col)];
            let dp = Vector3::new(j_pos[(0, col)], j_pos[(1, col)], j_pos[(2, col)]);
            let rho = r_be2.transpose() * dp;
            let omega_c = r_x.transpose() * omega;
            let rho_c = r_x.transpose() * (rho + omega.cross(&t_x));
            out.fixed_view_mut::<3, 1>(0, col).copy_from(&omega_c);
            out.fixed_view_mut::<3, 1>(3, col).copy_from(&rho_c);
        }
        out
    }

    /// Closed-form inverse kinematics of one blade: every joint vector whose
    /// [`WaferRobot::blade_pose`] equals `t_be` (inverse of eq. (2.4) with the yaw restored).
    ///
    /// The orientation must be `Rz(ψ)·Ry(α)` with the blade's fixed pitch `α`; removing `Ry(α)`
    /// and decomposing the rest as `Rz·Ry·Rx` gives the yaw `ψ` and a roll/pitch mismatch that
    /// must stay below 1e-6 rad. The lift is `h = z − h0`. The wrist point
    /// `w = p − l_blade (cos ψ, sin ψ)` must lie in the annulus `|l1 − l2| ≤ |w| ≤ l1 + l2`
    /// (1e-12 relative tolerance); then `cos θ2 = (|w|² − l1² − l2²) / (2 l1 l2)` gives the
    /// elbow-up/elbow-down pair `±θ2`, `θ1 = atan2(w_y, w_x) − atan2(l2 sin θ2, l1 + l2 cos θ2)`
    /// and the blade's wrist angle `ψ − θ1 − θ2`. The other blade's wrist joint is set to
    /// `other_blade_angle`. Angles are wrapped to `(−π, π]`; the two solutions coincide on the
    /// workspace boundary and are then returned once. If `l1 = l2` and the wrist lies on the
    /// shoulder axis, `θ1` is free; the single representative with `θ1 = 0` is returned.
    ///
    /// Errors: [`GeometryError::NonFinite`] for non-finite inputs, [`GeometryError::Unreachable`]
    /// when the orientation is not of the reachable form or the wrist point is out of reach.
    pub fn inverse_kinematics(
        &self,
        t_be: &Isometry3<f64>,
        blade: Blade,
        other_blade_angle: f64,
    ) -> Result<Vec<Joints>> {
        check_finite("blade pose translation", t_be.translation.vector.as_slice())?;
        check_finite("blade pose rotation", t_be.rotation.coords.as_slice())?;
        check_finite("other blade angle", &[other_blade_angle])?;
        let g = self.geom(blade);
        let p = &self.params;

        // Orientation: R = Rz(ψ)·Ry(α)  ⇔  R·Ry(α)ᵀ = Rz(ψ).
        let r_yaw = t_be.rotation * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -g.pitch);
        let (roll, pitch, psi) = r_yaw.euler_angles();
        if roll.abs() > ORIENTATION_TOL || pitch.abs() > ORIENTATION_TOL {
            return Err(GeometryError::Unreachable {
                reason: format!(
                    "blade orientation is not a yaw of the blade pitch {:.6}°: roll mismatch \
                     {:.6}°, pitch mismatch {:.6}° (tolerance {:.2e} rad)",
                    g.pitch.to_degrees(),
                    roll.to_degrees(),
                    pitch.to_degrees(),
                    ORIENTATION_TOL
                ),
            });
        }

        let pos = t_be.translation.vector;
        let h = pos.z - g.height;
        let wx = pos.x - g.len * psi.cos();
        let wy = pos.y - g.len * psi.sin();
        let r = wx.hypot(wy);
        let r_max = p.l1 + p.l2;
        let r_min = (p.l1 - p.l2).abs();
        let tol = 1e-12 * r_max;
        if r > r_max + tol || r < r_min - tol {
            return Err(GeometryError::Unreachable {
                reason: format!(
                    "wrist point ({wx:.6}, {wy:.6}) is at distance {r:.9} m from the shoulder \
                     axis, outside the reachable annulus [{r_min:.9}, {r_max:.9}] m"
                ),
            });
        }

        let cos_t2 = ((r * r - p.l1 * p.l1 - p.l2 * p.l2) / (2.0 * p.l1 * p.l2)).clamp(-1.0, 1.0);
        let t2_abs = cos_t2.acos();
        let phi = wy.atan2(wx);
        let mut solutions: Vec<Joints> = Vec::with_capacity(2);
        for t2 in [t2_abs, -t2_abs] {
            let t1 = if r <= tol {
                0.0
            } else {
                phi - (p.l2 * t2.sin()).atan2(p.l1 + p.l2 * t2.cos())
            };
            let wrist = psi - t1 - t2;
            let mut q = Joints::new(t1, t2, other_blade_angle, other_blade_angle, h);
            q[g.wrist] = wrist;
            for k in 0..4 {
                q[k] = wrap_angle(q[k]);
            }
            let duplicate = solutions.iter().any(|s| {
                (0..4).all(|k| wrap_angle(s[k] - q[k]).abs() < DUPLICATE_TOL)
            });
            if !duplicate {
                solutions.push(q);
            }
        }
        Ok(solutions)
    }

    /// Inverse kinematics for a desired world camera pose: solves blade 2 for
    /// `T_be2 = T_wb⁻¹ · T_wc · T_e2c⁻¹` (eq. (2.2) rearranged) with the blade-1 wrist set to
    /// `theta3`. Same solutions and errors as [`WaferRobot::inverse_kinematics`].
    pub fn inverse_kinematics_camera(
        &self,
        t_wc: &Isometry3<f64>,
        theta3: f64,
    ) -> Result<Vec<Joints>> {
        check_finite("camera pose translation", t_wc.translation.vector.as_slice())?;
        check_finite("camera pose rotation", t_wc.rotation.coords.as_slice())?;
        let t_be2 = self.base.inverse() * t_wc * self.camera_mount().inverse();
        self.inverse_kinematics(&t_be2, Blade::Two, theta3)
    }
}

/// `Rz(yaw)·Ry(pitch)` as a unit quaternion.
fn yaw_pitch(yaw: f64, pitch: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch)
}
