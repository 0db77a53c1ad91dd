"""Tests of autoteach.estimate: the unscented Kalman filter against filterpy.

The truth is filterpy's ``UnscentedKalmanFilter`` run on the same model, noises and
measurements (the parity target of the issue), plus the closed-form Kalman filter for linear
models and hand-built failure cases.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from autoteach import estimate as est
from autoteach.errors import ConvergenceError, InvalidInputError

filterpy_kalman = pytest.importorskip(
    "filterpy.kalman", reason="filterpy is the parity reference: pip install filterpy (in the 'test' extra)"
)
filterpy_common = pytest.importorskip("filterpy.common")

STEPS = 2000
RTOL = 1e-9


def assert_close(a, b, rtol=RTOL, what=""):
    """|a - b| <= rtol * max(1, |b|_max) elementwise: relative to the array's scale."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    assert a.shape == b.shape, (what, a.shape, b.shape)
    scale = max(1.0, float(np.abs(b).max()))
    err = float(np.abs(a - b).max())
    assert err <= rtol * scale, f"{what}: max error {err:.3e} at scale {scale:.3e}"


# ---------------------------------------------------------------------------------------------
# Models
# ---------------------------------------------------------------------------------------------


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def cv_fx(x, dt):
    """2-D constant velocity, state [x, vx, y, vy] (filterpy's example ordering)."""
    return np.array([x[0] + dt * x[1], x[1], x[2] + dt * x[3], x[3]])


def radar_hx(x):
    """Range and bearing from the origin."""
    return np.array([math.hypot(x[0], x[2]), math.atan2(x[2], x[0])])


def z_mean(sigmas, wm):
    return np.array([wm @ sigmas[:, 0], math.atan2(wm @ np.sin(sigmas[:, 1]), wm @ np.cos(sigmas[:, 1]))])


def residual_z(a, b):
    d = np.asarray(a, dtype=float) - b
    d[1] = wrap(d[1])
    return d


def radar_data(steps=STEPS, seed=1):
    """A target passing west of the radar, so the bearing crosses +-pi."""
    rng = np.random.default_rng(seed)
    x = np.array([-60.0, 0.02, -20.0, 0.04])
    zs = []
    for _ in range(steps):
        x = cv_fx(x, 1.0)
        z = radar_hx(x) + rng.normal(size=2) * [0.3, 0.005]
        z[1] = wrap(z[1])
        zs.append(z)
    return zs


def constant_acceleration(dt):
    """9-state 3-D constant-acceleration model [p; v; a], positions measured."""
    F = np.eye(9)
    for i in range(3):
        F[i, 3 + i] = dt
        F[i, 6 + i] = 0.5 * dt * dt
        F[3 + i, 6 + i] = dt
    H = np.zeros((3, 9))
    H[:, :3] = np.eye(3)
    return F, H


def ca_data(steps=STEPS, dt=0.01, seed=2):
    rng = np.random.default_rng(seed)
    F, H = constant_acceleration(dt)
    x = np.zeros(9)
    zs = []
    for _ in range(steps):
        x = F @ x + rng.normal(size=9) * np.r_[np.full(6, 1e-4), np.full(3, 1e-2)]
        zs.append(H @ x + rng.normal(size=3) * 0.05)
    return np.array(zs)


def setup_radar(kf):
    kf.x = np.array([-59.0, 0.0, -21.0, 0.0])
    kf.P = np.diag([4.0, 0.1, 4.0, 0.1])
    kf.Q = filterpy_common.Q_discrete_white_noise(dim=2, dt=1.0, var=1e-5, block_size=2)
    kf.R = np.diag([0.3**2, 0.005**2])


