//! Bindings of `autoteach_estimate::calib`: guided camera calibration with Max ERE
//! (seed 004_815695db12a6b16c.txt ch. 5). The friendly wrapper is `python/autoteach/calib.py`.

use std::str::FromStr;

use autoteach_estimate::EstimateError;
use autoteach_estimate::calib::View;
use autoteach_estimate::calib::ere::{GRID_MARGIN, test_grid_with_margin};
use autoteach_estimate::calib::guide::{
    candidate_poses, first_view_pose, novice_poses, random_poses, synthesize_view_seeded,
};
use autoteach_estimate::calib::solve::{
    CalibOptions, Calibration, RobustLoss, calibrate, select_model,
};
use autoteach_geometry::camera::{Camera, CameraModel};
use nalgebra::{DMatrix, Isometry3};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, Array};
use crate::errors;

/// Maps calibration errors: degenerate data → `DegenerateGeometryError`, too few points →
/// `InvalidInputError`, everything else as the estimation crate's mapping.
fn calib_err(err: EstimateError) -> PyErr {
    match err {
        EstimateError::DegenerateCalibration(_) | EstimateError::RankDeficient { .. } => {
            errors::new_err(errors::Class::DegenerateGeometry, err.to_string())
        }
        EstimateError::TooFewPoints { .. } => errors::invalid_input(err.to_string()),
        other => errors::estimate(other),
    }
}

/// Test pixels of the Max ERE: a `grid × grid` grid with the outer ring `margin` (fraction of
/// the image size) inside the border; `None` for the default [`GRID_MARGIN`].
fn grid_pixels(camera: &Camera, grid: usize, margin: Option<f64>) -> PyResult<Vec<[f64; 2]>> {
    let m = margin.unwrap_or(GRID_MARGIN);
    if !(m.is_finite() && (0.0..0.5).contains(&m)) {
        return Err(errors::invalid_input(format!(
            "grid_margin must be in [0, 0.5), got {m}"
        )));
    }
    Ok(test_grid_with_margin(
        camera.width(),
        camera.height(),
        grid,
        m,
    ))
}

fn model_arg(name: &str) -> PyResult<CameraModel> {
    CameraModel::from_str(name).map_err(errors::geometry)
}

/// Reads an `(N, cols)` float64 array (NaN allowed: missing points) as rows.
fn rows<const C: usize>(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    view: usize,
) -> PyResult<Vec<[f64; C]>> {
    let arr = Array::new(obj, name)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 || shape[1] != C {
        return Err(errors::invalid_input(format!(
            "{name}[{view}] must have shape (N, {C}), got {}",
            convert::shape_str(&shape)
        )));
    }
    let v = arr.view();
    Ok((0..shape[0])
        .map(|i| std::array::from_fn(|k| v[[i, k]]))
        .collect())
}

