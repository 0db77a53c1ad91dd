//! The explicit reduced camera system (Schur complement) for problems with many point-like
//! blocks: the damped normal equations
//!
//! ```text
//! [ H_cc + μD_c   H_cp        ] [δ_c]   [−g_c]
//! [ H_pc          H_pp + μD_p ] [δ_p] = [−g_p]
//! ```
//!
//! are reduced to S δ_c = −g_c + H_cp (H_pp + μD_p)⁻¹ g_p with
//! S = H_cc + μD_c − H_cp (H_pp + μD_p)⁻¹ H_pc, then δ_p = (H_pp + μD_p)⁻¹ (−g_p − H_pc δ_c)
//! (Triggs et al., "Bundle adjustment — a modern synthesis", Sec. 6.1, eq. (19)–(20); the
//! normal equations of the LM step, seed 004_815695db12a6b16c.txt eq. (5.4)–(5.5), applied to
//! the camera/landmark factor graph of seed 000_3b1454b2b2194811.txt ch. 5.3).
//!
//! Point-like blocks are the eliminated free blocks (free `Euclidean(3)` blocks by default, or
//! blocks marked with `Problem::set_eliminate`) when no residual touches two of them, so H_pp
//! is block diagonal: each block is factored on its own (H_pp,i + μD_i = L_i L_iᵀ) and enters
//! S through Y_ai = H_ai L_i⁻ᵀ as S_ab −= Y_ai Y_biᵀ. The eliminations run in parallel (rayon)
//! over points; S is accumulated in parallel over its column blocks (each task owns the
//! columns of one camera block, so the sums are deterministic). S is dense (faer's blocked
//! Cholesky) up to [`DENSE_CAMERA_LIMIT`] camera unknowns, sparse (faer, AMD ordering, symbolic
//! analysis once) beyond. All work buffers are allocated once per solve.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltRegularization, cholesky_in_place};
use faer::linalg::cholesky::llt::solve::solve_in_place_with_conj;
use faer::{Conj, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::evals::{EvalBuf, Evals};
use super::layout::Layout;
use super::linear::{Cholesky, Pattern};
use super::problem::Problem;
use crate::{EstimateError, Result};

mod dense;
use dense::{backward, dot, forward, small_cholesky};

/// Up to this many camera (non-eliminated) unknowns the reduced camera matrix S is dense.
pub(crate) const DENSE_CAMERA_LIMIT: usize = 2000;

/// A point-like (eliminated) block and its per-point work storage.
struct PointBlock {
    /// Column of its first tangent component in the full ordering.
    col: usize,
    /// Tangent dimension d_p.
    dim: usize,
    /// Residuals touching it: `(residual, local index of the point in the residual)`.
    res: Vec<(usize, usize)>,
    /// For each entry of `res`, the range in `res_cams` of its free camera blocks.
    res_cam_ptr: Vec<usize>,
    /// `(local index in the residual, pair index)` of the free camera blocks of each residual.
    res_cams: Vec<(usize, usize)>,
    /// Camera blocks coupled to the point (ascending camera index), one per pair.
    cams: Vec<usize>,
    /// Offset of each pair's d_a × d_p block in `hcp` and `y`.
    pair_off: Vec<usize>,
    /// H_pp (d_p × d_p, column-major), undamped.
    hpp: Vec<f64>,
    /// g_p = J_pᵀ r.
    gp: Vec<f64>,
    /// H_ap = J_aᵀ J_p per pair (d_a × d_p column-major).
    hcp: Vec<f64>,
    /// Cholesky factor L of H_pp + μD_p (lower, column-major).
    l: Vec<f64>,
    /// Start of its Y_a = H_ap L⁻ᵀ blocks (d_a × d_p column-major, at `y_off + pair_off`)
    /// in `SchurSystem::y`.
    y_off: usize,
    /// Per pair: offset of the copy of Y_a in the camera-major `SchurSystem::yc`.
    yc_pair: Vec<usize>,
    /// z = L⁻¹ g_p.
    z: Vec<f64>,
    /// Step δ_p.
    dx: Vec<f64>,
    /// L⁻¹ (lower, column-major).
    linv: Vec<f64>,
}

/// A camera (kept) block.
struct CamBlock {
    /// Column of its first tangent component in the full ordering.
    col: usize,
    /// Offset in the reduced system.
    off: usize,
    /// Tangent dimension.
    dim: usize,
    /// Residuals touching it and another camera block: `(residual, local index)` (their
    /// camera–camera terms of S).
    res: Vec<(usize, usize)>,
    /// Residuals touching it and no eliminated block: `(residual, local index)` (their terms
    /// of H_bb and g_b; those of residuals with a point are summed in the point pass).
    res_diag: Vec<(usize, usize)>,
    /// Points coupled to it: `(point, pair index in that point)`.
    pts: Vec<(usize, usize)>,
    /// Offset of its accumulator (H_bb, d × d, then g_b, d) in each point chunk's slice of
    /// `SchurSystem::cam_acc`.
    acc_off: usize,
    /// Start of its Y blocks (camera-major copy, in `pts` order) in `SchurSystem::yc`.
    yc_off: usize,
    /// H_bb without the point terms' cross couplings: the diagonal block of JᵀJ (d × d).
    hbb: Vec<f64>,
    /// g_b = J_bᵀ r.
    g: Vec<f64>,
}

/// Storage and factorisation of S.
enum Reduced {
    /// Dense n_c × n_c column-major (lower triangle used).
    Dense { mem: MemBuffer },
    /// Sparse lower CSC with the block pattern of S; `col_slots[b]` lists `(a, slot)` of the
    /// column block b, ascending in a.
    Sparse {
        pattern: Box<Pattern>,
        chol: Box<Cholesky>,
        col_slots: Vec<Vec<(usize, usize)>>,
    },
}

/// The reduced camera system of one solve (structure fixed, values refilled).
pub(crate) struct SchurSystem {
    points: Vec<PointBlock>,
    cams: Vec<CamBlock>,
    /// Per residual: range in `res_cam` of its free camera blocks.
    res_cam_ptr: Vec<usize>,
    /// `(local index, camera index)` of each residual's free camera blocks.
    res_cam: Vec<(usize, usize)>,
    /// Number of camera unknowns.
    nc: usize,
    /// g_c (full-ordering gradient restricted to cameras, reduced ordering).
    gc: Vec<f64>,
    /// S values (dense n_c² or sparse nnz).
    s: Vec<f64>,
    /// Start of each camera column block in `s`, plus the end.
    s_bounds: Vec<usize>,
    /// Right-hand side / solution of the reduced system.
    rhs: Vec<f64>,
    /// Y_ap = H_ap L_p⁻ᵀ of every point–camera pair, point-major (point p at `y_off`).
    y: Vec<f64>,
    /// Start of each point's Y blocks in `y`, plus the end.
    y_bounds: Vec<usize>,
    /// The same blocks camera-major (camera a's blocks contiguous, in point order), so that
    /// forming S streams through memory.
    yc: Vec<f64>,
    /// Start of each camera's blocks in `yc`, plus the end.
    yc_bounds: Vec<usize>,
    /// Per column block b: `(a, start, end)` for every a ≥ b coupled to b through points, the
    /// range of `shared` listing those points.
    col_targets: Vec<Vec<(usize, usize, usize)>>,
    /// `(offset of Y_ap, offset of Y_bp)` in `yc` for the points shared by a camera pair
    /// (a, b), grouped per pair as listed in `col_targets`, in point order.
    shared: Vec<(usize, usize)>,
    /// Per point chunk of the assembly: the camera accumulators (H_bb, g_b of every camera,
    /// `acc_len` values), summed over the chunks in order (deterministic for any thread count).
    cam_acc: Vec<f64>,
    /// Values per chunk in `cam_acc`.
    acc_len: usize,
    /// Points per chunk.
    chunk_points: usize,
    /// The common tangent dimension of the eliminated blocks, if they all have the same.
    point_dim: Option<usize>,
    reduced: Reduced,
    /// Accumulated time (s) eliminating points and forming S and its right-hand side, and
    /// back-substituting the points.
    pub time_reduce_s: f64,
    /// Accumulated time (s) factorising S and solving for the cameras.
    pub time_factor_s: f64,
}

/// Splits `s` into consecutive pieces starting at `bounds[i]` (bounds[0] = 0, last = len).
pub(crate) fn split_pieces<'a>(mut s: &'a mut [f64], bounds: &[usize]) -> Vec<&'a mut [f64]> {
    let mut out = Vec::with_capacity(bounds.len().saturating_sub(1));
    for w in bounds.windows(2) {
        let (head, tail) = s.split_at_mut(w[1] - w[0]);
        out.push(head);
        s = tail;
    }
    out
}

