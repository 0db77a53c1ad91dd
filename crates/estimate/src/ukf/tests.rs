//! Tests of the filters against independent truths: the closed-form Kalman filter for linear
//! models, the standard filter for the square-root one, a known rotation trajectory for the
//! SO(3) state, and hand-computed failure cases.

use autoteach_geometry::lie::{so3_exp, so3_log, so3_minus, so3_plus};
use nalgebra::{DMatrix, DVector, DVectorView, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::fixtures::constant_acceleration;
use super::*;
use crate::{EstimateError, Result};

fn normal(rng: &mut Pcg64, n: usize, sigma: f64) -> DVector<f64> {
    DVector::from_fn(n, |_, _| {
        let v: f64 = StandardNormal.sample(rng);
        sigma * v
    })
}

fn spd(n: usize, scale: f64, rng: &mut Pcg64) -> DMatrix<f64> {
    let a = DMatrix::from_fn(n, n, |_, _| {
        let v: f64 = StandardNormal.sample(rng);
        v
    });
    (&a * a.transpose() / n as f64 + DMatrix::identity(n, n)) * scale
}

/// The textbook Kalman filter, one step.
struct Kf {
    x: DVector<f64>,
    p: DMatrix<f64>,
    ll: f64,
}

impl Kf {
    fn step(&mut self, f: &DMatrix<f64>, b: &DMatrix<f64>, u: &DVector<f64>, q: &DMatrix<f64>) {
        self.x = f * &self.x + b * u;
        self.p = f * &self.p * f.transpose() + q;
    }

    fn update(&mut self, h: &DMatrix<f64>, r: &DMatrix<f64>, z: &DVector<f64>) {
        let s = h * &self.p * h.transpose() + r;
        let si = s.clone().try_inverse().unwrap();
        let k = &self.p * h.transpose() * &si;
        let y = z - h * &self.x;
        self.x = &self.x + &k * &y;
        self.p = &self.p - &k * &s * k.transpose();
        self.p = (&self.p + self.p.transpose()) * 0.5;
        let m = z.len() as f64;
        self.ll = -0.5
            * ((y.transpose() * &si * &y)[(0, 0)]
                + s.determinant().ln()
                + m * (2.0 * std::f64::consts::PI).ln());
    }
}

fn close(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64) -> bool {
    (a - b).amax() <= tol * b.amax().max(1.0)
}

fn close_v(a: &DVector<f64>, b: &DVector<f64>, tol: f64) -> bool {
    (a - b).amax() <= tol * b.amax().max(1.0)
}

struct LinearCase {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    b: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    p0: DMatrix<f64>,
    x0: DVector<f64>,
    us: Vec<DVector<f64>>,
    zs: Vec<Option<DVector<f64>>>,
}

fn linear_case(steps: usize) -> LinearCase {
    let mut rng = Pcg64::seed_from_u64(7);
    let (f, h, b) = constant_acceleration(0.05);
    let q = spd(9, 1e-3, &mut rng);
    let r = spd(3, 4e-2, &mut rng);
    let p0 = spd(9, 1.0, &mut rng);
    let x0 = normal(&mut rng, 9, 1.0);
    let mut truth = normal(&mut rng, 9, 1.0);
    let mut us = Vec::new();
    let mut zs = Vec::new();
    for k in 0..steps {
        let u = normal(&mut rng, 3, 0.1);
        truth = &f * &truth + &b * &u + normal(&mut rng, 9, 0.03);
        us.push(u);
        // Every 7th measurement is missing.
        zs.push((k % 7 != 3).then(|| &h * &truth + normal(&mut rng, 3, 0.2)));
    }
    LinearCase {
        f,
        h,
        b,
        q,
        r,
        p0,
        x0,
        us,
        zs,
    }
}

fn run_kf(
    c: &LinearCase,
    q_eff: &DMatrix<f64>,
) -> (Vec<DVector<f64>>, Vec<DMatrix<f64>>, Vec<f64>) {
    let mut kf = Kf {
        x: c.x0.clone(),
        p: c.p0.clone(),
        ll: f64::NAN,
    };
    let (mut xs, mut ps, mut lls) = (Vec::new(), Vec::new(), Vec::new());
    for (u, z) in c.us.iter().zip(&c.zs) {
        kf.step(&c.f, &c.b, u, q_eff);
        match z {
            Some(z) => {
                kf.update(&c.h, &c.r, z);
                lls.push(kf.ll);
            }
            None => lls.push(f64::NAN),
        }
        xs.push(kf.x.clone());
        ps.push(kf.p.clone());
    }
    (xs, ps, lls)
}

fn check_against_kf<F: SigmaPointFilter>(
    mut filt: F,
    c: &LinearCase,
    q_eff: &DMatrix<f64>,
    tol: f64,
) {
    filt.set_x(c.x0.clone()).unwrap();
    filt.set_p(c.p0.clone()).unwrap();
    let out = filt
        .batch(&BatchInputs::new(0.05, &c.zs).with_us(&c.us))
        .unwrap();
    let (xs, ps, lls) = run_kf(c, q_eff);
    for k in 0..xs.len() {
        assert!(
            close_v(&out.x(k).unwrap().into_owned(), &xs[k], tol),
            "x at step {k}: {} vs {}",
            out.x(k).unwrap().into_owned(),
            xs[k]
        );
        assert!(
            close(&out.p(k).unwrap().into_owned(), &ps[k], tol),
            "P at step {k}: diff {:e} scale {:e}",
            (&out.p(k).unwrap().into_owned() - &ps[k]).amax(),
            ps[k].amax()
        );
        if lls[k].is_nan() {
            assert!(out.log_likelihoods()[k].is_nan());
            assert_eq!(
                out.x(k).unwrap().into_owned(),
                out.x_prior(k).unwrap().into_owned()
            );
        } else {
            assert!(
                (out.log_likelihoods()[k] - lls[k]).abs() < 1e-8,
                "log-likelihood at {k}"
            );
        }
    }
}

#[test]
fn linear_ukf_equals_closed_form_kalman_filter() {
    let c = linear_case(1000);
    let model = LinearModel::new(c.f.clone(), c.h.clone(), Some(c.b.clone())).unwrap();
    for (alpha, beta, kappa) in [(1.0, 2.0, 0.0), (0.3, 2.0, -6.0), (0.1, 2.0, 0.0)] {
        let pts = MerweScaledSigmaPoints::new(9, alpha, beta, kappa).unwrap();
        let mut ukf = UnscentedKalmanFilter::new(model.clone(), pts).unwrap();
        ukf.set_q(c.q.clone()).unwrap();
        ukf.set_r(c.r.clone()).unwrap();
        check_against_kf(ukf, &c, &c.q, 1e-10);
    }
}

#[test]
fn square_root_linear_ukf_equals_closed_form_kalman_filter() {
    let c = linear_case(1000);
    let model = LinearModel::new(c.f.clone(), c.h.clone(), Some(c.b.clone())).unwrap();
    // Wc0 > 0 (update) and Wc0 < 0 (downdate) branches.
    for (alpha, beta, kappa) in [(1.0, 2.0, 0.0), (0.5, 2.0, -6.0)] {
        let pts = MerweScaledSigmaPoints::new(9, alpha, beta, kappa).unwrap();
        assert_eq!(pts.wc()[0] < 0.0, alpha < 1.0);
        let mut ukf = SquareRootUkf::new(model.clone(), pts).unwrap();
        ukf.set_q(c.q.clone()).unwrap();
        ukf.set_r(c.r.clone()).unwrap();
        check_against_kf(ukf, &c, &c.q, 1e-10);
    }
}

/// `x' = F x + B u + G w` with a 3-dim process noise entering through G: the augmented form
/// must equal the Kalman filter with Q_eff = G Q Gᵀ (singular, so the additive form would
/// need a PSD Q).
struct NoiseThroughG {
    lin: LinearModel,
    g: DMatrix<f64>,
}

impl UkfModel for NoiseThroughG {
    fn dim_x(&self) -> usize {
        9
    }
    fn dim_z(&self) -> usize {
        3
    }
    fn dim_u(&self) -> usize {
        3
    }
    fn dim_w(&self) -> usize {
        3
    }
    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        self.lin.fx(x, dt, u, out)
    }
    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        self.lin.hx(x, out)
    }
    fn fx_noise(
        &self,
        x: DVectorView<'_, f64>,
        w: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        self.lin.fx(x, dt, u, out)?;
        out.gemv(1.0, &self.g, &w, 1.0);
        Ok(())
    }
}

