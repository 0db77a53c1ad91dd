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
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64
from autoteach.errors import InvalidInputError
from autoteach.geometry import Ellipse
from autoteach.polygon import detect_polygon, global_voting
from autoteach.registration import cpd_affine, cpd_nonrigid, cpd_rigid, global_cpd

__all__ = [
    "EllipseFit",
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


def detect_wafers(
    image: ArrayLike,
    *,
    canny_low: float = 6.0,
    canny_high: float = 15.0,
    blur_sigma: float = 0.0,
    min_arc_points: int = 16,
    residual_threshold: float = 0.25,
    max_gap: float = 60.0,
    up: tuple[float, float] = (0.0, -1.0),
    max_rim_offset: float = 10.0,
    max_rim_axis_difference: float = 0.10,
    min_contrast_ratio: float = 0.45,
    semi_major_range: tuple[float, float] | None = None,
    semi_minor_range: tuple[float, float] | None = None,
    min_coverage: float = 0.08,
    min_rim_separation: float = 0.5,
    max_arc_deviation: float = 0.6,
    max_arc_residual_ratio: float = 1.5,
    max_unpaired_residual: float = 0.15,
    band_refinement: bool = True,
    share_rim_shape: bool = True,
    share_rim_centre: bool = True,
    joint_band_fit: bool = True,
    inflection_sigmas: float = 0.0,
    join_border_cut_arcs: bool = True,
    thickness_ratio: float | None = None,
    focal_length: float | None = None,
    restart_turn_at_cuts: bool = True,
    max_relative_sigma_b: float = 0.005,
    max_centre_sigma: float = 1.0,
    keep_flat_run_pieces: bool = True,
    border_pairs_take_arcs: bool = True,
    reflection_inside_rim: bool = True,
    seek_missing_partner: bool = True,
    thin_band_fit: bool = True,
    front_band_fit: bool = True,
    principal_point: tuple[float, float] | None = None,
    edge_profile: Literal["optical", "pixel"] = "optical",
    level_band_search: bool = True,
) -> list[WaferEdge]:
    """Detect the elliptic rims of wafers in a grayscale image (seed 000_3b1454b2b2194811.txt ch. 3.2).

    Sub-pixel Canny edges are linked into arcs, split at corners, inflections and quadrant
    changes, screened (short, straight, too curved), combined in pairs by the two-arc rule and
    Algorithm 1 (bipartite matching per connected component), merged by Algorithm 2, validated,
    labelled upper/lower by the side of the bright wafer edge face, cleaned of faint reflections
    and paired into wafers. Runs without the GIL.

    Args:
        image: ``(height, width)`` grayscale, dtype uint8 (0–255), float32 or float64 (0–1).
        canny_low: Hysteresis low threshold (grey levels per pixel on the 0–255 scale).
        canny_high: Hysteresis high threshold.
        blur_sigma: Optional Gaussian pre-blur (pixels); 0 for none.
        min_arc_points: Fewest edge points of an arc.
        residual_threshold: Largest mean orthogonal residual (pixels) of a combination.
        max_gap: Largest gap (pixels) between combined arcs.
        up: Image direction of the wafer normal (upper surface side); ``(0, -1)`` for an upright
            camera.
        max_rim_offset: Largest centre distance (pixels) of the two rims of one wafer.
        max_rim_axis_difference: Largest relative semi-axis difference of the two rims.
        min_contrast_ratio: Rims with less than this fraction of the contrast of the strongest
            rim of similar size are rejected as reflections (0 disables).
        semi_major_range: Optional prior ``(low, high)`` on the semi-major axis (pixels).
        semi_minor_range: Optional prior ``(low, high)`` on the semi-minor axis (pixels).
        min_coverage: Smallest fraction of its ellipse's perimeter a segment's arcs must cover
            (rims whose fit the points leave undetermined are rejected by the two σ tests).
        min_rim_separation: Points of the far lower rim closer to the upper rim than this
            fraction of the widest rim distance are dropped before its refit (0 disables).
        max_arc_deviation: An arc whose median distance (pixels) to its segment's ellipse
            exceeds this is dropped and the rest refitted (0 disables).
        max_arc_residual_ratio: Leave-one-out check of segments of three or more arcs: factor by
            which an arc may raise the mean residual (0 disables).
        max_unpaired_residual: A rim without a partner rim is kept only under this mean
            residual (pixels); ``math.inf`` disables.
        band_refinement: Re-locate rim points with the two-edge band model of the rim profile.
        share_rim_shape: Refit the less covered rim of a pair with its partner's semi-major
            axis and orientation.
        share_rim_centre: With ``share_rim_shape``, also hold its centre on the partner's line
            along ``up``.
        joint_band_fit: Refit the less covered rim with the joint band model of both rims.
        inflection_sigmas: When above 0, a cut at a turn-sign change moves to the previous
            polygon vertex if the points between already bend its way by more than this many
            standard errors of the chain's edge noise (0: cut at the sign change).
        join_border_cut_arcs: Join two arcs left over by the assembly into one rim when the
            part of their ellipse between them lies outside the image (a rim whose front arc runs
            out of the image top; farther apart than ``max_gap``).
        thickness_ratio: Wafer thickness / wafer radius (a standard 300 mm wafer: 0.775 / 150);
            with ``focal_length``, a prior on the offset between the images of a wafer's two
            rims, ``thickness_ratio · a · sqrt(1 + (a / focal_length)²)`` along ``up`` (4 %
            standard deviation), pins the joint fit of the far lower rim of a wafer seen from
            above. Give both or neither; a wrong thickness is worse than none.
        focal_length: Camera focal length (pixels) for the rim offset prior.
        restart_turn_at_cuts: A cut vertex (corner, inflection, quadrant change) starts a new
            piece whose first turn is not compared with the cut's own turn for an inflection,
            so the side after a foreign contour's junction at a rim's tip is kept (thin rims
            running into slot-tooth edges). On by default (with ``max_relative_sigma_b``, which
            rejects the recovered thin rims whose minor axis the fit leaves uncertain).
        max_relative_sigma_b: A rim is reported only when the standard deviation of its
            minor axis (from the fit's covariance) is at most this fraction of ``b``: thin rims
            seen along the front arc only, whose ``a``, ``b`` and centre trade off, and
            clutter. ``math.inf`` disables.
        max_centre_sigma: A rim whose centre standard deviation ``sqrt(var(cx) + var(cy))``
            (from its fit's covariance) is over this (pixels) is rejected: its points do not
            determine an ellipse (a short or nearly straight arc); ``math.inf`` disables.
        keep_flat_run_pieces: A chain piece that would be dropped as straight is kept when a
            quadrant-change cut alone joins it to a neighbouring arc of the same convex run and
            it bends the run's way significantly (3 standard errors of the chain's edge
            noise): the flat half of a flat rim's front arc between its lowest point and a
            foreign contour's junction.
        border_pairs_take_arcs: With ``join_border_cut_arcs``, a pair of arcs cut by the image
            border may take an arc of one of the assembly's two-arc segments when it fits
            better (lower mean residual) than that segment, which is then dissolved.
        reflection_inside_rim: A dim rim counts as a reflection (``min_contrast_ratio``) only
            when it lies inside the brighter rim on whose face it would be mirrored; ``False``
            compares it with every brighter rim of about its size.
        seek_missing_partner: The missing rim of a wafer of which only one rim was found is
            sought as the far edge of the side band along the found rim's front arc (per-profile
            band fits place a first guess, the joint band model of both rims fits it); it is
            reported when the fit stays within 2 px and 5 % of the guess and its measured far
            edges fit it, and passes the covariance screens like every rim.
        thin_band_fit: With the rim offset prior (``thickness_ratio``, ``focal_length``), the
            two rims of a thin wafer (``b`` under 9 px, 10 px seen from above; major axis near horizontal, ``up`` near
            ``(0, -1)``) are refitted together by one intensity fit of the image columns across
            the face's silhouette and the side band (four grey levels per column, one blur, the
            lower rim the exact image of the upper rim's circle moved by the thickness); an
            accepted fit (residual at the image's noise level) replaces the pair's edge-point
            fits. No effect without the prior.
        front_band_fit: With the rim offset prior, the two rims of a wider level wafer (``b`` from
            10 px seen from above, 9 px from below) are refitted together by one intensity fit of the image
            columns across the side band (three grey levels per column, clipped samples
            censored, one blur, the rims tied by the prior); an accepted fit replaces the pair's
            edge-point fits. No effect without the prior.
        principal_point: Camera principal point ``(cx, cy)`` (pixels) for the rim offset prior;
            ``None``: the image centre ``((width - 1) / 2, (height - 1) / 2)``. With it, the
            column fits (``thin_band_fit``, ``front_band_fit``) tie the lower rim to the upper
            one exactly: the upper rim's ellipse gives the circle's pose (radius 1) under the
            pinhole camera, and the lower rim is its image moved by ``thickness_ratio`` against
            the normal. Only with ``thickness_ratio`` and ``focal_length``.
        edge_profile: How the image forms an edge's profile, for the column fits:
            ``"optical"`` (a camera: the optics blur before the pixels integrate, a Gaussian
            profile ``Φ((y − E)/σ)`` whatever the edge's sub-pixel position) or ``"pixel"`` (the
            pixels integrate first and a Gaussian sampled on the pixel grid blurs the image after,
            as the simulator's renderer does: the profile ``Σₖ wₖ·clamp(y − E − k + ½, 0, 1)`` is
            piecewise linear in the edge's position, and a Gaussian profile fitted to it is off by
            up to ≈ 0.05 px by the edge's sub-pixel phase). σ is fitted either way.
        level_band_search: With the rim offset prior and ``thin_band_fit``, also finds the wafers
            seen almost edge-on (``b`` of 1–4 px), whose nearly straight rims no edge-point fit
            finds: long bright bars across the image, whose ends (the rims' tips, located to a
            tenth of a pixel) fix the centre column and ``a``, and whose sag seeds the thin column
            fit, which measures ``b`` and the rows (the tips' columns screened for clutter in runs
            of neighbouring columns). No effect without the prior.

    Returns:
        The rims, grouped by ``wafer_id`` (upper before lower); empty if none is found.

    Raises:
        InvalidInputError: Not 2-D, empty, unsupported dtype, NaN/inf pixels, bad parameters.

    """
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise InvalidInputError(f"image must be 2-D (height, width) grayscale, got shape {arr.shape}")
    if arr.size == 0:
        raise InvalidInputError(f"image is empty, shape {arr.shape}")
    if arr.dtype not in (np.uint8, np.float32, np.float64):
        raise InvalidInputError(f"image must have dtype uint8, float32 or float64, got {arr.dtype}")
    edges = _core.wafer_detect(
        np.ascontiguousarray(arr),
        canny_low=float(canny_low),
        canny_high=float(canny_high),
        blur_sigma=float(blur_sigma),
        min_arc_points=int(min_arc_points),
        residual_threshold=float(residual_threshold),
        max_gap=float(max_gap),
        up=(float(up[0]), float(up[1])),
        max_rim_offset=float(max_rim_offset),
        max_rim_axis_difference=float(max_rim_axis_difference),
        min_contrast_ratio=float(min_contrast_ratio),
        semi_major_range=None if semi_major_range is None else tuple(map(float, semi_major_range)),
        semi_minor_range=None if semi_minor_range is None else tuple(map(float, semi_minor_range)),
        min_coverage=float(min_coverage),
        min_rim_separation=float(min_rim_separation),
        max_arc_deviation=float(max_arc_deviation),
        max_arc_residual_ratio=float(max_arc_residual_ratio),
        max_unpaired_residual=float(max_unpaired_residual),
        band_refinement=bool(band_refinement),
        share_rim_shape=bool(share_rim_shape),
        share_rim_centre=bool(share_rim_centre),
        joint_band_fit=bool(joint_band_fit),
        inflection_sigmas=float(inflection_sigmas),
        join_border_cut_arcs=bool(join_border_cut_arcs),
        thickness_ratio=None if thickness_ratio is None else float(thickness_ratio),
        focal_length=None if focal_length is None else float(focal_length),
        restart_turn_at_cuts=bool(restart_turn_at_cuts),
        max_relative_sigma_b=float(max_relative_sigma_b),
        max_centre_sigma=float(max_centre_sigma),
        keep_flat_run_pieces=bool(keep_flat_run_pieces),
        border_pairs_take_arcs=bool(border_pairs_take_arcs),
        reflection_inside_rim=bool(reflection_inside_rim),
        seek_missing_partner=bool(seek_missing_partner),
        thin_band_fit=bool(thin_band_fit),
        front_band_fit=bool(front_band_fit),
        principal_point=None if principal_point is None else (float(principal_point[0]), float(principal_point[1])),
        edge_profile=str(edge_profile),
        level_band_search=bool(level_band_search),
    )
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
