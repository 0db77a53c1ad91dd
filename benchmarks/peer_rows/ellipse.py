"""Ellipse-fitting rows of ``benchmarks/peers.py``: autoteach's geometric fit vs OpenCV.

Arcs: ``benchmarks/ellipse_fit.py``'s generator (90–160° arcs of ellipses with a = 150–350 px,
b/a = 0.2–1, one point per pixel of arc length, 0.5 px isotropic Gaussian noise, seed 20240601),
rounded to float32 so every method reads the same numbers.

Peers: ``cv2.fitEllipse`` and ``cv2.fitEllipseAMS`` (``cv2.setNumThreads(threads)``), one call
per arc, as their Python API allows. Ours: :func:`autoteach.detect.fit_ellipses` — the same
geometric (orthogonal-distance, maximum-likelihood) fit as :func:`autoteach.detect.fit_ellipse`,
for all arcs in one call (points concatenated, arcs delimited by offsets), when the build has it;
otherwise one :func:`~autoteach.detect.fit_ellipse` call per arc. Time: per fit, the median over
repeated passes of the pass time divided by the number of arcs. Accuracy: median centre error.
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ellipse_fit import from_opencv, make_arcs  # noqa: E402

SEED = 20240601


def _centre_error(truths, fits) -> float:
    return float(np.median([math.hypot(f[0] - t[0], f[1] - t[1]) for t, f in zip(truths, fits, strict=True)]))


def _pass_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def ours_batch(inputs: list[np.ndarray]):
    """Centres of every arc through the batch API (or per-arc calls when the build lacks it)."""
    from autoteach import detect

    if hasattr(detect, "fit_ellipses"):
        points = np.concatenate(inputs).astype(np.float64)
        offsets = np.cumsum([0] + [len(p) for p in inputs])
        return lambda: [tuple(row) for row in detect.fit_ellipses(points, offsets).params]
    return lambda: [
        (e.cx, e.cy, e.a, e.b, e.theta) for e in (detect.fit_ellipse(p, method="geometric").ellipse for p in inputs)
    ]


def _per_call_times(inputs: list[np.ndarray], repeats: int) -> tuple[float, float]:
    """Pass time of one :func:`~autoteach.detect.fit_ellipse` call per arc, and the time of one
    call on 5 points (the per-call cost of the Python boundary plus a trivial fit)."""
    from autoteach import detect

    arcs = [np.ascontiguousarray(p, dtype=np.float64) for p in inputs]
    per_call, _ = _pass_time(lambda: [detect.fit_ellipse(p) for p in arcs], repeats)
    t = np.linspace(0.0, 2.0, 5)
    five = [np.column_stack([300 + 100 * np.cos(t), 200 + 60 * np.sin(t)])] * len(arcs)
    tiny, _ = _pass_time(lambda: [detect.fit_ellipse(p) for p in five], repeats)
    return per_call, tiny / len(five)


def rows(threads: int, quick: bool) -> list[dict]:
    """One row per OpenCV fitter (see the module docstring)."""
    arcs = make_arcs(np.random.default_rng(SEED))
    if quick:
        arcs = arcs[:150]
    truths = [a[0] for a in arcs]
    inputs = [a[1] for a in arcs]
    reps = 3 if quick else 7
    n = len(inputs)
    ours_fn = ours_batch(inputs)
    ours_t, ours_fits = _pass_time(ours_fn, reps)
    ours_err = _centre_error(truths, ours_fits)
    per_call_t, overhead_t = _per_call_times(inputs, reps)
    try:
        import cv2
    except ImportError:
        cv2 = None
    out = []
    for name in ("fitEllipse", "fitEllipseAMS"):
        row = {
            "workload": f"ellipse fit, {n} arcs of 90-160 deg, 0.5 px noise (per fit)",
            "peer": f"cv2.{name}, {threads} thread(s)",
            "ours_s": ours_t / n,
            "ours_accuracy": f"median centre error {ours_err:.3f} px",
        }
        if cv2 is None:
            out.append({**row, "peer_s": math.nan, "ratio": math.nan, "peer_accuracy": "", "note": "cv2 missing"})
            continue
        cv2.setNumThreads(threads)
        fn = getattr(cv2, name)
        peer_t, boxes = _pass_time(lambda fn=fn: [fn(p) for p in inputs], reps)
        peer_err = _centre_error(truths, [from_opencv(b) for b in boxes])
        out.append(
            {
                **row,
                "peer_s": peer_t / n,
                "ratio": peer_t / ours_t,
                "peer_accuracy": f"median centre error {peer_err:.3f} px",
                "note": f"OpenCV {cv2.__version__}; ours: geometric fit, all arcs in one call "
                f"(one fit_ellipse call per arc: {per_call_t / n * 1e6:.1f} us/fit; a call on 5 points: "
                f"{overhead_t * 1e6:.1f} us)",
            }
        )
    return out


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    for r in rows(a.threads, a.quick):
        print(r)
