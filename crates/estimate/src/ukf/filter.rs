//! The interface shared by the standard and the square-root filter, and the batch runner.

use nalgebra::{DMatrix, DMatrixView, DVector, DVectorView};

use crate::{EstimateError, Result};

/// How noise enters the model (see [`UkfModel`](super::UkfModel)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NoiseForm {
    /// `x' = f(x) + w`, `z = h(x) + v`: Q and R are added to the transformed covariances
    /// (filterpy's form).
    #[default]
    Additive,
    /// The state is augmented with the process noise for the prediction (`[x; w]`, sigma
    /// dimension `dim_x + dim_w`) and with the measurement noise for the update (`[x; v]`,
    /// `dim_x + dim_v`); the model's `fx_noise`/`hx_noise` receive the noise of each sigma
    /// point. The update redraws its sigma points from the predicted mean and covariance, as
    /// the additive form does.
    Augmented,
}

/// The inputs of a batch run: one entry per step, each step a prediction followed by an
/// update. Built with [`BatchInputs::new`] and the `with_*` methods.
#[derive(Debug, Clone, Copy)]
pub struct BatchInputs<'a> {
    /// The default time step.
    pub dt: f64,
    /// The measurements; `None` skips the update of that step.
    pub zs: &'a [Option<DVector<f64>>],
    /// Optional control inputs, one per step.
    pub us: Option<&'a [DVector<f64>]>,
    /// Optional time steps, one per step (overriding `dt`).
    pub dts: Option<&'a [f64]>,
    /// Optional measurement covariances, one per step (overriding R).
    pub rs: Option<&'a [DMatrix<f64>]>,
    /// Record the priors (default `true`; without them the result's prior accessors return
    /// `None` and a run stores half as much).
    pub keep_priors: bool,
}

impl<'a> BatchInputs<'a> {
    /// Measurements `zs` with the time step `dt`, no inputs, the filter's R.
    pub fn new(dt: f64, zs: &'a [Option<DVector<f64>>]) -> Self {
        Self {
            dt,
            zs,
            us: None,
            dts: None,
            rs: None,
            keep_priors: true,
        }
    }

    /// Does not record the priors.
    pub fn without_priors(mut self) -> Self {
        self.keep_priors = false;
        self
    }

    /// Adds control inputs (one per step).
    pub fn with_us(mut self, us: &'a [DVector<f64>]) -> Self {
        self.us = Some(us);
        self
    }

    /// Adds per-step time steps.
    pub fn with_dts(mut self, dts: &'a [f64]) -> Self {
        self.dts = Some(dts);
        self
    }

    /// Adds per-step measurement covariances.
    pub fn with_rs(mut self, rs: &'a [DMatrix<f64>]) -> Self {
        self.rs = Some(rs);
        self
    }

    fn check(&self) -> Result<()> {
        let n = self.zs.len();
        let lens = [
            ("inputs us", self.us.map(|v| v.len())),
            ("time steps dts", self.dts.map(|v| v.len())),
            ("measurement covariances Rs", self.rs.map(|v| v.len())),
        ];
        for (what, len) in lens {
            if let Some(len) = len
                && len != n
            {
                return Err(EstimateError::DimensionMismatch {
                    what: format!("{what} (one per measurement)"),
                    expected: vec![n],
                    got: vec![len],
                });
            }
        }
        Ok(())
    }
}

/// The output of a batch run: for every step the prior (after the prediction) and the
/// posterior (after the update; equal to the prior when the measurement was missing), stored
/// contiguously (each state `dim_x` values, each covariance `dim_x²` values column-major).
#[derive(Debug, Clone, PartialEq)]
pub struct BatchResult {
    dim_x: usize,
    xs: Vec<f64>,
    ps: Vec<f64>,
    x_priors: Vec<f64>,
    p_priors: Vec<f64>,
    log_likelihoods: Vec<f64>,
}

impl BatchResult {
    fn with_capacity(steps: usize, prior_steps: usize, n: usize) -> Self {
        Self {
            dim_x: n,
            xs: Vec::with_capacity(steps * n),
            ps: Vec::with_capacity(steps * n * n),
            x_priors: Vec::with_capacity(prior_steps * n),
            p_priors: Vec::with_capacity(prior_steps * n * n),
            log_likelihoods: Vec::with_capacity(steps),
        }
    }

