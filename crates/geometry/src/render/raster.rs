//! The pixel pipeline: which rays to cast for which pixel, and how to combine them.
//!
//! 1. Coarse pass: the centres of the pixels with even `u` and `v` (and the last row/column).
//! 2. Fill: a pixel inside a 2×2 cell whose four coarse corners see the same surface (and the
//!    same surface in the mirror) takes the bilinear interpolation of the corners' radiance,
//!    which varies smoothly over one surface; every other pixel centre is traced. A feature
//!    that crosses a cell without changing the surface seen at its corners would have to be
//!    thinner than the cell and bounded by the same surface on both sides, which the scene
//!    produces only when a wafer is seen exactly edge-on against a uniform backdrop.
//! 3. Edge flags: for every pair of 8-neighbours whose centres see different surfaces, one ray
//!    at the midpoint of the two centres (for a diagonal pair, the shared pixel corner) tells on
//!    which side the boundary passes; for a single straight edge this flags exactly the pixels
//!    whose square it crosses.
//! 4. Anti-aliasing: each flagged pixel becomes the mean (box filter) of `s×s` sub-samples in an
//!    n-rooks pattern (all `s²` sub-sample rows and columns distinct); pixels flagged only by a
//!    change of the mirrored surface (low-contrast clutter) use `min(s, 2)²` sub-samples.

use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

use super::trace::{self, KEY_BACKGROUND, KEY_NO_RAY, KEY_NONE, Prepared, TileCand, key2};
use super::{RayCamera, RenderOptions, Scene};

/// Secondary-only (mirror) surface changes with a radiance step below this are not
/// anti-aliased: 4/255, about twice the default sensor noise.
const MIRROR_CONTRAST: f64 = 4.0 / 255.0;

/// Flag of a pixel crossed by a boundary between primary surfaces.
const FLAG_PRIMARY: u8 = 2;
/// Flag of a pixel crossed only by a boundary in the mirror image.
const FLAG_MIRROR: u8 = 1;

/// The primary half of a surface key.
#[inline]
fn primary(k: u64) -> u32 {
    (k >> 32) as u32
}

/// The mirror half of a surface key.
#[inline]
fn mirror(k: u64) -> u32 {
    k as u32
}

/// Sets of primitives for tracing a ray against the surfaces its neighbours see.
#[derive(Default)]
struct Subset {
    prims: Vec<u32>,
    mirrors: Vec<u32>,
    open_primary: bool,
    open_mirror: bool,
}

impl Subset {
    fn clear(&mut self) {
        self.prims.clear();
        self.mirrors.clear();
        self.open_primary = false;
        self.open_mirror = false;
    }

