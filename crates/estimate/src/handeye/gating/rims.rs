//! The rims of the estimated wafers as one frame's camera sees them (eq. (5.13)).

use autoteach_geometry::conic::circle_image_conic_and_inverse;
use nalgebra::{Isometry3, Matrix3, Vector3, Vector5};

use crate::handeye::wafer::{Rim, WaferGeometry, rim_pose};
use crate::{EstimateError, Result};

/// Rim samples for the image box: 72, 5° apart (a prefilter: the gate is the conic distance).
const BOX_SAMPLES: usize = 72;

/// One rim of one wafer in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedRim {
    /// Wafer index.
    pub wafer: usize,
    /// Which rim.
    pub rim: Rim,
    /// `T_co`: the rim frame (origin at the rim centre, z along the normal) in the camera frame.
    pub t_co: Isometry3<f64>,
    /// Whether the whole rim is in front of the camera, so that its image is an ellipse; the
    /// fields below are meaningful only then.
    pub visible: bool,
    /// Image conic `C = H⁻ᵀ·C₀·H⁻¹`, unit Frobenius norm.
    pub conic: Matrix3<f64>,
    /// `H⁻¹`, `H = K·[r₁ r₂ t]` (image → rim plane).
    pub h_inv: Matrix3<f64>,
    /// Image box `[u_min, v_min, u_max, v_max]` of the rim (from [`BOX_SAMPLES`] samples).
    pub bbox: [f64; 4],
}

impl ProjectedRim {
    /// Whether the rim is visible and its image box, grown by `margin`, meets `bb`.
    pub fn overlaps(&self, bb: &[f64; 4], margin: f64) -> bool {
        let b = &self.bbox;
        self.visible
            && b[0] - margin <= bb[2]
            && bb[0] - margin <= b[2]
            && b[1] - margin <= bb[3]
            && bb[1] - margin <= b[3]
    }
}

/// Both rims of every wafer with an estimate (`Some`), upper then lower, projected by `k` from
/// the camera at `t_wc`. A rim that is not wholly in front of the camera is kept with
/// `visible = false` (its partner's band width still needs its pose).
pub fn project_rims(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    wafers: &[Option<Vector5<f64>>],
    geometry: WaferGeometry,
) -> Result<Vec<ProjectedRim>> {
    let t_cw = t_wc.inverse();
    let mut out = Vec::with_capacity(2 * wafers.len());
    for (w, wafer) in wafers.iter().enumerate() {
        let Some(wafer) = wafer else { continue };
        if let Some(i) = wafer.iter().position(|v| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: format!("wafer {w}"),
                index: i,
                value: wafer[i],
            });
        }
        for rim in [Rim::Upper, Rim::Lower] {
            let (t_wo, _) = rim_pose(wafer, rim, geometry.thickness);
            let t_co = t_cw * t_wo;
            let mut projected = ProjectedRim {
                wafer: w,
                rim,
                t_co,
                visible: false,
                conic: Matrix3::zeros(),
                h_inv: Matrix3::zeros(),
                bbox: [0.0; 4],
            };
            if let Ok((conic, h_inv)) = circle_image_conic_and_inverse(k, &t_co, geometry.radius) {
                projected.visible = true;
                projected.conic = conic;
                projected.h_inv = h_inv;
                projected.bbox = image_box(k, &t_co, geometry.radius);
            }
            out.push(projected);
        }
    }
    Ok(out)
}

/// Image box of a rim wholly in front of the camera, from [`BOX_SAMPLES`] rim points.
fn image_box(k: &Matrix3<f64>, t_co: &Isometry3<f64>, radius: f64) -> [f64; 4] {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for i in 0..BOX_SAMPLES {
        let a = 2.0 * std::f64::consts::PI * i as f64 / BOX_SAMPLES as f64;
        let pc = t_co * nalgebra::Point3::new(radius * a.cos(), radius * a.sin(), 0.0);
        let uvw: Vector3<f64> = k * pc.coords;
        let (u, v) = (uvw.x / uvw.z, uvw.y / uvw.z);
        b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
    }
    b
}
