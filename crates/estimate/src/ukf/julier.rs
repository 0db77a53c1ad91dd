//! Julier's symmetric sigma points and their weights.

use nalgebra::DVector;

use super::family::filled_weights;
use crate::{EstimateError, Result};

/// Julier & Uhlmann's symmetric sigma points for an `n`-dimensional Gaussian (the unscented
/// transform behind the UKF of seed 000_3b1454b2b2194811.txt §5.2, eqs. (5.1)–(5.2)), with
/// the weights of filterpy's `JulierSigmaPoints`:
/// `W₀ = κ/(n+κ)`, `Wᵢ = 1/(2(n+κ))` for i = 1…2n, and `Wc = Wm`.
/// The 2n + 1 points are `x`, `x ⊕ Lₖ`, `x ⊕ (−Lₖ)` with `Lₖ` the k-th column of the lower
/// Cholesky factor of `(n+κ)P` (the rows of filterpy's upper factor), in filterpy's order.
/// This is van der Merwe's scaled family at α = 1, β = 0, with λ = κ taken exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct JulierSigmaPoints {
    n: usize,
    kappa: f64,
    wm: DVector<f64>,
}

impl JulierSigmaPoints {
    /// Sigma points for dimension `n ≥ 1` with the spread `kappa` (`n + κ > 0`; 3 − n is
    /// Julier's choice for Gaussians, 0 filterpy's default).
    pub fn new(n: usize, kappa: f64) -> Result<Self> {
        if n == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "n",
                value: 0.0,
                reason: "the state dimension must be at least 1",
            });
        }
        if !kappa.is_finite() {
            return Err(EstimateError::InvalidParameter {
                name: "kappa",
                value: kappa,
                reason: "must be finite",
            });
        }
        let nf = n as f64;
        if (nf + kappa).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(EstimateError::InvalidParameter {
                name: "kappa",
                value: kappa,
                reason: "n + kappa must be positive (the sigma-point spread)",
            });
        }
        let count = n.checked_mul(2).and_then(|m| m.checked_add(1));
        let mut wm = filled_weights(count, 0.5 / (nf + kappa))?;
        wm[0] = kappa / (nf + kappa);
        Ok(Self { n, kappa, wm })
    }

    /// The dimension n.
    pub fn n(&self) -> usize {
        self.n
    }

    /// κ.
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// The spread n + κ (P is scaled by it before the square root).
    pub fn spread(&self) -> f64 {
        self.n as f64 + self.kappa
    }

    /// Number of sigma points, 2n + 1.
    pub fn num_sigmas(&self) -> usize {
        2 * self.n + 1
    }

    /// The mean weights Wm (length 2n + 1).
    pub fn wm(&self) -> &DVector<f64> {
        &self.wm
    }

    /// The covariance weights Wc (equal to Wm).
    pub fn wc(&self) -> &DVector<f64> {
        &self.wm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_follow_julier() {
        let pts = JulierSigmaPoints::new(3, 1.0).unwrap();
        assert!((pts.wm()[0] - 0.25).abs() < 1e-15);
        assert!((pts.wm()[1] - 0.125).abs() < 1e-15);
        assert!((pts.wm().sum() - 1.0).abs() < 1e-15);
        assert_eq!(pts.wm(), pts.wc());
        assert_eq!(pts.num_sigmas(), 7);
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        assert!(JulierSigmaPoints::new(0, 0.0).is_err());
        assert!(JulierSigmaPoints::new(2, -2.0).is_err());
        assert!(JulierSigmaPoints::new(2, f64::NAN).is_err());
    }
}
