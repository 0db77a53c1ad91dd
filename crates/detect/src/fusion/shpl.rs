//! The sparse non-homogeneous pooling layer (SHPL, §7.5).
//!
//! LiDAR points `X_i` project to image pixels `(u_i, v_i)` by the camera–LiDAR matrix `P`
//! (eq. 7.2). Instead of a kernel over the whole ray behind each pixel (eq. 7.3), the kernel is
//! sparsified by the point cloud (eq. 7.4–7.5): only an image cell and a BEV cell that see the
//! same point are paired. Points are equivalent when they fall in the same cell (eq. 7.7; here
//! "round to the same cell" means `⌊·/cell⌋` in each grid's coordinates), and the kernel rows
//! are normalised by the number of points in the output cell (eq. 7.8):
//!
//! ```text
//! image → BEV:  K[b, m] = |{i : b_i = b}|⁻¹ · Σ_{i: b_i = b} 1[m = m_i],
//! BEV → image:  K[m, b] = |{i : m_i = m}|⁻¹ · Σ_{i: m_i = m} 1[b = b_i].
//! ```
//!
//! With `neighbourhood = k > 1` (odd) each point gathers the `k×k` source cells around the one it
//! hits, each with weight `1/|window|` (clipped to the grid), the "gather a neighbourhood"
//! variant of eq. 7.9/Fig. 7.12; every non-empty row still sums to 1 (the row-normalised
//! variant the text describes after eq. 7.8). The three factors `Q·K·P` of eq. 7.9 collapse to
//! one sparse matrix here (`K` is the identity: no learned convolution inside the layer).
//!
//! Both directions are held as CSR matrices together with their transposes, so forward
//! (`out = K·in`) and backward (`grad_in = Kᵀ·grad_out`) are both row-parallel gathers. At most
//! `N·k²` non-zeros, whatever the feature-map sizes. Points behind the camera (`w ≤ 0`) or
//! outside either grid are dropped and counted, never written out of bounds.

use autoteach_geometry::counting_sort::bucket_offsets;
use rayon::prelude::*;

use super::Feature;
use crate::{DetectError, Result};

/// `a · b` cells, which the kernel's u32 cell indices must be able to address.
fn cell_count(what: &'static str, a: usize, b: usize) -> Result<usize> {
    match a.checked_mul(b) {
        Some(n) if n <= u32::MAX as usize => Ok(n),
        _ => Err(DetectError::InvalidParameter {
            what,
            value: a as f64 * b as f64,
            reason: "more cells than the kernel's 32-bit cell indices address (2³² − 1)",
        }),
    }
}

/// The image feature map: `rows × cols` cells of `stride × stride` pixels; pixel `(u, v)` falls
/// in cell `(⌊v/stride⌋, ⌊u/stride⌋)`, flat index `row·cols + col`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageGrid {
    /// Feature-map rows.
    pub rows: usize,
    /// Feature-map columns.
    pub cols: usize,
    /// Pixels per cell.
    pub stride: f64,
}

impl ImageGrid {
    /// A grid; fails for zero cells or a non-positive stride.
    pub fn new(rows: usize, cols: usize, stride: f64) -> Result<Self> {
        if rows == 0 || cols == 0 || !(stride.is_finite() && stride > 0.0) {
            return Err(DetectError::InvalidParameter {
                what: "image grid (rows, cols, stride)",
                value: if rows == 0 || cols == 0 { 0.0 } else { stride },
                reason: "need rows, cols ≥ 1 and a positive finite stride",
            });
        }
        cell_count("image grid (rows × cols)", rows, cols)?;
        Ok(Self { rows, cols, stride })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.rows * self.cols
    }

