//! The simulated experiment of 000_3b1454b2b2194811.txt ch. 2.5 end to end (Fig. 2.14,
//! Tables 2.3–2.4): plants of JT2 and JT4 at six poses, noisy sine sweeps, fitted models, the
//! classical baseline, the tuned controller, and the hand vibration of both on an S-curve.

use autoteach_geometry::robot::RobotParams;
use rand::SeedableRng;
use rand_pcg::Pcg64;

use super::baseline::classical_design;
use super::fit::{FitOptions, FitResult, fit_frequency_response};
use super::hand::{hand_acceleration, link_response, rms, s_curve};
use super::plant::{
    ArmMasses, Drive, Joint, JointPlant, demo_poses, joint_plant, log_grid_hz, sine_sweep,
};
use super::poly::C64;
use super::structure::{ControllerStructure, Section};
use super::tf::TransferFunction;
use super::tune::{TuneReport, TuneSpec, evaluate, resonances, tune};
use crate::Result;

/// Everything about one joint.
#[derive(Debug, Clone)]
pub struct JointDemo {
    /// The joint.
    pub joint: Joint,
    /// True plants, one per pose.
    pub plants: Vec<JointPlant>,
    /// Sweep frequencies (rad/s).
    pub sweep_w: Vec<f64>,
    /// Noisy sweeps, one per pose.
    pub sweeps: Vec<Vec<C64>>,
    /// Fitted models, one per pose.
    pub fits: Vec<FitResult>,
    /// The spec the tuning used.
    pub spec: TuneSpec,
    /// Baseline structure and its report on the true plants.
    pub baseline: (ControllerStructure, TuneReport),
    /// Tuned structure and its report on the true plants.
    pub tuned: (ControllerStructure, TuneReport),
    /// The tuning's own report (on the fitted models).
    pub tuned_on_fits: TuneReport,
}

/// Numerator/denominator orders of the plant fit (without the integrator).
pub const FIT_ORDERS: (usize, usize) = (4, 7);

/// The tuning spec for a plant set whose lowest resonance is `wr` and whose baseline crossover
/// is `wc0` (rad/s), on `grid`.
pub fn demo_spec(grid: Vec<f64>, wr: f64, wc0: f64) -> TuneSpec {
    let wc = 3.0 * wc0;
    TuneSpec {
        grid,
        sd_bandwidth: 0.6 * wc,
        sd_peak: 2.0,
        sd_low: 1e-3,
        min_gain_margin_db: 12.0,
        min_phase_margin_deg: 50.0,
        min_damping: 0.1,
        damping_max_freq: 2.0 * wr,
        max_loop_gain: 0.5,
        gain_band: (1.2 * wr.max(wc), 3.0 * wr),
        rolloff_freq: 3.0 * wr,
        target: (wc, 3.0 * wc, 6.0 * wc),
        max_iterations: 60,
    }
}

