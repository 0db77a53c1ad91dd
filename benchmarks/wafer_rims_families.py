"""Per-family figures of the geometry-paired wafer rims (``detect_wafer_rims``) beside ``detect_wafers``.

Uses ``benchmarks/wafer_families.py``'s ``run_family`` (scenes of ``autoteach.sim.appearance``,
scoring of ``autoteach.sim.appearance_eval``: a rim counts when its centre is within 1 px and both
semi-axes within 1.5 % of a visible true rim) with these detectors on identical images:

- ``wafers``: ``detect_wafers`` with its default options (the unchanged pipeline path);
- ``wafer_rims``: ``detect_wafer_rims`` given the scene's physical inputs only (wafer radius and
  thickness, the focal length of the intrinsics; ``up`` is image up, the generator's camera is
  upright);
- ``ellipses``: ``detect_ellipses`` with default options (all accepted edges, no pairing).

Run: ``RAYON_NUM_THREADS=1 PYTHONPATH=python:benchmarks python benchmarks/wafer_rims_families.py --images 10``.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import autoteach.detect as detect
from autoteach.sim.appearance import FAMILIES, CarrierScene
from wafer_families import run_family  # type: ignore[import-not-found]


def _rims(scene: CarrierScene) -> list:
    p = scene.params
    geo = detect.WaferGeometry(radius=p.wafer_radius, thickness=p.wafer_thickness, focal_length=float(scene.K[0, 0]))
    return detect.detect_wafer_rims(scene.image, geo)


DETECTORS = {
    "wafers": lambda s: detect.detect_wafers(s.image),
    "wafer_rims": _rims,
    "ellipses": lambda s: detect.detect_ellipses(s.image),
}


def main() -> None:
    """Print one line per family and detector."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--families", default=",".join(FAMILIES))
    args = ap.parse_args()
    print(f"{'family':13s} {'detector':11s} {'recall':>7s} {'precision':>9s} {'med.err px':>10s} {'ms/frame':>8s}")
    for fam in args.families.split(","):
        r = run_family(fam, args.images, args.seed, DETECTORS)
        for name in DETECTORS:
            s = r[name]
            print(
                f"{fam:13s} {name:11s} {s['recall']:7.3f} {s['precision']:9.3f} "
                f"{s['median_centre_error_px']:10.3f} {s['median_time_ms']:8.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
