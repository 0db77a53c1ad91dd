//! Bindings of `autoteach_estimate::active` (000_3b1454b2b2194811.txt ch. 6): design
//! functions, the hand-eye estimator and planner (`ActiveSystem`) and the simulated closed
//! loop. The friendly API is `autoteach.active`.

use autoteach_estimate::EstimateError;
use autoteach_estimate::active::closed_loop::{self, LoopMode, Scenario, TrialResult};
use autoteach_estimate::active::design::{self, DetmaxOptions, ObservabilityIndices};
use autoteach_estimate::active::model::{
    HandEyeEstimator, HandEyeParams, N_FULL, PARAM_NAMES, ParamMask,
};
use autoteach_estimate::active::planner::{self, ActiveScene, Criterion, Plan};
use autoteach_geometry::robot::Joints;
use nalgebra::{DMatrix, Vector2};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{self, to_numpy};
use crate::errors;

/// Adds the active functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(active_fisher_information, m)?)?;
    m.add_function(wrap_pyfunction!(active_observability_indices, m)?)?;
    m.add_function(wrap_pyfunction!(active_d_optimal_design, m)?)?;
    m.add_function(wrap_pyfunction!(active_directional_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(active_detmax, m)?)?;
    m.add_function(wrap_pyfunction!(active_run_trials, m)?)?;
    m.add("ACTIVE_PARAM_NAMES", PARAM_NAMES.to_vec())?;
    m.add_class::<PyActiveSystem>()?;
    Ok(())
}

/// Maps the active-specific errors to their Python exceptions (singular information →
/// `DegenerateGeometryError`, no feasible pose → `UnreachablePoseError`), the rest as usual.
fn err(e: EstimateError) -> PyErr {
    match e {
        EstimateError::SingularInformation { .. } => {
            errors::new_err(errors::Class::DegenerateGeometry, e.to_string())
        }
        EstimateError::NoFeasiblePose { .. } => {
            errors::new_err(errors::Class::UnreachablePose, e.to_string())
        }
        EstimateError::InvalidProblem(_) => errors::invalid_input(e.to_string()),
        other => errors::estimate(other),
    }
}

/// A finite 2-D float64 array as a matrix.
fn matrix(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<DMatrix<f64>> {
    let a = convert::finite_array(obj, name)?;
    let shape = a.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must be two-dimensional, got shape {}",
            convert::shape_str(&shape)
        )));
    }
    let data = a.exact(&shape)?;
    Ok(DMatrix::from_row_slice(shape[0], shape[1], &data))
}

/// A sequence of 2-D arrays as matrices.
fn matrices(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<DMatrix<f64>>> {
    let list = obj.cast::<PyList>().map_err(|_| {
        errors::invalid_input(format!("{name} must be a list of 2-D float64 arrays"))
    })?;
    list.iter().map(|item| matrix(&item, name)).collect()
}

fn mat_out<'py>(py: Python<'py>, m: &DMatrix<f64>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    to_numpy(
        py,
        m.transpose().as_slice().to_vec(),
        &[m.nrows(), m.ncols()],
    )
}

fn joints(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Joints> {
    let v = convert::finite_array(obj, name)?.exact(&[5])?;
    Ok(Joints::from_column_slice(&v))
}

fn indices_dict<'py>(py: Python<'py>, o: &ObservabilityIndices) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in [
        ("O1", o.o1),
        ("O2", o.o2),
        ("O3", o.o3),
        ("O4", o.o4),
        ("O5", o.o5),
        ("O6", o.o6),
        ("power", o.power),
        ("log_det", o.log_det),
    ] {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// Fisher information `Σ ω_i/σ_i² J_iᵀ J_i` of a design (eq. (6.6)).
#[pyfunction]
fn active_fisher_information<'py>(
    py: Python<'py>,
    jacobians: &Bound<'py, PyAny>,
    sigmas: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let js = matrices(jacobians, "jacobians")?;
    let s = convert::finite_array(sigmas, "sigmas")?.vector()?;
    let w = convert::finite_array(weights, "weights")?.vector()?;
    let m = design::fisher_information(&js, &s, &w).map_err(err)?;
    mat_out(py, &m)
}

