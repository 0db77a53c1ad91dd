//! Bindings of `autoteach_detect::cpd` (coherent point drift) and global-CPD; the friendly
//! wrappers live in `python/autoteach/registration.py`.
//!
//! Each function converts its NumPy inputs, calls one core function (without the GIL) and
//! returns a lean frozen result class whose getters build NumPy arrays.

use autoteach_detect::cpd::{
    AffineOptions, AffineResult, CpdOptions, EStep, GlobalCpdOptions, GlobalHypothesis,
    NonrigidOptions, NonrigidResult, RigidOptions, RigidResult, affine, global_cpd as core_global,
    nonrigid, rigid,
};
use autoteach_detect::voting::{VoteCount, VotingOptions};
use nalgebra::{DMatrix, DVector};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

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

/// Result of `cpd_rigid` (`x ≈ s R y + t`); see `autoteach.registration.RigidCpdResult`.
#[pyclass(name = "CpdRigidResult", module = "autoteach._core", frozen)]
pub struct PyCpdRigid {
    inner: RigidResult,
}

#[pymethods]
impl PyCpdRigid {
    /// Rotation `R` (D × D).
    #[getter]
    fn rotation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.rotation)
    }
    /// Translation `t` (D,).
    #[getter]
    fn translation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        vector_out(py, &self.inner.translation)
    }
    /// Scale `s`.
    #[getter]
    fn scale(&self) -> f64 {
        self.inner.scale
    }
    /// The moved Y (M × D).
    #[getter]
    fn transformed<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.transformed)
    }
    /// Final σ².
    #[getter]
    fn sigma2(&self) -> f64 {
        self.inner.sigma2
    }
    /// EM iterations run.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    /// Whether the tolerance was met.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    /// Posterior matrix `P` (M × N) of the last E-step, or `None`.
    #[getter]
    fn p<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f64>>>> {
        self.inner.p.as_ref().map(|p| matrix_out(py, p)).transpose()
    }
}

/// Result of `cpd_affine` (`x ≈ B y + t`).
#[pyclass(name = "CpdAffineResult", module = "autoteach._core", frozen)]
pub struct PyCpdAffine {
    inner: AffineResult,
}

#[pymethods]
impl PyCpdAffine {
    /// Linear part `B` (D × D).
    #[getter]
    fn matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.matrix)
    }
    /// Translation `t` (D,).
    #[getter]
    fn translation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        vector_out(py, &self.inner.translation)
    }
    /// The moved Y (M × D).
    #[getter]
    fn transformed<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.transformed)
    }
    /// Final σ².
    #[getter]
    fn sigma2(&self) -> f64 {
        self.inner.sigma2
    }
    /// EM iterations run.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    /// Whether the tolerance was met.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    /// Posterior matrix `P` (M × N) of the last E-step, or `None`.
    #[getter]
    fn p<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f64>>>> {
        self.inner.p.as_ref().map(|p| matrix_out(py, p)).transpose()
    }
}

/// Result of `cpd_nonrigid` (`T(Y) = Y + G W`).
#[pyclass(name = "CpdNonrigidResult", module = "autoteach._core", frozen)]
pub struct PyCpdNonrigid {
    inner: NonrigidResult,
}

#[pymethods]
impl PyCpdNonrigid {
    /// Kernel weights `W` (M × D).
    #[getter]
    fn w<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.w)
    }
    /// The moved Y (M × D).
    #[getter]
    fn transformed<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.transformed)
    }
    /// Deformation energy `tr(Wᵀ G W)`.
    #[getter]
    fn energy(&self) -> f64 {
        self.inner.energy
    }
    /// Final σ².
    #[getter]
    fn sigma2(&self) -> f64 {
        self.inner.sigma2
    }
    /// EM iterations run.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    /// Whether the tolerance was met.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    /// Eigenpairs used for `G`, or `None` for full rank.
    #[getter]
    fn rank(&self) -> Option<usize> {
        self.inner.rank
    }
    /// Posterior matrix `P` (M × N) of the last E-step, or `None`.
    #[getter]
    fn p<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f64>>>> {
        self.inner.p.as_ref().map(|p| matrix_out(py, p)).transpose()
    }
}

/// Rigid CPD of `y` (M, D) onto `x` (N, D).
#[pyfunction]
#[pyo3(signature = (x, y, w = 0.0, scale = true, max_iterations = 100, tolerance = 1e-3,
    sigma2 = None, e_step = "auto", return_p = false))]
#[allow(clippy::too_many_arguments)]
fn cpd_rigid(
    py: Python<'_>,
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    w: f64,
    scale: bool,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    e_step: &str,
    return_p: bool,
) -> PyResult<PyCpdRigid> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = RigidOptions {
        cpd: cpd_options(w, max_iterations, tolerance, sigma2, e_step, return_p)?,
        scale,
    };
    let inner = convert::detached(py, || rigid(&xm, &ym, &options).map_err(errors::detect))?;
    Ok(PyCpdRigid { inner })
}

