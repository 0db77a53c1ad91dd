//! Dense kernels on column-major slices for the small matrices of the filters (n ≲ 30).
//!
//! nalgebra's dynamically sized operations carry a per-call and per-element overhead that
//! dominates at these sizes; these loops run on plain slices so the compiler can drop the
//! bounds checks and keep the inner loops tight. Every matrix is column-major: entry (i, j)
//! of an `r × c` matrix is at `i + j·r`.

/// Above this size (every dimension) products go to nalgebra's `gemm`, which hands them to
/// `matrixmultiply` (packed, SIMD kernels chosen at run time); below it the plain loops win
/// (measured on the 9-state filter: the packing costs more than the 9 × 9 × 19 product).
const BLOCKED_MIN: usize = 17;

/// Calls the `#[inline(always)]` kernel body `$f` with its leading dimension argument replaced
/// by a literal for the small sizes of the common models (2, 3, 4, 6, 9), so that each of
/// those calls is compiled for a fixed size (unrolled, vectorised, no bounds checks); any
/// other size runs the same body with the size at run time.
macro_rules! fixed_dim {
    ($n:expr, $f:ident($($arg:expr),* $(,)?)) => {
        match $n {
            2 => $f(2, $($arg),*),
            3 => $f(3, $($arg),*),
            4 => $f(4, $($arg),*),
            6 => $f(6, $($arg),*),
            9 => $f(9, $($arg),*),
            n => $f(n, $($arg),*),
        }
    };
}

/// `out = a · b` (`m × k` times `k × n`), through `matrixmultiply` when every dimension is
/// at least [`BLOCKED_MIN`].
pub(crate) fn product(m: usize, k: usize, n: usize, a: &[f64], b: &[f64], out: &mut [f64]) {
    if m >= BLOCKED_MIN && k >= BLOCKED_MIN && n >= BLOCKED_MIN {
        let av = nalgebra::DMatrixView::from_slice(&a[..m * k], m, k);
        let bv = nalgebra::DMatrixView::from_slice(&b[..k * n], k, n);
        let mut ov = nalgebra::DMatrixViewMut::from_slice(&mut out[..m * n], m, n);
        ov.gemm(1.0, &av, &bv, 0.0);
    } else {
        gemm(m, k, n, a, b, out);
    }
}

/// `out = a · diag(w) · aᵀ` for `a` (`r × c`), through `matrixmultiply` for large enough
/// sizes (`scratch` holds `a · diag(w)`, `r × c`), else [`weighted_gram`]. Symmetrised.
pub(crate) fn weighted_gram_auto(
    r: usize,
    c: usize,
    a: &[f64],
    w: &[f64],
    scratch: &mut [f64],
    out: &mut [f64],
) {
    if r >= BLOCKED_MIN && c >= BLOCKED_MIN {
        let aw = &mut scratch[..r * c];
        for ((dst, src), &wk) in aw.chunks_exact_mut(r).zip(a.chunks_exact(r)).zip(w) {
            for (d, &x) in dst.iter_mut().zip(src) {
                *d = wk * x;
            }
        }
        let awv = nalgebra::DMatrixView::from_slice(aw, r, c);
        // aᵀ as a strided view of a's storage: entry (k, i) is a[i + k r].
        let atv = nalgebra::MatrixView::<
            f64,
            nalgebra::Dyn,
            nalgebra::Dyn,
            nalgebra::Dyn,
            nalgebra::Dyn,
        >::from_slice_with_strides(&a[..r * c], c, r, r, 1);
        let mut ov = nalgebra::DMatrixViewMut::from_slice(&mut out[..r * r], r, r);
        ov.gemm(1.0, &awv, &atv, 0.0);
        // Rounding in the blocked product can differ between (i, j) and (j, i).
        let o = &mut out[..r * r];
        for j in 0..r {
            for i in (j + 1)..r {
                let v = 0.5 * (o[i + j * r] + o[j + i * r]);
                o[i + j * r] = v;
                o[j + i * r] = v;
            }
        }
    } else if r <= 4 {
        weighted_gram_small(r, a, w, out);
    } else {
        weighted_gram(r, a, w, out);
    }
}

