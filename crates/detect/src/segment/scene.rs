//! A scene simulator for coloured point clouds: a tilting planar laser scanner of the seed's
//! kind (004_815695db12a6b16c.txt ch. 4.3: Hokuyo UTM-30LX, 270° planes at 40 Hz with ¼°
//! beams, nodded by a servo of ⅓° resolution) and a camera on the same mount, in scenes of
//! labelled objects (the hallway of Fig. 4.4a–h with a grey bin on a grey floor and a blue bin
//! against a blue wall, boxes, a ramp, and the sunlit hill of Fig. 4.4i–j).
//!
//! Frames: the world has z up with the floor at z = 0; the lidar frame has x forward, y left,
//! z up, its origin on the servo axis; the scan plane at servo angle φ is the lidar's xy plane
//! rotated by φ about its y axis (φ > 0 tilts it down), so beam θ points along
//! `R_y(φ) [cos θ, sin θ, 0]ᵀ` (ch. 4.1, `T_i(φ) r_i`).
//!
//! Colours are `255 · albedo · (ambient + sun · max(0, n·s) · lit)`, clipped to 255 (a sun
//! bright enough saturates the camera, as on the hill), `lit` false in the shadow of another
//! object, plus Gaussian pixel noise.

use autoteach_geometry::camera::{Camera, CameraModel};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector2, Vector3};

use crate::{DetectError, Result};

/// A small deterministic generator (SplitMix64) with Gaussian draws (Box–Muller).
#[derive(Debug, Clone)]
pub struct SimRng {
    state: u64,
    spare: Option<f64>,
}

impl SimRng {
    /// A generator for `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed ^ 0x9E37_79B9_7F4A_7C15,
            spare: None,
        }
    }

    /// Uniform on [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * a.sin());
        r * a.cos()
    }
}

/// A solid.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A box with half-extents `half` in its own frame, placed by `pose` (box → world).
    Cuboid {
        /// Box → world.
        pose: Isometry3<f64>,
        /// Half-extents (metres).
        half: [f64; 3],
    },
    /// An upright cylinder with a closed top, standing on `base`.
    Cylinder {
        /// Centre of the bottom disc.
        base: [f64; 3],
        /// Radius (metres).
        radius: f64,
        /// Height (metres).
        height: f64,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius (metres).
        radius: f64,
    },
}

/// A labelled object.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// Name (for plots and messages).
    pub name: String,
    /// Geometry.
    pub shape: Shape,
    /// Diffuse reflectance per channel, in [0, 1].
    pub albedo: [f64; 3],
    /// Ground-truth segment label (objects may share one, e.g. a hill and its ground).
    pub label: u32,
}

/// Illumination.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lighting {
    /// Ambient (sky or room) light; 1.0 renders the albedo.
    pub ambient: f64,
    /// Unit direction towards the sun, and its intensity (0 for none).
    pub sun: ([f64; 3], f64),
}

/// A scene: objects and light.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The objects.
    pub objects: Vec<Object>,
    /// The light.
    pub lighting: Lighting,
}

/// A ray–scene intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance for a unit direction).
    pub t: f64,
    /// Outward unit surface normal (world).
    pub normal: Vector3<f64>,
    /// Index of the object hit.
    pub object: usize,
}

fn hit_cuboid(
    pose: &Isometry3<f64>,
    half: &[f64; 3],
    o: &Point3<f64>,
    d: &Vector3<f64>,
) -> Option<(f64, Vector3<f64>)> {
    let ol = pose.inverse_transform_point(o);
    let dl = pose.inverse_transform_vector(d);
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut axis = 0usize;
    let mut sign = 0.0;
    for (k, &hk) in half.iter().enumerate() {
        if dl[k].abs() < 1e-15 {
            if ol[k].abs() > hk {
                return None;
            }
            continue;
        }
        let inv = 1.0 / dl[k];
        let (a, b) = ((-hk - ol[k]) * inv, (hk - ol[k]) * inv);
        let (near, far) = if a < b { (a, b) } else { (b, a) };
        if near > t0 {
            t0 = near;
            axis = k;
            sign = -dl[k].signum();
        }
        t1 = t1.min(far);
    }
    if t0 > t1 || t0 <= 1e-9 {
        return None; // A miss, or the origin inside the box (no outer surface ahead).
    }
    let mut nl = Vector3::zeros();
    nl[axis] = sign;
    Some((t0, pose.rotation * nl))
}