fn read_views(
    object_points: &[Bound<'_, PyAny>],
    image_points: &[Bound<'_, PyAny>],
) -> PyResult<Vec<View>> {
    if object_points.len() != image_points.len() {
        return Err(errors::invalid_input(format!(
            "object_points has {} views but image_points has {}",
            object_points.len(),
            image_points.len()
        )));
    }
    object_points
        .iter()
        .zip(image_points)
        .enumerate()
        .map(|(i, (o, p))| {
            let o = rows::<3>(o, "object_points", i)?;
            let p = rows::<2>(p, "image_points", i)?;
            View::new(i, &o, &p).map_err(calib_err)
        })
        .collect()
}

fn target_arg(obj: &Bound<'_, PyAny>) -> PyResult<Vec<[f64; 2]>> {
    let arr = convert::finite_array(obj, "target")?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 || shape[1] != 2 {
        return Err(errors::invalid_input(format!(
            "target must have shape (N, 2), got {}",
            convert::shape_str(&shape)
        )));
    }
    let v = arr.view();
    Ok((0..shape[0]).map(|i| [v[[i, 0]], v[[i, 1]]]).collect())
}

fn camera_arg(model: &str, params: &Bound<'_, PyAny>, width: u32, height: u32) -> PyResult<Camera> {
    let p = convert::finite_array(params, "params")?.vector()?;
    Camera::new(model_arg(model)?, &p, width, height).map_err(errors::geometry)
}

fn poses_arg(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<Isometry3<f64>>> {
    let arr = convert::finite_array(obj, name)?;
    let (data, lead) = arr.batch(&[4, 4], "(K, 4, 4)")?;
    let k: usize = lead.iter().product();
    (0..k)
        .map(|i| {
            let m = nalgebra::Matrix4::from_row_slice(&data[16 * i..16 * (i + 1)]);
            convert::matrix_to_isometry(&m, name)
        })
        .collect()
}

fn poses_out<'py>(
    py: Python<'py>,
    poses: &[Isometry3<f64>],
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let data: Vec<f64> = poses
        .iter()
        .flat_map(|p| convert::isometry_rows(p).into_iter().flatten())
        .collect();
    convert::to_numpy(py, data, &[poses.len(), 4, 4])
}

fn matrix_out<'py>(py: Python<'py>, m: &DMatrix<f64>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    convert::to_numpy(
        py,
        m.transpose().as_slice().to_vec(),
        &[m.nrows(), m.ncols()],
    )
}

/// A calibration (`autoteach._core.CalibResult`); see `autoteach.calib.Calibration`.
#[pyclass(name = "CalibResult", module = "autoteach._core", frozen)]
pub struct PyCalibResult {
    inner: Calibration,
}

#[pymethods]
impl PyCalibResult {
    /// Rebuilds a calibration from its parts (used when loading JSON).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (model, params, width, height, covariance, free, poses, object_points, image_points, sigma_z))]
    fn from_parts(
        py: Python<'_>,
        model: &str,
        params: &Bound<'_, PyAny>,
        width: u32,
        height: u32,
        covariance: &Bound<'_, PyAny>,
        free: Vec<bool>,
        poses: &Bound<'_, PyAny>,
        object_points: Vec<Bound<'_, PyAny>>,
        image_points: Vec<Bound<'_, PyAny>>,
        sigma_z: f64,
    ) -> PyResult<Self> {
        let camera = camera_arg(model, params, width, height)?;
        let n = camera.params().len();
        let cov = convert::finite_array(covariance, "covariance")?.exact(&[n, n])?;
        if free.len() != n {
            return Err(errors::invalid_input(format!(
                "free must have {n} entries, got {}",
                free.len()
            )));
        }
        let poses = poses_arg(poses, "poses")?;
        let views = read_views(&object_points, &image_points)?;
        if poses.len() != views.len() {
            return Err(errors::invalid_input(format!(
                "{} poses for {} views",
                poses.len(),
                views.len()
            )));
        }
        let _ = py;
        let errs = Calibration::reprojection_rms(&camera, &views, &poses).map_err(calib_err)?;
        Ok(Self {
            inner: Calibration {
                camera,
                free,
                covariance: DMatrix::from_row_slice(n, n, &cov),
                poses,
                views,
                view_rms: errs.0,
                rms: errs.1,
                outliers: Vec::new(),
                sigma_z,
                iterations: 0,
                final_cost: 0.0,
            },
        })
    }

    /// Model name.
    #[getter]
    fn model(&self) -> &'static str {
        self.inner.model().name()
    }

    /// Parameters in the model's order (OpenCV's for Brown–Conrady).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let p = self.inner.camera.params().to_vec();
        let n = p.len();
        convert::to_numpy(py, p, &[n])
    }

    /// `(width, height)`.
    #[getter]
    fn image_size(&self) -> (u32, u32) {
        (self.inner.camera.width(), self.inner.camera.height())
    }

    /// Which parameters were estimated.
    #[getter]
    fn free(&self) -> Vec<bool> {
        self.inner.free.clone()
    }

    /// Marginal covariance of the intrinsics (n×n).
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_out(py, &self.inner.covariance)
    }

    /// Marginal information of the intrinsics (n×n, Schur complements summed over views).
    fn information<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let info = convert::detached(py, || Ok(self.inner.information()))?;
        matrix_out(py, &info)
    }

    /// Target poses `T_ct`, `(V, 4, 4)`.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        poses_out(py, &self.inner.poses)
    }

    /// Per-view RMS reprojection error (pixels).
    #[getter]
    fn view_rms(&self) -> Vec<f64> {
        self.inner.view_rms.clone()
    }

    /// Total RMS reprojection error (pixels).
    #[getter]
    fn rms(&self) -> f64 {
        self.inner.rms
    }

    /// Outliers as `(view, row)` pairs.
    #[getter]
    fn outliers(&self) -> Vec<(usize, usize)> {
        self.inner.outliers.clone()
    }

    /// Detector noise σ_z used (pixels).
    #[getter]
    fn sigma_z(&self) -> f64 {
        self.inner.sigma_z
    }

    /// Solver iterations of the final stage.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }

    /// Final cost ½ Σ ‖r/σ_z‖².
    #[getter]
    fn final_cost(&self) -> f64 {
        self.inner.final_cost
    }

    /// The inlier observations per view: list of `(object (N, 3), image (N, 2), rows (N,))`.
    #[allow(clippy::type_complexity)]
    fn views<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<
        Vec<(
            Bound<'py, PyArrayDyn<f64>>,
            Bound<'py, PyArrayDyn<f64>>,
            Vec<usize>,
        )>,
    > {
        self.inner
            .views
            .iter()
            .map(|v| {
                let n = v.len();
                let o: Vec<f64> = v.plane.iter().flat_map(|p| [p[0], p[1], 0.0]).collect();
                let i: Vec<f64> = v.image.iter().flat_map(|p| [p[0], p[1]]).collect();
                Ok((
                    convert::to_numpy(py, o, &[n, 3])?,
                    convert::to_numpy(py, i, &[n, 2])?,
                    v.index.clone(),
                ))
            })
            .collect()
    }

    /// Max ERE (Algorithm 5.1): `(value, (u, v))`; `grid_margin` places the outer ring of the
    /// test grid (fraction of the image size, default `GRID_MARGIN`).
    #[pyo3(signature = (samples=200, grid=5, seed=0, grid_margin=None))]
    fn max_ere(
        &self,
        py: Python<'_>,
        samples: usize,
        grid: usize,
        seed: u64,
        grid_margin: Option<f64>,
    ) -> PyResult<(f64, (f64, f64))> {
        let pixels = grid_pixels(&self.inner.camera, grid, grid_margin)?;
        let m = convert::detached(py, || {
            self.inner
                .max_ere_at(samples, &pixels, seed)
                .map_err(calib_err)
        })?;
        Ok((m.value, (m.pixel[0], m.pixel[1])))
    }

    /// Max ERE statistics (dict: `max_ere`, `pixel`, `expected_max` = E over the samples of the
    /// largest error over the grid).
    #[pyo3(signature = (samples=200, grid=5, seed=0, grid_margin=None))]
    fn max_ere_stats<'py>(
        &self,
        py: Python<'py>,
        samples: usize,
        grid: usize,
        seed: u64,
        grid_margin: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let pixels = grid_pixels(&self.inner.camera, grid, grid_margin)?;
        let m = convert::detached(py, || {
            self.inner
                .max_ere_at(samples, &pixels, seed)
                .map_err(calib_err)
        })?;
        let d = PyDict::new(py);
        d.set_item("max_ere", m.value)?;
        d.set_item("pixel", (m.pixel[0], m.pixel[1]))?;
        d.set_item("expected_max", m.expected_max)?;
        Ok(d)
    }

    /// Per-pixel expected reprojection error map, `(ceil(h/step), ceil(w/step))`.
    #[pyo3(signature = (step=1, samples=100, seed=0))]
    fn error_map<'py>(
        &self,
        py: Python<'py>,
        step: usize,
        samples: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let m = convert::detached(py, || {
            self.inner.error_map(step, samples, seed).map_err(calib_err)
        })?;
        matrix_out(py, &m)
    }

    /// Next-view suggestion (dict: index, pose, pixels, target_index, expected_max_ere,
    /// current_max_ere, scores, candidates).
    #[pyo3(signature = (target, candidates=None, samples=100, grid=5, seed=0, grid_margin=None))]
    #[allow(clippy::too_many_arguments)]
    fn suggest_next_view<'py>(
        &self,
        py: Python<'py>,
        target: &Bound<'py, PyAny>,
        candidates: Option<&Bound<'py, PyAny>>,
        samples: usize,
        grid: usize,
        seed: u64,
        grid_margin: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let target = target_arg(target)?;
        let cands = candidates.map(|c| poses_arg(c, "candidates")).transpose()?;
        let pixels = grid_pixels(&self.inner.camera, grid, grid_margin)?;
        let s = convert::detached(py, || {
            self.inner
                .suggest_next_view_at(&target, cands.as_deref(), samples, &pixels, seed)
                .map_err(calib_err)
        })?;
        let d = PyDict::new(py);
        d.set_item("index", s.index)?;
        d.set_item(
            "pose",
            poses_out(py, std::slice::from_ref(&s.pose))?.get_item(0)?,
        )?;
        let n = s.pixels.len();
        d.set_item(
            "pixels",
            convert::to_numpy(py, s.pixels.iter().flatten().copied().collect(), &[n, 2])?,
        )?;
        d.set_item("target_index", s.target_index)?;
        d.set_item("expected_max_ere", s.expected_max_ere)?;
        d.set_item("current_max_ere", s.current_max_ere)?;
        d.set_item("scores", s.scores)?;
        d.set_item("candidates", poses_out(py, &s.candidates)?)?;
        Ok(d)
    }

    /// Per-point test errors (pixels) of test views with the intrinsics fixed and poses re-fit.
    fn test_errors(
        &self,
        py: Python<'_>,
        object_points: Vec<Bound<'_, PyAny>>,
        image_points: Vec<Bound<'_, PyAny>>,
    ) -> PyResult<Vec<Vec<f64>>> {
        let views = read_views(&object_points, &image_points)?;
        convert::detached(py, || self.inner.test_errors(&views).map_err(calib_err))
    }
}

