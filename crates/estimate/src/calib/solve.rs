//! The joint calibration solve (004_815695db12a6b16c.txt eqs. 5.1–5.2): sparse nonlinear least
//! squares over the intrinsics and every target pose with the bootstrapping schedule of
//! ch. 5.2, robust loss and outlier reporting, and the intrinsics' marginal covariance
//! (eqs. 5.3–5.5) from the solver's information matrix.

use std::sync::Arc;

use autoteach_geometry::camera::{Camera, CameraModel};
use nalgebra::{DMatrix, Isometry3, Point3};

use super::ere::{
    MaxEre, covariance_sqrt, error_map, max_ere, sample_cameras, standard_draws, test_grid,
};
use super::guide::{candidate_poses, score_candidates, visible_points};
use super::init::{initialise, pose_for_view};
use super::residual::{
    ReprojectionResidual, param_groups, pose_from_params, pose_to_params, view_information,
};
use super::{View, default_sigma};
use crate::lsq::{self, BlockId, Manifold, Problem, SolverOptions};
use crate::{EstimateError, Result};

impl lsq::Residual for ReprojectionResidual {
    fn dim(&self) -> usize {
        ReprojectionResidual::dim(self)
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        self.eval(params, residual, jacobians)
    }
}

/// Robust loss on the pixel residual of one point (scales in pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobustLoss {
    /// Plain least squares (what OpenCV's `calibrateCamera` minimises).
    Trivial,
    /// Huber loss with the given scale (pixels).
    Huber(f64),
    /// Cauchy loss with the given scale (pixels).
    Cauchy(f64),
}

/// Options of [`calibrate`].
#[derive(Debug, Clone, PartialEq)]
pub struct CalibOptions {
    /// The lens model.
    pub model: CameraModel,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Detector noise σ_z in pixels; `None` for eq. 5.6, `7·10⁻⁵ × width`.
    pub sigma_z: Option<f64>,
    /// Loss of the final solve (after outlier rejection).
    pub loss: RobustLoss,
    /// Points whose reprojection error exceeds this (pixels) after the first solve are reported
    /// as outliers and left out; `None`: 5 × the robust noise scale
    /// `median(‖r‖)/1.1774` (the Rayleigh median), never below 5 σ_z; `Some(inf)`: keep all.
    pub outlier_threshold: Option<f64>,
    /// Follow the bootstrapping schedule of ch. 5.2 (focal lengths only first; release the
    /// principal point and the first radial pair with the second view and everything from the
    /// third); `false` releases everything at once (after the focal-only warm-up).
    pub bootstrap: bool,
    /// Start from these parameters (e.g. the previous calibration of a live session) instead of
    /// the homography initialisation.
    pub initial_params: Option<Vec<f64>>,
    /// Maximum solver iterations per stage.
    pub max_iterations: usize,
}

impl CalibOptions {
    /// Defaults for `model` and an image of `width × height`: σ_z from eq. 5.6, automatic
    /// outlier rejection then plain least squares, bootstrapping on, 100 iterations per stage.
    pub fn new(model: CameraModel, width: u32, height: u32) -> Self {
        Self {
            model,
            width,
            height,
            sigma_z: None,
            loss: RobustLoss::Trivial,
            outlier_threshold: None,
            bootstrap: true,
            initial_params: None,
            max_iterations: 100,
        }
    }
}

/// A calibration: intrinsics, their marginal covariance, target poses and fit statistics.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The calibrated camera.
    pub camera: Camera,
    /// Which parameters were estimated (the others are held at their restricted values by the
    /// bootstrapping schedule).
    pub free: Vec<bool>,
    /// Marginal covariance of the intrinsics (n×n, parameter order of the model; zero rows and
    /// columns for fixed parameters), from eqs. 5.3–5.5 with detector noise `sigma_z`.
    pub covariance: DMatrix<f64>,
    /// Target pose `T_ct` (target → camera) of each view.
    pub poses: Vec<Isometry3<f64>>,
    /// The views used (outliers removed from them).
    pub views: Vec<View>,
    /// Per-view RMS reprojection error (pixels) over inliers.
    pub view_rms: Vec<f64>,
    /// Total RMS reprojection error (pixels) over inliers.
    pub rms: f64,
    /// Outliers as `(view, point row index)`.
    pub outliers: Vec<(usize, usize)>,
    /// Detector noise σ_z used for the covariance (pixels).
    pub sigma_z: f64,
    /// Solver iterations of the final stage.
    pub iterations: usize,
    /// Final cost ½ Σ ‖r/σ_z‖².
    pub final_cost: f64,
}

