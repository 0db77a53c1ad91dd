//! Per-cell observation counts (the "votes" of seed 004_815695db12a6b16c.txt §2.5) and the
//! rasterization of one node's scan into them.
//!
//! A node contributes at most one vote per cell, like the node's local occupancy grid: a
//! cell holding a beam end that is a hit is *occupied* for that node; otherwise a cell
//! crossed by a beam (or holding a no-return end) is *free* for it.

use autoteach_geometry::planar::{cell_of, traverse_cells};

use super::scan::LocalScan;

/// An axis-aligned box of cells, `[x0, x1) × [y0, y1)` (global cell indices: cell (i, j)
/// covers `[i·res, (i+1)·res) × [j·res, (j+1)·res)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellBox {
    /// First column.
    pub x0: i32,
    /// First row.
    pub y0: i32,
    /// One past the last column.
    pub x1: i32,
    /// One past the last row.
    pub y1: i32,
}

impl Default for CellBox {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl CellBox {
    /// The empty box.
    pub const EMPTY: CellBox = CellBox {
        x0: i32::MAX,
        y0: i32::MAX,
        x1: i32::MIN,
        y1: i32::MIN,
    };

    /// Whether no cell is inside.
    pub fn is_empty(&self) -> bool {
        self.x0 >= self.x1 || self.y0 >= self.y1
    }

    /// Grows the box to hold cell (i, j).
    #[inline]
    pub fn add(&mut self, i: i32, j: i32) {
        self.x0 = self.x0.min(i);
        self.y0 = self.y0.min(j);
        self.x1 = self.x1.max(i + 1);
        self.y1 = self.y1.max(j + 1);
    }

    /// The union of two boxes.
    pub fn union(&self, o: &CellBox) -> CellBox {
        if self.is_empty() {
            return *o;
        }
        if o.is_empty() {
            return *self;
        }
        CellBox {
            x0: self.x0.min(o.x0),
            y0: self.y0.min(o.y0),
            x1: self.x1.max(o.x1),
            y1: self.y1.max(o.y1),
        }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        if self.is_empty() {
            0
        } else {
            (self.x1 - self.x0) as usize
        }
    }

    /// Rows.
    pub fn height(&self) -> usize {
        if self.is_empty() {
            0
        } else {
            (self.y1 - self.y0) as usize
        }
    }

    /// Number of cells.
    pub fn area(&self) -> usize {
        self.width() * self.height()
    }
}

/// A scan placed at a pose, in CELL units: the origin and the beam ends, with the tight box
/// of the cells it votes on.
#[derive(Debug, Clone, Default)]
pub struct Projection {
    /// Scan origin (cell units).
    pub origin: [f64; 2],
    /// Beam ends (cell units).
    pub ends: Vec<[f64; 2]>,
    /// Hit flags (as in [`LocalScan`]).
    pub hit: Vec<bool>,
    /// Tight box of the voted cells.
    pub bbox: CellBox,
}

impl Projection {
    /// Projects `scan` at `pose = [x, y, θ]` (metres, rad) onto a grid of `resolution`.
    pub fn new(scan: &LocalScan, pose: &[f64; 3], resolution: f64) -> Self {
        let inv = 1.0 / resolution;
        let (s, c) = pose[2].sin_cos();
        let origin = [pose[0] * inv, pose[1] * inv];
        let (oi, oj) = (cell_of(origin[0]), cell_of(origin[1]));
        let mut bbox = CellBox::EMPTY;
        let mut leaves = false;
        let ends: Vec<[f64; 2]> = scan
            .ends
            .iter()
            .map(|e| {
                let (x, y) = (e[0] as f64, e[1] as f64);
                let p = [
                    origin[0] + (c * x - s * y) * inv,
                    origin[1] + (s * x + c * y) * inv,
                ];
                let (i, j) = (cell_of(p[0]), cell_of(p[1]));
                bbox.add(i, j);
                leaves |= i != oi || j != oj;
                p
            })
            .collect();
        if leaves {
            bbox.add(oi, oj);
        }
        Self {
            origin,
            ends,
            hit: scan.hit.clone(),
            bbox,
        }
    }
}

/// Dense vote counts over a box, with per-cell stamps so each node votes once per cell.
#[derive(Debug, Clone, Default)]
pub struct DenseVotes {
    /// The box covered.
    pub bbox: CellBox,
    /// Free votes per cell (row-major over the box).
    pub free: Vec<u16>,
    /// Occupied votes per cell.
    pub occ: Vec<u16>,
    stamp: Vec<u32>,
    next_tag: u32,
}

impl DenseVotes {
    /// Resets to zero votes over `bbox` (reusing the allocation).
    pub fn reset(&mut self, bbox: CellBox) {
        let n = bbox.area();
        self.bbox = bbox;
        for v in [&mut self.free, &mut self.occ] {
            v.clear();
            v.resize(n, 0);
        }
        self.stamp.clear();
        self.stamp.resize(n, 0);
        self.next_tag = 1;
    }

