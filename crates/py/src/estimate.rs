//! Bindings of `autoteach_estimate::ukf`: the unscented Kalman filter.
//!
//! * `UkfLinearModel(F, H, B=None)` and `UkfConstantVelocityModel(dim)`: the built-in models
//!   (the fast path: a batch runs entirely in Rust with the GIL released).
//! * `UkfFilter`: one standard or square-root filter, built with `UkfFilter.builtin(model,
//!   …)` or with Python callbacks by `UkfFilter.callbacks(dim_x, dim_z, fx, hx, …)`.
//!   Callbacks are called from Rust holding the GIL; an exception raised by a callback is
//!   re-raised unchanged.
//! * `merwe_sigma_points(x, P, alpha, beta, kappa)` and `merwe_weights(n, alpha, beta, kappa)`.
//! * `family_sigma_points(family, x, P, alpha, beta, kappa)` and `family_weights(family, n,
//!   alpha, beta, kappa)` for `family` in `"merwe"`, `"julier"`, `"simplex"`.
//! * `UkfFilter.rts_smoother(xs, Ps, Qs, dts)`: the unscented RTS smoother on the filter's
//!   model and sigma points (built-in models without the GIL).
//!
//! The friendly filterpy-compatible classes live in `autoteach.estimate`.

use std::sync::{Arc, Mutex, MutexGuard};

use autoteach_estimate::EstimateError;
use autoteach_estimate::ukf::{
    BatchInputs, ConstantVelocityModel, CovariancePolicy, GivenWeights, JulierSigmaPoints,
    LinearModel, MerweScaledSigmaPoints, NoiseForm, SigmaPointFilter, SigmaPoints,
    SimplexSigmaPoints, SquareRootUkf, UkfModel, UnscentedKalmanFilter, rts_smoother,
};
use nalgebra::{DMatrix, DVector, DVectorView};
use numpy::{PyArray1, PyArrayDyn, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{self, to_numpy};
use crate::errors;

mod models;
mod python_model;
mod sigma;
mod ukf_vectorized;

use models::*;
use python_model::*;
use sigma::*;

/// Adds the estimate functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLinearModel>()?;
    m.add_class::<PyCvModel>()?;
    m.add_class::<PyUkf>()?;
    m.add_function(wrap_pyfunction!(merwe_sigma_points, m)?)?;
    m.add_function(wrap_pyfunction!(merwe_weights, m)?)?;
    m.add_function(wrap_pyfunction!(family_sigma_points, m)?)?;
    m.add_function(wrap_pyfunction!(family_weights, m)?)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Conversions
// ---------------------------------------------------------------------------------------------

/// A finite float64 2-D array as a matrix.
fn matrix(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<DMatrix<f64>> {
    let a = convert::finite_array(obj, name)?;
    let shape = a.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must be two-dimensional, got shape {}",
            convert::shape_str(&shape)
        )));
    }
    let data = a.exact(&shape)?;
    Ok(DMatrix::from_row_slice(shape[0], shape[1], &data))
}

/// A finite float64 1-D array as a vector.
fn vector(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<DVector<f64>> {
    Ok(DVector::from_vec(
        convert::finite_array(obj, name)?.vector()?,
    ))
}

/// A vector as a 1-D NumPy array.
fn vec_out<'py>(py: Python<'py>, v: &DVector<f64>) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v.as_slice())
}

/// A matrix as a 2-D NumPy array.
fn mat_out<'py>(py: Python<'py>, m: &DMatrix<f64>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    to_numpy(
        py,
        m.transpose().as_slice().to_vec(),
        &[m.nrows(), m.ncols()],
    )
}

// ---------------------------------------------------------------------------------------------
// The filter
// ---------------------------------------------------------------------------------------------

type DynModel = Arc<dyn UkfModel + Send + Sync>;
type DynFilter = Box<dyn SigmaPointFilter + Send + Sync>;

