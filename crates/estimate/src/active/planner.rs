//! The one-step-horizon greedy measurement-pose planner of 000_3b1454b2b2194811.txt ch. 6.3,
//! eqs. (6.16)–(6.25).
//!
//! Given the current covariance `P(k−1)`, the next pose maximises the D-optimal gain
//! `log |I + C(k)ᵀ V^{-½} P(k−1) V^{-½} C(k)|` (eq. (6.22), one step) subject to visibility
//! (6.17), object size in the image (6.18), view angle (6.19), collision (6.20) and the lift
//! range. Three searches share one pose evaluation:
//!
//! * [`plan_reduced`], the reduced search of the seed's design steps 2–5: the object placed
//!   towards a corner of the image, a line search over the camera yaw (grid + golden-section
//!   refinement), sampling of the object depth (end-effector positions), inverse kinematics
//!   ([`WaferRobot::inverse_kinematics`] with the estimated camera mount);
//! * [`plan_sampling`], plain random sampling of camera poses in front of the object, the
//!   sampling-based comparison of Table 6.3;
//! * [`plan_candidates`], the best of a finite set of joint vectors.

use std::f64::consts::PI;

use autoteach_geometry::collision::{RobotShapes, Workspace};
use autoteach_geometry::robot::{Blade, Joints, WaferRobot};
use nalgebra::{
    Cholesky, DMatrix, Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use super::design;
use super::model::{HandEyeModel, HandEyeParams};
use crate::{EstimateError, Result};

/// The constraints of eq. (6.21).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Constraints {
    /// (6.17): every corner must project at least this many pixels inside the image.
    pub margin_px: f64,
    /// (6.18): `[S_min, S_max]`, bounds on the object's largest extent in the image (pixels).
    pub size_px: (f64, f64),
    /// (6.19): `α_max`, the largest angle between the viewing ray to the object centre and the
    /// object's normal (radians).
    pub max_view_angle: f64,
    /// (6.20): the smallest allowed clearance between the robot links and the obstacles (m).
    pub min_clearance: f64,
    /// Joint range of the lift `h` (m).
    pub lift_range: (f64, f64),
}

impl Default for Constraints {
    /// The seed's values (ch. 6.3): `[S_min, S_max] = [300, 2000]` px, `α_max = 60°`; a 20 px
    /// image margin, 2 cm clearance and a lift range of [0, 0.4] m.
    fn default() -> Self {
        Self {
            margin_px: 20.0,
            size_px: (300.0, 2000.0),
            max_view_angle: 60f64.to_radians(),
            min_clearance: 0.02,
            lift_range: (0.0, 0.4),
        }
    }
}

/// The optimality criterion scored by the planner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// D-optimality (O1): the log-determinant gain `log|I + F P Fᵀ|` of eq. (6.22).
    D,
    /// A-optimality: the reduction of `tr P`.
    A,
    /// E-optimality (O3): the smallest eigenvalue of the posterior information.
    E,
}

impl std::str::FromStr for Criterion {
    type Err = EstimateError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "D" | "d" => Ok(Criterion::D),
            "A" | "a" => Ok(Criterion::A),
            "E" | "e" => Ok(Criterion::E),
            _ => Err(EstimateError::InvalidProblem(format!(
                "unknown optimality criterion {s:?}; expected \"D\", \"A\" or \"E\""
            ))),
        }
    }
}

/// The planning problem: model, collision geometry and constraints.
#[derive(Debug, Clone)]
pub struct ActiveScene {
    /// The observation model (robot, camera, object corners, estimated parameters).
    pub model: HandEyeModel,
    /// Robot link shapes for the collision constraint.
    pub shapes: RobotShapes,
    /// Obstacles.
    pub workspace: Workspace,
    /// The constraints of (6.21).
    pub constraints: Constraints,
    /// The object's outward normal in its own frame (pointing towards the robot).
    pub normal: Vector3<f64>,
}

impl ActiveScene {
    /// The object centre (mean of the corners) in its own frame.
    pub fn centre(&self) -> Vector3<f64> {
        let n = self.model.corners.len() as f64;
        self.model.corners.iter().sum::<Vector3<f64>>() / n
    }

    /// The object's largest extent (max distance between two corners).
    pub fn extent(&self) -> f64 {
        let c = &self.model.corners;
        let mut e: f64 = 0.0;
        for a in c {
            for b in c {
                e = e.max((a - b).norm());
            }
        }
        e
    }

    /// Blade yaw (base frame) that points the camera along the object's inward normal.
    pub fn facing_yaw(&self, params: &HandEyeParams) -> f64 {
        let n_w = params.opening.rotation * (-self.normal);
        let n_b = self.model.robot.base.rotation.inverse() * n_w;
        n_b.y.atan2(n_b.x)
    }

