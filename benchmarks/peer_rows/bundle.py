"""Bundle-adjustment rows of ``benchmarks/peers.py``: autoteach vs Ceres and scipy on identical input.

Problems (``benchmarks/bundle_adjust.py``'s generator, poses 0 and 1 held fixed in every solver,
1 px noise, pinhole K with fx = fy = 500):

- ``50/500/10k``: 50 poses, 500 points, 20 observations per point (10 000 observations).
- ``BAL-size``: 300 poses, 5 000 points, 20 observations per point (100 000 observations),
  generated synthetically with the same generator (no BAL file is reachable offline).

Peers, each in its strongest configuration:

- Ceres 2.x through pycolmap's ``BundleAdjuster`` (COLMAP's C++ reprojection cost with
  automatic derivatives, constant PINHOLE intrinsics, quaternion pose manifold; no Python in the
  solver loop), Levenberg–Marquardt with ``DENSE_SCHUR`` and ``SPARSE_SCHUR``,
  ``function_tolerance = parameter_tolerance = gradient_tolerance = 1e-10``, 100 iterations at
  most, ``num_threads = threads``. Timed: ``BundleAdjuster.solve()`` only (problem building
  excluded; the pycolmap reconstruction is rebuilt from the same initial values before each run).
- scipy ``least_squares`` (``trf``, ``lsmr``, ``x_scale="jac"``) with an analytic sparse
  Jacobian (CSR, rotation-vector derivative by the SO(3) right Jacobian), tolerances 1e-10.

Ours: :func:`autoteach.estimate.bundle_adjust` (LM, automatic linear solver, tolerances 1e-10),
timed end to end through the Python call. Accuracy column: the final cost ½ Σ ‖r‖² (pixels²).
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bundle_adjust import make_scene, project, rotvec_to_matrix  # noqa: E402
from peer_rows import median_time  # noqa: E402

TOL = 1e-10
MAX_ITER = 100
FIXED = (0, 1)


def _skew(v: np.ndarray) -> np.ndarray:
    s = np.zeros((len(v), 3, 3))
    s[:, 0, 1], s[:, 0, 2], s[:, 1, 0] = -v[:, 2], v[:, 1], v[:, 2]
    s[:, 1, 2], s[:, 2, 0], s[:, 2, 1] = -v[:, 0], -v[:, 1], v[:, 0]
    return s


def right_jacobian(r: np.ndarray) -> np.ndarray:
    """SO(3) right Jacobian J_r(r) of a batch of rotation vectors: d Exp(r + δ) = Exp(r) Exp(J_r δ)."""
    th = np.linalg.norm(r, axis=1)[:, None, None]
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5, (1 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0, (ths - np.sin(ths)) / ths**3)
    k = _skew(r)
    return np.eye(3) - a * k + b * (k @ k)


class ScipyAnalytic:
    """scipy ``least_squares`` on the gauge-fixed problem with an analytic CSR Jacobian."""

    def __init__(self, K, obs, pose_idx, point_idx, init_poses, init_points):
        from scipy.sparse import csr_matrix

        self.K, self.obs, self.pi, self.xi = K, obs, pose_idx, point_idx
        self.init_poses, self.init_points = init_poses, init_points
        n_poses = len(init_poses)
        self.free = np.array([i for i in range(n_poses) if i not in FIXED])
        slot = -np.ones(n_poses, dtype=int)
        slot[self.free] = np.arange(len(self.free))
        self.slot = slot[pose_idx]
        self.n_cam = 6 * len(self.free)
        n = len(obs)
        # Each observation row pair: 6 pose columns (when free) then 3 point columns.
        ok = self.slot >= 0
        cols_pose = 6 * np.maximum(self.slot, 0)[:, None] + np.arange(6)
        cols_pt = self.n_cam + 3 * point_idx[:, None] + np.arange(3)
        cols = np.concatenate([cols_pose, cols_pt], axis=1)  # n×9
        self.mask = np.concatenate([np.repeat(ok[:, None], 6, 1), np.ones((n, 3), bool)], axis=1)
        col2 = np.repeat(cols[:, None, :], 2, axis=1)  # n×2×9
        m2 = np.repeat(self.mask[:, None, :], 2, axis=1)
        self.indices = col2[m2]
        counts = m2.sum(axis=2).ravel()
        self.indptr = np.concatenate([[0], np.cumsum(counts)])
        self.m2 = m2
        self.shape = (2 * n, self.n_cam + 3 * len(init_points))
        self._csr = csr_matrix

    def unpack(self, x):
        poses = self.init_poses.copy()
        poses[self.free] = x[: self.n_cam].reshape(-1, 6)
        return poses, x[self.n_cam :].reshape(-1, 3)

    def fun(self, x):
        poses, pts = self.unpack(x)
        return (project(self.K, poses[self.pi], pts[self.xi]) - self.obs).ravel()

    def jac(self, x):
        poses, pts = self.unpack(x)
        pp, X = poses[self.pi], pts[self.xi]
        R = rotvec_to_matrix(pp[:, :3])
        pc = np.einsum("kij,kj->ki", R, X) + pp[:, 3:]
        iz = 1.0 / pc[:, 2]
        f = np.array([self.K[0, 0], self.K[1, 1]])
        # d uv / d pc (n×2×3)
        dp = np.zeros((len(X), 2, 3))
        dp[:, 0, 0] = f[0] * iz
        dp[:, 0, 2] = -f[0] * pc[:, 0] * iz**2
        dp[:, 1, 1] = f[1] * iz
        dp[:, 1, 2] = -f[1] * pc[:, 1] * iz**2
        # d pc / d r = -R [X]x J_r(r);  d pc / d t = I;  d pc / d X = R
        d_r = -R @ _skew(X) @ right_jacobian(pp[:, :3])
        full = np.concatenate([dp @ d_r, dp, dp @ R], axis=2)  # n×2×9
        return self._csr((full[self.m2], self.indices, self.indptr), shape=self.shape)

    def x0(self):
        return np.concatenate([self.init_poses[self.free].ravel(), self.init_points.ravel()])

    def solve(self):
        from scipy.optimize import least_squares

        return least_squares(
            self.fun,
            self.x0(),
            jac=self.jac,
            x_scale="jac",
            method="trf",
            tr_solver="lsmr",
            ftol=TOL,
            xtol=TOL,
            gtol=TOL,
            max_nfev=MAX_ITER,
        )


def _quat_xyzw(rotvec: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(rotvec))
    if th < 1e-12:
        return np.array([*(0.5 * rotvec), 1.0])
    axis = rotvec / th
    return np.array([*(np.sin(th / 2) * axis), np.cos(th / 2)])


def colmap_problem(K, obs, pose_idx, point_idx, init_poses, init_points, solver: str, threads: int):
    """A pycolmap BundleAdjuster (Ceres, C++ costs) for the scene; returns (adjuster, reconstruction)."""
    import pycolmap

    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera.create_from_model_name(1, "PINHOLE", 500.0, 640, 480)
    cam.params = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    rec.add_camera_with_trivial_rig(cam)
    order = np.argsort(pose_idx, kind="stable")
    slots = np.empty(len(obs), dtype=int)
    starts = np.searchsorted(pose_idx[order], np.arange(len(init_poses)))
    for k, o in enumerate(order):
        slots[o] = k - starts[pose_idx[o]]
    point_ids = []
    for i, p in enumerate(init_poses):
        sel = order[pose_idx[order] == i]
        img = pycolmap.Image(name=f"{i}", keypoints=obs[sel], camera_id=1, image_id=i + 1)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(_quat_xyzw(p[:3])), p[3:])
        rec.add_image_with_trivial_frame(img, pose)
    for j, x in enumerate(init_points):
        track = pycolmap.Track()
        for k in np.flatnonzero(point_idx == j):
            track.add_element(int(pose_idx[k]) + 1, int(slots[k]))
        point_ids.append(rec.add_point3D(x, track))
    config = pycolmap.BundleAdjustmentConfig()
    for i in range(len(init_poses)):
        config.add_image(i + 1)
    config.set_constant_cam_intrinsics(1)
    for i in FIXED:
        config.set_constant_rig_from_world_pose(i + 1)
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = False
    opts.refine_principal_point = False
    opts.refine_extra_params = False
    opts.print_summary = False
    c = opts.ceres
    c.auto_select_solver_type = False
    c.min_num_residuals_for_cpu_multi_threading = 1
    so = c.solver_options
    import pyceres

    so.linear_solver_type = getattr(pyceres.LinearSolverType, solver)
    so.trust_region_strategy_type = pyceres.TrustRegionStrategyType.LEVENBERG_MARQUARDT
    so.function_tolerance = TOL
    so.gradient_tolerance = TOL
    so.parameter_tolerance = TOL
    so.max_num_iterations = MAX_ITER
    so.num_threads = threads
    so.logging_type = pyceres.LoggingType.SILENT
    c.solver_options = so
    opts.ceres = c
    return pycolmap.create_default_bundle_adjuster(opts, config, rec), rec


def _ours(K, obs, pose_idx, point_idx, init_poses, init_points):
    from autoteach.estimate import bundle_adjust

    return bundle_adjust(
        K, init_poses, init_points, obs, pose_idx, point_idx, fixed_poses=FIXED, ftol=TOL, gtol=TOL, xtol=TOL
    )


def _ceres_rows(name, scene, ours_s, ours_cost, threads, repeats):
    K, _, _, obs, pi, xi, p0, x0 = scene
    rows = []
    try:
        import pycolmap  # noqa: F401
    except ImportError:
        return [_missing(name, "Ceres via pycolmap", ours_s, ours_cost, "pycolmap not installed")]
    for solver in ("DENSE_SCHUR", "SPARSE_SCHUR"):
        times, inner, cost, iters = [], [], float("nan"), 0
        for _ in range(repeats):
            ba, _rec = colmap_problem(K, obs, pi, xi, p0, x0, solver, threads)
            t0 = time.perf_counter()
            summary = ba.solve()
            times.append(time.perf_counter() - t0)
            cs = summary.ceres_summary
            inner.append(float(cs.total_time_in_seconds))
            cost = float(cs.final_cost)  # Ceres reports ½ Σ ‖r‖², as we do
            iters = int(cs.num_successful_steps + cs.num_unsuccessful_steps)
        peer_s = statistics.median(times)
        rows.append(
            {
                "workload": name,
                "peer": f"Ceres {solver} LM via pycolmap BundleAdjuster (C++ costs), {threads} thread(s)",
                "peer_s": peer_s,
                "ours_s": ours_s,
                "ratio": peer_s / ours_s,
                "peer_accuracy": f"cost {cost:.6f} ({iters} it.)",
                "ours_accuracy": f"cost {ours_cost:.6f}",
                "note": f"relative cost difference {abs(cost - ours_cost) / cost:.1e}; "
                f"Ceres's own total_time_in_seconds {statistics.median(inner):.4f} s",
            }
        )
    return rows


def _missing(name, peer, ours_s, ours_cost, note):
    return {
        "workload": name,
        "peer": peer,
        "peer_s": float("nan"),
        "ours_s": ours_s,
        "ratio": float("nan"),
        "peer_accuracy": "",
        "ours_accuracy": f"cost {ours_cost:.6f}",
        "note": note,
    }


def rows(threads: int, quick: bool) -> list[dict]:
    """Rows for the 50/500/10k problem and the BAL-size problem (see the module docstring)."""
    out = []
    problems = [("bundle adjustment 50/500/10k", dict(n_poses=50, n_points=500, per_point=20))]
    if not quick:
        problems.append(("bundle adjustment BAL-size 300/5000/100k", dict(n_poses=300, n_points=5000, per_point=20)))
    for name, kw in problems:
        scene = make_scene(**kw)
        K, _, _, obs, pi, xi, p0, x0 = scene
        big = len(obs) > 50_000
        reps = 3 if (quick or big) else 7
        ours_s, res = median_time(lambda s=scene: _ours(s[0], *s[3:]), reps)
        ours_cost = res.final_cost
        out += _ceres_rows(name, scene, ours_s, ours_cost, threads, reps)
        try:
            import scipy  # noqa: F401
        except ImportError:
            out.append(_missing(name, "scipy least_squares", ours_s, ours_cost, "scipy not installed"))
            continue
        sp = ScipyAnalytic(K, obs, pi, xi, p0, x0)
        sp_reps = 1 if (quick or big) else 3
        peer_s, r = median_time(sp.solve, sp_reps)
        out.append(
            {
                "workload": name,
                "peer": "scipy least_squares trf/lsmr, analytic sparse Jacobian, x_scale='jac'",
                "peer_s": peer_s,
                "ours_s": ours_s,
                "ratio": peer_s / ours_s,
                "peer_accuracy": f"cost {r.cost:.6f} ({r.nfev} ev.)",
                "ours_accuracy": f"cost {ours_cost:.6f}",
                "note": f"relative cost difference {abs(r.cost - ours_cost) / r.cost:.1e}",
            }
        )
    return out


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    for row in rows(a.threads, a.quick):
        print(row)
