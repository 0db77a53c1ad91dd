//! The 3D circle (wafer rim) seen as an image ellipse by a calibrated pinhole camera: the
//! inverse of eq. (5.13)/(4.1) of 000_3b1454b2b2194811.txt, used to estimate each track's
//! wafer `w_k` for the projection prediction of §4.2 (eq. 4.1).
//!
//! The rays `x = K⁻¹p` through the ellipse `pᵀCp = 0` form the cone `xᵀQx = 0`,
//! `Q = KᵀCK`. With the eigenvalues of `Q` ordered `λ₁ ≥ λ₂ > 0 > λ₃` (after a sign flip
//! of `Q` if needed), subtracting `λ₂‖x‖²` shows that the planes cutting the cone in circles
//! are `√(λ₁−λ₂)·y₁ = ±√(λ₂−λ₃)·y₃` in the eigenbasis `y = Vᵀx`: two normals
//! `m = V·(√(λ₁−λ₂), 0, ±√(λ₂−λ₃))/√(λ₁−λ₃)` (the classical two-fold ambiguity). For each, the
//! section with the plane `m·x = 1` is a circle whose centre and radius follow from the 2×2
//! conic in the plane; scaling to the known radius fixes the distance.

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Isometry3, Matrix3, SymmetricEigen, Vector2, Vector3};

use crate::{DetectError, Result};

/// A circle in 3D: centre, unit normal of its plane, radius (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle3 {
    /// Centre.
    pub center: Vector3<f64>,
    /// Unit normal of the circle's plane.
    pub normal: Vector3<f64>,
    /// Radius.
    pub radius: f64,
}

impl Circle3 {
    /// The circle mapped by `t` (e.g. `T_wc` from camera to world coordinates).
    pub fn transformed(&self, t: &Isometry3<f64>) -> Circle3 {
        Circle3 {
            center: t.transform_vector(&self.center) + t.translation.vector,
            normal: t.rotation * self.normal,
            radius: self.radius,
        }
    }

    /// Two unit vectors `(u, v)` completing the normal to a right-handed orthonormal basis; the
    /// rim angle φ of a point `c + r(cos φ·u + sin φ·v)` is measured in it.
    pub fn basis(&self) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.normal;
        let helper = if n.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let u = (helper - n * n.dot(&helper)).normalize();
        (u, n.cross(&u))
    }

    /// The rim point at angle `phi`: `c + r(cos φ·u + sin φ·v)`, the bracket of eq. (4.1).
    pub fn point_at(&self, phi: f64) -> Vector3<f64> {
        let (u, v) = self.basis();
        let (s, c) = phi.sin_cos();
        self.center + (u * c + v * s) * self.radius
    }

    /// Rim angle of the point where the ray from `origin` along `direction` meets the circle's
    /// plane (`None` if the ray is parallel to the plane or meets it behind the origin).
    pub fn angle_of_ray(&self, origin: &Vector3<f64>, direction: &Vector3<f64>) -> Option<f64> {
        let den = self.normal.dot(direction);
        if den.abs() <= 1e-12 * direction.norm() {
            return None;
        }
        let s = self.normal.dot(&(self.center - origin)) / den;
        if !(s > 0.0 && s.is_finite()) {
            return None;
        }
        let x = origin + direction * s - self.center;
        let (u, v) = self.basis();
        Some(x.dot(&v).atan2(x.dot(&u)))
    }
}

