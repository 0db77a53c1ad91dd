//! Tests of the ellipse fits against known ellipses, finite differences and Monte-Carlo truth.

use std::f64::consts::PI;

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Vector2, Vector5};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

use super::*;

fn params(e: &Ellipse) -> Vector5<f64> {
    Vector5::new(e.cx, e.cy, e.a, e.b, e.theta)
}

/// Parameter error with θ wrapped modulo π.
fn param_error(fit: &Ellipse, truth: &Ellipse) -> Vector5<f64> {
    let mut d = params(fit) - params(truth);
    d[4] = (d[4] + PI / 2.0).rem_euclid(PI) - PI / 2.0;
    d
}

/// Points of `e` on an arc of `span` radians (eccentric angle) starting at `t0`, with
/// isotropic Gaussian noise `sigma` (pixels).
fn arc(
    e: &Ellipse,
    t0: f64,
    span: f64,
    n: usize,
    sigma: f64,
    rng: &mut Pcg64,
) -> Vec<Vector2<f64>> {
    let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
    e.sample(n, t0, t0 + span)
        .unwrap()
        .into_iter()
        .map(|p| {
            if sigma > 0.0 {
                p + Vector2::new(noise.sample(rng), noise.sample(rng))
            } else {
                p
            }
        })
        .collect()
}

fn truths() -> Vec<Ellipse> {
    vec![
        Ellipse::new(320.0, 240.0, 300.0, 40.0, 0.3).unwrap(),
        Ellipse::new(-50.0, 1000.0, 300.0, 150.0, -1.2).unwrap(),
        Ellipse::new(640.0, 480.0, 300.0, 290.0, 1.5).unwrap(),
        Ellipse::new(10.0, 20.0, 5.0, 2.0, 0.0).unwrap(),
    ]
}

#[test]
fn noiseless_full_and_partial_arcs_are_recovered_exactly() {
    let mut rng = Pcg64::seed_from_u64(1);
    for truth in truths() {
        for span_deg in [360.0, 160.0, 120.0, 90.0, 60.0] {
            for t0 in [0.0, 1.0, 2.5, -2.0] {
                let span = f64::to_radians(span_deg);
                let pts = arc(&truth, t0, span, 100, 0.0, &mut rng);
                for method in [FitMethod::Direct, FitMethod::Geometric] {
                    let fit = fit_ellipse(&pts, method).unwrap();
                    let d = param_error(&fit.ellipse, &truth);
                    let tol = 1e-9 * truth.a;
                    assert!(
                        d.fixed_rows::<4>(0).amax() < tol && d[4].abs() < 1e-9,
                        "{method:?} span {span_deg}° t0 {t0} truth {truth:?}: error {d:?}"
                    );
                    assert!(fit.residual_mean < tol && fit.residual_rms < tol);
                    assert!(fit.converged);
                }
            }
        }
    }
}

#[test]
fn jacobian_matches_finite_differences() {
    let mut rng = Pcg64::seed_from_u64(2);
    for e in [
        Ellipse::new(3.0, -2.0, 7.0, 3.0, 0.7).unwrap(),
        Ellipse::new(0.0, 0.0, 5.0, 4.9, -1.3).unwrap(),
    ] {
        let sc = e.theta.sin_cos();
        for _ in 0..200 {
            // Points inside and outside, away from the centre and the evolute.
            let t = rng.random_range(-PI..PI);
            let off = rng.random_range(-1.0..3.0);
            let p = e.point_at(t)
                + Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)) * off;
            let (r, g) = residual::distance_and_gradient(&e, sc, &p);
            assert!(
                (r - e.orthogonal_distance(&p)).abs() < 1e-12,
                "distance {r} vs {}",
                e.orthogonal_distance(&p)
            );
            // The single-point form (exact foot angle) is the same linearisation.
            let (r1, g1) = residual::point_distance_and_gradient(&e, &p);
            assert!(
                (r1 - r).abs() < 1e-12 && (g1 - g).amax() < 1e-9,
                "{g1} vs {g}"
            );
            for k in 0..5 {
                let h = 1e-6;
                let mut plus = params(&e);
                let mut minus = params(&e);
                plus[k] += h;
                minus[k] -= h;
                let ep = Ellipse {
                    cx: plus[0],
                    cy: plus[1],
                    a: plus[2],
                    b: plus[3],
                    theta: plus[4],
                };
                let em = Ellipse {
                    cx: minus[0],
                    cy: minus[1],
                    a: minus[2],
                    b: minus[3],
                    theta: minus[4],
                };
                let fd = (ep.orthogonal_distance(&p) - em.orthogonal_distance(&p)) / (2.0 * h);
                assert!(
                    (fd - g[k]).abs() < 1e-7,
                    "param {k}: analytic {} vs finite difference {fd}",
                    g[k]
                );
            }
        }
    }
}

