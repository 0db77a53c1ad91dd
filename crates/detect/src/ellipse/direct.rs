//! Direct (algebraic) ellipse fit: Fitzgibbon, Pilu & Fisher (1999) in the numerically stable
//! form of Halir & Flusser (1998).

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};

use super::{EllipseFit, Prepared, residual};
use crate::{DetectError, Result};

/// The ellipse-specific fit is rejected as "the data are a hyperbola (or a line pair)" when the
/// unconstrained conic is not an ellipse and fits with an RMS Sampson distance this many times
/// smaller. On noisy elliptic arcs both fits are at the noise level (ratio ≈ 1); on points of a
/// hyperbola the best ellipse is far off.
const HYPERBOLA_RATIO: f64 = 4.0;

/// Direct least-squares ellipse fit (000_3b1454b2b2194811.txt §3.2 `FitEllipse`, the conic of
/// eq. 3.3): minimises the algebraic error `Σ (Ax² + Bxy + Cy² + Dx + Ey + F)²` subject to the
/// ellipse constraint `4AC − B² = 1` (Fitzgibbon et al. 1999), solved as Halir & Flusser (1998):
/// the linear part is eliminated (`(D, E, F) = T·(A, B, C)`), leaving the 3×3 eigenproblem
/// `C₁⁻¹M·a = λa`, whose eigenvector with `4AC − B² > 0` (the one of least constrained cost) is
/// the solution. Points are centred and scaled before fitting and the ellipse mapped back.
///
/// Residuals and covariance are those of [`super::EllipseFit`], evaluated at the direct ellipse.
///
/// # Errors
/// [`DetectError::TooFewPoints`] (fewer than 5), [`DetectError::NonFinite`] (NaN/∞),
/// [`DetectError::Degenerate`] for coincident or collinear points, fewer than 5 distinct points,
/// points that lie on a hyperbola or a pair of lines, or any solution that is not a real ellipse;
/// [`DetectError::RankDeficient`] if the covariance is undetermined.
pub fn fit_ellipse_direct(points: &[Vector2<f64>]) -> Result<EllipseFit> {
    let prep = Prepared::new(points)?;
    let e = solve(&prep)?;
    let (residual_mean, residual_rms, covariance) = residual::evaluate(&e, &prep.centred, None)?;
    Ok(EllipseFit {
        ellipse: Ellipse {
            cx: e.cx + prep.centroid.x,
            cy: e.cy + prep.centroid.y,
            ..e
        },
        residual_mean,
        residual_rms,
        covariance,
        iterations: 0,
        converged: true,
    })
}

/// `4AC − B²` of the quadratic coefficients, i.e. `aᵀC₁a`.
fn ellipticity(a: &Vector3<f64>) -> f64 {
    4.0 * a[0] * a[2] - a[1] * a[1]
}

/// The direct fit in the centred pixel frame of `prep`.
pub(crate) fn solve(prep: &Prepared) -> Result<Ellipse> {
    let m = &prep.m;
    // C₁⁻¹M with C₁ = [[0, 0, 2], [0, −1, 0], [2, 0, 0]].
    let mp = Matrix3::from_rows(&[m.row(2) * 0.5, -m.row(1), m.row(0) * 0.5]);
    // The eigenvalues are real in theory (M is positive semi-definite); rounding may pair two
    // nearly equal ones, so take real parts and let the cost decide between the candidates.
    let eigenvalues = mp.complex_eigenvalues();
    let mut best: Option<(f64, Vector3<f64>)> = None;
    for lambda in eigenvalues.iter().map(|z| z.re) {
        let Some(a) = null_vector(&(mp - Matrix3::identity() * lambda)) else {
            continue;
        };
        let c = ellipticity(&a);
        if !(c > 1e-12 * a.norm_squared()) {
            continue;
        }
        // Constrained cost aᵀMa / aᵀC₁a: the true eigenvector minimises it over all a with
        // aᵀC₁a > 0, so an inaccurate candidate can never win over it.
        let cost = a.dot(&(m * a)) / c;
        if best.as_ref().is_none_or(|(b, _)| cost < *b) {
            best = Some((cost, a));
        }
    }
    let Some((_, a1)) = best else {
        return Err(DetectError::Degenerate {
            reason: format!(
                "no elliptic solution among the eigenvectors of the reduced scatter (eigenvalues {:?}) \
                 of the {} points",
                eigenvalues.iter().map(|z| z.re).collect::<Vec<_>>(),
                prep.centred.len()
            ),
        });
    };
    let conic = coefficients(prep, &a1);
    reject_hyperbolic(prep, &conic)?;
    let en = Ellipse::from_coefficients(&conic).map_err(|e| DetectError::Degenerate {
        reason: format!("the ellipse-specific conic fit is not a real ellipse: {e}"),
    })?;
    let s = prep.scale;
    Ellipse::new(en.cx * s, en.cy * s, en.a * s, en.b * s, en.theta).map_err(DetectError::from)
}

