//! Ellipses and conics (000_3b1454b2b2194811.txt ch. 3.2, eq. 3.1–3.3) and the image conic of
//! a 3D circle — a wafer rim — seen by a calibrated pinhole camera (eq. 5.13).
//!
//! An [`Ellipse`] is stored by its geometric parameters `(cx, cy, a, b, θ)` of eq. (3.1)/(3.2)
//! with `a ≥ b > 0` and `θ ∈ (−π/2, π/2]`. Its conic matrix [`Ellipse::conic`] has the exact
//! scaling of eq. (3.3), `C = Tᵀ·diag(Qᵀ, 1)·diag(a⁻², b⁻², −1)·diag(Q, 1)·T`, so that
//! `pᵀCp = −1` at the centre, `0` on the curve and is negative inside.
//!
//! Distances from a point to the ellipse come in three flavours: the algebraic value of
//! eq. (3.3), the first-order geometric (Sampson) distance, and the true signed Euclidean
//! (orthogonal) distance computed by a safeguarded root finder that is exact for every point,
//! including the centre and points on the axes.
//!
//! [`circle_image_conic`] builds the conic `C = H⁻ᵀ·C₀·H⁻¹` of eq. (5.13), `H = K·[r₁ r₂ t]`,
//! `C₀ = diag(1, 1, −r²)`, of a circle of radius `r` in the `z = 0` plane of an object (wafer)
//! frame, and [`circle_image_conic_jacobian`] / [`project_circle_jacobian`] give its analytic
//! derivatives with respect to a right perturbation `T_co ⊕ δ = T_co·Exp(δ)`, `δ = [ω; ρ]`.
//!
//! ```
//! use autoteach_geometry::conic::{project_circle, Ellipse};
//! use nalgebra::{Isometry3, Matrix3, Vector2, Vector3};
//! # fn main() -> Result<(), autoteach_geometry::GeometryError> {
//! let e = Ellipse::new(320.0, 240.0, 100.0, 50.0, 0.3)?;
//! // Any scale and sign of the conic matrix describes the same ellipse.
//! let back = Ellipse::from_conic(&(e.conic() * -7.0))?;
//! assert!((back.a - 100.0).abs() < 1e-9 && (back.theta - 0.3).abs() < 1e-12);
//! // The centre is one semi-minor axis inside the curve.
//! let d = e.orthogonal_distance(&Vector2::new(320.0, 240.0));
//! assert!((d + 50.0).abs() < 1e-12);
//!
//! // A 300 mm wafer rim (r = 0.15 m) half a metre in front of the camera, tilted by 0.4 rad.
//! let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
//! let t_co = Isometry3::new(Vector3::new(0.0, 0.0, 0.5), Vector3::new(0.4, 0.0, 0.0));
//! let img = project_circle(&k, &t_co, 0.15)?;
//! // The image of a rim point lies on the projected ellipse.
//! let x = t_co * nalgebra::Point3::new(0.15, 0.0, 0.0);
//! let p = Vector2::new(800.0 * x.x / x.z + 320.0, 800.0 * x.y / x.z + 240.0);
//! assert!(img.orthogonal_distance(&p).abs() < 1e-9);
//! # Ok(())
//! # }
//! ```

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{
    Isometry3, Matrix2, Matrix3, Matrix5x6, Rotation3, Translation3, UnitQuaternion, Vector2,
    Vector3,
};
use rayon::prelude::*;

use crate::error::check_finite;
use crate::{GeometryError, Result};

/// Relative tolerance below which the quadratic part `M` of a conic counts as singular
/// (parabola or parallel lines): `det M / (‖M‖²_F / 2) = 2λ₁λ₂/(λ₁² + λ₂²)`, about `2(b/a)²`
/// for an ellipse, so ellipses with an aspect ratio above ~10⁶ are rejected as parabolic.
const PARABOLIC_TOL: f64 = 1e-12;
/// Relative tolerance for rank deficiency: `|det C|` against the product of its column norms,
/// and the value at the centre against the terms it is computed from.
const RANK_TOL: f64 = 1e-12;
/// Relative gap `(a − b)/a` below which the orientation of an ellipse is treated as undefined
/// by the functions that differentiate it.
const CIRCULAR_TOL: f64 = 1e-9;
/// Batches at least this long are processed in parallel.
const PAR_MIN: usize = 4096;

/// An ellipse in the image plane, eq. (3.1)/(3.2): centre `(cx, cy)`, semi-axes `a ≥ b > 0`
/// and orientation `theta` (radians, of the `a` axis from the x axis, in `(-π/2, π/2]`).
///
/// Build it with [`Ellipse::new`] (which validates and canonicalises). The fields are public
/// for reading; every method is panic-free even for hand-made values, but only meaningful for
/// the canonical form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipse {
    /// Centre x (pixels).
    pub cx: f64,
    /// Centre y (pixels).
    pub cy: f64,
    /// Semi-major axis.
    pub a: f64,
    /// Semi-minor axis.
    pub b: f64,
    /// Orientation of the major axis.
    pub theta: f64,
}

/// Wraps an angle into `(−π/2, π/2]` (an axis direction is defined modulo π).
pub fn wrap_half_pi(theta: f64) -> f64 {
    let mut t = theta.rem_euclid(PI); // [0, π], π possible by rounding
    if t > FRAC_PI_2 {
        t -= PI;
    }
    if t <= -FRAC_PI_2 {
        t += PI;
    }
    t
}

/// Symmetric part `(X + Xᵀ)/2`.
fn sym(m: &Matrix3<f64>) -> Matrix3<f64> {
    (m + m.transpose()) * 0.5
}

/// Formats a slice of numbers compactly for error messages.
fn fmt_values(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:.6e}")).collect();
    format!("[{}]", parts.join(", "))
}

