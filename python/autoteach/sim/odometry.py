"""Simulated visual odometry: per-frame camera-motion increments that drift.

The UKF of 000_3b1454b2b2194811.txt §5.2 takes the output of a visual SLAM front end as its
process input: ``u_T`` (change of the camera translation, world frame) and ``u_R`` (the
incremental rotation, camera frame) between consecutive frames, eq. (5.1). Visual SLAM is
accurate over short spans and drifts over long ones (Figs. 5.3, 5.4, 5.8); this module turns the
true camera trajectory of a simulated session into such increments: the true increment plus
white noise plus a bias that performs a random walk (the drift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError


@dataclass(frozen=True)
class OdometryConfig:
    """Noise of the simulated visual odometry (per frame, SI units).

    Attributes:
        translation_noise: std of the white noise on ``u_T`` (m).
        rotation_noise: std of the white noise on ``u_R`` (rad).
        translation_drift: std of the per-frame random-walk step of the translation bias (m).
        rotation_drift: std of the per-frame random-walk step of the rotation bias (rad).

    """

    translation_noise: float = 0.0001
    rotation_noise: float = math.radians(0.01)
    translation_drift: float = 0.000005
    rotation_drift: float = math.radians(0.0005)

    def ukf_noise(self) -> list[float]:
        """UKF noise levels (16 values, see ``autoteach._core.handeye_ukf``) matched to this odometry.

        Process noise: three times the white noise per step (covering the slowly growing bias);
        measurement noise: the encoder-level precision of the forward kinematics.
        """
        d = math.radians
        w_t = 3.0 * self.translation_noise + 1e-6
        w_e = 3.0 * self.rotation_noise + 1e-9
        return [w_t] * 3 + [w_e] * 3 + [5e-5] * 3 + [d(0.005)] * 3 + [d(0.002)] * 3 + [1e-5]

    def __post_init__(self) -> None:
        for name in ("translation_noise", "rotation_noise", "translation_drift", "rotation_drift"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v < 0.0:
                raise InvalidInputError(f"odometry {name} must be finite and >= 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, v)


def _log_so3(r: np.ndarray) -> np.ndarray:
    c = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    th = math.acos(c)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if th < 1e-9:
        return 0.5 * w
    return th / (2.0 * math.sin(th)) * w


def _exp_so3(w: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + math.sin(th) / th * k + (1.0 - math.cos(th)) / th**2 * (k @ k)


def true_increments(camera_poses: np.ndarray) -> np.ndarray:
    """Exact increments ``[u_T; u_R]`` (F−1, 6) of a trajectory ``T_wc`` (F, 4, 4), eq. (5.1)."""
    poses = np.asarray(camera_poses, dtype=np.float64)
    out = np.zeros((max(len(poses) - 1, 0), 6))
    for k in range(len(poses) - 1):
        out[k, :3] = poses[k + 1, :3, 3] - poses[k, :3, 3]
        out[k, 3:] = _log_so3(poses[k, :3, :3].T @ poses[k + 1, :3, :3])
    return out


def simulate_odometry(camera_poses: np.ndarray, seed: int, config: OdometryConfig | None = None) -> np.ndarray:
    """Drifting visual-odometry increments (F−1, 6) of a true trajectory; deterministic for ``seed``."""
    config = config or OdometryConfig()
    exact = true_increments(camera_poses)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x564F]))
    n = len(exact)
    bias_t = np.cumsum(rng.normal(0.0, config.translation_drift, (n, 3)), axis=0)
    bias_r = np.cumsum(rng.normal(0.0, config.rotation_drift, (n, 3)), axis=0)
    out = exact.copy()
    out[:, :3] += bias_t + rng.normal(0.0, config.translation_noise, (n, 3))
    out[:, 3:] += bias_r + rng.normal(0.0, config.rotation_noise, (n, 3))
    return out


def integrate_odometry(start: np.ndarray, increments: np.ndarray) -> np.ndarray:
    """The trajectory (F, 4, 4) obtained by chaining increments from the pose ``start`` (dead reckoning)."""
    poses = [np.asarray(start, dtype=np.float64).copy()]
    for u in np.asarray(increments, dtype=np.float64):
        p = poses[-1].copy()
        p[:3, 3] = p[:3, 3] + u[:3]
        p[:3, :3] = p[:3, :3] @ _exp_so3(u[3:])
        poses.append(p)
    return np.stack(poses)


def relative_odometry(increments: np.ndarray, start_rotation: np.ndarray) -> np.ndarray:
    """Odometry increments ``[u_T; u_R]`` (F−1, 6) as relative camera poses ``T_wc(t)⁻¹·T_wc(t+1)`` (F−1, 4, 4).

    ``u_T`` is expressed in the odometry's world frame and ``u_R`` in the camera frame
    (eq. (5.1)), so the relative pose is ``[Exp(u_R), R(t)ᵀ·u_T]`` with ``R(t)`` the
    odometry's own rotation at ``t``, chained from ``start_rotation`` (the odometry's world
    orientation of the first camera frame): the form of the visual-odometry factor between
    consecutive camera poses (000_3b1454b2b2194811.txt eqs. (5.6), (5.11)).
    """
    inc = np.asarray(increments, dtype=np.float64)
    if inc.ndim != 2 or inc.shape[1] != 6 or not np.all(np.isfinite(inc)):
        raise InvalidInputError(f"odometry increments must be a finite (F-1, 6) array, got shape {inc.shape}")
    r = np.asarray(start_rotation, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)) or not np.allclose(r.T @ r, np.eye(3), atol=1e-6):
        raise InvalidInputError("start_rotation must be a finite 3x3 rotation matrix")
    out = np.zeros((len(inc), 4, 4))
    for k, u in enumerate(inc):
        step = _exp_so3(u[3:])
        out[k, :3, :3] = step
        out[k, :3, 3] = r.T @ u[:3]
        out[k, 3, 3] = 1.0
        r = r @ step
    return out


@dataclass(frozen=True)
class SlamConfig:
    """Errors of a simulated visual SLAM with a map (the seed's ORB-SLAM2, §5.2), per frame, SI units.

    A SLAM localises every frame against its map, so its pose error does not accumulate like
    dead-reckoned odometry: the estimated pose is ``S(k) = (t(k) + e_T(k), R(k)·Exp(e_R(k)))``
    with ``e = l + m``: ``l`` white localisation noise and ``m`` the map's error, a stationary
    first-order Gauss–Markov process (std ``map_*``, correlation ``exp(−1/correlation_frames)``
    per frame) — bounded, slowly varying. The increments handed to the UKF are the relative
    poses ``S(k)⁻¹S(k+1)``: ``u_T`` in the camera frame, ``u_R`` the incremental rotation.

    Attributes:
        loc_translation: std of the white position error (m).
        loc_rotation: std of the white orientation error (rad).
        map_translation: stationary std of the map's position error (m).
        map_rotation: stationary std of the map's orientation error (rad).
        correlation_frames: correlation time of the map error (frames).

    """

    loc_translation: float = 0.0001
    loc_rotation: float = math.radians(0.01)
    map_translation: float = 0.00002
    map_rotation: float = 0.0
    correlation_frames: float = 50.0

    def __post_init__(self) -> None:
        for name in ("loc_translation", "loc_rotation", "map_translation", "map_rotation"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v < 0.0:
                raise InvalidInputError(f"SLAM {name} must be finite and >= 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, v)
        c = float(self.correlation_frames)
        if not math.isfinite(c) or c <= 0.0:
            raise InvalidInputError(f"SLAM correlation_frames must be finite and > 0, got {self.correlation_frames!r}")
        object.__setattr__(self, "correlation_frames", c)

    @property
    def map_step(self) -> float:
        """Per-frame correlation ``a`` of the map error."""
        return math.exp(-1.0 / self.correlation_frames)

    def ukf_odometry(self) -> list[float]:
        """The 4 values of ``autoteach._core.handeye_ukf(odometry=...)`` for this model.

        The UKF models the orientation error as white (``loc_rotation``); a map orientation
        error (``map_rotation``) is simulated but not modelled by the filter.
        """
        return [self.loc_translation, self.loc_rotation, self.map_translation, self.map_step]

    def ukf_noise(self, encoder_noise: Any = (2e-5, 2e-5, 2e-5, 2e-5, 5e-6)) -> list[float]:
        """UKF noise levels (16 values, see ``autoteach._core.handeye_ukf``) for SLAM increments.

        The process noise comes from the SLAM model itself (:meth:`ukf_odometry`; ``w_T``,
        ``w_E`` are unused); the measurement noise is the encoders' (``v_θ`` of θ1, θ2, θ4 and
        the lift, from the 5 per-joint stds), and the camera pose fed to the inverse kinematics
        carries no extra noise (``v_T``, ``v_E`` 1e-7, a floor that keeps R positive definite).
        """
        sn = [float(v) for v in np.asarray(encoder_noise, dtype=np.float64).reshape(-1)]
        if len(sn) != 5 or not all(math.isfinite(v) and v >= 0.0 for v in sn):
            raise InvalidInputError(f"encoder_noise must be 5 finite values >= 0, got {encoder_noise!r}")
        v_theta = [max(sn[j], 1e-9) for j in (0, 1, 3, 4)]
        return [1e-3] * 3 + [1e-3] * 3 + [1e-7] * 6 + v_theta

    def pose_error_covariance(self, frames: int) -> np.ndarray:
        """Covariance (6F × 6F, component-major: ``e_T,x`` of all frames first) of the pose errors."""
        idx = np.arange(frames)
        gm = self.map_step ** np.abs(np.subtract.outer(idx, idx))
        out = np.zeros((6 * frames, 6 * frames))
        for c in range(6):
            loc, mp = (self.loc_translation, self.map_translation) if c < 3 else (self.loc_rotation, self.map_rotation)
            out[c * frames : (c + 1) * frames, c * frames : (c + 1) * frames] = (
                loc * loc * np.eye(frames) + mp * mp * gm
            )
        return out


def simulate_slam_poses(camera_poses: np.ndarray, seed: int, config: SlamConfig | None = None) -> np.ndarray:
    """The SLAM's pose estimates ``S(k)`` (F, 4, 4) of a true trajectory; deterministic for ``seed``."""
    config = config or SlamConfig()
    poses = np.asarray(camera_poses, dtype=np.float64)
    n = len(poses)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x534C]))
    a = config.map_step
    drive = math.sqrt(max(1.0 - a * a, 0.0))
    m = np.zeros((n, 6))
    m[0] = rng.normal(0.0, 1.0, 6)
    for k in range(1, n):
        m[k] = a * m[k - 1] + drive * rng.normal(0.0, 1.0, 6)
    loc = rng.normal(0.0, 1.0, (n, 6))
    sd_loc = np.array([config.loc_translation] * 3 + [config.loc_rotation] * 3)
    sd_map = np.array([config.map_translation] * 3 + [config.map_rotation] * 3)
    e = loc * sd_loc + m * sd_map
    out = poses.copy()
    for k in range(n):
        out[k, :3, 3] += e[k, :3]
        out[k, :3, :3] = poses[k, :3, :3] @ _exp_so3(e[k, 3:])
    return out


