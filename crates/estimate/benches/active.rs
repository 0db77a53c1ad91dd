//! Active auto-teaching timings (000_3b1454b2b2194811.txt ch. 6): one planning step of the
//! reduced search and of plain sampling on the chamber-opening scene after one measurement, the
//! observation Jacobian (6.14), the observability indices (Table 6.2) and DETMAX (6.10).

use autoteach_estimate::active::closed_loop::Scenario;
use autoteach_estimate::active::design::{self, DetmaxOptions};
use autoteach_estimate::active::model::{HandEyeEstimator, HandEyeParams};
use autoteach_estimate::active::planner::{self, PlannerOptions};
use autoteach_geometry::robot::Joints;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, Isometry3, Point3, Translation3, Vector2};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::hint::black_box;

/// The scene, the nominal estimate after one centred measurement 0.6 m away, and its joints.
fn state() -> (
    autoteach_estimate::active::planner::ActiveScene,
    HandEyeEstimator,
    Joints,
) {
    let sc = Scenario::chamber().expect("scenario");
    let scene = sc.scene().expect("scene");
    let nominal = HandEyeParams::nominal(&sc.robot, sc.opening);
    let rot = scene.camera_rotation(scene.facing_yaw(&nominal));
    let ray = sc
        .camera
        .unproject(&Vector2::new(639.5, 479.5))
        .expect("ray");
    let centre = nominal.opening * Point3::from(scene.centre());
    let t_wc = Isometry3::from_parts(
        Translation3::from(centre.coords - rot * (ray * (0.6 / ray.z))),
        rot,
    );
    let q = scene.camera_ik(&nominal, &t_wc).expect("ik")[0];
    let prior: Vec<f64> = sc
        .mask
        .indices()
        .iter()
        .map(|&i| sc.prior_sigmas[i])
        .collect();
    let mut est =
        HandEyeEstimator::new(scene.model.clone(), nominal, &prior, sc.sigma_px).expect("est");
    let det = scene.model.project(&nominal, &q).expect("project");
    est.update(&q, &det).expect("update");
    (scene, est, q)
}

fn bench(c: &mut Criterion) {
    let (scene, est, q) = state();
    let opts = PlannerOptions::default();
    c.bench_function("active/plan_reduced", |b| {
        b.iter(|| {
            planner::plan_reduced(
                black_box(&scene),
                &est.estimate,
                est.information(),
                0.5,
                &opts,
            )
            .expect("plan")
        })
    });
    c.bench_function("active/plan_sampling_2000", |b| {
        b.iter(|| {
            planner::plan_sampling(
                black_box(&scene),
                &est.estimate,
                est.information(),
                0.5,
                &opts,
            )
            .expect("plan")
        })
    });
    c.bench_function("active/observation_jacobian_4_corners", |b| {
        b.iter(|| {
            scene
                .model
                .full_jacobian(black_box(&est.estimate), &q)
                .expect("jac")
        })
    });
    let info = est.information().clone();
    c.bench_function("active/observability_indices_8x8", |b| {
        b.iter(|| design::observability_indices(black_box(&info), 2.0).expect("indices"))
    });
    let mut rng = Pcg64::seed_from_u64(1);
    let cands: Vec<DMatrix<f64>> = (0..200)
        .map(|_| DMatrix::from_fn(2, 8, |_, _| rng.random_range(-1.0..1.0)))
        .collect();
    c.bench_function("active/detmax_200_choose_10_p8", |b| {
        b.iter(|| {
            design::detmax(
                black_box(&cands),
                10,
                Some(&info),
                &DetmaxOptions::default(),
            )
            .expect("detmax")
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
