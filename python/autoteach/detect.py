"""Ellipse fitting and linear assignment (seed 000_3b1454b2b2194811.txt ch. 3.2).

Friendly front of the compiled detection bindings in :mod:`autoteach._core`: inputs may be
lists, tuples or NumPy arrays of any real dtype.

- :func:`fit_ellipse` -- direct (Halir–Flusser form of Fitzgibbon's algebraic fit) or geometric
  (Levenberg–Marquardt on the orthogonal distances, accurate on partial arcs) ellipse fitting,
  with the mean residual in pixels and the 5×5 parameter covariance: the ``FitEllipse`` of the
  seed's arc-merging Algorithms 1–2.
- :func:`detect_wafers` -- wafer-rim detection in a grayscale image (ch. 3.2): sub-pixel Canny
  edges, arcs, the two-arc combination rule with Algorithms 1–2, upper/lower rim pairing.
- :func:`cpd_rigid`, :func:`cpd_affine`, :func:`cpd_nonrigid`, :func:`global_cpd` -- coherent point
  drift and global-CPD (ch. 3.4), from :mod:`autoteach.registration`.
- :func:`global_voting`, :func:`detect_polygon` -- global voting of rigid transforms (Algorithm 3)
  and chamber-opening polygon detection (ch. 3.3), from :mod:`autoteach.polygon`.
- :func:`linear_sum_assignment` -- drop-in for ``scipy.optimize.linear_sum_assignment``
  (Jonker–Volgenant shortest augmenting path), with ``inf`` marking forbidden pairs.
- :func:`assign_with_unassigned` -- assignment that may leave rows and columns unassigned at a
  price (the dummy arc ``v0`` of the seed's eq. (3.4); new or lost tracks).

Errors: bad input raises :class:`~autoteach.errors.InvalidInputError`; degenerate data
(collinear or coincident points, a hyperbola) raises
:class:`~autoteach.errors.DegenerateGeometryError`.

Example:
    >>> import numpy as np
    >>> from autoteach.detect import fit_ellipse
    >>> from autoteach.geometry import Ellipse
    >>> arc = Ellipse(320.0, 240.0, 300.0, 120.0, 0.4).sample(200, 0.3, 0.3 + np.radians(120))
    >>> fit = fit_ellipse(arc, method="geometric")
    >>> round(fit.ellipse.cx, 6), round(fit.ellipse.b, 6)
    (320.0, 120.0)

"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64
from autoteach.errors import InvalidInputError
from autoteach.geometry import Ellipse
from autoteach.polygon import detect_polygon, global_voting
from autoteach.registration import cpd_affine, cpd_nonrigid, cpd_rigid, global_cpd
from autoteach.wafer_detect_options import WaferDetectOptions

__all__ = [
    "EllipseFit",
    "WaferDetectOptions",
    "WaferEdge",
    "assign_with_unassigned",
    "cpd_affine",
    "cpd_nonrigid",
    "cpd_rigid",
    "detect_polygon",
    "detect_wafers",
    "fit_ellipse",
    "global_cpd",
    "global_voting",
    "linear_sum_assignment",
]

FitMethod = Literal["direct", "geometric"]


@dataclass(frozen=True, slots=True)
class EllipseFit:
    """The result of :func:`fit_ellipse` (the fields of ``autoteach_detect::ellipse::EllipseFit``).

    Attributes:
        ellipse: The fitted ellipse (``a ≥ b``, ``theta`` in ``(-π/2, π/2]``).
        residual_mean: Mean absolute orthogonal distance of the points to the ellipse (pixels): the
            arc-grouping cost ``r(i, j)`` of the seed's Algorithm 1.
        residual_rms: Root-mean-square orthogonal distance (pixels).
        covariance: Covariance of ``(cx, cy, a, b, theta)``, shape ``(5, 5)``:
            ``σ̂²·(JᵀJ)⁻¹`` with ``J`` the Jacobian of the orthogonal distances and
            ``σ̂² = SSR/(n − 5)``; ``None`` for exactly 5 points. For a near-circle whose
            orientation the data do not determine, ``var(theta) = π²/12`` (uniform) with zero
            correlation. For the direct fit it is evaluated at the direct ellipse (the
            covariance the geometric fit would have there).
        iterations: Levenberg–Marquardt iterations (0 for the direct fit).
        converged: Whether the iteration met its tolerance (always true for the direct fit).

    """

    ellipse: Ellipse
    residual_mean: float
    residual_rms: float
    covariance: NDArray[np.float64] | None
    iterations: int
    converged: bool


def fit_ellipse(points: ArrayLike, method: FitMethod = "geometric") -> EllipseFit:
    """Fit an ellipse to 2-D points.

    Args:
        points: Pixel coordinates, shape ``(N, 2)`` with ``N ≥ 5``.
        method: ``"direct"`` -- closed-form, ellipse-specific algebraic least squares
            (Fitzgibbon et al. 1999 in the numerically stable form of Halir & Flusser 1998);
            fast but biased toward small ellipses on partial arcs. ``"geometric"`` (default) --
            minimises the sum of squared orthogonal distances by Levenberg–Marquardt, started
            from the direct fit: the maximum-likelihood fit for Gaussian edge noise, accurate
            on arcs of 60–160°.

    Returns:
        The fit, see :class:`EllipseFit`.

    Raises:
        InvalidInputError: Wrong shape or dtype, NaN/inf, fewer than 5 points, unknown method.
        DegenerateGeometryError: Coincident or collinear points, fewer than 5 distinct points,
            points on a hyperbola or a line pair, or parameters the points do not determine.

    """
    if method not in ("direct", "geometric"):
        raise InvalidInputError(f"method must be 'direct' or 'geometric', got {method!r}")
    inner = _core.fit_ellipse(as_f64(points, "points"), method)
    return EllipseFit(
        ellipse=Ellipse._wrap(inner.ellipse),
        residual_mean=inner.residual_mean,
        residual_rms=inner.residual_rms,
        covariance=inner.covariance,
        iterations=inner.iterations,
        converged=inner.converged,
    )


def linear_sum_assignment(cost: ArrayLike, maximize: bool = False) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Solve the linear assignment problem, like ``scipy.optimize.linear_sum_assignment``.

    Jonker–Volgenant shortest augmenting path (Crouse 2016), O(n²m) for an ``n × m`` matrix,
    ``n ≤ m``; the Hungarian "BipartiteMatch" of the seed's Algorithms 1–2.

    Args:
        cost: Cost matrix, shape ``(rows, cols)`` (rectangular allowed). ``+inf`` (``-inf``
            when maximising) marks a forbidden pair.
        maximize: Maximise the total instead of minimising it.

    Returns:
        ``(row_ind, col_ind)``: the assigned pairs, sorted by row; ``cost[row_ind,
        col_ind].sum()`` is optimal. Unlike scipy, forbidden pairs that make a complete
        assignment impossible do not raise: the result is then the optimal assignment among
        those with the most allowed pairs, and rows/columns left over are absent.

    Raises:
        InvalidInputError: Not two-dimensional, NaN, ``-inf`` (``+inf`` when maximising), or
            costs whose sums overflow.

    """
    return _core.linear_sum_assignment(as_f64(cost, "cost"), bool(maximize))


