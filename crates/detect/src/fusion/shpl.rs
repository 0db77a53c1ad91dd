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

use std::mem::MaybeUninit;

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

/// Output rows per parallel task of [`Csr::apply`].
const ROWS_PER_TASK: usize = 256;
/// Channels of one output row that [`gather_row`] sums in registers at a time.
const LANES: usize = 16;

/// An output element [`Csr::apply`] stores to: an initialised `T`, or a `MaybeUninit<T>` of a
/// freshly allocated buffer (so the output is not zeroed before the product overwrites it).
trait Slot<T>: Send {
    fn put(&mut self, v: T);
}

impl<T: Feature> Slot<T> for T {
    #[inline(always)]
    fn put(&mut self, v: T) {
        *self = v;
    }
}

impl<T: Feature> Slot<T> for MaybeUninit<T> {
    #[inline(always)]
    fn put(&mut self, v: T) {
        self.write(v);
    }
}

/// `input[start..start + LANES]` as an array.
#[inline(always)]
fn lanes<T>(input: &[T], start: usize) -> &[T; LANES] {
    &input[start..start + LANES].as_chunks::<LANES>().0[0]
}

/// `out[c] = Σ_k w_k · input[cols_k, c]` for every channel `c`, summed left to right in the order
/// of the entries (the first product is stored, not added to a zero); returns whether every
/// output value is finite. An empty row is zero.
///
/// `LANES` channels at a time are summed over all entries in registers and stored once: the
/// output row is written once and never read back, and each gathered row is read in
/// consecutive `LANES`-channel pieces, one stream per entry.
#[inline(always)]
fn gather_row<T: Feature, O: Slot<T>>(
    out: &mut [O],
    w: &[T],
    cols: &[u32],
    input: &[T],
    channels: usize,
) -> bool {
    let (Some((&w0, w_rest)), Some((&c0, c_rest))) = (w.split_first(), cols.split_first()) else {
        out.iter_mut().for_each(|o| o.put(T::ZERO));
        return true;
    };
    let start = |c: u32| c as usize * channels;
    let mut finite = true;
    let blocks = channels / LANES;
    for (j, out_block) in out[..blocks * LANES].chunks_exact_mut(LANES).enumerate() {
        let at = j * LANES;
        let first = lanes(input, start(c0) + at);
        let mut acc = [T::ZERO; LANES];
        for i in 0..LANES {
            acc[i] = w0 * first[i];
        }
        for (&wk, &ck) in w_rest.iter().zip(c_rest) {
            let s = lanes(input, start(ck) + at);
            for i in 0..LANES {
                acc[i] = acc[i] + wk * s[i];
            }
        }
        finite &= acc.iter().fold(true, |ok, v| ok & v.to_f64().is_finite());
        for (o, a) in out_block.iter_mut().zip(acc) {
            o.put(a);
        }
    }
    for (c, o) in out.iter_mut().enumerate().skip(blocks * LANES) {
        let mut acc = w0 * input[start(c0) + c];
        for (&wk, &ck) in w_rest.iter().zip(c_rest) {
            acc = acc + wk * input[start(ck) + c];
        }
        finite &= acc.to_f64().is_finite();
        o.put(acc);
    }
    finite
}

