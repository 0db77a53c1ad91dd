"""Probabilistic boxes (JIoU) and sparse non-homogeneous pooling (SHPL) against peers.

SHPL (seed eq. 7.4-7.8) at the issue's size: 20 000 LiDAR points, 512 channels, 155x46 image
cells -> 75x75 BEV cells. Peer: ``scipy.sparse`` in its strongest configuration (CSR times a
C-contiguous dense matrix forward; a pre-transposed CSR for the backward pass), on the same
kernel and the same features; both are checked to agree to 1e-5 first. Timings are medians. The
memory floor of each pass (read the gathered input once, write the output once, measured with
NumPy in the same run) bounds what any implementation can reach on the machine.

JIoU (eq. 8.4): a 15 000-pair evaluation of Gaussian boxes on 900-cell grids with ``p_G``
(eq. 8.3) evaluated per pair; 10 000 deterministic pairs against ``shapely`` polygons (accuracy
and time); the eq. 8.5 bounds on 1 000 Monte Carlo cases.

Run: ``RAYON_NUM_THREADS=1 python benchmarks/uncertainty_pooling.py [--repeats 30]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import scipy.sparse as sp
import shapely

from autoteach import uncertainty as U
from autoteach.fusion import SparsePooling

P = np.array([[621.0, -700.0, 0.0, 0.0], [187.0, 0.0, -700.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
IMAGE = (46, 155, 8.0)
BEV = (0.0, -37.5, 1.0, 75, 75)


def median_ms(f, repeats):
    f()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def shpl(repeats):
    rng = np.random.default_rng(0)
    x = rng.uniform(2, 70, 20_000)
    pts = np.column_stack([x, rng.uniform(-0.8, 0.8, x.size) * x, rng.uniform(-0.2, 0.2, x.size) * x])
    build = median_ms(lambda: SparsePooling.build(pts, P, IMAGE, BEV), repeats)
    op = SparsePooling.build(pts, P, IMAGE, BEV)
    indptr, indices, data, shape = op.csr("image_to_bev")
    print(f"SHPL: {op.kept} points kept, dropped {op.dropped}, nnz {len(data)}, kernel {shape}")
    print(f"  build: {build:.3f} ms")
    for dtype in (np.float32, np.float64):
        S = sp.csr_matrix((data.astype(dtype), indices, indptr), shape=shape)
        St = S.T.tocsr()
        feats = rng.normal(size=(shape[1], 512)).astype(dtype)
        grad = rng.normal(size=(shape[0], 512)).astype(dtype)
        assert np.abs(op.forward(feats) - S @ feats).max() < 1e-5
        assert np.abs(op.backward(grad) - St @ grad).max() < 1e-5
        rows = {
            "forward": (
                median_ms(lambda f=feats: op.forward(f), repeats),
                median_ms(lambda s=S, f=feats: s @ f, repeats),
            ),
            "backward": (
                median_ms(lambda g=grad: op.backward(g), repeats),
                median_ms(lambda s=St, g=grad: s @ g, repeats),
            ),
        }
        kind = np.dtype(dtype).name
        for name, (ours, peer) in rows.items():
            print(f"  {kind} {name}: autoteach {ours:.2f} ms, scipy.sparse {peer:.2f} ms, ratio {ours / peer:.2f}")
        memory_floor(kind, feats, grad, indptr, indices, shape, repeats)


def memory_floor(kind, feats, grad, indptr, indices, shape, repeats):
    """Time floor of a pooling pass in the same run: read each gathered input row once, write the output once.

    The read is a NumPy reduction over the input rows the kernel gathers (forward: the image cells
    with an entry; backward: the BEV cells with an entry); the write fills a freshly allocated
    output, as both the operator and ``scipy.sparse`` return a new array.
    """
    gathered = np.ascontiguousarray(feats[np.unique(indices)])
    grad = np.ascontiguousarray(grad[np.flatnonzero(np.diff(indptr))])
    read_fwd = median_ms(lambda: gathered.sum(axis=0), repeats)
    read_bwd = median_ms(lambda: grad.sum(axis=0), repeats)
    write_fwd = median_ms(lambda: np.ones((shape[0], feats.shape[1]), feats.dtype), repeats)
    write_bwd = median_ms(lambda: np.ones((shape[1], feats.shape[1]), feats.dtype), repeats)
    print(
        f"  {kind} memory floor: forward read {gathered.nbytes / 1e6:.1f} MB {read_fwd:.2f} ms + write "
        f"{write_fwd:.2f} ms = {read_fwd + write_fwd:.2f} ms; backward read {grad.nbytes / 1e6:.1f} MB "
        f"{read_bwd:.2f} ms + write {write_bwd:.2f} ms = {read_bwd + write_bwd:.2f} ms"
    )


def jiou(repeats):
    rng = np.random.default_rng(1)
    n = 15_000
    a = np.column_stack(
        [rng.uniform(-1, 1, (n, 2)), rng.normal(4.2, 0.2, n), rng.normal(1.8, 0.1, n), rng.uniform(-3, 3, n)]
    )
    b = a + rng.normal(size=(n, 5)) * np.array([0.3, 0.3, 0.1, 0.05, 0.05])
    ca = np.broadcast_to(np.diag([0.04, 0.01, 0.06, 0.01, 0.003]), (n, 5, 5))
    cb = np.broadcast_to(np.diag([0.02, 0.02, 0.02, 0.02, 0.001]), (n, 5, 5))
    t = median_ms(lambda: U.jiou(a, ca, b, cb, grid=30), max(3, repeats // 10))
    print(f"JIoU: {n} Gaussian pairs on 30x30 grids (64 samples, p_G included): {t:.0f} ms, {n / t * 1e3:,.0f} pairs/s")
    m = 10_000
    da, db = a[:m], b[:m]
    t0 = time.perf_counter()
    ours = U.jiou(da, None, db, None)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    pa = shapely.polygons(U.corners(da))
    pb = shapely.polygons(U.corners(db))
    truth = shapely.area(shapely.intersection(pa, pb)) / shapely.area(shapely.union(pa, pb))
    t_peer = time.perf_counter() - t0
    print(
        f"  deterministic JIoU vs shapely IoU on {m} pairs: max |diff| {np.abs(ours - truth).max():.1e}; "
        f"autoteach {1e3 * t_ours:.1f} ms, shapely (vectorised) {1e3 * t_peer:.1f} ms"
    )


def bounds(cases=1000):
    rng = np.random.default_rng(2)
    low_ok = up_ok = 0
    for _ in range(cases):
        mean = np.array([0.0, 0.0, rng.uniform(3, 5), rng.uniform(1.5, 2.5), rng.uniform(-0.5, 0.5)])
        samples = mean + rng.normal(size=(int(rng.integers(2, 12)), 5)) * rng.uniform(0.05, 0.6) * np.array(
            [1, 1, 0.5, 0.3, 0.2]
        )
        samples[:, 2:4] = np.abs(samples[:, 2:4]) + 0.3
        pred = mean + rng.normal(size=5) * np.array([0.5, 0.5, 0.3, 0.2, 0.1])
        pred[2:4] = np.abs(pred[2:4]) + 0.3
        grid = U.Grid.around(np.vstack([samples, pred]), n=60, margin=0.2)
        pl = U.rasterize(samples, np.full(len(samples), 1 / len(samples)), grid)
        pp = U.rasterize([pred], [1.0], grid)
        j = U.jiou_grid(pl, pp)
        cells = grid.centres().reshape(-1, 2)

        def inside(b, cells=cells):
            c = cells - b[:2]
            u = np.cos(b[4]) * c[:, 0] + np.sin(b[4]) * c[:, 1]
            v = -np.sin(b[4]) * c[:, 0] + np.cos(b[4]) * c[:, 1]
            return (np.abs(u) <= b[2] / 2) & (np.abs(v) <= b[3] / 2)

        mp = inside(pred)
        ms = [inside(s) for s in samples]
        lower = np.mean([np.sum(m & mp) / np.sum(m | mp) for m in ms])
        upper = np.mean([np.sum(m & mp) for m in ms]) / np.mean([max(m.sum(), mp.sum()) for m in ms])
        low_ok += lower - 1e-12 <= j
        up_ok += j <= upper + 1e-12
    print(f"eq. 8.5 on {cases} Monte Carlo cases: lower bound E[IoU] <= JIoU holds on {low_ok}, upper bound on {up_ok}")


def cars():
    """Eq. 8.12 sigma recovery and the Fig. 8.9 corner/centre total variances on simulated scans."""
    for sigma in (0.1, 0.2, 0.3):
        labels, scans = U.simulate_cars(40, sigma=sigma, seed=3, min_points=20)
        est = U.estimate_noise(labels, scans, tolerance=1e-6)
        print(f"eq. 8.12: true sigma {sigma} m, estimated {est.sigma:.4f} m ({100 * (est.sigma / sigma - 1):+.1f} %)")
    labels, scans = U.simulate_cars(200, sigma=0.2, seed=11, min_points=5)
    v0 = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    tvs = []
    for box, pts in zip(labels, scans, strict=True):
        post = U.label_uncertainty(box, pts, sigma=0.2, prior=1.0)
        order = np.argsort(np.linalg.norm(U.corners(box), axis=1))
        tvs.append(U.total_variance(box, post.cov, np.vstack([v0[order], [0.0, 0.0]])))
    tv = np.array(tvs)
    means = ", ".join(f"{k} {v:.4f}" for k, v in zip(("C1", "C2", "C3", "C4", "centre"), tv.mean(axis=0), strict=True))
    print(f"Fig. 8.9 on {len(tv)} cars (sigma 0.2 m, prior w=1): mean TV {means} m^2")
    print(f"  nearest corner below the centre in {100 * np.mean(tv[:, 0] < tv[:, 4]):.0f} % of cars")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args()
    print(f"RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', 'all')}")
    shpl(args.repeats)
    jiou(args.repeats)
    bounds()
    cars()


if __name__ == "__main__":
    main()
