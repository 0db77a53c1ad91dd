//! Levenberg–Marquardt (trust region, Nielsen's damping update) and Gauss–Newton on
//! manifolds (seed 004_815695db12a6b16c.txt eq. (5.2)–(5.5); seed 000_3b1454b2b2194811.txt
//! ch. 5.3): residuals and Jacobians evaluated in parallel, normal equations assembled by
//! block structure and solved by Cholesky (dense, sparse, or sparse with the point-like
//! blocks eliminated first — the Schur complement).

use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::SymbolicSparseColMatRef;
use faer::sparse::linalg::amd;
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::evals::{EVAL_CHUNK, Evals, copy_small, zero_small};
use super::layout::Layout;
use super::linear::{Cholesky, Pattern};
use super::problem::Problem;
use super::schur::{DENSE_CAMERA_LIMIT, SchurSystem};
use crate::{EstimateError, Result};

/// The nonlinear iteration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Levenberg–Marquardt: (JᵀJ + μ D) δ = −Jᵀr with D = diag(JᵀJ) (Marquardt scaling,
    /// clamped to [1e-6, 1e32]); steps accepted when the gain ratio ρ > 0, μ updated as in
    /// Nielsen (1999): μ ← μ·max(1/3, 1 − (2ρ − 1)³) on success, μ ← μ·ν, ν ← 2ν on failure.
    #[default]
    LevenbergMarquardt,
    /// Gauss–Newton: JᵀJ δ = −Jᵀr, every finite step accepted.
    GaussNewton,
}

/// How the normal equations are solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinearSolver {
    /// Dense below `SolverOptions::dense_threshold` unknowns; otherwise `SparseSchur` when
    /// eliminable (point-like) blocks hold at least half of the unknowns, else
    /// `SparseCholesky`.
    #[default]
    Auto,
    /// Dense Cholesky (nalgebra).
    DenseCholesky,
    /// Sparse Cholesky (faer) with an approximate-minimum-degree fill-reducing ordering.
    SparseCholesky,
    /// Schur complement: the eliminated (point-like) blocks are removed first and only the
    /// reduced camera system S = H_cc − H_cp H_pp⁻¹ H_pc is factored. When no residual touches
    /// two eliminated blocks (H_pp block diagonal: bundle adjustment), S is built explicitly
    /// (`schur.rs`: per-point elimination in parallel, dense Cholesky of S up to 2000 camera
    /// unknowns, faer sparse Cholesky beyond, LM damping on both H_pp and H_cc); otherwise the
    /// whole system goes to the sparse factor with the eliminated blocks ordered first. Blocks
    /// are eliminated when marked with [`Problem::set_eliminate`]`(b, Some(true))`, or
    /// automatically: free `Euclidean(3)` blocks (points) none of whose residuals touches
    /// another eliminated block.
    SparseSchur,
}

/// Solver settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SolverOptions {
    /// The iteration.
    pub method: Method,
    /// Maximum number of iterations (trial steps, accepted or not).
    pub max_iterations: usize,
    /// Stop when an accepted step decreases the cost by less than this fraction of it.
    pub function_tolerance: f64,
    /// Stop when max |Jᵀr| ≤ this.
    pub gradient_tolerance: f64,
    /// Stop when ‖δ‖ ≤ this · (‖x‖ + this) (x: the free ambient values).
    pub parameter_tolerance: f64,
    /// Linear solver.
    pub linear_solver: LinearSolver,
    /// Initial LM damping μ₀ (relative to diag(JᵀJ)).
    pub initial_damping: f64,
    /// `Auto` uses the dense solver up to this many unknowns.
    pub dense_threshold: usize,
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self {
            method: Method::LevenbergMarquardt,
            max_iterations: 100,
            function_tolerance: 1e-10,
            gradient_tolerance: 1e-10,
            parameter_tolerance: 1e-10,
            linear_solver: LinearSolver::Auto,
            initial_damping: 1e-4,
            dense_threshold: 250,
        }
    }
}

