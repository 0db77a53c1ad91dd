//! Prior widths of the first window, the theoretical resolution of eq. (5.14) and the edge
//! residuals exposed for tests and bindings (000_3b1454b2b2194811.txt §5.3–5.4).

use super::*;

/// Prior standard deviations of the first sliding window (the uncalibrated robot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PriorSigmas {
    /// Base rotation (rad).
    pub base_rotation: f64,
    /// Base translation (m).
    pub base_translation: f64,
    /// Joint offsets (rad).
    pub offset: f64,
}

impl PriorSigmas {
    /// Diagonal covariance of an SE(3) pose (base or camera mount) with these widths, in the
    /// tangent ordering `[ω; ρ]`: `base_rotation²` ×3, then `base_translation²` ×3.
    pub fn pose_covariance(&self) -> DMatrix<f64> {
        let (r2, t2) = (self.base_rotation.powi(2), self.base_translation.powi(2));
        DMatrix::from_diagonal(&DVector::from_column_slice(&[r2, r2, r2, t2, t2, t2]))
    }

    /// Diagonal covariance of a wafer pose `[centre (3); tilts (2)]` with the base's widths:
    /// `base_translation²` on the centre, `base_rotation²` on the tilts.
    pub fn wafer_covariance(&self) -> DMatrix<f64> {
        let (r2, t2) = (self.base_rotation.powi(2), self.base_translation.powi(2));
        DMatrix::from_diagonal(&DVector::from_column_slice(&[t2, t2, t2, r2, r2]))
    }
}

impl Default for PriorSigmas {
    /// 2°, 20 mm, 2°.
    fn default() -> Self {
        Self {
            base_rotation: 2f64.to_radians(),
            base_translation: 0.02,
            offset: 2f64.to_radians(),
        }
    }
}

/// Theoretical resolution of a wafer pose in one view, eq. (5.14): the RMS over `n` rim points
/// (both rims, visible or not) of the image motion per unit change of each wafer parameter,
/// `‖∂(u, v)/∂p‖` with `(u, v)` the projection `w⁻¹·K·E·T·x̄`. Returns pixels per millimetre
/// for the centre x, y, z and pixels per degree for the tilts rx, ry.
pub fn theoretical_resolution(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    w: &Vector5<f64>,
    geometry: &WaferGeometry,
    n: usize,
) -> Result<[f64; 5]> {
    if n == 0 {
        return Err(EstimateError::InvalidParameter {
            name: "n",
            value: 0.0,
            reason: "at least one rim point",
        });
    }
    let mut acc = [0.0; 5];
    let mut count = 0usize;
    for rim in [Rim::Upper, Rim::Lower] {
        let angles: Vec<f64> = (0..n)
            .map(|i| std::f64::consts::TAU * i as f64 / n as f64)
            .collect();
        let (t_wo, _) = crate::handeye::wafer::rim_pose(w, rim, geometry.thickness);
        let t_co = t_wc.inverse() * t_wo;
        let pts: Vec<Vector2<f64>> = angles
            .iter()
            .map(|&a| {
                let x = t_co
                    * nalgebra::Point3::from(crate::handeye::factors::rim_point(
                        geometry.radius,
                        a,
                    ));
                let p = k * x.coords;
                Vector2::new(p.x / p.z, p.y / p.z)
            })
            .collect();
        let mut r = vec![0.0; 2 * n];
        let mut j = EdgeJacobians {
            camera: DMatrix::zeros(2 * n, 6),
            wafer: DMatrix::zeros(2 * n, 5),
        };
        point_reprojection_residuals(
            k,
            t_wc,
            w,
            rim,
            geometry.radius,
            geometry.thickness,
            &pts,
            &angles,
            1.0,
            &mut r,
            Some(&mut j),
        )?;
        for i in 0..n {
            for (m, a) in acc.iter_mut().enumerate() {
                *a += j.wafer[(2 * i, m)].powi(2) + j.wafer[(2 * i + 1, m)].powi(2);
            }
            count += 1;
        }
    }
    let mut out = [0.0; 5];
    for m in 0..5 {
        let rms = (acc[m] / count as f64).sqrt();
        out[m] = if m < 3 {
            rms * 1e-3
        } else {
            rms * std::f64::consts::PI / 180.0
        };
    }
    Ok(out)
}

/// Exposed for tests and the bindings: evaluates the whitened edge residuals of one
/// observation for a state.
pub fn edge_residuals(
    config: &SlamMotConfig,
    state: &SlamMotState,
    q_enc: &Joints,
    obs: &EdgeObservation,
) -> Result<Vec<f64>> {
    let chain = CameraChain {
        robot: WaferRobot {
            params: config.robot_params,
            base: state.base,
        },
        offsets: state.offsets,
    };
    let t_wc = chain.camera_pose(q_enc);
    let mut r = vec![0.0; obs.points.len()];
    let w = state
        .wafers
        .get(obs.wafer)
        .ok_or(EstimateError::InvalidParameter {
            name: "wafer",
            value: obs.wafer as f64,
            reason: "no such wafer",
        })?;
    conic_edge_residuals(
        &config.k,
        &t_wc,
        w,
        obs.rim,
        config.geometry.radius,
        config.geometry.thickness,
        &obs.points,
        config.pixel_sigma,
        &mut r,
        None,
    )?;
    Ok(r)
}
