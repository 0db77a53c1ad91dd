//! The pixel pipeline: which rays to cast for which pixel, and how to combine them.
//!
//! 1. Coarse pass: the centres of the pixels whose `u` and `v` are multiples of 4 (and of the
//!    last row/column).
//! 2. Refinement to every second pixel, then to every pixel: a sample inside a cell whose four
//!    corners see the same surface (and the same surface in the mirror) takes the bilinear
//!    interpolation of the corners' radiance, which varies smoothly over one surface; every
//!    other sample is traced, and so are the 4-px cells that a slot ridge's edge crosses. A
//!    feature that crosses a cell without changing the surface seen at its corners would have
//!    to be thinner than the cell and bounded by the same surface on both sides: a slot ridge
//!    against its wall (hence the box-edge marks), a wafer seen exactly edge-on against a
//!    uniform backdrop, or a sub-pixel detail of the mirror images.
//! 3. Edge flags: for every pair of 8-neighbours whose centres see different surfaces, one ray
//!    at the midpoint of the two centres (for a diagonal pair, the shared pixel corner) tells on
//!    which side the boundary passes; for a single straight edge this flags exactly the pixels
//!    whose square it crosses.
//! 4. Anti-aliasing: each flagged pixel becomes the mean (box filter) of `s×s` sub-samples in an
//!    n-rooks pattern (all `s²` sub-sample rows and columns distinct); pixels crossed only by a
//!    weak boundary (a radiance step below 20/255, or a change of the mirrored surface only)
//!    use `min(s, 2)²` sub-samples, and steps below the noise (2/255; 4/255 in the mirror) are
//!    not anti-aliased. The bright rim bands step by far more than 20/255 against anything.

use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

use super::trace::{self, Bundle, KEY_BACKGROUND, KEY_NO_RAY, KEY_NONE, Prepared, TileCand, key2};
use super::{RayCamera, RenderOptions, Scene};

/// Secondary-only (mirror) surface changes with a radiance step below this are not
/// anti-aliased: 4/255, about twice the default sensor noise.
const MIRROR_CONTRAST: f64 = 4.0 / 255.0;
/// Boundaries between primary surfaces with a radiance step below this (2/255) are not
/// anti-aliased (the step is below the default sensor noise).
const MIN_CONTRAST: f64 = 2.0 / 255.0;
/// Boundaries with a radiance step of at least this (20/255, every rim against its
/// surroundings) get the full `s×s` sub-samples; weaker ones `min(s, 2)²`.
const HIGH_CONTRAST: f64 = 20.0 / 255.0;

/// Flag of a pixel crossed by a high-contrast boundary between primary surfaces.
const FLAG_PRIMARY: u8 = 2;
/// Flag of a pixel crossed by a low-contrast boundary or one in the mirror image only.
const FLAG_MIRROR: u8 = 1;

/// The primary half of a surface key.
#[inline]
fn primary(k: u32) -> u32 {
    k >> 16
}

/// The mirror half of a surface key.
#[inline]
fn mirror(k: u32) -> u32 {
    k & 0xFFFF
}

/// The surfaces that the centres around a sub-sample see: their primitives (to trace the
/// sub-ray against), and each distinct surface key with its radiance.
#[derive(Default)]
struct Subset {
    prims: Vec<u32>,
    mirrors: Vec<u32>,
    open_primary: bool,
    open_mirror: bool,
    seen: Vec<(u32, f64)>,
}

impl Subset {
    fn clear(&mut self) {
        self.prims.clear();
        self.mirrors.clear();
        self.open_primary = false;
        self.open_mirror = false;
        self.seen.clear();
    }

    /// The radiance seen with primary key `p` if exactly one full key has it.
    #[inline]
    fn unique(&self, p: u32) -> Option<(u32, f64)> {
        let mut found = None;
        for &(k, l) in &self.seen {
            if primary(k) == p {
                if found.is_some() {
                    return None;
                }
                found = Some((k, l));
            }
        }
        found
    }

