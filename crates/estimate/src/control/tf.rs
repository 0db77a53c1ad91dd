//! Continuous-time SISO transfer functions `G(s) = num(s) / den(s)`, the linear models of the
//! joint dynamics in 000_3b1454b2b2194811.txt ch. 2.5 ("multi-modal linear transfer
//! functions", Fig. 2.13) and of the controllers tuned for them (Fig. 2.14).

use super::poly::{self, C64};
use crate::{EstimateError, Result};

/// A continuous-time SISO transfer function in numerator/denominator form, coefficients in
/// descending powers of `s`. The denominator is stored monic.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    num: Vec<f64>,
    den: Vec<f64>,
}

fn check_finite(what: &str, c: &[f64]) -> Result<()> {
    if let Some((i, &v)) = c.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(EstimateError::NonFiniteInput {
            what: what.to_string(),
            index: i,
            value: v,
        });
    }
    Ok(())
}

fn invalid(what: &str, reason: String) -> EstimateError {
    EstimateError::InvalidModel {
        what: what.to_string(),
        reason,
    }
}

impl TransferFunction {
    /// `num(s)/den(s)`; leading zeros are trimmed and the denominator made monic.
    ///
    /// Errors: empty or non-finite coefficients, a zero denominator.
    pub fn new(num: &[f64], den: &[f64]) -> Result<Self> {
        if num.is_empty() || den.is_empty() {
            return Err(invalid(
                "transfer function",
                "empty numerator or denominator".into(),
            ));
        }
        check_finite("numerator", num)?;
        check_finite("denominator", den)?;
        let den = poly::trim(den);
        if den[0] == 0.0 {
            return Err(invalid(
                "transfer function",
                "the denominator is the zero polynomial".into(),
            ));
        }
        let lead = den[0];
        Ok(Self {
            num: poly::scale(&poly::trim(num), 1.0 / lead),
            den: poly::scale(&den, 1.0 / lead),
        })
    }

    /// `k · Π(s − zᵢ) / Π(s − pⱼ)`; complex zeros and poles must come in conjugate pairs.
    pub fn from_zpk(zeros: &[C64], poles: &[C64], gain: f64) -> Result<Self> {
        for (what, set) in [("zeros", zeros), ("poles", poles)] {
            for (i, z) in set.iter().enumerate() {
                if !z.re.is_finite() || !z.im.is_finite() {
                    return Err(EstimateError::NonFiniteInput {
                        what: what.into(),
                        index: i,
                        value: z.re + z.im,
                    });
                }
                if z.im != 0.0
                    && !set
                        .iter()
                        .any(|w| (w.conj() - z).norm() <= 1e-9 * (1.0 + z.norm()))
                {
                    return Err(invalid(
                        what,
                        format!("{z} has no complex-conjugate partner"),
                    ));
                }
            }
        }
        Self::new(
            &poly::scale(&poly::from_roots(zeros), gain),
            &poly::from_roots(poles),
        )
    }

    /// A static gain `k`.
    pub fn gain(k: f64) -> Result<Self> {
        Self::new(&[k], &[1.0])
    }

    /// Numerator coefficients (descending powers).
    pub fn num(&self) -> &[f64] {
        &self.num
    }

    /// Monic denominator coefficients (descending powers).
    pub fn den(&self) -> &[f64] {
        &self.den
    }

    /// Poles (roots of the denominator).
    pub fn poles(&self) -> Vec<C64> {
        poly::roots(&self.den)
    }

    /// Zeros (roots of the numerator; none for a zero numerator).
    pub fn zeros(&self) -> Vec<C64> {
        if self.num.iter().all(|&c| c == 0.0) {
            Vec::new()
        } else {
            poly::roots(&self.num)
        }
    }

    /// High-frequency gain factor: `num[0]` over the monic denominator (the `k` of zpk form).
    pub fn zpk_gain(&self) -> f64 {
        self.num[0]
    }

    /// `deg num ≤ deg den`.
    pub fn is_proper(&self) -> bool {
        poly::degree(&self.num) <= poly::degree(&self.den)
    }

    /// Every pole has a negative real part.
    pub fn is_stable(&self) -> bool {
        self.poles().iter().all(|p| p.re < 0.0)
    }

    /// Errors unless proper.
    pub fn require_proper(&self, what: &str) -> Result<()> {
        if self.is_proper() {
            Ok(())
        } else {
            Err(invalid(
                what,
                format!(
                    "improper: numerator degree {} > denominator degree {}",
                    poly::degree(&self.num),
                    poly::degree(&self.den)
                ),
            ))
        }
    }

