"""The ``autoteach radio`` command: signal-strength prediction for robot teams (seed 004 ch. 3).

Usage::

    autoteach radio --simulate [--environments office,campus,mixed] [--duration 240] [--seed 0]
                    [--stride 5] [--tune] [--out radio_out] [--json]

Replays simulated missions in 2 s steps (section 3.3), prints the RMSE of LogFit, MRGP, MRT and
MATTE per prediction horizon, and writes error-versus-horizon plots (like Figs. 3.5-3.6) and
MATTE's attenuation map (Fig. 3.1) into ``--out`` (needs matplotlib: ``pip install autoteach[plot]``).
With ``--tune``, MRT's and MATTE's meta-parameters are first found by compass search on two
training missions per environment (section 3.3; :mod:`autoteach.radio_tuning`), as the seed did.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from autoteach.errors import InvalidInputError


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``radio`` sub-command."""
    p = sub.add_parser(
        "radio",
        parents=[common],
        help="radio signal-strength prediction for robot teams (LogFit, MRGP, MRT, MATTE) on simulation",
        description="Compare LogFit, MRGP, MRT and MATTE on simulated robot-team missions (seed 004 ch. 3).",
    )
    p.add_argument("--simulate", action="store_true", help="run the simulated comparison (the only mode so far)")
    p.add_argument("--environments", default="office,campus,mixed", help="comma-separated environments")
    p.add_argument("--duration", type=float, default=240.0, help="mission length, seconds (default 240)")
    p.add_argument("--sigma", type=float, default=4.0, help="shadowing standard deviation, dB (default 4)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--stride", type=int, default=5, help="evaluate every N-th 2 s step (default 5)")
    p.add_argument(
        "--tune",
        action="store_true",
        help="compass-search MRT's and MATTE's parameters on two training missions per environment first (sec. 3.3)",
    )
    p.add_argument("--out", type=Path, default=Path("radio_out"), help="folder for the plots (default radio_out)")
    p.add_argument("--no-plots", action="store_true", help="do not write plots")
    p.set_defaults(func=run)


def format_table(r: dict[str, Any]) -> str:
    """RMSE (dB) per environment and model: near term (0-6 s ahead), far (10-20 s) and fit time."""
    lines = [f"RMSE in dB at {r['sigma']:g} dB shadowing ({r['duration']:g} s missions, every {r['stride']}. step)"]
    lines.append(f"{'environment':<10}{'model':<8}{'0-6 s':>8}{'10-20 s':>9}{'fit ms':>9}  per 2 s bin")
    for env, row in r["results"].items():
        for m, v in row["models"].items():
            bins = " ".join(f"{x:.1f}" for x in v["rmse"])
            lines.append(f"{env:<10}{m:<8}{v['near_term']:>8.2f}{v['far']:>9.2f}{1e3 * v['fit_seconds']:>9.1f}  {bins}")
        lines.append(f"{'':<10}ranking MATTE < MRT < MRGP < LogFit (0-6 s): {'yes' if row['ranking_ok'] else 'no'}")
        for m, p in r.get("tuned", {}).get(env, {}).items():
            values = ", ".join(f"{k}={v:.4g}" for k, v in p["params"].items())
            rmse = p["training_rmse"]
            lines.append(f"{'':<10}{m} tuned on training missions: {values} (training RMSE {rmse:.2f} dB)")
    return "\n".join(lines)


def write_plots(r: dict[str, Any], out: Path, seed: int) -> list[str]:
    """Error-versus-horizon per environment and MATTE's attenuation map of the first one."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:
        raise InvalidInputError("plots need matplotlib: pip install autoteach[plot] (or pass --no-plots)") from err
    import numpy as np

    from autoteach.radio import MATTE, simulate

    out.mkdir(parents=True, exist_ok=True)
    files = []
    envs = list(r["results"])
    fig, axes = plt.subplots(1, len(envs), figsize=(4.5 * len(envs), 3.6), squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        row = r["results"][env]
        h = np.asarray(row["horizons"])
        for m, v in row["models"].items():
            ax.plot(h + 1.0, np.asarray(v["rmse"]) ** 2, marker="o", label=m)
        ax.set_title(env)
        ax.set_xlabel("prediction horizon (s, bin centre)")
        ax.set_ylabel("MSE (dB$^2$)")
        ax.grid(alpha=0.3)
    axes[0][0].legend()
    fig.tight_layout()
    path = out / "radio_error_vs_horizon.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    files.append(str(path))
    sim = simulate(envs[0], duration=r["duration"], seed=seed, sigma=r["sigma"])
    occ = sim.occupancy_at(float(sim.times[-1]))
    model = MATTE().fit(sim.tx, sim.rx, sim.rss, occupancy=occ)
    att = model.attenuation_map()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    x0, y0, x1, y1 = occ.bounds
    im = axes[0].imshow(att, origin="lower", extent=(x0, x1, y0, y1), cmap="RdBu", vmin=-20, vmax=20)
    axes[0].set_title(f"MATTE attenuation (dB/m), {envs[0]}")
    fig.colorbar(im, ax=axes[0])
    im2 = axes[1].imshow(-sim.attenuation, origin="lower", extent=(x0, x1, y0, y1), cmap="RdBu", vmin=-20, vmax=20)
    axes[1].set_title("simulator truth (dB/m)")
    fig.colorbar(im2, ax=axes[1])
    for ax in axes:
        for p in sim.positions:
            ax.plot(p[:, 0], p[:, 1], lw=0.6, color="k")
    fig.tight_layout()
    path = out / "radio_attenuation_map.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    files.append(str(path))
    return files


def run(args: argparse.Namespace) -> int:
    """Run the comparison; print the table (or JSON) and write the plots."""
    from autoteach.radio import ENVIRONMENTS, compare

    if not args.simulate:
        raise InvalidInputError("autoteach radio: only --simulate is available (real logs: use autoteach.radio)")
    envs = tuple(e.strip() for e in args.environments.split(",") if e.strip())
    bad = [e for e in envs if e not in ENVIRONMENTS]
    if bad or not envs:
        raise InvalidInputError(
            f"--environments must name some of {', '.join(ENVIRONMENTS)}, got {args.environments!r}"
        )
    if args.stride < 1:
        raise InvalidInputError(f"--stride must be >= 1, got {args.stride}")
    if not args.duration > 30:  # written so that NaN fails
        raise InvalidInputError(f"--duration must be > 30 s, got {args.duration:g}")
    if not (math.isfinite(args.sigma) and args.sigma >= 0):
        raise InvalidInputError(f"--sigma must be a finite shadowing deviation >= 0 dB, got {args.sigma:g}")
    if args.tune:
        from autoteach.radio_tuning import compare_tuned

        result = compare_tuned(envs, duration=args.duration, seed=args.seed, sigma=args.sigma, stride=args.stride)
    else:
        result = compare(envs, duration=args.duration, seed=args.seed, sigma=args.sigma, stride=args.stride)
    if not args.no_plots:
        result["plots"] = write_plots(result, args.out, args.seed)
    if args.json:
        print(json.dumps(result))
    else:
        print(format_table(result))
        for f in result.get("plots", []):
            print(f"wrote {f}")
    return 0
