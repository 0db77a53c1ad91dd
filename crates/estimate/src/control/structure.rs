//! The fixed-structure joint controller of 000_3b1454b2b2194811.txt ch. 2.5 ("a linear filter
//! whose order is not restricted followed by a PID position controller", Fig. 2.14) and its
//! initial design by loop shaping toward eq. 2.18,
//! `G₀(s) = ω_c / (s (s/ω₁ + 1)(s/ω₂ + 1)²)`.
//!
//! Parameters are logarithms of positive physical quantities, so every parameter vector is a
//! valid controller: PID `K_p + K_i/s + K_d ω_d s/(s + ω_d)` → `[ln K_p, ln K_i, ln K_d, ln ω_d]`;
//! each filter section adds a notch `(s² + 2ζ_z ω s + ω²)/(s² + 2ζ_p ω s + ω²)` →
//! `[ln ω, ln ζ_z, ln ζ_p]` or a second-order low-pass `ω²/(s² + 2ζ ω s + ω²)` → `[ln ω, ln ζ]`.

use super::poly::{self, C64};
use super::tf::TransferFunction;
use crate::{EstimateError, Result};

/// A second-order filter section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Section {
    /// Notch (or, with ζ_z > ζ_p, a peaking section).
    Notch,
    /// Second-order low-pass.
    LowPass,
}

impl Section {
    fn n_params(self) -> usize {
        match self {
            Section::Notch => 3,
            Section::LowPass => 2,
        }
    }
}

/// Filter sections followed by a PID.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ControllerStructure {
    /// The filter sections (filter order = 2 × their number).
    pub sections: Vec<Section>,
}

/// Number of PID parameters.
pub const PID_PARAMS: usize = 4;

impl ControllerStructure {
    /// Filter of the given sections.
    pub fn new(sections: Vec<Section>) -> Self {
        Self { sections }
    }

    /// Filter order.
    pub fn filter_order(&self) -> usize {
        2 * self.sections.len()
    }

    /// Length of the parameter vector.
    pub fn n_params(&self) -> usize {
        PID_PARAMS + self.sections.iter().map(|s| s.n_params()).sum::<usize>()
    }

    fn check(&self, theta: &[f64]) -> Result<()> {
        if theta.len() != self.n_params() {
            return Err(EstimateError::DimensionMismatch {
                what: "controller parameters".into(),
                expected: vec![self.n_params()],
                got: vec![theta.len()],
            });
        }
        if let Some((i, &v)) = theta.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: "controller parameters".into(),
                index: i,
                value: v,
            });
        }
        Ok(())
    }

    /// The controller as a transfer function.
    pub fn tf(&self, theta: &[f64]) -> Result<TransferFunction> {
        self.check(theta)?;
        let (kp, ki, kd, wd) = (
            theta[0].exp(),
            theta[1].exp(),
            theta[2].exp(),
            theta[3].exp(),
        );
        let mut num = vec![kp + kd * wd, kp * wd + ki, ki * wd];
        let mut den = vec![1.0, wd, 0.0];
        let mut i = PID_PARAMS;
        for s in &self.sections {
            match s {
                Section::Notch => {
                    let (w, zz, zp) = (theta[i].exp(), theta[i + 1].exp(), theta[i + 2].exp());
                    num = poly::mul(&num, &[1.0, 2.0 * zz * w, w * w]);
                    den = poly::mul(&den, &[1.0, 2.0 * zp * w, w * w]);
                }
                Section::LowPass => {
                    let (w, z) = (theta[i].exp(), theta[i + 1].exp());
                    num = poly::scale(&num, w * w);
                    den = poly::mul(&den, &[1.0, 2.0 * z * w, w * w]);
                }
            }
            i += s.n_params();
        }
        TransferFunction::new(&num, &den)
    }

    /// `C(jω)` and `∂ ln C(jω) / ∂θ` (analytic), with `theta` already checked.
    pub fn resp_and_dlog(&self, theta: &[f64], w: f64) -> (C64, Vec<C64>) {
        let s = C64::new(0.0, w);
        let (kp, ki, kd, wd) = (
            theta[0].exp(),
            theta[1].exp(),
            theta[2].exp(),
            theta[3].exp(),
        );
        let deriv = kd * wd * s / (s + wd);
        let pid = kp + ki / s + deriv;
        let mut c = pid;
        let mut g = vec![C64::new(0.0, 0.0); self.n_params()];
        g[0] = C64::new(kp, 0.0) / pid;
        g[1] = ki / s / pid;
        g[2] = deriv / pid;
        g[3] = kd * wd * s * s / ((s + wd) * (s + wd)) / pid;
        let mut i = PID_PARAMS;
        for sec in &self.sections {
            match sec {
                Section::Notch => {
                    let (wn, zz, zp) = (theta[i].exp(), theta[i + 1].exp(), theta[i + 2].exp());
                    let n = s * s + 2.0 * zz * wn * s + wn * wn;
                    let d = s * s + 2.0 * zp * wn * s + wn * wn;
                    c *= n / d;
                    g[i] = wn * (2.0 * zz * s + 2.0 * wn) / n - wn * (2.0 * zp * s + 2.0 * wn) / d;
                    g[i + 1] = 2.0 * zz * wn * s / n;
                    g[i + 2] = -2.0 * zp * wn * s / d;
                }
                Section::LowPass => {
                    let (wn, z) = (theta[i].exp(), theta[i + 1].exp());
                    let d = s * s + 2.0 * z * wn * s + wn * wn;
                    c *= wn * wn / d;
                    g[i] = C64::new(2.0, 0.0) - wn * (2.0 * z * s + 2.0 * wn) / d;
                    g[i + 1] = -2.0 * z * wn * s / d;
                }
            }
            i += sec.n_params();
        }
        (c, g)
    }

    /// `C(jω)`.
    pub fn resp(&self, theta: &[f64], w: f64) -> C64 {
        self.resp_and_dlog(theta, w).0
    }

    /// Box bounds `[lo, hi]` on each (log) parameter, from the frequency band `[w_lo, w_hi]` of
    /// the design: filter frequencies inside the band, damping ratios in `[0.02, 2]`
    /// (notch zeros from 0.005), the derivative pole in `[w_lo, 10 w_hi]`, gains free.
    pub fn bounds(&self, w_lo: f64, w_hi: f64) -> (Vec<f64>, Vec<f64>) {
        let mut lo = vec![-60.0, -60.0, -60.0, w_lo.ln()];
        let mut hi = vec![60.0, 60.0, 60.0, (10.0 * w_hi).ln()];
        for s in &self.sections {
            match s {
                Section::Notch => {
                    lo.extend([w_lo.ln(), 0.005f64.ln(), 0.02f64.ln()]);
                    hi.extend([w_hi.ln(), 2f64.ln(), 2f64.ln()]);
                }
                Section::LowPass => {
                    lo.extend([w_lo.ln(), 0.1f64.ln()]);
                    hi.extend([(3.0 * w_hi).ln(), 2f64.ln()]);
                }
            }
        }
        (lo, hi)
    }
}

