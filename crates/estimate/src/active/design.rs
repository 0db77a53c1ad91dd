//! Optimal experimental design: the Fisher information of a design, the observability indices
//! O1–O6, the information gain of one more measurement, approximate D-optimal designs with the
//! General Equivalence Theorem check, and the DETMAX exchange algorithm for a finite candidate
//! set (000_3b1454b2b2194811.txt ch. 6.2, eqs. (6.1)–(6.10), Table 6.2).
//!
//! A measurement is described by its *whitened Jacobian* `F = V^{-1/2} ∂h/∂θ` (`d × p`, one row
//! per scalar observation); its Fisher information is `Fᵀ F` (eq. (6.6)).

use nalgebra::{Cholesky, DMatrix, DVector, Dyn, SymmetricEigen};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_pcg::Pcg64;

use crate::{EstimateError, Result};

/// Relative tolerance on the asymmetry of a matrix that must be symmetric.
const SYMMETRY_TOL: f64 = 1e-8;

/// Eigenvalues above `−EIG_TOL · λ_max` count as zero (rounding of a PSD matrix).
const EIG_TOL: f64 = 1e-10;

fn check_matrix_finite(what: &str, m: &DMatrix<f64>) -> Result<()> {
    match m.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        Some((index, &value)) => Err(EstimateError::NonFiniteInput {
            what: what.to_string(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

fn check_square(what: &str, m: &DMatrix<f64>) -> Result<()> {
    if m.nrows() != m.ncols() || m.nrows() == 0 {
        return Err(EstimateError::DimensionMismatch {
            what: what.to_string(),
            expected: vec![m.nrows().max(1), m.nrows().max(1)],
            got: vec![m.nrows(), m.ncols()],
        });
    }
    Ok(())
}

/// Checks that `m` is a finite, square, symmetric matrix (up to rounding) and returns its
/// symmetric part.
pub(crate) fn symmetric(what: &str, m: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    check_square(what, m)?;
    check_matrix_finite(what, m)?;
    let scale = m.amax().max(f64::MIN_POSITIVE);
    let asym = (m - m.transpose()).amax() / scale;
    if asym > SYMMETRY_TOL {
        let eig = SymmetricEigen::new(0.5 * (m + m.transpose())).eigenvalues;
        return Err(EstimateError::InvalidCovariance {
            what: what.to_string(),
            asymmetry: asym,
            min_eigenvalue: eig.min(),
        });
    }
    Ok(0.5 * (m + m.transpose()))
}

/// The Fisher information matrix of a discrete design, 000_3b1454b2b2194811.txt eqs. (6.4)–(6.6):
/// `M(ξ) = Σ_i ω_i / σ_i² · J_iᵀ J_i` for observations `y_i = h(x_i, θ) + v_i`,
/// `v_i ~ N(0, σ_i² I)`, where `J_i = ∂h(x_i, θ)/∂θ` (`d_i × p`, the transposed gradient of
/// (6.6) stacked for a vector observation) and `ω_i ≥ 0` are the design weights of (6.1).
///
/// Errors: empty design, mismatched lengths or column counts, non-finite values, `σ_i ≤ 0`,
/// negative weights.
pub fn fisher_information(
    jacobians: &[DMatrix<f64>],
    sigmas: &[f64],
    weights: &[f64],
) -> Result<DMatrix<f64>> {
    let Some(first) = jacobians.first() else {
        return Err(EstimateError::DimensionMismatch {
            what: "design (number of Jacobians)".into(),
            expected: vec![1],
            got: vec![0],
        });
    };
    for (what, len) in [("sigmas", sigmas.len()), ("weights", weights.len())] {
        if len != jacobians.len() {
            return Err(EstimateError::DimensionMismatch {
                what: what.into(),
                expected: vec![jacobians.len()],
                got: vec![len],
            });
        }
    }
    let p = first.ncols();
    let mut m = DMatrix::zeros(p, p);
    for (i, ((j, &s), &w)) in jacobians.iter().zip(sigmas).zip(weights).enumerate() {
        if j.ncols() != p {
            return Err(EstimateError::DimensionMismatch {
                what: format!("Jacobian {i}"),
                expected: vec![j.nrows(), p],
                got: vec![j.nrows(), j.ncols()],
            });
        }
        check_matrix_finite(&format!("Jacobian {i}"), j)?;
        if !(s.is_finite() && s > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "sigma",
                value: s,
                reason: "measurement standard deviations must be positive and finite",
            });
        }
        if !(w.is_finite() && w >= 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "weight",
                value: w,
                reason: "design weights must be non-negative and finite",
            });
        }
        m += (w / (s * s)) * j.transpose() * j;
    }
    Ok(m)
}

