//! Shared-shape fit of both rims of one wafer (seed 000_3b1454b2b2194811.txt §3.2, Fig. 3.2:
//! the two edges of a wafer's bright boundary; the rims are the images of two parallel circles
//! one wafer thickness apart, eq. (3.1)–(3.2)).
//!
//! The two rims' images share their semi-major axis and orientation to ≈ 0.03 % (the relative
//! depth change of one thickness, see `share_shape` in `pair.rs`), and their centres lie on
//! one line along the projected wafer normal `up`. When neither rim is seen beyond its front arc
//! (both cover about half of their ellipse), each rim's own fit trades `a`, `b` and the centre
//! off along the arc; [`fit_rim_pair`] fits both point sets at once with seven parameters,
//! `p = [cx, cy, a, θ, b_u, s, b_l]`: the upper rim is `(cx, cy, a, b_u, θ)`, the lower rim
//! `(cx + s·up.x, cy + s·up.y, a, b_l, θ)`. The residuals are the signed orthogonal distances of
//! eq. (3.1)'s curve, minimised by Levenberg–Marquardt with the analytic Jacobian (envelope
//! theorem at the foot point, Ahn, Rauh & Warnecke 2001): with `t` the foot point's eccentric
//! angle, `n̂` the outward normal there and `N = √(b²cos²t + a²sin²t)`,
//! `∂r/∂(cx, cy, a, b, θ) = −(n̂ₓ, n̂ᵧ, b·cos²t/N, a·sin²t/N, (a² − b²)·sin t·cos t/N)`.

// `!(x < y)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix5, SMatrix, SVector, Vector2};

/// Number of parameters of the shared fit.
const K: usize = 7;
/// Parameter vector `[cx, cy, a, θ, b_u, s, b_l]`.
type P = SVector<f64, K>;

/// Result of [`fit_rim_pair`].
#[derive(Debug, Clone)]
pub(super) struct RimPairFit {
    /// The upper rim.
    pub upper: Ellipse,
    /// The lower rim.
    pub lower: Ellipse,
    /// Covariance of `[cx, cy, a, θ, b_u, s, b_l]`, `σ̂²·(JᵀJ)⁻¹` with `σ̂² = SSR/(n − 7)`.
    pub covariance: SMatrix<f64, K, K>,
    /// The unit direction `up` of the fit.
    pub up: Vector2<f64>,
}

impl RimPairFit {
    /// Covariance of the lower rim's `(cx, cy, a, b, θ)`: `J·Σ·Jᵀ` with `J` the derivative of
    /// `(cx + s·up.x, cy + s·up.y, a, b_l, θ)` with respect to `[cx, cy, a, θ, b_u, s, b_l]`.
    pub fn lower_covariance(&self) -> Matrix5<f64> {
        let mut j = SMatrix::<f64, 5, K>::zeros();
        j[(0, 0)] = 1.0;
        j[(0, 5)] = self.up.x;
        j[(1, 1)] = 1.0;
        j[(1, 5)] = self.up.y;
        j[(2, 2)] = 1.0;
        j[(3, 6)] = 1.0;
        j[(4, 3)] = 1.0;
        j * self.covariance * j.transpose()
    }
}

/// The two ellipses for parameters `p`.
fn ellipses(p: &P, up: Vector2<f64>) -> Option<(Ellipse, Ellipse)> {
    let upper = Ellipse::new(p[0], p[1], p[2], p[4], p[3]).ok()?;
    let lower = Ellipse::new(p[0] + p[5] * up.x, p[1] + p[5] * up.y, p[2], p[6], p[3]).ok()?;
    // `Ellipse::new` normalises a < b by swapping: the shared `a` must stay the major axis.
    (upper.a == p[2] && lower.a == p[2]).then_some((upper, lower))
}

/// Residuals (upper points first) and, if `jac`, the Jacobian rows with respect to `p`.
fn residuals(
    p: &P,
    upper: &[Vector2<f64>],
    lower: &[Vector2<f64>],
    up: Vector2<f64>,
    mut jac: Option<&mut Vec<[f64; K]>>,
    r: &mut Vec<f64>,
) -> Option<()> {
    let (eu, el) = ellipses(p, up)?;
    r.clear();
    if let Some(j) = jac.as_mut() {
        j.clear();
    }
    for (e, points, is_upper) in [(&eu, upper, true), (&el, lower, false)] {
        for q in points {
            if jac.is_none() {
                r.push(e.orthogonal_distance(q));
                continue;
            }
            let (d, g) = crate::ellipse::point_distance_and_gradient(e, q);
            r.push(d);
            if let Some(j) = jac.as_mut() {
                j.push(if is_upper {
                    [g[0], g[1], g[2], g[4], g[3], 0.0, 0.0]
                } else {
                    [g[0], g[1], g[2], g[4], 0.0, g[0] * up.x + g[1] * up.y, g[3]]
                });
            }
        }
    }
    r.iter().all(|x| x.is_finite()).then_some(())
}