/// Unit-norm coefficients `[A, B, C, D, E, F]` of `Ax² + Bxy + Cy² + Dx + Ey + F` for a
/// symmetric conic matrix.
fn coefficients_of(c: &Matrix3<f64>) -> [f64; 6] {
    let v = [
        c[(0, 0)],
        2.0 * c[(0, 1)],
        c[(1, 1)],
        2.0 * c[(0, 2)],
        2.0 * c[(1, 2)],
        c[(2, 2)],
    ];
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 && n.is_finite() {
        v.map(|x| x / n)
    } else {
        v
    }
}

/// Everything `from_conic` learns about a conic, reused by the gradient.
struct ConicAnalysis {
    ellipse: Ellipse,
    /// Inverse of the quadratic part `M` of the conic scaled to unit Frobenius norm with `M`
    /// positive definite (`cn` below).
    m_inv: Matrix2<f64>,
    /// Value of `cn` at the centre, `f₀ = ĉᵀ·cn·ĉ` (negative).
    f0: f64,
    /// Eigenvalues `1/a²`, `1/b²` of `−M/f0`.
    lambda: (f64, f64),
    /// d(cn)/d(input) is `factor·(dC − cn⟨cn, dC⟩)`; the gradient of a scale-invariant function
    /// with respect to the input is `factor` times its gradient with respect to `cn`.
    factor: f64,
}

/// Classifies a conic and, if it is a real non-degenerate ellipse, extracts its parameters
/// (inverse of eq. 3.3).
fn analyse(c: &Matrix3<f64>) -> Result<ConicAnalysis> {
    check_finite("conic matrix", c.as_slice())?;
    let cs = sym(c);
    let amax = cs.amax();
    if amax == 0.0 {
        return Err(GeometryError::DegenerateConic {
            reason: "the conic matrix is zero".into(),
        });
    }
    let c1 = cs / amax;
    let n1 = c1.norm();
    let mut cn = c1 / n1;
    let coeffs = coefficients_of(&cn);
    let det_m = cn[(0, 0)] * cn[(1, 1)] - cn[(0, 1)] * cn[(0, 1)];
    let m_sq = cn[(0, 0)].powi(2) + cn[(1, 1)].powi(2) + 2.0 * cn[(0, 1)].powi(2);
    let disc = -4.0 * det_m; // B² − 4AC of the unit-Frobenius matrix
    let det_c = cn.determinant();
    let col_prod = cn.column(0).norm() * cn.column(1).norm() * cn.column(2).norm();
    let rank_deficient = det_c.abs() <= RANK_TOL * col_prod;
    // Built only on the error paths (this runs on every fit of the detector's hot loops).
    let numbers = || {
        format!(
            "discriminant B²−4AC = {disc:.6e}, det C = {det_c:.6e} (unit-Frobenius matrix), \
             coefficients [A, B, C, D, E, F] = {}",
            fmt_values(&coeffs)
        )
    };
    if m_sq == 0.0 {
        return Err(GeometryError::DegenerateConic {
            reason: format!(
                "no quadratic part (a line or the line at infinity): {}",
                numbers()
            ),
        });
    }
    let rho = det_m / (0.5 * m_sq);
    if rho < -PARABOLIC_TOL {
        let what = if rank_deficient {
            "a pair of intersecting lines, not an ellipse"
        } else {
            "a hyperbola, not an ellipse"
        };
        return Err(GeometryError::DegenerateConic {
            reason: format!("{what}: {}", numbers()),
        });
    }
    if rho <= PARABOLIC_TOL {
        let what = if rank_deficient {
            "a pair of parallel or coincident lines, not an ellipse"
        } else {
            "a parabola (or an ellipse with aspect ratio above ~1e6), not an ellipse"
        };
        return Err(GeometryError::DegenerateConic {
            reason: format!("{what}: {}", numbers()),
        });
    }
    let sigma = if cn[(0, 0)] + cn[(1, 1)] > 0.0 {
        1.0
    } else {
        -1.0
    };
    cn *= sigma;
    let (m00, m01, m11) = (cn[(0, 0)], cn[(0, 1)], cn[(1, 1)]);
    let m_inv = Matrix2::new(m11, -m01, -m01, m00) / det_m;
    let g = Vector2::new(cn[(0, 2)], cn[(1, 2)]);
    let centre = -(m_inv * g);
    let gc = g.dot(&centre);
    let f0 = cn[(2, 2)] + gc;
    if f0.abs() <= RANK_TOL * (cn[(2, 2)].abs() + gc.abs()) {
        return Err(GeometryError::DegenerateConic {
            reason: format!(
                "a point ellipse at ({:.6e}, {:.6e}) (rank-deficient, value at the centre {f0:.3e}): {}",
                centre.x,
                centre.y,
                numbers()
            ),
        });
    }
    if f0 > 0.0 {
        return Err(GeometryError::DegenerateConic {
            reason: format!(
                "an imaginary ellipse (no real points: value at the centre {f0:.6e} has the sign \
                 of the quadratic part): {}",
                numbers()
            ),
        });
    }
    // Shape matrix N = −M/f0 has eigenvalues 1/a² ≤ 1/b².
    let s = -1.0 / f0;
    let (n00, n01, n11) = (m00 * s, m01 * s, m11 * s);
    let half_diff = 0.5 * (n00 - n11);
    let lambda2 = 0.5 * (n00 + n11) + half_diff.hypot(n01);
    let lambda1 = det_m * s * s / lambda2;
    let theta = 0.5 * (-2.0 * n01).atan2(n11 - n00);
    let ellipse = Ellipse::new(
        centre.x,
        centre.y,
        1.0 / lambda1.sqrt(),
        1.0 / lambda2.sqrt(),
        theta,
    )
    .map_err(|e| GeometryError::DegenerateConic {
        reason: format!(
            "ellipse parameters are not representable ({e}): {}",
            numbers()
        ),
    })?;
    Ok(ConicAnalysis {
        ellipse,
        m_inv,
        f0,
        lambda: (lambda1, lambda2),
        factor: sigma / (amax * n1),
    })
}

