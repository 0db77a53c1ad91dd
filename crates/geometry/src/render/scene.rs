//! The simulated scene: wafers (thin discs) in a wafer carrier (FOUP).
//!
//! The world frame is the carrier frame: z up, the carrier opening faces −x (toward the robot),
//! slot `k = 1..=slots` holds its nominal wafer centre at `(0, 0, (k − 1)·pitch)`
//! (000_3b1454b2b2194811.txt §3.2, Fig. 3.2: wafers stacked in the FOUP, each showing an upper and
//! a lower bright rim edge).

use nalgebra::{Isometry3, Translation3, Vector3};

use crate::error::check_finite;
use crate::{GeometryError, Result};

/// Most wafers a scene may hold.
pub const MAX_WAFERS: usize = 7900;

/// Size of a wafer: a disc (slab) of `radius` and `thickness` lying between `z = ±thickness/2`
/// of its own frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaferShape {
    /// Radius in metres (0.150 for a 300 mm wafer).
    pub radius: f64,
    /// Thickness in metres (0.001 by default; a real 300 mm wafer is 0.775 mm).
    pub thickness: f64,
}

impl Default for WaferShape {
    fn default() -> Self {
        Self {
            radius: 0.150,
            thickness: 0.001,
        }
    }
}

impl WaferShape {
    /// Fails unless radius and thickness are finite and positive.
    pub fn validate(&self) -> Result<()> {
        positive("wafer radius", self.radius)?;
        positive("wafer thickness", self.thickness)
    }
}

/// Geometry of the wafer carrier, the clutter around the wafers. All boxes are axis-aligned in
/// the carrier (= world) frame. Lengths in metres; the side walls follow the wafer radius `r`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Carrier {
    /// Number of slots (26 in a FOUP).
    pub slots: usize,
    /// Vertical distance between slots (0.010).
    pub pitch: f64,
    /// Gap between the wafer edge and the inner face of a side wall: the walls' inner faces lie
    /// at `y = ±(r + wall_clearance)` (0.012).
    pub wall_clearance: f64,
    /// Thickness of the side walls (0.006).
    pub wall_thickness: f64,
    /// Front edge (x) of the side walls and ridges (−0.13; the wafers protrude beyond it).
    pub x_front: f64,
    /// Rear edge (x) of the side walls and ridges (0.16).
    pub x_rear: f64,
    /// Inner face (x) of the back wall (0.17).
    pub back_wall_x: f64,
    /// Thickness of the back wall and of the top and bottom plates (0.006).
    pub plate_thickness: f64,
    /// The slot ridges (teeth) reach inward to `|y| = r − ridge_inset` (0.006).
    pub ridge_inset: f64,
    /// Height of a ridge (0.003).
    pub ridge_height: f64,
    /// Gap between a ridge's top and the bottom of the nominal wafer of its slot (0.0005).
    pub ridge_gap: f64,
    /// Gap between the bottom plate and the lowest slot centre, and between the highest slot
    /// centre and the top plate (0.015).
    pub plate_margin: f64,
}

impl Default for Carrier {
    fn default() -> Self {
        Self {
            slots: 26,
            pitch: 0.010,
            wall_clearance: 0.012,
            wall_thickness: 0.006,
            x_front: -0.13,
            x_rear: 0.16,
            back_wall_x: 0.17,
            plate_thickness: 0.006,
            ridge_inset: 0.006,
            ridge_height: 0.003,
            ridge_gap: 0.0005,
            plate_margin: 0.015,
        }
    }
}

