//! The visual-inertial SLAM-MOT calibration of 000_3b1454b2b2194811.txt §5.3: factor graph
//! (eqs. (5.3)–(5.8)), camera poses through the kinematic chain (eqs. (5.9)–(5.10)), the conic
//! projection factor of every tracked edge point (eq. (5.13)), sliding-window and batch solves
//! and marginal covariances of every estimate.

use autoteach_geometry::lie::{hat, se3_adjoint, se3_minus, so3_right_jacobian_inv};
use autoteach_geometry::robot::{Joints, RobotParams, WaferRobot};
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Vector2, Vector3, Vector5};

use super::chain::{CameraChain, N_JOINTS};
use super::factors::{
    EdgeJacobians, conic_edge_residuals, nearest_model_angles, point_reprojection_residuals,
};
use super::motion::{FreeCameraEdgeResidual, RobotMotionResidual};
use super::wafer::{Rim, WaferGeometry};
use crate::lsq::{
    BlockId, Loss, Manifold, Problem, RelativePoseResidual, Residual, SolverOptions,
    se3_from_params, se3_to_params,
};
use crate::{EstimateError, Result};

mod basins;
pub use basins::BasinSearch;

/// Tracked edge points of one rim of one wafer in one frame (a camera observation `z_{k,t}`
/// of Fig. 5.5).
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeObservation {
    /// Frame index `t` (into the encoder readings).
    pub frame: usize,
    /// Wafer index `k`.
    pub wafer: usize,
    /// Which rim the points belong to.
    pub rim: Rim,
    /// Edge points in pixels (undistorted, pinhole `K`).
    pub points: Vec<Vector2<f64>>,
    /// Per-point factors of the edge-point standard deviation: point `i` has
    /// `σ_i = pixel_sigma · sigma_scale[i]`, i.e. the information `Ω^z_i = 1/σ_i²` of eq. (5.5)
    /// per point (a heteroscedastic noise model, e.g. from the predicted width of the wafer's
    /// side band at the point). Empty: every point has `pixel_sigma`.
    pub sigma_scale: Vec<f64>,
}

/// The camera-observation factor to use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EdgeFactor {
    /// The conic projection error of eq. (5.13) (point-to-object, no correspondences).
    Conic,
    /// Baseline: point-wise reprojection error against the nearest of `n_model` model points
    /// per rim, re-associated `rounds` times (point-based bundle adjustment with naive
    /// nearest-point association).
    NearestPoint {
        /// Model points per rim.
        n_model: usize,
        /// Association rounds.
        rounds: usize,
    },
}

/// Settings of the SLAM-MOT solve.
#[derive(Debug, Clone, PartialEq)]
pub struct SlamMotConfig {
    /// Pinhole intrinsic matrix `K`.
    pub k: Matrix3<f64>,
    /// Robot geometry (link lengths, camera mount), assumed accurate as in §5.3.
    pub robot_params: RobotParams,
    /// Wafer radius and thickness.
    pub geometry: WaferGeometry,
    /// Standard deviation of the edge points (pixels): `Ω^z = 1/σ²` of eq. (5.5).
    pub pixel_sigma: f64,
    /// Joints whose zero offsets are estimated (indices into `(θ1, θ2, θ3, θ4, h)`).
    pub estimate_offsets: Vec<usize>,
    /// Index of the reference wafer that defines the world frame (held fixed).
    pub reference_wafer: usize,
    /// Gauge prior on the yaw of the base about the world z axis (rad standard deviation).
    pub yaw_gauge_sigma: f64,
    /// Huber threshold on whitened residuals (`None`: plain least squares).
    pub huber: Option<f64>,
    /// Camera-observation factor.
    pub factor: EdgeFactor,
    /// Iteration limit of each solve.
    pub max_iterations: usize,
    /// Encoder noise (θ1, θ2, θ4, lift; rad, rad, rad, m) or `None`. With it every frame gets
    /// its own joint-noise variables `n_t` (the camera pose is `T_wc(q_enc − δ − n_t)`) with
    /// the Gaussian prior `N(0, diag(σ²))`: the robot-precision factor of eqs. (5.6), (5.11)
    /// in absolute form, so that the covariances account for the encoder noise that moves
    /// every edge point of a frame together.
    pub encoder_sigma: Option<[f64; 4]>,
    /// Also estimate a correction `ΔT` of the camera mount: `T_wc = T_wb·T_be(q)·T_ec·ΔT`
    /// (the optional calibration variable `T_ec` of §5.3; off by default). Reported as
    /// unobservable when the session does not constrain it.
    pub estimate_mount: bool,
    /// Link lengths whose additive corrections are estimated: 0 = `l1`, 1 = `l2`, 2 = `l4`
    /// (blade 2, which carries the camera); the kinematic parameters `γ` of eq. (5.10).
    pub estimate_links: Vec<usize>,
    /// Free-camera mode: every frame's camera pose is a variable, tied to the robot only
    /// through the relative robot motion factor of eqs. (5.10)–(5.12) between consecutive
    /// frames (and optionally visual-odometry increments). `None`: poses through the chain.
    pub free_camera: Option<FreeCamera>,
}

/// Settings of the free-camera mode (000_3b1454b2b2194811.txt eqs. (5.6), (5.10)–(5.12)).
#[derive(Debug, Clone, PartialEq)]
pub struct FreeCamera {
    /// Robot motion precision `[σ_ω (3, rad); σ_ρ (3, m)]` between consecutive frames.
    pub motion_sigma: [f64; 6],
    /// Visual-odometry increments `T_wc(t)⁻¹·T_wc(t+1)` (one per consecutive frame pair, or
    /// empty for none), each a relative-pose factor between the two camera poses.
    pub odometry: Vec<Isometry3<f64>>,
    /// Visual-odometry precision `[σ_ω (3); σ_ρ (3)]` per increment.
    pub odometry_sigma: [f64; 6],
    /// Gaussian prior on the calibration around its nominal value (`T_wb`, offsets) with
    /// these standard deviations (the robot's datasheet precision). Relative motions alone
    /// leave the base height along the vertical joint axes free and constrain the offsets of
    /// θ2/θ4 only through second-order (configuration-dependent) effects, with a far basin at
    /// `δ4 + π` and a displaced base; the prior keeps the solve in the physical one. `None`:
    /// no prior (the covariance then reports what the data alone constrain).
    pub calibration_prior: Option<(Isometry3<f64>, Joints, PriorSigmas)>,
}

/// Link lengths that may be calibrated, in [`SlamMotConfig::estimate_links`] order.
pub const LINK_NAMES: [&str; 3] = ["l1", "l2", "l4"];

/// Joints whose per-frame encoder noise is modelled (the others do not move the camera).
const NOISE_JOINTS: [usize; 4] = [0, 1, 3, 4];

/// `offsets` with a frame's joint noise `n_t` (one value per [`NOISE_JOINTS`] entry) added.
fn add_joint_noise(offsets: &mut Joints, n: &[f64]) {
    for (k, &j) in NOISE_JOINTS.iter().enumerate() {
        offsets[j] += n[k];
    }
}

impl SlamMotConfig {
    /// Defaults: 0.5 px edge noise, offsets of θ2 and θ4, wafer 0 as reference, a 1e-6 rad
    /// yaw gauge, Huber at 3σ, the conic factor, 50 iterations.
    pub fn new(k: Matrix3<f64>, robot_params: RobotParams, geometry: WaferGeometry) -> Self {
        Self {
            k,
            robot_params,
            geometry,
            pixel_sigma: 0.5,
            estimate_offsets: vec![1, 3],
            reference_wafer: 0,
            yaw_gauge_sigma: 1e-6,
            huber: Some(3.0),
            factor: EdgeFactor::Conic,
            max_iterations: 50,
            encoder_sigma: None,
            estimate_mount: false,
            estimate_links: Vec::new(),
            free_camera: None,
        }
    }

    fn validate(&self, n_wafers: usize) -> Result<()> {
        if !(self.pixel_sigma.is_finite() && self.pixel_sigma > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "pixel_sigma",
                value: self.pixel_sigma,
                reason: "must be positive",
            });
        }
        if !(self.yaw_gauge_sigma.is_finite() && self.yaw_gauge_sigma > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "yaw_gauge_sigma",
                value: self.yaw_gauge_sigma,
                reason: "must be positive",
            });
        }
        if let Some(&j) = self.estimate_offsets.iter().find(|&&j| j >= N_JOINTS) {
            return Err(EstimateError::InvalidParameter {
                name: "estimate_offsets",
                value: j as f64,
                reason: "joint indices are 0..5",
            });
        }
        if let Some(sig) = self.encoder_sigma
            && let Some(v) = sig.iter().find(|v| !(v.is_finite() && **v > 0.0))
        {
            return Err(EstimateError::InvalidParameter {
                name: "encoder_sigma",
                value: *v,
                reason: "must be finite and positive",
            });
        }
        if self.reference_wafer >= n_wafers {
            return Err(EstimateError::InvalidParameter {
                name: "reference_wafer",
                value: self.reference_wafer as f64,
                reason: "no such wafer",
            });
        }
        if let Some(&l) = self.estimate_links.iter().find(|&&l| l >= LINK_NAMES.len()) {
            return Err(EstimateError::InvalidParameter {
                name: "estimate_links",
                value: l as f64,
                reason: "link indices are 0 (l1), 1 (l2), 2 (l4)",
            });
        }
        if let Some(fc) = &self.free_camera {
            if self.estimate_mount || !self.estimate_links.is_empty() {
                return Err(EstimateError::InvalidParameter {
                    name: "free_camera",
                    value: 1.0,
                    reason: "the camera mount and link lengths are calibrated through the chain, not in free-camera mode",
                });
            }
            if self.encoder_sigma.is_some() || self.factor != EdgeFactor::Conic {
                return Err(EstimateError::InvalidParameter {
                    name: "free_camera",
                    value: 1.0,
                    reason: "free-camera mode uses the conic factor without per-frame encoder noise",
                });
            }
            if let Some(v) = fc
                .motion_sigma
                .iter()
                .chain(fc.odometry_sigma.iter())
                .find(|v| !(v.is_finite() && **v > 0.0))
            {
                return Err(EstimateError::InvalidParameter {
                    name: "free-camera sigma",
                    value: *v,
                    reason: "must be finite and positive",
                });
            }
        }
        if let EdgeFactor::NearestPoint { n_model, .. } = self.factor
            && n_model < 3
        {
            return Err(EstimateError::InvalidParameter {
                name: "n_model",
                value: n_model as f64,
                reason: "at least 3",
            });
        }
        Ok(())
    }
}

