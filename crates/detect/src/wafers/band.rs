//! The two-edge band model of a wafer rim (000_3b1454b2b2194811.txt §3.2, Fig. 3.2: "the
//! bright boundary of the wafer forms two edges: an upper one corresponding to the upper surface
//! and lower one corresponding to the lower surface"). Across the rim the image is a bright band
//! (the wafer's side face, 2–4 px wide) between darker surroundings, blurred by the optics. The
//! Sobel/Canny maximum of a step lies on the step, but the two edges of a band this narrow
//! pull each other's gradient maxima apart (the derivative of a blurred box peaks outside the
//! box: ≈ 0.2 px for a 2.5 px band at the ≈ 1 px combined blur of the renderer and the Sobel
//! difference), which shrinks the lower rim's minor axis by 1–3 %. This module fits the profile
//! itself, `I(t) = L₀ + (L_b − L₀)·Φ((t − t₁)/σ) + (L₂ − L_b)·Φ((t − t₂)/σ)` along the rim
//! normal (Φ the standard normal CDF: a box `[t₁, t₂]` of level `L_b` on a background stepping
//! from `L₀` to `L₂`, convolved with a Gaussian of σ), by Levenberg–Marquardt with the analytic
//! Jacobian; clipped (saturated) samples are censored data — they only require the model to
//! reach the clip level there (one-sided residual) — so the band's edges stay determined even
//! when its top is clipped.

use super::{GrayView, Pixel, Vector2};
use nalgebra::{Matrix6, SMatrix, SVector, Vector6};

/// First profile offset (pixels, from the edge point toward the bright side).
pub(super) const T_MIN: f64 = -3.0;
/// Last profile offset.
pub(super) const T_MAX: f64 = 6.0;
/// Profile sample spacing.
pub(super) const STEP: f64 = 0.5;
/// A sample at or above this grey level (0–255 scale) counts as clipped.
const CLIP: f32 = 254.5;

/// `p` of Abramowitz & Stegun (1964) eq. 7.1.26.
const AS_P: f64 = 0.327_591_1;
/// `a₁ … a₅` of Abramowitz & Stegun (1964) eq. 7.1.26.
const AS_A: [f64; 5] = [
    0.254_829_592,
    -0.284_496_736,
    1.421_413_741,
    -1.453_152_027,
    1.061_405_429,
];
/// `Σ aₖ`, the value of the approximation's sum at `t = 1` (`z = 0`).
const AS_SUM: f64 = AS_A[0] + AS_A[1] + AS_A[2] + AS_A[3] + AS_A[4];
/// Bound on `|cdf(z) − Φ(z)|` (half the 1.5·10⁻⁷ bound of eq. 7.1.26 on erfc).
#[cfg(test)]
pub(super) const CDF_MAX_ERROR: f64 = 0.75e-7;

/// The standard normal CDF `Φ(z)` and its derivative, sharing one exponential:
/// `Φ(z) = ½·erfc(−z/√2)` with `erfc(x) ≈ e^{−x²}·Σₖ aₖ tᵏ`, `t = 1/(1 + p·x)` for `x ≥ 0`
/// (Abramowitz & Stegun 1964, eq. 7.1.26: absolute error ≤ 1.5·10⁻⁷, i.e. ≤ 0.75·10⁻⁷ on Φ, or
/// 2·10⁻⁵ grey levels on a 255-level edge) and `erfc(−x) = 2 − erfc(x)`. The derivative is that
/// of the approximation itself (`d/dx[e^{−x²}S(t)] = e^{−x²}(−2x·S(t) − p·t²·S′(t))`), so the
/// model's Jacobian is exact for the model that is fitted (finite differences agree to
/// rounding); it differs from the normal density by less than 3·10⁻⁶.
#[inline]
pub(super) fn cdf_and_density(z: f64) -> (f64, f64) {
    let x = z.abs() * std::f64::consts::FRAC_1_SQRT_2;
    let t = 1.0 / (1.0 + AS_P * x);
    let [a1, a2, a3, a4, a5] = AS_A;
    let s = t * (a1 + t * (a2 + t * (a3 + t * (a4 + t * a5))));
    let ds = a1 + t * (2.0 * a2 + t * (3.0 * a3 + t * (4.0 * a4 + t * 5.0 * a5)));
    // Σ aₖ = 1 − 10⁻⁹: dividing by it makes the tail exactly ½ at z = 0, so the two branches
    // meet continuously (a 10⁻⁹ jump would spoil finite differences across z = 0).
    let e = (-x * x).exp() * (0.5 / AS_SUM);
    // Half the erfc of |z|/√2 (the smaller tail) and its derivative with respect to |z|.
    let tail = e * s;
    let dtail = e * (-2.0 * x * s - AS_P * t * t * ds) * std::f64::consts::FRAC_1_SQRT_2;
    if z < 0.0 {
        (tail, -dtail)
    } else {
        (1.0 - tail, -dtail)
    }
}

