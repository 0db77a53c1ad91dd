//! Binding of the SLAM-MOT calibration (`autoteach_estimate::handeye::run`): a problem built
//! once per session (`HandeyeSlamMot`), whose `solve` runs `run::solve` on a set of observations
//! and whose `gate_and_resolve` runs the detect front end's chain of gates
//! (`run::gate_and_resolve`). The friendly API is `autoteach.pipeline`.
//!
//! Observations cross in the solver's flat layout, a tuple `(frames, wafers, rims, start,
//! points, sigma_scale)`: edge points of observation `i` are `points[start[i]:start[i+1]]`,
//! `rims[i]` is 0 for the upper rim and 1 for the lower, `sigma_scale` is one factor per point
//! or `None`. A start is `(base_pose (4, 4), joint_offsets (5,), wafers (W, 5))`.

use autoteach_estimate::handeye::gating::{DetectedEdges, GateConfig, GateStats};
use autoteach_estimate::handeye::run::{self, GatingPlan, SlamMotInputs, SolvePlan};
use autoteach_estimate::handeye::{
    EdgeFactor, EdgeObservation, FreeCamera, PriorSigmas, Rim, SlamMotConfig, SlamMotSolution,
    SlamMotState, WaferGeometry, WindowRecord,
};
use autoteach_geometry::lie::se3_log;
use autoteach_geometry::robot::Joints;
use nalgebra::{Isometry3, Vector2, Vector5};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{self, to_numpy};
use crate::errors;
use crate::handeye::{joints, k_matrix, pose_array, read_robot_params, rows};

/// `free_camera` argument: motion σ (6), visual-odometry increments `(F−1, 4, 4)` or `None`,
/// odometry σ (6).
type FreeCameraArgs<'py> = (Vec<f64>, Option<Bound<'py, PyAny>>, Vec<f64>);

/// Observations in the flat layout (see the module doc).
type ObservationArgs<'py> = (
    Vec<usize>,
    Vec<usize>,
    Vec<usize>,
    Vec<usize>,
    Bound<'py, PyAny>,
    Option<Bound<'py, PyAny>>,
);

/// A start: base pose, joint offsets, wafers.
type StartArgs<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>);

/// Detected edges: points `(N, 2)`, `E + 1` offsets, the frame of each edge.
type DetectionArgs<'py> = (Bound<'py, PyAny>, Vec<usize>, Vec<usize>);

/// Adds the SLAM-MOT class to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySlamMot>()
}

fn state_dict<'py>(py: Python<'py>, s: &SlamMotState) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("base_pose", pose_array(py, &[s.base])?.get_item(0)?)?;
    d.set_item(
        "joint_offsets",
        to_numpy(py, s.offsets.as_slice().to_vec(), &[5])?,
    )?;
    let w: Vec<f64> = s.wafers.iter().flat_map(|w| w.iter().copied()).collect();
    d.set_item("wafers", to_numpy(py, w, &[s.wafers.len(), 5])?)?;
    d.set_item("mount", pose_array(py, &[s.mount])?.get_item(0)?)?;
    d.set_item("links", to_numpy(py, s.links.to_vec(), &[3])?)?;
    Ok(d)
}

fn solution_dict<'py>(py: Python<'py>, sol: &SlamMotSolution) -> PyResult<Bound<'py, PyDict>> {
    let d = state_dict(py, &sol.state)?;
    match &sol.uncertainty.covariance {
        Some(c) => d.set_item(
            "covariance",
            to_numpy(
                py,
                c.transpose().as_slice().to_vec(),
                &[c.nrows(), c.ncols()],
            )?,
        )?,
        None => d.set_item("covariance", py.None())?,
    }
    d.set_item("covariance_wafers", sol.uncertainty.wafer_order.clone())?;
    d.set_item("unobservable", sol.uncertainty.unobservable.clone())?;
    d.set_item("initial_cost", sol.initial_cost)?;
    d.set_item("final_cost", sol.final_cost)?;
    d.set_item("iterations", sol.iterations)?;
    d.set_item("rms_px", sol.rms_px)?;
    d.set_item("n_residuals", sol.n_residuals)?;
    d.set_item("camera_poses", pose_array(py, &sol.camera_poses)?)?;
    Ok(d)
}

fn history_list<'py>(py: Python<'py>, hist: &[WindowRecord]) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for h in hist {
        let d = state_dict(py, &h.state)?;
        d.set_item("last_frame", h.last_frame)?;
        d.set_item("std", to_numpy(py, h.std.clone(), &[h.std.len()])?)?;
        d.set_item(
            "base_log",
            to_numpy(py, se3_log(&h.state.base).as_slice().to_vec(), &[6])?,
        )?;
        out.append(d)?;
    }
    Ok(out)
}