/// Closest point on the axis-aligned ellipse `(x/e0)² + (y/e1)² = 1` to `(y0, y1)`, in that
/// frame. Eberly, "Distance from a point to an ellipse, an ellipsoid, or a hyperellipsoid"
/// (2013): reduction to the first quadrant and a monotone 1-D root, here in the variable
/// `t = s + 1` (bracketed Newton with geometric bisection) so that points arbitrarily close to
/// the major axis keep full relative precision.
fn closest_in_frame(e0: f64, e1: f64, y0: f64, y1: f64) -> (f64, f64) {
    if !(y0.is_finite() && y1.is_finite() && e0.is_finite() && e1.is_finite()) {
        return (f64::NAN, f64::NAN);
    }
    if e0 < e1 {
        let (x1, x0) = closest_in_frame(e1, e0, y1, y0);
        return (x0, x1);
    }
    let (ay0, ay1) = (y0.abs(), y1.abs());
    let z0 = ay0 / e0;
    let z1 = ay1 / e1;
    let (x0, x1) = if z1 > 0.0 {
        if z0 > 0.0 {
            let g = z0 * z0 + z1 * z1 - 1.0;
            if g == 0.0 {
                (ay0, ay1)
            } else {
                let r0 = (e0 / e1) * (e0 / e1);
                let d = (e0 - e1) * (e0 + e1) / (e1 * e1);
                let n0 = r0 * z0;
                let t = root_t(n0, z1, d, g);
                (r0 * ay0 / (t + d), ay1 / t)
            }
        } else {
            (0.0, e1)
        }
    } else {
        let numer0 = e0 * ay0;
        let denom0 = (e0 - e1) * (e0 + e1);
        if numer0 < denom0 {
            let xde0 = numer0 / denom0;
            (e0 * xde0, e1 * ((1.0 - xde0) * (1.0 + xde0)).sqrt())
        } else {
            (e0, 0.0)
        }
    };
    (x0.copysign(y0), x1.copysign(y1))
}

/// Root `t > 0` of `F(t) = (n0/(t + d))² + (z1/t)² − 1` (convex and decreasing on t > 0) for
/// finite `z1 > 0`, `n0 > 0`, `d ≥ 0`; `g = F(1)` tells whether the point is inside (`g < 0`).
fn root_t(n0: f64, z1: f64, d: f64, g: f64) -> f64 {
    let f = |t: f64| {
        let p = n0 / (t + d);
        let q = z1 / t;
        p * p + q * q - 1.0
    };
    // Each term is ≤ 1 at the root, so t ≥ z1 and t ≥ n0 − d; F(‖(n0, z1)‖) ≤ 0 bounds it
    // above. F(1) = g is known: outside (g > 0) the root is beyond 1; inside, 1 is an upper
    // end and, F being convex, the Newton step from it lands at or left of the root — a tight
    // lower end for points near the curve.
    let mut lo = z1.max(n0 - d);
    let mut hi = n0.hypot(z1);
    if g > 0.0 {
        lo = lo.max(1.0);
    } else {
        hi = hi.min(1.0);
        let p = n0 / (1.0 + d);
        let slope = 2.0 * (p * p / (1.0 + d) + z1 * z1); // −F'(1)
        lo = lo.max(1.0 + g / slope);
    }
    if lo >= hi {
        return lo.min(hi);
    }
    let mut f_lo = f(lo);
    for _ in 0..256 {
        if f_lo <= 0.0 {
            return lo;
        }
        // Newton from the left end never overshoots the root of a convex decreasing function.
        let p = n0 / (lo + d);
        let q = z1 / lo;
        let slope = 2.0 * (p * p / (lo + d) + q * q / lo); // −F'(lo) > 0
        let step = f_lo / slope;
        let newton = lo + step;
        // In exact arithmetic lo < newton ≤ root ≤ hi. A step of a few ulps (step/lo ≥
        // F/(2(F + 1)), so F(lo) is at rounding level), a Newton point at or past `hi`, or one
        // where F ≤ 0 can only come from rounding: the iterate is the root to rounding.
        if step <= 4.0 * f64::EPSILON * lo || newton >= hi {
            return newton.min(hi);
        }
        let f_n = f(newton);
        if f_n <= 0.0 {
            return newton;
        }
        let slow = f_n > 0.25 * f_lo;
        lo = newton;
        f_lo = f_n;
        if slow {
            let mid = if hi > 4.0 * lo {
                lo.sqrt() * hi.sqrt() // geometric mean; lo·hi itself may underflow
            } else {
                0.5 * (lo + hi)
            };
            if mid <= lo || mid >= hi {
                return lo;
            }
            let f_m = f(mid);
            if f_m > 0.0 {
                lo = mid;
                f_lo = f_m;
            } else if f_m == 0.0 {
                return mid;
            } else {
                hi = mid;
            }
        }
        if hi - lo <= 2.0 * f64::EPSILON * hi {
            return lo;
        }
    }
    lo
}

/// Precomputed frame of an ellipse: centre, major-axis direction and semi-axes.
#[derive(Clone, Copy)]
struct Frame {
    cx: f64,
    cy: f64,
    cos: f64,
    sin: f64,
    a: f64,
    b: f64,
}