/// The model at `t` for `p = [L₀, L_b, L₂, t₁, t₂, σ]`, and its gradient with respect to `p`
/// (Φ and its derivative from [`cdf_and_density`]).
///
/// `#[inline]` so that the callers' loops over the samples of a profile hoist `1/σ` (one
/// division per profile instead of five per sample).
#[inline]
pub(super) fn model(p: &[f64; 6], t: f64) -> (f64, [f64; 6]) {
    let [l0, lb, l2, t1, t2, s] = *p;
    let inv = 1.0 / s;
    let (z1, z2) = ((t - t1) * inv, (t - t2) * inv);
    let (c1, d1) = cdf_and_density(z1);
    let (c2, d2) = cdf_and_density(z2);
    let (h1, h2) = (lb - l0, l2 - lb);
    let f = l0 + h1 * c1 + h2 * c2;
    let (e1, e2) = (h1 * d1 * inv, h2 * d2 * inv);
    let g = [1.0 - c1, c1 - c2, c2, -e1, -e2, -(e1 * z1 + e2 * z2)];
    (f, g)
}

/// Bilinear grey level (0–255 scale) at `(x, y)`, `None` outside the image.
fn bilinear<T: Pixel>(img: &GrayView<'_, T>, x: f64, y: f64) -> Option<f32> {
    let (w, h) = (img.width(), img.height());
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
        return None;
    }
    // `x, y ≥ 0`: truncation is the floor (without a call to `floor`, which the baseline
    // x86-64 instruction set has no instruction for).
    let (x0, y0) = (x as usize, y as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let d = img.data();
    let at = |u: usize, v: usize| d.get(v * w + u).map(|p| p.grey());
    let (a, b, c, e) = (at(x0, y0)?, at(x1, y0)?, at(x0, y1)?, at(x1, y1)?);
    let top = a + fx * (b - a);
    let bottom = c + fx * (e - c);
    Some(top + fy * (bottom - top))
}

/// The profile through `p` along the unit direction `n` or `−n`, whichever points to the
/// brighter side (returned): samples `(t, grey)` into `out`, a clipped sample as
/// `(t, +∞)`, samples outside the image left out; `None` if fewer than 8 samples remain.
pub(super) fn profile<T: Pixel>(
    img: &GrayView<'_, T>,
    p: Vector2<f64>,
    n: Vector2<f64>,
    out: &mut Vec<(f64, f64)>,
) -> Option<Vector2<f64>> {
    let ahead = bilinear(img, p.x + 1.5 * n.x, p.y + 1.5 * n.y)?;
    let behind = bilinear(img, p.x - 1.5 * n.x, p.y - 1.5 * n.y)?;
    let d = if ahead >= behind { n } else { -n };
    out.clear();
    let count = ((T_MAX - T_MIN) / STEP).round() as usize + 1;
    for k in 0..count {
        let t = T_MIN + k as f64 * STEP;
        let q = p + d * t;
        if let Some(v) = bilinear(img, q.x, q.y) {
            out.push((
                t,
                if v < CLIP {
                    f64::from(v)
                } else {
                    f64::INFINITY
                },
            ));
        }
    }
    (out.len() >= 8).then_some(d)
}