#[test]
fn conic_and_sampson_gradients_match_finite_differences() {
    let mut rng = Pcg64::seed_from_u64(9);
    let e = Ellipse::new(0.3, -0.2, 1.4, 0.6, 0.7).unwrap();
    let q = e.conic_coefficients();
    let sc = e.theta.sin_cos();
    for _ in 0..100 {
        let p = e.point_at(rng.random_range(-PI..PI))
            + Vector2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1));
        let (r, g) = residual::distance_and_conic_gradient(
            &e,
            sc,
            &q,
            &p,
            residual::foot(&e, sc, &p).st_ct(),
        );
        assert!((r - e.orthogonal_distance(&p)).abs() < 1e-12);
        // Sampson residual and gradient of the single point, from the normal equations.
        let (_, jtr_s, ssr_s) = residual::accumulate_sampson(&q, &[p]);
        let f = |q: &[f64; 6]| {
            q[0] * p.x * p.x + q[1] * p.x * p.y + q[2] * p.y * p.y + q[3] * p.x + q[4] * p.y + q[5]
        };
        let sampson = |q: &[f64; 6]| {
            let gx = 2.0 * q[0] * p.x + q[1] * p.y + q[3];
            let gy = q[1] * p.x + 2.0 * q[2] * p.y + q[4];
            f(q) / gx.hypot(gy)
        };
        let rs = sampson(&q);
        assert!((rs * rs - ssr_s).abs() < 1e-15);
        for k in 0..6 {
            let h = 1e-7;
            let (mut qp, mut qm) = (q, q);
            qp[k] += h;
            qm[k] -= h;
            let ep = Ellipse::from_coefficients(&qp).unwrap();
            let em = Ellipse::from_coefficients(&qm).unwrap();
            let fd = (ep.orthogonal_distance(&p) - em.orthogonal_distance(&p)) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-6 * (1.0 + g[k].abs()),
                "orthogonal q{k}: {} vs {fd}",
                g[k]
            );
            let fd_s = (sampson(&qp) - sampson(&qm)) / (2.0 * h);
            assert!(
                (fd_s - jtr_s[k] / rs).abs() < 1e-6 * (1.0 + fd_s.abs()),
                "sampson q{k}: {} vs {fd_s}",
                jtr_s[k] / rs
            );
        }
    }
}

