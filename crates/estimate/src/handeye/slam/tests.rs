use super::*;
use autoteach_geometry::conic::project_circle;
use nalgebra::{Translation3, UnitQuaternion};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

/// A synthetic session: the default robot in front of a stack of wafers, the camera
/// sweeping up and down; edge points are the projections of the facing half of each rim
/// plus Gaussian pixel noise.
pub(crate) struct Scene {
    pub config: SlamMotConfig,
    pub truth: SlamMotState,
    pub encoders: Vec<Joints>,
    pub observations: Vec<EdgeObservation>,
}

pub(crate) fn scene(seed: u64, frames: usize, noise_px: f64) -> Scene {
    let params = RobotParams::default();
    let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0);
    let base = Isometry3::from_parts(
        Translation3::new(-1.0, 0.03, -0.48),
        UnitQuaternion::from_euler_angles(0.0012, -0.0009, 0.026),
    );
    let offsets = Joints::new(0.0, 0.009, 0.0, -0.012, 0.0);
    let robot = WaferRobot { params, base };
    let slots = [0.0, 0.03, 0.06, 0.09, 0.12];
    let wafers: Vec<Vector5<f64>> = slots
        .iter()
        .enumerate()
        .map(|(i, z)| {
            Vector5::new(
                0.0002 * i as f64,
                -0.0001 * i as f64,
                *z,
                0.0,
                if i == 4 { 0.0175 } else { 0.0005 * i as f64 },
            )
        })
        .collect();
    let ref_pose = robot.camera_pose(&Joints::zeros());
    let mut rng = Pcg64::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_px.max(1e-12)).unwrap();
    let mut encoders = Vec::new();
    let mut observations = Vec::new();
    let mut prev: Option<Joints> = None;
    for f in 0..frames {
        let s = f as f64 / (frames.max(2) - 1) as f64;
        let x = -0.52 + 0.1 * (3.0 * s).sin().abs();
        let y = -0.06 + 0.12 * s;
        let z = 0.03 + 0.12 * (0.5 - 0.5 * (std::f64::consts::TAU * s).cos());
        let yaw = 0.06 * (5.0 * s).sin();
        let rot = base.rotation
            * UnitQuaternion::from_euler_angles(0.0, 0.0, yaw - 0.026)
            * base.rotation.inverse()
            * ref_pose.rotation;
        let target = Isometry3::from_parts(Translation3::new(x, y, z), rot);
        let sols = robot.inverse_kinematics_camera(&target, 0.0).unwrap();
        let q = *sols
            .iter()
            .min_by(|a, b| {
                let da = prev.map_or(if a[1] > 0.0 { 0.0 } else { 1.0 }, |p| (*a - p).norm());
                let db = prev.map_or(if b[1] > 0.0 { 0.0 } else { 1.0 }, |p| (*b - p).norm());
                da.total_cmp(&db)
            })
            .unwrap();
        prev = Some(q);
        encoders.push(q + offsets);
        let t_wc = robot.camera_pose(&q);
        for (wi, w) in wafers.iter().enumerate() {
            for rim in [Rim::Upper, Rim::Lower] {
                let (t_wo, _) = super::super::wafer::rim_pose(w, rim, 0.001);
                let t_co = t_wc.inverse() * t_wo;
                let Ok(e) = project_circle(&k, &t_co, 0.15) else {
                    continue;
                };
                // Grazing views (the wafer seen nearly edge-on) are left out, as the
                // pipeline's front end does.
                if e.b / e.a < 0.05 {
                    continue;
                }
                let pts: Vec<Vector2<f64>> = (0..24)
                    .filter_map(|i| {
                        let th = std::f64::consts::PI * (0.55 + 0.9 * i as f64 / 23.0);
                        let xo =
                            t_co * nalgebra::Point3::new(0.15 * th.cos(), 0.15 * th.sin(), 0.0);
                        let p = k * xo.coords;
                        let px = Vector2::new(p.x / p.z, p.y / p.z);
                        (px.x > 0.0 && px.x < 1279.0 && px.y > 0.0 && px.y < 719.0).then(|| {
                            px + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng))
                        })
                    })
                    .collect();
                if pts.len() >= 6 {
                    observations.push(EdgeObservation {
                        frame: f,
                        wafer: wi,
                        rim,
                        points: pts,
                        sigma_scale: Vec::new(),
                    });
                }
            }
        }
    }
    let mut config = SlamMotConfig::new(k, params, WaferGeometry::new(0.15, 0.001).unwrap());
    config.pixel_sigma = noise_px.max(0.05);
    Scene {
        config,
        truth: SlamMotState::new(base, offsets, wafers),
        encoders,
        observations,
    }
}

