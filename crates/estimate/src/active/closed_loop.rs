//! The closed loop of active auto-teaching, 000_3b1454b2b2194811.txt Fig. 6.1 and ch. 6.4, on a
//! simulated robot in front of a chamber opening: detect, estimate with the Kalman filter
//! (6.15), plan the next measurement pose (6.22), move, repeat.
//!
//! Detections are simulated by projecting the opening's corners through the TRUE camera pose
//! (true opening pose, camera mount and joint offsets) with Gaussian pixel noise; corners
//! outside the image are not detected. The baseline of Table 6.4 ("w/o active calibration")
//! is the approach trajectory of the previous auto-teaching experiment: the camera moves
//! straight towards a pre-insertion pose in front of the (currently estimated) opening with the
//! blade yaw kept facing the opening.

use std::time::Instant;

use autoteach_geometry::camera::Camera;
use autoteach_geometry::collision::{LinkDims, RobotShapes, Workspace};
use autoteach_geometry::robot::{Joints, WaferRobot};
use nalgebra::{
    DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector2, Vector3,
};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

use super::design::{self, ObservabilityIndices};
use super::model::{
    HandEyeEstimator, HandEyeModel, HandEyeParams, N_FULL, ParamMask, report_scale,
};
use super::planner::{self, ActiveScene, Constraints, PlannerOptions};
use crate::{EstimateError, Result};

/// How the next measurement pose is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoopMode {
    /// Active planning with the reduced search ([`planner::plan_reduced`]).
    Reduced,
    /// Active planning with plain sampling ([`planner::plan_sampling`]).
    Sampling,
    /// No planning: the straight approach trajectory (the baseline of Table 6.4).
    Baseline,
}

impl std::str::FromStr for LoopMode {
    type Err = EstimateError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "reduced" | "active" => Ok(LoopMode::Reduced),
            "sampling" => Ok(LoopMode::Sampling),
            "baseline" => Ok(LoopMode::Baseline),
            _ => Err(EstimateError::InvalidProblem(format!(
                "unknown loop mode {s:?}; expected \"reduced\", \"sampling\" or \"baseline\""
            ))),
        }
    }
}

/// The simulated scenario of ch. 6.4.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The robot.
    pub robot: WaferRobot,
    /// The calibrated camera.
    pub camera: Camera,
    /// Nominal pose of the opening centre (x axis into the chamber, z up).
    pub opening: Isometry3<f64>,
    /// Opening width (horizontal) and height (m).
    pub opening_size: (f64, f64),
    /// Wall thickness and extent beyond the opening (m).
    pub wall: (f64, f64),
    /// Robot link shapes.
    pub link_dims: LinkDims,
    /// Planner constraints.
    pub constraints: Constraints,
    /// Estimated parameters.
    pub mask: ParamMask,
    /// Standard deviations (SI) of the true parameters around nominal, also the filter's prior,
    /// for the full parameter vector (only masked entries are used; the others are exact).
    pub prior_sigmas: [f64; N_FULL],
    /// Pixel noise σ of the simulated detections.
    pub sigma_px: f64,
    /// Number of measurement steps per trial.
    pub steps: usize,
    /// Planner options.
    pub planner: PlannerOptions,
    /// Range of the initial object depth (m).
    pub start_depth: (f64, f64),
    /// Half range of the initial image offset of the opening centre (pixels).
    pub start_offset_px: f64,
    /// Object depth at the end of the baseline approach (m).
    pub final_depth: f64,
    /// Power `P` of the O6 index.
    pub power: f64,
}

