//! The square-root unscented Kalman filter.

use nalgebra::{DMatrix, DVector};

use super::family::SigmaPoints;
use super::filter::{NoiseForm, SigmaPointFilter};
use super::linalg::{self, CovariancePolicy};
use super::model::UkfModel;
use super::transform::{self, Offsets, Space, Workspace};
use crate::{EstimateError, Result};

/// ln(2π).
const LN_2PI: f64 = 1.837_877_066_409_345_3;

/// The square-root UKF of van der Merwe & Wan, "The square-root unscented Kalman filter for
/// state and parameter estimation" (ICASSP 2001), for the filter of seed
/// 000_3b1454b2b2194811.txt §5.2: it propagates the lower Cholesky factor `S` (P = S Sᵀ)
/// instead of P, so P stays symmetric positive semi-definite by construction:
///
/// * predict: `S⁻ = qr{[√Wc₁ (χ₁…₂ₙ ⊖ x⁻), √Q]}` then a rank-1 Cholesky update (Wc₀ ≥ 0)
///   or downdate (Wc₀ < 0) with `√|Wc₀| (χ₀ ⊖ x⁻)` (their eqs. (20)–(21));
/// * update: `S_z` likewise from the measurement sigma points and `√R`, `K = (Pxz / S_zᵀ) / S_z`,
///   `S = cholupdate(S⁻, K S_z, −1)` (their eqs. (23)–(28)).
///
/// Its sigma points, means and gains are those of
/// [`UnscentedKalmanFilter`](super::UnscentedKalmanFilter) (the update redraws sigma points
/// from (x⁻, S⁻)), so the two
/// agree to rounding on well-conditioned problems. A failed downdate (the covariance would
/// lose definiteness) is reported as [`EstimateError::NotPositiveDefinite`], or repaired
/// under [`CovariancePolicy::Repair`] by clipping the eigenvalues of the reconstructed P.
#[derive(Debug, Clone)]
pub struct SquareRootUkf<M: UkfModel> {
    model: M,
    points: SigmaPoints,
    pred_points: SigmaPoints,
    upd_points: SigmaPoints,
    noise: NoiseForm,
    policy: CovariancePolicy,
    x: DVector<f64>,
    /// Lower-triangular square root of P.
    sf: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    q_sqrt: DMatrix<f64>,
    r_sqrt: DMatrix<f64>,
    x_prior: DVector<f64>,
    s_prior: DMatrix<f64>,
    x_post: DVector<f64>,
    s_post: DMatrix<f64>,
    k: DMatrix<f64>,
    y: DVector<f64>,
    sz: DMatrix<f64>,
    log_likelihood: f64,
    steps: usize,
    repairs: usize,
    pred_ws: Workspace,
    upd_ws: Workspace,
}

impl<M: UkfModel> SquareRootUkf<M> {
    /// A filter for `model` with sigma points `points` (`n == model.dim_x()`), additive noise
    /// and the strict policy; x = 0, P = Q = R = I initially.
    pub fn new(model: M, points: impl Into<SigmaPoints>) -> Result<Self> {
        let points: SigmaPoints = points.into();
        if let SigmaPoints::Given(_) = points {
            return Err(EstimateError::InvalidParameter {
                name: "points",
                value: points.n() as f64,
                reason: "the square-root filter needs a built-in sigma-point family (Merwe, Julier or simplex)",
            });
        }
        let n = model.dim_x();
        let m = model.dim_z();
        if n == 0 || m == 0 {
            return Err(EstimateError::DimensionMismatch {
                what: "model dimensions (dim_x, dim_z)".to_string(),
                expected: vec![n.max(1), m.max(1)],
                got: vec![n, m],
            });
        }
        if points.n() != n {
            return Err(EstimateError::DimensionMismatch {
                what: "sigma points n (must equal the state dimension)".to_string(),
                expected: vec![n],
                got: vec![points.n()],
            });
        }
        let ns = points.num_sigmas();
        Ok(Self {
            pred_points: points.clone(),
            upd_points: points.clone(),
            pred_ws: Workspace::new(n, 0, n, ns),
            upd_ws: Workspace::new(n, 0, m, ns),
            points,
            noise: NoiseForm::Additive,
            policy: CovariancePolicy::Strict,
            x: DVector::zeros(n),
            sf: DMatrix::identity(n, n),
            q: DMatrix::identity(n, n),
            r: DMatrix::identity(m, m),
            q_sqrt: DMatrix::identity(n, n),
            r_sqrt: DMatrix::identity(m, m),
            x_prior: DVector::zeros(n),
            s_prior: DMatrix::identity(n, n),
            x_post: DVector::zeros(n),
            s_post: DMatrix::identity(n, n),
            k: DMatrix::zeros(n, m),
            y: DVector::zeros(m),
            sz: DMatrix::zeros(m, m),
            log_likelihood: f64::NAN,
            steps: 0,
            repairs: 0,
            model,
        })
    }

