//! Tests of CPD against closed-form truth and between its own evaluation strategies.

use super::*;
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

fn cloud(m: usize, d: usize, seed: u64) -> DMatrix<f64> {
    let mut rng = Pcg64::seed_from_u64(seed);
    DMatrix::from_fn(m, d, |_, _| rng.random::<f64>() * 2.0 - 1.0)
}

fn apply(y: &DMatrix<f64>, b: &DMatrix<f64>, t: &DVector<f64>) -> DMatrix<f64> {
    let mut x = y * b.transpose();
    for mut row in x.row_iter_mut() {
        row += t.transpose();
    }
    x
}

fn rot2(a: f64) -> DMatrix<f64> {
    DMatrix::from_row_slice(2, 2, &[a.cos(), -a.sin(), a.sin(), a.cos()])
}

#[test]
fn rigid_recovers_similarity_2d_and_3d() {
    let y = cloud(60, 2, 1);
    let r = rot2(0.4);
    let t = DVector::from_vec(vec![0.3, -0.7]);
    let x = apply(&y, &(&r * 1.3), &t);
    let fit = rigid(&x, &y, &RigidOptions::default()).unwrap();
    assert!((&fit.rotation - &r).amax() < 1e-6, "{}", fit.rotation);
    assert!((fit.scale - 1.3).abs() < 1e-6);
    assert!((&fit.translation - &t).amax() < 1e-6);
    assert!(fit.converged);

    let y = cloud(80, 3, 2);
    let r3 = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.5)
        * Rotation3::from_euler_angles(0.2, -0.1, 0.3);
    let r = DMatrix::from_column_slice(3, 3, r3.matrix().as_slice());
    let t = DVector::from_vec(vec![0.1, 0.2, -0.3]);
    let x = apply(&y, &r, &t);
    let opts = RigidOptions {
        scale: false,
        ..Default::default()
    };
    let fit = rigid(&x, &y, &opts).unwrap();
    assert_eq!(fit.scale, 1.0);
    assert!((&fit.rotation - &r).amax() < 1e-6);
    assert!((&fit.transformed - &x).amax() < 1e-6);
}

#[test]
fn affine_recovers_known_map() {
    let y = cloud(70, 2, 3);
    let b = DMatrix::from_row_slice(2, 2, &[1.2, 0.3, -0.1, 0.8]);
    let t = DVector::from_vec(vec![0.2, 0.1]);
    let x = apply(&y, &b, &t);
    let fit = affine(&x, &y, &AffineOptions::default()).unwrap();
    assert!((&fit.matrix - &b).amax() < 1e-6, "{}", fit.matrix);
    assert!((&fit.translation - &t).amax() < 1e-6);
}

#[test]
fn outlier_weight_keeps_rigid_fit_with_clutter() {
    let y = cloud(80, 2, 4);
    let r = rot2(-0.3);
    let t = DVector::from_vec(vec![0.4, 0.2]);
    let clean = apply(&y, &r, &t);
    let clutter = cloud(60, 2, 5) * 3.0;
    let x = DMatrix::from_fn(140, 2, |i, d| {
        if i < 80 {
            clean[(i, d)]
        } else {
            clutter[(i - 80, d)]
        }
    });
    let mut o = RigidOptions::default();
    o.cpd.w = 0.5;
    o.cpd.tolerance = 1e-10;
    o.cpd.max_iterations = 500;
    let fit = rigid(&x, &y, &o).unwrap();
    assert!(
        (&fit.rotation - &r).amax() < 1e-3,
        "{} after {} iterations, sigma2 {}",
        fit.rotation,
        fit.iterations,
        fit.sigma2
    );
    assert!((&fit.translation - &t).amax() < 1e-3);
    // Without the outlier component the clutter pulls the scale up.
    let plain = rigid(
        &x,
        &y,
        &RigidOptions {
            cpd: CpdOptions {
                w: 0.0,
                ..o.cpd.clone()
            },
            ..o.clone()
        },
    )
    .unwrap();
    assert!((plain.scale - 1.0).abs() > (fit.scale - 1.0).abs());
}

