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
use nalgebra::{Matrix6, Vector6};

/// First profile offset (pixels, from the edge point toward the bright side).
pub(super) const T_MIN: f64 = -3.0;
/// Last profile offset.
pub(super) const T_MAX: f64 = 6.0;
/// Profile sample spacing.
pub(super) const STEP: f64 = 0.5;
/// A sample at or above this grey level (0–255 scale) counts as clipped.
const CLIP: f32 = 254.5;

/// Standard normal CDF.
pub(super) fn cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z * std::f64::consts::FRAC_1_SQRT_2)
}

/// Standard normal density.
pub(super) fn pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp()
        * (0.5 * std::f64::consts::FRAC_2_SQRT_PI * std::f64::consts::FRAC_1_SQRT_2)
}

/// The model at `t` for `p = [L₀, L_b, L₂, t₁, t₂, σ]`, and its gradient with respect to `p`.
pub(super) fn model(p: &[f64; 6], t: f64) -> (f64, [f64; 6]) {
    let [l0, lb, l2, t1, t2, s] = *p;
    let (z1, z2) = ((t - t1) / s, (t - t2) / s);
    let (c1, c2) = (cdf(z1), cdf(z2));
    let (d1, d2) = (pdf(z1), pdf(z2));
    let (h1, h2) = (lb - l0, l2 - lb);
    let f = l0 + h1 * c1 + h2 * c2;
    let g = [
        1.0 - c1,
        c1 - c2,
        c2,
        -h1 * d1 / s,
        -h2 * d2 / s,
        -(h1 * d1 * z1 + h2 * d2 * z2) / s,
    ];
    (f, g)
}

/// Bilinear grey level (0–255 scale) at `(x, y)`, `None` outside the image.
fn bilinear<T: Pixel>(img: &GrayView<'_, T>, x: f64, y: f64) -> Option<f32> {
    let (w, h) = (img.width(), img.height());
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
        return None;
    }
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
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

/// Levenberg–Marquardt fit of the band model to `samples` from `p0`; `sigma_free` fits σ,
/// else keeps `p0[5]`. Returns the parameters and the RMS residual (σ stays in (0.2, 5));
/// `None` if no sample is left.
pub(super) fn fit(
    samples: &[(f64, f64)],
    p0: [f64; 6],
    sigma_free: bool,
) -> Option<([f64; 6], f64)> {
    let k = if sigma_free { 6 } else { 5 };
    // A clipped sample (v = +∞) only asks the model to reach the clip level.
    let residual = |f: f64, v: f64| {
        if v.is_finite() {
            f - v
        } else {
            (f - f64::from(CLIP)).min(0.0)
        }
    };
    let cost = |p: &[f64; 6]| -> f64 {
        samples
            .iter()
            .map(|&(t, v)| {
                let r = residual(model(p, t).0, v);
                r * r
            })
            .sum()
    };
    let mut p = p0;
    let mut c = cost(&p);
    let mut lambda = 1e-3;
    for _ in 0..20 {
        let mut a = Matrix6::<f64>::zeros();
        let mut g = Vector6::<f64>::zeros();
        for &(t, v) in samples {
            let (f, j) = model(&p, t);
            let r = residual(f, v);
            if !v.is_finite() && r == 0.0 {
                continue;
            }
            for i in 0..k {
                g[i] += j[i] * r;
                for m in 0..=i {
                    a[(i, m)] += j[i] * j[m];
                }
            }
        }
        for i in 0..k {
            for m in 0..i {
                a[(m, i)] = a[(i, m)];
            }
        }
        for i in k..6 {
            a[(i, i)] = 1.0;
        }
        let mut improved = false;
        while lambda < 1e10 {
            let mut damped = a;
            for i in 0..k {
                damped[(i, i)] += lambda * a[(i, i)].max(1e-12);
            }
            let Some(ch) = damped.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let step = ch.solve(&(-g));
            let mut q = p;
            for i in 0..k {
                q[i] += step[i];
            }
            if !(q[5] > 0.2 && q[5] < 5.0) {
                lambda *= 10.0;
                continue;
            }
            let cq = cost(&q);
            if cq < c {
                let moved = step
                    .iter()
                    .take(k)
                    .skip(3)
                    .map(|x| x.abs())
                    .fold(0.0, f64::max);
                p = q;
                let small = c - cq <= 1e-8 * c || moved < 1e-4;
                c = cq;
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
