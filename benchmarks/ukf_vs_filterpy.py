"""UKF per-step time: filterpy vs autoteach (Python callbacks) vs autoteach batch (built-in model).

A 9-state 3-D constant-acceleration model (position, velocity, acceleration; positions
measured), 2000 steps, the same measurements, noises and sigma points for every filter. The
three runs are checked to agree (to 1e-9 relative) before the timings are printed.

Run: ``python benchmarks/ukf_vs_filterpy.py [--steps 2000] [--repeats 5]``
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import MerweScaledSigmaPoints as FpPoints
from filterpy.kalman import UnscentedKalmanFilter as FpUKF

from autoteach import estimate as est

DT = 0.01


def model():
    F = np.eye(9)
    for i in range(3):
        F[i, 3 + i] = DT
        F[i, 6 + i] = 0.5 * DT * DT
        F[3 + i, 6 + i] = DT
    H = np.zeros((3, 9))
    H[:, :3] = np.eye(3)
    return F, H


def measurements(steps, F, H, seed=0):
    rng = np.random.default_rng(seed)
    x = np.zeros(9)
    zs = np.empty((steps, 3))
    for k in range(steps):
        x = F @ x + rng.normal(size=9) * np.r_[np.full(6, 1e-4), np.full(3, 1e-2)]
        zs[k] = H @ x + rng.normal(size=3) * 0.05
    return zs


def setup(kf):
    kf.x = np.zeros(9)
    kf.P = np.eye(9)
    kf.Q = Q_discrete_white_noise(dim=3, dt=DT, var=1e-2, block_size=3, order_by_dim=False)
    kf.R = np.eye(3) * 0.05**2


def run_once(make, zs):
    """Wall time of one ``batch_filter`` on a fresh filter, and its result."""
    kf = make()
    setup(kf)
    t0 = time.perf_counter()
    out = kf.batch_filter(zs)
    return time.perf_counter() - t0, out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    F, H = model()
    zs = measurements(args.steps, F, H)
    lin = est.LinearModel(F, H)
    alpha, beta, kappa = 0.1, 2.0, -6.0

    def fx(x, dt):
        return F @ x

    def hx(x):
        return H @ x

    runs = {
        "filterpy (Python callbacks)": (
            lambda: FpUKF(9, 3, DT, hx=hx, fx=fx, points=FpPoints(9, alpha, beta, kappa)),
            1,
        ),
        "autoteach, Python callbacks": (
            lambda: est.UnscentedKalmanFilter(9, 3, DT, hx, fx, est.MerweScaledSigmaPoints(9, alpha, beta, kappa)),
            1,
        ),
        "autoteach batch, built-in LinearModel": (
            lambda: est.UnscentedKalmanFilter.from_model(lin, est.MerweScaledSigmaPoints(9, alpha, beta, kappa), dt=DT),
            15,
        ),
        "autoteach batch, built-in, square-root": (
            lambda: est.UnscentedKalmanFilter.from_model(
                lin, est.MerweScaledSigmaPoints(9, 1.0, 2.0, 0.0), dt=DT, square_root=True
            ),
            15,
        ),
    }
    # Interleaved rounds (each round runs every filter; the fast ones several times), so that a
    # change of machine load affects all filters alike; medians over rounds.
    times = {name: [] for name in runs}
    results = {}
    for _ in range(args.repeats):
        for name, (make, reps) in runs.items():
            for _ in range(reps):
                t, results[name] = run_once(make, zs)
                times[name].append(t)
    results = {name: (statistics.median(times[name]), results[name]) for name in runs}

    ref_means, ref_covs = results["filterpy (Python callbacks)"][1]
    for name in ("autoteach, Python callbacks", "autoteach batch, built-in LinearModel"):
        means, covs = results[name][1]
        err_m = np.abs(means - ref_means).max() / max(1.0, np.abs(ref_means).max())
        err_p = np.abs(covs - ref_covs).max() / max(1.0, np.abs(ref_covs).max())
        assert err_m < 1e-9 and err_p < 1e-9, (name, err_m, err_p)
        print(f"{name}: max relative difference to filterpy: means {err_m:.1e}, covariances {err_p:.1e}")

    base = results["filterpy (Python callbacks)"][0]
    print(f"\n9-state UKF, {args.steps} steps, median of {args.repeats} interleaved rounds")
    print(f"{'filter':<42}{'per step (us)':>15}{'speed-up vs filterpy':>24}")
    for name, (t, _) in results.items():
        print(f"{name:<42}{t / args.steps * 1e6:>15.2f}{base / t:>23.1f}x")


if __name__ == "__main__":
    main()
