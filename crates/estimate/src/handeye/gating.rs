//! Association of detected edges with the projected wafer estimate ("gating"), the step that
//! turns a detector's edges into the SLAM-MOT observations of 000_3b1454b2b2194811.txt §5.3.
//!
//! Once a first estimate exists, every wafer is projected through the estimated camera poses
//! into every frame: both rims, eq. (5.13)'s image conics `C = H⁻ᵀ·C₀·H⁻¹`
//! ([`autoteach_geometry::conic::circle_image_conic_and_inverse`]). Each detected edge is
//! scored against the predicted rims whose image box it overlaps with a truncated (robust)
//! loss: its points within `gate_px` (Sampson distance, [`Ellipse`]-free: `|pᵀCp| / 2‖(Cp)₁,₂‖`)
//! of a predicted rim are inliers. The edge goes to the rim with the most inliers when they are
//! at least `min_inlier_fraction` of its points and `min_points`; only its inlier points are
//! kept. Edges of wafers that were never tracked, false arcs and mislabelled rims are thereby
//! rejected or re-labelled; each (frame, wafer, rim) keeps its best edge. The association does
//! not use the tracker's identities.
//!
//! [`Ellipse`]: autoteach_geometry::conic::Ellipse

mod band;
mod rims;

pub use band::{
    BAND_NOISE_LOWER, BAND_NOISE_UPPER, BAND_NOISE_WIDTH_PX, band_sigma_scale, band_width,
};
pub use rims::{ProjectedRim, project_rims};

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Isometry3, Matrix3, Vector2, Vector5};

use super::slam::EdgeObservation;
use super::wafer::{Rim, WaferGeometry};
use crate::{EstimateError, Result};

/// The gating rules. Defaults: a 2 px gate, 60 % inliers, 24 points per rim, at least 12.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateConfig {
    /// Inlier distance to a predicted rim (pixels, Sampson distance).
    pub gate_px: f64,
    /// Smallest fraction of an edge's (subsampled) points that must be inliers of its rim.
    pub min_inlier_fraction: f64,
    /// Points kept per (frame, wafer, rim) observation, evenly spaced; edges are scored on twice
    /// as many (`min_points` counts on that subsample).
    pub points_per_rim: usize,
    /// Smallest number of points of an edge and of its inliers.
    pub min_points: usize,
    /// `> 0`: keep only inlier points where the predicted image of the wafer's side face is at
    /// least this wide (pixels, [`band_width`]). Where the band narrows its two edges blur into
    /// one and the detector's points are biased, an error the per-point noise of eq. (5.5) lacks.
    pub min_band_px: f64,
    /// Give every kept point a standard-deviation factor from the predicted band width
    /// ([`band_sigma_scale`], [`EdgeObservation::sigma_scale`]).
    pub band_weights: bool,
}

impl Default for GateConfig {
    fn default() -> Self {
        Self {
            gate_px: 2.0,
            min_inlier_fraction: 0.6,
            points_per_rim: 24,
            min_points: 12,
            min_band_px: 0.0,
            band_weights: false,
        }
    }
}

impl GateConfig {
    /// Checks the rules: a finite positive gate, a fraction in `[0, 1]`, `points_per_rim ≥ 1`,
    /// a finite non-negative band width.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, value, reason| {
            Err(EstimateError::InvalidParameter {
                name,
                value,
                reason,
            })
        };
        if !(self.gate_px.is_finite() && self.gate_px > 0.0) {
            return bad(
                "gate_px",
                self.gate_px,
                "must be finite and positive (pixels)",
            );
        }
        if !(0.0..=1.0).contains(&self.min_inlier_fraction) {
            return bad(
                "min_inlier_fraction",
                self.min_inlier_fraction,
                "must be a fraction in [0, 1]",
            );
        }
        if self.points_per_rim == 0 {
            return bad("points_per_rim", 0.0, "must be at least 1");
        }
        if !(self.min_band_px.is_finite() && self.min_band_px >= 0.0) {
            return bad(
                "min_band_px",
                self.min_band_px,
                "must be finite and non-negative (pixels)",
            );
        }
        Ok(())
    }
}

/// Detected edges of a session in a flat layout: edge `e` is `points[start[e]..start[e + 1]]`,
/// seen in frame `frames[e]`.
#[derive(Debug, Clone, Copy)]
pub struct DetectedEdges<'a> {
    /// All edge points (pixels), edge after edge.
    pub points: &'a [Vector2<f64>],
    /// `E + 1` offsets into `points`, non-decreasing, the last one `points.len()`.
    pub start: &'a [usize],
    /// Frame of each edge (index into the camera poses).
    pub frames: &'a [usize],
}

