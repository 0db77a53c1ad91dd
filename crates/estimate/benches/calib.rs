//! Calibration timings (seed 004_815695db12a6b16c.txt ch. 5): the full Brown–Conrady solve on 15
//! synthetic views of a 10 × 7 target (the workload of `benchmarks/calib_vs_opencv.py`), the
//! Max ERE of Algorithm 5.1 and a next-view suggestion over ~60 candidates.

use autoteach_estimate::calib::View;
use autoteach_estimate::calib::guide::{random_poses, synthesize_view_seeded};
use autoteach_estimate::calib::solve::{CalibOptions, calibrate};
use autoteach_geometry::camera::{Camera, CameraModel};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn target() -> Vec<[f64; 2]> {
    (0..70)
        .map(|i| [(i % 10) as f64 * 0.03, (i / 10) as f64 * 0.03])
        .collect()
}

fn views(cam: &Camera, count: usize) -> Vec<View> {
    let t = target();
    let poses = random_poses(cam, &t, 4 * count, 0.7, 1).expect("poses");
    poses
        .iter()
        .enumerate()
        .filter_map(|(k, p)| synthesize_view_seeded(cam, p, &t, 0.1, k as u64))
        .filter(|v| v.len() >= 30)
        .take(count)
        .collect()
}

fn bench(c: &mut Criterion) {
    let params = [
        420.0, 421.0, 318.0, 243.0, -0.30, 0.11, 0.0008, -0.0005, -0.018,
    ];
    let cam = Camera::new(CameraModel::BrownConrady, &params, 640, 480).expect("camera");
    let vs = views(&cam, 15);
    let mut opts = CalibOptions::new(CameraModel::BrownConrady, 640, 480);
    opts.outlier_threshold = Some(f64::INFINITY);
    c.bench_function("calibrate_brown_conrady_15_views", |b| {
        b.iter(|| calibrate(black_box(&vs), &opts).expect("calibrate"))
    });
    let calib = calibrate(&vs, &opts).expect("calibrate");
    c.bench_function("max_ere_200_samples_5x5", |b| {
        b.iter(|| calib.max_ere(200, 5, 0).expect("max ere"))
    });
    let few = calibrate(&vs[..4], &opts).expect("calibrate");
    c.bench_function("suggest_next_view_60_candidates", |b| {
        b.iter(|| {
            few.suggest_next_view(&target(), None, 100, 5, 0)
                .expect("suggest")
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