    /// World camera orientation for blade yaw `psi` (base frame).
    pub fn camera_rotation(&self, psi: f64) -> UnitQuaternion<f64> {
        let r = &self.model.robot;
        r.base.rotation
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), psi)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), r.params.alpha2)
            * r.camera_mount().rotation
    }

    /// Joint vectors (encoder readings, both IK branches, the blade-1 wrist aligned with blade 2)
    /// placing the camera at `t_wc` under the estimated mount and joint offsets.
    pub fn camera_ik(&self, params: &HandEyeParams, t_wc: &Isometry3<f64>) -> Result<Vec<Joints>> {
        let robot: &WaferRobot = &self.model.robot;
        let t_be2 = robot.base.inverse() * t_wc * self.model.mount(params).inverse();
        let sols = robot.inverse_kinematics(&t_be2, Blade::Two, 0.0)?;
        Ok(sols
            .into_iter()
            .map(|mut q| {
                q[2] = q[3];
                q + params.joint_offsets
            })
            .collect())
    }
}

/// Why a candidate pose was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// Inverse kinematics has no solution.
    Unreachable,
    /// The lift is out of its range.
    Lift,
    /// A corner is outside the image margin or behind the camera (6.17).
    Visibility,
    /// The object's image size is outside `[S_min, S_max]` (6.18).
    Size,
    /// The view angle exceeds `α_max` (6.19).
    ViewAngle,
    /// A link is closer than the clearance to an obstacle (6.20).
    Collision,
}

/// Rejection counts per constraint.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rejections {
    /// Unreachable poses.
    pub unreachable: usize,
    /// Lift out of range.
    pub lift: usize,
    /// Visibility (6.17).
    pub visibility: usize,
    /// Size (6.18).
    pub size: usize,
    /// View angle (6.19).
    pub view_angle: usize,
    /// Collision (6.20).
    pub collision: usize,
    /// Per constraint (in the order of [`Rejections::error`]'s list), the candidates that
    /// violated only that constraint: the constraints that bind.
    pub sole: [usize; 6],
}

impl Rejections {
    fn add(&mut self, r: Rejection) {
        self.add_first(r, true);
    }

    /// Counts a rejection by its first failing constraint `r`; `sole` when no other constraint
    /// was violated.
    fn add_first(&mut self, r: Rejection, sole: bool) {
        match r {
            Rejection::Unreachable => self.unreachable += 1,
            Rejection::Lift => self.lift += 1,
            Rejection::Visibility => self.visibility += 1,
            Rejection::Size => self.size += 1,
            Rejection::ViewAngle => self.view_angle += 1,
            Rejection::Collision => self.collision += 1,
        }
        if sole {
            self.sole[Self::slot(r)] += 1;
        }
    }

    /// Position of a constraint in [`Rejections::list`].
    fn slot(r: Rejection) -> usize {
        match r {
            Rejection::Visibility => 0,
            Rejection::Size => 1,
            Rejection::ViewAngle => 2,
            Rejection::Collision => 3,
            Rejection::Unreachable => 4,
            Rejection::Lift => 5,
        }
    }

    fn merge(&mut self, o: &Rejections) {
        self.unreachable += o.unreachable;
        self.lift += o.lift;
        self.visibility += o.visibility;
        self.size += o.size;
        self.view_angle += o.view_angle;
        self.collision += o.collision;
        for (a, b) in self.sole.iter_mut().zip(o.sole) {
            *a += b;
        }
    }

    fn list(&self) -> [(&'static str, usize); 6] {
        [
            ("visibility (6.17)", self.visibility),
            ("object size (6.18)", self.size),
            ("view angle (6.19)", self.view_angle),
            ("collision (6.20)", self.collision),
            ("inverse kinematics (unreachable)", self.unreachable),
            ("lift range", self.lift),
        ]
    }

    /// The no-feasible-pose error naming the binding constraint: the one most often violated
    /// alone (relaxing it would admit those candidates), else the one rejecting the most.
    pub fn error(&self, evaluated: usize) -> EstimateError {
        let list = self.list();
        let by_sole = (0..list.len())
            .filter(|&k| self.sole[k] > 0)
            .max_by_key(|&k| self.sole[k]);
        let binding = by_sole
            .or_else(|| (0..list.len()).max_by_key(|&k| list[k].1))
            .map_or("none", |k| list[k].0)
            .to_string();
        let counts = list
            .iter()
            .map(|(name, n)| format!("{name}: {n}"))
            .collect::<Vec<_>>()
            .join(", ");
        EstimateError::NoFeasiblePose {
            evaluated,
            binding,
            counts,
        }
    }
}

/// A planned (or evaluated) measurement pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedPose {
    /// Encoder readings to command.
    pub joints: Joints,
    /// The camera pose under the estimated model.
    pub camera_pose: Isometry3<f64>,
    /// The criterion's score (for D: the log-determinant gain).
    pub score: f64,
}

