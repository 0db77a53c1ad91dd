//! The Python exception hierarchy of autoteach, and the mapping from each core error variant
//! to the exception a caller would catch.
//!
//! ```text
//! AutoteachError(Exception)
//! ├── InvalidInputError(AutoteachError, ValueError)       wrong shape, dtype, NaN, bad parameter
//! ├── DegenerateGeometryError(AutoteachError, ValueError) degenerate conic, collinear points
//! ├── UnreachablePoseError(AutoteachError, ValueError)    inverse kinematics has no solution
//! ├── ConvergenceError(AutoteachError, RuntimeError)      an iteration did not converge
//! ├── AllocationError(AutoteachError, MemoryError)        an input asks for more memory than exists
//! └── InternalError(AutoteachError, RuntimeError)         a bug: a Rust panic caught at the boundary
//! ```
//! The classes are built at module initialisation (so they can derive from both
//! `AutoteachError` and the matching built-in) and live in `autoteach._core`.
//!
//! Every core error enum (`GeometryError`, `EstimateError`, `DetectError`, `PlanError`) is
//! mapped here by an exhaustive `match` with no catch-all arm. Adding a variant to one of them
//! fails to compile until it gets an arm: choose the class by who must act — the caller's input
//! (`InvalidInputError`), the data's geometry (`DegenerateGeometryError`), a pose out of reach
//! (`UnreachablePoseError`), the numerics (`ConvergenceError`) or memory (`AllocationError`).

use autoteach_geometry::GeometryError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// The exception classes, by name, in creation order: (name, built-in second base, doc).
const CLASSES: &[(&str, Option<&str>, &str)] = &[
    (
        "InvalidInputError",
        Some("ValueError"),
        "An input has the wrong shape, dtype, a NaN/inf, or an invalid value.",
    ),
    (
        "DegenerateGeometryError",
        Some("ValueError"),
        "The data are geometrically degenerate (collinear points, a degenerate conic, ...).",
    ),
    (
        "UnreachablePoseError",
        Some("ValueError"),
        "A requested robot pose cannot be reached.",
    ),
    (
        "ConvergenceError",
        Some("RuntimeError"),
        "An iterative computation did not converge.",
    ),
    (
        "AllocationError",
        Some("MemoryError"),
        "An input asks for a buffer larger than memory (a huge sample count or dimension).",
    ),
    (
        "InternalError",
        Some("RuntimeError"),
        "A bug inside autoteach (a Rust panic caught at the Python boundary).",
    ),
];

/// Creates `AutoteachError` and its subclasses and adds them to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    let builtins = py.import("builtins")?;
    let type_ = builtins.getattr("type")?;
    let exception = builtins.getattr("Exception")?;
    let ns = PyDict::new(py);
    ns.set_item("__doc__", "Base class of every error raised by autoteach.")?;
    ns.set_item("__module__", "autoteach")?;
    let base = type_.call1(("AutoteachError", PyTuple::new(py, [exception])?, ns))?;
    m.add("AutoteachError", &base)?;
    for (name, builtin, doc) in CLASSES {
        let mut bases = vec![base.clone()];
        if let Some(b) = builtin {
            bases.push(builtins.getattr(*b)?);
        }
        let ns = PyDict::new(py);
        ns.set_item("__doc__", *doc)?;
        ns.set_item("__module__", "autoteach")?;
        let cls = type_.call1((*name, PyTuple::new(py, bases)?, ns))?;
        m.add(*name, cls)?;
    }
    Ok(())
}

/// Builds an instance of the autoteach exception `class` with `message`.
pub fn new_err(class: &str, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| {
        let cls = py
            .import("autoteach._core")
            .and_then(|m| m.getattr(class))
            .and_then(|c| c.cast_into::<pyo3::types::PyType>().map_err(PyErr::from));
        match cls {
            Ok(cls) => PyErr::from_type(cls, message),
            Err(e) => e,
        }
    })
}

/// `InvalidInputError(message)`.
pub fn invalid_input(message: impl Into<String>) -> PyErr {
    new_err("InvalidInputError", message)
}

/// `InternalError(message)`.
pub fn internal(message: impl Into<String>) -> PyErr {
    new_err("InternalError", message)
}

/// Maps a geometry error to its Python exception.
pub fn geometry(err: GeometryError) -> PyErr {
    new_err(geometry_class(&err), err.to_string())
}

