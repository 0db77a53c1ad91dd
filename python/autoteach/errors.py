"""The exception hierarchy of autoteach.

Every error autoteach raises derives from :class:`AutoteachError`, and also from the built-in
exception a caller would naturally catch (``ValueError`` for bad input, ``RuntimeError`` for a
computation that failed, ``MemoryError`` for an input that asks for more memory than exists,
``OSError`` for a log that cannot be read).
"""

from __future__ import annotations

from autoteach._core import (
    AllocationError,
    AutoteachError,
    ConvergenceError,
    DegenerateGeometryError,
    InternalError,
    InvalidInputError,
    UnreachablePoseError,
)


class LogReadError(AutoteachError, OSError):
    """An MCAP log cannot be read (fully): the message says which file and where reading stopped."""


class LogSalvageWarning(UserWarning):
    """A damaged log was read with ``allow_truncated=True``: the message says which bytes and frames were lost."""


class MissingExtraError(AutoteachError, ImportError):
    """An optional feature needs a package that is not installed: the message names the extra to install."""


__all__ = [
    "AllocationError",
    "AutoteachError",
    "ConvergenceError",
    "DegenerateGeometryError",
    "InternalError",
    "InvalidInputError",
    "LogReadError",
    "LogSalvageWarning",
    "MissingExtraError",
    "UnreachablePoseError",
]
