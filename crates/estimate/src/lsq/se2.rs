//! SE(2): planar poses as least-squares parameter blocks, and the relative-pose (between)
//! residual of a 2-D pose graph (seed 004_815695db12a6b16c.txt §2.1: "the edges represent
//! constraints between two poses that determine their relative position, including a
//! covariance"; Solà, Deray & Atchuthan, "A micro Lie theory", Example 5 and App. C).
//!
//! Stored layout `[x, y, θ]` (θ wrapped to (−π, π]); tangent `[ρx, ρy, θ]`; ⊕ is the right
//! perturbation `X ⊕ δ = X·Exp(δ)`, `Y ⊖ X = Log(X⁻¹·Y)` like every manifold of this module.

use nalgebra::{DMatrix, Matrix3, Vector3};

use super::problem::Residual;
use crate::{EstimateError, Result};

/// Wraps an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

/// Below this |θ| the closed form `(θ − sin θ)/θ³` is replaced by its Taylor series.
///
/// Derivation (unit roundoff u = 2⁻⁵³ ≈ 1.1e-16): `sin θ` carries an absolute rounding error
/// of about u·|θ|, and `θ − sin θ ≈ θ³/6`, so the closed form has a relative error of about
/// 6u/θ² (1e-7 at θ = 1e-4, the precision loss the pose-graph Jacobian suffered). The series
/// of [`THETA_MINUS_SIN_SERIES`] stops after the θ¹⁰ term, so its relative truncation error
/// is about 6·θ¹²/15!. The two are equal where θ¹⁴ = u·15!, θ ≈ 0.53; at the threshold 0.5
/// the closed form's error is 6u/0.25 ≈ 2.7e-15 and the series' 6·0.5¹²/15! ≈ 1.1e-15, so
/// neither branch is worse than a few ulp anywhere. The test
/// `right_jacobian_matches_its_power_series` pins this against an independent sum.
const SE2_SERIES_ANGLE: f64 = 0.5;

/// `(−1)^k / (2k+3)!` for k = 0..5: the series of `(θ − sin θ)/θ³` in θ².
const THETA_MINUS_SIN_SERIES: [f64; 6] = [
    1.0 / 6.0,
    -1.0 / 120.0,
    1.0 / 5040.0,
    -1.0 / 362_880.0,
    1.0 / 39_916_800.0,
    -1.0 / 6_227_020_800.0,
];

/// `sin θ / θ`. The quotient has no cancellation (relative error ≈ 2u at every θ ≠ 0); the
/// series `1 − θ²/6 + θ⁴/120` only avoids 0/0 and is used below 1e-3, where its truncation
/// error θ⁶/5040 < 2e-22 is far below u.
fn sinc(th: f64) -> f64 {
    if th.abs() < 1e-3 {
        let t2 = th * th;
        1.0 - t2 / 6.0 * (1.0 - t2 / 20.0)
    } else {
        th.sin() / th
    }
}

/// `(1 − cos θ)/θ²`, computed as `½·sinc(θ/2)²` (= 2 sin²(θ/2)/θ²): no cancellation, so no
/// threshold (the textbook `1 − cos θ` loses all digits below θ ≈ 1e-8).
fn one_minus_cos_sq(th: f64) -> f64 {
    let s = sinc(0.5 * th);
    0.5 * s * s
}

/// `(θ − sin θ)/θ³`, the series below [`SE2_SERIES_ANGLE`].
fn theta_minus_sin_cu(th: f64) -> f64 {
    if th.abs() < SE2_SERIES_ANGLE {
        let t2 = th * th;
        THETA_MINUS_SIN_SERIES
            .iter()
            .rev()
            .fold(0.0, |acc, &c| acc * t2 + c)
    } else {
        (th - th.sin()) / (th * th * th)
    }
}

/// `(sin θ / θ, (1 − cos θ) / θ)`, accurate to a few ulp at every θ.
fn sinc_terms(th: f64) -> (f64, f64) {
    (sinc(th), th * one_minus_cos_sq(th))
}

/// Exp: tangent `[ρx, ρy, θ]` → pose `[x, y, θ]`, `t = V(θ)·ρ` (Solà eq. (156)).
pub fn se2_exp(d: &[f64; 3]) -> [f64; 3] {
    let (a, b) = sinc_terms(d[2]);
    [a * d[0] - b * d[1], b * d[0] + a * d[1], wrap_angle(d[2])]
}