impl SolverOptions {
    fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("function_tolerance", self.function_tolerance),
            ("gradient_tolerance", self.gradient_tolerance),
            ("parameter_tolerance", self.parameter_tolerance),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be finite and non-negative",
                });
            }
        }
        if !(self.initial_damping.is_finite() && self.initial_damping > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "initial_damping",
                value: self.initial_damping,
                reason: "must be finite and positive",
            });
        }
        Ok(())
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// Relative cost decrease below `function_tolerance`.
    FunctionTolerance,
    /// Gradient below `gradient_tolerance`.
    GradientTolerance,
    /// Step below `parameter_tolerance`.
    ParameterTolerance,
    /// `max_iterations` reached.
    MaxIterations,
    /// Every block is fixed (or there are no residuals): nothing to optimise.
    NoFreeParameters,
    /// LM: the damping grew beyond 1e32 without an acceptable step (e.g. every trial step
    /// makes a residual non-finite).
    DampingLimit,
    /// Gauss–Newton: the normal matrix is not positive definite (rank deficient); LM never
    /// stops for this, it raises the damping.
    LinearSolverFailure,
    /// A residual or Jacobian became non-finite at an accepted point (Gauss–Newton) — the
    /// values are left at the last finite point. See `Summary::message`.
    NonFinite,
}

impl Termination {
    /// Whether this is a convergence criterion (as opposed to a failure or a limit).
    pub fn converged(&self) -> bool {
        matches!(
            self,
            Termination::FunctionTolerance
                | Termination::GradientTolerance
                | Termination::ParameterTolerance
                | Termination::NoFreeParameters
        )
    }
}

/// What the solver did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Iterations (trial steps).
    pub iterations: usize,
    /// Accepted steps.
    pub successful_steps: usize,
    /// Cost ½ Σ ρ(‖r‖²) at the start.
    pub initial_cost: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// Why it stopped.
    pub termination: Termination,
    /// Human-readable reason.
    pub message: String,
    /// Wall time of the solve (s).
    pub time_s: f64,
    /// Linear solver used (resolved from `Auto`).
    pub linear_solver: LinearSolver,
    /// Free tangent dimension.
    pub num_parameters: usize,
    /// Total residual dimension.
    pub num_residuals: usize,
    /// Blocks eliminated first (Schur), 0 unless `SparseSchur`.
    pub num_eliminated_blocks: usize,
    /// max |Jᵀr| at the end.
    pub gradient_max_norm: f64,
    /// Time (s) in structure analysis (block pattern, ordering, symbolic factorisation).
    pub time_setup_s: f64,
    /// Time (s) evaluating residuals and Jacobians.
    pub time_evaluate_s: f64,
    /// Time (s) assembling the normal equations.
    pub time_assemble_s: f64,
    /// Time (s) factorising and solving the normal equations.
    pub time_linear_s: f64,
    /// Part of `time_linear_s` spent eliminating the point blocks (explicit reduced camera
    /// system: per-point factorisation, forming S and its right-hand side, back-substituting
    /// the points); 0 for the other solvers.
    pub time_schur_reduce_s: f64,
    /// Part of `time_linear_s` spent factorising and solving the reduced camera system
    /// (explicit Schur path); 0 for the other solvers.
    pub time_schur_factor_s: f64,
}

impl Layout {
    /// The solver `Auto` resolves to (others unchanged).
    pub fn resolve(&self, choice: LinearSolver, dense_threshold: usize) -> LinearSolver {
        match choice {
            LinearSolver::Auto => {
                if self.n <= dense_threshold {
                    LinearSolver::DenseCholesky
                } else if 2 * self.eliminated_dim() >= self.n {
                    LinearSolver::SparseSchur
                } else {
                    LinearSolver::SparseCholesky
                }
            }
            c => c,
        }
    }
}

/// The block structure of the free unknowns with the pattern of JᵀJ, fixed for one solve
/// (dereferences to its [`Layout`]).
pub(crate) struct Structure {
    /// Free blocks and elimination candidates.
    pub layout: Layout,
    /// Pattern of JᵀJ.
    pub pattern: Pattern,
    /// Per residual: `(local k_a, local k_b, slot)` for every pair of free blocks, the row
    /// block `a` having the larger free index.
    pub res_pairs: Vec<Vec<(usize, usize, usize)>>,
}

impl std::ops::Deref for Structure {
    type Target = Layout;
    fn deref(&self) -> &Layout {
        &self.layout
    }
}

