//! Ray-cast renderer of the simulated wafer carrier, and the exact ground truth of the visible
//! wafer rims.
//!
//! The scene (see [`Scene`]) is a stack of wafers — thin reflective discs whose cylindrical
//! side face shows as a bright band bounded by an upper and a lower rim edge — in a carrier
//! whose walls and slot ridges add straight-line clutter (000_3b1454b2b2194811.txt §3.2,
//! Fig. 3.2: "The surface of the wafer is reflective. The bright boundary of the wafer forms two
//! edges: an upper one corresponding to the upper surface and lower one corresponding to the
//! lower surface"; "only less than half of the boundary is visible for a wafer in the FOUP").
//!
//! Image formation (OpenCV convention: pixel `(u, v)` is centred at image position `(u, v)`):
//! 1. rays through pixel positions, unprojected by the camera model (so distortion renders
//!    exactly; see `rays.rs`), traced against the wafers (slabs) and the carrier's boxes. The
//!    wafer's top/bottom faces are dark mirrors that add `reflectivity ×` the radiance seen
//!    along the reflected ray (one bounce): mirrored rims of neighbouring wafers, mirrored
//!    ridges. Surfaces are shaded with a directional light (see [`Shading`]).
//! 2. Where to sample (`raster.rs`): pixel centres on a 4-px grid, refined to 2 px and 1 px
//!    by bilinear interpolation inside cells whose corners see the same surface and tracing
//!    elsewhere; then anti-aliasing of the pixels that a surface boundary crosses (found by
//!    one ray between neighbouring centres that see different surfaces) as the box-filtered
//!    mean of `s×s` sub-samples in an n-rooks pattern (all `s²` sub-sample rows and columns
//!    distinct, so near-horizontal and near-vertical edges get `1/s²` coverage resolution;
//!    low-contrast boundaries get `min(s, 2)²`).
//! 3. Lighting `255·gain·(1 + gx·x̂ + gy·ŷ)`, separable Gaussian blur (optical blur),
//!    additive Gaussian sensor noise from a seeded PCG generator, rounding to u8.
//!
//! [`rim_visibility`] gives the ground truth of the same geometry: per wafer and rim, the
//! image ellipse, the visible circle-angle intervals and the visible points.
//!
//! ```
//! use autoteach_geometry::camera::Camera;
//! use autoteach_geometry::render::{self, Carrier, RenderOptions, Scene};
//! use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
//!
//! let carrier = Carrier::default();
//! let scene = Scene::new((1..=26).map(|k| carrier.slot_pose(k)).collect());
//! let camera = Camera::pinhole(300.0, 300.0, 159.5, 119.5, 320, 240)?;
//! // Camera 0.45 m in front of the carrier at mid height, looking along +x (image x = −y).
//! let axes = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
//! let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
//! let t_wc = Isometry3::from_parts(Translation3::new(-0.45, 0.0, 0.125), rot);
//! let image = render::render(&scene, &camera, &t_wc, &RenderOptions::default())?;
//! assert_eq!(image.data.len(), 320 * 240);
//! let truth = render::rim_visibility(&scene, &camera, &t_wc, 360)?;
//! assert_eq!(truth.len(), 2 * 26);
//! assert!(truth.iter().any(|t| t.fraction > 0.0));
//! # Ok::<(), autoteach_geometry::GeometryError>(())
//! ```

pub mod opening;
mod post;
mod raster;
mod rays;
mod scene;
mod trace;
mod truth;

pub use scene::{Carrier, Scene, WaferShape};
pub use truth::{Rim, RimTruth, rim_points_visible, rim_visibility};

use nalgebra::{Isometry3, Matrix3, Vector2, Vector3};

use crate::camera::Camera;
use crate::error::check_finite;
use crate::{GeometryError, Result};

/// What the renderer needs from a camera model: the ray of a pixel position and the projection
/// of a point. Positions follow the OpenCV convention (pixel `(u, v)` is centred at `(u, v)`),
/// the camera frame has z forward, x right, y down.
pub(crate) trait RayCamera: Sync {
    /// Image width in pixels.
    fn width(&self) -> usize;
    /// Image height in pixels.
    fn height(&self) -> usize;
    /// Direction (camera frame, any positive length) of the ray through pixel position
    /// `(u, v)`, or `None` where the model has no ray.
    fn bearing(&self, u: f64, v: f64) -> Option<Vector3<f64>>;
    /// Pixel position of a camera-frame point, or `None` if it cannot be projected.
    fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>>;
    /// Intrinsic matrix `K` of the model's pinhole part (used for the ground-truth ellipses).
    fn k_matrix(&self) -> Matrix3<f64>;
}