/// [`weighted_gram`] for few rows: one accumulation over the columns per entry of the lower
/// triangle (the per-column loops of [`weighted_gram`] would be shorter than their overhead).
pub(crate) fn weighted_gram_small(r: usize, a: &[f64], w: &[f64], out: &mut [f64]) {
    fixed_dim!(r, weighted_gram_small_body(a, w, out))
}

#[inline(always)]
fn weighted_gram_small_body(r: usize, a: &[f64], w: &[f64], out: &mut [f64]) {
    let out = &mut out[..r * r];
    for j in 0..r {
        for i in j..r {
            let mut acc = 0.0;
            for (col, &wk) in a.chunks_exact(r.max(1)).zip(w) {
                acc += wk * col[i] * col[j];
            }
            out[i + j * r] = acc;
            out[j + i * r] = acc;
        }
    }
}

/// `out = a · b` for `a` (`m × k`) and `b` (`k × n`) with plain loops.
pub(crate) fn gemm(m: usize, k: usize, n: usize, a: &[f64], b: &[f64], out: &mut [f64]) {
    fixed_dim!(m, gemm_body(k, n, a, b, out))
}

#[inline(always)]
fn gemm_body(m: usize, k: usize, n: usize, a: &[f64], b: &[f64], out: &mut [f64]) {
    let a = &a[..m * k];
    let b = &b[..k * n];
    for (oj, bj) in out[..m * n]
        .chunks_exact_mut(m.max(1))
        .zip(b.chunks_exact(k.max(1)))
    {
        oj.fill(0.0);
        for (ap, &s) in a.chunks_exact(m.max(1)).zip(bj) {
            for (o, &x) in oj.iter_mut().zip(ap) {
                *o += s * x;
            }
        }
    }
}

/// `out[:, j] = a[:, j] − v` for every column of `a` (`r × c`).
pub(crate) fn sub_columns(r: usize, a: &[f64], v: &[f64], out: &mut [f64]) {
    fixed_dim!(r, sub_columns_body(a, v, out))
}

#[inline(always)]
fn sub_columns_body(r: usize, a: &[f64], v: &[f64], out: &mut [f64]) {
    let v = &v[..r];
    for (o, x) in out.chunks_exact_mut(r.max(1)).zip(a.chunks_exact(r.max(1))) {
        for ((oi, &xi), &vi) in o.iter_mut().zip(x).zip(v) {
            *oi = xi - vi;
        }
    }
}

/// `out[:, j] = v + a[:, j]` for every column of `a` (`r × c`).
pub(crate) fn add_columns(r: usize, v: &[f64], a: &[f64], out: &mut [f64]) {
    fixed_dim!(r, add_columns_body(v, a, out))
}

#[inline(always)]
fn add_columns_body(r: usize, v: &[f64], a: &[f64], out: &mut [f64]) {
    let v = &v[..r];
    for (o, x) in out.chunks_exact_mut(r.max(1)).zip(a.chunks_exact(r.max(1))) {
        for ((oi, &xi), &vi) in o.iter_mut().zip(x).zip(v) {
            *oi = vi + xi;
        }
    }
}

/// `out = a · w` (weighted sum of the columns of `a`, `r × c`).
pub(crate) fn weighted_sum(r: usize, a: &[f64], w: &[f64], out: &mut [f64]) {
    fixed_dim!(r, weighted_sum_body(a, w, out))
}

#[inline(always)]
fn weighted_sum_body(r: usize, a: &[f64], w: &[f64], out: &mut [f64]) {
    let out = &mut out[..r];
    out.fill(0.0);
    for (x, &wk) in a.chunks_exact(r.max(1)).zip(w) {
        for (o, &xi) in out.iter_mut().zip(x) {
            *o += wk * xi;
        }
    }
}

/// `out = Σₖ wₖ aₖ bₖᵀ` over the columns of `a` (`ra × c`) and `b` (`rb × c`); `out` is
/// `ra × rb`.
pub(crate) fn weighted_outer(
    ra: usize,
    rb: usize,
    a: &[f64],
    w: &[f64],
    b: &[f64],
    out: &mut [f64],
) {
    fixed_dim!(ra, weighted_outer_body(rb, a, w, b, out))
}

