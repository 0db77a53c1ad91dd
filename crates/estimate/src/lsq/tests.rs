//! Tests of the least-squares solver against independent truths: finite differences, closed
//! forms, dense linear algebra on the stacked Jacobian.

use autoteach_geometry::lie::{se3_exp, so3_exp};
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Vector3, Vector6};

use super::synthetic::{Rng, bundle_scene, pose_graph};
use super::*;
use crate::EstimateError;

/// Central differences of `r` on the tangent of each block, written independently of
/// `NumericDiff` (explicit loops over ⊕).
fn fd_jacobians(
    r: &dyn Residual,
    params: &[Vec<f64>],
    manifolds: &[Manifold],
) -> Vec<DMatrix<f64>> {
    let m = r.dim();
    let h = 1e-6;
    manifolds
        .iter()
        .enumerate()
        .map(|(k, man)| {
            let mut j = DMatrix::zeros(m, man.tangent_dim());
            for i in 0..man.tangent_dim() {
                let mut cols = [vec![0.0; m], vec![0.0; m]];
                for (s, col) in [h, -h].iter().zip(cols.iter_mut()) {
                    let mut d = vec![0.0; man.tangent_dim()];
                    d[i] = *s;
                    let mut moved = params.to_vec();
                    man.plus(&params[k], &d, &mut moved[k]);
                    let views: Vec<&[f64]> = moved.iter().map(|v| v.as_slice()).collect();
                    r.evaluate(&views, col, None).unwrap();
                }
                for row in 0..m {
                    j[(row, i)] = (cols[0][row] - cols[1][row]) / (2.0 * h);
                }
            }
            j
        })
        .collect()
}

fn analytic(
    r: &dyn Residual,
    params: &[Vec<f64>],
    manifolds: &[Manifold],
) -> (Vec<f64>, Vec<DMatrix<f64>>) {
    let mut res = vec![0.0; r.dim()];
    let mut jac: Vec<DMatrix<f64>> = manifolds
        .iter()
        .map(|m| DMatrix::zeros(r.dim(), m.tangent_dim()))
        .collect();
    let views: Vec<&[f64]> = params.iter().map(|v| v.as_slice()).collect();
    r.evaluate(&views, &mut res, Some(&mut jac)).unwrap();
    (res, jac)
}

fn assert_jacobians_match(r: &dyn Residual, params: &[Vec<f64>], manifolds: &[Manifold], tol: f64) {
    let (_, ja) = analytic(r, params, manifolds);
    let jf = fd_jacobians(r, params, manifolds);
    for (k, (a, f)) in ja.iter().zip(&jf).enumerate() {
        let scale = f.amax().max(1.0);
        assert!(
            (a - f).amax() <= tol * scale,
            "block {k}: analytic\n{a}\nfinite differences\n{f}"
        );
    }
}

fn pose(seed: u64) -> Isometry3<f64> {
    let mut rng = Rng::new(seed);
    se3_exp(&Vector6::from_fn(|_, _| rng.normal()))
}

#[test]
fn reprojection_jacobians_match_finite_differences() {
    let k = Matrix3::new(500.0, 0.3, 320.0, 0.0, 480.0, 240.0, 0.0, 0.0, 1.0);
    let r = ReprojectionResidual::new(&k, [300.0, 200.0], 0.7).unwrap();
    for s in 0..5 {
        let t = se3_exp(&Vector6::new(0.1 * s as f64, -0.2, 0.3, 0.1, 0.2, 0.0));
        let p_c = Vector3::new(0.3, -0.2, 4.0 + s as f64);
        let x_w = t.inverse() * nalgebra::Point3::from(p_c);
        let params = vec![se3_to_params(&t).to_vec(), x_w.coords.as_slice().to_vec()];
        assert_jacobians_match(&r, &params, &[Manifold::Se3, Manifold::Euclidean(3)], 1e-6);
    }
}

