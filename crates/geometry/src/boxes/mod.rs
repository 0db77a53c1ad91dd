//! Probabilistic bounding boxes (000_3b1454b2b2194811.txt ch. 8 and Appendix A).
//!
//! A BEV box is `y = [c₁, c₂, l, w, r_y]` (centre, full length along the heading, full width,
//! heading); a 3-D box adds `c₃` and `h`. Eq. (8.1) maps a point `v₀` of the unit box
//! `[−½, ½]^d` to the surface point `v(y) = R(r_y)·diag(l, w[, h])·v₀ + c`.
//!
//! A probabilistic box is a Gaussian `Y ~ N(ȳ, Σ)` over `y` (for example the label posterior of
//! `autoteach_detect::uncertainty`). From it this module computes
//! - the moments of `V(v₀, Y)` (Appendix A, eq. A.4–A.6) in [`moments`];
//! - the spatial distributions `p_G(u)` (eq. 8.3) and `P_PDQ(u)` (eq. 8.2) at points or on a
//!   grid in [`spatial`];
//! - the Jaccard IoU (eq. 8.4) by the `O(N log N)` probabilistic Jaccard index of Moulton & Jiang
//!   (ref. [249], their eq. 3) in [`jiou`], and the exact IoU of two rotated boxes in [`iou`];
//! - a BEV LiDAR scan simulator of cars (L-shaped hits, noise, occlusion) in [`scan`].
//!
//! This lives in `geometry` because none of it needs detection or estimation: the label
//! posterior (eq. 8.6–8.12), which reuses the CPD E-step, lives in `autoteach_detect`.
//!
//! ```
//! use autoteach_geometry::boxes::{Box2, iou::iou};
//! let a = Box2::new(0.0, 0.0, 4.0, 2.0, 0.0)?;
//! let b = Box2::new(1.0, 0.0, 4.0, 2.0, 0.0)?;
//! assert!((iou(&a, &b) - 6.0 / 10.0).abs() < 1e-12);
//! # Ok::<(), autoteach_geometry::GeometryError>(())
//! ```

// Small fixed-size linear algebra indexes several arrays at once; ranges read clearest.
#![allow(clippy::needless_range_loop)]

pub mod iou;
pub mod jiou;
pub mod moments;
pub mod scan;
pub mod spatial;
#[cfg(test)]
mod tests;

use crate::{GeometryError, Result};

/// Number of BEV box parameters `[c₁, c₂, l, w, r_y]`.
pub const BEV_PARAMS: usize = 5;

/// A 5×5 covariance over the BEV parameters `[c₁, c₂, l, w, r_y]`.
pub type Cov5 = [[f64; BEV_PARAMS]; BEV_PARAMS];

/// A rotated box in the bird's eye view: centre `(cx, cy)`, full length `l` along the heading
/// `r` (radians, counter-clockwise from the x axis) and full width `w`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Box2 {
    /// Centre x.
    pub cx: f64,
    /// Centre y.
    pub cy: f64,
    /// Full length (along the heading).
    pub l: f64,
    /// Full width.
    pub w: f64,
    /// Heading in radians.
    pub r: f64,
}

impl Box2 {
    /// A box; fails for non-finite values or a non-positive length or width.
    pub fn new(cx: f64, cy: f64, l: f64, w: f64, r: f64) -> Result<Self> {
        crate::error::check_finite("box parameters", &[cx, cy, l, w, r])?;
        for (what, v) in [("box length l", l), ("box width w", w)] {
            if v <= 0.0 {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value: v,
                    reason: "box sizes must be positive",
                });
            }
        }
        Ok(Self { cx, cy, l, w, r })
    }

    /// From `[c₁, c₂, l, w, r_y]`.
    pub fn from_params(y: &[f64; BEV_PARAMS]) -> Result<Self> {
        Self::new(y[0], y[1], y[2], y[3], y[4])
    }

    /// `[c₁, c₂, l, w, r_y]`.
    pub fn params(&self) -> [f64; BEV_PARAMS] {
        [self.cx, self.cy, self.l, self.w, self.r]
    }

    /// Area `l·w`.
    pub fn area(&self) -> f64 {
        self.l * self.w
    }

    /// Eq. (8.1) in BEV: the point `R(r)·diag(l, w)·v₀ + c` of the box for `v₀ ∈ [−½, ½]²`.
    pub fn point(&self, v0: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.r.sin_cos();
        let (a, b) = (self.l * v0[0], self.w * v0[1]);
        [self.cx + c * a - s * b, self.cy + s * a + c * b]
    }

    /// Jacobian `∂v/∂y` of eq. (8.1) at `v₀` (2×5, columns `c₁, c₂, l, w, r_y`).
    pub fn point_jacobian(&self, v0: [f64; 2]) -> [[f64; BEV_PARAMS]; 2] {
        let (s, c) = self.r.sin_cos();
        let (a, b) = (self.l * v0[0], self.w * v0[1]);
        [
            [1.0, 0.0, v0[0] * c, -v0[1] * s, -s * a - c * b],
            [0.0, 1.0, v0[0] * s, v0[1] * c, c * a - s * b],
        ]
    }

    /// The corners, counter-clockwise from `v₀ = (½, ½)`.
    pub fn corners(&self) -> [[f64; 2]; 4] {
        [
            self.point([0.5, 0.5]),
            self.point([-0.5, 0.5]),
            self.point([-0.5, -0.5]),
            self.point([0.5, -0.5]),
        ]
    }

    /// Whether `u` lies inside (or on) the box.
    pub fn contains(&self, u: [f64; 2]) -> bool {
        let (s, c) = self.r.sin_cos();
        let (dx, dy) = (u[0] - self.cx, u[1] - self.cy);
        let a = c * dx + s * dy;
        let b = -s * dx + c * dy;
        a.abs() <= 0.5 * self.l && b.abs() <= 0.5 * self.w
    }

    /// `n` unit-box points `v₀` spaced evenly along the boundary of the box `y` (arc length
    /// measured on this box), used to render the GMM of eq. (8.7).
    pub fn boundary_unit_points(&self, n: usize) -> Vec<[f64; 2]> {
        let per = 2.0 * (self.l + self.w);
        (0..n)
            .map(|i| {
                // Arc length from the corner (½, −½) counter-clockwise, at cell centres.
                let mut s = (i as f64 + 0.5) / n as f64 * per;
                if s < self.w {
                    return [0.5, -0.5 + s / self.w];
                }
                s -= self.w;
                if s < self.l {
                    return [0.5 - s / self.l, 0.5];
                }
                s -= self.l;
                if s < self.w {
                    return [-0.5, 0.5 - s / self.w];
                }
                s -= self.w;
                [-0.5 + s / self.l, -0.5]
            })
            .collect()
    }
}

