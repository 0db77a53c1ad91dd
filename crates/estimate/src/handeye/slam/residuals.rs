//! The residuals of the SLAM-MOT factor graph (000_3b1454b2b2194811.txt §5.3): the conic edge
//! factor of eq. (5.13), per-point row scaling, the base-yaw gauge and the marginalised window
//! prior.

use super::*;

/// The conic edge factor of eq. (5.13) with camera poses through eq. (5.9): blocks
/// `[base (Se3), offset_j (Euclidean 1) …, wafer (Euclidean 5), joint noise n_t (Euclidean 4)?,
/// mount correction ΔT (Se3)?, link corrections (Euclidean k)?]`.
pub(super) struct EdgeResidual {
    pub(super) k: Matrix3<f64>,
    pub(super) params: RobotParams,
    pub(super) geometry: WaferGeometry,
    pub(super) q_enc: Joints,
    pub(super) fixed_offsets: Joints,
    pub(super) offset_joints: Vec<usize>,
    pub(super) rim: Rim,
    pub(super) points: Vec<Vector2<f64>>,
    pub(super) sigma: f64,
    /// `Some(angles)`: the point-reprojection baseline with these associations.
    pub(super) angles: Option<Vec<f64>>,
    /// Whether the block after the wafer is the frame's joint noise `n_t` (Euclidean 4).
    pub(super) joint_noise: bool,
    /// Mount correction when it is not a block.
    pub(super) fixed_mount: Isometry3<f64>,
    /// Whether the mount correction is a block.
    pub(super) mount_block: bool,
    /// Link corrections when they are not blocks (all three).
    pub(super) fixed_links: [f64; 3],
    /// Links whose corrections form the last block.
    pub(super) link_idx: Vec<usize>,
}

impl EdgeResidual {
    /// Block positions of the wafer, the joint noise, the mount and the links.
    pub(super) fn layout(&self) -> (usize, Option<usize>, Option<usize>, Option<usize>) {
        let iw = 1 + self.offset_joints.len();
        let mut next = iw + 1;
        let noise = self.joint_noise.then(|| {
            next += 1;
            next - 1
        });
        let mount = self.mount_block.then(|| {
            next += 1;
            next - 1
        });
        let links = (!self.link_idx.is_empty()).then_some(next);
        (iw, noise, mount, links)
    }

    pub(super) fn chain(&self, params: &[&[f64]]) -> CameraChain {
        let (_, inoise, _, ilinks) = self.layout();
        let mut offsets = self.fixed_offsets;
        for (i, &j) in self.offset_joints.iter().enumerate() {
            offsets[j] = params[1 + i][0];
        }
        if let Some(i) = inoise {
            add_joint_noise(&mut offsets, params[i]);
        }
        let mut links = self.fixed_links;
        if let Some(i) = ilinks {
            for (k, &l) in self.link_idx.iter().enumerate() {
                links[l] = params[i][k];
            }
        }
        let mut rp = self.params;
        rp.l1 += links[0];
        rp.l2 += links[1];
        rp.l4 += links[2];
        CameraChain {
            robot: WaferRobot {
                params: rp,
                base: se3_from_params(params[0]),
            },
            offsets,
        }
    }
}

/// A residual whose rows are divided by per-point standard-deviation factors (eq. (5.5) with
/// `Ω^z_i = 1/(σ·s_i)²`): the inner residual is whitened by the common `σ`, each of its
/// `rows_per_point` rows of point `i` is then multiplied by `1/s_i`, and so are the matching
/// Jacobian rows (the scaling is constant, so the Jacobians stay exact).
pub(super) struct RowScaled<R> {
    pub(super) inner: R,
    /// `1/s` per residual row.
    pub(super) inv: Vec<f64>,
}

impl<R: Residual> RowScaled<R> {
    pub(super) fn new(inner: R, scale: &[f64], rows_per_point: usize) -> Self {
        let inv = scale
            .iter()
            .flat_map(|s| std::iter::repeat_n(1.0 / s, rows_per_point))
            .collect();
        Self { inner, inv }
    }
}

impl<R: Residual> Residual for RowScaled<R> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let mut jacobians = jacobians;
        self.inner
            .evaluate(params, residual, jacobians.as_deref_mut())?;
        for (r, w) in residual.iter_mut().zip(&self.inv) {
            *r *= w;
        }
        if let Some(jac) = jacobians {
            for j in jac.iter_mut() {
                for (i, w) in self.inv.iter().enumerate() {
                    j.row_mut(i).scale_mut(*w);
                }
            }
        }
        Ok(())
    }
}

/// Body-frame twist `[0; R_bcᵀ u]` of the camera per unit length of link `l` (0 = l1, 1 = l2,
/// 2 = l4): lengthening a link moves everything after it along the link's direction `u`
/// (angles `θ1`, `θ1+θ2`, `θ1+θ2+θ4` of the true joints, eq. (2.4)).
fn link_twist(chain: &CameraChain, q_enc: &Joints, link: usize) -> DVector<f64> {
    let q = chain.true_joints(q_enc);
    let angle = match link {
        0 => q[0],
        1 => q[0] + q[1],
        _ => q[0] + q[1] + q[3],
    };
    let u = Vector3::new(angle.cos(), angle.sin(), 0.0);
    let r_bc = chain.robot.camera_pose_in_base(&q).rotation;
    let rho = r_bc.inverse() * u;
    DVector::from_column_slice(&[0.0, 0.0, 0.0, rho.x, rho.y, rho.z])
}

