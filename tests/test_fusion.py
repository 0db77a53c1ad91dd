"""Tests of :mod:`autoteach.fusion` (seed ch. 7: SHPL eq. 7.4-7.9, non-zero max-min pooling)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from autoteach.errors import InvalidInputError
from autoteach.fusion import SparsePooling, maxmin_pool, maxmin_pool_backward

# A KITTI-like camera looking along +x: u = 700 (-y/x) + 600, v = 700 (-z/x) + 180.
P = np.array([[600.0, -700.0, 0.0, 0.0], [180.0, 0.0, -700.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
IMAGE = (23, 78, 16.0)
BEV = (0.0, -30.0, 1.0, 60, 60)


def _cloud(n, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-5, 60, n), rng.uniform(-30, 30, n), rng.uniform(-2, 1, n)])


def _reference_kernel(points, direction, k):
    """Eq. 7.4-7.8 written directly in NumPy (an independent dense construction)."""
    h = np.c_[points, np.ones(len(points))] @ P.T
    ok = h[:, 2] > 0
    u, v = h[:, 0] / np.where(ok, h[:, 2], 1), h[:, 1] / np.where(ok, h[:, 2], 1)
    col, row = np.floor(u / IMAGE[2]), np.floor(v / IMAGE[2])
    ok &= (col >= 0) & (row >= 0) & (col < IMAGE[1]) & (row < IMAGE[0])
    ix, iy = np.floor((points[:, 0] - BEV[0]) / BEV[2]), np.floor((points[:, 1] - BEV[1]) / BEV[2])
    ok &= (ix >= 0) & (iy >= 0) & (ix < BEV[3]) & (iy < BEV[4])
    row, col, ix, iy = (a[ok].astype(int) for a in (row, col, ix, iy))
    n_img, n_bev = IMAGE[0] * IMAGE[1], BEV[3] * BEV[4]
    img, bev = row * IMAGE[1] + col, ix * BEV[4] + iy
    if direction == "image_to_bev":
        out, src_rc, shape = bev, (row, col), (IMAGE[0], IMAGE[1])
        K = np.zeros((n_bev, n_img))
    else:
        out, src_rc, shape = img, (ix, iy), (BEV[3], BEV[4])
        K = np.zeros((n_img, n_bev))
    count = np.bincount(out, minlength=K.shape[0])
    r = k // 2
    for i in range(len(out)):
        a, b = src_rc[0][i], src_rc[1][i]
        cells = [
            (x, y)
            for x in range(max(a - r, 0), min(a + r + 1, shape[0]))
            for y in range(max(b - r, 0), min(b + r + 1, shape[1]))
        ]
        for x, y in cells:
            K[out[i], x * shape[1] + y] += 1.0 / (count[out[i]] * len(cells))
    return K


@pytest.mark.parametrize("k", [1, 3])
@pytest.mark.parametrize("direction", ["image_to_bev", "bev_to_image"])
def test_forward_backward_equal_dense_kernel_and_scipy(direction, k):
    pts = _cloud(2000)
    op = SparsePooling.build(pts, P, IMAGE, BEV, neighbourhood=k)
    K = _reference_kernel(pts, direction, k)
    assert np.abs(op.dense(direction) - K).max() < 1e-12
    indptr, indices, data, shape = op.csr(direction)
    S = sp.csr_matrix((data, indices, indptr), shape=shape)
    rng = np.random.default_rng(1)
    for dtype, tol in ((np.float64, 1e-12), (np.float32, 1e-6)):
        x = rng.normal(size=(K.shape[1], 16)).astype(dtype)
        y = op.forward(x, direction)
        assert y.dtype == dtype
        assert np.abs(y - K @ x.astype(np.float64)).max() < tol
        assert np.abs(y - S @ x).max() < tol
        g = rng.normal(size=(K.shape[0], 16)).astype(dtype)
        gx = op.backward(g, direction)
        assert np.abs(gx - K.T @ g.astype(np.float64)).max() < tol
        assert np.abs(gx - S.T @ g).max() < tol


def test_gradient_passes_a_finite_difference_check():
    pts = _cloud(800, seed=2)
    op = SparsePooling.build(pts, P, IMAGE, BEV, neighbourhood=3)
    rng = np.random.default_rng(3)
    x = rng.normal(size=(IMAGE[0], IMAGE[1], 4))
    w = rng.normal(size=(BEV[3], BEV[4], 4))

    def loss(z):
        return float(np.sum(np.tanh(op.forward(z)) * w))

    y = op.forward(x)
    grad = op.backward((1 - np.tanh(y) ** 2) * w)
    eps = 1e-6
    for idx in rng.choice(x.size, 40, replace=False):
        e = np.zeros(x.size)
        e[idx] = eps
        e = e.reshape(x.shape)
        fd = (loss(x + e) - loss(x - e)) / (2 * eps)
        assert abs(fd - grad.ravel()[idx]) < 1e-6


def test_points_behind_and_outside_are_dropped_and_counted():
    pts = np.array([[10.0, 0.0, 0.0], [-3.0, 0.0, 0.0], [10.0, 100.0, 0.0], [100.0, 0.0, 0.0], [20.0, 1.0, -1.0]])
    op = SparsePooling.build(pts, P, IMAGE, BEV)
    assert op.dropped == {"behind": 1, "outside_image": 1, "outside_bev": 1}
    assert op.kept == 2


FIG_7_6 = np.array(
    [
        [3, 1, 1, 3, -9, -9, -9, -9],
        [2, 2, 2, 2, -9, -9, -9, -9],
        [3, 1, 2, 1, -9, -9, -9, -9],
        [2, 3, -1, -1, -2, -2, -9, -9],
        [-9, -9, -1, -2, -1, -1, -9, -9],
        [-9, -9, -2, -1, -2, -2, -9, -9],
        [-9, -9, -1, -2, -1, -1, -9, -9],
        [-9, -9, -9, -9, -9, -9, -9, -9],
    ],
    dtype=float,
)


def _maxmin_reference(x):
    h, w, c = x.shape
    out = np.zeros(((h + 1) // 2, (w + 1) // 2, 2 * c))
    for i in range(0, h, 2):
        for j in range(0, w, 2):
            blk = x[i : i + 2, j : j + 2].reshape(-1, c)
            for k in range(c):
                nz = blk[:, k][blk[:, k] != 0]
                if nz.size:
                    out[i // 2, j // 2, k], out[i // 2, j // 2, c + k] = nz.max(), nz.min()
    return out


def test_fig_7_6_example_values():
    y = FIG_7_6[..., None]
    for _ in range(3):
        ref = _maxmin_reference(y)
        y = maxmin_pool(y)
        assert np.array_equal(y, ref)
    assert y.shape == (1, 1, 8)
    # Besides the extremes 3 and -9, the cluster edges 2, 1, -1, -2 survive (caption of Fig. 7.6).
    assert set(y.ravel()) == {3.0, 2.0, 1.0, -1.0, -2.0, -9.0}
    # Odd sizes and float32: partial windows, zeros ignored.
    rng = np.random.default_rng(4)
    x = np.where(rng.random((5, 7, 3)) < 0.4, 0, rng.normal(size=(5, 7, 3))).astype(np.float32)
    assert np.array_equal(maxmin_pool(x), _maxmin_reference(x).astype(np.float32))


def test_maxmin_gradient_finite_differences():
    rng = np.random.default_rng(5)
    x = np.where(rng.random((6, 5, 2)) < 0.3, 0, rng.normal(size=(6, 5, 2)))
    g = rng.normal(size=maxmin_pool(x).shape)
    grad = maxmin_pool_backward(x, g)
    eps = 1e-6
    for idx in np.ndindex(x.shape):
        if x[idx] == 0:
            assert grad[idx] == 0
            continue
        e = np.zeros_like(x)
        e[idx] = eps
        fd = (np.sum(maxmin_pool(x + e) * g) - np.sum(maxmin_pool(x - e) * g)) / (2 * eps)
        assert abs(fd - grad[idx]) < 1e-6


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(InvalidInputError, match="too few points"):
        SparsePooling.build(np.zeros((0, 3)), P, IMAGE, BEV)
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        SparsePooling.build([[np.inf, 0, 0]], P, IMAGE, BEV)
    with pytest.raises(InvalidInputError, match="odd"):
        SparsePooling.build(_cloud(10), P, IMAGE, BEV, neighbourhood=2)
    op = SparsePooling.build(_cloud(100), P, IMAGE, BEV)
    with pytest.raises(InvalidInputError, match="shape"):
        op.forward(np.zeros((IMAGE[0] * IMAGE[1] + 1, 4)))
    with pytest.raises(InvalidInputError, match="shape"):
        op.forward(np.zeros((BEV[3], BEV[4], 4)), "image_to_bev")
    with pytest.raises(InvalidInputError, match="direction"):
        op.forward(np.zeros((10, 4)), "sideways")  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        op.forward(np.full((IMAGE[0] * IMAGE[1], 2), np.nan))
    with pytest.raises(InvalidInputError):
        maxmin_pool(np.zeros((4, 4)))
    # Mismatched channel counts: 3 input channels pool to 6, not 4.
    with pytest.raises(InvalidInputError, match=r"grad_out must have shape \(2, 2, 6\)"):
        maxmin_pool_backward(np.ones((4, 4, 3)), np.ones((2, 2, 4)))
