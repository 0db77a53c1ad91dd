//! Parameter blocks on manifolds: storage layouts, ⊕ and ⊖ (seed 000_3b1454b2b2194811.txt
//! eq. (5.11), Solà's "micro Lie theory" Sec. III-A), built on [`autoteach_geometry::lie`].

use autoteach_geometry::lie::{quat_minus, quat_plus, se3_minus, se3_plus, so3_minus, so3_plus};
use nalgebra::{
    Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};

use crate::{EstimateError, Result};

/// The manifold a parameter block lives on, with its stored (ambient) layout.
///
/// * `Euclidean(n)`: `n` numbers, tangent dimension `n`, ⊕ is `+`.
/// * `So3`: 9 numbers, the rotation matrix column-major; tangent dimension 3.
/// * `UnitQuaternion`: 4 numbers `[w, x, y, z]` (Hamilton); tangent dimension 3.
/// * `Se3`: 7 numbers `[qw, qx, qy, qz, tx, ty, tz]`; tangent dimension 6, ordered `[ω; ρ]`.
///
/// ⊕ is the RIGHT perturbation `X ⊕ δ = X·Exp(δ)` and `Y ⊖ X = Log(X⁻¹·Y)` (the geometry
/// crate's `so3_plus`, `quat_plus`, `se3_plus` and their `*_minus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Manifold {
    /// Rⁿ.
    Euclidean(usize),
    /// SO(3) stored as a column-major rotation matrix.
    So3,
    /// SO(3) stored as a unit quaternion `[w, x, y, z]`.
    UnitQuaternion,
    /// SE(3) stored as `[qw, qx, qy, qz, tx, ty, tz]`.
    Se3,
    /// SE(2) stored as `[x, y, θ]`; tangent `[ρx, ρy, θ]` (see [`super::se2`]).
    Se2,
}

/// Tolerance on ‖q‖ − 1 and on ‖RᵀR − I‖ when validating stored values.
const UNIT_TOL: f64 = 1e-6;

impl Manifold {
    /// Number of stored numbers.
    pub fn ambient_dim(&self) -> usize {
        match self {
            Manifold::Euclidean(n) => *n,
            Manifold::So3 => 9,
            Manifold::UnitQuaternion => 4,
            Manifold::Se3 => 7,
            Manifold::Se2 => 3,
        }
    }

    /// Dimension of the tangent space (degrees of freedom).
    pub fn tangent_dim(&self) -> usize {
        match self {
            Manifold::Euclidean(n) => *n,
            Manifold::So3 | Manifold::UnitQuaternion => 3,
            Manifold::Se3 => 6,
            Manifold::Se2 => 3,
        }
    }

    /// Checks stored values (length, finiteness, unit norm / orthonormality) and returns them
    /// normalised (quaternions rescaled to unit norm, rotations re-orthonormalised).
    pub fn validate(&self, values: &[f64], what: &str) -> Result<Vec<f64>> {
        if values.len() != self.ambient_dim() {
            return Err(EstimateError::DimensionMismatch {
                what: format!("{what} ({self:?})"),
                expected: vec![self.ambient_dim()],
                got: vec![values.len()],
            });
        }
        if let Some((index, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: what.to_string(),
                index,
                value,
            });
        }
        match self {
            Manifold::Euclidean(0) => Err(EstimateError::InvalidProblem(format!(
                "{what}: a Euclidean block needs at least one dimension"
            ))),
            Manifold::Euclidean(_) => Ok(values.to_vec()),
            Manifold::Se2 => Ok(vec![
                values[0],
                values[1],
                super::se2::wrap_angle(values[2]),
            ]),
            Manifold::So3 => {
                let m = Matrix3::from_column_slice(values);
                let err = (m.transpose() * m - Matrix3::identity()).norm();
                if err > UNIT_TOL || m.determinant() <= 0.0 {
                    return Err(EstimateError::InvalidProblem(format!(
                        "{what}: not a rotation matrix (‖RᵀR − I‖ = {err:.3e}, det = {:.6})",
                        m.determinant()
                    )));
                }
                let r = Rotation3::from_matrix_eps(&m, 1e-15, 20, Rotation3::identity());
                Ok(so3_to_params(&r).to_vec())
            }
            Manifold::UnitQuaternion | Manifold::Se3 => {
                let n = values[..4].iter().map(|v| v * v).sum::<f64>().sqrt();
                if (n - 1.0).abs() > UNIT_TOL {
                    return Err(EstimateError::InvalidProblem(format!(
                        "{what}: quaternion norm {n} is not 1 (tolerance {UNIT_TOL:e})"
                    )));
                }
                let mut out = values.to_vec();
                out[..4].iter_mut().for_each(|v| *v /= n);
                Ok(out)
            }
        }
    }

    /// `out = x ⊕ delta` (right perturbation). Slices must have the ambient / tangent sizes.
    pub fn plus(&self, x: &[f64], delta: &[f64], out: &mut [f64]) {
        match self {
            Manifold::Euclidean(_) => {
                for ((o, a), d) in out.iter_mut().zip(x).zip(delta) {
                    *o = a + d;
                }
            }
            Manifold::So3 => {
                let r = so3_plus(&so3_from_params(x), &vec3(delta));
                out.copy_from_slice(&so3_to_params(&r));
            }
            Manifold::UnitQuaternion => {
                let q = quat_plus(&quat_from_params(x), &vec3(delta));
                out.copy_from_slice(&[q.w, q.i, q.j, q.k]);
            }
            Manifold::Se3 => {
                let xi =
                    Vector6::from_iterator(delta.iter().copied().chain(std::iter::repeat(0.0)));
                let t = se3_plus(&se3_from_params(x), &xi);
                out.copy_from_slice(&se3_to_params(&t));
            }
            Manifold::Se2 => {
                let (x, d) = (
                    super::se2::se2_from_slice(x),
                    super::se2::se2_from_slice(delta),
                );
                out.copy_from_slice(&super::se2::se2_plus(&x, &d));
            }
        }
    }

    /// `out = y ⊖ x = Log(x⁻¹·y)` (tangent at `x`).
    pub fn minus(&self, y: &[f64], x: &[f64], out: &mut [f64]) {
        match self {
            Manifold::Euclidean(_) => {
                for ((o, a), b) in out.iter_mut().zip(y).zip(x) {
                    *o = a - b;
                }
            }
            Manifold::So3 => {
                let d = so3_minus(&so3_from_params(y), &so3_from_params(x));
                out.copy_from_slice(d.as_slice());
            }
            Manifold::UnitQuaternion => {
                let d = quat_minus(&quat_from_params(y), &quat_from_params(x));
                out.copy_from_slice(d.as_slice());
            }
            Manifold::Se3 => {
                let d = se3_minus(&se3_from_params(y), &se3_from_params(x));
                out.copy_from_slice(d.as_slice());
            }
            Manifold::Se2 => {
                let (y, x) = (super::se2::se2_from_slice(y), super::se2::se2_from_slice(x));
                out.copy_from_slice(&super::se2::se2_minus(&y, &x));
            }
        }
    }
}

