//! Next-target suggestion (004_815695db12a6b16c.txt ch. 5.2–5.3): "we score a fixed set of
//! about 60 target positions regularly distributed throughout the view frustum" by
//! "incorporating hypothetical observations into the calibration … and then estimating the
//! marginal distribution over the model parameters". Here each hypothetical view adds its
//! Schur-complement information ([`super::residual::view_information`]) to the current
//! marginal information of the intrinsics — an information-matrix update instead of a full
//! re-solve — and is scored by the resulting Max ERE (Algorithm 5.1) with common random
//! numbers. Also synthetic views for simulated sessions.

use autoteach_geometry::camera::Camera;
use nalgebra::{
    DMatrix, Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3,
};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::ere::{covariance_sqrt, max_ere, sample_cameras};
use super::residual::view_information;
use super::{MIN_POINTS, View};
use crate::{EstimateError, Result};

/// Bounding box `(min, max)` of the target points.
fn target_box(target: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in target {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Horizontal field of view of `camera` through the principal row (radians), from the
/// unprojected left and right image edges.
fn horizontal_fov(camera: &Camera) -> f64 {
    let cy = camera.cy();
    let w = f64::from(camera.width());
    let l = camera.unproject(&Vector2::new(-0.5, cy));
    let r = camera.unproject(&Vector2::new(w - 0.5, cy));
    match (l, r) {
        (Ok(l), Ok(r)) => l.angle(&r),
        _ => 2.0 * (0.5 * w / camera.fx()).atan(),
    }
}

/// A target pose `T_ct` whose target centre lies on the ray through `pixel` (under `camera`),
/// facing back along that ray and then tilted by `tilt_x`, `tilt_y` about its own axes and
/// rolled by `roll` about its normal, at the distance where the target spans `coverage` of the
/// horizontal field of view.
pub fn pose_at_pixel(
    camera: &Camera,
    target: &[[f64; 2]],
    pixel: [f64; 2],
    coverage: f64,
    tilt_x: f64,
    tilt_y: f64,
    roll: f64,
) -> Result<Isometry3<f64>> {
    let (lo, hi) = target_box(target);
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if !(extent > 0.0 && extent.is_finite()) {
        return Err(EstimateError::DegenerateCalibration(
            "the target points span no area".into(),
        ));
    }
    let centre = Vector3::new(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.0);
    let ray = camera
        .unproject(&Vector2::new(pixel[0], pixel[1]))?
        .normalize();
    let alpha = (coverage * horizontal_fov(camera)).clamp(1e-3, 2.5);
    let dist = 0.5 * extent / (0.5 * alpha).tan();
    let base = Rotation3::rotation_between(&Vector3::z(), &ray)
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
    let r = base
        * Rotation3::from_axis_angle(&Vector3::x_axis(), tilt_x)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), tilt_y)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
    let t = ray * dist - r * centre;
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r),
    ))
}

/// Image positions (fractions of the width and height) of the candidate grid: 3 × 3.
const CANDIDATE_US: [f64; 3] = [0.15, 0.5, 0.85];
const CANDIDATE_VS: [f64; 3] = [0.2, 0.5, 0.8];
/// Fraction of the horizontal field of view spanned by a near candidate (and by the first view).
pub const NEAR_COVERAGE: f64 = 0.8;
/// Fraction of the horizontal field of view spanned by a far candidate.
const FAR_COVERAGE: f64 = 0.5;
/// Tilt (radians) of the near candidates about one target axis.
const NEAR_TILT: f64 = 0.7;
/// Tilt (radians) of the far candidates about each target axis (≈ 0.7 rad about a diagonal).
const FAR_TILT: f64 = 0.5;