/// Where the block (a, b) of S lives inside the slice of column block b: entry (i, j) is at
/// `pos(j) + i` (on a sparse diagonal block only i ≥ j is stored).
#[derive(Clone, Copy)]
enum Loc<'a> {
    /// Dense column-major n_c × n_c: `pos(j) = j·n_c + off_a`.
    Dense { nc: usize, oa: usize },
    /// Sparse CSC: `pos(j) = slot_base[j] − base − shift·j`.
    Sparse {
        sb: &'a [usize],
        base: usize,
        diag: bool,
    },
}

impl Loc<'_> {
    #[inline(always)]
    fn pos(&self, j: usize) -> usize {
        match *self {
            Loc::Dense { nc, oa } => j * nc + oa,
            Loc::Sparse { sb, base, diag } => sb[j] - base - if diag { j } else { 0 },
        }
    }

    /// Whether only i ≥ j may be written for a diagonal block.
    fn lower_only(&self) -> bool {
        matches!(self, Loc::Sparse { diag: true, .. })
    }
}

/// `dst[pos(j) + i] −= Σ_k ya[i, k] yb[j, k]` for the block (a, b) of S (`ya`: da × dp,
/// `yb`: db × dp, column-major); on a diagonal block only i ≥ j.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sub_yyt(
    dst: &mut [f64],
    loc: Loc<'_>,
    diag: bool,
    ya: &[f64],
    da: usize,
    yb: &[f64],
    db: usize,
    dp: usize,
) {
    let diag = diag && loc.lower_only();
    if da == 6
        && db == 6
        && dp == 3
        && !diag
        && let (Some(a), Some(bm)) = (ya.first_chunk::<18>(), yb.first_chunk::<18>())
    {
        // The SE(3) camera / 3-D point case on fixed-size arrays (unrolled, vectorised
        // along i, no bounds checks in the inner loop).
        for j in 0..6 {
            let p = loc.pos(j);
            if let Some((c, _)) = dst
                .get_mut(p..)
                .and_then(|d| d.split_first_chunk_mut::<6>())
            {
                let (b0, b1, b2) = (bm[j], bm[6 + j], bm[12 + j]);
                for i in 0..6 {
                    c[i] -= a[i] * b0 + a[6 + i] * b1 + a[12 + i] * b2;
                }
            }
        }
        return;
    }
    for j in 0..db {
        let p = loc.pos(j);
        let i0 = if diag { j } else { 0 };
        for i in i0..da {
            let mut acc = 0.0;
            for k in 0..dp {
                acc += ya[k * da + i] * yb[k * db + j];
            }
            dst[p + i] -= acc;
        }
    }
}

/// `dst[pos(j) + i] += Σ_r ja[r, i] jb[r, j]` (J_aᵀ J_b, `ja`: m × da, `jb`: m × db).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_jtj(
    dst: &mut [f64],
    loc: Loc<'_>,
    diag: bool,
    ja: &[f64],
    da: usize,
    jb: &[f64],
    db: usize,
    m: usize,
) {
    let diag = diag && loc.lower_only();
    for j in 0..db {
        let p = loc.pos(j);
        let cb = &jb[j * m..(j + 1) * m];
        let i0 = if diag { j } else { 0 };
        for i in i0..da {
            let ca = &ja[i * m..(i + 1) * m];
            dst[p + i] += ca.iter().zip(cb).map(|(x, y)| x * y).sum::<f64>();
        }
    }
}

