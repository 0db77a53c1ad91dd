//! Co-registration: colouring lidar points from a camera image (seed 004_815695db12a6b16c.txt
//! ch. 4.1, eq. (4.1) `p_i = d(K E T_i r_i)`).
//!
//! Points are given in the lidar frame (`T_i r_i`, already applied by the scanner); `E` is
//! `T_cam_lidar`; `d(K ·)` is the foundation's [`Camera`] (intrinsics and distortion). A point
//! takes the colour of the pixel it projects to, unless it is behind the camera, projects
//! outside the image, or is hidden from the camera by a nearer lidar point. Occlusion uses a
//! z-buffer: every projectable point writes its range from the camera into a square of
//! `(2·splat_radius + 1)²` pixels (lidar points are sparser than pixels, so a single pixel per
//! point would leave holes through which the background shows), and a point farther than the
//! buffer at its own pixel by more than `depth_tolerance` is occluded.

use autoteach_geometry::camera::Camera;
use nalgebra::{Isometry3, Point3};

use crate::{DetectError, Result};

/// Why a point has (or has no) colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PointStatus {
    /// Coloured.
    Colored = 0,
    /// A missing point (NaN coordinates) in an organised cloud.
    Missing = 1,
    /// Behind the camera (or outside the lens model's field).
    Behind = 2,
    /// Projects outside the image.
    Outside = 3,
    /// Hidden from the camera by a nearer surface.
    Occluded = 4,
}

/// An 8-bit RGB image, row-major, 3 bytes per pixel.
#[derive(Debug, Clone, Copy)]
pub struct RgbImage<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `height · width · 3` bytes.
    pub data: &'a [u8],
}

/// Options of [`colorize`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColorizeParams {
    /// Half-width (pixels) of the square each point writes into the z-buffer: about half the
    /// spacing of neighbouring lidar points in the image.
    pub splat_radius: usize,
    /// A point is occluded when it is farther from the camera than the z-buffer at its pixel
    /// by more than this (metres): the range noise plus the depth change across a splat.
    pub depth_tolerance: f64,
}

impl Default for ColorizeParams {
    /// 3 px (a ¾° lidar seen by a 752-px, 111° camera: ≈ 5 px spacing) and 0.1 m.
    fn default() -> Self {
        Self {
            splat_radius: 3,
            depth_tolerance: 0.1,
        }
    }
}

/// Colours and per-point status from [`colorize`].
#[derive(Debug, Clone, PartialEq)]
pub struct Colorized {
    /// RGB of every point (`[0, 0, 0]` where not coloured).
    pub colors: Vec<[u8; 3]>,
    /// Status of every point.
    pub status: Vec<PointStatus>,
}

/// Colours `points` (lidar frame; NaN rows are missing points) from `image` taken by `camera`
/// at `t_cam_lidar` (lidar → camera), eq. (4.1), with a z-buffer for occlusion.
///
/// Errors: `WrongLength` if the image buffer does not match its size or the camera's;
/// `NonFinite` for an infinite coordinate; `InvalidParameter` for a bad tolerance.
pub fn colorize(
    points: &[[f64; 3]],
    image: &RgbImage<'_>,
    camera: &Camera,
    t_cam_lidar: &Isometry3<f64>,
    params: &ColorizeParams,
) -> Result<Colorized> {
    let (w, h) = (image.width, image.height);
    if image.data.len() != w * h * 3 {
        return Err(DetectError::WrongLength {
            what: "image data (height * width * 3)",
            got: image.data.len(),
            expected: w * h * 3,
        });
    }
    if w != camera.width() as usize || h != camera.height() as usize {
        return Err(DetectError::WrongLength {
            what: "image width * height (must match the camera's)",
            got: w * h,
            expected: camera.width() as usize * camera.height() as usize,
        });
    }
    if !(params.depth_tolerance.is_finite() && params.depth_tolerance >= 0.0) {
        return Err(DetectError::InvalidParameter {
            what: "depth_tolerance",
            value: params.depth_tolerance,
            reason: "must be finite and non-negative (metres)",
        });
    }
    let n = points.len();
    let mut status = vec![PointStatus::Missing; n];
    let mut pix = vec![(0usize, 0usize); n];
    let mut depth = vec![0.0f64; n];
    for (i, p) in points.iter().enumerate() {
        if p.iter().any(|v| v.is_nan()) {
            continue;
        }
        if let Some(&value) = p.iter().find(|v| v.is_infinite()) {
            return Err(DetectError::NonFinite {
                what: "points",
                index: i,
                value,
            });
        }
        let pc = t_cam_lidar * Point3::new(p[0], p[1], p[2]);
        let Ok(px) = camera.project(&pc.coords) else {
            status[i] = PointStatus::Behind;
            continue;
        };
        if !camera.in_image(&px) {
            status[i] = PointStatus::Outside;
            continue;
        }
        // in_image guarantees −0.5 ≤ u < w − 0.5, so the rounded pixel is on the image.
        let (u, v) = ((px.x + 0.5).floor() as usize, (px.y + 0.5).floor() as usize);
        pix[i] = (u.min(w - 1), v.min(h - 1));
        depth[i] = pc.coords.norm();
        status[i] = PointStatus::Colored;
    }
    let r = params.splat_radius;
    let mut zbuf = vec![f64::INFINITY; w * h];
    for ((st, &(u, v)), &d) in status.iter().zip(&pix).zip(&depth) {
        if *st != PointStatus::Colored {
            continue;
        }
        for y in v.saturating_sub(r)..=(v + r).min(h - 1) {
            let row = &mut zbuf[y * w..(y + 1) * w];
            for z in &mut row[u.saturating_sub(r)..=(u + r).min(w - 1)] {
                if d < *z {
                    *z = d;
                }
            }
        }
    }
    let mut colors = vec![[0u8; 3]; n];
    for (((st, &(u, v)), &d), col) in status.iter_mut().zip(&pix).zip(&depth).zip(&mut colors) {
        if *st != PointStatus::Colored {
            continue;
        }
        if d > zbuf[v * w + u] + params.depth_tolerance {
            *st = PointStatus::Occluded;
            continue;
        }
        let k = (v * w + u) * 3;
        *col = [image.data[k], image.data[k + 1], image.data[k + 2]];
    }
    Ok(Colorized { colors, status })
}
