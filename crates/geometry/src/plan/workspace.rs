//! The planning workspace: the robot's links, blades, carried wafer and camera as parry shapes
//! posed by the kinematics of [`WaferRobot`] (000_3b1454b2b2194811.txt ch. 2.2, eqs. 2.4, 2.7),
//! box obstacles (carriers with slot rails, a chamber wall with its opening, the floor), joint
//! limits, and the signed distance `d_signed(q)` of eq. (2.17) with its gradient in `q`.
//!
//! * Shapes: the upper arm and forearm are capsules (the seed's cylinders), each blade a thin
//!   cuboid from the wrist axis to its tip, the camera a cuboid at the mount of eq. (2.7), and the
//!   wafer a 0.775 mm thick cylinder resting on blade 1. The arm's links sit at different heights
//!   (the blades 40 mm apart), so self-collision is not modelled.
//! * Signed distance: parry's `distance` for separated pairs, minus the penetration depth from
//!   parry's `contact` for overlapping ones; the minimum over every link–obstacle pair.
//! * Gradient: central finite differences of the signed distance (step 1e-6 rad / m). The
//!   minimum over pairs is only piecewise smooth, so an analytic gradient would be the gradient
//!   of the active pair only; the finite difference gives the same on a smooth piece.
//! * Speed: each link carries a bounding sphere and each obstacle its world AABB; a pair whose
//!   sphere–box distance already exceeds the margin (or the best distance so far) is skipped.
//! * Continuous checks: every robot point moves at most `Σ_i r_i |Δq_i|` when the joints move by
//!   `Δq` along a straight segment, with `r_i` the reach of joint `i` ([`PlanWorkspace::reach`]).
//!   Clearance is 1-Lipschitz in point motion, so a segment is certified free by conservative
//!   advancement ([`PlanWorkspace::segment_free`]).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::math::Vector;
use parry3d_f64::query;
use parry3d_f64::shape::{Capsule, Cuboid, Cylinder, Shape};

use crate::collision::{LinkDims, Obstacle, to_parry_pose};
use crate::robot::{Blade, Joints, WaferRobot, wrap_angle};

use super::PlanError;

/// A wafer carried on blade 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarriedWafer {
    /// Radius (m), 0.15 for a 300 mm wafer.
    pub radius: f64,
    /// Thickness (m), 0.775 mm for a 300 mm wafer.
    pub thickness: f64,
    /// Distance of the wafer centre behind the blade-1 tip, along the blade (m).
    pub setback: f64,
}

impl Default for CarriedWafer {
    fn default() -> Self {
        Self {
            radius: 0.15,
            thickness: 0.000_775,
            setback: 0.16,
        }
    }
}

/// Names of the link shapes, in the order of the internal shape array.
pub const LINK_NAMES: [&str; 6] = [
    "upper_arm",
    "forearm",
    "blade1",
    "blade2",
    "camera",
    "wafer",
];

/// The smallest signed distance and the pair that realises it.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanClearance {
    /// Signed distance (m): positive separation, negative penetration depth.
    pub distance: f64,
    /// Name of the closest link (one of [`LINK_NAMES`]).
    pub link: &'static str,
    /// Name of the closest obstacle.
    pub obstacle: String,
}

enum LinkShape {
    Capsule(Capsule),
    Cuboid(Cuboid),
    Cylinder(Cylinder),
}

impl LinkShape {
    fn shape(&self) -> &dyn Shape {
        match self {
            LinkShape::Capsule(c) => c,
            LinkShape::Cuboid(c) => c,
            LinkShape::Cylinder(c) => c,
        }
    }
}

/// A posed link: its shape, world pose and bounding sphere.
struct Posed {
    name: &'static str,
    pose: Isometry3<f64>,
    shape: LinkShape,
    radius: f64,
}

/// Smallest conservative-advancement step (fraction of a segment) before giving up.
const MIN_ADVANCE: f64 = 1e-3;

/// Prediction distance of parry's contact query: distances beyond it are reported as it.
const PREDICTION: f64 = 100.0;

/// Precomputed obstacle data.
#[derive(Debug, Clone)]
struct ObstacleGeom {
    cuboid: Cuboid,
    lo: Vector3<f64>,
    hi: Vector3<f64>,
}

