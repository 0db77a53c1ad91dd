//! Planar (2-D) ray casting for laser range finders and occupancy grids (seed
//! 004_815695db12a6b16c.txt ch. 2): the traversal of the grid cells a laser beam crosses
//! ([`traverse_cells`], Amanatides & Woo's voxel walk) and ray casting against a world of wall
//! segments with a uniform bucket grid ([`SegmentWorld`]).
//!
//! ```
//! use autoteach_geometry::planar::{Segment, SegmentWorld, traverse_cells};
//! // A wall at x = 5 m; a beam along +x from the origin hits it at 5 m.
//! let world = SegmentWorld::new(vec![Segment::new([5.0, -1.0], [5.0, 1.0])], 2.0)?;
//! let r = world.cast([0.0, 0.0], 0.0, 30.0).unwrap();
//! assert!((r - 5.0).abs() < 1e-12);
//! // The cells crossed at 1 m resolution before the hit cell: x = 0, 1, 2, 3, 4.
//! let mut cells = vec![];
//! traverse_cells([0.5, 0.5], [5.5, 0.5], |i, j| cells.push((i, j)));
//! assert_eq!(cells, vec![(0, 0), (1, 0), (2, 0), (3, 0), (4, 0)]);
//! # Ok::<(), autoteach_geometry::GeometryError>(())
//! ```

mod segments;
mod traverse;

pub use segments::{Segment, SegmentWorld};
pub use traverse::{cell_of, traverse_cells};
