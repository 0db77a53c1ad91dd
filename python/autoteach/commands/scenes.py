"""The ``autoteach scenes`` command: appearance-randomised carrier images with their truth (issue 42).

Usage::

    autoteach scenes --family dark_face --count 5 --seed 0 --out DIR [--sweep FRAMES] [--json]

Writes ``DIR/<family>_<seed>.pgm`` (8-bit binary PGM, readable by OpenCV, Pillow, ImageMagick)
and ``DIR/<family>_<seed>.json``: the camera matrix ``K``, the pose ``T_wc``, the scene
parameters and per slot the truth of each rim (``ellipse`` as ``[cx, cy, a, b, theta]``,
``visible``, ``visible_fraction``). With ``--sweep FRAMES`` one sweep of ``FRAMES`` frames per seed
(``<family>_<seed>_<frame>``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``scenes`` sub-command."""
    from autoteach.sim.appearance import FAMILIES

    p = sub.add_parser(
        "scenes",
        parents=[common],
        help="write appearance-randomised carrier images (PGM) with exact rim truth (JSON)",
        description="Generate carrier images of one appearance family (autoteach.sim.appearance) with the exact "
        "projected rim ellipses as ground truth.",
    )
    p.add_argument("--family", choices=FAMILIES, required=True, help="appearance family")
    p.add_argument("--count", type=int, default=1, help="number of seeds (default 1)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--sweep", type=int, default=0, help="frames of a sweep per seed (default 0: single images)")
    p.add_argument("--out", type=Path, required=True, help="output folder (created)")
    p.set_defaults(func=run)


def write_pgm(path: Path, image: np.ndarray) -> None:
    """Write a uint8 ``(H, W)`` image as binary PGM (P5)."""
    if image.dtype != np.uint8 or image.ndim != 2:
        raise InvalidInputError(f"PGM needs a 2-D uint8 image, got {image.dtype} {image.shape}")
    h, w = image.shape
    path.write_bytes(f"P5\n{w} {h}\n255\n".encode() + np.ascontiguousarray(image).tobytes())


def scene_truth(scene: Any) -> dict[str, Any]:
    """The JSON-serialisable truth of a :class:`~autoteach.sim.appearance.CarrierScene`."""

    def rim(r: Any) -> dict[str, Any] | None:
        if r is None:
            return None
        return {
            "ellipse": r.ellipse.as_array().tolist(),
            "visible": bool(r.visible),
            "visible_fraction": float(r.visible_fraction),
            "camera_side": bool(r.camera_side),
        }

    params = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(scene.params).items()}
    return {
        "family": scene.family,
        "seed": scene.seed,
        "K": scene.K.tolist(),
        "T_wc": scene.T_wc.tolist(),
        "params": params,
        "wafers": [
            {"slot": w.slot, "present": w.present, "upper": rim(w.upper), "lower": rim(w.lower)} for w in scene.wafers
        ],
    }


def run(args: argparse.Namespace) -> int:
    """Generate and write the scenes."""
    from autoteach.sim.appearance import render_carrier_image, render_sweep

    if args.count < 1:
        raise InvalidInputError(f"--count must be at least 1, got {args.count}")
    args.out.mkdir(parents=True, exist_ok=True)
    written = []
    for seed in range(args.seed, args.seed + args.count):
        if args.sweep > 0:
            items = [
                (f"{args.family}_{seed}_{i:03d}", s) for i, s in enumerate(render_sweep(args.family, seed, args.sweep))
            ]
        else:
            items = [(f"{args.family}_{seed}", render_carrier_image(args.family, seed))]
        for stem, scene in items:
            write_pgm(args.out / f"{stem}.pgm", scene.image)
            (args.out / f"{stem}.json").write_text(json.dumps(scene_truth(scene), indent=1))
            written.append(stem)
    if args.json:
        print(json.dumps({"out": str(args.out), "scenes": written}))
    elif not args.quiet:
        print(f"wrote {len(written)} scene(s) to {args.out}")
    return 0