/// One Monte-Carlo case: a = 300 px, b in 40..300, random pose, arc 60–160°, 0.5 px noise.
fn random_case(rng: &mut Pcg64, min_span: f64, max_span: f64) -> (Ellipse, Vec<Vector2<f64>>) {
    let b = rng.random_range(40.0..300.0);
    let truth = Ellipse::new(
        rng.random_range(200.0..800.0),
        rng.random_range(200.0..600.0),
        300.0,
        b,
        rng.random_range(-PI / 2.0..PI / 2.0),
    )
    .unwrap();
    let span = f64::to_radians(rng.random_range(min_span..max_span));
    // About one point per pixel of arc length, as an edge detector gives.
    let n = ((truth.a + truth.b) * 0.5 * span) as usize;
    let pts = arc(&truth, rng.random_range(-PI..PI), span, n.max(20), 0.5, rng);
    (truth, pts)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn geometric_fit_beats_direct_fit_on_noisy_partial_arcs() {
    let mut rng = Pcg64::seed_from_u64(3);
    let (mut err_direct, mut err_geom, mut ax_direct, mut ax_geom) =
        (vec![], vec![], vec![], vec![]);
    for _ in 0..300 {
        let (truth, pts) = random_case(&mut rng, 60.0, 160.0);
        let d = fit_ellipse(&pts, FitMethod::Direct).unwrap();
        let g = fit_ellipse(&pts, FitMethod::Geometric).unwrap();
        assert!(g.converged);
        // The geometric fit minimises exactly what it reports.
        assert!(g.residual_rms <= d.residual_rms + 1e-12);
        let cd = param_error(&d.ellipse, &truth);
        let cg = param_error(&g.ellipse, &truth);
        err_direct.push(cd[0].hypot(cd[1]));
        err_geom.push(cg[0].hypot(cg[1]));
        ax_direct.push(cd[2].abs().max(cd[3].abs()));
        ax_geom.push(cg[2].abs().max(cg[3].abs()));
    }
    let (md, mg) = (median(err_direct), median(err_geom));
    let (ad, ag) = (median(ax_direct), median(ax_geom));
    eprintln!(
        "median centre error: direct {md:.3} px, geometric {mg:.3} px; axes {ad:.3} / {ag:.3} px"
    );
    assert!(mg < 0.5 * md, "geometric {mg} vs direct {md}");
    assert!(ag < 0.5 * ad, "geometric axes {ag} vs direct {ad}");
}

#[test]
fn covariance_is_calibrated() {
    let mut rng = Pcg64::seed_from_u64(4);
    let trials = 400;
    let mut nees = Vec::with_capacity(trials);
    for _ in 0..trials {
        let (truth, pts) = random_case(&mut rng, 120.0, 160.0);
        let g = fit_ellipse(&pts, FitMethod::Geometric).unwrap();
        let cov: Matrix5<f64> = g.covariance.unwrap();
        let d = param_error(&g.ellipse, &truth);
        let q = d.dot(&(cov.try_inverse().unwrap() * d));
        nees.push(q);
    }
    let mean = nees.iter().sum::<f64>() / trials as f64;
    eprintln!("mean normalised estimation error squared {mean:.3} (expected 5)");
    // χ²(5) has variance 10: the standard error of the mean of 400 is 0.16.
    assert!((mean - 5.0).abs() < 0.6, "mean NEES {mean}");
}

#[test]
fn near_circle_covariance_stays_finite() {
    // Radial errors with no Fourier component of order 0, 1 or 2 leave the best-fitting
    // ellipse exactly the circle (or near-circle) they perturb, with a non-zero residual.
    let n = 200;
    for b in [100.0, 100.0 - 1e-7] {
        let truth = Ellipse::new(50.0, 60.0, 100.0, b, 0.2).unwrap();
        let pts: Vec<_> = (0..n)
            .map(|i| {
                let t = 2.0 * PI * i as f64 / n as f64;
                let dr = 0.5 * (3.0 * t).cos() + 0.3 * (5.0 * t).sin();
                truth.point_at(t)
                    + residual::foot(&truth, truth.theta.sin_cos(), &truth.point_at(t)).normal * dr
            })
            .collect();
        // Iterated to the exact optimum (the default stops within 0.01σ of it).
        let tight = GeometricFitOptions {
            noise_tolerance: 0.0,
            ..Default::default()
        };
        let g = fit_ellipse_geometric(&pts, None, &tight).unwrap();
        let d = param_error(&g.ellipse, &truth);
        assert!(d.fixed_rows::<4>(0).amax() < 1e-6, "{d:?}");
        let cov = g.covariance.unwrap();
        assert!(cov.iter().all(|v| v.is_finite()));
        assert_eq!(cov[(4, 4)], PI * PI / 12.0);
        assert!((0..4).all(|k| cov[(k, 4)] == 0.0 && cov[(4, k)] == 0.0));
        // Centre of a full circle: var = σ²/Σcos²t = 2σ²/n, with σ̂² = SSR/(n − 5).
        let s2 = g.residual_rms.powi(2) * n as f64 / (n - 5) as f64;
        assert!(
            (cov[(0, 0)] / (2.0 * s2 / n as f64) - 1.0).abs() < 1e-3,
            "var cx {}",
            cov[(0, 0)]
        );
        assert!(cov[(2, 2)] > 0.0 && cov[(3, 3)] > 0.0);
    }
    // A noisy circle whose fit is a slightly flattened ellipse: θ is (weakly) determined and
    // its variance comes from the data; it never exceeds the uniform bound.
    let mut rng = Pcg64::seed_from_u64(5);
    for _ in 0..20 {
        let truth = Ellipse::new(50.0, 60.0, 100.0, 100.0, 0.0).unwrap();
        let pts = arc(&truth, 0.0, 2.0 * PI, 100, 0.5, &mut rng);
        let cov = fit_ellipse(&pts, FitMethod::Geometric)
            .unwrap()
            .covariance
            .unwrap();
        assert!(cov.iter().all(|v| v.is_finite()) && cov[(4, 4)] <= PI * PI / 12.0);
    }
}

#[test]
fn five_points_interpolate_without_covariance() {
    let truth = Ellipse::new(1.0, 2.0, 6.0, 3.0, 0.4).unwrap();
    let pts: Vec<_> = [0.1, 1.0, 2.0, 3.5, 5.0]
        .iter()
        .map(|&t| truth.point_at(t))
        .collect();
    for method in [FitMethod::Direct, FitMethod::Geometric] {
        let fit = fit_ellipse(&pts, method).unwrap();
        assert!(param_error(&fit.ellipse, &truth).amax() < 1e-9);
        assert!(fit.covariance.is_none());
    }
}

fn both_fail(pts: &[Vector2<f64>], check: impl Fn(&DetectError) -> bool) {
    for method in [FitMethod::Direct, FitMethod::Geometric] {
        match fit_ellipse(pts, method) {
            Ok(fit) => panic!("{method:?} fabricated an ellipse {:?}", fit.ellipse),
            Err(e) => assert!(check(&e), "{method:?}: unexpected error {e}"),
        }
    }
}

#[test]
fn bad_inputs_are_errors() {
    let truth = Ellipse::new(0.0, 0.0, 10.0, 5.0, 0.3).unwrap();
    let five = truth.sample(5, 0.0, 5.0).unwrap();
    // Four points.
    both_fail(&five[..4], |e| {
        matches!(
            e,
            DetectError::TooFewPoints {
                got: 4,
                needed: 5,
                ..
            }
        )
    });
    both_fail(&[], |e| {
        matches!(
            e,
            DetectError::TooFewPoints {
                got: 0,
                needed: 5,
                ..
            }
        )
    });
    // NaN and infinity.
    let mut nan = five.clone();
    nan[2].y = f64::NAN;
    both_fail(&nan, |e| {
        matches!(e, DetectError::NonFinite { index: 2, .. })
    });
    nan[2].y = f64::INFINITY;
    both_fail(&nan, |e| {
        matches!(e, DetectError::NonFinite { index: 2, .. })
    });
    // Collinear points.
    let line: Vec<_> = (0..20)
        .map(|i| Vector2::new(1.0 + 2.0 * i as f64, -3.0 + 0.5 * i as f64))
        .collect();
    both_fail(&line, |e| matches!(e, DetectError::Degenerate { .. }));
    // All points coincide.
    both_fail(&[Vector2::new(3.0, 4.0); 10], |e| {
        matches!(e, DetectError::Degenerate { .. })
    });
    // Four distinct points repeated.
    let dup: Vec<_> = five[..4].iter().cycle().take(12).copied().collect();
    both_fail(&dup, |e| matches!(e, DetectError::Degenerate { .. }));
    // Four collinear points and one off the line: a pencil of line pairs fits.
    let mut four_on_line: Vec<_> = line[..4].to_vec();
    four_on_line.push(Vector2::new(0.0, 10.0));
    both_fail(&four_on_line, |e| {
        matches!(e, DetectError::Degenerate { .. })
    });
    // A hyperbola: x²/4 − y² = 1, both branches and one branch.
    let hyp: Vec<_> = (-10..=10)
        .flat_map(|i| {
            let s = i as f64 * 0.2;
            [
                Vector2::new(2.0 * s.cosh(), s.sinh()),
                Vector2::new(-2.0 * s.cosh(), s.sinh()),
            ]
        })
        .collect();
    both_fail(&hyp, |e| matches!(e, DetectError::Degenerate { .. }));
    let branch: Vec<_> = (-15..=15)
        .map(|i| Vector2::new(5.0 + 2.0 * (i as f64 * 0.1).cosh(), (i as f64 * 0.1).sinh()))
        .collect();
    both_fail(&branch, |e| matches!(e, DetectError::Degenerate { .. }));
    // Two crossing lines.
    let cross: Vec<_> = (-5..=5)
        .flat_map(|i| {
            [
                Vector2::new(i as f64, 0.5 * i as f64),
                Vector2::new(i as f64, -2.0 * i as f64 + 1.0),
            ]
        })
        .collect();
    both_fail(&cross, |e| matches!(e, DetectError::Degenerate { .. }));
}

#[test]
fn noisy_short_arcs_are_not_mistaken_for_hyperbolas() {
    // The hyperbola test must not reject genuine ellipse arcs, even short, flat and noisy ones.
    let mut rng = Pcg64::seed_from_u64(6);
    for _ in 0..300 {
        let b = rng.random_range(40.0..300.0);
        let truth = Ellipse::new(0.0, 0.0, 300.0, b, rng.random_range(-1.5..1.5)).unwrap();
        let span = f64::to_radians(rng.random_range(30.0..90.0));
        let pts = arc(&truth, rng.random_range(-PI..PI), span, 60, 2.0, &mut rng);
        fit_ellipse(&pts, FitMethod::Direct).unwrap();
    }
}

#[test]
fn geometric_options_and_initial_guess() {
    let truth = Ellipse::new(5.0, 6.0, 30.0, 20.0, 0.5).unwrap();
    let pts = truth.sample(50, 0.0, 3.0).unwrap();
    let start = Ellipse::new(4.0, 7.0, 28.0, 22.0, 0.3).unwrap();
    let fit = fit_ellipse_geometric(&pts, Some(start), &GeometricFitOptions::default()).unwrap();
    assert!(param_error(&fit.ellipse, &truth).amax() < 1e-9);
    assert!(fit.iterations > 0);
    // One iteration is not enough from there.
    let one = GeometricFitOptions {
        max_iterations: 1,
        ..Default::default()
    };
    let fit = fit_ellipse_geometric(&pts, Some(start), &one).unwrap();
    assert!(!fit.converged && fit.iterations == 1);
    let bad = Ellipse {
        cx: 0.0,
        cy: 0.0,
        a: -1.0,
        b: 1.0,
        theta: 0.0,
    };
    assert!(matches!(
        fit_ellipse_geometric(&pts, Some(bad), &GeometricFitOptions::default()),
        Err(DetectError::InvalidParameter { .. })
    ));
    let zero = GeometricFitOptions {
        max_iterations: 0,
        ..Default::default()
    };
    assert!(matches!(
        fit_ellipse_geometric(&pts, None, &zero),
        Err(DetectError::InvalidParameter { .. })
    ));
}

#[test]
fn fast_foot_points_agree_with_the_general_solver() {
    let mut rng = Pcg64::seed_from_u64(8);
    for e in [
        Ellipse::new(3.0, -2.0, 300.0, 40.0, 0.7).unwrap(),
        Ellipse::new(0.0, 0.0, 5.0, 4.9, -1.3).unwrap(),
        Ellipse::new(1.0, 1.0, 10.0, 10.0, 0.0).unwrap(),
        Ellipse::new(1.0, 1.0, 100.0, 3.0, 1.0).unwrap(),
    ] {
        // Edge points near the curve: the fast path must take (nearly) all of them.
        let near: Vec<_> = (0..2000)
            .map(|_| {
                let t = rng.random_range(-PI..PI);
                let d = 0.2 * e.b * e.b / e.a;
                e.point_at(t) + Vector2::new(rng.random_range(-d..d), rng.random_range(-d..d))
            })
            .collect();
        // Points anywhere in and around the ellipse, including near the centre.
        let anywhere: Vec<_> = (0..2000)
            .map(|_| {
                Vector2::new(e.cx, e.cy)
                    + Vector2::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5)) * e.a
            })
            .collect();
        let sc = e.theta.sin_cos();
        for (pts, max_general) in [(&near, 20), (&anywhere, 2000)] {
            let mut angles = vec![];
            let general = residual::foot_angles(&e, pts, &[], &mut angles);
            assert!(
                general <= max_general,
                "{e:?}: {general} points needed the general solver"
            );
            for (p, &(s, c)) in pts.iter().zip(&angles) {
                let t = e.parameter_of(p);
                let exact = e.orthogonal_distance(p);
                let f = residual::foot_at(&e, sc, p, (s, c));
                assert!(
                    (f.r - exact).abs() <= 1e-10 * (1.0 + exact.abs()),
                    "{e:?} {p:?}: {} vs {exact}",
                    f.r
                );
                assert!(e.algebraic_distance(&f.x).abs() < 1e-12);
                assert!(
                    (s - t.sin()).abs() < 1e-9 && (c - t.cos()).abs() < 1e-9,
                    "{e:?} {p:?}"
                );
            }
        }
    }
}

