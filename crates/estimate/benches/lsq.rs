//! Criterion benches of the sparse least-squares solver: the bundle-adjustment problem of the
//! peer comparison (50 poses, 500 points, 10 000 observations, 1 px noise) with each linear
//! solver, a chain-like pose graph, and the marginal covariance of one block.
//!
//! `cargo bench -p autoteach-estimate --bench lsq -- --warm-up-time 1 --measurement-time 3`

use autoteach_estimate::lsq::synthetic::{bundle_scene, pose_graph};
use autoteach_estimate::lsq::{LinearSolver, Loss, SolverOptions};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let scene = bundle_scene(50, 500, 20, 1.0, 1);
    for (name, solver) in [
        ("schur", LinearSolver::SparseSchur),
        ("sparse", LinearSolver::SparseCholesky),
    ] {
        let opts = SolverOptions {
            linear_solver: solver,
            ..Default::default()
        };
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