#[test]
fn relative_pose_and_prior_jacobians_match_finite_differences() {
    let cov = DMatrix::from_fn(
        6,
        6,
        |i, j| if i == j { 0.01 * (i + 1) as f64 } else { 0.001 },
    );
    for s in 0..4 {
        let a = pose(10 + s);
        let b = pose(20 + s);
        let z = a.inverse() * b * se3_exp(&Vector6::from_element(0.05));
        let r = RelativePoseResidual::new(&z, &cov).unwrap();
        let params = vec![se3_to_params(&a).to_vec(), se3_to_params(&b).to_vec()];
        assert_jacobians_match(&r, &params, &[Manifold::Se3, Manifold::Se3], 1e-6);
        // Zero at the measurement.
        let (res, _) = analytic(
            &r,
            &[params[0].clone(), se3_to_params(&(a * z)).to_vec()],
            &[Manifold::Se3, Manifold::Se3],
        );
        assert!(res.iter().all(|v| v.abs() < 1e-9));
    }
    let t = pose(3);
    let rot = t.rotation.to_rotation_matrix();
    let cases: Vec<(Manifold, Vec<f64>, Vec<f64>)> = vec![
        (Manifold::Euclidean(2), vec![1.0, 2.0], vec![0.5, -1.0]),
        (
            Manifold::So3,
            so3_to_params(&rot).to_vec(),
            so3_to_params(&(rot * so3_exp(&Vector3::new(0.3, 0.1, -0.2)))).to_vec(),
        ),
        (
            Manifold::UnitQuaternion,
            se3_to_params(&t)[..4].to_vec(),
            se3_to_params(&pose(4))[..4].to_vec(),
        ),
        (
            Manifold::Se3,
            se3_to_params(&t).to_vec(),
            se3_to_params(&pose(5)).to_vec(),
        ),
    ];
    for (m, x, mean) in cases {
        let n = m.tangent_dim();
        let cov = DMatrix::from_fn(n, n, |i, j| if i == j { 0.5 + i as f64 } else { 0.1 });
        let prior = PriorResidual::new(m, &mean, &cov).unwrap();
        assert_jacobians_match(&prior, &[x], &[m], 1e-6);
    }
}

#[test]
fn point_to_conic_jacobians_match_and_vanish_on_the_rim() {
    let k = Matrix3::new(600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0);
    let t_wo = se3_exp(&Vector6::new(0.1, -0.05, 0.2, 0.0, 0.0, 0.0));
    let t_cw = Isometry3::translation(0.01, -0.02, 0.5)
        * se3_exp(&Vector6::new(0.2, 0.1, 0.0, 0.0, 0.0, 0.0));
    let radius = 0.15;
    for s in 0..6 {
        let phi = s as f64;
        let rim = t_cw * t_wo * nalgebra::Point3::new(radius * phi.cos(), radius * phi.sin(), 0.0);
        let uv = [600.0 * rim.x / rim.z + 320.0, 600.0 * rim.y / rim.z + 240.0];
        let r = PointToConicResidual::new(&k, radius, uv, 1.0).unwrap();
        let params = vec![se3_to_params(&t_cw).to_vec(), se3_to_params(&t_wo).to_vec()];
        let (res, _) = analytic(&r, &params, &[Manifold::Se3, Manifold::Se3]);
        assert!(res[0].abs() < 1e-10, "on-rim residual {}", res[0]);
        let off = PointToConicResidual::new(&k, radius, [uv[0] + 3.0, uv[1] - 2.0], 1.0).unwrap();
        assert_jacobians_match(&off, &params, &[Manifold::Se3, Manifold::Se3], 1e-6);
    }
}

/// r = A x − b over two Euclidean blocks.
struct Linear {
    a: DMatrix<f64>,
    b: DVector<f64>,
}

impl Residual for Linear {
    fn dim(&self) -> usize {
        self.b.len()
    }
    fn evaluate(
        &self,
        p: &[&[f64]],
        r: &mut [f64],
        j: Option<&mut [DMatrix<f64>]>,
    ) -> std::result::Result<(), EstimateError> {
        let x = DVector::from_iterator(5, p[0].iter().chain(p[1].iter()).copied());
        let v = &self.a * x - &self.b;
        r.copy_from_slice(v.as_slice());
        if let Some(j) = j {
            j[0].copy_from(&self.a.columns(0, 2));
            j[1].copy_from(&self.a.columns(2, 3));
        }
        Ok(())
    }
}

