//! The EM estimate of the LiDAR noise σ (eq. 8.12).
//!
//! ```text
//! σ² ← Σ_objects Σ_jk φ_jk ‖x_k − v_j(ȳ)‖² / (d · Σ_objects N_P),   N_P = Σ_jk φ_jk = K,
//! ```
//!
//! iterated with the responsibilities φ of eq. 8.11 recomputed at the current σ, as in CPD's
//! σ² update (ref. [213]). The seed prints the normaliser as `M·d` (M = number of mixture
//! centres); with φ normalised over j for each point, `Σ_jk φ_jk = K` (the number of points) and
//! only `K·d` makes σ² the mean squared residual per coordinate — what the text says the result
//! is ("very close to the root mean square of distances between LiDAR points and bounding box
//! labels"). The `M·d` reading would scale σ by `√(K/M)`; see
//! `tests::eq_8_12_normaliser_is_the_point_count_not_m` (the seed's `z_j(ȳ)` is also `v_j(ȳ)`).
//!
//! With boundary centres spaced much closer than σ, a point's responsibilities spread along the
//! boundary with variance ≈ σ²_current (tangential) while its normal residual has variance
//! σ²_true, so the update is `σ² ← (σ²_true + σ²_current)/2`: the iteration converges to the
//! true σ, halving the error each step.

use autoteach_geometry::boxes::Box2;

use super::label::{check_points, check_sigma, e_step};
use crate::cpd::EStep;
use crate::{DetectError, Result};

/// Options of [`estimate_noise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseOptions {
    /// Starting σ (m).
    pub sigma0: f64,
    /// Boundary spacing as a fraction of the current σ.
    pub spacing: f64,
    /// Relative change of σ² at which to stop.
    pub tolerance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// E-step strategy.
    pub e_step: EStep,
}

impl Default for NoiseOptions {
    fn default() -> Self {
        Self {
            sigma0: 0.5,
            spacing: 0.5,
            tolerance: 1e-8,
            max_iterations: 200,
            e_step: EStep::Auto,
        }
    }
}

/// The result of [`estimate_noise`].
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseEstimate {
    /// Estimated σ (m).
    pub sigma: f64,
    /// Iterations run.
    pub iterations: usize,
    /// σ after each iteration.
    pub history: Vec<f64>,
}

/// Eq. 8.12 pooled over objects `(label, points)`.
pub fn estimate_noise(
    objects: &[(Box2, &[[f64; 2]])],
    opts: &NoiseOptions,
) -> Result<NoiseEstimate> {
    if objects.is_empty() {
        return Err(DetectError::TooFewPoints {
            what: "objects",
            got: 0,
            needed: 1,
        });
    }
    for (_, p) in objects {
        check_points(p)?;
    }
    check_sigma(opts.sigma0)?;
    if opts.tolerance.is_nan() || opts.tolerance <= 0.0 || opts.max_iterations == 0 {
        return Err(DetectError::InvalidParameter {
            what: "tolerance",
            value: opts.tolerance,
            reason: "need tolerance > 0 and max_iterations ≥ 1",
        });
    }
    let total: usize = objects.iter().map(|(_, p)| p.len()).sum();
    let mut s2 = opts.sigma0 * opts.sigma0;
    let mut history = Vec::new();
    for it in 1..=opts.max_iterations {
        let sigma = s2.sqrt();
        let mut ss = 0.0;
        for (label, pts) in objects {
            ss += e_step(label, pts, sigma, opts.spacing, opts.e_step)?.2;
        }
        let next = ss / (2.0 * total as f64);
        if next.is_nan() || next <= 0.0 {
            return Err(DetectError::Degenerate {
                reason: format!(
                    "the residuals vanish (σ² = {next:e}): points lie exactly on the boxes"
                ),
            });
        }
        history.push(next.sqrt());
        let done = (next - s2).abs() <= opts.tolerance * s2;
        s2 = next;
        if done {
            return Ok(NoiseEstimate {
                sigma: s2.sqrt(),
                iterations: it,
                history,
            });
        }
    }
    Ok(NoiseEstimate {
        sigma: s2.sqrt(),
        iterations: opts.max_iterations,
        history,
    })
}
