//! Line segments of an image: Canny edge pixels grouped into line-support regions of coherent
//! gradient direction (as in LSD), each fitted by total least squares to the sub-pixel edge
//! positions (parabolic peak of the gradient magnitude across the edge). Segments are oriented
//! so that the darker side is on their left (`(−dy, dx)` side), the polarity the polygon vote
//! uses.

use autoteach_geometry::render::GrayImage;
use nalgebra::{Matrix2, SymmetricEigen, Vector2};

use super::Segment;
use crate::{DetectError, Result};

/// Options of [`detect_segments`].
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentOptions {
    /// Canny low threshold (gradient magnitude of imageproc's Canny, grey levels).
    pub canny_low: f32,
    /// Canny high threshold.
    pub canny_high: f32,
    /// Gaussian sigma (pixels) of the smoothing before the sub-pixel gradient.
    pub gradient_sigma: f64,
    /// Largest gradient-direction difference (radians) inside one line-support region.
    pub angle_tolerance: f64,
    /// Shortest segment kept, pixels.
    pub min_length: f64,
    /// Largest RMS distance (pixels) of a region's edge points from its fitted line.
    pub max_rms: f64,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        Self {
            canny_low: 20.0,
            canny_high: 50.0,
            gradient_sigma: 1.0,
            angle_tolerance: 0.35,
            min_length: 8.0,
            max_rms: 0.7,
        }
    }
}

fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    let r = (3.0 * sigma).ceil().max(1.0) as i64;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.iter().map(|v| (v / s) as f32).collect()
}

/// Separable Gaussian blur with clamped borders, f32.
fn blur(img: &[f32], w: usize, h: usize, sigma: f64) -> Vec<f32> {
    if sigma <= 0.0 {
        return img.to_vec();
    }
    let k = gaussian_kernel(sigma);
    let r = (k.len() / 2) as i64;
    let mut tmp = vec![0f32; w * h];
    for v in 0..h {
        for u in 0..w {
            let mut a = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let x = (u as i64 + j as i64 - r).clamp(0, w as i64 - 1) as usize;
                a += kv * img[v * w + x];
            }
            tmp[v * w + u] = a;
        }
    }
    let mut out = vec![0f32; w * h];
    for v in 0..h {
        for u in 0..w {
            let mut a = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let y = (v as i64 + j as i64 - r).clamp(0, h as i64 - 1) as usize;
                a += kv * tmp[y * w + u];
            }
            out[v * w + u] = a;
        }
    }
    out
}

fn validate(image: &GrayImage, o: &SegmentOptions) -> Result<()> {
    if image.width < 3 || image.height < 3 {
        return Err(DetectError::InvalidParameter {
            what: "image size",
            value: image.width.min(image.height) as f64,
            reason: "the image must be at least 3×3 pixels",
        });
    }
    if image.data.len() != image.width * image.height {
        return Err(DetectError::WrongLength {
            what: "image data",
            got: image.data.len(),
            expected: image.width * image.height,
        });
    }
    let bad = |what, value: f64, reason| {
        Err(DetectError::InvalidParameter {
            what,
            value,
            reason,
        })
    };
    if !(o.canny_low.is_finite() && o.canny_low >= 0.0) {
        return bad("canny_low", o.canny_low as f64, "must be non-negative");
    }
    if !(o.canny_high.is_finite() && o.canny_high >= o.canny_low) {
        return bad(
            "canny_high",
            o.canny_high as f64,
            "must be finite and at least canny_low",
        );
    }
    if !(o.gradient_sigma.is_finite() && (0.0..=10.0).contains(&o.gradient_sigma)) {
        return bad("gradient_sigma", o.gradient_sigma, "must be in [0, 10]");
    }
    if !(o.angle_tolerance.is_finite()
        && o.angle_tolerance > 0.0
        && o.angle_tolerance < std::f64::consts::PI)
    {
        return bad("angle_tolerance", o.angle_tolerance, "must be in (0, π)");
    }
    if !(o.min_length.is_finite() && o.min_length >= 2.0) {
        return bad("min_length", o.min_length, "must be at least 2 pixels");
    }
    if !(o.max_rms.is_finite() && o.max_rms > 0.0) {
        return bad("max_rms", o.max_rms, "must be positive");
    }
    Ok(())
}