/// The robot, its carried wafer, joint limits and the obstacles (see the module docs).
#[derive(Debug, Clone)]
pub struct PlanWorkspace {
    /// Kinematics (parameters and base pose).
    pub robot: WaferRobot,
    /// Link shape dimensions.
    pub dims: LinkDims,
    /// The wafer on blade 1, if any.
    pub wafer: Option<CarriedWafer>,
    /// Lower joint limits `(θ1, θ2, θ3, θ4, h)`.
    pub lower: Joints,
    /// Upper joint limits.
    pub upper: Joints,
    obstacles: Vec<Obstacle>,
    geoms: Vec<ObstacleGeom>,
    reach: Joints,
}

/// Default joint limits: ±180° on the shoulder and the wrists, ±170° on the elbow, lift 0–0.35 m.
pub fn default_limits() -> (Joints, Joints) {
    let pi = std::f64::consts::PI;
    let e = 170f64.to_radians();
    (
        Joints::new(-pi, -e, -pi, -pi, 0.0),
        Joints::new(pi, e, pi, pi, 0.35),
    )
}

impl PlanWorkspace {
    /// A workspace from the robot, link dimensions, optional wafer, joint limits and obstacles.
    pub fn new(
        robot: WaferRobot,
        dims: LinkDims,
        wafer: Option<CarriedWafer>,
        lower: Joints,
        upper: Joints,
        obstacles: Vec<Obstacle>,
    ) -> Result<Self, PlanError> {
        robot.params.validate()?;
        crate::collision::RobotShapes::new(robot, dims)?;
        if lower.iter().chain(upper.iter()).any(|v| !v.is_finite()) {
            return Err(PlanError::InvalidInput {
                what: "joint limits",
                reason: "non-finite limit".into(),
            });
        }
        if let Some(i) = (0..5).find(|&i| lower[i] >= upper[i]) {
            return Err(PlanError::InvalidInput {
                what: "joint limits",
                reason: format!("joint {i}: lower {} >= upper {}", lower[i], upper[i]),
            });
        }
        if let Some(w) = wafer
            && !(w.radius > 0.0 && w.thickness > 0.0 && w.setback.is_finite())
        {
            return Err(PlanError::InvalidInput {
                what: "wafer",
                reason: format!(
                    "radius {} and thickness {} must be positive",
                    w.radius, w.thickness
                ),
            });
        }
        let geoms = obstacles.iter().map(obstacle_geom).collect();
        let p = &robot.params;
        let hw = dims.blade_half_width.hypot(dims.blade_half_thickness);
        let cam = Vector3::new(p.cam_d, 0.0, p.cam_h).norm() + dims.camera_half_extents.norm();
        let blade1 = p.l3 + hw + wafer.map_or(0.0, |w| (p.l3 - w.setback).abs() + w.radius);
        let blade2 = p.l4 + hw + cam;
        let wrist = blade1.max(blade2).max(dims.arm_radius);
        let reach = Joints::new(
            p.l1 + p.l2 + wrist + dims.arm_radius,
            p.l2 + wrist + dims.arm_radius,
            blade1,
            blade2,
            1.0,
        );
        Ok(Self {
            robot,
            dims,
            wafer,
            lower,
            upper,
            obstacles,
            geoms,
            reach,
        })
    }

    /// The obstacles.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// Adds a box obstacle.
    pub fn push(&mut self, obstacle: Obstacle) {
        self.geoms.push(obstacle_geom(&obstacle));
        self.obstacles.push(obstacle);
    }

    /// Reach `r_i` of each joint: an upper bound on the distance of any robot point from the
    /// axis of joint `i` (1 for the lift), so that a joint step `Δq` moves no point by more than
    /// `Σ r_i |Δq_i|`.
    pub fn reach(&self) -> Joints {
        self.reach
    }

    /// Upper bound on the motion of any robot point for a straight joint step `dq`.
    pub fn sweep_bound(&self, dq: &Joints) -> f64 {
        self.reach.dot(&dq.abs())
    }

