//! Vectorised Python models of the UKF: `fx(sigmas, dt, **fx_args)` and `hx(sigmas, **hx_args)`
//! receive ALL sigma points at once, as an `(N, n)` array with one point per row, and return
//! `(N, n)` / `(N, m)` (one image per row). One Python call per transform instead of N
//! (seed 000_3b1454b2b2194811.txt §5.2, eqs. 5.1–5.2: the unscented transform propagates every
//! sigma point through the same `f` and `h`; how they are evaluated does not change it).
//!
//! The returned array is validated: its shape must be `(N, len)` (or `(N,)` when `len == 1`),
//! its values real numbers (anything `numpy.asarray(r, float64)` accepts) and finite; a
//! violation raises `InvalidInputError` naming the function, the shape and the offending
//! sigma point.

use nalgebra::{DMatrix, DVector, DVectorView};
use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use super::{PyModel, cloned, sigmas_out};
use crate::{convert, errors};

impl PyModel {
    /// Calls the vectorised `fx` or `hx` (`f`, or the per-call override in `over`) once on
    /// all `sigmas` (`n × N`, points as columns) and writes the images into the columns of
    /// `out` (`len × N`).
    #[allow(clippy::too_many_arguments)]
    fn call_sigmas(
        &self,
        function: &'static str,
        f: &Py<PyAny>,
        over: &std::sync::Mutex<Option<Py<PyAny>>>,
        kwargs: &std::sync::Mutex<Option<Py<PyDict>>>,
        extra: Option<f64>,
        sigmas: &DMatrix<f64>,
        out: &mut DMatrix<f64>,
    ) -> autoteach_estimate::Result<()> {
        let over = cloned(over);
        let kwargs = cloned(kwargs);
        let f = over.as_ref().unwrap_or(f);
        Python::attach(|py| {
            let result = (|| {
                let s = sigmas_out(py, sigmas)?.into_any();
                let args = match extra {
                    Some(dt) => PyTuple::new(py, [s, dt.into_pyobject(py)?.into_any()])?,
                    None => PyTuple::new(py, [s])?,
                };
                let r = f.bind(py).call(args, kwargs.as_ref().map(|k| k.bind(py)))?;
                read_sigmas(py, &r, out, function)
            })();
            result.map_err(|e| self.fail(function, e))
        })
    }

    /// `fx` on all sigma points at once (the columns of `sigmas`).
    pub(super) fn fx_all(
        &self,
        sigmas: &DMatrix<f64>,
        dt: f64,
        out: &mut DMatrix<f64>,
    ) -> autoteach_estimate::Result<()> {
        let s = &self.shared;
        self.call_sigmas(
            "fx",
            &self.fx,
            &s.fx_override,
            &s.fx_kwargs,
            Some(dt),
            sigmas,
            out,
        )
    }

    /// `hx` on all sigma points at once (the columns of `sigmas`).
    pub(super) fn hx_all(
        &self,
        sigmas: &DMatrix<f64>,
        out: &mut DMatrix<f64>,
    ) -> autoteach_estimate::Result<()> {
        let s = &self.shared;
        self.call_sigmas(
            "hx",
            &self.hx,
            &s.hx_override,
            &s.hx_kwargs,
            None,
            sigmas,
            out,
        )
    }

    /// `fx` of one point through the vectorised callback (a `(1, n)` array).
    pub(super) fn fx_one(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        let mut o = DMatrix::zeros(out.len(), 1);
        self.fx_all(
            &DMatrix::from_column_slice(x.len(), 1, x.as_slice()),
            dt,
            &mut o,
        )?;
        out.copy_from(&o.column(0));
        Ok(())
    }

    /// `hx` of one point through the vectorised callback (a `(1, n)` array).
    pub(super) fn hx_one(
        &self,
        x: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        let mut o = DMatrix::zeros(out.len(), 1);
        self.hx_all(
            &DMatrix::from_column_slice(x.len(), 1, x.as_slice()),
            &mut o,
        )?;
        out.copy_from(&o.column(0));
        Ok(())
    }
}

/// Reads the `(N, len)` result `r` of a vectorised callback into the columns of `out`
/// (`len × N`), rejecting a wrong shape and non-finite values.
fn read_sigmas(
    py: Python<'_>,
    r: &Bound<'_, PyAny>,
    out: &mut DMatrix<f64>,
    function: &str,
) -> PyResult<()> {
    let (len, ns) = out.shape();
    let arr = match r.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        Ok(a) => a,
        Err(_) => py
            .import("numpy")?
            .call_method1("asarray", (r, "float64"))?
            .extract::<PyReadonlyArrayDyn<'_, f64>>()?,
    };
    let shape = arr.shape();
    let ok = match shape {
        [rows, cols] => *rows == ns && *cols == len,
        [rows] => len == 1 && *rows == ns,
        _ => false,
    };
    if !ok {
        return Err(errors::invalid_input(format!(
            "{function} (vectorized) returned an array of shape {}, expected ({ns}, {len}): one row per sigma point",
            convert::shape_str(shape)
        )));
    }
    let view = arr.as_array();
    // Row i of the result is sigma point i: column i of `out`. Element k of the row-major
    // iteration is (i, j) = (k / len, k % len).
    for (k, v) in view.iter().enumerate() {
        let (i, j) = (k / len, k % len);
        if !v.is_finite() {
            return Err(errors::invalid_input(format!(
                "{function} (vectorized) returned {v} at row {i} (sigma point {i}), column {j}"
            )));
        }
        out[(j, i)] = *v;
    }
    Ok(())
}