/// The current values of everything SLAM-MOT estimates.
#[derive(Debug, Clone, PartialEq)]
pub struct SlamMotState {
    /// Effective base pose `T_wb` (see the module docs of [`super`]).
    pub base: Isometry3<f64>,
    /// All five joint zero offsets (the estimated ones and the fixed rest).
    pub offsets: Joints,
    /// Wafers `[cx, cy, cz, rx, ry]`, indexed like the observations.
    pub wafers: Vec<Vector5<f64>>,
    /// Camera mount correction `ΔT` (identity unless [`SlamMotConfig::estimate_mount`]).
    pub mount: Isometry3<f64>,
    /// Link length corrections `Δl1, Δl2, Δl4` (m), added to the robot parameters.
    pub links: [f64; 3],
}

impl SlamMotState {
    /// A state with an identity mount correction and no link corrections.
    pub fn new(base: Isometry3<f64>, offsets: Joints, wafers: Vec<Vector5<f64>>) -> Self {
        Self {
            base,
            offsets,
            wafers,
            mount: Isometry3::identity(),
            links: [0.0; 3],
        }
    }

    /// The robot parameters with the link corrections applied.
    pub fn robot_params(&self, nominal: &RobotParams) -> RobotParams {
        let mut p = *nominal;
        p.l1 += self.links[0];
        p.l2 += self.links[1];
        p.l4 += self.links[2];
        p
    }
}

/// One estimate with its standard deviation (`None` when the data do not constrain it).
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Joint covariance of the estimated quantities in tangent coordinates, ordered: base
    /// `[ω; ρ]` (6), estimated offsets (in `estimate_offsets` order), then every observed
    /// non-reference wafer (5 each, in `wafer_order`), then the mount correction (6) and the
    /// link corrections when estimated. `None` if the information matrix is singular.
    pub covariance: Option<DMatrix<f64>>,
    /// Wafers in the order of the covariance.
    pub wafer_order: Vec<usize>,
    /// Blocks/directions the data leave unconstrained (the lsq engine's report), if any.
    pub unobservable: Option<String>,
}

/// Outcome of a solve.
#[derive(Debug, Clone, PartialEq)]
pub struct SlamMotSolution {
    /// Estimates.
    pub state: SlamMotState,
    /// Covariances.
    pub uncertainty: Uncertainty,
    /// Initial and final cost, iterations.
    pub initial_cost: f64,
    /// Final cost.
    pub final_cost: f64,
    /// LM iterations (summed over association rounds).
    pub iterations: usize,
    /// RMS of the final whitened edge residuals times σ (pixels).
    pub rms_px: f64,
    /// Number of scalar edge residuals.
    pub n_residuals: usize,
    /// Camera pose `T_wc` of every frame: through the calibrated chain, or the free poses
    /// (free-camera mode; frames without a pose variable get the chain pose).
    pub camera_poses: Vec<Isometry3<f64>>,
}

/// Per-window record of the sliding-window run (Fig. 5.11).
#[derive(Debug, Clone, PartialEq)]
pub struct WindowRecord {
    /// Last frame of the window.
    pub last_frame: usize,
    /// Estimates after the window.
    pub state: SlamMotState,
    /// Standard deviations of the base tangent `[ω; ρ]` (6) and the estimated offsets.
    pub std: Vec<f64>,
}

/// The conic edge factor of eq. (5.13) with camera poses through eq. (5.9): blocks
/// `[base (Se3), offset_j (Euclidean 1) …, wafer (Euclidean 5), joint noise n_t (Euclidean 4)?,
/// mount correction ΔT (Se3)?, link corrections (Euclidean k)?]`.
struct EdgeResidual {
    k: Matrix3<f64>,
    params: RobotParams,
    geometry: WaferGeometry,
    q_enc: Joints,
    fixed_offsets: Joints,
    offset_joints: Vec<usize>,
    rim: Rim,
    points: Vec<Vector2<f64>>,
    sigma: f64,
    /// `Some(angles)`: the point-reprojection baseline with these associations.
    angles: Option<Vec<f64>>,
    /// Whether the block after the wafer is the frame's joint noise `n_t` (Euclidean 4).
    joint_noise: bool,
    /// Mount correction when it is not a block.
    fixed_mount: Isometry3<f64>,
    /// Whether the mount correction is a block.
    mount_block: bool,
    /// Link corrections when they are not blocks (all three).
    fixed_links: [f64; 3],
    /// Links whose corrections form the last block.
    link_idx: Vec<usize>,
}

impl EdgeResidual {
    /// Block positions of the wafer, the joint noise, the mount and the links.
    fn layout(&self) -> (usize, Option<usize>, Option<usize>, Option<usize>) {
        let iw = 1 + self.offset_joints.len();
        let mut next = iw + 1;
        let noise = self.joint_noise.then(|| {
            next += 1;
            next - 1
        });
        let mount = self.mount_block.then(|| {
            next += 1;
            next - 1
        });
        let links = (!self.link_idx.is_empty()).then_some(next);
        (iw, noise, mount, links)
    }

    fn chain(&self, params: &[&[f64]]) -> CameraChain {
        let (_, inoise, _, ilinks) = self.layout();
        let mut offsets = self.fixed_offsets;
        for (i, &j) in self.offset_joints.iter().enumerate() {
            offsets[j] = params[1 + i][0];
        }
        if let Some(i) = inoise {
            add_joint_noise(&mut offsets, params[i]);
        }
        let mut links = self.fixed_links;
        if let Some(i) = ilinks {
            for (k, &l) in self.link_idx.iter().enumerate() {
                links[l] = params[i][k];
            }
        }
        let mut rp = self.params;
        rp.l1 += links[0];
        rp.l2 += links[1];
        rp.l4 += links[2];
        CameraChain {
            robot: WaferRobot {
                params: rp,
                base: se3_from_params(params[0]),
            },
            offsets,
        }
    }
}

/// A residual whose rows are divided by per-point standard-deviation factors (eq. (5.5) with
/// `Ω^z_i = 1/(σ·s_i)²`): the inner residual is whitened by the common `σ`, each of its
/// `rows_per_point` rows of point `i` is then multiplied by `1/s_i`, and so are the matching
/// Jacobian rows (the scaling is constant, so the Jacobians stay exact).
struct RowScaled<R> {
    inner: R,
    /// `1/s` per residual row.
    inv: Vec<f64>,
}

impl<R: Residual> RowScaled<R> {
    fn new(inner: R, scale: &[f64], rows_per_point: usize) -> Self {
        let inv = scale
            .iter()
            .flat_map(|s| std::iter::repeat_n(1.0 / s, rows_per_point))
            .collect();
        Self { inner, inv }
    }
}

impl<R: Residual> Residual for RowScaled<R> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let mut jacobians = jacobians;
        self.inner
            .evaluate(params, residual, jacobians.as_deref_mut())?;
        for (r, w) in residual.iter_mut().zip(&self.inv) {
            *r *= w;
        }
        if let Some(jac) = jacobians {
            for j in jac.iter_mut() {
                for (i, w) in self.inv.iter().enumerate() {
                    j.row_mut(i).scale_mut(*w);
                }
            }
        }
        Ok(())
    }
}

/// Body-frame twist `[0; R_bcᵀ u]` of the camera per unit length of link `l` (0 = l1, 1 = l2,
/// 2 = l4): lengthening a link moves everything after it along the link's direction `u`
/// (angles `θ1`, `θ1+θ2`, `θ1+θ2+θ4` of the true joints, eq. (2.4)).
fn link_twist(chain: &CameraChain, q_enc: &Joints, link: usize) -> DVector<f64> {
    let q = chain.true_joints(q_enc);
    let angle = match link {
        0 => q[0],
        1 => q[0] + q[1],
        _ => q[0] + q[1] + q[3],
    };
    let u = Vector3::new(angle.cos(), angle.sin(), 0.0);
    let r_bc = chain.robot.camera_pose_in_base(&q).rotation;
    let rho = r_bc.inverse() * u;
    DVector::from_column_slice(&[0.0, 0.0, 0.0, rho.x, rho.y, rho.z])
}

impl Residual for EdgeResidual {
    fn dim(&self) -> usize {
        self.points.len() * if self.angles.is_some() { 2 } else { 1 }
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let (iw, inoise, imount, ilinks) = self.layout();
        let chain = self.chain(params);
        let ev = chain.evaluate(&self.q_enc);
        let mount = imount.map_or(self.fixed_mount, |i| se3_from_params(params[i]));
        let t_wc = ev.t_wc * mount;
        let w = Vector5::from_column_slice(params[iw]);
        let n = self.dim();
        let mut ej = jacobians.as_ref().map(|_| EdgeJacobians {
            camera: DMatrix::zeros(n, 6),
            wafer: DMatrix::zeros(n, 5),
        });
        let (r, t) = (self.geometry.radius, self.geometry.thickness);
        match &self.angles {
            None => conic_edge_residuals(
                &self.k,
                &t_wc,
                &w,
                self.rim,
                r,
                t,
                &self.points,
                self.sigma,
                residual,
                ej.as_mut(),
            )?,
            Some(a) => point_reprojection_residuals(
                &self.k,
                &t_wc,
                &w,
                self.rim,
                r,
                t,
                &self.points,
                a,
                self.sigma,
                residual,
                ej.as_mut(),
            )?,
        }
        if let (Some(jac), Some(ej)) = (jacobians, ej) {
            // T_wc·ΔT ⊕ ε from T_wc ⊕ η: ε = Ad(ΔT⁻¹)·η.
            let ad = se3_adjoint(&mount.inverse());
            let cam = &ej.camera * DMatrix::from_column_slice(6, 6, ad.as_slice());
            jac[0].copy_from(&(&cam * DMatrix::from_column_slice(6, 6, ev.d_base.as_slice())));
            for (i, &j) in self.offset_joints.iter().enumerate() {
                let col = ev.d_offsets.column(j);
                let dcol = &cam * DVector::from_column_slice(col.as_slice());
                jac[1 + i].set_column(0, &dcol);
            }
            jac[iw].copy_from(&ej.wafer);
            if let Some(i) = inoise {
                for (k, &j) in NOISE_JOINTS.iter().enumerate() {
                    let col = ev.d_offsets.column(j);
                    jac[i].set_column(k, &(&cam * DVector::from_column_slice(col.as_slice())));
                }
            }
            if let Some(i) = imount {
                jac[i].copy_from(&ej.camera);
            }
            if let Some(i) = ilinks {
                for (k, &l) in self.link_idx.iter().enumerate() {
                    jac[i].set_column(k, &(&cam * link_twist(&chain, &self.q_enc, l)));
                }
            }
        }
        Ok(())
    }
}

