//! Signed orthogonal distances to an ellipse, their analytic gradient with respect to
//! `(cx, cy, a, b, θ)`, and the fit statistics (residuals, covariance) built from them.

use std::f64::consts::PI;

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Matrix6, SymmetricEigen, Vector2, Vector5, Vector6};

use crate::{DetectError, Result};

/// Smallest eigenvalue of the correlation form of `JᵀJ` accepted as full rank.
const RANK_TOL: f64 = 1e-12;
/// Variance of an angle uniform over the orientation range `(−π/2, π/2]`.
const THETA_UNIFORM_VAR: f64 = PI * PI / 12.0;

/// Foot point of `p` on `e`: signed orthogonal distance `r` (positive outside), the foot point
/// `x'`, the outward unit normal `n̂` there and `(sin t, cos t)` of its eccentric angle.
pub(crate) struct Foot {
    /// Signed orthogonal distance.
    pub r: f64,
    /// The closest point of the ellipse.
    #[cfg(test)]
    pub x: Vector2<f64>,
    /// Outward unit normal at `x`.
    pub normal: Vector2<f64>,
    /// `sin t`.
    pub st: f64,
    /// `cos t`.
    pub ct: f64,
    /// `N = ‖[b cos t, a sin t]‖`.
    pub nn: f64,
}

/// Most Newton passes over all points in [`foot_angles`] before the certifying step.
const MAX_NEWTON_PASSES: usize = 8;

/// Most scratch vectors of each kind kept per thread (see [`scratch`]).
const SCRATCH_KEPT: usize = 16;

thread_local! {
    /// Per-thread scratch vectors of the per-point passes (structure-of-arrays buffers and
    /// Jacobian columns), so that a fitting iteration does not allocate and free them.
    static SCRATCH: std::cell::RefCell<Vec<Vec<f64>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Scratch vectors kept per thread between calls (taken with [`Scratch::take`], returned on
/// drop): the buffers' contents never carry over (every taken vector is empty), only their
/// capacity. Nested takes simply get fresh vectors when the pool is empty.
mod scratch {
    use super::{SCRATCH, SCRATCH_KEPT};
    use std::cell::RefCell;
    use std::thread::LocalKey;

    /// Element types with a per-thread pool.
    pub(super) trait Pooled: Sized + 'static {
        /// The thread's pool of this type.
        fn pool() -> &'static LocalKey<RefCell<Vec<Vec<Self>>>>;
    }
    impl Pooled for f64 {
        fn pool() -> &'static LocalKey<RefCell<Vec<Vec<Self>>>> {
            &SCRATCH
        }
    }

    /// An empty vector with at least `capacity`, from the thread's pool when it has one.
    pub(super) fn take<T: Pooled>(capacity: usize) -> Vec<T> {
        let mut v = T::pool()
            .try_with(|p| p.try_borrow_mut().ok().and_then(|mut p| p.pop()))
            .ok()
            .flatten()
            .unwrap_or_default();
        v.clear();
        v.reserve(capacity);
        v
    }

    /// Returns `v` to the thread's pool (dropped if the pool is full or gone).
    pub(super) fn give<T: Pooled>(v: Vec<T>) {
        let _ = T::pool().try_with(|p| {
            if let Ok(mut p) = p.try_borrow_mut()
                && p.len() < SCRATCH_KEPT
            {
                p.push(v);
            }
        });
    }
}

impl Foot {
    /// `(sin t, cos t)` of the foot point.
    #[cfg(test)]
    pub fn st_ct(&self) -> (f64, f64) {
        (self.st, self.ct)
    }
}

/// The [`Foot`] of `p` on `e` (`sc = (sin θ, cos θ)` of `e`), for a single point.
#[cfg(test)]
pub(crate) fn foot(e: &Ellipse, sc: (f64, f64), p: &Vector2<f64>) -> Foot {
    let mut angles = Vec::with_capacity(1);
    foot_angles(e, std::slice::from_ref(p), &[], &mut angles);
    let t = angles
        .first()
        .copied()
        .unwrap_or_else(|| e.parameter_of(p).sin_cos());
    foot_at(e, sc, p, t)
}

/// The [`Foot`] of `p` at the foot angle `t = (sin t, cos t)` found by [`foot_angles`]:
/// `x' = c + R(θ)·[a cos t, b sin t]ᵀ` (eq. 3.2), `n̂ = R(θ)·[b cos t, a sin t]ᵀ/N`,
/// `r = n̂·(p − x')`.
pub(crate) fn foot_at(e: &Ellipse, sc: (f64, f64), p: &Vector2<f64>, (st, ct): (f64, f64)) -> Foot {
    let (sth, cth) = sc;
    let (dx, dy) = (p.x - e.cx, p.y - e.cy);
    let u = cth * dx + sth * dy;
    let v = -sth * dx + cth * dy;
    let (fu, fv) = (e.a * ct, e.b * st);
    let (nu, nv) = (e.b * ct, e.a * st);
    let nn = (nu * nu + nv * nv).sqrt();
    Foot {
        r: ((u - fu) * nu + (v - fv) * nv) / nn,
        #[cfg(test)]
        x: Vector2::new(e.cx + cth * fu - sth * fv, e.cy + sth * fu + cth * fv),
        normal: Vector2::new(cth * nu - sth * nv, sth * nu + cth * nv) / nn,
        st,
        ct,
        nn,
    }
}