impl Structure {
    pub fn new(p: &Problem) -> Self {
        Self::from_layout(p, Layout::new(p))
    }

    /// Adds the pattern of JᵀJ to a layout.
    pub fn from_layout(p: &Problem, layout: Layout) -> Self {
        let free_index = &layout.free_index;
        let mut pairs = Vec::new();
        for r in &p.residuals {
            let fr: Vec<usize> = r.blocks.iter().filter_map(|b| free_index[b.0]).collect();
            for (i, &a) in fr.iter().enumerate() {
                for &b in &fr[..i] {
                    pairs.push((a, b));
                }
            }
        }
        let pattern = Pattern::new(&layout.dims, pairs);
        let res_pairs = p
            .residuals
            .iter()
            .map(|r| {
                let mut out = Vec::new();
                for (ka, a) in r.blocks.iter().enumerate() {
                    let Some(fa) = free_index[a.0] else { continue };
                    for (kb, b) in r.blocks.iter().enumerate() {
                        let Some(fb) = free_index[b.0] else { continue };
                        if fa >= fb
                            && let Some(&slot) = pattern.slots.get(&(fa, fb))
                        {
                            out.push((ka, kb, slot));
                        }
                    }
                }
                out
            })
            .collect();
        Self {
            layout,
            pattern,
            res_pairs,
        }
    }

    /// A fill-reducing order with the eliminated blocks first (AMD order kept within each
    /// group).
    fn schur_ordering(&self) -> Result<(Vec<usize>, Vec<usize>)> {
        let n = self.n;
        let nnz = self.pattern.nnz();
        let mut perm = vec![0usize; n];
        let mut perm_inv = vec![0usize; n];
        let mut mem = MemBuffer::try_new(amd::order_scratch::<usize>(n, nnz))
            .map_err(|e| EstimateError::LinearSolver(format!("AMD workspace: {e:?}")))?;
        let sym = SymbolicSparseColMatRef::new_checked(
            n,
            n,
            &self.pattern.col_ptr,
            None,
            &self.pattern.row_idx,
        );
        amd::order(
            &mut perm,
            &mut perm_inv,
            sym,
            amd::Control::default(),
            MemStack::new(&mut mem),
        )
        .map_err(|e| EstimateError::LinearSolver(format!("AMD ordering: {e:?}")))?;
        let mut scalar_elim = vec![false; n];
        for (f, &e) in self.eliminated.iter().enumerate() {
            if e {
                scalar_elim[self.col_offset[f]..self.col_offset[f] + self.dims[f]].fill(true);
            }
        }
        let mut fwd: Vec<usize> = perm.iter().copied().filter(|&i| scalar_elim[i]).collect();
        fwd.extend(perm.iter().copied().filter(|&i| !scalar_elim[i]));
        let mut inv = vec![0usize; n];
        for (i, &f) in fwd.iter().enumerate() {
            inv[f] = i;
        }
        Ok((fwd, inv))
    }

    /// The factorisation for the chosen solver.
    pub fn make_solver(&self, resolved: LinearSolver) -> Result<Cholesky> {
        let ch = match resolved {
            LinearSolver::DenseCholesky => Cholesky::new(&self.pattern, true, None)?,
            LinearSolver::SparseSchur => {
                let (fwd, inv) = self.schur_ordering()?;
                Cholesky::new(&self.pattern, false, Some((&fwd, &inv)))?
            }
            _ => Cholesky::new(&self.pattern, false, None)?,
        };
        Ok(ch)
    }
}

/// The normal-equation machinery of one solve.
enum Normal {
    /// JᵀJ in its block pattern, factored by dense or sparse Cholesky (for `SparseSchur`
    /// with coupled eliminated blocks: the sparse factor with those blocks ordered first).
    Full {
        st: Box<Structure>,
        chol: Box<Cholesky>,
        h: Vec<f64>,
        hd: Vec<f64>,
    },
    /// The explicit reduced camera system (`SparseSchur` with independent point blocks).
    Schur(Box<SchurSystem>),
}

