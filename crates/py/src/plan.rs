//! Bindings of motion planning (issue 30): `autoteach_geometry::plan` (workspace, A*, RRT*,
//! B-splines, dynamics, limits) and `autoteach_estimate::plan` (time-optimal optimisation).
//! The friendly wrapper is `python/autoteach/plan.py`.

use autoteach_estimate::plan::{OptimizeConfig, optimize_trajectory, optimize_waypoints};
use autoteach_geometry::collision::{LinkDims, Obstacle};
use autoteach_geometry::plan::PlanError;
use autoteach_geometry::plan::astar::{AStarConfig, astar};
use autoteach_geometry::plan::bspline::{BSpline, BSplineTrajectory};
use autoteach_geometry::plan::dynamics::{Dynamics, DynamicsParams};
use autoteach_geometry::plan::limits::Limits;
use autoteach_geometry::plan::rrt_star::{RrtStarConfig, rrt_star};
use autoteach_geometry::plan::workspace::{
    CarriedWafer, PlanWorkspace, default_limits, default_scene,
};
use autoteach_geometry::robot::{Joints, WaferRobot};
use nalgebra::Vector3;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, finite_array};
use crate::errors;

type Arr<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Named joint configurations `[(name, q)]`.
type NamedPoses = Vec<(String, [f64; 5])>;

/// Maps every planning error to its exception: a configuration in collision, malformed input
/// and infeasible limits → `InvalidInputError`; no path within the budget → `ConvergenceError`.
/// (The mapping itself is `errors::plan`, beside the other crates' mappings.)
fn err(e: PlanError) -> PyErr {
    errors::plan(e)
}

fn joints(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Joints> {
    let v = finite_array(obj, name)?.exact(&[5])?;
    Ok(Joints::from_column_slice(&v))
}

fn joints_rows(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<Joints>> {
    let a = finite_array(obj, name)?;
    if a.shape().len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (N, 5), got {:?}",
            a.shape()
        )));
    }
    Ok(a.rows(5, "(N, 5)")?
        .0
        .iter()
        .map(|r| Joints::from_column_slice(r))
        .collect())
}

fn rows_out<'py>(py: Python<'py>, qs: &[Joints]) -> PyResult<Arr<'py>> {
    let flat: Vec<f64> = qs.iter().flat_map(|q| q.iter().copied()).collect();
    convert::to_numpy(py, flat, &[qs.len(), 5])
}

/// The planning workspace: robot, carried wafer, joint limits and box obstacles.
#[pyclass(name = "PlanWorkspace", module = "autoteach._core", frozen)]
pub struct PyPlanWorkspace {
    ws: PlanWorkspace,
}

#[pymethods]
impl PyPlanWorkspace {
    /// A workspace of the default robot with box obstacles `(name, pose 4×4, half_extents)`,
    /// optionally carrying a 300 mm wafer on blade 1.
    #[new]
    #[pyo3(signature = (obstacles, wafer=true))]
    fn new(
        obstacles: Vec<(String, Bound<'_, PyAny>, Bound<'_, PyAny>)>,
        wafer: bool,
    ) -> PyResult<Self> {
        let mut obs = Vec::new();
        for (name, pose, half) in &obstacles {
            let pose = convert::isometry(pose, "obstacle pose")?;
            let h = finite_array(half, "half_extents")?.exact(&[3])?;
            obs.push(
                Obstacle::new(name.clone(), pose, Vector3::new(h[0], h[1], h[2]))
                    .map_err(errors::geometry)?,
            );
        }
        let (lo, hi) = default_limits();
        let ws = PlanWorkspace::new(
            WaferRobot::default(),
            LinkDims::default(),
            wafer.then(CarriedWafer::default),
            lo,
            hi,
            obs,
        )
        .map_err(err)?;
        Ok(Self { ws })
    }

    /// `(distance, link, obstacle)` of the closest pair at `q`, or `None` without obstacles.
    fn clearance(&self, q: &Bound<'_, PyAny>) -> PyResult<Option<(f64, String, String)>> {
        let q = joints(q, "q")?;
        Ok(self
            .ws
            .clearance(&q)
            .map_err(err)?
            .map(|c| (c.distance, c.link.to_string(), c.obstacle)))
    }

