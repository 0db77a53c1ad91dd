"""Global registration over wide scene families (issue 29; seed 000_3b1454b2b2194811.txt §3.4).

Scenes from :mod:`autoteach.sim.registration_scenes` (an independent generator: random
polylines, letters, chevrons with a tail; 3-D point sets and object outlines; rotations over the
whole circle / sphere; clutter 0–300 %; one or two partial 0.9-scaled distractors; density
mismatch as in Fig. 3.12; 20 % cut away; and issue 29's own case). Success: RMS of the
registered template to its true placement below 2 % of the shape size.

Columns (identical inputs per trial):

- ``cpd``: plain rigid CPD (w = 0.5) from the template's own pose;
- ``gcpd-y`` / ``gcpd-pairs``: the original global-CPD (``global_cpd``, k = 3, least
  deformation energy first) with Y-count / pair-count voting;
- ``reg-lik`` / ``reg-expl`` / ``reg-energy``: ``global_register`` (suppressed voting
  hypotheses, each refined by rigid CPD) choosing by CPD likelihood with the outlier term, by
  the fraction of template points explained, or by non-rigid deformation energy;
  ``reg-expl-pairs``: the same with pair-count voting;
- peers (``--peers``): probreg FilterReg and GMMTree (2-D sets get a zero z column), and in 3-D
  Open3D FPFH + RANSAC (+ ICP), each in its documented strongest configuration.

Run: ``PYTHONPATH=python python benchmarks/registration_families.py --trials 100 [--peers]``.
Timings are wall-clock medians per trial on a shared machine (noisy).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from autoteach.errors import AutoteachError
from autoteach.registration import cpd_rigid, global_cpd
from autoteach.sim.registration_scenes import FAMILIES_2D, FAMILIES_3D, SETTINGS, make_scene, rms

try:
    from autoteach.global_registration import global_register
except ImportError:  # pragma: no cover - older builds
    global_register = None


Method = Callable[[np.ndarray, np.ndarray, float], dict[str, np.ndarray | None]]


def m_cpd(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    return {"cpd": cpd_rigid(x, y, w=0.5).transformed}


def m_gcpd(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    out: dict[str, np.ndarray | None] = {}
    for name, count in (("gcpd-y", "y"), ("gcpd-pairs", "pairs")):
        try:
            h = global_cpd(x, y, k=3, beta=0.5, lam=2.0, w=0.5, count=count)
            out[name] = h[0].cpd.transformed if h else None
        except AutoteachError:
            out[name] = None
    return out


def m_reg(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    r = global_register(x, y)
    return {
        "reg-expl": r.best_by("explained").transformed,
        "reg-lik": r.best_by("likelihood").transformed,
        "reg-final": r.transformed,
    }


def m_reg_energy(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    r = global_register(x, y, energy_all=True, beta=0.5 * size)
    return {"reg-energy": r.best_by("energy").transformed}


def m_reg_pairs(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    r = global_register(x, y, count="pairs")
    return {"reg-expl-pairs": r.best_by("explained").transformed}


def _pad3(p: np.ndarray) -> np.ndarray:
    return p if p.shape[1] == 3 else np.column_stack([p, np.zeros(len(p))])


def m_filterreg(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    from probreg import filterreg

    d = y.shape[1]
    res = filterreg.registration_filterreg(_pad3(y), _pad3(x), objective_type="pt2pt", sigma2=None, maxiter=50)
    t = res.transformation
    return {"filterreg": t.transform(_pad3(y))[:, :d]}


def m_gmmtree(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    from probreg import gmmtree

    d = y.shape[1]
    res = gmmtree.registration_gmmtree(_pad3(y), _pad3(x), maxiter=30)
    return {"gmmtree": res.transformation.transform(_pad3(y))[:, :d]}


def m_fpfh(x: np.ndarray, y: np.ndarray, size: float) -> dict[str, np.ndarray | None]:
    import open3d as o3d

    reg = o3d.pipelines.registration
    voxel = 0.03 * size

    def prep(p: np.ndarray):
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel * 2.5, max_nn=30))
        f = reg.compute_fpfh_feature(pc, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel * 2.5, max_nn=100))
        return pc, f

    src, fs = prep(y)
    dst, fd = prep(x)
    dist = 3 * voxel
    ransac = reg.registration_ransac_based_on_feature_matching(
        src,
        dst,
        fs,
        fd,
        True,
        dist,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    icp = reg.registration_icp(src, dst, voxel, ransac.transformation, reg.TransformationEstimationPointToPoint())
    t = np.asarray(icp.transformation)
    return {"fpfh-ransac": y @ t[:3, :3].T + t[:3, 3]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--families", nargs="*", default=list(FAMILIES_2D + FAMILIES_3D))
    ap.add_argument("--settings", nargs="*", default=list(SETTINGS))
    ap.add_argument("--peers", action="store_true", help="also run probreg / Open3D")
    ap.add_argument("--no-old", action="store_true", help="skip the original global_cpd columns")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip", action="append", default=[], help="drop a method by name, e.g. gmmtree (repeatable)")
    ap.add_argument("--energy", action="store_true", help="also rank by deformation energy (slow)")
    args = ap.parse_args()
    methods: list[tuple[str, Method]] = [("cpd", m_cpd)]
    if not args.no_old:
        methods.append(("gcpd", m_gcpd))
    if global_register is not None:
        methods += [("reg", m_reg), ("reg-pairs", m_reg_pairs)]
        if args.energy:
            methods.append(("reg-energy", m_reg_energy))
    if args.peers:
        methods += [("filterreg", m_filterreg), ("gmmtree", m_gmmtree)]
    print(f"{args.trials} seeded trials per setting; success = RMS to truth < 2 % of shape size")
    for family in args.families:
        for setting in args.settings:
            if setting == "issue" and family != "chevron":
                continue
            ok: dict[str, int] = {}
            crashed: dict[str, int] = {}
            last_error: dict[str, str] = {}
            times: dict[str, list[float]] = {}
            fam_methods = methods + ([("fpfh", m_fpfh)] if args.peers and family in FAMILIES_3D else [])
            fam_methods = [(name, fn) for name, fn in fam_methods if name not in args.skip]
            for trial in range(args.trials):
                sc = make_scene(family, setting, seed=args.seed + 7919 * trial + 101 * SETTINGS.index(setting))
                for mname, fn in fam_methods:
                    t0 = time.perf_counter()
                    try:
                        res = fn(sc.x, sc.y, sc.size)
                    except AutoteachError:
                        res = {}
                    except Exception as exc:  # a peer's own failure counts as a miss, and is tallied
                        if fn in (m_cpd, m_gcpd, m_reg, m_reg_energy, m_reg_pairs):
                            raise
                        crashed[mname] = crashed.get(mname, 0) + 1
                        last_error[mname] = f"{type(exc).__name__}: {exc}"[:80]
                        res = {}
                    times.setdefault(mname, []).append(time.perf_counter() - t0)
                    for col, tr in res.items():
                        good = tr is not None and rms(tr, sc.truth) < 0.02 * sc.size
                        ok[col] = ok.get(col, 0) + int(good)
            cols = "  ".join(f"{c}={v / args.trials:.0%}" for c, v in ok.items())
            tms = "  ".join(f"{k}:{1e3 * float(np.median(v)):.0f}ms" for k, v in times.items())
            print(f"{family:<10} {setting:<12} {cols}  | {tms}", flush=True)
            for mname, count in crashed.items():
                print(f"    {mname} raised in {count} of {args.trials} trials ({last_error[mname]})", flush=True)


if __name__ == "__main__":
    main()
