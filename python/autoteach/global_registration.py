"""Global registration that a distractor cannot win (seed 000_3b1454b2b2194811.txt §3.4; issue 29).

Friendly front of the compiled ``global_register``:

1. global voting (seed eq. (3.19)–(3.22), Algorithm 3, Y-count) with non-maximum suppression in
   transform space gives ``k`` distinct rigid hypotheses;
2. each is refined by rigid CPD (seed eq. (3.12)–(3.15)) on the scene window around it;
3. the refined hypotheses are scored on a common scale -- the fraction of template points
   explained within the inlier radius ``r = max(3·√(D·σ̂²), h)`` (σ̂² the best converged CPD
   variance, ``h`` the template's point spacing), the CPD likelihood with its outlier term, and
   optionally the deformation energy of seed eq. (3.17) -- and ranked by ``criterion``;
4. the template is voted onto itself: its rotational symmetries are reported, the equivalent
   poses of the best are among the candidates (``equivalent=True``) and ``ambiguous`` is set;
5. a full-resolution rigid CPD (optionally non-rigid) from the chosen pose.

Errors: bad input raises :class:`~autoteach.errors.InvalidInputError`; no voting cluster or no
refinable hypothesis raises :class:`~autoteach.errors.DegenerateGeometryError`.

Example:
    >>> import numpy as np
    >>> from autoteach.global_registration import global_register
    >>> t = np.linspace(0, 1, 60)
    >>> Y = np.vstack([np.column_stack([t, 0 * t]), np.column_stack([0 * t[:30], 0.5 * t[:30]])])
    >>> c, s = np.cos(2.0), np.sin(2.0)
    >>> X = Y @ np.array([[c, -s], [s, c]]).T + [3.0, 1.0]
    >>> r = global_register(X, Y)
    >>> bool(np.sqrt(np.mean(np.sum((r.transformed - X) ** 2, axis=1))) < 0.01), r.ambiguous
    (True, False)

"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError
from autoteach.options import field_names, refuse_unknown
from autoteach.polygon import RigidHypothesis, VotingOptions

__all__ = [
    "REGISTER_VOTING",
    "GlobalRegisterOptions",
    "GlobalRegistration",
    "RegistrationCandidate",
    "global_register",
]

CriterionName = Literal["explained", "likelihood", "energy"]


@dataclass(frozen=True, slots=True)
class RegistrationCandidate:
    """One refined hypothesis (fields of ``autoteach_detect::cpd::RegistrationCandidate``).

    Attributes:
        rotation: Refined rotation ``(D, D)``, ``x ≈ R y + t``.
        translation: Refined translation ``(D,)``.
        sigma2: Converged σ² of its rigid CPD.
        explained: Fraction of template points with a scene point within the inlier radius.
        log_likelihood: CPD log-likelihood with the outlier term at the common σ̂² (constant dropped).
        energy: Deformation energy of a non-rigid CPD from the pose (``None`` unless computed).
        equivalent: The chosen pose composed with a template symmetry.
        initial: The voting hypothesis it started from.
        template: The template ``(M, D)`` (for :attr:`transformed`).

    """

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    sigma2: float
    explained: float
    log_likelihood: float
    energy: float | None
    equivalent: bool
    initial: RigidHypothesis
    template: NDArray[np.float64]

    @property
    def transformed(self) -> NDArray[np.float64]:
        """The template moved by this candidate's pose."""
        return self.template @ self.rotation.T + self.translation


@dataclass(frozen=True, slots=True)
class GlobalRegistration:
    """Result of :func:`global_register`.

    Attributes:
        candidates: Refined hypotheses, best first by the criterion; symmetric equivalents of the
            best follow it.
        symmetries: Rotational self-maps ``(R, t)`` of the template.
        ambiguous: True when the template has a symmetry (several poses explain the scene equally).
        inlier_radius: Inlier radius of the scores.
        sigma2: Common σ̂² of the scores.
        rotation: Final rotation (full-resolution rigid CPD from the best candidate).
        translation: Final translation.
        transformed: The registered template (non-rigid if asked, else rigid).
        energy: Deformation energy of the final non-rigid CPD, if run.

    """

    candidates: list[RegistrationCandidate]
    symmetries: list[tuple[NDArray[np.float64], NDArray[np.float64]]]
    ambiguous: bool
    inlier_radius: float
    sigma2: float
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    transformed: NDArray[np.float64]
    energy: float | None

    def best_by(self, criterion: CriterionName) -> RegistrationCandidate:
        """The candidate another criterion would choose (``energy`` needs ``energy_all=True``)."""
        if criterion == "explained":
            return max(self.candidates, key=lambda c: (c.explained, c.log_likelihood))
        if criterion == "likelihood":
            return max(self.candidates, key=lambda c: c.log_likelihood)
        if criterion == "energy":
            with_e = [c for c in self.candidates if c.energy is not None]
            if not with_e:
                raise InvalidInputError("no candidate has an energy: call global_register(..., energy_all=True)")
            return min(with_e, key=lambda c: c.energy if c.energy is not None else np.inf)
        raise InvalidInputError(f"criterion must be 'explained', 'likelihood' or 'energy', got {criterion!r}")


