//! The sequential convex method for eq. (2.16).
//!
//! Unknowns: the free control points `P_4..P_{n−3}` (the first and last three are the start and
//! goal, which clamps the end velocity and acceleration to zero, eq. 2.15) and the `n − 3`
//! knot increments `Δt_j > 0` of the non-empty spans (the seed's zero increments of eq. 2.16 are
//! not variables). Objective: `T = Σ Δt_j`.
//!
//! Each iteration linearises, with exact sparse gradients, the velocity, acceleration and jerk
//! control points of eq. (2.12) (`V_i = 3 ΔP_i / (t_{i+4} − t_{i+1})`, …, each a rational
//! function of a few `P` and `Δt`) against their limits (the convex-hull bound), and the clearance
//! `d(q(t))` at four points per span (gradient `N_i(t) ∇d(q)` in the control points, the
//! basis values held at the span fractions), and solves the QP
//! `min Σ Δt + μ/2 ‖step‖²` within a trust region with clarabel. The new point is then made
//! exactly feasible by uniform time scaling, which leaves the geometric path (hence the
//! clearance) unchanged and divides velocity, acceleration, jerk and the inertial torque by
//! `λ, λ², λ³, λ²`: the smallest `λ` that satisfies every limit (torques sampled 8 times per
//! knot span). The step is accepted when the scaled duration decreases and the clearance is
//! certified at least `d_safe` on the whole curve (conservative advancement,
//! [`clearance_certified`]); otherwise the trust region shrinks. Torque limits thus enter
//! through the scaling, not the QP. The last iterate is rescaled with the torques sampled every
//! 1 ms and verified at 1 ms ([`verify`]); if that fails, the initial trajectory (built with the
//! 1 ms checks) is returned instead.

// Control points, spans and basis values are indexed together by the same span and joint
// indices, as in eqs. (2.12)–(2.14); index loops read closer to the equations than zips.
#![allow(clippy::needless_range_loop)]

use std::time::Instant;

use autoteach_geometry::plan::PlanError;
use autoteach_geometry::plan::bspline::{BSplineTrajectory, fit_path};
use autoteach_geometry::plan::dynamics::Dynamics;
use autoteach_geometry::plan::limits::{Limits, Verification, per_joint_bound, verify};
use autoteach_geometry::plan::workspace::PlanWorkspace;
use autoteach_geometry::robot::Joints;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

/// Settings of [`optimize_trajectory`].
#[derive(Debug, Clone, PartialEq)]
pub struct OptimizeConfig {
    /// Number of control points `n` (0: chosen from the path length, 10 to 30).
    pub n_ctrl: usize,
    /// Sequential-convex iterations.
    pub max_iterations: usize,
    /// Initial trust radius on the control points (rad; the lift uses a fifth of it in m).
    pub trust_radius: f64,
    /// Clearance samples are linearised where `d < d_safe + activation` (m).
    pub activation: f64,
    /// Metric weights used to resample the path (as in the planners).
    pub weights: Joints,
    /// Sampling step of the clearance and torque checks (s).
    pub check_dt: f64,
}

impl Default for OptimizeConfig {
    fn default() -> Self {
        Self {
            n_ctrl: 0,
            max_iterations: 40,
            trust_radius: 0.2,
            activation: 0.05,
            weights: Joints::new(1.0, 1.0, 1.0, 1.0, 5.0),
            check_dt: 1e-3,
        }
    }
}

/// Bytes of the trajectory QP per control point, at least: 30 limit rows (3 derivative orders ×
/// 5 joints × 2 signs), each with two (index, value) entries, its bound and its vector header.
const QP_BYTES_PER_CONTROL_POINT: usize = 30
    * (2 * std::mem::size_of::<(usize, f64)>()
        + std::mem::size_of::<f64>()
        + std::mem::size_of::<Vec<(usize, f64)>>());

/// The optimised trajectory and its figures.
#[derive(Debug, Clone, PartialEq)]
pub struct OptimizeResult {
    /// The trajectory.
    pub trajectory: BSplineTrajectory,
    /// Its duration (s).
    pub duration: f64,
    /// Duration of the fitted initial trajectory, scaled to the limits (s).
    pub initial_duration: f64,
    /// Per-joint lower bound: the slowest joint's time-optimal jerk-limited move (s).
    pub lower_bound: f64,
    /// The joint that sets the lower bound.
    pub bound_joint: usize,
    /// `duration / lower_bound − 1`.
    pub gap: f64,
    /// Constraints within 0.1 % of their limit (for example `"jerk joint 1"`, `"clearance"`).
    pub active: Vec<String>,
    /// Sequential-convex iterations run.
    pub iterations: usize,
    /// Accepted steps.
    pub accepted: usize,
    /// Seconds spent.
    pub time_s: f64,
    /// Dense 1 ms verification of the returned trajectory.
    pub verification: Verification,
}