/// The result of a planner run.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The best feasible pose.
    pub best: PlannedPose,
    /// Candidate poses evaluated.
    pub evaluated: usize,
    /// Rejections per constraint (collision only counted for candidates good enough to need the
    /// check).
    pub rejections: Rejections,
}

/// Options of the planners.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannerOptions {
    /// The optimality criterion.
    pub criterion: Criterion,
    /// Yaw grid size of the line search.
    pub yaw_samples: usize,
    /// Half range of the yaw search around the facing yaw (radians).
    pub yaw_half_range: f64,
    /// Number of object depths (end-effector positions) sampled.
    pub depth_samples: usize,
    /// Depth range of the object centre in front of the camera (m), further limited by (6.18).
    pub depth_range: (f64, f64),
    /// Fractions of the way from the image centre to each image corner where the object centre
    /// is placed (1 = at the corner; infeasible placements are rejected).
    pub corner_fractions: Vec<f64>,
    /// Golden-section iterations refining the yaw of the best candidate.
    pub refine_iterations: usize,
    /// Number of random poses of [`plan_sampling`].
    pub samples: usize,
    /// Lateral half range (m) of the poses sampled by [`plan_sampling`].
    pub lateral_range: f64,
    /// Seed of [`plan_sampling`].
    pub seed: u64,
}

impl Default for PlannerOptions {
    fn default() -> Self {
        Self {
            criterion: Criterion::D,
            yaw_samples: 25,
            yaw_half_range: 50f64.to_radians(),
            depth_samples: 6,
            depth_range: (0.2, 0.9),
            corner_fractions: vec![1.0, 0.8, 0.6, 0.4],
            refine_iterations: 12,
            samples: 2000,
            lateral_range: 0.4,
            seed: 0,
        }
    }
}

/// The current belief the planner scores against: the estimate, `P` and its Cholesky factor.
struct Belief<'a> {
    params: &'a HandEyeParams,
    info: DMatrix<f64>,
    chol_p: DMatrix<f64>,
    criterion: Criterion,
}

impl<'a> Belief<'a> {
    fn new(params: &'a HandEyeParams, info: &DMatrix<f64>, criterion: Criterion) -> Result<Self> {
        let ch = design::cholesky("information matrix", info)?;
        let p = ch.inverse();
        let chol_p = Cholesky::new(design::symmetric("covariance", &p)?)
            .ok_or_else(|| design::singular("covariance", &p))?
            .l();
        Ok(Self {
            params,
            info: info.clone(),
            chol_p,
            criterion,
        })
    }

    /// The score of one measurement with whitened Jacobian `f`.
    fn score(&self, f: &DMatrix<f64>) -> Result<f64> {
        match self.criterion {
            Criterion::D => design::d_gain(&self.chol_p, f),
            Criterion::A => {
                let post = &self.info + f.transpose() * f;
                let ch = design::cholesky("posterior information", &post)?;
                let prior_trace = (&self.chol_p * self.chol_p.transpose()).trace();
                Ok(prior_trace - ch.inverse().trace())
            }
            Criterion::E => {
                let post = &self.info + f.transpose() * f;
                Ok(nalgebra::SymmetricEigen::new(post).eigenvalues.min())
            }
        }
    }
}

/// Evaluates the cheap constraints (6.17)–(6.19) of a camera pose under the estimate.
fn check_view(
    scene: &ActiveScene,
    params: &HandEyeParams,
    t_wc: &Isometry3<f64>,
) -> std::result::Result<(), (Rejection, bool)> {
    let cam = &scene.model.camera;
    let c = &scene.constraints;
    let t_cw = t_wc.inverse();
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut visible = true;
    for x in &scene.model.corners {
        let p_c = t_cw * (params.opening * Point3::from(*x));
        let Ok(px) = cam.project(&p_c.coords) else {
            // Behind the camera: size and view angle are meaningless; not a sole violation.
            return Err((Rejection::Visibility, false));
        };
        if px.x < c.margin_px
            || px.y < c.margin_px
            || px.x > w - 1.0 - c.margin_px
            || px.y > h - 1.0 - c.margin_px
        {
            visible = false;
        }
        umin = umin.min(px.x);
        umax = umax.max(px.x);
        vmin = vmin.min(px.y);
        vmax = vmax.max(px.y);
    }
    let size = (umax - umin).max(vmax - vmin);
    let size_ok = size >= c.size_px.0 && size <= c.size_px.1;
    let centre_w = params.opening * Point3::from(scene.centre());
    let to_cam = (t_wc.translation.vector - centre_w.coords).normalize();
    let n_w = params.opening.rotation * scene.normal;
    let angle_ok = to_cam.dot(&n_w).clamp(-1.0, 1.0).acos() <= c.max_view_angle;
    let violated = [
        (!visible, Rejection::Visibility),
        (!size_ok, Rejection::Size),
        (!angle_ok, Rejection::ViewAngle),
    ];
    let n = violated.iter().filter(|v| v.0).count();
    match violated.iter().find(|v| v.0) {
        Some(&(_, r)) => Err((r, n == 1)),
        None => Ok(()),
    }
}