fn hit_cylinder(
    base: &[f64; 3],
    radius: f64,
    height: f64,
    o: &Point3<f64>,
    d: &Vector3<f64>,
) -> Option<(f64, Vector3<f64>)> {
    let (ox, oy) = (o.x - base[0], o.y - base[1]);
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-15 {
        let b = ox * d.x + oy * d.y;
        let c = ox * ox + oy * oy - radius * radius;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let z = o.z + t * d.z - base[2];
            if t > 1e-9 && (0.0..=height).contains(&z) {
                let n = Vector3::new(ox + t * d.x, oy + t * d.y, 0.0) / radius;
                best = Some((t, n));
            }
        }
    }
    if d.z.abs() > 1e-15 {
        let t = (base[2] + height - o.z) / d.z;
        let (x, y) = (ox + t * d.x, oy + t * d.y);
        if t > 1e-9 && x * x + y * y <= radius * radius && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, Vector3::new(0.0, 0.0, 1.0)));
        }
    }
    best
}

fn hit_sphere(
    center: &[f64; 3],
    radius: f64,
    o: &Point3<f64>,
    d: &Vector3<f64>,
) -> Option<(f64, Vector3<f64>)> {
    let oc = o.coords - Vector3::new(center[0], center[1], center[2]);
    let a = d.norm_squared();
    let b = oc.dot(d);
    let c = oc.norm_squared() - radius * radius;
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / a;
    (t > 1e-9).then(|| (t, (oc + t * d) / radius))
}

impl Scene {
    /// The nearest intersection of the ray `o + t d` (t > 0) with the scene.
    pub fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (k, obj) in self.objects.iter().enumerate() {
            let h = match &obj.shape {
                Shape::Cuboid { pose, half } => hit_cuboid(pose, half, o, d),
                Shape::Cylinder {
                    base,
                    radius,
                    height,
                } => hit_cylinder(base, *radius, *height, o, d),
                Shape::Sphere { center, radius } => hit_sphere(center, *radius, o, d),
            };
            if let Some((t, normal)) = h
                && best.is_none_or(|b| t < b.t)
            {
                best = Some(Hit {
                    t,
                    normal,
                    object: k,
                });
            }
        }
        best
    }

    /// Noise-free colour (0–255 per channel, clipped) of the surface at `hit` on ray `o + t d`.
    pub fn radiance(&self, o: &Point3<f64>, d: &Vector3<f64>, hit: &Hit) -> [f64; 3] {
        let obj = &self.objects[hit.object];
        let (s, sun) = self.lighting.sun;
        let mut light = self.lighting.ambient;
        if sun > 0.0 {
            let s = Vector3::new(s[0], s[1], s[2]);
            let cos = hit.normal.dot(&s);
            if cos > 0.0 {
                let p = o + d * hit.t + hit.normal * 1e-6;
                if self.intersect(&p, &s).is_none() {
                    light += sun * cos;
                }
            }
        }
        obj.albedo.map(|a| (255.0 * a * light).clamp(0.0, 255.0))
    }
}

/// The tilting planar scanner (ch. 4.3).
#[derive(Debug, Clone, PartialEq)]
pub struct Scanner {
    /// Field of view of a scan plane (degrees), centred on the lidar's x axis.
    pub fov_deg: f64,
    /// Angle between beams (degrees).
    pub beam_step_deg: f64,
    /// Scan planes per second.
    pub line_rate_hz: f64,
    /// Servo angle of the first plane (degrees; > 0 tilts down).
    pub tilt_start_deg: f64,
    /// Servo angle of the last plane (degrees).
    pub tilt_end_deg: f64,
    /// Servo speed (degrees per second): planes are `speed / rate` apart.
    pub tilt_speed_deg_s: f64,
    /// Servo resolution (degrees): commanded angles are rounded to it.
    pub servo_resolution_deg: f64,
    /// Standard deviation of the range noise (metres).
    pub range_sigma: f64,
    /// Largest range (metres); farther surfaces give no return.
    pub max_range: f64,
    /// Lidar → world.
    pub t_world_lidar: Isometry3<f64>,
}

impl Scanner {
    /// A Hokuyo UTM-30LX (270°, ¼°, 40 Hz, σ = 1 cm, 30 m) on an AX-12 servo (⅓°) nodding from
    /// −10° to 50° at 20°/s (½° between planes), 1 m above the floor.
    pub fn hokuyo() -> Self {
        Self {
            fov_deg: 270.0,
            beam_step_deg: 0.25,
            line_rate_hz: 40.0,
            tilt_start_deg: -10.0,
            tilt_end_deg: 50.0,
            tilt_speed_deg_s: 20.0,
            servo_resolution_deg: 1.0 / 3.0,
            range_sigma: 0.01,
            max_range: 30.0,
            t_world_lidar: Isometry3::translation(0.0, 0.0, 1.0),
        }
    }

