"""Active auto-teaching: Fisher information, observability indices and measurement-pose planning.

Friendly front of the compiled ``active`` bindings (seed 000_3b1454b2b2194811.txt ch. 6):

- :func:`fisher_information` -- the Fisher information of a design, eq. (6.6);
- :func:`observability_indices` -- O1-O6 of Table 6.2 (O6 with the power ``P``);
- :func:`d_optimal_design`, :func:`directional_derivatives` -- approximate D-optimal designs on
  a finite candidate set and the General Equivalence Theorem check (Theorem 6.2.1, eq. (6.8));
- :func:`detmax` -- the DETMAX exchange algorithm selecting ``n`` of a finite candidate set (6.10);
- :class:`ActiveState` -- the hand-eye system in front of a chamber opening: the linearised
  observation model (6.11)-(6.14) and its Kalman filter (6.15);
- :func:`plan_next_pose` -- the one-step greedy planner (6.22)-(6.25) under the constraints
  (6.17)-(6.20);
- :func:`run_trials`, :func:`compare` -- the closed loop of Fig. 6.1 on simulation, with and
  without active planning (Table 6.4, Fig. 6.4).

Units: SI inside (metres, radians); reported errors are in millimetres and degrees (the suffix
of each name says which). Errors: bad input raises :class:`~autoteach.errors.InvalidInputError`,
a singular information matrix :class:`~autoteach.errors.DegenerateGeometryError`, a planning
step without a feasible pose :class:`~autoteach.errors.UnreachablePoseError` whose message names
the binding constraint.

Example:
    >>> import numpy as np
    >>> from autoteach.active import observability_indices
    >>> o = observability_indices(np.diag([16.0, 4.0, 1.0]), power=2.0)
    >>> round(o.o1, 6), o.o2, o.o3
    (4.0, 0.0625, 1.0)

"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from autoteach import _core
from autoteach._convert import F64Array, as_f64
from autoteach.errors import InvalidInputError

__all__ = [
    "ActiveState",
    "ApproximateDesign",
    "DetmaxResult",
    "HandEyeParams",
    "ObservabilityIndices",
    "Plan",
    "PlannedPose",
    "Rejections",
    "TrialRuns",
    "UpdateSummary",
    "compare",
    "d_optimal_design",
    "detmax",
    "directional_derivatives",
    "fisher_information",
    "observability_indices",
    "plan_next_pose",
    "run_trials",
]

PARAM_NAMES: tuple[str, ...] = tuple(_core.ACTIVE_PARAM_NAMES)
"""Names of the full hand-eye parameter vector (units in the suffix)."""

INDEX_NAMES = ("O1", "O2", "O3", "O4", "O5", "O6", "log_det")


def _matrices(value: Any, name: str) -> list[F64Array]:
    if isinstance(value, np.ndarray) and value.ndim == 3:
        return [np.ascontiguousarray(m) for m in as_f64(value, name)]
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence | np.ndarray):
        raise InvalidInputError(f"{name} must be a sequence of 2-D arrays, got {type(value).__name__}")
    out = []
    for k, m in enumerate(value):
        a = as_f64(m, f"{name}[{k}]")
        if a.ndim == 1:
            a = a[None, :]
        out.append(np.ascontiguousarray(a))
    return out


@dataclass(frozen=True, slots=True)
class ObservabilityIndices:
    """Observability indices of Table 6.2.

    The fields of ``autoteach_estimate::active::design::ObservabilityIndices``; ``σ_1 ≥ … ≥ σ_m``
    are the singular values of the information matrix.
    """

    o1: float
    """O1 (D-optimality): ``(Π σ)^{1/m}``, the geometric mean."""
    o2: float
    """O2 (inverse condition number): ``σ_m/σ_1``."""
    o3: float
    """O3 (E-optimality): ``σ_m``."""
    o4: float
    """O4 (noise amplification index): ``σ_m²/σ_1``."""
    o5: float
    """O5: ``1/Σ σ⁻¹``."""
    o6: float
    """O6: ``1/Σ σ^{-P}`` with the power ``P`` below."""
    power: float
    """The power ``P`` of O6."""
    log_det: float
    """``log det M = Σ log σ`` (``-inf`` for a singular matrix)."""

    @classmethod
    def _from_core(cls, d: Mapping[str, float]) -> ObservabilityIndices:
        """From the binding's dict (keys ``O1``-``O6``, ``power``, ``log_det``)."""
        return cls(*(float(d[k]) for k in ("O1", "O2", "O3", "O4", "O5", "O6", "power", "log_det")))