/// A candidate that passed the cheap checks and was scored; collision is checked lazily.
#[derive(Clone)]
struct Scored {
    joints: Vec<Joints>,
    camera_pose: Isometry3<f64>,
    score: f64,
}

/// Scores a camera pose: cheap constraints, IK, lift, score (collision left to the caller).
fn score_camera_pose(
    scene: &ActiveScene,
    belief: &Belief<'_>,
    t_wc: &Isometry3<f64>,
    sigma_px: f64,
) -> Result<std::result::Result<Scored, (Rejection, bool)>> {
    // Every cheap constraint is evaluated (not only the first failing one) so that a rejection
    // can be marked as the sole violation, which identifies the binding constraint.
    let view = check_view(scene, belief.params, t_wc);
    let ik = scene.camera_ik(belief.params, t_wc).unwrap_or_default();
    let (lo, hi) = scene.constraints.lift_range;
    let in_range: Vec<Joints> = ik
        .iter()
        .copied()
        .filter(|q| {
            let h = q[4] - belief.params.joint_offsets[4];
            h >= lo && h <= hi
        })
        .collect();
    let reach = if ik.is_empty() {
        Some(Rejection::Unreachable)
    } else if in_range.is_empty() {
        Some(Rejection::Lift)
    } else {
        None
    };
    match (view, reach) {
        (Err((r, sole)), None) => return Ok(Err((r, sole))),
        (Err((r, _)), Some(_)) => return Ok(Err((r, false))),
        (Ok(()), Some(r)) => return Ok(Err((r, true))),
        (Ok(()), None) => {}
    }
    let sols = in_range;
    let (_, c) = scene.model.linearize(belief.params, &sols[0])?;
    let f = c / sigma_px;
    let score = belief.score(&f)?;
    Ok(Ok(Scored {
        joints: sols,
        camera_pose: *t_wc,
        score,
    }))
}

/// Scores joint vectors directly (finite candidate sets).
fn score_joints(
    scene: &ActiveScene,
    belief: &Belief<'_>,
    q_enc: &Joints,
    sigma_px: f64,
) -> Result<std::result::Result<Scored, (Rejection, bool)>> {
    let (lo, hi) = scene.constraints.lift_range;
    let h = q_enc[4] - belief.params.joint_offsets[4];
    let lift_ok = h >= lo && h <= hi;
    let t_wc = scene.model.camera_pose(belief.params, q_enc);
    match (check_view(scene, belief.params, &t_wc), lift_ok) {
        (Err((r, sole)), true) => return Ok(Err((r, sole))),
        (Err((r, _)), false) => return Ok(Err((r, false))),
        (Ok(()), false) => return Ok(Err((Rejection::Lift, true))),
        (Ok(()), true) => {}
    }
    let (_, c) = scene.model.linearize(belief.params, q_enc)?;
    let score = belief.score(&(c / sigma_px))?;
    Ok(Ok(Scored {
        joints: vec![*q_enc],
        camera_pose: t_wc,
        score,
    }))
}

/// The first collision-free IK branch of a scored candidate.
fn collision_free(
    scene: &ActiveScene,
    params: &HandEyeParams,
    s: &Scored,
) -> Result<Option<Joints>> {
    for q in &s.joints {
        let q_true = q - params.joint_offsets;
        if scene
            .shapes
            .is_free(&q_true, &scene.workspace, scene.constraints.min_clearance)?
        {
            return Ok(Some(*q));
        }
    }
    Ok(None)
}

/// Picks the best collision-free candidate (checking collision in descending score order).
fn select(
    scene: &ActiveScene,
    params: &HandEyeParams,
    mut scored: Vec<Scored>,
    evaluated: usize,
    mut rejections: Rejections,
) -> Result<Plan> {
    scored.sort_by(|a, b| b.score.total_cmp(&a.score));
    for s in &scored {
        if let Some(q) = collision_free(scene, params, s)? {
            return Ok(Plan {
                best: PlannedPose {
                    joints: q,
                    camera_pose: s.camera_pose,
                    score: s.score,
                },
                evaluated,
                rejections,
            });
        }
        rejections.add(Rejection::Collision);
    }
    Err(rejections.error(evaluated))
}

