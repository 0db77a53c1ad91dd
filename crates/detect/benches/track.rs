//! Association time per frame of the wafer tracker (000_3b1454b2b2194811.txt ch. 4) with 25
//! tracked wafers (two rims each, 20 px apart, ~300 edge points per rim): one full
//! `Tracker::update` (prediction, Algorithm 5 registration, Algorithm 4 management) and the
//! registration alone, against the greedy nearest-centre baseline.

use std::hint::black_box;

use autoteach_detect::track::registration::{
    RegistrationOptions, SegmentPoints, register_segments,
};
use autoteach_detect::track::{Associator, Tracker, TrackerOptions};
use autoteach_detect::wafers::{RimKind, WaferEdge};
use autoteach_geometry::conic::Ellipse;
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use nalgebra::Point2;

/// 25 wafers, upper and lower rims, the front arc (eccentric angles 0.1..π−0.1), shifted
/// down by `shift` pixels.
fn frame(shift: f64) -> Vec<WaferEdge> {
    let mut out = Vec::new();
    for w in 0..25 {
        for (kind, dy) in [(RimKind::Upper, 0.0), (RimKind::Lower, 2.5)] {
            let e = Ellipse::new(
                640.0,
                100.0 + 20.0 * w as f64 + dy + shift,
                300.0,
                30.0,
                0.0,
            )
            .expect("valid bench input");
            let points = e
                .sample(300, 0.1, std::f64::consts::PI - 0.1)
                .expect("valid bench input")
                .into_iter()
                .map(Point2::from)
                .collect();
            out.push(WaferEdge {
                ellipse: e,
                points,
                residual: 0.0,
                covariance: None,
                kind,
                wafer_id: w,
            });
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    for (name, associator) in [
        ("hierarchical", Associator::Hierarchical),
        ("greedy", Associator::GreedyNearestCentre),
    ] {
        let options = TrackerOptions {
            associator,
            ..TrackerOptions::default()
        };
        let mut tracker = Tracker::new(options).expect("valid bench input");
        for f in 0..3 {
            tracker
                .update(&frame(3.0 * f as f64), None)
                .expect("valid bench input");
        }
        assert_eq!(tracker.tracks().len(), 25);
        let next = frame(9.0);
        c.bench_function(&format!("tracker update 25 wafers ({name})"), |b| {
            b.iter_batched(
                || tracker.clone(),
                |mut t| {
                    t.update(black_box(&next), None).expect("valid bench input");
                    t
                },
                BatchSize::SmallInput,
            )
        });
    }
    // Algorithm 5 alone: 50 observed rims (48 points each) against 25 predicted wafers.
    let mut observed = SegmentPoints::default();
    for e in frame(9.0) {
        let pts: Vec<[f64; 2]> = e.points.iter().step_by(6).map(|p| [p.x, p.y]).collect();
        observed.push_segment(pts);
    }
    let mut predicted = SegmentPoints::default();
    for pair in frame(8.0).chunks(2) {
        let pts: Vec<[f64; 2]> = pair
            .iter()
            .flat_map(|e| e.points.iter().step_by(6).map(|p| [p.x, p.y]))
            .collect();
        predicted.push_segment(pts);
    }
    let opts = RegistrationOptions::default();
    c.bench_function("register_segments 50 rims x 25 wafers", |b| {
        b.iter(|| {
            register_segments(black_box(&observed), black_box(&predicted), &opts)
                .expect("valid bench input")
        })
    });
}

/// The multi-view 3D rim estimate (`circle_fit::refine_circle`, one Levenberg–Marquardt
/// iteration as the tracker runs it per registered rim and frame): 6 views × 24 points of a
/// wafer 0.45 m away seen from heights 20–50 mm above its plane.
fn bench_circle_fit(c: &mut Criterion) {
    use autoteach_detect::track::circle::Circle3;
    use autoteach_detect::track::circle_fit::{CircleFitOptions, RimView, refine_circle};
    use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};
    let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0);
    let truth = Circle3 {
        center: Vector3::new(0.45, 0.0, 0.1),
        normal: Vector3::z(),
        radius: 0.15,
    };
    let r =
        UnitQuaternion::from_matrix(&Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0));
    let views: Vec<RimView> = (0..6)
        .map(|v| {
            let t_wc =
                Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.12 + 0.006 * v as f64), r);
            let t_cw = t_wc.inverse();
            let points = (0..24)
                .map(|i| {
                    let phi = std::f64::consts::FRAC_PI_2
                        + std::f64::consts::PI * (i as f64 + 0.5) / 24.0;
                    let x = t_cw * Point3::from(truth.point_at(phi));
                    let p = k * x.coords;
                    [p.x / p.z, p.y / p.z]
                })
                .collect();
            RimView { t_cw, points }
        })
        .collect();
    let init = Circle3 {
        center: truth.center + Vector3::new(0.002, -0.001, 0.001),
        ..truth
    };
    let o = CircleFitOptions {
        max_iterations: 1,
        normal_prior: Some(Vector3::z()),
        ..CircleFitOptions::default()
    };
    c.bench_function("refine_circle 6 views x 24 points (1 LM iteration)", |b| {
        b.iter(|| refine_circle(&k, black_box(&views), &init, &o).expect("valid bench input"))
    });
}

criterion_group!(benches, bench, bench_circle_fit);
criterion_main!(benches);
