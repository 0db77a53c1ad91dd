//! The selection scores of [`super::global_register`]: the explained fraction and the CPD
//! likelihood with the outlier term (000_3b1454b2b2194811.txt eq. (3.12)), both at a common
//! inlier radius / σ̂², through a k-d tree of the scene.

use std::f64::consts::PI;
use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::DMatrix;

use crate::{DetectError, Result};

/// A k-d tree over the rows of a 2-D or 3-D point set.
pub(super) enum Index {
    /// Planar points.
    Two(ImmutableKdTree<f64, 2>, usize),
    /// Spatial points.
    Three(ImmutableKdTree<f64, 3>, usize),
}

fn tree<const D: usize>(p: &DMatrix<f64>) -> Result<ImmutableKdTree<f64, D>> {
    let pts: Vec<[f64; D]> = (0..p.nrows())
        .map(|r| std::array::from_fn(|c| p[(r, c)]))
        .collect();
    ImmutableKdTree::new_from_slice(&pts).map_err(|e| DetectError::Degenerate {
        reason: format!("k-d tree construction failed: {e:?}"),
    })
}

impl Index {
    /// Tree of the rows of `p` (N×2 or N×3).
    pub(super) fn new(p: &DMatrix<f64>) -> Result<Self> {
        Ok(if p.ncols() == 2 {
            Self::Two(tree::<2>(p)?, p.nrows())
        } else {
            Self::Three(tree::<3>(p)?, p.nrows())
        })
    }

    /// Index of, and squared distance to, the indexed point nearest to row `r` of `q`.
    pub(super) fn nearest(&self, q: &DMatrix<f64>, r: usize) -> (usize, f64) {
        match self {
            Self::Two(t, _) => {
                let p = [q[(r, 0)], q[(r, 1)]];
                let n = t.query(&p).nearest_one::<SquaredEuclidean<f64>>().execute();
                (n.item as usize, n.distance)
            }
            Self::Three(t, _) => {
                let p = [q[(r, 0)], q[(r, 1)], q[(r, 2)]];
                let n = t.query(&p).nearest_one::<SquaredEuclidean<f64>>().execute();
                (n.item as usize, n.distance)
            }
        }
    }

    /// Squared distance from row `r` of `q` to its nearest indexed point.
    fn nearest_sq(&self, q: &DMatrix<f64>, r: usize) -> f64 {
        self.nearest(q, r).1
    }

    /// `(index, squared distance)` of every indexed point within `radius` of row `r` of `q`.
    fn within(&self, q: &DMatrix<f64>, r: usize, radius: f64, out: &mut Vec<(usize, f64)>) {
        out.clear();
        let r2 = radius * radius;
        match self {
            Self::Two(t, _) => {
                let p = [q[(r, 0)], q[(r, 1)]];
                out.extend(
                    t.query(&p)
                        .within::<SquaredEuclidean<f64>>(r2)
                        .execute()
                        .into_iter()
                        .map(|n| (n.item as usize, n.distance)),
                );
            }
            Self::Three(t, _) => {
                let p = [q[(r, 0)], q[(r, 1)], q[(r, 2)]];
                out.extend(
                    t.query(&p)
                        .within::<SquaredEuclidean<f64>>(r2)
                        .execute()
                        .into_iter()
                        .map(|n| (n.item as usize, n.distance)),
                );
            }
        }
    }

    fn len(&self) -> usize {
        match self {
            Self::Two(_, n) | Self::Three(_, n) => *n,
        }
    }

    /// Fraction of the rows of `q` with an indexed point within `radius`.
    pub(super) fn fraction_within(&self, q: &DMatrix<f64>, radius: f64) -> f64 {
        let r2 = radius * radius;
        let hits = (0..q.nrows())
            .filter(|&r| self.nearest_sq(q, r) <= r2)
            .count();
        hits as f64 / q.nrows().max(1) as f64
    }
}

/// Median distance from each row of `p` to its nearest other row (the sampling resolution).
pub(super) fn median_spacing(p: &DMatrix<f64>) -> Result<f64> {
    let d = p.ncols();
    let mut nn: Vec<f64> = if d == 2 {
        nearest_other::<2>(p)?
    } else {
        nearest_other::<3>(p)?
    };
    nn.sort_by(f64::total_cmp);
    Ok(nn.get(nn.len() / 2).copied().unwrap_or(0.0))
}

fn nearest_other<const D: usize>(p: &DMatrix<f64>) -> Result<Vec<f64>> {
    let t = tree::<D>(p)?;
    let two = NonZero::new(2).ok_or(DetectError::TooFewPoints {
        what: "points",
        got: 0,
        needed: 2,
    })?;
    Ok((0..p.nrows())
        .map(|r| {
            let q: [f64; D] = std::array::from_fn(|c| p[(r, c)]);
            t.query(&q)
                .nearest_n::<SquaredEuclidean<f64>>(two)
                .execute()
                .into_iter()
                .map(|n| n.distance)
                .fold(0.0, f64::max)
                .sqrt()
        })
        .collect())
}

/// Uniform-stride subsample of `n` indices to at most `max`.
pub(super) fn subsample_rows(n: usize, max: usize) -> Vec<usize> {
    if n <= max {
        (0..n).collect()
    } else {
        (0..max).map(|k| k * n / max).collect()
    }
}

/// The common scale of the scores of one registration.
pub(super) struct Scorer<'a> {
    /// Tree of the scene.
    pub index: &'a Index,
    /// Inlier radius `r`.
    pub radius: f64,
    /// Common σ̂².
    pub sigma2: f64,
    /// Outlier weight.
    pub w: f64,
    /// Volume of the scene's bounding box (the support of the uniform term).
    pub volume: f64,
    /// Scene size N.
    pub n_scene: usize,
}

impl Scorer<'_> {
    /// Fraction of the rows of `moved` (the template at a pose) with a scene point within `r`.
    pub(super) fn explained(&self, moved: &DMatrix<f64>) -> f64 {
        self.index.fraction_within(moved, self.radius)
    }

    /// `Σ_n log(1 + c Σ_m 𝒩(x_n; moved_m, σ̂²I))`, `c = (1−w)V/(wM)`: the CPD log-likelihood
    /// (3.12) with the uniform term `w/V`, minus its constant `N log(w/V)`. Gaussians beyond
    /// `6σ̂` (relative weight < 1.6·10⁻⁸) are left out.
    pub(super) fn log_likelihood(&self, moved: &DMatrix<f64>) -> f64 {
        let d = moved.ncols() as f64;
        let m = moved.nrows() as f64;
        let norm = (2.0 * PI * self.sigma2).powf(-d / 2.0);
        let c = (1.0 - self.w) * self.volume / (self.w * m) * norm;
        let mut sums = vec![0.0f64; self.n_scene.min(self.index.len())];
        let mut near = Vec::new();
        let reach = 6.0 * self.sigma2.sqrt();
        for r in 0..moved.nrows() {
            self.index.within(moved, r, reach, &mut near);
            for &(i, d2) in &near {
                sums[i] += (-d2 / (2.0 * self.sigma2)).exp();
            }
        }
        sums.iter()
            .filter(|&&s| s > 0.0)
            .map(|&s| (c * s).ln_1p())
            .sum()
    }
}
