"""Table 2.1 of seed 000 on the default scene, with ruckig, toppra and OMPL beside it (issue 30).

Run: ``RAYON_NUM_THREADS=1 PYTHONPATH=python /work/venv/bin/python benchmarks/motion.py``
(peers: ``pip install 'autoteach[bench]'``; a missing peer's rows are skipped with a note).

1. Table 2.1: for each transfer (RRT* path, margin 20 mm; d_safe 10 mm) the planning time, the
   optimisation time, the number of control points, the trajectory time and the per-joint lower
   bound, then ruckig's time-optimal jerk-limited rest-to-rest move of every joint under the same
   v/a/j limits (no obstacles). ruckig's maximum over the joints must equal our bound. Run with
   the default 40 iterations and to convergence (300 allowed).
2. toppra on the same paths (the five RRT* paths and the 5-joint 5° A* paths that finish within a
   second): its strongest configuration is a cubic spline through the way-points (chord-length
   parameter; the best of not-a-knot, natural and clamped ends), the same velocity and
   acceleration limits with the interpolation discretisation, 2000 grid points and the
   constant-acceleration parametrizer. toppra knows no jerk or torque limit, so the per-joint
   jerk-limited bound over toppra's time is the smallest ratio any trajectory meeting our limits
   can reach; the goal ``ours ≤ 0.8 × toppra`` cannot be met where that floor exceeds 0.8.
   The last column is the clearance of toppra's spline (sampled at 2000 points): the spline
   leaves the certified straight segments, so it is not guaranteed collision-free.
3. OMPL's RRTstar in the same joint space (the lift scaled by the planners' weight 5, so its path
   length is our cost), with our clearance ``≥ margin`` as its validity checker, range 0.5 (our
   step), goal bias 0.1 and motions checked every 0.01 (weighted rad). Time to the first solution
   (intermediate-solution callback) and the cost after 1 s, raw and after OMPL's path simplifier;
   ours with a 1 s budget (tree cost, and after our shortcutting), and our seconds per collision
   check (the whole search time over the number of checks: an upper bound).
4. Table 2.2: carrier A → home → a folded pose turned towards carrier B → carrier B (RRT* paths
   of the three segments), optimised with zero and with free way-point velocities, the same
   iterations (300 allowed; the joint problem stops when a step gains < 1e-5).
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

import numpy as np

from autoteach import plan
from autoteach.commands.plan import TRANSFERS

WEIGHTS = np.array([1.0, 1.0, 1.0, 1.0, 5.0])
TOPPRA_GRID = 2000
_OMPL_SEEDED: list[bool] = []


def ruckig_bound(q0: np.ndarray, q1: np.ndarray, lim: plan.Limits) -> float | None:
    """ruckig's time-optimal synchronised duration for the move (None if ruckig is missing)."""
    try:
        from ruckig import InputParameter, Result, Ruckig, Trajectory
    except ImportError:
        return None
    inp = InputParameter(5)
    inp.current_position = list(q0)
    inp.target_position = list(q1)
    inp.max_velocity = list(lim.velocity)
    inp.max_acceleration = list(lim.acceleration)
    inp.max_jerk = list(lim.jerk)
    traj = Trajectory(5)
    if Ruckig(5).calculate(inp, traj) not in (Result.Working, Result.Finished):
        return None
    return float(traj.duration)


def toppra_time(ws: plan.Workspace, path: np.ndarray, lim: plan.Limits) -> tuple[float, str, float] | None:
    """toppra's duration on a spline through ``path`` (strongest of three end conditions).

    Returns ``(duration, end condition, min clearance of that spline)``; None without toppra.
    """
    try:
        import toppra as ta
        import toppra.algorithm as talgo
        import toppra.constraint as tcon
    except ImportError:
        return None
    import logging

    logging.getLogger("toppra").setLevel(logging.ERROR)
    p = np.asarray(path)
    keep = [0]
    for i in range(1, len(p)):
        if np.linalg.norm(p[i] - p[keep[-1]]) > 1e-9:
            keep.append(i)
    p = p[keep]
    ss = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    v, a = np.asarray(lim.velocity), np.asarray(lim.acceleration)
    best: tuple[float, str, Any] | None = None
    for bc in ("not-a-knot", "natural", "clamped"):
        spline = ta.SplineInterpolator(ss, p, bc_type=bc)
        cons = [
            tcon.JointVelocityConstraint(np.stack([-v, v], axis=1)),
            tcon.JointAccelerationConstraint(
                np.stack([-a, a], axis=1), discretization_scheme=tcon.DiscretizationType.Interpolation
            ),
        ]
        grid = np.linspace(0.0, ss[-1], TOPPRA_GRID)
        algo = talgo.TOPPRA(cons, spline, gridpoints=grid, parametrizer="ParametrizeConstAccel")
        jt = algo.compute_trajectory(0.0, 0.0)
        if jt is not None and (best is None or jt.duration < best[0]):
            best = (float(jt.duration), bc, spline)
    if best is None:
        return None
    qs = best[2](np.linspace(0.0, ss[-1], 2000))
    cl = min(c[0] for c in (plan.clearance(ws, q) for q in qs) if c is not None)
    return best[0], best[1], float(cl)