/// The name of the exception class a geometry error maps to (a batch error takes the class of
/// the failing element's error).
fn geometry_class(err: &GeometryError) -> &'static str {
    match err {
        GeometryError::NonFinite { .. }
        | GeometryError::WrongLength { .. }
        | GeometryError::InvalidParameter { .. }
        | GeometryError::NotProjectable { .. }
        | GeometryError::NotUnprojectable { .. }
        | GeometryError::UnknownModel { .. }
        | GeometryError::DegenerateQuaternion { .. } => "InvalidInputError",
        GeometryError::Unreachable { .. } => "UnreachablePoseError",
        GeometryError::DegenerateConic { .. } => "DegenerateGeometryError",
        GeometryError::NoConvergence { .. } => "ConvergenceError",
        GeometryError::OutOfMemory { .. } => "AllocationError",
        GeometryError::AtIndex { source, .. } => geometry_class(source),
    }
}

/// Maps an estimation error to its Python exception: bad inputs (sizes, parameters, NaN/inf
/// inputs, invalid P/Q/R, a failing model) → `InvalidInputError`; a covariance that lost
/// positive definiteness or symmetry, or NaN produced during filtering (the recursion broke
/// down at the named step) → `ConvergenceError`.
pub fn estimate(err: autoteach_estimate::EstimateError) -> PyErr {
    use autoteach_estimate::EstimateError as E;
    match err {
        E::Geometry(e) => geometry(e),
        E::DimensionMismatch { .. }
        | E::InvalidParameter { .. }
        | E::NonFiniteInput { .. }
        | E::InvalidCovariance { .. }
        | E::Model { .. } => invalid_input(err.to_string()),
        E::InvalidProblem(_) | E::TooFewPoints { .. } => invalid_input(err.to_string()),
        E::InvalidMapInput(_) => invalid_input(err.to_string()),
        E::InvalidModel { .. } => invalid_input(err.to_string()),
        // An unconstrained direction (gauge freedom), a singular information matrix, a
        // calibration that the views cannot determine, no pose meeting the constraints.
        E::RankDeficient { .. } | E::SingularInformation { .. } | E::DegenerateCalibration(_) => {
            new_err("DegenerateGeometryError", err.to_string())
        }
        E::NoFeasiblePose { .. } => new_err("UnreachablePoseError", err.to_string()),
        E::NotPositiveDefinite { .. }
        | E::NotSymmetric { .. }
        | E::NonFinite { .. }
        | E::NonFiniteResidual { .. }
        | E::LinearSolver(_)
        | E::NoConvergence { .. } => new_err("ConvergenceError", err.to_string()),
        // Radio models (issue 33): a kernel that is not positive definite on the data, a
        // link with coincident ends or outside the map, an empty training set.
        E::KernelNotPositiveDefinite { .. }
        | E::CoincidentLink { .. }
        | E::OutsideMap { .. }
        | E::EmptyInput(_)
        | E::InvalidInput(_) => invalid_input(err.to_string()),
    }
}

/// Maps a detection error to its Python exception: bad inputs (too few points, NaN/inf, invalid
/// costs, lengths or options, an infeasible assignment) → `InvalidInputError`; degenerate data
/// (collinear or coincident points, a hyperbola, an undetermined fit) → `DegenerateGeometryError`.
pub fn detect(err: autoteach_detect::DetectError) -> PyErr {
    use autoteach_detect::DetectError as E;
    match err {
        E::Geometry(e) => geometry(e),
        E::TooFewPoints { .. }
        | E::NonFinite { .. }
        | E::InvalidParameter { .. }
        | E::InvalidCost { .. }
        | E::WrongLength { .. }
        | E::Infeasible { .. } => invalid_input(err.to_string()),
        E::Degenerate { .. } | E::RankDeficient { .. } => {
            new_err("DegenerateGeometryError", err.to_string())
        }
    }
}

/// Maps a planning error to its Python exception: a configuration in collision, malformed input
/// and infeasible limits → `InvalidInputError`; no path within the budget → `ConvergenceError`.
pub fn plan(err: autoteach_geometry::plan::PlanError) -> PyErr {
    use autoteach_geometry::plan::PlanError as E;
    match err {
        E::Geometry(e) => geometry(e),
        E::InvalidInput { .. } | E::InCollision { .. } | E::Infeasible { .. } => {
            invalid_input(err.to_string())
        }
        E::NoPath { .. } => new_err("ConvergenceError", err.to_string()),
    }
}