/// Log: pose → tangent, `ρ = V(θ)⁻¹·t` (inverse of [`se2_exp`] for θ ∈ (−π, π]).
pub fn se2_log(x: &[f64; 3]) -> [f64; 3] {
    let th = wrap_angle(x[2]);
    let (a, b) = sinc_terms(th);
    let det = a * a + b * b;
    [
        (a * x[0] + b * x[1]) / det,
        (-b * x[0] + a * x[1]) / det,
        th,
    ]
}

/// Composition `a·b`.
pub fn se2_compose(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    let (s, c) = a[2].sin_cos();
    [
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        wrap_angle(a[2] + b[2]),
    ]
}

/// Inverse `a⁻¹`.
pub fn se2_inverse(a: &[f64; 3]) -> [f64; 3] {
    let (s, c) = a[2].sin_cos();
    [
        -(c * a[0] + s * a[1]),
        s * a[0] - c * a[1],
        wrap_angle(-a[2]),
    ]
}

/// The relative pose `a⁻¹·b` (b in the frame of a).
pub fn se2_between(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    se2_compose(&se2_inverse(a), b)
}

/// `x ⊕ δ = x·Exp(δ)`.
pub fn se2_plus(x: &[f64; 3], d: &[f64; 3]) -> [f64; 3] {
    se2_compose(x, &se2_exp(d))
}

/// `y ⊖ x = Log(x⁻¹·y)`.
pub fn se2_minus(y: &[f64; 3], x: &[f64; 3]) -> [f64; 3] {
    se2_log(&se2_between(x, y))
}

/// The adjoint `Ad_X = [[R, (y, −x)ᵀ], [0, 1]]` (Solà eq. (159)).
pub fn se2_adjoint(x: &[f64; 3]) -> Matrix3<f64> {
    let (s, c) = x[2].sin_cos();
    Matrix3::new(c, -s, x[1], s, c, -x[0], 0.0, 0.0, 1.0)
}

/// The right Jacobian `J_r(δ)` of SE(2) (Solà eq. (163)):
///
/// `J_r = [[A, B, ρ₁D − ρ₂C], [−B, A, ρ₁C + ρ₂D], [0, 0, 1]]` with `A = sin θ/θ`,
/// `B = (1 − cos θ)/θ`, `C = (1 − cos θ)/θ²`, `D = (θ − sin θ)/θ²` — eq. (163)'s third
/// column regrouped so that each coefficient is evaluated without cancellation (see
/// [`SE2_SERIES_ANGLE`]); at θ = 0 it is `I − ½ ad(δ)` exactly.
pub fn se2_right_jacobian(d: &[f64; 3]) -> Matrix3<f64> {
    let (r1, r2, th) = (d[0], d[1], d[2]);
    let a = sinc(th);
    let c = one_minus_cos_sq(th);
    let b = th * c;
    let dd = th * theta_minus_sin_cu(th);
    Matrix3::new(
        a,
        b,
        r1 * dd - r2 * c,
        -b,
        a,
        r1 * c + r2 * dd,
        0.0,
        0.0,
        1.0,
    )
}

/// `J_r(δ)⁻¹` (3×3 inverse of [`se2_right_jacobian`]; regular for |θ| < 2π).
pub fn se2_right_jacobian_inv(d: &[f64; 3]) -> Matrix3<f64> {
    se2_right_jacobian(d)
        .try_inverse()
        .unwrap_or_else(Matrix3::identity)
}

/// Reads a stored SE(2) value (missing numbers read as the identity's).
pub(crate) fn se2_from_slice(p: &[f64]) -> [f64; 3] {
    [
        p.first().copied().unwrap_or(0.0),
        p.get(1).copied().unwrap_or(0.0),
        p.get(2).copied().unwrap_or(0.0),
    ]
}

