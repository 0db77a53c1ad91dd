//! The Gaussian kernel matrix `G` of non-rigid CPD (000_3b1454b2b2194811.txt eq. (3.17),
//! `g_ij = exp(−‖y_i − y_j‖² / 2β²)`) and its low-rank approximation `G ≈ Q Λ Qᵀ` by its top
//! eigenpairs (Myronenko & Song 2010, §4.3 "fast implementation").
//!
//! The eigenpairs come from a Nyström approximation refined by subspace iteration:
//! 1. `L = min(M, 2K + 16)` landmarks by farthest-point sampling (deterministic, covers the
//!    shape evenly), `G ≈ C Cᵀ` with `C = G_ML · U_L S_L^{-1/2}` from the eigenpairs
//!    `U_L S_L U_Lᵀ` of the landmark block `G_LL`; the eigenpairs of `C Cᵀ` follow from the
//!    small `L × L` matrix `CᵀC`. Cost `O(M L²)`, never an `M × M` matrix.
//! 2. `power_iterations` steps of block subspace iteration with the exact `G` (products
//!    computed row block by row block, `O(M² L)` each, still without storing `G`), then a
//!    Rayleigh–Ritz step. The Gaussian kernel's spectrum decays fast, so one or two steps
//!    give the top K eigenpairs of `G` to ~1e−6 relative (checked in the tests against a dense
//!    symmetric eigendecomposition).

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use rayon::prelude::*;

use super::estep::exp_neg;

/// `G v` for `v` (M × k) without storing `G`: one row of `G` at a time (rows in parallel), under
/// runtime instruction-set dispatch so the exponentials and the row products vectorise.
fn kernel_times<const D: usize>(y: &[[f64; D]], inv2b2: f64, v: &DMatrix<f64>) -> DMatrix<f64> {
    let m = y.len();
    let k = v.ncols();
    // Row-major copy of v for contiguous inner loops.
    let vr: Vec<f64> = (0..m)
        .flat_map(|i| (0..k).map(move |c| (i, c)))
        .map(|(i, c)| v[(i, c)])
        .collect();
    let mut out = vec![0.0; m * k];
    let arch = pulp::Arch::new();
    out.par_chunks_mut(k).zip(y.par_iter()).for_each_init(
        || vec![0.0; m],
        |g, (orow, yi)| {
            arch.dispatch(KernelRow {
                y,
                yi,
                inv2b2,
                vr: &vr,
                g,
                orow,
            })
        },
    );
    DMatrix::from_row_slice(m, k, &out)
}

/// One row of [`kernel_times`].
struct KernelRow<'a, const D: usize> {
    y: &'a [[f64; D]],
    yi: &'a [f64; D],
    inv2b2: f64,
    vr: &'a [f64],
    g: &'a mut [f64],
    orow: &'a mut [f64],
}

impl<const D: usize> pulp::WithSimd for KernelRow<'_, D> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        let k = self.orow.len();
        for (gj, yj) in self.g.iter_mut().zip(self.y) {
            let mut d = 0.0;
            for (a, b) in self.yi.iter().zip(yj) {
                let e = a - b;
                d += e * e;
            }
            *gj = exp_neg(-d * self.inv2b2);
        }
        for (j, gj) in self.g.iter().enumerate() {
            let vrow = &self.vr[j * k..(j + 1) * k];
            for (o, vv) in self.orow.iter_mut().zip(vrow) {
                *o += gj * vv;
            }
        }
    }
}

/// The dense kernel matrix `G` (M × M).
pub(crate) fn kernel_matrix<const D: usize>(y: &[[f64; D]], beta: f64) -> DMatrix<f64> {
    let m = y.len();
    let inv2b2 = 0.5 / (beta * beta);
    let mut data = vec![0.0; m * m];
    data.par_chunks_mut(m.max(1))
        .zip(y.par_iter())
        .for_each(|(col, yi)| {
            for (c, yj) in col.iter_mut().zip(y) {
                let mut d = 0.0;
                for a in 0..D {
                    let e = yi[a] - yj[a];
                    d += e * e;
                }
                *c = exp_neg(-d * inv2b2);
            }
        });
    DMatrix::from_vec(m, m, data)
}