/// The pixels along the profile through `p` in the direction `n` or `−n`, whichever points to
/// the brighter side (returned, chosen as in [`profile`]): every pixel whose centre lies in the
/// strip `T_MIN ≤ t ≤ T_MAX`, `|w| ≤ half_width` (`t` the offset along the direction, `w`
/// across it) as `(t, grey)` into `out`, sorted by `t`, a saturated pixel as `(t, +∞)`; `None`
/// if fewer than 8 pixels remain.
///
/// Unlike the interpolated samples of [`profile`], each value is one pixel's own measurement:
/// a bilinear sample under the clip level with a saturated pixel among its four neighbours is
/// only a lower bound of the interpolated radiance, yet would be fitted as exact, pulling the
/// fitted band level (and with it a narrow band's far edge) down; a pixel is either exact or
/// censored (saturated).
pub(super) fn pixel_profile<T: Pixel>(
    img: &GrayView<'_, T>,
    p: Vector2<f64>,
    n: Vector2<f64>,
    half_width: f64,
    out: &mut Vec<(f64, f64)>,
) -> Option<Vector2<f64>> {
    let ahead = bilinear(img, p.x + 1.5 * n.x, p.y + 1.5 * n.y)?;
    let behind = bilinear(img, p.x - 1.5 * n.x, p.y - 1.5 * n.y)?;
    let d = if ahead >= behind { n } else { -n };
    let m = Vector2::new(-d.y, d.x);
    out.clear();
    let (w, h) = (img.width(), img.height());
    let corners = [
        p + d * T_MIN + m * half_width,
        p + d * T_MIN - m * half_width,
        p + d * T_MAX + m * half_width,
        p + d * T_MAX - m * half_width,
    ];
    let lo = |f: fn(&Vector2<f64>) -> f64| {
        corners
            .iter()
            .map(f)
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0)
    };
    let hi = |f: fn(&Vector2<f64>) -> f64, size: usize| {
        corners
            .iter()
            .map(f)
            .fold(f64::NEG_INFINITY, f64::max)
            .floor()
            .min((size - 1) as f64)
    };
    let (x0, x1) = (lo(|c| c.x), hi(|c| c.x, w));
    let (y0, y1) = (lo(|c| c.y), hi(|c| c.y, h));
    if !(x0 <= x1 && y0 <= y1) {
        return None;
    }
    let data = img.data();
    for y in y0 as usize..=y1 as usize {
        for x in x0 as usize..=x1 as usize {
            let r = Vector2::new(x as f64 - p.x, y as f64 - p.y);
            let (t, across) = (r.dot(&d), r.dot(&m));
            if !((T_MIN..=T_MAX).contains(&t) && across.abs() <= half_width) {
                continue;
            }
            let Some(v) = data.get(y * w + x).map(|q| q.grey()) else {
                continue;
            };
            out.push((
                t,
                if v < CLIP {
                    f64::from(v)
                } else {
                    f64::INFINITY
                },
            ));
        }
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    (out.len() >= 8).then_some(d)
}

/// A starting point for [`fit`] from the samples: dark level before the edge, band level
/// (the brightest sample in `[−1, 4]`, or 1.3× the clip level if the band top is clipped),
/// far level, `t₁ = 0`, `t₂` where the profile falls back below the middle of band and far
/// level, `σ = 1`.
pub(super) fn start(samples: &[(f64, f64)]) -> Option<[f64; 6]> {
    let first = samples.first().filter(|s| s.1.is_finite())?;
    let last = samples.last().filter(|s| s.1.is_finite())?;
    let mut peak = (f64::NEG_INFINITY, 0.0);
    for &(t, v) in samples {
        if (-1.0..=4.0).contains(&t) && v > peak.0 {
            peak = (v, t);
        }
    }
    let lb = if peak.0.is_infinite() {
        1.3 * f64::from(CLIP)
    } else {
        peak.0
    };
    let l2 = last.1;
    let mid = 0.5 * (lb + l2);
    let t2 = samples
        .iter()
        .find(|&&(t, v)| t > peak.1 && v < mid)
        .map_or(T_MAX, |&(t, _)| t - 0.5 * STEP);
    Some([first.1, lb, l2, 0.0, t2.max(0.5), 1.0])
}

