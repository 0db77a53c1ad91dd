//! Criterion benches of joint controller tuning (issue 31): margins, fitting, tuning.
#![allow(missing_docs)]

use autoteach_estimate::control::analysis::margins;
use autoteach_estimate::control::fit::{FitOptions, fit_frequency_response};
use autoteach_estimate::control::plant::{
    ArmMasses, Drive, Joint, demo_poses, joint_plant, log_grid_hz, sine_sweep,
};
use autoteach_estimate::control::structure::{ControllerStructure, Section};
use autoteach_estimate::control::tf::TransferFunction;
use autoteach_estimate::control::tune::{TuneSpec, tune};
use autoteach_geometry::robot::RobotParams;
use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::hint::black_box;

fn plants() -> Vec<TransferFunction> {
    let p = RobotParams::default();
    let m = ArmMasses::default();
    let d = Drive::default_for(Joint::Jt2);
    demo_poses(Joint::Jt2)
        .iter()
        .map(|q| joint_plant(&p, &m, &d, q, Joint::Jt2).expect("plant").motor)
        .collect()
}

fn bench(c: &mut Criterion) {
    let ps = plants();
    let l =
        ps[0].series(&TransferFunction::new(&[1.0, 10.0, 20.0], &[1.0, 100.0, 0.0]).expect("c"));
    c.bench_function("control/margins_order10", |b| {
        b.iter(|| margins(black_box(&l)))
    });
    let w = log_grid_hz(1.0, 500.0, 300);
    let mut rng = Pcg64::seed_from_u64(1);
    let h = sine_sweep(&ps[0], &w, 0.01, &mut rng).expect("sweep");
    let opts = FitOptions {
        num_order: 4,
        den_order: 7,
        integrators: 1,
        ..Default::default()
    };
    c.bench_function("control/fit_300pts_order8", |b| {
        b.iter(|| fit_frequency_response(black_box(&w), &h, &opts))
    });
    let wr = 2.0 * std::f64::consts::PI * 25.0;
    let spec = TuneSpec {
        grid: log_grid_hz(0.5, 500.0, 400),
        sd_bandwidth: 30.0,
        sd_peak: 2.0,
        sd_low: 1e-3,
        min_gain_margin_db: 12.0,
        min_phase_margin_deg: 50.0,
        min_damping: 0.1,
        damping_max_freq: 2.0 * wr,
        max_loop_gain: 0.5,
        gain_band: (1.2 * wr, 3.0 * wr),
        rolloff_freq: 3.0 * wr,
        target: (50.0, 150.0, 300.0),
        max_iterations: 30,
    };
    let st = ControllerStructure::new(vec![Section::Notch, Section::LowPass]);
    let mut g = c.benchmark_group("control/tune");
    g.sample_size(10);
    g.bench_function("6_plants_4th_order_400_grid", |b| {
        b.iter(|| tune(black_box(&ps), &st, &spec, None))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
