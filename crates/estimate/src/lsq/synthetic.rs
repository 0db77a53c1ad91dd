//! Deterministic synthetic problems (bundle adjustment, chain-like pose graphs) for tests,
//! benches and peer comparisons. Random numbers come from SplitMix64 + Box–Muller, so the
//! same seed gives the same scene on every platform.

use autoteach_geometry::lie::{se3_exp, se3_plus};
use nalgebra::{DMatrix, Isometry3, Matrix3, Point3, Vector3, Vector6};

use super::loss::Loss;
use super::manifold::{Manifold, se3_to_params};
use super::problem::{BlockId, Problem};
use super::residuals::{RelativePoseResidual, ReprojectionResidual};
use crate::Result;

/// SplitMix64 with a Gaussian sampler.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator for `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A bundle-adjustment scene: ground truth, noisy observations and perturbed initial values.
#[derive(Debug, Clone)]
pub struct BundleScene {
    /// Intrinsics K.
    pub k: Matrix3<f64>,
    /// True world-to-camera poses.
    pub poses_true: Vec<Isometry3<f64>>,
    /// True points (world).
    pub points_true: Vec<Point3<f64>>,
    /// Initial poses (truth perturbed).
    pub poses_init: Vec<Isometry3<f64>>,
    /// Initial points (truth perturbed).
    pub points_init: Vec<Point3<f64>>,
    /// Observations `(pose index, point index, [u, v])`.
    pub observations: Vec<(usize, usize, [f64; 2])>,
}

/// Cameras on a ring of radius 8 m around a 4 m cube of points, looking at its centre; each
/// point is seen by `obs_per_point` cameras chosen at random; pixel noise `noise_px`;
/// initial values perturbed by ~0.02 rad / 0.1 m (poses, except the first two) and 0.1 m
/// (points).
pub fn bundle_scene(
    n_poses: usize,
    n_points: usize,
    obs_per_point: usize,
    noise_px: f64,
    seed: u64,
) -> BundleScene {
    let mut rng = Rng::new(seed);
    let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    let poses_true: Vec<Isometry3<f64>> = (0..n_poses)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n_poses.max(1) as f64;
            let eye = Point3::new(8.0 * a.cos(), 8.0 * a.sin(), 1.0 + 0.5 * (3.0 * a).sin());
            // look_at_rh builds a view matrix with −z forward; flip to the OpenCV camera
            // (z forward, y down) by a rotation of π about x.
            let view = Isometry3::look_at_rh(&eye, &Point3::origin(), &Vector3::z());
            let flip = Isometry3::rotation(Vector3::new(std::f64::consts::PI, 0.0, 0.0));
            flip * view
        })
        .collect();
    let points_true: Vec<Point3<f64>> = (0..n_points)
        .map(|_| {
            Point3::new(
                4.0 * rng.uniform() - 2.0,
                4.0 * rng.uniform() - 2.0,
                4.0 * rng.uniform() - 2.0,
            )
        })
        .collect();
    let mut observations = Vec::with_capacity(n_points * obs_per_point);
    for (j, p) in points_true.iter().enumerate() {
        let mut cams: Vec<usize> = (0..n_poses).collect();
        for i in 0..obs_per_point.min(n_poses) {
            let pick = i + ((rng.uniform() * (n_poses - i) as f64) as usize).min(n_poses - i - 1);
            cams.swap(i, pick);
            let c = cams[i];
            let pc = poses_true[c] * p;
            let u = k[(0, 0)] * pc.x / pc.z + k[(0, 2)] + noise_px * rng.normal();
            let v = k[(1, 1)] * pc.y / pc.z + k[(1, 2)] + noise_px * rng.normal();
            observations.push((c, j, [u, v]));
        }
    }
    // The first two poses start at the truth (they hold the gauge when fixed).
    let poses_init = poses_true
        .iter()
        .enumerate()
        .map(|(i, t)| {
            if i < 2 {
                return *t;
            }
            let d = Vector6::from_fn(|i, _| if i < 3 { 0.02 } else { 0.1 } * rng.normal());
            se3_plus(t, &d)
        })
        .collect();
    let points_init = points_true
        .iter()
        .map(|p| p + Vector3::from_fn(|_, _| 0.1 * rng.normal()))
        .collect();
    BundleScene {
        k,
        poses_true,
        points_true,
        poses_init,
        points_init,
        observations,
    }
}

