"""Per-family recall and precision of ``detect_wafer_rims`` on a few scenes of every appearance family.

Scenes from :mod:`autoteach.sim.appearance` (a generator separate from the ray tracer), scored by
:mod:`autoteach.sim.appearance_eval` (a rim counts when its centre is within 1 px and both semi-axes
within 1.5 % of a visible true rim). The detector gets the physical inputs only: wafer radius and
thickness, and the focal length of the intrinsics.

The issue's goal (recall and precision ≥ 0.95 in every family) is NOT met yet; the floors below are
the figures measured on these three seeds (issue 42, ``docs/benchmarks.md``) less 0.1, so the test
fails on a regression of the detector, not on the open goal. Raise them as the detector improves.
"""

from __future__ import annotations

import numpy as np
import pytest

from autoteach.detect import WaferGeometry, detect_wafer_rims
from autoteach.sim.appearance import FAMILIES, render_carrier_image
from autoteach.sim.appearance_eval import score_frame, summarize

SEEDS = (1000, 1001, 1002)

#: (recall, precision) measured on SEEDS, less 0.1.
FLOORS = {
    "bright_face": (0.74, 0.84),
    "dark_face": (0.74, 0.84),
    "thin_lines": (0.58, 0.82),
    "low_contrast": (0.26, 0.90),
    "lighting": (0.58, 0.76),
    "clutter": (0.37, 0.65),
    "occlusion": (0.42, 0.73),
    "blur_noise": (0.42, 0.66),
    "elevation": (0.26, 0.70),
    "sparse_stack": (0.50, 0.90),
}


def test_every_family_has_a_floor() -> None:
    assert set(FLOORS) == set(FAMILIES)


@pytest.mark.parametrize("family", FAMILIES)
def test_recall_and_precision_per_family(family: str) -> None:
    scores = []
    for seed in SEEDS:
        scene = render_carrier_image(family, seed)
        p = scene.params
        geometry = WaferGeometry(radius=p.wafer_radius, thickness=p.wafer_thickness, focal_length=float(scene.K[0, 0]))
        rims = detect_wafer_rims(scene.image, geometry)
        scores.append(score_frame(rims, scene))
    s = summarize(scores)
    recall_floor, precision_floor = FLOORS[family]
    assert s["recall"] >= recall_floor, s
    assert s["precision"] >= precision_floor, s
    # Every matched rim is labelled upper/lower by geometry, and the labels are right.
    assert s["kind_accuracy"] >= 0.9 or np.isnan(s["kind_accuracy"]), s


def test_focal_length_must_be_positive() -> None:
    from autoteach.errors import InvalidInputError

    scene = render_carrier_image("bright_face", 1000)
    with pytest.raises(InvalidInputError, match="focal_length"):
        detect_wafer_rims(scene.image, WaferGeometry(focal_length=-1.0))
