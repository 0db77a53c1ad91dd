//! Felzenszwalb–Huttenlocher graph segmentation with a colour and a surface-normal criterion,
//! each with its own adaptive threshold (seed 004_815695db12a6b16c.txt ch. 4.2, eq. (4.3)–(4.5),
//! Algorithm 4.1).
//!
//! Edges are processed in increasing order of their sort key (colour weight by default,
//! Algorithm 4.1 line 4, by counting sort). An edge ⟨i, j, w_rgb, w_norm⟩ joins the segments
//! S_l ∋ i and S_m ∋ j iff `w_rgb < thresh_rgb(S)` and `w_norm < thresh_norm(S)` for both
//! S = S_l and S = S_m (line 10). After a union, eq. (4.3):
//! `thresh_rgb(S_lm) = w_rgb + K_rgb / |S_lm|` and likewise for the normals with K_norm.
//!
//! Eq. (4.3) relies on `w` being the largest weight inside the new segment, which holds for
//! the key the edges are sorted on. The other weight arrives unsorted, so for it the
//! threshold keeps the largest weight joined so far, `Int(S_lm) = max(Int(S_l), Int(S_m), w)`,
//! which is what eq. (4.3) computes for the sorted weight (the seed leaves this open: "sorting
//! edges without incorporating surface normal weights does not provide the same theoretical
//! guarantees").
//!
//! A final pass merges, in the same edge order, every edge whose endpoints lie in different
//! segments one of which is smaller than `min_size` (Table 4.1's "minsize"; FH's
//! post-processing).

use super::counting_sort::counting_sort_by_key;
use super::union_find::{MAX_VERTICES, UnionFind};
use crate::{DetectError, Result};

/// Largest squared RGB distance between 8-bit colours, 3·255²: the colour keys run over
/// `0..=RGB_KEY_MAX`.
pub const RGB_KEY_MAX: u32 = 3 * 255 * 255;

/// Angle quantum of the normal sort key (radians) in [`Criteria::NormalOnly`] mode.
pub const NORMAL_KEY_QUANTUM: f64 = 1e-4;

/// Which edge weights decide a union.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criteria {
    /// Colour and normals (the seed's method, Fig. 4.4e); edges sorted on colour.
    Both,
    /// Colour only (Fig. 4.4c); edges sorted on colour.
    ColorOnly,
    /// Normals only (Fig. 4.4d); edges sorted on the normal angle (quantised to
    /// [`NORMAL_KEY_QUANTUM`] for the counting sort).
    NormalOnly,
}

/// Segmentation constants (Table 4.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FhParams {
    /// K_rgb of eq. (4.3), in 8-bit RGB distance units × points.
    pub k_rgb: f64,
    /// K_norm, in radians × points.
    pub k_norm: f64,
    /// Segments smaller than this are merged into a neighbour (Table 4.1 "minsize").
    pub min_size: usize,
    /// Which criteria decide a union.
    pub criteria: Criteria,
}

impl Default for FhParams {
    /// Table 4.1, Fig. 4.4e: K_rgb = 9000, K_norm = 10, minsize = 100, both criteria.
    fn default() -> Self {
        Self {
            k_rgb: 9000.0,
            k_norm: 10.0,
            min_size: 100,
            criteria: Criteria::Both,
        }
    }
}

impl FhParams {
    /// Checks the constants (finite and non-negative).
    pub fn validate(&self) -> Result<()> {
        for (what, v) in [("k_rgb", self.k_rgb), ("k_norm", self.k_norm)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(DetectError::InvalidParameter {
                    what,
                    value: v,
                    reason: "must be finite and non-negative",
                });
            }
        }
        Ok(())
    }
}

/// Colour weight of eq. (4.4) as the exact integer squared distance (the counting-sort key).
#[inline]
pub fn rgb_key(a: [u8; 3], b: [u8; 3]) -> u32 {
    let d = |x: u8, y: u8| {
        let v = i32::from(x) - i32::from(y);
        (v * v) as u32
    };
    d(a[0], b[0]) + d(a[1], b[1]) + d(a[2], b[2])
}

/// Normal weight of eq. (4.5), `arccos(n_i · n_j)` for unit normals (clamped against rounding).
#[inline]
pub fn normal_weight(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
        .clamp(-1.0, 1.0)
        .acos()
}

/// The result of [`segment_graph`].
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// Segment of every vertex, `0..num_segments`, numbered by first vertex.
    pub labels: Vec<u32>,
    /// Number of segments.
    pub num_segments: usize,
    /// Unions accepted by the threshold test (before the minimum-size pass).
    pub threshold_unions: usize,
}

