//! Hierarchical segment registration with a Gaussian mixture, 000_3b1454b2b2194811.txt §4.3,
//! Algorithm 5, and the greedy nearest-centre associator it is compared with (the strategy of
//! the seed's reference \[90\], §4.3).
//!
//! Observed edge points `x_i` (segment `k = f(i)`) are explained by predicted points `x̂_j`
//! (segment `l = g(j)`) through the mixture of eq. (4.6): a Gaussian `N(x̂_j, σ²)` when the
//! segments are registered (`θ(k, l) = 1`), a uniform density `ω` otherwise. For a candidate
//! registration `θ(k, l) = 1` the E-step (4.7) gives, with `g_ij = exp(−‖x_i − x̂_j‖²/2σ²)`
//! and `N` the number of predicted points,
//!
//! `Q(i, j) = g_ij / (Σ_{j'∈J(l)} g_ij' + (N − |J(l)|)·ω)`,
//!
//! and the segment score (4.10) is `C(k, l) = Σ_{I(k), J(l)} Q(i, j)(c₁ − 2σ²log ω − ‖x_i − x̂_j‖²)`,
//! `c₁ = 2dσ²log(√(2π)σ)`, `d = 2`. Because `Q` of a point of segment `k` only depends on the
//! segment `l` it is registered to, the M-step (4.8)–(4.9) — the one-to-one `θ` maximising
//! `Σ C(k, l)θ(k, l)` — is exact in one pass: a rectangular assignment (the project's
//! Jonker–Volgenant/Hungarian solver) in which rows and columns may stay unassigned (new wafer,
//! wafer not visible). As in Algorithm 5, only the `K` nearest observed points of each
//! predicted point (kd-tree) enter the sums; pairs farther than `gate·σ` are dropped, where
//! `g_ij < e^{−gate²/2}` makes their contribution negligible.

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{DMatrix, Vector2};

use crate::assignment::{Assignment, solve_assignment_with_unassigned};
use crate::{DetectError, Result};

/// Parameters of the hierarchical registration (Algorithm 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationOptions {
    /// Standard deviation `σ` of the Gaussian components, eq. (4.2) (pixels).
    pub sigma: f64,
    /// Density `ω` of the uniform noise component, eq. (4.6)–(4.7) (in the units of the
    /// unnormalised Gaussian `g_ij`, which is 1 at its centre).
    pub omega: f64,
    /// `K` of the k-nearest-neighbour search of Algorithm 5.
    pub knn: usize,
    /// Pairs farther apart than `gate·σ` are left out of the sums.
    pub gate: f64,
    /// A segment pair is registered only if its score `C(k, l)` exceeds this value.
    pub min_score: f64,
    /// A segment pair is registered only if it explains at least this fraction of the observed
    /// segment's points (`Σ_{I(k),J(l)} Q(i, j) / |I(k)|`, the soft count of eq. 4.7) or of the
    /// predicted segment's points (those with an observed point of `k` within 2σ). `C(k, l) > 0`
    /// alone accepts a neighbouring wafer's rim when the track's own wafer is missing: two
    /// ellipses a pitch apart touch near the ends of their major axes, and those few points
    /// give a positive score. 0 disables the test.
    pub min_coverage: f64,
}

impl Default for RegistrationOptions {
    fn default() -> Self {
        RegistrationOptions {
            sigma: 3.0,
            omega: 1e-4,
            knn: 8,
            gate: 5.0,
            min_score: 0.0,
            min_coverage: 0.0,
        }
    }
}