#[test]
fn linear_problem_matches_the_closed_form_for_every_solver() {
    let mut rng = Rng::new(7);
    let a = DMatrix::from_fn(12, 5, |_, _| rng.normal());
    let b = DVector::from_fn(12, |_, _| rng.normal());
    let want = (a.transpose() * &a)
        .cholesky()
        .unwrap()
        .solve(&(a.transpose() * &b));
    for (method, solver) in [
        (Method::GaussNewton, LinearSolver::DenseCholesky),
        (Method::LevenbergMarquardt, LinearSolver::DenseCholesky),
        (Method::LevenbergMarquardt, LinearSolver::SparseCholesky),
        (Method::GaussNewton, LinearSolver::SparseSchur),
    ] {
        let mut p = Problem::new();
        let x0 = p.add_block(&[0.0, 0.0], Manifold::Euclidean(2)).unwrap();
        let x1 = p
            .add_block(&[0.0, 0.0, 0.0], Manifold::Euclidean(3))
            .unwrap();
        p.add_residual(
            Linear {
                a: a.clone(),
                b: b.clone(),
            },
            &[x0, x1],
            Loss::Trivial,
        )
        .unwrap();
        let opts = SolverOptions {
            method,
            linear_solver: solver,
            ..Default::default()
        };
        let s = p.solve(&opts).unwrap();
        let got: Vec<f64> = p.values(x0).iter().chain(p.values(x1)).copied().collect();
        for i in 0..5 {
            assert!(
                (got[i] - want[i]).abs() < 1e-9,
                "{method:?}/{solver:?}: {got:?} vs {want}"
            );
        }
        assert!(s.termination.converged(), "{s:?}");
        if method == Method::GaussNewton {
            assert!(s.successful_steps <= 2, "{s:?}");
        }
        let rmin = &a * &want - &b;
        assert!((s.final_cost - 0.5 * rmin.norm_squared()).abs() < 1e-9);
        // Covariance = (AᵀA)⁻¹.
        let cov = p.marginal_covariance(&[x1, x0]).unwrap();
        let inv = (a.transpose() * &a).try_inverse().unwrap();
        let order = [2, 3, 4, 0, 1];
        for i in 0..5 {
            for j in 0..5 {
                assert!((cov[(i, j)] - inv[(order[i], order[j])]).abs() < 1e-12);
            }
        }
    }
}

/// Stacks the whitened Jacobian of all residuals w.r.t. the free blocks (independently of
/// the solver's assembly) and returns (JᵀJ)⁻¹ by dense LU.
fn dense_covariance(p: &Problem, free: &[BlockId]) -> DMatrix<f64> {
    let offs: Vec<usize> = free
        .iter()
        .scan(0, |o, b| {
            let r = *o;
            *o += p.manifold(*b).unwrap().tangent_dim();
            Some(r)
        })
        .collect();
    let n: usize = free
        .iter()
        .map(|b| p.manifold(*b).unwrap().tangent_dim())
        .sum();
    let mut rows = Vec::new();
    for res in &p.residuals {
        let m = res.residual.dim();
        let params: Vec<Vec<f64>> = res.blocks.iter().map(|b| p.values(*b).to_vec()).collect();
        let mans: Vec<Manifold> = res.blocks.iter().map(|b| p.manifold(*b).unwrap()).collect();
        let (_, jac) = analytic(res.residual.as_ref(), &params, &mans);
        let mut row = DMatrix::zeros(m, n);
        for (k, b) in res.blocks.iter().enumerate() {
            if let Some(f) = free.iter().position(|x| x == b) {
                row.view_mut((0, offs[f]), (m, jac[k].ncols()))
                    .copy_from(&jac[k]);
            }
        }
        rows.push(row);
    }
    let total: usize = rows.iter().map(|r| r.nrows()).sum();
    let mut j = DMatrix::zeros(total, n);
    let mut r0 = 0;
    for r in rows {
        j.view_mut((r0, 0), (r.nrows(), n)).copy_from(&r);
        r0 += r.nrows();
    }
    (j.transpose() * j).lu().try_inverse().unwrap()
}