/// A SLAM-MOT problem of one session (000_3b1454b2b2194811.txt §5.3): intrinsics, robot,
/// wafer size, encoder readings, the number of wafers and the noise model, built once; the
/// observations and the start are given to each solve.
#[pyclass(name = "HandeyeSlamMot", module = "autoteach._core", frozen)]
pub struct PySlamMot {
    inputs: SlamMotInputs,
    window_prior: PriorSigmas,
}

#[pymethods]
impl PySlamMot {
    /// `prior_sigmas` (base rotation rad, base translation m, offsets rad): the priors carried
    /// between sliding windows, and in the free-camera mode the calibration prior centred on
    /// each solve's start. `free_camera = (motion σ (6), odometry (F−1, 4, 4) or None,
    /// odometry σ (6))` switches that mode on.
    #[new]
    #[pyo3(signature = (k, robot_params, wafer_radius, wafer_thickness, encoders, n_wafers, *, pixel_sigma=0.5,
        estimate_offsets=vec![1, 3], reference_wafer=0, huber=Some(3.0), max_iterations=50,
        prior_sigmas=(0.035, 0.02, 0.035), encoder_sigma=None, estimate_mount=false, estimate_links=vec![],
        free_camera=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        k: &Bound<'_, PyAny>,
        robot_params: &Bound<'_, PyAny>,
        wafer_radius: f64,
        wafer_thickness: f64,
        encoders: &Bound<'_, PyAny>,
        n_wafers: usize,
        pixel_sigma: f64,
        estimate_offsets: Vec<usize>,
        reference_wafer: usize,
        huber: Option<f64>,
        max_iterations: usize,
        prior_sigmas: (f64, f64, f64),
        encoder_sigma: Option<[f64; 4]>,
        estimate_mount: bool,
        estimate_links: Vec<usize>,
        free_camera: Option<FreeCameraArgs<'_>>,
    ) -> PyResult<Self> {
        let prior = PriorSigmas {
            base_rotation: prior_sigmas.0,
            base_translation: prior_sigmas.1,
            offset: prior_sigmas.2,
        };
        let geometry =
            WaferGeometry::new(wafer_radius, wafer_thickness).map_err(errors::estimate)?;
        let mut config =
            SlamMotConfig::new(k_matrix(k)?, read_robot_params(robot_params)?, geometry);
        config.pixel_sigma = pixel_sigma;
        config.estimate_offsets = estimate_offsets;
        config.reference_wafer = reference_wafer;
        config.huber = huber;
        config.max_iterations = max_iterations;
        config.encoder_sigma = encoder_sigma;
        config.estimate_mount = estimate_mount;
        config.estimate_links = estimate_links;
        config.free_camera = free_camera
            .map(|f| free_camera_config(f, prior))
            .transpose()?;
        Ok(Self {
            inputs: SlamMotInputs {
                config,
                encoders: joints(rows(encoders, "encoders", 5)?),
                n_wafers,
            },
            window_prior: prior,
        })
    }

    /// Solves from `start`: the height search over `init_heights = (low, high, step)` (m) when
    /// given, the sliding window of `window` frames when `window > 0` (its history is
    /// returned), then the batch solve, followed by the per-wafer basin search with
    /// `basin_search` (the wafers it moved are `basins_moved`). `factor`: `"conic"` (eq. (5.13))
    /// or `"point"` (nearest of `n_model` model points, `rounds` association rounds).
    #[pyo3(signature = (observations, start, *, factor="conic", n_model=360, rounds=3, window=0,
        init_heights=None, basin_search=false))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        observations: ObservationArgs<'py>,
        start: StartArgs<'py>,
        factor: &str,
        n_model: usize,
        rounds: usize,
        window: usize,
        init_heights: Option<(f64, f64, f64)>,
        basin_search: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let observations = read_observations(observations)?;
        let start = read_start(start)?;
        let mut inputs = self.inputs.clone();
        inputs.config.factor = match factor {
            "conic" => EdgeFactor::Conic,
            "point" => EdgeFactor::NearestPoint { n_model, rounds },
            other => {
                return Err(errors::invalid_input(format!(
                    "factor must be 'conic' or 'point', got {other:?}"
                )));
            }
        };
        let plan = SolvePlan {
            init_heights,
            window,
            window_prior: self.window_prior,
            basin_search,
        };
        let out = convert::detached(py, move || {
            let slam = inputs
                .problem(observations, &start)
                .map_err(errors::estimate)?;
            run::solve(&slam, &start, &plan).map_err(errors::estimate)
        })?;
        let d = solution_dict(py, &out.solution)?;
        d.set_item("basins_moved", out.basins_moved)?;
        d.set_item("history", history_list(py, &out.history)?)?;
        d.set_item("initial", state_dict(py, &out.initial)?)?;
        Ok(d)
    }

    /// The detect front end's chain of gates (`run::gate_and_resolve`): a first solve of the
    /// tracked `observations` from `start` (height search over `first_heights`), then every
    /// detected edge (`detections = (points (N, 2), start (E + 1), frames (E))`) re-associated
    /// with the projected estimate under each gate of `gates_px`, solving again after each;
    /// with `reset_tilts` also from level wafers, the chain explaining more edges winning.
    /// Returns `observations` (the flat layout, wafers with fewer than `min_wafer_frames`
    /// frames removed), `start` (base_pose, joint_offsets, wafers), `stats`, `too_few_views`.
    #[pyo3(signature = (observations, start, detections, *, gates_px, first_heights, reset_tilts=true,
        min_wafer_frames=8, points_per_rim=24, min_inlier_fraction=0.6, min_points=12, min_band_px=0.0,
        band_weights=false, basin_search=false))]
    #[allow(clippy::too_many_arguments)]
    fn gate_and_resolve<'py>(
        &self,
        py: Python<'py>,
        observations: ObservationArgs<'py>,
        start: StartArgs<'py>,
        detections: DetectionArgs<'py>,
        gates_px: Vec<f64>,
        first_heights: (f64, f64, f64),
        reset_tilts: bool,
        min_wafer_frames: usize,
        points_per_rim: usize,
        min_inlier_fraction: f64,
        min_points: usize,
        min_band_px: f64,
        band_weights: bool,
        basin_search: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let tracked = read_observations(observations)?;
        let start = read_start(start)?;
        let (points, edge_start, edge_frames) = detections;
        let points = points2(&points, "detection points")?;
        let plan = GatingPlan {
            gates_px,
            reset_tilts,
            // `gate_px` is each gate's in turn.
            gate: GateConfig {
                gate_px: 1.0,
                min_inlier_fraction,
                points_per_rim,
                min_points,
                min_band_px,
                band_weights,
            },
            min_wafer_frames,
            first_heights,
            basin_search,
        };
        let inputs = &self.inputs;
        let out = convert::detached(py, || {
            let edges = DetectedEdges {
                points: &points,
                start: &edge_start,
                frames: &edge_frames,
            };
            run::gate_and_resolve(inputs, tracked, &start, &edges, &plan).map_err(errors::estimate)
        })?;
        let d = PyDict::new(py);
        d.set_item(
            "observations",
            observations_tuple(py, &out.observations, band_weights)?,
        )?;
        let s = PyDict::new(py);
        s.set_item("base_pose", pose_array(py, &[out.start.base])?.get_item(0)?)?;
        s.set_item(
            "joint_offsets",
            to_numpy(py, out.start.offsets.as_slice().to_vec(), &[5])?,
        )?;
        let w: Vec<f64> = out
            .start
            .wafers
            .iter()
            .flat_map(|w| w.iter().copied())
            .collect();
        s.set_item("wafers", to_numpy(py, w, &[out.start.wafers.len(), 5])?)?;
        d.set_item("start", s)?;
        d.set_item("stats", stats_dict(py, &out.stats)?)?;
        d.set_item("last_gate_px", out.last_gate_px)?;
        d.set_item("too_few_views", out.too_few_views)?;
        Ok(d)
    }
}

