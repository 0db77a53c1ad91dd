//! Edge detection and edge-chain linking into arcs (seed 000_3b1454b2b2194811.txt ch. 3.1 and
//! the first stage of the arc-based framework of §3.2, Fig. 3.1/3.3: "extracts arcs from the
//! edge image and filters out short and non-convex arcs").
//!
//! Pipeline:
//! 1. [`canny`]: Sobel gradients, non-maximum suppression with sub-pixel localisation
//!    (Devernay 1995 in the form of von Gioi & Randall 2017, "A sub-pixel edge detector: an
//!    implementation of the Canny/Devernay algorithm", IPOL: the maximum is searched
//!    horizontally or vertically, whichever is closer to the gradient, and refined by a
//!    parabola through three magnitudes) and hysteresis thresholding. Unlike
//!    `imageproc::edges::canny`, which always pre-smooths with σ = 1.4 px, the pre-blur is a
//!    parameter (default none): the two rims of a wafer are only 2–3 px apart and a σ = 1.4 blur
//!    pushes both edges of that bright band outward by ≈ 0.4 px, i.e. more than 1 % of a
//!    30 px minor axis (the unit tests compare the gradients with `imageproc`'s Sobel filters).
//! 2. [`link_edges`]: chaining of edge points into ordered curves with 8-connectivity. Each
//!    edge point is linked to the neighbour that continues its edge direction (perpendicular to
//!    the gradient, oriented so that the brighter side is always on the left) with a compatible
//!    gradient; at junctions the closest continuation wins and the other branches start their
//!    own chains (von Gioi & Randall 2017, §3.3).
//! 3. [`split_arcs`]: polygonal approximation (Ramer–Douglas–Peucker) of each chain, splitting
//!    at corners (turn above a threshold), inflections (sign change of the turn) and at the
//!    extreme points where the tangent changes quadrant, so that every arc lies in one quadrant
//!    of its ellipse; rejection of short and straight arcs; curvature estimation (turn per
//!    length of the polygon) for outlier rejection; and the quadrant class of each arc from the
//!    sign of its slope and the sign of the area between the arc and its chord (Fornaciari,
//!    Prati & Cucchiara 2014, "A fast and effective ellipse detector for embedded vision
//!    applications", the framework [40] the seed builds on).

// `!(x > y)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;

use crate::{DetectError, Result};

/// A pixel type of a grayscale image view.
pub trait Pixel: Copy + Send + Sync {
    /// The value as a grey level on the 0–255 scale (`u8` as is; floats are taken on the 0–1
    /// scale and multiplied by 255).
    fn grey(self) -> f32;
    /// Whether the value is finite (always true for integers).
    fn finite(self) -> bool;
    /// The value as `f64`, for error messages.
    fn value(self) -> f64;
}

impl Pixel for u8 {
    fn grey(self) -> f32 {
        f32::from(self)
    }
    fn finite(self) -> bool {
        true
    }
    fn value(self) -> f64 {
        f64::from(self)
    }
}

impl Pixel for f32 {
    fn grey(self) -> f32 {
        self * 255.0
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
    fn value(self) -> f64 {
        f64::from(self)
    }
}

impl Pixel for f64 {
    fn grey(self) -> f32 {
        (self * 255.0) as f32
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
    fn value(self) -> f64 {
        self
    }
}

/// A borrowed row-major grayscale image: pixel `(u, v)` (column, row) is `data[v·width + u]`
/// and is centred at image position `(u, v)` (OpenCV convention).
#[derive(Debug, Clone, Copy)]
pub struct GrayView<'a, T: Pixel> {
    data: &'a [T],
    width: usize,
    height: usize,
}

impl<'a, T: Pixel> GrayView<'a, T> {
    /// Wraps `data` as a `width × height` image.
    ///
    /// # Errors
    /// [`DetectError::WrongLength`] if `data.len() != width·height`;
    /// [`DetectError::InvalidParameter`] if either side is 0; [`DetectError::NonFinite`] for a NaN or
    /// infinite pixel.
    pub fn new(data: &'a [T], width: usize, height: usize) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(DetectError::InvalidParameter {
                what: "image size",
                value: (width * height) as f64,
                reason: "the image has no pixels (width or height is 0)",
            });
        }
        let expected = width.saturating_mul(height);
        if data.len() != expected {
            return Err(DetectError::WrongLength {
                what: "image data",
                got: data.len(),
                expected,
            });
        }
        if let Some((index, p)) = data.iter().enumerate().find(|(_, p)| !p.finite()) {
            return Err(DetectError::NonFinite {
                what: "image",
                index,
                value: p.value(),
            });
        }
        Ok(Self {
            data,
            width,
            height,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixels, row-major.
    pub fn data(&self) -> &'a [T] {
        self.data
    }
}

