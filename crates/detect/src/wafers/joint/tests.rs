use super::*;

/// The cost's gradient `2·rg` (Gauss–Newton: `J_gᵀr` at the locals held) against central
/// finite differences of `cost` in each of the globals at `g0`.
fn assert_gradient_matches_fd(cost: &dyn Fn(&Globals) -> f64, g0: &Globals, rg: &Globals) {
    for k in 0..NG {
        let h = [1e-5, 1e-5, 1e-6, 1e-4, 1e-4, 1e-4, 1e-5][k];
        let (mut gp, mut gm) = (*g0, *g0);
        gp[k] += h;
        gm[k] -= h;
        let fd = (cost(&gp) - cost(&gm)) / (2.0 * h);
        let an = 2.0 * rg[k];
        assert!(
            (fd - an).abs() < 1e-5 * (1.0 + fd.abs().max(an.abs())),
            "k={k}: fd {fd} vs analytic {an}"
        );
    }
}
#[test]
fn ray_hit_derivatives_match_finite_differences() {
    let e = Ellipse::new(600.0, 300.0, 280.0, 33.0, 0.04).unwrap();
    for t in [0.4, 1.2, 1.7, 2.6] {
        let p = e.point_at(t) - Vector2::new(0.3, 2.2);
        let d = Vector2::new(0.1, 1.0).normalize();
        let (t0, g) = ray_hit(&e, p, d, 2.0).unwrap();
        // The hit lies on the ellipse.
        assert!(e.orthogonal_distance(&(p + d * t0)).abs() < 1e-9);
        let h = 1e-6;
        let shifted = |k: usize, sign: f64| {
            let mut v = [e.cx, e.cy, e.b, e.a];
            v[k] += sign * h;
            let f = Ellipse::new(v[0], v[1], v[3], v[2], e.theta).unwrap();
            ray_hit(&f, p, d, t0).unwrap().0
        };
        for (k, gk) in g.iter().enumerate() {
            let fd = (shifted(k, 1.0) - shifted(k, -1.0)) / (2.0 * h);
            assert!(
                (fd - gk).abs() < 1e-5 * (1.0 + fd.abs()),
                "t={t} k={k}: {fd} vs {}",
                gk
            );
        }
    }
    // A ray that misses.
    let far = Vector2::new(0.0, -500.0);
    assert!(ray_hit(&e, far, Vector2::new(1.0, 0.0), 0.0).is_none());
}

/// The reference rim, `up` and the true globals of the synthetic tests.
fn synthetic_case() -> (Ellipse, Vector2<f64>, Globals) {
    (
        Ellipse::new(620.0, 310.0, 300.0, 40.0, 0.03).unwrap(),
        Vector2::new(0.03, -1.0).normalize(),
        Globals::from_column_slice(&[-3.0, 39.2, 0.9, 330.0, 30.0, -20.0, 0.0]),
    )
}

/// Synthetic profiles across the band between `reference` and the target `g` (band model
/// samples with a deterministic wobble; the brightest band top clipped), locals perturbed.
fn synthetic_profiles(reference: &Ellipse, up: Vector2<f64>, g: &Globals) -> Vec<Profile> {
    let e = target(reference, up, g).unwrap();
    let (st, ct) = reference.theta.sin_cos();
    (0..24)
        .map(|k| {
            let t = 0.6 + 1.9 * k as f64 / 23.0;
            let p = reference.point_at(t);
            let (gx, gy) = (t.cos() / reference.a, t.sin() / reference.b);
            let n = Vector2::new(gx * ct - gy * st, gx * st + gy * ct).normalize();
            let d = if n.dot(&up) < 0.0 { n } else { -n };
            let (t2, _) = ray_hit(&e, p, d, 2.5).unwrap();
            let (u, v) = (t.cos(), t.sin());
            let lb = band_level(g, u, v);
            let q = [30.0 + k as f64, lb, 50.0, 0.1, t2, g[2]];
            let samples = (0..19)
                .map(|i| {
                    let s = band::T_MIN + i as f64 * band::STEP;
                    let y = band::model(&q, s).0 + 0.8 * (((i * 7919 + k) % 11) as f64 / 5.0 - 1.0);
                    (s, if y >= CLIP { f64::INFINITY } else { y })
                })
                .collect();
            Profile {
                p,
                d,
                u,
                v,
                samples,
                local: Vector3::new(q[0] + 2.0, q[2] - 3.0, q[3] + 0.2),
            }
        })
        .collect()
}