impl Carrier {
    /// Nominal pose of the wafer in slot `k` (1-based): centre `(0, 0, (k − 1)·pitch)`, level.
    pub fn slot_pose(&self, k: usize) -> Isometry3<f64> {
        let z = (k.max(1) - 1) as f64 * self.pitch;
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, z),
            nalgebra::UnitQuaternion::identity(),
        )
    }

    /// Fails unless every length is finite and positive (or, for `x_front`, finite) and the
    /// layout is consistent (`x_front < x_rear ≤ back_wall_x`, `ridge_inset < r`).
    pub fn validate(&self, wafer: &WaferShape) -> Result<()> {
        if self.slots == 0 || self.slots > 100 {
            return Err(GeometryError::InvalidParameter {
                what: "carrier slots",
                value: self.slots as f64,
                reason: "must be in 1..=100",
            });
        }
        positive("carrier pitch", self.pitch)?;
        positive("carrier wall_clearance", self.wall_clearance)?;
        positive("carrier wall_thickness", self.wall_thickness)?;
        positive("carrier plate_thickness", self.plate_thickness)?;
        positive("carrier ridge_height", self.ridge_height)?;
        positive("carrier plate_margin", self.plate_margin)?;
        check_finite("carrier x_front", &[self.x_front])?;
        check_finite("carrier x_rear", &[self.x_rear])?;
        check_finite("carrier back_wall_x", &[self.back_wall_x])?;
        check_finite("carrier ridge_gap", &[self.ridge_gap])?;
        check_finite("carrier ridge_inset", &[self.ridge_inset])?;
        if self.x_rear <= self.x_front {
            return Err(GeometryError::InvalidParameter {
                what: "carrier x_rear",
                value: self.x_rear,
                reason: "must exceed x_front",
            });
        }
        if self.back_wall_x < self.x_rear {
            return Err(GeometryError::InvalidParameter {
                what: "carrier back_wall_x",
                value: self.back_wall_x,
                reason: "must be at least x_rear",
            });
        }
        if self.ridge_inset >= wafer.radius + self.wall_clearance {
            return Err(GeometryError::InvalidParameter {
                what: "carrier ridge_inset",
                value: self.ridge_inset,
                reason: "ridges would cross the carrier's centre plane",
            });
        }
        Ok(())
    }

    /// Pushes the pair of boxes spanning `x_front..x_rear` and `z` that mirror each other in
    /// the centre plane: `y ∈ [-y.1, -y.0]` (the −y side first), then `y ∈ [y.0, y.1]`.
    fn push_mirrored(
        &self,
        out: &mut Vec<(Aabb, Material)>,
        y: (f64, f64),
        z: (f64, f64),
        material: Material,
    ) {
        for (y0, y1) in [(-y.1, -y.0), (y.0, y.1)] {
            out.push((
                Aabb::new(
                    Vector3::new(self.x_front, y0, z.0),
                    Vector3::new(self.x_rear, y1, z.1),
                ),
                material,
            ));
        }
    }

    /// The carrier's parts as axis-aligned boxes with their material, for a wafer of `wafer`.
    pub(crate) fn boxes(&self, wafer: &WaferShape) -> Vec<(Aabb, Material)> {
        let r = wafer.radius;
        let h = 0.5 * wafer.thickness;
        let y_in = r + self.wall_clearance;
        let y_out = y_in + self.wall_thickness;
        let z_top_slot = (self.slots - 1) as f64 * self.pitch;
        let z_lo = -self.plate_margin;
        let z_hi = z_top_slot + self.plate_margin;
        let x_back = self.back_wall_x + self.plate_thickness;
        let mut out = Vec::with_capacity(5 + 2 * self.slots);
        // Bottom and top plates.
        out.push((
            Aabb::new(
                Vector3::new(self.x_front, -y_out, z_lo - self.plate_thickness),
                Vector3::new(x_back, y_out, z_lo),
            ),
            Material::Plate,
        ));
        out.push((
            Aabb::new(
                Vector3::new(self.x_front, -y_out, z_hi),
                Vector3::new(x_back, y_out, z_hi + self.plate_thickness),
            ),
            Material::Plate,
        ));
        // Side walls.
        self.push_mirrored(&mut out, (y_in, y_out), (z_lo, z_hi), Material::Wall);
        // Back wall.
        out.push((
            Aabb::new(
                Vector3::new(self.back_wall_x, -y_out, z_lo),
                Vector3::new(x_back, y_out, z_hi),
            ),
            Material::Back,
        ));
        // Slot ridges: just below each slot's nominal wafer, attached to the side walls.
        let y_ridge = r - self.ridge_inset;
        for k in 0..self.slots {
            let z_top = k as f64 * self.pitch - h - self.ridge_gap;
            let z_bot = z_top - self.ridge_height;
            self.push_mirrored(&mut out, (y_ridge, y_in), (z_bot, z_top), Material::Ridge);
        }
        out
    }
}