    fn add(&mut self, k: u32, l: f64) {
        if !self.seen.iter().any(|e| e.0 == k) {
            self.seen.push((k, l));
        }
        match primary(k) {
            KEY_BACKGROUND | KEY_NO_RAY => self.open_primary = true,
            p if !self.prims.contains(&(p / 8)) => self.prims.push(p / 8),
            _ => {}
        }
        match mirror(k) {
            KEY_BACKGROUND => self.open_mirror = true,
            KEY_NONE | KEY_NO_RAY => {}
            m if !self.mirrors.contains(&(m / 8)) => self.mirrors.push(m / 8),
            _ => {}
        }
    }
}

/// The ray caster of one frame.
struct Caster<'a, C: RayCamera> {
    prep: &'a Prepared,
    cam: &'a C,
    tiles: Tiles,
}

impl<C: RayCamera> Caster<'_, C> {
    /// World direction (not normalised) of the ray through image position `(u, v)`.
    #[inline]
    fn ray(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let d = self.prep.r_wc * self.cam.bearing(u, v)?;
        (d.iter().all(|x| x.is_finite()) && d != Vector3::zeros()).then_some(d)
    }

    /// Radiance and surface key at `(u, v)`, traced against the whole tile of pixel `(pu, pv)`.
    #[inline]
    fn sample(&self, u: f64, v: f64, pu: usize, pv: usize) -> (f64, u32) {
        match self.ray(u, v) {
            Some(d) => {
                let hit = self
                    .prep
                    .trace_primary(&d, self.tiles.get(pu, pv), u as f32, v as f32);
                self.prep.shade(&self.prep.cam_center, &d, hit, None)
            }
            None => (self.prep.shading.background, key2(KEY_NO_RAY, KEY_NO_RAY)),
        }
    }

    /// As [`Self::sample`], but traced against the surfaces in `sub` first, falling back to
    /// the tile when the ray misses them and they do not include the background. When the
    /// surface hit is one that `sub` saw with a single radiance (radiance varies smoothly over
    /// one surface, and the sub-sample is within a pixel of where it was seen), that radiance
    /// is reused instead of shading again (which would trace the mirrored ray).
    #[inline]
    fn sample_subset(&self, u: f64, v: f64, pu: usize, pv: usize, sub: &Subset) -> (f64, u32) {
        match self.ray(u, v) {
            Some(d) => {
                let hit = match self.prep.trace_primary_subset(&d, &sub.prims) {
                    None if !sub.open_primary => {
                        self.prep
                            .trace_primary(&d, self.tiles.get(pu, pv), u as f32, v as f32)
                    }
                    found => found,
                };
                let p = hit.map_or(KEY_BACKGROUND, |h| h.key());
                if let Some((k, l)) = sub.unique(p) {
                    return (l, k);
                }
                self.prep.shade(
                    &self.prep.cam_center,
                    &d,
                    hit,
                    Some((&sub.mirrors, sub.open_mirror)),
                )
            }
            None => (self.prep.shading.background, key2(KEY_NO_RAY, KEY_NO_RAY)),
        }
    }
}

