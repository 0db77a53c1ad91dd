//! The regularised least-squares problem shared by MRT and MATTE (seed 004 eqs. 3.2, 3.5;
//! Algorithm 3.1 lines 11–12), solved exactly by a bordered sparse Cholesky.
//!
//! Unknowns `x = [L0, b, v₀ … v_{n−1}]` with `b = −a`; measurement row
//! `[1, log10 d, w₀ … w_{n−1}]`, regularisation rows `λ (v_i − v_j) = 0` (Tikhonov, eq. 3.5)
//! and prior rows `φ (v_k − ρ_k) = 0` (§3.2.3). The normal equations are
//!
//! ```text
//! [ P   Bᵀ ] [p]   [b_p]        P = A_pᵀA_p (2×2), B = A_vᵀA_p (n×2)
//! [ B   S  ] [v] = [b_v]        S = A_vᵀA_v + λ²ΓᵀΓ + φ²I  (sparse)
//! ```
//!
//! The two path-loss columns are dense (every measurement touches them): left inside the
//! matrix they turn any fill-reducing ordering into a dense border (issue 33: scipy's
//! `spsolve` takes 29 s on a 100×100 grid). Here they are eliminated by the Schur complement
//! on the 2×2 border: factor `S` once (AMD), solve `S Z = [B | b_v]`, then
//! `(P − BᵀZ_B) p = b_p − BᵀZ_b` and `v = Z_b − Z_B p`. This is the exact solution of the
//! full normal equations, not an approximation.
//!
//! `S` is assembled by [`super::normal::gram_lower`]; its symbolic analysis is kept in a
//! [`FactorCache`] and reused while the pattern does not grow ([`TomoRows::solve_cached`]).

use super::normal::gram_lower;
use super::sparse::{FactorError, LowerCsc, SparseLlt};
use crate::{EstimateError, Result};

/// The measurement rows of a tomographic problem, appended incrementally (a row is never
/// recomputed once its line-of-sight traversal is stored).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TomoRows {
    /// Number of spatial unknowns `n`.
    pub n: usize,
    /// Path-loss regressors `[1, log10 d]` per row.
    pub path: Vec<[f64; 2]>,
    /// CSR row pointers of the spatial weights.
    pub row_ptr: Vec<usize>,
    /// Column (unknown) indices.
    pub col_idx: Vec<usize>,
    /// Weights (metres of the link in the unknown's cells).
    pub weights: Vec<f64>,
    /// Observed RSS per row.
    pub y: Vec<f64>,
}

/// Regularisation of the spatial unknowns.
#[derive(Debug, Clone, PartialEq)]
pub struct Regularization {
    /// Smoothness pairs `(i, j)`: rows `λ (v_i − v_j) = 0`.
    pub pairs: Vec<(usize, usize)>,
    /// Smoothness weight λ.
    pub lambda: f64,
    /// Prior weight φ (rows `φ (v_k − ρ_k) = 0` for every unknown; 0 for none).
    pub phi: f64,
    /// Prior values ρ_k (length n; ignored when φ = 0).
    pub prior: Vec<f64>,
}

/// The symbolic analysis of the last factored pattern of `S`, kept between solves (see
/// [`TomoRows::solve_cached`]). Cloning gives an empty cache: it only saves time.
#[derive(Default)]
pub struct FactorCache {
    pattern: Option<LowerCsc>,
    llt: Option<SparseLlt>,
    /// Number of symbolic analyses done through this cache.
    pub analyses: usize,
}

impl Clone for FactorCache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for FactorCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FactorCache")
            .field("pattern_nnz", &self.pattern.as_ref().map(LowerCsc::nnz))
            .field("analyses", &self.analyses)
            .finish()
    }
}

impl FactorCache {
    /// Forgets the analysed pattern (the next solve analyses anew).
    pub fn clear(&mut self) {
        self.pattern = None;
        self.llt = None;
    }

    /// `s`'s values laid out on the cached pattern (zeros where `s` has no entry), or `None`
    /// when there is no cached pattern or `s` has an entry outside it.
    fn refill(&self, s: &LowerCsc) -> Option<Vec<f64>> {
        let pat = self.pattern.as_ref()?;
        if pat.n != s.n || self.llt.is_none() {
            return None;
        }
        let mut values = vec![0.0; pat.nnz()];
        for c in 0..s.n {
            let mut q = pat.col_ptr[c];
            let q_end = pat.col_ptr[c + 1];
            for p in s.col_ptr[c]..s.col_ptr[c + 1] {
                let r = s.row_idx[p];
                while q < q_end && pat.row_idx[q] < r {
                    q += 1;
                }
                if q == q_end || pat.row_idx[q] != r {
                    return None;
                }
                values[q] = s.values[p];
            }
        }
        Some(values)
    }
}

