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
//! The classes are built at module initialisation with `type(...)`, so that each derives from
//! both `AutoteachError` and the matching built-in (pyo3's `create_exception!` takes one base),
//! live in `autoteach._core`, and are kept in a table indexed by [`Class`]: the mapping names a
//! class by that enum, never by a string.
//!
//! Every core error enum (`GeometryError`, `EstimateError`, `DetectError`, `PlanError`) is
//! mapped here by an exhaustive `match` with no catch-all arm. Adding a variant to one of them
//! fails to compile until it gets an arm: choose the class by who must act — the caller's input
//! (`InvalidInputError`), the data's geometry (`DegenerateGeometryError`), a pose out of reach
//! (`UnreachablePoseError`), the numerics (`ConvergenceError`) or memory (`AllocationError`).

use autoteach_geometry::GeometryError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

/// The exception classes below `AutoteachError`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    /// `InvalidInputError(AutoteachError, ValueError)`.
    InvalidInput,
    /// `DegenerateGeometryError(AutoteachError, ValueError)`.
    DegenerateGeometry,
    /// `UnreachablePoseError(AutoteachError, ValueError)`.
    UnreachablePose,
    /// `ConvergenceError(AutoteachError, RuntimeError)`.
    Convergence,
    /// `AllocationError(AutoteachError, MemoryError)`.
    Allocation,
    /// `InternalError(AutoteachError, RuntimeError)`.
    Internal,
}

impl Class {
    /// Every class, in creation order.
    const ALL: [Class; 6] = [
        Class::InvalidInput,
        Class::DegenerateGeometry,
        Class::UnreachablePose,
        Class::Convergence,
        Class::Allocation,
        Class::Internal,
    ];

    /// (Python name, built-in second base, doc).
    fn spec(self) -> (&'static str, &'static str, &'static str) {
        match self {
            Class::InvalidInput => (
                "InvalidInputError",
                "ValueError",
                "An input has the wrong shape, dtype, a NaN/inf, or an invalid value.",
            ),
            Class::DegenerateGeometry => (
                "DegenerateGeometryError",
                "ValueError",
                "The data are geometrically degenerate (collinear points, a degenerate conic, ...).",
            ),
            Class::UnreachablePose => (
                "UnreachablePoseError",
                "ValueError",
                "A requested robot pose cannot be reached.",
            ),
            Class::Convergence => (
                "ConvergenceError",
                "RuntimeError",
                "An iterative computation did not converge.",
            ),
            Class::Allocation => (
                "AllocationError",
                "MemoryError",
                "An input asks for a buffer larger than memory (a huge sample count or dimension).",
            ),
            Class::Internal => (
                "InternalError",
                "RuntimeError",
                "A bug inside autoteach (a Rust panic caught at the Python boundary).",
            ),
        }
    }
}

/// The classes created by [`register`], in [`Class::ALL`] order.
static CLASSES: PyOnceLock<Vec<Py<PyType>>> = PyOnceLock::new();

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
    let mut created = Vec::with_capacity(Class::ALL.len());
    for class in Class::ALL {
        let (name, builtin, doc) = class.spec();
        let bases = [base.clone(), builtins.getattr(builtin)?];
        let ns = PyDict::new(py);
        ns.set_item("__doc__", doc)?;
        ns.set_item("__module__", "autoteach")?;
        let cls = type_
            .call1((name, PyTuple::new(py, bases)?, ns))?
            .cast_into::<PyType>()?;
        m.add(name, &cls)?;
        created.push(cls.unbind());
    }
    // A second initialisation of the module (a sub-interpreter) keeps the first classes.
    let _ = CLASSES.set(py, created);
    Ok(())
}

/// Builds an instance of the autoteach exception `class` with `message`.
pub fn new_err(class: Class, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| match CLASSES.get(py) {
        Some(classes) => PyErr::from_type(classes[class as usize].bind(py).clone(), message),
        // Only before the module is initialised, which no caller can reach.
        None => pyo3::exceptions::PyRuntimeError::new_err(message),
    })
}

/// `InvalidInputError(message)`.
pub fn invalid_input(message: impl Into<String>) -> PyErr {
    new_err(Class::InvalidInput, message)
}

/// `InternalError(message)`.
pub fn internal(message: impl Into<String>) -> PyErr {
    new_err(Class::Internal, message)
}

/// Maps a geometry error to its Python exception.
pub fn geometry(err: GeometryError) -> PyErr {
    new_err(geometry_class(&err), err.to_string())
}

/// The exception class a geometry error maps to (a batch error takes the class of
/// the failing element's error).
fn geometry_class(err: &GeometryError) -> Class {
    match err {
        GeometryError::NonFinite { .. }
        | GeometryError::WrongLength { .. }
        | GeometryError::InvalidParameter { .. }
        | GeometryError::NotProjectable { .. }
        | GeometryError::NotUnprojectable { .. }
        | GeometryError::UnknownModel { .. }
        | GeometryError::DegenerateQuaternion { .. } => Class::InvalidInput,
        GeometryError::Unreachable { .. } => Class::UnreachablePose,
        GeometryError::DegenerateConic { .. } => Class::DegenerateGeometry,
        GeometryError::NoConvergence { .. } => Class::Convergence,
        GeometryError::OutOfMemory { .. } => Class::Allocation,
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
            new_err(Class::DegenerateGeometry, err.to_string())
        }
        E::NoFeasiblePose { .. } => new_err(Class::UnreachablePose, err.to_string()),
        E::NotPositiveDefinite { .. }
        | E::NotSymmetric { .. }
        | E::NonFinite { .. }
        | E::NonFiniteResidual { .. }
        | E::LinearSolver(_)
        | E::NoConvergence { .. } => new_err(Class::Convergence, err.to_string()),
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
            new_err(Class::DegenerateGeometry, err.to_string())
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
        E::NoPath { .. } => new_err(Class::Convergence, err.to_string()),
    }
}
