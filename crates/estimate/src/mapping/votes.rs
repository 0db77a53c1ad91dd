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

    /// Whether every cell of `o` is inside this box (an empty `o` is).
    pub fn contains(&self, o: &CellBox) -> bool {
        o.is_empty() || (self.x0 <= o.x0 && self.y0 <= o.y0 && self.x1 >= o.x1 && self.y1 >= o.y1)
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

/// Dense vote counts over a box, and a per-node scratch of marks so each node votes once per
/// cell.
///
/// Counts are `u32`: a map composites any number of nodes without saturating, so removing a
/// slice's votes (CoverComposite's incremental composite) exactly undoes adding them.
#[derive(Debug, Clone, Default)]
pub struct DenseVotes {
    /// The box covered.
    pub bbox: CellBox,
    /// Free votes per cell (row-major over the box).
    pub free: Vec<u32>,
    /// Occupied votes per cell.
    pub occ: Vec<u32>,
    /// One node's marks over its own box (bit 0 crossed, bit 1 hit): a node's whole fan fits
    /// in a few hundred kB, so the ray walk stays in cache whatever the size of the map.
    marks: Vec<u8>,
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
    }

    /// Makes the box contain `want`, keeping every count (with a margin so that a map growing
    /// with exploration is copied O(log) times, not once per update).
    pub fn grow_to(&mut self, want: &CellBox) {
        if want.is_empty() || self.bbox.contains(want) {
            return;
        }
        let u = self.bbox.union(want);
        let (mx, my) = (
            (u.width() / 8).clamp(16, 1 << 12) as i32,
            (u.height() / 8).clamp(16, 1 << 12) as i32,
        );
        let grown = CellBox {
            x0: u.x0.saturating_sub(mx),
            y0: u.y0.saturating_sub(my),
            x1: u.x1.saturating_add(mx),
            y1: u.y1.saturating_add(my),
        };
        let old = std::mem::take(self);
        self.reset(grown);
        self.marks = old.marks;
        if old.bbox.is_empty() {
            return;
        }
        let (ow, nw) = (old.bbox.width(), grown.width());
        let ox = (old.bbox.x0 - grown.x0) as usize;
        for r in 0..old.bbox.height() {
            let t = (r + (old.bbox.y0 - grown.y0) as usize) * nw + ox;
            self.free[t..t + ow].copy_from_slice(&old.free[r * ow..(r + 1) * ow]);
            self.occ[t..t + ow].copy_from_slice(&old.occ[r * ow..(r + 1) * ow]);
        }
    }

    /// Adds one node's votes (cells outside the box are ignored).
    ///
    /// The node's beams are walked on a byte grid over the node's own box (a cell with a hit
    /// is occupied for the node, otherwise a crossed cell or a no-return end is free), which
    /// is then added row by row onto the counts.
    pub fn rasterize(&mut self, p: &Projection) {
        let nb = p.bbox;
        if nb.is_empty() {
            return;
        }
        let (w, h) = (nb.width(), nb.height());
        let marks = &mut self.marks;
        marks.clear();
        marks.resize(w * h, 0);
        for (e, &hit) in p.ends.iter().zip(&p.hit) {
            mark_beam(marks, &nb, p.origin, *e, if hit { 2 } else { 1 });
        }
        let b = self.bbox;
        let x0 = nb.x0.max(b.x0);
        let x1 = nb.x1.min(b.x1);
        let (y0, y1) = (nb.y0.max(b.y0), nb.y1.min(b.y1));
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        let (dw, n) = (b.width(), (x1 - x0) as usize);
        for j in y0..y1 {
            let s = (j - nb.y0) as usize * w + (x0 - nb.x0) as usize;
            let t = (j - b.y0) as usize * dw + (x0 - b.x0) as usize;
            let m = &self.marks[s..s + n];
            let free = &mut self.free[t..t + n];
            let occ = &mut self.occ[t..t + n];
            for ((f, o), &m) in free.iter_mut().zip(occ.iter_mut()).zip(m) {
                *o += u32::from(m >> 1);
                *f += u32::from(m == 1);
            }
        }
    }
}

