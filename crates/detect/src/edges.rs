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

/// Options of [`link_edges`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkParams {
    /// Smallest cosine between the gradient directions of two linked edgels. Default
    /// `cos 40°`.
    pub min_gradient_cos: f64,
}

impl Default for LinkParams {
    fn default() -> Self {
        Self {
            min_gradient_cos: 40f64.to_radians().cos(),
        }
    }
}

/// Links edgels into chains (000_3b1454b2b2194811.txt §3.2: "An arc is a curve of connected
/// points"). Each edgel `e` is linked forward to the 8-neighbour `f` that lies ahead along the
/// edge direction `t = (g_y, −g_x)/‖g‖` (brighter side on the left, image y down) and whose
/// gradient makes an angle under `acos(min_gradient_cos)` with `e`'s, choosing the closest
/// (sub-pixel distance) one; a neighbour claimed by two edgels keeps the closer one, so
/// junctions split into separate chains (von Gioi & Randall 2017, §3.3). Chains are returned in
/// edge-direction order, as edgel indices; closed contours are cut at their first edgel.
///
/// # Errors
/// [`DetectError::InvalidParameter`] if `min_gradient_cos` is not in `[-1, 1]`.
pub fn link_edges(map: &EdgeMap, params: &LinkParams) -> Result<Vec<Vec<u32>>> {
    if !(params.min_gradient_cos >= -1.0 && params.min_gradient_cos <= 1.0) {
        return Err(DetectError::InvalidParameter {
            what: "min_gradient_cos",
            value: params.min_gradient_cos,
            reason: "must be in [-1, 1]",
        });
    }
    let n = map.edgels.len();
    let (w, h) = (map.width as isize, map.height as isize);
    let mut next = vec![NONE; n];
    let mut prev = vec![NONE; n];
    let mut prev_dist = vec![f64::INFINITY; n];
    // Gradient magnitudes, once per edgel (each is read again by up to eight neighbours).
    let norms: Vec<f64> = map.edgels.iter().map(|e| e.grad.norm()).collect();
    for (i, (e, &gn)) in map.edgels.iter().zip(&norms).enumerate() {
        if !(gn > 0.0) {
            continue;
        }
        let g = e.grad / gn;
        let t = Vector2::new(g.y, -g.x);
        let mut best = (NONE, f64::INFINITY);
        for dy in [-1isize, 0, 1] {
            for dx in [-1isize, 0, 1] {
                if dx == 0 && dy == 0 {
                    continue;
                }
                let (qx, qy) = (e.px as isize + dx, e.py as isize + dy);
                if qx < 0 || qy < 0 || qx >= w || qy >= h {
                    continue;
                }
                let j = map.index[(qy * w + qx) as usize];
                if j == NONE {
                    continue;
                }
                let f = &map.edgels[j as usize];
                let d = f.pos - e.pos;
                if !(d.dot(&t) > 0.0) {
                    continue;
                }
                let fg = norms[j as usize];
                if !(f.grad.dot(&g) >= params.min_gradient_cos * fg) {
                    continue;
                }
                let dist = d.norm();
                if dist < best.1 {
                    best = (j, dist);
                }
            }
        }
        let (j, dist) = best;
        if j == NONE {
            continue;
        }
        let ju = j as usize;
        if dist < prev_dist[ju] {
            // Replace a farther claim on `j`.
            if prev[ju] != NONE {
                next[prev[ju] as usize] = NONE;
            }
            prev[ju] = i as u32;
            prev_dist[ju] = dist;
            next[i] = j;
        }
    }
    let mut visited = vec![false; n];
    let mut chains = Vec::new();
    // Open chains first (start where nothing links in), then what remains (closed loops).
    for pass in 0..2 {
        for start in 0..n {
            if visited[start] || (pass == 0 && prev[start] != NONE) {
                continue;
            }
            let mut chain = Vec::new();
            let mut k = start as u32;
            while k != NONE && !visited[k as usize] {
                visited[k as usize] = true;
                chain.push(k);
                k = next[k as usize];
            }
            chains.push(chain);
        }
    }
    Ok(chains)
}

/// Options of [`split_arcs`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcParams {
    /// Tolerance (pixels) of the polygonal approximation. Default 1.
    pub polygon_tolerance: f64,
    /// Turn (radians) between consecutive polygon sides above which the chain is cut (a
    /// corner). Default 50°.
    pub corner_angle: f64,
    /// Fewest edge points of an arc. Default 16.
    pub min_points: usize,
    /// An arc whose points all lie within this distance (pixels) of its chord is straight and
    /// rejected. Default 1.5.
    pub straight_tolerance: f64,
    /// Largest mean curvature (1/pixels) of an arc; higher is clutter. Default 0.25 (radius
    /// 4 px).
    pub max_curvature: f64,
    /// Placement of inflections: when the polygon's turn changes sign at a vertex and the
    /// points since the vertex of the last turn already bend the new way by more than this
    /// many standard errors of the chain's edge noise (a parabola fitted to them), the cut goes
    /// at that earlier vertex instead (see [`split_arcs`]). 0 always cuts at the later vertex
    /// (the plain polygon rule). Default 0 (off): at 3 it recovers rims on the wafer benchmark
    /// (recall 0.8249 → 0.8350 on seed 3, 0.7941 → 0.8074 on seed 4) but most recovered thin
    /// disturbance rims (b 5–10 px) still fit 0.5–1.5 % wide in `a`, so precision drops
    /// (0.9048 → 0.8877, 0.8955 → 0.8855); switch it on once those rims fit within 1 %.
    pub inflection_sigmas: f64,
    /// A vertex where the chain is cut (corner, inflection or quadrant change) starts a new
    /// piece, and its turn — the turn between the two pieces, not one inside the new piece —
    /// is not what the next vertex's turn is compared with for an inflection (see
    /// [`split_arcs`]). Without it, where a foreign contour joins a rim at the rim's tip (a thin
    /// rim's edge running on into a slot tooth's edge: a quadrant change at the junction), the
    /// junction's turn, opposite to the rim's, makes the rim's first own vertex an
    /// "inflection", and the side between them is cut off (and dropped as straight on a flat
    /// rim). Default true: on the wafer benchmark it recovers rims (recall 0.8698 → 0.8857 on
    /// seed 3, 0.8500 → 0.8662 on seed 4), but many recovered thin disturbance rims (b 5–10 px,
    /// seen along the front arc only) fit 1–5 % off in `b`, so on its own precision drops
    /// (0.9435 → 0.9301, 0.9398 → 0.9320); with the `σ_b` test of
    /// `DetectParams::max_relative_sigma_b` (which rejects most of those near-misses) both rise.
    pub restart_turn_at_cuts: bool,
    /// Straightness is a property of a convex run, not of one quadrant piece of it: a piece
    /// within `straight_tolerance` of its chord is kept when a cut that is only a quadrant
    /// change (no corner, no inflection) joins it to a neighbouring piece of the same chain
    /// that is kept as an arc, and its points bend the run's way significantly (the parabola
    /// test of the inflection rule at [`KEPT_FLAT_PIECE_SIGMAS`] standard errors of the
    /// chain's edge noise). On a flat rim (b/a ≲ 0.1) the half of the front arc between its
    /// lowest point and a foreign contour's junction sags only 0.5–1.5 px: dropped as straight
    /// it left the rim one arc, and a lone arc makes no segment (on the wafer benchmark, 8 of
    /// the 11 missed target lower rims of seed 3 and 8 of 12 of seed 4). Default true.
    pub keep_flat_run_pieces: bool,
}