fn free_camera_config(
    (motion, odo, odo_sigma): FreeCameraArgs<'_>,
    prior: PriorSigmas,
) -> PyResult<FreeCamera> {
    let six = |v: &[f64], what: &str| -> PyResult<[f64; 6]> {
        <[f64; 6]>::try_from(v).map_err(|_| {
            errors::invalid_input(format!(
                "{what} needs 6 standard deviations, got {}",
                v.len()
            ))
        })
    };
    let odometry = match odo {
        None => Vec::new(),
        Some(a) => {
            let arr = convert::finite_array(&a, "odometry")?;
            let shape = arr.shape().to_vec();
            if shape.len() != 3 || shape[1] != 4 || shape[2] != 4 {
                return Err(errors::invalid_input(format!(
                    "odometry must have shape (F-1, 4, 4), got {shape:?}"
                )));
            }
            let view = arr.view();
            let mut out = Vec::with_capacity(shape[0]);
            for i in 0..shape[0] {
                let m = nalgebra::Matrix4::from_fn(|r, c| view[[i, r, c]]);
                out.push(convert::matrix_to_isometry(&m, "odometry increment")?);
            }
            out
        }
    };
    Ok(FreeCamera {
        motion_sigma: six(&motion, "free_camera motion sigma")?,
        odometry,
        odometry_sigma: six(&odo_sigma, "free_camera odometry sigma")?,
        // Centred on each solve's start (`SlamMotInputs::problem`).
        calibration_prior: Some((Isometry3::identity(), Joints::zeros(), prior)),
    })
}

