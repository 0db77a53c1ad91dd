//! Bindings of `autoteach_estimate::lsq`: sparse nonlinear least squares on manifolds.
//!
//! * `lsq_bundle_adjust(K, poses, points, observations, pose_index, point_index, loss,
//!   f_scale, fixed_poses, **solver options)`: the whole solve in Rust with the GIL released.
//! * `LsqProblem`: a generic problem stated from NumPy: blocks on manifolds, the built-in
//!   residuals (reprojection, prior, relative pose, point-to-conic), `solve`, `values`,
//!   `marginal_covariance`.
//!
//! The friendly wrappers live in `autoteach.estimate`.

use autoteach_estimate::lsq::{
    BlockId, LinearSolver, Loss, Manifold, Method, PointToConicResidual, Problem,
    RelativePoseResidual, ReprojectionResidual, SolverOptions, Summary, bundle_adjust,
    se3_from_params, se3_to_params,
};
use nalgebra::{DMatrix, Matrix3};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, to_numpy};
use crate::errors;

/// Adds the lsq functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(lsq_bundle_adjust, m)?)?;
    m.add_class::<LsqProblem>()?;
    Ok(())
}

fn matrix(obj: &Bound<'_, PyAny>, name: &'static str, shape: [usize; 2]) -> PyResult<DMatrix<f64>> {
    let a = convert::finite_array(obj, name)?;
    let data = a.exact(&shape)?;
    Ok(DMatrix::from_row_slice(shape[0], shape[1], &data))
}

fn intrinsics(obj: &Bound<'_, PyAny>) -> PyResult<Matrix3<f64>> {
    let a = convert::finite_array(obj, "K")?;
    Ok(Matrix3::from_row_slice(&a.exact(&[3, 3])?))
}

fn loss(name: &str, scale: f64) -> PyResult<Loss> {
    let l = match name {
        "linear" | "trivial" => Loss::Trivial,
        "huber" => Loss::Huber(scale),
        "cauchy" => Loss::Cauchy(scale),
        "tukey" => Loss::Tukey(scale),
        other => {
            return Err(errors::invalid_input(format!(
                "loss must be one of 'linear', 'huber', 'cauchy', 'tukey', got {other:?}"
            )));
        }
    };
    l.validate().map_err(errors::estimate)?;
    Ok(l)
}

#[allow(clippy::too_many_arguments)]
fn options(
    method: &str,
    linear_solver: &str,
    max_iterations: usize,
    function_tolerance: f64,
    gradient_tolerance: f64,
    parameter_tolerance: f64,
    initial_damping: f64,
) -> PyResult<SolverOptions> {
    let method = match method {
        "lm" | "levenberg_marquardt" => Method::LevenbergMarquardt,
        "gn" | "gauss_newton" => Method::GaussNewton,
        other => {
            return Err(errors::invalid_input(format!(
                "method must be 'lm' or 'gn', got {other:?}"
            )));
        }
    };
    let linear_solver = match linear_solver {
        "auto" => LinearSolver::Auto,
        "dense" => LinearSolver::DenseCholesky,
        "sparse" => LinearSolver::SparseCholesky,
        "schur" => LinearSolver::SparseSchur,
        other => {
            return Err(errors::invalid_input(format!(
                "linear_solver must be 'auto', 'dense', 'sparse' or 'schur', got {other:?}"
            )));
        }
    };
    Ok(SolverOptions {
        method,
        max_iterations,
        function_tolerance,
        gradient_tolerance,
        parameter_tolerance,
        linear_solver,
        initial_damping,
        ..Default::default()
    })
}

