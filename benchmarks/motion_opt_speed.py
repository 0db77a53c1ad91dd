"""Optimisation time of the five default transfers (issue 30's "≤ 1 s per trajectory").

Run: ``RAYON_NUM_THREADS=1 PYTHONPATH=python nice -n 5 /work/venv/bin/python benchmarks/motion_opt_speed.py``

The RRT* paths of ``benchmarks/motion.py`` (margin 20 mm, default seed) are optimised with the
default 40 iterations and to convergence (300 allowed); each line gives the wall time, the
duration, the gap to the per-joint bound, the iterations and the dense 1 ms verification's
clearance and torque ratio. Pointing ``PYTHONPATH`` at another build compares two versions on the
same paths.
"""

from __future__ import annotations

import time

from autoteach import plan
from autoteach.commands.plan import TRANSFERS


def main() -> None:
    """Plan the five transfers, then time their optimisation."""
    ws, poses = plan.default_scene()
    paths = {name: plan.plan_path(ws, poses[a], poses[b], method="rrt*", margin=0.02).path for name, a, b in TRANSFERS}
    for name, _, _ in TRANSFERS:
        for iterations in (40, 300):
            t0 = time.perf_counter()
            r = plan.optimize_trajectory(ws, paths[name], plan.Limits(), max_iterations=iterations)
            wall = time.perf_counter() - t0
            v = r.verification
            print(
                f"{name} max_it={iterations:3d} wall {wall:6.3f} s  T {r.duration:.6f} s  gap {100 * r.gap:.3f} %  "
                f"it {r.iterations} (accepted {r.accepted})  "
                f"clearance {v.min_clearance:.4f} m  torque {v.torque_ratio:.3f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
