//! Wafer rims: detection of the elliptic edge segments of wafers in an image, pairing of the
//! upper and lower rim of one wafer, rejection of reflections (seed 000_3b1454b2b2194811.txt
//! ch. 3.1–3.2, 3.5).

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, Point2};

/// Which surface of a wafer an elliptic edge segment belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RimKind {
    /// The rim of the upper surface of the wafer.
    Upper,
    /// The rim of the lower surface of the wafer.
    Lower,
}

impl RimKind {
    /// `"upper"` or `"lower"`.
    pub fn as_str(self) -> &'static str {
        match self {
            RimKind::Upper => "upper",
            RimKind::Lower => "lower",
        }
    }
}

/// One detected elliptic edge segment of a wafer rim.
#[derive(Debug, Clone, PartialEq)]
pub struct WaferEdge {
    /// The fitted ellipse (pixels).
    pub ellipse: Ellipse,
    /// The edge points that support it (pixels, (u, v)).
    pub points: Vec<Point2<f64>>,
    /// Mean orthogonal distance of the points to the ellipse (pixels).
    pub residual: f64,
    /// Covariance of (cx, cy, a, b, theta), when the fit provides it.
    pub covariance: Option<Matrix5<f64>>,
    /// Upper or lower rim.
    pub kind: RimKind,
    /// Groups the two rims of one wafer within one image (0, 1, … in image order).
    pub wafer_id: usize,
}

use crate::assembly::{AssemblyParams, Segment, merge_arcs, merge_segments};
use crate::edges::{Arc, ArcParams, CannyParams, GrayView, LinkParams, Pixel, detect_arcs};
use crate::ellipse::EllipseFit;
use crate::{DetectError, Result};
use nalgebra::{DMatrix, Vector2};
use rayon::prelude::*;

/// Optional prior on the wafer rims in the image (for example from the expected wafer radius
/// and a rough camera pose): fitted ellipses outside these ranges are rejected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaferPrior {
    /// Accepted range of the semi-major axis (pixels).
    pub semi_major: (f64, f64),
    /// Accepted range of the semi-minor axis (pixels).
    pub semi_minor: (f64, f64),
}