def radar_pair(alpha=0.1, beta=2.0, kappa=-1.0, **options):
    def make(ukf_cls, points_cls, **extra):
        kf = ukf_cls(
            dim_x=4,
            dim_z=2,
            dt=1.0,
            hx=radar_hx,
            fx=cv_fx,
            points=points_cls(4, alpha, beta, kappa),
            z_mean_fn=z_mean,
            residual_z=residual_z,
            **extra,
        )
        setup_radar(kf)
        return kf

    fp = make(filterpy_kalman.UnscentedKalmanFilter, filterpy_kalman.MerweScaledSigmaPoints)
    at = make(est.UnscentedKalmanFilter, est.MerweScaledSigmaPoints, **options)
    return fp, at


# ---------------------------------------------------------------------------------------------
# Parity with filterpy
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("n", "alpha", "beta", "kappa"), [(1, 1.0, 2.0, 2.0), (4, 0.1, 2.0, -1.0), (9, 0.5, 0.0, 0.0)])
def test_sigma_points_and_weights_match_filterpy(n, alpha, beta, kappa):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    x = rng.normal(size=n)
    ours = est.MerweScaledSigmaPoints(n, alpha, beta, kappa)
    ref = filterpy_kalman.MerweScaledSigmaPoints(n, alpha, beta, kappa)
    assert_close(ours.Wm, ref.Wm, 1e-14, "Wm")
    assert_close(ours.Wc, ref.Wc, 1e-14, "Wc")
    assert ours.num_sigmas() == ref.num_sigmas()
    assert_close(ours.sigma_points(x, P), ref.sigma_points(x, P), 1e-12, "sigma points")
    # The hooks path (sqrt_method / subtract) too.
    sq = est.MerweScaledSigmaPoints(n, alpha, beta, kappa, subtract=np.subtract)
    assert_close(sq.sigma_points(x, P), ref.sigma_points(x, P), 1e-12, "sigma points via subtract")


def test_callbacks_match_filterpy_step_by_step_over_2000_steps():
    """Nonlinear radar model with a wrapping bearing (z_mean_fn, residual_z)."""
    fp, at = radar_pair()
    zs = radar_data()
    crossed = np.any(np.abs(np.diff([z[1] for z in zs])) > np.pi)
    assert crossed, "the bearing must wrap at +-pi for this test to mean something"
    for k, z in enumerate(zs):
        fp.predict()
        at.predict()
        if k % 250 == 0:
            assert_close(at.x_prior, fp.x_prior, what=f"x_prior {k}")
            assert_close(at.P_prior, fp.P_prior, what=f"P_prior {k}")
        fp.update(z)
        at.update(z)
        assert_close(at.x, fp.x, what=f"x {k}")
        assert_close(at.P, fp.P, what=f"P {k}")
    assert_close(at.K, fp.K, what="K")
    assert_close(at.y, fp.y, what="y")
    assert_close(at.S, fp.S, what="S")
    assert_close(at.x_post, fp.x_post, what="x_post")
    assert at.log_likelihood == pytest.approx(fp.log_likelihood, rel=1e-9)
    assert at.mahalanobis == pytest.approx(fp.mahalanobis, rel=1e-9)


def test_batch_callbacks_match_filterpy_with_missing_measurements_rs_and_dts():
    fp, at = radar_pair(alpha=0.5, beta=2.0, kappa=0.0)
    zs = list(radar_data())
    for k in range(3, STEPS, 97):
        zs[k] = None
    rng = np.random.default_rng(5)
    dts = 1.0 + 0.1 * rng.uniform(size=STEPS)
    Rs = [np.diag([0.3**2, 0.005**2]) * s for s in 1.0 + rng.uniform(size=STEPS)]
    m_ref, c_ref = fp.batch_filter(zs, Rs=Rs, dts=dts)
    m, c = at.batch_filter(zs, Rs=Rs, dts=dts)
    assert_close(m, m_ref, what="means")
    assert_close(c, c_ref, what="covariances")
    assert_close(at.x, fp.x, what="final x")
    assert_close(at.P, fp.P, what="final P")


