//! Tests of the radio models against independent truths: simulator parameters, dense
//! solves, closed-form GP algebra, eigenvalues.

use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

use super::grid::{ClassGrid, FREE, GridGeometry, STRUCTURE, UNKNOWN};
use super::kernel::{KernelParams, LinkKernel};
use super::logfit::LogFit;
use super::matte::{Matte, MatteOptions, MatteWeights};
use super::mrgp::Mrgp;
use super::mrt::{Mrt, MrtOptions};
use super::sim::{self, Environment, EnvironmentKind, RadioParams};
use super::tomo::{Regularization, TomoRows};
use super::{Link, REFERENCE_DISTANCE};
use crate::EstimateError;

fn random_links(rng: &mut Pcg64, n: usize, size: f64) -> Vec<Link> {
    (0..n)
        .map(|_| {
            loop {
                let l = Link {
                    tx: [rng.random_range(0.0..size), rng.random_range(0.0..size)],
                    rx: [rng.random_range(0.0..size), rng.random_range(0.0..size)],
                };
                if l.length() > 0.5 {
                    break l;
                }
            }
        })
        .collect()
}

fn min_eigenvalue(k: Vec<f64>, n: usize) -> f64 {
    let m = DMatrix::from_row_slice(n, n, &k);
    m.symmetric_eigenvalues().min()
}

/// Dense solve of the full normal equations of the stacked system (independent of the
/// bordered sparse path).
fn dense_solve(rows: &TomoRows, reg: &Regularization) -> DVector<f64> {
    let (trip, rhs) = rows.stacked(reg);
    let m = rhs.len();
    let n = rows.n + 2;
    let mut a = DMatrix::zeros(m, n);
    for (r, c, v) in trip {
        a[(r, c)] += v;
    }
    let b = DVector::from_vec(rhs);
    (a.transpose() * &a)
        .cholesky()
        .unwrap()
        .solve(&(a.transpose() * b))
}

fn small_world() -> (ClassGrid, Vec<Link>, Vec<f64>) {
    // 20 × 30 m at 0.5 m: a structure block, an unknown block, free elsewhere.
    let g = GridGeometry::new(40, 60, 0.5, [0.0, 0.0]).unwrap();
    let mut classes = vec![FREE; g.len()];
    for i in 0..g.rows {
        for j in 0..g.cols {
            let c = g.center(i, j);
            if (10.0..11.0).contains(&c[0]) && c[1] < 15.0 {
                classes[i * g.cols + j] = STRUCTURE;
            }
            if c[0] > 20.0 && c[1] > 12.0 {
                classes[i * g.cols + j] = UNKNOWN;
            }
        }
    }
    let map = ClassGrid::new(g, classes).unwrap();
    let mut rng = Pcg64::seed_from_u64(7);
    let links = random_links(&mut rng, 300, 20.0);
    let links: Vec<Link> = links
        .into_iter()
        .map(|l| Link {
            tx: [l.tx[0] * 1.45, l.tx[1]],
            rx: [l.rx[0] * 1.45, l.rx[1]],
        })
        .collect();
    let noise = Normal::new(0.0, 2.0).unwrap();
    let rss = links
        .iter()
        .map(|l| {
            let mut att = 0.0;
            g.traverse(l.tx, l.rx, |c, w| {
                att += w * [0.2, 12.0, 3.0][map.classes[c] as usize];
            });
            -40.0 - 22.0 * l.log_distance() - att + noise.sample(&mut rng)
        })
        .collect();
    (map, links, rss)
}

#[test]
fn logfit_recovers_the_simulator_path_loss() {
    // An open world (no walls, no clutter): the RSS is exactly eq. 3.1 plus shadowing.
    let g = GridGeometry::new(500, 500, 0.2, [0.0, 0.0]).unwrap();
    let env = Environment {
        name: "open",
        geometry: g,
        material: vec![0; g.len()],
        indoor: vec![false; g.len()],
        nodes: Vec::new(),
        edges: Vec::new(),
    };
    let p = RadioParams {
        correlated_share: 0.0,
        ..RadioParams::default()
    };
    let mut rng = Pcg64::seed_from_u64(3);
    let noise = Normal::new(0.0, p.sigma).unwrap();
    let links = random_links(&mut rng, 4000, 100.0);
    let rss: Vec<f64> = links
        .iter()
        .map(|l| env.mean_rss(l, &p) + noise.sample(&mut rng))
        .collect();
    let fit = LogFit::fit(&links, &rss).unwrap();
    let se_l0 = (fit.residual_variance * fit.normal_inverse[0]).sqrt();
    let se_a = (fit.residual_variance * fit.normal_inverse[3]).sqrt();
    assert!((fit.l0 - p.l0).abs() < 4.0 * se_l0, "{fit:?}");
    assert!((fit.exponent - p.exponent).abs() < 4.0 * se_a, "{fit:?}");
    assert!((fit.residual_variance.sqrt() - p.sigma).abs() < 0.2);
}