/// A value with its sparse gradient in the optimisation variables (exact forward mode).
#[derive(Debug, Clone)]
pub(super) struct Lin {
    pub(super) v: f64,
    pub(super) g: Vec<(usize, f64)>,
}

impl Lin {
    pub(super) fn sub(&self, o: &Lin) -> Lin {
        let mut g = self.g.clone();
        g.extend(o.g.iter().map(|(i, x)| (*i, -x)));
        Lin { v: self.v - o.v, g }
    }
    pub(super) fn scale(&self, s: f64) -> Lin {
        Lin {
            v: self.v * s,
            g: self.g.iter().map(|(i, x)| (*i, x * s)).collect(),
        }
    }
    /// `self / den`.
    pub(super) fn div(&self, den: &Lin) -> Lin {
        let v = self.v / den.v;
        let mut g: Vec<(usize, f64)> = self.g.iter().map(|(i, x)| (*i, x / den.v)).collect();
        g.extend(den.g.iter().map(|(i, x)| (*i, -v * x / den.v)));
        Lin { v, g }
    }
}

/// Variable layout: free control points then span durations.
struct Layout {
    n: usize,
}

impl Layout {
    fn n_p(&self) -> usize {
        5 * (self.n - 6)
    }
    fn n_vars(&self) -> usize {
        self.n_p() + self.n - 3
    }
    fn p_var(&self, i: usize, d: usize) -> Option<usize> {
        (i >= 3 && i + 3 < self.n).then(|| (i - 3) * 5 + d)
    }
    fn span_var(&self, j: usize) -> usize {
        self.n_p() + j
    }
    /// `t_b − t_a` (0-based knots) as the sum of the spans between them.
    fn den(&self, a: usize, b: usize, spans: &[f64]) -> Lin {
        let c = |m: usize| m.saturating_sub(3).min(self.n - 3);
        let (ca, cb) = (c(a), c(b));
        Lin {
            v: spans[ca..cb].iter().sum(),
            g: (ca..cb).map(|j| (self.span_var(j), 1.0)).collect(),
        }
    }
    fn p(&self, ctrl: &[Joints], i: usize, d: usize) -> Lin {
        Lin {
            v: ctrl[i][d],
            g: self.p_var(i, d).map(|k| vec![(k, 1.0)]).unwrap_or_default(),
        }
    }
}

/// The derivative control points `V, A, R` of eq. (2.12) for joint `d`, with gradients.
fn derivative_points(lay: &Layout, ctrl: &[Joints], spans: &[f64], d: usize) -> [Vec<Lin>; 3] {
    let n = lay.n;
    let v: Vec<Lin> = (0..n - 1)
        .map(|i| {
            lay.p(ctrl, i + 1, d)
                .sub(&lay.p(ctrl, i, d))
                .scale(3.0)
                .div(&lay.den(i + 1, i + 4, spans))
        })
        .collect();
    let a: Vec<Lin> = (0..n - 2)
        .map(|i| {
            v[i + 1]
                .sub(&v[i])
                .scale(2.0)
                .div(&lay.den(i + 2, i + 4, spans))
        })
        .collect();
    let r: Vec<Lin> = (0..n - 3)
        .map(|i| a[i + 1].sub(&a[i]).div(&lay.den(i + 3, i + 4, spans)))
        .collect();
    [v, a, r]
}

/// Cubic B-spline basis values at `t`: the span index `s` and `N_{s−3..s}` (NURBS book A2.2).
pub(super) fn basis(knots: &[f64], n: usize, t: f64) -> (usize, [f64; 4]) {
    let mut s = 3;
    while s + 1 < n && knots[s + 1] <= t {
        s += 1;
    }
    let mut nb = [1.0, 0.0, 0.0, 0.0];
    let mut left = [0.0; 4];
    let mut right = [0.0; 4];
    for j in 1..=3 {
        left[j] = t - knots[s + 1 - j];
        right[j] = knots[s + j] - t;
        let mut saved = 0.0;
        for r in 0..j {
            let den = right[r + 1] + left[j - r];
            let tmp = if den > 0.0 { nb[r] / den } else { 0.0 };
            nb[r] = saved + right[r + 1] * tmp;
            saved = left[j - r] * tmp;
        }
        nb[j] = saved;
    }
    (s, nb)
}

/// The smallest time stretch `λ ≥ 1` that satisfies every kinematic limit (convex hull) and the
/// torque limits (sampled every `dt`).
pub(super) fn required_stretch(
    traj: &BSplineTrajectory,
    limits: &Limits,
    dynamics: &Dynamics,
    dt: f64,
) -> Result<f64, PlanError> {
    required_stretch_at(traj, limits, dynamics, traj.check_times(dt))
}

