//! Bindings of `autoteach_geometry`: Lie-group helpers, the wafer robot, camera models and
//! ellipses.
//!
//! Every function validates its arrays through [`crate::convert`] (float64, shape, finiteness;
//! errors name the argument), calls one core function per item and converts the result back.
//! Functions taking `(..., n)` arrays are batched over the leading dimensions; batches larger
//! than [`convert::DETACH_THRESHOLD`] elements release the GIL. The friendly Python classes
//! in `autoteach.geometry` hold the compiled classes defined here (attribute `_inner`); other
//! binding modules accept either form through [`robot_arg`], [`camera_arg`] and
//! [`ellipse_arg`].

use autoteach_geometry::camera::{Camera, CameraModel};
use autoteach_geometry::conic::{self, Ellipse};
use autoteach_geometry::robot::{self, Blade, Joints, RobotParams, WaferRobot};
use autoteach_geometry::{GeometryError, lie};
use nalgebra::{Isometry3, Rotation3, SMatrix, Vector3, Vector5, Vector6};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, batched_shape, finite_batch, matrix3, to_numpy};
use crate::errors;

/// A float64 NumPy array returned to Python.
type Array<'py> = PyResult<Bound<'py, PyArrayDyn<f64>>>;

/// Three float64 NumPy arrays (a value and two Jacobians).
type Arrays3<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
);

/// Adds the geometry functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyWaferRobot>()?;
    m.add_class::<PyCamera>()?;
    m.add_class::<PyEllipse>()?;
    m.add_function(wrap_pyfunction!(so3_exp, m)?)?;
    m.add_function(wrap_pyfunction!(so3_log, m)?)?;
    m.add_function(wrap_pyfunction!(se3_exp, m)?)?;
    m.add_function(wrap_pyfunction!(se3_log, m)?)?;
    m.add_function(wrap_pyfunction!(se3_plus, m)?)?;
    m.add_function(wrap_pyfunction!(se3_minus, m)?)?;
    m.add_function(wrap_pyfunction!(quat_to_matrix, m)?)?;
    m.add_function(wrap_pyfunction!(matrix_to_quat, m)?)?;
    m.add_function(wrap_pyfunction!(euler_zyx_to_matrix, m)?)?;
    m.add_function(wrap_pyfunction!(matrix_to_euler_zyx, m)?)?;
    m.add_function(wrap_pyfunction!(euler_xyz_to_matrix, m)?)?;
    m.add_function(wrap_pyfunction!(matrix_to_euler_xyz, m)?)?;
    m.add_function(wrap_pyfunction!(joints_from_encoders, m)?)?;
    m.add_function(wrap_pyfunction!(circle_image_conic, m)?)?;
    m.add_function(wrap_pyfunction!(project_circle, m)?)?;
    m.add_function(wrap_pyfunction!(project_circle_jacobian, m)?)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Batch plumbing
// ---------------------------------------------------------------------------------------------

/// Writes `m` into `out` in row-major order.
fn write_rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>, out: &mut [f64]) {
    for (k, o) in out.iter_mut().enumerate().take(R * C) {
        *o = m[(k / C, k % C)];
    }
}

/// Evaluates `f` on every item of a batch, writing `out_len` values per item, and returns
/// the concatenated results. Large batches run without the GIL; a core error of one item is
/// reported with its (flat) index when the input is batched.
fn map_items<T, F>(
    py: Python<'_>,
    items: &[T],
    batched: bool,
    out_len: usize,
    f: F,
) -> PyResult<Vec<f64>>
where
    T: Sync,
    F: Fn(&T, &mut [f64]) -> autoteach_geometry::Result<()> + Sync,
{
    let mut out = vec![0.0; items.len() * out_len];
    let failed = convert::run_batched(py, out.len(), || {
        for (index, (item, o)) in items
            .iter()
            .zip(out.chunks_exact_mut(out_len.max(1)))
            .enumerate()
        {
            if let Err(source) = f(item, o) {
                return Ok(Some(if batched {
                    GeometryError::AtIndex {
                        index,
                        source: Box::new(source),
                    }
                } else {
                    source
                }));
            }
        }
        Ok(None)
    })?;
    match failed {
        Some(e) => Err(errors::geometry(e)),
        None => Ok(out),
    }
}

/// [`map_items`] over a batch with leading shape `lead`, returned as a NumPy array of shape
/// `lead + item_shape` (each item writes `item_shape.iter().product()` values).
fn map_batch<'py, T, F>(
    py: Python<'py>,
    items: &[T],
    lead: &[usize],
    item_shape: &[usize],
    f: F,
) -> Array<'py>
where
    T: Sync,
    F: Fn(&T, &mut [f64]) -> autoteach_geometry::Result<()> + Sync,
{
    let out_len = item_shape.iter().product();
    let out = map_items(py, items, !lead.is_empty(), out_len, f)?;
    to_numpy(py, out, &batched_shape(lead, item_shape))
}

/// Splits validated row-major data into items of `n` values.
fn chunks(data: &[f64], n: usize) -> Vec<&[f64]> {
    data.chunks_exact(n).collect()
}