fn check_inputs(info: &DMatrix<f64>, sigma_px: f64, scene: &ActiveScene) -> Result<()> {
    let k = scene.model.mask.len();
    if info.nrows() != k || info.ncols() != k {
        return Err(EstimateError::DimensionMismatch {
            what: "information matrix".into(),
            expected: vec![k, k],
            got: vec![info.nrows(), info.ncols()],
        });
    }
    if !(sigma_px.is_finite() && sigma_px > 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "sigma_px",
            value: sigma_px,
            reason: "pixel noise must be positive and finite",
        });
    }
    Ok(())
}

/// The camera pose with blade yaw `psi` that sees the object centre at pixel `anchor` at depth
/// `depth`.
fn anchored_pose(
    scene: &ActiveScene,
    params: &HandEyeParams,
    psi: f64,
    anchor: &Vector2<f64>,
    depth: f64,
) -> Option<Isometry3<f64>> {
    let ray = scene.model.camera.unproject(anchor).ok()?;
    if ray.z <= 0.0 {
        return None;
    }
    let p_c = ray * (depth / ray.z);
    let rot = scene.camera_rotation(psi);
    let centre_w = params.opening * Point3::from(scene.centre());
    let t = centre_w.coords - rot * p_c;
    Some(Isometry3::from_parts(Translation3::from(t), rot))
}

