//! Jaccard IoU (eq. 8.4) of two spatial distributions.
//!
//! On `N` sample points (grid cells of equal area, so the cell area cancels) eq. 8.4 is the
//! probabilistic Jaccard index of Moulton & Jiang (ref. [249], eq. 3):
//!
//! ```text
//! J_P(p₁, p₂) = Σ_{i: p₁ᵢ>0, p₂ᵢ>0} 1 / Σ_j max(p₁ⱼ/p₁ᵢ, p₂ⱼ/p₂ᵢ).
//! ```
//!
//! With `t_j = p₁ⱼ/p₂ⱼ`, `max(p₁ⱼ/p₁ᵢ, p₂ⱼ/p₂ᵢ) = p₁ⱼ/p₁ᵢ` exactly when `t_j ≥ t_i`, so after
//! sorting by `t` the inner sum is a suffix sum of `p₁` over `p₁ᵢ` plus a prefix sum of `p₂`
//! over `p₂ᵢ`: `O(N log N)` in all. `J_P` is invariant to scaling either distribution, so
//! unnormalised `P_PDQ` values can be passed as they are.
//!
//! Deterministic boxes (zero covariance) skip the grid: [`jiou`] then returns the exact IoU.

use rayon::prelude::*;

use super::spatial::{
    Grid2, RasterScratch, Weighting, normal_table, rasterize_into, sample_boxes_into, trig_into,
};
use super::{BEV_PARAMS, Box2, Cov5, check_covariance, is_deterministic};
use crate::{GeometryError, Result};

/// The probabilistic Jaccard index of two non-negative vectors on the same sample points.
pub fn probabilistic_jaccard(p1: &[f64], p2: &[f64]) -> Result<f64> {
    if p1.len() != p2.len() {
        return Err(GeometryError::WrongLength {
            what: "p2",
            got: p2.len(),
            expected: p1.len(),
        });
    }
    for (what, p) in [("p1", p1), ("p2", p2)] {
        if let Some(&v) = p.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(GeometryError::InvalidParameter {
                what,
                value: v,
                reason: "spatial distributions must be finite and non-negative",
            });
        }
        if !p.iter().any(|v| *v > 0.0) {
            return Err(GeometryError::InvalidParameter {
                what,
                value: 0.0,
                reason: "spatial distribution has no mass",
            });
        }
    }
    let mut buf = Vec::new();
    Ok(jaccard_unchecked(p1, p2, &mut buf, &mut Vec::new()))
}

/// Sort keys of [`jaccard_unchecked`]: with at most `2^PACKED_INDEX_BITS` sample points the cell index is packed
/// into the low bits of the ratio's bit pattern (see there); above it, `(ratio, p₁, p₂)` tuples
/// are sorted.
const PACKED_INDEX_BITS: u32 = 24;

/// [`probabilistic_jaccard`] without validation; `buf` and `keys` are scratch space.
///
/// The intersection cells are sorted by `t = p₁/p₂`. With `N ≤ 2²⁴` points each key is the
/// ratio's bit pattern (positive finite values sort like their bits) with its low `k = ⌈log₂ N⌉`
/// bits replaced by the cell index: an 8-byte integer sort instead of 24-byte tuples. Two
/// ratios within a relative `2^(k−52)` of each other may then come out in either order; a
/// swapped pair replaces `max(p₁ⱼ/p₁ᵢ, p₂ⱼ/p₂ᵢ)` by the other ratio, which differs from it by that
/// same relative amount, so `J` moves by at most `2^(k−52)` relative (2.3·10⁻¹³ on 900 cells).
pub(super) fn jaccard_unchecked(
    p1: &[f64],
    p2: &[f64],
    buf: &mut Vec<(f64, f64, f64)>,
    keys: &mut Vec<u64>,
) -> f64 {
    let bits = usize::BITS - p1.len().saturating_sub(1).leading_zeros();
    if bits > PACKED_INDEX_BITS {
        return jaccard_tuples(p1, p2, buf);
    }
    let mask = (1u64 << bits) - 1;
    // Points only in R₂ (t = 0) come first, only in R₁ (t = ∞) last: only the intersection is
    // sorted.
    let (mut only2, mut only1, mut total1) = (0.0, 0.0, 0.0);
    keys.clear();
    for (i, (&a, &b)) in p1.iter().zip(p2).enumerate() {
        match (a > 0.0, b > 0.0) {
            (true, true) => {
                keys.push(((a / b).to_bits() & !mask) | i as u64);
                total1 += a;
            }
            (false, true) => only2 += b,
            (true, false) => only1 += a,
            (false, false) => {}
        }
    }
    if keys.is_empty() {
        return 0.0;
    }
    keys.sort_unstable();
    // suffix sum of p₁ over positions ≥ k (plus the t = ∞ part), prefix of p₂ over < k (plus t = 0).
    let total1 = total1 + only1;
    let mut prefix2 = only2;
    let mut consumed1 = 0.0;
    let mut j = 0.0;
    for &key in keys.iter() {
        let i = (key & mask) as usize;
        let (a, b) = (p1[i], p2[i]);
        let suffix1 = total1 - consumed1;
        j += 1.0 / (suffix1 / a + prefix2 / b);
        consumed1 += a;
        prefix2 += b;
    }
    j
}