/// Reads a finite batch of vectors `(..., N)` as fixed-size vectors.
fn vectors<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    expected: &str,
) -> PyResult<(Vec<SMatrix<f64, N, 1>>, Vec<usize>)> {
    let (data, lead) = finite_batch(obj, name, &[N], expected)?;
    Ok((
        data.chunks_exact(N)
            .map(SMatrix::<f64, N, 1>::from_row_slice)
            .collect(),
        lead,
    ))
}

/// Reads one finite vector of exactly `N` values.
fn vector<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
) -> PyResult<SMatrix<f64, N, 1>> {
    let values = convert::finite_array(obj, name)?.exact(&[N])?;
    Ok(SMatrix::<f64, N, 1>::from_row_slice(&values))
}

/// Fails unless `value` is finite.
fn finite_scalar(value: f64, name: &str) -> PyResult<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(errors::invalid_input(format!(
            "{name} must be finite, got {value}"
        )))
    }
}

/// Row-major 4×4 of a pose as a NumPy array.
fn pose_array<'py>(py: Python<'py>, t: &Isometry3<f64>) -> Array<'py> {
    let mut out = vec![0.0; 16];
    write_rows(&t.to_homogeneous(), &mut out);
    to_numpy(py, out, &[4, 4])
}

// ---------------------------------------------------------------------------------------------
// Lie groups, quaternions, Euler angles
// ---------------------------------------------------------------------------------------------

/// Rotation matrices `Exp(ω)`: `(..., 3)` → `(..., 3, 3)`.
#[pyfunction]
fn so3_exp<'py>(py: Python<'py>, omega: &Bound<'py, PyAny>) -> Array<'py> {
    let (w, lead) = vectors::<3>(omega, "omega", "(..., 3)")?;
    map_batch(py, &w, &lead, &[3, 3], |w, o| {
        write_rows(lie::so3_exp(w).matrix(), o);
        Ok(())
    })
}

/// Rotation vectors `Log(R)`: `(..., 3, 3)` → `(..., 3)`.
#[pyfunction]
#[pyo3(name = "so3_log", signature = (R))]
#[allow(non_snake_case)]
fn so3_log<'py>(py: Python<'py>, R: &Bound<'py, PyAny>) -> Array<'py> {
    let (r, lead) = convert::rotations(R, "R")?;
    map_batch(py, &r, &lead, &[3], |r, o| {
        o.copy_from_slice(lie::so3_log(r).as_slice());
        Ok(())
    })
}

/// Poses `Exp(ξ)`, `ξ = [ω; ρ]`: `(..., 6)` → `(..., 4, 4)`.
#[pyfunction]
fn se3_exp<'py>(py: Python<'py>, xi: &Bound<'py, PyAny>) -> Array<'py> {
    let (x, lead) = vectors::<6>(xi, "xi", "(..., 6)")?;
    map_batch(py, &x, &lead, &[4, 4], |x, o| {
        write_rows(&lie::se3_exp(x).to_homogeneous(), o);
        Ok(())
    })
}

/// Twists `Log(T)`: `(..., 4, 4)` → `(..., 6)`.
#[pyfunction]
#[pyo3(signature = (T))]
#[allow(non_snake_case)]
fn se3_log<'py>(py: Python<'py>, T: &Bound<'py, PyAny>) -> Array<'py> {
    let (t, lead) = convert::isometries(T, "T")?;
    map_batch(py, &t, &lead, &[6], |t, o| {
        o.copy_from_slice(lie::se3_log(t).as_slice());
        Ok(())
    })
}

/// Fails unless two batch shapes are equal (the Python wrappers broadcast first).
fn same_batch(a: &[usize], a_name: &str, b: &[usize], b_name: &str) -> PyResult<()> {
    if a == b {
        Ok(())
    } else {
        Err(errors::invalid_input(format!(
            "the batch shapes of {a_name} {} and {b_name} {} differ",
            convert::shape_str(a),
            convert::shape_str(b)
        )))
    }
}

/// `T ⊕ ξ = T·Exp(ξ)`: `(..., 4, 4)`, `(..., 6)` (same leading shape) → `(..., 4, 4)`.
#[pyfunction]
#[pyo3(signature = (T, xi))]
#[allow(non_snake_case)]
fn se3_plus<'py>(py: Python<'py>, T: &Bound<'py, PyAny>, xi: &Bound<'py, PyAny>) -> Array<'py> {
    let (t, lead) = convert::isometries(T, "T")?;
    let (x, lead_x) = vectors::<6>(xi, "xi", "(..., 6)")?;
    same_batch(&lead, "T", &lead_x, "xi")?;
    let pairs: Vec<(Isometry3<f64>, Vector6<f64>)> = t.into_iter().zip(x).collect();
    map_batch(py, &pairs, &lead, &[4, 4], |(t, x), o| {
        write_rows(&lie::se3_plus(t, x).to_homogeneous(), o);
        Ok(())
    })
}

/// `Y ⊖ X = Log(X⁻¹·Y)`: two `(..., 4, 4)` (same leading shape) → `(..., 6)`.
#[pyfunction]
#[pyo3(signature = (Y, X))]
#[allow(non_snake_case)]
fn se3_minus<'py>(py: Python<'py>, Y: &Bound<'py, PyAny>, X: &Bound<'py, PyAny>) -> Array<'py> {
    let (y, lead) = convert::isometries(Y, "Y")?;
    let (x, lead_x) = convert::isometries(X, "X")?;
    same_batch(&lead, "Y", &lead_x, "X")?;
    let pairs: Vec<(Isometry3<f64>, Isometry3<f64>)> = y.into_iter().zip(x).collect();
    map_batch(py, &pairs, &lead, &[6], |(y, x), o| {
        o.copy_from_slice(lie::se3_minus(y, x).as_slice());
        Ok(())
    })
}