/// Options of [`canny`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CannyParams {
    /// Hysteresis low threshold on the gradient magnitude, in grey levels per pixel (Sobel
    /// normalised by 1/8, so a unit step of height `h` gives `h/2`). Default 6.
    pub low: f64,
    /// Hysteresis high threshold (grey levels per pixel). Default 15.
    pub high: f64,
    /// Standard deviation (pixels) of an optional Gaussian pre-blur; 0 (default) for none.
    pub blur_sigma: f64,
}

impl Default for CannyParams {
    fn default() -> Self {
        Self {
            low: 6.0,
            high: 15.0,
            blur_sigma: 0.0,
        }
    }
}

impl CannyParams {
    fn validate(&self) -> Result<()> {
        if !(self.low >= 0.0 && self.low.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what: "canny low threshold",
                value: self.low,
                reason: "must be finite and >= 0",
            });
        }
        if !(self.high >= self.low && self.high.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what: "canny high threshold",
                value: self.high,
                reason: "must be finite and >= the low threshold",
            });
        }
        if !(self.blur_sigma >= 0.0 && self.blur_sigma <= 20.0) {
            return Err(DetectError::InvalidParameter {
                what: "blur_sigma",
                value: self.blur_sigma,
                reason: "must be in [0, 20] pixels",
            });
        }
        Ok(())
    }
}

/// One edge point (edgel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edgel {
    /// Sub-pixel position (pixels, `(u, v)`).
    pub pos: Vector2<f64>,
    /// Gradient (grey levels per pixel), pointing from dark to bright.
    pub grad: Vector2<f64>,
    /// Pixel column.
    pub px: u32,
    /// Pixel row.
    pub py: u32,
}

/// The result of [`canny`]: the edge points and a per-pixel index into them.
#[derive(Debug, Clone)]
pub struct EdgeMap {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// The edge points, in raster order.
    pub edgels: Vec<Edgel>,
    /// `index[v·width + u]` is the edgel at that pixel, or `u32::MAX`.
    pub index: Vec<u32>,
}

/// No edgel at this pixel.
const NONE: u32 = u32::MAX;

/// Separable Gaussian blur of a float image (clamped borders).
pub(crate) fn gaussian_blur(img: &mut [f32], w: usize, h: usize, sigma: f64) {
    let r = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / sum).collect();
    let mut tmp = vec![0.0f32; img.len()];
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    for y in 0..h {
        let row = &img[y * w..(y + 1) * w];
        for x in 0..w {
            let mut s = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                s += kv * row[clamp(x as isize + k as isize - r, w)];
            }
            tmp[y * w + x] = s;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                s += kv * tmp[clamp(y as isize + k as isize - r, h) * w + x];
            }
            img[y * w + x] = s;
        }
    }
}

/// Sobel gradients of one row, normalised by 1/8 (grey levels per pixel): `gx`, `gy` and the
/// squared magnitude `mag` at columns `1..w − 1` from the grey rows above (`r0`), at (`r1`)
/// and below (`r2`); zero in the first and last column.
#[inline(always)]
fn sobel_row(
    (r0, r1, r2): (&[f32], &[f32], &[f32]),
    gx: &mut [f32],
    gy: &mut [f32],
    mag: &mut [f32],
) {
    let w = r1.len();
    for out in [&mut *gx, &mut *gy, &mut *mag] {
        out[0] = 0.0;
        out[w - 1] = 0.0;
    }
    // Straight-line code over equal-length slices: compiles to vector code.
    let n = w - 2;
    let (a, b, c) = (&r0[..n], &r0[1..n + 1], &r0[2..n + 2]);
    let (d, f) = (&r1[..n], &r1[2..n + 2]);
    let (g, hh, i) = (&r2[..n], &r2[1..n + 1], &r2[2..n + 2]);
    let (ox, oy, om) = (&mut gx[1..n + 1], &mut gy[1..n + 1], &mut mag[1..n + 1]);
    for x in 0..n {
        let sx = ((c[x] - a[x]) + 2.0 * (f[x] - d[x]) + (i[x] - g[x])) * 0.125;
        let sy = ((g[x] - a[x]) + 2.0 * (hh[x] - b[x]) + (i[x] - c[x])) * 0.125;
        ox[x] = sx;
        oy[x] = sy;
        om[x] = sx * sx + sy * sy;
    }
}