/// The solution of a tomographic problem.
#[derive(Debug, Clone, PartialEq)]
pub struct TomoSolution {
    /// Power at 1 m, dBm.
    pub l0: f64,
    /// Path-loss exponent `a` (`y = L0 − a log10 d + …`).
    pub exponent: f64,
    /// Spatial unknowns `v` (dB per metre, negative = attenuating).
    pub values: Vec<f64>,
    /// Stored entries of the sparse Cholesky factor of `S`.
    pub factor_nnz: usize,
}

impl TomoRows {
    /// An empty problem on `n` spatial unknowns.
    pub fn new(n: usize) -> Self {
        Self {
            n,
            row_ptr: vec![0],
            ..Default::default()
        }
    }

    /// Number of measurement rows.
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// Whether there is no row.
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    /// Appends one measurement row (entries may repeat an unknown: they are summed).
    pub fn push(&mut self, log_d: f64, entries: &[(usize, f64)], y: f64) {
        self.path.push([1.0, log_d]);
        let mut sorted = entries.to_vec();
        sorted.sort_unstable_by_key(|e| e.0);
        for (c, w) in sorted {
            if self.col_idx.len() > self.row_ptr[self.row_ptr.len() - 1]
                && self.col_idx.last() == Some(&c)
            {
                if let Some(last) = self.weights.last_mut() {
                    *last += w;
                }
            } else {
                self.col_idx.push(c);
                self.weights.push(w);
            }
        }
        self.row_ptr.push(self.col_idx.len());
        self.y.push(y);
    }

    /// `S = A_vᵀA_v + λ²ΓᵀΓ + φ²I` (lower CSC, by [`super::normal::gram_lower`]) and
    /// `b_v = A_vᵀy + φ²ρ`, `B = A_vᵀA_p` (column-major n × 2).
    pub fn assemble(&self, reg: &Regularization) -> (LowerCsc, Vec<f64>, Vec<f64>) {
        let n = self.n;
        let mut b = vec![0.0; 2 * n];
        let mut bv = vec![0.0; n];
        for r in 0..self.len() {
            for p in self.row_ptr[r]..self.row_ptr[r + 1] {
                let (c, w) = (self.col_idx[p], self.weights[p]);
                b[c] += w * self.path[r][0];
                b[n + c] += w * self.path[r][1];
                bv[c] += w * self.y[r];
            }
        }
        let p2 = reg.phi * reg.phi;
        if p2 > 0.0 {
            for (k, v) in bv.iter_mut().enumerate() {
                *v += p2 * reg.prior[k];
            }
        }
        (gram_lower(self, reg), bv, b)
    }

    /// `P = A_pᵀA_p` (row-major 2×2) and `b_p = A_pᵀy`.
    fn path_normal(&self) -> ([f64; 4], [f64; 2]) {
        let mut p = [0.0; 4];
        let mut bp = [0.0; 2];
        for (a, &y) in self.path.iter().zip(&self.y) {
            p[0] += a[0] * a[0];
            p[1] += a[0] * a[1];
            p[3] += a[1] * a[1];
            bp[0] += a[0] * y;
            bp[1] += a[1] * y;
        }
        p[2] = p[1];
        (p, bp)
    }

    /// Solves the regularised normal equations exactly (bordered sparse Cholesky, see the
    /// module doc). Errors: `EmptyInput` without rows; `RankDeficient` when `S` or the 2×2
    /// Schur complement is singular (e.g. no regularisation and unvisited cells, or every
    /// link of the same length).
    pub fn solve(&self, reg: &Regularization) -> Result<TomoSolution> {
        self.solve_cached(reg, &mut FactorCache::default())
    }

