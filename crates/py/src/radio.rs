//! Bindings of `autoteach_estimate::radio`: signal-strength prediction for robot teams (seed
//! 004_815695db12a6b16c.txt ch. 3). The friendly wrapper is `python/autoteach/radio.py`.

use autoteach_estimate::radio::Link;
use autoteach_estimate::radio::grid::{ClassGrid, GridGeometry};
use autoteach_estimate::radio::kernel::{KernelParams, LinkKernel};
use autoteach_estimate::radio::logfit::LogFit;
use autoteach_estimate::radio::matte::{Matte, MatteOptions, MatteWeights};
use autoteach_estimate::radio::mrgp::Mrgp;
use autoteach_estimate::radio::mrt::{Mrt, MrtOptions};
use autoteach_estimate::radio::sim::{self, Environment, EnvironmentKind, RadioParams};
use autoteach_estimate::radio::tomo::{Regularization, TomoRows, TomoSolution};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, Array};
use crate::errors;

type PyArr<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Reads an `(N, 2)` float64 array of points (finiteness is checked by the core, which names
/// the link).
fn points_arg(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<[f64; 2]>> {
    let a = Array::new(obj, name)?;
    let shape = a.shape().to_vec();
    if shape.len() != 2 || shape[1] != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (N, 2), got {}",
            convert::shape_str(&shape)
        )));
    }
    let v = a.view();
    Ok((0..shape[0]).map(|i| [v[[i, 0]], v[[i, 1]]]).collect())
}

/// Reads `tx`, `rx` as `(N, 2)` float64 arrays of equal length.
fn links_arg(tx: &Bound<'_, PyAny>, rx: &Bound<'_, PyAny>) -> PyResult<Vec<Link>> {
    let t = points_arg(tx, "tx")?;
    let r = points_arg(rx, "rx")?;
    if t.len() != r.len() {
        return Err(errors::invalid_input(format!(
            "tx and rx must have the same number of rows, got {} and {}",
            t.len(),
            r.len()
        )));
    }
    Ok(t.into_iter()
        .zip(r)
        .map(|(tx, rx)| Link { tx, rx })
        .collect())
}

fn rss_arg(rss: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    Array::new(rss, "rss")?.vector()
}

fn vec_out<'py>(py: Python<'py>, v: Vec<f64>) -> PyResult<PyArr<'py>> {
    let n = v.len();
    convert::to_numpy(py, v, &[n])
}

/// The stacked least-squares system as `(rows, cols, values, rhs, n_unknowns)`.
type Stacked = (Vec<usize>, Vec<usize>, Vec<f64>, Vec<f64>, usize);

fn stacked(rows: &TomoRows, reg: &Regularization) -> Stacked {
    let (t, rhs) = rows.stacked(reg);
    let (mut r, mut c, mut v) = (Vec::new(), Vec::new(), Vec::new());
    for (a, b, x) in t {
        r.push(a);
        c.push(b);
        v.push(x);
    }
    (r, c, v, rhs, rows.n + 2)
}

fn solution(sol: Option<&TomoSolution>, what: &str) -> PyResult<TomoSolution> {
    sol.cloned()
        .ok_or_else(|| errors::invalid_input(format!("{what}: call solve() (or fit) first")))
}

/// The log-distance fit of eq. 3.1.
#[pyclass(name = "RadioLogFit", module = "autoteach._core", frozen)]
pub struct PyLogFit {
    inner: LogFit,
}

#[pymethods]
impl PyLogFit {
    /// Least-squares fit of `L0` and the exponent.
    #[staticmethod]
    fn fit(tx: &Bound<'_, PyAny>, rx: &Bound<'_, PyAny>, rss: &Bound<'_, PyAny>) -> PyResult<Self> {
        let links = links_arg(tx, rx)?;
        let y = rss_arg(rss)?;
        let inner = convert::guarded(|| LogFit::fit(&links, &y).map_err(errors::estimate))?;
        Ok(Self { inner })
    }

    /// Predictions and predictive variances.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        tx: &Bound<'py, PyAny>,
        rx: &Bound<'py, PyAny>,
    ) -> PyResult<(PyArr<'py>, PyArr<'py>)> {
        let links = links_arg(tx, rx)?;
        let (m, v) = self.inner.predict(&links).map_err(errors::estimate)?;
        Ok((vec_out(py, m)?, vec_out(py, v)?))
    }

    /// Power at 1 m, dBm.
    #[getter]
    fn l0(&self) -> f64 {
        self.inner.l0
    }

    /// Path-loss exponent `a`.
    #[getter]
    fn exponent(&self) -> f64 {
        self.inner.exponent
    }

    /// Residual variance, dB².
    #[getter]
    fn residual_variance(&self) -> f64 {
        self.inner.residual_variance
    }

    /// `(AᵀA)⁻¹` of the regressors `[1, log10 d]`, 2 × 2.
    #[getter]
    fn normal_inverse<'py>(&self, py: Python<'py>) -> PyResult<PyArr<'py>> {
        convert::to_numpy(py, self.inner.normal_inverse.to_vec(), &[2, 2])
    }
}

