//! The covering test of seed 004_815695db12a6b16c.txt §2.4 ("Spatially non-redundant node
//! coverings"): a new node joins its robot's cover C_r unless a node already in C_r was
//! taken at nearly the same place AND looks in nearly the same direction (so its field of
//! view nearly coincides): "if both of these are too similar to an existing measurement, we
//! can remove it from the covering."

use crate::lsq::se2::wrap_angle;
use crate::{EstimateError, Result};

/// Thresholds of the covering test. A node is redundant if some covered node lies within
/// `distance` metres and its heading within `angle` radians. The defaults (0.75 m, 30°)
/// drop only revisits of a place along the same heading: with a 270° field of view two such
/// scans see the same walls from nearly the same viewpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoverTest {
    /// Position threshold (m).
    pub distance: f64,
    /// Heading threshold (rad).
    pub angle: f64,
}

impl Default for CoverTest {
    fn default() -> Self {
        Self {
            distance: 0.75,
            angle: 30f64.to_radians(),
        }
    }
}

impl CoverTest {
    /// Checks the thresholds (finite, non-negative).
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("cover distance", self.distance),
            ("cover angle", self.angle),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be finite and non-negative",
                });
            }
        }
        Ok(())
    }

    /// `coverTest(v, C_r)` of Algorithm 2.1: true if the node at `pose` adds a view the
    /// covered poses lack.
    pub fn admits<'a>(&self, pose: &[f64; 3], covered: impl Iterator<Item = &'a [f64; 3]>) -> bool {
        let d2 = self.distance * self.distance;
        !covered.into_iter().any(|c| {
            let (dx, dy) = (c[0] - pose[0], c[1] - pose[1]);
            dx * dx + dy * dy < d2 && wrap_angle(c[2] - pose[2]).abs() < self.angle
        })
    }
}
