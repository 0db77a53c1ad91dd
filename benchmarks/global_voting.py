"""Global voting (Algorithm 3): Y-count vs pair count on the density mismatch of Fig. 3.12, the
vote maps of Fig. 3.13, and time against a NumPy/SciPy implementation of the same vote.

Density mismatch (seeded trials): ``Y`` a chevron sampled every 0.05; ``X`` = ``Y`` under a random
rigid transform plus a straight edge sampled 10× denser (600 points) nearby. Success: RMS of the
moved ``Y`` to its true placement < 0.1 (2 % of the shape size is ≈ 0.07).

Timing: 2-D curves with 50 % uniform outliers, N = M; the peer computes the same local frames
(scipy ``cKDTree`` + ``numpy.linalg.eigh``), the same pair transforms and groups them by the full
bin tuple with ``numpy.unique`` (hash/sort clustering, O(n log n)), counting distinct Y per cell.

Run: ``python benchmarks/global_voting.py`` (``--trials 100 --figure docs/figures/vote_maps.png``).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.spatial import cKDTree

from autoteach.polygon import global_voting, vote_cells

CHEVRON = [(0.0, 0.0), (2.0, 1.0), (3.2, -0.4), (2.7, -0.9)]


def polyline(vertices: list[tuple[float, float]], spacing: float) -> np.ndarray:
    """Points every ``spacing`` along a polyline."""
    pts = []
    for a, b in zip(vertices[:-1], vertices[1:], strict=False):
        a, b = np.asarray(a), np.asarray(b)
        n = int(round(np.linalg.norm(b - a) / spacing))
        pts.extend(a + (b - a) * k / n for k in range(n))
    return np.array(pts)


def rot2(a: float) -> np.ndarray:
    """2-D rotation matrix."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def mismatch_case(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fig. 3.12: sparse model copy plus a dense straight edge."""
    rng = np.random.default_rng(seed)
    y = polyline(CHEVRON, 0.05)
    r, t = rot2(rng.uniform(-np.pi, np.pi)), rng.uniform(-3, 3, 2)
    a = rng.uniform(-np.pi, np.pi)
    start = t + 6.0 * np.array([np.cos(a), np.sin(a)])
    d = np.array([np.cos(a + 1.0), np.sin(a + 1.0)])
    x = np.vstack([y @ r.T + t, start + np.outer(np.arange(600) * 0.005, d)])
    return x, y, r, t


def numpy_voting(x: np.ndarray, y: np.ndarray, k: int = 10, angle_bin: float = 0.2) -> tuple[float, np.ndarray]:
    """Same vote with NumPy/SciPy: returns (best angle, best translation) by Y-count."""

    def frames(p: np.ndarray) -> np.ndarray:
        _, idx = cKDTree(p).query(p, k=k)
        nb = p[idx] - p[idx].mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", nb, nb)
        _, v = np.linalg.eigh(cov)
        t = v[:, :, 1]
        return np.arctan2(t[:, 1], t[:, 0])

    cy = y.mean(axis=0)
    yc = y - cy
    rms = np.sqrt(np.mean(np.sum(yc**2, axis=1)))
    tb = angle_bin * rms
    ax, ay = frames(x), frames(y)
    th = (ax[:, None, None] - ay[None, :, None] - np.array([0.0, np.pi])[None, None, :]).reshape(-1)
    th = (th + np.pi) % (2 * np.pi) - np.pi
    ii = np.repeat(np.arange(len(x)), 2 * len(y))
    jj = np.tile(np.repeat(np.arange(len(y)), 2), len(x))
    c, s = np.cos(th), np.sin(th)
    tx = x[ii, 0] - (c * yc[jj, 0] - s * yc[jj, 1])
    ty = x[ii, 1] - (s * yc[jj, 0] + c * yc[jj, 1])
    nb = int(round(2 * np.pi / angle_bin))
    keys = np.stack(
        [
            np.floor((th + np.pi) / (2 * np.pi / nb)).astype(np.int64) % nb,
            np.floor(tx / tb).astype(np.int64),
            np.floor(ty / tb).astype(np.int64),
        ],
        axis=1,
    )
    cells, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    uniq = np.unique(np.stack([inv, jj], axis=1), axis=0)
    ycount = np.bincount(uniq[:, 0], minlength=len(cells))
    best = int(np.argmax(ycount))
    m = inv == best
    ang = np.arctan2(np.mean(np.sin(th[m])), np.mean(np.cos(th[m])))
    t = np.array([tx[m].mean(), ty[m].mean()]) - rot2(ang) @ cy
    return ang, t


