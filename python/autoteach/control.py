"""Joint controller tuning for hand stabilisation (seed 000_3b1454b2b2194811.txt ch. 2.5, issue 31).

- :class:`TransferFunction` -- continuous-time SISO model (``num``/``den`` or :meth:`~TransferFunction.zpk`),
  frequency response, series/parallel/feedback connection, poles and zeros, closed-loop poles and an
  exact zero-order-hold simulation (:meth:`~TransferFunction.lsim`).
- :func:`fit_frequency_response` -- a transfer function from frequency-response data (Sanathanan-Koerner
  iteration + Levenberg-Marquardt, stable poles enforced, residual reported), the seed's ``tfest`` step.
- :func:`margins`, :func:`bandwidth`, :func:`sensitivity_peak`, :func:`closed_loop_damping` -- loop analysis
  (Table 2.3), equal to python-control's ``margin``/``bandwidth`` on the same loops.
- :func:`tune` -- fixed-structure multi-model H-infinity tuning of a filter + PID over all plants (eq. 2.19)
  from a loop-shaping initial design (eq. 2.18); :class:`TuneSpec` holds the objective and constraints.
- :func:`baseline` -- the classical hand-tuned comparison (second-order low-pass + PID).
- :func:`demo` -- the whole simulated experiment (Tables 2.3-2.4, Fig. 2.15) for ``autoteach tune --demo``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError

F64Array = NDArray[np.float64]


class TransferFunction:
    """A continuous-time SISO transfer function ``num(s) / den(s)`` (descending powers, monic den)."""

    def __init__(self, num: ArrayLike, den: ArrayLike) -> None:
        """Build from numerator and denominator coefficients (descending powers of ``s``)."""
        coefficients = {"num": as_f64(num, "num"), "den": as_f64(den, "den")}
        for name, c in coefficients.items():
            if c.size == 0:
                raise InvalidInputError(f"{name} must hold at least one coefficient, got shape {c.shape}")
        n, d = _core.control_tf_normalize(*(np.atleast_1d(c).ravel() for c in coefficients.values()))
        self.num: F64Array = n
        self.den: F64Array = d

    @classmethod
    def zpk(cls, zeros: ArrayLike, poles: ArrayLike, gain: float) -> TransferFunction:
        """``gain * prod(s - z) / prod(s - p)``; complex roots must come in conjugate pairs."""
        z = np.atleast_1d(np.asarray(zeros, dtype=complex))
        p = np.atleast_1d(np.asarray(poles, dtype=complex))
        for name, r in (("zeros", z), ("poles", p)):
            if not np.all(np.isfinite(r)):
                raise InvalidInputError(f"{name} must be finite")
            if np.abs(np.sort_complex(r) - np.sort_complex(r.conj())).max(initial=0.0) > 1e-9 * (
                1 + np.abs(r).max(initial=0.0)
            ):
                raise InvalidInputError(f"complex {name} must come in conjugate pairs")
        g = as_float(gain, "gain")
        return cls(g * np.real(np.poly(z)) if z.size else [g], np.real(np.poly(p)) if p.size else [1.0])

    def __repr__(self) -> str:
        """Coefficients."""
        return f"TransferFunction(num={self.num.tolist()}, den={self.den.tolist()})"

    def __call__(self, s: complex) -> complex:
        """``G(s)`` at a complex point."""
        return complex(np.polyval(self.num, s) / np.polyval(self.den, s))

    def frequency_response(self, omega: ArrayLike) -> NDArray[np.complex128]:
        """``G(j omega)`` at angular frequencies ``omega`` (rad/s)."""
        re, im = _core.control_freq_resp(self.num, self.den, np.atleast_1d(as_f64(omega, "omega")))
        return re + 1j * im

    def poles(self) -> NDArray[np.complex128]:
        """Roots of the denominator."""
        re, im = _core.control_roots(self.den)
        return re + 1j * im

    def zeros(self) -> NDArray[np.complex128]:
        """Roots of the numerator."""
        if not np.any(self.num):
            return np.zeros(0, dtype=complex)
        re, im = _core.control_roots(self.num)
        return re + 1j * im

    def is_stable(self) -> bool:
        """Every pole in the open left half plane."""
        return bool(np.all(self.poles().real < 0))

    def is_proper(self) -> bool:
        """Numerator degree at most the denominator's."""
        return len(np.trim_zeros(self.num, "f")) <= len(self.den)

    def __mul__(self, other: TransferFunction | float) -> TransferFunction:
        """Series connection."""
        o = other if isinstance(other, TransferFunction) else TransferFunction([as_float(other, "gain")], [1.0])
        return TransferFunction(*_core.control_series(self.num, self.den, o.num, o.den))

    __rmul__ = __mul__

    def __add__(self, other: TransferFunction | float) -> TransferFunction:
        """Parallel connection."""
        o = other if isinstance(other, TransferFunction) else TransferFunction([as_float(other, "gain")], [1.0])
        return TransferFunction(*_core.control_parallel(self.num, self.den, o.num, o.den))

    def feedback(self, other: TransferFunction | float = 1.0) -> TransferFunction:
        """Negative feedback ``self / (1 + self * other)``."""
        o = other if isinstance(other, TransferFunction) else TransferFunction([as_float(other, "gain")], [1.0])
        return TransferFunction(*_core.control_feedback(self.num, self.den, o.num, o.den))

    def closed_loop_poles(self) -> NDArray[np.complex128]:
        """Poles of the unity negative-feedback loop around ``self``."""
        return self.feedback(1.0).poles()

    def lsim(self, u: ArrayLike, dt: float) -> F64Array:
        """Response (zero initial state) to samples ``u`` held over each ``dt`` (exact ZOH)."""
        return _core.control_lsim(self.num, self.den, np.atleast_1d(as_f64(u, "u")), as_float(dt, "dt"))