    /// [`TomoRows::solve`], reusing `cache`'s symbolic analysis (AMD ordering, elimination
    /// tree, supernodes) when the pattern of `S` is contained in the analysed one — the case
    /// of an incremental update whose new links cross only already coupled cells, and of a
    /// repeated solve. Otherwise the pattern is analysed anew and kept in `cache`. The
    /// numeric factorisation is always redone: the solution is exact either way.
    pub fn solve_cached(
        &self,
        reg: &Regularization,
        cache: &mut FactorCache,
    ) -> Result<TomoSolution> {
        if self.is_empty() {
            return Err(EstimateError::EmptyInput("the training set".into()));
        }
        let n = self.n;
        let (s, bv, b) = self.assemble(reg);
        let values = match cache.refill(&s) {
            Some(v) => v,
            None => {
                cache.llt = Some(SparseLlt::analyse(&s)?);
                cache.analyses += 1;
                let values = s.values.clone();
                cache.pattern = Some(s);
                values
            }
        };
        let llt = cache
            .llt
            .as_mut()
            .ok_or_else(|| EstimateError::LinearSolver("factor cache without analysis".into()))?;
        llt.factor(&values)
            .map_err(
                |FactorError::NotPositiveDefinite(col)| EstimateError::RankDeficient {
                    what: "tomographic normal equations (A_vᵀA_v + λ²ΓᵀΓ + φ²I)".into(),
                    directions: format!(
                        "spatial unknown {col} (raise λ or φ, or cover the map with links)"
                    ),
                },
            )?;
        let mut z = Vec::with_capacity(3 * n);
        z.extend_from_slice(&b);
        z.extend_from_slice(&bv);
        llt.solve_in_place(&mut z, 3)?;
        let (p, bp) = self.path_normal();
        let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
        let (b0, b1) = (&b[..n], &b[n..]);
        let (z0, z1, zb) = (&z[..n], &z[n..2 * n], &z[2 * n..]);
        let c = [
            p[0] - dot(b0, z0),
            p[1] - dot(b0, z1),
            p[2] - dot(b1, z0),
            p[3] - dot(b1, z1),
        ];
        let r = [bp[0] - dot(b0, zb), bp[1] - dot(b1, zb)];
        let det = c[0] * c[3] - c[1] * c[2];
        // Also rejects a NaN determinant (no ordering).
        let threshold = 1e-12 * (c[0] * c[3]).abs().max(f64::MIN_POSITIVE);
        if det.abs().partial_cmp(&threshold) != Some(std::cmp::Ordering::Greater) {
            return Err(EstimateError::RankDeficient {
                what: "path-loss Schur complement of the tomographic normal equations".into(),
                directions: "L0 and the path-loss exponent a (links of too few lengths)".into(),
            });
        }
        let l0 = (c[3] * r[0] - c[1] * r[1]) / det;
        let slope = (c[0] * r[1] - c[2] * r[0]) / det;
        let values = (0..n).map(|k| zb[k] - z0[k] * l0 - z1[k] * slope).collect();
        Ok(TomoSolution {
            l0,
            exponent: -slope,
            values,
            factor_nnz: llt.factor_nnz(),
        })
    }

    /// The stacked least-squares system `[A; λΓ; φI] x = [y; 0; φρ]` over all `n + 2`
    /// unknowns `[L0, b, v]` as COO triplets `(row, col, value)` and its right-hand side:
    /// the same problem for a peer solver (scipy) or a dense check.
    pub fn stacked(&self, reg: &Regularization) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
        let mut t = Vec::new();
        let mut rhs = self.y.clone();
        for r in 0..self.len() {
            t.push((r, 0, self.path[r][0]));
            t.push((r, 1, self.path[r][1]));
            for p in self.row_ptr[r]..self.row_ptr[r + 1] {
                t.push((r, 2 + self.col_idx[p], self.weights[p]));
            }
        }
        let mut row = self.len();
        if reg.lambda > 0.0 {
            for &(i, j) in &reg.pairs {
                if i != j {
                    t.push((row, 2 + i, reg.lambda));
                    t.push((row, 2 + j, -reg.lambda));
                    rhs.push(0.0);
                    row += 1;
                }
            }
        }
        if reg.phi > 0.0 {
            for k in 0..self.n {
                t.push((row, 2 + k, reg.phi));
                rhs.push(reg.phi * reg.prior[k]);
                row += 1;
            }
        }
        (t, rhs)
    }
}

/// 4-neighbour smoothness pairs `(i, j)` of a `rows × cols` row-major grid (eq. 3.5's
/// `v_{i,j} − v_{i+1,j}`, `v_{i,j} − v_{i,j+1}`), unknowns offset by `offset`.
pub fn grid_pairs(rows: usize, cols: usize, offset: usize) -> Vec<(usize, usize)> {
    let mut pairs = Vec::with_capacity(2 * rows * cols);
    for i in 0..rows {
        for j in 0..cols {
            let k = offset + i * cols + j;
            if j + 1 < cols {
                pairs.push((k, k + 1));
            }
            if i + 1 < rows {
                pairs.push((k, k + cols));
            }
        }
    }
    pairs
}
