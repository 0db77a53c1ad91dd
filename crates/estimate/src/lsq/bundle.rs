//! Bundle adjustment from arrays: the entry point behind `autoteach.estimate.bundle_adjust`
//! (pinhole reprojection residuals, seed 004_815695db12a6b16c.txt eq. (5.1); the joint
//! camera/landmark refinement of seed 000_3b1454b2b2194811.txt ch. 5.3).

use autoteach_geometry::lie::{isometry_from_rotvec_translation, rotvec_translation};
use nalgebra::Matrix3;

use super::loss::Loss;
use super::manifold::{Manifold, se3_from_params, se3_to_params};
use super::problem::{BlockId, Problem};
use super::residuals::ReprojectionResidual;
use super::solver::{SolverOptions, Summary};
use crate::{EstimateError, Result};

/// Optimised bundle-adjustment values.
#[derive(Debug, Clone)]
pub struct BundleResult {
    /// World-to-camera poses as `[rx, ry, rz, tx, ty, tz]` (rotation vector, translation).
    pub poses: Vec<[f64; 6]>,
    /// World points.
    pub points: Vec<[f64; 3]>,
    /// Solver summary (final cost ½ Σ ρ(‖r‖²) with r in pixels).
    pub summary: Summary,
}

/// Bundle adjustment: minimises ½ Σ ρ(‖π(K (R_i X_j + t_i)) − z_ij‖²) over the poses
/// `poses[i] = [rotation vector, translation]` (world-to-camera) and the points `X_j`, the
/// observation k being pixel `observations[k]` of point `point_index[k]` in camera
/// `pose_index[k]`. Poses listed in `fixed_poses` are held (fix at least the first pose and
/// the scale, or add priors, to remove the gauge freedom; LM converges either way).
///
/// The poses live on SE(3) (⊕ = right perturbation); the returned rotation vectors are the
/// principal logarithms. Errors: mismatched lengths, indices out of range, non-finite values,
/// a point behind a camera at the start.
#[allow(clippy::too_many_arguments)]
pub fn bundle_adjust(
    k: &Matrix3<f64>,
    poses: &[[f64; 6]],
    points: &[[f64; 3]],
    observations: &[[f64; 2]],
    pose_index: &[usize],
    point_index: &[usize],
    loss: Loss,
    fixed_poses: &[usize],
    options: &SolverOptions,
) -> Result<BundleResult> {
    let n_obs = observations.len();
    for (what, len) in [
        ("pose_index", pose_index.len()),
        ("point_index", point_index.len()),
    ] {
        if len != n_obs {
            return Err(EstimateError::DimensionMismatch {
                what: what.into(),
                expected: vec![n_obs],
                got: vec![len],
            });
        }
    }
    let check_index = |what: &str, idx: &[usize], n: usize| -> Result<()> {
        match idx.iter().enumerate().find(|(_, i)| **i >= n) {
            Some((k, i)) => Err(EstimateError::InvalidProblem(format!(
                "{what}[{k}] = {i} is out of range: it must be in [0, {n})"
            ))),
            None => Ok(()),
        }
    };
    check_index("pose_index", pose_index, poses.len())?;
    check_index("point_index", point_index, points.len())?;
    check_index("fixed_poses", fixed_poses, poses.len())?;
    let mut p = Problem::new();
    let pose_ids = poses
        .iter()
        .map(|x| {
            p.add_block(
                &se3_to_params(&isometry_from_rotvec_translation(x)),
                Manifold::Se3,
            )
        })
        .collect::<Result<Vec<BlockId>>>()?;
    let point_ids = points
        .iter()
        .map(|x| p.add_block(x, Manifold::Euclidean(3)))
        .collect::<Result<Vec<BlockId>>>()?;
    for k_obs in 0..n_obs {
        let r = ReprojectionResidual::new(k, observations[k_obs], 1.0)?;
        p.add_residual(
            r,
            &[pose_ids[pose_index[k_obs]], point_ids[point_index[k_obs]]],
            loss,
        )?;
    }
    for &f in fixed_poses {
        p.set_fixed(pose_ids[f], true)?;
    }
    let summary = p.solve(options)?;
    Ok(BundleResult {
        poses: pose_ids
            .iter()
            .map(|b| rotvec_translation(&se3_from_params(p.values(*b))))
            .collect(),
        points: point_ids
            .iter()
            .map(|b| {
                let v = p.values(*b);
                [v[0], v[1], v[2]]
            })
            .collect(),
        summary,
    })
}
