//! Time-optimal trajectory optimisation of the wafer robot, 000_3b1454b2b2194811.txt ch. 2.4,
//! eqs. (2.16)–(2.17). The geometry (B-splines, workspace, dynamics, limits) lives in
//! `autoteach_geometry::plan`; this module holds the optimiser because it needs the QP solver
//! (clarabel) and the geometry crate stays solver-free.

mod time_optimal;
mod waypoints;

pub use time_optimal::{OptimizeConfig, OptimizeResult, optimize_trajectory};
pub use waypoints::{WaypointResult, optimize_waypoints};
