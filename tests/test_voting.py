"""Tests of autoteach.polygon.global_voting (seed 000_3b1454b2b2194811.txt §3.4, Algorithm 3).

Truth: known rigid transforms applied to model point sets (2-D and 3-D, with clutter and across
the ±π wrap), and the density-mismatch case of Fig. 3.12 where counting pairs must pick a wrong
transform and counting distinct Y points (Y-count) the right one.
"""

from __future__ import annotations

import numpy as np
import pytest

from autoteach.errors import DegenerateGeometryError, InvalidInputError
from autoteach.polygon import global_voting, vote_cells


def _rot2(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def _polyline(vertices: list[tuple[float, float]], spacing: float) -> np.ndarray:
    pts = []
    for a, b in zip(vertices[:-1], vertices[1:], strict=False):
        a, b = np.asarray(a), np.asarray(b)
        n = int(round(np.linalg.norm(b - a) / spacing))
        pts.extend(a + (b - a) * k / n for k in range(n))
    return np.array(pts)


CHEVRON = [(0.0, 0.0), (2.0, 1.0), (3.2, -0.4), (2.7, -0.9)]


def _placement_error(h, rot: np.ndarray, t: np.ndarray, model: np.ndarray) -> float:
    """RMS distance between the model moved by the hypothesis and by the truth."""
    return float(np.sqrt(np.mean(np.sum((h.apply(model) - (model @ rot.T + t)) ** 2, axis=1))))


@pytest.mark.parametrize("angle_deg", [179.5, -179.5, 90.0, 0.0, -45.0])
def test_recovers_2d_transform_in_clutter(angle_deg: float) -> None:
    rng = np.random.default_rng(5)
    y = _polyline(CHEVRON, 0.05)
    rot, t = _rot2(np.radians(angle_deg)), np.array([4.0, -2.0])
    x = np.vstack([y @ rot.T + t + rng.normal(0, 0.003, y.shape), rng.uniform([-1, -6], [9, 3], (80, 2))])
    hyps = global_voting(x, y, k=3)
    assert 1 <= len(hyps) <= 3
    best = hyps[0]
    assert _placement_error(best, rot, t, y) < 0.1  # a voting cell: an initialiser, ~3 % of the size
    assert abs(np.linalg.det(best.rotation) - 1.0) < 1e-9
    assert best.pair_votes >= best.votes > 0.8 * len(y)
    # Best first.
    assert all(a.votes >= b.votes for a, b in zip(hyps, hyps[1:], strict=False))


def test_recovers_3d_transform() -> None:
    rng = np.random.default_rng(2)
    s = np.linspace(0, 3, 150)
    helix = np.c_[np.cos(s), np.sin(s), 0.3 * s]
    patch = np.c_[rng.uniform(-1, 0, 150), rng.uniform(-0.5, 0.5, 150), np.full(150, -0.5)]
    wall = np.c_[np.full(100, 1.3), rng.uniform(-0.3, 0.3, 100), rng.uniform(0, 0.8, 100)]
    y = np.vstack([helix, patch, wall])
    a, b, c = 2.5, -0.7, -3.0
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    rot, t = rz @ ry @ rx, np.array([0.4, -1.0, 2.0])
    x = y @ rot.T + t
    best = global_voting(x, y, k=1, max_points=200)[0]
    assert _placement_error(best, rot, t, y) < 0.15
    assert best.rotation.shape == (3, 3) and best.translation.shape == (3,)


def _density_mismatch(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fig. 3.12: X = a sparse copy of the model plus a 10× denser straight edge elsewhere."""
    rng = np.random.default_rng(seed)
    y = _polyline(CHEVRON, 0.05)
    rot, t = _rot2(rng.uniform(-np.pi, np.pi)), rng.uniform(-3, 3, 2)
    a = rng.uniform(-np.pi, np.pi)
    start = t + 6.0 * np.array([np.cos(a), np.sin(a)])
    d = np.array([np.cos(a + 1.0), np.sin(a + 1.0)])
    dense = start + np.outer(np.arange(600) * 0.005, d)
    x = np.vstack([y @ rot.T + t, dense])
    return x, y, rot, t


def test_y_count_beats_pair_count_on_density_mismatch() -> None:
    ok_y = ok_pairs = 0
    for seed in range(10):
        x, y, rot, t = _density_mismatch(seed)
        ok_y += _placement_error(global_voting(x, y, k=1)[0], rot, t, y) < 0.1
        ok_pairs += _placement_error(global_voting(x, y, k=1, count="pairs")[0], rot, t, y) < 0.1
    assert ok_y == 10
    assert ok_pairs <= 2


def test_vote_cells_are_consistent_with_global_voting() -> None:
    x, y, rot, t = _density_mismatch(0)
    cells = vote_cells(x, y)
    best = global_voting(x, y, k=1, shifted_grid=False)[0]
    assert cells[0].votes == best.votes and cells[0].pair_votes == best.pair_votes
    assert all(c.votes <= min(c.pair_votes, len(y)) for c in cells)
    assert all(a.votes >= b.votes for a, b in zip(cells, cells[1:], strict=False))


def test_deterministic() -> None:
    x, y, _, _ = _density_mismatch(3)
    a, b = global_voting(x, y), global_voting(x, y)
    assert [(h.votes, h.pair_votes) for h in a] == [(h.votes, h.pair_votes) for h in b]
    assert all(
        np.array_equal(p.rotation, q.rotation) and np.array_equal(p.translation, q.translation)
        for p, q in zip(a, b, strict=True)
    )


def test_bad_input() -> None:
    y = _polyline(CHEVRON, 0.1)
    with pytest.raises(InvalidInputError, match="too few points"):
        global_voting(np.array([[0.0, 0.0], [1.0, 1.0]]), y)
    with pytest.raises(DegenerateGeometryError, match="identical"):
        global_voting(np.ones((10, 2)), y)
    bad = y.copy()
    bad[3, 0] = np.nan
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        global_voting(y, bad)
    with pytest.raises(InvalidInputError, match="dimension"):
        global_voting(y, np.random.default_rng(0).normal(size=(10, 3)))
    with pytest.raises(InvalidInputError):
        global_voting(np.zeros((10, 4)), np.zeros((10, 4)))
    with pytest.raises(InvalidInputError, match="angle_bin"):
        global_voting(y, y, angle_bin=0.0)
    with pytest.raises(InvalidInputError, match="count"):
        global_voting(y, y, count="both")  # type: ignore[arg-type]