/// [`required_stretch`] with the torques sampled at `times`.
fn required_stretch_at(
    traj: &BSplineTrajectory,
    limits: &Limits,
    dynamics: &Dynamics,
    times: impl Iterator<Item = f64>,
) -> Result<f64, PlanError> {
    let (vb, ab, jb) = (
        traj.velocity.hull_bounds(),
        traj.acceleration.hull_bounds(),
        traj.jerk.hull_bounds(),
    );
    let mut lam: f64 = 0.0;
    for i in 0..5 {
        lam = lam
            .max(vb[i] / limits.velocity[i])
            .max((ab[i] / limits.acceleration[i]).sqrt())
            .max((jb[i] / limits.jerk[i]).cbrt());
    }
    for t in times {
        let s = traj.sample(t);
        let (inertial, stat) = dynamics.split(&s.q, &s.dq, &s.ddq);
        for i in 0..5 {
            let room = limits.torque[i] - stat[i].abs();
            if room <= 0.0 {
                return Err(PlanError::Infeasible {
                    constraint: format!("torque joint {i}"),
                    reason: format!(
                        "the static load {:.3} exceeds the limit {}",
                        stat[i], limits.torque[i]
                    ),
                });
            }
            // τ(λ) = stat + inertial / λ²; bound |stat| + |inertial|/λ² ≤ τ_max.
            lam = lam.max((inertial[i].abs() / room).sqrt());
        }
    }
    // A hair above the requirement so rounding cannot cross a limit.
    Ok(lam.max(1e-12) * (1.0 + 1e-12))
}

fn stretched(
    ctrl: &[Joints],
    spans: &[f64],
    lam: f64,
) -> Result<(Vec<f64>, BSplineTrajectory), PlanError> {
    let s: Vec<f64> = spans.iter().map(|d| d * lam).collect();
    let tr = BSplineTrajectory::from_spans(ctrl.to_vec(), &s)?;
    Ok((s, tr))
}

/// Where the torques are sampled: every `dt` seconds (the dense grid of [`verify`]), or at
/// `m` equally spaced times per knot span (and the end).
#[derive(Debug, Clone, Copy)]
enum TorqueGrid {
    Dense(f64),
    PerSpan(usize),
}

/// Torque samples per knot span inside the iteration; the returned trajectory is rescaled on the
/// dense grid.
const TORQUE_SAMPLES_PER_SPAN: usize = 8;

fn torque_times(tr: &BSplineTrajectory, grid: TorqueGrid) -> Vec<f64> {
    match grid {
        TorqueGrid::Dense(dt) => tr.check_times(dt).collect(),
        TorqueGrid::PerSpan(m) => {
            let k = tr.knots();
            let n_spans = tr.control_points().len() - 3;
            let mut out: Vec<f64> = (0..n_spans)
                .flat_map(|j| {
                    let (a, b) = (k[j + 3], k[j + 4]);
                    (0..m).map(move |i| a + (b - a) * i as f64 / m as f64)
                })
                .collect();
            out.push(tr.duration());
            out
        }
    }
}

/// Makes `(ctrl, spans)` exactly feasible by time scaling (module docs) with the torques sampled
/// on `grid`; returns the scaled spans and trajectory.
fn feasible(
    ctrl: &[Joints],
    spans: &[f64],
    limits: &Limits,
    dynamics: &Dynamics,
    grid: TorqueGrid,
) -> Result<(Vec<f64>, BSplineTrajectory), PlanError> {
    let tr = BSplineTrajectory::from_spans(ctrl.to_vec(), spans)?;
    let lam = required_stretch_at(&tr, limits, dynamics, torque_times(&tr, grid).into_iter())?;
    let (s, tr) = stretched(ctrl, spans, lam)?;
    confirmed(ctrl, s, tr, limits, dynamics, grid)
}

/// The torque check is sampled: confirms `tr` (spans `s`) on `grid`, stretching a little more
/// if a sample between the previous ones binds (`λ > 1`; scaling keeps the path).
fn confirmed(
    ctrl: &[Joints],
    s: Vec<f64>,
    tr: BSplineTrajectory,
    limits: &Limits,
    dynamics: &Dynamics,
    grid: TorqueGrid,
) -> Result<(Vec<f64>, BSplineTrajectory), PlanError> {
    let lam2 = required_stretch_at(&tr, limits, dynamics, torque_times(&tr, grid).into_iter())?;
    if lam2 > 1.0 {
        stretched(ctrl, &s, lam2)
    } else {
        Ok((s, tr))
    }
}