/// Eccentric angles `(sin t, cos t)` of the points of `e` closest to `points`, into `angles`.
/// `start` holds the angles of the same points on a nearby ellipse (during an iteration) or is
/// empty.
///
/// Fast path for the fitting loops, exact like the general solver [`Ellipse::parameter_of`] of
/// the geometry crate, which decides every point this path cannot certify. Newton runs on
/// `g(t) = (p − x(t))·x'(t) = −au·sin t + bv·cos t + (a² − b²) sin t cos t` (`(u, v)`: the
/// point in the ellipse frame) from `start` or the "radial" angle `(cos t, sin t) ∝ (u/a, v/b)`,
/// rotating the unit vector `(cos t, sin t)` without trigonometric calls, in passes over all
/// points until every step is below 1e-6 (independent points pipeline well; the general
/// solver's bracketing is several times slower per point). A final Newton step certifies each
/// point: it must be a
/// minimum (`g' < 0`) reached to rounding (last step ≤ 1e-8, so the error is ~1e-16), at a
/// distance below the reach of the curve — its smallest radius of curvature
/// `min(a, b)²/max(a, b)` (the half-bottleneck `min(a, b)` is larger) — where normal segments
/// never cross, so the foot point found is *the* closest point. Anything else (points near the
/// centre, far away, or not converged) goes to [`Ellipse::parameter_of`]. Returns how many
/// points did.
pub(crate) fn foot_angles(
    e: &Ellipse,
    points: &[Vector2<f64>],
    start: &[(f64, f64)],
    angles: &mut Vec<(f64, f64)>,
) -> usize {
    let mut ok = Vec::new();
    certified_foot_angles(e, points, start, angles, &mut ok);
    solve_uncertified(e, points, angles, &ok)
}

/// The Newton passes and the certifying step of [`foot_angles`] without the general solver:
/// `angles` receives the angles, `ok` whether each is certified (exactly [`foot_angles`]'s
/// angle); the others are unfinished until [`solve_uncertified`].
pub(crate) fn certified_foot_angles(
    e: &Ellipse,
    points: &[Vector2<f64>],
    start: &[(f64, f64)],
    angles: &mut Vec<(f64, f64)>,
    ok: &mut Vec<bool>,
) {
    // Compiled for the best instruction set the CPU has (AVX2 + FMA where available), chosen
    // at run time: the passes below are independent per point and vectorise.
    pulp::Arch::new().dispatch(FootAnglesOp {
        e,
        points,
        start,
        angles,
        ok,
    })
}

/// The kernels run under [`pulp::Arch::dispatch`], one struct each: pulp's own `WithSimd` for
/// closures calls the closure through `FnOnce::call_once`, which LLVM leaves out of line and
/// compiles for the baseline target (two SSE2 lanes, no AVX), whereas these `#[inline(always)]`
/// `with_simd` bodies put the (`#[inline(always)]`) kernel inside pulp's `#[target_feature]`
/// function.
struct FootAnglesOp<'a> {
    e: &'a Ellipse,
    points: &'a [Vector2<f64>],
    start: &'a [(f64, f64)],
    angles: &'a mut Vec<(f64, f64)>,
    ok: &'a mut Vec<bool>,
}

impl pulp::WithSimd for FootAnglesOp<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        foot_angles_impl(self.e, self.points, self.start, self.angles, self.ok)
    }
}

/// [`conic_normal_equations`] under [`pulp::Arch::dispatch`] (see [`FootAnglesOp`]).
struct ConicNormalOp<'a> {
    e: &'a Ellipse,
    q: &'a [f64; 6],
    points: &'a [Vector2<f64>],
    angles: &'a [(f64, f64)],
}

impl pulp::WithSimd for ConicNormalOp<'_> {
    type Output = ConicNormal;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> ConicNormal {
        conic_normal_equations(self.e, self.q, self.points, self.angles)
    }
}

/// [`NormalAcc::finish_impl`] under [`pulp::Arch::dispatch`] (see [`FootAnglesOp`]).
struct FinishOp<'a, const K: usize>(&'a NormalAcc<K>);

impl<const K: usize> pulp::WithSimd for FinishOp<'_, K> {
    type Output = (nalgebra::SMatrix<f64, K, K>, nalgebra::SVector<f64, K>, f64);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        self.0.finish_impl()
    }
}

/// Completes [`certified_foot_angles`]: the points not marked in `ok` get their angle from the
/// general solver [`Ellipse::parameter_of`]. Returns how many did.
pub(crate) fn solve_uncertified(
    e: &Ellipse,
    points: &[Vector2<f64>],
    angles: &mut [(f64, f64)],
    ok: &[bool],
) -> usize {
    let mut general = 0;
    for ((t, ok), p) in angles.iter_mut().zip(ok).zip(points) {
        if !ok {
            *t = e.parameter_of(p).sin_cos();
            general += 1;
        }
    }
    general
}

