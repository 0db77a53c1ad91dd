//! Wafer rims: detection of the elliptic edge segments of wafers in an image, pairing of the
//! upper and lower rim of one wafer, rejection of reflections (seed 000_3b1454b2b2194811.txt
//! ch. 3.1–3.2, 3.5).

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Point2};

/// Which surface of a wafer an elliptic edge segment belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RimKind {
    /// The rim of the upper surface of the wafer.
    Upper,
    /// The rim of the lower surface of the wafer.
    Lower,
}

impl RimKind {
    /// `"upper"` or `"lower"`.
    pub fn as_str(self) -> &'static str {
        match self {
            RimKind::Upper => "upper",
            RimKind::Lower => "lower",
        }
    }
}

/// One detected elliptic edge segment of a wafer rim.
#[derive(Debug, Clone, PartialEq)]
pub struct WaferEdge {
    /// The fitted ellipse (pixels).
    pub ellipse: Ellipse,
    /// The edge points that support it (pixels, (u, v)).
    pub points: Vec<Point2<f64>>,
    /// Mean orthogonal distance of the points to the ellipse (pixels).
    pub residual: f64,
    /// Covariance of (cx, cy, a, b, theta), when the fit provides it.
    pub covariance: Option<Matrix5<f64>>,
    /// Upper or lower rim.
    pub kind: RimKind,
    /// Groups the two rims of one wafer within one image (0, 1, … in image order).
    pub wafer_id: usize,
}
