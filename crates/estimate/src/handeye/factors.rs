//! Measurement models of the SLAM-MOT factor graph (000_3b1454b2b2194811.txt §5.3): the conic
//! projection error of tracked edge points (eq. (5.13)) and, as the baseline the seed argues
//! against, the point-wise reprojection error with nearest-point association.

use autoteach_geometry::conic::circle_image_conic_jacobian;
use autoteach_geometry::lie::se3_adjoint;
use nalgebra::{DMatrix, Isometry3, Matrix3, Matrix6, Vector2, Vector3, Vector5, Vector6};

use super::wafer::{Rim, rim_pose};
use crate::{EstimateError, Result};

/// The Jacobians of a block of residuals with respect to the camera-pose twist `ε`
/// (`T_wc ⊕ ε`, n×6) and the wafer parameters (n×5).
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeJacobians {
    /// `∂r/∂ε` (n × 6).
    pub camera: DMatrix<f64>,
    /// `∂r/∂w` (n × 5).
    pub wafer: DMatrix<f64>,
}

/// `∂δ_co/∂ε_wc = −Ad(T_co⁻¹)`: how a right perturbation of the camera pose `T_wc` moves the
/// object-in-camera pose `T_co = T_wc⁻¹·T_wo`.
fn camera_to_object_twist(t_co: &Isometry3<f64>) -> Matrix6<f64> {
    -se3_adjoint(&t_co.inverse())
}

/// The conic projection error of eq. (5.13) for edge points of one rim, normalised to pixels.
///
/// The seed's `e_p = pᵀ C p` with `C = (K E)⁻ᵀ C₀ (K E)⁻¹` is the algebraic distance of the
/// homogeneous pixel `p` from the image conic of the wafer rim; its scale depends on how `C` is
/// normalised and on where the point lies. Here it is divided by its gradient norm
/// `2‖(C p)₁,₂‖` (the Sampson, first-order geometric distance), which is invariant to the
/// scale of `C` and is, to first order, the distance in pixels from the point to the ellipse;
/// the information matrix `Ω = 1/σ²` of eq. (5.5) is then the pixel noise of the edge points.
/// Points on the conic have zero error wherever they lie along it: no point correspondences.
///
/// `k` is the pinhole intrinsic matrix, `t_wc` the camera pose, `w` the wafer
/// ([`rim_pose`](super::wafer::rim_pose)), `sigma` the pixel noise. Writes `points.len()`
/// whitened residuals into `out`; with `jac`, also their Jacobians.
#[allow(clippy::too_many_arguments)]
pub fn conic_edge_residuals(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    w: &Vector5<f64>,
    rim: Rim,
    radius: f64,
    thickness: f64,
    points: &[Vector2<f64>],
    sigma: f64,
    out: &mut [f64],
    jac: Option<&mut EdgeJacobians>,
) -> Result<()> {
    let n = points.len();
    if out.len() != n {
        return Err(EstimateError::DimensionMismatch {
            what: "conic residual buffer".into(),
            expected: vec![n],
            got: vec![out.len()],
        });
    }
    let (t_wo, d_w) = rim_pose(w, rim, thickness);
    let t_co = t_wc.inverse() * t_wo;
    let (c, dc) = circle_image_conic_jacobian(k, &t_co, radius)?;
    let d_cam = camera_to_object_twist(&t_co);
    let mut jac = jac;
    for (i, p2) in points.iter().enumerate() {
        let p = Vector3::new(p2.x, p2.y, 1.0);
        let cp = c * p;
        let a = Vector2::new(cp.x, cp.y);
        let an = a.norm();
        if an.is_nan() || an <= 0.0 {
            return Err(EstimateError::NonFinite {
                what: format!("conic gradient at edge point ({}, {})", p2.x, p2.y),
                step: 0,
                index: i,
                value: an,
            });
        }
        let q = p.dot(&cp);
        let g = 2.0 * an;
        let e = q / g;
        out[i] = e / sigma;
        if let Some(j) = jac.as_deref_mut() {
            let mut de = Vector6::zeros();
            for (m, dcm) in dc.iter().enumerate() {
                let dcp = dcm * p;
                let dq = p.dot(&dcp);
                let dg_over_g = (a.x * dcp.x + a.y * dcp.y) / (an * an);
                de[m] = (dq / g - e * dg_over_g) / sigma;
            }
            let row_cam = de.transpose() * d_cam;
            let row_w = de.transpose() * d_w;
            for m in 0..6 {
                j.camera[(i, m)] = row_cam[m];
            }
            for m in 0..5 {
                j.wafer[(i, m)] = row_w[m];
            }
        }
    }
    Ok(())
}