#[inline(always)]
fn foot_angles_impl(
    e: &Ellipse,
    points: &[Vector2<f64>],
    start: &[(f64, f64)],
    angles: &mut Vec<(f64, f64)>,
    ok: &mut Vec<bool>,
) {
    let (sth, cth) = e.theta.sin_cos();
    let (a, b) = (e.a, e.b);
    let k = (a - b) * (a + b);
    let reach = a.min(b).powi(2) / a.max(b);
    // Structure of arrays, so that the passes below compile to vector code (no pushes or
    // branches in the loops).
    let n = points.len();
    let filled = |n: usize| {
        let mut v: Vec<f64> = scratch::take(n);
        v.resize(n, 0.0);
        v
    };
    let (mut us, mut vs, mut ss, mut cs) = (filled(n), filled(n), filled(n), filled(n));
    for ((u, v), p) in us.iter_mut().zip(vs.iter_mut()).zip(points) {
        let (dx, dy) = (p.x - e.cx, p.y - e.cy);
        *u = cth * dx + sth * dy;
        *v = -sth * dx + cth * dy;
    }
    // A zero vector below gives NaN, which the certificate sends to the general solver.
    if start.len() == n {
        for ((s, c), &(s0, c0)) in ss.iter_mut().zip(cs.iter_mut()).zip(start) {
            let inv = 1.0 / (c0 * c0 + s0 * s0).sqrt();
            *s = s0 * inv;
            *c = c0 * inv;
        }
    } else {
        // Cold start: the angle of the first-order (Sampson) foot point
        // `x' = x − f∇f/‖∇f‖²` of `f = u²/a² + v²/b² − 1`, `(cos t, sin t) ∝ (u'/a, v'/b)`;
        // for a point at distance `d` from the curve its angle error is `O(d²)`, where the
        // radial angle `(cos t, sin t) ∝ (u/a, v/b)` is off by `O(d·(a − b))`. The factors are
        // kept non-negative: far from the curve the projection may overshoot the axis, and
        // the radial side is then the better start.
        let (al, be) = (1.0 / (a * a), 1.0 / (b * b));
        let (ia, ib) = (1.0 / a, 1.0 / b);
        for (((s, c), &u), &v) in ss.iter_mut().zip(cs.iter_mut()).zip(&us).zip(&vs) {
            let (gu, gv) = (al * u, be * v);
            let f = gu * u + gv * v - 1.0;
            let k = 0.5 * f / (gu * gu + gv * gv);
            let c0 = u * ia * (1.0 - k * al).max(0.0);
            let s0 = v * ib * (1.0 - k * be).max(0.0);
            let inv = 1.0 / (c0 * c0 + s0 * s0).sqrt();
            *s = s0 * inv;
            *c = c0 * inv;
        }
    }
    // Newton passes over all points until every step is small; the certifying pass below
    // then takes one more, quadratically convergent, step.
    for _ in 0..MAX_NEWTON_PASSES {
        let mut pending = 0usize;
        for (((s, c), &u), &v) in ss.iter_mut().zip(cs.iter_mut()).zip(&us).zip(&vs) {
            let g = -a * u * *s + b * v * *c + k * *s * *c;
            let dg = -a * u * *c - b * v * *s + k * (*c - *s) * (*c + *s);
            let delta = (-g / dg).clamp(-0.5, 0.5);
            // Rotate by about delta and bring the norm back toward 1 without a square root
            // (one Newton step for 1/√n², exact to O((n² − 1)²)).
            let (cd, sd) = (1.0 - 0.5 * delta * delta, delta);
            let (nc, ns) = (*c * cd - *s * sd, *s * cd + *c * sd);
            let inv = 0.5 * (3.0 - (nc * nc + ns * ns));
            *c = nc * inv;
            *s = ns * inv;
            // Only points headed for a minimum count (the others go to the general solver).
            pending += usize::from(dg < 0.0 && delta.abs() > 1e-6);
        }
        if pending == 0 {
            break;
        }
    }
    // Certifying step, branch-free so that it vectorises (`ok` marks the certified points);
    // the others go to the general solver ([`solve_uncertified`]).
    ok.clear();
    ok.resize(n, false);
    for ((((s, c), &u), &v), ok) in ss
        .iter_mut()
        .zip(cs.iter_mut())
        .zip(&us)
        .zip(&vs)
        .zip(ok.iter_mut())
    {
        let g = -a * u * *s + b * v * *c + k * *s * *c;
        let dg = -a * u * *c - b * v * *s + k * (*c - *s) * (*c + *s);
        let delta = -g / dg;
        let (nc, ns) = (*c - *s * delta, *s + *c * delta);
        let inv = 1.0 / (nc * nc + ns * ns).sqrt();
        let (nc, ns) = (nc * inv, ns * inv);
        let (nu, nv) = (b * nc, a * ns);
        let r = ((u - a * nc) * nu + (v - b * ns) * nv) / (nu * nu + nv * nv).sqrt();
        *ok = dg < 0.0 && delta.abs() <= 1e-8 && r.abs() < 0.999 * reach;
        *c = nc;
        *s = ns;
    }
    angles.clear();
    angles.extend(ss.iter().zip(&cs).map(|(&s, &c)| (s, c)));
    for v in [us, vs, ss, cs] {
        scratch::give(v);
    }
}

/// Signed orthogonal distance `r` from `p` to `e` (positive outside) and its gradient
/// `∂r/∂(cx, cy, a, b, θ)`; `sc = (sin θ, cos θ)`.
///
/// With `x'` the foot point and `n̂` the outward unit normal there (see [`foot`]),
/// `r = n̂·(p − x')`. Because `p − x'` is normal to the curve at the optimal `t`, the envelope
/// theorem gives `∂r/∂q = −n̂·∂x'/∂q` at fixed `t`:
/// `(−n̂ₓ, −n̂ᵧ, −b cos²t/N, −a sin²t/N, −(a² − b²) sin t cos t/N)` (Ahn, Rauh & Warnecke 2001,
/// orthogonal distance fitting, with the foot-point angle eliminated).
#[cfg(test)]
pub(crate) fn distance_and_gradient(
    e: &Ellipse,
    sc: (f64, f64),
    p: &Vector2<f64>,
) -> (f64, Vector5<f64>) {
    gradient_at(e, &foot(e, sc, p))
}