/// About 60 candidate target poses regularly distributed through the view frustum
/// (004_815695db12a6b16c.txt ch. 5.3, "a fixed set of about 60 target positions regularly
/// distributed throughout the view frustum"): 63 poses, at each of a 3 × 3 grid of image
/// positions (15–85 % of the width, 20–80 % of the height) five near poses spanning
/// [`NEAR_COVERAGE`] of the field of view — fronto-parallel and tilted ±0.7 rad about either
/// target axis — and two far poses spanning half of it, tilted ±0.5 rad about both axes.
///
/// Near, strongly tilted targets are what constrains a narrow lens: they fill the image
/// (distortion out to the corners) and foreshorten strongly (focal length, eq. 5.1). Measured
/// on the 48° lens (guided sessions, 16 seeds, `benchmarks/guided_calibration.py`): the best of
/// a dense 3500-pose set (7 × 5 positions × coverage 0.3/0.45/0.6/0.8 × 25 attitudes up to
/// 1 rad) was a near (0.8) pose in every pick and reached a test 99.5th percentile under 1 px in
/// 3 views (4 views on 1 of 16 seeds), where the previous set (60 poses spanning 25 % or 45 % of
/// the field of view, tilted 0.6 rad) needed 2 to more than 12 views (median 5.5, 11 of 16
/// within 8; Max ERE ≈ 1.0 px after 8 views against 0.38 px now). This 63-pose set reaches it
/// in 3–4 views (median 3, 16 of 16); the wide lenses pick its near and edge poses too.
pub fn candidate_poses(camera: &Camera, target: &[[f64; 2]]) -> Result<Vec<Isometry3<f64>>> {
    let (w, h) = (f64::from(camera.width()), f64::from(camera.height()));
    let attitudes = [
        (NEAR_COVERAGE, 0.0, 0.0),
        (NEAR_COVERAGE, NEAR_TILT, 0.0),
        (NEAR_COVERAGE, -NEAR_TILT, 0.0),
        (NEAR_COVERAGE, 0.0, NEAR_TILT),
        (NEAR_COVERAGE, 0.0, -NEAR_TILT),
        (FAR_COVERAGE, FAR_TILT, FAR_TILT),
        (FAR_COVERAGE, -FAR_TILT, -FAR_TILT),
    ];
    let mut out = Vec::with_capacity(CANDIDATE_US.len() * CANDIDATE_VS.len() * attitudes.len());
    for &v in &CANDIDATE_VS {
        for &u in &CANDIDATE_US {
            for &(cov, tx, ty) in &attitudes {
                if let Ok(p) =
                    pose_at_pixel(camera, target, [u * w - 0.5, v * h - 0.5], cov, tx, ty, 0.0)
                {
                    out.push(p);
                }
            }
        }
    }
    Ok(out)
}

/// The first view of a guided session, before any calibration exists to score candidates
/// (004_815695db12a6b16c.txt ch. 5.2: the bootstrapping starts from a restricted model with the
/// focal lengths free): the target at the image centre, spanning [`NEAR_COVERAGE`] of the field
/// of view, tilted 0.5 rad about both target axes. The tilt about a diagonal foreshortens the
/// target along both image axes, so that one view constrains both focal lengths (a tilt about
/// one axis leaves the other focal length free: on the 87° lens the previous first view, tilted
/// about x only, gave f_y = 28 275 px against 421).
pub fn first_view_pose(camera: &Camera, target: &[[f64; 2]]) -> Result<Isometry3<f64>> {
    let (w, h) = (f64::from(camera.width()), f64::from(camera.height()));
    pose_at_pixel(
        camera,
        target,
        [0.5 * w - 0.5, 0.5 * h - 0.5],
        NEAR_COVERAGE,
        FAR_TILT,
        FAR_TILT,
        0.0,
    )
}

/// A random target pose for simulated sessions and test sets: the target centre on the ray of a
/// uniformly drawn pixel (5 % margin), covering 20–60 % of the field of view, tilted up to
/// `max_tilt` radians about each target axis and rolled up to ±0.3 rad.
pub fn random_pose<R: Rng>(
    camera: &Camera,
    target: &[[f64; 2]],
    max_tilt: f64,
    rng: &mut R,
) -> Result<Isometry3<f64>> {
    let (w, h) = (f64::from(camera.width()), f64::from(camera.height()));
    let u = rng.random_range(0.05..0.95) * w;
    let v = rng.random_range(0.05..0.95) * h;
    let cov = rng.random_range(0.2..0.6);
    let tx = rng.random_range(-max_tilt..=max_tilt);
    let ty = rng.random_range(-max_tilt..=max_tilt);
    let roll = rng.random_range(-0.3..0.3);
    pose_at_pixel(camera, target, [u, v], cov, tx, ty, roll)
}