#[test]
fn posterior_matrix_is_consistent_with_sums() {
    let y = cloud(30, 2, 6);
    let x = apply(&y, &rot2(0.2), &DVector::from_vec(vec![0.1, 0.0])) + cloud(30, 2, 7) * 0.01;
    let mut o = RigidOptions::default();
    o.cpd.return_p = true;
    o.cpd.w = 0.1;
    o.cpd.max_iterations = 3;
    let fit = rigid(&x, &y, &o).unwrap();
    let p = fit.p.unwrap();
    assert_eq!(p.shape(), (30, 30));
    // Column sums are ≤ 1 (the rest is the outlier component), all entries in [0, 1].
    for c in p.column_iter() {
        let s = c.sum();
        assert!(s > 0.0 && s < 1.0, "{s}");
    }
}

#[test]
fn truncated_e_step_matches_dense() {
    // A spread-out set with small σ² so the grid prunes.
    let mut rng = Pcg64::seed_from_u64(8);
    let x: Vec<[f64; 2]> = (0..3000)
        .map(|_| [rng.random::<f64>() * 50.0, rng.random::<f64>() * 50.0])
        .collect();
    let normal = Normal::new(0.0, 0.3).unwrap();
    let mut t: Vec<[f64; 2]> = x
        .iter()
        .map(|p| {
            [
                p[0] + normal.sample(&mut rng),
                p[1] + normal.sample(&mut rng),
            ]
        })
        .collect();
    t.truncate(2500);
    // A far-away source point (no neighbours) exercises the exact fallback.
    t.push([500.0, 500.0]);
    for w in [0.0, 0.2] {
        let mut dense = estep::EStepWork::<2>::new(x.len(), t.len(), EStep::Dense);
        let mut grid = estep::EStepWork::<2>::new(x.len(), t.len(), EStep::Truncated);
        let a = dense.run(&x, &t, 0.25, w);
        let b = grid.run(&x, &t, 0.25, w);
        assert!((a.np - b.np).abs() < 1e-6 * a.np, "{} vs {}", a.np, b.np);
        for j in 0..t.len() {
            assert!(
                (a.p1[j] - b.p1[j]).abs() < 1e-6,
                "p1[{j}] {} vs {}",
                a.p1[j],
                b.p1[j]
            );
            for d in 0..2 {
                assert!((a.px[j][d] - b.px[j][d]).abs() < 1e-4);
            }
        }
        for n in 0..x.len() {
            assert!((a.pt1[n] - b.pt1[n]).abs() < 1e-6);
        }
    }
}

#[test]
fn nonrigid_fits_smooth_deformation_and_low_rank_agrees() {
    let y = cloud(300, 2, 9);
    let x = DMatrix::from_fn(300, 2, |i, d| {
        let (a, b) = (y[(i, 0)], y[(i, 1)]);
        if d == 0 {
            a + 0.15 * (1.5 * b).sin()
        } else {
            b + 0.1 * a * a
        }
    });
    let opts = NonrigidOptions {
        beta: 1.0,
        lambda: 1.0,
        ..Default::default()
    };
    let full = nonrigid(&x, &y, &opts).unwrap();
    let rms = |t: &DMatrix<f64>| ((t - &x).norm_squared() / 300.0).sqrt();
    assert!(
        rms(&full.transformed) < 0.01,
        "full rms {}",
        rms(&full.transformed)
    );
    assert!(full.energy > 0.0 && full.rank.is_none());
    let lr = nonrigid(
        &x,
        &y,
        &NonrigidOptions {
            low_rank: Some(40),
            ..opts.clone()
        },
    )
    .unwrap();
    assert_eq!(lr.rank, Some(40));
    assert!(
        rms(&lr.transformed) < 0.01,
        "low-rank rms {}",
        rms(&lr.transformed)
    );
    assert!((&lr.transformed - &full.transformed).amax() < 0.02);
}