/// Normal equations `(JᵀJ, Jᵀr)` of the first `k` parameters and the cost `Σ r²` at `p`, in one
/// pass over the samples (a clipped sample, `v = +∞`, only asks the model to reach the clip
/// level: one-sided residual).
fn normal_equations(
    samples: &[(f64, f64)],
    p: &[f64; 6],
    k: usize,
) -> (Matrix6<f64>, Vector6<f64>, f64) {
    // Lower triangle and gradient in plain arrays (no bounds checks in the sample loop).
    let mut a = [[0.0f64; 6]; 6];
    let mut g = [0.0f64; 6];
    let mut cost = 0.0;
    let k = k.min(6);
    for &(t, v) in samples {
        let (f, j) = model(p, t);
        let r = if v.is_finite() {
            f - v
        } else {
            (f - f64::from(CLIP)).min(0.0)
        };
        cost += r * r;
        if !v.is_finite() && r == 0.0 {
            continue;
        }
        for (i, (row, gi)) in a.iter_mut().zip(g.iter_mut()).enumerate().take(k) {
            *gi += j[i] * r;
            for (m, x) in row.iter_mut().enumerate().take(i + 1) {
                *x += j[i] * j[m];
            }
        }
    }
    let mut out = Matrix6::<f64>::zeros();
    for i in 0..k {
        for m in 0..=i {
            out[(i, m)] = a[i][m];
            out[(m, i)] = a[i][m];
        }
    }
    for i in k..6 {
        out[(i, i)] = 1.0;
    }
    (out, Vector6::from(g), cost)
}

/// `m⁻¹·rhs` by the Cholesky factorisation of the symmetric `m` (its lower triangle), `None`
/// when `m` is not positive definite: the same operations, in the same order, as nalgebra's
/// `m.cholesky()` followed by `solve(rhs)` (column-oriented factorisation with the updates
/// `L[i][j] ← (−L[j][k])·L[i][k] + L[i][j]`, division of the column below the diagonal by the
/// square root, forward substitution with column updates, back substitution with dot products
/// summed from +0), so the result is bit-identical — written out for fixed sizes, where
/// nalgebra's generic column views cost more than the arithmetic (a test compares both).
///
/// Of a matrix whose rows and columns from `k` on are those of the identity (a parameter held
/// fixed: [`fit`] with σ fixed), the solve of the leading `k × k` block gives the first `k`
/// entries bit-identical to the solve of the whole: there the trailing columns of the factor
/// are the identity's and the trailing entries of the off-diagonal factor columns stay +0, so
/// every operation they enter adds a zero product to a sum that starts from +0 or is not zero
/// (a test compares both) — at a fraction of the arithmetic (5³ against 6³).
#[inline]
pub(super) fn cholesky_solve<const N: usize>(
    m: &SMatrix<f64, N, N>,
    rhs: &SVector<f64, N>,
) -> Option<SVector<f64, N>> {
    // l[c][r]: column-major like nalgebra, only r ≥ c is used.
    let mut l = [[0.0f64; N]; N];
    for (c, col) in l.iter_mut().enumerate() {
        for (r, x) in col.iter_mut().enumerate().skip(c) {
            *x = m[(r, c)];
        }
    }
    for j in 0..N {
        let (done, rest) = l.split_at_mut(j);
        let col = &mut rest[0];
        for prev in done.iter() {
            // nalgebra's `axpy`: `(factor·x)·1 + 1·y`, the same value as `y + factor·x`.
            let factor = -prev[j];
            for (y, x) in col[j..].iter_mut().zip(&prev[j..]) {
                *y += factor * x;
            }
        }
        let diag = col[j];
        // nalgebra's `try_sqrt`: zero, negative or NaN is not positive definite.
        if diag == 0.0 || !(diag >= 0.0) {
            return None;
        }
        let denom = diag.sqrt();
        col[j] = denom;
        for y in &mut col[j + 1..] {
            *y /= denom;
        }
    }
    let mut b = [0.0f64; N];
    b.copy_from_slice(rhs.as_slice());
    // L·y = b.
    for i in 0..N {
        let coeff = b[i] / l[i][i];
        b[i] = coeff;
        for r in i + 1..N {
            b[r] += -coeff * l[i][r];
        }
    }
    // Lᵀ·x = y.
    for i in (0..N).rev() {
        let mut dot = 0.0;
        for r in i + 1..N {
            dot += l[i][r] * b[r];
        }
        b[i] = (b[i] - dot) / l[i][i];
    }
    Some(SVector::from(b))
}

