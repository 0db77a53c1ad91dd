//! Van der Merwe's scaled sigma points and their weights.

use nalgebra::{DMatrix, DVector};

use super::family::filled_weights;
use super::linalg;
use crate::{EstimateError, Result};

/// Van der Merwe's scaled sigma points for an `n`-dimensional Gaussian (the unscented
/// transform behind the UKF of seed 000_3b1454b2b2194811.txt §5.2, eqs. (5.1)–(5.2)).
///
/// With λ = α²(n + κ) − n the weights are, exactly as in filterpy's
/// `MerweScaledSigmaPoints`:
/// `Wm₀ = λ/(n+λ)`, `Wc₀ = Wm₀ + 1 − α² + β`, `Wmᵢ = Wcᵢ = 1/(2(n+λ))` for i = 1…2n.
/// The 2n + 1 points are `χ₀ = x`, `χₖ₊₁ = x ⊕ Lₖ`, `χₙ₊ₖ₊₁ = x ⊕ (−Lₖ)`, where `Lₖ` is
/// column k of the lower Cholesky factor of `(n+λ)P` — the rows of filterpy's upper factor,
/// in the same order.
#[derive(Debug, Clone, PartialEq)]
pub struct MerweScaledSigmaPoints {
    n: usize,
    alpha: f64,
    beta: f64,
    kappa: f64,
    lambda: f64,
    wm: DVector<f64>,
    wc: DVector<f64>,
}