impl<C: RayCamera> Caster<'_, C> {
    /// Mean radiance over pixel `(u, v)` of the sub-samples at `offsets`, traced against the
    /// surfaces in `sub` (see [`Self::sample_subset`]). Over one pixel the ray direction is
    /// taken affine in the sub-pixel offset, from the rays at the centre and half a pixel to
    /// the right and below: exact for the pinhole model, and within ~1e-4 px for the
    /// distortion models, whose unprojection is smooth.
    fn pixel_mean(
        &self,
        u: usize,
        v: usize,
        offsets: &[(f64, f64)],
        sub: &Subset,
        bundle: &mut Bundle,
    ) -> f64 {
        let (uf, vf) = (u as f64, v as f64);
        let frame = (|| {
            Some([
                self.ray(uf, vf)?,
                self.ray(uf + 0.5, vf)?,
                self.ray(uf, vf + 0.5)?,
            ])
        })();
        let Some([d0, d1, d2]) = frame else {
            let sum: f64 = offsets
                .iter()
                .map(|(dx, dy)| self.sample_subset(uf + dx, vf + dy, u, v, sub).0)
                .sum();
            return sum / offsets.len() as f64;
        };
        self.prep
            .bundle([d0, (d1 - d0) * 2.0, (d2 - d0) * 2.0], &sub.prims, bundle);
        let mut sum = 0.0;
        for &(dx, dy) in offsets {
            let d = bundle.d[0] + bundle.d[1] * dx + bundle.d[2] * dy;
            let hit = match self.prep.trace_bundle(bundle, dx, dy, &d) {
                None if !sub.open_primary => self.prep.trace_primary(
                    &d,
                    self.tiles.get(u, v),
                    (uf + dx) as f32,
                    (vf + dy) as f32,
                ),
                found => found,
            };
            let p = hit.map_or(KEY_BACKGROUND, |h| h.key());
            sum += match sub.unique(p) {
                Some((_, l)) => l,
                None => {
                    self.prep
                        .shade(
                            &self.prep.cam_center,
                            &d,
                            hit,
                            Some((&sub.mirrors, sub.open_mirror)),
                        )
                        .0
                }
            };
        }
        sum / offsets.len() as f64
    }
}

/// Does the surface `k` at radiance `l` differ from `ka` at `la` enough to matter: another
/// primary surface with a visible radiance step, or another mirrored surface with a step above
/// the noise? Returns the flag (0 for no).
#[inline]
fn differs(k: u32, l: f64, ka: u32, la: f64) -> u8 {
    let step = (l - la).abs();
    if primary(k) != primary(ka) {
        if step >= HIGH_CONTRAST {
            FLAG_PRIMARY
        } else if step >= MIN_CONTRAST {
            FLAG_MIRROR
        } else {
            0
        }
    } else if k != ka && step > MIRROR_CONTRAST {
        FLAG_MIRROR
    } else {
        0
    }
}

/// Is the boundary between the centres worth locating: another primary surface (whatever the
/// radiance step, so that a thin feature between the centres is found), or another mirrored
/// surface with a visible step?
#[inline]
fn worth_midpoint(kn: u32, ln: f64, ka: u32, la: f64) -> bool {
    primary(kn) != primary(ka) || (kn != ka && (ln - la).abs() > MIRROR_CONTRAST)
}

/// Sample coordinates along an axis of `n` pixels with spacing `step`: 0, step, 2·step, … and
/// `n − 1`.
fn grid_axis(n: usize, step: usize) -> Vec<usize> {
    let mut c: Vec<usize> = (0..n).step_by(step).collect();
    if !(n - 1).is_multiple_of(step) {
        c.push(n - 1);
    }
    c
}

/// Pixel-centre samples (radiance and surface key) on a grid of spacing `step`.
struct Grid {
    step: usize,
    u: Vec<usize>,
    v: Vec<usize>,
    keys: Vec<u32>,
    rad: Vec<f32>,
}

impl Grid {
    /// Traces every sample of the grid of spacing `step` over a `w×h` image.
    fn trace<C: RayCamera>(caster: &Caster<'_, C>, w: usize, h: usize, step: usize) -> Self {
        let (u, v) = (grid_axis(w, step), grid_axis(h, step));
        let n = u.len();
        let mut keys = vec![0u32; n * v.len()];
        let mut rad = vec![0f32; n * v.len()];
        keys.par_chunks_mut(n)
            .zip(rad.par_chunks_mut(n))
            .enumerate()
            .for_each(|(j, (krow, rrow))| {
                for (i, &x) in u.iter().enumerate() {
                    let (l, k) = caster.sample(x as f64, v[j] as f64, x, v[j]);
                    krow[i] = k;
                    rrow[i] = l as f32;
                }
            });
        Self {
            step,
            u,
            v,
            keys,
            rad,
        }
    }