fn read_start((base, offsets, wafers): StartArgs<'_>) -> PyResult<SlamMotState> {
    let base = convert::isometry(&base, "initial_base")?;
    let offsets = Joints::from_column_slice(
        &convert::finite_array(&offsets, "initial_offsets")?.exact(&[5])?,
    );
    let wafers: Vec<Vector5<f64>> = rows(&wafers, "initial_wafers", 5)?
        .iter()
        .map(|r| Vector5::from_column_slice(r))
        .collect();
    Ok(SlamMotState::new(base, offsets, wafers))
}

fn read_observations(
    (frames, wafers, rims, start, points, sigma_scale): ObservationArgs<'_>,
) -> PyResult<Vec<EdgeObservation>> {
    let pts = points2(&points, "points")?;
    let scale = match &sigma_scale {
        None => Vec::new(),
        Some(a) => {
            let v = convert::finite_array(a, "point_sigma_scale")?.exact(&[pts.len()])?;
            if let Some(x) = v.iter().find(|x| **x <= 0.0) {
                return Err(errors::invalid_input(format!(
                    "point_sigma_scale must be positive (one factor per point), got {x}"
                )));
            }
            v
        }
    };
    let m = frames.len();
    if wafers.len() != m || rims.len() != m || start.len() != m + 1 {
        return Err(errors::invalid_input(format!(
            "observation frames, wafers, rims need one entry per observation ({m}) and start {} entries; got {}, {}, {}",
            m + 1,
            wafers.len(),
            rims.len(),
            start.len()
        )));
    }
    let mut observations = Vec::with_capacity(m);
    for i in 0..m {
        let (a, b) = (start[i], start[i + 1]);
        if a > b || b > pts.len() {
            return Err(errors::invalid_input(format!(
                "observation start is not a non-decreasing index into points at observation {i}: {a}..{b} of {}",
                pts.len()
            )));
        }
        let rim = match rims[i] {
            0 => Rim::Upper,
            1 => Rim::Lower,
            r => {
                return Err(errors::invalid_input(format!(
                    "observation rims must be 0 (upper) or 1 (lower), got {r} at {i}"
                )));
            }
        };
        observations.push(EdgeObservation {
            frame: frames[i],
            wafer: wafers[i],
            rim,
            points: pts[a..b].to_vec(),
            sigma_scale: if scale.is_empty() {
                Vec::new()
            } else {
                scale[a..b].to_vec()
            },
        });
    }
    Ok(observations)
}

/// Points `(N, 2)`, finite.
pub(crate) fn points2(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<Vector2<f64>>> {
    let (p, _) = convert::finite_array(obj, name)?.rows(2, "(N, 2)")?;
    Ok(p.iter().map(|r| Vector2::new(r[0], r[1])).collect())
}

/// Observations in the flat layout; `sigma_scale` is `None` unless `with_scale`.
pub(crate) fn observations_tuple<'py>(
    py: Python<'py>,
    obs: &[EdgeObservation],
    with_scale: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let mut start = vec![0usize];
    let mut flat = Vec::new();
    let mut scale = Vec::new();
    for o in obs {
        for q in &o.points {
            flat.extend_from_slice(&[q.x, q.y]);
        }
        scale.extend_from_slice(&o.sigma_scale);
        start.push(flat.len() / 2);
    }
    let n = flat.len() / 2;
    let scale = if with_scale && !obs.is_empty() {
        to_numpy(py, scale, &[n])?.into_any()
    } else {
        py.None().into_bound(py)
    };
    let t = (
        obs.iter().map(|o| o.frame).collect::<Vec<_>>(),
        obs.iter().map(|o| o.wafer).collect::<Vec<_>>(),
        obs.iter().map(|o| o.rim as usize).collect::<Vec<_>>(),
        start,
        to_numpy(py, flat, &[n, 2])?,
        scale,
    );
    Ok(t.into_pyobject(py)?.into_any())
}

/// The gating counts as a dict.
pub(crate) fn stats_dict<'py>(py: Python<'py>, s: &GateStats) -> PyResult<Bound<'py, PyDict>> {
    let stats = PyDict::new(py);
    stats.set_item("edges", s.edges)?;
    stats.set_item("edges_rejected", s.edges_rejected)?;
    stats.set_item("rims_used", s.rims_used)?;
    stats.set_item("frames_used", s.frames_used)?;
    stats.set_item("points_narrow_band", s.points_narrow_band)?;
    stats.set_item("rims_associated", s.rims_associated)?;
    Ok(stats)
}
