//! Ray casting against the prepared scene: per-frame precomputation, ray–primitive
//! intersection (wafer slabs and axis-aligned boxes), and shading with one mirror bounce.

use nalgebra::{Isometry3, Matrix3, Vector3};

pub(crate) use super::RayCamera;
use super::Shading;
use super::scene::{Aabb, Material, Scene};

/// Key of "no surface" (the ray escapes to the background). Surface keys are
/// `8·primitive + face` below these special values (16 bits each).
pub(crate) const KEY_BACKGROUND: u32 = 0xFFFF;
/// Key of a pixel without a ray under the camera model.
pub(crate) const KEY_NO_RAY: u32 = 0xFFFE;
/// Mirror key of a surface that does not reflect.
pub(crate) const KEY_NONE: u32 = 0xFFFD;
/// Most primitives a scene may have so that every surface key fits in 16 bits.
pub(crate) const MAX_PRIMS: usize = 0xFFF8 / 8;
// The most wafers plus the carrier's 5 + 2·100 boxes fit.
const _: () = assert!(super::scene::MAX_WAFERS + 5 + 2 * 100 <= MAX_PRIMS);

/// A ray `o + s·d` with the componentwise inverse of its direction.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Ray {
    pub o: Vector3<f64>,
    pub d: Vector3<f64>,
    pub inv: Vector3<f64>,
}

impl Ray {
    #[inline]
    pub fn new(o: Vector3<f64>, d: Vector3<f64>) -> Self {
        Self {
            o,
            d,
            inv: d.map(|x| 1.0 / x),
        }
    }
}

/// Faces of a wafer slab.
pub(crate) const FACE_TOP: u8 = 0;
/// Bottom face.
pub(crate) const FACE_BOTTOM: u8 = 1;
/// Cylindrical side face (the rim band).
pub(crate) const FACE_SIDE: u8 = 2;

/// Geometry of one primitive.
#[derive(Debug, Clone)]
pub(crate) enum Shape {
    /// A wafer: rotation and centre of `T_w,wafer`, the inverse rotation, and the camera centre
    /// in the wafer frame.
    Wafer {
        rot: Matrix3<f64>,
        rot_t: Matrix3<f64>,
        pos: Vector3<f64>,
        cam_local: Vector3<f64>,
    },
    /// A carrier box (the box itself is the primitive's `aabb`).
    Box(Material),
}

/// A primitive with its world bounding box.
#[derive(Debug, Clone)]
pub(crate) struct Prim {
    pub shape: Shape,
    pub aabb: Aabb,
}

/// A ray hit: distance along the (unit) ray, primitive index and face.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hit {
    pub s: f64,
    pub prim: u32,
    pub face: u8,
}

impl Hit {
    /// Identifier of the surface hit, unique over the scene.
    pub fn key(&self) -> u32 {
        self.prim * 8 + self.face as u32
    }
}

/// A candidate primitive of a ray bundle with its lower bound on the hit distance.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Cand {
    pub prim: u32,
    pub dmin: f64,
}

/// Everything precomputed once per frame.
pub(crate) struct Prepared {
    pub prims: Vec<Prim>,
    pub n_wafers: usize,
    pub radius: f64,
    pub half: f64,
    pub cam_center: Vector3<f64>,
    pub r_wc: Matrix3<f64>,
    pub shading: Shading,
    /// Per wafer, the candidates for rays leaving its top face (index 0) and its bottom face
    /// (index 1), sorted by `dmin`, which here is the height of the primitive above the face's
    /// plane (a ray leaving at unit speed `r·n` along the face normal `n` needs at least
    /// `dmin / r·n` to reach it).
    pub mirror: Vec<[Vec<Cand>; 2]>,
    /// All primitives sorted by their distance from the camera centre.
    pub by_distance: Vec<Cand>,
}

