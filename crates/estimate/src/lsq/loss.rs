//! Robust loss functions ρ(s) of the squared residual norm s = ‖r‖², and the IRLS
//! reweighting the solver applies (the robust M-estimators of seed 004_815695db12a6b16c.txt
//! ch. 3; cost = ½ Σ ρ(‖rᵢ‖²)).

use crate::{EstimateError, Result};

/// A robust loss ρ(s) of the squared norm s = ‖r‖² of one residual block, with ρ(s) ≈ s for
/// small s (ρ(0) = 0, ρ′(0) = 1). The scale `a > 0` is the residual norm where the loss
/// departs from the quadratic (same parameterisation as `scipy.optimize.least_squares`'
/// `f_scale` and Ceres' losses).
///
/// * `Trivial`: ρ(s) = s.
/// * `Huber(a)`: ρ(s) = s for s ≤ a², 2a√s − a² otherwise.
/// * `Cauchy(a)`: ρ(s) = a² ln(1 + s/a²).
/// * `Tukey(a)` (biweight): ρ(s) = a²/3 (1 − (1 − s/a²)³) for s ≤ a², a²/3 otherwise.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Loss {
    /// Plain least squares.
    #[default]
    Trivial,
    /// Huber loss with scale a.
    Huber(f64),
    /// Cauchy (Lorentzian) loss with scale a.
    Cauchy(f64),
    /// Tukey's biweight with scale a (redescending: outliers get zero weight).
    Tukey(f64),
}

impl Loss {
    /// Checks the scale (finite and positive).
    pub fn validate(&self) -> Result<()> {
        match self {
            Loss::Trivial => Ok(()),
            Loss::Huber(a) | Loss::Cauchy(a) | Loss::Tukey(a) => {
                if a.is_finite() && *a > 0.0 {
                    Ok(())
                } else {
                    Err(EstimateError::InvalidParameter {
                        name: "loss scale",
                        value: *a,
                        reason: "must be finite and positive",
                    })
                }
            }
        }
    }

    /// `[ρ(s), ρ′(s)]`.
    pub fn evaluate(&self, s: f64) -> [f64; 2] {
        match *self {
            Loss::Trivial => [s, 1.0],
            Loss::Huber(a) => {
                let a2 = a * a;
                if s <= a2 {
                    [s, 1.0]
                } else {
                    let r = s.sqrt();
                    [2.0 * a * r - a2, a / r]
                }
            }
            Loss::Cauchy(a) => {
                let a2 = a * a;
                [a2 * (s / a2).ln_1p(), 1.0 / (1.0 + s / a2)]
            }
            Loss::Tukey(a) => {
                let a2 = a * a;
                if s <= a2 {
                    let u = 1.0 - s / a2;
                    [a2 / 3.0 * (1.0 - u * u * u), u * u]
                } else {
                    [a2 / 3.0, 0.0]
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivative_matches_finite_differences_and_small_residuals_are_quadratic() {
        for loss in [
            Loss::Trivial,
            Loss::Huber(1.5),
            Loss::Cauchy(0.7),
            Loss::Tukey(2.0),
        ] {
            assert!((loss.evaluate(1e-10)[0] - 1e-10).abs() < 1e-15, "{loss:?}");
            assert!((loss.evaluate(0.0)[1] - 1.0).abs() < 1e-15, "{loss:?}");
            for s in [0.01, 0.5, 1.0, 3.0, 10.0] {
                let h = 1e-6;
                let fd = (loss.evaluate(s + h)[0] - loss.evaluate(s - h)[0]) / (2.0 * h);
                assert!((fd - loss.evaluate(s)[1]).abs() < 1e-6, "{loss:?} at {s}");
            }
        }
    }

    #[test]
    fn bad_scale_is_rejected() {
        assert!(Loss::Huber(0.0).validate().is_err());
        assert!(Loss::Cauchy(f64::NAN).validate().is_err());
        assert!(Loss::Tukey(1.0).validate().is_ok());
    }
}
