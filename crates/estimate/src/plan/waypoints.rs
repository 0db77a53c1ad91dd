//! A transfer through fixed way-points with free way-point velocities, 000_3b1454b2b2194811.txt
//! ch. 2.4 (Table 2.2: "we cannot change the location of way-points, we can change the velocity at
//! both way-points"), eqs. (2.15)–(2.17).
//!
//! Each segment between consecutive way-points is a clamped cubic B-spline (eq. 2.14). At a
//! way-point `W` with velocity `v` and zero acceleration, eq. (2.15) fixes the two control
//! points next to the end: from `V_1 = 3(P_2 − P_1)/s_1 = v` and `A_1 = 0` (so `V_2 = V_1`),
//! with `s_1, s_2` the first two span durations,
//!
//! `P_2 = W + v s_1 / 3`,  `P_3 = W + v (2 s_1 + s_2) / 3`,
//!
//! and at a segment's end `P_{n−1} = W − v s_m / 3`, `P_{n−2} = W − v (s_{m−1} + 2 s_m) / 3`
//! (`s_m` the last span). These points are functions of the velocity and the spans, so the
//! way-point velocities (one per interior way-point, shared by the two segments that meet
//! there; the transfer starts and ends at rest) join the free control points and the spans as
//! unknowns of eq. (2.16). The sequential convex method is the one of [`super::optimize_trajectory`]
//! over all segments at once: exact sparse gradients of the `V, A, R` control points (through
//! the derived points), linearised clearance, a QP with clarabel, then one uniform time scaling
//! `λ` of every segment (spans `× λ`, velocities `÷ λ`, which keeps the derived control points and
//! so the path and the joins), accepted when the total duration drops and the clearance holds.
//! It starts from the rest-to-rest optimum of each segment (zero way-point velocities).

#![allow(clippy::needless_range_loop)]

use std::time::Instant;

use autoteach_geometry::plan::PlanError;
use autoteach_geometry::plan::bspline::BSplineTrajectory;
use autoteach_geometry::plan::dynamics::Dynamics;
use autoteach_geometry::plan::limits::{Limits, Verification, verify};
use autoteach_geometry::plan::workspace::PlanWorkspace;
use autoteach_geometry::robot::Joints;

use super::time_optimal::{
    Lin, OptimizeConfig, basis, min_clearance, optimize_trajectory, required_stretch, solve_qp,
};

/// The optimised multi-segment transfer.
#[derive(Debug, Clone, PartialEq)]
pub struct WaypointResult {
    /// One trajectory per segment; segment `k` ends where segment `k + 1` starts.
    pub segments: Vec<BSplineTrajectory>,
    /// Velocity at each interior way-point (zero when the velocities are not free).
    pub velocities: Vec<Joints>,
    /// Total duration (s).
    pub duration: f64,
    /// Total duration of the rest-to-rest optima of the segments (zero way-point velocities),
    /// the starting point of the joint problem.
    pub initial_duration: f64,
    /// Sequential-convex iterations of the joint problem.
    pub iterations: usize,
    /// Accepted steps of the joint problem.
    pub accepted: usize,
    /// Seconds spent (segments and joint problem).
    pub time_s: f64,
    /// Dense 1 ms verification of each segment.
    pub verification: Vec<Verification>,
}

/// Where segment `k`'s unknowns sit in the variable vector.
struct Seg {
    n: usize,
    p_off: usize,
    s_off: usize,
    v_start: Option<usize>,
    v_end: Option<usize>,
}

struct Problem {
    segs: Vec<Seg>,
    v_off: usize,
    n_vars: usize,
}

impl Problem {
    fn new(ns: &[usize]) -> Self {
        let k = ns.len();
        let mut off = 0;
        let mut segs = Vec::with_capacity(k);
        for (j, &n) in ns.iter().enumerate() {
            let p_off = off;
            let s_off = p_off + 5 * (n - 6);
            off = s_off + n - 3;
            segs.push(Seg {
                n,
                p_off,
                s_off,
                v_start: (j > 0).then(|| j - 1),
                v_end: (j + 1 < k).then_some(j),
            });
        }
        Self {
            segs,
            v_off: off,
            n_vars: off + 5 * (k - 1),
        }
    }

    fn v_var(&self, w: usize, d: usize) -> usize {
        self.v_off + 5 * w + d
    }