/// The multi-robot Gaussian process.
#[pyclass(name = "RadioMrgp", module = "autoteach._core")]
pub struct PyMrgp {
    inner: Mrgp,
}

fn kernel_arg(name: &str) -> PyResult<LinkKernel> {
    match name {
        "swap" => Ok(LinkKernel::SwapAverage),
        "ds4" => Ok(LinkKernel::Ds4),
        _ => Err(errors::invalid_input(format!(
            "kernel must be 'swap' or 'ds4', got {name:?}"
        ))),
    }
}

#[pymethods]
impl PyMrgp {
    /// Fits the GP (GIL released).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (tx, rx, rss, kernel="swap", length_scale=28.75, sigma_f=1.0, sigma_d=1.5, theta=20.0, gamma=3.0, optimize=false))]
    fn fit(
        py: Python<'_>,
        tx: &Bound<'_, PyAny>,
        rx: &Bound<'_, PyAny>,
        rss: &Bound<'_, PyAny>,
        kernel: &str,
        length_scale: f64,
        sigma_f: f64,
        sigma_d: f64,
        theta: f64,
        gamma: f64,
        optimize: bool,
    ) -> PyResult<Self> {
        let links = links_arg(tx, rx)?;
        let y = rss_arg(rss)?;
        let kernel = kernel_arg(kernel)?;
        let params = KernelParams {
            length_scale,
            sigma_f,
            sigma_d,
            theta,
            gamma,
        };
        let inner = convert::detached(py, || {
            Mrgp::fit(&links, &y, kernel, params, optimize).map_err(errors::estimate)
        })?;
        Ok(Self { inner })
    }

    /// Adds measurements and refits with the current hyper-parameters.
    fn update(
        &mut self,
        py: Python<'_>,
        tx: &Bound<'_, PyAny>,
        rx: &Bound<'_, PyAny>,
        rss: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let links = links_arg(tx, rx)?;
        let y = rss_arg(rss)?;
        let inner = &mut self.inner;
        convert::detached(py, || inner.update(&links, &y).map_err(errors::estimate))
    }

    /// Means and (with `variance`) latent variances.
    #[pyo3(signature = (tx, rx, variance=false))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        tx: &Bound<'py, PyAny>,
        rx: &Bound<'py, PyAny>,
        variance: bool,
    ) -> PyResult<(PyArr<'py>, Option<PyArr<'py>>)> {
        let links = links_arg(tx, rx)?;
        let inner = &self.inner;
        let (m, v) = convert::detached(py, || {
            inner.predict(&links, variance).map_err(errors::estimate)
        })?;
        let v = match v {
            Some(v) => Some(vec_out(py, v)?),
            None => None,
        };
        Ok((vec_out(py, m)?, v))
    }

    /// Hyper-parameters `{length_scale, sigma_f, sigma_d, theta, gamma}`.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let p = self.inner.params;
        d.set_item("length_scale", p.length_scale)?;
        d.set_item("sigma_f", p.sigma_f)?;
        d.set_item("sigma_d", p.sigma_d)?;
        d.set_item("theta", p.theta)?;
        d.set_item("gamma", p.gamma)?;
        Ok(d)
    }

    /// Log marginal likelihood of the training residuals.
    #[getter]
    fn log_marginal_likelihood(&self) -> f64 {
        self.inner.log_marginal_likelihood()
    }

    /// `(L0, exponent)` of the log-fit mean.
    #[getter]
    fn mean_params(&self) -> (f64, f64) {
        (self.inner.mean.l0, self.inner.mean.exponent)
    }

    /// Stored entries of the lower triangle of K_y and of its Cholesky factor.
    #[getter]
    fn nnz(&self) -> (usize, usize) {
        (self.inner.covariance_nnz(), self.inner.factor_nnz())
    }

    /// Number of training links.
    fn __len__(&self) -> usize {
        self.inner.len()
    }
}

