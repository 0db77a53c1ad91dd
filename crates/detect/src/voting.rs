//! Global voting of rigid transforms between point sets (seed 000_3b1454b2b2194811.txt §3.4,
//! eq. (3.19)–(3.22), Algorithm 3, Figs. 3.12–3.13).
//!
//! Every point gets a local reference frame (LRF) from its neighbourhood: in 2-D the tangent
//! (principal direction of the k nearest neighbours) and the normal; in 3-D the eigenvectors of
//! the neighbourhood covariance. One pair `(x_i, y_j)` then fixes a rigid transform (3.20),
//! `R_ij = R_i R_jᵀ`, `T_ij = x_i − R_ij y_j`. The `M₁·N₁` transforms are clustered by the
//! discretisation of Algorithm 3: the transform space is binned one dimension at a time and only
//! populated bins are refined in the next dimension, so the cost is `O(D·M₁N₁ + D·K)` instead of
//! exponential in the dimension. A cluster's vote is the number of *distinct source points*
//! `y_j` in it ("Y-count", the seed's remedy for density mismatch, Fig. 3.12), not the number of
//! pairs; the pair count is reported too. Angles wrap at ±π.
//!
//! The transform maps `Y` onto `X` (`x ≈ R y + t`), as in CPD.
//!
//! Practical choices the seed leaves open, and what is done here:
//! - the LRF sign is ambiguous (a tangent has two directions), so each `y_j` frame is tried with
//!   every proper sign flip (2 in 2-D, 4 in 3-D); the Y-count keeps the flips of one point from
//!   counting twice;
//! - translations are voted for the *centred* model `y − ȳ`, which keeps the translation spread
//!   caused by an LRF angle error proportional to the shape size rather than to `‖ȳ‖`;
//! - a cluster cut by a bin boundary would be split, so the vote is repeated on a grid shifted by
//!   half a bin in every dimension and the cells of both grids compete (non-maximum suppression
//!   removes the duplicates);
//! - 3-D rotations are parameterised by roll–pitch–yaw (`nalgebra`'s `euler_angles`), roll and
//!   yaw wrapped.
//!
//! ```
//! use autoteach_detect::voting::{global_voting, VotingOptions};
//! use nalgebra::{DMatrix, Rotation2, Vector2};
//!
//! // An L-shaped model and its copy rotated by 100° and moved.
//! let mut pts = Vec::new();
//! for k in 0..40 { pts.push(Vector2::new(k as f64 * 0.05, 0.0)); }
//! for k in 1..25 { pts.push(Vector2::new(0.0, k as f64 * 0.05)); }
//! let y = DMatrix::from_fn(pts.len(), 2, |r, c| pts[r][c]);
//! let rot = Rotation2::new(100f64.to_radians());
//! let x = DMatrix::from_fn(pts.len(), 2, |r, c| (rot * pts[r] + Vector2::new(3.0, -1.0))[c]);
//! let best = &global_voting(&x, &y, &VotingOptions::default())?[0];
//! let angle = best.rotation[(1, 0)].atan2(best.rotation[(0, 0)]);
//! assert!((angle - 100f64.to_radians()).abs() < 0.05);
//! assert!((best.translation[0] - 3.0).abs() < 0.1 && (best.translation[1] + 1.0).abs() < 0.1);
//! # Ok::<(), autoteach_detect::DetectError>(())
//! ```

use std::f64::consts::PI;
use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, Rotation3, SymmetricEigen, Vector2, Vector3};

use crate::{DetectError, Result};

/// How the size of a cluster of transforms is counted (seed §3.4, "Efficient Tree Structure for
/// Vote Counting").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VoteCount {
    /// Number of distinct source points `y_j` in the cluster (the seed's proposed count; robust
    /// to density mismatch between the sets, Fig. 3.13b).
    YCount,
    /// Number of pairs `(x_i, y_j)` in the cluster (the classic count, Fig. 3.13a).
    Pairs,
}

