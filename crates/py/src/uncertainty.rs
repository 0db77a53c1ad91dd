//! Bindings of `autoteach_geometry::boxes` (rotated boxes, spatial distributions, JIoU, the
//! car-scan simulator) and `autoteach_detect::uncertainty` (label posterior, eq. 8.12 noise).
//! Names carry the `uncertainty_` prefix; the friendly wrappers live in
//! `python/autoteach/uncertainty.py`. Boxes are rows `[cx, cy, l, w, r]`.

use autoteach_detect::uncertainty::label::{
    LabelOptions, label_uncertainty, posterior_with_correspondences,
};
use autoteach_detect::uncertainty::noise::{NoiseOptions, estimate_noise};
use autoteach_detect::uncertainty::{LabelPosterior, Prior};
use autoteach_geometry::boxes::jiou::{JiouOptions, ProbBox, jiou_batch, probabilistic_jaccard};
use autoteach_geometry::boxes::moments::BoxMoments;
use autoteach_geometry::boxes::scan::{ScanOptions, simulate_cars};
use autoteach_geometry::boxes::spatial::{
    Grid2, Weighting, normal_table, pdq_at, pg_moments_at, rasterize, sampled_on_grid,
};
use autoteach_geometry::boxes::{Box2, Cov5, check_covariance, iou::iou};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

use crate::convert::{self, detached, guarded, to_numpy};
use crate::errors;

type PyArr<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Registers the functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(uncertainty_iou, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_jiou, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_jiou_grid, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_spatial_sampled, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_pg_moments, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_pdq_at, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_point_moments, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_label, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_label_correspondences, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_estimate_noise, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty_simulate_cars, m)?)?;
    Ok(())
}

/// Rows of `(n, 5)` boxes, validated.
fn boxes(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<Box2>> {
    let a = convert::finite_array(obj, name)?;
    let (data, lead) = a.batch(&[5], "(n, 5) rows [cx, cy, l, w, r]")?;
    if lead.len() != 1 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (n, 5), got {}",
            convert::shape_str(a.shape())
        )));
    }
    data.chunks(5)
        .enumerate()
        .map(|(i, y)| {
            Box2::new(y[0], y[1], y[2], y[3], y[4])
                .map_err(|e| errors::invalid_input(format!("{name}[{i}]: {e}")))
        })
        .collect()
}

/// One box `(5,)`.
fn one_box(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Box2> {
    let y = convert::finite_array(obj, name)?.exact(&[5])?;
    Box2::new(y[0], y[1], y[2], y[3], y[4])
        .map_err(|e| errors::invalid_input(format!("{name}: {e}")))
}

fn cov_from(data: &[f64]) -> Cov5 {
    let mut c = [[0.0; 5]; 5];
    for (i, row) in c.iter_mut().enumerate() {
        row.copy_from_slice(&data[5 * i..5 * i + 5]);
    }
    c
}

/// Covariances `(n, 5, 5)`, validated (symmetric PSD).
fn covs(obj: &Bound<'_, PyAny>, name: &'static str, n: usize) -> PyResult<Vec<Cov5>> {
    let a = convert::finite_array(obj, name)?;
    let data = a.exact(&[n, 5, 5])?;
    data.chunks(25)
        .enumerate()
        .map(|(i, d)| {
            let c = cov_from(d);
            check_covariance(&c).map_err(|e| errors::invalid_input(format!("{name}[{i}]: {e}")))?;
            Ok(c)
        })
        .collect()
}

fn one_cov(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Cov5> {
    Ok(covs(&reshape1(obj)?, name, 1)?[0])
}

fn reshape1<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    obj.call_method1("reshape", ((1, 5, 5),))
        .map_err(|_| errors::invalid_input("cov must be a (5, 5) float64 array"))
}

fn points2(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<[f64; 2]>> {
    let a = convert::finite_array(obj, name)?;
    let (data, lead) = a.batch(&[2], "(n, 2)")?;
    if lead.len() != 1 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (n, 2), got {}",
            convert::shape_str(a.shape())
        )));
    }
    Ok(data.chunks(2).map(|p| [p[0], p[1]]).collect())
}

fn grid(g: (f64, f64, f64, f64, usize, usize)) -> PyResult<Grid2> {
    Grid2::new(g.0, g.1, g.2, g.3, g.4, g.5).map_err(errors::geometry)
}

fn weighting(pdq: bool) -> Weighting {
    if pdq {
        Weighting::Indicator
    } else {
        Weighting::Density
    }
}