/// The reduced search of 000_3b1454b2b2194811.txt ch. 6.3 (design steps 2–5, justified by
/// eqs. (6.24)–(6.25)).
///
/// The object centre is placed at anchors towards each image corner and edge midpoint
/// ([`PlannerOptions::corner_fractions`]), the blade yaw is line-searched on a grid of
/// `yaw_samples` values within `±yaw_half_range` of the facing yaw, and the object depth
/// (equivalently the end-effector position along the viewing ray) is sampled geometrically in
/// the depth range allowed by (6.18); each camera pose is turned into joints by inverse
/// kinematics. The yaw, depth and corner fraction of the best three grid candidates are refined
/// by coordinate-wise golden-section search. The best collision-free candidate is returned.
///
/// `info` is the current information matrix `P(k−1)⁻¹`; `sigma_px` the pixel noise. Errors:
/// [`EstimateError::NoFeasiblePose`] naming the binding constraint, a singular `info`.
pub fn plan_reduced(
    scene: &ActiveScene,
    params: &HandEyeParams,
    info: &DMatrix<f64>,
    sigma_px: f64,
    options: &PlannerOptions,
) -> Result<Plan> {
    check_inputs(info, sigma_px, scene)?;
    if options.yaw_samples == 0 || options.depth_samples == 0 || options.corner_fractions.is_empty()
    {
        return Err(EstimateError::InvalidProblem(
            "the reduced search needs at least one yaw, one depth and one corner fraction".into(),
        ));
    }
    let belief = Belief::new(params, info, options.criterion)?;
    let cam = &scene.model.camera;
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    let centre_px = Vector2::new(0.5 * (w - 1.0), 0.5 * (h - 1.0));
    // The four image corners (the seed's step 2), plus the edge midpoints: an object wider than
    // the image's aspect allows reaches the left/right edges before the corners.
    let corners = [
        Vector2::new(0.0, 0.0),
        Vector2::new(w - 1.0, 0.0),
        Vector2::new(0.0, h - 1.0),
        Vector2::new(w - 1.0, h - 1.0),
        Vector2::new(centre_px.x, 0.0),
        Vector2::new(centre_px.x, h - 1.0),
        Vector2::new(0.0, centre_px.y),
        Vector2::new(w - 1.0, centre_px.y),
    ];
    // (direction from the image centre towards a corner, fraction of the way); the centre once.
    let mut anchors: Vec<(Vector2<f64>, f64)> = vec![(Vector2::zeros(), 0.0)];
    for corner in corners {
        for &s in &options.corner_fractions {
            anchors.push((corner - centre_px, s));
        }
    }
    let anchor_px = |dir: &Vector2<f64>, s: f64| centre_px + s * dir;
    let f = 0.5 * (cam.fx() + cam.fy());
    let e = scene.extent();
    let c = &scene.constraints;
    let d_lo = options.depth_range.0.max(f * e / c.size_px.1);
    let d_hi = options.depth_range.1.min(f * e / c.size_px.0);
    if !(d_lo.is_finite() && d_hi.is_finite() && d_lo > 0.0 && d_lo <= d_hi) {
        return Err(EstimateError::NoFeasiblePose {
            evaluated: 0,
            binding: "object size (6.18)".into(),
            counts: format!(
                "depth range [{:.3}, {:.3}] m and size limits [{}, {}] px leave no depth (object extent {e:.3} m)",
                options.depth_range.0, options.depth_range.1, c.size_px.0, c.size_px.1
            ),
        });
    }
    let depths: Vec<f64> = (0..options.depth_samples)
        .map(|i| {
            if options.depth_samples == 1 {
                (d_lo * d_hi).sqrt()
            } else {
                d_lo * (d_hi / d_lo).powf(i as f64 / (options.depth_samples - 1) as f64)
            }
        })
        .collect();
    let yaw0 = scene.facing_yaw(params);
    let yaw_step = if options.yaw_samples > 1 {
        2.0 * options.yaw_half_range / (options.yaw_samples - 1) as f64
    } else {
        0.0
    };
    let yaws: Vec<f64> = (0..options.yaw_samples)
        .map(|i| yaw0 - options.yaw_half_range + yaw_step * i as f64)
        .map(|y| if options.yaw_samples == 1 { yaw0 } else { y })
        .collect();
    let mut rejections = Rejections::default();
    let mut evaluated = 0;
    // (candidate, yaw, anchor direction, fraction, depth)
    let mut scored: Vec<(Scored, f64, Vector2<f64>, f64, f64)> = Vec::new();
    let eval = |psi: f64,
                dir: &Vector2<f64>,
                s: f64,
                d: f64|
     -> Result<std::result::Result<Scored, (Rejection, bool)>> {
        let Some(t_wc) = anchored_pose(scene, params, psi, &anchor_px(dir, s), d) else {
            return Ok(Err((Rejection::Visibility, false)));
        };
        score_camera_pose(scene, &belief, &t_wc, sigma_px)
    };
    for &psi in &yaws {
        for (dir, s) in &anchors {
            for &d in &depths {
                evaluated += 1;
                match eval(psi, dir, *s, d)? {
                    Ok(sc) => scored.push((sc, psi, *dir, *s, d)),
                    Err((r, sole)) => rejections.add_first(r, sole),
                }
            }
        }
    }
    // Coordinate-wise golden-section refinement (yaw, depth, corner fraction) of the best few
    // grid candidates: the optimum usually lies on a constraint boundary between grid points.
    scored.sort_by(|a, b| b.0.score.total_cmp(&a.0.score));
    let depth_ratio = if depths.len() > 1 {
        depths[1] / depths[0]
    } else {
        1.2
    };
    let mut refined: Vec<Scored> = Vec::new();
    for (_, psi0, dir, s0, d0) in scored.iter().take(3) {
        let (mut psi, mut s, mut d) = (*psi0, *s0, *d0);
        for _ in 0..2 {
            let (x, best) = golden(
                psi - yaw_step,
                psi + yaw_step,
                options.refine_iterations,
                |x| {
                    evaluated += 1;
                    Ok(eval(x, dir, s, d)?.ok())
                },
            )?;
            if let Some(b) = best {
                psi = x;
                refined.push(b);
            }
            let (x, best) = golden(
                d / depth_ratio,
                d * depth_ratio,
                options.refine_iterations,
                |x| {
                    evaluated += 1;
                    Ok(eval(psi, dir, s, x)?.ok())
                },
            )?;
            if let Some(b) = best {
                d = x;
                refined.push(b);
            }
            if s > 0.0 {
                let (x, best) = golden(
                    (s - 0.2).max(0.0),
                    (s + 0.2).min(1.0),
                    options.refine_iterations,
                    |x| {
                        evaluated += 1;
                        Ok(eval(psi, dir, x, d)?.ok())
                    },
                )?;
                if let Some(b) = best {
                    s = x;
                    refined.push(b);
                }
            }
        }
    }
    let all: Vec<Scored> = scored.into_iter().map(|(s, ..)| s).chain(refined).collect();
    select(scene, params, all, evaluated, rejections)
}

/// Golden-section search of `[lo, hi]` for the maximum of a scored function (`None` = infeasible,
/// treated as −∞). Returns the best abscissa evaluated and its candidate.
fn golden(
    mut lo: f64,
    mut hi: f64,
    iterations: usize,
    mut f: impl FnMut(f64) -> Result<Option<Scored>>,
) -> Result<(f64, Option<Scored>)> {
    let gr = 0.5 * (5f64.sqrt() - 1.0);
    let val = |o: &Option<Scored>| o.as_ref().map_or(f64::NEG_INFINITY, |s| s.score);
    let mut x1 = hi - gr * (hi - lo);
    let mut x2 = lo + gr * (hi - lo);
    let mut f1 = f(x1)?;
    let mut f2 = f(x2)?;
    let mut best: (f64, Option<Scored>) = (f64::NAN, None);
    let keep = |x: f64, o: &Option<Scored>, best: &mut (f64, Option<Scored>)| {
        if let Some(s) = o
            && val(&best.1) < s.score
        {
            *best = (x, Some(s.clone()));
        }
    };
    keep(x1, &f1, &mut best);
    keep(x2, &f2, &mut best);
    for _ in 0..iterations {
        if val(&f1) >= val(&f2) {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - gr * (hi - lo);
            f1 = f(x1)?;
            keep(x1, &f1, &mut best);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + gr * (hi - lo);
            f2 = f(x2)?;
            keep(x2, &f2, &mut best);
        }
    }
    Ok(best)
}

