//! Multi-view estimate of a wafer rim's 3D circle `w_k` from the edge points of several
//! frames with known camera poses, for the projection prediction of 000_3b1454b2b2194811.txt
//! §4.2, eq. (4.1).
//!
//! A single ellipse determines its circle only up to the two-fold ambiguity of [`super::circle`],
//! and badly when the rim is seen nearly edge-on or only in part (the fitted ellipse of a short
//! or flat arc is poorly constrained). Here the circle — centre and
//! plane normal, with the known wafer radius — is the pose `T_wo` of an object frame whose
//! `z = 0` plane holds the rim (`z` along the normal; the rotation about `z` is a gauge freedom
//! and is not estimated, leaving 5 parameters). Its image in view `v` is the conic of eq. (5.13),
//! `C_v = H_v⁻ᵀ diag(1, 1, −r²) H_v⁻¹`, `H_v = K [r₁ r₂ t]` of `T_co = T_cw,v · T_wo` (the same
//! projection as eq. 4.1). Each observed edge point `p = (u, v, 1)` gives the Sampson residual
//! `e = pᵀCp / (2‖(Cp)₁,₂‖)` (pixels, first-order orthogonal distance), Huber-weighted; an
//! optional prior on the normal (the carrier holds wafers level, §4.2 "prior shape information")
//! regularises views that see the rim edge-on. Levenberg–Marquardt on the right perturbation
//! `T_wo·Exp(δ)` (rotation first, the project's convention), with the analytic conic
//! derivatives of `autoteach_geometry::conic::circle_image_conic_jacobian` chained through the
//! Sampson distance (checked against finite differences in the tests).

use autoteach_geometry::conic::{circle_image_conic, circle_image_conic_jacobian};
use autoteach_geometry::lie::se3_plus;
use nalgebra::{
    Isometry3, Matrix3, Matrix5, Rotation3, Translation3, UnitQuaternion, Vector3, Vector5, Vector6,
};

use super::circle::Circle3;
use crate::{DetectError, Result};

/// One view of a rim: the camera pose and the rim's observed edge points in that frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RimView {
    /// World → camera pose `T_cw` of the frame (the inverse of the tracker's `T_wc`).
    pub t_cw: Isometry3<f64>,
    /// Observed edge points `(u, v)` (pixels).
    pub points: Vec<[f64; 2]>,
}

/// Options of [`refine_circle`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleFitOptions {
    /// Levenberg–Marquardt iterations at most.
    pub max_iterations: usize,
    /// Standard deviation of an edge point's Sampson distance (pixels).
    pub pixel_sigma: f64,
    /// Huber threshold on the whitened point residual.
    pub huber: f64,
    /// Expected normal of the circle's plane (world frame, either sign), if any.
    pub normal_prior: Option<Vector3<f64>>,
    /// Standard deviation (radians) of the tilt of the normal from `normal_prior`.
    pub normal_sigma: f64,
    /// Prior that the centre lies on a line (point, unit direction) with this standard
    /// deviation (metres) across it: the carrier's axis, along which the wafers are stacked.
    pub axis_prior: Option<(Vector3<f64>, Vector3<f64>, f64)>,
}

impl Default for CircleFitOptions {
    fn default() -> Self {
        CircleFitOptions {
            max_iterations: 10,
            pixel_sigma: 1.0,
            huber: 2.0,
            normal_prior: None,
            normal_sigma: 0.05,
            axis_prior: None,
        }
    }
}

/// Result of [`refine_circle`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleFit {
    /// The estimated circle (world frame).
    pub circle: Circle3,
    /// Root mean square Sampson distance of the points (pixels, unweighted).
    pub rms: f64,
    /// Final robust cost `½Σρ(e²)` (whitened, prior included).
    pub cost: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Points that entered the fit (views whose conic is undefined are left out).
    pub points: usize,
    /// Views that entered the fit.
    pub views: usize,
    /// Covariance `(JᵀWJ)⁻¹` of the tangent `(ω_x, ω_y, ρ_x, ρ_y, ρ_z)` at the estimate
    /// (`ρ` in the circle's own frame: `ρ_x, ρ_y` in its plane, `ρ_z` along the normal);
    /// `None` when the information matrix is singular (e.g. one edge-on view without a prior).
    pub covariance: Option<Matrix5<f64>>,
}