    /// Whether the grid has no cells (never for a grid from [`ImageGrid::new`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The bird's-eye-view feature map: `nx × ny` square cells of side `cell` from `(x_min, y_min)`;
/// point `(x, y, ·)` falls in `(⌊(x − x_min)/cell⌋, ⌊(y − y_min)/cell⌋)`, flat index `ix·ny + iy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BevGrid {
    /// Lower x edge.
    pub x_min: f64,
    /// Lower y edge.
    pub y_min: f64,
    /// Cell side.
    pub cell: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
}

impl BevGrid {
    /// A grid; fails for zero cells or a non-positive cell size.
    pub fn new(x_min: f64, y_min: f64, cell: f64, nx: usize, ny: usize) -> Result<Self> {
        if nx == 0
            || ny == 0
            || !(cell.is_finite() && cell > 0.0 && x_min.is_finite() && y_min.is_finite())
        {
            return Err(DetectError::InvalidParameter {
                what: "BEV grid (x_min, y_min, cell, nx, ny)",
                value: if nx == 0 || ny == 0 { 0.0 } else { cell },
                reason: "need nx, ny ≥ 1, a positive cell size and finite edges",
            });
        }
        cell_count("BEV grid (nx × ny)", nx, ny)?;
        Ok(Self {
            x_min,
            y_min,
            cell,
            nx,
            ny,
        })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// Whether the grid has no cells (never for a grid from [`BevGrid::new`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Direction of the pooling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Image features → BEV cells.
    ImageToBev,
    /// BEV features → image cells.
    BevToImage,
}

/// Points dropped while building the operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Dropped {
    /// Behind the camera (`w ≤ 0`).
    pub behind: usize,
    /// Projecting outside the image grid.
    pub outside_image: usize,
    /// Outside the BEV grid.
    pub outside_bev: usize,
}

/// A compressed sparse row matrix with `f64` and `f32` copies of its weights.
#[derive(Debug, Clone, PartialEq)]
pub struct Csr {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Row pointers (`rows + 1`).
    pub indptr: Vec<u32>,
    /// Column indices, ascending within a row.
    pub indices: Vec<u32>,
    /// Weights.
    pub data: Vec<f64>,
    data32: Vec<f32>,
    /// Columns without an entry: no row reads them, so [`Csr::apply`] checks them apart.
    unread_cols: Vec<u32>,
}

/// [`bucket_offsets`] as the `u32` row and column pointers of [`Csr`] (fewer than 2³² entries:
/// the kernel indexes with `u32`).
fn bucket_offsets_u32(n: usize, keys: impl Iterator<Item = u32>) -> Vec<u32> {
    bucket_offsets(n, keys)
        .into_iter()
        .map(|o| o as u32)
        .collect()
}

/// The buckets of `ptr` (column pointers) that hold no entry.
fn empty_buckets(ptr: &[u32]) -> Vec<u32> {
    (0..ptr.len().saturating_sub(1))
        .filter(|&c| ptr[c] == ptr[c + 1])
        .map(|c| c as u32)
        .collect()
}

/// Bytes of one channel block of [`Csr::apply`].
const BLOCK_BYTES: usize = 4096;
/// Output rows per parallel task of [`Csr::apply`].
const ROWS_PER_TASK: usize = 256;