#[test]
fn bundle_adjustment_solvers_agree_and_covariance_equals_dense_inverse() {
    let scene = bundle_scene(6, 40, 4, 1.0, 3);
    let mut costs = Vec::new();
    for solver in [
        LinearSolver::DenseCholesky,
        LinearSolver::SparseCholesky,
        LinearSolver::SparseSchur,
    ] {
        let (mut p, poses, points) = scene.problem(Loss::Trivial, true).unwrap();
        let opts = SolverOptions {
            linear_solver: solver,
            ..Default::default()
        };
        let s = p.solve(&opts).unwrap();
        assert!(s.termination.converged(), "{solver:?}: {s:?}");
        assert!(s.final_cost < 0.01 * s.initial_cost, "{s:?}");
        // Near the noise floor: E[2·cost] = m − n for 1 px noise.
        let dof = (s.num_residuals - s.num_parameters) as f64;
        assert!((2.0 * s.final_cost / dof - 1.0).abs() < 0.3, "{s:?}");
        costs.push(s.final_cost);
        if solver == LinearSolver::SparseSchur {
            assert_eq!(s.num_eliminated_blocks, 40);
            let free: Vec<BlockId> = poses[2..].iter().chain(&points).copied().collect();
            let want = dense_covariance(&p, &free);
            let sel = [poses[3], points[5], poses[5]];
            let got = p.marginal_covariance(&sel).unwrap();
            let offs = |b: BlockId| -> usize {
                free.iter()
                    .take_while(|x| **x != b)
                    .map(|x| p.manifold(*x).unwrap().tangent_dim())
                    .sum()
            };
            let mut idx = Vec::new();
            for b in sel {
                let o = offs(b);
                idx.extend(o..o + p.manifold(b).unwrap().tangent_dim());
            }
            let scale = want.amax();
            for (i, &ii) in idx.iter().enumerate() {
                for (j, &jj) in idx.iter().enumerate() {
                    assert!(
                        (got[(i, j)] - want[(ii, jj)]).abs() <= 1e-8 * scale,
                        "({i},{j}): {} vs {}",
                        got[(i, j)],
                        want[(ii, jj)]
                    );
                }
            }
            // Fixed blocks have zero covariance.
            assert_eq!(
                p.marginal_covariance(&[poses[0]]).unwrap(),
                DMatrix::zeros(6, 6)
            );
        }
    }
    for c in &costs {
        assert!((c / costs[0] - 1.0).abs() < 1e-9, "{costs:?}");
    }
}

#[test]
fn sparse_covariance_of_a_long_pose_graph_equals_dense_inverse() {
    // 110 poses: 660 unknowns, beyond the dense-eigen limit, so the sparse factor is used.
    let (mut p, ids) = pose_graph(110, 5).unwrap();
    let s = p.solve(&SolverOptions::default()).unwrap();
    assert!(s.termination.converged(), "{s:?}");
    assert_eq!(s.linear_solver, LinearSolver::SparseCholesky);
    let want = dense_covariance(&p, &ids);
    let got = p.marginal_covariance(&[ids[50], ids[109]]).unwrap();
    let idx: Vec<usize> = (300..306).chain(654..660).collect();
    let scale = want.amax();
    for (i, &ii) in idx.iter().enumerate() {
        for (j, &jj) in idx.iter().enumerate() {
            assert!((got[(i, j)] - want[(ii, jj)]).abs() <= 1e-8 * scale);
        }
    }
}

#[test]
fn gauge_freedom_is_reported_not_returned() {
    // Bundle adjustment without fixed poses: 7 gauge directions (dense analysis).
    let scene = bundle_scene(5, 30, 4, 1.0, 11);
    let (mut p, poses, _) = scene.problem(Loss::Trivial, false).unwrap();
    let s = p.solve(&SolverOptions::default()).unwrap();
    assert!(
        s.final_cost < 0.01 * s.initial_cost,
        "LM copes with the gauge: {s:?}"
    );
    match p.marginal_covariance(&[poses[1]]) {
        Err(EstimateError::RankDeficient { what, directions }) => {
            assert!(what.contains("7 null"), "{what}");
            assert!(directions.contains("block"), "{directions}");
        }
        other => panic!("expected RankDeficient, got {other:?}"),
    }
    // A pose graph without a prior: 6 gauge directions, found from the sparse pivots.
    let (mut g, ids) = pose_graph(110, 2).unwrap();
    let prior = g.residuals.len() - 1;
    g.residuals.remove(prior);
    assert!(matches!(
        g.marginal_covariance(&[ids[3]]),
        Err(EstimateError::RankDeficient { .. })
    ));
    // Gauss–Newton stops with a reason instead of returning garbage.
    let gn = SolverOptions {
        method: Method::GaussNewton,
        linear_solver: LinearSolver::DenseCholesky,
        ..Default::default()
    };
    let mut single = Problem::new();
    let a = single
        .add_block(&[1.0, 2.0], Manifold::Euclidean(2))
        .unwrap();
    let b = single.add_block(&[0.0], Manifold::Euclidean(1)).unwrap();
    // Only a + b constrained... r = a0 + a1 − 1: rank 1 in 2 unknowns.
    single
        .add_residual(
            NumericDiff::new(
                1,
                vec![Manifold::Euclidean(2)],
                |p: &[&[f64]], r: &mut [f64]| {
                    r[0] = p[0][0] + p[0][1] - 1.0;
                    Ok(())
                },
            ),
            &[a],
            Loss::Trivial,
        )
        .unwrap();
    let err = single.marginal_covariance(&[a]).unwrap_err();
    assert!(matches!(err, EstimateError::RankDeficient { .. }), "{err}");
    // Block b has no residual at all: named as unconstrained.
    let err = single.marginal_covariance(&[b]).unwrap_err().to_string();
    assert!(err.contains("block 1"), "{err}");
    let s = single.solve(&gn).unwrap();
    assert_eq!(s.termination, Termination::LinearSolverFailure, "{s:?}");
    assert!(s.message.contains("block"), "{}", s.message);
}

