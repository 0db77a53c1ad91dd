"""The ``autoteach active`` command: Table 6.4 / Fig. 6.4 of the seed on simulation.

``autoteach active --trials 10 [--seed N] [--steps N] [--json]`` runs the closed loop of active
auto-teaching (000_3b1454b2b2194811.txt Fig. 6.1) with the one-step greedy planner and the
baseline approach trajectory on the same random trials, and prints the final error statistics
(± std (peak)) of the opening and camera translation and the observability indices per step.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from autoteach.commands.args import positive, seed


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``active`` sub-command."""
    p = sub.add_parser(
        "active",
        parents=[common],
        help="active auto-teaching on simulation: errors with and without measurement-pose planning",
    )
    p.add_argument("--trials", type=positive, default=10, help="number of random trials (default 10)")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--steps", type=positive, default=None, help="measurements per trial (default 12)")
    p.set_defaults(func=_run)


def format_table(r: dict[str, Any]) -> str:
    """Table 6.4 layout: ± std (peak) of the final errors, then the indices over steps."""
    lines = [
        f"active auto-teaching, {r['trials']} trials x {r['steps']} steps (seed {r['seed']})",
        "final error: ± std (peak)",
        f"{'quantity':<18}{'w/o active':>22}{'proposed':>22}",
    ]
    for name in r["active"]:
        b, a = r["baseline"][name], r["active"][name]
        base = "±{:.3g} ({:.3g})".format(b["std"], b["peak"])
        prop = "±{:.3g} ({:.3g})".format(a["std"], a["peak"])
        lines.append(f"{name:<18}{base:>22}{prop:>22}")
    w = r["worst_axis"]
    lines.append(f"baseline worst axis {w['name']}: std ratio baseline/active {w['ratio']:.1f}x")
    t = r["planning_time_ms"]
    lines.append(f"planning time per step: median {t['median']:.1f} ms, max {t['max']:.1f} ms")
    lines.append("O1 (D-optimality, mm/deg units) per step, mean over trials:")
    for mode in ("baseline", "active"):
        o1 = r["indices"][mode]["O1"]["mean"]
        lines.append(f"  {mode:<9}" + " ".join(f"{v:.3g}" for v in o1))
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> int:
    from autoteach.active import compare

    result = compare(trials=args.trials, seed=args.seed, steps=args.steps)
    if args.json:
        print(json.dumps(result))
    else:
        print(format_table(result))
    return 0
