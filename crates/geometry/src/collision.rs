//! Collision checking of the wafer-handling robot against its workspace with parry, the
//! collision constraint (6.20) of 000_3b1454b2b2194811.txt ch. 6.3.
//!
//! The robot links are modelled as simple convex shapes posed by the kinematics of
//! [`WaferRobot`] (ch. 2.2, eq. (2.4)): the upper arm and the forearm as capsules in the
//! horizontal plane, each blade as a thin cuboid from the wrist axis to the blade tip, and the
//! camera body as a small cuboid at the camera mount (eq. (2.7)). Workspace obstacles (chamber
//! walls around an opening, a wafer carrier) are cuboids. Distances are computed by parry
//! (glam-based): poses are converted from nalgebra at the boundary.
//!
//! The printed (6.20) bounds "distances of robot arms to the boundary of the workspace"; the
//! workspace here is the free space outside the obstacles, so the constraint is evaluated as the
//! signed clearance between every link and every obstacle (negative = penetration depth) being
//! at least a safety margin.
//!
//! ```
//! use autoteach_geometry::collision::{LinkDims, Obstacle, RobotShapes, Workspace};
//! use autoteach_geometry::robot::{Joints, WaferRobot};
//! use nalgebra::{Isometry3, Vector3};
//! let shapes = RobotShapes::new(WaferRobot::default(), LinkDims::default())?;
//! let wall = Obstacle::new("wall", Isometry3::translation(2.0, 0.0, 0.5), Vector3::new(0.05, 1.0, 1.0))?;
//! let ws = Workspace::new(vec![wall])?;
//! let c = shapes.clearance(&Joints::new(0.0, 0.0, 0.0, 0.0, 0.1), &ws)?;
//! // `None` only for an empty workspace; the fully extended arm reaches x = 1.04 m.
//! assert!(c.is_some_and(|c| c.distance > 0.5));
//! # Ok::<(), autoteach_geometry::GeometryError>(())
//! ```

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::math::{Pose, Rotation, Vector};
use parry3d_f64::query;
use parry3d_f64::shape::{Capsule, Cuboid, Shape};

use crate::error::check_finite;
use crate::robot::{Blade, Joints, WaferRobot};
use crate::{GeometryError, Result};

/// Converts a nalgebra isometry to a parry (glam) pose.
pub fn to_parry_pose(t: &Isometry3<f64>) -> Pose {
    let q = t.rotation.quaternion();
    let v = t.translation.vector;
    Pose::from_parts(
        Vector::new(v.x, v.y, v.z),
        Rotation::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

/// A box-shaped obstacle of the workspace.
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// Name used in reports (e.g. `"wall above the opening"`).
    pub name: String,
    /// Pose of the box centre in the world (`T_w,box`).
    pub pose: Isometry3<f64>,
    /// Half extents along the box's own x, y, z axes (metres, positive).
    pub half_extents: Vector3<f64>,
}

impl Obstacle {
    /// Creates an obstacle after checking that the pose is finite and the half extents positive.
    pub fn new(
        name: impl Into<String>,
        pose: Isometry3<f64>,
        half_extents: Vector3<f64>,
    ) -> Result<Self> {
        check_finite("obstacle translation", pose.translation.vector.as_slice())?;
        check_finite("obstacle rotation", pose.rotation.coords.as_slice())?;
        check_finite("obstacle half extents", half_extents.as_slice())?;
        if let Some(&h) = half_extents.iter().find(|h| **h <= 0.0) {
            return Err(GeometryError::InvalidParameter {
                what: "obstacle half extent",
                value: h,
                reason: "half extents must be positive",
            });
        }
        Ok(Self {
            name: name.into(),
            pose,
            half_extents,
        })
    }
}

/// The obstacles bounding the robot's free space.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Workspace {
    obstacles: Vec<Obstacle>,
}

impl Workspace {
    /// A workspace made of the given obstacles (possibly none).
    pub fn new(obstacles: Vec<Obstacle>) -> Result<Self> {
        Ok(Self { obstacles })
    }