/// Rotation matrices of quaternions `(w, x, y, z)`: `(..., 4)` → `(..., 3, 3)`.
#[pyfunction]
fn quat_to_matrix<'py>(py: Python<'py>, q: &Bound<'py, PyAny>) -> Array<'py> {
    let (data, lead) = finite_batch(q, "q", &[4], "(..., 4)")?;
    let items = chunks(&data, 4);
    map_batch(py, &items, &lead, &[3, 3], |q, o| {
        let wxyz = [q[0], q[1], q[2], q[3]];
        write_rows(lie::quat_from_wxyz(&wxyz)?.to_rotation_matrix().matrix(), o);
        Ok(())
    })
}

/// Unit quaternions `(w, x, y, z)`, `w ≥ 0`, of rotation matrices: `(..., 3, 3)` → `(..., 4)`.
#[pyfunction]
#[pyo3(signature = (R))]
#[allow(non_snake_case)]
fn matrix_to_quat<'py>(py: Python<'py>, R: &Bound<'py, PyAny>) -> Array<'py> {
    let (r, lead) = convert::rotations(R, "R")?;
    map_batch(py, &r, &lead, &[4], |r, o| {
        let q = lie::quat_to_wxyz(&nalgebra::UnitQuaternion::from_rotation_matrix(r));
        // q and −q are the same rotation: report the one with w ≥ 0.
        let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
        for (o, v) in o.iter_mut().zip(q) {
            *o = sign * v;
        }
        Ok(())
    })
}

/// Rotation matrices `Rz(yaw)·Ry(pitch)·Rx(roll)`: `(..., 3)` → `(..., 3, 3)`.
#[pyfunction]
fn euler_zyx_to_matrix<'py>(py: Python<'py>, angles: &Bound<'py, PyAny>) -> Array<'py> {
    let (a, lead) = vectors::<3>(angles, "angles", "(..., 3)")?;
    map_batch(py, &a, &lead, &[3, 3], |a, o| {
        write_rows(lie::rotation_from_euler_zyx(a[0], a[1], a[2]).matrix(), o);
        Ok(())
    })
}

/// `(yaw, pitch, roll)` of rotation matrices: `(..., 3, 3)` → `(..., 3)`.
#[pyfunction]
#[pyo3(signature = (R))]
#[allow(non_snake_case)]
fn matrix_to_euler_zyx<'py>(py: Python<'py>, R: &Bound<'py, PyAny>) -> Array<'py> {
    let (r, lead) = convert::rotations(R, "R")?;
    map_batch(py, &r, &lead, &[3], |r, o| {
        let (yaw, pitch, roll) = lie::euler_zyx(r);
        o.copy_from_slice(&[yaw, pitch, roll]);
        Ok(())
    })
}

/// Rotation matrices `Rx(a)·Ry(b)·Rz(c)`: `(..., 3)` → `(..., 3, 3)`.
#[pyfunction]
fn euler_xyz_to_matrix<'py>(py: Python<'py>, angles: &Bound<'py, PyAny>) -> Array<'py> {
    let (a, lead) = vectors::<3>(angles, "angles", "(..., 3)")?;
    map_batch(py, &a, &lead, &[3, 3], |a, o| {
        write_rows(lie::rotation_from_euler_xyz(a[0], a[1], a[2]).matrix(), o);
        Ok(())
    })
}

/// `(a, b, c)` of rotation matrices `Rx(a)·Ry(b)·Rz(c)`: `(..., 3, 3)` → `(..., 3)`.
#[pyfunction]
#[pyo3(signature = (R))]
#[allow(non_snake_case)]
fn matrix_to_euler_xyz<'py>(py: Python<'py>, R: &Bound<'py, PyAny>) -> Array<'py> {
    let (r, lead) = convert::rotations(R, "R")?;
    map_batch(py, &r, &lead, &[3], |r: &Rotation3<f64>, o| {
        let (a, b, c) = lie::euler_xyz(r);
        o.copy_from_slice(&[a, b, c]);
        Ok(())
    })
}

// ---------------------------------------------------------------------------------------------
// The wafer robot
// ---------------------------------------------------------------------------------------------

/// Maps the Python blade number (1 or 2) to [`Blade`].
fn blade_arg(blade: i64) -> PyResult<Blade> {
    match blade {
        1 => Ok(Blade::One),
        2 => Ok(Blade::Two),
        other => Err(errors::invalid_input(format!(
            "blade must be 1 or 2, got {other}"
        ))),
    }
}

/// Reads joint vectors `(..., 5)`.
fn joints(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<(Vec<Joints>, Vec<usize>)> {
    vectors::<5>(obj, name, "(..., 5)")
}

/// The compiled wafer robot (`autoteach._core.WaferRobot`); see `autoteach.geometry.WaferRobot`.
#[pyclass(name = "WaferRobot", module = "autoteach._core", frozen)]
pub struct PyWaferRobot {
    /// The core robot.
    pub inner: WaferRobot,
}

/// `{name: value}` of robot parameters in the documented order.
fn params_dict<'py>(py: Python<'py>, params: &RobotParams) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, value) in RobotParams::NAMES.iter().zip(params.to_array()) {
        d.set_item(*name, value)?;
    }
    Ok(d)
}