/// A point of a rim in its own frame: `(r cos θ, r sin θ, 0)`.
pub fn rim_point(radius: f64, angle: f64) -> Vector3<f64> {
    Vector3::new(radius * angle.cos(), radius * angle.sin(), 0.0)
}

/// Pinhole projection of a camera-frame point with `K`, and its 2×3 derivative.
fn pinhole(k: &Matrix3<f64>, x: &Vector3<f64>) -> Result<(Vector2<f64>, nalgebra::Matrix2x3<f64>)> {
    if x.z.is_nan() || x.z <= 1e-9 {
        return Err(EstimateError::InvalidParameter {
            name: "rim point depth",
            value: x.z,
            reason: "a model point is behind the camera",
        });
    }
    let iz = 1.0 / x.z;
    let (u, v) = (x.x * iz, x.y * iz);
    let px = Vector2::new(
        k[(0, 0)] * u + k[(0, 1)] * v + k[(0, 2)],
        k[(1, 1)] * v + k[(1, 2)],
    );
    let dn = nalgebra::Matrix2x3::new(iz, 0.0, -u * iz, 0.0, iz, -v * iz);
    let kk = nalgebra::Matrix2::new(k[(0, 0)], k[(0, 1)], 0.0, k[(1, 1)]);
    Ok((px, kk * dn))
}

/// For every observed edge point, the angle of the nearest of `n_model` equally spaced model
/// points of the rim as projected with the current estimate: the naive nearest-point data
/// association of point-based bundle adjustment that §5.3 argues against.
#[allow(clippy::too_many_arguments)]
pub fn nearest_model_angles(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    w: &Vector5<f64>,
    rim: Rim,
    radius: f64,
    thickness: f64,
    points: &[Vector2<f64>],
    n_model: usize,
) -> Result<Vec<f64>> {
    if n_model < 3 {
        return Err(EstimateError::InvalidParameter {
            name: "n_model",
            value: n_model as f64,
            reason: "at least 3 model points per rim",
        });
    }
    let (t_wo, _) = rim_pose(w, rim, thickness);
    let t_co = t_wc.inverse() * t_wo;
    let mut model = Vec::with_capacity(n_model);
    for j in 0..n_model {
        let th = std::f64::consts::TAU * j as f64 / n_model as f64;
        let x = t_co * nalgebra::Point3::from(rim_point(radius, th));
        if let Ok((px, _)) = pinhole(k, &x.coords) {
            model.push((th, px));
        }
    }
    if model.is_empty() {
        return Err(EstimateError::InvalidParameter {
            name: "visible model points",
            value: 0.0,
            reason: "the whole rim is behind the camera",
        });
    }
    Ok(points
        .iter()
        .map(|p| {
            model
                .iter()
                .min_by(|a, b| {
                    (a.1 - p)
                        .norm_squared()
                        .total_cmp(&(b.1 - p).norm_squared())
                })
                .map(|m| m.0)
                .unwrap_or(0.0)
        })
        .collect())
}