    /// The link shapes posed at `q` (the kinematics of [`WaferRobot::blade_pose`] and
    /// [`WaferRobot::camera_pose`]).
    fn posed(&self, q: &Joints) -> Vec<Posed> {
        let p = &self.robot.params;
        let d = &self.dims;
        let base = &self.robot.base;
        let t_b1 = self.robot.blade_pose(q, Blade::One);
        let t_b2 = self.robot.blade_pose(q, Blade::Two);
        // The wrist is the blade tip moved back by the blade length along the blade.
        let wrist = (t_b1 * Translation3::new(-p.l3, 0.0, 0.0))
            .translation
            .vector;
        let elbow = Vector3::new(p.l1 * q[0].cos(), p.l1 * q[0].sin(), 0.0);
        let capsule = |name, a: Vector3<f64>, b: Vector3<f64>, z: f64| {
            let mid = 0.5 * (a + b);
            let dir = b - a;
            let half = 0.5 * dir.xy().norm();
            let pose = base
                * Isometry3::from_parts(
                    Translation3::new(mid.x, mid.y, z),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), dir.y.atan2(dir.x)),
                );
            Posed {
                name,
                pose,
                shape: LinkShape::Capsule(Capsule::new_x(half, d.arm_radius)),
                radius: half + d.arm_radius,
            }
        };
        let blade = |name, t: &Isometry3<f64>, len: f64| {
            let half = Vector3::new(0.5 * len, d.blade_half_width, d.blade_half_thickness);
            Posed {
                name,
                pose: base * t * Translation3::new(-0.5 * len, 0.0, 0.0),
                shape: LinkShape::Cuboid(Cuboid::new(Vector::new(half.x, half.y, half.z))),
                radius: half.norm(),
            }
        };
        let c = d.camera_half_extents;
        let mut out = vec![
            capsule("upper_arm", Vector3::zeros(), elbow, q[4] + d.upper_arm_z),
            capsule(
                "forearm",
                elbow,
                Vector3::new(wrist.x, wrist.y, 0.0),
                q[4] + d.forearm_z,
            ),
            blade("blade1", &t_b1, p.l3),
            blade("blade2", &t_b2, p.l4),
            Posed {
                name: "camera",
                pose: self.robot.camera_pose(q),
                shape: LinkShape::Cuboid(Cuboid::new(Vector::new(c.x, c.y, c.z))),
                radius: c.norm(),
            },
        ];
        if let Some(w) = self.wafer {
            // Parry's cylinder axis is its local y: turn it to the blade's z.
            let pose = base
                * t_b1
                * Isometry3::from_parts(
                    Translation3::new(-w.setback, 0.0, d.blade_half_thickness + 0.5 * w.thickness),
                    UnitQuaternion::from_axis_angle(
                        &Vector3::x_axis(),
                        std::f64::consts::FRAC_PI_2,
                    ),
                );
            out.push(Posed {
                name: "wafer",
                pose,
                shape: LinkShape::Cylinder(Cylinder::new(0.5 * w.thickness, w.radius)),
                radius: w.radius.hypot(0.5 * w.thickness),
            });
        }
        out
    }

    /// Centres of the link shapes at `q` (for plots of the swept motion).
    pub fn link_centres(&self, q: &Joints) -> Vec<(&'static str, Point3<f64>)> {
        self.posed(q)
            .into_iter()
            .map(|l| (l.name, Point3::from(l.pose.translation.vector)))
            .collect()
    }

    /// The exact minimum signed distance between the robot at `q` and the obstacles, eq. (2.17)'s
    /// `min d_signed(A, B)`; `None` without obstacles.
    pub fn clearance(&self, q: &Joints) -> Result<Option<PlanClearance>, PlanError> {
        check_joints(q)?;
        let links = self.posed(q);
        let mut best: Option<(f64, usize, usize)> = None;
        for (li, l) in links.iter().enumerate() {
            let c = l.pose.translation.vector;
            for (k, g) in self.geoms.iter().enumerate() {
                let lb = box_distance(&c, g) - l.radius;
                if best.is_some_and(|b| lb >= b.0) {
                    continue;
                }
                let d = self.pair_distance(l, k)?;
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, li, k));
                }
            }
        }
        Ok(best.map(|(distance, li, k)| PlanClearance {
            distance,
            link: links[li].name,
            obstacle: self.obstacles[k].name.clone(),
        }))
    }

    /// The minimum signed distance (m), `+∞` without obstacles.
    pub fn signed_distance(&self, q: &Joints) -> Result<f64, PlanError> {
        Ok(self.clearance(q)?.map_or(f64::INFINITY, |c| c.distance))
    }

    /// The signed distance and its gradient in `q` by central finite differences (step 1e-6).
    pub fn distance_gradient(&self, q: &Joints) -> Result<(f64, Joints), PlanError> {
        let d0 = self.signed_distance(q)?;
        let h = 1e-6;
        let mut g = Joints::zeros();
        for i in 0..5 {
            let mut qp = *q;
            let mut qm = *q;
            qp[i] += h;
            qm[i] -= h;
            g[i] = (self.signed_distance(&qp)? - self.signed_distance(&qm)?) / (2.0 * h);
        }
        Ok((d0, g))
    }

    /// Whether the robot at `q` is inside the joint limits and keeps at least `margin` from every
    /// obstacle. Fast path: pairs whose bounding sphere is farther than `margin` from the
    /// obstacle's box are not passed to parry.
    pub fn is_free(&self, q: &Joints, margin: f64) -> bool {
        if !self.within_limits(q) {
            return false;
        }
        self.free_distance(q, margin).is_some()
    }

    /// `Some(lower bound on the clearance)` if `q` keeps `margin`, else `None` (no limit check).
    pub fn free_distance(&self, q: &Joints, margin: f64) -> Option<f64> {
        let links = self.posed(q);
        let mut best = f64::INFINITY;
        for l in &links {
            let c = l.pose.translation.vector;
            for (k, g) in self.geoms.iter().enumerate() {
                let lb = box_distance(&c, g) - l.radius;
                if lb >= best {
                    continue;
                }
                if lb > margin {
                    best = best.min(lb);
                    continue;
                }
                let d = self.pair_distance(l, k).unwrap_or(f64::NEG_INFINITY);
                if d < margin {
                    return None;
                }
                best = best.min(d);
            }
        }
        Some(best)
    }

    /// Whether `q` is inside the joint limits.
    pub fn within_limits(&self, q: &Joints) -> bool {
        (0..5).all(|i| q[i] >= self.lower[i] && q[i] <= self.upper[i])
    }

    /// Whether the straight joint segment `a → b` keeps `margin` everywhere, certified by
    /// conservative advancement: from a point with clearance lower bound `d ≥ margin`, a step of
    /// `(d − margin) / L` (with `L` = [`Self::sweep_bound`] of the whole segment) stays above
    /// `margin`. A segment whose steps shrink below 1/1000 of its length is reported not free
    /// (conservative: at most 1000 checks per segment).
    pub fn segment_free(&self, a: &Joints, b: &Joints, margin: f64) -> bool {
        self.segment_free_counted(a, b, margin, &mut 0)
    }

    /// [`Self::segment_free`], adding the number of configuration checks to `checks`.
    pub fn segment_free_counted(
        &self,
        a: &Joints,
        b: &Joints,
        margin: f64,
        checks: &mut u64,
    ) -> bool {
        if !self.within_limits(a) || !self.within_limits(b) {
            return false;
        }
        let l = self.sweep_bound(&(b - a));
        let mut s = 0.0;
        let mut steps = 0usize;
        loop {
            let q = a + (b - a) * s;
            *checks += 1;
            let Some(d) = self.free_distance(&q, margin) else {
                return false;
            };
            if l <= 0.0 {
                return true;
            }
            let ds = (d - margin) / l;
            if ds < MIN_ADVANCE || steps > 1000 {
                return false;
            }
            if s + ds >= 1.0 {
                *checks += 1;
                return self.free_distance(b, margin).is_some();
            }
            s += ds;
            steps += 1;
        }
    }

    fn pair_distance(&self, l: &Posed, k: usize) -> Result<f64, PlanError> {
        let pl = to_parry_pose(&l.pose);
        let po = to_parry_pose(&self.obstacles[k].pose);
        let g = &self.geoms[k];
        let unsupported = |_| PlanError::InvalidInput {
            what: "shape pair",
            reason: "parry does not support this pair of shapes".into(),
        };
        // `query::contact` with a large prediction distance, not `query::distance`: parry 0.31's
        // cuboid–cuboid `distance` returns wrong values for some separated thin boxes (see the
        // test `parry_cuboid_distance_regression`), while `contact` is right on both sides.
        let contact = query::contact(&pl, l.shape.shape(), &po, &g.cuboid, PREDICTION)
            .map_err(unsupported)?;
        Ok(contact.map_or(PREDICTION, |c| c.dist))
    }

    /// Checks a configuration given by a user: finite, within the limits and `margin` clear.
    /// The error names the binding constraint.
    pub fn require_free(
        &self,
        which: &'static str,
        q: &Joints,
        margin: f64,
    ) -> Result<(), PlanError> {
        check_joints(q)?;
        if let Some(i) = (0..5).find(|&i| q[i] < self.lower[i] || q[i] > self.upper[i]) {
            return Err(PlanError::InCollision {
                which,
                constraint: format!(
                    "joint {i} = {:.6} outside its limits [{:.6}, {:.6}]",
                    q[i], self.lower[i], self.upper[i]
                ),
                clearance: f64::NAN,
                margin,
            });
        }
        if let Some(c) = self.clearance(q)?
            && c.distance < margin
        {
            return Err(PlanError::InCollision {
                which,
                constraint: format!("{} against {}", c.link, c.obstacle),
                clearance: c.distance,
                margin,
            });
        }
        Ok(())
    }
}

