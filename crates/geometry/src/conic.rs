//! Ellipses and conics (000_3b1454b2b2194811.txt ch. 3.2, eq. 3.1–3.3).

/// An ellipse in the image plane, eq. (3.1)/(3.2): centre `(cx, cy)`, semi-axes `a ≥ b > 0`
/// and orientation `theta` (radians, of the `a` axis from the x axis, in `(-π/2, π/2]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipse {
    /// Centre x (pixels).
    pub cx: f64,
    /// Centre y (pixels).
    pub cy: f64,
    /// Semi-major axis.
    pub a: f64,
    /// Semi-minor axis.
    pub b: f64,
    /// Orientation of the major axis.
    pub theta: f64,
}
