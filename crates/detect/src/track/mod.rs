//! Multi-wafer tracking by detection, 000_3b1454b2b2194811.txt ch. 4: prediction of each
//! track's elliptic segment (§4.2, eq. 4.1), hierarchical segment registration with a Gaussian
//! mixture (§4.3, Algorithm 5, eq. 4.2–4.10, in [`registration`]) and track management
//! (Algorithm 4): birth, update, loss, re-acquisition and retirement.
//!
//! One track is one wafer: the upper and lower rims of a wafer (the edges of one
//! [`WaferEdge::wafer_id`] in a frame) are registered together, and an unregistered edge lying
//! within [`TrackerOptions::rim_merge_distance`] of a rim registered in the same frame joins
//! that wafer's track (the seed's "distance between the upper and lower edges of a wafer is
//! much smaller than distances to edges of other wafers", §4.2), which also absorbs duplicated
//! edges.
//!
//! Prediction follows §4.2. A rim seen in the previous frame is moved by image motion: a
//! constant-velocity model on the ellipse parameters, each edge point keeping its eccentric
//! angle (the seed uses dense optical flow here; the motion model needs no image). A rim seen
//! earlier is predicted by eq. (4.1): its 3D circle `w_k` — estimated from the edge points of its
//! recent views, the camera poses and the known wafer radius ([`circle_fit`], started from the
//! single-ellipse back-projections of [`circle`]; with a normal prior and a carrier-axis prior,
//! see [`TrackerOptions::stack_axis_sigma`]) — is projected through the current camera pose at
//! the rim angles where it was seen. A rim whose estimate is tight
//! ([`TrackerOptions::projection_max_center_std`]) is projected also when it was seen in the
//! previous frame, and its track is kept [`TrackerOptions::max_missed_3d`] frames for
//! re-acquisition. Tracks unseen for more than
//! [`TrackerOptions::max_missed`] frames are retired, as the seed discards long-invisible
//! wafers. With the carrier's slot pitch ([`TrackerOptions::slot_pitch`]) the free slots next to
//! the tracks are predicted by eq. (4.1) too and compete in the registration as new wafers.
//!
//! ```
//! use autoteach_detect::track::{Tracker, TrackerOptions};
//! use autoteach_detect::wafers::{RimKind, WaferEdge};
//! use autoteach_geometry::conic::Ellipse;
//! use nalgebra::Point2;
//!
//! let edge = |cy: f64, id: usize| {
//!     let e = Ellipse::new(640.0, cy, 300.0, 40.0, 0.0).unwrap();
//!     let points = e.sample(60, 0.2, 2.9).unwrap().into_iter().map(Point2::from).collect();
//!     WaferEdge { ellipse: e, points, residual: 0.0, covariance: None, kind: RimKind::Upper, wafer_id: id }
//! };
//! let mut tracker = Tracker::new(TrackerOptions::default())?;
//! tracker.update(&[edge(300.0, 0), edge(330.0, 1)], None)?;
//! tracker.update(&[edge(333.0, 0), edge(303.0, 1)], None)?; // listed in the other order
//! let ids = tracker.edge_tracks();
//! assert_eq!(ids.len(), 2);
//! assert_ne!(ids[0], ids[1]);
//! let t = tracker.tracks().iter().find(|t| Some(t.id) == ids[1]).unwrap();
//! assert_eq!(t.history[0].1.ellipse.cy, 300.0); // the wafer at 303 continues the one at 300
//! # Ok::<(), autoteach_detect::DetectError>(())
//! ```

pub mod circle;
pub mod circle_fit;
mod occupancy;
pub mod registration;
mod rim_motion;

use std::collections::VecDeque;
use std::num::NonZeroUsize;

use autoteach_geometry::conic::{Ellipse, project_circle_world};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Isometry3, Matrix3, Vector2, Vector3};

use crate::wafers::{RimKind, WaferEdge};
use crate::{DetectError, Result};
use circle::{Circle3, check_intrinsics, circles_from_ellipse, project};
use circle_fit::{CircleFit, CircleFitOptions, RimView, refine_circle};
use occupancy::*;
use registration::{
    Registration, RegistrationOptions, SegmentPoints, greedy_nearest_centre,
    register_segments_gated,
};
use rim_motion::*;

/// Which associator registers predicted and observed segments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Associator {
    /// Hierarchical GMM segment registration, Algorithm 5 (the default).
    Hierarchical,
    /// Greedy nearest-centre association (the baseline of §4.3), gated by
    /// [`TrackerOptions::greedy_gate`].
    GreedyNearestCentre,
}

