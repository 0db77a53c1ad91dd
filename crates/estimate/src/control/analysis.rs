//! Loop analysis of ch. 2.5 (000_3b1454b2b2194811.txt, Table 2.3 and constraints 1–2 of
//! eq. 2.19): classical gain and phase margins, crossover frequency, closed-loop bandwidth,
//! sensitivity peak and the damping of the closed-loop poles.
//!
//! The margins follow python-control's `stability_margins` (polynomial method) on purpose, so
//! the two agree to rounding: the phase crossovers are the real roots `ω ≥ 0` of
//! `Im(N(jω)·conj(D(jω)))` where `L(jω)` is real and ≤ 0, the gain crossovers the real roots
//! `ω > 0` of `|N(jω)|² − |D(jω)|²`; among several crossovers the reported gain margin is the
//! one closest to 0 dB and the reported phase margin the one smallest in magnitude.

use super::poly::{self, C64};
use super::tf::TransferFunction;

/// Stability margins of a loop transfer function `L` (python-control's `margin` values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// Gain margin as a factor (`∞` if the Nyquist curve never crosses the negative real axis).
    pub gain_margin: f64,
    /// Phase margin in degrees (`∞` if `|L|` never crosses 1).
    pub phase_margin_deg: f64,
    /// Phase-crossover frequency (rad/s) of the reported gain margin (NaN if none).
    pub w_phase_crossover: f64,
    /// Gain-crossover frequency (rad/s) of the reported phase margin (NaN if none).
    pub w_gain_crossover: f64,
}

impl Margins {
    /// Gain margin in dB.
    pub fn gain_margin_db(&self) -> f64 {
        20.0 * self.gain_margin.log10()
    }
}

/// The complex polynomial `p(jω)` as (real part, imaginary part) polynomials in `ω`.
fn poly_iw(p: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let d = p.len() - 1;
    let mut re = vec![0.0; p.len()];
    let mut im = vec![0.0; p.len()];
    for (k, &c) in p.iter().enumerate() {
        // j^(d-k)
        match (d - k) % 4 {
            0 => re[k] = c,
            1 => im[k] = c,
            2 => re[k] = -c,
            _ => im[k] = -c,
        }
    }
    (re, im)
}

/// `|p(jω)|²` as a real polynomial in `ω`.
fn poly_iw_sqr(p: &[f64]) -> Vec<f64> {
    let (re, im) = poly_iw(p);
    poly::add(&poly::mul(&re, &re), &poly::mul(&im, &im))
}

/// Real roots (imaginary part exactly zero after the companion eigen-solve, as `np.isreal`).
fn real_roots(p: &[f64]) -> Vec<f64> {
    let t = poly::trim(p);
    if t.len() <= 1 {
        return Vec::new();
    }
    poly::roots(&t)
        .into_iter()
        .filter(|r| r.im == 0.0)
        .map(|r| r.re)
        .collect()
}

/// Gain and phase margins of the loop transfer function `l` (python-control's
/// `margin(l)`, polynomial method for continuous time).
pub fn margins(l: &TransferFunction) -> Margins {
    let (nr, ni) = poly_iw(l.num());
    let (dr, di) = poly_iw(l.den());
    let test_w = poly::add(
        &poly::mul(&ni, &dr),
        &poly::scale(&poly::mul(&nr, &di), -1.0),
    );
    let mut w180: Vec<(f64, C64)> = real_roots(&test_w)
        .into_iter()
        .filter(|&w| w >= 0.0)
        .map(|w| (w, l.freq_resp(w)))
        .filter(|(_, r)| r.re.is_finite() && r.im.is_finite())
        .filter(|(_, r)| r.re < 0.0 || (r.re == 0.0 && r.im <= 0.0))
        .collect();
    w180.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mag1 = poly::add(
        &poly_iw_sqr(l.num()),
        &poly::scale(&poly_iw_sqr(l.den()), -1.0),
    );
    let mut wc: Vec<(f64, C64)> = real_roots(&mag1)
        .into_iter()
        .filter(|&w| w > 0.0)
        .map(|w| (w, l.freq_resp(w)))
        .collect();
    wc.sort_by(|a, b| a.0.total_cmp(&b.0));

    let gms: Vec<f64> = w180.iter().map(|(_, r)| 1.0 / r.norm()).collect();
    let (gain_margin, w_phase_crossover) = if gms.is_empty() || gms.iter().all(|g| g.is_infinite())
    {
        (f64::INFINITY, f64::NAN)
    } else {
        let mut best = 0;
        for (i, g) in gms.iter().enumerate() {
            if g.ln().abs() < gms[best].ln().abs() {
                best = i;
            }
        }
        (gms[best], w180[best].0)
    };
    let pms: Vec<f64> = wc
        .iter()
        .map(|(_, r)| r.arg().to_degrees().rem_euclid(360.0) - 180.0)
        .collect();
    let (phase_margin_deg, w_gain_crossover) = if pms.is_empty() {
        (f64::INFINITY, f64::NAN)
    } else {
        let mut best = 0;
        for (i, p) in pms.iter().enumerate() {
            if p.abs() < pms[best].abs() {
                best = i;
            }
        }
        (pms[best], wc[best].0)
    };
    Margins {
        gain_margin,
        phase_margin_deg,
        w_phase_crossover,
        w_gain_crossover,
    }
}

