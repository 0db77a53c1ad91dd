//! Time-domain simulation of a transfer function with the input held constant between
//! samples (zero-order hold), discretised exactly by the matrix exponential:
//! `exp([[A, B], [0, 0]]·Δt) = [[A_d, B_d], [0, I]]`, so `x_{k+1} = A_d x_k + B_d u_k`. Used for
//! the S-curve moves of Table 2.4 (000_3b1454b2b2194811.txt ch. 2.5).

use nalgebra::{DMatrix, DVector};

use super::tf::TransferFunction;
use crate::{EstimateError, Result};

/// A continuous state-space realisation `(A, B, C, D)` of a proper SISO transfer function.
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// State matrix.
    pub a: DMatrix<f64>,
    /// Input column.
    pub b: DVector<f64>,
    /// Output row.
    pub c: DVector<f64>,
    /// Feed-through.
    pub d: f64,
}

impl StateSpace {
    /// Controllable canonical realisation in the time scale `ω₀ = |a_n|^{1/n}` (the geometric
    /// mean of the pole magnitudes): the companion matrix of `den(ω₀ ŝ)/ω₀ⁿ` times `ω₀`, which
    /// keeps the coefficients of stiff resonant models (poles from 1 to 10⁴ rad/s) near one.
    pub fn from_tf(g: &TransferFunction) -> Result<Self> {
        g.require_proper("transfer function to simulate")?;
        let den = g.den();
        let n = den.len() - 1;
        let mut num = vec![0.0; n + 1 - g.num().len()];
        num.extend_from_slice(g.num());
        let mut nz = den[1..]
            .iter()
            .rev()
            .position(|&c| c != 0.0)
            .map(|p| n - p)
            .unwrap_or(0);
        if nz == 0 {
            nz = n.max(1);
        }
        let w0 = if n == 0 {
            1.0
        } else {
            // Scale by the nonzero trailing coefficient (poles at the origin do not count).
            let an = den[nz].abs();
            if an > 0.0 {
                an.powf(1.0 / nz as f64)
            } else {
                1.0
            }
        };
        // Coefficient of s^p divided by w0^(n-p).
        let a_hat: Vec<f64> = (0..=n).map(|k| den[k] / w0.powi(k as i32)).collect();
        let b_hat: Vec<f64> = (0..=n).map(|k| num[k] / w0.powi(k as i32)).collect();
        let d = b_hat[0];
        let mut a = DMatrix::zeros(n, n);
        let mut c = DVector::zeros(n);
        for j in 0..n {
            a[(0, j)] = -a_hat[j + 1] * w0;
            c[j] = b_hat[j + 1] - d * a_hat[j + 1];
        }
        for i in 1..n {
            a[(i, i - 1)] = w0;
        }
        let mut b = DVector::zeros(n);
        if n > 0 {
            b[0] = w0;
        }
        Ok(Self { a, b, c, d })
    }

    /// Exact zero-order-hold discretisation `(A_d, B_d)` for sample time `dt`.
    pub fn zoh(&self, dt: f64) -> Result<(DMatrix<f64>, DVector<f64>)> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "dt",
                value: dt,
                reason: "must be finite and > 0",
            });
        }
        let n = self.a.nrows();
        let mut m = DMatrix::zeros(n + 1, n + 1);
        m.view_mut((0, 0), (n, n)).copy_from(&(&self.a * dt));
        m.view_mut((0, n), (n, 1)).copy_from(&(&self.b * dt));
        let e = m.exp();
        Ok((
            e.view((0, 0), (n, n)).into_owned(),
            e.view((0, n), (n, 1)).column(0).into_owned(),
        ))
    }
}

/// Response `y_k` of `g` (zero initial state) to the samples `u_k` held over `[k dt, (k+1) dt)`.
pub fn lsim(g: &TransferFunction, u: &[f64], dt: f64) -> Result<Vec<f64>> {
    if let Some((i, &v)) = u.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(EstimateError::NonFiniteInput {
            what: "input u".into(),
            index: i,
            value: v,
        });
    }
    let ss = StateSpace::from_tf(g)?;
    let (ad, bd) = ss.zoh(dt)?;
    let mut x = DVector::zeros(ss.a.nrows());
    let mut y = Vec::with_capacity(u.len());
    for &uk in u {
        y.push(ss.c.dot(&x) + ss.d * uk);
        x = &ad * &x + &bd * uk;
    }
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_step_matches_closed_form() {
        let a = 7.0;
        let g = TransferFunction::new(&[a], &[1.0, a]).unwrap();
        let dt = 0.01;
        let y = lsim(&g, &[1.0; 200], dt).unwrap();
        for (k, yk) in y.iter().enumerate() {
            let t = k as f64 * dt;
            assert!((yk - (1.0 - (-a * t).exp())).abs() < 1e-12, "k {k}");
        }
    }

    #[test]
    fn resonant_step_matches_closed_form() {
        // wn^2 / (s^2 + 2 z wn s + wn^2), z = 0.05, wn = 2π·300 rad/s, with a pole at the origin
        // (ramp response) to check stiff, marginal models.
        let (z, wn) = (0.05_f64, 2.0 * std::f64::consts::PI * 300.0);
        let g = TransferFunction::new(&[wn * wn], &[1.0, 2.0 * z * wn, wn * wn]).unwrap();
        let dt = 1e-4;
        let y = lsim(&g, &[1.0; 500], dt).unwrap();
        let wd = wn * (1.0 - z * z).sqrt();
        for (k, yk) in y.iter().enumerate() {
            let t = k as f64 * dt;
            let exact = 1.0 - (-z * wn * t).exp() * ((wd * t).cos() + z * wn / wd * (wd * t).sin());
            assert!((yk - exact).abs() < 1e-9, "k {k}: {yk} vs {exact}");
        }
        let ramp = lsim(&g.times_s_power(-1), &[1.0; 500], dt).unwrap();
        let t = 499.0 * dt;
        let exact = t - 2.0 * z / wn
            + (-z * wn * t).exp() / wd
                * ((2.0 * z * z - 1.0) * (wd * t).sin()
                    + 2.0 * z * (1.0 - z * z).sqrt() * (wd * t).cos());
        assert!((ramp[499] - exact).abs() < 1e-9, "{} vs {exact}", ramp[499]);
    }
}
