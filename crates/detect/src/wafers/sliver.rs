//! Level wafers seen almost edge-on: the seeds of the thin column fit ([`super::thin`]) for
//! wafers whose rims no edge-point fit finds (seed 000_3b1454b2b2194811.txt §3.5: a disturbance
//! wafer one to a few slots from the camera's height; §3.2, Fig. 3.2: the bright side face
//! between the two rims).
//!
//! A wafer within a few slots of the camera's height images as two ellipses with `b` of 1–4 px
//! for `a` ≈ 300–380 px: the side band between their front arcs is a bright bar 2–4 px high
//! that runs nearly straight across the whole opening (it sags by `b` over `2a`). Its edge
//! chains are straight enough for the arc stage to reject them (an arc sagging by 2 px over
//! 600 px is a line to it), so no rim of such a wafer reaches the pairing. Here the bar is
//! found directly, and the column fit measures it:
//!
//! 1. **Bars.** In every [`STRIDE`]-th column, rows whose grey level is a local maximum and
//!    exceeds both rows [`BAR_REACH`] above and below by [`MIN_BAR_CONTRAST`].
//! 2. **Chains.** Bars of neighbouring sampled columns within [`LINK_ROWS`] rows are linked
//!    (gaps of up to [`MAX_GAP`] samples: the bar crosses clutter); a chain spanning at least
//!    [`MIN_SPAN`] pixels is a candidate (slot ridges of the carrier, the other long bright bars
//!    of the scene, end at the carrier's walls).
//! 3. **Ends.** The bar is followed column by column beyond the chain's ends until it stops:
//!    there the side band ends, at the rims' tips `cx ± a` (the silhouette of the wafer's side,
//!    whose ends are the points where the view rays graze the rims).
//! 4. **Seed.** The bar's centre line is the mean of the two front arcs. With the rim offset
//!    prior's closed form ([`RimOffsetPrior::offset`]: the lower rim lies `d(a)` below the upper
//!    one and its `b` differs by `(t/R)·a²/f` toward the camera's side), the line
//!    `y = c₀ + c₁·(x − cx) + s·√(1 − ((x − cx)/a)²)` fitted to the bar's centres gives the
//!    upper rim: `cy = c₀ − d/2`, `b = |s| − side·(t/R)·a²/(2f)`, `θ = atan c₁`, seen from
//!    above when the bar sags downward (`s` > 0; the side, `front` in [`super::thin`]).
//! 5. **Fit.** The thin column fit from that seed ([`super::thin::refit_pair`]): the image of
//!    both rims, tied by the exact rim map, with its own acceptance tests (residual at the
//!    image's noise, columns kept, moves from the seed). The rims' points are the bar's
//!    measured half-level crossings (top: the upper rim's front arc; bottom: the lower rim's).
//!
//! Bars already explained by a reported rim are skipped: the bar's middle within
//! [`DUPLICATE_ROWS`] of the rim's arcs (its own band) or between them (a neighbour's band
//! mirrored in the wafer's face).

use super::rim_prior::RimOffsetPrior;
use super::thin::{EdgeProfile, Model, arc_row, refit_pair};
use super::{GrayView, Pixel, RimKind, WaferEdge};
use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix3, Point2, Vector2, Vector3};