fn check_joints(q: &Joints) -> Result<(), PlanError> {
    crate::error::check_finite("joints", q.as_slice())?;
    Ok(())
}

fn obstacle_geom(o: &Obstacle) -> ObstacleGeom {
    let h = o.half_extents;
    let r = o.pose.rotation.to_rotation_matrix();
    let ext = r.matrix().abs() * h;
    let c = o.pose.translation.vector;
    ObstacleGeom {
        cuboid: Cuboid::new(Vector::new(h.x, h.y, h.z)),
        lo: c - ext,
        hi: c + ext,
    }
}

/// Euclidean distance from a point to an axis-aligned box (0 inside).
fn box_distance(p: &Vector3<f64>, g: &ObstacleGeom) -> f64 {
    let dx = (g.lo.x - p.x).max(p.x - g.hi.x).max(0.0);
    let dy = (g.lo.y - p.y).max(p.y - g.hi.y).max(0.0);
    let dz = (g.lo.z - p.z).max(p.z - g.hi.z).max(0.0);
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// A named configuration of the default scene.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPose {
    /// Name (`"home"`, `"carrier_a"`, `"carrier_b"`, `"chamber"`).
    pub name: String,
    /// Joints.
    pub q: Joints,
}

/// Geometry of the default scene (see [`default_scene`]).
const CARRIER_DEPTH: f64 = 0.34;
const CARRIER_HALF_WIDTH: f64 = 0.17;
const SLOT_PITCH: f64 = 0.04;
const N_SLOTS: usize = 5;
const SLOT0_Z: f64 = 0.40;

