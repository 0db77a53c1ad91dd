//! Hand-eye auto-teaching (000_3b1454b2b2194811.txt ch. 5): the UKF fusion of visual odometry
//! and encoders (§5.2, eqs. (5.1)–(5.2)) and the visual-inertial SLAM-MOT calibration (§5.3,
//! eqs. (5.3)–(5.13)) with the theoretical resolution of eq. (5.14).
//!
//! # Parameters and what the data can tell
//!
//! The camera sits on blade 2, so its pose `T_wc = T_wb·T_be2(q)·T_e2c` (eq. (5.9)) depends on
//! θ1, θ2, θ4 and the lift `h`, never on θ3: the θ3 zero offset is unobservable. All revolute
//! axes are vertical and the shoulder axis passes through the base origin, so a θ1 zero offset
//! is exactly a yaw of `T_wb` (`T_wb·Rz(q1 − δ1) = (T_wb·Rz(−δ1))·Rz(q1)`), and a lift offset
//! is exactly a z shift of `T_wb`. Wafers are circles, so the world yaw about the reference
//! wafer's normal is a gauge freedom. SLAM-MOT therefore estimates the *effective* base pose
//! `T_wb·Rz(−δ1)·Tz(−δh)` (with its yaw held by a gauge prior), the offsets of θ2 and θ4 and
//! the wafers; asking for more is reported as unobservable by the covariance computation.
//! The UKF, whose visual-odometry translation increments are expressed in the (known) world
//! frame, observes δ1 as well.

pub mod chain;
pub mod factors;
pub mod gating;
pub mod motion;
pub mod run;
pub mod ukf_model;
pub mod wafer;

pub use chain::{CameraChain, ChainEval, JOINT_NAMES, N_JOINTS};
pub use factors::{
    EdgeJacobians, conic_edge_residuals, nearest_model_angles, point_reprojection_residuals,
};
pub use gating::{DetectedEdges, GateConfig, GateStats, Gated, gate_edges};
pub use motion::{FreeCameraEdgeResidual, RobotMotionResidual};
pub use ukf_model::{
    AutoTeachUkfModel, UKF_MEASURED_JOINTS, UKF_OFFSET_JOINTS, UkfNoise, UkfRun, run_autoteach_ukf,
};
pub use wafer::{Rim, WAFER_DIM, WaferGeometry, rim_pose, wafer_from_center_normal, wafer_normal};
pub mod slam;
pub use slam::{
    BasinSearch, EdgeFactor, EdgeObservation, FreeCamera, LINK_NAMES, PriorSigmas, SlamMot,
    SlamMotConfig, SlamMotSolution, SlamMotState, Uncertainty, WindowRecord, edge_residuals,
    theoretical_resolution,
};
