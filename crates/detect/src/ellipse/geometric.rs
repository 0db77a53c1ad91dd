//! Geometric (orthogonal-distance) ellipse fit by Levenberg–Marquardt.

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix6, Vector2, Vector6};

use super::{EllipseFit, Prepared, direct, residual};
use crate::{DetectError, Result};

/// Options of [`fit_ellipse_geometric`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeometricFitOptions {
    /// Maximum number of Levenberg–Marquardt iterations, both phases together (each iteration
    /// makes one accepted step, possibly after rejected ones). Default 100.
    pub max_iterations: usize,
    /// Relative tolerance of the orthogonal phase: the iteration stops when a step is predicted
    /// to lower the sum of squared distances — or an accepted step lowered it — by less than
    /// `tolerance` of it, or moves the unit-norm conic coefficients (normalised coordinates) by
    /// less than `tolerance`. Default `1e-10`.
    pub tolerance: f64,
    /// Statistical stopping rule of the orthogonal phase: it also stops when the next
    /// Gauss–Newton step is predicted to move the ellipse by less than `noise_tolerance`
    /// standard deviations of its own estimate — the predicted decrease `‖Jδ‖²` of the sum of
    /// squares, over `σ̂² = SSR/(n − 5)`, is the squared Mahalanobis length of the step
    /// `δᵀ(σ̂²(JᵀJ)⁻¹)⁻¹δ` under the covariance the fit reports. Steps that small change no
    /// figure of merit (at the default the remaining error adds `10⁻⁴` of the variance) but
    /// cost full iterations when `tolerance` alone must be met. `0` disables the rule
    /// (iterate to `tolerance`); noiseless data (`σ̂ → 0`) are always iterated to
    /// `tolerance`. Default `0.01`.
    pub noise_tolerance: f64,
}

impl Default for GeometricFitOptions {
    fn default() -> Self {
        GeometricFitOptions {
            max_iterations: 100,
            tolerance: 1e-10,
            noise_tolerance: 0.01,
        }
    }
}

/// Initial Marquardt damping, relative to the diagonal of `JᵀJ`.
const LAMBDA_START: f64 = 1e-3;
/// Damping beyond which no decrease is possible: the cost is at its minimum to rounding.
const LAMBDA_MAX: f64 = 1e16;
/// Relative tolerance of the Sampson phase of [`levenberg_marquardt`].
const SAMPSON_TOLERANCE: f64 = 1e-6;

