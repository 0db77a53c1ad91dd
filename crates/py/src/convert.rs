//! Validation and conversion of every array that crosses the Python boundary.
//!
//! Every function names the argument in its error and states the expected shape. Arrays must
//! be `float64` (the Python wrappers convert other dtypes first), finite, and are read through
//! ndarray views, so non-contiguous inputs are handled without raw-slice access.

use numpy::ndarray::ArrayViewD;
use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::{errors, validate};

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
                Err(_) => format!(
                    "a {}",
                    obj.get_type()
                        .name()
                        .map(|n| n.to_string())
                        .unwrap_or_default()
                ),
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
        validate::finite(&self.view(), self.name).map_err(errors::invalid_input)?;
        Ok(self)
    }

    /// Requires shape `(..., n)`: returns the rows (all leading dimensions flattened) and the
    /// leading shape, so results can be reshaped back for batched calls.
    pub fn rows(&self, n: usize, expected: &str) -> PyResult<(Vec<Vec<f64>>, Vec<usize>)> {
        validate::rows(&self.view(), self.name, n, expected).map_err(errors::invalid_input)
    }

    /// Requires exactly shape `shape` and returns the elements in row-major order.
    pub fn exact(&self, shape: &[usize]) -> PyResult<Vec<f64>> {
        validate::exact(&self.view(), self.name, shape).map_err(errors::invalid_input)
    }

    /// Requires a 1-D array and returns it.
    pub fn vector(&self) -> PyResult<Vec<f64>> {
        validate::vector(&self.view(), self.name).map_err(errors::invalid_input)
    }
}

impl Array<'_> {
    /// Requires shape `(..., *item)` (any number of leading dimensions, including none) and
    /// returns the elements in row-major order with the leading shape, so batched results can
    /// be reshaped to `(..., *out_item)`. `expected` spells the shape for the error message,
    /// e.g. `"(..., 4, 4)"`.
    pub fn batch(&self, item: &[usize], expected: &str) -> PyResult<(Vec<f64>, Vec<usize>)> {
        validate::batch(&self.view(), self.name, item, expected).map_err(errors::invalid_input)
    }

    /// The argument name used in error messages.
    pub fn name(&self) -> &'static str {
        self.name
    }
}

/// A shape as Python prints it: `(3,)`, `(2, 2)`, `()`.
pub fn shape_str(shape: &[usize]) -> String {
    validate::shape_str(shape)
}

/// Reads a finite batch of shape `(..., *item)`: the row-major elements and the leading shape.
pub fn finite_batch(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    item: &[usize],
    expected: &str,
) -> PyResult<(Vec<f64>, Vec<usize>)> {
    finite_array(obj, name)?.batch(item, expected)
}

/// Reads a batch `(..., 4, 4)` of rigid transforms (each checked by [`matrix_to_isometry`]).
pub fn isometries(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
) -> PyResult<(Vec<nalgebra::Isometry3<f64>>, Vec<usize>)> {
    square_batch::<4, _>(obj, name, "(..., 4, 4)", matrix_to_isometry)
}

/// Reads a batch `(..., 3, 3)` of rotation matrices (each checked by [`matrix_to_rotation`]).
pub fn rotations(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
) -> PyResult<(Vec<nalgebra::Rotation3<f64>>, Vec<usize>)> {
    square_batch::<3, _>(obj, name, "(..., 3, 3)", matrix_to_rotation)
}

