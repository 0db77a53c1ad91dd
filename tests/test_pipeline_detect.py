"""The real front end of auto-teaching: detection on rendered frames, tracking, gating by the prior.

A rendered session goes through ``detect_wafers`` on every frame and ``WaferTracker``; the tests
check the slots and every edge association against the simulator's ground truth, the
robustness to missed detections and false arcs, and the errors of the final estimate.
"""

from __future__ import annotations

import numpy as np
import pytest

import autoteach.pipeline as pipeline
from autoteach.errors import InvalidInputError
from autoteach.pipeline import autoteach, polyline_distance, rim_polyline, wafer_params_of
from autoteach.sim import simulate_session


@pytest.fixture(scope="module")
def session():
    return simulate_session(seed=3, frames=40, render=True)


@pytest.fixture(scope="module")
def detections(session):
    return pipeline.detect_all(session.images)


def _run(session, detections, monkeypatch, **kw):
    monkeypatch.setattr(pipeline, "detect_all", lambda images, progress=False: detections)
    return autoteach(session, frontend="detect", seed=3, **kw)


def _k(session):
    fx, fy, cx, cy = session.camera.params[:4]
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _true_rim_of(session, f, points):
    """The (wafer, rim) of the ground truth whose projected rim is nearest to the points."""
    k, cfg = _k(session), session.config
    best = (np.inf, None)
    for w, pose in enumerate(session.wafer_poses):
        for rim in (0, 1):
            poly = rim_polyline(
                k, session.camera_poses[f], wafer_params_of(pose), rim, cfg.wafer_radius, cfg.wafer_thickness
            )
            d = float(np.median(polyline_distance(points, poly)))
            if d < best[0]:
                best = (d, (w, rim))
    return best


def _check_associations(session, r):
    obs = r.observations
    slots = [int(s) for s in session.wafer_slots]
    wrong = 0
    for i, (f, w) in enumerate(zip(obs["frames"], obs["wafers"], strict=True)):
        pts = obs["points"][obs["start"][i] : obs["start"][i + 1]]
        d, (tw, _) = _true_rim_of(session, f, pts)
        wrong += tw != slots.index(int(r.wafer_slots[w]))
    return wrong


def test_detect_frontend_finds_the_slots_and_associates_every_edge(session, detections, monkeypatch):
    r = _run(session, detections, monkeypatch, window=0, baseline=False)
    st = r.frontend_stats
    assert st["spurious_slots"] == [] and st["true_slots_missed"] == []
    assert sorted(int(s) for s in r.wafer_slots) == sorted(int(s) for s in session.wafer_slots)
    assert st["gated"]["frames_used"] == 40 and st["gated"]["rims_used"] == r.n_observations > 200
    assert _check_associations(session, r) == 0
    # Independent truth: errors of the estimate against the simulator (detector-limited figures
    # are in docs/benchmarks.md; these bounds catch a broken front end, not the goals).
    assert r.errors["joint_offset_deg"] < 0.1
    assert r.errors["base_translation_mm"] < 2.0
    assert r.errors["wafer_center_mm"] < 2.0
    assert r.errors["wafer_tilt_deg"] < 0.5
    assert r.rms_px < 0.5


def test_detect_frontend_is_robust_to_missed_detections_and_false_arcs(session, detections, monkeypatch):
    rng = np.random.default_rng(0)
    damaged = []
    for f, edges in enumerate(detections):
        keep = [e for e in edges if rng.random() > 0.4]  # recall cut by 40 %
        if f % 4 == 0:
            keep = []  # frames where nothing is detected
        elif keep:
            # A false arc: a real edge moved by 25 px (a reflection), labelled as its rim.
            e = keep[0]
            keep.append(type(e)(**{**e.__dict__, "points": np.asarray(e.points) + [0.0, 25.0]}))
        damaged.append(keep)
    r = _run(session, damaged, monkeypatch, window=0, baseline=False, use_ukf=False)
    assert r.frontend_stats["spurious_slots"] == []
    assert r.frontend_stats["gated"]["edges_rejected"] > 0
    assert _check_associations(session, r) == 0
    assert r.errors["joint_offset_deg"] < 0.15
    # Wafers left with too few views are reported as not estimated, never as numbers.
    sparse = r.frontend_stats["gated"]["wafers_too_few_views"]
    for slot in sparse:
        w = list(r.wafer_slots).index(slot)
        assert np.all(np.isnan(r.wafer_params[w]))
    assert len(sparse) <= 2
    assert r.errors["wafer_center_mm"] < 1.0


def test_no_detection_in_any_frame_is_a_clear_error(session, monkeypatch):
    with pytest.raises(InvalidInputError, match="no wafer"):
        _run(session, [[] for _ in range(session.n_frames)], monkeypatch)


def test_rim_polyline_passes_through_the_simulated_rim_points(session):
    # Independent truth: the renderer's visible rim samples lie on the projected circle.
    k, cfg = _k(session), session.config
    f = 10
    for rec in session.rims[f][:6]:
        pts = np.asarray(rec["points"]).reshape(-1, 2)
        if len(pts) == 0:
            continue
        poly = rim_polyline(
            k,
            session.camera_poses[f],
            wafer_params_of(session.wafer_poses[rec["wafer"]]),
            0 if rec["rim"] == "upper" else 1,
            cfg.wafer_radius,
            cfg.wafer_thickness,
        )
        assert np.max(polyline_distance(pts, poly)) < 0.05


def test_polyline_distance_matches_the_closed_form_for_a_circle():
    ang = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    poly = np.stack([100 + 50 * np.cos(ang), 80 + 50 * np.sin(ang)], axis=1)
    pts = np.array([[100.0, 80.0], [160.0, 80.0], [100.0, 133.0], [130.0, 120.0]])
    truth = np.abs(np.hypot(pts[:, 0] - 100, pts[:, 1] - 80) - 50)
    np.testing.assert_allclose(polyline_distance(pts, poly), truth, atol=2e-3)