#[test]
fn fused_evaluation_equals_separate_passes() {
    // The one-pass cost and normal equations of `evaluate` against the residual/Jacobian
    // rows of `profile_residuals` accumulated separately (the pre-fusion code path), at a
    // start and at the solver's solution; the solver's per-profile costs and Schur
    // complement against a fresh separate evaluation there.
    let (reference, up, truth) = synthetic_case();
    let profiles = synthetic_profiles(&reference, up, &truth);
    assert!(
        profiles
            .iter()
            .any(|p| p.samples.iter().any(|s| s.1.is_infinite()))
    );
    let separate = |profiles: &[Profile], g: &Globals| {
        let e = target(&reference, up, g).unwrap();
        let (mut r, mut jl, mut jg) = (Vec::new(), Vec::new(), Vec::new());
        let mut cg = GlobalMatrix::zeros();
        let mut rg = Globals::zeros();
        let mut schur = GlobalMatrix::zeros();
        let mut blocks = Vec::new();
        let mut total = 0.0;
        for pr in profiles {
            let c =
                profile_residuals(pr, &e, up, g, 0.0, Some((&mut r, &mut jl, &mut jg))).unwrap();
            total += c;
            let mut a = Matrix3::<f64>::zeros();
            let mut b = Coupling::zeros();
            let mut ra = Vector3::<f64>::zeros();
            for ((res, l), gl) in r.iter().zip(&jl).zip(&jg) {
                let l = Vector3::from(*l);
                let gl = Globals::from(*gl);
                a += l * l.transpose();
                b += l * gl.transpose();
                ra += l * *res;
                cg += gl * gl.transpose();
                rg += gl * *res;
            }
            schur -= b.transpose() * a.try_inverse().unwrap() * b;
            blocks.push((a, b, ra, c));
        }
        // The prior on δa, with no noise estimate (σ_n = 0: one grey level).
        let w = 1.0 / PARTNER_A_SIGMA;
        cg[(6, 6)] += w * w;
        rg[6] += w * w * g[6];
        total += (w * g[6]).powi(2);
        (blocks, cg, rg, total, schur + cg)
    };
    let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-12 * scale.max(1.0);
    let g0 = Globals::from_column_slice(&[-2.5, 39.8, 1.1, 230.0, 20.0, 0.0, 0.1]);
    let mut ev = Evaluation::default();
    evaluate(&profiles, &reference, up, &g0, None, 0.0, &mut ev).unwrap();
    let (blocks, cg, rg, total, _) = separate(&profiles, &g0);
    assert!(close(ev.cost, total, total));
    assert_eq!(ev.blocks.len(), blocks.len());
    for (f, (a, b, ra, c)) in ev.blocks.iter().zip(&blocks) {
        assert!(close(f.cost, *c, *c));
        assert!((f.a - a).norm() <= 1e-12 * a.norm().max(1.0));
        assert!((f.b - b).norm() <= 1e-12 * b.norm().max(1.0));
        assert!((f.ra - ra).norm() <= 1e-12 * ra.norm().max(1.0));
    }
    assert!((ev.cg - cg).norm() <= 1e-12 * cg.norm());
    assert!((ev.rg - rg).norm() <= 1e-12 * rg.norm());
    // At the solution.
    let mut solved = synthetic_profiles(&reference, up, &truth);
    let (g, cost, schur, costs) = solve(&mut solved, &reference, up, g0, None, 0.0, false).unwrap();
    assert!(cost < total, "{cost} vs {total}");
    assert!((g[1] - truth[1]).abs() < 0.05, "{g:?}");
    let (blocks, _, _, total, schur_ref) = separate(&solved, &g);
    assert!(close(cost, total, total));
    for (c, b) in costs.iter().zip(&blocks) {
        assert!(close(*c, b.3, b.3));
    }
    assert!((schur - schur_ref).norm() <= 1e-12 * schur_ref.norm());
}

