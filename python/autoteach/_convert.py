"""Conversion of user input to the float64 arrays and scalars the compiled module accepts.

Shared by every friendly wrapper: each rejects what is not real numbers with
:class:`~autoteach.errors.InvalidInputError` naming the argument. Shapes and finiteness of
arrays are checked by the compiled functions, which name the argument too.
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach.errors import InvalidInputError

F64Array = NDArray[np.float64]


def _real_array(value: Any, name: str, what: str, reject: tuple[type, ...], dtype_owner: str) -> np.ndarray:
    """``np.asarray(value)`` if it is not one of the ``reject`` types and holds integers or floats.

    Otherwise raises :class:`InvalidInputError` saying that ``name`` must be ``what``; the dtype
    message reads ``got {dtype_owner}dtype ...``.
    """
    if value is None:
        raise InvalidInputError(f"{name} must be {what}, got None")
    if isinstance(value, reject):
        raise InvalidInputError(f"{name} must be {what}, got {type(value).__name__} {_short(value)}")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as err:
        raise InvalidInputError(f"{name} must be {what}: {err}") from None
    if arr.dtype.kind not in "iuf":
        raise InvalidInputError(f"{name} must be {what}, got {dtype_owner}dtype {arr.dtype}{_first_non_real(arr)}")
    return arr


def _first_non_real(arr: np.ndarray) -> str:
    """For an object array, ``" (None at index (0,))"``: its first element that is not a real number."""
    if arr.dtype != object:
        return ""
    for idx, v in np.ndenumerate(arr):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            return f" ({type(v).__name__} {_short(v)} at index {idx})"
    return ""


def as_f64(value: ArrayLike, name: str) -> F64Array:
    """Convert ``value`` to a float64 array, rejecting anything that is not real numbers.

    Shapes and finiteness are checked by the compiled functions, which name the argument too.
    """
    arr = _real_array(value, name, "an array of real numbers", (str, bytes), "")
    return arr.astype(np.float64, copy=False)


def as_finite_f64(value: ArrayLike, name: str) -> F64Array:
    """:func:`as_f64`, refusing NaN and infinity too (for arrays checked in Python, not in Rust)."""
    arr = as_f64(value, name)
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name} must be finite, got {arr[~np.isfinite(arr)].ravel()[0]}")
    return arr


def as_float(value: Any, name: str) -> float:
    """Convert a real, finite scalar (Python or NumPy, or a 0-d array) to ``float``."""
    arr = _real_array(value, name, "a real number", (str, bytes, bool, np.bool_), f"{type(value).__name__} of ")
    if arr.shape != ():
        raise InvalidInputError(f"{name} must be a real number (a scalar), got an array of shape {arr.shape}")
    out = float(arr)
    if not math.isfinite(out):
        raise InvalidInputError(f"{name} must be finite, got {out}")
    return out


def as_int(value: Any, name: str, *, signed: bool = False) -> int:
    """Convert an integer (Python or NumPy, not bool) to ``int``; negative only if ``signed``.

    Counts, sizes, iteration limits and seeds are unsigned in the compiled module, which would
    raise a bare ``OverflowError`` for a negative value; this names the argument instead.
    """
    if isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{name} must be an integer, got {value!r}")
    try:
        out = operator.index(value)
    except TypeError:
        raise InvalidInputError(f"{name} must be an integer, got {type(value).__name__} {_short(value)}") from None
    if out < 0 and not signed:
        raise InvalidInputError(f"{name} must be a non-negative integer, got {_short(out)}")
    if not -(2**63) <= out < 2**64:
        raise InvalidInputError(f"{name} must fit in 64 bits, got {_short(out)}")
    return out


def _short(value: Any) -> str:
    """``repr(value)``, elided in the middle when longer than 40 characters (a 300-digit number)."""
    r = repr(value)
    return r if len(r) <= 40 else f"{r[:18]}...{r[-18:]} ({len(r)} characters)"