/// Farthest-point sampling of `l` indices, starting from point 0.
fn farthest_points<const D: usize>(y: &[[f64; D]], l: usize) -> Vec<usize> {
    let mut chosen = Vec::with_capacity(l);
    let mut best = vec![f64::INFINITY; y.len()];
    let mut next = 0usize;
    for _ in 0..l {
        chosen.push(next);
        let c = y[next];
        let mut far = (0usize, -1.0);
        for (j, (b, p)) in best.iter_mut().zip(y).enumerate() {
            let mut d = 0.0;
            for a in 0..D {
                let e = p[a] - c[a];
                d += e * e;
            }
            if d < *b {
                *b = d;
            }
            if *b > far.1 {
                far = (j, *b);
            }
        }
        if far.1 <= 0.0 {
            break; // every remaining point coincides with a landmark
        }
        next = far.0;
    }
    chosen
}

/// Orthonormal basis of the columns of `z` (thin QR, faer: blocked and parallel).
fn orthonormalize(z: DMatrix<f64>) -> DMatrix<f64> {
    let (r, c) = z.shape();
    let q = faer::MatRef::from_column_major_slice(z.as_slice(), r, c)
        .qr()
        .compute_thin_Q();
    from_faer(q.as_ref())
}

/// `G v` for a symmetric `G` (M × M) and a thin `v` (M × k, k ≤ 3 here): element `i` of column
/// `c` is the dot product of column `i` of `G` (= row `i`) with `v_c`, columns in parallel. One
/// streaming pass over `G` for all `k` columns; the `M × M × k` product of a general GEMM is
/// memory-bound here and its thread synchronisation dominated the full-rank CG step.
pub(crate) fn sym_times(g: &DMatrix<f64>, v: &DMatrix<f64>) -> DMatrix<f64> {
    let m = g.nrows();
    let k = v.ncols();
    let mut out = vec![0.0; m * k];
    let gs = g.as_slice();
    let vs = v.as_slice();
    // Row-major output chunks: rows i.. of out, k values each.
    out.par_chunks_mut(32 * k.max(1))
        .enumerate()
        .for_each(|(c, chunk)| {
            for (r, o) in chunk.chunks_mut(k.max(1)).enumerate() {
                let i = c * 32 + r;
                let col = &gs[i * m..(i + 1) * m];
                for (cc, ov) in o.iter_mut().enumerate() {
                    let vc = &vs[cc * m..(cc + 1) * m];
                    let mut acc = [0.0; 4];
                    let mut a = col.chunks_exact(4);
                    let mut b = vc.chunks_exact(4);
                    for (x, y) in (&mut a).zip(&mut b) {
                        for l in 0..4 {
                            acc[l] += x[l] * y[l];
                        }
                    }
                    let mut sum = (acc[0] + acc[1]) + (acc[2] + acc[3]);
                    for (x, y) in a.remainder().iter().zip(b.remainder()) {
                        sum += x * y;
                    }
                    *ov = sum;
                }
            }
        });
    DMatrix::from_row_slice(m, k, &out)
}