/// `−ln(1 − Φ(z))` by Simpson's rule on the normal density (independent of `libm::erfc`
/// and of the tail series): `1 − Φ(z) = ∫_z^{z+14} φ` for `z ≥ 0` (the rest is below
/// `10⁻⁴²` of it), `1 − ∫_{z−14}^z φ` below.
fn tobit_nll_by_quadrature(z: f64) -> f64 {
    let simpson = |lo: f64, hi: f64| {
        let n = 28_000;
        let h = (hi - lo) / n as f64;
        let pdf = |t: f64| (-0.5 * t * t).exp() / std::f64::consts::TAU.sqrt();
        let mut sum = pdf(lo) + pdf(hi);
        for i in 1..n {
            sum += if i % 2 == 1 { 4.0 } else { 2.0 } * pdf(lo + i as f64 * h);
        }
        sum * h / 3.0
    };
    if z >= 0.0 {
        -simpson(z, z + 14.0).ln()
    } else {
        -(-simpson(z - 14.0, z)).ln_1p()
    }
}

#[test]
fn censored_residual_is_the_tobit_likelihood_with_its_exact_derivative() {
    let sigma_n = 2.0;
    // z from −32 to 30 (beyond, the quadrature's density values turn subnormal).
    for i in -400..=840 {
        let f = CLIP + 24.0 - i as f64 * 0.1;
        let (r, slope) = censored_residual(f, sigma_n);
        let z = (CLIP - f) / sigma_n;
        // r² = 2σ_n²·(−ln(1 − Φ(z))): the censored negative log-likelihood.
        let nll = tobit_nll_by_quadrature(z);
        assert!(
            (r * r / (2.0 * sigma_n * sigma_n) - nll).abs() <= 1e-5 + 1e-9 * nll,
            "f={f}: {r} vs nll {nll}"
        );
        assert!(
            r <= 0.0 && (0.0..=1.0 + 1e-12).contains(&slope),
            "{r} {slope}"
        );
        // The derivative is that of the residual (away from the series switch).
        let h = 1e-4;
        if (z - TAIL_SERIES_FROM).abs() > 2.0 * h / sigma_n {
            let fd = (censored_residual(f + h, sigma_n).0 - censored_residual(f - h, sigma_n).0)
                / (2.0 * h);
            assert!((fd - slope).abs() < 1e-6, "f={f}: fd {fd} vs {slope}");
        }
    }
    // Far below the clip the residual is the plain difference; far above, nothing.
    let (r, slope) = censored_residual(CLIP - 200.0, sigma_n);
    assert!(
        (r / -200.0 - 1.0).abs() < 0.005 && (slope - 1.0).abs() < 1e-3,
        "{r} {slope}"
    );
    let (r, slope) = censored_residual(CLIP + 100.0, sigma_n);
    assert!(r == 0.0 && slope == 0.0, "{r} {slope}");
    // Without a noise level: the hinge.
    assert_eq!(censored_residual(CLIP - 3.0, 0.0), (-3.0, 1.0));
    assert_eq!(censored_residual(CLIP + 3.0, 0.0), (0.0, 0.0));
}

