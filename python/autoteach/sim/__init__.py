"""The simulated wafer-handling robot, with full ground truth.

A carrier of wafers, the robot with its blade camera, a joint trajectory, encoder readings and
rendered images.

>>> from autoteach.sim import simulate_session
>>> session = simulate_session(seed=7, frames=3)  # doctest: +SKIP
>>> session.images.shape, session.wafer_slots.tolist()  # doctest: +SKIP
((3, 720, 1280), [4, 7, 10, 13, 15, 17, 19, 21, 22, 23, 24, 25])

See :class:`SimConfig` for the scene, noise and trajectory settings and :class:`Session` for the
recorded data and the ground truth. Sessions are stored as MCAP logs by :mod:`autoteach.io`.
"""

from __future__ import annotations

from autoteach.session import JOINT_NAMES, Calibration, CameraInfo, Session
from autoteach.sim.config import DEFAULT_BASE_POSE, DEFAULT_SLOTS, Lighting, SimConfig, TrajectoryConfig
from autoteach.sim.odometry import (
    OdometryConfig,
    integrate_odometry,
    relative_odometry,
    simulate_odometry,
    true_increments,
)
from autoteach.sim.simulate import simulate_session, wafer_poses
from autoteach.sim.trajectory import BSpline

__all__ = [
    "DEFAULT_BASE_POSE",
    "DEFAULT_SLOTS",
    "JOINT_NAMES",
    "BSpline",
    "Calibration",
    "CameraInfo",
    "Lighting",
    "OdometryConfig",
    "Session",
    "SimConfig",
    "TrajectoryConfig",
    "integrate_odometry",
    "relative_odometry",
    "simulate_odometry",
    "simulate_session",
    "true_increments",
    "wafer_poses",
]
