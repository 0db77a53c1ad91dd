"""Global registration (issue 29) against the independent scene generator's ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from autoteach.errors import DegenerateGeometryError, InvalidInputError
from autoteach.global_registration import global_register
from autoteach.sim.registration_scenes import make_scene, rms

# A few seeded trials per family and setting, small enough for CI (the full ≥100-trial tables
# are benchmarks/registration_families.py).
CASES_2D = [
    (fam, setting)
    for fam in ("polyline", "letter", "chevron")
    for setting in ("clutter300", "distractor2", "density", "missing")
] + [("chevron", "issue")]


@pytest.mark.parametrize(("family", "setting"), CASES_2D)
def test_2d_families_register_within_2_percent(family: str, setting: str) -> None:
    for seed in range(3):
        sc = make_scene(family, setting, seed=100 + seed)
        r = global_register(sc.x, sc.y)
        err = rms(r.transformed, sc.truth)
        assert err < 0.02 * sc.size, f"{family}/{setting} seed {seed}: RMS {err:.4f} vs size {sc.size:.3f}"


def test_3d_point_set_registers_within_2_percent() -> None:
    # 3-D reaches the goal only on the easier settings (docs/design/global_registration.md);
    # this pins the 3-D path on a point set rotated over the sphere.
    for seed in (200, 201):
        sc = make_scene("points3d", "clean", seed=seed, template_points=400)
        r = global_register(sc.x, sc.y)
        err = rms(r.transformed, sc.truth)
        assert err < 0.02 * sc.size, f"seed {seed}: RMS {err:.4f} vs size {sc.size:.3f}"


def test_explained_fraction_matches_the_generator() -> None:
    # 20 % of the target is cut away in the scene: the chosen pose explains about 80 % of the
    # template (the cut slab), not all of it, and the distractor-free truth is what it places.
    sc = make_scene("letter", "missing", seed=5)
    r = global_register(sc.x, sc.y)
    assert 0.7 < r.candidates[0].explained < 0.95


def _outline(v: np.ndarray, step: float) -> np.ndarray:
    pts = []
    for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
        n = int(np.ceil(np.linalg.norm(b - a) / step))
        pts.append(a + (np.arange(n)[:, None] / n) * (b - a))
    return np.vstack(pts)


def test_threefold_symmetric_template_returns_every_equivalent_pose() -> None:
    # An equilateral triangle: poses a, a + 120°, a + 240° explain the scene equally.
    ang = np.deg2rad([90, 210, 330])
    tri = np.column_stack([np.cos(ang), np.sin(ang)])
    y = _outline(tri, 0.03)
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    rng = np.random.default_rng(0)
    x = np.vstack([_outline(tri, 0.025) @ rot.T + [1.0, -2.0], rng.uniform(-4, 4, (100, 2))])
    r = global_register(x, y)
    assert r.ambiguous
    assert len(r.symmetries) == 2
    poses = [r.candidates[0]] + [c for c in r.candidates if c.equivalent]
    assert len(poses) == 3
    got = sorted(np.mod(np.arctan2(c.rotation[1, 0], c.rotation[0, 0]) - a, 2 * np.pi / 3) for c in poses)
    # Each pose is a + k·120° (mod 120° they all coincide with a).
    for g in got:
        assert min(g, 2 * np.pi / 3 - g) < 0.02
    angles = sorted(np.mod(np.arctan2(c.rotation[1, 0], c.rotation[0, 0]) - a, 2 * np.pi) for c in poses)
    assert np.allclose(np.diff(angles), 2 * np.pi / 3, atol=0.03)


def test_asymmetric_template_is_not_ambiguous() -> None:
    sc = make_scene("chevron", "clean", seed=3)
    r = global_register(sc.x, sc.y)
    assert not r.ambiguous
    assert r.symmetries == []


def test_bad_input_raises() -> None:
    sc = make_scene("letter", "clean", seed=1)
    with pytest.raises(InvalidInputError, match="criterion"):
        global_register(sc.x, sc.y, criterion="votes")  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="count"):
        global_register(sc.x, sc.y, count="x")  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="w"):
        global_register(sc.x, sc.y, w=0.0)
    with pytest.raises(InvalidInputError, match="k"):
        global_register(sc.x, sc.y, k=0)
    bad = sc.x.copy()
    bad[4, 0] = np.nan
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        global_register(bad, sc.y)
    with pytest.raises(InvalidInputError, match="shape"):
        global_register(sc.x[:, :1].ravel(), sc.y)
    with pytest.raises(DegenerateGeometryError, match="identical"):
        global_register(np.ones((20, 2)), sc.y)
    with pytest.raises(InvalidInputError, match="energy_all"):
        global_register(sc.x, sc.y).best_by("energy")