/// Certifies `d(q(t)) ≥ d_safe` on the whole of `[0, T]`, not only at samples, by conservative
/// advancement in time (the continuous check of `PlanWorkspace::segment_free`, applied to the
/// curve). On knot span `j` the velocity is in the convex hull of its three control points
/// `V_j..V_{j+2}` (eq. 2.12), so no robot point moves faster than
/// `L_j = Σ_i r_i max_k |V_{k,i}|` (`r_i` = [`PlanWorkspace::reach`]); the clearance is
/// 1-Lipschitz in point motion, so a clearance `d` at `t` holds `d_safe` on
/// `[t, t + (d − d_safe)/L_j]`.
///
/// Returns `Some(true)` when certified, `Some(false)` when a point below `d_safe` is found, and
/// `None` when more than `budget` clearance evaluations would be needed (a close approach).
pub(super) fn clearance_certified(
    ws: &PlanWorkspace,
    tr: &BSplineTrajectory,
    d_safe: f64,
    budget: usize,
) -> Result<Option<bool>, PlanError> {
    let reach = ws.reach();
    let knots = tr.knots();
    let ctrl = tr.control_points();
    let n = ctrl.len();
    let vel = &tr.velocity.ctrl;
    let mut evals = 0usize;
    for j in 0..n - 3 {
        let (a, b) = (knots[j + 3], knots[j + 4]);
        let speed: f64 = (0..5)
            .map(|i| reach[i] * (j..j + 3).map(|k| vel[k][i].abs()).fold(0.0, f64::max))
            .sum();
        if !speed.is_finite() {
            return Ok(None);
        }
        let mut t = a;
        loop {
            let (s, nb) = basis(knots, n, t);
            let q: Joints = (0..4).map(|k| ctrl[s - 3 + k] * nb[k]).sum();
            let d = ws.signed_distance(&q)?;
            evals += 1;
            if d < d_safe {
                return Ok(Some(false));
            }
            if speed <= 0.0 {
                break;
            }
            let step = (d - d_safe) / speed;
            if t + step >= b {
                break;
            }
            if evals >= budget {
                return Ok(None);
            }
            t += step;
        }
    }
    Ok(Some(true))
}

/// Whether the clearance keeps `d_safe`: certified continuously ([`clearance_certified`]), or,
/// for a close approach that the advancement cannot certify within the cost of the dense check,
/// sampled every `dt` as [`verify`] does.
fn keeps_clearance(
    ws: &PlanWorkspace,
    tr: &BSplineTrajectory,
    d_safe: f64,
    dt: f64,
) -> Result<bool, PlanError> {
    let budget = tr.check_times(dt).size_hint().0 / 2;
    match clearance_certified(ws, tr, d_safe, budget.max(1))? {
        Some(ok) => Ok(ok),
        None => Ok(min_clearance(ws, tr, dt)? >= d_safe),
    }
}

pub(super) fn min_clearance(
    ws: &PlanWorkspace,
    tr: &BSplineTrajectory,
    dt: f64,
) -> Result<f64, PlanError> {
    let mut m = f64::INFINITY;
    for t in tr.check_times(dt) {
        m = m.min(ws.signed_distance(&tr.sample(t).q)?);
    }
    Ok(m)
}

