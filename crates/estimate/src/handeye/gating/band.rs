//! The predicted image width of a wafer's side face (the bright band between its two rims) and
//! the detector's edge noise as a function of it.

use nalgebra::{Isometry3, Matrix3, Point3, Vector2, Vector3};

use crate::handeye::wafer::Rim;

/// Band widths (pixels) at which the detector's relative edge noise was measured: the centres
/// of the bins 0–1, 1–1.5, then 0.25 px wide to 3.5 (1.5–2 measured as one bin, its value
/// serving both entries), and 3.5–4 px.
pub const BAND_NOISE_WIDTH_PX: [f64; 11] = [
    0.5, 1.25, 1.625, 1.875, 2.125, 2.375, 2.625, 2.875, 3.125, 3.375, 3.75,
];

/// RMS normal offset of the detector's upper-rim points from the true rim at
/// [`BAND_NOISE_WIDTH_PX`], relative to that of upper-rim points on bands of at least 3 px
/// (0.0615 px). Measured with the detector's default rules on the simulated sessions of seeds
/// 0–4 (200 frames, 395 k gated points; `python benchmarks/autoteach_sessions.py --noise-model
/// --seeds 0 1 2 3 4`); seeds 5–7 were not used. Where the band narrows, its two blurred edges
/// merge and the band-profile fit is biased along the edge.
pub const BAND_NOISE_UPPER: [f64; 11] = [
    3.95, 2.73, 3.02, 3.02, 2.27, 1.64, 1.17, 1.05, 1.10, 0.98, 0.79,
];

/// As [`BAND_NOISE_UPPER`] for the lower rim, the band's far edge: the worse one from 3 px down.
pub const BAND_NOISE_LOWER: [f64; 11] = [
    5.61, 4.22, 2.91, 2.91, 2.81, 2.59, 1.85, 1.62, 1.39, 1.09, 0.79,
];

/// Factor of the edge-point standard deviation at predicted band width `band` (pixels).
///
/// A heteroscedastic version of eq. (5.5)'s `Ω^z = 1/σ²`: `σ_i = σ·s(b_i)` with `s` the
/// detector's measured relative edge noise ([`BAND_NOISE_UPPER`] / [`BAND_NOISE_LOWER`]), linear
/// in between, constant beyond the ends, never below 1 so that the best points keep the
/// solver's `σ`. A NaN width gives the largest factor of the table.
pub fn band_sigma_scale(band: f64, rim: Rim) -> f64 {
    let table = match rim {
        Rim::Upper => &BAND_NOISE_UPPER,
        Rim::Lower => &BAND_NOISE_LOWER,
    };
    let x = &BAND_NOISE_WIDTH_PX;
    let s = if band.is_nan() {
        table.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    } else if band <= x[0] {
        table[0]
    } else if band >= x[x.len() - 1] {
        table[table.len() - 1]
    } else {
        let j = x.partition_point(|v| *v <= band);
        let (x0, x1) = (x[j - 1], x[j]);
        let t = (band - x0) / (x1 - x0);
        table[j - 1] + t * (table[j] - table[j - 1])
    };
    s.max(1.0)
}

/// Predicted image width (pixels) of a wafer's side face at edge points of one of its rims.
///
/// Each point is mapped to the rim plane by `h_inv` (the inverse of the rim's homography
/// `H = K·[r₁ r₂ t]`, eq. (5.13)), giving its circle angle φ; the other rim's point at φ
/// (`t_co_other`: the other rim's frame in the camera frame) is projected, and the width is the
/// component of the displacement between the two rims' images along the unit normal of the
/// rim's image conic `conic` at the point. This is the apparent height of the side face (the
/// wafer's thickness): widest at the front of the visible arc, shrinking to zero where the
/// rim's image is tangent to the line of sight.
pub fn band_width(
    points: &[Vector2<f64>],
    h_inv: &Matrix3<f64>,
    t_co_other: &Isometry3<f64>,
    conic: &Matrix3<f64>,
    k: &Matrix3<f64>,
    radius: f64,
) -> Vec<f64> {
    // H itself, for the rim's own image at φ: H·(r cos φ, r sin φ, 1).
    let h = h_inv
        .try_inverse()
        .unwrap_or_else(|| Matrix3::from_element(f64::NAN));
    points
        .iter()
        .map(|p| {
            let ph = Vector3::new(p.x, p.y, 1.0);
            let x = h_inv * ph;
            let phi = (x.y / x.z).atan2(x.x / x.z);
            let (s, c) = phi.sin_cos();
            let pc = t_co_other * Point3::new(radius * c, radius * s, 0.0);
            let uvw: Vector3<f64> = k * pc.coords;
            let z = if uvw.z.abs() > 1e-12 { uvw.z } else { 1e-12 };
            let other = Vector2::new(uvw.x / z, uvw.y / z);
            let own = h * Vector3::new(radius * c, radius * s, 1.0);
            let own = Vector2::new(own.x / own.z, own.y / own.z);
            let g = conic * ph;
            let n = Vector2::new(g.x, g.y) / g.x.hypot(g.y).max(1e-300);
            (other - own).dot(&n).abs()
        })
        .collect()
}