#[test]
fn tomographic_solves_equal_dense_solves() {
    let (map, links, rss) = small_world();
    let mrt = Mrt::fit([0.0, 0.0, 30.0, 20.0], &links, &rss, MrtOptions::default()).unwrap();
    let sol = mrt.solution().unwrap();
    let want = dense_solve(mrt.rows(), &mrt.regularization());
    let scale = want.amax();
    assert!((sol.l0 - want[0]).abs() < 1e-7 * scale);
    assert!((-sol.exponent - want[1]).abs() < 1e-7 * scale);
    for (k, v) in sol.values.iter().enumerate() {
        assert!(
            (v - want[k + 2]).abs() < 1e-7 * scale,
            "cell {k}: {v} vs {}",
            want[k + 2]
        );
    }
    for weights in [MatteWeights::Length, MatteWeights::Indicator] {
        let opts = MatteOptions {
            weights,
            ..MatteOptions::default()
        };
        let matte = Matte::fit(map.clone(), &links, &rss, opts).unwrap();
        let sol = matte.solution().unwrap();
        let want = dense_solve(matte.rows(), &matte.regularization());
        let scale = want.amax();
        assert!((sol.l0 - want[0]).abs() < 1e-7 * scale);
        for (k, v) in sol.values.iter().enumerate() {
            assert!((v - want[k + 2]).abs() < 1e-7 * scale);
        }
    }
}

#[test]
fn incremental_updates_equal_a_single_fit() {
    let (map, links, rss) = small_world();
    let once = Matte::fit(map.clone(), &links, &rss, MatteOptions::default()).unwrap();
    let mut inc = Matte::new(map, MatteOptions::default()).unwrap();
    inc.update(&links[..120], &rss[..120]).unwrap();
    inc.update(&links[120..], &rss[120..]).unwrap();
    let (a, b) = (once.solution().unwrap(), inc.solution().unwrap());
    assert!((a.l0 - b.l0).abs() < 1e-9);
    for (x, y) in a.values.iter().zip(&b.values) {
        assert!((x - y).abs() < 1e-9);
    }
}

#[test]
fn matte_recovers_per_class_attenuation_and_beats_the_log_fit() {
    let (map, links, rss) = small_world();
    let (train, test) = (200, 300);
    let opts = MatteOptions {
        phi: 0.01,
        lambda: 2.0,
        ..MatteOptions::default()
    };
    let m = Matte::fit(map, &links[..train], &rss[..train], opts).unwrap();
    let sol = m.solution().unwrap();
    assert!((sol.exponent - 22.0).abs() < 3.0, "{}", sol.exponent);
    let pred = m.predict(&links[train..test]).unwrap();
    let lf = LogFit::fit(&links[..train], &rss[..train]).unwrap();
    let (lpred, _) = lf.predict(&links[train..test]).unwrap();
    let rmse = |p: &[f64]| {
        (p.iter()
            .zip(&rss[train..test])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / p.len() as f64)
            .sqrt()
    };
    assert!(
        rmse(&pred[..]) < 0.5 * rmse(&lpred[..]),
        "{} vs {}",
        rmse(&pred[..]),
        rmse(&lpred[..])
    );
    assert!(rmse(&pred[..]) < 3.0, "{}", rmse(&pred[..]));
}

/// Seed slip: Algorithm 3.2 line 4 predicts `x(0) + log10 ‖p‖`, dropping the exponent.
#[test]
fn algorithm_3_2_as_printed_drops_the_exponent() {
    let (map, links, rss) = small_world();
    let m = Matte::fit(map, &links[..200], &rss[..200], MatteOptions::default()).unwrap();
    let sol = m.solution().unwrap();
    let pred = m.predict(&links[200..]).unwrap();
    let truth = &rss[200..];
    let mut e_fixed = 0.0;
    let mut e_printed = 0.0;
    for ((l, p), y) in links[200..].iter().zip(&pred).zip(truth) {
        let path = sol.l0 - sol.exponent * l.log_distance();
        let printed = sol.l0 + l.log_distance() + (p - path);
        e_fixed += (p - y).powi(2);
        e_printed += (printed - y).powi(2);
    }
    let n = truth.len() as f64;
    let (e_fixed, e_printed) = ((e_fixed / n).sqrt(), (e_printed / n).sqrt());
    assert!(e_fixed < 3.5, "{e_fixed}");
    assert!(e_printed > 5.0 * e_fixed, "{e_printed} vs {e_fixed}");
}