/// The four kernels `[image → BEV, BEV → image, (image → BEV)ᵀ, (BEV → image)ᵀ]` of the
/// one-cell variant (eq. 7.8) from the `(image cell, BEV cell)` of each point.
///
/// Both directions share two sparsity patterns: `F` (rows: BEV cells) and its transpose `T`
/// (rows: image cells), each entry counting the `n_bm` points seen by BEV cell `b` and image
/// cell `m`. With `N_b`, `N_m` the points per cell, `K_ib[b, m] = n_bm/N_b` and `K_bi[m, b] =
/// n_bm/N_m`, so `K_ib = F/N_b`, `K_biᵀ = F/N_m`, `K_ibᵀ = T/N_b`, `K_bi = T/N_m`. Three
/// counting passes: bucket the points by `m`, then (reading the `m` buckets in order) by `b`,
/// which leaves each `F` row in ascending `m` with equal pairs adjacent; `T` is `F` bucketed by
/// column.
fn cell_kernels(n_img: usize, n_bev: usize, hits: &[(u32, u32)]) -> [Csr; 4] {
    let img_ptr = bucket_offsets_u32(n_img, hits.iter().map(|h| h.0));
    let bev_ptr = bucket_offsets_u32(n_bev, hits.iter().map(|h| h.1));
    let mut fill = img_ptr.clone();
    let mut by_img = vec![0u32; hits.len()];
    for &(m, b) in hits {
        by_img[fill[m as usize] as usize] = b;
        fill[m as usize] += 1;
    }
    let mut fill = bev_ptr.clone();
    let mut by_bev = vec![0u32; hits.len()];
    for m in 0..n_img {
        for &b in &by_img[img_ptr[m] as usize..img_ptr[m + 1] as usize] {
            by_bev[fill[b as usize] as usize] = m as u32;
            fill[b as usize] += 1;
        }
    }
    // F: runs of equal m in each row become one entry with its count.
    let mut f_ptr = Vec::with_capacity(n_bev + 1);
    f_ptr.push(0u32);
    let (mut f_col, mut f_cnt) = (
        Vec::with_capacity(hits.len()),
        Vec::with_capacity(hits.len()),
    );
    for b in 0..n_bev {
        let row = &by_bev[bev_ptr[b] as usize..bev_ptr[b + 1] as usize];
        for (k, &m) in row.iter().enumerate() {
            if k > 0 && row[k - 1] == m {
                if let Some(c) = f_cnt.last_mut() {
                    *c += 1;
                }
            } else {
                f_col.push(m);
                f_cnt.push(1u32);
            }
        }
        f_ptr.push(f_col.len() as u32);
    }
    // T = Fᵀ, rows filled in ascending b.
    let t_ptr = bucket_offsets_u32(n_img, f_col.iter().copied());
    let mut fill = t_ptr.clone();
    let (mut t_col, mut t_cnt) = (vec![0u32; f_col.len()], vec![0u32; f_col.len()]);
    for b in 0..n_bev {
        for k in f_ptr[b] as usize..f_ptr[b + 1] as usize {
            let slot = &mut fill[f_col[k] as usize];
            t_col[*slot as usize] = b as u32;
            t_cnt[*slot as usize] = f_cnt[k];
            *slot += 1;
        }
    }
    // `1/N` per cell (0 points: no entry reads it).
    let inverse = |ptr: &[u32]| -> Vec<f64> {
        ptr.windows(2)
            .map(|p| 1.0 / f64::from((p[1] - p[0]).max(1)))
            .collect()
    };
    let (inv_img, inv_bev) = (inverse(&img_ptr), inverse(&bev_ptr));
    // Weights `n_bm · (1/N)` of a pattern, the cell counted being its row or its column: exactly
    // `1/N` for an entry seen by one point (most), within an ulp of `n_bm/N` otherwise.
    let weights = |ptr: &[u32], col: &[u32], cnt: &[u32], inv: &[f64], by_row: bool| {
        let mut w = vec![0.0; col.len()];
        for (r, p) in ptr.windows(2).enumerate() {
            let span = p[0] as usize..p[1] as usize;
            let (w, col, cnt) = (&mut w[span.clone()], &col[span.clone()], &cnt[span]);
            if by_row {
                for (w, &n) in w.iter_mut().zip(cnt) {
                    *w = f64::from(n) * inv[r];
                }
            } else {
                for ((w, &n), &c) in w.iter_mut().zip(cnt).zip(col) {
                    *w = f64::from(n) * inv[c as usize];
                }
            }
        }
        w
    };
    let unread_img = empty_buckets(&img_ptr);
    let unread_bev = empty_buckets(&bev_ptr);
    let f_ib = weights(&f_ptr, &f_col, &f_cnt, &inv_bev, true);
    let f_bi = weights(&f_ptr, &f_col, &f_cnt, &inv_img, false);
    let t_ib = weights(&t_ptr, &t_col, &t_cnt, &inv_bev, false);
    let t_bi = weights(&t_ptr, &t_col, &t_cnt, &inv_img, true);
    [
        Csr::new(
            n_bev,
            n_img,
            f_ptr.clone(),
            f_col.clone(),
            f_ib,
            unread_img.clone(),
        ),
        Csr::new(
            n_img,
            n_bev,
            t_ptr.clone(),
            t_col.clone(),
            t_bi,
            unread_bev.clone(),
        ),
        Csr::new(n_img, n_bev, t_ptr, t_col, t_ib, unread_bev),
        Csr::new(n_bev, n_img, f_ptr, f_col, f_bi, unread_img),
    ]
}

