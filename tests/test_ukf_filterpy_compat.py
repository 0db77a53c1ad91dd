"""autoteach's UKF as a drop-in for filterpy's (issue 37), checked against filterpy itself.

The scenarios are those of filterpy's own ``test_ukf.py`` (radar range tracking, linear
constant velocity with each sigma-point family, RTS smoothing, fixed-lag smoothing, the
linear-RTS regression with a ``Saver``, missing data), written here from scratch: each runs
filterpy and autoteach on identical inputs and compares every attribute a user touches to
1e-10. The last test runs filterpy's own file with the import swapped
(``benchmarks/filterpy_suite.py``).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from autoteach import estimate as est
from autoteach.errors import InvalidInputError

fk = pytest.importorskip("filterpy.kalman", reason="filterpy is the parity reference (the 'test' extra)")
fc = pytest.importorskip("filterpy.common")

TOL = 1e-10


def close(a, b, what, tol=TOL):
    """|a - b| <= tol * max(1, |b|) elementwise (arrays of equal shape)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    assert a.shape == b.shape, (what, a.shape, b.shape)
    scale = max(1.0, float(np.abs(b).max())) if b.size else 1.0
    err = float(np.abs(a - b).max()) if b.size else 0.0
    assert err <= tol * scale, f"{what}: max error {err:.3e} (scale {scale:.3e})"


# ---------------------------------------------------------------------------------------------
# Models and data (the shapes of filterpy's scenarios)
# ---------------------------------------------------------------------------------------------


def radar_fx(x, dt):
    """[position, velocity, altitude]: constant velocity, constant altitude."""
    return np.array([x[0] + dt * x[1], x[1], x[2]])


def radar_hx(x):
    """Slant range to the aircraft."""
    return [math.sqrt(x[0] ** 2 + x[2] ** 2)]


def radar_ranges(n, dt=0.05, seed=200):
    rng = np.random.default_rng(seed)
    pos, out = 0.0, []
    for _ in range(n):
        pos += (100 + 5 * rng.standard_normal()) * dt
        alt = 1000 + 10 * rng.standard_normal()
        out.append(math.hypot(pos, alt) + pos * 0.05 * rng.standard_normal())
    return out


def cv2_fx(x, dt):
    """2-D constant velocity, state [x, vx, y, vy]."""
    return np.array([x[0] + dt * x[1], x[1], x[2] + dt * x[3], x[3]])


def cv2_hx(x):
    return np.array([x[0], x[2]])


def cv2_data(n=20, seed=3):
    rng = np.random.default_rng(seed)
    return [np.array([i + 0.1 * rng.standard_normal(), i + 0.1 * rng.standard_normal()]) for i in range(n)]


def pair(points_fp, points_at, dim_x, dim_z, dt, fx, hx, setup, **kw):
    """filterpy's filter and ours, identically configured."""
    fp = fk.UnscentedKalmanFilter(dim_x, dim_z, dt, fx=fx, hx=hx, points=points_fp, **kw)
    at = est.UnscentedKalmanFilter(dim_x, dim_z, dt, fx=fx, hx=hx, points=points_at, **kw)
    setup(fp)
    setup(at)
    return fp, at


def setup_radar(kf):
    kf.Q *= 0.01
    kf.R = 10
    kf.x = np.array([0.0, 90.0, 1100.0])
    kf.P *= 100.0


STATE = ("x", "P", "x_prior", "P_prior", "x_post", "P_post")
UPDATE = ("K", "y", "S", "SI", "sigmas_f", "sigmas_h")


def compare_state(fp, at, what, names=STATE + UPDATE):
    for name in names:
        close(getattr(at, name), getattr(fp, name), f"{what}: {name}")
    for name in ("log_likelihood", "likelihood", "mahalanobis"):
        a, b = getattr(at, name), getattr(fp, name)
        assert a == pytest.approx(b, rel=1e-9, abs=1e-300), f"{what}: {name} {a} vs {b}"