#[allow(clippy::too_many_arguments)]
fn options(
    model: &str,
    width: u32,
    height: u32,
    sigma_z: Option<f64>,
    loss: &str,
    loss_scale: Option<f64>,
    outlier_threshold: Option<f64>,
    bootstrap: bool,
    initial_params: Option<&Bound<'_, PyAny>>,
    max_iterations: usize,
) -> PyResult<CalibOptions> {
    let mut o = CalibOptions::new(model_arg(model)?, width, height);
    o.sigma_z = sigma_z;
    let sigma = sigma_z.unwrap_or_else(|| autoteach_estimate::calib::default_sigma(width));
    let scale = loss_scale.unwrap_or(3.0 * sigma);
    o.loss = match loss.trim().to_ascii_lowercase().as_str() {
        "trivial" | "none" | "linear" => RobustLoss::Trivial,
        "huber" => RobustLoss::Huber(scale),
        "cauchy" => RobustLoss::Cauchy(scale),
        other => {
            return Err(errors::invalid_input(format!(
                "loss must be one of 'trivial', 'huber' or 'cauchy', got {other:?}"
            )));
        }
    };
    o.outlier_threshold = outlier_threshold;
    o.bootstrap = bootstrap;
    o.initial_params = initial_params
        .map(|p| convert::finite_array(p, "initial_params")?.vector())
        .transpose()?;
    o.max_iterations = max_iterations;
    Ok(o)
}

