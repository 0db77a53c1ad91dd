//! Bindings of `autoteach_detect`: ellipse fitting and linear assignment.
//!
//! Each function converts its NumPy inputs, calls one core function and converts the result;
//! the friendly wrappers live in `python/autoteach/detect.py`.

use autoteach_detect::assignment::{Assignment, solve_assignment_with_unassigned};
use autoteach_detect::ellipse::{EllipseFit, FitMethod, fit_ellipse as core_fit_ellipse};
use autoteach_detect::lapjv::solve_assignment_row_major;
use nalgebra::{DMatrix, Vector2};
use numpy::{IntoPyArray, PyArray1, PyArrayDyn};
use pyo3::prelude::*;

use crate::convert::{self, Array};
use crate::errors;
use crate::geometry::PyEllipse;

/// The result of `fit_ellipse` (`autoteach._core.EllipseFit`); see `autoteach.detect.EllipseFit`.
#[pyclass(name = "EllipseFit", module = "autoteach._core", frozen)]
pub struct PyEllipseFit {
    inner: EllipseFit,
}

#[pymethods]
impl PyEllipseFit {
    /// The fitted ellipse.
    #[getter]
    fn ellipse(&self) -> PyEllipse {
        PyEllipse {
            inner: self.inner.ellipse,
        }
    }

    /// Mean absolute orthogonal distance (pixels).
    #[getter]
    fn residual_mean(&self) -> f64 {
        self.inner.residual_mean
    }

    /// RMS orthogonal distance (pixels).
    #[getter]
    fn residual_rms(&self) -> f64 {
        self.inner.residual_rms
    }

    /// Covariance of `(cx, cy, a, b, theta)`, 5×5, or `None` for exactly 5 points.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f64>>>> {
        self.inner
            .covariance
            .map(|c| convert::to_numpy(py, c.transpose().as_slice().to_vec(), &[5, 5]))
            .transpose()
    }

    /// Levenberg–Marquardt iterations (0 for the direct fit).
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }

    /// Whether the iteration met its tolerance.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }

    fn __repr__(&self) -> String {
        let e = &self.inner.ellipse;
        format!(
            "_core.EllipseFit(ellipse=({:?}, {:?}, {:?}, {:?}, {:?}), residual_mean={:?}, iterations={})",
            e.cx, e.cy, e.a, e.b, e.theta, self.inner.residual_mean, self.inner.iterations
        )
    }
}

/// Reads points of shape `(N, 2)` (finiteness is checked by the core, which names the index).
fn points_arg(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<Vector2<f64>>> {
    let arr = Array::new(obj, name)?;
    if arr.shape().len() != 2 || arr.shape()[1] != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (N, 2), got {}",
            convert::shape_str(arr.shape())
        )));
    }
    let (data, _) = arr.batch(&[2], "(N, 2)")?;
    Ok(data
        .chunks_exact(2)
        .map(|c| Vector2::new(c[0], c[1]))
        .collect())
}

/// Reads a 2-D cost matrix.
fn matrix_arg(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<DMatrix<f64>> {
    let arr = Array::new(obj, name)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must be two-dimensional (rows, cols), got shape {}",
            convert::shape_str(&shape)
        )));
    }
    let (data, _) = arr.batch(&[], "(rows, cols)")?;
    Ok(DMatrix::from_row_slice(shape[0], shape[1], &data))
}

/// Reads a 2-D float array as `(rows, cols, row-major data)`.
fn matrix_rows_arg(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
) -> PyResult<(usize, usize, Vec<f64>)> {
    let arr = Array::new(obj, name)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must be two-dimensional (rows, cols), got shape {}",
            convert::shape_str(&shape)
        )));
    }
    let (data, _) = arr.batch(&[], "(rows, cols)")?;
    Ok((shape[0], shape[1], data))
}

/// Fits an ellipse to points `(N, 2)` with `method` `"direct"` or `"geometric"`.
#[pyfunction]
#[pyo3(signature = (points, method = "geometric"))]
fn fit_ellipse(py: Python<'_>, points: &Bound<'_, PyAny>, method: &str) -> PyResult<PyEllipseFit> {
    let method = match method {
        "direct" => FitMethod::Direct,
        "geometric" => FitMethod::Geometric,
        other => {
            return Err(errors::invalid_input(format!(
                "method must be 'direct' or 'geometric', got {other:?}"
            )));
        }
    };
    let pts = points_arg(points, "points")?;
    let inner = convert::run_batched(py, 2 * pts.len(), || {
        core_fit_ellipse(&pts, method).map_err(errors::detect)
    })?;
    Ok(PyEllipseFit { inner })
}