impl Csr {
    /// From its parts (the `f32` weights are derived).
    fn new(
        rows: usize,
        cols: usize,
        indptr: Vec<u32>,
        indices: Vec<u32>,
        data: Vec<f64>,
        unread_cols: Vec<u32>,
    ) -> Self {
        let data32 = data.iter().map(|v| *v as f32).collect();
        Self {
            rows,
            cols,
            indptr,
            indices,
            data,
            data32,
            unread_cols,
        }
    }

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
    /// (`rows × channels`, every element written), rows in parallel.
    fn apply<T: Feature, O: Slot<T>>(
        &self,
        input: &[T],
        channels: usize,
        out: &mut [O],
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
        let rows_per_task = ROWS_PER_TASK.min(self.rows.max(1));
        let finite_out = out
            .par_chunks_mut(rows_per_task * channels)
            .enumerate()
            .map(|(t, rows_out)| {
                let r0 = t * rows_per_task;
                rows_out
                    .chunks_exact_mut(channels)
                    .enumerate()
                    .fold(true, |ok, (i, row)| {
                        let r = r0 + i;
                        let (a, b) = (self.indptr[r] as usize, self.indptr[r + 1] as usize);
                        let cols = &self.indices[a..b];
                        ok & gather_row(row, &weights[a..b], cols, input, channels)
                    })
            })
            .reduce(|| true, |x, y| x & y);
        // Non-finite inputs: a gathered NaN/∞ shows in the output (weights are positive and
        // finite); cells no row gathers are checked apart. The index is searched only then.
        let finite_unread = self.unread_cols.par_iter().all(|&c| {
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
            return Err(DetectError::TooFewPoints {
                what: "points",
                got: 0,
                needed: 1,
            });
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
        let img_idx = |r: usize, c: usize| (r * image.cols + c) as u32;
        let bev_idx = |ix: usize, iy: usize| (ix * bev.ny + iy) as u32;
        // (image cell, BEV cell) of each kept point.
        let mut hits: Vec<(u32, u32)> = Vec::with_capacity(points.len());
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
            hits.push((
                img_idx(r as usize, c as usize),
                bev_idx(ix as usize, iy as usize),
            ));
        }
        let (n_img, n_bev) = (image.len(), bev.len());
        let [image_to_bev, bev_to_image, image_to_bev_t, bev_to_image_t] = if neighbourhood == 1 {
            cell_kernels(n_img, n_bev, &hits)
        } else {
            let mut per_bev = vec![0u32; n_bev];
            let mut per_img = vec![0u32; n_img];
            for &(m, b) in &hits {
                per_bev[b as usize] += 1;
                per_img[m as usize] += 1;
            }
            let k2 = neighbourhood * neighbourhood;
            let mut ib = Vec::with_capacity(hits.len() * k2);
            let mut bi = Vec::with_capacity(hits.len() * k2);
            let mut win = Vec::with_capacity(k2);
            for &(m, b) in &hits {
                let (r, c) = (m as usize / image.cols, m as usize % image.cols);
                let (ix, iy) = (b as usize / bev.ny, b as usize % bev.ny);
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
            [image_to_bev, bev_to_image, image_to_bev_t, bev_to_image_t]
        };
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

    /// The kernel of the backward pass of a direction (the transpose of [`Self::kernel`]).
    fn kernel_t(&self, dir: Direction) -> &Csr {
        match dir {
            Direction::ImageToBev => &self.image_to_bev_t,
            Direction::BevToImage => &self.bev_to_image_t,
        }
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

    /// [`Self::forward`] into uninitialised memory (a new output buffer needs no zeroing pass):
    /// on `Ok` every element of `out` has been written.
    pub fn forward_uninit<T: Feature>(
        &self,
        dir: Direction,
        input: &[T],
        channels: usize,
        out: &mut [MaybeUninit<T>],
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
        let k = self.kernel_t(dir);
        k.apply(grad_out, channels, grad_in, k.weights::<T>())
    }

    /// [`Self::backward`] into uninitialised memory: on `Ok` every element of `grad_in` has been
    /// written.
    pub fn backward_uninit<T: Feature>(
        &self,
        dir: Direction,
        grad_out: &[T],
        channels: usize,
        grad_in: &mut [MaybeUninit<T>],
    ) -> Result<()> {
        let k = self.kernel_t(dir);
        k.apply(grad_out, channels, grad_in, k.weights::<T>())
    }
}