impl Frame {
    fn of(e: &Ellipse) -> Self {
        let (sin, cos) = e.theta.sin_cos();
        Frame {
            cx: e.cx,
            cy: e.cy,
            cos,
            sin,
            a: e.a,
            b: e.b,
        }
    }

    /// Coordinates of `p` along the major and minor axes (`Q·(p − c)` of eq. 3.3).
    fn local(&self, p: &Vector2<f64>) -> (f64, f64) {
        let dx = p.x - self.cx;
        let dy = p.y - self.cy;
        (
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }

    fn global(&self, u: f64, v: f64) -> Vector2<f64> {
        Vector2::new(
            self.cx + self.cos * u - self.sin * v,
            self.cy + self.sin * u + self.cos * v,
        )
    }

    fn algebraic(&self, p: &Vector2<f64>) -> f64 {
        let (u, v) = self.local(p);
        let (s, t) = (u / self.a, v / self.b);
        s * s + t * t - 1.0
    }

    fn sampson(&self, p: &Vector2<f64>) -> f64 {
        let (u, v) = self.local(p);
        let f = (u / self.a).powi(2) + (v / self.b).powi(2) - 1.0;
        let grad = (2.0 * u / (self.a * self.a)).hypot(2.0 * v / (self.b * self.b));
        if grad == 0.0 {
            f64::INFINITY
        } else {
            f.abs() / grad
        }
    }

    fn closest(&self, p: &Vector2<f64>) -> ((f64, f64), (f64, f64)) {
        let (u, v) = self.local(p);
        ((u, v), closest_in_frame(self.a, self.b, u, v))
    }

    fn orthogonal(&self, p: &Vector2<f64>) -> f64 {
        let ((u, v), (x0, x1)) = self.closest(p);
        let d = (u - x0).hypot(v - x1);
        if (u / self.a).powi(2) + (v / self.b).powi(2) < 1.0 {
            -d
        } else {
            d
        }
    }
}

/// Applies `f` to every point, in parallel for long batches.
fn batch<T: Send>(points: &[Vector2<f64>], f: impl Fn(&Vector2<f64>) -> T + Sync + Send) -> Vec<T> {
    if points.len() >= PAR_MIN {
        points.par_iter().map(f).collect()
    } else {
        points.iter().map(f).collect()
    }
}

/// The conic matrix `[[N, −Nc], [−cᵀN, cᵀNc − 1]]` of eq. (3.3) and its variation for a
/// change `dn` of the shape matrix and `dc` of the centre.
fn assemble(
    n: &Matrix2<f64>,
    c: &Vector2<f64>,
    dn: &Matrix2<f64>,
    dc: &Vector2<f64>,
) -> Matrix3<f64> {
    let top = -(dn * c) - n * dc;
    let corner = c.dot(&(dn * c)) + 2.0 * c.dot(&(n * dc));
    Matrix3::new(
        dn[(0, 0)],
        dn[(0, 1)],
        top.x,
        dn[(1, 0)],
        dn[(1, 1)],
        top.y,
        top.x,
        top.y,
        corner,
    )
}

impl Ellipse {
    /// Builds an ellipse of eq. (3.1)/(3.2), validating that all values are finite and
    /// `a, b > 0`, and canonicalising: if `a < b` the axes are swapped and `theta` rotated by
    /// π/2; `theta` is then wrapped into `(−π/2, π/2]`.
    pub fn new(cx: f64, cy: f64, a: f64, b: f64, theta: f64) -> Result<Ellipse> {
        check_finite(
            "ellipse parameters (cx, cy, a, b, theta)",
            &[cx, cy, a, b, theta],
        )?;
        for (what, value) in [("a", a), ("b", b)] {
            if value <= 0.0 {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value,
                    reason: "a semi-axis must be positive",
                });
            }
        }
        let (a, b, theta) = if a < b {
            (b, a, theta + FRAC_PI_2)
        } else {
            (a, b, theta)
        };
        Ok(Ellipse {
            cx,
            cy,
            a,
            b,
            theta: wrap_half_pi(theta),
        })
    }

    /// The symmetric conic matrix `C` of eq. (3.3) with its exact scaling:
    /// `C = Tᵀ·diag(Qᵀ, 1)·diag(a⁻², b⁻², −1)·diag(Q, 1)·T`, where `T` translates the centre to
    /// the origin and `Q` rotates by `−θ`. So `pᵀCp` (with `p = [x, y, 1]ᵀ`) is `−1` at the
    /// centre, negative inside, zero on the curve and positive outside.
    pub fn conic(&self) -> Matrix3<f64> {
        // [[N, −Nc], [−cᵀN, cᵀNc]] is the variation of the shape term for dN = N; the −1 of
        // diag(a⁻², b⁻², −1) completes eq. (3.3).
        let (n, c) = self.shape();
        let mut m = assemble(&n, &c, &n, &Vector2::zeros());
        m[(2, 2)] -= 1.0;
        m
    }

    /// Shape matrix `N = R·diag(a⁻², b⁻²)·Rᵀ` and centre.
    fn shape(&self) -> (Matrix2<f64>, Vector2<f64>) {
        let (s, c) = self.theta.sin_cos();
        let u1 = Vector2::new(c, s);
        let u2 = Vector2::new(-s, c);
        let n = u1 * u1.transpose() / (self.a * self.a) + u2 * u2.transpose() / (self.b * self.b);
        (n, Vector2::new(self.cx, self.cy))
    }

    /// Derivatives of [`Ellipse::conic`] (eq. 3.3) with respect to `(cx, cy, a, b, theta)`,
    /// in that order — what a fitter in ellipse parameters needs.
    pub fn conic_jacobian(&self) -> [Matrix3<f64>; 5] {
        let (n, c) = self.shape();
        let (s, co) = self.theta.sin_cos();
        let u1 = Vector2::new(co, s);
        let u2 = Vector2::new(-s, co);
        let z = Matrix2::zeros();
        let dn_a = u1 * u1.transpose() * (-2.0 / self.a.powi(3));
        let dn_b = u2 * u2.transpose() * (-2.0 / self.b.powi(3));
        let dn_t = (u1 * u2.transpose() + u2 * u1.transpose())
            * (1.0 / (self.a * self.a) - 1.0 / (self.b * self.b));
        [
            assemble(&n, &c, &z, &Vector2::new(1.0, 0.0)),
            assemble(&n, &c, &z, &Vector2::new(0.0, 1.0)),
            assemble(&n, &c, &dn_a, &Vector2::zeros()),
            assemble(&n, &c, &dn_b, &Vector2::zeros()),
            assemble(&n, &c, &dn_t, &Vector2::zeros()),
        ]
    }

    /// Coefficients `[A, B, C, D, E, F]` of `Ax² + Bxy + Cy² + Dx + Ey + F = 0` (the conic of
    /// eq. 3.3 written out), scaled to unit Euclidean norm, with the sign of eq. (3.3)
    /// (negative inside, `A + C > 0`).
    pub fn conic_coefficients(&self) -> [f64; 6] {
        coefficients_of(&self.conic())
    }

    /// The ellipse of a conic matrix (inverse of eq. 3.3). Any non-zero scale and either sign
    /// are accepted, and only the symmetric part `(C + Cᵀ)/2` is used.
    ///
    /// Errors: [`GeometryError::NonFinite`] for NaN/∞ entries, and
    /// [`GeometryError::DegenerateConic`] — naming the kind and quoting the discriminant
    /// `B² − 4AC` and `det C` — for hyperbolas, parabolas, line pairs, point ellipses,
    /// imaginary ellipses and the zero matrix.
    pub fn from_conic(c: &Matrix3<f64>) -> Result<Ellipse> {
        Ok(analyse(c)?.ellipse)
    }

    /// [`Ellipse::from_conic`] plus the gradient of each parameter `(cx, cy, a, b, theta)`
    /// with respect to the entries of `c`: a symmetric matrix `G_k` per parameter with
    /// `d p_k = Σᵢⱼ G_k[i, j]·dC[i, j]` for a symmetric change `dC`.
    ///
    /// Derived from `c = −M⁻¹g`, `f₀ = ĉᵀCĉ` (value at the centre, `ĉ = [c; 1]`), and the
    /// eigen-decomposition of `N = −M/f₀` (eigenvalues `a⁻²`, `b⁻²`; eigenvector perturbation
    /// for `θ`). Errors as `from_conic`, plus [`GeometryError::DegenerateConic`] when
    /// `(a − b)/a ≤ 1e-9`, where `θ` is undefined.
    pub fn from_conic_with_gradient(c: &Matrix3<f64>) -> Result<(Ellipse, [Matrix3<f64>; 5])> {
        let an = analyse(c)?;
        let e = an.ellipse;
        if e.a - e.b <= CIRCULAR_TOL * e.a {
            return Err(GeometryError::DegenerateConic {
                reason: format!(
                    "nearly circular ellipse (a = {:.6e}, b = {:.6e}): its orientation theta and \
                     the derivative of theta are undefined",
                    e.a, e.b
                ),
            });
        }
        let (l1, l2) = an.lambda;
        let f0 = an.f0;
        let (s, co) = e.theta.sin_cos();
        let ch = Vector3::new(e.cx, e.cy, 1.0);
        let u1 = Vector3::new(co, s, 0.0);
        let u2 = Vector3::new(-s, co, 0.0);
        let cc = ch * ch.transpose();
        let centre_grad = |col: usize| {
            let w = an.m_inv.column(col);
            let wh = Vector3::new(w[0], w[1], 0.0);
            -sym(&(wh * ch.transpose()))
        };
        let g_a = (u1 * u1.transpose() + cc * l1) * (e.a.powi(3) / (2.0 * f0));
        let g_b = (u2 * u2.transpose() + cc * l2) * (e.b.powi(3) / (2.0 * f0));
        let g_t = -sym(&(u2 * u1.transpose())) / (f0 * (l1 - l2));
        let k = an.factor;
        Ok((
            e,
            [
                centre_grad(0) * k,
                centre_grad(1) * k,
                g_a * k,
                g_b * k,
                g_t * k,
            ],
        ))
    }

    /// The ellipse of `Ax² + Bxy + Cy² + Dx + Ey + F = 0` (any scale and sign); see
    /// [`Ellipse::from_conic`] for the errors.
    pub fn from_coefficients(coeffs: &[f64; 6]) -> Result<Ellipse> {
        let [a, b, c, d, e, f] = *coeffs;
        Ellipse::from_conic(&Matrix3::new(
            a,
            0.5 * b,
            0.5 * d,
            0.5 * b,
            c,
            0.5 * e,
            0.5 * d,
            0.5 * e,
            f,
        ))
    }

    /// The point of eccentric angle `t` (radians), eq. (3.2):
    /// `p = c + R(θ)·[a·cos t, b·sin t]ᵀ`.
    pub fn point_at(&self, t: f64) -> Vector2<f64> {
        let (s, c) = t.sin_cos();
        Frame::of(self).global(self.a * c, self.b * s)
    }

    /// `n` points of eq. (3.2) at eccentric angles evenly spaced from `t0` to `t1`, both
    /// included. Errors: `n < 2` ([`GeometryError::InvalidParameter`]) or non-finite angles.
    pub fn sample(&self, n: usize, t0: f64, t1: f64) -> Result<Vec<Vector2<f64>>> {
        check_finite("arc parameters (t0, t1)", &[t0, t1])?;
        if n < 2 {
            return Err(GeometryError::InvalidParameter {
                what: "n",
                value: n as f64,
                reason: "an arc needs at least 2 sample points (both ends are included)",
            });
        }
        let step = (t1 - t0) / (n - 1) as f64;
        // A fallible reservation: a huge n is an error, not a capacity-overflow panic or an abort.
        let mut out = crate::alloc::try_with_capacity("the n ellipse sample points", n)?;
        out.extend((0..n).map(|i| {
            let t = if i + 1 == n { t1 } else { t0 + step * i as f64 };
            self.point_at(t)
        }));
        Ok(out)
    }

    /// Eccentric angle `t ∈ (−π, π]` (eq. 3.2) of the point of the ellipse closest to `p`.
    pub fn parameter_of(&self, p: &Vector2<f64>) -> f64 {
        let (_, (x0, x1)) = Frame::of(self).closest(p);
        (x1 / self.b).atan2(x0 / self.a)
    }

    /// Algebraic distance `pᵀCp` with the scaling of eq. (3.3), `p = [x, y, 1]ᵀ`: equal to
    /// `(u/a)² + (v/b)² − 1` in the ellipse frame (eq. 3.1), evaluated there for accuracy.
    pub fn algebraic_distance(&self, p: &Vector2<f64>) -> f64 {
        Frame::of(self).algebraic(p)
    }

    /// Sampson distance `|f|/‖∇f‖` with `f` the algebraic distance of eq. (3.3): the
    /// first-order approximation of the (unsigned) orthogonal distance, accurate near the
    /// curve. It is `+∞` at the centre, where `∇f = 0`.
    pub fn sampson_distance(&self, p: &Vector2<f64>) -> f64 {
        Frame::of(self).sampson(p)
    }

    /// Signed Euclidean distance from `p` to the ellipse (negative inside, eq. 3.1 < 0).
    /// Exact to rounding for every point, including the centre and points on the axes
    /// (Eberly's reduction to a monotone 1-D root, solved by bracketed Newton).
    pub fn orthogonal_distance(&self, p: &Vector2<f64>) -> f64 {
        Frame::of(self).orthogonal(p)
    }

    /// The point of the ellipse nearest to `p` (one of them when several are equally near,
    /// e.g. for the centre). See [`Ellipse::orthogonal_distance`].
    pub fn closest_point(&self, p: &Vector2<f64>) -> Vector2<f64> {
        let f = Frame::of(self);
        let (_, (x0, x1)) = f.closest(p);
        f.global(x0, x1)
    }

    /// [`Ellipse::algebraic_distance`] of every point.
    pub fn algebraic_distances(&self, points: &[Vector2<f64>]) -> Vec<f64> {
        let f = Frame::of(self);
        batch(points, |p| f.algebraic(p))
    }

    /// [`Ellipse::sampson_distance`] of every point.
    pub fn sampson_distances(&self, points: &[Vector2<f64>]) -> Vec<f64> {
        let f = Frame::of(self);
        batch(points, |p| f.sampson(p))
    }

    /// [`Ellipse::orthogonal_distance`] of every point (in parallel for long slices).
    pub fn orthogonal_distances(&self, points: &[Vector2<f64>]) -> Vec<f64> {
        let f = Frame::of(self);
        batch(points, |p| f.orthogonal(p))
    }

    /// [`Ellipse::closest_point`] of every point (in parallel for long slices).
    pub fn closest_points(&self, points: &[Vector2<f64>]) -> Vec<Vector2<f64>> {
        let f = Frame::of(self);
        batch(points, |p| {
            let (_, (x0, x1)) = f.closest(p);
            f.global(x0, x1)
        })
    }

    /// Area `π·a·b`.
    pub fn area(&self) -> f64 {
        PI * self.a * self.b
    }

    /// Perimeter, exact to rounding: Gauss–Kummer arithmetic-geometric-mean formula
    /// `P = 2π/AGM(a, b)·(a² − Σₙ 2ⁿ⁻¹cₙ²)`, `c₀² = a² − b²`, `cₙ₊₁ = (aₙ − gₙ)/2`.
    pub fn perimeter(&self) -> f64 {
        let (mut an, mut gn) = (self.a.max(self.b), self.a.min(self.b));
        let mut sum = 0.5 * (an - gn) * (an + gn);
        let mut pow = 0.5;
        let a2 = an * an;
        for _ in 0..64 {
            let c = 0.5 * (an - gn);
            if c <= f64::EPSILON * an * 1e-3 || !c.is_finite() {
                break;
            }
            let next_a = 0.5 * (an + gn);
            gn = (an * gn).sqrt();
            an = next_a;
            pow *= 2.0;
            sum += pow * c * c;
        }
        2.0 * PI * (a2 - sum) / an
    }

    /// Whether `p` lies inside or on the ellipse (algebraic distance ≤ 0).
    pub fn contains(&self, p: &Vector2<f64>) -> bool {
        self.algebraic_distance(p) <= 0.0
    }
}

