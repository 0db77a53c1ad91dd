"""The appearance-randomised scene generator (issue 42) and its scoring, against independent truths."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.special import ndtr

from autoteach.errors import InvalidInputError
from autoteach.geometry import Ellipse
from autoteach.sim.appearance import (
    FAMILIES,
    MAX_SLOTS,
    CarrierScene,
    draw_params,
    edge_coverage,
    render_carrier_image,
    render_sweep,
)
from autoteach.sim.appearance_eval import match_rims, score_frame, summarize, sweep_mot_frames

# A clean render: no noise, no lighting, no texture, a flat edge face (the radiometric model alone).
CLEAN = {
    "noise_sigma": 0.0,
    "shot_noise": 0.0,
    "gamma": 1.0,
    "vignetting": 0.0,
    "gradient": (0.0, 0.0),
    "light_spot": 0.0,
    "background_texture": 0.0,
    "face_texture": 0.0,
    "side_shading": 0.0,
    "side_spread": 0.0,
    "roll": 0.0,
}


@pytest.mark.parametrize("sigma", [0.0, 0.4, 1.3])
def test_edge_coverage_matches_numerical_integration(sigma: float) -> None:
    """Closed-form trapezoid ⊗ Gaussian ESF against brute-force integration over the pixel square."""
    rng = np.random.default_rng(5)
    g = (np.arange(400) + 0.5) / 400 - 0.5
    ux, uy = np.meshgrid(g, g)
    for _ in range(12):
        d = rng.uniform(-2.5, 2.5)
        ang = rng.uniform(0, 2 * math.pi)
        nx, ny = math.cos(ang), math.sin(ang)
        s = ux * nx + uy * ny + d  # signed distance of each point of the pixel square
        ref = float(np.mean(ndtr(-s / sigma))) if sigma > 0 else float(np.mean(s < 0))
        got = float(edge_coverage(np.array([d]), np.array([nx]), np.array([ny]), sigma)[0])
        assert got == pytest.approx(ref, abs=3e-3 if sigma == 0 else 2e-5)


def test_truth_points_lie_on_project_circle_ellipse() -> None:
    """The rim samples (own pinhole projection of the 3-D circle) lie on the library's projected ellipse."""
    scene = render_carrier_image("bright_face", 4)
    for rim in scene.rims:
        d = rim.ellipse.distance(rim.points)
        assert np.max(np.abs(d)) < 1e-6
    # Upper rim of a wafer above the camera's line of sight... here the camera is above: the upper
    # rim is the camera-side one and lies higher in the image (smaller v at the front).
    for w in scene.wafers:
        if w.present:
            assert w.upper.camera_side and not w.lower.camera_side
            assert w.upper.ellipse.cy < w.lower.ellipse.cy


def _top_wafer_scene(family: str, **extra: object) -> CarrierScene:
    kw = {**CLEAN, "wafers": 1, "wafer_thickness": 0.001, "distance": 0.36, "wafer_radius": 0.15}
    kw.update(extra)
    return render_carrier_image(family, 21, **kw)


def _front_columns(e: Ellipse, n: int = 40) -> np.ndarray:
    """Columns across the middle half of the front arc."""
    return np.round(np.linspace(e.cx - 0.5 * e.a, e.cx + 0.5 * e.a, n)).astype(int)


def _row_crossing(e: Ellipse, x: float, front: bool = True) -> float:
    """Row where column ``x`` crosses the ellipse (the front = larger row), from its conic."""
    A, B, C, D, E, F = e.conic_coefficients()
    qa, qb, qc = C, B * x + E, A * x * x + D * x + F
    r = math.sqrt(qb * qb - 4 * qa * qc)
    y1, y2 = (-qb - r) / (2 * qa), (-qb + r) / (2 * qa)
    return max(y1, y2) if front else min(y1, y2)


def test_half_level_crossing_of_bright_face_band_is_at_the_true_rim() -> None:
    scene = _top_wafer_scene("bright_face", blur_sigma=0.5)
    p = scene.params
    w = scene.wafers[0]
    img = scene.image.astype(np.float64)
    errs_u, errs_l = [], []
    for x in _front_columns(w.upper.ellipse):
        yu, yl = _row_crossing(w.upper.ellipse, x), _row_crossing(w.lower.ellipse, x)
        assert yl - yu > 2.0  # the band is resolved
        col = img[:, x]
        # Upper rim: face (above) to band (below); lower rim: band to background.
        for y_true, hi_lo, errs in ((yu, (p.face, p.side), errs_u), (yl, (p.side, p.background), errs_l)):
            level = 0.5 * (hi_lo[0] + hi_lo[1])
            i = int(math.floor(y_true))
            v0, v1 = col[i] - level, col[i + 1] - level
            assert v0 * v1 <= 0, (x, y_true, col[i - 2 : i + 3])
            errs.append(i + v0 / (v0 - v1) - y_true)
    assert np.max(np.abs(errs_u)) < 0.1 and np.max(np.abs(errs_l)) < 0.1
    assert abs(np.median(errs_u)) < 0.03 and abs(np.median(errs_l)) < 0.03