#[pymethods]
impl PyWaferRobot {
    /// Builds a robot from a `{name: value}` parameter dict (missing names take the defaults)
    /// and a 4×4 base pose `T_wb` (identity when `None`).
    #[new]
    #[pyo3(signature = (params=None, base=None))]
    fn new(params: Option<&Bound<'_, PyAny>>, base: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let mut values = RobotParams::default().to_array();
        if let Some(obj) = params.filter(|p| !p.is_none()) {
            let dict = obj.cast::<PyDict>().map_err(|_| {
                errors::invalid_input(format!(
                    "params must be a dict of parameter names to values, got {}",
                    obj.get_type()
                        .name()
                        .map(|n| n.to_string())
                        .unwrap_or_default()
                ))
            })?;
            for (key, value) in dict.iter() {
                let key: String = key.extract().map_err(|_| {
                    errors::invalid_input(format!(
                        "robot parameter names must be strings, got {key}"
                    ))
                })?;
                let Some(slot) = RobotParams::NAMES.iter().position(|n| *n == key) else {
                    return Err(errors::invalid_input(format!(
                        "unknown robot parameter {key:?}; expected one of {:?}",
                        RobotParams::NAMES
                    )));
                };
                values[slot] = value.extract::<f64>().map_err(|_| {
                    errors::invalid_input(format!(
                        "robot parameter {key} must be a real number, got {value}"
                    ))
                })?;
            }
        }
        let params = RobotParams::from_slice(&values).map_err(errors::geometry)?;
        let base = match base.filter(|b| !b.is_none()) {
            Some(b) => convert::isometry(b, "base")?,
            None => Isometry3::identity(),
        };
        let inner = WaferRobot::new(params, base).map_err(errors::geometry)?;
        Ok(Self { inner })
    }

    /// The default parameters as a `{name: value}` dict.
    #[staticmethod]
    fn default_params(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        params_dict(py, &RobotParams::default())
    }

    /// The parameters as a `{name: value}` dict.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        params_dict(py, &self.inner.params)
    }

    /// The base pose `T_wb` (4×4).
    #[getter]
    fn base<'py>(&self, py: Python<'py>) -> Array<'py> {
        pose_array(py, &self.inner.base)
    }

    /// The camera mount `T_e2c` (4×4).
    fn camera_mount<'py>(&self, py: Python<'py>) -> Array<'py> {
        pose_array(py, &self.inner.camera_mount())
    }

    /// Blade poses `T_be` in the base frame: `(..., 5)` → `(..., 4, 4)`.
    fn blade_pose<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, blade: i64) -> Array<'py> {
        let blade = blade_arg(blade)?;
        let (qs, lead) = joints(q, "q")?;
        map_batch(py, &qs, &lead, &[4, 4], |q, o| {
            write_rows(&self.inner.blade_pose(q, blade).to_homogeneous(), o);
            Ok(())
        })
    }

    /// World camera poses `T_wc`: `(..., 5)` → `(..., 4, 4)`.
    fn camera_pose<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> Array<'py> {
        let (qs, lead) = joints(q, "q")?;
        let out = convert::run_batched(py, qs.len() * 16, || {
            let poses = self.inner.camera_poses(&qs);
            let mut out = vec![0.0; poses.len() * 16];
            for (t, o) in poses.iter().zip(out.chunks_exact_mut(16)) {
                write_rows(&t.to_homogeneous(), o);
            }
            Ok(out)
        })?;
        to_numpy(py, out, &batched_shape(&lead, &[4, 4]))
    }

    /// Camera poses in the base `T_bc`: `(..., 5)` → `(..., 4, 4)`.
    fn camera_pose_in_base<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> Array<'py> {
        let (qs, lead) = joints(q, "q")?;
        map_batch(py, &qs, &lead, &[4, 4], |q, o| {
            write_rows(&self.inner.camera_pose_in_base(q).to_homogeneous(), o);
            Ok(())
        })
    }

    /// Blade Jacobians: `(..., 5)` → `(..., 4, 5)`.
    fn jacobian<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, blade: i64) -> Array<'py> {
        let blade = blade_arg(blade)?;
        let (qs, lead) = joints(q, "q")?;
        map_batch(py, &qs, &lead, &[4, 5], |q, o| {
            write_rows(&self.inner.jacobian(q, blade), o);
            Ok(())
        })
    }

    /// Camera-pose Jacobians (right-perturbation twists per joint): `(..., 5)` → `(..., 6, 5)`.
    fn camera_jacobian<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> Array<'py> {
        let (qs, lead) = joints(q, "q")?;
        map_batch(py, &qs, &lead, &[6, 5], |q, o| {
            write_rows(&self.inner.camera_jacobian(q), o);
            Ok(())
        })
    }

    /// Blade accelerations: three `(..., 5)` (same leading shape) → `(..., 4)`.
    fn acceleration<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        qd: &Bound<'py, PyAny>,
        qdd: &Bound<'py, PyAny>,
        blade: i64,
    ) -> Array<'py> {
        let blade = blade_arg(blade)?;
        let (qs, lead) = joints(q, "q")?;
        let (qds, lead_d) = joints(qd, "qd")?;
        let (qdds, lead_dd) = joints(qdd, "qdd")?;
        same_batch(&lead, "q", &lead_d, "qd")?;
        same_batch(&lead, "q", &lead_dd, "qdd")?;
        let items: Vec<(Joints, Joints, Joints)> = qs
            .into_iter()
            .zip(qds)
            .zip(qdds)
            .map(|((a, b), c)| (a, b, c))
            .collect();
        map_batch(py, &items, &lead, &[4], |(q, qd, qdd), o| {
            o.copy_from_slice(self.inner.acceleration(q, qd, qdd, blade).as_slice());
            Ok(())
        })
    }

    /// All joint vectors reaching the blade pose `T` (base frame): `(k, 5)`.
    #[pyo3(signature = (T, blade, other_blade_angle))]
    #[allow(non_snake_case)]
    fn inverse_kinematics<'py>(
        &self,
        py: Python<'py>,
        T: &Bound<'py, PyAny>,
        blade: i64,
        other_blade_angle: f64,
    ) -> Array<'py> {
        let blade = blade_arg(blade)?;
        let t = convert::isometry(T, "T")?;
        finite_scalar(other_blade_angle, "other_blade_angle")?;
        let sols = convert::guarded(|| {
            self.inner
                .inverse_kinematics(&t, blade, other_blade_angle)
                .map_err(errors::geometry)
        })?;
        joints_array(py, &sols)
    }

    /// All joint vectors reaching the world camera pose `T_wc`: `(k, 5)`.
    #[pyo3(signature = (T_wc, theta3))]
    #[allow(non_snake_case)]
    fn inverse_kinematics_camera<'py>(
        &self,
        py: Python<'py>,
        T_wc: &Bound<'py, PyAny>,
        theta3: f64,
    ) -> Array<'py> {
        let t = convert::isometry(T_wc, "T_wc")?;
        finite_scalar(theta3, "theta3")?;
        let sols = convert::guarded(|| {
            self.inner
                .inverse_kinematics_camera(&t, theta3)
                .map_err(errors::geometry)
        })?;
        joints_array(py, &sols)
    }

    fn __repr__(&self) -> String {
        format!("_core.WaferRobot({:?})", self.inner)
    }
}