@dataclass(frozen=True, slots=True)
class ApproximateDesign:
    """An approximate design on a finite candidate set.

    The fields of ``autoteach_estimate::active::design::ApproximateDesign``.
    """

    weights: F64Array
    """Weight ``ω_i`` of each candidate (sum 1), eq. (6.1)."""
    variance: F64Array
    """``d(x_i, ξ) = tr(M⁻¹ F_iᵀF_i)`` of every candidate (the standardised variance)."""
    max_variance: float
    """``max_i d(x_i, ξ)``; ``= p`` at the D-optimum (General Equivalence Theorem)."""
    log_det: float
    """``log det M(ξ)``."""
    iterations: int
    """Multiplicative iterations run."""


@dataclass(frozen=True, slots=True)
class DetmaxResult:
    """The result of :func:`detmax` (the fields of ``autoteach_estimate::active::design::DetmaxResult``)."""

    selected: list[int]
    """Indices of the selected candidates (sorted)."""
    log_det: float
    """``log det(M0 + Σ_selected F_iᵀF_i)``."""
    excursions: int
    """Accepted excursions and exchanges."""


@dataclass(frozen=True, slots=True)
class UpdateSummary:
    """Summary of one :meth:`ActiveState.update`.

    The fields of ``autoteach_estimate::active::model::UpdateSummary``.
    """

    used: int
    """Corners used (detected and projectable under the estimate)."""
    iterations: int
    """Gauss-Newton iterations of the iterated update."""
    rms_px: float
    """RMS pixel residual after the update."""


@dataclass(frozen=True, slots=True)
class HandEyeParams:
    """Hand-eye parameter values (the fields of ``autoteach_estimate::active::model::HandEyeParams``)."""

    opening: F64Array
    """Pose of the chamber opening in the world, ``T_wo`` (4×4)."""
    camera_translation: F64Array
    """Camera mount translation ``t_e2c`` in the blade-2 frame (3,), metres."""
    joint_offsets: F64Array
    """Joint zero offsets (5,) (encoder = true + offset)."""


def fisher_information(
    jacobians: Sequence[ArrayLike] | ArrayLike, sigmas: ArrayLike, weights: ArrayLike | None = None
) -> F64Array:
    """Fisher information ``M = Σ ω_i / σ_i² J_iᵀ J_i`` of a discrete design, eq. (6.6).

    ``jacobians[i]`` is ``∂h(x_i, θ)/∂θ`` (``(d_i, p)`` or a gradient ``(p,)``), ``sigmas[i]`` the
    noise standard deviation of observation ``i`` and ``weights`` the design weights (default 1).
    """
    js = _matrices(jacobians, "jacobians")
    s = np.atleast_1d(as_f64(sigmas, "sigmas"))
    w = np.ones(len(js)) if weights is None else np.atleast_1d(as_f64(weights, "weights"))
    return _core.active_fisher_information(js, np.ascontiguousarray(s), np.ascontiguousarray(w))