    /// Control point `i`, joint `d` of segment `seg` as a function of the unknowns (module docs).
    fn point(
        &self,
        seg: &Seg,
        ctrl: &[Joints],
        spans: &[f64],
        vel: &[Joints],
        i: usize,
        d: usize,
    ) -> Lin {
        let n = seg.n;
        let m = n - 3;
        let s = |j: usize| (seg.s_off + j, spans[j]);
        let derived = |w: usize, base: f64, sign: f64, terms: &[(usize, f64)]| {
            // base + sign · v · Σ c_j s_j / 3
            let v = vel[w][d];
            let c: f64 = terms.iter().map(|&(j, c)| c * spans[j]).sum::<f64>() / 3.0;
            let mut g = vec![(self.v_var(w, d), sign * c)];
            g.extend(terms.iter().map(|&(j, cj)| (s(j).0, sign * v * cj / 3.0)));
            Lin {
                v: base + sign * v * c,
                g,
            }
        };
        match (i, seg.v_start, seg.v_end) {
            (1, Some(w), _) => derived(w, ctrl[0][d], 1.0, &[(0, 1.0)]),
            (2, Some(w), _) => derived(w, ctrl[0][d], 1.0, &[(0, 2.0), (1, 1.0)]),
            (i, _, Some(w)) if i == n - 2 => derived(w, ctrl[n - 1][d], -1.0, &[(m - 1, 1.0)]),
            (i, _, Some(w)) if i == n - 3 => {
                derived(w, ctrl[n - 1][d], -1.0, &[(m - 2, 1.0), (m - 1, 2.0)])
            }
            (i, _, _) if i >= 3 && i + 3 < n => Lin {
                v: ctrl[i][d],
                g: vec![(seg.p_off + 5 * (i - 3) + d, 1.0)],
            },
            _ => Lin {
                v: ctrl[i][d],
                g: Vec::new(),
            },
        }
    }

    /// `t_b − t_a` (0-based knots) of a segment as the sum of its spans between them.
    fn den(seg: &Seg, a: usize, b: usize, spans: &[f64]) -> Lin {
        let c = |m: usize| m.saturating_sub(3).min(seg.n - 3);
        let (ca, cb) = (c(a), c(b));
        Lin {
            v: spans[ca..cb].iter().sum(),
            g: (ca..cb).map(|j| (seg.s_off + j, 1.0)).collect(),
        }
    }

    /// `V, A, R` control points of eq. (2.12) for joint `d` of a segment, with gradients.
    fn derivative_points(
        &self,
        seg: &Seg,
        ctrl: &[Joints],
        spans: &[f64],
        vel: &[Joints],
        d: usize,
    ) -> [Vec<Lin>; 3] {
        let n = seg.n;
        let p = |i: usize| self.point(seg, ctrl, spans, vel, i, d);
        let v: Vec<Lin> = (0..n - 1)
            .map(|i| {
                p(i + 1)
                    .sub(&p(i))
                    .scale(3.0)
                    .div(&Self::den(seg, i + 1, i + 4, spans))
            })
            .collect();
        let a: Vec<Lin> = (0..n - 2)
            .map(|i| {
                v[i + 1]
                    .sub(&v[i])
                    .scale(2.0)
                    .div(&Self::den(seg, i + 2, i + 4, spans))
            })
            .collect();
        let r: Vec<Lin> = (0..n - 3)
            .map(|i| {
                a[i + 1]
                    .sub(&a[i])
                    .div(&Self::den(seg, i + 3, i + 4, spans))
            })
            .collect();
        [v, a, r]
    }

    /// Sets the derived control points next to the way-points from the velocities and spans.
    fn materialise(&self, ctrl: &mut [Vec<Joints>], spans: &[Vec<f64>], vel: &[Joints]) {
        for (k, seg) in self.segs.iter().enumerate() {
            let n = seg.n;
            for i in [1, 2, n - 3, n - 2] {
                for d in 0..5 {
                    let v = self.point(seg, &ctrl[k], &spans[k], vel, i, d).v;
                    ctrl[k][i][d] = v;
                }
            }
        }
    }
}

/// Checks that consecutive paths share their end points and returns the way-points.
fn check_paths(paths: &[Vec<Joints>]) -> Result<(), PlanError> {
    if paths.is_empty() {
        return Err(PlanError::InvalidInput {
            what: "paths",
            reason: "no segment (need at least one path)".into(),
        });
    }
    for (k, p) in paths.iter().enumerate() {
        if p.len() < 2 || p.iter().any(|q| q.iter().any(|v| !v.is_finite())) {
            return Err(PlanError::InvalidInput {
                what: "paths",
                reason: format!(
                    "segment {k} has {} way-points (need at least 2, all finite)",
                    p.len()
                ),
            });
        }
    }
    for (k, w) in paths.windows(2).enumerate() {
        let gap = (w[0][w[0].len() - 1] - w[1][0]).norm();
        if gap > 1e-9 {
            return Err(PlanError::InvalidInput {
                what: "paths",
                reason: format!(
                    "segment {k} ends {gap:.3e} away from where segment {} starts (expected the same way-point)",
                    k + 1
                ),
            });
        }
    }
    Ok(())
}

