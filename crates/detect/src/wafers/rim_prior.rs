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

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::camera::Camera;
    use autoteach_geometry::render::{self, Rim, Scene, WaferShape};
    use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

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
            };
            assert!(p.validate().is_err(), "{t} {f}");
        }
        assert!(
            RimOffsetPrior {
                thickness_ratio: 0.005,
                focal_length: 900.0
            }
            .validate()
            .is_ok()
        );
    }
}