/// The kernel matrix `K_f` between two link sets (dense, for peer comparisons).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (tx_a, rx_a, tx_b, rx_b, kernel="swap", length_scale=28.75, sigma_f=1.0, theta=20.0, gamma=3.0))]
fn radio_link_kernel<'py>(
    py: Python<'py>,
    tx_a: &Bound<'py, PyAny>,
    rx_a: &Bound<'py, PyAny>,
    tx_b: &Bound<'py, PyAny>,
    rx_b: &Bound<'py, PyAny>,
    kernel: &str,
    length_scale: f64,
    sigma_f: f64,
    theta: f64,
    gamma: f64,
) -> PyResult<PyArr<'py>> {
    let a = links_arg(tx_a, rx_a)?;
    let b = links_arg(tx_b, rx_b)?;
    let kernel = kernel_arg(kernel)?;
    let p = KernelParams {
        length_scale,
        sigma_f,
        sigma_d: 1.0,
        theta,
        gamma,
    };
    let (na, nb) = (a.len(), b.len());
    let k = convert::detached(py, || {
        let mut k = Vec::with_capacity(na * nb);
        for la in &a {
            for lb in &b {
                k.push(kernel.eval(
                    &autoteach_estimate::radio::kernel::PairDistances::new(la, lb),
                    &p,
                ));
            }
        }
        Ok(k)
    })?;
    convert::to_numpy(py, k, &[na, nb])
}

/// Multi-robot tomography.
#[pyclass(name = "RadioMrt", module = "autoteach._core")]
pub struct PyMrt {
    inner: Mrt,
}

#[pymethods]
impl PyMrt {
    /// An empty model on the box `(x0, y0, x1, y1)`.
    #[new]
    #[pyo3(signature = (bounds, cell=3.0, lam=0.1375))]
    fn new(bounds: (f64, f64, f64, f64), cell: f64, lam: f64) -> PyResult<Self> {
        let inner = Mrt::new(
            [bounds.0, bounds.1, bounds.2, bounds.3],
            MrtOptions { cell, lambda: lam },
        )
        .map_err(errors::estimate)?;
        Ok(Self { inner })
    }

    /// Appends measurements.
    fn add(
        &mut self,
        tx: &Bound<'_, PyAny>,
        rx: &Bound<'_, PyAny>,
        rss: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let links = links_arg(tx, rx)?;
        let y = rss_arg(rss)?;
        self.inner.add(&links, &y).map_err(errors::estimate)
    }

    /// Solves eq. 3.5 (GIL released); returns the seconds spent. `cold` forgets
    /// the cached symbolic analysis first.
    #[pyo3(signature = (cold=false))]
    fn solve(&mut self, py: Python<'_>, cold: bool) -> PyResult<f64> {
        let inner = &mut self.inner;
        convert::detached(py, || {
            let t = std::time::Instant::now();
            if cold {
                inner.clear_factor_cache();
            }
            inner.solve().map_err(errors::estimate)?;
            Ok(t.elapsed().as_secs_f64())
        })
    }

    /// Predictions.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        tx: &Bound<'py, PyAny>,
        rx: &Bound<'py, PyAny>,
    ) -> PyResult<PyArr<'py>> {
        let links = links_arg(tx, rx)?;
        vec_out(py, self.inner.predict(&links).map_err(errors::estimate)?)
    }

    /// `(L0, exponent, values (rows, cols))` of the last solve.
    fn solution<'py>(&self, py: Python<'py>) -> PyResult<(f64, f64, PyArr<'py>)> {
        let s = solution(self.inner.solution(), "MRT")?;
        let g = self.inner.grid;
        Ok((
            s.l0,
            s.exponent,
            convert::to_numpy(py, s.values, &[g.rows, g.cols])?,
        ))
    }

    /// The stacked least-squares system (COO rows, cols, values; rhs; unknowns).
    fn stacked(&self) -> Stacked {
        stacked(self.inner.rows(), &self.inner.regularization())
    }

    /// Stored entries of the last Cholesky factor.
    #[getter]
    fn factor_nnz(&self) -> usize {
        self.inner.solution().map_or(0, |s| s.factor_nnz)
    }

    /// `(rows, cols)` of the attenuation grid.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.inner.grid.rows, self.inner.grid.cols)
    }

    /// Number of measurement rows.
    fn __len__(&self) -> usize {
        self.inner.rows().len()
    }
}

/// MATTE.
#[pyclass(name = "RadioMatte", module = "autoteach._core")]
pub struct PyMatte {
    inner: Matte,
}

