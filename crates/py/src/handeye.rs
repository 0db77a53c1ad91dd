//! Bindings of `autoteach_estimate::handeye`: the UKF auto-teaching filter, the SLAM-MOT
//! calibration (batch, sliding window, nearest-point baseline) and the theoretical resolution.
//! Python-visible names carry the `handeye_` prefix; the friendly API is
//! `autoteach.pipeline.autoteach`.

use autoteach_estimate::handeye::run::{self, SolvePlan};
use autoteach_estimate::handeye::{
    EdgeFactor, EdgeObservation, FreeCamera, PriorSigmas, Rim, SlamMot, SlamMotConfig,
    SlamMotSolution, SlamMotState, UkfNoise, WaferGeometry, WindowRecord, theoretical_resolution,
};
use autoteach_geometry::lie::se3_log;
use autoteach_geometry::robot::{Joints, RobotParams, WaferRobot};
use nalgebra::{Matrix3, Vector2, Vector5};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{self, to_numpy};
use crate::errors;

/// `free_camera` argument: motion σ (6), visual-odometry increments `(F−1, 4, 4)` or `None`,
/// odometry σ (6).
type FreeCameraArgs<'py> = (Vec<f64>, Option<Bound<'py, PyAny>>, Vec<f64>);

/// Adds the handeye functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(handeye_slam_mot, m)?)?;
    m.add_function(wrap_pyfunction!(handeye_ukf, m)?)?;
    m.add_function(wrap_pyfunction!(handeye_resolution, m)?)?;
    Ok(())
}

fn rows(obj: &Bound<'_, PyAny>, name: &'static str, width: usize) -> PyResult<Vec<Vec<f64>>> {
    let a = convert::finite_array(obj, name)?;
    let shape = a.shape().to_vec();
    if shape.len() != 2 || shape[1] != width {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (N, {width}), got {}",
            convert::shape_str(&shape)
        )));
    }
    let data = a.exact(&shape)?;
    Ok(data.chunks(width).map(|c| c.to_vec()).collect())
}

fn k_matrix(obj: &Bound<'_, PyAny>) -> PyResult<Matrix3<f64>> {
    convert::matrix3(obj, "K")
}

fn read_robot_params(obj: &Bound<'_, PyAny>) -> PyResult<RobotParams> {
    let v = convert::finite_array(obj, "robot_params")?.exact(&[11])?;
    RobotParams::from_slice(&v).map_err(errors::geometry)
}

fn joints(rows: Vec<Vec<f64>>) -> Vec<Joints> {
    rows.into_iter()
        .map(|r| Joints::from_column_slice(&r))
        .collect()
}

fn pose_array<'py>(
    py: Python<'py>,
    poses: &[nalgebra::Isometry3<f64>],
) -> PyResult<Bound<'py, PyAny>> {
    let mut data = Vec::with_capacity(poses.len() * 16);
    for p in poses {
        for row in convert::isometry_rows(p) {
            data.extend_from_slice(&row);
        }
    }
    Ok(to_numpy(py, data, &[poses.len(), 4, 4])?.into_any())
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

/// SLAM-MOT calibration (000_3b1454b2b2194811.txt §5.3). Edge points of observation `i` are
/// `points[obs_start[i]:obs_start[i+1]]`; `obs_rims` is 0 for the upper rim, 1 for the lower.
/// With `window > 0` the sliding-window run precedes the batch solve and its history is
/// returned; with `init_heights = (z_min, z_max, step)` the non-reference wafers' heights are
/// first found by a 1-D search. With `basin_search` the batch solve is followed by the
/// per-wafer basin search (`SlamMot::solve_batch_with_basins`, default settings); the wafers it
/// moved are `basins_moved`. Returns a dict (see `autoteach.pipeline`).
#[pyfunction]
#[pyo3(signature = (k, robot_params, wafer_radius, wafer_thickness, encoders, obs_frames, obs_wafers, obs_rims,
    obs_start, points, initial_base, initial_offsets, initial_wafers, *, pixel_sigma=0.5, estimate_offsets=vec![1, 3],
    reference_wafer=0, huber=Some(3.0), factor="conic", n_model=360, rounds=3, max_iterations=50, window=0,
    init_heights=None, prior_sigmas=(0.035, 0.02, 0.035), encoder_sigma=None, estimate_mount=false,
    estimate_links=vec![], free_camera=None, point_sigma_scale=None, basin_search=false))]