/// Everything the circle-image functions share: `H⁻¹`, `U⁻¹` (with `G = [r₁ r₂ t] = R·U`) and
/// the unnormalised image conic `H⁻ᵀ·C₀·H⁻¹` of eq. (5.13).
struct CircleImage {
    h_inv: Matrix3<f64>,
    u_inv: Matrix3<f64>,
    c0: Matrix3<f64>,
    c_raw: Matrix3<f64>,
}

/// Validates a pinhole intrinsic matrix (finite, last row `(0, 0, k₃₃ > 0)`, invertible) and
/// returns its inverse.
fn intrinsics_inverse(k: &Matrix3<f64>) -> Result<Matrix3<f64>> {
    check_finite("intrinsic matrix K", k.as_slice())?;
    if k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 || k[(2, 2)] <= 0.0 {
        return Err(GeometryError::InvalidParameter {
            what: "K last row",
            value: k[(2, 2)],
            reason: "a pinhole intrinsic matrix must have last row (0, 0, k33 > 0)",
        });
    }
    let det = k.determinant();
    let scale = k.column(0).norm() * k.column(1).norm() * k.column(2).norm();
    match k.try_inverse() {
        Some(inv) if det.abs() > 1e-14 * scale && inv.iter().all(|v| v.is_finite()) => Ok(inv),
        _ => Err(GeometryError::InvalidParameter {
            what: "det K",
            value: det,
            reason: "the intrinsic matrix is singular",
        }),
    }
}