/// Options of [`global_voting`].
#[derive(Debug, Clone, PartialEq)]
pub struct VotingOptions {
    /// Neighbours (including the point itself) used for each local reference frame.
    pub neighbours: usize,
    /// Bin width of every rotation angle, radians (`σ_θ` of (3.22)).
    pub angle_bin: f64,
    /// Bin width of every translation component (`σ_T` of (3.22)), in the units of the points.
    /// `None`: `angle_bin ×` the RMS radius of `Y` about its centroid (the translation spread an
    /// LRF error of one angle bin causes).
    pub translation_bin: Option<f64>,
    /// Number of hypotheses returned (top-K), best first.
    pub top_k: usize,
    /// Which count ranks the clusters.
    pub count: VoteCount,
    /// Clusters with a smaller count are discarded.
    pub min_votes: usize,
    /// At most this many points of each set take part in the vote (`M₁`, `N₁`); larger sets are
    /// subsampled with a uniform stride. Local frames always use all points.
    pub max_points: usize,
    /// If set, a pair votes only when the neighbourhood shape descriptors (eigenvalue ratios of
    /// the neighbourhood covariance, in `[0, 1]`) of `x_i` and `y_j` differ by at most this much
    /// in every component.
    pub descriptor_tolerance: Option<f64>,
    /// Also vote on a grid shifted by half a bin in every dimension (clusters cut by a bin
    /// boundary in one grid are whole in the other).
    pub shifted_grid: bool,
    /// Upper bound on the number of candidate transforms (`M₁·N₁·flips`); more is an error.
    pub max_pairs: usize,
}

impl Default for VotingOptions {
    fn default() -> Self {
        Self {
            neighbours: 10,
            angle_bin: 0.2,
            translation_bin: None,
            top_k: 3,
            count: VoteCount::YCount,
            min_votes: 3,
            max_points: 1000,
            descriptor_tolerance: None,
            shifted_grid: true,
            max_pairs: 8_000_000,
        }
    }
}

/// One rigid-transform hypothesis: `x ≈ rotation · y + translation`.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidHypothesis {
    /// `D×D` rotation matrix (mean of the cluster's rotations, projected onto SO(D)).
    pub rotation: DMatrix<f64>,
    /// Translation (length `D`).
    pub translation: DVector<f64>,
    /// Number of distinct source points `y_j` in the cluster (Y-count).
    pub votes: usize,
    /// Number of pairs `(x_i, y_j)` (with sign flips) in the cluster.
    pub pair_votes: usize,
}

/// A local reference frame: rotation (columns are the frame axes in world coordinates) and
/// the neighbourhood shape descriptor.
#[derive(Debug, Clone, Copy)]
struct Frame {
    /// Row-major 3×3 (2-D frames use the upper-left 2×2).
    r: Matrix3<f64>,
    /// Eigenvalue ratios `λ₂/λ₁` (and `λ₃/λ₁` in 3-D; 0 in 2-D).
    desc: [f64; 2],
}

fn validate_points(what: &'static str, p: &DMatrix<f64>) -> Result<()> {
    let d = p.ncols();
    if d != 2 && d != 3 {
        return Err(DetectError::InvalidParameter {
            what,
            value: d as f64,
            reason: "point sets must have 2 or 3 columns (one point per row, N×2 or N×3)",
        });
    }
    if p.nrows() < d + 1 {
        return Err(DetectError::TooFewPoints {
            what,
            got: p.nrows(),
            needed: d + 1,
        });
    }
    for r in 0..p.nrows() {
        for c in 0..d {
            let v = p[(r, c)];
            if !v.is_finite() {
                return Err(DetectError::NonFinite {
                    what,
                    index: r,
                    value: v,
                });
            }
        }
    }
    // Identical points: zero spread in every direction.
    let mut extent = 0.0f64;
    for c in 0..d {
        let col = p.column(c);
        extent = extent.max(col.max() - col.min());
    }
    if extent == 0.0 {
        return Err(DetectError::Degenerate {
            reason: format!("all {} points of {what} are identical", p.nrows()),
        });
    }
    Ok(())
}

fn validate_options(o: &VotingOptions, d: usize) -> Result<()> {
    let bad = |what, value: f64, reason| {
        Err(DetectError::InvalidParameter {
            what,
            value,
            reason,
        })
    };
    if !(o.angle_bin.is_finite() && o.angle_bin > 0.0 && o.angle_bin <= PI) {
        return bad("angle_bin", o.angle_bin, "must be in (0, π]");
    }
    if let Some(t) = o.translation_bin
        && !(t.is_finite() && t > 0.0)
    {
        return bad("translation_bin", t, "must be positive and finite");
    }
    if o.neighbours < d {
        return bad(
            "neighbours",
            o.neighbours as f64,
            "must be at least the dimension",
        );
    }
    if o.top_k == 0 {
        return bad("top_k", 0.0, "must be at least 1");
    }
    if o.min_votes == 0 {
        return bad("min_votes", 0.0, "must be at least 1");
    }
    if o.max_points < d + 1 {
        return bad(
            "max_points",
            o.max_points as f64,
            "must exceed the dimension",
        );
    }
    if let Some(t) = o.descriptor_tolerance
        && !(t.is_finite() && t >= 0.0)
    {
        return bad("descriptor_tolerance", t, "must be non-negative and finite");
    }
    Ok(())
}

