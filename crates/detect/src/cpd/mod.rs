//! Coherent point drift (CPD): rigid (with scale), affine and non-rigid registration of a
//! moving point set Y onto a target X with a uniform outlier component
//! (000_3b1454b2b2194811.txt §3.3, eq. (3.12)–(3.18); Myronenko & Song, "Point set
//! registration: coherent point drift", TPAMI 2010, Figs. 2–4).
//!
//! The points of Y are the centroids of a Gaussian mixture (eq. (3.13)) with common variance
//! σ², plus a uniform component of weight `w` for outliers. Expectation–maximisation
//! alternates the posteriors `p_mn` of eq. (3.12) (E-step, [`EStep`]) and the closed-form
//! transform and σ² that maximise eq. (3.15) (M-step):
//!
//! - [`rigid`]: `T(y) = s R y + t` (Myronenko Fig. 2; `R` from the SVD of `X̂ᵀPᵀŶ`);
//! - [`affine`]: `T(y) = B y + t` (Fig. 3);
//! - [`nonrigid`]: `T(Y) = Y + G W` with the Gaussian RKHS regulariser of eq. (3.16)–(3.17)
//!   and the update of eq. (3.18); optionally with the low-rank `G ≈ QΛQᵀ` of its top
//!   eigenpairs (§4.3 of Myronenko & Song), solved through the Woodbury identity in
//!   `O(M K²)` per iteration.
//!
//! Conventions: point sets are `N × D` / `M × D` matrices, one point per row, `D ∈ {2, 3}`;
//! the result maps Y onto X (`x ≈ s R y + t`). σ² starts at `Σ‖x_n − y_m‖²/(D N M)` unless
//! given; the iteration stops after `max_iterations` or when the change of the objective
//! (rigid, affine: the negative log-likelihood bound `Q` of eq. (3.15)) or of σ² (non-rigid)
//! falls to `tolerance` — the same rules as pycpd 2.0, so results can be compared directly.
//! A σ² that reaches ≤ 0 on exact data is reset to `tolerance / 10` (as pycpd; `1e−12·σ²₀`
//! when `tolerance` is 0); so is one at the rounding level of its own formula, and in both
//! cases the fit is exact and the iteration stops as converged.
//!
//! ```
//! use autoteach_detect::cpd::{rigid, RigidOptions};
//! use nalgebra::{DMatrix, Rotation2, Vector2};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let y = DMatrix::from_fn(40, 2, |i, j| ((i * 37 + j * 11) % 23) as f64 / 7.0);
//! let r = Rotation2::new(0.3);
//! let t = Vector2::new(0.5, -0.2);
//! let mut x = y.clone();
//! for i in 0..40 {
//!     let p = r * Vector2::new(y[(i, 0)], y[(i, 1)]) * 1.2 + t;
//!     x[(i, 0)] = p.x;
//!     x[(i, 1)] = p.y;
//! }
//! let fit = rigid(&x, &y, &RigidOptions::default())?;
//! assert!((fit.scale - 1.2).abs() < 1e-6);
//! assert!((fit.rotation[(1, 0)] - 0.3f64.sin()).abs() < 1e-6);
//! assert!((&fit.transformed - &x).amax() < 1e-6);
//! # Ok(())
//! # }
//! ```

// `!(x > y)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod estep;
mod fgt;
mod global;
mod kernel;
mod lowrank;
mod pcg;
mod register;
#[cfg(test)]
mod tests;

use nalgebra::{DMatrix, DVector};

pub use estep::EStep;
pub(crate) use estep::{EStepSums, EStepWork, posterior_matrix};
pub use global::{GlobalCpdOptions, GlobalHypothesis, global_cpd};
pub use register::{
    Criterion, GlobalRegisterOptions, GlobalRegistration, RegistrationCandidate, global_register,
};

use crate::{DetectError, Result};

/// Options shared by the three CPD variants.
#[derive(Debug, Clone, PartialEq)]
pub struct CpdOptions {
    /// Weight of the uniform outlier component, `0 ≤ w < 1` (default 0).
    pub w: f64,
    /// Maximum number of EM iterations (default 100, as pycpd).
    pub max_iterations: usize,
    /// Convergence tolerance on the change of the objective (rigid, affine) or of σ²
    /// (non-rigid), default 1e−3 (as pycpd). 0 runs `max_iterations`.
    pub tolerance: f64,
    /// Initial σ²; `None` for `Σ‖x_n − y_m‖²/(D N M)`.
    pub sigma2: Option<f64>,
    /// How the E-step sums are evaluated.
    pub e_step: EStep,
    /// Return the M × N posterior matrix `P` of the last E-step (allocates M·N numbers).
    pub return_p: bool,
}

