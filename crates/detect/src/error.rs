//! The error type of this crate.

use autoteach_geometry::error::Num;
use thiserror::Error;

/// Everything that can go wrong in this crate. Messages carry the offending values.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DetectError {
    /// An error from the geometry crate.
    #[error(transparent)]
    Geometry(#[from] autoteach_geometry::GeometryError),
    /// Too few points (or too few distinct points) for the requested fit.
    #[error("{what}: too few points: got {got}, need at least {needed}")]
    TooFewPoints {
        /// The argument (as the caller names it).
        what: &'static str,
        /// Number of (distinct) points received.
        got: usize,
        /// Minimum number required.
        needed: usize,
    },
    /// An input coordinate was NaN or infinite.
    #[error("{what} must be finite, got {value} at index {index}")]
    NonFinite {
        /// Which input held the value.
        what: &'static str,
        /// Index of the offending point or element.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// The data are geometrically degenerate for the requested fit (collinear or coincident
    /// points, points that lie on a hyperbola or a line pair rather than an ellipse).
    #[error("degenerate data: {reason}")]
    Degenerate {
        /// Why, with the numbers.
        reason: String,
    },
    /// The Jacobian of a fit is rank deficient, so the parameters (and their covariance) are
    /// not determined by the data.
    #[error("rank-deficient fit: {reason}")]
    RankDeficient {
        /// Which parameters are undetermined, with the numbers.
        reason: String,
    },
    /// An option or parameter is outside its valid domain.
    #[error("invalid parameter {what} = {}: {reason}", Num(*.value))]
    InvalidParameter {
        /// Parameter name.
        what: &'static str,
        /// Its value.
        value: f64,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// An assignment cost is NaN or −∞ (+∞ is allowed and means "forbidden pair").
    #[error("invalid {what} {value} at ({row}, {col}): costs must be finite or +inf (forbidden)")]
    InvalidCost {
        /// Which input held the value (the cost matrix or a non-assignment cost vector).
        what: &'static str,
        /// Row of the offending entry (for a per-row/per-column vector, its index).
        row: usize,
        /// Column of the offending entry (0 for a vector).
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// An input vector has the wrong length.
    #[error("{what} has length {got}, expected {expected}")]
    WrongLength {
        /// Which input.
        what: &'static str,
        /// Length received.
        got: usize,
        /// Length required.
        expected: usize,
    },
    /// No assignment satisfies the constraints (for example an infinite non-assignment cost
    /// for a row whose every pair is forbidden), or the costs overflow `f64`.
    #[error("infeasible assignment: {reason}")]
    Infeasible {
        /// Why, with the numbers.
        reason: String,
    },
}