/// `(k, 5)` array of joint vectors.
fn joints_array<'py>(py: Python<'py>, sols: &[Joints]) -> Array<'py> {
    let data = sols.iter().flat_map(|q| q.iter().copied()).collect();
    to_numpy(py, data, &[sols.len(), 5])
}

/// True joints from encoder readings: `(..., 5)`, offsets `(5,)` → `(..., 5)`.
#[pyfunction]
fn joints_from_encoders<'py>(
    py: Python<'py>,
    q_enc: &Bound<'py, PyAny>,
    offsets: &Bound<'py, PyAny>,
) -> Array<'py> {
    let (qs, lead) = joints(q_enc, "q_enc")?;
    let offsets: Vector5<f64> = vector::<5>(offsets, "offsets")?;
    map_batch(py, &qs, &lead, &[5], |q, o| {
        o.copy_from_slice(robot::joints_from_encoders(q, &offsets).as_slice());
        Ok(())
    })
}

/// Extracts the core robot from a compiled `_core.WaferRobot` or a Python wrapper holding one
/// in `_inner` (for other binding modules).
#[allow(
    dead_code,
    reason = "for the other binding modules (sim, detect, estimate)"
)]
pub fn robot_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<WaferRobot> {
    inner_of::<PyWaferRobot>(obj, name, "WaferRobot").map(|r| r.get().inner)
}

/// `obj` as the compiled class `T`, or `obj._inner` as `T`.
#[allow(
    dead_code,
    reason = "for the other binding modules (sim, detect, estimate)"
)]
fn inner_of<'py, T: pyo3::PyClass>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    class: &str,
) -> PyResult<Bound<'py, T>> {
    if let Ok(c) = obj.cast::<T>() {
        return Ok(c.clone());
    }
    if let Ok(inner) = obj.getattr("_inner")
        && let Ok(c) = inner.cast_into::<T>()
    {
        return Ok(c);
    }
    Err(errors::invalid_input(format!(
        "{name} must be an autoteach.geometry.{class}, got {}",
        obj.get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_default()
    )))
}

// ---------------------------------------------------------------------------------------------
// Cameras
// ---------------------------------------------------------------------------------------------

/// The compiled camera (`autoteach._core.Camera`); see `autoteach.geometry.Camera`.
#[pyclass(name = "Camera", module = "autoteach._core", frozen)]
pub struct PyCamera {
    /// The core camera.
    pub inner: Camera,
}

/// Reads an image dimension (positive, at most `u32::MAX`).
fn image_size(value: i64, name: &str) -> PyResult<u32> {
    u32::try_from(value).ok().filter(|v| *v > 0).ok_or_else(|| {
        errors::invalid_input(format!(
            "{name} must be a positive number of pixels, got {value}"
        ))
    })
}

/// A batch error without its index when the input was a single item.
fn unbatched(err: GeometryError, batched: bool) -> GeometryError {
    match err {
        GeometryError::AtIndex { source, .. } if !batched => *source,
        other => other,
    }
}