@dataclass(frozen=True, slots=True)
class GlobalRegisterOptions:
    """Options of the refinement and the choice of :func:`global_register` (module docs).

    Attributes:
        w: Outlier weight of the CPD runs and of the likelihood, in (0, 1).
        max_iterations: Iterations per rigid CPD refinement.
        max_refine_points: Template points refined and scored per hypothesis.
        window: Scene window around a moved template, as a fraction of the shape size.
        energy_all: Also compute every candidate's deformation energy.
        nonrigid: Finish with a non-rigid CPD (``transformed`` is then non-rigid).
        beta: Kernel width β of the non-rigid CPD.
        lam: Regularisation λ of the non-rigid CPD.
        symmetry_fraction: A self-map putting this fraction of the template on itself is a symmetry.
    """

    w: float = 0.5
    max_iterations: int = 10
    max_refine_points: int = 100
    window: float = 0.25
    energy_all: bool = False
    nonrigid: bool = False
    beta: float = 2.0
    lam: float = 2.0
    symmetry_fraction: float = 0.9


#: The voting defaults of :func:`global_register`: 200 points per set vote (the refinement, not
#: the vote, decides among the hypotheses).
REGISTER_VOTING = VotingOptions(max_points=200)


def global_register(
    X: ArrayLike,
    Y: ArrayLike,
    k: int = 8,
    criterion: CriterionName = "explained",
    options: GlobalRegisterOptions | None = None,
    voting: VotingOptions | None = None,
    **overrides: Any,
) -> GlobalRegistration:
    """Register a template ``Y`` into a cluttered scene ``X`` (module docs).

    Args:
        X: Scene points ``(N, D)``, ``D ∈ {2, 3}``.
        Y: Template points ``(M, D)``.
        k: Voting hypotheses refined (after suppression).
        criterion: ``"explained"`` (default), ``"likelihood"`` or ``"energy"``.
        options: Refinement and choice (default :class:`GlobalRegisterOptions`).
        voting: The global vote (default :data:`REGISTER_VOTING`; ``neighbours``, ``angle_bin``,
            ``translation_bin``, ``count``, ``min_votes`` and ``max_points`` apply).
        **overrides: Fields of either that replace them by name, e.g. ``beta=0.5`` or
            ``count="pairs"``.

    Returns:
        The registration.

    Raises:
        InvalidInputError: Bad shapes, dtypes, NaN/inf, too few points or invalid options.
        DegenerateGeometryError: All points identical, no voting cluster, nothing refinable.

    """
    if criterion not in ("explained", "likelihood", "energy"):
        raise InvalidInputError(f"criterion must be 'explained', 'likelihood' or 'energy', got {criterion!r}")
    o, v = _split_overrides(options or GlobalRegisterOptions(), voting or REGISTER_VOTING, overrides)
    if v.count not in ("y", "pairs"):
        raise InvalidInputError(f"count must be 'y' or 'pairs', got {v.count!r}")
    kk = as_int(k, "k")
    if kk < 1:
        raise InvalidInputError(f"k must be ≥ 1, got {kk}")
    y = as_f64(Y, "Y")
    tb = None if v.translation_bin is None else as_float(v.translation_bin, "translation_bin")
    r = _core.global_register(
        as_f64(X, "X"),
        y,
        kk,
        criterion,
        v.count,
        as_float(o.w, "w"),
        as_int(o.max_iterations, "max_iterations"),
        as_int(o.max_refine_points, "max_refine_points"),
        as_float(o.window, "window"),
        bool(o.energy_all),
        bool(o.nonrigid),
        as_float(o.beta, "beta"),
        as_float(o.lam, "lam"),
        as_float(o.symmetry_fraction, "symmetry_fraction"),
        as_int(v.neighbours, "neighbours"),
        as_float(v.angle_bin, "angle_bin"),
        tb,
        as_int(v.min_votes, "min_votes"),
        as_int(v.max_points, "max_points"),
    )
    cands = []
    for rot, tr, s2, expl, ll, en, eq, r0, t0, votes, pv in r.candidates:
        init = RigidHypothesis(r0, t0, int(votes), int(pv))
        cands.append(RegistrationCandidate(rot, tr, float(s2), float(expl), float(ll), en, bool(eq), init, y))
    rot, tr, transformed, _ = r.rigid
    nr = r.nonrigid
    energy = None
    if nr is not None:
        transformed, energy = nr[0], float(nr[1])
    return GlobalRegistration(
        cands,
        [(a, b) for a, b in r.symmetries],
        bool(r.ambiguous),
        float(r.inlier_radius),
        float(r.sigma2),
        rot,
        tr,
        transformed,
        energy,
    )


def _split_overrides(
    options: GlobalRegisterOptions, voting: VotingOptions, overrides: dict[str, Any]
) -> tuple[GlobalRegisterOptions, VotingOptions]:
    """``options`` and ``voting`` with each override applied to the one that has its name."""
    own, votes = field_names(GlobalRegisterOptions), field_names(VotingOptions)
    refuse_unknown(own | votes, overrides, "global-registration")
    fixed = [n for n in ("descriptor_tolerance", "shifted_grid", "max_pairs") if n in overrides]
    if fixed:
        raise InvalidInputError(f"global_register votes with the default {fixed}; they cannot be set here")
    options = dataclasses.replace(options, **{n: x for n, x in overrides.items() if n in own})
    return options, voting.replace(**{n: x for n, x in overrides.items() if n in votes})