/// Observability indices O1–O6 (Table 6.2) of an information matrix, with the O6 power.
#[pyfunction]
#[pyo3(signature = (information, power=2.0))]
fn active_observability_indices<'py>(
    py: Python<'py>,
    information: &Bound<'py, PyAny>,
    power: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let m = matrix(information, "information")?;
    let o = design::observability_indices(&m, power).map_err(err)?;
    indices_dict(py, &o)
}

/// Approximate D-optimal design weights on a finite candidate set (multiplicative algorithm).
#[pyfunction]
#[pyo3(signature = (candidates, tol=1e-6, max_iterations=100_000))]
fn active_d_optimal_design<'py>(
    py: Python<'py>,
    candidates: &Bound<'py, PyAny>,
    tol: f64,
    max_iterations: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let f = matrices(candidates, "candidates")?;
    let d = convert::detached(py, || {
        design::d_optimal_design(&f, tol, max_iterations).map_err(err)
    })?;
    let out = PyDict::new(py);
    out.set_item(
        "weights",
        to_numpy(py, d.weights.clone(), &[d.weights.len()])?,
    )?;
    out.set_item(
        "variance",
        to_numpy(py, d.variance.clone(), &[d.variance.len()])?,
    )?;
    out.set_item("max_variance", d.max_variance)?;
    out.set_item("log_det", d.log_det)?;
    out.set_item("iterations", d.iterations)?;
    Ok(out)
}

/// Directional derivatives `φ(x_i, ξ) = p − tr(M⁻¹ F_iᵀF_i)` (eq. (6.8), D-criterion).
#[pyfunction]
fn active_directional_derivatives<'py>(
    py: Python<'py>,
    candidates: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let f = matrices(candidates, "candidates")?;
    let w = convert::finite_array(weights, "weights")?.vector()?;
    let phi = design::d_directional_derivatives(&f, &w).map_err(err)?;
    let n = phi.len();
    to_numpy(py, phi, &[n])
}

/// DETMAX selection of `n` candidates maximising `log det(M0 + Σ F_iᵀF_i)` (eq. (6.10)).
#[pyfunction]
#[pyo3(signature = (candidates, n, prior=None, max_excursion=3, allow_repeats=false, seed=0))]
fn active_detmax<'py>(
    py: Python<'py>,
    candidates: &Bound<'py, PyAny>,
    n: usize,
    prior: Option<&Bound<'py, PyAny>>,
    max_excursion: usize,
    allow_repeats: bool,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let f = matrices(candidates, "candidates")?;
    let prior = prior.map(|p| matrix(p, "prior")).transpose()?;
    let opts = DetmaxOptions {
        max_excursion,
        allow_repeats,
        seed,
        ..DetmaxOptions::default()
    };
    let r = convert::detached(py, || {
        design::detmax(&f, n, prior.as_ref(), &opts).map_err(err)
    })?;
    let out = PyDict::new(py);
    out.set_item("selected", r.selected)?;
    out.set_item("log_det", r.log_det)?;
    out.set_item("excursions", r.excursions)?;
    Ok(out)
}

/// Builds the scenario from keyword options.
fn scenario(
    steps: Option<usize>,
    sigma_px: Option<f64>,
    power: Option<f64>,
    estimate: Option<Vec<String>>,
) -> PyResult<Scenario> {
    let mut sc = Scenario::chamber().map_err(err)?;
    if let Some(s) = steps {
        sc.steps = s;
    }
    if let Some(s) = sigma_px {
        if !(s.is_finite() && s > 0.0) {
            return Err(errors::invalid_input(format!(
                "sigma_px must be positive and finite, got {s}"
            )));
        }
        sc.sigma_px = s;
    }
    if let Some(p) = power {
        if !(p.is_finite() && p > 0.0) {
            return Err(errors::invalid_input(format!(
                "power must be positive and finite, got {p}"
            )));
        }
        sc.power = p;
    }
    if let Some(names) = estimate {
        sc.mask = ParamMask::from_names(&names).map_err(err)?;
    }
    Ok(sc)
}