/// Affine CPD of `y` (M, D) onto `x` (N, D).
#[pyfunction]
#[pyo3(signature = (x, y, w = 0.0, max_iterations = 100, tolerance = 1e-3, sigma2 = None,
    e_step = "auto", return_p = false))]
#[allow(clippy::too_many_arguments)]
fn cpd_affine(
    py: Python<'_>,
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    w: f64,
    max_iterations: usize,
    tolerance: f64,
    sigma2: Option<f64>,
    e_step: &str,
    return_p: bool,
) -> PyResult<PyCpdAffine> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = AffineOptions {
        cpd: cpd_options(w, max_iterations, tolerance, sigma2, e_step, return_p)?,
    };
    let inner = convert::detached(py, || affine(&xm, &ym, &options).map_err(errors::detect))?;
    Ok(PyCpdAffine { inner })
}

/// Non-rigid CPD of `y` (M, D) onto `x` (N, D).
#[pyfunction]
#[pyo3(signature = (x, y, beta = 2.0, lam = 2.0, low_rank = None, power_iterations = None,
    w = 0.0, max_iterations = 100, tolerance = 1e-3, sigma2 = None, e_step = "auto",
    return_p = false))]
#[allow(clippy::too_many_arguments)]
fn cpd_nonrigid(
    py: Python<'_>,
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
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
) -> PyResult<PyCpdNonrigid> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let options = NonrigidOptions {
        cpd: cpd_options(w, max_iterations, tolerance, sigma2, e_step, return_p)?,
        beta,
        lambda: lam,
        low_rank,
        power_iterations,
    };
    let inner = convert::detached(py, || nonrigid(&xm, &ym, &options).map_err(errors::detect))?;
    Ok(PyCpdNonrigid { inner })
}

/// One hypothesis of `global_cpd`: the rigid initial transform from global voting and the
/// non-rigid CPD run from it.
#[pyclass(name = "GlobalCpdHypothesis", module = "autoteach._core", frozen)]
pub struct PyGlobalHypothesis {
    inner: GlobalHypothesis,
}

#[pymethods]
impl PyGlobalHypothesis {
    /// The rigid initial transform from global voting, as the arrays and counts of
    /// `autoteach_detect::voting::RigidHypothesis`: `(rotation (D, D), translation (D,), votes,
    /// pair_votes)`.
    #[getter]
    fn initial<'py>(&self, py: Python<'py>) -> PyResult<GlobalInitial<'py>> {
        let h = &self.inner.initial;
        Ok((
            matrix_out(py, &h.rotation)?,
            vector_out(py, &h.translation)?,
            h.votes,
            h.pair_votes,
        ))
    }
    /// The non-rigid CPD run from the initial transform (its `energy` ranks the hypotheses).
    #[getter]
    fn cpd(&self) -> PyCpdNonrigid {
        PyCpdNonrigid {
            inner: self.inner.cpd.clone(),
        }
    }
}

/// `(rotation, translation, votes, pair_votes)` of a global-CPD hypothesis's initial transform.
type GlobalInitial<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    usize,
    usize,
);

/// Global-CPD of `y` (M, D) onto `x` (N, D): top-`k` voting hypotheses refined by non-rigid
/// CPD, ranked by deformation energy.
#[pyfunction]
#[pyo3(signature = (x, y, k = 3, beta = 2.0, lam = 2.0, w = 0.5, low_rank = None,
    max_iterations = 100, tolerance = 1e-3, sigma2 = None, neighbours = 10, angle_bin = 0.2,
    translation_bin = None, count = "y", min_votes = 3, max_points = 1000))]
#[allow(clippy::too_many_arguments)]
fn global_cpd(
    py: Python<'_>,
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
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
) -> PyResult<Vec<PyGlobalHypothesis>> {
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
    Ok(hyps
        .into_iter()
        .map(|inner| PyGlobalHypothesis { inner })
        .collect())
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

/// Adds the registration functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCpdRigid>()?;
    m.add_class::<PyCpdAffine>()?;
    m.add_class::<PyCpdNonrigid>()?;
    m.add_function(wrap_pyfunction!(cpd_rigid, m)?)?;
    m.add_function(wrap_pyfunction!(cpd_affine, m)?)?;
    m.add_function(wrap_pyfunction!(cpd_nonrigid, m)?)?;
    m.add_class::<PyGlobalHypothesis>()?;
    m.add_function(wrap_pyfunction!(global_cpd, m)?)?;
    Ok(())
}