    /// Chooses how noise enters (Q and R are reset to identities of the new sizes).
    pub fn with_noise(mut self, noise: NoiseForm) -> Result<Self> {
        let n = self.model.dim_x();
        let m = self.model.dim_z();
        let (qd, rd) = match noise {
            NoiseForm::Additive => (n, m),
            NoiseForm::Augmented => (self.model.dim_w(), self.model.dim_v()),
        };
        let (pp, up, pq, uq) = match noise {
            NoiseForm::Additive => (self.points.clone(), self.points.clone(), 0, 0),
            NoiseForm::Augmented => (
                self.points.with_dim(n + qd)?,
                self.points.with_dim(n + rd)?,
                qd,
                rd,
            ),
        };
        self.pred_ws = Workspace::new(n, pq, n, pp.num_sigmas());
        self.upd_ws = Workspace::new(n, uq, m, up.num_sigmas());
        self.pred_points = pp;
        self.upd_points = up;
        self.noise = noise;
        self.q = DMatrix::identity(qd, qd);
        self.r = DMatrix::identity(rd, rd);
        self.q_sqrt = self.q.clone();
        self.r_sqrt = self.r.clone();
        Ok(self)
    }

    /// Chooses the covariance policy.
    pub fn with_policy(mut self, policy: CovariancePolicy) -> Self {
        self.policy = policy;
        self
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The model, mutably.
    pub fn model_mut(&mut self) -> &mut M {
        &mut self.model
    }

    /// The lower-triangular square root S of the covariance (P = S Sᵀ).
    pub fn sqrt_p(&self) -> &DMatrix<f64> {
        &self.sf
    }

    /// The lower-triangular square root of the last innovation covariance.
    pub fn sqrt_s(&self) -> &DMatrix<f64> {
        &self.sz
    }

    /// `tria([√Wc₁ D₁…, extra])` followed by the rank-1 correction with `Wc₀ D₀`, where D
    /// are the deviation columns. On a failed downdate: error, or (repair policy) the
    /// eigenvalue-clipped factor of the reconstructed matrix.
    fn sqrt_of_deviations(
        &mut self,
        dev: &DMatrix<f64>,
        wc: &DVector<f64>,
        extra: Option<&DMatrix<f64>>,
        what: &str,
        step: usize,
    ) -> Result<DMatrix<f64>> {
        let d = dev.nrows();
        let nsig = dev.ncols();
        let ne = extra.map_or(0, |e| e.ncols());
        let mut a = DMatrix::zeros(d, nsig - 1 + ne);
        let w1 = wc[1].sqrt();
        for i in 1..nsig {
            let mut c = a.column_mut(i - 1);
            c.copy_from(&dev.column(i));
            c *= w1;
        }
        if let Some(e) = extra {
            a.columns_mut(nsig - 1, ne).copy_from(e);
        }
        let mut s = linalg::tria(&a);
        let w0 = wc[0];
        let mut v = dev.column(0) * w0.abs().sqrt();
        let ok = linalg::chol_rank1(&mut s, &mut v, w0.signum());
        let healthy = ok
            && linalg::first_non_finite(s.as_slice()).is_none()
            && s.diagonal().iter().all(|&x| x > 0.0);
        if healthy {
            return Ok(s);
        }
        // Reconstruct the full matrix for the diagnosis (or the repair).
        let mut p = &a * a.transpose() + dev.column(0) * dev.column(0).transpose() * w0;
        linalg::factor_covariance(&mut p, what, step, self.policy, &mut self.repairs)
    }

    /// S ← chol(S Sᵀ − U Uᵀ) by successive downdates, or the repaired/diagnosed fallback.
    fn downdate(
        &mut self,
        s: &DMatrix<f64>,
        u: &DMatrix<f64>,
        what: &str,
        step: usize,
    ) -> Result<DMatrix<f64>> {
        let mut out = s.clone();
        let mut ok = true;
        for j in 0..u.ncols() {
            let mut v = u.column(j).into_owned();
            if !linalg::chol_rank1(&mut out, &mut v, -1.0) {
                ok = false;
                break;
            }
        }
        if ok
            && linalg::first_non_finite(out.as_slice()).is_none()
            && out.diagonal().iter().all(|&x| x > 0.0)
        {
            return Ok(out);
        }
        let mut p = s * s.transpose() - u * u.transpose();
        linalg::factor_covariance(&mut p, what, step, self.policy, &mut self.repairs)
    }
}

impl<M: UkfModel> SigmaPointFilter for SquareRootUkf<M> {
    fn dim_x(&self) -> usize {
        self.model.dim_x()
    }

