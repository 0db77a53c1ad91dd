//! A bird's-eye-view LiDAR simulator of cars, for testing the label uncertainty of ch. 8.
//!
//! A scanner at the origin casts rays at a fixed azimuth step; each ray that hits a car's box
//! returns its first intersection with the boundary, so a car seen from outside shows one or
//! two sides (the "L shape" of §8.5, Fig. 8.9). Each hit gets isotropic Gaussian noise of
//! standard deviation `sigma` in both coordinates (the generative model of eq. 8.7), and with
//! probability `occlusion` a random contiguous run of up to `max_occluded` of the car's rays
//! is removed (an occluder in front of it).

use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

use super::Box2;
use crate::{GeometryError, Result};

/// Options of [`simulate_cars`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanOptions {
    /// Azimuth step between rays (radians).
    pub azimuth_step: f64,
    /// Noise standard deviation of every hit coordinate (m).
    pub sigma: f64,
    /// Probability that a car is partly occluded.
    pub occlusion: f64,
    /// Largest occluded fraction of a car's rays.
    pub max_occluded: f64,
    /// Range of car centres from the scanner (m).
    pub range: (f64, f64),
    /// Mean and standard deviation of car lengths (m).
    pub length: (f64, f64),
    /// Mean and standard deviation of car widths (m).
    pub width: (f64, f64),
}

impl Default for ScanOptions {
    fn default() -> Self {
        Self {
            azimuth_step: 0.2_f64.to_radians(),
            sigma: 0.2,
            occlusion: 0.3,
            max_occluded: 0.5,
            range: (6.0, 30.0),
            length: (4.2, 0.3),
            width: (1.8, 0.1),
        }
    }
}

/// First intersection `t > 0` of the ray `t·(cos θ, sin θ)` from the origin with the box.
pub fn ray_hit(b: &Box2, theta: f64) -> Option<f64> {
    let (s, c) = b.r.sin_cos();
    // Ray in box coordinates.
    let (ox, oy) = (-(c * b.cx + s * b.cy), -(-s * b.cx + c * b.cy));
    let (dx, dy) = (
        c * theta.cos() + s * theta.sin(),
        -s * theta.cos() + c * theta.sin(),
    );
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for (o, d, h) in [(ox, dx, 0.5 * b.l), (oy, dy, 0.5 * b.w)] {
        if d.abs() < 1e-15 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let (a, z) = ((-h - o) / d, (h - o) / d);
        t0 = t0.max(a.min(z));
        t1 = t1.min(a.max(z));
    }
    (t1 >= t0 && t0 > 0.0).then_some(t0)
}

/// One scan of `b` from the origin: the noisy hits (before occlusion is applied when
/// `occlusion` is false).
pub fn scan_box<R: Rng>(
    b: &Box2,
    opts: &ScanOptions,
    occlude: bool,
    rng: &mut R,
) -> Result<Vec<[f64; 2]>> {
    check(opts)?;
    if b.contains([0.0, 0.0]) {
        return Err(GeometryError::InvalidParameter {
            what: "box",
            value: b.cx.hypot(b.cy),
            reason: "the scanner (origin) lies inside the box",
        });
    }
    let corners = b.corners();
    let angles: Vec<f64> = corners.iter().map(|p| p[1].atan2(p[0])).collect();
    // Angular span around the centre direction (boxes never contain the origin).
    let centre = b.cy.atan2(b.cx);
    let wrap = |a: f64| {
        (a - centre + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI
    };
    let lo = angles
        .iter()
        .map(|a| wrap(*a))
        .fold(f64::INFINITY, f64::min)
        + centre;
    let hi = angles
        .iter()
        .map(|a| wrap(*a))
        .fold(f64::NEG_INFINITY, f64::max)
        + centre;
    let k0 = (lo / opts.azimuth_step).ceil() as i64;
    let k1 = (hi / opts.azimuth_step).floor() as i64;
    let mut rays: Vec<f64> = (k0..=k1).map(|k| k as f64 * opts.azimuth_step).collect();
    if occlude && !rays.is_empty() {
        let frac = rng.random_range(0.0..=opts.max_occluded);
        let n = ((rays.len() as f64) * frac).round() as usize;
        if n > 0 && n < rays.len() {
            let start = rng.random_range(0..=rays.len() - n);
            rays.drain(start..start + n);
        }
    }
    let noise = Normal::new(0.0, opts.sigma).map_err(|_| GeometryError::InvalidParameter {
        what: "sigma",
        value: opts.sigma,
        reason: "noise must be finite and non-negative",
    })?;
    Ok(rays
        .iter()
        .filter_map(|&th| ray_hit(b, th).map(|t| (th, t)))
        .map(|(th, t)| {
            [
                t * th.cos() + noise.sample(rng),
                t * th.sin() + noise.sample(rng),
            ]
        })
        .collect())
}

fn check(opts: &ScanOptions) -> Result<()> {
    let ok = opts.azimuth_step > 0.0
        && opts.sigma >= 0.0
        && (0.0..=1.0).contains(&opts.occlusion)
        && (0.0..1.0).contains(&opts.max_occluded)
        && opts.range.0 > 0.0
        && opts.range.1 >= opts.range.0
        && opts.length.0 > 0.0
        && opts.width.0 > 0.0
        && opts.length.1 >= 0.0
        && opts.width.1 >= 0.0;
    if !ok {
        return Err(GeometryError::InvalidParameter {
            what: "scan options",
            value: opts.sigma,
            reason: "need azimuth_step > 0, sigma ≥ 0, occlusion ∈ [0,1], max_occluded ∈ [0,1), 0 < range.0 ≤ range.1, positive mean sizes",
        });
    }
    Ok(())
}

/// `n` cars at random positions and headings around the scanner, each with its scan (cars
/// with fewer than `min_points` hits are redrawn). Deterministic for a seed.
pub fn simulate_cars(
    n: usize,
    opts: &ScanOptions,
    min_points: usize,
    seed: u64,
) -> Result<Vec<(Box2, Vec<[f64; 2]>)>> {
    check(opts)?;
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    let mut tries = 0usize;
    while out.len() < n {
        tries += 1;
        if tries > 100 * (n + 10) {
            return Err(GeometryError::InvalidParameter {
                what: "min_points",
                value: min_points as f64,
                reason: "cars rarely get that many hits with these options",
            });
        }
        let range = rng.random_range(opts.range.0..=opts.range.1);
        let bearing = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
        let l =
            (opts.length.0 + opts.length.1 * StdNormal.sample(&mut rng)).max(0.5 * opts.length.0);
        let w = (opts.width.0 + opts.width.1 * StdNormal.sample(&mut rng)).max(0.5 * opts.width.0);
        let heading = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
        let b = Box2::new(range * bearing.cos(), range * bearing.sin(), l, w, heading)?;
        if b.contains([0.0, 0.0]) {
            continue;
        }
        let occlude = rng.random_bool(opts.occlusion);
        let pts = scan_box(&b, opts, occlude, &mut rng)?;
        if pts.len() >= min_points.max(1) {
            out.push((b, pts));
        }
    }
    Ok(out)
}

/// The standard normal distribution (a zero-sized helper).
struct StdNormal;

impl Distribution<f64> for StdNormal {
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        rand_distr::StandardNormal.sample(rng)
    }
}