fn perturbed(truth: &SlamMotState) -> SlamMotState {
    let mut s = truth.clone();
    s.base = Isometry3::from_parts(
        Translation3::from(truth.base.translation.vector + Vector3::new(0.004, -0.003, 0.002)),
        truth.base.rotation * UnitQuaternion::from_euler_angles(0.004, -0.003, 0.0),
    );
    s.offsets = Joints::zeros();
    for (i, w) in s.wafers.iter_mut().enumerate() {
        if i > 0 {
            w[0] += 0.002;
            w[2] += 0.003;
            w[3] = 0.0;
            w[4] = 0.0;
        }
    }
    s
}

#[test]
fn batch_recovers_the_truth_within_three_sigma() {
    let sc = scene(1, 40, 0.3);
    let slam = SlamMot::new(
        sc.config.clone(),
        sc.encoders.clone(),
        sc.observations.clone(),
        sc.truth.wafers.len(),
    )
    .unwrap();
    let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
    let cov = sol.uncertainty.covariance.clone().expect("observable");
    let d = se3_minus(&sol.state.base, &sc.truth.base);
    for i in 0..6 {
        let sd = cov[(i, i)].sqrt();
        assert!(
            d[i].abs() < 4.0 * sd + 1e-9,
            "base {i}: error {} vs sd {sd}",
            d[i]
        );
    }
    for (i, &j) in sc.config.estimate_offsets.iter().enumerate() {
        let err = sol.state.offsets[j] - sc.truth.offsets[j];
        let sd = cov[(6 + i, 6 + i)].sqrt();
        assert!(
            err.abs() < 4.0 * sd && err.abs() < 2e-4,
            "offset {j}: {err} vs {sd}"
        );
    }
    for (w_est, w_true) in sol.state.wafers.iter().zip(&sc.truth.wafers) {
        assert!(
            (w_est - w_true).fixed_rows::<3>(0).norm() < 3e-4,
            "{w_est} vs {w_true}"
        );
    }
    assert!(sol.rms_px < 0.5 && sol.rms_px > 0.15, "rms {}", sol.rms_px);
}

#[test]
fn uniform_sigma_scale_equals_a_larger_pixel_sigma() {
    let sc = scene(2, 20, 0.3);
    let scaled: Vec<EdgeObservation> = sc
        .observations
        .iter()
        .map(|o| EdgeObservation {
            sigma_scale: vec![2.0; o.points.len()],
            ..o.clone()
        })
        .collect();
    let n = sc.truth.wafers.len();
    let a = SlamMot::new(sc.config.clone(), sc.encoders.clone(), scaled, n).unwrap();
    let mut cfg = sc.config.clone();
    cfg.pixel_sigma *= 2.0;
    let b = SlamMot::new(cfg, sc.encoders.clone(), sc.observations.clone(), n).unwrap();
    let start = perturbed(&sc.truth);
    let (sa, sb) = (
        a.solve_batch(&start).unwrap(),
        b.solve_batch(&start).unwrap(),
    );
    assert!(se3_minus(&sa.state.base, &sb.state.base).norm() < 1e-9);
    let (ca, cb) = (
        sa.uncertainty.covariance.unwrap(),
        sb.uncertainty.covariance.unwrap(),
    );
    assert!((&ca - &cb).norm() <= 1e-6 * cb.norm(), "{ca} vs {cb}");
    // Without the scales the covariance is clearly smaller (not exactly 4×: the yaw-gauge
    // prior is not scaled and the Huber weights change): the scales are used.
    let c = SlamMot::new(
        sc.config.clone(),
        sc.encoders.clone(),
        sc.observations.clone(),
        n,
    )
    .unwrap()
    .solve_batch(&start)
    .unwrap();
    let cc = c.uncertainty.covariance.unwrap();
    let ratio = ca[(3, 3)] / cc[(3, 3)];
    assert!(
        (1.5..=4.0 + 1e-9).contains(&ratio),
        "covariance ratio {ratio}"
    );
}