# ---------------------------------------------------------------------------------------------
# Sigma-point families
# ---------------------------------------------------------------------------------------------

FAMILIES = [
    ("MerweScaledSigmaPoints", (0.1, 2.0, -1.0)),
    ("MerweScaledSigmaPoints", (1e-3, 2.0, 0.0)),
    ("JulierSigmaPoints", (0.0,)),
    ("JulierSigmaPoints", (1.0,)),
    ("SimplexSigmaPoints", ()),
]


def spd(n, seed=0):
    a = np.random.default_rng(seed).normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize("name, params", FAMILIES)
@pytest.mark.parametrize("n", [1, 2, 4, 7])
def test_sigma_point_families_match_filterpy(name, params, n):
    if name == "MerweScaledSigmaPoints" and n + params[2] <= 0:
        # n + kappa = 0 makes n + lambda = 0: filterpy divides by zero, we refuse the parameters.
        with pytest.raises(ZeroDivisionError):
            getattr(fk, name)(n, *params)
        with pytest.raises(InvalidInputError, match="kappa"):
            getattr(est, name)(n, *params)
        return
    ours, theirs = getattr(est, name)(n, *params), getattr(fk, name)(n, *params)
    close(ours.Wm, theirs.Wm, "Wm")
    close(ours.Wc, theirs.Wc, "Wc")
    assert ours.num_sigmas() == theirs.num_sigmas() == len(theirs.Wm)
    x, P = np.linspace(-1.0, 2.0, n), spd(n, seed=n)
    close(ours.sigma_points(x, P), theirs.sigma_points(x, P), "sigma points")
    # The unscented transform of the points gives back (x, P): an independent truth.
    m, c = est.unscented_transform(ours.sigma_points(x, P), ours.Wm, ours.Wc)
    # The weighted sum cancels weights of size up to 1 / alpha^2: rounding grows with sum |Wm|.
    close(m, x, "UT mean", max(TOL, 16 * np.finfo(float).eps * float(np.abs(ours.Wm).sum())))
    close(c, P, "UT covariance", 1e-9)
    assert name in repr(ours)


@pytest.mark.parametrize("name, params", FAMILIES)
def test_scalar_inputs_and_hooks_match_filterpy(name, params):
    if name != "MerweScaledSigmaPoints" or 1 + params[2] > 0:  # n = 1, kappa = -1 is degenerate (above)
        ours, theirs = getattr(est, name)(1, *params), getattr(fk, name)(1, *params)
        close(ours.sigma_points(5.0, 9.0), theirs.sigma_points(5.0, 9.0), "scalar x, P")

    def sqrt_method(m):
        w, v = np.linalg.eigh(m)
        return (v * np.sqrt(w)).T  # a symmetric-root variant: rows are the offsets

    def subtract(a, b):
        return np.subtract(a, b) * 1.0

    n = 3
    x, P = np.array([0.5, -1.0, 2.0]), spd(n, seed=5)
    ours = getattr(est, name)(n, *params, sqrt_method=sqrt_method, subtract=subtract)
    theirs = getattr(fk, name)(n, *params, sqrt_method=sqrt_method, subtract=subtract)
    close(ours.sigma_points(x, P), theirs.sigma_points(x, P), "sigma points with hooks")
    with pytest.raises(InvalidInputError, match="size"):
        ours.sigma_points(np.zeros(2), P)


def test_unscented_transform_matches_filterpy():
    rng = np.random.default_rng(4)
    s, w = rng.normal(size=(7, 3)), np.full(7, 1 / 7)
    Q = np.eye(3) * 0.2

    def mean_fn(sig, wm):
        return wm @ sig + 0.0

    def residual(a, b):
        return a - b

    for args in [(), (Q,), (Q, mean_fn, residual)]:
        ours = est.unscented_transform(s, w, w, *args)
        theirs = fk.unscented_transform(s, w, w, *args)
        close(ours[0], theirs[0], "UT mean")
        close(ours[1], theirs[1], "UT cov")


