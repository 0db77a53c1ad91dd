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
        let view = self.view();
        // Fast path over contiguous memory; the (slower) indexed walk only runs to report.
        let all_finite = match view.as_slice() {
            Some(s) => s.iter().all(|v| v.is_finite()),
            None => view.iter().all(|v| v.is_finite()),
        };
        if all_finite {
            return Ok(self);
        }
        if let Some((idx, v)) = view.indexed_iter().find(|(_, v)| !v.is_finite()) {
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
                "{} must have shape {}, got {}",
                self.name,
                shape_str(shape),
                shape_str(self.shape())
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

impl Array<'_> {
    /// Requires shape `(..., *item)` (any number of leading dimensions, including none) and
    /// returns the elements in row-major order with the leading shape, so batched results can
    /// be reshaped to `(..., *out_item)`. `expected` spells the shape for the error message,
    /// e.g. `"(..., 4, 4)"`.
    pub fn batch(&self, item: &[usize], expected: &str) -> PyResult<(Vec<f64>, Vec<usize>)> {
        let shape = self.shape();
        if shape.len() < item.len() || shape[shape.len() - item.len()..] != *item {
            return Err(errors::invalid_input(format!(
                "{} must have shape {}, got {}",
                self.name,
                expected,
                shape_str(shape)
            )));
        }
        let lead = shape[..shape.len() - item.len()].to_vec();
        let view = self.view();
        let data = match view.as_slice() {
            // C-contiguous: one copy.
            Some(s) => s.to_vec(),
            // `iter` walks the logical (row-major) order whatever the strides.
            None => view.iter().copied().collect(),
        };
        Ok((data, lead))
    }

    /// The argument name used in error messages.
    pub fn name(&self) -> &'static str {
        self.name
    }
}

/// A shape as Python prints it: `(3,)`, `(2, 2)`, `()`.
pub fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
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
pub const ROTATION_TOL: f64 = 1e-6;

/// `|RᵀR − I|` (Frobenius); NaN when `RᵀR` overflows.
fn orthonormality_defect(r: &nalgebra::Matrix3<f64>) -> f64 {
    (r.transpose() * r - nalgebra::Matrix3::identity()).norm()
}

/// Converts a 3×3 matrix to a rotation, rejecting matrices that are not orthonormal with
/// determinant +1 (to [`ROTATION_TOL`]); NaN or overflowing entries are rejected too.
pub fn matrix_to_rotation(
    r: &nalgebra::Matrix3<f64>,
    name: &str,
) -> PyResult<nalgebra::Rotation3<f64>> {
    let orth = orthonormality_defect(r);
    // Written so that NaN fails: a huge matrix overflows RᵀR to NaN, which must not pass.
    let is_rotation = orth <= ROTATION_TOL && r.determinant() > 0.0;
    if !is_rotation {
        return Err(errors::invalid_input(format!(
            "{name} is not a rotation matrix (|RᵀR − I| = {orth:.3e}, det R = {:.6})",
            r.determinant()
        )));
    }
    // Re-orthonormalise so tiny input errors do not leak into the core.
    Ok(nalgebra::Rotation3::from_matrix(r))
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
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let orth = orthonormality_defect(&r);
    let last_ok =
        (m[(3, 0)].abs() + m[(3, 1)].abs() + m[(3, 2)].abs() + (m[(3, 3)] - 1.0).abs()) <= 1e-9;
    // Written so that NaN fails (see `matrix_to_rotation`).
    let is_rigid = orth <= ROTATION_TOL && r.determinant() > 0.0 && last_ok;
    if !is_rigid {
        return Err(errors::invalid_input(format!(
            "{name} is not a rigid transform (|RᵀR − I| = {orth:.3e}, det R = {:.6}, last row {:?})",
            r.determinant(),
            [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]]
        )));
    }
    let rot = nalgebra::Rotation3::from_matrix(&r);
    let t = nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Ok(nalgebra::Isometry3::from_parts(
        t,
        nalgebra::UnitQuaternion::from_rotation_matrix(&rot),
    ))
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
