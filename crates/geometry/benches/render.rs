//! Benchmark of the ray-cast renderer: one 1280×720 frame of the full carrier (26 slots, two
//! empty, one tilted wafer) with the default options (4×4 adaptive anti-aliasing, blur, noise),
//! and the rim ground truth of the same frame.

use autoteach_geometry::camera::Camera;
use autoteach_geometry::render::{self, RenderOptions, Scene};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::hint::black_box;

fn setup() -> (Scene, Camera, Isometry3<f64>) {
    let cam = Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).expect("valid camera");
    let carrier = render::Carrier::default();
    let mut wafers: Vec<Isometry3<f64>> = (1..=26)
        .filter(|k| *k != 5 && *k != 12)
        .map(|k| carrier.slot_pose(k))
        .collect();
    wafers[7] = Isometry3::new(
        Vector3::new(0.003, -0.002, 0.085),
        Vector3::new(0.01, -0.015, 0.2),
    );
    let (pitch, eye) = (0.08f64, Vector3::new(-0.38, 0.03, 0.13));
    let z = Vector3::new(pitch.cos(), 0.0, -pitch.sin());
    let x = Vector3::new(0.0, -1.0, 0.0);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, z.cross(&x), z]));
    let t_wc = Isometry3::from_parts(
        Translation3::from(eye),
        UnitQuaternion::from_rotation_matrix(&rot),
    );
    (Scene::new(wafers), cam, t_wc)
}

fn bench_render(c: &mut Criterion) {
    let (scene, cam, t_wc) = setup();
    let opts = RenderOptions {
        seed: 1,
        ..RenderOptions::default()
    };
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    g.bench_function("frame_1280x720", |b| {
        b.iter(|| render::render(black_box(&scene), &cam, &t_wc, &opts))
    });
    g.bench_function("rim_visibility_720", |b| {
        b.iter(|| render::rim_visibility(black_box(&scene), &cam, &t_wc, 720))
    });
    g.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