/// Calibrates from per-view object points `(N_i, 3)` (Z = 0) and image points `(N_i, 2)`
/// (NaN rows: missing points).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (object_points, image_points, model, width, height, *, sigma_z=None, loss="trivial", loss_scale=None,
                    outlier_threshold=None, bootstrap=true, initial_params=None, max_iterations=100))]
fn calib_calibrate(
    py: Python<'_>,
    object_points: Vec<Bound<'_, PyAny>>,
    image_points: Vec<Bound<'_, PyAny>>,
    model: &str,
    width: u32,
    height: u32,
    sigma_z: Option<f64>,
    loss: &str,
    loss_scale: Option<f64>,
    outlier_threshold: Option<f64>,
    bootstrap: bool,
    initial_params: Option<&Bound<'_, PyAny>>,
    max_iterations: usize,
) -> PyResult<PyCalibResult> {
    let views = read_views(&object_points, &image_points)?;
    let o = options(
        model,
        width,
        height,
        sigma_z,
        loss,
        loss_scale,
        outlier_threshold,
        bootstrap,
        initial_params,
        max_iterations,
    )?;
    let inner = convert::detached(py, || calibrate(&views, &o).map_err(calib_err))?;
    Ok(PyCalibResult { inner })
}

/// Calibrates every model in `models` and ranks them by BIC: list of
/// `(model, CalibResult or None, bic, error message or None)`, best first.
#[pyfunction]
#[pyo3(signature = (object_points, image_points, models, width, height, *, sigma_z=None))]
#[allow(clippy::type_complexity)]
fn calib_select_model(
    py: Python<'_>,
    object_points: Vec<Bound<'_, PyAny>>,
    image_points: Vec<Bound<'_, PyAny>>,
    models: Vec<String>,
    width: u32,
    height: u32,
    sigma_z: Option<f64>,
) -> PyResult<Vec<(String, Option<PyCalibResult>, f64, Option<String>)>> {
    let views = read_views(&object_points, &image_points)?;
    let ms = models
        .iter()
        .map(|m| model_arg(m))
        .collect::<PyResult<Vec<_>>>()?;
    let Some(&first) = ms.first() else {
        return Err(errors::invalid_input("models is empty"));
    };
    let mut o = CalibOptions::new(first, width, height);
    o.sigma_z = sigma_z;
    let ranked = convert::detached(py, || Ok(select_model(&views, &o, &ms)))?;
    Ok(ranked
        .into_iter()
        .map(|s| match s.calibration {
            Ok(c) => (
                s.model.name().to_string(),
                Some(PyCalibResult { inner: c }),
                s.bic,
                None,
            ),
            Err(e) => (s.model.name().to_string(), None, s.bic, Some(e.to_string())),
        })
        .collect())
}

