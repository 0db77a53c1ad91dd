//! The normal equations (JᵀJ + μD) δ = −Jᵀr assembled by block structure, and their
//! Cholesky solvers: dense (nalgebra) for small systems, sparse (faer, AMD fill-reducing
//! ordering; symbolic analysis once, numeric refactorisation per iteration) otherwise.
//! (Normal equations of the Gauss–Newton / Levenberg–Marquardt step, seed
//! 004_815695db12a6b16c.txt eq. (5.4)–(5.5).)

use std::collections::HashMap;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky, supernodal::SupernodalLltRef,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::DMatrix;

use crate::{EstimateError, Result};

/// Lower-triangular CSC pattern of a block-structured symmetric matrix, with the position of
/// every block pair, so the numeric values can be refilled in place each iteration.
#[derive(Debug, Clone)]
pub(crate) struct Pattern {
    /// Scalar dimension.
    pub n: usize,
    /// CSC column pointers.
    pub col_ptr: Vec<usize>,
    /// CSC row indices (sorted within each column).
    pub row_idx: Vec<usize>,
    /// Position of each diagonal entry in the value array.
    pub diag_pos: Vec<usize>,
    /// Per slot and per column of its column block: the position of the row block's first row
    /// (off-diagonal slots) or of the diagonal entry (diagonal slots).
    pub slot_base: Vec<Vec<usize>>,
    /// Whether each slot is a diagonal block.
    pub slot_diag: Vec<bool>,
    /// Slot of each block pair `(a, b)`, `a ≥ b` (block indices in column order).
    pub slots: HashMap<(usize, usize), usize>,
}

