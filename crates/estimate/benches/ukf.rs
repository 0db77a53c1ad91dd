//! UKF step and batch timings on the 9-state model of `benchmarks/ukf_vs_filterpy.py`
//! (3-D constant acceleration, positions measured).

use autoteach_estimate::ukf::{
    BatchInputs, LinearModel, MerweScaledSigmaPoints, SigmaPointFilter, SquareRootUkf,
    UnscentedKalmanFilter,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, DVector};
use std::hint::black_box;

fn model(dt: f64) -> LinearModel {
    let mut f = DMatrix::identity(9, 9);
    for i in 0..3 {
        f[(i, 3 + i)] = dt;
        f[(i, 6 + i)] = 0.5 * dt * dt;
        f[(3 + i, 6 + i)] = dt;
    }
    let mut h = DMatrix::zeros(3, 9);
    for i in 0..3 {
        h[(i, i)] = 1.0;
    }
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

fn bench(c: &mut Criterion) {
    let zs = measurements(2000);
    let pts = MerweScaledSigmaPoints::new(9, 0.1, 2.0, -6.0).expect("points");
    c.bench_function("ukf_batch_9state_2000", |b| {
        b.iter(|| {
            let mut f = UnscentedKalmanFilter::new(model(0.01), pts.clone()).expect("filter");
            setup(&mut f);
            black_box(f.batch(&BatchInputs::new(0.01, &zs)).expect("batch"))
        })
    });
    let pts_sr = MerweScaledSigmaPoints::new(9, 1.0, 2.0, 0.0).expect("points");
    c.bench_function("srukf_batch_9state_2000", |b| {
        b.iter(|| {
            let mut f = SquareRootUkf::new(model(0.01), pts_sr.clone()).expect("filter");
            setup(&mut f);
            black_box(f.batch(&BatchInputs::new(0.01, &zs)).expect("batch"))
        })
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