/// 1-D residual x − c that becomes NaN for x > limit.
struct Fragile {
    c: f64,
    limit: f64,
}

impl Residual for Fragile {
    fn dim(&self) -> usize {
        1
    }
    fn evaluate(
        &self,
        p: &[&[f64]],
        r: &mut [f64],
        j: Option<&mut [DMatrix<f64>]>,
    ) -> std::result::Result<(), EstimateError> {
        let x = p[0][0];
        r[0] = if x > self.limit { f64::NAN } else { x - self.c };
        if let Some(j) = j {
            j[0][(0, 0)] = 1.0;
        }
        Ok(())
    }
}

#[test]
fn non_finite_residuals_are_errors_at_the_start_and_rejected_steps_during_the_solve() {
    let mut p = Problem::new();
    let x = p.add_block(&[5.0], Manifold::Euclidean(1)).unwrap();
    p.add_residual(Fragile { c: 0.0, limit: 1.0 }, &[x], Loss::Trivial)
        .unwrap();
    let err = p.solve(&SolverOptions::default()).unwrap_err();
    assert!(
        matches!(err, EstimateError::NonFiniteResidual { residual: 0, .. }),
        "{err}"
    );
    // The minimum (x = 3) lies in the NaN region: LM stops at the boundary with a reason.
    let mut p = Problem::new();
    let x = p.add_block(&[0.0], Manifold::Euclidean(1)).unwrap();
    p.add_residual(Fragile { c: 3.0, limit: 1.0 }, &[x], Loss::Trivial)
        .unwrap();
    let s = p
        .solve(&SolverOptions {
            max_iterations: 200,
            ..Default::default()
        })
        .unwrap();
    assert!(
        p.values(x)[0] <= 1.0 && p.values(x)[0] > 0.99,
        "{:?} {s:?}",
        p.values(x)
    );
    assert!(s.final_cost.is_finite());
    assert!(
        !s.termination.converged() || s.termination == Termination::ParameterTolerance,
        "{s:?}"
    );
    assert!(!s.message.is_empty());
}