/// Optimises the shape and timing of a rest-to-rest trajectory along `path` (module docs).
///
/// Errors: malformed input, infeasible limits ([`PlanError::Infeasible`] naming the limit), a
/// path whose fitted spline does not keep `d_safe` even with 60 control points
/// ([`PlanError::Infeasible`] naming the clearance and the closest pair), or a QP failure.
pub fn optimize_trajectory(
    ws: &PlanWorkspace,
    dynamics: &Dynamics,
    path: &[Joints],
    limits: &Limits,
    cfg: &OptimizeConfig,
) -> Result<OptimizeResult, PlanError> {
    let t0 = Instant::now();
    limits.validate(dynamics)?;
    if path.len() < 2 || path.iter().any(|q| q.iter().any(|v| !v.is_finite())) {
        return Err(PlanError::InvalidInput {
            what: "path",
            reason: format!("{} way-points (need at least 2, all finite)", path.len()),
        });
    }
    ws.require_free("start", &path[0], limits.d_safe)?;
    ws.require_free("goal", &path[path.len() - 1], limits.d_safe)?;
    let dt = cfg.check_dt;
    let length: f64 = path
        .windows(2)
        .map(|w| (w[1] - w[0]).component_mul(&cfg.weights).norm())
        .sum();
    let mut n = if cfg.n_ctrl == 0 {
        (10 + (4.0 * length) as usize).min(30)
    } else {
        cfg.n_ctrl
    };
    if n < 7 {
        return Err(PlanError::InvalidInput {
            what: "number of control points",
            reason: format!("{n} (need at least 7)"),
        });
    }
    // The QP holds, per control point, at least the two-sided linearised limit rows of its
    // velocity, acceleration and jerk points on every joint (30 rows of ≥ 2 entries): a count
    // whose QP cannot fit in memory is refused up front, not aborted on deep in the solve.
    autoteach_geometry::alloc::ensure_within_physical_memory(
        "the trajectory QP of n_ctrl control points",
        n,
        QP_BYTES_PER_CONTROL_POINT,
    )?;
    // Initial trajectory: the path's control polygon, scaled to the limits; more control points
    // until it keeps the clearance.
    let (mut ctrl, mut spans, mut traj) = loop {
        let ctrl = fit_path(path, n, &cfg.weights)?;
        let (spans, tr) = feasible(
            &ctrl,
            &vec![0.1; n - 3],
            limits,
            dynamics,
            TorqueGrid::Dense(dt),
        )?;
        let c = min_clearance(ws, &tr, dt)?;
        if c >= limits.d_safe {
            break (ctrl, spans, tr);
        }
        if n >= 60 {
            return Err(PlanError::Infeasible {
                constraint: "clearance".into(),
                reason: format!(
                    "the spline fitted to the path comes within {c:.4} m of an obstacle (d_safe {}); plan the path with a larger margin",
                    limits.d_safe
                ),
            });
        }
        n = (2 * n).min(60);
    };
    let initial_duration = traj.duration();
    let initial = traj.clone();
    let lay = Layout { n };
    let mut radius = cfg.trust_radius;
    let mut iterations = 0;
    let mut accepted = 0;
    let mu = 1e-3;
    while iterations < cfg.max_iterations && radius > 1e-4 {
        iterations += 1;
        let nv = lay.n_vars();
        // The trust-region box `|x_k| ≤ w_k`. The span box shrinks with the radius: V, A, R
        // scale as 1/Δt, 1/Δt², 1/Δt³, so their linearisation only holds for small relative span
        // changes. (A fixed ±50 % box let the trust region collapse after a few steps, 0–3
        // accepted on the default transfers.)
        let frac = (0.5 * radius / cfg.trust_radius).min(0.5);
        let half_width: Vec<f64> = (0..nv)
            .map(|k| match k.checked_sub(lay.n_p()) {
                Some(j) => frac * spans[j],
                None if k % 5 == 4 => 0.2 * radius,
                None => radius,
            })
            .collect();
        // Rows of A x ≤ b with x the step.
        let mut rows: Vec<(Vec<(usize, f64)>, f64)> = Vec::new();
        for d in 0..5 {
            let [v, a, r] = derivative_points(&lay, &ctrl, &spans, d);
            for (pts, lim) in [
                (v, limits.velocity[d]),
                (a, limits.acceleration[d]),
                (r, limits.jerk[d]),
            ] {
                for p in pts {
                    if p.g.is_empty() {
                        continue;
                    }
                    let neg = p.g.iter().map(|(i, x)| (*i, -x)).collect();
                    rows.push((p.g, lim - p.v));
                    rows.push((neg, lim + p.v));
                }
            }
        }
        // Clearance at four points per span: d + ∇d·Σ N_i ΔP_i ≥ d_safe.
        let knots = traj.knots().to_vec();
        for j in 0..n - 3 {
            for f in [0.125, 0.375, 0.625, 0.875] {
                let t = knots[j + 3] + f * spans[j];
                let (s, nb) = basis(&knots, n, t);
                let q: Joints = (0..4).map(|k| ctrl[s - 3 + k] * nb[k]).sum();
                let dist = ws.signed_distance(&q)?;
                if dist >= limits.d_safe + cfg.activation {
                    continue;
                }
                let (_, grad) = ws.distance_gradient(&q)?;
                let mut g = Vec::new();
                for k in 0..4 {
                    for dd in 0..5 {
                        if let Some(var) = lay.p_var(s - 3 + k, dd) {
                            g.push((var, -nb[k] * grad[dd]));
                        }
                    }
                }
                if !g.is_empty() {
                    rows.push((g, dist - limits.d_safe));
                }
            }
        }
        // Trust region and positive spans.
        for (k, w) in half_width.iter().enumerate() {
            rows.push((vec![(k, 1.0)], *w));
            rows.push((vec![(k, -1.0)], *w));
        }
        let mut cost = vec![0.0; nv];
        for j in 0..n - 3 {
            cost[lay.span_var(j)] = 1.0;
        }
        let step = solve_qp(nv, &cost, &rows, mu)?;
        let Some(step) = step else {
            radius *= 0.5;
            continue;
        };
        let mut c2 = ctrl.clone();
        for i in 3..n - 3 {
            for d in 0..5 {
                if let Some(k) = lay.p_var(i, d) {
                    c2[i][d] += step[k];
                }
            }
        }
        let s2: Vec<f64> = (0..n - 3)
            .map(|j| (spans[j] + step[lay.span_var(j)]).max(1e-6 * spans[j]))
            .collect();
        let (s2, tr2) = feasible(
            &c2,
            &s2,
            limits,
            dynamics,
            TorqueGrid::PerSpan(TORQUE_SAMPLES_PER_SPAN),
        )?;
        let ok = tr2.duration() < traj.duration() * (1.0 - 1e-6)
            && keeps_clearance(ws, &tr2, limits.d_safe, dt)?;
        if ok {
            let gain = 1.0 - tr2.duration() / traj.duration();
            ctrl = c2;
            spans = s2;
            traj = tr2;
            accepted += 1;
            radius = (radius * 1.5).min(1.0);
            if gain < 1e-5 {
                break;
            }
        } else {
            radius *= 0.5;
        }
    }
    // The iterates' torques were sampled per span: rescale on the dense grid (`λ ≥ 1` only),
    // verify densely, and fall back to the initial trajectory (dense torque and clearance
    // checks) if the verification fails; never return an unverified trajectory.
    if accepted > 0 {
        traj = confirmed(&ctrl, spans, traj, limits, dynamics, TorqueGrid::Dense(dt))?.1;
    }
    let mut verification = verify(ws, dynamics, &traj, limits, 1e-3)?;
    if accepted > 0 && !verification.ok(1e-9, limits.d_safe) {
        traj = initial;
        verification = verify(ws, dynamics, &traj, limits, 1e-3)?;
    }
    if !verification.ok(1e-9, limits.d_safe) {
        return Err(PlanError::Infeasible {
            constraint: "dense verification".into(),
            reason: format!("the trajectory fails its 1 ms check: {verification:?}"),
        });
    }
    let (lower_bound, bound_joint) = per_joint_bound(&path[0], &path[path.len() - 1], limits);
    let duration = traj.duration();
    let mut active = Vec::new();
    let names = ["velocity", "acceleration", "jerk"];
    let hull = [
        traj.velocity.hull_bounds(),
        traj.acceleration.hull_bounds(),
        traj.jerk.hull_bounds(),
    ];
    let lims = [limits.velocity, limits.acceleration, limits.jerk];
    for k in 0..3 {
        for i in 0..5 {
            if hull[k][i] >= 0.999 * lims[k][i] {
                active.push(format!("{} joint {i}", names[k]));
            }
        }
    }
    if verification.torque_ratio >= 0.999 {
        active.push("torque".into());
    }
    if verification.min_clearance < limits.d_safe + 1e-3 {
        active.push("clearance".into());
    }
    Ok(OptimizeResult {
        trajectory: traj,
        duration,
        initial_duration,
        lower_bound,
        bound_joint,
        gap: if lower_bound > 0.0 {
            duration / lower_bound - 1.0
        } else {
            0.0
        },
        active,
        iterations,
        accepted,
        time_s: t0.elapsed().as_secs_f64(),
        verification,
    })
}

