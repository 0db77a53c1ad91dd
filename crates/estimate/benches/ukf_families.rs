//! Sigma-point families (Merwe, Julier, simplex) and the unscented RTS smoother, on the
//! 9-state model of `benchmarks/ukf_vs_filterpy.py` (3-D constant acceleration).

use autoteach_estimate::ukf::{
    BatchInputs, JulierSigmaPoints, LinearModel, MerweScaledSigmaPoints, SigmaPointFilter,
    SigmaPoints, SimplexSigmaPoints, UnscentedKalmanFilter, rts_smoother,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, DVector};
use std::hint::black_box;

#[path = "../src/ukf/fixtures.rs"]
mod fixtures;

fn model() -> LinearModel {
    let (f, h, _) = fixtures::constant_acceleration(0.01);
    LinearModel::new(f, h, None).expect("valid model")
}

fn families() -> Vec<(&'static str, SigmaPoints)> {
    vec![
        (
            "merwe",
            MerweScaledSigmaPoints::new(9, 0.1, 2.0, -6.0)
                .expect("points")
                .into(),
        ),
        (
            "julier",
            JulierSigmaPoints::new(9, 0.0).expect("points").into(),
        ),
        (
            "simplex",
            SimplexSigmaPoints::new(9).expect("points").into(),
        ),
    ]
}

fn bench(c: &mut Criterion) {
    let x = DVector::from_fn(9, |i, _| i as f64 * 0.1);
    let a = DMatrix::from_fn(9, 9, |i, j| ((i * 3 + j) % 5) as f64 * 0.1);
    let p = &a * a.transpose() + DMatrix::identity(9, 9);
    let zs: Vec<_> = (0..2000)
        .map(|k| {
            let t = k as f64 * 0.01;
            Some(DVector::from_vec(vec![t.sin(), t.cos(), 0.1 * t]))
        })
        .collect();
    for (name, pts) in families() {
        c.bench_function(&format!("sigma_points_{name}_9"), |b| {
            b.iter(|| {
                black_box(
                    pts.sigma_points(black_box(&x), black_box(&p))
                        .expect("points"),
                )
            })
        });
        // Filter once, then time the smoother over the 2000 epochs.
        let mut f = UnscentedKalmanFilter::new(model(), pts.clone()).expect("filter");
        f.set_q(DMatrix::identity(9, 9) * 1e-4).expect("Q");
        f.set_r(DMatrix::identity(3, 3) * 1e-2).expect("R");
        let run = f.batch(&BatchInputs::new(0.01, &zs)).expect("batch");
        let xs: Vec<_> = (0..zs.len())
            .map(|k| run.x(k).expect("x").into_owned())
            .collect();
        let ps: Vec<_> = (0..zs.len())
            .map(|k| run.p(k).expect("P").into_owned())
            .collect();
        let q = [DMatrix::identity(9, 9) * 1e-4];
        let dts = vec![0.01; zs.len()];
        let m = model();
        c.bench_function(&format!("rts_smoother_{name}_9state_2000"), |b| {
            b.iter(|| {
                black_box(rts_smoother(&m, &pts, &xs, &ps, &q, &dts, None).expect("smoother"))
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
