//! The standard (covariance-form) unscented Kalman filter.

use nalgebra::{DMatrix, DVector};

use super::family::SigmaPoints;
use super::filter::{NoiseForm, SigmaPointFilter};
use super::kernels;
use super::linalg::{self, CovariancePolicy};
use super::model::UkfModel;
use super::transform::{self, Offsets, Space, Workspace};
use crate::{EstimateError, Result};

/// ln(2π).
const LN_2PI: f64 = 1.837_877_066_409_345_3;

/// The unscented Kalman filter of seed 000_3b1454b2b2194811.txt §5.2 (eqs. (5.1)–(5.2)),
/// with van der Merwe's scaled sigma points, in the formulation of filterpy's
/// `UnscentedKalmanFilter` (Wan & van der Merwe 2000):
///
/// * predict: sigma points of (x, P) → `f` → `x⁻ = mean`, `P⁻ = Σ Wc (χ ⊖ x⁻)(χ ⊖ x⁻)ᵀ + Q`;
/// * update: sigma points redrawn from (x⁻, P⁻) → `h` → `ẑ`, `S = Σ Wc dz dzᵀ + R`,
///   `Pxz = Σ Wc dx dzᵀ`, `K = Pxz S⁻¹`, `x = x⁻ ⊕ K (z ⊖ ẑ)`, `P = P⁻ − K S Kᵀ`.
///
/// After every stage the covariance is checked (finite, symmetric, positive definite by
/// Cholesky); see [`CovariancePolicy`]. Noise is additive or augmented ([`NoiseForm`]).
#[derive(Debug, Clone)]
pub struct UnscentedKalmanFilter<M: UkfModel> {
    model: M,
    points: SigmaPoints,
    pred_points: SigmaPoints,
    upd_points: SigmaPoints,
    noise: NoiseForm,
    policy: CovariancePolicy,
    x: DVector<f64>,
    p: DMatrix<f64>,
    /// Lower Cholesky factor of `p` (kept valid at all times).
    l: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    q_sqrt: Option<DMatrix<f64>>,
    r_sqrt: Option<DMatrix<f64>>,
    x_prior: DVector<f64>,
    p_prior: DMatrix<f64>,
    x_post: DVector<f64>,
    p_post: DMatrix<f64>,
    k: DMatrix<f64>,
    y: DVector<f64>,
    s: DMatrix<f64>,
    z_pred: DVector<f64>,
    log_likelihood: f64,
    steps: usize,
    repairs: usize,
    pred_ws: Workspace,
    upd_ws: Workspace,
    scratch: Scratch,
}

/// Buffers of one predict/update, swapped into the filter when the stage completes (so a
/// failed stage leaves the filter unchanged and a step allocates nothing).
#[derive(Debug, Clone)]
struct Scratch {
    x: DVector<f64>,
    p: DMatrix<f64>,
    l: DMatrix<f64>,
    zp: DVector<f64>,
    s: DMatrix<f64>,
    ls: DMatrix<f64>,
    pxz: DMatrix<f64>,
    kt: DMatrix<f64>,
    k: DMatrix<f64>,
    y: DVector<f64>,
    dx: DVector<f64>,
    w: DVector<f64>,
}

impl Scratch {
    fn new(n: usize, m: usize) -> Self {
        Self {
            x: DVector::zeros(n),
            p: DMatrix::zeros(n, n),
            l: DMatrix::zeros(n, n),
            zp: DVector::zeros(m),
            s: DMatrix::zeros(m, m),
            ls: DMatrix::zeros(m, m),
            pxz: DMatrix::zeros(n, m),
            kt: DMatrix::zeros(m, n),
            k: DMatrix::zeros(n, m),
            y: DVector::zeros(m),
            dx: DVector::zeros(n),
            w: DVector::zeros(m),
        }
    }
}