    fn check(&self) -> Result<()> {
        let pos = [
            ("fov_deg", self.fov_deg),
            ("beam_step_deg", self.beam_step_deg),
            ("line_rate_hz", self.line_rate_hz),
            ("tilt_speed_deg_s", self.tilt_speed_deg_s),
            ("max_range", self.max_range),
        ];
        for (what, value) in pos {
            if !(value.is_finite() && value > 0.0) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "must be positive and finite",
                });
            }
        }
        for (what, value) in [
            ("servo_resolution_deg", self.servo_resolution_deg),
            ("range_sigma", self.range_sigma),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "must be non-negative and finite",
                });
            }
        }
        if !(self.tilt_end_deg.is_finite()
            && self.tilt_start_deg.is_finite()
            && self.tilt_end_deg >= self.tilt_start_deg)
        {
            return Err(DetectError::InvalidParameter {
                what: "tilt_end_deg",
                value: self.tilt_end_deg,
                reason: "must be finite and not below tilt_start_deg",
            });
        }
        Ok(())
    }

    /// Number of beams per plane.
    pub fn beams(&self) -> usize {
        (self.fov_deg / self.beam_step_deg + 1e-9).floor() as usize + 1
    }

    /// Servo angles of the planes (radians), rounded to the servo resolution.
    pub fn tilts(&self) -> Vec<f64> {
        let step = self.tilt_speed_deg_s / self.line_rate_hz;
        let lines = ((self.tilt_end_deg - self.tilt_start_deg) / step + 1e-9).floor() as usize + 1;
        (0..lines)
            .map(|l| {
                let a = self.tilt_start_deg + l as f64 * step;
                let a = if self.servo_resolution_deg > 0.0 {
                    (a / self.servo_resolution_deg).round() * self.servo_resolution_deg
                } else {
                    a
                };
                a.to_radians()
            })
            .collect()
    }
}

/// An organised scan: `lines × beams` rows, plane by plane.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Scan planes.
    pub lines: usize,
    /// Beams per plane.
    pub beams: usize,
    /// Measured points (lidar frame); NaN where there is no return.
    pub points: Vec<[f64; 3]>,
    /// Noise-free points (lidar frame); NaN where there is no return.
    pub true_points: Vec<[f64; 3]>,
    /// Surface normals of the hit surfaces (lidar frame); zero where there is no return.
    pub true_normals: Vec<[f64; 3]>,
    /// Ground-truth labels; `u32::MAX` where there is no return.
    pub labels: Vec<u32>,
    /// The colour the camera would record at each point if it saw it (noisy, 8-bit).
    pub true_colors: Vec<[u8; 3]>,
}

fn noisy_u8(c: [f64; 3], sigma: f64, rng: &mut SimRng) -> [u8; 3] {
    c.map(|v| (v + sigma * rng.normal()).round().clamp(0.0, 255.0) as u8)
}

/// Scans `scene` with `scanner`; `color_sigma` is the pixel noise of [`Scan::true_colors`].
pub fn scan(scene: &Scene, scanner: &Scanner, color_sigma: f64, seed: u64) -> Result<Scan> {
    scanner.check()?;
    let mut rng = SimRng::new(seed);
    let tilts = scanner.tilts();
    let beams = scanner.beams();
    let lines = tilts.len();
    let n = lines * beams;
    let mut out = Scan {
        lines,
        beams,
        points: vec![[f64::NAN; 3]; n],
        true_points: vec![[f64::NAN; 3]; n],
        true_normals: vec![[0.0; 3]; n],
        labels: vec![u32::MAX; n],
        true_colors: vec![[0; 3]; n],
    };
    let origin_w = scanner.t_world_lidar * Point3::origin();
    let half = scanner.fov_deg.to_radians() / 2.0;
    let step = scanner.beam_step_deg.to_radians();
    for (l, &phi) in tilts.iter().enumerate() {
        let rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), phi);
        for b in 0..beams {
            let theta = -half + b as f64 * step;
            let dl = rot * Vector3::new(theta.cos(), theta.sin(), 0.0);
            let dw = scanner.t_world_lidar * dl;
            let Some(hit) = scene.intersect(&origin_w, &dw) else {
                continue;
            };
            if hit.t > scanner.max_range {
                continue;
            }
            let i = l * beams + b;
            let r = hit.t + scanner.range_sigma * rng.normal();
            out.points[i] = (dl * r).into();
            out.true_points[i] = (dl * hit.t).into();
            out.true_normals[i] = scanner
                .t_world_lidar
                .inverse_transform_vector(&hit.normal)
                .into();
            out.labels[i] = scene.objects[hit.object].label;
            out.true_colors[i] =
                noisy_u8(scene.radiance(&origin_w, &dw, &hit), color_sigma, &mut rng);
        }
    }
    Ok(out)
}