fn vec3(d: &[f64]) -> Vector3<f64> {
    Vector3::new(at(d, 0, 0.0), at(d, 1, 0.0), at(d, 2, 0.0))
}

/// Reads `p[i]`, or `default` if the slice is too short (never panics).
fn at(p: &[f64], i: usize, default: f64) -> f64 {
    p.get(i).copied().unwrap_or(default)
}

/// The unit quaternion stored as `[w, x, y, z]` (renormalised).
pub fn quat_from_params(p: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(
        at(p, 0, 1.0),
        at(p, 1, 0.0),
        at(p, 2, 0.0),
        at(p, 3, 0.0),
    ))
}

/// The pose stored as `[qw, qx, qy, qz, tx, ty, tz]` (layout of [`Manifold::Se3`]). Missing
/// trailing numbers read as the identity; the quaternion is renormalised.
pub fn se3_from_params(p: &[f64]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(at(p, 4, 0.0), at(p, 5, 0.0), at(p, 6, 0.0)),
        quat_from_params(p),
    )
}

/// The stored layout `[qw, qx, qy, qz, tx, ty, tz]` of a pose.
pub fn se3_to_params(t: &Isometry3<f64>) -> [f64; 7] {
    let q = t.rotation;
    let v = t.translation.vector;
    [q.w, q.i, q.j, q.k, v.x, v.y, v.z]
}

/// The rotation stored column-major (layout of [`Manifold::So3`]). Missing numbers read as
/// the identity's.
pub fn so3_from_params(p: &[f64]) -> Rotation3<f64> {
    let id = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let m = Matrix3::from_fn(|r, c| at(p, 3 * c + r, id[3 * c + r]));
    Rotation3::from_matrix_unchecked(m)
}

/// The column-major layout of a rotation matrix.
pub fn so3_to_params(r: &Rotation3<f64>) -> [f64; 9] {
    let mut out = [0.0; 9];
    out.copy_from_slice(r.matrix().as_slice());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::lie::se3_exp;

    #[test]
    fn plus_minus_round_trip_on_every_manifold() {
        let t = se3_exp(&Vector6::new(0.3, -0.2, 0.5, 1.0, -2.0, 0.5));
        let cases: Vec<(Manifold, Vec<f64>)> = vec![
            (Manifold::Euclidean(2), vec![1.0, -3.0]),
            (
                Manifold::So3,
                so3_to_params(&t.rotation.to_rotation_matrix()).to_vec(),
            ),
            (Manifold::UnitQuaternion, se3_to_params(&t)[..4].to_vec()),
            (Manifold::Se3, se3_to_params(&t).to_vec()),
        ];
        for (m, x) in cases {
            let x = m.validate(&x, "x").unwrap();
            let d: Vec<f64> = (0..m.tangent_dim())
                .map(|i| 0.1 * (i as f64) - 0.2)
                .collect();
            let mut y = vec![0.0; m.ambient_dim()];
            m.plus(&x, &d, &mut y);
            let mut back = vec![0.0; m.tangent_dim()];
            m.minus(&y, &x, &mut back);
            for (a, b) in back.iter().zip(&d) {
                assert!((a - b).abs() < 1e-12, "{m:?}: {back:?} vs {d:?}");
            }
        }
    }

    #[test]
    fn se3_plus_is_right_multiplication_by_exp() {
        let t = se3_exp(&Vector6::new(0.3, -0.2, 0.5, 1.0, -2.0, 0.5));
        let d = Vector6::new(0.01, 0.02, -0.03, 0.1, 0.0, -0.1);
        let mut y = [0.0; 7];
        Manifold::Se3.plus(&se3_to_params(&t), d.as_slice(), &mut y);
        let want = t * se3_exp(&d);
        assert!((se3_from_params(&y).to_homogeneous() - want.to_homogeneous()).norm() < 1e-12);
    }

    #[test]
    fn validation_rejects_bad_values() {
        assert!(Manifold::Se3.validate(&[1.0, 0.0], "p").is_err());
        assert!(
            Manifold::UnitQuaternion
                .validate(&[2.0, 0.0, 0.0, 0.0], "q")
                .is_err()
        );
        assert!(
            Manifold::So3
                .validate(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0], "r")
                .is_err()
        );
        assert!(Manifold::Euclidean(1).validate(&[f64::NAN], "e").is_err());
        assert!(Manifold::Euclidean(0).validate(&[], "e").is_err());
    }
}
