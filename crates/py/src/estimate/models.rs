//! The built-in UKF models: `UkfLinearModel` and `UkfConstantVelocityModel` (a batch runs
//! entirely in Rust with the GIL released).

use super::*;

/// The linear model `x' = F x + B u`, `z = H x` (compiled; see `autoteach.estimate`).
#[pyclass(name = "UkfLinearModel", module = "autoteach._core", frozen)]
pub(super) struct PyLinearModel {
    pub(super) inner: LinearModel,
}

#[pymethods]
impl PyLinearModel {
    #[new]
    #[pyo3(signature = (f, h, b=None))]
    pub(super) fn new(
        f: &Bound<'_, PyAny>,
        h: &Bound<'_, PyAny>,
        b: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let f = matrix(f, "F")?;
        let h = matrix(h, "H")?;
        let b = b.map(|b| matrix(b, "B")).transpose()?;
        Ok(Self {
            inner: LinearModel::new(f, h, b).map_err(errors::estimate)?,
        })
    }

    /// State dimension.
    #[getter]
    pub(super) fn dim_x(&self) -> usize {
        self.inner.dim_x()
    }

    /// Measurement dimension.
    #[getter]
    pub(super) fn dim_z(&self) -> usize {
        self.inner.dim_z()
    }

    /// Input dimension (0 without B).
    #[getter]
    pub(super) fn dim_u(&self) -> usize {
        self.inner.dim_u()
    }
}

/// The constant-velocity model in `dim` dimensions (compiled; see `autoteach.estimate`).
#[pyclass(name = "UkfConstantVelocityModel", module = "autoteach._core", frozen)]
pub(super) struct PyCvModel {
    pub(super) inner: ConstantVelocityModel,
}

#[pymethods]
impl PyCvModel {
    #[new]
    pub(super) fn new(dim: usize) -> PyResult<Self> {
        Ok(Self {
            inner: ConstantVelocityModel::new(dim).map_err(errors::estimate)?,
        })
    }

    /// State dimension (2·dim).
    #[getter]
    pub(super) fn dim_x(&self) -> usize {
        self.inner.dim_x()
    }

    /// Measurement dimension (dim).
    #[getter]
    pub(super) fn dim_z(&self) -> usize {
        self.inner.dim_z()
    }

    /// Input dimension (dim: an acceleration).
    #[getter]
    pub(super) fn dim_u(&self) -> usize {
        self.inner.dim_u()
    }
}