def observability_indices(information: ArrayLike, power: float = 2.0) -> ObservabilityIndices:
    """Observability indices O1-O6 of Table 6.2 of a symmetric PSD information matrix.

    With the singular values ``σ_1 ≥ … ≥ σ_m``: ``O1 = (Π σ)^{1/m}``, ``O2 = σ_m/σ_1``,
    ``O3 = σ_m``, ``O4 = σ_m²/σ_1``, ``O5 = 1/Σ σ⁻¹``, ``O6 = 1/Σ σ^{-P}``; also ``log_det``.
    Computed in the log domain (robust for ill-conditioned matrices); a singular matrix gives
    zeros and ``log_det = -inf``.
    """
    return ObservabilityIndices._from_core(
        _core.active_observability_indices(as_f64(information, "information"), float(power))
    )


def d_optimal_design(
    candidates: Sequence[ArrayLike] | ArrayLike, tol: float = 1e-6, max_iterations: int = 100_000
) -> ApproximateDesign:
    """Approximate D-optimal design weights on a finite candidate set (multiplicative algorithm).

    ``candidates[i]`` is the whitened Jacobian ``F_i`` (``(d_i, p)``, or a regressor ``(p,)``).
    Returns the :class:`ApproximateDesign`: ``weights``, ``variance`` (``d_i = tr(M⁻¹ F_iᵀF_i)``),
    ``max_variance`` (``= p`` at the optimum, the General Equivalence Theorem), ``log_det`` and
    ``iterations``.
    """
    d = _core.active_d_optimal_design(_matrices(candidates, "candidates"), float(tol), int(max_iterations))
    return ApproximateDesign(
        weights=np.asarray(d["weights"]),
        variance=np.asarray(d["variance"]),
        max_variance=float(d["max_variance"]),
        log_det=float(d["log_det"]),
        iterations=int(d["iterations"]),
    )


def directional_derivatives(candidates: Sequence[ArrayLike] | ArrayLike, weights: ArrayLike) -> F64Array:
    """``φ(x_i, ξ) = p − tr(M(ξ)⁻¹ F_iᵀF_i)``, eq. (6.8) for ``ψ = −log det M`` (≥ 0 at the optimum)."""
    w = np.ascontiguousarray(np.atleast_1d(as_f64(weights, "weights")))
    return _core.active_directional_derivatives(_matrices(candidates, "candidates"), w)


def detmax(
    candidates: Sequence[ArrayLike] | ArrayLike,
    n: int,
    prior: ArrayLike | None = None,
    max_excursion: int = 3,
    allow_repeats: bool = False,
    seed: int = 0,
) -> DetmaxResult:
    """Select ``n`` candidates maximising ``log det(M0 + Σ F_iᵀF_i)`` with DETMAX (eq. (6.10)).

    Returns the :class:`DetmaxResult`: ``selected`` (sorted indices), ``log_det`` and ``excursions``.
    """
    p = None if prior is None else as_f64(prior, "prior")
    d = _core.active_detmax(
        _matrices(candidates, "candidates"), int(n), p, int(max_excursion), bool(allow_repeats), int(seed)
    )
    return DetmaxResult(
        selected=[int(i) for i in d["selected"]], log_det=float(d["log_det"]), excursions=int(d["excursions"])
    )


@dataclass(frozen=True, slots=True)
class PlannedPose:
    """A planned measurement pose (the fields of ``autoteach_estimate::active::planner::PlannedPose``)."""

    joints: F64Array
    """Encoder readings ``(θ1, θ2, θ3, θ4, h)`` to command."""
    camera_pose: F64Array
    """``T_wc`` (4×4) under the estimated model."""
    score: float
    """Criterion value (D: the log-determinant gain of eq. (6.22))."""


@dataclass(frozen=True, slots=True)
class Rejections:
    """Candidate rejections per constraint (the fields of ``autoteach_estimate::active::planner::Rejections``)."""

    unreachable: int
    """Poses the robot cannot reach."""
    lift: int
    """Lift out of range."""
    visibility: int
    """Visibility (6.17)."""
    size: int
    """Image size (6.18)."""
    view_angle: int
    """View angle (6.19)."""
    collision: int
    """Collision (6.20); counted only for candidates good enough to need the check."""
    sole: tuple[int, int, int, int, int, int]
    """Per constraint, in the order visibility, size, view angle, collision, unreachable, lift: the
    candidates that violated only that constraint (the constraints that bind)."""