impl DetectedEdges<'_> {
    fn validate(&self, n_frames: usize) -> Result<()> {
        let n = self.frames.len();
        if self.start.len() != n + 1 {
            return Err(EstimateError::DimensionMismatch {
                what: "edge offsets (one more than the edges)".into(),
                expected: vec![n + 1],
                got: vec![self.start.len()],
            });
        }
        if self.start[0] != 0
            || self.start.windows(2).any(|w| w[0] > w[1])
            || self.start[n] != self.points.len()
        {
            return Err(EstimateError::InvalidInput(format!(
                "edge offsets must rise from 0 to the number of points ({}), got {:?}…{:?}",
                self.points.len(),
                self.start.first(),
                self.start.last()
            )));
        }
        if let Some((e, f)) = self
            .frames
            .iter()
            .enumerate()
            .find(|(_, f)| **f >= n_frames)
        {
            return Err(EstimateError::InvalidInput(format!(
                "edge {e} is in frame {f}, but there are {n_frames} camera poses"
            )));
        }
        if let Some((i, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(EstimateError::NonFiniteInput {
                what: "edge points".into(),
                index: i,
                value: if p.x.is_finite() { p.y } else { p.x },
            });
        }
        Ok(())
    }
}

/// What the gating did, for the run's report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GateStats {
    /// Edges with at least `min_points` points (the ones scored).
    pub edges: usize,
    /// Scored edges given to no rim.
    pub edges_rejected: usize,
    /// (frame, wafer, rim) observations kept.
    pub rims_used: usize,
    /// Frames with at least one kept observation.
    pub frames_used: usize,
    /// Inlier points dropped because the predicted side band was narrower than `min_band_px`.
    pub points_narrow_band: usize,
    /// (frame, wafer, rim) triples some edge was associated with, before the band filter.
    pub rims_associated: usize,
}

/// The gated observations, sorted by (frame, wafer, rim), and what the gating did.
#[derive(Debug, Clone, PartialEq)]
pub struct Gated {
    /// One observation per (frame, wafer, rim), at most `points_per_rim` points each.
    pub observations: Vec<EdgeObservation>,
    /// Counts.
    pub stats: GateStats,
}

/// Evenly spaced indices `round(i·(n−1)/(m−1))` of `m` out of `n` items (all of them when
/// `n ≤ m`); rounding half to even, so that it picks the points NumPy's `linspace` would.
pub fn subsample_indices(n: usize, m: usize) -> Vec<usize> {
    if n <= m {
        return (0..n).collect();
    }
    if m == 1 {
        return vec![0];
    }
    let step = (n - 1) as f64 / (m - 1) as f64;
    let mut idx: Vec<usize> = (0..m)
        .map(|i| (i as f64 * step).round_ties_even() as usize)
        .collect();
    idx[m - 1] = n - 1;
    idx
}

/// Sampson (first-order geometric) distance of `p` to the conic `c` (pixels):
/// `|pᵀCp| / (2‖(Cp)₁,₂‖)`, the distance to the curve for points near it (the gating range of a
/// few pixels), an over- or under-estimate farther away.
pub fn sampson_distance(c: &Matrix3<f64>, p: &Vector2<f64>) -> f64 {
    let ph = nalgebra::Vector3::new(p.x, p.y, 1.0);
    let cp = c * ph;
    let grad = 2.0 * cp.x.hypot(cp.y);
    ph.dot(&cp).abs() / grad.max(1e-300)
}

