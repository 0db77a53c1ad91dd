//! The ternary occupancy grid the radio models read (seed 004 §3.2.3: known free space, known
//! structure, unknown) and the line-of-sight traversal that gives each cell's share of a link
//! (the weights `w_i` of eq. 3.2: the length of the transmitter–receiver segment inside the
//! cell).
//!
//! The grid is a plain row-major `(H, W)` class array with a resolution and the world
//! coordinates of its lower-left corner, so an occupancy grid of the team simulator (or a
//! rasterised SLAM map, ch. 2) can feed it directly: cell `(row i, column j)` covers
//! `x ∈ [x0 + j·res, x0 + (j+1)·res)`, `y ∈ [y0 + i·res, y0 + (i+1)·res)`.

use crate::{EstimateError, Result};

/// Class code of known free space.
pub const FREE: u8 = 0;
/// Class code of known structure (occupied).
pub const STRUCTURE: u8 = 1;
/// Class code of unknown (unobserved) space.
pub const UNKNOWN: u8 = 2;
/// Number of map classes.
pub const CLASSES: usize = 3;

/// A regular 2-D grid: `rows × cols` cells of side `resolution` metres, lower-left corner at
/// `origin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeometry {
    /// Number of rows (along y).
    pub rows: usize,
    /// Number of columns (along x).
    pub cols: usize,
    /// Cell side in metres.
    pub resolution: f64,
    /// World coordinates `[x0, y0]` of the grid's lower-left corner.
    pub origin: [f64; 2],
}

impl GridGeometry {
    /// A grid of `rows × cols` cells. Errors: `InvalidParameter` for an empty grid, a
    /// non-positive or non-finite resolution, or a non-finite origin.
    pub fn new(rows: usize, cols: usize, resolution: f64, origin: [f64; 2]) -> Result<Self> {
        if rows == 0 || cols == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "grid shape",
                value: (rows * cols) as f64,
                reason: "the grid must have at least one row and one column",
            });
        }
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "resolution",
                value: resolution,
                reason: "must be a positive finite number of metres",
            });
        }
        if let Some(v) = origin.iter().find(|v| !v.is_finite()) {
            return Err(EstimateError::InvalidParameter {
                name: "origin",
                value: *v,
                reason: "must be finite",
            });
        }
        Ok(Self {
            rows,
            cols,
            resolution,
            origin,
        })
    }

    /// The smallest grid of `resolution` cells covering the box `[x0, x1] × [y0, y1]`, with
    /// its origin at `(x0, y0)`.
    pub fn covering(x0: f64, y0: f64, x1: f64, y1: f64, resolution: f64) -> Result<Self> {
        let cols = (((x1 - x0) / resolution).ceil() as usize).max(1);
        let rows = (((y1 - y0) / resolution).ceil() as usize).max(1);
        Self::new(rows, cols, resolution, [x0, y0])
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.rows * self.cols
    }

    /// Whether the grid has no cell (never true for a grid built by [`GridGeometry::new`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Upper-right corner `[x1, y1]`.
    pub fn far_corner(&self) -> [f64; 2] {
        [
            self.origin[0] + self.cols as f64 * self.resolution,
            self.origin[1] + self.rows as f64 * self.resolution,
        ]
    }

    /// Whether world point `p` lies inside the grid (closed box).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        let [x1, y1] = self.far_corner();
        p[0] >= self.origin[0] && p[0] <= x1 && p[1] >= self.origin[1] && p[1] <= y1
    }

    /// `OutsideMap` for the first of `points` outside the grid.
    pub fn check_inside(&self, what: &str, points: &[[f64; 2]]) -> Result<()> {
        let [x1, y1] = self.far_corner();
        match points.iter().position(|p| !self.contains(*p)) {
            None => Ok(()),
            Some(index) => Err(EstimateError::OutsideMap {
                what: what.to_string(),
                index,
                x: points[index][0],
                y: points[index][1],
                x0: self.origin[0],
                x1,
                y0: self.origin[1],
                y1,
            }),
        }
    }

    /// Flat row-major index of the cell holding world point `p` (points on the far edges
    /// belong to the last row/column), or `None` outside the grid.
    pub fn cell_of(&self, p: [f64; 2]) -> Option<usize> {
        if !self.contains(p) {
            return None;
        }
        let j = (((p[0] - self.origin[0]) / self.resolution) as usize).min(self.cols - 1);
        let i = (((p[1] - self.origin[1]) / self.resolution) as usize).min(self.rows - 1);
        Some(i * self.cols + j)
    }

    /// World coordinates of the centre of cell `(i, j)`.
    pub fn center(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.origin[0] + (j as f64 + 0.5) * self.resolution,
            self.origin[1] + (i as f64 + 0.5) * self.resolution,
        ]
    }

    /// Walks the segment `a → b` through the grid (Amanatides–Woo voxel traversal) and calls
    /// `visit(cell, length)` for every cell it crosses with the length of the segment inside
    /// that cell in metres (the eq. 3.2 weight). The lengths sum to `‖b − a‖` for a segment
    /// inside the grid; parts outside the grid are skipped.
    pub fn traverse(&self, a: [f64; 2], b: [f64; 2], mut visit: impl FnMut(usize, f64)) {
        let r = self.resolution;
        let (gx, gy) = ((a[0] - self.origin[0]) / r, (a[1] - self.origin[1]) / r);
        let (dx, dy) = ((b[0] - a[0]) / r, (b[1] - a[1]) / r);
        let total = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        if total == 0.0 {
            return;
        }
        let (cols, rows) = (self.cols as i64, self.rows as i64);
        let mut ci = (gx.floor() as i64).clamp(0, cols - 1);
        let mut cj = (gy.floor() as i64).clamp(0, rows - 1);
        let step_x: i64 = if dx > 0.0 { 1 } else { -1 };
        let step_y: i64 = if dy > 0.0 { 1 } else { -1 };
        let next_x = |c: i64| {
            if dx > 0.0 {
                ((c + 1) as f64 - gx) / dx
            } else if dx < 0.0 {
                (gx - c as f64) / -dx
            } else {
                f64::INFINITY
            }
        };
        let next_y = |c: i64| {
            if dy > 0.0 {
                ((c + 1) as f64 - gy) / dy
            } else if dy < 0.0 {
                (gy - c as f64) / -dy
            } else {
                f64::INFINITY
            }
        };
        let (mut tx, mut ty) = (next_x(ci), next_y(cj));
        let (dtx, dty) = (1.0 / dx.abs(), 1.0 / dy.abs());
        let mut t = 0.0;
        loop {
            let t_next = tx.min(ty).min(1.0);
            if t_next > t {
                visit((cj * cols + ci) as usize, (t_next - t) * total);
            }
            if t_next >= 1.0 {
                break;
            }
            t = t_next;
            if tx <= ty {
                ci += step_x;
                tx += dtx;
            } else {
                cj += step_y;
                ty += dty;
            }
            if ci < 0 || ci >= cols || cj < 0 || cj >= rows {
                break;
            }
        }
    }
}