/// The singular values `σ_1 ≥ … ≥ σ_m ≥ 0` of a symmetric positive semi-definite information
/// matrix (its eigenvalues; rounding-level negative eigenvalues are clipped to zero).
///
/// Errors: non-square, non-finite or asymmetric input, or an eigenvalue below
/// `−1e-10 · λ_max` (the matrix is not positive semi-definite).
pub fn information_singular_values(m: &DMatrix<f64>) -> Result<DVector<f64>> {
    let s = symmetric("information matrix", m)?;
    let mut ev: Vec<f64> = SymmetricEigen::new(s).eigenvalues.iter().copied().collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    let max = ev.first().copied().unwrap_or(0.0);
    let min = ev.last().copied().unwrap_or(0.0);
    if min < -EIG_TOL * max.abs().max(f64::MIN_POSITIVE) {
        return Err(EstimateError::InvalidCovariance {
            what: "information matrix (not positive semi-definite)".into(),
            asymmetry: 0.0,
            min_eigenvalue: min,
        });
    }
    Ok(DVector::from_iterator(
        ev.len(),
        ev.into_iter().map(|v| v.max(0.0)),
    ))
}

/// The observability indices of 000_3b1454b2b2194811.txt Table 6.2 computed from the singular
/// values `σ_1 ≥ … ≥ σ_m` of a Fisher information matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservabilityIndices {
    /// O1 (D-optimality): `(σ_1 σ_2 ⋯ σ_m)^{1/m}`, the geometric mean.
    pub o1: f64,
    /// O2 (K-optimality, inverse condition number): `σ_m / σ_1`.
    pub o2: f64,
    /// O3 (E-optimality): `σ_m`.
    pub o3: f64,
    /// O4 (noise amplification index): `σ_m² / σ_1`.
    pub o4: f64,
    /// O5: `(σ_1⁻¹ + ⋯ + σ_m⁻¹)⁻¹`.
    pub o5: f64,
    /// O6: `(σ_1^{−P} + ⋯ + σ_m^{−P})⁻¹` with the power `P` below.
    pub o6: f64,
    /// The power `P` of O6.
    pub power: f64,
    /// `log det M = Σ log σ_i` (`−∞` for a singular matrix), the D-criterion of eq. (6.22).
    pub log_det: f64,
}

/// Observability indices O1–O6 of Table 6.2 (000_3b1454b2b2194811.txt ch. 6.2) of a symmetric
/// positive semi-definite information matrix, with the power `P > 0` of O6.
///
/// Computed from the eigenvalues (= singular values) of `M` in the log domain so that
/// ill-conditioned matrices neither overflow nor underflow: `O1 = exp(mean log σ)`,
/// `O6 = σ_m^P / Σ (σ_m/σ_i)^P`. A singular matrix gives `O1 = O2 = O3 = O4 = O5 = O6 = 0` and
/// `log_det = −∞` (exact limits, not errors); the zero matrix gives `O2 = 0`.
pub fn observability_indices(m: &DMatrix<f64>, power: f64) -> Result<ObservabilityIndices> {
    if !(power.is_finite() && power > 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "power",
            value: power,
            reason: "the O6 power P must be positive and finite",
        });
    }
    let s = information_singular_values(m)?;
    Ok(indices_from_singular_values(s.as_slice(), power))
}

/// [`observability_indices`] from already sorted (descending), non-negative singular values.
pub(crate) fn indices_from_singular_values(s: &[f64], power: f64) -> ObservabilityIndices {
    let n = s.len() as f64;
    let s1 = s.first().copied().unwrap_or(0.0);
    let sm = s.last().copied().unwrap_or(0.0);
    if sm <= 0.0 {
        return ObservabilityIndices {
            o1: 0.0,
            o2: 0.0,
            o3: 0.0,
            o4: 0.0,
            o5: 0.0,
            o6: 0.0,
            power,
            log_det: f64::NEG_INFINITY,
        };
    }
    let log_det: f64 = s.iter().map(|v| v.ln()).sum();
    let ratio_sum = |p: f64| s.iter().map(|v| (sm / v).powf(p)).sum::<f64>();
    ObservabilityIndices {
        o1: (log_det / n).exp(),
        o2: sm / s1,
        o3: sm,
        o4: sm * (sm / s1),
        o5: sm / ratio_sum(1.0),
        o6: (power * sm.ln() - ratio_sum(power).ln()).exp(),
        power,
        log_det,
    }
}

/// `log det A` of a symmetric positive definite matrix by Cholesky.
///
/// Errors: [`EstimateError::SingularInformation`] (with the eigenvalue range) when `A` is not
/// positive definite.
pub fn log_det_spd(what: &str, a: &DMatrix<f64>) -> Result<f64> {
    let a = symmetric(what, a)?;
    match Cholesky::new(a.clone()) {
        Some(ch) => Ok(2.0 * ch.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>()),
        None => Err(singular(what, &a)),
    }
}