/// Reads a `(H, W)` class array (given as float64 by the wrapper) into a [`ClassGrid`].
fn class_grid(
    classes: &Bound<'_, PyAny>,
    resolution: f64,
    origin: (f64, f64),
) -> PyResult<ClassGrid> {
    let a = convert::finite_array(classes, "occupancy")?;
    let shape = a.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "occupancy must have shape (H, W), got {}",
            convert::shape_str(&shape)
        )));
    }
    let vals: Vec<u8> = a
        .view()
        .iter()
        .map(|&v| {
            if v == v.round() && (0.0..=2.0).contains(&v) {
                v as u8
            } else {
                u8::MAX
            }
        })
        .collect();
    let g = GridGeometry::new(shape[0], shape[1], resolution, [origin.0, origin.1])
        .map_err(errors::estimate)?;
    ClassGrid::new(g, vals).map_err(errors::estimate)
}

#[pymethods]
impl PyMatte {
    /// An empty model on an occupancy grid (`0` free, `1` structure, `2` unknown).
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (occupancy, resolution, origin=(0.0, 0.0), cell=4.0, lam=2.0, phi=0.2, rho_free=-0.1, rho_structure=-0.3, weights="length"))]
    fn new(
        occupancy: &Bound<'_, PyAny>,
        resolution: f64,
        origin: (f64, f64),
        cell: f64,
        lam: f64,
        phi: f64,
        rho_free: f64,
        rho_structure: f64,
        weights: &str,
    ) -> PyResult<Self> {
        let map = class_grid(occupancy, resolution, origin)?;
        let weights = match weights {
            "length" => MatteWeights::Length,
            "indicator" => MatteWeights::Indicator,
            _ => {
                return Err(errors::invalid_input(format!(
                    "weights must be 'length' or 'indicator', got {weights:?}"
                )));
            }
        };
        let opts = MatteOptions {
            cell,
            lambda: lam,
            phi,
            rho_free,
            rho_structure,
            weights,
        };
        let inner = Matte::new(map, opts).map_err(errors::estimate)?;
        Ok(Self { inner })
    }

    /// Appends measurements.
    fn add(
        &mut self,
        tx: &Bound<'_, PyAny>,
        rx: &Bound<'_, PyAny>,
        rss: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let links = links_arg(tx, rx)?;
        let y = rss_arg(rss)?;
        self.inner.add(&links, &y).map_err(errors::estimate)
    }

    /// Solves (Algorithm 3.1; GIL released); returns the seconds spent. `cold` forgets
    /// the cached symbolic analysis first.
    #[pyo3(signature = (cold=false))]
    fn solve(&mut self, py: Python<'_>, cold: bool) -> PyResult<f64> {
        let inner = &mut self.inner;
        convert::detached(py, || {
            let t = std::time::Instant::now();
            if cold {
                inner.clear_factor_cache();
            }
            inner.solve().map_err(errors::estimate)?;
            Ok(t.elapsed().as_secs_f64())
        })
    }

    /// Predictions (Algorithm 3.2 with the exponent).
    fn predict<'py>(
        &self,
        py: Python<'py>,
        tx: &Bound<'py, PyAny>,
        rx: &Bound<'py, PyAny>,
    ) -> PyResult<PyArr<'py>> {
        let links = links_arg(tx, rx)?;
        vec_out(py, self.inner.predict(&links).map_err(errors::estimate)?)
    }

    /// `(L0, exponent, values (3, rows, cols))`: per-class coarse attenuation.
    fn solution<'py>(&self, py: Python<'py>) -> PyResult<(f64, f64, PyArr<'py>)> {
        let s = solution(self.inner.solution(), "MATTE")?;
        let g = self.inner.coarse;
        Ok((
            s.l0,
            s.exponent,
            convert::to_numpy(py, s.values, &[3, g.rows, g.cols])?,
        ))
    }

    /// The fine attenuation map `(H, W)`, dB per metre.
    fn attenuation_map<'py>(&self, py: Python<'py>) -> PyResult<PyArr<'py>> {
        let g = self.inner.map.geometry;
        let m = self.inner.attenuation_map().map_err(errors::estimate)?;
        convert::to_numpy(py, m, &[g.rows, g.cols])
    }

    /// The stacked least-squares system (COO rows, cols, values; rhs; unknowns).
    fn stacked(&self) -> Stacked {
        stacked(self.inner.rows(), &self.inner.regularization())
    }

    /// Stored entries of the last Cholesky factor.
    #[getter]
    fn factor_nnz(&self) -> usize {
        self.inner.solution().map_or(0, |s| s.factor_nnz)
    }

    /// `(rows, cols)` of the coarse grid.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.inner.coarse.rows, self.inner.coarse.cols)
    }

    /// Number of measurement rows.
    fn __len__(&self) -> usize {
        self.inner.rows().len()
    }
}

