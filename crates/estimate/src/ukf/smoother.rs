//! The unscented Rauch–Tung–Striebel smoother.

use nalgebra::{DMatrix, DVector};

use super::family::SigmaPoints;
use super::linalg;
use super::model::UkfModel;
use super::transform::{self, Space, Workspace};
use crate::{EstimateError, Result};

/// The smoothed run of [`rts_smoother`].
#[derive(Debug, Clone, PartialEq)]
pub struct RtsResult {
    /// Smoothed means, one per epoch.
    pub xs: Vec<DVector<f64>>,
    /// Smoothed covariances.
    pub ps: Vec<DMatrix<f64>>,
    /// Smoother gains (the last one is zero, as in filterpy).
    pub ks: Vec<DMatrix<f64>>,
}

/// The unscented RTS smoother (Särkkä 2008) of the filtered means `xs` and covariances `ps`
/// of a run of the UKF of seed 000_3b1454b2b2194811.txt §5.2 (eqs. (5.1)–(5.2)), in the
/// formulation of filterpy's `UnscentedKalmanFilter.rts_smoother`. Backwards over
/// k = n−2 … 0, with χᵢ the sigma points of (xₖ, Pₖ) (the filtered values):
///
/// * `x̄ = Σ Wmᵢ f(χᵢ)`, `P̄ = Σ Wcᵢ (f(χᵢ) ⊖ x̄)(f(χᵢ) ⊖ x̄)ᵀ + Qₖ`,
/// * `C = Σ Wcᵢ (χᵢ ⊖ xₖ)(f(χᵢ) ⊖ x̄)ᵀ`, `Kₖ = C P̄⁻¹`,
/// * `xₖˢ = xₖ + Kₖ (xₖ₊₁ˢ ⊖ x̄)`, `Pₖˢ = Pₖ + Kₖ (Pₖ₊₁ˢ − P̄) Kₖᵀ`.
///
/// `f` is `model.fx` over `dts[k]` with input `us[k]` (if given); the mean and ⊖ are the
/// model's hooks, the sigma points its ⊕ (or its own draw for [`SigmaPoints::Given`]). `qs`
/// holds one Q for all epochs or one per epoch (filterpy itself uses the filter's Q for
/// every epoch whatever `Qs` says: with a constant Q the two agree). Only additive noise.
///
/// Fails on sizes that disagree, NaN/inf, a `Pₖ` that is not positive definite or a `P̄`
/// that cannot be inverted (naming the epoch).
pub fn rts_smoother<M: UkfModel + ?Sized>(
    model: &M,
    points: &SigmaPoints,
    xs: &[DVector<f64>],
    ps: &[DMatrix<f64>],
    qs: &[DMatrix<f64>],
    dts: &[f64],
    us: Option<&[DVector<f64>]>,
) -> Result<RtsResult> {
    let n = model.dim_x();
    let steps = xs.len();
    let mismatch = |what: &str, expected: usize, got: usize| EstimateError::DimensionMismatch {
        what: what.to_string(),
        expected: vec![expected],
        got: vec![got],
    };
    if points.n() != n {
        return Err(mismatch(
            "sigma points n (the state dimension)",
            n,
            points.n(),
        ));
    }
    if ps.len() != steps {
        return Err(mismatch(
            "number of covariances Ps (one per mean)",
            steps,
            ps.len(),
        ));
    }
    if dts.len() != steps {
        return Err(mismatch("number of time steps dts", steps, dts.len()));
    }
    if qs.len() != 1 && qs.len() != steps {
        return Err(mismatch(
            "number of process noises Qs (1 or one per epoch)",
            steps,
            qs.len(),
        ));
    }
    if let Some(us) = us
        && us.len() != steps
    {
        return Err(mismatch("number of inputs us", steps, us.len()));
    }
    for (k, (x, p)) in xs.iter().zip(ps).enumerate() {
        linalg::check_len(x, n, &format!("Xs[{k}]"))?;
        linalg::check_finite_input(x.as_slice(), &format!("Xs[{k}]"))?;
        linalg::check_shape(p, n, n, &format!("Ps[{k}]"))?;
        linalg::check_finite_input(p.as_slice(), &format!("Ps[{k}]"))?;
        if !dts[k].is_finite() {
            return Err(EstimateError::NonFiniteInput {
                what: format!("dts[{k}]"),
                index: k,
                value: dts[k],
            });
        }
    }
    for (k, q) in qs.iter().enumerate() {
        linalg::check_shape(q, n, n, &format!("Qs[{k}]"))?;
        linalg::check_finite_input(q.as_slice(), &format!("Qs[{k}]"))?;
    }
    let mut out = RtsResult {
        xs: xs.to_vec(),
        ps: ps.to_vec(),
        ks: vec![DMatrix::zeros(n, n); steps],
    };
    if steps < 2 {
        return Ok(out);
    }
    let ns = points.num_sigmas();
    let mut ws = Workspace::new(n, 0, n, ns);
    let mut xb = DVector::zeros(n);
    let mut pb = DMatrix::zeros(n, n);
    let mut pxb = DMatrix::zeros(n, n);
    let mut r = DVector::zeros(n);
    for k in (0..steps - 1).rev() {
        transform::draw_cov(model, points, &xs[k], &ps[k], &mut ws, k)?;
        let u = us.map(|us| &us[k]);
        transform::propagate_f(model, false, dts[k], u, &mut ws, k)?;
        transform::mean_and_devs(model, Space::State, points.wm(), &mut xb, &mut ws, k)?;
        transform::weighted_gram(&ws.dev_out, points.wc(), &mut ws.scratch, &mut pb);
        pb += &qs[if qs.len() == 1 { 0 } else { k }];
        transform::state_devs(model, &xs[k], &mut ws, k)?;
        transform::weighted_outer(&ws.dev_x, points.wc(), &ws.dev_out, &mut pxb);
        // K = C P̄⁻¹  ⇔  P̄ Kᵀ = Cᵀ (P̄ symmetric), by LU so that a P̄ that is merely
        // invertible (a singular Q) is accepted as filterpy's inverse accepts it.
        let kt = pb
            .clone()
            .lu()
            .solve(&pxb.transpose())
            .filter(|kt| linalg::first_non_finite(kt.as_slice()).is_none())
            .ok_or_else(|| EstimateError::NotPositiveDefinite {
                what: "predicted smoother covariance P̄".to_string(),
                step: k,
                min_eigenvalue: linalg::min_eigenvalue(&pb),
            })?;
        let gain = kt.transpose();
        model
            .x_residual(out.xs[k + 1].column(0), xb.column(0), &mut r)
            .map_err(|e| transform::at_step(e, k))?;
        let dx = &gain * &r;
        out.xs[k] += dx;
        let dp = &gain * (&out.ps[k + 1] - &pb) * gain.transpose();
        out.ps[k] += dp;
        out.ks[k] = gain;
        linalg::check_finite_at(out.xs[k].as_slice(), || "smoothed mean".to_string(), k)?;
        linalg::check_finite_at(
            out.ps[k].as_slice(),
            || "smoothed covariance".to_string(),
            k,
        )?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ukf::{
        BatchInputs, JulierSigmaPoints, LinearModel, MerweScaledSigmaPoints, SigmaPointFilter,
        SimplexSigmaPoints, UnscentedKalmanFilter,
    };

    /// A linear Gaussian model: the unscented smoother equals the Kalman RTS smoother
    /// (computed here in closed form) for every sigma-point family.
    #[test]
    fn linear_model_matches_the_kalman_rts_smoother() {
        let f = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0]);
        let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let q = DMatrix::from_row_slice(2, 2, &[0.01, 0.02, 0.02, 0.05]);
        let zs: Vec<_> = (0..30)
            .map(|k| {
                Some(DVector::from_element(
                    1,
                    0.3 * k as f64 + (k as f64 * 1.7).sin() * 0.2,
                ))
            })
            .collect();
        let fams: Vec<SigmaPoints> = vec![
            MerweScaledSigmaPoints::new(2, 0.5, 2.0, 1.0)
                .unwrap()
                .into(),
            JulierSigmaPoints::new(2, 1.0).unwrap().into(),
            SimplexSigmaPoints::new(2).unwrap().into(),
        ];
        for pts in fams {
            let model = LinearModel::new(f.clone(), h.clone(), None).unwrap();
            let mut ukf = UnscentedKalmanFilter::new(model.clone(), pts.clone()).unwrap();
            ukf.set_q(q.clone()).unwrap();
            ukf.set_r(DMatrix::identity(1, 1) * 0.04).unwrap();
            let run = ukf.batch(&BatchInputs::new(1.0, &zs)).unwrap();
            let steps = zs.len();
            let xs: Vec<_> = (0..steps).map(|k| run.x(k).unwrap().into_owned()).collect();
            let ps: Vec<_> = (0..steps).map(|k| run.p(k).unwrap().into_owned()).collect();
            let sm = rts_smoother(
                &model,
                &pts,
                &xs,
                &ps,
                std::slice::from_ref(&q),
                &vec![1.0; steps],
                None,
            )
            .unwrap();
            // Kalman RTS: P̄ = F P Fᵀ + Q, K = P Fᵀ P̄⁻¹.
            let (mut xk, mut pk) = (xs[steps - 1].clone(), ps[steps - 1].clone());
            for k in (0..steps - 1).rev() {
                let pbar = &f * &ps[k] * f.transpose() + &q;
                let g = &ps[k] * f.transpose() * pbar.clone().try_inverse().unwrap();
                xk = &xs[k] + &g * (&xk - &f * &xs[k]);
                pk = &ps[k] + &g * (&pk - &pbar) * g.transpose();
                assert!((&xk - &sm.xs[k]).amax() < 1e-9, "{pts:?} x at {k}");
                assert!((&pk - &sm.ps[k]).amax() < 1e-9, "{pts:?} P at {k}");
                assert!((&g - &sm.ks[k]).amax() < 1e-9, "{pts:?} K at {k}");
            }
            assert_eq!(sm.ks[steps - 1], DMatrix::zeros(2, 2));
        }
    }

    #[test]
    fn bad_inputs_are_refused() {
        let model = LinearModel::new(
            DMatrix::identity(2, 2),
            DMatrix::identity(1, 2).rows(0, 1).into_owned(),
            None,
        )
        .unwrap();
        let pts: SigmaPoints = JulierSigmaPoints::new(2, 0.0).unwrap().into();
        let xs = vec![DVector::zeros(2); 3];
        let ps = vec![DMatrix::identity(2, 2); 3];
        let q = [DMatrix::identity(2, 2)];
        assert!(rts_smoother(&model, &pts, &xs, &ps[..2], &q, &[1.0; 3], None).is_err());
        assert!(rts_smoother(&model, &pts, &xs, &ps, &q, &[1.0; 2], None).is_err());
        let mut bad = ps.clone();
        bad[0][(0, 0)] = -1.0;
        assert!(matches!(
            rts_smoother(&model, &pts, &xs, &bad, &q, &[1.0; 3], None),
            Err(EstimateError::NotPositiveDefinite { step: 0, .. })
        ));
        let mut nan = xs.clone();
        nan[1][0] = f64::NAN;
        assert!(rts_smoother(&model, &pts, &nan, &ps, &q, &[1.0; 3], None).is_err());
    }
}
