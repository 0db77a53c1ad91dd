//! Coherent point drift: rigid, affine and non-rigid (full and low-rank) on 2-D point sets of
//! N = M = 2000 (a noisy, rotated copy of a random cloud; full-rank non-rigid also on the peer
//! benchmark's sine-deformed 10 × 10 scene), and low-rank non-rigid at 20 000 (first 20
//! iterations).

use std::hint::black_box;

use autoteach_detect::cpd::{
    AffineOptions, CpdOptions, NonrigidOptions, RigidOptions, affine, nonrigid, rigid,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Y uniform in the unit square; X = R(0.3)·Y + t + small noise, same size.
fn pair(n: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let y = DMatrix::from_fn(n, 2, |_, _| rng.random::<f64>());
    let (s, c) = 0.3f64.sin_cos();
    let x = DMatrix::from_fn(n, 2, |i, d| {
        let (a, b) = (y[(i, 0)], y[(i, 1)]);
        let v = if d == 0 {
            c * a - s * b + 0.1
        } else {
            s * a + c * b - 0.05
        };
        v + 0.002 * (rng.random::<f64>() - 0.5)
    });
    (x, y)
}

/// Y uniform in a 10 × 10 square; X = Y + 0.4·(sin(0.5 y₂), cos(0.4 y₁)) + small noise.
fn sine_pair(n: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let y = DMatrix::from_fn(n, 2, |_, _| 10.0 * rng.random::<f64>());
    let x = DMatrix::from_fn(n, 2, |i, d| {
        let shift = if d == 0 {
            (0.5 * y[(i, 1)]).sin()
        } else {
            (0.4 * y[(i, 0)]).cos()
        };
        y[(i, d)] + 0.4 * shift + 0.02 * (rng.random::<f64>() - 0.5)
    });
    (x, y)
}

fn bench(c: &mut Criterion) {
    let (x, y) = pair(2000, 1);
    let mut g = c.benchmark_group("cpd 2000");
    g.sample_size(10);
    g.bench_function("rigid", |b| {
        b.iter(|| rigid(black_box(&x), &y, &RigidOptions::default()))
    });
    g.bench_function("affine", |b| {
        b.iter(|| affine(black_box(&x), &y, &AffineOptions::default()))
    });
    let nr = NonrigidOptions {
        beta: 0.3,
        lambda: 2.0,
        ..Default::default()
    };
    g.bench_function("nonrigid full", |b| {
        b.iter(|| nonrigid(black_box(&x), &y, &nr))
    });
    let lr = NonrigidOptions {
        low_rank: Some(100),
        ..nr.clone()
    };
    g.bench_function("nonrigid low-rank 100", |b| {
        b.iter(|| nonrigid(black_box(&x), &y, &lr))
    });
    // The peer benchmark's scene (benchmarks/cpd_vs_peers.py): β = λ = 2 over a 10 × 10 square,
    // where the full-rank kernel is applied by the fast Gauss transform.
    let (x, y) = sine_pair(2000, 3);
    g.bench_function("nonrigid full, 10 x 10 sine scene", |b| {
        b.iter(|| nonrigid(black_box(&x), &y, &NonrigidOptions::default()))
    });
    g.finish();
    let (x, y) = pair(20_000, 2);
    let mut g = c.benchmark_group("cpd 20000");
    g.sample_size(10);
    // The first 20 iterations (large σ: the fast Gauss transform E-step) keep the run short.
    let lr = NonrigidOptions {
        beta: 0.3,
        low_rank: Some(100),
        cpd: CpdOptions {
            max_iterations: 20,
            ..Default::default()
        },
        ..Default::default()
    };
    g.bench_function("nonrigid low-rank 100, 20 iterations", |b| {
        b.iter(|| nonrigid(black_box(&x), &y, &lr))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