/// Neighbour indices (including the point itself) of every row of `p`.
fn neighbourhoods<const D: usize>(p: &DMatrix<f64>, k: usize) -> Result<Vec<Vec<usize>>> {
    let n = p.nrows();
    let entries: Vec<[f64; D]> = (0..n).map(|r| std::array::from_fn(|c| p[(r, c)])).collect();
    let tree = ImmutableKdTree::<f64, D>::new_from_slice(&entries).map_err(|e| {
        DetectError::Degenerate {
            reason: format!("k-d tree construction failed: {e:?}"),
        }
    })?;
    let kk = NonZero::new(k.min(n).max(1)).ok_or(DetectError::TooFewPoints {
        what: "points",
        got: n,
        needed: 1,
    })?;
    Ok(entries
        .iter()
        .map(|q| {
            tree.query(q)
                .nearest_n::<SquaredEuclidean<f64>>(kk)
                .execute()
                .into_iter()
                .map(|r| r.item as usize)
                .collect()
        })
        .collect())
}

/// Local reference frames of all points; `None` where the neighbourhood has no extent.
fn frames(p: &DMatrix<f64>, k: usize) -> Result<Vec<Option<Frame>>> {
    let d = p.ncols();
    let nbh = if d == 2 {
        neighbourhoods::<2>(p, k)?
    } else {
        neighbourhoods::<3>(p, k)?
    };
    let mut scale = 0.0f64;
    for c in 0..d {
        let col = p.column(c);
        scale = scale.max(col.max() - col.min());
    }
    let tiny = (1e-12 * scale).powi(2);
    Ok(nbh
        .iter()
        .map(|idx| {
            let m = idx.len() as f64;
            if d == 2 {
                let mean = idx.iter().fold(Vector2::zeros(), |a, &i| {
                    a + Vector2::new(p[(i, 0)], p[(i, 1)])
                }) / m;
                let cov = idx.iter().fold(Matrix2::zeros(), |a, &i| {
                    let v = Vector2::new(p[(i, 0)], p[(i, 1)]) - mean;
                    a + v * v.transpose()
                }) / m;
                let eig = SymmetricEigen::new(cov);
                let (i1, i2) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
                    (0, 1)
                } else {
                    (1, 0)
                };
                let (l1, l2) = (eig.eigenvalues[i1], eig.eigenvalues[i2].max(0.0));
                if l1 <= tiny {
                    return None;
                }
                let e1 = eig.eigenvectors.column(i1).into_owned();
                let mut r = Matrix3::identity();
                r[(0, 0)] = e1[0];
                r[(1, 0)] = e1[1];
                r[(0, 1)] = -e1[1];
                r[(1, 1)] = e1[0];
                Some(Frame {
                    r,
                    desc: [l2 / l1, 0.0],
                })
            } else {
                let pt = |i: usize| Vector3::new(p[(i, 0)], p[(i, 1)], p[(i, 2)]);
                let mean = idx.iter().fold(Vector3::zeros(), |a, &i| a + pt(i)) / m;
                let cov = idx.iter().fold(Matrix3::zeros(), |a, &i| {
                    let v = pt(i) - mean;
                    a + v * v.transpose()
                }) / m;
                let eig = SymmetricEigen::new(cov);
                let mut order = [0usize, 1, 2];
                order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
                let l: [f64; 3] = std::array::from_fn(|q| eig.eigenvalues[order[q]].max(0.0));
                if l[0] <= tiny {
                    return None;
                }
                let e1 = eig.eigenvectors.column(order[0]).into_owned();
                let e2 = eig.eigenvectors.column(order[1]).into_owned();
                let e3 = e1.cross(&e2);
                let r = Matrix3::from_columns(&[e1, e2, e3]);
                Some(Frame {
                    r,
                    desc: [l[1] / l[0], l[2] / l[0]],
                })
            }
        })
        .collect())
}