/// The common bundle-adjustment case on fixed-size arrays: a 2-D residual (a pixel), a 3-D
/// point and 6-D (SE(3)) camera blocks. Accumulates exactly the terms of the generic loop in
/// [`SchurSystem::assemble`] (H_pp, g_p and H_ap) without slice bounds checks. Returns `false`, having changed nothing, when a block
/// does not have those sizes (the caller then runs the generic loop).
#[inline(always)]
fn accumulate_pixel_residual(
    pb: &mut PointBlock,
    o: usize,
    buf: EvalBuf<'_>,
    kp: usize,
    cams: &[CamBlock],
    acc: &mut [f64],
) -> bool {
    let (Some(r), Some(jp)) = (buf.r.first_chunk::<2>(), buf.jac(kp).first_chunk::<6>()) else {
        return false;
    };
    let pairs = &pb.res_cams[pb.res_cam_ptr[o]..pb.res_cam_ptr[o + 1]];
    if pairs
        .iter()
        .any(|&(k, pair)| cams[pb.cams[pair]].dim != 6 || buf.jac(k).len() != 12)
    {
        return false;
    }
    // Column c of a 2 × n column-major Jacobian is (x[2c], x[2c + 1]).
    for j in 0..3 {
        pb.gp[j] += jp[2 * j] * r[0] + jp[2 * j + 1] * r[1];
        for i in j..3 {
            pb.hpp[j * 3 + i] += jp[2 * i] * jp[2 * j] + jp[2 * i + 1] * jp[2 * j + 1];
        }
    }
    for &(k, pair) in pairs {
        let Some(ja) = buf.jac(k).first_chunk::<12>() else {
            continue;
        };
        let off = pb.pair_off[pair];
        if let Some(h) = pb
            .hcp
            .get_mut(off..)
            .and_then(|x| x.first_chunk_mut::<18>())
        {
            for j in 0..3 {
                for i in 0..6 {
                    h[j * 6 + i] += ja[2 * i] * jp[2 * j] + ja[2 * i + 1] * jp[2 * j + 1];
                }
            }
        }
        // The camera's J_aᵀJ_a (lower triangle) and J_aᵀr.
        if let Some(a) = acc
            .get_mut(cams[pb.cams[pair]].acc_off..)
            .and_then(|x| x.first_chunk_mut::<42>())
        {
            for j in 0..6 {
                a[36 + j] += ja[2 * j] * r[0] + ja[2 * j + 1] * r[1];
                for i in j..6 {
                    a[j * 6 + i] += ja[2 * i] * ja[2 * j] + ja[2 * i + 1] * ja[2 * j + 1];
                }
            }
        }
    }
    true
}

/// One point's terms of the normal equations from its residuals (in residual order): H_pp,
/// g_p and H_ap into the point block, and each camera's J_aᵀJ_a (lower triangle, d_a × d_a)
/// and J_aᵀr into its slot of the chunk accumulator `acc`.
#[inline(always)]
fn accumulate_point(pb: &mut PointBlock, bufs: &Evals, cams: &[CamBlock], acc: &mut [f64]) {
    let d = pb.dim;
    pb.hpp.fill(0.0);
    pb.gp.fill(0.0);
    pb.hcp.fill(0.0);
    for o in 0..pb.res.len() {
        let (ri, kp) = pb.res[o];
        let buf = bufs.get(ri);
        let m = buf.r.len();
        let jp = buf.jac(kp);
        if m == 2 && d == 3 && accumulate_pixel_residual(pb, o, buf, kp, cams, acc) {
            continue;
        }
        for j in 0..d {
            let cj = &jp[j * m..(j + 1) * m];
            pb.gp[j] += dot(cj, buf.r);
            for i in j..d {
                pb.hpp[j * d + i] += dot(&jp[i * m..(i + 1) * m], cj);
            }
        }
        for &(k, pair) in &pb.res_cams[pb.res_cam_ptr[o]..pb.res_cam_ptr[o + 1]] {
            let ja = buf.jac(k);
            let cb = &cams[pb.cams[pair]];
            let da = cb.dim;
            let h = &mut pb.hcp[pb.pair_off[pair]..pb.pair_off[pair] + da * d];
            for j in 0..d {
                let cj = &jp[j * m..(j + 1) * m];
                for i in 0..da {
                    h[j * da + i] += dot(&ja[i * m..(i + 1) * m], cj);
                }
            }
            let a = &mut acc[cb.acc_off..cb.acc_off + da * (da + 1)];
            for j in 0..da {
                let cj = &ja[j * m..(j + 1) * m];
                a[da * da + j] += dot(cj, buf.r);
                for i in j..da {
                    a[j * da + i] += dot(&ja[i * m..(i + 1) * m], cj);
                }
            }
        }
    }
    for j in 0..d {
        for i in 0..j {
            pb.hpp[j * d + i] = pb.hpp[i * d + j];
        }
    }
}

/// What the accumulation of one column block of S reads.
struct ColumnCtx<'a> {
    cams: &'a [CamBlock],
    points: &'a [PointBlock],
    res_cam_ptr: &'a [usize],
    res_cam: &'a [(usize, usize)],
    reduced: &'a Reduced,
    nc: usize,
    bufs: &'a Evals,
    mu: f64,
    damp: &'a [f64],
    /// The point-major Y slab (see `SchurSystem::y`).
    y: &'a [f64],
    /// The camera-major Y slab (see `SchurSystem::yc`).
    yc: &'a [f64],
    /// `SchurSystem::col_targets`.
    col_targets: &'a [Vec<(usize, usize, usize)>],
    /// `SchurSystem::shared`.
    shared: &'a [(usize, usize)],
    /// The common tangent dimension of the eliminated blocks (None when they differ: S is
    /// then accumulated point by point).
    point_dim: Option<usize>,
}

