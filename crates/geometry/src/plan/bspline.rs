//! Clamped cubic B-splines in joint space, 000_3b1454b2b2194811.txt ch. 2.4, eqs. (2.10)–(2.15).
//!
//! A B-spline of degree `k` with control points `P_1..P_n` and knots `t_1..t_{n+k+1}` is
//! `B(t) = Σ P_i N_{i,k}(t)` (eq. 2.11) with the Cox–de Boor basis of eq. (2.10). Its
//! derivative is a B-spline of degree `k−1` on the knots without the first and last one, with
//! control points `V_i = k (P_{i+1} − P_i) / (t_{i+k+1} − t_{i+1})` (eq. 2.12); applied three
//! times this gives the control points of velocity `V`, acceleration `A` and jerk `R`. By the
//! convex-hull property every component of the curve lies between the smallest and largest
//! control point of that component, which makes `max |V|, max |A|, max |R|` conservative bounds
//! on the velocity, acceleration and jerk ([`BSpline::hull_bounds`]).
//!
//! Clamped knots (eq. 2.14) repeat the first and last knot `k+1` times so that
//! `B(0) = P_1, B(T) = P_n` and the end velocity and acceleration are the first and last `V`
//! and `A` (eq. 2.15).
//!
//! Indexing here is 0-based: control point `i` of the seed is `ctrl[i−1]`.

use crate::robot::Joints;

use super::PlanError;

/// A B-spline curve in the five-dimensional joint space (eq. 2.11).
#[derive(Debug, Clone, PartialEq)]
pub struct BSpline {
    /// Degree `k` (3 for the trajectories).
    pub degree: usize,
    /// Knots `t_1..t_{n+k+1}`, non-decreasing.
    pub knots: Vec<f64>,
    /// Control points `P_1..P_n`.
    pub ctrl: Vec<Joints>,
}

impl BSpline {
    /// Builds a spline after checking `knots.len() == ctrl.len() + degree + 1`, finiteness and
    /// monotone knots.
    pub fn new(degree: usize, knots: Vec<f64>, ctrl: Vec<Joints>) -> Result<Self, PlanError> {
        if ctrl.len() <= degree || knots.len() != ctrl.len() + degree + 1 {
            return Err(PlanError::InvalidInput {
                what: "B-spline",
                reason: format!(
                    "{} control points and {} knots for degree {degree} (need n > k and n + k + 1 knots)",
                    ctrl.len(),
                    knots.len()
                ),
            });
        }
        if knots.iter().any(|t| !t.is_finite())
            || ctrl.iter().any(|p| p.iter().any(|v| !v.is_finite()))
        {
            return Err(PlanError::InvalidInput {
                what: "B-spline",
                reason: "non-finite knot or control point".into(),
            });
        }
        if knots.windows(2).any(|w| w[1] < w[0]) {
            return Err(PlanError::InvalidInput {
                what: "B-spline knots",
                reason: "knots must be non-decreasing".into(),
            });
        }
        Ok(Self {
            degree,
            knots,
            ctrl,
        })
    }

    /// Start of the domain, `t_{k+1}`.
    pub fn t_start(&self) -> f64 {
        self.knots[self.degree]
    }

    /// End of the domain, `t_{n+1}`.
    pub fn t_end(&self) -> f64 {
        self.knots[self.ctrl.len()]
    }

