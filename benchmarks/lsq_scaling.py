"""Scaling of the least-squares solver on chain-like SE(3) pose graphs (time vs size).

Graphs of N poses: odometry edges i-1 → i and a "loop" edge i-5 → i every 10 poses (noise
0.01 rad / 0.02 m), initial values by composing the noisy odometry, a prior on pose 0. The
sizes are N, 10 N and 100 N (default N = 100). Reports solver wall time (Rust, GIL released),
iterations, time per iteration and per pose; near-linear scaling shows as a flat time per
pose-iteration.

Run: ``python benchmarks/lsq_scaling.py [--base 100]``
"""

from __future__ import annotations

import argparse

import numpy as np

from autoteach.estimate import LeastSquaresProblem


def _exp(xi: np.ndarray) -> np.ndarray:
    """SE(3) exponential of ξ = [ω; ρ] as a 4×4 matrix."""
    w, rho = xi[:3], xi[3:]
    th = np.linalg.norm(w)
    W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-9:
        R, V = np.eye(3) + W, np.eye(3) + 0.5 * W
    else:
        R = np.eye(3) + np.sin(th) / th * W + (1 - np.cos(th)) / th**2 * W @ W
        V = np.eye(3) + (1 - np.cos(th)) / th**2 * W + (th - np.sin(th)) / th**3 * W @ W
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, V @ rho
    return T


def build(n: int, seed: int = 0) -> LeastSquaresProblem:
    """The chain-like pose graph of n poses."""
    rng = np.random.default_rng(seed)
    truth = [_exp(np.array([0, 0, 0.05 * i, 0.5 * i, 0, 0.01 * i])) for i in range(n)]
    sig = np.array([0.01] * 3 + [0.02] * 3)
    cov = np.diag(sig**2)
    edges = [(i - 1, i) for i in range(1, n)] + [(i - 5, i) for i in range(10, n, 10)]
    meas = {e: np.linalg.inv(truth[e[0]]) @ truth[e[1]] @ _exp(sig * rng.standard_normal(6)) for e in edges}
    init = [truth[0]]
    for i in range(1, n):
        init.append(init[-1] @ meas[(i - 1, i)])
    p = LeastSquaresProblem()
    ids = [p.add_pose(T) for T in init]
    for a, b in edges:
        p.add_relative_pose(ids[a], ids[b], meas[(a, b)], cov)
    p.add_prior(ids[0], truth[0], cov * 0.01)
    return p


def main() -> None:
    """Solve the three sizes and print a table."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--base", type=int, default=100)
    args = ap.parse_args()
    print(
        f"{'poses':>8} {'unknowns':>9} {'residuals':>9} {'iters':>5} {'solver':>15} {'time s':>8} {'µs/pose/iter':>12}"
    )
    for n in (args.base, 10 * args.base, 100 * args.base):
        s = build(n).solve()
        per = s.time_s / n / max(s.iterations, 1) * 1e6
        print(
            f"{n:>8} {s.num_parameters:>9} {s.num_residuals:>9} {s.iterations:>5} "
            f"{s.linear_solver:>15} {s.time_s:>8.3f} {per:>12.2f}  ({s.termination})"
        )


if __name__ == "__main__":
    main()