/// Builds `H⁻¹ = U⁻¹·Rᵀ·K⁻¹` for a circle of `radius` in the object frame's `z = 0` plane,
/// checking the radius, the pose, that the camera centre is off the circle's plane and that
/// the whole circle is in front of the camera (so its image is a real ellipse).
fn circle_image(k: &Matrix3<f64>, t_co: &Isometry3<f64>, radius: f64) -> Result<CircleImage> {
    let k_inv = intrinsics_inverse(k)?;
    check_finite("circle radius", &[radius])?;
    if radius <= 0.0 {
        return Err(GeometryError::InvalidParameter {
            what: "radius",
            value: radius,
            reason: "a circle radius must be positive",
        });
    }
    check_finite("pose T_co translation", t_co.translation.vector.as_slice())?;
    check_finite("pose T_co rotation", t_co.rotation.coords.as_slice())?;
    let r = t_co.rotation.to_rotation_matrix().into_inner();
    let t = t_co.translation.vector;
    // s = Rᵀt; s₂ = r₃·t is the signed distance of the camera centre from the circle plane.
    let s = r.transpose() * t;
    if s.z.abs() <= 1e-12 * (t.norm() + radius) {
        return Err(GeometryError::DegenerateConic {
            reason: format!(
                "the camera centre lies in the circle's plane (distance {:.3e} m, camera at \
                 {:.6e} m from the circle centre): H = K[r1 r2 t] is singular and the image is \
                 a line segment",
                s.z,
                t.norm()
            ),
        });
    }
    // Depth of the rim point φ: t_z + r(R₂₀cos φ + R₂₁sin φ); its minimum over φ.
    let hyp = r[(2, 0)].hypot(r[(2, 1)]);
    let z_min = t.z - radius * hyp;
    if z_min <= 0.0 {
        let (cphi, sphi) = if hyp > 0.0 {
            (-r[(2, 0)] / hyp, -r[(2, 1)] / hyp)
        } else {
            (1.0, 0.0)
        };
        let x = r * Vector3::new(radius * cphi, radius * sphi, 0.0) + t;
        let reason = if t.z + radius * hyp <= 0.0 {
            "the circle lies entirely behind the camera (this is its nearest rim point)"
        } else {
            "the circle crosses the camera's principal plane z = 0 (this is its deepest rim \
             point behind it): its image is not an ellipse"
        };
        return Err(GeometryError::NotProjectable {
            x: x.x,
            y: x.y,
            z: x.z,
            reason,
        });
    }
    let u_inv = Matrix3::new(
        1.0,
        0.0,
        -s.x / s.z,
        0.0,
        1.0,
        -s.y / s.z,
        0.0,
        0.0,
        1.0 / s.z,
    );
    let h_inv = u_inv * r.transpose() * k_inv;
    let c0 = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -radius * radius));
    let c_raw = sym(&(h_inv.transpose() * c0 * h_inv));
    Ok(CircleImage {
        h_inv,
        u_inv,
        c0,
        c_raw,
    })
}