/// Optimises a transfer through the fixed way-points that join `paths` (module docs). With
/// `free_velocities` false the velocities stay zero and the joint problem (same iterations)
/// only refines the segments, so the two settings differ by the way-point velocities alone.
/// Errors: as [`optimize_trajectory`], and paths that do not join.
pub fn optimize_waypoints(
    ws: &PlanWorkspace,
    dynamics: &Dynamics,
    paths: &[Vec<Joints>],
    limits: &Limits,
    cfg: &OptimizeConfig,
    free_velocities: bool,
) -> Result<WaypointResult, PlanError> {
    let t0 = Instant::now();
    check_paths(paths)?;
    let mut ctrl = Vec::with_capacity(paths.len());
    let mut spans = Vec::with_capacity(paths.len());
    for p in paths {
        let r = optimize_trajectory(ws, dynamics, p, limits, cfg)?;
        spans.push(
            r.trajectory
                .knots()
                .windows(2)
                .map(|w| w[1] - w[0])
                .filter(|d| *d > 0.0)
                .collect::<Vec<f64>>(),
        );
        ctrl.push(r.trajectory.control_points().to_vec());
    }
    let mut vel = vec![Joints::zeros(); paths.len() - 1];
    let total = |s: &[Vec<f64>]| s.iter().flatten().sum::<f64>();
    let initial_duration = total(&spans);
    let build = |c: &[Vec<Joints>], s: &[Vec<f64>]| -> Result<Vec<BSplineTrajectory>, PlanError> {
        c.iter()
            .zip(s)
            .map(|(c, s)| BSplineTrajectory::from_spans(c.clone(), s))
            .collect()
    };
    let mut trajs = build(&ctrl, &spans)?;
    let (mut iterations, mut accepted) = (0, 0);
    {
        let prob = Problem::new(&ctrl.iter().map(Vec::len).collect::<Vec<_>>());
        let dt = cfg.check_dt;
        let mut radius = cfg.trust_radius;
        let mu = 1e-3;
        let mut current = initial_duration;
        while iterations < cfg.max_iterations && radius > 1e-4 {
            iterations += 1;
            let mut rows: Vec<(Vec<(usize, f64)>, f64)> = Vec::new();
            for (k, seg) in prob.segs.iter().enumerate() {
                for d in 0..5 {
                    let [v, a, r] = prob.derivative_points(seg, &ctrl[k], &spans[k], &vel, d);
                    for (pts, lim) in [
                        (v, limits.velocity[d]),
                        (a, limits.acceleration[d]),
                        (r, limits.jerk[d]),
                    ] {
                        for p in pts.into_iter().filter(|p| !p.g.is_empty()) {
                            rows.push((p.g.iter().map(|(i, x)| (*i, -x)).collect(), lim + p.v));
                            rows.push((p.g, lim - p.v));
                        }
                    }
                }
                // Clearance at four points per span: d + ∇d · Σ N_i ΔP_i ≥ d_safe.
                let n = seg.n;
                let knots = trajs[k].knots().to_vec();
                for j in 0..n - 3 {
                    for f in [0.125, 0.375, 0.625, 0.875] {
                        let t = knots[j + 3] + f * spans[k][j];
                        let (s, nb) = basis(&knots, n, t);
                        let q: Joints = (0..4).map(|i| ctrl[k][s - 3 + i] * nb[i]).sum();
                        let dist = ws.signed_distance(&q)?;
                        if dist >= limits.d_safe + cfg.activation {
                            continue;
                        }
                        let (_, grad) = ws.distance_gradient(&q)?;
                        let mut g = Vec::new();
                        for i in 0..4 {
                            for dd in 0..5 {
                                let p = prob.point(seg, &ctrl[k], &spans[k], &vel, s - 3 + i, dd);
                                g.extend(p.g.iter().map(|(var, x)| (*var, -nb[i] * grad[dd] * x)));
                            }
                        }
                        if !g.is_empty() {
                            rows.push((g, dist - limits.d_safe));
                        }
                    }
                }
                // Trust region on the free control points and the spans.
                for i in 3..n - 3 {
                    for d in 0..5 {
                        let r = if d == 4 { 0.2 * radius } else { radius };
                        let var = seg.p_off + 5 * (i - 3) + d;
                        rows.push((vec![(var, 1.0)], r));
                        rows.push((vec![(var, -1.0)], r));
                    }
                }
                // The span box shrinks with the radius: V, A, R scale as 1/Δt, 1/Δt², 1/Δt³,
                // so their linearisation is only good for small relative span changes.
                let frac = (0.5 * radius / cfg.trust_radius).min(0.5);
                for j in 0..n - 3 {
                    rows.push((vec![(seg.s_off + j, 1.0)], frac * spans[k][j]));
                    rows.push((vec![(seg.s_off + j, -1.0)], frac * spans[k][j]));
                }
            }
            for w in 0..vel.len() {
                for d in 0..5 {
                    let r = if free_velocities {
                        radius * limits.velocity[d]
                    } else {
                        0.0
                    };
                    rows.push((vec![(prob.v_var(w, d), 1.0)], r));
                    rows.push((vec![(prob.v_var(w, d), -1.0)], r));
                }
            }
            let mut cost = vec![0.0; prob.n_vars];
            for seg in &prob.segs {
                for j in 0..seg.n - 3 {
                    cost[seg.s_off + j] = 1.0;
                }
            }
            let Some(step) = solve_qp(prob.n_vars, &cost, &rows, mu)? else {
                radius *= 0.5;
                continue;
            };
            let mut c2 = ctrl.clone();
            let mut s2 = spans.clone();
            let mut v2 = vel.clone();
            for (k, seg) in prob.segs.iter().enumerate() {
                for i in 3..seg.n - 3 {
                    for d in 0..5 {
                        c2[k][i][d] += step[seg.p_off + 5 * (i - 3) + d];
                    }
                }
                for j in 0..seg.n - 3 {
                    s2[k][j] = (spans[k][j] + step[seg.s_off + j]).max(1e-6 * spans[k][j]);
                }
            }
            if free_velocities {
                for w in 0..v2.len() {
                    for d in 0..5 {
                        v2[w][d] += step[prob.v_var(w, d)];
                    }
                }
            }
            // One uniform time scaling of every segment (twice: torques are sampled).
            prob.materialise(&mut c2, &s2, &v2);
            let mut t2 = build(&c2, &s2)?;
            for _ in 0..2 {
                let mut lam: f64 = 0.0;
                for tr in &t2 {
                    lam = lam.max(required_stretch(tr, limits, dynamics, dt)?);
                }
                if (1.0 - 1e-9..=1.0).contains(&lam) {
                    break;
                }
                s2.iter_mut().flatten().for_each(|s| *s *= lam);
                v2.iter_mut().for_each(|v| *v /= lam);
                prob.materialise(&mut c2, &s2, &v2);
                t2 = build(&c2, &s2)?;
            }
            let new_total = total(&s2);
            let mut ok = new_total < current * (1.0 - 1e-6);
            if ok {
                for tr in &t2 {
                    if min_clearance(ws, tr, dt)? < limits.d_safe {
                        ok = false;
                        break;
                    }
                }
            }
            if ok {
                let gain = 1.0 - new_total / current;
                (ctrl, spans, vel, trajs, current) = (c2, s2, v2, t2, new_total);
                accepted += 1;
                radius = (radius * 1.5).min(1.0);
                if gain < 1e-5 {
                    break;
                }
            } else {
                radius *= 0.5;
            }
        }
    }
    let verification = trajs
        .iter()
        .map(|tr| verify(ws, dynamics, tr, limits, 1e-3))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(WaypointResult {
        duration: total(&spans),
        segments: trajs,
        velocities: vel,
        initial_duration,
        iterations,
        accepted,
        time_s: t0.elapsed().as_secs_f64(),
        verification,
    })
}