/// Geometric ellipse fit (000_3b1454b2b2194811.txt §3.2 `FitEllipse`, ellipse of eq. 3.1/3.2):
/// Levenberg–Marquardt minimisation of `Σ dᵢ²` over the ellipse, with `dᵢ` the signed
/// orthogonal (Euclidean) distance of point `i` to it — the maximum-likelihood fit for
/// isotropic Gaussian edge noise, unbiased to first order even on arcs of 60–160°, where the
/// algebraic fits shrink the ellipse.
///
/// The iteration runs on the conic coefficients of eq. (3.3) in normalised coordinates (a
/// linear family of conics fits a partial arc, so Gauss–Newton converges in a few steps where it
/// crawls along a curved valley in `(cx, cy, a, b, θ)`), first on the Sampson distance, then on
/// the exact orthogonal distance with its exact Jacobian `∂dᵢ/∂q = m(x'ᵢ)/‖∇f(x'ᵢ)‖` at the foot
/// points `x'ᵢ`; Marquardt's damping `λ·diag(JᵀJ)` keeps the steps scale-invariant. Foot points
/// are exact closest points (certified Newton, else [`Ellipse::parameter_of`]). The covariance
/// uses the analytic Jacobian with respect to `(cx, cy, a, b, θ)`, `∂dᵢ/∂p = −n̂ᵢ·∂x'/∂p` at the
/// foot point (Ahn, Rauh & Warnecke 2001, orthogonal distance fitting with the foot-point angles
/// eliminated).
///
/// Starts from `initial` if given (Sampson phase first), else from Taubin's algebraic fit —
/// nearly unbiased on partial arcs, so the orthogonal phase starts at once and usually needs
/// one or two steps — or, when Taubin's conic is not an ellipse, from
/// [`super::fit_ellipse_direct`] with the Sampson phase first. The direct fit screens the
/// points in every case. The orthogonal phase stops at `options.tolerance` or, on noisy data,
/// once the next step would move the ellipse by less than `options.noise_tolerance` standard
/// deviations (see [`GeometricFitOptions::noise_tolerance`]). The returned covariance is
/// `σ̂²(JᵀJ)⁻¹` at the solution (see
/// [`EllipseFit::covariance`] for near-circles). When the iteration limit is reached the last
/// (best) ellipse is returned with `converged = false`.
///
/// # Errors
/// As [`super::fit_ellipse_direct`]; [`DetectError::InvalidParameter`] for bad options or a
/// non-finite or non-positive `initial`; [`DetectError::RankDeficient`] if the solution's
/// parameters are not determined by the points — in particular when, on a short noisy arc, the
/// least-squares ellipse does not exist and the iteration runs off toward a parabola
/// (`a → ∞`; the message says so).
pub fn fit_ellipse_geometric(
    points: &[Vector2<f64>],
    initial: Option<Ellipse>,
    options: &GeometricFitOptions,
) -> Result<EllipseFit> {
    if options.max_iterations == 0 {
        return Err(DetectError::InvalidParameter {
            what: "max_iterations",
            value: 0.0,
            reason: "at least one iteration is needed",
        });
    }
    if !(options.tolerance > 0.0 && options.tolerance.is_finite()) {
        return Err(DetectError::InvalidParameter {
            what: "tolerance",
            value: options.tolerance,
            reason: "must be positive and finite",
        });
    }
    if !(options.noise_tolerance >= 0.0 && options.noise_tolerance.is_finite()) {
        return Err(DetectError::InvalidParameter {
            what: "noise_tolerance",
            value: options.noise_tolerance,
            reason: "must be non-negative and finite",
        });
    }
    let prep = Prepared::new(points)?;
    let c = prep.centroid;
    // The direct fit also screens the data (hyperbolas, line pairs), even with an `initial`.
    let direct = direct::solve(&prep)?;
    let start = match initial {
        Some(e) => {
            let start = Ellipse::new(e.cx - c.x, e.cy - c.y, e.a, e.b, e.theta).map_err(|err| {
                DetectError::InvalidParameter {
                    what: "initial ellipse",
                    value: [e.cx, e.cy, e.a, e.b, e.theta]
                        .into_iter()
                        .find(|v| !v.is_finite() || *v <= 0.0)
                        .unwrap_or(f64::NAN),
                    reason: if matches!(err, autoteach_geometry::GeometryError::NonFinite { .. }) {
                        "parameters must be finite"
                    } else {
                        "semi-axes must be positive"
                    },
                }
            })?;
            // A caller's guess may be far off: the Sampson phase first.
            (start, true)
        }
        None => start_of(&prep, direct),
    };
    let (fit, _) = finish(&prep, start, options, &[])?;
    Ok(fit)
}

/// A fit and the eccentric angles `(sin t, cos t)` of the foot points of its points.
pub(crate) type FitWithAngles = (EllipseFit, Vec<(f64, f64)>);

/// The geometric fit of `prep` from `start` (centred frame; with the Sampson phase first if
/// `start.1`), with the foot angles of the points on the result; `warm`: foot angles of the
/// points on a nearby ellipse, or empty.
fn finish(
    prep: &Prepared,
    start: (Ellipse, bool),
    options: &GeometricFitOptions,
    warm: &[(f64, f64)],
) -> Result<FitWithAngles> {
    let c = prep.centroid;
    let (e, iterations, converged, angles, normal) =
        levenberg_marquardt(prep, start.0, start.1, options, warm);
    let (residual_mean, residual_rms, covariance) =
        residual::statistics(&e, &prep.centred, &normal)?;
    let fit = EllipseFit {
        ellipse: Ellipse {
            cx: e.cx + c.x,
            cy: e.cy + c.y,
            ..e
        },
        residual_mean,
        residual_rms,
        covariance,
        iterations,
        converged,
    };
    Ok((fit, angles))
}