def test_bad_sigma_point_parameters_raise():
    with pytest.raises(InvalidInputError, match="kappa"):
        est.JulierSigmaPoints(2, -2.0)
    with pytest.raises(InvalidInputError, match="n must be a positive integer"):
        est.SimplexSigmaPoints(0)
    with pytest.raises(InvalidInputError, match="not a valid covariance|positive definite"):
        est.SimplexSigmaPoints(2).sigma_points(np.zeros(2), np.array([[1.0, 2.0], [2.0, 1.0]]))


# ---------------------------------------------------------------------------------------------
# The filter, step by step (radar scenario), with our points and with filterpy's
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("ours_points", [True, False], ids=["our-julier", "filterpy-julier"])
def test_radar_step_by_step_matches_filterpy(ours_points):
    sp = est.JulierSigmaPoints(3, 0.0) if ours_points else fk.JulierSigmaPoints(3, 0.0)
    fp, at = pair(fk.JulierSigmaPoints(3, 0.0), sp, 3, 1, 0.05, radar_fx, radar_hx, setup_radar)
    # Before any step: filterpy's initial attributes, and no division by a zero S.
    compare_state(fp, at, "initial")
    str(at)
    for i, r in enumerate(radar_ranges(150)):
        fp.predict()
        at.predict()
        # filterpy's update timing: predict sets the prior (and sigmas_f) and leaves x_post, P_post,
        # K, y, S, SI, sigmas_h and the likelihoods of the last update.
        compare_state(fp, at, f"after predict {i}")
        fp.update([r])
        at.update([r])
        compare_state(fp, at, f"step {i}")


def test_angles_with_mean_and_residual_hooks_match_filterpy():
    """Range-bearing radar with wrapped bearings: x_mean_fn, z_mean_fn, residual_x, residual_z, state_add."""

    def wrap(a):
        return (a + np.pi) % (2 * np.pi) - np.pi

    def fx(x, dt):
        return np.array([x[0] + dt * x[1], x[1], wrap(x[2] + dt * x[3]), x[3]])

    def hx(x):
        return np.array([x[0], wrap(x[2] + 0.1)])

    def x_mean(s, w):
        return np.array([w @ s[:, 0], w @ s[:, 1], math.atan2(w @ np.sin(s[:, 2]), w @ np.cos(s[:, 2])), w @ s[:, 3]])

    def z_mean(s, w):
        return np.array([w @ s[:, 0], math.atan2(w @ np.sin(s[:, 1]), w @ np.cos(s[:, 1]))])

    def res_x(a, b):
        d = np.subtract(a, b)
        d[2] = wrap(d[2])
        return d

    def res_z(a, b):
        d = np.subtract(a, b)
        d[1] = wrap(d[1])
        return d

    def add(x, dx):
        out = np.add(x, dx)
        out[2] = wrap(out[2])
        return out

    def setup(kf):
        kf.x = np.array([10.0, 1.0, 3.0, 0.3])
        kf.P = np.diag([1.0, 0.1, 0.2, 0.05])
        kf.Q = np.eye(4) * 1e-3
        kf.R = np.diag([0.1, 0.01])

    hooks = dict(x_mean_fn=x_mean, z_mean_fn=z_mean, residual_x=res_x, residual_z=res_z, state_add=add)
    fp, at = pair(fk.MerweScaledSigmaPoints(4, 0.5, 2.0, -1.0), est.MerweScaledSigmaPoints(4, 0.5, 2.0, -1.0),
                  4, 2, 0.5, fx, hx, setup, **hooks)  # fmt: skip
    rng = np.random.default_rng(8)
    truth = np.array([10.0, 1.0, 3.0, 0.3])
    for i in range(100):
        truth = fx(truth, 0.5)
        z = hx(truth) + rng.normal(size=2) * [0.3, 0.1]
        for kf in (fp, at):
            kf.predict()
            kf.update(z)
        compare_state(fp, at, f"step {i}", names=STATE + ("K", "y", "S"))