def assign_with_unassigned(
    cost: ArrayLike, row_unassigned_cost: ArrayLike, col_unassigned_cost: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.intp], float]:
    """Minimum-cost assignment in which rows and columns may stay unassigned, at a price.

    Leaving row ``i`` unassigned costs ``row_unassigned_cost[i]``, column ``j``
    ``col_unassigned_cost[j]``; a pair is chosen only when it is cheaper than leaving both
    alone (the dummy arc ``v0`` of the seed's eq. (3.4)). Solved exactly as a square
    ``(rows + cols)`` assignment.

    Args:
        cost: Pair costs, shape ``(rows, cols)``; ``+inf`` forbids a pair.
        row_unassigned_cost: Shape ``(rows,)``; ``+inf`` means the row must be assigned.
        col_unassigned_cost: Shape ``(cols,)``; ``+inf`` means the column must be assigned.

    Returns:
        ``(row_ind, col_ind, total)``: assigned pairs sorted by row, and the total cost
        including the non-assignment costs.

    Raises:
        InvalidInputError: Wrong shapes, NaN or ``-inf``, or rows/columns that must be
            assigned but cannot be.

    """
    return _core.assign_with_unassigned(
        as_f64(cost, "cost"),
        as_f64(row_unassigned_cost, "row_unassigned_cost"),
        as_f64(col_unassigned_cost, "col_unassigned_cost"),
    )