#[inline(always)]
fn weighted_outer_body(ra: usize, rb: usize, a: &[f64], w: &[f64], b: &[f64], out: &mut [f64]) {
    let out = &mut out[..ra * rb];
    out.fill(0.0);
    for ((ak, bk), &wk) in a
        .chunks_exact(ra.max(1))
        .zip(b.chunks_exact(rb.max(1)))
        .zip(w)
    {
        for (oj, &bjk) in out.chunks_exact_mut(ra.max(1)).zip(bk) {
            let s = wk * bjk;
            for (o, &x) in oj.iter_mut().zip(ak) {
                *o += s * x;
            }
        }
    }
}

/// `out = Σₖ wₖ aₖ aₖᵀ` (`r × r`): the lower triangle accumulated, then mirrored, so the
/// result is exactly symmetric.
pub(crate) fn weighted_gram(r: usize, a: &[f64], w: &[f64], out: &mut [f64]) {
    fixed_dim!(r, weighted_gram_body(a, w, out))
}

#[inline(always)]
fn weighted_gram_body(r: usize, a: &[f64], w: &[f64], out: &mut [f64]) {
    let out = &mut out[..r * r];
    out.fill(0.0);
    for (ak, &wk) in a.chunks_exact(r.max(1)).zip(w) {
        for (j, oj) in out.chunks_exact_mut(r).enumerate() {
            let s = wk * ak[j];
            for (o, &x) in oj[j..].iter_mut().zip(&ak[j..]) {
                *o += s * x;
            }
        }
    }
    mirror_lower(r, out);
}

/// `p ← p − a bᵀ` on the lower triangle of the `r × r` matrix `p` (mirrored to the upper, so
/// the result is exactly symmetric), for `a`, `b` of shape `r × c`. With `a = K` and
/// `b = Pxz` this is the covariance update `P⁻ − K S Kᵀ` (as `K S = Pxz`).
pub(crate) fn sub_lower_abt(r: usize, c: usize, a: &[f64], b: &[f64], p: &mut [f64]) {
    fixed_dim!(r, sub_lower_abt_body(c, a, b, p))
}

#[inline(always)]
fn sub_lower_abt_body(r: usize, c: usize, a: &[f64], b: &[f64], p: &mut [f64]) {
    let p = &mut p[..r * r];
    let a = &a[..r * c];
    let b = &b[..r * c];
    for (ak, bk) in a.chunks_exact(r.max(1)).zip(b.chunks_exact(r.max(1))) {
        for (j, pj) in p.chunks_exact_mut(r).enumerate() {
            let s = bk[j];
            for (o, &x) in pj[j..].iter_mut().zip(&ak[j..]) {
                *o -= s * x;
            }
        }
    }
    mirror_lower(r, p);
}

/// Copies the lower triangle of an `r × r` matrix onto its upper triangle.
pub(crate) fn mirror_lower(r: usize, m: &mut [f64]) {
    for j in 0..r {
        for i in (j + 1)..r {
            m[j + i * r] = m[i + j * r];
        }
    }
}

/// Lower Cholesky factor of the symmetric `n × n` matrix `a` (only its lower triangle is
/// read) into `l` (upper triangle zeroed). `false` unless positive definite (NaN included).
/// Left-looking, column by column, so every inner loop runs over a contiguous column.
pub(crate) fn cholesky(n: usize, a: &[f64], l: &mut [f64]) -> bool {
    fixed_dim!(n, cholesky_body(a, l))
}

#[inline(always)]
fn cholesky_body(n: usize, a: &[f64], l: &mut [f64]) -> bool {
    let l = &mut l[..n * n];
    for j in 0..n {
        let (done, rest) = l.split_at_mut(j * n);
        let lj = &mut rest[..n];
        lj[..j].fill(0.0);
        lj[j..].copy_from_slice(&a[j + j * n..(j + 1) * n]);
        // L[j.., j] = A[j.., j] − Σₖ L[j, k] L[j.., k], two columns k per pass over L[j.., j].
        let mut pairs = done.chunks_exact(2 * n);
        for lk in &mut pairs {
            let (a0, a1) = lk.split_at(n);
            let (s0, s1) = (a0[j], a1[j]);
            for ((o, &v0), &v1) in lj[j..].iter_mut().zip(&a0[j..]).zip(&a1[j..]) {
                *o -= s0 * v0 + s1 * v1;
            }
        }
        if let Some(lk) = pairs.remainder().get(..n) {
            let s0 = lk[j];
            for (o, &v) in lj[j..].iter_mut().zip(&lk[j..]) {
                *o -= s0 * v;
            }
        }
        let d = lj[j];
        // `d > 0` is false for NaN too.
        if d.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !d.is_finite() {
            return false;
        }
        let djj = d.sqrt();
        lj[j] = djj;
        let inv = 1.0 / djj;
        for o in &mut lj[j + 1..] {
            *o *= inv;
        }
    }
    true
}

