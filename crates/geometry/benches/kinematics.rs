//! Kinematics benches for the wafer-handling robot (000_3b1454b2b2194811.txt ch. 2.2):
//! batched camera forward kinematics (eq. (2.2)), single-pose FK and closed-form IK.
//!
//! Run: `cargo bench -p autoteach-geometry --bench kinematics -- --warm-up-time 1 --measurement-time 3`

use std::f64::consts::PI;
use std::hint::black_box;

use autoteach_geometry::robot::{Blade, Joints, WaferRobot};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn random_joints(rng: &mut Pcg64, n: usize) -> Vec<Joints> {
    (0..n)
        .map(|_| {
            Joints::new(
                rng.random_range(-PI..PI),
                rng.random_range(-PI..PI),
                rng.random_range(-PI..PI),
                rng.random_range(-PI..PI),
                rng.random_range(-0.2..0.4),
            )
        })
        .collect()
}

fn kinematics(c: &mut Criterion) {
    let robot = WaferRobot::default();
    let mut rng = Pcg64::seed_from_u64(42);
    let batch = random_joints(&mut rng, 10_000);
    let q = batch[0];

    let mut group = c.benchmark_group("kinematics");
    group.throughput(Throughput::Elements(batch.len() as u64));
    group.bench_function("camera_poses_batch_10000", |b| {
        b.iter(|| robot.camera_poses(black_box(&batch)))
    });
    group.bench_function("camera_pose_loop_10000", |b| {
        b.iter(|| {
            black_box(&batch)
                .iter()
                .map(|q| robot.camera_pose(q))
                .collect::<Vec<_>>()
        })
    });
    group.throughput(Throughput::Elements(1));
    group.bench_function("camera_pose_single", |b| {
        b.iter(|| robot.camera_pose(black_box(&q)))
    });
    group.bench_function("blade_pose_single", |b| {
        b.iter(|| robot.blade_pose(black_box(&q), Blade::One))
    });
    let target = robot.blade_pose(&q, Blade::One);
    group.bench_function("inverse_kinematics_blade", |b| {
        b.iter(|| robot.inverse_kinematics(black_box(&target), Blade::One, 0.0))
    });
    let t_wc = robot.camera_pose(&q);
    group.bench_function("inverse_kinematics_camera", |b| {
        b.iter(|| robot.inverse_kinematics_camera(black_box(&t_wc), 0.0))
    });
    group.bench_function("camera_jacobian", |b| {
        b.iter(|| robot.camera_jacobian(black_box(&q)))
    });
    group.finish();
}

criterion_group!(benches, kinematics);
criterion_main!(benches);
