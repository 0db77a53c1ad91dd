"""A* on the joint lattices of issue 30 (seed 000 ch. 2.3): time, expansions, collision checks.

Run: ``RAYON_NUM_THREADS=1 PYTHONPATH=python /work/venv/bin/python benchmarks/astar_lattices.py``

The goals are the 3-joint lattice at 1° and the 5-joint lattice at 5° (lift 25 mm), each in
≤ 3 s. The transfers are the default scene's (margin 20 mm, `plan_path`'s default). In the
3-joint runs joints 3 and 4 are held at the goal's values (the lattice plans joints 0-2 only).
The optimal cost is checked against a plain Dijkstra by the Rust tests (`plan::astar::tests`),
on coarser lattices.
"""

from __future__ import annotations

import argparse
import time

from autoteach import plan

MOVES = (("home", "chamber"), ("home", "carrier_a"), ("carrier_a", "chamber"), ("home", "carrier_b"))


def main() -> None:
    """Print one line per transfer and lattice."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--five-only", action="store_true", help="only the 5-joint 5° lattice")
    args = ap.parse_args()
    ws, poses = plan.default_scene()
    lattices = [([0, 1, 2, 3, 4], 5.0)] if args.five_only else [([0, 1, 2], 1.0), ([0, 1, 2, 3, 4], 5.0)]
    print("move                  joints  step   time(s)   cost   expansions   checks")
    for a, b in MOVES:
        for joints, step in lattices:
            s, g = poses[a].copy(), poses[b].copy()
            if len(joints) == 3:
                s[3:] = g[3:]
            t0 = time.perf_counter()
            r = plan.plan_path(ws, s, g, method="a*", step_deg=step, joints=joints)
            t = time.perf_counter() - t0
            print(
                f"{a + '->' + b:<22}{len(joints):6d}{step:6.1f}{t:10.3f}{r.cost:8.4f}{r.iterations:12d}"
                f"{r.collision_checks:10d}"
            )


if __name__ == "__main__":
    main()