    /// A wall with a rectangular chamber opening (a slit valve) in it, as four cuboids framing
    /// the opening.
    ///
    /// `opening` is the pose of the opening centre; its x axis is the opening normal pointing
    /// into the chamber (away from the robot), y is horizontal and z vertical. The opening is
    /// `width` (along y) by `height` (along z); the wall is `thickness` thick (along x, starting
    /// at the opening plane and extending into the chamber) and extends `margin` beyond the
    /// opening on every side.
    pub fn chamber_opening(
        opening: &Isometry3<f64>,
        width: f64,
        height: f64,
        thickness: f64,
        margin: f64,
    ) -> Result<Self> {
        for (what, v) in [
            ("opening width", width),
            ("opening height", height),
            ("wall thickness", thickness),
            ("wall margin", margin),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value: v,
                    reason: "chamber dimensions must be positive and finite",
                });
            }
        }
        let hx = 0.5 * thickness;
        let (hw, hh) = (0.5 * width, 0.5 * height);
        let at = |y: f64, z: f64| opening * Isometry3::translation(hx, y, z);
        let obstacles = vec![
            Obstacle::new(
                "wall above the opening",
                at(0.0, hh + 0.5 * margin),
                Vector3::new(hx, hw + margin, 0.5 * margin),
            )?,
            Obstacle::new(
                "wall below the opening",
                at(0.0, -hh - 0.5 * margin),
                Vector3::new(hx, hw + margin, 0.5 * margin),
            )?,
            Obstacle::new(
                "wall left of the opening",
                at(hw + 0.5 * margin, 0.0),
                Vector3::new(hx, 0.5 * margin, hh),
            )?,
            Obstacle::new(
                "wall right of the opening",
                at(-hw - 0.5 * margin, 0.0),
                Vector3::new(hx, 0.5 * margin, hh),
            )?,
        ];
        Ok(Self { obstacles })
    }

    /// Adds an obstacle.
    pub fn push(&mut self, obstacle: Obstacle) {
        self.obstacles.push(obstacle);
    }

    /// The obstacles.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
}

/// Dimensions of the convex link shapes of the robot (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkDims {
    /// Radius of the upper-arm and forearm capsules.
    pub arm_radius: f64,
    /// Height of the upper-arm axis above the lifted column `h`.
    pub upper_arm_z: f64,
    /// Height of the forearm axis above the lifted column `h`.
    pub forearm_z: f64,
    /// Half width of each blade (across the blade, horizontal).
    pub blade_half_width: f64,
    /// Half thickness of each blade (vertical).
    pub blade_half_thickness: f64,
    /// Half extents of the camera body, in the camera frame (x right, y down, z forward).
    pub camera_half_extents: Vector3<f64>,
}

impl Default for LinkDims {
    /// A slim 300 mm wafer-handling robot: 40 mm arm capsules, 100 mm wide blades 6 mm thick,
    /// a 30 × 30 × 40 mm camera.
    fn default() -> Self {
        Self {
            arm_radius: 0.04,
            upper_arm_z: 0.10,
            forearm_z: 0.18,
            blade_half_width: 0.05,
            blade_half_thickness: 0.003,
            camera_half_extents: Vector3::new(0.015, 0.015, 0.02),
        }
    }
}

/// One link of the robot's collision model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Link {
    /// Shoulder (JT2) to elbow (JT4), capsule.
    UpperArm,
    /// Elbow to wrist (JT6/JT7), capsule.
    Forearm,
    /// Blade 1, cuboid from the wrist to its tip.
    Blade1,
    /// Blade 2 (carrying the camera), cuboid from the wrist to its tip.
    Blade2,
    /// Camera body, cuboid at the camera mount.
    Camera,
}

impl Link {
    /// Lower-case name (`"upper_arm"`, `"forearm"`, `"blade1"`, `"blade2"`, `"camera"`).
    pub fn name(self) -> &'static str {
        match self {
            Link::UpperArm => "upper_arm",
            Link::Forearm => "forearm",
            Link::Blade1 => "blade1",
            Link::Blade2 => "blade2",
            Link::Camera => "camera",
        }
    }
}

/// The smallest signed clearance between the robot and the workspace.
#[derive(Debug, Clone, PartialEq)]
pub struct Clearance {
    /// Signed distance (metres): positive = separation, negative = penetration depth.
    pub distance: f64,
    /// The robot link closest to (or deepest in) an obstacle.
    pub link: Link,
    /// Index of that obstacle in [`Workspace::obstacles`].
    pub obstacle: usize,
}

/// A convex link shape posed in the world.
enum LinkShape {
    Capsule(Capsule),
    Cuboid(Cuboid),
}

