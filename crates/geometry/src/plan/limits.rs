//! Kinematic and torque limits, the per-joint time-optimal bound and the dense verification of a
//! trajectory (000_3b1454b2b2194811.txt ch. 2.4, eqs. 2.16–2.17, Fig. 2.11).

use crate::robot::Joints;

use super::PlanError;
use super::bspline::BSplineTrajectory;
use super::dynamics::Dynamics;
use super::workspace::PlanWorkspace;

/// Limits of eq. (2.16): per-joint velocity, acceleration, jerk and torque (N·m; N for the lift)
/// and the clearance `d_safe` of eq. (2.17).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// `v_max` (rad/s, m/s for the lift).
    pub velocity: Joints,
    /// `a_max`.
    pub acceleration: Joints,
    /// `j_max`.
    pub jerk: Joints,
    /// `τ_max`.
    pub torque: Joints,
    /// `d_safe` (m).
    pub d_safe: f64,
}

impl Default for Limits {
    /// A 300 mm wafer robot: 3–4 rad/s, 10–15 rad/s², 100–150 rad/s³ on the arm, 0.5 m/s,
    /// 2 m/s², 20 m/s³ on the lift; 200/100/20/20 N·m and 600 N; 10 mm clearance.
    fn default() -> Self {
        Self {
            velocity: Joints::new(3.0, 3.0, 4.0, 4.0, 0.5),
            acceleration: Joints::new(10.0, 10.0, 15.0, 15.0, 2.0),
            jerk: Joints::new(100.0, 100.0, 150.0, 150.0, 20.0),
            torque: Joints::new(200.0, 100.0, 20.0, 20.0, 600.0),
            d_safe: 0.01,
        }
    }
}

impl Limits {
    /// Checks the limits: positive and finite, and the lift's force above the lifted weight.
    pub fn validate(&self, dynamics: &Dynamics) -> Result<(), PlanError> {
        for (name, v) in [
            ("velocity", &self.velocity),
            ("acceleration", &self.acceleration),
            ("jerk", &self.jerk),
            ("torque", &self.torque),
        ] {
            if let Some(i) = (0..5).find(|&i| !(v[i].is_finite() && v[i] > 0.0)) {
                return Err(PlanError::Infeasible {
                    constraint: format!("{name} limit of joint {i}"),
                    reason: format!("{} must be positive and finite", v[i]),
                });
            }
        }
        if !(self.d_safe.is_finite() && self.d_safe >= 0.0) {
            return Err(PlanError::Infeasible {
                constraint: "clearance d_safe".into(),
                reason: format!("{} must be non-negative and finite", self.d_safe),
            });
        }
        let weight = dynamics.torques(&Joints::zeros(), &Joints::zeros(), &Joints::zeros())[4];
        if self.torque[4] <= weight {
            return Err(PlanError::Infeasible {
                constraint: "torque joint 4 (lift)".into(),
                reason: format!(
                    "the lift's force limit {:.1} N does not exceed the lifted weight {weight:.1} N",
                    self.torque[4]
                ),
            });
        }
        Ok(())
    }
}

/// Time of the time-optimal rest-to-rest move of one joint over `distance` under velocity,
/// acceleration and jerk limits (the seven-phase jerk-limited profile that the seed's Fig. 2.11
/// calls the trapezoidal lower bound, and that ruckig computes): with the acceleration phase
/// `T_a(v) = v/a + a/j` (or `2√(v/j)` if `v < a²/j`) covering `v T_a / 2`, the move cruises
/// at `v_max` when `v_max T_a(v_max) ≤ distance`, else reaches the peak `v_p` with
/// `v_p T_a(v_p) = distance` (solved by bisection).
pub fn joint_time_bound(distance: f64, v: f64, a: f64, j: f64) -> f64 {
    let d = distance.abs();
    if d == 0.0 {
        return 0.0;
    }
    let ta = |v: f64| {
        if v * j >= a * a {
            v / a + a / j
        } else {
            2.0 * (v / j).sqrt()
        }
    };
    if v * ta(v) <= d {
        return 2.0 * ta(v) + (d - v * ta(v)) / v;
    }
    let (mut lo, mut hi) = (0.0, v);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid * ta(mid) < d {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    2.0 * ta(0.5 * (lo + hi))
}

/// The per-joint lower bound of a rest-to-rest move from `q0` to `q1`: the slowest joint's
/// time-optimal move (no obstacles, no torque limits, no coupling). Returns `(time, joint)`.
pub fn per_joint_bound(q0: &Joints, q1: &Joints, limits: &Limits) -> (f64, usize) {
    (0..5)
        .map(|i| {
            (
                joint_time_bound(
                    q1[i] - q0[i],
                    limits.velocity[i],
                    limits.acceleration[i],
                    limits.jerk[i],
                ),
                i,
            )
        })
        .fold((0.0, 0), |b, c| if c.0 > b.0 { c } else { b })
}

/// What a dense check of a trajectory found: the largest ratio of |value| to limit per kind
/// (≤ 1 means within the limit) and the smallest clearance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verification {
    /// Largest `|q̇_i| / v_max,i`.
    pub velocity_ratio: f64,
    /// Largest `|q̈_i| / a_max,i`.
    pub acceleration_ratio: f64,
    /// Largest `|q⃛_i| / j_max,i` (the jerk is piecewise constant; each span is sampled).
    pub jerk_ratio: f64,
    /// Largest `|τ_i| / τ_max,i`.
    pub torque_ratio: f64,
    /// Smallest signed clearance (m).
    pub min_clearance: f64,
    /// Number of samples.
    pub samples: usize,
}