def test_fx_hx_kwargs_and_overrides_match_filterpy():
    def fx(x, dt, gain=1.0):
        return cv2_fx(x, dt) * gain

    def hx(x, offset=0.0):
        return cv2_hx(x) + offset

    def setup(kf):
        kf.x = np.array([-1.0, 1.0, -1.0, 1.0])
        kf.R *= 0.01

    fp, at = pair(fk.MerweScaledSigmaPoints(4, 0.1, 2.0, -1.0), est.MerweScaledSigmaPoints(4, 0.1, 2.0, -1.0),
                  4, 2, 0.1, fx, hx, setup)  # fmt: skip
    for i, z in enumerate(cv2_data(30)):
        for kf in (fp, at):
            kf.predict(gain=0.999)
            kf.update(z, R=0.02 if i % 2 else None, offset=0.01)
        compare_state(fp, at, f"step {i}")
    for kf in (fp, at):
        kf.predict(dt=0.2, fx=lambda x, dt: cv2_fx(x, dt))
        kf.update(np.array([30.0, 30.0]), hx=lambda x: cv2_hx(x) - 0.5)
    compare_state(fp, at, "overrides")


def test_compute_process_sigmas_and_cross_variance_match_filterpy():
    fp, at = pair(fk.JulierSigmaPoints(3, 1.0), est.JulierSigmaPoints(3, 1.0), 3, 1, 0.05, radar_fx, radar_hx,
                  setup_radar)  # fmt: skip
    for kf in (fp, at):
        kf.compute_process_sigmas(0.05)
    close(at.sigmas_f, fp.sigmas_f, "process sigmas")
    sh = np.array([radar_hx(s) for s in fp.sigmas_f])
    zp = fp.Wm @ sh
    close(at.cross_variance(fp.x, zp, fp.sigmas_f, sh), fp.cross_variance(fp.x, zp, fp.sigmas_f, sh), "Pxz")


def test_custom_ut_and_inv_match_filterpy():
    """A custom UT (an extra inflation) and an overridden inverse (pinv) take filterpy's path."""

    def ut(sigmas, wm, wc, noise, mean_fn, residual_fn):
        x, P = fk.unscented_transform(sigmas, wm, wc, noise, mean_fn, residual_fn)
        return x, P * 1.01

    def msqrt(m):
        return np.linalg.cholesky(m).T

    fp, at = pair(fk.JulierSigmaPoints(3, 0.0), est.JulierSigmaPoints(3, 0.0), 3, 1, 0.05, radar_fx, radar_hx,
                  setup_radar, sqrt_fn=msqrt)  # fmt: skip
    # filterpy keeps sqrt_fn as msqrt and draws with the points' own sqrt_method; so do we.
    assert at.msqrt is msqrt and fp.msqrt is msqrt
    for kf in (fp, at):
        kf.inv = np.linalg.pinv
    rs = radar_ranges(60)
    for i, r in enumerate(rs[:30]):
        for kf in (fp, at):
            kf.predict(UT=ut)
            kf.update([r], UT=ut)
        compare_state(fp, at, f"custom UT step {i}")
    m_fp, c_fp = fp.batch_filter(rs[30:], UT=ut)
    m_at, c_at = at.batch_filter(rs[30:], UT=ut)
    close(m_at, m_fp, "batch means, custom UT")
    close(c_at, c_fp, "batch covariances, custom UT")
    s_fp = fp.rts_smoother(m_fp, c_fp, UT=ut)
    s_at = at.rts_smoother(m_at, c_at, UT=ut)
    for a, b, what in zip(s_at, s_fp, ("xs", "Ps", "Ks"), strict=True):
        close(a, b, f"smoother {what}, custom UT and inv")


# ---------------------------------------------------------------------------------------------
# batch_filter, Saver, missing data
# ---------------------------------------------------------------------------------------------