    fn dim_z(&self) -> usize {
        self.model.dim_z()
    }

    fn x(&self) -> &DVector<f64> {
        &self.x
    }

    fn p(&self) -> DMatrix<f64> {
        &self.sf * self.sf.transpose()
    }

    fn set_x(&mut self, x: DVector<f64>) -> Result<()> {
        linalg::state_input(&x, self.x.len())?;
        self.x = x;
        Ok(())
    }

    fn set_p(&mut self, p: DMatrix<f64>) -> Result<()> {
        let (_, l) = linalg::covariance_input(&p, self.x.len(), self.policy, &mut self.repairs)?;
        self.sf = l;
        Ok(())
    }

    fn q(&self) -> &DMatrix<f64> {
        &self.q
    }

    fn set_q(&mut self, q: DMatrix<f64>) -> Result<()> {
        let d = self.q.nrows();
        let (q, sqrt) = linalg::noise_input(&q, d, "process noise Q")?;
        self.q_sqrt = sqrt;
        self.q = q;
        Ok(())
    }

    fn r(&self) -> &DMatrix<f64> {
        &self.r
    }

    fn set_r(&mut self, r: DMatrix<f64>) -> Result<()> {
        let d = self.r.nrows();
        let (r, sqrt) = linalg::noise_input(&r, d, "measurement noise R")?;
        self.r_sqrt = sqrt;
        self.r = r;
        Ok(())
    }

    fn predict(&mut self, dt: f64, u: Option<&DVector<f64>>) -> Result<()> {
        let step = self.steps;
        linalg::check_predict_inputs(dt, u, self.model.dim_u())?;
        let augmented = self.noise == NoiseForm::Augmented;
        let mut ws = std::mem::replace(&mut self.pred_ws, Workspace::new(0, 0, 0, 0));
        let result = (|| {
            transform::draw(
                &self.model,
                &self.pred_points,
                &self.x,
                Offsets::Factor(&self.sf),
                augmented.then_some(&self.q_sqrt),
                &mut ws,
                step,
            )?;
            transform::propagate_f(&self.model, augmented, dt, u, &mut ws, step)?;
            let mut x = DVector::zeros(self.x.len());
            transform::mean_and_devs(
                &self.model,
                Space::State,
                self.pred_points.wm(),
                &mut x,
                &mut ws,
                step,
            )?;
            Ok(x)
        })();
        let x = match result {
            Ok(x) => x,
            Err(e) => {
                self.pred_ws = ws;
                return Err(e);
            }
        };
        let wc = self.pred_points.wc().clone();
        let q_sqrt = (!augmented).then(|| self.q_sqrt.clone());
        let sf = self.sqrt_of_deviations(
            &ws.dev_out,
            &wc,
            q_sqrt.as_ref(),
            "predicted covariance P_prior",
            step,
        );
        self.pred_ws = ws;
        let sf = sf?;
        self.x_prior.copy_from(&x);
        self.s_prior.copy_from(&sf);
        self.x = x;
        self.sf = sf;
        self.steps += 1;
        Ok(())
    }