    /// Number of steps.
    pub fn len(&self) -> usize {
        self.log_likelihoods.len()
    }

    /// `true` for a run over no steps.
    pub fn is_empty(&self) -> bool {
        self.log_likelihoods.is_empty()
    }

    /// The state dimension.
    pub fn dim_x(&self) -> usize {
        self.dim_x
    }

    fn vector<'a>(&self, data: &'a [f64], k: usize) -> Option<DVectorView<'a, f64>> {
        let n = self.dim_x;
        data.get(k * n..(k + 1) * n)
            .map(|s| DVectorView::from_slice(s, n))
    }

    fn matrix<'a>(&self, data: &'a [f64], k: usize) -> Option<DMatrixView<'a, f64>> {
        let n = self.dim_x;
        data.get(k * n * n..(k + 1) * n * n)
            .map(|s| DMatrixView::from_slice(s, n, n))
    }

    /// The posterior mean of step `k` (`None` past the end).
    pub fn x(&self, k: usize) -> Option<DVectorView<'_, f64>> {
        self.vector(&self.xs, k)
    }

    /// The posterior covariance of step `k`.
    pub fn p(&self, k: usize) -> Option<DMatrixView<'_, f64>> {
        self.matrix(&self.ps, k)
    }

    /// The prior mean of step `k`.
    pub fn x_prior(&self, k: usize) -> Option<DVectorView<'_, f64>> {
        self.vector(&self.x_priors, k)
    }

    /// The prior covariance of step `k`.
    pub fn p_prior(&self, k: usize) -> Option<DMatrixView<'_, f64>> {
        self.matrix(&self.p_priors, k)
    }

    /// Log-likelihood of each measurement (NaN where it was missing).
    pub fn log_likelihoods(&self) -> &[f64] {
        &self.log_likelihoods
    }

    /// All posterior means, step after step (`len() · dim_x` values).
    pub fn xs(&self) -> &[f64] {
        &self.xs
    }

    /// All posterior covariances, step after step, each column-major.
    pub fn ps(&self) -> &[f64] {
        &self.ps
    }

    /// All prior means (empty when the priors were not kept).
    pub fn x_priors(&self) -> &[f64] {
        &self.x_priors
    }

    /// All prior covariances.
    pub fn p_priors(&self) -> &[f64] {
        &self.p_priors
    }

    /// The storage, without copying: `(xs, ps, x_priors, p_priors, log_likelihoods)` as
    /// returned by the accessors of the same names.
    pub fn into_flat(self) -> FlatBatch {
        FlatBatch {
            xs: self.xs,
            ps: self.ps,
            x_priors: self.x_priors,
            p_priors: self.p_priors,
            log_likelihoods: self.log_likelihoods,
        }
    }
}

/// The storage of a [`BatchResult`], taken by [`BatchResult::into_flat`].
#[derive(Debug, Clone, PartialEq)]
pub struct FlatBatch {
    /// Posterior means, step after step.
    pub xs: Vec<f64>,
    /// Posterior covariances, step after step, each column-major.
    pub ps: Vec<f64>,
    /// Prior means (empty when not kept).
    pub x_priors: Vec<f64>,
    /// Prior covariances (empty when not kept).
    pub p_priors: Vec<f64>,
    /// Log-likelihoods (NaN where the measurement was missing).
    pub log_likelihoods: Vec<f64>,
}