/// Bootstrapping schedule (004_815695db12a6b16c.txt ch. 5.2, "start with a restricted camera
/// model with very few parameters, relaxing to the full model as new images of the target are
/// added … fully constrained (typically after 3 images)"): which parameter groups of
/// [`param_groups`] are free with `views` views.
pub fn free_groups(model: CameraModel, views: usize) -> Vec<bool> {
    let g = param_groups(model).len();
    (0..g)
        .map(|i| match views {
            0 | 1 => i == 0,
            2 => i <= 2,
            _ => true,
        })
        .collect()
}

struct Built {
    problem: Problem,
    groups: Vec<BlockId>,
    poses: Vec<BlockId>,
}

#[allow(clippy::too_many_arguments)]
fn build(
    opts: &CalibOptions,
    sigma: f64,
    views: &[View],
    params: &[f64],
    poses: &[Isometry3<f64>],
    free: &[bool],
    loss: RobustLoss,
) -> Result<Built> {
    let groups = Arc::new(param_groups(opts.model));
    let mut problem = Problem::new();
    let mut gids = Vec::with_capacity(groups.len());
    for (grp, &f) in groups.iter().zip(free) {
        let vals: Vec<f64> = grp.iter().map(|&i| params[i]).collect();
        let id = problem.add_block(&vals, Manifold::Euclidean(grp.len()))?;
        problem.set_fixed(id, !f)?;
        gids.push(id);
    }
    let camera = Camera::new(opts.model, params, opts.width, opts.height)?;
    let mut pids = Vec::with_capacity(views.len());
    for (v, pose) in views.iter().zip(poses) {
        let pid = problem.add_block(&pose_to_params(pose), Manifold::Se3)?;
        // Each view's residuals touch the intrinsics and this pose only: H_pp is block
        // diagonal over the poses, which the Schur complement eliminates (see `solver_options`).
        problem.set_eliminate(pid, Some(true))?;
        pids.push(pid);
        let mut blocks = gids.clone();
        blocks.push(pid);
        // Points that do not project at the current estimate (e.g. behind the camera under a
        // rough bootstrap initialisation near the edges of a strongly distorted lens) sit out
        // this stage; later stages and the outlier check see them again.
        let (plane, image): (Vec<[f64; 2]>, Vec<[f64; 2]>) = v
            .plane
            .iter()
            .zip(&v.image)
            .filter(|(pl, _)| {
                camera
                    .project(&(pose * Point3::new(pl[0], pl[1], 0.0)).coords)
                    .is_ok()
            })
            .map(|(a, b)| (*a, *b))
            .unzip();
        if plane.len() < super::MIN_POINTS {
            problem.set_fixed(pid, true)?;
            continue;
        }
        let mk = |plane: Vec<[f64; 2]>, image: Vec<[f64; 2]>| {
            ReprojectionResidual::new(
                opts.model,
                opts.width,
                opts.height,
                groups.clone(),
                plane,
                image,
                sigma,
            )
        };
        match loss {
            RobustLoss::Trivial => {
                problem.add_residual(mk(plane, image)?, &blocks, lsq::Loss::Trivial)?;
            }
            RobustLoss::Huber(s) | RobustLoss::Cauchy(s) => {
                let scale = s / sigma;
                for (pl, im) in plane.iter().zip(&image) {
                    let l = if matches!(loss, RobustLoss::Huber(_)) {
                        lsq::Loss::Huber(scale)
                    } else {
                        lsq::Loss::Cauchy(scale)
                    };
                    problem.add_residual(mk(vec![*pl], vec![*im])?, &blocks, l)?;
                }
            }
        }
    }
    Ok(Built {
        problem,
        groups: gids,
        poses: pids,
    })
}

fn read_back(b: &Built, model: CameraModel) -> Result<(Vec<f64>, Vec<Isometry3<f64>>)> {
    let groups = param_groups(model);
    let mut params = vec![0.0; model.num_params()];
    for (grp, id) in groups.iter().zip(&b.groups) {
        for (&i, &v) in grp.iter().zip(b.problem.values(*id)) {
            params[i] = v;
        }
    }
    let poses = b
        .poses
        .iter()
        .map(|id| pose_from_params(b.problem.values(*id)))
        .collect::<Result<Vec<_>>>()?;
    Ok((params, poses))
}

/// Relative cost decrease that ends the focal-length-only stage A of [`calibrate`] (a start for
/// stage B, not a result: 1e-6 of the cost is far below what moves stage B's start out of its
/// basin).
const STAGE_A_FUNCTION_TOLERANCE: f64 = 1e-6;