/// A scene to render: wafer poses `T_w,wafer`, the wafer size, and optionally the carrier.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Pose of each wafer in the world (carrier) frame, `T_w,wafer`.
    pub wafers: Vec<Isometry3<f64>>,
    /// Size shared by all wafers.
    pub shape: WaferShape,
    /// The carrier, or `None` for wafers floating in front of the dark background.
    pub carrier: Option<Carrier>,
}

impl Scene {
    /// A scene with the default wafer size and the default carrier.
    pub fn new(wafers: Vec<Isometry3<f64>>) -> Self {
        Self {
            wafers,
            shape: WaferShape::default(),
            carrier: Some(Carrier::default()),
        }
    }

    /// Fails on a non-positive wafer size, an invalid carrier, or a non-finite pose.
    pub fn validate(&self) -> Result<()> {
        self.shape.validate()?;
        if self.wafers.len() > MAX_WAFERS {
            return Err(GeometryError::InvalidParameter {
                what: "number of wafers",
                value: self.wafers.len() as f64,
                reason: "at most 7900 wafers per scene",
            });
        }
        if let Some(c) = &self.carrier {
            c.validate(&self.shape)?;
        }
        for (index, pose) in self.wafers.iter().enumerate() {
            validate_pose("wafer pose", pose).map_err(|e| GeometryError::AtIndex {
                index,
                source: Box::new(e),
            })?;
        }
        Ok(())
    }
}

/// Fails unless the pose's translation and quaternion are finite and the quaternion is unit.
pub(crate) fn validate_pose(what: &'static str, pose: &Isometry3<f64>) -> Result<()> {
    check_finite(what, pose.translation.vector.as_slice())?;
    let q = pose.rotation.quaternion();
    check_finite(what, q.coords.as_slice())?;
    let n = q.norm();
    if (n - 1.0).abs() > 1e-6 {
        return Err(GeometryError::InvalidParameter {
            what,
            value: n,
            reason: "rotation quaternion is not unit",
        });
    }
    Ok(())
}

fn positive(what: &'static str, value: f64) -> Result<()> {
    if !value.is_finite() {
        return Err(GeometryError::NonFinite { what, value });
    }
    if value <= 0.0 {
        return Err(GeometryError::InvalidParameter {
            what,
            value,
            reason: "must be positive",
        });
    }
    Ok(())
}

/// Surface material of a carrier part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Material {
    /// Top and bottom plates.
    Plate,
    /// Side walls.
    Wall,
    /// Back wall (dark).
    Back,
    /// Slot ridges (brighter faces).
    Ridge,
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Aabb {
    pub min: Vector3<f64>,
    pub max: Vector3<f64>,
}

impl Aabb {
    pub fn new(a: Vector3<f64>, b: Vector3<f64>) -> Self {
        Self {
            min: a.inf(&b),
            max: a.sup(&b),
        }
    }

    /// Euclidean distance from a point to the box (0 inside).
    pub fn distance_to_point(&self, p: &Vector3<f64>) -> f64 {
        let d = (self.min - p).sup(&(p - self.max)).sup(&Vector3::zeros());
        d.norm()
    }

    /// The 8 corners.
    pub fn corners(&self) -> [Vector3<f64>; 8] {
        let mut out = [Vector3::zeros(); 8];
        for (i, c) in out.iter_mut().enumerate() {
            *c = Vector3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            );
        }
        out
    }
}
