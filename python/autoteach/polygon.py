"""Chamber-opening (polygon) detection and global voting of rigid transforms.

Seed 000_3b1454b2b2194811.txt §3.3 ("Detection of Chamber Openings in RGB image", eq. 3.8–3.10)
and §3.4 (eq. 3.19–3.22, Algorithm 3). Friendly front of the compiled ``polygon_*`` functions of
:mod:`autoteach._core`:

- :func:`detect_polygon` -- line segments, transfer to the reference plane by the homography
  (3.8), Hough voting of potential polygon centres per segment (3.9) over centre, rotation and
  scale, best-cell selection, IRLS fit of centre, rotation and uniform scale (3.10).
- :func:`detect_segments` -- the segment detector (Canny edges grouped by gradient direction,
  sub-pixel total-least-squares lines, dark side on the left).
- :func:`global_voting` -- top-K rigid transforms ``x ≈ R y + t`` mapping ``Y`` onto ``X`` from
  local reference frames, clustered per dimension, ranked by the number of distinct ``Y`` points
  (Y-count) or by pairs; :func:`vote_cells` gives the whole vote map (Fig. 3.13).
- :func:`render_opening` and :func:`simulate_opening` -- synthetic chamber-opening images with
  occlusion, clutter lines, a similar distracting shape, blur and noise, with ground truth.

Errors: bad input raises :class:`~autoteach.errors.InvalidInputError`; degenerate data (identical
points, singular homography, no vote) raises :class:`~autoteach.errors.DegenerateGeometryError`.

Example:
    >>> import numpy as np
    >>> from autoteach.polygon import CROSS_TEMPLATE, detect_polygon, simulate_opening
    >>> scene = simulate_opening(seed=3)
    >>> det = detect_polygon(scene.image, CROSS_TEMPLATE, scene.homography)
    >>> bool(np.hypot(*(det.centre_image - scene.centre_image)) < 1.0)
    True

"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError
from autoteach.options import checked_replace

__all__ = [
    "CROSS_TEMPLATE",
    "OpeningScene",
    "PolygonDetection",
    "PolygonPose",
    "RigidHypothesis",
    "VoteMap",
    "VotingOptions",
    "detect_polygon",
    "detect_segments",
    "global_voting",
    "render_opening",
    "simulate_opening",
    "vote_cells",
]

#: Cross-shaped chamber-opening template (reference units ≈ pixels), vertices around its centre.
CROSS_TEMPLATE: NDArray[np.float64] = np.array(
    [
        [-80.0, -20.0],
        [-30.0, -20.0],
        [-30.0, -40.0],
        [30.0, -40.0],
        [30.0, -20.0],
        [80.0, -20.0],
        [80.0, 20.0],
        [30.0, 20.0],
        [30.0, 40.0],
        [-30.0, 40.0],
        [-30.0, 20.0],
        [-80.0, 20.0],
    ]
)

#: The distracting shape of :func:`simulate_opening`: the cross's bar without its centre part.
BAR_TEMPLATE: NDArray[np.float64] = np.array([[-80.0, -20.0], [80.0, -20.0], [80.0, 20.0], [-80.0, 20.0]])


@dataclass(frozen=True, slots=True)
class RigidHypothesis:
    """A rigid transform ``x ≈ rotation @ y + translation`` and its votes.

    The fields of ``autoteach_detect::voting::RigidHypothesis``; also the initial transform of a
    :class:`~autoteach.registration.GlobalCpdHypothesis`.
    """

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    votes: int
    pair_votes: int

    def apply(self, points: ArrayLike) -> NDArray[np.float64]:
        """Move points ``(N, D)`` by the transform."""
        p = as_f64(points, "points")
        return p @ self.rotation.T + self.translation


@dataclass(frozen=True, slots=True)
class VotingOptions:
    """Options of global voting (seed 000_3b1454b2b2194811.txt eq. (3.20)–(3.22), Algorithm 3).

    Attributes:
        neighbours: Neighbours per local reference frame.
        angle_bin: Voting bin width of the rotation angle(s), radians.
        translation_bin: Voting bin width of the translation; ``None`` for ``angle_bin ×`` the RMS
            radius of the model.
        count: ``"y"`` ranks clusters by distinct model points (the seed's Y-count, Fig. 3.13b),
            ``"pairs"`` by pairs (classic voting).
        min_votes: Clusters with fewer votes are discarded.
        max_points: At most this many points per set take part in the vote.
        descriptor_tolerance: Largest descriptor difference of a matched pair (``None``: derived
            from the bins).
        shifted_grid: Also vote on the grid shifted by half a bin (clusters on a bin edge).
        max_pairs: Bound on the matched pairs (an error beyond it, not a silent cut).
    """

    neighbours: int = 10
    angle_bin: float = 0.2
    translation_bin: float | None = None
    count: Literal["y", "pairs"] = "y"
    min_votes: int = 3
    max_points: int = 1000
    descriptor_tolerance: float | None = None
    shifted_grid: bool = True
    max_pairs: int = 8_000_000

    def replace(self, **changes: Any) -> VotingOptions:
        """A copy with ``changes``; an unknown option name is an error that lists the known ones."""
        return checked_replace(self, "voting", changes)

    def core_options(self, top_k: int | None = None) -> dict[str, Any]:
        """The options dict of the compiled voting calls (counts checked by name)."""
        kw = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if top_k is not None:
            kw["top_k"] = top_k
        return _voting_options(**kw)


def voting_options(options: VotingOptions | None, overrides: dict[str, Any], **defaults: Any) -> VotingOptions:
    """``options`` (default: :class:`VotingOptions` with ``defaults``) with ``overrides`` applied."""
    base = options if options is not None else VotingOptions().replace(**defaults)
    return base.replace(**overrides) if overrides else base


def _voting_options(**kw: Any) -> dict[str, Any]:
    count = kw.get("count", "y")
    if count not in ("y", "pairs"):
        raise InvalidInputError(f"count must be 'y' or 'pairs', got {count!r}")
    # Counts are unsigned in the compiled options: name a negative one here (the user's `k`
    # is the options' `top_k`).
    for key in ("top_k", "neighbours", "min_votes", "max_points", "max_pairs"):
        if key in kw:
            kw[key] = as_int(kw[key], "k" if key == "top_k" else key)
    return {k: v for k, v in kw.items() if v is not None}


def _hypotheses(arrays: tuple[Any, Any, Any, Any]) -> list[RigidHypothesis]:
    r, t, votes, pairs = arrays
    return [RigidHypothesis(r[i], t[i], int(votes[i]), int(pairs[i])) for i in range(len(votes))]


def global_voting(
    X: ArrayLike, Y: ArrayLike, k: int = 3, options: VotingOptions | None = None, **overrides: Any
) -> list[RigidHypothesis]:
    """Top-``k`` rigid transforms mapping ``Y`` onto ``X`` by global voting (Algorithm 3).

    ``X`` (N, D) and ``Y`` (M, D), D ∈ {2, 3}. ``options`` (:class:`VotingOptions`; keyword
    ``overrides`` replace its fields by name, e.g. ``count="pairs"``) set the local frames and
    the vote bins. Returns hypotheses best first (possibly fewer than ``k``, or none).
    """
    opts = voting_options(options, overrides).core_options(top_k=k)
    return _hypotheses(_core.polygon_global_voting(as_f64(X, "X"), as_f64(Y, "Y"), opts))


def vote_cells(
    X: ArrayLike, Y: ArrayLike, options: VotingOptions | None = None, **overrides: Any
) -> list[RigidHypothesis]:
    """Every populated cell of the vote grid (the vote map of Fig. 3.13), sorted by ``count``.

    The grid is the unshifted one whatever ``shifted_grid`` says: a vote map has one grid.
    """
    opts = voting_options(options, overrides).core_options()
    return _hypotheses(_core.polygon_vote_cells(as_f64(X, "X"), as_f64(Y, "Y"), opts))


@dataclass(frozen=True, slots=True)
class PolygonPose:
    """Template pose in the reference plane: ``p = centre + scale · R(rotation) · v``.

    The fields of ``autoteach_detect::polygon::PolygonPose``.
    """

    centre: NDArray[np.float64]
    rotation: float
    scale: float


@dataclass(frozen=True, slots=True)
class VoteMap:
    """The centre vote map of the best (rotation, scale) slice (the fields of ``autoteach_detect::polygon::VoteMap``).

    Cell ``[r, c]`` of :attr:`data` is centred at ``origin + cell · (c + ½, r + ½)``.
    """

    data: NDArray[np.float64] = field(repr=False)
    """Votes, shape ``(rows, cols)``."""
    rows: int
    """Rows."""
    cols: int
    """Columns."""
    origin: NDArray[np.float64]
    """Reference-plane position of the map's corner, ``(2,)``."""
    cell: float
    """Cell size (reference units)."""


@dataclass(frozen=True, slots=True)
class PolygonDetection:
    """Result of :func:`detect_polygon` (the fields of ``autoteach_detect::polygon::PolygonDetection``).

    ``pose`` is the IRLS fit, ``coarse`` the best Hough cell, ``votes`` its supported edge length
    (reference units), ``support`` the ``(segment index, template edge index)`` pairs used by the
    fit, ``segments`` the image segments ``(N, 4)``, ``centre_image`` the pixel position of the
    centre, ``rms`` the support's end-point distance from the fitted polygon, and ``vote_map`` the
    centre votes of the best (rotation, scale) slice (a :class:`VoteMap`).
    """

    pose: PolygonPose
    coarse: PolygonPose
    votes: float
    support: NDArray[np.int64]
    segments: NDArray[np.float64]
    centre_image: NDArray[np.float64]
    rms: float
    vote_map: VoteMap = field(repr=False)

    @property
    def supporting_segments(self) -> NDArray[np.float64]:
        """The image segments ``(S, 4)`` that support the fit."""
        return self.segments[self.support[:, 0]] if len(self.support) else np.zeros((0, 4))


def _image_u8(image: ArrayLike) -> NDArray[np.uint8]:
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise InvalidInputError(f"image must be two-dimensional (H, W), got shape {arr.shape}")
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise InvalidInputError(f"image must hold real numbers, got dtype {arr.dtype}")
    f = arr.astype(np.float64)
    if not np.all(np.isfinite(f)):
        raise InvalidInputError("image contains non-finite values")
    return np.ascontiguousarray(np.clip(np.rint(f), 0, 255).astype(np.uint8))


def detect_segments(image: ArrayLike, **options: Any) -> NDArray[np.float64]:
    """Line segments ``(N, 4)`` rows ``[ax, ay, bx, by]`` of a grey image (dark side on the left).

    Options: ``canny_low`` (20), ``canny_high`` (50), ``gradient_sigma`` (1.0),
    ``angle_tolerance`` (0.35 rad), ``min_length`` (8 px), ``max_rms`` (0.7 px).
    """
    return _core.polygon_detect_segments(_image_u8(image), options)


def _pose(p: tuple[float, float, float, float]) -> PolygonPose:
    return PolygonPose(np.array([p[0], p[1]]), float(p[2]), float(p[3]))


def detect_polygon(
    image_or_segments: ArrayLike,
    template: ArrayLike,
    homography: ArrayLike,
    *,
    segment_options: dict[str, Any] | None = None,
    **params: Any,
) -> PolygonDetection:
    """Detect the ``template`` polygon in an image or among segments (seed §3.3).

    ``image_or_segments``: a grey image (uint8, or real values in [0, 255]), or float segments
    ``(N, 4)`` ``[ax, ay, bx, by]`` in pixels (oriented with the dark side on the left unless
    ``oriented=False``). ``template``: vertices ``(K, 2)`` around the polygon centre, in reference
    units. ``homography``: 3×3, reference plane → image (eq. 3.8).

    ``params`` (reference units): ``cell`` (2.0), ``rotation_nominal`` (0), ``rotation_range``
    (0.2 rad), ``rotation_step`` (0.02), ``scale_min``/``scale_max``/``scale_step``
    (0.9/1.1/0.025), ``epsilon`` (0.1, eq. 3.9), ``min_segment_length`` (6),
    ``support_distance`` (3), ``support_angle`` (0.1 rad), ``oriented`` (True),
    ``irls_iterations`` (30). ``segment_options`` go to :func:`detect_segments`.
    """
    if image_or_segments is None:
        raise InvalidInputError("image_or_segments must be an image (H, W) or segments (S, 4), got None")
    arr = np.asarray(image_or_segments)
    t = as_f64(template, "template")
    h = as_f64(homography, "homography")
    is_segments = arr.ndim == 2 and arr.shape[1] == 4 and np.issubdtype(arr.dtype, np.floating)
    if is_segments:
        if segment_options:
            raise InvalidInputError("segment_options only apply when an image is given")
        d = _core.polygon_detect(t, h, segments=as_f64(arr, "segments"), options=params)
    else:
        d = _core.polygon_detect(t, h, image=_image_u8(arr), options=params, segment_options=segment_options or {})
    vm = np.asarray(d["vote_map"])
    return PolygonDetection(
        pose=_pose(d["pose"]),
        coarse=_pose(d["coarse"]),
        votes=float(d["votes"]),
        support=np.asarray(d["support"], dtype=np.int64).reshape(-1, 2),
        segments=np.asarray(d["segments"]),
        centre_image=np.array(d["centre_image"]),
        rms=float(d["rms"]),
        vote_map=VoteMap(
            data=vm,
            rows=int(vm.shape[0]),
            cols=int(vm.shape[1]),
            origin=np.array(d["vote_map_origin"]),
            cell=float(d["vote_map_cell"]),
        ),
    )


def render_opening(
    width: int,
    height: int,
    homography: ArrayLike,
    *,
    plate: float = 190.0,
    polygons: list[tuple[ArrayLike, float]] = (),  # type: ignore[assignment]
    lines: ArrayLike | None = None,
    occluders: list[tuple[ArrayLike, float]] = (),  # type: ignore[assignment]
    supersample: int = 4,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    seed: int = 0,
) -> NDArray[np.uint8]:
    """Render a chamber-opening image (uint8, ``(height, width)``).

    ``polygons``: ``(vertices (K, 2) in the reference plane, grey level)`` drawn through the
    homography (reference plane → image); ``lines``: ``(L, 6)`` image lines
    ``[ax, ay, bx, by, width, grey]``; ``occluders``: image polygons drawn last.
    """
    polys = [(as_f64(v, "polygons vertices"), float(g)) for v, g in polygons]
    occ = [(as_f64(v, "occluders vertices"), float(g)) for v, g in occluders]
    ln = np.zeros((0, 6)) if lines is None else as_f64(lines, "lines").reshape(-1, 6)
    return _core.polygon_render_opening(
        int(width),
        int(height),
        as_f64(homography, "homography"),
        float(plate),
        polys,
        ln,
        occ,
        int(supersample),
        float(blur_sigma),
        float(noise_sigma),
        int(seed),
    )


@dataclass(frozen=True)
class OpeningScene:
    """A simulated chamber-opening image and its ground truth."""

    image: NDArray[np.uint8]
    homography: NDArray[np.float64]
    pose: PolygonPose
    centre_image: NDArray[np.float64]
    distractor: PolygonPose


def _apply(h: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    q = h @ np.array([p[0], p[1], 1.0])
    return q[:2] / q[2]


def _place(template: NDArray[np.float64], pose: PolygonPose) -> NDArray[np.float64]:
    c, s = np.cos(pose.rotation), np.sin(pose.rotation)
    return pose.centre + pose.scale * template @ np.array([[c, s], [-s, c]])


def simulate_opening(
    seed: int,
    *,
    width: int = 480,
    height: int = 360,
    n_lines: int = 3,
    occlusion: bool = True,
    distractor: bool = True,
    blur_sigma: float = 0.8,
    noise_sigma: float = 3.0,
) -> OpeningScene:
    """A seeded random chamber-opening image with :data:`CROSS_TEMPLATE`.

    Perspective homography (rotation ±0.3 rad, scale 0.85–1.15, perspective terms ±6·10⁻⁴);
    the opening at a random centre, rotation ±0.1 rad and scale 0.93–1.07; a bar-shaped
    distractor (:data:`BAR_TEMPLATE`, the cross without its centre part) beside it; ``n_lines``
    dark clutter lines across the image; a grey occluder over one arm; blur and noise.
    """
    seed, width, height, n_lines = (
        as_int(v, name) for v, name in ((seed, "seed"), (width, "width"), (height, "height"), (n_lines, "n_lines"))
    )
    blur_sigma, noise_sigma = as_float(blur_sigma, "blur_sigma"), as_float(noise_sigma, "noise_sigma")
    rng = np.random.default_rng(seed)
    psi, k = rng.uniform(-0.3, 0.3), rng.uniform(0.85, 1.15)
    c, s = np.cos(psi), np.sin(psi)
    a = np.array([[k * c, -k * s, 0.0], [k * s, k * c, 0.0], [0.0, 0.0, 1.0]])
    p = np.eye(3)
    p[2, :2] = rng.uniform(-6e-4, 6e-4, size=2)
    t = np.array([[1.0, 0.0, width / 2], [0.0, 1.0, height / 2], [0.0, 0.0, 1.0]])
    h = t @ p @ a
    pose = PolygonPose(rng.uniform([-40.0, -30.0], [40.0, 30.0]), rng.uniform(-0.1, 0.1), rng.uniform(0.93, 1.07))
    side = 1.0 if rng.random() < 0.5 else -1.0
    dpose = PolygonPose(pose.centre + np.array([rng.uniform(-30.0, 30.0), side * 115.0]), rng.uniform(-0.1, 0.1), 1.0)
    polygons = [(_place(CROSS_TEMPLATE, pose), 35.0)]
    if distractor:
        polygons.insert(0, (_place(BAR_TEMPLATE, dpose), 45.0))
    lines = np.array(
        [
            [
                rng.uniform(0, width),
                0.0,
                rng.uniform(0, width),
                float(height),
                rng.uniform(1.5, 3.0),
                rng.uniform(40, 120),
            ]
            for _ in range(n_lines)
        ]
    ).reshape(-1, 6)
    occluders = []
    if occlusion:
        oc = _apply(h, pose.centre + np.array([side * 70.0, 0.0]))
        tri = oc + np.array([[-18.0, -35.0], [20.0, -30.0], [12.0, 35.0]])
        occluders.append((tri, 150.0))
    image = render_opening(
        width,
        height,
        h,
        plate=190.0,
        polygons=polygons,
        lines=lines,
        occluders=occluders,
        supersample=4,
        blur_sigma=blur_sigma,
        noise_sigma=noise_sigma,
        seed=seed,
    )
    return OpeningScene(image, h, pose, _apply(h, pose.centre), dpose)