/// A ternary occupancy grid: a class ([`FREE`], [`STRUCTURE`], [`UNKNOWN`]) per cell.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassGrid {
    /// Its geometry.
    pub geometry: GridGeometry,
    /// Row-major classes, `rows × cols`.
    pub classes: Vec<u8>,
}

impl ClassGrid {
    /// Wraps a row-major class array. Errors: `DimensionMismatch` when `classes` does not
    /// hold `rows × cols` values, `InvalidParameter` for a class code other than 0, 1, 2.
    pub fn new(geometry: GridGeometry, classes: Vec<u8>) -> Result<Self> {
        if classes.len() != geometry.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "occupancy classes".into(),
                expected: vec![geometry.rows, geometry.cols],
                got: vec![classes.len()],
            });
        }
        if let Some(c) = classes.iter().find(|&&c| c as usize >= CLASSES) {
            return Err(EstimateError::InvalidParameter {
                name: "occupancy class",
                value: f64::from(*c),
                reason: "classes are 0 (free), 1 (structure) and 2 (unknown)",
            });
        }
        Ok(Self { geometry, classes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traversal_lengths_sum_to_the_segment_and_match_a_fine_sampling() {
        let g = GridGeometry::new(7, 9, 0.5, [-1.0, 2.0]).unwrap();
        let segments = [
            ([-0.9, 2.1], [3.3, 5.2]),
            ([3.4, 5.4], [-0.7, 2.05]),
            ([0.25, 3.0], [0.25, 4.9]), // vertical, on no boundary
            ([-1.0, 2.0], [0.0, 3.0]),  // through grid corners
            ([1.0, 2.5], [3.0, 2.5]),   // along a cell boundary
        ];
        for (a, b) in segments {
            let mut acc = vec![0.0; g.len()];
            g.traverse(a, b, |c, l| acc[c] += l);
            let total = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            assert!((acc.iter().sum::<f64>() - total).abs() < 1e-9);
            // Independent truth: midpoint sampling of 200 000 pieces.
            let n = 200_000;
            let mut want = vec![0.0; g.len()];
            for k in 0..n {
                let s = (k as f64 + 0.5) / n as f64;
                let p = [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])];
                want[g.cell_of(p).unwrap()] += total / n as f64;
            }
            for (x, y) in acc.iter().zip(&want) {
                assert!((x - y).abs() < 1e-3, "{acc:?}\n{want:?}");
            }
        }
    }

    #[test]
    fn points_outside_are_reported() {
        let g = GridGeometry::new(2, 2, 1.0, [0.0, 0.0]).unwrap();
        assert!(g.check_inside("tx", &[[0.5, 0.5], [2.0, 2.0]]).is_ok());
        let e = g.check_inside("tx", &[[0.5, 0.5], [2.5, 0.5]]).unwrap_err();
        assert!(matches!(e, EstimateError::OutsideMap { index: 1, .. }));
        assert!(ClassGrid::new(g, vec![0, 1, 2, 3]).is_err());
        assert!(ClassGrid::new(g, vec![0, 1, 2]).is_err());
    }
}