#[cfg(test)]
mod tests {
    use super::super::time_optimal::tests::free_space;
    use super::*;
    use autoteach_geometry::plan::limits::per_joint_bound;

    fn collinear() -> (Vec<Joints>, Vec<Vec<Joints>>) {
        let w: Vec<Joints> = (0..4)
            .map(|k| {
                let k = k as f64;
                Joints::new(0.6 * k, 0.5 - 0.05 * k, -0.1 * k, 0.1 * k, 0.1)
            })
            .collect();
        let paths = w.windows(2).map(<[Joints]>::to_vec).collect();
        (w, paths)
    }

    #[test]
    fn free_waypoint_velocities_shorten_a_collinear_transfer_and_keep_the_joins() {
        let (ws, dy) = free_space();
        let limits = Limits::default();
        let (w, paths) = collinear();
        let cfg = OptimizeConfig::default();
        let zero = optimize_waypoints(&ws, &dy, &paths, &limits, &cfg, false).unwrap();
        let free = optimize_waypoints(&ws, &dy, &paths, &limits, &cfg, true).unwrap();
        assert!(zero.duration <= zero.initial_duration);
        assert_eq!(zero.initial_duration, free.initial_duration);
        assert!(zero.velocities.iter().all(|v| v.norm() == 0.0));
        for v in &zero.verification {
            assert!(v.ok(1e-9, limits.d_safe), "{v:?}");
        }
        // Stopping twice on a straight move costs two decelerations: free velocities remove them,
        // and no trajectory under the limits beats the slowest joint's rest-to-rest move.
        let (bound, _) = per_joint_bound(&w[0], &w[3], &limits);
        assert!(
            free.duration < 0.92 * zero.duration,
            "{} vs {}",
            free.duration,
            zero.duration
        );
        assert!(
            free.duration >= bound * (1.0 - 1e-9),
            "{} < {bound}",
            free.duration
        );
        for v in &free.verification {
            assert!(v.ok(1e-9, limits.d_safe), "{v:?}");
        }
        for k in 0..2 {
            let (a, b) = (&free.segments[k], &free.segments[k + 1]);
            let (ea, sb) = (a.sample(a.duration()), b.sample(0.0));
            assert!((ea.q - w[k + 1]).norm() < 1e-9 && (sb.q - w[k + 1]).norm() < 1e-9);
            let v = free.velocities[k];
            assert!(v.norm() > 0.1, "{v:?}");
            assert!((ea.dq - v).norm() < 1e-9 && (sb.dq - v).norm() < 1e-9);
            assert!(ea.ddq.norm() < 1e-6 && sb.ddq.norm() < 1e-6);
        }
        let (first, last) = (&free.segments[0], &free.segments[2]);
        assert!(first.sample(0.0).dq.norm() < 1e-12);
        assert!(last.sample(last.duration()).dq.norm() < 1e-12);
        let sum: f64 = free.segments.iter().map(BSplineTrajectory::duration).sum();
        assert!((sum - free.duration).abs() < 1e-9 * sum);
    }

