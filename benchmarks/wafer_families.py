"""Wafer-rim detection and tracking per appearance family (issue 42), on :mod:`autoteach.sim.appearance`.

For each family, ``--images`` generated images (default 200; seeds ``seed + i``) go through the
detectors and are scored by :mod:`autoteach.sim.appearance_eval` (a rim counts when its centre is
within 1 px and both semi-axes within 1.5 % of a visible true rim, one-to-one): recall,
precision, F-measure, median centre error, median time per frame. Detectors:

- ``wafers``: ``autoteach.detect.detect_wafers`` with its default options;
- ``wafers_prior``: the same with the physical inputs it accepts (wafer thickness / radius,
  focal length, principal point);
- ``ellipses``: ``autoteach.detect.detect_ellipses`` with default options, when it exists.

Tracking (``--sweep-frames``, default 40; 0 to skip): per family one sweep of a 10-slot stack past
the camera, detections of the first detector through ``autoteach.track.WaferTracker`` (image
size, intrinsics, wafer radius, camera poses), CLEAR-MOT (MOTA, identity switches) of the tracks
registered in each frame against the wafers with a visible rim.

Run: ``python benchmarks/wafer_families.py [--images N] [--families a,b] [--detectors wafers,ellipses]
[--sweep-frames 40] [--json] [--out FILE]``. Times are single-threaded when ``RAYON_NUM_THREADS=1``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import autoteach.detect as detect
from autoteach.sim.appearance import FAMILIES, CarrierScene, render_carrier_image, render_sweep
from autoteach.sim.appearance_eval import score_frame, summarize, sweep_mot_frames

Detector = Callable[[CarrierScene], list[Any]]


def _prior(scene: CarrierScene) -> dict[str, Any]:
    p = scene.params
    return {
        "thickness_ratio": p.wafer_thickness / p.wafer_radius,
        "focal_length": p.focal_length,
        "principal_point": tuple(p.principal_point),
    }


def detectors(names: list[str]) -> dict[str, Detector]:
    """The named detectors that exist in this build."""
    table: dict[str, Detector] = {
        "wafers": lambda s: detect.detect_wafers(s.image),
        "wafers_prior": lambda s: detect.detect_wafers(s.image, **_prior(s)),
    }
    if hasattr(detect, "detect_ellipses"):
        table["ellipses"] = lambda s: detect.detect_ellipses(s.image)  # type: ignore[attr-defined]
    return {n: table[n] for n in names if n in table}


def run_family(family: str, n_images: int, seed: int, dets: dict[str, Detector]) -> dict[str, Any]:
    """Detection figures of one family."""
    scores: dict[str, list] = {name: [] for name in dets}
    render_times = []
    for i in range(n_images):
        t0 = time.perf_counter()
        scene = render_carrier_image(family, seed + i)
        render_times.append(time.perf_counter() - t0)
        for name, fn in dets.items():
            t0 = time.perf_counter()
            found = fn(scene)
            scores[name].append(score_frame(found, scene, time.perf_counter() - t0))
    out: dict[str, Any] = {"images": n_images, "median_render_ms": 1e3 * float(np.median(render_times))}
    for name, s in scores.items():
        out[name] = summarize(s)
    return out


def run_sweep(family: str, frames: int, seed: int, fn: Detector) -> dict[str, float]:
    """MOTA and identity switches of the tracker on one sweep."""
    from autoteach.track import WaferTracker, clear_mot

    scenes = render_sweep(family, seed, frames=frames, wafers=10)
    p = scenes[0].params
    tracker = WaferTracker(image_size=(p.width, p.height), intrinsics=p.K, wafer_radius=p.wafer_radius)
    per_frame = []
    for scene in scenes:
        tracks = tracker.update(fn(scene), camera_pose=scene.T_wc)
        per_frame.append([(t.id, t.ellipse) for t in tracks if t.visible and t.ellipse is not None])
    return clear_mot(sweep_mot_frames(scenes, per_frame))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=200, help="images per family (default 200)")
    ap.add_argument("--families", default=",".join(FAMILIES), help="comma-separated families (default all)")
    ap.add_argument("--detectors", default="wafers,wafers_prior,ellipses", help="comma-separated detectors")
    ap.add_argument("--sweep-frames", type=int, default=40, help="frames of the tracking sweep (0: skip)")
    ap.add_argument("--seed", type=int, default=1000, help="first seed (default 1000)")
    ap.add_argument("--json", action="store_true", help="print JSON")
    ap.add_argument("--out", default=None, help="also write the JSON here, updated after every family")
    args = ap.parse_args(argv)
    families = [f for f in args.families.split(",") if f]
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        ap.error(f"unknown families {unknown}; known: {', '.join(FAMILIES)}")
    dets = detectors([d for d in args.detectors.split(",") if d])
    if not dets:
        ap.error("no detector available")
    results: dict[str, Any] = {}
    for family in families:
        r = run_family(family, args.images, args.seed, dets)
        if args.sweep_frames > 0:
            first = next(iter(dets))
            r["tracking"] = {"detector": first, **run_sweep(family, args.sweep_frames, args.seed, dets[first])}
        results[family] = r
        if args.out:
            with open(args.out, "w") as fh:
                json.dump(results, fh, indent=1, default=float)
        print(f"{family} ({args.images} images, render {r['median_render_ms']:.0f} ms)", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(results, indent=1, default=float))
        return 0
    head = (
        "| family | detector | visible rims | recall | precision | F | median centre err (px) | kind acc | ms/frame |"
    )
    print(head)
    print("|" + "---|" * 9)
    for family, r in results.items():
        for name in dets:
            s = r[name]
            print(
                f"| {family} | {name} | {s['visible_rims']:.0f} | {s['recall']:.3f} | {s['precision']:.3f} | "
                f"{s['f1']:.3f} | {s['median_centre_error_px']:.3f} | {s['kind_accuracy']:.2f} | "
                f"{s['median_time_ms']:.1f} |"
            )
    if args.sweep_frames > 0:
        print()
        print("| family | detector | wafer-frames | misses | false | ID switches | MOTA |")
        print("|---|---|---|---|---|---|---|")
        for family, r in results.items():
            t = r["tracking"]
            mota = t["mota"] if math.isfinite(t["mota"]) else float("nan")
            print(
                f"| {family} | {t['detector']} | {t['num_gt']:.0f} | {t['fn']:.0f} | {t['fp']:.0f} | "
                f"{t['idsw']:.0f} | {mota:.3f} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