def test_thin_line_peaks_at_the_rim() -> None:
    # Equal levels either side, so the profile is the line alone (on a step the sum peaks off-centre).
    scene = _top_wafer_scene("thin_lines", blur_sigma=0.8, line_width=1.0, face=20.0, side=20.0, background=20.0)
    w = scene.wafers[0]
    img = scene.image.astype(np.float64)
    errs = []
    for rim in (w.upper, w.lower):
        for x in _front_columns(rim.ellipse):
            y_true = _row_crossing(rim.ellipse, x)
            i = int(round(y_true))
            a, b, c = img[i - 1, x], img[i, x], img[i + 1, x]
            assert b >= a and b >= c
            errs.append(i + 0.5 * (a - c) / (a - 2 * b + c) - y_true)
    assert np.max(np.abs(errs)) < 0.1


def test_deterministic_for_a_seed() -> None:
    a = render_carrier_image("clutter", 8, wafers=3)
    b = render_carrier_image("clutter", 8, wafers=3)
    c = render_carrier_image("clutter", 9, wafers=3)
    assert np.array_equal(a.image, b.image)
    assert [r.ellipse.as_array().tolist() for r in a.rims] == [r.ellipse.as_array().tolist() for r in b.rims]
    assert not np.array_equal(a.image, c.image)
    # Overriding the noise keeps the rest of the draw.
    d = render_carrier_image("clutter", 8, wafers=3, noise_sigma=0.0)
    assert dataclasses.replace(d.params, noise_sigma=a.params.noise_sigma) == a.params
    assert np.abs(d.image.astype(int) - a.image.astype(int)).mean() < 3 * a.params.noise_sigma


# Documented ranges (docs/design/appearance-generator.md), checked on drawn parameters.
RANGES = {
    "blur_noise": {"blur_sigma": (0.5, 2.0), "noise_sigma": (2.0, 8.0)},
    "lighting": {"gamma": (0.4, 2.5), "vignetting": (0.3, 0.7)},
    "clutter": {"blobs": (3, 12), "carrier_lines": (2, 6), "reflection": (0.15, 0.5)},
    "occlusion": {"occluders": (1, 3)},
    "thin_lines": {"line": (90, 220), "line_width": (0.6, 1.5)},
    "elevation": {"near_semi_minor": (3.0, 150.0)},
}


@pytest.mark.parametrize("family", FAMILIES)
def test_every_family_renders_in_its_ranges(family: str) -> None:
    for seed in (0, 1):
        s = render_carrier_image(family, seed)
        p = s.params
        assert s.image.dtype == np.uint8 and s.image.shape == (720, 1280)
        assert 0.0005 <= p.wafer_thickness <= 0.001 and p.wafer_radius in (0.075, 0.1, 0.15)
        assert 1 <= len(p.present) <= MAX_SLOTS and any(p.present)
        assert len(s.wafers) == len(p.present)
        for name, (lo, hi) in RANGES.get(family, {}).items():
            assert lo <= getattr(p, name) <= hi, (name, getattr(p, name))
        if family == "low_contrast":
            assert 8 <= p.side - p.background <= 20
        assert s.visible_rims, family
        # The truth's semi-axes: the image of a wafer of radius R at distance ≈ D.
        for r in s.rims:
            assert r.ellipse.a == pytest.approx(p.focal_length * p.wafer_radius / p.distance, rel=0.35)


def test_elevation_spans_semi_minor_axes() -> None:
    bs = [min(r.ellipse.b for r in render_carrier_image("elevation", i, wafers=2).rims) for i in range(8)]
    assert min(bs) < 8 and max(bs) > 40


def test_sparse_stack_has_missing_slots() -> None:
    counts = [draw_params("sparse_stack", i).present for i in range(10)]
    assert any(not all(c) for c in counts)
    assert {len(c) for c in counts} - {1} and max(len(c) for c in counts) <= MAX_SLOTS