def test_builtin_linear_model_matches_filterpy_over_2000_steps():
    """The fast path (whole batch in Rust) on the 9-state model of the benchmark."""
    dt = 0.01
    F, H = constant_acceleration(dt)
    model = est.LinearModel(F, H)
    zs = ca_data(dt=dt)
    Q = filterpy_common.Q_discrete_white_noise(dim=3, dt=dt, var=1e-2, block_size=3, order_by_dim=False)

    def setup(kf):
        kf.x = np.zeros(9)
        kf.P = np.eye(9)
        kf.Q = Q
        kf.R = np.eye(3) * 0.05**2

    for alpha, beta, kappa in [(0.1, 2.0, -6.0), (1.0, 2.0, 0.0)]:
        fp = filterpy_kalman.UnscentedKalmanFilter(
            9, 3, dt, hx=model.hx, fx=model.fx, points=filterpy_kalman.MerweScaledSigmaPoints(9, alpha, beta, kappa)
        )
        at = est.UnscentedKalmanFilter.from_model(model, est.MerweScaledSigmaPoints(9, alpha, beta, kappa), dt=dt)
        setup(fp)
        setup(at)
        m_ref, c_ref = fp.batch_filter(zs)
        m, c = at.batch_filter(zs)
        assert m.shape == m_ref.shape == (STEPS, 9)
        assert c.shape == c_ref.shape == (STEPS, 9, 9)
        assert_close(m, m_ref, what=f"means alpha={alpha}")
        assert_close(c, c_ref, what=f"covariances alpha={alpha}")


def test_builtin_constant_velocity_with_inputs_matches_filterpy():
    model = est.ConstantVelocityModel(2, dt=0.1)
    rng = np.random.default_rng(9)
    us = rng.normal(size=(500, 2))
    zs = rng.normal(size=(500, 2)) + np.cumsum(np.cumsum(us, axis=0), axis=0) * 0.01
    pts = (4, 0.3, 2.0, -1.0)
    fp = filterpy_kalman.UnscentedKalmanFilter(
        4, 2, 0.1, hx=model.hx, fx=model.fx, points=filterpy_kalman.MerweScaledSigmaPoints(*pts)
    )
    at = est.UnscentedKalmanFilter(4, 2, 0.1, None, model, est.MerweScaledSigmaPoints(*pts))
    for kf in (fp, at):
        kf.Q = np.eye(4) * 1e-3
        kf.R = np.eye(2) * 0.5
    xs = []
    for u, z in zip(us, zs, strict=True):
        fp.predict(u=u)
        fp.update(z)
        xs.append(fp.x.copy())
    m, _ = at.batch_filter(zs, us=us)
    assert_close(m, np.array(xs), what="means")
    assert_close(at.P, fp.P, what="final P")


def test_callback_path_equals_builtin_path():
    dt = 0.01
    F, H = constant_acceleration(dt)
    B = np.zeros((9, 3))
    B[6:, :] = np.eye(3)
    model = est.LinearModel(F, H, B)
    zs = ca_data(steps=400, dt=dt)
    us = np.random.default_rng(4).normal(size=(400, 3)) * 0.01
    pts = est.MerweScaledSigmaPoints(9, 0.2, 2.0, 0.0)
    fast = est.UnscentedKalmanFilter.from_model(model, pts, dt=dt)
    slow = est.UnscentedKalmanFilter(9, 3, dt, model.hx, model.fx, pts)
    for kf in (fast, slow):
        kf.P = np.eye(9) * 2.0
        kf.Q = np.eye(9) * 1e-5
        kf.R = np.eye(3) * 0.01
    m_fast, c_fast = fast.batch_filter(zs, us=us)
    for u, z in zip(us, zs, strict=True):
        slow.predict(u=u)  # callbacks receive u as a keyword, like filterpy's fx_args
        slow.update(z)
    assert_close(slow.x, m_fast[-1], 1e-12, "x")
    assert_close(slow.P, c_fast[-1], 1e-12, "P")


