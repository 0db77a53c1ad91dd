//! Ground truth of the visible wafer rims: per wafer and rim, the image ellipse, the visible
//! circle-angle intervals, the visible fraction and the sampled visible points.

use nalgebra::{Isometry3, Point3, Translation3, Vector2, Vector3};
use rayon::prelude::*;

use super::trace::{Prepared, RayCamera};
use super::{Scene, Shading};
use crate::camera::Camera;
use crate::conic::{Ellipse, project_circle};
use crate::{GeometryError, Result};

/// Which rim (edge circle) of a wafer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rim {
    /// The circle `z = +t/2` of the wafer frame (between the top face and the side face).
    Upper,
    /// The circle `z = −t/2` of the wafer frame (between the bottom face and the side face).
    Lower,
}

impl Rim {
    /// `"upper"` or `"lower"`.
    pub fn name(&self) -> &'static str {
        match self {
            Rim::Upper => "upper",
            Rim::Lower => "lower",
        }
    }

    /// `+1` for the upper rim, `−1` for the lower one.
    fn sign(&self) -> f64 {
        match self {
            Rim::Upper => 1.0,
            Rim::Lower => -1.0,
        }
    }
}

/// The ground truth of one rim of one wafer in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct RimTruth {
    /// Index of the wafer in [`Scene::wafers`].
    pub wafer: usize,
    /// Which rim.
    pub rim: Rim,
    /// Image ellipse of the full rim circle under the pinhole part of the camera (the camera's
    /// `K`, no distortion; exact for the pinhole model, the undistorted image otherwise), or
    /// `None` if the circle's image is not an ellipse (part of it behind the camera, or the
    /// camera in the circle's plane).
    pub ellipse: Option<Ellipse>,
    /// Visible intervals `[φ0, φ1]` of the circle angle φ (wafer frame, counter-clockwise from
    /// `x_wafer`), with `φ0 ∈ [0, 2π)` and `φ0 < φ1 ≤ φ0 + 2π` (an interval through φ = 0 has
    /// `φ1 > 2π`; a fully visible rim is `[0, 2π]`). Ends are refined by bisection to 1e-9 rad;
    /// pieces shorter than the sampling step `2π/n_samples` may be missed.
    pub intervals: Vec<[f64; 2]>,
    /// Total length of the intervals divided by 2π.
    pub fraction: f64,
    /// Circle angles `φ_j = 2πj/n_samples` of the visible samples.
    pub angles: Vec<f64>,
    /// Pixel positions of the visible samples (through the full camera model).
    pub points: Vec<Vector2<f64>>,
    /// For each visible sample, whether the wafer's side face (the bright band) faces the
    /// camera there. Where it does not, the rim is visible only as the silhouette of the dark
    /// top/bottom face against what lies behind, an edge of little contrast.
    pub side_facing: Vec<bool>,
}

/// Occlusion tests stop this far (metres) before the rim point, so the point's own surfaces
/// do not hide it.
const EPS_OCCLUSION: f64 = 1e-9;
/// Bisection steps refining the interval ends (2π/720 · 2⁻²⁴ ≈ 5e-10 rad).
const BISECTION_STEPS: usize = 24;

/// The visibility test of one rim point.
struct Tester<'a, C: RayCamera> {
    prep: &'a Prepared,
    cam: &'a C,
    t_cw: Isometry3<f64>,
}

/// Outcome of the test of one rim point.
struct PointTest {
    visible: bool,
    pixel: Vector2<f64>,
    side_facing: bool,
}