#[test]
fn bad_inputs_are_rejected_with_clear_errors() {
    let mut p = Problem::new();
    assert!(matches!(
        p.add_block(&[1.0, 0.0, 0.0], Manifold::Se3),
        Err(EstimateError::DimensionMismatch { .. })
    ));
    assert!(p.add_block(&[f64::NAN], Manifold::Euclidean(1)).is_err());
    let a = p.add_block(&[0.0, 0.0], Manifold::Euclidean(2)).unwrap();
    assert!(p.set_fixed(BlockId(9), true).is_err());
    assert!(p.set_values(a, &[1.0]).is_err());
    let lin = || Linear {
        a: DMatrix::identity(5, 5),
        b: DVector::zeros(5),
    };
    assert!(matches!(
        p.add_residual(lin(), &[a, BlockId(4)], Loss::Trivial),
        Err(EstimateError::InvalidProblem(_))
    ));
    assert!(matches!(
        p.add_residual(lin(), &[a, a], Loss::Trivial),
        Err(EstimateError::InvalidProblem(_))
    ));
    assert!(p.add_residual(lin(), &[a], Loss::Huber(-1.0)).is_err());
    assert!(
        p.add_prior(a, &[0.0, 0.0], &DMatrix::identity(3, 3))
            .is_err()
    );
    let not_pd = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
    assert!(matches!(
        p.add_prior(a, &[0.0, 0.0], &not_pd),
        Err(EstimateError::InvalidCovariance { .. })
    ));
    assert!(p.marginal_covariance(&[a, a]).is_err());
    assert!(p.marginal_covariance(&[BlockId(7)]).is_err());
    let bad = SolverOptions {
        function_tolerance: f64::NAN,
        ..Default::default()
    };
    assert!(p.solve(&bad).is_err());
    let k_bad = Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    assert!(ReprojectionResidual::new(&k_bad, [0.0, 0.0], 1.0).is_err());
    assert!(ReprojectionResidual::new(&Matrix3::identity(), [0.0, 0.0], 0.0).is_err());
    // A residual whose point is behind the camera is an error at the start.
    let mut q = Problem::new();
    let cam = q
        .add_block(&se3_to_params(&Isometry3::identity()), Manifold::Se3)
        .unwrap();
    let pt = q
        .add_block(&[0.0, 0.0, -1.0], Manifold::Euclidean(3))
        .unwrap();
    q.add_residual(
        ReprojectionResidual::new(&Matrix3::identity(), [0.0, 0.0], 1.0).unwrap(),
        &[cam, pt],
        Loss::Trivial,
    )
    .unwrap();
    assert!(q.solve(&SolverOptions::default()).is_err());
    // All blocks fixed: nothing to do, said so.
    let mut r = Problem::new();
    let z = r.add_block(&[1.0], Manifold::Euclidean(1)).unwrap();
    r.add_residual(Fragile { c: 0.0, limit: 9.0 }, &[z], Loss::Trivial)
        .unwrap();
    r.set_fixed(z, true).unwrap();
    let s = r.solve(&SolverOptions::default()).unwrap();
    assert_eq!(s.termination, Termination::NoFreeParameters);
    assert_eq!(r.values(z), &[1.0]);
}

#[test]
fn robust_losses_reach_a_stationary_point_of_the_robust_cost_and_resist_outliers() {
    // Fit a line y = a x + b with 20% gross outliers.
    let mut rng = Rng::new(9);
    let pts: Vec<(f64, f64)> = (0..50)
        .map(|i| {
            let x = i as f64 / 10.0;
            let y = 2.0 * x - 1.0 + 0.05 * rng.normal() + if i % 5 == 0 { 8.0 } else { 0.0 };
            (x, y)
        })
        .collect();
    for loss in [Loss::Huber(0.1), Loss::Cauchy(0.1), Loss::Tukey(0.5)] {
        let mut p = Problem::new();
        let ab = p.add_block(&[1.8, -0.8], Manifold::Euclidean(2)).unwrap();
        for &(x, y) in &pts {
            p.add_residual(
                NumericDiff::new(
                    1,
                    vec![Manifold::Euclidean(2)],
                    move |q: &[&[f64]], r: &mut [f64]| {
                        r[0] = q[0][0] * x + q[0][1] - y;
                        Ok(())
                    },
                ),
                &[ab],
                loss,
            )
            .unwrap();
        }
        let s = p
            .solve(&SolverOptions {
                max_iterations: 500,
                ..Default::default()
            })
            .unwrap();
        let v = p.values(ab).to_vec();
        assert!(
            (v[0] - 2.0).abs() < 0.05 && (v[1] + 1.0).abs() < 0.1,
            "{loss:?}: {v:?} {s:?}"
        );
        // Stationary point of ½ Σ ρ(r²): no small move decreases the cost.
        let cost = |a: f64, b: f64| -> f64 {
            pts.iter()
                .map(|&(x, y)| 0.5 * loss.evaluate((a * x + b - y).powi(2))[0])
                .sum()
        };
        assert!((cost(v[0], v[1]) - s.final_cost).abs() < 1e-12);
        for (da, db) in [(1e-5, 0.0), (-1e-5, 0.0), (0.0, 1e-5), (0.0, -1e-5)] {
            assert!(
                cost(v[0] + da, v[1] + db) >= s.final_cost - 1e-10,
                "{loss:?}"
            );
        }
    }
}