/// Parameters of the [`Tracker`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerOptions {
    /// Parameters of the segment registration (σ, ω, K, gate, minimum score).
    pub registration: RegistrationOptions,
    /// The associator.
    pub associator: Associator,
    /// Largest centre distance (pixels) the greedy associator registers.
    pub greedy_gate: f64,
    /// Edge points per segment used for registration (longer segments are subsampled evenly).
    pub max_points_per_segment: usize,
    /// A confirmed track unseen for more than this many consecutive frames is retired.
    pub max_missed: usize,
    /// A new track is confirmed after this many registered frames; a tentative track that
    /// misses a frame is dropped.
    pub min_hits: usize,
    /// An unregistered edge whose points lie within this mean distance (pixels, Sampson) of an
    /// edge registered to a track in the same frame joins that track (other rim, duplicate).
    pub rim_merge_distance: f64,
    /// Image size `(width, height)`: predicted points outside it are dropped.
    pub image_size: Option<(f64, f64)>,
    /// Pinhole intrinsics `K` of the camera, needed for the projection prediction (eq. 4.1).
    pub intrinsics: Option<Matrix3<f64>>,
    /// Wafer radius (metres) for the 3D circle estimate.
    pub wafer_radius: f64,
    /// Expected wafer normal in the world frame (either sign); resolves the two-fold circle
    /// ambiguity from a single view. Without it the ambiguity is resolved across views.
    pub normal_prior: Option<Vector3<f64>>,
    /// Number of most recent views whose circle estimates are averaged per rim.
    pub circle_window: usize,
    /// Use the projection (4.1) whenever a 3D estimate and a pose exist, also for rims seen in
    /// the previous frame with a known image velocity (the seed uses image motion there; a rim
    /// seen only once has no velocity and is projected whenever possible).
    pub prefer_projection: bool,
    /// Estimate each rim's 3D circle from the edge points of its last `circle_window` views
    /// with their camera poses ([`circle_fit::refine_circle`]) instead of averaging per-view
    /// ellipse back-projections (needs poses and `intrinsics`).
    pub multiview_circle: bool,
    /// Standard deviation (radians) of a wafer's tilt from `normal_prior` in the multi-view fit.
    pub normal_prior_sigma: f64,
    /// Levenberg–Marquardt iterations of the multi-view fit per registered frame (warm start).
    pub circle_fit_iterations: usize,
    /// A rim whose multi-view estimate has a centre standard deviation below this (metres) and
    /// an RMS point distance below `projection_max_rms` is predicted by the projection (4.1)
    /// also when it was seen in the previous frame: with known camera poses it is exact up to
    /// the estimate's error, while image motion extrapolates noisy ellipse fits.
    pub projection_max_center_std: f64,
    /// See `projection_max_center_std` (pixels).
    pub projection_max_rms: f64,
    /// A confirmed track whose 3D estimate is good enough for the projection prediction (see
    /// `projection_max_center_std`) is kept this many frames unseen (instead of `max_missed`),
    /// so that a wafer leaving the image and coming back is re-acquired by its projected 3D
    /// position (Algorithm 4's re-acquisition, prediction case 2 of §4.2).
    pub max_missed_3d: usize,
    /// Carrier-axis prior (metres; `None`: off). The carrier stacks the wafers coaxially at a
    /// fixed pitch, so every wafer centre lies near one line along the common normal. The line
    /// is the mean centre and mean normal of the tracks with well-estimated rims (at least
    /// three); a young rim's multi-view fit gets a prior with this standard deviation across
    /// it, so that one partial or edge-on view already fixes its height on the stack and the
    /// projection prediction (4.1) replaces image-motion extrapolation of noisy ellipses.
    pub stack_axis_sigma: Option<f64>,
    /// Carrier slot pitch (metres; `None`: off). The carrier holds the wafers at this pitch
    /// along its axis, so the slots next to a tracked wafer are known up to occupancy: each
    /// free neighbouring slot (±pitch along the axis from a track's 3D estimate, with no track
    /// within half a pitch of it) is predicted by eq. (4.1) — the track's predicted points
    /// moved by the image displacement between its rim and the rim one pitch away — and enters
    /// the registration (Algorithm 5) as a column of its own, whose registered segment starts a
    /// new track. A wafer appearing next to a track whose own wafer is missed then explains its
    /// points by its own slot instead of the track's prediction one pitch away.
    pub slot_pitch: Option<f64>,
}

impl Default for TrackerOptions {
    fn default() -> Self {
        TrackerOptions {
            registration: RegistrationOptions::default(),
            associator: Associator::Hierarchical,
            greedy_gate: 40.0,
            max_points_per_segment: 48,
            max_missed: 30,
            min_hits: 2,
            rim_merge_distance: 4.0,
            image_size: None,
            intrinsics: None,
            wafer_radius: 0.15,
            normal_prior: None,
            circle_window: 6,
            prefer_projection: false,
            multiview_circle: true,
            normal_prior_sigma: 0.05,
            circle_fit_iterations: 1,
            projection_max_center_std: 0.003,
            projection_max_rms: 2.0,
            max_missed_3d: 300,
            stack_axis_sigma: Some(0.002),
            slot_pitch: None,
        }
    }
}

