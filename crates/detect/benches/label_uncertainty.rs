//! Label uncertainty by variational Bayes (000_3b1454b2b2194811.txt eq. 8.10–8.12) on simulated
//! car scans.
//!
//! Run: `RAYON_NUM_THREADS=1 cargo bench -p autoteach-detect --bench label_uncertainty -- --warm-up-time 1 --measurement-time 3`.
#![allow(missing_docs)]

use autoteach_detect::uncertainty::Prior;
use autoteach_detect::uncertainty::label::{LabelOptions, label_uncertainty};
use autoteach_detect::uncertainty::noise::{NoiseOptions, estimate_noise};
use autoteach_geometry::boxes::Box2;
use autoteach_geometry::boxes::scan::{ScanOptions, simulate_cars};
use criterion::{Criterion, criterion_group, criterion_main};

fn label(c: &mut Criterion) {
    let cars = simulate_cars(100, &ScanOptions::default(), 10, 1).expect("cars");
    let opts = LabelOptions {
        sigma: 0.2,
        prior: Prior::seed(1.0).expect("prior"),
        ..Default::default()
    };
    c.bench_function("label_uncertainty_100_cars", |b| {
        b.iter(|| {
            cars.iter()
                .map(|(bx, p)| label_uncertainty(bx, p, &opts).expect("vb").cov[0][0])
                .sum::<f64>()
        })
    });
    let objs: Vec<(Box2, &[[f64; 2]])> = cars.iter().map(|(b, p)| (*b, p.as_slice())).collect();
    c.bench_function("estimate_noise_100_cars", |b| {
        b.iter(|| {
            estimate_noise(
                &objs,
                &NoiseOptions {
                    tolerance: 1e-6,
                    ..Default::default()
                },
            )
            .expect("em")
            .sigma
        })
    });
}

criterion_group!(benches, label);
criterion_main!(benches);