/// `min cost·x + μ/2 ‖x‖²` (the cost is 1 on the span steps: `Σ Δt_j`) subject to the rows;
/// `None` if clarabel reports infeasibility.
pub(super) fn solve_qp(
    nv: usize,
    cost: &[f64],
    rows: &[(Vec<(usize, f64)>, f64)],
    mu: f64,
) -> Result<Option<Vec<f64>>, PlanError> {
    let p = CscMatrix::new(nv, nv, (0..=nv).collect(), (0..nv).collect(), vec![mu; nv]);
    let q = cost.to_vec();
    // Build A in CSC from the rows (duplicates summed).
    let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); nv];
    let mut b = Vec::with_capacity(rows.len());
    for (r, (g, rhs)) in rows.iter().enumerate() {
        for &(k, x) in g {
            match cols[k].last_mut() {
                Some((rr, v)) if *rr == r => *v += x,
                _ => cols[k].push((r, x)),
            }
        }
        b.push(*rhs);
    }
    let mut colptr = vec![0usize];
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    for c in &cols {
        for &(r, x) in c {
            rowval.push(r);
            nzval.push(x);
        }
        colptr.push(rowval.len());
    }
    let a = CscMatrix::new(rows.len(), nv, colptr, rowval, nzval);
    let cones = [SupportedConeT::NonnegativeConeT(b.len())];
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(100)
        .build()
        .map_err(|e| PlanError::InvalidInput {
            what: "QP settings",
            reason: format!("{e:?}"),
        })?;
    let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings).map_err(|e| {
        PlanError::InvalidInput {
            what: "QP",
            reason: format!("clarabel setup: {e:?}"),
        }
    })?;
    solver.solve();
    Ok(match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Some(solver.solution.x.clone()),
        _ => None,
    })
}

#[cfg(test)]
pub(in crate::plan) mod tests {
    use super::*;
    use autoteach_geometry::collision::LinkDims;
    use autoteach_geometry::plan::dynamics::DynamicsParams;
    use autoteach_geometry::plan::workspace::{default_limits, default_scene};
    use autoteach_geometry::robot::WaferRobot;

