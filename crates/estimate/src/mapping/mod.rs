//! Occupancy-grid rasterization for robot teams (seed 004_815695db12a6b16c.txt ch. 2):
//! slice caching (§2.3), spatially non-redundant node coverings (§2.4), transient-object
//! removal by per-cell log-odds voting (§2.5) — Algorithm 2.1 COVER_COMPOSITE and the naïve
//! methods of Table 2.1 ([`Rasterizer`]) — and a team simulator that yields the sequence of
//! SE(2) pose graphs, solved by [`crate::lsq`], with ground truth ([`TeamSimulator`]).
//!
//! ```
//! use autoteach_estimate::mapping::{Method, NodeInput, RasterConfig, Rasterizer, OCCUPIED};
//! // One node at the origin sees a wall 5 m ahead with three beams (−10°, 0°, +10°).
//! let mut cfg = RasterConfig { method: Method::CoverComposite, ..RasterConfig::default() };
//! cfg.scan.angle_min = -10f64.to_radians();
//! cfg.scan.angle_increment = 10f64.to_radians();
//! let mut r = Rasterizer::new(cfg)?;
//! let ranges = [5.0 / 10f64.to_radians().cos(), 5.0, 5.0 / 10f64.to_radians().cos()];
//! let node = NodeInput { id: 0, robot: 0, pose: [0.0, 0.0, 0.0], ranges: Some(&ranges) };
//! let (map, report) = r.update(&[node])?;
//! assert_eq!(map.at(5.02, 0.02), Some(OCCUPIED));
//! assert_eq!((report.slices_regenerated, report.nodes_composited), (1, 1));
//! # Ok::<(), autoteach_estimate::EstimateError>(())
//! ```

mod cover;
mod eval;
mod grid;
mod raster;
mod scan;
mod sim;
mod votes;
mod world;

#[cfg(test)]
mod tests;

pub use cover::CoverTest;
pub use eval::{
    NodeTransientHits, TransientReport, WallGapReport, differing_cells, transient_residue,
    wall_gaps,
};
pub use grid::{FREE, OCCUPIED, OccupancyGrid, UNKNOWN, VoteModel};
pub use raster::{Method, NodeInput, RasterConfig, Rasterizer, UpdateReport};
pub use scan::{LocalScan, ScanGeometry, footprint_displacement};
pub use sim::{Edge, EdgeKind, GraphSnapshot, TeamConfig, TeamSimulator};
pub use votes::{CellBox, DenseVotes, Projection, SparseVotes};
pub use world::{World, WorldConfig};