/// Sobel gradients normalised by 1/8 (grey levels per pixel), zero on the one-pixel border.
/// Returns `(gx, gy)` (whole images; [`canny`] streams the same rows instead).
#[cfg(test)]
pub(crate) fn sobel(img: &[f32], w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
    let mut gx = vec![0.0f32; w * h];
    let mut gy = vec![0.0f32; w * h];
    if w < 3 || h < 3 {
        return (gx, gy);
    }
    let mut mag = vec![0.0f32; w];
    for y in 1..h - 1 {
        let rows = (
            &img[(y - 1) * w..y * w],
            &img[y * w..(y + 1) * w],
            &img[(y + 1) * w..(y + 2) * w],
        );
        let (ox, oy) = (&mut gx[y * w..(y + 1) * w], &mut gy[y * w..(y + 1) * w]);
        sobel_row(rows, ox, oy, &mut mag);
    }
    (gx, gy)
}

/// A pixel that survived non-maximum suppression.
#[derive(Debug, Clone, Copy)]
struct Survivor {
    /// Pixel index `v·width + u`.
    k: u32,
    gx: f32,
    gy: f32,
    /// Sub-pixel offset of the maximum along the search direction.
    offset: f32,
}

/// Rows per parallel work item of [`canny`]'s fused pass.
const CANNY_ROWS: usize = 48;

/// The buffers of one block of rows of [`canny`]'s fused pass: its survivors (output) and the
/// three-row rings of grey levels, gradients and squared magnitudes. Kept by [`EdgeWorkspace`]
/// between calls, so that a frame's pass allocates nothing (the survivors' vector would
/// otherwise grow by doubling, with fresh pages, on every frame).
#[derive(Debug, Clone, Default)]
struct RowBlock {
    /// Survivors of the block, in raster order.
    survivors: Vec<Survivor>,
    /// Rings `[grey | gx | gy | mag]`, each `3·w` long.
    rings: Vec<f32>,
}

/// Where [`suppress_rows`] reads its grey rows: the image itself, or its blurred copy.
#[derive(Clone, Copy)]
enum GreySource<'a, T: Pixel> {
    /// The image's pixels (converted with [`Pixel::grey`]).
    Image(&'a [T]),
    /// A pre-blurred grey image.
    Blurred(&'a [f32]),
}

impl<T: Pixel> GreySource<'_, T> {
    /// Writes grey row `y` (of width `out.len()`) into `out`.
    #[inline(always)]
    fn row(&self, y: usize, out: &mut [f32]) {
        let w = out.len();
        match self {
            GreySource::Image(data) => {
                for (o, p) in out.iter_mut().zip(&data[y * w..(y + 1) * w]) {
                    *o = p.grey();
                }
            }
            GreySource::Blurred(b) => out.copy_from_slice(&b[y * w..(y + 1) * w]),
        }
    }
}

/// One block of rows of [`canny`]'s fused pass, run under runtime instruction-set dispatch
/// (`pulp`): the row loops of [`suppress_rows`] are compiled for the dispatched instruction set
/// (8-wide single-precision vectors with AVX2 on x86-64-v3, the baseline elsewhere). The
/// arithmetic is the same on every path (no fused multiply–adds), so the output is
/// bit-identical.
struct SuppressOp<'a, T: Pixel> {
    grey: GreySource<'a, T>,
    size: (usize, usize),
    rows: (usize, usize),
    thresholds: (f32, f32),
    state: &'a mut [u8],
    block: &'a mut RowBlock,
}

impl<T: Pixel> pulp::WithSimd for SuppressOp<'_, T> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        let ((w, h), (y0, y1)) = (self.size, self.rows);
        suppress_rows(
            &self.grey,
            w,
            h,
            y0,
            y1,
            self.thresholds,
            self.state,
            self.block,
        );
    }
}

