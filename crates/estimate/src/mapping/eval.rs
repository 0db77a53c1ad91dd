//! Map-quality checks against ground truth (seed 004_815695db12a6b16c.txt §2.6.1: "if the map
//! contains a gap in a wall … robots may be tasked to drive through a wall"; §2.5: transient
//! objects must not remain in the map).

use autoteach_geometry::planar::Segment;

use super::grid::{FREE, OCCUPIED, OccupancyGrid};
use super::world::World;
use crate::lsq::se2::{se2_between, se2_compose};

/// Result of [`wall_gaps`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WallGapReport {
    /// Wall samples where the reference map shows the wall.
    pub samples: usize,
    /// Of those, samples where the candidate map shows no structure.
    pub gaps: usize,
}

/// Structure within `radius` cells (Chebyshev) of world point `p`.
fn structure_near(g: &OccupancyGrid, p: [f64; 2], radius: i64) -> bool {
    let c = ((p[0] - g.origin_x) / g.resolution).floor() as i64;
    let r = ((p[1] - g.origin_y) / g.resolution).floor() as i64;
    for dr in -radius..=radius {
        for dc in -radius..=radius {
            let (cc, rr) = (c + dc, r + dr);
            if cc >= 0
                && rr >= 0
                && (cc as usize) < g.width
                && (rr as usize) < g.height
                && g.cells[rr as usize * g.width + cc as usize] == OCCUPIED
            {
                return true;
            }
        }
    }
    false
}

/// The connectivity check along every true wall: samples each wall every half cell and
/// counts the samples where `reference` has structure within `radius` cells but `candidate`
/// has none (a gap that the reference map does not have).
pub fn wall_gaps(
    candidate: &OccupancyGrid,
    reference: &OccupancyGrid,
    walls: &[Segment],
    radius: i64,
) -> WallGapReport {
    let mut rep = WallGapReport::default();
    let step = reference.resolution / 2.0;
    for w in walls {
        let n = (w.length() / step).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let p = [
                w.a[0] + t * (w.b[0] - w.a[0]),
                w.a[1] + t * (w.b[1] - w.a[1]),
            ];
            if structure_near(reference, p, radius) {
                rep.samples += 1;
                if !structure_near(candidate, p, radius) {
                    rep.gaps += 1;
                }
            }
        }
    }
    rep
}

/// Result of [`transient_residue`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TransientReport {
    /// Map cells that only transient objects occupied (hit points farther than `margin`
    /// from every true wall), deduplicated.
    pub cells: usize,
    /// Of those, cells the map marks as structure.
    pub structure: usize,
    /// Of those, cells marked free.
    pub free: usize,
}

/// One node's transient returns: its true pose, its posterior and the world points where
/// its beams hit a transient object.
pub type NodeTransientHits = ([f64; 3], [f64; 3], Vec<[f32; 2]>);

/// Where do the laser returns from transient objects end up? Each ground-truth hit point
/// `hits[k]` (world frame) seen from a node with true pose `truth[k]` and posterior
/// `posterior[k]` is placed in the map frame as the node's posterior saw it, and the map's
/// class of that cell is counted (cells within `margin` metres of a true wall are skipped).
pub fn transient_residue(
    map: &OccupancyGrid,
    world: &World,
    hits: &[NodeTransientHits],
    margin: f64,
) -> TransientReport {
    let mut seen = std::collections::HashSet::new();
    let mut rep = TransientReport::default();
    for (truth, posterior, pts) in hits {
        for p in pts {
            let pw = [p[0] as f64, p[1] as f64];
            if world.wall_distance(pw) <= margin {
                continue;
            }
            let local = se2_between(truth, &[pw[0], pw[1], 0.0]);
            let m = se2_compose(posterior, &local);
            let c = ((m[0] - map.origin_x) / map.resolution).floor() as i64;
            let r = ((m[1] - map.origin_y) / map.resolution).floor() as i64;
            if !seen.insert((c, r)) {
                continue;
            }
            rep.cells += 1;
            match map.at(m[0], m[1]) {
                Some(OCCUPIED) => rep.structure += 1,
                Some(FREE) => rep.free += 1,
                _ => {}
            }
        }
    }
    rep
}

/// Cells whose class differs between two grids of the same resolution, over the union of
/// their boxes (a cell outside a grid counts as unknown): `(differing, cells in the union)`.
pub fn differing_cells(a: &OccupancyGrid, b: &OccupancyGrid) -> (usize, usize) {
    let res = a.resolution;
    let cell = |v: f64| (v / res).round() as i64;
    let (ax, ay, bx, by) = (
        cell(a.origin_x),
        cell(a.origin_y),
        cell(b.origin_x),
        cell(b.origin_y),
    );
    let x0 = ax.min(bx);
    let y0 = ay.min(by);
    let x1 = (ax + a.width as i64).max(bx + b.width as i64);
    let y1 = (ay + a.height as i64).max(by + b.height as i64);
    let get = |g: &OccupancyGrid, gx: i64, gy: i64, i: i64, j: i64| -> i8 {
        let (c, r) = (i - gx, j - gy);
        if c < 0 || r < 0 || c >= g.width as i64 || r >= g.height as i64 {
            super::grid::UNKNOWN
        } else {
            g.cells[r as usize * g.width + c as usize]
        }
    };
    let mut differ = 0;
    for j in y0..y1 {
        for i in x0..x1 {
            if get(a, ax, ay, i, j) != get(b, bx, by, i, j) {
                differ += 1;
            }
        }
    }
    (differ, ((x1 - x0).max(0) * (y1 - y0).max(0)) as usize)
}
