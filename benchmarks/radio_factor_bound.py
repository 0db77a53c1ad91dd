"""How fast can an exact MRT/MATTE solve be? Flops of the Cholesky factor under the best ordering.

Issue 33 asks for exact (direct) MRT and MATTE solves on 10 000-30 000 unknowns in <= 0.1 s. The
solver factors ``S = A_v^T A_v + lam^2 G^T G + phi^2 I`` (``docs/design/radio.md``); every training
link couples every cell it crosses, so the factor's cost is set by the fill, whatever the code. This
script measures, on the same ``S``, in one run:

- ours: ``solve(cold=True)`` (assembly, AMD analysis, numeric factor) and a repeated solve that reuses
  the analysis;
- CHOLMOD (SuiteSparse, supernodal, the strongest sparse Cholesky peer) with AMD and with METIS
  nested dissection (``nesdis``), numeric factor time, BLAS single-threaded (``OPENBLAS_NUM_THREADS=1``);
- the factor's flop count ``sum_j c_j^2`` (``c_j``: column count of ``L``, the multiply-adds of the
  rank-one updates counted as two flops) under each ordering, and the time that count takes at the
  core's theoretical peak (``--peak-gflops``; Zen 3 at 3.5 GHz x 16 double flops/cycle = 56).

A solve can be no faster than its factorisation at peak. With the campus mission's 14 400 links the
1 m MRT grid (16 000 unknowns) needs more flops than 0.1 s at peak under every ordering tried; the
seed's own regime (600-2 000 links per area) is measured by ``--links``.

CHOLMOD comes from ``scikit-sparse`` (not on a wheel for NumPy 2 here): ``apt install
libsuitesparse-dev libopenblas0-pthread`` then ``pip install --no-build-isolation
scikit-sparse==0.4.12``. Without it the CHOLMOD rows are skipped.

Usage: ``RAYON_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=python python
benchmarks/radio_factor_bound.py [--links 2000 14400]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import scipy.sparse as sp

from autoteach import radio

CASES = [("MATTE", 2.0), ("MRT", 1.6), ("MRT", 1.0)]


def timed(f, repeats: int = 3) -> float:
    """Median wall time of ``repeats`` calls."""
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def cell_block(model) -> sp.csc_matrix:
    """``S``: the normal matrix of the stacked system without the two path-loss columns."""
    amat, _ = model.stacked_system()
    av = sp.csr_matrix(amat)[:, 2:]
    return (av.T @ av).tocsc()


def cholmod_rows(s: sp.csc_matrix, peak: float) -> list[str]:
    """CHOLMOD's factor time and the factor's flops under AMD and nested dissection."""
    try:
        from sksparse.cholmod import analyze
    except ImportError:
        return ["  CHOLMOD: skipped (scikit-sparse missing; see the module docstring)"]
    out = []
    for ordering in ("amd", "nesdis"):
        an = analyze(s, mode="supernodal", ordering_method=ordering)
        t_num = timed(lambda an=an: an.cholesky(s))
        # Exact column counts from the simplicial analysis (the supernodal one pads supernodes).
        exact = analyze(s, mode="simplicial", ordering_method=ordering)
        col = np.diff(exact.cholesky(s).L().tocsc().indptr).astype(float)
        flops = float(np.sum(col * col))
        out.append(
            f"  CHOLMOD {ordering:<6} numeric {t_num * 1e3:7.1f} ms   L nnz {int(col.sum()):>9}   "
            f"flops {flops:.2e} -> {flops / peak * 1e3:6.1f} ms at peak"
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--links", type=int, nargs="+", default=[14400], help="training links (even subsample)")
    ap.add_argument("--peak-gflops", type=float, default=56.0, help="one core's theoretical double peak")
    args = ap.parse_args()
    peak = args.peak_gflops * 1e9
    sim = radio.simulate("campus", duration=240.0, seed=0)
    occ = sim.occupancy_at(float(sim.times[-1]))
    for n_links in args.links:
        idx = np.unique(np.linspace(0, len(sim.rss) - 1, min(n_links, len(sim.rss))).astype(int))
        tx, rx, rss = sim.tx[idx], sim.rx[idx], sim.rss[idx]
        for kind, cell in CASES:
            m = radio.MRT(cell=cell, bounds=(0.0, 0.0, 160.0, 100.0)) if kind == "MRT" else radio.MATTE(cell=cell)
            m.fit(tx, rx, rss, occupancy=occ)
            t_cold = timed(lambda m=m: m._need().solve(cold=True))
            t_warm = timed(lambda m=m: m._need().solve())
            s = cell_block(m)
            print(
                f"{len(idx):>6} links {kind:<5} {cell:.1f} m: {s.shape[0]:>6} unknowns, S nnz {s.nnz:>8}; "
                f"ours cold {t_cold * 1e3:7.1f} ms, analysis reused {t_warm * 1e3:7.1f} ms "
                f"(L nnz {m._need().factor_nnz})",
                flush=True,
            )
            for line in cholmod_rows(s, peak):
                print(line, flush=True)


if __name__ == "__main__":
    main()
