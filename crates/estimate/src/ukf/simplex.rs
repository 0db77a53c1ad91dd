//! Julier's spherical simplex sigma points and their weights.

use nalgebra::{DMatrix, DVector};

use super::family::filled_weights;
use crate::{EstimateError, Result};

/// The spherical simplex sigma points of Julier (2003) for an `n`-dimensional Gaussian (the
/// unscented transform behind the UKF of seed 000_3b1454b2b2194811.txt §5.2), as filterpy's
/// `SimplexSigmaPoints`: n + 1 points `x ⊕ L cⱼ` with equal weights `1/(n+1)`, where
/// `L Lᵀ = P` (lower Cholesky factor) and `cⱼ` is column j of the unit simplex matrix
/// `C = √n · C*`. `C*` (n × (n+1)) is built row by row with λ = n/(n+1):
/// row 1 is `[−1/√(2λ), 1/√(2λ), 0, …]`; row d (d = 2…n) has `1/√(λ d (d+1))` in its first d
/// entries, `−d/√(λ d (d+1))` in entry d + 1 and zeros after. Its columns sum to zero and
/// `C Cᵀ /(n+1) = I`, so the points reproduce the mean and covariance exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct SimplexSigmaPoints {
    n: usize,
    w: DVector<f64>,
    unit: DMatrix<f64>,
}

impl SimplexSigmaPoints {
    /// Simplex sigma points for dimension `n ≥ 1`.
    pub fn new(n: usize) -> Result<Self> {
        if n == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "n",
                value: 0.0,
                reason: "the state dimension must be at least 1",
            });
        }
        let nf = n as f64;
        let lambda = nf / (nf + 1.0);
        // The n × (n + 1) unit simplex: n comes from the caller, so the buffer is fallible.
        let cells = n
            .checked_add(1)
            .and_then(|m| m.checked_mul(n))
            .unwrap_or(usize::MAX);
        let zeros = autoteach_geometry::alloc::try_filled("simplex sigma points", cells, 0.0)?;
        let mut unit = DMatrix::from_vec(n, n + 1, zeros);
        let a = 1.0 / (2.0 * lambda).sqrt();
        unit[(0, 0)] = -a;
        unit[(0, 1)] = a;
        for d in 2..=n {
            let df = d as f64;
            let s = 1.0 / (lambda * df * (df + 1.0)).sqrt();
            for j in 0..d {
                unit[(d - 1, j)] = s;
            }
            unit[(d - 1, d)] = -df * s;
        }
        unit *= nf.sqrt();
        Ok(Self {
            n,
            w: filled_weights(n.checked_add(1), 1.0 / (nf + 1.0))?,
            unit,
        })
    }

    /// The dimension n.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of sigma points, n + 1.
    pub fn num_sigmas(&self) -> usize {
        self.n + 1
    }

    /// The weights Wm = Wc (all `1/(n+1)`).
    pub fn wm(&self) -> &DVector<f64> {
        &self.w
    }

    /// The covariance weights (equal to Wm).
    pub fn wc(&self) -> &DVector<f64> {
        &self.w
    }

    /// The unit simplex matrix C (n × (n+1)): sigma point j is `x ⊕ L C[:, j]`.
    pub fn unit(&self) -> &DMatrix<f64> {
        &self.unit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_simplex_is_centred_and_whitening() {
        for n in 1..7 {
            let s = SimplexSigmaPoints::new(n).unwrap();
            let c = s.unit();
            // Columns sum to zero: the mean is reproduced.
            for i in 0..n {
                assert!(c.row(i).sum().abs() < 1e-12);
            }
            // Σ w cⱼ cⱼᵀ = I: the covariance is reproduced.
            let cov = c * c.transpose() / (n as f64 + 1.0);
            assert!(
                (cov - DMatrix::<f64>::identity(n, n)).amax() < 1e-12,
                "n = {n}"
            );
        }
    }

    #[test]
    fn one_dimension_is_plus_minus_one_sigma() {
        let s = SimplexSigmaPoints::new(1).unwrap();
        // λ = 1/2, so C* = [−1, 1] and C = [−1, 1].
        assert!((s.unit()[(0, 0)] + 1.0).abs() < 1e-15);
        assert!((s.unit()[(0, 1)] - 1.0).abs() < 1e-15);
        assert!(SimplexSigmaPoints::new(0).is_err());
    }
}
