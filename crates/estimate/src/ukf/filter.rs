//! The interface shared by the standard and the square-root filter, and the batch runner.

use nalgebra::{DMatrix, DVector};

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
        }
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
/// posterior (after the update; equal to the prior when the measurement was missing).
#[derive(Debug, Clone, PartialEq)]
pub struct BatchResult {
    /// Posterior means.
    pub xs: Vec<DVector<f64>>,
    /// Posterior covariances.
    pub ps: Vec<DMatrix<f64>>,
    /// Prior means.
    pub x_priors: Vec<DVector<f64>>,
    /// Prior covariances.
    pub p_priors: Vec<DMatrix<f64>>,
    /// Log-likelihood of each measurement (NaN where it was missing).
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
        let mut out = BatchResult {
            xs: Vec::with_capacity(n),
            ps: Vec::with_capacity(n),
            x_priors: Vec::with_capacity(n),
            p_priors: Vec::with_capacity(n),
            log_likelihoods: Vec::with_capacity(n),
        };
        for (i, z) in inputs.zs.iter().enumerate() {
            let dt = inputs.dts.map_or(inputs.dt, |d| d[i]);
            let u = inputs.us.map(|u| &u[i]);
            self.predict(dt, u)?;
            out.x_priors.push(self.x().clone());
            out.p_priors.push(self.p());
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
            out.xs.push(self.x().clone());
            out.ps.push(self.p());
        }
        Ok(out)
    }

    /// Records a missing measurement: the posterior equals the prior (filterpy's
    /// `update(None)`).
    fn skip_update(&mut self);
}
