//! Small dense linear-algebra helpers of the UKF: validation, covariance health checks and
//! repair, square roots of covariances, and the rank-1 Cholesky update/downdate of the
//! square-root filter.

use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::kernels;
use crate::{EstimateError, Result};

/// Relative asymmetry above which a computed covariance is reported (or repaired) rather than
/// symmetrised silently. Rounding in `P − K S Kᵀ` leaves asymmetries near 1e-16.
pub(crate) const SYMMETRY_TOL: f64 = 1e-8;

/// Eigenvalues of a repaired covariance are clipped to at least this fraction of the largest.
pub(crate) const REPAIR_FLOOR: f64 = 1e-12;

/// Eigenvalues of Q and R down to `-PSD_TOL · max |λ|` count as zero.
const PSD_TOL: f64 = 1e-12;

/// What to do when a covariance computed by the filter stops being symmetric positive
/// definite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CovariancePolicy {
    /// Stop with [`EstimateError::NotPositiveDefinite`] / [`EstimateError::NotSymmetric`]
    /// naming the step (the default: never propagate a broken covariance silently).
    #[default]
    Strict,
    /// Symmetrise and clip eigenvalues to `1e-12 · λ_max`, counting each repair (see the
    /// filters' `repairs()`); fails only if no eigenvalue is positive.
    Repair,
}

/// Fails with [`EstimateError::DimensionMismatch`] unless `v` has `n` entries.
pub(crate) fn check_len(v: &DVector<f64>, n: usize, what: &str) -> Result<()> {
    if v.len() != n {
        return Err(EstimateError::DimensionMismatch {
            what: what.to_string(),
            expected: vec![n],
            got: vec![v.len()],
        });
    }
    Ok(())
}

/// Fails with [`EstimateError::DimensionMismatch`] unless `m` is `r × c`.
pub(crate) fn check_shape(m: &DMatrix<f64>, r: usize, c: usize, what: &str) -> Result<()> {
    if m.shape() != (r, c) {
        return Err(EstimateError::DimensionMismatch {
            what: what.to_string(),
            expected: vec![r, c],
            got: vec![m.nrows(), m.ncols()],
        });
    }
    Ok(())
}

/// The first non-finite element (flat column-major index and value).
pub(crate) fn first_non_finite(data: &[f64]) -> Option<(usize, f64)> {
    if kernels::all_finite(data) {
        return None;
    }
    data.iter()
        .copied()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
}