def simulate_slam(camera_poses: np.ndarray, seed: int, config: SlamConfig | None = None) -> np.ndarray:
    """Increments (F−1, 6) ``[u_T (camera frame); u_R]`` of a simulated SLAM (:class:`SlamConfig`)."""
    return increments_in(simulate_slam_poses(camera_poses, seed, config), "camera")


# ---------------------------------------------------------------------------------------------
# What the odometry says about the joint zero offsets: Fisher information, Cramér–Rao bound and
# the batch least-squares estimate (the best any filter of eq. (5.1)–(5.2) can do).
# ---------------------------------------------------------------------------------------------

#: Joints whose zero offsets the UKF of eq. (5.1) estimates (θ1, θ2, θ4) and the measured joints.
UKF_JOINTS: tuple[int, ...] = (0, 1, 3)
_MEASURED: tuple[int, ...] = (0, 1, 3, 4)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _so3_right_jacobian_inv(phi: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(phi))
    k = _skew(phi)
    if th < 1e-8:
        return np.eye(3) + 0.5 * k + k @ k / 12.0
    return np.eye(3) + 0.5 * k + (1.0 / th**2 - (1.0 + math.cos(th)) / (2.0 * th * math.sin(th))) * (k @ k)


def _check_frame(frame: str) -> None:
    if frame not in ("world", "camera"):
        raise InvalidInputError(f"odometry frame must be 'world' or 'camera', got {frame!r}")


