"""The UKF with vectorised Python models (issue 36): ``fx``/``hx`` receive all sigma points at once.

Checked against the per-point form of the same filter (to 1e-14 when the callbacks do the same
arithmetic per point) and against filterpy on identical inputs, on a linear 9-state model and
on a nonlinear one (radar range), plus the validation of what a vectorised callback returns.
Against filterpy the tolerance is the 1e-10 of ``test_ukf_filterpy_compat.py``: filterpy sums
the covariances in another order, and over hundreds of steps the rounding reaches ~1e-12.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from autoteach import estimate as est
from autoteach.errors import InvalidInputError

fk = pytest.importorskip("filterpy.kalman", reason="filterpy is the parity reference (the 'test' extra)")

TOL = 1e-10
SAME = 1e-14
DT = 0.01


def rel(a, b) -> float:
    """Largest absolute difference relative to max(1, |b|)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, (a.shape, b.shape)
    return float(np.abs(a - b).max() / max(1.0, float(np.abs(b).max())))


def const_accel():
    F = np.eye(9)  # noqa: N806
    for i in range(3):
        F[i, 3 + i] = DT
        F[i, 6 + i] = 0.5 * DT * DT
        F[3 + i, 6 + i] = DT
    H = np.zeros((3, 9))  # noqa: N806
    H[:, :3] = np.eye(3)
    return F, H


def measurements(n, F, H, seed=0):  # noqa: N803
    rng = np.random.default_rng(seed)
    x = np.zeros(9)
    zs = np.empty((n, 3))
    for k in range(n):
        x = F @ x + rng.normal(size=9) * np.r_[np.full(6, 1e-4), np.full(3, 1e-2)]
        zs[k] = H @ x + rng.normal(size=3) * 0.05
    return zs


def setup(kf, n):
    kf.x = np.zeros(n)
    kf.P = np.eye(n)
    kf.Q = np.eye(n) * 1e-4
    kf.R = np.eye(kf._dim_z if hasattr(kf, "_dim_z") else kf.dim_z) * 0.05**2
    return kf


def test_linear_model_equals_per_point_and_filterpy():
    F, H = const_accel()  # noqa: N806
    zs = measurements(300, F, H)
    calls = {"fx": 0, "hx": 0}

    def fx(x, dt):
        return F @ x

    def hx(x):
        return H @ x

    def fx_all(s, dt):
        calls["fx"] += 1
        assert s.shape == (19, 9)
        return s @ F.T

    def hx_all(s):
        calls["hx"] += 1
        assert s.shape == (19, 9)
        return s @ H.T

    def pts(mod):
        return mod(9, 0.1, 2.0, -6.0)

    fp = setup(fk.UnscentedKalmanFilter(9, 3, DT, hx=hx, fx=fx, points=pts(fk.MerweScaledSigmaPoints)), 9)
    per = setup(est.UnscentedKalmanFilter(9, 3, DT, hx, fx, pts(est.MerweScaledSigmaPoints)), 9)
    vec = setup(
        est.UnscentedKalmanFilter(9, 3, DT, hx_all, fx_all, pts(est.MerweScaledSigmaPoints), vectorized=True), 9
    )
    m_fp, p_fp = fp.batch_filter(zs)
    m_per, p_per = per.batch_filter(zs)
    m_vec, p_vec = vec.batch_filter(zs)
    # One call per transform: 300 predictions and 300 updates.
    assert calls == {"fx": 300, "hx": 300}
    # ``s @ F.T`` (one matrix product) and ``F @ x`` (per point) round differently: 1e-10.
    assert rel(m_vec, m_per) <= TOL and rel(p_vec, p_per) <= TOL
    assert rel(m_vec, m_fp) <= TOL and rel(p_vec, p_fp) <= TOL
    # The smoother goes through the same vectorised fx.
    xs_fp, ps_fp, _ = fp.rts_smoother(m_fp, p_fp)
    xs_vec, ps_vec, _ = vec.rts_smoother(m_vec, p_vec)
    assert rel(xs_vec, xs_fp) <= 1e-10 and rel(ps_vec, ps_fp) <= 1e-10


