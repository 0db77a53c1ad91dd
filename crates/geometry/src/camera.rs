//! Camera models: pinhole, Brown–Conrady (OpenCV's `k1, k2, p1, p2, k3`) and the angular
//! polynomial Kannala–Brandt model (OpenCV's `fisheye` model), with projection, unprojection
//! to unit bearing vectors and analytic Jacobians with respect to the point and the parameters.
//!
//! Conventions: the camera frame has z forward (optical axis), x right and y down; pixel
//! `(u, v)` is (column, row) with the centre of the top-left pixel at `(0, 0)` (OpenCV).
//!
//! The seed's calibration chapter (004_815695db12a6b16c.txt ch. 5.1, lines 853–857) explains
//! why the angular model is offered beside the Brown–Conrady polynomial in the image radius:
//! "a polynomial as a function of θ, the angle from the principal axis, yields as good or
//! better calibrations, often with fewer distortion terms, … and handles Z ≤ 0"; it is "a
//! reduced version of the model by Kannala and Brandt \[70\]" without their tangential terms.
//! [`CameraModel::KannalaBrandt`] implements exactly that reduced model, in OpenCV's fisheye
//! parameterisation `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`; unlike OpenCV (which divides
//! by z first) it measures θ with `atan2`, so rays behind the image plane (θ > π/2) of very
//! wide lenses project correctly.
//!
//! ```
//! use autoteach_geometry::camera::{Camera, CameraModel};
//! use nalgebra::Vector3;
//! let params = [300.0, 300.0, 640.0, 480.0, 0.05, -0.01, 0.002, -0.0003];
//! let cam = Camera::new(CameraModel::KannalaBrandt, &params, 1280, 960)?;
//! let p = Vector3::new(0.3, -0.2, 1.0);
//! let px = cam.project(&p)?;
//! let ray = cam.unproject(&px)?;
//! assert!((ray - p.normalize()).norm() < 1e-12);
//! # Ok::<(), autoteach_geometry::GeometryError>(())
//! ```

use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

use nalgebra::{DMatrix, Matrix2x3, Matrix3, Vector2, Vector3};
use rayon::prelude::*;

use crate::Result;
use crate::error::{GeometryError, check_finite};

/// Batches at least this long are split across rayon's thread pool by
/// [`Camera::par_project_into`] and [`Camera::par_unproject_into`]; shorter ones run serially.
pub const PAR_MIN_BATCH: usize = 4096;

/// Points per rayon task in the parallel batch methods.
const PAR_CHUNK: usize = 1024;

/// Undistortion tolerance on the residual, in normalised image coordinates (scaled by
/// `max(1, |target|)`, and never below the rounding error of evaluating the model).
const NEWTON_TOL: f64 = 1e-12;

/// Iteration cap of the undistortion solvers.
const MAX_ITERATIONS: usize = 100;

/// Below this incidence angle the Kannala–Brandt ratio θ/ρ is evaluated by its Taylor series
/// (the truncation error, O(θ⁴), is below 1e-16 there).
const SMALL_THETA: f64 = 1e-4;

const BEHIND: &str = "z <= 0: behind the camera or on its focal plane";
const KB_AXIS_BEHIND: &str =
    "on the optical axis at or behind the centre of projection (rho = 0, z <= 0)";
const KB_BEYOND: &str = "incidence angle beyond the Kannala-Brandt model's range (theta_d(theta) must increase, theta < pi)";
const OVERFLOW: &str = "projection overflows (point too close to the focal plane)";
const KB_PIXEL_BEYOND: &str =
    "distorted radius beyond the largest theta_d of the Kannala-Brandt model's monotonic range";
const DEGENERATE_POINT: &str = "point is the centre of projection";

/// The camera (intrinsic) models.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CameraModel {
    /// Ideal pinhole: `u = fx x/z + cx`, `v = fy y/z + cy`. Parameters `[fx, fy, cx, cy]`.
    Pinhole,
    /// Brown–Conrady radial–tangential distortion in OpenCV's convention (`projectPoints` with
    /// five coefficients). Parameters `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`.
    BrownConrady,
    /// Kannala–Brandt angular polynomial (004_815695db12a6b16c.txt ch. 5.1, ll. 853–857) in
    /// OpenCV's fisheye convention. Parameters `[fx, fy, cx, cy, k1, k2, k3, k4]`.
    KannalaBrandt,
}

impl CameraModel {
    /// All models, in declaration order.
    pub const ALL: [CameraModel; 3] = [
        CameraModel::Pinhole,
        CameraModel::BrownConrady,
        CameraModel::KannalaBrandt,
    ];