/// Seed slip: Algorithm 3.1 line 6 sets indicator weights, eq. 3.2 uses lengths. With a
/// constant per-class attenuation and no noise, length weights reproduce the data exactly
/// (the truth is in the model), indicator weights cannot (a cell's count does not follow the
/// link's length inside it).
#[test]
fn indicator_weights_of_algorithm_3_1_are_biased() {
    let (map, links, _) = small_world();
    let g = map.geometry;
    let rss: Vec<f64> = links
        .iter()
        .map(|l| {
            let mut att = 0.0;
            g.traverse(l.tx, l.rx, |c, w| {
                att += w * [0.0, 20.0, 5.0][map.classes[c] as usize]
            });
            -40.0 - 22.0 * l.log_distance() - att
        })
        .collect();
    let resid = |weights| {
        let opts = MatteOptions {
            weights,
            lambda: 1.0,
            phi: 1e-6,
            ..MatteOptions::default()
        };
        let m = Matte::fit(map.clone(), &links, &rss, opts).unwrap();
        let p = m.predict(&links).unwrap();
        (p.iter()
            .zip(&rss)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / p.len() as f64)
            .sqrt()
    };
    let (len, ind) = (resid(MatteWeights::Length), resid(MatteWeights::Indicator));
    assert!(len < 0.02, "length weights: {len}");
    assert!(
        ind > 10.0 * len && ind > 0.1,
        "indicator {ind} vs length {len}"
    );
}

#[test]
fn swap_average_kernel_is_positive_definite_on_random_links() {
    let mut rng = Pcg64::seed_from_u64(11);
    let p = KernelParams::default();
    for _ in 0..5 {
        let links = random_links(&mut rng, 300, 40.0);
        let k = Mrgp::kernel_matrix(&links, LinkKernel::SwapAverage, &p);
        let min = min_eigenvalue(k, links.len());
        assert!(min > -1e-10, "{min}");
    }
}

/// Eq. 3.3's d_s4 kernel: the seed calls it not positive definite in general, but no draw here
/// (nor a Nelder-Mead search over 5-link sets, `docs/design/radio.md`) found a negative
/// eigenvalue. What is checked is the guard: the MRGP's d_s4 fit succeeds exactly when the
/// kernel matrix (with the 10⁻⁶σ_f² jitter) is positive definite by an independent dense
/// eigen-decomposition, and the swap-average kernel is positive semi-definite.
#[test]
fn ds4_guard_agrees_with_dense_eigenvalues() {
    let mut rng = Pcg64::seed_from_u64(11);
    let p = KernelParams::default();
    let jitter = 1e-6 * p.sigma_f * p.sigma_f;
    for _ in 0..3 {
        let links = random_links(&mut rng, 200, 40.0);
        let swap = Mrgp::kernel_matrix(&links, LinkKernel::SwapAverage, &p);
        assert!(min_eigenvalue(swap, links.len()) > -1e-10);
        let min = min_eigenvalue(
            Mrgp::kernel_matrix(&links, LinkKernel::Ds4, &p),
            links.len(),
        );
        let rss: Vec<f64> = links
            .iter()
            .map(|l| -60.0 - 20.0 * l.log_distance())
            .collect();
        let fit = Mrgp::fit(&links, &rss, LinkKernel::Ds4, p, false);
        if min + jitter > 1e-9 {
            assert!(fit.is_ok(), "lowest eigenvalue {min}");
        } else if min + jitter < -1e-9 {
            let err = fit.unwrap_err();
            assert!(
                matches!(err, EstimateError::KernelNotPositiveDefinite { .. }),
                "{err}"
            );
        }
    }
}