/// Gauge prior on the base yaw `atan2(R₁₀, R₀₀)` (one whitened residual).
struct YawGauge {
    yaw: f64,
    sigma: f64,
}

impl Residual for YawGauge {
    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let t = se3_from_params(params[0]);
        let r = t.rotation.to_rotation_matrix().into_inner();
        let h = r.column(0).into_owned();
        let yaw = h.y.atan2(h.x);
        residual[0] = autoteach_geometry::robot::wrap_angle(yaw - self.yaw) / self.sigma;
        if let Some(jac) = jacobians {
            // d(R Exp(ω) e_x)/dω = −R [e_x]×.
            let dh = -r * hat(&Vector3::x());
            let den = h.x * h.x + h.y * h.y;
            for m in 0..3 {
                jac[0][(0, m)] = (h.x * dh[(1, m)] - h.y * dh[(0, m)]) / den / self.sigma;
            }
        }
        Ok(())
    }
}

/// A Gaussian prior on several blocks jointly (the marginalised previous window):
/// `r = L⁻¹ [x_b ⊖ μ_b]_b` with `Σ = L Lᵀ`; blocks are Se3 (first) and Euclidean.
struct JointPrior {
    means: Vec<Vec<f64>>,
    manifolds: Vec<Manifold>,
    l_inv: DMatrix<f64>,
}

impl Residual for JointPrior {
    fn dim(&self) -> usize {
        self.l_inv.nrows()
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let n = self.dim();
        let mut d = DVector::zeros(n);
        let mut dj = DMatrix::zeros(n, n);
        let mut off = 0;
        for (b, (m, mu)) in self.manifolds.iter().zip(&self.means).enumerate() {
            match m {
                Manifold::Se3 => {
                    let x = se3_from_params(params[b]);
                    let e = se3_minus(&x, &se3_from_params(mu));
                    d.rows_mut(off, 6).copy_from(&e);
                    // ∂(x ⊖ μ)/∂δx = J_r⁻¹(e) for SE(3); the rotation block approximation
                    // J_r⁻¹ of SO(3) on both parts is exact to first order near e = 0.
                    let jr = so3_right_jacobian_inv(&Vector3::new(e[0], e[1], e[2]));
                    let mut j6 = DMatrix::<f64>::identity(6, 6);
                    j6.view_mut((0, 0), (3, 3)).copy_from(&jr);
                    j6.view_mut((3, 3), (3, 3)).copy_from(&jr);
                    dj.view_mut((off, off), (6, 6)).copy_from(&j6);
                    off += 6;
                }
                _ => {
                    let k = params[b].len();
                    for i in 0..k {
                        d[off + i] = params[b][i] - mu[i];
                        dj[(off + i, off + i)] = 1.0;
                    }
                    off += k;
                }
            }
        }
        let r = &self.l_inv * d;
        residual.copy_from_slice(r.as_slice());
        if let Some(jac) = jacobians {
            let full = &self.l_inv * dj;
            let mut off = 0;
            for (b, m) in self.manifolds.iter().enumerate() {
                let k = m.tangent_dim();
                jac[b].copy_from(&full.columns(off, k));
                off += k;
            }
        }
        Ok(())
    }
}

/// The parameter blocks of one problem.
struct Blocks {
    base: BlockId,
    offsets: Vec<BlockId>,
    wafers: Vec<Option<BlockId>>,
    mount: Option<BlockId>,
    links: Option<BlockId>,
    cameras: Vec<Option<BlockId>>,
    /// Each frame's joint-noise block `n_t` (with [`SlamMotConfig::encoder_sigma`]).
    noise: Vec<Option<BlockId>>,
}

impl Blocks {
    /// The calibration blocks in covariance order: base, offsets, mount, links.
    fn calibration(&self) -> Vec<BlockId> {
        let mut v = vec![self.base];
        v.extend(&self.offsets);
        v.extend(self.mount);
        v.extend(self.links);
        v
    }
}

/// The SLAM-MOT estimator over a session: encoder readings per frame and edge observations.
#[derive(Debug, Clone)]
pub struct SlamMot {
    config: SlamMotConfig,
    encoders: Vec<Joints>,
    observations: Vec<EdgeObservation>,
    n_wafers: usize,
}

