//! Binding of `autoteach_estimate::handeye::gating`: the association of detected edges with
//! the projected wafer estimate. The friendly API is `autoteach.pipeline.gate_detections`.

use autoteach_estimate::handeye::gating::{
    BAND_NOISE_LOWER, BAND_NOISE_UPPER, BAND_NOISE_WIDTH_PX, DetectedEdges, GateConfig,
    band_sigma_scale, band_width, gate_edges,
};
use autoteach_estimate::handeye::{Rim, WaferGeometry};
use nalgebra::Vector5;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, matrix3, to_numpy};
use crate::errors;
use crate::handeye_slam::{observations_tuple, points2, stats_dict};

/// Adds the gating function to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(handeye_gate, m)?)?;
    m.add_function(wrap_pyfunction!(handeye_band_width, m)?)?;
    m.add_function(wrap_pyfunction!(handeye_band_sigma_scale, m)?)?;
    m.add(
        "HANDEYE_BAND_NOISE",
        (
            BAND_NOISE_WIDTH_PX.to_vec(),
            BAND_NOISE_UPPER.to_vec(),
            BAND_NOISE_LOWER.to_vec(),
        ),
    )?;
    Ok(())
}

/// Gates detected edges (`edge_points (N, 2)`, `edge_start (E + 1)`, `edge_frames (E)`) against
/// the rims of `wafers (W, 5)` (a row with a non-finite value has no estimate) projected by `k`
/// from `camera_poses (F, 4, 4)` (`T_wc`). Returns
/// `observations` in the solver's flat layout (`handeye_slam`'s module doc; the per-point σ
/// factors only with `band_weights`) and the `stats`.
#[pyfunction]
#[pyo3(signature = (k, camera_poses, wafers, wafer_radius, wafer_thickness, edge_points, edge_start, edge_frames, *,
    gate_px=2.0, min_inlier_fraction=0.6, points_per_rim=24, min_points=12, min_band_px=0.0, band_weights=false))]
#[allow(clippy::too_many_arguments)]
fn handeye_gate<'py>(
    py: Python<'py>,
    k: &Bound<'py, PyAny>,
    camera_poses: &Bound<'py, PyAny>,
    wafers: &Bound<'py, PyAny>,
    wafer_radius: f64,
    wafer_thickness: f64,
    edge_points: &Bound<'py, PyAny>,
    edge_start: Vec<usize>,
    edge_frames: Vec<usize>,
    gate_px: f64,
    min_inlier_fraction: f64,
    points_per_rim: usize,
    min_points: usize,
    min_band_px: f64,
    band_weights: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let k = matrix3(k, "K")?;
    let (cams, lead) = convert::isometries(camera_poses, "camera_poses")?;
    if lead.len() != 1 {
        return Err(errors::invalid_input(format!(
            "camera_poses must have shape (F, 4, 4), got {}",
            convert::shape_str(&[lead.as_slice(), &[4, 4]].concat())
        )));
    }
    let (w, _) = convert::Array::new(wafers, "wafers")?.rows(5, "(W, 5)")?;
    let wafers: Vec<Option<Vector5<f64>>> = w
        .iter()
        .map(|r| {
            r.iter()
                .all(|v| v.is_finite())
                .then(|| Vector5::from_column_slice(r))
        })
        .collect();
    let points = points2(edge_points, "edge_points")?;
    let geometry = WaferGeometry::new(wafer_radius, wafer_thickness).map_err(errors::estimate)?;
    let config = GateConfig {
        gate_px,
        min_inlier_fraction,
        points_per_rim,
        min_points,
        min_band_px,
        band_weights,
    };
    let gated = convert::detached(py, || {
        let edges = DetectedEdges {
            points: &points,
            start: &edge_start,
            frames: &edge_frames,
        };
        gate_edges(&k, &cams, &wafers, geometry, &edges, &config).map_err(errors::estimate)
    })?;
    let d = PyDict::new(py);
    d.set_item(
        "observations",
        observations_tuple(py, &gated.observations, band_weights)?,
    )?;
    d.set_item("stats", stats_dict(py, &gated.stats)?)?;
    Ok(d)
}

/// Predicted image width (pixels) of a wafer's side face at `points (N, 2)` of one rim
/// (`autoteach_estimate::handeye::gating::band_width`).
#[pyfunction]
fn handeye_band_width<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    h_inv: &Bound<'py, PyAny>,
    t_co_other: &Bound<'py, PyAny>,
    conic: &Bound<'py, PyAny>,
    k: &Bound<'py, PyAny>,
    radius: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let p = points2(points, "points")?;
    let h_inv = matrix3(h_inv, "h_inv")?;
    let t = convert::isometry(t_co_other, "t_co_other")?;
    let c = matrix3(conic, "conic")?;
    let k = matrix3(k, "K")?;
    if !(radius.is_finite() && radius > 0.0) {
        return Err(errors::invalid_input(format!(
            "radius must be finite and positive, got {radius}"
        )));
    }
    let n = p.len();
    Ok(to_numpy(py, band_width(&p, &h_inv, &t, &c, &k, radius), &[n])?.into_any())
}

/// Edge-noise factor at each predicted band width (`rim` 0 upper, 1 lower).
#[pyfunction]
fn handeye_band_sigma_scale<'py>(
    py: Python<'py>,
    band: &Bound<'py, PyAny>,
    rim: u8,
) -> PyResult<Bound<'py, PyAny>> {
    let rim = match rim {
        0 => Rim::Upper,
        1 => Rim::Lower,
        r => {
            return Err(errors::invalid_input(format!(
                "rim must be 0 (upper) or 1 (lower), got {r}"
            )));
        }
    };
    let b = convert::Array::new(band, "band")?.vector()?;
    let n = b.len();
    let s: Vec<f64> = b.into_iter().map(|x| band_sigma_scale(x, rim)).collect();
    Ok(to_numpy(py, s, &[n])?.into_any())
}