impl Default for CpdOptions {
    fn default() -> Self {
        Self {
            w: 0.0,
            max_iterations: 100,
            tolerance: 1e-3,
            sigma2: None,
            e_step: EStep::Auto,
            return_p: false,
        }
    }
}

/// Options of [`rigid`].
#[derive(Debug, Clone, PartialEq)]
pub struct RigidOptions {
    /// Shared options.
    pub cpd: CpdOptions,
    /// Estimate the uniform scale `s` (default true); false fixes `s = 1`.
    pub scale: bool,
}

impl Default for RigidOptions {
    fn default() -> Self {
        Self {
            cpd: CpdOptions::default(),
            scale: true,
        }
    }
}

/// Options of [`affine`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AffineOptions {
    /// Shared options.
    pub cpd: CpdOptions,
}

/// Options of [`nonrigid`].
#[derive(Debug, Clone, PartialEq)]
pub struct NonrigidOptions {
    /// Shared options.
    pub cpd: CpdOptions,
    /// Width β of the Gaussian kernel `G` (default 2, as pycpd), in the units of the points.
    pub beta: f64,
    /// Regularisation weight λ (pycpd's `alpha`, default 2).
    pub lambda: f64,
    /// Number of eigenpairs K of the low-rank `G ≈ QΛQᵀ`; `None` for the full `G` (solved by
    /// conjugate gradients; stored as `M × M` numbers unless the fast Gauss transform applies
    /// it more cheaply, see [`nonrigid`]).
    pub low_rank: Option<usize>,
    /// Subspace-iteration steps refining the Nyström eigenpairs (see the `lowrank` module
    /// docs); `None` for 2 when `M ≤ 5000`, else 0 (Nyström alone).
    pub power_iterations: Option<usize>,
}

impl Default for NonrigidOptions {
    fn default() -> Self {
        Self {
            cpd: CpdOptions::default(),
            beta: 2.0,
            lambda: 2.0,
            low_rank: None,
            power_iterations: None,
        }
    }
}

/// Number of blocks whose partial sums the parallel reductions (the E-step's `(P1, PX)`, the
/// fast Gauss transform's spread) add in a fixed order. It is a constant, not the thread count,
/// so every result is bit-identical for any `RAYON_NUM_THREADS`; 8 keeps up to 4 threads busy.
pub(crate) const REDUCTION_BLOCKS: usize = 8;

/// Full-rank non-rigid CPD refuses sets larger than this (`G` alone would need M²·8 bytes).
pub const MAX_FULL_RANK_POINTS: usize = 12_000;

/// Result of [`rigid`]: `x ≈ s R y + t`.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidResult {
    /// Rotation `R` (D × D, det +1).
    pub rotation: DMatrix<f64>,
    /// Translation `t` (D).
    pub translation: DVector<f64>,
    /// Uniform scale `s` (1 when not estimated).
    pub scale: f64,
    /// The moved Y, `s R y_m + t` (M × D).
    pub transformed: DMatrix<f64>,
    /// Final σ².
    pub sigma2: f64,
    /// EM iterations run.
    pub iterations: usize,
    /// Whether the tolerance was met before `max_iterations`.
    pub converged: bool,
    /// Posterior matrix `P` (M × N) of the last E-step, when requested.
    pub p: Option<DMatrix<f64>>,
}

/// Result of [`affine`]: `x ≈ B y + t`.
#[derive(Debug, Clone, PartialEq)]
pub struct AffineResult {
    /// Linear part `B` (D × D).
    pub matrix: DMatrix<f64>,
    /// Translation `t` (D).
    pub translation: DVector<f64>,
    /// The moved Y (M × D).
    pub transformed: DMatrix<f64>,
    /// Final σ².
    pub sigma2: f64,
    /// EM iterations run.
    pub iterations: usize,
    /// Whether the tolerance was met before `max_iterations`.
    pub converged: bool,
    /// Posterior matrix `P` (M × N) of the last E-step, when requested.
    pub p: Option<DMatrix<f64>>,
}

