"""UKF per-step time: filterpy vs autoteach (Python callbacks) vs autoteach batch (built-in model).

A 9-state 3-D constant-acceleration model (position, velocity, acceleration; positions
measured), 2000 steps, the same measurements, noises and sigma points for every filter. The
three runs are checked to agree (to 1e-9 relative) before the timings are printed.

Second table (issue 37): the other sigma-point families (Julier, simplex) per step, and the
unscented RTS smoother of the filtered run (filterpy's ``rts_smoother`` with Python ``fx`` vs
autoteach's in Rust on the built-in model, and with Python callbacks), checked to agree first.

Run: ``python benchmarks/ukf_vs_filterpy.py [--steps 2000] [--repeats 5]``
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import JulierSigmaPoints as FpJulier
from filterpy.kalman import MerweScaledSigmaPoints as FpPoints
from filterpy.kalman import SimplexSigmaPoints as FpSimplex
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
    families_and_smoother(zs, lin, fx, hx, args)


def _timed(f):
    t0 = time.perf_counter()
    out = f()
    return time.perf_counter() - t0, out


def _rel(a, b):
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / max(1.0, float(np.abs(b).max())))


def families_and_smoother(zs, lin, fx, hx, args):
    """Julier and simplex per step (filterpy vs built-in batch), and the RTS smoother of each run."""
    steps = len(zs)
    rows = []
    for name, fp_pts, at_pts in [
        (
            "Merwe (0.1, 2, -6)",
            lambda: FpPoints(9, 0.1, 2.0, -6.0),
            lambda: est.MerweScaledSigmaPoints(9, 0.1, 2.0, -6.0),
        ),
        ("Julier (kappa 0)", lambda: FpJulier(9, 0.0), lambda: est.JulierSigmaPoints(9, 0.0)),
        ("simplex", lambda: FpSimplex(9), lambda: est.SimplexSigmaPoints(9)),
    ]:
        times = {"fp_filter": [], "at_filter": [], "fp_rts": [], "at_rts": [], "at_rts_cb": []}
        for _ in range(args.repeats):
            t, (m_fp, c_fp) = run_once(lambda: FpUKF(9, 3, DT, hx=hx, fx=fx, points=fp_pts()), zs)  # noqa: B023
            times["fp_filter"].append(t)
            at = est.UnscentedKalmanFilter.from_model(lin, at_pts(), dt=DT)
            setup(at)
            cb = est.UnscentedKalmanFilter(9, 3, DT, hx, fx, at_pts())
            setup(cb)
            fp = FpUKF(9, 3, DT, hx=hx, fx=fx, points=fp_pts())
            setup(fp)
            for _ in range(10):
                setup(at)
                t, (m_at, c_at) = _timed(lambda: at.batch_filter(zs))  # noqa: B023
                times["at_filter"].append(t)
            t, s_fp = _timed(lambda: fp.rts_smoother(m_fp, c_fp))  # noqa: B023
            times["fp_rts"].append(t)
            for _ in range(10):
                t, s_at = _timed(lambda: at.rts_smoother(m_fp, c_fp))  # noqa: B023
                times["at_rts"].append(t)
            t, s_cb = _timed(lambda: cb.rts_smoother(m_fp, c_fp))  # noqa: B023
            times["at_rts_cb"].append(t)
        err_f = max(_rel(m_at, m_fp), _rel(c_at, c_fp))
        err_s = max(_rel(a, b) for s in (s_at, s_cb) for a, b in zip(s, s_fp, strict=True))
        assert err_f < 1e-9 and err_s < 1e-9, (name, err_f, err_s)
        med = {k: statistics.median(v) for k, v in times.items()}
        rows.append((name, med, err_f, err_s))
    print(f"\nSigma-point families and the RTS smoother, 9 states, {steps} epochs, medians")
    head = f"{'points':<20}{'filter us/step fp / ours':>28}{'ratio':>8}{'RTS ms fp / ours (batch)':>28}{'ratio':>8}"
    print(head + f"{'RTS ms ours (callbacks)':>26}{'ratio':>8}{'max rel diff':>14}")
    for name, med, err_f, err_s in rows:
        f_fp, f_at = med["fp_filter"] / steps * 1e6, med["at_filter"] / steps * 1e6
        r_fp, r_at, r_cb = med["fp_rts"] * 1e3, med["at_rts"] * 1e3, med["at_rts_cb"] * 1e3
        print(
            f"{name:<20}{f_fp:>14.1f} / {f_at:<11.2f}{f_fp / f_at:>7.0f}x{r_fp:>15.1f} / {r_at:<10.2f}"
            f"{r_fp / r_at:>7.0f}x{r_cb:>26.1f}{r_fp / r_cb:>7.1f}x{max(err_f, err_s):>14.1e}"
        )


if __name__ == "__main__":
    main()