/// The step of [`fit`] with σ fixed: [`cholesky_solve`] of the leading 5 × 5 block (see there),
/// σ's entry zero.
#[inline]
fn cholesky_solve_sigma_fixed(m: &Matrix6<f64>, rhs: &Vector6<f64>) -> Option<Vector6<f64>> {
    let head = cholesky_solve::<5>(
        &m.fixed_view::<5, 5>(0, 0).into_owned(),
        &rhs.fixed_rows::<5>(0).into_owned(),
    )?;
    let mut x = Vector6::zeros();
    x.fixed_rows_mut::<5>(0).copy_from(&head);
    Some(x)
}

/// Levenberg–Marquardt fit of the band model to `samples` from `p0`; `sigma_free` fits σ,
/// else keeps `p0[5]`. Returns the parameters and the RMS residual (σ stays in (0.2, 5));
/// `None` if no sample is left.
///
/// Each trial step is evaluated with its normal equations in the same pass
/// ([`normal_equations`]), so an accepted step needs no second pass over the samples.
pub(super) fn fit(
    samples: &[(f64, f64)],
    p0: [f64; 6],
    sigma_free: bool,
) -> Option<([f64; 6], f64)> {
    if samples.is_empty() {
        return None;
    }
    let k = if sigma_free { 6 } else { 5 };
    let mut p = p0;
    let (mut a, mut g, mut c) = normal_equations(samples, &p, k);
    let mut lambda = 1e-3;
    for _ in 0..20 {
        let mut improved = false;
        while lambda < 1e10 {
            let mut damped = a;
            for i in 0..k {
                damped[(i, i)] += lambda * a[(i, i)].max(1e-12);
            }
            // With σ fixed its row and column are the identity's: the 5 × 5 solve gives the
            // same step.
            let solved = if sigma_free {
                cholesky_solve(&damped, &(-g))
            } else {
                cholesky_solve_sigma_fixed(&damped, &(-g))
            };
            let Some(step) = solved else {
                lambda *= 10.0;
                continue;
            };
            let mut q = p;
            for i in 0..k {
                q[i] += step[i];
            }
            if !(q[5] > 0.2 && q[5] < 5.0) {
                lambda *= 10.0;
                continue;
            }
            let (aq, gq, cq) = normal_equations(samples, &q, k);
            if cq < c {
                let moved = step
                    .iter()
                    .take(k)
                    .skip(3)
                    .map(|x| x.abs())
                    .fold(0.0, f64::max);
                p = q;
                let small = c - cq <= 1e-8 * c || moved < 1e-4;
                (a, g, c) = (aq, gq, cq);
                lambda = (lambda * 0.3).max(1e-9);
                improved = true;
                if small {
                    return Some((p, (c / samples.len() as f64).sqrt()));
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Some((p, (c / samples.len() as f64).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Standard normal CDF from libm's erfc (the reference).
    fn phi(z: f64) -> f64 {
        0.5 * libm::erfc(-z * std::f64::consts::FRAC_1_SQRT_2)
    }

    #[test]
    fn fast_cdf_is_within_its_bound_and_its_derivative_is_exact() {
        let mut worst: f64 = 0.0;
        let mut worst_density: f64 = 0.0;
        for i in -120_000..=120_000 {
            let z = i as f64 * 1e-4;
            let (c, d) = cdf_and_density(z);
            worst = worst.max((c - phi(z)).abs());
            let pdf = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
            worst_density = worst_density.max((d - pdf).abs());
            // The returned derivative is that of the returned function.
            let h = 1e-5;
            let fd = (cdf_and_density(z + h).0 - cdf_and_density(z - h).0) / (2.0 * h);
            assert!((fd - d).abs() < 1e-9, "z={z}: {fd} vs {d}");
            assert!((0.0..=1.0).contains(&c));
        }
        assert!(worst <= CDF_MAX_ERROR, "{worst}");
        // A tight bound is used: the approximation is not looser than that.
        assert!(worst > 0.1 * CDF_MAX_ERROR, "{worst}");
        assert!(worst_density < 3e-6, "{worst_density}");
        // Far tails: exact limits, no NaN.
        assert_eq!(cdf_and_density(-60.0).0, 0.0);
        assert_eq!(cdf_and_density(60.0).0, 1.0);
        assert!(cdf_and_density(f64::INFINITY).0 == 1.0);
    }

    #[test]
    fn cholesky_solve_is_bit_identical_to_nalgebra() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let mut solved = 0;
        for case in 0..4000 {
            // Random Gram matrices (SPD), some with the identity row/column of a fixed σ, some
            // indefinite or singular, over a wide range of scales and damping.
            let jac = nalgebra::SMatrix::<f64, 8, 6>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let scale = 10f64.powf(rng.random_range(-6.0..6.0));
            let mut m = jac.transpose() * jac * scale;
            if case % 3 == 1 {
                for i in 0..6 {
                    m[(5, i)] = 0.0;
                    m[(i, 5)] = 0.0;
                }
                m[(5, 5)] = 1.0;
            }
            if case % 7 == 3 {
                m[(2, 2)] = -m[(2, 2)];
            }
            if case % 11 == 5 {
                m.row_mut(4).fill(0.0);
                m.column_mut(4).fill(0.0);
            }
            let lambda = 10f64.powf(rng.random_range(-9.0..3.0));
            for i in 0..6 {
                m[(i, i)] += lambda * m[(i, i)].max(1e-12);
            }
            // An upper triangle that differs from the lower must not be read.
            let mut dirty = m;
            dirty[(0, 3)] = f64::NAN;
            let rhs = Vector6::from_fn(|_, _| rng.random_range(-1e3..1e3));
            let reference = m.cholesky().map(|ch| ch.solve(&rhs));
            let ours = cholesky_solve(&dirty, &rhs);
            if case % 3 == 1 {
                // σ fixed: the 5 × 5 solve of the leading block gives the same first 5 entries.
                let leading = cholesky_solve_sigma_fixed(&dirty, &rhs);
                assert_eq!(leading.is_some(), reference.is_some(), "case {case}");
                if let (Some(x), Some(y)) = (reference, leading) {
                    for i in 0..5 {
                        assert_eq!(x[i].to_bits(), y[i].to_bits(), "case {case}: {x} vs {y}");
                    }
                    assert_eq!(y[5], 0.0);
                }
            }
            match (reference, ours) {
                (Some(x), Some(y)) => {
                    solved += 1;
                    for i in 0..6 {
                        assert_eq!(x[i].to_bits(), y[i].to_bits(), "case {case}: {x} vs {y}");
                    }
                }
                (None, None) => {}
                (x, y) => panic!("case {case}: nalgebra {x:?}, ours {y:?}"),
            }
        }
        assert!(solved > 2500, "{solved}");
    }

    #[test]
    fn pixel_profile_takes_each_pixel_of_the_strip_once() {
        // A planar image `v = 12x + 2y + 10` (saturated above the clip level): every pixel whose
        // centre lies in the strip is returned once, at its own offset along the direction,
        // with its own value (or +∞ if saturated), against a brute-force enumeration.
        let (w, h) = (40usize, 30usize);
        let data: Vec<u8> = (0..w * h)
            .map(|i| (12 * (i % w) + 2 * (i / w) + 10).min(255) as u8)
            .collect();
        let img = GrayView::new(&data, w, h).unwrap();
        let p = Vector2::new(17.3, 12.6);
        let n = Vector2::new(0.8, -0.6);
        let mut out = Vec::new();
        let d = pixel_profile(&img, p, n, 1.0, &mut out).unwrap();
        // The brighter side is along +n here (12·0.8 − 2·0.6 > 0).
        assert_eq!(d, n);
        let mut expected = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let r = Vector2::new(x as f64, y as f64) - p;
                let (t, across) = (r.dot(&n), r.x * -n.y + r.y * n.x);
                if (T_MIN..=T_MAX).contains(&t) && across.abs() <= 1.0 {
                    let v = data[y * w + x];
                    expected.push((
                        t,
                        if v == 255 {
                            f64::INFINITY
                        } else {
                            f64::from(v)
                        },
                    ));
                }
            }
        }
        assert!(expected.iter().any(|s| s.1.is_infinite()));
        assert_eq!(out.len(), expected.len());
        let mut sorted = expected.clone();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (a, b) in out.iter().zip(&sorted) {
            assert!((a.0 - b.0).abs() < 1e-12 && a.1 == b.1, "{a:?} vs {b:?}");
        }
        // A strip outside the image.
        assert!(pixel_profile(&img, Vector2::new(-20.0, -20.0), n, 1.0, &mut out).is_none());
    }

    #[test]
    fn fused_fit_matches_separate_cost_and_jacobian_passes() {
        // A noisy sampled band: the fit's cost equals a direct evaluation at its result, and the
        // gradient there vanishes (a minimum).
        let truth = [40.0, 210.0, 60.0, 0.3, 2.8, 0.9];
        let mut samples: Vec<(f64, f64)> = (0..19)
            .map(|k| {
                let t = T_MIN + k as f64 * STEP;
                let noise = 1.5 * (((k * 7919) % 13) as f64 / 6.0 - 1.0);
                (t, model(&truth, t).0 + noise)
            })
            .collect();
        let p0 = start(&samples).unwrap();
        let (p, rms) = fit(&samples, p0, true).unwrap();
        let (_, g, c) = normal_equations(&samples, &p, 6);
        assert!((rms - (c / 19.0).sqrt()).abs() < 1e-12);
        assert!(
            (p[3] - truth[3]).abs() < 0.1 && (p[4] - truth[4]).abs() < 0.1,
            "{p:?}"
        );
        assert!(g.norm() < 1e-2 * c.max(1.0), "{g:?}");
        // A clipped top (band level 420 seen as "at least the clip level"): censored samples
        // (v = +∞) are honoured, with σ fixed.
        let truth = [40.0, 420.0, 60.0, 0.3, 2.8, 0.9];
        for s in &mut samples {
            let v = model(&truth, s.0).0;
            s.1 = if v >= f64::from(CLIP) {
                f64::INFINITY
            } else {
                v
            };
        }
        assert!(samples.iter().filter(|s| s.1.is_infinite()).count() >= 3);
        let mut p0 = start(&samples).unwrap();
        p0[5] = 0.9;
        let (q, _) = fit(&samples, p0, false).unwrap();
        assert_eq!(q[5], 0.9);
        assert!(
            (q[3] - truth[3]).abs() < 0.05 && (q[4] - truth[4]).abs() < 0.05,
            "{q:?}"
        );
        assert!(fit(&[], p0, true).is_none());
    }
}