    /// Index of the cell (its lower corner in the axis) holding coordinate `x`.
    #[inline]
    fn cell(&self, x: usize, axis_len: usize) -> usize {
        (x / self.step).min(axis_len.saturating_sub(2))
    }

    /// The grid of spacing `step` (dividing this grid's spacing): samples of this grid are
    /// copied; the others are interpolated bilinearly where the four corners of their cell
    /// see the same surface, traced otherwise.
    ///
    /// `marks`, indexed like the samples by the cell's lower corner, forces tracing in the
    /// marked cells.
    fn refine<C: RayCamera>(
        &self,
        caster: &Caster<'_, C>,
        step: usize,
        marks: Option<&[bool]>,
    ) -> Self {
        let (w, h) = (self.u[self.u.len() - 1] + 1, self.v[self.v.len() - 1] + 1);
        let (fu, fv) = (grid_axis(w, step), grid_axis(h, step));
        let (ncu, ncv) = (self.u.len(), self.v.len());
        let n = fu.len();
        let mut keys = vec![0u32; n * fv.len()];
        let mut rad = vec![0f32; n * fv.len()];
        keys.par_chunks_mut(n)
            .zip(rad.par_chunks_mut(n))
            .enumerate()
            .for_each(|(jf, (krow, rrow))| {
                let y = fv[jf];
                let j = self.cell(y, ncv);
                let j1 = (j + 1).min(ncv - 1);
                let (v0, v1) = (self.v[j], self.v[j1]);
                let fy = if v1 > v0 {
                    (y - v0) as f32 / (v1 - v0) as f32
                } else {
                    0.0
                };
                for (ifine, &x) in fu.iter().enumerate() {
                    let i = self.cell(x, ncu);
                    let i1 = (i + 1).min(ncu - 1);
                    let (u0, u1) = (self.u[i], self.u[i1]);
                    let c = [j * ncu + i, j * ncu + i1, j1 * ncu + i, j1 * ncu + i1];
                    if (x == u0 || x == u1) && (y == v0 || y == v1) {
                        let idx = c[usize::from(x != u0) + 2 * usize::from(y != v0)];
                        krow[ifine] = self.keys[idx];
                        rrow[ifine] = self.rad[idx];
                        continue;
                    }
                    let fx = if u1 > u0 {
                        (x - u0) as f32 / (u1 - u0) as f32
                    } else {
                        0.0
                    };
                    // A sample on a grid line depends on that line's two ends only.
                    let (ids, wts): (&[usize], [f32; 4]) = if x == u0 || x == u1 {
                        let col = usize::from(x != u0);
                        (&[c[col], c[col + 2]][..], [1.0 - fy, fy, 0.0, 0.0])
                    } else if y == v0 || y == v1 {
                        let row = 2 * usize::from(y != v0);
                        (&[c[row], c[row + 1]][..], [1.0 - fx, fx, 0.0, 0.0])
                    } else {
                        (
                            &c[..],
                            [
                                (1.0 - fx) * (1.0 - fy),
                                fx * (1.0 - fy),
                                (1.0 - fx) * fy,
                                fx * fy,
                            ],
                        )
                    };
                    let k = self.keys[ids[0]];
                    let marked = marks.is_some_and(|m| m[c[0]]);
                    if !marked && ids.iter().all(|&ci| self.keys[ci] == k) {
                        krow[ifine] = k;
                        rrow[ifine] = ids.iter().zip(wts).map(|(&ci, wt)| self.rad[ci] * wt).sum();
                    } else {
                        let (l, k) = caster.sample(x as f64, y as f64, x, y);
                        krow[ifine] = k;
                        rrow[ifine] = l as f32;
                    }
                }
            });
        Self {
            step,
            u: fu,
            v: fv,
            keys,
            rad,
        }
    }
}