/// Sobel gradients and non-maximum suppression (with the parabolic refinement) of rows
/// `y0..y1` (clipped to the suppression range `2..h − 2`), streamed through three-row rings
/// of the grey rows of `grey` (in `block.rings`, resized as needed). Writes the state (1
/// candidate, 2 strong) of each survivor into `state` (the rows `y0..y1`) and the survivors,
/// in raster order, into `block.survivors` (cleared first).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn suppress_rows<T: Pixel>(
    grey: &GreySource<'_, T>,
    w: usize,
    h: usize,
    y0: usize,
    y1: usize,
    (low, high): (f32, f32),
    state: &mut [u8],
    block: &mut RowBlock,
) {
    let out = &mut block.survivors;
    out.clear();
    let (ys, ye) = (y0.max(2), y1.min(h.saturating_sub(2)));
    if ys >= ye || w < 5 {
        return;
    }
    // Every ring entry that is read was written before in this call (grey rows before their
    // gradients, gradient rows before their suppression), so stale contents do not matter.
    block.rings.resize(12 * w, 0.0);
    let (g, rest) = block.rings.split_at_mut(3 * w);
    let (gx, rest) = rest.split_at_mut(3 * w);
    let (gy, mag) = rest.split_at_mut(3 * w);
    let slot = |r: usize| (r % 3) * w..(r % 3 + 1) * w;
    grey.row(ys - 2, &mut g[slot(ys - 2)]);
    grey.row(ys - 1, &mut g[slot(ys - 1)]);
    for r in ys - 1..=ye {
        // Gradient row r from grey rows r − 1, r, r + 1 (r + 1 ≤ h − 1).
        grey.row(r + 1, &mut g[slot(r + 1)]);
        sobel_row(
            (&g[slot(r - 1)], &g[slot(r)], &g[slot(r + 1)]),
            &mut gx[slot(r)],
            &mut gy[slot(r)],
            &mut mag[slot(r)],
        );
        if r < ys + 1 {
            continue;
        }
        // Suppression of row y = r − 1 (magnitude rows y − 1, y, y + 1 are in the ring).
        let y = r - 1;
        let (mu, mc, md) = (&mag[slot(y - 1)], &mag[slot(y)], &mag[slot(y + 1)]);
        let (gxr, gyr) = (&gx[slot(y)], &gy[slot(y)]);
        let srow = &mut state[(y - y0) * w..(y - y0 + 1) * w];
        // Most pixels are under the low threshold: one branch-free comparison pass gives the
        // bit mask of the candidates of 32 columns at a time, and only its set bits are
        // visited (in increasing column order, as a scan would).
        let candidates = |ms: &[f32]| {
            let mut mask = 0u32;
            for (i, &m) in ms.iter().enumerate() {
                mask |= u32::from(m >= low && m != 0.0) << i;
            }
            mask
        };
        let chunks = mc[2..w - 2].chunks_exact(32);
        let rest = candidates(chunks.remainder());
        let masks = chunks.map(candidates).chain(std::iter::once(rest));
        for (c, mut mask) in masks.enumerate() {
            while mask != 0 {
                let x = 2 + 32 * c + mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let m = mc[x];
                let horizontal = gxr[x].abs() >= gyr[x].abs();
                let (ma, mb) = if horizontal {
                    (mc[x - 1], mc[x + 1])
                } else {
                    (mu[x], md[x])
                };
                // Strict on one side, non-strict on the other (von Gioi & Randall 2017).
                if m > ma && m >= mb {
                    srow[x] = if m >= high { 2 } else { 1 };
                    let (ma, m, mb) = (ma.sqrt(), m.sqrt(), mb.sqrt());
                    let den = ma - 2.0 * m + mb;
                    let offset = if den < 0.0 {
                        (0.5 * (ma - mb) / den).clamp(-0.5, 0.5)
                    } else {
                        0.0
                    };
                    out.push(Survivor {
                        k: (y * w + x) as u32,
                        gx: gxr[x],
                        gy: gyr[x],
                        offset,
                    });
                }
            }
        }
    }
}