#[test]
fn augmented_linear_ukf_equals_kalman_filter_with_projected_noise() {
    let c = linear_case(600);
    let mut g = DMatrix::zeros(9, 3);
    for i in 0..3 {
        g[(6 + i, i)] = 0.05;
        g[(3 + i, i)] = 0.01;
    }
    let qw = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 2.0, 0.5]));
    let q_eff = &g * &qw * g.transpose();
    let model = NoiseThroughG {
        lin: LinearModel::new(c.f.clone(), c.h.clone(), Some(c.b.clone())).unwrap(),
        g,
    };
    let pts = MerweScaledSigmaPoints::new(9, 0.5, 2.0, 0.0).unwrap();
    let mut ukf = UnscentedKalmanFilter::new(&model, pts.clone())
        .unwrap()
        .with_noise(NoiseForm::Augmented)
        .unwrap();
    ukf.set_q(qw.clone()).unwrap();
    ukf.set_r(c.r.clone()).unwrap();
    check_against_kf(ukf, &c, &q_eff, 1e-10);
    let mut sr = SquareRootUkf::new(&model, pts)
        .unwrap()
        .with_noise(NoiseForm::Augmented)
        .unwrap();
    sr.set_q(qw).unwrap();
    sr.set_r(c.r.clone()).unwrap();
    check_against_kf(sr, &c, &q_eff, 1e-10);
}

