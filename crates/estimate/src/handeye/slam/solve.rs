//! The batch and sliding-window solves of the SLAM-MOT factor graph (000_3b1454b2b2194811.txt
//! §5.3), with marginal covariances of every estimate.

use super::*;

impl SlamMot {
    /// The full batch solve over all frames from `initial`, with marginal covariances.
    pub fn solve_batch(&self, initial: &SlamMotState) -> Result<SlamMotSolution> {
        self.check_state(initial)?;
        let all = 0..self.encoders.len();
        let (rounds, n_model) = match self.config.factor {
            EdgeFactor::Conic => (1, 0),
            EdgeFactor::NearestPoint { n_model, rounds } => (rounds.max(1), n_model),
        };
        let mut state = initial.clone();
        let mut iterations = 0;
        let mut initial_cost = f64::NAN;
        let mut last = None;
        for round in 0..rounds {
            let angles = if n_model > 0 {
                Some(self.associate(&state, n_model)?)
            } else {
                None
            };
            let (mut p, b, n_res) = self.build(&state, all.clone(), angles.as_deref())?;
            let summary = p.solve(&self.options())?;
            if round == 0 {
                initial_cost = summary.initial_cost;
            }
            iterations += summary.iterations;
            state = self.read_state(&p, &b, &state);
            last = Some((p, b, n_res, summary.final_cost));
        }
        let (p, b, n_res, final_cost) = last.ok_or(EstimateError::InvalidParameter {
            name: "rounds",
            value: 0.0,
            reason: "no solve ran",
        })?;
        let uncertainty = self.uncertainty(&p, &b);
        let camera_poses = self.frame_poses(&p, &b, &state);
        let rms_px = self.rms_with_poses(&camera_poses, &state, n_model)?;
        Ok(SlamMotSolution {
            state,
            uncertainty,
            initial_cost,
            final_cost,
            iterations,
            rms_px,
            n_residuals: n_res,
            camera_poses,
        })
    }

    /// RMS edge error in pixels of a state (conic distance, or point distance for the
    /// baseline).
    pub fn rms(&self, state: &SlamMotState, n_model: usize) -> Result<f64> {
        self.rms_with_poses(&self.camera_poses(state), state, n_model)
    }