#[test]
fn bad_input_is_rejected() {
    let y = cloud(10, 2, 10);
    let o = RigidOptions::default();
    // Fewer points than dimensions + 1.
    let two = cloud(2, 2, 11);
    assert!(matches!(
        rigid(&two, &y, &o),
        Err(DetectError::TooFewPoints {
            got: 2,
            needed: 3,
            ..
        })
    ));
    // Identical points.
    let same = DMatrix::from_element(10, 2, 0.5);
    assert!(matches!(
        rigid(&same, &y, &o),
        Err(DetectError::Degenerate { .. })
    ));
    // NaN.
    let mut nan = y.clone();
    nan[(4, 1)] = f64::NAN;
    assert!(matches!(
        rigid(&nan, &y, &o),
        Err(DetectError::NonFinite {
            what: "X",
            index: 4,
            ..
        })
    ));
    // Mismatched and unsupported dimensions.
    assert!(matches!(
        rigid(&cloud(10, 3, 12), &y, &o),
        Err(DetectError::WrongLength { .. })
    ));
    assert!(matches!(
        rigid(&cloud(10, 4, 12), &cloud(10, 4, 13), &o),
        Err(DetectError::WrongLength { .. })
    ));
    // Invalid options.
    let mut bad = o.clone();
    bad.cpd.w = 1.0;
    assert!(matches!(
        rigid(&y, &y, &bad),
        Err(DetectError::InvalidParameter { what: "w", .. })
    ));
    bad.cpd.w = 0.0;
    bad.cpd.sigma2 = Some(0.0);
    assert!(matches!(
        rigid(&y, &y, &bad),
        Err(DetectError::InvalidParameter { what: "sigma2", .. })
    ));
    let nr = NonrigidOptions {
        beta: -1.0,
        ..Default::default()
    };
    assert!(matches!(
        nonrigid(&y, &y, &nr),
        Err(DetectError::InvalidParameter { what: "beta", .. })
    ));
    let nr = NonrigidOptions {
        low_rank: Some(11),
        ..Default::default()
    };
    assert!(matches!(
        nonrigid(&y, &y, &nr),
        Err(DetectError::InvalidParameter {
            what: "low_rank",
            ..
        })
    ));
    // Above the full-rank limit the message names the limit and the low-rank option.
    let big = DMatrix::from_fn(MAX_FULL_RANK_POINTS + 1, 2, |i, d| (i * (d + 1)) as f64);
    let e = nonrigid(&big, &big, &NonrigidOptions::default()).unwrap_err();
    assert!(
        e.to_string().contains(&format!(
            "must stay within {MAX_FULL_RANK_POINTS} source points; set low_rank="
        )),
        "{e}"
    );
    // Collinear Y: the affine map is undetermined.
    let line = DMatrix::from_fn(10, 2, |i, d| if d == 0 { i as f64 } else { 2.0 * i as f64 });
    assert!(matches!(
        affine(&y, &line, &AffineOptions::default()),
        Err(DetectError::Degenerate { .. })
    ));
}