/// Parameters of [`detect_wafers`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectParams {
    /// Edge detection.
    pub canny: CannyParams,
    /// Edge linking.
    pub link: LinkParams,
    /// Arc splitting and screening.
    pub arcs: ArcParams,
    /// Algorithms 1–2.
    pub assembly: AssemblyParams,
    /// Image direction (need not be unit) in which the wafer's upper surface lies relative to
    /// its lower surface, i.e. the projected wafer normal: `(0, −1)` (up in the image) for an
    /// upright camera. It decides which rim is "upper".
    pub up: [f64; 2],
    /// Largest distance (pixels) between the centres of the upper and lower rim of one wafer.
    /// Default 10.
    pub max_rim_offset: f64,
    /// Largest relative difference of the semi-axes of the two rims of one wafer (plus 1 px).
    /// The gate applies before the pair's shape-sharing and joint refits, to fits of which one
    /// may rest on its front arc only: there `b` (and `a`) are off by up to 5–8 % (a lower rim
    /// of a wafer seen from above fits its own front arc alone), and a tighter gate leaves
    /// exactly those rims unpaired, with their off fit, instead of refitted. The two rims of one
    /// wafer differ by the wafer's thickness (under 1 px or 4 % in `b` on the benchmark scenes); the rims
    /// of wafers one slot apart are kept apart by `max_rim_offset`. Default 0.10.
    pub max_rim_axis_difference: f64,
    /// A segment whose edge contrast is under this fraction of the strongest contrast among
    /// the rims of about the same size (semi-major within 10 %) inside whose ellipse it lies
    /// (most of its points: seen on that wafer's face) is taken for a reflection of a
    /// neighbouring wafer in the mirror-like face and rejected. 0 disables. Default 0.45.
    pub min_contrast_ratio: f64,
    /// Smallest fraction of the fitted ellipse's perimeter covered by the segment's arcs (the
    /// validation stage of §3.2: a fit supported by too little of its ellipse is a chance
    /// alignment, e.g. of two straight-ish clutter arcs). Default 0.08: a rim whose fit its
    /// points leave undetermined is rejected on the fit's own covariance
    /// ([`DetectParams::max_centre_sigma`], [`DetectParams::max_relative_sigma_b`]), so the
    /// coverage only needs to keep out what no fit could confirm. At 0.15 (before those tests)
    /// it dropped the rims of disturbance wafers high above the camera, seen only as the two
    /// arcs at the tips of their back arc, joined across the image top (0.09–0.14 of the
    /// perimeter; on the wafer benchmark 5 rims of seed 3 and 7 of seed 4, no detection
    /// added that matches no rim).
    pub min_coverage: f64,
    /// Points of the lower rim of a wafer seen from above (the far edge of the side band) whose
    /// distance to the upper rim is under this fraction of the widest distance are dropped and
    /// the rim refitted: where the bright side face between the rims narrows toward the ends of
    /// the front arc, the blurred edges of the two rims push each other apart and bias the fit.
    /// The near-edge rim is left whole (its band-end points pin its centre and `a`; see
    /// `pair.rs`). 0 disables. Default 0.5.
    pub min_rim_separation: f64,
    /// An arc of an assembled segment whose median distance (pixels) to the segment's ellipse
    /// exceeds this is dropped and the rest refitted (worst arc first). The two rims of a wafer
    /// are near-copies of one ellipse a few pixels apart, so the assembly can join the front
    /// arc of one rim with a back-arc silhouette of the other into an ellipse whose mean
    /// residual still passes. 0 disables. Default 0.6.
    pub max_arc_deviation: f64,
    /// Re-locates the rim points with the two-edge band model of the rim profile (see
    /// [`refine_band_edges`]) before the final fit. Default true.
    pub band_refinement: bool,
    /// Refits the less covered rim of a pair with the semi-major axis and orientation of the
    /// better covered one (see [`share_shape`]). Default true.
    pub share_rim_shape: bool,
    /// With `share_rim_shape`, also holds the refitted rim's centre on the line through the
    /// other rim's centre along `up` (see [`share_shape`]). Default true.
    pub share_rim_centre: bool,
    /// Leave-one-out check of assembled segments of three or more arcs (see
    /// [`drop_outlier_arcs`]): an arc is dropped when its median distance to the fit of the
    /// other arcs exceeds `max_arc_deviation` and including it raises the mean residual by more
    /// than this factor. 0 disables. Default 1.5.
    pub max_arc_residual_ratio: f64,
    /// Refits the less covered rim of a pair with the joint band model of both rims (see
    /// [`joint`]: the far edge of the side band on the profiles of the well-seen rim, with one
    /// blur and one smooth band level for all profiles), after [`share_shape`]. Default true.
    pub joint_band_fit: bool,
    /// Seeks the missing rim of a wafer of which only one rim was found, as the far edge of the
    /// side band along the found rim's front arc (see [`seek`]). Default true.
    pub seek_missing_partner: bool,
    /// A rim left without a partner by the pairing is kept only when its mean residual (after
    /// the band refinement) is under this (pixels). A rim edge is a clean step or band edge
    /// (residual 0.03–0.12 px on the benchmark scenes); assemblies of slot-tooth clutter or of
    /// arcs from different rims fit at 0.15–0.25 px, under the assembly's threshold, and have no
    /// second rim to confirm them, whereas a wafer's rim usually has. `f64::INFINITY` disables.
    /// Default 0.15.
    pub max_unpaired_residual: f64,
    /// Joins two arcs left over by the assembly into one rim when the part of the ellipse
    /// between them lies outside the image (see [`find_cut`]: the side arcs of a rim whose front
    /// arc runs out of the image top, farther apart than the assembly's `max_gap`). Default true.
    pub join_border_cut_arcs: bool,
    /// With [`DetectParams::join_border_cut_arcs`], a border pair may also take an arc of one of
    /// the assembly's two-arc segments when it fits better than that segment (which is then
    /// dissolved; see [`find_cut::border_cut_pairs`]). Default true.
    pub border_pairs_take_arcs: bool,
    /// A dim candidate counts as a reflection (see [`DetectParams::min_contrast_ratio`]) only
    /// when it lies inside the brighter rim, on whose face it would be mirrored; false compares
    /// it with every brighter rim of about its size (the earlier, wider rule). Default true.
    pub reflection_inside_rim: bool,
    /// A rim is reported only when its fit determines the minor axis to a standard deviation
    /// (from the fit's covariance, [`WaferEdge::covariance`]) of at most this fraction of `b`.
    /// A thin rim (`b` 5–10 px) seen along its front arc only is a half ellipse whose `a`, `b`
    /// and centre trade off against each other: there a systematic shift of its edge points by
    /// 0.1–0.3 px (the two edges of the 2–4 px side band push each other's gradient maxima
    /// apart, and a slot tooth joins the rim at its tips) moves `b` by 1–5 %, and the fit's own
    /// `σ_b` is then large too. Measured with the renderer's truth on the wafer benchmark (210
    /// images, seeds 3 and 4, with [`ArcParams::restart_turn_at_cuts`]): of the detections with
    /// `σ_b > 0.5 % b`, 13 and 5 were near-misses (the right rim, `b` 1–5 % off), 8 and 11
    /// wrong (clutter: all wrong detections of both seeds; 7 and 9 of them have `σ_b` above
    /// 1 %) and 9 and 2 hits (mostly thin disturbance rims too). 0.005 asks `2σ_b` to be within
    /// 1 % of `b`. `f64::INFINITY` disables. Default 0.005.
    pub max_relative_sigma_b: f64,
    /// A rim whose centre is determined by its fit to a standard deviation
    /// `√(σ²_cx + σ²_cy)` (from the fit's covariance) over this many pixels is rejected
    /// (see [`drop_uncertain`]). A rim edge seen along its front arc at 0.03–0.12 px edge noise
    /// fixes its centre to 0.02–0.5 px; the covariance exceeds that many times over when the
    /// points do not constrain an ellipse — a short or nearly straight arc (slot-tooth edges,
    /// a rim's silhouette without its band edge, arcs of two rims joined) whose ellipse slides
    /// along its own curve. Such a fit is a guess, not a measurement of a rim to a pixel.
    /// Measured with the renderer's truth on the wafer benchmark (210 images each of seeds 3
    /// and 4, before [`ArcParams::restart_turn_at_cuts`] was on): the largest centre σ of a
    /// detection within 1 px / 1 % of a rim was 0.48 px; 22 of the 23 detections within 3 px /
    /// 5 % of no rim had σ over 1 px (σ 1.2–440 px). `f64::INFINITY` disables. Default 1.0.
    pub max_centre_sigma: f64,
    /// With [`DetectParams::rim_offset`] given, refits both rims of a thin wafer (`b` under
    /// 9 px, 10 px seen from above; major axis near horizontal, `up` near −y) by one intensity
    /// fit of the image columns across its face and side band, the two rims tied by the rim
    /// offset prior (see [`thin`]). An accepted fit replaces the pair's edge-point fits.
    /// Default true (no effect without `rim_offset`).
    pub thin_band_fit: bool,
    /// With [`DetectParams::rim_offset`] given, refits both rims of a wider level wafer, seen
    /// from above or below (`b` from 10 px seen from above, from 9 px below; major axis near
    /// horizontal, `up` near −y), by one intensity fit of the image columns across its side
    /// band, the two rims tied by the rim offset prior (see [`thin`], `Model::Band`). An
    /// accepted fit replaces the pair's edge-point fits. Default true (no effect without
    /// `rim_offset`).
    pub front_band_fit: bool,
    /// With [`DetectParams::rim_offset`] given and [`DetectParams::thin_band_fit`] on, also
    /// searches the wafers seen almost edge-on (`b` of 1–4 px), whose rims no edge-point fit
    /// finds: long bright bars across the image, measured by the thin column fit from a seed
    /// of the bar's centre line and ends (see [`sliver`]). Default true.
    pub level_band_search: bool,
    /// How the image forms an edge's profile, for the column fits of
    /// [`DetectParams::thin_band_fit`] and [`DetectParams::front_band_fit`]:
    /// [`EdgeProfile::Optical`] (a camera: the optics blur before the pixels integrate; the
    /// default) or [`EdgeProfile::PixelGrid`] (the pixels integrate first and a Gaussian
    /// sampled on the pixel grid blurs after: a digital blur, as the renderer of
    /// `autoteach_geometry::render` forms the simulator's images).
    pub edge_profile: EdgeProfile,
    /// Optional size prior.
    pub prior: Option<WaferPrior>,
    /// Optional prior on the offset between the images of a wafer's two rims, from the wafer's
    /// thickness-to-radius ratio and the camera's focal length (see [`RimOffsetPrior`]): used by
    /// the joint band fit ([`joint`]) of the lower rim of a wafer seen from above. Default
    /// `None` (no prior).
    pub rim_offset: Option<RimOffsetPrior>,
}