/// Result of [`nonrigid`]: `T(Y) = Y + G W`.
#[derive(Debug, Clone, PartialEq)]
pub struct NonrigidResult {
    /// Kernel weights `W` (M × D) of eq. (3.17).
    pub w: DMatrix<f64>,
    /// The moved Y, `Y + G W` (M × D; `G` the low-rank approximation when used).
    pub transformed: DMatrix<f64>,
    /// Deformation energy `‖f‖²_H = tr(Wᵀ G W)` (eq. (3.17)).
    pub energy: f64,
    /// Final σ².
    pub sigma2: f64,
    /// EM iterations run.
    pub iterations: usize,
    /// Whether the tolerance was met before `max_iterations`.
    pub converged: bool,
    /// Eigenpairs used for `G` (`None`: full rank).
    pub rank: Option<usize>,
    /// Posterior matrix `P` (M × N) of the last E-step, when requested.
    pub p: Option<DMatrix<f64>>,
}

// ---------------------------------------------------------------------------------------
// Validation and conversion.

/// Checks a point set and returns it row-major.
fn points<const D: usize>(p: &DMatrix<f64>, what: &'static str) -> Result<Vec<[f64; D]>> {
    let mut out = Vec::with_capacity(p.nrows());
    for i in 0..p.nrows() {
        let mut row = [0.0; D];
        for (d, v) in row.iter_mut().enumerate() {
            let value = p[(i, d)];
            if !value.is_finite() {
                return Err(DetectError::NonFinite {
                    what,
                    index: i,
                    value,
                });
            }
            *v = value;
        }
        out.push(row);
    }
    if out.len() < D + 1 {
        return Err(DetectError::TooFewPoints {
            what,
            got: out.len(),
            needed: D + 1,
        });
    }
    if out.iter().all(|q| q == &out[0]) {
        return Err(DetectError::Degenerate {
            reason: format!(
                "all {} points of {what} are identical ({:?}): the set has zero variance",
                out.len(),
                out[0]
            ),
        });
    }
    Ok(out)
}

/// Validates the shared options and the dimensions; returns D.
fn check(x: &DMatrix<f64>, y: &DMatrix<f64>, o: &CpdOptions) -> Result<usize> {
    let d = x.ncols();
    if d != 2 && d != 3 {
        return Err(DetectError::WrongLength {
            what: "the point dimension (columns) of X",
            got: d,
            expected: if d < 2 { 2 } else { 3 },
        });
    }
    if y.ncols() != d {
        return Err(DetectError::WrongLength {
            what: "the point dimension (columns) of Y",
            got: y.ncols(),
            expected: d,
        });
    }
    if !(o.w >= 0.0 && o.w < 1.0) {
        return Err(DetectError::InvalidParameter {
            what: "w",
            value: o.w,
            reason: "the outlier weight must lie in [0, 1)",
        });
    }
    if !(o.tolerance >= 0.0) || !o.tolerance.is_finite() {
        return Err(DetectError::InvalidParameter {
            what: "tolerance",
            value: o.tolerance,
            reason: "must be finite and ≥ 0",
        });
    }
    if let Some(s2) = o.sigma2
        && !(s2 > 0.0 && s2.is_finite())
    {
        return Err(DetectError::InvalidParameter {
            what: "sigma2",
            value: s2,
            reason: "the initial variance must be finite and > 0",
        });
    }
    Ok(d)
}

/// `Σ_nm ‖x_n − y_m‖² / (D N M)` in O((N + M) D), from the means and second moments.
fn initial_sigma2<const D: usize>(x: &[[f64; D]], y: &[[f64; D]]) -> f64 {
    let mean = |p: &[[f64; D]]| {
        let mut m = [0.0; D];
        for q in p {
            for d in 0..D {
                m[d] += q[d];
            }
        }
        m.map(|v| v / p.len() as f64)
    };
    let (mx, my) = (mean(x), mean(y));
    // Σ_nm ‖x_n − y_m‖² = M Σ‖x_n − x̄‖² + N Σ‖y_m − ȳ‖² + N M ‖x̄ − ȳ‖².
    let spread = |p: &[[f64; D]], m: &[f64; D]| {
        p.iter()
            .map(|q| (0..D).map(|d| (q[d] - m[d]).powi(2)).sum::<f64>())
            .sum::<f64>()
    };
    let (n, mm) = (x.len() as f64, y.len() as f64);
    let between: f64 = (0..D).map(|d| (mx[d] - my[d]).powi(2)).sum();
    (mm * spread(x, &mx) + n * spread(y, &my) + n * mm * between) / (D as f64 * n * mm)
}

/// The σ² floor applied when an update reaches ≤ 0 (see the module docs).
fn sigma2_floor(tolerance: f64, sigma2_0: f64) -> f64 {
    if tolerance > 0.0 {
        tolerance / 10.0
    } else {
        1e-12 * sigma2_0
    }
}

