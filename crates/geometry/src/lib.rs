//! # autoteach-geometry
//!
//! The geometric foundation of autoteach: rigid transforms on SO(3)/SE(3) with the ⊕/⊖
//! operators and their Jacobians, the kinematics of the dual-blade wafer-handling robot of
//! the seed dissertation (000_3b1454b2b2194811.txt, ch. 2), camera models (pinhole,
//! Brown–Conrady, Kannala–Brandt), conics and the image of a 3D circle, and a ray-cast
//! renderer used by the simulator.
//!
//! All lengths are in metres and all angles in radians. Poses are `nalgebra::Isometry3<f64>`;
//! `T_ab` maps coordinates in frame `b` to frame `a` (so `T_wc` takes camera points to world).
//!
//! ```
//! use autoteach_geometry::lie;
//! use nalgebra::Vector3;
//! let w = Vector3::new(0.1, -0.2, 0.3);
//! let r = lie::so3_exp(&w);
//! assert!((lie::so3_log(&r) - w).norm() < 1e-12);
//! ```
#![deny(missing_docs)]

pub mod alloc;
pub mod boxes;
pub mod camera;
pub mod collision;
pub mod conic;
pub mod counting_sort;
pub mod error;
pub mod lie;
pub mod plan;
pub mod planar;
pub mod render;
pub mod robot;

pub use error::GeometryError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, GeometryError>;