/// [`distance_and_gradient`] for one point outside a fit, with the foot angle from the exact
/// solver [`Ellipse::parameter_of`] (the fits find theirs in batches with [`foot_angles`]): the
/// one linearisation of the orthogonal distance that the detector's refits and screens
/// (`wafers::validate`, `wafers::rim_shared`) share.
pub(crate) fn point_distance_and_gradient(e: &Ellipse, p: &Vector2<f64>) -> (f64, Vector5<f64>) {
    let t = e.parameter_of(p).sin_cos();
    gradient_at(e, &foot_at(e, e.theta.sin_cos(), p, t))
}

/// [`distance_and_gradient`] from a computed foot point.
fn gradient_at(e: &Ellipse, f: &Foot) -> (f64, Vector5<f64>) {
    let grad = Vector5::new(
        -f.normal.x,
        -f.normal.y,
        -e.b * f.ct * f.ct / f.nn,
        -e.a * f.st * f.st / f.nn,
        -(e.a - e.b) * (e.a + e.b) * f.st * f.ct / f.nn,
    );
    (f.r, grad)
}

/// Signed orthogonal distance `r` from `p` to the ellipse `e` and its gradient with respect to
/// the coefficients `q = [A, B, C, D, E, F]` of the same curve `f(x) = Ax² + Bxy + Cy² + Dx +
/// Ey + F = 0` (eq. 3.3 written out, `f > 0` outside): perturbing `q` by `dq` moves the curve at
/// the foot point `x'` along its normal by `−dq·m(x')/‖∇f(x')‖`, with
/// `m = [x², xy, y², x, y, 1]`, so `∂r/∂q = m(x')/‖∇f(x')‖`. (The fit accumulates the same
/// rows in [`accumulate_conic`]; this per-point form is the reference its tests check.)
#[cfg(test)]
pub(crate) fn distance_and_conic_gradient(
    e: &Ellipse,
    sc: (f64, f64),
    q: &[f64; 6],
    p: &Vector2<f64>,
    t: (f64, f64),
) -> (f64, Vector6<f64>) {
    let f = foot_at(e, sc, p, t);
    let (x, y) = (f.x.x, f.x.y);
    let gx = 2.0 * q[0] * x + q[1] * y + q[3];
    let gy = q[1] * x + 2.0 * q[2] * y + q[4];
    let g = 1.0 / (gx * gx + gy * gy).sqrt();
    (
        f.r,
        Vector6::new(x * x * g, x * y * g, y * y * g, x * g, y * g, g),
    )
}

/// `Σᵢ aᵢbᵢ` with four independent partial sums, so that the loop vectorises.
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut s = [0.0f64; 4];
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// The Jacobian of `K` parameters, stored by columns, and the residuals; the normal equations
/// `(JᵀJ, Jᵀr, Σ r²)` are formed at the end as column dot products ([`dot`]): 21 running sums
/// per point (for `K = 6`) do not fit in the registers, column products vectorise.
struct NormalAcc<const K: usize> {
    cols: [Vec<f64>; K],
    r: Vec<f64>,
}

impl<const K: usize> Drop for NormalAcc<K> {
    fn drop(&mut self) {
        for c in &mut self.cols {
            scratch::give(std::mem::take(c));
        }
        scratch::give(std::mem::take(&mut self.r));
    }
}

impl<const K: usize> NormalAcc<K> {
    fn new(capacity: usize) -> Self {
        NormalAcc {
            cols: std::array::from_fn(|_| scratch::take(capacity)),
            r: scratch::take(capacity),
        }
    }

    /// Adds one residual `r` with gradient `g`.
    #[inline(always)]
    fn add(&mut self, g: &[f64; K], r: f64) {
        for (c, v) in self.cols.iter_mut().zip(g) {
            c.push(*v);
        }
        self.r.push(r);
    }

    /// `(JᵀJ, Jᵀr, Σ r²)`.
    fn finish(&self) -> (nalgebra::SMatrix<f64, K, K>, nalgebra::SVector<f64, K>, f64) {
        pulp::Arch::new().dispatch(FinishOp(self))
    }

    #[inline(always)]
    fn finish_impl(&self) -> (nalgebra::SMatrix<f64, K, K>, nalgebra::SVector<f64, K>, f64) {
        let mut m = nalgebra::SMatrix::<f64, K, K>::zeros();
        let mut jtr = nalgebra::SVector::<f64, K>::zeros();
        for j in 0..K {
            for i in 0..=j {
                let v = dot(&self.cols[i], &self.cols[j]);
                m[(i, j)] = v;
                m[(j, i)] = v;
            }
            jtr[j] = dot(&self.cols[j], &self.r);
        }
        (m, jtr, dot(&self.r, &self.r))
    }
}

/// Gauss–Newton normal equations of the orthogonal distances of `points` to `e`.
pub(crate) struct Normal {
    /// `JᵀJ`.
    pub jtj: Matrix5<f64>,
    /// `Jᵀr`.
    pub jtr: Vector5<f64>,
    /// `Σ r²`.
    pub ssr: f64,
    /// `Σ |r|`.
    pub sum_abs: f64,
}