/// Line segments of `image` (see the module docs), in pixel coordinates (OpenCV convention),
/// each oriented with the darker side on its left.
pub fn detect_segments(image: &GrayImage, opts: &SegmentOptions) -> Result<Vec<Segment>> {
    validate(image, opts)?;
    let (w, h) = (image.width, image.height);
    let buf = image::GrayImage::from_raw(w as u32, h as u32, image.data.clone()).ok_or(
        DetectError::WrongLength {
            what: "image data",
            got: image.data.len(),
            expected: w * h,
        },
    )?;
    let edges = imageproc::edges::canny(&buf, opts.canny_low, opts.canny_high);
    let edge = |u: usize, v: usize| edges.as_raw()[v * w + u] > 0;
    let f: Vec<f32> = image.data.iter().map(|&g| g as f32).collect();
    let s = blur(&f, w, h, opts.gradient_sigma);
    let at = |u: usize, v: usize| s[v * w + u];
    // Central-difference gradient of the smoothed image (zero on the border).
    let mut gx = vec![0f32; w * h];
    let mut gy = vec![0f32; w * h];
    for v in 1..h - 1 {
        for u in 1..w - 1 {
            gx[v * w + u] = 0.5 * (at(u + 1, v) - at(u - 1, v));
            gy[v * w + u] = 0.5 * (at(u, v + 1) - at(u, v - 1));
        }
    }
    let mag = |u: usize, v: usize| (gx[v * w + u] as f64).hypot(gy[v * w + u] as f64);
    let ang = |u: usize, v: usize| (gy[v * w + u] as f64).atan2(gx[v * w + u] as f64);
    let mut used = vec![false; w * h];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    let mut region: Vec<(usize, usize)> = Vec::new();
    for v0 in 1..h - 1 {
        for u0 in 1..w - 1 {
            if used[v0 * w + u0] || !edge(u0, v0) || mag(u0, v0) == 0.0 {
                continue;
            }
            // Region growing with a running mean direction.
            region.clear();
            stack.clear();
            stack.push((u0, v0));
            used[v0 * w + u0] = true;
            let (mut cx, mut cy) = (0.0, 0.0);
            while let Some((u, v)) = stack.pop() {
                region.push((u, v));
                let a = ang(u, v);
                cx += a.cos();
                cy += a.sin();
                let mean = cy.atan2(cx);
                for dv in -1i64..=1 {
                    for du in -1i64..=1 {
                        let (nu, nv) = (u as i64 + du, v as i64 + dv);
                        if nu < 1 || nv < 1 || nu >= w as i64 - 1 || nv >= h as i64 - 1 {
                            continue;
                        }
                        let (nu, nv) = (nu as usize, nv as usize);
                        if used[nv * w + nu] || !edge(nu, nv) || mag(nu, nv) == 0.0 {
                            continue;
                        }
                        let d = (ang(nu, nv) - mean + std::f64::consts::PI)
                            .rem_euclid(2.0 * std::f64::consts::PI)
                            - std::f64::consts::PI;
                        if d.abs() <= opts.angle_tolerance {
                            used[nv * w + nu] = true;
                            stack.push((nu, nv));
                        }
                    }
                }
            }
            if (region.len() as f64) < 0.7 * opts.min_length {
                continue;
            }
            // Sub-pixel edge points: parabolic peak of |∇| along the dominant gradient axis.
            let pts: Vec<Vector2<f64>> = region
                .iter()
                .map(|&(u, v)| {
                    let (ax, ay) = (gx[v * w + u].abs(), gy[v * w + u].abs());
                    let (m0, mm, mp) = if ax >= ay {
                        (mag(u, v), mag(u - 1, v), mag(u + 1, v))
                    } else {
                        (mag(u, v), mag(u, v - 1), mag(u, v + 1))
                    };
                    let den = mm - 2.0 * m0 + mp;
                    let off = if den < 0.0 {
                        (0.5 * (mm - mp) / den).clamp(-0.5, 0.5)
                    } else {
                        0.0
                    };
                    if ax >= ay {
                        Vector2::new(u as f64 + off, v as f64)
                    } else {
                        Vector2::new(u as f64, v as f64 + off)
                    }
                })
                .collect();
            if let Some(seg) = fit_segment(&pts, cy.atan2(cx), opts) {
                out.push(seg);
            }
        }
    }
    Ok(out)
}

/// Total-least-squares line through `pts`, clipped to their extreme projections and oriented
/// so that the gradient direction `grad_angle` (dark → bright) points to its right.
fn fit_segment(pts: &[Vector2<f64>], grad_angle: f64, opts: &SegmentOptions) -> Option<Segment> {
    let n = pts.len() as f64;
    let mean = pts.iter().sum::<Vector2<f64>>() / n;
    let cov = pts.iter().fold(Matrix2::zeros(), |a, p| {
        a + (p - mean) * (p - mean).transpose()
    }) / n;
    let eig = SymmetricEigen::new(cov);
    let (i1, i2) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    if eig.eigenvalues[i2].max(0.0).sqrt() > opts.max_rms {
        return None;
    }
    let mut dir = eig.eigenvectors.column(i1).into_owned();
    // Right of dir is (dy, −dx); the gradient must point there.
    let g = Vector2::new(grad_angle.cos(), grad_angle.sin());
    if g.dot(&Vector2::new(dir.y, -dir.x)) < 0.0 {
        dir = -dir;
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in pts {
        let t = (p - mean).dot(&dir);
        lo = lo.min(t);
        hi = hi.max(t);
    }
    // Pixel extent: the extreme pixels' centres lie half a pixel inside the true ends.
    let (a, b) = (mean + dir * (lo - 0.5), mean + dir * (hi + 0.5));
    ((b - a).norm() >= opts.min_length).then_some(Segment { a, b })
}