impl CircleFit {
    /// Largest standard deviation (metres) of the centre, over all directions; infinite when
    /// the covariance is unknown.
    pub fn center_std(&self) -> f64 {
        self.covariance.map_or(f64::INFINITY, |c| {
            let b = c.fixed_view::<3, 3>(2, 2).into_owned();
            let l = nalgebra::SymmetricEigen::new(b).eigenvalues.max();
            if l.is_finite() {
                l.max(0.0).sqrt()
            } else {
                f64::INFINITY
            }
        })
    }
}

/// The object frame `T_wo` of a circle: origin at the centre, `z` along the normal.
pub fn circle_frame(c: &Circle3) -> Isometry3<f64> {
    let (u, v) = c.basis();
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[u, v, c.normal]));
    Isometry3::from_parts(
        Translation3::from(c.center),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

fn frame_circle(t_wo: &Isometry3<f64>, radius: f64) -> Circle3 {
    Circle3 {
        center: t_wo.translation.vector,
        normal: t_wo.rotation * Vector3::z(),
        radius,
    }
}

/// The Sampson distance `e = pᵀCp / (2‖(Cp)₁,₂‖)` of pixel `p` to conic `c` and its derivative
/// `∂e/∂δᵢ` given `∂C/∂δᵢ` (`dc`): with `s = pᵀCp`, `w = (Cp)₁,₂`, `g = ‖w‖`,
/// `de = ds/(2g) − s·(w·dw)/(2g³)`. `None` where the conic's gradient vanishes (its centre).
pub fn sampson_with_jacobian(
    c: &Matrix3<f64>,
    dc: &[Matrix3<f64>; 6],
    p: &[f64; 2],
) -> Option<(f64, [f64; 6])> {
    let ph = Vector3::new(p[0], p[1], 1.0);
    let cp = c * ph;
    let s = ph.dot(&cp);
    let g2 = cp.x * cp.x + cp.y * cp.y;
    let g = g2.sqrt();
    if !(g > 1e-300 && g.is_finite()) {
        return None;
    }
    let e = s / (2.0 * g);
    let mut j = [0.0; 6];
    for (ji, d) in j.iter_mut().zip(dc) {
        let dp = d * ph;
        let ds = ph.dot(&dp);
        let wdw = cp.x * dp.x + cp.y * dp.y;
        *ji = ds / (2.0 * g) - s * wdw / (2.0 * g * g2);
    }
    Some((e, j))
}

/// The Sampson distance alone (see [`sampson_with_jacobian`]).
fn sampson(c: &Matrix3<f64>, p: &[f64; 2]) -> Option<f64> {
    let ph = Vector3::new(p[0], p[1], 1.0);
    let cp = c * ph;
    let g = cp.x.hypot(cp.y);
    (g > 1e-300 && g.is_finite()).then(|| ph.dot(&cp) / (2.0 * g))
}

/// The tangent columns estimated: `ω_x, ω_y, ρ_x, ρ_y, ρ_z` (`ω_z` turns the circle in its own
/// plane and leaves it unchanged).
const COLUMNS: [usize; 5] = [0, 1, 3, 4, 5];

/// Accumulated normal equations of one linearisation.
struct Normal {
    h: Matrix5<f64>,
    g: Vector5<f64>,
    cost: f64,
    sq: f64,
    points: usize,
    views: usize,
}

fn huber(e: f64, k: f64) -> (f64, f64) {
    // (ρ(e²)/2 contribution, IRLS weight)
    let a = e.abs();
    if a <= k {
        (0.5 * e * e, 1.0)
    } else {
        (k * a - 0.5 * k * k, k / a)
    }
}

fn linearise(
    k: &Matrix3<f64>,
    views: &[RimView],
    t_wo: &Isometry3<f64>,
    radius: f64,
    o: &CircleFitOptions,
    with_jacobian: bool,
) -> Normal {
    let mut n = Normal {
        h: Matrix5::zeros(),
        g: Vector5::zeros(),
        cost: 0.0,
        sq: 0.0,
        points: 0,
        views: 0,
    };
    for v in views {
        let t_co = v.t_cw * t_wo;
        let mut used = false;
        if !with_jacobian {
            // Cost only (LM trial steps): the conic without its derivatives.
            let Ok(c) = circle_image_conic(k, &t_co, radius) else {
                continue;
            };
            for p in &v.points {
                let Some(e) = sampson(&c, p) else {
                    continue;
                };
                used = true;
                n.points += 1;
                n.sq += e * e;
                n.cost += huber(e / o.pixel_sigma, o.huber).0;
            }
            n.views += usize::from(used);
            continue;
        }
        let Ok((c, dc)) = circle_image_conic_jacobian(k, &t_co, radius) else {
            continue;
        };
        for p in &v.points {
            let Some((e, j)) = sampson_with_jacobian(&c, &dc, p) else {
                continue;
            };
            used = true;
            n.points += 1;
            n.sq += e * e;
            let ew = e / o.pixel_sigma;
            let (rho, w) = huber(ew, o.huber);
            n.cost += rho;
            let jr = Vector5::from_fn(|r, _| j[COLUMNS[r]] / o.pixel_sigma);
            n.h += jr * jr.transpose() * w;
            n.g += jr * (w * ew);
        }
        if used {
            n.views += 1;
        }
    }
    if let Some(n0) = o.normal_prior {
        // m = Rᵀn₀ (the prior normal in object coordinates); its x, y components are the tilt.
        // Under T_wo·Exp(δ): m(ω) ≈ m + [m]×ω.
        let m = t_wo.rotation.inverse() * n0;
        let r = [m.x / o.normal_sigma, m.y / o.normal_sigma];
        n.cost += 0.5 * (r[0] * r[0] + r[1] * r[1]);
        if with_jacobian {
            let mut j0 = Vector5::zeros();
            let mut j1 = Vector5::zeros();
            j0[1] = -m.z / o.normal_sigma;
            j1[0] = m.z / o.normal_sigma;
            n.h += j0 * j0.transpose() + j1 * j1.transpose();
            n.g += j0 * r[0] + j1 * r[1];
        }
    }
    if let Some((p0, dir, sigma)) = o.axis_prior {
        // r = Bᵀ(c − p₀)/σ with B ⟂ the axis; c(δ) = c + Rρ, so ∂r/∂ρ = BᵀR/σ.
        let (b1, b2) = Circle3 {
            center: p0,
            normal: dir,
            radius: 1.0,
        }
        .basis();
        let d = t_wo.translation.vector - p0;
        let r = [b1.dot(&d) / sigma, b2.dot(&d) / sigma];
        n.cost += 0.5 * (r[0] * r[0] + r[1] * r[1]);
        if with_jacobian {
            let rot = t_wo.rotation.to_rotation_matrix();
            for (b, ri) in [(b1, r[0]), (b2, r[1])] {
                let jr = rot.transpose() * b / sigma;
                let j = Vector5::new(0.0, 0.0, jr.x, jr.y, jr.z);
                n.h += j * j.transpose();
                n.g += j * ri;
            }
        }
    }
    n
}

fn step(t_wo: &Isometry3<f64>, d: &Vector5<f64>) -> Isometry3<f64> {
    let mut xi = Vector6::zeros();
    for (r, &c) in COLUMNS.iter().enumerate() {
        xi[c] = d[r];
    }
    se3_plus(t_wo, &xi)
}

/// Levenberg–Marquardt estimate of a rim's 3D circle (world frame) of known `radius` from its
/// edge points in several views with known poses (see the module doc), starting at `init`.
///
/// Errors: [`DetectError::InvalidParameter`] for a bad radius or options,
/// [`DetectError::TooFewPoints`] when fewer than 5 points (in views where the circle has an
/// image conic) constrain the circle, [`DetectError::NonFinite`] for non-finite input points.
pub fn refine_circle(
    k: &Matrix3<f64>,
    views: &[RimView],
    init: &Circle3,
    o: &CircleFitOptions,
) -> Result<CircleFit> {
    let radius = init.radius;
    for (what, v) in [
        ("radius", radius),
        ("pixel_sigma", o.pixel_sigma),
        ("huber", o.huber),
        ("normal_sigma", o.normal_sigma),
    ] {
        if !(v > 0.0 && v.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what,
                value: v,
                reason: "must be finite and positive",
            });
        }
    }
    for (i, v) in views.iter().enumerate() {
        if let Some(x) = v.points.iter().flatten().find(|x| !x.is_finite()) {
            return Err(DetectError::NonFinite {
                what: "rim view points",
                index: i,
                value: *x,
            });
        }
    }
    let mut o = *o;
    if let Some((p0, dir, sigma)) = o.axis_prior {
        let ok = p0.iter().all(|v| v.is_finite()) && sigma > 0.0 && sigma.is_finite();
        o.axis_prior = dir
            .try_normalize(1e-300)
            .filter(|d| ok && d.iter().all(|v| v.is_finite()))
            .map(|d| (p0, d, sigma));
        if o.axis_prior.is_none() {
            return Err(DetectError::InvalidParameter {
                what: "axis_prior sigma",
                value: sigma,
                reason: "the axis prior needs a finite point, a non-zero direction and sigma > 0",
            });
        }
    }
    o.normal_prior = o
        .normal_prior
        .and_then(|n| n.try_normalize(1e-300))
        .filter(|n| n.iter().all(|v| v.is_finite()));
    let mut t_wo = circle_frame(init);
    let mut lin = linearise(k, views, &t_wo, radius, &o, true);
    if lin.points < 5 {
        return Err(DetectError::TooFewPoints {
            what: "edge points",
            needed: 5,
            got: lin.points,
        });
    }
    let mut lambda = 1e-3;
    let mut iterations = 0;
    while iterations < o.max_iterations {
        iterations += 1;
        let mut improved = false;
        for _ in 0..8 {
            let mut a = lin.h;
            for i in 0..5 {
                a[(i, i)] += lambda * lin.h[(i, i)].max(1e-12);
            }
            let Some(d) = a.cholesky().map(|c| -c.solve(&lin.g)) else {
                lambda *= 10.0;
                continue;
            };
            let trial = step(&t_wo, &d);
            let tl = linearise(k, views, &trial, radius, &o, false);
            if tl.points >= 5 && tl.cost < lin.cost {
                let rel = (lin.cost - tl.cost) / lin.cost.max(1e-300);
                t_wo = trial;
                lin = linearise(k, views, &t_wo, radius, &o, true);
                lambda = (lambda * 0.1).max(1e-9);
                improved = rel > 1e-10 && d.norm() > 1e-12;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let circle = frame_circle(&t_wo, radius);
    if !(circle.center.iter().chain(circle.normal.iter())).all(|v| v.is_finite()) {
        return Err(DetectError::Degenerate {
            reason: "the circle estimate diverged".into(),
        });
    }
    // Covariance from the whitened information; a relative eigenvalue floor flags the
    // unconstrained directions as singular rather than returning a meaningless inverse.
    let eig = nalgebra::SymmetricEigen::new(lin.h);
    let lmax = eig.eigenvalues.max();
    let covariance = (lmax > 0.0 && eig.eigenvalues.min() > 1e-12 * lmax).then(|| {
        let inv = eig.eigenvalues.map(|l| 1.0 / l);
        eig.eigenvectors * Matrix5::from_diagonal(&inv) * eig.eigenvectors.transpose()
    });
    Ok(CircleFit {
        circle,
        rms: (lin.sq / lin.points.max(1) as f64).sqrt(),
        cost: lin.cost,
        iterations,
        points: lin.points,
        views: lin.views,
        covariance,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::conic::project_circle;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn k() -> Matrix3<f64> {
        Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 359.5, 0.0, 0.0, 1.0)
    }

    /// A camera looking along +x (world) from `(x, 0, z)`: camera z = world x, camera x = −world y,
    /// camera y = −world z.
    fn t_cw(x: f64, z: f64) -> Isometry3<f64> {
        let r = Rotation3::from_matrix_unchecked(Matrix3::new(
            0.0, 0.0, 1.0, //
            -1.0, 0.0, 0.0, //
            0.0, -1.0, 0.0,
        ));
        let t_wc = Isometry3::from_parts(
            Translation3::new(x, 0.0, z),
            UnitQuaternion::from_rotation_matrix(&r),
        );
        t_wc.inverse()
    }

    fn truth() -> Circle3 {
        Circle3 {
            center: Vector3::new(0.45, 0.01, 0.12),
            normal: Vector3::new(0.01, -0.005, 1.0).normalize(),
            radius: 0.15,
        }
    }

    /// Visible front half of the rim in a view, with Gaussian noise.
    fn view(c: &Circle3, t: Isometry3<f64>, noise: f64, rng: &mut Pcg64) -> RimView {
        let points = (0..60)
            .filter_map(|i| {
                let phi = -std::f64::consts::PI + std::f64::consts::TAU * i as f64 / 60.0;
                let x = t * nalgebra::Point3::from(c.point_at(phi));
                let p = k() * x.coords;
                let q = [
                    p.x / p.z + noise * rng.random_range(-1.0..1.0),
                    p.y / p.z + noise * rng.random_range(-1.0..1.0),
                ];
                // Only the half nearer the camera (the front rim).
                let world = c.point_at(phi);
                (world.x < c.center.x).then_some(q)
            })
            .collect();
        RimView { t_cw: t, points }
    }

    #[test]
    fn sampson_jacobian_matches_finite_differences() {
        let t_co = t_cw(0.0, 0.2) * circle_frame(&truth());
        let (c, dc) = circle_image_conic_jacobian(&k(), &t_co, 0.15).unwrap();
        for p in [[700.0, 420.0], [300.0, 500.0], [900.0, 380.0]] {
            let (e, j) = sampson_with_jacobian(&c, &dc, &p).unwrap();
            for (i, ji) in j.iter().enumerate() {
                let h = 1e-6;
                let mut xi = Vector6::zeros();
                xi[i] = h;
                let f = |t: &Isometry3<f64>| {
                    let c = circle_image_conic(&k(), t, 0.15).unwrap();
                    let ph = Vector3::new(p[0], p[1], 1.0);
                    let cp = c * ph;
                    ph.dot(&cp) / (2.0 * cp.x.hypot(cp.y))
                };
                let fd = (f(&se3_plus(&t_co, &xi)) - f(&se3_plus(&t_co, &(-xi)))) / (2.0 * h);
                assert!(
                    (fd - ji).abs() < 1e-5 * (1.0 + fd.abs()),
                    "column {i}: analytic {ji}, numeric {fd}, e = {e}"
                );
            }
        }
    }

    #[test]
    fn prior_jacobian_matches_finite_differences() {
        let o = CircleFitOptions {
            normal_prior: Some(Vector3::z()),
            normal_sigma: 0.1,
            axis_prior: Some((
                Vector3::new(0.44, 0.0, 0.0),
                Vector3::new(0.02, 0.01, 1.0).normalize(),
                0.002,
            )),
            ..CircleFitOptions::default()
        };
        let c = truth();
        let t_wo = circle_frame(&c);
        let n = linearise(&k(), &[], &t_wo, 0.15, &o, true);
        // g = Jᵀr and H = JᵀJ for the 2 prior residuals: check g by differentiating the cost.
        for i in 0..5 {
            let h = 1e-6;
            let mut d = Vector5::zeros();
            d[i] = h;
            let cp = linearise(&k(), &[], &step(&t_wo, &d), 0.15, &o, false).cost;
            let cm = linearise(&k(), &[], &step(&t_wo, &(-d)), 0.15, &o, false).cost;
            let fd = (cp - cm) / (2.0 * h);
            assert!(
                (fd - n.g[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                "column {i}: {} vs {fd}",
                n.g[i]
            );
        }
    }

    /// Three views from different heights (one nearly edge-on) recover the circle from a
    /// perturbed start; a single edge-on ellipse cannot.
    #[test]
    fn refine_recovers_the_circle_from_three_views() {
        let mut rng = Pcg64::seed_from_u64(7);
        let c = truth();
        let views: Vec<RimView> = [0.30, 0.20, 0.125]
            .iter()
            .map(|&z| view(&c, t_cw(0.0, z), 0.5, &mut rng))
            .collect();
        let init = Circle3 {
            center: c.center + Vector3::new(0.03, -0.02, 0.01),
            normal: Vector3::new(0.05, 0.02, 1.0).normalize(),
            radius: 0.15,
        };
        let fit = refine_circle(&k(), &views, &init, &CircleFitOptions::default()).unwrap();
        let dc = (fit.circle.center - c.center).norm();
        let dn = fit.circle.normal.cross(&c.normal).norm();
        assert!(dc < 1e-3, "centre error {dc} m");
        assert!(dn < 5e-3, "normal error {dn}");
        assert!(fit.rms < 0.6, "rms {}", fit.rms);
        assert_eq!(fit.views, 3);
        // The projected ellipse of the estimate matches the true one in a new view.
        let t = t_cw(0.02, 0.05);
        let e_true = project_circle(&k(), &(t * circle_frame(&c)), 0.15).unwrap();
        let e_fit = project_circle(&k(), &(t * circle_frame(&fit.circle)), 0.15).unwrap();
        assert!((e_true.cx - e_fit.cx).hypot(e_true.cy - e_fit.cy) < 1.0);
    }

    /// One edge-on view (the camera 1 mm above the rim's plane) sees a line: the centre can
    /// slide far along the plane and the covariance says so; adding an open view constrains it.
    #[test]
    fn edge_on_view_leaves_the_centre_unconstrained() {
        let mut rng = Pcg64::seed_from_u64(8);
        let c = Circle3 {
            normal: Vector3::z(),
            ..truth()
        };
        let views = vec![view(&c, t_cw(0.0, 0.121), 0.3, &mut rng)];
        let init = Circle3 {
            center: c.center + Vector3::new(0.01, 0.0, 0.002),
            normal: Vector3::new(0.0, 0.03, 1.0).normalize(),
            radius: 0.15,
        };
        let o = CircleFitOptions {
            normal_prior: Some(-Vector3::z()),
            normal_sigma: 0.01,
            ..CircleFitOptions::default()
        };
        let fit = refine_circle(&k(), &views, &init, &o).unwrap();
        assert!(fit.rms < 0.5, "the points fit: rms {}", fit.rms);
        assert!(fit.center_std() > 0.05, "centre std {}", fit.center_std());
        let mut views = views;
        views.push(view(&c, t_cw(0.0, 0.3), 0.3, &mut rng));
        let fit = refine_circle(&k(), &views, &init, &o).unwrap();
        assert!((fit.circle.center - c.center).norm() < 2e-3);
        assert!(fit.center_std() < 2e-3, "centre std {}", fit.center_std());
    }

    /// A partial edge-on view alone leaves the centre free in the plane; the carrier-axis prior
    /// pins it (the wafer's height then follows from the view).
    #[test]
    fn axis_prior_constrains_a_single_edge_on_view() {
        let mut rng = Pcg64::seed_from_u64(9);
        let c = Circle3 {
            normal: Vector3::z(),
            ..truth()
        };
        let views = vec![view(&c, t_cw(0.0, 0.122), 0.3, &mut rng)];
        let init = Circle3 {
            center: c.center + Vector3::new(0.01, -0.005, 0.003),
            normal: Vector3::z(),
            radius: 0.15,
        };
        let o = CircleFitOptions {
            normal_prior: Some(Vector3::z()),
            normal_sigma: 0.01,
            axis_prior: Some((
                Vector3::new(c.center.x, c.center.y, 0.5),
                Vector3::z(),
                0.001,
            )),
            ..CircleFitOptions::default()
        };
        let fit = refine_circle(&k(), &views, &init, &o).unwrap();
        assert!(
            (fit.circle.center - c.center).norm() < 2e-3,
            "{:?}",
            fit.circle
        );
        assert!(fit.center_std() < 3e-3, "centre std {}", fit.center_std());
        let bad = CircleFitOptions {
            axis_prior: Some((c.center, Vector3::zeros(), 0.001)),
            ..o
        };
        assert!(refine_circle(&k(), &views, &init, &bad).is_err());
    }

    #[test]
    fn bad_inputs_are_errors() {
        let c = truth();
        let o = CircleFitOptions::default();
        assert!(matches!(
            refine_circle(&k(), &[], &c, &o),
            Err(DetectError::TooFewPoints { .. })
        ));
        let bad = RimView {
            t_cw: t_cw(0.0, 0.2),
            points: vec![[f64::NAN, 1.0]],
        };
        assert!(refine_circle(&k(), &[bad], &c, &o).is_err());
        let zero = Circle3 { radius: 0.0, ..c };
        assert!(refine_circle(&k(), &[], &zero, &o).is_err());
        let o2 = CircleFitOptions {
            pixel_sigma: -1.0,
            ..o
        };
        assert!(refine_circle(&k(), &[], &c, &o2).is_err());
    }
}