/// All six conic coefficients (normalised coordinates) from the quadratic part.
fn coefficients(prep: &Prepared, a1: &Vector3<f64>) -> [f64; 6] {
    let a2 = prep.t * a1;
    [a1[0], a1[1], a1[2], a2[0], a2[1], a2[2]]
}

/// A unit null vector of a (numerically) rank-2 3×3 matrix: the longest cross product of two
/// of its rows.
fn null_vector(b: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let rows = [
        b.row(0).transpose(),
        b.row(1).transpose(),
        b.row(2).transpose(),
    ];
    let candidates = [
        rows[0].cross(&rows[1]),
        rows[0].cross(&rows[2]),
        rows[1].cross(&rows[2]),
    ];
    let v = candidates
        .into_iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))?;
    let n = v.norm();
    (n > 0.0 && n.is_finite()).then(|| v / n)
}

/// RMS Sampson distance `|f|/‖∇f‖` of the normalised points to a conic.
fn rms_sampson(prep: &Prepared, c: &[f64; 6]) -> f64 {
    let inv = 1.0 / prep.scale;
    let [a, b, cc, d, e, f] = *c;
    let sum: f64 = prep
        .centred
        .iter()
        .map(|p| {
            let (x, y) = (p.x * inv, p.y * inv);
            let val = a * x * x + b * x * y + cc * y * y + d * x + e * y + f;
            let gx = 2.0 * a * x + b * y + d;
            let gy = b * x + 2.0 * cc * y + e;
            let g2 = gx * gx + gy * gy;
            if g2 > 0.0 {
                val * val / g2
            } else {
                f64::INFINITY
            }
        })
        .sum();
    (sum / prep.centred.len() as f64).sqrt()
}

/// Rejects point sets that a hyperbola or a line pair explains much better than any ellipse.
fn reject_hyperbolic(prep: &Prepared, ellipse_conic: &[f64; 6]) -> Result<()> {
    let eig = SymmetricEigen::new(prep.m);
    let k = eig.eigenvalues.imin();
    let u: Vector3<f64> = eig.eigenvectors.column(k).into_owned();
    let c = ellipticity(&u);
    if c > 0.0 {
        return Ok(());
    }
    let free = coefficients(prep, &u);
    let r_free = rms_sampson(prep, &free);
    let r_ellipse = rms_sampson(prep, ellipse_conic);
    if r_ellipse > HYPERBOLA_RATIO * r_free {
        let kind = if c == 0.0 {
            "a parabola or parallel lines"
        } else {
            "a hyperbola or a pair of lines"
        };
        return Err(DetectError::Degenerate {
            reason: format!(
                "the {} points lie on {kind}, not an ellipse: RMS Sampson distance {:.3e} px for the \
                 best conic (4AC − B² = {c:.3e}) against {:.3e} px for the best ellipse",
                prep.centred.len(),
                r_free * prep.scale,
                r_ellipse * prep.scale
            ),
        });
    }
    Ok(())
}

