"""Compatibility path: :class:`~autoteach.session.Session` lives in :mod:`autoteach.session`.

A session is not specific to the simulator (logs of a real robot read into the same type), so it
moved to a neutral module; this module keeps ``autoteach.sim.session`` imports working.
"""

from __future__ import annotations

from autoteach.session import JOINT_NAMES, RIM_KEYS, Calibration, CameraInfo, Session

__all__ = ["JOINT_NAMES", "RIM_KEYS", "Calibration", "CameraInfo", "Session"]
