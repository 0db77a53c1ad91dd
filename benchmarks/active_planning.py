"""Measurement-pose planning (seed 000_3b1454b2b2194811.txt ch. 6): reduced search vs peers.

One planning step on the chamber-opening scene after one centred measurement, maximising the
D-optimal gain ``log|I + F P Fᵀ|`` (eq. (6.22)) under the constraints (6.17)-(6.20):

- autoteach reduced search (object towards an image corner, yaw line search, depth sampling, IK);
- autoteach plain random sampling of camera poses (2000 and 20000 samples);
- scipy's differential evolution (a genetic optimiser, the sampling-based family of Table 6.3)
  over the joints ``(θ1, θ2, θ4, h)`` with the same objective (infeasible = no gain), scored
  through autoteach's candidate evaluation.

Then the closed loop of Fig. 6.1 (``--trials`` trials): final-error std of the baseline's worst
axis with the reduced search, with plain sampling and without planning, and the planning time per
step. Every planner's pose is re-scored by NumPy (slogdet on the returned Jacobian) as a check.

Run: ``python benchmarks/active_planning.py [--trials 10] [--repeats 5]``
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.optimize import differential_evolution

from autoteach import active
from autoteach.errors import UnreachablePoseError


def numpy_gain(state: active.ActiveState, q: np.ndarray) -> float:
    """The D gain of joints ``q`` recomputed with NumPy from the observation matrix."""
    f = state.jacobian(q) / 0.5
    return float(np.linalg.slogdet(np.eye(f.shape[0]) + f @ state.covariance @ f.T)[1])


def fresh_state() -> active.ActiveState:
    """The nominal state after one noise-free measurement at the reduced planner's first pose."""
    state = active.ActiveState()
    q0 = active.plan_next_pose(state).best.joints
    state.update(q0, state.project(q0))
    return state


def timed(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    state = fresh_state()
    rows = []
    t, plan = timed(lambda: active.plan_next_pose(state), args.repeats)
    rows.append(("autoteach reduced search", t, plan.best.score, numpy_gain(state, plan.best.joints), plan.evaluated))
    for n in (2000, 20000):
        t, plan = timed(lambda n=n: active.plan_next_pose(state, method="sampling", samples=n, seed=1), args.repeats)
        gain = numpy_gain(state, plan.best.joints)
        rows.append((f"autoteach sampling {n}", t, plan.best.score, gain, plan.evaluated))

    evals = 0

    def objective(x: np.ndarray) -> float:
        nonlocal evals
        evals += 1
        q = np.array([x[0], x[1], x[2], x[2], x[3]])
        try:
            return -active.plan_next_pose(state, candidates=q[None, :]).best.score
        except UnreachablePoseError:
            return 0.0

    bounds = [(-np.pi, np.pi), (-np.pi, np.pi), (-np.pi, np.pi), (0.0, 0.4)]
    t0 = time.perf_counter()
    res = differential_evolution(objective, bounds, seed=1, maxiter=60, popsize=15, tol=0.0, polish=False)
    t_de = time.perf_counter() - t0
    q_de = np.array([res.x[0], res.x[1], res.x[2], res.x[2], res.x[3]])
    de_gain = -res.fun
    rows.append(("scipy differential_evolution", t_de, de_gain, numpy_gain(state, q_de) if de_gain > 0 else 0.0, evals))

    print("one planning step (D gain log|I + F P F^T|, higher is better)")
    print(f"{'planner':<32}{'time [ms]':>12}{'gain':>10}{'numpy gain':>12}{'evaluated':>11}")
    for name, t, g, gn, n in rows:
        print(f"{name:<32}{t * 1e3:>12.2f}{g:>10.3f}{gn:>12.3f}{n:>11}")

    print(f"\nclosed loop, {args.trials} trials x 12 steps (seed 0): final error std [mm] / planning time")
    runs = {mode: active.run_trials(args.trials, 0, mode) for mode in ("reduced", "sampling", "baseline")}
    names = runs["reduced"].estimated
    idx = [active.PARAM_NAMES.index(n) for n in names]
    print(f"{'quantity':<16}" + "".join(f"{m:>12}" for m in runs))
    for n, i in zip(names, idx, strict=True):
        print(f"{n:<16}" + "".join(f"{np.std(r.errors[:, -1, i]):>12.4f}" for r in runs.values()))
    for mode, r in runs.items():
        ms = r.plan_times.ravel() * 1e3
        print(f"planning time {mode:<9}: median {np.median(ms):.2f} ms, max {np.max(ms):.2f} ms")


if __name__ == "__main__":
    main()
