"""autoteach: robust perception and self-calibration for camera-carrying robots.

Submodules:

- :mod:`autoteach.geometry` -- rigid transforms, the wafer-handling robot, camera models, conics.
- :mod:`autoteach.sim` -- the simulated wafer-handling robot and carrier (sessions with ground truth).
- :mod:`autoteach.io` -- MCAP session logs (write and read).
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

__all__ = [
    "AutoteachError",
    "ConvergenceError",
    "DegenerateGeometryError",
    "InternalError",
    "InvalidInputError",
    "LogReadError",
    "UnreachablePoseError",
    "__version__",
]