/// The accumulation of column block `b` of S into its slice `sl`:
/// S_ab = Σ_r J_aᵀ J_b (+ μD_b on the diagonal) − Σ_p Y_ap Y_bpᵀ for every a ≥ b.
struct ColumnTask<'a, 's> {
    ctx: &'a ColumnCtx<'a>,
    sl: &'s mut [f64],
    b: usize,
    cb: &'a CamBlock,
}

/// Σ_p Y_ap Y_bpᵀ (6 × 6, column-major, into `out`) over the shared points `list` of a camera
/// pair for SE(3) cameras and 3-D points (Y blocks 6 × 3 column-major at the listed offsets of
/// `y`): AVX2/FMA with the 6 × 6 sum held in registers (rows 0–3 and 4–5 of each column).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sum_yyt_6x3_v3(simd: pulp::x86::V3, y: &[f64], list: &[(usize, usize)], out: &mut [f64; 36]) {
    let zero = simd.splat_f64x4(0.0);
    let mut lo = [zero; 6];
    let mut hi = [zero; 6];
    for &(oa, ob) in list {
        let (Some(a), Some(b)) = (
            y.get(oa..).and_then(|v| v.first_chunk::<18>()),
            y.get(ob..).and_then(|v| v.first_chunk::<18>()),
        ) else {
            continue;
        };
        for k in 0..3 {
            let c = 6 * k;
            let al = pulp::f64x4(a[c], a[c + 1], a[c + 2], a[c + 3]);
            let ah = pulp::f64x4(a[c + 4], a[c + 5], 0.0, 0.0);
            for j in 0..6 {
                let bj = simd.splat_f64x4(b[c + j]);
                lo[j] = simd.mul_add_f64x4(al, bj, lo[j]);
                hi[j] = simd.mul_add_f64x4(ah, bj, hi[j]);
            }
        }
    }
    for j in 0..6 {
        let (l, h) = (lo[j], hi[j]);
        out[6 * j..6 * j + 6].copy_from_slice(&[l.0, l.1, l.2, l.3, h.0, h.1]);
    }
}

/// Σ_p Y_ap Y_bpᵀ (da × db, column-major, into `out`) over the shared points `list`
/// (Y_ap: da × dp, Y_bp: db × dp column-major at the listed offsets of `y`).
#[inline(always)]
fn sum_yyt(y: &[f64], list: &[(usize, usize)], da: usize, db: usize, dp: usize, out: &mut [f64]) {
    out.fill(0.0);
    for &(oa, ob) in list {
        let (ya, yb) = (&y[oa..oa + da * dp], &y[ob..ob + db * dp]);
        for k in 0..dp {
            let (ca, cb) = (&ya[k * da..(k + 1) * da], &yb[k * db..(k + 1) * db]);
            for (j, &bj) in cb.iter().enumerate() {
                for (o, &ai) in out[j * da..(j + 1) * da].iter_mut().zip(ca) {
                    *o += ai * bj;
                }
            }
        }
    }
}

impl ColumnTask<'_, '_> {
    /// Fills the column block; `kernel6` computes the 6 × 6 × 3 pair sums (SE(3) cameras,
    /// 3-D points) when it is given.
    #[inline(always)]
    fn run<K: Fn(&[f64], &[(usize, usize)], &mut [f64; 36])>(self, kernel6: Option<K>) {
        let ColumnTask { ctx, sl, b, cb } = self;
        let (cams, points, nc) = (ctx.cams, ctx.points, ctx.nc);
        sl.fill(0.0);
        let base = match ctx.reduced {
            Reduced::Dense { .. } => cb.off * nc,
            Reduced::Sparse { pattern, .. } => pattern.col_ptr[cb.off],
        };
        let locate = |a: usize| -> Loc<'_> {
            match ctx.reduced {
                Reduced::Dense { .. } => Loc::Dense {
                    nc,
                    oa: cams[a].off,
                },
                Reduced::Sparse {
                    pattern, col_slots, ..
                } => {
                    let slots = &col_slots[b];
                    let s = slots
                        .binary_search_by_key(&a, |x| x.0)
                        .map(|i| slots[i].1)
                        .unwrap_or(0);
                    Loc::Sparse {
                        sb: &pattern.slot_base[s],
                        base,
                        diag: a == b,
                    }
                }
            }
        };
        let db = cb.dim;
        // Diagonal block: H_bb (lower triangle) + μD_b.
        let loc = locate(b);
        for j in 0..db {
            let p = loc.pos(j);
            for i in j..db {
                sl[p + i] = cb.hbb[j * db + i];
            }
            sl[p + j] += ctx.mu * ctx.damp[cb.col + j];
        }
        // Camera–camera couplings of residuals touching several cameras.
        for &(ri, kb) in &cb.res {
            let buf = ctx.bufs.get(ri);
            let m = buf.r.len();
            let jb = buf.jac(kb);
            for &(ka, a) in &ctx.res_cam[ctx.res_cam_ptr[ri]..ctx.res_cam_ptr[ri + 1]] {
                if a <= b {
                    continue;
                }
                add_jtj(sl, locate(a), a == b, buf.jac(ka), cams[a].dim, jb, db, m);
            }
        }
        // The point terms −Σ_p Y_ap Y_bpᵀ.
        let Some(dp) = ctx.point_dim else {
            for &(pi, ib) in &cb.pts {
                let pb = &points[pi];
                let dp = pb.dim;
                let ob = pb.y_off + pb.pair_off[ib];
                let yb = &ctx.y[ob..ob + db * dp];
                for ia in ib..pb.cams.len() {
                    let a = pb.cams[ia];
                    let da = cams[a].dim;
                    let oa = pb.y_off + pb.pair_off[ia];
                    let ya = &ctx.y[oa..oa + da * dp];
                    sub_yyt(sl, locate(a), a == b, ya, da, yb, db, dp);
                }
            }
            return;
        };
        let mut acc6 = [0.0; 36];
        let mut acc = Vec::new();
        for &(a, start, end) in &ctx.col_targets[b] {
            let list = &ctx.shared[start..end];
            let da = cams[a].dim;
            let sum: &[f64] = match &kernel6 {
                Some(k) if da == 6 && db == 6 && dp == 3 => {
                    k(ctx.yc, list, &mut acc6);
                    &acc6
                }
                _ => {
                    acc.resize(da * db, 0.0);
                    sum_yyt(ctx.yc, list, da, db, dp, &mut acc);
                    &acc
                }
            };
            let loc = locate(a);
            let lower = a == b && loc.lower_only();
            for j in 0..db {
                let p = loc.pos(j);
                let i0 = if lower { j } else { 0 };
                for i in i0..da {
                    sl[p + i] -= sum[j * da + i];
                }
            }
        }
    }
}

