//! Bindings of `autoteach_geometry::render`: the ray-cast renderer of the simulated wafer
//! carrier and the ground truth of the visible wafer rims.
//!
//! Each function reads its arrays through [`crate::convert`], builds the scene and the camera,
//! runs one core function without the GIL (through [`convert::detached`]) and converts the
//! result.

use autoteach_geometry::camera::{Camera, CameraModel};
use autoteach_geometry::render::{self, Carrier, RenderOptions, Rim, RimTruth, Scene, WaferShape};
use nalgebra::Isometry3;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert;
use crate::errors;

/// Adds the sim functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(render_frame, m)?)?;
    m.add_function(wrap_pyfunction!(rim_visibility, m)?)?;
    m.add_function(wrap_pyfunction!(rim_points_visible, m)?)?;
    Ok(())
}

/// Reads the camera arguments (model name as accepted by `CameraModel::from_str`).
fn camera(model: &str, params: &Bound<'_, PyAny>, width: i64, height: i64) -> PyResult<Camera> {
    let p = convert::finite_array(params, "camera_params")?.vector()?;
    let size = |n: i64, what: &str| {
        u32::try_from(n).ok().filter(|&n| n > 0).ok_or_else(|| {
            errors::invalid_input(format!("{what} must be a positive 32-bit integer, got {n}"))
        })
    };
    let (w, h) = (size(width, "width")?, size(height, "height")?);
    let model: CameraModel = model.parse().map_err(errors::geometry)?;
    Camera::new(model, &p, w, h).map_err(errors::geometry)
}

/// Reads the wafer poses `(N, 4, 4)` and builds the scene.
fn scene(
    wafer_poses: &Bound<'_, PyAny>,
    radius: f64,
    thickness: f64,
    carrier: bool,
) -> PyResult<Scene> {
    let (wafers, lead) = convert::isometries(wafer_poses, "wafer_poses")?;
    if lead.len() != 1 {
        return Err(errors::invalid_input(format!(
            "wafer_poses must have shape (N, 4, 4), got leading shape {}",
            convert::shape_str(&lead)
        )));
    }
    Ok(Scene {
        wafers,
        shape: WaferShape { radius, thickness },
        carrier: carrier.then(Carrier::default),
    })
}

/// Reads the arguments shared by the frame functions, in the order they are validated: the
/// camera `(model, params, width, height)`, the scene (`wafer_poses` and
/// `(radius, thickness, carrier)`) and the camera pose `t_wc`.
fn frame(
    wafer_poses: &Bound<'_, PyAny>,
    (model, params, width, height): (&str, &Bound<'_, PyAny>, i64, i64),
    t_wc: &Bound<'_, PyAny>,
    (radius, thickness, carrier): (f64, f64, bool),
) -> PyResult<(Scene, Camera, Isometry3<f64>)> {
    let cam = camera(model, params, width, height)?;
    let scene = scene(wafer_poses, radius, thickness, carrier)?;
    let t_wc = convert::isometry(t_wc, "t_wc")?;
    Ok((scene, cam, t_wc))
}

/// Renders one grayscale frame of the simulated wafer carrier.
///
/// Wafers are discs of `wafer_radius` and `wafer_thickness` (metres) at poses `wafer_poses`
/// `(N, 4, 4)` (`T_w,wafer`, world = carrier frame, z up, opening toward −x); `t_wc` (4×4) is
/// the camera pose (camera → world; camera z forward, x right, y down). Returns a
/// `(height, width)` uint8 array; pixel `(u, v)` is centred at image position `(u, v)`.
/// The same inputs and `seed` give identical bytes.
#[pyfunction]
#[pyo3(signature = (
    wafer_poses, camera_model, camera_params, width, height, t_wc, *,
    wafer_radius=0.15, wafer_thickness=0.001, carrier=true, gain=1.0, gradient=(0.0, 0.0),
    blur_sigma=0.8, noise_sigma=2.0, supersample=4, seed=0
))]
#[allow(clippy::too_many_arguments)]
fn render_frame<'py>(
    py: Python<'py>,
    wafer_poses: &Bound<'py, PyAny>,
    camera_model: &str,
    camera_params: &Bound<'py, PyAny>,
    width: i64,
    height: i64,
    t_wc: &Bound<'py, PyAny>,
    wafer_radius: f64,
    wafer_thickness: f64,
    carrier: bool,
    gain: f64,
    gradient: (f64, f64),
    blur_sigma: f64,
    noise_sigma: f64,
    supersample: i64,
    seed: i128,
) -> PyResult<Bound<'py, PyArray2<u8>>> {
    let (scene, cam, t_wc) = frame(
        wafer_poses,
        (camera_model, camera_params, width, height),
        t_wc,
        (wafer_radius, wafer_thickness, carrier),
    )?;
    if !(1..=16).contains(&supersample) {
        return Err(errors::invalid_input(format!(
            "supersample must be in 1..=16, got {supersample}"
        )));
    }
    let opts = RenderOptions {
        gain,
        gradient: [gradient.0, gradient.1],
        blur_sigma,
        noise_sigma,
        supersample: supersample as usize,
        seed: u64::try_from(seed).map_err(|_| {
            errors::invalid_input(format!("seed must be an integer in [0, 2**64), got {seed}"))
        })?,
        ..RenderOptions::default()
    };
    let img = convert::detached(py, || {
        render::render(&scene, &cam, &t_wc, &opts).map_err(errors::geometry)
    })?;
    let arr = Array2::from_shape_vec((img.height, img.width), img.data)
        .map_err(|e| errors::internal(format!("image of {}x{}: {e}", img.width, img.height)))?;
    Ok(arr.into_pyarray(py))
}

