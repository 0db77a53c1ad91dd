//! Bindings of `autoteach_detect::segment` (coloured point-cloud co-registration and
//! segmentation, seed 004_815695db12a6b16c.txt ch. 4) and of
//! `autoteach_estimate::lidar_camera` (extrinsic calibration, eq. (4.2)).
//!
//! Each function converts its NumPy inputs, calls one core function without the GIL and
//! converts the result; the friendly wrappers live in `python/autoteach/segment.py`.

use autoteach_detect::segment::scene::{self, Scanner};
use autoteach_detect::segment::{
    ColorizeParams, Criteria, FhParams, GraphKind, RgbImage, SegmentParams, UNLABELLED,
    colorize as core_colorize, segment_cloud,
};
use autoteach_estimate::lidar_camera::calibrate_extrinsics;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, Array};
use crate::errors;
use crate::geometry::PyCamera;

/// Adds the segmentation functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(segment_colored_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(colorize_points, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_colored_scan, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_lidar_camera, m)?)?;
    Ok(())
}

/// Reads float64 points of shape `(..., 3)`: rows and leading shape. NaN is kept (the core
/// decides where it is allowed); infinities are reported by the core with their index.
fn points_arg(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<(Vec<[f64; 3]>, Vec<usize>)> {
    let arr = Array::new(obj, name)?;
    let (data, lead) = arr.batch(&[3], "(..., 3)")?;
    Ok((
        data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        lead,
    ))
}

/// Reads a uint8 array of shape `(..., 3)` (the Python wrapper converts other dtypes after
/// checking their range).
fn rgb_arg<'py>(
    obj: &Bound<'py, PyAny>,
    name: &'static str,
) -> PyResult<(Vec<[u8; 3]>, Vec<usize>)> {
    let arr = obj.extract::<PyReadonlyArrayDyn<'py, u8>>().map_err(|_| {
        errors::invalid_input(format!(
            "{name} must be a uint8 NumPy array (0-255), got {}",
            obj.getattr("dtype")
                .map(|d| format!("dtype {d}"))
                .unwrap_or_else(|_| "a non-array".into())
        ))
    })?;
    let shape = arr.shape().to_vec();
    if shape.last() != Some(&3) {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (..., 3), got {}",
            convert::shape_str(&shape)
        )));
    }
    let view = arr.as_array();
    let data: Vec<u8> = view.iter().copied().collect();
    Ok((
        data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        shape[..shape.len() - 1].to_vec(),
    ))
}

fn criteria(name: &str) -> PyResult<Criteria> {
    match name {
        "both" => Ok(Criteria::Both),
        "color" => Ok(Criteria::ColorOnly),
        "normal" => Ok(Criteria::NormalOnly),
        other => Err(errors::invalid_input(format!(
            "criteria must be 'both', 'color' or 'normal', got {other:?}"
        ))),
    }
}

fn nonneg_usize(v: i64, name: &str) -> PyResult<usize> {
    usize::try_from(v).map_err(|_| {
        errors::invalid_input(format!("{name} must be a non-negative integer, got {v}"))
    })
}

