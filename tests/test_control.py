"""Joint controller tuning (issue 31): parity with python-control, fitting accuracy, ZOH simulation, tuning."""

from __future__ import annotations

import math

import numpy as np
import pytest

control = pytest.importorskip("control")

from autoteach.control import (  # noqa: E402
    PlantReport,
    TransferFunction,
    TuneResult,
    TuneSpec,
    bandwidth,
    baseline,
    closed_loop_damping,
    demo,
    evaluate,
    fit_frequency_response,
    joint_plants,
    margins,
    sine_sweep,
    table_2_3,
    tune,
)
from autoteach.errors import InvalidInputError  # noqa: E402


def _random_stable(rng: np.random.Generator, order: int) -> np.ndarray:
    roots: list[complex] = []
    while len(roots) < order:
        if order - len(roots) >= 2 and rng.random() < 0.6:
            wn = 10 ** rng.uniform(-0.5, 1.7)
            z = rng.uniform(0.05, 0.9)
            roots += [complex(-z * wn, wn * math.sqrt(1 - z * z)), complex(-z * wn, -wn * math.sqrt(1 - z * z))]
        else:
            roots.append(complex(-(10 ** rng.uniform(-0.5, 1.7)), 0))
    return np.real(np.poly(roots))


def _pairs(n: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        pd = _random_stable(rng, int(rng.integers(2, 5)))
        pn = _random_stable(rng, int(rng.integers(0, 2))) * pd[-1] * 10 ** rng.uniform(-0.5, 1.5)
        # Lead-lag or PI-like controller with a stable (or integrating) denominator.
        z, p = 10 ** rng.uniform(-0.5, 1.5, size=2)
        k = 10 ** rng.uniform(-1, 1)
        cn = np.array([k, k * z])
        cd = np.array([1.0, p]) if rng.random() < 0.7 else np.array([1.0, 0.0])
        out.append((pn, pd, cn, cd))
    return out


PAIRS = _pairs(200)


def _close(a: float, b: float, tol: float = 1e-6) -> bool:
    if math.isinf(a) or math.isinf(b) or math.isnan(a) or math.isnan(b):
        return (math.isinf(a) and math.isinf(b)) or (math.isnan(a) and math.isnan(b))
    return abs(a - b) <= tol * max(1.0, abs(b))


def test_margins_equal_python_control_on_200_random_pairs() -> None:
    mismatches = []
    for i, (pn, pd, cn, cd) in enumerate(PAIRS):
        ours = margins(TransferFunction(pn, pd), TransferFunction(cn, cd))
        theirs = control.margin(control.tf(pn, pd) * control.tf(cn, cd))
        got = (ours.gain_margin, ours.phase_margin_deg, ours.w_phase_crossover, ours.w_gain_crossover)
        if not all(_close(a, float(b)) for a, b in zip(got, theirs, strict=True)):
            mismatches.append((i, got, theirs))
    assert not mismatches, mismatches[:3]


def test_bandwidth_and_frequency_response_equal_python_control() -> None:
    w = np.logspace(-2, 3, 50)
    checked = 0
    for pn, pd, cn, cd in PAIRS:
        loop = TransferFunction(pn, pd) * TransferFunction(cn, cd)
        t = loop.feedback(1.0)
        ct = control.feedback(control.tf(pn, pd) * control.tf(cn, cd), 1)
        resp = control.frequency_response(ct, w)
        theirs = np.asarray(resp.magnitude) * np.exp(1j * np.asarray(resp.phase))
        ours = t.frequency_response(w)
        assert np.allclose(ours, theirs, rtol=1e-6, atol=1e-12)
        if not t.is_stable():
            continue
        ours_bw, theirs_bw = bandwidth(t), float(control.bandwidth(ct))
        if math.isinf(theirs_bw) and math.isfinite(ours_bw):
            # python-control scans its default frequency range only and reports inf when the
            # -3 dB point lies beyond it; check ours against the definition instead.
            dc = abs(t.frequency_response(np.array([0.0]))[0])
            edge = abs(t.frequency_response(np.array([ours_bw]))[0])
            assert edge == pytest.approx(dc * 10 ** (-3 / 20), rel=1e-6)
            below = np.abs(t.frequency_response(np.geomspace(1e-3, ours_bw, 2000)[:-1]))
            assert np.all(below > dc * 10 ** (-3 / 20) * (1 - 1e-9))
            continue
        assert _close(ours_bw, theirs_bw, 1e-6)
        checked += 1
    assert checked >= 100


def test_closed_loop_damping_equals_python_control_poles() -> None:
    for pn, pd, cn, cd in PAIRS[:30]:
        ours = closed_loop_damping(TransferFunction(pn, pd), TransferFunction(cn, cd))
        wn, zeta, _ = control.damp(control.feedback(control.tf(pn, pd) * control.tf(cn, cd), 1), doprint=False)
        assert ours == pytest.approx(float(np.min(zeta)), abs=1e-6)


def test_zoh_simulation_matches_closed_form() -> None:
    wn, z, dt = 40.0, 0.2, 1e-3
    g = TransferFunction([wn * wn], [1, 2 * z * wn, wn * wn])
    y = g.lsim(np.ones(400), dt)
    t = np.arange(400) * dt
    wd = wn * math.sqrt(1 - z * z)
    exact = 1 - np.exp(-z * wn * t) * (np.cos(wd * t) + z * wn / wd * np.sin(wd * t))
    np.testing.assert_allclose(y, exact, atol=1e-10)
    # Ramp through a pole at the origin: y = t - 1/a (1 - e^{-a t}) for 1/(s (s + a)) a.
    a = 5.0
    y = TransferFunction([a], [1, a, 0]).lsim(np.ones(300), dt)
    t = np.arange(300) * dt
    np.testing.assert_allclose(y, t - (1 - np.exp(-a * t)) / a, atol=1e-10)


def _resonances(g: TransferFunction, w_max: float) -> np.ndarray:
    p = g.poles()
    p = p[(p.imag > 0) & (np.abs(p) < w_max)]
    zeta = -p.real / np.abs(p)
    return np.sort(np.abs(p[zeta < 0.3]))


@pytest.mark.parametrize("joint", ["JT2", "JT4"])
def test_fit_recovers_resonances_at_one_percent_noise(joint: str) -> None:
    w = 2 * np.pi * np.logspace(0, math.log10(500), 300)
    for k, plant in enumerate(joint_plants(joint)):
        truth = plant.motor
        h = sine_sweep(truth, w, 0.01, seed=k)
        fit = fit_frequency_response(w, h, 4, 7, integrators=1)
        assert fit.model.is_stable() or np.all(fit.model.poles().real <= 0)
        assert fit.residual < 0.03
        r_true = _resonances(truth, w[-1])
        r_fit = _resonances(fit.model, w[-1] * 1.2)
        assert len(r_true) >= 2
        for r in r_true:
            assert np.min(np.abs(r_fit - r) / r) < 0.01, (joint, k, r, r_fit)
            fine = np.linspace(0.9 * r, 1.1 * r, 2001)
            peak_true = 20 * np.log10(np.abs(truth.frequency_response(fine)).max())
            peak_fit = 20 * np.log10(np.abs(fit.model.frequency_response(fine)).max())
            assert abs(peak_true - peak_fit) < 0.5, (joint, k, r, peak_true, peak_fit)


def test_bad_frequency_data_is_rejected() -> None:
    h = np.ones(20, dtype=complex)
    w = np.linspace(1, 20, 20)
    with pytest.raises(InvalidInputError, match="increasing"):
        fit_frequency_response(w[::-1], h, 1, 2)
    bad = w.copy()
    bad[3] = np.nan
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        fit_frequency_response(bad, h, 1, 2)
    with pytest.raises(InvalidInputError):
        fit_frequency_response(w, h[:5], 1, 2)


def _spec(**kw: float) -> TuneSpec:
    wr = 2 * np.pi * 25
    base = dict(
        grid=2 * np.pi * np.logspace(math.log10(0.5), math.log10(500), 400),
        sd_bandwidth=40.0,
        target=(60.0, 180.0, 360.0),
        gain_band=(1.2 * wr, 3 * wr),
        rolloff_freq=3 * wr,
        damping_max_freq=2 * wr,
        max_iterations=25,
    )
    base.update(kw)
    return TuneSpec(**base)  # type: ignore[arg-type]


def test_unstable_or_improper_plants_are_rejected() -> None:
    spec = _spec()
    with pytest.raises(InvalidInputError, match="improper"):
        tune([TransferFunction([1, 0, 0], [1, 1])], spec)
    with pytest.raises(InvalidInputError, match="unstable"):
        tune([TransferFunction([1], [1, -1, 4])], spec)
    with pytest.raises(InvalidInputError, match="improper"):
        TransferFunction([1, 0, 0], [1, 1]).lsim(np.ones(3), 0.1)


def test_tune_report_is_honest_on_jt2() -> None:
    plants = [p.motor for p in joint_plants("JT2")]
    res = tune(plants, _spec())
    assert type(res) is TuneResult and all(type(r) is PlantReport for r in res.plants)
    # Success only with no unmet constraint; each unmet constraint is named with its plant.
    assert res.success == (not res.unmet)
    assert all("(plant " in u for u in res.unmet), res.unmet
    # Recheck the reported phase margins independently (polynomial method): an unmet phase
    # margin must be one the polynomial method also sees below 50°.
    for i, (p, rep) in enumerate(zip(plants, res.plants, strict=True)):
        m = margins(p, res.controller)
        if any(u.startswith("phase margin") and f"(plant {i}:" in u for u in res.unmet):
            assert min(m.phase_margin_deg, rep.worst_phase_margin_deg) < 50


# Measured: every constraint met on all six JT2 plants; crossover 1.60 -> 15.5 rad/s (9.7x).
def test_tuned_controller_meets_constraints_and_beats_baseline() -> None:
    plants = [p.motor for p in joint_plants("JT2")]
    spec = _spec()
    base = baseline(plants, spec)
    # Measured: the classical rule keeps the margins but not the damping floor on JT2 (closed-loop
    # damping 0.078-0.098 < 0.1); the report must say so and name only that constraint.
    assert base.success == (not base.unmet)
    assert all(u.startswith("closed-loop damping") for u in base.unmet), base.unmet
    res = tune(plants, spec)
    # Success is claimed only with no unmet constraint; the margins of every loop are then
    # recomputed independently by the polynomial method.
    assert res.success == (not res.unmet)
    assert res.success, res.unmet
    # The report is re-checked independently: margins of every loop from the polynomial method.
    for p, rep in zip(plants, res.plants, strict=True):
        m = margins(p, res.controller)
        assert abs(m.gain_margin_db) >= 12 - 1e-3 or math.isinf(m.gain_margin)
        assert m.phase_margin_deg >= 50 - 1e-3
        assert rep.crossover > 0
    x_base = min(p.crossover for p in base.plants)
    x_tuned = min(p.crossover for p in res.plants)
    assert x_tuned > 1.5 * x_base


def test_infeasible_spec_names_the_constraint() -> None:
    plants = [p.motor for p in joint_plants("JT4")][:2]
    spec = _spec(min_phase_margin_deg=89.0, min_gain_margin_db=60.0, max_iterations=5)
    res = tune(plants, spec)
    assert not res.success
    assert any("margin" in u for u in res.unmet)
    again = evaluate(plants, spec, res.sections, res.theta)
    assert again.unmet == res.unmet


def test_demo_tables_bandwidth_rises_and_vibration_falls() -> None:
    # The simulated experiment end to end (sweeps, fits, baseline, tuning on the fits, report on
    # the true plants). Measured: crossover 0.26 -> 0.89 Hz (JT2), 0.89 -> 3.65 Hz (JT4); RMS hand
    # acceleration lower on both axes, total and vibration.
    result = demo()
    rows = {(r["joint"], r["controller"]): r for r in table_2_3(result)}
    for joint in ("JT2", "JT4"):
        base, tuned = rows[(joint, "baseline")], rows[(joint, "tuned")]
        assert math.isfinite(base["crossover_hz"]) and base["crossover_hz"] > 0
        assert tuned["crossover_hz"] >= 2 * base["crossover_hz"], (base, tuned)
        for r in (base, tuned):
            assert r["success"] == (not r["unmet"])
        # The baseline keeps both margins (it is detuned for them); its damping is the plant's own.
        assert base["phase_margin_deg"] >= 50 - 1e-3 and base["gain_margin_db"] >= 12 - 1e-3
    v = result["vibration"]
    for key in ("total", "vibration"):
        assert all(t < b for t, b in zip(v["tuned"][key], v["baseline"][key], strict=True)), v
