//! The calibration measurement model: reprojection of planar-target points through the camera
//! model and the target pose (004_815695db12a6b16c.txt ch. 5.1: "each row-pair corresponds to
//! projecting a feature from a known 3D coordinate on the calibration target into pixel
//! coordinates"), whitened by the detector noise σ_z (eq. 5.1's `Σ_z`), with analytic Jacobians
//! with respect to the intrinsic parameter groups and the right-perturbation tangent of the
//! pose, and the per-view Schur complement that gives the intrinsics' information (eq. 5.5).

use std::sync::Arc;

use autoteach_geometry::camera::{Camera, CameraModel};
use nalgebra::{
    DMatrix, Isometry3, Matrix2x3, Matrix3, Point3, Quaternion, Translation3, UnitQuaternion,
    Vector3,
};

use crate::{EstimateError, Result};

/// The parameter groups (indices into the model's parameter vector) that the bootstrapping
/// phase fixes or releases together: `[fx, fy]`, `[cx, cy]`, then the distortion terms
/// (Brown–Conrady: `[k1, k2]`, `[p1, p2]`, `[k3]`; Kannala–Brandt: `[k1, k2]`, `[k3, k4]`).
pub fn param_groups(model: CameraModel) -> Vec<Vec<usize>> {
    match model {
        CameraModel::Pinhole => vec![vec![0, 1], vec![2, 3]],
        CameraModel::BrownConrady => vec![vec![0, 1], vec![2, 3], vec![4, 5], vec![6, 7], vec![8]],
        CameraModel::KannalaBrandt => vec![vec![0, 1], vec![2, 3], vec![4, 5], vec![6, 7]],
    }
}

/// A pose stored as `[qw, qx, qy, qz, tx, ty, tz]` (the least-squares `Se3` layout).
pub fn pose_from_params(p: &[f64]) -> Result<Isometry3<f64>> {
    if p.len() != 7 {
        return Err(EstimateError::DimensionMismatch {
            what: "target pose parameters".into(),
            expected: vec![7],
            got: vec![p.len()],
        });
    }
    let q = UnitQuaternion::from_quaternion(Quaternion::new(p[0], p[1], p[2], p[3]));
    Ok(Isometry3::from_parts(
        Translation3::new(p[4], p[5], p[6]),
        q,
    ))
}

/// `[qw, qx, qy, qz, tx, ty, tz]` of a pose.
pub fn pose_to_params(t: &Isometry3<f64>) -> [f64; 7] {
    let q = t.rotation.quaternion();
    let v = t.translation.vector;
    [q.w, q.i, q.j, q.k, v.x, v.y, v.z]
}

/// Reprojection residuals of the points of one view (or one point of it, for robust losses):
/// `r = (π(m, T_ct · [X, Y, 0]) − z) / σ_z`, two rows per point.
///
/// Blocks: the intrinsic groups of [`param_groups`] (each `Euclidean`), then the pose `T_ct`
/// (`Se3`, right perturbation `T·Exp([ω; ρ])`, so `∂p_c/∂ω = −R [p]×` and `∂p_c/∂ρ = R`).
#[derive(Debug, Clone)]
pub struct ReprojectionResidual {
    model: CameraModel,
    width: u32,
    height: u32,
    groups: Arc<Vec<Vec<usize>>>,
    plane: Vec<[f64; 2]>,
    image: Vec<[f64; 2]>,
    inv_sigma: f64,
}