/// The ROS monocular-calibration checklist that the seed's novices followed (004_815695db12a6b16c.txt
/// ch. 5.4): target on the left, right, top and bottom of the view, close (filling the view),
/// far (about 1/5 of the view), tilted left, right, top and bottom. Each entry is
/// `(u, v, coverage, tilt_x, tilt_y)` with `(u, v)` as fractions of the image size.
const NOVICE_CHECKLIST: [(f64, f64, f64, f64, f64); 10] = [
    (0.25, 0.5, 0.4, 0.0, 0.0),
    (0.75, 0.5, 0.4, 0.0, 0.0),
    (0.5, 0.25, 0.4, 0.0, 0.0),
    (0.5, 0.75, 0.4, 0.0, 0.0),
    (0.5, 0.5, 0.75, 0.0, 0.0),
    (0.5, 0.5, 0.2, 0.0, 0.0),
    (0.5, 0.5, 0.45, 0.0, 0.5),
    (0.5, 0.5, 0.45, 0.0, -0.5),
    (0.5, 0.5, 0.45, 0.5, 0.0),
    (0.5, 0.5, 0.45, -0.5, 0.0),
];

/// `count` target poses of a simulated novice following the written instructions of
/// 004_815695db12a6b16c.txt ch. 5.4 (the ROS checklist): the checklist
/// entries in a seeded random order (repeated when `count` exceeds it), each achieved loosely —
/// position ±8 % of the image, size ±20 %, every attitude ±0.15 rad off, rolled up to ±0.2 rad
/// — the views spread naturally over the image, not chosen adversarially.
pub fn novice_poses(
    camera: &Camera,
    target: &[[f64; 2]],
    count: usize,
    seed: u64,
) -> Result<Vec<Isometry3<f64>>> {
    let (w, h) = (f64::from(camera.width()), f64::from(camera.height()));
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let mut order: Vec<usize> = Vec::with_capacity(count);
    while order.len() < count {
        let mut round: Vec<usize> = (0..NOVICE_CHECKLIST.len()).collect();
        for i in (1..round.len()).rev() {
            round.swap(i, rng.random_range(0..=i));
        }
        order.extend(round);
    }
    order
        .into_iter()
        .take(count)
        .map(|k| {
            let (u, v, cov, tx, ty) = NOVICE_CHECKLIST[k];
            let u = (u + rng.random_range(-0.08..0.08)).clamp(0.05, 0.95) * w - 0.5;
            let v = (v + rng.random_range(-0.08..0.08)).clamp(0.05, 0.95) * h - 0.5;
            let cov = cov * rng.random_range(0.8..1.2);
            let tx = tx + rng.random_range(-0.15..0.15);
            let ty = ty + rng.random_range(-0.15..0.15);
            let roll = rng.random_range(-0.2..0.2);
            pose_at_pixel(camera, target, [u, v], cov, tx, ty, roll)
        })
        .collect()
}

/// The target points visible from `pose`: projected through `camera`, inside the image, within
/// the lens's invertible range (the pixel unprojects to the point's ray), with the line of sight
/// more than 5° off the target plane (not edge-on). Returns `(indices, pixels)`.
pub fn visible_points(
    camera: &Camera,
    pose: &Isometry3<f64>,
    target: &[[f64; 2]],
) -> (Vec<usize>, Vec<[f64; 2]>) {
    let normal = pose.rotation * Vector3::z();
    let mut idx = Vec::new();
    let mut px = Vec::new();
    for (i, p) in target.iter().enumerate() {
        let pc = pose * Point3::new(p[0], p[1], 0.0);
        let n = pc.coords.norm();
        if n.is_nan() || n <= 0.0 || normal.dot(&pc.coords).abs() / n < 0.087 {
            continue;
        }
        if let Ok(q) = camera.project(&pc.coords) {
            // Beyond a fold of the distortion polynomial (a Brown–Conrady lens used past the
            // angle where r_d(r) stops increasing) a point lands inside the image but no real
            // lens images it there: keep only points whose pixel unprojects to their ray.
            let round_trip = camera
                .unproject(&q)
                .map(|r| r.angle(&pc.coords) < 1e-6)
                .unwrap_or(false);
            if camera.in_image(&q) && round_trip {
                idx.push(i);
                px.push([q.x, q.y]);
            }
        }
    }
    (idx, px)
}