/// Row-major points back to an M × D matrix.
fn to_matrix<const D: usize>(p: &[[f64; D]]) -> DMatrix<f64> {
    DMatrix::from_fn(p.len(), D, |i, d| p[i][d])
}

/// Fails when no point received posterior mass (every target point is an outlier).
fn check_mass<const D: usize>(e: &EStepSums<D>, sigma2: f64) -> Result<()> {
    if !(e.np > 1e-300) {
        return Err(DetectError::Degenerate {
            reason: format!(
                "no target point is explained by the mixture (N_P = {:e} at σ² = {sigma2:e}): \
                 the outlier weight w dominates every point",
                e.np
            ),
        });
    }
    Ok(())
}

/// Weighted means `μx = XᵀPᵀ1/N_P`, `μy = YᵀP1/N_P`.
fn weighted_means<const D: usize>(
    x: &[[f64; D]],
    y: &[[f64; D]],
    e: &EStepSums<D>,
) -> ([f64; D], [f64; D]) {
    let mut mx = [0.0; D];
    let mut my = [0.0; D];
    for (p, q) in e.pt1.iter().zip(x) {
        for d in 0..D {
            mx[d] += p * q[d];
        }
    }
    for (p, q) in e.p1.iter().zip(y) {
        for d in 0..D {
            my[d] += p * q[d];
        }
    }
    (mx.map(|v| v / e.np), my.map(|v| v / e.np))
}

/// `A = X̂ᵀPᵀŶ = Σ_m (PX_m − P1_m μx)(y_m − μy)ᵀ` and `x̂ᵀd(Pᵀ1)x̂ = Σ_n Pt1_n ‖x_n − μx‖²`.
fn cross_terms<const D: usize>(
    x: &[[f64; D]],
    y: &[[f64; D]],
    e: &EStepSums<D>,
    mx: &[f64; D],
    my: &[f64; D],
) -> (DMatrix<f64>, f64) {
    let mut a = DMatrix::zeros(D, D);
    for ((pxm, p1m), ym) in e.px.iter().zip(&e.p1).zip(y) {
        for i in 0..D {
            let u = pxm[i] - p1m * mx[i];
            for j in 0..D {
                a[(i, j)] += u * (ym[j] - my[j]);
            }
        }
    }
    let xpx = e
        .pt1
        .iter()
        .zip(x)
        .map(|(p, q)| p * (0..D).map(|d| (q[d] - mx[d]).powi(2)).sum::<f64>())
        .sum();
    (a, xpx)
}

/// The iteration state shared by the three variants.
struct Em<const D: usize> {
    work: EStepWork<D>,
    sigma2: f64,
    sigma2_0: f64,
    w: f64,
    /// Moved Y and σ² of the last E-step (for `P` on request).
    last: Option<(Vec<[f64; D]>, f64)>,
}

impl<const D: usize> Em<D> {
    fn new(x: &[[f64; D]], y: &[[f64; D]], o: &CpdOptions) -> Result<Self> {
        let sigma2 = o.sigma2.unwrap_or_else(|| initial_sigma2(x, y));
        if !(sigma2 > 0.0) || !sigma2.is_finite() {
            return Err(DetectError::Degenerate {
                reason: format!("the initial variance σ² = {sigma2:e} is not positive"),
            });
        }
        Ok(Self {
            work: EStepWork::new(x.len(), y.len(), o.e_step),
            sigma2,
            sigma2_0: sigma2,
            w: o.w,
            last: None,
        })
    }

    fn e_step(&mut self, x: &[[f64; D]], t: &[[f64; D]], keep_last: bool) -> Result<EStepSums<D>> {
        if keep_last {
            self.last = Some((t.to_vec(), self.sigma2));
        }
        let e = self.work.run(x, t, self.sigma2, self.w);
        check_mass(&e, self.sigma2)?;
        Ok(e)
    }

    /// Sets σ² from the M-step value `s2`, computed as a difference of terms of size about
    /// `scale`: a value that is not above the rounding error of that difference
    /// (`64 ε · scale`) is indistinguishable from 0 and gets the floor, as a value ≤ 0 does.
    /// Returns true in that case: the transform explains the data exactly (to rounding) and
    /// the iteration stops as converged — the objective alone would oscillate between the
    /// floor and the next rounding-level σ² without ever meeting the tolerance.
    #[must_use]
    fn set_sigma2(&mut self, s2: f64, scale: f64, tolerance: f64) -> bool {
        let exact = !(s2 > 64.0 * f64::EPSILON * scale.abs());
        self.sigma2 = if exact {
            sigma2_floor(tolerance, self.sigma2_0)
        } else {
            s2
        };
        exact
    }