impl Scenario {
    /// The default chamber-opening scene: default robot at the origin; a 1280×960 pinhole
    /// camera (f = 900 px); a 340 × 50 mm slit opening 1.05 m ahead at 0.45 m height in a wall
    /// 50 mm thick; prior σ of 1° (opening rotation), 30 mm (opening x, y; camera x, y) and
    /// 10 mm (opening z); 0.5 px pixel noise; 12 steps.
    pub fn chamber() -> Result<Self> {
        let camera = Camera::pinhole(900.0, 900.0, 639.5, 479.5, 1280, 960)?;
        let mut prior = [0.0; N_FULL];
        let deg = 1f64.to_radians();
        prior[..3].copy_from_slice(&[deg, deg, deg]);
        prior[3..9].copy_from_slice(&[0.03, 0.03, 0.01, 0.03, 0.03, 0.01]);
        prior[9..13].copy_from_slice(&[0.2f64.to_radians(); 4]);
        prior[13] = 0.002;
        Ok(Self {
            robot: WaferRobot::default(),
            camera,
            opening: Isometry3::translation(1.05, 0.0, 0.45),
            opening_size: (0.34, 0.05),
            wall: (0.05, 0.5),
            link_dims: LinkDims::default(),
            constraints: Constraints::default(),
            mask: ParamMask::default(),
            prior_sigmas: prior,
            sigma_px: 0.5,
            steps: 12,
            planner: PlannerOptions::default(),
            start_depth: (0.55, 0.8),
            start_offset_px: 120.0,
            final_depth: 0.32,
            power: 2.0,
        })
    }

    /// The opening's corner points in its own frame.
    pub fn corners(&self) -> Vec<Vector3<f64>> {
        let (w, h) = (0.5 * self.opening_size.0, 0.5 * self.opening_size.1);
        vec![
            Vector3::new(0.0, w, h),
            Vector3::new(0.0, -w, h),
            Vector3::new(0.0, -w, -h),
            Vector3::new(0.0, w, -h),
        ]
    }

    /// The planning scene (model, collision shapes around the NOMINAL opening, constraints).
    pub fn scene(&self) -> Result<ActiveScene> {
        let model = HandEyeModel::new(self.robot, self.camera.clone(), self.corners(), self.mask)?;
        let shapes = RobotShapes::new(self.robot, self.link_dims)?;
        let workspace = Workspace::chamber_opening(
            &self.opening,
            self.opening_size.0,
            self.opening_size.1,
            self.wall.0,
            self.wall.1,
        )?;
        Ok(ActiveScene {
            model,
            shapes,
            workspace,
            constraints: self.constraints,
            normal: -Vector3::x(),
        })
    }

    fn masked_prior(&self) -> Vec<f64> {
        self.mask
            .indices()
            .iter()
            .map(|&i| self.prior_sigmas[i])
            .collect()
    }
}

/// The record of one trial.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    /// Per step: truth ⊟ estimate for the full parameter vector, in report units (deg, mm).
    pub errors: Vec<[f64; N_FULL]>,
    /// Per step: observability indices of the information matrix in report units.
    pub indices: Vec<ObservabilityIndices>,
    /// Per step: the encoder readings of the measurement pose.
    pub joints: Vec<Joints>,
    /// Per step: the corners detected.
    pub detected: Vec<usize>,
    /// Per planning step: wall time of the planner (s).
    pub plan_times: Vec<f64>,
    /// Per planning step: the planner's score of the chosen pose (NaN for the baseline).
    pub scores: Vec<f64>,
    /// Final coupled error (mm) of the opening relative to the camera, in the final blade frame:
    /// `R_z(ψ)ᵀ e_opening − e_camera` (x, y) and `e_opening,z − e_camera,z`.
    pub coupled: [f64; 3],
    /// Planning steps where no feasible pose was found (the robot stayed).
    pub infeasible_steps: usize,
}

/// Indices of the information matrix expressed in report units (mm, deg): `S⁻¹ Λ S⁻¹`.
fn report_indices(
    info: &DMatrix<f64>,
    mask: &ParamMask,
    power: f64,
) -> Result<ObservabilityIndices> {
    let s = DVector::from_iterator(
        mask.len(),
        mask.indices().into_iter().map(|i| 1.0 / report_scale(i)),
    );
    let scaled = DMatrix::from_fn(info.nrows(), info.ncols(), |r, c| {
        info[(r, c)] * s[r] * s[c]
    });
    design::observability_indices(&scaled, power)
}