    #[test]
    fn gradients_of_derivative_points_match_finite_differences() {
        let n = 9;
        let lay = Layout { n };
        let ctrl: Vec<Joints> = (0..n)
            .map(|i| Joints::from_fn(|d, _| ((i * 3 + d) as f64).sin()))
            .collect();
        let spans = vec![0.2, 0.3, 0.25, 0.4, 0.15, 0.35];
        let base = derivative_points(&lay, &ctrl, &spans, 2);
        let h = 1e-7;
        for var in 0..lay.n_vars() {
            let (mut c2, mut s2) = (ctrl.clone(), spans.clone());
            if var < lay.n_p() {
                c2[3 + var / 5][var % 5] += h;
            } else {
                s2[var - lay.n_p()] += h;
            }
            let pert = derivative_points(&lay, &c2, &s2, 2);
            for k in 0..3 {
                for (p0, p1) in base[k].iter().zip(&pert[k]) {
                    let g: f64 = p0.g.iter().filter(|(i, _)| *i == var).map(|(_, x)| x).sum();
                    let fd = (p1.v - p0.v) / h;
                    assert!(
                        (g - fd).abs() < 1e-4 * (1.0 + fd.abs()),
                        "var {var} kind {k}: {g} vs {fd}"
                    );
                }
            }
        }
        // And the values equal the B-spline's own derivative control points.
        let tr = BSplineTrajectory::from_spans(ctrl, &spans).unwrap();
        for (i, p) in base[2].iter().enumerate() {
            assert!((p.v - tr.jerk.ctrl[i][2]).abs() < 1e-9);
        }
    }

    #[test]
    fn basis_reproduces_the_spline() {
        let ctrl: Vec<Joints> = (0..9)
            .map(|i| Joints::from_fn(|d, _| ((i + 2 * d) as f64).cos()))
            .collect();
        let tr = BSplineTrajectory::from_spans(ctrl.clone(), &[0.2, 0.3, 0.25, 0.4, 0.15, 0.35])
            .unwrap();
        for k in 0..=50 {
            let t = tr.duration() * k as f64 / 50.0;
            let (s, nb) = basis(tr.knots(), 9, t);
            let q: Joints = (0..4).map(|j| ctrl[s - 3 + j] * nb[j]).sum();
            assert!((q - tr.sample(t).q).norm() < 1e-12);
        }
    }

    /// The continuous certificate never accepts a trajectory that dense sampling rejects: random
    /// splines between the default scene's poses (through a perturbed mid-point, random spans),
    /// with `d_safe` just above, just below and well below each one's own minimum clearance
    /// (sampled every 0.2 ms), and the default 10 mm.
    #[test]
    fn certified_clearance_never_accepts_what_dense_sampling_rejects() {
        use rand::{Rng, SeedableRng};
        let (ws, poses) = default_scene().unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(30);
        let weights = OptimizeConfig::default().weights;
        let (mut certified, mut refused) = (0, 0);
        for _ in 0..12 {
            let a = poses[rng.random_range(0..poses.len())].q;
            let b = poses[rng.random_range(0..poses.len())].q;
            let mut mid = (a + b) * 0.5;
            for d in 0..4 {
                mid[d] += rng.random_range(-0.4..0.4);
            }
            let ctrl = fit_path(&[a, mid, b], 12, &weights).unwrap();
            let spans: Vec<f64> = (0..9).map(|_| rng.random_range(0.03..0.15)).collect();
            let tr = BSplineTrajectory::from_spans(ctrl, &spans).unwrap();
            let fine = min_clearance(&ws, &tr, 2e-4).unwrap();
            for d_safe in [fine + 1e-4, fine - 1e-3, fine - 2e-2, 0.01] {
                if d_safe < 0.0 {
                    continue;
                }
                let cert = clearance_certified(&ws, &tr, d_safe, 20_000).unwrap();
                let accepted = keeps_clearance(&ws, &tr, d_safe, 1e-3).unwrap();
                if cert == Some(true) || accepted {
                    certified += 1;
                    assert!(fine >= d_safe, "accepted {d_safe} with samples at {fine}");
                    let v = min_clearance(&ws, &tr, 1e-3).unwrap();
                    assert!(v >= d_safe, "accepted {d_safe}, 1 ms check {v}");
                } else {
                    refused += 1;
                }
            }
        }
        assert!(certified > 0 && refused > 0, "{certified} {refused}");
    }

    /// The robot alone (no obstacles, no wafer) with its default masses: the tests' free space.
    pub(in crate::plan) fn free_space() -> (PlanWorkspace, Dynamics) {
        let (lo, hi) = default_limits();
        let ws = PlanWorkspace::new(
            WaferRobot::default(),
            LinkDims::default(),
            None,
            lo,
            hi,
            vec![],
        )
        .unwrap();
        let dy = Dynamics::new(&ws.robot.params, &DynamicsParams::default(), None);
        (ws, dy)
    }

