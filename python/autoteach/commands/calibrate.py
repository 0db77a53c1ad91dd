"""The ``autoteach calibrate`` command: camera calibration with Max ERE (seed 004 ch. 5).

Usage::

    autoteach calibrate views.npz [--model brown_conrady] [--out calib.json] [--json]
    autoteach calibrate --simulate [--lens medium] [--strategy guided|random|novice] [--threshold 0.5] [--json]

``views.npz`` holds ``image_size`` (``[width, height]``) and either ``object_points`` /
``image_points`` as ``(V, N, 3)`` / ``(V, N, 2)`` arrays (NaN rows: missing points) or per-view
arrays ``object_points_0``, ``image_points_0``, ``object_points_1``, ...
"""

from __future__ import annotations

import argparse
import json
import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from autoteach.commands.args import positive, seed
from autoteach.errors import InvalidInputError


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``calibrate`` sub-command."""
    from autoteach.calib import LENSES, MODELS, STRATEGIES

    p = sub.add_parser(
        "calibrate",
        parents=[common],
        help="calibrate a camera from target views (or run a simulated guided session)",
        description="Calibrate a camera from planar-target views with Max ERE uncertainty, or --simulate a "
        "guided calibration session on a known lens that shows the suggest / capture / re-calibrate loop.",
    )
    p.add_argument("views", nargs="?", type=Path, help="an .npz file with object_points, image_points, image_size")
    p.add_argument(
        "--model", choices=MODELS, default=None, help="lens model (default brown_conrady; lens's own when simulating)"
    )
    p.add_argument("--sigma-z", type=float, default=None, help="detector noise in pixels (default 7e-5 * width)")
    p.add_argument("--loss", choices=("trivial", "huber", "cauchy"), default="trivial", help="final-solve loss")
    p.add_argument("--out", type=Path, default=None, help="write the calibration as JSON here")
    p.add_argument("--simulate", action="store_true", help="run a simulated guided session instead")
    p.add_argument("--lens", choices=tuple(LENSES), default="medium", help="simulated lens (default medium)")
    p.add_argument(
        "--strategy",
        choices=STRATEGIES,
        default="guided",
        help="how views are chosen: suggestions, random, or a novice following the ROS checklist (default guided)",
    )
    p.add_argument("--threshold", type=float, default=0.5, help="stop when Max ERE < this many pixels (default 0.5)")
    p.add_argument("--max-views", type=positive, default=12, help="at most this many views (default 12)")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.set_defaults(func=run)


def _load_npz(path: Path) -> tuple[list[np.ndarray], list[np.ndarray], tuple[int, int]]:
    try:
        return _read_npz(path)
    except InvalidInputError:
        raise  # already names the file and the problem (it is a ValueError too)
    except (ValueError, EOFError, KeyError, zipfile.BadZipFile) as err:
        # np.load raises these for files that are not an .npz of plain arrays.
        raise InvalidInputError(
            f"{path}: not a readable .npz archive of calibration views ({type(err).__name__})"
        ) from None


def _read_npz(path: Path) -> tuple[list[np.ndarray], list[np.ndarray], tuple[int, int]]:
    with np.load(path, allow_pickle=False) as z:
        keys = set(z.files)
        if "image_size" not in keys:
            raise InvalidInputError(f"{path}: missing 'image_size' ([width, height])")
        size = np.asarray(z["image_size"]).ravel()
        if size.shape != (2,) or size.dtype.kind not in "iuf" or not np.all(np.isfinite(size)) or np.any(size < 1):
            raise InvalidInputError(f"{path}: 'image_size' must be [width, height] in pixels, got {size.tolist()}")
        w, h = (int(v) for v in size)
        if "object_points" in keys and "image_points" in keys:
            return list(z["object_points"]), list(z["image_points"]), (w, h)
        obj, img = [], []
        k = 0
        while f"object_points_{k}" in keys:
            if f"image_points_{k}" not in keys:
                raise InvalidInputError(f"{path}: object_points_{k} has no image_points_{k}")
            obj.append(z[f"object_points_{k}"])
            img.append(z[f"image_points_{k}"])
            k += 1
        if not obj:
            raise InvalidInputError(f"{path}: no object_points / image_points arrays")
        return obj, img, (w, h)


def _summary(cal: Any) -> dict[str, Any]:
    return {
        "model": cal.model,
        "image_size": list(cal.image_size),
        "params": dict(zip(cal.param_names, cal.params.tolist(), strict=True)),
        "std": dict(zip(cal.param_names, cal.std.tolist(), strict=True)),
        "rms_px": cal.rms,
        "view_rms_px": cal.view_rms.tolist(),
        "outliers": [list(o) for o in cal.outliers],
        "max_ere_px": cal.max_ere,
        "sigma_z_px": cal.sigma_z,
    }


def run(args: argparse.Namespace) -> int:
    """Run the command; returns the exit status."""
    from autoteach.calib import calibrate, simulate_session

    if args.simulate:
        if args.views is not None:
            raise InvalidInputError("give either a views file or --simulate, not both")
        if not args.json:
            print(f"simulated {args.strategy} session, lens {args.lens}, stop when Max ERE < {args.threshold} px")
            print(
                "test set: 60 views; 'vs truth' = rays of the true lens (ch. 5.5.3), 're-fit' = poses re-fit (ch. 5.5)"
            )
            print(" views  Max ERE [px]  E[max] [px]  p99.5 vs truth  mean vs truth  p99.5 re-fit  train rms [px]")

        def show(step: Any) -> None:
            if not args.json:
                if math.isfinite(step.max_ere):
                    ere = f"{step.max_ere:13.3f}  {step.expected_max:11.3f}"
                else:
                    ere = f"{'(bootstrap)':>13}  {'':>11}"
                print(
                    f" {step.views:5d} {ere}  {step.test_p995:14.3f}  {step.test_mean:13.3f}"
                    f"  {step.refit_p995:12.3f}  {step.rms:14.3f}"
                )

        res = simulate_session(
            args.lens,
            strategy=args.strategy,
            model=args.model,
            threshold=args.threshold,
            max_views=args.max_views,
            seed=args.seed,
            sigma=args.sigma_z,
            stop_at_threshold=True,
            callback=show,
        )
        out = res.to_dict()
        if res.calibration is not None:
            out["calibration"] = _summary(res.calibration)
            if args.out is not None:
                res.calibration.save(args.out)
        if args.json:
            print(json.dumps(out))
        else:
            n = res.views_to_threshold
            print(f"stopping rule met after {n} views" if n else f"threshold not reached in {args.max_views} views")
        return 0

    if args.views is None:
        raise InvalidInputError("a views .npz file (or --simulate) is required")
    obj, img, size = _load_npz(args.views)
    cal = calibrate(obj, img, args.model or "brown_conrady", size, sigma_z=args.sigma_z, loss=args.loss)
    if args.out is not None:
        cal.save(args.out)
    s = _summary(cal)
    if args.json:
        print(json.dumps(s))
    else:
        print(f"{cal!r}")
        for n, v, sd in zip(cal.param_names, cal.params, cal.std, strict=True):
            print(f"  {n:>3} = {v:14.8g} +- {sd:.3g}")
        print(
            f"rms {cal.rms:.4f} px over {cal.num_views} views, {len(cal.outliers)} outliers, "
            f"Max ERE {cal.max_ere:.3f} px"
        )
    return 0
