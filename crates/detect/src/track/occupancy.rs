//! Where rims are seen: other tracks' predicted rims in the image (a free slot that is another
//! track's) and the rim-angle coverage of a circle's views.

use super::*;

/// The predicted points of every track in one kd-tree, with the track index of each point.
pub(super) type PredictionTree = Option<(ImmutableKdTree<f64, 2>, Vec<usize>)>;

/// Whether a free-slot candidate of track `own` (points `v_j` with the lengths `δ_j` of their
/// displacements from the track's prediction) is another track's slot in the image: over the
/// candidate points (at least 3) that have a predicted point of track `m` within `δ_j`, the sum
/// of the distances to `m`'s nearest predicted point is below half the sum of the distances to
/// the own track's nearest predicted point (capped at `δ_j`). A track one pitch further on is
/// as far from the candidate as the own track (ratio ≈ 1); a track in the slot is at its
/// prediction error (ratio ≪ 1). This catches an occupied slot whose track's 3D estimate is
/// still too poor (a young track, a partial view) for the test along the axis. The tree of the
/// predicted points is built on first use.
pub(super) fn occupied_in_image(
    pts: &[([f64; 2], f64)],
    own: usize,
    predictions: &[Prediction],
    tree: &mut Option<PredictionTree>,
) -> bool {
    let built = tree.get_or_insert_with(|| {
        let mut all = Vec::new();
        let mut owner = Vec::new();
        for (m, p) in predictions.iter().enumerate() {
            all.extend_from_slice(&p.points);
            owner.extend(std::iter::repeat_n(m, p.points.len()));
        }
        ImmutableKdTree::new_from_slice(&all)
            .ok()
            .map(|t| (t, owner))
    });
    let Some((tree, owner)) = built.as_ref() else {
        return false;
    };
    const NEAREST: NonZeroUsize = NonZeroUsize::new(16).unwrap();
    // Per other track `m`: (points of the candidate with `m` within `δ_j`, Σ dist_mj, Σ own_j)
    // with `own_j = min(dist_own,j, δ_j)`, over those points only (a young track seen on a
    // short arc occupies its slot where it was seen).
    let mut acc: Vec<(usize, usize, f64, f64)> = Vec::new();
    let mut nearest: Vec<(usize, f64)> = Vec::new();
    for (v, d) in pts {
        nearest.clear();
        let found = tree
            .query(v)
            .nearest_n::<SquaredEuclidean<f64>>(NEAREST)
            .within(d * d)
            .execute();
        for r in found {
            let Some(&m) = owner.get(r.item as usize) else {
                continue;
            };
            let dist = r.distance.sqrt();
            match nearest.iter_mut().find(|e| e.0 == m) {
                Some(e) => e.1 = e.1.min(dist),
                None => nearest.push((m, dist)),
            }
        }
        let own_j = nearest
            .iter()
            .find(|e| e.0 == own)
            .map_or(*d, |e| e.1.min(*d));
        for &(m, dist) in nearest.iter().filter(|e| e.0 != own) {
            match acc.iter_mut().find(|e| e.0 == m) {
                Some(e) => {
                    e.1 += 1;
                    e.2 += dist;
                    e.3 += own_j;
                }
                None => acc.push((m, 1, dist, own_j)),
            }
        }
    }
    acc.iter()
        .any(|&(_, n, dm, down)| n >= 3 && dm < 0.5 * down)
}

/// Number of rim-angle bins over the circle (10° each) recording where a rim was seen.
pub(super) const ANGLE_BINS: usize = 36;

/// The rim-angle bins (bit `b` for `φ ∈ [−π + b·10°, −π + (b+1)·10°)`) of the points of a view
/// taken from camera pose `t_wc`, located on the circle `c` by their rays.
pub(super) fn angle_bins(
    c: &Circle3,
    t_wc: &Isometry3<f64>,
    k: &Matrix3<f64>,
    points: &[[f64; 2]],
) -> u64 {
    let Some(k_inv) = k.try_inverse() else {
        return 0;
    };
    let origin = t_wc.translation.vector;
    let mut bins = 0u64;
    for p in points {
        let ray = t_wc.rotation * (k_inv * Vector3::new(p[0], p[1], 1.0));
        if let Some(phi) = rim_angle_of_ray(c, &origin, &ray) {
            let b =
                ((phi + std::f64::consts::PI) / std::f64::consts::TAU * ANGLE_BINS as f64).floor();
            if b.is_finite() {
                bins |= 1 << (b as usize).min(ANGLE_BINS - 1);
            }
        }
    }
    bins
}