def test_batch_with_missing_data_rs_and_saver_matches_filterpy():
    def setup(kf):
        kf.x = np.array([-1.0, 1.0, -1.0, 1.0])
        kf.P *= 0.0001

    fp, at = pair(fk.MerweScaledSigmaPoints(4, 0.1, 2.0, -1.0), est.MerweScaledSigmaPoints(4, 0.1, 2.0, -1.0),
                  4, 2, 0.1, cv2_fx, cv2_hx, setup)  # fmt: skip
    zs = cv2_data(20)
    zs[2] = None
    rs = [1.0] * len(zs)
    rs[2] = None
    rs[5] = np.eye(2) * 0.5
    s_fp, s_at = fc.Saver(fp), fc.Saver(at)
    m_fp, c_fp = fp.batch_filter(zs, Rs=rs, saver=s_fp)
    m_at, c_at = at.batch_filter(zs, Rs=rs, saver=s_at)
    close(m_at, m_fp, "means")
    close(c_at, c_fp, "covariances")
    # filterpy stores z = [[None], [None]] (shape 2x1) for the missing epoch, so its own Saver
    # cannot stack z; ours records the same z and fails the same way.
    for saver in (s_fp, s_at):
        with pytest.raises(ValueError, match="could not convert z"):
            saver.to_array()
    assert s_at.z[2].shape == s_fp.z[2].shape and all(v is None for v in s_at.z[2].ravel())
    for i in set(range(len(zs))) - {2}:
        close(s_at.z[i], s_fp.z[i], f"saved z {i}")
    for key in ("x", "P", "x_prior", "P_prior", "x_post", "P_post", "K", "S", "mahalanobis", "log_likelihood"):
        close(np.array(s_at[key]), np.array(s_fp[key]), f"saved {key}")
    # The Rust batch (no saver) gives the same run.
    _, at2 = pair(fk.MerweScaledSigmaPoints(4, 0.1, 2.0, -1.0), est.MerweScaledSigmaPoints(4, 0.1, 2.0, -1.0),
                  4, 2, 0.1, cv2_fx, cv2_hx, setup)  # fmt: skip
    m2, c2 = at2.batch_filter(zs, Rs=rs)
    close(m2, m_fp, "rust batch means")
    close(c2, c_fp, "rust batch covariances")
    compare_state(fp, at2, "after batch", names=("x", "P", "K", "y", "S", "SI"))


def test_batch_equals_step_by_step_exactly():
    """filterpy's test_rts asserts array_equal between batch_filter and predict/update."""
    _, a = pair(
        fk.JulierSigmaPoints(3, 1.0), est.JulierSigmaPoints(3, 1.0), 3, 1, 0.05, radar_fx, radar_hx, setup_radar
    )
    _, b = pair(
        fk.JulierSigmaPoints(3, 1.0), est.JulierSigmaPoints(3, 1.0), 3, 1, 0.05, radar_fx, radar_hx, setup_radar
    )
    rs = radar_ranges(100)
    xs = []
    for r in rs:
        a.predict()
        a.update([r])
        xs.append(a.x.copy())
    m, _ = b.batch_filter(rs)
    assert np.array_equal(m, np.array(xs))