def test_closed_form_kalman_filter_equals_builtin_batch():
    dt = 0.05
    F, H = constant_acceleration(dt)
    zs = ca_data(steps=300, dt=dt)
    Q = np.eye(9) * 1e-4
    R = np.eye(3) * 0.01
    x = np.zeros(9)
    P = np.eye(9)
    kf = est.UnscentedKalmanFilter.from_model(
        est.LinearModel(F, H), est.MerweScaledSigmaPoints(9, 0.7, 2.0, 0.0), dt=dt
    )
    kf.Q, kf.R = Q, R
    for variant in [{}, {"square_root": True}, {"noise": "augmented"}]:
        f = est.UnscentedKalmanFilter.from_model(
            est.LinearModel(F, H), est.MerweScaledSigmaPoints(9, 0.7, 2.0, 0.0), dt=dt, **variant
        )
        f.Q, f.R = Q, R
        out = f.batch(zs)
        x, P = np.zeros(9), np.eye(9)
        for k, z in enumerate(zs):
            x, P = F @ x, F @ P @ F.T + Q
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            y = z - H @ x
            x, P = x + K @ y, P - K @ S @ K.T
            P = 0.5 * (P + P.T)
            ll = -0.5 * (y @ np.linalg.solve(S, y) + np.log(np.linalg.det(S)) + 3 * np.log(2 * np.pi))
            assert out["log_likelihoods"][k] == pytest.approx(ll, rel=1e-9, abs=1e-9)
        assert_close(out["xs"][-1], x, 1e-9, f"x {variant}")
        assert_close(out["Ps"][-1], P, 1e-9, f"P {variant}")


def test_per_call_overrides_match_filterpy():
    """predict(dt=, fx=, **fx_args) and update(R=scalar, hx=, **hx_args) as filterpy."""

    def fx_scaled(x, dt, gain=1.0):
        return cv_fx(x, dt) * np.array([1.0, gain, 1.0, gain])

    def hx_offset(x, offset=0.0):
        return radar_hx(x) + np.array([offset, 0.0])

    fp, at = radar_pair(alpha=0.5, beta=2.0, kappa=0.0)
    for k, z in enumerate(radar_data(steps=40)):
        for kf in (fp, at):
            kf.predict(dt=0.5, fx=fx_scaled, gain=0.99)
            kf.update(z, R=0.01 * (1 + k % 3), hx=hx_offset, offset=0.1)
        assert_close(at.x, fp.x, what=f"x {k}")
        assert_close(at.P, fp.P, what=f"P {k}")
    assert_close(at.x_prior, fp.x_prior, what="x_prior")


def test_builtin_batch_releases_the_gil():
    import threading

    model = est.ConstantVelocityModel(3, dt=0.01)
    kf = est.UnscentedKalmanFilter.from_model(model, est.MerweScaledSigmaPoints(6, 0.5, 2.0, 0.0))
    zs = np.random.default_rng(0).normal(size=(50_000, 3))
    ticks = [0]
    seen = {}
    done = threading.Event()

    def run():
        seen["before"] = ticks[0]
        kf.batch_filter(zs)
        seen["after"] = ticks[0]
        done.set()

    worker = threading.Thread(target=run)
    worker.start()
    while not done.is_set():
        ticks[0] += 1  # the main thread advances during the batch only if the GIL is released
    worker.join()
    assert seen["after"] - seen["before"] > 1000


def test_square_root_matches_standard_on_the_nonlinear_model():
    _, std = radar_pair(alpha=1.0, beta=2.0, kappa=-1.0)
    _, sr = radar_pair(alpha=1.0, beta=2.0, kappa=-1.0, square_root=True)
    zs = radar_data(steps=500)
    m1, c1 = std.batch_filter(zs)
    m2, c2 = sr.batch_filter(zs)
    assert_close(m2, m1, what="means")
    assert_close(c2, c1, what="covariances")