/// The [`EstimateError::SingularInformation`] error of a matrix, with its eigenvalue range.
pub(crate) fn singular(what: &str, a: &DMatrix<f64>) -> EstimateError {
    let ev = SymmetricEigen::new(0.5 * (a + a.transpose())).eigenvalues;
    EstimateError::SingularInformation {
        what: what.to_string(),
        min_eigenvalue: ev.min(),
        max_eigenvalue: ev.max(),
    }
}

/// Cholesky factor of a symmetric positive definite matrix, or `SingularInformation`.
pub(crate) fn cholesky(what: &str, a: &DMatrix<f64>) -> Result<Cholesky<f64, Dyn>> {
    let a = symmetric(what, a)?;
    Cholesky::new(a.clone()).ok_or_else(|| singular(what, &a))
}

/// The D-optimal information gain of one measurement, 000_3b1454b2b2194811.txt eq. (6.22):
/// `log |I + F P Fᵀ| = log |I + C(k)ᵀ V^{-½} P(k−1) V^{-½} C(k)|`-type determinant
/// `= log det(P⁻¹ + FᵀF) − log det P⁻¹`, with the whitened Jacobian `F = V^{-½} C` (`d × p`)
/// and the current covariance `P` given by its lower Cholesky factor `L` (`P = L Lᵀ`).
///
/// Evaluated as `log det(I_p + (F L)ᵀ (F L))` by Cholesky (always positive definite).
pub fn d_gain(l: &DMatrix<f64>, f: &DMatrix<f64>) -> Result<f64> {
    if f.ncols() != l.nrows() {
        return Err(EstimateError::DimensionMismatch {
            what: "whitened Jacobian F".into(),
            expected: vec![f.nrows(), l.nrows()],
            got: vec![f.nrows(), f.ncols()],
        });
    }
    let b = f * l;
    let mut g = b.transpose() * &b;
    for i in 0..g.nrows() {
        g[(i, i)] += 1.0;
    }
    log_det_spd("I + (F L)ᵀ(F L)", &g)
}

/// The Kalman information recursion of 000_3b1454b2b2194811.txt eq. (6.15) for a static state:
/// `P⁻¹(k+1) = P⁻¹(k) + Cᵀ(k) V⁻¹ C(k)`, with `V = σ² I`.
pub fn information_update(
    info: &DMatrix<f64>,
    c: &DMatrix<f64>,
    sigma: f64,
) -> Result<DMatrix<f64>> {
    let info = symmetric("information matrix", info)?;
    if c.ncols() != info.nrows() {
        return Err(EstimateError::DimensionMismatch {
            what: "observation matrix C".into(),
            expected: vec![c.nrows(), info.nrows()],
            got: vec![c.nrows(), c.ncols()],
        });
    }
    check_matrix_finite("observation matrix C", c)?;
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "sigma",
            value: sigma,
            reason: "measurement noise must be positive and finite",
        });
    }
    Ok(info + c.transpose() * c / (sigma * sigma))
}

/// An approximate (continuous) design on a finite candidate set.
#[derive(Debug, Clone, PartialEq)]
pub struct ApproximateDesign {
    /// Weight `ω_i` of each candidate (sum 1), eq. (6.1).
    pub weights: Vec<f64>,
    /// `d(x_i, ξ) = tr(M(ξ)⁻¹ F_iᵀ F_i)` for every candidate (the standardised variance; for a
    /// scalar observation `f(x)ᵀ M⁻¹ f(x)`).
    pub variance: Vec<f64>,
    /// `max_i d(x_i, ξ)`; equals `p` at the D-optimum (Kiefer–Wolfowitz).
    pub max_variance: f64,
    /// `log det M(ξ)`.
    pub log_det: f64,
    /// Multiplicative iterations run.
    pub iterations: usize,
}

/// Standardised variances `d_i = tr(M⁻¹ F_iᵀ F_i)` of every candidate under weights `w`.
fn variances(f: &[DMatrix<f64>], w: &[f64]) -> Result<(Vec<f64>, f64)> {
    let p = f[0].ncols();
    let mut m = DMatrix::zeros(p, p);
    for (fi, &wi) in f.iter().zip(w) {
        m += wi * fi.transpose() * fi;
    }
    let ch = cholesky("design information matrix M(ξ)", &m)?;
    let log_det = 2.0 * ch.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>();
    let d = f
        .iter()
        .map(|fi| {
            // tr(M⁻¹ FᵀF) = ‖L⁻¹ Fᵀ‖²_F.
            let x = ch
                .l()
                .solve_lower_triangular(&fi.transpose())
                .unwrap_or_else(|| fi.transpose() * f64::NAN);
            x.norm_squared()
        })
        .collect();
    Ok((d, log_det))
}

