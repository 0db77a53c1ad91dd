"""Multi-wafer tracking on simulated carrier sweeps: hierarchical GMM registration vs greedy.

The camera sweeps a carrier of 12–25 wafers at 10 mm pitch (neighbouring rims ~20 px apart,
upper and lower rims ~2 px apart); wafers leave and re-enter the image during the sweeps. The
detections are the simulator's ground-truth visible rims with pixel noise, fitted ellipses,
missed wafers, duplicated edges and false arcs (:func:`autoteach.track.synthetic_detections`).
Both associators run on identical detections, with the same predictions (image motion; eq. (4.1)
projection with the camera poses for rims unseen in the previous frame) and the same options; the
carrier's slot pitch lets the hierarchical associator add the free slots next to its tracks as
birth hypotheses (``WaferTracker(slot_pitch=...)``), which the greedy baseline does not use. Prints MOTA, IDF1,
identity switches and identity changes between neighbouring wafers, and the time per frame.

    python benchmarks/tracking.py [--seeds 0 1 2 3 4 5] [--frames 100] [--wafers 12 25]
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from autoteach.sim import SimConfig, simulate_session
from autoteach.track import WaferTracker, clear_mot, identity_changes, idf1, synthetic_detections


def scenario(n_wafers: int, seed: int, frames: int) -> Any:
    """A carrier sweep with ``n_wafers`` wafers in consecutive slots (10 mm pitch)."""
    first = 26 - n_wafers
    cfg = SimConfig(slots=tuple(range(first, first + n_wafers)), n_rim_samples=720)
    return simulate_session(seed, frames, cfg, render=False)


def evaluate(session: Any, detections: list[list[Any]], **params: Any) -> dict[str, float]:
    """Track ``detections`` and score the result against the edges' ground-truth labels."""
    cam = session.camera
    fx, fy, cx, cy = (float(v) for v in cam.params[:4])
    tracker = WaferTracker(
        intrinsics=[[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]],
        image_size=(cam.width, cam.height),
        normal_prior=(0.0, 0.0, 1.0),
        wafer_radius=session.config.wafer_radius,
        **{"slot_pitch": session.config.slot_pitch, **params},
    )
    times = []
    stages: dict[str, list[float]] = {"predict": [], "associate": [], "manage": []}
    for f, edges in enumerate(detections):
        t0 = time.perf_counter()
        tracker.update(edges, session.camera_poses[f])
        times.append(time.perf_counter() - t0)
        for k in stages:
            stages[k].append(getattr(tracker.last_timings, k))
    tracks = tracker.all_tracks()
    frames = sequence_frames(detections, tracks)
    slots = session.wafer_slots
    changes = identity_changes(tracks, neighbours=lambda a, b: abs(int(slots[a]) - int(slots[b])) == 1)
    out = clear_mot(frames)
    out.update(idf1(frames))
    out.update(changes)
    out["ms_per_frame"] = 1e3 * float(np.median(times))
    for k, v in stages.items():
        out[f"{k}_ms"] = 1e3 * float(np.median(v))
    return out


def sequence_frames(detections: list[list[Any]], tracks: list[Any]) -> list[tuple[list[Any], list[Any], Any]]:
    """Per frame: the detected wafers (ground truth), the tracks with edges in the frame, and
    distance 0 where a track holds an edge of the wafer (inf otherwise)."""
    per_frame: list[dict[int, set[Any]]] = [{} for _ in detections]
    for t in tracks:
        for f, e in t.history:
            per_frame[f].setdefault(t.id, set()).add(e.label)
    frames = []
    for f, edges in enumerate(detections):
        gt = sorted({e.label for e in edges if e.label is not None})
        hyp = sorted(per_frame[f])
        d = np.full((len(gt), len(hyp)), np.inf)
        for j, h in enumerate(hyp):
            for i, g in enumerate(gt):
                if g in per_frame[f][h]:
                    d[i, j] = 0.0
        frames.append((gt, hyp, d))
    return frames


def main() -> None:
    """Run the comparison: one line per (wafers, seed, associator), then one summary line per figure."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--wafers", type=int, nargs="+", default=[12, 25])
    args = ap.parse_args()
    print(
        f"{'wafers':>6} {'seed':>4} {'associator':>12} {'MOTA':>7} {'IDF1':>7} {'IDSW':>5} "
        f"{'changes':>7} {'nbr':>4} {'FP':>5} {'FN':>5} {'GT':>6} {'assoc ms':>8} {'pred ms':>7} "
        f"{'mgmt ms':>7} {'update ms':>9}"
    )
    results: dict[tuple[int, str], list[dict[str, float]]] = {}
    for n in args.wafers:
        for seed in args.seeds:
            session = scenario(n, seed, args.frames)
            dets = synthetic_detections(session, seed=seed)
            for name in ("hierarchical", "greedy"):
                r = evaluate(session, dets, associator=name)
                results.setdefault((n, name), []).append(r)
                print(
                    f"{n:>6} {seed:>4} {name:>12} {r['mota']:7.4f} {r['idf1']:7.4f} {int(r['idsw']):>5} "
                    f"{r['changes']:>7} {r['neighbour_changes']:>4} {int(r['fp']):>5} {int(r['fn']):>5} "
                    f"{int(r['num_gt']):>6} {r['associate_ms']:8.3f} {r['predict_ms']:7.3f} "
                    f"{r['manage_ms']:7.3f} {r['ms_per_frame']:9.3f}",
                    flush=True,
                )
    print()
    for (n, name), rs in results.items():
        print(
            f"SUMMARY wafers={n} {name}: MOTA {min(r['mota'] for r in rs):.4f}-{max(r['mota'] for r in rs):.4f}, "
            f"IDF1 {min(r['idf1'] for r in rs):.4f}-{max(r['idf1'] for r in rs):.4f}, "
            f"neighbour switches {sum(r['neighbour_changes'] for r in rs)}, IDSW {int(sum(r['idsw'] for r in rs))}, "
            f"association median {np.median([r['associate_ms'] for r in rs]):.3f} ms/frame, "
            f"update median {np.median([r['ms_per_frame'] for r in rs]):.3f} ms/frame ({len(rs)} seeds)"
        )


if __name__ == "__main__":
    main()
