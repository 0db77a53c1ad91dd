//! UKF step and batch timings on the 9-state model of `benchmarks/ukf_vs_filterpy.py`
//! (3-D constant acceleration, positions measured).

use autoteach_estimate::ukf::{
    BatchInputs, LinearModel, MerweScaledSigmaPoints, SigmaPointFilter, SquareRootUkf,
    UnscentedKalmanFilter,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, DVector};
use std::hint::black_box;

#[path = "../src/ukf/fixtures.rs"]
mod fixtures;

fn model(dt: f64) -> LinearModel {
    let (f, h, _) = fixtures::constant_acceleration(dt);
    LinearModel::new(f, h, None).expect("valid model")
}

fn measurements(n: usize) -> Vec<Option<DVector<f64>>> {
    (0..n)
        .map(|k| {
            let t = k as f64 * 0.01;
            Some(DVector::from_vec(vec![t.sin(), t.cos(), 0.1 * t]))
        })
        .collect()
}

fn setup<F: SigmaPointFilter>(f: &mut F) {
    f.set_p(DMatrix::identity(9, 9)).expect("P");
    f.set_q(DMatrix::identity(9, 9) * 1e-4).expect("Q");
    f.set_r(DMatrix::identity(3, 3) * 1e-2).expect("R");
}

/// Times building a filter with `make`, setting it up and running it over `zs`.
fn batch<F: SigmaPointFilter>(
    c: &mut Criterion,
    name: &str,
    zs: &[Option<DVector<f64>>],
    make: impl Fn() -> F,
) {
    c.bench_function(name, |b| {
        b.iter(|| {
            let mut f = make();
            setup(&mut f);
            black_box(f.batch(&BatchInputs::new(0.01, zs)).expect("batch"))
        })
    });
}

fn bench(c: &mut Criterion) {
    let zs = measurements(2000);
    let pts = MerweScaledSigmaPoints::new(9, 0.1, 2.0, -6.0).expect("points");
    batch(c, "ukf_batch_9state_2000", &zs, || {
        UnscentedKalmanFilter::new(model(0.01), pts.clone()).expect("filter")
    });
    let pts_sr = MerweScaledSigmaPoints::new(9, 1.0, 2.0, 0.0).expect("points");
    batch(c, "srukf_batch_9state_2000", &zs, || {
        SquareRootUkf::new(model(0.01), pts_sr.clone()).expect("filter")
    });
    c.bench_function("ukf_step_9state", |b| {
        let mut f = UnscentedKalmanFilter::new(model(0.01), pts.clone()).expect("filter");
        setup(&mut f);
        let z = DVector::from_vec(vec![0.1, 0.2, 0.3]);
        b.iter(|| {
            f.predict(0.01, None).expect("predict");
            f.update(black_box(&z), None).expect("update");
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
