"""Tests of autoteach.track.WaferTracker on simulated carrier sweeps and on bad input.

Truth: the simulator's ground-truth rims (each edge carries the wafer it came from), scored with
the CLEAR MOT / IDF1 code of autoteach.track (itself checked against py-motmetrics in
test_track_metrics.py).
"""

from __future__ import annotations

import enum
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from autoteach.errors import AutoteachError, InvalidInputError
from autoteach.geometry import Ellipse
from autoteach.track import Edge, WaferTracker, synthetic_detections, track_frames, track_log

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from tracking import evaluate, scenario  # noqa: E402


def _arc(cy: float, wafer_id: int, kind: str = "upper", n: int = 120) -> dict[str, Any]:
    t = np.linspace(0.2, 2.9, n)
    pts = np.stack([640.0 + 300.0 * np.cos(t), cy + 30.0 * np.sin(t)], axis=1)
    return {"ellipse": (640.0, cy, 300.0, 30.0, 0.0), "points": pts, "kind": kind, "wafer_id": wafer_id}


def _stack(n: int, shift: float) -> list[dict[str, Any]]:
    out = []
    for w in range(n):
        out.append(_arc(100.0 + 20.0 * w + shift, w, "upper"))
        out.append(_arc(102.5 + 20.0 * w + shift, w, "lower"))
    return out


@pytest.fixture(scope="module")
def sweep() -> tuple[Any, list[list[Edge]]]:
    # The benchmark's sequence length: on 60 frames the greedy baseline, which shares the
    # multi-view 3D predictions, happens to make no identity change.
    session = scenario(12, seed=0, frames=100)
    return session, synthetic_detections(session, seed=0)


def test_sweep_hierarchical_beats_greedy(sweep: tuple[Any, list[list[Edge]]]) -> None:
    session, dets = sweep
    ours = evaluate(session, dets, associator="hierarchical")
    base = evaluate(session, dets, associator="greedy")
    assert ours["mota"] >= 0.98, ours
    assert ours["idf1"] >= 0.98, ours
    assert ours["neighbour_changes"] == 0, ours
    assert base["changes"] > 0, base
    assert base["idsw"] > ours["idsw"], (base, ours)
    assert base["idf1"] < ours["idf1"]


def test_sweep_is_deterministic(sweep: tuple[Any, list[list[Edge]]]) -> None:
    session, dets = sweep
    a = track_frames(dets[:40], session.camera_poses[:40])
    b = track_frames(dets[:40], session.camera_poses[:40])
    assert a.frame_assignments == b.frame_assignments


class Kind(enum.Enum):
    """A detector's own rim-kind enum."""

    UPPER = "upper"
    LOWER = "lower"


def test_accepts_dicts_edges_and_objects() -> None:
    tracker = WaferTracker(min_hits=1)
    frame = _stack(3, 0.0)
    tracks = tracker.update(frame)
    assert [t.id for t in tracks] == [0, 1, 2]
    # The same wafers as Edge objects with geometry.Ellipse and an enum kind, in reverse order.
    objs = []
    for d in reversed(_stack(3, 4.0)):
        e = Edge(ellipse=np.asarray(d["ellipse"]), points=d["points"], kind=d["kind"], wafer_id=d["wafer_id"])
        e.ellipse = Ellipse(*d["ellipse"])  # type: ignore[assignment]
        e.kind = Kind.UPPER if d["kind"] == "upper" else Kind.LOWER  # type: ignore[assignment]
        objs.append(e)
    tracks = tracker.update(objs)
    assert len(tracks) == 3
    for t in tracks:
        assert t.visible and len(t.history) == 4
        cys = [e["ellipse"][1] if isinstance(e, dict) else e.ellipse.cy for _, e in t.history if _ == 0]
        assert t.ellipse is not None
        assert t.ellipse.cy - min(cys) == pytest.approx(4.0)


def test_bad_input_raises_and_keeps_state() -> None:
    tracker = WaferTracker()
    tracker.update(_stack(2, 0.0))
    bad = _stack(2, 1.0)
    bad[1]["points"][3, 0] = np.nan
    with pytest.raises(AutoteachError):
        tracker.update(bad)
    bad = _stack(2, 1.0)
    bad[0]["kind"] = "middle"
    with pytest.raises(InvalidInputError):
        tracker.update(bad)
    with pytest.raises(InvalidInputError):
        tracker.update([{"ellipse": (1.0, 2.0, 3.0), "points": np.zeros((3, 2))}])
    with pytest.raises(InvalidInputError):
        tracker.update(_stack(2, 1.0), camera_pose=np.eye(3))
    with pytest.raises(InvalidInputError):
        WaferTracker(sigma=-1.0)
    with pytest.raises(InvalidInputError):
        WaferTracker(associator="nearest")
    for pitch in (0.0, -0.01, float("nan")):
        with pytest.raises(InvalidInputError):
            WaferTracker(slot_pitch=pitch)
    assert tracker.frame == 1


def test_empty_frames_spurious_arcs_and_duplicates() -> None:
    rng = np.random.default_rng(5)
    tracker = WaferTracker(max_missed=10)
    tracker.update(_stack(8, 0.0))
    tracker.update(_stack(8, 3.0))
    ids = [t.id for t in tracker.tracks()]
    for _ in range(3):
        assert len(tracker.update([])) == 8
    frame = _stack(8, 12.0)
    frame += [dict(d) for d in frame]  # duplicated edges
    for k in range(300):
        t0 = rng.uniform(-3.0, 3.0)
        t = np.linspace(t0, t0 + 0.5, 25)
        a, b = rng.uniform(20.0, 300.0), rng.uniform(3.0, 15.0)
        c = rng.uniform([0.0, 0.0], [1280.0, 720.0])
        pts = np.stack([c[0] + a * np.cos(t), c[1] + b * np.sin(t)], axis=1)
        frame.append({"ellipse": (c[0], c[1], a, b, 0.0), "points": pts, "kind": "upper", "wafer_id": 1000 + k})
    tracks = tracker.update(frame)
    assert [t.id for t in tracks] == ids
    assert all(t.visible for t in tracks)
    assert len(tracker.update(_stack(8, 15.0))) == 8
    assert len(tracker.tracks(include_tentative=True)) == 8


def test_track_log_runs_over_a_session_log(tmp_path: Path) -> None:
    from autoteach.io import write_log

    session = scenario(12, seed=2, frames=30)
    dets = synthetic_detections(session, seed=2)
    path = tmp_path / "sweep.mcap"
    write_log(session, path)
    frames = iter(dets)
    tracker = track_log(path, detector=lambda image: next(frames))
    assert tracker.frame == 30
    direct = track_frames(
        dets,
        session.camera_poses,
        intrinsics=[[1000.0, 0.0, 639.5], [0.0, 1000.0, 359.5], [0.0, 0.0, 1.0]],
        image_size=(1280, 720),
    )
    assert tracker.frame_assignments == direct.frame_assignments
    assert len(tracker.all_tracks()) >= 10
