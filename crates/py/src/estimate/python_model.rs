//! The UKF model whose `fx` and `hx` are Python callbacks, called from Rust holding the GIL;
//! an exception raised by a callback is re-raised unchanged.

use super::*;

/// Per-call state shared between the filter object and its callback model.
#[derive(Default)]
pub(super) struct Shared {
    pub(super) fx_kwargs: Mutex<Option<Py<PyDict>>>,
    pub(super) hx_kwargs: Mutex<Option<Py<PyDict>>>,
    pub(super) fx_override: Mutex<Option<Py<PyAny>>>,
    pub(super) hx_override: Mutex<Option<Py<PyAny>>>,
    /// The exception raised by the last failing callback (re-raised by the binding).
    pub(super) error: Mutex<Option<PyErr>>,
}

/// Locks a mutex, ignoring poisoning (the data are plain options).
pub(super) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Optional callbacks of the filterpy interface.
#[derive(Default)]
pub(super) struct Hooks {
    pub(super) x_mean: Option<Py<PyAny>>,
    pub(super) z_mean: Option<Py<PyAny>>,
    pub(super) residual_x: Option<Py<PyAny>>,
    pub(super) residual_z: Option<Py<PyAny>>,
    pub(super) state_add: Option<Py<PyAny>>,
    pub(super) subtract: Option<Py<PyAny>>,
    pub(super) sqrt: Option<Py<PyAny>>,
    /// `sigma_points(x, P)` of an external sigma-point object (returns `(N, n)`).
    pub(super) draw: Option<Py<PyAny>>,
    /// N, the number of points `draw` returns.
    pub(super) num_sigmas: usize,
}

/// A [`UkfModel`] whose functions are Python callables, called as filterpy calls them:
/// `fx(x, dt, **fx_args)`, `hx(x, **hx_args)` (augmented form: `fx(x, dt, w, **fx_args)`,
/// `hx(x, v, **hx_args)`), `x_mean_fn(sigmas, Wm)` with `sigmas` of shape `(2n+1, n)`,
/// `residual_x(a, b)`, `state_add(x, dx)`, `subtract(x, -offset)` for the sigma points, and
/// `sqrt_method(M)` returning a matrix whose ROWS are the offsets.
pub(super) struct PyModel {
    pub(super) dim_x: usize,
    pub(super) dim_z: usize,
    pub(super) dim_w: usize,
    pub(super) dim_v: usize,
    pub(super) fx: Py<PyAny>,
    pub(super) hx: Py<PyAny>,
    pub(super) hooks: Hooks,
    pub(super) shared: Arc<Shared>,
    /// `fx`/`hx` take all sigma points at once (`ukf_vectorized`).
    pub(super) vectorized: bool,
}

impl PyModel {
    /// Records a Python error and returns the core error that stops the filter.
    pub(super) fn fail(&self, function: &'static str, err: PyErr) -> EstimateError {
        let message = err.to_string();
        *lock(&self.shared.error) = Some(err);
        EstimateError::Model {
            function,
            step: 0,
            message,
        }
    }

    /// Calls `f(*args, **kwargs)` and writes its result (any array-like of `out.len()`
    /// numbers) into `out`.
    pub(super) fn call(
        &self,
        function: &'static str,
        f: &Py<PyAny>,
        args: impl FnOnce(Python<'_>) -> PyResult<Bound<'_, PyTuple>>,
        kwargs: Option<&Py<PyDict>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        Python::attach(|py| {
            let result = args(py)
                .and_then(|a| f.bind(py).call(a, kwargs.map(|k| k.bind(py))))
                .and_then(|r| read_values(py, &r, out, function));
            result.map_err(|e| self.fail(function, e))
        })
    }
}

/// Writes the values of an array-like `r` (any shape with `out.len()` elements) into `out`.
pub(super) fn read_values(
    py: Python<'_>,
    r: &Bound<'_, PyAny>,
    out: &mut DVector<f64>,
    function: &str,
) -> PyResult<()> {
    let arr = match r.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        Ok(a) => a,
        Err(_) => py
            .import("numpy")?
            .call_method1("asarray", (r, "float64"))?
            .extract::<PyReadonlyArrayDyn<'_, f64>>()?,
    };
    if arr.len() != out.len() {
        return Err(errors::invalid_input(format!(
            "{function} returned an array of shape {}, expected {} values",
            convert::shape_str(arr.shape()),
            out.len()
        )));
    }
    for (o, v) in out.iter_mut().zip(arr.as_array().iter()) {
        *o = *v;
    }
    Ok(())
}