#[test]
fn per_point_sigma_downweights_the_noisy_points() {
    // Every other point gets 3 px extra noise; telling the solver so (σ factor 10) must
    // give a better estimate than treating all points alike.
    let sc = scene(3, 30, 0.3);
    let mut rng = Pcg64::seed_from_u64(11);
    let noise = Normal::new(0.0, 3.0).unwrap();
    let noisy: Vec<EdgeObservation> = sc
        .observations
        .iter()
        .map(|o| {
            let mut o = o.clone();
            for p in o.points.iter_mut().step_by(2) {
                *p += Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng));
            }
            o
        })
        .collect();
    let weighted: Vec<EdgeObservation> = noisy
        .iter()
        .map(|o| EdgeObservation {
            sigma_scale: (0..o.points.len())
                .map(|i| if i % 2 == 0 { 10.0 } else { 1.0 })
                .collect(),
            ..o.clone()
        })
        .collect();
    let n = sc.truth.wafers.len();
    let err = |obs: Vec<EdgeObservation>| {
        let slam = SlamMot::new(sc.config.clone(), sc.encoders.clone(), obs, n).unwrap();
        let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
        let d: f64 = sol
            .state
            .wafers
            .iter()
            .zip(&sc.truth.wafers)
            .map(|(a, b)| (a - b).fixed_rows::<3>(0).norm_squared())
            .sum();
        (d / n as f64).sqrt() + se3_minus(&sol.state.base, &sc.truth.base).norm()
    };
    let (plain, with_scale) = (err(noisy), err(weighted));
    assert!(
        with_scale < 0.6 * plain,
        "weighted {with_scale} vs plain {plain}"
    );
}

#[test]
fn bad_sigma_scales_are_rejected() {
    let sc = scene(1, 5, 0.3);
    let n = sc.truth.wafers.len();
    let m = sc.observations[0].points.len();
    // Wrong length, NaN, zero, negative.
    for bad in [
        vec![1.0; m + 1],
        vec![f64::NAN; m],
        vec![0.0; m],
        vec![-1.0; m],
    ] {
        let mut obs = sc.observations.clone();
        obs[0].sigma_scale = bad;
        assert!(SlamMot::new(sc.config.clone(), sc.encoders.clone(), obs, n).is_err());
    }
}

/// The edge residual of observation `obs` of scene `sc` (σ 0.5 px, identity mount, zero
/// fixed offsets and link corrections); `extended` adds the joint-noise and mount blocks.
fn test_edge_residual(
    sc: &Scene,
    obs: &EdgeObservation,
    offset_joints: Vec<usize>,
    extended: bool,
    link_idx: Vec<usize>,
) -> EdgeResidual {
    let cfg = &sc.config;
    EdgeResidual {
        k: cfg.k,
        params: cfg.robot_params,
        geometry: cfg.geometry,
        q_enc: sc.encoders[obs.frame],
        fixed_offsets: Joints::zeros(),
        offset_joints,
        rim: obs.rim,
        points: obs.points.clone(),
        sigma: 0.5,
        angles: None,
        joint_noise: extended,
        fixed_mount: Isometry3::identity(),
        mount_block: extended,
        fixed_links: [0.0; 3],
        link_idx,
    }
}

