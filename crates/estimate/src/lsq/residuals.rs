//! Built-in residuals with analytic Jacobians (right perturbations, tangent `[ω; ρ]`):
//! pinhole reprojection of a 3D point (bundle adjustment; seed 004_815695db12a6b16c.txt
//! eq. (5.1)), relative pose between SE(3) blocks (seed 000_3b1454b2b2194811.txt eq. (5.11))
//! and point-to-conic (seed 000_3b1454b2b2194811.txt eq. (5.13)). The pose prior is
//! [`super::PriorResidual`].

use autoteach_geometry::lie::{hat, se3_adjoint, se3_log, se3_right_jacobian_inv};
use nalgebra::{DMatrix, Isometry3, Matrix3, Vector3, Vector6};

use super::manifold::{Manifold, se3_from_params};
use super::problem::Residual;
use crate::{EstimateError, Result};
use autoteach_geometry::error::Num;

/// Validated pinhole intrinsics `K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length along u (px).
    pub fx: f64,
    /// Focal length along v (px).
    pub fy: f64,
    /// Principal point u (px).
    pub cx: f64,
    /// Principal point v (px).
    pub cy: f64,
    /// Skew.
    pub skew: f64,
}

impl Intrinsics {
    /// From a 3×3 K (upper triangular, K₂₂ = 1, positive focal lengths, finite).
    pub fn from_matrix(k: &Matrix3<f64>) -> Result<Self> {
        if let Some((index, &value)) = k.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: "K".into(),
                index,
                value,
            });
        }
        if k[(1, 0)] != 0.0 || k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 || k[(2, 2)] != 1.0 {
            return Err(EstimateError::InvalidProblem(format!(
                "K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got last rows [{}, {}, {}], [{}, {}, {}]",
                Num(k[(1, 0)]),
                Num(k[(1, 1)]),
                Num(k[(1, 2)]),
                Num(k[(2, 0)]),
                Num(k[(2, 1)]),
                Num(k[(2, 2)])
            )));
        }
        if k[(0, 0)] <= 0.0 || k[(1, 1)] <= 0.0 {
            return Err(EstimateError::InvalidParameter {
                name: "K focal length",
                value: k[(0, 0)].min(k[(1, 1)]),
                reason: "must be positive",
            });
        }
        Ok(Self {
            fx: k[(0, 0)],
            fy: k[(1, 1)],
            cx: k[(0, 2)],
            cy: k[(1, 2)],
            skew: k[(0, 1)],
        })
    }

    /// The matrix K.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.fx, self.skew, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0,
        )
    }
}

fn check_sigma(sigma: f64) -> Result<f64> {
    if sigma.is_finite() && sigma > 0.0 {
        Ok(1.0 / sigma)
    } else {
        Err(EstimateError::InvalidParameter {
            name: "sigma",
            value: sigma,
            reason: "must be finite and positive",
        })
    }
}