/// The local reference frames (seed §3.4: 2-D from the neighbourhood tangent/normal, 3-D from the
/// neighbourhood covariance) of every point of `points` (N×2 or N×3), each a `D×D` rotation whose
/// first column is the principal direction of the `neighbours` nearest points; `None` where all
/// neighbours coincide. The frames' signs are arbitrary (see the module docs).
pub fn local_frames(points: &DMatrix<f64>, neighbours: usize) -> Result<Vec<Option<DMatrix<f64>>>> {
    validate_points("points", points)?;
    let d = points.ncols();
    if neighbours < d {
        return Err(DetectError::InvalidParameter {
            what: "neighbours",
            value: neighbours as f64,
            reason: "must be at least the dimension",
        });
    }
    Ok(frames(points, neighbours)?
        .into_iter()
        .map(|f| f.map(|f| DMatrix::from_fn(d, d, |r, c| f.r[(r, c)])))
        .collect())
}

/// Proper sign flips of a frame (diagonal ±1 with determinant +1).
fn flips(d: usize) -> &'static [[f64; 3]] {
    const F2: [[f64; 3]; 2] = [[1.0, 1.0, 1.0], [-1.0, -1.0, 1.0]];
    const F3: [[f64; 3]; 4] = [
        [1.0, 1.0, 1.0],
        [-1.0, -1.0, 1.0],
        [-1.0, 1.0, -1.0],
        [1.0, -1.0, -1.0],
    ];
    if d == 2 { &F2 } else { &F3 }
}

/// `R_i F R_jᵀ` (3.20) for frame flip `f`.
fn pair_rotation(ri: &Matrix3<f64>, rj: &Matrix3<f64>, f: &[f64; 3]) -> Matrix3<f64> {
    ri * Matrix3::from_diagonal(&Vector3::new(f[0], f[1], f[2])) * rj.transpose()
}

/// Transform parameters `[θ, tx, ty]` (2-D) or `[roll, pitch, yaw, tx, ty, tz]` (3-D).
fn params(r: &Matrix3<f64>, t: &Vector3<f64>, d: usize, out: &mut [f32]) {
    if d == 2 {
        out[0] = r[(1, 0)].atan2(r[(0, 0)]) as f32;
        out[1] = t[0] as f32;
        out[2] = t[1] as f32;
    } else {
        let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(*r).euler_angles();
        out[0] = roll as f32;
        out[1] = pitch as f32;
        out[2] = yaw as f32;
        out[3] = t[0] as f32;
        out[4] = t[1] as f32;
        out[5] = t[2] as f32;
    }
}

/// One dimension of the discretisation.
#[derive(Debug, Clone, Copy)]
struct Binner {
    width: f64,
    /// Number of bins of a wrapped (angle) dimension; 0 for an unwrapped one.
    wrap_bins: i64,
    shift: f64,
    kmin: i64,
    bins: usize,
}

impl Binner {
    fn raw(&self, v: f32) -> i64 {
        if self.wrap_bins > 0 {
            (((v as f64 + PI) / self.width + self.shift).floor() as i64).rem_euclid(self.wrap_bins)
        } else {
            (v as f64 / self.width + self.shift).floor() as i64
        }
    }
    fn bin(&self, v: f32) -> usize {
        (self.raw(v) - self.kmin) as usize
    }
}

/// The candidate transforms.
struct Pairs {
    d: usize,
    dv: usize,
    vals: Vec<f32>,
    i: Vec<u32>,
    j: Vec<u32>,
    f: Vec<u8>,
}

/// Everything shared by the clustering and the hypothesis estimation.
struct Problem {
    d: usize,
    x_sub: Vec<usize>,
    y_sub: Vec<usize>,
    fx: Vec<Option<Frame>>,
    fy: Vec<Option<Frame>>,
    /// X in the voting frame, `(x/unit − x_mean)/scale`.
    x: DMatrix<f64>,
    /// Y in the voting frame, `(y/unit − centroid)/scale`.
    yc: DMatrix<f64>,
    /// Centroid of `y/unit`.
    centroid: Vector3<f64>,
    /// Centroid of `x/unit`.
    x_mean: Vector3<f64>,
    /// Largest absolute input coordinate.
    unit: f64,
    /// Largest absolute coordinate after centring `x/unit` and `y/unit`.
    scale: f64,
    angle_bin: f64,
    translation_bin: f64,
}

fn subsample(n: usize, max: usize) -> Vec<usize> {
    if n <= max {
        (0..n).collect()
    } else {
        (0..max).map(|k| k * n / max).collect()
    }
}

fn row3(p: &DMatrix<f64>, r: usize) -> Vector3<f64> {
    let mut v = Vector3::zeros();
    for c in 0..p.ncols() {
        v[c] = p[(r, c)];
    }
    v
}