impl LinkShape {
    fn shape(&self) -> &dyn Shape {
        match self {
            LinkShape::Capsule(c) => c,
            LinkShape::Cuboid(c) => c,
        }
    }
}

/// The robot's collision model: [`WaferRobot`] kinematics plus [`LinkDims`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotShapes {
    /// The robot (parameters and base pose).
    pub robot: WaferRobot,
    /// Link shape dimensions.
    pub dims: LinkDims,
}

impl RobotShapes {
    /// Creates the collision model after validating the dimensions (finite, radii and half
    /// extents positive).
    pub fn new(robot: WaferRobot, dims: LinkDims) -> Result<Self> {
        check_finite(
            "link dimensions",
            &[
                dims.arm_radius,
                dims.upper_arm_z,
                dims.forearm_z,
                dims.blade_half_width,
                dims.blade_half_thickness,
            ],
        )?;
        check_finite("camera half extents", dims.camera_half_extents.as_slice())?;
        for (what, v) in [
            ("arm radius", dims.arm_radius),
            ("blade half width", dims.blade_half_width),
            ("blade half thickness", dims.blade_half_thickness),
            ("camera half extent x", dims.camera_half_extents.x),
            ("camera half extent y", dims.camera_half_extents.y),
            ("camera half extent z", dims.camera_half_extents.z),
        ] {
            if v <= 0.0 {
                return Err(GeometryError::InvalidParameter {
                    what,
                    value: v,
                    reason: "link radii and half extents must be positive",
                });
            }
        }
        Ok(Self { robot, dims })
    }

    /// The world poses and parry shapes of every link at joints `q` (forward kinematics of
    /// eq. (2.4) for the link end points).
    fn link_shapes(&self, q: &Joints) -> [(Link, Isometry3<f64>, LinkShape); 5] {
        let p = &self.robot.params;
        let d = &self.dims;
        let base = &self.robot.base;
        let t1 = q[0];
        let t12 = t1 + q[1];
        let elbow = Vector3::new(p.l1 * t1.cos(), p.l1 * t1.sin(), 0.0);
        let wrist = elbow + Vector3::new(p.l2 * t12.cos(), p.l2 * t12.sin(), 0.0);
        let capsule = |a: Vector3<f64>, b: Vector3<f64>, z: f64| {
            // A capsule along its local x axis, centred between a and b at height z.
            let mid = 0.5 * (a + b);
            let dir = b - a;
            let yaw = dir.y.atan2(dir.x);
            let pose = base
                * Isometry3::from_parts(
                    Translation3::new(mid.x, mid.y, z),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
                );
            (
                pose,
                LinkShape::Capsule(Capsule::new_x(0.5 * dir.norm(), d.arm_radius)),
            )
        };
        let (pose_ua, ua) = capsule(Vector3::zeros(), elbow, q[4] + d.upper_arm_z);
        let (pose_fa, fa) = capsule(elbow, wrist, q[4] + d.forearm_z);
        let blade = |b: Blade, len: f64| {
            let pose =
                base * self.robot.blade_pose(q, b) * Isometry3::translation(-0.5 * len, 0.0, 0.0);
            let half = Vector::new(0.5 * len, d.blade_half_width, d.blade_half_thickness);
            (pose, LinkShape::Cuboid(Cuboid::new(half)))
        };
        let (pose_b1, b1) = blade(Blade::One, p.l3);
        let (pose_b2, b2) = blade(Blade::Two, p.l4);
        let c = d.camera_half_extents;
        let cam = (
            self.robot.camera_pose(q),
            LinkShape::Cuboid(Cuboid::new(Vector::new(c.x, c.y, c.z))),
        );
        [
            (Link::UpperArm, pose_ua, ua),
            (Link::Forearm, pose_fa, fa),
            (Link::Blade1, pose_b1, b1),
            (Link::Blade2, pose_b2, b2),
            (Link::Camera, cam.0, cam.1),
        ]
    }

    /// The centre points of the link shapes in the world at joints `q`, in the order upper arm,
    /// forearm, blade 1, blade 2, camera (for plotting and tests).
    pub fn link_centres(&self, q: &Joints) -> Result<Vec<(Link, Point3<f64>)>> {
        check_finite("joints", q.as_slice())?;
        Ok(self
            .link_shapes(q)
            .iter()
            .map(|(l, pose, _)| (*l, Point3::from(pose.translation.vector)))
            .collect())
    }

