//! Global voting (Algorithm 3) time against point-set size, 2-D and 3-D.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use autoteach_detect::voting::{VotingOptions, global_voting};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, Rotation2, Rotation3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::hint::black_box;

/// A 2-D curve model of `n` points and a rotated, moved copy with `n / 2` outliers.
fn sets2(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = Pcg64::seed_from_u64(n as u64);
    let y: Vec<Vector2<f64>> = (0..n)
        .map(|k| {
            let s = k as f64 / n as f64 * 4.0;
            Vector2::new(s, (1.7 * s).sin())
        })
        .collect();
    let r = Rotation2::new(2.0);
    let mut x: Vec<Vector2<f64>> = y.iter().map(|p| r * p + Vector2::new(3.0, 1.0)).collect();
    x.extend(
        (0..n / 2).map(|_| Vector2::new(rng.random_range(-2.0..8.0), rng.random_range(-4.0..6.0))),
    );
    (
        DMatrix::from_fn(x.len(), 2, |i, c| x[i][c]),
        DMatrix::from_fn(n, 2, |i, c| y[i][c]),
    )
}

fn sets3(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let y: Vec<Vector3<f64>> = (0..n)
        .map(|k| {
            let s = k as f64 / n as f64 * 6.0;
            Vector3::new(s.cos(), s.sin(), 0.2 * s + 0.1 * (3.0 * s).sin())
        })
        .collect();
    let r = Rotation3::from_euler_angles(0.3, -0.5, 2.0);
    let x: Vec<Vector3<f64>> = y
        .iter()
        .map(|p| r * p + Vector3::new(0.5, 1.0, -1.0))
        .collect();
    (
        DMatrix::from_fn(n, 3, |i, c| x[i][c]),
        DMatrix::from_fn(n, 3, |i, c| y[i][c]),
    )
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("global_voting");
    g.sample_size(10);
    let o = VotingOptions::default();
    for n in [100usize, 200, 400, 800] {
        let (x, y) = sets2(n);
        g.bench_with_input(BenchmarkId::new("2d", n), &n, |b, _| {
            b.iter(|| global_voting(black_box(&x), &y, &o).unwrap())
        });
    }
    for n in [100usize, 200, 400] {
        let (x, y) = sets3(n);
        g.bench_with_input(BenchmarkId::new("3d", n), &n, |b, _| {
            b.iter(|| global_voting(black_box(&x), &y, &o).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