impl<M: UkfModel> UnscentedKalmanFilter<M> {
    /// A filter for `model` with sigma points `points` (whose `n` must equal
    /// `model.dim_x()`), additive noise and the strict covariance policy. The state starts
    /// at zero with P = I, Q = I, R = I (as in filterpy): set them before filtering.
    pub fn new(model: M, points: impl Into<SigmaPoints>) -> Result<Self> {
        let points: SigmaPoints = points.into();
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
            scratch: Scratch::new(n, m),
            points,
            noise: NoiseForm::Additive,
            policy: CovariancePolicy::Strict,
            x: DVector::zeros(n),
            p: DMatrix::identity(n, n),
            l: DMatrix::identity(n, n),
            q: DMatrix::identity(n, n),
            r: DMatrix::identity(m, m),
            q_sqrt: None,
            r_sqrt: None,
            x_prior: DVector::zeros(n),
            p_prior: DMatrix::identity(n, n),
            x_post: DVector::zeros(n),
            p_post: DMatrix::identity(n, n),
            k: DMatrix::zeros(n, m),
            y: DVector::zeros(m),
            s: DMatrix::zeros(m, m),
            z_pred: DVector::zeros(m),
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
        self.noise = noise;
        let (pp, up) = match noise {
            NoiseForm::Additive => (self.points.clone(), self.points.clone()),
            NoiseForm::Augmented => (self.points.with_dim(n + qd)?, self.points.with_dim(n + rd)?),
        };
        let (pq, uq) = match noise {
            NoiseForm::Additive => (0, 0),
            NoiseForm::Augmented => (qd, rd),
        };
        self.pred_ws = Workspace::new(n, pq, n, pp.num_sigmas());
        self.upd_ws = Workspace::new(n, uq, m, up.num_sigmas());
        self.pred_points = pp;
        self.upd_points = up;
        self.q = DMatrix::identity(qd, qd);
        self.r = DMatrix::identity(rd, rd);
        self.q_sqrt = (noise == NoiseForm::Augmented).then(|| self.q.clone());
        self.r_sqrt = (noise == NoiseForm::Augmented).then(|| self.r.clone());
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

    /// The model, mutably (e.g. to change its parameters between steps).
    pub fn model_mut(&mut self) -> &mut M {
        &mut self.model
    }

    /// The sigma points (for the state dimension).
    pub fn points(&self) -> &SigmaPoints {
        &self.points
    }

    /// The noise form.
    pub fn noise(&self) -> NoiseForm {
        self.noise
    }

    /// The covariance policy.
    pub fn policy(&self) -> CovariancePolicy {
        self.policy
    }

    /// The predicted measurement ẑ of the last update.
    pub fn z_pred(&self) -> &DVector<f64> {
        &self.z_pred
    }

    /// The sigma points (columns) the last update passed through `h` (filterpy's `sigmas_f`
    /// after a prediction, state part only).
    pub fn last_update_sigmas(&self) -> &DMatrix<f64> {
        &self.upd_ws.sig
    }

    /// The sigma-point offsets for (x, P): a custom square root of `(n+λ)P` from the model,
    /// or the cached Cholesky factor.
    fn custom_offsets(&self, step: usize) -> Result<Option<DMatrix<f64>>> {
        if self.noise == NoiseForm::Augmented {
            return Ok(None);
        }
        let n = self.x.len();
        match self.model.sqrt_cov(&self.p, self.points.spread()) {
            None => Ok(None),
            Some(r) => {
                let a = r.map_err(|e| transform::at_step(e, step))?;
                linalg::check_shape(&a, n, n, "custom matrix square root")?;
                linalg::check_finite_at(a.as_slice(), || "custom matrix square root".into(), step)?;
                Ok(Some(a))
            }
        }
    }
}

impl<M: UkfModel> SigmaPointFilter for UnscentedKalmanFilter<M> {
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
        self.p.clone()
    }

    fn set_x(&mut self, x: DVector<f64>) -> Result<()> {
        linalg::state_input(&x, self.x.len())?;
        self.x = x;
        Ok(())
    }

    fn set_p(&mut self, p: DMatrix<f64>) -> Result<()> {
        let (p, l) = linalg::covariance_input(&p, self.x.len(), self.policy, &mut self.repairs)?;
        self.p = p;
        self.l = l;
        Ok(())
    }

