"""Tests of autoteach.polygon.detect_polygon (seed 000_3b1454b2b2194811.txt §3.3, eq. 3.8–3.10).

Truth: the renderer's known opening pose and homography (image centre = H · centre), exact
segments generated from a placed template (closed form: the IRLS fit must return the pose), the
rendered polygon edges for the segment detector, and OpenCV's polygon fill for the renderer.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from autoteach.errors import DegenerateGeometryError, InvalidInputError
from autoteach.polygon import CROSS_TEMPLATE, detect_polygon, detect_segments, render_opening, simulate_opening


def _apply(h: np.ndarray, p: np.ndarray) -> np.ndarray:
    q = np.c_[p, np.ones(len(p))] @ h.T
    return q[:, :2] / q[:, 2:]


def _placed(c: np.ndarray, rot: float, scale: float) -> np.ndarray:
    cs, sn = np.cos(rot), np.sin(rot)
    return c + scale * CROSS_TEMPLATE @ np.array([[cs, sn], [-sn, cs]])


H = np.array([[0.95, -0.2, 250.0], [0.15, 1.05, 170.0], [3e-4, -2e-4, 1.0]])


def test_twenty_simulated_openings_subpixel() -> None:
    errors = []
    for seed in range(20):
        scene = simulate_opening(seed=1000 + seed)
        det = detect_polygon(scene.image, CROSS_TEMPLATE, scene.homography)
        errors.append(float(np.hypot(*(det.centre_image - scene.centre_image))))
    errors = np.array(errors)
    assert np.mean(errors < 1.0) >= 0.95, errors


def test_exact_segments_give_exact_pose() -> None:
    centre, rot, scale = np.array([12.0, -7.0]), 0.06, 1.04
    verts = _apply(H, _placed(centre, rot, scale))
    n = len(verts)
    # Each edge as a shortened segment (20 % cut at both ends), plus clutter segments.
    segs = []
    for k in range(n):
        a, b = verts[k], verts[(k + 1) % n]
        segs.append(np.r_[a + 0.2 * (b - a), a + 0.8 * (b - a)])
    rng = np.random.default_rng(1)
    segs.extend(np.r_[p, p + rng.normal(0, 30, 2)] for p in rng.uniform(0, 480, (15, 2)))
    segs = np.array(segs)
    # The template is CW in these coordinates, so the segments already run with the opening on
    # their left after normalisation only if oriented consistently: use unoriented voting.
    det = detect_polygon(segs, CROSS_TEMPLATE, H, oriented=False)
    assert np.allclose(det.pose.centre, centre, atol=1e-6)
    assert det.pose.rotation == pytest.approx(rot, abs=1e-6)
    assert det.pose.scale == pytest.approx(scale, abs=1e-6)
    assert sorted(det.support[:, 0]) == list(range(n))
    assert det.rms < 1e-6
    assert np.allclose(det.centre_image, _apply(H, centre[None])[0], atol=1e-6)
    assert det.vote_map.data.shape == (det.vote_map.rows, det.vote_map.cols) and det.vote_map.data.max() > 0


def test_segment_detector_finds_rendered_edges() -> None:
    centre = np.array([0.0, 0.0])
    verts = _apply(H, _placed(centre, 0.0, 1.0))
    img = render_opening(480, 360, H, polygons=[(_placed(centre, 0.0, 1.0), 35.0)], blur_sigma=0.8, noise_sigma=2.0)
    segs = detect_segments(img)
    n = len(verts)
    for k in range(n):
        a, b = verts[k], verts[(k + 1) % n]
        d = (b - a) / np.linalg.norm(b - a)
        nrm = np.array([-d[1], d[0]])
        # Best segment on this edge: both end points within 0.3 px of the edge line, direction within 1°.
        best = min(
            max(abs((s[:2] - a) @ nrm), abs((s[2:] - a) @ nrm))
            + (1.0 - abs((s[2:] - s[:2]) @ d) / np.linalg.norm(s[2:] - s[:2])) * 1e3
            for s in segs
        )
        assert best < 0.3, (k, best)


def test_renderer_matches_opencv_fill() -> None:
    poly = _placed(np.array([0.0, 0.0]), 0.1, 1.0) + np.array([240.0, 180.0])
    img = render_opening(480, 360, np.eye(3), plate=200.0, polygons=[(poly, 0.0)], supersample=8)
    ref = np.full((360, 480), 200, np.uint8)
    shift = 4
    cv2.fillPoly(ref, [np.round(poly * (1 << shift)).astype(np.int32)], 0, lineType=cv2.LINE_AA, shift=shift)
    # Interior and exterior agree exactly; only anti-aliased boundary pixels may differ.
    diff = np.abs(img.astype(int) - ref.astype(int))
    assert np.mean(diff > 0) < 0.02
    # Coverage is area: the summed darkness equals the shoelace area of the polygon.
    area = 0.5 * abs(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
    assert np.sum((200.0 - img) / 200.0) == pytest.approx(area, rel=2e-3)


def test_bad_input() -> None:
    scene = simulate_opening(seed=1)
    with pytest.raises(InvalidInputError, match="too few points"):
        detect_polygon(scene.image, CROSS_TEMPLATE[:2], scene.homography)
    with pytest.raises(DegenerateGeometryError, match="singular"):
        detect_polygon(scene.image, CROSS_TEMPLATE, np.zeros((3, 3)))
    h = scene.homography.copy()
    h[0, 0] = np.nan
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        detect_polygon(scene.image, CROSS_TEMPLATE, h)
    with pytest.raises(InvalidInputError, match="unknown polygon option"):
        detect_polygon(scene.image, CROSS_TEMPLATE, scene.homography, cel=3.0)
    with pytest.raises(InvalidInputError, match="cell"):
        detect_polygon(scene.image, CROSS_TEMPLATE, scene.homography, cell=-1.0)
    with pytest.raises(InvalidInputError, match="two-dimensional"):
        detect_polygon(np.zeros((4, 4, 3), np.uint8), CROSS_TEMPLATE, scene.homography)
    segs = np.array([[0.0, 0.0, np.nan, 1.0]])
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        detect_polygon(segs, CROSS_TEMPLATE, scene.homography)
    with pytest.raises(DegenerateGeometryError, match="no segment matched"):
        detect_polygon(np.array([[0.0, 0.0, 1.0, 300.0]]), CROSS_TEMPLATE, scene.homography)


@pytest.mark.parametrize("scale", [1e15, 1e18, 1e300])
def test_huge_templates_are_refused_not_hung(scale) -> None:
    """Regression: at ×1e18 the Hough size product overflowed past its guard and the call hung."""
    scene = simulate_opening(seed=1)
    with pytest.raises(InvalidInputError, match="2·10⁸ cells"):
        detect_polygon(scene.image, CROSS_TEMPLATE * scale, scene.homography)