#[test]
fn mrgp_sparse_predictions_equal_dense_gp_algebra() {
    let mut rng = Pcg64::seed_from_u64(5);
    let links = random_links(&mut rng, 400, 60.0);
    let noise = Normal::new(0.0, 3.0).unwrap();
    let rss: Vec<f64> = links
        .iter()
        .map(|l| {
            -40.0 - 25.0 * l.log_distance() + noise.sample(&mut rng) + (l.tx[0] / 10.0).sin() * 4.0
        })
        .collect();
    let p = KernelParams {
        length_scale: 4.0,
        sigma_f: 3.0,
        ..KernelParams::default()
    };
    let gp = Mrgp::fit(&links, &rss, LinkKernel::SwapAverage, p, false).unwrap();
    let query = random_links(&mut rng, 50, 60.0);
    let (mean, var) = gp.predict(&query, true).unwrap();
    let var = var.unwrap();
    // Dense GP algebra.
    let n = links.len();
    let k = DMatrix::from_row_slice(
        n,
        n,
        &Mrgp::kernel_matrix(&links, LinkKernel::SwapAverage, &p),
    ) + DMatrix::identity(n, n) * p.sigma_d * p.sigma_d;
    let r = DVector::from_iterator(n, links.iter().zip(&rss).map(|(l, y)| y - gp.mean.mean(l)));
    let ch = k.cholesky().unwrap();
    let alpha = ch.solve(&r);
    let mut all = links.clone();
    all.extend_from_slice(&query);
    let kall = Mrgp::kernel_matrix(&all, LinkKernel::SwapAverage, &p);
    let m = all.len();
    for (qi, q) in query.iter().enumerate() {
        let row = n + qi;
        let ks = DVector::from_iterator(n, (0..n).map(|j| kall[row * m + j]));
        let want_mean = gp.mean.mean(q) + ks.dot(&alpha);
        let want_var = kall[row * m + row] - ks.dot(&ch.solve(&ks));
        assert!(
            (mean[qi] - want_mean).abs() < 1e-8,
            "{} vs {want_mean}",
            mean[qi]
        );
        assert!((var[qi] - want_var).abs() < 1e-8);
    }
    // Log marginal likelihood.
    let logdet = 2.0 * ch.l().diagonal().map(|v| v.ln()).sum();
    let want =
        -0.5 * r.dot(&alpha) - 0.5 * logdet - 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln();
    assert!((gp.log_marginal_likelihood() - want).abs() < 1e-6 * want.abs());
}

#[test]
fn marginal_likelihood_search_finds_a_local_maximum() {
    let mut rng = Pcg64::seed_from_u64(9);
    let links = random_links(&mut rng, 500, 60.0);
    let noise = Normal::new(0.0, 2.0).unwrap();
    let rss: Vec<f64> = links
        .iter()
        .map(|l| {
            -40.0 - 25.0 * l.log_distance()
                + noise.sample(&mut rng)
                + 5.0 * ((l.tx[0] + l.rx[0]) / 15.0).sin()
        })
        .collect();
    let start = KernelParams::default();
    let gp0 = Mrgp::fit(&links, &rss, LinkKernel::SwapAverage, start, false).unwrap();
    let gp = Mrgp::fit(&links, &rss, LinkKernel::SwapAverage, start, true).unwrap();
    let best = gp.log_marginal_likelihood();
    assert!(best > gp0.log_marginal_likelihood() + 1.0);
    // The simulated noise is 2 dB, but the likelihood's maximum puts σ_d at its lower bound
    // (0.05 dB): the rough tapered kernel (Askey's taper is linear at 0, like an exponential
    // kernel) absorbs white noise between links that are sparse in the 4-D link space, so σ_d
    // is not identifiable here -- why it stays fixed (Table 3.1) unless `optimize` is asked
    // for. What is checked: the search result beats the start, and no coordinate move of ±10 %
    // that stays inside the search box improves it.
    let bounds = [(0.5, 200.0), (0.05, 50.0), (0.05, 50.0)];
    for (k, &(lo, hi)) in bounds.iter().enumerate() {
        for f in [0.9, 1.1] {
            let mut p = gp.params;
            let v = match k {
                0 => &mut p.length_scale,
                1 => &mut p.sigma_f,
                _ => &mut p.sigma_d,
            };
            *v *= f;
            if *v < lo || *v > hi {
                continue;
            }
            let other = Mrgp::fit(&links, &rss, LinkKernel::SwapAverage, p, false).unwrap();
            assert!(other.log_marginal_likelihood() < best + 0.05, "{k} {f}");
        }
    }
}

