//! The unscented Kalman filter (seed 000_3b1454b2b2194811.txt §5.2).
//!
//! * [`MerweScaledSigmaPoints`]: van der Merwe's scaled sigma points, weights as filterpy.
//! * [`JulierSigmaPoints`], [`SimplexSigmaPoints`]: filterpy's other two families; [`SigmaPoints`]
//!   holds any of them (or [`GivenWeights`] of points a model draws itself).
//! * [`rts_smoother`]: the unscented Rauch–Tung–Striebel smoother of a filtered run.
//! * [`UkfModel`]: the process/measurement model with ⊕/⊖ hooks for angle and SO(3) parts.
//! * [`UnscentedKalmanFilter`]: the covariance-form filter (additive or augmented noise).
//! * [`SquareRootUkf`]: the square-root form (van der Merwe & Wan 2001).
//! * [`SigmaPointFilter`]: their common interface, with the batch runner
//!   [`SigmaPointFilter::batch`].
//! * Built-in models: [`LinearModel`] and [`ConstantVelocityModel`].
//!
//! # Example
//!
//! ```
//! use autoteach_estimate::ukf::{
//!     BatchInputs, ConstantVelocityModel, MerweScaledSigmaPoints, SigmaPointFilter,
//!     UnscentedKalmanFilter,
//! };
//! use nalgebra::{DMatrix, DVector};
//!
//! // A 1-D constant-velocity target measured in position.
//! let model = ConstantVelocityModel::new(1)?;
//! let points = MerweScaledSigmaPoints::new(2, 0.5, 2.0, 1.0)?;
//! let mut ukf = UnscentedKalmanFilter::new(model, points)?;
//! ukf.set_p(DMatrix::identity(2, 2) * 10.0)?;
//! ukf.set_q(DMatrix::identity(2, 2) * 1e-4)?;
//! ukf.set_r(DMatrix::identity(1, 1) * 0.01)?;
//! let zs: Vec<_> = (0..50).map(|k| Some(DVector::from_element(1, 0.5 * k as f64))).collect();
//! let out = ukf.batch(&BatchInputs::new(1.0, &zs))?;
//! assert!((out.x(49).unwrap()[1] - 0.5).abs() < 1e-3); // the velocity
//! # Ok::<(), autoteach_estimate::EstimateError>(())
//! ```

mod family;
mod filter;
mod julier;
mod kernels;
mod linalg;
mod model;
mod models;
mod points;
mod simplex;
mod smoother;
mod sqrt;
mod standard;
mod transform;

pub use family::{GivenWeights, SigmaPoints};
pub use filter::{BatchInputs, BatchResult, FlatBatch, NoiseForm, SigmaPointFilter};
pub use julier::JulierSigmaPoints;
pub use linalg::CovariancePolicy;
pub use model::UkfModel;
pub use models::{ConstantVelocityModel, LinearModel};
pub use points::MerweScaledSigmaPoints;
pub use simplex::SimplexSigmaPoints;
pub use smoother::{RtsResult, rts_smoother};
pub use sqrt::SquareRootUkf;
pub use standard::UnscentedKalmanFilter;

#[cfg(test)]
mod fixtures;
#[cfg(test)]
mod tests;