/// A 3-D box `y = [c₁, c₂, c₃, l, w, h, r_y]` in a z-up frame (LiDAR convention: `r_y` is the
/// yaw about z; the seed's eq. A.5 writes the same map in KITTI's camera frame, y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Box3 {
    /// Centre.
    pub c: [f64; 3],
    /// Full length, width and height.
    pub size: [f64; 3],
    /// Yaw in radians.
    pub r: f64,
}

impl Box3 {
    /// A box; fails for non-finite values or non-positive sizes.
    pub fn new(c: [f64; 3], size: [f64; 3], r: f64) -> Result<Self> {
        crate::error::check_finite(
            "box parameters",
            &[c[0], c[1], c[2], size[0], size[1], size[2], r],
        )?;
        for (what, v) in [
            ("box length l", size[0]),
            ("box width w", size[1]),
            ("box height h", size[2]),
        ] {
            if v <= 0.0 {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value: v,
                    reason: "box sizes must be positive",
                });
            }
        }
        Ok(Self { c, size, r })
    }

    /// Eq. (8.1): `v(y) = R_y·diag(l, w, h)·v₀ + c` for `v₀ ∈ [−½, ½]³`.
    pub fn point(&self, v0: [f64; 3]) -> [f64; 3] {
        let (s, co) = self.r.sin_cos();
        let a = [
            self.size[0] * v0[0],
            self.size[1] * v0[1],
            self.size[2] * v0[2],
        ];
        [
            self.c[0] + co * a[0] - s * a[1],
            self.c[1] + s * a[0] + co * a[1],
            self.c[2] + a[2],
        ]
    }

    /// The eight corners (bottom face first, counter-clockwise).
    pub fn corners(&self) -> [[f64; 3]; 8] {
        let mut out = [[0.0; 3]; 8];
        for (k, o) in out.iter_mut().enumerate() {
            let z = if k < 4 { -0.5 } else { 0.5 };
            let (x, y) = [(0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)][k % 4];
            *o = self.point([x, y, z]);
        }
        out
    }

    /// Volume `l·w·h`.
    pub fn volume(&self) -> f64 {
        self.size.iter().product()
    }

    /// The bird's eye view box (drops `c₃` and `h`).
    pub fn bev(&self) -> Box2 {
        Box2 {
            cx: self.c[0],
            cy: self.c[1],
            l: self.size[0],
            w: self.size[1],
            r: self.r,
        }
    }
}

/// Validates a 5×5 BEV covariance: finite, symmetric (to 1e−9 relative) and positive
/// semi-definite (smallest eigenvalue ≥ −1e−12·largest). Returns its eigen-decomposition
/// square root `L` with `L·Lᵀ = Σ` (valid for singular Σ, unlike a Cholesky factor).
pub fn check_covariance(cov: &Cov5) -> Result<[[f64; BEV_PARAMS]; BEV_PARAMS]> {
    let flat: Vec<f64> = cov.iter().flatten().copied().collect();
    crate::error::check_finite("covariance", &flat)?;
    let scale = flat.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for i in 0..BEV_PARAMS {
        for j in 0..i {
            if (cov[i][j] - cov[j][i]).abs() > 1e-9 * scale.max(1e-300) {
                return Err(GeometryError::InvalidParameter {
                    what: "covariance",
                    value: cov[i][j] - cov[j][i],
                    reason: "covariance must be symmetric (value is Σ_ij − Σ_ji)",
                });
            }
        }
    }
    let m = nalgebra::SMatrix::<f64, 5, 5>::from_fn(|i, j| 0.5 * (cov[i][j] + cov[j][i]));
    let eig = m.symmetric_eigen();
    let (lo, hi) = eig
        .eigenvalues
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if lo < -1e-12 * hi.max(1e-300) {
        return Err(GeometryError::InvalidParameter {
            what: "covariance",
            value: lo,
            reason: "covariance must be positive semi-definite (value is its smallest eigenvalue)",
        });
    }
    let mut l = [[0.0; BEV_PARAMS]; BEV_PARAMS];
    for (i, row) in l.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = eig.eigenvectors[(i, j)] * eig.eigenvalues[j].max(0.0).sqrt();
        }
    }
    Ok(l)
}

/// Whether every entry of `cov` is zero (a deterministic box).
pub fn is_deterministic(cov: &Cov5) -> bool {
    cov.iter().flatten().all(|v| *v == 0.0)
}