def increments_in(camera_poses: np.ndarray, frame: str = "world") -> np.ndarray:
    """Exact increments (F−1, 6) of ``T_wc`` (F, 4, 4) with ``u_T`` in the world or the camera frame.

    ``frame="world"``: ``u_T = t(k+1) − t(k)`` in the world (eq. (5.1) read literally: needs the
    odometry's world aligned with the true world); ``frame="camera"``: ``u_T = R(k)ᵀ(t(k+1) −
    t(k))``, the relative pose a visual odometry measures in its own frame. ``u_R = Log(R(k)ᵀ
    R(k+1))`` in both.
    """
    _check_frame(frame)
    out = true_increments(camera_poses)
    if frame == "camera":
        poses = np.asarray(camera_poses, dtype=np.float64)
        out[:, :3] = np.einsum("kji,kj->ki", poses[:-1, :3, :3], out[:, :3])
    return out


def joint_axis_twists(robot: Any, q_true: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera poses and their derivatives w.r.t. θ1, θ2, θ4 and the lift, in closed form.

    All revolute joints of the robot turn about the base z axis ``z_w = R_wb e_z``
    (000_3b1454b2b2194811.txt eq. (2.4)): turning joint j by ε moves the camera centre by
    ``ε z_w × (t − p_j)`` (``p_j`` a point of the joint's axis: the base origin for θ1, the elbow
    ``l1(cos θ1, sin θ1)`` for θ2, the wrist for θ4) and turns the camera by ``Exp(ε z_w)`` on
    the left; the lift moves it along ``z_w``.

    Returns:
        poses (F, 4, 4); ``dt`` (F, 3, 4): ∂t/∂(θ1, θ2, θ4, h); ``da`` (F, 3, 4): the world-frame
        rotation vector of each derivative (``z_w`` for the revolute joints, 0 for the lift).

    """
    q = np.asarray(q_true, dtype=np.float64)
    poses = np.asarray(robot.camera_pose(q), dtype=np.float64)
    base = np.asarray(robot.base, dtype=np.float64)
    p = robot.params
    z = base[:3, 2]
    t1 = q[:, 0]
    t12 = q[:, 0] + q[:, 1]
    elbow = np.stack([p.l1 * np.cos(t1), p.l1 * np.sin(t1), np.zeros_like(t1)], axis=1)
    wrist = elbow + np.stack([p.l2 * np.cos(t12), p.l2 * np.sin(t12), np.zeros_like(t1)], axis=1)
    axes = [np.zeros_like(elbow), elbow, wrist]
    t = poses[:, :3, 3]
    dt = np.zeros((len(q), 3, 4))
    da = np.zeros((len(q), 3, 4))
    for j, pj in enumerate(axes):
        pw = base[:3, 3] + pj @ base[:3, :3].T
        dt[:, :, j] = np.cross(z, t - pw)
        da[:, :, j] = z
    dt[:, :, 3] = z
    return poses, dt, da


def _increment_jacobians(
    poses: np.ndarray, dt: np.ndarray, da: np.ndarray, frame: str
) -> tuple[np.ndarray, np.ndarray]:
    """∂u(k)/∂(perturbation at k) and ∂u(k)/∂(perturbation at k+1): (F−1, 6, m) each."""
    r = poses[:, :3, :3]
    d = poses[1:, :3, 3] - poses[:-1, :3, 3]
    n, m = len(poses) - 1, dt.shape[2]
    a0 = np.zeros((n, 6, m))
    a1 = np.zeros((n, 6, m))
    for k in range(n):
        jr = _so3_right_jacobian_inv(_log_so3(r[k].T @ r[k + 1]))
        g = jr @ r[k + 1].T
        a0[k, 3:] = -g @ da[k]
        a1[k, 3:] = g @ da[k + 1]
        if frame == "world":
            a0[k, :3] = -dt[k]
            a1[k, :3] = dt[k + 1]
        else:
            # u_T = R(k)ᵀ Δt: R(k) → Exp(a)R(k) gives R(k)ᵀ(Δt × a).
            a0[k, :3] = r[k].T @ (-dt[k] + np.cross(d[k], da[k].T).T)
            a1[k, :3] = r[k].T @ dt[k + 1]
    return a0, a1


def _banded(a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """(6n, m(n+1)) map from per-frame perturbations (frame-major) to the increments (component-major)."""
    n, _, m = a0.shape
    c0, c1 = _component_major(a0), _component_major(a1)
    out = np.zeros((6 * n, m * (n + 1)))
    rows = np.arange(6 * n)
    for j in range(m):
        out[rows, m * (rows % n) + j] = c0[:, j]
        out[rows, m * (rows % n + 1) + j] = c1[:, j]
    return out


def odometry_noise_covariance(n: int, config: OdometryConfig | None = None) -> np.ndarray:
    """Covariance (6n × 6n, component-major: all ``u_T,x`` first) of the simulated odometry's errors.

    :func:`simulate_odometry` adds to increment ``k`` white noise ``σ_w`` and the bias
    ``b(k) = Σ_{i≤k} d(i)``, ``d ~ N(0, σ_d²)`` (the drift), independently per component:
    ``Cov(e_k, e_l) = σ_w² [k = l] + σ_d² (min(k, l) + 1)``.
    """
    config = config or OdometryConfig()
    idx = np.arange(n)
    walk = np.minimum.outer(idx, idx) + 1.0
    out = np.zeros((6 * n, 6 * n))
    for c in range(6):
        sw, sd = (
            (config.translation_noise, config.translation_drift)
            if c < 3
            else (config.rotation_noise, config.rotation_drift)
        )
        out[c * n : (c + 1) * n, c * n : (c + 1) * n] = sw * sw * np.eye(n) + sd * sd * walk
    return out


def _component_major(a: np.ndarray) -> np.ndarray:
    """(n, 6, m) → (6n, m) with the components outermost."""
    return np.transpose(a, (1, 0, 2)).reshape(6 * a.shape[0], a.shape[2])


@dataclass(frozen=True)
class OffsetInformation:
    """Fisher information of the joint zero offsets (θ1, θ2, θ4) in a session's odometry and encoders.

    Attributes:
        fisher: 3×3 Fisher information (rad⁻²).
        crb_std: Cramér–Rao bound of each offset's standard deviation (rad); ``inf`` for an
            offset in the null space of ``fisher`` (not identifiable from this data).
        jacobian: ∂h/∂δ (6(F−1), 3), component-major, of the predicted increments.
        covariance: the total covariance of the increment residuals (odometry + encoder noise).
        unobservable: names of the unidentifiable offsets.

    """

    fisher: np.ndarray
    crb_std: np.ndarray
    jacobian: np.ndarray
    covariance: np.ndarray
    unobservable: tuple[str, ...]


def _bound(fisher: np.ndarray, rel_tol: float = 1e-9) -> tuple[np.ndarray, tuple[str, ...]]:
    w, v = np.linalg.eigh(fisher)
    keep = w > rel_tol * max(float(w.max()), 1e-300)
    names = ("joint1", "joint2", "joint4")
    # An offset is unidentifiable when it has a component in the null space.
    null = v[:, ~keep]
    bad = tuple(names[i] for i in range(3) if np.linalg.norm(null[i]) > 1e-6) if null.size else ()
    cov = (v[:, keep] / w[keep]) @ v[:, keep].T
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    for i, name in enumerate(names):
        if name in bad:
            std[i] = math.inf
    return std, bad


def offset_information(
    robot: Any,
    encoders: np.ndarray,
    offsets: np.ndarray,
    config: OdometryConfig | SlamConfig | None = None,
    encoder_noise: np.ndarray | None = None,
    frame: str = "world",
) -> OffsetInformation:
    """Fisher information and Cramér–Rao bound of (θ1, θ2, θ4) for the model of eqs. (5.1)–(5.2).

    Data: the encoder readings ``q_enc = q_true + δ + n`` (eq. (5.1)'s ``y``, noise ``n`` with
    std ``encoder_noise`` per joint, 5 values) and the odometry increments of
    :func:`simulate_odometry` (noise model :func:`odometry_noise_covariance`) or, for a
    :class:`SlamConfig`, of :func:`simulate_slam` (pose errors mapped into the increments). The encoders fix
    the camera pose up to the offsets, ``T_wc(k) = FK(q_enc(k) − δ)``, so the increments predicted
    from them, ``h(δ)``, against the measured ones carry all the information: with
    ``J = ∂h/∂δ`` (closed form, :func:`joint_axis_twists`) and ``Σ = Σ_odo + B Σ_n Bᵀ`` (``B``:
    how encoder noise moves the predicted increments), ``I = Jᵀ Σ⁻¹ J`` and the bound is
    ``diag(I⁻¹)^½``. Rotation increments are invariant to the offsets (all joint axes are
    parallel); with ``frame="camera"`` θ1, whose axis passes through the base origin along the
    base z axis, turns the whole trajectory rigidly and is invisible (reported in
    ``unobservable``). ``offsets``: the true (θ1, θ2, θ4) (the point of linearisation).
    """
    _check_frame(frame)
    if isinstance(config, SlamConfig) and frame != "camera":
        raise InvalidInputError("SLAM increments are relative poses: use frame='camera'")
    enc = np.asarray(encoders, dtype=np.float64)
    if enc.ndim != 2 or enc.shape[1] != 5 or len(enc) < 2 or not np.all(np.isfinite(enc)):
        raise InvalidInputError(f"encoders must be a finite (F >= 2, 5) array, got shape {enc.shape}")
    off = np.asarray(offsets, dtype=np.float64).reshape(-1)
    if off.shape != (3,) or not np.all(np.isfinite(off)):
        raise InvalidInputError(f"offsets must be 3 finite values (θ1, θ2, θ4), got {offsets!r}")
    sn = np.asarray(encoder_noise if encoder_noise is not None else (2e-5, 2e-5, 2e-5, 2e-5, 5e-6), dtype=np.float64)
    if sn.shape != (5,) or not np.all(np.isfinite(sn)) or np.any(sn < 0):
        raise InvalidInputError(f"encoder_noise must be 5 finite values >= 0, got {encoder_noise!r}")
    q = enc.copy()
    q[:, list(UKF_JOINTS)] -= off
    poses, dt, da = joint_axis_twists(robot, q)
    a0, a1 = _increment_jacobians(poses, dt, da, frame)
    n = len(enc) - 1
    # ∂h/∂δ: q_true = q_enc − δ, so minus the joint derivatives of both frames of each increment.
    jac = _component_major(-(a0[:, :, :3] + a1[:, :, :3]))
    # Encoder noise of frame k enters increments k−1 (as frame k+1) and k (as frame k).
    b = _banded(a0, a1)
    var_n = np.tile(sn[list(_MEASURED)] ** 2, n + 1)
    cov = (b * var_n) @ b.T
    if isinstance(config, SlamConfig):
        # Pose errors (t + e_T, R·Exp(e_R)): world translation, left rotation R·e_R.
        dt_e = np.zeros((n + 1, 3, 6))
        dt_e[:, :, :3] = np.eye(3)
        da_e = np.zeros((n + 1, 3, 6))
        da_e[:, :, 3:] = poses[:, :3, :3]
        e = _banded(*_increment_jacobians(poses, dt_e, da_e, frame))
        # _banded orders the pose errors frame-major; the covariance is component-major.
        order = (np.arange(6)[None, :] * (n + 1) + np.arange(n + 1)[:, None]).reshape(-1)
        sig = config.pose_error_covariance(n + 1)[np.ix_(order, order)]
        cov += e @ sig @ e.T
    else:
        cov += odometry_noise_covariance(n, config)
    chol = np.linalg.cholesky(cov)
    wj = np.linalg.solve(chol, jac)
    fisher = wj.T @ wj
    std, bad = _bound(fisher)
    return OffsetInformation(fisher=fisher, crb_std=std, jacobian=jac, covariance=cov, unobservable=bad)


def _offset_jacobian(robot: Any, encoders: np.ndarray, offsets: np.ndarray, frame: str) -> np.ndarray:
    """∂h/∂δ (6(F−1), 3), component-major, of the increments of ``FK(q_enc − δ)``."""
    q = np.asarray(encoders, dtype=np.float64).copy()
    q[:, list(UKF_JOINTS)] -= offsets
    poses, dt, da = joint_axis_twists(robot, q)
    a0, a1 = _increment_jacobians(poses, dt[:, :, :3], da[:, :, :3], frame)
    return _component_major(-(a0 + a1))


def predicted_increments(robot: Any, encoders: np.ndarray, offsets: np.ndarray, frame: str = "world") -> np.ndarray:
    """Increments (F−1, 6) of the camera poses ``FK(q_enc − δ)`` (eq. (5.1) run on encoders)."""
    q = np.asarray(encoders, dtype=np.float64).copy()
    q[:, list(UKF_JOINTS)] -= np.asarray(offsets, dtype=np.float64)
    return increments_in(np.asarray(robot.camera_pose(q), dtype=np.float64), frame)


def batch_offsets(
    robot: Any,
    encoders: np.ndarray,
    increments: np.ndarray,
    config: OdometryConfig | SlamConfig | None = None,
    encoder_noise: np.ndarray | None = None,
    frame: str = "world",
    iterations: int = 5,
    information: OffsetInformation | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Batch generalised least squares of the offsets over the whole session (Gauss–Newton).

    Minimises ``rᵀ Σ⁻¹ r``, ``r = u − h(δ)`` with the full correlated covariance of
    :func:`offset_information` (white noise, drift and encoder noise): the maximum-likelihood
    estimate from all frames at once, the bound a causal filter of eq. (5.1) can at best reach at
    the last frame. Unidentifiable offsets stay at 0 and get an infinite std. ``information``: a
    precomputed :func:`offset_information` of the same session and noise model (reused for many
    noise draws); by default it is computed at ``δ = 0``.

    Returns:
        (offsets (3,), std (3,), unobservable names).

    """
    inc = np.asarray(increments, dtype=np.float64)
    enc = np.asarray(encoders, dtype=np.float64)
    if inc.shape != (len(enc) - 1, 6) or not np.all(np.isfinite(inc)):
        raise InvalidInputError(f"increments must be finite of shape ({len(enc) - 1}, 6), got {inc.shape}")
    delta = np.zeros(3)
    # The covariance hardly depends on δ (offsets of ~1° move the lever arms by ~1 %): factor it
    # once at δ = 0; the Jacobian and the residual are re-evaluated every iteration.
    info = information or offset_information(robot, enc, delta, config, encoder_noise, frame)
    whiten = np.linalg.inv(np.linalg.cholesky(info.covariance))  # L⁻¹, once (numpy has no triangular solve)
    for _ in range(max(int(iterations), 1)):
        h = predicted_increments(robot, enc, delta, frame)
        r = inc - h
        r[:, 3:] = [_log_so3(_exp_so3(hr).T @ _exp_so3(ur)) for ur, hr in zip(inc[:, 3:], h[:, 3:], strict=True)]
        rv = r.T.reshape(-1)
        wj = whiten @ _offset_jacobian(robot, enc, delta, frame)
        wr = whiten @ rv
        keep = [i for i, name in enumerate(("joint1", "joint2", "joint4")) if name not in info.unobservable]
        step = np.linalg.lstsq(wj[:, keep], wr, rcond=None)[0]
        delta[keep] += step
        if np.max(np.abs(step)) < 1e-12:
            break
    return delta, info.crb_std, info.unobservable


def integrate_relative(start: np.ndarray, increments: np.ndarray) -> np.ndarray:
    """The trajectory (F, 4, 4) chained from ``start`` by relative-pose increments (``u_T`` in the camera frame)."""
    poses = [np.asarray(start, dtype=np.float64).copy()]
    for u in np.asarray(increments, dtype=np.float64):
        step = np.eye(4)
        step[:3, :3] = _exp_so3(u[3:])
        step[:3, 3] = u[:3]
        poses.append(poses[-1] @ step)
    return np.stack(poses)
