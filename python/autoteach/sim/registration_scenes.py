"""Seeded point-registration scenes with ground truth, in wide families (issue 29).

An independent generator for global registration (seed 000_3b1454b2b2194811.txt §3.4,
Figs. 3.11, 3.12, 3.21, 3.22): a template ``Y`` and a scene ``X`` that holds the template at a
random rigid pose, sampled afresh (other sample positions than ``Y``), with noise and the
difficulties of one *setting*:

- ``clean``: the placed template only;
- ``clutter0`` / ``clutter100`` / ``clutter300``: uniform clutter of 0, 100 or 300 % of the
  template's point count in a box four shape sizes wide;
- ``distractor1`` / ``distractor2``: one or two partial (70 % kept) 0.9-scaled copies at other
  random poses, away from the target, plus 100 % clutter;
- ``density``: the scene samples the target three times denser than the template and adds a
  dense straight run of outliers as long as half the shape (Fig. 3.12);
- ``missing``: a contiguous 20 % of the template (by arc length) is cut away in the scene,
  plus 100 % clutter;
- ``issue``: the case of issue 29 (rotation 90° ± 10°, shift ≤ 1 unit, noise 0.01, one
  partial 0.9-scaled copy, 150 clutter points in an 8 × 8 square).

Shape families, 2-D: ``polyline`` (random asymmetric open polylines), ``letter`` (letter-like
stroke sets F, G, J, L, P, R, 4, 7), ``chevron`` (chevrons with a random opening and a tail);
3-D: ``points3d`` (anisotropic point sets: a few Gaussian clumps of unequal weight, observed
point for point with noise) and
``outline3d`` (scanned-like object outlines: edges of an L-shaped block with a handle). The
rotation is uniform over the circle (2-D) or the sphere (3-D) in every setting except
``issue``. The shape size is the diagonal of the template's bounding box; success of a
registration is an RMS distance to ``truth`` below 2 % of it.

Nothing here calls autoteach's registration code; only NumPy is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from autoteach.errors import InvalidInputError

__all__ = ["FAMILIES_2D", "FAMILIES_3D", "SETTINGS", "RegistrationScene", "make_scene", "rms", "shape_size"]

FAMILIES_2D = ("polyline", "letter", "chevron")
FAMILIES_3D = ("points3d", "outline3d")
SETTINGS = (
    "clean",
    "clutter0",
    "clutter100",
    "clutter300",
    "distractor1",
    "distractor2",
    "density",
    "missing",
    "issue",
)

_LETTERS: dict[str, list[list[tuple[float, float]]]] = {
    "F": [[(0, 0), (0, 2), (1.2, 2)], [(0, 1.1), (0.8, 1.1)]],
    "G": [[(1.2, 1.6), (0.9, 2), (0.2, 2), (0, 1.6), (0, 0.4), (0.3, 0), (1.0, 0), (1.2, 0.4), (1.2, 0.9), (0.6, 0.9)]],
    "J": [[(0.2, 2), (1.2, 2)], [(0.9, 2), (0.9, 0.3), (0.6, 0), (0.2, 0), (0, 0.3)]],
    "L": [[(0, 2), (0, 0), (1.1, 0)], [(0, 1.3), (0.35, 1.6)]],
    "P": [[(0, 0), (0, 2), (0.9, 2), (1.2, 1.7), (1.2, 1.3), (0.9, 1.0), (0, 1.0)]],
    "R": [[(0, 0), (0, 2), (0.9, 2), (1.2, 1.7), (1.2, 1.3), (0.9, 1.0), (0, 1.0)], [(0.5, 1.0), (1.2, 0)]],
    "4": [[(0.9, 0), (0.9, 2), (0, 0.7), (1.3, 0.7)]],
    "7": [[(0, 2), (1.2, 2), (0.4, 0)], [(0.3, 1.1), (0.9, 1.1)]],
}


@dataclass(frozen=True, slots=True)
class RegistrationScene:
    """One seeded scene.

    Attributes:
        x: Scene points ``(N, D)`` (target, distractors, clutter; shuffled).
        y: Template points ``(M, D)``.
        truth: The template moved to its true placement, ``(M, D)`` (row ``i`` is ``y[i]``).
        rotation: True rotation ``(D, D)``: ``truth = y @ rotation.T + translation``.
        translation: True translation ``(D,)``.
        size: Shape size (bounding-box diagonal of ``y``).
        family: Shape family.
        setting: Difficulty setting.

    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    truth: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    size: float
    family: str
    setting: str