/// Accumulates [`Normal`] without storing the Jacobian. `known` may hold the foot angles of
/// the points on exactly this ellipse (from the last fitting iteration); otherwise they are
/// computed.
pub(crate) fn accumulate(
    e: &Ellipse,
    points: &[Vector2<f64>],
    known: Option<&[(f64, f64)]>,
) -> Normal {
    let sc = e.theta.sin_cos();
    let mut out = Normal {
        jtj: Matrix5::zeros(),
        jtr: Vector5::zeros(),
        ssr: 0.0,
        sum_abs: 0.0,
    };
    let mut computed = Vec::new();
    let angles = match known {
        Some(k) if k.len() == points.len() => k,
        _ => {
            foot_angles(e, points, &[], &mut computed);
            &computed
        }
    };
    let mut acc = NormalAcc::<5>::new(points.len());
    let mut sum_abs = 0.0;
    for (p, &t) in points.iter().zip(angles) {
        let (r, g) = gradient_at(e, &foot_at(e, sc, p, t));
        acc.add(&g.into(), r);
        sum_abs += r.abs();
    }
    (out.jtj, out.jtr, out.ssr) = acc.finish();
    out.sum_abs = sum_abs;
    out
}

/// Normal equations of the orthogonal distances with respect to the conic coefficients `q`
/// of `e` (see [`distance_and_conic_gradient`]): `(JᵀJ, Jᵀr, Σ r²)`. `angles` holds the foot
/// angles `(sin t, cos t)` of the points on a nearby ellipse to start from (or is empty), and
/// receives those on `e`.
pub(crate) fn accumulate_conic(
    e: &Ellipse,
    q: &[f64; 6],
    points: &[Vector2<f64>],
    start: &[(f64, f64)],
    angles: &mut Vec<(f64, f64)>,
) -> ConicNormal {
    foot_angles(e, points, start, angles);
    pulp::Arch::new().dispatch(ConicNormalOp {
        e,
        q,
        points,
        angles,
    })
}

/// The normal equations of [`accumulate_conic`] at known foot angles, as weighted moments.
///
/// Row `i` of the Jacobian is `wᵢ·m(x'ᵢ)` with `wᵢ = 1/‖∇f(x'ᵢ)‖` and `m = [x², xy, y², x, y,
/// 1]`, so every entry of `JᵀJ = Σ wᵢ² m mᵀ` is one of the 15 moments `Σ wᵢ² x'^j y'^k`
/// (`j + k ≤ 4`) and `Jᵀr = Σ wᵢrᵢ m`: 22 running sums instead of 28 column products, in
/// passes over structure-of-arrays buffers that vectorise (four lanes per sum).
#[inline(always)]
fn conic_normal_equations(
    e: &Ellipse,
    q: &[f64; 6],
    points: &[Vector2<f64>],
    angles: &[(f64, f64)],
) -> ConicNormal {
    let (sth, cth) = e.theta.sin_cos();
    let (a, b) = (e.a, e.b);
    let n = points.len().min(angles.len());
    // Foot points, weights w² and w·r, in flat buffers padded to a multiple of four (a zero
    // weight adds nothing), filled by a loop without branches or pushes so that it vectorises.
    let padded = n.div_ceil(4) * 4;
    let zeros = || {
        let mut v: Vec<f64> = scratch::take(padded);
        v.resize(padded, 0.0);
        v
    };
    let (mut xs, mut ys, mut w2, mut wr, mut rr) = (zeros(), zeros(), zeros(), zeros(), zeros());
    let outputs = xs
        .iter_mut()
        .zip(ys.iter_mut())
        .zip(w2.iter_mut())
        .zip(wr.iter_mut())
        .zip(rr.iter_mut());
    for (((((xo, yo), w2o), wro), rro), (p, &(st, ct))) in outputs.zip(points.iter().zip(angles)) {
        let (dx, dy) = (p.x - e.cx, p.y - e.cy);
        let u = cth * dx + sth * dy;
        let v = -sth * dx + cth * dy;
        let (fu, fv) = (a * ct, b * st);
        let (nu, nv) = (b * ct, a * st);
        let r = ((u - fu) * nu + (v - fv) * nv) / (nu * nu + nv * nv).sqrt();
        let x = e.cx + cth * fu - sth * fv;
        let y = e.cy + sth * fu + cth * fv;
        let gx = 2.0 * q[0] * x + q[1] * y + q[3];
        let gy = q[1] * x + 2.0 * q[2] * y + q[4];
        let g2 = 1.0 / (gx * gx + gy * gy);
        *xo = x;
        *yo = y;
        *w2o = g2;
        *wro = g2.sqrt() * r;
        *rro = r;
    }
    // The 15 moments Σ w² xʲ yᵏ, j + k ≤ 4, in the order of `MOMENT`.
    let mut mom = [[0.0f64; 4]; 15];
    fn quads(v: &[f64]) -> std::slice::ChunksExact<'_, f64> {
        v.chunks_exact(4)
    }
    for ((x, y), w) in quads(&xs).zip(quads(&ys)).zip(quads(&w2)) {
        for l in 0..4 {
            let (x, y, w) = (x[l], y[l], w[l]);
            let (wx, wy) = (w * x, w * y);
            let (wxx, wxy, wyy) = (wx * x, wx * y, wy * y);
            let (wxxx, wxxy, wxyy, wyyy) = (wxx * x, wxx * y, wxy * y, wyy * y);
            let terms = [
                w,
                wx,
                wy,
                wxx,
                wxy,
                wyy,
                wxxx,
                wxxy,
                wxyy,
                wyyy,
                wxxx * x,
                wxxx * y,
                wxxy * y,
                wxyy * y,
                wyyy * y,
            ];
            for (m, t) in mom.iter_mut().zip(terms) {
                m[l] += t;
            }
        }
    }
    // Σ w·r·m, Σ r² and Σ |r|.
    let mut lin = [[0.0f64; 4]; 8];
    for (((x, y), wr), r) in quads(&xs).zip(quads(&ys)).zip(quads(&wr)).zip(quads(&rr)) {
        for l in 0..4 {
            let (x, y, t) = (x[l], y[l], wr[l]);
            let (tx, ty) = (t * x, t * y);
            let terms = [tx * x, tx * y, ty * y, tx, ty, t, r[l] * r[l], r[l].abs()];
            for (m, t) in lin.iter_mut().zip(terms) {
                m[l] += t;
            }
        }
    }
    let total = |m: &[f64; 4]| (m[0] + m[1]) + (m[2] + m[3]);
    let mom: [f64; 15] = std::array::from_fn(|k| total(&mom[k]));
    let lin: [f64; 8] = std::array::from_fn(|k| total(&lin[k]));
    for v in [xs, ys, w2, wr, rr] {
        scratch::give(v);
    }
    // Monomial m_k = x^MONO[k].0 · y^MONO[k].1, and the index in `mom` of x^j y^k.
    const MONO: [(usize, usize); 6] = [(2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0)];
    let index = |j: usize, k: usize| {
        let d = j + k;
        // Moments of degree d start at d(d + 1)/2, ordered by falling power of x.
        d * (d + 1) / 2 + k
    };
    let jtj = Matrix6::from_fn(|r, c| {
        let (j, k) = (MONO[r].0 + MONO[c].0, MONO[r].1 + MONO[c].1);
        mom[index(j, k)]
    });
    let jtr = Vector6::from_fn(|r, _| lin[r]);
    ConicNormal {
        jtj,
        jtr,
        ssr: lin[6],
        sum_abs: lin[7],
    }
}