/// About 60 candidate target poses `(K, 4, 4)` through the view frustum of a camera.
#[pyfunction]
fn calib_candidate_poses<'py>(
    py: Python<'py>,
    model: &str,
    params: &Bound<'py, PyAny>,
    width: u32,
    height: u32,
    target: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let cam = camera_arg(model, params, width, height)?;
    let target = target_arg(target)?;
    let poses = candidate_poses(&cam, &target).map_err(calib_err)?;
    poses_out(py, &poses)
}

/// The first target pose `(4, 4)` of a guided session: image centre, near, tilted about both
/// target axes.
#[pyfunction]
fn calib_first_view_pose<'py>(
    py: Python<'py>,
    model: &str,
    params: &Bound<'py, PyAny>,
    width: u32,
    height: u32,
    target: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let cam = camera_arg(model, params, width, height)?;
    let target = target_arg(target)?;
    let pose = first_view_pose(&cam, &target).map_err(calib_err)?;
    poses_out(py, &[pose])
}

/// `count` random target poses `(count, 4, 4)` (seeded) for simulated sessions and test sets.
#[pyfunction]
#[pyo3(signature = (model, params, width, height, target, count, *, max_tilt=0.7, seed=0))]
#[allow(clippy::too_many_arguments)]
fn calib_random_poses<'py>(
    py: Python<'py>,
    model: &str,
    params: &Bound<'py, PyAny>,
    width: u32,
    height: u32,
    target: &Bound<'py, PyAny>,
    count: usize,
    max_tilt: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let cam = camera_arg(model, params, width, height)?;
    let target = target_arg(target)?;
    let poses = random_poses(&cam, &target, count, max_tilt, seed).map_err(calib_err)?;
    poses_out(py, &poses)
}