/// Segments a coloured cloud; returns `(labels, normals, num_segments, num_edges)`.
#[pyfunction]
#[pyo3(signature = (points, colors, normals, graph, k, k_rgb, k_norm, edge_cut, min_size, criteria_name, viewpoint))]
#[allow(clippy::too_many_arguments)]
fn segment_colored_cloud<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    colors: &Bound<'py, PyAny>,
    normals: Option<&Bound<'py, PyAny>>,
    graph: &str,
    k: i64,
    k_rgb: f64,
    k_norm: f64,
    edge_cut: f64,
    min_size: i64,
    criteria_name: &str,
    viewpoint: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let (pts, lead) = points_arg(points, "points")?;
    let (cols, clead) = rgb_arg(colors, "colors")?;
    if clead != lead {
        return Err(errors::invalid_input(format!(
            "colors must have shape {} to match points, got {}",
            convert::shape_str(&convert::batched_shape(&lead, &[3])),
            convert::shape_str(&convert::batched_shape(&clead, &[3]))
        )));
    }
    let given = match normals {
        Some(nr) => {
            let (n, nlead) = points_arg(nr, "normals")?;
            if nlead != lead {
                return Err(errors::invalid_input(format!(
                    "normals must have the shape of points, got leading shape {nlead:?}"
                )));
            }
            Some(n)
        }
        None => None,
    };
    let graph = match graph {
        "scan" => {
            if lead.len() != 2 {
                return Err(errors::invalid_input(format!(
                    "graph='scan' needs an organised cloud of shape (lines, beams, 3), got {}",
                    convert::shape_str(&convert::batched_shape(&lead, &[3]))
                )));
            }
            GraphKind::Scan {
                lines: lead[0],
                beams: lead[1],
            }
        }
        "knn" => {
            if lead.len() != 1 {
                return Err(errors::invalid_input(format!(
                    "graph='knn' needs an unorganised cloud of shape (N, 3), got {}",
                    convert::shape_str(&convert::batched_shape(&lead, &[3]))
                )));
            }
            GraphKind::Knn {
                k: nonneg_usize(k, "k")?,
            }
        }
        other => {
            return Err(errors::invalid_input(format!(
                "graph must be 'scan' or 'knn', got {other:?}"
            )));
        }
    };
    let vp = convert::finite_array(viewpoint, "viewpoint")?.exact(&[3])?;
    let params = SegmentParams {
        fh: FhParams {
            k_rgb,
            k_norm,
            min_size: nonneg_usize(min_size, "min_size")?,
            criteria: criteria(criteria_name)?,
        },
        edge_cut,
        graph,
        viewpoint: [vp[0], vp[1], vp[2]],
    };
    let out = convert::detached(py, move || {
        segment_cloud(&pts, &cols, given.as_deref(), &params).map_err(errors::detect)
    })?;
    let labels: Vec<i64> = out
        .labels
        .iter()
        .map(|&l| if l == UNLABELLED { -1 } else { i64::from(l) })
        .collect();
    let d = PyDict::new(py);
    let labels = Array1::from(labels)
        .into_shape_with_order(numpy::ndarray::IxDyn(&lead))
        .map_err(|e| errors::internal(e.to_string()))?;
    d.set_item("labels", labels.into_pyarray(py))?;
    let flat: Vec<f64> = out.normals.iter().flatten().copied().collect();
    d.set_item(
        "normals",
        convert::to_numpy(py, flat, &convert::batched_shape(&lead, &[3]))?,
    )?;
    let normal_ok = Array1::from(out.normal_ok)
        .into_shape_with_order(numpy::ndarray::IxDyn(&lead))
        .map_err(|e| errors::internal(e.to_string()))?;
    d.set_item("normal_ok", normal_ok.into_pyarray(py))?;
    d.set_item("num_segments", out.num_segments)?;
    d.set_item("num_edges", out.num_edges)?;
    Ok(d)
}

/// Colours lidar points from an image; returns `(colors (N, 3) uint8, status (N,) uint8)`.
#[pyfunction]
#[pyo3(signature = (points, image, camera, t_cam_lidar, splat_radius, depth_tolerance))]
fn colorize_points<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    image: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyCamera>,
    t_cam_lidar: &Bound<'py, PyAny>,
    splat_radius: i64,
    depth_tolerance: f64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let (pts, lead) = points_arg(points, "points")?;
    if lead.len() != 1 {
        return Err(errors::invalid_input(format!(
            "points must have shape (N, 3), got {}",
            convert::shape_str(&convert::batched_shape(&lead, &[3]))
        )));
    }
    let (pix, ilead) = rgb_arg(image, "image")?;
    if ilead.len() != 2 {
        return Err(errors::invalid_input(format!(
            "image must have shape (height, width, 3), got {}",
            convert::shape_str(&convert::batched_shape(&ilead, &[3]))
        )));
    }
    let t = convert::isometry(t_cam_lidar, "T_cam_lidar")?;
    let cam = camera.get().inner.clone();
    let params = ColorizeParams {
        splat_radius: nonneg_usize(splat_radius, "splat_radius")?,
        depth_tolerance,
    };
    let (h, w) = (ilead[0], ilead[1]);
    let out = convert::detached(py, move || {
        let data: Vec<u8> = pix.iter().flatten().copied().collect();
        let img = RgbImage {
            width: w,
            height: h,
            data: &data,
        };
        core_colorize(&pts, &img, &cam, &t, &params).map_err(errors::detect)
    })?;
    let n = out.colors.len();
    let colors = Array2::from_shape_vec((n, 3), out.colors.iter().flatten().copied().collect())
        .map_err(|e| errors::internal(e.to_string()))?;
    let status: Array1<u8> = out.status.iter().map(|s| *s as u8).collect();
    Ok((
        colors.into_pyarray(py).into_any(),
        status.into_pyarray(py).into_any(),
    ))
}