/// `ColumnTask::run` with the AVX2/FMA pair kernel (compiled with those features).
#[cfg(target_arch = "x86_64")]
struct ColumnTaskV3<'a, 's>(pulp::x86::V3, ColumnTask<'a, 's>);

#[cfg(target_arch = "x86_64")]
impl pulp::NullaryFnOnce for ColumnTaskV3<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn call(self) {
        let simd = self.0;
        self.1.run(Some(
            #[inline(always)]
            |y: &[f64], list: &[(usize, usize)], out: &mut [f64; 36]| {
                sum_yyt_6x3_v3(simd, y, list, out)
            },
        ));
    }
}

impl ColumnTask<'_, '_> {
    /// Runs the task with the fastest kernel the CPU supports.
    fn dispatch(self) {
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = pulp::x86::V3::try_new() {
            simd.vectorize(ColumnTaskV3(simd, self));
            return;
        }
        self.run(None::<fn(&[f64], &[(usize, usize)], &mut [f64; 36])>);
    }
}

/// For every column block b of S, the camera blocks a ≥ b coupled to it through points and,
/// per such pair, the offsets of (Y_ap, Y_bp) in the camera-major Y slab for every shared point p (point
/// order, so the sums are deterministic): S_ab −= Σ_p Y_ap Y_bpᵀ is then one register-resident
/// accumulation per pair. Built by counting sort per column: O(Σ_p n_p²).
#[allow(clippy::type_complexity)]
fn shared_points(
    cams: &[CamBlock],
    points: &[PointBlock],
) -> (Vec<Vec<(usize, usize, usize)>>, Vec<(usize, usize)>) {
    let nc = cams.len();
    let mut count = vec![0usize; nc];
    let mut cursor = vec![0usize; nc];
    let mut touched = Vec::new();
    let mut targets = Vec::with_capacity(nc);
    let total: usize = points
        .iter()
        .map(|pb| pb.cams.len() * (pb.cams.len() + 1) / 2)
        .sum();
    let mut shared = Vec::with_capacity(total);
    for cb in cams {
        for &(pi, ib) in &cb.pts {
            for &a in &points[pi].cams[ib..] {
                if count[a] == 0 {
                    touched.push(a);
                }
                count[a] += 1;
            }
        }
        touched.sort_unstable();
        let mut t = Vec::with_capacity(touched.len());
        let mut pos = shared.len();
        for &a in &touched {
            t.push((a, pos, pos + count[a]));
            cursor[a] = pos;
            pos += count[a];
        }
        shared.resize(pos, (0, 0));
        for &(pi, ib) in &cb.pts {
            let pb = &points[pi];
            let ob = pb.yc_pair[ib];
            for (ia, &a) in pb.cams.iter().enumerate().skip(ib) {
                shared[cursor[a]] = (pb.yc_pair[ia], ob);
                cursor[a] += 1;
            }
        }
        for &a in &touched {
            count[a] = 0;
        }
        touched.clear();
        targets.push(t);
    }
    (targets, shared)
}

impl SchurSystem {
    /// Whether the layout admits the explicit reduced system: some blocks eliminated, and no
    /// residual touching two eliminated blocks.
    pub fn applicable(p: &Problem, layout: &Layout) -> bool {
        if !layout.eliminated.iter().any(|e| *e) || layout.eliminated.iter().all(|e| *e) {
            return false;
        }
        p.residuals.iter().all(|r| {
            r.blocks
                .iter()
                .filter(|b| layout.free_index[b.0].is_some_and(|f| layout.eliminated[f]))
                .count()
                <= 1
        })
    }