/// `out = Σ_k w_k · input[cols_k, c0..c0 + out.len()]`, summed left to right in the order of
/// the entries (the first product is stored, not added to a zero).
///
/// Four entries are taken per pass over `out`: `((o + w₁s₁) + w₂s₂) + …` per channel is the
/// same rounding as four passes, but four source rows stream at once (the gather is bound by
/// memory latency, not arithmetic) and `out` is read and written a quarter as often.
#[inline(always)]
fn gather_row<T: Feature>(
    out: &mut [T],
    w: &[T],
    cols: &[u32],
    input: &[T],
    channels: usize,
    c0: usize,
) {
    let n = out.len();
    let src = |c: u32| {
        let s = c as usize * channels + c0;
        &input[s..s + n]
    };
    match (w.first(), cols.first()) {
        (Some(&w0), Some(&col0)) => {
            for (o, s) in out.iter_mut().zip(src(col0)) {
                *o = w0 * *s;
            }
        }
        _ => {
            out.fill(T::ZERO);
            return;
        }
    }
    let (mut w, mut cols) = (&w[1..], &cols[1..]);
    while let (Some(w4), Some(c4)) = (w.first_chunk::<4>(), cols.first_chunk::<4>()) {
        let (s0, s1, s2, s3) = (src(c4[0]), src(c4[1]), src(c4[2]), src(c4[3]));
        for i in 0..n {
            out[i] = out[i] + w4[0] * s0[i] + w4[1] * s1[i] + w4[2] * s2[i] + w4[3] * s3[i];
        }
        (w, cols) = (&w[4..], &cols[4..]);
    }
    for (&wk, &ck) in w.iter().zip(cols) {
        for (o, s) in out.iter_mut().zip(src(ck)) {
            *o = *o + wk * *s;
        }
    }
}

impl Csr {
    /// From `(row, col, weight)` triplets; duplicates are summed.
    ///
    /// Two counting passes and no comparison sort: the triplets are bucketed by column (a CSC
    /// layout), and reading the columns in order while bucketing by row leaves every row's
    /// entries in ascending column order, duplicates adjacent, so they are summed in one pass.
    /// `O(nnz + rows + cols)`.
    fn from_triplets(rows: usize, cols: usize, trip: &[(u32, u32, f64)]) -> Self {
        // Column buckets.
        let cptr = bucket_offsets_u32(cols, trip.iter().map(|t| t.1));
        let mut fill = cptr.clone();
        let mut by_col = vec![(0u32, 0.0f64); trip.len()];
        for t in trip {
            let c = t.1 as usize;
            by_col[fill[c] as usize] = (t.0, t.2);
            fill[c] += 1;
        }
        // Row buckets, filled column by column.
        let rptr = bucket_offsets_u32(rows, trip.iter().map(|t| t.0));
        let mut fill = rptr.clone();
        let mut idx = vec![0u32; trip.len()];
        let mut val = vec![0.0f64; trip.len()];
        for c in 0..cols {
            for &(r, w) in &by_col[cptr[c] as usize..cptr[c + 1] as usize] {
                let k = fill[r as usize] as usize;
                idx[k] = c as u32;
                val[k] = w;
                fill[r as usize] += 1;
            }
        }
        // Sum the (adjacent) duplicates in place.
        let mut indptr = Vec::with_capacity(rows + 1);
        indptr.push(0u32);
        let mut out = 0usize;
        for r in 0..rows {
            let (a, z) = (rptr[r] as usize, rptr[r + 1] as usize);
            let row_start = out;
            for k in a..z {
                if out > row_start && idx[out - 1] == idx[k] {
                    val[out - 1] += val[k];
                } else {
                    idx[out] = idx[k];
                    val[out] = val[k];
                    out += 1;
                }
            }
            indptr.push(out as u32);
        }
        idx.truncate(out);
        val.truncate(out);
        let data32 = val.iter().map(|v| *v as f32).collect();
        Self {
            rows,
            cols,
            indptr,
            indices: idx,
            data: val,
            data32,
            unread_cols: empty_buckets(&cptr),
        }
    }

    /// The transpose (`cols × rows`), by one counting pass; rows stay in ascending column order.
    fn transpose(&self) -> Self {
        let nnz = self.indices.len();
        let ptr = bucket_offsets_u32(self.cols, self.indices.iter().copied());
        let mut fill = ptr.clone();
        let mut idx = vec![0u32; nnz];
        let mut val = vec![0.0f64; nnz];
        for r in 0..self.rows {
            let (a, z) = (self.indptr[r] as usize, self.indptr[r + 1] as usize);
            for (&c, &w) in self.indices[a..z].iter().zip(&self.data[a..z]) {
                let k = fill[c as usize] as usize;
                idx[k] = r as u32;
                val[k] = w;
                fill[c as usize] += 1;
            }
        }
        let data32 = val.iter().map(|v| *v as f32).collect();
        Self {
            rows: self.cols,
            cols: self.rows,
            indptr: ptr,
            indices: idx,
            data: val,
            data32,
            unread_cols: empty_buckets(&self.indptr),
        }
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.indices.len()
    }