#[test]
fn edge_residual_jacobians_match_finite_differences() {
    use autoteach_geometry::lie::se3_plus;
    let sc = scene(6, 4, 0.3);
    let obs = &sc.observations[3];
    let res = test_edge_residual(&sc, obs, vec![0, 1, 3], false, Vec::new());
    let base = se3_to_params(&sc.truth.base).to_vec();
    let offs = [vec![0.001], vec![0.002], vec![-0.003]];
    let w = sc.truth.wafers[obs.wafer].as_slice().to_vec();
    let eval = |b: &[f64], o: &[Vec<f64>; 3], w: &[f64], jac: Option<&mut [DMatrix<f64>]>| {
        let mut r = vec![0.0; res.dim()];
        res.evaluate(&[b, &o[0], &o[1], &o[2], w], &mut r, jac)
            .unwrap();
        r
    };
    let n = res.dim();
    let mut jac = vec![
        DMatrix::zeros(n, 6),
        DMatrix::zeros(n, 1),
        DMatrix::zeros(n, 1),
        DMatrix::zeros(n, 1),
        DMatrix::zeros(n, 5),
    ];
    let r0 = eval(&base, &offs, &w, Some(&mut jac));
    let h = 1e-7;
    let close = |fd: f64, an: f64, what: &str| {
        assert!(
            (fd - an).abs() < 1e-3 * (1.0 + an.abs()),
            "{what}: {fd} vs {an}"
        )
    };
    for m in 0..6 {
        let mut d = nalgebra::Vector6::zeros();
        d[m] = h;
        let b2 = se3_to_params(&se3_plus(&sc.truth.base, &d)).to_vec();
        let b3 = se3_to_params(&se3_plus(&sc.truth.base, &(-d))).to_vec();
        let r1 = eval(&b2, &offs, &w, None);
        let r2 = eval(&b3, &offs, &w, None);
        for i in 0..n {
            close((r1[i] - r2[i]) / (2.0 * h), jac[0][(i, m)], "base");
        }
    }
    for j in 0..3 {
        let mut o2 = offs.clone();
        o2[j][0] += h;
        let r1 = eval(&base, &o2, &w, None);
        for i in 0..n {
            close((r1[i] - r0[i]) / h, jac[1 + j][(i, 0)], "offset");
        }
    }
}

#[test]
fn mount_and_link_jacobians_match_finite_differences() {
    use autoteach_geometry::lie::se3_plus;
    let sc = scene(6, 4, 0.3);
    let obs = &sc.observations[5];
    let res = test_edge_residual(&sc, obs, vec![1], true, vec![0, 1, 2]);
    let mount = Isometry3::from_parts(
        Translation3::new(0.002, -0.001, 0.003),
        UnitQuaternion::from_euler_angles(0.01, -0.02, 0.005),
    );
    let vals: Vec<Vec<f64>> = vec![
        se3_to_params(&sc.truth.base).to_vec(),
        vec![0.002],
        sc.truth.wafers[obs.wafer].as_slice().to_vec(),
        vec![1e-4, -2e-4, 5e-5, 1e-5],
        se3_to_params(&mount).to_vec(),
        vec![0.001, -0.002, 0.0015],
    ];
    let n = res.dim();
    let eval = |v: &[Vec<f64>], jac: Option<&mut [DMatrix<f64>]>| {
        let p: Vec<&[f64]> = v.iter().map(|x| x.as_slice()).collect();
        let mut r = vec![0.0; n];
        res.evaluate(&p, &mut r, jac).unwrap();
        r
    };
    let dims = [6usize, 1, 5, 4, 6, 3];
    let mut jac: Vec<DMatrix<f64>> = dims.iter().map(|&d| DMatrix::zeros(n, d)).collect();
    eval(&vals, Some(&mut jac));
    let h = 1e-7;
    for (blk, &dim) in dims.iter().enumerate() {
        for c in 0..dim {
            let (mut up, mut dn) = (vals.clone(), vals.clone());
            if blk == 0 || blk == 4 {
                let mut d = nalgebra::Vector6::zeros();
                d[c] = h;
                let x = se3_from_params(&vals[blk]);
                up[blk] = se3_to_params(&se3_plus(&x, &d)).to_vec();
                dn[blk] = se3_to_params(&se3_plus(&x, &(-d))).to_vec();
            } else {
                up[blk][c] += h;
                dn[blk][c] -= h;
            }
            let (r1, r2) = (eval(&up, None), eval(&dn, None));
            for (i, (a, b)) in r1.iter().zip(&r2).enumerate() {
                let fd = (a - b) / (2.0 * h);
                let an = jac[blk][(i, c)];
                assert!(
                    (fd - an).abs() < 1e-3 * (1.0 + an.abs()),
                    "block {blk} col {c} row {i}: {fd} vs {an}"
                );
            }
        }
    }
}

