"""Simulated guided calibration sessions (seed 004_815695db12a6b16c.txt ch. 5.5, Figs. 5.7-5.8).

For every simulated lens (narrow 48 deg to 140 deg diagonal FOV; Brown-Conrady for the narrow ones,
Kannala-Brandt for the wide ones) and seed, runs a guided session (each view is the suggestion of
``suggest_next_view``, achieved by a simulated user up to a small pose error) and a random one
(views drawn like the test set), up to ``--max-views`` views each. After every view it records the
Max ERE (Algorithm 5.1) and the error on an independent 60-view test set (poses re-fit with the
intrinsics fixed, observations from the true lens: the reference protocol of ch. 5.5.3).

Reports per lens: the ratio Max ERE / test 99.5th percentile over all fully constrained steps
(median and share within +-30 %), and the distributions of the number of views needed for a test
99.5th-percentile error below 1 px, guided versus random.

    python benchmarks/guided_calibration.py [--seeds 5] [--max-views 12] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

import numpy as np

from autoteach.calib import LENSES, simulate_session


def main() -> None:
    """Run the sessions and print the summary."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--max-views", type=int, default=12)
    ap.add_argument("--lenses", nargs="*", default=list(LENSES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    report: dict[str, dict] = {}
    t0 = time.perf_counter()
    for lens in args.lenses:
        entry: dict[str, list] = {"ratios": [], "guided_views": [], "random_views": [], "guided_p995_at_8": []}
        for seed in range(args.seeds):
            for strategy in ("guided", "random"):
                res = simulate_session(lens, strategy=strategy, max_views=args.max_views, seed=seed)
                n = res.views_to_test_1px
                entry[f"{strategy}_views"].append(n if n is not None else math.inf)
                if strategy == "guided":
                    entry["ratios"] += [s.max_ere / s.test_p995 for s in res.steps if math.isfinite(s.max_ere)]
                    at8 = [s.test_p995 for s in res.steps if s.views == 8]
                    entry["guided_p995_at_8"] += at8
        r = np.array(entry["ratios"])
        report[lens] = {
            "fov_deg": LENSES[lens]["fov_deg"],
            "model": LENSES[lens]["model"],
            "ratio_median": float(np.median(r)) if r.size else math.nan,
            "ratio_within_30pct": float(np.mean(np.abs(r - 1.0) <= 0.3)) if r.size else math.nan,
            "ratio_count": int(r.size),
            "guided_views_to_1px": entry["guided_views"],
            "random_views_to_1px": entry["random_views"],
            "guided_p995_at_8_views_px": entry["guided_p995_at_8"],
        }
    elapsed = time.perf_counter() - t0
    if args.json:
        print(json.dumps({"lenses": report, "seeds": args.seeds, "max_views": args.max_views, "elapsed_s": elapsed}))
        return

    def fmt(v: list) -> str:
        return "[" + ", ".join("-" if not math.isfinite(x) else str(int(x)) for x in v) + "]"

    def med(v: list) -> str:
        m = statistics.median(v)
        return ">max" if not math.isfinite(m) else f"{m:g}"

    print(f"{args.seeds} seeds per lens and strategy, at most {args.max_views} views; '-' = not reached")
    print(f"{'lens':>10} {'FOV':>5} {'model':>15} {'MaxERE/p99.5 med':>17} {'within30%':>9}  views to p99.5<1px")
    for lens, e in report.items():
        print(
            f"{lens:>10} {e['fov_deg']:>5.0f} {e['model']:>15} {e['ratio_median']:>17.2f}"
            f" {e['ratio_within_30pct']:>9.0%}"
            f"  guided {fmt(e['guided_views_to_1px'])} (median {med(e['guided_views_to_1px'])})"
            f"  random {fmt(e['random_views_to_1px'])} (median {med(e['random_views_to_1px'])})"
        )
    print(f"elapsed {elapsed:.1f} s")


if __name__ == "__main__":
    main()
