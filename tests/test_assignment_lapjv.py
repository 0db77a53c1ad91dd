"""Linear assignment (Jonker–Volgenant for square matrices, issue 36) against scipy's optimum.

The three cost families of ``benchmarks/peer_rows/assignment.py`` (uniform, integer with many
ties, geometric distances), rectangular shapes, forbidden pairs and bad input. The reference
is the total cost of ``scipy.optimize.linear_sum_assignment`` on the same array (the optimum
is unique in cost, not always in the pairs).
"""

from __future__ import annotations

import numpy as np
import pytest

from autoteach import detect
from autoteach.errors import InvalidInputError

scipy_lsa = pytest.importorskip("scipy.optimize").linear_sum_assignment


def costs(family: str, rows: int, cols: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if family == "uniform":
        return rng.random((rows, cols))
    if family == "integer":
        return rng.integers(0, 20, size=(rows, cols)).astype(np.float64)
    a, b = rng.random((rows, 2)), rng.random((cols, 2))
    return np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)


def check_optimal(c: np.ndarray, maximize: bool = False) -> None:
    r, k = detect.linear_sum_assignment(c, maximize=maximize)
    rs, ks = scipy_lsa(c, maximize=maximize)
    assert len(r) == len(rs) == min(c.shape)
    assert len(set(r.tolist())) == len(r) and len(set(k.tolist())) == len(k)
    ours, ref = c[r, k].sum(), c[rs, ks].sum()
    assert abs(ours - ref) <= 1e-9 * max(1.0, abs(ref)), (ours, ref)


@pytest.mark.parametrize("family", ["uniform", "integer", "geometric"])
@pytest.mark.parametrize("n", [1, 2, 3, 7, 40, 300])
def test_square_families_equal_scipy_cost(family: str, n: int) -> None:
    for seed in range(3 if n < 300 else 1):
        check_optimal(costs(family, n, n, seed))


@pytest.mark.parametrize("shape", [(5, 9), (9, 5), (60, 200), (200, 60), (1, 30)])
@pytest.mark.parametrize("family", ["uniform", "integer", "geometric"])
def test_rectangular_equals_scipy_cost(shape: tuple[int, int], family: str) -> None:
    check_optimal(costs(family, *shape, seed=11))


def test_maximize_negative_and_transposed_layouts() -> None:
    c = costs("uniform", 120, 120, 5) * 200 - 100
    check_optimal(c, maximize=True)
    check_optimal(np.asfortranarray(c))
    check_optimal(c.T)
    check_optimal(c[::2, ::2])
    check_optimal(c.astype(np.float32).astype(np.float64))


def test_forbidden_pairs_keep_their_semantics() -> None:
    rng = np.random.default_rng(2)
    c = rng.random((50, 50))
    c[rng.random((50, 50)) < 0.3] = np.inf
    check_optimal(c)


def test_bad_input() -> None:
    with pytest.raises(InvalidInputError):
        detect.linear_sum_assignment(np.array([[1.0, np.nan], [0.0, 1.0]]))
    with pytest.raises(InvalidInputError):
        detect.linear_sum_assignment(np.array([[1.0, -np.inf], [0.0, 1.0]]))
    with pytest.raises(InvalidInputError):
        detect.linear_sum_assignment(np.zeros(4))
    with pytest.raises(InvalidInputError):
        detect.linear_sum_assignment([["a", "b"]])
    r, k = detect.linear_sum_assignment(np.zeros((0, 0)))
    assert r.size == 0 and k.size == 0


def test_in_place_read_matches_the_copied_layouts_and_leaves_the_input_alone() -> None:
    """A C-order float64 matrix is read in place (no copy); other layouts are copied first."""
    c = costs("integer", 300, 300, seed=36)
    c.setflags(write=False)
    before = c.copy()
    r, k = detect.linear_sum_assignment(c)
    rf, kf = detect.linear_sum_assignment(np.asfortranarray(c))
    rs, ks = scipy_lsa(c)
    best = c[rs, ks].sum()
    assert c[r, k].sum() == pytest.approx(best, rel=1e-12)
    assert c[rf, kf].sum() == pytest.approx(best, rel=1e-12)
    np.testing.assert_array_equal(c, before)
    bad = c.copy()
    bad[123, 45] = np.nan
    with pytest.raises(InvalidInputError, match="123"):
        detect.linear_sum_assignment(bad)