impl Prepared {
    /// Builds the primitives of `scene` seen from the camera at `t_wc`.
    pub fn new(scene: &Scene, t_wc: &Isometry3<f64>, shading: Shading) -> Self {
        let r = scene.shape.radius;
        let h = 0.5 * scene.shape.thickness;
        let cam_center = t_wc.translation.vector;
        let mut prims = Vec::with_capacity(scene.wafers.len() + 60);
        for pose in &scene.wafers {
            let rot = pose.rotation.to_rotation_matrix().into_inner();
            let rot_t = rot.transpose();
            let pos = pose.translation.vector;
            let cam_local = rot_t * (cam_center - pos);
            prims.push(Prim {
                shape: Shape::Wafer {
                    rot,
                    rot_t,
                    pos,
                    cam_local,
                },
                aabb: wafer_aabb(&rot, &pos, r, h),
            });
        }
        let n_wafers = prims.len();
        if let Some(c) = &scene.carrier {
            for (aabb, m) in c.boxes(&scene.shape) {
                prims.push(Prim {
                    shape: Shape::Box(m),
                    aabb,
                });
            }
        }
        let mut by_distance: Vec<Cand> = prims
            .iter()
            .enumerate()
            .map(|(i, p)| Cand {
                prim: i as u32,
                dmin: p.aabb.distance_to_point(&cam_center),
            })
            .collect();
        by_distance.sort_by(|a, b| a.dmin.total_cmp(&b.dmin));
        let mut mirror = Vec::with_capacity(n_wafers);
        for i in 0..n_wafers {
            let Shape::Wafer { rot, pos, .. } = &prims[i].shape else {
                unreachable_wafer()
            };
            let n = rot.column(2).into_owned();
            let lists = [1.0f64, -1.0].map(|sign| {
                // Rays leave the face at z = ±h into the half-space sign·n·(x − pos) > h.
                let normal = n * sign;
                let offset = normal.dot(pos) + h;
                let mut list: Vec<Cand> = prims
                    .iter()
                    .enumerate()
                    .filter(|(j, p)| *j != i && max_along(&p.aabb, &normal) > offset)
                    .map(|(j, p)| Cand {
                        prim: j as u32,
                        dmin: (-max_along(&p.aabb, &-normal) - offset).max(0.0),
                    })
                    .collect();
                list.sort_by(|a, b| a.dmin.total_cmp(&b.dmin));
                list
            });
            mirror.push(lists);
        }
        Self {
            prims,
            n_wafers,
            radius: r,
            half: h,
            cam_center,
            r_wc: t_wc.rotation.to_rotation_matrix().into_inner(),
            shading,
            mirror,
            by_distance,
        }
    }

    /// Intersects the ray `o + s·d` (world frame, `d` unit) with primitive `i`, returning the
    /// entry distance `s ∈ (s_min, s_max)` and the face entered.
    #[inline]
    pub fn intersect(&self, i: u32, ray: &Ray, s_min: f64, s_max: f64) -> Option<(f64, u8)> {
        let p = &self.prims[i as usize];
        match &p.shape {
            Shape::Wafer { rot_t, pos, .. } => {
                let ol = rot_t * (ray.o - pos);
                let dl = rot_t * ray.d;
                intersect_slab(&ol, &dl, self.radius, self.half, s_min, s_max)
            }
            Shape::Box(_) => intersect_box(&p.aabb, &ray.o, &ray.inv, s_min, s_max),
        }
    }

    /// Closest hit of a ray among `cands` (sorted by `dmin`), skipping primitive `skip`; the
    /// search stops at the first candidate with `dmin ≥ scale·s` for the closest hit `s` so far.
    #[inline]
    pub fn trace(
        &self,
        ray: &Ray,
        cands: &[Cand],
        skip: u32,
        s_min: f64,
        scale: f64,
    ) -> Option<Hit> {
        closest_hit(
            cands,
            |c| c.prim,
            |c, s_max| c.dmin >= s_max * scale,
            |c, s_max| {
                if c.prim == skip {
                    None
                } else {
                    self.intersect(c.prim, ray, s_min, s_max)
                }
            },
        )
    }

    /// Closest hit of a ray among the primitives `prims` (any order), skipping `skip`.
    #[inline]
    pub fn trace_subset(&self, ray: &Ray, prims: &[u32], skip: u32, s_min: f64) -> Option<Hit> {
        closest_hit(
            prims,
            |&i| i,
            |_, _| false,
            |&i, s_max| {
                if i == skip {
                    None
                } else {
                    self.intersect(i, ray, s_min, s_max)
                }
            },
        )
    }