fn simulate_detections(
    model: &HandEyeModel,
    truth: &HandEyeParams,
    q: &Joints,
    sigma: f64,
    rng: &mut Pcg64,
) -> Result<Vec<Option<Vector2<f64>>>> {
    let noise = Normal::new(0.0, sigma).map_err(|_| EstimateError::InvalidParameter {
        name: "sigma_px",
        value: sigma,
        reason: "pixel noise must be positive and finite",
    })?;
    let (w, h) = (
        f64::from(model.camera.width()),
        f64::from(model.camera.height()),
    );
    Ok(model
        .project(truth, q)?
        .into_iter()
        .map(|p| {
            let n = Vector2::new(noise.sample(rng), noise.sample(rng));
            p.map(|p| p + n)
                .filter(|p| p.x >= 0.0 && p.y >= 0.0 && p.x <= w - 1.0 && p.y <= h - 1.0)
        })
        .collect())
}

/// Camera pose with blade yaw `psi` seeing the opening centre at pixel `anchor`, depth `d`.
fn anchored(
    scene: &ActiveScene,
    params: &HandEyeParams,
    psi: f64,
    anchor: &Vector2<f64>,
    d: f64,
) -> Option<Isometry3<f64>> {
    let ray = scene.model.camera.unproject(anchor).ok()?;
    let rot = scene.camera_rotation(psi);
    let centre = params.opening * Point3::from(scene.centre());
    let t = centre.coords - rot * (ray * (d / ray.z));
    Some(Isometry3::from_parts(Translation3::from(t), rot))
}

/// First collision-free, in-range IK solution for a camera pose.
fn reach(
    scene: &ActiveScene,
    params: &HandEyeParams,
    t_wc: &Isometry3<f64>,
) -> Result<Option<Joints>> {
    let Ok(sols) = scene.camera_ik(params, t_wc) else {
        return Ok(None);
    };
    let (lo, hi) = scene.constraints.lift_range;
    for q in sols {
        let q_true = q - params.joint_offsets;
        if q_true[4] < lo || q_true[4] > hi {
            continue;
        }
        if scene
            .shapes
            .is_free(&q_true, &scene.workspace, scene.constraints.min_clearance)?
        {
            return Ok(Some(q));
        }
    }
    Ok(None)
}