/// Sampled columns: every this many.
const STRIDE: usize = 8;
/// Rows above and below a bar's peak that its contrast is measured against.
const BAR_REACH: usize = 4;
/// Smallest contrast (grey levels on the 0–255 scale) of a bar's peak over the rows
/// [`BAR_REACH`] away: a fixed level, so that the image's noise is estimated only when a chain
/// is found (a wafer's side band stands 100–200 grey levels above its surroundings on the
/// benchmark's renders, under the dimmest lighting still over 50; ten times the renderer's
/// noise).
const MIN_BAR_CONTRAST: f64 = 20.0;
/// Largest row change between linked bars.
const LINK_ROWS: f64 = 1.5;
/// Largest gap (sampled columns without a linked bar) inside a chain.
const MAX_GAP: usize = 2;
/// Smallest horizontal extent (pixels) of a chain: a wafer's `2a` across the opening is
/// 500–800 px on the benchmark's views; the carrier's slot ridges are under 300 px.
const MIN_SPAN: f64 = 400.0;
/// Smallest fraction of a chain's sampled columns with a bar.
const MIN_FILL: f64 = 0.6;
/// Misses in a row that end the walk beyond a chain's end.
const END_MISSES: usize = 3;
/// Rows searched around the predicted row while walking beyond a chain's end.
const END_ROWS: f64 = 2.0;
/// Smallest sag `|s|` (pixels) of the bar's centre line: below it the side (from above or
/// below) is not known.
const MIN_SAG: f64 = 0.5;
/// Floor (pixels) of a band end's standard deviation: the end is where the side face's
/// silhouette meets the rims' tips, not exactly at `cx ± a` under perspective and blur.
const MIN_END_SD: f64 = 0.2;
/// Samples inside a chain's ends where the walks to the band's ends start.
const END_INSET: usize = 4;
/// Columns searched on each side of the walk's last column for the band's end.
const END_SEARCH: i64 = 8;
/// Fraction of the bar's contrast at a chain's end below which the walk beyond it counts a
/// miss.
const END_CONTRAST_FRACTION: f64 = 0.6;
/// Columns on each side of a band's end whose sums give its inside and outside levels.
const END_LEVEL_COLUMNS: i64 = 4;
/// Smallest drop of the bar's row sum at its end, in noise deviations of a sum.
const END_CONTRAST_OVER_NOISE: f64 = 10.0;
/// A bar whose middle lies within this many rows of a detected rim's arc is that rim's.
const DUPLICATE_ROWS: f64 = 4.0;

/// One chain of bars: `(x, y)` of each sampled column's peak.
struct Chain {
    points: Vec<(f64, f64)>,
    last: usize,
}

/// The contrast of a bar whose peak is `c`, with `prev` and `next` the rows next to it and
/// `above` and `below` the rows [`BAR_REACH`] away: `c` over the brighter of those two, when `c`
/// is a local maximum (the first of equal rows) and the contrast reaches `min_contrast`.
#[inline]
fn bar_contrast(
    above: f32,
    prev: f32,
    c: f32,
    next: f32,
    below: f32,
    min_contrast: f32,
) -> Option<f32> {
    let contrast = c - above.max(below);
    (contrast >= min_contrast && c >= prev && c > next).then_some(contrast)
}