impl Default for DetectParams {
    fn default() -> Self {
        Self {
            canny: CannyParams::default(),
            link: LinkParams::default(),
            arcs: ArcParams::default(),
            assembly: AssemblyParams::default(),
            up: [0.0, -1.0],
            max_rim_offset: 10.0,
            max_rim_axis_difference: 0.10,
            min_contrast_ratio: 0.45,
            min_coverage: 0.08,
            min_rim_separation: 0.5,
            max_arc_deviation: 0.6,
            band_refinement: true,
            share_rim_shape: true,
            share_rim_centre: true,
            max_arc_residual_ratio: 1.5,
            joint_band_fit: true,
            seek_missing_partner: true,
            max_unpaired_residual: 0.15,
            join_border_cut_arcs: true,
            border_pairs_take_arcs: true,
            reflection_inside_rim: true,
            max_relative_sigma_b: 0.005,
            max_centre_sigma: 1.0,
            thin_band_fit: true,
            front_band_fit: true,
            level_band_search: true,
            edge_profile: EdgeProfile::Optical,
            prior: None,
            rim_offset: None,
        }
    }
}

impl DetectParams {
    fn validate(&self) -> Result<Vector2<f64>> {
        let up = Vector2::new(self.up[0], self.up[1]);
        let n = up.norm();
        require(
            n > 0.0 && n.is_finite(),
            "up",
            n,
            "must be a finite non-zero direction",
        )?;
        for (what, value) in [
            ("max_rim_offset", self.max_rim_offset),
            ("max_rim_axis_difference", self.max_rim_axis_difference),
        ] {
            require(
                value > 0.0 && value.is_finite(),
                what,
                value,
                "must be positive and finite",
            )?;
        }
        require(
            self.min_coverage >= 0.0 && self.min_coverage <= 1.0,
            "min_coverage",
            self.min_coverage,
            "must be in [0, 1]",
        )?;
        require(
            self.min_rim_separation >= 0.0 && self.min_rim_separation < 1.0,
            "min_rim_separation",
            self.min_rim_separation,
            "must be in [0, 1)",
        )?;
        require(
            self.max_arc_deviation >= 0.0 && self.max_arc_deviation.is_finite(),
            "max_arc_deviation",
            self.max_arc_deviation,
            "must be finite and >= 0",
        )?;
        require(
            self.max_arc_residual_ratio >= 0.0 && self.max_arc_residual_ratio.is_finite(),
            "max_arc_residual_ratio",
            self.max_arc_residual_ratio,
            "must be finite and >= 0",
        )?;
        require(
            self.max_unpaired_residual > 0.0 && !self.max_unpaired_residual.is_nan(),
            "max_unpaired_residual",
            self.max_unpaired_residual,
            "must be positive (infinity disables)",
        )?;
        require(
            self.max_relative_sigma_b > 0.0 && !self.max_relative_sigma_b.is_nan(),
            "max_relative_sigma_b",
            self.max_relative_sigma_b,
            "must be positive (infinity disables)",
        )?;
        require(
            self.max_centre_sigma > 0.0 && !self.max_centre_sigma.is_nan(),
            "max_centre_sigma",
            self.max_centre_sigma,
            "must be positive (infinity disables)",
        )?;
        require(
            self.min_contrast_ratio >= 0.0 && self.min_contrast_ratio <= 1.0,
            "min_contrast_ratio",
            self.min_contrast_ratio,
            "must be in [0, 1]",
        )?;
        if let Some(p) = &self.rim_offset {
            p.validate()?;
        }
        if let Some(p) = &self.prior {
            for (what, (lo, hi)) in [
                ("prior semi_major", p.semi_major),
                ("prior semi_minor", p.semi_minor),
            ] {
                require(
                    lo >= 0.0 && hi >= lo && hi.is_finite(),
                    what,
                    lo,
                    "must be a range 0 <= low <= high < inf",
                )?;
            }
        }
        Ok(up / n)
    }
}

