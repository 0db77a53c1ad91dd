//! Bindings of `autoteach_detect::wafers`: wafer-rim detection in grayscale images.
//!
//! `wafer_detect` converts the image (uint8, float32 or float64, 2-D) and the parameters, runs
//! [`autoteach_detect::wafers::detect_wafers`] without the GIL and wraps the edges; the friendly
//! front is `autoteach.detect.detect_wafers`.

use autoteach_detect::DetectError;
use autoteach_detect::edges::{GrayView, Pixel};
use autoteach_detect::wafers::{
    DetectParams, EdgeProfile, RimOffsetPrior, WaferEdge, WaferPrior, detect_wafers,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert;
use crate::errors;
use crate::geometry::PyEllipse;
use crate::gray::{GrayJob, on_gray_image};

/// One detected wafer rim (`autoteach._core.WaferEdge`); see `autoteach.detect.WaferEdge`.
#[pyclass(name = "WaferEdge", module = "autoteach._core", frozen)]
pub struct PyWaferEdge {
    pub(crate) inner: WaferEdge,
}

#[pymethods]
impl PyWaferEdge {
    /// The fitted ellipse.
    #[getter]
    fn ellipse(&self) -> PyEllipse {
        PyEllipse {
            inner: self.inner.ellipse,
        }
    }

    /// Supporting edge points `(N, 2)`.
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let n = self.inner.points.len();
        let data = self.inner.points.iter().flat_map(|p| [p.x, p.y]).collect();
        convert::to_numpy(py, data, &[n, 2])
    }

    /// Mean orthogonal distance of the points to the ellipse (pixels).
    #[getter]
    fn residual(&self) -> f64 {
        self.inner.residual
    }

    /// Covariance of `(cx, cy, a, b, theta)` (5×5) or `None`.
    #[getter]
    fn covariance<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, numpy::PyArrayDyn<f64>>>> {
        self.inner
            .covariance
            .map(|c| convert::to_numpy(py, c.transpose().as_slice().to_vec(), &[5, 5]))
            .transpose()
    }

    /// `"upper"` or `"lower"`.
    #[getter]
    fn kind(&self) -> &'static str {
        self.inner.kind.as_str()
    }

    /// Wafer index within the image (the two rims of one wafer share it).
    #[getter]
    fn wafer_id(&self) -> usize {
        self.inner.wafer_id
    }

    fn __repr__(&self) -> String {
        let e = &self.inner.ellipse;
        format!(
            "_core.WaferEdge(kind={:?}, wafer_id={}, ellipse=({:?}, {:?}, {:?}, {:?}, {:?}), residual={:?}, points={})",
            self.inner.kind.as_str(),
            self.inner.wafer_id,
            e.cx,
            e.cy,
            e.a,
            e.b,
            e.theta,
            self.inner.residual,
            self.inner.points.len()
        )
    }
}

/// The wafer detector as a [`GrayJob`].
struct WaferJob<'a>(&'a DetectParams);

impl GrayJob for WaferJob<'_> {
    type Output = Vec<WaferEdge>;
    fn run<T: Pixel>(&self, view: &GrayView<'_, T>) -> Result<Self::Output, DetectError> {
        detect_wafers(view, self.0)
    }
}