    /// The smallest signed clearance between any link and any obstacle at joints `q`
    /// (the `g_collide` of eq. (6.20)): parry's `distance` between separated shapes, minus the
    /// penetration depth from parry's `contact` when they overlap.
    ///
    /// Returns `Ok(None)` for a workspace without obstacles. Errors: non-finite joints.
    pub fn clearance(&self, q: &Joints, workspace: &Workspace) -> Result<Option<Clearance>> {
        check_finite("joints", q.as_slice())?;
        let links = self.link_shapes(q);
        let mut best: Option<Clearance> = None;
        for (k, obs) in workspace.obstacles.iter().enumerate() {
            let pose_o = to_parry_pose(&obs.pose);
            let h = obs.half_extents;
            let cuboid = Cuboid::new(Vector::new(h.x, h.y, h.z));
            for (link, pose_l, shape) in &links {
                let pose_l = to_parry_pose(pose_l);
                let d = signed_distance(&pose_l, shape.shape(), &pose_o, &cuboid)?;
                if best.as_ref().is_none_or(|b| d < b.distance) {
                    best = Some(Clearance {
                        distance: d,
                        link: *link,
                        obstacle: k,
                    });
                }
            }
        }
        Ok(best)
    }

    /// Whether the robot at `q` keeps at least `margin` metres from every obstacle.
    pub fn is_free(&self, q: &Joints, workspace: &Workspace, margin: f64) -> Result<bool> {
        check_finite("clearance margin", &[margin])?;
        Ok(self
            .clearance(q, workspace)?
            .is_none_or(|c| c.distance >= margin))
    }
}

/// Signed distance between two posed convex shapes: positive separation, negative depth.
fn signed_distance(pos1: &Pose, g1: &dyn Shape, pos2: &Pose, g2: &dyn Shape) -> Result<f64> {
    let unsupported = |_| GeometryError::InvalidParameter {
        what: "shape pair",
        value: f64::NAN,
        reason: "parry does not support this pair of shapes",
    };
    // `query::contact` with a prediction distance beyond any workspace, not `query::distance`:
    // parry 0.31's cuboid–cuboid `distance` returns wrong values for some separated thin boxes
    // (0.147 m where the truth is 0.019 m; `plan::workspace`'s test
    // `parry_cuboid_distance_regression`), while `contact` is right on both sides.
    let contact = query::contact(pos1, g1, pos2, g2, PREDICTION).map_err(unsupported)?;
    Ok(contact.map_or(PREDICTION, |c| c.dist))
}