/// `Ok` when `ok`, else [`DetectError::InvalidParameter`] naming the parameter, its value and why.
fn require(ok: bool, what: &'static str, value: f64, reason: &'static str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(DetectError::InvalidParameter {
            what,
            value,
            reason,
        })
    }
}

/// A validated rim candidate.
#[derive(Clone)]
struct Candidate {
    seg: Segment,
    kind: RimKind,
    contrast: f64,
}

/// Detects the elliptic edge segments of wafer rims in a grayscale image
/// (000_3b1454b2b2194811.txt ch. 3.2, Fig. 3.3, validated in ch. 3.5).
///
/// 1. Arcs: [`crate::edges::detect_arcs`] (Canny with sub-pixel edgels, linking, splitting,
///    short/straight/curvature rejection, quadrant classes).
/// 2. Elliptic segments: [`crate::assembly::assemble`] (combination rule, Algorithms 1–2),
///    plus pairs of left-over arcs of a rim cut by the image border ([`find_cut`]).
/// 3. Validation: each segment is refitted (orthogonal-distance LM, with covariance) and
///    checked against the residual threshold and the optional [`WaferPrior`].
/// 4. Rims (§3.2, Fig. 3.2: "the bright boundary of the wafer forms two edges: an upper one
///    corresponding to the upper surface and lower one corresponding to the lower surface"):
///    the bright side face lies below the upper rim and above the lower rim, so a segment whose
///    gradient (dark → bright) points against `up` is an upper rim, otherwise a lower rim.
///    Reflections of neighbouring wafers in the mirror-like faces lie inside the mirroring
///    wafer's rim with a fraction of its contrast and are rejected (`min_contrast_ratio`). Upper and lower rims are paired by a
///    minimum-cost assignment (centre offset + axis differences, the lower rim's centre
///    displaced against `up`, within `max_rim_offset` and `max_rim_axis_difference`); the two
///    rims of a pair share a `wafer_id`, unpaired rims get their own. Wafer ids are numbered in
///    image order along `up` (topmost first), upper before lower.
///
/// Returns an empty list when nothing is found (blank, black or saturated images).
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters (image errors are caught by
/// [`GrayView::new`]).
pub fn detect_wafers<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &DetectParams,
) -> Result<Vec<WaferEdge>> {
    // The stages' parallel loops (Canny's row blocks, the assembly's pair fits, the band
    // profiles of each rim: a dozen or more per image) each hand their work to rayon's pool
    // when called from outside it, and the calling thread sleeps until the pool is done: two
    // thread wake-ups per loop. `rayon::scope` moves the whole detection onto a worker of the
    // pool once, so the loops run there directly (inline with one thread, work-stealing with
    // more). The same work in the same order: the result does not change.
    rayon::scope(|_| detect_wafers_on_pool(image, params))
}