#[test]
fn short_arc_whose_best_fit_degenerates_is_an_error() {
    // Regression: a 60° arc (176 points, 0.5 px noise) whose least-squares ellipse runs off
    // toward a parabola (a → ∞). It must be reported, not returned with a wrong covariance.
    let truth = Ellipse::new(534.086, 334.379, 225.255, 112.341, 0.36066).unwrap();
    let noise = Normal::new(0.0, 0.5).unwrap();
    let mut failures = 0;
    let mut rng = Pcg64::seed_from_u64(10);
    for _ in 0..200 {
        let pts = arc(
            &truth,
            rng.random_range(-PI..PI),
            f64::to_radians(60.0),
            176,
            0.0,
            &mut rng,
        )
        .into_iter()
        .map(|p| p + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng)))
        .collect::<Vec<_>>();
        match fit_ellipse(&pts, FitMethod::Geometric) {
            Ok(fit) => {
                let cov = fit.covariance.unwrap();
                assert!(
                    cov.iter().all(|v| v.is_finite()) && cov.symmetric_eigenvalues().min() > 0.0
                );
            }
            Err(DetectError::RankDeficient { reason }) => {
                assert!(reason.contains("parabola"), "{reason}");
                failures += 1;
            }
            Err(e) => panic!("unexpected error {e}"),
        }
    }
    // Rare, but it happens on such short arcs (this seed has such an arc).
    assert!(
        (1..40).contains(&failures),
        "{failures} of 200 fits degenerated"
    );
    eprintln!("{failures} of 200 60° arcs have no bounded least-squares ellipse");
}

