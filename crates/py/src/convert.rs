//! Validation and conversion of every array that crosses the Python boundary.
//!
//! Every function names the argument in its error and states the expected shape. Arrays must
//! be `float64` (the Python wrappers convert other dtypes first), finite, and are read through
//! ndarray views, so non-contiguous inputs are handled without raw-slice access.

use numpy::ndarray::{ArrayViewD, Axis, Dimension};
use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::errors;

/// A borrowed, validated float64 array of any shape.
pub struct Array<'py> {
    inner: PyReadonlyArrayDyn<'py, f64>,
    name: &'static str,
}

impl<'py> Array<'py> {
    /// Extracts a float64 array, naming `name` in the error for any other type or dtype.
    pub fn new(obj: &Bound<'py, PyAny>, name: &'static str) -> PyResult<Self> {
        let inner = obj.extract::<PyReadonlyArrayDyn<'py, f64>>().map_err(|_| {
            let what = match obj.getattr("dtype") {
                Ok(dt) => format!("an array of dtype {dt}"),
                Err(_) => format!("a {}", obj.get_type().name().map(|n| n.to_string()).unwrap_or_default()),
            };
            errors::invalid_input(format!("{name} must be a float64 NumPy array, got {what}"))
        })?;
        Ok(Self { inner, name })
    }

    /// The shape.
    pub fn shape(&self) -> &[usize] {
        self.inner.shape()
    }

    /// A view of the data.
    pub fn view(&self) -> ArrayViewD<'_, f64> {
        self.inner.as_array()
    }

    /// Fails unless every element is finite.
    pub fn finite(self) -> PyResult<Self> {
        if let Some((idx, v)) = self.view().indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(errors::invalid_input(format!(
                "{} contains a non-finite value {} at index {:?}",
                self.name,
                v,
                idx.slice()
            )));
        }
        Ok(self)
    }

    /// Requires shape `(..., n)`: returns the rows (all leading dimensions flattened) and the
    /// leading shape, so results can be reshaped back for batched calls.
    pub fn rows(&self, n: usize, expected: &str) -> PyResult<(Vec<Vec<f64>>, Vec<usize>)> {
        let shape = self.shape();
        if shape.is_empty() || shape[shape.len() - 1] != n {
            return Err(errors::invalid_input(format!(
                "{} must have shape {}, got {:?}",
                self.name, expected, shape
            )));
        }
        let lead = shape[..shape.len() - 1].to_vec();
        let count: usize = lead.iter().product();
        let v = self.view();
        let flat = v
            .to_shape((count, n))
            .map_err(|e| errors::internal(format!("reshaping {}: {e}", self.name)))?;
        let rows = flat.axis_iter(Axis(0)).map(|r| r.to_vec()).collect();
        Ok((rows, lead))
    }

    /// Requires exactly shape `shape` and returns the elements in row-major order.
    pub fn exact(&self, shape: &[usize]) -> PyResult<Vec<f64>> {
        if self.shape() != shape {
            return Err(errors::invalid_input(format!(
                "{} must have shape {:?}, got {:?}",
                self.name,
                shape,
                self.shape()
            )));
        }
        Ok(self.view().iter().copied().collect())
    }

    /// Requires a 1-D array and returns it.
    pub fn vector(&self) -> PyResult<Vec<f64>> {
        if self.shape().len() != 1 {
            return Err(errors::invalid_input(format!(
                "{} must be one-dimensional, got shape {:?}",
                self.name,
                self.shape()
            )));
        }
        Ok(self.view().iter().copied().collect())
    }
}

/// Extracts a finite float64 array in one call.
pub fn finite_array<'py>(obj: &Bound<'py, PyAny>, name: &'static str) -> PyResult<Array<'py>> {
    Array::new(obj, name)?.finite()
}

/// Reads a finite 4×4 homogeneous rigid transform (rotation orthonormal to 1e-6).
pub fn isometry(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<nalgebra::Isometry3<f64>> {
    let a = finite_array(obj, name)?;
    let m = a.exact(&[4, 4])?;
    let mat = nalgebra::Matrix4::from_row_slice(&m);
    matrix_to_isometry(&mat, name)
}

/// Converts a 4×4 homogeneous matrix to an isometry, rejecting non-rigid matrices.
pub fn matrix_to_isometry(m: &nalgebra::Matrix4<f64>, name: &str) -> PyResult<nalgebra::Isometry3<f64>> {
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let orth = (r.transpose() * r - nalgebra::Matrix3::identity()).norm();
    let last = (m[(3, 0)].abs() + m[(3, 1)].abs() + m[(3, 2)].abs() + (m[(3, 3)] - 1.0).abs()) > 1e-9;
    if orth > 1e-6 || r.determinant() < 0.0 || last {
        return Err(errors::invalid_input(format!(
            "{name} is not a rigid transform (|RᵀR − I| = {orth:.3e}, det R = {:.6}, last row {:?})",
            r.determinant(),
            [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]]
        )));
    }
    let rot = nalgebra::Rotation3::from_matrix(&r);
    let t = nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Ok(nalgebra::Isometry3::from_parts(t, nalgebra::UnitQuaternion::from_rotation_matrix(&rot)))
}

/// Row-major 4×4 of an isometry.
pub fn isometry_rows(t: &nalgebra::Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    let mut out = [[0.0; 4]; 4];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = m[(i, j)];
        }
    }
    out
}

/// Runs `f` without the GIL and converts any panic into `InternalError`, so a Rust panic never
/// crosses into Python. Every long call goes through here.
pub fn detached<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> PyResult<T> + Send,
{
    let out = py.detach(|| std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    match out {
        Ok(r) => r,
        Err(payload) => Err(panic_error(payload.as_ref())),
    }
}

/// Runs `f` (holding the GIL) and converts any panic into `InternalError`.
pub fn guarded<T, F: FnOnce() -> PyResult<T>>(f: F) -> PyResult<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => Err(panic_error(payload.as_ref())),
    }
}

/// `InternalError` carrying a caught panic's message.
fn panic_error(payload: &(dyn std::any::Any + Send)) -> PyErr {
    let msg = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_string());
    errors::internal(format!("internal error (please report): {msg}"))
}
