//! Ellipse fitting to edge points (the `FitEllipse` of 000_3b1454b2b2194811.txt §3.2,
//! Algorithms 1–2, whose residual `r(i, j)` — the mean distance of the points to the fitted
//! ellipse — is the arc-grouping cost).
//!
//! Two estimators, both returning the ellipse of eq. (3.1)/(3.2) as
//! [`autoteach_geometry::conic::Ellipse`]:
//!
//! - [`fit_ellipse_direct`]: the numerically stable (Halir & Flusser 1998) form of Fitzgibbon's
//!   ellipse-specific algebraic least squares on the conic of eq. (3.3). Closed form, always an
//!   ellipse, but biased toward small, round ellipses on partial arcs.
//! - [`fit_ellipse_geometric`]: Levenberg–Marquardt on the sum of squared orthogonal
//!   (Euclidean) point-to-ellipse distances over `(cx, cy, a, b, θ)` — the maximum-likelihood
//!   estimate under isotropic Gaussian noise, which stays accurate on arcs of 60–160°.
//!
//! Both report the mean and RMS orthogonal residual in pixels and a 5×5 covariance (see
//! [`EllipseFit`]). Bad input (fewer than 5 points, NaN, collinear or coincident points, points
//! on a hyperbola or a line pair) is an error, never a fabricated ellipse.
//!
//! ```
//! use autoteach_detect::ellipse::{fit_ellipse, FitMethod};
//! use autoteach_geometry::conic::Ellipse;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let truth = Ellipse::new(320.0, 240.0, 300.0, 120.0, 0.4)?;
//! // A 120° arc of the rim.
//! let points = truth.sample(200, 0.3, 0.3 + 120f64.to_radians())?;
//! let fit = fit_ellipse(&points, FitMethod::Geometric)?;
//! assert!((fit.ellipse.cx - 320.0).abs() < 1e-6 && (fit.ellipse.b - 120.0).abs() < 1e-6);
//! assert!(fit.residual_mean < 1e-9);
//! # Ok(())
//! # }
//! ```

// `!(x > y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod batch;
mod direct;
mod geometric;
mod residual;

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix3, Matrix5, SymmetricEigen, Vector2};

use crate::{DetectError, Result};

pub use batch::{check_offsets, fit_ellipses};
pub use direct::fit_ellipse_direct;
pub(crate) use geometric::fit_screened;
pub use geometric::{GeometricFitOptions, fit_ellipse_geometric, fit_ellipse_geometric_masked};
pub(crate) use residual::point_distance_and_gradient;

/// The result of an ellipse fit.
#[derive(Debug, Clone, PartialEq)]
pub struct EllipseFit {
    /// The fitted ellipse (canonical: `a ≥ b`, `θ ∈ (−π/2, π/2]`).
    pub ellipse: Ellipse,
    /// Mean absolute orthogonal distance of the points to the ellipse, in pixels (the arc
    /// grouping residual `r(i, j)` of 000_3b1454b2b2194811.txt §3.2).
    pub residual_mean: f64,
    /// Root-mean-square orthogonal distance, in pixels.
    pub residual_rms: f64,
    /// Covariance of `(cx, cy, a, b, θ)`: `σ̂²·(JᵀJ)⁻¹` with `J` the Jacobian of the signed
    /// orthogonal distances at the fitted ellipse and `σ̂² = SSR/(n − 5)`. `None` for exactly
    /// 5 points, where `σ̂²` cannot be estimated.
    ///
    /// For the geometric fit this is the usual first-order covariance of the maximum-likelihood
    /// estimate. For the direct fit it is the same expression evaluated at the direct ellipse,
    /// i.e. the covariance the geometric estimate would have there (a lower bound: the
    /// algebraic estimate's own error is larger, and biased, on partial arcs).
    ///
    /// Near-circles: when `θ` is not determined by the data — its standard deviation would
    /// exceed that of an angle uniform over the whole range (variance `π²/12`), or the
    /// ellipse is circular to rounding (`(a − b)` too small to move any point) — the `θ` row and
    /// column are set to `var θ = π²/12` and zero correlation, and the other four parameters get
    /// the covariance with `θ` held fixed. The matrix therefore stays finite.
    pub covariance: Option<Matrix5<f64>>,
    /// Levenberg–Marquardt iterations (0 for the direct fit).
    pub iterations: usize,
    /// Whether the iteration met its tolerance (always `true` for the direct fit).
    pub converged: bool,
}

/// Which estimator [`fit_ellipse`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FitMethod {
    /// [`fit_ellipse_direct`]: closed-form algebraic fit.
    Direct,
    /// [`fit_ellipse_geometric`] with default options, started from the direct fit.
    #[default]
    Geometric,
}

/// Fits an ellipse to `points` (pixel coordinates) with the chosen `method`; see
/// [`fit_ellipse_direct`] and [`fit_ellipse_geometric`] (000_3b1454b2b2194811.txt §3.2,
/// `FitEllipse`).
///
/// # Errors
/// As the chosen estimator.
pub fn fit_ellipse(points: &[Vector2<f64>], method: FitMethod) -> Result<EllipseFit> {
    match method {
        FitMethod::Direct => fit_ellipse_direct(points),
        FitMethod::Geometric => {
            fit_ellipse_geometric(points, None, &GeometricFitOptions::default())
        }
    }
}