def test_nonlinear_radar_step_by_step_with_kwargs_equals_filterpy():
    def fx(x, dt, scale=1.0):
        return np.array([x[0] + dt * x[1] * scale, x[1], x[2]])

    def hx(x, offset=0.0):
        return [math.sqrt(x[0] * x[0] + x[2] * x[2]) + offset]

    def fx_all(s, dt, scale=1.0):
        return np.column_stack([s[:, 0] + dt * s[:, 1] * scale, s[:, 1], s[:, 2]])

    def hx_all(s, offset=0.0):
        return np.sqrt(s[:, 0] * s[:, 0] + s[:, 2] * s[:, 2]) + offset  # (N,) accepted when dim_z == 1

    def make(mod, f, h, **kw):
        kf = mod.UnscentedKalmanFilter(
            3, 1, 0.05, hx=h, fx=f, points=mod.MerweScaledSigmaPoints(3, 0.1, 2.0, 0.0), **kw
        )
        kf.x = np.array([-10.0, 90.0, 1100.0])
        kf.P = np.diag([100.0, 10.0, 100.0])
        kf.Q = np.diag([0.0, 0.1, 0.1]) * 0.05
        kf.R = np.array([[10.0]])
        return kf

    fp = make(fk, fx, hx)
    per = make(est, fx, hx)
    vec = make(est, fx_all, hx_all, vectorized=True)
    rng = np.random.default_rng(3)
    for k in range(60):
        z = math.hypot(k * 5.0, 1000.0) + rng.normal()
        for kf in (fp, per, vec):
            kf.predict(scale=1.01)
        assert rel(vec.x_prior, per.x_prior) <= SAME and rel(vec.P_prior, per.P_prior) <= SAME
        assert rel(vec.x_prior, fp.x_prior) <= TOL and rel(vec.P_prior, fp.P_prior) <= TOL
        for kf in (fp, per, vec):
            kf.update(z, offset=0.5)
        assert rel(vec.x, per.x) <= SAME and rel(vec.P, per.P) <= SAME
        assert rel(vec.x, fp.x) <= TOL and rel(vec.P, fp.P) <= TOL
        assert rel(vec.sigmas_h, fp.sigmas_h) <= 1e-10


def test_vectorised_callback_results_are_validated():
    F, H = const_accel()  # noqa: N806
    zs = measurements(5, F, H)

    def build(fx_all, hx_all):
        return setup(
            est.UnscentedKalmanFilter(
                9, 3, DT, hx_all, fx_all, est.MerweScaledSigmaPoints(9, 0.1, 2.0, -6.0), vectorized=True
            ),
            9,
        )

    good_f = lambda s, dt: s @ F.T  # noqa: E731
    good_h = lambda s: s @ H.T  # noqa: E731
    with pytest.raises(
        InvalidInputError, match=r"fx \(vectorized\) returned an array of shape \(9,\), expected \(19, 9\)"
    ):
        build(lambda s, dt: s[0], good_h).predict()
    with pytest.raises(InvalidInputError, match=r"hx \(vectorized\).*shape \(19, 9\), expected \(19, 3\)"):
        kf = build(good_f, lambda s: s)
        kf.predict()
        kf.update(zs[0])

    def nan_f(s, dt):
        out = s @ F.T
        out[4, 2] = np.nan
        return out

    with pytest.raises(InvalidInputError, match=r"fx \(vectorized\) returned NaN at row 4 \(sigma point 4\), column 2"):
        build(nan_f, good_h).predict()
    with pytest.raises((InvalidInputError, ValueError, TypeError)):
        build(lambda s, dt: [["a"] * 9] * 19, good_h).predict()
    # Exceptions raised by the callback propagate unchanged.
    with pytest.raises(ZeroDivisionError):
        build(lambda s, dt: 1 / 0, good_h).predict()
    # Options that cannot combine with the vectorised form.
    pts = est.MerweScaledSigmaPoints(9, 0.1, 2.0, -6.0)
    with pytest.raises(InvalidInputError, match="additive"):
        est.UnscentedKalmanFilter(9, 3, DT, good_h, good_f, pts, noise="augmented", vectorized=True)
    with pytest.raises(InvalidInputError, match="built-in model"):
        est.UnscentedKalmanFilter(9, 3, DT, None, est.LinearModel(F, H), pts, vectorized=True)
    with pytest.raises(InvalidInputError, match="must be a bool"):
        est.UnscentedKalmanFilter(9, 3, DT, good_h, good_f, pts, vectorized="yes")