@dataclass(frozen=True, slots=True)
class Margins:
    """Classical stability margins of a loop (python-control's ``margin`` values)."""

    gain_margin: float
    """Gain margin as a factor (inf if none)."""
    phase_margin_deg: float
    """Phase margin in degrees (inf if none)."""
    w_phase_crossover: float
    """Frequency (rad/s) of the gain margin."""
    w_gain_crossover: float
    """Frequency (rad/s) of the phase margin (the crossover of Table 2.3)."""

    @property
    def gain_margin_db(self) -> float:
        """Gain margin in dB."""
        return float(20 * np.log10(self.gain_margin))


def _loop(plant: TransferFunction, controller: TransferFunction | None) -> TransferFunction:
    if not isinstance(plant, TransferFunction):
        raise InvalidInputError(f"plant must be a TransferFunction, got {type(plant).__name__}")
    return plant if controller is None else plant * controller


def margins(plant: TransferFunction, controller: TransferFunction | None = None) -> Margins:
    """Gain and phase margins of the loop ``plant * controller`` (or of ``plant`` alone)."""
    return Margins(*_core.control_margins(*_tf_pair(_loop(plant, controller))))


def _tf_pair(g: TransferFunction) -> tuple[F64Array, F64Array]:
    return g.num, g.den


def bandwidth(system: TransferFunction, dbdrop: float = -3.0) -> float:
    """First frequency (rad/s) where the gain drops ``dbdrop`` dB below DC (python-control's ``bandwidth``)."""
    return float(_core.control_bandwidth(system.num, system.den, as_float(dbdrop, "dbdrop")))


def sensitivity_peak(plant: TransferFunction, controller: TransferFunction | None = None) -> tuple[float, float]:
    """``(max |S|, frequency)`` of the loop's sensitivity ``1/(1+L)``."""
    return _core.control_sensitivity_peak(*_tf_pair(_loop(plant, controller)))


def closed_loop_damping(plant: TransferFunction, controller: TransferFunction | None = None) -> float:
    """Smallest damping ratio of the closed-loop poles."""
    return float(_core.control_closed_loop_damping(*_tf_pair(_loop(plant, controller))))


@dataclass(frozen=True, slots=True)
class FitResult:
    """A fitted model and its relative weighted residual (Rust ``control::FitResult``)."""

    model: TransferFunction
    residual: float
    """Relative weighted residual ``||w (H_fit - H)|| / ||w H||``."""
    reflected_poles: int
    """Unstable poles reflected into the left half plane."""


