"""Tests of autoteach.detect: ellipse fitting and linear assignment against OpenCV and scipy.

Truth: OpenCV's ellipse fits on identical (float32-representable) points, known ellipses
sampled with and without noise, and scipy's ``linear_sum_assignment`` on identical matrices.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment as scipy_lsa

from autoteach import detect
from autoteach.errors import AutoteachError, DegenerateGeometryError, InvalidInputError
from autoteach.geometry import Ellipse

SEED = 20240612


def _opencv_params(box: tuple) -> np.ndarray:
    """OpenCV's ((cx, cy), (width, height), angle°) as canonical (cx, cy, a, b, theta)."""
    (cx, cy), (w, h), angle = box
    return Ellipse(cx, cy, 0.5 * w, 0.5 * h, math.radians(angle)).as_array()


def _noisy_arc(rng: np.random.Generator, span_deg: float, sigma: float = 0.5) -> tuple[Ellipse, np.ndarray]:
    a = rng.uniform(200.0, 350.0)
    truth = Ellipse(rng.uniform(300, 900), rng.uniform(300, 700), a, a * rng.uniform(0.25, 1.0), rng.uniform(-3, 3))
    span = math.radians(span_deg)
    t0 = rng.uniform(-math.pi, math.pi)
    n = int(0.5 * (truth.a + truth.b) * span)
    pts = truth.sample(n, t0, t0 + span) + rng.normal(0.0, sigma, (n, 2))
    # float32-representable, so OpenCV sees exactly the same points.
    return truth, pts.astype(np.float32).astype(np.float64)