fn prepare(x: &DMatrix<f64>, y: &DMatrix<f64>, o: &VotingOptions) -> Result<Problem> {
    validate_points("X", x)?;
    validate_points("Y", y)?;
    if x.ncols() != y.ncols() {
        return Err(DetectError::WrongLength {
            what: "columns (dimension) of Y",
            got: y.ncols(),
            expected: x.ncols(),
        });
    }
    let d = x.ncols();
    validate_options(o, d)?;
    // Votes are binned in f32 and frames from squared distances, so both sets are moved to a
    // common frame of unit extent first: x̃ = (x/m − x̄)/s, ỹ = (y/m − ȳ)/s. A rigid transform
    // keeps its rotation and maps back through `hypothesis`; coordinates of 1e-300 or 1e300 then
    // vote exactly as coordinates of 1 do.
    let m = x.amax().max(y.amax());
    let centroid_of = |p: &DMatrix<f64>| {
        (0..p.nrows()).fold(Vector3::zeros(), |a, r| a + row3(p, r) / m) / p.nrows() as f64
    };
    let (x_mean, centroid) = (centroid_of(x), centroid_of(y));
    let centred = |p: &DMatrix<f64>, c: &Vector3<f64>| {
        DMatrix::from_fn(p.nrows(), d, |r, k| p[(r, k)] / m - c[k])
    };
    let (xc, yc) = (centred(x, &x_mean), centred(y, &centroid));
    let s = xc.amax().max(yc.amax());
    let (xn, yn) = (xc / s, yc / s);
    let rms = ((0..yn.nrows())
        .map(|r| row3(&yn, r).norm_squared())
        .sum::<f64>()
        / yn.nrows() as f64)
        .sqrt();
    let translation_bin = match o.translation_bin {
        Some(t) => t / m / s,
        None => o.angle_bin * rms,
    };
    if !(translation_bin.is_finite() && translation_bin > 0.0) {
        return Err(DetectError::InvalidParameter {
            what: "translation_bin",
            value: o.translation_bin.unwrap_or(f64::NAN),
            reason: "must be finite and > 0 (unset, it is angle_bin times the data's RMS extent, which overflows here)",
        });
    }
    Ok(Problem {
        d,
        x_sub: subsample(x.nrows(), o.max_points),
        y_sub: subsample(y.nrows(), o.max_points),
        fx: frames(&xn, o.neighbours)?,
        fy: frames(&yn, o.neighbours)?,
        x: xn,
        yc: yn,
        centroid,
        x_mean,
        unit: m,
        scale: s,
        angle_bin: o.angle_bin,
        translation_bin,
    })
}

/// All candidate transforms (3.20) of the subsampled pairs.
fn candidate_pairs(p: &Problem, o: &VotingOptions) -> Result<Pairs> {
    let d = p.d;
    let dv = if d == 2 { 3 } else { 6 };
    let fl = flips(d);
    let xs: Vec<(usize, Frame)> = p
        .x_sub
        .iter()
        .filter_map(|&i| p.fx[i].map(|f| (i, f)))
        .collect();
    let ys: Vec<(usize, Frame)> = p
        .y_sub
        .iter()
        .enumerate()
        .filter_map(|(jj, &j)| p.fy[j].map(|f| (jj, f)))
        .collect();
    if xs.is_empty() || ys.is_empty() {
        return Err(DetectError::Degenerate {
            reason: format!(
                "no local frame could be computed ({} of X, {} of Y): every neighbourhood is a single repeated point",
                xs.len(),
                ys.len()
            ),
        });
    }
    let total = xs.len() * ys.len() * fl.len();
    if total > o.max_pairs {
        return Err(DetectError::InvalidParameter {
            what: "max_pairs",
            value: o.max_pairs as f64,
            reason: "fewer than the candidate transforms M₁·N₁·flips; lower max_points or raise max_pairs",
        });
    }
    let mut out = Pairs {
        d,
        dv,
        vals: Vec::with_capacity(total * dv),
        i: Vec::with_capacity(total),
        j: Vec::with_capacity(total),
        f: Vec::with_capacity(total),
    };
    // Per (y_j, flip): M = F R_jᵀ and w = M (y_j − ȳ), so that R_ij = R_i M and
    // T_ij = x_i − R_i w (3.20) cost one 3×3 product each. In 2-D the angles simply subtract.
    struct YPre {
        jj: u32,
        k: u8,
        m: Matrix3<f64>,
        w: Vector3<f64>,
        y: Vector3<f64>,
        angle: f64,
        desc: [f64; 2],
    }
    let mut ypre = Vec::with_capacity(ys.len() * fl.len());
    for &(jj, fj) in &ys {
        let yj = row3(&p.yc, p.y_sub[jj]);
        for (k, f) in fl.iter().enumerate() {
            let m = Matrix3::from_diagonal(&Vector3::new(f[0], f[1], f[2])) * fj.r.transpose();
            let w = m * yj;
            // 2-D: R(a_i) F R(a_j)ᵀ = R(a_i − a_j + π·[flip]).
            let angle = fj.r[(1, 0)].atan2(fj.r[(0, 0)]) - if f[0] < 0.0 { PI } else { 0.0 };
            ypre.push(YPre {
                jj: jj as u32,
                k: k as u8,
                m,
                w,
                y: yj,
                angle,
                desc: fj.desc,
            });
        }
    }
    let mut buf = [0f32; 6];
    for &(i, fi) in &xs {
        let xi = row3(&p.x, i);
        let ai = fi.r[(1, 0)].atan2(fi.r[(0, 0)]);
        for y in &ypre {
            if let Some(tol) = o.descriptor_tolerance
                && ((fi.desc[0] - y.desc[0]).abs() > tol || (fi.desc[1] - y.desc[1]).abs() > tol)
            {
                continue;
            }
            if d == 2 {
                let th = ai - y.angle;
                let (sn, cs) = th.sin_cos();
                let yv = y.y;
                buf[0] = (th + PI).rem_euclid(2.0 * PI) as f32 - PI as f32;
                buf[1] = (xi.x - (cs * yv.x - sn * yv.y)) as f32;
                buf[2] = (xi.y - (sn * yv.x + cs * yv.y)) as f32;
            } else {
                let r = fi.r * y.m;
                let t = xi - fi.r * y.w;
                params(&r, &t, d, &mut buf[..dv]);
            }
            out.vals.extend_from_slice(&buf[..dv]);
            out.i.push(i as u32);
            out.j.push(y.jj);
            out.f.push(y.k);
        }
    }
    Ok(out)
}