/// The 15 moments `Σ xʲyᵏ` (`j + k ≤ 4`; degree `d` at `d(d + 1)/2 + k`) of the points
/// `(p − c)·inv`: every entry of the conic scatter `Σ z zᵀ`, `z = [x², xy, y², x, y, 1]`
/// (eq. 3.3 written out), in one vectorised pass.
pub(crate) fn scatter_moments(points: &[Vector2<f64>], c: Vector2<f64>, inv: f64) -> [f64; 15] {
    pulp::Arch::new().dispatch(MomentsOp { points, c, inv })
}

/// [`scatter_moments`] under [`pulp::Arch::dispatch`] (see [`FootAnglesOp`]).
struct MomentsOp<'a> {
    points: &'a [Vector2<f64>],
    c: Vector2<f64>,
    inv: f64,
}

impl pulp::WithSimd for MomentsOp<'_> {
    type Output = [f64; 15];

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> [f64; 15] {
        let (cx, cy, inv) = (self.c.x, self.c.y, self.inv);
        let mut mom = [[0.0f64; 4]; 15];
        let chunks = self.points.chunks_exact(4);
        let tail = chunks.remainder();
        let mut add = |x: [f64; 4], y: [f64; 4]| {
            for l in 0..4 {
                let (x, y) = (x[l], y[l]);
                let (xx, xy, yy) = (x * x, x * y, y * y);
                let (xxx, xxy, xyy, yyy) = (xx * x, xx * y, xy * y, yy * y);
                let terms = [
                    1.0,
                    x,
                    y,
                    xx,
                    xy,
                    yy,
                    xxx,
                    xxy,
                    xyy,
                    yyy,
                    xxx * x,
                    xxx * y,
                    xxy * y,
                    xyy * y,
                    yyy * y,
                ];
                for (m, t) in mom.iter_mut().zip(terms) {
                    m[l] += t;
                }
            }
        };
        for p in chunks {
            add(
                std::array::from_fn(|l| (p[l].x - cx) * inv),
                std::array::from_fn(|l| (p[l].y - cy) * inv),
            );
        }
        let mut sum: [f64; 15] = std::array::from_fn(|k| {
            let m = &mom[k];
            (m[0] + m[1]) + (m[2] + m[3])
        });
        for p in tail {
            let (x, y) = ((p.x - cx) * inv, (p.y - cy) * inv);
            let (xx, xy, yy) = (x * x, x * y, y * y);
            let terms = [
                1.0,
                x,
                y,
                xx,
                xy,
                yy,
                xx * x,
                xx * y,
                xy * y,
                yy * y,
                xx * xx,
                xx * xy,
                xx * yy,
                xy * yy,
                yy * yy,
            ];
            for (m, t) in sum.iter_mut().zip(terms) {
                *m += t;
            }
        }
        sum
    }
}

/// Normal equations of the orthogonal distances with respect to the conic coefficients `q`
/// (see [`accumulate_conic`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConicNormal {
    /// `JᵀJ`.
    pub jtj: Matrix6<f64>,
    /// `Jᵀr`.
    pub jtr: Vector6<f64>,
    /// `Σ r²`.
    pub ssr: f64,
    /// `Σ |r|`.
    pub sum_abs: f64,
}