/// Runs the simulated closed loop (Fig. 6.1) for `trials` trials of one mode (`"reduced"`,
/// `"sampling"` or `"baseline"`) and returns the per-trial records as arrays.
#[pyfunction]
#[pyo3(signature = (trials, seed=0, mode="reduced", steps=None, sigma_px=None, power=None, estimate=None))]
#[allow(clippy::too_many_arguments)]
fn active_run_trials<'py>(
    py: Python<'py>,
    trials: usize,
    seed: u64,
    mode: &str,
    steps: Option<usize>,
    sigma_px: Option<f64>,
    power: Option<f64>,
    estimate: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyDict>> {
    if trials == 0 {
        return Err(errors::invalid_input("trials must be at least 1"));
    }
    let mode: LoopMode = mode.parse().map_err(err)?;
    let sc = scenario(steps, sigma_px, power, estimate)?;
    let results: Vec<TrialResult> = convert::detached(py, || {
        closed_loop::run_trials(&sc, seed, trials, mode).map_err(err)
    })?;
    let steps = sc.steps;
    let t = results.len();
    let mut errors_ = Vec::with_capacity(t * steps * N_FULL);
    let mut indices = Vec::with_capacity(t * steps * 8);
    let mut joints_ = Vec::with_capacity(t * steps * 5);
    let mut detected = Vec::with_capacity(t * steps);
    let mut times = Vec::with_capacity(t * steps.saturating_sub(1));
    let mut scores = Vec::with_capacity(t * steps.saturating_sub(1));
    let mut coupled = Vec::with_capacity(t * 3);
    let mut infeasible = Vec::with_capacity(t);
    for r in &results {
        for e in &r.errors {
            errors_.extend_from_slice(e);
        }
        for o in &r.indices {
            indices.extend_from_slice(&[o.o1, o.o2, o.o3, o.o4, o.o5, o.o6, o.log_det]);
        }
        for q in &r.joints {
            joints_.extend_from_slice(q.as_slice());
        }
        detected.extend(r.detected.iter().map(|&d| d as f64));
        times.extend_from_slice(&r.plan_times);
        scores.extend_from_slice(&r.scores);
        coupled.extend_from_slice(&r.coupled);
        infeasible.push(r.infeasible_steps as f64);
    }
    let out = PyDict::new(py);
    out.set_item("names", PARAM_NAMES.to_vec())?;
    out.set_item("estimated", sc.mask.names())?;
    out.set_item("errors", to_numpy(py, errors_, &[t, steps, N_FULL])?)?;
    out.set_item("indices", to_numpy(py, indices, &[t, steps, 7])?)?;
    out.set_item("joints", to_numpy(py, joints_, &[t, steps, 5])?)?;
    out.set_item("detected", to_numpy(py, detected, &[t, steps])?)?;
    out.set_item(
        "plan_times",
        to_numpy(py, times, &[t, steps.saturating_sub(1)])?,
    )?;
    out.set_item(
        "scores",
        to_numpy(py, scores, &[t, steps.saturating_sub(1)])?,
    )?;
    out.set_item("coupled", to_numpy(py, coupled, &[t, 3])?)?;
    out.set_item("infeasible_steps", to_numpy(py, infeasible, &[t])?)?;
    out.set_item("power", sc.power)?;
    Ok(out)
}

/// The hand-eye system in front of the simulated chamber opening: estimator state (estimate,
/// information matrix) plus the planning scene. See `autoteach.active.ActiveState`.
#[pyclass(name = "ActiveSystem", module = "autoteach._core")]
struct PyActiveSystem {
    scene: ActiveScene,
    est: HandEyeEstimator,
    power: f64,
}