/// Relative eigenvalue below which a scatter matrix counts as singular.
const RANK_TOL: f64 = 1e-12;

/// Validated points, centred on their centroid, with the conic scatter of the normalised
/// points reduced as in Halir & Flusser (1998): `M = S₁ − S₂S₃⁻¹S₂ᵀ`, `T = −S₃⁻¹S₂ᵀ`.
pub(crate) struct Prepared {
    /// The centroid (pixels).
    pub centroid: Vector2<f64>,
    /// Normalising scale (pixels): the RMS distance of the points to the centroid over √2.
    pub scale: f64,
    /// Points minus the centroid (pixels).
    pub centred: Vec<Vector2<f64>>,
    /// Reduced scatter of the quadratic coefficients `(A, B, C)` (normalised coordinates).
    pub m: Matrix3<f64>,
    /// Linear coefficients `(D, E, F) = T·(A, B, C)` that minimise the algebraic error.
    pub t: Matrix3<f64>,
    /// Scatter blocks of `z = [x², xy, y², x, y, 1]` over the normalised points:
    /// `Σ z₁z₁ᵀ`, `Σ z₁z₂ᵀ`, `Σ z₂z₂ᵀ` with `z₁ = [x², xy, y²]`, `z₂ = [x, y, 1]`.
    pub scatter: [Matrix3<f64>; 3],
}

impl Prepared {
    /// Checks the points (finite, at least 5, not collinear, determining a unique conic) and
    /// builds the scatter.
    pub fn new(points: &[Vector2<f64>]) -> Result<Self> {
        for (index, p) in points.iter().enumerate() {
            for value in [p.x, p.y] {
                if !value.is_finite() {
                    return Err(DetectError::NonFinite {
                        what: "points",
                        index,
                        value,
                    });
                }
            }
        }
        let n = points.len();
        if n < 5 {
            return Err(DetectError::TooFewPoints {
                what: "points",
                got: n,
                needed: 5,
            });
        }
        let centroid = points.iter().sum::<Vector2<f64>>() / n as f64;
        let centred: Vec<Vector2<f64>> = points.iter().map(|p| p - centroid).collect();
        let spread = centred.iter().map(|p| p.norm_squared()).sum::<f64>() / n as f64;
        let scale = (0.5 * spread).sqrt();
        if !(scale > 0.0) || !scale.is_finite() {
            return Err(DetectError::Degenerate {
                reason: format!(
                    "all {n} points coincide at ({}, {})",
                    centroid.x, centroid.y
                ),
            });
        }
        // Scatter of [x², xy, y²] (s1), cross terms (s2) and [x, y, 1] (s3): every entry is
        // one of the 15 moments Σ xʲyᵏ (j + k ≤ 4) of the normalised points.
        let mom = residual::scatter_moments(points, centroid, 1.0 / scale);
        const MONO: [(usize, usize); 6] = [(2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0)];
        let entry = |r: usize, c: usize| {
            let (j, k) = (MONO[r].0 + MONO[c].0, MONO[r].1 + MONO[c].1);
            mom[(j + k) * (j + k + 1) / 2 + k]
        };
        let s1 = Matrix3::from_fn(entry);
        let s2 = Matrix3::from_fn(|r, c| entry(r, c + 3));
        let s3 = Matrix3::from_fn(|r, c| entry(r + 3, c + 3));
        // Collinearity: the 2×2 second-moment matrix of the centred points is singular.
        let (sxx, sxy, syy) = (s3[(0, 0)], s3[(0, 1)], s3[(1, 1)]);
        let half_tr = 0.5 * (sxx + syy);
        let dev = (0.5 * (sxx - syy)).hypot(sxy);
        let (lmin, lmax) = (half_tr - dev, half_tr + dev);
        if lmin <= RANK_TOL * lmax {
            return Err(DetectError::Degenerate {
                reason: format!(
                    "the {n} points are collinear (second moments {lmin:.3e} / {lmax:.3e} across / \
                     along their line, relative to the spread)"
                ),
            });
        }
        let s3_inv = s3.try_inverse().ok_or_else(|| DetectError::Degenerate {
            reason: format!("the scatter of the {n} points is singular (collinear points)"),
        })?;
        let t = -(s3_inv * s2.transpose());
        let m = s1 + s2 * t;
        let m = (m + m.transpose()) * 0.5;
        // A unique conic through the data needs rank(M) ≥ 2: with fewer than 5 distinct
        // points (or 4 of 5 collinear) a whole pencil of conics fits exactly.
        let eig = SymmetricEigen::new(m).eigenvalues;
        let mut ev = [eig[0], eig[1], eig[2]];
        ev.sort_by(f64::total_cmp);
        if ev[1] <= RANK_TOL * ev[2] {
            return Err(DetectError::Degenerate {
                reason: format!(
                    "the {n} points do not determine a unique conic (fewer than 5 distinct points, \
                     or all but one on a line): scatter eigenvalues {:.3e}, {:.3e}, {:.3e}",
                    ev[0], ev[1], ev[2]
                ),
            });
        }
        Ok(Prepared {
            centroid,
            scale,
            centred,
            m,
            t,
            scatter: [s1, s2, s3],
        })
    }
}

#[cfg(test)]
mod tests;