impl TrackerOptions {
    /// Checks every field.
    pub fn validate(&self) -> Result<()> {
        self.registration.validate()?;
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
        positive("greedy_gate", self.greedy_gate)?;
        positive("rim_merge_distance", self.rim_merge_distance)?;
        positive("wafer_radius", self.wafer_radius)?;
        positive("normal_prior_sigma", self.normal_prior_sigma)?;
        positive("projection_max_center_std", self.projection_max_center_std)?;
        positive("projection_max_rms", self.projection_max_rms)?;
        if let Some(s) = self.stack_axis_sigma {
            positive("stack_axis_sigma", s)?;
        }
        if let Some(p) = self.slot_pitch {
            positive("slot_pitch", p)?;
        }
        for (what, v) in [
            ("max_points_per_segment", self.max_points_per_segment),
            ("min_hits", self.min_hits),
            ("circle_window", self.circle_window),
        ] {
            if v == 0 {
                return Err(DetectError::InvalidParameter {
                    what,
                    value: 0.0,
                    reason: "must be at least 1",
                });
            }
        }
        if let Some((w, h)) = self.image_size {
            positive("image width", w)?;
            positive("image height", h)?;
        }
        if let Some(k) = &self.intrinsics {
            check_intrinsics(k)?;
        }
        if let Some(n) = &self.normal_prior {
            let len = n.norm();
            if !(len > 0.0 && len.is_finite()) {
                return Err(DetectError::InvalidParameter {
                    what: "normal_prior length",
                    value: len,
                    reason: "the normal prior must be a finite non-zero vector",
                });
            }
        }
        Ok(())
    }
}

/// The state of one rim (upper or lower) of a track.
#[derive(Debug, Clone, PartialEq)]
struct RimState {
    /// Last registered edge of this rim.
    edge: WaferEdge,
    /// Frame of `edge`.
    frame: usize,
    /// Camera pose `T_wc` of that frame, if given.
    pose: Option<Isometry3<f64>>,
    /// The previous registered ellipse of this rim and its frame (for the velocity).
    prev: Option<(usize, Ellipse)>,
    /// The two circle candidates (world frame) of the most recent views.
    candidates: VecDeque<[Circle3; 2]>,
    /// The current 3D estimate (world frame).
    circle: Option<Circle3>,
    /// The rim's most recent views (pose and edge points) for the multi-view estimate.
    views: VecDeque<RimView>,
    /// The multi-view estimate, if it ran.
    fit: Option<CircleFit>,
    /// Per view in `views`: the rim-angle bins (`ANGLE_BINS` over the circle) its points fell
    /// in, located on the estimate of that frame.
    bins: VecDeque<u64>,
}

/// The predicted segment of one track in the current frame.
#[derive(Debug, Clone, PartialEq)]
struct Prediction {
    points: Vec<[f64; 2]>,
    ellipse: Option<Ellipse>,
    /// Every rim was projected from a well-estimated 3D circle (a tight prediction).
    tight: bool,
}

/// One tracked wafer.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// Track identifier (unique within a tracker, increasing in order of birth).
    pub id: u64,
    /// The edges registered in the last frame the track was seen (one or two rims).
    pub edges: Vec<WaferEdge>,
    /// Whether the track was registered in the current frame.
    pub visible: bool,
    /// Whether the track has been registered in at least [`TrackerOptions::min_hits`] frames.
    pub confirmed: bool,
    /// Number of frames in which the track was registered.
    pub hits: usize,
    /// Consecutive frames in which it was not registered.
    pub missed: usize,
    /// Frame of the first registration.
    pub first_frame: usize,
    /// Frame of the last registration.
    pub last_frame: usize,
    /// Every registered edge with its frame index.
    pub history: Vec<(usize, WaferEdge)>,
    /// The predicted ellipse of the current frame (upper rim if predicted, else lower).
    pub predicted: Option<Ellipse>,
    rims: [Option<RimState>; 2],
}

impl Track {
    /// The latest registered ellipse (the upper rim's if the last frame had one).
    pub fn ellipse(&self) -> Option<Ellipse> {
        self.edges
            .iter()
            .find(|e| e.kind == RimKind::Upper)
            .or_else(|| self.edges.first())
            .map(|e| e.ellipse)
    }

    /// The current 3D estimate (world frame) of the upper rim, else of the lower rim.
    pub fn circle(&self) -> Option<Circle3> {
        self.rims.iter().flatten().find_map(|r| r.circle)
    }
}

/// Edge points per view kept for the multi-view circle estimate.
const MULTIVIEW_POINTS: usize = 24;

fn rim_index(kind: RimKind) -> usize {
    match kind {
        RimKind::Upper => 0,
        RimKind::Lower => 1,
    }
}

/// Wall-clock time (seconds) of the stages of the last [`Tracker::update`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UpdateTimings {
    /// Prediction of every track's segment (§4.2).
    pub predict: f64,
    /// Association: point sets, kd-tree, kNN, E-step, cost matrix and assignment (Algorithm 5),
    /// or the greedy baseline.
    pub associate: f64,
    /// Track management (Algorithm 4), including the 3D rim estimates.
    pub manage: f64,
}