#[test]
fn masked_fit_recovers_the_free_parameters_and_matches_the_full_fit_when_all_are_free() {
    let mut rng = Pcg64::seed_from_u64(31);
    // A flat rim ellipse seen along its front arc (eccentric angles 0.1π…0.9π, 40 %).
    let truth = Ellipse::new(640.0, 300.0, 300.0, 22.0, 0.01).unwrap();
    let pts = arc(&truth, 0.1 * PI, 0.8 * PI, 400, 0.05, &mut rng);
    let start = Ellipse {
        cx: truth.cx + 1.5,
        cy: truth.cy - 1.0,
        b: truth.b * 1.05,
        ..truth
    };
    let opts = GeometricFitOptions::default();
    let fit =
        fit_ellipse_geometric_masked(&pts, start, [true, true, false, true, false], &opts).unwrap();
    assert!(fit.converged);
    let err = param_error(&fit.ellipse, &truth);
    assert_eq!((err[2], err[4]), (0.0, 0.0), "fixed parameters moved");
    let cov = fit.covariance.unwrap();
    for k in [0, 1, 3] {
        // Within 4σ of the fit's own covariance (an independent check of the Jacobian scale).
        assert!(
            err[k].abs() < 4.0 * cov[(k, k)].sqrt() + 1e-9,
            "k={k}: {err:?} {cov}"
        );
    }
    assert_eq!(cov[(2, 2)], 0.0);
    assert!(fit.residual_rms < 0.07);
    // All free: the same minimum as the conic-space LM (both iterated to `tolerance`).
    let tight = GeometricFitOptions {
        noise_tolerance: 0.0,
        ..opts
    };
    let full = fit_ellipse_geometric(&pts, None, &tight).unwrap();
    let all = fit_ellipse_geometric_masked(&pts, full.ellipse, [true; 5], &opts).unwrap();
    let d = param_error(&all.ellipse, &full.ellipse);
    assert!(d.amax() < 1e-6 * 300.0, "{d:?}");
    assert!((all.residual_rms - full.residual_rms).abs() < 1e-9);
}

#[test]
fn masked_fit_rejects_bad_input() {
    let e = Ellipse::new(0.0, 0.0, 10.0, 5.0, 0.0).unwrap();
    let pts = e.sample(20, 0.0, 2.0).unwrap();
    let opts = GeometricFitOptions::default();
    assert!(fit_ellipse_geometric_masked(&pts, e, [false; 5], &opts).is_err());
    assert!(matches!(
        fit_ellipse_geometric_masked(&pts[..3], e, [true, true, false, true, false], &opts),
        Err(DetectError::TooFewPoints { .. })
    ));
    let mut nan = pts.clone();
    nan[4].x = f64::NAN;
    assert!(matches!(
        fit_ellipse_geometric_masked(&nan, e, [true; 5], &opts),
        Err(DetectError::NonFinite { .. })
    ));
    let bad = Ellipse { b: -1.0, ..e };
    assert!(fit_ellipse_geometric_masked(&pts, bad, [true; 5], &opts).is_err());
}

