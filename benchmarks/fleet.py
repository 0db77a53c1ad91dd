"""Wall time of a fleet batch: ``autoteach.fleet.run_batch`` with N workers against one process.

Simulates ``--logs`` rendered sessions (seeds 0..logs-1, ``--frames`` each) into a temporary
folder, then auto-teaches them (detect front end, as ``autoteach run``) sequentially in this
process and with ``--workers`` worker processes, ``--repeats`` times each (the median is
printed), checks that both give bit-identical results, and prints the ratio. Optionally also with
Ray (``--ray``: a local ``ray.init(num_cpus=workers)``; start-up is not timed).

    RAYON_NUM_THREADS unset; python benchmarks/fleet.py --logs 8 --frames 20 --workers 2 [--ray]

It also prints how many cores the sequential run keeps busy (CPU seconds of the process, all its
threads, per wall second): the same CPU work on P cores cannot take less than that / P of the
sequential wall time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from autoteach.fleet import RunOptions, run_batch
from autoteach.io import write_log
from autoteach.sim import simulate_session


def same(a, b) -> bool:
    return all(
        x.ok == y.ok
        and (
            not x.ok
            or (
                np.array_equal(x.joint_offsets, y.joint_offsets, equal_nan=True)
                and np.array_equal(x.base_pose, y.base_pose, equal_nan=True)
                and np.array_equal(x.wafer_poses, y.wafer_poses, equal_nan=True)
            )
        )
        for x, y in zip(a.outcomes, b.outcomes, strict=True)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=8)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--frontend", choices=("detect", "simulated"), default="detect")
    ap.add_argument("--ray", action="store_true")
    args = ap.parse_args()
    options = RunOptions(frontend=args.frontend)
    with tempfile.TemporaryDirectory() as tmp:
        logs = [
            write_log(simulate_session(seed=s, frames=args.frames), Path(tmp) / f"r{s}.mcap") for s in range(args.logs)
        ]
        rows: dict[str, list[float]] = {"sequential": [], f"{args.workers} workers": []}
        runs = {}
        cores: list[float] = []  # CPU seconds per wall second of the sequential run (all its threads)
        for _ in range(args.repeats):
            for name, workers in (("sequential", 1), (f"{args.workers} workers", args.workers)):
                t0, c0 = time.perf_counter(), time.process_time()
                runs[name] = run_batch(logs, options=options, workers=workers)
                rows[name].append(time.perf_counter() - t0)
                if workers == 1:
                    cores.append((time.process_time() - c0) / rows[name][-1])
        if args.ray:
            import ray

            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
            rows["ray"] = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                runs["ray"] = run_batch(logs, options=options, engine="ray")
                rows["ray"].append(time.perf_counter() - t0)
            ray.shutdown()
        base = statistics.median(rows["sequential"])
        print(f"{args.logs} logs x {args.frames} frames, {args.frontend} front end, {args.repeats} repeat(s)")
        for name, times in rows.items():
            med = statistics.median(times)
            ok = same(runs[name], runs["sequential"])
            n_ok = sum(o.ok for o in runs[name].outcomes)
            print(
                f"  {name:<12} median {med:7.2f} s  ratio {med / base:.2f}  {n_ok} logs auto-taught, "
                f"identical to sequential: {ok}"
            )
        used = statistics.median(cores)
        n_cpu = os.cpu_count() or 1
        print(
            f"  the sequential run keeps {used:.2f} of {n_cpu} cores busy: with the same CPU work, no schedule "
            f"can take less than {used / n_cpu:.2f} of its wall time"
        )
        per_log = [o.runtime_s for o in runs["sequential"].outcomes]
        print(f"  per-log runtime (sequential): median {statistics.median(per_log):.2f} s")


if __name__ == "__main__":
    main()