#[test]
fn censored_evaluation_gradient_matches_finite_differences() {
    // With the Tobit residual of the clipped samples: the evaluation's J_gᵀr against central
    // finite differences of its cost, and the fused pass against the separate one.
    let (reference, up, truth) = synthetic_case();
    let profiles = synthetic_profiles(&reference, up, &truth);
    let sigma_n = 2.0;
    let g0 = Globals::from_column_slice(&[-2.8, 39.5, 1.05, 300.0, 25.0, -10.0, 0.15]);
    let cost = |g: &Globals| {
        let mut ev = Evaluation::default();
        evaluate(&profiles, &reference, up, g, None, sigma_n, &mut ev).unwrap();
        ev.cost
    };
    let mut ev = Evaluation::default();
    evaluate(&profiles, &reference, up, &g0, None, sigma_n, &mut ev).unwrap();
    let mut hinge = Evaluation::default();
    evaluate(&profiles, &reference, up, &g0, None, 0.0, &mut hinge).unwrap();
    assert!(
        (ev.cost - hinge.cost).abs() > 1.0,
        "{} {}",
        ev.cost,
        hinge.cost
    );
    assert_gradient_matches_fd(&cost, &g0, &ev.rg);
    let e = target(&reference, up, &g0).unwrap();
    let (mut r, mut jl, mut jg) = (Vec::new(), Vec::new(), Vec::new());
    for (pr, blk) in profiles.iter().zip(&ev.blocks) {
        let c =
            profile_residuals(pr, &e, up, &g0, sigma_n, Some((&mut r, &mut jl, &mut jg))).unwrap();
        assert!((c - blk.cost).abs() <= 1e-12 * c.max(1.0));
        let ra: Vector3<f64> = r
            .iter()
            .zip(&jl)
            .map(|(res, l)| Vector3::from(*l) * *res)
            .sum();
        assert!((ra - blk.ra).norm() <= 1e-10 * ra.norm().max(1.0));
    }
}

#[test]
fn offset_prior_gradient_matches_finite_differences_and_pins_the_offset() {
    // The cost's gradient with respect to the globals, with the locals held, is 2·J_gᵀr: the
    // evaluation's `rg` (band residuals and the prior's residual) against central finite
    // differences of its cost.
    let (reference, up, truth) = synthetic_case();
    let profiles = synthetic_profiles(&reference, up, &truth);
    let prior = PriorTerm {
        mean: -2.6,
        weight: 7.0,
    };
    let g0 = Globals::from_column_slice(&[-2.8, 39.5, 1.05, 300.0, 25.0, -10.0, 0.15]);
    let cost = |g: &Globals| {
        let mut ev = Evaluation::default();
        evaluate(&profiles, &reference, up, g, Some(prior), 0.0, &mut ev).unwrap();
        ev.cost
    };
    let mut ev = Evaluation::default();
    evaluate(&profiles, &reference, up, &g0, Some(prior), 0.0, &mut ev).unwrap();
    let mut plain = Evaluation::default();
    evaluate(&profiles, &reference, up, &g0, None, 0.0, &mut plain).unwrap();
    let r = prior.weight * (g0[0] - prior.mean);
    assert!((ev.cost - plain.cost - r * r).abs() < 1e-9 * ev.cost);
    assert!((ev.cg[(0, 0)] - plain.cg[(0, 0)] - prior.weight.powi(2)).abs() < 1e-9 * ev.cg[(0, 0)]);
    assert_gradient_matches_fd(&cost, &g0, &ev.rg);
    // A tight prior pins `s` at its mean; without it the data put `s` at the truth.
    let mut free = synthetic_profiles(&reference, up, &truth);
    let (g, ..) = solve(&mut free, &reference, up, g0, None, 0.0, false).unwrap();
    assert!((g[0] - truth[0]).abs() < 0.05, "{g:?}");
    let mut pinned = synthetic_profiles(&reference, up, &truth);
    let tight = PriorTerm {
        mean: -2.6,
        weight: 1e4,
    };
    let (g, ..) = solve(&mut pinned, &reference, up, g0, Some(tight), 0.0, false).unwrap();
    assert!((g[0] - tight.mean).abs() < 0.01, "{g:?}");
}

