"""The ``autoteach segment`` command: coloured point-cloud segmentation (seed 004 ch. 4).

Usage::

    autoteach segment --simulate [--scene hallway] [--seed 0] [--out segments.ply] [--png segments.png] [--json]
    autoteach segment cloud.ply [--k 8] [--out segments.ply] [--png segments.png] [--json]

With ``--simulate`` a tilting scanner and a camera are simulated in a labelled scene, the points
are coloured through the camera image, segmented on the scan mesh, and scored against the
ground truth (adapted Rand error). A PLY file is segmented on its k-nearest-neighbour graph.
The output PLY holds the points coloured by segment with a ``label`` property.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from autoteach.errors import InvalidInputError


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``segment`` sub-command."""
    from autoteach.segment import SCENES

    p = sub.add_parser(
        "segment",
        parents=[common],
        help="segment a coloured point cloud by colour and surface normals (or --simulate one)",
        description="Graph segmentation of coloured lidar points by colour and surface normals "
        "(Felzenszwalb-Huttenlocher with two adaptive thresholds, seed 004 Algorithm 4.1).",
    )
    p.add_argument("cloud", nargs="?", type=Path, help="a PLY file with x y z red green blue")
    p.add_argument("--simulate", action="store_true", help="simulate a scan of a labelled scene instead")
    p.add_argument("--scene", choices=SCENES, default="hallway", help="simulated scene (default hallway)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulation (default 0)")
    p.add_argument("--criteria", choices=("both", "color", "normal"), default="both", help="merge criteria")
    p.add_argument("--k-rgb", type=float, default=9000.0, help="K_rgb (default 9000, Table 4.1)")
    p.add_argument("--k-norm", type=float, default=10.0, help="K_norm (default 10, Table 4.1)")
    p.add_argument("--edge-cut", type=float, default=0.25, help="longest edge in metres (default 0.25)")
    p.add_argument("--min-size", type=int, default=100, help="smallest segment (default 100)")
    p.add_argument("--k", type=int, default=8, help="neighbours of the k-NN graph for PLY input (default 8)")
    p.add_argument("--out", type=Path, default=Path("segments.ply"), help="output PLY (default segments.ply)")
    p.add_argument("--png", type=Path, default=None, help="also write a PNG view (needs the plot extra)")
    from autoteach.commands.viewer_flag import add_rerun_argument

    add_rerun_argument(p, "OUT with suffix .rrd")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the command; returns the exit status."""
    from autoteach import segment as seg

    params = {
        "k_rgb": args.k_rgb,
        "k_norm": args.k_norm,
        "edge_cut": args.edge_cut,
        "min_size": args.min_size,
        "criteria": args.criteria,
    }
    from autoteach.commands.viewer_flag import rerun_target

    rrd = rerun_target(args, args.out.with_suffix(".rrd"))
    summary: dict[str, object] = {}
    truth = None
    if args.simulate:
        if args.cloud is not None:
            raise InvalidInputError("give either a PLY file or --simulate, not both")
        sim = seg.simulate_scan(args.scene, seed=args.seed)
        points, colors = sim.cloud()
        truth = sim.labels
        t0 = time.perf_counter()
        res = seg.segment_cloud(points, colors, graph="scan", **params)
        summary["scene"] = args.scene
    else:
        if args.cloud is None:
            raise InvalidInputError("a PLY file (or --simulate) is required")
        cloud = seg.read_ply(args.cloud)
        if cloud.colors is None:
            raise InvalidInputError(f"{args.cloud}: no red/green/blue vertex properties")
        points, colors = cloud.points, cloud.colors
        t0 = time.perf_counter()
        res = seg.segment_cloud(points, colors, normals=cloud.normals, graph="knn", k=args.k, **params)
    elapsed = time.perf_counter() - t0
    valid = res.labels >= 0
    summary.update(
        {
            "points": int(valid.sum()),
            "segments": res.num_segments,
            "edges": res.num_edges,
            "time_s": elapsed,
            "out": str(args.out),
        }
    )
    if truth is not None:
        scored = valid & (truth >= 0)
        summary["adapted_rand_error"] = seg.adapted_rand_error(truth[scored], res.labels[scored])
    seg.write_ply(args.out, points, seg.label_colors(res.labels), normals=res.normals, labels=res.labels)
    if args.png is not None:
        seg.plot_segments(points, res.labels, args.png, colors=colors, title=f"{res.num_segments} segments")
        summary["png"] = str(args.png)
    if rrd is not None:
        from autoteach.viewer import log_segments

        summary["rerun"] = str(log_segments(points, res.labels, rrd, colors=colors))
    if args.json:
        print(json.dumps(summary))
    else:
        line = f"{summary['points']} points -> {res.num_segments} segments in {elapsed * 1e3:.1f} ms"
        if "adapted_rand_error" in summary:
            line += f", adapted Rand error {summary['adapted_rand_error']:.3f} vs ground truth"
        print(line)
        print(f"wrote {args.out}" + (f" and {args.png}" if args.png else ""))
    return 0