/// Full 6×6 scatter `S = Σ zzᵀ` and Taubin normaliser `N = Σ ∇z∇zᵀ` of `z = [x², xy, y², x,
/// y, 1]`, built directly from the points (independent of [`Prepared`]'s reduced blocks).
fn taubin_matrices(pts: &[Vector2<f64>]) -> (nalgebra::Matrix6<f64>, nalgebra::Matrix6<f64>) {
    let mut s = nalgebra::Matrix6::zeros();
    let mut n = nalgebra::Matrix6::zeros();
    for p in pts {
        let (x, y) = (p.x, p.y);
        let z = nalgebra::Vector6::new(x * x, x * y, y * y, x, y, 1.0);
        let gx = nalgebra::Vector6::new(2.0 * x, y, 0.0, 1.0, 0.0, 0.0);
        let gy = nalgebra::Vector6::new(0.0, x, 2.0 * y, 0.0, 1.0, 0.0);
        s += z * z.transpose();
        n += gx * gx.transpose() + gy * gy.transpose();
    }
    (s, n)
}

#[test]
fn taubin_fit_is_exact_on_noiseless_arcs_and_minimises_its_quotient() {
    for truth in truths() {
        let pts = truth.sample(80, 0.4, 0.4 + 2.0).unwrap();
        let prep = Prepared::new(&pts).unwrap();
        let t = direct::taubin(&prep).unwrap();
        let c = prep.centroid;
        let t = Ellipse::new(t.cx + c.x, t.cy + c.y, t.a, t.b, t.theta).unwrap();
        let err = param_error(&t, &truth);
        assert!(err.amax() < 1e-7 * truth.a, "{truth:?}: {err:?}");
    }
    // Noisy partial arcs: the conic is the minimiser of qᵀSq / qᵀNq over all conics, checked
    // on the unreduced 6×6 matrices (stationarity S q = λ N q, and no perturbation does better).
    let mut rng = Pcg64::seed_from_u64(41);
    for _ in 0..20 {
        let (_, pts) = random_case(&mut rng, 90.0, 160.0);
        let prep = Prepared::new(&pts).unwrap();
        let t = direct::taubin(&prep).unwrap();
        let scaled: Vec<Vector2<f64>> = prep.centred.iter().map(|p| p / prep.scale).collect();
        let (s, n) = taubin_matrices(&scaled);
        let inv = 1.0 / prep.scale;
        let en = Ellipse::new(t.cx * inv, t.cy * inv, t.a * inv, t.b * inv, t.theta).unwrap();
        let q = nalgebra::Vector6::from(en.conic_coefficients());
        let quotient = |q: &nalgebra::Vector6<f64>| q.dot(&(s * q)) / q.dot(&(n * q));
        let lambda = quotient(&q);
        let res = s * q - n * q * lambda;
        assert!(
            res.norm() < 1e-8 * (s * q).norm().max(1e-12),
            "S q − λ N q = {res:?}"
        );
        for _ in 0..200 {
            let d = nalgebra::Vector6::from_fn(|_, _| rng.random_range(-1.0..1.0)) * 1e-3;
            assert!(quotient(&(q + d * q.norm())) >= lambda * (1.0 - 1e-12));
        }
    }
}

#[test]
fn taubin_start_is_less_biased_than_the_direct_fit_on_partial_arcs() {
    let mut rng = Pcg64::seed_from_u64(42);
    let (mut err_t, mut err_d) = (vec![], vec![]);
    for _ in 0..200 {
        let (truth, pts) = random_case(&mut rng, 90.0, 160.0);
        let prep = Prepared::new(&pts).unwrap();
        let c = prep.centroid;
        let d = direct::solve(&prep).unwrap();
        let t = direct::taubin(&prep).unwrap();
        err_d.push((d.cx + c.x - truth.cx).hypot(d.cy + c.y - truth.cy));
        err_t.push((t.cx + c.x - truth.cx).hypot(t.cy + c.y - truth.cy));
    }
    let (mt, md) = (median(err_t), median(err_d));
    eprintln!("median centre error: Taubin {mt:.3} px, direct {md:.3} px");
    assert!(mt < 0.5 * md, "Taubin {mt} vs direct {md}");
}

#[test]
fn conic_normal_equations_equal_the_sum_of_the_per_point_rows() {
    let mut rng = Pcg64::seed_from_u64(43);
    let e = Ellipse::new(0.3, -0.2, 1.4, 0.6, 0.7).unwrap();
    let q = e.conic_coefficients();
    let sc = e.theta.sin_cos();
    // Lengths around the four lanes of the accumulation.
    for n in [5usize, 6, 7, 8, 9, 103] {
        let pts: Vec<Vector2<f64>> = (0..n)
            .map(|_| {
                e.point_at(rng.random_range(-PI..PI))
                    + Vector2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1))
            })
            .collect();
        let mut angles = Vec::new();
        let acc = residual::accumulate_conic(&e, &q, &pts, &[], &mut angles);
        let (mut jtj, mut jtr, mut ssr, mut sum_abs) = (
            nalgebra::Matrix6::zeros(),
            nalgebra::Vector6::zeros(),
            0.0,
            0.0,
        );
        for p in &pts {
            let (r, g) = residual::distance_and_conic_gradient(
                &e,
                sc,
                &q,
                p,
                residual::foot(&e, sc, p).st_ct(),
            );
            jtj += g * g.transpose();
            jtr += g * r;
            ssr += r * r;
            sum_abs += r.abs();
        }
        assert!((acc.jtj - jtj).norm() < 1e-12 * jtj.norm(), "n={n}");
        assert!(
            (acc.jtr - jtr).norm() < 1e-12 * (jtr.norm() + 1e-12),
            "n={n}"
        );
        assert!((acc.ssr - ssr).abs() < 1e-12 * ssr, "n={n}");
        assert!((acc.sum_abs - sum_abs).abs() < 1e-12 * sum_abs, "n={n}");
    }
}