/// [`detect_wafers`], run on a worker of rayon's pool.
fn detect_wafers_on_pool<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &DetectParams,
) -> Result<Vec<WaferEdge>> {
    let up = params.validate()?;
    let arcs = detect_arcs(image, &params.canny, &params.link, &params.arcs)?;
    let (s0, v0) = merge_arcs(&arcs, &params.assembly)?;
    let (mut segments, rest) = merge_segments(&arcs, s0, v0, &params.assembly)?;
    if params.join_border_cut_arcs {
        let offered: &[Segment] = if params.border_pairs_take_arcs {
            &segments
        } else {
            &[]
        };
        let (cut, dissolved) = find_cut::border_cut_pairs(
            &arcs,
            &rest,
            offered,
            image.width(),
            image.height(),
            &params.assembly,
        );
        let mut k = 0;
        segments.retain(|_| {
            k += 1;
            dissolved.binary_search(&(k - 1)).is_err()
        });
        segments.extend(cut);
    }
    let mut candidates = Vec::new();
    for mut seg in segments {
        drop_inconsistent_arcs(&mut seg, &arcs, params);
        drop_outlier_arcs(&mut seg, &arcs, params);
        // The assembly's fit of the union is the final estimate (with its covariance).
        let fit = seg.fit.clone();
        if !(fit.residual_mean < params.assembly.residual_threshold) {
            continue;
        }
        if let Some(p) = &params.prior {
            let e = &fit.ellipse;
            if e.a < p.semi_major.0
                || e.a > p.semi_major.1
                || e.b < p.semi_minor.0
                || e.b > p.semi_minor.1
            {
                continue;
            }
        }
        let covered: f64 = seg
            .arcs
            .iter()
            .map(|&k| {
                arcs[k]
                    .points
                    .windows(2)
                    .map(|w| (w[1] - w[0]).norm())
                    .sum::<f64>()
            })
            .sum();
        if !(covered >= params.min_coverage * fit.ellipse.perimeter()) {
            continue;
        }
        let mut s = 0.0;
        let mut contrast = 0.0;
        let mut count = 0usize;
        for &k in &seg.arcs {
            let arc = &arcs[k];
            s += arc.normals.iter().map(|n| -n.dot(&up)).sum::<f64>();
            contrast += arc.contrast * arc.points.len() as f64;
            count += arc.points.len();
        }
        let kind = if s > 0.0 {
            RimKind::Upper
        } else {
            RimKind::Lower
        };
        candidates.push(Candidate {
            seg,
            kind,
            contrast: contrast / count.max(1) as f64,
        });
    }
    reject_reflections(
        &mut candidates,
        params.min_contrast_ratio,
        params.reflection_inside_rim,
    );
    if params.band_refinement {
        for c in &mut candidates {
            refine_band_edges(image, &mut c.seg, params.assembly.residual_threshold);
        }
    }
    let edges = pair_rims(image, candidates, up, params)?;
    let mut edges = drop_unconfirmed(edges, params.max_unpaired_residual);
    // The column fits run before the uncertainty screens: the edge-point fits of thin pairs,
    // and of some wider ones, are too uncertain to pass them, and the column fit is what
    // measures them.
    if let Some(prior) = &params.rim_offset {
        let mut noise = None;
        for (on, model) in [
            (params.thin_band_fit, thin::Model::Thin),
            (params.front_band_fit, thin::Model::Band),
        ] {
            if on {
                edges = thin::refit_level_wafers(
                    image,
                    edges,
                    up,
                    prior,
                    model,
                    params.edge_profile,
                    &mut noise,
                );
            }
        }
        if params.thin_band_fit && params.level_band_search {
            // The bars are matched against the rims that pass the uncertainty screens: an
            // edge-point fit of a wafer seen edge-on (a guess along its straight band) does
            // not explain its bar.
            edges = drop_uncertain(edges, params);
            let found =
                sliver::find_level_bands(image, &edges, up, prior, params.edge_profile, &mut noise);
            if !found.is_empty() {
                edges.extend(found);
                edges = in_image_order(edges, up);
            }
        }
    }
    let edges = drop_uncertain(edges, params);
    Ok(edges)
}