/// Marks the cells of `grid` (indexed by their lower corner) that an edge of a slot ridge
/// crosses (within 1.5 px): ridges are only a few pixels tall and seen against the wall they
/// are attached to, so a coarse cell could otherwise hold a whole ridge between corners that
/// all see the wall.
fn edge_marks<C: RayCamera>(
    prep: &Prepared,
    cam: &C,
    t_wc: &Isometry3<f64>,
    grid: &Grid,
) -> Vec<bool> {
    let (ncu, ncv) = (grid.u.len(), grid.v.len());
    let mut marks = vec![false; ncu * ncv];
    let t_cw = t_wc.inverse();
    let project = |x: &Vector3<f64>| cam.project(&(t_cw * nalgebra::Point3::from(*x)).coords);
    let (wf, hf) = (grid.u[ncu - 1] as f64, grid.v[ncv - 1] as f64);
    for p in &prep.prims {
        if !matches!(p.shape, trace::Shape::Box(super::scene::Material::Ridge)) {
            continue;
        }
        let c = p.aabb.corners();
        for i in 0..8usize {
            for bit in [1usize, 2, 4] {
                if i & bit != 0 {
                    continue;
                }
                let (a, b) = (c[i], c[i | bit]);
                // Samples at most ~1 px apart in the image (many if an end is not projectable).
                let n = match (project(&a), project(&b)) {
                    (Some(qa), Some(qb)) => ((qa - qb).norm().ceil() as usize).clamp(2, 8192),
                    _ => 4096,
                };
                for k in 0..=n {
                    let x = a + (b - a) * (k as f64 / n as f64);
                    let Some(q) = project(&x) else { continue };
                    if !(q.x > -2.0 && q.y > -2.0 && q.x < wf + 2.0 && q.y < hf + 2.0) {
                        continue;
                    }
                    for y in [q.y - 1.5, q.y + 1.5] {
                        for xx in [q.x - 1.5, q.x + 1.5] {
                            let (xc, yc) = (xx.clamp(0.0, wf) as usize, y.clamp(0.0, hf) as usize);
                            marks[grid.cell(yc, ncv) * ncu + grid.cell(xc, ncu)] = true;
                        }
                    }
                }
            }
        }
    }
    marks
}