    /// `(distance, gradient)` of the signed distance at `q`.
    fn distance_gradient<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
    ) -> PyResult<(f64, Arr<'py>)> {
        let (d, g) = self.ws.distance_gradient(&joints(q, "q")?).map_err(err)?;
        Ok((d, convert::to_numpy(py, g.iter().copied().collect(), &[5])?))
    }

    /// `(name, pose 4×4 rows, half_extents)` of every obstacle.
    fn obstacles(&self) -> Vec<(String, [[f64; 4]; 4], [f64; 3])> {
        self.ws
            .obstacles()
            .iter()
            .map(|o| {
                (
                    o.name.clone(),
                    convert::isometry_rows(&o.pose),
                    [o.half_extents.x, o.half_extents.y, o.half_extents.z],
                )
            })
            .collect()
    }

    /// `(lower, upper)` joint limits.
    fn joint_limits(&self) -> ([f64; 5], [f64; 5]) {
        let a = |j: &Joints| std::array::from_fn(|i| j[i]);
        (a(&self.ws.lower), a(&self.ws.upper))
    }

    /// Link names and world centres at `q`.
    fn link_centres(&self, q: &Bound<'_, PyAny>) -> PyResult<Vec<(String, [f64; 3])>> {
        let q = joints(q, "q")?;
        Ok(self
            .ws
            .link_centres(&q)
            .into_iter()
            .map(|(n, p)| (n.to_string(), [p.x, p.y, p.z]))
            .collect())
    }
}

/// The default scene: the workspace and its named poses `[(name, q)]`.
#[pyfunction]
fn plan_default_scene() -> PyResult<(PyPlanWorkspace, NamedPoses)> {
    let (ws, poses) = default_scene().map_err(err)?;
    let poses = poses
        .into_iter()
        .map(|p| (p.name, std::array::from_fn(|i| p.q[i])))
        .collect();
    Ok((PyPlanWorkspace { ws }, poses))
}

/// Plans a path with `method` `"rrt*"` or `"a*"`; returns a dict of the `PathResult` fields
/// (plus `tree_cost`, `first_solution_s`, `nodes` for RRT*). `time_limit_s` ends RRT* at the
/// first iteration after that many seconds once a path exists.
#[pyfunction]
#[pyo3(signature = (workspace, q_start, q_goal, method="rrt*", margin=0.01, max_iterations=3000, seed=7, step_deg=5.0, joints_planned=None, time_limit_s=None))]
#[allow(clippy::too_many_arguments)]
fn plan_path<'py>(
    py: Python<'py>,
    workspace: &PyPlanWorkspace,
    q_start: &Bound<'py, PyAny>,
    q_goal: &Bound<'py, PyAny>,
    method: &str,
    margin: f64,
    max_iterations: usize,
    seed: u64,
    step_deg: f64,
    joints_planned: Option<Vec<usize>>,
    time_limit_s: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (a, b) = (joints(q_start, "q_start")?, joints(q_goal, "q_goal")?);
    if let Some(t) = time_limit_s.filter(|t| !(t.is_finite() && *t > 0.0)) {
        return Err(errors::invalid_input(format!(
            "time_limit_s must be positive and finite, got {t}"
        )));
    }
    if !(margin.is_finite() && margin >= 0.0 && step_deg.is_finite() && step_deg > 0.0) {
        return Err(errors::invalid_input(format!(
            "margin ({margin}) must be non-negative and step_deg ({step_deg}) positive"
        )));
    }
    let ws = &workspace.ws;
    let out = PyDict::new(py);
    match method {
        "rrt*" | "rrt_star" => {
            let cfg = RrtStarConfig {
                max_iterations,
                margin,
                seed,
                time_limit_s,
                ..RrtStarConfig::default()
            };
            let r = convert::detached(py, || rrt_star(ws, &a, &b, &cfg).map_err(err))?;
            out.set_item("tree_cost", r.tree_cost)?;
            out.set_item("first_solution_s", r.first_solution_s)?;
            out.set_item("first_solution_iteration", r.first_solution_iteration)?;
            out.set_item("nodes", r.nodes)?;
            fill(py, &out, &r.result)?;
        }
        "a*" | "astar" => {
            let d = step_deg.to_radians();
            let mut cfg = AStarConfig {
                margin,
                max_expansions: max_iterations.max(1).saturating_mul(1000),
                ..AStarConfig::default()
            };
            cfg.step = Joints::new(d, d, d, d, cfg.step[4] * step_deg / 5.0);
            if let Some(j) = joints_planned {
                cfg.joints = j;
            }
            let r = convert::detached(py, || astar(ws, &a, &b, &cfg).map_err(err))?;
            fill(py, &out, &r)?;
        }
        m => {
            return Err(errors::invalid_input(format!(
                "unknown method {m:?} (expected \"rrt*\" or \"a*\")"
            )));
        }
    }
    Ok(out)
}

fn fill<'py>(
    py: Python<'py>,
    out: &Bound<'py, PyDict>,
    r: &autoteach_geometry::plan::astar::PathResult,
) -> PyResult<()> {
    out.set_item("path", rows_out(py, &r.path)?)?;
    out.set_item("cost", r.cost)?;
    out.set_item("iterations", r.iterations)?;
    out.set_item("collision_checks", r.collision_checks)?;
    out.set_item("time_s", r.time_s)?;
    Ok(())
}