/// A 2-D constant-velocity target observed by range and bearing from the origin: the bearing
/// wraps at ±π, handled by z_mean/z_residual.
struct RangeBearing;

fn wrap(a: f64) -> f64 {
    let t = (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI);
    t - std::f64::consts::PI
}

impl UkfModel for RangeBearing {
    fn dim_x(&self) -> usize {
        4
    }
    fn dim_z(&self) -> usize {
        2
    }
    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        _u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out[0] = x[0] + dt * x[2];
        out[1] = x[1] + dt * x[3];
        out[2] = x[2];
        out[3] = x[3];
        Ok(())
    }
    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        out[0] = x[0].hypot(x[1]);
        out[1] = x[1].atan2(x[0]);
        Ok(())
    }
    fn z_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let (mut r, mut s, mut c) = (0.0, 0.0, 0.0);
        for i in 0..wm.len() {
            r += wm[i] * sigmas[(0, i)];
            s += wm[i] * sigmas[(1, i)].sin();
            c += wm[i] * sigmas[(1, i)].cos();
        }
        out[0] = r;
        out[1] = s.atan2(c);
        Ok(())
    }
    fn z_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out[0] = a[0] - b[0];
        out[1] = wrap(a[1] - b[1]);
        Ok(())
    }
}

fn range_bearing_data(steps: usize) -> Vec<Option<DVector<f64>>> {
    let mut rng = Pcg64::seed_from_u64(11);
    // Passes west of the origin so the bearing crosses ±π.
    let mut x = DVector::from_vec(vec![-20.0, -30.0, 0.0, 1.0]);
    let m = RangeBearing;
    (0..steps)
        .map(|_| {
            let mut nx = DVector::zeros(4);
            m.fx(x.column(0), 1.0, None, &mut nx).unwrap();
            x = nx;
            let mut z = DVector::zeros(2);
            m.hx(x.column(0), &mut z).unwrap();
            let (n0, n1): (f64, f64) = (
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            );
            z[0] += 0.5 * n0;
            z[1] = wrap(z[1] + 0.01 * n1);
            Some(z)
        })
        .collect()
}

