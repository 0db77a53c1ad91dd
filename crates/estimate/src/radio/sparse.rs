//! Sparse symmetric matrices (lower CSC) and their LLᵀ factorisation with faer: AMD ordering
//! and symbolic analysis once per pattern, numeric factorisation per set of values (the MRGP
//! refactors the same pattern for every hyper-parameter trial).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky, supernodal::SupernodalLltRef,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::{EstimateError, Result};

/// The lower triangle (diagonal included) of a symmetric `n × n` matrix in CSC form, row
/// indices sorted within each column.
#[derive(Debug, Clone, PartialEq)]
pub struct LowerCsc {
    /// Dimension.
    pub n: usize,
    /// Column pointers (`n + 1`).
    pub col_ptr: Vec<usize>,
    /// Row indices (≥ the column), sorted per column.
    pub row_idx: Vec<usize>,
    /// Values.
    pub values: Vec<f64>,
}

impl LowerCsc {
    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// `y = S x` for the full symmetric matrix.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        for c in 0..self.n {
            for p in self.col_ptr[c]..self.col_ptr[c + 1] {
                let (r, v) = (self.row_idx[p], self.values[p]);
                y[r] += v * x[c];
                if r != c {
                    y[c] += v * x[r];
                }
            }
        }
        y
    }

    /// The full symmetric matrix, column-major `n × n` (small systems and tests only).
    pub fn to_dense(&self) -> Vec<f64> {
        let n = self.n;
        let mut m = vec![0.0; n * n];
        for c in 0..n {
            for p in self.col_ptr[c]..self.col_ptr[c + 1] {
                let r = self.row_idx[p];
                m[c * n + r] = self.values[p];
                m[r * n + c] = self.values[p];
            }
        }
        m
    }
}

/// A sparse LLᵀ factorisation (faer, AMD fill-reducing ordering).
pub struct SparseLlt {
    symbolic: SymbolicCholesky<usize>,
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
}

impl std::fmt::Debug for SparseLlt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseLlt")
            .field("n", &self.n)
            .field("factor_nnz", &self.l_values.len())
            .finish()
    }
}

/// Why a numeric factorisation failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FactorError {
    /// The matrix is not (numerically) positive definite: the pivot of this column (original
    /// ordering) is not positive.
    NotPositiveDefinite(usize),
}

impl SparseLlt {
    /// Symbolic analysis (AMD ordering, elimination tree, supernodes) of `pattern`.
    pub fn analyse(pattern: &LowerCsc) -> Result<Self> {
        let sym = SymbolicSparseColMatRef::new_checked(
            pattern.n,
            pattern.n,
            &pattern.col_ptr,
            None,
            &pattern.row_idx,
        );
        let symbolic = factorize_symbolic_cholesky(
            sym,
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| EstimateError::LinearSolver(format!("symbolic analysis: {e:?}")))?;
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(4, Par::Seq));
        let mem = MemBuffer::try_new(req)
            .map_err(|e| EstimateError::LinearSolver(format!("workspace allocation: {e:?}")))?;
        Ok(Self {
            l_values: vec![0.0; symbolic.len_val()],
            symbolic,
            n: pattern.n,
            col_ptr: pattern.col_ptr.clone(),
            row_idx: pattern.row_idx.clone(),
            mem,
        })
    }

    /// Numeric factorisation of `values` (same pattern as the analysed matrix).
    pub fn factor(&mut self, values: &[f64]) -> std::result::Result<(), FactorError> {
        let a = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(
                self.n,
                self.n,
                &self.col_ptr,
                None,
                &self.row_idx,
            ),
            values,
        );
        let res = self.symbolic.factorize_numeric_llt(
            &mut self.l_values,
            a,
            Side::Lower,
            LltRegularization::default(),
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        );
        match res {
            Ok(_) => Ok(()),
            Err(LltError::NonPositivePivot { index }) => {
                let orig = self
                    .symbolic
                    .perm()
                    .and_then(|p| p.arrays().0.get(index).copied())
                    .unwrap_or(index);
                Err(FactorError::NotPositiveDefinite(orig))
            }
        }
    }

    /// Solves `S X = B` in place; `b` is `n × k` column-major.
    pub fn solve_in_place(&self, b: &mut [f64], k: usize) -> Result<()> {
        let llt = LltRef::new(&self.symbolic, &self.l_values);
        let req = self.symbolic.solve_in_place_scratch::<f64>(k, Par::Seq);
        let mut mem = MemBuffer::try_new(req)
            .map_err(|e| EstimateError::LinearSolver(format!("workspace allocation: {e:?}")))?;
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(b, self.n, k),
            Par::Seq,
            MemStack::new(&mut mem),
        );
        Ok(())
    }

    /// `log det S = 2 Σ log Lᵢᵢ` of the last factorisation.
    pub fn log_det(&self) -> f64 {
        let mut acc = 0.0;
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(sym) => {
                let cp = sym.col_ptr();
                let ri = sym.row_idx();
                for j in 0..self.n {
                    let col = cp[j]..cp[j + 1];
                    for (&row, &v) in ri[col.clone()].iter().zip(&self.l_values[col]) {
                        if row == j {
                            acc += v.ln();
                        }
                    }
                }
            }
            SymbolicCholeskyRaw::Supernodal(sym) => {
                let llt = SupernodalLltRef::new(sym, &self.l_values);
                for k in 0..sym.n_supernodes() {
                    let v = llt.supernode(k).val();
                    for j in 0..v.ncols() {
                        acc += v[(j, j)].ln();
                    }
                }
            }
        }
        2.0 * acc
    }

    /// Number of stored entries of the factor L.
    pub fn factor_nnz(&self) -> usize {
        self.l_values.len()
    }
}