/// Canny edge detection with sub-pixel edge positions (000_3b1454b2b2194811.txt §3.1, the
/// "edge detector [33] which calculates gradients of the points and extracts edgels"): Sobel
/// gradients, non-maximum suppression along the horizontal or vertical (whichever is closer to
/// the gradient direction) with the Devernay parabolic refinement, and hysteresis with
/// 8-connectivity. See the module documentation.
///
/// Implementation: one fused pass per block of rows (rayon) converts the grey rows, takes the
/// Sobel gradients and suppresses non-maxima through three-row ring buffers (no whole-image
/// gradient or magnitude buffers), keeping only the survivors; hysteresis then grows from the
/// strong survivors over a one-byte state image. The squared magnitudes are compared (monotone
/// in the magnitude); square roots are taken only for the parabolic refinement of the maxima.
///
/// Allocates the whole-image state and index images on every call; [`EdgeWorkspace::canny`]
/// gives the same edge map from buffers kept between calls (frames of a video).
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad thresholds or blur.
pub fn canny<T: Pixel>(image: &GrayView<'_, T>, params: &CannyParams) -> Result<EdgeMap> {
    params.validate()?;
    let (w, h) = (image.width, image.height);
    let mut state = vec![0u8; w * h];
    let mut map = EdgeMap {
        width: w,
        height: h,
        edgels: Vec::new(),
        index: vec![NONE; w * h],
    };
    canny_into(
        image,
        params,
        &mut state,
        &mut Vec::new(),
        &mut Vec::new(),
        &mut map,
    );
    Ok(map)
}

/// The work of [`canny`] on caller-provided buffers, with `params` already validated. On entry
/// `state` is `w·h` zeros, `map.index` is `w·h` × [`NONE`] and `map.edgels` is empty (sizes
/// set); on return `map` holds the edge map and `state` is all zeros again (only the survivors'
/// pixels are ever written, and they are cleared), so both can serve the next call unchanged.
/// `stack` and `blocks` are scratch (any contents).
fn canny_into<T: Pixel>(
    image: &GrayView<'_, T>,
    params: &CannyParams,
    state: &mut [u8],
    stack: &mut Vec<usize>,
    blocks: &mut Vec<RowBlock>,
    map: &mut EdgeMap,
) {
    let (w, h) = (image.width, image.height);
    let low = params.low as f32;
    let high = params.high as f32;
    let thresholds = (low * low, high * high);
    let blurred: Option<Vec<f32>> = (params.blur_sigma > 0.0).then(|| {
        let mut img: Vec<f32> = image.data.par_iter().map(|p| p.grey()).collect();
        gaussian_blur(&mut img, w, h, params.blur_sigma);
        img
    });
    let grey = match &blurred {
        Some(b) => GreySource::Blurred(b),
        None => GreySource::Image(image.data),
    };
    let arch = pulp::Arch::new();
    // `state`: 0 none, 1 candidate (≥ low), 2 strong (≥ high), 3 kept by the hysteresis.
    blocks.resize_with(h.div_ceil(CANNY_ROWS), RowBlock::default);
    state
        .par_chunks_mut(w * CANNY_ROWS)
        .zip(blocks.par_iter_mut())
        .enumerate()
        .for_each(|(c, (rows, block))| {
            let y0 = c * CANNY_ROWS;
            arch.dispatch(SuppressOp {
                grey,
                size: (w, h),
                rows: (y0, (y0 + CANNY_ROWS).min(h)),
                thresholds,
                state: rows,
                block,
            })
        });
    // All survivors in raster order (the blocks are consecutive row ranges).
    let blocks = &*blocks;
    let survivors = || blocks.iter().flat_map(|b| &b.survivors);
    // Hysteresis: grow from strong pixels through 8-connected candidates. Survivors lie in
    // rows and columns 2..n − 2, so every neighbour index is inside the image.
    stack.clear();
    let offsets = [
        -(w as isize) - 1,
        -(w as isize),
        -(w as isize) + 1,
        -1,
        1,
        w as isize - 1,
        w as isize,
        w as isize + 1,
    ];
    for s in survivors() {
        let k = s.k as usize;
        if state[k] != 2 {
            continue;
        }
        state[k] = 3;
        stack.push(k);
        while let Some(p) = stack.pop() {
            for d in offsets {
                let q = p.wrapping_add_signed(d);
                if let Some(v) = state.get_mut(q)
                    && (*v == 1 || *v == 2)
                {
                    *v = 3;
                    stack.push(q);
                }
            }
        }
    }
    let kept = survivors().filter(|s| state[s.k as usize] == 3).count();
    let (edgels, index) = (&mut map.edgels, &mut map.index);
    edgels.clear();
    edgels.reserve(kept);
    for s in survivors() {
        let k = s.k as usize;
        // Back to zero for the next call (a survivor is the only kind of pixel written).
        let kept = std::mem::take(&mut state[k]) == 3;
        if !kept {
            continue;
        }
        let (x, y) = (k % w, k / w);
        let o = f64::from(s.offset);
        let pos = if s.gx.abs() >= s.gy.abs() {
            Vector2::new(x as f64 + o, y as f64)
        } else {
            Vector2::new(x as f64, y as f64 + o)
        };
        index[k] = edgels.len() as u32;
        edgels.push(Edgel {
            pos,
            grad: Vector2::new(f64::from(s.gx), f64::from(s.gy)),
            px: x as u32,
            py: y as u32,
        });
    }
}

