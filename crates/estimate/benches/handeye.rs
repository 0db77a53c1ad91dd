//! Benchmarks of the hand-eye factors (000_3b1454b2b2194811.txt eq. (5.13)) and the UKF model.

use autoteach_estimate::handeye::{
    AutoTeachUkfModel, EdgeJacobians, Rim, RobotMotionResidual, conic_edge_residuals,
    point_reprojection_residuals,
};
use autoteach_estimate::lsq::{Residual, se3_to_params};
use autoteach_estimate::ukf::UkfModel;
use autoteach_geometry::conic::project_circle;
use autoteach_geometry::robot::{Joints, WaferRobot};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Translation3, UnitQuaternion, Vector2, Vector5,
};
use std::hint::black_box;

fn setup() -> (
    Matrix3<f64>,
    Isometry3<f64>,
    Vector5<f64>,
    Vec<Vector2<f64>>,
) {
    let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0);
    let look =
        UnitQuaternion::from_matrix(&Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0))
            * UnitQuaternion::from_euler_angles(0.14, 0.0, 0.0);
    let t_wc = Isometry3::from_parts(Translation3::new(-0.45, 0.01, 0.12), look);
    let w = Vector5::new(0.002, -0.001, 0.06, 0.004, -0.006);
    let (t_wo, _) = autoteach_estimate::handeye::rim_pose(&w, Rim::Upper, 0.001);
    let e = project_circle(&k, &(t_wc.inverse() * t_wo), 0.15).expect("valid bench input");
    let pts = (0..24)
        .map(|i| e.point_at(0.3 + 0.12 * i as f64) + Vector2::new(0.2, -0.1))
        .collect();
    (k, t_wc, w, pts)
}

fn bench(c: &mut Criterion) {
    let (k, t_wc, w, pts) = setup();
    let n = pts.len();
    c.bench_function("handeye conic factor 24 points + jacobians", |b| {
        let mut r = vec![0.0; n];
        let mut j = EdgeJacobians {
            camera: DMatrix::zeros(n, 6),
            wafer: DMatrix::zeros(n, 5),
        };
        b.iter(|| {
            conic_edge_residuals(
                &k,
                black_box(&t_wc),
                &w,
                Rim::Upper,
                0.15,
                0.001,
                &pts,
                0.3,
                &mut r,
                Some(&mut j),
            )
            .expect("valid bench input");
        })
    });
    let angles: Vec<f64> = (0..n).map(|i| 0.3 + 0.12 * i as f64).collect();
    c.bench_function("handeye point factor 24 points + jacobians", |b| {
        let mut r = vec![0.0; 2 * n];
        let mut j = EdgeJacobians {
            camera: DMatrix::zeros(2 * n, 6),
            wafer: DMatrix::zeros(2 * n, 5),
        };
        b.iter(|| {
            point_reprojection_residuals(
                &k,
                black_box(&t_wc),
                &w,
                Rim::Upper,
                0.15,
                0.001,
                &pts,
                &angles,
                0.3,
                &mut r,
                Some(&mut j),
            )
            .expect("valid bench input");
        })
    });
    let robot = WaferRobot::default();
    let q = Joints::new(0.2, 1.4, 0.3, -1.5, 0.1);
    let m = AutoTeachUkfModel::new(robot, &q).expect("valid bench input");
    let x = AutoTeachUkfModel::state_of(&robot.camera_pose(&q), &[0.01, 0.0, -0.01]);
    c.bench_function("handeye UKF measurement (inverse kinematics)", |b| {
        let mut z = DVector::zeros(4);
        b.iter(|| {
            m.hx(black_box(x.column(0)), &mut z)
                .expect("valid bench input")
        })
    });
    let q2 = Joints::new(0.21, 1.38, 0.3, -1.48, 0.101);
    let motion =
        RobotMotionResidual::new(robot.params, q, q2, Joints::zeros(), vec![1, 3], [2e-5; 6])
            .expect("valid bench input");
    let vals: Vec<Vec<f64>> = vec![
        se3_to_params(&robot.camera_pose(&q)).to_vec(),
        se3_to_params(&robot.camera_pose(&q2)).to_vec(),
        se3_to_params(&robot.base).to_vec(),
        vec![0.001],
        vec![-0.002],
    ];
    c.bench_function("handeye robot motion factor (5.11) + jacobians", |b| {
        let p: Vec<&[f64]> = vals.iter().map(|v| v.as_slice()).collect();
        let mut r = vec![0.0; 6];
        let mut j = vec![
            DMatrix::zeros(6, 6),
            DMatrix::zeros(6, 6),
            DMatrix::zeros(6, 6),
            DMatrix::zeros(6, 1),
            DMatrix::zeros(6, 1),
        ];
        b.iter(|| {
            motion
                .evaluate(black_box(&p), &mut r, Some(&mut j))
                .expect("valid bench input")
        })
    });
}

/// Gating (`handeye::gating`): a 26-wafer carrier seen in 20 frames, both rims of every wafer
/// detected as one 60-point arc per frame, plus a 40-point clutter edge per frame.
fn bench_gating(c: &mut Criterion) {
    use autoteach_estimate::handeye::{DetectedEdges, GateConfig, WaferGeometry, gate_edges};
    let (k, t_wc, _, _) = setup();
    let geometry = WaferGeometry::new(0.15, 0.001).expect("valid bench input");
    let wafers: Vec<Option<Vector5<f64>>> = (0..26)
        .map(|i| Some(Vector5::new(0.0, 0.0, 0.01 * i as f64, 0.0, 0.0)))
        .collect();
    let cams: Vec<Isometry3<f64>> = (0..20)
        .map(|f| {
            Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.005 * f as f64),
                UnitQuaternion::identity(),
            ) * t_wc
        })
        .collect();
    let (mut points, mut start, mut frames) = (Vec::new(), vec![0], Vec::new());
    for (f, cam) in cams.iter().enumerate() {
        for w in wafers.iter().flatten() {
            for rim in [Rim::Upper, Rim::Lower] {
                let (t_wo, _) = autoteach_estimate::handeye::rim_pose(w, rim, 0.001);
                if let Ok(e) = project_circle(&k, &(cam.inverse() * t_wo), 0.15) {
                    points.extend((0..60).map(|i| e.point_at(0.4 + 0.03 * i as f64)));
                    start.push(points.len());
                    frames.push(f);
                }
            }
        }
        points.extend((0..40).map(|i| Vector2::new(300.0 + 3.0 * i as f64, 200.0)));
        start.push(points.len());
        frames.push(f);
    }
    let edges = DetectedEdges {
        points: &points,
        start: &start,
        frames: &frames,
    };
    let cfg = GateConfig::default();
    c.bench_function("handeye gating 26 wafers x 20 frames", |b| {
        b.iter(|| gate_edges(&k, &cams, black_box(&wafers), geometry, &edges, &cfg))
    });
}

criterion_group!(benches, bench, bench_gating);
criterion_main!(benches);
