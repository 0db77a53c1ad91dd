//! Benchmarks of motion planning (issue 30): collision checks, A*, RRT*, B-spline sampling and
//! inverse dynamics on the default scene.

use std::hint::black_box;

use autoteach_geometry::plan::astar::{AStarConfig, astar};
use autoteach_geometry::plan::bspline::{BSplineTrajectory, fit_path};
use autoteach_geometry::plan::dynamics::{Dynamics, DynamicsParams};
use autoteach_geometry::plan::rrt_star::{RrtStarConfig, rrt_star};
use autoteach_geometry::plan::workspace::default_scene;
use autoteach_geometry::robot::Joints;
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let (ws, poses) = default_scene().expect("default scene");
    let (lo, hi) = (ws.lower, ws.upper);
    let qs: Vec<Joints> = (0..1024)
        .map(|k| {
            Joints::from_fn(|i, _| {
                lo[i] + (hi[i] - lo[i]) * (((k * 7919 + i * 104729) % 1000) as f64 / 1000.0)
            })
        })
        .collect();
    let mut k = 0;
    c.bench_function("plan/is_free", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            black_box(ws.is_free(&qs[k], 0.01))
        })
    });
    c.bench_function("plan/signed_distance", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            black_box(ws.signed_distance(&qs[k]).ok())
        })
    });
    let mut g = c.benchmark_group("plan_search");
    g.sample_size(10);
    g.bench_function("rrt_star_carrier_a_to_b_1500", |b| {
        let cfg = RrtStarConfig {
            max_iterations: 1500,
            ..RrtStarConfig::default()
        };
        b.iter(|| black_box(rrt_star(&ws, &poses[1].q, &poses[2].q, &cfg).ok()))
    });
    g.bench_function("astar_5joint_5deg_home_to_carrier_a", |b| {
        b.iter(|| black_box(astar(&ws, &poses[0].q, &poses[1].q, &AStarConfig::default()).ok()))
    });
    g.finish();
    let path = vec![poses[0].q, poses[1].q, poses[2].q];
    let ctrl = fit_path(&path, 20, &Joints::repeat(1.0)).expect("fit");
    let tr = BSplineTrajectory::from_spans(ctrl, &[0.1; 17]).expect("trajectory");
    let dy = Dynamics::new(
        &ws.robot.params,
        &DynamicsParams::default(),
        ws.wafer.as_ref(),
    );
    c.bench_function("plan/bspline_sample", |b| {
        b.iter(|| black_box(tr.sample(black_box(0.77))))
    });
    c.bench_function("plan/inverse_dynamics", |b| {
        let s = tr.sample(0.77);
        b.iter(|| black_box(dy.torques(&s.q, &s.dq, &s.ddq)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
