//! A node's local laser scan (seed 004_815695db12a6b16c.txt §2.1: "each node is associated
//! with a local occupancy grid taken at that moment") and its projection into the global
//! grid at a quantised pose.

use crate::{EstimateError, Result};

/// Geometry of a planar laser scan: beam k points at `angle_min + k·angle_increment` in the
/// node frame; returns at or beyond `max_range` are "no return" (free space up to
/// `max_range`). Defaults: the 270°, 1081-beam, 30 m laser of the seed (Hokuyo UTM-30LX,
/// §4.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanGeometry {
    /// Angle of beam 0 (rad).
    pub angle_min: f64,
    /// Angle between beams (rad).
    pub angle_increment: f64,
    /// Maximum range (m).
    pub max_range: f64,
}

impl Default for ScanGeometry {
    fn default() -> Self {
        let fov = 270f64.to_radians();
        Self {
            angle_min: -fov / 2.0,
            angle_increment: fov / 1080.0,
            max_range: 30.0,
        }
    }
}

impl ScanGeometry {
    /// Checks the parameters (finite; positive range).
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("angle_min", self.angle_min),
            ("angle_increment", self.angle_increment),
            ("max_range", self.max_range),
        ] {
            if !v.is_finite() {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be finite",
                });
            }
        }
        if self.max_range <= 0.0 {
            return Err(EstimateError::InvalidParameter {
                name: "max_range",
                value: self.max_range,
                reason: "must be positive",
            });
        }
        Ok(())
    }
}

/// A scan reduced to beam end points in the node frame (metres), each flagged as a hit
/// (structure at the end) or a no-return (free up to `max_range`).
///
/// Range handling (documented, not an error): `NaN` = an invalid return, the beam is
/// dropped (counted in [`LocalScan::dropped`]); `+inf` or ≥ `max_range` = no return. A
/// negative range or `−inf` is an error.
#[derive(Debug, Clone, Default)]
pub struct LocalScan {
    /// End points `[x, y]` in the node frame.
    pub ends: Vec<[f32; 2]>,
    /// Whether end `k` is a hit.
    pub hit: Vec<bool>,
    /// Beams dropped for NaN ranges.
    pub dropped: usize,
}

impl LocalScan {
    /// From ranges (m) of a scan with geometry `g`; `node` names the node in errors.
    pub fn from_ranges(ranges: &[f64], g: &ScanGeometry, node: u64) -> Result<Self> {
        let mut s = LocalScan {
            ends: Vec::with_capacity(ranges.len()),
            hit: Vec::with_capacity(ranges.len()),
            dropped: 0,
        };
        for (k, &r) in ranges.iter().enumerate() {
            if r.is_nan() {
                s.dropped += 1;
                continue;
            }
            if r < 0.0 {
                return Err(EstimateError::InvalidMapInput(format!(
                    "scans: node {node}, beam {k} has range {}; a range must be >= 0 (NaN for \
                     an invalid return, +inf for no return)",
                    autoteach_geometry::error::Num(r)
                )));
            }
            let hit = r < g.max_range;
            let r = if hit { r } else { g.max_range };
            let a = g.angle_min + k as f64 * g.angle_increment;
            s.ends.push([(r * a.cos()) as f32, (r * a.sin()) as f32]);
            s.hit.push(hit);
        }
        Ok(s)
    }
}

/// A pose quantised to a lattice fine enough that moving to a neighbouring lattice point
/// moves every beam end by less than one cell: translation step `resolution / 2`, rotation
/// step `resolution / (2 · max_range)`. The rasterizer projects every node at its quantised
/// posterior, so "the projection changed" (§2.3: "more than 1 grid cell of change in its
/// projection") is an exact integer comparison, and every method projects identically.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct QuantizedPose {
    /// x / (resolution / 2), rounded.
    pub ix: i64,
    /// y / (resolution / 2), rounded.
    pub iy: i64,
    /// θ / (resolution / (2 max_range)), rounded (θ wrapped to (−π, π]).
    pub it: i64,
}

/// Quantisation steps (translation m, rotation rad) for a resolution and range.
pub fn quanta(resolution: f64, max_range: f64) -> (f64, f64) {
    (resolution / 2.0, resolution / (2.0 * max_range))
}

impl QuantizedPose {
    /// Quantises a pose `[x, y, θ]`.
    pub fn new(p: &[f64; 3], q: (f64, f64)) -> Self {
        let th = crate::lsq::se2::wrap_angle(p[2]);
        Self {
            ix: (p[0] / q.0).round() as i64,
            iy: (p[1] / q.0).round() as i64,
            it: (th / q.1).round() as i64,
        }
    }

    /// The lattice pose.
    pub fn pose(&self, q: (f64, f64)) -> [f64; 3] {
        [
            self.ix as f64 * q.0,
            self.iy as f64 * q.0,
            self.it as f64 * q.1,
        ]
    }
}
