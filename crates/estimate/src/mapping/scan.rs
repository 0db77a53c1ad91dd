//! A node's local laser scan (seed 004_815695db12a6b16c.txt §2.1: "each node is associated
//! with a local occupancy grid taken at that moment") and its projection into the global
//! grid.

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

/// The largest displacement (m) of a point within `reach` of the sensor when the node's pose
/// changes from `from` to `to` (`[x, y, θ]`): a point `e` of the node frame moves by
/// `Δt + (R(θ') − R(θ))·e`, and `R(θ') − R(θ)` is `2 sin(Δθ/2)` times a rotation, so the
/// largest move over `|e| ≤ reach` is `|Δt| + 2|sin(Δθ/2)|·reach`. The rasterizer re-renders a
/// node when this exceeds one cell (seed §2.3: "more than 1 grid cell of change in its
/// projection"); it bounds every scan's projection (all beams end within `max_range`) and does
/// not depend on what the scan saw, so a run with transient objects hidden re-renders the
/// same nodes.
pub fn footprint_displacement(from: &[f64; 3], to: &[f64; 3], reach: f64) -> f64 {
    let dt = (to[0] - from[0]).hypot(to[1] - from[1]);
    dt + 2.0 * (0.5 * (to[2] - from[2])).sin().abs() * reach
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the brute-force largest displacement of points of the disc of radius `reach`
    /// (rings of 720 points, the rim included).
    #[test]
    fn footprint_displacement_matches_brute_force() {
        let reach = 30.0;
        let place = |p: &[f64; 3], e: [f64; 2]| {
            let (s, c) = p[2].sin_cos();
            [p[0] + c * e[0] - s * e[1], p[1] + s * e[0] + c * e[1]]
        };
        let from = [3.0, -2.0, 0.4];
        for k in 0..60 {
            let t = k as f64 / 60.0;
            let to = [
                from[0] + 0.08 * (7.0 * t).sin(),
                from[1] + 0.06 * (5.0 * t).cos(),
                from[2]
                    + 0.006 * (11.0 * t).sin()
                    + if k == 59 {
                        2.0 * std::f64::consts::PI
                    } else {
                        0.0
                    },
            ];
            let mut worst: f64 = 0.0;
            for ring in 0..=10 {
                let r = reach * ring as f64 / 10.0;
                for a in 0..720 {
                    let a = a as f64 * std::f64::consts::PI / 360.0;
                    let e = [r * a.cos(), r * a.sin()];
                    let (p, q) = (place(&from, e), place(&to, e));
                    worst = worst.max((q[0] - p[0]).hypot(q[1] - p[1]));
                }
            }
            let got = footprint_displacement(&from, &to, reach);
            assert!(
                got >= worst - 1e-9 && got <= worst + 1e-4 * (1.0 + worst),
                "step {k}: {got} vs {worst}"
            );
        }
    }
}
