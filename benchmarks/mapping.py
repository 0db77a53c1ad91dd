"""Occupancy-grid rasterization (seed 004_815695db12a6b16c.txt ch. 2, issue 32): Table 2.1's methods on one stream.

One run on the simulated phase-2 stream (220 x 160 m, 14 robots, 429 graphs 10 s apart, 0.1 m cells),
every method fed identical inputs:

- exactness: CoverComposite(4) with coverings off equals NaiveComposite cell for cell at every graph;
  with coverings on, the fraction of differing cells and the wall-gap check against NaiveComposite;
- speed: total and mean update time per method, CoverComposite(4) vs NaiveComposite, the worst
  per-graph ratio, N = 4 / 16 / 64 (Fig. 2.5's trade-off: total and updates under 1 s);
- transients: cells only people/vehicles occupied, and static wall cells lost against a stream with
  the transients invisible (identical graphs);
- memory: the rasterizers' held bytes and the process peak RSS; a 2-hour stream (720 graphs) of
  CoverComposite(4) alone with ``--two-hours``;
- peer: OctoMap (pyoctomap, ``insertPointCloud`` with lazy evaluation and discretisation, its fastest
  configuration) re-inserting every scan at its posterior, i.e. a full rebuild per graph, timed on
  a sample of graphs.

Run: ``RAYON_NUM_THREADS=1 python benchmarks/mapping.py [--graphs 429] [--robots 14] [--two-hours]
[--json out.json] [--plot runtime.png]``
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np

from autoteach.mapping import (
    StreamResult,
    TeamSimulator,
    differing_cells,
    plot_runtimes,
    rasterize_stream,
    wall_gaps,
)


def summary(reps):
    t = np.array([r.seconds for r in reps])
    return {
        "total_s": float(t.sum()),
        "mean_s": float(t.mean()),
        "median_s": float(np.median(t)),
        "max_s": float(t.max()),
        "under_1s": int((t < 1.0).sum()),
        "slices_regenerated": int(sum(r.slices_regenerated for r in reps)),
        "nodes_rasterized": int(sum(r.nodes_rasterized for r in reps)),
        "final_cover": reps[-1].cover_nodes,
        "final_nodes": reps[-1].nodes,
    }


def octomap_rebuild(sim, graph, sample, seed=0):
    """Seconds per scan for a full OctoMap rebuild of ``graph`` (a sample of its nodes, all scans inserted)."""
    import pyoctomap

    rng = np.random.default_rng(seed)
    ids = np.sort(rng.choice(graph.node_ids, size=min(sample, len(graph.node_ids)), replace=False))
    ranges = sim._inner.ranges(np.ascontiguousarray(ids))
    angles = sim.angle_min + np.arange(ranges.shape[1]) * sim.angle_increment
    tree = pyoctomap.OcTree(0.1)
    t0 = time.perf_counter()
    for k, node in enumerate(ids):
        x, y, th = graph.poses[node]
        r = ranges[k]
        ok = np.isfinite(r)
        rr = np.where(ok, r, sim.max_range)
        pts = np.c_[x + rr * np.cos(th + angles), y + rr * np.sin(th + angles), np.zeros_like(rr)]
        tree.insertPointCloud(pts, np.array([x, y, 0.0]), max_range=sim.max_range, lazy_eval=True, discretize=True)
    tree.updateInnerOccupancy()
    return (time.perf_counter() - t0) / len(ids)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graphs", type=int, default=429)
    ap.add_argument("--robots", type=int, default=14)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--octomap-sample", type=int, default=200, help="scans per OctoMap timing")
    ap.add_argument("--two-hours", action="store_true", help="also run a 720-graph stream (memory)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--plot", default=None)
    args = ap.parse_args()

    out = {"graphs": args.graphs, "robots": args.robots, "seed": args.seed, "resolution": 0.1}
    sim = TeamSimulator("showgrounds", robots=args.robots, graphs=args.graphs, seed=args.seed)
    t0 = time.perf_counter()
    graphs = list(sim)
    out["simulate_s"] = time.perf_counter() - t0
    out["final_nodes"] = len(graphs[-1].node_ids)
    out["solve_s_total"] = sum(g.solve_seconds for g in graphs)
    out["loop_closures"] = int((graphs[-1].edge_kinds == 2).sum())

    class Replay:
        def __init__(self, gs):
            self.gs, self.graphs = gs, len(gs)

        def __iter__(self):
            return iter(self.gs)

    methods = {
        "NaiveComposite": sim.rasterizer("naive_composite"),
        "CoverComposite(4), coverings off": sim.rasterizer("cover_composite", 4, covering=False),
        "NaiveCoverComposite": sim.rasterizer("naive_cover_composite"),
        "CoverComposite(4)": sim.rasterizer("cover_composite", 4),
        "CoverComposite(16)": sim.rasterizer("cover_composite", 16),
        "CoverComposite(64)": sim.rasterizer("cover_composite", 64),
    }
    # Run graph by graph to check exactness at every step without keeping every map.
    exact_steps, differ = 0, []
    reports = {k: [] for k in methods}
    peak = {k: 0 for k in methods}
    maps = {}
    for g in graphs:
        scans = g.scans_by_row()
        for name, r in methods.items():
            maps[name] = r.update(g.node_ids, g.robot_ids, g.poses, scans)
            reports[name].append(r.last_report)
            peak[name] = max(peak[name], r.memory_bytes)
        a, b = maps["NaiveComposite"], maps["CoverComposite(4), coverings off"]
        exact_steps += int(a.origin == b.origin and np.array_equal(a.cells, b.cells))
        c = maps["CoverComposite(4)"]
        d, total = differing_cells(a, c)
        differ.append(d / total)
    out["exact_steps"] = exact_steps
    out["cover_differ_fraction_max"] = max(differ)
    out["cover_differ_fraction_final"] = differ[-1]
    out["wall_gaps"] = wall_gaps(maps["CoverComposite(4)"], maps["NaiveComposite"], sim.walls)
    out["methods"] = {k: summary(v) | {"peak_mb": peak[k] / 2**20} for k, v in reports.items()}
    naive_t = np.array([r.seconds for r in reports["NaiveComposite"]])
    cover_t = np.array([r.seconds for r in reports["CoverComposite(4)"]])
    out["speedup_total_cover4_vs_naive"] = float(naive_t.sum() / cover_t.sum())
    out["worst_step_ratio_cover4_over_naive"] = float((cover_t / naive_t).max())
    out["transients"] = sim.transient_residue(maps["CoverComposite(4)"], graphs[-1])
    out["transients_naive"] = sim.transient_residue(maps["NaiveComposite"], graphs[-1])

    # Static walls lost to transients: the same graphs with the transients invisible.
    clean_sim = TeamSimulator("showgrounds", robots=args.robots, graphs=args.graphs, seed=args.seed, transients=False)
    clean = rasterize_stream(clean_sim, {"c": clean_sim.rasterizer("cover_composite", 4)}).maps["c"]
    with_t = maps["CoverComposite(4)"]
    out["static"] = {
        "differing_cells_vs_clean": differing_cells(with_t, clean),
        "wall_gaps_vs_clean": wall_gaps(with_t, clean, sim.walls),
    }

    # OctoMap full rebuild: per-scan cost on the final graph's scans, times the nodes of every graph.
    try:
        per_scan = octomap_rebuild(sim, graphs[-1], args.octomap_sample)
        rebuild = [per_scan * len(g.node_ids) for g in graphs]
        out["octomap"] = {
            "per_scan_s": per_scan,
            "final_rebuild_s": rebuild[-1],
            "total_rebuild_s": float(sum(rebuild)),
            "speedup_total_cover4": float(sum(rebuild) / cover_t.sum()),
        }
    except ImportError as err:
        out["octomap"] = f"unavailable: {err}; install the bench extra: pip install 'autoteach[bench]'"

    if args.two_hours:
        long = TeamSimulator("showgrounds", robots=args.robots, graphs=720, seed=args.seed)
        r4 = long.rasterizer("cover_composite", 4)
        mem, nodes = [], []
        for g in long:
            r4.update(g.node_ids, g.robot_ids, g.poses, g.scans_by_row())
            mem.append(r4.memory_bytes)
            nodes.append(len(g.node_ids))
        out["two_hours"] = {
            "graphs": 720,
            "final_nodes": nodes[-1],
            "rasterizer_mb_at_1h": mem[359] / 2**20,
            "rasterizer_mb_at_2h": mem[-1] / 2**20,
            "peak_mb": max(mem) / 2**20,
        }
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if args.plot:
        shown = (
            "NaiveComposite",
            "NaiveCoverComposite",
            "CoverComposite(4)",
            "CoverComposite(16)",
            "CoverComposite(64)",
        )
        res = StreamResult({k: reports[k] for k in shown}, {}, [len(g.node_ids) for g in graphs], [], {})
        plot_runtimes(res, args.plot, f"showgrounds stream, {args.robots} robots, {len(graphs)} graphs")

    m = out["methods"]
    print(f"stream: {len(graphs)} graphs, {out['final_nodes']} nodes, {out['loop_closures']} loop closures")
    print(f"{'method':<34}{'total s':>9}{'mean s':>9}{'median':>9}{'max s':>9}{'<1 s':>6}{'MB':>7}")
    for k, v in m.items():
        print(
            f"{k:<34}{v['total_s']:>9.2f}{v['mean_s']:>9.3f}{v['median_s']:>9.3f}{v['max_s']:>9.3f}"
            f"{v['under_1s']:>6}{v['peak_mb']:>7.1f}"
        )
    print(json.dumps({k: v for k, v in out.items() if k != "methods"}, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
