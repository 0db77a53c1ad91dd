//! Bindings of `autoteach_detect::cpd` (coherent point drift) and global-CPD; the friendly
//! wrappers live in `python/autoteach/registration.py`.
//!
//! Each function converts its NumPy inputs, calls one core function (without the GIL) and
//! returns the result's fields as a dict keyed by the Rust field names; the result classes are
//! defined once, in Python, and a test pins their fields to the Rust structs.

use autoteach_detect::cpd::{
    AffineOptions, AffineResult, CpdOptions, EStep, GlobalCpdOptions, NonrigidOptions,
    NonrigidResult, RigidOptions, RigidResult, affine, global_cpd as core_global, nonrigid, rigid,
};
use autoteach_detect::voting::{VoteCount, VotingOptions};
use nalgebra::{DMatrix, DVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, Array};
use crate::errors;

/// Reads a point set `(N, D)` as a matrix (finiteness and D are checked by the core, which
/// names the offending index).
pub(crate) fn points_arg(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<DMatrix<f64>> {
    let arr = Array::new(obj, name)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (N, D) with D = 2 or 3, got {}",
            convert::shape_str(&shape)
        )));
    }
    let (data, _) = arr.batch(&[], "(N, D)")?;
    Ok(DMatrix::from_row_slice(shape[0], shape[1], &data))
}

/// A matrix as a row-major NumPy array.
pub(crate) fn matrix_out<'py>(
    py: Python<'py>,
    m: &DMatrix<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let data: Vec<f64> = m.transpose().as_slice().to_vec();
    convert::to_numpy(py, data, &[m.nrows(), m.ncols()])
}

/// A vector as a NumPy array.
pub(crate) fn vector_out<'py>(
    py: Python<'py>,
    v: &DVector<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    convert::to_numpy(py, v.as_slice().to_vec(), &[v.len()])
}

/// Parses the E-step strategy name.
fn e_step_arg(name: &str) -> PyResult<EStep> {
    match name {
        "auto" => Ok(EStep::Auto),
        "dense" => Ok(EStep::Dense),
        "truncated" => Ok(EStep::Truncated),
        "fast_gauss" => Ok(EStep::FastGauss),
        other => Err(errors::invalid_input(format!(
            "e_step must be 'auto', 'dense', 'truncated' or 'fast_gauss', got {other:?}"
        ))),
    }
}

/// The shared options.
fn cpd_options(
    w: f64,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    e_step: &str,
    return_p: bool,
) -> PyResult<CpdOptions> {
    Ok(CpdOptions {
        w,
        max_iterations,
        tolerance,
        sigma2,
        e_step: e_step_arg(e_step)?,
        return_p,
    })
}

/// A CPD result's fields as a dict keyed by the Rust field names (the Python result classes of
/// `autoteach.registration` are built from it, and a test pins their fields to the Rust struct).
fn rigid_dict<'py>(py: Python<'py>, r: &RigidResult) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("rotation", matrix_out(py, &r.rotation)?)?;
    d.set_item("translation", vector_out(py, &r.translation)?)?;
    d.set_item("scale", r.scale)?;
    d.set_item("transformed", matrix_out(py, &r.transformed)?)?;
    em_fields(py, d, r.sigma2, r.iterations, r.converged, &r.p)
}

/// See [`rigid_dict`].
fn affine_dict<'py>(py: Python<'py>, r: &AffineResult) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("matrix", matrix_out(py, &r.matrix)?)?;
    d.set_item("translation", vector_out(py, &r.translation)?)?;
    d.set_item("transformed", matrix_out(py, &r.transformed)?)?;
    em_fields(py, d, r.sigma2, r.iterations, r.converged, &r.p)
}

/// See [`rigid_dict`].
fn nonrigid_dict<'py>(py: Python<'py>, r: &NonrigidResult) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("w", matrix_out(py, &r.w)?)?;
    d.set_item("transformed", matrix_out(py, &r.transformed)?)?;
    d.set_item("energy", r.energy)?;
    d.set_item("rank", r.rank)?;
    em_fields(py, d, r.sigma2, r.iterations, r.converged, &r.p)
}

/// The fields every CPD result shares: the final σ², the EM iterations, convergence and the
/// posterior matrix `P` (M × N) of the last E-step or `None`.
fn em_fields<'py>(
    py: Python<'py>,
    d: Bound<'py, PyDict>,
    sigma2: f64,
    iterations: usize,
    converged: bool,
    p: &Option<DMatrix<f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    d.set_item("sigma2", sigma2)?;
    d.set_item("iterations", iterations)?;
    d.set_item("converged", converged)?;
    d.set_item("p", p.as_ref().map(|p| matrix_out(py, p)).transpose()?)?;
    Ok(d)
}

/// Rigid CPD of `y` (M, D) onto `x` (N, D).
#[pyfunction]
#[pyo3(signature = (x, y, w = 0.0, scale = true, max_iterations = 100, tolerance = 1e-3,
    sigma2 = None, e_step = "auto", return_p = false))]