    /// Builds the structure (camera/point classification, pairs, S pattern, buffers).
    pub fn new(p: &Problem, layout: &Layout, dense_limit: usize) -> Result<Self> {
        let nf = layout.free_blocks.len();
        let mut cam_of = vec![usize::MAX; nf];
        let mut pt_of = vec![usize::MAX; nf];
        let mut cams = Vec::new();
        let mut points = Vec::new();
        let mut nc = 0;
        for f in 0..nf {
            let dim = layout.dims[f];
            let col = layout.col_offset[f];
            if layout.eliminated[f] {
                pt_of[f] = points.len();
                points.push(PointBlock {
                    col,
                    dim,
                    res: Vec::new(),
                    res_cam_ptr: vec![0],
                    res_cams: Vec::new(),
                    cams: Vec::new(),
                    pair_off: Vec::new(),
                    hpp: vec![0.0; dim * dim],
                    gp: vec![0.0; dim],
                    hcp: Vec::new(),
                    l: vec![0.0; dim * dim],
                    y_off: 0,
                    yc_pair: Vec::new(),
                    z: vec![0.0; dim],
                    dx: vec![0.0; dim],
                    linv: vec![0.0; dim * dim],
                });
            } else {
                cam_of[f] = cams.len();
                cams.push(CamBlock {
                    col,
                    off: nc,
                    dim,
                    res: Vec::new(),
                    res_diag: Vec::new(),
                    pts: Vec::new(),
                    acc_off: 0,
                    yc_off: 0,
                    hbb: vec![0.0; dim * dim],
                    g: vec![0.0; dim],
                });
                nc += dim;
            }
        }
        let mut res_cam_ptr = Vec::with_capacity(p.residuals.len() + 1);
        let mut res_cam = Vec::new();
        res_cam_ptr.push(0);
        let mut res_point = Vec::with_capacity(p.residuals.len());
        for (ri, r) in p.residuals.iter().enumerate() {
            let mut point = None;
            for (k, b) in r.blocks.iter().enumerate() {
                let Some(f) = layout.free_index[b.0] else {
                    continue;
                };
                if pt_of[f] != usize::MAX {
                    point = Some((pt_of[f], k));
                } else {
                    res_cam.push((k, cam_of[f]));
                }
            }
            let rc = &res_cam[res_cam_ptr[ri]..];
            for &(k, c) in rc {
                if rc.len() > 1 {
                    cams[c].res.push((ri, k));
                }
                if point.is_none() {
                    cams[c].res_diag.push((ri, k));
                }
            }
            res_cam_ptr.push(res_cam.len());
            res_point.push(point);
        }
        // Pairs per point.
        for (ri, rp) in res_point.iter().enumerate() {
            if let Some((pt, k)) = *rp {
                let pb = &mut points[pt];
                pb.res.push((ri, k));
                for &(_, c) in &res_cam[res_cam_ptr[ri]..res_cam_ptr[ri + 1]] {
                    pb.cams.push(c);
                }
            }
        }
        let mut y_len = 0;
        for (pi, pb) in points.iter_mut().enumerate() {
            pb.cams.sort_unstable();
            pb.cams.dedup();
            let mut off = 0;
            for &c in &pb.cams {
                pb.pair_off.push(off);
                off += cams[c].dim * pb.dim;
            }
            pb.hcp = vec![0.0; off];
            pb.y_off = y_len;
            y_len += off;
            for &(ri, _) in &pb.res {
                for &(k, c) in &res_cam[res_cam_ptr[ri]..res_cam_ptr[ri + 1]] {
                    // `cams` is sorted and contains c.
                    let pair = pb.cams.binary_search(&c).unwrap_or(0);
                    pb.res_cams.push((k, pair));
                }
                pb.res_cam_ptr.push(pb.res_cams.len());
            }
            for (i, &c) in pb.cams.iter().enumerate() {
                cams[c].pts.push((pi, i));
            }
        }
        let y_bounds: Vec<usize> = points
            .iter()
            .map(|pb| pb.y_off)
            .chain(std::iter::once(y_len))
            .collect();
        // Camera-major copy of Y and the per-chunk camera accumulators.
        for pb in points.iter_mut() {
            pb.yc_pair = vec![0; pb.cams.len()];
        }
        let (mut yc_len, mut acc_len) = (0, 0);
        for cb in cams.iter_mut() {
            cb.yc_off = yc_len;
            cb.acc_off = acc_len;
            acc_len += cb.dim * (cb.dim + 1);
            for &(pi, ia) in &cb.pts {
                points[pi].yc_pair[ia] = yc_len;
                yc_len += cb.dim * points[pi].dim;
            }
        }
        let yc_bounds: Vec<usize> = cams
            .iter()
            .map(|cb| cb.yc_off)
            .chain(std::iter::once(yc_len))
            .collect();
        // At most 16 chunks (enough to balance the threads), fewer when the accumulators
        // would pass 4 M values.
        let n_chunks = 16
            .min(points.len().max(1))
            .min(((1 << 22) / acc_len.max(1)).max(1));
        let chunk_points = points.len().div_ceil(n_chunks).max(1);
        let n_chunks = points.len().div_ceil(chunk_points).max(1);
        let point_dim = points
            .first()
            .map(|p| p.dim)
            .filter(|&d| points.iter().all(|p| p.dim == d));
        let (col_targets, shared) = if point_dim.is_some() {
            shared_points(&cams, &points)
        } else {
            (Vec::new(), Vec::new())
        };
        let reduced = if nc <= dense_limit {
            let req = faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(
                nc,
                Par::Seq,
                Default::default(),
            );
            let mem = MemBuffer::try_new(req)
                .map_err(|e| EstimateError::LinearSolver(format!("workspace allocation: {e:?}")))?;
            Reduced::Dense { mem }
        } else {
            let dims: Vec<usize> = cams.iter().map(|c| c.dim).collect();
            let mut pairs = Vec::new();
            for w in res_cam_ptr.windows(2) {
                let rc = &res_cam[w[0]..w[1]];
                for (i, &(_, a)) in rc.iter().enumerate() {
                    for &(_, b) in &rc[..i] {
                        pairs.push((a, b));
                    }
                }
            }
            for pb in &points {
                for (i, &a) in pb.cams.iter().enumerate() {
                    for &b in &pb.cams[..i] {
                        pairs.push((a, b));
                    }
                }
            }
            let pattern = Pattern::new(&dims, pairs);
            let chol = Cholesky::new(&pattern, false, None)?;
            let mut col_slots = vec![Vec::new(); cams.len()];
            for (&(a, b), &slot) in &pattern.slots {
                col_slots[b].push((a, slot));
            }
            col_slots.iter_mut().for_each(|v| v.sort_unstable());
            Reduced::Sparse {
                pattern: Box::new(pattern),
                chol: Box::new(chol),
                col_slots,
            }
        };
        let s_bounds: Vec<usize> = match &reduced {
            Reduced::Dense { .. } => cams
                .iter()
                .map(|c| c.off * nc)
                .chain(std::iter::once(nc * nc))
                .collect(),
            Reduced::Sparse { pattern, .. } => cams
                .iter()
                .map(|c| pattern.col_ptr[c.off])
                .chain(std::iter::once(pattern.nnz()))
                .collect(),
        };
        let s_len = s_bounds.last().copied().unwrap_or(0);
        Ok(Self {
            points,
            cams,
            res_cam_ptr,
            res_cam,
            nc,
            gc: vec![0.0; nc],
            s: vec![0.0; s_len],
            s_bounds,
            rhs: vec![0.0; nc],
            y: vec![0.0; y_len],
            y_bounds,
            yc: vec![0.0; yc_len],
            yc_bounds,
            col_targets,
            shared,
            cam_acc: vec![0.0; n_chunks * acc_len],
            acc_len,
            chunk_points,
            point_dim,
            reduced,
            time_reduce_s: 0.0,
            time_factor_s: 0.0,
        })
    }

