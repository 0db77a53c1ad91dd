//! Trimmed nearest-neighbour sharpening of a refined pose (issue 29).
//!
//! Rigid CPD with a *uniform* outlier term (000_3b1454b2b2194811.txt eq. (3.12)) is biased by
//! structured outliers: a dense run of points across the template (the density mismatch of
//! Fig. 3.12) holds σ² large and the pose a few per cent off. The selection criterion counts
//! template points with a scene point within the inlier radius; this step climbs that same
//! objective locally: each template point is paired with its nearest scene point, pairs beyond
//! the gate `max(3·√D·σ, 2·median distance, h)` are dropped, the rigid transform of the rest is
//! solved in closed form (Kabsch/Umeyama, the M-step of eq. (3.15) with a 0/1 posterior), and σ
//! is re-estimated from the kept pairs.

use nalgebra::{DMatrix, DVector};

use super::scoring::Index;

/// Sharpens the pose `(r, t)` of `y` in the scene indexed by `index` (rows of `x`); returns the
/// new pose and its per-coordinate σ² over the kept pairs. `h` is the template's point spacing.
#[allow(clippy::too_many_arguments)]
pub(super) fn sharpen(
    index: &Index,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    r: &DMatrix<f64>,
    t: &DVector<f64>,
    sigma2: f64,
    h: f64,
    iterations: usize,
) -> (DMatrix<f64>, DVector<f64>, f64) {
    let d = y.ncols();
    let (mut r, mut t, mut s2) = (r.clone(), t.clone(), sigma2);
    let mut pairs: Vec<(usize, usize, f64)> = Vec::with_capacity(y.nrows());
    for _ in 0..iterations {
        let moved = super::apply(y, &r, &t);
        pairs.clear();
        for m in 0..moved.nrows() {
            let (i, d2) = index.nearest(&moved, m);
            pairs.push((m, i, d2));
        }
        let mut dist: Vec<f64> = pairs.iter().map(|p| p.2.sqrt()).collect();
        dist.sort_by(f64::total_cmp);
        let median = dist[dist.len() / 2];
        let gate = (3.0 * (d as f64 * s2).sqrt()).max(2.0 * median).max(h);
        let kept: Vec<&(usize, usize, f64)> = pairs.iter().filter(|p| p.2.sqrt() <= gate).collect();
        if kept.len() < d + 1 {
            break;
        }
        let n = kept.len() as f64;
        let my = DVector::from_fn(d, |c, _| kept.iter().map(|p| y[(p.0, c)]).sum::<f64>() / n);
        let mx = DVector::from_fn(d, |c, _| kept.iter().map(|p| x[(p.1, c)]).sum::<f64>() / n);
        let mut a = DMatrix::<f64>::zeros(d, d);
        for p in &kept {
            let xv = DVector::from_fn(d, |c, _| x[(p.1, c)]) - &mx;
            let yv = DVector::from_fn(d, |c, _| y[(p.0, c)]) - &my;
            a += xv * yv.transpose();
        }
        let svd = a.svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            break;
        };
        let mut c = DMatrix::<f64>::identity(d, d);
        c[(d - 1, d - 1)] = (&u * &vt).determinant().signum();
        let r_new = &u * c * &vt;
        let t_new = &mx - &r_new * &my;
        let moved_new = super::apply(y, &r_new, &t_new);
        let ss: f64 = kept
            .iter()
            .map(|p| {
                (0..d)
                    .map(|c| (moved_new[(p.0, c)] - x[(p.1, c)]).powi(2))
                    .sum::<f64>()
            })
            .sum();
        let change = (&r_new - &r).norm() + (&t_new - &t).norm();
        r = r_new;
        t = t_new;
        s2 = (ss / (n * d as f64)).max(f64::MIN_POSITIVE);
        if change <= 1e-9 * (1.0 + t.norm()) {
            break;
        }
    }
    (r, t, s2)
}
