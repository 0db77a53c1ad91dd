//! Bindings of `autoteach_detect::ellipse_detection`: general a-contrario ellipse detection.
//!
//! `ellipse_detect` converts the image (uint8, uint16, float32 or float64, 2-D) and the
//! options, runs [`autoteach_detect::ellipse_detection::detect_ellipses`] without the GIL and
//! wraps the detections; the friendly front is `autoteach.detect.detect_ellipses`.

use autoteach_detect::DetectError;
use autoteach_detect::edges::{GrayView, Pixel};
use autoteach_detect::ellipse_detection::{EllipseDetectParams, EllipseDetection, detect_ellipses};
use pyo3::prelude::*;

use crate::convert;
use crate::geometry::PyEllipse;
use crate::gray::{GrayJob, on_gray_image};
use crate::wafers::PyWaferEdge;
use autoteach_detect::wafer_rims::{WaferGeometry, WaferRimParams, detect_wafer_rims};

/// One detected ellipse (`autoteach._core.EllipseDetection`); see
/// `autoteach.detect.EllipseDetection`.
#[pyclass(name = "EllipseDetection", module = "autoteach._core", frozen)]
pub struct PyEllipseDetection {
    inner: EllipseDetection,
}

#[pymethods]
impl PyEllipseDetection {
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

    /// Mean orthogonal distance of the points to the ellipse (pixels).
    #[getter]
    fn residual(&self) -> f64 {
        self.inner.residual
    }

    /// `-log10 NFA`.
    #[getter]
    fn score(&self) -> f64 {
        self.inner.score
    }

    /// `+1` brighter outside, `-1` brighter inside, `0` centre of a thin line.
    #[getter]
    fn polarity(&self) -> i8 {
        self.inner.polarity
    }

    fn __repr__(&self) -> String {
        let e = &self.inner.ellipse;
        format!(
            "_core.EllipseDetection(ellipse=({:?}, {:?}, {:?}, {:?}, {:?}), score={:?}, polarity={}, points={})",
            e.cx,
            e.cy,
            e.a,
            e.b,
            e.theta,
            self.inner.score,
            self.inner.polarity,
            self.inner.points.len()
        )
    }
}

/// The ellipse detector as a [`GrayJob`].
struct EllipseJob<'a>(&'a EllipseDetectParams);

impl GrayJob for EllipseJob<'_> {
    type Output = Vec<EllipseDetection>;
    fn run<T: Pixel>(&self, view: &GrayView<'_, T>) -> Result<Self::Output, DetectError> {
        detect_ellipses(view, self.0)
    }
}

/// The geometric rim pairing as a [`GrayJob`].
struct RimJob<'a>(&'a WaferRimParams);

impl GrayJob for RimJob<'_> {
    type Output = Vec<autoteach_detect::wafers::WaferEdge>;
    fn run<T: Pixel>(&self, view: &GrayView<'_, T>) -> Result<Self::Output, DetectError> {
        detect_wafer_rims(view, self.0)
    }
}

/// Detects ellipses in a grayscale image `(height, width)` of dtype uint8 (0–255), uint16
/// (0–65535) or float32/float64 (0–1). Returns a list of `EllipseDetection`.
#[pyfunction]
#[pyo3(signature = (
    image, *, min_arc_points=12, min_semi_minor=2.0, max_semi_major=None, max_gap=None,
    blur_sigma=0.0, max_nfa=1.0, max_line_width=None, gradient_noise=None
))]
#[allow(clippy::too_many_arguments)]
fn ellipse_detect(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    min_arc_points: usize,
    min_semi_minor: f64,
    max_semi_major: Option<f64>,
    max_gap: Option<f64>,
    blur_sigma: f64,
    max_nfa: f64,
    max_line_width: Option<f64>,
    gradient_noise: Option<f64>,
) -> PyResult<Vec<PyEllipseDetection>> {
    let params = EllipseDetectParams {
        min_arc_points,
        min_semi_minor,
        max_semi_major,
        max_gap,
        blur_sigma,
        max_nfa,
        max_line_width,
        gradient_noise,
    };
    let found = on_gray_image(py, image, &EllipseJob(&params), true)?;
    Ok(found
        .into_iter()
        .map(|inner| PyEllipseDetection { inner })
        .collect())
}

/// Wafer rims from general ellipse detections paired by geometry (radius and thickness in
/// mm, `up` the image direction of the wafers' normal). Same image dtypes as
/// `ellipse_detect`. Returns a list of `WaferEdge`.
#[pyfunction]
#[pyo3(signature = (
    image, *, radius=75.0, thickness=0.775, up=(0.0, -1.0), semi_major_range=None,
    focal_length=None, min_arc_points=12, min_semi_minor=2.0, max_gap=None, blur_sigma=0.0, max_nfa=1.0,
    gradient_noise=None
))]
#[allow(clippy::too_many_arguments)]
fn wafer_rims_detect(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    radius: f64,
    thickness: f64,
    up: (f64, f64),
    semi_major_range: Option<(f64, f64)>,
    focal_length: Option<f64>,
    min_arc_points: usize,
    min_semi_minor: f64,
    max_gap: Option<f64>,
    blur_sigma: f64,
    max_nfa: f64,
    gradient_noise: Option<f64>,
) -> PyResult<Vec<PyWaferEdge>> {
    let params = WaferRimParams {
        geometry: WaferGeometry {
            radius,
            thickness,
            up: [up.0, up.1],
            semi_major: semi_major_range,
            focal_length,
        },
        ellipses: EllipseDetectParams {
            min_arc_points,
            min_semi_minor,
            max_semi_major: semi_major_range.map(|r| r.1),
            max_gap,
            blur_sigma,
            max_nfa,
            max_line_width: None,
            gradient_noise,
        },
    };
    let rims = on_gray_image(py, image, &RimJob(&params), true)?;
    Ok(rims
        .into_iter()
        .map(|inner| PyWaferEdge { inner })
        .collect())
}

/// Adds the ellipse-detection functions and class to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEllipseDetection>()?;
    m.add_function(wrap_pyfunction!(ellipse_detect, m)?)?;
    m.add_function(wrap_pyfunction!(wafer_rims_detect, m)?)?;
    Ok(())
}