/// Runs the experiment for one joint: sweeps with relative `noise`, fits, baseline, tuning with
/// `sections` (the seed's proposed controller has a 4th-order filter).
pub fn run_joint(joint: Joint, noise: f64, seed: u64, sections: Vec<Section>) -> Result<JointDemo> {
    let params = RobotParams::default();
    let masses = ArmMasses::default();
    let drive = Drive::default_for(joint);
    let plants: Vec<JointPlant> = demo_poses(joint)
        .iter()
        .map(|q| joint_plant(&params, &masses, &drive, q, joint))
        .collect::<Result<_>>()?;
    let sweep_w = log_grid_hz(1.0, 500.0, 300);
    let mut rng = Pcg64::seed_from_u64(seed);
    let sweeps: Vec<Vec<C64>> = plants
        .iter()
        .map(|p| sine_sweep(&p.motor, &sweep_w, noise, &mut rng))
        .collect::<Result<_>>()?;
    let opts = FitOptions {
        num_order: FIT_ORDERS.0,
        den_order: FIT_ORDERS.1,
        integrators: 1,
        ..Default::default()
    };
    let fits: Vec<FitResult> = sweeps
        .iter()
        .map(|h| fit_frequency_response(&sweep_w, h, &opts))
        .collect::<Result<_>>()?;
    let fitted: Vec<TransferFunction> = fits.iter().map(|f| f.model.clone()).collect();
    let truth: Vec<TransferFunction> = plants.iter().map(|p| p.motor.clone()).collect();
    let grid = log_grid_hz(0.5, 500.0, 400);
    let wr = resonances(&fitted, &grid, 1)
        .first()
        .copied()
        .unwrap_or(grid[grid.len() / 2]);
    // The baseline's rule does not depend on the spec's objective; its constraints are the same.
    let pre = demo_spec(grid.clone(), wr, wr / 6.0);
    let (bst, b_fit) = classical_design(&fitted, &pre)?;
    let wc0 = b_fit
        .plants
        .iter()
        .map(|r| r.crossover)
        .fold(f64::INFINITY, f64::min);
    let spec = demo_spec(grid, wr, wc0);
    let baseline_report = evaluate(&truth, &bst, &b_fit.theta, &spec)?;
    let st = ControllerStructure::new(sections);
    let tuned_on_fits = tune(&fitted, &st, &spec, None)?;
    let tuned_report = evaluate(&truth, &st, &tuned_on_fits.theta, &spec)?;
    Ok(JointDemo {
        joint,
        plants,
        sweep_w,
        sweeps,
        fits,
        spec,
        baseline: (bst, baseline_report),
        tuned: (st, tuned_report),
        tuned_on_fits,
    })
}

/// RMS hand accelerations (m/s²) of one controller pair: `[forward, lateral]` total, and the
/// same for the vibration (total minus the acceleration of perfect tracking).
#[derive(Debug, Clone, Copy)]
pub struct Vibration {
    /// RMS total acceleration `[forward, lateral]`.
    pub total: [f64; 2],
    /// RMS of the deviation from the ideal (rigid, perfectly tracked) acceleration.
    pub vibration: [f64; 2],
}

/// Table 2.4 on simulation: JT2 moves by `d2` and JT4 by `d4` (rad) together on a cycloidal
/// S-curve of `duration` s, then holds for `settle` s; each joint's plant is its middle pose's.
pub fn hand_vibration(
    jt2: &JointDemo,
    jt4: &JointDemo,
    which: usize,
    d2: f64,
    d4: f64,
    duration: f64,
    settle: f64,
) -> Result<Vibration> {
    let params = RobotParams::default();
    let dt = 2e-4;
    let k2 = jt2.plants.len() / 2;
    let k4 = jt4.plants.len() / 2;
    let c2 = if which == 0 {
        &jt2.baseline
    } else {
        &jt2.tuned
    };
    let c4 = if which == 0 {
        &jt4.baseline
    } else {
        &jt4.tuned
    };
    let (r2, v2, a2) = s_curve(d2, duration, settle, dt)?;
    let (r4, v4, a4) = s_curve(d4, duration, settle, dt)?;
    let y2 = link_response(
        &jt2.plants[k2].motor,
        &jt2.plants[k2].link,
        &c2.1.controller,
        &r2,
        dt,
    )?;
    let y4 = link_response(
        &jt4.plants[k4].motor,
        &jt4.plants[k4].link,
        &c4.1.controller,
        &r4,
        dt,
    )?;
    let q0 = jt2.plants[k2].pose;
    let q0 = autoteach_geometry::robot::Joints::new(
        q0[0],
        jt4.plants[k4].pose[1],
        jt4.plants[k4].pose[2],
        q0[3],
        0.0,
    );
    let acc = hand_acceleration(&params, &q0, &y2, &y4)?;
    let ideal = hand_acceleration(&params, &q0, &[r2, v2, a2], &[r4, v4, a4])?;
    let f: Vec<f64> = acc.iter().map(|a| a.0).collect();
    let l: Vec<f64> = acc.iter().map(|a| a.1).collect();
    let fv: Vec<f64> = acc.iter().zip(&ideal).map(|(a, b)| a.0 - b.0).collect();
    let lv: Vec<f64> = acc.iter().zip(&ideal).map(|(a, b)| a.1 - b.1).collect();
    Ok(Vibration {
        total: [rms(&f), rms(&l)],
        vibration: [rms(&fv), rms(&lv)],
    })
}