/// Segments a graph of `n` vertices (Algorithm 4.1 after `buildGraph`).
///
/// `edges` are vertex pairs; `colors` (length n) are 8-bit RGB; `normals` (length n, unit) are
/// required unless `params.criteria` is [`Criteria::ColorOnly`].
pub fn segment_graph(
    n: usize,
    edges: &[[u32; 2]],
    colors: &[[u8; 3]],
    normals: Option<&[[f64; 3]]>,
    params: &FhParams,
) -> Result<Segmentation> {
    params.validate()?;
    if colors.len() != n {
        return Err(DetectError::WrongLength {
            what: "colors",
            got: colors.len(),
            expected: n,
        });
    }
    let normals = match (params.criteria, normals) {
        (Criteria::ColorOnly, _) => None,
        (_, Some(nr)) if nr.len() == n => Some(nr),
        (_, Some(nr)) => {
            return Err(DetectError::WrongLength {
                what: "normals",
                got: nr.len(),
                expected: n,
            });
        }
        (_, None) => {
            return Err(DetectError::InvalidParameter {
                what: "normals",
                value: f64::NAN,
                reason: "normals are required unless the criteria are colour only",
            });
        }
    };
    if n > MAX_VERTICES {
        return Err(DetectError::InvalidParameter {
            what: "number of points",
            value: n as f64,
            reason: "at most 2^31 - 1 points",
        });
    }
    if let Some(e) = edges
        .iter()
        .find(|e| e[0] as usize >= n || e[1] as usize >= n)
    {
        return Err(DetectError::InvalidParameter {
            what: "edge vertex",
            value: f64::from(e[0].max(e[1])),
            reason: "edge refers to a vertex beyond the point count",
        });
    }

    // Algorithm 4.1 lines 3–4: the sort keys, and the counting sort. The records carry their
    // endpoints, so lines 5–13 and the minimum-size pass read them in order, sequentially.
    let normal_key = |e: &[u32; 2], nr: &[[f64; 3]]| {
        let w = normal_weight(&nr[e[0] as usize], &nr[e[1] as usize]);
        ((w / NORMAL_KEY_QUANTUM).round() as u32).min(normal_key_max())
    };
    let sorted: Vec<SortEdge> = match (params.criteria, normals) {
        (Criteria::NormalOnly, Some(nr)) => counting_sort_by_key(
            edges
                .iter()
                .map(|e| SortEdge {
                    i: e[0],
                    j: e[1],
                    key: normal_key(e, nr),
                })
                .collect(),
            normal_key_max(),
            |e| e.key,
        ),
        _ => counting_sort_by_key(
            edges
                .iter()
                .map(|e| SortEdge {
                    i: e[0],
                    j: e[1],
                    key: rgb_key(colors[e[0] as usize], colors[e[1] as usize]),
                })
                .collect(),
            RGB_KEY_MAX,
            |e| e.key,
        ),
    };

    // Lines 5–13. A singleton's threshold is K / 1 (its internal weight is 0). Each root keeps
    // its two internal weights `Int` as the union–find payload.
    let use_rgb = params.criteria != Criteria::NormalOnly;
    let use_norm = params.criteria != Criteria::ColorOnly;
    let mut uf = UnionFind::with_data(n, Internal::default());
    let mut unions = 0usize;
    for (k, e) in sorted.iter().enumerate() {
        if let Some(ahead) = sorted.get(k + LOOKAHEAD) {
            std::hint::black_box(uf.entry_of(ahead.i) ^ uf.entry_of(ahead.j));
        }
        let a = uf.find(e.i);
        let b = uf.find(e.j);
        if a == b {
            continue;
        }
        let (sa, sb) = (f64::from(uf.size(a)), f64::from(uf.size(b)));
        let (da, db) = (*uf.data(a), *uf.data(b));
        // The colour weight of eq. (4.4) (in NormalOnly mode it is neither tested nor kept).
        let wr = if use_rgb {
            f64::from(e.key).sqrt()
        } else {
            0.0
        };
        if use_rgb && !(wr < da.rgb + params.k_rgb / sa && wr < db.rgb + params.k_rgb / sb) {
            continue;
        }
        // The normal weight of eq. (4.5), computed only for the edges the colour test passes.
        let wn = match normals {
            Some(nr) if use_norm => normal_weight(&nr[e.i as usize], &nr[e.j as usize]),
            _ => 0.0,
        };
        if use_norm && !(wn < da.norm + params.k_norm / sa && wn < db.norm + params.k_norm / sb) {
            continue;
        }
        let r = uf.union_roots(a, b);
        *uf.data_mut(r) = Internal {
            rgb: da.rgb.max(db.rgb).max(wr),
            norm: da.norm.max(db.norm).max(wn),
        };
        unions += 1;
    }

    // Minimum segment size.
    if params.min_size > 1 {
        let min = u32::try_from(params.min_size).unwrap_or(u32::MAX);
        for e in &sorted {
            let a = uf.find(e.i);
            let b = uf.find(e.j);
            if a != b && (uf.size(a) < min || uf.size(b) < min) {
                uf.union_roots(a, b);
            }
        }
    }
    drop(sorted);
    let (labels, num_segments) = uf.labels();
    Ok(Segmentation {
        labels,
        num_segments,
        threshold_unions: unions,
    })
}

/// How many edges ahead the merge loop loads the endpoints' union–find entries.
const LOOKAHEAD: usize = 16;

/// Largest normal sort key: π quantised to [`NORMAL_KEY_QUANTUM`].
fn normal_key_max() -> u32 {
    (std::f64::consts::PI / NORMAL_KEY_QUANTUM).ceil() as u32
}

/// An edge with its sort key, in the order the counting sort moves it.
#[derive(Debug, Clone, Copy)]
struct SortEdge {
    i: u32,
    j: u32,
    key: u32,
}

/// A segment's internal weights `Int(S)` of eq. (4.3): the largest colour and normal weights
/// joined into it (zero for a singleton).
#[derive(Debug, Clone, Copy, Default)]
struct Internal {
    rgb: f64,
    norm: f64,
}