impl SlamMot {
    /// Validates the inputs: finite encoders and points, observations naming existing frames
    /// and wafers, a non-empty point set per observation.
    pub fn new(
        config: SlamMotConfig,
        encoders: Vec<Joints>,
        observations: Vec<EdgeObservation>,
        n_wafers: usize,
    ) -> Result<Self> {
        config.validate(n_wafers)?;
        config.robot_params.validate()?;
        for (f, q) in encoders.iter().enumerate() {
            if let Some((i, v)) = q.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(EstimateError::NonFiniteInput {
                    what: format!("encoder reading of frame {f}"),
                    index: i,
                    value: *v,
                });
            }
        }
        for (o, obs) in observations.iter().enumerate() {
            if obs.frame >= encoders.len() || obs.wafer >= n_wafers {
                return Err(EstimateError::InvalidParameter {
                    name: "observation frame/wafer",
                    value: o as f64,
                    reason: "an observation names a frame without encoder reading or an unknown wafer",
                });
            }
            if obs.points.is_empty() {
                return Err(EstimateError::InvalidParameter {
                    name: "observation points",
                    value: o as f64,
                    reason: "an observation has no edge points",
                });
            }
            if !obs.sigma_scale.is_empty() && obs.sigma_scale.len() != obs.points.len() {
                return Err(EstimateError::DimensionMismatch {
                    what: format!("sigma_scale of observation {o} (one per edge point or none)"),
                    expected: vec![obs.points.len()],
                    got: vec![obs.sigma_scale.len()],
                });
            }
            if let Some(v) = obs
                .sigma_scale
                .iter()
                .find(|v| !(v.is_finite() && **v > 0.0))
            {
                return Err(EstimateError::InvalidParameter {
                    name: "sigma_scale",
                    value: *v,
                    reason: "per-point standard-deviation factors must be finite and positive",
                });
            }
            if let Some(p) = obs
                .points
                .iter()
                .find(|p| !(p.x.is_finite() && p.y.is_finite()))
            {
                return Err(EstimateError::NonFiniteInput {
                    what: format!("edge points of observation {o}"),
                    index: 0,
                    value: if p.x.is_finite() { p.y } else { p.x },
                });
            }
        }
        if observations.is_empty() {
            return Err(EstimateError::InvalidParameter {
                name: "observations",
                value: 0.0,
                reason: "no wafer edge was observed in any frame: nothing constrains the calibration",
            });
        }
        Ok(Self {
            config,
            encoders,
            observations,
            n_wafers,
        })
    }

    /// The settings.
    pub fn config(&self) -> &SlamMotConfig {
        &self.config
    }

    /// Camera poses `T_wc` of every frame for a state (eq. (5.9)).
    pub fn camera_poses(&self, state: &SlamMotState) -> Vec<Isometry3<f64>> {
        self.chain_poses(state, |_| state.offsets)
    }

    /// Camera poses `T_wc` through the chain of `state` with the zero offsets `offsets(t)` of
    /// frame `t`.
    fn chain_poses(
        &self,
        state: &SlamMotState,
        offsets: impl Fn(usize) -> Joints,
    ) -> Vec<Isometry3<f64>> {
        let robot = WaferRobot {
            params: state.robot_params(&self.config.robot_params),
            base: state.base,
        };
        let qs: Vec<Joints> = self
            .encoders
            .iter()
            .enumerate()
            .map(|(t, q)| q - offsets(t))
            .collect();
        let poses = robot.camera_poses(&qs);
        if state.mount == Isometry3::identity() {
            poses
        } else {
            poses.into_iter().map(|t| t * state.mount).collect()
        }
    }

    /// Initial height of every wafer by a 1-D search along the world z axis (wafers stacked
    /// above the reference, level): for each wafer the z (step `step`, within `z_range`) whose
    /// rim conics best explain its edge points (median |conic error|) with the camera poses of
    /// `state`; the reference wafer keeps its value. Returns the wafers of `state` updated.
    pub fn initial_wafer_heights(
        &self,
        state: &SlamMotState,
        z_range: (f64, f64),
        step: f64,
    ) -> Result<Vec<Vector5<f64>>> {
        if !(step > 0.0 && z_range.1 > z_range.0) {
            return Err(EstimateError::InvalidParameter {
                name: "z search step",
                value: step,
                reason: "needs step > 0 and a non-empty range",
            });
        }
        let poses = self.camera_poses(state);
        let mut out = state.wafers.clone();
        let n_steps = ((z_range.1 - z_range.0) / step).ceil() as usize + 1;
        for (k, wk) in out.iter_mut().enumerate() {
            if k == self.config.reference_wafer {
                continue;
            }
            let obs: Vec<&EdgeObservation> =
                self.observations.iter().filter(|o| o.wafer == k).collect();
            if obs.is_empty() {
                continue;
            }
            let mut best = (f64::INFINITY, wk[2]);
            for s in 0..n_steps {
                let z = z_range.0 + step * s as f64;
                let w = Vector5::new(wk[0], wk[1], z, wk[3], wk[4]);
                let mut errs = Vec::new();
                for o in obs.iter().step_by((obs.len() / 40).max(1)) {
                    let mut r = vec![0.0; o.points.len()];
                    if conic_edge_residuals(
                        &self.config.k,
                        &poses[o.frame],
                        &w,
                        o.rim,
                        self.config.geometry.radius,
                        self.config.geometry.thickness,
                        &o.points,
                        1.0,
                        &mut r,
                        None,
                    )
                    .is_ok()
                    {
                        errs.extend(r.iter().map(|v| v.abs()));
                    }
                }
                if errs.is_empty() {
                    continue;
                }
                errs.sort_by(f64::total_cmp);
                let med = errs[errs.len() / 2];
                if med < best.0 {
                    best = (med, z);
                }
            }
            wk[2] = best.1;
        }
        Ok(out)
    }

    fn build(
        &self,
        state: &SlamMotState,
        frames: std::ops::Range<usize>,
        angles: Option<&[Option<Vec<f64>>]>,
    ) -> Result<(Problem, Blocks, usize)> {
        let mut p = Problem::new();
        let base = p.add_block(&se3_to_params(&state.base), Manifold::Se3)?;
        let offsets: Vec<BlockId> = self
            .config
            .estimate_offsets
            .iter()
            .map(|&j| p.add_block(&[state.offsets[j]], Manifold::Euclidean(1)))
            .collect::<Result<_>>()?;
        let mount = if self.config.estimate_mount {
            Some(p.add_block(&se3_to_params(&state.mount), Manifold::Se3)?)
        } else {
            None
        };
        let links = if self.config.estimate_links.is_empty() {
            None
        } else {
            let v: Vec<f64> = self
                .config
                .estimate_links
                .iter()
                .map(|&l| state.links[l])
                .collect();
            Some(p.add_block(&v, Manifold::Euclidean(v.len()))?)
        };
        let mut cameras: Vec<Option<BlockId>> = vec![None; self.encoders.len()];
        if let Some(fc) = &self.config.free_camera {
            let poses = self.camera_poses(state);
            for f in frames.clone() {
                cameras[f] = Some(p.add_block(&se3_to_params(&poses[f]), Manifold::Se3)?);
            }
            let cov = DMatrix::from_diagonal(&DVector::from_iterator(
                6,
                fc.odometry_sigma.iter().map(|v| v * v),
            ));
            for f in frames.start..frames.end.saturating_sub(1) {
                let (Some(a), Some(b)) = (cameras[f], cameras[f + 1]) else {
                    continue;
                };
                let motion = RobotMotionResidual::new(
                    self.config.robot_params,
                    self.encoders[f],
                    self.encoders[f + 1],
                    state.offsets,
                    self.config.estimate_offsets.clone(),
                    fc.motion_sigma,
                )?;
                let mut blocks = vec![a, b, base];
                blocks.extend(&offsets);
                p.add_residual(motion, &blocks, Loss::Trivial)?;
                if let Some(z) = fc.odometry.get(f) {
                    p.add_residual(RelativePoseResidual::new(z, &cov)?, &[a, b], Loss::Trivial)?;
                }
            }
            if let Some((nominal_base, nominal_offsets, sig)) = &fc.calibration_prior {
                p.add_prior(base, &se3_to_params(nominal_base), &sig.pose_covariance())?;
                for (i, &j) in self.config.estimate_offsets.iter().enumerate() {
                    let c1 = DMatrix::from_element(1, 1, sig.offset.powi(2));
                    p.add_prior(offsets[i], &[nominal_offsets[j]], &c1)?;
                }
            }
        }
        let mut wafers: Vec<Option<BlockId>> = vec![None; self.n_wafers];
        let mut noise: Vec<Option<BlockId>> = vec![None; self.encoders.len()];
        let loss = self.config.huber.map_or(Loss::Trivial, Loss::Huber);
        let mut n_res = 0;
        for (o, obs) in self.observations.iter().enumerate() {
            if !frames.contains(&obs.frame) {
                continue;
            }
            let wb = match wafers[obs.wafer] {
                Some(b) => b,
                None => {
                    let b =
                        p.add_block(state.wafers[obs.wafer].as_slice(), Manifold::Euclidean(5))?;
                    if obs.wafer == self.config.reference_wafer {
                        p.set_fixed(b, true)?;
                    }
                    wafers[obs.wafer] = Some(b);
                    b
                }
            };
            if let Some(cb) = cameras[obs.frame] {
                let res = FreeCameraEdgeResidual {
                    k: self.config.k,
                    geometry: self.config.geometry,
                    rim: obs.rim,
                    points: obs.points.clone(),
                    sigma: self.config.pixel_sigma,
                };
                n_res += res.dim();
                if obs.sigma_scale.is_empty() {
                    p.add_residual(res, &[cb, wb], loss)?;
                } else {
                    let res = RowScaled::new(res, &obs.sigma_scale, 1);
                    p.add_residual(res, &[cb, wb], loss)?;
                }
                continue;
            }
            let nb = match (self.config.encoder_sigma, noise[obs.frame]) {
                (None, _) => None,
                (Some(_), Some(b)) => Some(b),
                (Some(sig), None) => {
                    let b = p.add_block(&[0.0; 4], Manifold::Euclidean(4))?;
                    let cov = DMatrix::from_diagonal(&DVector::from_iterator(
                        4,
                        sig.iter().map(|v| v * v),
                    ));
                    p.add_prior(b, &[0.0; 4], &cov)?;
                    noise[obs.frame] = Some(b);
                    Some(b)
                }
            };
            let res = EdgeResidual {
                k: self.config.k,
                params: self.config.robot_params,
                geometry: self.config.geometry,
                q_enc: self.encoders[obs.frame],
                fixed_offsets: state.offsets,
                offset_joints: self.config.estimate_offsets.clone(),
                rim: obs.rim,
                points: obs.points.clone(),
                sigma: self.config.pixel_sigma,
                angles: angles.and_then(|a| a[o].clone()),
                joint_noise: nb.is_some(),
                fixed_mount: state.mount,
                mount_block: mount.is_some(),
                fixed_links: state.links,
                link_idx: self.config.estimate_links.clone(),
            };
            n_res += res.dim();
            let mut blocks = vec![base];
            blocks.extend(&offsets);
            blocks.push(wb);
            blocks.extend(nb);
            blocks.extend(mount);
            blocks.extend(links);
            if obs.sigma_scale.is_empty() {
                p.add_residual(res, &blocks, loss)?;
            } else {
                let rows = if res.angles.is_some() { 2 } else { 1 };
                p.add_residual(RowScaled::new(res, &obs.sigma_scale, rows), &blocks, loss)?;
            }
        }
        let yaw = {
            let r = state.base.rotation.to_rotation_matrix().into_inner();
            r[(1, 0)].atan2(r[(0, 0)])
        };
        p.add_residual(
            YawGauge {
                yaw,
                sigma: self.config.yaw_gauge_sigma,
            },
            &[base],
            Loss::Trivial,
        )?;
        Ok((
            p,
            Blocks {
                base,
                offsets,
                wafers,
                mount,
                links,
                cameras,
                noise,
            },
            n_res,
        ))
    }

    fn read_state(&self, p: &Problem, b: &Blocks, prev: &SlamMotState) -> SlamMotState {
        let mut s = prev.clone();
        s.base = se3_from_params(p.values(b.base));
        for (i, &j) in self.config.estimate_offsets.iter().enumerate() {
            s.offsets[j] = p.values(b.offsets[i])[0];
        }
        for (k, w) in b.wafers.iter().enumerate() {
            if let Some(w) = w {
                s.wafers[k] = Vector5::from_column_slice(p.values(*w));
            }
        }
        if let Some(m) = b.mount {
            s.mount = se3_from_params(p.values(m));
        }
        if let Some(l) = b.links {
            for (k, &li) in self.config.estimate_links.iter().enumerate() {
                s.links[li] = p.values(l)[k];
            }
        }
        s
    }

    /// Per-frame camera poses: the free pose variables where they exist, else the chain.
    /// The camera pose of every frame as the solve's edge residuals see it: the free pose, or
    /// the chain's with the frame's estimated joint noise `n_t` added to the offsets (the
    /// residuals' [`EdgeResidual::chain`]), else the chain's of `state`.
    fn frame_poses(&self, p: &Problem, b: &Blocks, state: &SlamMotState) -> Vec<Isometry3<f64>> {
        let mut poses = self.chain_poses(state, |t| {
            let mut offsets = state.offsets;
            if let Some(nb) = b.noise[t] {
                add_joint_noise(&mut offsets, p.values(nb));
            }
            offsets
        });
        for (f, c) in b.cameras.iter().enumerate() {
            if let Some(c) = c {
                poses[f] = se3_from_params(p.values(*c));
            }
        }
        poses
    }

    fn uncertainty(&self, p: &Problem, b: &Blocks) -> Uncertainty {
        let mut blocks = vec![b.base];
        blocks.extend(&b.offsets);
        let mut order = Vec::new();
        for (k, w) in b.wafers.iter().enumerate() {
            if let Some(w) = w
                && k != self.config.reference_wafer
            {
                blocks.push(*w);
                order.push(k);
            }
        }
        blocks.extend(b.mount);
        blocks.extend(b.links);
        match p.marginal_covariance(&blocks) {
            Ok(c) => Uncertainty {
                covariance: Some(c),
                wafer_order: order,
                unobservable: None,
            },
            Err(EstimateError::RankDeficient { directions, .. }) => Uncertainty {
                covariance: None,
                wafer_order: order,
                unobservable: Some(self.describe(&directions, b)),
            },
            Err(e) => Uncertainty {
                covariance: None,
                wafer_order: order,
                unobservable: Some(format!("covariance failed: {e}")),
            },
        }
    }

    /// Rewrites the engine's `block N` names into parameter names.
    fn describe(&self, directions: &str, b: &Blocks) -> String {
        let mut names: Vec<(usize, String)> = vec![(b.base.0, "base pose".into())];
        for (i, &j) in self.config.estimate_offsets.iter().enumerate() {
            names.push((
                b.offsets[i].0,
                format!("{} zero offset", super::chain::JOINT_NAMES[j]),
            ));
        }
        for (k, w) in b.wafers.iter().enumerate() {
            if let Some(w) = w {
                names.push((w.0, format!("wafer {k}")));
            }
        }
        if let Some(m) = b.mount {
            names.push((m.0, "camera mount T_ec".into()));
        }
        if let Some(l) = b.links {
            let which: Vec<&str> = self
                .config
                .estimate_links
                .iter()
                .map(|&i| LINK_NAMES[i])
                .collect();
            names.push((l.0, format!("link lengths ({})", which.join(", "))));
        }
        for (f, c) in b.cameras.iter().enumerate() {
            if let Some(c) = c {
                names.push((c.0, format!("camera pose of frame {f}")));
            }
        }
        let mut out = directions.to_string();
        names.sort_by_key(|n| std::cmp::Reverse(n.0));
        for (id, name) in names {
            out = out
                .replace(&format!("block {id} "), &format!("{name} "))
                .replace(&format!("block {id})"), &format!("{name})"));
        }
        format!("unobservable: {out}")
    }

    fn options(&self) -> SolverOptions {
        SolverOptions {
            max_iterations: self.config.max_iterations,
            ..SolverOptions::default()
        }
    }

    fn associate(&self, state: &SlamMotState, n_model: usize) -> Result<Vec<Option<Vec<f64>>>> {
        let poses = self.camera_poses(state);
        self.observations
            .iter()
            .map(|o| {
                nearest_model_angles(
                    &self.config.k,
                    &poses[o.frame],
                    &state.wafers[o.wafer],
                    o.rim,
                    self.config.geometry.radius,
                    self.config.geometry.thickness,
                    &o.points,
                    n_model,
                )
                .map(Some)
            })
            .collect()
    }

    /// The full batch solve over all frames from `initial`, with marginal covariances.
    pub fn solve_batch(&self, initial: &SlamMotState) -> Result<SlamMotSolution> {
        self.check_state(initial)?;
        let all = 0..self.encoders.len();
        let (rounds, n_model) = match self.config.factor {
            EdgeFactor::Conic => (1, 0),
            EdgeFactor::NearestPoint { n_model, rounds } => (rounds.max(1), n_model),
        };
        let mut state = initial.clone();
        let mut iterations = 0;
        let mut initial_cost = f64::NAN;
        let mut last = None;
        for round in 0..rounds {
            let angles = if n_model > 0 {
                Some(self.associate(&state, n_model)?)
            } else {
                None
            };
            let (mut p, b, n_res) = self.build(&state, all.clone(), angles.as_deref())?;
            let summary = p.solve(&self.options())?;
            if round == 0 {
                initial_cost = summary.initial_cost;
            }
            iterations += summary.iterations;
            state = self.read_state(&p, &b, &state);
            last = Some((p, b, n_res, summary.final_cost));
        }
        let (p, b, n_res, final_cost) = last.ok_or(EstimateError::InvalidParameter {
            name: "rounds",
            value: 0.0,
            reason: "no solve ran",
        })?;
        let uncertainty = self.uncertainty(&p, &b);
        let camera_poses = self.frame_poses(&p, &b, &state);
        let rms_px = self.rms_with_poses(&camera_poses, &state, n_model)?;
        Ok(SlamMotSolution {
            state,
            uncertainty,
            initial_cost,
            final_cost,
            iterations,
            rms_px,
            n_residuals: n_res,
            camera_poses,
        })
    }

    /// RMS edge error in pixels of a state (conic distance, or point distance for the
    /// baseline).
    pub fn rms(&self, state: &SlamMotState, n_model: usize) -> Result<f64> {
        self.rms_with_poses(&self.camera_poses(state), state, n_model)
    }

    /// [`Self::rms`] with given per-frame camera poses (free-camera mode).
    pub fn rms_with_poses(
        &self,
        poses: &[Isometry3<f64>],
        state: &SlamMotState,
        n_model: usize,
    ) -> Result<f64> {
        if poses.len() != self.encoders.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "camera poses".into(),
                expected: vec![self.encoders.len()],
                got: vec![poses.len()],
            });
        }
        let (mut s, mut n) = (0.0, 0usize);
        for o in &self.observations {
            let w = &state.wafers[o.wafer];
            let (g, k) = (&self.config.geometry, &self.config.k);
            let r = if n_model > 0 {
                let a = nearest_model_angles(
                    k,
                    &poses[o.frame],
                    w,
                    o.rim,
                    g.radius,
                    g.thickness,
                    &o.points,
                    n_model,
                )?;
                let mut r = vec![0.0; 2 * o.points.len()];
                point_reprojection_residuals(
                    k,
                    &poses[o.frame],
                    w,
                    o.rim,
                    g.radius,
                    g.thickness,
                    &o.points,
                    &a,
                    1.0,
                    &mut r,
                    None,
                )?;
                r
            } else {
                let mut r = vec![0.0; o.points.len()];
                conic_edge_residuals(
                    k,
                    &poses[o.frame],
                    w,
                    o.rim,
                    g.radius,
                    g.thickness,
                    &o.points,
                    1.0,
                    &mut r,
                    None,
                )?;
                r
            };
            s += r.iter().map(|v| v * v).sum::<f64>();
            n += r.len();
        }
        Ok(if n > 0 {
            (s / n as f64).sqrt()
        } else {
            f64::NAN
        })
    }

    fn check_state(&self, s: &SlamMotState) -> Result<()> {
        if s.wafers.len() != self.n_wafers {
            return Err(EstimateError::DimensionMismatch {
                what: "initial wafers".into(),
                expected: vec![self.n_wafers, 5],
                got: vec![s.wafers.len(), 5],
            });
        }
        let vals = s
            .wafers
            .iter()
            .flat_map(|w| w.iter().copied())
            .chain(s.offsets.iter().copied())
            .chain(s.base.translation.vector.iter().copied());
        for (i, v) in vals.enumerate() {
            if !v.is_finite() {
                return Err(EstimateError::NonFiniteInput {
                    what: "initial state".into(),
                    index: i,
                    value: v,
                });
            }
        }
        Ok(())
    }

    /// The online sliding-window solve (§5.3, "a standard sliding-window optimization"):
    /// consecutive windows of `window` frames, each solved with the observations of its
    /// frames and a joint Gaussian prior on the calibration and every wafer seen so far
    /// (the previous window's posterior: its estimates and joint marginal covariance, i.e.
    /// marginalisation of the old frames, whose poses are functions of the calibration).
    /// A wafer first seen in a window enters it with the first window's prior widths
    /// (`base_translation` on its centre, `base_rotation` on its tilts) around its current
    /// estimate. Returns the estimate after every window (Fig. 5.11). The conic factor is used.
    pub fn solve_sliding_window(
        &self,
        initial: &SlamMotState,
        window: usize,
        prior_sigmas: &PriorSigmas,
    ) -> Result<Vec<WindowRecord>> {
        self.check_state(initial)?;
        if window == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "window",
                value: 0.0,
                reason: "the window needs at least one frame",
            });
        }
        let mut state = initial.clone();
        // Prior: blocks → (mean, manifold); covariance over their tangents.
        let n_off = self.config.estimate_offsets.len();
        let n_mount = if self.config.estimate_mount { 6 } else { 0 };
        let n_links = self.config.estimate_links.len();
        let n_cal = 6 + n_off + n_mount + n_links;
        let mut prior_cov = DMatrix::<f64>::zeros(n_cal, n_cal);
        let pose_cov = prior_sigmas.pose_covariance();
        prior_cov.view_mut((0, 0), (6, 6)).copy_from(&pose_cov);
        for i in 0..n_off {
            prior_cov[(6 + i, 6 + i)] = prior_sigmas.offset.powi(2);
        }
        if n_mount > 0 {
            prior_cov
                .view_mut((6 + n_off, 6 + n_off), (6, 6))
                .copy_from(&pose_cov);
        }
        for i in 0..n_links {
            let k = 6 + n_off + n_mount + i;
            prior_cov[(k, k)] = prior_sigmas.base_translation.powi(2);
        }
        let mut prior_wafers: Vec<usize> = Vec::new();
        let mut out = Vec::new();
        let n = self.encoders.len();
        let mut start = 0;
        while start < n {
            let end = (start + window).min(n);
            let (mut p, b, n_res) = self.build(&state, start..end, None)?;
            // Wafers that were seen before but not in this window still get their block (prior only).
            let mut wafer_blocks = b.wafers.clone();
            for &k in &prior_wafers {
                if wafer_blocks[k].is_none() {
                    let blk = p.add_block(state.wafers[k].as_slice(), Manifold::Euclidean(5))?;
                    wafer_blocks[k] = Some(blk);
                }
            }
            // A wafer first seen in this window enters with the prior of the uncalibrated
            // setup around its current estimate (centre ±σ_t, tilts ±σ_r, the base's prior
            // widths): a few edge points of one short arc need not fix all five of its
            // parameters, and without it such a window's posterior would not exist.
            for (k, blk) in b.wafers.iter().enumerate() {
                if let Some(blk) = blk
                    && k != self.config.reference_wafer
                    && !prior_wafers.contains(&k)
                {
                    p.add_prior(
                        *blk,
                        state.wafers[k].as_slice(),
                        &prior_sigmas.wafer_covariance(),
                    )?;
                }
            }
            // Joint prior over base, offsets and previously seen wafers.
            let mut blocks = b.calibration();
            let mut means: Vec<Vec<f64>> = vec![se3_to_params(&state.base).to_vec()];
            let mut manifolds = vec![Manifold::Se3];
            for &j in &self.config.estimate_offsets {
                means.push(vec![state.offsets[j]]);
                manifolds.push(Manifold::Euclidean(1));
            }
            if b.mount.is_some() {
                means.push(se3_to_params(&state.mount).to_vec());
                manifolds.push(Manifold::Se3);
            }
            if b.links.is_some() {
                means.push(
                    self.config
                        .estimate_links
                        .iter()
                        .map(|&l| state.links[l])
                        .collect(),
                );
                manifolds.push(Manifold::Euclidean(n_links));
            }
            for &k in &prior_wafers {
                if let Some(blk) = wafer_blocks[k] {
                    blocks.push(blk);
                    means.push(state.wafers[k].as_slice().to_vec());
                    manifolds.push(Manifold::Euclidean(5));
                }
            }
            let l =
                prior_cov
                    .clone()
                    .cholesky()
                    .ok_or_else(|| EstimateError::InvalidCovariance {
                        what: "sliding-window prior".into(),
                        asymmetry: 0.0,
                        min_eigenvalue: prior_cov.symmetric_eigenvalues().min(),
                    })?;
            let l_inv = l
                .l()
                .try_inverse()
                .ok_or_else(|| EstimateError::LinearSolver("prior factor not invertible".into()))?;
            p.add_residual(
                JointPrior {
                    means,
                    manifolds,
                    l_inv,
                },
                &blocks,
                Loss::Trivial,
            )?;
            if n_res > 0 {
                p.solve(&self.options())?;
            }
            let full = Blocks {
                base: b.base,
                offsets: b.offsets.clone(),
                wafers: wafer_blocks.clone(),
                mount: b.mount,
                links: b.links,
                cameras: b.cameras.clone(),
                noise: b.noise.clone(),
            };
            state = self.read_state(&p, &full, &state);
            // Posterior → next prior (all wafers seen so far, the reference excluded: fixed).
            let mut post_blocks = b.calibration();
            let mut seen: Vec<usize> = Vec::new();
            for (k, w) in wafer_blocks.iter().enumerate() {
                if let Some(w) = w
                    && k != self.config.reference_wafer
                {
                    post_blocks.push(*w);
                    seen.push(k);
                }
            }
            let cov = p.marginal_covariance(&post_blocks)?;
            // New wafers enter the prior with their window posterior; keep the ordering.
            prior_cov = cov;
            prior_wafers = seen;
            let std: Vec<f64> = (0..6 + n_off)
                .map(|i| prior_cov[(i, i)].max(0.0).sqrt())
                .collect();
            out.push(WindowRecord {
                last_frame: end - 1,
                state: state.clone(),
                std,
            });
            start = end;
        }
        Ok(out)
    }
}

