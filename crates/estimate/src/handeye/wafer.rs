//! Wafer parameterisation: centre and tilt (5 numbers), and the poses of its two rims.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3, Vector5};

use crate::{EstimateError, Result};

/// Number of parameters of a wafer: `[cx, cy, cz, rx, ry]`.
pub const WAFER_DIM: usize = 5;

/// Which rim (edge circle) of a wafer: the upper (`+h/2` along the normal) or the lower one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rim {
    /// The rim at `+h/2` along the wafer normal.
    Upper,
    /// The rim at `−h/2` along the wafer normal.
    Lower,
}

impl Rim {
    /// `+1` for the upper rim, `−1` for the lower.
    pub fn sign(self) -> f64 {
        match self {
            Rim::Upper => 1.0,
            Rim::Lower => -1.0,
        }
    }
}

/// A wafer as a flat disc of `radius` and `thickness` whose pose is
/// `[cx, cy, cz, rx, ry]`: centre `c` (world, metres) and orientation `R = Ry(ry)·Rx(rx)`
/// (the tilt about the world x and y axes, radians; the normal is `R e_z`).
///
/// A circle has no yaw: the rotation about its own normal is not a parameter, which keeps
/// the SLAM-MOT problem of 000_3b1454b2b2194811.txt §5.3 free of that gauge freedom. (The
/// seed's `w_k` is a full pose; the parameterisation by centre and normal is the one its
/// theoretical resolution (5.14) uses: only `T`'s action on rim points matters.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaferGeometry {
    /// Radius (m), 0.15 for 300 mm wafers.
    pub radius: f64,
    /// Thickness (m); the rims are at `±thickness/2`.
    pub thickness: f64,
}

impl WaferGeometry {
    /// Validated geometry: radius > 0, thickness ≥ 0, both finite.
    pub fn new(radius: f64, thickness: f64) -> Result<Self> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "wafer radius",
                value: radius,
                reason: "must be finite and positive",
            });
        }
        if !(thickness.is_finite() && thickness >= 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "wafer thickness",
                value: thickness,
                reason: "must be finite and non-negative",
            });
        }
        Ok(Self { radius, thickness })
    }
}

/// `Ry(ry)·Rx(rx)`.
pub fn wafer_rotation(rx: f64, ry: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::y_axis(), ry)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), rx)
}

/// The world pose `T_wo` of a wafer's rim frame (origin at the rim centre, z along the normal)
/// and `∂δ/∂w` (6×5): the right-perturbation twist `[ω; ρ]` of `T_wo` per unit change of
/// each wafer parameter.
///
/// `R = Ry·Rx`, `t = c + s·h/2·R e_z`: `∂R/∂rx = R[e_x]×` (ω = e_x), `∂R/∂ry = R[Rxᵀe_y]×`
/// (ω = Rxᵀe_y), and for every ω the rim offset gives `ρ = s·h/2·ω × e_z`; `∂t/∂c_j = e_j`
/// gives `ρ = Rᵀe_j`.
pub fn rim_pose(
    w: &Vector5<f64>,
    rim: Rim,
    thickness: f64,
) -> (Isometry3<f64>, nalgebra::Matrix6x5<f64>) {
    let rot = wafer_rotation(w[3], w[4]);
    let half = rim.sign() * 0.5 * thickness;
    let r = rot.matrix();
    let t = Vector3::new(w[0], w[1], w[2]) + r.column(2) * half;
    let mut d = nalgebra::Matrix6x5::zeros();
    let rt: Matrix3<f64> = r.transpose();
    for j in 0..3 {
        d.fixed_view_mut::<3, 1>(3, j).copy_from(&rt.column(j));
    }
    let (sx, cx) = w[3].sin_cos();
    let omegas = [Vector3::x(), Vector3::new(0.0, cx, -sx)];
    for (k, om) in omegas.iter().enumerate() {
        d.fixed_view_mut::<3, 1>(0, 3 + k).copy_from(om);
        d.fixed_view_mut::<3, 1>(3, 3 + k)
            .copy_from(&(om.cross(&Vector3::z()) * half));
    }
    let pose = Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rot),
    );
    (pose, d)
}

/// Unit normal `R e_z` of a wafer.
pub fn wafer_normal(w: &Vector5<f64>) -> Vector3<f64> {
    wafer_rotation(w[3], w[4]) * Vector3::z()
}

/// Wafer parameters from a centre and a normal (the normal's sign is chosen so that it points
/// up, `n_z > 0`): `rx = −asin(n_y)`, `ry = atan2(n_x, n_z)` inverts `n = Ry(ry)·Rx(rx)·e_z`.
pub fn wafer_from_center_normal(c: &Vector3<f64>, n: &Vector3<f64>) -> Result<Vector5<f64>> {
    let len = n.norm();
    if !len.is_finite() || len <= 0.0 || !c.iter().all(|v| v.is_finite()) {
        return Err(EstimateError::InvalidParameter {
            name: "wafer normal length",
            value: len,
            reason: "the normal must be a finite non-zero vector and the centre finite",
        });
    }
    let mut n = n / len;
    if n.z < 0.0 {
        n = -n;
    }
    let rx = -n.y.clamp(-1.0, 1.0).asin();
    let ry = n.x.atan2(n.z);
    Ok(Vector5::new(c.x, c.y, c.z, rx, ry))
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::lie::se3_minus;

    #[test]
    fn rim_pose_jacobian_matches_finite_differences() {
        let w = Vector5::new(0.01, -0.02, 0.2, 0.03, -0.02);
        for rim in [Rim::Upper, Rim::Lower] {
            let (p0, d) = rim_pose(&w, rim, 0.01);
            for j in 0..5 {
                let mut w2 = w;
                w2[j] += 1e-7;
                let fd = se3_minus(&rim_pose(&w2, rim, 0.01).0, &p0) / 1e-7;
                assert!(
                    (fd - d.column(j)).norm() < 1e-6,
                    "{rim:?} param {j}: {fd} vs {}",
                    d.column(j)
                );
            }
        }
    }

    #[test]
    fn center_normal_round_trip() {
        let w = Vector5::new(0.01, -0.02, 0.2, 0.03, -0.02);
        let n = wafer_normal(&w);
        let back = wafer_from_center_normal(&Vector3::new(w[0], w[1], w[2]), &(-n * 3.0)).unwrap();
        assert!((back - w).norm() < 1e-12);
    }
}