    /// The dense `rows × cols` matrix, row-major (for tests and small problems).
    pub fn to_dense(&self) -> Vec<f64> {
        let mut out = vec![0.0; self.rows * self.cols];
        for r in 0..self.rows {
            for k in self.indptr[r] as usize..self.indptr[r + 1] as usize {
                out[r * self.cols + self.indices[k] as usize] += self.data[k];
            }
        }
        out
    }

    /// The weights in the precision of `T` (no copy).
    fn weights<T: Feature>(&self) -> &[T] {
        T::pick(&self.data, &self.data32)
    }

    /// `out = self · input` for channels-last `input` (`cols × channels`) into `out`
    /// (`rows × channels`), rows in parallel.
    fn apply<T: Feature>(
        &self,
        input: &[T],
        channels: usize,
        out: &mut [T],
        weights: &[T],
    ) -> Result<()> {
        if channels == 0 {
            return Err(DetectError::InvalidParameter {
                what: "channels",
                value: 0.0,
                reason: "need at least one channel",
            });
        }
        if input.len() != self.cols * channels {
            return Err(DetectError::WrongLength {
                what: "input features (cells × channels)",
                got: input.len(),
                expected: self.cols * channels,
            });
        }
        if out.len() != self.rows * channels {
            return Err(DetectError::WrongLength {
                what: "output features (cells × channels)",
                got: out.len(),
                expected: self.rows * channels,
            });
        }
        // Rows are independent and each is summed in a fixed order: thread-count invariant.
        // Tasks own runs of whole output rows; inside a task the channels are walked in blocks
        // of `BLOCK_BYTES` (whole rows up to 4 KiB: a contiguous gathered row is what the
        // hardware prefetcher follows; 256-byte blocks measured 1.4× slower).
        let block = (BLOCK_BYTES / std::mem::size_of::<T>()).clamp(1, channels);
        let rows_per_task = ROWS_PER_TASK.min(self.rows.max(1));
        out.par_chunks_mut(rows_per_task * channels)
            .enumerate()
            .for_each(|(t, rows_out)| {
                let r0 = t * rows_per_task;
                let mut c0 = 0;
                while c0 < channels {
                    let c1 = (c0 + block).min(channels);
                    for (i, row) in rows_out.chunks_exact_mut(channels).enumerate() {
                        let r = r0 + i;
                        let (a, b) = (self.indptr[r] as usize, self.indptr[r + 1] as usize);
                        gather_row(
                            &mut row[c0..c1],
                            &weights[a..b],
                            &self.indices[a..b],
                            input,
                            channels,
                            c0,
                        );
                    }
                    c0 = c1;
                }
            });
        // Non-finite inputs: a gathered NaN/∞ shows in the output (weights are positive and
        // finite); cells no row gathers are checked apart. The index is searched only then.
        let finite_out = out
            .par_chunks(1 << 14)
            .all(|c| c.iter().fold(true, |ok, v| ok & v.to_f64().is_finite()));
        let finite_unread = self.unread_cols.iter().all(|&c| {
            let c = c as usize;
            input[c * channels..(c + 1) * channels]
                .iter()
                .fold(true, |ok, v| ok & v.to_f64().is_finite())
        });
        // A finite input whose sum overflows gives ∞ as its answer, not an error.
        if !(finite_out && finite_unread)
            && let Some((index, v)) = input
                .iter()
                .enumerate()
                .find(|(_, v)| !v.to_f64().is_finite())
        {
            return Err(DetectError::NonFinite {
                what: "input features",
                index,
                value: v.to_f64(),
            });
        }
        Ok(())
    }
}

