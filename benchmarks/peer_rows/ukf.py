"""UKF with Python models: autoteach vs filterpy on the 9-state model of issue 36.

A 3-D constant-acceleration model (position, velocity, acceleration; positions measured),
``dt = 0.01``, 2 000 steps (500 with ``quick``), the same measurements, noises and Merwe sigma
points (alpha 0.1, beta 2, kappa -6) for every filter; ``batch_filter`` on a fresh filter per
repeat. Accuracy: the largest difference of the means and covariances to filterpy's, relative to
max(1, |filterpy's|), over all steps (summation order differs, so rounding accumulates).
"""

from __future__ import annotations

import inspect

import numpy as np

from peer_rows import median_time, missing, missing_row, row

DT = 0.01


def model() -> tuple[np.ndarray, np.ndarray]:
    """F (9 × 9) and H (3 × 9) of the constant-acceleration model."""
    F = np.eye(9)  # noqa: N806
    for i in range(3):
        F[i, 3 + i] = DT
        F[i, 6 + i] = 0.5 * DT * DT
        F[3 + i, 6 + i] = DT
    H = np.zeros((3, 9))  # noqa: N806
    H[:, :3] = np.eye(3)
    return F, H


def measurements(steps: int, F: np.ndarray, H: np.ndarray, seed: int = 0) -> np.ndarray:  # noqa: N803
    """Simulated position measurements of the model."""
    rng = np.random.default_rng(seed)
    x = np.zeros(9)
    zs = np.empty((steps, 3))
    for k in range(steps):
        x = F @ x + rng.normal(size=9) * np.r_[np.full(6, 1e-4), np.full(3, 1e-2)]
        zs[k] = H @ x + rng.normal(size=3) * 0.05
    return zs


def rows(threads: int, quick: bool) -> list[dict]:
    """filterpy (per-point callbacks) vs autoteach per-point, vectorised and built-in."""
    workload = "UKF, 9 states, 2 000 steps"
    if missing("filterpy"):
        return [missing_row(workload, "filterpy UnscentedKalmanFilter", ["filterpy"])]
    import filterpy
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import MerweScaledSigmaPoints as FpPoints
    from filterpy.kalman import UnscentedKalmanFilter as FpUKF

    from autoteach import estimate as est

    steps = 500 if quick else 2000
    workload = f"UKF, 9 states, {steps} steps"
    reps = 3 if quick else 5
    F, H = model()  # noqa: N806
    zs = measurements(steps, F, H)
    FT, HT = F.T.copy(), H.T.copy()  # noqa: N806
    q = Q_discrete_white_noise(dim=3, dt=DT, var=1e-2, block_size=3, order_by_dim=False)

    def fx(x, dt):
        return F @ x

    def hx(x):
        return H @ x

    def fx_all(sigmas, dt):
        return sigmas @ FT

    def hx_all(sigmas):
        return sigmas @ HT

    def run(make):
        kf = make()
        kf.x = np.zeros(9)
        kf.P = np.eye(9)
        kf.Q = q.copy()
        kf.R = np.eye(3) * 0.05**2
        return kf.batch_filter(zs)

    def merwe(mod):
        return mod(9, 0.1, 2.0, -6.0)

    t_fp, (ref_m, ref_p) = median_time(lambda: run(lambda: FpUKF(9, 3, DT, hx=hx, fx=fx, points=merwe(FpPoints))), reps)
    ours = {
        "Python fx/hx per sigma point (filterpy form)": lambda: est.UnscentedKalmanFilter(
            9, 3, DT, hx, fx, merwe(est.MerweScaledSigmaPoints)
        ),
        "built-in LinearModel (no Python in the loop)": lambda: est.UnscentedKalmanFilter.from_model(
            est.LinearModel(F, H), merwe(est.MerweScaledSigmaPoints), dt=DT
        ),
    }
    if "vectorized" in inspect.signature(est.UnscentedKalmanFilter).parameters:
        ours["Python fx/hx vectorised (all sigma points per call)"] = lambda: est.UnscentedKalmanFilter(
            9, 3, DT, hx_all, fx_all, merwe(est.MerweScaledSigmaPoints), vectorized=True
        )
    out = []
    for name, make in ours.items():
        t, (m, p) = median_time(lambda make=make: run(make), reps * (5 if "built-in" in name else 1))
        err = max(
            float(np.abs(m - ref_m).max() / max(1.0, np.abs(ref_m).max())),
            float(np.abs(p - ref_p).max() / max(1.0, np.abs(ref_p).max())),
        )
        out.append(
            row(
                f"{workload}; ours: {name}",
                f"filterpy {filterpy.__version__} UnscentedKalmanFilter, per-point fx/hx",
                t_fp / steps,
                t / steps,
                "reference",
                f"max rel. diff {err:.0e}",
                "per step",
            )
        )
    return out