/// What both optimiser bindings build from their arguments: the limits (velocity,
/// acceleration, jerk and torque 5-vectors, in that order), the workspace robot's dynamics with
/// the default masses, and the optimiser's configuration.
fn optimizer_inputs(
    workspace: &PyPlanWorkspace,
    vectors: [&Bound<'_, PyAny>; 4],
    d_safe: f64,
    n_ctrl: usize,
    max_iterations: usize,
) -> PyResult<(Limits, Dynamics, OptimizeConfig)> {
    let [velocity, acceleration, jerk, torque] = vectors;
    let limits = Limits {
        velocity: joints(velocity, "velocity")?,
        acceleration: joints(acceleration, "acceleration")?,
        jerk: joints(jerk, "jerk")?,
        torque: joints(torque, "torque")?,
        d_safe,
    };
    let ws = &workspace.ws;
    let dy = Dynamics::new(
        &ws.robot.params,
        &DynamicsParams::default(),
        ws.wafer.as_ref(),
    );
    let cfg = OptimizeConfig {
        n_ctrl,
        max_iterations,
        ..OptimizeConfig::default()
    };
    Ok((limits, dy, cfg))
}

/// Optimises a trajectory along `path` (N×5); limits as 5-vectors. Returns a dict of the
/// `OptimizeResult` fields with the trajectory as `knots` and `control_points`.
#[pyfunction]
#[pyo3(signature = (workspace, path, velocity, acceleration, jerk, torque, d_safe=0.01, n_ctrl=0, max_iterations=40))]
#[allow(clippy::too_many_arguments)]
fn plan_optimize<'py>(
    py: Python<'py>,
    workspace: &PyPlanWorkspace,
    path: &Bound<'py, PyAny>,
    velocity: &Bound<'py, PyAny>,
    acceleration: &Bound<'py, PyAny>,
    jerk: &Bound<'py, PyAny>,
    torque: &Bound<'py, PyAny>,
    d_safe: f64,
    n_ctrl: usize,
    max_iterations: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let path = joints_rows(path, "path")?;
    let (limits, dy, cfg) = optimizer_inputs(
        workspace,
        [velocity, acceleration, jerk, torque],
        d_safe,
        n_ctrl,
        max_iterations,
    )?;
    let ws = &workspace.ws;
    let r = convert::detached(py, || {
        optimize_trajectory(ws, &dy, &path, &limits, &cfg).map_err(err)
    })?;
    let out = PyDict::new(py);
    let n = r.trajectory.knots().len();
    out.set_item(
        "knots",
        convert::to_numpy(py, r.trajectory.knots().to_vec(), &[n])?,
    )?;
    out.set_item(
        "control_points",
        rows_out(py, r.trajectory.control_points())?,
    )?;
    for (k, v) in [
        ("duration", r.duration),
        ("initial_duration", r.initial_duration),
        ("lower_bound", r.lower_bound),
        ("gap", r.gap),
        ("time_s", r.time_s),
    ] {
        out.set_item(k, v)?;
    }
    out.set_item("bound_joint", r.bound_joint)?;
    out.set_item("active", r.active)?;
    out.set_item("iterations", r.iterations)?;
    out.set_item("accepted", r.accepted)?;
    out.set_item("verification", verification_dict(py, &r.verification)?)?;
    Ok(out)
}

/// Optimises a transfer through the way-points that join `paths` (each N×5); with
/// `free_velocities` the way-point velocities are unknowns. Returns a dict: `segments` as
/// `(knots, control_points)` pairs, `velocities` (K−1, 5), the durations, counts and the
/// per-segment verification.
#[pyfunction]
#[pyo3(signature = (workspace, paths, velocity, acceleration, jerk, torque, d_safe=0.01, free_velocities=true, n_ctrl=0, max_iterations=40))]
#[allow(clippy::too_many_arguments)]
fn plan_optimize_waypoints<'py>(
    py: Python<'py>,
    workspace: &PyPlanWorkspace,
    paths: Vec<Bound<'py, PyAny>>,
    velocity: &Bound<'py, PyAny>,
    acceleration: &Bound<'py, PyAny>,
    jerk: &Bound<'py, PyAny>,
    torque: &Bound<'py, PyAny>,
    d_safe: f64,
    free_velocities: bool,
    n_ctrl: usize,
    max_iterations: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let paths = paths
        .iter()
        .map(|p| joints_rows(p, "paths"))
        .collect::<PyResult<Vec<_>>>()?;
    let (limits, dy, cfg) = optimizer_inputs(
        workspace,
        [velocity, acceleration, jerk, torque],
        d_safe,
        n_ctrl,
        max_iterations,
    )?;
    let ws = &workspace.ws;
    let r = convert::detached(py, || {
        optimize_waypoints(ws, &dy, &paths, &limits, &cfg, free_velocities).map_err(err)
    })?;
    let out = PyDict::new(py);
    let mut segs = Vec::with_capacity(r.segments.len());
    for tr in &r.segments {
        let n = tr.knots().len();
        segs.push((
            convert::to_numpy(py, tr.knots().to_vec(), &[n])?,
            rows_out(py, tr.control_points())?,
        ));
    }
    out.set_item("segments", segs)?;
    out.set_item("velocities", rows_out(py, &r.velocities)?)?;
    out.set_item("duration", r.duration)?;
    out.set_item("initial_duration", r.initial_duration)?;
    out.set_item("iterations", r.iterations)?;
    out.set_item("accepted", r.accepted)?;
    out.set_item("time_s", r.time_s)?;
    let mut vers = Vec::with_capacity(r.verification.len());
    for v in &r.verification {
        vers.push(verification_dict(py, v)?);
    }
    out.set_item("verification", vers)?;
    Ok(out)
}