# --- assignment -----------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(50, 60), (60, 50), (50, 50)])
def test_assignment_matches_scipy_on_random_matrices(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(SEED)
    for trial in range(10):
        cost = rng.random(shape) if trial % 2 else rng.integers(0, 5, shape).astype(float)  # ties
        rows, cols = detect.linear_sum_assignment(cost)
        srows, scols = scipy_lsa(cost)
        assert rows.dtype == np.intp and cols.dtype == np.intp
        assert len(rows) == len(srows) == min(shape)
        np.testing.assert_array_equal(rows, np.sort(rows))
        assert len(set(cols.tolist())) == len(cols)
        assert cost[rows, cols].sum() == pytest.approx(cost[srows, scols].sum(), abs=1e-9)


def test_assignment_maximize_and_forbidden_pairs_match_scipy() -> None:
    rng = np.random.default_rng(SEED + 1)
    cost = rng.random((30, 40))
    rows, cols = detect.linear_sum_assignment(cost, maximize=True)
    srows, scols = scipy_lsa(cost, maximize=True)
    assert cost[rows, cols].sum() == pytest.approx(cost[srows, scols].sum(), abs=1e-9)
    # Forbidden pairs (inf) that still allow a complete assignment: same optimum as scipy.
    cost[rng.random(cost.shape) < 0.3] = np.inf
    rows, cols = detect.linear_sum_assignment(cost)
    srows, scols = scipy_lsa(cost)
    assert np.isfinite(cost[rows, cols]).all()
    assert cost[rows, cols].sum() == pytest.approx(cost[srows, scols].sum(), abs=1e-9)


def test_assignment_infeasible_rows_are_left_out() -> None:
    inf = np.inf
    cost = np.array([[10.0, inf], [1.0, inf], [inf, inf]])
    rows, cols = detect.linear_sum_assignment(cost)
    assert rows.tolist() == [1] and cols.tolist() == [0]
    rows, cols = detect.linear_sum_assignment(np.zeros((0, 3)))
    assert rows.shape == (0,) and cols.shape == (0,)


def test_assign_with_unassigned_dummy_costs() -> None:
    inf = np.inf
    # Arcs 0 and 1 fit together (residual 0.3); arc 2 fits nothing below the 1.0 price.
    r = np.array([[inf, 0.3, 5.0], [0.3, inf, 6.0], [5.0, 6.0, inf]])
    rows, cols, total = detect.assign_with_unassigned(r, [1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
    assert rows.tolist() == [0, 1] and cols.tolist() == [1, 0]
    assert total == pytest.approx(0.6 + 2.0)
    # Cheap non-assignment: nothing is assigned.
    rows, cols, total = detect.assign_with_unassigned(r, [0.1] * 3, [0.1] * 3)
    assert len(rows) == 0 and total == pytest.approx(0.6)


def test_assignment_bad_inputs() -> None:
    with pytest.raises(InvalidInputError, match="NaN"):
        detect.linear_sum_assignment([[1.0, float("nan")], [0.0, 1.0]])
    with pytest.raises(InvalidInputError, match="two-dimensional"):
        detect.linear_sum_assignment(np.zeros((2, 2, 2)))
    with pytest.raises(InvalidInputError):
        detect.linear_sum_assignment([[1.0, -np.inf]])
    with pytest.raises(InvalidInputError, match="maximize"):
        detect.linear_sum_assignment([[1.0, np.inf]], maximize=True)
    with pytest.raises(InvalidInputError, match="row_unassigned_cost"):
        detect.assign_with_unassigned(np.zeros((2, 2)), [1.0], [1.0, 1.0])


# --- ellipse fitting ------------------------------------------------------------------------


def test_full_noiseless_ellipse_matches_opencv() -> None:
    truth = Ellipse(320.25, 240.5, 150.0, 60.0, 0.4)
    pts = truth.sample(100, 0.0, 2 * math.pi * 99 / 100).astype(np.float32)
    ref = _opencv_params(cv2.fitEllipse(pts))
    for method in ("direct", "geometric"):
        fit = detect.fit_ellipse(pts.astype(np.float64), method=method)
        np.testing.assert_allclose(fit.ellipse.as_array(), ref, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(fit.ellipse.as_array(), truth.as_array(), rtol=1e-6, atol=1e-6)
        assert fit.residual_mean < 1e-4 and fit.residual_rms < 1e-4  # float32 rounding of the points
    # OpenCV's direct (Fitzgibbon) fit is the same estimator as ours.
    ref_direct = _opencv_params(cv2.fitEllipseDirect(pts))
    fit = detect.fit_ellipse(pts.astype(np.float64), method="direct")
    np.testing.assert_allclose(fit.ellipse.as_array(), ref_direct, rtol=1e-6, atol=1e-6)


def test_noisy_direct_fit_matches_opencv_direct() -> None:
    rng = np.random.default_rng(SEED + 2)
    for _ in range(20):
        _, pts = _noisy_arc(rng, 120.0)
        ours = detect.fit_ellipse(pts, method="direct").ellipse.as_array()
        ref = _opencv_params(cv2.fitEllipseDirect(pts.astype(np.float32)))
        # Same estimator on the same points; OpenCV returns float32 values.
        np.testing.assert_allclose(ours[:4], ref[:4], rtol=2e-5, atol=2e-3)


def test_partial_arcs_more_accurate_than_opencv() -> None:
    rng = np.random.default_rng(SEED + 3)
    errors: dict[str, list[float]] = {"geometric": [], "fitEllipse": [], "fitEllipseAMS": [], "fitEllipseDirect": []}
    for trial in range(200):
        truth, pts = _noisy_arc(rng, 60.0 + 100.0 * (trial % 5) / 4)  # 60–160°
        p32 = pts.astype(np.float32)
        try:
            ours = detect.fit_ellipse(pts).ellipse.as_array()
        except DegenerateGeometryError as err:
            # A few 60° arcs have no bounded least-squares ellipse (it runs off to a
            # parabola): reported, and counted here as an infinitely wrong fit.
            assert "parabola" in str(err)
            ours = np.full(5, np.inf)
        estimates = {
            "geometric": ours,
            "fitEllipse": _opencv_params(cv2.fitEllipse(p32)),
            "fitEllipseAMS": _opencv_params(cv2.fitEllipseAMS(p32)),
            "fitEllipseDirect": _opencv_params(cv2.fitEllipseDirect(p32)),
        }
        for name, p in estimates.items():
            errors[name].append(math.hypot(p[0] - truth.cx, p[1] - truth.cy))
    assert sum(math.isinf(e) for e in errors["geometric"]) <= 5
    medians = {k: float(np.median(v)) for k, v in errors.items()}
    best_peer = min(v for k, v in medians.items() if k != "geometric")
    assert medians["geometric"] < best_peer, medians
    assert medians["geometric"] < 0.5 * medians["fitEllipseDirect"], medians


def test_geometric_fit_is_at_the_orthogonal_distance_optimum_found_by_scipy() -> None:
    # scipy's Levenberg–Marquardt, iterated to 1e-12 from our result on the same orthogonal
    # distances, may move the ellipse by at most a few hundredths of a standard deviation (our
    # fit stops once its next step is below 0.01σ) and cannot lower the sum of squares by more.
    least_squares = pytest.importorskip("scipy.optimize").least_squares
    rng = np.random.default_rng(SEED + 7)
    for trial in range(20):
        _, pts = _noisy_arc(rng, 90.0 + 70.0 * (trial % 5) / 4)  # 90–160°
        fit = detect.fit_ellipse(pts)
        ours = fit.ellipse.as_array()
        ref = least_squares(
            lambda p, pts=pts: Ellipse(*p).distance(pts), ours, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12
        )
        d = Ellipse(*ref.x).as_array() - ours
        d[4] = (d[4] + math.pi / 2) % math.pi - math.pi / 2
        steps = math.sqrt(d @ np.linalg.solve(fit.covariance, d))
        assert steps < 0.05, (trial, steps)
        ssr = float(np.sum(fit.ellipse.distance(pts) ** 2))
        sigma2 = ssr / (len(pts) - 5)
        assert ssr - 2.0 * ref.cost <= 0.05**2 * sigma2, (trial, ssr, 2.0 * ref.cost)


def test_fit_result_fields_and_covariance() -> None:
    rng = np.random.default_rng(SEED + 4)
    truth, pts = _noisy_arc(rng, 150.0)
    fit = detect.fit_ellipse(pts, method="geometric")
    assert isinstance(fit.ellipse, Ellipse)
    assert fit.converged and fit.iterations >= 1
    d = fit.ellipse.distance(pts)
    assert fit.residual_mean == pytest.approx(np.mean(np.abs(d)), rel=1e-9)
    assert fit.residual_rms == pytest.approx(np.sqrt(np.mean(d**2)), rel=1e-9)
    assert 0.3 < fit.residual_rms < 0.7  # 0.5 px noise
    cov = fit.covariance
    assert cov is not None and cov.shape == (5, 5)
    np.testing.assert_allclose(cov, cov.T, rtol=1e-9, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    direct = detect.fit_ellipse(pts, method="direct")
    assert direct.iterations == 0 and direct.converged
    # The geometric fit minimises the orthogonal distances the direct fit only approximates.
    assert fit.residual_rms <= direct.residual_rms
    # Exactly five points: interpolated, no covariance.
    five = Ellipse(10.0, 20.0, 8.0, 3.0, 0.2).sample(5, 0.0, 4.0)
    fit5 = detect.fit_ellipse(five)
    assert fit5.covariance is None
    np.testing.assert_allclose(fit5.ellipse.as_array(), [10.0, 20.0, 8.0, 3.0, 0.2], atol=1e-8)


def test_fit_accepts_lists_and_other_dtypes() -> None:
    pts = Ellipse(5.0, 6.0, 4.0, 2.0, 0.0).sample(20, 0.0, 3.0)
    a = detect.fit_ellipse(pts.tolist()).ellipse.as_array()
    b = detect.fit_ellipse(pts.astype(np.float32)).ellipse.as_array()
    np.testing.assert_allclose(a, [5.0, 6.0, 4.0, 2.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(b, a, atol=1e-4)
    # Integer pixel coordinates (an edge detector's output).
    ints = np.round(Ellipse(50.0, 60.0, 40.0, 20.0, 0.3).sample(200, 0.0, 2 * math.pi)).astype(np.int32)
    assert detect.fit_ellipse(ints).ellipse.a == pytest.approx(40.0, abs=0.5)


@pytest.mark.parametrize("method", ["direct", "geometric"])
def test_bad_inputs_raise_clear_errors(method: str) -> None:
    five = Ellipse(0.0, 0.0, 10.0, 5.0, 0.3).sample(5, 0.0, 5.0)
    with pytest.raises(InvalidInputError, match="too few points: got 4"):
        detect.fit_ellipse(five[:4], method=method)
    nan = five.copy()
    nan[3, 0] = np.nan
    with pytest.raises(InvalidInputError, match="points must be finite, got NaN at index 3"):
        detect.fit_ellipse(nan, method=method)
    with pytest.raises(InvalidInputError, match=r"shape \(N, 2\)"):
        detect.fit_ellipse(np.zeros((10, 3)), method=method)
    line = np.stack([np.arange(20.0), 0.5 * np.arange(20.0) + 3.0], axis=1)
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        detect.fit_ellipse(line, method=method)
    with pytest.raises(DegenerateGeometryError, match="unique conic"):
        detect.fit_ellipse(np.tile(five[:4], (3, 1)), method=method)
    s = np.linspace(-2.0, 2.0, 21)
    hyperbola = np.concatenate([np.stack([2 * np.cosh(s), np.sinh(s)], 1), np.stack([-2 * np.cosh(s), np.sinh(s)], 1)])
    with pytest.raises(DegenerateGeometryError, match="hyperbola"):
        detect.fit_ellipse(hyperbola, method=method)
    # Every error is an AutoteachError and a ValueError.
    with pytest.raises(AutoteachError):
        detect.fit_ellipse(line, method=method)
    with pytest.raises(ValueError):
        detect.fit_ellipse(line, method=method)


def test_unknown_method_and_non_numeric_input() -> None:
    pts = Ellipse(5.0, 6.0, 4.0, 2.0, 0.0).sample(20, 0.0, 3.0)
    with pytest.raises(InvalidInputError, match="method"):
        detect.fit_ellipse(pts, method="ransac")  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError):
        detect.fit_ellipse("points")
    with pytest.raises(InvalidInputError):
        detect.fit_ellipse([["a", "b"]] * 6)