/// The SHPL operator for one point cloud (both directions, with their transposes).
#[derive(Debug, Clone, PartialEq)]
pub struct SparsePooling {
    /// Image → BEV kernel (`bev cells × image cells`).
    pub image_to_bev: Csr,
    /// BEV → image kernel (`image cells × bev cells`).
    pub bev_to_image: Csr,
    image_to_bev_t: Csr,
    bev_to_image_t: Csr,
    /// Points kept.
    pub kept: usize,
    /// Points dropped, by reason.
    pub dropped: Dropped,
    /// The image grid.
    pub image: ImageGrid,
    /// The BEV grid.
    pub bev: BevGrid,
}

/// Cells of a `k×k` window centred on `(a, b)` in an `na × nb` grid (clipped).
fn window(a: usize, b: usize, na: usize, nb: usize, k: usize, out: &mut Vec<(usize, usize)>) {
    out.clear();
    let h = k / 2;
    for i in a.saturating_sub(h)..(a + h + 1).min(na) {
        for j in b.saturating_sub(h)..(b + h + 1).min(nb) {
            out.push((i, j));
        }
    }
}

impl SparsePooling {
    /// Builds the operator (eq. 7.4–7.8) for `points` (LiDAR frame, `N×3`), the `3×4`
    /// camera–LiDAR projection `p` (eq. 7.2), the two grids and an odd `neighbourhood`
    /// window size (1 = the cell hit only, eq. 7.8).
    pub fn build(
        points: &[[f64; 3]],
        p: &[[f64; 4]; 3],
        image: ImageGrid,
        bev: BevGrid,
        neighbourhood: usize,
    ) -> Result<Self> {
        if points.is_empty() {
            return Err(DetectError::TooFewPoints { got: 0, needed: 1 });
        }
        if neighbourhood == 0 || neighbourhood.is_multiple_of(2) {
            return Err(DetectError::InvalidParameter {
                what: "neighbourhood",
                value: neighbourhood as f64,
                reason: "the window size must be odd (1, 3, 5, …)",
            });
        }
        if let Some(&value) = p.iter().flatten().find(|v| !v.is_finite()) {
            return Err(DetectError::NonFinite {
                what: "projection matrix",
                index: 0,
                value,
            });
        }
        if image.len() > u32::MAX as usize || bev.len() > u32::MAX as usize {
            return Err(DetectError::InvalidParameter {
                what: "grid cells",
                value: image.len().max(bev.len()) as f64,
                reason: "at most 2³² − 1 cells",
            });
        }
        let mut dropped = Dropped::default();
        // (image cell (row, col), bev cell (ix, iy)) of each kept point.
        let mut hits: Vec<(u32, u32, u32, u32)> = Vec::with_capacity(points.len());
        for (index, x) in points.iter().enumerate() {
            if let Some(&value) = x.iter().find(|v| !v.is_finite()) {
                return Err(DetectError::NonFinite {
                    what: "points",
                    index,
                    value,
                });
            }
            let pr = |r: &[f64; 4]| r[0] * x[0] + r[1] * x[1] + r[2] * x[2] + r[3];
            let (uw, vw, w) = (pr(&p[0]), pr(&p[1]), pr(&p[2]));
            if w.is_nan() || w <= 0.0 {
                dropped.behind += 1;
                continue;
            }
            // `⌊c⌋ ∈ [0, cols)` exactly when `c ∈ [0, cols)` (cols is an integer), and `as u32`
            // truncates a non-negative value to its floor: no `floor` call per coordinate.
            let (c, r) = (uw / w / image.stride, vw / w / image.stride);
            if !(c >= 0.0 && r >= 0.0 && c < image.cols as f64 && r < image.rows as f64) {
                dropped.outside_image += 1;
                continue;
            }
            let (ix, iy) = ((x[0] - bev.x_min) / bev.cell, (x[1] - bev.y_min) / bev.cell);
            if !(ix >= 0.0 && iy >= 0.0 && ix < bev.nx as f64 && iy < bev.ny as f64) {
                dropped.outside_bev += 1;
                continue;
            }
            hits.push((r as u32, c as u32, ix as u32, iy as u32));
        }
        let n_img = image.len();
        let n_bev = bev.len();
        let img_idx = |r: usize, c: usize| (r * image.cols + c) as u32;
        let bev_idx = |ix: usize, iy: usize| (ix * bev.ny + iy) as u32;
        let mut per_bev = vec![0u32; n_bev];
        let mut per_img = vec![0u32; n_img];
        for h in &hits {
            per_bev[bev_idx(h.2 as usize, h.3 as usize) as usize] += 1;
            per_img[img_idx(h.0 as usize, h.1 as usize) as usize] += 1;
        }
        let k2 = neighbourhood * neighbourhood;
        let mut ib = Vec::with_capacity(hits.len() * k2);
        let mut bi = Vec::with_capacity(hits.len() * k2);
        let mut win = Vec::with_capacity(k2);
        for h in &hits {
            let (r, c, ix, iy) = (h.0 as usize, h.1 as usize, h.2 as usize, h.3 as usize);
            let (b, m) = (bev_idx(ix, iy), img_idx(r, c));
            // image → BEV: row b gathers the image window around m.
            window(r, c, image.rows, image.cols, neighbourhood, &mut win);
            let w = 1.0 / (per_bev[b as usize] as f64 * win.len() as f64);
            for &(i, j) in &win {
                ib.push((b, img_idx(i, j), w));
            }
            // BEV → image: row m gathers the BEV window around b.
            window(ix, iy, bev.nx, bev.ny, neighbourhood, &mut win);
            let w = 1.0 / (per_img[m as usize] as f64 * win.len() as f64);
            for &(i, j) in &win {
                bi.push((m, bev_idx(i, j), w));
            }
        }
        let image_to_bev = Csr::from_triplets(n_bev, n_img, &ib);
        let bev_to_image = Csr::from_triplets(n_img, n_bev, &bi);
        let image_to_bev_t = image_to_bev.transpose();
        let bev_to_image_t = bev_to_image.transpose();
        Ok(Self {
            image_to_bev,
            bev_to_image,
            image_to_bev_t,
            bev_to_image_t,
            kept: hits.len(),
            dropped,
            image,
            bev,
        })
    }

