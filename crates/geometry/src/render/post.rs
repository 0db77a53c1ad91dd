//! Image formation after ray casting: lighting gradient and gain, optical blur (separable
//! Gaussian), additive Gaussian sensor noise from a seeded PCG generator, quantisation to u8.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// Multiplies the linear radiance image by `255·gain·(1 + gx·x̂ + gy·ŷ)`, where
/// `x̂ = (2u − (w − 1))/w` and `ŷ = (2v − (h − 1))/h` run from about −1 to 1 across the image
/// (the factor is clamped at 0). The result is in grey levels.
pub(crate) fn apply_lighting(img: &mut [f32], w: usize, h: usize, gain: f64, gradient: [f64; 2]) {
    img.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        let yh = (2.0 * v as f64 - (h as f64 - 1.0)) / h as f64;
        for (u, px) in row.iter_mut().enumerate() {
            let xh = (2.0 * u as f64 - (w as f64 - 1.0)) / w as f64;
            let f = (255.0 * gain * (1.0 + gradient[0] * xh + gradient[1] * yh)).max(0.0);
            *px = (*px as f64 * f) as f32;
        }
    });
}

/// Normalised 1-D Gaussian kernel of standard deviation `sigma` (pixels), radius ⌈3σ⌉.
pub(crate) fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil().max(1.0) as usize;
    let mut k: Vec<f64> = (0..=2 * radius)
        .map(|i| (-((i as f64 - radius as f64).powi(2)) / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = k.iter().sum();
    k.iter_mut().for_each(|x| *x /= sum);
    k.into_iter().map(|x| x as f32).collect()
}

/// Separable Gaussian blur with replicated borders. The kernel is symmetric, so edges do not
/// move. No-op for `sigma ≤ 0`.
pub(crate) fn blur(img: &mut [f32], w: usize, h: usize, sigma: f64) {
    if sigma <= 0.0 || w == 0 || h == 0 {
        return;
    }
    let k = gaussian_kernel(sigma);
    let r = k.len() / 2;
    // Horizontal pass: tap by tap over the interior (vectorisable), clamped at the borders.
    let mut tmp = vec![0.0f32; w * h];
    tmp.par_chunks_mut(w)
        .zip(img.par_chunks(w))
        .for_each(|(out, row)| {
            if w > 2 * r {
                for (j, kv) in k.iter().enumerate() {
                    let src = &row[j..j + w - 2 * r];
                    for (o, s) in out[r..w - r].iter_mut().zip(src) {
                        *o += kv * s;
                    }
                }
            }
            let border = (0..r.min(w)).chain(w.saturating_sub(r).max(r.min(w))..w);
            for u in border {
                let mut acc = 0.0f32;
                for (j, kv) in k.iter().enumerate() {
                    let x = (u + j).saturating_sub(r).min(w - 1);
                    acc += kv * row[x];
                }
                out[u] = acc;
            }
        });
    // Vertical pass.
    img.par_chunks_mut(w).enumerate().for_each(|(v, out)| {
        out.iter_mut().for_each(|o| *o = 0.0);
        for (j, kv) in k.iter().enumerate() {
            let y = (v + j).saturating_sub(r).min(h - 1);
            let src = &tmp[y * w..(y + 1) * w];
            for (o, s) in out.iter_mut().zip(src) {
                *o += kv * s;
            }
        }
    });
}

/// Adds N(0, sigma²) noise (grey levels) and quantises to u8 (rounded half up, clamped to
/// [0, 255]). Each row draws from its own PCG stream seeded from `(seed, row)`, so
/// the result does not depend on the thread schedule.
pub(crate) fn noise_quantise(img: &[f32], w: usize, sigma: f64, seed: u64) -> Vec<u8> {
    let mut out = vec![0u8; img.len()];
    if w == 0 {
        return out;
    }
    out.par_chunks_mut(w)
        .zip(img.par_chunks(w))
        .enumerate()
        .for_each(|(v, (o, row))| {
            if sigma > 0.0 {
                let mut rng = Pcg64Mcg::seed_from_u64(mix(seed, v as u64));
                for (q, x) in o.iter_mut().zip(row) {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    *q = quantise(*x as f64 + sigma * z);
                }
            } else {
                for (q, x) in o.iter_mut().zip(row) {
                    *q = quantise(*x as f64);
                }
            }
        });
    out
}

/// Rounds half up and clamps to [0, 255] (NaN → 0).
#[inline]
fn quantise(x: f64) -> u8 {
    // After the clamp, +0.5 and truncation round half up; `as` maps NaN to 0.
    (x.clamp(0.0, 255.0) + 0.5) as u8
}

/// SplitMix64 of a seed and a stream index.
fn mix(seed: u64, stream: u64) -> u64 {
    let mut z = seed
        ^ stream
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(0x6A09_E667_F3BC_C909);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_is_normalised_and_symmetric() {
        let k = gaussian_kernel(0.8);
        assert_eq!(k.len(), 7);
        let s: f32 = k.iter().sum();
        assert!((s - 1.0).abs() < 1e-6);
        for i in 0..k.len() {
            assert_eq!(k[i], k[k.len() - 1 - i]);
        }
        // Discrete variance close to sigma² (truncation at 3σ loses little).
        let var: f64 = k
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 - 3.0).powi(2) * *v as f64)
            .sum();
        assert!((var - 0.64).abs() < 0.02, "variance {var}");
    }

    #[test]
    fn blur_keeps_constant_images_and_step_midpoints() {
        let (w, h) = (20, 9);
        for (w, h) in [(w, h), (4, 3), (1, 1)] {
            let mut img = vec![7.0f32; w * h];
            blur(&mut img, w, h, 1.3);
            assert!(img.iter().all(|x| (x - 7.0).abs() < 1e-4), "{w}x{h}");
        }
        // A vertical step between columns 9 and 10: the blurred profile stays antisymmetric
        // about u = 9.5.
        let mut img: Vec<f32> = (0..w * h)
            .map(|i| if i % w >= 10 { 100.0 } else { 0.0 })
            .collect();
        blur(&mut img, w, h, 0.8);
        // The interior fast path and the clamped border agree with a direct evaluation.
        let k = gaussian_kernel(0.8);
        for u in 0..w {
            let direct: f32 = (0..k.len())
                .map(|j| {
                    k[j] * if (u + j).saturating_sub(3).min(w - 1) >= 10 {
                        100.0
                    } else {
                        0.0
                    }
                })
                .sum();
            assert!(
                (img[4 * w + u] - direct).abs() < 1e-3,
                "u={u}: {} vs {direct}",
                img[4 * w + u]
            );
        }
        for u in 0..10 {
            let a = img[4 * w + u];
            let b = img[4 * w + (w - 1 - u)];
            assert!((a + b - 100.0).abs() < 1e-3, "u={u}: {a} + {b}");
        }
    }

    #[test]
    fn quantisation_rounds_and_clamps() {
        let cases = [
            (-3.0, 0),
            (0.49, 0),
            (0.5, 1),
            (1.5, 2),
            (254.49, 254),
            (254.5, 255),
            (300.0, 255),
            (f64::NAN, 0),
        ];
        for (x, q) in cases {
            assert_eq!(quantise(x), q, "{x}");
        }
    }

    #[test]
    fn noise_has_requested_sigma() {
        let w = 200;
        let img = vec![100.0f32; w * 100];
        let q = noise_quantise(&img, w, 3.0, 42);
        let n = q.len() as f64;
        let mean = q.iter().map(|&x| x as f64).sum::<f64>() / n;
        let var = q.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n;
        assert!((mean - 100.0).abs() < 0.05, "mean {mean}");
        // Quantisation adds 1/12 to the variance.
        assert!((var - 9.0 - 1.0 / 12.0).abs() < 0.3, "var {var}");
    }
}
