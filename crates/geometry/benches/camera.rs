//! Camera projection throughput (points per second): Brown–Conrady and Kannala–Brandt,
//! single-threaded (`project_into`) and on rayon's pool (`par_project_into`), plus
//! unprojection (Newton undistortion) single-threaded.
//!
//! `cargo bench -p autoteach-geometry --bench camera -- --warm-up-time 1 --measurement-time 3`

use std::f64::consts::PI;
use std::hint::black_box;

use autoteach_geometry::camera::{Camera, CameraModel};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const N: usize = 100_000;

/// `N` points at incidence angles up to `max_theta`, azimuths and depths spread by
/// low-discrepancy sequences (deterministic, no RNG).
fn points(max_theta: f64) -> Vec<[f64; 3]> {
    (0..N)
        .map(|i| {
            let i = i as f64;
            let theta = max_theta * (i * 0.618_033_988_749_895).fract().sqrt();
            let phi = 2.0 * PI * (i * 0.754_877_666_246_693).fract();
            let depth = 0.5 + 4.0 * (i * 0.569_840_290_998_053).fract();
            [
                depth * theta.sin() * phi.cos(),
                depth * theta.sin() * phi.sin(),
                depth * theta.cos(),
            ]
        })
        .collect()
}

fn cameras() -> [(&'static str, Camera, f64); 2] {
    let bc = Camera::new(
        CameraModel::BrownConrady,
        &[
            600.0, 580.0, 640.5, 479.25, -0.1, 0.01, 0.001, -0.0005, -0.0002,
        ],
        1280,
        960,
    )
    .expect("valid Brown-Conrady parameters");
    let kb = Camera::new(
        CameraModel::KannalaBrandt,
        &[350.0, 345.0, 639.5, 481.0, -0.02, 0.004, -0.0005, 0.00002],
        1280,
        960,
    )
    .expect("valid Kannala-Brandt parameters");
    [
        ("brown_conrady", bc, 50f64.to_radians()),
        ("kannala_brandt", kb, 100f64.to_radians()),
    ]
}

fn bench_camera(c: &mut Criterion) {
    let mut project = c.benchmark_group("camera_project_100k");
    project.throughput(Throughput::Elements(N as u64));
    for (name, cam, max_theta) in cameras() {
        let pts = points(max_theta);
        let mut out = vec![[0.0; 2]; N];
        project.bench_function(format!("{name}/serial"), |b| {
            b.iter(|| {
                cam.project_into(black_box(&pts), black_box(&mut out))
                    .expect("projectable")
            })
        });
        project.bench_function(format!("{name}/rayon"), |b| {
            b.iter(|| {
                cam.par_project_into(black_box(&pts), black_box(&mut out))
                    .expect("projectable")
            })
        });
    }
    project.finish();

    let mut unproject = c.benchmark_group("camera_unproject_100k");
    unproject.throughput(Throughput::Elements(N as u64));
    for (name, cam, max_theta) in cameras() {
        let pts = points(max_theta);
        let mut px = vec![[0.0; 2]; N];
        cam.project_into(&pts, &mut px).expect("projectable");
        let mut rays = vec![[0.0; 3]; N];
        unproject.bench_function(format!("{name}/serial"), |b| {
            b.iter(|| {
                cam.unproject_into(black_box(&px), black_box(&mut rays))
                    .expect("unprojectable")
            })
        });
    }
    unproject.finish();
}

criterion_group!(benches, bench_camera);
criterion_main!(benches);