#[test]
fn square_root_equals_standard_on_a_nonlinear_model() {
    let zs = range_bearing_data(60);
    for (alpha, beta, kappa) in [(1.0, 2.0, -1.0), (0.5, 2.0, 0.0)] {
        let pts = MerweScaledSigmaPoints::new(4, alpha, beta, kappa).unwrap();
        let p0 = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 4.0, 0.5, 0.5]));
        let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1e-3, 1e-3, 1e-3, 1e-3]));
        let r = DMatrix::from_diagonal(&DVector::from_vec(vec![0.25, 1e-4]));
        let x0 = DVector::from_vec(vec![-19.0, -29.0, 0.2, 0.8]);
        let mut std_f = UnscentedKalmanFilter::new(RangeBearing, pts.clone()).unwrap();
        let mut sr_f = SquareRootUkf::new(RangeBearing, pts).unwrap();
        for f in [&mut std_f as &mut dyn SigmaPointFilter, &mut sr_f] {
            f.set_x(x0.clone()).unwrap();
            f.set_p(p0.clone()).unwrap();
            f.set_q(q.clone()).unwrap();
            f.set_r(r.clone()).unwrap();
        }
        let a = std_f.batch(&BatchInputs::new(1.0, &zs)).unwrap();
        let b = sr_f.batch(&BatchInputs::new(1.0, &zs)).unwrap();
        for k in 0..zs.len() {
            assert!(
                close_v(
                    &a.x(k).unwrap().into_owned(),
                    &b.x(k).unwrap().into_owned(),
                    1e-9
                ),
                "x at {k}"
            );
            assert!(
                close(
                    &a.p(k).unwrap().into_owned(),
                    &b.p(k).unwrap().into_owned(),
                    1e-9
                ),
                "P at {k}"
            );
            assert!(
                close(
                    &a.p_prior(k).unwrap().into_owned(),
                    &b.p_prior(k).unwrap().into_owned(),
                    1e-9
                ),
                "P prior at {k}"
            );
            assert!((a.log_likelihoods()[k] - b.log_likelihoods()[k]).abs() < 1e-8);
        }
        // The target crossed the ±π bearing line and the filter followed it.
        let last = a.x(a.len() - 1).unwrap().into_owned();
        assert!(last[0] < 0.0 && last[1] > 0.0, "{last}");
        assert!((last[3] - 1.0).abs() < 0.1, "{last}");
    }
}

/// Attitude as a rotation vector φ (R = Exp(φ)), driven by a gyro (u = ω), observing two
/// known directions in the body frame: z = [Rᵀ g; Rᵀ m]. ⊕/⊖ are those of SO(3); the mean is
/// the iterative weighted Karcher mean of the sigma rotations.
struct Attitude;

fn rot(v: DVectorView<'_, f64>) -> nalgebra::Rotation3<f64> {
    so3_exp(&Vector3::new(v[0], v[1], v[2]))
}

const G_REF: [f64; 3] = [0.0, 0.0, 1.0];
const M_REF: [f64; 3] = [0.6, 0.0, 0.8];

impl UkfModel for Attitude {
    fn dim_x(&self) -> usize {
        3
    }
    fn dim_z(&self) -> usize {
        6
    }
    fn dim_u(&self) -> usize {
        3
    }
    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let w = u.map_or(Vector3::zeros(), |u| Vector3::new(u[0], u[1], u[2]));
        out.copy_from(&so3_log(&so3_plus(&rot(x), &(w * dt))));
        Ok(())
    }
    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        let rt = rot(x).inverse();
        let g = rt * Vector3::from(G_REF);
        let m = rt * Vector3::from(M_REF);
        out.rows_mut(0, 3).copy_from(&g);
        out.rows_mut(3, 3).copy_from(&m);
        Ok(())
    }
    fn x_add(
        &self,
        x: DVectorView<'_, f64>,
        dx: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.copy_from(&so3_log(&so3_plus(
            &rot(x),
            &Vector3::new(dx[0], dx[1], dx[2]),
        )));
        Ok(())
    }
    fn x_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.copy_from(&so3_minus(&rot(a), &rot(b)));
        Ok(())
    }
    fn x_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let mut mean = rot(sigmas.column(0));
        for _ in 0..50 {
            let mut d = Vector3::zeros();
            for i in 0..wm.len() {
                d += wm[i] * so3_minus(&rot(sigmas.column(i)), &mean);
            }
            mean = so3_plus(&mean, &d);
            if d.norm() < 1e-13 {
                out.copy_from(&so3_log(&mean));
                return Ok(());
            }
        }
        Err(EstimateError::Model {
            function: "x_mean",
            step: 0,
            message: "Karcher mean did not converge in 50 iterations".into(),
        })
    }
}

