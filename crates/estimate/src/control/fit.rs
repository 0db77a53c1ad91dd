//! Transfer-function fitting from frequency-response data, the role MATLAB's `tfest` plays in
//! 000_3b1454b2b2194811.txt ch. 2.5 ("for each frequency response, we fit a transfer function
//! that captures all the resonances", Fig. 2.13).
//!
//! Method: Sanathanan–Koerner iteration (Sanathanan & Koerner 1963) — the linearised problem
//! `min Σ w_k² |N(s_k) − H_k D(s_k)|² / |D_prev(s_k)|²` solved repeatedly — then a
//! Levenberg–Marquardt refinement of the true output error `Σ w_k² |N/D(s_k) − H_k|²`. Poles
//! in the right half plane are reflected to the left and the numerator refitted, so the model
//! is stable. Known integrators are divided out of the data first. Frequencies are scaled by
//! the largest one so the monomial basis stays conditioned.

use nalgebra::{DMatrix, DVector};

use super::poly::{self, C64};
use super::tf::TransferFunction;
use crate::{EstimateError, Result};

/// Options of [`fit_frequency_response`].
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// Numerator degree (of the part without the integrators).
    pub num_order: usize,
    /// Denominator degree (without the integrators).
    pub den_order: usize,
    /// Number of known poles at the origin (e.g. 1 for torque → position with viscous friction).
    pub integrators: usize,
    /// Per-point weights (`None`: `1/|H_k|`, i.e. relative error, so resonances and the
    /// high-frequency roll-off weigh alike).
    pub weights: Option<Vec<f64>>,
    /// Sanathanan–Koerner iterations.
    pub sk_iterations: usize,
    /// Levenberg–Marquardt iterations after SK.
    pub lm_iterations: usize,
    /// Reflect unstable poles into the left half plane.
    pub enforce_stable: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            num_order: 2,
            den_order: 4,
            integrators: 0,
            weights: None,
            sk_iterations: 30,
            lm_iterations: 50,
            enforce_stable: true,
        }
    }
}

/// A fitted model and its quality.
#[derive(Debug, Clone)]
pub struct FitResult {
    /// The model, integrators included.
    pub model: TransferFunction,
    /// Relative weighted residual `sqrt(Σ w²|G−H|² / Σ w²|H|²)`.
    pub residual: f64,
    /// Poles that were reflected from the right half plane.
    pub reflected_poles: usize,
}

/// Validates a frequency-response data set: equal lengths, finite values, strictly increasing
/// positive frequencies.
pub fn validate_data(w: &[f64], h: &[C64]) -> Result<()> {
    if w.len() != h.len() {
        return Err(EstimateError::DimensionMismatch {
            what: "frequency response h".into(),
            expected: vec![w.len()],
            got: vec![h.len()],
        });
    }
    for (i, &x) in w.iter().enumerate() {
        if !x.is_finite() {
            return Err(EstimateError::NonFiniteInput {
                what: "frequencies".into(),
                index: i,
                value: x,
            });
        }
        if x <= 0.0 {
            return Err(EstimateError::InvalidModel {
                what: "frequency data".into(),
                reason: format!("frequency {x} at index {i} is not positive"),
            });
        }
        if i > 0 && x <= w[i - 1] {
            return Err(EstimateError::InvalidModel {
                what: "frequency data".into(),
                reason: format!(
                    "frequencies not strictly increasing at index {i}: {} then {x}",
                    w[i - 1]
                ),
            });
        }
    }
    for (i, z) in h.iter().enumerate() {
        if !(z.re.is_finite() && z.im.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: "frequency response h".into(),
                index: i,
                value: z.re + z.im,
            });
        }
    }
    Ok(())
}

/// Ascending-power evaluation `Σ c_i x^i`.
fn eval_asc(c: &[f64], s: C64) -> C64 {
    c.iter()
        .rev()
        .fold(C64::new(0.0, 0.0), |acc, &v| acc * s + v)
}

