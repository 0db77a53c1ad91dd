"""Probabilistic bounding boxes: label uncertainty, spatial distributions and Jaccard IoU.

000_3b1454b2b2194811.txt ch. 8 and Appendix A. A BEV box is ``[cx, cy, l, w, r]`` (centre, full
length along the heading, full width, heading in radians); a probabilistic box is a Gaussian
``N(box, cov)`` with a 5x5 covariance over those parameters (all zeros: deterministic).

- :func:`label_uncertainty`: the variational-Bayes label posterior of eq. 8.6-8.11 (GMM of
  boundary points, responsibilities by the CPD E-step, the prior of Sec. 8.5);
  :func:`posterior_with_correspondences` for known correspondences (Fig. 8.6);
  :func:`estimate_noise` the EM noise estimate of eq. 8.12.
- :func:`spatial_distribution`: ``p_G(u)`` (eq. 8.3; Appendix A moments or Monte Carlo) and
  ``P_PDQ(u)`` (eq. 8.2), at points or on a :class:`Grid`.
- :func:`jiou` (eq. 8.4, exact IoU for deterministic pairs), :func:`jiou_grid` (the
  ``O(N log N)`` probabilistic Jaccard index on samples), :func:`iou`.
- :func:`simulate_cars`: BEV LiDAR scans of cars (L-shaped hits, noise, occlusion).
- :func:`read_gaussian_boxes` and :func:`read_corner_boxes`: the two published prediction
  formats (diagonal-Gaussian boxes as ProbPIXOR, corner-uncertainty boxes).
- :func:`fig_8_6` and :func:`fig_8_5`: the seed's worked examples, with its slips named.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError

F64Array = NDArray[np.float64]

SEED_PRIOR_STD = (0.44, 0.11, 0.25, 0.25, 0.17)
"""Standard deviations of the Sec. 8.5 prior over ``[cx, cy, l, w, r]`` at weight 1."""

Kind = Literal["pg", "pdq"]


def _boxes(value: ArrayLike, name: str) -> tuple[F64Array, bool]:
    arr = as_f64(value, name)
    if arr.ndim == 1 and arr.shape == (5,):
        return arr.reshape(1, -1), True
    if arr.ndim != 2 or arr.shape[1] != 5:
        raise InvalidInputError(f"{name} must be one box (5,) or boxes (n, 5), got shape {arr.shape}")
    return arr, False


def _covs(value: ArrayLike | None, n: int, name: str) -> F64Array:
    if value is None:
        return np.zeros((n, 5, 5))
    arr = as_f64(value, name)
    if arr.shape == (5, 5):
        arr = np.broadcast_to(arr, (n, 5, 5))
    return np.ascontiguousarray(arr)


def _kind(kind: str) -> bool:
    if kind not in ("pg", "pdq"):
        raise InvalidInputError(f'kind must be "pg" (eq. 8.3) or "pdq" (eq. 8.2), got {kind!r}')
    return kind == "pdq"


def seed_prior(weight: float = 1.0) -> F64Array:
    """The Sec. 8.5 prior covariance ``1/w * diag(0.44^2, 0.11^2, 0.25^2, 0.25^2, 0.17^2)``."""
    w = as_float(weight, "weight")
    if w <= 0:
        raise InvalidInputError(f"weight must be positive, got {w}")
    return np.diag(np.square(SEED_PRIOR_STD)) / w


@dataclass(frozen=True, slots=True)
class Grid:
    """A regular BEV grid: cell ``(iy, ix)`` has centre ``(x0 + (ix+.5) dx, y0 + (iy+.5) dy)``."""

    x0: float
    y0: float
    dx: float
    dy: float
    nx: int
    ny: int

    def as_tuple(self) -> tuple[float, float, float, float, int, int]:
        """The tuple the compiled functions take."""
        return (
            as_float(self.x0, "x0"),
            as_float(self.y0, "y0"),
            as_float(self.dx, "dx"),
            as_float(self.dy, "dy"),
            as_int(self.nx, "nx"),
            as_int(self.ny, "ny"),
        )

    def centres(self) -> F64Array:
        """Cell centres, shape ``(ny, nx, 2)``."""
        xs = self.x0 + (np.arange(self.nx) + 0.5) * self.dx
        ys = self.y0 + (np.arange(self.ny) + 0.5) * self.dy
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx, gy], axis=-1)

    @classmethod
    def around(cls, boxes: ArrayLike, n: int = 100, margin: float = 1.0) -> Grid:
        """An ``n x n`` grid over the corners of ``boxes`` plus ``margin`` metres."""
        b, _ = _boxes(boxes, "boxes")
        c = corners(b).reshape(-1, 2)
        lo, hi = c.min(axis=0) - margin, c.max(axis=0) + margin
        return cls(float(lo[0]), float(lo[1]), float(hi[0] - lo[0]) / n, float(hi[1] - lo[1]) / n, n, n)


def corners(boxes: ArrayLike) -> F64Array:
    """Corners ``(n, 4, 2)`` (or ``(4, 2)``) of boxes, counter-clockwise from ``v0 = (1/2, 1/2)`` (eq. 8.1)."""
    b, single = _boxes(boxes, "boxes")
    v0 = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    c, s = np.cos(b[:, 4]), np.sin(b[:, 4])
    a = v0[None, :, 0] * b[:, 2:3]
    d = v0[None, :, 1] * b[:, 3:4]
    out = np.stack([b[:, 0:1] + c[:, None] * a - s[:, None] * d, b[:, 1:2] + s[:, None] * a + c[:, None] * d], axis=-1)
    return out[0] if single else out


def iou(box_a: ArrayLike, box_b: ArrayLike) -> float | F64Array:
    """Exact IoU of rotated boxes (rows ``[cx, cy, l, w, r]``; one box or ``(n, 5)`` each)."""
    a, single = _boxes(box_a, "box_a")
    b, _ = _boxes(box_b, "box_b")
    out = _core.uncertainty_iou(a, b)
    return float(out[0]) if single else out


def jiou(
    box_a: ArrayLike,
    cov_a: ArrayLike | None,
    box_b: ArrayLike,
    cov_b: ArrayLike | None,
    *,
    grid: int = 30,
    samples: int = 64,
    seed: int = 0,
    kind: Kind = "pg",
) -> float | F64Array:
    """Jaccard IoU (eq. 8.4) of Gaussian boxes ``N(box_a, cov_a)`` and ``N(box_b, cov_b)``.

    ``cov=None`` means deterministic; two deterministic boxes give the exact IoU. Otherwise the
    spatial distributions (``kind="pg"``: eq. 8.3; ``"pdq"``: eq. 8.2) are evaluated on a
    ``grid x grid`` grid spanning ``samples`` Monte Carlo boxes of each, and compared by the
    probabilistic Jaccard index. Pass ``(n, 5)`` boxes and ``(n, 5, 5)`` covariances for a batch.
    """
    a, single = _boxes(box_a, "box_a")
    b, _ = _boxes(box_b, "box_b")
    ca = _covs(cov_a, a.shape[0], "cov_a")
    cb = _covs(cov_b, b.shape[0], "cov_b")
    out = _core.uncertainty_jiou(
        a, ca, b, cb, as_int(grid, "grid"), as_int(samples, "samples"), as_int(seed, "seed"), _kind(kind)
    )
    return float(out[0]) if single else out


def jiou_grid(p1: ArrayLike, p2: ArrayLike) -> float:
    """Probabilistic Jaccard index (eq. 8.4 on samples) of two distributions on the same grid."""
    return _core.uncertainty_jiou_grid(as_f64(p1, "p1"), as_f64(p2, "p2"))


def rasterize(boxes: ArrayLike, weights: ArrayLike, grid: Grid, kind: Kind = "pg") -> F64Array:
    """Spatial distribution of a discrete mixture of boxes on ``grid`` (shape ``(ny, nx)``).

    ``kind="pg"`` spreads each box's weight uniformly over the cells whose centres it covers
    (eq. 8.3 on the grid's counting measure); ``"pdq"`` adds the weight to each covered cell
    (eq. 8.2).
    """
    b, _ = _boxes(boxes, "boxes")
    out, _skipped = _core.uncertainty_rasterize(b, as_f64(weights, "weights"), grid.as_tuple(), _kind(kind))
    return out


def spatial_distribution(
    box: ArrayLike,
    cov: ArrayLike | None,
    *,
    grid: Grid | None = None,
    points: ArrayLike | None = None,
    method: Literal["moments", "sampled"] = "moments",
    kind: Kind = "pg",
    lattice: int = 20,
    samples: int = 256,
    seed: int = 0,
) -> F64Array:
    """``p_G(u)`` (eq. 8.3) or ``P_PDQ(u)`` (eq. 8.2) of ``N(box, cov)`` on a grid or at points.

    ``method="moments"`` (``p_G`` only) uses the Gaussian moment approximation of Appendix A on an
    ``lattice x lattice`` midpoint lattice of the unit box (a smooth density); ``"sampled"``
    rasterises ``samples`` Monte Carlo boxes (``p_G`` normalised on the grid). At points,
    ``P_PDQ`` is the Monte Carlo fraction of boxes containing each point.
    """
    m = as_f64(box, "box")
    c = np.zeros((5, 5)) if cov is None else as_f64(cov, "cov")
    pdq = _kind(kind)
    if (grid is None) == (points is None):
        raise InvalidInputError(
            f"exactly one of grid and points must be given, got {'neither' if grid is None else 'both'}"
        )
    if method not in ("moments", "sampled"):
        raise InvalidInputError(f'method must be "moments" or "sampled", got {method!r}')
    if grid is not None and method == "sampled":
        return _core.uncertainty_spatial_sampled(
            m, c, grid.as_tuple(), as_int(samples, "samples"), as_int(seed, "seed"), pdq
        )
    pts = grid.centres().reshape(-1, 2) if grid is not None else as_f64(points, "points")
    if pdq:
        out = _core.uncertainty_pdq_at(m, c, pts, as_int(samples, "samples"), as_int(seed, "seed"))
    elif method == "moments":
        out = _core.uncertainty_pg_moments(m, c, pts, as_int(lattice, "lattice"))
    else:
        raise InvalidInputError('method="sampled" needs a grid for p_G (its normaliser is the grid cell count)')
    return out.reshape(grid.ny, grid.nx) if grid is not None else out


def point_moments(box: ArrayLike, cov: ArrayLike, v0: ArrayLike) -> tuple[F64Array, F64Array]:
    """Mean ``(n, 2)`` and covariance ``(n, 2, 2)`` of the box point ``V(v0, Y)`` (eq. A.6)."""
    return _core.uncertainty_point_moments(as_f64(box, "box"), as_f64(cov, "cov"), np.atleast_2d(as_f64(v0, "v0")))


def total_variance(box: ArrayLike, cov: ArrayLike, v0: ArrayLike) -> F64Array:
    """Total variance ``tr Cov[V(v0, Y)]`` at unit-box points ``v0`` (Fig. 8.9)."""
    _, c = point_moments(box, cov, v0)
    return np.trace(c, axis1=1, axis2=2)


@dataclass(frozen=True, slots=True)
class LabelPosterior:
    """A Gaussian label posterior ``N(mean, cov)`` over ``[cx, cy, l, w, r]`` (``detect::uncertainty::LabelPosterior``).

    Attributes:
        mean: Posterior mean ``(5,)``: the label itself (Sec. 8.1 only needs the spread).
        cov: Posterior covariance ``(5, 5)`` (eq. 8.10).
        precision: Its inverse ``(5, 5)``, prior plus data information.
        sigma: The LiDAR noise standard deviation used, in metres.
        points: Number of points that observed the box.
    """

    mean: F64Array
    cov: F64Array
    precision: F64Array
    sigma: float
    points: int


@dataclass(frozen=True, slots=True)
class NoiseEstimate:
    """The EM noise estimate of eq. 8.12 (``detect::uncertainty::noise::NoiseEstimate``).

    Attributes:
        sigma: Estimated noise standard deviation, in metres.
        iterations: EM iterations run.
        history: ``sigma`` after each iteration.
    """

    sigma: float
    iterations: int
    history: F64Array


def _prior(prior: float | ArrayLike | str | None) -> F64Array | None:
    if prior is None or (isinstance(prior, str) and prior == "flat"):
        return None
    if isinstance(prior, str):
        raise InvalidInputError(f'prior must be a weight, a (5, 5) covariance, "flat" or None, got {prior!r}')
    arr = np.asarray(prior)
    if arr.ndim == 0:
        return seed_prior(float(arr))
    return as_f64(prior, "prior")


def label_uncertainty(
    box: ArrayLike,
    points: ArrayLike,
    *,
    sigma: float = 0.2,
    prior: float | ArrayLike | str | None = 1.0,
    spacing: float = 0.5,
    estimate_heading: bool = True,
) -> LabelPosterior:
    """Variational-Bayes label posterior (eq. 8.10-8.11) of ``box`` given its LiDAR ``points (k, 2)``.

    ``prior`` is the weight ``w`` of the Sec. 8.5 prior (a number), a 5x5 covariance, or
    ``"flat"``/``None``. ``spacing`` is the distance between rendered boundary points in units
    of ``sigma``. With ``estimate_heading=False`` the heading is fixed (zero row and column).
    """
    out = _core.uncertainty_label(
        as_f64(box, "box"),
        as_f64(points, "points"),
        as_float(sigma, "sigma"),
        _prior(prior),
        as_float(spacing, "spacing"),
        bool(estimate_heading),
    )
    return LabelPosterior(*out)


def posterior_with_correspondences(
    box: ArrayLike,
    points: ArrayLike,
    v0: ArrayLike,
    *,
    sigma: float = 0.2,
    prior: float | ArrayLike | str | None = None,
    estimate_heading: bool = True,
) -> LabelPosterior:
    """Label posterior when point ``k`` is known to come from unit-box point ``v0[k]`` (Fig. 8.6)."""
    out = _core.uncertainty_label_correspondences(
        as_f64(box, "box"),
        as_f64(points, "points"),
        as_f64(v0, "v0"),
        as_float(sigma, "sigma"),
        _prior(prior),
        bool(estimate_heading),
    )
    return LabelPosterior(*out)


def estimate_noise(
    labels: ArrayLike,
    scans: list[ArrayLike],
    *,
    sigma0: float = 0.5,
    tolerance: float = 1e-8,
    max_iterations: int = 200,
) -> NoiseEstimate:
    """EM estimate of the LiDAR noise (eq. 8.12, normalised by the point count) pooled over objects."""
    b, _ = _boxes(labels, "labels")
    pts = [np.atleast_2d(as_f64(p, "scans")) for p in scans]
    counts = [p.shape[0] for p in pts]
    allp = np.concatenate(pts, axis=0) if pts else np.zeros((0, 2))
    sigma, iterations, history = _core.uncertainty_estimate_noise(
        b,
        allp,
        counts,
        as_float(sigma0, "sigma0"),
        as_float(tolerance, "tolerance"),
        as_int(max_iterations, "max_iterations"),
    )
    return NoiseEstimate(float(sigma), int(iterations), history)


def simulate_cars(
    n: int,
    *,
    sigma: float = 0.2,
    seed: int = 0,
    occlusion: float = 0.3,
    max_occluded: float = 0.5,
    azimuth_step_deg: float = 0.2,
    min_points: int = 10,
    range_m: tuple[float, float] = (6.0, 30.0),
) -> tuple[F64Array, list[F64Array]]:
    """``n`` cars around a scanner at the origin: ``(labels (n, 5), [points (k_i, 2)])``."""
    labels, pts, counts = _core.uncertainty_simulate_cars(
        as_int(n, "n"),
        as_float(sigma, "sigma"),
        as_int(seed, "seed"),
        as_float(occlusion, "occlusion"),
        as_float(max_occluded, "max_occluded"),
        as_float(azimuth_step_deg, "azimuth_step_deg"),
        as_int(min_points, "min_points"),
        (as_float(range_m[0], "range_m"), as_float(range_m[1], "range_m")),
    )
    return labels, np.split(pts, np.cumsum(counts)[:-1])


def _read_rows(source: str | os.PathLike[str] | ArrayLike, width: int, name: str) -> F64Array:
    if isinstance(source, (str, os.PathLike)):
        try:
            rows = np.loadtxt(source, delimiter=None, ndmin=2, comments="#")
        except ValueError:
            rows = np.loadtxt(source, delimiter=",", ndmin=2, comments="#")
    else:
        rows = np.atleast_2d(as_f64(source, name))
    if rows.ndim != 2 or rows.shape[1] != width:
        raise InvalidInputError(f"{name} must have {width} numbers per row, got shape {rows.shape}")
    if not np.all(np.isfinite(rows)):
        raise InvalidInputError(f"{name} contains non-finite values")
    return rows


def read_gaussian_boxes(
    source: str | os.PathLike[str] | ArrayLike, *, log_variance: bool = False
) -> tuple[F64Array, F64Array]:
    """Diagonal-Gaussian box predictions (ProbPIXOR-style, ref. [243] of the seed).

    One box per row: ``cx cy l w r v_cx v_cy v_l v_w v_r`` (variances, or log-variances with
    ``log_variance=True``), whitespace- or comma-separated, ``#`` comments. Returns
    ``(boxes (n, 5), covs (n, 5, 5))``.
    """
    rows = _read_rows(source, 10, "gaussian boxes")
    var = np.exp(rows[:, 5:]) if log_variance else rows[:, 5:]
    if np.any(var < 0):
        raise InvalidInputError("variances must be non-negative")
    b = rows[:, :5]
    if np.any(b[:, 2:4] <= 0):
        raise InvalidInputError("box sizes l, w must be positive")
    covs = np.zeros((rows.shape[0], 5, 5))
    covs[:, np.arange(5), np.arange(5)] = var
    return b, covs


def read_corner_boxes(source: str | os.PathLike[str] | ArrayLike) -> tuple[F64Array, F64Array]:
    """Corner-uncertainty box predictions (Appendix A case 1: corner distributions predicted).

    One box per row: four corners ``x y`` in counter-clockwise order starting at front-left
    (``v0 = (1/2, 1/2)``), then four corner covariances ``s_xx s_xy s_yy`` (20 numbers). The box
    Gaussian is the generalised least-squares fit of eq. 8.1 to the corners: mean from the
    corner means, ``cov = (J^T S^-1 J)^-1`` with ``J`` the 8x5 Jacobian of the corners.
    """
    rows = _read_rows(source, 20, "corner boxes")
    n = rows.shape[0]
    c = rows[:, :8].reshape(n, 4, 2)
    s = rows[:, 8:].reshape(n, 4, 3)
    centre = c.mean(axis=1)
    front = 0.5 * (c[:, 0] + c[:, 3]) - 0.5 * (c[:, 1] + c[:, 2])
    left = 0.5 * (c[:, 0] + c[:, 1]) - 0.5 * (c[:, 2] + c[:, 3])
    length = np.linalg.norm(front, axis=1)
    width = np.linalg.norm(left, axis=1)
    if np.any(length <= 0) or np.any(width <= 0):
        raise InvalidInputError("corner boxes must have positive length and width")
    heading = np.arctan2(front[:, 1], front[:, 0])
    boxes = np.column_stack([centre, length, width, heading])
    v0 = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    covs = np.zeros((n, 5, 5))
    for i in range(n):
        cr, sr = np.cos(heading[i]), np.sin(heading[i])
        jac = np.zeros((8, 5))
        info = np.zeros((8, 8))
        for k, (a, b) in enumerate(v0):
            la, wb = length[i] * a, width[i] * b
            jac[2 * k] = [1, 0, a * cr, -b * sr, -sr * la - cr * wb]
            jac[2 * k + 1] = [0, 1, a * sr, b * cr, cr * la - sr * wb]
            sk = np.array([[s[i, k, 0], s[i, k, 1]], [s[i, k, 1], s[i, k, 2]]])
            if np.linalg.eigvalsh(sk)[0] <= 0:
                raise InvalidInputError(f"corner covariance {k} of box {i} is not positive definite")
            info[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = np.linalg.inv(sk)
        covs[i] = np.linalg.inv(jac.T @ info @ jac)
        covs[i] = 0.5 * (covs[i] + covs[i].T)
    return boxes, covs


FIG_8_6_POINTS = np.array([[1.8, 0.0], [1.8, 0.9], [0.0, 0.9]])
FIG_8_6_V0 = np.array([[0.5, 0.0], [0.5, 0.5], [0.0, 0.5]])
FIG_8_6_BOX = np.array([0.0, 0.0, 3.6, 1.8, 0.0])


def fig_8_6(sigma: float = 0.2, prior_variance: float = 100.0**2) -> dict[str, Any]:
    """Fig. 8.6 of the seed: the posterior with deterministic latent variables.

    Returns the covariance over ``[c1, c2, l, w]`` (full extents, eq. 8.1) and over
    ``[c1, c2, l/2, w/2]`` (half extents: the seed's printed matrix), and the four standard
    deviations the text mixes up: ``eigen`` (square roots of the eigenvalues of the half-extent
    matrix: 0.094 and 0.302 m) and ``edge`` (the observed edge ``c1 + l/2``: 0.141 m; the
    unobserved ``c1 - l/2``: 0.424 m). The text's "0.09 m and 0.43 m" takes one of each.
    """
    post = posterior_with_correspondences(
        FIG_8_6_BOX,
        FIG_8_6_POINTS,
        FIG_8_6_V0,
        sigma=sigma,
        prior=np.eye(5) * prior_variance,
        estimate_heading=False,
    )
    full = post.cov[:4, :4]
    t = np.diag([1.0, 1.0, 0.5, 0.5])
    half = t @ full @ t
    eig = np.sqrt(np.sort(np.linalg.eigvalsh(half)))

    def edge(a: list[float]) -> float:
        v = np.array(a)
        return float(np.sqrt(v @ full @ v))

    return {
        "cov_full_extent": full,
        "cov_half_extent": half,
        "eigen_std": {"small": float(eig[0]), "large": float(eig[-1])},
        "edge_std": {"observed": edge([1, 0, 0.5, 0]), "unobserved": edge([1, 0, -0.5, 0])},
        "seed_matrix": 0.01 * np.array([[4, 0, -4, 0], [0, 4, 0, -4], [-4, 0, 6, 0], [0, -4, 0, 6]], dtype=float),
    }


def fig_8_7(sigma: float = 0.2, prior_variance: float = 100.0**2) -> LabelPosterior:
    """Fig. 8.7: the variational-Bayes posterior (GMM responsibilities) for the Fig. 8.6 points."""
    return label_uncertainty(
        FIG_8_6_BOX, FIG_8_6_POINTS, sigma=sigma, prior=np.eye(5) * prior_variance, estimate_heading=False
    )


def fig_8_5(cell: float = 0.05) -> dict[str, float]:
    """Fig. 8.5: a label with two equally likely (disjoint) boxes, a prediction equal to the small one.

    JIoU is 1/2 under ``p_G`` whatever the sizes, and ``A_small/(A_small + A_big)`` (near 0)
    under ``P_PDQ``.
    """
    big = [0.0, 0.0, 8.0, 4.0, 0.0]
    small = [7.0, 0.0, 2.0, 1.0, 0.0]
    grid = Grid(-5.0, -3.0, cell, cell, int(round(13.0 / cell)), int(round(6.0 / cell)))
    pred = rasterize([small], [1.0], grid)
    out = {}
    for kind in ("pg", "pdq"):
        label = rasterize([big, small], [0.5, 0.5], grid, kind=kind)  # type: ignore[arg-type]
        out[kind] = jiou_grid(label, pred)
    return out


__all__ = [
    "SEED_PRIOR_STD",
    "Grid",
    "LabelPosterior",
    "NoiseEstimate",
    "corners",
    "estimate_noise",
    "fig_8_5",
    "fig_8_6",
    "fig_8_7",
    "iou",
    "jiou",
    "jiou_grid",
    "label_uncertainty",
    "point_moments",
    "posterior_with_correspondences",
    "rasterize",
    "read_corner_boxes",
    "read_gaussian_boxes",
    "seed_prior",
    "simulate_cars",
    "spatial_distribution",
    "total_variance",
]