/// The solver of every calibration stage: Levenberg–Marquardt on eqs. 5.1–5.2 with the target
/// poses eliminated by the Schur complement (their 6×6 blocks of the normal equations are
/// independent), so only the reduced intrinsics system (at most 9 × 9 for Brown–Conrady) is
/// factored instead of the dense `9 + 6·views` system: the same damped step, without the cubic
/// cost in the number of views.
fn solver_options(max_iterations: usize) -> SolverOptions {
    SolverOptions {
        max_iterations,
        linear_solver: lsq::LinearSolver::SparseSchur,
        function_tolerance: 1e-16,
        gradient_tolerance: 1e-14,
        parameter_tolerance: 1e-14,
        ..SolverOptions::default()
    }
}

/// Per-point reprojection errors (pixel vectors) of every view; +inf for points that do not
/// project.
fn reprojection_errors(
    camera: &Camera,
    views: &[View],
    poses: &[Isometry3<f64>],
) -> Vec<Vec<[f64; 2]>> {
    views
        .iter()
        .zip(poses)
        .map(|(v, pose)| {
            v.plane
                .iter()
                .zip(&v.image)
                .map(|(pl, im)| {
                    let pc = pose * Point3::new(pl[0], pl[1], 0.0);
                    match camera.project(&pc.coords) {
                        Ok(px) => [px.x - im[0], px.y - im[1]],
                        Err(_) => [f64::INFINITY, f64::INFINITY],
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

fn rms_of(errs: &[[f64; 2]]) -> f64 {
    if errs.is_empty() {
        return 0.0;
    }
    (errs.iter().map(|e| e[0] * e[0] + e[1] * e[1]).sum::<f64>() / errs.len() as f64).sqrt()
}

/// A solved stage: the problem, its summary, the intrinsics and the target poses.
type Stage = (Built, lsq::Summary, Vec<f64>, Vec<Isometry3<f64>>);

/// The fallback of [`calibrate`]'s stage B: starting from `start` (the homography
/// initialisation), solves with the parameter groups of [`free_groups`] for two and then three
/// or more views (restricted to `free_g`), each stage starting from the previous one.
fn staged_release(
    opts: &CalibOptions,
    sigma: f64,
    views: &[View],
    start: (Vec<f64>, Vec<Isometry3<f64>>),
    free_g: &[bool],
) -> Result<Stage> {
    let (mut params, mut poses) = start;
    let mut last = None;
    for stage in 2..=3 {
        let free: Vec<bool> = free_groups(opts.model, stage)
            .iter()
            .zip(free_g)
            .map(|(a, b)| *a && *b)
            .collect();
        let mut b = build(
            opts,
            sigma,
            views,
            &params,
            &poses,
            &free,
            RobustLoss::Trivial,
        )?;
        let summary = b.problem.solve(&solver_options(opts.max_iterations))?;
        (params, poses) = read_back(&b, opts.model)?;
        last = Some((b, summary));
    }
    let (b, summary) = last.ok_or(EstimateError::InvalidParameter {
        name: "views",
        value: views.len() as f64,
        reason: "no release stage ran",
    })?;
    Ok((b, summary, params, poses))
}

/// Calibrates a camera from views of a planar target (004_815695db12a6b16c.txt ch. 5.1–5.2):
///
/// 1. initialisation: the restricted model from plane-to-ray homographies ([`initialise`]), or
///    `opts.initial_params` with poses from the homographies of the rays;
/// 2. a focal-length-only solve, then the solve with the parameter groups released by the
///    bootstrapping schedule ([`free_groups`]) — eqs. 5.1–5.2 by Levenberg–Marquardt over the
///    intrinsics and all target poses (`lsq::Problem`);
/// 3. outlier rejection (see [`CalibOptions::outlier_threshold`]) and a final solve with
///    `opts.loss`;
/// 4. the marginal covariance of the free intrinsics (eqs. 5.3–5.5), residuals whitened by σ_z.
///
/// Errors: `InvalidParameter` (no views, bad σ_z or initial parameters),
/// `DegenerateCalibration` (e.g. all views fronto-parallel, or free parameters left
/// unconstrained: the covariance is rank-deficient), solver errors.
pub fn calibrate(views: &[View], opts: &CalibOptions) -> Result<Calibration> {
    if views.is_empty() {
        return Err(EstimateError::InvalidParameter {
            name: "views",
            value: 0.0,
            reason: "at least one view is needed",
        });
    }
    let sigma = opts.sigma_z.unwrap_or_else(|| default_sigma(opts.width));
    if !(sigma > 0.0 && sigma.is_finite()) {
        return Err(EstimateError::InvalidParameter {
            name: "sigma_z",
            value: sigma,
            reason: "must be positive and finite",
        });
    }
    let model = opts.model;
    let n = model.num_params();
    let (mut params, mut poses) = match &opts.initial_params {
        Some(p) => {
            let cam = Camera::new(model, p, opts.width, opts.height)?;
            let poses = views
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    pose_for_view(&cam, v).ok_or_else(|| {
                        EstimateError::DegenerateCalibration(format!(
                            "view {i}: no target pose under the initial parameters"
                        ))
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            (p.clone(), poses)
        }
        None => {
            let init = initialise(model, opts.width, opts.height, views)?;
            (init.params, init.poses)
        }
    };
    let groups = param_groups(model);
    let free_g = if opts.bootstrap {
        free_groups(model, views.len())
    } else {
        vec![true; groups.len()]
    };
    let init_state = (params.clone(), poses.clone());
    // Stage A: focal lengths and poses only (skipped on a warm start).
    if opts.initial_params.is_none() {
        let mut only_f = vec![false; groups.len()];
        only_f[0] = true;
        let mut b = build(
            opts,
            sigma,
            views,
            &params,
            &poses,
            &only_f,
            RobustLoss::Trivial,
        )?;
        // Only a start for stage B, which iterates to the full tolerance from here: a loose
        // relative cost decrease ends it once the focal length has settled.
        let loose = SolverOptions {
            function_tolerance: STAGE_A_FUNCTION_TOLERANCE,
            ..solver_options(opts.max_iterations)
        };
        b.problem.solve(&loose)?;
        (params, poses) = read_back(&b, model)?;
    }
    // Stage B: the schedule's parameters.
    let mut b = build(
        opts,
        sigma,
        views,
        &params,
        &poses,
        &free_g,
        RobustLoss::Trivial,
    )?;
    let mut summary = b.problem.solve(&solver_options(opts.max_iterations))?;
    (params, poses) = read_back(&b, model)?;
    // The focal-only fit of a strongly distorted lens can wander far (three views of a
    // k1 = −0.3 lens: fx 794, fy 3075 from 457), and releasing everything from there ends in a
    // far local minimum (fy → 10⁴, χ²/dof ≈ 270). If the fit is implausible for the detector
    // noise (χ²/dof above 25, i.e. RMS above 5 σ_z), retry from the homography initialisation
    // releasing the groups in the order of the bootstrapping schedule (ch. 5.2: the two-view
    // set, then all) and keep the lower cost.
    let nobs: usize = views.iter().map(|v| 2 * v.len()).sum();
    let nfree: usize = groups
        .iter()
        .zip(&free_g)
        .filter(|(_, f)| **f)
        .map(|(g, _)| g.len())
        .sum::<usize>()
        + 6 * views.len();
    let chi2_dof = 2.0 * summary.final_cost / nobs.saturating_sub(nfree).max(1) as f64;
    if chi2_dof > 25.0
        && opts.initial_params.is_none()
        && let Ok((pb, ps, pp, pq)) = staged_release(opts, sigma, views, init_state, &free_g)
        && ps.final_cost < summary.final_cost
    {
        (b, summary, params, poses) = (pb, ps, pp, pq);
    }
    // Outliers: flag against the current fit over all points, re-solve on the inliers, and
    // repeat until the flagged set is stable (a gross outlier biases the first fit, so points
    // near it may be flagged once and come back).
    let mut outliers: Vec<(usize, usize)> = Vec::new();
    let mut kept: Vec<View> = views.to_vec();
    let mut solved_with_loss = false;
    for _round in 0..5 {
        let camera = Camera::new(model, &params, opts.width, opts.height)?;
        let errs = reprojection_errors(&camera, views, &poses);
        let threshold = match opts.outlier_threshold {
            Some(t) => t,
            None => {
                // Robust scale from the points currently kept.
                let mut norms: Vec<f64> = Vec::new();
                for (vi, (v, e)) in views.iter().zip(&errs).enumerate() {
                    for (k, d) in e.iter().enumerate() {
                        if !outliers.contains(&(vi, v.index[k])) {
                            norms.push(d[0].hypot(d[1]));
                        }
                    }
                }
                norms.sort_by(f64::total_cmp);
                let median = norms.get(norms.len() / 2).copied().unwrap_or(0.0);
                (5.0 * median / 1.1774).max(5.0 * sigma)
            }
        };
        let mut new_outliers = Vec::new();
        let mut new_kept: Vec<View> = Vec::with_capacity(views.len());
        for (vi, (v, e)) in views.iter().zip(&errs).enumerate() {
            let mut nv = View {
                plane: Vec::new(),
                image: Vec::new(),
                index: Vec::new(),
            };
            for (k, ek) in e.iter().enumerate() {
                let err = ek[0].hypot(ek[1]);
                if err.is_nan() || err > threshold {
                    new_outliers.push((vi, v.index[k]));
                } else {
                    nv.plane.push(v.plane[k]);
                    nv.image.push(v.image[k]);
                    nv.index.push(v.index[k]);
                }
            }
            if nv.len() < super::MIN_POINTS {
                return Err(EstimateError::TooFewPoints {
                    view: vi,
                    got: nv.len(),
                    needed: super::MIN_POINTS,
                });
            }
            new_kept.push(nv);
        }
        let stable = new_outliers == outliers;
        outliers = new_outliers;
        kept = new_kept;
        if stable && (solved_with_loss || (outliers.is_empty() && opts.loss == RobustLoss::Trivial))
        {
            break;
        }
        b = build(opts, sigma, &kept, &params, &poses, &free_g, opts.loss)?;
        summary = b.problem.solve(&solver_options(opts.max_iterations))?;
        (params, poses) = read_back(&b, model)?;
        solved_with_loss = true;
        if opts.outlier_threshold.is_some() && stable {
            break;
        }
    }
    let camera = Camera::new(model, &params, opts.width, opts.height)?;
    // Marginal covariance of the free intrinsic groups (eqs. 5.3–5.5).
    let free_ids: Vec<BlockId> = b
        .groups
        .iter()
        .zip(&free_g)
        .filter(|(_, f)| **f)
        .map(|(id, _)| *id)
        .collect();
    let max_tilt = kept
        .iter()
        .zip(&poses)
        .map(|(_, p)| super::init::view_tilt(p))
        .fold(0.0, f64::max)
        .to_degrees();
    let marg = b.problem.marginal_covariance(&free_ids).map_err(|e| match e {
        EstimateError::RankDeficient { directions, .. } => {
            let why = if max_tilt < 10.0 {
                format!("all {} views are near fronto-parallel (largest target tilt {max_tilt:.1} deg), so focal length and target distance cannot be separated; ", kept.len())
            } else {
                String::new()
            };
            EstimateError::DegenerateCalibration(format!(
                "{why}the views do not constrain every free intrinsic parameter of the {model} model \
                 (unconstrained: {directions}); add views with the target tilted 20-50 deg and in the image corners"
            ))
        }
        other => other,
    })?;
    let mut free = vec![false; n];
    let mut order = Vec::new();
    for (grp, &f) in groups.iter().zip(&free_g) {
        if f {
            for &i in grp {
                free[i] = true;
                order.push(i);
            }
        }
    }
    let mut covariance = DMatrix::zeros(n, n);
    for (a, &i) in order.iter().enumerate() {
        for (c, &j) in order.iter().enumerate() {
            covariance[(i, j)] = marg[(a, c)];
        }
    }
    let errs = reprojection_errors(&camera, &kept, &poses);
    let view_rms = errs.iter().map(|e| rms_of(e)).collect();
    let all: Vec<[f64; 2]> = errs.iter().flatten().copied().collect();
    Ok(Calibration {
        camera,
        free,
        covariance,
        poses,
        views: kept,
        view_rms,
        rms: rms_of(&all),
        outliers,
        sigma_z: sigma,
        iterations: summary.iterations,
        final_cost: summary.final_cost,
    })
}

/// A next-view suggestion.
#[derive(Debug, Clone)]
pub struct Suggestion {
    /// Index of the best candidate.
    pub index: usize,
    /// Its target pose `T_ct`.
    pub pose: Isometry3<f64>,
    /// Its predicted image points (through the current calibration) and their target rows.
    pub pixels: Vec<[f64; 2]>,
    /// Row indices (into the target) of the predicted points.
    pub target_index: Vec<usize>,
    /// Max ERE expected after adding it (pixels).
    pub expected_max_ere: f64,
    /// Max ERE of the current calibration (all parameters free; +inf if not yet constrained).
    pub current_max_ere: f64,
    /// Score of every candidate (+inf for unusable ones).
    pub scores: Vec<f64>,
    /// The candidates scored.
    pub candidates: Vec<Isometry3<f64>>,
}

impl Calibration {
    /// Per-view and total RMS reprojection error (pixels) of `views` seen from `poses`.
    pub fn reprojection_rms(
        camera: &Camera,
        views: &[View],
        poses: &[Isometry3<f64>],
    ) -> Result<(Vec<f64>, f64)> {
        let errs = reprojection_errors(camera, views, poses);
        let all: Vec<[f64; 2]> = errs.iter().flatten().copied().collect();
        Ok((errs.iter().map(|e| rms_of(e)).collect(), rms_of(&all)))
    }

    /// The model.
    pub fn model(&self) -> CameraModel {
        self.camera.model()
    }

    /// Marginal information of all intrinsics (n×n): the sum over views of the Schur
    /// complements of [`view_information`] at the current estimate (eq. 5.5 with the poses
    /// marginalised, eq. 5.3).
    pub fn information(&self) -> DMatrix<f64> {
        let n = self.camera.params().len();
        let mut info = DMatrix::zeros(n, n);
        for (v, pose) in self.views.iter().zip(&self.poses) {
            if let Some(i) = view_information(&self.camera, pose, &v.plane, self.sigma_z) {
                info += i;
            }
        }
        info
    }

    /// Max ERE (Algorithm 5.1) of this calibration: `samples` posterior draws (seeded) of the
    /// free intrinsics, a `grid × grid` test grid.
    pub fn max_ere(&self, samples: usize, grid: usize, seed: u64) -> Result<MaxEre> {
        check_sampling(samples, grid)?;
        self.max_ere_at(
            samples,
            &test_grid(self.camera.width(), self.camera.height(), grid),
            seed,
        )
    }

    /// [`Calibration::max_ere`] over explicit test `pixels` (e.g.
    /// [`super::ere::test_grid_with_margin`]).
    pub fn max_ere_at(&self, samples: usize, pixels: &[[f64; 2]], seed: u64) -> Result<MaxEre> {
        check_sampling(samples, pixels.len())?;
        let l = covariance_sqrt(&self.covariance)?;
        let draws = standard_draws(samples, self.camera.params().len(), seed);
        let cams = sample_cameras(&self.camera, &l, &draws)?;
        max_ere(&self.camera, &cams, pixels)
    }

    /// Per-pixel expected reprojection error map (see [`error_map`]).
    pub fn error_map(&self, step: usize, samples: usize, seed: u64) -> Result<DMatrix<f64>> {
        check_sampling(samples, 1)?;
        let l = covariance_sqrt(&self.covariance)?;
        let draws = standard_draws(samples, self.camera.params().len(), seed);
        let cams = sample_cameras(&self.camera, &l, &draws)?;
        error_map(&self.camera, &cams, step)
    }

    /// The target points seen so far (union over views by row index; the target layout).
    pub fn target(&self) -> Vec<[f64; 2]> {
        let mut rows: Vec<(usize, [f64; 2])> = Vec::new();
        for v in &self.views {
            for (&i, p) in v.index.iter().zip(&v.plane) {
                rows.push((i, *p));
            }
        }
        rows.sort_by_key(|r| r.0);
        rows.dedup_by_key(|r| r.0);
        rows.into_iter().map(|r| r.1).collect()
    }

    /// Suggests the next target pose (004_815695db12a6b16c.txt ch. 5.2–5.3): every candidate
    /// (default: [`candidate_poses`], about 60 through the view frustum) is scored by the Max
    /// ERE after adding its hypothetical observations to the current marginal information of
    /// all intrinsics ([`score_candidates`]); the lowest wins. While the full model is not yet
    /// constrained even with the candidate, only `fx, fy, cx, cy` are scored.
    pub fn suggest_next_view(
        &self,
        target: &[[f64; 2]],
        candidates: Option<&[Isometry3<f64>]>,
        samples: usize,
        grid: usize,
        seed: u64,
    ) -> Result<Suggestion> {
        check_sampling(samples, grid)?;
        let pixels = test_grid(self.camera.width(), self.camera.height(), grid);
        self.suggest_next_view_at(target, candidates, samples, &pixels, seed)
    }

    /// [`Calibration::suggest_next_view`] with the Max ERE scored over explicit test `pixels`
    /// (e.g. [`super::ere::test_grid_with_margin`]).
    pub fn suggest_next_view_at(
        &self,
        target: &[[f64; 2]],
        candidates: Option<&[Isometry3<f64>]>,
        samples: usize,
        pixels: &[[f64; 2]],
        seed: u64,
    ) -> Result<Suggestion> {
        check_sampling(samples, pixels.len())?;
        if target.len() < super::MIN_POINTS {
            return Err(EstimateError::TooFewPoints {
                view: usize::MAX,
                got: target.len(),
                needed: super::MIN_POINTS,
            });
        }
        let cands: Vec<Isometry3<f64>> = match candidates {
            Some(c) => c.to_vec(),
            None => candidate_poses(&self.camera, target)?,
        };
        if cands.is_empty() {
            return Err(EstimateError::InvalidParameter {
                name: "candidates",
                value: 0.0,
                reason: "no candidate poses",
            });
        }
        let n = self.camera.params().len();
        let pixels = pixels.to_vec();
        let info = self.information();
        let draws = standard_draws(samples, n, seed);
        let current = super::guide::max_ere_from_information(&self.camera, &info, &draws, &pixels)
            .unwrap_or(f64::INFINITY);
        let mut scores = score_candidates(
            &self.camera,
            &info,
            target,
            &cands,
            self.sigma_z,
            &draws,
            &pixels,
            0.25,
        );
        if scores.iter().all(|s| !s.is_finite()) {
            // Bootstrapping: score the linear intrinsics only, distortion held fixed.
            let sub: Vec<usize> = (0..4).collect();
            let cam = &self.camera;
            scores = cands
                .iter()
                .map(|pose| {
                    let (idx, _) = visible_points(cam, pose, target);
                    let plane: Vec<[f64; 2]> = idx.iter().map(|&i| target[i]).collect();
                    let Some(extra) = view_information(cam, pose, &plane, self.sigma_z) else {
                        return f64::INFINITY;
                    };
                    let total = &info + extra;
                    let small = total.select_rows(&sub).select_columns(&sub);
                    let Some(c) = small.cholesky() else {
                        return f64::INFINITY;
                    };
                    let cs = c.inverse();
                    let mut cov = DMatrix::zeros(n, n);
                    cov.view_mut((0, 0), (4, 4)).copy_from(&cs);
                    covariance_sqrt(&cov)
                        .and_then(|l| sample_cameras(cam, &l, &draws))
                        .and_then(|s| max_ere(cam, &s, &pixels))
                        .map(|m| m.value)
                        .unwrap_or(f64::INFINITY)
                })
                .collect();
        }
        let (index, &best) = scores
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .ok_or(EstimateError::InvalidParameter {
                name: "candidates",
                value: 0.0,
                reason: "no candidate poses",
            })?;
        if !best.is_finite() {
            return Err(EstimateError::DegenerateCalibration(
                "no candidate view sees enough of the target to constrain the calibration".into(),
            ));
        }
        let pose = cands[index];
        let (target_index, px) = visible_points(&self.camera, &pose, target);
        Ok(Suggestion {
            index,
            pose,
            pixels: px,
            target_index,
            expected_max_ere: best,
            current_max_ere: current,
            scores,
            candidates: cands,
        })
    }

    /// Per-point reprojection errors (pixels) of test views with these intrinsics held fixed and
    /// each view's target pose re-optimised (the test-set protocol of 004_815695db12a6b16c.txt
    /// ch. 5.5: "the error we report is after we optimize the target extrinsics to best fit the
    /// fixed model parameters").
    pub fn test_errors(&self, views: &[View]) -> Result<Vec<Vec<f64>>> {
        let mut opts = CalibOptions::new(self.model(), self.camera.width(), self.camera.height());
        opts.sigma_z = Some(self.sigma_z);
        let groups = param_groups(self.model());
        let none = vec![false; groups.len()];
        views
            .iter()
            .map(|v| {
                let Some(pose) = pose_for_view(&self.camera, v) else {
                    // The calibration cannot even unproject this view: it does not generalise
                    // there, every point counts as an infinite error.
                    return Ok(vec![f64::INFINITY; v.len()]);
                };
                let mut b = build(
                    &opts,
                    self.sigma_z,
                    std::slice::from_ref(v),
                    self.camera.params(),
                    &[pose],
                    &none,
                    RobustLoss::Trivial,
                )?;
                b.problem.solve(&solver_options(50))?;
                let (_, p) = read_back(&b, self.model())?;
                let e = reprojection_errors(&self.camera, std::slice::from_ref(v), &p);
                Ok(e.into_iter().flatten().map(|d| d[0].hypot(d[1])).collect())
            })
            .collect()
    }
}

fn check_sampling(samples: usize, grid: usize) -> Result<()> {
    if samples < 2 {
        return Err(EstimateError::InvalidParameter {
            name: "samples",
            value: samples as f64,
            reason: "at least 2 posterior samples",
        });
    }
    if grid < 1 {
        return Err(EstimateError::InvalidParameter {
            name: "grid",
            value: 0.0,
            reason: "the test grid needs at least 1 x 1 points",
        });
    }
    Ok(())
}

/// One entry of [`select_model`].
#[derive(Debug, Clone)]
pub struct ModelScore {
    /// The model.
    pub model: CameraModel,
    /// Its calibration, or why it failed.
    pub calibration: std::result::Result<Calibration, EstimateError>,
    /// Bayesian information criterion `χ² + k ln N` with `χ² = Σ‖r‖²/σ_z²`, `k` intrinsics and
    /// `N` scalar observations (+inf if the calibration failed).
    pub bic: f64,
}

/// Model selection between lens models (004_815695db12a6b16c.txt ch. 5.1, footnote 4: "AprilCal
/// can perform model selection to evaluate all available models"): calibrates each model on the
/// same views and ranks them by BIC (poses are common to all models, so only the intrinsics
/// count), best first. Outlier rejection is off so every model sees the same points.
pub fn select_model(
    views: &[View],
    opts: &CalibOptions,
    models: &[CameraModel],
) -> Vec<ModelScore> {
    let nobs: usize = views.iter().map(|v| 2 * v.len()).sum();
    let mut out: Vec<ModelScore> = models
        .iter()
        .map(|&model| {
            let mut o = opts.clone();
            o.model = model;
            o.outlier_threshold = Some(f64::INFINITY);
            o.initial_params = None;
            let calibration = calibrate(views, &o);
            let bic = match &calibration {
                Ok(c) => 2.0 * c.final_cost + model.num_params() as f64 * (nobs as f64).ln(),
                Err(_) => f64::INFINITY,
            };
            ModelScore {
                model,
                calibration,
                bic,
            }
        })
        .collect();
    out.sort_by(|a, b| a.bic.total_cmp(&b.bic));
    out
}

#[cfg(test)]
mod schur_tests {
    use super::*;
    use crate::calib::guide::{random_poses, synthesize_view_seeded};

    /// The Schur-complement solve of the calibration (poses eliminated) reaches the same
    /// intrinsics and poses as the dense Cholesky solve of the full normal equations, from the
    /// same start, on 20 noisy views of a Brown–Conrady lens.
    #[test]
    fn schur_solve_equals_dense_solve() {
        let params = [
            420.0, 421.0, 318.0, 243.0, -0.30, 0.11, 0.0008, -0.0005, -0.018,
        ];
        let cam = Camera::new(CameraModel::BrownConrady, &params, 640, 480).unwrap();
        let target: Vec<[f64; 2]> = (0..70)
            .map(|i| [(i % 10) as f64 * 0.03, (i / 10) as f64 * 0.03])
            .collect();
        let poses = random_poses(&cam, &target, 80, 0.7, 1).unwrap();
        let views: Vec<View> = poses
            .iter()
            .enumerate()
            .filter_map(|(k, p)| synthesize_view_seeded(&cam, p, &target, 0.1, k as u64))
            .filter(|v| v.len() >= 30)
            .take(20)
            .collect();
        assert_eq!(views.len(), 20);
        let opts = CalibOptions::new(CameraModel::BrownConrady, 640, 480);
        let init = initialise(opts.model, 640, 480, &views).unwrap();
        let free = vec![true; param_groups(opts.model).len()];
        let solve = |solver: lsq::LinearSolver| {
            let mut b = build(
                &opts,
                0.1,
                &views,
                &init.params,
                &init.poses,
                &free,
                RobustLoss::Trivial,
            )
            .unwrap();
            let summary = b
                .problem
                .solve(&SolverOptions {
                    linear_solver: solver,
                    ..solver_options(200)
                })
                .unwrap();
            (summary, read_back(&b, opts.model).unwrap())
        };
        let (s_schur, (p_schur, q_schur)) = solve(lsq::LinearSolver::SparseSchur);
        let (s_dense, (p_dense, q_dense)) = solve(lsq::LinearSolver::DenseCholesky);
        assert_eq!(s_schur.linear_solver, lsq::LinearSolver::SparseSchur);
        assert!((s_schur.final_cost - s_dense.final_cost).abs() <= 1e-10 * s_dense.final_cost);
        for (a, b) in p_schur.iter().zip(&p_dense) {
            assert!((a - b).abs() <= 1e-8 * b.abs().max(1e-3), "{a} vs {b}");
        }
        // And the truth, within the noise (0.1 px on 20 views).
        assert!((p_schur[0] - params[0]).abs() < 1.0 && (p_schur[4] - params[4]).abs() < 5e-3);
        for (a, b) in q_schur.iter().zip(&q_dense) {
            assert!((a.translation.vector - b.translation.vector).norm() < 1e-8);
            assert!(a.rotation.angle_to(&b.rotation) < 1e-8);
        }
    }
}