/// A faer matrix as a nalgebra one.
pub(crate) fn from_faer(m: faer::MatRef<'_, f64>) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Rows per task of the tall products in [`mul`].
const MUL_ROWS: usize = 2048;

/// `op(a) · b` (`op(a) = aᵀ` when `transpose_a`) for the tall-and-thin products of the kernels
/// (`Qᵀ D Q`, `Qᵀ F`, `Q z`, `G_ML U`): the long dimension is cut into blocks of
/// [`MUL_ROWS`] rows, one rayon task each running faer's sequential kernel; partial sums of
/// `aᵀ b` are added in block order (deterministic). faer's own parallel product synchronises
/// its threads with spinning barriers, which dominated these small products on a loaded
/// machine.
pub(crate) fn mul(a: &DMatrix<f64>, transpose_a: bool, b: &DMatrix<f64>) -> DMatrix<f64> {
    use faer::{Accum, MatMut, MatRef, Par};
    let fa = MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols());
    let fb = MatRef::from_column_major_slice(b.as_slice(), b.nrows(), b.ncols());
    let seq = |dst: MatMut<'_, f64>, l: MatRef<'_, f64>, r: MatRef<'_, f64>| {
        faer::linalg::matmul::matmul(dst, Accum::Replace, l, r, 1.0, Par::Seq);
    };
    let long = a.nrows();
    let blocks = long.div_ceil(MUL_ROWS);
    if transpose_a {
        let (r, c) = (a.ncols(), b.ncols());
        let parts: Vec<DMatrix<f64>> = (0..blocks)
            .into_par_iter()
            .map(|k| {
                let r0 = k * MUL_ROWS;
                let len = MUL_ROWS.min(long - r0);
                let mut part = DMatrix::zeros(r, c);
                seq(
                    MatMut::from_column_major_slice_mut(part.as_mut_slice(), r, c),
                    fa.subrows(r0, len).transpose(),
                    fb.subrows(r0, len),
                );
                part
            })
            .collect();
        let mut out = DMatrix::zeros(r, c);
        for part in &parts {
            out += part;
        }
        out
    } else {
        let c = b.ncols();
        let parts: Vec<DMatrix<f64>> = (0..blocks)
            .into_par_iter()
            .map(|k| {
                let r0 = k * MUL_ROWS;
                let len = MUL_ROWS.min(long - r0);
                let mut part = DMatrix::zeros(len, c);
                seq(
                    MatMut::from_column_major_slice_mut(part.as_mut_slice(), len, c),
                    fa.subrows(r0, len),
                    fb,
                );
                part
            })
            .collect();
        let mut out = DMatrix::zeros(long, c);
        for (k, part) in parts.iter().enumerate() {
            out.rows_mut(k * MUL_ROWS, part.nrows()).copy_from(part);
        }
        out
    }
}

/// `Qᵀ d(w) Q` (K × K, symmetric) for an M × K matrix `Q` and weights `w ≥ 0`: blocks of
/// [`MUL_ROWS`] rows, each scaled by `√w` and multiplied into the lower triangle only (half the
/// multiply–adds of a general product), partial sums added in a fixed order, then mirrored.
pub(crate) fn weighted_gram(q: &DMatrix<f64>, w: &[f64]) -> DMatrix<f64> {
    use faer::linalg::matmul::triangular::{BlockStructure, matmul};
    use faer::{Accum, MatMut, MatRef, Par};
    let (m, k) = (q.nrows(), q.ncols());
    let blocks = m.div_ceil(MUL_ROWS);
    let parts: Vec<DMatrix<f64>> = (0..blocks)
        .into_par_iter()
        .map(|b| {
            let r0 = b * MUL_ROWS;
            let len = MUL_ROWS.min(m - r0);
            let mut s = DMatrix::<f64>::zeros(len, k);
            for j in 0..k {
                let src = &q.column(j);
                for i in 0..len {
                    s[(i, j)] = src[r0 + i] * w[r0 + i].max(0.0).sqrt();
                }
            }
            let fs = MatRef::from_column_major_slice(s.as_slice(), len, k);
            let mut part = DMatrix::zeros(k, k);
            matmul(
                MatMut::from_column_major_slice_mut(part.as_mut_slice(), k, k),
                BlockStructure::TriangularLower,
                Accum::Replace,
                fs.transpose(),
                BlockStructure::Rectangular,
                fs,
                BlockStructure::Rectangular,
                1.0,
                Par::Seq,
            );
            part
        })
        .collect();
    let mut out = DMatrix::zeros(k, k);
    for part in &parts {
        for j in 0..k {
            for i in j..k {
                out[(i, j)] += part[(i, j)];
            }
        }
    }
    for j in 0..k {
        for i in 0..j {
            out[(i, j)] = out[(j, i)];
        }
    }
    out
}

/// Top-`k` eigenpairs of `G` (eigenvalues in decreasing order): `(Q (M × k'), λ (k'))` with
/// `k' ≤ k` when `G` has numerical rank below `k` (coincident points).
pub(crate) fn low_rank_kernel<const D: usize>(
    y: &[[f64; D]],
    beta: f64,
    k: usize,
    power_iterations: usize,
) -> (DMatrix<f64>, DVector<f64>) {
    low_rank_impl(y, beta, k, power_iterations, None)
}