/// Buffers of the edge stage kept between calls: [`EdgeWorkspace::canny`] computes the same
/// edge map as [`canny`] without allocating and clearing the whole-image state (1 byte per
/// pixel) and index (4 bytes per pixel) images on every frame: only the pixels the last call
/// wrote are reset. (For 1280×720 images: where the allocator hands freed blocks back to the
/// system, fresh pages' faults and clearing were ≈ 4 of ≈ 10 ms of Canny; where it keeps them,
/// as in the Python benchmark, the clearing alone, ≈ 1 % of the detection.) [`detect_arcs`]
/// (and so [`crate::wafers::detect_wafers`]) keeps one workspace per thread; hold one yourself
/// to reuse the edge map between the stages.
#[derive(Debug, Clone)]
pub struct EdgeWorkspace {
    /// The last edge map; `index` is [`NONE`] except at the pixels of `edgels`.
    map: EdgeMap,
    /// The hysteresis state image, all zeros between calls.
    state: Vec<u8>,
    /// The hysteresis stack.
    stack: Vec<usize>,
    /// The per-block buffers of the fused Sobel/suppression pass.
    blocks: Vec<RowBlock>,
    /// Set while a call runs: a call that did not finish (a panic) leaves the buffers in an
    /// unknown state, and the next call then starts from fresh ones.
    busy: bool,
}

impl Default for EdgeWorkspace {
    fn default() -> Self {
        Self::new()
    }
}

impl EdgeWorkspace {
    /// An empty workspace (buffers are sized by the first image).
    pub fn new() -> Self {
        Self {
            map: EdgeMap {
                width: 0,
                height: 0,
                edgels: Vec::new(),
                index: Vec::new(),
            },
            state: Vec::new(),
            stack: Vec::new(),
            blocks: Vec::new(),
            busy: false,
        }
    }

    /// [`canny`] on the workspace's buffers (reallocated when the image size changes); the
    /// returned map is the same as [`canny`]'s and stays valid until the next call.
    ///
    /// # Errors
    /// As [`canny`] (the workspace is left usable).
    pub fn canny<T: Pixel>(
        &mut self,
        image: &GrayView<'_, T>,
        params: &CannyParams,
    ) -> Result<&EdgeMap> {
        params.validate()?;
        let (w, h) = (image.width, image.height);
        let map = &mut self.map;
        if self.busy || (map.width, map.height) != (w, h) || map.index.len() != w * h {
            *map = EdgeMap {
                width: w,
                height: h,
                edgels: Vec::new(),
                index: vec![NONE; w * h],
            };
            self.state = vec![0u8; w * h];
        } else {
            // Sparse reset of the last call's index entries.
            for e in &map.edgels {
                map.index[e.py as usize * w + e.px as usize] = NONE;
            }
            map.edgels.clear();
        }
        self.busy = true;
        canny_into(
            image,
            params,
            &mut self.state,
            &mut self.stack,
            &mut self.blocks,
            map,
        );
        self.busy = false;
        Ok(&self.map)
    }
}

mod arcs;
mod link;
pub use arcs::*;
pub use link::*;

#[cfg(test)]
mod tests;
