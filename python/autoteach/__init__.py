"""autoteach: robust perception and self-calibration for camera-carrying robots.

Submodules:

- :mod:`autoteach.geometry` -- rigid transforms, the wafer-handling robot, camera models, conics.
- :mod:`autoteach.sim` -- the simulated wafer-handling robot and carrier (sessions with ground truth).
- :mod:`autoteach.io` -- MCAP session logs (write and read).
- :mod:`autoteach.detect` -- wafer-rim detection, ellipse fitting, CPD, global voting, polygon detection.
- :mod:`autoteach.track` -- multi-wafer tracking (hierarchical GMM association, track management).
- :mod:`autoteach.estimate` -- unscented Kalman filter and sparse nonlinear least squares.
- :mod:`autoteach.pipeline` -- auto-teaching end to end: :func:`autoteach` (UKF + SLAM-MOT).
- :mod:`autoteach.calib` -- guided camera calibration with Max ERE.
- :mod:`autoteach.active` -- active auto-teaching (Fisher information, next-pose planning).
"""

from __future__ import annotations

from autoteach._core import __version__
from autoteach.errors import (
    AutoteachError,
    ConvergenceError,
    DegenerateGeometryError,
    InternalError,
    InvalidInputError,
    LogReadError,
    UnreachablePoseError,
)
from autoteach.pipeline import AutoTeachResult, autoteach

__all__ = [
    "AutoTeachResult",
    "AutoteachError",
    "ConvergenceError",
    "DegenerateGeometryError",
    "InternalError",
    "InvalidInputError",
    "LogReadError",
    "UnreachablePoseError",
    "__version__",
    "autoteach",
]