/// The peak rows of the bars of every [`STRIDE`]-th column (sub-pixel by the parabola through
/// the peak and its neighbours), with contrast at least `min_contrast`: one list per sampled
/// column, in row order. The image is read row by row (its memory order).
fn bars<T: Pixel>(image: &GrayView<'_, T>, min_contrast: f64) -> Vec<Vec<f64>> {
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let xs: Vec<usize> = (STRIDE / 2..w).step_by(STRIDE).collect();
    let mut out = vec![Vec::new(); xs.len()];
    if h <= 2 * BAR_REACH {
        return out;
    }
    let min_contrast = min_contrast as f32;
    let row = |y: usize| &data[y * w..(y + 1) * w];
    for y in BAR_REACH..h - BAR_REACH {
        let (above, prev, cur, next, below) = (
            row(y - BAR_REACH),
            row(y - 1),
            row(y),
            row(y + 1),
            row(y + BAR_REACH),
        );
        for (k, &x) in xs.iter().enumerate() {
            // Most pixels fail on the contrast alone: the neighbours are read after it.
            let (c, a, b) = (cur[x].grey(), above[x].grey(), below[x].grey());
            if c - a.max(b) < min_contrast {
                continue;
            }
            let (up, down) = (prev[x].grey(), next[x].grey());
            if bar_contrast(a, up, c, down, b, min_contrast).is_none() {
                continue;
            }
            let den = f64::from(up) - 2.0 * f64::from(c) + f64::from(down);
            let dy = if den < 0.0 {
                (0.5 * f64::from(up - down) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            out[k].push(y as f64 + dy);
        }
    }
    out
}

/// The bar of column `x` nearest to row `y` within [`END_ROWS`] with contrast at least
/// `min_contrast`: its row and contrast.
fn bar_near<T: Pixel>(
    image: &GrayView<'_, T>,
    x: usize,
    y: f64,
    min_contrast: f64,
) -> Option<(f64, f64)> {
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let g = |r: usize| data[r * w + x].grey();
    let lo = (y - END_ROWS).floor().max(BAR_REACH as f64) as usize;
    let hi = ((y + END_ROWS).ceil() as usize).min(h.checked_sub(BAR_REACH + 1)?);
    let mut best: Option<(f64, f64)> = None;
    for r in lo..=hi {
        let bar = bar_contrast(
            g(r - BAR_REACH),
            g(r - 1),
            g(r),
            g(r + 1),
            g(r + BAR_REACH),
            min_contrast as f32,
        );
        if let Some(contrast) = bar
            && best.is_none_or(|(b, _)| (r as f64 - y).abs() < (b - y).abs())
        {
            best = Some((r as f64, f64::from(contrast)));
        }
    }
    best
}

/// Links the bars of the sampled columns into chains (module doc, step 2) and returns those
/// spanning [`MIN_SPAN`].
fn chains<T: Pixel>(image: &GrayView<'_, T>, min_contrast: f64) -> Vec<Vec<(f64, f64)>> {
    let mut active: Vec<Chain> = Vec::new();
    let mut done: Vec<Chain> = Vec::new();
    let columns = (STRIDE / 2..image.width()).step_by(STRIDE);
    for (ci, (x, bars)) in columns.zip(bars(image, min_contrast)).enumerate() {
        let (finished, open): (Vec<Chain>, Vec<Chain>) =
            active.into_iter().partition(|c| c.last + MAX_GAP < ci);
        done.extend(finished);
        active = open;
        let mut taken = vec![false; active.len()];
        for y in bars {
            let best = active
                .iter()
                .enumerate()
                .filter(|(k, c)| !taken[*k] && c.last < ci)
                .map(|(k, c)| (k, (c.points[c.points.len() - 1].1 - y).abs()))
                .filter(|&(_, d)| d <= LINK_ROWS)
                .min_by(|p, q| p.1.total_cmp(&q.1));
            match best {
                Some((k, _)) => {
                    taken[k] = true;
                    active[k].points.push((x as f64, y));
                    active[k].last = ci;
                }
                None => active.push(Chain {
                    points: vec![(x as f64, y)],
                    last: ci,
                }),
            }
            taken.resize(active.len(), true);
        }
    }
    done.extend(active);
    done.into_iter()
        .map(|c| c.points)
        .filter(|p| {
            let span = p[p.len() - 1].0 - p[0].0;
            span >= MIN_SPAN && p.len() as f64 >= MIN_FILL * (span / STRIDE as f64 + 1.0)
        })
        .collect()
}

/// Follows the bar from `(x, y)` column by column in direction `dir` (±1) until
/// [`END_MISSES`] columns in a row have none with at least [`END_CONTRAST_FRACTION`] of the
/// bar's median contrast `reference` near that end of its chain (a slot ridge of the carrier can continue the band's row
/// beyond its end, dimmer); the bar's last column and row.
fn walk<T: Pixel>(
    image: &GrayView<'_, T>,
    (x, y): (f64, f64),
    dir: i64,
    min_contrast: f64,
    reference: f64,
) -> (f64, f64) {
    let w = image.width() as i64;
    let floor = (END_CONTRAST_FRACTION * reference).max(min_contrast);
    let (mut last_x, mut last_y) = (x, y);
    let mut misses = 0;
    let mut xi = x as i64 + dir;
    while (0..w).contains(&xi) && misses < END_MISSES {
        match bar_near(image, xi as usize, last_y, floor) {
            Some((r, _)) => {
                (last_x, last_y) = (xi as f64, r);
                misses = 0;
            }
            None => misses += 1,
        }
        xi += dir;
    }
    (last_x, last_y)
}

/// The band's end to sub-pixel precision near column `x` (the walk's last column with the
/// bar, row `y`) in direction `dir`, with its standard deviation from the image noise `sigma`.
/// The bar's rows `y ± BAR_REACH/2` are summed per column; the end is the steepest outward drop
/// of that sum within [`END_SEARCH`] columns of `x` (the carrier behind may be brighter than
/// the background, but not as bright as the band), located where the sum crosses half way
/// between its levels inside and outside (medians of [`END_LEVEL_COLUMNS`] columns on each
/// side), by linear interpolation. `None` when the drop is under [`END_CONTRAST_OVER_NOISE`]
/// noise deviations of a sum.
fn band_end<T: Pixel>(
    image: &GrayView<'_, T>,
    (x, y): (f64, f64),
    dir: i64,
    sigma: f64,
) -> Option<(f64, f64)> {
    let (w, h) = (image.width() as i64, image.height() as i64);
    let data = image.data();
    let half = (BAR_REACH / 2) as i64;
    let r = y.round() as i64;
    if r - half < 0 || r + half >= h {
        return None;
    }
    let noise = sigma * ((2 * half + 1) as f64).sqrt();
    let sum = |c: i64| -> Option<f64> {
        (0..w).contains(&c).then(|| {
            (r - half..=r + half)
                .map(|yy| f64::from(data[(yy * w + c) as usize].grey()))
                .sum()
        })
    };
    let xi = x as i64;
    // The steepest drop over two columns (the blurred step spans about three).
    let drop = |c: i64| Some(sum(c - dir)? - sum(c + dir)?);
    let (mut at, mut best) = (None, f64::NEG_INFINITY);
    for k in -END_SEARCH..=END_SEARCH {
        if let Some(d) = drop(xi + dir * k)
            && d > best
        {
            (at, best) = (Some(xi + dir * k), d);
        }
    }
    let c = at?;
    let median = |cs: Vec<i64>| -> Option<f64> {
        let mut v: Vec<f64> = cs.into_iter().map(sum).collect::<Option<_>>()?;
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let inside = median((2..2 + END_LEVEL_COLUMNS).map(|k| c - dir * k).collect())?;
    let outside = median((2..2 + END_LEVEL_COLUMNS).map(|k| c + dir * k).collect())?;
    let step = inside - outside;
    if !(step >= END_CONTRAST_OVER_NOISE * noise) {
        return None;
    }
    let level = outside + 0.5 * step;
    for k in -2..=1 {
        let c0 = c + dir * k;
        let (s0, s1) = (sum(c0)?, sum(c0 + dir)?);
        if s0 >= level && s1 < level {
            let t = (s0 - level) / (s0 - s1);
            return Some((c0 as f64 + dir as f64 * t, noise / (s0 - s1)));
        }
    }
    None
}

/// The two ends of the band along `chain` (module doc, step 3), each with its standard
/// deviation ([`band_end`]): walks from a few samples inside the chain's ends, each against the
/// bar's contrast near its end (the carrier behind the band's ends is brighter than the
/// opening's background).
fn band_ends<T: Pixel>(
    image: &GrayView<'_, T>,
    chain: &[(f64, f64)],
    min_contrast: f64,
    sigma: f64,
) -> Option<((f64, f64), (f64, f64))> {
    // The walks start a few samples inside the chain: its last samples may lie on a slot
    // ridge that continues the band's row beyond its end.
    let n = chain.len();
    let inset = END_INSET.min(n / 4);
    let reference = |points: &[(f64, f64)]| {
        let mut c: Vec<f64> = points
            .iter()
            .filter_map(|&(x, y)| bar_near(image, x as usize, y, min_contrast).map(|b| b.1))
            .collect();
        c.sort_by(f64::total_cmp);
        c.get(c.len() / 2).copied()
    };
    let left = walk(
        image,
        chain[inset],
        -1,
        min_contrast,
        reference(&chain[..=2 * inset])?,
    );
    let right = walk(
        image,
        chain[n - 1 - inset],
        1,
        min_contrast,
        reference(&chain[n - 1 - 2 * inset..])?,
    );
    Some((
        band_end(image, left, -1, sigma)?,
        band_end(image, right, 1, sigma)?,
    ))
}

/// The half-level crossings above and below the bar of column `x` near row `y`: the band's
/// top and bottom edges.
fn band_edges<T: Pixel>(image: &GrayView<'_, T>, x: usize, y: f64) -> Option<(f64, f64)> {
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let g = |r: usize| f64::from(data[r * w + x].grey());
    let peak_row = (y.round() as usize).clamp(BAR_REACH, h.checked_sub(BAR_REACH + 1)?);
    let lo = peak_row.checked_sub(1)?;
    let peak = (lo..=peak_row + 1).max_by(|&p, &q| g(p).total_cmp(&g(q)))?;
    if peak < BAR_REACH || peak + BAR_REACH >= h {
        return None;
    }
    let top_level = 0.5 * (g(peak) + g(peak - BAR_REACH));
    let bottom_level = 0.5 * (g(peak) + g(peak + BAR_REACH));
    let cross = |dir: i64, level: f64| -> Option<f64> {
        let mut r = peak as i64;
        for _ in 0..BAR_REACH {
            let next = r + dir;
            let (a, b) = (g(r as usize), g(next as usize));
            if b < level {
                // Linear interpolation between rows r and next.
                return Some(r as f64 + dir as f64 * (a - level) / (a - b));
            }
            r = next;
        }
        None
    };
    Some((cross(-1, top_level)?, cross(1, bottom_level)?))
}

/// The basis of the bar's centre line at column `x` (module doc, step 4): its row is
/// `(c₀, c₁, s) · (1, x − cx, √(1 − ((x − cx)/a)²))`.
fn line_basis(x: f64, cx: f64, a: f64) -> Vector3<f64> {
    let u = (x - cx) / a;
    Vector3::new(1.0, x - cx, (1.0 - u * u).max(0.0).sqrt())
}

/// Least-squares fit of the bar's centre line ([`line_basis`]) for given `cx`, `a`:
/// `(c₀, c₁, s)`.
fn centre_line(points: &[(f64, f64)], cx: f64, a: f64) -> Option<Vector3<f64>> {
    let mut ata = Matrix3::zeros();
    let mut aty = Vector3::zeros();
    for &(x, y) in points {
        let row = line_basis(x, cx, a);
        ata += row * row.transpose();
        aty += row * y;
    }
    ata.cholesky().map(|c| c.solve(&aty))
}

/// Whether `(x, y)` lies on or inside a rim of `edges` (within [`DUPLICATE_ROWS`] of the span
/// between its two arcs in column `x`): on it, the bar is that rim's band; inside, on the
/// wafer's mirror-like face, it is a neighbour's band reflected there.
fn explained(edges: &[WaferEdge], x: f64, y: f64) -> bool {
    edges.iter().any(|e| {
        let el = &e.ellipse;
        let p = [el.cx, el.cy, el.a, el.b, el.theta];
        match (arc_row(&p, x, -1.0), arc_row(&p, x, 1.0)) {
            (Some((top, _)), Some((bottom, _))) => {
                y >= top.min(bottom) - DUPLICATE_ROWS && y <= top.max(bottom) + DUPLICATE_ROWS
            }
            _ => false,
        }
    })
}

/// The wafers seen almost edge-on in `image` that no rim of `edges` explains (module doc),
/// measured by the thin column fit: pairs of (upper, lower) rims, each pair with its own
/// `wafer_id` after those of `edges`. `noise` is the image's noise estimate (computed here
/// when `None`).
pub(super) fn find_level_bands<T: Pixel>(
    image: &GrayView<'_, T>,
    edges: &[WaferEdge],
    up: Vector2<f64>,
    prior: &RimOffsetPrior,
    profile: EdgeProfile,
    noise: &mut Option<f64>,
) -> Vec<WaferEdge> {
    let min_contrast = MIN_BAR_CONTRAST;
    let mut next_id = edges.iter().map(|e| e.wafer_id + 1).max().unwrap_or(0);
    let mut out: Vec<WaferEdge> = Vec::new();
    for chain in chains(image, min_contrast) {
        let mid = chain[chain.len() / 2];
        if explained(edges, mid.0, mid.1) || explained(&out, mid.0, mid.1) {
            continue;
        }
        let sigma = *noise.get_or_insert_with(|| super::thin::noise_sigma(image));
        let Some(((xl, sl), (xr, sr))) = band_ends(image, &chain, min_contrast, sigma) else {
            continue;
        };
        let end_sd = sl.max(sr).max(MIN_END_SD);
        let (cx, a) = (0.5 * (xl + xr), 0.5 * (xr - xl));
        // The centre line from the chain's samples between the ends, then from the middles of
        // the band's measured edges every second column (the seed's `b` is the line's sag).
        let inner: Vec<(f64, f64)> = chain
            .iter()
            .copied()
            .filter(|&(x, _)| x > xl + 1.0 && x < xr - 1.0)
            .collect();
        let Some(c) = centre_line(&inner, cx, a) else {
            continue;
        };
        let (mut top, mut bottom) = (Vec::new(), Vec::new());
        let mut x = (xl + 1.0).ceil();
        while x < xr - 1.0 {
            let y = c.dot(&line_basis(x, cx, a));
            if let Some((t, bt)) = band_edges(image, x as usize, y) {
                top.push(Point2::new(x, t));
                bottom.push(Point2::new(x, bt));
            }
            x += 2.0;
        }
        let middles: Vec<(f64, f64)> = top
            .iter()
            .zip(&bottom)
            .map(|(t, b)| (t.x, 0.5 * (t.y + b.y)))
            .collect();
        let Some(c) = centre_line(&middles, cx, a) else {
            continue;
        };
        let (c0, c1, s) = (c[0], c[1], c[2]);
        if !(s.abs() >= MIN_SAG) {
            continue;
        }
        let front = s.signum();
        let k = prior.thickness_ratio * a * a / prior.focal_length;
        let b = s.abs() - front * 0.5 * k;
        let d = prior.offset(a);
        let theta = c1.atan();
        let (Ok(upper), Ok(lower)) = (
            Ellipse::new(cx, c0 - 0.5 * d, a, b, theta),
            Ellipse::new(cx, c0 + 0.5 * d, a, b + front * k, theta),
        ) else {
            continue;
        };
        let seed = |ellipse: Ellipse, points: Vec<Point2<f64>>, kind| WaferEdge {
            ellipse,
            points,
            residual: 0.0,
            covariance: None,
            kind,
            wafer_id: next_id,
        };
        let (u, l) = (
            seed(upper, top, RimKind::Upper),
            seed(lower, bottom, RimKind::Lower),
        );
        if let Some((u, l)) = refit_pair(
            image,
            &u,
            &l,
            up,
            prior,
            sigma,
            Model::Thin,
            profile,
            Some(front),
            Some(end_sd),
        ) {
            out.push(u);
            out.push(l);
            next_id += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::tests::benchmark_scene;
    use super::super::thin::tests::{SceneParams, assert_column_fit_hits};
    use super::*;
    use autoteach_geometry::render::Rim;
    use nalgebra::Matrix6;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Image 24 of the wafer benchmark (seed 3: a disturbance 5 slots above, seen from above,
    /// `b` 1.50 / 2.39 px) and image 4 (seed 4: 5 slots above, seen from below, `b` 3.72 /
    /// 3.09 px).
    const EDGE_ON: [SceneParams; 2] = [
        (
            5,
            (
                -0.438_500_521_853_128_6,
                0.014_001_899_122_421_474,
                0.052_173_622_706_801_315,
            ),
            -0.654_307_266_101_919_4,
            6.782_857_519_737_945,
            1.218_906_930_226_88,
            [-0.253_333_242_981_063_24, 0.219_863_563_072_681_57],
            3_874_327_914,
        ),
        (
            5,
            (
                -0.515_181_659_262_093_5,
                0.042_977_469_530_806_695,
                0.044_586_264_230_623_826,
            ),
            1.054_805_189_601_155_2,
            7.380_194_552_377_009,
            0.716_980_026_421_995_1,
            [0.115_531_226_826_336_38, 0.162_378_289_855_046_27],
            2_311_307_375,
        ),
    ];

    /// Both rims of a wafer seen edge-on, from above and from below, are hits (benchmark rule,
    /// renderer ground truth) with the band search and no detection is wrong; without it the
    /// wafer is not found.
    #[test]
    fn wafers_seen_edge_on_are_found_and_measured() {
        for scene in EDGE_ON {
            assert_column_fit_hits(scene, 1, |p, on| {
                p.edge_profile = EdgeProfile::PixelGrid;
                p.level_band_search = on;
            });
        }
    }

    /// The band's ends are the rims' tips `cx ± a` (renderer ground truth) to 0.2 px: the chain
    /// of bars, the walks beyond its ends and the half-level crossings.
    #[test]
    fn band_ends_are_the_rims_tips() {
        for (k, camera, yaw, down, gain, gradient, seed) in EDGE_ON {
            let (data, w, h, rims) = benchmark_scene(k, camera, yaw, down, gain, gradient, seed);
            let view = GrayView::new(&data, w, h).unwrap();
            let (_, _, e, _) = rims
                .iter()
                .find(|(wafer, rim, _, _)| *wafer == 1 && *rim == Rim::Upper)
                .unwrap();
            let sigma = super::super::thin::noise_sigma(&view);
            let bands = chains(&view, MIN_BAR_CONTRAST);
            let chain = bands
                .iter()
                .find(|c| c.iter().all(|&(_, y)| (y - e.cy).abs() < 6.0))
                .expect("a chain along the band");
            let ((xl, _), (xr, _)) = band_ends(&view, chain, MIN_BAR_CONTRAST, sigma).unwrap();
            assert!((xl - (e.cx - e.a)).abs() < 0.2, "{xl} vs {}", e.cx - e.a);
            assert!((xr - (e.cx + e.a)).abs() < 0.2, "{xr} vs {}", e.cx + e.a);
        }
    }

    /// The wafers found here join the others in image order along `up` (topmost first), each
    /// wafer's rims in their order, ids renumbered.
    #[test]
    fn found_wafers_are_numbered_in_image_order() {
        let rim = |cy: f64, kind, wafer_id| WaferEdge {
            ellipse: Ellipse::new(600.0, cy, 300.0, 2.0, 0.0).unwrap(),
            points: Vec::new(),
            residual: 0.0,
            covariance: None,
            kind,
            wafer_id,
        };
        let edges = vec![
            rim(300.0, RimKind::Upper, 0),
            rim(303.0, RimKind::Lower, 0),
            rim(100.0, RimKind::Upper, 1),
            rim(102.0, RimKind::Lower, 1),
            rim(200.0, RimKind::Lower, 2),
        ];
        let ordered = super::super::in_image_order(edges, Vector2::new(0.0, -1.0));
        let got: Vec<(f64, usize)> = ordered.iter().map(|e| (e.ellipse.cy, e.wafer_id)).collect();
        assert_eq!(
            got,
            vec![(100.0, 0), (102.0, 0), (200.0, 1), (300.0, 2), (303.0, 2)]
        );
    }

    /// The centre line's least squares recover the line a set of points was drawn from.
    #[test]
    fn centre_line_recovers_its_parameters() {
        let (cx, a) = (600.0, 350.0);
        let truth = Vector3::new(240.0, 0.004, 1.7);
        let points: Vec<(f64, f64)> = (0..300)
            .map(|i| {
                let x = cx - a + 2.0 + 2.32 * f64::from(i);
                let u = (x - cx) / a;
                (
                    x,
                    truth[0] + truth[1] * (x - cx) + truth[2] * (1.0 - u * u).sqrt(),
                )
            })
            .collect();
        let c = centre_line(&points, cx, a).unwrap();
        assert!((c - truth).norm() < 1e-9, "{c} vs {truth}");
    }

    /// The covariance of a least-squares fit with two parameters held at values measured with
    /// standard deviation `sd/√2` each ([`super::super::thin`]'s `held_covariance`) against the
    /// scatter of such fits on a linear model (Monte Carlo, 4000 draws of the data's noise and
    /// of the held values' errors).
    #[test]
    fn held_parameters_covariance_matches_monte_carlo() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let rows = 40;
        let j = nalgebra::DMatrix::<f64>::from_fn(rows, 6, |r, c| {
            ((r * 7 + c * 3) as f64 * 0.37).sin() + if r % 6 == c { 1.5 } else { 0.0 }
        });
        let jtj: Matrix6<f64> = (j.transpose() * &j).fixed_view::<6, 6>(0, 0).into_owned();
        let (noise, end_sd) = (0.3, 0.5);
        let cov = super::super::thin::held_covariance(&jtj, noise * noise, end_sd).unwrap();
        let free = [1usize, 3, 4, 5];
        let held = [0usize, 2];
        let jf = j.select_columns(&free);
        let jh = j.select_columns(&held);
        let solve = (jf.transpose() * &jf).try_inverse().unwrap() * jf.transpose();
        let draws = 4000;
        let mut samples = Vec::with_capacity(draws);
        for _ in 0..draws {
            // Truth zero: data = noise; the held values are measured with error.
            let eps = nalgebra::DVector::from_fn(rows, |_, _| noise * unit.sample(&mut rng));
            let h =
                nalgebra::DVector::from_fn(2, |_, _| end_sd / 2f64.sqrt() * unit.sample(&mut rng));
            let f = &solve * (eps - &jh * &h);
            let mut p = nalgebra::DVector::zeros(6);
            for (k, &i) in free.iter().enumerate() {
                p[i] = f[k];
            }
            for (k, &i) in held.iter().enumerate() {
                p[i] = h[k];
            }
            samples.push(p);
        }
        let mut emp = Matrix6::<f64>::zeros();
        for p in &samples {
            for r in 0..6 {
                for c in 0..6 {
                    emp[(r, c)] += p[r] * p[c] / draws as f64;
                }
            }
        }
        for r in 0..6 {
            for c in 0..6 {
                let scale = (cov[(r, r)] * cov[(c, c)]).sqrt();
                assert!(
                    (emp[(r, c)] - cov[(r, c)]).abs() < 0.1 * scale,
                    "({r}, {c}): Monte Carlo {} vs {}",
                    emp[(r, c)],
                    cov[(r, c)]
                );
            }
        }
    }
}
