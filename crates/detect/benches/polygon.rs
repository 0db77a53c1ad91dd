//! Polygon detection (seed §3.3): segment detection + voting + IRLS on a rendered 480×360
#![allow(clippy::unwrap_used, clippy::expect_used)]
//! chamber-opening image, and voting + IRLS alone from its segments.
use autoteach_detect::polygon::{
    PolygonInput, PolygonOptions, SegmentOptions, detect_polygon, detect_segments,
};
use autoteach_geometry::render::opening::{
    ImageLine, OpeningScene, Placement, RefPolygon, render_opening,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix3, Vector2};
use std::hint::black_box;

fn cross() -> Vec<Vector2<f64>> {
    [
        (-80., -20.),
        (-30., -20.),
        (-30., -40.),
        (30., -40.),
        (30., -20.),
        (80., -20.),
        (80., 20.),
        (30., 20.),
        (30., 40.),
        (-30., 40.),
        (-30., 20.),
        (-80., 20.),
    ]
    .iter()
    .map(|&(x, y)| Vector2::new(x, y))
    .collect()
}

fn bench(c: &mut Criterion) {
    let h = Matrix3::new(0.98, -0.12, 240.0, 0.1, 1.02, 180.0, 2e-4, -3e-4, 1.0);
    let place = Placement {
        centre: Vector2::new(10.0, -5.0),
        rotation: 0.05,
        scale: 1.02,
    };
    let scene = OpeningScene {
        width: 480,
        height: 360,
        homography: h,
        plate: 190.0,
        polygons: vec![RefPolygon {
            vertices: place.apply(&cross()),
            intensity: 35.0,
        }],
        lines: vec![ImageLine {
            a: Vector2::new(50.0, 0.0),
            b: Vector2::new(300.0, 360.0),
            width: 2.0,
            intensity: 80.0,
        }],
        occluders: vec![],
        supersample: 4,
        blur_sigma: 0.8,
        noise_sigma: 3.0,
        seed: 1,
    };
    let img = render_opening(&scene).unwrap();
    let so = SegmentOptions::default();
    let po = PolygonOptions::default();
    let segs = detect_segments(&img, &so).unwrap();
    let mut g = c.benchmark_group("polygon");
    g.sample_size(10);
    g.bench_function("detect_segments_480x360", |b| {
        b.iter(|| detect_segments(black_box(&img), &so).unwrap())
    });
    g.bench_function("vote_and_irls_from_segments", |b| {
        b.iter(|| {
            detect_polygon(PolygonInput::Segments(black_box(&segs)), &cross(), &h, &po).unwrap()
        })
    });
    g.bench_function("detect_polygon_image_480x360", |b| {
        b.iter(|| {
            detect_polygon(PolygonInput::Image(black_box(&img), &so), &cross(), &h, &po).unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