fn check_finite(what: &str, v: &[f64]) -> Result<()> {
    match v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        Some((index, &value)) => Err(EstimateError::NonFiniteInput {
            what: what.into(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// Reprojection error of a world point `X` (block 1, `Euclidean(3)`) seen by a camera with
/// world-to-camera pose `T_cw` (block 0, `Se3`): r = (π(K (R X + t)) − z) / σ, π the
/// perspective division (seed 004_815695db12a6b16c.txt eq. (5.1), pinhole case).
///
/// Jacobians, with X_c = R X + t and right perturbation T·Exp([ω; ρ]):
/// ∂X_c/∂ω = −R \[X\]×, ∂X_c/∂ρ = R, ∂X_c/∂X = R; ∂π/∂X_c = [[fx/z, s/z, −(fx x + s y)/z²],
/// [0, fy/z, −fy y/z²]]. A point at depth z ≤ 1e-12 is an error (during a solve, the trial
/// step is rejected).
#[derive(Debug, Clone)]
pub struct ReprojectionResidual {
    k: Intrinsics,
    observed: [f64; 2],
    inv_sigma: f64,
}

impl ReprojectionResidual {
    /// Observation `observed = (u, v)` (px) with isotropic standard deviation `sigma` (px).
    pub fn new(k: &Matrix3<f64>, observed: [f64; 2], sigma: f64) -> Result<Self> {
        check_finite("observed pixel", &observed)?;
        Ok(Self {
            k: Intrinsics::from_matrix(k)?,
            observed,
            inv_sigma: check_sigma(sigma)?,
        })
    }
}

impl Residual for ReprojectionResidual {
    fn block_manifolds(&self) -> Option<Vec<Manifold>> {
        Some(vec![Manifold::Se3, Manifold::Euclidean(3)])
    }

    fn dim(&self) -> usize {
        2
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let (Some(pose), Some(x)) = (params.first(), params.get(1)) else {
            return Err(EstimateError::InvalidProblem(
                "ReprojectionResidual needs [pose, point] blocks".into(),
            ));
        };
        let t = se3_from_params(pose);
        let xw = Vector3::new(x[0], x[1], x[2]);
        let r = t.rotation.to_rotation_matrix().into_inner();
        let pc = r * xw + t.translation.vector;
        if pc.z <= 1e-12 {
            return Err(EstimateError::InvalidProblem(format!(
                "point at depth {:.3e} is not in front of the camera: a depth > 1e-12 is expected",
                pc.z
            )));
        }
        let k = &self.k;
        let iz = 1.0 / pc.z;
        let u = (k.fx * pc.x + k.skew * pc.y) * iz + k.cx;
        let v = k.fy * pc.y * iz + k.cy;
        residual[0] = (u - self.observed[0]) * self.inv_sigma;
        residual[1] = (v - self.observed[1]) * self.inv_sigma;
        if let Some(jac) = jacobians {
            let s = self.inv_sigma;
            let dpi = nalgebra::Matrix2x3::new(
                k.fx * iz * s,
                k.skew * iz * s,
                -(k.fx * pc.x + k.skew * pc.y) * iz * iz * s,
                0.0,
                k.fy * iz * s,
                -k.fy * pc.y * iz * iz * s,
            );
            let dr = dpi * r;
            let jw = -dr * hat(&xw);
            // The pre-sized 2 × 6 and 2 × 3 column-major Jacobians take [∂/∂ω | ∂/∂ρ] and
            // ∂/∂X as whole columns (other shapes, e.g. a caller's own matrices, by entry).
            if let Some(jp) = jac.get_mut(0).filter(|j| j.shape() == (2, 6))
                && let Some((w, rho)) = jp.as_mut_slice().split_first_chunk_mut::<6>()
                && let Some(rho) = rho.first_chunk_mut::<6>()
            {
                w.copy_from_slice(jw.as_slice());
                rho.copy_from_slice(dr.as_slice());
            } else if let Some(jp) = jac.get_mut(0) {
                for c in 0..3 {
                    for rr in 0..2 {
                        jp[(rr, c)] = jw[(rr, c)];
                        jp[(rr, c + 3)] = dr[(rr, c)];
                    }
                }
            }
            if let Some(jx) = jac.get_mut(1).filter(|j| j.shape() == (2, 3))
                && let Some(x6) = jx.as_mut_slice().first_chunk_mut::<6>()
            {
                x6.copy_from_slice(dr.as_slice());
            } else if let Some(jx) = jac.get_mut(1) {
                for c in 0..3 {
                    for rr in 0..2 {
                        jx[(rr, c)] = dr[(rr, c)];
                    }
                }
            }
        }
        Ok(())
    }
}

/// Whitened relative-pose error between SE(3) blocks A (block 0) and B (block 1) given a
/// measurement Z of A⁻¹B: r = L⁻¹ Log(Z⁻¹ A⁻¹ B), Σ = L Lᵀ (the robot-motion factor of
/// seed 000_3b1454b2b2194811.txt eq. (5.11), e = (A⁻¹B) ⊖ Z).
///
/// Jacobians (Solà App. D): ∂e/∂δB = J_r⁻¹(e); ∂e/∂δA = −J_r⁻¹(e) Ad_{(A⁻¹B)⁻¹}.
#[derive(Debug, Clone)]
pub struct RelativePoseResidual {
    z_inv: Isometry3<f64>,
    sqrt_info: DMatrix<f64>,
}

impl RelativePoseResidual {
    /// Measurement `z_ab` of A⁻¹B with tangent covariance `covariance` (6×6, SPD).
    pub fn new(z_ab: &Isometry3<f64>, covariance: &DMatrix<f64>) -> Result<Self> {
        let prior = super::problem::PriorResidual::new(
            super::Manifold::Se3,
            &super::se3_to_params(z_ab),
            covariance,
        )?;
        Ok(Self {
            z_inv: z_ab.inverse(),
            sqrt_info: prior.sqrt_info().clone(),
        })
    }
}

impl Residual for RelativePoseResidual {
    fn block_manifolds(&self) -> Option<Vec<Manifold>> {
        Some(vec![Manifold::Se3, Manifold::Se3])
    }

    fn dim(&self) -> usize {
        6
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let (Some(a), Some(b)) = (params.first(), params.get(1)) else {
            return Err(EstimateError::InvalidProblem(
                "RelativePoseResidual needs [A, B] blocks".into(),
            ));
        };
        let m = se3_from_params(a).inverse() * se3_from_params(b);
        let e = se3_log(&(self.z_inv * m));
        let r = &self.sqrt_info * DMatrix::from_column_slice(6, 1, e.as_slice());
        residual.copy_from_slice(r.as_slice());
        if let Some(jac) = jacobians {
            let jri = se3_right_jacobian_inv(&e);
            let jri_d = DMatrix::from_column_slice(6, 6, jri.as_slice());
            let ad = se3_adjoint(&m.inverse());
            let ja = -(jri * ad);
            if let Some(j) = jac.get_mut(0) {
                *j = &self.sqrt_info * DMatrix::from_column_slice(6, 6, ja.as_slice());
            }
            if let Some(j) = jac.get_mut(1) {
                *j = &self.sqrt_info * jri_d;
            }
        }
        Ok(())
    }
}

/// Conic-fit error of an image point on the rim of a circular object (seed
/// 000_3b1454b2b2194811.txt eq. (5.13)): with camera pose `T_cw` (block 0, world-to-camera),
/// object pose `T_wo` (block 1, object-to-world), E = T_cw T_wo, the plane homography
/// H = K [e₁ e₂ t] of E's rotation columns and translation, and C₀ = diag(1, 1, −ρ²) the rim
/// circle of radius ρ in the object's z = 0 plane, r = w · pᵀ H⁻ᵀ C₀ H⁻¹ p for p = [u, v, 1]ᵀ.
/// Zero for every point on the projected rim (no point-to-point correspondence).
///
/// Jacobians: q = H⁻¹p, ∂r = −2w qᵀC₀ H⁻¹ (∂H) q with ∂H = K [∂R e₁, ∂R e₂, ∂t], where for
/// the object ∂R = R_E \[eᵢ\]×, ∂t = R_E eᵢ (ω, ρ), and for the camera
/// ∂R = R_cw \[eᵢ\]× R_wo, ∂t = R_cw (eᵢ × t_wo) (ω) and ∂t = R_cw eᵢ (ρ).
#[derive(Debug, Clone)]
pub struct PointToConicResidual {
    k: Matrix3<f64>,
    radius: f64,
    p: Vector3<f64>,
    weight: f64,
}

impl PointToConicResidual {
    /// Rim of radius `radius` (m), observed point `observed` (px), weight `w` (> 0).
    pub fn new(k: &Matrix3<f64>, radius: f64, observed: [f64; 2], weight: f64) -> Result<Self> {
        let k = Intrinsics::from_matrix(k)?.matrix();
        check_finite("observed pixel", &observed)?;
        if !(radius.is_finite() && radius > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "radius",
                value: radius,
                reason: "must be finite and positive",
            });
        }
        if !(weight.is_finite() && weight > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "weight",
                value: weight,
                reason: "must be finite and positive",
            });
        }
        Ok(Self {
            k,
            radius,
            p: Vector3::new(observed[0], observed[1], 1.0),
            weight,
        })
    }
}