/// Significance (standard errors of the chain's edge noise) of the bend of a flat piece kept
/// by [`ArcParams::keep_flat_run_pieces`].
pub const KEPT_FLAT_PIECE_SIGMAS: f64 = 3.0;

impl Default for ArcParams {
    fn default() -> Self {
        Self {
            polygon_tolerance: 1.0,
            corner_angle: 50f64.to_radians(),
            min_points: 16,
            straight_tolerance: 1.5,
            max_curvature: 0.25,
            inflection_sigmas: 0.0,
            restart_turn_at_cuts: true,
            keep_flat_run_pieces: true,
        }
    }
}

impl ArcParams {
    fn validate(&self) -> Result<()> {
        let checks = [
            ("polygon_tolerance", self.polygon_tolerance, 0.0, 100.0),
            ("corner_angle", self.corner_angle, 0.0, std::f64::consts::PI),
            ("straight_tolerance", self.straight_tolerance, 0.0, 1e6),
            ("max_curvature", self.max_curvature, 0.0, 1e6),
        ];
        for (what, value, lo, hi) in checks {
            if !(value > lo && value <= hi) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "out of range",
                });
            }
        }
        if !(self.inflection_sigmas >= 0.0 && self.inflection_sigmas.is_finite()) {
            return Err(DetectError::InvalidParameter {
                what: "inflection_sigmas",
                value: self.inflection_sigmas,
                reason: "must be finite and >= 0",
            });
        }
        if self.min_points < 5 {
            return Err(DetectError::InvalidParameter {
                what: "min_points",
                value: self.min_points as f64,
                reason: "an arc needs at least 5 points to constrain an ellipse",
            });
        }
        Ok(())
    }
}

/// The quadrant class of an arc (Fornaciari et al. 2014): which quarter of an ellipse, in the
/// displayed image (u right, v down), it can belong to. `I` is the upper-right quarter, `II`
/// the upper-left, `III` the lower-left, `IV` the lower-right (counter-clockwise on screen).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quadrant {
    /// Upper-right quarter: bulges toward +u and −v.
    I,
    /// Upper-left quarter: bulges toward −u and −v.
    II,
    /// Lower-left quarter: bulges toward −u and +v.
    III,
    /// Lower-right quarter: bulges toward +u and +v.
    IV,
}

impl Quadrant {
    /// `(sign u, sign v)` of the direction in which the arc bulges (away from its ellipse's
    /// centre).
    pub fn bulge(self) -> (f64, f64) {
        match self {
            Quadrant::I => (1.0, -1.0),
            Quadrant::II => (-1.0, -1.0),
            Quadrant::III => (-1.0, 1.0),
            Quadrant::IV => (1.0, 1.0),
        }
    }
}

/// An arc: edge points of one convex, single-quadrant piece of an edge chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Arc {
    /// Sub-pixel edge points, in chain order.
    pub points: Vec<Vector2<f64>>,
    /// Unit gradient directions (dark → bright) at the points.
    pub normals: Vec<Vector2<f64>>,
    /// Mean gradient magnitude (grey levels per pixel): the contrast of the edge.
    pub contrast: f64,
    /// The quadrant class.
    pub quadrant: Quadrant,
    /// `+1` if the gradient points to the convex side (away from the centre of curvature,
    /// brighter outside), `−1` if it points to the concave side.
    pub polarity: i8,
    /// Mean curvature (1/pixels): total turn of the polygon over its length.
    pub curvature: f64,
    /// Total turn of the arc's tangent (radians).
    pub turn: f64,
}

/// Ramer–Douglas–Peucker simplification: indices of the kept vertices (first and last always).
fn rdp(points: &[Vector2<f64>], tol: f64) -> Vec<usize> {
    let n = points.len();
    if n < 3 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let (a, b) = (points[i], points[j]);
        let d = b - a;
        let len = d.norm();
        let mut best = (0.0, i);
        for (k, p) in points.iter().enumerate().take(j).skip(i + 1) {
            let dist = if len > 0.0 {
                ((p - a).perp(&d) / len).abs()
            } else {
                (p - a).norm()
            };
            if dist > best.0 {
                best = (dist, k);
            }
        }
        if best.0 > tol {
            keep[best.1] = true;
            stack.push((i, best.1));
            stack.push((best.1, j));
        }
    }
    (0..n).filter(|&k| keep[k]).collect()
}