impl<C: RayCamera> Tester<'_, C> {
    /// A rim point is a visible edge iff it projects inside the image, lies in front of the
    /// camera, one of its two adjacent faces (the side face, normal `(cos φ, sin φ, 0)`, or
    /// the top/bottom face, normal `±z`, in the wafer frame) faces the camera, and the segment
    /// from the camera centre to it meets no surface (other wafers, the carrier, or the wafer
    /// itself) before it.
    fn test(&self, wafer: usize, rim: Rim, phi: f64) -> PointTest {
        let hidden = PointTest {
            visible: false,
            pixel: Vector2::new(f64::NAN, f64::NAN),
            side_facing: false,
        };
        let super::trace::Shape::Wafer { rot, pos, .. } = &self.prep.prims[wafer].shape else {
            return hidden;
        };
        let r = self.prep.radius;
        let (c, s) = (phi.cos(), phi.sin());
        let x = pos + rot * Vector3::new(r * c, r * s, rim.sign() * self.prep.half);
        let pc = self.t_cw * Point3::from(x);
        if pc.z <= 0.0 {
            return hidden;
        }
        let Some(px) = self.cam.project(&pc.coords) else {
            return hidden;
        };
        let (w, h) = (self.cam.width() as f64, self.cam.height() as f64);
        if !(px.x >= -0.5 && px.x <= w - 0.5 && px.y >= -0.5 && px.y <= h - 0.5) {
            return hidden;
        }
        let to_cam = self.prep.cam_center - x;
        let side_facing = (rot * Vector3::new(c, s, 0.0)).dot(&to_cam) > 0.0;
        let flat_facing = (rot.column(2) * rim.sign()).dot(&to_cam) > 0.0;
        if !(side_facing || flat_facing) {
            return PointTest {
                pixel: px,
                ..hidden
            };
        }
        let dist = to_cam.norm();
        let d = -to_cam / dist;
        let ray = super::trace::Ray::new(self.prep.cam_center, d);
        let blocked = self
            .prep
            .trace(&ray, &self.prep.by_distance, u32::MAX, 0.0, 1.0);
        let visible = match blocked {
            Some(hit) => hit.s >= dist - EPS_OCCLUSION,
            None => true,
        };
        PointTest {
            visible,
            pixel: px,
            side_facing,
        }
    }

    fn visible(&self, wafer: usize, rim: Rim, phi: f64) -> bool {
        self.test(wafer, rim, phi).visible
    }

    /// Transition angle between `a` (visibility `va`) and `b` (the opposite).
    fn refine(&self, wafer: usize, rim: Rim, mut a: f64, mut b: f64, va: bool) -> f64 {
        for _ in 0..BISECTION_STEPS {
            let m = 0.5 * (a + b);
            if self.visible(wafer, rim, m) == va {
                a = m;
            } else {
                b = m;
            }
        }
        0.5 * (a + b)
    }

    fn truth(&self, wafer: usize, rim: Rim, pose: &Isometry3<f64>, n: usize) -> RimTruth {
        let tau = std::f64::consts::TAU;
        let step = tau / n as f64;
        let tests: Vec<PointTest> = (0..n)
            .map(|j| self.test(wafer, rim, step * j as f64))
            .collect();
        let vis: Vec<bool> = tests.iter().map(|t| t.visible).collect();
        let mut intervals = Vec::new();
        if vis.iter().all(|&v| v) {
            intervals.push([0.0, tau]);
        } else if vis.iter().any(|&v| v) {
            // Start at a hidden sample so that every run of visible samples is complete.
            let start = vis.iter().position(|&v| !v).unwrap_or(0);
            let mut j = 0;
            while j < n {
                let i = (start + j) % n;
                let prev = (start + j + n - 1) % n;
                if vis[i] && !vis[prev] {
                    // A run starts at sample i (index start + j, unwrapped).
                    let a = step * (start + j) as f64;
                    let phi0 = self.refine(wafer, rim, a - step, a, false);
                    let mut k = j;
                    while k + 1 < n && vis[(start + k + 1) % n] {
                        k += 1;
                    }
                    let e = step * (start + k) as f64;
                    let phi1 = self.refine(wafer, rim, e, e + step, true);
                    let shift = (phi0 / tau).floor() * tau;
                    intervals.push([phi0 - shift, phi1 - shift]);
                    j = k + 1;
                } else {
                    j += 1;
                }
            }
            intervals.sort_by(|a, b| a[0].total_cmp(&b[0]));
        }
        let fraction = intervals.iter().map(|iv| iv[1] - iv[0]).sum::<f64>() / tau;
        let mut angles = Vec::new();
        let mut points = Vec::new();
        let mut side_facing = Vec::new();
        for (j, t) in tests.iter().enumerate() {
            if t.visible {
                angles.push(step * j as f64);
                points.push(t.pixel);
                side_facing.push(t.side_facing);
            }
        }
        let t_co = self.t_cw * pose * Translation3::new(0.0, 0.0, rim.sign() * self.prep.half);
        let ellipse = project_circle(&self.cam.k_matrix(), &t_co, self.prep.radius).ok();
        RimTruth {
            wafer,
            rim,
            ellipse,
            intervals,
            fraction,
            angles,
            points,
            side_facing,
        }
    }
}

