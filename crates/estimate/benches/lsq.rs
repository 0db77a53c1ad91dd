//! Criterion benches of the sparse least-squares solver: the bundle-adjustment problem of the
//! peer comparison (50 poses, 500 points, 10 000 observations, 1 px noise) with each linear
//! solver, a chain-like pose graph, and the marginal covariance of one block.
//!
//! `cargo bench -p autoteach-estimate --bench lsq -- --warm-up-time 1 --measurement-time 3`

use autoteach_estimate::lsq::synthetic::{BundleScene, bundle_scene, pose_graph};
use autoteach_estimate::lsq::{LinearSolver, Loss, SolverOptions};
use criterion::{Criterion, criterion_group, criterion_main};

/// Median stage timings (ms) of `n` solves: `[total, setup, evaluate, assemble, linear,
/// Schur reduce, Schur factor]`.
fn stages(scene: &BundleScene, opts: &SolverOptions, n: usize) -> [f64; 7] {
    let mut stages: Vec<[f64; 7]> = (0..n)
        .map(|_| {
            let (mut p, _, _) = scene.problem(Loss::Trivial, true).expect("scene");
            let s = p.solve(opts).expect("solve");
            [
                s.time_s,
                s.time_setup_s,
                s.time_evaluate_s,
                s.time_assemble_s,
                s.time_linear_s,
                s.time_schur_reduce_s,
                s.time_schur_factor_s,
            ]
            .map(|t| t * 1e3)
        })
        .collect();
    stages.sort_by(|a, b| a[0].total_cmp(&b[0]));
    stages[n / 2]
}

fn bench(c: &mut Criterion) {
    let scene = bundle_scene(50, 500, 20, 1.0, 1);
    // `LSQ_PROFILE_SOLVES=n`: only n Schur solves of the bundle problem and their median stage
    // timings (for profilers: `perf record`, `perf stat`), no criterion run.
    if let Some(n) = std::env::var("LSQ_PROFILE_SOLVES")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        let opts = SolverOptions {
            linear_solver: LinearSolver::SparseSchur,
            ..Default::default()
        };
        let m = stages(&scene, &opts, n.max(1));
        eprintln!(
            "lsq_bundle_50x500_schur, median of {n}: solve {:.2} ms = setup {:.2} + evaluate {:.2} + assemble {:.2} + linear {:.2} ms (Schur: reduce {:.2}, factor {:.2})",
            m[0], m[1], m[2], m[3], m[4], m[5], m[6]
        );
        std::process::exit(0);
    }
    for (name, solver) in [
        ("schur", LinearSolver::SparseSchur),
        ("sparse", LinearSolver::SparseCholesky),
    ] {
        let opts = SolverOptions {
            linear_solver: solver,
            ..Default::default()
        };
        // Where the time goes (median of 5 stage timings, printed once).
        let m = stages(&scene, &opts, 5);
        eprintln!(
            "lsq_bundle_50x500_{name}: solve {:.2} ms = setup {:.2} + evaluate {:.2} + assemble {:.2} + linear {:.2} ms (Schur: reduce {:.2}, factor {:.2})",
            m[0], m[1], m[2], m[3], m[4], m[5], m[6]
        );
        c.bench_function(&format!("lsq_bundle_50x500_{name}"), |b| {
            b.iter_batched(
                || scene.problem(Loss::Trivial, true).expect("scene"),
                |(mut p, _, _)| p.solve(&opts).expect("solve"),
                criterion::BatchSize::LargeInput,
            )
        });
    }
    // The dense fallback on a small problem (10 poses, 100 points: 288 unknowns).
    let small = bundle_scene(10, 100, 5, 1.0, 2);
    for (name, solver) in [
        ("dense", LinearSolver::DenseCholesky),
        ("schur", LinearSolver::SparseSchur),
    ] {
        let opts = SolverOptions {
            linear_solver: solver,
            ..Default::default()
        };
        c.bench_function(&format!("lsq_bundle_10x100_{name}"), |b| {
            b.iter_batched(
                || small.problem(Loss::Trivial, true).expect("scene"),
                |(mut p, _, _)| p.solve(&opts).expect("solve"),
                criterion::BatchSize::LargeInput,
            )
        });
    }
    let ids = pose_graph(1000, 1).expect("graph").1;
    c.bench_function("lsq_pose_graph_1000", |b| {
        b.iter_batched(
            || pose_graph(1000, 1).expect("graph").0,
            |mut p| p.solve(&SolverOptions::default()).expect("solve"),
            criterion::BatchSize::LargeInput,
        )
    });
    let (mut solved, _) = pose_graph(1000, 1).expect("graph");
    solved.solve(&SolverOptions::default()).expect("solve");
    c.bench_function("lsq_pose_graph_1000_covariance_one_block", |b| {
        b.iter(|| solved.marginal_covariance(&[ids[500]]).expect("cov"))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
