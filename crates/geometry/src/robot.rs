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
    /// Checks that every value is finite, the link and blade lengths `l1..l4` are positive and
    /// the camera tilt and blade pitches satisfy `|β_c|, |α1|, |α2| < 90°` (a blade pitched by
    /// 90° or more is not a blade, and the inverse kinematics' yaw extraction needs it).
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
        for (name, value) in [
            ("beta_c", self.beta_c),
            ("alpha1", self.alpha1),
            ("alpha2", self.alpha2),
        ] {
            if value.abs() >= FRAC_PI_2 {
                return Err(GeometryError::InvalidParameter {
                    what: name,
                    value,
                    reason: "camera tilt and blade pitches must be below pi/2 in magnitude",
                });
            }
        }
        Ok(())
    }
}

/// Generates [`RobotParams::NAMES`], [`RobotParams::to_array`] and [`RobotParams::from_slice`]
/// from one ordered field list, so the three cannot disagree on the order.
macro_rules! param_array {
    ($($field:ident),+ $(,)?) => {
        impl RobotParams {
            /// Parameter names in the documented order of [`RobotParams::to_array`].
            pub const NAMES: [&'static str; N_PARAMS] = [$(stringify!($field)),+];

            /// The parameters as an array in the documented order [`RobotParams::NAMES`].
            pub fn to_array(&self) -> [f64; N_PARAMS] {
                [$(self.$field),+]
            }

            /// Builds and validates parameters from a slice in the order [`RobotParams::NAMES`].
            pub fn from_slice(values: &[f64]) -> Result<Self> {
                let &[$($field),+] = values else {
                    return Err(GeometryError::WrongLength {
                        what: "robot parameters",
                        got: values.len(),
                        expected: N_PARAMS,
                    });
                };
                let params = Self { $($field),+ };
                params.validate()?;
                Ok(params)
            }
        }
    };
}

param_array!(
    l1, l2, l3, l4, h01, h02, alpha1, alpha2, beta_c, cam_d, cam_h
);

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
    /// The orientation must be `Rz(ψ)·Ry(α)` with the blade's fixed pitch `α`: its Z-Y-X Euler
    /// decomposition `Rz(ψ)·Ry(pitch)·Rx(roll)` gives the yaw `ψ`, and the roll and `pitch − α`
    /// mismatches must stay below 1e-6 rad. The lift is `h = z − h0`. The wrist point
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

        // Orientation: R = Rz(yaw)·Ry(pitch)·Rx(roll) must have roll = 0 and pitch = α.
        let (roll, pitch, psi) = t_be.rotation.euler_angles();
        let pitch_mismatch = pitch - g.pitch;
        if roll.abs() > ORIENTATION_TOL || pitch_mismatch.abs() > ORIENTATION_TOL {
            return Err(GeometryError::Unreachable {
                reason: format!(
                    "blade orientation is not Rz(yaw)·Ry(alpha) with the blade pitch alpha = \
                     {:.6}°: roll mismatch {:.6}°, pitch mismatch {:.6}° (tolerance {:.1e} rad)",
                    g.pitch.to_degrees(),
                    roll.to_degrees(),
                    pitch_mismatch.to_degrees(),
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
            let duplicate = solutions
                .iter()
                .any(|s| (0..4).all(|k| wrap_angle(s[k] - q[k]).abs() < DUPLICATE_TOL));
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
        check_finite(
            "camera pose translation",
            t_wc.translation.vector.as_slice(),
        )?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// A non-symmetric parameter set (l1 ≠ l2, pitched blades) to exercise every term.
    fn skewed_params() -> RobotParams {
        RobotParams {
            l1: 0.41,
            l2: 0.33,
            l3: 0.29,
            l4: 0.35,
            h01: 0.21,
            h02: 0.27,
            alpha1: 0.03,
            alpha2: -0.05,
            beta_c: 0.2,
            cam_d: 0.07,
            cam_h: 0.04,
        }
    }

    fn skewed_robot() -> WaferRobot {
        let base = Isometry3::new(Vector3::new(1.2, -0.4, 0.3), Vector3::new(0.02, -0.01, 0.7));
        WaferRobot::new(skewed_params(), base).unwrap()
    }

    fn random_joints(rng: &mut Pcg64) -> Joints {
        Joints::new(
            rng.random_range(-PI..PI),
            rng.random_range(-PI..PI),
            rng.random_range(-PI..PI),
            rng.random_range(-PI..PI),
            rng.random_range(-0.2..0.4),
        )
    }

    /// (translation error, rotation angle error) between two poses.
    fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        let d = a.inverse() * b;
        (d.translation.vector.norm(), d.rotation.angle())
    }

    fn joints_close(a: &Joints, b: &Joints, tol: f64) -> bool {
        (0..4).all(|k| wrap_angle(a[k] - b[k]).abs() < tol) && (a[4] - b[4]).abs() < tol
    }

    #[test]
    fn default_params_are_valid_and_round_trip_through_arrays() {
        let p = RobotParams::default();
        p.validate().unwrap();
        assert_eq!(RobotParams::from_slice(&p.to_array()).unwrap(), p);
        let s = skewed_params();
        assert_eq!(RobotParams::from_slice(&s.to_array()).unwrap(), s);
        // The documented order: check a few positions by name.
        let a = s.to_array();
        assert_eq!(
            a[RobotParams::NAMES.iter().position(|n| *n == "l4").unwrap()],
            s.l4
        );
        assert_eq!(
            a[RobotParams::NAMES
                .iter()
                .position(|n| *n == "beta_c")
                .unwrap()],
            s.beta_c
        );
        assert_eq!(
            a[RobotParams::NAMES
                .iter()
                .position(|n| *n == "cam_h")
                .unwrap()],
            s.cam_h
        );
    }

    #[test]
    fn invalid_params_are_rejected() {
        let base = RobotParams::default();
        let cases: Vec<(RobotParams, &str)> = vec![
            (RobotParams { l1: 0.0, ..base }, "l1"),
            (RobotParams { l2: -0.1, ..base }, "l2"),
            (RobotParams { l3: 0.0, ..base }, "l3"),
            (RobotParams { l4: -1.0, ..base }, "l4"),
            (
                RobotParams {
                    beta_c: FRAC_PI_2,
                    ..base
                },
                "beta_c",
            ),
            (
                RobotParams {
                    beta_c: -1.6,
                    ..base
                },
                "beta_c",
            ),
            (
                RobotParams {
                    alpha2: 2.0,
                    ..base
                },
                "alpha2",
            ),
            (
                RobotParams {
                    h01: f64::NAN,
                    ..base
                },
                "h01",
            ),
            (
                RobotParams {
                    cam_d: f64::INFINITY,
                    ..base
                },
                "cam_d",
            ),
        ];
        for (p, name) in cases {
            match p.validate() {
                Err(GeometryError::InvalidParameter { what, .. })
                | Err(GeometryError::NonFinite { what, .. }) => assert_eq!(what, name),
                other => panic!("{name}: expected a parameter error, got {other:?}"),
            }
            assert!(WaferRobot::new(p, Isometry3::identity()).is_err());
        }
        assert!(matches!(
            RobotParams::from_slice(&[0.3; 10]),
            Err(GeometryError::WrongLength {
                got: 10,
                expected: 11,
                ..
            })
        ));
        let mut bad_base = Isometry3::identity();
        bad_base.translation.vector.x = f64::NAN;
        assert!(WaferRobot::new(base, bad_base).is_err());
    }

    #[test]
    fn blade_pose_matches_eq_2_4_with_yaw_restored() {
        // Independent construction with 4×4 homogeneous matrices: translation of (2.4) and the
        // rotation Rz(θ123)·Ry(α), where Ry is the printed block of (2.4).
        let robot = skewed_robot();
        let p = robot.params;
        let mut rng = Pcg64::seed_from_u64(1);
        for _ in 0..50 {
            let q = random_joints(&mut rng);
            for (blade, len, h0, a, wrist) in [
                (Blade::One, p.l3, p.h01, p.alpha1, q[2]),
                (Blade::Two, p.l4, p.h02, p.alpha2, q[3]),
            ] {
                let (t1, t12) = (q[0], q[0] + q[1]);
                let psi = t12 + wrist;
                let (sa, ca) = a.sin_cos();
                let ry = Matrix4::new(
                    ca, 0.0, sa, 0.0, 0.0, 1.0, 0.0, 0.0, -sa, 0.0, ca, 0.0, 0.0, 0.0, 0.0, 1.0,
                );
                let (sp, cp) = psi.sin_cos();
                let rz = Matrix4::new(
                    cp, -sp, 0.0, 0.0, sp, cp, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
                );
                let mut expected = rz * ry;
                expected[(0, 3)] = p.l1 * t1.cos() + p.l2 * t12.cos() + len * psi.cos();
                expected[(1, 3)] = p.l1 * t1.sin() + p.l2 * t12.sin() + len * psi.sin();
                expected[(2, 3)] = q[4] + h0;
                let got = robot.blade_pose(&q, blade).to_homogeneous();
                assert!(
                    (got - expected).abs().max() < 1e-12,
                    "{blade:?} {got} {expected}"
                );
            }
        }
    }

    #[test]
    fn camera_mount_matches_printed_eq_2_7_up_to_inverse_and_tilt_sign() {
        let p = skewed_params();
        let robot = WaferRobot::new(p, Isometry3::identity()).unwrap();
        // Printed (2.7) evaluated at −β_c.
        let b = -p.beta_c;
        let (s, c) = b.sin_cos();
        let (d, h) = (p.cam_d, p.cam_h);
        let printed = Matrix4::new(
            0.0,
            -1.0,
            0.0,
            0.0,
            s,
            0.0,
            -c,
            d * s + h * c,
            c,
            0.0,
            s,
            d * c - h * s,
            0.0,
            0.0,
            0.0,
            1.0,
        );
        let got = robot.camera_mount().inverse().to_homogeneous();
        assert!((got - printed).abs().max() < 1e-12, "{got} vs {printed}");
    }

    #[test]
    fn camera_looks_along_blade_and_down_by_beta_c() {
        let robot = skewed_robot();
        let p = robot.params;
        let mut rng = Pcg64::seed_from_u64(2);
        for _ in 0..50 {
            let q = random_joints(&mut rng);
            let t_wb2 = robot.base * robot.blade_pose(&q, Blade::Two);
            let t_wc = robot.camera_pose(&q);
            let blade_x = t_wb2.rotation * Vector3::x();
            let blade_y = t_wb2.rotation * Vector3::y();
            let blade_z = t_wb2.rotation * Vector3::z();
            let cam_z = t_wc.rotation * Vector3::z();
            let cam_x = t_wc.rotation * Vector3::x();
            let cam_y = t_wc.rotation * Vector3::y();
            // Optical axis: in the blade's x–z plane, below the blade x axis by β_c.
            assert!(cam_z.dot(&blade_y).abs() < 1e-12);
            assert!((cam_z.dot(&blade_x) - p.beta_c.cos()).abs() < 1e-12);
            assert!((cam_z.dot(&blade_z) + p.beta_c.sin()).abs() < 1e-12);
            // Image x to the blade's right, image y downward.
            assert!((cam_x + blade_y).norm() < 1e-12);
            assert!(cam_y.dot(&blade_z) < -0.9);
            // Camera centre at (−d, 0, h) in the blade frame.
            let centre_in_blade = t_wb2.inverse() * nalgebra::Point3::from(t_wc.translation.vector);
            let expected = Vector3::new(-p.cam_d, 0.0, p.cam_h);
            assert!((centre_in_blade.coords - expected).norm() < 1e-12);
            // Batched FK agrees with the single one.
            let batch = robot.camera_poses(&[q]);
            let (et, er) = pose_error(&batch[0], &t_wc);
            assert!(et < 1e-12 && er < 1e-12);
        }
        // Level blade on the world-aligned default robot: optical axis pitched down by β_c.
        let robot = WaferRobot::default();
        let t_wc = robot.camera_pose(&Joints::zeros());
        let z = t_wc.rotation * Vector3::z();
        assert!((z.z.atan2(z.x) + robot.params.beta_c).abs() < 1e-12);
    }

    #[test]
    fn batched_fk_matches_single_fk_serial_and_parallel() {
        let robot = skewed_robot();
        let mut rng = Pcg64::seed_from_u64(3);
        for n in [0, 1, 17, PARALLEL_BATCH, PARALLEL_BATCH + 1, 1000] {
            let qs: Vec<Joints> = (0..n).map(|_| random_joints(&mut rng)).collect();
            let poses = robot.camera_poses(&qs);
            assert_eq!(poses.len(), n);
            for (q, t) in qs.iter().zip(&poses) {
                let (et, er) = pose_error(t, &robot.camera_pose(q));
                assert!(et < 1e-12 && er < 1e-12, "n = {n}: {et} {er}");
            }
        }
    }

    #[test]
    fn fk_ik_round_trip_over_random_reachable_poses() {
        for robot in [WaferRobot::default(), skewed_robot()] {
            let mut rng = Pcg64::seed_from_u64(4);
            for blade in [Blade::One, Blade::Two] {
                for _ in 0..600 {
                    let q = random_joints(&mut rng);
                    let other = if blade == Blade::One { q[3] } else { q[2] };
                    let target = robot.blade_pose(&q, blade);
                    let sols = robot.inverse_kinematics(&target, blade, other).unwrap();
                    assert!(!sols.is_empty() && sols.len() <= 2);
                    assert!(
                        sols.iter().any(|s| joints_close(s, &q, 1e-8)),
                        "{blade:?}: {q} not among {sols:?}"
                    );
                    for s in &sols {
                        let (et, er) = pose_error(&robot.blade_pose(s, blade), &target);
                        assert!(et < 1e-9 && er < 1e-9, "{blade:?} {q}: {et} {er}");
                        assert!(s.iter().take(4).all(|a| *a > -PI && *a <= PI));
                        let (other_idx, other_val) = match blade {
                            Blade::One => (3, s[3]),
                            Blade::Two => (2, s[2]),
                        };
                        assert_eq!(other_val, wrap_angle(q[other_idx]));
                    }
                    if sols.len() == 2 {
                        // Elbow up and elbow down: opposite elbow angles.
                        assert!((sols[0][1] + sols[1][1]).abs() < 1e-9);
                    }
                }
            }
        }
    }

    #[test]
    fn camera_ik_round_trip() {
        let robot = skewed_robot();
        let mut rng = Pcg64::seed_from_u64(5);
        for _ in 0..500 {
            let q = random_joints(&mut rng);
            let t_wc = robot.camera_pose(&q);
            let sols = robot.inverse_kinematics_camera(&t_wc, q[2]).unwrap();
            assert!(sols.iter().any(|s| joints_close(s, &q, 1e-8)));
            for s in &sols {
                let (et, er) = pose_error(&robot.camera_pose(s), &t_wc);
                assert!(et < 1e-9 && er < 1e-9);
            }
        }
    }

    #[test]
    fn boundary_solutions_collapse_to_one() {
        let robot = skewed_robot();
        for (t2, name) in [(0.0, "stretched"), (PI, "folded")] {
            let q = Joints::new(0.4, t2, -0.7, 0.2, 0.1);
            let target = robot.blade_pose(&q, Blade::One);
            let sols = robot.inverse_kinematics(&target, Blade::One, 0.2).unwrap();
            assert_eq!(sols.len(), 1, "{name}: {sols:?}");
            let (et, er) = pose_error(&robot.blade_pose(&sols[0], Blade::One), &target);
            assert!(et < 1e-9 && er < 1e-9, "{name}");
        }
        // l1 = l2 with the wrist on the shoulder axis: θ1 is free, one representative.
        let robot = WaferRobot::default();
        let q = Joints::new(0.0, PI, 0.9, 0.0, 0.0);
        let target = robot.blade_pose(&q, Blade::One);
        let sols = robot.inverse_kinematics(&target, Blade::One, 0.0).unwrap();
        assert_eq!(sols.len(), 1);
        let (et, er) = pose_error(&robot.blade_pose(&sols[0], Blade::One), &target);
        assert!(et < 1e-9 && er < 1e-9);
    }

    #[test]
    fn unreachable_poses_are_reported_with_numbers() {
        let robot = skewed_robot();
        let p = robot.params;
        let yaw = 0.3;
        let rot = yaw_pitch(yaw, p.alpha1);
        // Blade tip placed so that the wrist is at distance r from the shoulder axis.
        let at = |r: f64| {
            let wrist = Vector3::new(r, 0.0, 0.0);
            let tip = wrist + Vector3::new(p.l3 * yaw.cos(), p.l3 * yaw.sin(), 0.5);
            Isometry3::from_parts(Translation3::from(tip), rot)
        };
        let r_max = p.l1 + p.l2;
        let r_min = p.l1 - p.l2;
        for r in [r_max + 1e-6, r_max * 2.0, r_min - 1e-6, 0.0] {
            match robot.inverse_kinematics(&at(r), Blade::One, 0.0) {
                Err(GeometryError::Unreachable { reason }) => {
                    assert!(reason.contains("annulus"), "{reason}");
                    assert!(reason.contains(&format!("{r_max:.9}")), "{reason}");
                }
                other => panic!("r = {r}: expected Unreachable, got {other:?}"),
            }
        }
        // Just inside both limits is reachable.
        assert!(
            robot
                .inverse_kinematics(&at(r_max - 1e-9), Blade::One, 0.0)
                .is_ok()
        );
        assert!(
            robot
                .inverse_kinematics(&at(r_min + 1e-9), Blade::One, 0.0)
                .is_ok()
        );

        // Wrong roll or pitch: a reachable position with a tilted blade.
        let good = at(0.5);
        for (axis, angle) in [(Vector3::x_axis(), 1e-3), (Vector3::y_axis(), -0.02)] {
            let tilted = Isometry3::from_parts(
                good.translation,
                good.rotation * UnitQuaternion::from_axis_angle(&axis, angle),
            );
            match robot.inverse_kinematics(&tilted, Blade::One, 0.0) {
                Err(GeometryError::Unreachable { reason }) => {
                    assert!(reason.contains("mismatch"), "{reason}");
                    let deg = format!("{:.6}", angle.abs().to_degrees());
                    assert!(reason.contains(&deg), "{reason} should contain {deg}");
                }
                other => panic!("expected Unreachable, got {other:?}"),
            }
        }
        // Blade 2 has a different pitch: blade-1 orientation is not reachable for blade 2.
        assert!(matches!(
            robot.inverse_kinematics(&good, Blade::Two, 0.0),
            Err(GeometryError::Unreachable { .. })
        ));
        // Non-finite input.
        let mut nan = good;
        nan.translation.vector.y = f64::NAN;
        assert!(matches!(
            robot.inverse_kinematics(&nan, Blade::One, 0.0),
            Err(GeometryError::NonFinite { .. })
        ));
        assert!(
            robot
                .inverse_kinematics(&good, Blade::One, f64::INFINITY)
                .is_err()
        );
    }

    /// Blade position and yaw (continuous, unwrapped) for finite differences.
    fn position_yaw(robot: &WaferRobot, q: &Joints, blade: Blade) -> Vector4<f64> {
        let t = robot.blade_pose(q, blade).translation.vector;
        let wrist = if blade == Blade::One { q[2] } else { q[3] };
        Vector4::new(t.x, t.y, t.z, q[0] + q[1] + wrist)
    }

    #[test]
    fn jacobian_matches_central_finite_differences() {
        let robot = skewed_robot();
        let mut rng = Pcg64::seed_from_u64(6);
        let eps = 1e-6;
        for _ in 0..100 {
            let q = random_joints(&mut rng);
            for blade in [Blade::One, Blade::Two] {
                let j = robot.jacobian(&q, blade);
                for col in 0..5 {
                    let mut qp = q;
                    let mut qm = q;
                    qp[col] += eps;
                    qm[col] -= eps;
                    let fd = (position_yaw(&robot, &qp, blade) - position_yaw(&robot, &qm, blade))
                        / (2.0 * eps);
                    let err = (fd - j.column(col)).abs().max();
                    assert!(err < 1e-8, "{blade:?} column {col}: {err}");
                }
                // The yaw row must also agree with the rotation of blade_pose itself.
                let mut qp = q;
                qp[0] += eps;
                let d = robot.blade_pose(&q, blade).inverse() * robot.blade_pose(&qp, blade);
                let yaw_axis_in_blade =
                    robot.blade_pose(&q, blade).rotation.inverse() * Vector3::z();
                let w = d.rotation.scaled_axis() / eps;
                assert!((w - yaw_axis_in_blade * j[(3, 0)]).norm() < 1e-6);
            }
        }
    }

    #[test]
    fn acceleration_matches_finite_differences_of_velocity_along_trajectory() {
        let robot = skewed_robot();
        let mut rng = Pcg64::seed_from_u64(7);
        for _ in 0..20 {
            let c = random_joints(&mut rng);
            let amp = Joints::from_fn(|_, _| rng.random_range(-1.5..1.5));
            let freq = Joints::from_fn(|_, _| rng.random_range(0.3..3.0));
            let phase = Joints::from_fn(|_, _| rng.random_range(-PI..PI));
            let q_at =
                |t: f64| Joints::from_fn(|i, _| c[i] + amp[i] * (freq[i] * t + phase[i]).sin());
            let qd_at =
                |t: f64| Joints::from_fn(|i, _| amp[i] * freq[i] * (freq[i] * t + phase[i]).cos());
            let qdd_at = |t: f64| {
                Joints::from_fn(|i, _| -amp[i] * freq[i] * freq[i] * (freq[i] * t + phase[i]).sin())
            };
            let t0 = rng.random_range(0.0..5.0);
            let dt = 1e-5;
            for blade in [Blade::One, Blade::Two] {
                // The velocity itself is a finite difference of the pose along the trajectory.
                let vel_fd = (position_yaw(&robot, &q_at(t0 + dt), blade)
                    - position_yaw(&robot, &q_at(t0 - dt), blade))
                    / (2.0 * dt);
                let vel = robot.jacobian(&q_at(t0), blade) * qd_at(t0);
                assert!((vel_fd - vel).abs().max() < 1e-7, "{blade:?} velocity");
                let v = |t: f64| robot.jacobian(&q_at(t), blade) * qd_at(t);
                let acc_fd = (v(t0 + dt) - v(t0 - dt)) / (2.0 * dt);
                let acc = robot.acceleration(&q_at(t0), &qd_at(t0), &qdd_at(t0), blade);
                let err = (acc_fd - acc).abs().max();
                assert!(
                    err < 1e-6 * (1.0 + acc.abs().max()),
                    "{blade:?}: {acc_fd} vs {acc}"
                );
            }
        }
    }

    #[test]
    fn camera_jacobian_matches_finite_differences_with_se3_minus() {
        use crate::lie::{se3_minus, se3_plus};
        let robot = skewed_robot();
        let mut rng = Pcg64::seed_from_u64(8);
        let eps = 1e-6;
        for _ in 0..100 {
            let q = random_joints(&mut rng);
            let t_wc = robot.camera_pose(&q);
            let j = robot.camera_jacobian(&q);
            for col in 0..5 {
                let mut qp = q;
                let mut qm = q;
                qp[col] += eps;
                qm[col] -= eps;
                let fd = (se3_minus(&robot.camera_pose(&qp), &t_wc)
                    - se3_minus(&robot.camera_pose(&qm), &t_wc))
                    / (2.0 * eps);
                let err = (fd - j.column(col)).abs().max();
                assert!(err < 1e-8, "column {col}: {err}\n{fd}\n{}", j.column(col));
            }
            // First-order prediction of a small joint step, T(q + δq) ≈ T(q) ⊕ J δq.
            let dq = Joints::from_fn(|_, _| rng.random_range(-1e-4..1e-4));
            let predicted = se3_plus(&t_wc, &(j * dq));
            let (et, er) = pose_error(&predicted, &robot.camera_pose(&(q + dq)));
            assert!(et < 1e-7 && er < 1e-7, "{et} {er}");
            // Blade 1 (θ3) does not move the camera.
            assert!(j.column(2).norm() == 0.0);
        }
    }

    #[test]
    fn joint_offsets_follow_the_encoder_convention() {
        let robot = skewed_robot();
        let q_true = Joints::new(0.2, -1.0, 0.5, 2.0, 0.12);
        let offsets = Joints::new(0.01, -0.02, 0.003, 0.0, -0.004);
        let q_enc = encoders_from_joints(&q_true, &offsets);
        // q_enc = q_true + δ, component by component.
        for k in 0..5 {
            assert_eq!(q_enc[k], q_true[k] + offsets[k]);
        }
        let back = joints_from_encoders(&q_enc, &offsets);
        assert!((back - q_true).norm() < 1e-15);
        // Correcting the readings restores the true camera pose; ignoring the offsets does not.
        let (et, er) = pose_error(&robot.camera_pose(&back), &robot.camera_pose(&q_true));
        assert!(et < 1e-12 && er < 1e-12);
        let (et, _) = pose_error(&robot.camera_pose(&q_enc), &robot.camera_pose(&q_true));
        assert!(et > 1e-3);
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-7.0, -PI, -3.0, 0.0, 3.0, PI, 7.0, 100.0] {
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!(((a - w) / TAU - ((a - w) / TAU).round()).abs() < 1e-12);
        }
        assert_eq!(wrap_angle(-PI), PI);
    }
}