    /// Whether S is dense.
    #[cfg(test)]
    pub fn is_dense(&self) -> bool {
        matches!(self.reduced, Reduced::Dense { .. })
    }

    /// From evaluated (loss-weighted) residuals and Jacobians: H_pp, g_p and H_ap per point,
    /// g_c per camera, and the full-ordering gradient `g` and diagonal of JᵀJ `hdiag`.
    pub fn assemble(&mut self, bufs: &Evals, g: &mut [f64], hdiag: &mut [f64]) {
        let cams = &self.cams;
        // Per point, in residual order: H_pp, g_p, H_ap; and the camera terms J_aᵀJ_a, J_aᵀr
        // of those residuals into the accumulators of the point's chunk.
        let acc_len = self.acc_len.max(1);
        self.cam_acc.fill(0.0);
        self.points
            .par_chunks_mut(self.chunk_points)
            .zip(self.cam_acc.par_chunks_mut(acc_len))
            .for_each(|(chunk, acc)| {
                for pb in chunk {
                    accumulate_point(pb, bufs, cams, acc);
                }
            });
        // Per camera: H_bb (lower triangle) and g_b: the chunk sums, then the residuals
        // without a point.
        let (cam_acc, n_chunks) = (&self.cam_acc, self.cam_acc.len() / acc_len);
        self.cams.par_iter_mut().for_each(|cb| {
            let d = cb.dim;
            cb.hbb.fill(0.0);
            cb.g.fill(0.0);
            for ch in 0..n_chunks {
                let a =
                    &cam_acc[ch * acc_len + cb.acc_off..ch * acc_len + cb.acc_off + d * (d + 1)];
                for (x, y) in cb.hbb.iter_mut().zip(&a[..d * d]) {
                    *x += y;
                }
                for (x, y) in cb.g.iter_mut().zip(&a[d * d..]) {
                    *x += y;
                }
            }
            for &(ri, k) in &cb.res_diag {
                let buf = bufs.get(ri);
                let m = buf.r.len();
                let jb = buf.jac(k);
                for j in 0..d {
                    let cj = &jb[j * m..(j + 1) * m];
                    cb.g[j] += dot(cj, buf.r);
                    for i in j..d {
                        cb.hbb[j * d + i] += dot(&jb[i * m..(i + 1) * m], cj);
                    }
                }
            }
        });
        for pb in &self.points {
            for j in 0..pb.dim {
                g[pb.col + j] = pb.gp[j];
                hdiag[pb.col + j] = pb.hpp[j * pb.dim + j];
            }
        }
        for cb in &self.cams {
            for j in 0..cb.dim {
                g[cb.col + j] = cb.g[j];
                hdiag[cb.col + j] = cb.hbb[j * cb.dim + j];
                self.gc[cb.off + j] = cb.g[j];
            }
        }
    }

