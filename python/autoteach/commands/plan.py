"""The ``autoteach plan`` command: Table 2.1 of the seed on the default scene.

``autoteach plan --demo [--plot DIR] [--json]`` plans (RRT*) and optimises (eq. 2.16) the
transfers between home, the two carriers and the chamber of the default workspace and prints, per
transfer, the planning time, the optimisation time, the number of control points, the trajectory
time and the per-joint lower bound. With ``--plot`` it writes the joint trajectories against the
planned path (Figs. 2.10-2.11) and a 3-D view of the swept link centres (needs matplotlib).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

TRANSFERS = (("traj01", "home", "carrier_a"), ("traj02", "home", "carrier_b"), ("traj03", "home", "chamber"))
TRANSFERS += (("traj13", "carrier_a", "chamber"), ("traj23", "carrier_b", "chamber"))


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``plan`` sub-command."""
    p = sub.add_parser("plan", parents=[common], help="collision-free time-optimal transfers: Table 2.1")
    p.add_argument("--demo", action="store_true", help="plan and optimise the default scene's transfers (required)")
    p.add_argument("--plot", type=Path, default=None, help="folder for the plots (needs matplotlib)")
    from autoteach.commands.viewer_flag import add_rerun_argument

    add_rerun_argument(p, "autoteach-plan.rrd")
    p.set_defaults(func=_run)


def run_demo() -> list[dict[str, Any]]:
    """Plan and optimise every transfer; one row of Table 2.1 per transfer."""
    from autoteach import plan

    ws, poses = plan.default_scene()
    rows = []
    for name, a, b in TRANSFERS:
        p = plan.plan_path(ws, poses[a], poses[b], method="rrt*", margin=0.02)
        r = plan.optimize_trajectory(ws, p.path, plan.Limits())
        rows.append(
            {
                "name": name,
                "from": a,
                "to": b,
                "planning_time_s": p.time_s,
                "optimisation_time_s": r.time_s,
                "control_points": len(r.trajectory.control_points),
                "trajectory_time_s": r.duration,
                "per_joint_bound_s": r.lower_bound,
                "gap": r.gap,
                "active": r.active,
                "min_clearance_m": r.verification.min_clearance,
                "_path": p.path,
                "_result": r,
            }
        )
    return rows


def _plot(rows: list[dict[str, Any]], folder: Path, ws: Any) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'autoteach[plot]'") from e
    import numpy as np

    folder.mkdir(parents=True, exist_ok=True)
    for row in rows:
        r = row["_result"]
        fig, ax = plt.subplots(figsize=(7, 4))
        r.trajectory.plot(ax=ax, path=row["_path"])
        ax.set_title(f"{row['name']}: {row['trajectory_time_s']:.3f} s (bound {row['per_joint_bound_s']:.3f} s)")
        fig.savefig(folder / f"{row['name']}_joints.png", dpi=100)
        plt.close(fig)
        fig = plt.figure(figsize=(6, 6))
        ax3 = fig.add_subplot(projection="3d")
        q = r.trajectory.sample(np.linspace(0.0, r.duration, 60))[0]
        for k in range(len(ws.link_centres(q[0]))):
            c = np.array([ws.link_centres(qi)[k][1] for qi in q])
            ax3.plot(c[:, 0], c[:, 1], c[:, 2], label=ws.link_centres(q[0])[k][0])
        ax3.legend()
        fig.savefig(folder / f"{row['name']}_swept.png", dpi=100)
        plt.close(fig)


def _run(args: argparse.Namespace) -> int:
    if not args.demo:
        print("autoteach plan: error: --demo is expected (the only mode)", file=sys.stderr)
        return 2
    from autoteach.commands.viewer_flag import rerun_target

    rrd = rerun_target(args, Path("autoteach-plan.rrd"))
    rows = run_demo()
    if rrd is not None:
        from autoteach import plan
        from autoteach.viewer import log_plan

        print(f"Rerun recording: {log_plan(rows, plan.default_scene()[0], rrd)}", file=sys.stderr)
    if args.plot is not None:
        from autoteach import plan

        _plot(rows, args.plot, plan.default_scene()[0])
    public = [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]
    if args.json:
        print(json.dumps(public, indent=2))
        return 0
    print("Table 2.1 (default scene, RRT* paths, 2-core VM)")
    print(f"{'name':<8}{'plan(s)':>9}{'opt(s)':>9}{'ctrl':>6}{'T(s)':>8}{'bound(s)':>10}{'gap':>7}  active")
    for r in public:
        print(
            f"{r['name']:<8}{r['planning_time_s']:>9.3f}{r['optimisation_time_s']:>9.3f}{r['control_points']:>6d}"
            f"{r['trajectory_time_s']:>8.3f}{r['per_joint_bound_s']:>10.3f}{r['gap']:>7.2f}  {', '.join(r['active'])}"
        )
    return 0