def shape_size(points: NDArray[np.float64]) -> float:
    """Diagonal of the axis-aligned bounding box of ``points``."""
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def rms(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """RMS distance between corresponding rows of ``a`` and ``b``."""
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def _resample(strokes: list[NDArray[np.float64]], n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``n`` points equally spaced by arc length over all strokes, with a random phase."""
    lengths = [np.linalg.norm(np.diff(s, axis=0), axis=1) for s in strokes]
    total = float(sum(seg.sum() for seg in lengths))
    step = total / n
    s_all = (rng.uniform(0, 1) + np.arange(n)) * step
    out = []
    offset = 0.0
    for s, seg in zip(strokes, lengths, strict=True):
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        mine = s_all[(s_all >= offset) & (s_all < offset + cum[-1])] - offset
        k = np.clip(np.searchsorted(cum, mine, side="right") - 1, 0, len(seg) - 1)
        f = (mine - cum[k]) / np.maximum(seg[k], 1e-300)
        out.append(s[k] + f[:, None] * (s[k + 1] - s[k]))
        offset += cum[-1]
    return np.vstack(out)


def _strokes_2d(family: str, rng: np.random.Generator) -> list[NDArray[np.float64]]:
    if family == "polyline":
        while True:
            nv = int(rng.integers(5, 9))
            ang = np.cumsum(rng.uniform(-2.2, 2.2, nv - 1))
            steps = rng.uniform(0.4, 1.0, (nv - 1, 1)) * np.column_stack([np.cos(ang), np.sin(ang)])
            v = np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])
            # Reject near-straight or self-crossing-prone walks: keep an aspect ratio ≥ 0.25.
            ev = np.linalg.eigvalsh(np.cov(v.T))
            if ev[0] > 0.06 * ev[1]:
                return [v]
    if family == "letter":
        name = list(_LETTERS)[int(rng.integers(len(_LETTERS)))]
        return [np.array(s, dtype=float) for s in _LETTERS[name]]
    if family == "chevron":
        op = rng.uniform(0.6, 1.4)
        v = np.array([[-1.0, op], [0.0, 0.0], [-1.0, -op], [-0.55, -op], [0.45, 0.0], [-0.55, op], [-1.0, op]])
        tail_len = rng.uniform(0.5, 1.0)
        tail = np.array([[0.45, 0.0], [0.45 + tail_len, 0.25 * rng.uniform(-1, 1)]])
        return [v, tail]
    raise InvalidInputError(f"unknown 2-D family {family!r}; expected one of {FAMILIES_2D}")


def _sample_3d(family: str, n: int, rng: np.random.Generator, params: dict[str, NDArray[np.float64]]) -> NDArray:
    if family == "points3d":
        centres, scales, weights = params["centres"], params["scales"], params["weights"]
        k = rng.choice(len(weights), size=n, p=weights)
        return centres[k] + rng.normal(size=(n, 3)) * scales[k]
    if family == "outline3d":
        return _resample(list(params["edges"]), n, rng)
    raise InvalidInputError(f"unknown 3-D family {family!r}; expected one of {FAMILIES_3D}")


def _params_3d(family: str, rng: np.random.Generator) -> dict[str, NDArray[np.float64]]:
    if family == "points3d":
        k = 4
        w = rng.uniform(0.5, 1.5, k)
        return {
            "centres": rng.uniform(-1, 1, (k, 3)) * np.array([1.0, 0.7, 0.4]),
            "scales": rng.uniform(0.08, 0.3, (k, 3)),
            "weights": w / w.sum(),
        }
    if family == "outline3d":
        a, b, c = rng.uniform(0.8, 1.2), rng.uniform(0.5, 0.8), rng.uniform(0.3, 0.5)
        # L-shaped block: box [0,a]×[0,b]×[0,c] minus the corner [a/2,a]×[b/2,b]×[c/2... ] — its
        # silhouette edges, plus a handle (a bent rod) on one side.
        base = [
            [(0, 0, 0), (a, 0, 0), (a, b / 2, 0), (a / 2, b / 2, 0), (a / 2, b, 0), (0, b, 0), (0, 0, 0)],
            [(0, 0, c), (a, 0, c), (a, b / 2, c), (a / 2, b / 2, c), (a / 2, b, c), (0, b, c), (0, 0, c)],
            [(0, 0, 0), (0, 0, c)],
            [(a, 0, 0), (a, 0, c)],
            [(a, b / 2, 0), (a, b / 2, c)],
            [(a / 2, b, 0), (a / 2, b, c)],
            [(0, b, 0), (0, b, c)],
            [(0, b / 3, c), (-0.3, b / 3, c + 0.3), (-0.3, b / 3, c + 0.6)],
        ]
        return {"edges": np.array([np.array(e, dtype=float) for e in base], dtype=object)}
    raise InvalidInputError(f"unknown 3-D family {family!r}; expected one of {FAMILIES_3D}")


def _random_rotation(dim: int, rng: np.random.Generator) -> NDArray[np.float64]:
    if dim == 2:
        a = rng.uniform(-np.pi, np.pi)
        return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def make_scene(
    family: str,
    setting: str,
    seed: int,
    template_points: int | None = None,
    noise: float = 0.005,
) -> RegistrationScene:
    """Build one seeded scene.

    Args:
        family: One of :data:`FAMILIES_2D` or :data:`FAMILIES_3D`.
        setting: One of :data:`SETTINGS`.
        seed: Random seed (the scene is a pure function of the arguments).
        template_points: Points of the template (default 150 in 2-D, 2000 in 3-D).
        noise: Noise standard deviation per coordinate, as a fraction of the shape size
            (``issue`` uses its own 0.01 absolute).

    Returns:
        The scene with its ground truth.

    Raises:
        InvalidInputError: Unknown family or setting, or a non-positive point count.

    """
    if setting not in SETTINGS:
        raise InvalidInputError(f"unknown setting {setting!r}; expected one of {SETTINGS}")
    dim = 2 if family in FAMILIES_2D else 3 if family in FAMILIES_3D else 0
    if dim == 0:
        raise InvalidInputError(f"unknown family {family!r}; expected one of {FAMILIES_2D + FAMILIES_3D}")
    m = template_points if template_points is not None else (150 if dim == 2 else 2000)
    if m < 10:
        raise InvalidInputError(f"template_points must be ≥ 10, got {m}")
    rng = np.random.default_rng(seed)
    density = 3 if setting == "density" else 1
    if dim == 2:
        strokes = _strokes_2d(family, rng)
        y = _resample(strokes, m, rng)
        target = _resample(strokes, density * m, rng)

        def copy(n: int) -> NDArray[np.float64]:
            return _resample(strokes, n, rng)

    else:
        params = _params_3d(family, rng)
        y = _sample_3d(family, m, rng, params)
        if family == "points3d":
            # A point set is observed point for point (plus noise); the density setting adds
            # two more draws from the same distribution.
            target = np.vstack([y] + [_sample_3d(family, m, rng, params) for _ in range(density - 1)])
        else:
            target = _sample_3d(family, density * m, rng, params)

        def copy(n: int) -> NDArray[np.float64]:
            return _sample_3d(family, n, rng, params)

    centre = y.mean(axis=0)
    y, target = y - centre, target - centre
    size = shape_size(y)
    if setting == "issue":
        # Issue 29's case, in its own absolute units: extent ≈ 1.2.
        scale = 1.2 / np.max(y.max(axis=0) - y.min(axis=0))
        y, target, size = y * scale, target * scale, size * scale
    if setting == "missing":
        # Cut a contiguous 20 %: the points of the target nearest (along a random direction)
        # to one end, i.e. a slab of the shape.
        d = rng.normal(size=dim)
        proj = target @ (d / np.linalg.norm(d))
        target = target[proj > np.quantile(proj, 0.2)]
    if setting == "issue":
        a = np.pi / 2 + rng.uniform(-1, 1) * np.deg2rad(10)
        r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) if dim == 2 else _random_rotation(dim, rng)
        t = rng.uniform(-1, 1, dim) / np.sqrt(dim)
        sigma = 0.01
    else:
        r = _random_rotation(dim, rng)
        t = rng.uniform(-1, 1, dim) * size
        sigma = noise * size
    truth = y @ r.T + t
    parts = [target @ r.T + t + rng.normal(0, sigma, target.shape)]
    n_distractors = {"distractor1": 1, "distractor2": 2, "issue": 1}.get(setting, 0)
    placed: list[NDArray[np.float64]] = [t]
    for _ in range(n_distractors):
        c = copy(m) * 0.9
        d = rng.normal(size=dim)
        proj = c @ (d / np.linalg.norm(d))
        c = c[proj > np.quantile(proj, 0.3)]
        for _attempt in range(100):
            t2 = t + rng.uniform(-2.5, 2.5, dim) * size
            if all(np.linalg.norm(t2 - p) > 1.1 * size for p in placed):
                break
        placed.append(t2)
        parts.append(c @ _random_rotation(dim, rng).T + t2 + rng.normal(0, sigma, c.shape))
    clutter_frac = {"clutter100": 1.0, "clutter300": 3.0, "distractor1": 1.0, "distractor2": 1.0, "missing": 1.0}
    frac = clutter_frac.get(setting, 0.0)
    lo = np.min([p - 2 * size for p in placed], axis=0)
    hi = np.max([p + 2 * size for p in placed], axis=0)
    if frac > 0:
        parts.append(rng.uniform(lo, hi, (int(round(frac * m)), dim)))
    if setting == "density":
        # A dense run of outliers along a straight line half the shape long (Fig. 3.12).
        p0 = t + rng.uniform(-1.5, 1.5, dim) * size
        u = rng.normal(size=dim)
        run = p0 + np.outer(np.linspace(0, 0.5 * size, m), u / np.linalg.norm(u))
        parts.append(run + rng.normal(0, sigma, run.shape))
    if setting == "issue":
        parts.append(rng.uniform(-4, 4, (150, dim)))
    x = np.vstack(parts)
    x = x[rng.permutation(len(x))]
    return RegistrationScene(x, y, truth, r, t, size, family, setting)