pub(super) fn view_out<'py>(py: Python<'py>, v: DVectorView<'_, f64>) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_iter(py, v.iter().copied())
}

/// `sigmas` (columns are points) as the `(2n+1, n)` array filterpy passes to `x_mean_fn`.
pub(super) fn sigmas_out<'py>(
    py: Python<'py>,
    s: &DMatrix<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    to_numpy(py, s.as_slice().to_vec(), &[s.ncols(), s.nrows()])
}

/// Clones the object held in a per-call slot, if any.
pub(super) fn cloned<T>(slot: &Mutex<Option<Py<T>>>) -> Option<Py<T>> {
    lock(slot)
        .as_ref()
        .map(|f| Python::attach(|py| f.clone_ref(py)))
}

impl PyModel {
    /// Calls the user's `fx` or `hx` (`f`, or the per-call override in `over`) with the
    /// per-call keyword arguments in `kwargs`.
    pub(super) fn call_user(
        &self,
        function: &'static str,
        f: &Py<PyAny>,
        over: &Mutex<Option<Py<PyAny>>>,
        kwargs: &Mutex<Option<Py<PyDict>>>,
        args: impl FnOnce(Python<'_>) -> PyResult<Bound<'_, PyTuple>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        let over = cloned(over);
        let kwargs = cloned(kwargs);
        let f = over.as_ref().unwrap_or(f);
        self.call(function, f, args, kwargs.as_ref(), out)
    }

    /// Calls `fx(x, dt, [w], **fx_args)`.
    pub(super) fn call_fx(
        &self,
        args: impl FnOnce(Python<'_>) -> PyResult<Bound<'_, PyTuple>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        let s = &self.shared;
        self.call_user("fx", &self.fx, &s.fx_override, &s.fx_kwargs, args, out)
    }

    /// Calls `hx(x, [v], **hx_args)`.
    pub(super) fn call_hx(
        &self,
        args: impl FnOnce(Python<'_>) -> PyResult<Bound<'_, PyTuple>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        let s = &self.shared;
        self.call_user("hx", &self.hx, &s.hx_override, &s.hx_kwargs, args, out)
    }

    /// Calls the optional hook `hook(*args)` or, without one, computes `default(out)`.
    pub(super) fn hook(
        &self,
        function: &'static str,
        hook: &Option<Py<PyAny>>,
        default: impl FnOnce(&mut DVector<f64>),
        args: impl FnOnce(Python<'_>) -> PyResult<Bound<'_, PyTuple>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        match hook {
            None => {
                default(out);
                Ok(())
            }
            Some(f) => self.call(function, f, args, None, out),
        }
    }

    /// A weighted mean: `hook(sigmas, wm)` or `sigmas · wm`.
    pub(super) fn mean(
        &self,
        function: &'static str,
        hook: &Option<Py<PyAny>>,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.hook(
            function,
            hook,
            |out| out.gemv(1.0, sigmas, wm, 0.0),
            |py| {
                PyTuple::new(
                    py,
                    [
                        sigmas_out(py, sigmas)?.into_any(),
                        vec_out(py, wm).into_any(),
                    ],
                )
            },
            out,
        )
    }

    /// A residual: `hook(a, b)` or `a - b`.
    pub(super) fn residual(
        &self,
        function: &'static str,
        hook: &Option<Py<PyAny>>,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.hook(
            function,
            hook,
            |out| {
                out.copy_from(&a);
                *out -= b;
            },
            |py| PyTuple::new(py, [view_out(py, a), view_out(py, b)]),
            out,
        )
    }
}

impl UkfModel for PyModel {
    fn dim_x(&self) -> usize {
        self.dim_x
    }

    fn dim_z(&self) -> usize {
        self.dim_z
    }

    fn dim_w(&self) -> usize {
        self.dim_w
    }

    fn dim_v(&self) -> usize {
        self.dim_v
    }

    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        _u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        if self.vectorized {
            return self.fx_one(x, dt, out);
        }
        self.call_fx(
            |py| {
                PyTuple::new(
                    py,
                    [view_out(py, x).into_any(), dt.into_pyobject(py)?.into_any()],
                )
            },
            out,
        )
    }

    fn hx(
        &self,
        x: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        if self.vectorized {
            return self.hx_one(x, out);
        }
        self.call_hx(|py| PyTuple::new(py, [view_out(py, x)]), out)
    }

    fn fx_sigmas(
        &self,
        sigmas: &DMatrix<f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DMatrix<f64>,
    ) -> autoteach_estimate::Result<()> {
        if self.vectorized {
            return self.fx_all(sigmas, dt, out);
        }
        let mut tmp = DVector::zeros(out.nrows());
        for i in 0..sigmas.ncols() {
            self.fx(sigmas.column(i), dt, u, &mut tmp)?;
            out.set_column(i, &tmp);
        }
        Ok(())
    }

    fn hx_sigmas(
        &self,
        sigmas: &DMatrix<f64>,
        out: &mut DMatrix<f64>,
    ) -> autoteach_estimate::Result<()> {
        if self.vectorized {
            return self.hx_all(sigmas, out);
        }
        let mut tmp = DVector::zeros(out.nrows());
        for i in 0..sigmas.ncols() {
            self.hx(sigmas.column(i), &mut tmp)?;
            out.set_column(i, &tmp);
        }
        Ok(())
    }

    fn fx_noise(
        &self,
        x: DVectorView<'_, f64>,
        w: DVectorView<'_, f64>,
        dt: f64,
        _u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.call_fx(
            |py| {
                PyTuple::new(
                    py,
                    [
                        view_out(py, x).into_any(),
                        dt.into_pyobject(py)?.into_any(),
                        view_out(py, w).into_any(),
                    ],
                )
            },
            out,
        )
    }

    fn hx_noise(
        &self,
        x: DVectorView<'_, f64>,
        v: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.call_hx(
            |py| PyTuple::new(py, [view_out(py, x), view_out(py, v)]),
            out,
        )
    }

    fn x_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.mean("x_mean_fn", &self.hooks.x_mean, sigmas, wm, out)
    }

    fn z_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.mean("z_mean_fn", &self.hooks.z_mean, sigmas, wm, out)
    }

    fn x_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.residual("residual_x", &self.hooks.residual_x, a, b, out)
    }

