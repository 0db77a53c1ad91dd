"""Ellipse fits of many arcs in one call (issue 36).

:func:`fit_ellipses` fits every arc of a point array delimited by offsets with the fit of
:func:`autoteach.detect.fit_ellipse` (seed 000_3b1454b2b2194811.txt §3.2, ``FitEllipse``): the
same estimate bit for bit, with one Python→Rust crossing for all arcs, the GIL released and the
arcs shared among rayon's threads (``RAYON_NUM_THREADS``). Results come back as arrays.

Example:
    >>> import numpy as np
    >>> from autoteach.detect import fit_ellipses
    >>> from autoteach.geometry import Ellipse
    >>> arcs = [Ellipse(320.0, 240.0, 300.0 - 50 * k, 120.0, 0.4).sample(200, k, k + 2.0) for k in range(3)]
    >>> fits = fit_ellipses(np.concatenate(arcs), np.cumsum([0] + [len(a) for a in arcs]))
    >>> np.round(fits.params[:, 3], 6).tolist()
    [120.0, 120.0, 120.0]

"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64
from autoteach.errors import InvalidInputError

__all__ = ["EllipseFits", "fit_ellipses"]


@dataclass(frozen=True, slots=True)
class EllipseFits:
    """The results of :func:`fit_ellipses`, one row per arc (see :class:`autoteach.detect.EllipseFit`).

    A failed arc (fewer than 5 points, NaN, degenerate points) has NaN parameters, residuals and
    covariance, 0 iterations, ``converged`` false, and its error message in ``errors``.

    Attributes:
        params: ``(cx, cy, a, b, theta)`` per arc, shape ``(K, 5)`` (``a ≥ b``, ``theta`` in
            ``(-π/2, π/2]``).
        residual_mean: Mean absolute orthogonal distance per arc (pixels), shape ``(K,)``.
        residual_rms: RMS orthogonal distance per arc (pixels), shape ``(K,)``.
        covariance: Covariance of ``(cx, cy, a, b, theta)`` per arc, shape ``(K, 5, 5)``; NaN
            where :attr:`autoteach.detect.EllipseFit.covariance` is ``None`` (exactly 5 points).
        iterations: Levenberg–Marquardt iterations per arc, shape ``(K,)``.
        converged: Whether each iteration met its tolerance, shape ``(K,)``.
        errors: ``None`` for a fitted arc, else the message of the error
            :func:`autoteach.detect.fit_ellipse` would have raised on it.

    """

    params: NDArray[np.float64]
    residual_mean: NDArray[np.float64]
    residual_rms: NDArray[np.float64]
    covariance: NDArray[np.float64]
    iterations: NDArray[np.int64]
    converged: NDArray[np.bool_]
    errors: list[str | None]

    @property
    def ok(self) -> NDArray[np.bool_]:
        """Which arcs were fitted (``errors[i] is None``)."""
        return np.array([e is None for e in self.errors], dtype=bool)

    def __len__(self) -> int:
        """Number of arcs."""
        return len(self.errors)


def fit_ellipses(
    points: ArrayLike, offsets: ArrayLike, method: Literal["direct", "geometric"] = "geometric"
) -> EllipseFits:
    """Fit one ellipse per arc ``points[offsets[i]:offsets[i + 1]]`` in one call.

    Args:
        points: Pixel coordinates of every arc, concatenated, shape ``(N, 2)``.
        offsets: Arc boundaries, 1-D integers: ``offsets[0] = 0``, non-decreasing,
            ``offsets[-1] = N``; ``K = len(offsets) - 1`` arcs.
        method: ``"direct"`` or ``"geometric"`` (default), as in :func:`autoteach.detect.fit_ellipse`.

    Returns:
        The fits as arrays, see :class:`EllipseFits`.

    Raises:
        InvalidInputError: Wrong shape or dtype of ``points`` or ``offsets``, bad offsets, unknown
            method. Errors of single arcs are reported in :attr:`EllipseFits.errors` instead.

    """
    if method not in ("direct", "geometric"):
        raise InvalidInputError(f"method must be 'direct' or 'geometric', got {method!r}")
    off = np.asarray(offsets)
    if off.ndim != 1 or (off.size and not np.issubdtype(off.dtype, np.integer)):
        raise InvalidInputError(f"offsets must be a 1-D array of integers, got dtype {off.dtype}, shape {off.shape}")
    if off.size and off.dtype.kind == "u" and off.max() > np.iinfo(np.int64).max:
        raise InvalidInputError(f"offsets[{int(np.argmax(off))}] = {off.max()} is out of range")
    params, mean, rms, cov, iterations, converged, errors = _core.fit_ellipses(
        as_f64(points, "points"), np.ascontiguousarray(off, dtype=np.int64), method
    )
    return EllipseFits(params, mean, rms, cov, iterations, converged, list(errors))
