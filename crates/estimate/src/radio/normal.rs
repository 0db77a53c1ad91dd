//! Fast assembly of the tomographic normal matrix `S = A_vᵀA_v + λ²ΓᵀΓ + φ²I` (seed 004
//! eqs. 3.2, 3.5; the `S` block of [`super::tomo`]'s bordered system) in lower CSC.
//!
//! `A_vᵀA_v = Σ_r a_r a_rᵀ` is a sum of one dense clique per link (every cell a link
//! crosses couples with every other), `Σ_r |a_r|²` products — about 10⁸ for 14 400 links
//! of 100 cells. A column-by-column (Gustavson) product touches each of them through a
//! scattered accumulator; here they are summed instead in small dense blocks and only the
//! block sums are sorted:
//!
//! 1. rows are ordered by their first and last unknown (for a grid, the cells of the two
//!    ends), so nearly parallel, overlapping links — consecutive samples of one robot pair
//!    at 20 Hz — come together;
//! 2. runs of up to [`WINDOW_ROWS`] such rows share one dense accumulator on the union of
//!    their unknowns (at most [`WINDOW_UNION`], or one longer row alone), whose lower
//!    triangle is emitted once as triplets `(row, col, value)`, skipping pairs no row of the
//!    window couples;
//! 3. the triplets (and the regularisation's) are sorted by a two-pass counting sort (by
//!    row, then stably by column) and duplicates summed: `O(triplets + n)`, no comparison
//!    sort.
//!
//! The result is the same matrix, to rounding, as the dense product of the stacked system
//! (test `blocked_normal_assembly_equals_the_dense_product`). Measured effect and the
//! alternatives weighed: docs/design/radio.md.

use autoteach_geometry::counting_sort::{bucket_offsets, counting_sort_order};

use super::sparse::LowerCsc;
use super::tomo::{Regularization, TomoRows};

/// Most rows summed in one dense block.
pub const WINDOW_ROWS: usize = 256;
/// Largest union of unknowns of one dense block (its accumulator is `u × u`).
pub const WINDOW_UNION: usize = 1024;

/// Triplets `(row ≥ col, col, value)` of a lower triangle, in three arrays.
#[derive(Debug, Default)]
struct Triplets {
    rows: Vec<u32>,
    cols: Vec<u32>,
    values: Vec<f64>,
}

impl Triplets {
    fn push(&mut self, r: usize, c: usize, v: f64) {
        self.rows.push(r as u32);
        self.cols.push(c as u32);
        self.values.push(v);
    }