/// Exact IoU of box rows `a[i]`, `b[i]`.
#[pyfunction]
fn uncertainty_iou<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
) -> PyResult<PyArr<'py>> {
    let (a, b) = (boxes(a, "box_a")?, boxes(b, "box_b")?);
    if a.len() != b.len() {
        return Err(errors::invalid_input(format!(
            "box_a and box_b hold {} and {} boxes",
            a.len(),
            b.len()
        )));
    }
    let out: Vec<f64> = a.iter().zip(&b).map(|(x, y)| iou(x, y)).collect();
    let n = out.len();
    to_numpy(py, out, &[n])
}

/// JIoU (eq. 8.4) of Gaussian boxes `(a_mean[i], a_cov[i])`, `(b_mean[i], b_cov[i])`.
#[pyfunction]
#[pyo3(signature = (a_mean, a_cov, b_mean, b_cov, grid=30, samples=64, seed=0, pdq=false))]
#[allow(clippy::too_many_arguments)]
fn uncertainty_jiou<'py>(
    py: Python<'py>,
    a_mean: &Bound<'py, PyAny>,
    a_cov: &Bound<'py, PyAny>,
    b_mean: &Bound<'py, PyAny>,
    b_cov: &Bound<'py, PyAny>,
    grid: usize,
    samples: usize,
    seed: u64,
    pdq: bool,
) -> PyResult<PyArr<'py>> {
    let am = boxes(a_mean, "box_a")?;
    let bm = boxes(b_mean, "box_b")?;
    if am.len() != bm.len() {
        return Err(errors::invalid_input(format!(
            "box_a and box_b must hold as many boxes, got {} and {}",
            am.len(),
            bm.len()
        )));
    }
    let ac = covs(a_cov, "cov_a", am.len())?;
    let bc = covs(b_cov, "cov_b", bm.len())?;
    let a: Vec<ProbBox> = am
        .iter()
        .zip(&ac)
        .map(|(m, c)| ProbBox { mean: *m, cov: *c })
        .collect();
    let b: Vec<ProbBox> = bm
        .iter()
        .zip(&bc)
        .map(|(m, c)| ProbBox { mean: *m, cov: *c })
        .collect();
    let opts = JiouOptions {
        grid,
        samples,
        seed,
        weighting: weighting(pdq),
    };
    let out = detached(py, || jiou_batch(&a, &b, &opts).map_err(errors::geometry))?;
    let n = out.len();
    to_numpy(py, out, &[n])
}

/// Probabilistic Jaccard index of two distributions on the same samples (eq. 8.4).
#[pyfunction]
fn uncertainty_jiou_grid(p1: &Bound<'_, PyAny>, p2: &Bound<'_, PyAny>) -> PyResult<f64> {
    let a = convert::finite_array(p1, "p1")?;
    let b = convert::finite_array(p2, "p2")?;
    if a.shape() != b.shape() {
        return Err(errors::invalid_input(format!(
            "p1 and p2 must have the same shape, got {} and {}",
            convert::shape_str(a.shape()),
            convert::shape_str(b.shape())
        )));
    }
    let (x, _) = a.batch(&[], "any shape")?;
    let (y, _) = b.batch(&[], "any shape")?;
    guarded(|| probabilistic_jaccard(&x, &y).map_err(errors::geometry))
}

/// Rasterises a mixture of boxes on a grid `(x0, y0, dx, dy, nx, ny)`: `(values (ny, nx), skipped)`.
#[pyfunction]
#[pyo3(signature = (boxes_, weights, grid_, pdq=false))]
fn uncertainty_rasterize<'py>(
    py: Python<'py>,
    boxes_: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
    grid_: (f64, f64, f64, f64, usize, usize),
    pdq: bool,
) -> PyResult<(PyArr<'py>, usize)> {
    let b = boxes(boxes_, "boxes")?;
    let w = convert::finite_array(weights, "weights")?.exact(&[b.len()])?;
    let g = grid(grid_)?;
    let (v, skipped) = guarded(|| rasterize(&b, &w, &g, weighting(pdq)).map_err(errors::geometry))?;
    Ok((to_numpy(py, v, &[g.ny, g.nx])?, skipped))
}

