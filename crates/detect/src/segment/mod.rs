//! Coloured point clouds: camera–lidar co-registration and graph segmentation by colour and
//! surface normals (seed 004_815695db12a6b16c.txt ch. 4, eq. (4.1)–(4.5), Algorithm 4.1).
//!
//! The pipeline of Algorithm 4.1, one stage per file:
//! - [`coregister`]: colour lidar points from an image (eq. (4.1)) with a z-buffer;
//! - [`graph`]: the scan-topology mesh (8-neighbours in the previous, current and next scan
//!   line, edges cut above a length) or a k-NN graph for unorganised clouds;
//! - [`normals`]: local PCA over graph neighbours, oriented to the viewpoint;
//! - [`felzenszwalb`]: counting sort on the colour weight (eq. (4.4)), union–find, the colour
//!   and normal thresholds (eq. (4.3), (4.5)) and the minimum segment size;
//! - [`scene`]: a tilting-scanner and camera simulator with ground-truth labels.
//!
//! [`segment_cloud`] runs graph → normals → segmentation.
//!
//! ```
//! use autoteach_detect::segment::{segment_cloud, GraphKind, SegmentParams};
//! // Two flat patches side by side on a 10 × 20 scan grid: red on the left, blue on the right.
//! let (lines, beams) = (10, 20);
//! let mut points = Vec::new();
//! let mut colors = Vec::new();
//! for l in 0..lines {
//!     for b in 0..beams {
//!         points.push([1.0, b as f64 * 0.02, l as f64 * 0.02]);
//!         colors.push(if b < 10 { [200, 30, 30] } else { [30, 30, 200] });
//!     }
//! }
//! let params = SegmentParams { graph: GraphKind::Scan { lines, beams }, ..SegmentParams::default() };
//! let params = SegmentParams { fh: autoteach_detect::segment::FhParams { min_size: 10, ..params.fh }, ..params };
//! let out = segment_cloud(&points, &colors, None, &params)?;
//! assert_eq!(out.num_segments, 2);
//! assert_ne!(out.labels[0], out.labels[beams - 1]);
//! # Ok::<(), autoteach_detect::DetectError>(())
//! ```

pub mod coregister;
pub mod counting_sort;
pub mod felzenszwalb;
pub mod graph;
pub mod normals;
pub mod scene;
#[cfg(test)]
mod tests;
pub mod union_find;

pub use coregister::{ColorizeParams, Colorized, PointStatus, RgbImage, colorize};
pub use felzenszwalb::{Criteria, FhParams, Segmentation, segment_graph};
pub use graph::{Graph, knn_graph, scan_graph};
pub use normals::estimate_normals;

use crate::{DetectError, Result};

/// Label of a missing point (NaN row of an organised cloud).
pub const UNLABELLED: u32 = u32::MAX;

/// Which graph joins the points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraphKind {
    /// The scan-topology mesh of an organised `lines × beams` cloud (NaN rows: missing).
    Scan {
        /// Scan lines.
        lines: usize,
        /// Beams per line.
        beams: usize,
    },
    /// The k-nearest-neighbour graph of an unorganised cloud.
    Knn {
        /// Neighbours per point.
        k: usize,
    },
}

/// Everything [`segment_cloud`] needs besides the cloud.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentParams {
    /// Segmentation constants and criteria.
    pub fh: FhParams,
    /// Longest edge kept (metres; Table 4.1 "Edge cut", 0.25 m).
    pub edge_cut: f64,
    /// The graph.
    pub graph: GraphKind,
    /// Where the sensor was (normals point towards it), in the cloud's frame.
    pub viewpoint: [f64; 3],
}

impl Default for SegmentParams {
    /// Table 4.1 (Fig. 4.4e): edge cut 0.25 m, K_rgb 9000, K_norm 10, minsize 100; a k-NN
    /// graph with k = 8 (the mesh's neighbour count); viewpoint at the origin.
    fn default() -> Self {
        Self {
            fh: FhParams::default(),
            edge_cut: 0.25,
            graph: GraphKind::Knn { k: 8 },
            viewpoint: [0.0; 3],
        }
    }
}