/// Robust standard deviation (pixels) of a chain's edge points across the chain: the median
/// absolute distance of each point to the chord of its neighbours three points away, scaled to
/// a Gaussian σ (1.4826 · MAD; for independent noise that distance has variance 1.5 σ²).
/// Floored at 0.01 px.
pub(crate) fn chain_noise(pts: &[Vector2<f64>]) -> f64 {
    const K: usize = 3;
    if pts.len() < 2 * K + 1 {
        return 0.01;
    }
    let mut d: Vec<f64> = (K..pts.len() - K)
        .filter_map(|i| {
            let chord = pts[i + K] - pts[i - K];
            let len = chord.norm();
            (len > 0.0).then(|| (chord.perp(&(pts[i] - pts[i - K])) / len).abs())
        })
        .collect();
    if d.is_empty() {
        return 0.01;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    (1.4826 * *m / 1.5f64.sqrt()).max(0.01)
}

/// Whether the points `pts[i..=j]` bend significantly toward `sign` (+1: to the left of the
/// chord `pts[j] − pts[i]`, the side a positive polygon turn bends to): the quadratic
/// coefficient of the least-squares parabola `across = c₀ + c₁ s + c₂ s²` in the chord frame
/// (`s` ∈ [−1, 1] along the chord) has that sign and exceeds `sigmas` of its standard error
/// `σ √((XᵀX)⁻¹)₂₂` under edge noise `sigma`. A local model over the whole side, not the
/// turn at one polygon vertex (which the noise of that one point moves by a degree or two on
/// a nearly straight arc).
fn side_bends(
    pts: &[Vector2<f64>],
    i: usize,
    j: usize,
    sign: f64,
    sigma: f64,
    sigmas: f64,
) -> bool {
    let Some(side) = pts.get(i..=j) else {
        return false;
    };
    let a = pts[i];
    let chord = pts[j] - a;
    let len2 = chord.norm_squared();
    if !(len2 > 0.0) || side.len() < 5 {
        return false;
    }
    let len = len2.sqrt();
    let mut xtx = Matrix3::<f64>::zeros();
    let mut xty = Vector3::<f64>::zeros();
    for p in side {
        let s = 2.0 * (p - a).dot(&chord) / len2 - 1.0;
        let across = chord.perp(&(p - a)) / len;
        let x = Vector3::new(1.0, s, s * s);
        xtx += x * x.transpose();
        xty += x * across;
    }
    let Some(inv) = xtx.try_inverse() else {
        return false;
    };
    let c2 = (inv * xty)[2];
    let se = sigma * inv[(2, 2)].max(0.0).sqrt();
    c2 * sign > sigmas * se
}

/// Splits edge chains into arcs and classifies them (000_3b1454b2b2194811.txt §3.2, first
/// stage: "extracts arcs from the edge image and filters out short and non-convex arcs"; the
/// quadrant classes of [37, 40] from "gradients and difference between areas over and under
/// the arc"; "curvature estimation for outlier rejection", Fig. 3.3).
///
/// Each chain is approximated by a polygon (Ramer–Douglas–Peucker, `polygon_tolerance`) and
/// cut at vertices where the turn exceeds `corner_angle` (corners), where the turn changes sign
/// (inflections, so arcs are convex; the cut goes at the earlier of the two vertices bounding
/// the sign change when the points between them already bend the new way, tested against the
/// chain's edge noise with `inflection_sigmas`: on a nearly straight arc the polygon's first
/// vertex after a foreign contour's junction turns the arc's way by only a few degrees, and
/// cutting there lost the side to a piece rejected as straight), and where the direction of
/// the sides changes quadrant
/// (the extreme points of an ellipse, so arcs are monotone in u and v). With
/// `restart_turn_at_cuts`, the turn at a cut vertex lies between two pieces and does not count
/// toward the next piece's convexity: an inflection is a sign change between two vertices
/// inside one piece. The curvature of each
/// piece (total turn over length) rejects pieces curved more than `max_curvature` (texture,
/// noise); pieces with fewer than `min_points` points or within `straight_tolerance` of their
/// chord (lines, e.g. the carrier's ridges) are dropped. The quadrant follows from the sign of
/// the chord's slope and of the area between arc and chord; the polarity from the mean
/// gradient relative to the bulge direction.
///
/// # Errors
/// [`DetectError::InvalidParameter`] for bad parameters.
pub fn split_arcs(map: &EdgeMap, chains: &[Vec<u32>], params: &ArcParams) -> Result<Vec<Arc>> {
    params.validate()?;
    let mut arcs = Vec::new();
    for chain in chains {
        if chain.len() < params.min_points {
            continue;
        }
        let pts: Vec<Vector2<f64>> = chain.iter().map(|&k| map.edgels[k as usize].pos).collect();
        let verts = rdp(&pts, params.polygon_tolerance);
        let sigma = if params.inflection_sigmas > 0.0 {
            chain_noise(&pts)
        } else {
            0.0
        };
        // Cut points (indices into `pts`), and per cut the turn sign of the convex run it
        // splits when it is only a quadrant change (`None`: the run ends there).
        let mut cuts = vec![0usize];
        let mut run_turn: Vec<Option<f64>> = vec![None];
        let mut last_turn_sign = 0.0;
        // The vertex (index into `pts`) that set `last_turn_sign`.
        let mut last_vertex: Option<usize> = None;
        for w in verts.windows(3) {
            let d0 = pts[w[1]] - pts[w[0]];
            let d1 = pts[w[2]] - pts[w[1]];
            let turn = d0.perp(&d1).atan2(d0.dot(&d1));
            let sign = turn.signum();
            let corner = turn.abs() > params.corner_angle;
            let inflection = last_turn_sign != 0.0 && sign != last_turn_sign && turn.abs() > 1e-9;
            // Quadrant change: a component of the side direction changes sign.
            let quadrant_change = d0.x * d1.x < 0.0 || d0.y * d1.y < 0.0;
            // The inflection lies between the vertex of the last turn and this one. When the
            // points between them already bend this vertex's way, the chain changed convexity
            // at the earlier vertex (a foreign contour meeting the arc there): cut there, so
            // the side goes with the arc it belongs to.
            let earlier = match last_vertex {
                Some(v) if inflection && params.inflection_sigmas > 0.0 => {
                    side_bends(&pts, v, w[1], sign, sigma, params.inflection_sigmas).then_some(v)
                }
                _ => None,
            };
            if let Some(v) = earlier {
                if cuts.last().is_some_and(|&c| v > c) {
                    cuts.push(v);
                    run_turn.push(None);
                }
                if quadrant_change {
                    cuts.push(w[1]);
                    run_turn.push((!corner).then_some(sign));
                }
            } else if corner || inflection || quadrant_change {
                cuts.push(w[1]);
                run_turn.push((quadrant_change && !corner && !inflection).then_some(sign));
            }
            // A cut at this vertex (not moved to an earlier one) starts a new piece here.
            let cut_here = corner || quadrant_change || (inflection && earlier.is_none());
            if corner || (params.restart_turn_at_cuts && cut_here) {
                last_turn_sign = 0.0;
                last_vertex = None;
            } else if quadrant_change || turn.abs() > 1e-9 {
                last_turn_sign = sign;
                last_vertex = Some(w[1]);
            }
        }
        cuts.push(pts.len() - 1);
        run_turn.push(None);
        // Pieces `(start, end)`; consecutive pieces do not share their cut point.
        let pieces: Vec<(usize, usize)> = cuts
            .windows(2)
            .enumerate()
            .map(|(k, win)| (if k == 0 { win[0] } else { win[0] + 1 }, win[1]))
            .collect();
        let long = |&(s, e): &(usize, usize)| e >= s && e + 1 - s >= params.min_points;
        let mut made: Vec<Option<Arc>> = pieces
            .iter()
            .map(|p| {
                long(p)
                    .then(|| make_arc(map, chain, &pts, p.0, p.1, params, false))
                    .flatten()
            })
            .collect();
        if params.keep_flat_run_pieces {
            let mut noise = None;
            for k in 0..pieces.len() {
                if made[k].is_some() || !long(&pieces[k]) {
                    continue;
                }
                // The run's turn sign across the cut before (after) piece `k`, when the
                // neighbour there is an arc.
                let before = run_turn[k].filter(|_| k > 0 && made[k - 1].is_some());
                let after =
                    run_turn[k + 1].filter(|_| made.get(k + 1).is_some_and(Option::is_some));
                let Some(sign) = before.or(after) else {
                    continue;
                };
                let sigma = *noise.get_or_insert_with(|| chain_noise(&pts));
                let (s, e) = pieces[k];
                if side_bends(&pts, s, e, sign, sigma, KEPT_FLAT_PIECE_SIGMAS) {
                    made[k] = make_arc(map, chain, &pts, s, e, params, true);
                }
            }
        }
        arcs.extend(made.into_iter().flatten());
    }
    Ok(arcs)
}

/// Builds and screens the arc `pts[s..=e]` (`flat_ok`: without the straightness test, for a
/// piece of a curved run, see [`ArcParams::keep_flat_run_pieces`]).
fn make_arc(
    map: &EdgeMap,
    chain: &[u32],
    pts: &[Vector2<f64>],
    s: usize,
    e: usize,
    params: &ArcParams,
    flat_ok: bool,
) -> Option<Arc> {
    let points = pts[s..=e].to_vec();
    let (a, b) = (points[0], points[points.len() - 1]);
    let chord = b - a;
    let len = chord.norm();
    if !(len > 0.0) {
        return None;
    }
    // Signed distances to the chord; area between arc and chord (trapezoids).
    let mut max_dev: f64 = 0.0;
    let mut area = 0.0;
    let mut prev: Option<(f64, f64)> = None;
    for p in &points {
        let along = (p - a).dot(&chord) / len;
        let across = chord.perp(&(p - a)) / len;
        max_dev = max_dev.max(across.abs());
        if let Some((pa, pc)) = prev {
            area += 0.5 * (across + pc) * (along - pa);
        }
        prev = Some((along, across));
    }
    if max_dev < params.straight_tolerance && !flat_ok {
        return None;
    }
    // Bulge direction: the unit normal of the chord on the side where the area between arc
    // and chord is (`across` is the signed distance along `left`).
    let left = Vector2::new(-chord.y, chord.x) / len;
    let bulge = if area > 0.0 { left } else { -left };
    let quadrant = match (bulge.x >= 0.0, bulge.y >= 0.0) {
        (true, false) => Quadrant::I,
        (false, false) => Quadrant::II,
        (false, true) => Quadrant::III,
        (true, true) => Quadrant::IV,
    };
    // Curvature and turn from a coarse polygon of the arc.
    let verts = rdp(&points, params.polygon_tolerance * 0.5);
    let mut turn = 0.0;
    let mut length = 0.0;
    for k in 1..verts.len() {
        length += (points[verts[k]] - points[verts[k - 1]]).norm();
    }
    for k in 1..verts.len().saturating_sub(1) {
        let d0 = points[verts[k]] - points[verts[k - 1]];
        let d1 = points[verts[k + 1]] - points[verts[k]];
        turn += d0.perp(&d1).atan2(d0.dot(&d1)).abs();
    }
    // A single side: the turn is at least the sagitta angle.
    let turn = turn.max(4.0 * max_dev / len);
    let curvature = if length > 0.0 { turn / length } else { 0.0 };
    if curvature > params.max_curvature {
        return None;
    }
    let mut normals = Vec::with_capacity(points.len());
    let mut contrast = 0.0;
    let mut pol = 0.0;
    for &k in &chain[s..=e] {
        let g = map.edgels[k as usize].grad;
        let gn = g.norm();
        contrast += gn;
        let u = if gn > 0.0 { g / gn } else { Vector2::zeros() };
        pol += u.dot(&bulge);
        normals.push(u);
    }
    contrast /= points.len() as f64;
    Some(Arc {
        points,
        normals,
        contrast,
        quadrant,
        polarity: if pol >= 0.0 { 1 } else { -1 },
        curvature,
        turn,
    })
}

thread_local! {
    /// The [`EdgeWorkspace`] of [`detect_arcs`] on this thread.
    static EDGE_WORKSPACE: std::cell::RefCell<EdgeWorkspace> =
        std::cell::RefCell::new(EdgeWorkspace::new());
}

/// [`canny`], [`link_edges`] and [`split_arcs`] with the given parameters.
///
/// The edge map comes from an [`EdgeWorkspace`] kept per thread (the whole-image buffers are
/// allocated once per thread and image size, not per call; same result as [`canny`]); a nested
/// call on the same thread (a rayon worker that picks up another detection while this one
/// waits) uses a fresh workspace. [`detect_arcs_with`] takes the workspace from the caller.
///
/// # Errors
/// As the three steps.
pub fn detect_arcs<T: Pixel>(
    image: &GrayView<'_, T>,
    canny_params: &CannyParams,
    link_params: &LinkParams,
    arc_params: &ArcParams,
) -> Result<Vec<Arc>> {
    EDGE_WORKSPACE.with(|cell| match cell.try_borrow_mut() {
        Ok(mut ws) => detect_arcs_with(&mut ws, image, canny_params, link_params, arc_params),
        Err(_) => detect_arcs_with(
            &mut EdgeWorkspace::new(),
            image,
            canny_params,
            link_params,
            arc_params,
        ),
    })
}

/// [`detect_arcs`] with the edge map computed in `workspace` ([`EdgeWorkspace::canny`]).
///
/// # Errors
/// As the three steps.
pub fn detect_arcs_with<T: Pixel>(
    workspace: &mut EdgeWorkspace,
    image: &GrayView<'_, T>,
    canny_params: &CannyParams,
    link_params: &LinkParams,
    arc_params: &ArcParams,
) -> Result<Vec<Arc>> {
    let map = workspace.canny(image, canny_params)?;
    let chains = link_edges(map, link_params)?;
    split_arcs(map, &chains, arc_params)
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::conic::Ellipse;

    /// A synthetic image: a bright filled ellipse (antialiased by supersampling) on dark.
    fn disc_image(w: usize, h: usize, cx: f64, cy: f64, a: f64, b: f64) -> Vec<u8> {
        let mut img = vec![0u8; w * h];
        let s = 8;
        for y in 0..h {
            for x in 0..w {
                let mut inside = 0;
                for j in 0..s {
                    for i in 0..s {
                        let u = x as f64 - 0.5 + (i as f64 + 0.5) / s as f64;
                        let v = y as f64 - 0.5 + (j as f64 + 0.5) / s as f64;
                        let q = ((u - cx) / a).powi(2) + ((v - cy) / b).powi(2);
                        if q <= 1.0 {
                            inside += 1;
                        }
                    }
                }
                img[y * w + x] = (30.0 + 170.0 * inside as f64 / (s * s) as f64).round() as u8;
            }
        }
        img
    }

    /// The whole-image implementation of `canny` (Sobel, magnitude, state and
    /// offset images, hysteresis over all pixels): the reference of the fused pass.
    fn canny_reference<T: Pixel>(image: &GrayView<'_, T>, params: &CannyParams) -> Result<EdgeMap> {
        params.validate()?;
        let (w, h) = (image.width, image.height);
        let mut img: Vec<f32> = image.data.par_iter().map(|p| p.grey()).collect();
        if params.blur_sigma > 0.0 {
            gaussian_blur(&mut img, w, h, params.blur_sigma);
        }
        let (gx, gy) = sobel(&img, w, h);
        let low = params.low as f32;
        let high = params.high as f32;
        // Squared magnitudes: monotone in the magnitude, so the suppression can compare them; the
        // square roots are taken only for the parabolic refinement of the maxima.
        let mag: Vec<f32> = gx
            .par_iter()
            .zip(gy.par_iter())
            .map(|(a, b)| a * a + b * b)
            .collect();
        let (low, high) = (low * low, high * high);
        // Non-maximum suppression (rows in parallel); `state`: 0 none, 1 candidate (≥ low),
        // 2 strong (≥ high).
        let mut state = vec![0u8; w * h];
        let mut offset = vec![0.0f32; w * h];
        if w >= 5 && h >= 5 {
            state
                .par_chunks_mut(w)
                .zip(offset.par_chunks_mut(w))
                .enumerate()
                .filter(|(y, _)| *y >= 2 && *y + 2 < h)
                .for_each(|(y, (srow, orow))| {
                    for x in 2..w - 2 {
                        let k = y * w + x;
                        let m = mag[k];
                        if !(m >= low) || m == 0.0 {
                            continue;
                        }
                        let horizontal = gx[k].abs() >= gy[k].abs();
                        let (ma, mb) = if horizontal {
                            (mag[k - 1], mag[k + 1])
                        } else {
                            (mag[k - w], mag[k + w])
                        };
                        // Strict on one side, non-strict on the other (von Gioi & Randall 2017).
                        if m > ma && m >= mb {
                            srow[x] = if m >= high { 2 } else { 1 };
                            let (ma, m, mb) = (ma.sqrt(), m.sqrt(), mb.sqrt());
                            let den = ma - 2.0 * m + mb;
                            orow[x] = if den < 0.0 {
                                (0.5 * (ma - mb) / den).clamp(-0.5, 0.5)
                            } else {
                                0.0
                            };
                        }
                    }
                });
        }
        // Hysteresis: grow from strong pixels through 8-connected candidates.
        let mut keep = vec![false; w * h];
        let mut stack = Vec::new();
        for k in 0..w * h {
            if state[k] == 2 && !keep[k] {
                keep[k] = true;
                stack.push(k);
                while let Some(p) = stack.pop() {
                    let (px, py) = (p % w, p / w);
                    for dy in [-1isize, 0, 1] {
                        for dx in [-1isize, 0, 1] {
                            let (qx, qy) = (px as isize + dx, py as isize + dy);
                            if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                                continue;
                            }
                            let q = qy as usize * w + qx as usize;
                            if state[q] != 0 && !keep[q] {
                                keep[q] = true;
                                stack.push(q);
                            }
                        }
                    }
                }
            }
        }
        let mut edgels = Vec::new();
        let mut index = vec![NONE; w * h];
        for k in 0..w * h {
            if !keep[k] {
                continue;
            }
            let (x, y) = (k % w, k / w);
            let horizontal = gx[k].abs() >= gy[k].abs();
            let o = f64::from(offset[k]);
            let pos = if horizontal {
                Vector2::new(x as f64 + o, y as f64)
            } else {
                Vector2::new(x as f64, y as f64 + o)
            };
            index[k] = edgels.len() as u32;
            edgels.push(Edgel {
                pos,
                grad: Vector2::new(f64::from(gx[k]), f64::from(gy[k])),
                px: x as u32,
                py: y as u32,
            });
        }
        Ok(EdgeMap {
            width: w,
            height: h,
            edgels,
            index,
        })
    }

    /// Two overlapping bright ellipses, a dark disc and deterministic noise.
    fn textured_image(w: usize, h: usize) -> Vec<u8> {
        let a = disc_image(
            w,
            h,
            0.45 * w as f64,
            0.5 * h as f64,
            0.3 * w as f64,
            0.2 * h as f64,
        );
        let b = disc_image(
            w,
            h,
            0.6 * w as f64,
            0.45 * h as f64,
            0.15 * w as f64,
            0.3 * h as f64,
        );
        let mut state = 12345u64;
        a.iter()
            .zip(&b)
            .enumerate()
            .map(|(k, (&p, &q))| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let noise = ((state >> 33) % 9) as f64 - 4.0;
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                let dark = if (x - 0.2 * w as f64).hypot(y - 0.3 * h as f64) < 0.1 * h as f64 {
                    -60.0
                } else {
                    0.0
                };
                (f64::from(p) + 0.6 * f64::from(q) + noise + dark).clamp(0.0, 255.0) as u8
            })
            .collect()
    }

    #[test]
    fn fused_canny_equals_the_whole_image_reference() {
        // Sizes that leave partial row blocks; u8 and f32 pixels, with and without pre-blur.
        for (w, h) in [(211, 157), (64, 5), (5, 64), (320, 97)] {
            let data = textured_image(w, h);
            let floats: Vec<f32> = data.iter().map(|&v| f32::from(v) / 255.0).collect();
            for params in [
                CannyParams::default(),
                CannyParams {
                    low: 3.0,
                    high: 8.0,
                    blur_sigma: 1.2,
                },
            ] {
                let view = GrayView::new(&data, w, h).unwrap();
                let (got, want) = (
                    canny(&view, &params).unwrap(),
                    canny_reference(&view, &params).unwrap(),
                );
                assert!(
                    w < 6 || h < 6 || got.edgels.len() > 20,
                    "{w}x{h}: {}",
                    got.edgels.len()
                );
                assert_eq!(got.edgels, want.edgels, "{w}x{h} u8 {params:?}");
                assert_eq!(got.index, want.index);
                let view = GrayView::new(&floats, w, h).unwrap();
                let (got, want) = (
                    canny(&view, &params).unwrap(),
                    canny_reference(&view, &params).unwrap(),
                );
                assert_eq!(got.edgels, want.edgels, "{w}x{h} f32 {params:?}");
                assert_eq!(got.index, want.index);
            }
        }
    }

    #[test]
    fn workspace_canny_equals_the_reference_over_a_sequence_of_frames() {
        // One workspace over frames of changing content, size, pixel type and parameters, a
        // rejected call and a call that did not finish: every map equals the whole-image
        // reference (the sparse reset leaves no edgel of an earlier frame behind).
        let mut ws = EdgeWorkspace::new();
        let blur = CannyParams {
            low: 3.0,
            high: 8.0,
            blur_sigma: 1.2,
        };
        let frames = [
            (211, 157, CannyParams::default()),
            (211, 157, blur),
            (211, 157, CannyParams::default()),
            (64, 5, CannyParams::default()),
            (320, 97, blur),
            (320, 97, CannyParams::default()),
        ];
        for (f, &(w, h, params)) in frames.iter().enumerate() {
            // Shift the content between frames of one size so that the edgels move.
            let mut data = textured_image(w, h);
            let shift = f * 7 % data.len();
            data.rotate_left(shift);
            let view = GrayView::new(&data, w, h).unwrap();
            let want = canny_reference(&view, &params).unwrap();
            let got = ws.canny(&view, &params).unwrap();
            assert!(w < 6 || h < 6 || got.edgels.len() > 20);
            assert_eq!(got.edgels, want.edgels, "frame {f} {w}x{h}");
            assert_eq!(got.index, want.index, "frame {f} {w}x{h}");
            assert!(ws.state.iter().all(|&s| s == 0), "state not cleared");
            let floats: Vec<f32> = data.iter().map(|&v| f32::from(v) / 255.0).collect();
            let view = GrayView::new(&floats, w, h).unwrap();
            let got = ws.canny(&view, &params).unwrap();
            assert_eq!(got.edgels, canny_reference(&view, &params).unwrap().edgels);
        }
        let (w, h) = (211, 157);
        let data = textured_image(w, h);
        let view = GrayView::new(&data, w, h).unwrap();
        let bad = CannyParams {
            low: f64::NAN,
            ..CannyParams::default()
        };
        assert!(matches!(
            ws.canny(&view, &bad),
            Err(DetectError::InvalidParameter { .. })
        ));
        let want = canny_reference(&view, &CannyParams::default()).unwrap();
        assert_eq!(
            ws.canny(&view, &CannyParams::default()).unwrap().index,
            want.index
        );
        // A call that stopped half-way (a panic inside) leaves garbage: the next call must not
        // trust the buffers.
        ws.busy = true;
        ws.state.iter_mut().for_each(|s| *s = 2);
        ws.map.index.iter_mut().for_each(|i| *i = 7);
        let got = ws.canny(&view, &CannyParams::default()).unwrap();
        assert_eq!(got.edgels, want.edgels);
        assert_eq!(got.index, want.index);
    }

    #[test]
    fn detect_arcs_with_the_thread_workspace_equals_the_allocating_steps() {
        let (w, h) = (320, 240);
        let mut ws = EdgeWorkspace::new();
        for (k, (cx, cy)) in [(150.0, 120.0), (170.0, 110.0), (150.0, 120.0)]
            .into_iter()
            .enumerate()
        {
            let data = disc_image(w, h, cx, cy, 90.0 + 5.0 * k as f64, 60.0);
            let view = GrayView::new(&data, w, h).unwrap();
            let (cp, lp, ap) = (
                CannyParams::default(),
                LinkParams::default(),
                ArcParams::default(),
            );
            let map = canny(&view, &cp).unwrap();
            let chains = link_edges(&map, &lp).unwrap();
            let want = split_arcs(&map, &chains, &ap).unwrap();
            assert!(want.len() >= 4, "{} arcs", want.len());
            assert_eq!(detect_arcs(&view, &cp, &lp, &ap).unwrap(), want);
            assert_eq!(
                detect_arcs_with(&mut ws, &view, &cp, &lp, &ap).unwrap(),
                want
            );
        }
    }

    #[test]
    fn sobel_matches_imageproc() {
        let (w, h) = (40, 30);
        let data = disc_image(w, h, 20.3, 14.8, 12.0, 8.0);
        let img: Vec<f32> = data.iter().map(|&v| f32::from(v)).collect();
        let (gx, gy) = sobel(&img, w, h);
        let gi = image::GrayImage::from_raw(w as u32, h as u32, data).unwrap();
        let hx = imageproc::gradients::horizontal_sobel(&gi);
        let hy = imageproc::gradients::vertical_sobel(&gi);
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let k = y * w + x;
                assert_eq!(gx[k] * 8.0, f32::from(hx.get_pixel(x as u32, y as u32)[0]));
                assert_eq!(gy[k] * 8.0, f32::from(hy.get_pixel(x as u32, y as u32)[0]));
            }
        }
    }

    #[test]
    fn subpixel_edges_lie_on_the_disc_boundary() {
        let (w, h) = (200, 150);
        let (cx, cy, a, b) = (100.3, 74.6, 70.0, 45.0);
        let data = disc_image(w, h, cx, cy, a, b);
        let view = GrayView::new(&data, w, h).unwrap();
        let map = canny(&view, &CannyParams::default()).unwrap();
        assert!(map.edgels.len() > 300, "{}", map.edgels.len());
        let truth = autoteach_geometry::conic::Ellipse::new(cx, cy, a, b, 0.0).unwrap();
        let mut d: Vec<f64> = map
            .edgels
            .iter()
            .map(|e| truth.orthogonal_distance(&e.pos).abs())
            .collect();
        d.sort_by(f64::total_cmp);
        let median = d[d.len() / 2];
        assert!(median < 0.1, "median edge distance {median}");
        assert!(d[d.len() * 95 / 100] < 0.3);
        // Gradient points from dark (outside) to bright (inside).
        for e in &map.edgels {
            let out = e.pos - Vector2::new(cx, cy);
            assert!(e.grad.dot(&out) < 0.0);
        }
    }

    #[test]
    fn disc_gives_four_quadrant_arcs_of_negative_polarity() {
        let (w, h) = (200, 150);
        let data = disc_image(w, h, 100.3, 74.6, 70.0, 45.0);
        let view = GrayView::new(&data, w, h).unwrap();
        let arcs = detect_arcs(
            &view,
            &CannyParams::default(),
            &LinkParams::default(),
            &ArcParams::default(),
        )
        .unwrap();
        let mut quads: Vec<Quadrant> = arcs.iter().map(|a| a.quadrant).collect();
        quads.sort_by_key(|q| *q as u8);
        quads.dedup();
        assert_eq!(
            quads.len(),
            4,
            "{:?}",
            arcs.iter().map(|a| a.quadrant).collect::<Vec<_>>()
        );
        let total: usize = arcs.iter().map(|a| a.points.len()).sum();
        assert!(total > 300, "{total}");
        for arc in &arcs {
            // Brighter inside: the gradient points to the concave side.
            assert_eq!(arc.polarity, -1);
            let c = Vector2::new(100.3, 74.6);
            let mid = arc.points[arc.points.len() / 2] - c;
            let (su, sv) = arc.quadrant.bulge();
            assert!(
                mid.x * su > 0.0 && mid.y * sv > 0.0,
                "{:?} at {mid:?}",
                arc.quadrant
            );
        }
    }

    #[test]
    fn straight_edges_give_no_arcs() {
        let (w, h) = (120, 80);
        let data: Vec<u8> = (0..w * h)
            .map(|k| {
                if (k % w) as f64 > 0.4 * (k / w) as f64 + 40.0 {
                    200
                } else {
                    20
                }
            })
            .collect();
        let view = GrayView::new(&data, w, h).unwrap();
        let map = canny(&view, &CannyParams::default()).unwrap();
        assert!(map.edgels.len() > 50);
        let chains = link_edges(&map, &LinkParams::default()).unwrap();
        assert!(chains.iter().any(|c| c.len() > 50));
        let arcs = split_arcs(&map, &chains, &ArcParams::default()).unwrap();
        assert!(arcs.is_empty(), "{} arcs from a straight edge", arcs.len());
    }

    #[test]
    fn side_bends_detects_the_sign_of_a_bend_against_the_noise() {
        // Points along a chord of 60 px with white noise σ = 0.1 px across it; a parabolic
        // bend of sagitta h bulges to the left of the chord (h > 0) or to the right.
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let sigma = 0.1;
        let side = |h: f64, seed: u64| {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
            let noise = Normal::new(0.0, sigma).unwrap();
            (0..=60)
                .map(|k| {
                    let s = k as f64 / 30.0 - 1.0;
                    // Chord along +u: "left" of it (a positive turn) is −v.
                    Vector2::new(k as f64, -h * (1.0 - s * s) + noise.sample(&mut rng))
                })
                .collect::<Vec<_>>()
        };
        let mut straight_hits = 0;
        for seed in 0..200 {
            // Sagitta 0.6 px = 6 σ: found with its sign, never with the other one.
            let left = side(0.6, seed);
            assert!(side_bends(&left, 0, 60, 1.0, sigma, 3.0), "seed {seed}");
            assert!(!side_bends(&left, 0, 60, -1.0, sigma, 3.0), "seed {seed}");
            let right = side(-0.6, seed);
            assert!(side_bends(&right, 0, 60, -1.0, sigma, 3.0), "seed {seed}");
            // A straight side bends significantly only by chance (one-sided 3σ: 0.13 %).
            let line = side(0.0, seed);
            straight_hits += usize::from(side_bends(&line, 0, 60, 1.0, sigma, 3.0));
        }
        assert!(straight_hits <= 2, "{straight_hits} of 200");
        // The noise estimate of a long straight noisy chain is σ (MAD: ≈ 4 % spread on 1000
        // points).
        for seed in 0..20 {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(1000 + seed);
            let noise = Normal::new(0.0, sigma).unwrap();
            let line: Vec<_> = (0..1000)
                .map(|k| {
                    Vector2::new(0.8 * k as f64, 0.6 * k as f64)
                        + Vector2::new(-0.6, 0.8) * noise.sample(&mut rng)
                })
                .collect();
            let est = chain_noise(&line);
            assert!((est - sigma).abs() < 0.15 * sigma, "seed {seed}: {est}");
        }
    }

    #[test]
    fn bad_images_are_errors_or_empty() {
        assert!(matches!(
            GrayView::<u8>::new(&[], 0, 0),
            Err(DetectError::InvalidParameter { .. })
        ));
        assert!(matches!(
            GrayView::new(&[0u8; 5], 2, 3),
            Err(DetectError::WrongLength { .. })
        ));
        let nan = [0.0f32, f32::NAN, 0.0, 0.0];
        assert!(matches!(
            GrayView::new(&nan, 2, 2),
            Err(DetectError::NonFinite { index: 1, .. })
        ));
        for v in [0u8, 255u8] {
            let data = vec![v; 64 * 48];
            let view = GrayView::new(&data, 64, 48).unwrap();
            assert!(
                canny(&view, &CannyParams::default())
                    .unwrap()
                    .edgels
                    .is_empty()
            );
        }
        // Tiny images have no interior: no edges, no panic.
        let data = [0u8, 255, 0, 255, 0, 255];
        let view = GrayView::new(&data, 3, 2).unwrap();
        assert!(
            canny(&view, &CannyParams::default())
                .unwrap()
                .edgels
                .is_empty()
        );
        let bad = CannyParams {
            low: 10.0,
            high: 5.0,
            ..CannyParams::default()
        };
        let data = vec![0u8; 64];
        let view = GrayView::new(&data, 8, 8).unwrap();
        assert!(canny(&view, &bad).is_err());
    }

    /// An edge chain like the upper rim of a thin disturbance wafer on wafer-benchmark image 21
    /// (seed 3) whose edge runs on into a slot tooth's edge at the rim's left tip: a straight
    /// tooth edge rising toward the tip, then the front half of the rim `(637, 214)`,
    /// `a = 358`, `b = 6.4` (sampled every pixel in u, gradient along the rim's outward
    /// normal). The junction turns against the rim (a quadrant change: v falls, then rises).
    fn tooth_and_thin_rim_chain() -> (EdgeMap, Vec<Vec<u32>>, Ellipse) {
        let e = Ellipse {
            cx: 637.0,
            cy: 214.0,
            a: 358.0,
            b: 6.4,
            theta: 0.0,
        };
        let mut pts = Vec::new();
        let tip = e.cx - e.a;
        // The tooth edge: 120 px rising by 4 px toward the tip.
        for k in 0..120 {
            let u = tip - 120.0 + k as f64;
            pts.push((
                Vector2::new(u, e.cy + 4.0 * (tip - u) / 120.0),
                Vector2::new(0.0, 1.0),
            ));
        }
        // The rim's front half, tip to tip (v grows downward: the lower half of the ellipse).
        for k in 0..=(2.0 * e.a) as usize {
            let u = tip + k as f64;
            let x = ((u - e.cx) / e.a).clamp(-1.0, 1.0);
            let y = e.b * (1.0 - x * x).sqrt();
            let n = Vector2::new(x / e.a, y / (e.b * e.b)).normalize();
            pts.push((Vector2::new(u, e.cy + y), n));
        }
        let edgels: Vec<Edgel> = pts
            .iter()
            .map(|(p, n)| Edgel {
                pos: *p,
                grad: 50.0 * n,
                px: p.x.round() as u32,
                py: p.y.round() as u32,
            })
            .collect();
        let chain = (0..edgels.len() as u32).collect();
        let map = EdgeMap {
            width: 1280,
            height: 720,
            edgels,
            index: Vec::new(),
        };
        (map, vec![chain], e)
    }

    #[test]
    fn restart_turn_at_cuts_keeps_the_side_after_a_junction_at_the_tip() {
        let (map, chains, e) = tooth_and_thin_rim_chain();
        let tip = e.cx - e.a;
        // The u range of the arc of the rim's left half (quadrant III: bulging toward −u, +v).
        let left_half = |params: &ArcParams| {
            let arcs = split_arcs(&map, &chains, params).unwrap();
            let third: Vec<&Arc> = arcs
                .iter()
                .filter(|a| a.quadrant == Quadrant::III)
                .collect();
            assert_eq!(third.len(), 1, "{params:?}");
            third[0]
                .points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
                    (l.min(p.x), h.max(p.x))
                })
        };
        let restart = ArcParams {
            restart_turn_at_cuts: true,
            ..ArcParams::default()
        };
        // Without the rule the junction's turn (against the rim's) makes the rim's first own
        // polygon vertex an inflection: the arc starts there, tens of pixels into the rim (on
        // the noisy edges of the benchmark image, far enough in that the rest of the flat side
        // is dropped as straight).
        let plain = ArcParams {
            restart_turn_at_cuts: false,
            ..ArcParams::default()
        };
        let (lo, _) = left_half(&plain);
        assert!(lo > tip + 20.0, "{lo} vs tip {tip}");
        // With it the left half is one arc from the tip (the junction vertex) to the bottom,
        // and no point of the tooth edge is on it.
        let (lo, hi) = left_half(&restart);
        assert!(lo >= tip && lo < tip + 2.0, "{lo} vs tip {tip}");
        assert!(hi > e.cx, "{hi}");
    }

    #[test]
    fn flat_half_of_a_front_arc_before_a_junction_is_kept() {
        // The lower rim of a flat target wafer (a = 378, b = 25, as on wafer-benchmark image 30
        // of seed 3) from its right tip past its lowest point to u = cx − 0.55·a, where a
        // straight foreign contour (a slot tooth's edge) leaves it downward to the left (an
        // inflection). The half between the lowest point (a quadrant change) and the junction
        // lies within 1.1 px of its chord.
        let e = Ellipse {
            cx: 500.0,
            cy: 270.0,
            a: 378.0,
            b: 25.0,
            theta: 0.0,
        };
        let mut pts = Vec::new();
        let (right, junction) = (e.cx + e.a, e.cx - 0.55 * e.a);
        let mut u = right;
        while u >= junction {
            let x = ((u - e.cx) / e.a).clamp(-1.0, 1.0);
            let y = e.b * (1.0 - x * x).sqrt();
            pts.push(Vector2::new(u, e.cy + y));
            u -= 1.0;
        }
        let end = pts[pts.len() - 1];
        for k in 1..=150 {
            pts.push(end + Vector2::new(-(k as f64), 0.3 * k as f64));
        }
        let edgels: Vec<Edgel> = pts
            .iter()
            .map(|p| Edgel {
                pos: *p,
                grad: Vector2::new(0.0, -50.0),
                px: p.x.round() as u32,
                py: p.y.round() as u32,
            })
            .collect();
        let chains = vec![(0..edgels.len() as u32).collect::<Vec<_>>()];
        let map = EdgeMap {
            width: 1280,
            height: 720,
            edgels,
            index: Vec::new(),
        };
        // The u range of the quadrant-III arcs (the left half of the front arc).
        let left_half = |keep: bool| {
            let params = ArcParams {
                keep_flat_run_pieces: keep,
                ..ArcParams::default()
            };
            let arcs = split_arcs(&map, &chains, &params).unwrap();
            assert!(arcs.iter().any(|a| a.quadrant == Quadrant::IV));
            arcs.iter()
                .filter(|a| a.quadrant == Quadrant::III)
                .map(|a| {
                    let us = a.points.iter().map(|p| p.x);
                    (
                        us.clone().fold(f64::INFINITY, f64::min),
                        us.fold(0.0, f64::max),
                    )
                })
                .collect::<Vec<_>>()
        };
        assert!(left_half(false).is_empty());
        let kept = left_half(true);
        assert_eq!(kept.len(), 1, "{kept:?}");
        // From about the lowest point to the junction; nothing of the straight contour.
        let (lo, hi) = kept[0];
        assert!(
            lo >= junction - 2.0 && lo < junction + 20.0,
            "{lo} vs {junction}"
        );
        assert!(hi > e.cx - 60.0 && hi < e.cx + 60.0, "{hi}");
    }
}