@dataclass(frozen=True, slots=True)
class Plan:
    """The result of :func:`plan_next_pose` (the fields of ``autoteach_estimate::active::planner::Plan``)."""

    best: PlannedPose
    """The best feasible pose."""
    evaluated: int
    """Candidate poses evaluated."""
    rejections: Rejections
    """Rejections per constraint."""


class ActiveState:
    """The hand-eye system in front of the simulated chamber opening, and its Kalman filter.

    The state holds the estimate (opening pose, camera mount translation, joint offsets) and the
    information matrix ``P⁻¹`` of the estimated parameters (:attr:`names`), starting from the
    nominal values with the scenario's prior.

    Args:
        sigma_px: pixel noise of the corner detections (default 0.5).
        power: the O6 power ``P`` (default 2).
        estimate: names of the estimated parameters (default: opening rotation and translation,
            camera x and y), from :data:`PARAM_NAMES`.
    """

    def __init__(
        self, sigma_px: float | None = None, power: float | None = None, estimate: Sequence[str] | None = None
    ) -> None:
        names = None if estimate is None else [str(n) for n in estimate]
        self._inner = _core.ActiveSystem(
            None if sigma_px is None else float(sigma_px), None if power is None else float(power), names
        )

    @property
    def names(self) -> list[str]:
        """Names of the estimated parameters (units in the suffix; values inside are SI)."""
        return list(self._inner.names)

    def estimate(self) -> HandEyeParams:
        """The current estimate: ``opening`` (4×4 ``T_wo``), ``camera_translation`` (3), ``joint_offsets`` (5)."""
        d = self._inner.estimate()
        return HandEyeParams(
            opening=np.asarray(d["opening"]),
            camera_translation=np.asarray(d["camera_translation"]),
            joint_offsets=np.asarray(d["joint_offsets"]),
        )

    @property
    def information(self) -> F64Array:
        """The information matrix ``P⁻¹`` (SI units)."""
        return self._inner.information()

    @information.setter
    def information(self, value: ArrayLike) -> None:
        self._inner.set_information(as_f64(value, "information"))

    @property
    def covariance(self) -> F64Array:
        """The covariance ``P`` (SI units)."""
        return self._inner.covariance()

    def indices(self, power: float | None = None) -> ObservabilityIndices:
        """Observability indices of the information matrix."""
        return ObservabilityIndices._from_core(self._inner.indices(power))

    def project(self, joints: ArrayLike) -> F64Array:
        """Corner pixels ``(m, 2)`` under the estimate at encoder readings ``joints`` (NaN = not projectable)."""
        return self._inner.project(as_f64(joints, "joints"))

    def jacobian(self, joints: ArrayLike) -> F64Array:
        """Observation matrix ``C`` of eq. (6.14), ``(2m, k)``."""
        return self._inner.jacobian(as_f64(joints, "joints"))

    def update(self, joints: ArrayLike, pixels: ArrayLike) -> UpdateSummary:
        """Kalman update (6.15) with detected corner pixels ``(m, 2)`` (NaN rows = not detected)."""
        d = self._inner.update(as_f64(joints, "joints"), as_f64(pixels, "pixels"))
        return UpdateSummary(used=int(d["used"]), iterations=int(d["iterations"]), rms_px=float(d["rms_px"]))