    /// Sums duplicates into a lower CSC with sorted row indices (two stable counting sorts).
    fn into_csc(self, n: usize) -> LowerCsc {
        let t = self.values.len();
        // Pass 1: stable order by row.
        let by_row = counting_sort_order(&self.rows, n);
        // Pass 2: stable order by column of the row-ordered sequence.
        let cnt = bucket_offsets(n, self.cols.iter().copied());
        let mut order = vec![0usize; t];
        let mut fill = cnt.clone();
        for &k in &by_row {
            let k = k as usize;
            let c = self.cols[k] as usize;
            order[fill[c]] = k;
            fill[c] += 1;
        }
        // Sum duplicates (adjacent now) per column.
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(t / 2);
        let mut values = Vec::with_capacity(t / 2);
        col_ptr.push(0);
        for c in 0..n {
            let start = row_idx.len();
            for &k in &order[cnt[c]..cnt[c + 1]] {
                let (r, v) = (self.rows[k] as usize, self.values[k]);
                if row_idx.len() > start && row_idx.last() == Some(&r) {
                    if let Some(last) = values.last_mut() {
                        *last += v;
                    }
                } else {
                    row_idx.push(r);
                    values.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        LowerCsc {
            n,
            col_ptr,
            row_idx,
            values,
        }
    }
}

/// `S = A_vᵀA_v + λ²ΓᵀΓ + φ²I` of `rows` and `reg` in lower CSC (see the module doc). Every
/// diagonal entry is stored, even a zero one.
pub fn gram_lower(rows: &TomoRows, reg: &Regularization) -> LowerCsc {
    let n = rows.n;
    let m = rows.len();
    let mut trip = Triplets::default();
    // Regularisation: diagonal (always stored) and the smoothness couplings.
    let l2 = reg.lambda * reg.lambda;
    let p2 = reg.phi * reg.phi;
    let mut diag = vec![if p2 > 0.0 { p2 } else { 0.0 }; n];
    if l2 > 0.0 {
        for &(i, j) in &reg.pairs {
            if i == j {
                continue;
            }
            diag[i] += l2;
            diag[j] += l2;
            trip.push(i.max(j), i.min(j), -l2);
        }
    }
    for (k, &d) in diag.iter().enumerate() {
        trip.push(k, k, d);
    }
    // Rows ordered by (first unknown, last unknown); empty rows contribute nothing.
    let span = |r: usize| -> Option<(usize, usize)> {
        let (a, b) = (rows.row_ptr[r], rows.row_ptr[r + 1]);
        (b > a).then(|| (rows.col_idx[a], rows.col_idx[b - 1]))
    };
    let mut order: Vec<(usize, usize, usize)> = (0..m)
        .filter_map(|r| span(r).map(|(lo, hi)| (lo, hi, r)))
        .collect();
    // Two stable counting sorts: by last unknown, then by first.
    let his: Vec<u32> = order.iter().map(|o| o.1 as u32).collect();
    let by_hi = counting_sort_order(&his, n);
    let los: Vec<u32> = by_hi.iter().map(|&k| order[k as usize].0 as u32).collect();
    let by_lo = counting_sort_order(&los, n);
    let sorted: Vec<usize> = by_lo
        .iter()
        .map(|&k| order[by_hi[k as usize] as usize].2)
        .collect();
    order.clear();

    let mut local = vec![usize::MAX; n];
    let mut union: Vec<usize> = Vec::with_capacity(WINDOW_UNION);
    let mut acc: Vec<f64> = Vec::new();
    let mut li: Vec<usize> = Vec::new();
    let mut start = 0;
    while start < sorted.len() {
        // Grow the window while the union stays within its cap.
        union.clear();
        let mut end = start;
        while end < sorted.len() && end - start < WINDOW_ROWS {
            let r = sorted[end];
            let cols = &rows.col_idx[rows.row_ptr[r]..rows.row_ptr[r + 1]];
            let new = cols.iter().filter(|&&c| local[c] == usize::MAX).count();
            if end > start && union.len() + new > WINDOW_UNION {
                break;
            }
            for &c in cols {
                if local[c] == usize::MAX {
                    local[c] = 0;
                    union.push(c);
                }
            }
            end += 1;
        }
        // A single row longer than the cap makes a larger block: grow the accumulator.
        let u = union.len();
        if acc.len() < u * u {
            acc.resize(u * u, 0.0);
        }
        union.sort_unstable();
        for (i, &c) in union.iter().enumerate() {
            local[c] = i;
        }
        acc[..u * u].fill(0.0);
        for &r in &sorted[start..end] {
            let (a, b) = (rows.row_ptr[r], rows.row_ptr[r + 1]);
            li.clear();
            li.extend(rows.col_idx[a..b].iter().map(|&c| local[c]));
            let w = &rows.weights[a..b];
            // Row entries are sorted by unknown, so li is increasing: (p, q ≤ p) is lower.
            for q in 0..li.len() {
                let (cq, wq) = (li[q] * u, w[q]);
                for p in q..li.len() {
                    acc[cq + li[p]] += w[p] * wq;
                }
            }
        }
        for (j, &cj) in union.iter().enumerate() {
            for i in j..u {
                // Weights are lengths (> 0): a zero sum means no row of the window couples
                // the pair (and an exact zero would add nothing anyway).
                let v = acc[j * u + i];
                if v != 0.0 {
                    trip.push(union[i], cj, v);
                }
            }
        }
        for &c in &union {
            local[c] = usize::MAX;
        }
        start = end;
    }
    trip.into_csc(n)
}
