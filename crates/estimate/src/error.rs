//! The error type of this crate.

use thiserror::Error;

/// Everything that can go wrong in this crate. Messages carry the offending values.
///
/// `#[non_exhaustive]` so that estimation engines can add variants without breaking the
/// bindings' mapping to Python exceptions.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum EstimateError {
    /// An error from the geometry crate.
    #[error(transparent)]
    Geometry(#[from] autoteach_geometry::GeometryError),

    /// A vector or matrix has the wrong size for the filter or model it is given to.
    #[error("{what}: expected shape {expected:?}, got {got:?}")]
    DimensionMismatch {
        /// What was passed (e.g. `"measurement z"`).
        what: String,
        /// The expected shape.
        expected: Vec<usize>,
        /// The shape received.
        got: Vec<usize>,
    },

    /// A parameter is outside its valid range.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// Why it is invalid.
        reason: &'static str,
    },

    /// An input contains NaN or ±inf.
    #[error("{what} contains a non-finite value {value} at index {index}")]
    NonFiniteInput {
        /// What was passed.
        what: String,
        /// The flat (column-major for matrices) index of the first offending element.
        index: usize,
        /// The offending value.
        value: f64,
    },

    /// A covariance given as input (initial P, Q or R) is not symmetric positive
    /// (semi-)definite.
    #[error(
        "{what} is not a valid covariance: asymmetry {asymmetry:.3e}, smallest eigenvalue {min_eigenvalue:.6e}"
    )]
    InvalidCovariance {
        /// Which matrix.
        what: String,
        /// max |Aᵢⱼ − Aⱼᵢ| relative to max |Aᵢⱼ|.
        asymmetry: f64,
        /// Its smallest eigenvalue (of the symmetric part).
        min_eigenvalue: f64,
    },

    /// A covariance computed by the filter lost positive definiteness (and the repair policy
    /// is off): the run stops instead of propagating it.
    #[error(
        "step {step}: {what} is not positive definite (smallest eigenvalue {min_eigenvalue:.6e}); \
         enable the repair policy to clip eigenvalues instead"
    )]
    NotPositiveDefinite {
        /// Which covariance (e.g. `"predicted covariance P_prior"`).
        what: String,
        /// The filter step (number of predictions before this one, 0-based).
        step: usize,
        /// The smallest eigenvalue of its symmetric part (NaN if it could not be computed).
        min_eigenvalue: f64,
    },

    /// A covariance computed by the filter is far from symmetric (and the repair policy is
    /// off); rounding-level asymmetry is always removed silently.
    #[error("step {step}: {what} is not symmetric (relative asymmetry {asymmetry:.3e})")]
    NotSymmetric {
        /// Which covariance.
        what: String,
        /// The filter step (0-based).
        step: usize,
        /// max |Pᵢⱼ − Pⱼᵢ| relative to max |Pᵢⱼ|.
        asymmetry: f64,
    },

    /// A value computed during filtering (a model output, the state, a covariance) is NaN or
    /// infinite.
    #[error("step {step}: {what} is not finite (value {value} at index {index})")]
    NonFinite {
        /// What became non-finite (e.g. `"fx output at sigma point 3"`).
        what: String,
        /// The filter step (0-based).
        step: usize,
        /// The flat index of the first offending element.
        index: usize,
        /// The offending value.
        value: f64,
    },

    /// A user model (e.g. a Python callback) failed; the message is the model's own.
    #[error("step {step}: the model's {function} failed: {message}")]
    Model {
        /// Which model function (`"fx"`, `"hx"`, `"x_mean"`, …).
        function: &'static str,
        /// The filter step (0-based).
        step: usize,
        /// The model's error message.
        message: String,
    },
}