/// Solves a 20-frame scene with `edit` applied to its configuration, asserts that no
/// covariance is reported and that the unobservable message names one of `names`.
fn assert_reported_unobservable(edit: impl FnOnce(&mut SlamMotConfig), names: [&str; 2]) {
    let sc = scene(2, 20, 0.3);
    let mut cfg = sc.config.clone();
    edit(&mut cfg);
    let slam = SlamMot::new(
        cfg,
        sc.encoders.clone(),
        sc.observations.clone(),
        sc.truth.wafers.len(),
    )
    .unwrap();
    let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
    assert!(sol.uncertainty.covariance.is_none());
    let msg = sol.uncertainty.unobservable.unwrap();
    assert!(names.iter().any(|n| msg.contains(n)), "{msg}");
}

#[test]
fn mount_with_a_free_base_is_reported_unobservable() {
    // All joint axes are vertical: a mount correction and the base pose trade off, so the
    // session cannot constrain T_ec together with T_wb.
    assert_reported_unobservable(|c| c.estimate_mount = true, ["camera mount", "base pose"]);
}

#[test]
fn link_lengths_are_recovered_within_three_sigma() {
    // The elbow and blade-2 lengths change the camera path as the joints move: observable.
    let sc = scene(4, 40, 0.3);
    let mut cfg = sc.config.clone();
    cfg.estimate_links = vec![1, 2];
    let truth_links = [0.0, 0.0015, -0.001];
    let mut scene_cfg = sc.config.clone();
    scene_cfg.robot_params.l2 -= truth_links[1];
    scene_cfg.robot_params.l4 -= truth_links[2];
    cfg.robot_params = scene_cfg.robot_params;
    let slam = SlamMot::new(
        cfg,
        sc.encoders.clone(),
        sc.observations.clone(),
        sc.truth.wafers.len(),
    )
    .unwrap();
    let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
    let cov = sol.uncertainty.covariance.clone().expect("observable");
    let n = cov.nrows();
    for (k, l) in [1usize, 2].iter().enumerate() {
        let err = sol.state.links[*l] - truth_links[*l];
        let sd = cov[(n - 2 + k, n - 2 + k)].sqrt();
        assert!(err.abs() < 4.0 * sd && sd < 1e-3, "link {l}: {err} vs {sd}");
    }
}

