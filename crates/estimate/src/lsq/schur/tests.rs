use nalgebra::{DMatrix, Isometry3, Vector3};

use super::*;
use crate::lsq::linear::Cholesky;
use crate::lsq::solver::Structure;
use crate::lsq::synthetic::bundle_scene;
use crate::lsq::{Loss, Manifold, RelativePoseResidual};

/// The full normal equations (JᵀJ + μD) δ = −g solved densely by the block-pattern
/// assembly of the generic path, independent of the reduced system.
fn full_step(p: &Problem, bufs: &Evals, mu: f64) -> (Vec<f64>, Vec<f64>) {
    let st = Structure::new(p);
    let mut h = vec![0.0; st.pattern.nnz()];
    let mut g = vec![0.0; st.n];
    p.assemble(&st, bufs, &mut h, &mut g);
    let damp: Vec<f64> = st
        .pattern
        .diag_pos
        .iter()
        .map(|&q| h[q].clamp(1e-6, 1e32))
        .collect();
    for (c, &q) in st.pattern.diag_pos.iter().enumerate() {
        h[q] += mu * damp[c];
    }
    let mut ch = Cholesky::new(&st.pattern, true, None).unwrap();
    ch.factor(&st.pattern, &h).unwrap();
    let mut d: Vec<f64> = g.iter().map(|v| -v).collect();
    ch.solve_in_place(&mut d, st.n, 1).unwrap();
    (d, damp)
}

/// A bundle problem plus camera–camera factors (relative poses), a fixed pose, a point
/// prior (a residual on a point alone) and an SE(3) prior on a camera.
fn mixed_problem() -> Problem {
    let scene = bundle_scene(7, 60, 4, 1.0, 11);
    let (mut p, poses, points) = scene.problem(Loss::Huber(2.0), false).unwrap();
    p.set_fixed(poses[0], true).unwrap();
    let cov = DMatrix::from_diagonal_element(6, 6, 0.01);
    for w in poses.windows(2) {
        let z = Isometry3::translation(0.1, 0.0, 0.0);
        p.add_residual(
            RelativePoseResidual::new(&z, &cov).unwrap(),
            &[w[0], w[1]],
            Loss::Trivial,
        )
        .unwrap();
    }
    let x = p.values(points[3]).to_vec();
    p.add_prior(points[3], &x, &DMatrix::identity(3, 3))
        .unwrap();
    let pose_mean = p.values(poses[4]).to_vec();
    p.add_prior(poses[4], &pose_mean, &DMatrix::identity(6, 6))
        .unwrap();
    // A "stereo" residual over two cameras and one point (a point residual coupling
    // cameras directly): the difference of the point's camera-frame coordinates.
    for (a, b, x) in [(1, 2, 5), (3, 5, 7), (2, 6, 5)] {
        let r = crate::lsq::NumericDiff::new(
            3,
            vec![Manifold::Se3, Manifold::Se3, Manifold::Euclidean(3)],
            |q: &[&[f64]], out: &mut [f64]| {
                let xw = nalgebra::Point3::new(q[2][0], q[2][1], q[2][2]);
                let d =
                    crate::lsq::se3_from_params(q[0]) * xw - crate::lsq::se3_from_params(q[1]) * xw;
                out.copy_from_slice(d.as_slice());
                Ok(())
            },
        );
        p.add_residual(r, &[poses[a], poses[b], points[x]], Loss::Trivial)
            .unwrap();
    }
    p
}

/// `mixed_problem` plus a 2-D camera-side block (a pixel offset shared by the
/// observations of cameras 2 and 5: S then has 2 × 6 and 2 × 2 blocks next to the 6 × 6
/// ones) and, with `odd_point`, an eliminated 2-D block seen by two cameras (the
/// eliminated blocks then differ in size and S is accumulated point by point).
fn mixed_dims_problem(odd_point: bool) -> Problem {
    let mut p = mixed_problem();
    let k = nalgebra::Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    use crate::lsq::{BlockId, Residual};
    let offset = p.add_block(&[0.3, -0.2], Manifold::Euclidean(2)).unwrap();
    let reproj = |obs: [f64; 2]| {
        let r = crate::lsq::ReprojectionResidual::new(&k, obs, 1.0).unwrap();
        crate::lsq::NumericDiff::new(
            2,
            vec![
                Manifold::Se3,
                Manifold::Euclidean(2),
                Manifold::Euclidean(3),
            ],
            move |q: &[&[f64]], out: &mut [f64]| {
                r.evaluate(&[q[0], q[2]], out, None)?;
                out[0] += q[1][0];
                out[1] += q[1][1];
                Ok(())
            },
        )
    };
    for (cam, pt) in [(2, 1), (5, 1), (2, 9), (5, 12), (5, 13)] {
        let obs = [310.0 + pt as f64, 250.0 - cam as f64];
        p.add_residual(
            reproj(obs),
            &[BlockId(cam), offset, BlockId(7 + pt)],
            Loss::Trivial,
        )
        .unwrap();
    }
    if odd_point {
        let q = p.add_block(&[0.5, 1.5], Manifold::Euclidean(2)).unwrap();
        p.set_eliminate(q, Some(true)).unwrap();
        for cam in [3, 6] {
            let r = crate::lsq::NumericDiff::new(
                2,
                vec![Manifold::Se3, Manifold::Euclidean(2)],
                |v: &[&[f64]], out: &mut [f64]| {
                    let t = crate::lsq::se3_from_params(v[0]);
                    let x = t * nalgebra::Point3::new(v[1][0], v[1][1], 1.0);
                    out[0] = x.x - 0.2;
                    out[1] = x.y + 0.1;
                    Ok(())
                },
            );
            p.add_residual(r, &[BlockId(cam), q], Loss::Trivial)
                .unwrap();
        }
    }
    p
}

