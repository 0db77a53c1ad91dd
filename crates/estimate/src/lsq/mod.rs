//! Sparse nonlinear least squares on manifolds (seed 000_3b1454b2b2194811.txt ch. 5.3, the
//! SLAM-MOT factor graph; seed 004_815695db12a6b16c.txt ch. 3 and ch. 5, eq. (5.1)–(5.5),
//! calibration by Levenberg–Marquardt).
//!
//! A [`Problem`] holds parameter blocks on [`Manifold`]s and residual blocks (anything
//! implementing [`Residual`], with analytic Jacobians on the tangent space, or wrapped in
//! [`NumericDiff`]) with robust [`Loss`]es. [`Problem::solve`] runs Levenberg–Marquardt or
//! Gauss–Newton on the normal equations, assembled by block structure and solved by a dense
//! or sparse (faer) Cholesky factorisation, optionally eliminating point-like blocks first
//! (Schur complement). [`Problem::marginal_covariance`] returns covariances of chosen blocks
//! or names the unconstrained directions.
//!
//! ```
//! use autoteach_estimate::lsq::{Loss, Manifold, Problem, Residual, SolverOptions};
//! use nalgebra::DMatrix;
//!
//! /// r = x − target (2-D).
//! struct Anchor([f64; 2]);
//! impl Residual for Anchor {
//!     fn dim(&self) -> usize { 2 }
//!     fn evaluate(&self, p: &[&[f64]], r: &mut [f64], j: Option<&mut [DMatrix<f64>]>)
//!         -> Result<(), autoteach_estimate::EstimateError> {
//!         r[0] = p[0][0] - self.0[0];
//!         r[1] = p[0][1] - self.0[1];
//!         if let Some(j) = j { j[0].fill_with_identity(); }
//!         Ok(())
//!     }
//! }
//! let mut problem = Problem::new();
//! let x = problem.add_block(&[0.0, 0.0], Manifold::Euclidean(2))?;
//! problem.add_residual(Anchor([1.0, 2.0]), &[x], Loss::Trivial)?;
//! problem.add_residual(Anchor([3.0, 2.0]), &[x], Loss::Trivial)?;
//! let summary = problem.solve(&SolverOptions::default())?;
//! assert!((problem.values(x)[0] - 2.0).abs() < 1e-6 && summary.final_cost < 1.0 + 1e-9);
//! let cov = problem.marginal_covariance(&[x])?; // (JᵀJ)⁻¹ = I/2
//! assert!((cov[(0, 0)] - 0.5).abs() < 1e-12);
//! # Ok::<(), autoteach_estimate::EstimateError>(())
//! ```

mod bundle;
mod covariance;
mod evals;
mod layout;
mod linear;
mod loss;
mod manifold;
mod numeric;
mod problem;
mod residuals;
mod schur;
pub mod se2;
mod solver;
pub mod synthetic;
#[cfg(test)]
mod tests;

pub use bundle::{BundleResult, bundle_adjust};
pub use covariance::RANK_TOLERANCE;
pub use loss::Loss;
pub use manifold::{
    Manifold, quat_from_params, se3_from_params, se3_to_params, so3_from_params, so3_to_params,
};
pub use numeric::NumericDiff;
pub use problem::{BlockId, PriorResidual, Problem, Residual, ResidualId};
pub use residuals::{Intrinsics, PointToConicResidual, RelativePoseResidual, ReprojectionResidual};
pub use se2::Se2BetweenResidual;
pub use solver::{LinearSolver, Method, SolverOptions, Summary, Termination};