#[allow(clippy::too_many_arguments)]
fn handeye_slam_mot<'py>(
    py: Python<'py>,
    k: &Bound<'py, PyAny>,
    robot_params: &Bound<'py, PyAny>,
    wafer_radius: f64,
    wafer_thickness: f64,
    encoders: &Bound<'py, PyAny>,
    obs_frames: Vec<usize>,
    obs_wafers: Vec<usize>,
    obs_rims: Vec<u8>,
    obs_start: Vec<usize>,
    points: &Bound<'py, PyAny>,
    initial_base: &Bound<'py, PyAny>,
    initial_offsets: &Bound<'py, PyAny>,
    initial_wafers: &Bound<'py, PyAny>,
    pixel_sigma: f64,
    estimate_offsets: Vec<usize>,
    reference_wafer: usize,
    huber: Option<f64>,
    factor: &str,
    n_model: usize,
    rounds: usize,
    max_iterations: usize,
    window: usize,
    init_heights: Option<(f64, f64, f64)>,
    prior_sigmas: (f64, f64, f64),
    encoder_sigma: Option<[f64; 4]>,
    estimate_mount: bool,
    estimate_links: Vec<usize>,
    free_camera: Option<FreeCameraArgs<'py>>,
    point_sigma_scale: Option<Bound<'py, PyAny>>,
    basin_search: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let k = k_matrix(k)?;
    let params = read_robot_params(robot_params)?;
    let geometry = WaferGeometry::new(wafer_radius, wafer_thickness).map_err(errors::estimate)?;
    let enc = joints(rows(encoders, "encoders", 5)?);
    let pts = rows(points, "points", 2)?;
    let scale = match &point_sigma_scale {
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
    let m = obs_frames.len();
    if obs_wafers.len() != m || obs_rims.len() != m || obs_start.len() != m + 1 {
        return Err(errors::invalid_input(format!(
            "obs_frames, obs_wafers, obs_rims need one entry per observation ({m}) and obs_start {} entries; got {}, {}, {}",
            m + 1,
            obs_wafers.len(),
            obs_rims.len(),
            obs_start.len()
        )));
    }
    let mut observations = Vec::with_capacity(m);
    for i in 0..m {
        let (a, b) = (obs_start[i], obs_start[i + 1]);
        if a > b || b > pts.len() {
            return Err(errors::invalid_input(format!(
                "obs_start is not a non-decreasing index into points at observation {i}: {a}..{b} of {}",
                pts.len()
            )));
        }
        let rim = match obs_rims[i] {
            0 => Rim::Upper,
            1 => Rim::Lower,
            r => {
                return Err(errors::invalid_input(format!(
                    "obs_rims must be 0 (upper) or 1 (lower), got {r} at {i}"
                )));
            }
        };
        observations.push(EdgeObservation {
            frame: obs_frames[i],
            wafer: obs_wafers[i],
            rim,
            points: pts[a..b].iter().map(|p| Vector2::new(p[0], p[1])).collect(),
            sigma_scale: if scale.is_empty() {
                Vec::new()
            } else {
                scale[a..b].to_vec()
            },
        });
    }
    let base = convert::isometry(initial_base, "initial_base")?;
    let offsets = Joints::from_column_slice(
        &convert::finite_array(initial_offsets, "initial_offsets")?.exact(&[5])?,
    );
    let free_camera = match free_camera {
        None => None,
        Some((motion, odo, odo_sigma)) => {
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
            Some(FreeCamera {
                motion_sigma: six(&motion, "free_camera motion sigma")?,
                odometry,
                odometry_sigma: six(&odo_sigma, "free_camera odometry sigma")?,
                calibration_prior: Some((
                    base,
                    offsets,
                    PriorSigmas {
                        base_rotation: prior_sigmas.0,
                        base_translation: prior_sigmas.1,
                        offset: prior_sigmas.2,
                    },
                )),
            })
        }
    };
    let wafers: Vec<Vector5<f64>> = rows(initial_wafers, "initial_wafers", 5)?
        .iter()
        .map(|r| Vector5::from_column_slice(r))
        .collect();
    let mut config = SlamMotConfig::new(k, params, geometry);
    config.pixel_sigma = pixel_sigma;
    config.estimate_offsets = estimate_offsets;
    config.reference_wafer = reference_wafer;
    config.huber = huber;
    config.max_iterations = max_iterations;
    config.encoder_sigma = encoder_sigma;
    config.estimate_mount = estimate_mount;
    config.estimate_links = estimate_links;
    config.free_camera = free_camera;
    config.factor = match factor {
        "conic" => EdgeFactor::Conic,
        "point" => EdgeFactor::NearestPoint { n_model, rounds },
        other => {
            return Err(errors::invalid_input(format!(
                "factor must be 'conic' or 'point', got {other:?}"
            )));
        }
    };
    let n_wafers = wafers.len();
    let plan = SolvePlan {
        init_heights,
        window,
        window_prior: PriorSigmas {
            base_rotation: prior_sigmas.0,
            base_translation: prior_sigmas.1,
            offset: prior_sigmas.2,
        },
        basin_search,
    };
    let out = convert::detached(py, move || {
        let slam = SlamMot::new(config, enc, observations, n_wafers).map_err(errors::estimate)?;
        let start = SlamMotState::new(base, offsets, wafers);
        run::solve(&slam, &start, &plan).map_err(errors::estimate)
    })?;
    let d = solution_dict(py, &out.solution)?;
    d.set_item("basins_moved", out.basins_moved)?;
    d.set_item("history", history_list(py, &out.history)?)?;
    d.set_item("initial", state_dict(py, &out.initial)?)?;
    Ok(d)
}

