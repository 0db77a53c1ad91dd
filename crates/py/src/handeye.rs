//! Bindings of `autoteach_estimate::handeye`: the UKF auto-teaching filter and the theoretical
//! resolution (the SLAM-MOT calibration is `handeye_slam`, the gating `handeye_gate`).
//! Python-visible names carry the `handeye_` prefix; the friendly API is
//! `autoteach.pipeline.autoteach`.

use autoteach_estimate::handeye::{UkfNoise, WaferGeometry, theoretical_resolution};
use autoteach_geometry::robot::{Joints, RobotParams, WaferRobot};
use nalgebra::{Matrix3, Vector5};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, to_numpy};
use crate::errors;

/// Adds the handeye functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(handeye_ukf, m)?)?;
    m.add_function(wrap_pyfunction!(handeye_resolution, m)?)?;
    Ok(())
}

pub(crate) fn rows(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    width: usize,
) -> PyResult<Vec<Vec<f64>>> {
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

pub(crate) fn k_matrix(obj: &Bound<'_, PyAny>) -> PyResult<Matrix3<f64>> {
    convert::matrix3(obj, "K")
}

pub(crate) fn read_robot_params(obj: &Bound<'_, PyAny>) -> PyResult<RobotParams> {
    let v = convert::finite_array(obj, "robot_params")?.exact(&[11])?;
    RobotParams::from_slice(&v).map_err(errors::geometry)
}

pub(crate) fn joints(rows: Vec<Vec<f64>>) -> Vec<Joints> {
    rows.into_iter()
        .map(|r| Joints::from_column_slice(&r))
        .collect()
}

pub(crate) fn pose_array<'py>(
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
