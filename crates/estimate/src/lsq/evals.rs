//! The residual values and Jacobians of one evaluation of a problem, each kind in one contiguous
//! slab (allocated once per solve, filled in place), shared by the solver and the Schur
//! complement.

/// Residuals this many at a time form one parallel evaluation task.
pub(crate) const EVAL_CHUNK: usize = 64;

/// Residual values and Jacobians of every residual block, each kind in one contiguous slab
/// (allocated once per solve, filled in place by [`Problem::evaluate_all`]).
pub(crate) struct Evals {
    /// The residual vectors r_i, concatenated.
    pub(crate) r: Vec<f64>,
    /// Start of each residual in `r`, plus the end.
    pub(crate) r_ptr: Vec<usize>,
    /// The Jacobians ∂r_i/∂δ_k (m_i × d_k, column-major) of every (residual, block),
    /// concatenated in residual order.
    pub(crate) jac: Vec<f64>,
    /// Start of each (residual, block) Jacobian in `jac`, plus the end.
    pub(crate) jac_ptr: Vec<usize>,
    /// Index in `jac_ptr` of each residual's first block, plus the end.
    pub(crate) blk_ptr: Vec<usize>,
    /// ρ(‖r_i‖²) (unweighted cost contribution ×2).
    pub(crate) rho: Vec<f64>,
    /// First residual of each evaluation task, plus the end.
    pub(crate) chunks: Vec<usize>,
    /// Start of each task's residuals in `r`, plus the end.
    pub(crate) r_chunks: Vec<usize>,
    /// Start of each task's Jacobians in `jac`, plus the end.
    pub(crate) jac_chunks: Vec<usize>,
}

/// `dst = src` (equal lengths), inline for the Jacobian sizes of pixel residuals on SE(3) and
/// 3-D blocks (a libc call per 12 numbers would cost more than the copy).
#[inline(always)]
pub(crate) fn copy_small(dst: &mut [f64], src: &[f64]) {
    match (dst.first_chunk_mut::<12>(), src.first_chunk::<12>()) {
        (Some(d), Some(s)) if src.len() == 12 => *d = *s,
        _ => match (dst.first_chunk_mut::<6>(), src.first_chunk::<6>()) {
            (Some(d), Some(s)) if src.len() == 6 => *d = *s,
            _ => dst.copy_from_slice(src),
        },
    }
}

/// `s = 0`, inline for the sizes of [`copy_small`].
#[inline(always)]
pub(crate) fn zero_small(s: &mut [f64]) {
    let n = s.len();
    match s.first_chunk_mut::<12>() {
        Some(c) if n == 12 => *c = [0.0; 12],
        _ => match s.first_chunk_mut::<6>() {
            Some(c) if n == 6 => *c = [0.0; 6],
            _ => s.fill(0.0),
        },
    }
}

/// One evaluated residual block: its (loss-weighted) residual and Jacobians.
#[derive(Clone, Copy)]
pub(crate) struct EvalBuf<'a> {
    /// The residual (m values).
    pub r: &'a [f64],
    pub(crate) jac: &'a [f64],
    pub(crate) ptr: &'a [usize],
}

impl<'a> EvalBuf<'a> {
    /// ∂r/∂δ_k w.r.t. the k-th block of the residual (m × d_k, column-major).
    #[inline(always)]
    pub fn jac(&self, k: usize) -> &'a [f64] {
        &self.jac[self.ptr[k]..self.ptr[k + 1]]
    }
}

impl Evals {
    /// Residual block `i`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> EvalBuf<'_> {
        EvalBuf {
            r: &self.r[self.r_ptr[i]..self.r_ptr[i + 1]],
            jac: &self.jac,
            ptr: &self.jac_ptr[self.blk_ptr[i]..=self.blk_ptr[i + 1]],
        }
    }

    /// Total residual dimension.
    pub fn residual_dim(&self) -> usize {
        self.r.len()
    }
}