/// Renders the image of `camera` at `t_world_cam` (camera → world): row-major RGB bytes; pixels
/// that see nothing (or that the lens model cannot unproject) are black.
pub fn render(
    scene: &Scene,
    camera: &Camera,
    t_world_cam: &Isometry3<f64>,
    sigma: f64,
    seed: u64,
) -> Vec<u8> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let mut rng = SimRng::new(seed ^ 0xC0FF_EE00);
    let o = t_world_cam * Point3::origin();
    let mut img = vec![0u8; w * h * 3];
    for v in 0..h {
        for u in 0..w {
            let Ok(ray) = camera.unproject(&Vector2::new(u as f64, v as f64)) else {
                continue;
            };
            let d = t_world_cam * ray;
            let c = match scene.intersect(&o, &d) {
                Some(hit) => noisy_u8(scene.radiance(&o, &d, &hit), sigma, &mut rng),
                None => [0; 3],
            };
            img[(v * w + u) * 3..(v * w + u) * 3 + 3].copy_from_slice(&c);
        }
    }
    img
}

/// The camera of the seed's rig (ch. 4.3: Firefly MV, 752 × 480, 111° Tamron lens), modelled
/// as Brown–Conrady with mild barrel distortion.
pub fn firefly_camera() -> Result<Camera> {
    Ok(Camera::new(
        CameraModel::BrownConrady,
        &[300.0, 300.0, 376.0, 240.0, -0.12, 0.02, 3e-4, -2e-4, 0.0],
        752,
        480,
    )?)
}

/// The camera's pose on the rig, lidar → camera: 8 cm above and 3 cm ahead of the servo axis,
/// looking along the lidar's x axis and pitched down by 15°.
pub fn default_t_cam_lidar() -> Isometry3<f64> {
    // Camera axes in the lidar frame: x_c = −y_l, y_c = −z_l, z_c = x_l, then pitch down.
    let base = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
        0.0, -1.0, 0.0, //
        0.0, 0.0, -1.0, //
        1.0, 0.0, 0.0,
    ));
    let pitch = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), 15f64.to_radians());
    let r = pitch * base;
    let c = Vector3::new(0.03, 0.0, 0.08);
    let t = -(r * c);
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

fn cuboid(
    name: &str,
    c: [f64; 3],
    half: [f64; 3],
    yaw: f64,
    albedo: [f64; 3],
    label: u32,
) -> Object {
    Object {
        name: name.into(),
        shape: Shape::Cuboid {
            pose: Isometry3::new(Vector3::new(c[0], c[1], c[2]), Vector3::z() * yaw),
            half,
        },
        albedo,
        label,
    }
}

fn cylinder(
    name: &str,
    base: [f64; 3],
    radius: f64,
    height: f64,
    albedo: [f64; 3],
    label: u32,
) -> Object {
    Object {
        name: name.into(),
        shape: Shape::Cylinder {
            base,
            radius,
            height,
        },
        albedo,
        label,
    }
}

/// Floor and wall colours of the hallway (8-bit ≈ 255 × albedo).
const GREY: [f64; 3] = [0.47, 0.47, 0.47];
const WALL_BLUE: [f64; 3] = [0.36, 0.45, 0.68];
const BEIGE: [f64; 3] = [0.78, 0.74, 0.62];

/// The names of the preset scenes.
pub const SCENES: [&str; 3] = ["hallway", "ramp", "hill"];

