//! Whole-image wafer-rim detection on a rendered 1280×720 carrier image (target wafer in slot 5,
//! disturbance wafer 2 slots above), single-threaded, and its stages.
//!
//! Run: `cargo bench -p autoteach-detect --bench wafer_detect -- --warm-up-time 1 --measurement-time 3`.

use autoteach_detect::assembly::{AssemblyParams, assemble};
use autoteach_detect::edges::{
    ArcParams, CannyParams, GrayView, LinkParams, canny, detect_arcs, link_edges,
};
use autoteach_detect::wafers::{DetectParams, detect_wafers};
use autoteach_geometry::camera::Camera;
use autoteach_geometry::render::{self, Carrier, RenderOptions, Scene};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::hint::black_box;

fn image() -> (Vec<u8>, usize, usize) {
    let carrier = Carrier::default();
    let scene = Scene::new(vec![carrier.slot_pose(5), carrier.slot_pose(7)]);
    let camera = Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).expect("camera");
    let axes = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.03)
        * Rotation3::from_matrix_unchecked(axes)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), -0.14);
    let t_wc = Isometry3::from_parts(
        Translation3::new(-0.48, 0.02, 0.09),
        UnitQuaternion::from_rotation_matrix(&r),
    );
    let img = render::render(&scene, &camera, &t_wc, &RenderOptions::default()).expect("render");
    (img.data, img.width, img.height)
}

fn bench(c: &mut Criterion) {
    let (data, w, h) = image();
    let view = GrayView::new(&data, w, h).expect("image");
    let params = DetectParams::default();
    assert!(detect_wafers(&view, &params).expect("detect").len() >= 4);
    c.bench_function("detect_wafers 1280x720", |b| {
        b.iter(|| detect_wafers(black_box(&view), &params))
    });
    c.bench_function("canny 1280x720", |b| {
        b.iter(|| canny(black_box(&view), &CannyParams::default()))
    });
    let map = canny(&view, &CannyParams::default()).expect("canny");
    c.bench_function("link_edges 1280x720", |b| {
        b.iter(|| link_edges(black_box(&map), &LinkParams::default()))
    });
    let arcs = detect_arcs(
        &view,
        &CannyParams::default(),
        &LinkParams::default(),
        &ArcParams::default(),
    )
    .expect("arcs");
    c.bench_function("assemble (Algorithms 1-2)", |b| {
        b.iter(|| assemble(black_box(&arcs), &AssemblyParams::default()))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