impl ReprojectionResidual {
    /// Residual of the target points `plane` (`[X, Y]`, z = 0) observed at `image`.
    pub fn new(
        model: CameraModel,
        width: u32,
        height: u32,
        groups: Arc<Vec<Vec<usize>>>,
        plane: Vec<[f64; 2]>,
        image: Vec<[f64; 2]>,
        sigma: f64,
    ) -> Result<Self> {
        if plane.len() != image.len() || plane.is_empty() {
            return Err(EstimateError::DimensionMismatch {
                what: "reprojection residual points".into(),
                expected: vec![plane.len()],
                got: vec![image.len()],
            });
        }
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(EstimateError::InvalidParameter {
                name: "sigma_z",
                value: sigma,
                reason: "must be positive and finite",
            });
        }
        Ok(Self {
            model,
            width,
            height,
            groups,
            plane,
            image,
            inv_sigma: 1.0 / sigma,
        })
    }

    /// Residual dimension (two per point).
    pub fn dim(&self) -> usize {
        2 * self.plane.len()
    }

    /// Evaluates the residual and, if asked, the Jacobians (one per block: the intrinsic groups,
    /// then the pose), following the least-squares `Residual` contract.
    pub fn eval(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let g = self.groups.len();
        if params.len() != g + 1 || residual.len() != self.dim() {
            return Err(EstimateError::DimensionMismatch {
                what: "reprojection residual blocks".into(),
                expected: vec![g + 1, self.dim()],
                got: vec![params.len(), residual.len()],
            });
        }
        let mut p = vec![0.0; self.model.num_params()];
        for (grp, vals) in self.groups.iter().zip(params) {
            if grp.len() != vals.len() {
                return Err(EstimateError::DimensionMismatch {
                    what: "intrinsic group".into(),
                    expected: vec![grp.len()],
                    got: vec![vals.len()],
                });
            }
            for (&i, &v) in grp.iter().zip(vals.iter()) {
                p[i] = v;
            }
        }
        let cam = Camera::new(self.model, &p, self.width, self.height)?;
        let pose = pose_from_params(params[g])?;
        let rot: Matrix3<f64> = *pose.rotation.to_rotation_matrix().matrix();
        let s = self.inv_sigma;
        match jacobians {
            None => {
                for (k, (pl, obs)) in self.plane.iter().zip(&self.image).enumerate() {
                    let pc = pose * Point3::new(pl[0], pl[1], 0.0);
                    // An unprojectable point (behind the camera, beyond the lens's range) gives
                    // a NaN residual: the solver rejects such trial steps (and reports it at the
                    // initial values) instead of aborting.
                    let (u, v) = cam
                        .project(&pc.coords)
                        .map(|px| (px.x, px.y))
                        .unwrap_or((f64::NAN, f64::NAN));
                    residual[2 * k] = (u - obs[0]) * s;
                    residual[2 * k + 1] = (v - obs[1]) * s;
                }
            }
            Some(jacs) => {
                if jacs.len() != g + 1 {
                    return Err(EstimateError::DimensionMismatch {
                        what: "reprojection residual Jacobians".into(),
                        expected: vec![g + 1],
                        got: vec![jacs.len()],
                    });
                }
                for (k, (pl, obs)) in self.plane.iter().zip(&self.image).enumerate() {
                    let pt = Vector3::new(pl[0], pl[1], 0.0);
                    let pc = pose * Point3::from(pt);
                    let Ok((px, jp, jm)) = cam.project_jacobians(&pc.coords) else {
                        residual[2 * k] = f64::NAN;
                        residual[2 * k + 1] = f64::NAN;
                        continue;
                    };
                    residual[2 * k] = (px.x - obs[0]) * s;
                    residual[2 * k + 1] = (px.y - obs[1]) * s;
                    for (grp, jac) in self.groups.iter().zip(jacs.iter_mut()) {
                        for (c, &i) in grp.iter().enumerate() {
                            jac[(2 * k, c)] = jm[(0, i)] * s;
                            jac[(2 * k + 1, c)] = jm[(1, i)] * s;
                        }
                    }
                    let jpose = pose_jacobian(&jp, &rot, &pt);
                    let jac = &mut jacs[g];
                    for c in 0..6 {
                        jac[(2 * k, c)] = jpose[(0, c)] * s;
                        jac[(2 * k + 1, c)] = jpose[(1, c)] * s;
                    }
                }
            }
        }
        Ok(())
    }
}

/// `∂pixel/∂δ` for the right perturbation `T·Exp(δ)`, `δ = [ω; ρ]`: `J_point · [−R[p]×, R]`.
pub fn pose_jacobian(
    j_point: &Matrix2x3<f64>,
    rot: &Matrix3<f64>,
    p_target: &Vector3<f64>,
) -> nalgebra::Matrix2x6<f64> {
    let jr = j_point * rot;
    let jw = -jr * autoteach_geometry::lie::hat(p_target);
    let mut out = nalgebra::Matrix2x6::zeros();
    out.fixed_view_mut::<2, 3>(0, 0).copy_from(&jw);
    out.fixed_view_mut::<2, 3>(0, 3).copy_from(&jr);
    out
}

/// Information about the intrinsics contributed by one view with its pose marginalised out
/// (004_815695db12a6b16c.txt eqs. 5.3–5.5): with `A = JᵀJ/σ_z²` split into intrinsics `m` and
/// pose `T`, the Schur complement `A_mm − A_mT A_TT⁻¹ A_Tm` (n×n, all model parameters).
/// Views are independent given the intrinsics, so these add up to the marginal information.
///
/// Points that do not project are skipped; `None` when fewer than 4 remain or `A_TT` is
/// singular (the pose is not determined by this view).
pub fn view_information(
    camera: &Camera,
    pose: &Isometry3<f64>,
    plane: &[[f64; 2]],
    sigma: f64,
) -> Option<DMatrix<f64>> {
    let n = camera.model().num_params();
    let rot: Matrix3<f64> = *pose.rotation.to_rotation_matrix().matrix();
    let mut amm = DMatrix::<f64>::zeros(n, n);
    let mut amt = DMatrix::<f64>::zeros(n, 6);
    let mut att = nalgebra::Matrix6::<f64>::zeros();
    let w = 1.0 / (sigma * sigma);
    let mut used = 0;
    for pl in plane {
        let pt = Vector3::new(pl[0], pl[1], 0.0);
        let pc = pose * Point3::from(pt);
        let Ok((_, jp, jm)) = camera.project_jacobians(&pc.coords) else {
            continue;
        };
        used += 1;
        let jt = pose_jacobian(&jp, &rot, &pt);
        amm += jm.transpose() * &jm * w;
        for i in 0..n {
            for c in 0..6 {
                amt[(i, c)] += (jm[(0, i)] * jt[(0, c)] + jm[(1, i)] * jt[(1, c)]) * w;
            }
        }
        att += jt.transpose() * jt * w;
    }
    if used < 4 {
        return None;
    }
    let chol = att.cholesky()?;
    let mut x = DMatrix::<f64>::zeros(6, n);
    for i in 0..n {
        let col = nalgebra::Vector6::from_fn(|c, _| amt[(i, c)]);
        let sol = chol.solve(&col);
        for c in 0..6 {
            x[(c, i)] = sol[c];
        }
    }
    let mut info = amm - &amt * x;
    info = (&info + info.transpose()) * 0.5;
    Some(info)
}