impl Normal {
    fn new(p: &Problem, layout: Layout, resolved: LinearSolver) -> Result<Self> {
        if resolved == LinearSolver::SparseSchur && SchurSystem::applicable(p, &layout) {
            let sys = SchurSystem::new(p, &layout, DENSE_CAMERA_LIMIT)?;
            return Ok(Normal::Schur(Box::new(sys)));
        }
        let st = Structure::from_layout(p, layout);
        let chol = st.make_solver(resolved)?;
        let h = vec![0.0; st.pattern.nnz()];
        Ok(Normal::Full {
            hd: h.clone(),
            h,
            chol: Box::new(chol),
            st: Box::new(st),
        })
    }

    /// Gradient g = Jᵀr and diag(JᵀJ) (and whatever the step needs) from evaluated buffers.
    fn assemble(&mut self, p: &Problem, bufs: &Evals, g: &mut [f64], hdiag: &mut [f64]) {
        match self {
            Normal::Full { st, h, .. } => {
                p.assemble(st, bufs, h, g);
                for (d, &pos) in hdiag.iter_mut().zip(&st.pattern.diag_pos) {
                    *d = h[pos];
                }
            }
            Normal::Schur(sys) => sys.assemble(bufs, g, hdiag),
        }
    }

    /// Solves (JᵀJ + μ·diag(damp)) δ = −g; `Ok(Err(col))` when the matrix is not
    /// numerically positive definite.
    fn step(
        &mut self,
        bufs: &Evals,
        mu: f64,
        damp: &[f64],
        g: &[f64],
        delta: &mut [f64],
    ) -> Result<std::result::Result<(), Option<usize>>> {
        match self {
            Normal::Full { st, chol, h, hd } => {
                hd.copy_from_slice(h);
                for (c, &pos) in st.pattern.diag_pos.iter().enumerate() {
                    hd[pos] += mu * damp[c];
                }
                if let Err(col) = chol.factor(&st.pattern, hd) {
                    return Ok(Err(col));
                }
                for (d, gi) in delta.iter_mut().zip(g) {
                    *d = -gi;
                }
                chol.solve_in_place(delta, st.n, 1)?;
                Ok(Ok(()))
            }
            Normal::Schur(sys) => sys.solve(bufs, mu, damp, delta),
        }
    }
}

