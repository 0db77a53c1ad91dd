//! Ellipse fits on a noisy 120° arc of 250 points (a wafer rim seen obliquely).

use std::hint::black_box;

use autoteach_detect::ellipse::{FitMethod, fit_ellipse};
use autoteach_geometry::conic::Ellipse;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

fn bench(c: &mut Criterion) {
    let truth = Ellipse {
        cx: 500.0,
        cy: 400.0,
        a: 300.0,
        b: 120.0,
        theta: 0.3,
    };
    let mut rng = Pcg64::seed_from_u64(1);
    let noise = Normal::new(0.0, 0.5).expect("valid sigma");
    let points: Vec<Vector2<f64>> = (0..250)
        .map(|i| {
            let t = 0.4 + f64::to_radians(120.0) * i as f64 / 249.0;
            truth.point_at(t) + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng))
        })
        .collect();
    c.bench_function("fit_ellipse direct 250 pts", |b| {
        b.iter(|| fit_ellipse(black_box(&points), FitMethod::Direct))
    });
    c.bench_function("fit_ellipse geometric 250 pts", |b| {
        b.iter(|| fit_ellipse(black_box(&points), FitMethod::Geometric))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
