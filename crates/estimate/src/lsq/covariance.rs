//! Marginal covariances of chosen blocks from the factor of the information matrix JᵀJ
//! (seed 004_815695db12a6b16c.txt eq. (5.5): Σ = (JᵀJ)⁻¹ for whitened residuals), and the
//! rank-deficiency (gauge freedom) report.

use nalgebra::DMatrix;

use super::linear::Cholesky;
use super::problem::{BlockId, Problem};
use super::solver::Structure;
use crate::{EstimateError, Result};

/// Relative pivot (of the Jacobi-scaled information matrix, unit diagonal) below which a
/// direction counts as unconstrained.
pub const RANK_TOLERANCE: f64 = 1e-10;

/// Up to this many unknowns the rank is analysed by a dense eigendecomposition (which names
/// the null-space directions exactly); above, by the pivots of the sparse factor.
const DENSE_COVARIANCE_LIMIT: usize = 600;

impl Problem {
    /// Joint covariance (tangent space, at the current values) of the chosen blocks, from
    /// (JᵀJ)⁻¹ with residuals taken as whitened (robust losses enter through their IRLS
    /// weights, as in the solver). Only the needed columns of the inverse are solved for,
    /// from a Cholesky factor of the Jacobi-scaled information matrix; the whole inverse is
    /// never formed. Fixed blocks have zero covariance (the other blocks' covariance is
    /// conditional on them).
    ///
    /// Errors: [`EstimateError::RankDeficient`] naming the unconstrained directions/blocks when
    /// the information matrix is singular (gauge freedom, a block without residuals);
    /// [`EstimateError::InvalidProblem`] for unknown or repeated blocks.
    pub fn marginal_covariance(&self, blocks: &[BlockId]) -> Result<DMatrix<f64>> {
        for (k, b) in blocks.iter().enumerate() {
            self.block(*b)?;
            if blocks[..k].contains(b) {
                return Err(EstimateError::InvalidProblem(format!(
                    "block {} requested twice in marginal_covariance",
                    b.0
                )));
            }
        }
        let dims: Vec<usize> = blocks
            .iter()
            .map(|b| self.blocks[b.0].manifold.tangent_dim())
            .collect();
        let total: usize = dims.iter().sum();
        let st = Structure::new(self);
        let n = st.n;
        // Output rows of each requested free block, and its column in the unknowns.
        let mut sel: Vec<(usize, usize)> = Vec::new(); // (output index, unknown column)
        let mut out_off = 0;
        for (b, d) in blocks.iter().zip(&dims) {
            if let Some(f) = st.free_index[b.0] {
                for i in 0..*d {
                    sel.push((out_off + i, st.col_offset[f] + i));
                }
            }
            out_off += d;
        }
        let mut cov = DMatrix::zeros(total, total);
        if sel.is_empty() {
            return Ok(cov);
        }
        let mut bufs = self.make_buffers();
        self.evaluate_all(&self.values, &mut bufs, true)?;
        let mut h = vec![0.0; st.pattern.nnz()];
        let mut g = vec![0.0; n];
        self.assemble(&st, &bufs, &mut h, &mut g);
        let what = "marginal covariance".to_string();
        // Jacobi scaling: Hs = S H S, S = diag(H)^-1/2.
        let mut zero_cols = Vec::new();
        let s: Vec<f64> = st
            .pattern
            .diag_pos
            .iter()
            .enumerate()
            .map(|(c, &p)| {
                if h[p] > 0.0 {
                    1.0 / h[p].sqrt()
                } else {
                    zero_cols.push(c);
                    1.0
                }
            })
            .collect();
        if !zero_cols.is_empty() {
            return Err(EstimateError::RankDeficient {
                what: format!("{what}: no residual constrains these directions"),
                directions: self.describe_columns(&st, &zero_cols),
            });
        }
        for c in 0..n {
            for p in st.pattern.col_ptr[c]..st.pattern.col_ptr[c + 1] {
                h[p] *= s[st.pattern.row_idx[p]] * s[c];
            }
        }
        let dense = n <= DENSE_COVARIANCE_LIMIT;
        if dense {
            let eig = st.pattern.to_dense(&h).symmetric_eigen();
            let null: Vec<usize> = (0..n)
                .filter(|&i| eig.eigenvalues[i] < RANK_TOLERANCE)
                .collect();
            if !null.is_empty() {
                // Describe at most three null directions; the count says how many there are.
                let dirs: Vec<String> = null
                    .iter()
                    .take(3)
                    .map(|&i| {
                        let v = eig.eigenvectors.column(i);
                        let vmax = v.amax();
                        let cols: Vec<usize> =
                            (0..n).filter(|&r| v[r].abs() > 0.1 * vmax).collect();
                        format!(
                            "[eigenvalue {:.2e} of the scaled information: {}]",
                            eig.eigenvalues[i],
                            self.describe_columns(&st, &cols)
                        )
                    })
                    .collect();
                return Err(EstimateError::RankDeficient {
                    what: format!("{what}: {} null direction(s)", null.len()),
                    directions: dirs.join("; "),
                });
            }
        }
        let mut chol = Cholesky::new(&st.pattern, dense, None)?;
        if let Err(col) = chol.factor(&st.pattern, &h) {
            return Err(EstimateError::RankDeficient {
                what: format!("{what}: the information matrix is not positive definite"),
                directions: col
                    .map(|c| self.describe_columns(&st, &[c]))
                    .unwrap_or_else(|| "unknown".into()),
            });
        }
        if !dense {
            let piv = chol.pivots(n);
            let weak: Vec<usize> = (0..n)
                .filter(|&c| piv[c].is_nan() || piv[c] < RANK_TOLERANCE)
                .collect();
            if !weak.is_empty() {
                return Err(EstimateError::RankDeficient {
                    what: format!(
                        "{what}: {} pivot(s) below {RANK_TOLERANCE:e} (relative)",
                        weak.len()
                    ),
                    directions: self.describe_columns(&st, &weak),
                });
            }
        }
        let k = sel.len();
        let mut rhs = vec![0.0; n * k];
        for (j, &(_, c)) in sel.iter().enumerate() {
            rhs[j * n + c] = 1.0;
        }
        chol.solve_in_place(&mut rhs, n, k)?;
        for (j, &(oj, cj)) in sel.iter().enumerate() {
            for &(oi, ci) in &sel {
                cov[(oi, oj)] = rhs[j * n + ci] * s[ci] * s[cj];
            }
        }
        // Symmetrise the rounding.
        let cov = (&cov + cov.transpose()) * 0.5;
        Ok(cov)
    }

    /// Groups scalar columns by block: "block 3 (Se3) components [0, 1]; block 7 …".
    fn describe_columns(&self, st: &Structure, cols: &[usize]) -> String {
        let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
        let mut sorted = cols.to_vec();
        sorted.sort_unstable();
        for c in sorted {
            let Some(f) = st.col_offset.iter().rposition(|&o| o <= c) else {
                continue;
            };
            let comp = c - st.col_offset[f];
            match groups.last_mut() {
                Some((g, comps)) if *g == f => comps.push(comp),
                _ => groups.push((f, vec![comp])),
            }
        }
        // Keep messages readable on large problems: name the first few blocks, count the rest.
        const SHOWN: usize = 6;
        let mut text = groups
            .iter()
            .take(SHOWN)
            .map(|(f, comps)| {
                let b = st.free_blocks[*f];
                format!(
                    "block {b} ({:?}) tangent components {comps:?}",
                    self.blocks[b].manifold
                )
            })
            .collect::<Vec<_>>()
            .join("; ");
        if groups.len() > SHOWN {
            text.push_str(&format!(" … and {} more block(s)", groups.len() - SHOWN));
        }
        text
    }
}