    /// The knot span `s` with `t_s ≤ t < t_{s+1}` (`k ≤ s < n`), clamping `t` to the domain.
    fn span(&self, t: f64) -> usize {
        let k = self.degree;
        let n = self.ctrl.len();
        if t >= self.knots[n] {
            // Last non-empty span.
            let mut s = n - 1;
            while s > k && self.knots[s] >= self.knots[n] {
                s -= 1;
            }
            return s;
        }
        // Binary search in knots[k..=n].
        let (mut lo, mut hi) = (k, n);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if self.knots[mid] <= t {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// Evaluates `B(t)` (eq. 2.11) by de Boor's algorithm, which is the recursion (2.10)
    /// applied to the control points; `t` is clamped to the domain.
    pub fn eval(&self, t: f64) -> Joints {
        let k = self.degree;
        let t = t.clamp(self.t_start(), self.t_end());
        let s = self.span(t);
        let mut d: Vec<Joints> = (0..=k).map(|j| self.ctrl[j + s - k]).collect();
        for r in 1..=k {
            for j in (r..=k).rev() {
                let i = j + s - k;
                let den = self.knots[i + k + 1 - r] - self.knots[i];
                let a = if den > 0.0 {
                    (t - self.knots[i]) / den
                } else {
                    0.0
                };
                d[j] = d[j - 1] * (1.0 - a) + d[j] * a;
            }
        }
        d[k]
    }

    /// The derivative spline, eq. (2.12): degree `k−1`, knots `t_2..t_{n+k}`, control points
    /// `k (P_{i+1} − P_i) / (t_{i+k+1} − t_{i+1})` (zero where the denominator vanishes).
    pub fn derivative(&self) -> Result<Self, PlanError> {
        let k = self.degree;
        if k == 0 {
            return Err(PlanError::InvalidInput {
                what: "B-spline",
                reason: "the derivative of a degree-0 spline is not a B-spline".into(),
            });
        }
        let ctrl = (0..self.ctrl.len() - 1)
            .map(|i| {
                let den = self.knots[i + k + 1] - self.knots[i + 1];
                if den > 0.0 {
                    (self.ctrl[i + 1] - self.ctrl[i]) * (k as f64 / den)
                } else {
                    Joints::zeros()
                }
            })
            .collect();
        Ok(Self {
            degree: k - 1,
            knots: self.knots[1..self.knots.len() - 1].to_vec(),
            ctrl,
        })
    }

    /// Per-joint convex-hull bound `max_i |P_i|` (ch. 2.4 after eq. 2.12): `|B(t)|` never
    /// exceeds it, per component.
    pub fn hull_bounds(&self) -> Joints {
        self.ctrl
            .iter()
            .fold(Joints::zeros(), |m, p| m.sup(&p.abs()))
    }
}

/// Clamped knots of eq. (2.14) for a cubic spline from the durations of its `n − 3` non-empty
/// spans: `t_1 = … = t_4 = 0`, `t_{i+4} = Σ_{j≤i} Δt_j`, `t_{n+1} = … = t_{n+4} = T`.
pub fn clamped_knots(spans: &[f64]) -> Vec<f64> {
    let mut knots = vec![0.0; 4];
    let mut t = 0.0;
    for (j, d) in spans.iter().enumerate() {
        t += d;
        if j + 1 < spans.len() {
            knots.push(t);
        }
    }
    knots.extend([t; 4]);
    knots
}

/// Most samples per knot span in a check of a trajectory ([`BSplineTrajectory::check_times`]).
/// A cubic span's velocity, acceleration and torque vary smoothly within it; a grid of 1 000
/// points per span finds a quadratic's extremum to 1e-6 of its range, so a finer grid only
/// follows a longer duration, not a different shape. Trajectories of a few seconds at the 1 ms
/// step of the checks stay below it and are sampled as before.
pub const MAX_CHECK_SAMPLES_PER_SPAN: usize = 1000;

/// A time-parametrised joint trajectory: a clamped cubic B-spline (eqs. 2.11, 2.14) with its
/// velocity, acceleration and jerk splines (eq. 2.12) precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct BSplineTrajectory {
    /// Position spline (degree 3).
    pub position: BSpline,
    /// Velocity spline, control points `V_i`.
    pub velocity: BSpline,
    /// Acceleration spline, control points `A_i`.
    pub acceleration: BSpline,
    /// Jerk spline (piecewise constant), control points `R_i`.
    pub jerk: BSpline,
}

/// One sample of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectorySample {
    /// Joint positions.
    pub q: Joints,
    /// Joint velocities.
    pub dq: Joints,
    /// Joint accelerations.
    pub ddq: Joints,
    /// Joint jerks.
    pub dddq: Joints,
}

impl BSplineTrajectory {
    /// A clamped cubic trajectory from control points and the durations of its `n − 3` spans
    /// (each positive).
    pub fn from_spans(ctrl: Vec<Joints>, spans: &[f64]) -> Result<Self, PlanError> {
        if ctrl.len() < 4 || spans.len() + 3 != ctrl.len() {
            return Err(PlanError::InvalidInput {
                what: "trajectory",
                reason: format!(
                    "{} control points need {} span durations, got {}",
                    ctrl.len(),
                    ctrl.len().saturating_sub(3),
                    spans.len()
                ),
            });
        }
        if let Some(d) = spans.iter().find(|d| !(d.is_finite() && **d > 0.0)) {
            return Err(PlanError::InvalidInput {
                what: "span durations",
                reason: format!("every span must be positive and finite, got {d}"),
            });
        }
        Self::from_spline(BSpline::new(3, clamped_knots(spans), ctrl)?)
    }

    /// Wraps a cubic position spline with clamped knots.
    pub fn from_spline(position: BSpline) -> Result<Self, PlanError> {
        if position.degree != 3 {
            return Err(PlanError::InvalidInput {
                what: "trajectory",
                reason: format!("degree {} (a trajectory is cubic)", position.degree),
            });
        }
        let velocity = position.derivative()?;
        let acceleration = velocity.derivative()?;
        let jerk = acceleration.derivative()?;
        Ok(Self {
            position,
            velocity,
            acceleration,
            jerk,
        })
    }