impl RegistrationOptions {
    /// Checks every field.
    pub fn validate(&self) -> Result<()> {
        let positive = |what: &'static str, v: f64| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(DetectError::InvalidParameter {
                    what,
                    value: v,
                    reason: "must be finite and positive",
                })
            }
        };
        positive("sigma", self.sigma)?;
        positive("omega", self.omega)?;
        positive("gate", self.gate)?;
        if self.knn == 0 {
            return Err(DetectError::InvalidParameter {
                what: "knn",
                value: 0.0,
                reason: "the kNN search needs K >= 1",
            });
        }
        if !(0.0..=1.0).contains(&self.min_coverage) {
            return Err(DetectError::InvalidParameter {
                what: "min_coverage",
                value: self.min_coverage,
                reason: "must be a fraction in [0, 1]",
            });
        }
        if !self.min_score.is_finite() {
            return Err(DetectError::InvalidParameter {
                what: "min_score",
                value: self.min_score,
                reason: "must be finite",
            });
        }
        Ok(())
    }

    /// The constant `c₁ − 2σ²log ω` of eq. (4.8)/(4.10), `c₁ = 2dσ²log(√(2π)σ)`, `d = 2`.
    pub fn score_offset(&self) -> f64 {
        let s2 = self.sigma * self.sigma;
        let c1 = 4.0 * s2 * ((2.0 * std::f64::consts::PI).sqrt() * self.sigma).ln();
        c1 - 2.0 * s2 * self.omega.ln()
    }
}

/// Result of [`register_segments`].
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The score matrix `C(k, l)` of eq. (4.10), observed segments × predicted segments.
    pub score: DMatrix<f64>,
    /// The coverage of each pair (see [`RegistrationOptions::min_coverage`]): the larger of the
    /// explained fractions of the observed and of the predicted segment.
    pub coverage: DMatrix<f64>,
    /// The one-to-one registration `θ` of eq. (4.9): rows are observed, columns predicted
    /// segments; `assignment.cost` is `−Σ C(k, l)` over the registered pairs.
    pub assignment: Assignment,
}

/// Points of several segments in one flat array: `points[i]` belongs to segment `segment[i]`
/// (the maps `f` and `g` of §4.3).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SegmentPoints {
    /// The points `(u, v)` (pixels).
    pub points: Vec<[f64; 2]>,
    /// Segment index of each point.
    pub segment: Vec<usize>,
    /// Number of segments (segments may have no points).
    pub count: usize,
}

impl SegmentPoints {
    /// Builds the flat form from one point list per segment.
    pub fn from_segments(segments: &[Vec<Vector2<f64>>]) -> SegmentPoints {
        let mut out = SegmentPoints {
            count: segments.len(),
            ..SegmentPoints::default()
        };
        for (s, pts) in segments.iter().enumerate() {
            for p in pts {
                out.points.push([p.x, p.y]);
                out.segment.push(s);
            }
        }
        out
    }

    /// Appends one segment's points and returns its index.
    pub fn push_segment(&mut self, points: impl IntoIterator<Item = [f64; 2]>) -> usize {
        let s = self.count;
        for p in points {
            self.points.push(p);
            self.segment.push(s);
        }
        self.count += 1;
        s
    }

    fn validate(&self, what: &'static str) -> Result<()> {
        if self.segment.len() != self.points.len() {
            return Err(DetectError::WrongLength {
                what,
                got: self.segment.len(),
                expected: self.points.len(),
            });
        }
        for (i, p) in self.points.iter().enumerate() {
            if let Some(v) = p.iter().find(|v| !v.is_finite()) {
                return Err(DetectError::NonFinite {
                    what,
                    index: i,
                    value: *v,
                });
            }
        }
        if let Some(&s) = self.segment.iter().find(|&&s| s >= self.count) {
            return Err(DetectError::InvalidParameter {
                what: "segment index",
                value: s as f64,
                reason: "a point's segment index is not below the segment count",
            });
        }
        Ok(())
    }
}

/// Hierarchical segment registration, 000_3b1454b2b2194811.txt Algorithm 5 with the E-step
/// (4.7), the segment score (4.10) and the one-to-one M-step (4.9) (see the module doc).
///
/// `observed` are the edge points of the segments `Z_t` detected in this frame, `predicted`
/// the points of the predicted segments `Ẑ_t` of the tracks. Either may be empty (then nothing
/// is registered).
///
/// Errors: invalid options, non-finite points, inconsistent segment indices.
pub fn register_segments(
    observed: &SegmentPoints,
    predicted: &SegmentPoints,
    options: &RegistrationOptions,
) -> Result<Registration> {
    register_segments_gated(observed, predicted, options, None)
}