/// The detector's default parameters, by the keyword names of `wafer_detect` (the Python front
/// checks its documented defaults against these).
#[pyfunction]
fn wafer_detect_defaults<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    let p = DetectParams::default();
    let d = PyDict::new(py);
    d.set_item("canny_low", p.canny.low)?;
    d.set_item("canny_high", p.canny.high)?;
    d.set_item("blur_sigma", p.canny.blur_sigma)?;
    d.set_item("min_arc_points", p.arcs.min_points)?;
    d.set_item("inflection_sigmas", p.arcs.inflection_sigmas)?;
    d.set_item("restart_turn_at_cuts", p.arcs.restart_turn_at_cuts)?;
    d.set_item("keep_flat_run_pieces", p.arcs.keep_flat_run_pieces)?;
    d.set_item("border_pairs_take_arcs", p.border_pairs_take_arcs)?;
    d.set_item("reflection_inside_rim", p.reflection_inside_rim)?;
    d.set_item("seek_missing_partner", p.seek_missing_partner)?;
    d.set_item("residual_threshold", p.assembly.residual_threshold)?;
    d.set_item("max_gap", p.assembly.max_gap)?;
    d.set_item("up", (p.up[0], p.up[1]))?;
    d.set_item("max_rim_offset", p.max_rim_offset)?;
    d.set_item("max_rim_axis_difference", p.max_rim_axis_difference)?;
    d.set_item("min_contrast_ratio", p.min_contrast_ratio)?;
    d.set_item("min_coverage", p.min_coverage)?;
    d.set_item("min_rim_separation", p.min_rim_separation)?;
    d.set_item("max_arc_deviation", p.max_arc_deviation)?;
    d.set_item("max_arc_residual_ratio", p.max_arc_residual_ratio)?;
    d.set_item("max_unpaired_residual", p.max_unpaired_residual)?;
    d.set_item("max_relative_sigma_b", p.max_relative_sigma_b)?;
    d.set_item("max_centre_sigma", p.max_centre_sigma)?;
    d.set_item("band_refinement", p.band_refinement)?;
    d.set_item("share_rim_shape", p.share_rim_shape)?;
    d.set_item("share_rim_centre", p.share_rim_centre)?;
    d.set_item("joint_band_fit", p.joint_band_fit)?;
    d.set_item("join_border_cut_arcs", p.join_border_cut_arcs)?;
    d.set_item("thin_band_fit", p.thin_band_fit)?;
    d.set_item("front_band_fit", p.front_band_fit)?;
    d.set_item("level_band_search", p.level_band_search)?;
    let profile = EDGE_PROFILES.iter().find(|(_, e)| *e == p.edge_profile);
    d.set_item("edge_profile", profile.map(|(name, _)| *name))?;
    Ok(d)
}

/// The Python names of the column fits' edge profiles (`edge_profile=`).
const EDGE_PROFILES: [(&str, EdgeProfile); 2] = [
    ("optical", EdgeProfile::Optical),
    ("pixel", EdgeProfile::PixelGrid),
];