/// Simulates an environment, a team exploring it and every pair's RSS (see
/// `autoteach_estimate::radio::sim`). Returns a dict of arrays.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (environment, robots=3, duration=240.0, speed=1.0, rate=20.0, seed=0, l0=-40.0, exponent=22.0, sigma=4.0, correlated_share=0.5, correlation_length=6.0, clutter=0.4, lidar_range=20.0))]
fn radio_simulate<'py>(
    py: Python<'py>,
    environment: &str,
    robots: usize,
    duration: f64,
    speed: f64,
    rate: f64,
    seed: u64,
    l0: f64,
    exponent: f64,
    sigma: f64,
    correlated_share: f64,
    correlation_length: f64,
    clutter: f64,
    lidar_range: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let kind = EnvironmentKind::from_name(environment).map_err(errors::estimate)?;
    for (name, v) in [
        ("sigma", sigma),
        ("correlation_length", correlation_length),
        ("lidar_range", lidar_range),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(errors::invalid_input(format!(
                "{name} must be positive, got {v}"
            )));
        }
    }
    if !(0.0..=1.0).contains(&correlated_share)
        || !l0.is_finite()
        || !exponent.is_finite()
        || !clutter.is_finite()
    {
        return Err(errors::invalid_input(
            "correlated_share must be in [0, 1]; l0, exponent, clutter finite",
        ));
    }
    let p = RadioParams {
        l0,
        exponent,
        sigma,
        correlated_share,
        correlation_length,
        clutter,
    };
    let (env, traj, m, obs) = convert::detached(py, || {
        let env = Environment::new(kind, seed);
        let traj = sim::explore(&env, robots, duration, speed, rate, seed.wrapping_add(1))
            .map_err(errors::estimate)?;
        let m = sim::measure(&env, &traj, &p, seed.wrapping_add(2));
        let obs = sim::observe(&env, &traj, lidar_range);
        Ok((env, traj, m, obs))
    })?;
    let g = env.geometry;
    let d = PyDict::new(py);
    let n = m.rss.len();
    d.set_item("name", env.name)?;
    d.set_item("resolution", g.resolution)?;
    d.set_item("origin", (g.origin[0], g.origin[1]))?;
    d.set_item("times", vec_out(py, m.times)?)?;
    let flat = |f: &dyn Fn(&Link) -> [f64; 2]| m.links.iter().flat_map(f).collect::<Vec<f64>>();
    d.set_item("tx", convert::to_numpy(py, flat(&|l| l.tx), &[n, 2])?)?;
    d.set_item("rx", convert::to_numpy(py, flat(&|l| l.rx), &[n, 2])?)?;
    let pairs: Vec<f64> = m
        .pairs
        .iter()
        .flat_map(|p| [p[0] as f64, p[1] as f64])
        .collect();
    d.set_item("pairs", convert::to_numpy(py, pairs, &[n, 2])?)?;
    d.set_item("rss", vec_out(py, m.rss)?)?;
    d.set_item("mean", vec_out(py, m.mean)?)?;
    let shape = [g.rows, g.cols];
    d.set_item("first_seen", convert::to_numpy(py, obs.first_seen, &shape)?)?;
    let solid: Vec<f64> = obs.solid.iter().map(|&s| f64::from(u8::from(s))).collect();
    d.set_item("solid", convert::to_numpy(py, solid, &shape)?)?;
    d.set_item(
        "attenuation",
        convert::to_numpy(py, env.attenuation(&p), &shape)?,
    )?;
    let mat: Vec<f64> = env.material.iter().map(|&v| f64::from(v)).collect();
    d.set_item("material", convert::to_numpy(py, mat, &shape)?)?;
    let r = traj.positions.len();
    let t = traj.times.len();
    let pos: Vec<f64> = traj.positions.iter().flatten().flat_map(|p| *p).collect();
    d.set_item("positions", convert::to_numpy(py, pos, &[r, t, 2])?)?;
    d.set_item("trajectory_times", vec_out(py, traj.times)?)?;
    Ok(d)
}

/// Registers the radio classes and functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLogFit>()?;
    m.add_class::<PyMrgp>()?;
    m.add_class::<PyMrt>()?;
    m.add_class::<PyMatte>()?;
    m.add_function(wrap_pyfunction!(radio_link_kernel, m)?)?;
    m.add_function(wrap_pyfunction!(radio_simulate, m)?)?;
    Ok(())
}