#[test]
fn bad_inputs_give_clear_errors() {
    let links = vec![
        Link {
            tx: [1.0, 1.0],
            rx: [5.0, 1.0],
        },
        Link {
            tx: [2.0, 2.0],
            rx: [2.0, 2.0],
        },
    ];
    let e = LogFit::fit(&links, &[-50.0, -60.0]).unwrap_err();
    assert!(
        matches!(e, EstimateError::CoincidentLink { index: 1, .. }),
        "{e}"
    );
    let e = LogFit::fit(&links[..1], &[f64::NAN]).unwrap_err();
    assert!(matches!(e, EstimateError::NonFiniteInput { .. }), "{e}");
    let e = LogFit::fit(&[], &[]).unwrap_err();
    assert!(matches!(e, EstimateError::EmptyInput(_)), "{e}");
    let e = Mrgp::fit(
        &[],
        &[],
        LinkKernel::SwapAverage,
        KernelParams::default(),
        false,
    )
    .unwrap_err();
    assert!(matches!(e, EstimateError::EmptyInput(_)), "{e}");
    let (map, good, rss) = small_world();
    let outside = [Link {
        tx: [1.0, 1.0],
        rx: [31.0, 5.0],
    }];
    let e = Matte::fit(map.clone(), &outside, &[-60.0], MatteOptions::default()).unwrap_err();
    assert!(matches!(e, EstimateError::OutsideMap { .. }), "{e}");
    let m = Matte::fit(map, &good, &rss, MatteOptions::default()).unwrap();
    assert!(matches!(
        m.predict(&outside).unwrap_err(),
        EstimateError::OutsideMap { .. }
    ));
    let e = Mrt::new([0.0, 0.0, 30.0, 20.0], MrtOptions::default())
        .unwrap()
        .solve()
        .unwrap_err();
    assert!(matches!(e, EstimateError::EmptyInput(_)), "{e}");
    // Same-length links: the exponent is undetermined.
    let same: Vec<Link> = (0..5)
        .map(|k| Link {
            tx: [k as f64, 0.0],
            rx: [k as f64, 3.0],
        })
        .collect();
    let e = LogFit::fit(&same, &[-50.0; 5]).unwrap_err();
    assert!(matches!(e, EstimateError::RankDeficient { .. }), "{e}");
    // Short links are clamped to the 1 m reference (documented near-field handling).
    let short = Link {
        tx: [0.0, 0.0],
        rx: [0.3, 0.0],
    };
    assert_eq!(short.log_distance(), REFERENCE_DISTANCE.log10());
}

#[test]
fn simulated_robots_stay_in_free_space_and_measure_every_pair() {
    for kind in [
        EnvironmentKind::Office,
        EnvironmentKind::Campus,
        EnvironmentKind::Mixed,
    ] {
        let env = Environment::new(kind, 1);
        let traj = sim::explore(&env, 3, 30.0, 1.0, 20.0, 2).unwrap();
        assert_eq!(traj.times.len(), 600);
        let walls_hit = traj
            .positions
            .iter()
            .flatten()
            .filter(|p| env.material[env.geometry.cell_of(**p).unwrap()] != 0)
            .count();
        assert_eq!(walls_hit, 0, "{kind:?}");
        let m = sim::measure(&env, &traj, &RadioParams::default(), 3);
        assert!(m.rss.len() > 3 * 590, "{kind:?}: {}", m.rss.len());
        let obs = sim::observe(&env, &traj, 20.0);
        let map = obs.map_at(30.0);
        let known = map.classes.iter().filter(|&&c| c != UNKNOWN).count();
        assert!(known > 1000 && known < map.classes.len(), "{kind:?}");
        // Shadowing has the requested spread.
        let d: Vec<f64> = m.rss.iter().zip(&m.mean).map(|(a, b)| a - b).collect();
        let sd = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
        assert!(sd > 2.0 && sd < 6.0, "{kind:?}: {sd}");
    }
}

/// Dense `A_vᵀA_v + λ²ΓᵀΓ + φ²I` from the stacked system (independent of the blocked
/// assembly): the spatial columns of `[A; λΓ; φI]`, squared.
fn dense_normal(rows: &TomoRows, reg: &Regularization) -> DMatrix<f64> {
    let (trip, rhs) = rows.stacked(reg);
    let mut a = DMatrix::<f64>::zeros(rhs.len(), rows.n);
    for (r, c, v) in trip {
        if c >= 2 {
            a[(r, c - 2)] += v;
        }
    }
    a.transpose() * a
}

fn assert_lower_equals_dense(s: &super::sparse::LowerCsc, want: &DMatrix<f64>) {
    let got = DMatrix::from_column_slice(s.n, s.n, &s.to_dense());
    let scale = want.amax();
    let err = (&got - want).amax();
    assert!(
        err <= 1e-12 * scale,
        "max |S − dense| = {err:e} (scale {scale})"
    );
    for c in 0..s.n {
        let col = &s.row_idx[s.col_ptr[c]..s.col_ptr[c + 1]];
        assert!(col.windows(2).all(|w| w[0] < w[1]) && col.first() == Some(&c));
    }
}

