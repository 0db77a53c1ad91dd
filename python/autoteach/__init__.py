"""autoteach: robust perception and self-calibration for camera-carrying robots.

Submodules (each imported on first access, so ``import autoteach`` stays cheap and
``autoteach.detect.fit_ellipse(...)`` works without importing ``autoteach.detect`` first):

- :mod:`autoteach.geometry` -- rigid transforms, the wafer-handling robot, camera models, conics.
- :mod:`autoteach.sim` -- the simulated wafer-handling robot and carrier (sessions with ground truth).
- :mod:`autoteach.session` -- the :class:`~autoteach.session.Session` every stage consumes (logged or simulated).
- :mod:`autoteach.io` -- MCAP session logs (write and read).
- :mod:`autoteach.config` -- :class:`~autoteach.config.AutoteachConfig`, the options of auto-teaching.
- :mod:`autoteach.evaluation` -- errors of a result against a simulated session's ground truth.
- :mod:`autoteach.detect` -- wafer-rim detection, ellipse fitting, CPD, global voting, polygon detection.
- :mod:`autoteach.ellipse_detection` -- the general a-contrario elliptic-arc detector (also in ``detect``).
- :mod:`autoteach.track` -- multi-wafer tracking (hierarchical GMM association, track management).
- :mod:`autoteach.estimate` -- unscented Kalman filter and sparse nonlinear least squares.
- :mod:`autoteach.pipeline` -- auto-teaching end to end: :func:`autoteach` (UKF + SLAM-MOT).
- :mod:`autoteach.calib` -- guided camera calibration with Max ERE.
- :mod:`autoteach.active` -- active auto-teaching (Fisher information, next-pose planning).
- :mod:`autoteach.polygon`, :mod:`autoteach.registration` -- chamber openings, CPD and global
  registration (also re-exported by :mod:`autoteach.detect`); :mod:`autoteach.global_registration`
  -- global registration that reports every candidate and template symmetries.
- :mod:`autoteach.radio`, :mod:`autoteach.radio_tuning` -- radio signal-strength prediction and its
  meta-parameter search.
- :mod:`autoteach.report`, :mod:`autoteach.cli` -- the report writer and the command line.

Only numpy, mcap and tqdm are needed at run time; plots need the ``plot`` extra
(``pip install 'autoteach[plot]'``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from autoteach._core import __version__
from autoteach.errors import (
    AllocationError,
    AutoteachError,
    ConvergenceError,
    DegenerateGeometryError,
    InternalError,
    InvalidInputError,
    LogReadError,
    UnreachablePoseError,
)

if TYPE_CHECKING:
    from autoteach import (
        active,
        calib,
        cli,
        config,
        detect,
        ellipse_detection,
        estimate,
        evaluation,
        geometry,
        global_registration,
        io,
        mapping,
        pipeline,
        polygon,
        poses,
        radio,
        radio_tuning,
        registration,
        report,
        segment,
        session,
        sim,
        track,
        wafer_detect_options,
    )
    from autoteach.config import AutoteachConfig
    from autoteach.pipeline import AutoTeachResult, autoteach

#: The public submodules, imported lazily by :func:`__getattr__` (PEP 562).
SUBMODULES = (
    "active",
    "calib",
    "cli",
    "config",
    "control",
    "detect",
    "ellipse_detection",
    "estimate",
    "evaluation",
    "fusion",
    "geometry",
    "global_registration",
    "io",
    "mapping",
    "pipeline",
    "plan",
    "polygon",
    "poses",
    "radio",
    "radio_tuning",
    "registration",
    "report",
    "segment",
    "session",
    "sigma_points",
    "sim",
    "track",
    "uncertainty",
    "wafer_detect_options",
)

#: Names re-exported from submodules, also imported on first access.
_LAZY_NAMES = {"AutoTeachResult": "pipeline", "AutoteachConfig": "config", "autoteach": "pipeline"}

__all__ = [
    "AllocationError",
    "AutoTeachResult",
    "AutoteachConfig",
    "AutoteachError",
    "ConvergenceError",
    "DegenerateGeometryError",
    "InternalError",
    "InvalidInputError",
    "LogReadError",
    "UnreachablePoseError",
    "__version__",
    "active",
    "autoteach",
    "calib",
    "cli",
    "config",
    "control",
    "detect",
    "ellipse_detection",
    "estimate",
    "evaluation",
    "fusion",
    "geometry",
    "global_registration",
    "io",
    "mapping",
    "pipeline",
    "plan",
    "polygon",
    "poses",
    "radio",
    "radio_tuning",
    "registration",
    "report",
    "segment",
    "session",
    "sigma_points",
    "sim",
    "track",
    "uncertainty",
    "wafer_detect_options",
]

# Fleets and viewers (issue 41): batch/Ray processing, ROS 2 messages, Rerun recordings.
SUBMODULES += ("fleet", "ros2_messages", "viewer")
__all__ += ["fleet", "ros2_messages", "viewer"]


def __getattr__(name: str) -> Any:
    """Import a public submodule, or a name re-exported from one, on first access (PEP 562)."""
    if name in SUBMODULES:
        return importlib.import_module(f"autoteach.{name}")
    if name in _LAZY_NAMES:
        value = getattr(importlib.import_module(f"autoteach.{_LAZY_NAMES[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'autoteach' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(SUBMODULES) | set(_LAZY_NAMES))