fn check_candidates(f: &[DMatrix<f64>]) -> Result<usize> {
    let Some(first) = f.first() else {
        return Err(EstimateError::DimensionMismatch {
            what: "candidate set".into(),
            expected: vec![1],
            got: vec![0],
        });
    };
    let p = first.ncols();
    if p == 0 {
        return Err(EstimateError::DimensionMismatch {
            what: "candidate 0".into(),
            expected: vec![first.nrows(), 1],
            got: vec![first.nrows(), 0],
        });
    }
    for (i, fi) in f.iter().enumerate() {
        if fi.ncols() != p || fi.nrows() == 0 {
            return Err(EstimateError::DimensionMismatch {
                what: format!("candidate {i}"),
                expected: vec![fi.nrows().max(1), p],
                got: vec![fi.nrows(), fi.ncols()],
            });
        }
        check_matrix_finite(&format!("candidate {i}"), fi)?;
    }
    Ok(p)
}

/// Approximate D-optimal design on a finite candidate set by the multiplicative algorithm
/// (Silvey–Titterington–Torsney): `ω_i ← ω_i d(x_i, ξ) / p`, started from uniform weights.
///
/// The General Equivalence Theorem (000_3b1454b2b2194811.txt Theorem 6.2.1) for
/// `ψ = −log det M` states that `ξ*` is optimal iff the directional derivative (6.8)
/// `φ(x, ξ*) = p − d(x, ξ*) ≥ 0` for every candidate (with equality on the support), i.e.
/// `max_x d(x, ξ*) = p`; the iteration stops when `max_i d_i ≤ p (1 + tol)`.
///
/// `f[i]` is the whitened Jacobian of candidate `i` (`d_i × p`). Errors: empty or inconsistent
/// candidates, non-finite values, a candidate set whose information is singular (it does not
/// identify all `p` parameters), or no convergence within `max_iterations`.
pub fn d_optimal_design(
    f: &[DMatrix<f64>],
    tol: f64,
    max_iterations: usize,
) -> Result<ApproximateDesign> {
    let p = check_candidates(f)? as f64;
    if !(tol.is_finite() && tol > 0.0) {
        return Err(EstimateError::InvalidParameter {
            name: "tol",
            value: tol,
            reason: "the tolerance must be positive",
        });
    }
    let n = f.len();
    let mut w = vec![1.0 / n as f64; n];
    for it in 0..=max_iterations {
        let (d, log_det) = variances(f, &w)?;
        let max_variance = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if max_variance <= p * (1.0 + tol) {
            return Ok(ApproximateDesign {
                weights: w,
                variance: d,
                max_variance,
                log_det,
                iterations: it,
            });
        }
        if it == max_iterations {
            return Err(EstimateError::NoConvergence {
                what: format!("D-optimal design (max variance above p = {p})"),
                iterations: it,
                residual: max_variance - p,
            });
        }
        // Each candidate contributes tr(M⁻¹ ω_i A_i) = ω_i d_i; these sum to p.
        for (wi, di) in w.iter_mut().zip(&d) {
            *wi *= di / p;
        }
        let s: f64 = w.iter().sum();
        w.iter_mut().for_each(|wi| *wi /= s);
    }
    unreachable!("the loop returns at it == max_iterations")
}

/// The directional derivative (6.8) of `ψ = −log det M` at design weights `w` towards each
/// candidate point: `φ(x_i, ξ) = p − tr(M(ξ)⁻¹ F_iᵀ F_i)` (000_3b1454b2b2194811.txt
/// Theorem 6.2.1: all `≥ 0` at the optimum, `= 0` on its support).
pub fn d_directional_derivatives(f: &[DMatrix<f64>], weights: &[f64]) -> Result<Vec<f64>> {
    let p = check_candidates(f)? as f64;
    if weights.len() != f.len() {
        return Err(EstimateError::DimensionMismatch {
            what: "weights".into(),
            expected: vec![f.len()],
            got: vec![weights.len()],
        });
    }
    if let Some(&w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(EstimateError::InvalidParameter {
            name: "weight",
            value: w,
            reason: "design weights must be non-negative and finite",
        });
    }
    let (d, _) = variances(f, weights)?;
    Ok(d.into_iter().map(|di| p - di).collect())
}

/// Options of [`detmax`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetmaxOptions {
    /// Largest excursion size (points added then removed, or removed then added, at once).
    pub max_excursion: usize,
    /// Maximal number of accepted excursions.
    pub max_iterations: usize,
    /// Whether a candidate may be selected more than once (repeated measurements).
    pub allow_repeats: bool,
    /// Ridge added to the information when there is no prior and the design is still singular
    /// (relative to the largest diagonal entry of the candidates' information).
    pub ridge: f64,
    /// Seed of the random tie-breaking of the initial design.
    pub seed: u64,
}