/// [`low_rank_kernel`] for a kernel matrix already formed (`g = kernel_matrix(y, beta)`): the
/// landmark columns are read from `g` and the subspace iterations multiply by it.
pub(crate) fn low_rank_of_dense<const D: usize>(
    y: &[[f64; D]],
    beta: f64,
    g: &DMatrix<f64>,
    k: usize,
    power_iterations: usize,
) -> (DMatrix<f64>, DVector<f64>) {
    low_rank_impl(y, beta, k, power_iterations, Some(g))
}

fn low_rank_impl<const D: usize>(
    y: &[[f64; D]],
    beta: f64,
    k: usize,
    power_iterations: usize,
    dense: Option<&DMatrix<f64>>,
) -> (DMatrix<f64>, DVector<f64>) {
    let m = y.len();
    let inv2b2 = 0.5 / (beta * beta);
    let l = m.min(2 * k + 16);
    let land = farthest_points(y, l);
    let l = land.len();
    let yl: Vec<[f64; D]> = land.iter().map(|&i| y[i]).collect();
    // G_LL eigenpairs.
    let gll = match dense {
        Some(g) => DMatrix::from_fn(l, l, |r, c| g[(land[r], land[c])]),
        None => kernel_matrix(&yl, beta),
    };
    let eig = SymmetricEigen::new(gll);
    let smax = eig.eigenvalues.max();
    let keep: Vec<usize> = (0..l)
        .filter(|&i| eig.eigenvalues[i] > 1e-10 * smax)
        .collect();
    // C = G_ML U S^{-1/2}.
    let mut us = DMatrix::zeros(l, keep.len());
    for (c, &i) in keep.iter().enumerate() {
        let s = eig.eigenvalues[i].sqrt();
        for r in 0..l {
            us[(r, c)] = eig.eigenvectors[(r, i)] / s;
        }
    }
    let mut gdata = vec![0.0; m * l];
    gdata
        .par_chunks_mut(m.max(1))
        .zip(yl.par_iter().zip(land.par_iter()))
        .for_each(|(col, (yc, &lc))| {
            for (r, (v, yr)) in col.iter_mut().zip(y).enumerate() {
                *v = match dense {
                    Some(g) => g[(r, lc)],
                    None => {
                        let mut d = 0.0;
                        for a in 0..D {
                            let e = yr[a] - yc[a];
                            d += e * e;
                        }
                        exp_neg(-d * inv2b2)
                    }
                };
            }
        });
    let gml = DMatrix::from_vec(m, l, gdata);
    let cmat = mul(&gml, false, &us);
    if power_iterations == 0 && l < m {
        // Nyström only: the eigenpairs of C Cᵀ from those of the small CᵀC = V Σ² Vᵀ:
        // C Cᵀ (C v_i) = σ_i² (C v_i), so q_i = C v_i / σ_i (orthonormal: q_iᵀ q_j = δ_ij).
        let ctc = mul(&cmat, true, &cmat);
        let ctc = (&ctc + ctc.transpose()) * 0.5;
        let eig = SymmetricEigen::new(ctc);
        let order = leading_eigenpairs(&eig, k);
        let mut vs = DMatrix::zeros(eig.eigenvectors.nrows(), order.len());
        let mut lam = DVector::zeros(order.len());
        for (c, &i) in order.iter().enumerate() {
            let s = eig.eigenvalues[i].sqrt();
            vs.set_column(c, &(eig.eigenvectors.column(i) / s));
            lam[c] = eig.eigenvalues[i];
        }
        return (mul(&cmat, false, &vs), lam);
    }
    let mut basis = orthonormalize(cmat.clone());
    let times = |b: &DMatrix<f64>| match dense {
        Some(g) => mul(g, false, b),
        None => kernel_times(y, inv2b2, b),
    };
    for _ in 0..power_iterations {
        basis = orthonormalize(times(&basis));
    }
    // Rayleigh–Ritz on span(basis): H = Bᵀ G B with the exact G.
    let gb = times(&basis);
    let h = mul(&basis, true, &gb);
    let h = (&h + h.transpose()) * 0.5;
    ritz(&basis, h, k)
}