impl Residual for PointToConicResidual {
    fn block_manifolds(&self) -> Option<Vec<Manifold>> {
        Some(vec![Manifold::Se3, Manifold::Se3])
    }

    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let (Some(cam), Some(obj)) = (params.first(), params.get(1)) else {
            return Err(EstimateError::InvalidProblem(
                "PointToConicResidual needs [camera, object] blocks".into(),
            ));
        };
        let t_cw = se3_from_params(cam);
        let t_wo = se3_from_params(obj);
        let e = t_cw * t_wo;
        let re = e.rotation.to_rotation_matrix().into_inner();
        let te = e.translation.vector;
        let h = self.k
            * Matrix3::from_columns(&[re.column(0).into_owned(), re.column(1).into_owned(), te]);
        let Some(hi) = h.try_inverse() else {
            return Err(EstimateError::InvalidProblem(
                "the object plane passes through the camera centre (singular homography)".into(),
            ));
        };
        let c0 = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -self.radius * self.radius));
        let q = hi * self.p;
        residual[0] = self.weight * (q.transpose() * c0 * q)[(0, 0)];
        if let Some(jac) = jacobians {
            // dr/dH (contracted with a dH): −2w qᵀC₀ H⁻¹ dH q.
            let g = -2.0 * self.weight * (c0 * q).transpose() * hi;
            let dr = |dr_rot: &Matrix3<f64>, dt: &Vector3<f64>| -> f64 {
                let dh = self.k
                    * Matrix3::from_columns(&[
                        dr_rot.column(0).into_owned(),
                        dr_rot.column(1).into_owned(),
                        *dt,
                    ]);
                (g * dh * q)[(0, 0)]
            };
            let r_cw = t_cw.rotation.to_rotation_matrix().into_inner();
            let r_wo = t_wo.rotation.to_rotation_matrix().into_inner();
            let t_wo_v = t_wo.translation.vector;
            let mut jc = Vector6::zeros();
            let mut jo = Vector6::zeros();
            for i in 0..3 {
                let ei = Vector3::ith(i, 1.0);
                let hx = hat(&ei);
                jo[i] = dr(&(re * hx), &Vector3::zeros());
                jo[i + 3] = dr(&Matrix3::zeros(), &(re * ei));
                jc[i] = dr(&(r_cw * hx * r_wo), &(r_cw * ei.cross(&t_wo_v)));
                jc[i + 3] = dr(&Matrix3::zeros(), &(r_cw * ei));
            }
            if let Some(j) = jac.get_mut(0) {
                j.copy_from(&DMatrix::from_row_slice(1, 6, jc.as_slice()));
            }
            if let Some(j) = jac.get_mut(1) {
                j.copy_from(&DMatrix::from_row_slice(1, 6, jo.as_slice()));
            }
        }
        Ok(())
    }
}
