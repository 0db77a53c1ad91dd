//! Sigma points and their weights: the Merwe scaled, Julier and simplex families
//! (`merwe_sigma_points`, `merwe_weights`, `family_sigma_points`, `family_weights`).

use super::*;

pub(super) fn sigma_points(
    alpha: f64,
    beta: f64,
    kappa: f64,
    n: usize,
) -> PyResult<MerweScaledSigmaPoints> {
    MerweScaledSigmaPoints::new(n, alpha, beta, kappa).map_err(errors::estimate)
}

/// Sigma points `(2n+1, n)` of (x, P) (van der Merwe's scaled points, in filterpy's order).
#[pyfunction]
pub(super) fn merwe_sigma_points<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    p: &Bound<'py, PyAny>,
    alpha: f64,
    beta: f64,
    kappa: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let x = vector(x, "x")?;
    let p = matrix(p, "P")?;
    let pts = sigma_points(alpha, beta, kappa, x.len())?;
    let s = pts.sigma_points(&x, &p).map_err(errors::estimate)?;
    // Columns are the points: the column-major data is the row-major (2n+1, n) array.
    to_numpy(py, s.as_slice().to_vec(), &[s.ncols(), s.nrows()])
}

/// The sigma-point family `family` (`"merwe"`: α, β, κ; `"julier"`: κ; `"simplex"`) for
/// dimension `n`.
pub(super) fn family(
    family: &str,
    n: usize,
    alpha: f64,
    beta: f64,
    kappa: f64,
) -> PyResult<SigmaPoints> {
    let pts: autoteach_estimate::Result<SigmaPoints> = match family {
        "merwe" => MerweScaledSigmaPoints::new(n, alpha, beta, kappa).map(Into::into),
        "julier" => JulierSigmaPoints::new(n, kappa).map(Into::into),
        "simplex" => SimplexSigmaPoints::new(n).map(Into::into),
        other => {
            return Err(errors::invalid_input(format!(
                "family must be 'merwe', 'julier' or 'simplex', got {other:?}"
            )));
        }
    };
    pts.map_err(errors::estimate)
}

/// Sigma points `(N, n)` of (x, P) of a family (in filterpy's order).
#[pyfunction]
#[pyo3(signature = (family_name, x, p, alpha=1.0, beta=0.0, kappa=0.0))]
pub(super) fn family_sigma_points<'py>(
    py: Python<'py>,
    family_name: &str,
    x: &Bound<'py, PyAny>,
    p: &Bound<'py, PyAny>,
    alpha: f64,
    beta: f64,
    kappa: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let x = vector(x, "x")?;
    let p = matrix(p, "P")?;
    let pts = family(family_name, x.len(), alpha, beta, kappa)?;
    let s = pts.sigma_points(&x, &p).map_err(errors::estimate)?;
    to_numpy(py, s.as_slice().to_vec(), &[s.ncols(), s.nrows()])
}

/// The weights `(Wm, Wc)` of a family.
#[pyfunction]
#[pyo3(signature = (family_name, n, alpha=1.0, beta=0.0, kappa=0.0))]
pub(super) fn family_weights<'py>(
    py: Python<'py>,
    family_name: &str,
    n: usize,
    alpha: f64,
    beta: f64,
    kappa: f64,
) -> PyResult<Weights<'py>> {
    let pts = family(family_name, n, alpha, beta, kappa)?;
    Ok((vec_out(py, pts.wm()), vec_out(py, pts.wc())))
}

/// `(Wm, Wc)` as NumPy arrays.
pub(super) type Weights<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// The weights `(Wm, Wc)` of van der Merwe's scaled sigma points.
#[pyfunction]
pub(super) fn merwe_weights<'py>(
    py: Python<'py>,
    n: usize,
    alpha: f64,
    beta: f64,
    kappa: f64,
) -> PyResult<Weights<'py>> {
    let pts = sigma_points(alpha, beta, kappa, n)?;
    Ok((vec_out(py, pts.wm()), vec_out(py, pts.wc())))
}
