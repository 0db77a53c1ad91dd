"""Pose helpers of the auto-teaching pipeline: wafer parameters and their 4×4 frames.

A wafer's pose is the 5-vector ``[cx, cy, cz, rx, ry]`` of its centre and two tilts (the yaw
about its normal is not observable: a wafer is a circle), 000_3b1454b2b2194811.txt §5.3.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["axis_rotation", "log_so3", "rpy", "wafer_params_of", "wafer_pose"]


def rpy(r: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad) of a rotation ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``."""
    return (
        math.atan2(r[2, 1], r[2, 2]),
        math.asin(max(-1.0, min(1.0, -r[2, 0]))),
        math.atan2(r[1, 0], r[0, 0]),
    )


def axis_rotation(axis: str, a: float) -> np.ndarray:
    """The rotation by ``a`` (rad) about the ``"x"``, ``"y"`` or ``"z"`` axis."""
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)


def wafer_pose(w: np.ndarray) -> np.ndarray:
    """The 4×4 frame of wafer parameters ``[cx, cy, cz, rx, ry]`` (rotation ``Ry(ry)·Rx(rx)``)."""
    t = np.eye(4)
    t[:3, :3] = axis_rotation("y", w[4]) @ axis_rotation("x", w[3])
    t[:3, 3] = w[:3]
    return t


def wafer_params_of(pose: np.ndarray) -> np.ndarray:
    """Inverse of :func:`wafer_pose` for the centre and normal (the yaw about the normal is dropped)."""
    n = pose[:3, 2]
    if n[2] < 0:
        n = -n
    return np.array([pose[0, 3], pose[1, 3], pose[2, 3], -math.asin(max(-1.0, min(1.0, n[1]))), math.atan2(n[0], n[2])])


def log_so3(r: np.ndarray) -> np.ndarray:
    """The rotation vector ``Log(R)`` (rad) of a rotation matrix away from a half turn."""
    c = max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0))
    th = math.acos(c)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return 0.5 * w if th < 1e-9 else th / (2.0 * math.sin(th)) * w