/// The result of [`segment_cloud`].
#[derive(Debug, Clone, PartialEq)]
pub struct CloudSegmentation {
    /// Segment of every point, `0..num_segments` numbered by first point; [`UNLABELLED`] for
    /// missing points.
    pub labels: Vec<u32>,
    /// Number of segments.
    pub num_segments: usize,
    /// The unit normals used (estimated or given); zero for missing points.
    pub normals: Vec<[f64; 3]>,
    /// Whether each normal was determined by its neighbourhood (false: the viewing direction
    /// stands in, see [`normals::estimate_normals`]).
    pub normal_ok: Vec<bool>,
    /// Edges in the graph.
    pub num_edges: usize,
}

fn check_normals(given: &[[f64; 3]], points: &[[f64; 3]]) -> Result<Vec<[f64; 3]>> {
    if given.len() != points.len() {
        return Err(DetectError::WrongLength {
            what: "normals",
            got: given.len(),
            expected: points.len(),
        });
    }
    let mut out = Vec::with_capacity(given.len());
    for (i, (n, p)) in given.iter().zip(points).enumerate() {
        if p.iter().any(|v| v.is_nan()) {
            out.push([0.0; 3]);
            continue;
        }
        if let Some(&value) = n.iter().find(|v| !v.is_finite()) {
            return Err(DetectError::NonFinite {
                what: "normals",
                index: i,
                value,
            });
        }
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len.is_nan() || len <= 1e-12 {
            return Err(DetectError::InvalidParameter {
                what: "normal length",
                value: len,
                reason: "given normals must be non-zero",
            });
        }
        out.push([n[0] / len, n[1] / len, n[2] / len]);
    }
    Ok(out)
}

/// Segments a coloured cloud (Algorithm 4.1): builds the graph, estimates normals unless given
/// (or unless the criteria are colour only) and runs [`segment_graph`].
///
/// Errors: `TooFewPoints` for an empty cloud; `NonFinite` for NaN/inf coordinates (NaN is
/// allowed only in an organised cloud, where it marks a missing point); `WrongLength` for
/// mismatched colours/normals; `InvalidParameter` for bad constants.
pub fn segment_cloud(
    points: &[[f64; 3]],
    colors: &[[u8; 3]],
    normals: Option<&[[f64; 3]]>,
    params: &SegmentParams,
) -> Result<CloudSegmentation> {
    let n = points.len();
    if n == 0 {
        return Err(DetectError::TooFewPoints {
            what: "points",
            got: 0,
            needed: 1,
        });
    }
    if colors.len() != n {
        return Err(DetectError::WrongLength {
            what: "colors",
            got: colors.len(),
            expected: n,
        });
    }
    if params.viewpoint.iter().any(|v| !v.is_finite()) {
        return Err(DetectError::NonFinite {
            what: "viewpoint",
            index: 0,
            value: params.viewpoint[0],
        });
    }
    params.fh.validate()?;
    let graph = match params.graph {
        GraphKind::Scan { lines, beams } => scan_graph(points, lines, beams, params.edge_cut)?,
        GraphKind::Knn { k } => knn_graph(points, k, params.edge_cut)?,
    };
    let (normals, normal_ok) = match (normals, params.fh.criteria) {
        (Some(given), _) => (check_normals(given, points)?, vec![true; n]),
        (None, Criteria::ColorOnly) => (vec![[0.0; 3]; n], vec![false; n]),
        (None, _) => estimate_normals(points, &graph, params.viewpoint),
    };
    let seg = segment_graph(n, &graph.edges, colors, Some(&normals), &params.fh)?;
    // Missing points are isolated singletons: give them UNLABELLED and renumber the rest.
    let missing: Vec<bool> = points
        .iter()
        .map(|p| p.iter().any(|v| v.is_nan()))
        .collect();
    let (labels, num_segments) = if missing.iter().any(|&m| m) {
        let mut map = vec![UNLABELLED; seg.num_segments];
        let mut next = 0u32;
        let labels = seg
            .labels
            .iter()
            .zip(&missing)
            .map(|(&l, &m)| {
                if m {
                    return UNLABELLED;
                }
                if map[l as usize] == UNLABELLED {
                    map[l as usize] = next;
                    next += 1;
                }
                map[l as usize]
            })
            .collect();
        (labels, next as usize)
    } else {
        (seg.labels, seg.num_segments)
    };
    Ok(CloudSegmentation {
        labels,
        num_segments,
        normals,
        normal_ok,
        num_edges: graph.edges.len(),
    })
}