/// [`jaccard_unchecked`] sorting `(ratio, p₁, p₂)` tuples (any number of points).
pub(super) fn jaccard_tuples(p1: &[f64], p2: &[f64], buf: &mut Vec<(f64, f64, f64)>) -> f64 {
    // Points only in R₂ (t = 0) come first, only in R₁ (t = ∞) last: only the intersection is
    // sorted.
    let (mut only2, mut only1) = (0.0, 0.0);
    buf.clear();
    for (&a, &b) in p1.iter().zip(p2) {
        match (a > 0.0, b > 0.0) {
            (true, true) => buf.push((a / b, a, b)),
            (false, true) => only2 += b,
            (true, false) => only1 += a,
            (false, false) => {}
        }
    }
    if buf.is_empty() {
        return 0.0;
    }
    // The ratios are positive and finite, so their bit patterns sort like the values.
    buf.sort_unstable_by_key(|x| x.0.to_bits());
    // suffix sum of p₁ over positions ≥ k (plus the t = ∞ part), prefix of p₂ over < k (plus t = 0).
    let total1: f64 = buf.iter().map(|e| e.1).sum::<f64>() + only1;
    let mut prefix2 = only2;
    let mut consumed1 = 0.0;
    let mut j = 0.0;
    for &(_, a, b) in buf.iter() {
        let suffix1 = total1 - consumed1;
        j += 1.0 / (suffix1 / a + prefix2 / b);
        consumed1 += a;
        prefix2 += b;
    }
    j
}

/// Options of the grid evaluation of JIoU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JiouOptions {
    /// Cells per axis of the grid spanning both boxes' samples (`30` → 900 cells).
    pub grid: usize,
    /// Monte Carlo boxes per probabilistic box (antithetic pairs).
    pub samples: usize,
    /// Seed of the normal table.
    pub seed: u64,
    /// `p_G` (eq. 8.3, the seed's choice) or `P_PDQ` (eq. 8.2, for comparison).
    pub weighting: Weighting,
}

impl Default for JiouOptions {
    fn default() -> Self {
        Self {
            grid: 30,
            samples: 64,
            seed: 0,
            weighting: Weighting::Density,
        }
    }
}

/// A Gaussian box `N(mean, cov)` over `[c₁, c₂, l, w, r_y]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbBox {
    /// Mean box ȳ.
    pub mean: Box2,
    /// Covariance (all zeros for a deterministic box).
    pub cov: Cov5,
}

impl ProbBox {
    /// A validated probabilistic box.
    pub fn new(mean: Box2, cov: Cov5) -> Result<Self> {
        check_covariance(&cov)?;
        Ok(Self { mean, cov })
    }
}

/// Reusable state of JIoU evaluations (the normal table and scratch).
struct Evaluator {
    table: Vec<[f64; BEV_PARAMS]>,
    opts: JiouOptions,
}