/// Every crossover of a loop frequency response `l(ω)` found on `grid` (increasing, rad/s) and
/// refined by bisection to rounding: the gain crossovers (`|L| = 1`) with their phase margins
/// (degrees, python-control's convention `arg L mod 360 − 180`) and the phase crossovers
/// (`Im L = 0`, `Re L < 0`) with their gain margins in dB. Evaluates the loop in factored form,
/// so it stays accurate for high-order loops where the polynomial method of [`margins`] loses
/// digits.
#[derive(Debug, Clone, Default)]
pub struct Crossovers {
    /// `(ω, phase margin in degrees)` at each gain crossover.
    pub gain: Vec<(f64, f64)>,
    /// `(ω, gain margin in dB)` at each phase crossover.
    pub phase: Vec<(f64, f64)>,
}

impl Crossovers {
    /// Python-control's selection: the phase margin smallest in magnitude and the gain margin
    /// closest to 0 dB.
    pub fn margins(&self) -> Margins {
        let pm = self
            .gain
            .iter()
            .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
        let gm = self
            .phase
            .iter()
            .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
        Margins {
            gain_margin: gm.map_or(f64::INFINITY, |g| 10f64.powf(g.1 / 20.0)),
            phase_margin_deg: pm.map_or(f64::INFINITY, |p| p.1),
            w_phase_crossover: gm.map_or(f64::NAN, |g| g.0),
            w_gain_crossover: pm.map_or(f64::NAN, |p| p.0),
        }
    }

    /// Worst margins over all crossovers: `(min |GM| in dB, min PM in degrees)` (∞ if none).
    pub fn worst(&self) -> (f64, f64) {
        (
            self.phase
                .iter()
                .map(|g| g.1.abs())
                .fold(f64::INFINITY, f64::min),
            self.gain.iter().map(|p| p.1).fold(f64::INFINITY, f64::min),
        )
    }
}

fn bisect(f: &dyn Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let fa = f(a);
    for _ in 0..80 {
        let m = (a * b).sqrt();
        if m <= a || m >= b {
            break;
        }
        if (f(m) < 0.0) == (fa < 0.0) {
            a = m
        } else {
            b = m
        }
    }
    (a * b).sqrt()
}

/// Crossovers of the loop `l(ω)` on `grid`, see [`Crossovers`].
pub fn crossovers(l: &dyn Fn(f64) -> C64, grid: &[f64]) -> Crossovers {
    let vals: Vec<C64> = grid.iter().map(|&w| l(w)).collect();
    let mut out = Crossovers::default();
    let mag = |w: f64| l(w).norm().ln();
    let imag = |w: f64| l(w).im;
    for k in 1..grid.len() {
        let (a, b) = (vals[k - 1], vals[k]);
        if (a.norm().ln() < 0.0) != (b.norm().ln() < 0.0) {
            let w = bisect(&mag, grid[k - 1], grid[k]);
            let r = l(w);
            out.gain
                .push((w, r.arg().to_degrees().rem_euclid(360.0) - 180.0));
        }
        if (a.im < 0.0) != (b.im < 0.0) && (a.re < 0.0 || b.re < 0.0) {
            let w = bisect(&imag, grid[k - 1], grid[k]);
            let r = l(w);
            if r.re < 0.0 {
                out.phase.push((w, -20.0 * r.norm().log10()));
            }
        }
    }
    out
}

