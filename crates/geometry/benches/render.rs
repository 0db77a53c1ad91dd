//! Benchmark of the ray-cast renderer: one 1280×720 frame of the full carrier (26 slots, two
//! empty, one tilted wafer) with the default options (4×4 adaptive anti-aliasing, blur, noise),
//! and the rim ground truth of the same frame.

use autoteach_geometry::render::{self, RayCamera, RenderOptions, Scene};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};
use std::hint::black_box;

struct Pinhole {
    k: Matrix3<f64>,
    k_inv: Matrix3<f64>,
}

impl RayCamera for Pinhole {
    fn width(&self) -> usize {
        1280
    }
    fn height(&self) -> usize {
        720
    }
    fn bearing(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        Some(self.k_inv * Vector3::new(u, v, 1.0))
    }
    fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        (p.z > 0.0).then(|| {
            let q = self.k * p;
            Vector2::new(q.x / q.z, q.y / q.z)
        })
    }
    fn k_matrix(&self) -> Matrix3<f64> {
        self.k
    }
}

fn setup() -> (Scene, Pinhole, Isometry3<f64>) {
    let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0);
    let cam = Pinhole { k, k_inv: k.try_inverse().expect("invertible K") };
    let carrier = render::Carrier::default();
    let mut wafers: Vec<Isometry3<f64>> = (1..=26).filter(|k| *k != 5 && *k != 12).map(|k| carrier.slot_pose(k)).collect();
    wafers[7] = Isometry3::new(Vector3::new(0.003, -0.002, 0.085), Vector3::new(0.01, -0.015, 0.2));
    let (pitch, eye) = (0.08f64, Vector3::new(-0.38, 0.03, 0.13));
    let z = Vector3::new(pitch.cos(), 0.0, -pitch.sin());
    let x = Vector3::new(0.0, -1.0, 0.0);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, z.cross(&x), z]));
    let t_wc = Isometry3::from_parts(Translation3::from(eye), UnitQuaternion::from_rotation_matrix(&rot));
    (Scene::new(wafers), cam, t_wc)
}

fn bench_render(c: &mut Criterion) {
    let (scene, cam, t_wc) = setup();
    let opts = RenderOptions { seed: 1, ..RenderOptions::default() };
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    g.bench_function("frame_1280x720", |b| b.iter(|| render::render(black_box(&scene), &cam, &t_wc, &opts)));
    g.bench_function("rim_visibility_720", |b| {
        b.iter(|| render::rim_visibility(black_box(&scene), &cam, &t_wc, 720))
    });
    g.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
