//! The log-distance path-loss fit of eq. 3.1 (seed 004 §3.1): `y = L0 − a·log10 ‖r − t‖`,
//! `x = [L0, a]` by least squares — the baseline every other model is compared with, and the
//! mean function of the MRGP.

use super::{Link, check_links, check_training};
use crate::{EstimateError, Result};

/// A fitted path-loss model with its least-squares covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogFit {
    /// Power at the 1 m reference distance, dBm.
    pub l0: f64,
    /// Path-loss exponent `a` (dB per decade of distance; `10·n` for the usual exponent `n`).
    pub exponent: f64,
    /// Residual variance `s² = ‖y − A x‖² / (m − 2)` (dB²), the noise of a new measurement.
    pub residual_variance: f64,
    /// `(AᵀA)⁻¹` of the regressors `[1, log10 d]` (row-major 2 × 2).
    pub normal_inverse: [f64; 4],
}

impl LogFit {
    /// Least-squares fit of eq. 3.1 to `rss` measured on `links`.
    ///
    /// Errors: `EmptyInput`, `DimensionMismatch`, `NonFiniteInput`, `CoincidentLink` from
    /// [`check_training`]; `RankDeficient` when every link has the same length (the
    /// exponent is then undetermined).
    pub fn fit(links: &[Link], rss: &[f64]) -> Result<LogFit> {
        check_training(links, rss)?;
        let (mut s1, mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (l, &y) in links.iter().zip(rss) {
            let x = l.log_distance();
            s1 += 1.0;
            sx += x;
            sxx += x * x;
            sy += y;
            sxy += x * y;
        }
        let det = s1 * sxx - sx * sx;
        // Written so that NaN (sums that overflowed) fails the test too.
        if det.partial_cmp(&(1e-12 * s1 * sxx.max(1.0))) != Some(std::cmp::Ordering::Greater) {
            return Err(EstimateError::RankDeficient {
                what: "log-distance fit (every link has the same length)".into(),
                directions: "path-loss exponent a".into(),
            });
        }
        let inv = [sxx / det, -sx / det, -sx / det, s1 / det];
        let l0 = inv[0] * sy + inv[1] * sxy;
        let slope = inv[2] * sy + inv[3] * sxy;
        let sse: f64 = links
            .iter()
            .zip(rss)
            .map(|(l, &y)| (y - l0 - slope * l.log_distance()).powi(2))
            .sum();
        let dof = (links.len() as f64 - 2.0).max(1.0);
        Ok(LogFit {
            l0,
            exponent: -slope,
            residual_variance: sse / dof,
            normal_inverse: inv,
        })
    }

    /// Mean `L0 − a·log10 d` for one link (no validation).
    pub fn mean(&self, link: &Link) -> f64 {
        self.l0 - self.exponent * link.log_distance()
    }

    /// Predictions and their variances `s²·(1 + φᵀ(AᵀA)⁻¹φ)`, `φ = [1, log10 d]` (a new
    /// measurement's predictive variance). Errors: `NonFiniteInput`, `CoincidentLink`.
    pub fn predict(&self, links: &[Link]) -> Result<(Vec<f64>, Vec<f64>)> {
        check_links("query links", links)?;
        let inv = &self.normal_inverse;
        Ok(links
            .iter()
            .map(|l| {
                let x = l.log_distance();
                let q = inv[0] + 2.0 * inv[1] * x + inv[3] * x * x;
                (self.mean(l), self.residual_variance * (1.0 + q))
            })
            .unzip())
    }
}