@dataclass(frozen=True)
class WaferEdge:
    """One detected wafer rim (an elliptic edge segment), see :func:`detect_wafers`.

    Attributes:
        ellipse: The fitted ellipse (pixels).
        points: The supporting sub-pixel edge points, shape ``(N, 2)``, ``(u, v)``.
        residual: Mean orthogonal distance of the points to the ellipse (pixels).
        kind: ``"upper"`` or ``"lower"``: which surface's rim.
        wafer_id: Groups the two rims of one wafer in this image (0, 1, … topmost first).
        covariance: Covariance of ``(cx, cy, a, b, theta)``, shape ``(5, 5)``, or ``None``. It is
            the fit's statistical covariance (edge-point noise only); on the rendered benchmark
            the actual errors are larger, because the band model's small per-scene biases
            dominate: error / reported σ has a standard deviation of 3.2–4.4 for ``b`` and
            2.2–3.5 for ``a`` (``docs/changelog.md``, wafer-rim detection). Scale it before
            using it as a measurement covariance.

    """

    ellipse: Ellipse
    points: NDArray[np.float64]
    residual: float
    kind: Literal["upper", "lower"]
    wafer_id: int
    covariance: NDArray[np.float64] | None

    @classmethod
    def _from_core(cls, e: _core.WaferEdge) -> WaferEdge:
        """Wraps a compiled ``_core.WaferEdge`` (every wafer-rim detector returns these)."""
        return cls(
            ellipse=Ellipse._wrap(e.ellipse),
            points=e.points,
            residual=e.residual,
            kind=e.kind,
            wafer_id=e.wafer_id,
            covariance=e.covariance,
        )


def detect_wafers(image: ArrayLike, options: WaferDetectOptions | None = None, **overrides: Any) -> list[WaferEdge]:
    """Detect the elliptic rims of wafers in a grayscale image (seed 000_3b1454b2b2194811.txt ch. 3.2).

    Sub-pixel Canny edges are linked into arcs, split at corners, inflections and quadrant
    changes, screened (short, straight, too curved), combined in pairs by the two-arc rule and
    Algorithm 1 (bipartite matching per connected component), merged by Algorithm 2, validated,
    labelled upper/lower by the side of the bright wafer edge face, cleaned of faint reflections
    and paired into wafers. Runs without the GIL.

    Args:
        image: ``(height, width)`` grayscale, dtype uint8 (0–255), float32 or float64 (0–1).
        options: the detector's options (default :class:`~autoteach.wafer_detect_options.WaferDetectOptions`,
            whose attributes document each one).
        **overrides: options that replace those of ``options`` by name, e.g. ``canny_low=8.0``.

    Returns:
        The rims, grouped by ``wafer_id`` (upper before lower); empty if none is found.

    Raises:
        InvalidInputError: Not 2-D, empty, unsupported dtype, NaN/inf pixels, bad parameters.

    """
    if image is None:
        raise InvalidInputError("image must be a 2-D (height, width) grayscale array, got None")
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise InvalidInputError(f"image must be 2-D (height, width) grayscale, got shape {arr.shape}")
    if arr.size == 0:
        raise InvalidInputError(f"image must not be empty, got shape {arr.shape}")
    if arr.dtype not in (np.uint8, np.float32, np.float64):
        raise InvalidInputError(f"image must have dtype uint8, float32 or float64, got {arr.dtype}")
    opts = options or WaferDetectOptions()
    if overrides:
        opts = opts.replace(**overrides)
    edges = _core.wafer_detect(np.ascontiguousarray(arr), **opts.core_kwargs())
    return [WaferEdge._from_core(e) for e in edges]


# --- general ellipse detection (issue 42) ---
from autoteach.ellipse_detection import (  # noqa: E402
    EllipseDetection,
    EllipseDetectOptions,
    WaferGeometry,
    detect_ellipses,
    detect_wafer_rims,
)

__all__ += ["EllipseDetectOptions", "EllipseDetection", "WaferGeometry", "detect_ellipses", "detect_wafer_rims"]

# --- ellipse fits of many arcs in one call (issue 36) ---
from autoteach.ellipse_batch import EllipseFits, fit_ellipses  # noqa: E402

__all__ += ["EllipseFits", "fit_ellipses"]