    /// Errors unless every pole has a negative real part (names the worst pole).
    pub fn require_stable(&self, what: &str) -> Result<()> {
        let worst = self
            .poles()
            .into_iter()
            .max_by(|a, b| a.re.total_cmp(&b.re));
        match worst {
            Some(p) if p.re >= 0.0 => Err(invalid(
                what,
                format!("unstable: pole {p} has real part ≥ 0"),
            )),
            _ => Ok(()),
        }
    }

    /// `G(s)` at a complex point.
    pub fn eval(&self, s: C64) -> C64 {
        poly::eval(&self.num, s) / poly::eval(&self.den, s)
    }

    /// Frequency response `G(jω)` at angular frequency `ω` (rad/s).
    pub fn freq_resp(&self, w: f64) -> C64 {
        self.eval(C64::new(0.0, w))
    }

    /// Frequency responses at many angular frequencies.
    pub fn freq_resp_many(&self, w: &[f64]) -> Vec<C64> {
        w.iter().map(|&w| self.freq_resp(w)).collect()
    }

    /// `G(0)` (infinite for a pole at the origin).
    pub fn dc_gain(&self) -> f64 {
        let d = *self.den.last().unwrap_or(&1.0);
        let n = *self.num.last().unwrap_or(&0.0);
        if d == 0.0 {
            if n == 0.0 {
                f64::NAN
            } else {
                f64::INFINITY * n.signum()
            }
        } else {
            n / d
        }
    }

    /// Series connection `self · other`.
    pub fn series(&self, other: &Self) -> Self {
        Self {
            num: poly::mul(&self.num, &other.num),
            den: poly::mul(&self.den, &other.den),
        }
    }

    /// Parallel connection `self + other`.
    pub fn parallel(&self, other: &Self) -> Self {
        let num = poly::add(
            &poly::mul(&self.num, &other.den),
            &poly::mul(&other.num, &self.den),
        );
        Self {
            num: poly::trim(&num),
            den: poly::mul(&self.den, &other.den),
        }
    }

    /// Negative feedback `self / (1 + self · other)` (`other` in the feedback path).
    pub fn feedback(&self, other: &Self) -> Result<Self> {
        let num = poly::mul(&self.num, &other.den);
        let den = poly::add(
            &poly::mul(&self.den, &other.den),
            &poly::mul(&self.num, &other.num),
        );
        Self::new(&num, &den)
    }

    /// Sensitivity `1 / (1 + self)` of the loop transfer function `self`.
    pub fn sensitivity(&self) -> Result<Self> {
        Self::new(&self.den, &poly::add(&self.den, &self.num))
    }

    /// Complementary sensitivity `self / (1 + self)`.
    pub fn complementary(&self) -> Result<Self> {
        Self::new(&self.num, &poly::add(&self.den, &self.num))
    }

    /// Closed-loop poles of the unity negative-feedback loop around `self` (as the loop
    /// transfer function): roots of `den + num`.
    pub fn closed_loop_poles(&self) -> Vec<C64> {
        poly::roots(&poly::add(&self.den, &self.num))
    }

    /// Multiplies by `sᵏ` (k > 0) or divides by `s⁻ᵏ` (k < 0).
    pub fn times_s_power(&self, k: i32) -> Self {
        let mut num = self.num.clone();
        let mut den = self.den.clone();
        for _ in 0..k.unsigned_abs() {
            if k > 0 { num.push(0.0) } else { den.push(0.0) }
        }
        Self { num, den }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feedback_of_integrator_is_first_order_lag() {
        let g = TransferFunction::new(&[2.0], &[1.0, 0.0]).unwrap();
        let t = g.feedback(&TransferFunction::gain(1.0).unwrap()).unwrap();
        assert_eq!(t.num(), &[2.0]);
        assert_eq!(t.den(), &[1.0, 2.0]);
        let w = 3.0;
        let closed = C64::new(2.0, 0.0) / C64::new(2.0, w);
        assert!((t.freq_resp(w) - closed).norm() < 1e-15);
        assert!(t.is_stable() && !g.is_stable());
    }

    #[test]
    fn zpk_round_trip_and_bad_input() {
        let z = [C64::new(-1.0, 0.0)];
        let p = [C64::new(-2.0, 3.0), C64::new(-2.0, -3.0)];
        let g = TransferFunction::from_zpk(&z, &p, 4.0).unwrap();
        assert_eq!(g.num(), &[4.0, 4.0]);
        assert_eq!(g.den(), &[1.0, 4.0, 13.0]);
        assert!(TransferFunction::from_zpk(&[], &[C64::new(-1.0, 1.0)], 1.0).is_err());
        assert!(TransferFunction::new(&[1.0], &[0.0, 0.0]).is_err());
        assert!(TransferFunction::new(&[f64::NAN], &[1.0]).is_err());
        let improper = TransferFunction::new(&[1.0, 0.0, 0.0], &[1.0, 1.0]).unwrap();
        assert!(improper.require_proper("g").is_err());
    }
}