    /// The kernel of a direction.
    pub fn kernel(&self, dir: Direction) -> &Csr {
        match dir {
            Direction::ImageToBev => &self.image_to_bev,
            Direction::BevToImage => &self.bev_to_image,
        }
    }

    /// `(input cells, output cells)` of a direction.
    pub fn shape(&self, dir: Direction) -> (usize, usize) {
        let k = self.kernel(dir);
        (k.cols, k.rows)
    }

    /// Forward pooling `out = K·input` (channels-last `input`: input cells × `channels`).
    pub fn forward<T: Feature>(
        &self,
        dir: Direction,
        input: &[T],
        channels: usize,
        out: &mut [T],
    ) -> Result<()> {
        let k = self.kernel(dir);
        k.apply(input, channels, out, k.weights::<T>())
    }

    /// Backward pass `grad_in = Kᵀ·grad_out` (the gradient of any loss with respect to the
    /// input features, given its gradient with respect to the output).
    pub fn backward<T: Feature>(
        &self,
        dir: Direction,
        grad_out: &[T],
        channels: usize,
        grad_in: &mut [T],
    ) -> Result<()> {
        let k = match dir {
            Direction::ImageToBev => &self.image_to_bev_t,
            Direction::BevToImage => &self.bev_to_image_t,
        };
        k.apply(grad_out, channels, grad_in, k.weights::<T>())
    }
}