/// The combination test of the elliptic-segment assembly (000_3b1454b2b2194811.txt §3.2,
/// `FitEllipse` in Algorithms 1–2) in one preparation: the direct fit
/// ([`super::fit_ellipse_direct`]) as a cheap screen — `Ok(None)` when its mean orthogonal
/// residual is not under `max_direct_residual` — then [`fit_ellipse_geometric`] (from its
/// usual start). Same results as calling the two in turn, without preparing the points twice,
/// without the direct fit's covariance, and with the direct fit's foot angles as Newton starts
/// of the first orthogonal evaluation. Also returns the eccentric angles `(sin t, cos t)` of the foot
/// points of `points` on the fitted ellipse.
///
/// # Errors
/// As [`fit_ellipse_geometric`].
pub(crate) fn fit_screened(
    points: &[Vector2<f64>],
    max_direct_residual: f64,
    options: &GeometricFitOptions,
) -> Result<Option<FitWithAngles>> {
    let prep = Prepared::new(points)?;
    let direct = direct::solve(&prep)?;
    let mut angles = Vec::with_capacity(points.len());
    let mut certified = Vec::with_capacity(points.len());
    residual::certified_foot_angles(&direct, &prep.centred, &[], &mut angles, &mut certified);
    let sc = direct.theta.sin_cos();
    if screen_lower_bound(&direct, sc, &prep.centred, &angles, &certified)
        >= max_direct_residual * points.len() as f64 * (1.0 + SCREEN_MARGIN)
    {
        // The points the general solver would have to decide cannot bring the mean residual
        // under the screen: rejected as below, without solving them.
        return Ok(None);
    }
    residual::solve_uncertified(&direct, &prep.centred, &mut angles, &certified);
    let sum_abs: f64 = prep
        .centred
        .iter()
        .zip(&angles)
        .map(|(p, &t)| residual::foot_at(&direct, sc, p, t).r.abs())
        .sum();
    if !(sum_abs / (points.len() as f64) < max_direct_residual) {
        return Ok(None);
    }
    finish(&prep, start_of(&prep, direct), options, &angles).map(Some)
}

/// Relative margin of the early rejection of [`fit_screened`] over the rounding of the two
/// sums it compares (≈ `n·ε`, `ε = 1.1·10⁻¹⁶`): far below any residual that matters, far above
/// rounding, so the early rejection decides exactly as the full sum would.
const SCREEN_MARGIN: f64 = 1e-9;

/// A lower bound of `Σᵢ |rᵢ|`, the orthogonal distances of the centred `points` to `e`
/// (`sc = (sin θ, cos θ)`): the exact `|rᵢ|` of the points whose foot angle is `certified`,
/// and for the others `min(a, b)·|ρᵢ − 1|` with `ρᵢ = ‖(uᵢ/a, vᵢ/b)‖` (`(u, v)`: the point in the
/// ellipse frame). The map `(u, v) ↦ (u/a, v/b)` takes the ellipse to the unit circle and
/// shrinks every distance by at least `1/min(a, b)`, so a point at distance `d` from the ellipse
/// is within `d/min(a, b)` of the circle: `d ≥ min(a, b)·|ρ − 1|`.
pub(super) fn screen_lower_bound(
    e: &Ellipse,
    sc: (f64, f64),
    points: &[Vector2<f64>],
    angles: &[(f64, f64)],
    certified: &[bool],
) -> f64 {
    let (sth, cth) = sc;
    let (ea, eb) = (1.0 / e.a, 1.0 / e.b);
    let b = e.a.min(e.b);
    points
        .iter()
        .zip(angles)
        .zip(certified)
        .map(|((p, &t), &ok)| {
            if ok {
                residual::foot_at(e, sc, p, t).r.abs()
            } else {
                let (dx, dy) = (p.x - e.cx, p.y - e.cy);
                let u = (cth * dx + sth * dy) * ea;
                let v = (-sth * dx + cth * dy) * eb;
                b * ((u * u + v * v).sqrt() - 1.0).abs()
            }
        })
        .sum()
}