    /// Hit of a camera ray (origin at the camera centre, direction `d`, componentwise inverse
    /// `inv`) with primitive `i` at a distance in `(0, s_max)` (units of `|d|`), and its face.
    #[inline]
    fn intersect_primary(
        &self,
        i: u32,
        d: &Vector3<f64>,
        inv: &Vector3<f64>,
        s_max: f64,
    ) -> Option<(f64, u8)> {
        let p = &self.prims[i as usize];
        match &p.shape {
            Shape::Wafer {
                rot_t, cam_local, ..
            } => intersect_slab(cam_local, &(rot_t * d), self.radius, self.half, 0.0, s_max),
            Shape::Box(_) => intersect_box(&p.aabb, &self.cam_center, inv, 0.0, s_max),
        }
    }

    /// Closest hit of a camera ray (origin at the camera centre, direction `d` of any positive
    /// length; hit distances are in units of `|d|`) through image position `(u, v)` among
    /// `cands`, skipping those whose image box misses `(u, v)`.
    #[inline]
    pub fn trace_primary(
        &self,
        d: &Vector3<f64>,
        cands: &[TileCand],
        u: f32,
        v: f32,
    ) -> Option<Hit> {
        let inv = d.map(|x| 1.0 / x);
        let len = d.norm();
        closest_hit(
            cands,
            |c| c.prim,
            |c, s_max| c.dmin >= s_max * len,
            |c, s_max| {
                if u < c.bounds[0] || v < c.bounds[1] || u > c.bounds[2] || v > c.bounds[3] {
                    None
                } else {
                    self.intersect_primary(c.prim, d, &inv, s_max)
                }
            },
        )
    }

    /// Closest hit of a camera ray among the primitives `prims` (any order).
    #[inline]
    pub fn trace_primary_subset(&self, d: &Vector3<f64>, prims: &[u32]) -> Option<Hit> {
        let inv = d.map(|x| 1.0 / x);
        closest_hit(
            prims,
            |&i| i,
            |_, _| false,
            |&i, s_max| self.intersect_primary(i, d, &inv, s_max),
        )
    }

    /// Prepares the camera rays over one pixel, `d(dx, dy) = d[0] + dx·d[1] + dy·d[2]` (world),
    /// for tracing against `prims`: each wafer gets the three vectors in its own frame.
    pub fn bundle(&self, d: [Vector3<f64>; 3], prims: &[u32], out: &mut Bundle) {
        out.d = d;
        out.prims.clear();
        for &i in prims {
            let local = match &self.prims[i as usize].shape {
                Shape::Wafer { rot_t, .. } => Some([rot_t * d[0], rot_t * d[1], rot_t * d[2]]),
                Shape::Box(_) => None,
            };
            out.prims.push((i, local));
        }
    }

    /// Closest hit, among the bundle's primitives, of the bundle's ray at sub-pixel offset
    /// `(dx, dy)`, whose world direction is `d`.
    #[inline]
    pub fn trace_bundle(&self, b: &Bundle, dx: f64, dy: f64, d: &Vector3<f64>) -> Option<Hit> {
        closest_hit(
            &b.prims,
            |(i, _)| *i,
            |_, _| false,
            |(i, local), s_max| match (local, &self.prims[*i as usize].shape) {
                (Some(l), Shape::Wafer { cam_local, .. }) => {
                    let dl = l[0] + l[1] * dx + l[2] * dy;
                    intersect_slab(cam_local, &dl, self.radius, self.half, 0.0, s_max)
                }
                _ => intersect_box(
                    &self.prims[*i as usize].aabb,
                    &self.cam_center,
                    &d.map(|x| 1.0 / x),
                    0.0,
                    s_max,
                ),
            },
        )
    }

    /// World normal of the surface at a hit point `x`.
    pub fn normal(&self, hit: &Hit, x: &Vector3<f64>) -> Vector3<f64> {
        let p = &self.prims[hit.prim as usize];
        match &p.shape {
            Shape::Wafer {
                rot, rot_t, pos, ..
            } => match hit.face {
                FACE_TOP => rot.column(2).into_owned(),
                FACE_BOTTOM => -rot.column(2).into_owned(),
                _ => {
                    let l = rot_t * (x - pos);
                    let n = Vector3::new(l.x, l.y, 0.0);
                    rot * (n / n.norm().max(f64::MIN_POSITIVE))
                }
            },
            Shape::Box(_) => {
                let axis = (hit.face / 2) as usize;
                let mut n = Vector3::zeros();
                n[axis] = if hit.face % 2 == 1 { 1.0 } else { -1.0 };
                n
            }
        }
    }

