//! Batch ellipse fitting (`fit_ellipses`): 100 noisy arcs of 90–160° (0.5 px noise, about one
//! point per pixel of arc length) in one call, against one `fit_ellipse` call per arc.

use std::hint::black_box;

use autoteach_detect::ellipse::{FitMethod, fit_ellipse, fit_ellipses};
use autoteach_geometry::conic::Ellipse;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector2;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

fn arcs() -> (Vec<Vector2<f64>>, Vec<usize>) {
    let mut rng = Pcg64::seed_from_u64(7);
    let noise = Normal::new(0.0, 0.5).expect("valid sigma");
    let mut points = Vec::new();
    let mut offsets = vec![0];
    for _ in 0..100 {
        let a = rng.random_range(150.0..350.0);
        let e = Ellipse::new(
            rng.random_range(300.0..900.0),
            rng.random_range(300.0..700.0),
            a,
            a * rng.random_range(0.2..1.0),
            rng.random_range(-3.0..3.0),
        )
        .expect("valid ellipse");
        let span = rng.random_range(90f64..160.0).to_radians();
        let t0 = rng.random_range(-3.1..3.1);
        let n = ((0.5 * (e.a + e.b) * span) as usize).max(20);
        points.extend((0..n).map(|i| {
            e.point_at(t0 + span * i as f64 / (n - 1) as f64)
                + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng))
        }));
        offsets.push(points.len());
    }
    (points, offsets)
}

fn bench(c: &mut Criterion) {
    let (points, offsets) = arcs();
    c.bench_function("fit_ellipses geometric 100 arcs", |b| {
        b.iter(|| fit_ellipses(black_box(&points), &offsets, FitMethod::Geometric))
    });
    c.bench_function("fit_ellipse geometric 100 arcs, one call each", |b| {
        b.iter(|| {
            offsets
                .windows(2)
                .map(|w| fit_ellipse(black_box(&points[w[0]..w[1]]), FitMethod::Geometric))
                .collect::<Vec<_>>()
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
