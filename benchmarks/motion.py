"""Table 2.1 of seed 000 on the default scene, with ruckig's per-joint bound beside ours.

Run: ``RAYON_NUM_THREADS=1 PYTHONPATH=python /work/venv/bin/python benchmarks/motion.py``

For each transfer (RRT* path, margin 20 mm; d_safe 10 mm) it prints the planning time, the
optimisation time, the number of control points, the trajectory time and the per-joint lower
bound, then ruckig's time-optimal jerk-limited rest-to-rest move of every joint under the same
v/a/j limits (no obstacles). ruckig's maximum over the joints must equal our bound. toppra and OMPL
are not compared here (not installed in this session).
"""

from __future__ import annotations

import time

import numpy as np

from autoteach import plan
from autoteach.commands.plan import TRANSFERS


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


def main() -> None:
    """Print Table 2.1 with ruckig's bound."""
    ws, poses = plan.default_scene()
    lim = plan.Limits()
    print("name    plan(s)  opt(s)  ctrl   T(s)  bound(s)  ruckig(s)  gap   min clearance(m)  active")
    for name, a, b in TRANSFERS:
        t0 = time.perf_counter()
        p = plan.plan_path(ws, poses[a], poses[b], method="rrt*", margin=0.02)
        t1 = time.perf_counter()
        r = plan.optimize_trajectory(ws, p.path, lim)
        t2 = time.perf_counter()
        rb = ruckig_bound(poses[a], poses[b], lim)
        rb_s = f"{rb:9.4f}" if rb is not None else "      n/a"
        print(
            f"{name:<7}{t1 - t0:8.3f}{t2 - t1:8.3f}{len(r.trajectory.control_points):6d}{r.duration:7.3f}"
            f"{r.lower_bound:10.4f}{rb_s}{r.gap:6.2f}{r.verification.min_clearance:12.4f}      {', '.join(r.active)}"
        )


if __name__ == "__main__":
    main()
