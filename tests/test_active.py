"""Tests of autoteach.active: design criteria, the hand-eye Kalman filter, the planner and the loop.

Truth: NumPy's SVD/eigen/slogdet on identical matrices (observability indices, information
gain), closed-form D-optimal designs of polynomial regression (General Equivalence Theorem),
brute-force enumeration (DETMAX), the information recursion (6.15) recomputed from the returned
Jacobian, and the simulator's ground truth in the closed loop (Table 6.4 / Fig. 6.4).
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from autoteach import active
from autoteach.cli import main
from autoteach.errors import DegenerateGeometryError, InvalidInputError, UnreachablePoseError

SEED = 20261122


def _numpy_indices(m: np.ndarray, power: float) -> dict[str, float]:
    s = np.linalg.svd(m, compute_uv=False)
    return {
        "O1": float(np.prod(s) ** (1.0 / len(s))),
        "O2": float(s[-1] / s[0]),
        "O3": float(s[-1]),
        "O4": float(s[-1] ** 2 / s[0]),
        "O5": float(1.0 / np.sum(1.0 / s)),
        "O6": float(1.0 / np.sum(s**-power)),
    }


# --- indices and information -----------------------------------------------------------------


@pytest.mark.parametrize("power", [0.5, 1.0, 2.0, 3.5])
def test_indices_match_numpy_svd(power: float) -> None:
    rng = np.random.default_rng(SEED)
    for _ in range(20):
        a = rng.normal(size=(12, 6)) * rng.uniform(0.1, 10.0, size=6)
        m = a.T @ a
        got = active.observability_indices(m, power=power)
        want = _numpy_indices(m, power)
        for k, v in want.items():
            assert getattr(got, k.lower()) == pytest.approx(v, rel=1e-9), k
        assert got.log_det == pytest.approx(np.linalg.slogdet(m)[1], rel=1e-10)
        assert got.power == power


def test_indices_closed_form_and_singular_limits() -> None:
    o = active.observability_indices(np.diag([16.0, 4.0, 1.0]), power=2.0)
    assert o.o1 == pytest.approx(4.0)
    assert (o.o2, o.o3, o.o4) == pytest.approx((1 / 16, 1.0, 1 / 16))
    assert o.o5 == pytest.approx(1 / (1 / 16 + 1 / 4 + 1))
    assert o.o6 == pytest.approx(1 / (1 / 256 + 1 / 16 + 1))
    z = active.observability_indices(np.diag([3.0, 0.0]))
    assert z.o1 == z.o3 == z.o5 == z.o6 == 0.0
    assert z.log_det == -math.inf


def test_fisher_information_is_eq_6_6() -> None:
    rng = np.random.default_rng(SEED + 1)
    js = [rng.normal(size=(2, 4)) for _ in range(5)]
    sig = rng.uniform(0.2, 2.0, 5)
    w = rng.uniform(0.0, 1.0, 5)
    m = active.fisher_information(js, sig, w)
    want = sum(wi / si**2 * j.T @ j for j, si, wi in zip(js, sig, w, strict=True))
    np.testing.assert_allclose(m, want, rtol=1e-12, atol=1e-14)
    # Scalar observations given as gradients.
    g = active.fisher_information([[1.0, 2.0]], [0.5])
    np.testing.assert_allclose(g, 4.0 * np.outer([1.0, 2.0], [1.0, 2.0]))


# --- General Equivalence Theorem and DETMAX ---------------------------------------------------


def _poly(xs: np.ndarray, deg: int) -> list[np.ndarray]:
    return [np.array([[x**k for k in range(deg + 1)]]) for x in xs]


def test_d_optimal_quadratic_design_and_equivalence_theorem() -> None:
    xs = np.linspace(-1.0, 1.0, 41)
    f = _poly(xs, 2)
    d = active.d_optimal_design(f, tol=1e-7)
    # Kiefer–Wolfowitz: max_x f(x)ᵀ M⁻¹ f(x) = p = 3 at the optimum.
    assert d.max_variance == pytest.approx(3.0, rel=1e-6)
    support = np.isclose(np.abs(xs), 1.0) | np.isclose(xs, 0.0)
    np.testing.assert_allclose(d.weights[support], 1 / 3, atol=1e-3)
    assert np.all(d.weights[~support] < 1e-3)
    # The exact optimum satisfies φ ≥ 0 everywhere and φ = 0 on its support (Theorem 6.2.1).
    exact = np.where(support, 1 / 3, 0.0)
    phi = active.directional_derivatives(f, exact)
    assert np.all(phi >= -1e-10)
    np.testing.assert_allclose(phi[support], 0.0, atol=1e-10)
    # Independent check of φ with NumPy.
    m = sum(w * fi.T @ fi for w, fi in zip(exact, f, strict=True))
    want = [3.0 - (fi @ np.linalg.solve(m, fi.T)).item() for fi in f]
    np.testing.assert_allclose(phi, want, atol=1e-10)


def test_d_optimal_cubic_design_closed_form() -> None:
    # Cubic regression on [-1, 1]: weights 1/4 at ±1 and ±1/√5.
    r = 1 / math.sqrt(5)
    xs = np.unique(np.concatenate([np.linspace(-1, 1, 21), [-r, r]]))
    d = active.d_optimal_design(_poly(xs, 3), tol=1e-7)
    for x0 in (-1.0, -r, r, 1.0):
        assert d.weights[np.argmin(np.abs(xs - x0))] == pytest.approx(0.25, abs=2e-3)
    assert d.max_variance == pytest.approx(4.0, rel=1e-6)


def test_detmax_matches_brute_force() -> None:
    rng = np.random.default_rng(SEED + 2)
    for trial in range(5):
        f = [rng.normal(size=(2, 3)) for _ in range(10)]
        prior = 0.1 * np.eye(3)
        r = active.detmax(f, 3, prior=prior, seed=trial)
        best = max(
            np.linalg.slogdet(prior + sum(f[i].T @ f[i] for i in sel))[1]
            for sel in itertools.combinations(range(10), 3)
        )
        assert r.log_det == pytest.approx(best, rel=1e-9)
        assert len(r.selected) == 3


def test_design_bad_inputs() -> None:
    with pytest.raises(InvalidInputError):
        active.observability_indices(np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(InvalidInputError):
        active.observability_indices(np.array([[1.0, np.nan], [np.nan, 1.0]]))
    with pytest.raises(InvalidInputError):
        active.observability_indices(np.eye(2), power=-1.0)
    with pytest.raises(InvalidInputError):
        active.observability_indices(np.diag([1.0, -1.0]))
    with pytest.raises(DegenerateGeometryError, match="singular"):
        active.d_optimal_design([[1.0, 0.0], [2.0, 0.0]])
    with pytest.raises(InvalidInputError):
        active.detmax([[1.0]] * 3, 4)
    with pytest.raises(InvalidInputError):
        active.fisher_information([[1.0, 2.0]], [0.0])


# --- hand-eye state and planner ---------------------------------------------------------------


def _start() -> tuple[active.ActiveState, np.ndarray]:
    state = active.ActiveState()
    plan = active.plan_next_pose(state)
    return state, plan.best.joints


def test_update_follows_the_information_recursion() -> None:
    state, q = _start()
    info0 = state.information
    px = state.project(q)
    rng = np.random.default_rng(SEED + 3)
    summary = state.update(q, px + rng.normal(0.0, 0.5, px.shape))
    assert summary.used == 4
    c = state.jacobian(q)  # at the updated estimate
    sigma = 0.5  # the default pixel noise
    np.testing.assert_allclose(state.information, info0 + c.T @ c / sigma**2, rtol=1e-9, atol=1e-6)
    cov = state.covariance
    np.testing.assert_allclose(cov, np.linalg.inv(state.information), rtol=1e-6, atol=1e-9 * np.abs(cov).max())
    # Undetected corners (NaN rows) are skipped.
    px2 = state.project(q)
    px2[:2] = np.nan
    assert state.update(q, px2).used == 2


def test_planned_pose_is_feasible_and_its_gain_is_the_log_det_ratio() -> None:
    state, _ = _start()
    plan = active.plan_next_pose(state, criterion="D")
    px = state.project(plan.best.joints)
    assert np.all(np.isfinite(px))
    assert np.all(px >= 20.0) and np.all(px[:, 0] <= 1279 - 20.0) and np.all(px[:, 1] <= 959 - 20.0)
    size = max(np.ptp(px[:, 0]), np.ptp(px[:, 1]))
    assert 300.0 <= size <= 2000.0
    f = state.jacobian(plan.best.joints) / 0.5
    p = state.covariance
    want = np.linalg.slogdet(np.eye(f.shape[0]) + f @ p @ f.T)[1]
    assert plan.best.score == pytest.approx(want, rel=1e-8)
    assert plan.evaluated > 100


def test_candidate_selection_picks_the_best_feasible_candidate() -> None:
    state, _ = _start()
    reduced = active.plan_next_pose(state).best.joints
    sampled = active.plan_next_pose(state, method="sampling", samples=300, seed=3).best.joints
    far = reduced.copy()
    far[4] = 5.0  # lift out of range: infeasible
    cands = np.stack([sampled, reduced, far])
    plan = active.plan_next_pose(state, candidates=cands)
    p = state.covariance
    scores = []
    for q in (sampled, reduced):
        f = state.jacobian(q) / 0.5
        scores.append(np.linalg.slogdet(np.eye(f.shape[0]) + f @ p @ f.T)[1])
    np.testing.assert_allclose(plan.best.joints, cands[int(np.argmax(scores))])
    assert plan.rejections.lift + plan.rejections.visibility == 1
    # A and E criteria score the same candidates differently but still pick a feasible one.
    for crit in ("A", "E"):
        other = active.plan_next_pose(state, candidates=cands, criterion=crit)
        assert any(np.array_equal(other.best.joints, c) for c in cands[:2])


def test_planner_bad_inputs_name_the_binding_constraint() -> None:
    state, q = _start()
    away = q.copy()
    away[3] += math.pi  # camera turned away from the opening
    with pytest.raises(UnreachablePoseError, match=r"binding constraint: visibility \(6.17\)"):
        active.plan_next_pose(state, candidates=np.stack([away, away]))
    close = q.copy()
    close[4] = 3.0  # 3 m lift: out of range and the opening far below the image
    with pytest.raises(UnreachablePoseError, match="lift range: 0"):
        active.plan_next_pose(state, candidates=close)
    with pytest.raises(InvalidInputError, match="criterion"):
        active.plan_next_pose(state, criterion="Z")
    with pytest.raises(InvalidInputError):
        active.plan_next_pose(state, candidates=np.full((1, 5), np.nan))
    with pytest.raises(InvalidInputError):
        active.plan_next_pose(state, candidates=np.zeros((2, 4)))
    with pytest.raises(DegenerateGeometryError, match="singular"):
        state.information = np.zeros((8, 8))
    with pytest.raises(InvalidInputError):
        state.update(q, np.zeros((3, 2)))
    with pytest.raises(InvalidInputError):
        active.ActiveState(estimate=["nope"])
    with pytest.raises(InvalidInputError):
        active.plan_next_pose("state")  # type: ignore[arg-type]


# --- closed loop (Table 6.4 / Fig. 6.4) -------------------------------------------------------


def test_closed_loop_is_deterministic() -> None:
    a = active.run_trials(2, seed=5, mode="reduced", steps=4)
    b = active.run_trials(2, seed=5, mode="reduced", steps=4)
    np.testing.assert_array_equal(a.errors, b.errors)
    c = active.run_trials(2, seed=5, mode="baseline", steps=4)
    # Same truth and start pose: identical first step.
    np.testing.assert_array_equal(a.errors[:, 0], c.errors[:, 0])
    with pytest.raises(InvalidInputError):
        active.run_trials(1, mode="nope")


def test_table_6_4_reproduction_meets_the_goal() -> None:
    r = active.compare(trials=10, seed=0)
    assert r["worst_axis"]["ratio"] >= 10.0
    for name, s in r["active"].items():
        assert s["std"] <= 1.05 * r["baseline"][name]["std"], name
    # Fig. 6.4: the information (O1) of the planned trajectory is higher at every step after the
    # first and grows monotonically.
    o1a = np.array(r["indices"]["active"]["O1"]["mean"])
    o1b = np.array(r["indices"]["baseline"]["O1"]["mean"])
    assert np.all(o1a[1:] > o1b[1:])
    assert np.all(np.diff(r["indices"]["active"]["log_det"]["mean"]) >= 0.0)
    assert r["planning_time_ms"]["median"] < 100.0


def test_cli_json() -> None:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["active", "--trials", "2", "--steps", "4", "--seed", "3", "--json"]) == 0
    r = json.loads(out.getvalue())
    for mode in ("active", "baseline"):
        assert r[mode]
        for name, s in r[mode].items():
            assert name.endswith(("_mm", "_deg"))
            assert set(s) == {"std", "peak"}
            assert 0.0 <= s["std"] <= s["peak"] + 1e-12
        assert len(r["indices"][mode]["O1"]["mean"]) == 4
    with pytest.raises(SystemExit) as exc:
        main(["active", "--trials", "0"])
    assert exc.value.code == 2
