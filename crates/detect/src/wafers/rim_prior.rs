//! Geometric prior on the offset between the images of a wafer's two rims (seed
//! 000_3b1454b2b2194811.txt §3.1–3.2: the rims are the images of two parallel circles one wafer
//! thickness apart, eq. (3.1)–(3.2), seen by the pinhole camera of §3.1).
//!
//! **Derivation.** A circle of radius `R`, centre `C` and unit normal `n` (camera frame, `z`
//! forward, focal length `f` in pixels) images as an ellipse whose centre is not the image of
//! `C` but of the pole `P` of the line where the circle's plane meets the camera's principal
//! plane `z = 0` (the image ellipse's centre is the pole of the image's line at infinity, and
//! the principal plane projects onto that line): `P = C − (R²/C_z)·(ẑ − n_z n)`. For a wafer
//! straight ahead with its normal across the optical axis, `C = (0, h, D)`, `n = (0, ∓1, 0)`,
//! the rim `x² + (z − D)² = R²` at height `h` images as
//! `u²h² + (D² − R²)(v − v₀)² = f²h²R²/(D² − R²)`, i.e.
//! `a = fR/√(D² − R²)`, `b = fhR/(D² − R²)` and centre `v₀ = fhD/(D² − R²)`.
//! Moving the circle by the wafer thickness `t` along `n` (`h → h ∓ t`) moves the centre by
//! `t·fD/(D² − R²)`, which in image terms is
//!
//! `Δ = (t/R) · a · √(1 + (a/f)²)`                                            (∗)
//!
//! along the projected normal (`up`), the lower rim's centre on the far side. The
//! weak-perspective (orthographic) form, `(t/R)·a·cos ε` with the view elevation
//! `cos ε = √(1 − (b/a)²)`, is wrong twice under perspective: the displacement lands on the
//! image plane, not on the plane across the ray, so there is no `cos ε`; and it misses the
//! factor `√(1 + (a/f)²)` (1.04–1.05 for `a ≈ 300 px` at `f = 1000 px`).
//!
//! **Perspective error of (∗) for the benchmark's views** (renderer ground truth, 210 images,
//! seed 3: camera 0.42–0.55 m from the wafer centre, 2–7 cm above it, pitched down 5–10°,
//! yawed ±3°; `t/R = 1/150`): true offset / (∗) is 0.971–1.005 (mean error −0.023 px, sd
//! 0.015 px, largest 0.08 px on offsets of ≈ 2.3 px) for the target wafers, all seen from
//! above, and 0.982–1.011 for the disturbance wafers seen from above; the weak-perspective form
//! is 1.03–1.07 (+0.11 px bias). The terms left out are the principal-point offset times the
//! camera pitch (`P_xy/P_z · n_z`) and the pole's shift off the optical axis; they grow for
//! wafers far off the image centre: for disturbance wafers seen from below (10–20 cm above the
//! camera) the ratio is 0.996–1.10, so [`super::pair`] uses the prior only for the lower rim of
//! a wafer seen from above.
//!
//! **Exact form** ([`RimMap`]). With the principal point too (the image centre unless given),
//! the upper rim's ellipse fixes the circle's pose up to its radius: a circle of radius 1 whose
//! image is that ellipse (five equations for the five pose parameters that change a circle's
//! image; the rotation about its normal does not) — two poses in general, mirror images through
//! the viewing ray, one seen from above and one from below, of which the side of the rim's
//! front arc picks one. The lower rim is then the image of that circle moved by `t/R` against
//! its normal (eq. 5.13 of the seed's pinhole projection of a circle, [`project_circle`]).
//! This is exact for a pinhole camera and a level wafer: on the benchmark's views (seeds 3 and
//! 4, 420 wafers each) it predicts the true lower rim to 10⁻⁴ px in every parameter, where (∗)
//! with the same `a`, `θ` and centre column is off by up to 0.29 px in `cy`, 0.22 px in `a`
//! and 0.31 px in `b` (for wafers seen from below; 0.08 px in `cy` and `b` from above).

use autoteach_geometry::conic::{project_circle_jacobian, wrap_half_pi};
use autoteach_geometry::lie::{se3_adjoint, se3_plus};
use nalgebra::{
    Isometry3, Matrix3, Matrix5, Rotation3, SMatrix, Translation3, UnitQuaternion, Vector2,
    Vector3, Vector5,
};

use crate::{DetectError, Result};