/// Prior standard deviations of the first sliding window (the uncalibrated robot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PriorSigmas {
    /// Base rotation (rad).
    pub base_rotation: f64,
    /// Base translation (m).
    pub base_translation: f64,
    /// Joint offsets (rad).
    pub offset: f64,
}

impl PriorSigmas {
    /// Diagonal covariance of an SE(3) pose (base or camera mount) with these widths, in the
    /// tangent ordering `[ω; ρ]`: `base_rotation²` ×3, then `base_translation²` ×3.
    pub fn pose_covariance(&self) -> DMatrix<f64> {
        let (r2, t2) = (self.base_rotation.powi(2), self.base_translation.powi(2));
        DMatrix::from_diagonal(&DVector::from_column_slice(&[r2, r2, r2, t2, t2, t2]))
    }

    /// Diagonal covariance of a wafer pose `[centre (3); tilts (2)]` with the base's widths:
    /// `base_translation²` on the centre, `base_rotation²` on the tilts.
    pub fn wafer_covariance(&self) -> DMatrix<f64> {
        let (r2, t2) = (self.base_rotation.powi(2), self.base_translation.powi(2));
        DMatrix::from_diagonal(&DVector::from_column_slice(&[t2, t2, t2, r2, r2]))
    }
}

impl Default for PriorSigmas {
    /// 2°, 20 mm, 2°.
    fn default() -> Self {
        Self {
            base_rotation: 2f64.to_radians(),
            base_translation: 0.02,
            offset: 2f64.to_radians(),
        }
    }
}