/// The binners of one grid (`shift` = 0 or ½ bin).
fn binners(p: &Problem, pairs: &Pairs, shift: f64) -> Result<Vec<Binner>> {
    let n = pairs.i.len();
    let mut out = Vec::with_capacity(pairs.dv);
    for dim in 0..pairs.dv {
        let angle = dim < pairs.dv / 2;
        let wrapped = angle && !(pairs.d == 3 && dim == 1);
        let mut b = if wrapped {
            let nb = ((2.0 * PI / p.angle_bin).round() as i64).max(1);
            Binner {
                width: 2.0 * PI / nb as f64,
                wrap_bins: nb,
                shift,
                kmin: 0,
                bins: nb as usize,
            }
        } else {
            let width = if angle {
                p.angle_bin
            } else {
                p.translation_bin
            };
            Binner {
                width,
                wrap_bins: 0,
                shift,
                kmin: 0,
                bins: 0,
            }
        };
        if !wrapped {
            // The bin range in f64: an i64 difference of saturated bins (a width of 1e-20 of
            // the data's extent) would wrap past the guard below.
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for q in 0..n {
                let k = (f64::from(pairs.vals[q * pairs.dv + dim]) / b.width + b.shift).floor();
                lo = lo.min(k);
                hi = hi.max(k);
            }
            let span = hi - lo + 1.0;
            if span.is_nan() || span > 50_000_000.0 {
                // The width in the caller's units (translations are binned in the voting frame).
                let (what, value) = if angle {
                    ("angle_bin", b.width)
                } else {
                    ("translation_bin", b.width * p.unit * p.scale)
                };
                return Err(DetectError::InvalidParameter {
                    what,
                    value,
                    reason: "too small for the extent of the data: it must leave at most 5·10⁷ bins in one dimension",
                });
            }
            b.kmin = lo.min(hi) as i64;
            b.bins = span.max(1.0) as usize;
        }
        out.push(b);
    }
    Ok(out)
}

/// A populated cell of the discretised transform space: its member pairs and counts.
struct Cell {
    members: Vec<u32>,
    votes: usize,
    pair_votes: usize,
}