/// Linear radiance per pixel after anti-aliasing (before lighting, blur and noise). Inputs must
/// have been validated.
pub(crate) fn radiance<C: RayCamera>(
    scene: &Scene,
    cam: &C,
    t_wc: &Isometry3<f64>,
    opts: &RenderOptions,
) -> Vec<f32> {
    let (w, h) = (cam.width(), cam.height());
    let prep = Prepared::new(scene, t_wc, opts.shading);
    let tiles = Tiles::new(&prep, cam, t_wc);
    let caster = Caster {
        prep: &prep,
        cam,
        tiles,
    };

    // 1. Coarse pass on every fourth row and column, 2. refinement to every second, then to
    //    every pixel.
    let coarse = Grid::trace(&caster, w, h, 4);
    let marks = edge_marks(&prep, cam, t_wc, &coarse);
    let mid = coarse.refine(&caster, 2, Some(&marks));
    let Grid { keys, rad, .. } = mid.refine(&caster, 1, None);
    let mut rad = rad;
    let s = opts.supersample;
    if s == 1 {
        return rad;
    }

    // 3. Edge flags from the midpoints of differing neighbour pairs. Each pixel owns the pairs
    //    with its right, lower-left, lower and lower-right neighbours and computes each pair's
    //    midpoint ray once: `own` collects the flags the pairs give the owner, `other[p]` the
    //    flag pair p gives the neighbour.
    const FORWARD: [(i64, i64); 4] = [(1, 0), (-1, 1), (0, 1), (1, 1)];
    let mut own = vec![0u8; w * h];
    let mut other = vec![[0u8; 4]; w * h];
    own.par_chunks_mut(w)
        .zip(other.par_chunks_mut(w))
        .enumerate()
        .for_each(|(v, (orow, nrow))| {
            let mut sub = Subset::default();
            for u in 0..w {
                let (ka, la) = (keys[v * w + u], rad[v * w + u] as f64);
                for (p, (du, dv)) in FORWARD.iter().enumerate() {
                    let (nu, nv) = (u as i64 + du, v as i64 + dv);
                    if nu < 0 || nu >= w as i64 || nv >= h as i64 {
                        continue;
                    }
                    let n = nv as usize * w + nu as usize;
                    let (kn, ln) = (keys[n], rad[n] as f64);
                    if !worth_midpoint(kn, ln, ka, la) {
                        continue;
                    }
                    sub.clear();
                    sub.add(ka, la);
                    sub.add(kn, ln);
                    let (um, vm) = (u as f64 + 0.5 * *du as f64, v as f64 + 0.5 * *dv as f64);
                    let (lm, km) = caster.sample_subset(um, vm, u, v, &sub);
                    orow[u] = orow[u].max(differs(km, lm, ka, la));
                    nrow[u][p] = differs(km, lm, kn, ln);
                }
            }
        });
    let flags: Vec<u8> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (u, v) = ((i % w) as i64, (i / w) as i64);
            let mut f = own[i];
            for (p, (du, dv)) in FORWARD.iter().enumerate() {
                // The owner of the pair in which this pixel is the neighbour.
                let (ou, ov) = (u - du, v - dv);
                if ou >= 0 && ov >= 0 && ou < w as i64 && ov < h as i64 {
                    f = f.max(other[ov as usize * w + ou as usize][p]);
                }
            }
            f
        })
        .collect();

    // 4. Anti-aliasing of the flagged pixels, traced against the surfaces their 3×3
    //    neighbourhood sees (a surface no neighbouring centre sees is narrower than the
    //    sampling resolves anyway), falling back to the tile when the sub-ray misses them.
    let full = n_rooks(s);
    let light = n_rooks(s.min(2));
    let base = rad.clone();
    rad.par_chunks_mut(w).enumerate().for_each(|(v, rrow)| {
        let mut sub = Subset::default();
        let mut bundle = Bundle::default();
        for (u, px) in rrow.iter_mut().enumerate() {
            let offsets = match flags[v * w + u] {
                FLAG_PRIMARY => &full,
                FLAG_MIRROR => &light,
                _ => continue,
            };
            sub.clear();
            for nv in v.saturating_sub(1)..(v + 2).min(h) {
                for nu in u.saturating_sub(1)..(u + 2).min(w) {
                    sub.add(keys[nv * w + nu], base[nv * w + nu] as f64);
                }
            }
            *px = caster.pixel_mean(u, v, offsets, &sub, &mut bundle) as f32;
        }
    });
    rad
}

/// `s×s` sub-pixel offsets in `(−0.5, 0.5)²`: the n-rooks pattern `((a + (b + ½)/s)/s − ½,
/// (b + (a + ½)/s)/s − ½)`, one sample per stratum with all rows and columns distinct.
fn n_rooks(s: usize) -> Vec<(f64, f64)> {
    let sf = s as f64;
    (0..s)
        .flat_map(|a| (0..s).map(move |b| (a as f64, b as f64)))
        .map(|(a, b)| {
            (
                (a + (b + 0.5) / sf) / sf - 0.5,
                (b + (a + 0.5) / sf) / sf - 0.5,
            )
        })
        .collect()
}

/// Number of rim samples per circle used to bound a wafer's image.
const BOUND_SAMPLES: usize = 128;
/// Samples per box edge used to bound a box's image.
const EDGE_SAMPLES: usize = 9;
/// Padding (pixels) of the projected bounding boxes.
const BOUND_PAD: f64 = 3.0;

/// Side of the square image tiles that carry their own candidate lists.
const TILE: usize = 16;