/// Theoretical resolution of a wafer pose in one view, eq. (5.14): the RMS over `n` rim points
/// (both rims, visible or not) of the image motion per unit change of each wafer parameter,
/// `‖∂(u, v)/∂p‖` with `(u, v)` the projection `w⁻¹·K·E·T·x̄`. Returns pixels per millimetre
/// for the centre x, y, z and pixels per degree for the tilts rx, ry.
pub fn theoretical_resolution(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    w: &Vector5<f64>,
    geometry: &WaferGeometry,
    n: usize,
) -> Result<[f64; 5]> {
    if n == 0 {
        return Err(EstimateError::InvalidParameter {
            name: "n",
            value: 0.0,
            reason: "at least one rim point",
        });
    }
    let mut acc = [0.0; 5];
    let mut count = 0usize;
    for rim in [Rim::Upper, Rim::Lower] {
        let angles: Vec<f64> = (0..n)
            .map(|i| std::f64::consts::TAU * i as f64 / n as f64)
            .collect();
        let (t_wo, _) = super::wafer::rim_pose(w, rim, geometry.thickness);
        let t_co = t_wc.inverse() * t_wo;
        let pts: Vec<Vector2<f64>> = angles
            .iter()
            .map(|&a| {
                let x =
                    t_co * nalgebra::Point3::from(super::factors::rim_point(geometry.radius, a));
                let p = k * x.coords;
                Vector2::new(p.x / p.z, p.y / p.z)
            })
            .collect();
        let mut r = vec![0.0; 2 * n];
        let mut j = EdgeJacobians {
            camera: DMatrix::zeros(2 * n, 6),
            wafer: DMatrix::zeros(2 * n, 5),
        };
        point_reprojection_residuals(
            k,
            t_wc,
            w,
            rim,
            geometry.radius,
            geometry.thickness,
            &pts,
            &angles,
            1.0,
            &mut r,
            Some(&mut j),
        )?;
        for i in 0..n {
            for (m, a) in acc.iter_mut().enumerate() {
                *a += j.wafer[(2 * i, m)].powi(2) + j.wafer[(2 * i + 1, m)].powi(2);
            }
            count += 1;
        }
    }
    let mut out = [0.0; 5];
    for m in 0..5 {
        let rms = (acc[m] / count as f64).sqrt();
        out[m] = if m < 3 {
            rms * 1e-3
        } else {
            rms * std::f64::consts::PI / 180.0
        };
    }
    Ok(out)
}