/// Marks the cells a beam `a → b` (cell units) crosses with bit 0 (free) and its end cell
/// with `end_bit`, on a row-major byte grid over `nb`; cells outside `nb` are skipped.
///
/// The same cells, in the same order, as [`traverse_cells`] (Amanatides & Woo) followed by
/// the end cell, but walking a linear index with a branch-free choice of axis (the choice
/// is data dependent and mispredicts on diagonal beams otherwise). A beam inside `nb` (the
/// node's tight box always holds its beams) is walked on the fast path.
fn mark_beam(marks: &mut [u8], nb: &CellBox, a: [f64; 2], b: [f64; 2], end_bit: u8) {
    let (w, h) = (nb.width() as i64, nb.height() as i64);
    let local = |i: i32, j: i32| -> Option<usize> {
        let (c, r) = (
            i64::from(i) - i64::from(nb.x0),
            i64::from(j) - i64::from(nb.y0),
        );
        (c >= 0 && c < w && r >= 0 && r < h).then_some((r * w + c) as usize)
    };
    let fin = a[0].is_finite() && a[1].is_finite() && b[0].is_finite() && b[1].is_finite();
    let (i, j) = (cell_of(a[0]), cell_of(a[1]));
    let (ie, je) = (cell_of(b[0]), cell_of(b[1]));
    let (Some(start), Some(end)) = (local(i, j), local(ie, je)) else {
        if fin {
            traverse_cells(a, b, |i, j| {
                if let Some(k) = local(i, j) {
                    marks[k] |= 1;
                }
            });
        }
        if let Some(k) = local(ie, je) {
            marks[k] |= end_bit;
        }
        return;
    };
    if fin {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let (si, sj) = (
            if dx > 0.0 { 1i64 } else { -1 },
            if dy > 0.0 { 1i64 } else { -1 },
        );
        let mut nx = (ie - i).unsigned_abs();
        let mut ny = (je - j).unsigned_abs();
        let mut t_x = if dx != 0.0 {
            let next = if dx > 0.0 { i as f64 + 1.0 } else { i as f64 };
            (next - a[0]) / dx
        } else {
            f64::INFINITY
        };
        let mut t_y = if dy != 0.0 {
            let next = if dy > 0.0 { j as f64 + 1.0 } else { j as f64 };
            (next - a[1]) / dy
        } else {
            f64::INFINITY
        };
        let d_x = if dx != 0.0 {
            (1.0 / dx).abs()
        } else {
            f64::INFINITY
        };
        let d_y = if dy != 0.0 {
            (1.0 / dy).abs()
        } else {
            f64::INFINITY
        };
        let (step_x, step_y) = (si, sj * w);
        let mut k = start as i64;
        for _ in 0..nx + ny {
            marks[k as usize] |= 1;
            // traverse_cells' rule: along x if x's boundary comes first and x is not yet
            // exhausted, or if y is exhausted.
            let go_x = (t_x < t_y) & (nx != 0) | (ny == 0);
            k += if go_x { step_x } else { step_y };
            t_x += if go_x { d_x } else { 0.0 };
            t_y += if go_x { 0.0 } else { d_y };
            nx -= u32::from(go_x);
            ny -= u32::from(!go_x);
        }
    }
    marks[end] |= end_bit;
}

/// Sparse vote counts (the cached sub-map m_j of a slice, §2.3): only observed cells, row by
/// row (compressed rows over the slice's box).
#[derive(Debug, Clone, Default)]
pub struct SparseVotes {
    /// The box the cells lie in (tight: the union of the members' boxes).
    pub bbox: CellBox,
    /// `row_start[r]..row_start[r + 1]` are the entries of row `r` of the box.
    pub row_start: Vec<u32>,
    /// Column of each entry within the box.
    pub col: Vec<u32>,
    /// Free votes (at most the slice's size, ≤ 4096).
    pub free: Vec<u16>,
    /// Occupied votes.
    pub occ: Vec<u16>,
}

impl SparseVotes {
    /// The observed cells of a dense grid whose counts are below 2¹⁶ (a slice's).
    pub fn from_dense(d: &DenseVotes) -> Self {
        let (w, h) = (d.bbox.width(), d.bbox.height());
        let mut s = SparseVotes {
            bbox: d.bbox,
            row_start: Vec::with_capacity(h + 1),
            ..Default::default()
        };
        s.row_start.push(0);
        const CHUNK: usize = 16;
        for r in 0..h {
            let (f, o) = (&d.free[r * w..(r + 1) * w], &d.occ[r * w..(r + 1) * w]);
            // Unobserved runs are skipped a chunk at a time (an OR the compiler vectorises).
            for (q, (fc, oc)) in f.chunks(CHUNK).zip(o.chunks(CHUNK)).enumerate() {
                if fc.iter().zip(oc).fold(0, |a, (&f, &o)| a | f | o) == 0 {
                    continue;
                }
                for (c, (&f, &o)) in fc.iter().zip(oc).enumerate() {
                    if f != 0 || o != 0 {
                        s.col.push((q * CHUNK + c) as u32);
                        s.free.push(f.min(u32::from(u16::MAX)) as u16);
                        s.occ.push(o.min(u32::from(u16::MAX)) as u16);
                    }
                }
            }
            s.row_start.push(s.col.len() as u32);
        }
        s
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        (self.row_start.capacity() + self.col.capacity()) * 4
            + (self.free.capacity() + self.occ.capacity()) * 2
    }

