//! Lie-group benches (000_3b1454b2b2194811.txt eq. (2.1)-(2.3), (5.11)): the SE(3) exponential
//! and logarithm and the ⊕ Jacobians a least-squares solver evaluates per residual.
//!
//! Run: `cargo bench -p autoteach-geometry --bench lie -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use autoteach_geometry::lie::{se3_exp, se3_log, se3_plus_jacobians};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector6;

fn lie(c: &mut Criterion) {
    // A generic tangent (1.0 rad, well outside the small-angle series) and a small one.
    let xi = Vector6::new(0.4, -0.7, 0.5, 1.0, -2.0, 0.3);
    let small = Vector6::new(1e-3, -2e-3, 5e-4, 1.0, -2.0, 0.3);
    let x = se3_exp(&xi);

    c.bench_function("se3_exp", |b| b.iter(|| se3_exp(black_box(&xi))));
    c.bench_function("se3_exp_small_angle", |b| {
        b.iter(|| se3_exp(black_box(&small)))
    });
    c.bench_function("se3_log", |b| b.iter(|| se3_log(black_box(&x))));
    c.bench_function("se3_plus_jacobians", |b| {
        b.iter(|| se3_plus_jacobians(black_box(&x), black_box(&xi)))
    });
}

criterion_group!(benches, lie);
criterion_main!(benches);
