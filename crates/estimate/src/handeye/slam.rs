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
mod residuals;
mod resolution;
mod solve;
pub use basins::BasinSearch;
use residuals::{EdgeResidual, JointPrior, RowScaled, YawGauge};
pub use resolution::{PriorSigmas, edge_residuals, theoretical_resolution};

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
}

#[cfg(test)]
pub(crate) mod tests;