def test_occlusion_marks_occluded_samples() -> None:
    fracs = []
    for i in range(4):
        s = render_carrier_image("occlusion", i)
        fracs.append(np.mean([r.occluded[r.in_image].mean() for r in s.rims if r.in_image.any()]))
    assert max(fracs) > 0.02


def test_sweep_keeps_identities_and_moves_the_camera() -> None:
    scenes = render_sweep("bright_face", 3, frames=3, wafers=4)
    assert [w.slot for w in scenes[0].wafers] == [1, 2, 3, 4]
    assert all([w.slot for w in s.wafers] == [1, 2, 3, 4] for s in scenes)
    assert scenes[0].params == scenes[2].params
    shift = scenes[2].wafers[0].upper.ellipse.cx - scenes[0].wafers[0].upper.ellipse.cx
    assert abs(shift) > 20
    assert not np.array_equal(scenes[0].image, scenes[1].image)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"wafers": 0},
        {"wafers": 13},
        {"wafers": 2.5},
        {"no_such_parameter": 1},
        {"noise_sigma": -1.0},
        {"blur_sigma": float("nan")},
        {"present": (False, False)},
    ],
)
def test_bad_input_raises(kwargs: dict) -> None:
    with pytest.raises(InvalidInputError):
        render_carrier_image("bright_face", 0, **kwargs)


def test_bad_family_seed_frames() -> None:
    with pytest.raises(InvalidInputError, match="unknown appearance family"):
        render_carrier_image("fog", 0)
    with pytest.raises(InvalidInputError):
        draw_params("bright_face", -1)
    with pytest.raises(InvalidInputError):
        render_sweep("bright_face", 0, frames=0)
    with pytest.raises(InvalidInputError):
        render_sweep("bright_face", 0, wafers=20)


def test_metric_known_answer() -> None:
    """Hand-made detections with known matches: the recall, precision and centre error are exact."""
    scene = render_carrier_image("bright_face", 4, wafers=2)
    vis = scene.visible_rims
    assert len(vis) >= 3
    e0, e1, e2 = (r.ellipse for r in vis[:3])
    dets = [
        Ellipse(e0.cx + 0.6, e0.cy, e0.a, e0.b, e0.theta),  # match, error 0.6
        Ellipse(e1.cx, e1.cy - 0.3, e1.a * 1.01, e1.b, e1.theta),  # match, error 0.3
        Ellipse(e1.cx + 0.1, e1.cy, e1.a, e1.b, e1.theta),  # better match for e1: error 0.1 wins
        Ellipse(e2.cx + 1.5, e2.cy, e2.a, e2.b, e2.theta),  # centre off: false
        Ellipse(e2.cx, e2.cy, e2.a, e2.b * 1.02, e2.theta),  # axis off by 2 %: false
        Ellipse(100.0, 100.0, 50.0, 10.0, 0.0),  # clutter: false
    ]
    pairs = match_rims(dets, vis[:3])
    assert sorted((i, j) for i, j, _ in pairs) == [(0, 0), (2, 1)]
    s = score_frame(dets, scene)
    assert s.found == 2 and s.detections == 6 and s.visible == len(vis)
    out = summarize([s])
    assert out["recall"] == pytest.approx(2 / len(vis))
    assert out["precision"] == pytest.approx(2 / 6)
    assert out["median_centre_error_px"] == pytest.approx(0.35, abs=1e-9)


def test_mot_frames_known_answer() -> None:
    from autoteach.track import clear_mot

    scenes = render_sweep("bright_face", 5, frames=3, wafers=2)
    # Track 7 follows slot 1's upper rim; track 8 follows slot 2 but switches to 9 in the last frame.
    frames = []
    for k, s in enumerate(scenes):
        w1, w2 = s.wafers[0].upper.ellipse, s.wafers[1].upper.ellipse
        frames.append([(7, w1), (8 if k < 2 else 9, w2)])
    out = clear_mot(sweep_mot_frames(scenes, frames))
    n_gt = sum(sum(1 for w in s.wafers if w.upper.visible or w.lower.visible) for s in scenes)
    assert out["num_gt"] == n_gt == 6
    assert out["idsw"] == 1 and out["fn"] == 0 and out["fp"] == 0
    assert out["mota"] == pytest.approx(1 - 1 / 6)