/// Runs one trial of the closed loop. `seed` and `trial` fix the random truth, start pose and
/// noise, so the same `(seed, trial)` gives the same truth and start for every mode.
pub fn run_trial(
    scenario: &Scenario,
    seed: u64,
    trial: u64,
    mode: LoopMode,
) -> Result<TrialResult> {
    if scenario.steps == 0 {
        return Err(EstimateError::InvalidProblem(
            "a trial needs at least one step".into(),
        ));
    }
    let scene = scenario.scene()?;
    let mask = scenario.mask;
    let mut rng = Pcg64::seed_from_u64(seed ^ (trial.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
    // Random truth around nominal (estimated parameters only).
    let nominal = HandEyeParams::nominal(&scenario.robot, scenario.opening);
    let mut delta = [0.0; N_FULL];
    for i in mask.indices() {
        let s = scenario.prior_sigmas[i];
        delta[i] = Normal::new(0.0, s)
            .map_err(|_| EstimateError::InvalidParameter {
                name: "prior sigma",
                value: s,
                reason: "prior standard deviations must be positive and finite",
            })?
            .sample(&mut rng);
    }
    let truth = nominal.plus_full(&delta);
    let mut est = HandEyeEstimator::new(
        scene.model.clone(),
        nominal,
        &scenario.masked_prior(),
        scenario.sigma_px,
    )?;
    // Random start: facing the (nominal) opening, centre offset in the image, random depth.
    let cam = &scenario.camera;
    let centre_px = Vector2::new(
        0.5 * (f64::from(cam.width()) - 1.0),
        0.5 * (f64::from(cam.height()) - 1.0),
    );
    let yaw = scene.facing_yaw(&nominal);
    let mut start = None;
    for _ in 0..200 {
        let d = rng.random_range(scenario.start_depth.0..=scenario.start_depth.1);
        let off = Vector2::new(
            rng.random_range(-scenario.start_offset_px..=scenario.start_offset_px),
            rng.random_range(-scenario.start_offset_px..=scenario.start_offset_px),
        );
        let Some(t_wc) = anchored(&scene, &nominal, yaw, &(centre_px + off), d) else {
            continue;
        };
        if let Some(q) = reach(&scene, &nominal, &t_wc)?
            && model_sees_all(&scene.model, &truth, &q)?
        {
            start = Some((q, d, off));
            break;
        }
    }
    let Some((mut q, d0, off0)) = start else {
        return Err(EstimateError::NoFeasiblePose {
            evaluated: 200,
            binding: "initial pose".into(),
            counts: "no random start pose sees the whole opening without collision".into(),
        });
    };
    let mut result = TrialResult {
        errors: Vec::new(),
        indices: Vec::new(),
        joints: Vec::new(),
        detected: Vec::new(),
        plan_times: Vec::new(),
        scores: Vec::new(),
        coupled: [0.0; 3],
        infeasible_steps: 0,
    };
    let mut planner_opts = scenario.planner.clone();
    for step in 0..scenario.steps {
        let det = simulate_detections(&scene.model, &truth, &q, scenario.sigma_px, &mut rng)?;
        let summary = est.update(&q, &det)?;
        let err = est.estimate.minus_full(&truth);
        let mut rep = [0.0; N_FULL];
        for i in 0..N_FULL {
            rep[i] = err[i] * report_scale(i);
        }
        result.errors.push(rep);
        result
            .indices
            .push(report_indices(est.information(), &mask, scenario.power)?);
        result.joints.push(q);
        result.detected.push(summary.used);
        if step + 1 == scenario.steps {
            break;
        }
        let t0 = Instant::now();
        let next = match mode {
            LoopMode::Reduced | LoopMode::Sampling => {
                planner_opts.seed = seed.wrapping_add(1000 * trial + step as u64);
                let plan = if mode == LoopMode::Reduced {
                    planner::plan_reduced(
                        &scene,
                        &est.estimate,
                        est.information(),
                        scenario.sigma_px,
                        &planner_opts,
                    )
                } else {
                    planner::plan_sampling(
                        &scene,
                        &est.estimate,
                        est.information(),
                        scenario.sigma_px,
                        &planner_opts,
                    )
                };
                match plan {
                    Ok(p) => Some((p.best.joints, p.best.score)),
                    Err(EstimateError::NoFeasiblePose { .. }) => None,
                    Err(e) => return Err(e),
                }
            }
            LoopMode::Baseline => {
                // Straight approach towards the pre-insertion pose, re-aimed at the estimate.
                let s = (step + 1) as f64 / (scenario.steps - 1) as f64;
                let d = d0 + s * (scenario.final_depth - d0);
                let anchor = centre_px + off0 * (1.0 - s);
                let yaw = scene.facing_yaw(&est.estimate);
                match anchored(&scene, &est.estimate, yaw, &anchor, d) {
                    Some(t_wc) => reach(&scene, &est.estimate, &t_wc)?.map(|q| (q, f64::NAN)),
                    None => None,
                }
            }
        };
        result.plan_times.push(t0.elapsed().as_secs_f64());
        match next {
            Some((qn, score)) => {
                q = qn;
                result.scores.push(score);
            }
            None => {
                result.infeasible_steps += 1;
                result.scores.push(f64::NAN);
            }
        }
    }
    // Coupled error in the final blade frame.
    let last = result.errors.last().copied().unwrap_or([0.0; N_FULL]);
    let q_true = q - truth.joint_offsets;
    let psi = q_true[0] + q_true[1] + q_true[3];
    let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), psi);
    let e_open = r.inverse()
        * (scenario.robot.base.rotation.inverse() * Vector3::new(last[3], last[4], last[5]));
    result.coupled = [e_open.x - last[6], e_open.y - last[7], e_open.z - last[8]];
    Ok(result)
}