/// Row and column indices of assigned pairs, as NumPy `intp` arrays.
type Indices<'py> = (Bound<'py, PyArray1<isize>>, Bound<'py, PyArray1<isize>>);

/// Row and column indices of assigned pairs and the total cost.
type IndicesAndTotal<'py> = (
    Bound<'py, PyArray1<isize>>,
    Bound<'py, PyArray1<isize>>,
    f64,
);

/// Assigned pairs as (row indices, column indices), sorted by row.
fn pairs<'py>(py: Python<'py>, a: &Assignment) -> Indices<'py> {
    let (rows, cols): (Vec<isize>, Vec<isize>) = a
        .pairs()
        .into_iter()
        .map(|(i, j)| (i as isize, j as isize))
        .unzip();
    (rows.into_pyarray(py), cols.into_pyarray(py))
}

/// Minimum- (or maximum-) cost assignment of a rectangular cost matrix; `+inf` (`-inf` when
/// maximising) marks forbidden pairs. Returns (row indices, column indices).
#[pyfunction]
#[pyo3(signature = (cost, maximize = false))]
fn linear_sum_assignment<'py>(
    py: Python<'py>,
    cost: &Bound<'py, PyAny>,
    maximize: bool,
) -> PyResult<Indices<'py>> {
    if !maximize {
        // A C-contiguous float64 matrix is solved in place: no copy (72 MB at n = 3 000, a
        // sixth of the solve with its page faults) — the solver reads it row by row and
        // checks every entry itself. The array must not be written by another thread during
        // the call (as for NumPy's own routines that release the GIL).
        let arr = Array::new(cost, "cost")?;
        let shape = arr.shape().to_vec();
        if shape.len() == 2 {
            let view = arr.view();
            if let Some(data) = view.to_slice() {
                let a = convert::run_batched(py, data.len(), || {
                    solve_assignment_row_major(shape[0], shape[1], data).map_err(errors::detect)
                })?;
                return Ok(pairs(py, &a));
            }
        }
    }
    let (rows, cols, mut m) = matrix_rows_arg(cost, "cost")?;
    if maximize {
        if let Some(v) = m.iter().find(|v| v.is_nan() || **v == f64::INFINITY) {
            return Err(errors::invalid_input(format!(
                "cost contains {v}: with maximize=True entries must be finite or -inf (forbidden)"
            )));
        }
        m.iter_mut().for_each(|v| *v = -*v);
    }
    let a = convert::run_batched(py, m.len(), || {
        solve_assignment_row_major(rows, cols, &m).map_err(errors::detect)
    })?;
    Ok(pairs(py, &a))
}

/// Minimum-cost assignment where row `i` / column `j` may stay unassigned at cost
/// `row_unassigned_cost[i]` / `col_unassigned_cost[j]`. Returns (rows, cols, total cost).
#[pyfunction]
fn assign_with_unassigned<'py>(
    py: Python<'py>,
    cost: &Bound<'py, PyAny>,
    row_unassigned_cost: &Bound<'py, PyAny>,
    col_unassigned_cost: &Bound<'py, PyAny>,
) -> PyResult<IndicesAndTotal<'py>> {
    let m = matrix_arg(cost, "cost")?;
    let ru = Array::new(row_unassigned_cost, "row_unassigned_cost")?.vector()?;
    let cu = Array::new(col_unassigned_cost, "col_unassigned_cost")?.vector()?;
    let a = convert::run_batched(py, m.len(), || {
        solve_assignment_with_unassigned(&m, &ru, &cu).map_err(errors::detect)
    })?;
    let (rows, cols) = pairs(py, &a);
    Ok((rows, cols, a.cost))
}

/// Adds the detect functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEllipseFit>()?;
    m.add_function(wrap_pyfunction!(fit_ellipse, m)?)?;
    m.add_function(wrap_pyfunction!(linear_sum_assignment, m)?)?;
    m.add_function(wrap_pyfunction!(assign_with_unassigned, m)?)?;
    Ok(())
}