fn summary_dict<'py>(py: Python<'py>, s: &Summary) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("iterations", s.iterations)?;
    d.set_item("successful_steps", s.successful_steps)?;
    d.set_item("initial_cost", s.initial_cost)?;
    d.set_item("final_cost", s.final_cost)?;
    d.set_item("termination", format!("{:?}", s.termination))?;
    d.set_item("converged", s.termination.converged())?;
    d.set_item("message", &s.message)?;
    d.set_item("time_s", s.time_s)?;
    d.set_item("linear_solver", format!("{:?}", s.linear_solver))?;
    d.set_item("num_parameters", s.num_parameters)?;
    d.set_item("num_residuals", s.num_residuals)?;
    d.set_item("num_eliminated_blocks", s.num_eliminated_blocks)?;
    d.set_item("gradient_max_norm", s.gradient_max_norm)?;
    d.set_item("time_setup_s", s.time_setup_s)?;
    d.set_item("time_evaluate_s", s.time_evaluate_s)?;
    d.set_item("time_assemble_s", s.time_assemble_s)?;
    d.set_item("time_linear_s", s.time_linear_s)?;
    d.set_item("time_schur_reduce_s", s.time_schur_reduce_s)?;
    d.set_item("time_schur_factor_s", s.time_schur_factor_s)?;
    Ok(d)
}

fn indices(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<usize>> {
    // An int64 NumPy vector is read as one slice (the Python wrappers pass these); anything
    // else goes through the sequence protocol.
    if let Ok(arr) = obj.extract::<numpy::PyReadonlyArray1<'_, i64>>() {
        let view = arr.as_array();
        return view
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                usize::try_from(i)
                    .map_err(|_| errors::invalid_input(format!("{name}[{k}] = {i} is negative")))
            })
            .collect();
    }
    let v: Vec<i64> = obj.extract().map_err(|_| {
        errors::invalid_input(format!(
            "{name} must be a sequence or 1-D array of integers"
        ))
    })?;
    v.iter()
        .enumerate()
        .map(|(k, &i)| {
            usize::try_from(i)
                .map_err(|_| errors::invalid_input(format!("{name}[{k}] = {i} is negative")))
        })
        .collect()
}

/// `(poses N×6, points M×3, summary dict)` returned by `lsq_bundle_adjust`.
type BundleOut<'py> = (
    Bound<'py, numpy::PyArrayDyn<f64>>,
    Bound<'py, numpy::PyArrayDyn<f64>>,
    Bound<'py, PyDict>,
);

/// Bundle adjustment (see `autoteach.estimate.bundle_adjust`). Returns
/// `(poses N×6, points M×3, summary dict)`.
#[pyfunction]
#[pyo3(signature = (k, poses, points, observations, pose_index, point_index, loss_name="linear", f_scale=1.0, fixed_poses=Vec::new(), method="lm", linear_solver="auto", max_iterations=100, function_tolerance=1e-10, gradient_tolerance=1e-10, parameter_tolerance=1e-10, initial_damping=1e-4))]
#[allow(clippy::too_many_arguments)]
fn lsq_bundle_adjust<'py>(
    py: Python<'py>,
    k: &Bound<'py, PyAny>,
    poses: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    observations: &Bound<'py, PyAny>,
    pose_index: &Bound<'py, PyAny>,
    point_index: &Bound<'py, PyAny>,
    loss_name: &str,
    f_scale: f64,
    fixed_poses: Vec<i64>,
    method: &str,
    linear_solver: &str,
    max_iterations: usize,
    function_tolerance: f64,
    gradient_tolerance: f64,
    parameter_tolerance: f64,
    initial_damping: f64,
) -> PyResult<BundleOut<'py>> {
    let k = intrinsics(k)?;
    let (pv, _) = convert::finite_batch(poses, "poses", &[6], "(N, 6)")?;
    let (xv, _) = convert::finite_batch(points, "points", &[3], "(M, 3)")?;
    let (ov, _) = convert::finite_batch(observations, "observations", &[2], "(K, 2)")?;
    let poses: Vec<[f64; 6]> = pv
        .chunks_exact(6)
        .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5]])
        .collect();
    let points: Vec<[f64; 3]> = xv.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let obs: Vec<[f64; 2]> = ov.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    let pi = indices(pose_index, "pose_index")?;
    let xi = indices(point_index, "point_index")?;
    let fixed = fixed_poses
        .iter()
        .map(|&i| {
            usize::try_from(i)
                .map_err(|_| errors::invalid_input(format!("fixed_poses contains {i}")))
        })
        .collect::<PyResult<Vec<usize>>>()?;
    let loss = loss(loss_name, f_scale)?;
    let opts = options(
        method,
        linear_solver,
        max_iterations,
        function_tolerance,
        gradient_tolerance,
        parameter_tolerance,
        initial_damping,
    )?;
    let res = convert::detached(py, || {
        bundle_adjust(&k, &poses, &points, &obs, &pi, &xi, loss, &fixed, &opts)
            .map_err(errors::estimate)
    })?;
    let np = res.poses.len();
    let nx = res.points.len();
    Ok((
        to_numpy(py, res.poses.concat(), &[np, 6])?,
        to_numpy(py, res.points.concat(), &[nx, 3])?,
        summary_dict(py, &res.summary)?,
    ))
}