/// The full-rank fit (CG M-step) equals the fit with the direct Cholesky M-step of every
/// iteration, and the fast Gauss transform E-step (boxes a few σ wide in the middle range)
/// gives the same low-rank fit as the dense one.
#[test]
fn cg_and_fast_gauss_fits_match_direct_and_dense() {
    let n = 600;
    let mut rng = Pcg64::seed_from_u64(21);
    let y = DMatrix::from_fn(n, 2, |_, _| rng.random::<f64>() * 6.0);
    let x = DMatrix::from_fn(n, 2, |i, d| {
        let v = if d == 0 {
            (0.5 * y[(i, 1)]).sin()
        } else {
            (0.4 * y[(i, 0)]).cos()
        };
        y[(i, d)] + 0.3 * v
    });
    let opts = NonrigidOptions {
        beta: 1.5,
        lambda: 2.0,
        ..Default::default()
    };
    let fit = nonrigid(&x, &y, &opts).unwrap();
    // Reference: the same EM with the dense Cholesky M-step.
    let xs = points::<2>(&x, "X").unwrap();
    let ys = points::<2>(&y, "Y").unwrap();
    let g = lowrank::kernel_matrix(&ys, opts.beta);
    let mut em = Em::new(&xs, &ys, &opts.cpd).unwrap();
    let mut ty = ys.clone();
    for _ in 0..fit.iterations {
        let e = em.e_step(&xs, &ty, false).unwrap();
        let f = DMatrix::from_fn(n, 2, |i, d| e.px[i][d] - e.p1[i] * ys[i][d]);
        let w = solve_full(&g, &e.p1, &f, opts.lambda * em.sigma2).unwrap();
        let gw = &g * &w;
        for (i, t) in ty.iter_mut().enumerate() {
            *t = [ys[i][0] + gw[(i, 0)], ys[i][1] + gw[(i, 1)]];
        }
        let c = mean(&xs);
        let (mut xpx, mut trpxt, mut tpt) = (0.0, 0.0, 0.0);
        for (p, q) in e.pt1.iter().zip(&xs) {
            xpx += p * ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2));
        }
        for ((pxm, p1m), t) in e.px.iter().zip(&e.p1).zip(&ty) {
            for d in 0..2 {
                trpxt += (pxm[d] - p1m * c[d]) * (t[d] - c[d]);
                tpt += p1m * (t[d] - c[d]).powi(2);
            }
        }
        let _ = em.set_sigma2(
            (xpx - 2.0 * trpxt + tpt) / (e.np * 2.0),
            (xpx + tpt) / (e.np * 2.0),
            opts.cpd.tolerance,
        );
    }
    let diff = (&fit.transformed - to_matrix(&ty)).amax();
    assert!(diff < 1e-7, "CG vs direct M-step: {diff:e}");
    assert!(
        (fit.sigma2 - em.sigma2).abs() < 1e-6 * em.sigma2,
        "σ² {:e} vs {:e}",
        fit.sigma2,
        em.sigma2
    );

    let lr = |e_step| {
        let mut o = opts.clone();
        o.low_rank = Some(60);
        o.cpd.e_step = e_step;
        nonrigid(&x, &y, &o).unwrap()
    };
    let (fast, dense) = (lr(EStep::FastGauss), lr(EStep::Dense));
    assert_eq!(fast.iterations, dense.iterations);
    let diff = (&fast.transformed - &dense.transformed).amax();
    assert!(diff < 1e-6, "fast Gauss vs dense E-step: {diff:e}");
}
/// Full-rank non-rigid CPD on the peer benchmark's kind of scene (β = λ = 2 over a 10 × 10
/// square, N = M = 2000), where `Auto` applies `G` by the fast Gauss transform and takes the
/// transform E-step: the same fit as the exact run (stored `G`, every pair) to 1e-6.
#[test]
fn fast_gauss_kernel_fit_matches_exact_fit() {
    let n = 2000;
    let mut rng = Pcg64::seed_from_u64(31);
    let y = DMatrix::from_fn(n, 2, |_, _| rng.random::<f64>() * 10.0);
    let x = DMatrix::from_fn(n, 2, |i, d| {
        let v = if d == 0 {
            (0.5 * y[(i, 1)]).sin()
        } else {
            (0.4 * y[(i, 0)]).cos()
        };
        y[(i, d)] + 0.4 * v + 0.01 * (rng.random::<f64>() - 0.5)
    });
    let ys = points::<2>(&y, "Y").unwrap();
    assert!(pcg::FullSystem::new(&ys, 2.0, false).is_fast());
    let run = |e_step| {
        let mut o = NonrigidOptions::default();
        o.cpd.max_iterations = 30;
        o.cpd.e_step = e_step;
        nonrigid(&x, &y, &o).unwrap()
    };
    let (fast, exact) = (run(EStep::Auto), run(EStep::Dense));
    assert_eq!(fast.iterations, exact.iterations);
    let diff = (&fast.transformed - &exact.transformed).amax();
    assert!(diff < 1e-6, "moved points differ by {diff:e}");
    assert!((fast.sigma2 - exact.sigma2).abs() < 1e-6 * exact.sigma2);
    assert!((fast.energy - exact.energy).abs() < 1e-6 * exact.energy);
}