/// A synthetic view of the target from `pose`: the visible points projected through `camera`
/// with Gaussian pixel noise of standard deviation `sigma`; `None` if fewer than
/// [`MIN_POINTS`] are visible.
pub fn synthesize_view<R: Rng>(
    camera: &Camera,
    pose: &Isometry3<f64>,
    target: &[[f64; 2]],
    sigma: f64,
    rng: &mut R,
) -> Option<View> {
    let (idx, px) = visible_points(camera, pose, target);
    if idx.len() < MIN_POINTS {
        return None;
    }
    let noise = Normal::new(0.0, sigma.max(0.0)).ok()?;
    Some(View {
        plane: idx.iter().map(|&i| target[i]).collect(),
        image: px
            .iter()
            .map(|p| [p[0] + noise.sample(rng), p[1] + noise.sample(rng)])
            .collect(),
        index: idx,
    })
}

/// Max ERE of the intrinsics posterior with information `info` (all model parameters) around
/// `camera`; `None` if `info` is singular.
pub fn max_ere_from_information(
    camera: &Camera,
    info: &DMatrix<f64>,
    draws: &DMatrix<f64>,
    pixels: &[[f64; 2]],
) -> Option<f64> {
    let cov = info.clone().cholesky()?.inverse();
    let l = covariance_sqrt(&cov).ok()?;
    let samples = sample_cameras(camera, &l, draws).ok()?;
    max_ere(camera, &samples, pixels).ok().map(|m| m.value)
}

/// Scores of hypothetical views (004_815695db12a6b16c.txt ch. 5.2–5.3): for each candidate pose,
/// the Max ERE after adding its predicted observations' information to `info` (the current
/// marginal information of all intrinsics, n×n). Candidates seeing fewer than
/// `max(MIN_POINTS, min_fraction × target)` points, or leaving the information singular, score
/// +inf. Candidates are scored in parallel.
#[allow(clippy::too_many_arguments)]
pub fn score_candidates(
    camera: &Camera,
    info: &DMatrix<f64>,
    target: &[[f64; 2]],
    candidates: &[Isometry3<f64>],
    sigma: f64,
    draws: &DMatrix<f64>,
    pixels: &[[f64; 2]],
    min_fraction: f64,
) -> Vec<f64> {
    let need = MIN_POINTS.max((min_fraction * target.len() as f64).ceil() as usize);
    candidates
        .par_iter()
        .map(|pose| {
            let (idx, _) = visible_points(camera, pose, target);
            if idx.len() < need {
                return f64::INFINITY;
            }
            let plane: Vec<[f64; 2]> = idx.iter().map(|&i| target[i]).collect();
            let Some(extra) = view_information(camera, pose, &plane, sigma) else {
                return f64::INFINITY;
            };
            max_ere_from_information(camera, &(info + extra), draws, pixels)
                .unwrap_or(f64::INFINITY)
        })
        .collect()
}

/// `count` random target poses ([`random_pose`]) from a PCG generator seeded with `seed`.
pub fn random_poses(
    camera: &Camera,
    target: &[[f64; 2]],
    count: usize,
    max_tilt: f64,
    seed: u64,
) -> Result<Vec<Isometry3<f64>>> {
    if !(0.0..std::f64::consts::FRAC_PI_2).contains(&max_tilt) {
        return Err(EstimateError::InvalidParameter {
            name: "max_tilt",
            value: max_tilt,
            reason: "must be in [0, pi/2)",
        });
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    (0..count)
        .map(|_| random_pose(camera, target, max_tilt, &mut rng))
        .collect()
}

/// [`synthesize_view`] with a PCG generator seeded with `seed`.
pub fn synthesize_view_seeded(
    camera: &Camera,
    pose: &Isometry3<f64>,
    target: &[[f64; 2]],
    sigma: f64,
    seed: u64,
) -> Option<View> {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    synthesize_view(camera, pose, target, sigma, &mut rng)
}