def fit_frequency_response(
    omega: ArrayLike,
    response: ArrayLike,
    num_order: int,
    den_order: int,
    *,
    integrators: int = 0,
    weights: ArrayLike | None = None,
    enforce_stable: bool = True,
) -> FitResult:
    """Fit ``N(s) / (D(s) s^integrators)`` to complex ``response`` at increasing ``omega`` (rad/s).

    ``num_order``/``den_order`` are the degrees of ``N`` and ``D``; ``weights`` default to ``1/|H|``
    (relative error). Unstable poles are reflected into the left half plane unless ``enforce_stable`` is
    false. Raises :class:`~autoteach.errors.InvalidInputError` for NaN, unsorted or non-positive
    frequencies, mismatched lengths or too few points.
    """
    h = np.atleast_1d(np.asarray(response))
    if h.dtype.kind not in "iufc":
        raise InvalidInputError(f"response must be complex numbers, got dtype {h.dtype}")
    h = h.astype(np.complex128)
    w = np.atleast_1d(as_f64(omega, "omega"))
    wt = None if weights is None else np.atleast_1d(as_f64(weights, "weights"))
    num, den, res, refl = _core.control_fit(
        w,
        np.ascontiguousarray(h.real),
        np.ascontiguousarray(h.imag),
        as_int(num_order, "num_order"),
        as_int(den_order, "den_order"),
        integrators=as_int(integrators, "integrators"),
        weights=wt,
        enforce_stable=bool(enforce_stable),
    )
    return FitResult(TransferFunction(num, den), float(res), int(refl))