fn verification_dict<'py>(
    py: Python<'py>,
    v: &autoteach_geometry::plan::limits::Verification,
) -> PyResult<Bound<'py, PyDict>> {
    let ver = PyDict::new(py);
    ver.set_item("velocity_ratio", v.velocity_ratio)?;
    ver.set_item("acceleration_ratio", v.acceleration_ratio)?;
    ver.set_item("jerk_ratio", v.jerk_ratio)?;
    ver.set_item("torque_ratio", v.torque_ratio)?;
    ver.set_item("min_clearance", v.min_clearance)?;
    ver.set_item("samples", v.samples)?;
    Ok(ver)
}

/// Samples a clamped cubic B-spline trajectory at `times`: `(q, dq, ddq, dddq)`, each (M, 5).
#[pyfunction]
fn plan_sample<'py>(
    py: Python<'py>,
    knots: &Bound<'py, PyAny>,
    control_points: &Bound<'py, PyAny>,
    times: &Bound<'py, PyAny>,
) -> PyResult<(Arr<'py>, Arr<'py>, Arr<'py>, Arr<'py>)> {
    let knots = finite_array(knots, "knots")?.vector()?;
    let ctrl = joints_rows(control_points, "control_points")?;
    let times = finite_array(times, "times")?.vector()?;
    let spline = BSpline::new(3, knots, ctrl).map_err(err)?;
    let tr = BSplineTrajectory::from_spline(spline).map_err(err)?;
    let s: Vec<_> = times.iter().map(|&t| tr.sample(t)).collect();
    Ok((
        rows_out(py, &s.iter().map(|x| x.q).collect::<Vec<_>>())?,
        rows_out(py, &s.iter().map(|x| x.dq).collect::<Vec<_>>())?,
        rows_out(py, &s.iter().map(|x| x.ddq).collect::<Vec<_>>())?,
        rows_out(py, &s.iter().map(|x| x.dddq).collect::<Vec<_>>())?,
    ))
}

/// Inverse dynamics `τ(q, q̇, q̈)` (eqs. 2.8–2.9) with the default masses and a carried wafer.
#[pyfunction]
#[pyo3(signature = (q, dq, ddq, wafer=true))]
fn plan_inverse_dynamics<'py>(
    py: Python<'py>,
    q: &Bound<'py, PyAny>,
    dq: &Bound<'py, PyAny>,
    ddq: &Bound<'py, PyAny>,
    wafer: bool,
) -> PyResult<Arr<'py>> {
    let w = CarriedWafer::default();
    let dy = Dynamics::new(
        &WaferRobot::default().params,
        &DynamicsParams::default(),
        wafer.then_some(&w),
    );
    let t = dy.torques(&joints(q, "q")?, &joints(dq, "dq")?, &joints(ddq, "ddq")?);
    // Finite inputs can still overflow (q̇² of 1e155 rad/s): say so instead of returning inf.
    if let Some(k) = t.iter().position(|v| !v.is_finite()) {
        return Err(errors::invalid_input(format!(
            "the generalised force of joint {} is {}: q, dq and ddq are too large for the dynamics \
             (|dq| and |ddq| must keep q̇², q̈ within the f64 range)",
            k + 1,
            t[k]
        )));
    }
    convert::to_numpy(py, t.iter().copied().collect(), &[5])
}

/// Registers the planning bindings.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPlanWorkspace>()?;
    m.add_function(wrap_pyfunction!(plan_default_scene, m)?)?;
    m.add_function(wrap_pyfunction!(plan_path, m)?)?;
    m.add_function(wrap_pyfunction!(plan_optimize, m)?)?;
    m.add_function(wrap_pyfunction!(plan_optimize_waypoints, m)?)?;
    m.add_function(wrap_pyfunction!(plan_sample, m)?)?;
    m.add_function(wrap_pyfunction!(plan_inverse_dynamics, m)?)?;
    Ok(())
}