    /// Solves the damped normal equations (H + μ·diag(`damp`)) δ = −g (full ordering; `damp`
    /// is all zeros for Gauss–Newton) by elimination of the points, Cholesky of S and
    /// back-substitution. `Ok(Err(col))` when a pivot is not positive (`col`: the offending
    /// column of the full ordering, when known).
    pub fn solve(
        &mut self,
        bufs: &Evals,
        mu: f64,
        damp: &[f64],
        delta: &mut [f64],
    ) -> Result<std::result::Result<(), Option<usize>>> {
        // 1. Per point: L L ᵀ = H_pp + μD_p, z = L⁻¹ g_p, Y_a = H_ap L⁻ᵀ.
        let t0 = std::time::Instant::now();
        let cams = &self.cams;
        let y_pieces = split_pieces(&mut self.y, &self.y_bounds);
        let failed = self
            .points
            .par_iter_mut()
            .zip(y_pieces)
            .map(|(pb, y)| {
                let d = pb.dim;
                pb.l.copy_from_slice(&pb.hpp);
                for j in 0..d {
                    pb.l[j * d + j] += mu * damp[pb.col + j];
                }
                if let Err(k) = small_cholesky(&mut pb.l, d) {
                    return Some(pb.col + k);
                }
                pb.z.copy_from_slice(&pb.gp);
                forward(&pb.l, d, &mut pb.z);
                // L⁻¹ (lower, column-major), one triangular solve per column.
                pb.linv.fill(0.0);
                for (j, col) in pb.linv.chunks_exact_mut(d).enumerate() {
                    col[j] = 1.0;
                    forward(&pb.l, d, col);
                }
                // Y_a = H_ap L⁻ᵀ: column k of Y_a is Σ_{t ≤ k} (L⁻¹)_kt · column t of H_ap.
                for (pair, &c) in pb.cams.iter().enumerate() {
                    let da = cams[c].dim;
                    let off = pb.pair_off[pair];
                    let h = &pb.hcp[off..off + da * d];
                    let ya = &mut y[off..off + da * d];
                    for (k, yk) in ya.chunks_exact_mut(da).enumerate() {
                        yk.fill(0.0);
                        for (t, ht) in h.chunks_exact(da).enumerate().take(k + 1) {
                            let s = pb.linv[t * d + k];
                            for (o, &v) in yk.iter_mut().zip(ht) {
                                *o += s * v;
                            }
                        }
                    }
                }
                None
            })
            .reduce(|| None, |a, b| a.or(b));
        if let Some(col) = failed {
            self.time_reduce_s += t0.elapsed().as_secs_f64();
            return Ok(Err(Some(col)));
        }
        // 2. Per camera: the camera-major copy of its Y blocks (point order) and its entry of
        // the reduced right-hand side −g_c + Σ_p Y_ap z_p.
        let points = &self.points;
        let y = &self.y;
        let gc = &self.gc;
        let mut rhs_pieces: Vec<&mut [f64]> = Vec::with_capacity(cams.len());
        let mut rest = self.rhs.as_mut_slice();
        for cb in cams {
            let (head, tail) = rest.split_at_mut(cb.dim);
            rhs_pieces.push(head);
            rest = tail;
        }
        split_pieces(&mut self.yc, &self.yc_bounds)
            .into_par_iter()
            .zip(rhs_pieces)
            .zip(cams.par_iter())
            .for_each(|((yc, rhs), cb)| {
                let da = cb.dim;
                for (r, &g) in rhs.iter_mut().zip(&gc[cb.off..cb.off + da]) {
                    *r = -g;
                }
                let mut o = 0;
                for &(pi, ia) in &cb.pts {
                    let pb = &points[pi];
                    let src = pb.y_off + pb.pair_off[ia];
                    let ya = &y[src..src + da * pb.dim];
                    match (
                        yc.get_mut(o..).and_then(|v| v.first_chunk_mut::<18>()),
                        ya.first_chunk::<18>(),
                    ) {
                        (Some(d), Some(src)) if ya.len() == 18 => *d = *src,
                        _ => yc[o..o + ya.len()].copy_from_slice(ya),
                    }
                    o += ya.len();
                    for (col, &zk) in ya.chunks_exact(da).zip(&pb.z) {
                        for (r, &v) in rhs.iter_mut().zip(col) {
                            *r += v * zk;
                        }
                    }
                }
            });
        // 3. S column block by column block.
        let nc = self.nc;
        let (res_cam_ptr, res_cam) = (&self.res_cam_ptr, &self.res_cam);
        let reduced = &self.reduced;
        let ctx = ColumnCtx {
            cams,
            points,
            res_cam_ptr,
            res_cam,
            reduced,
            nc,
            bufs,
            mu,
            damp,
            y: &self.y,
            yc: &self.yc,
            col_targets: &self.col_targets,
            shared: &self.shared,
            point_dim: self.point_dim,
        };
        let pieces = split_pieces(&mut self.s, &self.s_bounds);
        pieces
            .into_par_iter()
            .zip(cams.par_iter().enumerate())
            .for_each(|(sl, (b, cb))| {
                ColumnTask {
                    ctx: &ctx,
                    sl,
                    b,
                    cb,
                }
                .dispatch()
            });
        // 4. Cholesky of S and the camera step.
        let t1 = std::time::Instant::now();
        self.time_reduce_s += (t1 - t0).as_secs_f64();
        let cam_col = |c: usize| -> Option<usize> {
            cams.iter()
                .rposition(|cb| cb.off <= c)
                .map(|i| cams[i].col + (c - cams[i].off))
        };
        match &mut self.reduced {
            Reduced::Dense { mem } => {
                let mut a = MatMut::from_column_major_slice_mut(&mut self.s, nc, nc);
                let res = cholesky_in_place(
                    a.as_mut(),
                    LltRegularization::default(),
                    Par::Seq,
                    MemStack::new(mem),
                    Default::default(),
                );
                if let Err(faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot {
                    index,
                }) = res
                {
                    self.time_factor_s += t1.elapsed().as_secs_f64();
                    return Ok(Err(cam_col(index)));
                }
                let l = MatRef::from_column_major_slice(&self.s, nc, nc);
                solve_in_place_with_conj(
                    l,
                    Conj::No,
                    MatMut::from_column_major_slice_mut(&mut self.rhs, nc, 1),
                    Par::Seq,
                    MemStack::new(mem),
                );
            }
            Reduced::Sparse { pattern, chol, .. } => {
                if let Err(c) = chol.factor(pattern, &self.s) {
                    self.time_factor_s += t1.elapsed().as_secs_f64();
                    return Ok(Err(c.and_then(cam_col)));
                }
                chol.solve_in_place(&mut self.rhs, nc, 1)?;
            }
        }
        // 5. Back-substitution δ_p = L⁻ᵀ (−z − Σ_a Y_aᵀ δ_a).
        let t2 = std::time::Instant::now();
        self.time_factor_s += (t2 - t1).as_secs_f64();
        let rhs = &self.rhs;
        let y = &self.y;
        self.points.par_iter_mut().for_each(|pb| {
            let d = pb.dim;
            for k in 0..d {
                pb.dx[k] = -pb.z[k];
            }
            for (pair, &c) in pb.cams.iter().enumerate() {
                let cb = &cams[c];
                let da = cb.dim;
                let o = pb.y_off + pb.pair_off[pair];
                let ya = &y[o..o + da * d];
                for k in 0..d {
                    let col = &ya[k * da..(k + 1) * da];
                    pb.dx[k] -= col
                        .iter()
                        .zip(&rhs[cb.off..cb.off + da])
                        .map(|(a, b)| a * b)
                        .sum::<f64>();
                }
            }
            backward(&pb.l, d, &mut pb.dx);
        });
        for cb in cams {
            delta[cb.col..cb.col + cb.dim].copy_from_slice(&rhs[cb.off..cb.off + cb.dim]);
        }
        for pb in &self.points {
            delta[pb.col..pb.col + pb.dim].copy_from_slice(&pb.dx);
        }
        self.time_reduce_s += t2.elapsed().as_secs_f64();
        Ok(Ok(()))
    }
}

#[cfg(test)]
mod tests;