/// Relative standard deviation of the prior offset (∗): the perspective terms (∗) leaves out
/// (1–3 % over the views above) and the thickness tolerance of a real wafer (SEMI M1: 775 ± 25
/// µm for 300 mm, 3.2 %), added in quadrature and rounded up.
pub const RIM_OFFSET_RELATIVE_SIGMA: f64 = 0.04;

/// The wafer's thickness-to-radius ratio and the camera's focal length, from which the offset
/// between the images of a wafer's two rims follows ([`RimOffsetPrior::offset`]; module doc of
/// `rim_prior.rs`). A standard 300 mm wafer (SEMI M1, 775 µm) has `thickness_ratio`
/// 0.000775 / 0.150 = 0.00517; the renderer's default wafer (`WaferShape`: 1 mm, 150 mm) has
/// 1/150 = 0.00667.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RimOffsetPrior {
    /// Wafer thickness divided by wafer radius (dimensionless, > 0).
    pub thickness_ratio: f64,
    /// Camera focal length in pixels (`f_x ≈ f_y`; > 0).
    pub focal_length: f64,
    /// Camera principal point in pixels (`c_x`, `c_y`); `None`: the image centre
    /// `((w − 1)/2, (h − 1)/2)`. Used by the exact form ([`RimMap`]).
    pub principal_point: Option<[f64; 2]>,
}

impl RimOffsetPrior {
    /// [`DetectError::InvalidParameter`] unless both values are finite and positive.
    pub fn validate(&self) -> Result<()> {
        for (what, value) in [
            ("rim_offset thickness_ratio", self.thickness_ratio),
            ("rim_offset focal_length", self.focal_length),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "must be positive and finite",
                });
            }
        }
        for value in self.principal_point.into_iter().flatten() {
            if !value.is_finite() {
                return Err(DetectError::InvalidParameter {
                    what: "rim_offset principal_point",
                    value,
                    reason: "must be finite",
                });
            }
        }
        Ok(())
    }

    /// Expected distance (pixels) between the centres of the two rims' images along the
    /// projected wafer normal, for rims of semi-major axis `a` (pixels): eq. (∗) of the module
    /// doc, `(t/R)·a·√(1 + (a/f)²)`.
    pub fn offset(&self, a: f64) -> f64 {
        self.thickness_ratio * a * (1.0 + (a / self.focal_length).powi(2)).sqrt()
    }

    /// Standard deviation (pixels) of [`Self::offset`]: [`RIM_OFFSET_RELATIVE_SIGMA`] of it.
    pub fn sigma(&self, a: f64) -> f64 {
        RIM_OFFSET_RELATIVE_SIGMA * self.offset(a)
    }
}

/// Gauss–Newton iterations of the pose recovery in [`RimMap::lower_rim`].
const POSE_ITERATIONS: usize = 50;
/// Step halvings per iteration before the recovery gives up.
const POSE_HALVINGS: usize = 30;
/// Largest weighted residual (pixels; `θ` weighted by `a`) of a recovered pose.
const POSE_TOLERANCE: f64 = 1e-6;

/// The exact map from the upper rim's ellipse to the lower rim's (module doc, "Exact form")
/// for one camera and one side of view.
#[derive(Debug, Clone, Copy)]
pub struct RimMap {
    k: Matrix3<f64>,
    thickness_ratio: f64,
    /// +1: the wafer seen from above (the camera on the side its normal points to), −1: from
    /// below.
    front: f64,
    /// The image direction of the wafer's normal (the detector's `up`).
    up: Vector2<f64>,
}

impl RimMap {
    /// The map for `prior`, an image of `width × height` pixels (for the default principal
    /// point), wafers seen from above (`front` > 0) or below, and the image direction `up` of
    /// their normal.
    pub fn new(
        prior: &RimOffsetPrior,
        width: usize,
        height: usize,
        front: f64,
        up: Vector2<f64>,
    ) -> RimMap {
        let [px, py] = prior
            .principal_point
            .unwrap_or([0.5 * (width as f64 - 1.0), 0.5 * (height as f64 - 1.0)]);
        let f = prior.focal_length;
        RimMap {
            k: Matrix3::new(f, 0.0, px, 0.0, f, py, 0.0, 0.0, 1.0),
            thickness_ratio: prior.thickness_ratio,
            front: front.signum(),
            up,
        }
    }