impl Problem {
    /// Evaluates every residual (in parallel) at `values`, with Jacobians when `jac`;
    /// robust losses are applied as IRLS weights: r and J are scaled by √ρ′(‖r‖²) so that
    /// Jᵀr is the exact gradient of ½ Σ ρ and JᵀJ the Gauss–Newton approximation with the
    /// curvature term 2ρ″ Jᵀr rᵀJ dropped (it would make the normal matrix indefinite for
    /// the provided losses, whose ρ″ ≤ 0; Triggs et al., "Bundle adjustment — a modern
    /// synthesis", Sec. 4.3). Returns the cost ½ Σ ρ(‖r‖²), or the first non-finite value.
    pub(crate) fn evaluate_all(&self, values: &[f64], bufs: &mut Evals, jac: bool) -> Result<f64> {
        let blocks = &self.blocks;
        let Evals {
            r,
            r_ptr,
            jac: jslab,
            jac_ptr,
            blk_ptr,
            rho,
            chunks,
            r_chunks,
            jac_chunks,
        } = bufs;
        let (r_ptr, jac_ptr, blk_ptr, chunks) = (&*r_ptr, &*jac_ptr, &*blk_ptr, &*chunks);
        let r_pieces = super::schur::split_pieces(r, r_chunks);
        let j_pieces = super::schur::split_pieces(jslab, jac_chunks);
        // The first failing residual (lowest index) wins, independently of the scheduling:
        // tasks are contiguous residual ranges and each stops at its first failure.
        let failure = r_pieces
            .into_par_iter()
            .zip(j_pieces)
            .zip(rho.par_chunks_mut(EVAL_CHUNK))
            .enumerate()
            .map_init(
                Vec::<DMatrix<f64>>::new,
                |scratch, (c, ((rc, jc), rhoc))| -> Result<()> {
                    let (i0, i1) = (chunks[c], chunks[c + 1]);
                    let (r0, j0) = (r_ptr[i0], jac_ptr[blk_ptr[i0]]);
                    for i in i0..i1 {
                        let res = &self.residuals[i];
                        let buf_r = &mut rc[r_ptr[i] - r0..r_ptr[i + 1] - r0];
                        let m = buf_r.len();
                        let slice = |b: &super::problem::BlockId| -> &[f64] {
                            let blk = &blocks[b.0];
                            &values[blk.offset..blk.offset + blk.manifold.ambient_dim()]
                        };
                        // Parameter slices on the stack for up to 8 blocks (no allocation).
                        let mut small: [&[f64]; 8] = [&[]; 8];
                        let heap: Vec<&[f64]>;
                        let params: &[&[f64]] = if res.blocks.len() <= small.len() {
                            for (s, b) in small.iter_mut().zip(&res.blocks) {
                                *s = slice(b);
                            }
                            &small[..res.blocks.len()]
                        } else {
                            heap = res.blocks.iter().map(slice).collect();
                            &heap
                        };
                        let nb = res.blocks.len();
                        if jac {
                            // The trait's DMatrix Jacobians live in per-task scratch,
                            // reshaped only when the block sizes change.
                            if scratch.len() < nb {
                                scratch.resize(nb, DMatrix::zeros(0, 0));
                            }
                            for (j, b) in scratch.iter_mut().zip(&res.blocks) {
                                let d = blocks[b.0].manifold.tangent_dim();
                                if j.shape() == (m, d) {
                                    zero_small(j.as_mut_slice());
                                } else {
                                    *j = DMatrix::zeros(m, d);
                                }
                            }
                            res.residual
                                .evaluate(params, buf_r, Some(&mut scratch[..nb]))?;
                        } else {
                            res.residual.evaluate(params, buf_r, None)?;
                        }
                        if buf_r.iter().any(|v| !v.is_finite())
                            && let Some((index, &value)) =
                                buf_r.iter().enumerate().find(|(_, v)| !v.is_finite())
                        {
                            return Err(EstimateError::NonFiniteResidual {
                                residual: i,
                                index,
                                value,
                                context: String::new(),
                            });
                        }
                        let s: f64 = buf_r.iter().map(|v| v * v).sum();
                        if !s.is_finite() {
                            // Finite components whose squares overflow: no cost to minimise.
                            return Err(EstimateError::NonFiniteResidual {
                                residual: i,
                                index: 0,
                                value: s,
                                context: " (its squared norm overflows f64)".into(),
                            });
                        }
                        let [rho_i, d1] = res.loss.evaluate(s);
                        rhoc[i - i0] = rho_i;
                        if jac {
                            let js =
                                &mut jc[jac_ptr[blk_ptr[i]] - j0..jac_ptr[blk_ptr[i + 1]] - j0];
                            let mut o = 0;
                            for (k, j) in scratch[..nb].iter().enumerate() {
                                let src = j.as_slice();
                                if !src.iter().all(|v| v.is_finite())
                                    && let Some((index, &value)) =
                                        src.iter().enumerate().find(|(_, v)| !v.is_finite())
                                {
                                    return Err(EstimateError::NonFiniteResidual {
                                        residual: i,
                                        index,
                                        value,
                                        context: format!(
                                            " in its Jacobian w.r.t. block {}",
                                            res.blocks[k].0
                                        ),
                                    });
                                }
                                copy_small(&mut js[o..o + src.len()], src);
                                o += src.len();
                            }
                            if d1 != 1.0 {
                                let w = d1.max(0.0).sqrt();
                                buf_r.iter_mut().for_each(|v| *v *= w);
                                js.iter_mut().for_each(|v| *v *= w);
                            }
                        }
                    }
                    Ok(())
                },
            )
            .find_map_first(|r| r.err());
        if let Some(e) = failure {
            return Err(e);
        }
        Ok(0.5 * rho.iter().sum::<f64>())
    }

