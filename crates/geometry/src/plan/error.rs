//! The error type of motion planning ([`crate::plan`]).

use thiserror::Error;

use crate::GeometryError;

/// Everything that can go wrong when planning or timing a motion. Messages carry the values
/// and name the binding constraint.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PlanError {
    /// A geometric input was invalid (non-finite joints, bad link dimensions, …).
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// An input to the planner or the optimiser is malformed (wrong length, empty, out of range).
    #[error("invalid {what}: {reason}")]
    InvalidInput {
        /// Which input.
        what: &'static str,
        /// Why, with the numbers.
        reason: String,
    },
    /// The start or goal configuration violates the clearance margin or a joint limit.
    #[error(
        "{which} configuration is not free: {constraint} (clearance {clearance:.4} m < {margin:.4} m)"
    )]
    InCollision {
        /// `"start"` or `"goal"`.
        which: &'static str,
        /// The binding constraint (link and obstacle, or joint limit).
        constraint: String,
        /// The clearance at the configuration (metres; negative = penetration).
        clearance: f64,
        /// The required clearance.
        margin: f64,
    },
    /// The planner exhausted its budget (lattice, iterations) without reaching the goal.
    #[error("no collision-free path found by {method}: {reason}")]
    NoPath {
        /// `"a*"` or `"rrt*"`.
        method: &'static str,
        /// Why (budget spent, lattice exhausted), with the numbers.
        reason: String,
    },
    /// The limits cannot be met by any trajectory (zero or negative limits, gravity above the
    /// lift's force limit, …).
    #[error("infeasible limits: {constraint}: {reason}")]
    Infeasible {
        /// The binding constraint (for example `"torque joint 4 (lift)"`).
        constraint: String,
        /// Why, with the numbers.
        reason: String,
    },
}