@dataclass
class TuneSpec:
    """Objective and constraints of the tuning (eq. 2.19); frequencies in rad/s.

    The desired sensitivity is ``S_d(s) = (s + sd_low*sd_bandwidth) / (s/sd_peak + sd_bandwidth)``; the
    loop-shaping target of eq. 2.18 is ``target = (w_c, w_1, w_2)``.
    """

    grid: F64Array
    sd_bandwidth: float
    target: tuple[float, float, float]
    gain_band: tuple[float, float]
    rolloff_freq: float
    damping_max_freq: float
    sd_peak: float = 2.0
    sd_low: float = 1e-3
    min_gain_margin_db: float = 12.0
    min_phase_margin_deg: float = 50.0
    min_damping: float = 0.1
    max_loop_gain: float = 0.5
    max_iterations: int = 60

    def as_dict(self) -> dict[str, Any]:
        """The dict the compiled module reads."""
        return {
            "grid": np.atleast_1d(as_f64(self.grid, "grid")),
            "sd_bandwidth": as_float(self.sd_bandwidth, "sd_bandwidth"),
            "sd_peak": as_float(self.sd_peak, "sd_peak"),
            "sd_low": as_float(self.sd_low, "sd_low"),
            "min_gain_margin_db": as_float(self.min_gain_margin_db, "min_gain_margin_db"),
            "min_phase_margin_deg": as_float(self.min_phase_margin_deg, "min_phase_margin_deg"),
            "min_damping": as_float(self.min_damping, "min_damping"),
            "damping_max_freq": as_float(self.damping_max_freq, "damping_max_freq"),
            "max_loop_gain": as_float(self.max_loop_gain, "max_loop_gain"),
            "gain_band": tuple(as_float(v, "gain_band") for v in self.gain_band),
            "rolloff_freq": as_float(self.rolloff_freq, "rolloff_freq"),
            "target": tuple(as_float(v, "target") for v in self.target),
            "max_iterations": float(as_int(self.max_iterations, "max_iterations")),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TuneSpec:
        """Inverse of :meth:`as_dict`."""
        keys = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        keys["max_iterations"] = int(keys.get("max_iterations", 60))
        keys["gain_band"] = tuple(keys["gain_band"])
        keys["target"] = tuple(keys["target"])
        return cls(**keys)


@dataclass(frozen=True, slots=True)
class PlantReport:
    """Analysis of one plant under a controller (Rust ``control::PlantReport``); frequencies in rad/s."""

    gain_margin_db: float
    """Gain margin (dB), python-control's ``margin`` convention."""
    phase_margin_deg: float
    """Phase margin (degrees), python-control's ``margin`` convention."""
    worst_gain_margin_db: float
    """Smallest gain margin (dB) over every phase crossover."""
    worst_phase_margin_deg: float
    """Smallest phase margin (degrees) over every gain crossover."""
    crossover: float
    """Gain-crossover frequency of the reported phase margin ("bandwidth" of Table 2.3)."""
    bandwidth: float
    """Closed-loop -3 dB bandwidth of ``T = L/(1+L)``."""
    sensitivity_peak: float
    """``max |S|``."""
    weighted_peak: float
    """Peak of ``|W S|`` (below 1: ``|S| < |S_d|``)."""
    damping: float
    """Smallest closed-loop damping below ``damping_max_freq``."""
    damping_all: float
    """Smallest closed-loop damping ratio of all poles."""
    band_gain_ratio: float
    """Largest ``|L|`` on ``gain_band`` relative to ``max_loop_gain`` (≤ 1 met)."""
    rolloff_ratio: float
    """Largest ``|L(jw)| / (M (w2/w)^2)`` for ``w ≥ rolloff_freq`` (≤ 1 met)."""


@dataclass(frozen=True, slots=True)
class TuneResult:
    """A tuned (or evaluated) controller and its report (Rust ``control::TuneReport``).

    ``sections`` is Python-only: Rust returns the ``ControllerStructure`` beside the report; it is what
    ``theta`` parameterises.
    """

    controller: TransferFunction
    sections: list[str]
    theta: F64Array
    success: bool
    """True only if every constraint holds on every plant."""
    unmet: list[str]
    """Each unmet constraint, named with plant and value."""
    objective: float
    """``max_i ||W S_i||_inf``; below 1 means ``|S_i| < |S_d|`` for every plant."""
    iterations: int
    plants: list[PlantReport] = field(default_factory=list)

    @classmethod
    def _from_core(cls, r: dict[str, Any]) -> TuneResult:
        return cls(
            controller=TransferFunction(*r["controller"]),
            sections=list(r["sections"]),
            theta=r["theta"],
            success=bool(r["success"]),
            unmet=list(r["unmet"]),
            objective=float(r["objective"]),
            iterations=int(r["iterations"]),
            plants=[PlantReport(**{k: float(v) for k, v in p.items()}) for p in r["plants"]],
        )


@dataclass(frozen=True, slots=True)
class JointPlant:
    """A simulated joint plant at one pose (Rust ``control::JointPlant``)."""

    motor: TransferFunction
    """Motor torque (N m) to joint angle at the motor encoder (rad): the model the controller sees."""
    link: TransferFunction
    """Motor torque (N m) to link (hand-side) joint angle (rad)."""
    link_inertia: float
    """Link inertia about the joint axis (kg m², joint side)."""
    pose: F64Array
    """The pose (joint angles)."""


def _plants_arg(plants: Sequence[TransferFunction]) -> list[tuple[F64Array, F64Array]]:
    out = []
    for i, p in enumerate(plants):
        if not isinstance(p, TransferFunction):
            raise InvalidInputError(f"plants[{i}] must be a TransferFunction, got {type(p).__name__}")
        out.append((p.num, p.den))
    if not out:
        raise InvalidInputError("plants must not be empty")
    return out


def _sections_arg(sections: Sequence[str]) -> list[str]:
    if isinstance(sections, str):
        raise InvalidInputError("sections must be a sequence of 'notch'/'lowpass', not a string")
    return [str(s) for s in sections]


def tune(
    plants: Sequence[TransferFunction],
    spec: TuneSpec,
    sections: Sequence[str] = ("notch", "lowpass"),
    theta0: ArrayLike | None = None,
) -> TuneResult:
    """Tune a filter (``sections``: ``"notch"``/``"lowpass"``, 2nd order each) + PID over all ``plants``.

    Minimises ``max_i ||W S_i||_inf`` subject to the spec's margins, damping and loop-gain bounds (eq. 2.19);
    starts from the loop-shaping design of eq. 2.18 unless ``theta0`` is given. ``result.success`` is true
    only if every constraint holds; otherwise ``result.unmet`` names each failing constraint.
    """
    t0 = None if theta0 is None else np.atleast_1d(as_f64(theta0, "theta0"))
    r = _core.control_tune(_plants_arg(plants), _sections_arg(sections), spec.as_dict(), t0)
    return TuneResult._from_core(r)


def evaluate(
    plants: Sequence[TransferFunction], spec: TuneSpec, sections: Sequence[str], theta: ArrayLike
) -> TuneResult:
    """Report of a given controller (``sections``, ``theta``) against ``spec`` on ``plants``."""
    r = _core.control_evaluate(
        _plants_arg(plants), _sections_arg(sections), np.atleast_1d(as_f64(theta, "theta")), spec.as_dict()
    )
    return TuneResult._from_core(r)


def baseline(plants: Sequence[TransferFunction], spec: TuneSpec) -> TuneResult:
    """Classical hand-tuned baseline: second-order low-pass + PID placed by a rigid-body rule, detuned to the spec."""
    return TuneResult._from_core(_core.control_baseline(_plants_arg(plants), spec.as_dict()))


def joint_plants(joint: str, count: int = 6) -> list[JointPlant]:
    """The simulated plants of ``"JT2"`` or ``"JT4"`` at ``count`` sweep poses (``motor``/``link`` models)."""
    return [
        JointPlant(
            motor=TransferFunction(*p["motor"]),
            link=TransferFunction(*p["link"]),
            link_inertia=float(p["link_inertia"]),
            pose=p["pose"],
        )
        for p in _core.control_joint_plants(str(joint), as_int(count, "count"))
    ]


def sine_sweep(plant: TransferFunction, omega: ArrayLike, noise: float, seed: int = 0) -> NDArray[np.complex128]:
    """Stepped-sine measurement of ``plant`` with relative complex noise of RMS ``noise``."""
    re, im = _core.control_sine_sweep(
        plant.num, plant.den, np.atleast_1d(as_f64(omega, "omega")), as_float(noise, "noise"), as_int(seed, "seed")
    )
    return re + 1j * im


def demo(noise: float = 0.01, seed: int = 0, sections: Sequence[str] = ("notch", "lowpass")) -> dict[str, Any]:
    """The simulated experiment of ch. 2.5 (raw dict: per joint plants, sweeps, fits, baseline, tuned; vibration)."""
    return _core.control_demo(as_float(noise, "noise"), as_int(seed, "seed"), _sections_arg(sections))


def table_2_3(result: dict[str, Any]) -> list[dict[str, Any]]:
    """Rows of Table 2.3 (worst case over the plants: lowest crossover and margins, filter order)."""
    rows = []
    for joint in ("JT2", "JT4"):
        for name in ("baseline", "tuned"):
            r = result[joint][name]
            ps = r["plants"]
            rows.append(
                {
                    "joint": joint,
                    "controller": name,
                    "crossover_hz": min(p["crossover"] for p in ps) / (2 * np.pi),
                    "bandwidth_hz": min(p["bandwidth"] for p in ps) / (2 * np.pi),
                    "phase_margin_deg": min(p["worst_phase_margin_deg"] for p in ps),
                    "gain_margin_db": min(p["worst_gain_margin_db"] for p in ps),
                    "damping": min(p["damping"] for p in ps),
                    "filter_order": 2 * len(r["sections"]),
                    "success": bool(r["success"]),
                    "unmet": list(r["unmet"]),
                }
            )
    return rows


def plot_sensitivities(result: dict[str, Any], joint: str, path: str) -> None:
    """Bode magnitudes of every ``S_i`` (baseline and tuned) against ``S_d`` (Fig. 2.15) to ``path``."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'autoteach[plot]'") from err
    r = result[joint]
    spec = TuneSpec.from_dict(r["spec"])
    w = np.asarray(spec.grid)
    s = 1j * w
    sd = (s + spec.sd_low * spec.sd_bandwidth) / (s / spec.sd_peak + spec.sd_bandwidth)
    fig, ax = plt.subplots(figsize=(7, 4))
    for name, style in (("baseline", ":"), ("tuned", "-")):
        c = TransferFunction(*r[name]["controller"])
        for i, p in enumerate(r["plants"]):
            pl = TransferFunction(*p["motor"])
            ls = 1 / (1 + pl.frequency_response(w) * c.frequency_response(w))
            ax.semilogx(w / (2 * np.pi), 20 * np.log10(np.abs(ls)), style, lw=1, label=name if i == 0 else None)
    ax.semilogx(w / (2 * np.pi), 20 * np.log10(np.abs(sd)), "k--", lw=2, label="S_d")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("|S| (dB)")
    ax.set_title(f"{joint}: sensitivities of all plants vs S_d (Fig. 2.15)")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


__all__ = [
    "FitResult",
    "JointPlant",
    "Margins",
    "PlantReport",
    "TransferFunction",
    "TuneResult",
    "TuneSpec",
    "bandwidth",
    "baseline",
    "closed_loop_damping",
    "demo",
    "evaluate",
    "fit_frequency_response",
    "joint_plants",
    "margins",
    "plot_sensitivities",
    "sensitivity_peak",
    "sine_sweep",
    "table_2_3",
    "tune",
]