#[test]
fn blocked_normal_assembly_equals_the_dense_product() {
    let (map, links, rss) = small_world();
    let mrt = Mrt::fit([0.0, 0.0, 30.0, 20.0], &links, &rss, MrtOptions::default()).unwrap();
    let reg = mrt.regularization();
    let s = super::normal::gram_lower(mrt.rows(), &reg);
    assert_lower_equals_dense(&s, &dense_normal(mrt.rows(), &reg));
    for weights in [MatteWeights::Length, MatteWeights::Indicator] {
        let opts = MatteOptions {
            weights,
            cell: 1.5,
            ..MatteOptions::default()
        };
        let matte = Matte::fit(map.clone(), &links, &rss, opts).unwrap();
        let reg = matte.regularization();
        let s = super::normal::gram_lower(matte.rows(), &reg);
        assert_lower_equals_dense(&s, &dense_normal(matte.rows(), &reg));
    }
    // Rows longer than a block's union cap, unsorted and repeated entries, an empty row.
    let n = super::normal::WINDOW_UNION + 300;
    let mut rows = TomoRows::new(n);
    let mut rng = Pcg64::seed_from_u64(11);
    for r in 0..40 {
        let len = if r % 7 == 0 {
            n - 50
        } else {
            rng.random_range(0..60)
        };
        let first = rng.random_range(0..n - len.min(n - 1));
        let entries: Vec<(usize, f64)> = (0..len)
            .rev()
            .map(|k| ((first + k).min(n - 1), rng.random_range(0.1..2.0)))
            .collect();
        rows.push(1.0, &entries, -50.0);
    }
    let reg = Regularization {
        pairs: (0..n - 1).map(|k| (k + 1, k)).collect(),
        lambda: 0.3,
        phi: 0.1,
        prior: vec![-0.2; n],
    };
    let s = super::normal::gram_lower(&rows, &reg);
    assert_lower_equals_dense(&s, &dense_normal(&rows, &reg));
}

#[test]
fn fast_solve_equals_a_dense_solve_to_1e9_relative() {
    let (map, links, rss) = small_world();
    let rel = |sol: &super::tomo::TomoSolution, want: &DVector<f64>| {
        let mut got = vec![sol.l0, -sol.exponent];
        got.extend_from_slice(&sol.values);
        (DVector::from_vec(got) - want).norm() / want.norm()
    };
    let mrt = Mrt::fit([0.0, 0.0, 30.0, 20.0], &links, &rss, MrtOptions::default()).unwrap();
    let want = dense_solve(mrt.rows(), &mrt.regularization());
    let e = rel(mrt.solution().unwrap(), &want);
    assert!(e <= 1e-9, "MRT relative difference {e:e}");
    let matte = Matte::fit(map, &links, &rss, MatteOptions::default()).unwrap();
    let want = dense_solve(matte.rows(), &matte.regularization());
    let e = rel(matte.solution().unwrap(), &want);
    assert!(e <= 1e-9, "MATTE relative difference {e:e}");
}

#[test]
fn reused_symbolic_analysis_gives_the_cold_solution() {
    let (map, links, rss) = small_world();
    let mut m = Matte::new(map, MatteOptions::default()).unwrap();
    m.update(&links[..150], &rss[..150]).unwrap();
    assert_eq!(m.analyses(), 1);
    // New links cross new cells: the pattern grows and is analysed anew.
    m.update(&links[150..], &rss[150..]).unwrap();
    assert_eq!(m.analyses(), 2);
    // Repeated links (other RSS) add no coupling: the analysis is reused.
    let again: Vec<f64> = rss[..50].iter().map(|y| y + 1.0).collect();
    m.update(&links[..50], &again).unwrap();
    assert_eq!(m.analyses(), 2);
    let warm = m.solution().unwrap().clone();
    let cold = m.rows().solve(&m.regularization()).unwrap();
    assert!((warm.l0 - cold.l0).abs() <= 1e-12 * cold.l0.abs());
    let scale = cold.values.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for (x, y) in warm.values.iter().zip(&cold.values) {
        assert!((x - y).abs() <= 1e-12 * scale);
    }
    m.clear_factor_cache();
    m.solve().unwrap();
    assert_eq!(m.analyses(), 3);
}
