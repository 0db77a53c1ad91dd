"""The ``autoteach map`` command: occupancy-grid rasterization for robot teams (seed 004 ch. 2).

Usage::

    autoteach map --simulate [--world showgrounds|keswick|small] [--robots N] [--graphs N]
                  [--method cover_composite] [--slice-size 4] [--resolution 0.1] [--compare]
                  [--out DIR] [--json]

Runs the embedded team simulator, rasterizes every graph (10 s of mission time apart) and writes the
final map as ``map.pgm`` + ``map.yaml`` (ROS ``map_server`` / nav2) and ``map.png``, and the runtime
plot ``runtime.png`` (Figs. 2.5-2.8; needs the ``plot`` extra). ``--compare`` also runs the naive
methods of Table 2.1 on identical inputs (slow: NaiveComposite re-renders every node every time).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def _resolution(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}") from None
    if not (value > 0.0 and value < 10.0):
        raise argparse.ArgumentTypeError(f"must be in (0, 10) metres, got {value}")
    return value


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``map`` sub-command."""
    from autoteach.mapping import METHODS, WORLDS

    p = sub.add_parser(
        "map",
        parents=[common],
        help="rasterize a robot team's SLAM graphs into occupancy grids (simulated team)",
        description="Rasterize a sequence of SLAM graphs into ternary occupancy grids with CoverComposite "
        "(slice caching, node coverings, transient removal) on the embedded team simulator.",
    )
    p.add_argument("--simulate", action="store_true", help="run the embedded team simulator (required)")
    p.add_argument("--world", choices=WORLDS, default="showgrounds", help="world (default showgrounds, 220 x 160 m)")
    p.add_argument("--robots", type=_positive, default=None, help="robots (default: the world's, 14 for showgrounds)")
    p.add_argument("--graphs", type=_positive, default=None, help="graphs, 10 s apart (default: the world's)")
    p.add_argument("--method", choices=METHODS, default="cover_composite", help="method (default cover_composite)")
    p.add_argument("--slice-size", type=_positive, default=4, help="N, nodes per slice (default 4)")
    p.add_argument("--resolution", type=_resolution, default=0.1, help="metres per cell (default 0.1)")
    p.add_argument("--compare", action="store_true", help="also run the naive methods of Table 2.1")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--out", type=Path, default=Path("map_out"), help="output folder (default ./map_out)")
    from autoteach.commands.viewer_flag import add_rerun_argument

    add_rerun_argument(p, "OUT/map.rrd")
    p.set_defaults(func=_run)


def _summary(result: Any, sim: Any, args: argparse.Namespace, files: dict[str, str]) -> dict[str, Any]:
    methods = {}
    for name, reps in result.reports.items():
        t = [r.seconds for r in reps]
        methods[name] = {
            "total_s": sum(t),
            "mean_s": sum(t) / len(t),
            "max_s": max(t),
            "under_1s": sum(v < 1.0 for v in t),
            "slices_regenerated": sum(r.slices_regenerated for r in reps),
            "final_cover_nodes": reps[-1].cover_nodes,
            "peak_memory_mb": result.peak_bytes[name] / 2**20,
            "final_map": result.maps[name].counts(),
        }
    return {
        "world": args.world,
        "extent_m": list(sim.extent),
        "graphs": len(result.nodes),
        "final_nodes": result.nodes[-1],
        "mission_time_s": result.times[-1],
        "resolution": args.resolution,
        "methods": methods,
        "files": files,
    }


def _run(args: argparse.Namespace) -> int:
    from autoteach.errors import InvalidInputError
    from autoteach.mapping import TeamSimulator, plot_runtimes, rasterize_stream

    if not args.simulate:
        raise InvalidInputError("autoteach map needs --simulate (rasterizing your own graphs: use autoteach.mapping)")
    sim = TeamSimulator(args.world, robots=args.robots, graphs=args.graphs, seed=args.seed)
    names = [args.method]
    if args.compare:
        names = [m for m in ("naive_composite", "naive_cover_composite") if m != args.method] + names
    rasterizers = {
        (f"{m}({args.slice_size})" if m == "cover_composite" else m): sim.rasterizer(
            m, args.slice_size, resolution=args.resolution
        )
        for m in names
    }
    progress = not args.quiet and sys.stderr.isatty()
    recorder = None
    if getattr(args, "rerun", None) is not None:
        from autoteach.commands.viewer_flag import rerun_target
        from autoteach.viewer import MapRecorder

        args.out.mkdir(parents=True, exist_ok=True)
        last = list(rasterizers)[-1]
        rasterizers[last] = recorder = MapRecorder(rasterizers[last], rerun_target(args, args.out / "map.rrd"))
    result = rasterize_stream(sim, rasterizers, progress=progress)
    args.out.mkdir(parents=True, exist_ok=True)
    main = list(rasterizers)[-1]
    grid = result.maps[main]
    pgm, yaml = grid.save(args.out / "map")
    png = grid.to_png(args.out / "map.png")
    files = {"pgm": str(pgm), "yaml": str(yaml), "png": str(png)}
    try:
        files["runtime_plot"] = str(plot_runtimes(result, args.out / "runtime.png", f"{args.world}: runtime per graph"))
    except ImportError as err:
        files["runtime_plot"] = f"not written: {err}"
    if recorder is not None:
        files["rerun"] = str(recorder.close())
    summary = _summary(result, sim, args, files)
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"{summary['world']} {summary['extent_m'][0]:.0f} x {summary['extent_m'][1]:.0f} m, "
            f"{summary['graphs']} graphs, {summary['final_nodes']} nodes, {args.resolution} m cells"
        )
        print(f"{'method':<26}{'total s':>9}{'mean s':>9}{'max s':>9}{'<1 s':>6}{'cover':>7}{'MB':>7}")
        for name, m in summary["methods"].items():
            print(
                f"{name:<26}{m['total_s']:>9.2f}{m['mean_s']:>9.3f}{m['max_s']:>9.3f}{m['under_1s']:>6}"
                f"{m['final_cover_nodes']:>7}{m['peak_memory_mb']:>7.1f}"
            )
        for k, v in files.items():
            print(f"{k}: {v}")
    return 0