    /// Adds these votes onto a dense grid whose box contains this one.
    pub fn composite_onto(&self, d: &mut DenseVotes) {
        self.apply(d, |a, v| *a += v);
    }

    /// Removes these votes from a dense grid they were added to.
    pub fn remove_from(&self, d: &mut DenseVotes) {
        self.apply(d, |a, v| *a -= v);
    }

    fn apply(&self, d: &mut DenseVotes, op: impl Fn(&mut u32, u32)) {
        let (b, db) = (self.bbox, d.bbox);
        if b.is_empty() {
            return;
        }
        let dw = db.width();
        let (ox, oy) = ((b.x0 - db.x0) as usize, (b.y0 - db.y0) as usize);
        for (r, w) in self.row_start.windows(2).enumerate() {
            let base = (r + oy) * dw + ox;
            let e = w[0] as usize..w[1] as usize;
            for ((&c, &f), &o) in self.col[e.clone()]
                .iter()
                .zip(&self.free[e.clone()])
                .zip(&self.occ[e])
            {
                let t = base + c as usize;
                op(&mut d.free[t], u32::from(f));
                op(&mut d.occ[t], u32::from(o));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `mark_beam` marks exactly `traverse_cells`' cells plus the end cell (that walk is
    /// itself checked against dense sampling of the segment), inside and across the box.
    #[test]
    fn mark_beam_matches_traverse_cells() {
        let nb = CellBox {
            x0: -20,
            y0: -15,
            x1: 25,
            y1: 18,
        };
        let (w, h) = (nb.width(), nb.height());
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = |lo: f64, hi: f64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            lo + (hi - lo) * (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..400 {
            // Half inside the box (the fast path), half reaching outside it.
            let r = if case % 2 == 0 { 14.0 } else { 40.0 };
            let a = [uniform(-14.0, 14.0), uniform(-14.0, 14.0)];
            let mut b = [a[0] + uniform(-r, r), a[1] + uniform(-r, r)];
            if case % 50 == 7 {
                b[1] = a[1]; // axis-aligned
            }
            let mut got = vec![0u8; w * h];
            mark_beam(&mut got, &nb, a, b, 2);
            let mut want = vec![0u8; w * h];
            let mut put = |i: i32, j: i32, bit: u8| {
                if i >= nb.x0 && i < nb.x1 && j >= nb.y0 && j < nb.y1 {
                    want[((j - nb.y0) as usize) * w + (i - nb.x0) as usize] |= bit;
                }
            };
            traverse_cells(a, b, |i, j| put(i, j, 1));
            put(cell_of(b[0]), cell_of(b[1]), 2);
            assert_eq!(got, want, "case {case}: {a:?} -> {b:?}");
        }
    }

    /// Removing a slice's votes undoes adding them, and growing keeps every count.
    #[test]
    fn sparse_votes_add_remove_and_grow_are_exact() {
        let mut d = DenseVotes::default();
        d.reset(CellBox {
            x0: 0,
            y0: 0,
            x1: 40,
            y1: 30,
        });
        let p = Projection {
            origin: [10.5, 10.5],
            ends: vec![[35.2, 12.7], [3.1, 28.9], [10.5, 2.2]],
            hit: vec![true, false, true],
            bbox: CellBox {
                x0: 3,
                y0: 2,
                x1: 36,
                y1: 29,
            },
        };
        d.rasterize(&p);
        let s = SparseVotes::from_dense(&d);
        let mut map = DenseVotes::default();
        map.grow_to(&CellBox {
            x0: -5,
            y0: -5,
            x1: 0,
            y1: 0,
        });
        map.grow_to(&s.bbox);
        s.composite_onto(&mut map);
        map.grow_to(&CellBox {
            x0: 100,
            y0: 90,
            x1: 101,
            y1: 91,
        });
        let at = |m: &DenseVotes, i: i32, j: i32| {
            let k = ((j - m.bbox.y0) as usize) * m.bbox.width() + (i - m.bbox.x0) as usize;
            (m.free[k], m.occ[k])
        };
        for j in 0..30 {
            for i in 0..40 {
                assert_eq!(at(&map, i, j), at(&d, i, j), "cell ({i}, {j})");
            }
        }
        assert_eq!(at(&d, 35, 12), (0, 1));
        assert_eq!(at(&d, 3, 28), (1, 0));
        s.remove_from(&mut map);
        assert!(map.free.iter().chain(&map.occ).all(|&v| v == 0));
    }
}