/// The start of the iteration without a caller's guess: Taubin's fit ([`direct::taubin`]),
/// nearly unbiased on partial arcs, so the orthogonal phase starts at once (`false`: no
/// Sampson phase); else the ellipse-specific `direct` fit, biased on partial arcs, with the
/// Sampson phase first.
fn start_of(prep: &Prepared, direct: Ellipse) -> (Ellipse, bool) {
    match direct::taubin(prep) {
        Some(t) => (t, false),
        None => (direct, true),
    }
}

/// Minimises the sum of squared orthogonal distances from `start` (centred pixel frame).
/// Returns the best ellipse, the number of iterations, whether a tolerance was met, the foot
/// angles of the points on that ellipse, and the normal equations of its orthogonal distances
/// with respect to `(cx, cy, a, b, θ)` in pixels (from those with respect to the conic by
/// [`residual::conic_parameter_jacobian`]: no further pass over the points).
///
/// The iteration runs on the unit-norm conic coefficients `q` of the ellipse in the
/// normalised frame of `prep` (see [`residual::distance_and_conic_gradient`]): the ellipses
/// that fit a partial arc about equally well form a nearly *linear* family of conics (a pencil
/// through the arc), whereas in `(cx, cy, a, b, θ)` they form a curved valley along which
/// Gauss–Newton steps overshoot and Levenberg–Marquardt crawls. The scale of `q` is fixed by a
/// gauge term `‖JᵀJ‖·qqᵀ` (no step along `q`) and renormalisation after each step.
///
/// Two phases: if `sampson` (a start that may be far off), first the Sampson distance `f/‖∇f‖`
/// (the first-order orthogonal distance, no foot points, a few times cheaper) to a loose
/// tolerance; then the exact orthogonal distance from there to `options.tolerance` or the noise
/// rule of [`GeometricFitOptions::noise_tolerance`]; the second phase only has to cover the
/// small difference between the two optima, usually in one or two steps. Foot angles are
/// warm-started from the previous evaluation's.
fn levenberg_marquardt(
    prep: &Prepared,
    start: Ellipse,
    sampson: bool,
    options: &GeometricFitOptions,
    warm: &[(f64, f64)],
) -> (Ellipse, usize, bool, Vec<(f64, f64)>, residual::Normal) {
    let s = prep.scale;
    let inv = 1.0 / s;
    let points: Vec<Vector2<f64>> = prep.centred.iter().map(|p| p * inv).collect();
    // The result in pixels, with the normal equations `conic` at `e` carried over to
    // `(cx, cy, a, b, θ)`: `Jₚ = J_q·∂q/∂p` in the normalised frame, then residuals and the
    // first four parameters scaled by `s` (so `∂r/∂θ` by `s`).
    let result = |e: Ellipse, conic: &residual::ConicNormal, q: &[f64; 6]| {
        let g = residual::conic_parameter_jacobian(&e, q);
        let d = nalgebra::Vector5::new(1.0, 1.0, 1.0, 1.0, s);
        let jtj = g.transpose() * conic.jtj * g;
        let normal = residual::Normal {
            jtj: nalgebra::Matrix5::from_fn(|i, j| jtj[(i, j)] * d[i] * d[j]),
            jtr: (g.transpose() * conic.jtr).component_mul(&d) * s,
            ssr: conic.ssr * s * s,
            sum_abs: conic.sum_abs * s,
        };
        let e = Ellipse {
            cx: e.cx * s,
            cy: e.cy * s,
            a: e.a * s,
            b: e.b * s,
            theta: e.theta,
        };
        (e, normal)
    };
    // Sum of squares that counts as an exact fit (rounding level of the input coordinates).
    let exact = points.len() as f64 * (1e-15 * (1.0 + prep.centroid.abs().max() * inv)).powi(2);
    let mut e = Ellipse {
        cx: start.cx * inv,
        cy: start.cy * inv,
        a: start.a * inv,
        b: start.b * inv,
        theta: start.theta,
    };
    let mut q = oriented(e.conic_coefficients());
    // Foot angles on the current ellipse (Newton starts for the next evaluation) and on the
    // candidate; empty during the Sampson phase.
    let mut angles = Vec::with_capacity(points.len());
    let mut next_angles = Vec::with_capacity(points.len());
    let mut orthogonal = false;
    let mut tol = SAMPSON_TOLERANCE.max(options.tolerance);
    // Variance per residual `σ̂²` per unit of sum of squares (`1/(n − 5)`), for the noise rule.
    let per_dof = if points.len() > 5 {
        1.0 / (points.len() - 5) as f64
    } else {
        0.0
    };
    // The noise rule applies to the orthogonal phase only.
    let mut noise = 0.0;
    let (mut jtj, mut jtr, mut ssr) = if sampson {
        residual::accumulate_sampson(&q, &points)
    } else {
        (Matrix6::zeros(), Vector6::zeros(), f64::INFINITY)
    };
    // Σ |r| of the orthogonal distances at `e` (orthogonal phase).
    let mut sum_abs = f64::NAN;
    let mut lambda = LAMBDA_START;
    let mut iteration = 0;
    // Without the Sampson phase: straight to the hand-over below.
    let mut phase_end = !sampson;
    loop {
        if phase_end || ssr <= exact || iteration >= options.max_iterations {
            if orthogonal {
                let conic = residual::ConicNormal {
                    jtj,
                    jtr,
                    ssr,
                    sum_abs,
                };
                let (e, normal) = result(e, &conic, &q);
                return (e, iteration, phase_end || ssr <= exact, angles, normal);
            }
            // Hand over from the Sampson to the orthogonal distance.
            orthogonal = true;
            tol = options.tolerance;
            noise = options.noise_tolerance.powi(2) * per_dof;
            // Close to the optimum already: start with nearly Gauss–Newton steps.
            lambda = LAMBDA_START * 1e-3;
            let conic = residual::accumulate_conic(&e, &q, &points, warm, &mut angles);
            (jtj, jtr, ssr, sum_abs) = (conic.jtj, conic.jtr, conic.ssr, conic.sum_abs);
            if ssr <= exact || iteration >= options.max_iterations {
                let (e, normal) = result(e, &conic, &q);
                return (e, iteration, ssr <= exact, angles, normal);
            }
        }
        iteration += 1;
        let diag = jtj.diagonal();
        let dmax = diag.max();
        let qv = Vector6::from(q);
        let damped_base = jtj + qv * qv.transpose() * dmax;
        let finished = loop {
            let mut a = damped_base;
            for k in 0..6 {
                a[(k, k)] += lambda * diag[k].max(1e-12 * dmax);
            }
            let candidate = a.cholesky().map(|ch| ch.solve(&(-jtr))).and_then(|d| {
                let next = qv + d;
                let norm = next.norm();
                let qn = oriented(std::array::from_fn(|k| next[k] / norm));
                Ellipse::from_coefficients(&qn).ok().map(|ne| (d, qn, ne))
            });
            let Some((delta, next_q, next)) = candidate else {
                lambda *= 10.0;
                if lambda > LAMBDA_MAX {
                    break true;
                }
                continue;
            };
            // Converged when a (nearly undamped) step is predicted to lower the sum of squares
            // by less than `tol` of it, ‖r + Jδ‖² − ‖r‖² = 2δᵀJᵀr + δᵀJᵀJδ: no need to
            // evaluate it.
            let predicted = -(2.0 * delta.dot(&jtr) + delta.dot(&(jtj * delta)));
            // Or by less than `noise` (ε²/(n − 5)) of it: a step of less than ε standard
            // deviations (see [`GeometricFitOptions::noise_tolerance`]).
            let enough = (tol * ssr).max(noise * ssr);
            if lambda <= LAMBDA_START && (predicted <= enough || delta.amax() <= tol) {
                break true;
            }
            let (next_jtj, next_jtr, next_ssr, next_abs) = if orthogonal {
                let c =
                    residual::accumulate_conic(&next, &next_q, &points, &angles, &mut next_angles);
                (c.jtj, c.jtr, c.ssr, c.sum_abs)
            } else {
                let (jtj, jtr, ssr) = residual::accumulate_sampson(&next_q, &points);
                (jtj, jtr, ssr, f64::NAN)
            };
            if next_ssr < ssr {
                let small_gain = ssr - next_ssr <= tol * ssr;
                (e, q, jtj, jtr, ssr) = (next, next_q, next_jtj, next_jtr, next_ssr);
                sum_abs = next_abs;
                std::mem::swap(&mut angles, &mut next_angles);
                lambda = (lambda * 0.1).max(1e-15);
                break small_gain || delta.amax() <= tol;
            }
            lambda *= 10.0;
            if lambda > LAMBDA_MAX {
                break true;
            }
        };
        phase_end = finished;
    }
}