/// The UKF of 000_3b1454b2b2194811.txt eqs. (5.1)–(5.2) over a session. `noise`: 16 standard
/// deviations `w_T(3), w_E(3), v_T(3), v_E(3), v_θ(4)` in SI units or `None` for eq. (5.2).
#[pyfunction]
/// `odometry`: `None` for world-frame increments with white errors (eq. (5.1) literally), or
/// `[loc_t, loc_r, map_t, map_step]` for the relative poses of a SLAM with a map
/// (`autoteach_estimate::handeye::ukf_model::UkfOdometry::Slam`).
#[pyo3(signature = (robot_params, base_pose, encoders, increments, noise=None, offset_std0=0.035, odometry=None))]
#[allow(clippy::too_many_arguments)]
fn handeye_ukf<'py>(
    py: Python<'py>,
    robot_params: &Bound<'py, PyAny>,
    base_pose: &Bound<'py, PyAny>,
    encoders: &Bound<'py, PyAny>,
    increments: &Bound<'py, PyAny>,
    noise: Option<Vec<f64>>,
    offset_std0: f64,
    odometry: Option<Vec<f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    use autoteach_estimate::handeye::ukf_model::{SlamNoise, UkfOdometry, run_autoteach_ukf_with};
    let odometry = match odometry {
        None => UkfOdometry::World,
        Some(v) if v.len() == 4 => UkfOdometry::Slam(SlamNoise {
            loc_t: v[0],
            loc_r: v[1],
            map_t: v[2],
            map_step: v[3],
        }),
        Some(v) => {
            return Err(errors::invalid_input(format!(
                "odometry must have 4 values [loc_t, loc_r, map_t, map_step], got {}",
                v.len()
            )));
        }
    };
    let params = read_robot_params(robot_params)?;
    let base = convert::isometry(base_pose, "base_pose")?;
    let robot = WaferRobot::new(params, base).map_err(errors::geometry)?;
    let enc = joints(rows(encoders, "encoders", 5)?);
    let inc: Vec<[f64; 6]> = if enc.len() <= 1 {
        Vec::new()
    } else {
        rows(increments, "increments", 6)?
            .iter()
            .map(|r| [r[0], r[1], r[2], r[3], r[4], r[5]])
            .collect()
    };
    let noise = match noise {
        None => UkfNoise::default(),
        Some(v) if v.len() == 16 => UkfNoise {
            w_t: [v[0], v[1], v[2]],
            w_e: [v[3], v[4], v[5]],
            v_t: [v[6], v[7], v[8]],
            v_e: [v[9], v[10], v[11]],
            v_theta: [v[12], v[13], v[14], v[15]],
        },
        Some(v) => {
            return Err(errors::invalid_input(format!(
                "noise must have 16 values, got {}",
                v.len()
            )));
        }
    };
    let run = convert::detached(py, move || {
        run_autoteach_ukf_with(robot, &enc, &inc, &noise, odometry, offset_std0)
            .map_err(errors::estimate)
    })?;
    let d = PyDict::new(py);
    d.set_item("poses", pose_array(py, &run.poses)?)?;
    let n = run.offsets.len();
    d.set_item(
        "offsets",
        to_numpy(py, run.offsets.iter().flatten().copied().collect(), &[n, 3])?,
    )?;
    d.set_item(
        "offset_std",
        to_numpy(
            py,
            run.offset_std.iter().flatten().copied().collect(),
            &[n, 3],
        )?,
    )?;
    d.set_item(
        "covariance",
        to_numpy(py, run.covariance.transpose().as_slice().to_vec(), &[9, 9])?,
    )?;
    d.set_item("observable", run.observable.to_vec())?;
    Ok(d)
}

/// Theoretical resolution (eq. (5.14)) of a wafer `[cx, cy, cz, rx, ry]` seen from `t_wc`:
/// pixels per mm of the centre x, y, z and pixels per degree of the tilts rx, ry.
#[pyfunction]
#[pyo3(signature = (k, t_wc, wafer, wafer_radius, wafer_thickness, n=180))]
fn handeye_resolution<'py>(
    py: Python<'py>,
    k: &Bound<'py, PyAny>,
    t_wc: &Bound<'py, PyAny>,
    wafer: &Bound<'py, PyAny>,
    wafer_radius: f64,
    wafer_thickness: f64,
    n: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let k = k_matrix(k)?;
    let t = convert::isometry(t_wc, "t_wc")?;
    let w = Vector5::from_column_slice(&convert::finite_array(wafer, "wafer")?.exact(&[5])?);
    let g = WaferGeometry::new(wafer_radius, wafer_thickness).map_err(errors::estimate)?;
    let r = theoretical_resolution(&k, &t, &w, &g, n).map_err(errors::estimate)?;
    Ok(to_numpy(py, r.to_vec(), &[5])?.into_any())
}