/// A generic least-squares problem (see `autoteach.estimate.LeastSquaresProblem`).
#[pyclass(name = "LsqProblem", module = "autoteach._core")]
pub struct LsqProblem {
    inner: Problem,
}

impl LsqProblem {
    fn block(&self, b: usize) -> PyResult<BlockId> {
        if b < self.inner.num_blocks() {
            Ok(BlockId(b))
        } else {
            Err(errors::invalid_input(format!(
                "unknown block {b}: block must be an id in [0, {}) returned by an add_* call",
                self.inner.num_blocks()
            )))
        }
    }
}

#[pymethods]
impl LsqProblem {
    #[new]
    fn new() -> Self {
        Self {
            inner: Problem::new(),
        }
    }

    /// Adds a block with stored `values` on `manifold` ('euclidean', 'so3', 'quaternion',
    /// 'se3'); returns its id.
    fn add_block(&mut self, values: &Bound<'_, PyAny>, manifold: &str) -> PyResult<usize> {
        let v = convert::finite_array(values, "values")?.vector()?;
        let m = match manifold {
            "euclidean" => Manifold::Euclidean(v.len()),
            "so3" => Manifold::So3,
            "quaternion" => Manifold::UnitQuaternion,
            "se3" => Manifold::Se3,
            other => {
                return Err(errors::invalid_input(format!(
                    "manifold must be 'euclidean', 'so3', 'quaternion' or 'se3', got {other:?}"
                )));
            }
        };
        self.inner
            .add_block(&v, m)
            .map(|b| b.0)
            .map_err(errors::estimate)
    }

    /// Adds an SO(3) block from a 3×3 rotation matrix (refused unless orthonormal with det +1,
    /// like every rotation argument); returns its id.
    fn add_rotation(&mut self, r: &Bound<'_, PyAny>) -> PyResult<usize> {
        let rot = convert::matrix_to_rotation(&convert::matrix3(r, "R")?, "R")?;
        // nalgebra stores column-major: the So3 block's value layout.
        self.inner
            .add_block(rot.matrix().as_slice(), Manifold::So3)
            .map(|b| b.0)
            .map_err(errors::estimate)
    }

    /// Adds an SE(3) block from a 4×4 homogeneous transform; returns its id.
    fn add_pose(&mut self, t: &Bound<'_, PyAny>) -> PyResult<usize> {
        let t = convert::isometry(t, "T")?;
        self.inner
            .add_block(&se3_to_params(&t), Manifold::Se3)
            .map(|b| b.0)
            .map_err(errors::estimate)
    }