/// Fits both rims of a wafer with shared `a`, `θ` and centre line (module doc), starting from
/// their separate fits `eu`, `el`. `up` is the unit image direction of the wafer normal.
/// `None` when either rim has fewer than 10 points, the inputs are not finite, or the fit
/// fails or does not converge within 50 iterations.
pub(super) fn fit_rim_pair(
    upper: &[Vector2<f64>],
    lower: &[Vector2<f64>],
    eu: &Ellipse,
    el: &Ellipse,
    up: Vector2<f64>,
) -> Option<RimPairFit> {
    if upper.len() < 10 || lower.len() < 10 || !(up.norm() > 0.0) {
        return None;
    }
    let s0 = (el.cx - eu.cx) * up.x + (el.cy - eu.cy) * up.y;
    let mut p =
        P::from_column_slice(&[eu.cx, eu.cy, 0.5 * (eu.a + el.a), eu.theta, eu.b, s0, el.b]);
    if !p.iter().all(|x| x.is_finite()) {
        return None;
    }
    let (mut r, mut j) = (Vec::new(), Vec::new());
    residuals(&p, upper, lower, up, None, &mut r)?;
    let mut cost: f64 = r.iter().map(|x| x * x).sum();
    let mut lambda = 1e-3;
    let mut converged = false;
    for _ in 0..50 {
        residuals(&p, upper, lower, up, Some(&mut j), &mut r)?;
        let mut h = SMatrix::<f64, K, K>::zeros();
        let mut g = P::zeros();
        for (row, res) in j.iter().zip(&r) {
            let v = P::from_column_slice(row);
            h += v * v.transpose();
            g += v * *res;
        }
        let mut stepped = false;
        while lambda < 1e10 {
            let mut hd = h;
            for i in 0..K {
                hd[(i, i)] += lambda * h[(i, i)].max(1e-12);
            }
            let Some(dp) = hd.cholesky().map(|c| c.solve(&(-g))) else {
                lambda *= 10.0;
                continue;
            };
            let p_new = p + dp;
            let c_new = residuals(&p_new, upper, lower, up, None, &mut r)
                .map(|_| r.iter().map(|x| x * x).sum::<f64>());
            match c_new {
                Some(c) if c <= cost => {
                    let small =
                        cost - c <= 1e-12 * cost.max(1e-300) || dp.iter().all(|x| x.abs() < 1e-9);
                    p = p_new;
                    cost = c;
                    lambda = (lambda * 0.3).max(1e-12);
                    stepped = true;
                    converged = small;
                    break;
                }
                _ => lambda *= 10.0,
            }
        }
        if !stepped {
            // No descent at any damping: at the minimum to rounding.
            converged = true;
        }
        if converged {
            break;
        }
    }
    if !converged {
        return None;
    }
    residuals(&p, upper, lower, up, Some(&mut j), &mut r)?;
    let mut h = SMatrix::<f64, K, K>::zeros();
    for row in &j {
        let v = P::from_column_slice(row);
        h += v * v.transpose();
    }
    let dof = (r.len() - K).max(1) as f64;
    let covariance = h.try_inverse()? * (cost / dof);
    let (upper, lower) = ellipses(&p, up)?;
    Some(RimPairFit {
        upper,
        lower,
        covariance,
        up,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pair_jacobian_matches_finite_differences() {
        let up = Vector2::new(0.05, -1.0).normalize();
        let eu = Ellipse::new(640.0, 200.0, 300.0, 20.0, 0.02).unwrap();
        let el = Ellipse::new(640.1, 202.0, 300.0, 21.0, 0.02).unwrap();
        let pu = eu.sample(30, 3.4, 6.0).unwrap();
        let pl: Vec<Vector2<f64>> = el
            .sample(30, 3.4, 6.0)
            .unwrap()
            .iter()
            .enumerate()
            .map(|(i, q)| q + Vector2::new(0.0, 0.2 * ((i % 3) as f64 - 1.0)))
            .collect();
        let p = P::from_column_slice(&[640.2, 199.8, 300.5, 0.021, 20.3, -2.1, 20.8]);
        let (mut r, mut j) = (Vec::new(), Vec::new());
        residuals(&p, &pu, &pl, up, Some(&mut j), &mut r).unwrap();
        for k in 0..K {
            let h = 1e-6 * (1.0 + p[k].abs());
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let (mut ra, mut rb) = (Vec::new(), Vec::new());
            residuals(&a, &pu, &pl, up, None, &mut ra).unwrap();
            residuals(&b, &pu, &pl, up, None, &mut rb).unwrap();
            for i in 0..r.len() {
                let fd = (ra[i] - rb[i]) / (2.0 * h);
                assert!(
                    (fd - j[i][k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "row {i} k={k}: {fd} vs {}",
                    j[i][k]
                );
            }
        }
    }

    #[test]
    fn exact_front_arcs_give_back_both_rims_and_bad_input_gives_none() {
        // Two parallel-circle images seen from below: front arcs are the upper halves.
        let up = Vector2::new(0.0, -1.0);
        let eu = Ellipse::new(640.0, 150.0, 310.0, 9.0, 0.01).unwrap();
        let el = Ellipse::new(640.0, 152.5, 310.0, 9.4, 0.01).unwrap();
        let pu = eu.sample(120, -3.0, -0.14).unwrap();
        let pl = el.sample(120, -3.0, -0.14).unwrap();
        // Start from biased separate fits (a off by 1.5 %, b by 4 %, centres by 0.6 px).
        let su = Ellipse::new(640.3, 150.4, 312.0, 9.3, 0.012).unwrap();
        let sl = Ellipse::new(639.8, 153.0, 314.6, 9.8, 0.008).unwrap();
        let fit = fit_rim_pair(&pu, &pl, &su, &sl, up).unwrap();
        for (f, t) in [(fit.upper, eu), (fit.lower, el)] {
            assert!(
                (f.cx - t.cx).abs() < 1e-6 && (f.cy - t.cy).abs() < 1e-6,
                "{f:?} {t:?}"
            );
            assert!(
                (f.a - t.a).abs() < 1e-6 && (f.b - t.b).abs() < 1e-6,
                "{f:?} {t:?}"
            );
            assert!((f.theta - t.theta).abs() < 1e-9);
        }
        // Too few points, non-finite input.
        assert!(fit_rim_pair(&pu[..5], &pl, &su, &sl, up).is_none());
        let mut bad = pl.clone();
        bad[3].x = f64::NAN;
        assert!(fit_rim_pair(&pu, &bad, &su, &sl, up).is_none());
    }
}