/// Plain random sampling of camera poses (the sampling-based comparison): `samples` poses with
/// the object centre at a uniformly random depth in the depth range along the object normal,
/// a uniform lateral offset within `±lateral_range`, a uniform lift in its range and a uniform
/// yaw within `±yaw_half_range` of the facing yaw. Same evaluation and errors as
/// [`plan_reduced`].
pub fn plan_sampling(
    scene: &ActiveScene,
    params: &HandEyeParams,
    info: &DMatrix<f64>,
    sigma_px: f64,
    options: &PlannerOptions,
) -> Result<Plan> {
    check_inputs(info, sigma_px, scene)?;
    if options.samples == 0 {
        return Err(EstimateError::InvalidProblem(
            "plan_sampling needs at least one sample".into(),
        ));
    }
    let belief = Belief::new(params, info, options.criterion)?;
    let mut rng = Pcg64::seed_from_u64(options.seed);
    let centre_w = params.opening * Point3::from(scene.centre());
    let n_w = params.opening.rotation * scene.normal;
    let lateral = Vector3::z()
        .cross(&n_w)
        .try_normalize(1e-12)
        .unwrap_or_else(Vector3::y);
    let yaw0 = scene.facing_yaw(params);
    let robot = &scene.model.robot;
    let z_cam = |h: f64| {
        // Camera height above the base for lift h (the camera mount is rigid on the blade).
        (robot.base * Point3::new(0.0, 0.0, h + robot.params.h02 + params.camera_translation.z)).z
    };
    let (lo, hi) = scene.constraints.lift_range;
    let mut rejections = Rejections::default();
    let mut scored = Vec::new();
    for _ in 0..options.samples {
        let d = rng.random_range(options.depth_range.0..=options.depth_range.1);
        let l = rng.random_range(-options.lateral_range..=options.lateral_range);
        let hl = rng.random_range(lo..=hi);
        let psi = yaw0 + rng.random_range(-options.yaw_half_range..=options.yaw_half_range);
        let mut pos = centre_w.coords + n_w * d + lateral * l;
        pos.z = z_cam(hl);
        let t_wc = Isometry3::from_parts(Translation3::from(pos), scene.camera_rotation(psi));
        match score_camera_pose(scene, &belief, &t_wc, sigma_px)? {
            Ok(s) => scored.push(s),
            Err((r, sole)) => rejections.add_first(r, sole),
        }
    }
    select(scene, params, scored, options.samples, rejections)
}

/// The best of a finite set of candidate joint vectors (encoder readings) under the criterion.
/// Same errors as [`plan_reduced`]; an empty or non-finite candidate set is an input error.
pub fn plan_candidates(
    scene: &ActiveScene,
    params: &HandEyeParams,
    info: &DMatrix<f64>,
    sigma_px: f64,
    candidates: &[Joints],
    criterion: Criterion,
) -> Result<Plan> {
    check_inputs(info, sigma_px, scene)?;
    if candidates.is_empty() {
        return Err(EstimateError::DimensionMismatch {
            what: "candidate joints".into(),
            expected: vec![1, 5],
            got: vec![0, 5],
        });
    }
    for (i, q) in candidates.iter().enumerate() {
        if let Some((k, &v)) = q.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: "candidate joints".into(),
                index: 5 * i + k,
                value: v,
            });
        }
    }
    let belief = Belief::new(params, info, criterion)?;
    let mut rejections = Rejections::default();
    let mut scored = Vec::new();
    for q in candidates {
        match score_joints(scene, &belief, q, sigma_px)? {
            Ok(s) => scored.push(s),
            Err((r, sole)) => rejections.add_first(r, sole),
        }
    }
    select(scene, params, scored, candidates.len(), rejections)
}

/// Merges rejection counts (used by callers that run several planners).
pub fn merge_rejections(a: &mut Rejections, b: &Rejections) {
    a.merge(b);
}

/// A unit-free helper for tests and callers: the rotation about the world z axis by `yaw`.
pub fn yaw_rotation(yaw: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
}

