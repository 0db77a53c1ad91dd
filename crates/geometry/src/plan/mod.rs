//! Motion planning and time-optimal trajectories for the wafer-handling robot,
//! 000_3b1454b2b2194811.txt ch. 2.2–2.4.
//!
//! * [`workspace`]: the robot's links, blades, wafer and camera as parry shapes, obstacles,
//!   signed distance and its gradient (eq. 2.17).
//! * [`dynamics`]: inverse dynamics τ(q, q̇, q̈) (eqs. 2.8–2.9).
//! * [`astar`]: A* on a joint lattice; [`rrt_star`]: RRT* with a k-d tree (ch. 2.3).
//! * [`bspline`]: clamped cubic B-splines (eqs. 2.10–2.15) and [`bspline::BSplineTrajectory`].
//! * [`limits`]: kinematic and torque limits, the per-joint time-optimal bound and the dense
//!   verification of a trajectory.
//!
//! The time-optimal optimisation of eq. (2.16), which needs a QP solver, lives in
//! `autoteach_estimate::plan` so that this crate stays solver-free.
//!
//! ```
//! use autoteach_geometry::plan::workspace::default_scene;
//! let (ws, poses) = default_scene()?;
//! let home = &poses[0];
//! assert!(ws.clearance(&home.q)?.is_some_and(|c| c.distance > 0.0));
//! # Ok::<(), autoteach_geometry::plan::PlanError>(())
//! ```

pub mod astar;
pub mod bspline;
pub mod dynamics;
mod error;
pub mod limits;
pub mod rrt_star;
pub mod workspace;

pub use error::PlanError;