/// The loop-shaping target of eq. 2.18 at `jω`.
pub fn target_loop(wc: f64, w1: f64, w2: f64, w: f64) -> C64 {
    let s = C64::new(0.0, w);
    let a = s / w1 + 1.0;
    let b = s / w2 + 1.0;
    wc / (s * a * b * b)
}

/// Initial design (eq. 2.18): the parameters minimising
/// `Σ_i Σ_k |ln L_i(jω_k) − ln G₀(jω_k)|²` (log-magnitude and phase of every plant's loop
/// against the target) by Levenberg–Marquardt from `theta0`, with `plants[i][k] = P_i(jω_k)`.
/// The phase difference is wrapped to `(−π, π]`.
pub fn loop_shape(
    structure: &ControllerStructure,
    theta0: &[f64],
    w: &[f64],
    plants: &[Vec<C64>],
    target: &[C64],
    bounds: &(Vec<f64>, Vec<f64>),
    iterations: usize,
) -> Result<Vec<f64>> {
    structure.check(theta0)?;
    let np = structure.n_params();
    let residuals = |theta: &[f64]| -> (Vec<f64>, Vec<Vec<f64>>) {
        let mut r = Vec::new();
        let mut jac = Vec::new();
        for p in plants {
            for (k, &wk) in w.iter().enumerate() {
                let (c, g) = structure.resp_and_dlog(theta, wk);
                let e = (p[k] * c / target[k]).ln();
                let im = (e.im + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                    - std::f64::consts::PI;
                r.push(e.re);
                r.push(im);
                jac.push(g.iter().map(|z| z.re).collect());
                jac.push(g.iter().map(|z| z.im).collect());
            }
        }
        (r, jac)
    };
    let clamp = |t: &mut Vec<f64>| {
        for (j, v) in t.iter_mut().enumerate() {
            *v = v.clamp(bounds.0[j], bounds.1[j]);
        }
    };
    let mut theta = theta0.to_vec();
    clamp(&mut theta);
    let cost = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
    let (mut r, mut jac) = residuals(&theta);
    let mut c = cost(&r);
    let mut lambda = 1e-2;
    for _ in 0..iterations {
        let mut jtj = nalgebra::DMatrix::<f64>::zeros(np, np);
        let mut jtr = nalgebra::DVector::<f64>::zeros(np);
        for (row, &ri) in jac.iter().zip(&r) {
            for a in 0..np {
                jtr[a] += row[a] * ri;
                for b in 0..np {
                    jtj[(a, b)] += row[a] * row[b];
                }
            }
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut aug = jtj.clone();
            for a in 0..np {
                aug[(a, a)] += lambda * (1.0 + jtj[(a, a)]);
            }
            let Some(step) = aug.lu().solve(&(-&jtr)) else {
                break;
            };
            let mut cand: Vec<f64> = theta.iter().zip(step.iter()).map(|(t, d)| t + d).collect();
            clamp(&mut cand);
            let (r2, j2) = residuals(&cand);
            let c2 = cost(&r2);
            if c2.is_finite() && c2 < c {
                improved = (c - c2) > 1e-10 * c;
                theta = cand;
                r = r2;
                jac = j2;
                c = c2;
                lambda = (lambda * 0.3).max(1e-9);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Ok(theta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_log_derivative_matches_finite_differences() {
        let st = ControllerStructure::new(vec![Section::Notch, Section::LowPass]);
        let theta = [2.0, 3.0, -1.0, 6.0, 5.0, -3.0, -1.0, 6.5, -0.5];
        let w = 120.0;
        let (c, g) = st.resp_and_dlog(&theta, w);
        let tf = st.tf(&theta).unwrap();
        assert!((tf.freq_resp(w) - c).norm() < 1e-9 * c.norm());
        for j in 0..theta.len() {
            let mut tp = theta;
            let mut tm = theta;
            tp[j] += 1e-6;
            tm[j] -= 1e-6;
            let fd = (st.resp(&tp, w).ln() - st.resp(&tm, w).ln()) / 2e-6;
            assert!((fd - g[j]).norm() < 1e-6, "param {j}: {fd} vs {}", g[j]);
        }
    }
}