/// Associates every detected edge with the rims of `wafers` projected through `camera_poses`
/// (`T_wc`, one per frame) and `k`; see the module documentation.
///
/// `wafers[w] = None` marks a wafer without an estimate: its rims are not predicted, and an
/// edge of it is rejected (or goes to a neighbour whose prediction it fits).
///
/// Errors: [`EstimateError::InvalidParameter`] for invalid rules,
/// [`EstimateError::DimensionMismatch`] / [`EstimateError::InvalidInput`] for an inconsistent
/// edge layout or a frame without a camera pose, [`EstimateError::NonFiniteInput`] for a
/// non-finite point, pose or wafer, and the geometry errors of an invalid `k`.
pub fn gate_edges(
    k: &Matrix3<f64>,
    camera_poses: &[Isometry3<f64>],
    wafers: &[Option<Vector5<f64>>],
    geometry: WaferGeometry,
    edges: &DetectedEdges<'_>,
    config: &GateConfig,
) -> Result<Gated> {
    config.validate()?;
    edges.validate(camera_poses.len())?;
    let mut stats = GateStats::default();
    // (frame, wafer, rim) → (inliers, points, σ factors), best edge kept.
    let mut best: Kept = BTreeMap::new();
    let mut associated = BTreeSet::new();
    let mut by_frame: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (e, f) in edges.frames.iter().enumerate() {
        by_frame.entry(*f).or_default().push(e);
    }
    let n_score = (2 * config.points_per_rim).max(config.min_points);
    for (f, edge_ids) in by_frame {
        let rims = project_rims(k, &camera_poses[f], wafers, geometry)?;
        if rims.is_empty() {
            continue;
        }
        for e in edge_ids {
            let all = &edges.points[edges.start[e]..edges.start[e + 1]];
            if all.len() < config.min_points {
                continue;
            }
            stats.edges += 1;
            let p: Vec<Vector2<f64>> = subsample_indices(all.len(), n_score)
                .into_iter()
                .map(|i| all[i])
                .collect();
            let Some((r, q)) = best_rim(&p, &rims, config) else {
                stats.edges_rejected += 1;
                continue;
            };
            let rim = &rims[r];
            let key = (f, rim.wafer, rim.rim as u8);
            associated.insert(key);
            let (q, scale) = if config.min_band_px > 0.0 || config.band_weights {
                // The rims of a wafer are pushed upper then lower: the partner is r ^ 1.
                let (q, scale, narrow) =
                    band_filter(q, rim, &rims[r ^ 1], k, geometry.radius, config);
                stats.points_narrow_band += narrow;
                if q.len() < config.min_points {
                    stats.edges_rejected += 1;
                    continue;
                }
                (q, scale)
            } else {
                (q, Vec::new())
            };
            if best.get(&key).is_none_or(|b| q.len() > b.0) {
                best.insert(key, (q.len(), q, scale));
            }
        }
    }
    let mut frames = BTreeSet::new();
    let observations: Vec<EdgeObservation> = best
        .into_iter()
        .map(|((f, w, r), (_, q, scale))| {
            frames.insert(f);
            let idx = subsample_indices(q.len(), config.points_per_rim);
            EdgeObservation {
                frame: f,
                wafer: w,
                rim: if r == 0 { Rim::Upper } else { Rim::Lower },
                points: idx.iter().map(|i| q[*i]).collect(),
                sigma_scale: if scale.is_empty() {
                    Vec::new()
                } else {
                    idx.iter().map(|i| scale[*i]).collect()
                },
            }
        })
        .collect();
    stats.rims_used = observations.len();
    stats.frames_used = frames.len();
    stats.rims_associated = associated.len();
    Ok(Gated {
        observations,
        stats,
    })
}

/// The rim (index into `rims`) with the most inliers among the points `p` of one edge, and those
/// inliers; `None` when no rim whose image box meets the edge's has enough of them (at least
/// `min_points` and `min_inlier_fraction` of `p`).
fn best_rim(
    p: &[Vector2<f64>],
    rims: &[ProjectedRim],
    config: &GateConfig,
) -> Option<(usize, Vec<Vector2<f64>>)> {
    let bb = bbox(p);
    let margin = 3.0 * config.gate_px;
    let mut choice: Option<(usize, Vec<Vector2<f64>>)> = None;
    for (r, rim) in rims
        .iter()
        .enumerate()
        .filter(|(_, r)| r.overlaps(&bb, margin))
    {
        let inliers: Vec<Vector2<f64>> = p
            .iter()
            .filter(|q| sampson_distance(&rim.conic, q) <= config.gate_px)
            .copied()
            .collect();
        if inliers.len() > choice.as_ref().map_or(0, |c| c.1.len()) {
            choice = Some((r, inliers));
        }
    }
    let needed = (config.min_points as f64).max(config.min_inlier_fraction * p.len() as f64);
    choice.filter(|(_, q)| q.len() as f64 >= needed)
}

/// The points of `q` (on `rim`) where the predicted side band is at least `min_band_px` wide,
/// their σ factors when `band_weights` is set (else empty), and how many were dropped.
fn band_filter(
    q: Vec<Vector2<f64>>,
    rim: &ProjectedRim,
    other: &ProjectedRim,
    k: &Matrix3<f64>,
    radius: f64,
    config: &GateConfig,
) -> (Vec<Vector2<f64>>, Vec<f64>, usize) {
    let band = band_width(&q, &rim.h_inv, &other.t_co, &rim.conic, k, radius);
    // A NaN width is not known to be narrow: the point stays (with the largest σ factor).
    let keep: Vec<bool> = band
        .iter()
        .map(|b| b.is_nan() || *b >= config.min_band_px)
        .collect();
    let narrow = keep.iter().filter(|k| !**k).count();
    let kept = |i: &usize| keep[*i];
    let idx: Vec<usize> = (0..q.len()).filter(kept).collect();
    let scale = if config.band_weights {
        idx.iter()
            .map(|i| band_sigma_scale(band[*i], rim.rim))
            .collect()
    } else {
        Vec::new()
    };
    (idx.iter().map(|i| q[*i]).collect(), scale, narrow)
}

/// The best edge of each (frame, wafer, rim): its inlier count, points and σ factors.
type Kept = BTreeMap<(usize, usize, u8), (usize, Vec<Vector2<f64>>, Vec<f64>)>;

/// `[u_min, v_min, u_max, v_max]` of a non-empty point set.
fn bbox(p: &[Vector2<f64>]) -> [f64; 4] {
    p.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, q| [b[0].min(q.x), b[1].min(q.y), b[2].max(q.x), b[3].max(q.y)],
    )
}

#[cfg(test)]
mod tests;
