"""The ``autoteach tune`` command: Tables 2.3 and 2.4 and Fig. 2.15 of the seed on simulation.

``autoteach tune --demo [--seed N] [--noise 0.01] [--plot DIR] [--json]`` runs the joint controller tuning
of 000_3b1454b2b2194811.txt ch. 2.5 on the simulated JT2 and JT4 plants (six poses each): noisy sine
sweeps, fitted models, the classical baseline and the multi-model tuned controller; it prints Table 2.3
(worst case over the plants) and Table 2.4 (RMS hand acceleration on an S-curve move), and with
``--plot`` writes the Bode magnitudes of every S_i against S_d (Fig. 2.15) as PNG files.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any


def _noise(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"noise must be a number, got {text!r}") from None
    if not (math.isfinite(value) and 0 <= value < 1):
        raise argparse.ArgumentTypeError(f"noise must be in [0, 1), got {value}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seed must be a non-negative integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"seed must be a non-negative integer, got {value}")
    return value


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``tune`` sub-command."""
    p = sub.add_parser(
        "tune",
        parents=[common],
        help="joint controller tuning on simulation: Tables 2.3 and 2.4, Fig. 2.15",
    )
    p.add_argument("--demo", action="store_true", help="run the simulated JT2/JT4 experiment (required)")
    p.add_argument("--seed", type=_seed, default=0, help="random seed of the sweep noise (default 0)")
    p.add_argument("--noise", type=_noise, default=0.01, help="relative sweep noise (default 0.01)")
    p.add_argument("--plot", type=Path, default=None, help="folder for the Fig. 2.15 plots (needs matplotlib)")
    p.set_defaults(func=_run)


def format_tables(result: dict[str, Any]) -> str:
    """Table 2.3 (worst case over the plants) and Table 2.4 in the seed's layout."""
    from autoteach.control import table_2_3

    lines = ["Table 2.3 (simulation, worst case over 6 poses; crossover = bandwidth column of the seed)"]
    head = f"{'':<10}{'crossover(Hz)':>14}{'-3dB BW(Hz)':>12}{'PM(deg)':>9}{'GM(dB)':>8}{'damping':>9}{'order':>7}  ok"
    for row in table_2_3(result):
        if row["controller"] == "baseline":
            lines += [row["joint"], head]
        name = "original" if row["controller"] == "baseline" else "proposed"
        lines.append(
            f"{name:<10}{row['crossover_hz']:>14.2f}{row['bandwidth_hz']:>12.2f}{row['phase_margin_deg']:>9.1f}"
            f"{row['gain_margin_db']:>8.1f}{row['damping']:>9.3f}{row['filter_order']:>7d}  "
            + ("yes" if row["success"] else "NO: " + "; ".join(row["unmet"]))
        )
    v = result["vibration"]
    lines += [
        "",
        "Table 2.4 (simulation: RMS hand acceleration, m/s^2, on a cycloidal S-curve; planar model, no Z)",
        f"{'':<10}{'forward':>10}{'lateral':>10}{'vib fwd':>10}{'vib lat':>10}",
    ]
    for key, name in (("baseline", "original"), ("tuned", "proposed")):
        t, d = v[key]["total"], v[key]["vibration"]
        lines.append(f"{name:<10}{t[0]:>10.4f}{t[1]:>10.4f}{d[0]:>10.4f}{d[1]:>10.4f}")
    return "\n".join(lines)


def _jsonable(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _run(args: argparse.Namespace) -> int:
    if not args.demo:
        print(
            "autoteach tune: error: --demo is expected (the only mode: the simulated JT2/JT4 experiment)",
            file=sys.stderr,
        )
        return 2
    from autoteach.control import demo, plot_sensitivities, table_2_3

    result = demo(noise=args.noise, seed=args.seed)
    if args.plot is not None:
        args.plot.mkdir(parents=True, exist_ok=True)
        for joint in ("JT2", "JT4"):
            plot_sensitivities(result, joint, str(args.plot / f"sensitivity_{joint}.png"))
    if args.json:
        out = {"table_2_3": table_2_3(result), "table_2_4": result["vibration"]}
        print(json.dumps(_jsonable(out)))
    elif not args.quiet:
        print(format_tables(result))
    return 0