/// Per image tile, the primitives whose projected bounding box meets the tile (every ray
/// within ±0.5 px of the tile's pixel centres), in increasing distance from the camera.
pub(crate) struct Tiles {
    nx: usize,
    pub(crate) lists: Vec<Vec<TileCand>>,
}

impl Tiles {
    pub(crate) fn new<C: RayCamera>(prep: &Prepared, cam: &C, t_wc: &Isometry3<f64>) -> Self {
        let (w, h) = (cam.width(), cam.height());
        let t_cw = t_wc.inverse();
        let full = [
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::INFINITY,
        ];
        let bounds: Vec<[f32; 4]> = prep
            .prims
            .par_iter()
            .map(|p| {
                if p.aabb.distance_to_point(&prep.cam_center) == 0.0 {
                    return full;
                }
                let mut b = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for x in prim_outline(prep, p) {
                    let pc = t_cw * nalgebra::Point3::from(x);
                    match cam.project(&pc.coords) {
                        Some(q) if q.x.is_finite() && q.y.is_finite() => {
                            b = [b[0].min(q.x), b[1].min(q.y), b[2].max(q.x), b[3].max(q.y)];
                        }
                        _ => return full,
                    }
                }
                [
                    (b[0] - BOUND_PAD) as f32,
                    (b[1] - BOUND_PAD) as f32,
                    (b[2] + BOUND_PAD) as f32,
                    (b[3] + BOUND_PAD) as f32,
                ]
            })
            .collect();
        let nx = w.div_ceil(TILE);
        let ny = h.div_ceil(TILE);
        let lists = (0..nx * ny)
            .into_par_iter()
            .map(|t| {
                let (tx, ty) = ((t % nx) as f32, (t / nx) as f32);
                let t = TILE as f32;
                let (u0, v0) = (tx * t - 0.5, ty * t - 0.5);
                let (u1, v1) = (u0 + t, v0 + t);
                prep.by_distance
                    .iter()
                    .filter_map(|c| {
                        let b = bounds[c.prim as usize];
                        (b[0] <= u1 && b[2] >= u0 && b[1] <= v1 && b[3] >= v0).then_some(TileCand {
                            prim: c.prim,
                            bounds: b,
                            dmin: c.dmin,
                        })
                    })
                    .collect()
            })
            .collect();
        Self { nx, lists }
    }

    /// Candidates of the tile holding pixel `(u, v)`.
    #[inline]
    fn get(&self, u: usize, v: usize) -> &[TileCand] {
        &self.lists[(v / TILE) * self.nx + u / TILE]
    }
}

/// World points on a primitive's outline whose projections bound its image: both rims of a
/// wafer, the edges of a box.
fn prim_outline(prep: &Prepared, p: &trace::Prim) -> Vec<Vector3<f64>> {
    match &p.shape {
        trace::Shape::Wafer { rot, pos, .. } => {
            let mut out = Vec::with_capacity(2 * BOUND_SAMPLES);
            for z in [prep.half, -prep.half] {
                for j in 0..BOUND_SAMPLES {
                    let phi = std::f64::consts::TAU * j as f64 / BOUND_SAMPLES as f64;
                    out.push(
                        pos + rot
                            * Vector3::new(prep.radius * phi.cos(), prep.radius * phi.sin(), z),
                    );
                }
            }
            out
        }
        trace::Shape::Box(_) => {
            let c = p.aabb.corners();
            let mut out = Vec::with_capacity(12 * EDGE_SAMPLES);
            for i in 0..8usize {
                for bit in [1usize, 2, 4] {
                    if i & bit == 0 {
                        let (a, b) = (c[i], c[i | bit]);
                        for k in 0..EDGE_SAMPLES {
                            let t = k as f64 / (EDGE_SAMPLES - 1) as f64;
                            out.push(a + (b - a) * t);
                        }
                    }
                }
            }
            out
        }
    }
}