/// Simulates the tilting scanner and camera in a preset scene; returns a dict of arrays.
#[pyfunction]
#[pyo3(signature = (scene_name, beam_step_deg, tilt_start_deg, tilt_end_deg, tilt_speed_deg_s, range_sigma, color_sigma, seed, render))]
#[allow(clippy::too_many_arguments)]
fn simulate_colored_scan<'py>(
    py: Python<'py>,
    scene_name: &str,
    beam_step_deg: f64,
    tilt_start_deg: f64,
    tilt_end_deg: f64,
    tilt_speed_deg_s: f64,
    range_sigma: f64,
    color_sigma: f64,
    seed: u64,
    render: bool,
) -> PyResult<Bound<'py, PyDict>> {
    if !(color_sigma.is_finite() && color_sigma >= 0.0) {
        return Err(errors::invalid_input(format!(
            "color_sigma must be non-negative and finite, got {color_sigma}"
        )));
    }
    let sc = scene::preset(scene_name).map_err(errors::detect)?;
    let scanner = Scanner {
        beam_step_deg,
        tilt_start_deg,
        tilt_end_deg,
        tilt_speed_deg_s,
        range_sigma,
        ..Scanner::hokuyo()
    };
    let names: Vec<(u32, String)> = sc
        .objects
        .iter()
        .map(|o| (o.label, o.name.clone()))
        .collect();
    let (s, img, cam, t_cam_lidar, t_world_lidar) = convert::detached(py, move || {
        let s = scene::scan(&sc, &scanner, color_sigma, seed).map_err(errors::detect)?;
        let cam = scene::firefly_camera().map_err(errors::detect)?;
        let t_cam_lidar = scene::default_t_cam_lidar();
        let img = if render {
            let t_world_cam = scanner.t_world_lidar * t_cam_lidar.inverse();
            Some(scene::render(&sc, &cam, &t_world_cam, color_sigma, seed))
        } else {
            None
        };
        Ok((s, img, cam, t_cam_lidar, scanner.t_world_lidar))
    })?;
    let (l, b) = (s.lines, s.beams);
    let d = PyDict::new(py);
    let f3 = |v: &[[f64; 3]]| -> PyResult<Bound<'py, PyAny>> {
        Ok(
            Array3::from_shape_vec((l, b, 3), v.iter().flatten().copied().collect())
                .map_err(|e| errors::internal(e.to_string()))?
                .into_pyarray(py)
                .into_any(),
        )
    };
    d.set_item("points", f3(&s.points)?)?;
    d.set_item("true_points", f3(&s.true_points)?)?;
    d.set_item("true_normals", f3(&s.true_normals)?)?;
    let labels: Vec<i64> = s
        .labels
        .iter()
        .map(|&x| if x == u32::MAX { -1 } else { i64::from(x) })
        .collect();
    d.set_item(
        "labels",
        Array2::from_shape_vec((l, b), labels)
            .map_err(|e| errors::internal(e.to_string()))?
            .into_pyarray(py),
    )?;
    d.set_item(
        "true_colors",
        Array3::from_shape_vec((l, b, 3), s.true_colors.iter().flatten().copied().collect())
            .map_err(|e| errors::internal(e.to_string()))?
            .into_pyarray(py),
    )?;
    if let Some(img) = img {
        let (w, h) = (cam.width() as usize, cam.height() as usize);
        d.set_item(
            "image",
            Array3::from_shape_vec((h, w, 3), img)
                .map_err(|e| errors::internal(e.to_string()))?
                .into_pyarray(py),
        )?;
    }
    d.set_item("camera_params", cam.params().to_vec())?;
    d.set_item("camera_size", (cam.width(), cam.height()))?;
    d.set_item("T_cam_lidar", convert::isometry_rows(&t_cam_lidar))?;
    d.set_item("T_world_lidar", convert::isometry_rows(&t_world_lidar))?;
    d.set_item("object_names", names)?;
    Ok(d)
}

/// Estimates `T_cam_lidar` from point–pixel correspondences (eq. (4.2)); returns a dict.
#[pyfunction]
#[pyo3(signature = (camera, points, pixels, initial, sigma=None))]
fn calibrate_lidar_camera<'py>(
    py: Python<'py>,
    camera: &Bound<'py, PyCamera>,
    points: &Bound<'py, PyAny>,
    pixels: &Bound<'py, PyAny>,
    initial: &Bound<'py, PyAny>,
    sigma: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (p, _) = convert::finite_batch(points, "points", &[3], "(N, 3)")?;
    let (q, _) = convert::finite_batch(pixels, "pixels", &[2], "(N, 2)")?;
    let pts: Vec<[f64; 3]> = p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let pix: Vec<[f64; 2]> = q.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    let init = convert::isometry(initial, "initial")?;
    let cam = camera.get().inner.clone();
    let fit = convert::detached(py, move || {
        calibrate_extrinsics(&cam, &pts, &pix, &init, sigma).map_err(errors::estimate)
    })?;
    let d = PyDict::new(py);
    d.set_item("T_cam_lidar", convert::isometry_rows(&fit.t_cam_lidar))?;
    let cov: Vec<f64> = (0..6)
        .flat_map(|r| (0..6).map(move |c| (r, c)))
        .map(|(r, c)| fit.covariance[(r, c)])
        .collect();
    d.set_item("covariance", convert::to_numpy(py, cov, &[6, 6])?)?;
    d.set_item("sigma", fit.sigma)?;
    d.set_item("rms", fit.rms)?;
    d.set_item("iterations", fit.iterations)?;
    d.set_item("converged", fit.converged)?;
    Ok(d)
}