    /// Duration `T = t_{n+1} − t_4`.
    pub fn duration(&self) -> f64 {
        self.position.t_end() - self.position.t_start()
    }

    /// The times of a check sampled every `dt` seconds from 0 to `T` (both included), coarsened
    /// to at most [`MAX_CHECK_SAMPLES_PER_SPAN`] per knot span: the cost of a check follows the
    /// trajectory's shape, not its duration. (A jerk limit of 1e-300 rad/s³ stretches a move to
    /// 1e99 s; sampling it every millisecond would never end.) A non-positive or non-finite
    /// `dt` gives the coarsened grid.
    pub fn check_times(&self, dt: f64) -> impl Iterator<Item = f64> + use<> {
        let t_end = self.duration();
        let spans = self
            .position
            .ctrl
            .len()
            .saturating_sub(self.position.degree)
            .max(1);
        let cap = spans.saturating_mul(MAX_CHECK_SAMPLES_PER_SPAN);
        let fine = t_end / dt;
        let (n, step) = if dt > 0.0 && fine.is_finite() && fine.ceil() <= cap as f64 {
            (fine.ceil() as usize, dt)
        } else {
            (cap, t_end / cap as f64)
        };
        (0..=n).map(move |k| (k as f64 * step).min(t_end))
    }

    /// Knots `t_1..t_{n+4}`.
    pub fn knots(&self) -> &[f64] {
        &self.position.knots
    }

    /// Control points `P_1..P_n`.
    pub fn control_points(&self) -> &[Joints] {
        &self.position.ctrl
    }

    /// Position, velocity, acceleration and jerk at time `t` (clamped to `[0, T]`).
    pub fn sample(&self, t: f64) -> TrajectorySample {
        TrajectorySample {
            q: self.position.eval(t),
            dq: self.velocity.eval(t),
            ddq: self.acceleration.eval(t),
            dddq: self.jerk.eval(t),
        }
    }
}

