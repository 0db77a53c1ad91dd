"""Auto-teaching on several simulated sessions: errors vs ground truth, conic factor vs point baseline.

Usage::

    python benchmarks/autoteach_sessions.py [--seeds 0 1 2 3 4] [--frames 200] [--json]

Each seed simulates a session (12 wafers in slots 4–25, the top one tilted by 1°, joint zero
offsets of 0.2–1°, drifting visual odometry, 0.3 px edge noise; images are not rendered: the
simulated front end uses the ground-truth visible rims) and runs :func:`autoteach.pipeline.autoteach`
with the conic factor of 000_3b1454b2b2194811.txt eq. (5.13) and with the point-reprojection +
nearest-point-association baseline on identical edge points. Prints one row per seed and method
(like Table 5.1) and the goals.
"""

from __future__ import annotations

import argparse
import json
import time

from autoteach.pipeline import autoteach
from autoteach.report import GOALS
from autoteach.sim import simulate_session


def main() -> None:
    """Run the sessions and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    for seed in args.seeds:
        session = simulate_session(seed=seed, frames=args.frames, render=False)
        t0 = time.perf_counter()
        r = autoteach(session, seed=seed, baseline=True)
        rows.append(
            {
                "seed": seed,
                "conic": r.errors,
                "within_3sigma": r.within_3sigma,
                "ukf_joint_offset_deg": r.ukf["errors"]["joint_offset_deg"] if r.ukf else None,
                "point_baseline": r.baseline["errors"],
                "conic_s": r.timings["slam_mot_s"],
                "baseline_s": r.baseline["runtime_s"],
                "total_s": time.perf_counter() - t0,
            }
        )
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    keys = list(GOALS)
    head = "seed  method    " + "  ".join(f"{k:>20}" for k in keys) + "   3σ   time[s]"
    print(head)
    print("goal            " + "  ".join(f"{GOALS[k]:>20g}" for k in keys))
    for row in rows:
        ok = "yes" if all(row["within_3sigma"].values()) else "NO"
        print(
            f"{row['seed']:>4}  conic     "
            + "  ".join(f"{row['conic'][k]:>20.4f}" for k in keys)
            + f"  {ok:>4}  {row['conic_s']:7.2f}"
        )
        print(
            f"{row['seed']:>4}  point     "
            + "  ".join(f"{row['point_baseline'][k]:>20.4f}" for k in keys)
            + f"        {row['baseline_s']:7.2f}"
        )
        print(f"{row['seed']:>4}  UKF θ1,θ2,θ4 max offset error {row['ukf_joint_offset_deg']:.4f} deg")


if __name__ == "__main__":
    main()
