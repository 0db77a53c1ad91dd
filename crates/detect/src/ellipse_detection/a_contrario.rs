//! A-contrario validation of a candidate elliptic arc (the validation stage of
//! 000_3b1454b2b2194811.txt §3.2, Fig. 3.1/3.3, done by a number of false alarms instead of
//! the "percentage of points off the ellipse" threshold of [37, 40] that §3.2 criticises).
//!
//! As in LSD and ELSD (von Gioi et al. 2010, "LSD: a fast line segment detector with a false
//! detection control"; Pătrăucean, Gurdjos & von Gioi 2012, "A parameterless line segment and
//! elliptical arc detector with enhanced ellipse fitting"): under the background model `H₀`
//! the gradient orientations of the pixels are independent and uniform. A pixel on the
//! candidate arc is *aligned* when its gradient points along the arc's normal (with the
//! arc's polarity) within `±π/8`, which happens under `H₀` with probability `p = 1/8`. Of
//! `n` pixels on the arc, `k` aligned ones have the binomial tail probability
//! `B(n, k, p) = Σ_{i ≥ k} C(n, i) pⁱ (1 − p)ⁿ⁻ⁱ`, and the number of false alarms is
//! `NFA = N_tests · B(n, k, p)`. An arc with `NFA ≤ ε` is ε-meaningful: in an image of pure
//! noise fewer than `ε` arcs are accepted on average.
//!
//! `N_tests` counts the elliptic arcs an image of `W × H` pixels can hold: 5 ellipse
//! parameters and the 2 end angles of the arc, each resolved to about `√(WH)` values, gives
//! `(WH)^{7/2}` (the same counting that gives LSD's `(WH)^{5/2}` for rectangles with 5
//! parameters).
//!
//! Pixels whose gradient magnitude is under `ρ` are counted as not aligned: their
//! orientation is too uncertain (LSD's `ρ`, here from the image's estimated gradient noise).
//! This only lowers `k`, so the test stays conservative. Sobel gradients of neighbouring
//! pixels share pixels, so they are not quite independent (LSD makes the same approximation);
//! the pure-noise test of this module's tests measures the actual false alarms.

use std::f64::consts::{PI, TAU};

use autoteach_geometry::conic::Ellipse;
use nalgebra::Vector2;

use super::noise::sobel_at;
use crate::edges::{GrayView, Pixel};

/// Probability that a pixel's gradient is aligned under `H₀` (angle tolerance `±π/8`).
pub const ALIGNMENT_PROBABILITY: f64 = 0.125;

/// `log₁₀ N_tests = 3.5 · log₁₀(W·H)`: the number of elliptic arcs of a `W × H` image.
pub fn log10_tests(width: usize, height: usize) -> f64 {
    3.5 * ((width as f64) * (height as f64)).max(1.0).log10()
}

/// `−log₁₀ NFA = −log₁₀ B(n, k, p) − log₁₀ N_tests` (LSD's `nfa()`, in the log domain). For
/// `k ≤ n·p` (no more aligned pixels than chance) it returns `−log₁₀ N_tests` (the tail is
/// then at least ≈ ½, so this overstates the NFA by at most a factor 2: conservative).
pub fn score(n: usize, k: usize, p: f64, log10_nt: f64) -> f64 {
    if n == 0 || k == 0 || (k as f64) <= (n as f64) * p {
        return -log10_nt;
    }
    let (nf, kf) = (n as f64, k as f64);
    // ln of the first term C(n, k) p^k (1 − p)^(n − k).
    let ln_first = libm::lgamma(nf + 1.0) - libm::lgamma(kf + 1.0) - libm::lgamma(nf - kf + 1.0)
        + kf * p.ln()
        + (nf - kf) * (1.0 - p).ln();
    // The tail relative to the first term: the ratios of consecutive terms,
    // (n − i + 1)/i · p/(1 − p), are below 1 for i > n·p, so the sum converges fast.
    let odds = p / (1.0 - p);
    let (mut term, mut sum) = (1.0f64, 1.0f64);
    for i in k + 1..=n {
        term *= (nf - i as f64 + 1.0) / i as f64 * odds;
        sum += term;
        if term < 1e-12 * sum {
            break;
        }
    }
    -(ln_first + sum.ln()) / std::f64::consts::LN_10 - log10_nt
}

/// The counts of the test: `n` pixels on the arc, `k` of them aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Alignment {
    /// Distinct pixels visited along the arc (inside the image's one-pixel border).
    pub n: usize,
    /// Of those, pixels whose gradient is aligned with the arc's normal.
    pub k: usize,
}