/// Damping of the closed-loop poles, split at `max_freq` (rad/s): `(min ζ over poles with
/// |p| ≤ max_freq, min ζ over all poles)`. Constraint 2 of ch. 2.5 applies to the first
/// (poles far above the loop's bandwidth sit on the plant's own lightly damped modes, which
/// no controller moves; MATLAB's `TuningGoal.Poles` has the same `MaxFrequency` cut-off); the
/// second must stay positive (stability).
pub fn closed_loop_damping_split(l: &TransferFunction, max_freq: f64) -> (f64, f64) {
    let mut low = f64::INFINITY;
    let mut all = f64::INFINITY;
    for p in l.closed_loop_poles() {
        let z = if p.norm() == 0.0 {
            0.0
        } else {
            -p.re / p.norm()
        };
        all = all.min(z);
        if p.norm() <= max_freq {
            low = low.min(z);
        }
    }
    (low, all)
}

/// Smallest damping ratio `ζ = −Re p / |p|` of the closed-loop poles of the unity feedback
/// loop around `l` (a pole at the origin counts as ζ = 0; an unstable pole gives ζ < 0).
pub fn closed_loop_damping(l: &TransferFunction) -> f64 {
    l.closed_loop_poles()
        .iter()
        .map(|p| {
            if p.norm() == 0.0 {
                0.0
            } else {
                -p.re / p.norm()
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// A log-spaced frequency grid covering the poles and zeros of `g` with two decades each side.
pub fn default_grid(g: &TransferFunction, points: usize) -> Vec<f64> {
    let feats: Vec<f64> = g
        .poles()
        .into_iter()
        .chain(g.zeros())
        .map(|p| p.norm())
        .filter(|&m| m > 0.0 && m.is_finite())
        .collect();
    let lo = feats.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = feats.iter().cloned().fold(0.0, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > 0.0 {
        (lo, hi)
    } else {
        (1.0, 1.0)
    };
    let a = lo.log10().floor() - 2.0;
    let b = hi.log10().ceil() + 2.0;
    (0..points)
        .map(|i| 10f64.powf(a + (b - a) * i as f64 / (points - 1) as f64))
        .collect()
}

/// First frequency (rad/s) at which `|g(jω)|` drops `db_drop` dB (negative) below its DC gain,
/// as python-control's `bandwidth`: NaN for an infinite DC gain, ∞ if it never drops. The
/// crossing is bracketed on a dense grid and solved by bisection to rounding.
pub fn bandwidth(g: &TransferFunction, db_drop: f64) -> f64 {
    let dc = g.dc_gain();
    if !dc.is_finite() {
        return f64::NAN;
    }
    let level = dc.abs() * 10f64.powf(db_drop / 20.0);
    let grid = default_grid(g, 4000);
    let f = |w: f64| g.freq_resp(w).norm() - level;
    let Some(i) = grid.iter().position(|&w| f(w) < 0.0) else {
        return f64::INFINITY;
    };
    if i == 0 {
        return grid[0];
    }
    let (mut a, mut b) = (grid[i - 1], grid[i]);
    for _ in 0..200 {
        let m = 0.5 * (a + b);
        if m <= a || m >= b {
            break;
        }
        if f(m) < 0.0 { b = m } else { a = m }
    }
    0.5 * (a + b)
}

/// Peak `max_ω |S(jω)|` of the sensitivity `S = 1/(1+L)` and its frequency, found exactly at
/// the real roots of `d|S|²/dω` (and the limits ω → 0, ∞).
pub fn sensitivity_peak(l: &TransferFunction) -> (f64, f64) {
    let d = l.den();
    let n = poly::add(l.den(), l.num());
    let p = poly_iw_sqr(d);
    let q = poly_iw_sqr(&n);
    // d/dω (p/q) = (p' q − p q') / q²
    let test = poly::add(
        &poly::mul(&poly::deriv(&p), &q),
        &poly::scale(&poly::mul(&p, &poly::deriv(&q)), -1.0),
    );
    let s = |w: f64| (poly::eval_real(&p, w) / poly::eval_real(&q, w)).sqrt();
    let mut best = (s(0.0), 0.0);
    if !best.0.is_finite() {
        best = (0.0, 0.0);
    }
    for w in real_roots(&test).into_iter().filter(|&w| w > 0.0) {
        let v = s(w);
        if v.is_finite() && v > best.0 {
            best = (v, w);
        }
    }
    // ω → ∞
    let inf = l.freq_resp(1e12);
    let v_inf = 1.0 / (C64::new(1.0, 0.0) + inf).norm();
    if v_inf > best.0 {
        best = (v_inf, f64::INFINITY);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn margins_of_a_loop_whose_companion_matrix_stalled_nalgebra() {
        // First random pair of tests/test_control.py: `margins` never returned while the
        // companion eigen-solve ran nalgebra's uncapped QR iteration. Expected values are
        // python-control 0.10.2's `margin` on the same loop.
        let plant = TransferFunction::new(
            &[128.8826523056646, 1640.9180759233398],
            &[
                1.0,
                39.097958419776546,
                222.2188188331554,
                16.88743988861308,
                33.33837919628236,
            ],
        )
        .unwrap();
        let pi =
            TransferFunction::new(&[0.10126911166161184, 2.3747716075346754], &[1.0, 0.0]).unwrap();
        let m = margins(&plant.series(&pi));
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
        assert!(close(m.gain_margin, 0.0004258709541424586), "{m:?}");
        assert!(close(m.phase_margin_deg, -96.42048603213671), "{m:?}");
        assert!(close(m.w_phase_crossover, 0.38862923270316896), "{m:?}");
        assert!(close(m.w_gain_crossover, 2.587842166844239), "{m:?}");
    }

    #[test]
    fn margins_of_integrator_with_lag_match_closed_form() {
        // L = k / (s (s+1)^2): phase crossover at ω = 1 where |L| = k/2, so GM = 2/k.
        let k = 0.5;
        let l = TransferFunction::new(&[k], &[1.0, 2.0, 1.0, 0.0]).unwrap();
        let m = margins(&l);
        assert!((m.gain_margin - 2.0 / k).abs() < 1e-10);
        assert!((m.w_phase_crossover - 1.0).abs() < 1e-10);
        // Gain crossover: k = ω (1 + ω²).
        let wc = m.w_gain_crossover;
        assert!((wc * (1.0 + wc * wc) - k).abs() < 1e-10);
        let pm = 180.0 - 90.0 - 2.0 * wc.atan().to_degrees();
        assert!((m.phase_margin_deg - pm).abs() < 1e-9);
    }

    #[test]
    fn bandwidth_of_first_order_lag_is_its_pole() {
        let g = TransferFunction::new(&[3.0], &[1.0, 3.0]).unwrap();
        let bw = bandwidth(&g, -20.0 * 2f64.sqrt().log10());
        assert!((bw - 3.0).abs() < 1e-9, "{bw}");
    }

    #[test]
    fn damping_and_peak_of_a_second_order_loop() {
        // L = wn² / (s (s + 2 ζ wn)) closes to the standard second-order system.
        let (z, wn) = (0.3, 5.0);
        let l = TransferFunction::new(&[wn * wn], &[1.0, 2.0 * z * wn, 0.0]).unwrap();
        assert!((closed_loop_damping(&l) - z).abs() < 1e-12);
        let (peak, w) = sensitivity_peak(&l);
        let grid_peak = (1..200000)
            .map(|i| i as f64 * 1e-3)
            .map(|w| 1.0 / (C64::new(1.0, 0.0) + l.freq_resp(w)).norm())
            .fold(0.0, f64::max);
        assert!((peak - grid_peak).abs() < 1e-6 && w > 0.0);
    }
}