/// `∂q/∂p`: how the conic coefficients `q` of `e` (eq. 3.3 written out, in the scale and sign
/// of the given `q`) change with `p = (cx, cy, a, b, θ)` — so that the orthogonal-distance
/// Jacobian with respect to `p` is `J_q·∂q/∂p` and `JₚᵀJₚ = (∂q/∂p)ᵀ(J_qᵀJ_q)(∂q/∂p)`, with no
/// further pass over the points.
///
/// With `α = a⁻²`, `β = b⁻²`: `A = α cos²θ + β sin²θ`, `B = 2(α − β) sin θ cos θ`,
/// `C = α sin²θ + β cos²θ`, `D = −2A cx − B cy`, `E = −B cx − 2C cy`,
/// `F = A cx² + B cx cy + C cy² − 1`, times `κ = q·c/‖c‖²` (the scale of `q`). The part of `∂q/∂p`
/// along `q` itself is irrelevant: `J_q q = Σ m(x')·q/‖∇f‖ = f(x')/‖∇f‖ = 0` at foot points.
pub(crate) fn conic_parameter_jacobian(e: &Ellipse, q: &[f64; 6]) -> nalgebra::SMatrix<f64, 6, 5> {
    let (s, c) = e.theta.sin_cos();
    let (cx, cy) = (e.cx, e.cy);
    let (al, be) = (1.0 / (e.a * e.a), 1.0 / (e.b * e.b));
    let quad = |al: f64, be: f64| {
        (
            al * c * c + be * s * s,
            2.0 * (al - be) * s * c,
            al * s * s + be * c * c,
        )
    };
    // Full coefficients from (A, B, C) and the centre: linear in (A, B, C).
    let full = |(qa, qb, qc): (f64, f64, f64), f0: f64| {
        [
            qa,
            qb,
            qc,
            -2.0 * qa * cx - qb * cy,
            -qb * cx - 2.0 * qc * cy,
            qa * cx * cx + qb * cx * cy + qc * cy * cy + f0,
        ]
    };
    let (qa, qb, qc) = quad(al, be);
    let conic = full((qa, qb, qc), -1.0);
    let kappa = conic.iter().zip(q).map(|(x, y)| x * y).sum::<f64>()
        / conic.iter().map(|x| x * x).sum::<f64>();
    let (s2, c2) = (2.0 * s * c, c * c - s * s);
    let d_a = full(quad(-2.0 * al / e.a, 0.0), 0.0);
    let d_b = full(quad(0.0, -2.0 * be / e.b), 0.0);
    let d_t = full(((be - al) * s2, 2.0 * (al - be) * c2, (al - be) * s2), 0.0);
    let d_cx = [0.0, 0.0, 0.0, -2.0 * qa, -qb, 2.0 * qa * cx + qb * cy];
    let d_cy = [0.0, 0.0, 0.0, -qb, -2.0 * qc, qb * cx + 2.0 * qc * cy];
    let cols = [d_cx, d_cy, d_a, d_b, d_t];
    nalgebra::SMatrix::<f64, 6, 5>::from_fn(|i, j| kappa * cols[j][i])
}

/// Normal equations of the Sampson distances `rᵢ = f(xᵢ)/‖∇f(xᵢ)‖` (the first-order
/// approximation of the signed orthogonal distance, eq. 3.3 written out as
/// `f = q·m(x)`, `m = [x², xy, y², x, y, 1]`) with respect to `q`: `(JᵀJ, Jᵀr, Σ r²)` with
/// `∂r/∂q = m/‖∇f‖ − f·(∇f·∂∇f/∂q)/‖∇f‖³`.
pub(crate) fn accumulate_sampson(
    q: &[f64; 6],
    points: &[Vector2<f64>],
) -> (Matrix6<f64>, Vector6<f64>, f64) {
    let grad = |p: &Vector2<f64>| {
        (
            2.0 * q[0] * p.x + q[1] * p.y + q[3],
            q[1] * p.x + 2.0 * q[2] * p.y + q[4],
        )
    };
    // 1/‖∇f‖ in a separate, vectorisable pass (square roots and divisions dominate otherwise).
    let mut inv_norms: Vec<f64> = scratch::take(points.len());
    inv_norms.extend(points.iter().map(|p| {
        let (gx, gy) = grad(p);
        1.0 / (gx * gx + gy * gy).sqrt()
    }));
    let mut acc = NormalAcc::<6>::new(points.len());
    for (p, &w) in points.iter().zip(&inv_norms) {
        if !w.is_finite() {
            // ∇f = 0 only at the centre, far from any point an iteration would accept.
            continue;
        }
        let (x, y) = (p.x, p.y);
        let (gx, gy) = grad(p);
        let m = [x * x, x * y, y * y, x, y, 1.0];
        let f = q[0] * m[0] + q[1] * m[1] + q[2] * m[2] + q[3] * x + q[4] * y + q[5];
        let h = [2.0 * x * gx, y * gx + x * gy, 2.0 * y * gy, gx, gy, 0.0];
        let r = f * w;
        let fw3 = r * w * w;
        let g: [f64; 6] = std::array::from_fn(|k| m[k] * w - h[k] * fw3);
        acc.add(&g, r);
    }
    scratch::give(inv_norms);
    acc.finish()
}

/// Mean and RMS absolute orthogonal residual and the covariance of `(cx, cy, a, b, θ)` of the
/// fit `e` to `points` (see [`super::EllipseFit::covariance`] for the conventions).
/// `points` are centred on their centroid (the frame of `e`); `known`: foot angles on `e`, as
/// for [`accumulate`].
///
/// # Errors
/// [`DetectError::RankDeficient`] when `JᵀJ` (apart from a circle's undefined `θ`) is singular.
pub(crate) fn evaluate(
    e: &Ellipse,
    points: &[Vector2<f64>],
    known: Option<&[(f64, f64)]>,
) -> Result<(f64, f64, Option<Matrix5<f64>>)> {
    let acc = accumulate(e, points, known);
    statistics(e, points, &acc)
}

