//! Binding of `autoteach_detect::ellipse::fit_ellipses`: many arcs in one call.
//!
//! Converts the point array and the offsets, runs the batch without the GIL and returns
//! struct-of-arrays results; the friendly wrapper is `autoteach.detect.fit_ellipses`.

use autoteach_detect::ellipse::{FitMethod, fit_ellipses as core_fit_ellipses};
use nalgebra::Vector2;
use numpy::{IntoPyArray, PyArray1, PyArrayDyn};
use pyo3::prelude::*;

use crate::convert::{self, Array};
use crate::errors;

/// `(params K×5, residual_mean K, residual_rms K, covariance K×5×5, iterations K, converged K,
/// errors)`; failed arcs hold NaN, 0, `False` and their error message.
type BatchOut<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<bool>>,
    Vec<Option<String>>,
);

/// Reads the offsets: a 1-D int64 NumPy array of non-negative values.
fn offsets_arg(obj: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
    let arr = obj
        .extract::<numpy::PyReadonlyArray1<'_, i64>>()
        .map_err(|_| errors::invalid_input("offsets must be a 1-D int64 NumPy array"))?;
    arr.as_array()
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            usize::try_from(i)
                .map_err(|_| errors::invalid_input(format!("offsets[{k}] = {i} is negative")))
        })
        .collect()
}

/// Fits one ellipse per arc `points[offsets[i]:offsets[i + 1]]` (`points` `(N, 2)` float64,
/// `offsets` int64 from 0 to N) with `method` `"direct"` or `"geometric"`.
#[pyfunction]
#[pyo3(signature = (points, offsets, method = "geometric"))]
fn fit_ellipses<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    offsets: &Bound<'py, PyAny>,
    method: &str,
) -> PyResult<BatchOut<'py>> {
    let method = match method {
        "direct" => FitMethod::Direct,
        "geometric" => FitMethod::Geometric,
        other => {
            return Err(errors::invalid_input(format!(
                "method must be 'direct' or 'geometric', got {other:?}"
            )));
        }
    };
    let arr = Array::new(points, "points")?;
    if arr.shape().len() != 2 || arr.shape()[1] != 2 {
        return Err(errors::invalid_input(format!(
            "points must have shape (N, 2), got {}",
            convert::shape_str(arr.shape())
        )));
    }
    let (data, _) = arr.batch(&[2], "(N, 2)")?;
    let pts: Vec<Vector2<f64>> = data
        .chunks_exact(2)
        .map(|c| Vector2::new(c[0], c[1]))
        .collect();
    let offs = offsets_arg(offsets)?;
    let fits = convert::detached(py, || {
        core_fit_ellipses(&pts, &offs, method).map_err(errors::detect)
    })?;
    let k = fits.len();
    let mut params = Vec::with_capacity(5 * k);
    let mut mean = Vec::with_capacity(k);
    let mut rms = Vec::with_capacity(k);
    let mut cov = Vec::with_capacity(25 * k);
    let mut iterations = Vec::with_capacity(k);
    let mut converged = Vec::with_capacity(k);
    let mut messages = Vec::with_capacity(k);
    for fit in fits {
        match fit {
            Ok(f) => {
                let e = f.ellipse;
                params.extend([e.cx, e.cy, e.a, e.b, e.theta]);
                mean.push(f.residual_mean);
                rms.push(f.residual_rms);
                match f.covariance {
                    // Row-major: the covariance is symmetric, the transpose only documents it.
                    Some(c) => cov.extend_from_slice(c.transpose().as_slice()),
                    None => cov.extend([f64::NAN; 25]),
                }
                iterations.push(f.iterations as i64);
                converged.push(f.converged);
                messages.push(None);
            }
            Err(err) => {
                params.extend([f64::NAN; 5]);
                mean.push(f64::NAN);
                rms.push(f64::NAN);
                cov.extend([f64::NAN; 25]);
                iterations.push(0);
                converged.push(false);
                messages.push(Some(err.to_string()));
            }
        }
    }
    Ok((
        convert::to_numpy(py, params, &[k, 5])?,
        mean.into_pyarray(py),
        rms.into_pyarray(py),
        convert::to_numpy(py, cov, &[k, 5, 5])?,
        iterations.into_pyarray(py),
        converged.into_pyarray(py),
        messages,
    ))
}

/// Adds `fit_ellipses` to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fit_ellipses, m)?)?;
    Ok(())
}