    /// Evaluation storage for every residual block (see [`Evals`]).
    pub(crate) fn make_buffers(&self) -> Evals {
        let nres = self.residuals.len();
        let mut r_ptr = Vec::with_capacity(nres + 1);
        let mut blk_ptr = Vec::with_capacity(nres + 1);
        let mut jac_ptr = Vec::with_capacity(2 * nres + 1);
        let (mut nr, mut nj) = (0, 0);
        for res in &self.residuals {
            let m = res.residual.dim();
            r_ptr.push(nr);
            blk_ptr.push(jac_ptr.len());
            for b in &res.blocks {
                jac_ptr.push(nj);
                nj += m * self.blocks[b.0].manifold.tangent_dim();
            }
            nr += m;
        }
        r_ptr.push(nr);
        blk_ptr.push(jac_ptr.len());
        jac_ptr.push(nj);
        let chunks: Vec<usize> = (0..nres)
            .step_by(EVAL_CHUNK)
            .chain(std::iter::once(nres))
            .collect();
        let r_chunks = chunks.iter().map(|&i| r_ptr[i]).collect();
        let jac_chunks = chunks.iter().map(|&i| jac_ptr[blk_ptr[i]]).collect();
        Evals {
            r: vec![0.0; nr],
            r_ptr,
            jac: vec![0.0; nj],
            jac_ptr,
            blk_ptr,
            rho: vec![0.0; nres],
            chunks,
            r_chunks,
            jac_chunks,
        }
    }

    /// Assembles JᵀJ (lower CSC values of `st.pattern`) and g = Jᵀr from evaluated buffers.
    pub(crate) fn assemble(&self, st: &Structure, bufs: &Evals, h: &mut [f64], g: &mut [f64]) {
        h.iter_mut().for_each(|v| *v = 0.0);
        g.iter_mut().for_each(|v| *v = 0.0);
        for (i, (res, pairs)) in self.residuals.iter().zip(&st.res_pairs).enumerate() {
            let buf = bufs.get(i);
            let m = buf.r.len().max(1);
            for (k, b) in res.blocks.iter().enumerate() {
                if let Some(f) = st.free_index[b.0] {
                    let off = st.col_offset[f];
                    for (c, col) in buf.jac(k).chunks_exact(m).enumerate() {
                        g[off + c] += col.iter().zip(buf.r).map(|(a, b)| a * b).sum::<f64>();
                    }
                }
            }
            for &(ka, kb, slot) in pairs {
                st.pattern
                    .add_product(h, slot, buf.jac(ka), buf.jac(kb), buf.r.len());
            }
        }
    }

    /// `out = values ⊕ δ` for the free blocks (fixed blocks copied).
    pub(crate) fn retract(&self, st: &Layout, values: &[f64], delta: &[f64], out: &mut [f64]) {
        out.copy_from_slice(values);
        for (f, &b) in st.free_blocks.iter().enumerate() {
            let blk = &self.blocks[b];
            let a = blk.manifold.ambient_dim();
            let off = st.col_offset[f];
            blk.manifold.plus(
                &values[blk.offset..blk.offset + a],
                &delta[off..off + st.dims[f]],
                &mut out[blk.offset..blk.offset + a],
            );
        }
    }

    /// Minimises ½ Σ ρ(‖r‖²) from the current values, which are updated in place. Errors
    /// on invalid options or a non-finite residual/Jacobian at the initial values; stops
    /// with a [`Summary`] saying why otherwise.
    ///
    /// Called from outside rayon's pool, the whole solve moves onto a pool thread once, so the
    /// parallel loops of every iteration (evaluation, Schur elimination) start from a worker
    /// instead of each waking the pool from outside and blocking until it is done: with one
    /// rayon thread they run in place, with no thread hand-over per loop (which costs a context
    /// switch each, and far more on a loaded machine). The arithmetic is the same.
    pub fn solve(&mut self, options: &SolverOptions) -> Result<Summary> {
        if rayon::current_thread_index().is_some() {
            self.solve_in_pool(options)
        } else {
            rayon::scope(|_| self.solve_in_pool(options))
        }
    }