    fn p(&self, x: &[[f64; D]], return_p: bool) -> Option<DMatrix<f64>> {
        if !return_p {
            return None;
        }
        self.last
            .as_ref()
            .map(|(t, s2)| posterior_matrix(x, t, *s2, self.w))
    }
}

// ---------------------------------------------------------------------------------------
// Rigid.

/// Rigid CPD with optional uniform scale (Myronenko & Song Fig. 2; 000_3b1454b2b2194811.txt
/// eq. (3.12)–(3.15)): finds `s, R, t` with `x ≈ s R y + t`.
///
/// Errors: dimensions other than 2/3 or different for X and Y, fewer than D + 1 points,
/// non-finite coordinates, all points identical, invalid options, or no posterior mass.
pub fn rigid(x: &DMatrix<f64>, y: &DMatrix<f64>, options: &RigidOptions) -> Result<RigidResult> {
    match check(x, y, &options.cpd)? {
        2 => rigid_d::<2>(x, y, options),
        _ => rigid_d::<3>(x, y, options),
    }
}

fn rigid_d<const D: usize>(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    options: &RigidOptions,
) -> Result<RigidResult> {
    let o = &options.cpd;
    let xs = points::<D>(x, "X")?;
    let ys = points::<D>(y, "Y")?;
    let mut em = Em::new(&xs, &ys, o)?;
    let mut r = DMatrix::<f64>::identity(D, D);
    let mut t = DVector::<f64>::zeros(D);
    let mut s = 1.0;
    let mut ty = ys.clone();
    let mut q = f64::INFINITY;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < o.max_iterations {
        let e = em.e_step(&xs, &ty, o.return_p)?;
        let (mx, my) = weighted_means(&xs, &ys, &e);
        let (a, xpx) = cross_terms(&xs, &ys, &e, &mx, &my);
        let ypy: f64 =
            e.p1.iter()
                .zip(&ys)
                .map(|(p, q)| p * (0..D).map(|d| (q[d] - my[d]).powi(2)).sum::<f64>())
                .sum();
        let svd = a.clone().svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            return Err(DetectError::Degenerate {
                reason: "SVD of the cross-covariance XᵀPᵀY failed".into(),
            });
        };
        let mut c = DMatrix::<f64>::identity(D, D);
        c[(D - 1, D - 1)] = (&u * &vt).determinant().signum();
        r = &u * c * &vt;
        let tr_ar = (a.transpose() * &r).trace();
        if options.scale {
            if !(ypy > 0.0) {
                return Err(DetectError::Degenerate {
                    reason: format!(
                        "the weighted spread of Y is {ypy:e}: the matched points of Y coincide"
                    ),
                });
            }
            s = tr_ar / ypy;
        }
        let myv = DVector::from_column_slice(&my);
        t = DVector::from_column_slice(&mx) - s * (&r * myv);
        let q_new = (xpx - 2.0 * s * tr_ar + s * s * ypy) / (2.0 * em.sigma2)
            + D as f64 * e.np / 2.0 * em.sigma2.ln();
        let diff = (q_new - q).abs();
        q = q_new;
        let s2 = if options.scale {
            (xpx - s * tr_ar) / (e.np * D as f64)
        } else {
            (xpx - 2.0 * tr_ar + ypy) / (e.np * D as f64)
        };
        let exact = em.set_sigma2(s2, xpx / (e.np * D as f64), o.tolerance);
        ty = transform_rigid(&ys, &r, &t, s);
        iterations += 1;
        if diff <= o.tolerance || exact {
            converged = true;
            break;
        }
    }
    let p = em.p(&xs, o.return_p);
    Ok(RigidResult {
        rotation: r,
        translation: t,
        scale: s,
        transformed: to_matrix(&ty),
        sigma2: em.sigma2,
        iterations,
        converged,
        p,
    })
}

/// `s R y + t` for every point.
fn transform_rigid<const D: usize>(
    y: &[[f64; D]],
    r: &DMatrix<f64>,
    t: &DVector<f64>,
    s: f64,
) -> Vec<[f64; D]> {
    y.iter()
        .map(|q| {
            let mut o = [0.0; D];
            for i in 0..D {
                let mut v = t[i];
                for j in 0..D {
                    v += s * r[(i, j)] * q[j];
                }
                o[i] = v;
            }
            o
        })
        .collect()
}