    #[test]
    fn derived_points_have_exact_gradients() {
        let prob = Problem::new(&[9, 8]);
        let ctrl: Vec<Vec<Joints>> = [9, 8]
            .iter()
            .map(|&n| {
                (0..n)
                    .map(|i| Joints::from_fn(|d, _| ((i * 3 + d) as f64).sin()))
                    .collect()
            })
            .collect();
        let spans = vec![
            vec![0.2, 0.3, 0.25, 0.4, 0.15, 0.35],
            vec![0.3, 0.2, 0.45, 0.1, 0.25],
        ];
        let vel = vec![Joints::new(0.4, -0.3, 0.2, 0.5, -0.1)];
        let h = 1e-7;
        for (k, seg) in prob.segs.iter().enumerate() {
            let base = prob.derivative_points(seg, &ctrl[k], &spans[k], &vel, 3);
            for var in 0..prob.n_vars {
                let (mut c2, mut s2, mut v2) = (ctrl.clone(), spans.clone(), vel.clone());
                if var >= prob.v_off {
                    v2[(var - prob.v_off) / 5][(var - prob.v_off) % 5] += h;
                } else if let Some((kk, sg)) = prob
                    .segs
                    .iter()
                    .enumerate()
                    .find(|(_, sg)| var >= sg.p_off && var < sg.s_off + sg.n - 3)
                {
                    if var < sg.s_off {
                        let i = 3 + (var - sg.p_off) / 5;
                        c2[kk][i][(var - sg.p_off) % 5] += h;
                    } else {
                        s2[kk][var - sg.s_off] += h;
                    }
                }
                let pert = prob.derivative_points(seg, &c2[k], &s2[k], &v2, 3);
                for kind in 0..3 {
                    for (p0, p1) in base[kind].iter().zip(&pert[kind]) {
                        let g: f64 = p0.g.iter().filter(|(i, _)| *i == var).map(|(_, x)| x).sum();
                        let fd = (p1.v - p0.v) / h;
                        assert!(
                            (g - fd).abs() < 1e-4 * (1.0 + fd.abs()),
                            "segment {k} var {var} kind {kind}: {g} vs {fd}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn paths_that_do_not_join_are_refused() {
        let (ws, dy) = free_space();
        let (_, mut paths) = collinear();
        paths[1][0][0] += 1e-3;
        let e = optimize_waypoints(
            &ws,
            &dy,
            &paths,
            &Limits::default(),
            &OptimizeConfig::default(),
            true,
        )
        .unwrap_err();
        assert!(e.to_string().contains("segment 0 ends"), "{e}");
    }
}