#[test]
fn free_camera_mode_recovers_offsets_and_wafers_with_the_motion_factor() {
    let sc = scene(1, 40, 0.3);
    let mut cfg = sc.config.clone();
    cfg.free_camera = Some(FreeCamera {
        motion_sigma: [2e-5, 2e-5, 2e-5, 2e-5, 2e-5, 2e-5],
        odometry: Vec::new(),
        odometry_sigma: [1.0; 6],
        calibration_prior: Some((
            perturbed(&sc.truth).base,
            Joints::zeros(),
            PriorSigmas::default(),
        )),
    });
    let slam = SlamMot::new(
        cfg,
        sc.encoders.clone(),
        sc.observations.clone(),
        sc.truth.wafers.len(),
    )
    .unwrap();
    let sol = slam.solve_batch(&perturbed(&sc.truth)).unwrap();
    // The elbow offset is fixed by the relative motions; every estimate lies within 3σ of
    // the truth (the θ4 offset is only weakly constrained by relative motion: its σ stays
    // close to the prior's, and that is what the covariance reports).
    let cov = sol
        .uncertainty
        .covariance
        .clone()
        .expect("the prior makes it observable");
    for (i, &j) in sc.config.estimate_offsets.iter().enumerate() {
        let err = sol.state.offsets[j] - sc.truth.offsets[j];
        let sd = cov[(6 + i, 6 + i)].sqrt();
        assert!(err.abs() < 3.0 * sd, "offset {j}: {err} vs {sd}");
    }
    let err2 = sol.state.offsets[1] - sc.truth.offsets[1];
    assert!(err2.abs() < 5e-4, "elbow offset {err2}");
    for (w_est, w_true) in sol.state.wafers.iter().zip(&sc.truth.wafers) {
        assert!(
            (w_est - w_true).fixed_rows::<3>(0).norm() < 5e-4,
            "{w_est} vs {w_true}"
        );
    }
    // The free poses follow the true camera path.
    let robot = WaferRobot {
        params: sc.config.robot_params,
        base: sc.truth.base,
    };
    for (f, q) in sc.encoders.iter().enumerate() {
        let truth = robot.camera_pose(&(q - sc.truth.offsets));
        let d = se3_minus(&sol.camera_poses[f], &truth);
        assert!(d.norm() < 2e-3, "frame {f}: {d}");
    }
    // Sliding windows of 5 frames use the same factors.
    let hist = slam
        .solve_sliding_window(&perturbed(&sc.truth), 5, &PriorSigmas::default())
        .unwrap();
    assert_eq!(hist.len(), 8);
    let last = &hist[hist.len() - 1].state;
    // The windows gain information on the elbow offset (σ below half the 2° prior; short
    // windows of relative motions carry little of it) and
    // their estimate lies within 3σ of the truth.
    let sd = hist[hist.len() - 1].std[7];
    let err = last.offsets[1] - sc.truth.offsets[1];
    assert!(sd < 0.5 * PriorSigmas::default().offset, "window σ {sd}");
    assert!(
        err.abs() < 3.0 * sd,
        "window elbow offset error {err} vs σ {sd}"
    );
}

#[test]
fn free_camera_rejects_chain_only_options() {
    let sc = scene(1, 4, 0.3);
    let mut cfg = sc.config.clone();
    cfg.free_camera = Some(FreeCamera {
        motion_sigma: [1e-4; 6],
        odometry: Vec::new(),
        odometry_sigma: [1.0; 6],
        calibration_prior: None,
    });
    cfg.estimate_mount = true;
    assert!(SlamMot::new(cfg, sc.encoders.clone(), sc.observations.clone(), 5).is_err());
}

#[test]
fn lift_offset_with_free_base_is_reported_unobservable() {
    assert_reported_unobservable(
        |c| c.estimate_offsets = vec![1, 3, 4],
        ["lift zero offset", "base pose"],
    );
}