    /// Adds one node's votes (its projection must lie inside the box; cells outside are
    /// ignored).
    pub fn rasterize(&mut self, p: &Projection) {
        if self.next_tag >= u32::MAX - 2 {
            self.stamp.iter_mut().for_each(|s| *s = 0);
            self.next_tag = 1;
        }
        let tag_occ = self.next_tag;
        let tag_free = self.next_tag + 1;
        self.next_tag += 2;
        let b = self.bbox;
        let w = b.width() as i32;
        let index = |i: i32, j: i32| -> Option<usize> {
            (i >= b.x0 && i < b.x1 && j >= b.y0 && j < b.y1)
                .then(|| ((j - b.y0) * w + (i - b.x0)) as usize)
        };
        // Hits first: within one node, occupied wins over free.
        for (e, &h) in p.ends.iter().zip(&p.hit) {
            if h && let Some(k) = index(cell_of(e[0]), cell_of(e[1]))
                && self.stamp[k] != tag_occ
            {
                self.stamp[k] = tag_occ;
                self.occ[k] = self.occ[k].saturating_add(1);
            }
        }
        let (stamp, free) = (&mut self.stamp, &mut self.free);
        let mut vote_free = |i: i32, j: i32| {
            if let Some(k) = index(i, j) {
                let s = stamp[k];
                if s != tag_occ && s != tag_free {
                    stamp[k] = tag_free;
                    free[k] = free[k].saturating_add(1);
                }
            }
        };
        for (e, &h) in p.ends.iter().zip(&p.hit) {
            traverse_cells(p.origin, *e, &mut vote_free);
            if !h {
                vote_free(cell_of(e[0]), cell_of(e[1]));
            }
        }
    }
}

/// Sparse vote counts (the cached sub-map m_j of a slice, §2.3): only observed cells, as
/// indices into a box.
#[derive(Debug, Clone, Default)]
pub struct SparseVotes {
    /// The box the indices refer to (tight: the union of the members' boxes).
    pub bbox: CellBox,
    /// Row-major cell index within the box.
    pub index: Vec<u32>,
    /// Free votes.
    pub free: Vec<u16>,
    /// Occupied votes.
    pub occ: Vec<u16>,
}

impl SparseVotes {
    /// The observed cells of a dense grid.
    pub fn from_dense(d: &DenseVotes) -> Self {
        let mut s = SparseVotes {
            bbox: d.bbox,
            ..Default::default()
        };
        for (k, (&f, &o)) in d.free.iter().zip(&d.occ).enumerate() {
            if f != 0 || o != 0 {
                s.index.push(k as u32);
                s.free.push(f);
                s.occ.push(o);
            }
        }
        s
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.index.capacity() * 4 + (self.free.capacity() + self.occ.capacity()) * 2
    }

    /// Adds these votes onto a dense grid whose box contains this one.
    pub fn composite_onto(&self, d: &mut DenseVotes) {
        let (b, db) = (self.bbox, d.bbox);
        let w = b.width() as u32;
        let dw = db.width();
        let (ox, oy) = ((b.x0 - db.x0) as usize, (b.y0 - db.y0) as usize);
        for ((&k, &f), &o) in self.index.iter().zip(&self.free).zip(&self.occ) {
            let (i, j) = ((k % w) as usize, (k / w) as usize);
            let t = (j + oy) * dw + i + ox;
            d.free[t] = d.free[t].saturating_add(f);
            d.occ[t] = d.occ[t].saturating_add(o);
        }
    }
}