/// The whitened between residual of a 2-D pose graph edge `z` (the pose of node j in the
/// frame of node i) with covariance Σ = L Lᵀ on the tangent at `z`:
///
/// `r = L⁻¹ · Log(z⁻¹ · xᵢ⁻¹ · xⱼ)`
///
/// Jacobians (right perturbations): `∂r/∂δⱼ = L⁻¹ J_r⁻¹(e)`,
/// `∂r/∂δᵢ = −L⁻¹ J_r⁻¹(e) Ad(xⱼ⁻¹ xᵢ)`.
#[derive(Debug, Clone)]
pub struct Se2BetweenResidual {
    z: [f64; 3],
    sqrt_info: Matrix3<f64>,
}

impl Se2BetweenResidual {
    /// An edge with measurement `z = [x, y, θ]` and its 3×3 covariance (symmetric positive
    /// definite, finite).
    pub fn new(z: [f64; 3], covariance: &Matrix3<f64>) -> Result<Self> {
        if let Some((index, &value)) = z
            .iter()
            .chain(covariance.iter())
            .enumerate()
            .find(|(_, v)| !v.is_finite())
        {
            return Err(EstimateError::NonFiniteInput {
                what: "SE(2) edge (measurement, covariance)".into(),
                index,
                value,
            });
        }
        let asym = (covariance - covariance.transpose()).amax() / covariance.amax().max(1e-300);
        let chol = if asym <= 1e-9 {
            nalgebra::Cholesky::new(*covariance)
        } else {
            None
        };
        let Some(chol) = chol else {
            return Err(EstimateError::InvalidCovariance {
                what: "SE(2) edge covariance".into(),
                asymmetry: asym,
                min_eigenvalue: covariance.symmetric_eigenvalues().min(),
            });
        };
        let sqrt_info = chol
            .l()
            .try_inverse()
            .ok_or_else(|| EstimateError::InvalidCovariance {
                what: "SE(2) edge covariance".into(),
                asymmetry: asym,
                min_eigenvalue: 0.0,
            })?;
        Ok(Self {
            z: [z[0], z[1], wrap_angle(z[2])],
            sqrt_info,
        })
    }

    /// The measurement.
    pub fn measurement(&self) -> [f64; 3] {
        self.z
    }
}

