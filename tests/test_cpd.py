"""Coherent point drift: closed-form truth, parity with pycpd on identical input, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from autoteach.errors import DegenerateGeometryError, InvalidInputError
from autoteach.registration import cpd_affine, cpd_nonrigid, cpd_rigid

pycpd = pytest.importorskip("pycpd")


def rot2(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def rot3(rx: float, ry: float, rz: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rxm = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rym = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rzm = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rzm @ rym @ rxm


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_recovers_known_similarity(dim: int) -> None:
    rng = np.random.default_rng(1)
    y = rng.uniform(-1, 1, (80, dim))
    r = rot2(0.5) if dim == 2 else rot3(0.3, -0.2, 0.4)
    t = rng.normal(size=dim)
    x = 0.8 * y @ r.T + t
    fit = cpd_rigid(x[rng.permutation(80)], y, tolerance=1e-10, max_iterations=300)
    np.testing.assert_allclose(fit.rotation, r, atol=1e-7)
    np.testing.assert_allclose(fit.translation, t, atol=1e-7)
    assert fit.scale == pytest.approx(0.8, abs=1e-7)
    np.testing.assert_allclose(fit.transformed, x, atol=1e-7)
    assert fit.p is None
    np.testing.assert_allclose(np.linalg.det(fit.rotation), 1.0)


def test_rigid_without_scale_keeps_unit_scale() -> None:
    rng = np.random.default_rng(2)
    y = rng.uniform(-1, 1, (60, 2))
    x = y @ rot2(-0.7).T + [0.3, 0.1]
    fit = cpd_rigid(x, y, scale=False, tolerance=1e-10)
    assert fit.scale == 1.0
    np.testing.assert_allclose(fit.rotation, rot2(-0.7), atol=1e-7)


@pytest.mark.parametrize("dim", [2, 3])
def test_affine_recovers_known_map(dim: int) -> None:
    rng = np.random.default_rng(3)
    y = rng.uniform(-1, 1, (70, dim))
    b = np.eye(dim) + 0.25 * rng.normal(size=(dim, dim))
    t = rng.normal(size=dim)
    x = y @ b.T + t
    fit = cpd_affine(x, y, tolerance=1e-12, max_iterations=500)
    np.testing.assert_allclose(fit.matrix, b, atol=1e-6)
    np.testing.assert_allclose(fit.translation, t, atol=1e-6)


def _pair(n: int, m: int, dim: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    y = rng.uniform(-1, 1, (m, dim))
    r = rot2(0.35) if dim == 2 else rot3(0.2, 0.1, -0.3)
    x = 1.05 * y[rng.integers(0, m, n)] @ r.T + 0.2 + rng.normal(0, 0.02, (n, dim))
    return x, y


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_matches_pycpd(dim: int) -> None:
    x, y = _pair(150, 120, dim, 4)
    for w in (0.0, 0.2):
        ours = cpd_rigid(x, y, w=w, return_P=True)
        ref = pycpd.RigidRegistration(X=x, Y=y, w=w)
        ty, (s, r, t) = ref.register()
        assert ours.iterations == ref.iteration
        np.testing.assert_allclose(ours.transformed, ty, atol=1e-9)
        np.testing.assert_allclose(ours.rotation, r.T, atol=1e-9)  # pycpd stores Rᵀ (TY = s·Y·R + t)
        np.testing.assert_allclose(ours.translation, np.ravel(t), atol=1e-9)
        assert ours.scale == pytest.approx(s, abs=1e-10)
        assert ours.sigma2 == pytest.approx(ref.sigma2, rel=1e-8)
        np.testing.assert_allclose(ours.p, ref.P, atol=1e-10)


def test_affine_matches_pycpd() -> None:
    # pycpd 2.0 evaluates the affine objective with tr(Bᵀ·YPY·Bᵀ) instead of tr(B·YPY·Bᵀ)
    # (in our orientation), so its stopping point differs: compare a fixed iteration count.
    x, y = _pair(140, 100, 2, 5)
    ours = cpd_affine(x, y, w=0.1, tolerance=0.0, max_iterations=40)
    ref = pycpd.AffineRegistration(X=x, Y=y, w=0.1, tolerance=0.0, max_iterations=40)
    ty, (b, t) = ref.register()
    assert ours.iterations == ref.iteration == 40
    np.testing.assert_allclose(ours.transformed, ty, atol=1e-9)
    np.testing.assert_allclose(ours.matrix, b.T, atol=1e-9)
    assert ours.sigma2 == pytest.approx(ref.sigma2, rel=1e-8)


@pytest.mark.parametrize("dim", [2, 3])
def test_nonrigid_matches_pycpd(dim: int) -> None:
    rng = np.random.default_rng(6)
    y = rng.uniform(-1, 1, (120, dim))
    x = y + 0.15 * np.sin(2.0 * y[:, ::-1]) + rng.normal(0, 0.01, y.shape)
    ours = cpd_nonrigid(x, y, beta=1.0, lam=2.0, return_P=True)
    ref = pycpd.DeformableRegistration(X=x, Y=y, alpha=2.0, beta=1.0)
    ty, (g, w) = ref.register()
    assert ours.iterations == ref.iteration
    np.testing.assert_allclose(ours.transformed, ty, atol=1e-8)
    np.testing.assert_allclose(ours.w, w, atol=1e-6 * np.abs(w).max())
    assert ours.sigma2 == pytest.approx(ref.sigma2, rel=1e-7)
    np.testing.assert_allclose(ours.p, ref.P, atol=1e-9)
    assert ours.energy == pytest.approx(float(np.sum(w * (g @ w))), rel=1e-8)
    assert ours.rank is None


def test_nonrigid_low_rank_close_to_full_rank() -> None:
    rng = np.random.default_rng(7)
    y = rng.uniform(0, 10, (600, 2))
    x = y + 0.4 * np.column_stack([np.sin(0.5 * y[:, 1]), np.cos(0.4 * y[:, 0])])
    full = cpd_nonrigid(x, y, beta=2.0, lam=2.0)
    low = cpd_nonrigid(x, y, beta=2.0, lam=2.0, low_rank=60)
    assert low.rank == 60
    truth_rms = lambda t: float(np.sqrt(np.mean(np.sum((t - x) ** 2, axis=1))))  # noqa: E731
    assert truth_rms(full.transformed) < 0.02
    assert truth_rms(low.transformed) < 0.02
    np.testing.assert_allclose(low.transformed, full.transformed, atol=0.02)


def test_truncated_e_step_agrees_with_dense() -> None:
    rng = np.random.default_rng(8)
    y = rng.uniform(0, 30, (3000, 2))
    x = y @ rot2(0.05).T + 0.3 + rng.normal(0, 0.05, y.shape)
    dense = cpd_rigid(x, y, e_step="dense", tolerance=1e-8)
    trunc = cpd_rigid(x, y, e_step="truncated", tolerance=1e-8)
    np.testing.assert_allclose(trunc.rotation, dense.rotation, atol=1e-7)
    np.testing.assert_allclose(trunc.translation, dense.translation, atol=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_fast_gauss_e_step_agrees_with_dense(dim: int) -> None:
    # The fast Gauss transform serves the large-σ iterations, the dense E-step the rest: the
    # registrations agree to far below the noise.
    rng = np.random.default_rng(10)
    y = rng.uniform(0, 10, (900, dim))
    x = y + 0.3 * np.sin(0.4 * y[:, ::-1]) + rng.normal(0, 0.01, y.shape)
    dense = cpd_nonrigid(x, y, low_rank=60, e_step="dense", w=0.1)
    fast = cpd_nonrigid(x, y, low_rank=60, e_step="fast_gauss", w=0.1)
    assert fast.iterations == dense.iterations
    np.testing.assert_allclose(fast.transformed, dense.transformed, atol=1e-6)
    assert fast.sigma2 == pytest.approx(dense.sigma2, rel=1e-5)


def test_outlier_weight_resists_clutter() -> None:
    rng = np.random.default_rng(9)
    y = rng.uniform(-1, 1, (100, 2))
    r, t = rot2(0.3), np.array([0.2, -0.1])
    # Clutter around (not on) the shape: it pulls a plain mixture, the uniform component absorbs it.
    c = rng.uniform(-3, 3, (400, 2))
    clutter = c[np.abs(c).max(axis=1) > 1.6][:60]
    x = np.vstack([y @ r.T + t, clutter])
    robust = cpd_rigid(x, y, w=0.5, tolerance=1e-10, max_iterations=500)
    plain = cpd_rigid(x, y, w=0.0, tolerance=1e-10, max_iterations=500)
    err = lambda f: float(np.abs(f.transformed - (y @ r.T + t)).max())  # noqa: E731
    assert err(robust) < 1e-3
    assert err(plain) > 10 * err(robust)


def test_posterior_matrix_on_request() -> None:
    x, y = _pair(50, 40, 2, 10)
    fit = cpd_rigid(x, y, w=0.1, return_P=True)
    assert fit.p.shape == (40, 50)
    assert np.all(fit.p >= 0)
    assert np.all(fit.p.sum(axis=0) <= 1.0 + 1e-12)


def test_bad_input_raises_clear_errors() -> None:
    rng = np.random.default_rng(11)
    y = rng.uniform(size=(20, 2))
    with pytest.raises(InvalidInputError, match="too few points"):
        cpd_rigid(y[:2], y)
    with pytest.raises(DegenerateGeometryError, match="identical"):
        cpd_rigid(np.ones((20, 2)), y)
    bad = y.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        cpd_nonrigid(bad, y)
    with pytest.raises(InvalidInputError, match="columns"):
        cpd_rigid(rng.uniform(size=(20, 3)), y)
    with pytest.raises(InvalidInputError, match="columns"):
        cpd_affine(rng.uniform(size=(20, 4)), rng.uniform(size=(20, 4)))
    with pytest.raises(InvalidInputError, match=r"shape \(N, D\)"):
        cpd_rigid(y.ravel(), y)
    with pytest.raises(InvalidInputError, match="sigma2"):
        cpd_rigid(y, y, sigma2=0.0)
    with pytest.raises(InvalidInputError, match="w"):
        cpd_rigid(y, y, w=1.0)
    with pytest.raises(InvalidInputError, match="beta"):
        cpd_nonrigid(y, y, beta=0.0)
    with pytest.raises(InvalidInputError, match="low_rank"):
        cpd_nonrigid(y, y, low_rank=21)
    with pytest.raises(DegenerateGeometryError, match="singular"):
        line = np.column_stack([np.arange(20.0), 2 * np.arange(20.0)])
        cpd_affine(y, line)
    with pytest.raises(InvalidInputError, match="e_step"):
        cpd_rigid(y, y, e_step="fast")