/// The sign of eq. (3.3): `f < 0` inside, i.e. `A + C > 0`.
fn oriented(q: [f64; 6]) -> [f64; 6] {
    if q[0] + q[2] < 0.0 { q.map(|v| -v) } else { q }
}

/// Orthogonal-distance fit of the ellipse parameters `(cx, cy, a, b, θ)` marked in `free`,
/// the others held at their values in `initial` (Levenberg–Marquardt on the analytic
/// Jacobian `∂r/∂p = −n̂·∂x'/∂p` at the foot points, as for the covariance of
/// [`fit_ellipse_geometric`]; 000_3b1454b2b2194811.txt §3.2, ellipse of eq. 3.2).
///
/// For a rim seen only along a short front arc whose shape parameters are known from a better
/// covered ellipse (the two rims of a wafer share `a` and `θ` to ≈ 0.03 %; see
/// [`crate::wafers`]). The covariance is that of the free parameters with the fixed ones
/// taken as exact (zero rows and columns), `σ̂² = SSR/(n − k)`.
///
/// # Errors
/// [`DetectError::TooFewPoints`] for fewer than `k + 1` points (`k` free parameters);
/// [`DetectError::NonFinite`] for a NaN or infinite coordinate;
/// [`DetectError::InvalidParameter`] for bad options, no free parameter, or a non-finite or
/// non-positive `initial`; [`DetectError::RankDeficient`] when the free parameters are not
/// determined by the points.
pub fn fit_ellipse_geometric_masked(
    points: &[Vector2<f64>],
    initial: Ellipse,
    free: [bool; 5],
    options: &GeometricFitOptions,
) -> Result<EllipseFit> {
    let k = free.iter().filter(|f| **f).count();
    if k == 0 {
        return Err(DetectError::InvalidParameter {
            what: "free parameters",
            value: 0.0,
            reason: "at least one parameter must be free",
        });
    }
    if options.max_iterations == 0 || !(options.tolerance > 0.0 && options.tolerance.is_finite()) {
        return Err(DetectError::InvalidParameter {
            what: "options",
            value: options.tolerance,
            reason: "max_iterations must be >= 1 and tolerance positive and finite",
        });
    }
    if points.len() <= k {
        return Err(DetectError::TooFewPoints {
            what: "points",
            got: points.len(),
            needed: k + 1,
        });
    }
    if let Some((index, p)) = points
        .iter()
        .enumerate()
        .find(|(_, p)| !(p.x.is_finite() && p.y.is_finite()))
    {
        return Err(DetectError::NonFinite {
            what: "points",
            index,
            value: if p.x.is_finite() { p.y } else { p.x },
        });
    }
    let params = [initial.cx, initial.cy, initial.a, initial.b, initial.theta];
    if !(params.iter().all(|v| v.is_finite()) && initial.a > 0.0 && initial.b > 0.0) {
        return Err(DetectError::InvalidParameter {
            what: "initial ellipse",
            value: params
                .into_iter()
                .find(|v| !v.is_finite() || *v <= 0.0)
                .unwrap_or(f64::NAN),
            reason: "parameters must be finite and the semi-axes positive",
        });
    }
    // Centre the points for conditioning.
    let n = points.len() as f64;
    let c = points.iter().fold(Vector2::zeros(), |s, p| s + p) / n;
    let centred: Vec<Vector2<f64>> = points.iter().map(|p| p - c).collect();
    let idx: Vec<usize> = (0..5).filter(|&i| free[i]).collect();
    let to_vec = |e: &Ellipse| [e.cx, e.cy, e.a, e.b, e.theta];
    let from_vec = |v: [f64; 5]| Ellipse {
        cx: v[0],
        cy: v[1],
        a: v[2],
        b: v[3],
        theta: v[4],
    };
    let mut e = Ellipse {
        cx: initial.cx - c.x,
        cy: initial.cy - c.y,
        ..initial
    };
    let mut acc = residual::accumulate(&e, &centred, None);
    let mut lambda = LAMBDA_START;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < options.max_iterations {
        iterations += 1;
        let mut a = nalgebra::DMatrix::<f64>::zeros(k, k);
        let mut g = nalgebra::DVector::<f64>::zeros(k);
        for (r, &i) in idx.iter().enumerate() {
            g[r] = acc.jtr[i];
            for (s, &j) in idx.iter().enumerate() {
                a[(r, s)] = acc.jtj[(i, j)];
            }
        }
        let mut accepted = false;
        while lambda <= LAMBDA_MAX {
            let mut damped = a.clone();
            for r in 0..k {
                damped[(r, r)] += lambda * a[(r, r)].max(1e-300);
            }
            let Some(step) = damped.cholesky().map(|ch| ch.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let mut v = to_vec(&e);
            for (r, &i) in idx.iter().enumerate() {
                v[i] += step[r];
            }
            if !(v[2] > 0.0 && v[3] > 0.0 && v.iter().all(|x| x.is_finite())) {
                lambda *= 10.0;
                continue;
            }
            let next = from_vec(v);
            let next_acc = residual::accumulate(&next, &centred, None);
            if next_acc.ssr < acc.ssr {
                let gain = acc.ssr - next_acc.ssr;
                let small = gain <= options.tolerance * acc.ssr
                    || step.amax() <= options.tolerance * (1.0 + e.a);
                e = next;
                acc = next_acc;
                lambda = (lambda * 0.1).max(1e-15);
                accepted = true;
                converged = small;
                break;
            }
            lambda *= 10.0;
        }
        if !accepted {
            // No decrease possible: at the minimum to rounding.
            converged = true;
        }
        if converged {
            break;
        }
    }
    let mut a = nalgebra::DMatrix::<f64>::zeros(k, k);
    for (r, &i) in idx.iter().enumerate() {
        for (s, &j) in idx.iter().enumerate() {
            a[(r, s)] = acc.jtj[(i, j)];
        }
    }
    let names = ["cx", "cy", "a", "b", "theta"];
    let Some(inv) = a
        .clone()
        .try_inverse()
        .filter(|m| m.iter().all(|x| x.is_finite()))
    else {
        let free_names: Vec<&str> = idx.iter().map(|&i| names[i]).collect();
        return Err(DetectError::RankDeficient {
            reason: format!(
                "the free parameters {free_names:?} are not determined by the {} points",
                points.len()
            ),
        });
    };
    let dof = points.len() - k;
    let sigma2 = acc.ssr / dof as f64;
    let mut cov = nalgebra::Matrix5::<f64>::zeros();
    for (r, &i) in idx.iter().enumerate() {
        for (s, &j) in idx.iter().enumerate() {
            cov[(i, j)] = sigma2 * inv[(r, s)];
        }
    }
    Ok(EllipseFit {
        ellipse: Ellipse {
            cx: e.cx + c.x,
            cy: e.cy + c.y,
            ..e
        },
        residual_mean: acc.sum_abs / n,
        residual_rms: (acc.ssr / n).sqrt(),
        covariance: Some(cov),
        iterations,
        converged,
    })
}