/// Copies validated row-major data into fixed-size rows.
fn fixed_rows<const N: usize>(data: &[f64]) -> Vec<[f64; N]> {
    data.chunks_exact(N)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect()
}

#[pymethods]
impl PyCamera {
    /// Builds a camera: model name, parameter vector `(n,)`, image size in pixels.
    #[new]
    fn new(model: &str, params: &Bound<'_, PyAny>, width: i64, height: i64) -> PyResult<Self> {
        let model: CameraModel = model.parse().map_err(errors::geometry)?;
        let values = convert::finite_array(params, "params")?;
        if values.shape() != [model.num_params()] {
            return Err(errors::invalid_input(format!(
                "params must have shape ({},) = ({}) for the {} model, got {}",
                model.num_params(),
                model.param_names().join(", "),
                model.name(),
                convert::shape_str(values.shape())
            )));
        }
        let values = values.vector()?;
        let (w, h) = (image_size(width, "width")?, image_size(height, "height")?);
        let inner = Camera::new(model, &values, w, h).map_err(errors::geometry)?;
        Ok(Self { inner })
    }

    /// Canonical model name.
    #[getter]
    fn model(&self) -> &'static str {
        self.inner.model().name()
    }

    /// The parameter vector (a copy).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> Array<'py> {
        let p = self.inner.params().to_vec();
        let n = p.len();
        to_numpy(py, p, &[n])
    }

    /// Names of the parameters.
    #[getter]
    fn param_names(&self) -> Vec<&'static str> {
        self.inner.model().param_names().to_vec()
    }

    /// Image width (pixels).
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width()
    }

    /// Image height (pixels).
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height()
    }

    /// The camera matrix (3×3).
    #[getter(K)]
    #[allow(non_snake_case)]
    fn K<'py>(&self, py: Python<'py>) -> Array<'py> {
        let mut out = vec![0.0; 9];
        write_rows(&self.inner.k_matrix(), &mut out);
        to_numpy(py, out, &[3, 3])
    }

    /// Pixels of camera-frame points: `(..., 3)` → `(..., 2)`.
    fn project<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>) -> Array<'py> {
        let (data, lead) = finite_batch(points, "points", &[3], "(..., 3)")?;
        let pts = fixed_rows::<3>(&data);
        let mut out = vec![[0.0; 2]; pts.len()];
        convert::run_batched(py, data.len(), || {
            self.inner
                .par_project_into(&pts, &mut out)
                .map_err(|e| errors::geometry(unbatched(e, !lead.is_empty())))
        })?;
        to_numpy(py, out.concat(), &batched_shape(&lead, &[2]))
    }

    /// Pixels and their Jacobians with respect to the point and the parameters:
    /// `(..., 3)` → `(..., 2)`, `(..., 2, 3)`, `(..., 2, n)`.
    fn project_jacobians<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Arrays3<'py>> {
        let (pts, lead) = vectors::<3>(points, "points", "(..., 3)")?;
        let n = self.inner.model().num_params();
        let stride = 2 + 6 + 2 * n;
        let all = map_items(py, &pts, !lead.is_empty(), stride, |p, o| {
            let (px, j_pt, j_par) = self.inner.project_jacobians(p)?;
            o[..2].copy_from_slice(px.as_slice());
            write_rows(&j_pt, &mut o[2..8]);
            for (k, v) in o[8..].iter_mut().enumerate() {
                *v = j_par[(k / n, k % n)];
            }
            Ok(())
        })?;
        let count = pts.len();
        let (mut px, mut j_pt, mut j_par) = (
            Vec::with_capacity(2 * count),
            Vec::with_capacity(6 * count),
            Vec::with_capacity(2 * n * count),
        );
        for item in all.chunks_exact(stride) {
            px.extend_from_slice(&item[..2]);
            j_pt.extend_from_slice(&item[2..8]);
            j_par.extend_from_slice(&item[8..]);
        }
        Ok((
            to_numpy(py, px, &batched_shape(&lead, &[2]))?,
            to_numpy(py, j_pt, &batched_shape(&lead, &[2, 3]))?,
            to_numpy(py, j_par, &batched_shape(&lead, &[2, n]))?,
        ))
    }

    /// Unit bearings of pixels: `(..., 2)` → `(..., 3)`.
    fn unproject<'py>(&self, py: Python<'py>, pixels: &Bound<'py, PyAny>) -> Array<'py> {
        let (data, lead) = finite_batch(pixels, "pixels", &[2], "(..., 2)")?;
        let px = fixed_rows::<2>(&data);
        let mut out = vec![[0.0; 3]; px.len()];
        // Unprojection iterates (Newton): count it as several elements per pixel.
        convert::run_batched(py, 4 * data.len(), || {
            self.inner
                .par_unproject_into(&px, &mut out)
                .map_err(|e| errors::geometry(unbatched(e, !lead.is_empty())))
        })?;
        to_numpy(py, out.concat(), &batched_shape(&lead, &[3]))
    }

    /// Whether pixels lie on the image: `(..., 2)` → bool `(...)`; NaN pixels are outside.
    fn in_image<'py>(
        &self,
        py: Python<'py>,
        pixels: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        // Non-finite pixels are allowed here: they are simply not on the image.
        let (data, lead) = convert::Array::new(pixels, "pixels")?.batch(&[2], "(..., 2)")?;
        let inside: Vec<bool> = data
            .chunks_exact(2)
            .map(|c| self.inner.in_image(&nalgebra::Vector2::new(c[0], c[1])))
            .collect();
        let arr = numpy::ndarray::ArrayD::from_shape_vec(numpy::ndarray::IxDyn(&lead), inside)
            .map_err(|e| errors::internal(format!("building the in_image mask: {e}")))?;
        Ok(numpy::IntoPyArray::into_pyarray(arr, py))
    }

    fn __repr__(&self) -> String {
        format!(
            "_core.Camera({:?}, {:?}, {}, {})",
            self.inner.model().name(),
            self.inner.params(),
            self.inner.width(),
            self.inner.height()
        )
    }
}

