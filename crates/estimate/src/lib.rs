//! # autoteach-estimate
//!
//! Estimation engines of autoteach: the unscented Kalman filter, and later sparse nonlinear
//! least squares, factor graphs, calibration and experimental design.
#![deny(missing_docs)]

pub mod error;
pub mod ukf;

pub use error::EstimateError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, EstimateError>;