#[test]
fn rotation_blocks_converge_to_the_karcher_mean_and_fixed_blocks_stay() {
    let base = so3_exp(&Vector3::new(0.4, -0.2, 0.9));
    let means: Vec<_> = [
        Vector3::new(0.1, 0.0, 0.0),
        Vector3::new(-0.05, 0.12, 0.0),
        Vector3::new(0.0, -0.07, 0.2),
    ]
    .iter()
    .map(|d| base * so3_exp(d))
    .collect();
    for m in [Manifold::So3, Manifold::UnitQuaternion] {
        let to = |r: &nalgebra::Rotation3<f64>| -> Vec<f64> {
            match m {
                Manifold::So3 => so3_to_params(r).to_vec(),
                _ => {
                    let q = nalgebra::UnitQuaternion::from_rotation_matrix(r);
                    vec![q.w, q.i, q.j, q.k]
                }
            }
        };
        let mut p = Problem::new();
        let x = p
            .add_block(&to(&nalgebra::Rotation3::identity()), m)
            .unwrap();
        let fixed = p.add_block(&to(&base), m).unwrap();
        p.set_fixed(fixed, true).unwrap();
        for mu in &means {
            p.add_prior(x, &to(mu), &DMatrix::identity(3, 3)).unwrap();
        }
        let before = p.values(fixed).to_vec();
        let s = p.solve(&SolverOptions::default()).unwrap();
        assert!(s.termination.converged(), "{s:?}");
        // Karcher mean: Σ Log(μᵢ⁻¹ R) = 0.
        let mut sum = vec![0.0; 3];
        for mu in &means {
            let mut d = [0.0; 3];
            m.minus(p.values(x), &to(mu), &mut d);
            sum.iter_mut().zip(d).for_each(|(s, v)| *s += v);
        }
        assert!(sum.iter().all(|v| v.abs() < 1e-8), "{m:?}: {sum:?}");
        assert_eq!(p.values(fixed), before.as_slice());
    }
}

#[test]
fn numeric_diff_matches_the_analytic_reprojection() {
    let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    let analytic_r = ReprojectionResidual::new(&k, [310.0, 250.0], 1.0).unwrap();
    let inner = analytic_r.clone();
    let numeric = NumericDiff::new(
        2,
        vec![Manifold::Se3, Manifold::Euclidean(3)],
        move |p: &[&[f64]], r: &mut [f64]| inner.evaluate(p, r, None),
    );
    let t = pose(8);
    let x = t.inverse() * nalgebra::Point3::new(0.1, 0.2, 3.0);
    let params = vec![se3_to_params(&t).to_vec(), x.coords.as_slice().to_vec()];
    let mans = [Manifold::Se3, Manifold::Euclidean(3)];
    let (_, ja) = analytic(&analytic_r, &params, &mans);
    let (_, jn) = analytic(&numeric, &params, &mans);
    for (a, n) in ja.iter().zip(&jn) {
        assert!((a - n).amax() < 1e-5 * a.amax().max(1.0), "{a}\n{n}");
    }
}

#[test]
fn residual_on_blocks_of_the_wrong_manifold_is_refused() {
    // Regression: a relative pose between two Euclidean 3-vectors was accepted, and the solve
    // then indexed past the blocks' values and panicked.
    let cov = DMatrix::identity(6, 6);
    let r = RelativePoseResidual::new(&Isometry3::identity(), &cov).unwrap();
    let mut p = Problem::new();
    let a = p
        .add_block(&[0.0, 0.0, 0.0], Manifold::Euclidean(3))
        .unwrap();
    let b = p
        .add_block(&[1.0, 0.0, 0.0], Manifold::Euclidean(3))
        .unwrap();
    let err = p
        .add_residual(r.clone(), &[a, b], Loss::Trivial)
        .unwrap_err();
    assert!(
        matches!(err, EstimateError::InvalidProblem(ref m) if m.contains("needs Se3")),
        "{err}"
    );
    let c = p
        .add_block(&se3_to_params(&Isometry3::identity()), Manifold::Se3)
        .unwrap();
    let err = p.add_residual(r.clone(), &[c], Loss::Trivial).unwrap_err();
    assert!(
        matches!(err, EstimateError::InvalidProblem(ref m) if m.contains("reads 2 blocks")),
        "{err}"
    );
    let d = p
        .add_block(&se3_to_params(&pose(3)), Manifold::Se3)
        .unwrap();
    assert!(p.add_residual(r, &[c, d], Loss::Trivial).is_ok());
}