/// One rim's ground truth as a dict.
fn truth_dict<'py>(py: Python<'py>, t: RimTruth) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("wafer", t.wafer)?;
    d.set_item("rim", t.rim.name())?;
    match t.ellipse {
        Some(e) => d.set_item(
            "ellipse",
            PyArray1::from_vec(py, vec![e.cx, e.cy, e.a, e.b, e.theta]),
        )?,
        None => d.set_item("ellipse", py.None())?,
    }
    let n = t.intervals.len();
    let iv: Vec<f64> = t.intervals.iter().flatten().copied().collect();
    d.set_item("intervals", convert::to_numpy(py, iv, &[n, 2])?)?;
    d.set_item("fraction", t.fraction)?;
    let m = t.points.len();
    let pts: Vec<f64> = t.points.iter().flat_map(|p| [p.x, p.y]).collect();
    d.set_item("points", convert::to_numpy(py, pts, &[m, 2])?)?;
    d.set_item("angles", PyArray1::from_vec(py, t.angles))?;
    d.set_item("side_facing", PyArray1::from_vec(py, t.side_facing))?;
    Ok(d)
}

/// Ground truth of the visible wafer rims in one frame: a list with, for each wafer, a dict
/// for its upper rim then one for its lower rim. Arguments as `render_frame`.
#[pyfunction]
#[pyo3(signature = (
    wafer_poses, camera_model, camera_params, width, height, t_wc, *,
    wafer_radius=0.15, wafer_thickness=0.001, carrier=true, n_samples=720
))]
#[allow(clippy::too_many_arguments)]
fn rim_visibility<'py>(
    py: Python<'py>,
    wafer_poses: &Bound<'py, PyAny>,
    camera_model: &str,
    camera_params: &Bound<'py, PyAny>,
    width: i64,
    height: i64,
    t_wc: &Bound<'py, PyAny>,
    wafer_radius: f64,
    wafer_thickness: f64,
    carrier: bool,
    n_samples: i64,
) -> PyResult<Bound<'py, PyList>> {
    let (scene, cam, t_wc) = frame(
        wafer_poses,
        (camera_model, camera_params, width, height),
        t_wc,
        (wafer_radius, wafer_thickness, carrier),
    )?;
    if !(3..=1_000_000).contains(&n_samples) {
        return Err(errors::invalid_input(format!(
            "n_samples must be in 3..=1000000, got {n_samples}"
        )));
    }
    let truths = convert::detached(py, || {
        render::rim_visibility(&scene, &cam, &t_wc, n_samples as usize).map_err(errors::geometry)
    })?;
    let list = PyList::empty(py);
    for t in truths {
        list.append(truth_dict(py, t)?)?;
    }
    Ok(list)
}

/// Visibility of the points at circle angles `angles` (radians, wafer frame) of one rim
/// (`"upper"` or `"lower"`) of wafer `wafer`: a bool array like `angles`.
#[pyfunction]
#[pyo3(signature = (
    wafer_poses, camera_model, camera_params, width, height, t_wc, wafer, rim, angles, *,
    wafer_radius=0.15, wafer_thickness=0.001, carrier=true
))]
#[allow(clippy::too_many_arguments)]
fn rim_points_visible<'py>(
    py: Python<'py>,
    wafer_poses: &Bound<'py, PyAny>,
    camera_model: &str,
    camera_params: &Bound<'py, PyAny>,
    width: i64,
    height: i64,
    t_wc: &Bound<'py, PyAny>,
    wafer: i64,
    rim: &str,
    angles: &Bound<'py, PyAny>,
    wafer_radius: f64,
    wafer_thickness: f64,
    carrier: bool,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (scene, cam, t_wc) = frame(
        wafer_poses,
        (camera_model, camera_params, width, height),
        t_wc,
        (wafer_radius, wafer_thickness, carrier),
    )?;
    let rim = match rim {
        "upper" => Rim::Upper,
        "lower" => Rim::Lower,
        other => {
            return Err(errors::invalid_input(format!(
                "rim must be \"upper\" or \"lower\", got {other:?}"
            )));
        }
    };
    if wafer < 0 || wafer as usize >= scene.wafers.len() {
        return Err(errors::invalid_input(format!(
            "wafer index {wafer} out of range for {} wafers",
            scene.wafers.len()
        )));
    }
    let angles = convert::finite_array(angles, "angles")?.vector()?;
    let vis = convert::detached(py, || {
        render::rim_points_visible(&scene, &cam, &t_wc, wafer as usize, rim, &angles)
            .map_err(errors::geometry)
    })?;
    Ok(PyArray1::from_vec(py, vis))
}