#[pymethods]
impl PyActiveSystem {
    /// The nominal chamber scenario with the prior of `Scenario::chamber`.
    #[new]
    #[pyo3(signature = (sigma_px=None, power=None, estimate=None))]
    fn new(
        sigma_px: Option<f64>,
        power: Option<f64>,
        estimate: Option<Vec<String>>,
    ) -> PyResult<Self> {
        let sc = scenario(None, sigma_px, power, estimate)?;
        let scene = sc.scene().map_err(err)?;
        let prior: Vec<f64> = sc
            .mask
            .indices()
            .iter()
            .map(|&i| sc.prior_sigmas[i])
            .collect();
        let nominal = HandEyeParams::nominal(&sc.robot, sc.opening);
        let est = HandEyeEstimator::new(scene.model.clone(), nominal, &prior, sc.sigma_px)
            .map_err(err)?;
        Ok(Self {
            scene,
            est,
            power: sc.power,
        })
    }

    /// Names of the estimated parameters (units in the suffix).
    #[getter]
    fn names(&self) -> Vec<&'static str> {
        self.est.model.mask.names()
    }

    /// Pixel noise σ.
    #[getter]
    fn sigma_px(&self) -> f64 {
        self.est.sigma_px
    }

    /// The current estimate: opening pose (4×4), camera mount translation (3), joint offsets (5).
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let e = &self.est.estimate;
        let d = PyDict::new(py);
        let rows = convert::isometry_rows(&e.opening);
        d.set_item("opening", to_numpy(py, rows.concat(), &[4, 4])?)?;
        d.set_item(
            "camera_translation",
            to_numpy(py, e.camera_translation.as_slice().to_vec(), &[3])?,
        )?;
        d.set_item(
            "joint_offsets",
            to_numpy(py, e.joint_offsets.as_slice().to_vec(), &[5])?,
        )?;
        Ok(d)
    }

    /// Information matrix `P⁻¹` (SI units).
    fn information<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, self.est.information())
    }

    /// Replaces the information matrix (symmetric positive definite, `k × k`).
    fn set_information(&mut self, information: &Bound<'_, PyAny>) -> PyResult<()> {
        let m = matrix(information, "information")?;
        self.est.set_information(m).map_err(err)
    }

    /// Covariance `P` (SI units).
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, &self.est.covariance().map_err(err)?)
    }

    /// Observability indices of the information matrix (SI units).
    #[pyo3(signature = (power=None))]
    fn indices<'py>(&self, py: Python<'py>, power: Option<f64>) -> PyResult<Bound<'py, PyDict>> {
        let o = self.est.indices(power.unwrap_or(self.power)).map_err(err)?;
        indices_dict(py, &o)
    }

    /// Pixels `(m, 2)` of the corners under the estimate at encoder readings `joints` (NaN rows
    /// for corners that cannot be projected).
    fn project<'py>(
        &self,
        py: Python<'py>,
        joints_: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let q = joints(joints_, "joints")?;
        let px = self
            .est
            .model
            .project(&self.est.estimate, &q)
            .map_err(err)?;
        let m = px.len();
        let data = px
            .iter()
            .flat_map(|p| p.map_or([f64::NAN, f64::NAN], |p| [p.x, p.y]))
            .collect();
        to_numpy(py, data, &[m, 2])
    }

    /// Observation matrix `C` of eq. (6.14) (`2m × k`) at encoder readings `joints`.
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        joints_: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let q = joints(joints_, "joints")?;
        let (_, c) = self
            .est
            .model
            .linearize(&self.est.estimate, &q)
            .map_err(err)?;
        mat_out(py, &c)
    }

    /// Kalman update (6.15) with detected corner pixels `(m, 2)` (NaN rows = not detected).
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        joints_: &Bound<'py, PyAny>,
        pixels: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let q = joints(joints_, "joints")?;
        let m = self.est.model.corners.len();
        let a = convert::Array::new(pixels, "pixels")?;
        let data = a.exact(&[m, 2])?;
        let mut det = Vec::with_capacity(m);
        for j in 0..m {
            let (u, v) = (data[2 * j], data[2 * j + 1]);
            if u.is_nan() && v.is_nan() {
                det.push(None);
            } else if u.is_finite() && v.is_finite() {
                det.push(Some(Vector2::new(u, v)));
            } else {
                return Err(errors::invalid_input(format!(
                    "pixels row {j} = ({u}, {v}): rows must be finite or both NaN (not detected)"
                )));
            }
        }
        let s = self.est.update(&q, &det).map_err(err)?;
        let d = PyDict::new(py);
        d.set_item("used", s.used)?;
        d.set_item("iterations", s.iterations)?;
        d.set_item("rms_px", s.rms_px)?;
        Ok(d)
    }

    /// Plans the next measurement pose: `method` `"reduced"` (default) or `"sampling"`, or the
    /// best of `candidates` (`(n, 5)` encoder readings); `criterion` `"D"`, `"A"` or `"E"`.
    #[pyo3(signature = (candidates=None, criterion="D", method="reduced", samples=None, seed=0))]
    fn plan<'py>(
        &self,
        py: Python<'py>,
        candidates: Option<&Bound<'py, PyAny>>,
        criterion: &str,
        method: &str,
        samples: Option<usize>,
        seed: u64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let criterion: Criterion = criterion.parse().map_err(err)?;
        let cands = match candidates {
            Some(c) => {
                let (data, lead) = convert::finite_batch(c, "candidates", &[5], "(n, 5)")?;
                if lead.len() != 1 {
                    return Err(errors::invalid_input(format!(
                        "candidates must have shape (n, 5), got {}",
                        convert::shape_str(&convert::batched_shape(&lead, &[5]))
                    )));
                }
                Some(
                    data.chunks(5)
                        .map(Joints::from_column_slice)
                        .collect::<Vec<_>>(),
                )
            }
            None => None,
        };
        let mut opts = planner::PlannerOptions {
            criterion,
            seed,
            ..planner::PlannerOptions::default()
        };
        if let Some(s) = samples {
            opts.samples = s;
        }
        let (scene, est) = (&self.scene, &self.est);
        let method = method.to_string();
        let plan: Plan = convert::detached(py, || {
            let r = match (&cands, method.as_str()) {
                (Some(c), _) => planner::plan_candidates(
                    scene,
                    &est.estimate,
                    est.information(),
                    est.sigma_px,
                    c,
                    criterion,
                ),
                (None, "reduced") => planner::plan_reduced(
                    scene,
                    &est.estimate,
                    est.information(),
                    est.sigma_px,
                    &opts,
                ),
                (None, "sampling") => planner::plan_sampling(
                    scene,
                    &est.estimate,
                    est.information(),
                    est.sigma_px,
                    &opts,
                ),
                (None, m) => Err(EstimateError::InvalidProblem(format!(
                    "unknown planning method {m:?}; expected \"reduced\" or \"sampling\""
                ))),
            };
            r.map_err(err)
        })?;
        let d = PyDict::new(py);
        d.set_item(
            "joints",
            to_numpy(py, plan.best.joints.as_slice().to_vec(), &[5])?,
        )?;
        d.set_item(
            "camera_pose",
            to_numpy(
                py,
                convert::isometry_rows(&plan.best.camera_pose).concat(),
                &[4, 4],
            )?,
        )?;
        d.set_item("score", plan.best.score)?;
        d.set_item("evaluated", plan.evaluated)?;
        let r = &plan.rejections;
        let rej = PyDict::new(py);
        rej.set_item("visibility", r.visibility)?;
        rej.set_item("size", r.size)?;
        rej.set_item("view_angle", r.view_angle)?;
        rej.set_item("collision", r.collision)?;
        rej.set_item("unreachable", r.unreachable)?;
        rej.set_item("lift", r.lift)?;
        rej.set_item("sole", r.sole.to_vec())?;
        d.set_item("rejections", rej)?;
        Ok(d)
    }
}
