//! The error type of the geometry crate.

use thiserror::Error;

/// Everything that can go wrong in `autoteach-geometry`. Messages carry the offending values.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GeometryError {
    /// An input value was NaN or infinite.
    #[error("{what} must be finite, got {value}")]
    NonFinite {
        /// Which input held the value.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A parameter vector or array had the wrong length.
    #[error("{what} has length {got}, expected {expected}")]
    WrongLength {
        /// Which input.
        what: &'static str,
        /// Length received.
        got: usize,
        /// Length required.
        expected: usize,
    },
    /// A parameter is outside its valid domain (for example a non-positive focal length).
    #[error("invalid parameter {what} = {}: {reason}", Num(*.value))]
    InvalidParameter {
        /// Parameter name.
        what: &'static str,
        /// Its value.
        value: f64,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// A desired pose cannot be reached by the robot.
    #[error("pose unreachable: {reason}")]
    Unreachable {
        /// What makes it unreachable, with the numbers.
        reason: String,
    },
    /// A conic is degenerate (not a real, non-degenerate ellipse) for the requested operation.
    #[error("degenerate conic: {reason}")]
    DegenerateConic {
        /// Why, with the numbers.
        reason: String,
    },
    /// A point cannot be projected (behind the camera or outside the model's valid domain).
    #[error(
        "cannot project point ({}, {}, {}): {reason} (a point in the model's field of view is expected)",
        Num(*.x), Num(*.y), Num(*.z)
    )]
    NotProjectable {
        /// Point x.
        x: f64,
        /// Point y.
        y: f64,
        /// Point z.
        z: f64,
        /// Why.
        reason: &'static str,
    },
    /// An iterative computation (undistortion, inverse kinematics refinement) did not converge.
    #[error("{what} did not converge after {iterations} iterations (residual {residual:e})")]
    NoConvergence {
        /// What was being computed.
        what: &'static str,
        /// Iterations spent.
        iterations: usize,
        /// Final residual.
        residual: f64,
    },
    /// A quaternion given as (w, x, y, z) has (near-)zero norm and encodes no rotation.
    #[error(
        "quaternion q = (w={}, x={}, y={}, z={}) has norm {norm:e}: it must be at least {} to normalise",
        Num(*.w), Num(*.x), Num(*.y), Num(*.z), crate::lie::MIN_QUATERNION_NORM
    )]
    DegenerateQuaternion {
        /// Scalar part.
        w: f64,
        /// First vector component.
        x: f64,
        /// Second vector component.
        y: f64,
        /// Third vector component.
        z: f64,
        /// Its Euclidean norm.
        norm: f64,
    },
    /// A camera model name was not recognised.
    #[error(
        "unknown camera model {name:?} (expected \"pinhole\", \"brown_conrady\"/\"opencv\" or \"kannala_brandt\"/\"fisheye\"/\"kb\")"
    )]
    UnknownModel {
        /// The name received.
        name: String,
    },
    /// A pixel has no ray under the camera model (for example it lies outside the image of the
    /// Kannala–Brandt model's monotonic range).
    #[error("cannot unproject pixel ({}, {}): {reason}", Num(*.u), Num(*.v))]
    NotUnprojectable {
        /// Pixel column.
        u: f64,
        /// Pixel row.
        v: f64,
        /// Why.
        reason: &'static str,
    },
    /// An allocation the input asks for cannot be made (its size overflows, or the allocator
    /// refuses it): reported instead of aborting the process.
    #[error(
        "{what} must fit in memory: {elements} elements of {bytes_each} bytes cannot be allocated"
    )]
    OutOfMemory {
        /// What was being allocated.
        what: &'static str,
        /// Number of elements asked for (saturated at `usize::MAX` when the count overflows).
        elements: usize,
        /// Size of one element in bytes.
        bytes_each: usize,
    },
    /// An element of a batch failed; `source` is the error of that element.
    #[error("element {index}: {source}")]
    AtIndex {
        /// Index of the first failing element in the batch.
        index: usize,
        /// What went wrong with it.
        source: Box<GeometryError>,
    },
}

/// A number as a message shows it: plain decimals for ordinary magnitudes, scientific notation
/// beyond them (`{}` alone writes 1e300 as 301 digits and 1e-300 as 300 zeros).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        if v == 0.0 || !v.is_finite() || (1e-4..1e16).contains(&v.abs()) {
            write!(f, "{v}")
        } else {
            write!(f, "{v:e}")
        }
    }
}

/// Returns `Err(NonFinite)` naming `what` if any value is NaN or infinite.
pub fn check_finite(what: &'static str, values: &[f64]) -> crate::Result<()> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(&value) => Err(GeometryError::NonFinite { what, value }),
        None => Ok(()),
    }
}