/// Fails with [`EstimateError::NonFiniteInput`] if an input has NaN/inf.
pub(crate) fn check_finite_input(data: &[f64], what: &str) -> Result<()> {
    match first_non_finite(data) {
        Some((index, value)) => Err(EstimateError::NonFiniteInput {
            what: what.to_string(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// Fails with [`EstimateError::NonFinite`] if a computed value has NaN/inf.
pub(crate) fn check_finite_at(data: &[f64], what: impl Fn() -> String, step: usize) -> Result<()> {
    match first_non_finite(data) {
        Some((index, value)) => Err(EstimateError::NonFinite {
            what: what(),
            step,
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// max |Aᵢⱼ − Aⱼᵢ| / max(max |Aᵢⱼ|, tiny).
pub(crate) fn asymmetry(m: &DMatrix<f64>) -> f64 {
    let n = m.nrows();
    let a = m.as_slice();
    let scale = a
        .iter()
        .fold(0.0f64, |acc, v| acc.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    let mut worst: f64 = 0.0;
    for j in 0..n {
        for i in (j + 1)..n {
            worst = worst.max((a[i + j * n] - a[j + i * n]).abs());
        }
    }
    worst / scale
}

/// Replaces `m` by (m + mᵀ)/2.
pub(crate) fn symmetrise(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    let a = m.as_mut_slice();
    for j in 0..n {
        for i in (j + 1)..n {
            let v = 0.5 * (a[i + j * n] + a[j + i * n]);
            a[i + j * n] = v;
            a[j + i * n] = v;
        }
    }
}

/// Smallest eigenvalue of a symmetric matrix (NaN if `m` has NaN).
pub(crate) fn min_eigenvalue(m: &DMatrix<f64>) -> f64 {
    if first_non_finite(m.as_slice()).is_some() {
        return f64::NAN;
    }
    SymmetricEigen::new(m.clone()).eigenvalues.min()
}

/// Lower Cholesky factor of a symmetric matrix, `None` unless positive definite.
pub(crate) fn cholesky(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = m.nrows();
    let mut l = DMatrix::zeros(n, n);
    kernels::cholesky(n, m.as_slice(), l.as_mut_slice()).then_some(l)
}

/// `V · max(Λ, floor) · Vᵀ` with `floor = REPAIR_FLOOR · λ_max`; `None` if no eigenvalue is
/// positive (nothing sensible to keep).
pub(crate) fn clip_eigenvalues(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if first_non_finite(m.as_slice()).is_some() {
        return None;
    }
    let eig = SymmetricEigen::new(m.clone());
    let max = eig.eigenvalues.max();
    if max <= 0.0 || !max.is_finite() {
        return None;
    }
    let floor = REPAIR_FLOOR * max;
    let d = eig.eigenvalues.map(|l| l.max(floor));
    let v = &eig.eigenvectors;
    let mut out = v * DMatrix::from_diagonal(&d) * v.transpose();
    symmetrise(&mut out);
    Some(out)
}

/// Checks a covariance computed by the filter at `step` and returns its lower Cholesky
/// factor: NaN/inf → [`EstimateError::NonFinite`]; rounding-level asymmetry is removed;
/// larger asymmetry or a failed Cholesky → error under [`CovariancePolicy::Strict`], or
/// symmetrisation and eigenvalue clipping under [`CovariancePolicy::Repair`] (`repairs` is
/// incremented). `p` is replaced by the (symmetrised / repaired) matrix.
pub(crate) fn factor_covariance(
    p: &mut DMatrix<f64>,
    what: &str,
    step: usize,
    policy: CovariancePolicy,
    repairs: &mut usize,
) -> Result<DMatrix<f64>> {
    check_finite_at(p.as_slice(), || what.to_string(), step)?;
    let asym = asymmetry(p);
    if asym > SYMMETRY_TOL && policy == CovariancePolicy::Strict {
        return Err(EstimateError::NotSymmetric {
            what: what.to_string(),
            step,
            asymmetry: asym,
        });
    }
    symmetrise(p);
    if let Some(l) = cholesky(p) {
        if asym > SYMMETRY_TOL {
            *repairs += 1;
        }
        return Ok(l);
    }
    let not_pd = || EstimateError::NotPositiveDefinite {
        what: what.to_string(),
        step,
        min_eigenvalue: min_eigenvalue(p),
    };
    if policy == CovariancePolicy::Strict {
        return Err(not_pd());
    }
    let fixed = clip_eigenvalues(p).ok_or_else(not_pd)?;
    let l = cholesky(&fixed).ok_or_else(not_pd)?;
    *p = fixed;
    *repairs += 1;
    Ok(l)
}

/// [`factor_covariance`] for a matrix that is symmetric by construction (a weighted Gram
/// matrix plus a validated Q or R, or a lower-triangle update mirrored): the factor is written
/// into `l` (`n × n`), and the symmetry test is skipped (and nothing allocated) when the
/// factorisation succeeds.
pub(crate) fn factor_symmetric_into(
    p: &mut DMatrix<f64>,
    l: &mut DMatrix<f64>,
    what: &str,
    step: usize,
    policy: CovariancePolicy,
    repairs: &mut usize,
) -> Result<()> {
    let n = p.nrows();
    if kernels::all_finite(p.as_slice()) && kernels::cholesky(n, p.as_slice(), l.as_mut_slice()) {
        return Ok(());
    }
    let f = factor_covariance(p, what, step, policy, repairs)?;
    l.copy_from(&f);
    Ok(())
}

/// Validates a covariance given as input (`n × n`, finite, symmetric to [`SYMMETRY_TOL`]) and
/// returns its symmetrised copy.
pub(crate) fn validate_covariance_input(
    m: &DMatrix<f64>,
    n: usize,
    what: &str,
) -> Result<DMatrix<f64>> {
    check_shape(m, n, n, what)?;
    check_finite_input(m.as_slice(), what)?;
    let asym = asymmetry(m);
    if asym > SYMMETRY_TOL {
        return Err(EstimateError::InvalidCovariance {
            what: what.to_string(),
            asymmetry: asym,
            min_eigenvalue: min_eigenvalue(m),
        });
    }
    let mut out = m.clone();
    symmetrise(&mut out);
    Ok(out)
}

/// A square root `A` (with `A Aᵀ = M`) of a symmetric positive semi-definite input matrix:
/// its Cholesky factor when positive definite, else `V·√Λ` from the eigendecomposition, with
/// eigenvalues down to `−1e-12 · max |λ|` treated as zero. Anything more negative fails with
/// [`EstimateError::InvalidCovariance`].
pub(crate) fn psd_sqrt(m: &DMatrix<f64>, what: &str) -> Result<DMatrix<f64>> {
    if let Some(l) = cholesky(m) {
        return Ok(l);
    }
    let eig = SymmetricEigen::new(m.clone());
    let scale = eig.eigenvalues.amax();
    let min = eig.eigenvalues.min();
    if min < -PSD_TOL * scale || !min.is_finite() {
        return Err(EstimateError::InvalidCovariance {
            what: what.to_string(),
            asymmetry: asymmetry(m),
            min_eigenvalue: min,
        });
    }
    let d = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    Ok(&eig.eigenvectors * DMatrix::from_diagonal(&d))
}

/// A validated noise covariance (Q or R) of size `d × d` and its square root
/// ([`psd_sqrt`]); the setters of both filters use it.
pub(crate) fn noise_input(
    m: &DMatrix<f64>,
    d: usize,
    what: &str,
) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let m = validate_covariance_input(m, d, what)?;
    let sqrt = psd_sqrt(&m, what)?;
    Ok((m, sqrt))
}

/// A validated user covariance P of size `n × n` and its Cholesky factor. A P that is not
/// positive definite fails, or (repair policy) is replaced by its eigenvalue-clipped form
/// (`repairs` is incremented). Returns (P as used, its lower factor).
pub(crate) fn covariance_input(
    p: &DMatrix<f64>,
    n: usize,
    policy: CovariancePolicy,
    repairs: &mut usize,
) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let p = validate_covariance_input(p, n, "covariance P")?;
    if let Some(l) = cholesky(&p) {
        return Ok((p, l));
    }
    if policy == CovariancePolicy::Repair {
        let fixed = clip_eigenvalues(&p).and_then(|f| {
            let l = cholesky(&f)?;
            Some((f, l))
        });
        return match fixed {
            Some(fl) => {
                *repairs += 1;
                Ok(fl)
            }
            None => Err(EstimateError::InvalidCovariance {
                what: "covariance P".to_string(),
                asymmetry: 0.0,
                min_eigenvalue: min_eigenvalue(&p),
            }),
        };
    }
    Err(EstimateError::InvalidCovariance {
        what: "covariance P (must be positive definite)".to_string(),
        asymmetry: 0.0,
        min_eigenvalue: min_eigenvalue(&p),
    })
}

/// Checks a user state `x` against the length `n` and for finiteness.
pub(crate) fn state_input(x: &DVector<f64>, n: usize) -> Result<()> {
    check_len(x, n, "state x")?;
    check_finite_input(x.as_slice(), "state x")
}

/// Checks the inputs of a prediction: a finite time step `dt` and an optional control input
/// `u` for a model taking `du` inputs (0: none).
pub(crate) fn check_predict_inputs(dt: f64, u: Option<&DVector<f64>>, du: usize) -> Result<()> {
    if !dt.is_finite() {
        return Err(EstimateError::NonFiniteInput {
            what: "time step dt".to_string(),
            index: 0,
            value: dt,
        });
    }
    if let Some(u) = u {
        if du == 0 {
            return Err(EstimateError::DimensionMismatch {
                what: "input u (the model takes no input)".to_string(),
                expected: vec![0],
                got: vec![u.len()],
            });
        }
        check_len(u, du, "input u")?;
        check_finite_input(u.as_slice(), "input u")?;
    }
    Ok(())
}

/// Rank-1 update (`sign = +1`) or downdate (`sign = −1`) of a lower Cholesky factor in place:
/// `L Lᵀ ← L Lᵀ + sign · x xᵀ` (`x` is overwritten). Returns `false` (leaving `l` partly
/// modified) when a downdate would lose positive definiteness. Golub & Van Loan, "Matrix
/// Computations", §6.5.4; van der Merwe & Wan (2001) use it for the 0th sigma weight.
pub(crate) fn chol_rank1(l: &mut DMatrix<f64>, x: &mut DVector<f64>, sign: f64) -> bool {
    let n = l.nrows();
    for k in 0..n {
        let lkk = l[(k, k)];
        let r2 = lkk * lkk + sign * x[k] * x[k];
        if r2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            || !r2.is_finite()
            || lkk == 0.0
        {
            return false;
        }
        let r = r2.sqrt();
        let c = r / lkk;
        let s = x[k] / lkk;
        l[(k, k)] = r;
        for i in (k + 1)..n {
            let li = (l[(i, k)] + sign * s * x[i]) / c;
            x[i] = c * x[i] - s * li;
            l[(i, k)] = li;
        }
    }
    true
}

/// The lower-triangular `S` with `S Sᵀ = A Aᵀ` for a wide `A` (`n × m`, `m ≥ n`): the
/// transposed R factor of the QR decomposition of `Aᵀ`, rows sign-flipped so the diagonal is
/// non-negative (van der Merwe & Wan 2001, eq. (20) "qr{…}").
pub(crate) fn tria(a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let r = nalgebra::QR::new(a.transpose()).unpack_r();
    let mut s = DMatrix::zeros(n, n);
    for i in 0..n.min(r.nrows()) {
        let sign = if r[(i, i)] < 0.0 { -1.0 } else { 1.0 };
        for j in i..n {
            s[(j, i)] = sign * r[(i, j)];
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        let a = DMatrix::from_fn(n, n, |_, _| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        });
        &a * a.transpose() + DMatrix::identity(n, n) * 0.1
    }

    #[test]
    fn rank1_update_and_downdate_match_refactoring() {
        let p = spd(6, 1);
        let v = DVector::from_fn(6, |i, _| 0.1 * (i as f64 + 1.0));
        let mut l = cholesky(&p).unwrap();
        assert!(chol_rank1(&mut l, &mut v.clone(), 1.0));
        let up = &p + &v * v.transpose();
        assert!((&l * l.transpose() - &up).amax() < 1e-12);
        assert!(chol_rank1(&mut l, &mut v.clone(), -1.0));
        assert!((&l * l.transpose() - &p).amax() < 1e-12);
    }

    #[test]
    fn downdate_past_definiteness_fails() {
        let p = DMatrix::<f64>::identity(3, 3);
        let mut l = cholesky(&p).unwrap();
        let mut v = DVector::from_vec(vec![0.0, 1.5, 0.0]);
        assert!(!chol_rank1(&mut l, &mut v, -1.0));
    }

    #[test]
    fn tria_reproduces_a_at() {
        let a = DMatrix::from_fn(4, 9, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 2.0 + 0.1 * j as f64
        });
        let s = tria(&a);
        assert!((&s * s.transpose() - &a * a.transpose()).amax() < 1e-12);
        for i in 0..4 {
            assert!(s[(i, i)] >= 0.0);
            for j in (i + 1)..4 {
                assert_eq!(s[(i, j)], 0.0);
            }
        }
    }

    #[test]
    fn psd_sqrt_handles_singular_and_rejects_indefinite() {
        let q = DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, 0.0, 1.0]));
        let a = psd_sqrt(&q, "Q").unwrap();
        assert!((&a * a.transpose() - &q).amax() < 1e-14);
        let bad = DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, -0.5, 1.0]));
        match psd_sqrt(&bad, "Q") {
            Err(EstimateError::InvalidCovariance { min_eigenvalue, .. }) => {
                assert!((min_eigenvalue + 0.5).abs() < 1e-12)
            }
            other => panic!("expected InvalidCovariance, got {other:?}"),
        }
    }

    #[test]
    fn factor_covariance_strict_reports_and_repair_clips() {
        let bad = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]); // eigenvalues 3, −1
        let mut repairs = 0;
        let mut p = bad.clone();
        match factor_covariance(&mut p, "P", 7, CovariancePolicy::Strict, &mut repairs) {
            Err(EstimateError::NotPositiveDefinite {
                step,
                min_eigenvalue,
                ..
            }) => {
                assert_eq!(step, 7);
                assert!((min_eigenvalue + 1.0).abs() < 1e-12);
            }
            other => panic!("expected NotPositiveDefinite, got {other:?}"),
        }
        let mut p = bad.clone();
        let l = factor_covariance(&mut p, "P", 7, CovariancePolicy::Repair, &mut repairs).unwrap();
        assert_eq!(repairs, 1);
        assert!((&l * l.transpose() - &p).amax() < 1e-12);
        // The positive eigenpair is kept: (1, 1)/√2 with eigenvalue 3.
        let v = DVector::from_vec(vec![1.0, 1.0]) / 2f64.sqrt();
        assert!(((&p * &v) - &v * 3.0).norm() < 1e-9);
        let mut p = DMatrix::from_row_slice(2, 2, &[1.0, f64::NAN, 0.0, 1.0]);
        assert!(matches!(
            factor_covariance(&mut p, "P", 3, CovariancePolicy::Repair, &mut repairs),
            Err(EstimateError::NonFinite { step: 3, .. })
        ));
    }
}