/// Surface appearance, in linear radiance (1.0 = 255 grey levels at unit gain).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// Radiance of rays that escape the scene (35/255).
    pub background: f64,
    /// Unit direction toward the directional light, world frame (default from the front and
    /// above: `(−1, 0, 1)/√2`).
    pub light_dir: Vector3<f64>,
    /// Ambient fraction of the carrier's Lambertian shading `albedo·(ambient + (1 − ambient)·max(0, n·l))`.
    pub ambient: f64,
    /// Albedo of the side walls.
    pub wall_albedo: f64,
    /// Albedo of the top and bottom plates.
    pub plate_albedo: f64,
    /// Albedo of the slot ridges (brighter than the walls).
    pub ridge_albedo: f64,
    /// Albedo of the back wall (dark, about the background level).
    pub back_albedo: f64,
    /// Albedo of the wafer's side face (the bright rim band).
    pub rim_albedo: f64,
    /// Ambient fraction of the rim shading.
    pub rim_ambient: f64,
    /// Own radiance of the wafer's polished top and bottom faces.
    pub face_base: f64,
    /// Mirror reflectance of the wafer's top and bottom faces.
    pub reflectivity: f64,
}

impl Default for Shading {
    fn default() -> Self {
        Self {
            background: 35.0 / 255.0,
            light_dir: Vector3::new(-1.0, 0.0, 1.0).normalize(),
            ambient: 0.6,
            wall_albedo: 0.55,
            plate_albedo: 0.5,
            ridge_albedo: 0.62,
            back_albedo: 0.155,
            rim_albedo: 0.92,
            rim_ambient: 0.8,
            face_base: 0.09,
            reflectivity: 0.3,
        }
    }
}

impl Shading {
    fn validate(&self) -> Result<()> {
        check_finite("light_dir", self.light_dir.as_slice())?;
        let n = self.light_dir.norm();
        if (n - 1.0).abs() > 1e-6 {
            return Err(GeometryError::InvalidParameter {
                what: "light_dir norm",
                value: n,
                reason: "must be 1",
            });
        }
        for (what, v) in [
            ("background", self.background),
            ("ambient", self.ambient),
            ("wall_albedo", self.wall_albedo),
            ("plate_albedo", self.plate_albedo),
            ("ridge_albedo", self.ridge_albedo),
            ("back_albedo", self.back_albedo),
            ("rim_albedo", self.rim_albedo),
            ("rim_ambient", self.rim_ambient),
            ("face_base", self.face_base),
            ("reflectivity", self.reflectivity),
        ] {
            non_negative(what, v)?;
        }
        Ok(())
    }
}

/// Per-frame rendering options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Global gain (1.0).
    pub gain: f64,
    /// Linear lighting gradient `(gx, gy)`: the gain is multiplied by `1 + gx·x̂ + gy·ŷ`, with
    /// `x̂, ŷ` running from −1 (left/top) to 1 (right/bottom). Default `(0, 0)`.
    pub gradient: [f64; 2],
    /// Standard deviation of the Gaussian optical blur in pixels (0.8; 0 disables).
    pub blur_sigma: f64,
    /// Standard deviation of the additive sensor noise in grey levels (2.0; 0 disables).
    pub noise_sigma: f64,
    /// Anti-aliasing: `s×s` rays per edge pixel (4; 1 disables anti-aliasing).
    pub supersample: usize,
    /// Seed of the noise generator; the same seed gives identical bytes.
    pub seed: u64,
    /// Surface appearance.
    pub shading: Shading,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            gain: 1.0,
            gradient: [0.0, 0.0],
            blur_sigma: 0.8,
            noise_sigma: 2.0,
            supersample: 4,
            seed: 0,
            shading: Shading::default(),
        }
    }
}

impl RenderOptions {
    /// Fails on negative or non-finite values, or `supersample` outside `1..=16`.
    pub fn validate(&self) -> Result<()> {
        non_negative("gain", self.gain)?;
        check_finite("gradient", &self.gradient)?;
        non_negative("blur_sigma", self.blur_sigma)?;
        if self.blur_sigma > 100.0 {
            return Err(GeometryError::InvalidParameter {
                what: "blur_sigma",
                value: self.blur_sigma,
                reason: "must be at most 100 pixels",
            });
        }
        non_negative("noise_sigma", self.noise_sigma)?;
        if !(1..=16).contains(&self.supersample) {
            return Err(GeometryError::InvalidParameter {
                what: "supersample",
                value: self.supersample as f64,
                reason: "must be in 1..=16",
            });
        }
        self.shading.validate()
    }
}