/// Taubin's (1991) algebraic fit in the centred pixel frame of `prep`, or `None` when its conic
/// is not a real ellipse (then the caller keeps the ellipse-specific [`solve`]).
///
/// Minimises `Σ f(xᵢ)² / Σ ‖∇f(xᵢ)‖²` over the conic `f = q·z`, `z = [x², xy, y², x, y, 1]`
/// (eq. 3.3 of 000_3b1454b2b2194811.txt written out): the first-order (Sampson) distance with
/// one common gradient normalisation, a generalised eigenproblem `S q = λ N q`. Unlike the
/// ellipse-specific constraint `4AC − B² = 1`, which pulls partial arcs toward small, round
/// ellipses, Taubin's normalisation removes the leading bias term (Kanatani's "essential
/// bias" remains; Al-Sharadqah & Chernov 2009): on arcs of 90–160° it starts the geometric fit
/// a fraction of a standard deviation from its optimum, where the fit-specific start is several
/// off.
///
/// Built from the scatter blocks of [`Prepared`] (no pass over the points): `F` is eliminated
/// (`F = −Σzᵢ·q̃/n` for `q̃ = (A, B, C, D, E)`), leaving the centred 5×5 scatter `S₅`, and with
/// `∇z = [2x, y, 0, 1, 0]`, `[0, x, 2y, 0, 1]` the normaliser `N₅ = Σ ∇zᵢ∇zᵢᵀ` holds only
/// moments up to order 2. `N₅ = LLᵀ` (positive definite for non-collinear points), and `q̃`
/// is `L⁻ᵀ` times the eigenvector of the least eigenvalue of `L⁻¹S₅L⁻ᵀ`.
pub(crate) fn taubin(prep: &Prepared) -> Option<Ellipse> {
    use nalgebra::{Matrix5, Vector5};
    let [s1, s2, s3] = &prep.scatter;
    // Full 6×6 scatter entry (i, j) of z = [z₁; z₂].
    let s = |i: usize, j: usize| -> f64 {
        match (i < 3, j < 3) {
            (true, true) => s1[(i, j)],
            (true, false) => s2[(i, j - 3)],
            (false, true) => s2[(j, i - 3)],
            (false, false) => s3[(i - 3, j - 3)],
        }
    };
    let n = s(5, 5);
    let s5 = Matrix5::from_fn(|i, j| s(i, j) - s(i, 5) * s(j, 5) / n);
    let (sx, sy, sxx, sxy, syy) = (s(3, 5), s(4, 5), s(3, 3), s(3, 4), s(4, 4));
    #[rustfmt::skip]
    let n5 = Matrix5::new(
        4.0 * sxx, 2.0 * sxy, 0.0, 2.0 * sx, 0.0,
        2.0 * sxy, sxx + syy, 2.0 * sxy, sy, sx,
        0.0, 2.0 * sxy, 4.0 * syy, 0.0, 2.0 * sy,
        2.0 * sx, sy, 0.0, n, 0.0,
        0.0, sx, 2.0 * sy, 0.0, n,
    );
    let l = n5.cholesky()?.l();
    let l_inv = l.try_inverse()?;
    let c = l_inv * s5 * l_inv.transpose();
    let eig = nalgebra::SymmetricEigen::new((c + c.transpose()) * 0.5);
    let k = eig.eigenvalues.imin();
    let y: Vector5<f64> = eig.eigenvectors.column(k).into_owned();
    let q5 = l_inv.transpose() * y;
    let f = -(0..5).map(|i| s(i, 5) * q5[i]).sum::<f64>() / n;
    let conic = [q5[0], q5[1], q5[2], q5[3], q5[4], f];
    let en = Ellipse::from_coefficients(&conic).ok()?;
    let sc = prep.scale;
    Ellipse::new(en.cx * sc, en.cy * sc, en.a * sc, en.b * sc, en.theta).ok()
}