/// `true` iff every value is finite: `x · 0` is NaN exactly for NaN and ±inf, summed in eight
/// independent lanes so the compiler vectorises the pass and the additions do not wait on
/// each other.
pub(crate) fn all_finite(a: &[f64]) -> bool {
    let mut acc = [0.0f64; 8];
    let chunks = a.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (s, &x) in acc.iter_mut().zip(c) {
            *s += x * 0.0;
        }
    }
    for (s, &x) in acc.iter_mut().zip(rest) {
        *s += x * 0.0;
    }
    acc.iter().sum::<f64>() == 0.0
}

/// `out[i + j m] = at[:, i] · b[:, j]` for `at` (`k × m`, the transpose of the left factor)
/// and `b` (`k × n`): contiguous dot products, faster than [`gemm`] when `m` is small.
pub(crate) fn gemm_tn(m: usize, k: usize, n: usize, at: &[f64], b: &[f64], out: &mut [f64]) {
    // Specialised on the length k of the dot products.
    fixed_dim!(k, gemm_tn_body(m, n, at, b, out))
}

#[inline(always)]
fn gemm_tn_body(k: usize, m: usize, n: usize, at: &[f64], b: &[f64], out: &mut [f64]) {
    let at = &at[..k * m];
    for (oj, bj) in out[..m * n]
        .chunks_exact_mut(m.max(1))
        .zip(b[..k * n].chunks_exact(k.max(1)))
    {
        for (o, ai) in oj.iter_mut().zip(at.chunks_exact(k.max(1))) {
            *o = ai.iter().zip(bj).map(|(x, y)| x * y).sum();
        }
    }
}

/// Solves `L X = B` in place for lower-triangular `L` (`n × n`) and `B` (`n × c`).
pub(crate) fn solve_lower(n: usize, l: &[f64], b: &mut [f64]) {
    fixed_dim!(n, solve_lower_body(l, b))
}

#[inline(always)]
fn solve_lower_body(n: usize, l: &[f64], b: &mut [f64]) {
    let l = &l[..n * n];
    for x in b.chunks_exact_mut(n.max(1)) {
        for (j, lj) in l.chunks_exact(n).enumerate() {
            let v = x[j] / lj[j];
            x[j] = v;
            for (xi, &lij) in x[j + 1..].iter_mut().zip(&lj[j + 1..]) {
                *xi -= lij * v;
            }
        }
    }
}

/// Solves `Lᵀ X = B` in place for lower-triangular `L` (`n × n`) and `B` (`n × c`).
pub(crate) fn solve_lower_transposed(n: usize, l: &[f64], b: &mut [f64]) {
    fixed_dim!(n, solve_lower_transposed_body(l, b))
}

#[inline(always)]
fn solve_lower_transposed_body(n: usize, l: &[f64], b: &mut [f64]) {
    let l = &l[..n * n];
    for x in b.chunks_exact_mut(n.max(1)) {
        for (j, lj) in l.chunks_exact(n).enumerate().rev() {
            let dot: f64 = lj[j + 1..]
                .iter()
                .zip(&x[j + 1..])
                .map(|(a, b)| a * b)
                .sum();
            x[j] = (x[j] - dot) / lj[j];
        }
    }
}