/// Control points of a rest-to-rest clamped cubic through a joint-space path: the polyline is
/// resampled at `n − 4` points equally spaced in (weighted) arc length, and the first and last
/// points are repeated three times so that the end velocity and acceleration are zero
/// (eq. 2.15 with `P_1 = P_2 = P_3`). The curve then stays within the convex hull of every four
/// consecutive resampled points, i.e. close to the path when `n` is large.
pub fn fit_path(
    path: &[Joints],
    n_ctrl: usize,
    weights: &Joints,
) -> Result<Vec<Joints>, PlanError> {
    if path.len() < 2 {
        return Err(PlanError::InvalidInput {
            what: "path",
            reason: format!("{} points (need at least 2)", path.len()),
        });
    }
    if n_ctrl < 6 {
        return Err(PlanError::InvalidInput {
            what: "number of control points",
            reason: format!("{n_ctrl} (need at least 6 for a rest-to-rest cubic)"),
        });
    }
    let m = n_ctrl - 4;
    let seg: Vec<f64> = path
        .windows(2)
        .map(|w| (w[1] - w[0]).component_mul(weights).norm())
        .collect();
    let total: f64 = seg.iter().sum();
    let mut pts = crate::alloc::try_with_capacity("B-spline control points", n_ctrl)?;
    let first = path[0];
    let last = path[path.len() - 1];
    pts.extend([first, first]);
    let mut j = 0;
    let mut acc = 0.0;
    for i in 0..m {
        let s = if m > 1 {
            total * i as f64 / (m - 1) as f64
        } else {
            0.0
        };
        while j + 1 < seg.len() && acc + seg[j] < s {
            acc += seg[j];
            j += 1;
        }
        let f = if seg[j] > 0.0 {
            ((s - acc) / seg[j]).clamp(0.0, 1.0)
        } else {
            0.0
        };
        pts.push(path[j] * (1.0 - f) + path[j + 1] * f);
    }
    pts[2] = first;
    pts[n_ctrl - 3] = last;
    pts.extend([last, last]);
    Ok(pts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo() -> BSplineTrajectory {
        let ctrl: Vec<Joints> = (0..9)
            .map(|i| {
                let x = i as f64;
                Joints::new(x.sin(), 0.3 * x, (0.5 * x).cos(), -0.1 * x * x, 0.01 * x)
            })
            .collect();
        BSplineTrajectory::from_spans(ctrl, &[0.2, 0.1, 0.3, 0.15, 0.25, 0.2]).unwrap()
    }

    #[test]
    fn clamped_ends_match_eq_2_15() {
        let tr = demo();
        let p = tr.control_points();
        let t = tr.knots();
        let n = p.len();
        assert!((tr.sample(0.0).q - p[0]).norm() < 1e-12);
        assert!((tr.sample(tr.duration()).q - p[n - 1]).norm() < 1e-12);
        let v1 = (p[1] - p[0]) * (3.0 / (t[4] - t[1]));
        assert!((tr.sample(0.0).dq - v1).norm() < 1e-9);
        let vn = (p[n - 1] - p[n - 2]) * (3.0 / (t[n + 2] - t[n - 1]));
        assert!((tr.sample(tr.duration()).dq - vn).norm() < 1e-9);
        // Accelerations at the ends: A_1 = 2 (V_2 − V_1) / (t_5 − t_3) and
        // A_{n−2} = 2 (V_{n−1} − V_{n−2}) / (t_{n+2} − t_n) (1-based), from (2.12). The
        // denominators printed in (2.15), t_4 − t_2 and t_{n+3} − t_{n+1}, are zero on the
        // clamped knots of (2.14): a slip of the seed (docs/design/motion.md).
        let v = tr.velocity.ctrl.clone();
        let a1 = (v[1] - v[0]) * (2.0 / (t[4] - t[2]));
        let an = (v[n - 2] - v[n - 3]) * (2.0 / (t[n + 1] - t[n - 1]));
        assert!((tr.sample(0.0).ddq - a1).norm() < 1e-9);
        assert!((tr.sample(tr.duration()).ddq - an).norm() < 1e-9);
        assert_eq!(t[3] - t[1], 0.0);
        assert_eq!(t[n + 2] - t[n], 0.0);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let tr = demo();
        let h = 1e-6;
        for &t in &[0.05, 0.31, 0.62, 0.9, 1.1] {
            let s = tr.sample(t);
            let fd = |f: &dyn Fn(f64) -> Joints| (f(t + h) - f(t - h)) / (2.0 * h);
            let dq = fd(&|u| tr.sample(u).q);
            let ddq = fd(&|u| tr.sample(u).dq);
            let dddq = fd(&|u| tr.sample(u).ddq);
            assert!((dq - s.dq).norm() < 1e-6 * (1.0 + s.dq.norm()), "{t}");
            assert!((ddq - s.ddq).norm() < 1e-5 * (1.0 + s.ddq.norm()), "{t}");
            assert!((dddq - s.dddq).norm() < 1e-4 * (1.0 + s.dddq.norm()), "{t}");
        }
    }

    #[test]
    fn basis_is_a_partition_of_unity_and_curve_is_in_the_hull() {
        let tr = demo();
        // A constant control polygon is reproduced exactly (Σ N = 1).
        let c = Joints::new(0.3, -0.2, 1.0, 0.5, 0.1);
        let flat =
            BSplineTrajectory::from_spans(vec![c; 9], &[0.2, 0.1, 0.3, 0.15, 0.25, 0.2]).unwrap();
        for i in 0..=100 {
            let t = flat.duration() * i as f64 / 100.0;
            assert!((flat.sample(t).q - c).norm() < 1e-12);
        }
        let (vb, ab, jb) = (
            tr.velocity.hull_bounds(),
            tr.acceleration.hull_bounds(),
            tr.jerk.hull_bounds(),
        );
        for i in 0..=2000 {
            let s = tr.sample(tr.duration() * i as f64 / 2000.0);
            for d in 0..5 {
                assert!(s.dq[d].abs() <= vb[d] * (1.0 + 1e-12) + 1e-15);
                assert!(s.ddq[d].abs() <= ab[d] * (1.0 + 1e-12) + 1e-15);
                assert!(s.dddq[d].abs() <= jb[d] * (1.0 + 1e-12) + 1e-15);
            }
        }
    }

    #[test]
    fn fit_path_starts_and_ends_at_rest() {
        let path = vec![
            Joints::zeros(),
            Joints::new(1.0, 0.0, 0.0, 0.0, 0.0),
            Joints::new(1.0, 1.0, 0.0, 0.0, 0.1),
        ];
        let ctrl = fit_path(&path, 12, &Joints::repeat(1.0)).unwrap();
        assert_eq!(ctrl.len(), 12);
        let tr = BSplineTrajectory::from_spans(ctrl, &[0.1; 9]).unwrap();
        let (a, b) = (tr.sample(0.0), tr.sample(tr.duration()));
        assert!(
            a.dq.norm() < 1e-12
                && a.ddq.norm() < 1e-12
                && b.dq.norm() < 1e-12
                && b.ddq.norm() < 1e-12
        );
        assert!((b.q - path[2]).norm() < 1e-12);
        assert!(BSplineTrajectory::from_spans(vec![Joints::zeros(); 5], &[0.1, 0.0]).is_err());
        assert!(fit_path(&path[..1], 12, &Joints::repeat(1.0)).is_err());
    }
}