/// Algorithm 3: recursive per-dimension bucketing of the candidate transforms; returns the cells
/// whose pair count and Y-count reach `min_votes`.
fn cluster(pairs: &Pairs, bins: &[Binner], n_y: usize, min_votes: usize) -> Vec<Cell> {
    let n = pairs.i.len();
    let dv = pairs.dv;
    // Records [bin₀ … bin_{dv−1}, pair index] moved together, so every pass reads and writes
    // contiguous memory (a counting sort per dimension inside each current cluster).
    let stride = dv + 1;
    let mut rec = vec![0u32; n * stride];
    for q in 0..n {
        let r = &mut rec[q * stride..(q + 1) * stride];
        for (dim, b) in bins.iter().enumerate() {
            r[dim] = b.bin(pairs.vals[q * dv + dim]) as u32;
        }
        r[dv] = q as u32;
    }
    let mut tmp = vec![0u32; n * stride];
    let mut ranges: Vec<(usize, usize)> = if n >= min_votes {
        vec![(0, n)]
    } else {
        Vec::new()
    };
    let kmax = bins.iter().map(|b| b.bins).max().unwrap_or(1);
    let mut counts = vec![0u32; kmax];
    let mut starts = vec![0usize; kmax];
    let mut touched: Vec<usize> = Vec::new();
    for dim in 0..dv {
        let mut next = Vec::new();
        for &(s, e) in &ranges {
            touched.clear();
            for q in s..e {
                let k = rec[q * stride + dim] as usize;
                if counts[k] == 0 {
                    touched.push(k);
                }
                counts[k] += 1;
            }
            if touched.len() == 1 {
                // One bin: nothing moves.
                counts[touched[0]] = 0;
                next.push((s, e));
                continue;
            }
            let mut off = s;
            for &k in &touched {
                starts[k] = off;
                let c = counts[k] as usize;
                if c >= min_votes {
                    next.push((off, off + c));
                }
                off += c;
            }
            for q in s..e {
                let k = rec[q * stride + dim] as usize;
                let dst = starts[k];
                tmp[dst * stride..(dst + 1) * stride]
                    .copy_from_slice(&rec[q * stride..(q + 1) * stride]);
                starts[k] += 1;
            }
            rec[s * stride..e * stride].copy_from_slice(&tmp[s * stride..e * stride]);
            for &k in &touched {
                counts[k] = 0;
            }
        }
        ranges = next;
    }
    let order: Vec<u32> = (0..n).map(|q| rec[q * stride + dv]).collect();
    // Count unique source points per cell ("count unique index" of Algorithm 3, Y-count).
    let mut stamp = vec![u32::MAX; n_y];
    ranges
        .iter()
        .enumerate()
        .filter_map(|(c, &(s, e))| {
            let mut votes = 0;
            for &q in &order[s..e] {
                let j = pairs.j[q as usize] as usize;
                if stamp[j] != c as u32 {
                    stamp[j] = c as u32;
                    votes += 1;
                }
            }
            (votes >= min_votes).then(|| Cell {
                members: order[s..e].to_vec(),
                votes,
                pair_votes: e - s,
            })
        })
        .collect()
}

/// Mean transform of a cell: rotation = projection of the mean rotation onto SO(D), translation
/// = mean of `x_i − R̄ (y_j − ȳ)`; returned for the centred model.
fn cell_transform(p: &Problem, pairs: &Pairs, cell: &Cell) -> (Matrix3<f64>, Vector3<f64>) {
    let fl = flips(p.d);
    let mut sum = Matrix3::zeros();
    for &q in &cell.members {
        let q = q as usize;
        let (i, j) = (pairs.i[q] as usize, p.y_sub[pairs.j[q] as usize]);
        if let (Some(fi), Some(fj)) = (p.fx[i], p.fy[j]) {
            sum += pair_rotation(&fi.r, &fj.r, &fl[pairs.f[q] as usize]);
        }
    }
    let r = project_rotation(&sum, p.d);
    let mut t = Vector3::zeros();
    for &q in &cell.members {
        let q = q as usize;
        let (i, j) = (pairs.i[q] as usize, p.y_sub[pairs.j[q] as usize]);
        t += row3(&p.x, i) - r * row3(&p.yc, j);
    }
    (r, t / cell.members.len().max(1) as f64)
}

/// Nearest rotation (Frobenius) to `m`: in 2-D the angle `atan2(m₁₀ − m₀₁, m₀₀ + m₁₁)`, in 3-D
/// `U diag(1, 1, det(UVᵀ)) Vᵀ`.
fn project_rotation(m: &Matrix3<f64>, d: usize) -> Matrix3<f64> {
    if d == 2 {
        let a = (m[(1, 0)] - m[(0, 1)]).atan2(m[(0, 0)] + m[(1, 1)]);
        let (s, c) = a.sin_cos();
        let mut r = Matrix3::identity();
        r[(0, 0)] = c;
        r[(0, 1)] = -s;
        r[(1, 0)] = s;
        r[(1, 1)] = c;
        r
    } else {
        let svd = m.svd(true, true);
        match (svd.u, svd.v_t) {
            (Some(u), Some(vt)) => {
                let det = (u * vt).determinant().signum();
                u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, det)) * vt
            }
            _ => Matrix3::identity(),
        }
    }
}