#[test]
fn far_side_step_flags_an_edge_beyond_the_band() {
    // Synthetic profiles at the true globals: a flat far side gives standardised steps of
    // the order of the noise; a second edge 2 px beyond the far edge (the far level rising
    // by 40 grey levels) gives a step far above 3σ.
    let (reference, up, truth) = synthetic_case();
    let e = target(&reference, up, &truth).unwrap();
    let mut profiles = synthetic_profiles(&reference, up, &truth);
    for pr in &mut profiles {
        // The locals at their true values (see `synthetic_profiles`).
        pr.local -= Vector3::new(2.0, -3.0, 0.2);
    }
    for pr in &profiles {
        let z = far_side_step(pr, &e, &truth).unwrap();
        assert!(z < 3.0 * 0.8, "{z}");
    }
    let mut stepped = profiles.swap_remove(5);
    let (t2, _) = ray_hit(&e, stepped.p, stepped.d, 2.5).unwrap();
    for s in &mut stepped.samples {
        s.1 += 40.0 * band::cdf_and_density((s.0 - t2 - 2.0) / truth[2]).0;
    }
    let z = far_side_step(&stepped, &e, &truth).unwrap();
    assert!(z > 10.0, "{z}");
    // Too few samples beyond the far edge: no statistic.
    stepped.samples.retain(|s| s.0 < t2 + 1.5);
    assert!(far_side_step(&stepped, &e, &truth).is_none());
}

/// The values the generator of `benchmarks/wafer_detection.py` drew for one image (seed 3):
/// disturbance slots above `k`, camera `(x, y, dz)`, yaw and pitch-down (degrees), gain,
/// lighting gradient and noise seed.
type Scenario = (usize, (f64, f64, f64), f64, f64, f64, [f64; 2], u64);

/// The target wafer's true upper and lower rims of a rendered scene, and a start for the
/// lower rim's joint fit 2 % flat and 0.5 px off along `up`.
fn target_rims_and_biased_start(
    rims: &[(usize, autoteach_geometry::render::Rim, Ellipse, f64)],
) -> (Ellipse, Ellipse, Ellipse) {
    use autoteach_geometry::render::Rim;
    let truth = |rim: Rim| {
        rims.iter()
            .find(|r| r.0 == 0 && r.1 == rim)
            .map(|r| r.2)
            .unwrap()
    };
    let (upper, lower) = (truth(Rim::Upper), truth(Rim::Lower));
    let start = Ellipse::new(
        lower.cx,
        lower.cy + 0.5,
        lower.a,
        0.98 * lower.b,
        lower.theta,
    )
    .unwrap();
    (upper, lower, start)
}

/// The relative `b` error of the lower rim's joint fit on the scenario `s`, with the true
/// upper rim as the reference, a start 2 % flat and 0.5 px off, and the far-side screen's
/// limit `max_step`.
fn lower_rim_b_error(s: Scenario, max_step: f64) -> f64 {
    let (k, camera, yaw, down, gain, gradient, seed) = s;
    let (data, w, h, rims) =
        super::super::tests::benchmark_scene(k, camera, yaw, down, gain, gradient, seed);
    let view = GrayView::new(&data, w, h).unwrap();
    let (upper, lower, start) = target_rims_and_biased_start(&rims);
    let up = Vector2::new(0.0, -1.0);
    let points = lower.sample(200, 0.3, std::f64::consts::PI - 0.3).unwrap();
    let fit = fit_partner(&view, &upper, &start, &points, up, 0.9, None, max_step).unwrap();
    (fit.ellipse.b - lower.b) / lower.b
}

