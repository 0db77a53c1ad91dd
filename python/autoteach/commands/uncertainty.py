"""The ``autoteach uncertainty`` command: the worked examples of seed ch. 8.

``autoteach uncertainty --demo [--out DIR] [--json]`` prints Fig. 8.6 (the posterior covariance
with deterministic correspondences, in the full- and half-extent parametrisations, and the four
standard deviations the text mixes up), Fig. 8.5 (JIoU under ``p_G`` and ``P_PDQ``) and the
variational-Bayes posterior of Fig. 8.7, and writes ``fig_8_7.png`` (the joint ``p(c2, w | x)``)
and ``fig_8_4.png`` (the spatial distribution of the Fig. 8.6 box) into ``--out`` with matplotlib
(the ``plot`` extra).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``uncertainty`` sub-command."""
    p = sub.add_parser(
        "uncertainty",
        parents=[common],
        help="probabilistic boxes: the seed's Fig. 8.5-8.7 examples (label uncertainty, JIoU)",
    )
    p.add_argument("--demo", action="store_true", help="reproduce Fig. 8.5/8.6 and plot Fig. 8.7")
    p.add_argument("--out", type=Path, default=Path("."), help="folder for the plots (default: current)")
    p.add_argument("--no-plot", action="store_true", help="skip the matplotlib figures")
    p.set_defaults(func=_run)


def demo() -> dict[str, Any]:
    """The numbers of Fig. 8.5, 8.6 and 8.7."""
    from autoteach.uncertainty import fig_8_5, fig_8_6, fig_8_7

    f6 = fig_8_6()
    vb = fig_8_7()
    return {
        "fig_8_6": {
            "cov_full_extent": f6["cov_full_extent"].round(6).tolist(),
            "cov_half_extent": f6["cov_half_extent"].round(6).tolist(),
            "max_abs_diff_to_seed": float(np.abs(f6["cov_half_extent"] - f6["seed_matrix"]).max()),
            "eigen_std": f6["eigen_std"],
            "edge_std": f6["edge_std"],
        },
        "fig_8_5": {"jiou_pg": fig_8_5()["pg"], "jiou_pdq": fig_8_5()["pdq"]},
        "fig_8_7": {"cov": vb.cov[:4, :4].round(6).tolist()},
    }


def _plots(out: Path) -> list[str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise SystemExit("plots need matplotlib: pip install autoteach[plot] (or pass --no-plot)") from None
    from autoteach.uncertainty import FIG_8_6_BOX, FIG_8_6_POINTS, Grid, corners, fig_8_7, spatial_distribution

    out.mkdir(parents=True, exist_ok=True)
    vb = fig_8_7()
    # Fig. 8.7: joint Gaussian of (c2, w).
    idx = [1, 3]
    m = vb.mean[idx]
    c = vb.cov[np.ix_(idx, idx)]
    gx, gy = np.meshgrid(np.linspace(m[0] - 1.0, m[0] + 1.0, 200), np.linspace(m[1] - 2.0, m[1] + 2.0, 200))
    d = np.stack([gx - m[0], gy - m[1]], axis=-1)
    q = np.einsum("...i,ij,...j->...", d, np.linalg.inv(c), d)
    dens = np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(np.linalg.det(c)))
    fig, ax = plt.subplots(figsize=(5, 4))
    cs = ax.contourf(gx, gy, dens, levels=20)
    fig.colorbar(cs, ax=ax)
    ax.plot(gx[0], 2 * (0.9 - gx[0]), "w--", lw=1, label="c2 + w/2 = 0.9 (observed edge)")
    ax.set_xlabel("c2 [m]")
    ax.set_ylabel("w [m]")
    ax.set_title("Fig. 8.7: p(c2, w | x) by variational Bayes")
    ax.legend(loc="upper right", fontsize=7)
    files = [str(out / "fig_8_7.png")]
    fig.savefig(files[0], dpi=120, bbox_inches="tight")
    plt.close(fig)
    # Fig. 8.4-style spatial distribution of the Fig. 8.6 box (moments, Appendix A).
    grid = Grid.around(FIG_8_6_BOX, n=120, margin=1.5)
    p = spatial_distribution(FIG_8_6_BOX, vb.cov, grid=grid)
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.imshow(p, origin="lower", extent=(grid.x0, grid.x0 + grid.nx * grid.dx, grid.y0, grid.y0 + grid.ny * grid.dy))
    cr = corners(FIG_8_6_BOX)
    ax.plot(*np.vstack([cr, cr[:1]]).T, "w-", lw=1)
    ax.plot(*FIG_8_6_POINTS.T, "rx")
    ax.set_title("p_G(u) of the Fig. 8.6 label (eq. 8.3, Appendix A)")
    files.append(str(out / "fig_8_4.png"))
    fig.savefig(files[1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    return files


def _run(args: argparse.Namespace) -> int:
    if not args.demo:
        print("autoteach uncertainty: error: nothing to do: --demo is expected (the only mode)", file=sys.stderr)
        return 2
    result = demo()
    if not args.no_plot:
        result["plots"] = _plots(args.out)
    if args.json:
        print(json.dumps(result))
        return 0
    f6 = result["fig_8_6"]
    print("Fig. 8.6 posterior covariance (sigma 0.2 m, prior 100^2):")
    print("  [c1, c2, l, w]     (full extents, eq. 8.1):", f6["cov_full_extent"])
    print("  [c1, c2, l/2, w/2] (half extents = seed):  ", f6["cov_half_extent"])
    print(f"  max |diff| to the seed's matrix: {f6['max_abs_diff_to_seed']:.2e}")
    e, g = f6["eigen_std"], f6["edge_std"]
    print(f"  eigen std (half-extent matrix): {e['small']:.3f} m, {e['large']:.3f} m")
    print(f"  edge std: observed c1+l/2 {g['observed']:.3f} m, unobserved c1-l/2 {g['unobserved']:.3f} m")
    print("  (the seed's '0.09 m / 0.43 m' mixes an eigen std with an edge std)")
    f5 = result["fig_8_5"]
    print(f"Fig. 8.5 JIoU: p_G {f5['jiou_pg']:.3f}, P_PDQ {f5['jiou_pdq']:.3f}")
    print("Fig. 8.7 VB covariance [c1, c2, l, w]:", result["fig_8_7"]["cov"])
    for f in result.get("plots", []):
        print("wrote", f)
    return 0