/// [`register_segments`] with the coverage test ([`RegistrationOptions::min_coverage`]) applied
/// only to the predicted segments flagged in `coverage_test` (one flag per predicted segment;
/// `None`: all). The tracker flags the segments whose prediction is tight (projected from a
/// well-estimated 3D rim): for a loose prediction (image motion of a young track) a true
/// registration may be displaced by more than the coverage radius of 2σ.
///
/// Errors: as [`register_segments`], and [`DetectError::WrongLength`] when `coverage_test`
/// does not have one flag per predicted segment.
pub fn register_segments_gated(
    observed: &SegmentPoints,
    predicted: &SegmentPoints,
    options: &RegistrationOptions,
    coverage_test: Option<&[bool]>,
) -> Result<Registration> {
    options.validate()?;
    if let Some(f) = coverage_test
        && f.len() != predicted.count
    {
        return Err(DetectError::WrongLength {
            what: "coverage_test flags",
            got: f.len(),
            expected: predicted.count,
        });
    }
    observed.validate("observed points")?;
    predicted.validate("predicted points")?;
    let (kc, lc) = (observed.count, predicted.count);
    let mut score = DMatrix::zeros(kc, lc);
    let mut coverage = DMatrix::zeros(kc, lc);
    if !observed.points.is_empty() && !predicted.points.is_empty() {
        accumulate_scores(observed, predicted, options, &mut score, &mut coverage)?;
    }
    let cost = DMatrix::from_fn(kc, lc, |k, l| {
        let c = score[(k, l)];
        let tested = coverage_test.is_none_or(|f| f[l]);
        if c > options.min_score && (!tested || coverage[(k, l)] >= options.min_coverage) {
            -c
        } else {
            f64::INFINITY
        }
    });
    let assignment = solve_assignment_with_unassigned(&cost, &vec![0.0; kc], &vec![0.0; lc])?;
    Ok(Registration {
        score,
        coverage,
        assignment,
    })
}