/// Sampled `p_G` (or `P_PDQ`) of a Gaussian box on a grid.
#[pyfunction]
#[pyo3(signature = (mean, cov, grid_, samples=256, seed=0, pdq=false))]
fn uncertainty_spatial_sampled<'py>(
    py: Python<'py>,
    mean: &Bound<'py, PyAny>,
    cov: &Bound<'py, PyAny>,
    grid_: (f64, f64, f64, f64, usize, usize),
    samples: usize,
    seed: u64,
    pdq: bool,
) -> PyResult<PyArr<'py>> {
    let m = one_box(mean, "box")?;
    let c = one_cov(cov, "cov")?;
    let g = grid(grid_)?;
    if samples < 1 {
        return Err(errors::invalid_input("samples must be ≥ 1"));
    }
    let v = detached(py, || {
        sampled_on_grid(&m, &c, &g, &normal_table(samples, seed), weighting(pdq))
            .map_err(errors::geometry)
    })?;
    to_numpy(py, v, &[g.ny, g.nx])
}

/// `p_G(u)` by the Appendix A moment approximation at points `(n, 2)`.
#[pyfunction]
#[pyo3(signature = (mean, cov, points, lattice=20))]
fn uncertainty_pg_moments<'py>(
    py: Python<'py>,
    mean: &Bound<'py, PyAny>,
    cov: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    lattice: usize,
) -> PyResult<PyArr<'py>> {
    let m = one_box(mean, "box")?;
    let c = one_cov(cov, "cov")?;
    let p = points2(points, "points")?;
    let v = detached(py, || {
        pg_moments_at(&m, &c, &p, lattice).map_err(errors::geometry)
    })?;
    let n = v.len();
    to_numpy(py, v, &[n])
}

/// `P_PDQ(u)` (eq. 8.2) at points by Monte Carlo.
#[pyfunction]
#[pyo3(signature = (mean, cov, points, samples=1024, seed=0))]
fn uncertainty_pdq_at<'py>(
    py: Python<'py>,
    mean: &Bound<'py, PyAny>,
    cov: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    samples: usize,
    seed: u64,
) -> PyResult<PyArr<'py>> {
    let m = one_box(mean, "box")?;
    let c = one_cov(cov, "cov")?;
    let p = points2(points, "points")?;
    if samples < 1 {
        return Err(errors::invalid_input("samples must be ≥ 1"));
    }
    let v = detached(py, || {
        pdq_at(&m, &c, &p, &normal_table(samples, seed)).map_err(errors::geometry)
    })?;
    let n = v.len();
    to_numpy(py, v, &[n])
}

/// Moments of `V(v₀, Y)` (Appendix A) at unit-box points `(n, 2)`: `(means (n, 2), covs (n, 2, 2))`.
#[pyfunction]
fn uncertainty_point_moments<'py>(
    py: Python<'py>,
    mean: &Bound<'py, PyAny>,
    cov: &Bound<'py, PyAny>,
    v0: &Bound<'py, PyAny>,
) -> PyResult<(PyArr<'py>, PyArr<'py>)> {
    let m = one_box(mean, "box")?;
    let c = one_cov(cov, "cov")?;
    let p = points2(v0, "v0")?;
    let mom = BoxMoments::new(&m, &c);
    let mut means = Vec::with_capacity(2 * p.len());
    let mut cs = Vec::with_capacity(4 * p.len());
    for q in &p {
        let (a, b) = mom.point(*q);
        means.extend(a);
        cs.extend(b.iter().flatten());
    }
    Ok((
        to_numpy(py, means, &[p.len(), 2])?,
        to_numpy(py, cs, &[p.len(), 2, 2])?,
    ))
}

fn prior(prior_cov: Option<&Bound<'_, PyAny>>) -> PyResult<Prior> {
    match prior_cov {
        None => Ok(Prior::Flat),
        Some(c) => Ok(Prior::Gaussian(one_cov(c, "prior_cov")?)),
    }
}

/// The fields of a [`LabelPosterior`]: `(mean (5,), cov (5, 5), precision (5, 5), sigma, points)`.
type PosteriorOut<'py> = (PyArr<'py>, PyArr<'py>, PyArr<'py>, f64, usize);

fn posterior_out<'py>(py: Python<'py>, p: LabelPosterior) -> PyResult<PosteriorOut<'py>> {
    Ok((
        to_numpy(py, p.mean.to_vec(), &[5])?,
        to_numpy(py, p.cov.iter().flatten().copied().collect(), &[5, 5])?,
        to_numpy(py, p.precision.iter().flatten().copied().collect(), &[5, 5])?,
        p.sigma,
        p.points,
    ))
}