impl Default for DetmaxOptions {
    fn default() -> Self {
        Self {
            max_excursion: 3,
            max_iterations: 1000,
            allow_repeats: false,
            ridge: 1e-9,
            seed: 0,
        }
    }
}

/// The result of [`detmax`].
#[derive(Debug, Clone, PartialEq)]
pub struct DetmaxResult {
    /// Indices of the selected candidates (sorted).
    pub selected: Vec<usize>,
    /// `log det(M_0 + Σ_selected F_iᵀ F_i)` (`M_0` the prior information or the ridge).
    pub log_det: f64,
    /// Accepted excursions and exchanges.
    pub excursions: usize,
}

/// The DETMAX exchange algorithm (Mitchell 1974; 000_3b1454b2b2194811.txt ch. 6.2, the finite
/// selection problem (6.10) with the D-criterion): choose `n` of the candidate measurements
/// maximising `log det(M_0 + Σ_{i∈S} F_iᵀ F_i)`.
///
/// Start: the greedy sequential design (each step adds the candidate of largest variance
/// `log det(I + F_i M⁻¹ F_iᵀ)`). Excursions of size `k = 1..=max_excursion`: add the `k` best
/// points then remove the `k` worst, or remove `k` then add `k`; an excursion is accepted when it
/// increases the log-determinant, and the search stops when no excursion does. The result is
/// then polished by single-point (Fedorov) exchanges until no swap of a selected point for a
/// candidate increases the log-determinant.
///
/// `prior` is `M_0` (e.g. the inverse prior covariance; `None` = a tiny ridge). Errors: empty
/// or inconsistent candidates, `n` larger than the candidate count without repeats or `n = 0`,
/// a singular final design.
pub fn detmax(
    f: &[DMatrix<f64>],
    n: usize,
    prior: Option<&DMatrix<f64>>,
    options: &DetmaxOptions,
) -> Result<DetmaxResult> {
    let p = check_candidates(f)?;
    if n == 0 || (!options.allow_repeats && n > f.len()) {
        return Err(EstimateError::InvalidParameter {
            name: "n",
            value: n as f64,
            reason: "the design size must be positive and at most the number of candidates (without repeats)",
        });
    }
    let a: Vec<DMatrix<f64>> = f.iter().map(|fi| fi.transpose() * fi).collect();
    let m0 = match prior {
        Some(m) => {
            if m.nrows() != p || m.ncols() != p {
                return Err(EstimateError::DimensionMismatch {
                    what: "prior information".into(),
                    expected: vec![p, p],
                    got: vec![m.nrows(), m.ncols()],
                });
            }
            symmetric("prior information", m)?
        }
        None => {
            let scale = a
                .iter()
                .flat_map(|ai| ai.diagonal().iter().copied().collect::<Vec<_>>())
                .fold(0.0, f64::max)
                .max(1.0);
            DMatrix::identity(p, p) * (options.ridge * scale)
        }
    };
    let info = |sel: &[usize]| -> DMatrix<f64> {
        let mut m = m0.clone();
        for &i in sel {
            m += &a[i];
        }
        m
    };
    let logdet = |sel: &[usize]| -> f64 {
        Cholesky::new(info(sel)).map_or(f64::NEG_INFINITY, |ch| {
            2.0 * ch.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>()
        })
    };
    // Gain of adding each candidate: log det(I + F_i M⁻¹ F_iᵀ); loss of removing a selected
    // one: −log det(I − F_i M⁻¹ F_iᵀ).
    let scores = |sel: &[usize]| -> Option<Vec<f64>> {
        let ch = Cholesky::new(info(sel))?;
        Some(
            f.iter()
                .map(|fi| {
                    let x = ch
                        .l()
                        .solve_lower_triangular(&fi.transpose())
                        .unwrap_or_else(|| fi.transpose() * f64::NAN);
                    let mut g = x.transpose() * x; // F M⁻¹ Fᵀ
                    for i in 0..g.nrows() {
                        g[(i, i)] += 1.0;
                    }
                    Cholesky::new(g).map_or(f64::NAN, |c| {
                        2.0 * c.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>()
                    })
                })
                .collect(),
        )
    };
    let mut rng = Pcg64::seed_from_u64(options.seed);
    let mut order: Vec<usize> = (0..f.len()).collect();
    order.shuffle(&mut rng);
    let add_best = |sel: &mut Vec<usize>| -> bool {
        let Some(s) = scores(sel) else { return false };
        let best = order
            .iter()
            .copied()
            .filter(|i| options.allow_repeats || !sel.contains(i))
            .filter(|&i| s[i].is_finite())
            .max_by(|&i, &j| s[i].total_cmp(&s[j]));
        match best {
            Some(i) => {
                sel.push(i);
                true
            }
            None => false,
        }
    };
    let remove_worst = |sel: &mut Vec<usize>| -> bool {
        if sel.is_empty() {
            return false;
        }
        // Remove the point whose removal keeps the largest log-determinant.
        let mut best: Option<(usize, f64)> = None;
        for k in 0..sel.len() {
            let mut t = sel.clone();
            t.swap_remove(k);
            let v = logdet(&t);
            if best.is_none_or(|(_, b)| v > b) {
                best = Some((k, v));
            }
        }
        match best {
            Some((k, _)) => {
                sel.swap_remove(k);
                true
            }
            None => false,
        }
    };
    let mut sel: Vec<usize> = Vec::with_capacity(n + options.max_excursion);
    while sel.len() < n {
        if !add_best(&mut sel) {
            return Err(EstimateError::InvalidParameter {
                name: "n",
                value: n as f64,
                reason: "the candidates cannot fill a design of this size",
            });
        }
    }
    let mut current = logdet(&sel);
    let mut excursions = 0;
    'outer: while excursions < options.max_iterations {
        for k in 1..=options.max_excursion {
            for add_first in [true, false] {
                let mut t = sel.clone();
                let ok = if add_first {
                    (0..k).all(|_| add_best(&mut t)) && (0..k).all(|_| remove_worst(&mut t))
                } else if t.len() > k {
                    (0..k).all(|_| remove_worst(&mut t)) && (0..k).all(|_| add_best(&mut t))
                } else {
                    false
                };
                if !ok || t.len() != n {
                    continue;
                }
                let v = logdet(&t);
                if v > current + 1e-12 * current.abs().max(1.0) {
                    sel = t;
                    current = v;
                    excursions += 1;
                    continue 'outer;
                }
            }
        }
        break;
    }
    // Polish with single-point (Fedorov) exchanges: swap a selected point for a candidate while
    // that increases the log-determinant.
    loop {
        let mut best: Option<(usize, usize, f64)> = None;
        for k in 0..sel.len() {
            for j in 0..f.len() {
                if sel[k] == j || (!options.allow_repeats && sel.contains(&j)) {
                    continue;
                }
                let mut t = sel.clone();
                t[k] = j;
                let v = logdet(&t);
                if v > best.map_or(current, |b| b.2) + 1e-12 * current.abs().max(1.0) {
                    best = Some((k, j, v));
                }
            }
        }
        match best {
            Some((k, j, v)) if excursions < options.max_iterations => {
                sel[k] = j;
                current = v;
                excursions += 1;
            }
            _ => break,
        }
    }
    if !current.is_finite() {
        return Err(singular("DETMAX design information", &info(&sel)));
    }
    sel.sort_unstable();
    Ok(DetmaxResult {
        selected: sel,
        log_det: current,
        excursions,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use rand::Rng;

    /// Regressor rows f(x) = (1, x, …, x^deg) on a grid of [-1, 1].
    fn poly_candidates(deg: usize, n: usize) -> (Vec<f64>, Vec<DMatrix<f64>>) {
        let xs: Vec<f64> = (0..n)
            .map(|i| -1.0 + 2.0 * i as f64 / (n - 1) as f64)
            .collect();
        let f = xs
            .iter()
            .map(|&x| DMatrix::from_fn(1, deg + 1, |_, j| x.powi(j as i32)))
            .collect();
        (xs, f)
    }

    #[test]
    fn indices_match_closed_forms_on_a_diagonal_matrix() {
        let m = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 1.0, 16.0]));
        let o = observability_indices(&m, 2.0).unwrap();
        // σ = (16, 4, 1)
        assert_relative_eq!(o.o1, 64f64.powf(1.0 / 3.0), max_relative = 1e-12);
        assert_relative_eq!(o.o2, 1.0 / 16.0, max_relative = 1e-12);
        assert_relative_eq!(o.o3, 1.0, max_relative = 1e-12);
        assert_relative_eq!(o.o4, 1.0 / 16.0, max_relative = 1e-12);
        assert_relative_eq!(o.o5, 1.0 / (1.0 / 16.0 + 0.25 + 1.0), max_relative = 1e-12);
        assert_relative_eq!(
            o.o6,
            1.0 / (1.0 / 256.0 + 1.0 / 16.0 + 1.0),
            max_relative = 1e-12
        );
        assert_relative_eq!(o.log_det, 64f64.ln(), max_relative = 1e-12);
    }

    #[test]
    fn indices_are_rotation_invariant_and_robust_when_ill_conditioned() {
        // M = R diag(1e6, 1, 1e-6) Rᵀ (condition number 1e12): the indices only depend on the
        // spectrum.
        let r = autoteach_geometry::lie::so3_exp(&nalgebra::Vector3::new(0.3, -0.7, 0.2));
        let r = DMatrix::from_column_slice(3, 3, r.matrix().as_slice());
        let d = DMatrix::from_diagonal(&DVector::from_vec(vec![1e6, 1.0, 1e-6]));
        let m = &r * d * r.transpose();
        let o = observability_indices(&m, 3.0).unwrap();
        assert_relative_eq!(o.o1, 1.0, max_relative = 1e-3);
        assert_relative_eq!(o.o2, 1e-12, max_relative = 1e-3);
        assert_relative_eq!(o.o4, 1e-18, max_relative = 1e-3);
        // O6 = 1 / (1e-18 + 1 + 1e18) ≈ 1e-18 = σ_m^P: σ_m^{-P} = 1e18 dominates.
        assert_relative_eq!(o.o6, 1e-18, max_relative = 1e-3);
        // Huge spectra stay finite in the log domain: σ = (1e200, 1e150), P = 4 → σ^{-P} underflows
        // naively, O6 = 1e600 / (1 + 1e200) overflows naively; here O6 = σ_m^P/(1 + (σ_m/σ_1)^P).
        let big = DMatrix::from_diagonal(&DVector::from_vec(vec![1e200, 1e150]));
        let o = observability_indices(&big, 1.0).unwrap();
        assert_relative_eq!(o.o6, 1e150 / (1.0 + 1e-50), max_relative = 1e-12);
        assert_relative_eq!(o.o1, 1e175, max_relative = 1e-9);
        // Singular: exact zeros, log det = −∞.
        let s = DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, 0.0]));
        let o = observability_indices(&s, 2.0).unwrap();
        assert_eq!((o.o1, o.o3, o.o5, o.o6), (0.0, 0.0, 0.0, 0.0));
        assert_eq!(o.log_det, f64::NEG_INFINITY);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0]);
        assert!(observability_indices(&m, 2.0).is_err());
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        assert!(observability_indices(&m, 2.0).is_err());
        assert!(observability_indices(&DMatrix::identity(2, 2), 0.0).is_err());
        assert!(observability_indices(&DMatrix::zeros(2, 3), 1.0).is_err());
        let mut m = DMatrix::identity(2, 2);
        m[(0, 0)] = f64::NAN;
        assert!(observability_indices(&m, 1.0).is_err());
        assert!(matches!(
            log_det_spd("M", &DMatrix::zeros(2, 2)),
            Err(EstimateError::SingularInformation { .. })
        ));
        assert!(fisher_information(&[], &[], &[]).is_err());
        let j = DMatrix::identity(2, 2);
        assert!(fisher_information(std::slice::from_ref(&j), &[0.0], &[1.0]).is_err());
        assert!(fisher_information(std::slice::from_ref(&j), &[1.0], &[-1.0]).is_err());
    }

    #[test]
    fn fisher_information_matches_eq_6_6_and_the_information_recursion() {
        let mut rng = Pcg64::seed_from_u64(3);
        let js: Vec<DMatrix<f64>> = (0..4)
            .map(|_| DMatrix::from_fn(2, 3, |_, _| rng.random_range(-1.0..1.0)))
            .collect();
        let sig = [0.5, 1.0, 2.0, 0.3];
        let w = [1.0; 4];
        let m = fisher_information(&js, &sig, &w).unwrap();
        // The recursion (6.15) from zero information gives the same matrix.
        let mut info = DMatrix::zeros(3, 3);
        for (j, s) in js.iter().zip(sig) {
            info = information_update(&info, j, s).unwrap();
        }
        assert_relative_eq!(m, info, epsilon = 1e-12);
        // Scalar observation: (6.6) is ω/σ² ∇h ∇hᵀ.
        let g = DMatrix::from_row_slice(1, 2, &[2.0, -1.0]);
        let m = fisher_information(&[g], &[0.5], &[0.25]).unwrap();
        assert_relative_eq!(
            m,
            DMatrix::from_row_slice(2, 2, &[4.0, -2.0, -2.0, 1.0]),
            epsilon = 1e-12
        );
    }

    #[test]
    fn d_gain_equals_log_det_ratio_of_posterior_to_prior_information() {
        let mut rng = Pcg64::seed_from_u64(5);
        let a = DMatrix::from_fn(4, 4, |_, _| rng.random_range(-1.0..1.0));
        let p = &a * a.transpose() + DMatrix::identity(4, 4) * 0.1;
        let f = DMatrix::from_fn(2, 4, |_, _| rng.random_range(-1.0..1.0));
        let l = Cholesky::new(p.clone()).unwrap().l();
        let g = d_gain(&l, &f).unwrap();
        let pinv = p.clone().try_inverse().unwrap();
        let expected = log_det_spd("post", &(&pinv + f.transpose() * &f)).unwrap()
            - log_det_spd("prior", &pinv).unwrap();
        assert_relative_eq!(g, expected, max_relative = 1e-10);
        // Sylvester: log|I_p + Lᵀ Fᵀ F L| = log|I_d + F P Fᵀ|.
        let alt = log_det_spd("s", &(DMatrix::identity(2, 2) + &f * &p * f.transpose())).unwrap();
        assert_relative_eq!(g, alt, max_relative = 1e-10);
    }

    #[test]
    fn general_equivalence_theorem_linear_and_quadratic_regression() {
        // Linear regression on [-1, 1]: D-optimal design = ½ at ±1 (closed form).
        let (xs, f) = poly_candidates(1, 21);
        let d = d_optimal_design(&f, 1e-6, 100_000).unwrap();
        assert!(d.max_variance <= 2.0 * (1.0 + 1e-6));
        let end_weight = d.weights[0] + d.weights[20];
        assert_relative_eq!(end_weight, 1.0, epsilon = 1e-3);
        // Quadratic: ⅓ at -1, 0, 1 (closed form); max_x f(x)ᵀ M⁻¹ f(x) = p = 3 at the optimum.
        let (xs2, f2) = poly_candidates(2, 21);
        let d2 = d_optimal_design(&f2, 1e-6, 100_000).unwrap();
        for (x, w) in xs2.iter().zip(&d2.weights) {
            let expected = if (x.abs() - 1.0).abs() < 1e-12 || x.abs() < 1e-12 {
                1.0 / 3.0
            } else {
                0.0
            };
            assert!(
                (w - expected).abs() < 2e-3,
                "x = {x}: w = {w}, expected {expected}"
            );
        }
        // GET: φ ≥ 0 everywhere and = 0 on the support, at the exact optimum.
        let exact: Vec<f64> = xs2
            .iter()
            .map(|x| {
                if (x.abs() - 1.0).abs() < 1e-12 || x.abs() < 1e-12 {
                    1.0 / 3.0
                } else {
                    0.0
                }
            })
            .collect();
        let phi = d_directional_derivatives(&f2, &exact).unwrap();
        for ((x, w), ph) in xs2.iter().zip(&exact).zip(&phi) {
            assert!(*ph >= -1e-12, "x = {x}: φ = {ph}");
            if *w > 0.0 {
                assert!(ph.abs() < 1e-12, "support x = {x}: φ = {ph}");
            }
        }
        // A non-optimal design (uniform) violates the condition: some φ < 0.
        let uniform = vec![1.0 / 21.0; 21];
        let phi = d_directional_derivatives(&f2, &uniform).unwrap();
        assert!(phi.iter().any(|v| *v < -0.1));
        let _ = xs;
    }

    #[test]
    fn d_optimal_design_of_a_singular_candidate_set_is_an_error() {
        // Both candidates only see the first parameter.
        let f = vec![
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::from_row_slice(1, 2, &[2.0, 0.0]),
        ];
        assert!(matches!(
            d_optimal_design(&f, 1e-6, 100),
            Err(EstimateError::SingularInformation { .. })
        ));
    }

    fn brute_force(f: &[DMatrix<f64>], n: usize, m0: &DMatrix<f64>) -> f64 {
        let a: Vec<DMatrix<f64>> = f.iter().map(|fi| fi.transpose() * fi).collect();
        let mut best = f64::NEG_INFINITY;
        let k = f.len();
        for mask in 0u32..(1 << k) {
            if mask.count_ones() as usize != n {
                continue;
            }
            let mut m = m0.clone();
            for (i, ai) in a.iter().enumerate() {
                if mask & (1 << i) != 0 {
                    m += ai;
                }
            }
            if let Some(ch) = Cholesky::new(m) {
                best = best.max(2.0 * ch.l_dirty().diagonal().iter().map(|v| v.ln()).sum::<f64>());
            }
        }
        best
    }

    #[test]
    fn detmax_finds_the_brute_force_optimum_on_small_problems() {
        for seed in 0..8 {
            let mut rng = Pcg64::seed_from_u64(100 + seed);
            let f: Vec<DMatrix<f64>> = (0..12)
                .map(|_| DMatrix::from_fn(1, 3, |_, _| rng.random_range(-1.0..1.0)))
                .collect();
            let m0 = DMatrix::identity(3, 3) * 0.05;
            let r = detmax(&f, 4, Some(&m0), &DetmaxOptions::default()).unwrap();
            let best = brute_force(&f, 4, &m0);
            assert_relative_eq!(r.log_det, best, max_relative = 1e-9);
            assert_eq!(r.selected.len(), 4);
        }
    }

    #[test]
    fn detmax_rejects_bad_sizes() {
        let f = vec![DMatrix::identity(1, 1); 3];
        assert!(detmax(&f, 0, None, &DetmaxOptions::default()).is_err());
        assert!(detmax(&f, 4, None, &DetmaxOptions::default()).is_err());
        let opts = DetmaxOptions {
            allow_repeats: true,
            ..DetmaxOptions::default()
        };
        assert_eq!(detmax(&f, 4, None, &opts).unwrap().selected.len(), 4);
    }
}