/// The two circles of `radius` (camera coordinates, in front of the camera) whose image through
/// the pinhole intrinsics `k` is `ellipse` (inverse of eq. 5.13; see the module doc). Normals
/// point towards the camera (`n·c < 0`).
///
/// Errors: [`DetectError::InvalidParameter`] for a non-positive or non-finite radius or a
/// singular/non-finite `k`; [`DetectError::Degenerate`] when the back-projected cone is not an
/// elliptic cone (numerically degenerate ellipse).
pub fn circles_from_ellipse(
    k: &Matrix3<f64>,
    ellipse: &Ellipse,
    radius: f64,
) -> Result<[Circle3; 2]> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(DetectError::InvalidParameter {
            what: "radius",
            value: radius,
            reason: "the circle radius must be finite and positive",
        });
    }
    check_intrinsics(k)?;
    let c = ellipse.conic();
    let mut q = k.transpose() * c * k;
    q = (q + q.transpose()) * 0.5;
    let norm = q.norm();
    if !(norm > 0.0 && norm.is_finite()) {
        return Err(DetectError::Degenerate {
            reason: format!("the back-projected cone of {ellipse:?} has norm {norm}"),
        });
    }
    q /= norm;
    let eig = SymmetricEigen::new(q);
    let positives = eig.eigenvalues.iter().filter(|&&l| l > 0.0).count();
    let flip = if positives == 1 { -1.0 } else { 1.0 };
    let mut order: Vec<(f64, Vector3<f64>)> = (0..3)
        .map(|i| {
            (
                flip * eig.eigenvalues[i],
                eig.eigenvectors.column(i).into_owned(),
            )
        })
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (l1, l2, l3) = (order[0].0, order[1].0, order[2].0);
    if !(l2 > 1e-12 && l3 < -1e-12) {
        return Err(DetectError::Degenerate {
            reason: format!(
                "the back-projected cone of {ellipse:?} is not elliptic (eigenvalues {l1:.3e}, \
                 {l2:.3e}, {l3:.3e})"
            ),
        });
    }
    let v = Matrix3::from_columns(&[order[0].1, order[1].1, order[2].1]);
    let a = ((l1 - l2) / (l1 - l3)).max(0.0).sqrt();
    let b = ((l2 - l3) / (l1 - l3)).max(0.0).sqrt();
    let mut out = [Circle3 {
        center: Vector3::zeros(),
        normal: Vector3::z(),
        radius,
    }; 2];
    for (slot, sign) in out.iter_mut().zip([1.0, -1.0]) {
        let m = v * Vector3::new(a, 0.0, sign * b);
        *slot = section(&q, &m, radius).ok_or_else(|| DetectError::Degenerate {
            reason: format!("the circular section of the cone of {ellipse:?} is degenerate"),
        })?;
    }
    Ok(out)
}

/// The circle cut from the cone `xᵀQx = 0` by a plane of unit normal `m`, scaled to `radius`
/// and placed in front of the camera.
fn section(q: &Matrix3<f64>, m: &Vector3<f64>, radius: f64) -> Option<Circle3> {
    let helper = if m.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = (helper - m * m.dot(&helper)).normalize();
    let e2 = m.cross(&e1);
    // Points p0 + s·e1 + t·e2 of the plane m·x = 1 (p0 = m): the cone becomes the conic
    // [s t 1] M [s t 1]ᵀ = 0 with M = Bᵀ Q B, B = [e1 e2 m].
    let bm = Matrix3::from_columns(&[e1, e2, *m]);
    let mm = bm.transpose() * q * bm;
    let a2 = nalgebra::Matrix2::new(mm[(0, 0)], mm[(0, 1)], mm[(1, 0)], mm[(1, 1)]);
    let bv = Vector2::new(mm[(0, 2)], mm[(1, 2)]);
    let s0 = -(a2.try_inverse()? * bv);
    let f0 = mm[(2, 2)] + bv.dot(&s0);
    let alpha = 0.5 * (a2[(0, 0)] + a2[(1, 1)]);
    let rho2 = -f0 / alpha;
    if !(rho2 > 0.0 && rho2.is_finite()) {
        return None;
    }
    let d = radius / rho2.sqrt();
    let mut center = (m + e1 * s0.x + e2 * s0.y) * d;
    if center.z < 0.0 {
        center = -center;
    }
    let mut normal = *m;
    if normal.dot(&center) > 0.0 {
        normal = -normal;
    }
    Some(Circle3 {
        center,
        normal,
        radius,
    })
}