/// An 8-bit grayscale image, row-major (`data[v·width + u]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GrayImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixel values, `height·width` bytes.
    pub data: Vec<u8>,
}

impl GrayImage {
    /// Value of pixel `(u, v)`, or `None` outside the image.
    pub fn get(&self, u: usize, v: usize) -> Option<u8> {
        (u < self.width && v < self.height).then(|| self.data[v * self.width + u])
    }
}

fn non_negative(what: &'static str, value: f64) -> Result<()> {
    if !value.is_finite() {
        return Err(GeometryError::NonFinite { what, value });
    }
    if value < 0.0 {
        return Err(GeometryError::InvalidParameter {
            what,
            value,
            reason: "must be non-negative",
        });
    }
    Ok(())
}

/// Validates the common inputs of a render or visibility call.
fn validate_inputs<C: RayCamera>(scene: &Scene, cam: &C, t_wc: &Isometry3<f64>) -> Result<()> {
    if cam.width() == 0 || cam.height() == 0 {
        return Err(GeometryError::InvalidParameter {
            what: "image size",
            value: (cam.width() * cam.height()) as f64,
            reason: "width and height must be positive",
        });
    }
    scene.validate()?;
    scene::validate_pose("t_wc", t_wc)
}

/// Renders the grey levels of a frame after lighting and blur, before noise and quantisation
/// (row-major `height·width` values, nominally 0–255 but not clamped). See [`render`].
///
/// # Errors
/// As [`render`].
pub fn render_float(
    scene: &Scene,
    camera: &Camera,
    t_wc: &Isometry3<f64>,
    opts: &RenderOptions,
) -> Result<Vec<f32>> {
    render_float_with(scene, &rays::Rays::new(camera), t_wc, opts)
}

/// Renders the 8-bit grayscale frame of `scene` seen by `camera` at pose `t_wc` (camera →
/// world): see the module documentation for the image formation.
///
/// Deterministic: the same inputs and `opts.seed` give identical bytes on any number of
/// threads. Runs in parallel over image rows (rayon). For the distortion models the first frame
/// of a camera also computes its table of pixel bearings (kept for the next frames).
///
/// # Errors
/// [`GeometryError::InvalidParameter`] for a non-positive wafer size, an invalid carrier or
/// option; [`GeometryError::NonFinite`] for NaN/inf values; [`GeometryError::AtIndex`] naming
/// the first invalid wafer pose.
pub fn render(
    scene: &Scene,
    camera: &Camera,
    t_wc: &Isometry3<f64>,
    opts: &RenderOptions,
) -> Result<GrayImage> {
    render_with(scene, &rays::Rays::new(camera), t_wc, opts)
}

fn render_float_with<C: RayCamera>(
    scene: &Scene,
    cam: &C,
    t_wc: &Isometry3<f64>,
    opts: &RenderOptions,
) -> Result<Vec<f32>> {
    validate_inputs(scene, cam, t_wc)?;
    opts.validate()?;
    let mut img = raster::radiance(scene, cam, t_wc, opts);
    let (w, h) = (cam.width(), cam.height());
    post::apply_lighting(&mut img, w, h, opts.gain, opts.gradient);
    post::blur(&mut img, w, h, opts.blur_sigma);
    Ok(img)
}

fn render_with<C: RayCamera>(
    scene: &Scene,
    cam: &C,
    t_wc: &Isometry3<f64>,
    opts: &RenderOptions,
) -> Result<GrayImage> {
    let img = render_float_with(scene, cam, t_wc, opts)?;
    let data = post::noise_quantise(&img, cam.width(), opts.noise_sigma, opts.seed);
    Ok(GrayImage {
        width: cam.width(),
        height: cam.height(),
        data,
    })
}

/// The camera itself: exact unprojection for every ray (the renderer wraps it in
/// [`rays::Rays`], which is faster for the distortion models).
impl RayCamera for Camera {
    fn width(&self) -> usize {
        Camera::width(self) as usize
    }

    fn height(&self) -> usize {
        Camera::height(self) as usize
    }

    fn bearing(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        self.unproject(&Vector2::new(u, v)).ok()
    }

    fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        Camera::project(self, p).ok()
    }

    fn k_matrix(&self) -> Matrix3<f64> {
        Camera::k_matrix(self)
    }
}

#[cfg(test)]
mod tests;