/// `edges` with their wafers in image order along `up` (topmost first, by the first rim of
/// each wafer, as [`pair_rims`] numbers them), each wafer's rims in their order, and the wafer
/// ids renumbered 0, 1, … in that order.
fn in_image_order(edges: Vec<WaferEdge>, up: Vector2<f64>) -> Vec<WaferEdge> {
    let mut groups: Vec<Vec<WaferEdge>> = Vec::new();
    for e in edges {
        match groups.iter_mut().find(|g| g[0].wafer_id == e.wafer_id) {
            Some(g) => g.push(e),
            None => groups.push(vec![e]),
        }
    }
    let height = |g: &Vec<WaferEdge>| -(g[0].ellipse.cx * up.x + g[0].ellipse.cy * up.y);
    groups.sort_by(|x, y| height(x).total_cmp(&height(y)));
    groups
        .into_iter()
        .enumerate()
        .flat_map(|(id, g)| {
            g.into_iter().map(move |mut e| {
                e.wafer_id = id;
                e
            })
        })
        .collect()
}

/// Standard deviations of the centre `√(σ²_cx + σ²_cy)` and of the minor axis `σ_b` (pixels)
/// of `e` from its fit's covariance; `None` without a covariance. A negative or non-finite
/// variance (a fit that does not determine the parameter) gives `+∞`.
fn centre_and_minor_sigma(e: &WaferEdge) -> Option<(f64, f64)> {
    let sd = |v: f64| {
        if v >= 0.0 && v.is_finite() {
            v.sqrt()
        } else {
            f64::INFINITY
        }
    };
    e.covariance
        .map(|c| (sd(c[(0, 0)] + c[(1, 1)]), sd(c[(3, 3)])))
}