    fn q(&self) -> &DMatrix<f64> {
        &self.q
    }

    fn set_q(&mut self, q: DMatrix<f64>) -> Result<()> {
        let d = self.q.nrows();
        let (q, sqrt) = linalg::noise_input(&q, d, "process noise Q")?;
        if self.noise == NoiseForm::Augmented {
            self.q_sqrt = Some(sqrt);
        }
        self.q = q;
        Ok(())
    }

    fn r(&self) -> &DMatrix<f64> {
        &self.r
    }

    fn set_r(&mut self, r: DMatrix<f64>) -> Result<()> {
        let d = self.r.nrows();
        let (r, sqrt) = linalg::noise_input(&r, d, "measurement noise R")?;
        if self.noise == NoiseForm::Augmented {
            self.r_sqrt = Some(sqrt);
        }
        self.r = r;
        Ok(())
    }

    fn predict(&mut self, dt: f64, u: Option<&DVector<f64>>) -> Result<()> {
        let step = self.steps;
        linalg::check_predict_inputs(dt, u, self.model.dim_u())?;
        let augmented = self.noise == NoiseForm::Augmented;
        let custom = self.custom_offsets(step)?;
        let offsets = match (&custom, &self.points) {
            (_, SigmaPoints::Given(_)) => Offsets::Covariance(&self.p),
            (Some(a), _) => Offsets::Scaled(a),
            (None, _) => Offsets::Factor(&self.l),
        };
        let ws = &mut self.pred_ws;
        let sc = &mut self.scratch;
        transform::draw(
            &self.model,
            &self.pred_points,
            &self.x,
            offsets,
            self.q_sqrt.as_ref().filter(|_| augmented),
            ws,
            step,
        )?;
        transform::propagate_f(&self.model, augmented, dt, u, ws, step)?;
        transform::mean_and_devs(
            &self.model,
            Space::State,
            self.pred_points.wm(),
            &mut sc.x,
            ws,
            step,
        )?;
        transform::weighted_gram(
            &ws.dev_out,
            self.pred_points.wc(),
            &mut ws.scratch,
            &mut sc.p,
        );
        if !augmented {
            sc.p += &self.q;
        }
        linalg::factor_symmetric_into(
            &mut sc.p,
            &mut sc.l,
            "predicted covariance P_prior",
            step,
            self.policy,
            &mut self.repairs,
        )?;
        std::mem::swap(&mut self.x, &mut sc.x);
        std::mem::swap(&mut self.p, &mut sc.p);
        std::mem::swap(&mut self.l, &mut sc.l);
        self.x_prior.copy_from(&self.x);
        self.p_prior.copy_from(&self.p);
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
        let r_given = match r {
            Some(r) => Some(linalg::noise_input(
                r,
                self.r.nrows(),
                "measurement noise R",
            )?),
            None => None,
        };
        let (r_mat, r_sqrt) = match &r_given {
            Some((rv, sq)) => (rv, Some(sq)),
            None => (&self.r, self.r_sqrt.as_ref()),
        };
        let custom = self.custom_offsets(step)?;
        let offsets = match (&custom, &self.points) {
            (_, SigmaPoints::Given(_)) => Offsets::Covariance(&self.p),
            (Some(a), _) => Offsets::Scaled(a),
            (None, _) => Offsets::Factor(&self.l),
        };
        let ws = &mut self.upd_ws;
        let sc = &mut self.scratch;
        transform::draw(
            &self.model,
            &self.upd_points,
            &self.x,
            offsets,
            r_sqrt.filter(|_| augmented),
            ws,
            step,
        )?;
        transform::propagate_h(&self.model, augmented, ws, step)?;
        let wm = self.upd_points.wm();
        let wc = self.upd_points.wc();
        transform::mean_and_devs(&self.model, Space::Measurement, wm, &mut sc.zp, ws, step)?;
        transform::state_devs(&self.model, &self.x, ws, step)?;
        transform::weighted_gram(&ws.dev_out, wc, &mut ws.scratch, &mut sc.s);
        if !augmented {
            sc.s += r_mat;
        }
        transform::weighted_outer(&ws.dev_x, wc, &ws.dev_out, &mut sc.pxz);
        linalg::factor_symmetric_into(
            &mut sc.s,
            &mut sc.ls,
            "innovation covariance S",
            step,
            self.policy,
            &mut self.repairs,
        )?;
        // K = Pxz S⁻¹  ⇔  S Kᵀ = Pxzᵀ, solved with S = Ls Lsᵀ.
        kernels::transpose(n, m, sc.pxz.as_slice(), sc.kt.as_mut_slice());
        kernels::solve_lower(m, sc.ls.as_slice(), sc.kt.as_mut_slice());
        kernels::solve_lower_transposed(m, sc.ls.as_slice(), sc.kt.as_mut_slice());
        kernels::transpose(m, n, sc.kt.as_slice(), sc.k.as_mut_slice());
        self.model
            .z_residual(z.column(0), sc.zp.column(0), &mut sc.y)
            .map_err(|e| transform::at_step(e, step))?;
        linalg::check_finite_at(sc.y.as_slice(), || "innovation y".into(), step)?;
        kernels::gemm(
            n,
            m,
            1,
            sc.k.as_slice(),
            sc.y.as_slice(),
            sc.dx.as_mut_slice(),
        );
        self.model
            .x_add(self.x.column(0), sc.dx.column(0), &mut sc.x)
            .map_err(|e| transform::at_step(e, step))?;
        linalg::check_finite_at(sc.x.as_slice(), || "updated state x".into(), step)?;
        // P = P⁻ − K S Kᵀ = P⁻ − K Pxzᵀ, on the lower triangle (exactly symmetric).
        sc.p.copy_from(&self.p);
        kernels::sub_lower_abt(
            n,
            m,
            sc.k.as_slice(),
            sc.pxz.as_slice(),
            sc.p.as_mut_slice(),
        );
        linalg::factor_symmetric_into(
            &mut sc.p,
            &mut sc.l,
            "updated covariance P",
            step,
            self.policy,
            &mut self.repairs,
        )?;
        // log N(y; 0, S) = −½ (yᵀS⁻¹y + ln det S + m ln 2π).
        sc.w.copy_from(&sc.y);
        kernels::solve_lower(m, sc.ls.as_slice(), sc.w.as_mut_slice());
        let log_det: f64 = 2.0 * sc.ls.diagonal().iter().map(|d| d.ln()).sum::<f64>();
        self.log_likelihood = -0.5 * (sc.w.norm_squared() + log_det + m as f64 * LN_2PI);
        std::mem::swap(&mut self.x, &mut sc.x);
        std::mem::swap(&mut self.p, &mut sc.p);
        std::mem::swap(&mut self.l, &mut sc.l);
        std::mem::swap(&mut self.k, &mut sc.k);
        std::mem::swap(&mut self.y, &mut sc.y);
        std::mem::swap(&mut self.s, &mut sc.s);
        std::mem::swap(&mut self.z_pred, &mut sc.zp);
        self.x_post.copy_from(&self.x);
        self.p_post.copy_from(&self.p);
        Ok(())
    }

    fn x_prior(&self) -> &DVector<f64> {
        &self.x_prior
    }

    fn p_prior(&self) -> DMatrix<f64> {
        self.p_prior.clone()
    }

    fn x_post(&self) -> &DVector<f64> {
        &self.x_post
    }

    fn p_post(&self) -> DMatrix<f64> {
        self.p_post.clone()
    }

    fn k(&self) -> &DMatrix<f64> {
        &self.k
    }

    fn y(&self) -> &DVector<f64> {
        &self.y
    }

    fn s(&self) -> DMatrix<f64> {
        self.s.clone()
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
        self.p_post.copy_from(&self.p);
    }

    fn append_p(&self, out: &mut Vec<f64>) {
        out.extend_from_slice(self.p.as_slice());
    }
}