/// The multi-wafer tracker of 000_3b1454b2b2194811.txt Algorithm 4 (see the module doc).
#[derive(Debug, Clone)]
pub struct Tracker {
    options: TrackerOptions,
    tracks: Vec<Track>,
    retired: Vec<Track>,
    frame: usize,
    next_id: u64,
    edge_tracks: Vec<Option<u64>>,
    timings: UpdateTimings,
    /// The carrier axis (point, unit direction) of this frame, if estimated.
    axis: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl Tracker {
    /// A tracker with the given options (validated).
    pub fn new(options: TrackerOptions) -> Result<Tracker> {
        options.validate()?;
        Ok(Tracker {
            options,
            tracks: Vec::new(),
            retired: Vec::new(),
            frame: 0,
            next_id: 0,
            edge_tracks: Vec::new(),
            timings: UpdateTimings::default(),
            axis: None,
        })
    }

    /// The options.
    pub fn options(&self) -> &TrackerOptions {
        &self.options
    }

    /// The live tracks (tentative and confirmed, visible or not), in order of birth.
    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    /// Confirmed tracks that were retired (unseen for more than `max_missed` frames).
    pub fn retired(&self) -> &[Track] {
        &self.retired
    }

    /// Number of frames processed so far (the index of the next frame).
    pub fn frame(&self) -> usize {
        self.frame
    }

    /// Stage timings of the last [`Tracker::update`].
    pub fn timings(&self) -> UpdateTimings {
        self.timings
    }

    /// For each edge of the last [`Tracker::update`], the track it was registered to
    /// (`None`: not registered — a merged duplicate is registered to its wafer's track).
    pub fn edge_tracks(&self) -> &[Option<u64>] {
        &self.edge_tracks
    }

    /// Processes one frame (Algorithm 4, one iteration of its loop): predicts every track
    /// into this frame, registers `edges` to the predictions (Algorithm 5 or the greedy
    /// baseline), updates registered tracks, creates tracks for unregistered wafers and ages
    /// or retires unregistered tracks. `t_wc` is the camera pose (camera → world) of the frame,
    /// needed for the projection prediction (eq. 4.1).
    ///
    /// Errors (the tracker is unchanged): an edge with non-finite values or an invalid
    /// ellipse, a non-finite pose.
    pub fn update(&mut self, edges: &[WaferEdge], t_wc: Option<&Isometry3<f64>>) -> Result<()> {
        validate_edges(edges)?;
        if let Some(t) = t_wc {
            let v = t
                .translation
                .vector
                .iter()
                .chain(t.rotation.coords.iter())
                .find(|v| !v.is_finite());
            if let Some(v) = v {
                return Err(DetectError::NonFinite {
                    what: "camera pose",
                    index: 0,
                    value: *v,
                });
            }
        }
        let frame = self.frame;
        // Observed segments: the edges grouped by wafer_id, in order of first appearance.
        let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
        for (i, e) in edges.iter().enumerate() {
            match groups.iter_mut().find(|g| g.0 == e.wafer_id) {
                Some(g) => g.1.push(i),
                None => groups.push((e.wafer_id, vec![i])),
            }
        }
        let t0 = std::time::Instant::now();
        let predictions: Vec<Prediction> = self
            .tracks
            .iter()
            .map(|t| self.predict(t, frame, t_wc))
            .collect();
        let t1 = std::time::Instant::now();
        // Rows registered to a free slot (row, slot column) and the score matrix C(k, l).
        let mut slot_rows: Vec<(usize, usize)> = Vec::new();
        let mut slot_score = None;
        let assignment = match self.options.associator {
            Associator::Hierarchical => {
                let slots = self.free_neighbour_slots(&predictions, t_wc);
                let reg = self.register_hierarchical(edges, &groups, &predictions, &slots)?;
                let mut a = reg.assignment;
                // A segment registered to a free slot is no track's: it starts a new one
                // unless it is the other rim or a duplicate of a wafer registered in this
                // frame that the track explains at least as well as the slot (see below).
                for (k, r) in a.row_to_col.iter_mut().enumerate() {
                    if let Some(v) = r.filter(|&l| l >= self.tracks.len()) {
                        slot_rows.push((k, v));
                        *r = None;
                    }
                }
                a.col_to_row.truncate(self.tracks.len());
                slot_score = Some(reg.score);
                a
            }
            Associator::GreedyNearestCentre => {
                let observed: Vec<Vector2<f64>> = groups
                    .iter()
                    .map(|(_, idx)| {
                        let e = idx
                            .iter()
                            .map(|&i| &edges[i])
                            .find(|e| e.kind == RimKind::Upper)
                            .unwrap_or(&edges[idx[0]]);
                        Vector2::new(e.ellipse.cx, e.ellipse.cy)
                    })
                    .collect();
                let predicted: Vec<Option<Vector2<f64>>> = predictions
                    .iter()
                    .map(|p| p.ellipse.map(|e| Vector2::new(e.cx, e.cy)))
                    .collect();
                greedy_nearest_centre(&observed, &predicted, self.options.greedy_gate)?
            }
        };
        let t2 = std::time::Instant::now();
        self.axis = self.stack_axis();
        // Track management (Algorithm 4).
        self.edge_tracks = vec![None; edges.len()];
        for (t, p) in self.tracks.iter_mut().zip(&predictions) {
            t.visible = false;
            t.predicted = p.ellipse;
        }
        for (k, (_, idx)) in groups.iter().enumerate() {
            if let Some(l) = assignment.row_to_col[k] {
                let edges_k: Vec<&WaferEdge> = idx.iter().map(|&i| &edges[i]).collect();
                self.register(l, &edges_k, frame, t_wc);
                for &i in idx {
                    self.edge_tracks[i] = Some(self.tracks[l].id);
                }
            }
        }
        // Unregistered groups: the other rim (or a duplicate) of a wafer registered in this
        // frame joins its track; the rest start new tracks.
        let mut births = Vec::new();
        for (k, (_, idx)) in groups.iter().enumerate() {
            if assignment.row_to_col[k].is_some() {
                continue;
            }
            let mut target = self.merge_target(edges, idx);
            if let (Some(l), Some(&(_, v)), Some(c)) = (
                target,
                slot_rows.iter().find(|r| r.0 == k),
                slot_score.as_ref(),
            ) && c[(k, l)] < c[(k, v)]
            {
                target = None;
            }
            match target {
                Some(l) => {
                    let edges_k: Vec<&WaferEdge> = idx.iter().map(|&i| &edges[i]).collect();
                    self.register(l, &edges_k, frame, t_wc);
                    for &i in idx {
                        self.edge_tracks[i] = Some(self.tracks[l].id);
                    }
                }
                None => births.push(k),
            }
        }
        // Loss and retirement of unregistered tracks.
        let max_missed = self.options.max_missed;
        let mut kept = Vec::with_capacity(self.tracks.len() + births.len());
        for mut t in std::mem::take(&mut self.tracks) {
            if !t.visible {
                t.missed += 1;
                if !t.confirmed {
                    continue;
                }
                let limit = if t.rims.iter().flatten().any(|r| self.well_estimated(r)) {
                    max_missed.max(self.options.max_missed_3d)
                } else {
                    max_missed
                };
                if t.missed > limit {
                    self.retired.push(t);
                    continue;
                }
            }
            kept.push(t);
        }
        self.tracks = kept;
        for k in births {
            let idx = &groups[k].1;
            let id = self.next_id;
            self.next_id += 1;
            self.tracks.push(Track {
                id,
                edges: Vec::new(),
                visible: false,
                confirmed: false,
                hits: 0,
                missed: 0,
                first_frame: frame,
                last_frame: frame,
                history: Vec::new(),
                predicted: None,
                rims: [None, None],
            });
            let l = self.tracks.len() - 1;
            let edges_k: Vec<&WaferEdge> = idx.iter().map(|&i| &edges[i]).collect();
            self.register(l, &edges_k, frame, t_wc);
            for &i in idx {
                self.edge_tracks[i] = Some(id);
            }
        }
        self.frame += 1;
        let t3 = std::time::Instant::now();
        self.timings = UpdateTimings {
            predict: (t1 - t0).as_secs_f64(),
            associate: (t2 - t1).as_secs_f64(),
            manage: (t3 - t2).as_secs_f64(),
        };
        Ok(())
    }

    /// Builds the point sets of Algorithm 5 and registers them.
    fn register_hierarchical(
        &self,
        edges: &[WaferEdge],
        groups: &[(usize, Vec<usize>)],
        predictions: &[Prediction],
        free_slots: &[Vec<[f64; 2]>],
    ) -> Result<Registration> {
        let m = self.options.max_points_per_segment;
        let mut observed = SegmentPoints::default();
        for (_, idx) in groups {
            let mut pts = Vec::new();
            for &i in idx {
                pts.extend(subsample(&edge_points(&edges[i]), m));
            }
            observed.push_segment(pts);
        }
        let mut predicted = SegmentPoints::default();
        for p in predictions {
            predicted.push_segment(p.points.iter().copied());
        }
        for pts in free_slots {
            predicted.push_segment(pts.iter().copied());
        }
        let tight: Vec<bool> = predictions
            .iter()
            .map(|p| p.tight)
            .chain(free_slots.iter().map(|_| false))
            .collect();
        register_segments_gated(
            &observed,
            &predicted,
            &self.options.registration,
            Some(&tight),
        )
    }

    /// The track registered in this frame whose edges the group's edges lie next to
    /// (mean Sampson distance below `rim_merge_distance`), if any.
    fn merge_target(&self, edges: &[WaferEdge], idx: &[usize]) -> Option<usize> {
        let tol = self.options.rim_merge_distance;
        let mut target = None;
        for &i in idx {
            let pts = subsample(&edge_points(&edges[i]), 32);
            let e = &edges[i].ellipse;
            let mut best: Option<(f64, usize)> = None;
            for (l, t) in self.tracks.iter().enumerate() {
                if !t.visible {
                    continue;
                }
                for te in &t.edges {
                    let f = &te.ellipse;
                    // Cheap pre-check: centres and axes within a few tolerances.
                    let near = (f.cx - e.cx).hypot(f.cy - e.cy) < 4.0 * tol + 0.2 * f.a
                        && (f.a - e.a).abs() < 4.0 * tol + 0.2 * f.a;
                    if !near {
                        continue;
                    }
                    let d = pts
                        .iter()
                        .map(|p| f.sampson_distance(&Vector2::new(p[0], p[1])).abs())
                        .sum::<f64>()
                        / pts.len().max(1) as f64;
                    if d < tol && best.is_none_or(|b| d < b.0) {
                        best = Some((d, l));
                    }
                }
            }
            match (best, target) {
                (None, _) => return None,
                (Some((_, l)), None) => target = Some(l),
                (Some((_, l)), Some(t)) if l != t => return None,
                _ => {}
            }
        }
        target
    }

    /// Updates track `l` with the edges registered to it in `frame`.
    fn register(
        &mut self,
        l: usize,
        edges: &[&WaferEdge],
        frame: usize,
        t_wc: Option<&Isometry3<f64>>,
    ) {
        let opts = self.options.clone();
        let axis = self.axis;
        let t = &mut self.tracks[l];
        if !t.visible {
            t.visible = true;
            t.hits += 1;
            t.missed = 0;
            t.edges.clear();
        }
        t.last_frame = frame;
        if t.hits >= opts.min_hits {
            t.confirmed = true;
        }
        for e in edges {
            t.history.push((frame, (*e).clone()));
            t.edges.push((*e).clone());
        }
        // Rim states: per kind, the edge with the most points of this frame.
        for kind in [RimKind::Upper, RimKind::Lower] {
            let Some(e) = t
                .edges
                .iter()
                .filter(|e| e.kind == kind)
                .max_by_key(|e| e.points.len())
            else {
                continue;
            };
            let slot = &mut t.rims[rim_index(kind)];
            let (prev, mut candidates, mut views, mut bins, old_fit, same_frame) = match slot.take()
            {
                Some(s) if s.frame == frame => (s.prev, s.candidates, s.views, s.bins, s.fit, true),
                Some(s) => (
                    Some((s.frame, s.edge.ellipse)),
                    s.candidates,
                    s.views,
                    s.bins,
                    s.fit,
                    false,
                ),
                None => (
                    None,
                    VecDeque::new(),
                    VecDeque::new(),
                    VecDeque::new(),
                    None,
                    false,
                ),
            };
            let cands = match (t_wc, opts.intrinsics.as_ref()) {
                (Some(pose), Some(k)) => circles_from_ellipse(k, &e.ellipse, opts.wafer_radius)
                    .ok()
                    .map(|c| [c[0].transformed(pose), c[1].transformed(pose)]),
                _ => None,
            };
            if let Some(c) = cands {
                if candidates.len() == opts.circle_window {
                    candidates.pop_front();
                }
                candidates.push_back(c);
            }
            let mut circle = estimate_circle(&candidates, opts.normal_prior.as_ref());
            let mut fit = None;
            if let (true, Some(pose), Some(k)) =
                (opts.multiview_circle, t_wc, opts.intrinsics.as_ref())
            {
                let view = RimView {
                    t_cw: pose.inverse(),
                    points: subsample(&edge_points(e), MULTIVIEW_POINTS),
                };
                // A second registration of this rim in the same frame (merged edge) replaces
                // the frame's view.
                if same_frame && t_wc.is_some() {
                    views.pop_back();
                    if bins.len() > views.len() {
                        bins.pop_back();
                    }
                }
                if views.len() == opts.circle_window {
                    views.pop_front();
                    if bins.len() > views.len() {
                        bins.pop_front();
                    }
                }
                views.push_back(view);
                // Warm start from the previous estimate while it is well constrained, else
                // from the back-projected candidates.
                let init = old_fit
                    .filter(|f| f.center_std() < 10.0 * opts.projection_max_center_std)
                    .map(|f| f.circle)
                    .or(circle);
                if let Some(init) = init {
                    let o = CircleFitOptions {
                        max_iterations: opts.circle_fit_iterations,
                        pixel_sigma: 1.0,
                        huber: 2.0,
                        normal_prior: opts.normal_prior,
                        normal_sigma: opts.normal_prior_sigma,
                        axis_prior: match (axis, opts.stack_axis_sigma) {
                            (Some((p, d)), Some(s)) => Some((p, d, s)),
                            _ => None,
                        },
                    };
                    let init = Circle3 {
                        radius: opts.wafer_radius,
                        ..init
                    };
                    if let Ok(f) = refine_circle(k, views.make_contiguous(), &init, &o) {
                        circle = Some(f.circle);
                        fit = Some(f);
                    }
                }
                // Keep `bins` aligned with `views` (0: no estimate to locate the points on).
                while bins.len() + 1 < views.len() {
                    bins.push_front(0);
                }
                let b = match (fit.as_ref(), views.back()) {
                    (Some(f), Some(v)) => angle_bins(&f.circle, pose, k, &v.points),
                    _ => 0,
                };
                bins.push_back(b);
            }
            *slot = Some(RimState {
                edge: e.clone(),
                frame,
                pose: t_wc.copied(),
                prev,
                candidates,
                circle,
                views,
                fit,
                bins,
            });
        }
    }

    /// The predicted segment of track `t` in `frame` (§4.2).
    fn predict(&self, t: &Track, frame: usize, t_wc: Option<&Isometry3<f64>>) -> Prediction {
        let m = self.options.max_points_per_segment;
        let mut out = Prediction {
            points: Vec::new(),
            ellipse: None,
            tight: t.rims.iter().any(Option::is_some),
        };
        for rim in t.rims.iter().flatten() {
            let gap = frame.saturating_sub(rim.frame).max(1);
            let projected = match (t_wc, self.options.intrinsics.as_ref(), rim.circle, rim.pose) {
                (Some(pose), Some(k), Some(c), _)
                    if self.well_estimated(rim) && rim.bins.iter().any(|&b| b != 0) =>
                {
                    let seen = rim.bins.iter().fold(0, |a, &b| a | b);
                    project_bins(k, pose, &c, seen, m)
                }
                (Some(pose), Some(k), Some(c), Some(old_pose))
                    if gap > 1
                        || self.options.prefer_projection
                        || !has_velocity(rim)
                        || self.well_estimated(rim) =>
                {
                    project_rim(k, pose, &old_pose, &c, &rim.edge, m)
                }
                _ => None,
            };
            out.tight &= projected.is_some() && self.well_estimated(rim);
            let (pts, ell) = match projected {
                Some(p) => p,
                None => {
                    let e = extrapolate(rim, frame);
                    let pts = subsample(&edge_points(&rim.edge), m)
                        .iter()
                        .map(|p| {
                            let q = e
                                .point_at(rim.edge.ellipse.parameter_of(&Vector2::new(p[0], p[1])));
                            [q.x, q.y]
                        })
                        .collect();
                    (pts, Some(e))
                }
            };
            if out.ellipse.is_none() {
                out.ellipse = ell;
            }
            out.points
                .extend(pts.into_iter().filter(|p| self.in_image(p)));
        }
        out
    }

    /// The predicted points of the free carrier slots next to the tracks (see
    /// [`TrackerOptions::slot_pitch`]), one list per slot; empty without `slot_pitch`, a camera
    /// pose or intrinsics.
    ///
    /// A track `l` with a 3D estimate `c_l` (unit axis `a`: the carrier axis if estimated, else
    /// the rim normal) has neighbouring slots at `c_l ± p·a`. A slot is free when no track's
    /// estimate lies within `p/2` of it along the axis (and within a radius across it) and no
    /// free slot was taken for it already. Its predicted points are the track's predicted
    /// points `x̂_j` moved by `π(c_l ± p·a, φ_j) − π(c_l, φ_j)` (eq. 4.1 for both circles), `φ_j`
    /// the rim angle of `x̂_j`'s ray on `c_l`: the relative displacement is accurate even when
    /// a young track's absolute 3D estimate is not.
    fn free_neighbour_slots(
        &self,
        predictions: &[Prediction],
        t_wc: Option<&Isometry3<f64>>,
    ) -> Vec<Vec<[f64; 2]>> {
        let (Some(pitch), Some(pose), Some(k)) = (
            self.options.slot_pitch,
            t_wc,
            self.options.intrinsics.as_ref(),
        ) else {
            return Vec::new();
        };
        let Some(k_inv) = k.try_inverse() else {
            return Vec::new();
        };
        let circles: Vec<Option<Circle3>> = self.tracks.iter().map(Track::circle).collect();
        // Tracks whose 3D estimate is good enough to tell slots apart along the axis.
        let tight: Vec<Vector3<f64>> = self
            .tracks
            .iter()
            .filter_map(|t| {
                t.rims
                    .iter()
                    .flatten()
                    .find(|r| self.well_estimated(r))
                    .and_then(|r| r.circle)
                    .map(|c| c.center)
            })
            .collect();
        let origin = pose.translation.vector;
        let t_cw = pose.inverse();
        let image_of = |x: &Vector3<f64>| {
            let x_c = t_cw * nalgebra::Point3::from(*x);
            project(k, &x_c.coords)
        };
        let mut out = Vec::new();
        let mut tree = None;
        for (l, p) in predictions.iter().enumerate() {
            let Some(c) = circles[l] else { continue };
            if p.points.is_empty() {
                continue;
            }
            let a = match self.axis {
                Some((_, d)) => d,
                None => c.normal,
            };
            for side in [-1.0, 1.0] {
                let centre = c.center + a * (side * pitch);
                let occupied = tight.iter().any(|x| {
                    let d = x - centre;
                    let along = d.dot(&a);
                    along.abs() < 0.5 * pitch && (d - a * along).norm() < c.radius
                });
                if occupied {
                    continue;
                }
                let moved = Circle3 {
                    center: centre,
                    ..c
                };
                // Each moved point with the length of its displacement.
                let pts: Vec<([f64; 2], f64)> = p
                    .points
                    .iter()
                    .filter_map(|q| {
                        let ray = pose.rotation * (k_inv * Vector3::new(q[0], q[1], 1.0));
                        let phi = rim_angle_of_ray(&c, &origin, &ray)?;
                        let d = image_of(&moved.point_at(phi))? - image_of(&c.point_at(phi))?;
                        let v = [q[0] + d.x, q[1] + d.y];
                        (v.iter().all(|x| x.is_finite()) && self.in_image(&v))
                            .then_some((v, d.norm()))
                    })
                    .collect();
                if pts.is_empty() || occupied_in_image(&pts, l, predictions, &mut tree) {
                    continue;
                }
                out.push(pts.into_iter().map(|(v, _)| v).collect());
            }
        }
        out
    }

    /// The carrier axis: mean centre and sign-aligned mean normal of the upper rims (else lower)
    /// of the tracks whose estimate is good enough for the projection prediction; `None` with
    /// fewer than three such tracks or without `stack_axis_sigma`.
    fn stack_axis(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        self.options.stack_axis_sigma?;
        let mut centre = Vector3::zeros();
        let mut normal = Vector3::zeros();
        let mut count = 0usize;
        for t in &self.tracks {
            let Some(f) = t
                .rims
                .iter()
                .flatten()
                .find(|r| self.well_estimated(r))
                .and_then(|r| r.fit)
            else {
                continue;
            };
            let n = f.circle.normal;
            normal += if count > 0 && n.dot(&normal) < 0.0 {
                -n
            } else {
                n
            };
            centre += f.circle.center;
            count += 1;
        }
        if count < 3 {
            return None;
        }
        let dir = normal.try_normalize(1e-12)?;
        Some((centre / count as f64, dir))
    }

    /// Whether the rim's multi-view 3D estimate is good enough to predict it by projection.
    fn well_estimated(&self, rim: &RimState) -> bool {
        rim.fit.is_some_and(|f| {
            f.center_std() < self.options.projection_max_center_std
                && f.rms < self.options.projection_max_rms
        })
    }

    fn in_image(&self, p: &[f64; 2]) -> bool {
        match self.options.image_size {
            Some((w, h)) => p[0] >= -0.5 && p[1] >= -0.5 && p[0] <= w - 0.5 && p[1] <= h - 0.5,
            None => true,
        }
    }
}

/// An edge's points as `[u, v]`; an edge without points stands for its whole ellipse
/// (64 samples).
fn edge_points(edge: &WaferEdge) -> Vec<[f64; 2]> {
    if edge.points.is_empty() {
        let e = &edge.ellipse;
        (0..64)
            .map(|i| {
                let p = e.point_at(i as f64 * std::f64::consts::TAU / 64.0);
                [p.x, p.y]
            })
            .collect()
    } else {
        edge.points.iter().map(|p| [p.x, p.y]).collect()
    }
}

/// At most `m` evenly spaced elements (all of them if there are fewer).
fn subsample(points: &[[f64; 2]], m: usize) -> Vec<[f64; 2]> {
    if points.len() <= m {
        return points.to_vec();
    }
    let step = points.len() as f64 / m as f64;
    (0..m)
        .map(|i| points[((i as f64 * step) as usize).min(points.len() - 1)])
        .collect()
}

/// Rejects edges with non-finite points or an invalid ellipse.
fn validate_edges(edges: &[WaferEdge]) -> Result<()> {
    for (i, e) in edges.iter().enumerate() {
        let el = &e.ellipse;
        let params = [el.cx, el.cy, el.a, el.b, el.theta];
        if let Some(v) = params.iter().find(|v| !v.is_finite()) {
            return Err(DetectError::NonFinite {
                what: "edge ellipse",
                index: i,
                value: *v,
            });
        }
        if !(el.b > 0.0 && el.a >= el.b) {
            return Err(DetectError::InvalidParameter {
                what: "edge ellipse semi-minor axis b",
                value: el.b,
                reason: "an edge ellipse needs a >= b > 0",
            });
        }
        if let Some(v) = e
            .points
            .iter()
            .flat_map(|p| [p.x, p.y])
            .find(|v| !v.is_finite())
        {
            return Err(DetectError::NonFinite {
                what: "edge points",
                index: i,
                value: v,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
