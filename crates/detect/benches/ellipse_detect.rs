//! General ellipse detection (`detect_ellipses`) and the wafer rims built on it
//! (`detect_wafer_rims`) on 1280×720 images: a rendered carrier image (target wafer in slot 5,
//! disturbance wafer in slot 7, as the `wafer_detect` bench) and a synthetic image of eight
//! ellipses of both polarities and sizes on a noisy ground (σ = 4 grey levels); the line path
//! (`ridges::detect_line_ellipses`) on the synthetic image.
//!
//! Run: `RAYON_NUM_THREADS=1 cargo bench -p autoteach-detect --bench ellipse_detect --
//! --warm-up-time 1 --measurement-time 3`.

use autoteach_detect::edges::GrayView;
use autoteach_detect::ellipse_detection::ridges::{detect_line_ellipses, ridge_scale};
use autoteach_detect::ellipse_detection::{EllipseDetectParams, detect_ellipses};
use autoteach_detect::wafer_rims::{WaferRimParams, detect_wafer_rims};
use autoteach_geometry::camera::Camera;
use autoteach_geometry::render::{self, Carrier, RenderOptions, Scene};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;
use std::hint::black_box;

fn rendered() -> (Vec<u8>, usize, usize) {
    let camera = Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).expect("camera");
    let axes = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.03)
        * Rotation3::from_matrix_unchecked(axes)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), -0.14);
    let t_wc = Isometry3::from_parts(
        Translation3::new(-0.48, 0.02, 0.09),
        UnitQuaternion::from_rotation_matrix(&r),
    );
    let carrier = Carrier::default();
    let scene = Scene::new(vec![carrier.slot_pose(5), carrier.slot_pose(7)]);
    let img = render::render(&scene, &camera, &t_wc, &RenderOptions::default()).expect("render");
    (img.data, img.width, img.height)
}

fn synthetic() -> (Vec<u8>, usize, usize) {
    let (w, h) = (1280usize, 720usize);
    // (cx, cy, a, b, theta, grey inside)
    let ellipses: [(f64, f64, f64, f64, f64, f64); 8] = [
        (200.0, 180.0, 120.0, 80.0, 0.2, 200.0),
        (520.0, 200.0, 60.0, 58.0, 0.0, 40.0),
        (860.0, 180.0, 200.0, 40.0, -0.1, 180.0),
        (1150.0, 200.0, 80.0, 30.0, 1.2, 30.0),
        (240.0, 520.0, 150.0, 120.0, 0.7, 60.0),
        (600.0, 540.0, 30.0, 20.0, 0.4, 220.0),
        (880.0, 560.0, 220.0, 90.0, 0.05, 210.0),
        (1180.0, 600.0, 50.0, 45.0, 0.0, 20.0),
    ];
    let mut img = vec![120f64; w * h];
    for &(cx, cy, a, b, t, grey) in &ellipses {
        let (s, c) = f64::sin_cos(t);
        let (x0, x1) = (
            (cx - a - 2.0).max(0.0) as usize,
            ((cx + a + 2.0) as usize).min(w - 1),
        );
        let (y0, y1) = (
            (cy - a - 2.0).max(0.0) as usize,
            ((cy + a + 2.0) as usize).min(h - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let mut inside = 0.0;
                for j in 0..4 {
                    for i in 0..4 {
                        let du = x as f64 - 0.375 + 0.25 * f64::from(i) - cx;
                        let dv = y as f64 - 0.375 + 0.25 * f64::from(j) - cy;
                        let (u, v) = (c * du + s * dv, -s * du + c * dv);
                        if (u / a).powi(2) + (v / b).powi(2) <= 1.0 {
                            inside += 1.0 / 16.0;
                        }
                    }
                }
                let k = y * w + x;
                img[k] = img[k] * (1.0 - inside) + grey * inside;
            }
        }
    }
    let mut rng = Pcg64::seed_from_u64(1);
    let noise = Normal::new(0.0, 4.0).expect("normal");
    let data = img
        .iter()
        .map(|v| (v + noise.sample(&mut rng)).round().clamp(0.0, 255.0) as u8)
        .collect();
    (data, w, h)
}

fn bench(c: &mut Criterion) {
    let params = EllipseDetectParams::default();
    for (name, (data, w, h)) in [("synthetic", synthetic()), ("rendered", rendered())] {
        let view = GrayView::new(&data, w, h).expect("view");
        let n = detect_ellipses(&view, &params).expect("detect").len();
        eprintln!("{name}: {n} ellipses");
        c.bench_function(&format!("detect_ellipses_{name}_1280x720"), |b| {
            b.iter(|| detect_ellipses(black_box(&view), &params).expect("detect"))
        });
    }
    // Thin lines found on their centre lines (Hessian at the wafer rims' default scale).
    let (data, w, h) = synthetic();
    let view = GrayView::new(&data, w, h).expect("view");
    let sigma = ridge_scale(autoteach_detect::wafer_rims::RIM_LINE_WIDTH);
    c.bench_function("detect_line_ellipses_synthetic_1280x720", |b| {
        b.iter(|| detect_line_ellipses(black_box(&view), &params, sigma).expect("lines"))
    });
    let (data, w, h) = rendered();
    let view = GrayView::new(&data, w, h).expect("view");
    let rims = WaferRimParams::default();
    c.bench_function("detect_wafer_rims_rendered_1280x720", |b| {
        b.iter(|| detect_wafer_rims(black_box(&view), &rims).expect("rims"))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