fn model_sees_all(model: &HandEyeModel, truth: &HandEyeParams, q: &Joints) -> Result<bool> {
    let (w, h) = (
        f64::from(model.camera.width()),
        f64::from(model.camera.height()),
    );
    Ok(model
        .project(truth, q)?
        .iter()
        .all(|p| p.is_some_and(|p| p.x >= 0.0 && p.y >= 0.0 && p.x <= w - 1.0 && p.y <= h - 1.0)))
}

/// Runs `trials` trials (trial indices `0..trials`) of one mode.
pub fn run_trials(
    scenario: &Scenario,
    seed: u64,
    trials: usize,
    mode: LoopMode,
) -> Result<Vec<TrialResult>> {
    (0..trials as u64)
        .map(|t| run_trial(scenario, seed, t, mode))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trials_are_deterministic_and_share_truth_across_modes() {
        let mut sc = Scenario::chamber().unwrap();
        sc.steps = 3;
        let a = run_trial(&sc, 7, 1, LoopMode::Baseline).unwrap();
        let b = run_trial(&sc, 7, 1, LoopMode::Baseline).unwrap();
        assert_eq!(a.errors, b.errors);
        let c = run_trial(&sc, 7, 1, LoopMode::Reduced).unwrap();
        // Same truth and start: identical first measurement and update.
        assert_eq!(a.errors[0], c.errors[0]);
        assert_eq!(a.joints[0], c.joints[0]);
    }

    #[test]
    fn active_planning_decouples_opening_and_camera_translation() {
        let sc = Scenario::chamber().unwrap();
        let mut worst_base: f64 = 0.0;
        let mut worst_active: f64 = 0.0;
        for t in 0..3 {
            let b = run_trial(&sc, 11, t, LoopMode::Baseline).unwrap();
            let a = run_trial(&sc, 11, t, LoopMode::Reduced).unwrap();
            let eb = b.errors.last().unwrap();
            let ea = a.errors.last().unwrap();
            worst_base = worst_base.max(eb[3].abs().max(eb[4].abs()));
            worst_active = worst_active.max(ea[3].abs().max(ea[4].abs()));
            // The information only grows (6.15): O1 is non-decreasing over steps.
            for w in a.indices.windows(2) {
                assert!(w[1].log_det >= w[0].log_det - 1e-9);
            }
        }
        assert!(
            worst_active < 3.0,
            "active worst opening x/y error {worst_active} mm"
        );
        assert!(
            worst_base > 3.0 * worst_active,
            "baseline {worst_base} mm vs active {worst_active} mm"
        );
    }

    /// Table 6.4 on simulation: 10 trials, final error std of every estimated quantity with and
    /// without planning.
    #[test]
    fn table_6_4_reproduction_meets_the_goal() {
        let sc = Scenario::chamber().unwrap();
        let names = sc.mask.names();
        let idx = sc.mask.indices();
        let stats = |mode| {
            let runs = run_trials(&sc, 0, 10, mode).unwrap();
            idx.iter()
                .map(|&i| {
                    let e: Vec<f64> = runs.iter().map(|r| r.errors.last().unwrap()[i]).collect();
                    let m = e.iter().sum::<f64>() / e.len() as f64;
                    (e.iter().map(|v| (v - m).powi(2)).sum::<f64>() / e.len() as f64).sqrt()
                })
                .collect::<Vec<f64>>()
        };
        let base = stats(LoopMode::Baseline);
        let act = stats(LoopMode::Reduced);
        for (k, n) in names.iter().enumerate() {
            eprintln!("{n:>16}: baseline ±{:.3}  active ±{:.3}", base[k], act[k]);
        }
        let worst = (0..names.len())
            .filter(|&k| names[k].ends_with("_mm"))
            .max_by(|&a, &b| base[a].total_cmp(&base[b]))
            .unwrap();
        assert!(
            base[worst] >= 10.0 * act[worst],
            "worst axis {}: {} vs {}",
            names[worst],
            base[worst],
            act[worst]
        );
        for k in 0..names.len() {
            assert!(
                act[k] <= base[k] * 1.05,
                "{} worse with planning: {} vs {}",
                names[k],
                act[k],
                base[k]
            );
        }
    }
}