/// A wafer carrier (FOUP): back, side, top and bottom walls and a pair of slot rails per slot.
/// `front` is the centre of the open face at the height of slot 0; its x axis points into the
/// carrier.
pub fn carrier(name: &str, front: &Isometry3<f64>) -> Result<Vec<Obstacle>, PlanError> {
    let t = 0.01;
    let (d, w) = (CARRIER_DEPTH, CARRIER_HALF_WIDTH);
    let z_lo = -0.03;
    let z_hi = SLOT_PITCH * N_SLOTS as f64 + 0.02;
    let zc = 0.5 * (z_lo + z_hi);
    let hz = 0.5 * (z_hi - z_lo);
    let at = |x: f64, y: f64, z: f64| front * Isometry3::translation(x, y, z);
    let mut out = vec![
        Obstacle::new(
            format!("{name} back"),
            at(d + t, 0.0, zc),
            Vector3::new(t, w + 2.0 * t, hz),
        )?,
        Obstacle::new(
            format!("{name} left side"),
            at(0.5 * d, w + t, zc),
            Vector3::new(0.5 * d, t, hz),
        )?,
        Obstacle::new(
            format!("{name} right side"),
            at(0.5 * d, -w - t, zc),
            Vector3::new(0.5 * d, t, hz),
        )?,
        Obstacle::new(
            format!("{name} top"),
            at(0.5 * d, 0.0, z_hi + t),
            Vector3::new(0.5 * d + t, w + 2.0 * t, t),
        )?,
        Obstacle::new(
            format!("{name} bottom"),
            at(0.5 * d, 0.0, z_lo - t),
            Vector3::new(0.5 * d + t, w + 2.0 * t, t),
        )?,
    ];
    for s in 0..N_SLOTS {
        let z = SLOT_PITCH * s as f64 - 0.001;
        for (side, y) in [("left", w - 0.0125), ("right", -w + 0.0125)] {
            out.push(Obstacle::new(
                format!("{name} slot {s} {side} rail"),
                at(0.5 * d + 0.01, y, z),
                Vector3::new(0.5 * d - 0.01, 0.0125, 0.001),
            )?);
        }
    }
    Ok(out)
}