/// Detects wafer rims in a grayscale image `(height, width)` of dtype uint8 (0–255) or
/// float32/float64 (0–1). Returns a list of `WaferEdge`.
#[pyfunction]
#[pyo3(signature = (
    image, *, canny_low=6.0, canny_high=15.0, blur_sigma=0.0, min_arc_points=16,
    residual_threshold=0.25, max_gap=60.0, up=(0.0, -1.0), max_rim_offset=10.0,
    max_rim_axis_difference=0.10, min_contrast_ratio=0.45, semi_major_range=None,
    semi_minor_range=None, min_coverage=None, min_rim_separation=None, max_arc_deviation=None,
    max_arc_residual_ratio=None, max_unpaired_residual=None, band_refinement=None,
    share_rim_shape=None, share_rim_centre=None, joint_band_fit=None, inflection_sigmas=None,
    join_border_cut_arcs=None, thickness_ratio=None, focal_length=None, restart_turn_at_cuts=None,
    max_relative_sigma_b=None, max_centre_sigma=None, keep_flat_run_pieces=None,
    border_pairs_take_arcs=None, reflection_inside_rim=None, seek_missing_partner=None,
    thin_band_fit=None, front_band_fit=None, principal_point=None, edge_profile=None,
    level_band_search=None
))]
#[allow(clippy::too_many_arguments)]
fn wafer_detect(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    canny_low: f64,
    canny_high: f64,
    blur_sigma: f64,
    min_arc_points: usize,
    residual_threshold: f64,
    max_gap: f64,
    up: (f64, f64),
    max_rim_offset: f64,
    max_rim_axis_difference: f64,
    min_contrast_ratio: f64,
    semi_major_range: Option<(f64, f64)>,
    semi_minor_range: Option<(f64, f64)>,
    min_coverage: Option<f64>,
    min_rim_separation: Option<f64>,
    max_arc_deviation: Option<f64>,
    max_arc_residual_ratio: Option<f64>,
    max_unpaired_residual: Option<f64>,
    band_refinement: Option<bool>,
    share_rim_shape: Option<bool>,
    share_rim_centre: Option<bool>,
    joint_band_fit: Option<bool>,
    inflection_sigmas: Option<f64>,
    join_border_cut_arcs: Option<bool>,
    thickness_ratio: Option<f64>,
    focal_length: Option<f64>,
    restart_turn_at_cuts: Option<bool>,
    max_relative_sigma_b: Option<f64>,
    max_centre_sigma: Option<f64>,
    keep_flat_run_pieces: Option<bool>,
    border_pairs_take_arcs: Option<bool>,
    reflection_inside_rim: Option<bool>,
    seek_missing_partner: Option<bool>,
    thin_band_fit: Option<bool>,
    front_band_fit: Option<bool>,
    principal_point: Option<(f64, f64)>,
    edge_profile: Option<&str>,
    level_band_search: Option<bool>,
) -> PyResult<Vec<PyWaferEdge>> {
    let edge_profile = match edge_profile {
        None => EdgeProfile::default(),
        Some(name) => EDGE_PROFILES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, p)| p)
            .ok_or_else(|| {
                errors::invalid_input(format!(
                    "edge_profile must be \"optical\" or \"pixel\", got {name:?}"
                ))
            })?,
    };
    let mut params = DetectParams {
        edge_profile,
        ..DetectParams::default()
    };
    // `None` keeps the library default (`wafer_detect_defaults`).
    let set = |slot: &mut f64, value: Option<f64>| {
        if let Some(v) = value {
            *slot = v;
        }
    };
    set(&mut params.min_coverage, min_coverage);
    set(&mut params.min_rim_separation, min_rim_separation);
    set(&mut params.max_arc_deviation, max_arc_deviation);
    set(&mut params.max_arc_residual_ratio, max_arc_residual_ratio);
    set(&mut params.max_unpaired_residual, max_unpaired_residual);
    set(&mut params.arcs.inflection_sigmas, inflection_sigmas);
    set(&mut params.max_relative_sigma_b, max_relative_sigma_b);
    set(&mut params.max_centre_sigma, max_centre_sigma);
    for (slot, value) in [
        (&mut params.band_refinement, band_refinement),
        (&mut params.share_rim_shape, share_rim_shape),
        (&mut params.share_rim_centre, share_rim_centre),
        (&mut params.joint_band_fit, joint_band_fit),
        (&mut params.join_border_cut_arcs, join_border_cut_arcs),
        (&mut params.arcs.restart_turn_at_cuts, restart_turn_at_cuts),
        (&mut params.arcs.keep_flat_run_pieces, keep_flat_run_pieces),
        (&mut params.border_pairs_take_arcs, border_pairs_take_arcs),
        (&mut params.reflection_inside_rim, reflection_inside_rim),
        (&mut params.seek_missing_partner, seek_missing_partner),
        (&mut params.thin_band_fit, thin_band_fit),
        (&mut params.front_band_fit, front_band_fit),
        (&mut params.level_band_search, level_band_search),
    ] {
        if let Some(v) = value {
            *slot = v;
        }
    }
    params.canny.low = canny_low;
    params.canny.high = canny_high;
    params.canny.blur_sigma = blur_sigma;
    params.arcs.min_points = min_arc_points;
    params.assembly.residual_threshold = residual_threshold;
    params.assembly.max_gap = max_gap;
    params.up = [up.0, up.1];
    params.max_rim_offset = max_rim_offset;
    params.max_rim_axis_difference = max_rim_axis_difference;
    params.min_contrast_ratio = min_contrast_ratio;
    params.prior = match (semi_major_range, semi_minor_range) {
        (None, None) => None,
        (a, b) => Some(WaferPrior {
            semi_major: a.unwrap_or((0.0, f64::MAX)),
            semi_minor: b.unwrap_or((0.0, f64::MAX)),
        }),
    };
    params.rim_offset = match (thickness_ratio, focal_length) {
        (None, None) if principal_point.is_some() => {
            return Err(errors::invalid_input(
                "principal_point belongs to the rim offset prior: give thickness_ratio and focal_length too",
            ));
        }
        (None, None) => None,
        (Some(thickness_ratio), Some(focal_length)) => Some(RimOffsetPrior {
            thickness_ratio,
            focal_length,
            principal_point: principal_point.map(|(x, y)| [x, y]),
        }),
        _ => {
            return Err(errors::invalid_input(
                "thickness_ratio and focal_length go together (the rim offset prior needs both)",
            ));
        }
    };
    let edges = on_gray_image(py, image, &WaferJob(&params), false)?;
    Ok(edges
        .into_iter()
        .map(|inner| PyWaferEdge { inner })
        .collect())
}

/// Adds the wafers functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyWaferEdge>()?;
    m.add_function(wrap_pyfunction!(wafer_detect, m)?)?;
    m.add_function(wrap_pyfunction!(wafer_detect_defaults, m)?)?;
    Ok(())
}
