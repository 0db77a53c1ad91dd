//! Camera–LiDAR feature fusion layers (000_3b1454b2b2194811.txt ch. 7): the sparse
//! non-homogeneous pooling layer (SHPL, §7.5, eq. 7.4–7.9, Fig. 7.12) in [`shpl`] and the
//! non-zero max-min pooling of the serial fusion network (§7.4, Figs. 7.5–7.6) in [`maxmin`].
//!
//! Both are framework-free operators on channels-last `f32` or `f64` feature maps with explicit
//! forward and backward passes, so a deep-learning framework can wrap them as a custom op.
//! Every output row is computed by one thread in a fixed order, so results are bit-identical
//! whatever the number of rayon threads.
//!
//! ```
//! use autoteach_detect::fusion::shpl::{BevGrid, Direction, ImageGrid, SparsePooling};
//! // Two LiDAR points in the same BEV cell, seen by different image cells.
//! let p = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
//! let points = [[0.5, 0.5, 0.0], [1.5, 0.5, 0.0]];
//! let op = SparsePooling::build(&points, &p, ImageGrid::new(2, 2, 1.0)?, BevGrid::new(0.0, 0.0, 2.0, 1, 1)?, 1)?;
//! // Image features (4 cells × 1 channel) → the BEV cell averages the two cells seen.
//! let mut out = [0.0f64];
//! op.forward(Direction::ImageToBev, &[1.0, 3.0, 5.0, 7.0], 1, &mut out)?;
//! assert_eq!(out[0], 2.0);
//! # Ok::<(), autoteach_detect::DetectError>(())
//! ```

pub mod maxmin;
pub mod shpl;
#[cfg(test)]
mod tests;

/// A feature scalar: `f32` or `f64`.
pub trait Feature:
    Copy
    + Send
    + Sync
    + PartialOrd
    + std::fmt::Debug
    + std::ops::Add<Output = Self>
    + std::ops::Mul<Output = Self>
    + 'static
{
    /// Zero.
    const ZERO: Self;
    /// From an `f64` weight.
    fn from_f64(v: f64) -> Self;
    /// As `f64`.
    fn to_f64(self) -> f64;
    /// The weights stored in this precision.
    fn pick<'a>(d64: &'a [f64], d32: &'a [f32]) -> &'a [Self];
}

impl Feature for f32 {
    const ZERO: Self = 0.0;
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn pick<'a>(_: &'a [f64], d32: &'a [f32]) -> &'a [Self] {
        d32
    }
}

impl Feature for f64 {
    const ZERO: Self = 0.0;
    fn from_f64(v: f64) -> Self {
        v
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn pick<'a>(d64: &'a [f64], _: &'a [f32]) -> &'a [Self] {
        d64
    }
}