def test_filterpy_saver_works():
    fp, at = radar_pair()
    saver = filterpy_common.Saver(at)
    zs = radar_data(steps=20)
    m, _ = at.batch_filter(zs, saver=saver)
    m_ref, _ = fp.batch_filter(zs)
    saver.to_array()
    assert_close(saver.x, m_ref, what="saved x")
    assert_close(m, m_ref, what="means")
    assert copy.deepcopy(est.LinearModel(np.eye(2), np.eye(2))).dim_x == 2


def test_augmented_callbacks_receive_noise():
    """Noise entering x' = x + dt * (v + w): the augmented filter equals the KF with G Q G^T."""
    dt = 1.0
    calls = {"w": 0}

    def fx(x, dt, w):
        calls["w"] += 1
        return np.array([x[0] + dt * x[1] + 0.5 * dt * w[0], x[1] + w[0]])

    def hx(x, v):
        return np.array([x[0] + v[0]])

    f = est.UnscentedKalmanFilter(
        2, 1, dt, hx, fx, est.MerweScaledSigmaPoints(2, 0.5, 2.0, 0.0), noise="augmented", dim_w=1
    )
    assert f.Q.shape == (1, 1)
    f.Q = np.array([[0.04]])
    f.R = np.array([[0.25]])
    zs = np.arange(30, dtype=float)[:, None] * 0.7
    m, c = f.batch_filter(zs)
    assert calls["w"] == 30 * 7  # 2 * (2 + 1) + 1 sigma points per prediction
    Fm = np.array([[1.0, dt], [0.0, 1.0]])
    G = np.array([[0.5 * dt], [1.0]])
    x, P = np.zeros(2), np.eye(2)
    for z in zs:
        x, P = Fm @ x, Fm @ P @ Fm.T + G @ f.Q @ G.T
        S = P[:1, :1] + f.R
        K = P[:, :1] @ np.linalg.inv(S)
        x, P = x + K @ (z - x[:1]), P - K @ S @ K.T
    assert_close(m[-1], x, 1e-10, "x")
    assert_close(c[-1], P, 1e-10, "P")


# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------


def test_bad_inputs_raise_invalid_input():
    _, at = radar_pair()
    at.predict()
    with pytest.raises(InvalidInputError, match=r"measurement z: expected shape \(2,\), got \(3,\)"):
        at.update(np.array([1.0, 2.0, 3.0]))
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        at.update(np.array([1.0, np.nan]))
    at.P = np.diag([1.0, -1.0, 1.0, 1.0])
    with pytest.raises(InvalidInputError, match="covariance P"):
        at.predict()
    at.P = np.eye(4)
    at.P[0, 1] = 0.5
    with pytest.raises(InvalidInputError, match="not a valid covariance"):
        at.predict()
    at.P = np.eye(4)
    at.Q = np.eye(3)
    with pytest.raises(InvalidInputError, match=r"process noise Q: expected shape \(4, 4\)"):
        at.predict()
    at.Q = np.eye(4) * 1e-4
    with pytest.raises(InvalidInputError, match="zs"):
        at.batch_filter([np.zeros(3)])
    with pytest.raises(InvalidInputError, match="points.n"):
        est.UnscentedKalmanFilter(3, 1, 1.0, radar_hx, cv_fx, est.MerweScaledSigmaPoints(4, 1.0, 2.0, 0.0))
    with pytest.raises(InvalidInputError, match="kappa"):
        est.MerweScaledSigmaPoints(4, 1.0, 2.0, -5.0)
    with pytest.raises(InvalidInputError, match="UT"):
        at.predict(UT=lambda *a: None)
    with pytest.raises(InvalidInputError, match="built-in"):
        est.UnscentedKalmanFilter.from_model(
            est.ConstantVelocityModel(2), est.MerweScaledSigmaPoints(4, 1, 2, 0)
        ).predict(w=1)
    with pytest.raises(InvalidInputError, match=r"measurement matrix H: expected shape \(2, 3\), got \(2, 2\)"):
        est.LinearModel(np.eye(3), np.eye(2))
    with pytest.raises(InvalidInputError, match="transition matrix F"):
        est.LinearModel(np.ones((2, 3)), np.eye(2))


