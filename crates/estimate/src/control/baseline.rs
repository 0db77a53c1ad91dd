//! The hand-tuned baseline of Table 2.3 (000_3b1454b2b2194811.txt ch. 2.5, "the controller
//! used in the factory which is tuned by the engineer"): a second-order low-pass filter plus
//! PID, placed by a classical rigid-body rule and then detuned as an engineer would:
//!
//! 1. the crossover starts at `ω_c = ω_r / 3`, a third of the lowest resonance `ω_r` of the
//!    plant set (local maximum of `|P(jω)| ω²`);
//! 2. PID `K (s + ω_c/3)(s + ω_c/10) / s` with a derivative pole at `10 ω_c` (zeros a third and
//!    a tenth of the crossover, the textbook lead/lag placement for a double integrator), and
//!    `K` set so that `|L(jω_c)| = 1` on the plant of largest gain at `ω_c`;
//! 3. low-pass `ω_f² / (s² + 1.4 ω_f s + ω_f²)` at `ω_f = 5 ω_c`;
//! 4. while any plant misses a margin, damping or frequency-bound constraint of the spec, lower
//!    `ω_c` by 10 % (at most 60 times).

use super::structure::{ControllerStructure, Section};
use super::tf::TransferFunction;
use super::tune::{TuneReport, TuneSpec, evaluate, resonances};
use crate::Result;

/// Parameters of the rule at crossover `wc`.
fn rule(st: &ControllerStructure, plants: &[TransferFunction], wc: f64) -> Vec<f64> {
    let wd = 10.0 * wc;
    let wf = 5.0 * wc;
    // K (s + a)(s + b)/s = K s + K (a + b) + K a b / s: Kd = K, Kp = K (a + b), Ki = K a b (the
    // derivative pole ω_d = 10 ω_c filters the D term).
    let (a, b) = (wc / 3.0, wc / 10.0);
    let unit = [
        (a + b).ln(),
        (a * b).ln(),
        0.0,
        wd.ln(),
        wf.ln(),
        0.7f64.ln(),
    ];
    let c1 = st.resp(&unit, wc).norm();
    let gain = plants
        .iter()
        .map(|p| p.freq_resp(wc).norm())
        .fold(0.0, f64::max);
    let lk = -(gain * c1).ln();
    vec![unit[0] + lk, unit[1] + lk, lk, unit[3], unit[4], unit[5]]
}

/// The baseline controller and its report on `plants` against `spec`.
pub fn classical_design(
    plants: &[TransferFunction],
    spec: &TuneSpec,
) -> Result<(ControllerStructure, TuneReport)> {
    let st = ControllerStructure::new(vec![Section::LowPass]);
    let wr = resonances(plants, &spec.grid, 1)
        .first()
        .copied()
        .unwrap_or(spec.target.0 * 3.0);
    let mut wc = wr / 3.0;
    let mut report = evaluate(plants, &st, &rule(&st, plants, wc), spec)?;
    for _ in 0..60 {
        if report.success {
            break;
        }
        wc *= 0.9;
        report = evaluate(plants, &st, &rule(&st, plants, wc), spec)?;
    }
    Ok((st, report))
}