#[test]
fn conic_to_parameter_chain_rule_gives_the_parameter_jacobian() {
    // Row by row: J_q·∂q/∂p equals the analytic ∂r/∂(cx, cy, a, b, θ) (itself checked against
    // finite differences above), for conic coefficients of any scale and sign.
    let mut rng = Pcg64::seed_from_u64(44);
    for e in [
        Ellipse::new(0.3, -0.2, 1.4, 0.6, 0.7).unwrap(),
        Ellipse::new(-1.0, 2.0, 0.9, 0.85, -1.3).unwrap(),
    ] {
        let sc = e.theta.sin_cos();
        // Positive scales: the conic gradient assumes eq. (3.3)'s orientation, f > 0 outside.
        for scale in [1.0, 3.5, 0.01] {
            let q = e.conic_coefficients().map(|v| v * scale);
            let g = residual::conic_parameter_jacobian(&e, &q);
            for _ in 0..50 {
                let p = e.point_at(rng.random_range(-PI..PI))
                    + Vector2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1));
                let t = residual::foot(&e, sc, &p).st_ct();
                let (_, jq) = residual::distance_and_conic_gradient(&e, sc, &q, &p, t);
                let (_, jp) = residual::distance_and_gradient(&e, sc, &p);
                let chain = g.transpose() * jq;
                assert!(
                    (chain - jp).amax() < 1e-10 * (1.0 + jp.amax()),
                    "{chain:?} vs {jp:?}"
                );
            }
        }
    }
}

#[test]
fn fit_statistics_equal_a_fresh_evaluation_at_the_result() {
    // The fit carries its normal equations over from the conic to (cx, cy, a, b, θ); a fresh
    // orthogonal evaluation at the returned ellipse gives the same residuals and covariance.
    let mut rng = Pcg64::seed_from_u64(45);
    for _ in 0..30 {
        let (_, pts) = random_case(&mut rng, 60.0, 160.0);
        let fit = fit_ellipse(&pts, FitMethod::Geometric).unwrap();
        let c = pts.iter().sum::<Vector2<f64>>() / pts.len() as f64;
        let centred: Vec<Vector2<f64>> = pts.iter().map(|p| p - c).collect();
        let e = Ellipse {
            cx: fit.ellipse.cx - c.x,
            cy: fit.ellipse.cy - c.y,
            ..fit.ellipse
        };
        let (mean, rms, cov) = residual::evaluate(&e, &centred, None).unwrap();
        assert!((mean - fit.residual_mean).abs() < 1e-9 * mean);
        assert!((rms - fit.residual_rms).abs() < 1e-9 * rms);
        let (cov, fc) = (cov.unwrap(), fit.covariance.unwrap());
        for i in 0..5 {
            for j in 0..5 {
                let scale = (cov[(i, i)] * cov[(j, j)]).sqrt();
                assert!(
                    (cov[(i, j)] - fc[(i, j)]).abs() < 1e-6 * scale,
                    "({i}, {j}): {} vs {}",
                    fc[(i, j)],
                    cov[(i, j)]
                );
            }
        }
    }
}

#[test]
fn noise_tolerance_stops_within_a_few_hundredths_of_a_standard_deviation() {
    let mut rng = Pcg64::seed_from_u64(46);
    let tight = GeometricFitOptions {
        noise_tolerance: 0.0,
        ..Default::default()
    };
    let (mut its, mut its_tight, mut worst) = (0, 0, 0.0f64);
    let trials = 100;
    for _ in 0..trials {
        let (_, pts) = random_case(&mut rng, 60.0, 160.0);
        let fit = fit_ellipse_geometric(&pts, None, &GeometricFitOptions::default()).unwrap();
        let reference = fit_ellipse_geometric(&pts, None, &tight).unwrap();
        assert!(fit.converged && reference.converged);
        its += fit.iterations;
        its_tight += reference.iterations;
        // Distance to the fully converged fit in standard deviations of the fit's estimate.
        let d = param_error(&fit.ellipse, &reference.ellipse);
        let cov = reference.covariance.unwrap();
        let m = d.dot(&(cov.try_inverse().unwrap() * d)).sqrt();
        // The rule bounds the next Gauss–Newton step by 0.01σ; where Gauss–Newton converges
        // only linearly (short, strongly correlated arcs of 60°) the distance left is a few
        // times that step (largest seen: 0.028σ).
        assert!(m < 0.05, "{m} standard deviations from the converged fit");
        worst = worst.max(m);
    }
    eprintln!(
        "iterations per fit: {its} / {its_tight} over {trials}; largest distance {worst:.4}σ"
    );
    assert!(its <= its_tight);
    for bad in [-1e-3, f64::NAN, f64::INFINITY] {
        let opts = GeometricFitOptions {
            noise_tolerance: bad,
            ..Default::default()
        };
        let (_, pts) = random_case(&mut rng, 90.0, 120.0);
        assert!(matches!(
            fit_ellipse_geometric(&pts, None, &opts),
            Err(DetectError::InvalidParameter {
                what: "noise_tolerance",
                ..
            })
        ));
    }
}