#[test]
fn lower_rim_with_an_edge_beyond_its_band_is_recovered() {
    // Benchmark images 98 and 117 (seed 3): wafers seen from above whose lower rim's band
    // is followed, near the middle of the front arc, by the front edge of the carrier's
    // bottom plate beyond a dark gap. Without the far-side screen the joint fit leaves `b`
    // 1.7–1.8 % low (the pipeline's near-misses); with it, within 0.5 %.
    let images: [Scenario; 2] = [
        (
            19,
            (
                -0.44258054060903845,
                0.0043576475915637625,
                0.04846552798591182,
            ),
            1.0592861358632124,
            9.91453066962723,
            0.5039116083560223,
            [-0.22878683404651967, -0.24674263920567732],
            1860291828,
        ),
        (
            18,
            (
                -0.4545712307231655,
                -0.03130224437687722,
                0.05036261138162976,
            ),
            0.19836851218487528,
            7.65355704033987,
            0.6821719505148166,
            [0.1951579050836426, 0.02426083012358815],
            1448973671,
        ),
    ];
    for s in images {
        let without = lower_rim_b_error(s, f64::INFINITY);
        let with = lower_rim_b_error(s, MAX_FAR_SIDE_STEP);
        assert!(without < -0.01, "without the screen: b error {without}");
        assert!(with.abs() < 0.005, "with the screen: b error {with}");
    }
}

#[test]
fn clipped_lower_rims_are_recovered() {
    // Benchmark images 106, 172 and 208 (seed 3, gain 1.34–1.46): the target's side band is
    // clipped along the middle of the front arc. With bilinear samples the joint fit left `b`
    // 0.6–1.4 % high (band level pulled down by the saturated neighbours of the samples);
    // with pixel strips, censored samples and σ from the unclipped profiles, within 0.5 %.
    let images: [Scenario; 3] = [
        (
            7,
            (
                -0.506486818170594,
                -0.041943628020059825,
                0.061671723507729787,
            ),
            -2.049310280724067,
            8.7140596303066,
            1.3804598989396313,
            [-0.16950857914083065, -0.10951889998261927],
            1640619969,
        ),
        (
            13,
            (
                -0.4408921266763114,
                -0.025463002994466456,
                0.04259298503088618,
            ),
            -1.9442232564589643,
            6.108926988834359,
            1.343020952416651,
            [-0.23589133150019756, 0.2505947725096345],
            2493457385,
        ),
        (
            9,
            (
                -0.48483528167313544,
                -0.03879634828562827,
                0.06474104421044159,
            ),
            0.8620562884823153,
            8.14945727447176,
            1.4614985269444285,
            [-0.22883448409504487, -0.06894844715411247],
            908336791,
        ),
    ];
    for s in images {
        let (k, camera, yaw, down, gain, gradient, seed) = s;
        let (data, ..) =
            super::super::tests::benchmark_scene(k, camera, yaw, down, gain, gradient, seed);
        assert!(data.iter().filter(|&&v| v == 255).count() > 1000);
        let error = lower_rim_b_error(s, MAX_FAR_SIDE_STEP);
        assert!(error.abs() < 0.005, "b error {error}");
    }
}

#[test]
fn rendered_lower_rim_is_recovered_from_a_biased_start() {
    // Target wafer seen from above (renderer ground truth): the upper rim as the reference,
    // the lower rim started 2 % too flat and 0.5 px off along `up`, supported by its front
    // arc only.
    let (data, w, h, rims) = super::super::tests::scene(3, 1.0, 11);
    let view = GrayView::new(&data, w, h).unwrap();
    let (upper, lower, start) = target_rims_and_biased_start(&rims);
    let up = Vector2::new(0.0, -1.0);
    let points = lower.sample(200, 0.5, std::f64::consts::PI - 0.5).unwrap();
    let fit = fit_partner(
        &view,
        &upper,
        &start,
        &points,
        up,
        0.9,
        None,
        MAX_FAR_SIDE_STEP,
    )
    .unwrap();
    let e = fit.ellipse;
    let centre = (e.cx - lower.cx).hypot(e.cy - lower.cy);
    assert!(centre < 0.25, "centre error {centre}: {e:?} vs {lower:?}");
    assert!(
        (e.b - lower.b).abs() < 0.005 * lower.b,
        "b {} vs {}",
        e.b,
        lower.b
    );
    assert!(fit.covariance[(1, 1)] > 0.0 && fit.covariance[(1, 1)].sqrt() < 0.2);
}