/// Transpose of an `r × c` matrix into `out` (`c × r`).
pub(crate) fn transpose(r: usize, c: usize, a: &[f64], out: &mut [f64]) {
    for j in 0..c {
        for i in 0..r {
            out[j + i * c] = a[i + j * r];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn mat(r: usize, c: usize, seed: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |i, j| {
            (((i * 7 + j * 13 + seed * 5) % 11) as f64 - 5.0) * 0.3
        })
    }

    fn spd_copy(a: &DMatrix<f64>) -> DMatrix<f64> {
        a * a.transpose() + DMatrix::identity(a.nrows(), a.nrows())
    }

    #[test]
    fn kernels_match_nalgebra() {
        let a = mat(4, 6, 1);
        let b = mat(6, 3, 2);
        let mut out = vec![0.0; 12];
        gemm(4, 6, 3, a.as_slice(), b.as_slice(), &mut out);
        assert!((DMatrix::from_column_slice(4, 3, &out) - &a * &b).amax() < 1e-12);

        let w: Vec<f64> = (0..6).map(|k| 0.1 * k as f64 - 0.2).collect();
        let wd = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&w));
        let c = mat(3, 6, 3);
        let mut o = vec![0.0; 12];
        weighted_outer(4, 3, a.as_slice(), &w, c.as_slice(), &mut o);
        assert!((DMatrix::from_column_slice(4, 3, &o) - &a * &wd * c.transpose()).amax() < 1e-12);
        let mut g = vec![0.0; 16];
        weighted_gram(4, a.as_slice(), &w, &mut g);
        assert!((DMatrix::from_column_slice(4, 4, &g) - &a * &wd * a.transpose()).amax() < 1e-12);

        let big = mat(9, 19, 4);
        let wb: Vec<f64> = (0..19).map(|k| 0.05 * k as f64 - 0.3).collect();
        let mut scratch = vec![0.0; 9 * 19];
        let mut gb = vec![0.0; 81];
        weighted_gram_auto(9, 19, big.as_slice(), &wb, &mut scratch, &mut gb);
        let wbd = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&wb));
        assert!(
            (DMatrix::from_column_slice(9, 9, &gb) - &big * &wbd * big.transpose()).amax() < 1e-12
        );
        let small = mat(3, 19, 6);
        let mut gs = vec![0.0; 9];
        weighted_gram_auto(3, 19, small.as_slice(), &wb, &mut scratch, &mut gs);
        assert!(
            (DMatrix::from_column_slice(3, 3, &gs) - &small * &wbd * small.transpose()).amax()
                < 1e-12
        );
        let f = mat(9, 9, 5);
        let mut fb = vec![0.0; 9 * 19];
        product(9, 9, 19, f.as_slice(), big.as_slice(), &mut fb);
        assert!((DMatrix::from_column_slice(9, 19, &fb) - &f * &big).amax() < 1e-12);

        let spd = &a * a.transpose() + DMatrix::identity(4, 4);
        let mut l = vec![0.0; 16];
        assert!(cholesky(4, spd.as_slice(), &mut l));
        let lm = DMatrix::from_column_slice(4, 4, &l);
        assert!((&lm * lm.transpose() - &spd).amax() < 1e-12);
        let mut x = b.as_slice()[..12].to_vec();
        solve_lower(4, &l, &mut x);
        solve_lower_transposed(4, &l, &mut x);
        let rhs = DMatrix::from_column_slice(4, 3, &b.as_slice()[..12]);
        assert!((&spd * DMatrix::from_column_slice(4, 3, &x) - rhs).amax() < 1e-10);
        let mut t = vec![0.0; 24];
        transpose(4, 6, a.as_slice(), &mut t);
        assert_eq!(DMatrix::from_column_slice(6, 4, &t), a.transpose());
        let mut pp = spd_copy(&a);
        let bb = mat(4, 6, 9);
        sub_lower_abt(4, 6, a.as_slice(), bb.as_slice(), pp.as_mut_slice());
        let expect = &a * a.transpose() + DMatrix::identity(4, 4) - &a * bb.transpose();
        for j in 0..4 {
            for i in j..4 {
                assert!((pp[(i, j)] - expect[(i, j)]).abs() < 1e-12);
                assert_eq!(pp[(i, j)], pp[(j, i)]);
            }
        }
        let mut tn = vec![0.0; 12];
        let at = a.transpose();
        gemm_tn(4, 6, 3, at.as_slice(), b.as_slice(), &mut tn);
        assert!((DMatrix::from_column_slice(4, 3, &tn) - &a * &b).amax() < 1e-12);
        assert!(all_finite(&[1.0, -2.0, 0.0]));
        assert!(!all_finite(&[1.0, f64::NAN]) && !all_finite(&[f64::INFINITY, 0.0]));
        let not_pd = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(!cholesky(2, not_pd.as_slice(), &mut l));
    }
}