/// Eq. (4.1) for a well-estimated rim: the circle `c` projected through the current pose at
/// the rim angles where the rim was seen in its recent views (`seen` bins, 3 samples per bin,
/// at most `m` points), and the projected ellipse of the whole rim.
pub(super) fn project_bins(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    c: &Circle3,
    seen: u64,
    m: usize,
) -> Option<(Vec<[f64; 2]>, Option<Ellipse>)> {
    let t_cw = t_wc.inverse();
    let width = std::f64::consts::TAU / ANGLE_BINS as f64;
    let mut pts = Vec::with_capacity(3 * ANGLE_BINS);
    for b in (0..ANGLE_BINS).filter(|b| seen & (1 << b) != 0) {
        for s in 0..3 {
            let phi = -std::f64::consts::PI + width * (b as f64 + (s as f64 + 0.5) / 3.0);
            let x_c = t_cw * nalgebra::Point3::from(c.point_at(phi));
            if let Some(q) = project(k, &x_c.coords) {
                pts.push([q.x, q.y]);
            }
        }
    }
    if pts.is_empty() {
        return None;
    }
    let ell = project_circle_world(k, &t_cw, &c.center, &c.normal, c.radius).ok();
    Some((subsample(&pts, m), ell))
}

/// Eq. (4.1): the rim points of the last visible segment, located on the 3D circle `c` by
/// their rays from the old camera pose, projected through the current pose `t_wc`; and the
/// projected ellipse of the whole rim.
pub(super) fn project_rim(
    k: &Matrix3<f64>,
    t_wc: &Isometry3<f64>,
    old_pose: &Isometry3<f64>,
    c: &Circle3,
    edge: &WaferEdge,
    m: usize,
) -> Option<(Vec<[f64; 2]>, Option<Ellipse>)> {
    let k_inv = k.try_inverse()?;
    let origin = old_pose.translation.vector;
    let t_cw = t_wc.inverse();
    let pts: Vec<[f64; 2]> = subsample(&edge_points(edge), m)
        .iter()
        .filter_map(|p| {
            let ray = old_pose.rotation * (k_inv * Vector3::new(p[0], p[1], 1.0));
            let phi = rim_angle_of_ray(c, &origin, &ray)?;
            let x_c = t_cw * nalgebra::Point3::from(c.point_at(phi));
            project(k, &x_c.coords).map(|q| [q.x, q.y])
        })
        .collect();
    if pts.is_empty() {
        return None;
    }
    let ell = project_circle_world(k, &t_cw, &c.center, &c.normal, c.radius).ok();
    Some((pts, ell))
}

/// Rim angle of the circle point seen along a ray: where the ray meets the circle's plane, or,
/// when the view is within ~6° of edge-on (where that intersection is ill-conditioned), where
/// it enters the sphere through the rim (the near side, which is the visible front rim);
/// `None` if the ray misses both.
pub(super) fn rim_angle_of_ray(
    c: &Circle3,
    origin: &Vector3<f64>,
    ray: &Vector3<f64>,
) -> Option<f64> {
    let d = ray.try_normalize(1e-300)?;
    if c.normal.dot(&d).abs() > 0.1 {
        return c.angle_of_ray(origin, &d);
    }
    let oc = origin - c.center;
    let b = oc.dot(&d);
    let disc = b * b - (oc.norm_squared() - c.radius * c.radius);
    // A ray passing beside the sphere: its closest approach.
    let s = if disc >= 0.0 { -b - disc.sqrt() } else { -b };
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let x = oc + d * s;
    let (u, v) = c.basis();
    Some(x.dot(&v).atan2(x.dot(&u)))
}