/// The compiled unscented Kalman filter behind `autoteach.estimate.UnscentedKalmanFilter`.
#[pyclass(name = "UkfFilter", module = "autoteach._core")]
struct PyUkf {
    inner: DynFilter,
    /// Set for callback models: per-call arguments and the last callback exception.
    shared: Option<Arc<Shared>>,
    points: SigmaPoints,
    /// The model (shared with `inner`), for the smoother and the sigma points.
    model: DynModel,
}

/// Builds the engine.
fn build(
    model: DynModel,
    points: SigmaPoints,
    square_root: bool,
    augmented: bool,
    repair: bool,
) -> autoteach_estimate::Result<DynFilter> {
    let noise = if augmented {
        NoiseForm::Augmented
    } else {
        NoiseForm::Additive
    };
    let policy = if repair {
        CovariancePolicy::Repair
    } else {
        CovariancePolicy::Strict
    };
    Ok(if square_root {
        Box::new(
            SquareRootUkf::new(model, points)?
                .with_noise(noise)?
                .with_policy(policy),
        )
    } else {
        Box::new(
            UnscentedKalmanFilter::new(model, points)?
                .with_noise(noise)?
                .with_policy(policy),
        )
    })
}

/// Clears the per-call state when dropped (also on error).
struct CallGuard<'a>(&'a Option<Arc<Shared>>);

impl Drop for CallGuard<'_> {
    fn drop(&mut self) {
        if let Some(s) = self.0 {
            *lock(&s.fx_kwargs) = None;
            *lock(&s.hx_kwargs) = None;
            *lock(&s.fx_override) = None;
            *lock(&s.hx_override) = None;
        }
    }
}

impl PyUkf {
    /// Maps a core error, re-raising the Python exception of a failed callback unchanged.
    fn error(&self, err: EstimateError) -> PyErr {
        if let Some(s) = &self.shared
            && let Some(e) = lock(&s.error).take()
        {
            return e;
        }
        errors::estimate(err)
    }

    fn is_callback(&self) -> bool {
        self.shared.is_some()
    }

    fn set_call(
        &self,
        fx_kwargs: Option<Bound<'_, PyDict>>,
        hx_kwargs: Option<Bound<'_, PyDict>>,
        fx: Option<Bound<'_, PyAny>>,
        hx: Option<Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        match &self.shared {
            Some(s) => {
                *lock(&s.fx_kwargs) = fx_kwargs.map(|k| k.unbind());
                *lock(&s.hx_kwargs) = hx_kwargs.map(|k| k.unbind());
                *lock(&s.fx_override) = fx.map(|k| k.unbind());
                *lock(&s.hx_override) = hx.map(|k| k.unbind());
                *lock(&s.error) = None;
                Ok(())
            }
            None => {
                let has_kwargs = fx_kwargs.is_some_and(|k| !k.is_empty())
                    || hx_kwargs.is_some_and(|k| !k.is_empty());
                if has_kwargs || fx.is_some() || hx.is_some() {
                    return Err(errors::invalid_input(
                        "a filter with a built-in model takes no fx/hx overrides or keyword arguments",
                    ));
                }
                Ok(())
            }
        }
    }
}