#[test]
fn so3_state_converges_across_the_chart_boundary() {
    let mut rng = Pcg64::seed_from_u64(3);
    let dt = 0.05;
    let omega = Vector3::new(0.5, 0.2, -0.3);
    // Close to a half turn, so the rotation vector of the truth jumps at ‖φ‖ = π.
    let mut truth = so3_exp(&Vector3::new(0.3, -2.6, 1.0));
    let x0 = so3_log(&so3_plus(&truth, &Vector3::new(0.4, -0.3, 0.2)));
    let pts = MerweScaledSigmaPoints::new(3, 0.5, 2.0, 0.0).unwrap();
    let mut ukf = UnscentedKalmanFilter::new(Attitude, pts.clone()).unwrap();
    let mut sr = SquareRootUkf::new(Attitude, pts).unwrap();
    let mut truths = Vec::new();
    let mut zs = Vec::new();
    let mut us = Vec::new();
    let gyro_sigma = 0.01;
    for _ in 0..400 {
        truth = so3_plus(&truth, &(omega * dt));
        truths.push(truth);
        let u = DVector::from_iterator(3, omega.iter().copied()) + normal(&mut rng, 3, gyro_sigma);
        us.push(u);
        let mut z = DVector::zeros(6);
        let phi = DVector::from_iterator(3, so3_log(&truth).iter().copied());
        Attitude.hx(phi.column(0), &mut z).unwrap();
        zs.push(Some(z + normal(&mut rng, 6, 0.02)));
    }
    let jumps = truths
        .windows(2)
        .filter(|w| (so3_log(&w[1]) - so3_log(&w[0])).norm() > 1.0)
        .count();
    assert!(jumps >= 1, "the trajectory must cross the chart boundary");
    for f in [&mut ukf as &mut dyn SigmaPointFilter, &mut sr] {
        f.set_x(DVector::from_iterator(3, x0.iter().copied()))
            .unwrap();
        f.set_p(DMatrix::identity(3, 3) * 0.3f64.powi(2)).unwrap();
        f.set_q(DMatrix::identity(3, 3) * (gyro_sigma * dt).powi(2))
            .unwrap();
        f.set_r(DMatrix::identity(6, 6) * 0.02f64.powi(2)).unwrap();
        let out = f.batch(&BatchInputs::new(dt, &zs).with_us(&us)).unwrap();
        for (k, truth) in truths.iter().enumerate().skip(20) {
            let (x, p) = (
                out.x(k).unwrap().into_owned(),
                out.p(k).unwrap().into_owned(),
            );
            let err = so3_minus(&rot(x.column(0)), truth);
            let sd = p.diagonal().map(f64::sqrt);
            assert!(err.norm() < 0.05, "step {k}: error {} rad", err.norm());
            for i in 0..3 {
                assert!(
                    err[i].abs() < 5.0 * sd[i],
                    "step {k}: error {err} vs sd {sd}"
                );
            }
            assert!(x.norm() <= std::f64::consts::PI + 1e-9);
        }
    }
    // The two forms agree on the manifold too.
    let a = ukf.x().clone();
    let b = sr.x().clone();
    assert!(so3_minus(&rot(a.column(0)), &rot(b.column(0))).norm() < 1e-8);
}

/// f(x) = [x₀²; x₁] at x = 0 with κ < 0 and β = 0 (α = 1): along x₀ the unscented variance
/// is `P₀₀²(Wc₀ + ((c−1)² + 1)/c) = (c − 1) P₀₀²` with c = n + λ = 2 + κ = 0.5, so
/// P⁻ = diag(−0.5 + Q, 1 + Q) for P = I — indefinite (Julier's known failure of negative κ).
struct Square;

impl UkfModel for Square {
    fn dim_x(&self) -> usize {
        2
    }
    fn dim_z(&self) -> usize {
        1
    }
    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        _dt: f64,
        _u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out[0] = x[0] * x[0];
        out[1] = x[1];
        Ok(())
    }
    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        out[0] = x[0] + x[1];
        Ok(())
    }
}

