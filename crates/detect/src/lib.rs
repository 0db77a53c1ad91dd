//! # autoteach-detect
//!
//! Detection and association for autoteach: assignment (Hungarian / Jonker–Volgenant),
//! ellipse fitting, and later arcs, Hough voting, coherent point drift and tracking.
#![deny(missing_docs)]

pub mod assignment;
pub mod ellipse;
pub mod error;

pub use error::DetectError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, DetectError>;