    /// Radiance of a surface hit without any further bounce.
    fn direct(&self, hit: &Hit, x: &Vector3<f64>) -> f64 {
        let sh = &self.shading;
        let p = &self.prims[hit.prim as usize];
        let n = self.normal(hit, x);
        let lambert = |albedo: f64, ambient: f64| {
            albedo * (ambient + (1.0 - ambient) * n.dot(&sh.light_dir).max(0.0))
        };
        match &p.shape {
            Shape::Wafer { .. } => {
                if hit.face == FACE_SIDE {
                    lambert(sh.rim_albedo, sh.rim_ambient)
                } else {
                    sh.face_base
                }
            }
            Shape::Box(m) => {
                let albedo = match m {
                    Material::Plate => sh.plate_albedo,
                    Material::Wall => sh.wall_albedo,
                    Material::Back => sh.back_albedo,
                    Material::Ridge => sh.ridge_albedo,
                };
                lambert(albedo, sh.ambient)
            }
        }
    }

    /// Radiance and surface key (primary key in the high half, mirrored key in the low half) of
    /// the ray `o + s·d` (`d` of any positive length) given its first hit.
    ///
    /// With `mirror_subset = Some((prims, complete))` the mirrored ray is first traced against
    /// `prims` only; if it misses them and `complete` is false, against the whole scene.
    pub fn shade(
        &self,
        o: &Vector3<f64>,
        d: &Vector3<f64>,
        hit: Option<Hit>,
        mirror_subset: Option<(&[u32], bool)>,
    ) -> (f64, u32) {
        let Some(hit) = hit else {
            return (self.shading.background, key2(KEY_BACKGROUND, KEY_NONE));
        };
        let x = o + d * hit.s;
        let is_face = (hit.prim as usize) < self.n_wafers && hit.face != FACE_SIDE;
        if !is_face || self.shading.reflectivity == 0.0 {
            return (self.direct(&hit, &x), key2(hit.key(), KEY_NONE));
        }
        // One mirror bounce off the specular wafer face.
        let n = self.normal(&hit, &x);
        let r = d - n * (2.0 * d.dot(&n));
        let ray = Ray::new(x, r);
        let list = &self.mirror[hit.prim as usize][hit.face as usize];
        let sh = &self.shading;
        let found = match mirror_subset {
            Some((prims, complete)) => match self.trace_subset(&ray, prims, hit.prim, 1e-9) {
                Some(h2) => Some(h2),
                None if complete => None,
                None => self.trace(&ray, list, hit.prim, 1e-9, r.dot(&n)),
            },
            None => self.trace(&ray, list, hit.prim, 1e-9, r.dot(&n)),
        };
        match found {
            Some(h2) => {
                let x2 = x + r * h2.s;
                (
                    sh.face_base + sh.reflectivity * self.direct(&h2, &x2),
                    key2(hit.key(), h2.key()),
                )
            }
            None => (
                sh.face_base + sh.reflectivity * sh.background,
                key2(hit.key(), KEY_BACKGROUND),
            ),
        }
    }
}

/// The camera rays over one pixel, affine in the sub-pixel offset, prepared for a few
/// primitives (see [`Prepared::bundle`]).
#[derive(Debug, Default)]
pub(crate) struct Bundle {
    /// World directions `d0, ∂d/∂u, ∂d/∂v`.
    pub d: [Vector3<f64>; 3],
    /// The primitives, with the three vectors in the wafer frame for wafers.
    pub prims: Vec<(u32, Option<[Vector3<f64>; 3]>)>,
}

/// A primitive that may be hit by the camera rays of one image tile, with the bounding box
/// `[umin, vmin, umax, vmax]` of its image and its distance bound.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TileCand {
    pub prim: u32,
    pub bounds: [f32; 4],
    pub dmin: f64,
}

/// A pixel's surface key: the primary surface's key in the high 16 bits, the mirrored
/// surface's key in the low 16 bits.
#[inline]
pub(crate) fn key2(a: u32, b: u32) -> u32 {
    (a << 16) | b
}

#[cold]
fn unreachable_wafer() -> ! {
    // The first `n_wafers` primitives are built as wafers just above.
    panic!("primitive below n_wafers is not a wafer")
}