// ---------------------------------------------------------------------------------------
// Affine.

/// Affine CPD (Myronenko & Song Fig. 3; 000_3b1454b2b2194811.txt eq. (3.12)–(3.15)): finds
/// `B, t` with `x ≈ B y + t`.
///
/// Errors: as [`rigid`], plus a degenerate (e.g. collinear in 2D) weighted spread of Y.
pub fn affine(x: &DMatrix<f64>, y: &DMatrix<f64>, options: &AffineOptions) -> Result<AffineResult> {
    match check(x, y, &options.cpd)? {
        2 => affine_d::<2>(x, y, options),
        _ => affine_d::<3>(x, y, options),
    }
}

fn affine_d<const D: usize>(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    options: &AffineOptions,
) -> Result<AffineResult> {
    let o = &options.cpd;
    let xs = points::<D>(x, "X")?;
    let ys = points::<D>(y, "Y")?;
    let mut em = Em::new(&xs, &ys, o)?;
    let mut b = DMatrix::<f64>::identity(D, D);
    let mut t = DVector::<f64>::zeros(D);
    let mut ty = ys.clone();
    let mut q = f64::INFINITY;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < o.max_iterations {
        let e = em.e_step(&xs, &ty, o.return_p)?;
        let (mx, my) = weighted_means(&xs, &ys, &e);
        let (a, xpx) = cross_terms(&xs, &ys, &e, &mx, &my);
        // Ŷᵀ d(P1) Ŷ.
        let mut ypy = DMatrix::<f64>::zeros(D, D);
        for (p, q) in e.p1.iter().zip(&ys) {
            for i in 0..D {
                for j in 0..D {
                    ypy[(i, j)] += p * (q[i] - my[i]) * (q[j] - my[j]);
                }
            }
        }
        let scale = ypy.trace();
        let Some(ypy_inv) = ypy.clone().cholesky().map(|c| c.inverse()).filter(|inv| {
            // Reject a numerically singular spread (collinear / coplanar Y).
            scale > 0.0 && inv.amax() * scale < 1e12
        }) else {
            return Err(DetectError::Degenerate {
                reason: format!(
                    "the weighted spread ŶᵀdiagP1Ŷ of Y is singular (eigenvalues {:?}): Y lies \
                     in a lower-dimensional subspace, the affine map is undetermined",
                    ypy.symmetric_eigenvalues().as_slice()
                ),
            });
        };
        b = &a * ypy_inv;
        let myv = DVector::from_column_slice(&my);
        t = DVector::from_column_slice(&mx) - &b * myv;
        // tr(A Bᵀ) in our orientation equals pycpd's tr(A B_pycpd).
        let tr_ab = (&a * b.transpose()).trace();
        let tr_bypyb = (&b * &ypy * b.transpose()).trace();
        let q_new = (xpx - 2.0 * tr_ab + tr_bypyb) / (2.0 * em.sigma2)
            + D as f64 * e.np / 2.0 * em.sigma2.ln();
        let diff = (q_new - q).abs();
        q = q_new;
        let exact = em.set_sigma2(
            (xpx - tr_ab) / (e.np * D as f64),
            xpx / (e.np * D as f64),
            o.tolerance,
        );
        ty = transform_rigid(&ys, &b, &t, 1.0);
        iterations += 1;
        if diff <= o.tolerance || exact {
            converged = true;
            break;
        }
    }
    let p = em.p(&xs, o.return_p);
    Ok(AffineResult {
        matrix: b,
        translation: t,
        transformed: to_matrix(&ty),
        sigma2: em.sigma2,
        iterations,
        converged,
        p,
    })
}

// ---------------------------------------------------------------------------------------
// Non-rigid.

/// The kernel in one of its two forms.
enum Kernel<const D: usize> {
    /// Full `G` (M × M), solved by preconditioned CG.
    Full(Box<pcg::FullSystem<D>>),
    /// `G ≈ Q Λ Qᵀ`.
    LowRank {
        q: DMatrix<f64>,
        lambda: DVector<f64>,
    },
}

impl<const D: usize> Kernel<D> {
    /// `G W`.
    fn times(&self, w: &DMatrix<f64>) -> DMatrix<f64> {
        match self {
            Kernel::Full(g) => g.times(w),
            Kernel::LowRank { q, lambda } => {
                let mut qtw = lowrank::mul(q, true, w);
                for (mut row, l) in qtw.row_iter_mut().zip(lambda.iter()) {
                    row *= *l;
                }
                lowrank::mul(q, false, &qtw)
            }
        }
    }
}

