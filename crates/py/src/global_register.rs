//! Binding of `autoteach_detect::cpd::global_register` (issue 29); the friendly wrapper is
//! `autoteach.registration.global_register`.

use autoteach_detect::cpd::{
    Criterion, GlobalRegisterOptions, GlobalRegistration, RegistrationCandidate, global_register,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

use crate::convert;
use crate::errors;
use crate::registration::{matrix_out, points_arg, vector_out, voting_options};

/// Result of `global_register`: candidates, symmetries and the final rigid (and optional
/// non-rigid) CPD.
#[pyclass(name = "GlobalRegistration", module = "autoteach._core", frozen)]
pub struct PyGlobalRegistration {
    inner: GlobalRegistration,
}

/// `(rotation, translation, sigma2, explained, log_likelihood, energy, equivalent,
/// initial_rotation, initial_translation, votes, pair_votes)` of one candidate.
type CandidateTuple<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    f64,
    f64,
    f64,
    Option<f64>,
    bool,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    usize,
    usize,
);

fn candidate<'py>(py: Python<'py>, c: &RegistrationCandidate) -> PyResult<CandidateTuple<'py>> {
    Ok((
        matrix_out(py, &c.rotation)?,
        vector_out(py, &c.translation)?,
        c.sigma2,
        c.explained,
        c.log_likelihood,
        c.energy,
        c.equivalent,
        matrix_out(py, &c.initial.rotation)?,
        vector_out(py, &c.initial.translation)?,
        c.initial.votes,
        c.initial.pair_votes,
    ))
}

#[pymethods]
impl PyGlobalRegistration {
    /// Candidates, best first (see `CandidateTuple`).
    #[getter]
    fn candidates<'py>(&self, py: Python<'py>) -> PyResult<Vec<CandidateTuple<'py>>> {
        self.inner
            .candidates
            .iter()
            .map(|c| candidate(py, c))
            .collect()
    }
    /// Template symmetries `(R, t)`.
    #[getter]
    #[allow(clippy::type_complexity)]
    fn symmetries<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Vec<(Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<f64>>)>> {
        self.inner
            .symmetries
            .iter()
            .map(|(r, t)| Ok((matrix_out(py, r)?, vector_out(py, t)?)))
            .collect()
    }
    /// Several poses explain the scene equally well (the template has a symmetry).
    #[getter]
    fn ambiguous(&self) -> bool {
        self.inner.ambiguous
    }
    /// Inlier radius of the scores.
    #[getter]
    fn inlier_radius(&self) -> f64 {
        self.inner.inlier_radius
    }
    /// Common σ̂² of the scores.
    #[getter]
    fn sigma2(&self) -> f64 {
        self.inner.sigma2
    }
    /// Final rigid CPD: `(rotation, translation, transformed, sigma2)`.
    #[getter]
    #[allow(clippy::type_complexity)]
    fn rigid<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArrayDyn<f64>>,
        Bound<'py, PyArrayDyn<f64>>,
        Bound<'py, PyArrayDyn<f64>>,
        f64,
    )> {
        let r = &self.inner.rigid;
        Ok((
            matrix_out(py, &r.rotation)?,
            vector_out(py, &r.translation)?,
            matrix_out(py, &r.transformed)?,
            r.sigma2,
        ))
    }
    /// Final non-rigid CPD `(transformed, energy)`, if run.
    #[getter]
    fn nonrigid<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<(Bound<'py, PyArrayDyn<f64>>, f64)>> {
        match &self.inner.nonrigid {
            Some(n) => Ok(Some((matrix_out(py, &n.transformed)?, n.energy))),
            None => Ok(None),
        }
    }
}

/// Global registration of `y` (M, D) into `x` (N, D) (issue 29; seed §3.4).
#[pyfunction]
#[pyo3(name = "global_register", signature = (x, y, k = 8, criterion = "explained", count = "y", w = 0.5,
    max_iterations = 10, max_refine_points = 100, window = 0.25, energy_all = false,
    nonrigid = false, beta = 2.0, lam = 2.0, symmetry_fraction = 0.9, neighbours = 10,
    angle_bin = 0.2, translation_bin = None, min_votes = 3, max_points = 200))]
#[allow(clippy::too_many_arguments)]
fn global_register_py(
    py: Python<'_>,
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    k: usize,
    criterion: &str,
    count: &str,
    w: f64,
    max_iterations: usize,
    max_refine_points: usize,
    window: f64,
    energy_all: bool,
    nonrigid: bool,
    beta: f64,
    lam: f64,
    symmetry_fraction: f64,
    neighbours: usize,
    angle_bin: f64,
    translation_bin: Option<f64>,
    min_votes: usize,
    max_points: usize,
) -> PyResult<PyGlobalRegistration> {
    let (xm, ym) = (points_arg(x, "X")?, points_arg(y, "Y")?);
    let criterion = match criterion {
        "explained" => Criterion::Explained,
        "likelihood" => Criterion::Likelihood,
        "energy" => Criterion::Energy,
        other => {
            return Err(errors::invalid_input(format!(
                "criterion must be 'explained', 'likelihood' or 'energy', got {other:?}"
            )));
        }
    };
    let mut options = GlobalRegisterOptions {
        voting: voting_options(
            neighbours,
            angle_bin,
            translation_bin,
            k,
            count,
            min_votes,
            max_points,
        )?,
        w,
        max_iterations,
        max_refine_points,
        window,
        criterion,
        energy_all,
        final_nonrigid: nonrigid,
        symmetry_fraction,
        ..GlobalRegisterOptions::default()
    };
    options.nonrigid.beta = beta;
    options.nonrigid.lambda = lam;
    options.nonrigid.cpd.w = w;
    let inner = convert::detached(py, || {
        global_register(&xm, &ym, &options).map_err(errors::detect)
    })?;
    Ok(PyGlobalRegistration { inner })
}

/// Adds `global_register` and its result class to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyGlobalRegistration>()?;
    m.add_function(wrap_pyfunction!(global_register_py, m)?)?;
    Ok(())
}
