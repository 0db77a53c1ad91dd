"""Scoring detections and tracks against the truth of :mod:`autoteach.sim.appearance` (issue 42).

One definition of a found rim for the benchmark (``benchmarks/wafer_families.py``) and the tests:

- A detection *matches* a true rim when its centre is within :data:`CENTRE_TOL_PX` (1 px) of the
  rim's and both its semi-axes are within :data:`AXIS_TOL` (1.5 %) of the rim's; detections and
  rims are paired one-to-one by a minimum-total-centre-error assignment among the matching pairs.
  The rim's kind (upper/lower) is not required to agree; :attr:`FrameScore.kind_correct` counts
  the matches whose kind does (when the detection has one).
- *Recall* = matched visible rims / visible rims (:attr:`RimTruth.visible`).
- *Precision* = matched detections / counted detections, where a detection matched to a rim that
  is present but not visible (e.g. mostly occluded) is counted in neither.
- Tracking: per frame, the ground-truth objects are the wafers with a visible rim, the hypotheses
  the tracker's tracks registered in that frame; a track and a wafer may correspond when the
  track's ellipse is within :data:`TRACK_GATE_PX` of either rim's centre with axes within
  :data:`TRACK_AXIS_TOL`; CLEAR-MOT (MOTA, identity switches) by
  :func:`autoteach.track.clear_mot`.

Detections may be anything with an ``ellipse`` attribute (an :class:`~autoteach.geometry.Ellipse`
or 5 numbers ``(cx, cy, a, b, theta)``) and optionally ``kind``, or bare ellipses.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from autoteach.detect import linear_sum_assignment
from autoteach.errors import InvalidInputError
from autoteach.sim.appearance import CarrierScene, RimTruth

__all__ = [
    "AXIS_TOL",
    "CENTRE_TOL_PX",
    "TRACK_AXIS_TOL",
    "TRACK_GATE_PX",
    "FrameScore",
    "ellipse_of",
    "match_rims",
    "score_frame",
    "summarize",
    "sweep_mot_frames",
]

#: Largest centre error (pixels) of a matched rim.
CENTRE_TOL_PX = 1.0
#: Largest relative error of each semi-axis of a matched rim.
AXIS_TOL = 0.015
#: Largest centre distance (pixels) of a track's ellipse to a rim of its wafer.
TRACK_GATE_PX = 3.0
#: Largest relative semi-axis error of a track's ellipse to that rim.
TRACK_AXIS_TOL = 0.05


def ellipse_of(det: Any) -> NDArray[np.float64]:
    """``(cx, cy, a, b, theta)`` of a detection, an ellipse, or 5 numbers."""
    e = getattr(det, "ellipse", det)
    if hasattr(e, "cx"):
        return np.array([e.cx, e.cy, e.a, e.b, e.theta], dtype=np.float64)
    arr = np.asarray(e, dtype=np.float64).reshape(-1)
    if arr.shape != (5,) or not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"a detection's ellipse must be 5 finite numbers (cx, cy, a, b, theta), got {e!r}")
    return arr


def _errors(det: NDArray[np.float64], rim: RimTruth) -> tuple[float, float]:
    e = rim.ellipse
    centre = math.hypot(det[0] - e.cx, det[1] - e.cy)
    axis = max(abs(det[2] - e.a) / e.a, abs(det[3] - e.b) / e.b)
    return centre, axis


def match_rims(
    detections: Sequence[Any],
    rims: Sequence[RimTruth],
    centre_tol: float = CENTRE_TOL_PX,
    axis_tol: float = AXIS_TOL,
) -> list[tuple[int, int, float]]:
    """One-to-one matches ``(detection index, rim index, centre error)`` meeting both tolerances.

    The assignment minimises the total centre error among the admissible pairs (most pairs first).
    """
    dets = [ellipse_of(d) for d in detections]
    if not dets or not rims:
        return []
    cost = np.full((len(dets), len(rims)), np.inf)
    for i, d in enumerate(dets):
        for j, r in enumerate(rims):
            ce, ae = _errors(d, r)
            if ce <= centre_tol and ae <= axis_tol:
                cost[i, j] = ce
    if not np.isfinite(cost).any():
        return []
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c), float(cost[r, c])) for r, c in zip(rows, cols, strict=True) if np.isfinite(cost[r, c])]


@dataclass
class FrameScore:
    """Counts of one frame (add them up with :func:`summarize`).

    Attributes:
        visible: Visible rims.
        found: Visible rims matched.
        detections: Detections.
        ignored: Detections matched to present rims that are not visible.
        matched: Detections matched to visible rims (= ``found``).
        kind_correct: Of those, detections whose ``kind`` agrees with the rim's.
        kind_known: Of those, detections that carry a ``kind``.
        centre_errors: Centre errors of the matches to visible rims (pixels).
        axis_errors: Larger relative semi-axis error of those matches.
        seconds: Detection time, if measured.

    """

    visible: int = 0
    found: int = 0
    detections: int = 0
    ignored: int = 0
    matched: int = 0
    kind_correct: int = 0
    kind_known: int = 0
    centre_errors: list[float] = field(default_factory=list)
    axis_errors: list[float] = field(default_factory=list)
    seconds: float = math.nan


def score_frame(detections: Sequence[Any], scene: CarrierScene, seconds: float = math.nan) -> FrameScore:
    """Score one frame's detections against the scene's rims (see the module docstring)."""
    rims = scene.rims
    pairs = match_rims(detections, rims)
    s = FrameScore(visible=sum(r.visible for r in rims), detections=len(detections), seconds=seconds)
    for i, j, ce in pairs:
        rim = rims[j]
        if not rim.visible:
            s.ignored += 1
            continue
        s.found += 1
        s.matched += 1
        s.centre_errors.append(ce)
        s.axis_errors.append(_errors(ellipse_of(detections[i]), rim)[1])
        kind = getattr(detections[i], "kind", None)
        if kind is not None:
            s.kind_known += 1
            s.kind_correct += str(kind).lower().rsplit(".", 1)[-1] == rim.kind
    return s


def summarize(scores: Iterable[FrameScore]) -> dict[str, float]:
    """Recall, precision, F-measure, median centre error and time over frames."""
    scores = list(scores)
    visible = sum(s.visible for s in scores)
    found = sum(s.found for s in scores)
    counted = sum(s.detections - s.ignored for s in scores)
    matched = sum(s.matched for s in scores)
    ce = [e for s in scores for e in s.centre_errors]
    ae = [e for s in scores for e in s.axis_errors]
    times = [s.seconds for s in scores if math.isfinite(s.seconds)]
    known = sum(s.kind_known for s in scores)
    recall = found / visible if visible else math.nan
    precision = matched / counted if counted else (1.0 if visible == 0 else math.nan)
    if counted == 0:
        precision = math.nan
    f1 = 2 * recall * precision / (recall + precision) if recall + precision > 0 else 0.0
    return {
        "frames": float(len(scores)),
        "visible_rims": float(visible),
        "found": float(found),
        "detections": float(sum(s.detections for s in scores)),
        "recall": recall,
        "precision": precision,
        "f1": f1,
        "median_centre_error_px": float(np.median(ce)) if ce else math.nan,
        "median_axis_error_rel": float(np.median(ae)) if ae else math.nan,
        "kind_accuracy": sum(s.kind_correct for s in scores) / known if known else math.nan,
        "median_time_ms": 1e3 * float(np.median(times)) if times else math.nan,
    }


def _track_distance(ell: NDArray[np.float64], scene_rims: Sequence[RimTruth]) -> float:
    best = math.inf
    for r in scene_rims:
        ce, ae = _errors(ell, r)
        if ae <= TRACK_AXIS_TOL and ce <= TRACK_GATE_PX:
            best = min(best, ce)
    return best


def sweep_mot_frames(
    scenes: Sequence[CarrierScene], frame_tracks: Sequence[Sequence[tuple[Any, Any]]]
) -> list[tuple[list[int], list[Any], NDArray[np.float64]]]:
    """Per-frame ``(gt_ids, hyp_ids, dists)`` for :func:`autoteach.track.clear_mot`.

    Args:
        scenes: The sweep's scenes.
        frame_tracks: Per frame, ``(track id, ellipse)`` of the tracks registered in that frame.

    Returns:
        Ground truth: the slots of the wafers with a visible rim; distances: centre distance of a
        track's ellipse to the nearer rim of the wafer, ``inf`` outside the gates.

    """
    if len(scenes) != len(frame_tracks):
        raise InvalidInputError(f"{len(scenes)} scenes but {len(frame_tracks)} frames of tracks")
    out = []
    for scene, tracks in zip(scenes, frame_tracks, strict=True):
        gt = [w for w in scene.wafers if w.present and ((w.upper and w.upper.visible) or (w.lower and w.lower.visible))]
        hyp = list(tracks)
        d = np.full((len(gt), len(hyp)), np.inf)
        for i, w in enumerate(gt):
            rims = [r for r in (w.upper, w.lower) if r is not None]
            for j, (_, ell) in enumerate(hyp):
                d[i, j] = _track_distance(ellipse_of(ell), rims)
        out.append(([w.slot for w in gt], [t for t, _ in hyp], d))
    return out