def plan_next_pose(
    state: ActiveState,
    candidates: ArrayLike | None = None,
    criterion: str = "D",
    method: str = "reduced",
    samples: int | None = None,
    seed: int = 0,
) -> Plan:
    """Plan the next measurement pose of the one-step greedy planner (eqs. (6.22)-(6.25)).

    Maximises the criterion (``"D"``: ``log|I + Cᵀ V^{-1/2} P V^{-1/2} C|``; ``"A"``: reduction of
    ``tr P``; ``"E"``: smallest posterior information eigenvalue) subject to visibility (6.17),
    image size (6.18), view angle (6.19) and collision (6.20). Without ``candidates`` the
    ``method`` is the reduced search (``"reduced"``: object towards an image corner, yaw line
    search, depth sampling, inverse kinematics) or plain random ``"sampling"``; with candidates
    (``(n, 5)`` encoder readings) the best feasible candidate is returned.

    Returns:
        The :class:`Plan`: the best pose (``plan.best.joints`` to command), the candidates
        evaluated and the rejections per constraint.

    Raises:
        UnreachablePoseError: no candidate is feasible; the message names the binding constraint.
    """
    if not isinstance(state, ActiveState):
        raise InvalidInputError(f"state must be an ActiveState, got {type(state).__name__}")
    c = None if candidates is None else np.ascontiguousarray(np.atleast_2d(as_f64(candidates, "candidates")))
    d = state._inner.plan(c, str(criterion), str(method), samples, int(seed))
    r = d["rejections"]
    return Plan(
        best=PlannedPose(joints=d["joints"], camera_pose=d["camera_pose"], score=float(d["score"])),
        evaluated=int(d["evaluated"]),
        rejections=Rejections(
            unreachable=int(r["unreachable"]),
            lift=int(r["lift"]),
            visibility=int(r["visibility"]),
            size=int(r["size"]),
            view_angle=int(r["view_angle"]),
            collision=int(r["collision"]),
            sole=tuple(int(v) for v in r["sole"]),  # type: ignore[arg-type]
        ),
    )


@dataclass(frozen=True, slots=True)
class TrialRuns:
    """The trials of :func:`run_trials`, with the names and power they share.

    The fields of ``autoteach_estimate::active::closed_loop::TrialResult``, stacked over the trials
    (leading axis); errors are truth − estimate in report units (mm, deg).
    """

    errors: F64Array
    """(trials, steps, 14) per step, truth − estimate of the full parameter vector (:data:`PARAM_NAMES`)."""
    indices: F64Array
    """(trials, steps, 7) per step, O1-O6 and log det of the information (report units), as
    :data:`INDEX_NAMES` (the fields of :class:`ObservabilityIndices` but ``power``)."""
    joints: F64Array
    """(trials, steps, 5) per step, the encoder readings of the measurement pose."""
    detected: F64Array
    """(trials, steps) per step, the corners detected."""
    plan_times: F64Array
    """(trials, steps − 1) per planning step, the planner's wall time (s)."""
    scores: F64Array
    """(trials, steps − 1) per planning step, the planner's score (NaN for the baseline)."""
    coupled: F64Array
    """(trials, 3) final coupled error (mm) of the opening relative to the camera (x, y, z)."""
    infeasible_steps: F64Array
    """(trials,) planning steps where no feasible pose was found."""
    names: list[str]
    """:data:`PARAM_NAMES`, the columns of :attr:`errors`."""
    estimated: list[str]
    """The estimated parameters."""
    power: float
    """The O6 power ``P``."""