/// Drops the rims whose fit leaves the rim undetermined: a centre standard deviation over
/// [`DetectParams::max_centre_sigma`], or a minor-axis standard deviation above
/// [`DetectParams::max_relative_sigma_b`] × `b` (both from the fit's covariance,
/// [`centre_and_minor_sigma`]). A rim without a covariance is kept (nothing is known against
/// it). The wafers are numbered again consecutively in their order; a rim whose partner is
/// dropped keeps its place (it was confirmed by the pairing).
fn drop_uncertain(edges: Vec<WaferEdge>, params: &DetectParams) -> Vec<WaferEdge> {
    let mut ids = std::collections::HashMap::<usize, usize>::new();
    let mut out = Vec::with_capacity(edges.len());
    for mut e in edges {
        let uncertain = centre_and_minor_sigma(&e).is_some_and(|(centre, minor)| {
            !(centre <= params.max_centre_sigma)
                || !(minor <= params.max_relative_sigma_b * e.ellipse.b)
        });
        if uncertain {
            continue;
        }
        let next = ids.len();
        e.wafer_id = *ids.entry(e.wafer_id).or_insert(next);
        out.push(e);
    }
    out
}

/// Drops the rims that are alone in their wafer (no partner rim) and whose mean residual is not
/// under `max_residual` (see [`DetectParams::max_unpaired_residual`]), and numbers the remaining
/// wafers again consecutively in their order (the image order of [`pair_rims`]).
fn drop_unconfirmed(edges: Vec<WaferEdge>, max_residual: f64) -> Vec<WaferEdge> {
    let mut count = std::collections::HashMap::<usize, usize>::new();
    for e in &edges {
        *count.entry(e.wafer_id).or_default() += 1;
    }
    let mut ids = std::collections::HashMap::<usize, usize>::new();
    let mut out = Vec::with_capacity(edges.len());
    for mut e in edges {
        if count.get(&e.wafer_id) == Some(&1) && !(e.residual < max_residual) {
            continue;
        }
        let next = ids.len();
        e.wafer_id = *ids.entry(e.wafer_id).or_insert(next);
        out.push(e);
    }
    out
}

/// Fraction of `points` inside `e` (0 for no points).
fn inside_fraction(e: &Ellipse, points: &[Vector2<f64>]) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    points.iter().filter(|p| e.contains(p)).count() as f64 / points.len() as f64
}

/// Drops candidates whose contrast is under `ratio` × the strongest contrast among the
/// candidates with a semi-major axis within 10 % on whose face they are seen: a reflection of a
/// neighbouring wafer's rim is mirrored in a wafer's face, so it lies inside that wafer's rim
/// ellipse (most of its points: [`inside_fraction`] over one half). A dim rim beside a bright
/// one is not a reflection of it (a flat target's lower rim, the far edge of a bright side band
/// against a bright carrier floor, has under half the contrast of a disturbance rim higher up
/// the image whose `a` is within 10 %). Without `inside_only`, every brighter candidate of
/// about the same size counts.
fn reject_reflections(candidates: &mut Vec<Candidate>, ratio: f64, inside_only: bool) {
    if ratio <= 0.0 {
        return;
    }
    // (A candidate is never `ratio` ≤ 1 times brighter than itself.)
    let keep: Vec<bool> = candidates
        .iter()
        .map(|c| {
            let a = c.seg.fit.ellipse.a;
            !candidates.iter().any(|o| {
                o.contrast * ratio > c.contrast
                    && (o.seg.fit.ellipse.a - a).abs() <= 0.1 * a
                    && (!inside_only || inside_fraction(&o.seg.fit.ellipse, &c.seg.points) > 0.5)
            })
        })
        .collect();
    let mut k = 0;
    candidates.retain(|_| {
        k += 1;
        keep[k - 1]
    });
}

mod band;
mod find_cut;
mod joint;
mod joint_refit;
mod pair;
mod refine;
mod rim_prior;
mod rim_shared;
mod seek;
mod sliver;
mod thin;
mod validate;

use pair::pair_rims;
pub use refine::refine_band_edges;
pub use rim_prior::{RIM_OFFSET_RELATIVE_SIGMA, RimMap, RimOffsetPrior};
pub use thin::EdgeProfile;
use validate::{drop_inconsistent_arcs, drop_outlier_arcs, median};

#[cfg(test)]
mod tests;