    fn z_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.residual("residual_z", &self.hooks.residual_z, a, b, out)
    }

    fn x_add(
        &self,
        x: DVectorView<'_, f64>,
        dx: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.hook(
            "state_add",
            &self.hooks.state_add,
            |out| {
                out.copy_from(&x);
                *out += dx;
            },
            |py| PyTuple::new(py, [view_out(py, x), view_out(py, dx)]),
            out,
        )
    }

    fn sigma_add(
        &self,
        x: DVectorView<'_, f64>,
        offset: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> autoteach_estimate::Result<()> {
        self.hook(
            "subtract",
            &self.hooks.subtract,
            |out| {
                out.copy_from(&x);
                *out += offset;
            },
            |py| {
                PyTuple::new(
                    py,
                    [
                        view_out(py, x),
                        PyArray1::from_iter(py, offset.iter().map(|v| -v)),
                    ],
                )
            },
            out,
        )
    }

    fn sqrt_cov(
        &self,
        p: &DMatrix<f64>,
        scale: f64,
    ) -> Option<autoteach_estimate::Result<DMatrix<f64>>> {
        let f = self.hooks.sqrt.as_ref()?;
        let n = p.nrows();
        let m = p * scale;
        let mut flat = DVector::zeros(n * n);
        let r = self.call(
            "sqrt_method",
            f,
            |py| PyTuple::new(py, [mat_out(py, &m)?]),
            None,
            &mut flat,
        );
        // The returned rows are the offsets: the row-major data read column-major is the
        // transpose, whose columns are those rows.
        Some(r.map(|()| DMatrix::from_column_slice(n, n, flat.as_slice())))
    }

    fn draw_sigmas(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        out: &mut DMatrix<f64>,
    ) -> Option<autoteach_estimate::Result<()>> {
        let f = self.hooks.draw.as_ref()?;
        let (n, ns) = (x.len(), self.hooks.num_sigmas);
        let mut flat = DVector::zeros(n * ns);
        let r = self.call(
            "sigma_points",
            f,
            |py| PyTuple::new(py, [vec_out(py, x).into_any(), mat_out(py, p)?.into_any()]),
            None,
            &mut flat,
        );
        // The (N, n) row-major result read column-major is n × N with the points as columns.
        Some(r.map(|()| out.copy_from_slice(flat.as_slice())))
    }
}