    /// The 4×4 homogeneous transform of an SE(3) block.
    fn pose<'py>(
        &self,
        py: Python<'py>,
        block: usize,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let b = self.block(block)?;
        if self.inner.manifold(b).map_err(errors::estimate)? != Manifold::Se3 {
            return Err(errors::invalid_input(format!(
                "block {block} is not an SE(3) block"
            )));
        }
        let rows = convert::isometry_rows(&se3_from_params(self.inner.values(b)));
        to_numpy(py, rows.concat(), &[4, 4])
    }

    /// The manifold name of a block.
    fn manifold(&self, block: usize) -> PyResult<String> {
        let b = self.block(block)?;
        Ok(match self.inner.manifold(b).map_err(errors::estimate)? {
            Manifold::Euclidean(_) => "euclidean",
            Manifold::So3 => "so3",
            Manifold::UnitQuaternion => "quaternion",
            Manifold::Se3 => "se3",
            Manifold::Se2 => "se2",
        }
        .to_string())
    }

    /// Number of blocks.
    #[getter]
    fn num_blocks(&self) -> usize {
        self.inner.num_blocks()
    }

    /// Number of residual blocks.
    #[getter]
    fn num_residuals(&self) -> usize {
        self.inner.num_residuals()
    }

    /// Holds a block constant (or releases it).
    fn set_fixed(&mut self, block: usize, fixed: bool) -> PyResult<()> {
        let b = self.block(block)?;
        self.inner.set_fixed(b, fixed).map_err(errors::estimate)
    }

    /// Marks a block for Schur elimination (True/False) or restores the automatic rule (None).
    #[pyo3(signature = (block, eliminate=None))]
    fn set_eliminate(&mut self, block: usize, eliminate: Option<bool>) -> PyResult<()> {
        let b = self.block(block)?;
        self.inner
            .set_eliminate(b, eliminate)
            .map_err(errors::estimate)
    }

    /// The stored values of a block.
    fn values<'py>(
        &self,
        py: Python<'py>,
        block: usize,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let b = self.block(block)?;
        let v = self.inner.values(b).to_vec();
        let n = v.len();
        to_numpy(py, v, &[n])
    }

    /// Overwrites the stored values of a block.
    fn set_values(&mut self, block: usize, values: &Bound<'_, PyAny>) -> PyResult<()> {
        let b = self.block(block)?;
        let v = convert::finite_array(values, "values")?.vector()?;
        self.inner.set_values(b, &v).map_err(errors::estimate)
    }

    /// Reprojection residuals of points (blocks `point_blocks`) in cameras (`pose_blocks`,
    /// world-to-camera SE(3)) observed at `observations` (K×2 px) with σ `sigma` px.
    #[pyo3(signature = (k, observations, pose_blocks, point_blocks, sigma=1.0, loss_name="linear", f_scale=1.0))]
    #[allow(clippy::too_many_arguments)]
    fn add_reprojections(
        &mut self,
        k: &Bound<'_, PyAny>,
        observations: &Bound<'_, PyAny>,
        pose_blocks: &Bound<'_, PyAny>,
        point_blocks: &Bound<'_, PyAny>,
        sigma: f64,
        loss_name: &str,
        f_scale: f64,
    ) -> PyResult<Vec<usize>> {
        let k = intrinsics(k)?;
        let (ov, _) = convert::finite_batch(observations, "observations", &[2], "(K, 2)")?;
        let pb = indices(pose_blocks, "pose_blocks")?;
        let xb = indices(point_blocks, "point_blocks")?;
        let n = ov.len() / 2;
        if pb.len() != n || xb.len() != n {
            return Err(errors::invalid_input(format!(
                "pose_blocks and point_blocks must have one entry per observation ({n}), got {} and {}",
                pb.len(),
                xb.len()
            )));
        }
        let loss = loss(loss_name, f_scale)?;
        let mut ids = Vec::with_capacity(n);
        for i in 0..n {
            let r = ReprojectionResidual::new(&k, [ov[2 * i], ov[2 * i + 1]], sigma)
                .map_err(errors::estimate)?;
            let (a, b) = (self.block(pb[i])?, self.block(xb[i])?);
            ids.push(
                self.inner
                    .add_residual(r, &[a, b], loss)
                    .map_err(errors::estimate)?
                    .0,
            );
        }
        Ok(ids)
    }

    /// A Gaussian prior on a block: whitened `x ⊖ mean` with tangent `covariance`.
    fn add_prior(
        &mut self,
        block: usize,
        mean: &Bound<'_, PyAny>,
        covariance: &Bound<'_, PyAny>,
    ) -> PyResult<usize> {
        let b = self.block(block)?;
        let mean = convert::finite_array(mean, "mean")?.vector()?;
        let n = self
            .inner
            .manifold(b)
            .map_err(errors::estimate)?
            .tangent_dim();
        let cov = matrix(covariance, "covariance", [n, n])?;
        self.inner
            .add_prior(b, &mean, &cov)
            .map(|r| r.0)
            .map_err(errors::estimate)
    }

    /// Relative pose between SE(3) blocks: measurement `t_ab` (4×4) of A⁻¹B, 6×6 covariance.
    #[pyo3(signature = (a, b, t_ab, covariance, loss_name="linear", f_scale=1.0))]
    fn add_relative_pose(
        &mut self,
        a: usize,
        b: usize,
        t_ab: &Bound<'_, PyAny>,
        covariance: &Bound<'_, PyAny>,
        loss_name: &str,
        f_scale: f64,
    ) -> PyResult<usize> {
        let (a, b) = (self.block(a)?, self.block(b)?);
        let z = convert::isometry(t_ab, "t_ab")?;
        let cov = matrix(covariance, "covariance", [6, 6])?;
        let r = RelativePoseResidual::new(&z, &cov).map_err(errors::estimate)?;
        let loss = loss(loss_name, f_scale)?;
        self.inner
            .add_residual(r, &[a, b], loss)
            .map(|r| r.0)
            .map_err(errors::estimate)
    }

    /// Point-to-conic residuals (seed eq. (5.13)) of rim points `observations` (K×2 px) of a
    /// circle of `radius` in the object's z = 0 plane; camera block (world-to-camera SE(3)),
    /// object block (object-to-world SE(3)).
    #[pyo3(signature = (k, radius, observations, camera_block, object_block, weight=1.0, loss_name="linear", f_scale=1.0))]
    #[allow(clippy::too_many_arguments)]
    fn add_point_to_conic(
        &mut self,
        k: &Bound<'_, PyAny>,
        radius: f64,
        observations: &Bound<'_, PyAny>,
        camera_block: usize,
        object_block: usize,
        weight: f64,
        loss_name: &str,
        f_scale: f64,
    ) -> PyResult<Vec<usize>> {
        let k = intrinsics(k)?;
        let (ov, _) = convert::finite_batch(observations, "observations", &[2], "(K, 2)")?;
        let (c, o) = (self.block(camera_block)?, self.block(object_block)?);
        let loss = loss(loss_name, f_scale)?;
        ov.chunks_exact(2)
            .map(|uv| {
                let r = PointToConicResidual::new(&k, radius, [uv[0], uv[1]], weight)
                    .map_err(errors::estimate)?;
                self.inner
                    .add_residual(r, &[c, o], loss)
                    .map(|r| r.0)
                    .map_err(errors::estimate)
            })
            .collect()
    }

    /// Solves; returns the summary dict. The GIL is released during the solve.
    #[pyo3(signature = (method="lm", linear_solver="auto", max_iterations=100, function_tolerance=1e-10, gradient_tolerance=1e-10, parameter_tolerance=1e-10, initial_damping=1e-4))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        method: &str,
        linear_solver: &str,
        max_iterations: usize,
        function_tolerance: f64,
        gradient_tolerance: f64,
        parameter_tolerance: f64,
        initial_damping: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let opts = options(
            method,
            linear_solver,
            max_iterations,
            function_tolerance,
            gradient_tolerance,
            parameter_tolerance,
            initial_damping,
        )?;
        let inner = &mut self.inner;
        let s = convert::detached(py, || inner.solve(&opts).map_err(errors::estimate))?;
        summary_dict(py, &s)
    }

    /// Joint tangent-space covariance of the listed blocks.
    fn marginal_covariance<'py>(
        &self,
        py: Python<'py>,
        blocks: Vec<usize>,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let ids = blocks
            .iter()
            .map(|&b| self.block(b))
            .collect::<PyResult<Vec<_>>>()?;
        let inner = &self.inner;
        let cov = convert::detached(py, || {
            inner.marginal_covariance(&ids).map_err(errors::estimate)
        })?;
        let n = cov.nrows();
        // Row-major for NumPy (the matrix is symmetric, but be explicit).
        let data: Vec<f64> = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| cov[(i, j)])
            .collect();
        to_numpy(py, data, &[n, n])
    }
}