#[pymethods]
impl PyUkf {
    /// A filter on a built-in model (`UkfLinearModel` or `UkfConstantVelocityModel`).
    #[staticmethod]
    #[pyo3(signature = (model, alpha, beta, kappa, *, square_root=false, augmented=false, repair=false,
        family_name="merwe"))]
    #[allow(clippy::too_many_arguments)]
    fn builtin(
        model: &Bound<'_, PyAny>,
        alpha: f64,
        beta: f64,
        kappa: f64,
        square_root: bool,
        augmented: bool,
        repair: bool,
        family_name: &str,
    ) -> PyResult<Self> {
        let m: DynModel = if let Ok(m) = model.cast::<PyLinearModel>() {
            Arc::new(m.get().inner.clone())
        } else if let Ok(m) = model.cast::<PyCvModel>() {
            Arc::new(m.get().inner)
        } else {
            return Err(errors::invalid_input(format!(
                "model must be a UkfLinearModel or UkfConstantVelocityModel, got {}",
                model.get_type().name()?
            )));
        };
        let points = family(family_name, m.dim_x(), alpha, beta, kappa)?;
        let inner = build(m.clone(), points.clone(), square_root, augmented, repair)
            .map_err(errors::estimate)?;
        Ok(Self {
            inner,
            shared: None,
            points,
            model: m,
        })
    }

    /// A filter whose model is Python callables (see the module docs for their signatures).
    #[staticmethod]
    #[pyo3(signature = (dim_x, dim_z, fx, hx, alpha, beta, kappa, *, x_mean=None, z_mean=None,
        residual_x=None, residual_z=None, state_add=None, subtract=None, sqrt=None,
        square_root=false, augmented=false, repair=false, dim_w=None, dim_v=None, family_name="merwe",
        draw=None, wm=None, wc=None, vectorized=false))]
    #[allow(clippy::too_many_arguments)]
    fn callbacks(
        dim_x: usize,
        dim_z: usize,
        fx: Bound<'_, PyAny>,
        hx: Bound<'_, PyAny>,
        alpha: f64,
        beta: f64,
        kappa: f64,
        x_mean: Option<Bound<'_, PyAny>>,
        z_mean: Option<Bound<'_, PyAny>>,
        residual_x: Option<Bound<'_, PyAny>>,
        residual_z: Option<Bound<'_, PyAny>>,
        state_add: Option<Bound<'_, PyAny>>,
        subtract: Option<Bound<'_, PyAny>>,
        sqrt: Option<Bound<'_, PyAny>>,
        square_root: bool,
        augmented: bool,
        repair: bool,
        dim_w: Option<usize>,
        dim_v: Option<usize>,
        family_name: &str,
        draw: Option<Bound<'_, PyAny>>,
        wm: Option<&Bound<'_, PyAny>>,
        wc: Option<&Bound<'_, PyAny>>,
        vectorized: bool,
    ) -> PyResult<Self> {
        if vectorized && augmented {
            return Err(errors::invalid_input(
                "vectorized fx/hx need additive noise (the augmented form calls fx(x, dt, w) per sigma point)",
            ));
        }
        if dim_x == 0 || dim_z == 0 {
            return Err(errors::invalid_input(format!(
                "dim_x and dim_z must be positive, got {dim_x} and {dim_z}"
            )));
        }
        for (name, f) in [
            ("fx", Some(&fx)),
            ("hx", Some(&hx)),
            ("x_mean_fn", x_mean.as_ref()),
            ("z_mean_fn", z_mean.as_ref()),
            ("residual_x", residual_x.as_ref()),
            ("residual_z", residual_z.as_ref()),
            ("state_add", state_add.as_ref()),
            ("subtract", subtract.as_ref()),
            ("sqrt_method", sqrt.as_ref()),
            ("sigma_points", draw.as_ref()),
        ] {
            if let Some(f) = f
                && !f.is_callable()
            {
                return Err(errors::invalid_input(format!("{name} must be callable")));
            }
        }
        // An external sigma-point object: its weights, and its `sigma_points` draws.
        let points = match (&draw, wm, wc) {
            (Some(_), Some(wm), Some(wc)) => SigmaPoints::from(
                GivenWeights::new(dim_x, vector(wm, "Wm")?, vector(wc, "Wc")?)
                    .map_err(errors::estimate)?,
            ),
            (None, None, None) => family(family_name, dim_x, alpha, beta, kappa)?,
            _ => {
                return Err(errors::invalid_input(
                    "external sigma points need all of draw, Wm and Wc",
                ));
            }
        };
        let shared = Arc::new(Shared::default());
        let model = PyModel {
            dim_x,
            dim_z,
            dim_w: dim_w.unwrap_or(dim_x),
            dim_v: dim_v.unwrap_or(dim_z),
            fx: fx.unbind(),
            hx: hx.unbind(),
            hooks: Hooks {
                x_mean: x_mean.map(Bound::unbind),
                z_mean: z_mean.map(Bound::unbind),
                residual_x: residual_x.map(Bound::unbind),
                residual_z: residual_z.map(Bound::unbind),
                state_add: state_add.map(Bound::unbind),
                subtract: subtract.map(Bound::unbind),
                sqrt: sqrt.map(Bound::unbind),
                draw: draw.map(Bound::unbind),
                num_sigmas: points.num_sigmas(),
            },
            shared: shared.clone(),
            vectorized,
        };
        let model: DynModel = Arc::new(model);
        let inner = build(
            model.clone(),
            points.clone(),
            square_root,
            augmented,
            repair,
        )
        .map_err(errors::estimate)?;
        Ok(Self {
            inner,
            shared: Some(shared),
            points,
            model,
        })
    }

    /// Sets any of x, P, Q, R (validated: sizes, finiteness, symmetry, definiteness).
    #[pyo3(signature = (x=None, p=None, q=None, r=None))]
    fn set_state(
        &mut self,
        x: Option<&Bound<'_, PyAny>>,
        p: Option<&Bound<'_, PyAny>>,
        q: Option<&Bound<'_, PyAny>>,
        r: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        if let Some(x) = x {
            let x = vector(x, "x")?;
            self.inner.set_x(x).map_err(errors::estimate)?;
        }
        if let Some(p) = p {
            let p = matrix(p, "P")?;
            self.inner.set_p(p).map_err(errors::estimate)?;
        }
        if let Some(q) = q {
            let q = matrix(q, "Q")?;
            self.inner.set_q(q).map_err(errors::estimate)?;
        }
        if let Some(r) = r {
            let r = matrix(r, "R")?;
            self.inner.set_r(r).map_err(errors::estimate)?;
        }
        Ok(())
    }

    /// One prediction over `dt` (optional input `u` for built-in models; keyword arguments
    /// `fx_kwargs` and an `fx` override for callback models).
    #[pyo3(signature = (dt, u=None, fx_kwargs=None, fx=None))]
    fn predict(
        &mut self,
        dt: f64,
        u: Option<&Bound<'_, PyAny>>,
        fx_kwargs: Option<Bound<'_, PyDict>>,
        fx: Option<Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let u = u.map(|u| vector(u, "u")).transpose()?;
        self.set_call(fx_kwargs, None, fx, None)?;
        let _guard = CallGuard(&self.shared);
        let r = convert::guarded(|| Ok(self.inner.predict(dt, u.as_ref())))?;
        r.map_err(|e| self.error(e))
    }

    /// One update with measurement `z` (optional `R` for this update only; `hx_kwargs` and
    /// an `hx` override for callback models).
    #[pyo3(signature = (z, r=None, hx_kwargs=None, hx=None))]
    fn update(
        &mut self,
        z: &Bound<'_, PyAny>,
        r: Option<&Bound<'_, PyAny>>,
        hx_kwargs: Option<Bound<'_, PyDict>>,
        hx: Option<Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let z = vector(z, "z")?;
        let r = r.map(|r| matrix(r, "R")).transpose()?;
        self.set_call(None, hx_kwargs, None, hx)?;
        let _guard = CallGuard(&self.shared);
        let res = convert::guarded(|| Ok(self.inner.update(&z, r.as_ref())))?;
        res.map_err(|e| self.error(e))
    }

    /// Records a missing measurement (posterior = prior).
    fn skip_update(&mut self) {
        self.inner.skip_update();
    }

    /// Runs predict/update over all steps. `zs` is `(n, dim_z)`; `mask` `(n,)` bool marks the
    /// measurements present (default all); `us` `(n, dim_u)`, `dts` `(n,)` and `rs`
    /// `(n, dim_z, dim_z)` are optional. Returns a dict of `xs`, `Ps`, `log_likelihoods` and
    /// (with `priors`) `x_priors`, `P_priors`. Built-in models run without the GIL.
    #[pyo3(signature = (zs, dt, mask=None, us=None, dts=None, rs=None, priors=true))]
    #[allow(clippy::too_many_arguments)]
    fn batch<'py>(
        &mut self,
        py: Python<'py>,
        zs: &Bound<'py, PyAny>,
        dt: f64,
        mask: Option<Vec<bool>>,
        us: Option<&Bound<'py, PyAny>>,
        dts: Option<&Bound<'py, PyAny>>,
        rs: Option<&Bound<'py, PyAny>>,
        priors: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let m = self.inner.dim_z();
        let n = self.inner.dim_x();
        let (zdata, lead) = convert::finite_batch(zs, "zs", &[m], &format!("(n, {m})"))?;
        if lead.len() != 1 {
            return Err(errors::invalid_input(format!(
                "zs must have shape (n, {m}), got {}",
                convert::shape_str(&convert::batched_shape(&lead, &[m]))
            )));
        }
        let steps = lead[0];
        if let Some(mask) = &mask
            && mask.len() != steps
        {
            return Err(errors::invalid_input(format!(
                "mask must have shape ({steps},), got ({},)",
                mask.len()
            )));
        }
        let zs: Vec<Option<DVector<f64>>> = zdata
            .chunks_exact(m)
            .enumerate()
            .map(|(i, z)| {
                mask.as_ref()
                    .is_none_or(|mk| mk[i])
                    .then(|| DVector::from_column_slice(z))
            })
            .collect();
        let us = match us {
            Some(u) => {
                let a = convert::finite_array(u, "us")?;
                let shape = a.shape().to_vec();
                if shape.len() != 2 || shape[0] != steps {
                    return Err(errors::invalid_input(format!(
                        "us must have shape ({steps}, dim_u), got {}",
                        convert::shape_str(&shape)
                    )));
                }
                let data = a.exact(&shape)?;
                Some(
                    data.chunks_exact(shape[1].max(1))
                        .map(DVector::from_column_slice)
                        .collect::<Vec<_>>(),
                )
            }
            None => None,
        };
        let dts = dts
            .map(|d| {
                let (v, lead) = convert::finite_batch(d, "dts", &[], "(n,)")?;
                if lead != [steps] {
                    return Err(errors::invalid_input(format!(
                        "dts must have shape ({steps},), got {}",
                        convert::shape_str(&lead)
                    )));
                }
                Ok(v)
            })
            .transpose()?;
        let rs = rs
            .map(|r| {
                let (v, lead) = convert::finite_batch(r, "Rs", &[m, m], &format!("(n, {m}, {m})"))?;
                if lead != [steps] {
                    return Err(errors::invalid_input(format!(
                        "Rs must have shape ({steps}, {m}, {m}), got {}",
                        convert::shape_str(&convert::batched_shape(&lead, &[m, m]))
                    )));
                }
                Ok(v.chunks_exact(m * m)
                    .map(|c| DMatrix::from_row_slice(m, m, c))
                    .collect::<Vec<_>>())
            })
            .transpose()?;
        let mut inputs = BatchInputs::new(dt, &zs);
        if !priors {
            inputs = inputs.without_priors();
        }
        if let Some(us) = &us {
            inputs = inputs.with_us(us);
        }
        if let Some(d) = &dts {
            inputs = inputs.with_dts(d);
        }
        if let Some(r) = &rs {
            inputs = inputs.with_rs(r);
        }
        self.set_call(None, None, None, None)?;
        let result = if self.is_callback() {
            convert::guarded(|| Ok(self.inner.batch(&inputs)))?
        } else {
            let inner = &mut self.inner;
            convert::detached(py, || Ok(inner.batch(&inputs)))?
        };
        let out = result.map_err(|e| self.error(e))?.into_flat();
        // Covariances are stored column-major: the (steps, n, n) array of that memory holds
        // each matrix transposed, so its axes 1 and 2 are swapped (a view, no copy).
        let matrices = |data: Vec<f64>| -> PyResult<Bound<'py, PyAny>> {
            to_numpy(py, data, &[steps, n, n])?.call_method1("swapaxes", (1, 2))
        };
        let d = PyDict::new(py);
        d.set_item("xs", to_numpy(py, out.xs, &[steps, n])?)?;
        d.set_item("Ps", matrices(out.ps)?)?;
        if priors {
            d.set_item("x_priors", to_numpy(py, out.x_priors, &[steps, n])?)?;
            d.set_item("P_priors", matrices(out.p_priors)?)?;
        }
        d.set_item(
            "log_likelihoods",
            PyArray1::from_vec(py, out.log_likelihoods),
        )?;
        Ok(d)
    }

    /// State dimension.
    #[getter]
    fn dim_x(&self) -> usize {
        self.inner.dim_x()
    }

    /// Measurement dimension.
    #[getter]
    fn dim_z(&self) -> usize {
        self.inner.dim_z()
    }

    /// The state estimate.
    #[getter]
    fn x<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.inner.x())
    }

    /// The covariance.
    #[getter(P)]
    fn p<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, &self.inner.p())
    }

    /// Q.
    #[getter(Q)]
    fn q<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, self.inner.q())
    }

    /// R.
    #[getter(R)]
    fn r<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, self.inner.r())
    }

    /// The state after the last prediction.
    #[getter]
    fn x_prior<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.inner.x_prior())
    }

    /// The covariance after the last prediction.
    #[getter(P_prior)]
    fn p_prior<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, &self.inner.p_prior())
    }

    /// The state after the last update.
    #[getter]
    fn x_post<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.inner.x_post())
    }

    /// The covariance after the last update.
    #[getter(P_post)]
    fn p_post<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, &self.inner.p_post())
    }

    /// The Kalman gain of the last update.
    #[getter(K)]
    fn k<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, self.inner.k())
    }

    /// The innovation of the last update.
    #[getter]
    fn y<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.inner.y())
    }

    /// The innovation covariance of the last update.
    #[getter(S)]
    fn s<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        mat_out(py, &self.inner.s())
    }

    /// The log-likelihood of the last measurement.
    #[getter]
    fn log_likelihood(&self) -> f64 {
        self.inner.log_likelihood()
    }

    /// The number of predictions made.
    #[getter]
    fn step(&self) -> usize {
        self.inner.step()
    }

    /// The number of covariance repairs made (repair policy).
    #[getter]
    fn repairs(&self) -> usize {
        self.inner.repairs()
    }

    /// Sigma points `(N, n)` of (x, P) as this filter draws them (its family, and the
    /// model's `subtract` / `sqrt_method` / external `sigma_points` hooks).
    fn sigma_points<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        p: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let x = vector(x, "x")?;
        let p = matrix(p, "P")?;
        self.set_call(None, None, None, None)?;
        let r = convert::guarded(|| Ok(self.points.draw_with(&self.model, &x, &p)))?;
        let s = r.map_err(|e| self.error(e))?;
        to_numpy(py, s.as_slice().to_vec(), &[s.ncols(), s.nrows()])
    }

    /// The unscented RTS smoother of filtered means `xs` `(n, dim_x)` and covariances `Ps`
    /// `(n, dim_x, dim_x)`, with `Qs` `(dim_x, dim_x)` or `(n, dim_x, dim_x)` and `dts` `(n,)`
    /// (and `us` `(n, dim_u)` for built-in models). Returns `(xs, Ps, Ks)`. Built-in models
    /// run without the GIL.
    #[pyo3(signature = (xs, ps, qs, dts, us=None))]
    #[allow(clippy::type_complexity)]
    fn rts_smoother<'py>(
        &self,
        py: Python<'py>,
        xs: &Bound<'py, PyAny>,
        ps: &Bound<'py, PyAny>,
        qs: &Bound<'py, PyAny>,
        dts: &Bound<'py, PyAny>,
        us: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(
        Bound<'py, PyArrayDyn<f64>>,
        Bound<'py, PyAny>,
        Bound<'py, PyAny>,
    )> {
        let n = self.inner.dim_x();
        let (xd, lead) = convert::finite_batch(xs, "Xs", &[n], &format!("(k, {n})"))?;
        if lead.len() != 1 {
            return Err(errors::invalid_input(format!(
                "Xs must have shape (k, {n}), got {}",
                convert::shape_str(&convert::batched_shape(&lead, &[n]))
            )));
        }
        let steps = lead[0];
        let (pd, plead) =
            convert::finite_batch(ps, "Ps", &[n, n], &format!("({steps}, {n}, {n})"))?;
        if plead != [steps] {
            return Err(errors::invalid_input(format!(
                "Ps must have shape ({steps}, {n}, {n}) (one per mean), got {}",
                convert::shape_str(&convert::batched_shape(&plead, &[n, n]))
            )));
        }
        let (qd, qlead) = convert::finite_batch(qs, "Qs", &[n, n], &format!("({n}, {n})"))?;
        if !(qlead.is_empty() || qlead == [steps]) {
            return Err(errors::invalid_input(format!(
                "Qs must have shape ({n}, {n}) or ({steps}, {n}, {n}), got {}",
                convert::shape_str(&convert::batched_shape(&qlead, &[n, n]))
            )));
        }
        let (dd, dlead) = convert::finite_batch(dts, "dts", &[], "(k,)")?;
        if dlead != [steps] {
            return Err(errors::invalid_input(format!(
                "dts must have shape ({steps},), got {}",
                convert::shape_str(&dlead)
            )));
        }
        let us = match us {
            Some(u) => {
                let a = convert::finite_array(u, "us")?;
                let shape = a.shape().to_vec();
                if shape.len() != 2 || shape[0] != steps {
                    return Err(errors::invalid_input(format!(
                        "us must have shape ({steps}, dim_u), got {}",
                        convert::shape_str(&shape)
                    )));
                }
                let data = a.exact(&shape)?;
                Some(
                    data.chunks_exact(shape[1].max(1))
                        .map(DVector::from_column_slice)
                        .collect::<Vec<_>>(),
                )
            }
            None => None,
        };
        let xv: Vec<DVector<f64>> = xd.chunks_exact(n).map(DVector::from_column_slice).collect();
        let mats = |d: &[f64]| -> Vec<DMatrix<f64>> {
            d.chunks_exact(n * n)
                .map(|c| DMatrix::from_row_slice(n, n, c))
                .collect()
        };
        let (pv, qv) = (mats(&pd), mats(&qd));
        self.set_call(None, None, None, None)?;
        let run = || {
            Ok(rts_smoother(
                &self.model,
                &self.points,
                &xv,
                &pv,
                &qv,
                &dd,
                us.as_deref(),
            ))
        };
        let result = if self.is_callback() {
            convert::guarded(run)?
        } else {
            convert::detached(py, run)?
        };
        let out = result.map_err(|e| self.error(e))?;
        let flat_x: Vec<f64> = out.xs.iter().flat_map(|v| v.iter().copied()).collect();
        // Column-major matrices: swap the last two axes of the (k, n, n) array (a view).
        let mats_out = |m: &[DMatrix<f64>]| -> PyResult<Bound<'py, PyAny>> {
            let flat: Vec<f64> = m.iter().flat_map(|a| a.iter().copied()).collect();
            to_numpy(py, flat, &[steps, n, n])?.call_method1("swapaxes", (1, 2))
        };
        Ok((
            to_numpy(py, flat_x, &[steps, n])?,
            mats_out(&out.ps)?,
            mats_out(&out.ks)?,
        ))
    }

    /// The mean weights of the sigma points.
    #[getter(Wm)]
    fn wm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.points.wm())
    }

    /// The covariance weights of the sigma points.
    #[getter(Wc)]
    fn wc<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.points.wc())
    }
}