/// Exposed for tests and the bindings: evaluates the whitened edge residuals of one
/// observation for a state.
pub fn edge_residuals(
    config: &SlamMotConfig,
    state: &SlamMotState,
    q_enc: &Joints,
    obs: &EdgeObservation,
) -> Result<Vec<f64>> {
    let chain = CameraChain {
        robot: WaferRobot {
            params: config.robot_params,
            base: state.base,
        },
        offsets: state.offsets,
    };
    let t_wc = chain.camera_pose(q_enc);
    let mut r = vec![0.0; obs.points.len()];
    let w = state
        .wafers
        .get(obs.wafer)
        .ok_or(EstimateError::InvalidParameter {
            name: "wafer",
            value: obs.wafer as f64,
            reason: "no such wafer",
        })?;
    conic_edge_residuals(
        &config.k,
        &t_wc,
        w,
        obs.rim,
        config.geometry.radius,
        config.geometry.thickness,
        &obs.points,
        config.pixel_sigma,
        &mut r,
        None,
    )?;
    Ok(r)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use autoteach_geometry::conic::project_circle;
    use nalgebra::{Translation3, UnitQuaternion};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use rand_pcg::Pcg64;

    /// A synthetic session: the default robot in front of a stack of wafers, the camera
    /// sweeping up and down; edge points are the projections of the facing half of each rim
    /// plus Gaussian pixel noise.
    pub(crate) struct Scene {
        pub config: SlamMotConfig,
        pub truth: SlamMotState,
        pub encoders: Vec<Joints>,
        pub observations: Vec<EdgeObservation>,
    }

    pub(crate) fn scene(seed: u64, frames: usize, noise_px: f64) -> Scene {
        let params = RobotParams::default();
        let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0);
        let base = Isometry3::from_parts(
            Translation3::new(-1.0, 0.03, -0.48),
            UnitQuaternion::from_euler_angles(0.0012, -0.0009, 0.026),
        );
        let offsets = Joints::new(0.0, 0.009, 0.0, -0.012, 0.0);
        let robot = WaferRobot { params, base };
        let slots = [0.0, 0.03, 0.06, 0.09, 0.12];
        let wafers: Vec<Vector5<f64>> = slots
            .iter()
            .enumerate()
            .map(|(i, z)| {
                Vector5::new(
                    0.0002 * i as f64,
                    -0.0001 * i as f64,
                    *z,
                    0.0,
                    if i == 4 { 0.0175 } else { 0.0005 * i as f64 },
                )
            })
            .collect();
        let ref_pose = robot.camera_pose(&Joints::zeros());
        let mut rng = Pcg64::seed_from_u64(seed);
        let noise = Normal::new(0.0, noise_px.max(1e-12)).unwrap();
        let mut encoders = Vec::new();
        let mut observations = Vec::new();
        let mut prev: Option<Joints> = None;
        for f in 0..frames {
            let s = f as f64 / (frames.max(2) - 1) as f64;
            let x = -0.52 + 0.1 * (3.0 * s).sin().abs();
            let y = -0.06 + 0.12 * s;
            let z = 0.03 + 0.12 * (0.5 - 0.5 * (std::f64::consts::TAU * s).cos());
            let yaw = 0.06 * (5.0 * s).sin();
            let rot = base.rotation
                * UnitQuaternion::from_euler_angles(0.0, 0.0, yaw - 0.026)
                * base.rotation.inverse()
                * ref_pose.rotation;
            let target = Isometry3::from_parts(Translation3::new(x, y, z), rot);
            let sols = robot.inverse_kinematics_camera(&target, 0.0).unwrap();
            let q = *sols
                .iter()
                .min_by(|a, b| {
                    let da = prev.map_or(if a[1] > 0.0 { 0.0 } else { 1.0 }, |p| (*a - p).norm());
                    let db = prev.map_or(if b[1] > 0.0 { 0.0 } else { 1.0 }, |p| (*b - p).norm());
                    da.total_cmp(&db)
                })
                .unwrap();
            prev = Some(q);
            encoders.push(q + offsets);
            let t_wc = robot.camera_pose(&q);
            for (wi, w) in wafers.iter().enumerate() {
                for rim in [Rim::Upper, Rim::Lower] {
                    let (t_wo, _) = super::super::wafer::rim_pose(w, rim, 0.001);
                    let t_co = t_wc.inverse() * t_wo;
                    let Ok(e) = project_circle(&k, &t_co, 0.15) else {
                        continue;
                    };
                    // Grazing views (the wafer seen nearly edge-on) are left out, as the
                    // pipeline's front end does.
                    if e.b / e.a < 0.05 {
                        continue;
                    }
                    let pts: Vec<Vector2<f64>> = (0..24)
                        .filter_map(|i| {
                            let th = std::f64::consts::PI * (0.55 + 0.9 * i as f64 / 23.0);
                            let xo =
                                t_co * nalgebra::Point3::new(0.15 * th.cos(), 0.15 * th.sin(), 0.0);
                            let p = k * xo.coords;
                            let px = Vector2::new(p.x / p.z, p.y / p.z);
                            (px.x > 0.0 && px.x < 1279.0 && px.y > 0.0 && px.y < 719.0).then(|| {
                                px + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng))
                            })
                        })
                        .collect();
                    if pts.len() >= 6 {
                        observations.push(EdgeObservation {
                            frame: f,
                            wafer: wi,
                            rim,
                            points: pts,
                            sigma_scale: Vec::new(),
                        });
                    }
                }
            }
        }
        let mut config = SlamMotConfig::new(k, params, WaferGeometry::new(0.15, 0.001).unwrap());
        config.pixel_sigma = noise_px.max(0.05);
        Scene {
            config,
            truth: SlamMotState::new(base, offsets, wafers),
            encoders,
            observations,
        }
    }

    fn perturbed(truth: &SlamMotState) -> SlamMotState {
        let mut s = truth.clone();
        s.base = Isometry3::from_parts(
            Translation3::from(truth.base.translation.vector + Vector3::new(0.004, -0.003, 0.002)),
            truth.base.rotation * UnitQuaternion::from_euler_angles(0.004, -0.003, 0.0),
        );
        s.offsets = Joints::zeros();
        for (i, w) in s.wafers.iter_mut().enumerate() {
            if i > 0 {
                w[0] += 0.002;
                w[2] += 0.003;
                w[3] = 0.0;
                w[4] = 0.0;
            }
        }
        s
    }

    #[test]
    fn batch_recovers_the_truth_within_three_sigma() {
        let sc = scene(1, 40, 0.3);
        let slam = SlamMot::new(
            sc.config.clone(),
            sc.encoders.clone(),
            sc.observations.clone(),
            sc.truth.wafers.len(),
        )
        .unwrap();
        let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
        let cov = sol.uncertainty.covariance.clone().expect("observable");
        let d = se3_minus(&sol.state.base, &sc.truth.base);
        for i in 0..6 {
            let sd = cov[(i, i)].sqrt();
            assert!(
                d[i].abs() < 4.0 * sd + 1e-9,
                "base {i}: error {} vs sd {sd}",
                d[i]
            );
        }
        for (i, &j) in sc.config.estimate_offsets.iter().enumerate() {
            let err = sol.state.offsets[j] - sc.truth.offsets[j];
            let sd = cov[(6 + i, 6 + i)].sqrt();
            assert!(
                err.abs() < 4.0 * sd && err.abs() < 2e-4,
                "offset {j}: {err} vs {sd}"
            );
        }
        for (w_est, w_true) in sol.state.wafers.iter().zip(&sc.truth.wafers) {
            assert!(
                (w_est - w_true).fixed_rows::<3>(0).norm() < 3e-4,
                "{w_est} vs {w_true}"
            );
        }
        assert!(sol.rms_px < 0.5 && sol.rms_px > 0.15, "rms {}", sol.rms_px);
    }

    #[test]
    fn uniform_sigma_scale_equals_a_larger_pixel_sigma() {
        let sc = scene(2, 20, 0.3);
        let scaled: Vec<EdgeObservation> = sc
            .observations
            .iter()
            .map(|o| EdgeObservation {
                sigma_scale: vec![2.0; o.points.len()],
                ..o.clone()
            })
            .collect();
        let n = sc.truth.wafers.len();
        let a = SlamMot::new(sc.config.clone(), sc.encoders.clone(), scaled, n).unwrap();
        let mut cfg = sc.config.clone();
        cfg.pixel_sigma *= 2.0;
        let b = SlamMot::new(cfg, sc.encoders.clone(), sc.observations.clone(), n).unwrap();
        let start = perturbed(&sc.truth);
        let (sa, sb) = (
            a.solve_batch(&start).unwrap(),
            b.solve_batch(&start).unwrap(),
        );
        assert!(se3_minus(&sa.state.base, &sb.state.base).norm() < 1e-9);
        let (ca, cb) = (
            sa.uncertainty.covariance.unwrap(),
            sb.uncertainty.covariance.unwrap(),
        );
        assert!((&ca - &cb).norm() <= 1e-6 * cb.norm(), "{ca} vs {cb}");
        // Without the scales the covariance is clearly smaller (not exactly 4×: the yaw-gauge
        // prior is not scaled and the Huber weights change): the scales are used.
        let c = SlamMot::new(
            sc.config.clone(),
            sc.encoders.clone(),
            sc.observations.clone(),
            n,
        )
        .unwrap()
        .solve_batch(&start)
        .unwrap();
        let cc = c.uncertainty.covariance.unwrap();
        let ratio = ca[(3, 3)] / cc[(3, 3)];
        assert!(
            (1.5..=4.0 + 1e-9).contains(&ratio),
            "covariance ratio {ratio}"
        );
    }

    #[test]
    fn per_point_sigma_downweights_the_noisy_points() {
        // Every other point gets 3 px extra noise; telling the solver so (σ factor 10) must
        // give a better estimate than treating all points alike.
        let sc = scene(3, 30, 0.3);
        let mut rng = Pcg64::seed_from_u64(11);
        let noise = Normal::new(0.0, 3.0).unwrap();
        let noisy: Vec<EdgeObservation> = sc
            .observations
            .iter()
            .map(|o| {
                let mut o = o.clone();
                for p in o.points.iter_mut().step_by(2) {
                    *p += Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng));
                }
                o
            })
            .collect();
        let weighted: Vec<EdgeObservation> = noisy
            .iter()
            .map(|o| EdgeObservation {
                sigma_scale: (0..o.points.len())
                    .map(|i| if i % 2 == 0 { 10.0 } else { 1.0 })
                    .collect(),
                ..o.clone()
            })
            .collect();
        let n = sc.truth.wafers.len();
        let err = |obs: Vec<EdgeObservation>| {
            let slam = SlamMot::new(sc.config.clone(), sc.encoders.clone(), obs, n).unwrap();
            let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
            let d: f64 = sol
                .state
                .wafers
                .iter()
                .zip(&sc.truth.wafers)
                .map(|(a, b)| (a - b).fixed_rows::<3>(0).norm_squared())
                .sum();
            (d / n as f64).sqrt() + se3_minus(&sol.state.base, &sc.truth.base).norm()
        };
        let (plain, with_scale) = (err(noisy), err(weighted));
        assert!(
            with_scale < 0.6 * plain,
            "weighted {with_scale} vs plain {plain}"
        );
    }

    #[test]
    fn bad_sigma_scales_are_rejected() {
        let sc = scene(1, 5, 0.3);
        let n = sc.truth.wafers.len();
        let m = sc.observations[0].points.len();
        // Wrong length, NaN, zero, negative.
        for bad in [
            vec![1.0; m + 1],
            vec![f64::NAN; m],
            vec![0.0; m],
            vec![-1.0; m],
        ] {
            let mut obs = sc.observations.clone();
            obs[0].sigma_scale = bad;
            assert!(SlamMot::new(sc.config.clone(), sc.encoders.clone(), obs, n).is_err());
        }
    }

    /// The edge residual of observation `obs` of scene `sc` (σ 0.5 px, identity mount, zero
    /// fixed offsets and link corrections); `extended` adds the joint-noise and mount blocks.
    fn test_edge_residual(
        sc: &Scene,
        obs: &EdgeObservation,
        offset_joints: Vec<usize>,
        extended: bool,
        link_idx: Vec<usize>,
    ) -> EdgeResidual {
        let cfg = &sc.config;
        EdgeResidual {
            k: cfg.k,
            params: cfg.robot_params,
            geometry: cfg.geometry,
            q_enc: sc.encoders[obs.frame],
            fixed_offsets: Joints::zeros(),
            offset_joints,
            rim: obs.rim,
            points: obs.points.clone(),
            sigma: 0.5,
            angles: None,
            joint_noise: extended,
            fixed_mount: Isometry3::identity(),
            mount_block: extended,
            fixed_links: [0.0; 3],
            link_idx,
        }
    }

    #[test]
    fn edge_residual_jacobians_match_finite_differences() {
        use autoteach_geometry::lie::se3_plus;
        let sc = scene(6, 4, 0.3);
        let obs = &sc.observations[3];
        let res = test_edge_residual(&sc, obs, vec![0, 1, 3], false, Vec::new());
        let base = se3_to_params(&sc.truth.base).to_vec();
        let offs = [vec![0.001], vec![0.002], vec![-0.003]];
        let w = sc.truth.wafers[obs.wafer].as_slice().to_vec();
        let eval = |b: &[f64], o: &[Vec<f64>; 3], w: &[f64], jac: Option<&mut [DMatrix<f64>]>| {
            let mut r = vec![0.0; res.dim()];
            res.evaluate(&[b, &o[0], &o[1], &o[2], w], &mut r, jac)
                .unwrap();
            r
        };
        let n = res.dim();
        let mut jac = vec![
            DMatrix::zeros(n, 6),
            DMatrix::zeros(n, 1),
            DMatrix::zeros(n, 1),
            DMatrix::zeros(n, 1),
            DMatrix::zeros(n, 5),
        ];
        let r0 = eval(&base, &offs, &w, Some(&mut jac));
        let h = 1e-7;
        let close = |fd: f64, an: f64, what: &str| {
            assert!(
                (fd - an).abs() < 1e-3 * (1.0 + an.abs()),
                "{what}: {fd} vs {an}"
            )
        };
        for m in 0..6 {
            let mut d = nalgebra::Vector6::zeros();
            d[m] = h;
            let b2 = se3_to_params(&se3_plus(&sc.truth.base, &d)).to_vec();
            let b3 = se3_to_params(&se3_plus(&sc.truth.base, &(-d))).to_vec();
            let r1 = eval(&b2, &offs, &w, None);
            let r2 = eval(&b3, &offs, &w, None);
            for i in 0..n {
                close((r1[i] - r2[i]) / (2.0 * h), jac[0][(i, m)], "base");
            }
        }
        for j in 0..3 {
            let mut o2 = offs.clone();
            o2[j][0] += h;
            let r1 = eval(&base, &o2, &w, None);
            for i in 0..n {
                close((r1[i] - r0[i]) / h, jac[1 + j][(i, 0)], "offset");
            }
        }
    }

    #[test]
    fn mount_and_link_jacobians_match_finite_differences() {
        use autoteach_geometry::lie::se3_plus;
        let sc = scene(6, 4, 0.3);
        let obs = &sc.observations[5];
        let res = test_edge_residual(&sc, obs, vec![1], true, vec![0, 1, 2]);
        let mount = Isometry3::from_parts(
            Translation3::new(0.002, -0.001, 0.003),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 0.005),
        );
        let vals: Vec<Vec<f64>> = vec![
            se3_to_params(&sc.truth.base).to_vec(),
            vec![0.002],
            sc.truth.wafers[obs.wafer].as_slice().to_vec(),
            vec![1e-4, -2e-4, 5e-5, 1e-5],
            se3_to_params(&mount).to_vec(),
            vec![0.001, -0.002, 0.0015],
        ];
        let n = res.dim();
        let eval = |v: &[Vec<f64>], jac: Option<&mut [DMatrix<f64>]>| {
            let p: Vec<&[f64]> = v.iter().map(|x| x.as_slice()).collect();
            let mut r = vec![0.0; n];
            res.evaluate(&p, &mut r, jac).unwrap();
            r
        };
        let dims = [6usize, 1, 5, 4, 6, 3];
        let mut jac: Vec<DMatrix<f64>> = dims.iter().map(|&d| DMatrix::zeros(n, d)).collect();
        eval(&vals, Some(&mut jac));
        let h = 1e-7;
        for (blk, &dim) in dims.iter().enumerate() {
            for c in 0..dim {
                let (mut up, mut dn) = (vals.clone(), vals.clone());
                if blk == 0 || blk == 4 {
                    let mut d = nalgebra::Vector6::zeros();
                    d[c] = h;
                    let x = se3_from_params(&vals[blk]);
                    up[blk] = se3_to_params(&se3_plus(&x, &d)).to_vec();
                    dn[blk] = se3_to_params(&se3_plus(&x, &(-d))).to_vec();
                } else {
                    up[blk][c] += h;
                    dn[blk][c] -= h;
                }
                let (r1, r2) = (eval(&up, None), eval(&dn, None));
                for (i, (a, b)) in r1.iter().zip(&r2).enumerate() {
                    let fd = (a - b) / (2.0 * h);
                    let an = jac[blk][(i, c)];
                    assert!(
                        (fd - an).abs() < 1e-3 * (1.0 + an.abs()),
                        "block {blk} col {c} row {i}: {fd} vs {an}"
                    );
                }
            }
        }
    }

    /// Solves a 20-frame scene with `edit` applied to its configuration, asserts that no
    /// covariance is reported and that the unobservable message names one of `names`.
    fn assert_reported_unobservable(edit: impl FnOnce(&mut SlamMotConfig), names: [&str; 2]) {
        let sc = scene(2, 20, 0.3);
        let mut cfg = sc.config.clone();
        edit(&mut cfg);
        let slam = SlamMot::new(
            cfg,
            sc.encoders.clone(),
            sc.observations.clone(),
            sc.truth.wafers.len(),
        )
        .unwrap();
        let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
        assert!(sol.uncertainty.covariance.is_none());
        let msg = sol.uncertainty.unobservable.unwrap();
        assert!(names.iter().any(|n| msg.contains(n)), "{msg}");
    }

    #[test]
    fn mount_with_a_free_base_is_reported_unobservable() {
        // All joint axes are vertical: a mount correction and the base pose trade off, so the
        // session cannot constrain T_ec together with T_wb.
        assert_reported_unobservable(|c| c.estimate_mount = true, ["camera mount", "base pose"]);
    }

    #[test]
    fn link_lengths_are_recovered_within_three_sigma() {
        // The elbow and blade-2 lengths change the camera path as the joints move: observable.
        let sc = scene(4, 40, 0.3);
        let mut cfg = sc.config.clone();
        cfg.estimate_links = vec![1, 2];
        let truth_links = [0.0, 0.0015, -0.001];
        let mut scene_cfg = sc.config.clone();
        scene_cfg.robot_params.l2 -= truth_links[1];
        scene_cfg.robot_params.l4 -= truth_links[2];
        cfg.robot_params = scene_cfg.robot_params;
        let slam = SlamMot::new(
            cfg,
            sc.encoders.clone(),
            sc.observations.clone(),
            sc.truth.wafers.len(),
        )
        .unwrap();
        let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
        let cov = sol.uncertainty.covariance.clone().expect("observable");
        let n = cov.nrows();
        for (k, l) in [1usize, 2].iter().enumerate() {
            let err = sol.state.links[*l] - truth_links[*l];
            let sd = cov[(n - 2 + k, n - 2 + k)].sqrt();
            assert!(err.abs() < 4.0 * sd && sd < 1e-3, "link {l}: {err} vs {sd}");
        }
    }

    #[test]
    fn free_camera_mode_recovers_offsets_and_wafers_with_the_motion_factor() {
        let sc = scene(1, 40, 0.3);
        let mut cfg = sc.config.clone();
        cfg.free_camera = Some(FreeCamera {
            motion_sigma: [2e-5, 2e-5, 2e-5, 2e-5, 2e-5, 2e-5],
            odometry: Vec::new(),
            odometry_sigma: [1.0; 6],
            calibration_prior: Some((
                perturbed(&sc.truth).base,
                Joints::zeros(),
                PriorSigmas::default(),
            )),
        });
        let slam = SlamMot::new(
            cfg,
            sc.encoders.clone(),
            sc.observations.clone(),
            sc.truth.wafers.len(),
        )
        .unwrap();
        let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
        // The elbow offset is fixed by the relative motions; every estimate lies within 3σ of
        // the truth (the θ4 offset is only weakly constrained by relative motion: its σ stays
        // close to the prior's, and that is what the covariance reports).
        let cov = sol
            .uncertainty
            .covariance
            .clone()
            .expect("the prior makes it observable");
        for (i, &j) in sc.config.estimate_offsets.iter().enumerate() {
            let err = sol.state.offsets[j] - sc.truth.offsets[j];
            let sd = cov[(6 + i, 6 + i)].sqrt();
            assert!(err.abs() < 3.0 * sd, "offset {j}: {err} vs {sd}");
        }
        let err2 = sol.state.offsets[1] - sc.truth.offsets[1];
        assert!(err2.abs() < 5e-4, "elbow offset {err2}");
        for (w_est, w_true) in sol.state.wafers.iter().zip(&sc.truth.wafers) {
            assert!(
                (w_est - w_true).fixed_rows::<3>(0).norm() < 5e-4,
                "{w_est} vs {w_true}"
            );
        }
        // The free poses follow the true camera path.
        let robot = WaferRobot {
            params: sc.config.robot_params,
            base: sc.truth.base,
        };
        for (f, q) in sc.encoders.iter().enumerate() {
            let truth = robot.camera_pose(&(q - sc.truth.offsets));
            let d = se3_minus(&sol.camera_poses[f], &truth);
            assert!(d.norm() < 2e-3, "frame {f}: {d}");
        }
        // Sliding windows of 5 frames use the same factors.
        let hist = slam
            .solve_sliding_window(&perturbed(&sc.truth), 5, &PriorSigmas::default())
            .unwrap();
        assert_eq!(hist.len(), 8);
        let last = &hist[hist.len() - 1].state;
        // The windows gain information on the elbow offset (σ below half the 2° prior; short
        // windows of relative motions carry little of it) and
        // their estimate lies within 3σ of the truth.
        let sd = hist[hist.len() - 1].std[7];
        let err = last.offsets[1] - sc.truth.offsets[1];
        assert!(sd < 0.5 * PriorSigmas::default().offset, "window σ {sd}");
        assert!(
            err.abs() < 3.0 * sd,
            "window elbow offset error {err} vs σ {sd}"
        );
    }

    #[test]
    fn free_camera_rejects_chain_only_options() {
        let sc = scene(1, 4, 0.3);
        let mut cfg = sc.config.clone();
        cfg.free_camera = Some(FreeCamera {
            motion_sigma: [1e-4; 6],
            odometry: Vec::new(),
            odometry_sigma: [1.0; 6],
            calibration_prior: None,
        });
        cfg.estimate_mount = true;
        assert!(SlamMot::new(cfg, sc.encoders.clone(), sc.observations.clone(), 5).is_err());
    }

    #[test]
    fn lift_offset_with_free_base_is_reported_unobservable() {
        assert_reported_unobservable(
            |c| c.estimate_offsets = vec![1, 3, 4],
            ["lift zero offset", "base pose"],
        );
    }

    #[test]
    fn a_wafer_barely_seen_in_one_window_does_not_break_the_sliding_window() {
        // Wafer 2 is seen only once, by three edge points (fewer than its five parameters):
        // its window cannot fix it from the data, the entry prior keeps the window's
        // posterior defined, and the batch reports the wafer as unobservable.
        let sc = scene(1, 20, 0.3);
        let mut obs: Vec<EdgeObservation> = sc
            .observations
            .iter()
            .filter(|o| o.wafer != 2)
            .cloned()
            .collect();
        let mut one = sc
            .observations
            .iter()
            .find(|o| o.wafer == 2 && o.frame == 12)
            .cloned()
            .expect("wafer 2 is seen in frame 12");
        one.points.truncate(3);
        obs.push(one);
        let slam = SlamMot::new(sc.config.clone(), sc.encoders.clone(), obs, 5).unwrap();
        let start = perturbed(&sc.truth);
        let hist = slam
            .solve_sliding_window(&start, 5, &PriorSigmas::default())
            .expect("the entry prior keeps every window's posterior defined");
        assert_eq!(hist.len(), 4);
        for h in &hist {
            assert!(h.std.iter().all(|v| v.is_finite() && *v > 0.0));
        }
        // The window moved wafer 2 by no more than a few prior widths.
        let moved = (hist[3].state.wafers[2] - start.wafers[2]).abs();
        assert!(moved.fixed_rows::<3>(0).max() < 0.06, "{moved}");
        let sol = slam.solve_batch(&hist[3].state).unwrap();
        assert!(sol.uncertainty.covariance.is_none());
        assert!(sol.uncertainty.unobservable.is_some());
    }

    #[test]
    fn sliding_window_converges_toward_the_batch() {
        let sc = scene(3, 40, 0.3);
        let slam = SlamMot::new(
            sc.config.clone(),
            sc.encoders.clone(),
            sc.observations.clone(),
            sc.truth.wafers.len(),
        )
        .unwrap();
        // Start from a nominal installation: base within a few millimetres, offsets zero.
        let mut init = sc.truth.clone();
        init.base = Isometry3::from_parts(
            Translation3::from(
                sc.truth.base.translation.vector + Vector3::new(0.002, -0.0015, 0.001),
            ),
            sc.truth.base.rotation * UnitQuaternion::from_euler_angles(0.0008, -0.0006, 0.0),
        );
        init.offsets = Joints::zeros();
        for w in init.wafers.iter_mut().skip(1) {
            w[3] = 0.0;
            w[4] = 0.0;
        }
        let hist = slam
            .solve_sliding_window(&init, 5, &PriorSigmas::default())
            .unwrap();
        assert_eq!(hist.len(), 8);
        let last = &hist.last().unwrap().state;
        let err0 = se3_minus(&init.base, &sc.truth.base)
            .fixed_rows::<3>(3)
            .norm();
        let err1 = se3_minus(&last.base, &sc.truth.base)
            .fixed_rows::<3>(3)
            .norm();
        eprintln!("sliding window: base translation error {err0} -> {err1}");
        assert!(err1 < 0.2 * err0, "{err1} vs {err0}");
        assert!(hist.last().unwrap().std[3] < hist[0].std[3]);
    }

    #[test]
    fn no_observations_is_a_clear_error() {
        let sc = scene(4, 5, 0.3);
        let err = SlamMot::new(sc.config.clone(), sc.encoders.clone(), vec![], 5).unwrap_err();
        assert!(err.to_string().contains("no wafer edge"), "{err}");
    }

    #[test]
    fn resolution_grows_when_the_camera_is_closer() {
        let sc = scene(5, 3, 0.3);
        let g = sc.config.geometry;
        let w = sc.truth.wafers[1];
        let far = Isometry3::from_parts(
            Translation3::new(-0.6, 0.0, 0.06),
            UnitQuaternion::from_matrix(&Matrix3::new(
                0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
            )),
        );
        let mut near = far;
        near.translation.vector.x = -0.45;
        let rf = theoretical_resolution(&sc.config.k, &far, &w, &g, 90).unwrap();
        let rn = theoretical_resolution(&sc.config.k, &near, &w, &g, 90).unwrap();
        for m in 0..5 {
            assert!(rn[m] > rf[m], "{m}: {rn:?} vs {rf:?}");
        }
        // Lateral motion of 1 mm at ~0.6 m with f = 1000 px: ≈ 1000/600 px.
        assert!((rf[1] - 1000.0 / 600.0).abs() < 0.4, "{rf:?}");
    }
}
