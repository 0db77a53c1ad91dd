//! # autoteach-detect
//!
//! Detection and association for autoteach (seed 000_3b1454b2b2194811.txt ch. 3–4). So far:
//! the rectangular assignment solver shared by arc merging (Algorithms 1–2) and tracking
//! ([`assignment`]), and ellipse fitting: the Halir–Flusser direct fit and an
//! orthogonal-distance Levenberg–Marquardt refinement with its covariance ([`ellipse`]).
//!
//! ```
//! use autoteach_detect::assignment::solve_assignment;
//! use autoteach_detect::ellipse::{fit_ellipse, FitMethod};
//! use autoteach_geometry::conic::Ellipse;
//! use nalgebra::DMatrix;
//!
//! // A 120° arc of an ellipse, fitted by orthogonal distance.
//! let truth = Ellipse::new(320.0, 240.0, 150.0, 60.0, 0.2)?;
//! let arc = truth.sample(80, 0.0, 2.0 * std::f64::consts::PI / 3.0)?;
//! let fit = fit_ellipse(&arc, FitMethod::Geometric)?;
//! assert!((fit.ellipse.cx - truth.cx).abs() < 1e-6);
//!
//! // Minimum-cost one-to-one assignment.
//! let cost = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 2.0, 8.0]);
//! let a = solve_assignment(&cost)?;
//! assert_eq!(a.row_to_col, vec![Some(1), Some(0)]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The wafer-rim detector ([`wafers::detect_wafers`]) stage by stage on an image of your own
//! (8-bit grey, raw bytes): `cargo run --release -p autoteach-detect --example wafer_stages --
//! IMAGE.raw WIDTH HEIGHT` prints the arcs, the assembled elliptic segments and the rims.
#![deny(missing_docs)]

pub mod assembly;
pub mod assignment;
pub mod cpd;
pub mod edges;
pub mod ellipse;
pub mod ellipse_detection;
pub mod error;
pub mod fusion;
pub mod lapjv;
pub mod polygon;
pub mod track;
pub mod uncertainty;
pub mod voting;
pub mod wafer_rims;
pub mod wafers;

pub use error::DetectError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, DetectError>;
pub mod segment;
