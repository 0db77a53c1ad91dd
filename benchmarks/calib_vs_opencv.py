"""Brown-Conrady calibration: autoteach.calib.calibrate versus cv2.calibrateCamera on identical views.

Both get the same synthetic views (a 10x7 target seen by the ``medium`` simulated lens, Gaussian
pixel noise, points rounded to float32 so both read the same numbers). Prints both parameter
vectors, the largest relative difference, and the median wall time of each over ``--repeats``
runs (autoteach with outlier rejection off, as OpenCV has none; its covariance is included).

    python benchmarks/calib_vs_opencv.py [--views 15] [--sigma 0.1] [--repeats 15] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

import cv2
import numpy as np

from autoteach.calib import LENSES, calibrate, make_target, random_poses, simulate_view


def views(count: int, sigma: float, seed: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Noisy views with at least 30 visible points, float32-exact."""
    lens = LENSES["medium"]
    target = make_target()
    poses = random_poses(lens["model"], lens["params"], lens["image_size"], target, 6 * count, seed=seed)
    obj, img = [], []
    for k, pose in enumerate(poses):
        v = simulate_view(lens["model"], lens["params"], lens["image_size"], pose, target, sigma=sigma, seed=seed + k)
        if v is not None and len(v[2]) >= 30:
            obj.append(v[0].astype(np.float32))
            img.append(v[1].astype(np.float32))
        if len(obj) == count:
            break
    return obj, img


def main() -> None:
    """Run the comparison and print it."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--views", type=int, default=15)
    ap.add_argument("--sigma", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    size = LENSES["medium"]["image_size"]
    obj32, img32 = views(args.views, args.sigma, args.seed)
    obj64 = [o.astype(np.float64) for o in obj32]
    img64 = [i.astype(np.float64) for i in img32]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 500, 1e-16)

    def run_cv():
        return cv2.calibrateCamera(obj32, img32, size, None, None, criteria=criteria)

    def run_at():
        return calibrate(obj64, img64, "brown_conrady", size, outlier_threshold=math.inf)

    t_cv, t_at = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        rms_cv, k, d, _, _ = run_cv()
        t_cv.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        cal = run_at()
        t_at.append(time.perf_counter() - t0)
    ref = np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], *d.ravel()[:5]])
    rel = np.abs(cal.params - ref) / np.abs(ref)
    names = cal.param_names
    out = {
        "views": len(obj32),
        "points": int(sum(len(o) for o in obj32)),
        "sigma_px": args.sigma,
        "opencv_version": cv2.__version__,
        "opencv": dict(zip(names, ref.tolist(), strict=True)),
        "autoteach": dict(zip(names, cal.params.tolist(), strict=True)),
        "max_relative_difference": float(rel.max()),
        "rms_opencv": float(rms_cv),
        "rms_autoteach": cal.rms,
        "median_ms_opencv": 1e3 * statistics.median(t_cv),
        "median_ms_autoteach": 1e3 * statistics.median(t_at),
    }
    out["speedup"] = out["median_ms_opencv"] / out["median_ms_autoteach"]
    if args.json:
        print(json.dumps(out))
        return
    print(f"{out['views']} views, {out['points']} points, noise {args.sigma} px, OpenCV {cv2.__version__}")
    print(f"{'param':>5} {'cv2.calibrateCamera':>22} {'autoteach':>22} {'rel. diff':>10}")
    for n, a, b, r in zip(names, ref, cal.params, rel, strict=True):
        print(f"{n:>5} {a:22.12g} {b:22.12g} {r:10.2e}")
    print(f"rms: OpenCV {rms_cv:.9f} px, autoteach {cal.rms:.9f} px")
    print(
        f"median time over {args.repeats} runs: OpenCV {out['median_ms_opencv']:.2f} ms, "
        f"autoteach {out['median_ms_autoteach']:.2f} ms (speed-up x{out['speedup']:.2f})"
    )


if __name__ == "__main__":
    main()