/// Wraps an angle to `(−π, π]`.
pub fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::active::closed_loop::Scenario;
    use crate::active::model::HandEyeEstimator;

    /// The chamber scene and an estimator after one centred, noise-free measurement.
    fn setup() -> (ActiveScene, HandEyeEstimator) {
        let sc = Scenario::chamber().unwrap();
        let scene = sc.scene().unwrap();
        let nominal = HandEyeParams::nominal(&sc.robot, sc.opening);
        let rot = scene.camera_rotation(scene.facing_yaw(&nominal));
        let ray = sc.camera.unproject(&Vector2::new(639.5, 479.5)).unwrap();
        let centre = nominal.opening * Point3::from(scene.centre());
        let t_wc = Isometry3::from_parts(
            Translation3::from(centre.coords - rot * (ray * (0.6 / ray.z))),
            rot,
        );
        let q = scene.camera_ik(&nominal, &t_wc).unwrap()[0];
        let prior: Vec<f64> = sc
            .mask
            .indices()
            .iter()
            .map(|&i| sc.prior_sigmas[i])
            .collect();
        let mut est =
            HandEyeEstimator::new(scene.model.clone(), nominal, &prior, sc.sigma_px).unwrap();
        let det = scene.model.project(&nominal, &q).unwrap();
        est.update(&q, &det).unwrap();
        (scene, est)
    }

    #[test]
    fn reduced_search_returns_a_feasible_pose_at_least_as_good_as_sampling() {
        let (scene, est) = setup();
        let opts = PlannerOptions::default();
        let plan = plan_reduced(&scene, &est.estimate, est.information(), 0.5, &opts).unwrap();
        // Independent feasibility check of the returned joints.
        let q = plan.best.joints;
        let px = scene.model.project(&est.estimate, &q).unwrap();
        let c = &scene.constraints;
        for p in &px {
            let p = p.unwrap();
            assert!(
                p.x >= c.margin_px
                    && p.y >= c.margin_px
                    && p.x <= 1279.0 - c.margin_px
                    && p.y <= 959.0 - c.margin_px
            );
        }
        assert!(
            scene
                .shapes
                .is_free(&q, &scene.workspace, c.min_clearance)
                .unwrap()
        );
        assert!(q[4] >= c.lift_range.0 && q[4] <= c.lift_range.1);
        // Its score is the D gain of the pose (recomputed from the information matrices).
        let (_, cm) = scene.model.linearize(&est.estimate, &q).unwrap();
        let f = cm / 0.5;
        let post = est.information() + f.transpose() * &f;
        let gain = design::log_det_spd("post", &post).unwrap()
            - design::log_det_spd("prior", est.information()).unwrap();
        assert!((plan.best.score - gain).abs() < 1e-8 * gain.abs().max(1.0));
        // Plain sampling with a similar budget does not beat the reduced search.
        for seed in 0..3 {
            let o = PlannerOptions {
                seed,
                samples: 3000,
                ..opts.clone()
            };
            let sampled = plan_sampling(&scene, &est.estimate, est.information(), 0.5, &o).unwrap();
            assert!(
                sampled.best.score <= plan.best.score + 1e-9,
                "{} > {}",
                sampled.best.score,
                plan.best.score
            );
        }
    }

    #[test]
    fn infeasible_constraints_name_the_binding_constraint() {
        let (mut scene, est) = setup();
        scene.constraints.max_view_angle = 1e-4;
        let err = plan_reduced(
            &scene,
            &est.estimate,
            est.information(),
            0.5,
            &PlannerOptions::default(),
        )
        .unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("binding constraint: view angle (6.19)"),
            "{msg}"
        );
        scene.constraints.max_view_angle = 1.0;
        scene.constraints.size_px = (5000.0, 6000.0);
        let err = plan_reduced(
            &scene,
            &est.estimate,
            est.information(),
            0.5,
            &PlannerOptions::default(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("object size (6.18)"), "{err}");
        scene.constraints.size_px = (300.0, 2000.0);
        scene.constraints.lift_range = (1.0, 2.0);
        let err = plan_reduced(
            &scene,
            &est.estimate,
            est.information(),
            0.5,
            &PlannerOptions::default(),
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("binding constraint: lift range"),
            "{err}"
        );
        scene.constraints.lift_range = (0.0, 0.4);
        // A singular information matrix is reported, not planned with.
        let zero = DMatrix::zeros(8, 8);
        assert!(matches!(
            plan_reduced(
                &scene,
                &est.estimate,
                &zero,
                0.5,
                &PlannerOptions::default()
            ),
            Err(EstimateError::SingularInformation { .. })
        ));
        assert!(
            plan_reduced(
                &scene,
                &est.estimate,
                est.information(),
                0.0,
                &PlannerOptions::default()
            )
            .is_err()
        );
        assert!("X".parse::<Criterion>().is_err());
    }
}
