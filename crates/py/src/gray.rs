//! Grayscale NumPy images for the detectors: one dtype dispatch and one borrowed view.
//!
//! A detector binding states its computation as a [`GrayJob`] (generic over the pixel type)
//! and calls [`on_gray_image`], which reads uint8, float32 and float64 arrays in place when
//! they are C-contiguous (copying other layouts row-major), optionally accepts uint16 (scaled
//! to 0–1 floats), and runs the job without the GIL.

use autoteach_detect::DetectError;
use autoteach_detect::edges::{GrayView, Pixel};
use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::{convert, errors};

/// A detector run on a grayscale view of any pixel type.
pub(crate) trait GrayJob: Sync {
    /// What the job returns.
    type Output: Send;
    /// Runs the job on `view`.
    fn run<T: Pixel>(&self, view: &GrayView<'_, T>) -> Result<Self::Output, DetectError>;
}

/// Runs `job` on a typed 2-D array, read in place when C-contiguous.
fn run_typed<J: GrayJob, T: Pixel + numpy::Element>(
    py: Python<'_>,
    arr: PyReadonlyArray2<'_, T>,
    job: &J,
) -> PyResult<J::Output> {
    let shape = arr.shape();
    let (h, w) = (shape[0], shape[1]);
    // A C-contiguous array is read in place; any other view is copied row-major first.
    // (`as_slice` also accepts Fortran order, whose memory order is not row-major.)
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
        job.run(&view).map_err(errors::detect)
    })
}

/// Runs `job` on `image` (2-D; uint8, float32 or float64, and uint16 scaled to 0–1 when
/// `accept_u16`); any other dtype is an `InvalidInputError` naming the accepted ones.
pub(crate) fn on_gray_image<J: GrayJob>(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    job: &J,
    accept_u16: bool,
) -> PyResult<J::Output> {
    check_2d(image)?;
    if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u8>>() {
        return run_typed(py, a, job);
    }
    if accept_u16 && let Ok(a) = image.extract::<PyReadonlyArray2<'_, u16>>() {
        // 16-bit: scaled to 0–1 floats (the detectors' grey scale is 0–255 either way).
        let shape = a.shape();
        let (h, w) = (shape[0], shape[1]);
        let unit: Vec<f32> = a
            .as_array()
            .iter()
            .map(|&v| f32::from(v) / 65535.0)
            .collect();
        return convert::detached(py, || {
            let view = GrayView::new(&unit, w, h).map_err(errors::detect)?;
            job.run(&view).map_err(errors::detect)
        });
    }
    if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f32>>() {
        return run_typed(py, a, job);
    }
    if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f64>>() {
        return run_typed(py, a, job);
    }
    let dtype = image
        .getattr("dtype")
        .map(|d| d.to_string())
        .unwrap_or_else(|_| "unknown".into());
    let accepted = if accept_u16 {
        "uint8, uint16, float32 or float64"
    } else {
        "uint8, float32 or float64"
    };
    Err(errors::invalid_input(format!(
        "image must have dtype {accepted}, got {dtype}"
    )))
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
