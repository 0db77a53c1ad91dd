"""Efficiency of the geometric ellipse fit: centre error against the Cramér–Rao bound (issue 3 / 42 note).

Arcs as ``benchmarks/ellipse_fit.py`` (90–160° of ellipses with a = 150–350 px, b/a = 0.2–1, one
point per pixel of arc length, isotropic Gaussian noise of 0.5 px). For each of ``--arcs`` arcs,
``--trials`` noise draws are fitted with ``fit_ellipse(method="geometric")``; the mean squared
centre error is compared with the bound.

The bound (independent of the fit's code): with the points ``x(tᵢ) + σ nᵢ εᵢ`` and the angles
``tᵢ`` as nuisance parameters, only the normal component informs ``(cx, cy, a, b, θ)``, so the
Fisher information is ``σ⁻² Σ Jᵢᵀ Jᵢ`` with ``Jᵢ = nᵢᵀ ∂x(tᵢ)/∂(cx, cy, a, b, θ)`` at the truth
(the tangential noise moves ``tᵢ``). The efficiency is ``√(mean |ĉ − c|²) / √(CRB_cx + CRB_cy)``
per arc; 1 is efficient. Reported: the median and the 10/90 % quantiles over the arcs, and
the ratio of the pooled mean squared error to the pooled bound.

Run: ``PYTHONPATH=python /work/venv/bin/python benchmarks/ellipse_crb.py --arcs 60 --trials 100``.
"""

from __future__ import annotations

import argparse

import numpy as np

from autoteach.detect import fit_ellipse

NOISE_PX = 0.5


def arc_points(cx, cy, a, b, th, t0, span):
    """Points one pixel of arc length apart, their angles and unit normals."""
    ts = np.linspace(t0, t0 + span, 4000)
    c, s = np.cos(th), np.sin(th)
    x = np.stack([cx + c * a * np.cos(ts) - s * b * np.sin(ts), cy + s * a * np.cos(ts) + c * b * np.sin(ts)], 1)
    seg = np.r_[0, np.cumsum(np.hypot(*np.diff(x, axis=0).T))]
    keep = np.searchsorted(seg, np.arange(0, seg[-1], 1.0))
    t = ts[keep]
    pts = x[keep]
    # Unit normal ∝ R·(b cos t, a sin t).
    nx, ny = b * np.cos(t), a * np.sin(t)
    n = np.stack([c * nx - s * ny, s * nx + c * ny], 1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return t, pts, n


def crb_centre(a, b, th, t, n, sigma):
    """CRB of cx plus that of cy (see the module docstring)."""
    c, s = np.cos(th), np.sin(th)
    ca, sa = np.cos(t), np.sin(t)
    d = np.zeros((len(t), 2, 5))
    d[:, 0, 0] = 1.0
    d[:, 1, 1] = 1.0
    d[:, :, 2] = np.stack([c * ca, s * ca], 1)
    d[:, :, 3] = np.stack([-s * sa, c * sa], 1)
    d[:, :, 4] = np.stack([-s * a * ca - c * b * sa, c * a * ca - s * b * sa], 1)
    j = np.einsum("ni,nij->nj", n, d)
    info = j.T @ j / sigma**2
    cov = np.linalg.inv(info)
    return cov[0, 0] + cov[1, 1]


def main() -> None:
    """Run and print the efficiency."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arcs", type=int, default=60)
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--seed", type=int, default=20240601)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    ratios, mse_all, crb_all = [], [], []
    for _ in range(args.arcs):
        a = rng.uniform(150, 350)
        b = a * rng.uniform(0.2, 1.0)
        th = rng.uniform(-np.pi / 2, np.pi / 2)
        cx, cy = rng.uniform(400, 900), rng.uniform(300, 500)
        span = np.radians(rng.uniform(90, 160))
        t, pts, n = arc_points(cx, cy, a, b, th, rng.uniform(0, 2 * np.pi), span)
        bound = crb_centre(a, b, th, t, n, NOISE_PX)
        errs = []
        for _ in range(args.trials):
            noisy = pts + rng.normal(0, NOISE_PX, pts.shape)
            e = fit_ellipse(noisy, method="geometric").ellipse
            errs.append((e.cx - cx) ** 2 + (e.cy - cy) ** 2)
        mse = float(np.mean(errs))
        ratios.append(np.sqrt(mse / bound))
        mse_all.append(mse)
        crb_all.append(bound)
    r = np.array(ratios)
    print(f"{args.arcs} arcs x {args.trials} trials, noise {NOISE_PX} px")
    print(
        f"efficiency sqrt(MSE/CRB) of the centre: median {np.median(r):.3f}, "
        f"10-90 % {np.quantile(r, 0.1):.3f}-{np.quantile(r, 0.9):.3f}, "
        f"pooled {np.sqrt(np.sum(mse_all) / np.sum(crb_all)):.3f}"
    )


if __name__ == "__main__":
    main()