    /// [`Self::rms`] with given per-frame camera poses (free-camera mode).
    pub fn rms_with_poses(
        &self,
        poses: &[Isometry3<f64>],
        state: &SlamMotState,
        n_model: usize,
    ) -> Result<f64> {
        if poses.len() != self.encoders.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "camera poses".into(),
                expected: vec![self.encoders.len()],
                got: vec![poses.len()],
            });
        }
        let (mut s, mut n) = (0.0, 0usize);
        for o in &self.observations {
            let w = &state.wafers[o.wafer];
            let (g, k) = (&self.config.geometry, &self.config.k);
            let r = if n_model > 0 {
                let a = nearest_model_angles(
                    k,
                    &poses[o.frame],
                    w,
                    o.rim,
                    g.radius,
                    g.thickness,
                    &o.points,
                    n_model,
                )?;
                let mut r = vec![0.0; 2 * o.points.len()];
                point_reprojection_residuals(
                    k,
                    &poses[o.frame],
                    w,
                    o.rim,
                    g.radius,
                    g.thickness,
                    &o.points,
                    &a,
                    1.0,
                    &mut r,
                    None,
                )?;
                r
            } else {
                let mut r = vec![0.0; o.points.len()];
                conic_edge_residuals(
                    k,
                    &poses[o.frame],
                    w,
                    o.rim,
                    g.radius,
                    g.thickness,
                    &o.points,
                    1.0,
                    &mut r,
                    None,
                )?;
                r
            };
            s += r.iter().map(|v| v * v).sum::<f64>();
            n += r.len();
        }
        Ok(if n > 0 {
            (s / n as f64).sqrt()
        } else {
            f64::NAN
        })
    }

    pub(super) fn check_state(&self, s: &SlamMotState) -> Result<()> {
        if s.wafers.len() != self.n_wafers {
            return Err(EstimateError::DimensionMismatch {
                what: "initial wafers".into(),
                expected: vec![self.n_wafers, 5],
                got: vec![s.wafers.len(), 5],
            });
        }
        let vals = s
            .wafers
            .iter()
            .flat_map(|w| w.iter().copied())
            .chain(s.offsets.iter().copied())
            .chain(s.base.translation.vector.iter().copied());
        for (i, v) in vals.enumerate() {
            if !v.is_finite() {
                return Err(EstimateError::NonFiniteInput {
                    what: "initial state".into(),
                    index: i,
                    value: v,
                });
            }
        }
        Ok(())
    }

    /// The online sliding-window solve (§5.3, "a standard sliding-window optimization"):
    /// consecutive windows of `window` frames, each solved with the observations of its
    /// frames and a joint Gaussian prior on the calibration and every wafer seen so far
    /// (the previous window's posterior: its estimates and joint marginal covariance, i.e.
    /// marginalisation of the old frames, whose poses are functions of the calibration).
    /// A wafer first seen in a window enters it with the first window's prior widths
    /// (`base_translation` on its centre, `base_rotation` on its tilts) around its current
    /// estimate. Returns the estimate after every window (Fig. 5.11). The conic factor is used.
    pub fn solve_sliding_window(
        &self,
        initial: &SlamMotState,
        window: usize,
        prior_sigmas: &PriorSigmas,
    ) -> Result<Vec<WindowRecord>> {
        self.check_state(initial)?;
        if window == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "window",
                value: 0.0,
                reason: "the window needs at least one frame",
            });
        }
        let mut state = initial.clone();
        // Prior: blocks → (mean, manifold); covariance over their tangents.
        let n_off = self.config.estimate_offsets.len();
        let n_mount = if self.config.estimate_mount { 6 } else { 0 };
        let n_links = self.config.estimate_links.len();
        let n_cal = 6 + n_off + n_mount + n_links;
        let mut prior_cov = DMatrix::<f64>::zeros(n_cal, n_cal);
        let pose_cov = prior_sigmas.pose_covariance();
        prior_cov.view_mut((0, 0), (6, 6)).copy_from(&pose_cov);
        for i in 0..n_off {
            prior_cov[(6 + i, 6 + i)] = prior_sigmas.offset.powi(2);
        }
        if n_mount > 0 {
            prior_cov
                .view_mut((6 + n_off, 6 + n_off), (6, 6))
                .copy_from(&pose_cov);
        }
        for i in 0..n_links {
            let k = 6 + n_off + n_mount + i;
            prior_cov[(k, k)] = prior_sigmas.base_translation.powi(2);
        }
        let mut prior_wafers: Vec<usize> = Vec::new();
        let mut out = Vec::new();
        let n = self.encoders.len();
        let mut start = 0;
        while start < n {
            let end = (start + window).min(n);
            let (mut p, b, n_res) = self.build(&state, start..end, None)?;
            // Wafers that were seen before but not in this window still get their block (prior only).
            let mut wafer_blocks = b.wafers.clone();
            for &k in &prior_wafers {
                if wafer_blocks[k].is_none() {
                    let blk = p.add_block(state.wafers[k].as_slice(), Manifold::Euclidean(5))?;
                    wafer_blocks[k] = Some(blk);
                }
            }
            // A wafer first seen in this window enters with the prior of the uncalibrated
            // setup around its current estimate (centre ±σ_t, tilts ±σ_r, the base's prior
            // widths): a few edge points of one short arc need not fix all five of its
            // parameters, and without it such a window's posterior would not exist.
            for (k, blk) in b.wafers.iter().enumerate() {
                if let Some(blk) = blk
                    && k != self.config.reference_wafer
                    && !prior_wafers.contains(&k)
                {
                    p.add_prior(
                        *blk,
                        state.wafers[k].as_slice(),
                        &prior_sigmas.wafer_covariance(),
                    )?;
                }
            }
            // Joint prior over base, offsets and previously seen wafers.
            let mut blocks = b.calibration();
            let mut means: Vec<Vec<f64>> = vec![se3_to_params(&state.base).to_vec()];
            let mut manifolds = vec![Manifold::Se3];
            for &j in &self.config.estimate_offsets {
                means.push(vec![state.offsets[j]]);
                manifolds.push(Manifold::Euclidean(1));
            }
            if b.mount.is_some() {
                means.push(se3_to_params(&state.mount).to_vec());
                manifolds.push(Manifold::Se3);
            }
            if b.links.is_some() {
                means.push(
                    self.config
                        .estimate_links
                        .iter()
                        .map(|&l| state.links[l])
                        .collect(),
                );
                manifolds.push(Manifold::Euclidean(n_links));
            }
            for &k in &prior_wafers {
                if let Some(blk) = wafer_blocks[k] {
                    blocks.push(blk);
                    means.push(state.wafers[k].as_slice().to_vec());
                    manifolds.push(Manifold::Euclidean(5));
                }
            }
            let l =
                prior_cov
                    .clone()
                    .cholesky()
                    .ok_or_else(|| EstimateError::InvalidCovariance {
                        what: "sliding-window prior".into(),
                        asymmetry: 0.0,
                        min_eigenvalue: prior_cov.symmetric_eigenvalues().min(),
                    })?;
            let l_inv = l
                .l()
                .try_inverse()
                .ok_or_else(|| EstimateError::LinearSolver("prior factor not invertible".into()))?;
            p.add_residual(
                JointPrior {
                    means,
                    manifolds,
                    l_inv,
                },
                &blocks,
                Loss::Trivial,
            )?;
            if n_res > 0 {
                p.solve(&self.options())?;
            }
            let full = Blocks {
                base: b.base,
                offsets: b.offsets.clone(),
                wafers: wafer_blocks.clone(),
                mount: b.mount,
                links: b.links,
                cameras: b.cameras.clone(),
                noise: b.noise.clone(),
            };
            state = self.read_state(&p, &full, &state);
            // Posterior → next prior (all wafers seen so far, the reference excluded: fixed).
            let mut post_blocks = b.calibration();
            let mut seen: Vec<usize> = Vec::new();
            for (k, w) in wafer_blocks.iter().enumerate() {
                if let Some(w) = w
                    && k != self.config.reference_wafer
                {
                    post_blocks.push(*w);
                    seen.push(k);
                }
            }
            let cov = p.marginal_covariance(&post_blocks)?;
            // New wafers enter the prior with their window posterior; keep the ordering.
            prior_cov = cov;
            prior_wafers = seen;
            let std: Vec<f64> = (0..6 + n_off)
                .map(|i| prior_cov[(i, i)].max(0.0).sqrt())
                .collect();
            out.push(WindowRecord {
                last_frame: end - 1,
                state: state.clone(),
                std,
            });
            start = end;
        }
        Ok(out)
    }
}