def test_callback_errors_propagate():
    def boom(x, dt):
        raise KeyError("boom")

    f = est.UnscentedKalmanFilter(4, 2, 1.0, radar_hx, boom, est.MerweScaledSigmaPoints(4, 1.0, 2.0, 0.0))
    with pytest.raises(KeyError, match="boom"):
        f.predict()
    g = est.UnscentedKalmanFilter(
        4, 2, 1.0, radar_hx, lambda x, dt: x[:3], est.MerweScaledSigmaPoints(4, 1.0, 2.0, 0.0)
    )
    with pytest.raises(InvalidInputError, match=r"fx returned an array of shape \(3,\), expected 4 values"):
        g.predict()


def test_nan_during_filtering_names_the_step():
    def fx(x, dt):
        return x + 1.0 if x[0] < 4.5 else np.full(2, np.nan)

    f = est.UnscentedKalmanFilter(2, 1, 1.0, lambda x: x[:1], fx, est.MerweScaledSigmaPoints(2, 1.0, 2.0, 0.0))
    f.P = np.eye(2) * 1e-6
    f.Q = np.eye(2) * 1e-6
    f.R = np.eye(1) * 1e-6
    with pytest.raises(ConvergenceError, match=r"step 5: fx output at sigma point \d+ is not finite"):
        f.batch_filter(np.arange(1.0, 11.0)[:, None])
    assert f.x[0] == pytest.approx(5.0, abs=1e-3)  # the filter holds the last completed stage


def test_indefinite_covariance_is_reported_or_repaired():
    """Negative kappa with beta = 0 makes the unscented covariance of x0**2 negative (-0.5 P00**2)."""

    def fx(x, dt):
        return np.array([x[0] ** 2, x[1]])

    def hx(x):
        return np.array([x[0] + x[1]])

    pts = est.MerweScaledSigmaPoints(2, 1.0, 0.0, -1.5)
    for square_root in (False, True):
        f = est.UnscentedKalmanFilter(2, 1, 1.0, hx, fx, pts, square_root=square_root)
        f.Q = np.eye(2) * 0.1
        with pytest.raises(ConvergenceError, match=r"step 0: predicted covariance P_prior is not positive definite"):
            f.predict()
        r = est.UnscentedKalmanFilter(2, 1, 1.0, hx, fx, pts, square_root=square_root, repair=True)
        r.Q = np.eye(2) * 0.1
        r.predict()
        assert r.repairs == 1
        assert np.all(np.linalg.eigvalsh(r.P) > 0)
        assert r.P[1, 1] == pytest.approx(1.1, rel=1e-12)
        r.update(np.array([0.2]))
        assert np.all(np.linalg.eigvalsh(r.P) > 0)


# ---------------------------------------------------------------------------------------------
# The auto-teaching UKF (000_3b1454b2b2194811.txt eqs. (5.1)–(5.2)): what the odometry can tell
# about the joint zero offsets (Cramér–Rao bound) and whether the filter reaches it.
# ---------------------------------------------------------------------------------------------

#: A teaching motion that turns the arm (yaw ±30°, 25 × 30 cm): the offsets' signal in the camera
#: motion grows with the change of the arm's configuration.
TEACH = dict(yaw_max=math.radians(30.0), x_range=(-0.60, -0.35), y_range=(-0.15, 0.15))


def _session(frames, seed=0, teach=True):
    from autoteach.geometry import WaferRobot
    from autoteach.sim import SimConfig, TrajectoryConfig, simulate_session

    cfg = SimConfig(trajectory=TrajectoryConfig(**TEACH)) if teach else SimConfig()
    s = simulate_session(seed=seed, frames=frames, render=False, config=cfg)
    robot = WaferRobot(params=s.config.robot, base=np.array(s.config.base_pose))
    return s, robot, np.asarray(s.calibration.joint_offsets)[[0, 1, 3]]