#[allow(clippy::too_many_arguments)]
fn cpd_rigid<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    w: f64,
    scale: bool,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    e_step: &str,
    return_p: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = RigidOptions {
        cpd: cpd_options(w, max_iterations, tolerance, sigma2, e_step, return_p)?,
        scale,
    };
    let out = convert::detached(py, || rigid(&xm, &ym, &options).map_err(errors::detect))?;
    rigid_dict(py, &out)
}

/// Affine CPD of `y` (M, D) onto `x` (N, D).
#[pyfunction]
#[pyo3(signature = (x, y, w = 0.0, max_iterations = 100, tolerance = 1e-3, sigma2 = None,
    e_step = "auto", return_p = false))]
#[allow(clippy::too_many_arguments)]
fn cpd_affine<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    w: f64,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    e_step: &str,
    return_p: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = AffineOptions {
        cpd: cpd_options(w, max_iterations, tolerance, sigma2, e_step, return_p)?,
    };
    let out = convert::detached(py, || affine(&xm, &ym, &options).map_err(errors::detect))?;
    affine_dict(py, &out)
}

/// Non-rigid CPD of `y` (M, D) onto `x` (N, D).
#[pyfunction]
#[pyo3(signature = (x, y, beta = 2.0, lam = 2.0, low_rank = None, power_iterations = None,
    w = 0.0, max_iterations = 100, tolerance = 1e-3, sigma2 = None, e_step = "auto",
    return_p = false))]
#[allow(clippy::too_many_arguments)]
fn cpd_nonrigid<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    beta: f64,
    lam: f64,
    low_rank: Option<usize>,
    power_iterations: Option<usize>,
    w: f64,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    e_step: &str,
    return_p: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = NonrigidOptions {
        cpd: cpd_options(w, max_iterations, tolerance, sigma2, e_step, return_p)?,
        beta,
        lambda: lam,
        low_rank,
        power_iterations,
    };
    let out = convert::detached(py, || nonrigid(&xm, &ym, &options).map_err(errors::detect))?;
    nonrigid_dict(py, &out)
}

/// Global-CPD of `y` (M, D) onto `x` (N, D): top-`k` voting hypotheses refined by non-rigid
/// CPD, ranked by deformation energy. Each hypothesis is a dict: `initial`, the rigid transform
/// from global voting as `(rotation (D, D), translation (D,), votes, pair_votes)`
/// (`autoteach_detect::voting::RigidHypothesis`), and `cpd`, the non-rigid run from it.
#[pyfunction]
#[pyo3(signature = (x, y, k = 3, beta = 2.0, lam = 2.0, w = 0.5, low_rank = None,
    max_iterations = 100, tolerance = 1e-3, sigma2 = None, neighbours = 10, angle_bin = 0.2,
    translation_bin = None, count = "y", min_votes = 3, max_points = 1000))]
#[allow(clippy::too_many_arguments)]
fn global_cpd<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    k: usize,
    beta: f64,
    lam: f64,
    w: f64,
    low_rank: Option<usize>,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    neighbours: usize,
    angle_bin: f64,
    translation_bin: Option<f64>,
    count: &str,
    min_votes: usize,
    max_points: usize,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = GlobalCpdOptions {
        voting: voting_options(
            neighbours,
            angle_bin,
            translation_bin,
            k,
            count,
            min_votes,
            max_points,
        )?,
        nonrigid: NonrigidOptions {
            cpd: cpd_options(w, max_iterations, tolerance, sigma2, "auto", false)?,
            beta,
            lambda: lam,
            low_rank,
            power_iterations: None,
        },
    };
    let hyps = convert::detached(py, || {
        core_global(&xm, &ym, &options).map_err(errors::detect)
    })?;
    hyps.iter()
        .map(|h| {
            let d = PyDict::new(py);
            let i = &h.initial;
            let initial = (
                matrix_out(py, &i.rotation)?,
                vector_out(py, &i.translation)?,
                i.votes,
                i.pair_votes,
            );
            d.set_item("initial", initial)?;
            d.set_item("cpd", nonrigid_dict(py, &h.cpd)?)?;
            Ok(d)
        })
        .collect()
}

/// The voting options of the global registrations (`count` is `"y"` or `"pairs"`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn voting_options(
    neighbours: usize,
    angle_bin: f64,
    translation_bin: Option<f64>,
    top_k: usize,
    count: &str,
    min_votes: usize,
    max_points: usize,
) -> PyResult<VotingOptions> {
    let count = match count {
        "y" => VoteCount::YCount,
        "pairs" => VoteCount::Pairs,
        other => {
            return Err(errors::invalid_input(format!(
                "count must be 'y' or 'pairs', got {other:?}"
            )));
        }
    };
    Ok(VotingOptions {
        neighbours,
        angle_bin,
        translation_bin,
        top_k,
        count,
        min_votes,
        max_points,
        ..VotingOptions::default()
    })
}

/// Adds the registration functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(cpd_rigid, m)?)?;
    m.add_function(wrap_pyfunction!(cpd_affine, m)?)?;
    m.add_function(wrap_pyfunction!(cpd_nonrigid, m)?)?;
    m.add_function(wrap_pyfunction!(global_cpd, m)?)?;
    Ok(())
}