/// The kNN / E-step / score loop of Algorithm 5.
fn accumulate_scores(
    observed: &SegmentPoints,
    predicted: &SegmentPoints,
    options: &RegistrationOptions,
    score: &mut DMatrix<f64>,
    coverage: &mut DMatrix<f64>,
) -> Result<()> {
    let tree: ImmutableKdTree<f64, 2> =
        ImmutableKdTree::new_from_slice(&observed.points).map_err(|e| DetectError::Degenerate {
            reason: format!("kd-tree construction failed: {e}"),
        })?;
    let knn = NonZeroUsize::new(options.knn).unwrap_or(NonZeroUsize::MIN);
    let two_s2 = 2.0 * options.sigma * options.sigma;
    let r2 = (options.gate * options.sigma).powi(2);
    let c = options.score_offset();
    let n = predicted.points.len() as f64;
    let mut seg_size = vec![0usize; predicted.count];
    for &l in &predicted.segment {
        seg_size[l] += 1;
    }
    let mut obs_size = vec![0usize; observed.count];
    for &k in &observed.segment {
        obs_size[k] += 1;
    }
    let r_cov2 = 4.0 * options.sigma * options.sigma;
    // Per pair: soft count of explained observed points, count of covered predicted points.
    let mut explained = DMatrix::<f64>::zeros(observed.count, predicted.count);
    let mut covered = DMatrix::<f64>::zeros(observed.count, predicted.count);
    let mut near_segments: Vec<usize> = Vec::new();
    // Predicted points grouped by segment (stable order).
    let mut order: Vec<usize> = (0..predicted.points.len()).collect();
    order.sort_by_key(|&j| predicted.segment[j]);
    // Per segment l: the kNN pairs (i, g_ij, ‖x_i − x̂_j‖²) of its points, and the sums
    // S(i, l) = Σ_{j∈J(l)} g_ij in a dense scratch indexed by i (reset through `touched`).
    let mut sum_g = vec![0.0; observed.points.len()];
    let mut touched: Vec<u32> = Vec::new();
    let mut pairs: Vec<(u32, f64, f64)> = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let l = predicted.segment[order[start]];
        let mut end = start;
        pairs.clear();
        while end < order.len() && predicted.segment[order[end]] == l {
            let q = &predicted.points[order[end]];
            let found = tree
                .query(q)
                .nearest_n::<SquaredEuclidean<f64>>(knn)
                .within(r2)
                .execute();
            near_segments.clear();
            for r in found {
                let g = (-r.distance / two_s2).exp();
                let i = r.item as usize;
                if sum_g[i] == 0.0 {
                    touched.push(r.item);
                }
                sum_g[i] += g;
                pairs.push((r.item, g, r.distance));
                let k = observed.segment[i];
                if r.distance <= r_cov2 && !near_segments.contains(&k) {
                    near_segments.push(k);
                    covered[(k, l)] += 1.0;
                }
            }
            end += 1;
        }
        // Eq. (4.7) with θ(k, l) = 1: Nω + Σ_{j∈J(l)} (g_ij − ω).
        let outlier = (n - seg_size[l] as f64) * options.omega;
        for &(i, g, d2) in &pairs {
            let i = i as usize;
            let denom = sum_g[i] + outlier;
            if denom > 0.0 {
                score[(observed.segment[i], l)] += g / denom * (c - d2);
            }
        }
        for &i in &touched {
            let i = i as usize;
            let s = sum_g[i];
            if s + outlier > 0.0 {
                explained[(observed.segment[i], l)] += s / (s + outlier);
            }
            sum_g[i] = 0.0;
        }
        touched.clear();
        start = end;
    }
    for l in 0..predicted.count {
        for k in 0..observed.count {
            let fo = explained[(k, l)] / obs_size[k].max(1) as f64;
            let fp = covered[(k, l)] / seg_size[l].max(1) as f64;
            coverage[(k, l)] = fo.max(fp);
        }
    }
    Ok(())
}

/// The greedy nearest-centre associator (the baseline of §4.3, reference \[90\]): repeatedly
/// registers the closest remaining (observed centre, predicted centre) pair, if closer than
/// `gate` pixels. `predicted` entries that are `None` (no prediction) are never registered.
///
/// Errors: non-finite centres or a non-positive gate.
pub fn greedy_nearest_centre(
    observed: &[Vector2<f64>],
    predicted: &[Option<Vector2<f64>>],
    gate: f64,
) -> Result<Assignment> {
    if gate.is_nan() || gate <= 0.0 {
        return Err(DetectError::InvalidParameter {
            what: "gate",
            value: gate,
            reason: "the greedy association gate must be positive",
        });
    }
    for (i, p) in observed
        .iter()
        .chain(predicted.iter().flatten())
        .enumerate()
    {
        if let Some(v) = p.iter().find(|v| !v.is_finite()) {
            return Err(DetectError::NonFinite {
                what: "segment centre",
                index: i,
                value: *v,
            });
        }
    }
    let mut cands: Vec<(f64, usize, usize)> = Vec::new();
    for (k, o) in observed.iter().enumerate() {
        for (l, p) in predicted.iter().enumerate() {
            if let Some(p) = p {
                let d = (o - p).norm();
                if d < gate {
                    cands.push((d, k, l));
                }
            }
        }
    }
    cands.sort_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
    let mut out = Assignment {
        row_to_col: vec![None; observed.len()],
        col_to_row: vec![None; predicted.len()],
        cost: 0.0,
    };
    for (d, k, l) in cands {
        if out.row_to_col[k].is_none() && out.col_to_row[l].is_none() {
            out.row_to_col[k] = Some(l);
            out.col_to_row[l] = Some(k);
            out.cost += d;
        }
    }
    Ok(out)
}