/// `count` target poses `(count, 4, 4)` (seeded) of a simulated novice following the ROS
/// checklist of the seed's ch. 5.4 (left/right/top/bottom, close/far, tilted).
#[pyfunction]
#[pyo3(signature = (model, params, width, height, target, count, *, seed=0))]
#[allow(clippy::too_many_arguments)]
fn calib_novice_poses<'py>(
    py: Python<'py>,
    model: &str,
    params: &Bound<'py, PyAny>,
    width: u32,
    height: u32,
    target: &Bound<'py, PyAny>,
    count: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let cam = camera_arg(model, params, width, height)?;
    let target = target_arg(target)?;
    let poses = novice_poses(&cam, &target, count, seed).map_err(calib_err)?;
    poses_out(py, &poses)
}

/// A synthetic view: `(object (N, 3), image (N, 2), rows (N,))` of the visible target points
/// with Gaussian pixel noise `sigma` (seeded), or `None` if fewer than 4 are visible.
#[pyfunction]
#[pyo3(signature = (model, params, width, height, pose, target, *, sigma=0.0, seed=0))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn calib_synthesize_view<'py>(
    py: Python<'py>,
    model: &str,
    params: &Bound<'py, PyAny>,
    width: u32,
    height: u32,
    pose: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    sigma: f64,
    seed: u64,
) -> PyResult<
    Option<(
        Bound<'py, PyArrayDyn<f64>>,
        Bound<'py, PyArrayDyn<f64>>,
        Vec<usize>,
    )>,
> {
    let cam = camera_arg(model, params, width, height)?;
    let pose = convert::isometry(pose, "pose")?;
    let target = target_arg(target)?;
    if !(sigma >= 0.0 && sigma.is_finite()) {
        return Err(errors::invalid_input(format!(
            "sigma must be finite and >= 0, got {sigma}"
        )));
    }
    let Some(v) = synthesize_view_seeded(&cam, &pose, &target, sigma, seed) else {
        return Ok(None);
    };
    let n = v.len();
    let o: Vec<f64> = v.plane.iter().flat_map(|p| [p[0], p[1], 0.0]).collect();
    let i: Vec<f64> = v.image.iter().flat_map(|p| [p[0], p[1]]).collect();
    Ok(Some((
        convert::to_numpy(py, o, &[n, 3])?,
        convert::to_numpy(py, i, &[n, 2])?,
        v.index,
    )))
}

/// Adds the calib functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCalibResult>()?;
    m.add_function(wrap_pyfunction!(calib_calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(calib_select_model, m)?)?;
    m.add_function(wrap_pyfunction!(calib_candidate_poses, m)?)?;
    m.add_function(wrap_pyfunction!(calib_first_view_pose, m)?)?;
    m.add_function(wrap_pyfunction!(calib_random_poses, m)?)?;
    m.add_function(wrap_pyfunction!(calib_novice_poses, m)?)?;
    m.add_function(wrap_pyfunction!(calib_synthesize_view, m)?)?;
    m.add("CALIB_GRID_MARGIN", GRID_MARGIN)?;
    Ok(())
}