/// Least squares on stacked real/imaginary rows.
fn lstsq(a: DMatrix<f64>, b: DVector<f64>) -> Result<DVector<f64>> {
    let svd = a.svd(true, true);
    svd.solve(&b, 1e-13)
        .map_err(|e| EstimateError::LinearSolver(e.to_string()))
}

/// Fits `G(s) = N(s) / (D(s) s^integrators)` to `h_k ≈ G(jω_k)`.
///
/// Errors: malformed data ([`validate_data`]), more parameters than real equations, a
/// denominator order of zero with integrators only is fine; non-finite or negative weights.
pub fn fit_frequency_response(w: &[f64], h: &[C64], opts: &FitOptions) -> Result<FitResult> {
    validate_data(w, h)?;
    let n = w.len();
    let nb = opts.num_order;
    let na = opts.den_order;
    let params = nb + 1 + na;
    if 2 * n < params + 1 {
        return Err(EstimateError::InvalidParameter {
            name: "frequency points",
            value: n as f64,
            reason: "fewer real equations than model parameters",
        });
    }
    let weights: Vec<f64> = match &opts.weights {
        Some(ws) => {
            if ws.len() != n {
                return Err(EstimateError::DimensionMismatch {
                    what: "weights".into(),
                    expected: vec![n],
                    got: vec![ws.len()],
                });
            }
            if let Some((i, &v)) = ws
                .iter()
                .enumerate()
                .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
            {
                return Err(EstimateError::NonFiniteInput {
                    what: "weights (must be finite and ≥ 0)".into(),
                    index: i,
                    value: v,
                });
            }
            ws.clone()
        }
        None => h
            .iter()
            .map(|z| if z.norm() > 0.0 { 1.0 / z.norm() } else { 0.0 })
            .collect(),
    };
    let ws = w[n - 1];
    let s: Vec<C64> = w.iter().map(|&x| C64::new(0.0, x / ws)).collect();
    let s_true: Vec<C64> = w.iter().map(|&x| C64::new(0.0, x)).collect();
    // Remove the integrators: H'(s) = H(s) s^k, in scaled units (s^k = ws^k ŝ^k).
    let hp: Vec<C64> = h
        .iter()
        .zip(&s_true)
        .map(|(&z, &st)| z * st.powi(opts.integrators as i32) / ws.powi(opts.integrators as i32))
        .collect();
    let wts: Vec<f64> = weights
        .iter()
        .zip(h.iter().zip(&hp))
        .map(|(&wt, (z, zp))| {
            if zp.norm() > 0.0 {
                wt * z.norm() / zp.norm()
            } else {
                0.0
            }
        })
        .collect();
    // Ascending coefficients: b_0..b_nb, a_0 = 1, a_1..a_na.
    let mut a = vec![1.0; na + 1];
    for v in a.iter_mut().skip(1) {
        *v = 0.0;
    }
    let mut b = vec![0.0; nb + 1];
    for _ in 0..opts.sk_iterations {
        let mut m = DMatrix::zeros(2 * n, params);
        let mut rhs = DVector::zeros(2 * n);
        for k in 0..n {
            let dprev = eval_asc(&a, s[k]);
            let scale = wts[k] / dprev.norm().max(1e-300);
            let mut sp = C64::new(1.0, 0.0);
            for i in 0..=nb {
                let v = sp * scale;
                m[(2 * k, i)] = v.re;
                m[(2 * k + 1, i)] = v.im;
                sp *= s[k];
            }
            let mut sp = s[k];
            for i in 1..=na {
                let v = -hp[k] * sp * scale;
                m[(2 * k, nb + i)] = v.re;
                m[(2 * k + 1, nb + i)] = v.im;
                sp *= s[k];
            }
            let r = hp[k] * scale;
            rhs[2 * k] = r.re;
            rhs[2 * k + 1] = r.im;
        }
        let x = lstsq(m, rhs)?;
        let new_a: Vec<f64> = std::iter::once(1.0)
            .chain((1..=na).map(|i| x[nb + i]))
            .collect();
        let change = new_a
            .iter()
            .zip(&a)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        a = new_a;
        b = (0..=nb).map(|i| x[i]).collect();
        if change < 1e-12 {
            break;
        }
    }
    // Output-error refinement (Levenberg–Marquardt on b and a_1..a_na).
    let residual_of = |b: &[f64], a: &[f64]| -> f64 {
        (0..n)
            .map(|k| (wts[k] * (eval_asc(b, s[k]) / eval_asc(a, s[k]) - hp[k])).norm_sqr())
            .sum::<f64>()
    };
    let mut lambda = 1e-3;
    let mut cost = residual_of(&b, &a);
    for _ in 0..opts.lm_iterations {
        let mut jac = DMatrix::zeros(2 * n, params);
        let mut res = DVector::zeros(2 * n);
        for k in 0..n {
            let nk = eval_asc(&b, s[k]);
            let dk = eval_asc(&a, s[k]);
            let e = wts[k] * (nk / dk - hp[k]);
            res[2 * k] = e.re;
            res[2 * k + 1] = e.im;
            let mut sp = C64::new(1.0, 0.0);
            for i in 0..=nb {
                let v = wts[k] * sp / dk;
                jac[(2 * k, i)] = v.re;
                jac[(2 * k + 1, i)] = v.im;
                sp *= s[k];
            }
            let mut sp = s[k];
            for i in 1..=na {
                let v = -wts[k] * nk * sp / (dk * dk);
                jac[(2 * k, nb + i)] = v.re;
                jac[(2 * k + 1, nb + i)] = v.im;
                sp *= s[k];
            }
        }
        let jt = jac.transpose();
        let jtj = &jt * &jac;
        let g = &jt * &res;
        let mut improved = false;
        for _ in 0..10 {
            let mut aug = jtj.clone();
            for i in 0..params {
                aug[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = aug.lu().solve(&(-&g)) else {
                break;
            };
            let nb_: Vec<f64> = (0..=nb).map(|i| b[i] + step[i]).collect();
            let na_: Vec<f64> = std::iter::once(1.0)
                .chain((1..=na).map(|i| a[i] + step[nb + i]))
                .collect();
            let c = residual_of(&nb_, &na_);
            if c.is_finite() && c < cost {
                let rel = (cost - c) / cost.max(1e-300);
                b = nb_;
                a = na_;
                cost = c;
                lambda = (lambda * 0.3).max(1e-12);
                improved = rel > 1e-12;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    // Stability: reflect right-half-plane poles and refit the numerator with D fixed.
    let mut reflected = 0;
    if opts.enforce_stable && na > 0 {
        let desc: Vec<f64> = a.iter().rev().cloned().collect();
        let roots = poly::roots(&desc);
        if roots.iter().any(|r| r.re >= 0.0) {
            let fixed: Vec<C64> = roots
                .iter()
                .map(|r| {
                    if r.re >= 0.0 {
                        reflected += 1;
                        C64::new(-r.re.abs().max(1e-9 * r.norm().max(1e-9)), r.im)
                    } else {
                        *r
                    }
                })
                .collect();
            let monic = poly::from_roots(&fixed);
            let a0 = *monic.last().unwrap_or(&1.0);
            a = monic.iter().rev().map(|c| c / a0).collect();
            let mut m = DMatrix::zeros(2 * n, nb + 1);
            let mut rhs = DVector::zeros(2 * n);
            for k in 0..n {
                let dk = eval_asc(&a, s[k]);
                let mut sp = C64::new(1.0, 0.0);
                for i in 0..=nb {
                    let v = wts[k] * sp / dk;
                    m[(2 * k, i)] = v.re;
                    m[(2 * k + 1, i)] = v.im;
                    sp *= s[k];
                }
                let r = wts[k] * hp[k];
                rhs[2 * k] = r.re;
                rhs[2 * k + 1] = r.im;
            }
            let x = lstsq(m, rhs)?;
            b = x.iter().cloned().collect();
        }
    }
    // Back to physical frequency: coefficient of ŝ^i → divide by ws^i; integrators scale.
    let ki = opts.integrators as i32;
    let num_asc: Vec<f64> = b
        .iter()
        .enumerate()
        .map(|(i, &c)| c / ws.powi(i as i32) * ws.powi(ki))
        .collect();
    let den_asc: Vec<f64> = a
        .iter()
        .enumerate()
        .map(|(i, &c)| c / ws.powi(i as i32))
        .collect();
    let num: Vec<f64> = num_asc.into_iter().rev().collect();
    let mut den: Vec<f64> = den_asc.into_iter().rev().collect();
    den.extend(std::iter::repeat_n(0.0, opts.integrators));
    let model = TransferFunction::new(&num, &den)?;
    let mut e2 = 0.0;
    let mut h2 = 0.0;
    for k in 0..n {
        e2 += (weights[k] * (model.freq_resp(w[k]) - h[k])).norm_sqr();
        h2 += (weights[k] * h[k]).norm_sqr();
    }
    Ok(FitResult {
        model,
        residual: (e2 / h2.max(1e-300)).sqrt(),
        reflected_poles: reflected,
    })
}

/// Order choice: fits every denominator order in `den_orders` (numerator order
/// `den_order − relative_degree`, at least 0) and returns the lowest order whose residual is
/// within `tolerance` (e.g. 1.05) of the best one found.
pub fn fit_select_order(
    w: &[f64],
    h: &[C64],
    den_orders: &[usize],
    relative_degree: usize,
    base: &FitOptions,
    tolerance: f64,
) -> Result<FitResult> {
    if den_orders.is_empty() {
        return Err(EstimateError::InvalidParameter {
            name: "den_orders",
            value: 0.0,
            reason: "no candidate order",
        });
    }
    let mut fits = Vec::new();
    for &na in den_orders {
        let opts = FitOptions {
            den_order: na,
            num_order: na.saturating_sub(relative_degree),
            ..base.clone()
        };
        fits.push(fit_frequency_response(w, h, &opts)?);
    }
    let best = fits
        .iter()
        .map(|f| f.residual)
        .fold(f64::INFINITY, f64::min);
    let mut order: Vec<usize> = (0..fits.len()).collect();
    order.sort_by_key(|&i| den_orders[i]);
    let pick = order
        .into_iter()
        .find(|&i| fits[i].residual <= tolerance * best)
        .unwrap_or(0);
    Ok(fits.swap_remove(pick))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_data_is_recovered() {
        // 1/(s (s^2 + 2·0.02·300 s + 300^2)) · (s^2 + 2·0.03·150 s + 150^2) · 2e4
        let truth = TransferFunction::new(
            &poly::scale(&[1.0, 2.0 * 0.03 * 150.0, 150.0 * 150.0], 2e4),
            &poly::mul(&[1.0, 2.0 * 0.02 * 300.0, 300.0 * 300.0], &[1.0, 5.0, 0.0]),
        )
        .unwrap();
        let w: Vec<f64> = (0..300)
            .map(|i| 10f64.powf(0.5 + 2.5 * i as f64 / 299.0))
            .collect();
        let h = truth.freq_resp_many(&w);
        let fit = fit_frequency_response(
            &w,
            &h,
            &FitOptions {
                num_order: 2,
                den_order: 3,
                integrators: 1,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(fit.residual < 1e-8, "{}", fit.residual);
        for (p, q) in fit.model.den().iter().zip(truth.den()) {
            assert!((p - q).abs() <= 1e-5 * q.abs().max(1.0), "{p} vs {q}");
        }
    }

    #[test]
    fn bad_frequency_data_is_rejected() {
        let h = vec![C64::new(1.0, 0.0); 3];
        assert!(validate_data(&[1.0, 3.0, 2.0], &h).is_err());
        assert!(validate_data(&[1.0, f64::NAN, 2.0], &h).is_err());
        assert!(validate_data(&[0.0, 1.0, 2.0], &h).is_err());
        assert!(validate_data(&[1.0, 2.0], &h).is_err());
    }
}
