"""Camera-calibration row of ``benchmarks/peers.py``: autoteach vs ``cv2.calibrateCamera``.

Input: 20 views of the 10×7 target seen by the ``medium`` simulated Brown–Conrady lens
(k1 = −0.30), 0.1 px Gaussian noise, at least 30 visible points per view, points rounded to
float32 so both read the same numbers (``benchmarks/calib_vs_opencv.py``'s generator).

Both estimate the same 9 parameters (fx, fy, cx, cy, k1, k2, p1, p2, k3) and the per-view
poses. OpenCV: default flags, ``criteria = (COUNT + EPS, 500, 1e-16)``,
``cv2.setNumThreads(threads)``. Ours: :func:`autoteach.calib.calibrate` with outlier
rejection off (OpenCV has none); it also returns the marginal covariance. Accuracy: the RMS
reprojection error of each and the largest relative parameter difference.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib_vs_opencv import views  # noqa: E402
from peer_rows import median_time  # noqa: E402

N_VIEWS = 20
SIGMA = 0.1
SEED = 3


def rows(threads: int, quick: bool) -> list[dict]:
    """One row (see the module docstring)."""
    from autoteach.calib import LENSES, calibrate

    size = LENSES["medium"]["image_size"]
    obj32, img32 = views(N_VIEWS, SIGMA, SEED)
    obj64 = [o.astype(np.float64) for o in obj32]
    img64 = [i.astype(np.float64) for i in img32]
    reps = 5 if quick else 15
    row = {"workload": f"camera calibration, {len(obj32)} views of a 10x7 board, Brown-Conrady"}
    ours_s, cal = median_time(lambda: calibrate(obj64, img64, "brown_conrady", size, outlier_threshold=math.inf), reps)
    try:
        import cv2
    except ImportError:
        return [
            {
                **row,
                "peer": "cv2.calibrateCamera",
                "peer_s": math.nan,
                "ours_s": ours_s,
                "ratio": math.nan,
                "peer_accuracy": "",
                "ours_accuracy": f"rms {cal.rms:.6f} px",
                "note": "cv2 missing",
            }
        ]
    cv2.setNumThreads(threads)
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 500, 1e-16)
    peer_s, (rms_cv, k, d, _, _) = median_time(
        lambda: cv2.calibrateCamera(obj32, img32, size, None, None, criteria=criteria), reps
    )
    ref = np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], *d.ravel()[:5]])
    rel = float(np.max(np.abs(cal.params - ref) / np.abs(ref)))
    return [
        {
            **row,
            "peer": f"cv2.calibrateCamera (OpenCV {cv2.__version__}, 500 it. / 1e-16), {threads} thread(s)",
            "peer_s": peer_s,
            "ours_s": ours_s,
            "ratio": peer_s / ours_s,
            "peer_accuracy": f"rms {rms_cv:.6f} px",
            "ours_accuracy": f"rms {cal.rms:.6f} px",
            "note": f"same 9 parameters; largest relative parameter difference {rel:.1e}; ours includes covariance",
        }
    ]


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    for r in rows(a.threads, a.quick):
        print(r)