impl Pattern {
    /// Builds the pattern of blocks with scalar `dims` (blocks laid out consecutively) and the
    /// given coupled pairs `(a, b)` (any order; duplicates allowed). Every diagonal block is
    /// present.
    pub fn new(dims: &[usize], pairs: impl IntoIterator<Item = (usize, usize)>) -> Self {
        let nb = dims.len();
        let mut offsets = Vec::with_capacity(nb);
        let mut n = 0;
        for d in dims {
            offsets.push(n);
            n += d;
        }
        let mut below: Vec<Vec<usize>> = (0..nb).map(|b| vec![b]).collect();
        for (a, b) in pairs {
            let (a, b) = if a >= b { (a, b) } else { (b, a) };
            if a != b {
                below[b].push(a);
            }
        }
        let mut slots = HashMap::new();
        let mut slot_base = Vec::new();
        let mut slot_diag = Vec::new();
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut diag_pos = Vec::with_capacity(n);
        col_ptr.push(0);
        for (b, list) in below.iter_mut().enumerate() {
            list.sort_unstable();
            list.dedup();
            let slot_ids: Vec<usize> = list
                .iter()
                .map(|&a| {
                    let id = slot_base.len();
                    slots.insert((a, b), id);
                    slot_base.push(Vec::with_capacity(dims[b]));
                    slot_diag.push(a == b);
                    id
                })
                .collect();
            for j in 0..dims[b] {
                for (&a, &s) in list.iter().zip(&slot_ids) {
                    slot_base[s].push(row_idx.len());
                    if a == b {
                        diag_pos.push(row_idx.len());
                        row_idx.extend(offsets[b] + j..offsets[b] + dims[b]);
                    } else {
                        row_idx.extend(offsets[a]..offsets[a] + dims[a]);
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        Self {
            n,
            col_ptr,
            row_idx,
            diag_pos,
            slot_base,
            slot_diag,
            slots,
        }
    }

    /// Number of stored (lower-triangle) entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// Adds `ja_rowᵀ · jb` (the block (a, b) of JᵀJ from one residual: `ja` is m × da, `jb`
    /// is m × db) into `values` at `slot`.
    pub fn add_product(&self, values: &mut [f64], slot: usize, ja: &[f64], jb: &[f64], m: usize) {
        let base = &self.slot_base[slot];
        let m = m.max(1);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let diag = self.slot_diag[slot];
        for ((j, &p), cj) in base.iter().enumerate().zip(jb.chunks_exact(m)) {
            let i0 = if diag { j } else { 0 };
            for (i, ci) in ja.chunks_exact(m).enumerate().skip(i0) {
                values[p + i - if diag { j } else { 0 }] += dot(ci, cj);
            }
        }
    }

    /// The full symmetric dense matrix of `values`.
    pub fn to_dense(&self, values: &[f64]) -> DMatrix<f64> {
        let mut m = DMatrix::zeros(self.n, self.n);
        for c in 0..self.n {
            let range = self.col_ptr[c]..self.col_ptr[c + 1];
            for (&r, &v) in self.row_idx[range.clone()].iter().zip(&values[range]) {
                m[(r, c)] = v;
                m[(c, r)] = v;
            }
        }
        m
    }

    /// `y = A x` for the symmetric matrix stored in `values`.
    #[cfg(test)]
    pub fn mul_vec(&self, values: &[f64], x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        for c in 0..self.n {
            let range = self.col_ptr[c]..self.col_ptr[c + 1];
            for (&r, &v) in self.row_idx[range.clone()].iter().zip(&values[range]) {
                y[r] += v * x[c];
                if r != c {
                    y[c] += v * x[r];
                }
            }
        }
    }
}

/// A Cholesky factorisation of a symmetric positive-definite matrix with a fixed pattern.
pub(crate) enum Cholesky {
    /// Dense factor (nalgebra), for small systems.
    Dense(Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>),
    /// Sparse factor (faer).
    Sparse(Box<SparseCholesky>),
}

/// faer's sparse LLᵀ with the symbolic analysis (AMD ordering, elimination tree, supernodes)
/// done once and the numeric factorisation redone for each new set of values.
pub(crate) struct SparseCholesky {
    symbolic: SymbolicCholesky<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    factored: bool,
}

impl Cholesky {
    /// A solver for matrices with this pattern: dense when `dense`, sparse otherwise.
    /// `ordering`: a custom fill-reducing permutation `(fwd, inv)` (AMD otherwise).
    pub fn new(
        pattern: &Pattern,
        dense: bool,
        ordering: Option<(&[usize], &[usize])>,
    ) -> Result<Self> {
        if dense {
            return Ok(Cholesky::Dense(None));
        }
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
            match ordering {
                Some((fwd, inv)) => {
                    SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(fwd, inv, pattern.n))
                }
                None => SymmetricOrdering::Amd,
            },
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| EstimateError::LinearSolver(format!("symbolic analysis: {e:?}")))?;
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let mem = MemBuffer::try_new(req)
            .map_err(|e| EstimateError::LinearSolver(format!("workspace allocation: {e:?}")))?;
        let l_values = vec![0.0; symbolic.len_val()];
        Ok(Cholesky::Sparse(Box::new(SparseCholesky {
            symbolic,
            col_ptr: pattern.col_ptr.clone(),
            row_idx: pattern.row_idx.clone(),
            l_values,
            mem,
            factored: false,
        })))
    }

    /// Factorises the matrix `values` (lower CSC of `pattern`). `Err(index)` when a pivot is
    /// not positive (the matrix is not numerically positive definite); `index` is the
    /// offending column in the original ordering when known.
    pub fn factor(
        &mut self,
        pattern: &Pattern,
        values: &[f64],
    ) -> std::result::Result<(), Option<usize>> {
        match self {
            Cholesky::Dense(slot) => {
                let m = pattern.to_dense(values);
                *slot = nalgebra::Cholesky::new(m.clone());
                if slot.is_some() {
                    Ok(())
                } else {
                    Err(failing_pivot(m))
                }
            }
            Cholesky::Sparse(s) => {
                s.factored = false;
                let a = SparseColMatRef::new(
                    SymbolicSparseColMatRef::new_checked(
                        pattern.n, pattern.n, &s.col_ptr, None, &s.row_idx,
                    ),
                    values,
                );
                let stack = MemStack::new(&mut s.mem);
                let res = s.symbolic.factorize_numeric_llt(
                    &mut s.l_values,
                    a,
                    Side::Lower,
                    LltRegularization::default(),
                    Par::Seq,
                    stack,
                    Default::default(),
                );
                match res {
                    Ok(_) => {
                        s.factored = true;
                        Ok(())
                    }
                    Err(faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot {
                        index,
                    }) => {
                        let orig = s.symbolic.perm().map(|p| p.arrays().0.get(index).copied());
                        Err(orig.unwrap_or(Some(index)))
                    }
                }
            }
        }
    }

    /// Solves A X = B in place for the factored matrix; `b` is n × k column-major.
    pub fn solve_in_place(&mut self, b: &mut [f64], n: usize, k: usize) -> Result<()> {
        match self {
            Cholesky::Dense(Some(ch)) => {
                let mut m = DMatrix::from_column_slice(n, k, b);
                ch.solve_mut(&mut m);
                b.copy_from_slice(m.as_slice());
                Ok(())
            }
            Cholesky::Sparse(s) if s.factored => {
                if k > 1 {
                    let req = s.symbolic.solve_in_place_scratch::<f64>(k, Par::Seq);
                    let mut mem = MemBuffer::try_new(req).map_err(|e| {
                        EstimateError::LinearSolver(format!("workspace allocation: {e:?}"))
                    })?;
                    let llt = LltRef::new(&s.symbolic, &s.l_values);
                    llt.solve_in_place_with_conj(
                        Conj::No,
                        MatMut::from_column_major_slice_mut(b, n, k),
                        Par::Seq,
                        MemStack::new(&mut mem),
                    );
                } else {
                    let llt = LltRef::new(&s.symbolic, &s.l_values);
                    llt.solve_in_place_with_conj(
                        Conj::No,
                        MatMut::from_column_major_slice_mut(b, n, 1),
                        Par::Seq,
                        MemStack::new(&mut s.mem),
                    );
                }
                Ok(())
            }
            _ => Err(EstimateError::LinearSolver(
                "solve requested before a successful factorisation".into(),
            )),
        }
    }

    /// The squared diagonal of the Cholesky factor, L_ii², indexed by the ORIGINAL
    /// (unpermuted) column: the pivots of the elimination, used to detect near-singular
    /// directions.
    pub fn pivots(&self, n: usize) -> Vec<f64> {
        match self {
            Cholesky::Dense(Some(ch)) => {
                let l = ch.l_dirty();
                (0..n).map(|i| l[(i, i)] * l[(i, i)]).collect()
            }
            Cholesky::Sparse(s) if s.factored => {
                let mut piv = vec![f64::NAN; n];
                match s.symbolic.raw() {
                    SymbolicCholeskyRaw::Simplicial(sym) => {
                        let cp = sym.col_ptr();
                        let ri = sym.row_idx();
                        for (j, pj) in piv.iter_mut().enumerate() {
                            let range = cp[j]..cp[j + 1];
                            for (&r, &l) in ri[range.clone()].iter().zip(&s.l_values[range]) {
                                if r == j {
                                    *pj = l * l;
                                }
                            }
                        }
                    }
                    SymbolicCholeskyRaw::Supernodal(sym) => {
                        let llt = SupernodalLltRef::new(sym, &s.l_values);
                        for k in 0..sym.n_supernodes() {
                            let node = llt.supernode(k);
                            let v = node.val();
                            let start = node.start();
                            for j in 0..v.ncols() {
                                let d = v[(j, j)];
                                piv[start + j] = d * d;
                            }
                        }
                    }
                }
                match s.symbolic.perm() {
                    Some(p) => {
                        let fwd = p.arrays().0;
                        let mut out = vec![f64::NAN; n];
                        for (i, &f) in fwd.iter().enumerate() {
                            out[f] = piv[i];
                        }
                        out
                    }
                    None => piv,
                }
            }
            _ => vec![f64::NAN; n],
        }
    }
}

/// The first column where a plain Cholesky of `m` meets a non-positive pivot (only run after
/// nalgebra's factorisation failed, to name the offending column).
fn failing_pivot(mut m: DMatrix<f64>) -> Option<usize> {
    let n = m.nrows();
    for j in 0..n {
        let mut d = m[(j, j)];
        for k in 0..j {
            d -= m[(j, k)] * m[(j, k)];
        }
        if d.is_nan() || d <= 0.0 {
            return Some(j);
        }
        let d = d.sqrt();
        m[(j, j)] = d;
        for i in j + 1..n {
            let mut v = m[(i, j)];
            for k in 0..j {
                v -= m[(i, k)] * m[(j, k)];
            }
            m[(i, j)] = v / d;
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd_pattern() -> (Pattern, Vec<f64>, DMatrix<f64>) {
        // Blocks of sizes 2, 3, 1, 2 coupled as a chain plus (0, 3).
        let dims = [2, 3, 1, 2];
        let pattern = Pattern::new(&dims, [(1, 0), (2, 1), (3, 2), (0, 3)]);
        let mut values = vec![0.0; pattern.nnz()];
        for (k, v) in values.iter_mut().enumerate() {
            *v = ((k * 7919) % 13) as f64 / 13.0 - 0.5;
        }
        for &p in &pattern.diag_pos {
            values[p] = 10.0;
        }
        let dense = pattern.to_dense(&values);
        (pattern, values, dense)
    }

    #[test]
    fn sparse_and_dense_solves_match_the_dense_inverse() {
        let (pattern, values, dense) = spd_pattern();
        let n = pattern.n;
        let rhs: Vec<f64> = (0..n).map(|i| i as f64 - 3.0).collect();
        let want = dense
            .clone()
            .cholesky()
            .unwrap()
            .solve(&nalgebra::DVector::from_vec(rhs.clone()));
        for is_dense in [true, false] {
            let mut ch = Cholesky::new(&pattern, is_dense, None).unwrap();
            ch.factor(&pattern, &values).unwrap();
            let mut b = rhs.clone();
            ch.solve_in_place(&mut b, n, 1).unwrap();
            for i in 0..n {
                assert!((b[i] - want[i]).abs() < 1e-12);
            }
            // The product of the pivots is det(A), independent of the ordering.
            let det: f64 = ch.pivots(n).iter().product();
            assert!(
                (det / dense.determinant() - 1.0).abs() < 1e-10,
                "dense={is_dense}"
            );
            let mut x = vec![0.0; n];
            pattern.mul_vec(&values, &b, &mut x);
            for i in 0..n {
                assert!((x[i] - rhs[i]).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn indefinite_matrix_fails_to_factor() {
        let (pattern, mut values, _) = spd_pattern();
        values[pattern.diag_pos[4]] = -1.0;
        for is_dense in [true, false] {
            let mut ch = Cholesky::new(&pattern, is_dense, None).unwrap();
            assert!(ch.factor(&pattern, &values).is_err());
            let mut b = vec![1.0; pattern.n];
            assert!(ch.solve_in_place(&mut b, pattern.n, 1).is_err());
        }
    }
}