impl MerweScaledSigmaPoints {
    /// Sigma points for dimension `n ≥ 1` with spread `alpha > 0`, prior-knowledge `beta`
    /// (2 is optimal for Gaussians) and secondary scaling `kappa` (often `3 − n` or 0).
    /// Fails unless `n + λ = α²(n + κ) > 0` and all parameters are finite.
    pub fn new(n: usize, alpha: f64, beta: f64, kappa: f64) -> Result<Self> {
        if n == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "n",
                value: 0.0,
                reason: "the state dimension must be at least 1",
            });
        }
        for (name, value) in [("alpha", alpha), ("beta", beta), ("kappa", kappa)] {
            if !value.is_finite() {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value,
                    reason: "must be finite",
                });
            }
        }
        if alpha <= 0.0 {
            return Err(EstimateError::InvalidParameter {
                name: "alpha",
                value: alpha,
                reason: "must be positive",
            });
        }
        let nf = n as f64;
        let lambda = alpha * alpha * (nf + kappa) - nf;
        if (nf + lambda).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(EstimateError::InvalidParameter {
                name: "kappa",
                value: kappa,
                reason: "n + kappa must be positive (the sigma-point spread n + lambda = alpha^2 (n + kappa))",
            });
        }
        let c = 0.5 / (nf + lambda);
        let count = n.checked_mul(2).and_then(|m| m.checked_add(1));
        let mut wm = filled_weights(count, c)?;
        let mut wc = filled_weights(count, c)?;
        wm[0] = lambda / (nf + lambda);
        wc[0] = lambda / (nf + lambda) + (1.0 - alpha * alpha + beta);
        Ok(Self {
            n,
            alpha,
            beta,
            kappa,
            lambda,
            wm,
            wc,
        })
    }

    /// The same α, β, κ for another dimension (used for the augmented state).
    pub fn with_dim(&self, n: usize) -> Result<Self> {
        Self::new(n, self.alpha, self.beta, self.kappa)
    }

    /// The dimension n.
    pub fn n(&self) -> usize {
        self.n
    }

    /// α.
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// β.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// κ.
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// λ = α²(n + κ) − n.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// Number of sigma points, 2n + 1.
    pub fn num_sigmas(&self) -> usize {
        2 * self.n + 1
    }

    /// The mean weights Wm (length 2n + 1).
    pub fn wm(&self) -> &DVector<f64> {
        &self.wm
    }

    /// The covariance weights Wc (length 2n + 1).
    pub fn wc(&self) -> &DVector<f64> {
        &self.wc
    }

    /// Sigma points of (x, P) as the columns of an `n × (2n+1)` matrix, with plain vector
    /// addition. Fails for wrong sizes, NaN, or a P that is not symmetric positive definite.
    pub fn sigma_points(&self, x: &DVector<f64>, p: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        linalg::check_len(x, self.n, "state x")?;
        linalg::check_finite_input(x.as_slice(), "state x")?;
        let p = linalg::validate_covariance_input(p, self.n, "covariance P")?;
        let scaled = p * (self.n as f64 + self.lambda);
        let l = linalg::cholesky(&scaled).ok_or_else(|| EstimateError::InvalidCovariance {
            what: "covariance P".to_string(),
            asymmetry: 0.0,
            min_eigenvalue: linalg::min_eigenvalue(&scaled) / (self.n as f64 + self.lambda),
        })?;
        let mut out = DMatrix::zeros(self.n, self.num_sigmas());
        for k in 0..self.num_sigmas() {
            out.set_column(k, x);
        }
        for k in 0..self.n {
            let col = l.column(k);
            let mut plus = out.column_mut(k + 1);
            plus += col;
            let mut minus = out.column_mut(self.n + k + 1);
            minus -= col;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_follow_merwe_and_sum_to_one() {
        let pts = MerweScaledSigmaPoints::new(4, 0.1, 2.0, -1.0).unwrap();
        // λ = 0.01·3 − 4 = −3.97, n + λ = 0.03.
        assert!((pts.lambda() + 3.97).abs() < 1e-15);
        assert!((pts.wm()[0] - (-3.97 / 0.03)).abs() < 1e-10);
        assert!((pts.wc()[0] - (-3.97 / 0.03 + 1.0 - 0.01 + 2.0)).abs() < 1e-10);
        assert!((pts.wm()[1] - 0.5 / 0.03).abs() < 1e-10);
        assert!((pts.wm().sum() - 1.0).abs() < 1e-12);
        assert_eq!(pts.num_sigmas(), 9);
    }

    #[test]
    fn sigma_points_reproduce_mean_and_covariance() {
        let n = 5;
        let pts = MerweScaledSigmaPoints::new(n, 0.5, 2.0, 3.0 - n as f64).unwrap();
        let x = DVector::from_fn(n, |i, _| i as f64 - 1.5);
        let a = DMatrix::from_fn(n, n, |i, j| ((i + 2 * j) % 4) as f64 * 0.3 - 0.2);
        let p = &a * a.transpose() + DMatrix::identity(n, n) * 0.5;
        let s = pts.sigma_points(&x, &p).unwrap();
        let mean = &s * pts.wm();
        assert!((&mean - &x).amax() < 1e-12);
        let mut cov = DMatrix::zeros(n, n);
        for k in 0..s.ncols() {
            let d = s.column(k) - &mean;
            cov += pts.wc()[k] * &d * d.transpose();
        }
        // Σ Wc dd^T = P + (1 − α² + β)(χ₀ − x)(χ₀ − x)^T and χ₀ = x.
        assert!((&cov - &p).amax() < 1e-12);
        // Symmetric pairs around the mean.
        for k in 0..n {
            let sum = s.column(k + 1) + s.column(n + k + 1);
            assert!((sum - &x * 2.0).amax() < 1e-12);
        }
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        assert!(matches!(
            MerweScaledSigmaPoints::new(3, 1.0, 2.0, -3.0),
            Err(EstimateError::InvalidParameter { name: "kappa", .. })
        ));
        assert!(matches!(
            MerweScaledSigmaPoints::new(3, 0.0, 2.0, 0.0),
            Err(EstimateError::InvalidParameter { name: "alpha", .. })
        ));
        assert!(matches!(
            MerweScaledSigmaPoints::new(0, 1.0, 2.0, 0.0),
            Err(EstimateError::InvalidParameter { name: "n", .. })
        ));
        let pts = MerweScaledSigmaPoints::new(2, 1.0, 2.0, 1.0).unwrap();
        let bad = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(matches!(
            pts.sigma_points(&DVector::zeros(2), &bad),
            Err(EstimateError::InvalidCovariance { .. })
        ));
        assert!(matches!(
            pts.sigma_points(&DVector::zeros(3), &DMatrix::identity(2, 2)),
            Err(EstimateError::DimensionMismatch { .. })
        ));
    }
}