/// Point-wise reprojection error (the baseline): observed pixel `p_i` minus the projection of
/// the associated model point at angle `angles[i]`, whitened by `sigma`; 2 residuals per point
/// (`out.len() = 2n`), Jacobians `2n × 6` and `2n × 5`.
#[allow(clippy::too_many_arguments)]
pub fn point_reprojection_residuals(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    w: &Vector5<f64>,
    rim: Rim,
    radius: f64,
    thickness: f64,
    points: &[Vector2<f64>],
    angles: &[f64],
    sigma: f64,
    out: &mut [f64],
    jac: Option<&mut EdgeJacobians>,
) -> Result<()> {
    let n = points.len();
    if out.len() != 2 * n || angles.len() != n {
        return Err(EstimateError::DimensionMismatch {
            what: "point reprojection residual buffer / angles".into(),
            expected: vec![2 * n, n],
            got: vec![out.len(), angles.len()],
        });
    }
    let (t_wo, d_w) = rim_pose(w, rim, thickness);
    let t_co = t_wc.inverse() * t_wo;
    let d_cam = camera_to_object_twist(&t_co);
    let r_co = t_co.rotation.to_rotation_matrix().into_inner();
    let mut jac = jac;
    for i in 0..n {
        let xo = rim_point(radius, angles[i]);
        let xc = t_co * nalgebra::Point3::from(xo);
        let (px, dpx) = pinhole(k, &xc.coords)?;
        out[2 * i] = (px.x - points[i].x) / sigma;
        out[2 * i + 1] = (px.y - points[i].y) / sigma;
        if let Some(j) = jac.as_deref_mut() {
            // d(R Exp(ω) x + t + Rρ) = R(−[x]× ω + ρ).
            let mut dx = nalgebra::Matrix3x6::zeros();
            dx.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&(-r_co * autoteach_geometry::lie::hat(&xo)));
            dx.fixed_view_mut::<3, 3>(0, 3).copy_from(&r_co);
            let dd = dpx * dx / sigma;
            let jc = dd * d_cam;
            let jw = dd * d_w;
            for r in 0..2 {
                for m in 0..6 {
                    j.camera[(2 * i + r, m)] = jc[(r, m)];
                }
                for m in 0..5 {
                    j.wafer[(2 * i + r, m)] = jw[(r, m)];
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::conic::project_circle;
    use autoteach_geometry::lie::se3_plus;
    use nalgebra::{Translation3, UnitQuaternion};

    fn setup() -> (Matrix3<f64>, Isometry3<f64>, Vector5<f64>) {
        let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0);
        // Camera 0.45 m in front of the wafer, 6 cm above it, looking along +x and down 8°.
        let look = UnitQuaternion::from_matrix(&Matrix3::new(
            0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
        )) * UnitQuaternion::from_euler_angles(0.14, 0.0, 0.0);
        let t_wc = Isometry3::from_parts(Translation3::new(-0.45, 0.01, 0.12), look);
        let w = Vector5::new(0.002, -0.001, 0.06, 0.004, -0.006);
        (k, t_wc, w)
    }

    fn edge_points(
        k: &Matrix3<f64>,
        t_wc: &Isometry3<f64>,
        w: &Vector5<f64>,
        rim: Rim,
    ) -> Vec<Vector2<f64>> {
        let (t_wo, _) = rim_pose(w, rim, 0.001);
        let e = project_circle(k, &(t_wc.inverse() * t_wo), 0.15).unwrap();
        (0..20).map(|i| e.point_at(0.3 + 0.12 * i as f64)).collect()
    }

    #[test]
    fn conic_error_is_zero_on_the_rim_and_the_pixel_distance_off_it() {
        let (k, t_wc, w) = setup();
        let pts = edge_points(&k, &t_wc, &w, Rim::Upper);
        let mut out = vec![0.0; pts.len()];
        conic_edge_residuals(
            &k,
            &t_wc,
            &w,
            Rim::Upper,
            0.15,
            0.001,
            &pts,
            1.0,
            &mut out,
            None,
        )
        .unwrap();
        assert!(out.iter().all(|r| r.abs() < 1e-6), "{out:?}");
        // Moving a point 0.5 px along the image normal of the ellipse gives ±0.5 px error.
        let (t_wo, _) = rim_pose(&w, Rim::Upper, 0.001);
        let e = project_circle(&k, &(t_wc.inverse() * t_wo), 0.15).unwrap();
        let off: Vec<_> = pts
            .iter()
            .map(|p| {
                let c = Vector2::new(e.cx, e.cy);
                p + (p - c).normalize() * 0.5
            })
            .collect();
        conic_edge_residuals(
            &k,
            &t_wc,
            &w,
            Rim::Upper,
            0.15,
            0.001,
            &off,
            1.0,
            &mut out,
            None,
        )
        .unwrap();
        for (r, p) in out.iter().zip(&off) {
            let d = e.orthogonal_distance(p);
            assert!((r.abs() - d).abs() < 0.05 * d + 1e-3, "{r} vs {d}");
        }
    }

    #[test]
    fn conic_jacobians_match_finite_differences() {
        let (k, t_wc, w) = setup();
        for rim in [Rim::Upper, Rim::Lower] {
            let pts: Vec<_> = edge_points(&k, &t_wc, &w, rim)
                .iter()
                .map(|p| p + Vector2::new(0.7, -0.4))
                .collect();
            let n = pts.len();
            let mut r0 = vec![0.0; n];
            let mut j = EdgeJacobians {
                camera: DMatrix::zeros(n, 6),
                wafer: DMatrix::zeros(n, 5),
            };
            conic_edge_residuals(
                &k,
                &t_wc,
                &w,
                rim,
                0.15,
                0.001,
                &pts,
                0.5,
                &mut r0,
                Some(&mut j),
            )
            .unwrap();
            let h = 1e-7;
            let mut r1 = vec![0.0; n];
            for m in 0..6 {
                let mut d = Vector6::zeros();
                d[m] = h;
                conic_edge_residuals(
                    &k,
                    &se3_plus(&t_wc, &d),
                    &w,
                    rim,
                    0.15,
                    0.001,
                    &pts,
                    0.5,
                    &mut r1,
                    None,
                )
                .unwrap();
                for i in 0..n {
                    let fd = (r1[i] - r0[i]) / h;
                    assert!(
                        (fd - j.camera[(i, m)]).abs() < 1e-4 * (1.0 + fd.abs()),
                        "cam {m} pt {i}: {fd} vs {}",
                        j.camera[(i, m)]
                    );
                }
            }
            for m in 0..5 {
                let mut w2 = w;
                w2[m] += h;
                conic_edge_residuals(&k, &t_wc, &w2, rim, 0.15, 0.001, &pts, 0.5, &mut r1, None)
                    .unwrap();
                for i in 0..n {
                    let fd = (r1[i] - r0[i]) / h;
                    assert!(
                        (fd - j.wafer[(i, m)]).abs() < 1e-4 * (1.0 + fd.abs()),
                        "wafer {m} pt {i}: {fd} vs {}",
                        j.wafer[(i, m)]
                    );
                }
            }
        }
    }

    #[test]
    fn point_jacobians_match_finite_differences_and_association_is_nearest() {
        let (k, t_wc, w) = setup();
        let pts = edge_points(&k, &t_wc, &w, Rim::Lower);
        let angles =
            nearest_model_angles(&k, &t_wc, &w, Rim::Lower, 0.15, 0.001, &pts, 360).unwrap();
        let n = pts.len();
        let mut r0 = vec![0.0; 2 * n];
        let mut j = EdgeJacobians {
            camera: DMatrix::zeros(2 * n, 6),
            wafer: DMatrix::zeros(2 * n, 5),
        };
        point_reprojection_residuals(
            &k,
            &t_wc,
            &w,
            Rim::Lower,
            0.15,
            0.001,
            &pts,
            &angles,
            1.0,
            &mut r0,
            Some(&mut j),
        )
        .unwrap();
        // Nearest of 360 model points: within half the spacing of the projected samples.
        assert!(r0.iter().all(|r| r.abs() < 5.0), "{r0:?}");
        let h = 1e-7;
        let residuals = |t: &Isometry3<f64>, wafer: &Vector5<f64>| {
            let mut r = vec![0.0; 2 * n];
            point_reprojection_residuals(
                &k,
                t,
                wafer,
                Rim::Lower,
                0.15,
                0.001,
                &pts,
                &angles,
                1.0,
                &mut r,
                None,
            )
            .unwrap();
            r
        };
        let check = |what: &str, m: usize, r1: &[f64], analytic: &DMatrix<f64>| {
            for i in 0..2 * n {
                let fd = (r1[i] - r0[i]) / h;
                assert!(
                    (fd - analytic[(i, m)]).abs() < 1e-3 * (1.0 + fd.abs()),
                    "{what} {m}: {fd} vs {}",
                    analytic[(i, m)]
                );
            }
        };
        for m in 0..6 {
            let mut d = Vector6::zeros();
            d[m] = h;
            check("cam", m, &residuals(&se3_plus(&t_wc, &d), &w), &j.camera);
        }
        for m in 0..5 {
            let mut w2 = w;
            w2[m] += h;
            check("wafer", m, &residuals(&t_wc, &w2), &j.wafer);
        }
    }
}