/// An unscented (sigma-point) Kalman filter: the common interface of
/// [`UnscentedKalmanFilter`](super::UnscentedKalmanFilter) and
/// [`SquareRootUkf`](super::SquareRootUkf), with the batch runner.
///
/// A failed call leaves the filter unchanged (its state is only committed when a stage
/// completes). Errors raised during filtering name the step: the number of predictions made
/// before the failing one (so, for a fresh filter, the index in a batch).
pub trait SigmaPointFilter {
    /// State dimension.
    fn dim_x(&self) -> usize;
    /// Measurement dimension.
    fn dim_z(&self) -> usize;
    /// The current state estimate.
    fn x(&self) -> &DVector<f64>;
    /// The current covariance.
    fn p(&self) -> DMatrix<f64>;
    /// Sets the state (length `dim_x`, finite).
    fn set_x(&mut self, x: DVector<f64>) -> Result<()>;
    /// Sets the covariance (`dim_x × dim_x`, finite, symmetric, positive definite; with the
    /// repair policy an indefinite matrix is clipped instead).
    fn set_p(&mut self, p: DMatrix<f64>) -> Result<()>;
    /// The process noise covariance Q.
    fn q(&self) -> &DMatrix<f64>;
    /// Sets Q (`dim_x × dim_x`, or `dim_w × dim_w` in the augmented form; symmetric positive
    /// semi-definite).
    fn set_q(&mut self, q: DMatrix<f64>) -> Result<()>;
    /// The measurement noise covariance R.
    fn r(&self) -> &DMatrix<f64>;
    /// Sets R (`dim_z × dim_z`, or `dim_v × dim_v` in the augmented form; symmetric
    /// positive semi-definite).
    fn set_r(&mut self, r: DMatrix<f64>) -> Result<()>;
    /// Prediction over `dt` with the optional input `u` (length `dim_u` of the model).
    fn predict(&mut self, dt: f64, u: Option<&DVector<f64>>) -> Result<()>;
    /// Update with the measurement `z`, optionally with a measurement covariance for this
    /// update only.
    fn update(&mut self, z: &DVector<f64>, r: Option<&DMatrix<f64>>) -> Result<()>;
    /// The state after the last prediction.
    fn x_prior(&self) -> &DVector<f64>;
    /// The covariance after the last prediction.
    fn p_prior(&self) -> DMatrix<f64>;
    /// The state after the last update.
    fn x_post(&self) -> &DVector<f64>;
    /// The covariance after the last update.
    fn p_post(&self) -> DMatrix<f64>;
    /// The Kalman gain of the last update (`dim_x × dim_z`).
    fn k(&self) -> &DMatrix<f64>;
    /// The innovation `z ⊖ ẑ` of the last update.
    fn y(&self) -> &DVector<f64>;
    /// The innovation covariance of the last update.
    fn s(&self) -> DMatrix<f64>;
    /// The Gaussian log-likelihood of the last measurement.
    fn log_likelihood(&self) -> f64;
    /// The number of predictions made so far.
    fn step(&self) -> usize;
    /// How many covariances the repair policy has fixed so far.
    fn repairs(&self) -> usize;

    /// Runs predict/update over all steps without returning to the caller in between, and
    /// records priors and posteriors. On error the filter holds the last completed stage.
    fn batch(&mut self, inputs: &BatchInputs<'_>) -> Result<BatchResult> {
        inputs.check()?;
        let n = inputs.zs.len();
        let prior_steps = if inputs.keep_priors { n } else { 0 };
        let mut out = BatchResult::with_capacity(n, prior_steps, self.dim_x());
        for (i, z) in inputs.zs.iter().enumerate() {
            let dt = inputs.dts.map_or(inputs.dt, |d| d[i]);
            let u = inputs.us.map(|u| &u[i]);
            self.predict(dt, u)?;
            if inputs.keep_priors {
                out.x_priors.extend_from_slice(self.x().as_slice());
                self.append_p(&mut out.p_priors);
            }
            match z {
                Some(z) => {
                    self.update(z, inputs.rs.map(|r| &r[i]))?;
                    out.log_likelihoods.push(self.log_likelihood());
                }
                None => {
                    self.skip_update();
                    out.log_likelihoods.push(f64::NAN);
                }
            }
            out.xs.extend_from_slice(self.x().as_slice());
            self.append_p(&mut out.ps);
        }
        Ok(out)
    }

    /// Appends the current covariance (column-major) to `out`.
    fn append_p(&self, out: &mut Vec<f64>) {
        out.extend_from_slice(self.p().as_slice());
    }

    /// Records a missing measurement: the posterior equals the prior (filterpy's
    /// `update(None)`).
    fn skip_update(&mut self);
}
