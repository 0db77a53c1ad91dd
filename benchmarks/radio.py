"""Radio signal-strength prediction (issue 33, seed 004 ch. 3): accuracy and speed, one run.

1. Accuracy: replay of the three simulated environments (office: indoor-heavy, campus: outdoor-heavy,
   mixed) in 2 s steps (section 3.3), RMSE per horizon for LogFit, MRGP, MRT and MATTE at 4 dB shadowing;
   with ``--tune``, MRT's and MATTE's parameters are first compass-searched on training missions (seed §3.3).
2. MRGP on 6 000 training links: fit time, and scikit-learn's ``GaussianProcessRegressor`` (dense
   Cholesky; the same kernel as a vectorised NumPy callable, fixed hyper-parameters, ``optimizer=None``)
   on the same data; predictions compared.
3. MRT and MATTE solves from 10 000 to 90 000 unknowns (300 x 300 MRT grid) beside scipy
   ``spsolve`` (SuperLU, COLAMD) and ``cg`` (rtol 1e-10) on the same normal equations; ours cold (symbolic
   analysis included) and with the cached analysis of the previous solve (as in an incremental update).

Usage: ``PYTHONPATH=python python benchmarks/radio.py [--stride 2] [--quick] [--only accuracy]``
(``RAYON_NUM_THREADS=1``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
from scipy.sparse import linalg as splinalg
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import Kernel

from autoteach import radio, radio_tuning


class SkLinkKernel(Kernel):
    """The swap-average link kernel (kernel.rs) in NumPy, for scikit-learn.

    The taper length is ``taper_theta``: an argument named ``theta`` would shadow scikit-learn's
    ``Kernel.theta`` property (log hyper-parameters from ``get_params()``) and recurse without end.
    """

    def __init__(self, length_scale=28.75, sigma_f=1.0, taper_theta=20.0, gamma=3.0):
        self.length_scale = length_scale
        self.sigma_f = sigma_f
        self.taper_theta = taper_theta
        self.gamma = gamma

    def __call__(self, X, Y=None, eval_gradient=False):
        Y = X if Y is None else Y

        def dist(a, b):
            return np.sqrt(np.maximum(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1), 0.0))

        def taper(s):
            return np.clip(1 - s / self.taper_theta, 0, None) ** self.gamma

        l2 = self.length_scale**2
        a, b = dist(X[:, 2:], Y[:, 2:]), dist(X[:, :2], Y[:, :2])
        k = np.exp(-(a + b) / l2) * taper(a) * taper(b)
        del a, b
        a, b = dist(X[:, 2:], Y[:, :2]), dist(X[:, :2], Y[:, 2:])
        k += np.exp(-(a + b) / l2) * taper(a) * taper(b)
        return 0.5 * self.sigma_f**2 * k

    def diag(self, X):
        d = np.linalg.norm(X[:, :2] - X[:, 2:], axis=1)
        t = np.clip(1 - d / self.taper_theta, 0, None) ** self.gamma
        return 0.5 * self.sigma_f**2 * (1 + np.exp(-2 * d / self.length_scale**2) * t * t)

    def is_stationary(self):
        return False


def timed(f, repeats=3):
    ts, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def accuracy(stride: int, duration: float, tune: bool) -> dict:
    t0 = time.perf_counter()
    if tune:  # the seed's protocol (§3.3): MRT's and MATTE's parameters by compass search on training missions
        r = radio_tuning.compare_tuned(radio.ENVIRONMENTS, duration=duration, seed=0, sigma=4.0, stride=stride)
    else:
        r = radio.compare(radio.ENVIRONMENTS, duration=duration, seed=0, sigma=4.0, stride=stride)
    r["seconds"] = time.perf_counter() - t0
    print(f"\n== accuracy: RMSE (dB) at 4 dB shadowing, {duration:g} s missions, every {stride}. 2 s step ==")
    print(f"{'env':<8}{'model':<8}{'0-6 s':>7}{'10-20 s':>9}{'fit ms':>8}   per bin 0-2 ... 18-20 s")
    for env, row in r["results"].items():
        for m, v in row["models"].items():
            bins = " ".join(f"{x:.1f}" for x in v["rmse"])
            print(f"{env:<8}{m:<8}{v['near_term']:>7.2f}{v['far']:>9.2f}{1e3 * v['fit_seconds']:>8.0f}   {bins}")
        print(f"        ranking MATTE < MRT < MRGP < LogFit: {row['ranking_ok']}")
        for m, p in r.get("tuned", {}).get(env, {}).items():
            rmse, evals = p["training_rmse"], p["evaluations"]
            print(f"        {m} tuned: {p['params']} (training RMSE {rmse:.2f} dB, {evals} evaluations)")
    return r


def mrgp_vs_sklearn(n: int) -> dict:
    sim = radio.simulate("campus", duration=240.0, seed=0)
    idx = np.linspace(0, len(sim.rss) - 1, n).round().astype(int)
    tx, rx, rss = sim.tx[idx], sim.rx[idx], sim.rss[idx]
    test = np.setdiff1d(np.arange(len(sim.rss)), idx)[::20]
    params = {"length_scale": 28.75, "sigma_f": 1.0, "theta": 20.0, "gamma": 3.0}
    t_ours, gp = timed(lambda: radio.MRGP(**params).fit(tx, rx, rss))
    mean = gp.predict(sim.tx[test], sim.rx[test])
    t_opt, gpo = timed(lambda: radio.MRGP(optimize=True, **params).fit(tx, rx, rss), repeats=1)
    lf = radio.LogFit().fit(tx, rx, rss)
    resid = rss - lf.predict(tx, rx)
    sk_kernel = SkLinkKernel(params["length_scale"], params["sigma_f"], params["theta"], params["gamma"])
    sk = GaussianProcessRegressor(kernel=sk_kernel, alpha=1.5**2, optimizer=None, normalize_y=False)
    t_sk, _ = timed(lambda: sk.fit(np.hstack([tx, rx]), resid), repeats=1)
    sk_mean = sk.predict(np.hstack([sim.tx[test], sim.rx[test]])) + lf.predict(sim.tx[test], sim.rx[test])
    diff = float(np.abs(mean - sk_mean).max())
    out = {
        "links": n,
        "ours_fit_s": t_ours,
        "ours_optimize_fit_s": t_opt,
        "optimized_params": gpo.params,
        "nnz": gp.nnz,
        "sklearn_fit_s": t_sk,
        "max_abs_prediction_difference": diff,
    }
    print(f"\n== MRGP on {n} links (campus) ==")
    print(f"ours fit {t_ours:.3f} s (K nnz {gp.nnz[0]}, L nnz {gp.nnz[1]}); with ML search {t_opt:.2f} s")
    print(f"sklearn GaussianProcessRegressor fit {t_sk:.2f} s; ratio {t_sk / t_ours:.1f}x; max |diff| {diff:.2e} dB")
    return out


def solves(quick: bool, cg_maxiter: int = 20000, spsolve_max: int = 20000, model: str | None = None) -> list[dict]:
    sim = radio.simulate("campus", duration=240.0, seed=0)
    occ = sim.occupancy_at(float(sim.times[-1]))
    rows = []
    cases = [("MRT", 1.6), ("MRT", 0.9155), ("MRT", 160 / 300), ("MATTE", 2.0), ("MATTE", 1.27)]
    if quick:
        cases = cases[:1] + cases[3:4]
    if model is not None:
        cases = [c for c in cases if c[0] == model]
    for kind, cell in cases:
        if kind == "MRT":
            m = radio.MRT(cell=cell, bounds=(0.0, 0.0, 160.0, 160.0 if cell < 0.6 else 100.0))
        else:
            m = radio.MATTE(cell=cell)
        m.fit(sim.tx, sim.rx, sim.rss, occupancy=occ)
        t_cold, _ = timed(lambda m=m: m._need().solve(cold=True))
        t_ours, _ = timed(lambda m=m: m._need().solve())
        sol = m.solution()
        l0, a, vals = sol.l0, sol.exponent, sol.values
        ours = np.concatenate([[l0, -a], vals.ravel()])
        amat, rhs = m.stacked_system()
        normal = (amat.T @ amat).tocsc()
        b = amat.T @ rhs
        n = normal.shape[0]
        row = {
            "model": kind,
            "cell": cell,
            "unknowns": n,
            "ours_cold_s": t_cold,
            "ours_s": t_ours,
            "factor_nnz": m._need().factor_nnz,
        }
        t0 = time.perf_counter()
        x_cg, info = splinalg.cg(normal, b, rtol=1e-10, maxiter=cg_maxiter)
        row["cg_s"] = time.perf_counter() - t0
        row["cg_info"] = int(info)
        row["cg_rel_diff"] = float(np.linalg.norm(x_cg - ours) / np.linalg.norm(ours))
        if n <= spsolve_max:
            t0 = time.perf_counter()
            x_sp = splinalg.spsolve(normal, b)
            row["spsolve_s"] = time.perf_counter() - t0
            row["spsolve_rel_diff"] = float(np.linalg.norm(x_sp - ours) / np.linalg.norm(ours))
        rows.append(row)
        sp = f"spsolve {row['spsolve_s']:.2f} s (rel diff {row['spsolve_rel_diff']:.1e})" if "spsolve_s" in row else ""
        print(
            f"{kind:<6} cell {cell:.3f} m: {n:>6} unknowns  ours cold {t_cold * 1e3:7.1f} ms, "
            f"analysis reused {t_ours * 1e3:7.1f} ms (L nnz {row['factor_nnz']})  "
            f"cg {row['cg_s']:.2f} s (rel diff {row['cg_rel_diff']:.1e})  {sp}"
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--stride", type=int, default=2)
    ap.add_argument("--duration", type=float, default=240.0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", type=str, default=None)
    ap.add_argument("--tune", action="store_true", help="accuracy with MRT/MATTE tuned on training missions (sec. 3.3)")
    ap.add_argument(
        "--only", action="append", choices=["solves", "mrgp", "accuracy"], help="run only these parts (repeatable)"
    )
    ap.add_argument("--cg-maxiter", type=int, default=20000, help="iteration cap of scipy's cg")
    ap.add_argument("--model", choices=["MRT", "MATTE"], default=None, help="solves of this model only")
    ap.add_argument("--spsolve-max", type=int, default=20000, help="largest system given to scipy's spsolve")
    args = ap.parse_args()
    parts = set(args.only or ["solves", "mrgp", "accuracy"])
    out = {"solves": [], "mrgp": None, "accuracy": None}
    if "solves" in parts:
        print("== tomographic solves (campus mission, 14 400 links) ==")
        out["solves"] = solves(args.quick, args.cg_maxiter, args.spsolve_max, args.model)
    if "mrgp" in parts:
        out["mrgp"] = mrgp_vs_sklearn(2000 if args.quick else 6000)
    if "accuracy" in parts:
        out["accuracy"] = accuracy(args.stride, args.duration, args.tune)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1, default=float)


if __name__ == "__main__":
    main()
