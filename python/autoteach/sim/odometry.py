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