/// [`evaluate`] from the normal equations `acc` of the orthogonal distances of `points` to `e`
/// with respect to `(cx, cy, a, b, θ)` (only `jtj`, `ssr` and `sum_abs` are used).
///
/// # Errors
/// As [`evaluate`].
pub(crate) fn statistics(
    e: &Ellipse,
    points: &[Vector2<f64>],
    acc: &Normal,
) -> Result<(f64, f64, Option<Matrix5<f64>>)> {
    let n = points.len();
    let mean = acc.sum_abs / n as f64;
    let rms = (acc.ssr / n as f64).sqrt();
    if n <= 5 {
        return Ok((mean, rms, None));
    }
    let sigma2 = acc.ssr / (n - 5) as f64;
    let a = acc.jtj;
    let diag = a.diagonal();
    let names = ["cx", "cy", "a", "b", "theta"];
    if let Some(k) = (0..4).find(|&k| !(diag[k] > 0.0)) {
        return Err(DetectError::RankDeficient {
            reason: format!(
                "the points do not constrain {} (JᵀJ diagonal {:?})",
                names[k],
                diag.as_slice()
            ),
        });
    }
    // `points` are centred on their centroid: their RMS radius.
    let spread = (points.iter().map(|p| p.norm_squared()).sum::<f64>() / n as f64).sqrt();
    // The fit described for an error message (formatted only on failure).
    let shape = || {
        format!(
            "fitted ellipse a = {:.4e}, b = {:.4e} px for {n} points of RMS radius {spread:.4e} px{}",
            e.a,
            e.b,
            if e.a > 20.0 * spread {
                "; the fit degenerates toward a parabola: the arc is too short or too noisy to determine an ellipse"
            } else {
                ""
            }
        )
    };
    // θ is undefined for a circle to rounding: its Jacobian column vanishes.
    let d4max = diag.iter().take(4).copied().fold(0.0, f64::max);
    let circular = !(diag[4] > RANK_TOL * d4max);
    if !circular {
        let cov = scaled_inverse(&a, false, &shape)? * sigma2;
        if cov[(4, 4)] <= THETA_UNIFORM_VAR {
            return Ok((mean, rms, Some(cov)));
        }
    }
    // θ not determined by the data: hold it fixed for the others, report a uniform variance.
    let mut cov = scaled_inverse(&a, true, &shape)? * sigma2;
    cov[(4, 4)] = THETA_UNIFORM_VAR;
    Ok((mean, rms, Some(cov)))
}

/// Inverse of the symmetric positive semi-definite `a` through its correlation form
/// `D⁻¹AD⁻¹` (unit diagonal), rejecting it when that form is singular to `RANK_TOL`. With
/// `without_theta`, the `θ` row and column are ignored (the result's are zero): the inverse of
/// the 4×4 block of the other parameters. `what()` describes the fit for the error message.
fn scaled_inverse(
    a: &Matrix5<f64>,
    without_theta: bool,
    what: &dyn Fn() -> String,
) -> Result<Matrix5<f64>> {
    let keep = |i: usize| !(without_theta && i == 4);
    let d = Vector5::from_fn(|i, _| if keep(i) { 1.0 / a[(i, i)].sqrt() } else { 0.0 });
    // The dropped parameter gets an identity row/column: it decouples and has eigenvalue 1.
    let r = Matrix5::from_fn(|i, j| {
        if keep(i) && keep(j) {
            a[(i, j)] * d[i] * d[j]
        } else if i == j {
            1.0
        } else {
            0.0
        }
    });
    let eig = SymmetricEigen::new(r);
    let kmin = eig.eigenvalues.imin();
    let lmin = eig.eigenvalues[kmin];
    if !(lmin > RANK_TOL) {
        let v = eig.eigenvectors.column(kmin);
        return Err(DetectError::RankDeficient {
            reason: format!(
                "the orthogonal-distance Jacobian is rank deficient (smallest eigenvalue {lmin:.3e} of \
                 the normalised JᵀJ, along (cx, cy, a, b, theta) = {:?}): {}",
                v.iter()
                    .map(|x| (x * 1e3).round() / 1e3)
                    .collect::<Vec<_>>(),
                what()
            ),
        });
    }
    let rinv = eig.eigenvectors
        * Matrix5::from_diagonal(&eig.eigenvalues.map(|l| 1.0 / l))
        * eig.eigenvectors.transpose();
    Ok(Matrix5::from_fn(|i, j| rinv[(i, j)] * d[i] * d[j]))
}

#[cfg(test)]
mod column_tests {
    use super::*;

    #[test]
    fn column_normal_equations_equal_the_running_sums() {
        // Lengths around the 4-wide chunks of `dot`, values of mixed sign and scale.
        for n in [0usize, 1, 3, 4, 5, 17, 250] {
            let g = |i: usize, k: usize| ((i * 37 + k * 11) % 23) as f64 / 7.0 - 1.5 + k as f64;
            let r = |i: usize| ((i * 13) % 17) as f64 / 3.0 - 2.0;
            let mut acc = NormalAcc::<6>::new(n);
            let (mut jtj, mut jtr, mut ssr) = (Matrix6::zeros(), Vector6::zeros(), 0.0);
            for i in 0..n {
                let gi: [f64; 6] = std::array::from_fn(|k| g(i, k));
                acc.add(&gi, r(i));
                let v = Vector6::from(gi);
                jtj += v * v.transpose();
                jtr += v * r(i);
                ssr += r(i) * r(i);
            }
            let (a, b, c) = acc.finish();
            let scale = 1.0 + jtj.norm();
            assert!((a - jtj).norm() <= 1e-13 * scale, "n={n}");
            assert_eq!(a, a.transpose());
            assert!((b - jtr).norm() <= 1e-13 * (1.0 + jtr.norm()), "n={n}");
            assert!((c - ssr).abs() <= 1e-13 * (1.0 + ssr), "n={n}");
        }
    }
}