/// Non-rigid CPD with Gaussian RKHS regularisation (000_3b1454b2b2194811.txt eq. (3.16)–(3.18);
/// Myronenko & Song Fig. 4): `T(Y) = Y + G W`,
/// `W = (G + λσ² d(P1)⁻¹)⁻¹ (d(P1)⁻¹ P X − Y)`.
///
/// Full rank solves the equivalent symmetric positive definite system
/// `(D^{½} G D^{½} + λσ² I) V = D^{-½}(PX − D Y)`, `W = D^{½} V` with `D = d(P1)` by
/// preconditioned conjugate gradients (the `pcg` module: `G` applied by the fast Gauss
/// transform when that is cheaper than the dense product, except with `EStep::Dense`; dense
/// Cholesky as fallback). With `low_rank = Some(K)`, `G ≈ QΛQᵀ` and the
/// Woodbury identity gives
/// `W = (λσ²)⁻¹ [F − D Q (λσ² Λ⁻¹ + Qᵀ D Q)⁻¹ Qᵀ F]`, `F = PX − D Y`, in `O(M K²)`.
///
/// Errors: as [`rigid`], plus `beta`, `lambda` not finite and > 0, `low_rank` outside
/// `1..=M`, or a full-rank problem larger than [`MAX_FULL_RANK_POINTS`].
pub fn nonrigid(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    options: &NonrigidOptions,
) -> Result<NonrigidResult> {
    let d = check(x, y, &options.cpd)?;
    for (what, value) in [("beta", options.beta), ("lam", options.lambda)] {
        if !(value > 0.0 && value.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what,
                value,
                reason: "must be finite and > 0",
            });
        }
    }
    match options.low_rank {
        Some(k) if k == 0 || k > y.nrows() => {
            return Err(DetectError::InvalidParameter {
                what: "low_rank",
                value: k as f64,
                reason: "the number of eigenpairs must lie in 1..=M",
            });
        }
        None if y.nrows() > MAX_FULL_RANK_POINTS => {
            // The message names the limit literally (tests/test_reliability.py pins the wording).
            return Err(DetectError::InvalidParameter {
                what: "number of source points M (rows of Y)",
                value: y.nrows() as f64,
                reason: "full-rank non-rigid CPD holds the M × M kernel and must stay within \
                         12000 source points; set low_rank=K eigenpairs (for example low_rank=100)",
            });
        }
        _ => {}
    }
    match d {
        2 => nonrigid_d::<2>(x, y, options),
        _ => nonrigid_d::<3>(x, y, options),
    }
}

fn nonrigid_d<const D: usize>(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    options: &NonrigidOptions,
) -> Result<NonrigidResult> {
    let o = &options.cpd;
    let xs = points::<D>(x, "X")?;
    let ys = points::<D>(y, "Y")?;
    let m = ys.len();
    let mut em = Em::new(&xs, &ys, o)?;
    let mut kernel = match options.low_rank {
        None => Kernel::Full(Box::new(pcg::FullSystem::new(
            &ys,
            options.beta,
            o.e_step == EStep::Dense,
        ))),
        Some(k) => {
            let iters = options
                .power_iterations
                .unwrap_or(if m <= 5000 { 2 } else { 0 });
            let (q, lambda) = lowrank::low_rank_kernel(&ys, options.beta, k, iters);
            Kernel::LowRank { q, lambda }
        }
    };
    let ym = to_matrix(&ys);
    let mut w = DMatrix::<f64>::zeros(m, D);
    let mut ty = ys.clone();
    let mut iterations = 0;
    let mut converged = false;
    while iterations < o.max_iterations {
        let e = em.e_step(&xs, &ty, o.return_p)?;
        let lam_s2 = options.lambda * em.sigma2;
        // F = PX − d(P1) Y.
        let f = DMatrix::from_fn(m, D, |i, d| e.px[i][d] - e.p1[i] * ym[(i, d)]);
        let gw = match &mut kernel {
            Kernel::Full(sys) => {
                w = sys.solve(&e.p1, &f, lam_s2)?;
                sys.last_gw().cloned().unwrap_or_else(|| sys.times(&w))
            }
            Kernel::LowRank { q, lambda } => {
                w = solve_woodbury(q, lambda, &e.p1, &f, lam_s2)?;
                kernel.times(&w)
            }
        };
        for (i, t) in ty.iter_mut().enumerate() {
            for d in 0..D {
                t[d] = ys[i][d] + gw[(i, d)];
            }
        }
        // σ² of eq. (3.18): [tr(Xᵀd(Pᵀ1)X) − 2tr((PX)ᵀT) + tr(Tᵀd(P1)T)] / (N_P D), with X and
        // T shifted by the mean of X so the three terms do not cancel catastrophically.
        let c = mean(&xs);
        let xpx: f64 = e
            .pt1
            .iter()
            .zip(&xs)
            .map(|(p, q)| p * (0..D).map(|d| (q[d] - c[d]).powi(2)).sum::<f64>())
            .sum();
        let mut trpxt = 0.0;
        let mut tpt = 0.0;
        for ((pxm, p1m), t) in e.px.iter().zip(&e.p1).zip(&ty) {
            for d in 0..D {
                let tc = t[d] - c[d];
                trpxt += (pxm[d] - p1m * c[d]) * tc;
                tpt += p1m * tc * tc;
            }
        }
        let prev = em.sigma2;
        let exact = em.set_sigma2(
            (xpx - 2.0 * trpxt + tpt) / (e.np * D as f64),
            (xpx + tpt) / (e.np * D as f64),
            o.tolerance,
        );
        iterations += 1;
        if (em.sigma2 - prev).abs() <= o.tolerance || exact {
            converged = true;
            break;
        }
    }
    let energy = {
        let gw = kernel.times(&w);
        w.component_mul(&gw).sum()
    };
    let p = em.p(&xs, o.return_p);
    Ok(NonrigidResult {
        w,
        transformed: to_matrix(&ty),
        energy,
        sigma2: em.sigma2,
        iterations,
        converged,
        rank: match &kernel {
            Kernel::Full(_) => None,
            Kernel::LowRank { lambda, .. } => Some(lambda.len()),
        },
        p,
    })
}