    /// +1 for wafers seen from above, −1 from below (the sign the map was built with).
    pub(crate) fn front(&self) -> f64 {
        self.front
    }

    /// The pose (camera from circle) of the unit circle whose image is `upper` = `(cx, cy, a,
    /// b, θ)`, seen from the side `front`: Gauss–Newton on [`project_circle_jacobian`] from the
    /// weak-perspective pose (centre on the ray through the ellipse's centre at distance
    /// `f/a`, normal at the elevation `asin(b/a)` to the ray, towards `up`), minimum-norm steps
    /// (the rotation about the normal is free), halved until the residual drops. `None` when
    /// it does not converge or lands on the other side.
    fn pose(&self, upper: &[f64; 5]) -> Option<Isometry3<f64>> {
        let [cx, cy, a, b, _] = *upper;
        if !(a > 0.0 && b > 0.0 && upper.iter().all(|v| v.is_finite())) {
            return None;
        }
        let f = self.k[(0, 0)];
        let ray =
            Vector3::new((cx - self.k[(0, 2)]) / f, (cy - self.k[(1, 2)]) / f, 1.0).normalize();
        let up = Vector3::new(self.up.x, self.up.y, 0.0);
        let across = (up - ray * ray.dot(&up)).try_normalize(1e-12)?;
        let s = (b / a).min(0.999);
        let normal = -self.front * s * ray + (1.0 - s * s).sqrt() * across;
        let x = (Vector3::x() - normal * normal.x).try_normalize(1e-12)?;
        let rot =
            Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, normal.cross(&x), normal]));
        let mut pose = Isometry3::from_parts(
            Translation3::from(ray * (f / a)),
            UnitQuaternion::from_rotation_matrix(&rot),
        );
        let weights = Vector5::new(1.0, 1.0, 1.0, 1.0, a);
        let residual = |pose: &Isometry3<f64>| {
            let (e, j) = project_circle_jacobian(&self.k, pose, 1.0).ok()?;
            let r = Vector5::new(
                e.cx - cx,
                e.cy - cy,
                e.a - a,
                e.b - b,
                wrap_half_pi(e.theta - upper[4]),
            )
            .component_mul(&weights);
            Some((r, Matrix5::from_diagonal(&weights) * j))
        };
        let (mut r, mut wj) = residual(&pose)?;
        for _ in 0..POSE_ITERATIONS {
            if r.amax() < 1e-10 {
                break;
            }
            let Some(normal) = (wj * wj.transpose()).cholesky() else {
                break;
            };
            let step = -(wj.transpose() * normal.solve(&r));
            let mut scale = 1.0;
            let mut next = None;
            for _ in 0..POSE_HALVINGS {
                let trial = se3_plus(&pose, &(step * scale));
                if let Some((rt, jt)) = residual(&trial)
                    && rt.norm() < r.norm()
                {
                    next = Some((trial, rt, jt));
                    break;
                }
                scale *= 0.5;
            }
            // No step decreases the residual: at the floor of rounding (or stuck, which the
            // tolerance below rejects).
            let Some((p, rt, jt)) = next else { break };
            (pose, r, wj) = (p, rt, jt);
        }
        let facing = -pose.translation.vector.dot(&(pose.rotation * Vector3::z()));
        (r.amax() < POSE_TOLERANCE && facing * self.front > 0.0).then_some(pose)
    }

    /// The lower rim `(cx, cy, a, b, θ)` of the wafer whose upper rim images as `upper`, and
    /// its 5×5 Jacobian with respect to `upper`: `J_l·Ad(S⁻¹)·J_u⁺`, with `J_u`, `J_l` the
    /// Jacobians of the two rims' ellipses with respect to the right perturbation of the
    /// circle's pose ([`project_circle_jacobian`]), `J_u⁺ = J_uᵀ(J_uJ_uᵀ)⁻¹` (any right inverse
    /// serves: `J_u`'s null space, the rotation about the normal, moves neither rim) and `S`
    /// the shift from the upper circle to the lower one (`T·Exp(δ)·S = T·S·Exp(Ad(S⁻¹)δ)`).
    /// `None` where the pose is not recovered (Gauss–Newton from the weak-perspective pose does
    /// not converge, or converges to the other side).
    pub fn lower_rim(&self, upper: &[f64; 5]) -> Option<([f64; 5], Matrix5<f64>)> {
        let pose = self.pose(upper)?;
        let shift = Isometry3::translation(0.0, 0.0, -self.thickness_ratio);
        let (_, ju) = project_circle_jacobian(&self.k, &pose, 1.0).ok()?;
        let (lower, jl) = project_circle_jacobian(&self.k, &(pose * shift), 1.0).ok()?;
        let right_inverse: SMatrix<f64, 6, 5> =
            ju.transpose() * (ju * ju.transpose()).try_inverse()?;
        let chain = jl * se3_adjoint(&shift.inverse()) * right_inverse;
        let theta = upper[4] + wrap_half_pi(lower.theta - upper[4]);
        Some(([lower.cx, lower.cy, lower.a, lower.b, theta], chain))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wafers::tests::camera_pose;
    use autoteach_geometry::camera::Camera;
    use autoteach_geometry::render::{self, Rim, Scene, WaferShape};

    /// The closed form of the module doc: a level camera looking straight at the wafer centre
    /// (normal across the optical axis) — eq. (∗) is exact to first order in `t`, against the
    /// renderer's exact rim ellipses of a thin wafer.
    #[test]
    fn offset_matches_the_exact_projection_of_a_thin_wafer() {
        let shape = WaferShape {
            radius: 0.15,
            thickness: 1e-5,
        };
        let camera = Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).unwrap();
        // Camera at (−0.5, 0, h) looking along +x, level (image x = −y, image y = −z).
        let axes = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
        for h in [0.02, 0.05, 0.09] {
            let t_wc = Isometry3::from_parts(
                Translation3::new(-0.5, 0.0, h),
                UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes)),
            );
            let scene = Scene {
                shape,
                carrier: None,
                ..Scene::new(vec![Isometry3::identity()])
            };
            let truth = render::rim_visibility(&scene, &camera, &t_wc, 720).unwrap();
            let e = |rim: Rim| {
                truth
                    .iter()
                    .find(|t| t.rim == rim)
                    .unwrap()
                    .ellipse
                    .unwrap()
            };
            let (u, l) = (e(Rim::Upper), e(Rim::Lower));
            let prior = RimOffsetPrior {
                thickness_ratio: shape.thickness / shape.radius,
                focal_length: 1000.0,
                principal_point: None,
            };
            let offset = l.cy - u.cy;
            let a = 0.5 * (u.a + l.a);
            assert!(
                (offset - prior.offset(a)).abs() < 1e-4 * offset,
                "h={h}: {offset} vs {}",
                prior.offset(a)
            );
            // The weak-perspective form misses √(1 + (a/f)²) and wrongly shrinks by cos ε.
            let weak = prior.thickness_ratio * a * (1.0 - (u.b / u.a).powi(2)).sqrt();
            assert!(offset > 1.03 * weak, "h={h}: {offset} vs {weak}");
        }
    }

    /// The true rims (renderer ground truth) of a level 1 mm wafer at height `z` seen by
    /// `t_wc`, and the side it is seen from.
    fn true_rims(t_wc: &Isometry3<f64>, z: f64) -> ([f64; 5], [f64; 5], f64) {
        let camera = Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).unwrap();
        let scene = Scene {
            carrier: None,
            ..Scene::new(vec![Isometry3::translation(0.0, 0.0, z)])
        };
        let truth = render::rim_visibility(&scene, &camera, t_wc, 72).unwrap();
        let e = |rim: Rim| {
            let e = truth
                .iter()
                .find(|t| t.rim == rim)
                .unwrap()
                .ellipse
                .unwrap();
            [e.cx, e.cy, e.a, e.b, e.theta]
        };
        let front = if t_wc.translation.z > z { 1.0 } else { -1.0 };
        (e(Rim::Upper), e(Rim::Lower), front)
    }

    const PRIOR: RimOffsetPrior = RimOffsetPrior {
        thickness_ratio: 0.001 / 0.150,
        focal_length: 1000.0,
        principal_point: None,
    };

    /// The exact map against the renderer's exact rim ellipses, for wafers seen from above and
    /// from below, off the image centre, with the camera yawed and pitched (the benchmark's
    /// views): every parameter of the lower rim to 10⁻⁶ px (rad), where (∗) with the upper
    /// rim's `a`, `θ` and centre column is off by up to a tenth of a pixel. A principal point
    /// given explicitly equals the default (the image centre) here.
    #[test]
    fn exact_map_predicts_the_lower_rim() {
        let views = [
            (-0.50, 0.03, 0.09, 0.04, 0.15, 0.0),
            (-0.45, -0.04, 0.11, -0.05, 0.12, 0.0),
            (-0.52, 0.00, 0.05, 0.02, 0.10, 0.14),
            (-0.47, 0.05, 0.06, 0.05, 0.17, 0.12),
        ];
        let mut worst_closed_form: f64 = 0.0;
        for (x, y, z, yaw, down, wafer_z) in views {
            let t_wc = camera_pose(x, y, z, yaw, down);
            let (u, l, front) = true_rims(&t_wc, wafer_z);
            for prior in [
                PRIOR,
                RimOffsetPrior {
                    principal_point: Some([639.5, 359.5]),
                    ..PRIOR
                },
            ] {
                let map = RimMap::new(&prior, 1280, 720, front, Vector2::new(0.0, -1.0));
                let (lower, _) = map.lower_rim(&u).unwrap();
                for k in 0..5 {
                    assert!(
                        (lower[k] - l[k]).abs() < 1e-6,
                        "view {x} {y} {z} front {front} parameter {k}: {} vs {}",
                        lower[k],
                        l[k]
                    );
                }
                // The other side gives no pose, or one whose lower rim is far off.
                let other = RimMap::new(&prior, 1280, 720, -front, Vector2::new(0.0, -1.0));
                if let Some((wrong, _)) = other.lower_rim(&u) {
                    assert!((wrong[3] - l[3]).abs() > 0.1, "{wrong:?} vs {l:?}");
                }
            }
            let closed = [
                u[0],
                u[1] + PRIOR.offset(u[2]),
                u[2],
                u[3] + front * PRIOR.thickness_ratio * u[2] * u[2] / PRIOR.focal_length,
            ];
            for k in 0..4 {
                worst_closed_form = worst_closed_form.max((closed[k] - l[k]).abs());
            }
        }
        assert!(worst_closed_form > 0.02, "{worst_closed_form}");
    }

    /// `RimMap::lower_rim`'s Jacobian against central differences of the map itself.
    #[test]
    fn exact_map_jacobian_matches_finite_differences() {
        for (front, u) in [
            (1.0, [700.0, 420.0, 330.0, 14.0, 0.01]),
            (-1.0, [600.0, 150.0, 300.0, 9.0, -0.02]),
            (1.0, [640.0, 380.0, 350.0, 2.5, 0.001]),
        ] {
            let map = RimMap::new(&PRIOR, 1280, 720, front, Vector2::new(0.0, -1.0));
            let (_, jac) = map.lower_rim(&u).unwrap();
            for (k, h) in [1e-3, 1e-3, 1e-3, 1e-4, 1e-4].into_iter().enumerate() {
                let at = |s: f64| {
                    let mut v = u;
                    v[k] += s * h;
                    map.lower_rim(&v).unwrap().0
                };
                let (hi, lo) = (at(1.0), at(-1.0));
                for row in 0..5 {
                    let fd = (hi[row] - lo[row]) / (2.0 * h);
                    assert!(
                        (jac[(row, k)] - fd).abs() < 1e-4 * (1.0 + fd.abs()),
                        "{u:?} front {front} d{row}/d{k}: {} vs {fd}",
                        jac[(row, k)]
                    );
                }
            }
        }
    }

    /// Images the map cannot invert give `None`, not a pose.
    #[test]
    fn exact_map_rejects_impossible_ellipses() {
        let map = RimMap::new(&PRIOR, 1280, 720, 1.0, Vector2::new(0.0, -1.0));
        for u in [
            [640.0, 360.0, -5.0, 3.0, 0.0],
            [640.0, 360.0, 300.0, 0.0, 0.0],
            [f64::NAN, 360.0, 300.0, 3.0, 0.0],
        ] {
            assert!(map.lower_rim(&u).is_none(), "{u:?}");
        }
    }

    #[test]
    fn bad_values_are_errors() {
        for (t, f) in [
            (0.0, 1000.0),
            (f64::NAN, 1000.0),
            (0.005, -1.0),
            (0.005, f64::INFINITY),
        ] {
            let p = RimOffsetPrior {
                thickness_ratio: t,
                focal_length: f,
                principal_point: None,
            };
            assert!(p.validate().is_err(), "{t} {f}");
        }
        assert!(
            RimOffsetPrior {
                thickness_ratio: 0.005,
                focal_length: 900.0,
                principal_point: None,
            }
            .validate()
            .is_ok()
        );
    }
}