/// The angular extent `(start, length)` (eccentric angles, radians) of the arc covered by the
/// points with eccentric angles `ts`: the circle minus its largest gap between consecutive
/// angles. Gaps between the arcs of a segment stay inside the extent, so the test sees them.
pub fn covered_extent(ts: &[f64]) -> (f64, f64) {
    let mut s: Vec<f64> = ts.iter().map(|t| t.rem_euclid(TAU)).collect();
    s.sort_by(f64::total_cmp);
    let Some(&first) = s.first() else {
        return (0.0, 0.0);
    };
    let last = s[s.len() - 1];
    // The wrap-around gap first.
    let (mut gap, mut start) = (first + TAU - last, first);
    for w in s.windows(2) {
        if w[1] - w[0] > gap {
            gap = w[1] - w[0];
            start = w[1];
        }
    }
    (start, TAU - gap)
}

/// The points of the arc of `ellipse` from eccentric angle `start` over `length` radians, about
/// one pixel of arc length apart, each with its unit outward normal.
pub(crate) fn arc_pixels(
    ellipse: &Ellipse,
    start: f64,
    length: f64,
) -> impl Iterator<Item = (Vector2<f64>, Vector2<f64>)> {
    let (a, b) = (ellipse.a, ellipse.b);
    let (st, ct) = ellipse.theta.sin_cos();
    let (cx, cy) = (ellipse.cx, ellipse.cy);
    let end = start + length;
    let mut t = start;
    // At most one step per pixel of arc length; bounded by the perimeter.
    let mut steps = (2.0 * PI * a.max(b) * 2.0 + 10.0) as usize;
    std::iter::from_fn(move || {
        if steps == 0 || !(t <= end) {
            return None;
        }
        steps -= 1;
        let (s, c) = t.sin_cos();
        let (lx, ly) = (a * c, b * s);
        let p = Vector2::new(cx + ct * lx - st * ly, cy + st * lx + ct * ly);
        // Outward normal ∝ (b cos t, a sin t) in the ellipse frame.
        let (nx, ny) = (b * c, a * s);
        let nn = (nx * nx + ny * ny).sqrt().max(1e-12);
        let e = Vector2::new(ct * nx - st * ny, st * nx + ct * ny) / nn;
        let speed = (a * a * s * s + b * b * c * c).sqrt().max(1e-3);
        t += 1.0 / speed;
        Some((p, e))
    })
}

/// The distinct pixels `(x, y)` (rounded positions, consecutive repeats skipped) of
/// [`arc_pixels`] inside the one-pixel border of a `w × h` image, each with the outward normal.
pub(crate) fn distinct_pixels(
    ellipse: &Ellipse,
    (start, length): (f64, f64),
    w: usize,
    h: usize,
) -> impl Iterator<Item = (usize, usize, Vector2<f64>)> {
    let mut last: Option<(i64, i64)> = None;
    let usable = w >= 3 && h >= 3 && length > 0.0;
    arc_pixels(ellipse, start, if usable { length } else { -1.0 }).filter_map(move |(p, normal)| {
        let (px, py) = (p.x.round() as i64, p.y.round() as i64);
        if last == Some((px, py)) {
            return None;
        }
        last = Some((px, py));
        (px >= 1 && py >= 1 && px < w as i64 - 1 && py < h as i64 - 1).then_some((
            px as usize,
            py as usize,
            normal,
        ))
    })
}

/// `−log₁₀ NFA` of the ellipse `e` over the angular extent its `points` cover, with `count`
/// giving the alignment counts over an extent; `None` when the extent covers no pixels.
pub(crate) fn score_support(
    e: &Ellipse,
    points: &[Vector2<f64>],
    log_nt: f64,
    count: impl FnOnce((f64, f64)) -> Alignment,
) -> Option<f64> {
    let ts: Vec<f64> = points.iter().map(|p| e.parameter_of(p)).collect();
    let al = count(covered_extent(&ts));
    (al.n > 0).then(|| score(al.n, al.k, ALIGNMENT_PROBABILITY, log_nt))
}

/// Counts the aligned pixels along the arc of `ellipse` from eccentric angle `start` over
/// `length` radians, stepping about one pixel of arc length at a time ([`arc_pixels`]); each
/// distinct pixel (rounded position) inside the one-pixel border counts once. A pixel is aligned
/// when its Sobel gradient has magnitude at least `rho` and lies within `±π/8` of `polarity`
/// times the outward normal (`+1`: brighter outside, `−1`: brighter inside).
pub fn count_alignment<T: Pixel>(
    image: &GrayView<'_, T>,
    ellipse: &Ellipse,
    extent: (f64, f64),
    polarity: i8,
    rho: f64,
) -> Alignment {
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let cos_tol = (PI / 8.0).cos() as f32;
    let rho2 = (rho * rho) as f32;
    let sign = f64::from(polarity.signum());
    let mut out = Alignment { n: 0, k: 0 };
    for (px, py, normal) in distinct_pixels(ellipse, extent, w, h) {
        let e = normal * sign;
        out.n += 1;
        let (gx, gy) = sobel_at(data, w, px, py);
        let m2 = gx * gx + gy * gy;
        if m2 < rho2 || m2 == 0.0 {
            continue;
        }
        let dot = gx * e.x as f32 + gy * e.y as f32;
        if dot > 0.0 && dot * dot >= cos_tol * cos_tol * m2 {
            out.k += 1;
        }
    }
    out
}