fn mean<const D: usize>(p: &[[f64; D]]) -> [f64; D] {
    let mut m = [0.0; D];
    for q in p {
        for d in 0..D {
            m[d] += q[d];
        }
    }
    m.map(|v| v / p.len() as f64)
}

/// Full-rank W: `(D^{½} G D^{½} + λσ² I) V = D^{-½} F`, `W = D^{½} V` (Cholesky, faer): the
/// direct solve, the fallback of the CG solver of the `pcg` module and its reference in the
/// tests.
pub(crate) fn solve_full(
    g: &DMatrix<f64>,
    p1: &[f64],
    f: &DMatrix<f64>,
    lam_s2: f64,
) -> Result<DMatrix<f64>> {
    use faer::linalg::solvers::Solve;
    let m = g.nrows();
    let sq: Vec<f64> = p1.iter().map(|p| p.max(0.0).sqrt()).collect();
    let a = faer::Mat::<f64>::from_fn(m, m, |i, j| {
        sq[i] * g[(i, j)] * sq[j] + if i == j { lam_s2 } else { 0.0 }
    });
    let rhs = faer::Mat::<f64>::from_fn(m, f.ncols(), |i, d| {
        if sq[i] > 0.0 { f[(i, d)] / sq[i] } else { 0.0 }
    });
    let llt = a
        .llt(faer::Side::Lower)
        .map_err(|e| DetectError::Degenerate {
            reason: format!(
                "Cholesky of the non-rigid CPD system failed ({e:?}) at λσ² = {lam_s2:e}"
            ),
        })?;
    let v = llt.solve(&rhs);
    Ok(DMatrix::from_fn(m, f.ncols(), |i, d| sq[i] * v[(i, d)]))
}

/// Low-rank W by the Woodbury identity (see [`nonrigid`]).
fn solve_woodbury(
    q: &DMatrix<f64>,
    lambda: &DVector<f64>,
    p1: &[f64],
    f: &DMatrix<f64>,
    lam_s2: f64,
) -> Result<DMatrix<f64>> {
    let k = lambda.len();
    // Qᵀ D Q + λσ² Λ⁻¹ (K × K, SPD).
    let mut inner = lowrank::weighted_gram(q, p1);
    for i in 0..k {
        inner[(i, i)] += lam_s2 / lambda[i];
    }
    let Some(chol) = inner.cholesky() else {
        return Err(DetectError::Degenerate {
            reason: format!("the low-rank CPD system is not positive definite at λσ² = {lam_s2:e}"),
        });
    };
    let z = chol.solve(&lowrank::mul(q, true, f));
    // D Q z = d(P1)·(Q z).
    let mut dqz = lowrank::mul(q, false, &z);
    for (mut row, p) in dqz.row_iter_mut().zip(p1) {
        row *= *p;
    }
    Ok((f - dqz) / lam_s2)
}
