//! Camera–lidar extrinsic calibration from point–pixel correspondences (seed
//! 004_815695db12a6b16c.txt ch. 4.1, eq. (4.2)): minimise the squared projection error
//! `e = Σ_j |p_j − d(K E T_j r_j)|²` over the extrinsics `E = T_cam_lidar` with the intrinsics
//! and distortion `d(K ·)` of an already calibrated camera (ch. 5), by Levenberg–Marquardt on
//! the project's solver ([`crate::lsq`]) instead of the seed's compass search, which gives the
//! covariance of the estimate as well.
//!
//! The seed varies intrinsics, extrinsics and distortion together (16 parameters) from one
//! scene's hand-picked corners; here the camera comes calibrated (its uncertainty is ch. 5's
//! business) and the six extrinsic parameters are estimated, so a handful of corners suffices.
//!
//! ```
//! use autoteach_estimate::lidar_camera::calibrate_extrinsics;
//! use autoteach_geometry::camera::Camera;
//! use nalgebra::{Isometry3, Point3, Vector3};
//! let cam = Camera::pinhole(500.0, 500.0, 320.0, 240.0, 640, 480)?;
//! let truth = Isometry3::new(Vector3::new(0.1, -0.05, 0.02), Vector3::new(-1.2, 0.1, -1.2));
//! let pts: Vec<[f64; 3]> = (0..12)
//!     .map(|k| [2.0 + 0.1 * k as f64, -0.6 + 0.11 * (k % 5) as f64, -0.4 + 0.07 * (k % 7) as f64])
//!     .collect();
//! let pix: Vec<[f64; 2]> = pts
//!     .iter()
//!     .map(|p| {
//!         let px = cam.project(&(truth * Point3::from(*p)).coords).unwrap();
//!         [px.x, px.y]
//!     })
//!     .collect();
//! let start = Isometry3::new(Vector3::new(0.0, 0.0, 0.0), Vector3::new(-1.15, 0.12, -1.25));
//! let fit = calibrate_extrinsics(&cam, &pts, &pix, &start, Some(0.5))?;
//! assert!((fit.t_cam_lidar.translation.vector - truth.translation.vector).norm() < 1e-6);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::sync::Arc;

use autoteach_geometry::camera::Camera;
use autoteach_geometry::lie::hat;
use nalgebra::{DMatrix, Isometry3, Matrix6, Vector3};

use crate::lsq::{
    Loss, Manifold, Problem, Residual, SolverOptions, se3_from_params, se3_to_params,
};
use crate::{EstimateError, Result};

/// Fewest correspondences accepted: six unknowns, two equations each, plus redundancy to
/// estimate the noise.
pub const MIN_CORRESPONDENCES: usize = 4;

/// Whitened projection error of one lidar point `x` observed at pixel `observed`:
/// `r = (d(K (R x + t)) − p) / σ` over the SE(3) block `T_cam_lidar = (R, t)`.
///
/// Jacobian with the right perturbation `T·Exp([ω; ρ])`: `∂X_c/∂ω = −R [x]×`, `∂X_c/∂ρ = R`,
/// chained with the camera's analytic `∂pixel/∂X_c`.
struct ProjectionResidual {
    camera: Arc<Camera>,
    point: Vector3<f64>,
    observed: [f64; 2],
    inv_sigma: f64,
}

impl Residual for ProjectionResidual {
    fn dim(&self) -> usize {
        2
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let Some(pose) = params.first() else {
            return Err(EstimateError::InvalidProblem(
                "the extrinsic residual needs the T_cam_lidar block".into(),
            ));
        };
        let t = se3_from_params(pose);
        let r = t.rotation.to_rotation_matrix().into_inner();
        let pc = r * self.point + t.translation.vector;
        let (px, j_point, _) = self.camera.project_jacobians(&pc)?;
        residual[0] = (px.x - self.observed[0]) * self.inv_sigma;
        residual[1] = (px.y - self.observed[1]) * self.inv_sigma;
        if let Some(jac) = jacobians
            && let Some(j) = jac.first_mut()
        {
            let jw = -(j_point * r * hat(&self.point)) * self.inv_sigma;
            let jr = (j_point * r) * self.inv_sigma;
            for c in 0..3 {
                for row in 0..2 {
                    j[(row, c)] = jw[(row, c)];
                    j[(row, c + 3)] = jr[(row, c)];
                }
            }
        }
        Ok(())
    }
}