def ompl_rrt_star(ws: plan.Workspace, q0: np.ndarray, q1: np.ndarray, margin: float, seconds: float) -> Any:
    """OMPL RRTstar with our clearance as validity checker: (first-solution s, cost, simplified cost, checks)."""
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except ImportError:
        return None
    ou.setLogLevel(ou.LogLevel.LOG_WARN)
    if not _OMPL_SEEDED:  # OMPL takes its seed once per process, before any sampling
        ou.RNG.setSeed(7)
        _OMPL_SEEDED.append(True)
    lo, hi = ws.joint_limits()
    space = ob.RealVectorStateSpace(5)
    bounds = ob.RealVectorBounds(5)
    for i in range(5):
        bounds.setLow(i, float(lo[i] * WEIGHTS[i]))
        bounds.setHigh(i, float(hi[i] * WEIGHTS[i]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    checks = [0]

    def valid(s: Any) -> bool:
        checks[0] += 1
        c = plan.clearance(ws, np.array([s[i] for i in range(5)]) / WEIGHTS)
        return c is None or c[0] >= margin

    setup.setStateValidityChecker(valid)
    si = setup.getSpaceInformation()
    si.setStateValidityCheckingResolution(0.01 / space.getMaximumExtent())
    planner = og.RRTstar(si)
    planner.setRange(0.5)
    planner.setGoalBias(0.1)
    setup.setPlanner(planner)
    setup.setOptimizationObjective(ob.PathLengthOptimizationObjective(si))

    def state(q: np.ndarray) -> Any:
        s = space.allocState()
        for i in range(5):
            s[i] = float(q[i] * WEIGHTS[i])
        return s

    setup.setStartAndGoalStates(state(q0), state(q1), 1e-6)
    # Time to the first solution: a run that stops once RRTstar's best cost is finite; then a
    # fresh run (same seed) for the cost after the budget.
    t0 = time.perf_counter()
    setup.solve(
        ob.plannerOrTerminationCondition(
            ob.timedPlannerTerminationCondition(seconds),
            ob.PlannerTerminationCondition(lambda: math.isfinite(planner.bestCost().value())),
        )
    )
    first = time.perf_counter() - t0 if setup.getProblemDefinition().hasExactSolution() else None
    setup.clear()
    checks[0] = 0
    setup.solve(seconds)
    if not setup.getProblemDefinition().hasExactSolution():
        return (None, None, None, checks[0])
    raw = setup.getSolutionPath().length()
    setup.simplifySolution()
    return (first, raw, setup.getSolutionPath().length(), checks[0])


def main() -> None:
    """Print Table 2.1 with ruckig's bound, then the toppra and OMPL comparisons."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ompl-seconds", type=float, default=1.0, help="RRTstar budget of both planners (s)")
    args = ap.parse_args()
    ws, poses = plan.default_scene()
    lim = plan.Limits()
    print("Table 2.1 (RRT* paths)")
    print(
        "name    plan(s)  opt(s)  ctrl   T(s)  bound(s)  ruckig(s)  gap   min clearance(m)  "
        "| 300 it: opt(s) T(s) gap  active"
    )
    runs = []
    for name, a, b in TRANSFERS:
        t0 = time.perf_counter()
        p = plan.plan_path(ws, poses[a], poses[b], method="rrt*", margin=0.02)
        t1 = time.perf_counter()
        r = plan.optimize_trajectory(ws, p.path, lim)
        t2 = time.perf_counter()
        runs.append((name + " rrt*", p.path, r))
        rc = plan.optimize_trajectory(ws, p.path, lim, max_iterations=300)
        rb = ruckig_bound(poses[a], poses[b], lim)
        rb_s = f"{rb:9.4f}" if rb is not None else "      n/a"
        print(
            f"{name:<7}{t1 - t0:8.3f}{t2 - t1:8.3f}{len(r.trajectory.control_points):6d}{r.duration:7.3f}"
            f"{r.lower_bound:10.4f}{rb_s}{r.gap:6.3f}{r.verification.min_clearance:12.4f}      |"
            f"{rc.time_s:8.3f}{rc.duration:7.4f}{rc.gap:7.4f}  {', '.join(rc.active)}"
        )
    for name, a, b in (("traj03", "home", "chamber"), ("traj13", "carrier_a", "chamber")):
        p = plan.plan_path(ws, poses[a], poses[b], method="a*", margin=0.02)
        runs.append((name + " a*", p.path, plan.optimize_trajectory(ws, p.path, lim)))

    print(f"\ntoppra (v, a limits; spline through the way-points, {TOPPRA_GRID} grid points)")
    print("path          ours(s)  toppra(s)  ours/toppra  bound/toppra  ends        toppra-spline clearance(m)")
    for label, path, r in runs:
        tp = toppra_time(ws, path, lim)
        if tp is None:
            print(f"{label:<13} toppra missing: pip install 'autoteach[bench]'")
            continue
        t, bc, cl = tp
        print(
            f"{label:<13}{r.duration:8.3f}{t:11.3f}{r.duration / t:13.2f}{r.lower_bound / t:14.2f}  {bc:<11}{cl:10.4f}"
        )

    print(f"\nRRT*: ours vs OMPL RRTstar, {args.ompl_seconds:g} s budget, margin 20 mm")
    print(
        "name    first sol. ours(s) OMPL(s)  cost ours tree/shortcut  OMPL raw/simplified  "
        "checks ours  OMPL  ours us/check"
    )
    for name, a, b in TRANSFERS:
        o = ompl_rrt_star(ws, poses[a], poses[b], 0.02, args.ompl_seconds)
        if o is None:
            print(f"{name:<7} OMPL missing: pip install 'autoteach[bench]'")
            continue
        p = plan.plan_path(
            ws, poses[a], poses[b], method="rrt*", margin=0.02, max_iterations=10**6, time_limit_s=args.ompl_seconds
        )
        of, oraw, osimp, ochecks = o
        fmt = lambda x: f"{x:8.3f}" if x is not None else "    none"  # noqa: E731
        print(
            f"{name:<7}{p.extra['first_solution_s']:14.3f}{fmt(of)}{p.extra['tree_cost']:12.3f}{p.cost:8.3f}"
            f"{fmt(oraw)}{fmt(osimp)}{p.collision_checks:12d}{ochecks:8d}{1e6 * p.time_s / p.collision_checks:10.2f}"
        )
    table_2_2(ws, poses, lim)


def table_2_2(ws: plan.Workspace, poses: dict[str, np.ndarray], lim: plan.Limits) -> None:
    """Seed Table 2.2: a three-segment transfer, zero against free way-point velocities."""
    w1 = poses["home"]
    w2 = poses["home"].copy()
    w2[0], w2[4] = -0.7, poses["carrier_b"][4]
    ends = [poses["carrier_a"], w1, w2, poses["carrier_b"]]
    paths = [plan.plan_path(ws, ends[k], ends[k + 1], method="rrt*", margin=0.02).path for k in range(3)]
    print("\nTable 2.2: carrier A -> home -> folded towards B -> carrier B")
    print("way-point velocities              middle(s)  total(s)  opt(s)  iterations")
    rows = {}
    for free in (False, True):
        r = plan.optimize_waypoints(ws, paths, lim, free_velocities=free, max_iterations=300)
        assert all(v.min_clearance >= lim.d_safe for v in r.verification)
        rows[free] = r
        label = "zero" if not free else "free"
        print(f"{label:<34}{r.segments[1].duration:10.3f}{r.duration:10.3f}{r.time_s:8.2f}{r.iterations:8d}")
        if free:
            for k, v in enumerate(r.velocities):
                print(f"  v{k + 1} = {np.round(v, 2).tolist()}")
    print(f"cut by free velocities: {1.0 - rows[True].duration / rows[False].duration:.1%}")


if __name__ == "__main__":
    main()