def timing_case(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A 2-D curve of n points and its moved copy with n/2 outliers."""
    rng = np.random.default_rng(n)
    s = np.linspace(0, 4, n, endpoint=False)
    y = np.c_[s, np.sin(1.7 * s)]
    x = np.vstack([y @ rot2(2.0).T + np.array([3.0, 1.0]), rng.uniform([-2, -4], [8, 6], (n // 2, 2))])
    return x, y


def main() -> None:
    """Run the comparisons and print the tables."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--figure", default=None, help="write the Fig. 3.13 vote maps (PNG) here")
    args = ap.parse_args()

    ok = {"y": 0, "pairs": 0}
    for seed in range(args.trials):
        x, y, r, t = mismatch_case(seed)
        for count in ok:
            h = global_voting(x, y, k=1, count=count)[0]
            ok[count] += float(np.sqrt(np.mean(np.sum((h.apply(y) - (y @ r.T + t)) ** 2, axis=1)))) < 0.1
    print(
        f"density mismatch (Fig. 3.12), {args.trials} trials: "
        f"success Y-count {ok['y']}/{args.trials}, pairs {ok['pairs']}/{args.trials}"
    )

    print(f"{'N=M':>6s} {'autoteach ms':>13s} {'numpy/scipy ms':>15s} {'ratio':>7s} {'same best':>10s}")
    for n in (100, 200, 400, 800):
        x, y = timing_case(n)
        ta, tp = [], []
        for _ in range(3):
            t0 = time.perf_counter()
            h = global_voting(x, y, k=1)[0]
            t1 = time.perf_counter()
            ang, tr = numpy_voting(x, y)
            t2 = time.perf_counter()
            ta.append(t1 - t0)
            tp.append(t2 - t1)
        a_at = np.arctan2(h.rotation[1, 0], h.rotation[0, 0])
        same = abs((a_at - ang + np.pi) % (2 * np.pi) - np.pi) < 0.1 and np.linalg.norm(h.translation - tr) < 0.2
        ma, mp = statistics.median(ta), statistics.median(tp)
        print(f"{n:6d} {1e3 * ma:13.2f} {1e3 * mp:15.2f} {mp / ma:7.1f} {str(same):>10s}")

    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        x, y, r, t = mismatch_case(0)
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
        axes[0].plot(x[:, 0], x[:, 1], ".", ms=2, label="X")
        axes[0].plot(*(y @ r.T + t).T, ".", ms=3, label="Y at truth")
        axes[0].set_title("Fig. 3.12: X with a dense outlier edge")
        axes[0].axis("equal")
        axes[0].legend()
        for ax, count in zip(axes[1:], ("pairs", "y"), strict=False):
            cells = vote_cells(x, y, count=count, min_votes=1)
            tb = 0.2 * np.sqrt(np.mean(np.sum((y - y.mean(0)) ** 2, axis=1)))
            grid: dict[tuple[int, int], float] = {}
            for c in cells:
                key = tuple(np.floor(c.translation / tb).astype(int))
                v = c.pair_votes if count == "pairs" else c.votes
                grid[key] = max(grid.get(key, 0), v)  # max over rotation, as in Fig. 3.13
            keys = np.array(list(grid))
            img = np.zeros((np.ptp(keys[:, 1]) + 1, np.ptp(keys[:, 0]) + 1))
            for (kx, ky), v in grid.items():
                img[ky - keys[:, 1].min(), kx - keys[:, 0].min()] = v
            ext = [
                keys[:, 0].min() * tb,
                (keys[:, 0].max() + 1) * tb,
                keys[:, 1].min() * tb,
                (keys[:, 1].max() + 1) * tb,
            ]
            im = ax.imshow(img, origin="lower", extent=ext, cmap="viridis")
            truth_t = t + r @ np.zeros(2)
            ax.plot(*truth_t, "r+", ms=14, mew=2, label="true translation")
            ax.set_title(f"vote map (max over rotation), {'pair count' if count == 'pairs' else 'Y-count'}")
            ax.legend(loc="upper right")
            fig.colorbar(im, ax=ax)
        fig.tight_layout()
        fig.savefig(args.figure, dpi=110)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