/// Ground truth of both rims of every wafer, in wafer order (for each wafer its upper rim,
/// then its lower rim), sampling each rim circle at `n_samples` angles `φ_j = 2πj/n_samples`.
///
/// A rim point is a visible edge iff it lies in front of the camera (`z_c > 0`), projects
/// inside the image (`−0.5 ≤ u ≤ width − 0.5`, same for `v`), one of its two adjacent faces
/// (side face, normal `(cos φ, sin φ, 0)`; top face `+z` for the upper rim, bottom face `−z`
/// for the lower rim, wafer frame) faces the camera, and the segment from the camera centre to
/// it meets no surface of the scene (other wafers, the carrier, the wafer itself) before it.
/// This is the same geometry the renderer traces, so rendered edges and the truth agree.
/// The image ellipse comes from [`crate::conic::project_circle`] with
/// `T_co = T_wc⁻¹·T_w,wafer·Translation(0, 0, ±t/2)` (seed 000_3b1454b2b2194811.txt eq. 5.13).
///
/// # Errors
/// As [`super::render`], plus [`GeometryError::InvalidParameter`] for `n_samples < 3`.
pub fn rim_visibility(
    scene: &Scene,
    camera: &Camera,
    t_wc: &Isometry3<f64>,
    n_samples: usize,
) -> Result<Vec<RimTruth>> {
    let cam = camera;
    super::validate_inputs(scene, cam, t_wc)?;
    if n_samples < 3 {
        return Err(GeometryError::InvalidParameter {
            what: "n_samples",
            value: n_samples as f64,
            reason: "need at least 3 samples per rim",
        });
    }
    let prep = Prepared::new(scene, t_wc, Shading::default());
    let tester = Tester {
        prep: &prep,
        cam,
        t_cw: t_wc.inverse(),
    };
    let jobs: Vec<(usize, Rim)> = (0..scene.wafers.len())
        .flat_map(|i| [(i, Rim::Upper), (i, Rim::Lower)])
        .collect();
    Ok(jobs
        .par_iter()
        .map(|&(i, rim)| tester.truth(i, rim, &scene.wafers[i], n_samples))
        .collect())
}

/// Visibility (the test of [`rim_visibility`]) of the points at circle angles `angles` of one
/// rim of wafer `wafer`.
///
/// # Errors
/// As [`rim_visibility`], plus [`GeometryError::InvalidParameter`] for a wafer index out of
/// range and [`GeometryError::NonFinite`] for a NaN/inf angle.
pub fn rim_points_visible(
    scene: &Scene,
    camera: &Camera,
    t_wc: &Isometry3<f64>,
    wafer: usize,
    rim: Rim,
    angles: &[f64],
) -> Result<Vec<bool>> {
    let cam = camera;
    super::validate_inputs(scene, cam, t_wc)?;
    if wafer >= scene.wafers.len() {
        return Err(GeometryError::InvalidParameter {
            what: "wafer index",
            value: wafer as f64,
            reason: "no such wafer in the scene",
        });
    }
    crate::error::check_finite("angles", angles)?;
    let prep = Prepared::new(scene, t_wc, Shading::default());
    let tester = Tester {
        prep: &prep,
        cam,
        t_cw: t_wc.inverse(),
    };
    Ok(angles
        .iter()
        .map(|&phi| tester.visible(wafer, rim, phi))
        .collect())
}