impl Verification {
    /// Whether every limit holds within `rel` (relative) and the clearance is at least `d_safe`.
    pub fn ok(&self, rel: f64, d_safe: f64) -> bool {
        let r = 1.0 + rel;
        self.velocity_ratio <= r
            && self.acceleration_ratio <= r
            && self.jerk_ratio <= r
            && self.torque_ratio <= r
            && self.min_clearance >= d_safe
    }
}

/// Samples a trajectory every `dt` seconds (and at its end) and measures the limits and the
/// clearance with parry, independently of how the trajectory was made.
pub fn verify(
    ws: &PlanWorkspace,
    dynamics: &Dynamics,
    traj: &BSplineTrajectory,
    limits: &Limits,
    dt: f64,
) -> Result<Verification, PlanError> {
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(PlanError::InvalidInput {
            what: "sampling step",
            reason: format!("{dt} must be positive"),
        });
    }
    let times: Vec<f64> = traj.check_times(dt).collect();
    let mut v = Verification {
        velocity_ratio: 0.0,
        acceleration_ratio: 0.0,
        jerk_ratio: 0.0,
        torque_ratio: 0.0,
        min_clearance: f64::INFINITY,
        samples: times.len(),
    };
    let ratio = |x: &Joints, l: &Joints| (0..5).map(|i| x[i].abs() / l[i]).fold(0.0, f64::max);
    for t in times {
        let s = traj.sample(t);
        v.velocity_ratio = v.velocity_ratio.max(ratio(&s.dq, &limits.velocity));
        v.acceleration_ratio = v
            .acceleration_ratio
            .max(ratio(&s.ddq, &limits.acceleration));
        v.jerk_ratio = v.jerk_ratio.max(ratio(&s.dddq, &limits.jerk));
        let tau = dynamics.torques(&s.q, &s.dq, &s.ddq);
        v.torque_ratio = v.torque_ratio.max(ratio(&tau, &limits.torque));
        v.min_clearance = v.min_clearance.min(ws.signed_distance(&s.q)?);
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The three cases of the jerk-limited profile against their closed forms.
    #[test]
    fn joint_bound_matches_closed_forms() {
        // Closed form: long move with a cruise phase: T = d/v + v/a + a/j.
        let t = joint_time_bound(10.0, 2.0, 4.0, 40.0);
        assert!((t - (10.0 / 2.0 + 2.0 / 4.0 + 4.0 / 40.0)).abs() < 1e-12);
        // Short move, jerk-limited only: T = 4 (d / (2 j))^{1/3}.
        let t = joint_time_bound(1e-3, 10.0, 100.0, 10.0);
        assert!((t - 4.0 * (1e-3 / 20.0f64).cbrt()).abs() < 1e-9);
        // Acceleration-limited without cruise: v_p² / a + v_p a / j = d.
        let (d, a, j) = (1.0f64, 5.0f64, 100.0f64);
        let vp = 0.5 * a * (-a / j + ((a / j).powi(2) + 4.0 * d / a).sqrt());
        let t = joint_time_bound(d, 100.0, a, j);
        assert!((t - 2.0 * (vp / a + a / j)).abs() < 1e-9, "{t}");
    }
}