/// Image conic of the circle `x² + y² = r²` in the `z = 0` plane of an object (wafer) frame,
/// seen by a pinhole camera with intrinsic matrix `k`; `t_co` maps object to camera
/// coordinates. Seed 000_3b1454b2b2194811.txt eq. (5.13): `H = K·[r₁ r₂ t]`,
/// `C = H⁻ᵀ·C₀·H⁻¹`, `C₀ = diag(1, 1, −r²)`.
///
/// Normalisation: `C` is scaled by a positive factor to unit Frobenius norm. A positive
/// factor keeps the sign of `H⁻ᵀC₀H⁻¹`, which (for a circle in front of the camera) has a
/// positive-definite upper-left 2×2 block: `pᵀCp` is negative inside the image ellipse,
/// zero on it and positive outside, like eq. (3.3) (which differs only by scale).
///
/// Errors: [`GeometryError::InvalidParameter`] for a non-positive radius or an invalid `K`,
/// [`GeometryError::NonFinite`], [`GeometryError::DegenerateConic`] when the camera centre
/// lies in the circle's plane (`H` singular), [`GeometryError::NotProjectable`] (with the
/// offending rim point in camera coordinates) when part of the circle is at or behind the
/// camera's principal plane.
pub fn circle_image_conic(
    k: &Matrix3<f64>,
    t_co: &Isometry3<f64>,
    radius: f64,
) -> Result<Matrix3<f64>> {
    let ci = circle_image(k, t_co, radius)?;
    Ok(ci.c_raw / ci.c_raw.norm())
}

/// [`circle_image_conic`] and `H⁻¹` (eq. (5.13), `H = K·[r₁ r₂ t]`), the map from the image to
/// the circle's plane: what a caller needs to find the circle angle of an image point.
/// Errors as [`circle_image_conic`].
pub fn circle_image_conic_and_inverse(
    k: &Matrix3<f64>,
    t_co: &Isometry3<f64>,
    radius: f64,
) -> Result<(Matrix3<f64>, Matrix3<f64>)> {
    let ci = circle_image(k, t_co, radius)?;
    Ok((ci.c_raw / ci.c_raw.norm(), ci.h_inv))
}