# ---------------------------------------------------------------------------------------------
# RTS smoother
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make",
    [
        lambda m: m.JulierSigmaPoints(3, 1.0),
        lambda m: m.MerweScaledSigmaPoints(3, 0.5, 2.0, 0.0),
        lambda m: m.SimplexSigmaPoints(3),
    ],
    ids=["julier", "merwe", "simplex"],
)
def test_rts_smoother_matches_filterpy(make):
    fp, at = pair(make(fk), make(est), 3, 1, 0.05, radar_fx, radar_hx, setup_radar)
    rs = radar_ranges(200)
    m_fp, c_fp = fp.batch_filter(rs)
    m_at, c_at = at.batch_filter(rs)
    close(m_at, m_fp, "filtered means")
    for kwargs in ({}, {"Qs": [fp.Q] * len(rs)}, {"dts": 0.05}):
        s_fp = fp.rts_smoother(m_fp, c_fp, **kwargs)
        s_at = at.rts_smoother(m_fp, c_fp, **kwargs)
        for a, b, what in zip(s_at, s_fp, ("xs", "Ps", "Ks"), strict=True):
            close(a, b, f"smoother {what} {sorted(kwargs)}")
    # Fixed lag: the smoother on the last 10 epochs only.
    s_fp = fp.rts_smoother(m_fp[-10:], c_fp[-10:])
    s_at = at.rts_smoother(m_fp[-10:], c_fp[-10:])
    close(s_at[0], s_fp[0], "fixed-lag xs")
    close(s_at[1], s_fp[1], "fixed-lag Ps")


def test_rts_with_filterpy_points_and_per_epoch_fs():
    fp, at = pair(fk.SimplexSigmaPoints(4), fk.SimplexSigmaPoints(4), 4, 2, 0.1, cv2_fx, cv2_hx,
                  lambda kf: setattr(kf, "x", np.array([-1.0, 1.0, -1.0, 1.0])))  # fmt: skip
    zs = cv2_data(25)
    m, c = fp.batch_filter(zs)
    m_at, c_at = at.batch_filter(zs)
    close(m_at, m, "means (filterpy's simplex points in our filter)")
    s_fp = fp.rts_smoother(m, c, dts=0.1)
    s_at = at.rts_smoother(m, c, dts=0.1)
    close(s_at[0], s_fp[0], "smoothed means")
    close(s_at[1], s_fp[1], "smoothed covariances")
    # Per-epoch process functions (all equal to fx here) take the Python path: same result.
    s_fs = at.rts_smoother(m, c, dts=0.1, Fs=[cv2_fx] * len(zs))
    close(s_fs[0], s_fp[0], "smoothed means with Fs")


def test_linear_rts_with_saver_matches_kalman_and_filterpy():
    """filterpy's test_linear_rts: a Saver before any update (once a singular-matrix error), then
    UKF + RTS against the linear Kalman filter + RTS (closed form for a linear model)."""
    dt, sig_o = 1.0, 1e-4
    F, H = np.array([[1.0, dt], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    rng = np.random.default_rng(11)
    obs = np.arange(1, 51) + rng.normal(scale=sig_o, size=50)
    q = fc.Q_discrete_white_noise(dim=2, dt=dt, var=0.1**2)

    def setup(kf):
        kf.x = np.array([0.0, 1.0])
        kf.R = np.ones((1, 1)) * sig_o**2
        kf.Q = np.copy(q)

    fp, at = pair(fk.MerweScaledSigmaPoints(2, 0.1, 2.0, 1.0), est.MerweScaledSigmaPoints(2, 0.1, 2.0, 1.0),
                  2, 1, dt, lambda x, dt: F @ x, lambda x: H @ x, setup)  # fmt: skip
    saver = fc.Saver(at)
    saver.save()
    saver.to_array()
    assert at.mahalanobis == 0.0
    m_fp, c_fp = fp.batch_filter(obs)
    m_at, c_at = at.batch_filter(obs)
    close(m_at, m_fp, "means")
    s_fp = fp.rts_smoother(m_fp, c_fp)
    s_at = at.rts_smoother(m_at, c_at)
    close(s_at[0], s_fp[0], "smoothed means", 1e-8)
    kf = fk.KalmanFilter(dim_x=2, dim_z=1)
    kf.x, kf.F, kf.H, kf.R, kf.Q = np.array([[0.0, 1.0]]).T, F, H, np.ones((1, 1)) * sig_o**2, np.copy(q)
    mu, cov, _, _ = kf.batch_filter(obs)
    xk, _, _, _ = kf.rts_smoother(mu, cov)
    close(s_at[0][:, 0], xk[:, 0, 0], "RTS position vs Kalman", 1e-7)


def test_builtin_model_rts_in_rust_matches_filterpy():
    """The batch form: a built-in LinearModel filters and smooths in Rust; filterpy on its numpy fx."""
    F = np.array([[1.0, 0.1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.1], [0, 0, 0, 1]])
    model = est.LinearModel(F, np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]]))
    families = [("JulierSigmaPoints", (1.0,)), ("SimplexSigmaPoints", ()), ("MerweScaledSigmaPoints", (0.3, 2.0, 0.0))]
    for name, params in families:
        fp = fk.UnscentedKalmanFilter(4, 2, 0.1, fx=model.fx, hx=model.hx, points=getattr(fk, name)(4, *params))
        # filterpy's own points object is accepted for a built-in model (mapped onto our family).
        at = est.UnscentedKalmanFilter.from_model(model, getattr(fk, name)(4, *params), dt=0.1)
        for kf in (fp, at):
            kf.x = np.array([-1.0, 1.0, -1.0, 1.0])
            kf.Q = np.eye(4) * 1e-3
            kf.R = np.eye(2) * 0.01
        zs = cv2_data(300)
        m_fp, c_fp = fp.batch_filter(zs)
        m_at, c_at = at.batch_filter(zs)
        close(m_at, m_fp, f"{name} means")
        s_fp, s_at = fp.rts_smoother(m_fp, c_fp), at.rts_smoother(m_at, c_at)
        for a, b, what in zip(s_at, s_fp, ("xs", "Ps", "Ks"), strict=True):
            close(a, b, f"{name} smoother {what}", 1e-9)


# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------


def test_bad_inputs_to_the_new_surface_raise():
    fp, at = pair(fk.JulierSigmaPoints(3, 0.0), est.JulierSigmaPoints(3, 0.0), 3, 1, 0.05, radar_fx, radar_hx,
                  setup_radar)  # fmt: skip
    m, c = at.batch_filter(radar_ranges(20))
    with pytest.raises(InvalidInputError, match="same length"):
        at.rts_smoother(m, c[:-1])
    bad = m.copy()
    bad[3, 0] = np.nan
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        at.rts_smoother(bad, c)
    with pytest.raises(InvalidInputError, match="Xs must have shape"):
        at.rts_smoother(m[:, :2], c)
    with pytest.raises(InvalidInputError, match="UT must return"):
        at.predict(UT=lambda *a: None)
    with pytest.raises(InvalidInputError, match="sigma-point object"):
        est.UnscentedKalmanFilter(3, 1, 0.1, radar_hx, radar_fx, points=object())
    with pytest.raises(InvalidInputError, match="standard filter"):
        est.UnscentedKalmanFilter(3, 1, 0.1, radar_hx, radar_fx, fk.JulierSigmaPoints(3), square_root=True)
    with pytest.raises(InvalidInputError, match="points.n"):
        est.UnscentedKalmanFilter(3, 1, 0.1, radar_hx, radar_fx, fk.JulierSigmaPoints(4))
    with pytest.raises(InvalidInputError, match="rows"):
        at.cross_variance(at.x, np.zeros(1), np.zeros((2, 3)), np.zeros((2, 1)))


# ---------------------------------------------------------------------------------------------
# filterpy's own suite, import swapped
# ---------------------------------------------------------------------------------------------


def _suite_module():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "filterpy_suite.py"
    spec = importlib.util.spec_from_file_location("filterpy_suite", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_filterpy_own_suite_passes_with_our_filter(tmp_path):
    """filterpy's test_ukf.py with only its UnscentedKalmanFilter import swapped: 16 of 16."""
    suite = _suite_module()
    source = suite.find_source(tmp_path, timeout=60.0)
    if source is None:
        pytest.skip("filterpy's test_ukf.py is not available (no sdist download); set FILTERPY_TEST_UKF")
    passed, total, out = suite.run_suite(source, tmp_path)
    assert total == 16, out
    assert passed == total, out