#[test]
fn reduced_camera_system_step_equals_the_full_solve() {
    assert_reduced_step_equals_full_solve(&mixed_problem());
}

#[test]
fn reduced_camera_system_with_mixed_block_sizes_equals_the_full_solve() {
    for odd_point in [false, true] {
        let p = mixed_dims_problem(odd_point);
        let sys = SchurSystem::new(&p, &Layout::new(&p), DENSE_CAMERA_LIMIT).unwrap();
        assert_eq!(sys.point_dim.is_some(), !odd_point);
        assert_reduced_step_equals_full_solve(&p);
    }
}

fn assert_reduced_step_equals_full_solve(p: &Problem) {
    let layout = Layout::new(p);
    assert!(SchurSystem::applicable(p, &layout));
    let mut bufs = p.make_buffers();
    let values = p.values.clone();
    p.evaluate_all(&values, &mut bufs, true).unwrap();
    for limit in [DENSE_CAMERA_LIMIT, 0] {
        let mut sys = SchurSystem::new(p, &layout, limit).unwrap();
        assert_eq!(sys.is_dense(), limit > 0);
        let n = layout.n;
        let (mut g, mut hdiag) = (vec![0.0; n], vec![0.0; n]);
        sys.assemble(&bufs, &mut g, &mut hdiag);
        for mu in [1e-4, 0.3, 0.0] {
            let (want, damp) = full_step(p, &bufs, mu);
            // The same diagonal of JᵀJ as the generic assembly.
            for (a, b) in hdiag.iter().zip(&damp) {
                assert!((a.clamp(1e-6, 1e32) - b).abs() <= 1e-9 * b.abs().max(1.0));
            }
            let mut delta = vec![f64::NAN; n];
            sys.solve(&bufs, mu, &damp, &mut delta).unwrap().unwrap();
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (i, (a, b)) in delta.iter().zip(&want).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-9 * scale,
                    "limit {limit} μ {mu} col {i}: {a} vs {b}"
                );
            }
        }
    }
}

#[test]
fn singular_point_block_is_reported_by_column() {
    // A point seen once (2 equations for 3 unknowns): H_pp is singular, so Gauss–Newton
    // (μ = 0) must fail at that point's column, and LM damping makes it solvable.
    let mut p = Problem::new();
    let k = nalgebra::Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    let cam = p
        .add_block(
            &crate::lsq::se3_to_params(&Isometry3::identity()),
            Manifold::Se3,
        )
        .unwrap();
    let mut pts = Vec::new();
    for i in 0..4 {
        let x = Vector3::new(0.3 * i as f64 - 0.5, 0.1 * i as f64, 4.0 + i as f64);
        pts.push(p.add_block(x.as_slice(), Manifold::Euclidean(3)).unwrap());
    }
    for (i, &b) in pts.iter().enumerate() {
        p.add_residual(
            crate::lsq::ReprojectionResidual::new(&k, [300.0 + i as f64, 200.0], 1.0).unwrap(),
            &[cam, b],
            Loss::Trivial,
        )
        .unwrap();
    }
    let layout = Layout::new(&p);
    let mut sys = SchurSystem::new(&p, &layout, DENSE_CAMERA_LIMIT).unwrap();
    let mut bufs = p.make_buffers();
    let values = p.values.clone();
    p.evaluate_all(&values, &mut bufs, true).unwrap();
    let n = layout.n;
    let (mut g, mut hdiag) = (vec![0.0; n], vec![0.0; n]);
    sys.assemble(&bufs, &mut g, &mut hdiag);
    let damp: Vec<f64> = hdiag.iter().map(|h| h.clamp(1e-6, 1e32)).collect();
    let mut delta = vec![0.0; n];
    let col = sys.solve(&bufs, 0.0, &damp, &mut delta).unwrap();
    let first_point_col = layout.col_offset[1];
    assert!(
        matches!(col, Err(Some(c)) if (first_point_col..first_point_col + 3).contains(&c)),
        "{col:?}"
    );
    assert!(sys.solve(&bufs, 1e-3, &damp, &mut delta).unwrap().is_ok());
    assert!(delta.iter().all(|v| v.is_finite()));
}