/// Extracts the core camera from a compiled `_core.Camera` or a Python wrapper holding one in
/// `_inner` (for other binding modules).
#[allow(
    dead_code,
    reason = "for the other binding modules (sim, detect, estimate)"
)]
pub fn camera_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Camera> {
    inner_of::<PyCamera>(obj, name, "Camera").map(|c| c.get().inner.clone())
}

// ---------------------------------------------------------------------------------------------
// Ellipses
// ---------------------------------------------------------------------------------------------

/// The compiled ellipse (`autoteach._core.Ellipse`); see `autoteach.geometry.Ellipse`.
#[pyclass(name = "Ellipse", module = "autoteach._core", frozen)]
pub struct PyEllipse {
    /// The core ellipse.
    pub inner: Ellipse,
}

/// Reads points `(..., 2)`.
fn points2(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
) -> PyResult<(Vec<nalgebra::Vector2<f64>>, Vec<usize>)> {
    vectors::<2>(obj, name, "(..., 2)")
}

#[pymethods]
impl PyEllipse {
    /// Builds (validates and canonicalises) an ellipse.
    #[new]
    fn new(cx: f64, cy: f64, a: f64, b: f64, theta: f64) -> PyResult<Self> {
        let inner = Ellipse::new(cx, cy, a, b, theta).map_err(errors::geometry)?;
        Ok(Self { inner })
    }

    /// The ellipse of a 3×3 conic matrix.
    #[staticmethod]
    #[pyo3(signature = (C))]
    #[allow(non_snake_case)]
    fn from_conic(C: &Bound<'_, PyAny>) -> PyResult<Self> {
        let c = matrix3(C, "C")?;
        // The core uses the symmetric part; the Python API promises to refuse an asymmetric C.
        let asym = (c - c.transpose()).norm();
        if asym.is_nan() || asym > 1e-9 * c.norm() {
            return Err(errors::invalid_input(format!(
                "C must be a symmetric 3×3 conic matrix, got |C − Cᵀ| = {asym:.3e} (|C| = {:.3e})",
                c.norm()
            )));
        }
        let inner = convert::guarded(|| Ellipse::from_conic(&c).map_err(errors::geometry))?;
        Ok(Self { inner })
    }

    /// Centre x.
    #[getter]
    fn cx(&self) -> f64 {
        self.inner.cx
    }

    /// Centre y.
    #[getter]
    fn cy(&self) -> f64 {
        self.inner.cy
    }

    /// Semi-major axis.
    #[getter]
    fn a(&self) -> f64 {
        self.inner.a
    }

    /// Semi-minor axis.
    #[getter]
    fn b(&self) -> f64 {
        self.inner.b
    }

    /// Orientation of the major axis.
    #[getter]
    fn theta(&self) -> f64 {
        self.inner.theta
    }

    /// Area `π a b`.
    #[getter]
    fn area(&self) -> f64 {
        self.inner.area()
    }

    /// Perimeter.
    #[getter]
    fn perimeter(&self) -> f64 {
        self.inner.perimeter()
    }