#[test]
fn indefinite_prior_is_reported_or_repaired() {
    let pts = MerweScaledSigmaPoints::new(2, 1.0, 0.0, -1.5).unwrap();
    let q = DMatrix::identity(2, 2) * 0.1;
    let mut ukf = UnscentedKalmanFilter::new(Square, pts.clone()).unwrap();
    ukf.set_q(q.clone()).unwrap();
    match ukf.predict(1.0, None) {
        Err(EstimateError::NotPositiveDefinite {
            step,
            min_eigenvalue,
            what,
        }) => {
            assert_eq!(step, 0);
            assert!(what.contains("P_prior"));
            assert!(
                (min_eigenvalue - (-0.5 + 0.1)).abs() < 1e-12,
                "{min_eigenvalue}"
            );
        }
        other => panic!("expected NotPositiveDefinite, got {other:?}"),
    }
    // Nothing was committed.
    assert_eq!(ukf.p(), DMatrix::identity(2, 2));
    assert_eq!(ukf.step(), 0);

    let mut sr = SquareRootUkf::new(Square, pts.clone()).unwrap();
    sr.set_q(q.clone()).unwrap();
    match sr.predict(1.0, None) {
        Err(EstimateError::NotPositiveDefinite {
            step: 0,
            min_eigenvalue,
            ..
        }) => {
            assert!(
                (min_eigenvalue - (-0.5 + 0.1)).abs() < 1e-12,
                "{min_eigenvalue}"
            );
        }
        other => panic!("expected NotPositiveDefinite, got {other:?}"),
    }

    for policy_filter in [
        Box::new(
            UnscentedKalmanFilter::new(Square, pts.clone())
                .unwrap()
                .with_policy(CovariancePolicy::Repair),
        ) as Box<dyn SigmaPointFilter>,
        Box::new(
            SquareRootUkf::new(Square, pts.clone())
                .unwrap()
                .with_policy(CovariancePolicy::Repair),
        ),
    ] {
        let mut rep = policy_filter;
        rep.set_q(q.clone()).unwrap();
        rep.predict(1.0, None).unwrap();
        assert_eq!(rep.repairs(), 1);
        let p = rep.p();
        // The negative eigenvalue is clipped to 1e-12·λ_max, the positive one kept.
        assert!((p[(1, 1)] - 1.1).abs() < 1e-12, "{p}");
        assert!(p[(0, 0)] > 0.0 && p[(0, 0)] < 1e-11, "{p}");
        rep.update(&DVector::from_element(1, 0.3), None).unwrap();
        assert!(nalgebra::Cholesky::new(rep.p()).is_some());
    }
}

/// fx returns NaN for states beyond 1: the error names the step and the sigma point.
struct NanBeyondOne;

impl UkfModel for NanBeyondOne {
    fn dim_x(&self) -> usize {
        2
    }
    fn dim_z(&self) -> usize {
        1
    }
    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        _dt: f64,
        _u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out[0] = if x[0] > 1.0 { f64::NAN } else { x[0] + 0.3 };
        out[1] = x[1];
        Ok(())
    }
    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        out[0] = x[0];
        Ok(())
    }
}

