//! Global-CPD (000_3b1454b2b2194811.txt §3.4 "The Modified Global-CPD Framework", Fig. 3.14):
//! the top-K rigid transforms of global voting ([`crate::voting::global_voting`], Algorithm 3)
//! each start a non-rigid CPD; the hypotheses are ranked by the deformation energy
//! `‖f‖²_H = tr(Wᵀ G W)` (eq. (3.17)) of their CPD solution, least first — "the deformation
//! should not be too large for the objects encountered in practical cases".
//!
//! Each CPD starts from `Y` already moved by its hypothesis. Since the start is near its
//! answer, the initial σ² is by default the mean squared distance of the moved `Y` to its
//! nearest point of `X` (a local scale) rather than CPD's global `Σ‖x − y‖²/(DNM)`, which in a
//! cluttered scene would be dominated by the clutter and let the mixture drift away from the
//! hypothesis. An explicit `nonrigid.cpd.sigma2` overrides it.

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::{NonrigidOptions, NonrigidResult, nonrigid};
use crate::voting::{RigidHypothesis, VotingOptions, global_voting};
use crate::{DetectError, Result};

/// Options of [`global_cpd`].
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalCpdOptions {
    /// Global voting (its `top_k` is the number K of hypotheses refined).
    pub voting: VotingOptions,
    /// The non-rigid CPD run from every hypothesis.
    pub nonrigid: NonrigidOptions,
}

impl Default for GlobalCpdOptions {
    /// Voting defaults, and non-rigid CPD defaults with outlier weight `w = 0.5` (the scenes
    /// global-CPD is for are cluttered).
    fn default() -> Self {
        let mut nonrigid = NonrigidOptions::default();
        nonrigid.cpd.w = 0.5;
        Self {
            voting: VotingOptions::default(),
            nonrigid,
        }
    }
}

/// One refined hypothesis of [`global_cpd`].
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalHypothesis {
    /// The rigid initial transform from global voting (`x ≈ R y + t`) with its votes.
    pub initial: RigidHypothesis,
    /// The non-rigid CPD started from it; `transformed` is in the frame of X and `energy`
    /// ranks the hypotheses.
    pub cpd: NonrigidResult,
}

/// Global-CPD (Fig. 3.14): all K hypotheses refined by non-rigid CPD, ranked by deformation
/// energy, least first. An empty list when voting finds no cluster with enough votes.
///
/// Errors: those of [`global_voting`] and [`nonrigid`] (bad shapes, NaN, too few points,
/// invalid options); a hypothesis whose CPD fails on degenerate data is dropped, and the error
/// is returned only when every hypothesis fails.
pub fn global_cpd(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    options: &GlobalCpdOptions,
) -> Result<Vec<GlobalHypothesis>> {
    let hyps = global_voting(x, y, &options.voting)?;
    let runs: Vec<Result<GlobalHypothesis>> = hyps
        .into_par_iter()
        .map(|h| {
            let moved = move_points(y, &h);
            let mut opts = options.nonrigid.clone();
            if opts.cpd.sigma2.is_none() {
                opts.cpd.sigma2 = Some(nearest_sigma2(x, &moved)?);
            }
            let cpd = nonrigid(x, &moved, &opts)?;
            Ok(GlobalHypothesis { initial: h, cpd })
        })
        .collect();
    let mut first_err = None;
    let mut out = Vec::new();
    for r in runs {
        match r {
            Ok(h) => out.push(h),
            Err(e @ DetectError::Degenerate { .. }) => {
                first_err.get_or_insert(e);
            }
            Err(e) => return Err(e),
        }
    }
    if out.is_empty()
        && let Some(e) = first_err
    {
        return Err(e);
    }
    out.sort_by(|a, b| a.cpd.energy.total_cmp(&b.cpd.energy));
    Ok(out)
}

/// `R y + t` for every row.
fn move_points(y: &DMatrix<f64>, h: &RigidHypothesis) -> DMatrix<f64> {
    let mut m = y * h.rotation.transpose();
    for mut row in m.row_iter_mut() {
        row += h.translation.transpose();
    }
    m
}

/// Mean over the rows of `y` of the squared distance to the nearest row of `x`, divided by D
/// (a per-coordinate variance), floored at 1e−12 of the squared extent of `y`.
fn nearest_sigma2(x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<f64> {
    let d = y.ncols();
    // Nearest distances in parallel, summed in row order: rayon's `sum` splits by the thread
    // count, and the total must be bit-identical for any number of threads.
    let nearest: Vec<f64> = (0..y.nrows())
        .into_par_iter()
        .map(|i| {
            (0..x.nrows())
                .map(|j| (0..d).map(|c| (x[(j, c)] - y[(i, c)]).powi(2)).sum::<f64>())
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let total: f64 = nearest.iter().sum();
    let s2 = total / (y.nrows() * d) as f64;
    let extent = (0..d)
        .map(|c| {
            let col = y.column(c);
            (col.max() - col.min()).powi(2)
        })
        .sum::<f64>();
    if !s2.is_finite() {
        return Err(DetectError::Degenerate {
            reason: format!("initial variance of a hypothesis is {s2}"),
        });
    }
    Ok(s2.max(1e-12 * extent).max(f64::MIN_POSITIVE))
}
