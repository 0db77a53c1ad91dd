//! Renderer of a chamber-opening image (seed 000_3b1454b2b2194811.txt §3.3, "Detection of
//! Chamber Openings in RGB image", Figs. 3.7–3.8): a plate with a dark polygonal opening (and
//! optionally similar distracting shapes) lying in a plane that the camera sees through the plane
//! homography `H` of eq. (3.8) (reference-plane point `(u₀, v₀)` ↦ pixel `(u, v)` ∝
//! `H (u₀, v₀, 1)ᵀ`), plus image-space clutter: straight lines (cables, plate seams) and occluders
//! drawn over the plate.
//!
//! Image formation: each pixel is the box-filtered mean of `s×s` sub-samples (pixel `(u, v)` is
//! centred at image position `(u, v)` and covers `[u − ½, u + ½] × [v − ½, v + ½]`), then a
//! separable Gaussian blur (optical blur), additive Gaussian noise from a seeded generator and
//! rounding to u8 — the same post-processing as the carrier renderer.
//!
//! ```
//! use autoteach_geometry::render::opening::{render_opening, OpeningScene, Placement, RefPolygon};
//! use nalgebra::{Matrix3, Vector2};
//!
//! let square = vec![Vector2::new(-20.0, -20.0), Vector2::new(20.0, -20.0),
//!                   Vector2::new(20.0, 20.0), Vector2::new(-20.0, 20.0)];
//! let place = Placement { centre: Vector2::new(50.0, 40.0), rotation: 0.0, scale: 1.0 };
//! let scene = OpeningScene {
//!     width: 100, height: 80, homography: Matrix3::identity(), plate: 200.0,
//!     polygons: vec![RefPolygon { vertices: place.apply(&square), intensity: 30.0 }],
//!     lines: vec![], occluders: vec![], supersample: 4, blur_sigma: 0.0, noise_sigma: 0.0, seed: 0,
//! };
//! let img = render_opening(&scene)?;
//! assert_eq!(img.get(50, 40), Some(30));
//! assert_eq!(img.get(5, 5), Some(200));
//! # Ok::<(), autoteach_geometry::GeometryError>(())
//! ```

use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;

use super::GrayImage;
use super::post::{blur, noise_quantise};
use crate::error::check_finite;
use crate::{GeometryError, Result};

/// Placement of a template polygon in the reference plane: `p = centre + scale · R(rotation) · v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Centre (template origin) in the reference plane.
    pub centre: Vector2<f64>,
    /// Rotation about the centre, radians (counter-clockwise in `(u₀, v₀)`).
    pub rotation: f64,
    /// Uniform scale.
    pub scale: f64,
}

impl Placement {
    /// The template's vertices placed in the reference plane.
    pub fn apply(&self, template: &[Vector2<f64>]) -> Vec<Vector2<f64>> {
        let (s, c) = self.rotation.sin_cos();
        template
            .iter()
            .map(|v| self.centre + self.scale * Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y))
            .collect()
    }
}

/// A filled polygon in the reference plane (the opening or a distracting shape).
#[derive(Debug, Clone, PartialEq)]
pub struct RefPolygon {
    /// Vertices in the reference plane (any orientation, simple polygon).
    pub vertices: Vec<Vector2<f64>>,
    /// Grey level inside.
    pub intensity: f64,
}

/// A straight line drawn in the image (clutter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageLine {
    /// First end point (pixels).
    pub a: Vector2<f64>,
    /// Second end point (pixels).
    pub b: Vector2<f64>,
    /// Width in pixels.
    pub width: f64,
    /// Grey level.
    pub intensity: f64,
}

/// A filled polygon drawn in the image over everything else (an occluder).
#[derive(Debug, Clone, PartialEq)]
pub struct ImagePolygon {
    /// Vertices in pixels.
    pub vertices: Vec<Vector2<f64>>,
    /// Grey level inside.
    pub intensity: f64,
}

/// Everything the opening renderer draws.
#[derive(Debug, Clone, PartialEq)]
pub struct OpeningScene {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Plane homography `H` (reference plane → image), eq. (3.8).
    pub homography: Matrix3<f64>,
    /// Grey level of the plate.
    pub plate: f64,
    /// Polygons in the reference plane, drawn in order over the plate.
    pub polygons: Vec<RefPolygon>,
    /// Image lines drawn over the plane.
    pub lines: Vec<ImageLine>,
    /// Image polygons drawn last (occluders).
    pub occluders: Vec<ImagePolygon>,
    /// Sub-samples per pixel side (≥ 1).
    pub supersample: usize,
    /// Gaussian blur sigma in pixels (0: none).
    pub blur_sigma: f64,
    /// Additive Gaussian noise sigma in grey levels (0: none).
    pub noise_sigma: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

/// Even–odd point-in-polygon test.
fn inside(p: &Vector2<f64>, poly: &[Vector2<f64>]) -> bool {
    let mut c = false;
    let n = poly.len();
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y) {
            c = !c;
        }
    }
    c
}

