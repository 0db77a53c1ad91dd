//! The error type of this crate.

use thiserror::Error;

/// Everything that can go wrong in this crate. Messages carry the offending values.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DetectError {
    /// An error from the geometry crate.
    #[error(transparent)]
    Geometry(#[from] autoteach_geometry::GeometryError),
}
