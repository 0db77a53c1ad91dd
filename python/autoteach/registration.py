"""Point-set registration: coherent point drift (seed 000_3b1454b2b2194811.txt ch. 3.3–3.4).

Friendly front of the compiled registration bindings in :mod:`autoteach._core`: inputs may be
lists, tuples or NumPy arrays of any real dtype.

- :func:`cpd_rigid` -- rigid CPD with uniform scale, ``x ≈ s R y + t`` (Myronenko & Song 2010,
  Fig. 2).
- :func:`cpd_affine` -- affine CPD, ``x ≈ B y + t`` (Fig. 3).
- :func:`cpd_nonrigid` -- non-rigid CPD with Gaussian RKHS regularisation, ``T(Y) = Y + G W``
  (seed eq. (3.16)–(3.18)), optionally with the low-rank kernel ``G ≈ QΛQᵀ``.
- :func:`global_cpd` -- global-CPD (seed §3.4, Fig. 3.14): the top-K rigid hypotheses of global
  voting (Algorithm 3), each refined by non-rigid CPD, ranked by deformation energy.

All three treat the rows of ``Y`` (``M × D``) as the centroids of a Gaussian mixture fitted to
the rows of ``X`` (``N × D``), ``D ∈ {2, 3}``, with a uniform outlier component of weight
``w`` (seed eq. (3.12)–(3.15)). Stopping rules and defaults are those of pycpd 2.0
(``max_iterations=100``, ``tolerance=1e-3`` on the objective for rigid/affine, on σ² for
non-rigid), so results compare directly.

Errors: bad input (wrong shape or dtype, NaN, fewer than ``D + 1`` points, mismatched
dimensions, invalid options) raises :class:`~autoteach.errors.InvalidInputError`; degenerate
data (all points identical, a collinear ``Y`` for the affine fit, every point an outlier)
raises :class:`~autoteach.errors.DegenerateGeometryError`.

Example:
    >>> import numpy as np
    >>> from autoteach.registration import cpd_rigid
    >>> rng = np.random.default_rng(0)
    >>> Y = rng.uniform(-1, 1, (50, 2))
    >>> c, s = np.cos(0.4), np.sin(0.4)
    >>> X = 1.5 * Y @ np.array([[c, -s], [s, c]]).T + [0.2, -0.1]
    >>> fit = cpd_rigid(X, Y)
    >>> round(fit.scale, 6), bool(np.allclose(fit.transformed, X, atol=1e-6))
    (1.5, True)

"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError
from autoteach.polygon import RigidHypothesis, VotingOptions, voting_options

__all__ = [
    "AffineCpdResult",
    "GlobalCpdHypothesis",
    "NonrigidCpdResult",
    "RigidCpdResult",
    "cpd_affine",
    "cpd_nonrigid",
    "cpd_rigid",
    "global_cpd",
]

EStepMode = Literal["auto", "dense", "truncated", "fast_gauss"]


@dataclass(frozen=True, slots=True)
class RigidCpdResult:
    """The result of :func:`cpd_rigid`: ``x ≈ scale · rotation · y + translation``.

    The fields are those of ``autoteach_detect::cpd::RigidResult``.

    Attributes:
        rotation: Rotation ``R``, shape ``(D, D)``, ``det R = +1``.
        translation: Translation ``t``, shape ``(D,)``.
        scale: Uniform scale ``s`` (``1.0`` with ``scale=False``).
        transformed: The moved ``Y``, ``s Y Rᵀ + t``, shape ``(M, D)``.
        sigma2: Final variance σ² of the mixture.
        iterations: EM iterations run.
        converged: Whether the tolerance was met before ``max_iterations``.
        p: Posterior matrix ``P`` of the last E-step, shape ``(M, N)`` (``P[m, n] = p(y_m | x_n)``),
            or ``None`` unless ``return_P=True``.

    """

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    scale: float
    transformed: NDArray[np.float64]
    sigma2: float
    iterations: int
    converged: bool
    p: NDArray[np.float64] | None


@dataclass(frozen=True, slots=True)
class AffineCpdResult:
    """The result of :func:`cpd_affine`: ``x ≈ matrix · y + translation``.

    The fields are those of ``autoteach_detect::cpd::AffineResult``.

    Attributes:
        matrix: Linear part ``B``, shape ``(D, D)``.
        translation: Translation ``t``, shape ``(D,)``.
        transformed: The moved ``Y``, ``Y Bᵀ + t``, shape ``(M, D)``.
        sigma2: Final variance σ².
        iterations: EM iterations run.
        converged: Whether the tolerance was met before ``max_iterations``.
        p: Posterior matrix ``P`` ``(M, N)`` of the last E-step, or ``None``.

    """

    matrix: NDArray[np.float64]
    translation: NDArray[np.float64]
    transformed: NDArray[np.float64]
    sigma2: float
    iterations: int
    converged: bool
    p: NDArray[np.float64] | None


@dataclass(frozen=True, slots=True)
class NonrigidCpdResult:
    """The result of :func:`cpd_nonrigid`: ``T(Y) = Y + G W``.

    The fields are those of ``autoteach_detect::cpd::NonrigidResult``.

    Attributes:
        w: Kernel weights ``W``, shape ``(M, D)`` (seed eq. (3.17)); not the outlier weight
            argument ``w`` of the functions.
        transformed: The moved ``Y``, shape ``(M, D)``.
        energy: Deformation energy ``‖f‖²_H = tr(Wᵀ G W)`` (seed eq. (3.17)).
        sigma2: Final variance σ².
        iterations: EM iterations run.
        converged: Whether the tolerance was met before ``max_iterations``.
        rank: Number of eigenpairs of ``G`` used, or ``None`` for the full kernel.
        p: Posterior matrix ``P`` ``(M, N)`` of the last E-step, or ``None``.

    """

    w: NDArray[np.float64]
    transformed: NDArray[np.float64]
    energy: float
    sigma2: float
    iterations: int
    converged: bool
    rank: int | None
    p: NDArray[np.float64] | None


def _common(
    w: float, max_iterations: int, tolerance: float, sigma2: float | None, e_step: str
) -> tuple[float, int, float, float | None, str]:
    """Validate the options shared by the three variants."""
    w = as_float(w, "w")
    max_iterations = as_int(max_iterations, "max_iterations")
    if max_iterations < 0:
        raise InvalidInputError(f"max_iterations must be ≥ 0, got {max_iterations}")
    tolerance = as_float(tolerance, "tolerance")
    s2 = None if sigma2 is None else as_float(sigma2, "sigma2")
    if e_step not in ("auto", "dense", "truncated", "fast_gauss"):
        raise InvalidInputError(f"e_step must be 'auto', 'dense', 'truncated' or 'fast_gauss', got {e_step!r}")
    return w, max_iterations, tolerance, s2, e_step


def cpd_rigid(
    X: ArrayLike,
    Y: ArrayLike,
    w: float = 0.0,
    scale: bool = True,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    e_step: EStepMode = "auto",
    return_P: bool = False,
) -> RigidCpdResult:
    """Register ``Y`` onto ``X`` with a similarity (or rigid) transform by CPD.

    Args:
        X: Target points, shape ``(N, D)``, ``D ∈ {2, 3}``.
        Y: Moving points, shape ``(M, D)``.
        w: Weight of the uniform outlier component, ``0 ≤ w < 1``.
        scale: Estimate the uniform scale; ``False`` keeps ``s = 1``.
        max_iterations: Maximum EM iterations.
        tolerance: Stop when the objective changes by at most this much.
        sigma2: Initial σ²; ``None`` for ``Σ‖x − y‖²/(D N M)``.
        e_step: ``"dense"`` evaluates every pair; ``"truncated"`` only pairs within ~8.6 σ
            (grid, relative error below 1e-8 per row); ``"fast_gauss"`` uses a Chebyshev fast
            Gauss transform (kernel values to ~1e-11) when σ allows it; ``"auto"`` truncates
            when it pays off and, above 10⁶ pairs, uses the fast Gauss transform when it is
            cheaper. Full-rank :func:`cpd_nonrigid` also applies its kernel ``G`` by the fast
            Gauss transform when cheaper, except with ``"dense"`` (stored exact ``G``).
        return_P: Also return the ``(M, N)`` posterior matrix of the last E-step.

    Returns:
        See :class:`RigidCpdResult`.

    Raises:
        InvalidInputError: Bad shapes, dtypes, NaN, too few points or invalid options.
        DegenerateGeometryError: All points identical, or no point explained by the mixture.

    """
    w, max_iterations, tolerance, sigma2, e_step = _common(w, max_iterations, tolerance, sigma2, e_step)
    r = _core.cpd_rigid(
        as_f64(X, "X"), as_f64(Y, "Y"), w, bool(scale), max_iterations, tolerance, sigma2, e_step, bool(return_P)
    )
    return RigidCpdResult(**r)


def cpd_affine(
    X: ArrayLike,
    Y: ArrayLike,
    w: float = 0.0,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    e_step: EStepMode = "auto",
    return_P: bool = False,
) -> AffineCpdResult:
    """Register ``Y`` onto ``X`` with an affine transform by CPD.

    Args:
        X: Target points, shape ``(N, D)``, ``D ∈ {2, 3}``.
        Y: Moving points, shape ``(M, D)``; must span ``D`` dimensions.
        w: Weight of the uniform outlier component, ``0 ≤ w < 1``.
        max_iterations: Maximum EM iterations.
        tolerance: Stop when the objective changes by at most this much.
        sigma2: Initial σ²; ``None`` for ``Σ‖x − y‖²/(D N M)``.
        e_step: See :func:`cpd_rigid`.
        return_P: Also return the ``(M, N)`` posterior matrix of the last E-step.

    Returns:
        See :class:`AffineCpdResult`.

    Raises:
        InvalidInputError: Bad shapes, dtypes, NaN, too few points or invalid options.
        DegenerateGeometryError: Identical or collinear (coplanar in 3-D) ``Y``.

    """
    w, max_iterations, tolerance, sigma2, e_step = _common(w, max_iterations, tolerance, sigma2, e_step)
    r = _core.cpd_affine(as_f64(X, "X"), as_f64(Y, "Y"), w, max_iterations, tolerance, sigma2, e_step, bool(return_P))
    return AffineCpdResult(**r)


def cpd_nonrigid(
    X: ArrayLike,
    Y: ArrayLike,
    beta: float = 2.0,
    lam: float = 2.0,
    low_rank: int | None = None,
    power_iterations: int | None = None,
    w: float = 0.0,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    e_step: EStepMode = "auto",
    return_P: bool = False,
) -> NonrigidCpdResult:
    """Register ``Y`` onto ``X`` with a smooth non-rigid deformation by CPD.

    Args:
        X: Target points, shape ``(N, D)``, ``D ∈ {2, 3}``.
        Y: Moving points, shape ``(M, D)``.
        beta: Width β of the Gaussian kernel ``G`` (in the units of the points).
        lam: Regularisation weight λ (pycpd's ``alpha``).
        low_rank: Number ``K`` of eigenpairs of ``G`` to keep (``O(M K²)`` per iteration);
            ``None`` for the full kernel (``M ≤ 12000``).
        power_iterations: Subspace-iteration steps refining the Nyström eigenpairs;
            ``None`` for 2 when ``M ≤ 5000``, else 0.
        w: Weight of the uniform outlier component, ``0 ≤ w < 1``.
        max_iterations: Maximum EM iterations.
        tolerance: Stop when σ² changes by at most this much.
        sigma2: Initial σ²; ``None`` for ``Σ‖x − y‖²/(D N M)``.
        e_step: See :func:`cpd_rigid`.
        return_P: Also return the ``(M, N)`` posterior matrix of the last E-step.

    Returns:
        See :class:`NonrigidCpdResult`.

    Raises:
        InvalidInputError: Bad shapes, dtypes, NaN, too few points or invalid options.
        DegenerateGeometryError: All points identical, or no point explained by the mixture.

    """
    w, max_iterations, tolerance, sigma2, e_step = _common(w, max_iterations, tolerance, sigma2, e_step)
    k = None if low_rank is None else as_int(low_rank, "low_rank")
    if k is not None and k < 1:
        raise InvalidInputError(f"low_rank must be ≥ 1 or None, got {k}")
    pi = None if power_iterations is None else as_int(power_iterations, "power_iterations")
    if pi is not None and pi < 0:
        raise InvalidInputError(f"power_iterations must be ≥ 0 or None, got {pi}")
    r = _core.cpd_nonrigid(
        as_f64(X, "X"),
        as_f64(Y, "Y"),
        as_float(beta, "beta"),
        as_float(lam, "lam"),
        k,
        pi,
        w,
        max_iterations,
        tolerance,
        sigma2,
        e_step,
        bool(return_P),
    )
    return NonrigidCpdResult(**r)


@dataclass(frozen=True, slots=True)
class GlobalCpdHypothesis:
    """One hypothesis of :func:`global_cpd`.

    The fields are those of ``autoteach_detect::cpd::GlobalHypothesis``.

    Attributes:
        initial: The rigid initial transform from global voting, ``x ≈ R y + t``, with its votes
            (the :class:`~autoteach.polygon.RigidHypothesis` that :func:`~autoteach.polygon.global_voting`
            returns).
        cpd: The non-rigid CPD run from it; ``cpd.transformed`` is the model in the frame of ``X``
            and ``cpd.energy`` (``tr(Wᵀ G W)``, least is best) ranks the hypotheses.

    """

    initial: RigidHypothesis
    cpd: NonrigidCpdResult


#: The voting options global-CPD does not expose, at the values it uses.
_VOTING_DEFAULT_OF = {
    "descriptor_tolerance": VotingOptions().descriptor_tolerance,
    "shifted_grid": VotingOptions().shifted_grid,
    "max_pairs": VotingOptions().max_pairs,
}


def global_cpd(
    X: ArrayLike,
    Y: ArrayLike,
    k: int = 3,
    beta: float = 2.0,
    lam: float = 2.0,
    w: float = 0.5,
    low_rank: int | None = None,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    voting: VotingOptions | None = None,
    **voting_overrides: Any,
) -> list[GlobalCpdHypothesis]:
    """Register a model ``Y`` into a cluttered scene ``X`` by global-CPD (seed Fig. 3.14).

    Global voting (seed eq. (3.20)–(3.22), Algorithm 3) proposes the top-``k`` rigid transforms
    from local reference frames; non-rigid CPD refines each from its transform; the hypotheses
    are ranked by deformation energy ``tr(Wᵀ G W)`` (seed eq. (3.17)), least first. The CPD
    starts from σ² = mean squared distance of the moved model to its nearest scene point
    unless ``sigma2`` is given.

    Args:
        X: Scene points, shape ``(N, D)``, ``D ∈ {2, 3}``.
        Y: Model points, shape ``(M, D)``.
        k: Number of voting hypotheses refined.
        beta: Kernel width β of the non-rigid CPD.
        lam: Regularisation weight λ of the non-rigid CPD.
        w: Outlier weight of the CPD (scenes are cluttered: default 0.5).
        low_rank: Eigenpairs of ``G`` for the CPD, ``None`` for full rank.
        max_iterations: Maximum CPD iterations per hypothesis.
        tolerance: CPD tolerance on σ².
        sigma2: Initial σ² of every CPD run (see above for the default).
        voting: Options of the global vote (default :class:`~autoteach.polygon.VotingOptions`;
            ``neighbours``, ``angle_bin``, ``translation_bin``, ``count``, ``min_votes``,
            ``max_points`` are passed to global-CPD).
        **voting_overrides: Voting options that replace those of ``voting`` by name, e.g.
            ``count="pairs"``.

    Returns:
        Up to ``k`` hypotheses, least deformation energy first (empty when no cluster has
        enough votes).

    Raises:
        InvalidInputError: Bad shapes, dtypes, NaN, too few points or invalid options.
        DegenerateGeometryError: Degenerate point sets (all identical).

    """
    vote = voting_options(voting, voting_overrides)
    unused = [
        n for n in ("descriptor_tolerance", "shifted_grid", "max_pairs") if getattr(vote, n) != _VOTING_DEFAULT_OF[n]
    ]
    if unused:
        raise InvalidInputError(f"global_cpd votes with the default {unused}; they cannot be set here")
    if vote.count not in ("y", "pairs"):
        raise InvalidInputError(f"count must be 'y' or 'pairs', got {vote.count!r}")
    w, max_iterations, tolerance, s2, _ = _common(w, max_iterations, tolerance, sigma2, "auto")
    kk = as_int(k, "k")
    if kk < 1:
        raise InvalidInputError(f"k must be ≥ 1, got {kk}")
    lr = None if low_rank is None else as_int(low_rank, "low_rank")
    tb = None if vote.translation_bin is None else as_float(vote.translation_bin, "translation_bin")
    hyps = _core.global_cpd(
        as_f64(X, "X"),
        as_f64(Y, "Y"),
        kk,
        as_float(beta, "beta"),
        as_float(lam, "lam"),
        w,
        lr,
        max_iterations,
        tolerance,
        s2,
        as_int(vote.neighbours, "neighbours"),
        as_float(vote.angle_bin, "angle_bin"),
        tb,
        vote.count,
        as_int(vote.min_votes, "min_votes"),
        as_int(vote.max_points, "max_points"),
    )
    out = []
    for h in hyps:
        rotation, translation, votes, pair_votes = h["initial"]
        initial = RigidHypothesis(rotation, translation, int(votes), int(pair_votes))
        out.append(GlobalCpdHypothesis(initial, NonrigidCpdResult(**h["cpd"])))
    return out