/// Indices of the (at most) `k` largest eigenvalues of `eig`, largest first, keeping only those
/// above 1e-12 of the largest (the numerically non-zero part of a PSD spectrum).
fn leading_eigenpairs(eig: &SymmetricEigen<f64, nalgebra::Dyn>, k: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let lmax = eig.eigenvalues.max().max(0.0);
    order
        .into_iter()
        .filter(|&i| eig.eigenvalues[i] > 1e-12 * lmax)
        .take(k)
        .collect()
}

/// Top-k Ritz pairs of the symmetric `h` on `basis`.
fn ritz(basis: &DMatrix<f64>, h: DMatrix<f64>, k: usize) -> (DMatrix<f64>, DVector<f64>) {
    let eig = SymmetricEigen::new(h);
    let order = leading_eigenpairs(&eig, k);
    let mut v = DMatrix::zeros(eig.eigenvectors.nrows(), order.len());
    let mut lam = DVector::zeros(order.len());
    for (c, &i) in order.iter().enumerate() {
        v.set_column(c, &eig.eigenvectors.column(i));
        lam[c] = eig.eigenvalues[i];
    }
    (mul(basis, false, &v), lam)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn cloud(m: usize, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = Pcg64::seed_from_u64(seed);
        (0..m)
            .map(|_| [rng.random::<f64>() * 4.0, rng.random::<f64>() * 3.0])
            .collect()
    }

    #[test]
    fn low_rank_matches_dense_eigendecomposition() {
        let y = cloud(400, 3);
        let beta = 1.0;
        let g = kernel_matrix(&y, beta);
        let eig = SymmetricEigen::new(g.clone());
        let mut ev: Vec<f64> = eig.eigenvalues.iter().copied().collect();
        ev.sort_by(|a, b| b.total_cmp(a));
        for iters in [1, 2] {
            let (q, lam) = low_rank_kernel(&y, beta, 20, iters);
            assert_eq!(lam.len(), 20);
            for i in 0..20 {
                let rel = (lam[i] - ev[i]).abs() / ev[i];
                assert!(
                    rel < 1e-6,
                    "iters {iters} eigenvalue {i}: {} vs {} ({rel:e})",
                    lam[i],
                    ev[i]
                );
            }
            // Orthonormal columns and G q ≈ λ q.
            let qtq = q.transpose() * &q;
            assert!((qtq - DMatrix::identity(20, 20)).amax() < 1e-10);
            let res = &g * &q - &q * DMatrix::from_diagonal(&lam);
            assert!(res.amax() < 1e-5 * ev[0], "residual {}", res.amax());
        }
        // Nyström alone is a coarser but still sound approximation of the top of the spectrum.
        let (_, lam0) = low_rank_kernel(&y, beta, 20, 0);
        for i in 0..5 {
            assert!(
                (lam0[i] - ev[i]).abs() / ev[i] < 1e-3,
                "nystrom {i}: {} vs {}",
                lam0[i],
                ev[i]
            );
        }
    }

    #[test]
    fn kernel_times_matches_dense() {
        let y = cloud(150, 9);
        let g = kernel_matrix(&y, 0.7);
        let v = DMatrix::from_fn(150, 3, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0);
        let a = kernel_times(&y, 0.5 / 0.49, &v);
        assert!((a - &g * &v).amax() < 1e-10);
    }

    #[test]
    fn weighted_gram_matches_the_dense_product() {
        // Several row blocks plus a partial one, and a zero weight.
        let m = 2 * MUL_ROWS + 37;
        let mut rng = Pcg64::seed_from_u64(9);
        let q = DMatrix::from_fn(m, 13, |_, _| rng.random::<f64>() - 0.5);
        let mut w: Vec<f64> = (0..m).map(|_| rng.random::<f64>() * 2.0).collect();
        w[5] = 0.0;
        let dq = DMatrix::from_fn(m, 13, |i, j| w[i] * q[(i, j)]);
        let dense = q.transpose() * dq;
        let g = weighted_gram(&q, &w);
        assert!(
            (&g - &dense).amax() < 1e-10 * dense.amax(),
            "{}",
            (&g - &dense).amax()
        );
        assert_eq!(g, g.transpose());
    }
}