/// Label posterior (eq. 8.10–8.11): the fields of `LabelPosterior` (see [`posterior_out`]).
#[pyfunction]
#[pyo3(signature = (label, points, sigma, prior_cov=None, spacing=0.5, estimate_heading=true))]
fn uncertainty_label<'py>(
    py: Python<'py>,
    label: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    sigma: f64,
    prior_cov: Option<&Bound<'py, PyAny>>,
    spacing: f64,
    estimate_heading: bool,
) -> PyResult<PosteriorOut<'py>> {
    let b = one_box(label, "label")?;
    let p = points2(points, "points")?;
    let opts = LabelOptions {
        sigma,
        prior: prior(prior_cov)?,
        spacing,
        estimate_heading,
        ..Default::default()
    };
    let post = detached(py, || {
        label_uncertainty(&b, &p, &opts).map_err(errors::detect)
    })?;
    posterior_out(py, post)
}

/// Label posterior with known correspondences (Fig. 8.6): the fields of `LabelPosterior`.
#[pyfunction]
#[pyo3(signature = (label, points, v0, sigma, prior_cov=None, estimate_heading=true))]
fn uncertainty_label_correspondences<'py>(
    py: Python<'py>,
    label: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    v0: &Bound<'py, PyAny>,
    sigma: f64,
    prior_cov: Option<&Bound<'py, PyAny>>,
    estimate_heading: bool,
) -> PyResult<PosteriorOut<'py>> {
    let b = one_box(label, "label")?;
    let p = points2(points, "points")?;
    let v = points2(v0, "v0")?;
    let pr = prior(prior_cov)?;
    let post = guarded(|| {
        posterior_with_correspondences(&b, &p, &v, sigma, &pr, estimate_heading)
            .map_err(errors::detect)
    })?;
    posterior_out(py, post)
}

/// Eq. 8.12 pooled over objects: `(sigma, iterations, history)`.
#[pyfunction]
#[pyo3(signature = (labels, points, counts, sigma0=0.5, tolerance=1e-8, max_iterations=200))]
fn uncertainty_estimate_noise<'py>(
    py: Python<'py>,
    labels: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    counts: Vec<usize>,
    sigma0: f64,
    tolerance: f64,
    max_iterations: usize,
) -> PyResult<(f64, usize, PyArr<'py>)> {
    let b = boxes(labels, "labels")?;
    let p = points2(points, "points")?;
    if counts.len() != b.len() || counts.iter().sum::<usize>() != p.len() {
        return Err(errors::invalid_input(format!(
            "counts must have one entry per label ({}) summing to the number of points ({}), got {} entries summing to {}",
            b.len(),
            p.len(),
            counts.len(),
            counts.iter().sum::<usize>()
        )));
    }
    let mut objs = Vec::with_capacity(b.len());
    let mut start = 0;
    for (lb, &n) in b.iter().zip(&counts) {
        objs.push((*lb, &p[start..start + n]));
        start += n;
    }
    let opts = NoiseOptions {
        sigma0,
        tolerance,
        max_iterations,
        ..Default::default()
    };
    let est = detached(py, || estimate_noise(&objs, &opts).map_err(errors::detect))?;
    let n = est.history.len();
    Ok((est.sigma, est.iterations, to_numpy(py, est.history, &[n])?))
}

/// Simulated car scans: `(labels (n, 5), points (k, 2), counts (n,))`.
#[pyfunction]
#[pyo3(signature = (n, sigma=0.2, seed=0, occlusion=0.3, max_occluded=0.5, azimuth_step_deg=0.2, min_points=10, range=(6.0, 30.0)))]
#[allow(clippy::too_many_arguments)]
fn uncertainty_simulate_cars<'py>(
    py: Python<'py>,
    n: usize,
    sigma: f64,
    seed: u64,
    occlusion: f64,
    max_occluded: f64,
    azimuth_step_deg: f64,
    min_points: usize,
    range: (f64, f64),
) -> PyResult<(PyArr<'py>, PyArr<'py>, Vec<usize>)> {
    let opts = ScanOptions {
        sigma,
        occlusion,
        max_occluded,
        azimuth_step: azimuth_step_deg.to_radians(),
        range,
        ..Default::default()
    };
    let cars = detached(py, || {
        simulate_cars(n, &opts, min_points, seed).map_err(errors::geometry)
    })?;
    let labels: Vec<f64> = cars.iter().flat_map(|(b, _)| b.params()).collect();
    let pts: Vec<f64> = cars
        .iter()
        .flat_map(|(_, p)| p.iter().flatten().copied())
        .collect();
    let counts: Vec<usize> = cars.iter().map(|(_, p)| p.len()).collect();
    let k = pts.len() / 2;
    Ok((
        to_numpy(py, labels, &[cars.len(), 5])?,
        to_numpy(py, pts, &[k, 2])?,
        counts,
    ))
}