impl Residual for Se2BetweenResidual {
    fn dim(&self) -> usize {
        3
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        if params.len() != 2 {
            return Err(EstimateError::InvalidProblem(format!(
                "an SE(2) between residual reads 2 blocks, got {}",
                params.len()
            )));
        }
        let xi = se2_from_slice(params[0]);
        let xj = se2_from_slice(params[1]);
        let rel = se2_between(&xi, &xj);
        let e = se2_log(&se2_between(&self.z, &rel));
        let r = self.sqrt_info * Vector3::from(e);
        residual.copy_from_slice(r.as_slice());
        if let Some(jac) = jacobians {
            let jr_inv = se2_right_jacobian_inv(&e);
            let jj = self.sqrt_info * jr_inv;
            let ji = -(jj * se2_adjoint(&se2_inverse(&rel)));
            if let Some(j0) = jac.get_mut(0) {
                *j0 = DMatrix::from_column_slice(3, 3, ji.as_slice());
            }
            if let Some(j1) = jac.get_mut(1) {
                *j1 = DMatrix::from_column_slice(3, 3, jj.as_slice());
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Manifold, PriorResidual};
    use super::*;

    /// Central differences of `r` on each block's tangent, through `Manifold::Se2.plus`.
    fn fd(r: &dyn Residual, params: &[[f64; 3]]) -> Vec<Matrix3<f64>> {
        let h = 1e-6;
        (0..params.len())
            .map(|b| {
                let mut j = Matrix3::zeros();
                for i in 0..3 {
                    let mut cols = [[0.0; 3]; 2];
                    for (s, col) in [h, -h].iter().zip(cols.iter_mut()) {
                        let mut d = [0.0; 3];
                        d[i] = *s;
                        let mut moved = params.to_vec();
                        Manifold::Se2.plus(&params[b], &d, &mut moved[b]);
                        let views: Vec<&[f64]> = moved.iter().map(|v| v.as_slice()).collect();
                        r.evaluate(&views, col, None).unwrap();
                    }
                    for row in 0..3 {
                        j[(row, i)] = (cols[0][row] - cols[1][row]) / (2.0 * h);
                    }
                }
                j
            })
            .collect()
    }

    fn analytic(r: &dyn Residual, params: &[[f64; 3]]) -> Vec<Matrix3<f64>> {
        let mut res = vec![0.0; 3];
        let mut jac = vec![DMatrix::zeros(3, 3); params.len()];
        let views: Vec<&[f64]> = params.iter().map(|v| v.as_slice()).collect();
        r.evaluate(&views, &mut res, Some(&mut jac)).unwrap();
        jac.iter()
            .map(|j| Matrix3::from_column_slice(j.as_slice()))
            .collect()
    }

    #[test]
    fn exp_log_inverse_and_associativity() {
        for d in [
            [0.3, -1.2, 0.7],
            [2.0, 0.5, -3.0],
            [1e-9, 2e-9, 1e-10],
            [0.0, 0.0, 0.0],
        ] {
            let x = se2_exp(&d);
            let back = se2_log(&x);
            for k in 0..3 {
                assert!((back[k] - d[k]).abs() < 1e-12, "{d:?} -> {back:?}");
            }
        }
        let (a, b, c) = ([1.0, 2.0, 0.3], [-0.5, 0.7, 2.9], [3.0, -1.0, -2.0]);
        let l = se2_compose(&se2_compose(&a, &b), &c);
        let r = se2_compose(&a, &se2_compose(&b, &c));
        assert!(l.iter().zip(&r).all(|(x, y)| (x - y).abs() < 1e-12));
        let id = se2_compose(&a, &se2_inverse(&a));
        assert!(id.iter().all(|v| v.abs() < 1e-12));
        // Exp of a pure rotation about the origin, and of a quarter-turn arc: closed forms.
        let e = se2_exp(&[
            std::f64::consts::FRAC_PI_2,
            0.0,
            std::f64::consts::FRAC_PI_2,
        ]);
        assert!((e[0] - 1.0).abs() < 1e-12 && (e[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn plus_minus_round_trip_and_wrap() {
        let x = Manifold::Se2.validate(&[1.0, -2.0, 7.0], "x").unwrap();
        assert!((x[2] - wrap_angle(7.0)).abs() < 1e-15 && x[2] <= std::f64::consts::PI);
        let d = [0.2, -0.1, 0.4];
        let mut y = [0.0; 3];
        Manifold::Se2.plus(&x, &d, &mut y);
        let mut back = [0.0; 3];
        Manifold::Se2.minus(&y, &x, &mut back);
        assert!(back.iter().zip(&d).all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(Manifold::Se2.validate(&[0.0, f64::NAN, 0.0], "x").is_err());
    }

    /// `J_r(τ) = Σ_k (−ad τ)^k / (k+1)!` summed term by term (Solà eq. (41) with the se(2)
    /// adjoint `ad τ = [[0, −θ, ρ₂], [θ, 0, −ρ₁], [0, 0, 0]]`): an evaluation independent of
    /// eq. (163)'s closed form and of its series branch.
    fn right_jacobian_by_power_series(d: &[f64; 3]) -> Matrix3<f64> {
        let ad = Matrix3::new(0.0, -d[2], d[1], d[2], 0.0, -d[0], 0.0, 0.0, 0.0);
        let mut term = Matrix3::identity();
        let mut sum = Matrix3::identity();
        for k in 1..60 {
            let next: Matrix3<f64> = term * ad;
            term = next * (-1.0 / (k as f64 + 1.0));
            sum += term;
        }
        sum
    }

    #[test]
    fn right_jacobian_matches_its_power_series() {
        // Both sides of the series threshold, and the angles where the old closed form lost
        // digits (6u/θ² relative error: 7e-9 at θ = 1e-4, 7e-3 at θ = 1e-7).
        for th in [
            0.0, 1e-12, 1e-8, 1e-7, 1e-5, 1e-4, 1e-3, 0.1, 0.4999, 0.5, 0.5001, 1.3, -2.7,
        ] {
            let tau = [1.7, -0.8, th];
            let jr = se2_right_jacobian(&tau);
            let truth = right_jacobian_by_power_series(&tau);
            let err = (jr - truth).amax();
            assert!(
                err < 1e-14,
                "θ = {th:e}: |J_r − series| = {err:e}\n{jr}\n{truth}"
            );
        }
    }

    #[test]
    fn right_jacobian_matches_finite_differences() {
        // Exp(τ + δ) ≈ Exp(τ)·Exp(J_r(τ) δ).
        for tau in [
            [0.4, -0.3, 1.1],
            [1.0, 2.0, 1e-8],
            [1.0, 2.0, 3e-5],
            [-2.0, 0.5, -2.5],
        ] {
            let jr = se2_right_jacobian(&tau);
            let h = 1e-6;
            for i in 0..3 {
                let mut tp = tau;
                tp[i] += h;
                let mut tm = tau;
                tm[i] -= h;
                let dp = se2_minus(&se2_exp(&tp), &se2_exp(&tau));
                let dm = se2_minus(&se2_exp(&tm), &se2_exp(&tau));
                for row in 0..3 {
                    let num = (dp[row] - dm[row]) / (2.0 * h);
                    assert!((num - jr[(row, i)]).abs() < 1e-6, "{tau:?} ({row},{i})");
                }
            }
        }
    }

    #[test]
    fn between_residual_jacobians_match_finite_differences() {
        let cov = Matrix3::new(0.04, 0.01, 0.0, 0.01, 0.09, 0.002, 0.0, 0.002, 0.01);
        for (xi, xj, z) in [
            ([1.0, 2.0, 0.3], [2.5, 1.0, -0.4], [1.2, -1.5, -0.6]),
            ([-3.0, 0.5, 3.0], [-1.0, 0.0, -3.0], [0.4, 2.0, 0.2]),
            ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ] {
            let r = Se2BetweenResidual::new(z, &cov).unwrap();
            let a = analytic(&r, &[xi, xj]);
            let n = fd(&r, &[xi, xj]);
            for (ja, jn) in a.iter().zip(&n) {
                assert!((ja - jn).amax() < 1e-6, "{ja} vs {jn}");
            }
        }
        let mean = [0.5, -0.5, 2.0];
        let prior = PriorResidual::new(
            Manifold::Se2,
            &mean,
            &DMatrix::from_column_slice(3, 3, cov.as_slice()),
        )
        .unwrap();
        let x = [1.0, 0.2, -2.8];
        let a = analytic(&prior, &[x]);
        let n = fd(&prior, &[x]);
        assert!((a[0] - n[0]).amax() < 1e-6, "{} vs {}", a[0], n[0]);
    }

    #[test]
    fn pose_graph_square_with_a_closure_is_solved() {
        // Four poses around a 2 m square, odometry with a heading error, one closure: the
        // solve returns the truth within the closure's precision.
        use super::super::{Loss, Problem, SolverOptions};
        use std::f64::consts::{FRAC_PI_2, PI};
        let truth = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, FRAC_PI_2],
            [2.0, 2.0, PI],
            [0.0, 2.0, -FRAC_PI_2],
        ];
        let mut p = Problem::new();
        let mut x = truth[0];
        let blocks: Vec<_> = (0..4)
            .map(|k| {
                if k > 0 {
                    let z = se2_between(&truth[k - 1], &truth[k]);
                    x = se2_compose(&x, &[z[0], z[1], z[2] + 0.2]);
                }
                p.add_block(&x, Manifold::Se2).unwrap()
            })
            .collect();
        let tight = Matrix3::from_diagonal_element(1e-4);
        let odo = Matrix3::from_diagonal(&Vector3::new(1e-2, 1e-2, 1e-1));
        p.add_prior(
            blocks[0],
            &truth[0],
            &DMatrix::from_column_slice(3, 3, tight.as_slice()),
        )
        .unwrap();
        for k in 1..4 {
            let z = se2_between(&truth[k - 1], &truth[k]);
            p.add_residual(
                Se2BetweenResidual::new(z, &odo).unwrap(),
                &[blocks[k - 1], blocks[k]],
                Loss::Trivial,
            )
            .unwrap();
        }
        let z = se2_between(&truth[3], &truth[0]);
        p.add_residual(
            Se2BetweenResidual::new(z, &tight).unwrap(),
            &[blocks[3], blocks[0]],
            Loss::Trivial,
        )
        .unwrap();
        p.solve(&SolverOptions::default()).unwrap();
        for (b, t) in blocks.iter().zip(&truth) {
            let v = p.values(*b);
            let d = se2_minus(&se2_from_slice(v), t);
            assert!(d.iter().all(|e| e.abs() < 1e-3), "{v:?} vs {t:?}");
        }
    }
}