#[test]
fn nan_model_output_names_step_and_sigma_point() {
    let pts = MerweScaledSigmaPoints::new(2, 1.0, 2.0, 0.0).unwrap();
    let mut ukf = UnscentedKalmanFilter::new(NanBeyondOne, pts).unwrap();
    ukf.set_p(DMatrix::identity(2, 2) * 1e-4).unwrap();
    ukf.set_q(DMatrix::identity(2, 2) * 1e-6).unwrap();
    ukf.set_r(DMatrix::identity(1, 1) * 1e-6).unwrap();
    let zs: Vec<_> = (1..10)
        .map(|k| Some(DVector::from_element(1, 0.3 * k as f64)))
        .collect();
    // After 4 predictions x ≈ 1.2: every sigma point of step 4 is beyond 1 → NaN.
    match ukf.batch(&BatchInputs::new(1.0, &zs)) {
        Err(EstimateError::NonFinite {
            step, what, value, ..
        }) => {
            assert_eq!(step, 4);
            assert!(what.starts_with("fx output at sigma point"), "{what}");
            assert!(value.is_nan());
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }
    assert_eq!(ukf.step(), 4);
    let x = ukf.x()[0];
    assert!((x - 1.2).abs() < 1e-3, "{x}");
}

#[test]
fn size_mismatches_and_bad_inputs_are_reported() {
    let model = ConstantVelocityModel::new(2).unwrap();
    assert!(matches!(
        UnscentedKalmanFilter::new(
            model,
            MerweScaledSigmaPoints::new(3, 1.0, 2.0, 0.0).unwrap()
        ),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    let pts = MerweScaledSigmaPoints::new(4, 1.0, 2.0, 0.0).unwrap();
    let mut ukf = UnscentedKalmanFilter::new(model, pts).unwrap();
    let err = ukf.update(&DVector::zeros(3), None).unwrap_err();
    assert_eq!(
        err,
        EstimateError::DimensionMismatch {
            what: "measurement z".into(),
            expected: vec![2],
            got: vec![3]
        }
    );
    assert!(err.to_string().contains("expected shape (2,), got (3,)"));
    assert!(matches!(
        ukf.set_q(DMatrix::identity(3, 3)),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        ukf.set_x(DVector::zeros(5)),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        ukf.predict(1.0, Some(&DVector::zeros(3))),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        ukf.update(&DVector::from_vec(vec![1.0, f64::NAN]), None),
        Err(EstimateError::NonFiniteInput { index: 1, .. })
    ));
    assert!(matches!(
        ukf.predict(f64::INFINITY, None),
        Err(EstimateError::NonFiniteInput { .. })
    ));
    let indefinite = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, -1.0, 1.0, 1.0]));
    assert!(matches!(
        ukf.set_p(indefinite.clone()),
        Err(EstimateError::InvalidCovariance { .. })
    ));
    assert!(matches!(
        ukf.set_r(DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, -1.0]))),
        Err(EstimateError::InvalidCovariance { .. })
    ));
    let mut asym = DMatrix::identity(4, 4);
    asym[(0, 1)] = 0.5;
    assert!(matches!(
        ukf.set_p(asym),
        Err(EstimateError::InvalidCovariance { .. })
    ));
    // Batch lengths.
    let zs = vec![Some(DVector::zeros(2)); 3];
    let dts = [1.0, 1.0];
    assert!(matches!(
        ukf.batch(&BatchInputs::new(1.0, &zs).with_dts(&dts)),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    // A model without input rejects u.
    let lin = LinearModel::new(DMatrix::identity(2, 2), DMatrix::identity(1, 2), None).unwrap();
    let mut f =
        UnscentedKalmanFilter::new(lin, MerweScaledSigmaPoints::new(2, 1.0, 2.0, 1.0).unwrap())
            .unwrap();
    assert!(matches!(
        f.predict(1.0, Some(&DVector::zeros(1))),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    assert!(LinearModel::new(DMatrix::identity(2, 2), DMatrix::identity(1, 3), None).is_err());
    assert!(LinearModel::new(DMatrix::identity(2, 3), DMatrix::identity(1, 2), None).is_err());
    // The repair policy accepts and clips an indefinite initial P.
    let mut rep = UnscentedKalmanFilter::new(
        ConstantVelocityModel::new(2).unwrap(),
        MerweScaledSigmaPoints::new(4, 1.0, 2.0, 0.0).unwrap(),
    )
    .unwrap()
    .with_policy(CovariancePolicy::Repair);
    rep.set_p(indefinite).unwrap();
    assert_eq!(rep.repairs(), 1);
    assert!(rep.p()[(1, 1)] > 0.0);
}

#[test]
fn constant_velocity_model_matches_its_linear_form() {
    // CV with acceleration input equals LinearModel with the same F, B for a fixed dt.
    let dt = 0.2;
    let mut f = DMatrix::identity(4, 4);
    f[(0, 2)] = dt;
    f[(1, 3)] = dt;
    let h = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    let b = DMatrix::from_row_slice(
        4,
        2,
        &[0.5 * dt * dt, 0.0, 0.0, 0.5 * dt * dt, dt, 0.0, 0.0, dt],
    );
    let lin = LinearModel::new(f, h, Some(b)).unwrap();
    let cv = ConstantVelocityModel::new(2).unwrap();
    let mut rng = Pcg64::seed_from_u64(5);
    let zs: Vec<_> = (0..100).map(|_| Some(normal(&mut rng, 2, 1.0))).collect();
    let us: Vec<_> = (0..100).map(|_| normal(&mut rng, 2, 1.0)).collect();
    let pts = MerweScaledSigmaPoints::new(4, 0.7, 2.0, 0.0).unwrap();
    let mut a = UnscentedKalmanFilter::new(lin, pts.clone()).unwrap();
    let mut c = UnscentedKalmanFilter::new(cv, pts).unwrap();
    let ra = a.batch(&BatchInputs::new(dt, &zs).with_us(&us)).unwrap();
    let rc = c.batch(&BatchInputs::new(dt, &zs).with_us(&us)).unwrap();
    for k in 0..100 {
        assert!(close_v(
            &ra.x(k).unwrap().into_owned(),
            &rc.x(k).unwrap().into_owned(),
            1e-12
        ));
        assert!(close(
            &ra.p(k).unwrap().into_owned(),
            &rc.p(k).unwrap().into_owned(),
            1e-12
        ));
    }
}
