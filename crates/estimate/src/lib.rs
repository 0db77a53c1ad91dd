//! # autoteach-estimate
//!
//! Estimation engines of autoteach (seed 000_3b1454b2b2194811.txt ch. 5). So far: the
//! unscented Kalman filter ([`ukf`]: Merwe sigma points, standard and square-root forms,
//! additive and augmented noise, manifold states, a batch runner). Sparse nonlinear least
//! squares, factor graphs, calibration and experimental design follow.
//!
//! ```
//! use autoteach_estimate::ukf::{LinearModel, MerweScaledSigmaPoints, SigmaPointFilter, UnscentedKalmanFilter};
//! use nalgebra::{DMatrix, DVector};
//!
//! // A random walk observed directly: one update moves the estimate toward the measurement.
//! let model = LinearModel::new(DMatrix::identity(1, 1), DMatrix::identity(1, 1), None)?;
//! let mut ukf = UnscentedKalmanFilter::new(model, MerweScaledSigmaPoints::new(1, 0.1, 2.0, 0.0)?)?;
//! ukf.set_r(DMatrix::identity(1, 1))?;
//! ukf.predict(1.0, None)?;
//! ukf.update(&DVector::from_element(1, 2.0), None)?;
//! assert!(ukf.x()[0] > 0.5 && ukf.x()[0] < 2.0);
//! # Ok::<(), autoteach_estimate::EstimateError>(())
//! ```
#![deny(missing_docs)]

pub mod active;
pub mod calib;
pub mod control;
pub mod error;
pub mod handeye;
pub mod lsq;
pub mod mapping;
pub mod radio;
pub mod ukf;

pub use error::EstimateError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, EstimateError>;
pub mod lidar_camera;
/// Time-optimal B-spline trajectories of the wafer robot (issue 30).
pub mod plan;
