//! Bindings of `autoteach_detect::ellipse_detection`: general a-contrario ellipse detection.
//!
//! `ellipse_detect` converts the image (uint8, uint16, float32 or float64, 2-D) and the
//! options, runs [`autoteach_detect::ellipse_detection::detect_ellipses`] without the GIL and
//! wraps the detections; the friendly front is `autoteach.detect.detect_ellipses`.

use autoteach_detect::edges::{GrayView, Pixel};
use autoteach_detect::ellipse_detection::{EllipseDetectParams, EllipseDetection, detect_ellipses};
use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::convert;
use crate::errors;
use crate::geometry::PyEllipse;
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

/// Runs the detector on a 2-D array of one pixel type.
fn run<T: Pixel + numpy::Element>(
    py: Python<'_>,
    arr: PyReadonlyArray2<'_, T>,
    params: &EllipseDetectParams,
) -> PyResult<Vec<EllipseDetection>> {
    let shape = arr.shape();
    let (h, w) = (shape[0], shape[1]);
    // A C-contiguous array is read in place; any other view is copied row-major first.
    let copied: Vec<T>;
    let data: &[T] = match arr.as_slice() {
        Ok(slice) if arr.is_c_contiguous() => slice,
        _ => {
            copied = arr.as_array().iter().copied().collect();
            &copied
        }
    };
    convert::detached(py, || {
        let view = GrayView::new(data, w, h).map_err(errors::detect)?;
        detect_ellipses(&view, params).map_err(errors::detect)
    })
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
    check_2d(image)?;
    let found = if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u8>>() {
        run(py, a, &params)?
    } else if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u16>>() {
        // 16-bit: scaled to 0–1 floats (the detector's grey scale is 0–255 either way).
        let shape = a.shape();
        let (h, w) = (shape[0], shape[1]);
        let unit: Vec<f32> = a
            .as_array()
            .iter()
            .map(|&v| f32::from(v) / 65535.0)
            .collect();
        convert::detached(py, || {
            let view = GrayView::new(&unit, w, h).map_err(errors::detect)?;
            detect_ellipses(&view, &params).map_err(errors::detect)
        })?
    } else if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f32>>() {
        run(py, a, &params)?
    } else if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f64>>() {
        run(py, a, &params)?
    } else {
        return Err(bad_dtype(image));
    };
    Ok(found
        .into_iter()
        .map(|inner| PyEllipseDetection { inner })
        .collect())
}

/// Runs [`detect_wafer_rims`] on a 2-D array of one pixel type.
fn run_rims<T: Pixel + numpy::Element>(
    py: Python<'_>,
    arr: PyReadonlyArray2<'_, T>,
    params: &WaferRimParams,
) -> PyResult<Vec<autoteach_detect::wafers::WaferEdge>> {
    let shape = arr.shape();
    let (h, w) = (shape[0], shape[1]);
    let copied: Vec<T>;
    let data: &[T] = match arr.as_slice() {
        Ok(slice) if arr.is_c_contiguous() => slice,
        _ => {
            copied = arr.as_array().iter().copied().collect();
            &copied
        }
    };
    convert::detached(py, || {
        let view = GrayView::new(data, w, h).map_err(errors::detect)?;
        detect_wafer_rims(&view, params).map_err(errors::detect)
    })
}

/// Wafer rims from general ellipse detections paired by geometry (radius and thickness in
/// mm, `up` the image direction of the wafers' normal). Same image dtypes as
/// `ellipse_detect`. Returns a list of `WaferEdge`.
#[pyfunction]
#[pyo3(signature = (
    image, *, radius=75.0, thickness=0.775, up=(0.0, -1.0), semi_major_range=None,
    min_arc_points=12, min_semi_minor=2.0, max_gap=None, blur_sigma=0.0, max_nfa=1.0,
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
    check_2d(image)?;
    let rims = if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u8>>() {
        run_rims(py, a, &params)?
    } else if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u16>>() {
        let shape = a.shape();
        let (h, w) = (shape[0], shape[1]);
        let unit: Vec<f32> = a
            .as_array()
            .iter()
            .map(|&v| f32::from(v) / 65535.0)
            .collect();
        convert::detached(py, || {
            let view = GrayView::new(&unit, w, h).map_err(errors::detect)?;
            detect_wafer_rims(&view, &params).map_err(errors::detect)
        })?
    } else if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f32>>() {
        run_rims(py, a, &params)?
    } else if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f64>>() {
        run_rims(py, a, &params)?
    } else {
        return Err(bad_dtype(image));
    };
    Ok(rims
        .into_iter()
        .map(|inner| PyWaferEdge { inner })
        .collect())
}

/// The error for an unsupported dtype.
fn bad_dtype(image: &Bound<'_, PyAny>) -> PyErr {
    let dtype = image
        .getattr("dtype")
        .map(|d| d.to_string())
        .unwrap_or_else(|_| "unknown".into());
    errors::invalid_input(format!(
        "image must have dtype uint8, uint16, float32 or float64, got {dtype}"
    ))
}

/// Fails unless `image` is a 2-D array.
fn check_2d(image: &Bound<'_, PyAny>) -> PyResult<()> {
    let ndim = image
        .getattr("ndim")
        .and_then(|n| n.extract::<usize>())
        .map_err(|_| {
            errors::invalid_input(format!(
                "image must be a 2-D NumPy array, got a {}",
                image
                    .get_type()
                    .name()
                    .map(|n| n.to_string())
                    .unwrap_or_default()
            ))
        })?;
    if ndim != 2 {
        return Err(errors::invalid_input(format!(
            "image must be 2-D (height, width) grayscale, got {ndim} dimensions"
        )));
    }
    Ok(())
}

/// Adds the ellipse-detection functions and class to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEllipseDetection>()?;
    m.add_function(wrap_pyfunction!(ellipse_detect, m)?)?;
    m.add_function(wrap_pyfunction!(wafer_rims_detect, m)?)?;
    Ok(())
}