/// Per-thread buffers of [`Evaluator::pair`], reused across pairs.
#[derive(Default)]
struct PairScratch {
    sa: Vec<Box2>,
    sb: Vec<Box2>,
    ta: Vec<(f64, f64)>,
    tb: Vec<(f64, f64)>,
    ra: RasterScratch,
    rb: RasterScratch,
    buf: Vec<(f64, f64, f64)>,
    keys: Vec<u64>,
}

impl Evaluator {
    fn pair(&self, a: &ProbBox, b: &ProbBox, s: &mut PairScratch) -> Result<f64> {
        if is_deterministic(&a.cov) && is_deterministic(&b.cov) {
            return Ok(super::iou::iou(&a.mean, &b.mean));
        }
        sample_boxes_into(&a.mean, &a.cov, &self.table, &mut s.sa)?;
        sample_boxes_into(&b.mean, &b.cov, &self.table, &mut s.sb)?;
        trig_into(&s.sa, &mut s.ta);
        trig_into(&s.sb, &mut s.tb);
        let both = s.sa.iter().zip(&s.ta).chain(s.sb.iter().zip(&s.tb));
        let grid = Grid2::covering_trig(both, self.opts.grid)?;
        let wa = std::iter::repeat(1.0 / s.sa.len().max(1) as f64);
        let wb = std::iter::repeat(1.0 / s.sb.len().max(1) as f64);
        rasterize_into(&s.sa, &s.ta, wa, &grid, self.opts.weighting, &mut s.ra);
        rasterize_into(&s.sb, &s.tb, wb, &grid, self.opts.weighting, &mut s.rb);
        let (pa, pb) = (&s.ra.out, &s.rb.out);
        if !pa.iter().any(|v| *v > 0.0) || !pb.iter().any(|v| *v > 0.0) {
            return Err(GeometryError::InvalidParameter {
                what: "grid",
                value: self.opts.grid as f64,
                reason: "each box must cover at least one cell centre: use a finer grid",
            });
        }
        Ok(jaccard_unchecked(pa, pb, &mut s.buf, &mut s.keys))
    }
}

fn check_opts(opts: &JiouOptions) -> Result<()> {
    if opts.grid < 2 || opts.samples < 2 {
        return Err(GeometryError::InvalidParameter {
            what: "JIoU options (grid, samples)",
            value: opts.grid.min(opts.samples) as f64,
            reason: "need at least 2 cells per axis and 2 samples",
        });
    }
    // Both sizes come from the caller: the grid² rasters, the sampled boxes and the normal
    // table must fit in memory, or the allocation would abort the process.
    let cells = crate::alloc::checked_count("JIoU grid cells", opts.grid, opts.grid)?;
    crate::alloc::ensure_fits::<(f64, f64, f64)>("JIoU grid cells", cells)?;
    crate::alloc::ensure_fits::<[f64; BEV_PARAMS]>("JIoU samples", opts.samples)?;
    Ok(())
}

/// JIoU (eq. 8.4) of two Gaussian boxes on an `opts.grid²` grid spanning both; the exact IoU
/// when both are deterministic.
pub fn jiou(a: &ProbBox, b: &ProbBox, opts: &JiouOptions) -> Result<f64> {
    check_opts(opts)?;
    let ev = Evaluator {
        table: normal_table(opts.samples, opts.seed),
        opts: *opts,
    };
    ev.pair(a, b, &mut PairScratch::default())
}

/// JIoU of many pairs `(a[i], b[i])`, in parallel (the same normal table for every box, so the
/// result does not depend on the thread count).
pub fn jiou_batch(a: &[ProbBox], b: &[ProbBox], opts: &JiouOptions) -> Result<Vec<f64>> {
    check_opts(opts)?;
    if a.len() != b.len() {
        return Err(GeometryError::WrongLength {
            what: "second box list",
            got: b.len(),
            expected: a.len(),
        });
    }
    let ev = Evaluator {
        table: normal_table(opts.samples, opts.seed),
        opts: *opts,
    };
    a.par_iter()
        .zip(b.par_iter())
        .enumerate()
        .map_init(PairScratch::default, |scratch, (i, (x, y))| {
            ev.pair(x, y, scratch).map_err(|e| GeometryError::AtIndex {
                index: i,
                source: Box::new(e),
            })
        })
        .collect()
}