#[test]
fn screen_lower_bound_never_exceeds_the_orthogonal_distance() {
    // Per point, with the foot angle left uncertified (the bound `min(a, b)·|ρ − 1|`) and
    // certified (the exact distance): never above the exact distance of the general solver.
    let mut rng = Pcg64::seed_from_u64(21);
    for e in [
        Ellipse::new(3.0, -2.0, 300.0, 40.0, 0.7).unwrap(),
        Ellipse::new(0.0, 0.0, 5.0, 4.9, -1.3).unwrap(),
        Ellipse::new(1.0, 1.0, 100.0, 3.0, 1.0).unwrap(),
        // Semi-axes in the other order (b > a): the bound must use the smaller one.
        Ellipse {
            cx: 2.0,
            cy: 5.0,
            a: 20.0,
            b: 200.0,
            theta: 0.3,
        },
    ] {
        let sc = e.theta.sin_cos();
        let scale = e.a.max(e.b);
        let mut tight = 0;
        for _ in 0..3000 {
            let p = Vector2::new(e.cx, e.cy)
                + Vector2::new(rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)) * scale;
            let exact = e.orthogonal_distance(&p).abs();
            let t = e.parameter_of(&p).sin_cos();
            let bound = geometric::screen_lower_bound(&e, sc, &[p], &[t], &[false]);
            assert!(
                bound <= exact * (1.0 + 1e-12) + 1e-12,
                "{e:?} {p:?}: bound {bound} > distance {exact}"
            );
            tight += usize::from(bound >= 0.5 * exact);
            let certified = geometric::screen_lower_bound(&e, sc, &[p], &[t], &[true]);
            assert!((certified - exact).abs() <= 1e-9 * (1.0 + exact));
        }
        // Not vacuous: on the near-circle most points are bounded within a factor of two.
        if e.a / e.b < 1.1 {
            assert!(tight > 2000, "{e:?}: {tight}");
        }
    }
}

#[test]
fn screened_fit_decides_and_fits_as_the_direct_then_geometric_fits() {
    // Unions of two arcs of the same ellipse, of two different ellipses and of an arc with
    // clutter: `fit_screened` must reject exactly when the direct fit's mean orthogonal residual
    // is not under the screen (thresholds just below and above it, where the early rejection on
    // a lower bound must not decide differently), and otherwise return the geometric fit.
    let mut rng = Pcg64::seed_from_u64(22);
    let opts = GeometricFitOptions {
        max_iterations: 20,
        ..GeometricFitOptions::default()
    };
    let mut rejected_early = 0;
    for case in 0..60 {
        let e1 = Ellipse::new(
            rng.random_range(200.0..900.0),
            rng.random_range(100.0..500.0),
            rng.random_range(60.0..400.0),
            rng.random_range(5.0..60.0),
            rng.random_range(-0.2..0.2),
        )
        .unwrap();
        let e2 = match case % 3 {
            0 => e1,
            1 => Ellipse::new(e1.cx + 3.0, e1.cy + 4.0, e1.a * 1.02, e1.b * 1.3, e1.theta).unwrap(),
            _ => Ellipse::new(e1.cx + 40.0, e1.cy - 30.0, e1.a * 0.5, e1.b, -e1.theta).unwrap(),
        };
        let mut pts = arc(&e1, rng.random_range(-PI..PI), 1.0, 60, 0.3, &mut rng);
        pts.extend(arc(&e2, rng.random_range(-PI..PI), 1.2, 70, 0.3, &mut rng));
        let Ok(direct) = fit_ellipse_direct(&pts) else {
            continue;
        };
        let m = direct.residual_mean;
        let want = fit_ellipse_geometric(&pts, None, &opts);
        for thr in [0.3 * m, m * (1.0 - 1e-6), m * (1.0 + 1e-6), 3.0 * m] {
            let got = geometric::fit_screened(&pts, thr, &opts);
            match (&got, m < thr) {
                (Ok(None), false) => {}
                (Ok(Some((fit, angles))), true) => {
                    let want = want.as_ref().unwrap();
                    assert_eq!(angles.len(), pts.len());
                    assert!((params(&fit.ellipse) - params(&want.ellipse)).amax() < 1e-9);
                }
                (Err(_), true) => assert!(want.is_err()),
                _ => panic!("case {case}: threshold {thr}, direct mean {m}: got {got:?}"),
            }
            // How often the bound alone rejects (the screen's shortcut is exercised).
            let prep = Prepared::new(&pts).unwrap();
            let d = direct::solve(&prep).unwrap();
            let (mut angles, mut ok) = (Vec::new(), Vec::new());
            residual::certified_foot_angles(&d, &prep.centred, &[], &mut angles, &mut ok);
            let lb =
                geometric::screen_lower_bound(&d, d.theta.sin_cos(), &prep.centred, &angles, &ok);
            if ok.contains(&false) && lb >= thr * pts.len() as f64 {
                rejected_early += 1;
            }
        }
    }
    assert!(rejected_early > 5, "{rejected_early}");
}