/// Validates a pinhole intrinsic matrix (finite, last row `(0, 0, 1)`-like, invertible).
pub(crate) fn check_intrinsics(k: &Matrix3<f64>) -> Result<()> {
    if let Some((i, v)) = k.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(DetectError::NonFinite {
            what: "intrinsic matrix K",
            index: i,
            value: *v,
        });
    }
    if k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 || k[(2, 2)] <= 0.0 {
        return Err(DetectError::InvalidParameter {
            what: "K[2, 2]",
            value: k[(2, 2)],
            reason: "a pinhole intrinsic matrix must have last row (0, 0, k33 > 0)",
        });
    }
    let det = k.determinant();
    if det.abs().partial_cmp(&1e-12) != Some(std::cmp::Ordering::Greater) {
        return Err(DetectError::InvalidParameter {
            what: "det K",
            value: det,
            reason: "the intrinsic matrix is singular",
        });
    }
    Ok(())
}

/// Pixel of a camera-frame point through `k` (`None` behind or on the principal plane).
pub(crate) fn project(k: &Matrix3<f64>, x: &Vector3<f64>) -> Option<Vector2<f64>> {
    if x.z.partial_cmp(&1e-9) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let p = k * x;
    let px = Vector2::new(p.x / p.z, p.y / p.z);
    (px.x.is_finite() && px.y.is_finite()).then_some(px)
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::conic::project_circle;
    use nalgebra::{Point3, Vector3};

    fn k() -> Matrix3<f64> {
        Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0)
    }

    /// Round trip: project a circle with the geometry crate (eq. 5.13), back-project, and find
    /// the true centre and normal among the two candidates.
    #[test]
    fn circles_from_projected_ellipse_contain_the_truth() {
        for (i, (t, r)) in [
            (Vector3::new(0.02, 0.05, 0.45), Vector3::new(1.3, 0.1, 0.0)),
            (
                Vector3::new(-0.1, -0.03, 0.6),
                Vector3::new(-1.45, 0.0, 0.2),
            ),
            (Vector3::new(0.0, 0.0, 0.5), Vector3::new(0.3, -0.4, 0.7)),
        ]
        .into_iter()
        .enumerate()
        {
            let t_co = Isometry3::new(t, r);
            let e = project_circle(&k(), &t_co, 0.15).unwrap();
            let cands = circles_from_ellipse(&k(), &e, 0.15).unwrap();
            let n_true = t_co.rotation * Vector3::z();
            let best = cands
                .iter()
                .map(|c| {
                    let dn = c.normal.cross(&n_true).norm();
                    ((c.center - t).norm(), dn)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            assert!(best.0 < 1e-7, "case {i}: centre error {}", best.0);
            assert!(best.1 < 1e-7, "case {i}: normal error {}", best.1);
            // Both candidates reproject onto the same ellipse.
            for c in &cands {
                let p = Point3::from(c.point_at(0.7));
                let px = project(&k(), &p.coords).unwrap();
                assert!(e.orthogonal_distance(&px).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn ray_angle_round_trip() {
        let c = Circle3 {
            center: Vector3::new(0.1, 0.0, 0.5),
            normal: Vector3::new(0.0, -0.8, -0.6),
            radius: 0.15,
        };
        for phi in [-3.0, -1.0, 0.0, 0.5, 2.9] {
            let x = c.point_at(phi);
            let got = c.angle_of_ray(&Vector3::zeros(), &x).unwrap();
            assert!((got - phi).abs() < 1e-9);
        }
        assert!(c.angle_of_ray(&Vector3::zeros(), &(-c.center)).is_none());
    }

    #[test]
    fn bad_inputs_are_errors() {
        let e = Ellipse::new(640.0, 360.0, 300.0, 50.0, 0.0).unwrap();
        assert!(circles_from_ellipse(&k(), &e, 0.0).is_err());
        assert!(circles_from_ellipse(&k(), &e, f64::NAN).is_err());
        assert!(circles_from_ellipse(&Matrix3::zeros(), &e, 0.15).is_err());
    }
}