def test_detect_wafers_on_an_easy_image() -> None:
    """The current detector on one clean bright-face image, scored two ways that must agree.

    The rims of the scene are more than 2 px apart and the match gate is 1 px, so each detection
    can match at most one rim: a brute-force count of detections within the gates of a visible
    rim equals the one-to-one assignment's count.
    """
    from autoteach.detect import detect_wafers

    scene = render_carrier_image("bright_face", 2, wafers=3, noise_sigma=1.0)
    dets = detect_wafers(scene.image)
    s = score_frame(dets, scene)
    rims = scene.rims
    centres = np.array([[r.ellipse.cx, r.ellipse.cy] for r in rims])
    assert min(np.hypot(*(a - b)) for i, a in enumerate(centres) for b in centres[i + 1 :]) > 2.0
    hits = set()
    for d in dets:
        e = d.ellipse
        for j, r in enumerate(rims):
            t = r.ellipse
            if (
                math.hypot(e.cx - t.cx, e.cy - t.cy) <= 1.0
                and abs(e.a / t.a - 1) <= 0.015
                and abs(e.b / t.b - 1) <= 0.015
                and r.visible
            ):
                hits.add(j)
    assert s.found == len(hits) >= 2
    assert s.visible == sum(r.visible for r in rims) and s.detections == len(dets)


@pytest.mark.parametrize("sigma", [0.0, 0.7, 2.0])
def test_coverage_table_matches_closed_form(sigma: float) -> None:
    from autoteach.sim.appearance import _coverage_table

    rng = np.random.default_rng(2)
    d = rng.uniform(-12, 12, 5000)
    ang = rng.uniform(0, 2 * math.pi, 5000)
    nx, ny = np.cos(ang), np.sin(ang)
    tol = 5e-4 if sigma == 0 else 2e-4  # the box-only profile has kinks
    assert np.max(np.abs(_coverage_table(sigma)(d, nx, ny) - edge_coverage(d, nx, ny, sigma))) < tol


def test_band_distances_match_orthogonal_distance() -> None:
    """The renderer's band distances (Sampson where the curve is flat, exact elsewhere) against exact ones."""
    from autoteach.sim.appearance import _Boundary, _Conic, _window

    cases = [(640.3, 360.2, 375.0, 25.0, 0.02), (600.0, 300.0, 200.0, 3.0, -0.05), (600.0, 300.0, 350.0, 1.0, 0.0)]
    for e in (Ellipse(*c) for c in cases + [(600.0, 300.0, 150.0, 140.0, 0.5)]):
        c = _Conic(e)
        win = _window([c], 8, 1280, 720)
        b = _Boundary(c, win, 12.0)
        exact = e.distance(np.column_stack([win.bx, win.by]))
        assert np.max(np.abs(b.d - exact)) < 0.005
        near = np.abs(exact) < 3.0
        assert np.max(np.abs(b.d - exact)[near]) < 0.0025


def test_scenes_command_writes_pgm_and_truth(tmp_path: object) -> None:
    import json
    import pathlib

    from autoteach.cli import main

    out = pathlib.Path(str(tmp_path))
    assert main(["scenes", "--family", "dark_face", "--seed", "3", "--out", str(out), "--quiet"]) == 0
    raw = (out / "dark_face_3.pgm").read_bytes()
    header = b"P5\n1280 720\n255\n"
    assert raw.startswith(header) and len(raw) == len(header) + 1280 * 720
    truth = json.loads((out / "dark_face_3.json").read_text())
    scene = render_carrier_image("dark_face", 3)
    assert np.array_equal(np.frombuffer(raw[len(header) :], np.uint8).reshape(720, 1280), scene.image)
    w = next(w for w in scene.wafers if w.present)
    assert truth["wafers"][0]["upper"]["ellipse"] == w.upper.ellipse.as_array().tolist()


def test_jpeg_like_matches_opencv_closely() -> None:
    """The JPEG-like step against OpenCV's real JPEG codec at the same quality (same luminance table)."""
    import cv2

    from autoteach.sim.appearance import jpeg_like

    img = render_carrier_image("bright_face", 6).image
    for q in (50, 90):
        ours = jpeg_like(img, q).astype(int)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, q])
        ref = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE).astype(int)
        assert np.mean(np.abs(ours - ref)) < 0.5
        assert np.mean(np.abs(ours - img.astype(int))) > 0.1  # it does change the image


def test_tilted_wafers_truth_on_projected_circle() -> None:
    s = render_carrier_image("bright_face", 12, tilt_sigma=0.01, shift_sigma=0.002)
    for w in s.wafers:
        if w.present:
            assert abs(np.linalg.norm(w.normal) - 1) < 1e-12 and w.normal[2] < 1 - 1e-6
            for r in (w.upper, w.lower):
                assert np.max(np.abs(r.ellipse.distance(r.points))) < 1e-6