/// Reads a batch `(..., N, N)` of row-major matrices, each converted by `convert` (an item's
/// error is prefixed with its multi-index when batched).
fn square_batch<const N: usize, T>(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    expected: &str,
    convert: impl Fn(&nalgebra::SMatrix<f64, N, N>, &str) -> PyResult<T>,
) -> PyResult<(Vec<T>, Vec<usize>)> {
    let (data, lead) = finite_batch(obj, name, &[N, N], expected)?;
    let items = data
        .chunks_exact(N * N)
        .enumerate()
        .map(|(i, m)| {
            let mat = nalgebra::SMatrix::<f64, N, N>::from_row_slice(m);
            convert(&mat, name).map_err(|e| with_index(e, name, i, &lead))
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((items, lead))
}

/// Prefixes an error about item `flat` of a batch with its multi-index (when batched).
fn with_index(err: PyErr, name: &str, flat: usize, lead: &[usize]) -> PyErr {
    if lead.is_empty() {
        return err;
    }
    let mut idx = vec![0; lead.len()];
    let mut rest = flat;
    for (k, n) in lead.iter().enumerate().rev() {
        idx[k] = rest % n;
        rest /= n;
    }
    let msg = Python::attach(|py| err.value(py).to_string());
    errors::invalid_input(format!(
        "{name}[{}]: {msg}",
        idx.iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    ))
}

/// Tolerance on `|RᵀR − I|` (Frobenius) for a matrix accepted as a rotation.
pub const ROTATION_TOL: f64 = validate::ROTATION_TOL;

/// Converts a 3×3 matrix to a rotation, rejecting matrices that are not orthonormal with
/// determinant +1 (to [`ROTATION_TOL`]); NaN or overflowing entries are rejected too.
pub fn matrix_to_rotation(
    r: &nalgebra::Matrix3<f64>,
    name: &str,
) -> PyResult<nalgebra::Rotation3<f64>> {
    validate::rotation(r, name).map_err(errors::invalid_input)
}

/// A new float64 NumPy array of `shape` holding `data` in row-major order.
pub fn to_numpy<'py>(
    py: Python<'py>,
    data: Vec<f64>,
    shape: &[usize],
) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
    let arr = numpy::ndarray::ArrayD::from_shape_vec(numpy::ndarray::IxDyn(shape), data)
        .map_err(|e| errors::internal(format!("building an array of shape {shape:?}: {e}")))?;
    Ok(numpy::IntoPyArray::into_pyarray(arr, py))
}

/// `lead` followed by `item`: the shape of a batched result.
pub fn batched_shape(lead: &[usize], item: &[usize]) -> Vec<usize> {
    lead.iter().chain(item).copied().collect()
}

/// Batches with more elements than this release the GIL (see [`run_batched`]).
pub const DETACH_THRESHOLD: usize = 10_000;

/// Runs a batched computation over `elements` scalars: without the GIL (through [`detached`])
/// when the batch is large, holding it (through [`guarded`]) when it is too small for the
/// release to pay off. Either way a panic becomes `InternalError`.
pub fn run_batched<T, F>(py: Python<'_>, elements: usize, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> PyResult<T> + Send,
{
    if elements > DETACH_THRESHOLD {
        detached(py, f)
    } else {
        guarded(f)
    }
}

/// Extracts a finite float64 array in one call.
pub fn finite_array<'py>(obj: &Bound<'py, PyAny>, name: &'static str) -> PyResult<Array<'py>> {
    Array::new(obj, name)?.finite()
}

/// Reads one finite 3×3 matrix (row-major from NumPy).
pub fn matrix3(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<nalgebra::Matrix3<f64>> {
    let values = finite_array(obj, name)?.exact(&[3, 3])?;
    Ok(nalgebra::Matrix3::from_row_slice(&values))
}

/// Reads a finite 4×4 homogeneous rigid transform (rotation orthonormal to 1e-6).
pub fn isometry(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<nalgebra::Isometry3<f64>> {
    let a = finite_array(obj, name)?;
    let m = a.exact(&[4, 4])?;
    let mat = nalgebra::Matrix4::from_row_slice(&m);
    matrix_to_isometry(&mat, name)
}

/// Converts a 4×4 homogeneous matrix to an isometry, rejecting non-rigid matrices.
pub fn matrix_to_isometry(
    m: &nalgebra::Matrix4<f64>,
    name: &str,
) -> PyResult<nalgebra::Isometry3<f64>> {
    validate::isometry(m, name).map_err(errors::invalid_input)
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