#[test]
fn a_wafer_barely_seen_in_one_window_does_not_break_the_sliding_window() {
    // Wafer 2 is seen only once, by three edge points (fewer than its five parameters):
    // its window cannot fix it from the data, the entry prior keeps the window's
    // posterior defined, and the batch reports the wafer as unobservable.
    let sc = scene(1, 20, 0.3);
    let mut obs: Vec<EdgeObservation> = sc
        .observations
        .iter()
        .filter(|o| o.wafer != 2)
        .cloned()
        .collect();
    let mut one = sc
        .observations
        .iter()
        .find(|o| o.wafer == 2 && o.frame == 12)
        .cloned()
        .expect("wafer 2 is seen in frame 12");
    one.points.truncate(3);
    obs.push(one);
    let slam = SlamMot::new(sc.config.clone(), sc.encoders.clone(), obs, 5).unwrap();
    let start = perturbed(&sc.truth);
    let hist = slam
        .solve_sliding_window(&start, 5, &PriorSigmas::default())
        .expect("the entry prior keeps every window's posterior defined");
    assert_eq!(hist.len(), 4);
    for h in &hist {
        assert!(h.std.iter().all(|v| v.is_finite() && *v > 0.0));
    }
    // The window moved wafer 2 by no more than a few prior widths.
    let moved = (hist[3].state.wafers[2] - start.wafers[2]).abs();
    assert!(moved.fixed_rows::<3>(0).max() < 0.06, "{moved}");
    let sol = slam.solve_batch(&hist[3].state).unwrap();
    assert!(sol.uncertainty.covariance.is_none());
    assert!(sol.uncertainty.unobservable.is_some());
}

#[test]
fn sliding_window_converges_toward_the_batch() {
    let sc = scene(3, 40, 0.3);
    let slam = SlamMot::new(
        sc.config.clone(),
        sc.encoders.clone(),
        sc.observations.clone(),
        sc.truth.wafers.len(),
    )
    .unwrap();
    // Start from a nominal installation: base within a few millimetres, offsets zero.
    let mut init = sc.truth.clone();
    init.base = Isometry3::from_parts(
        Translation3::from(sc.truth.base.translation.vector + Vector3::new(0.002, -0.0015, 0.001)),
        sc.truth.base.rotation * UnitQuaternion::from_euler_angles(0.0008, -0.0006, 0.0),
    );
    init.offsets = Joints::zeros();
    for w in init.wafers.iter_mut().skip(1) {
        w[3] = 0.0;
        w[4] = 0.0;
    }
    let hist = slam
        .solve_sliding_window(&init, 5, &PriorSigmas::default())
        .unwrap();
    assert_eq!(hist.len(), 8);
    let last = &hist.last().unwrap().state;
    let err0 = se3_minus(&init.base, &sc.truth.base)
        .fixed_rows::<3>(3)
        .norm();
    let err1 = se3_minus(&last.base, &sc.truth.base)
        .fixed_rows::<3>(3)
        .norm();
    eprintln!("sliding window: base translation error {err0} -> {err1}");
    assert!(err1 < 0.2 * err0, "{err1} vs {err0}");
    assert!(hist.last().unwrap().std[3] < hist[0].std[3]);
}

#[test]
fn no_observations_is_a_clear_error() {
    let sc = scene(4, 5, 0.3);
    let err = SlamMot::new(sc.config.clone(), sc.encoders.clone(), vec![], 5).unwrap_err();
    assert!(err.to_string().contains("no wafer edge"), "{err}");
}

#[test]
fn resolution_grows_when_the_camera_is_closer() {
    let sc = scene(5, 3, 0.3);
    let g = sc.config.geometry;
    let w = sc.truth.wafers[1];
    let far = Isometry3::from_parts(
        Translation3::new(-0.6, 0.0, 0.06),
        UnitQuaternion::from_matrix(&Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0)),
    );
    let mut near = far;
    near.translation.vector.x = -0.45;
    let rf = theoretical_resolution(&sc.config.k, &far, &w, &g, 90).unwrap();
    let rn = theoretical_resolution(&sc.config.k, &near, &w, &g, 90).unwrap();
    for m in 0..5 {
        assert!(rn[m] > rf[m], "{m}: {rn:?} vs {rf:?}");
    }
    // Lateral motion of 1 mm at ~0.6 m with f = 1000 px: ≈ 1000/600 px.
    assert!((rf[1] - 1000.0 / 600.0).abs() < 0.4, "{rf:?}");
}