/// The default scene of the seed's kind (Fig. 2.6): the robot at the origin carrying a wafer on
/// blade 1, two carriers (FOUPs) with five slots each at ±40° in front of it, a process chamber
/// behind it (a wall with a 340 × 60 mm slit opening), and the floor. Returns the workspace and
/// the named poses `home` (folded), `carrier_a` and `carrier_b` (blade 1 lined up 60 mm in front
/// of slot 0 and slot 2, below the wafer's rails) and `chamber` (blade 1 60 mm in front of the
/// slit, level with it).
pub fn default_scene() -> Result<(PlanWorkspace, Vec<NamedPose>), PlanError> {
    let robot = WaferRobot::default();
    let dims = LinkDims::default();
    let (lower, upper) = default_limits();
    let mut obstacles = vec![Obstacle::new(
        "floor",
        Isometry3::translation(0.0, 0.0, -0.05),
        Vector3::new(2.0, 2.0, 0.05),
    )?];
    let carrier_front = |bearing: f64| {
        Isometry3::from_parts(
            Translation3::new(0.72 * bearing.cos(), 0.72 * bearing.sin(), SLOT0_Z),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), bearing),
        )
    };
    let (ba, bb) = (40f64.to_radians(), -40f64.to_radians());
    obstacles.extend(carrier("carrier A", &carrier_front(ba))?);
    obstacles.extend(carrier("carrier B", &carrier_front(bb))?);
    let z_chamber = 0.45;
    let opening = Isometry3::from_parts(
        Translation3::new(-0.78, 0.0, z_chamber),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
    );
    obstacles.extend(
        crate::collision::Workspace::chamber_opening(&opening, 0.34, 0.06, 0.05, 0.35)?
            .obstacles()
            .iter()
            .map(|o| Obstacle {
                name: format!("chamber {}", o.name),
                ..o.clone()
            }),
    );
    let ws = PlanWorkspace::new(
        robot,
        dims,
        Some(CarriedWafer::default()),
        lower,
        upper,
        obstacles,
    )?;
    // Blade 1 lined up in front of a target; blade 2 points the other way (θ4 = θ3 + π).
    let approach = |bearing: f64, dist: f64, z: f64| -> Result<Joints, PlanError> {
        let t = Isometry3::from_parts(
            Translation3::new(dist * bearing.cos(), dist * bearing.sin(), z),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), bearing),
        );
        let sols = robot.inverse_kinematics(&t, Blade::One, 0.0)?;
        // The elbow-right solution (θ2 > 0) for every target, so that transfers are comparable.
        let mut q = sols
            .into_iter()
            .max_by(|a, b| a[1].total_cmp(&b[1]))
            .ok_or_else(|| PlanError::InvalidInput {
                what: "default scene",
                reason: "no inverse-kinematics solution".into(),
            })?;
        q[3] = wrap_angle(q[2] + std::f64::consts::PI);
        Ok(q)
    };
    let h1 = robot.params.h01;
    let below_slot = 0.012;
    let poses = vec![
        NamedPose {
            name: "home".into(),
            q: Joints::new(0.0, 2.6, -2.6, 2.6 - std::f64::consts::PI, 0.15),
        },
        NamedPose {
            name: "carrier_a".into(),
            q: approach(ba, 0.66, SLOT0_Z - below_slot)?,
        },
        NamedPose {
            name: "carrier_b".into(),
            q: approach(bb, 0.66, SLOT0_Z + 2.0 * SLOT_PITCH - below_slot)?,
        },
        NamedPose {
            name: "chamber".into(),
            q: approach(std::f64::consts::PI, 0.72, z_chamber)?,
        },
    ];
    let _ = h1;
    Ok((ws, poses))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_scene_poses_are_free() {
        let (ws, poses) = default_scene().unwrap();
        for p in &poses {
            let c = ws.clearance(&p.q).unwrap().unwrap();
            assert!(c.distance > 0.005, "{} {:?} {:?}", p.name, p.q, c);
            assert!(ws.within_limits(&p.q), "{} {:?}", p.name, p.q);
        }
    }

    #[test]
    fn gradient_matches_distance_change() {
        let (ws, poses) = default_scene().unwrap();
        let q = poses[1].q + Joints::new(0.05, -0.1, 0.07, 0.2, 0.01);
        let (d, g) = ws.distance_gradient(&q).unwrap();
        let dq = Joints::new(1e-4, -5e-5, 2e-5, 1e-5, 1e-5) * 1e-3;
        let d2 = ws.signed_distance(&(q + dq)).unwrap();
        assert!((d2 - d - g.dot(&dq)).abs() < 1e-10, "{d} {d2} {g:?}");
    }

    #[test]
    fn fast_check_agrees_with_exact_clearance_and_sweep_bound_holds() {
        let (ws, _) = default_scene().unwrap();
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let q = Joints::from_fn(|i, _| ws.lower[i] + (ws.upper[i] - ws.lower[i]) * next());
            let d = ws.signed_distance(&q).unwrap();
            assert_eq!(ws.is_free(&q, 0.01), d >= 0.01, "{q:?} {d}");
            // Lipschitz bound of the sweep: a small step changes the clearance by at most L|Δq|.
            let dq = Joints::from_fn(|_, _| 0.02 * (next() - 0.5));
            let d2 = ws.signed_distance(&(q + dq)).unwrap();
            assert!(
                (d2 - d).abs() <= ws.sweep_bound(&dq) + 1e-9,
                "{d} {d2} {:?} {:?} {q:?} {dq:?}",
                ws.clearance(&q).unwrap(),
                ws.clearance(&(q + dq)).unwrap()
            );
        }
    }

    /// Parry 0.31's `query::distance` between the blade-2 cuboid and the carrier's bottom plate
    /// at this configuration returns 0.1469 m; the true distance (brute force over the blade's
    /// surface) is 0.0194 m. The workspace uses `query::contact`, which is right.
    #[test]
    fn parry_cuboid_distance_regression() {
        use parry3d_f64::query::PointQuery;
        let (ws, _) = default_scene().unwrap();
        let q = Joints::new(-0.245356, -0.512876, -2.142285, -2.175487, 0.037568);
        let links = ws.posed(&q);
        let blade2 = links.iter().find(|l| l.name == "blade2").unwrap();
        let k = ws
            .obstacles
            .iter()
            .position(|o| o.name == "carrier B bottom")
            .unwrap();
        let LinkShape::Cuboid(c) = &blade2.shape else {
            panic!()
        };
        let pl = to_parry_pose(&blade2.pose);
        let po = to_parry_pose(&ws.obstacles[k].pose);
        let h = c.half_extents;
        let mut brute = f64::INFINITY;
        for i in 0..=80 {
            for j in 0..=80 {
                for s in [-1.0, 1.0] {
                    let lp = Vector::new(
                        h.x * (i as f64 / 40.0 - 1.0),
                        h.y * (j as f64 / 40.0 - 1.0),
                        h.z * s,
                    );
                    brute = brute.min(ws.geoms[k].cuboid.distance_to_point(&po, pl * lp, true));
                }
            }
        }
        let ours = ws.pair_distance(blade2, k).unwrap();
        assert!((ours - brute).abs() < 1e-6, "{ours} {brute}");
        let parry = query::distance(&pl, c, &po, &ws.geoms[k].cuboid)
            .unwrap()
            .distance;
        assert!(
            parry > brute + 0.1,
            "parry's distance was fixed ({parry} vs {brute}): drop the workaround note"
        );
    }
}