/// The result of [`calibrate_extrinsics`].
#[derive(Debug, Clone, PartialEq)]
pub struct ExtrinsicsFit {
    /// Lidar → camera.
    pub t_cam_lidar: Isometry3<f64>,
    /// Covariance of the estimate on the tangent `[ω; ρ]` (radians, metres) of the right
    /// perturbation `T̂·Exp(δ)`.
    pub covariance: Matrix6<f64>,
    /// Pixel noise used for the covariance: the given σ, or the residual estimate
    /// `√(Σ|e_j|² / (2N − 6))`.
    pub sigma: f64,
    /// RMS reprojection error (pixels).
    pub rms: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// Whether the solver met a convergence criterion.
    pub converged: bool,
}

/// Estimates `T_cam_lidar` from lidar points `points` (lidar frame) and the pixels `pixels`
/// where the camera sees them, starting from `initial`, eq. (4.2). With `sigma` (pixels) the
/// covariance is `(JᵀJ)⁻¹` of the whitened problem; without, σ is estimated from the
/// residuals.
///
/// Errors: `DimensionMismatch` for unequal lengths; `TooFewPoints` for fewer than
/// [`MIN_CORRESPONDENCES`]; `NonFiniteInput`; `InvalidParameter` for a bad σ; a point behind
/// the camera at the start is a geometry error; `RankDeficient` when the correspondences do not
/// determine the pose (e.g. all on one line).
pub fn calibrate_extrinsics(
    camera: &Camera,
    points: &[[f64; 3]],
    pixels: &[[f64; 2]],
    initial: &Isometry3<f64>,
    sigma: Option<f64>,
) -> Result<ExtrinsicsFit> {
    if points.len() != pixels.len() {
        return Err(EstimateError::DimensionMismatch {
            what: "pixels (one per point)".into(),
            expected: vec![points.len(), 2],
            got: vec![pixels.len(), 2],
        });
    }
    if points.len() < MIN_CORRESPONDENCES {
        return Err(EstimateError::TooFewPoints {
            view: 0,
            got: points.len(),
            needed: MIN_CORRESPONDENCES,
        });
    }
    for (what, flat) in [
        (
            "points",
            points.iter().flatten().copied().collect::<Vec<_>>(),
        ),
        (
            "pixels",
            pixels.iter().flatten().copied().collect::<Vec<_>>(),
        ),
    ] {
        if let Some((index, &value)) = flat.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: what.into(),
                index,
                value,
            });
        }
    }
    if let Some(s) = sigma
        && !(s.is_finite() && s > 0.0)
    {
        return Err(EstimateError::InvalidParameter {
            name: "sigma",
            value: s,
            reason: "the pixel noise must be positive and finite",
        });
    }
    let s = sigma.unwrap_or(1.0);
    let camera = Arc::new(camera.clone());
    let mut problem = Problem::new();
    let block = problem.add_block(&se3_to_params(initial), Manifold::Se3)?;
    for (p, px) in points.iter().zip(pixels) {
        problem.add_residual(
            ProjectionResidual {
                camera: Arc::clone(&camera),
                point: Vector3::new(p[0], p[1], p[2]),
                observed: *px,
                inv_sigma: 1.0 / s,
            },
            &[block],
            Loss::Trivial,
        )?;
    }
    let options = SolverOptions {
        max_iterations: 100,
        ..SolverOptions::default()
    };
    let summary = problem.solve(&options)?;
    let cov = problem.marginal_covariance(&[block])?;
    let n = points.len() as f64;
    // final_cost = ½ Σ |r|² of the whitened residuals.
    let sum_sq = 2.0 * summary.final_cost * s * s;
    let rms = (sum_sq / n).sqrt();
    let (sigma_used, scale) = match sigma {
        Some(g) => (g, 1.0),
        None => {
            let var = sum_sq / (2.0 * n - 6.0);
            (var.sqrt(), var)
        }
    };
    let mut covariance = Matrix6::zeros();
    for r in 0..6 {
        for c in 0..6 {
            covariance[(r, c)] = cov[(r, c)] * scale;
        }
    }
    Ok(ExtrinsicsFit {
        t_cam_lidar: se3_from_params(problem.values(block)),
        covariance,
        sigma: sigma_used,
        rms,
        iterations: summary.iterations,
        converged: summary.termination.converged(),
    })
}