impl Residual for EdgeResidual {
    fn dim(&self) -> usize {
        self.points.len() * if self.angles.is_some() { 2 } else { 1 }
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let (iw, inoise, imount, ilinks) = self.layout();
        let chain = self.chain(params);
        let ev = chain.evaluate(&self.q_enc);
        let mount = imount.map_or(self.fixed_mount, |i| se3_from_params(params[i]));
        let t_wc = ev.t_wc * mount;
        let w = Vector5::from_column_slice(params[iw]);
        let n = self.dim();
        let mut ej = jacobians.as_ref().map(|_| EdgeJacobians {
            camera: DMatrix::zeros(n, 6),
            wafer: DMatrix::zeros(n, 5),
        });
        let (r, t) = (self.geometry.radius, self.geometry.thickness);
        match &self.angles {
            None => conic_edge_residuals(
                &self.k,
                &t_wc,
                &w,
                self.rim,
                r,
                t,
                &self.points,
                self.sigma,
                residual,
                ej.as_mut(),
            )?,
            Some(a) => point_reprojection_residuals(
                &self.k,
                &t_wc,
                &w,
                self.rim,
                r,
                t,
                &self.points,
                a,
                self.sigma,
                residual,
                ej.as_mut(),
            )?,
        }
        if let (Some(jac), Some(ej)) = (jacobians, ej) {
            // T_wc·ΔT ⊕ ε from T_wc ⊕ η: ε = Ad(ΔT⁻¹)·η.
            let ad = se3_adjoint(&mount.inverse());
            let cam = &ej.camera * DMatrix::from_column_slice(6, 6, ad.as_slice());
            jac[0].copy_from(&(&cam * DMatrix::from_column_slice(6, 6, ev.d_base.as_slice())));
            for (i, &j) in self.offset_joints.iter().enumerate() {
                let col = ev.d_offsets.column(j);
                let dcol = &cam * DVector::from_column_slice(col.as_slice());
                jac[1 + i].set_column(0, &dcol);
            }
            jac[iw].copy_from(&ej.wafer);
            if let Some(i) = inoise {
                for (k, &j) in NOISE_JOINTS.iter().enumerate() {
                    let col = ev.d_offsets.column(j);
                    jac[i].set_column(k, &(&cam * DVector::from_column_slice(col.as_slice())));
                }
            }
            if let Some(i) = imount {
                jac[i].copy_from(&ej.camera);
            }
            if let Some(i) = ilinks {
                for (k, &l) in self.link_idx.iter().enumerate() {
                    jac[i].set_column(k, &(&cam * link_twist(&chain, &self.q_enc, l)));
                }
            }
        }
        Ok(())
    }
}

/// Gauge prior on the base yaw `atan2(R₁₀, R₀₀)` (one whitened residual).
pub(super) struct YawGauge {
    pub(super) yaw: f64,
    pub(super) sigma: f64,
}

impl Residual for YawGauge {
    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let t = se3_from_params(params[0]);
        let r = t.rotation.to_rotation_matrix().into_inner();
        let h = r.column(0).into_owned();
        let yaw = h.y.atan2(h.x);
        residual[0] = autoteach_geometry::robot::wrap_angle(yaw - self.yaw) / self.sigma;
        if let Some(jac) = jacobians {
            // d(R Exp(ω) e_x)/dω = −R [e_x]×.
            let dh = -r * hat(&Vector3::x());
            let den = h.x * h.x + h.y * h.y;
            for m in 0..3 {
                jac[0][(0, m)] = (h.x * dh[(1, m)] - h.y * dh[(0, m)]) / den / self.sigma;
            }
        }
        Ok(())
    }
}

/// A Gaussian prior on several blocks jointly (the marginalised previous window):
/// `r = L⁻¹ [x_b ⊖ μ_b]_b` with `Σ = L Lᵀ`; blocks are Se3 (first) and Euclidean.
pub(super) struct JointPrior {
    pub(super) means: Vec<Vec<f64>>,
    pub(super) manifolds: Vec<Manifold>,
    pub(super) l_inv: DMatrix<f64>,
}

impl Residual for JointPrior {
    fn dim(&self) -> usize {
        self.l_inv.nrows()
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let n = self.dim();
        let mut d = DVector::zeros(n);
        let mut dj = DMatrix::zeros(n, n);
        let mut off = 0;
        for (b, (m, mu)) in self.manifolds.iter().zip(&self.means).enumerate() {
            match m {
                Manifold::Se3 => {
                    let x = se3_from_params(params[b]);
                    let e = se3_minus(&x, &se3_from_params(mu));
                    d.rows_mut(off, 6).copy_from(&e);
                    // ∂(x ⊖ μ)/∂δx = J_r⁻¹(e) for SE(3); the rotation block approximation
                    // J_r⁻¹ of SO(3) on both parts is exact to first order near e = 0.
                    let jr = so3_right_jacobian_inv(&Vector3::new(e[0], e[1], e[2]));
                    let mut j6 = DMatrix::<f64>::identity(6, 6);
                    j6.view_mut((0, 0), (3, 3)).copy_from(&jr);
                    j6.view_mut((3, 3), (3, 3)).copy_from(&jr);
                    dj.view_mut((off, off), (6, 6)).copy_from(&j6);
                    off += 6;
                }
                _ => {
                    let k = params[b].len();
                    for i in 0..k {
                        d[off + i] = params[b][i] - mu[i];
                        dj[(off + i, off + i)] = 1.0;
                    }
                    off += k;
                }
            }
        }
        let r = &self.l_inv * d;
        residual.copy_from_slice(r.as_slice());
        if let Some(jac) = jacobians {
            let full = &self.l_inv * dj;
            let mut off = 0;
            for (b, m) in self.manifolds.iter().enumerate() {
                let k = m.tangent_dim();
                jac[b].copy_from(&full.columns(off, k));
                off += k;
            }
        }
        Ok(())
    }
}