    /// [`Problem::solve`] on the current thread.
    fn solve_in_pool(&mut self, options: &SolverOptions) -> Result<Summary> {
        let t0 = Instant::now();
        options.validate()?;
        let layout = Layout::new(self);
        let mut bufs = self.make_buffers();
        let num_residuals = bufs.residual_dim();
        let mut values = self.values.clone();
        let t_setup = t0.elapsed().as_secs_f64();
        let te = Instant::now();
        let initial_cost = self.evaluate_all(&values, &mut bufs, true)?;
        let mut time_eval = te.elapsed().as_secs_f64();
        let n = layout.n;
        let mut summary = Summary {
            iterations: 0,
            successful_steps: 0,
            initial_cost,
            final_cost: initial_cost,
            termination: Termination::NoFreeParameters,
            message: String::new(),
            time_s: 0.0,
            linear_solver: options.linear_solver,
            num_parameters: n,
            num_residuals,
            num_eliminated_blocks: 0,
            gradient_max_norm: 0.0,
            time_setup_s: 0.0,
            time_evaluate_s: 0.0,
            time_assemble_s: 0.0,
            time_linear_s: 0.0,
            time_schur_reduce_s: 0.0,
            time_schur_factor_s: 0.0,
        };
        if n == 0 || self.residuals.is_empty() {
            summary.message = "no free parameters or no residuals".into();
            summary.time_s = t0.elapsed().as_secs_f64();
            return Ok(summary);
        }
        let ts = Instant::now();
        let resolved = layout.resolve(options.linear_solver, options.dense_threshold);
        if resolved == LinearSolver::SparseSchur {
            summary.num_eliminated_blocks = layout.eliminated.iter().filter(|e| **e).count();
        }
        let mut normal = Normal::new(self, layout.clone(), resolved)?;
        let layout = &layout;
        summary.time_setup_s = t_setup + ts.elapsed().as_secs_f64();
        let mut time_asm = 0.0;
        let mut time_lin = 0.0;
        summary.linear_solver = resolved;
        let lm = options.method == Method::LevenbergMarquardt;
        let mut g = vec![0.0; n];
        let mut hdiag = vec![0.0; n];
        // LM scaling D = diag(JᵀJ) clamped to [1e-6, 1e32] (zero for Gauss–Newton).
        let mut ddd = vec![0.0; n];
        let mut delta = vec![0.0; n];
        let mut cand = values.clone();
        let ta = Instant::now();
        normal.assemble(self, &bufs, &mut g, &mut hdiag);
        time_asm += ta.elapsed().as_secs_f64();
        let scaling = |hdiag: &[f64], ddd: &mut [f64]| {
            if lm {
                for (d, h) in ddd.iter_mut().zip(hdiag) {
                    *d = h.clamp(1e-6, 1e32);
                }
            }
        };
        scaling(&hdiag, &mut ddd);
        let mut cost = initial_cost;
        let mut mu = if lm { options.initial_damping } else { 0.0 };
        let mut nu = 2.0;
        let free_ambient = |v: &[f64]| -> f64 {
            layout
                .free_blocks
                .iter()
                .map(|&b| {
                    let blk = &self.blocks[b];
                    v[blk.offset..blk.offset + blk.manifold.ambient_dim()]
                        .iter()
                        .map(|x| x * x)
                        .sum::<f64>()
                })
                .sum::<f64>()
                .sqrt()
        };
        let gmax = |g: &[f64]| g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let (termination, message) = loop {
            let gm = gmax(&g);
            if gm <= options.gradient_tolerance {
                break (
                    Termination::GradientTolerance,
                    format!("max |Jᵀr| = {gm:.3e} ≤ {:.1e}", options.gradient_tolerance),
                );
            }
            if summary.iterations >= options.max_iterations {
                break (
                    Termination::MaxIterations,
                    format!("reached max_iterations = {}", options.max_iterations),
                );
            }
            summary.iterations += 1;
            let tl = Instant::now();
            let solved = normal.step(&bufs, mu, &ddd, &g, &mut delta)?;
            time_lin += tl.elapsed().as_secs_f64();
            if let Err(col) = solved {
                if lm {
                    mu *= nu;
                    nu *= 2.0;
                    if mu > 1e32 {
                        break (
                            Termination::DampingLimit,
                            "damping exceeded 1e32: the damped normal matrix never became positive definite".into(),
                        );
                    }
                    continue;
                }
                let where_ = col
                    .map(|c| self.describe_column(layout, c))
                    .unwrap_or_else(|| "unknown column".into());
                break (
                    Termination::LinearSolverFailure,
                    format!(
                        "Gauss–Newton normal matrix is not positive definite (rank deficient at {where_}); use Levenberg–Marquardt, fix the gauge or add priors"
                    ),
                );
            }
            let step = delta.iter().map(|v| v * v).sum::<f64>().sqrt();
            let xn = free_ambient(&values);
            if step <= options.parameter_tolerance * (xn + options.parameter_tolerance) {
                break (
                    Termination::ParameterTolerance,
                    format!("‖δ‖ = {step:.3e} ≤ parameter_tolerance·(‖x‖ + tol)"),
                );
            }
            self.retract(layout, &values, &delta, &mut cand);
            let te = Instant::now();
            let new_cost = self
                .evaluate_all(&cand, &mut bufs, false)
                .unwrap_or(f64::INFINITY);
            time_eval += te.elapsed().as_secs_f64();
            let gd: f64 = g.iter().zip(&delta).map(|(a, b)| a * b).sum();
            let dd: f64 = ddd.iter().zip(&delta).map(|(a, b)| a * b * b).sum();
            let predicted = 0.5 * (-gd + mu * dd);
            let actual = cost - new_cost;
            let rho = if predicted > 0.0 {
                actual / predicted
            } else {
                f64::NEG_INFINITY
            };
            let accept = if lm {
                new_cost.is_finite() && rho > 0.0
            } else {
                new_cost.is_finite()
            };
            if !accept {
                if !lm {
                    break (
                        Termination::NonFinite,
                        "the Gauss–Newton step made a residual non-finite; values left at the last finite point".into(),
                    );
                }
                mu *= nu;
                nu *= 2.0;
                if mu > 1e32 {
                    break (
                        Termination::DampingLimit,
                        format!(
                            "damping exceeded 1e32 without an acceptable step (last trial cost {new_cost:.6e})"
                        ),
                    );
                }
                continue;
            }
            summary.successful_steps += 1;
            std::mem::swap(&mut values, &mut cand);
            let old = cost;
            let te = Instant::now();
            let evaluated = self.evaluate_all(&values, &mut bufs, true);
            time_eval += te.elapsed().as_secs_f64();
            cost = match evaluated {
                Ok(c) => c,
                Err(e) => {
                    // Go back to the last point where everything was finite.
                    std::mem::swap(&mut values, &mut cand);
                    break (
                        Termination::NonFinite,
                        format!("after an accepted step: {e}"),
                    );
                }
            };
            let ta = Instant::now();
            normal.assemble(self, &bufs, &mut g, &mut hdiag);
            scaling(&hdiag, &mut ddd);
            time_asm += ta.elapsed().as_secs_f64();
            if lm {
                let t = 2.0 * rho - 1.0;
                mu *= (1.0f64 / 3.0).max(1.0 - t * t * t);
                nu = 2.0;
            }
            if (old - cost).abs() <= options.function_tolerance * old {
                break (
                    Termination::FunctionTolerance,
                    format!(
                        "relative cost change {:.3e} ≤ {:.1e}",
                        (old - cost).abs() / old.max(f64::MIN_POSITIVE),
                        options.function_tolerance
                    ),
                );
            }
        };
        // `cost` is the cost at the values kept (a rejected trial never replaces them).
        summary.final_cost = cost;
        self.values = values;
        summary.termination = termination;
        summary.message = message;
        summary.gradient_max_norm = gmax(&g);
        summary.time_evaluate_s = time_eval;
        summary.time_assemble_s = time_asm;
        summary.time_linear_s = time_lin;
        if let Normal::Schur(sys) = &normal {
            summary.time_schur_reduce_s = sys.time_reduce_s;
            summary.time_schur_factor_s = sys.time_factor_s;
        }
        summary.time_s = t0.elapsed().as_secs_f64();
        Ok(summary)
    }

    /// "block b (tangent component c)" for a scalar column of the free unknowns.
    pub(crate) fn describe_column(&self, st: &Layout, col: usize) -> String {
        match st.col_offset.iter().rposition(|&o| o <= col) {
            Some(f) => format!(
                "block {} ({:?}) tangent component {}",
                st.free_blocks[f],
                self.blocks[st.free_blocks[f]].manifold,
                col - st.col_offset[f]
            ),
            None => format!("column {col}"),
        }
    }
}