fn segment_distance(p: &Vector2<f64>, a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    let d = b - a;
    let l2 = d.norm_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(&d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + d * t)).norm()
}

fn validate(scene: &OpeningScene) -> Result<()> {
    if scene.width == 0 || scene.height == 0 {
        return Err(GeometryError::InvalidParameter {
            what: "width/height",
            value: (scene.width.min(scene.height)) as f64,
            reason: "image must have at least one pixel",
        });
    }
    if scene.supersample == 0 || scene.supersample > 16 {
        return Err(GeometryError::InvalidParameter {
            what: "supersample",
            value: scene.supersample as f64,
            reason: "must be in 1..=16",
        });
    }
    for &v in scene.homography.iter() {
        check_finite("homography", &[v])?;
    }
    if scene.homography.determinant().abs() < 1e-300 {
        return Err(GeometryError::InvalidParameter {
            what: "homography determinant",
            value: scene.homography.determinant(),
            reason: "the homography must be invertible",
        });
    }
    for (what, v) in [
        ("plate", scene.plate),
        ("blur_sigma", scene.blur_sigma),
        ("noise_sigma", scene.noise_sigma),
    ] {
        check_finite(what, &[v])?;
    }
    if scene.blur_sigma < 0.0 || scene.noise_sigma < 0.0 {
        return Err(GeometryError::InvalidParameter {
            what: "blur_sigma/noise_sigma",
            value: scene.blur_sigma.min(scene.noise_sigma),
            reason: "must be non-negative",
        });
    }
    // The blur kernel has 2·⌈3σ⌉ + 1 taps: a σ beyond the image's size flattens it and, at
    // σ ≈ 1e300, asked for a kernel no allocator gives (the process aborted).
    let extent = scene.width.max(scene.height) as f64;
    if scene.blur_sigma > extent {
        return Err(GeometryError::InvalidParameter {
            what: "blur_sigma",
            value: scene.blur_sigma,
            reason: "must not exceed the image's larger side in pixels",
        });
    }
    for poly in &scene.polygons {
        if poly.vertices.len() < 3 {
            return Err(GeometryError::WrongLength {
                what: "polygon vertices",
                got: poly.vertices.len(),
                expected: 3,
            });
        }
        check_finite("polygon intensity", &[poly.intensity])?;
        for v in &poly.vertices {
            check_finite("polygon vertex", &[v.x])?;
            check_finite("polygon vertex", &[v.y])?;
        }
    }
    for o in &scene.occluders {
        if o.vertices.len() < 3 {
            return Err(GeometryError::WrongLength {
                what: "occluder vertices",
                got: o.vertices.len(),
                expected: 3,
            });
        }
        check_finite("occluder intensity", &[o.intensity])?;
        for v in &o.vertices {
            check_finite("occluder vertex", &[v.x])?;
            check_finite("occluder vertex", &[v.y])?;
        }
    }
    for l in &scene.lines {
        for v in [l.a.x, l.a.y, l.b.x, l.b.y, l.width, l.intensity] {
            check_finite("line", &[v])?;
        }
    }
    Ok(())
}

/// Renders the scene (see the module docs). Errors: empty image, `supersample ∉ 1..=16`,
/// non-finite or singular homography, NaN anywhere, negative blur/noise, polygons with fewer
/// than 3 vertices.
pub fn render_opening(scene: &OpeningScene) -> Result<GrayImage> {
    validate(scene)?;
    let (w, h, s) = (scene.width, scene.height, scene.supersample);
    let hinv = scene
        .homography
        .try_inverse()
        .ok_or(GeometryError::InvalidParameter {
            what: "homography determinant",
            value: scene.homography.determinant(),
            reason: "the homography must be invertible",
        })?;
    // Sizes from the caller: the image, the blur's scratch copy and the 8-bit result must fit.
    let n = crate::alloc::checked_count("opening image pixels", w, h)?;
    let mut img = crate::alloc::try_filled("opening image pixels", n, 0f32)?;
    crate::alloc::ensure_fits::<f32>("opening blur buffer", n)?;
    crate::alloc::ensure_fits::<u8>("opening image", n)?;
    img.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for (u, px) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for sy in 0..s {
                for sx in 0..s {
                    let p = Vector2::new(
                        u as f64 - 0.5 + (sx as f64 + 0.5) / s as f64,
                        v as f64 - 0.5 + (sy as f64 + 0.5) / s as f64,
                    );
                    acc += sample(scene, &hinv, &p);
                }
            }
            *px = (acc / (s * s) as f64) as f32;
        }
    });
    blur(&mut img, w, h, scene.blur_sigma);
    Ok(GrayImage {
        width: w,
        height: h,
        data: noise_quantise(&img, w, scene.noise_sigma, scene.seed),
    })
}

