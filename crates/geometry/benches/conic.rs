//! Ellipse distances and circle projection (000_3b1454b2b2194811.txt eq. 3.3, 5.13).
//!
//! Run: `cargo bench -p autoteach-geometry --bench conic -- --warm-up-time 1 --measurement-time 3`.
#![allow(missing_docs)]

use std::hint::black_box;

use autoteach_geometry::conic::{Ellipse, project_circle_jacobian};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Matrix3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn conic(c: &mut Criterion) {
    let e = Ellipse::new(640.0, 360.0, 300.0, 120.0, 0.4).expect("valid ellipse");
    let mut rng = Pcg64::seed_from_u64(7);
    // Edge-like points: mostly within a few pixels of the curve, some anywhere.
    let pts: Vec<Vector2<f64>> = (0..100_000)
        .map(|i| {
            if i % 10 == 0 {
                Vector2::new(rng.random_range(0.0..1280.0), rng.random_range(0.0..720.0))
            } else {
                let p = e.point_at(rng.random_range(-3.2..3.2));
                p + Vector2::new(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0))
            }
        })
        .collect();

    let mut g = c.benchmark_group("ellipse_100k_points");
    g.throughput(Throughput::Elements(pts.len() as u64));
    g.bench_function("orthogonal_distance_loop", |b| {
        b.iter(|| {
            black_box(&pts)
                .iter()
                .map(|p| e.orthogonal_distance(p))
                .sum::<f64>()
        })
    });
    g.bench_function("orthogonal_distances_batched", |b| {
        b.iter(|| e.orthogonal_distances(black_box(&pts)))
    });
    g.bench_function("sampson_distances", |b| {
        b.iter(|| e.sampson_distances(black_box(&pts)))
    });
    g.finish();

    let k = Matrix3::new(900.0, 0.0, 640.0, 0.0, 900.0, 360.0, 0.0, 0.0, 1.0);
    let t_co = Isometry3::new(Vector3::new(0.02, -0.03, 0.6), Vector3::new(0.5, 0.2, 0.1));
    c.bench_function("project_circle_jacobian", |b| {
        b.iter(|| project_circle_jacobian(black_box(&k), black_box(&t_co), 0.15))
    });
}

criterion_group!(benches, conic);
criterion_main!(benches);