def run_trials(
    trials: int = 10,
    seed: int = 0,
    mode: str = "reduced",
    steps: int | None = None,
    sigma_px: float | None = None,
    power: float | None = None,
    estimate: Sequence[str] | None = None,
) -> TrialRuns:
    """Run the simulated closed loop (Fig. 6.1) for ``trials`` trials of one ``mode``.

    ``mode`` is ``"reduced"`` (active planning, reduced search), ``"sampling"`` (active planning,
    plain sampling) or ``"baseline"`` (the straight approach without planning). The same
    ``(seed, trial)`` gives the same true parameters and start pose in every mode. Returns the
    :class:`TrialRuns`: ``errors`` (trials, steps, 14) truth − estimate in mm/deg
    (:data:`PARAM_NAMES`), ``indices`` (trials, steps, 7) O1-O6 and log det of the information in
    mm/deg units, ``joints``, ``detected``, ``plan_times`` (s), ``scores``, ``coupled``
    (trials, 3) and ``infeasible_steps``.
    """
    names = None if estimate is None else [str(n) for n in estimate]
    d = _core.active_run_trials(
        int(trials),
        int(seed),
        str(mode),
        None if steps is None else int(steps),
        None if sigma_px is None else float(sigma_px),
        None if power is None else float(power),
        names,
    )
    arrays = ("errors", "indices", "joints", "detected", "plan_times", "scores", "coupled", "infeasible_steps")
    return TrialRuns(
        **{k: np.asarray(d[k]) for k in arrays},
        names=[str(n) for n in d["names"]],
        estimated=[str(n) for n in d["estimated"]],
        power=float(d["power"]),
    )


def _final_stats(run: TrialRuns) -> dict[str, dict[str, float]]:
    """``{"std": …, "peak": …}`` of the final error of every estimated quantity over trials."""
    final = run.errors[:, -1, :]
    out: dict[str, dict[str, float]] = {}
    for name in run.estimated:
        e = final[:, PARAM_NAMES.index(name)]
        out[name] = {"std": float(np.std(e)), "peak": float(np.max(np.abs(e)))}
    for k, axis in enumerate("xyz"):
        e = run.coupled[:, k]
        out[f"coupled_{axis}_mm"] = {"std": float(np.std(e)), "peak": float(np.max(np.abs(e)))}
    return out


def _index_curves(run: TrialRuns) -> dict[str, dict[str, list[float]]]:
    ind = run.indices
    return {
        name: {"mean": np.mean(ind[:, :, k], axis=0).tolist(), "std": np.std(ind[:, :, k], axis=0).tolist()}
        for k, name in enumerate(INDEX_NAMES)
    }


def compare(
    trials: int = 10,
    seed: int = 0,
    steps: int | None = None,
    sigma_px: float | None = None,
    power: float | None = None,
) -> dict[str, Any]:
    """Table 6.4 / Fig. 6.4 on simulation: final errors with and without active planning.

    Runs :func:`run_trials` in the ``"reduced"`` and ``"baseline"`` modes on the same trials and
    returns a JSON-ready dict: ``active`` and ``baseline`` map each estimated quantity (names
    ending ``_mm``/``_deg``, plus the ``coupled_*_mm`` opening-relative-to-camera errors) to
    ``{"std", "peak"}`` of its final error over the trials; ``indices`` holds the observability
    indices per step (mean and std over trials) of both; ``worst_axis`` is the baseline's worst
    translation axis with the std ``ratio`` baseline/active there; ``planning_time_ms`` the
    median and maximum planning time per step.
    """
    active = run_trials(trials, seed, "reduced", steps, sigma_px, power)
    baseline = run_trials(trials, seed, "baseline", steps, sigma_px, power)
    a, b = _final_stats(active), _final_stats(baseline)
    translation = [n for n in active.estimated if n.endswith("_mm")]
    worst = max(translation, key=lambda n: b[n]["std"])
    times = active.plan_times.ravel() * 1e3
    return {
        "trials": int(trials),
        "seed": int(seed),
        "steps": int(active.errors.shape[1]),
        "power": float(active.power),
        "active": a,
        "baseline": b,
        "indices": {"active": _index_curves(active), "baseline": _index_curves(baseline)},
        "worst_axis": {
            "name": worst,
            "baseline_std": b[worst]["std"],
            "active_std": a[worst]["std"],
            "ratio": b[worst]["std"] / max(a[worst]["std"], 1e-300),
        },
        "planning_time_ms": {"median": float(np.median(times)), "max": float(np.max(times))},
        "infeasible_steps": {
            "active": int(np.sum(active.infeasible_steps)),
            "baseline": int(np.sum(baseline.infeasible_steps)),
        },
    }