/// Grey level at image position `p`.
fn sample(scene: &OpeningScene, hinv: &Matrix3<f64>, p: &Vector2<f64>) -> f64 {
    if let Some(o) = scene
        .occluders
        .iter()
        .rev()
        .find(|o| inside(p, &o.vertices))
    {
        return o.intensity;
    }
    if let Some(l) = scene
        .lines
        .iter()
        .rev()
        .find(|l| segment_distance(p, &l.a, &l.b) <= 0.5 * l.width)
    {
        return l.intensity;
    }
    let q = hinv * Vector3::new(p.x, p.y, 1.0);
    if q.z.abs() > 1e-300 {
        let r = Vector2::new(q.x / q.z, q.y / q.z);
        if let Some(poly) = scene
            .polygons
            .iter()
            .rev()
            .find(|poly| inside(&r, &poly.vertices))
        {
            return poly.intensity;
        }
    }
    scene.plate
}

/// Image position of a reference-plane point under `H` (eq. 3.8), or `None` at infinity.
pub fn to_image(homography: &Matrix3<f64>, p: &Vector2<f64>) -> Option<Vector2<f64>> {
    let q = homography * Vector3::new(p.x, p.y, 1.0);
    (q.z.abs() > 1e-300).then(|| Vector2::new(q.x / q.z, q.y / q.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Vec<Vector2<f64>> {
        vec![
            Vector2::new(-10.0, -10.0),
            Vector2::new(10.0, -10.0),
            Vector2::new(10.0, 10.0),
            Vector2::new(-10.0, 10.0),
        ]
    }

    fn scene(h: Matrix3<f64>) -> OpeningScene {
        OpeningScene {
            width: 64,
            height: 48,
            homography: h,
            plate: 200.0,
            polygons: vec![RefPolygon {
                vertices: Placement {
                    centre: Vector2::new(30.25, 20.0),
                    rotation: 0.0,
                    scale: 1.0,
                }
                .apply(&square()),
                intensity: 40.0,
            }],
            lines: vec![],
            occluders: vec![],
            supersample: 8,
            blur_sigma: 0.0,
            noise_sigma: 0.0,
            seed: 1,
        }
    }

    /// The dark area equals the polygon's image area (coverage is exact up to the sub-sampling).
    #[test]
    fn dark_area_matches_projected_polygon_area() {
        let h = Matrix3::new(1.1, 0.1, 2.0, -0.05, 0.95, 1.0, 0.0005, 0.0002, 1.0);
        let sc = scene(h);
        let img = render_opening(&sc).unwrap();
        let dark: f64 = img.data.iter().map(|&g| (200.0 - g as f64) / 160.0).sum();
        let poly: Vec<Vector2<f64>> = sc.polygons[0]
            .vertices
            .iter()
            .map(|p| to_image(&h, p).unwrap())
            .collect();
        let area = 0.5
            * (0..poly.len())
                .map(|k| {
                    let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
                    a.x * b.y - b.x * a.y
                })
                .sum::<f64>()
                .abs();
        assert!((dark - area).abs() < 0.01 * area + 2.0, "{dark} vs {area}");
    }

    /// A vertical edge at u = 20.25 darkens pixel column u = 20 by a quarter.
    #[test]
    fn edge_coverage_is_subpixel() {
        let img = render_opening(&scene(Matrix3::identity())).unwrap();
        let g = img.get(20, 20).unwrap() as f64;
        // Pixel 20 covers [19.5, 20.5]; the opening starts at 20.25: 25 % dark.
        assert!((g - (200.0 - 0.25 * 160.0)).abs() <= 1.0, "{g}");
        assert_eq!(img.get(25, 20), Some(40));
    }

    #[test]
    fn occluders_and_lines_draw_on_top() {
        let mut sc = scene(Matrix3::identity());
        sc.lines.push(ImageLine {
            a: Vector2::new(0.0, 5.0),
            b: Vector2::new(63.0, 5.0),
            width: 3.0,
            intensity: 90.0,
        });
        sc.occluders.push(ImagePolygon {
            vertices: vec![
                Vector2::new(25.0, 15.0),
                Vector2::new(40.0, 15.0),
                Vector2::new(40.0, 40.0),
            ],
            intensity: 250.0,
        });
        let img = render_opening(&sc).unwrap();
        assert_eq!(img.get(10, 5), Some(90));
        assert_eq!(img.get(38, 20), Some(250));
    }

    #[test]
    fn bad_scenes_are_errors() {
        let mut sc = scene(Matrix3::zeros());
        assert!(render_opening(&sc).is_err());
        sc.homography = Matrix3::identity();
        sc.supersample = 0;
        assert!(render_opening(&sc).is_err());
        sc.supersample = 2;
        sc.polygons[0].vertices.truncate(2);
        assert!(render_opening(&sc).is_err());
        let mut sc = scene(Matrix3::identity());
        sc.plate = f64::NAN;
        assert!(render_opening(&sc).is_err());
    }
}