    #[test]
    fn free_space_move_approaches_the_per_joint_bound_and_verifies() {
        let (ws, dy) = free_space();
        let limits = Limits::default();
        let path = vec![
            Joints::new(0.0, 0.5, 0.0, 0.0, 0.1),
            Joints::new(1.5, 0.2, -0.3, 0.4, 0.15),
        ];
        let r = optimize_trajectory(&ws, &dy, &path, &limits, &OptimizeConfig::default()).unwrap();
        assert!(
            r.verification.ok(1e-9, limits.d_safe),
            "{:?}",
            r.verification
        );
        assert!(r.duration >= r.lower_bound * (1.0 - 1e-9));
        assert!(r.duration < r.initial_duration);
        let s = r.trajectory.sample(r.duration);
        assert!((s.q - path[1]).norm() < 1e-12 && s.dq.norm() < 1e-9);
    }

    #[test]
    fn default_scene_transfer_keeps_clearance_and_limits() {
        let (ws, poses) = default_scene().unwrap();
        let dy = Dynamics::new(
            &ws.robot.params,
            &DynamicsParams::default(),
            ws.wafer.as_ref(),
        );
        let limits = Limits::default();
        let cfg = autoteach_geometry::plan::rrt_star::RrtStarConfig {
            margin: 0.02,
            ..Default::default()
        };
        let p = autoteach_geometry::plan::rrt_star::rrt_star(&ws, &poses[0].q, &poses[3].q, &cfg)
            .unwrap();
        let r = optimize_trajectory(
            &ws,
            &dy,
            &p.result.path,
            &limits,
            &OptimizeConfig::default(),
        )
        .unwrap();
        // Independent dense check at 1 ms with parry.
        let v = verify(&ws, &dy, &r.trajectory, &limits, 1e-3).unwrap();
        assert!(v.ok(1e-9, limits.d_safe), "{v:?}");
        assert!(r.duration <= r.initial_duration);
    }

    #[test]
    fn a_vanishing_jerk_limit_ends_in_bounded_time() {
        // A jerk limit of 1e-300 rad/s³ stretches the move to ~1e99 s: the checks sample the
        // knot spans, not every millisecond of that, so the call returns (in well under a second
        // here) with a finite trajectory that meets the limit.
        let (ws, poses) = default_scene().unwrap();
        let dy = Dynamics::new(
            &ws.robot.params,
            &DynamicsParams::default(),
            ws.wafer.as_ref(),
        );
        let limits = Limits {
            jerk: Joints::repeat(1e-300),
            ..Limits::default()
        };
        let mut q1 = poses[0].q;
        q1[0] += 0.2;
        let t0 = std::time::Instant::now();
        let cfg = OptimizeConfig {
            max_iterations: 10,
            ..OptimizeConfig::default()
        };
        match optimize_trajectory(&ws, &dy, &[poses[0].q, q1], &limits, &cfg) {
            Ok(r) => {
                assert!(
                    r.duration.is_finite() && r.duration > 1e90,
                    "{}",
                    r.duration
                );
                assert!(r.verification.samples <= 1000 * r.trajectory.control_points().len());
            }
            Err(e) => assert!(matches!(e, PlanError::Infeasible { .. }), "{e}"),
        }
        assert!(t0.elapsed().as_secs_f64() < 30.0);
    }

    #[test]
    fn a_control_point_count_beyond_memory_is_refused_not_aborted() {
        let (ws, poses) = default_scene().unwrap();
        let dy = Dynamics::new(
            &ws.robot.params,
            &DynamicsParams::default(),
            ws.wafer.as_ref(),
        );
        let mut q1 = poses[0].q;
        q1[0] += 0.2;
        for n_ctrl in [1usize << 31, 1 << 62, usize::MAX] {
            let cfg = OptimizeConfig {
                n_ctrl,
                ..OptimizeConfig::default()
            };
            let e = optimize_trajectory(&ws, &dy, &[poses[0].q, q1], &Limits::default(), &cfg)
                .unwrap_err();
            assert!(
                matches!(
                    e,
                    PlanError::Geometry(autoteach_geometry::GeometryError::OutOfMemory { .. })
                ),
                "{e}"
            );
        }
    }

    #[test]
    fn infeasible_limits_name_the_constraint() {
        let (ws, poses) = default_scene().unwrap();
        let dy = Dynamics::new(
            &ws.robot.params,
            &DynamicsParams::default(),
            ws.wafer.as_ref(),
        );
        let cases = [
            (
                Limits {
                    torque: Joints::new(200.0, 100.0, 20.0, 20.0, 100.0),
                    ..Limits::default()
                },
                "torque joint 4",
            ),
            (
                Limits {
                    jerk: Joints::new(100.0, 0.0, 1.0, 1.0, 1.0),
                    ..Limits::default()
                },
                "jerk limit of joint 1",
            ),
        ];
        for (limits, named) in cases {
            let e = optimize_trajectory(
                &ws,
                &dy,
                &[poses[0].q, poses[3].q],
                &limits,
                &OptimizeConfig::default(),
            )
            .unwrap_err();
            assert!(e.to_string().contains(named), "{e}");
        }
    }
}
