//! Radio signal-strength prediction timings (seed 004_815695db12a6b16c.txt ch. 3) on a
//! simulated 240 s mission of three robots in the campus environment (14 400 links): the
//! log fit, the MRGP fit on 6 000 links (sparse Cholesky), the MRT solve on a 1 m grid
//! (160 × 100 = 16 000 unknowns) and the MATTE solve on a 2 m grid (3 × 80 × 50 = 12 000
//! unknowns); the solves with the symbolic analysis of the previous solve reused (as in an
//! incremental update whose links couple no new cells) and cold (`_cold`).

use autoteach_estimate::radio::kernel::{KernelParams, LinkKernel};
use autoteach_estimate::radio::logfit::LogFit;
use autoteach_estimate::radio::matte::{Matte, MatteOptions};
use autoteach_estimate::radio::mrgp::Mrgp;
use autoteach_estimate::radio::mrt::{Mrt, MrtOptions};
use autoteach_estimate::radio::sim::{self, Environment, EnvironmentKind, RadioParams};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let env = Environment::new(EnvironmentKind::Campus, 0);
    let traj = sim::explore(&env, 3, 240.0, 1.0, 20.0, 1).expect("trajectories");
    let m = sim::measure(&env, &traj, &RadioParams::default(), 2);
    let map = sim::observe(&env, &traj, 20.0).map_at(240.0);
    let (links, rss) = (&m.links, &m.rss);
    c.bench_function("radio_logfit_14400", |b| {
        b.iter(|| LogFit::fit(black_box(links), rss).expect("fit"))
    });
    let step = links.len() / 6000;
    let sub: Vec<_> = links.iter().step_by(step).take(6000).copied().collect();
    let sub_rss: Vec<f64> = rss.iter().step_by(step).take(6000).copied().collect();
    let mut g = c.benchmark_group("radio_slow");
    g.sample_size(10);
    g.bench_function("radio_mrgp_fit_6000", |b| {
        b.iter(|| {
            Mrgp::fit(
                black_box(&sub),
                &sub_rss,
                LinkKernel::SwapAverage,
                KernelParams::default(),
                false,
            )
            .expect("fit")
        })
    });
    let mut mrt = Mrt::new(
        [0.0, 0.0, 160.0, 100.0],
        MrtOptions {
            cell: 1.0,
            ..MrtOptions::default()
        },
    )
    .expect("mrt");
    mrt.add(links, rss).expect("add");
    g.bench_function("radio_mrt_solve_16000_unknowns", |b| {
        b.iter(|| mrt.solve().expect("solve").l0)
    });
    g.bench_function("radio_mrt_solve_16000_unknowns_cold", |b| {
        b.iter(|| {
            mrt.clear_factor_cache();
            mrt.solve().expect("solve").l0
        })
    });
    let mut matte = Matte::new(
        map,
        MatteOptions {
            cell: 2.0,
            ..MatteOptions::default()
        },
    )
    .expect("matte");
    matte.add(links, rss).expect("add");
    g.bench_function("radio_matte_solve_12000_unknowns", |b| {
        b.iter(|| matte.solve().expect("solve").l0)
    });
    g.bench_function("radio_matte_solve_12000_unknowns_cold", |b| {
        b.iter(|| {
            matte.clear_factor_cache();
            matte.solve().expect("solve").l0
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