    /// The conic matrix (value −1 at the centre).
    fn conic<'py>(&self, py: Python<'py>) -> Array<'py> {
        let mut out = vec![0.0; 9];
        write_rows(&self.inner.conic(), &mut out);
        to_numpy(py, out, &[3, 3])
    }

    /// `(A, B, C, D, E, F)`, unit norm.
    fn conic_coefficients<'py>(&self, py: Python<'py>) -> Array<'py> {
        to_numpy(py, self.inner.conic_coefficients().to_vec(), &[6])
    }

    /// Points at eccentric angles: `(...)` → `(..., 2)`.
    fn point_at<'py>(&self, py: Python<'py>, t: &Bound<'py, PyAny>) -> Array<'py> {
        let (ts, lead) = finite_batch(t, "t", &[], "(...)")?;
        map_batch(py, &ts, &lead, &[2], |t, o| {
            o.copy_from_slice(self.inner.point_at(*t).as_slice());
            Ok(())
        })
    }

    /// `n` points at evenly spaced eccentric angles from `t0` to `t1`: `(n, 2)`.
    fn sample<'py>(&self, py: Python<'py>, n: i64, t0: f64, t1: f64) -> Array<'py> {
        let n = usize::try_from(n)
            .map_err(|_| errors::invalid_input(format!("n must be at least 2, got {n}")))?;
        let pts = convert::run_batched(py, n * 2, || {
            self.inner.sample(n, t0, t1).map_err(errors::geometry)
        })?;
        let data = pts.iter().flat_map(|p| [p.x, p.y]).collect();
        to_numpy(py, data, &[pts.len(), 2])
    }

    /// Distances of points `(..., 2)` → `(...)`; `kind` is "orthogonal", "sampson" or
    /// "algebraic".
    fn distance<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>, kind: &str) -> Array<'py> {
        type Batch = fn(&Ellipse, &[nalgebra::Vector2<f64>]) -> Vec<f64>;
        let f: Batch = match kind {
            "orthogonal" => Ellipse::orthogonal_distances,
            "sampson" => Ellipse::sampson_distances,
            "algebraic" => Ellipse::algebraic_distances,
            other => {
                return Err(errors::invalid_input(format!(
                    "kind must be \"orthogonal\", \"sampson\" or \"algebraic\", got {other:?}"
                )));
            }
        };
        let (pts, lead) = points2(points, "points")?;
        let out = convert::run_batched(py, pts.len() * 2, || Ok(f(&self.inner, &pts)))?;
        to_numpy(py, out, &lead)
    }

    /// Closest points on the ellipse: `(..., 2)` → `(..., 2)`.
    fn closest_point<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>) -> Array<'py> {
        let (pts, lead) = points2(points, "points")?;
        let out = convert::run_batched(py, pts.len() * 2, || Ok(self.inner.closest_points(&pts)))?;
        let data = out.iter().flat_map(|p| [p.x, p.y]).collect();
        to_numpy(py, data, &batched_shape(&lead, &[2]))
    }

    fn __repr__(&self) -> String {
        let e = &self.inner;
        format!(
            "_core.Ellipse(cx={:?}, cy={:?}, a={:?}, b={:?}, theta={:?})",
            e.cx, e.cy, e.a, e.b, e.theta
        )
    }
}

/// Extracts the core ellipse from a compiled `_core.Ellipse` or a Python wrapper holding one in
/// `_inner` (for other binding modules).
#[allow(
    dead_code,
    reason = "for the other binding modules (sim, detect, estimate)"
)]
pub fn ellipse_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Ellipse> {
    inner_of::<PyEllipse>(obj, name, "Ellipse").map(|e| e.get().inner)
}

/// Reads a circle radius: finite (positivity is the core's check).
fn radius_arg(radius: f64) -> PyResult<f64> {
    finite_scalar(radius, "radius")?;
    Ok(radius)
}

/// Image conic (unit Frobenius norm) of a circle of `radius` in the `z = 0` plane of the object
/// frame, `T_co` mapping object to camera coordinates: 3×3.
#[pyfunction]
#[pyo3(signature = (K, T_co, radius))]
#[allow(non_snake_case)]
fn circle_image_conic<'py>(
    py: Python<'py>,
    K: &Bound<'py, PyAny>,
    T_co: &Bound<'py, PyAny>,
    radius: f64,
) -> Array<'py> {
    let k = matrix3(K, "K")?;
    let t = convert::isometry(T_co, "T_co")?;
    let r = radius_arg(radius)?;
    let c = convert::guarded(|| conic::circle_image_conic(&k, &t, r).map_err(errors::geometry))?;
    let mut out = vec![0.0; 9];
    write_rows(&c, &mut out);
    to_numpy(py, out, &[3, 3])
}

/// The ellipse a world circle (centre, normal, radius) projects to under `K`, `T_cw`.
#[pyfunction]
#[pyo3(signature = (K, T_cw, center, normal, radius))]
#[allow(non_snake_case)]
fn project_circle(
    K: &Bound<'_, PyAny>,
    T_cw: &Bound<'_, PyAny>,
    center: &Bound<'_, PyAny>,
    normal: &Bound<'_, PyAny>,
    radius: f64,
) -> PyResult<PyEllipse> {
    let k = matrix3(K, "K")?;
    let t = convert::isometry(T_cw, "T_cw")?;
    let c: Vector3<f64> = vector::<3>(center, "center")?;
    let n: Vector3<f64> = vector::<3>(normal, "normal")?;
    let r = radius_arg(radius)?;
    let inner = convert::guarded(|| {
        conic::project_circle_world(&k, &t, &c, &n, r).map_err(errors::geometry)
    })?;
    Ok(PyEllipse { inner })
}

/// The ellipse of a circle in the object frame's `z = 0` plane and its 5×6 Jacobian with
/// respect to the right perturbation of `T_co`.
#[pyfunction]
#[pyo3(signature = (K, T_co, radius))]
#[allow(non_snake_case)]
fn project_circle_jacobian<'py>(
    py: Python<'py>,
    K: &Bound<'py, PyAny>,
    T_co: &Bound<'py, PyAny>,
    radius: f64,
) -> PyResult<(PyEllipse, Bound<'py, PyArrayDyn<f64>>)> {
    let k = matrix3(K, "K")?;
    let t = convert::isometry(T_co, "T_co")?;
    let r = radius_arg(radius)?;
    let (inner, j) =
        convert::guarded(|| conic::project_circle_jacobian(&k, &t, r).map_err(errors::geometry))?;
    let mut out = vec![0.0; 30];
    write_rows(&j, &mut out);
    Ok((PyEllipse { inner }, to_numpy(py, out, &[5, 6])?))
}
