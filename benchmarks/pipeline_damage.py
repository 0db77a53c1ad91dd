"""Robustness of the detect front end over random damage patterns (figures in docs/benchmarks.md).

The detections of the 40-frame rendered session of seed 3 are damaged as in
``tests/test_pipeline_detect.py``: 40 % of the rims dropped, every fourth frame empty, one false arc
per frame. For each pattern ``default_rng(seed)`` it prints the wafer centre and tilt errors
against the simulator's truth, whether they are inside 3σ, and which slots the basin search
moved.

    python benchmarks/pipeline_damage.py --patterns 14 54 [--level-band-search] [--no-basin-search]
"""

from __future__ import annotations

import argparse

import numpy as np

import autoteach.pipeline as pipeline
from autoteach.pipeline import autoteach
from autoteach.sim import simulate_session


def damaged(detections: list[list[object]], seed: int) -> list[list[object]]:
    rng = np.random.default_rng(seed)
    out = []
    for f, edges in enumerate(detections):
        keep = [e for e in edges if rng.random() > 0.4]
        if f % 4 == 0:
            keep = []
        elif keep:
            e = keep[0]
            keep.append(type(e)(**{**e.__dict__, "points": np.asarray(e.points) + [0.0, 25.0]}))
        out.append(keep)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patterns", nargs=2, type=int, default=(14, 54), metavar=("FIRST", "END"))
    ap.add_argument("--level-band-search", action="store_true")
    ap.add_argument("--no-basin-search", action="store_true")
    args = ap.parse_args()
    session = simulate_session(seed=3, frames=40, render=True)
    fx, fy, cx, cy = session.camera.params[:4]
    k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    cfg = session.config
    opts = pipeline.detector_options(k, cfg.wafer_radius, cfg.wafer_thickness, edge_profile="pixel")
    opts["level_band_search"] = bool(args.level_band_search)
    detections = pipeline.detect_all(session.images, **opts)
    real = pipeline.detect_all
    over = 0
    try:
        for seed in range(*args.patterns):
            d = damaged(detections, seed)
            pipeline.detect_all = lambda images, progress=False, _d=d, **o: _d
            r = autoteach(
                session,
                frontend="detect",
                seed=3,
                window=0,
                baseline=False,
                use_ukf=False,
                basin_search=not args.no_basin_search,
            )
            centre, tilt = r.errors["wafer_center_mm"], r.errors["wafer_tilt_deg"]
            over += centre >= 1.0
            print(
                f"pattern {seed}: centre {centre:.3f} mm, tilt {tilt:.3f} deg, "
                f"inside 3σ {r.within_3sigma['wafer_centers']}, moved {r.frontend_stats['basins_moved']}",
                flush=True,
            )
    finally:
        pipeline.detect_all = real
    print(f"patterns over 1.0 mm: {over} of {args.patterns[1] - args.patterns[0]}")


if __name__ == "__main__":
    main()