/// [`circle_image_conic`] and its derivatives with respect to a right perturbation of the
/// circle pose, `T_co ⊕ δ = T_co·Exp(δ)`, `δ = [ω; ρ]` (rotation first): element `i` of the
/// array is `∂C/∂δᵢ` at `δ = 0`.
///
/// Analytic, eq. (5.13): with `G = [r₁ r₂ t]` (`H = K·G`), `dR = R[ω]×` and `dt = Rρ` give
/// `dG = R·Bᵢ` with `Bᵢ = [eᵢ×e₁, eᵢ×e₂, 0]` for `ωᵢ` and `[0, 0, eᵢ]` for `ρᵢ`; then
/// `dH⁻¹ = −H⁻¹dH·H⁻¹ = −Aᵢ·H⁻¹` with `Aᵢ = G⁻¹dG = U⁻¹Bᵢ`, so
/// `dC_raw = −H⁻ᵀ(AᵢᵀC₀ + C₀Aᵢ)H⁻¹`; finally the unit-norm scaling contributes
/// `dC = (dC_raw − C⟨C, dC_raw⟩)/‖C_raw‖`.
pub fn circle_image_conic_jacobian(
    k: &Matrix3<f64>,
    t_co: &Isometry3<f64>,
    radius: f64,
) -> Result<(Matrix3<f64>, [Matrix3<f64>; 6])> {
    let ci = circle_image(k, t_co, radius)?;
    let norm = ci.c_raw.norm();
    let cn = ci.c_raw / norm;
    let e = [Vector3::x(), Vector3::y(), Vector3::z()];
    let mut out = [Matrix3::zeros(); 6];
    for (i, d) in out.iter_mut().enumerate() {
        let b = if i < 3 {
            let mut b = Matrix3::zeros();
            b.set_column(0, &e[i].cross(&e[0]));
            b.set_column(1, &e[i].cross(&e[1]));
            b
        } else {
            let mut b = Matrix3::zeros();
            b.set_column(2, &e[i - 3]);
            b
        };
        let a = ci.u_inv * b;
        let dc_raw = -(ci.h_inv.transpose() * (a.transpose() * ci.c0 + ci.c0 * a) * ci.h_inv);
        let dc_raw = sym(&dc_raw);
        *d = (dc_raw - cn * cn.dot(&dc_raw)) / norm;
    }
    Ok((cn, out))
}

/// The ellipse that a circle of `radius` (in the object frame's `z = 0` plane, centred at the
/// origin) projects to: [`Ellipse::from_conic`] of [`circle_image_conic`] (eq. 5.13 → 3.3).
pub fn project_circle(k: &Matrix3<f64>, t_co: &Isometry3<f64>, radius: f64) -> Result<Ellipse> {
    Ellipse::from_conic(&circle_image_conic(k, t_co, radius)?)
}

/// [`project_circle`] and the 5×6 Jacobian of `(cx, cy, a, b, theta)` with respect to the
/// right perturbation `δ = [ω; ρ]` of `t_co` (`T_co·Exp(δ)`).
///
/// Analytic, by composing [`circle_image_conic_jacobian`] with the gradient of the
/// conic → ellipse map ([`Ellipse::from_conic_with_gradient`]): `J[k][i] = ⟨G_k, ∂C/∂δᵢ⟩`.
/// Errors as [`project_circle`], plus [`GeometryError::DegenerateConic`] when the image is
/// nearly circular (`(a − b)/a ≤ 1e-9`), where `theta` and its derivative are undefined.
pub fn project_circle_jacobian(
    k: &Matrix3<f64>,
    t_co: &Isometry3<f64>,
    radius: f64,
) -> Result<(Ellipse, Matrix5x6<f64>)> {
    let (c, dc) = circle_image_conic_jacobian(k, t_co, radius)?;
    let (e, grads) = Ellipse::from_conic_with_gradient(&c)?;
    let mut j = Matrix5x6::zeros();
    for (row, g) in grads.iter().enumerate() {
        for (col, d) in dc.iter().enumerate() {
            j[(row, col)] = g.dot(d);
        }
    }
    Ok((e, j))
}

/// Image of a circle given in world coordinates: centre `center`, plane normal `normal`
/// (any length, not zero), `radius`; `t_cw` maps world to camera coordinates. Builds an
/// object frame `T_wo` with origin `center` and z axis along the normalised normal (the
/// in-plane axes are arbitrary — a circle does not depend on them) and calls
/// [`project_circle`] with `T_co = T_cw·T_wo` (eq. 5.13).
///
/// Errors: [`GeometryError::InvalidParameter`] for a zero normal, and those of
/// [`project_circle`].
pub fn project_circle_world(
    k: &Matrix3<f64>,
    t_cw: &Isometry3<f64>,
    center: &Vector3<f64>,
    normal: &Vector3<f64>,
    radius: f64,
) -> Result<Ellipse> {
    check_finite("circle center", center.as_slice())?;
    check_finite("circle normal", normal.as_slice())?;
    let len = normal.norm();
    if len == 0.0 || !len.is_finite() {
        return Err(GeometryError::InvalidParameter {
            what: "normal length",
            value: len,
            reason: "the circle's plane normal must be a non-zero vector",
        });
    }
    let z = normal / len;
    let helper = if z.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x = (helper - z * z.dot(&helper)).normalize();
    let y = z.cross(&x);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    let t_wo = Isometry3::from_parts(
        Translation3::from(*center),
        UnitQuaternion::from_rotation_matrix(&rot),
    );
    project_circle(k, &(t_cw * t_wo), radius)
}

#[cfg(test)]
mod tests;