/// Distances beyond this (m) are reported as this: no robot workspace is that large.
const PREDICTION: f64 = 100.0;

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn thin_box_distances_match_the_closed_form() {
        // Axis-aligned boxes (thin like blades and slot rails): the separation is the norm of
        // the per-axis gaps; overlapping pairs have negative signed distance.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        for _ in 0..500 {
            let h1 = Vector::new(
                rng.random_range(0.01..0.3),
                rng.random_range(0.01..0.3),
                0.002,
            );
            let h2 = Vector::new(
                rng.random_range(0.01..0.3),
                0.003,
                rng.random_range(0.01..0.3),
            );
            let c = Vector::new(
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.4..0.4),
            );
            let p1 = Pose::from_translation(Vector::ZERO);
            let p2 = Pose::from_translation(c);
            let d = signed_distance(&p1, &Cuboid::new(h1), &p2, &Cuboid::new(h2)).unwrap();
            let gap = (c.abs() - h1 - h2).max(Vector::ZERO);
            if gap.length() > 0.0 {
                assert!((d - gap.length()).abs() < 1e-9, "{d} vs {gap:?}");
            } else {
                assert!(d <= 0.0, "{d}");
            }
        }
    }

    fn shapes() -> RobotShapes {
        RobotShapes::new(WaferRobot::default(), LinkDims::default()).unwrap()
    }

    /// A single large box with its -x face at x = `x_face`.
    fn wall_at(x_face: f64) -> Workspace {
        Workspace::new(vec![
            Obstacle::new(
                "wall",
                Isometry3::translation(x_face + 0.5, 0.0, 0.0),
                Vector3::new(0.5, 3.0, 3.0),
            )
            .unwrap(),
        ])
        .unwrap()
    }

    #[test]
    fn straight_arm_clearance_matches_closed_form() {
        // Fully extended along +x: the blades reach x = l1 + l2 + l3 = 1.04 m; the camera body
        // is behind the tip; the forearm capsule ends at x = l1 + l2 + r = 0.76 m.
        let s = shapes();
        let q = Joints::new(0.0, 0.0, 0.0, 0.0, 0.0);
        let c = s.clearance(&q, &wall_at(1.2)).unwrap().unwrap();
        assert_relative_eq!(c.distance, 1.2 - 1.04, epsilon = 1e-9);
        assert!(matches!(c.link, Link::Blade1 | Link::Blade2));
        // Penetration: the wall face at x = 1.0 cuts 40 mm into both blades.
        let c = s.clearance(&q, &wall_at(1.0)).unwrap().unwrap();
        assert_relative_eq!(c.distance, -0.04, epsilon = 1e-9);
        assert!(!s.is_free(&q, &wall_at(1.0), 0.0).unwrap());
        assert!(s.is_free(&q, &wall_at(1.2), 0.1).unwrap());
        assert!(!s.is_free(&q, &wall_at(1.2), 0.2).unwrap());
    }

    #[test]
    fn folded_arm_upper_arm_capsule_distance() {
        // Upper arm along +y (θ1 = 90°), forearm folded back (θ2 = 180°), blades back along -y:
        // the farthest point along +y is the elbow capsule cap at l1 + r.
        let s = shapes();
        let q = Joints::new(
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::PI,
            0.0,
            0.0,
            0.0,
        );
        let ws = Workspace::new(vec![
            Obstacle::new(
                "side",
                Isometry3::translation(0.0, 0.9, 0.0),
                Vector3::new(3.0, 0.4, 3.0),
            )
            .unwrap(),
        ])
        .unwrap();
        let c = s.clearance(&q, &ws).unwrap().unwrap();
        assert_relative_eq!(c.distance, 0.5 - (0.36 + 0.04), epsilon = 1e-9);
        assert!(matches!(c.link, Link::UpperArm | Link::Forearm));
    }

    #[test]
    fn chamber_opening_lets_blade_through_the_slit_but_not_the_wall() {
        let s = shapes();
        let robot = s.robot;
        // Opening at x = 0.9, at the height of blade 2 for h = 0.05.
        let z = 0.05 + robot.params.h02;
        let opening = Isometry3::translation(0.9, 0.0, z);
        let ws = Workspace::chamber_opening(&opening, 0.34, 0.05, 0.05, 0.5).unwrap();
        let q = Joints::new(0.0, 0.0, 0.0, 0.0, 0.05);
        // Blade 2 is centred in the slit: its tip passes the wall plane; blade 1 (40 mm lower)
        // and the camera (35 mm higher) hit the wall.
        let c = s.clearance(&q, &ws).unwrap().unwrap();
        assert!(c.distance < 0.0, "{c:?}");
        // Pulled back 0.2 m, nothing touches.
        let q_back = robot
            .inverse_kinematics(&Isometry3::translation(0.7, 0.0, z), Blade::Two, 0.0)
            .unwrap()[0];
        let c = s.clearance(&q_back, &ws).unwrap().unwrap();
        assert!(c.distance > 0.1, "{c:?}");
    }

    #[test]
    fn bad_inputs_are_rejected() {
        assert!(Obstacle::new("x", Isometry3::identity(), Vector3::new(0.1, 0.0, 0.1)).is_err());
        assert!(
            Obstacle::new(
                "x",
                Isometry3::translation(f64::NAN, 0.0, 0.0),
                Vector3::new(0.1, 0.1, 0.1)
            )
            .is_err()
        );
        assert!(Workspace::chamber_opening(&Isometry3::identity(), -1.0, 0.1, 0.1, 0.1).is_err());
        let dims = LinkDims {
            arm_radius: 0.0,
            ..LinkDims::default()
        };
        assert!(RobotShapes::new(WaferRobot::default(), dims).is_err());
        let s = shapes();
        let q = Joints::new(f64::NAN, 0.0, 0.0, 0.0, 0.0);
        assert!(s.clearance(&q, &wall_at(1.0)).is_err());
        assert!(
            s.clearance(&Joints::zeros(), &Workspace::default())
                .unwrap()
                .is_none()
        );
    }
}
