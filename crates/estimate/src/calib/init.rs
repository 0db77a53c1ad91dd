//! Closed-form initialisation of a planar-target calibration: plane-to-ray homographies
//! (Zhang's construction, with the image replaced by unit bearing rays so that distorted and
//! wide-angle lenses are handled too), a one-dimensional search for the focal length of the
//! restricted model of the bootstrapping phase (004_815695db12a6b16c.txt ch. 5.2, "we start
//! with a restricted camera model with very few parameters"), and target poses from the
//! homographies.

use autoteach_geometry::camera::{Camera, CameraModel};
use nalgebra::{
    Isometry3, Matrix3, Rotation3, SMatrix, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
};

use super::View;
use crate::{EstimateError, Result};

/// Views whose target plane is tilted less than this (degrees) against the line of sight are
/// treated as fronto-parallel by the degeneracy check.
pub const FRONTO_PARALLEL_DEG: f64 = 3.0;

/// A homography `H` (3×3) mapping target-plane points `[X, Y, 1]` to homogeneous image-side
/// vectors (unit rays here), estimated by the normalised direct linear transform.
///
/// Zhang (2000), the initialisation cited by the seed (004_815695db12a6b16c.txt ch. 5.1,
/// "multiple views of a planar target \[44\]"): each correspondence gives the two rows
/// `[0ᵀ, -c sᵀ, b sᵀ]` and `[c sᵀ, 0ᵀ, -a sᵀ]` of `A h = 0` for `dst = (a, b, c)`; `h` is the
/// eigenvector of `AᵀA` with the smallest eigenvalue. Target points are first centred and
/// scaled to mean distance √2 (Hartley normalisation); rays are used as given (unit length).
pub fn homography(src: &[[f64; 2]], dst: &[[f64; 3]]) -> Option<Matrix3<f64>> {
    let n = src.len();
    if n < 4 || dst.len() != n {
        return None;
    }
    let (mut mx, mut my) = (0.0, 0.0);
    for s in src {
        mx += s[0];
        my += s[1];
    }
    mx /= n as f64;
    my /= n as f64;
    let mean_dist = src
        .iter()
        .map(|s| (s[0] - mx).hypot(s[1] - my))
        .sum::<f64>()
        / n as f64;
    if mean_dist.is_nan() || mean_dist <= 0.0 {
        return None;
    }
    let k = std::f64::consts::SQRT_2 / mean_dist;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (s, d) in src.iter().zip(dst) {
        let sv = [(s[0] - mx) * k, (s[1] - my) * k, 1.0];
        let [a, b, c] = *d;
        let mut r1 = [0.0; 9];
        let mut r2 = [0.0; 9];
        for j in 0..3 {
            r1[3 + j] = -c * sv[j];
            r1[6 + j] = b * sv[j];
            r2[j] = c * sv[j];
            r2[6 + j] = -a * sv[j];
        }
        for i in 0..9 {
            for j in i..9 {
                ata[(i, j)] += r1[i] * r1[j] + r2[i] * r2[j];
            }
        }
    }
    for i in 0..9 {
        for j in 0..i {
            ata[(i, j)] = ata[(j, i)];
        }
    }
    let eig = SymmetricEigen::new(ata);
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let t = Matrix3::new(k, 0.0, -k * mx, 0.0, k, -k * my, 0.0, 0.0, 1.0);
    let out = hn * t;
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The pose `T_ct` (target → camera) encoded by a plane-to-ray homography `H ∝ [r1 r2 t]`
/// (Zhang's decomposition with `K = I`, since the image side is already in rays): scale by the
/// mean norm of the first two columns, pick the sign that puts the target in front of the rays,
/// and project `[r1 r2 r1×r2]` onto SO(3) by SVD.
pub fn pose_from_homography(
    h: &Matrix3<f64>,
    src: &[[f64; 2]],
    rays: &[[f64; 3]],
) -> Option<Isometry3<f64>> {
    let h1 = h.column(0).into_owned();
    let h2 = h.column(1).into_owned();
    let h3 = h.column(2).into_owned();
    let norm = 0.5 * (h1.norm() + h2.norm());
    if norm.is_nan() || norm <= 0.0 {
        return None;
    }
    let mut lambda = 1.0 / norm;
    // Sign: the mapped points must point along the observed rays.
    let dot: f64 = src
        .iter()
        .zip(rays)
        .map(|(s, r)| {
            let p = h1 * s[0] + h2 * s[1] + h3;
            p.dot(&Vector3::new(r[0], r[1], r[2]))
        })
        .sum();
    if dot < 0.0 {
        lambda = -lambda;
    }
    let r1 = h1 * lambda;
    let r2 = h2 * lambda;
    let r3 = r1.cross(&r2);
    let m = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        u2.column_mut(2).neg_mut();
        r = u2 * vt;
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = h3 * lambda;
    let iso = Isometry3::from_parts(Translation3::from(t), rot);
    iso.translation
        .vector
        .iter()
        .all(|v| v.is_finite())
        .then_some(iso)
}

/// Angle (radians) between the target plane and the image plane (between the target normal and
/// the optical axis) for a target pose `T_ct`; zero for a fronto-parallel view, where the
/// homography's perspective row vanishes and Zhang's constraints on the focal length degenerate.
pub fn view_tilt(pose: &Isometry3<f64>) -> f64 {
    let normal = pose.rotation * Vector3::z();
    normal.z.abs().clamp(0.0, 1.0).acos()
}

/// The restricted (bootstrap) camera of `model`: `fx = fy = f`, principal point at the image
/// centre, no distortion — so a Kannala–Brandt lens starts as the equidistant model
/// `θ_d = θ` and the others as a pinhole.
pub fn restricted_params(model: CameraModel, f: f64, width: u32, height: u32) -> Vec<f64> {
    let cx = (f64::from(width) - 1.0) / 2.0;
    let cy = (f64::from(height) - 1.0) / 2.0;
    let mut p = vec![0.0; model.num_params()];
    p[0] = f;
    p[1] = f;
    p[2] = cx;
    p[3] = cy;
    p
}

/// Unit rays of every point of every view through `camera`; `None` if any fails to unproject.
fn rays_of(camera: &Camera, views: &[View]) -> Option<Vec<Vec<[f64; 3]>>> {
    views
        .iter()
        .map(|v| {
            v.image
                .iter()
                .map(|px| {
                    camera
                        .unproject(&nalgebra::Vector2::new(px[0], px[1]))
                        .ok()
                        .map(|r| [r.x, r.y, r.z])
                })
                .collect::<Option<Vec<_>>>()
        })
        .collect()
}

/// Zhang's orthonormality constraints on a ray homography `[h1 h2 h3] ∝ [r1 r2 t]`:
/// `cos²∠(h1, h2) + ((‖h1‖ − ‖h2‖)/(‖h1‖ + ‖h2‖))²·4`, zero for the true intrinsics.
fn orthonormality_defect(h: &Matrix3<f64>) -> f64 {
    let h1 = h.column(0);
    let h2 = h.column(1);
    let (n1, n2) = (h1.norm(), h2.norm());
    if !(n1 > 0.0 && n2 > 0.0) {
        return f64::INFINITY;
    }
    let c = h1.dot(&h2) / (n1 * n2);
    let d = 2.0 * (n1 - n2) / (n1 + n2);
    c * c + d * d
}

/// Sum over views of the orthonormality defect of the ray homographies under the restricted
/// model with focal length `f`.
fn focal_score(model: CameraModel, f: f64, width: u32, height: u32, views: &[View]) -> f64 {
    let Ok(cam) = Camera::new(
        model,
        &restricted_params(model, f, width, height),
        width,
        height,
    ) else {
        return f64::INFINITY;
    };
    let Some(rays) = rays_of(&cam, views) else {
        return f64::INFINITY;
    };
    let mut total = 0.0;
    for (v, r) in views.iter().zip(&rays) {
        match homography(&v.plane, r) {
            Some(h) => total += orthonormality_defect(&h),
            None => return f64::INFINITY,
        }
    }
    total
}

/// Result of [`initialise`]: restricted intrinsics and one target pose per view.
#[derive(Debug, Clone)]
pub struct Initial {
    /// Restricted parameters (see [`restricted_params`]).
    pub params: Vec<f64>,
    /// `T_ct` per view.
    pub poses: Vec<Isometry3<f64>>,
    /// Tilt of each view (radians, see [`view_tilt`]).
    pub tilts: Vec<f64>,
}

/// Initial intrinsics and poses for the bootstrapping phase (004_815695db12a6b16c.txt ch. 5.2):
/// the restricted model's single focal length `f` minimises the summed orthonormality defect
/// of Zhang's plane-to-ray homographies (a log-spaced scan over `[0.1, 5]×` the image
/// half-diagonal, then golden-section refinement); poses come from the homographies at that
/// `f`. For pinhole images the defect is Zhang's constraint `h1ᵀ K⁻ᵀK⁻¹ h2 = 0`,
/// `h1ᵀ K⁻ᵀK⁻¹ h1 = h2ᵀ K⁻ᵀK⁻¹ h2` with the principal point fixed at the centre (as OpenCV's
/// `initIntrinsicParams2D`), and for fisheye images it uses the equidistant projection.
///
/// Errors: [`EstimateError::DegenerateCalibration`] when every view is fronto-parallel (tilt
/// below [`FRONTO_PARALLEL_DEG`]): focal length and distance are then inseparable.
pub fn initialise(model: CameraModel, width: u32, height: u32, views: &[View]) -> Result<Initial> {
    let half_diag = 0.5 * f64::from(width).hypot(f64::from(height));
    let (lo, hi) = ((0.1 * half_diag).ln(), (5.0 * half_diag).ln());
    let steps = 60;
    let grid: Vec<f64> = (0..=steps)
        .map(|i| (lo + (hi - lo) * i as f64 / steps as f64).exp())
        .collect();
    // Pinhole-restricted models: the ray homography at focal f is diag(1/f, 1/f, 1) times the
    // pixel homography (centred pixels), so the DLT runs once per view instead of once per f.
    let (cx, cy) = (
        (f64::from(width) - 1.0) / 2.0,
        (f64::from(height) - 1.0) / 2.0,
    );
    let pixel_h: Option<Vec<Matrix3<f64>>> = if model == CameraModel::KannalaBrandt {
        None
    } else {
        views
            .iter()
            .map(|v| {
                let dst: Vec<[f64; 3]> = v
                    .image
                    .iter()
                    .map(|p| [(p[0] - cx) / half_diag, (p[1] - cy) / half_diag, 1.0])
                    .collect();
                homography(&v.plane, &dst)
            })
            .collect()
    };
    let score = |f: f64| match &pixel_h {
        Some(hs) => {
            let k = Matrix3::new(
                half_diag / f,
                0.0,
                0.0,
                0.0,
                half_diag / f,
                0.0,
                0.0,
                0.0,
                1.0,
            );
            hs.iter().map(|h| orthonormality_defect(&(k * h))).sum()
        }
        None => focal_score(model, f, width, height, views),
    };
    let scores: Vec<f64> = grid.iter().map(|&f| score(f)).collect();
    let (best, best_score) = scores
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_finite())
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, s)| (i, *s))
        .ok_or_else(|| {
            EstimateError::DegenerateCalibration(
                "no focal length in [0.1, 5] x the image half-diagonal gives valid target homographies \
                 (are the target points planar and spread out?)"
                    .into(),
            )
        })?;
    // Golden-section refinement between the neighbours of the best grid point (in log f).
    let (mut a, mut b) = (
        grid[best.saturating_sub(1)].ln(),
        grid[(best + 1).min(steps)].ln(),
    );
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let score = |lf: f64| score(lf.exp());
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (score(c), score(d));
    for _ in 0..40 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = score(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = score(d);
        }
    }
    let f = if fc.min(fd) <= best_score {
        (0.5 * (a + b)).exp()
    } else {
        grid[best]
    };
    let params = restricted_params(model, f, width, height);
    let cam = Camera::new(model, &params, width, height)?;
    let rays = rays_of(&cam, views).ok_or_else(|| {
        EstimateError::DegenerateCalibration(format!(
            "image points do not unproject under the initial focal length {f}"
        ))
    })?;
    let mut poses = Vec::with_capacity(views.len());
    let mut tilts = Vec::with_capacity(views.len());
    for (i, (v, r)) in views.iter().zip(&rays).enumerate() {
        let pose = homography(&v.plane, r)
            .and_then(|h| pose_from_homography(&h, &v.plane, r))
            .ok_or_else(|| {
                EstimateError::DegenerateCalibration(format!(
                    "view {i}: no target homography (collinear or coincident target points?)"
                ))
            })?;
        tilts.push(view_tilt(&pose));
        poses.push(pose);
    }
    let max_tilt = tilts.iter().copied().fold(0.0, f64::max);
    if max_tilt < FRONTO_PARALLEL_DEG.to_radians() {
        return Err(EstimateError::DegenerateCalibration(format!(
            "all {} views are fronto-parallel (largest target tilt {:.2} deg < {FRONTO_PARALLEL_DEG} deg): \
             focal length and target distance cannot be separated; tilt the target by 20-50 deg in some views",
            views.len(),
            max_tilt.to_degrees()
        )));
    }
    Ok(Initial {
        params,
        poses,
        tilts,
    })
}

/// Pose of one view with the intrinsics fixed (`camera`): rays through the camera of the pixels
/// that unproject, then the ray homography's pose; `None` if fewer than four unproject. Used for
/// test-set evaluation and warm starts.
pub fn pose_for_view(camera: &Camera, view: &View) -> Option<Isometry3<f64>> {
    let mut plane = Vec::with_capacity(view.len());
    let mut rays = Vec::with_capacity(view.len());
    for (pl, px) in view.plane.iter().zip(&view.image) {
        if let Ok(r) = camera.unproject(&nalgebra::Vector2::new(px[0], px[1])) {
            plane.push(*pl);
            rays.push([r.x, r.y, r.z]);
        }
    }
    homography(&plane, &rays).and_then(|h| pose_from_homography(&h, &plane, &rays))
}