/// Largest value of `n·x` over the box.
fn max_along(b: &Aabb, n: &Vector3<f64>) -> f64 {
    (0..3)
        .map(|k| {
            if n[k] >= 0.0 {
                n[k] * b.max[k]
            } else {
                n[k] * b.min[k]
            }
        })
        .sum()
}

/// Exact world AABB of a slab of radius `r`, half-thickness `h`, axis `rot·e_z`, centre `pos`.
pub(crate) fn wafer_aabb(rot: &Matrix3<f64>, pos: &Vector3<f64>, r: f64, h: f64) -> Aabb {
    let n = rot.column(2);
    let ext = Vector3::from_fn(|k, _| r * (1.0 - n[k] * n[k]).max(0.0).sqrt() + h * n[k].abs());
    Aabb::new(pos - ext, pos + ext)
}

/// The closest hit over `items` in order, shared by the `trace*` methods: `hit(item, s_max)`
/// is the item's hit nearer than `s_max` (the closest hit so far, or infinity), `prim(item)`
/// its primitive, and the search stops before the first item with `stop(item, s_max)`.
#[inline(always)]
fn closest_hit<'a, T: 'a>(
    items: impl IntoIterator<Item = &'a T>,
    prim: impl Fn(&T) -> u32,
    stop: impl Fn(&T, f64) -> bool,
    hit: impl Fn(&T, f64) -> Option<(f64, u8)>,
) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    let mut s_max = f64::INFINITY;
    for item in items {
        if stop(item, s_max) {
            break;
        }
        if let Some((s, face)) = hit(item, s_max) {
            s_max = s;
            best = Some(Hit {
                s,
                prim: prim(item),
                face,
            });
        }
    }
    best
}

/// Entry of the ray `o + s·d` (wafer frame) into the slab `x² + y² ≤ r², |z| ≤ h`, for
/// `s ∈ (s_min, s_max)`. Only surfaces entered from outside count (d·n < 0).
#[inline]
pub(crate) fn intersect_slab(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    r: f64,
    h: f64,
    s_min: f64,
    s_max: f64,
) -> Option<(f64, u8)> {
    let r2 = r * r;
    // Flat face on the side the ray comes from. A ray enters a convex body at most once, so
    // an entry through this face is the answer.
    if d.z != 0.0 {
        let (zf, f) = if d.z < 0.0 {
            (h, FACE_TOP)
        } else {
            (-h, FACE_BOTTOM)
        };
        let s = (zf - o.z) / d.z;
        if s > s_min && s < s_max {
            let x = o.x + s * d.x;
            let y = o.y + s * d.y;
            if x * x + y * y <= r2 {
                return Some((s, f));
            }
        }
    }
    // Cylindrical side, entering root.
    let a = d.x * d.x + d.y * d.y;
    if a > 0.0 {
        let b = o.x * d.x + o.y * d.y;
        let c = o.x * o.x + o.y * o.y - r2;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            // Numerically stable smaller root.
            let s = if b > 0.0 {
                (-b - sq) / a
            } else {
                c / (-b + sq)
            };
            if s > s_min && s < s_max && (o.z + s * d.z).abs() <= h {
                return Some((s, FACE_SIDE));
            }
        }
    }
    None
}

/// Entry of the ray `o + s·d` into an axis-aligned box (slab method), given `inv = 1/d`
/// componentwise (±∞ for zero components); the face is `2·axis + (1 if the outward normal
/// points to +axis)`.
#[inline]
pub(crate) fn intersect_box(
    b: &Aabb,
    o: &Vector3<f64>,
    inv: &Vector3<f64>,
    s_min: f64,
    s_max: f64,
) -> Option<(f64, u8)> {
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    let mut face = u8::MAX;
    for k in 0..3 {
        if inv[k].is_infinite() {
            if o[k] < b.min[k] || o[k] > b.max[k] {
                return None;
            }
            continue;
        }
        let (near, far, f) = if inv[k] > 0.0 {
            (
                (b.min[k] - o[k]) * inv[k],
                (b.max[k] - o[k]) * inv[k],
                2 * k as u8,
            )
        } else {
            (
                (b.max[k] - o[k]) * inv[k],
                (b.min[k] - o[k]) * inv[k],
                2 * k as u8 + 1,
            )
        };
        if near > t0 {
            t0 = near;
            face = f;
        }
        t1 = t1.min(far);
    }
    (t0 <= t1 && t0 > s_min && t0 < s_max && face != u8::MAX).then_some((t0, face))
}