def test_offset_fisher_information_matches_finite_differences():
    """I = Jᵀ Σ⁻¹ J with the closed-form J (joint twists) against J by central differences of FK."""
    from autoteach.sim.odometry import OdometryConfig, SlamConfig, offset_information, predicted_increments

    s, robot, true = _session(40, seed=1)
    enc = np.asarray(s.joints_encoder)
    for frame, cfg in (("world", OdometryConfig()), ("camera", OdometryConfig()), ("camera", SlamConfig())):
        info = offset_information(robot, enc, true, cfg, s.config.encoder_noise, frame)
        h = 1e-6
        jfd = np.zeros_like(info.jacobian)
        for j in range(3):
            d = np.zeros(3)
            d[j] = h
            diff = predicted_increments(robot, enc, true + d, frame) - predicted_increments(robot, enc, true - d, frame)
            jfd[:, j] = (diff / (2 * h)).T.reshape(-1)
        chol = np.linalg.cholesky(info.covariance)
        wj = np.linalg.solve(chol, jfd)
        fisher_fd = wj.T @ wj
        scale = np.abs(info.fisher).max()
        assert np.abs(fisher_fd - info.fisher).max() < 1e-6 * scale, (frame, fisher_fd, info.fisher)
        # All joint axes are parallel: the rotation increments do not depend on the offsets.
        n = len(enc) - 1
        assert np.abs(jfd[3 * n :]).max() < 1e-7
        if frame == "camera":
            # θ1 turns the whole trajectory rigidly about the base z axis: invisible in relative motion.
            assert np.abs(jfd[:, 0]).max() < 1e-7
            assert info.unobservable == ("joint1",) and math.isinf(info.crb_std[0])
        else:
            assert info.unobservable == () and np.all(np.isfinite(info.crb_std))


def test_offset_bound_matches_the_spread_of_the_batch_estimate():
    """The CRB (from the modelled covariance) against the spread of the batch estimate over 24 SLAM noise draws."""
    from autoteach.sim.odometry import SlamConfig, batch_offsets, offset_information, simulate_slam

    s, robot, true = _session(80, seed=2)
    enc = np.asarray(s.joints_encoder)
    cfg = SlamConfig(map_translation=1e-4)
    info = offset_information(robot, enc, true, cfg, s.config.encoder_noise, "camera")
    errs = []
    for k in range(24):
        inc = simulate_slam(s.camera_poses, 100 + k, cfg)
        est_k, _, bad = batch_offsets(robot, enc, inc, cfg, s.config.encoder_noise, "camera", 3, info)
        assert bad == ("joint1",)
        errs.append(est_k[1:] - true[1:])
    spread = np.sqrt(np.mean(np.square(errs), axis=0))  # RMS about the truth (the estimator is unbiased)
    ratio = spread / info.crb_std[1:]
    # 24 draws: the RMS of a unit normal lies in [0.67, 1.33] with probability > 99 %.
    assert np.all((ratio > 0.6) & (ratio < 1.4)), (ratio, np.degrees(info.crb_std))