    /// Canonical name: `"pinhole"`, `"brown_conrady"` or `"kannala_brandt"`.
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::Pinhole => "pinhole",
            CameraModel::BrownConrady => "brown_conrady",
            CameraModel::KannalaBrandt => "kannala_brandt",
        }
    }

    /// Parameter names in the order of the parameter vector (and of the parameter Jacobian's
    /// columns).
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            CameraModel::Pinhole => &["fx", "fy", "cx", "cy"],
            CameraModel::BrownConrady => &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"],
            CameraModel::KannalaBrandt => &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
        }
    }

    /// Length of the parameter vector.
    pub fn num_params(self) -> usize {
        self.param_names().len()
    }
}

impl fmt::Display for CameraModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for CameraModel {
    type Err = GeometryError;

    /// Parses a model name, ignoring case, surrounding blanks and `-` versus `_`: the canonical
    /// names, `"opencv"` for Brown–Conrady, and `"fisheye"` or `"kb"` for Kannala–Brandt.
    fn from_str(s: &str) -> Result<Self> {
        let key = s.trim().to_ascii_lowercase().replace('-', "_");
        match key.as_str() {
            "pinhole" => Ok(CameraModel::Pinhole),
            "brown_conrady" | "opencv" => Ok(CameraModel::BrownConrady),
            "kannala_brandt" | "fisheye" | "kb" => Ok(CameraModel::KannalaBrandt),
            _ => Err(GeometryError::UnknownModel {
                name: s.to_string(),
            }),
        }
    }
}

