//! The image's own gradient noise, from which the edge thresholds and the a-contrario
//! alignment test of [`super::detect_ellipses`] follow (no threshold tuned to a renderer).
//!
//! Model: in a flat region with white Gaussian pixel noise of standard deviation `σ`, each
//! component of the Sobel gradient (normalised by 1/8, as in [`crate::edges::canny`]) is
//! Gaussian with standard deviation `σ_g = σ·√(12/64) = 0.433·σ` (the kernel's squared weights
//! sum to 12/64), and the magnitude `|g|` is Rayleigh with scale `σ_g`:
//! `P(|g| > t) = exp(−t²/(2σ_g²))`, whose median is `σ_g·√(2 ln 2)`. Most pixels of a
//! natural or industrial image are away from edges, so the median of `|g|` over the image
//! estimates `σ_g` robustly (edges and texture are the minority that a median ignores). The
//! estimate includes whatever the image holds of correlated noise (blur, texture), which a
//! pixel-noise estimate such as Immerkær's would not: it is the gradient noise the edge
//! detector actually sees.

use crate::edges::{GrayView, Pixel};

/// Lowest gradient noise (grey levels per pixel): the 8-bit quantisation noise `1/√12` grey
/// levels through the Sobel kernel (`0.433/√12 = 0.125`). A noise-free float image would
/// otherwise give zero thresholds.
pub const MIN_GRADIENT_NOISE: f64 = 0.125;

/// The Sobel gradient (normalised by 1/8, grey levels per pixel, dark → bright) at pixel
/// `(x, y)`, `1 ≤ x < w − 1`, `1 ≤ y < h − 1` (the caller checks the bounds).
#[inline]
pub(crate) fn sobel_at<T: Pixel>(data: &[T], w: usize, x: usize, y: usize) -> (f32, f32) {
    let k = y * w + x;
    let p = |i: usize| data[i].grey();
    let (a, b, c) = (p(k - w - 1), p(k - w), p(k - w + 1));
    let (d, f) = (p(k - 1), p(k + 1));
    let (g, hh, i) = (p(k + w - 1), p(k + w), p(k + w + 1));
    let gx = (c + 2.0 * f + i - a - 2.0 * d - g) * 0.125;
    let gy = (g + 2.0 * hh + i - a - 2.0 * b - c) * 0.125;
    (gx, gy)
}

/// Estimated standard deviation `σ_g` (grey levels per pixel) of one component of the Sobel
/// gradient under the image's noise: the median gradient magnitude over a grid of pixels
/// (every `stride`-th row and column, inside the one-pixel border) divided by the Rayleigh
/// median factor `√(2 ln 2)`, floored at [`MIN_GRADIENT_NOISE`]. Returns the floor for images
/// smaller than 3×3.
pub fn gradient_noise<T: Pixel>(image: &GrayView<'_, T>, stride: usize) -> f64 {
    let (w, h) = (image.width(), image.height());
    if w < 3 || h < 3 {
        return MIN_GRADIENT_NOISE;
    }
    let stride = stride.max(1);
    let data = image.data();
    let mut mags: Vec<f32> = Vec::with_capacity(((w - 2) / stride + 1) * ((h - 2) / stride + 1));
    for y in (1..h - 1).step_by(stride) {
        for x in (1..w - 1).step_by(stride) {
            let (gx, gy) = sobel_at(data, w, x, y);
            mags.push(gx * gx + gy * gy);
        }
    }
    let mid = mags.len() / 2;
    let (_, m, _) = mags.select_nth_unstable_by(mid, f32::total_cmp);
    let median = f64::from(m.sqrt());
    (median / (2.0 * std::f64::consts::LN_2).sqrt()).max(MIN_GRADIENT_NOISE)
}

/// The gradient magnitude that pure noise of scale `sigma_g` exceeds with probability `p`
/// (Rayleigh tail): `σ_g·√(2 ln(1/p))`.
pub fn rayleigh_quantile(sigma_g: f64, p: f64) -> f64 {
    sigma_g * (2.0 * (1.0 / p).ln()).sqrt()
}