fn rotation_angle_between(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let c = ((a.transpose() * b).trace() - 1.0) / 2.0;
    c.clamp(-1.0, 1.0).acos()
}

/// Scored cells of every grid, best first by the chosen count.
fn scored_cells(p: &Problem, pairs: &Pairs, o: &VotingOptions) -> Result<Vec<Cell>> {
    let shifts: &[f64] = if o.shifted_grid { &[0.0, 0.5] } else { &[0.0] };
    let mut cells = Vec::new();
    for &s in shifts {
        let b = binners(p, pairs, s)?;
        cells.extend(cluster(pairs, &b, p.y_sub.len(), o.min_votes));
    }
    let key = |c: &Cell| match o.count {
        VoteCount::YCount => (c.votes, c.pair_votes),
        VoteCount::Pairs => (c.pair_votes, c.votes),
    };
    cells.sort_by_key(|c| std::cmp::Reverse(key(c)));
    Ok(cells)
}

fn hypothesis(p: &Problem, r: &Matrix3<f64>, tc: &Vector3<f64>, cell: &Cell) -> RigidHypothesis {
    let d = p.d;
    // x/u = R·(y/u − ȳ) + s·t̃ + x̄ in the voting frame, so t = u·(s·t̃ + x̄ − R·ȳ).
    let t = p.unit * (p.scale * tc + p.x_mean - r * p.centroid);
    RigidHypothesis {
        rotation: DMatrix::from_fn(d, d, |a, b| r[(a, b)]),
        translation: DVector::from_fn(d, |a, _| t[a]),
        votes: cell.votes,
        pair_votes: cell.pair_votes,
    }
}

/// Global voting of rigid transforms (seed 000_3b1454b2b2194811.txt §3.4, eq. (3.20)–(3.22),
/// Algorithm 3): the top-K rigid transforms `x ≈ R y + t` mapping `Y` (M×D, the model) onto `X`
/// (N×D, the scene), best first, ranked by `opts.count` (Y-count by default). Cells that lie
/// within 1.5 bins (in angle and translation) of a better hypothesis are suppressed. Returns an
/// empty list when no cluster reaches `opts.min_votes`.
///
/// Errors: `D ∉ {2, 3}` or differing dimensions, fewer than `D + 1` points, NaN/∞, all points
/// identical, invalid options, or more than `opts.max_pairs` candidate transforms.
pub fn global_voting(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    opts: &VotingOptions,
) -> Result<Vec<RigidHypothesis>> {
    let p = prepare(x, y, opts)?;
    let pairs = candidate_pairs(&p, opts)?;
    let cells = scored_cells(&p, &pairs, opts)?;
    let mut chosen: Vec<(Matrix3<f64>, Vector3<f64>)> = Vec::new();
    let mut out = Vec::new();
    for cell in &cells {
        if out.len() >= opts.top_k {
            break;
        }
        let (r, t) = cell_transform(&p, &pairs, cell);
        let duplicate = chosen.iter().any(|(rc, tc)| {
            rotation_angle_between(rc, &r) <= 1.5 * p.angle_bin
                && (tc - t).norm() <= 1.5 * p.translation_bin
        });
        if duplicate {
            continue;
        }
        chosen.push((r, t));
        out.push(hypothesis(&p, &r, &t, cell));
    }
    Ok(out)
}

/// Every populated cell of the (unshifted) vote grid with at least `opts.min_votes`, as
/// hypotheses sorted by `opts.count` — the discretised vote map of Fig. 3.13 (no suppression,
/// `top_k` ignored). Same inputs and errors as [`global_voting`].
pub fn vote_cells(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    opts: &VotingOptions,
) -> Result<Vec<RigidHypothesis>> {
    let single = VotingOptions {
        shifted_grid: false,
        ..opts.clone()
    };
    let p = prepare(x, y, &single)?;
    let pairs = candidate_pairs(&p, &single)?;
    let cells = scored_cells(&p, &pairs, &single)?;
    Ok(cells
        .iter()
        .map(|c| {
            let (r, t) = cell_transform(&p, &pairs, c);
            hypothesis(&p, &r, &t, c)
        })
        .collect())
}

#[cfg(test)]
mod tests;