/// Why a single point or pixel failed inside a kernel; turned into a [`GeometryError`] that
/// carries the input by the caller.
#[derive(Debug, Clone, Copy)]
enum Fail {
    NonFinite(f64),
    Reason(&'static str),
    NoConvergence {
        what: &'static str,
        iterations: usize,
        residual: f64,
    },
}

type KResult<T> = std::result::Result<T, Fail>;

fn project_error(p: &[f64; 3], fail: Fail) -> GeometryError {
    match fail {
        Fail::NonFinite(value) => GeometryError::NonFinite {
            what: "point",
            value,
        },
        Fail::Reason(reason) => GeometryError::NotProjectable {
            x: p[0],
            y: p[1],
            z: p[2],
            reason,
        },
        Fail::NoConvergence {
            what,
            iterations,
            residual,
        } => GeometryError::NoConvergence {
            what,
            iterations,
            residual,
        },
    }
}

fn unproject_error(px: &[f64; 2], fail: Fail) -> GeometryError {
    match fail {
        Fail::NonFinite(value) => GeometryError::NonFinite {
            what: "pixel",
            value,
        },
        Fail::Reason(reason) => GeometryError::NotUnprojectable {
            u: px[0],
            v: px[1],
            reason,
        },
        Fail::NoConvergence {
            what,
            iterations,
            residual,
        } => GeometryError::NoConvergence {
            what,
            iterations,
            residual,
        },
    }
}

fn check_values<const N: usize>(v: &[f64; N]) -> KResult<()> {
    match v.iter().find(|x| !x.is_finite()) {
        Some(&bad) => Err(Fail::NonFinite(bad)),
        None => Ok(()),
    }
}

fn finite_pixel(u: f64, v: f64) -> KResult<[f64; 2]> {
    if u.is_finite() && v.is_finite() {
        Ok([u, v])
    } else {
        Err(Fail::Reason(OVERFLOW))
    }
}

/// Runs `kernel` over `input`, writing `out`, and stops at the first failure, reported as
/// `AtIndex { index: offset + i, .. }`.
fn run_batch<const I: usize, const O: usize>(
    input: &[[f64; I]],
    out: &mut [[f64; O]],
    offset: usize,
    kernel: impl Fn(&[f64; I]) -> KResult<[f64; O]>,
    to_error: fn(&[f64; I], Fail) -> GeometryError,
) -> Result<()> {
    for (i, (p, o)) in input.iter().zip(out.iter_mut()).enumerate() {
        match kernel(p) {
            Ok(v) => *o = v,
            Err(fail) => {
                return Err(GeometryError::AtIndex {
                    index: offset + i,
                    source: Box::new(to_error(p, fail)),
                });
            }
        }
    }
    Ok(())
}

fn check_batch(input: usize, output: usize) -> Result<()> {
    if input == output {
        Ok(())
    } else {
        Err(GeometryError::WrongLength {
            what: "output buffer",
            got: output,
            expected: input,
        })
    }
}

/// Of several batch errors, the one with the smallest index.
fn first_error(errors: impl ParallelIterator<Item = GeometryError>) -> Result<()> {
    let index = |e: &GeometryError| match e {
        GeometryError::AtIndex { index, .. } => *index,
        _ => usize::MAX,
    };
    match errors.min_by_key(index) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Brown–Conrady distortion of normalised coordinates and its 2×2 Jacobian.
#[derive(Debug, Clone, Copy)]
struct Distorted {
    xd: f64,
    yd: f64,
    /// Row-major `∂(xd, yd)/∂(x, y)`.
    jac: [f64; 4],
    radial: f64,
}

impl Distorted {
    fn det(&self) -> f64 {
        self.jac[0] * self.jac[3] - self.jac[1] * self.jac[2]
    }

    /// Inside the region where the distortion is a local diffeomorphism that preserves
    /// orientation and does not fold the image through the centre.
    fn invertible(&self) -> bool {
        self.radial > 0.0 && self.det() > 0.0 && self.xd.is_finite() && self.yd.is_finite()
    }
}

/// A calibrated camera: a model, its parameter vector (in [`CameraModel::param_names`] order)
/// and the image size in pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    model: CameraModel,
    params: Vec<f64>,
    width: u32,
    height: u32,
    /// `params` zero-padded to nine entries, for panic-free destructuring in the kernels.
    c: [f64; 9],
    /// Largest admissible incidence angle (exclusive): for Kannala–Brandt the first θ ≤ π where
    /// dθ_d/dθ reaches zero (π if none); π/2 for the other models.
    theta_max: f64,
    /// Kannala–Brandt: θ_d(theta_max), the supremum of the distorted radius; 0 otherwise.
    theta_d_max: f64,
}

impl Camera {
    /// Builds a camera, validating the parameter vector's length (`WrongLength`), finiteness
    /// (`NonFinite`), positive focal lengths and a non-empty image (`InvalidParameter`).
    ///
    /// For Kannala–Brandt it also finds the largest angle up to which θ_d(θ) increases (see
    /// [`Camera::max_incidence_angle`]); points beyond it are not projectable.
    pub fn new(model: CameraModel, params: &[f64], width: u32, height: u32) -> Result<Camera> {
        let expected = model.num_params();
        if params.len() != expected {
            return Err(GeometryError::WrongLength {
                what: "params (camera parameters)",
                got: params.len(),
                expected,
            });
        }
        check_finite("params (camera parameters)", params)?;
        for (what, value) in [("fx", params[0]), ("fy", params[1])] {
            if value <= 0.0 {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value,
                    reason: "focal length must be positive",
                });
            }
        }
        for (what, value) in [("width", width), ("height", height)] {
            if value == 0 {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value: 0.0,
                    reason: "image size must be positive",
                });
            }
        }
        let mut c = [0.0; 9];
        for (dst, src) in c.iter_mut().zip(params) {
            *dst = *src;
        }
        let (theta_max, theta_d_max) = match model {
            CameraModel::KannalaBrandt => {
                let t = kb_monotonic_limit([c[4], c[5], c[6], c[7]]);
                (t, kb_theta_d(&c, t))
            }
            _ => (PI / 2.0, 0.0),
        };
        Ok(Camera {
            model,
            params: params.to_vec(),
            width,
            height,
            c,
            theta_max,
            theta_d_max,
        })
    }

    /// An ideal pinhole camera.
    pub fn pinhole(fx: f64, fy: f64, cx: f64, cy: f64, width: u32, height: u32) -> Result<Camera> {
        Camera::new(CameraModel::Pinhole, &[fx, fy, cx, cy], width, height)
    }

    /// The model.
    pub fn model(&self) -> CameraModel {
        self.model
    }

    /// The parameter vector, in [`CameraModel::param_names`] order.
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    /// The distortion coefficients (the parameters after `fx, fy, cx, cy`; empty for pinhole).
    pub fn distortion(&self) -> &[f64] {
        self.params.get(4..).unwrap_or(&[])
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Focal length along x, in pixels.
    pub fn fx(&self) -> f64 {
        self.c[0]
    }

    /// Focal length along y, in pixels.
    pub fn fy(&self) -> f64 {
        self.c[1]
    }

    /// Principal point column.
    pub fn cx(&self) -> f64 {
        self.c[2]
    }

    /// Principal point row.
    pub fn cy(&self) -> f64 {
        self.c[3]
    }

    /// The intrinsic matrix `K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`.
    pub fn k_matrix(&self) -> Matrix3<f64> {
        let [fx, fy, cx, cy, ..] = self.c;
        Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0)
    }

    /// The largest incidence angle (angle between a ray and the optical axis, exclusive) that
    /// the camera can project: π/2 for pinhole and Brown–Conrady; for Kannala–Brandt the first
    /// angle at which dθ_d/dθ = 1 + 3k1θ² + 5k2θ⁴ + 7k3θ⁶ + 9k4θ⁸ reaches zero, or π.
    pub fn max_incidence_angle(&self) -> f64 {
        self.theta_max
    }

    /// Whether a pixel lies on the image: `-0.5 ≤ u < width - 0.5` and `-0.5 ≤ v < height - 0.5`
    /// (pixel centres at integer coordinates). False for NaN.
    pub fn in_image(&self, px: &Vector2<f64>) -> bool {
        px.x >= -0.5
            && px.x < f64::from(self.width) - 0.5
            && px.y >= -0.5
            && px.y < f64::from(self.height) - 0.5
    }

    // ----------------------------------------------------------------------------------------
    // Projection kernels.

    #[inline(always)]
    fn pinhole_kernel(&self, p: &[f64; 3]) -> KResult<[f64; 2]> {
        check_values(p)?;
        let [x, y, z] = *p;
        if z <= 0.0 {
            return Err(Fail::Reason(BEHIND));
        }
        let iz = 1.0 / z;
        let [fx, fy, cx, cy, ..] = self.c;
        finite_pixel(fx * (x * iz) + cx, fy * (y * iz) + cy)
    }

    /// Brown–Conrady distortion of normalised coordinates (OpenCV `projectPoints`):
    /// `r² = x² + y²`, `radial = 1 + k1 r² + k2 r⁴ + k3 r⁶`,
    /// `x'' = x radial + 2 p1 x y + p2 (r² + 2x²)`, `y'' = y radial + p1 (r² + 2y²) + 2 p2 x y`.
    #[inline(always)]
    fn bc_distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [_, _, _, _, k1, k2, p1, p2, k3] = self.c;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xy2 = 2.0 * x * y;
        (
            x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2,
        )
    }

    /// [`Camera::bc_distort`] with its Jacobian with respect to `(x, y)`.
    fn bc_distort_jac(&self, x: f64, y: f64) -> Distorted {
        let [_, _, _, _, k1, k2, p1, p2, k3] = self.c;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2); // ∂radial/∂(r²)
        let (xd, yd) = self.bc_distort(x, y);
        let cross = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y;
        Distorted {
            xd,
            yd,
            jac: [
                radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x,
                cross,
                cross,
                radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x,
            ],
            radial,
        }
    }

    #[inline(always)]
    fn bc_kernel(&self, p: &[f64; 3]) -> KResult<[f64; 2]> {
        check_values(p)?;
        let [x, y, z] = *p;
        if z <= 0.0 {
            return Err(Fail::Reason(BEHIND));
        }
        // OpenCV multiplies by the reciprocal of z too.
        let iz = 1.0 / z;
        let (xd, yd) = self.bc_distort(x * iz, y * iz);
        let [fx, fy, cx, cy, ..] = self.c;
        finite_pixel(fx * xd + cx, fy * yd + cy)
    }

    /// Kannala–Brandt projection (004_815695db12a6b16c.txt ch. 5.1, ll. 853–857; OpenCV fisheye):
    /// `θ = atan2(ρ, z)` with `ρ = √(x² + y²)`, `θ_d = θ (1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸)`,
    /// `u = fx θ_d x/ρ + cx`, `v = fy θ_d y/ρ + cy`.
    #[inline(always)]
    fn kb_kernel(&self, p: &[f64; 3]) -> KResult<[f64; 2]> {
        check_values(p)?;
        let [mut x, mut y, mut z] = *p;
        // The model depends on the direction only: rescale points whose squares would
        // overflow or underflow.
        let m = x.abs().max(y.abs()).max(z.abs());
        if !(m > 1e-150 && m < 1e150) {
            if m == 0.0 {
                return Err(Fail::Reason(DEGENERATE_POINT));
            }
            x /= m;
            y /= m;
            z /= m;
        }
        let rho = (x * x + y * y).sqrt();
        if rho == 0.0 && z <= 0.0 {
            return Err(Fail::Reason(KB_AXIS_BEHIND));
        }
        let theta = rho.atan2(z);
        if theta >= self.theta_max {
            return Err(Fail::Reason(KB_BEYOND));
        }
        let t2 = theta * theta;
        // θ/ρ; near the axis θ/ρ = (θ/tan θ)/z = (1 - θ²/3 + O(θ⁴))/z, which also covers ρ = 0.
        let theta_over_rho = if theta < SMALL_THETA {
            (1.0 - t2 / 3.0) / z
        } else {
            theta / rho
        };
        let [fx, fy, cx, cy, k1, k2, k3, k4, _] = self.c;
        let scale = theta_over_rho * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
        finite_pixel(fx * (scale * x) + cx, fy * (scale * y) + cy)
    }

    #[inline(always)]
    fn project_kernel(&self, p: &[f64; 3]) -> KResult<[f64; 2]> {
        match self.model {
            CameraModel::Pinhole => self.pinhole_kernel(p),
            CameraModel::BrownConrady => self.bc_kernel(p),
            CameraModel::KannalaBrandt => self.kb_kernel(p),
        }
    }

    /// Projects a point given in the camera frame to a pixel.
    ///
    /// Errors: `NonFinite`; `NotProjectable` for `z ≤ 0` (pinhole, Brown–Conrady), for
    /// Kannala–Brandt on the optical axis behind the camera or beyond
    /// [`Camera::max_incidence_angle`], and when the result overflows.
    pub fn project(&self, p_c: &Vector3<f64>) -> Result<Vector2<f64>> {
        let p = [p_c.x, p_c.y, p_c.z];
        self.project_kernel(&p)
            .map(|[u, v]| Vector2::new(u, v))
            .map_err(|f| project_error(&p, f))
    }

    /// Projects each point; one result per point.
    pub fn project_many(&self, pts: &[Vector3<f64>]) -> Vec<Result<Vector2<f64>>> {
        pts.iter().map(|p| self.project(p)).collect()
    }

    fn project_chunk(&self, pts: &[[f64; 3]], out: &mut [[f64; 2]], offset: usize) -> Result<()> {
        // One dispatch per chunk, so each loop is monomorphic and inlined.
        match self.model {
            CameraModel::Pinhole => {
                run_batch(pts, out, offset, |p| self.pinhole_kernel(p), project_error)
            }
            CameraModel::BrownConrady => {
                run_batch(pts, out, offset, |p| self.bc_kernel(p), project_error)
            }
            CameraModel::KannalaBrandt => {
                run_batch(pts, out, offset, |p| self.kb_kernel(p), project_error)
            }
        }
    }

    /// Projects `pts` (camera frame, `[x, y, z]` rows) into `out` (`[u, v]` rows) without
    /// allocating. `out` must have the same length (`WrongLength`). Stops at the first point
    /// that fails, returning `AtIndex { index, source }` (the rows before it are written, the
    /// others are unspecified).
    pub fn project_into(&self, pts: &[[f64; 3]], out: &mut [[f64; 2]]) -> Result<()> {
        check_batch(pts.len(), out.len())?;
        self.project_chunk(pts, out, 0)
    }

    /// [`Camera::project_into`] on rayon's thread pool for batches of at least
    /// [`PAR_MIN_BATCH`] points. On failure it reports the failing point with the smallest
    /// index; other rows of `out` are unspecified.
    pub fn par_project_into(&self, pts: &[[f64; 3]], out: &mut [[f64; 2]]) -> Result<()> {
        check_batch(pts.len(), out.len())?;
        if pts.len() < PAR_MIN_BATCH {
            return self.project_chunk(pts, out, 0);
        }
        first_error(
            pts.par_chunks(PAR_CHUNK)
                .zip(out.par_chunks_mut(PAR_CHUNK))
                .enumerate()
                .filter_map(|(k, (p, o))| self.project_chunk(p, o, k * PAR_CHUNK).err()),
        )
    }

    // ----------------------------------------------------------------------------------------
    // Jacobians.

    /// Projects a point and returns `(pixel, ∂pixel/∂point (2×3), ∂pixel/∂params (2×n))`, both
    /// analytic, the parameter columns in [`CameraModel::param_names`] order. Fails like
    /// [`Camera::project`].
    ///
    /// Brown–Conrady: with `x = X/Z`, `y = Y/Z`, `∂u/∂k1 = fx x r²`, `∂u/∂p1 = 2 fx x y`,
    /// `∂u/∂p2 = fx (r² + 2x²)`, …, and the point Jacobian is
    /// `diag(fx, fy) · ∂(x'', y'')/∂(x, y) · ∂(x, y)/∂(X, Y, Z)`.
    /// Kannala–Brandt: writing `u = fx g X + cx` with `g = θ_d/ρ`, `∂g/∂Z = -θ_d'(θ)/n²` and
    /// `ρ ∂g/∂ρ = (θ_d'(θ) Z ρ/n² - θ_d)/ρ` (`n = |P|`), both bounded as ρ → 0.
    pub fn project_jacobians(
        &self,
        p_c: &Vector3<f64>,
    ) -> Result<(Vector2<f64>, Matrix2x3<f64>, DMatrix<f64>)> {
        let p = [p_c.x, p_c.y, p_c.z];
        let r = match self.model {
            CameraModel::Pinhole | CameraModel::BrownConrady => self.bc_jacobians(&p),
            CameraModel::KannalaBrandt => self.kb_jacobians(&p),
        };
        r.map_err(|f| project_error(&p, f))
    }

    /// Pinhole and Brown–Conrady Jacobians (pinhole is Brown–Conrady with zero distortion;
    /// its parameter Jacobian keeps the first four columns).
    fn bc_jacobians(&self, p: &[f64; 3]) -> KResult<(Vector2<f64>, Matrix2x3<f64>, DMatrix<f64>)> {
        check_values(p)?;
        let [x, y, z] = *p;
        if z <= 0.0 {
            return Err(Fail::Reason(BEHIND));
        }
        let iz = 1.0 / z;
        let (xn, yn) = (x * iz, y * iz);
        let d = self.bc_distort_jac(xn, yn);
        let [fx, fy, cx, cy, ..] = self.c;
        let [u, v] = finite_pixel(fx * d.xd + cx, fy * d.yd + cy)?;
        // ∂(xn, yn)/∂(X, Y, Z) = [[1/z, 0, -xn/z], [0, 1/z, -yn/z]].
        let [a, b, c, e] = d.jac;
        let j_point = Matrix2x3::new(
            fx * a * iz,
            fx * b * iz,
            -fx * (a * xn + b * yn) * iz,
            fy * c * iz,
            fy * e * iz,
            -fy * (c * xn + e * yn) * iz,
        );
        let n = self.model.num_params();
        let mut j_params = DMatrix::zeros(2, n);
        j_params[(0, 0)] = d.xd;
        j_params[(1, 1)] = d.yd;
        j_params[(0, 2)] = 1.0;
        j_params[(1, 3)] = 1.0;
        if n == 9 {
            let r2 = xn * xn + yn * yn;
            let (r4, xy2) = (r2 * r2, 2.0 * xn * yn);
            let cols = [
                (xn * r2, yn * r2),           // k1
                (xn * r4, yn * r4),           // k2
                (xy2, r2 + 2.0 * yn * yn),    // p1
                (r2 + 2.0 * xn * xn, xy2),    // p2
                (xn * r4 * r2, yn * r4 * r2), // k3
            ];
            for (k, (du, dv)) in cols.into_iter().enumerate() {
                j_params[(0, 4 + k)] = fx * du;
                j_params[(1, 4 + k)] = fy * dv;
            }
        }
        Ok((Vector2::new(u, v), j_point, j_params))
    }

    fn kb_jacobians(&self, p: &[f64; 3]) -> KResult<(Vector2<f64>, Matrix2x3<f64>, DMatrix<f64>)> {
        check_values(p)?;
        let m = p[0].abs().max(p[1].abs()).max(p[2].abs());
        if m == 0.0 {
            return Err(Fail::Reason(DEGENERATE_POINT));
        }
        // Work on the unit direction; the point Jacobian is homogeneous of degree -1.
        let s = [p[0] / m, p[1] / m, p[2] / m];
        let ns = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
        let norm = m * ns;
        let [x, y, z] = [s[0] / ns, s[1] / ns, s[2] / ns];
        let rho = (x * x + y * y).sqrt();
        if rho == 0.0 && z <= 0.0 {
            return Err(Fail::Reason(KB_AXIS_BEHIND));
        }
        let theta = rho.atan2(z);
        if theta >= self.theta_max {
            return Err(Fail::Reason(KB_BEYOND));
        }
        let [fx, fy, cx, cy, k1, k2, k3, k4, _] = self.c;
        let t2 = theta * theta;
        // θ/ρ = θ/sin θ on the unit sphere.
        let inv_sinc = if theta < SMALL_THETA {
            1.0 + t2 / 6.0
        } else {
            theta / rho
        };
        let poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
        let dpoly = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
        let g = poly * inv_sinc; // θ_d/ρ
        let q = dpoly * z - g; // ρ ∂g/∂ρ
        let (c, sn) = if rho > 0.0 {
            (x / rho, y / rho)
        } else {
            (0.0, 0.0)
        };
        let [u, v] = finite_pixel(fx * g * x + cx, fy * g * y + cy)?;
        let j_point = Matrix2x3::new(
            fx * (g + q * c * c),
            fx * q * c * sn,
            -fx * x * dpoly,
            fy * q * c * sn,
            fy * (g + q * sn * sn),
            -fy * y * dpoly,
        ) / norm;
        let mut j_params = DMatrix::zeros(2, 8);
        j_params[(0, 0)] = g * x;
        j_params[(1, 1)] = g * y;
        j_params[(0, 2)] = 1.0;
        j_params[(1, 3)] = 1.0;
        let (ax, ay) = (fx * x * inv_sinc, fy * y * inv_sinc);
        let mut power = 1.0;
        for k in 0..4 {
            power *= t2;
            j_params[(0, 4 + k)] = ax * power;
            j_params[(1, 4 + k)] = ay * power;
        }
        Ok((Vector2::new(u, v), j_point, j_params))
    }

    // ----------------------------------------------------------------------------------------
    // Unprojection.

    /// Undistorts Brown–Conrady normalised coordinates by damped Newton iterations on the 2×2
    /// distortion Jacobian, confined to the invertible region (radial factor and Jacobian
    /// determinant positive), so a root on a fold of the distortion is never returned.
    fn bc_undistort(&self, xd: f64, yd: f64) -> KResult<(f64, f64)> {
        let [_, _, _, _, k1, k2, p1, p2, k3] = self.c;
        if k1 == 0.0 && k2 == 0.0 && p1 == 0.0 && p2 == 0.0 && k3 == 0.0 {
            return Ok((xd, yd));
        }
        let base_tol = NEWTON_TOL * xd.hypot(yd).max(1.0);
        // Rounding floor: a few ulps of the largest term of the distortion polynomial.
        let tol_at = |x: f64, y: f64| {
            let r2 = x * x + y * y;
            let mag = (x.abs() + y.abs())
                * (1.0 + r2 * (k1.abs() + r2 * (k2.abs() + r2 * k3.abs())))
                + 3.0 * r2 * (p1.abs() + p2.abs());
            base_tol.max(8.0 * f64::EPSILON * mag)
        };
        let (mut x, mut y) = (xd, yd);
        let mut st = self.bc_distort_jac(x, y);
        if !st.invertible() {
            // The origin always is (Jacobian = identity).
            (x, y) = (0.0, 0.0);
            st = self.bc_distort_jac(x, y);
        }
        // (sqrt of squares rather than hypot: cheaper, and a residual that overflows simply fails)
        let residual = |d: &Distorted| ((d.xd - xd).powi(2) + (d.yd - yd).powi(2)).sqrt();
        let mut res = residual(&st);
        let mut iterations = 0;
        while iterations < MAX_ITERATIONS {
            if res <= tol_at(x, y) {
                return Ok((x, y));
            }
            iterations += 1;
            let [a, b, c, e] = st.jac;
            let det = st.det();
            let (rx, ry) = (st.xd - xd, st.yd - yd);
            let sx = -(e * rx - b * ry) / det;
            let sy = -(a * ry - c * rx) / det;
            let mut lambda = 1.0;
            let mut accepted = false;
            for _ in 0..60 {
                let (nx, ny) = (x + lambda * sx, y + lambda * sy);
                let ns = self.bc_distort_jac(nx, ny);
                let nres = residual(&ns);
                if ns.invertible() && nres < res {
                    (x, y, st, res) = (nx, ny, ns, nres);
                    accepted = true;
                    break;
                }
                lambda *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        if res <= tol_at(x, y) {
            return Ok((x, y));
        }
        Err(Fail::NoConvergence {
            what: "Brown-Conrady undistortion",
            iterations,
            residual: res,
        })
    }

    /// Solves θ_d(θ) = `td` for θ in `[0, theta_max)` by Newton's method safeguarded with
    /// bisection (θ_d increases strictly there).
    fn kb_solve_theta(&self, td: f64) -> KResult<f64> {
        let [_, _, _, _, k1, k2, k3, k4, _] = self.c;
        let base_tol = NEWTON_TOL * td.max(1.0);
        let (mut lo, mut hi) = (0.0_f64, self.theta_max);
        let mut theta = if td < hi { td } else { 0.5 * hi };
        let mut residual = f64::INFINITY;
        let mut iterations = 0;
        while iterations < MAX_ITERATIONS {
            let t2 = theta * theta;
            let f = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - td;
            residual = f.abs();
            let mag =
                theta * (1.0 + t2 * (k1.abs() + t2 * (k2.abs() + t2 * (k3.abs() + t2 * k4.abs()))));
            if residual <= base_tol.max(8.0 * f64::EPSILON * mag) {
                return Ok(theta);
            }
            iterations += 1;
            if f > 0.0 {
                hi = theta;
            } else {
                lo = theta;
            }
            let fp = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
            let mut next = theta - f / fp;
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            }
            if next == theta {
                break;
            }
            theta = next;
        }
        Err(Fail::NoConvergence {
            what: "Kannala-Brandt unprojection (theta from theta_d)",
            iterations,
            residual,
        })
    }

    #[inline(always)]
    fn unproject_kernel(&self, px: &[f64; 2]) -> KResult<[f64; 3]> {
        check_values(px)?;
        let [fx, fy, cx, cy, ..] = self.c;
        let (mx, my) = ((px[0] - cx) / fx, (px[1] - cy) / fy);
        let bearing = |x: f64, y: f64| {
            let n = (x * x + y * y + 1.0).sqrt();
            [x / n, y / n, 1.0 / n]
        };
        match self.model {
            CameraModel::Pinhole => Ok(bearing(mx, my)),
            CameraModel::BrownConrady => {
                let (x, y) = self.bc_undistort(mx, my)?;
                Ok(bearing(x, y))
            }
            CameraModel::KannalaBrandt => {
                let td = mx.hypot(my);
                if td == 0.0 {
                    return Ok([0.0, 0.0, 1.0]);
                }
                if td >= self.theta_d_max {
                    return Err(Fail::Reason(KB_PIXEL_BEYOND));
                }
                let theta = self.kb_solve_theta(td)?;
                let (s, c) = theta.sin_cos();
                Ok([s * mx / td, s * my / td, c])
            }
        }
    }

    /// The unit bearing vector (camera frame) of the ray through a pixel.
    ///
    /// Brown–Conrady is inverted by Newton iterations on the 2×2 distortion Jacobian to a
    /// residual of 1e-12 in normalised coordinates, inside the region where the distortion is
    /// invertible (radial factor and Jacobian determinant positive); `NoConvergence` otherwise,
    /// never a wrong point. Kannala–Brandt solves θ from θ_d by safeguarded Newton on the
    /// monotonic range; pixels beyond that range's image are `NotUnprojectable`.
    pub fn unproject(&self, px: &Vector2<f64>) -> Result<Vector3<f64>> {
        let q = [px.x, px.y];
        self.unproject_kernel(&q)
            .map(|[x, y, z]| Vector3::new(x, y, z))
            .map_err(|f| unproject_error(&q, f))
    }

    /// Unprojects each pixel; one result per pixel.
    pub fn unproject_many(&self, px: &[Vector2<f64>]) -> Vec<Result<Vector3<f64>>> {
        px.iter().map(|p| self.unproject(p)).collect()
    }

    /// Unprojects `px` (`[u, v]` rows) into unit bearings `out` (`[x, y, z]` rows), like
    /// [`Camera::project_into`]: same lengths, stops at the first failure with `AtIndex`.
    pub fn unproject_into(&self, px: &[[f64; 2]], out: &mut [[f64; 3]]) -> Result<()> {
        check_batch(px.len(), out.len())?;
        run_batch(px, out, 0, |q| self.unproject_kernel(q), unproject_error)
    }

    /// [`Camera::unproject_into`] on rayon's thread pool for batches of at least
    /// [`PAR_MIN_BATCH`] pixels; reports the failing pixel with the smallest index.
    pub fn par_unproject_into(&self, px: &[[f64; 2]], out: &mut [[f64; 3]]) -> Result<()> {
        check_batch(px.len(), out.len())?;
        if px.len() < PAR_MIN_BATCH {
            return run_batch(px, out, 0, |q| self.unproject_kernel(q), unproject_error);
        }
        first_error(
            px.par_chunks(PAR_CHUNK)
                .zip(out.par_chunks_mut(PAR_CHUNK))
                .enumerate()
                .filter_map(|(k, (p, o))| {
                    run_batch(
                        p,
                        o,
                        k * PAR_CHUNK,
                        |q| self.unproject_kernel(q),
                        unproject_error,
                    )
                    .err()
                }),
        )
    }
}

