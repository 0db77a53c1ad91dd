"""Tests of autoteach.detect.fit_ellipses (many arcs in one call) against per-arc fits and OpenCV."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autoteach.detect import fit_ellipse, fit_ellipses
from autoteach.errors import InvalidInputError
from autoteach.geometry import Ellipse


def _arcs(count: int, seed: int) -> tuple[list[tuple[float, float, float, float, float]], list[np.ndarray]]:
    """90–160° arcs, a = 150–350 px, b/a = 0.2–1, one point per pixel, 0.5 px noise (float32-exact)."""
    rng = np.random.default_rng(seed)
    truths, arcs = [], []
    for _ in range(count):
        a = rng.uniform(150.0, 350.0)
        e = Ellipse(rng.uniform(300, 900), rng.uniform(300, 700), a, a * rng.uniform(0.2, 1.0), rng.uniform(-3, 3))
        span = math.radians(rng.uniform(90.0, 160.0))
        t0 = rng.uniform(-math.pi, math.pi)
        n = max(20, int(0.5 * (e.a + e.b) * span))
        pts = e.sample(n, t0, t0 + span) + rng.normal(0.0, 0.5, (n, 2))
        truths.append((e.cx, e.cy, e.a, e.b, e.theta))
        arcs.append(pts.astype(np.float32).astype(np.float64))
    return truths, arcs


def _offsets(arcs: list[np.ndarray]) -> np.ndarray:
    return np.cumsum([0] + [len(a) for a in arcs])


@pytest.mark.parametrize("method", ["geometric", "direct"])
def test_batch_equals_one_fit_per_arc(method: str) -> None:
    _, arcs = _arcs(40, 1)
    fits = fit_ellipses(np.concatenate(arcs), _offsets(arcs), method=method)
    assert len(fits) == 40 and fits.ok.all()
    for k, pts in enumerate(arcs):
        one = fit_ellipse(pts, method=method)
        e = one.ellipse
        np.testing.assert_array_equal(fits.params[k], [e.cx, e.cy, e.a, e.b, e.theta])
        assert fits.residual_rms[k] == one.residual_rms and fits.residual_mean[k] == one.residual_mean
        np.testing.assert_array_equal(fits.covariance[k], one.covariance)
        assert fits.iterations[k] == one.iterations and fits.converged[k] == one.converged


def test_centre_error_not_worse_than_fit_ellipse_ams() -> None:
    cv2 = pytest.importorskip("cv2")
    truths, arcs = _arcs(150, 2)
    fits = fit_ellipses(np.concatenate(arcs), _offsets(arcs))
    ours = np.median([math.hypot(p[0] - t[0], p[1] - t[1]) for p, t in zip(fits.params, truths, strict=True)])
    ams = []
    for pts, t in zip(arcs, truths, strict=True):
        (cx, cy), _, _ = cv2.fitEllipseAMS(pts.astype(np.float32))
        ams.append(math.hypot(cx - t[0], cy - t[1]))
    # The geometric fit is the maximum-likelihood estimate: at least as accurate as AMS.
    assert ours <= np.median(ams)


def test_bad_arcs_are_reported_not_raised() -> None:
    _, arcs = _arcs(3, 3)
    bad_nan = arcs[0][:30].copy()
    bad_nan[4, 1] = np.nan
    line = np.column_stack([np.arange(10.0), 2 * np.arange(10.0)])
    all_arcs = [arcs[0], np.zeros((3, 2)), bad_nan, line, arcs[1]]
    fits = fit_ellipses(np.concatenate(all_arcs), _offsets(all_arcs))
    assert fits.ok.tolist() == [True, False, False, False, True]
    assert "too few points" in fits.errors[1]
    assert "must be finite" in fits.errors[2] and "index 4" in fits.errors[2]
    assert "collinear" in fits.errors[3]
    assert np.isnan(fits.params[1:4]).all() and not fits.converged[1:4].any()
    e = fit_ellipse(arcs[1]).ellipse
    np.testing.assert_array_equal(fits.params[4], [e.cx, e.cy, e.a, e.b, e.theta])


def test_empty_batch() -> None:
    fits = fit_ellipses(np.zeros((0, 2)), [0])
    assert len(fits) == 0 and fits.params.shape == (0, 5) and fits.covariance.shape == (0, 5, 5)


@pytest.mark.parametrize(
    ("points", "offsets", "match"),
    [
        (np.zeros((10, 3)), [0, 10], "shape"),
        (np.zeros((10, 2)), [0, 9], "offsets|length"),
        (np.zeros((10, 2)), [1, 10], "offsets"),
        (np.zeros((10, 2)), [0, 6, 4, 10], "non-decreasing"),
        (np.zeros((10, 2)), [0, -1, 10], "negative"),
        (np.zeros((10, 2)), [0.0, 10.0], "integers"),
        (np.zeros((10, 2)), [[0, 10]], "1-D"),
        (np.zeros((10, 2)), [], "offsets"),
        (np.array([["a", "b"]] * 10), [0, 10], "real"),
    ],
)
def test_bad_input_raises(points, offsets, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        fit_ellipses(points, offsets)


def test_unknown_method() -> None:
    with pytest.raises(InvalidInputError, match="method"):
        fit_ellipses(np.zeros((10, 2)), [0, 10], method="algebraic")  # type: ignore[arg-type]