def test_ukf_with_slam_odometry_reaches_the_bound_and_converges():
    """UKF (SLAM increments, state augmented by the SLAM's error) against simulator truth and the CRB."""
    from autoteach import _core
    from autoteach.pipeline import _robot_array
    from autoteach.sim.odometry import SlamConfig, batch_offsets, offset_information, simulate_slam

    s, robot, true = _session(200, seed=0)
    enc = np.ascontiguousarray(s.joints_encoder)
    cfg = SlamConfig()
    inc = simulate_slam(s.camera_poses, 0, cfg)
    run = _core.handeye_ukf(
        _robot_array(s.config.robot),
        np.array(s.config.base_pose),
        enc,
        np.ascontiguousarray(inc),
        cfg.ukf_noise(s.config.encoder_noise),
        odometry=cfg.ukf_odometry(),
    )
    info = offset_information(robot, enc, true, cfg, s.config.encoder_noise, "camera")
    est_b, _, _ = batch_offsets(robot, enc, inc, cfg, s.config.encoder_noise, "camera")
    err = run["offsets"][-1] - true
    sd = run["offset_std"][-1]
    crb = info.crb_std
    # θ2, θ4: inside 3σ, within 0.02°, σ near the bound, and next to the batch estimate.
    assert np.all(np.abs(err[1:]) < 3 * sd[1:]), (np.degrees(err), np.degrees(sd))
    assert np.all(np.abs(err[1:]) < math.radians(0.02)), np.degrees(err)
    assert np.all(sd[1:] < 1.5 * crb[1:]), (np.degrees(sd), np.degrees(crb))
    assert np.all(sd[1:] > 0.9 * crb[1:]), (np.degrees(sd), np.degrees(crb))
    assert np.all(np.abs(run["offsets"][-1][1:] - est_b[1:]) < crb[1:]), (
        np.degrees(run["offsets"][-1]),
        np.degrees(est_b),
    )
    # θ1 is unobservable from relative motion: not estimated, reported with its prior (2°).
    assert list(run["observable"]) == [False, True, True]
    assert abs(run["offsets"][-1][0]) < 1e-6 and sd[0] == 0.035
    # Convergence over frames: σ shrinks from the prior.
    assert np.all(run["offset_std"][0][1:] > 10 * sd[1:])


def test_ukf_slam_odometry_bad_values_raise():
    from autoteach import _core
    from autoteach.pipeline import _robot_array
    from autoteach.sim import SimConfig

    p = _robot_array(SimConfig().robot)
    enc = np.tile([0.2, 1.4, 0.3, -1.5, 0.1], (3, 1))
    inc = np.zeros((2, 6))
    with pytest.raises(InvalidInputError, match="4 values"):
        _core.handeye_ukf(p, np.eye(4), enc, inc, odometry=[1e-4, 1e-4, 0.0])
    with pytest.raises(InvalidInputError, match="map_step"):
        _core.handeye_ukf(p, np.eye(4), enc, inc, odometry=[1e-4, 1e-4, 0.0, 1.0])
    with pytest.raises(InvalidInputError, match="loc_t"):
        _core.handeye_ukf(p, np.eye(4), enc, inc, odometry=[0.0, 1e-4, 0.0, 0.5])


def test_pipeline_ukf_slam_odometry_reports_joint1_unobservable():
    """autoteach(..., ukf_odometry="slam"): SLAM increments, θ1 unobservable, θ2/θ4 errors against the truth."""
    from autoteach.pipeline import autoteach
    from autoteach.sim import simulate_session

    s = simulate_session(seed=3, frames=60, render=False)
    true = np.asarray(s.calibration.joint_offsets)[[0, 1, 3]]
    vo = autoteach(s, frontend="simulated", seed=3, window=0)
    assert vo.ukf["observable"] == [True, True, True] and vo.offset_status["joint1"] == "ukf"
    slam = autoteach(s, frontend="simulated", seed=3, window=0, ukf_odometry="slam")
    assert slam.ukf["observable"] == [False, True, True]
    assert slam.offset_status["joint1"].startswith("unobservable")
    err = np.abs(slam.ukf["offsets"][-1] - true)[1:]
    assert slam.ukf["errors"]["joint_offset_deg"] == pytest.approx(np.degrees(err.max()))
    assert np.all(err < 3 * slam.ukf["offset_std"][-1][1:])
    # The dead-reckoned SLAM trajectory starts at the uncalibrated forward kinematics.
    np.testing.assert_allclose(slam.ukf["odometry_poses"][0], slam.ukf["encoder_poses"][0])
    with pytest.raises(InvalidInputError, match="ukf_odometry"):
        autoteach(s, frontend="simulated", window=0, ukf_odometry="map")