/// θ_d(θ) of the Kannala–Brandt model with parameters `c` (`c[4..8]` = k1..k4).
fn kb_theta_d(c: &[f64; 9], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (c[4] + t2 * (c[5] + t2 * (c[6] + t2 * c[7]))))
}

/// Evaluates `c[0] + c[1] t + c[2] t² + …`.
fn poly_eval(c: &[f64], t: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &ci| acc * t + ci)
}

/// The sorted real roots of the polynomial `c` (ascending coefficients) in `[a, b]`, found by
/// splitting `[a, b]` at the roots of the derivative into monotonic pieces and bisecting each
/// piece that changes sign (exact up to rounding, no root can be skipped).
fn poly_roots_in(c: &[f64], a: f64, b: f64) -> Vec<f64> {
    let mut deg = c.len();
    while deg > 0 && c[deg - 1] == 0.0 {
        deg -= 1;
    }
    if deg <= 1 {
        return Vec::new(); // constant (or zero) polynomial: no isolated roots
    }
    let c = &c[..deg];
    let derivative: Vec<f64> = c
        .iter()
        .enumerate()
        .skip(1)
        .map(|(i, &ci)| i as f64 * ci)
        .collect();
    let mut knots = vec![a];
    knots.extend(poly_roots_in(&derivative, a, b));
    knots.push(b);
    let mut roots = Vec::new();
    for w in knots.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (flo, fhi) = (poly_eval(c, lo), poly_eval(c, hi));
        if flo == 0.0 {
            if roots.last() != Some(&lo) {
                roots.push(lo);
            }
            continue;
        }
        if fhi == 0.0 {
            roots.push(hi);
            continue;
        }
        if (flo > 0.0) == (fhi > 0.0) {
            continue;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if (poly_eval(c, mid) > 0.0) == (flo > 0.0) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        // Keep the side where the sign has not changed yet.
        roots.push(lo);
    }
    roots
}

/// The largest θ ≤ π up to which θ_d(θ) = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸) is strictly
/// increasing: the first root in `(0, π²]` of `dθ_d/dθ = 1 + 3k1 t + 5k2 t² + 7k3 t³ + 9k4 t⁴`
/// (t = θ²), or π if there is none.
fn kb_monotonic_limit(k: [f64; 4]) -> f64 {
    let coeffs = [1.0, 3.0 * k[0], 5.0 * k[1], 7.0 * k[2], 9.0 * k[3]];
    match poly_roots_in(&coeffs, 0.0, PI * PI).first() {
        Some(&t) => t.sqrt().min(PI),
        None => PI,
    }
}

#[cfg(test)]
mod tests;