/// A preset scene by name: `"hallway"` (Fig. 4.4a–h: a grey bin on a grey floor, a blue bin
/// flush against a blue wall, two boxes, in a room), `"ramp"` (a grey ramp on the grey floor
/// and a box) or `"hill"` (Fig. 4.4i–j: outdoors in bright sun, a hill, two orange buckets and
/// a tree whose canopy shades the ground).
pub fn preset(name: &str) -> Result<Scene> {
    let room = |objs: &mut Vec<Object>| {
        objs.push(cuboid(
            "floor",
            [0.5, 0.0, -0.05],
            [5.0, 4.0, 0.05],
            0.0,
            GREY,
            1,
        ));
        objs.push(cuboid(
            "back wall",
            [4.05, 0.0, 1.5],
            [0.05, 4.0, 1.5],
            0.0,
            WALL_BLUE,
            2,
        ));
        objs.push(cuboid(
            "left wall",
            [0.5, 2.55, 1.5],
            [5.0, 0.05, 1.5],
            0.0,
            BEIGE,
            3,
        ));
        objs.push(cuboid(
            "right wall",
            [0.5, -2.55, 1.5],
            [5.0, 0.05, 1.5],
            0.0,
            BEIGE,
            4,
        ));
        objs.push(cuboid(
            "rear wall",
            [-3.05, 0.0, 1.5],
            [0.05, 4.0, 1.5],
            0.0,
            BEIGE,
            5,
        ));
        objs.push(cuboid(
            "ceiling",
            [0.5, 0.0, 3.05],
            [5.0, 4.0, 0.05],
            0.0,
            [0.9, 0.9, 0.88],
            10,
        ));
    };
    let mut objects = Vec::new();
    let lighting = match name {
        "hallway" => {
            room(&mut objects);
            objects.push(cylinder(
                "grey bin",
                [2.2, 0.7, 0.0],
                0.22,
                0.65,
                [0.49, 0.48, 0.47],
                6,
            ));
            objects.push(cuboid(
                "blue bin",
                [3.92, -0.5, 0.36],
                [0.08, 0.28, 0.36],
                0.0,
                [0.12, 0.22, 0.78],
                7,
            ));
            objects.push(cuboid(
                "box",
                [2.5, -1.3, 0.2],
                [0.25, 0.2, 0.2],
                0.35,
                [0.62, 0.46, 0.26],
                8,
            ));
            objects.push(cuboid(
                "red box",
                [1.7, -0.3, 0.12],
                [0.15, 0.15, 0.12],
                -0.2,
                [0.75, 0.15, 0.12],
                9,
            ));
            Lighting {
                ambient: 1.0,
                sun: ([0.0, 0.0, 1.0], 0.0),
            }
        }
        "ramp" => {
            room(&mut objects);
            let slope = 15f64.to_radians();
            let (len, thick) = (1.6, 0.05);
            // A board resting on the floor, rising away from the scanner.
            let c = [
                2.2 + 0.5 * len * slope.cos(),
                0.0,
                0.5 * len * slope.sin() - 0.5 * thick * slope.cos() + 0.01,
            ];
            objects.push(Object {
                name: "ramp".into(),
                shape: Shape::Cuboid {
                    pose: Isometry3::new(Vector3::new(c[0], c[1], c[2]), Vector3::y() * -slope),
                    half: [0.5 * len, 0.6, 0.5 * thick],
                },
                albedo: [0.5, 0.49, 0.47],
                label: 6,
            });
            objects.push(cuboid(
                "box",
                [1.6, -1.2, 0.2],
                [0.2, 0.25, 0.2],
                0.3,
                [0.62, 0.46, 0.26],
                7,
            ));
            Lighting {
                ambient: 1.0,
                sun: ([0.0, 0.0, 1.0], 0.0),
            }
        }
        "hill" => {
            let ground = [0.42, 0.36, 0.22];
            objects.push(cuboid(
                "ground",
                [10.0, 0.0, -0.05],
                [15.0, 15.0, 0.05],
                0.0,
                ground,
                1,
            ));
            objects.push(Object {
                name: "hill".into(),
                shape: Shape::Sphere {
                    center: [6.5, -1.0, -7.9],
                    radius: 8.5,
                },
                albedo: ground,
                label: 1,
            });
            let orange = [0.85, 0.42, 0.1];
            objects.push(cylinder("bucket", [2.6, 0.9, 0.0], 0.16, 0.36, orange, 2));
            objects.push(cylinder(
                "bucket 2",
                [3.3, -0.7, 0.0],
                0.16,
                0.36,
                orange,
                3,
            ));
            objects.push(cylinder(
                "tree trunk",
                [4.5, 1.6, 0.0],
                0.18,
                3.0,
                [0.45, 0.33, 0.2],
                4,
            ));
            objects.push(Object {
                name: "canopy".into(),
                shape: Shape::Sphere {
                    center: [4.5, 1.6, 3.6],
                    radius: 1.3,
                },
                albedo: [0.18, 0.38, 0.12],
                label: 5,
            });
            let s = Vector3::new(0.45, 0.35, 0.82).normalize();
            Lighting {
                ambient: 0.35,
                sun: ([s.x, s.y, s.z], 1.9),
            }
        }
        other => {
            let _ = other;
            return Err(DetectError::InvalidParameter {
                what: "scene",
                value: f64::NAN,
                reason: "unknown scene name: use \"hallway\", \"ramp\" or \"hill\"",
            });
        }
    };
    Ok(Scene { objects, lighting })
}