    fn update(&mut self, z: &DVector<f64>, r: Option<&DMatrix<f64>>) -> Result<()> {
        let step = self.steps.saturating_sub(1);
        let m = self.model.dim_z();
        let n = self.x.len();
        linalg::check_len(z, m, "measurement z")?;
        linalg::check_finite_input(z.as_slice(), "measurement z")?;
        let augmented = self.noise == NoiseForm::Augmented;
        let r_sqrt = match r {
            Some(r) => linalg::noise_input(r, self.r.nrows(), "measurement noise R")?.1,
            None => self.r_sqrt.clone(),
        };
        let mut ws = std::mem::replace(&mut self.upd_ws, Workspace::new(0, 0, 0, 0));
        let result = (|| {
            transform::draw(
                &self.model,
                &self.upd_points,
                &self.x,
                Offsets::Factor(&self.sf),
                augmented.then_some(&r_sqrt),
                &mut ws,
                step,
            )?;
            transform::propagate_h(&self.model, augmented, &mut ws, step)?;
            let mut zp = DVector::zeros(m);
            transform::mean_and_devs(
                &self.model,
                Space::Measurement,
                self.upd_points.wm(),
                &mut zp,
                &mut ws,
                step,
            )?;
            transform::state_devs(&self.model, &self.x, &mut ws, step)?;
            Ok(zp)
        })();
        let zp = match result {
            Ok(zp) => zp,
            Err(e) => {
                self.upd_ws = ws;
                return Err(e);
            }
        };
        let wc = self.upd_points.wc().clone();
        let sz = self.sqrt_of_deviations(
            &ws.dev_out,
            &wc,
            (!augmented).then_some(&r_sqrt),
            "innovation covariance S",
            step,
        );
        let mut pxz = DMatrix::zeros(n, m);
        transform::weighted_outer(&ws.dev_x, &wc, &ws.dev_out, &mut pxz);
        self.upd_ws = ws;
        let sz = sz?;
        // K = Pxz (Sz Szᵀ)⁻¹: Sz W = Pxzᵀ, then Szᵀ Kᵀ = W.
        let not_pd = || EstimateError::NotPositiveDefinite {
            what: "innovation covariance S".to_string(),
            step,
            min_eigenvalue: 0.0,
        };
        let w = sz
            .solve_lower_triangular(&pxz.transpose())
            .ok_or_else(not_pd)?;
        let k = sz
            .tr_solve_lower_triangular(&w)
            .ok_or_else(not_pd)?
            .transpose();
        let mut y = DVector::zeros(m);
        self.model
            .z_residual(z.column(0), zp.column(0), &mut y)
            .map_err(|e| transform::at_step(e, step))?;
        linalg::check_finite_at(y.as_slice(), || "innovation y".into(), step)?;
        let dx = &k * &y;
        let mut x = DVector::zeros(n);
        self.model
            .x_add(self.x.column(0), dx.column(0), &mut x)
            .map_err(|e| transform::at_step(e, step))?;
        linalg::check_finite_at(x.as_slice(), || "updated state x".into(), step)?;
        let u = &k * &sz;
        let sf_old = self.sf.clone();
        let sf = self.downdate(&sf_old, &u, "updated covariance P", step)?;
        let wy = sz
            .solve_lower_triangular(&y)
            .unwrap_or_else(|| DVector::from_element(m, f64::NAN));
        let log_det: f64 = 2.0 * sz.diagonal().iter().map(|d| d.ln()).sum::<f64>();
        self.log_likelihood = -0.5 * (wy.norm_squared() + log_det + m as f64 * LN_2PI);
        self.x_post.copy_from(&x);
        self.s_post.copy_from(&sf);
        self.x = x;
        self.sf = sf;
        self.k = k;
        self.y = y;
        self.sz = sz;
        Ok(())
    }

    fn x_prior(&self) -> &DVector<f64> {
        &self.x_prior
    }

    fn p_prior(&self) -> DMatrix<f64> {
        &self.s_prior * self.s_prior.transpose()
    }

    fn x_post(&self) -> &DVector<f64> {
        &self.x_post
    }

    fn p_post(&self) -> DMatrix<f64> {
        &self.s_post * self.s_post.transpose()
    }

    fn k(&self) -> &DMatrix<f64> {
        &self.k
    }

    fn y(&self) -> &DVector<f64> {
        &self.y
    }

    fn s(&self) -> DMatrix<f64> {
        &self.sz * self.sz.transpose()
    }

    fn log_likelihood(&self) -> f64 {
        self.log_likelihood
    }

    fn step(&self) -> usize {
        self.steps
    }

    fn repairs(&self) -> usize {
        self.repairs
    }

    fn skip_update(&mut self) {
        self.x_post.copy_from(&self.x);
        self.s_post.copy_from(&self.sf);
    }
}