impl BundleScene {
    /// The least-squares problem (σ = 1 px, `loss`), with the first pose (and, to fix the
    /// scale, the second) held fixed when `fix_gauge`. Returns the problem and the pose and
    /// point block ids.
    pub fn problem(
        &self,
        loss: Loss,
        fix_gauge: bool,
    ) -> Result<(Problem, Vec<BlockId>, Vec<BlockId>)> {
        let mut p = Problem::new();
        let poses = self
            .poses_init
            .iter()
            .map(|t| p.add_block(&se3_to_params(t), Manifold::Se3))
            .collect::<Result<Vec<_>>>()?;
        let points = self
            .points_init
            .iter()
            .map(|x| p.add_block(x.coords.as_slice(), Manifold::Euclidean(3)))
            .collect::<Result<Vec<_>>>()?;
        for &(c, j, uv) in &self.observations {
            p.add_residual(
                ReprojectionResidual::new(&self.k, uv, 1.0)?,
                &[poses[c], points[j]],
                loss,
            )?;
        }
        if fix_gauge {
            for b in poses.iter().take(2) {
                p.set_fixed(*b, true)?;
            }
        }
        Ok((p, poses, points))
    }
}

/// A chain-like pose graph of `n` SE(3) poses: odometry between consecutive poses plus a
/// "loop" edge from pose i to i − 5 every 10 poses, noisy measurements (σ 0.01 rad / 0.02 m),
/// initial values by composing the noisy odometry, and a prior on the first pose.
pub fn pose_graph(n: usize, seed: u64) -> Result<(Problem, Vec<BlockId>)> {
    let mut rng = Rng::new(seed);
    let truth: Vec<Isometry3<f64>> = (0..n)
        .map(|i| {
            let s = i as f64;
            se3_exp(&Vector6::new(0.0, 0.0, 0.05 * s, 0.5 * s, 0.0, 0.01 * s))
        })
        .collect();
    let sig = Vector6::new(0.01, 0.01, 0.01, 0.02, 0.02, 0.02);
    let cov = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        6,
        sig.iter().map(|s| s * s),
    ));
    let noisy = |rng: &mut Rng, z: Isometry3<f64>| {
        se3_plus(&z, &Vector6::from_fn(|i, _| sig[i] * rng.normal()))
    };
    let mut edges = Vec::new();
    for i in 1..n {
        edges.push((i - 1, i));
        if i % 10 == 0 && i >= 5 {
            edges.push((i - 5, i));
        }
    }
    let meas: Vec<Isometry3<f64>> = edges
        .iter()
        .map(|&(a, b)| noisy(&mut rng, truth[a].inverse() * truth[b]))
        .collect();
    let mut init = vec![truth[0]; n];
    for (e, &(a, b)) in edges.iter().enumerate() {
        if b == a + 1 {
            init[b] = init[a] * meas[e];
        }
    }
    let mut p = Problem::new();
    let ids = init
        .iter()
        .map(|t| p.add_block(&se3_to_params(t), Manifold::Se3))
        .collect::<Result<Vec<_>>>()?;
    for (e, &(a, b)) in edges.iter().enumerate() {
        p.add_residual(
            RelativePoseResidual::new(&meas[e], &cov)?,
            &[ids[a], ids[b]],
            Loss::Trivial,
        )?;
    }
    if let Some(first) = ids.first() {
        p.add_prior(*first, &se3_to_params(&truth[0]), &(cov.clone() * 0.01))?;
    }
    Ok((p, ids))
}
