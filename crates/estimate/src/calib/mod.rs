//! Guided camera calibration with calibrated uncertainty (seed 004_815695db12a6b16c.txt ch. 5,
//! "AprilCal").
//!
//! * [`View`]: the observations of a planar target (z = 0) in one image, missing points
//!   allowed (NaN rows are dropped, original indices kept).
//! * [`init`]: Zhang-style homography initialisation of the restricted bootstrap model.
//! * [`residual`]: the reprojection residual (eq. 5.1) with analytic Jacobians and the
//!   per-view Schur complement giving the intrinsics' marginal information (eqs. 5.3–5.5).
//! * [`ere`]: Max ERE by sampling the intrinsics marginal (Algorithm 5.1) and the per-pixel
//!   expected-error map.
//! * [`guide`]: candidate target poses through the view frustum, next-view suggestion scored
//!   by the Max ERE after adding each hypothetical view, synthetic views.
//!
//! The detector noise defaults to eq. 5.6, `σ_z = 7·10⁻⁵ · width` pixels ([`default_sigma`]).

pub mod ere;
pub mod guide;
pub mod init;
pub mod residual;
pub mod solve;

use crate::{EstimateError, Result};

/// Minimum number of usable points per view (a homography needs four).
pub const MIN_POINTS: usize = 4;

/// Detector noise of eq. 5.6 (004_815695db12a6b16c.txt): `σ_z = 7·10⁻⁵ × width` pixels.
pub fn default_sigma(width: u32) -> f64 {
    7e-5 * f64::from(width)
}

/// The observations of the planar target in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Target coordinates `[X, Y]` of the usable points (the target plane is z = 0).
    pub plane: Vec<[f64; 2]>,
    /// Their observed pixels `[u, v]`.
    pub image: Vec<[f64; 2]>,
    /// Row index of each usable point in the arrays given to [`View::new`].
    pub index: Vec<usize>,
}

impl View {
    /// Builds view number `view` from object points (`[X, Y, Z]`, Z must be 0: a planar
    /// target) and image points, one row each. A row with a NaN anywhere is a missing point
    /// and is dropped; ±inf is an error.
    ///
    /// Errors: `DimensionMismatch` for different lengths, `NonFiniteInput` for ±inf,
    /// `InvalidParameter` for a non-zero Z, `TooFewPoints` for fewer than [`MIN_POINTS`]
    /// usable rows.
    pub fn new(view: usize, object: &[[f64; 3]], image: &[[f64; 2]]) -> Result<View> {
        if object.len() != image.len() {
            return Err(EstimateError::DimensionMismatch {
                what: format!("image_points[{view}] (one row per row of object_points[{view}])"),
                expected: vec![object.len(), 2],
                got: vec![image.len(), 2],
            });
        }
        let mut out = View {
            plane: Vec::with_capacity(object.len()),
            image: Vec::with_capacity(object.len()),
            index: Vec::new(),
        };
        for (i, (o, p)) in object.iter().zip(image).enumerate() {
            let vals = [o[0], o[1], o[2], p[0], p[1]];
            if let Some(k) = vals.iter().position(|v| v.is_infinite()) {
                let (what, column) = if k < 3 {
                    ("object_points", k)
                } else {
                    ("image_points", k - 3)
                };
                return Err(EstimateError::NonFiniteInput {
                    what: format!("{what}[{view}][{i}] (NaN marks a missing point)"),
                    index: column,
                    value: vals[k],
                });
            }
            if vals.iter().any(|v| v.is_nan()) {
                continue;
            }
            if o[2] != 0.0 {
                let scale = o[0].abs().max(o[1].abs()).max(1.0);
                if o[2].abs() > 1e-9 * scale {
                    return Err(EstimateError::InvalidParameter {
                        name: "object point Z",
                        value: o[2],
                        reason: "the calibration target must be planar with Z = 0",
                    });
                }
            }
            out.plane.push([o[0], o[1]]);
            out.image.push(*p);
            out.index.push(i);
        }
        if out.plane.len() < MIN_POINTS {
            return Err(EstimateError::TooFewPoints {
                view,
                got: out.plane.len(),
                needed: MIN_POINTS,
            });
        }
        Ok(out)
    }

    /// Number of usable points.
    pub fn len(&self) -> usize {
        self.plane.len()
    }

    /// Whether the view has no usable points (never true for a view from [`View::new`]).
    pub fn is_empty(&self) -> bool {
        self.plane.is_empty()
    }

    /// Mean target coordinate of the usable points.
    pub fn centroid(&self) -> [f64; 2] {
        let n = self.plane.len().max(1) as f64;
        let (sx, sy) = self
            .plane
            .iter()
            .fold((0.0, 0.0), |a, p| (a.0 + p[0], a.1 + p[1]));
        [sx / n, sy / n]
    }
}

#[cfg(test)]
mod tests;