    fn add(&mut self, k: u64) {
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
    /// Unit world direction of the ray through image position `(u, v)`.
    #[inline]
    fn ray(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let d = self.prep.r_wc * self.cam.bearing(u, v)?;
        let n = d.norm();
        (n > 0.0 && n.is_finite()).then(|| d / n)
    }

    /// Radiance and surface key at `(u, v)`, traced against the whole tile of pixel `(pu, pv)`.
    #[inline]
    fn sample(&self, u: f64, v: f64, pu: usize, pv: usize) -> (f64, u64) {
        match self.ray(u, v) {
            Some(d) => {
                let hit = self.prep.trace_primary(&d, self.tiles.get(pu, pv), u as f32, v as f32);
                self.prep.shade(&self.prep.cam_center, &d, hit, None)
            }
            None => (self.prep.shading.background, key2(KEY_NO_RAY, KEY_NO_RAY)),
        }
    }

    /// As [`Self::sample`], but traced against the surfaces in `sub` first, falling back to
    /// the tile when the ray misses them and they do not include the background.
    #[inline]
    fn sample_subset(&self, u: f64, v: f64, pu: usize, pv: usize, sub: &Subset) -> (f64, u64) {
        match self.ray(u, v) {
            Some(d) => {
                let hit = match self.prep.trace_primary_subset(&d, &sub.prims) {
                    None if !sub.open_primary => {
                        self.prep.trace_primary(&d, self.tiles.get(pu, pv), u as f32, v as f32)
                    }
                    found => found,
                };
                self.prep.shade(&self.prep.cam_center, &d, hit, Some((&sub.mirrors, sub.open_mirror)))
            }
            None => (self.prep.shading.background, key2(KEY_NO_RAY, KEY_NO_RAY)),
        }
    }
}

/// Does the surface `k` at radiance `l` differ from `ka` at `la` enough to matter: another
/// primary surface, or another mirrored surface with a visible radiance step? Returns the flag.
#[inline]
fn differs(k: u64, l: f64, ka: u64, la: f64) -> u8 {
    if primary(k) != primary(ka) {
        FLAG_PRIMARY
    } else if k != ka && (l - la).abs() > MIRROR_CONTRAST {
        FLAG_MIRROR
    } else {
        0
    }
}

/// Coarse sample coordinates along an axis of `n` pixels: 0, 2, 4, … and `n − 1`.
fn coarse_axis(n: usize) -> Vec<usize> {
    let mut c: Vec<usize> = (0..n).step_by(2).collect();
    if (n - 1) % 2 == 1 {
        c.push(n - 1);
    }
    c
}

/// Index of the coarse cell (left/upper corner index into `coarse_axis`) holding pixel `x`.
#[inline]
fn cell_of(x: usize, n_coarse: usize) -> usize {
    (x / 2).min(n_coarse.saturating_sub(2))
}

/// Linear radiance per pixel after anti-aliasing (before lighting, blur and noise). Inputs must
/// have been validated.
pub(crate) fn radiance<C: RayCamera>(scene: &Scene, cam: &C, t_wc: &Isometry3<f64>, opts: &RenderOptions) -> Vec<f32> {
    let (w, h) = (cam.width(), cam.height());
    let t0 = std::time::Instant::now();
    let dbg = |what: &str| if std::env::var_os("DBG_TIMING").is_some() { eprintln!("DBG {what} {:?}", t0.elapsed()) };
    let prep = Prepared::new(scene, t_wc, opts.shading);
    let tiles = Tiles::new(&prep, cam, t_wc);
    let caster = Caster { prep: &prep, cam, tiles };

    // 1. Coarse pass.
    let cu = coarse_axis(w);
    let cv = coarse_axis(h);
    let (ncu, ncv) = (cu.len(), cv.len());
    let mut ckeys = vec![0u64; ncu * ncv];
    let mut crad = vec![0f64; ncu * ncv];
    ckeys.par_chunks_mut(ncu).zip(crad.par_chunks_mut(ncu)).enumerate().for_each(|(j, (krow, rrow))| {
        let v = cv[j];
        for (i, &u) in cu.iter().enumerate() {
            let (l, k) = caster.sample(u as f64, v as f64, u, v);
            krow[i] = k;
            rrow[i] = l;
        }
    });

    dbg("coarse");
    // 2. Fill.
    let mut keys = vec![0u64; w * h];
    let mut rad = vec![0f32; w * h];
    keys.par_chunks_mut(w).zip(rad.par_chunks_mut(w)).enumerate().for_each(|(v, (krow, rrow))| {
        let j = cell_of(v, ncv);
        let (v0, v1) = (cv[j], cv[(j + 1).min(ncv - 1)]);
        let fy = if v1 > v0 { (v - v0) as f64 / (v1 - v0) as f64 } else { 0.0 };
        for u in 0..w {
            let i = cell_of(u, ncu);
            let (u0, u1) = (cu[i], cu[(i + 1).min(ncu - 1)]);
            let (i1, j1) = ((i + 1).min(ncu - 1), (j + 1).min(ncv - 1));
            let c = [j * ncu + i, j * ncu + i1, j1 * ncu + i, j1 * ncu + i1];
            if (u == u0 || u == u1) && (v == v0 || v == v1) {
                // A coarse sample itself.
                let idx = if u == u0 { 0 } else { 1 } + if v == v0 { 0 } else { 2 };
                krow[u] = ckeys[c[idx]];
                rrow[u] = crad[c[idx]] as f32;
                continue;
            }
            let k = ckeys[c[0]];
            if c.iter().all(|&ci| ckeys[ci] == k) {
                let fx = if u1 > u0 { (u - u0) as f64 / (u1 - u0) as f64 } else { 0.0 };
                let top = crad[c[0]] * (1.0 - fx) + crad[c[1]] * fx;
                let bottom = crad[c[2]] * (1.0 - fx) + crad[c[3]] * fx;
                krow[u] = k;
                rrow[u] = (top * (1.0 - fy) + bottom * fy) as f32;
            } else {
                let (l, k) = caster.sample(u as f64, v as f64, u, v);
                krow[u] = k;
                rrow[u] = l as f32;
            }
        }
    });
    dbg("fill");
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
    own.par_chunks_mut(w).zip(other.par_chunks_mut(w)).enumerate().for_each(|(v, (orow, nrow))| {
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
                if differs(kn, ln, ka, la) == 0 {
                    continue;
                }
                sub.clear();
                sub.add(ka);
                sub.add(kn);
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

    dbg(&format!("flags ({} primary, {} mirror)", flags.iter().filter(|&&f| f == FLAG_PRIMARY).count(), flags.iter().filter(|&&f| f == FLAG_MIRROR).count()));
    if std::env::var_os("DBG_FLAGS").is_some() {
        let mut bytes = format!("P5\n{w} {h}\n255\n").into_bytes();
        bytes.extend(flags.iter().map(|f| f * 120));
        std::fs::write("/tmp/flags.pgm", bytes).ok();
    }
    // 4. Anti-aliasing of the flagged pixels, traced against the surfaces their 3×3
    //    neighbourhood sees (a surface no neighbouring centre sees is narrower than the
    //    sampling resolves anyway), falling back to the tile when the sub-ray misses them.
    let full = n_rooks(s);
    let light = n_rooks(s.min(2));
    rad.par_chunks_mut(w).enumerate().for_each(|(v, rrow)| {
        let mut sub = Subset::default();
        for (u, px) in rrow.iter_mut().enumerate() {
            let offsets = match flags[v * w + u] {
                FLAG_PRIMARY => &full,
                FLAG_MIRROR => &light,
                _ => continue,
            };
            sub.clear();
            for nv in v.saturating_sub(1)..(v + 2).min(h) {
                for nu in u.saturating_sub(1)..(u + 2).min(w) {
                    sub.add(keys[nv * w + nu]);
                }
            }
            let sum: f64 = offsets
                .iter()
                .map(|(dx, dy)| caster.sample_subset(u as f64 + dx, v as f64 + dy, u, v, &sub).0)
                .sum();
            *px = (sum / offsets.len() as f64) as f32;
        }
    });
    dbg("aa");
    rad
}

/// `s×s` sub-pixel offsets in `(−0.5, 0.5)²`: the n-rooks pattern `((a + (b + ½)/s)/s − ½,
/// (b + (a + ½)/s)/s − ½)`, one sample per stratum with all rows and columns distinct.
fn n_rooks(s: usize) -> Vec<(f64, f64)> {
    let sf = s as f64;
    (0..s)
        .flat_map(|a| (0..s).map(move |b| (a as f64, b as f64)))
        .map(|(a, b)| ((a + (b + 0.5) / sf) / sf - 0.5, (b + (a + 0.5) / sf) / sf - 0.5))
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
        let full = [f32::NEG_INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::INFINITY];
        let bounds: Vec<[f32; 4]> = prep
            .prims
            .par_iter()
            .map(|p| {
                if p.aabb.distance_to_point(&prep.cam_center) == 0.0 {
                    return full;
                }
                let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
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
                    out.push(pos + rot * Vector3::new(prep.radius * phi.cos(), prep.radius * phi.sin(), z));
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

