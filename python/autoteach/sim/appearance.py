"""Appearance-randomised carrier images with exact rim ground truth (issue 42, seed 000 ch. 3.1–3.2).

A scene generator for wafer-rim detection and tracking that is separate from the ray tracer of
:func:`autoteach.sim.simulate_session`: a stack of wafers (discs of radius ``R`` and thickness
``t`` at a slot pitch, some slots empty) seen by a pinhole camera, drawn by a *different image
formation* and under a randomised *family* of appearances. The ground truth is the exact image of
every rim circle, :func:`autoteach.geometry.project_circle` (pixel centres at integers, the
top-left pixel's centre is ``(0, 0)``).

API (stable):

- :data:`FAMILIES` -- the appearance families (:data:`AppearanceFamily`): ``bright_face``,
  ``dark_face``, ``thin_lines``, ``low_contrast``, ``lighting``, ``clutter``, ``occlusion``,
  ``blur_noise``, ``elevation``, ``sparse_stack``. Each is a random distribution, see
  ``docs/design/appearance-generator.md`` for the parameter ranges.
- :func:`draw_params` ``(family, seed, **overrides) -> SceneParams``: the drawn scene parameters.
- :func:`render_carrier_image` ``(family, seed, **overrides) -> CarrierScene``: one image with
  its truth. ``overrides`` are :class:`SceneParams` fields (e.g. ``noise_sigma=0.0``,
  ``blur_sigma=0.0``) or ``wafers`` (number of slots, 1–12).
- :func:`render_sweep` ``(family, seed, frames=40, wafers=10) -> list[CarrierScene]``: the camera
  translates sideways past the stack; appearance, wafers and identities (``slot``) are constant.
- :func:`render_scene` ``(params, camera_pose, seed) -> CarrierScene``: a scene for given
  parameters and camera pose.

A :class:`CarrierScene` holds ``image`` (uint8, ``(720, 1280)``), ``K`` (3×3), ``T_wc``
(camera-to-world, 4×4; the world frame has the stack axis along ``z`` through the origin, slot
``k``'s mid-plane at ``z = (k − 1)·pitch``, each wafer slightly tilted and offset), the
:class:`SceneParams` and ``wafers``: one :class:`WaferTruth` per slot with ``slot``, ``present``,
the ``upper`` and ``lower`` :class:`RimTruth` (``None`` for an empty slot) and the wafer's
``centre`` and ``normal``. A :class:`RimTruth` has the exact ``ellipse``,
its ``kind``, sampled ``points`` (the rim circle at :data:`RIM_SAMPLES` angles, projected) with
per-sample flags ``in_image``, ``occluded`` and ``edge`` (an image edge of at least
:data:`MIN_EDGE_CONTRAST` grey levels there), ``visible_fraction`` (fraction of samples that are
all three) and ``visible`` (``visible_fraction ≥`` :data:`MIN_VISIBLE_FRACTION`). Only visible
rims are expected of a detector (:mod:`autoteach.sim.appearance_eval`).

Image formation (different in kind from the ray tracer's pixel-box-then-grid-blur): the scene's
radiance is piecewise smooth; every boundary (rim ellipse, occluder, carrier line) contributes
the analytic edge-spread function of a Gaussian optical PSF (σ) convolved with the unit square
pixel aperture, evaluated at the *exact* orthogonal signed distance of the pixel centre to the
boundary (a trapezoid ⊗ Gaussian, closed form), so an edge's profile is continuous in its
sub-pixel position. Surfaces are composited front-to-back by the painter's rule with these
coverages (nested regions of one wafer by differences, which is exact). Then illumination
(vignetting, uneven light), camera gamma, Gaussian read noise and shot noise, 8-bit quantisation
and clipping (saturation). Pinhole only: with lens distortion the rims are not ellipses.

Example:
    >>> from autoteach.sim.appearance import render_carrier_image
    >>> scene = render_carrier_image("bright_face", seed=3)  # doctest: +SKIP
    >>> scene.image.shape, [w.slot for w in scene.wafers if w.present]  # doctest: +SKIP
    ((720, 1280), [1, 2, 3, 4, 5])

"""

from __future__ import annotations

import dataclasses
import math
import operator
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from autoteach.errors import DegenerateGeometryError, InvalidInputError
from autoteach.geometry import Ellipse, project_circle

__all__ = [
    "FAMILIES",
    "HEIGHT",
    "MAX_SLOTS",
    "MIN_EDGE_CONTRAST",
    "MIN_VISIBLE_FRACTION",
    "RIM_SAMPLES",
    "WIDTH",
    "AppearanceFamily",
    "CarrierScene",
    "RimTruth",
    "SceneParams",
    "WaferTruth",
    "camera_position",
    "default_pose",
    "draw_params",
    "edge_coverage",
    "jpeg_like",
    "look_at_pose",
    "render_carrier_image",
    "render_scene",
    "render_sweep",
    "sweep_poses",
]

AppearanceFamily = Literal[
    "bright_face",
    "dark_face",
    "thin_lines",
    "low_contrast",
    "lighting",
    "clutter",
    "occlusion",
    "blur_noise",
    "elevation",
    "sparse_stack",
]

#: The appearance families, in the order the benchmark reports them.
FAMILIES: tuple[str, ...] = (
    "bright_face",
    "dark_face",
    "thin_lines",
    "low_contrast",
    "lighting",
    "clutter",
    "occlusion",
    "blur_noise",
    "elevation",
    "sparse_stack",
)

WIDTH, HEIGHT = 1280, 720
#: Most slots of a scene.
MAX_SLOTS = 12
#: Samples of a rim circle (equal angles) in the truth.
RIM_SAMPLES = 720
#: Least radiance step (grey levels, before gamma and lighting) across a rim for it to be an edge.
MIN_EDGE_CONTRAST = 5.0
#: Least fraction of a rim's samples that must be visible edges for a detector to be expected to find it.
MIN_VISIBLE_FRACTION = 0.15

# Independent random streams: overriding one parameter does not change the others' draws.
_STREAMS = ("params", "layout", "noise")


# --------------------------------------------------------------------------------------------
# Parameters and truth
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneParams:
    """The drawn parameters of one scene (lengths in metres, angles in radians, levels in grey levels).

    Attributes:
        family: The appearance family.
        wafer_radius: Wafer radius (0.150 for 300 mm wafers, also 0.100 and 0.075).
        wafer_thickness: Wafer thickness (0.5–1.0 mm): each wafer's edge face spans between its
            upper rim (``z + t/2``) and lower rim (``z − t/2``).
        slot_pitch: Slot pitch (0.010).
        present: Occupancy of slots ``1..n`` (bottom first).
        focal_length: ``fx = fy`` (pixels).
        principal_point: ``(cx, cy)`` (pixels).
        distance: Horizontal distance of the camera centre from the stack axis.
        near_semi_minor: Target semi-minor axis (pixels) of the wafer nearest the camera's height;
            sets the camera's height above (below) the stack.
        camera_below: The camera is below the stack (sees the lower faces).
        lateral: Sideways offset of the camera (world ``y``).
        look_lateral: Sideways offset of the point looked at.
        roll: Camera roll about its optical axis.
        background: Background radiance.
        background_texture: Relative amplitude of the smooth background texture.
        side: Radiance of the wafer edge faces (the band between the rims).
        side_shading: Darkening of the edge face toward the rim tips (0: flat, 1: Lambertian).
        side_spread: Relative per-wafer spread of ``side``.
        mixed_polarity: Each wafer's edge face is at random brighter or darker than the background.
        face: Radiance of the wafer faces turned to the camera.
        face_texture: Relative amplitude of the faces' smooth texture (reflections).
        line: Amplitude of a thin bright line on each rim (0: none; the rim is the line's centre).
        line_width: Width of that line (pixels).
        reflection: Reflectance of the faces for the mirrored edge face of the neighbour above
            (0: none).
        blobs: Number of specular blobs.
        carrier_lines: Number of vertical carrier lines in front of the stack.
        occluders: Number of opaque occluders (discs, blade-like bars) in front of the stack.
        tilt_sigma: Standard deviation of each wafer's tilt about the world ``x`` and ``y`` axes
            (radians; a wafer resting unevenly in its slot).
        shift_sigma: Standard deviation of each wafer's horizontal offset from the stack axis (m).
        blur_sigma: Optical Gaussian PSF σ (pixels), applied with the unit pixel aperture.
        jpeg_quality: JPEG-like compression of the 8-bit image (8×8 DCT blocks, the standard
            luminance table scaled to this quality, 1–100; 0: none).
        gamma: Camera response exponent (``out = 255·(E/255)^gamma``).
        vignetting: Relative darkening at the image corners.
        gradient: Uneven light: relative gain slope across the image ``(x, y)``.
        light_spot: Relative gain of a broad light spot.
        noise_sigma: Gaussian read noise σ (grey levels).
        shot_noise: Shot noise variance per grey level.
        width: Image width (pixels).
        height: Image height (pixels).

    """

    family: str
    wafer_radius: float = 0.150
    wafer_thickness: float = 0.00075
    slot_pitch: float = 0.010
    present: tuple[bool, ...] = (True,) * 5
    focal_length: float = 1000.0
    principal_point: tuple[float, float] = (639.5, 359.5)
    distance: float = 0.45
    near_semi_minor: float = 25.0
    camera_below: bool = False
    lateral: float = 0.0
    look_lateral: float = 0.0
    roll: float = 0.0
    background: float = 30.0
    background_texture: float = 0.1
    side: float = 200.0
    side_shading: float = 0.3
    side_spread: float = 0.05
    mixed_polarity: bool = False
    face: float = 70.0
    face_texture: float = 0.05
    line: float = 0.0
    line_width: float = 1.0
    reflection: float = 0.0
    blobs: int = 0
    carrier_lines: int = 0
    occluders: int = 0
    tilt_sigma: float = 0.0
    shift_sigma: float = 0.0
    blur_sigma: float = 0.7
    jpeg_quality: int = 0
    gamma: float = 1.0
    vignetting: float = 0.05
    gradient: tuple[float, float] = (0.0, 0.0)
    light_spot: float = 0.0
    noise_sigma: float = 2.0
    shot_noise: float = 0.0
    width: int = WIDTH
    height: int = HEIGHT

    def __post_init__(self) -> None:
        _validate(self)

    @property
    def slots(self) -> tuple[int, ...]:
        """Slot numbers ``1..n``."""
        return tuple(range(1, len(self.present) + 1))

    @property
    def K(self) -> NDArray[np.float64]:
        """The 3×3 camera matrix."""
        f, (cx, cy) = self.focal_length, self.principal_point
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class RimTruth:
    """The truth of one rim (a circle of radius ``R`` at ``z ± t/2`` of a wafer).

    Attributes:
        slot: The wafer's slot (its identity in a sweep).
        kind: ``"upper"`` or ``"lower"``.
        ellipse: The exact image of the rim circle.
        points: The rim circle at :data:`RIM_SAMPLES` equal angles, projected, ``(N, 2)``.
        in_image: Per sample: at least 1 px inside the image.
        occluded: Per sample: behind a nearer wafer or an occluder (or within 1 px of one).
        edge: Per sample: the radiance steps by at least :data:`MIN_EDGE_CONTRAST` across the
            rim there (for thin lines: the line stands out by that much), before lighting.
        visible_fraction: Fraction of samples that are in the image, not occluded, and an edge.
        visible: ``visible_fraction ≥ MIN_VISIBLE_FRACTION``.
        camera_side: The rim bounds the face turned to the camera (its whole circle can be an
            edge); the other rim is hidden behind that face along its back arc.

    """

    slot: int
    kind: Literal["upper", "lower"]
    ellipse: Ellipse
    points: NDArray[np.float64]
    in_image: NDArray[np.bool_]
    occluded: NDArray[np.bool_]
    edge: NDArray[np.bool_]
    visible_fraction: float
    visible: bool
    camera_side: bool


@dataclass(frozen=True)
class WaferTruth:
    """The truth of one slot.

    Attributes:
        slot: Slot number (1 = bottom).
        present: A wafer is in the slot.
        upper: Its upper rim, or ``None`` for an empty slot.
        lower: Its lower rim, or ``None`` for an empty slot.
        centre: The wafer's centre (world, m), ``None`` for an empty slot.
        normal: Its unit normal (world; the upper rim is at ``centre + t/2·normal``).

    """

    slot: int
    present: bool
    upper: RimTruth | None
    lower: RimTruth | None
    centre: NDArray[np.float64] | None = None
    normal: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class CarrierScene:
    """One generated image with its ground truth (see the module docstring).

    Attributes:
        image: ``(height, width)`` uint8.
        K: The 3×3 camera matrix (pinhole, no distortion).
        T_wc: Camera pose (camera to world), 4×4.
        params: The scene parameters.
        wafers: One :class:`WaferTruth` per slot, bottom first.
        seed: The seed of the scene's random streams.
        extra: Free-form metadata for callers (empty when generated).

    """

    image: NDArray[np.uint8]
    K: NDArray[np.float64]
    T_wc: NDArray[np.float64]
    params: SceneParams
    wafers: list[WaferTruth]
    seed: int
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def family(self) -> str:
        """The appearance family."""
        return self.params.family

    @property
    def T_cw(self) -> NDArray[np.float64]:
        """World to camera (the inverse of :attr:`T_wc`)."""
        return _inverse(self.T_wc)

    @property
    def rims(self) -> list[RimTruth]:
        """Every rim of every present wafer (upper before lower, bottom wafer first)."""
        return [r for w in self.wafers if w.present for r in (w.upper, w.lower) if r is not None]

    @property
    def visible_rims(self) -> list[RimTruth]:
        """The rims a detector is expected to find."""
        return [r for r in self.rims if r.visible]


def _check_family(family: Any) -> str:
    if not isinstance(family, str) or family not in FAMILIES:
        raise InvalidInputError(f"unknown appearance family {family!r}; expected one of {', '.join(FAMILIES)}")
    return family


def _check_int(value: Any, name: str, low: int, high: int) -> int:
    if isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{name} must be an integer, got {value!r}")
    try:
        n = operator.index(value)
    except TypeError:
        raise InvalidInputError(f"{name} must be an integer, got {value!r}") from None
    if not low <= n <= high:
        raise InvalidInputError(f"{name} must be in [{low}, {high}], got {n}")
    return n


def _validate(p: SceneParams) -> None:
    _check_family(p.family)
    floats = {
        "wafer_radius": (1e-3, 1.0),
        "wafer_thickness": (1e-5, 0.01),
        "slot_pitch": (1e-3, 0.1),
        "focal_length": (50.0, 1e5),
        "distance": (0.05, 10.0),
        "near_semi_minor": (0.5, 1e4),
        "background": (0.0, 1e4),
        "background_texture": (0.0, 1.0),
        "side": (0.0, 1e4),
        "side_shading": (0.0, 1.0),
        "side_spread": (0.0, 1.0),
        "face": (0.0, 1e4),
        "face_texture": (0.0, 1.0),
        "line": (0.0, 1e4),
        "line_width": (0.05, 20.0),
        "reflection": (0.0, 1.0),
        "blur_sigma": (0.0, 20.0),
        "tilt_sigma": (0.0, 0.1),
        "shift_sigma": (0.0, 0.05),
        "gamma": (0.05, 20.0),
        "vignetting": (0.0, 0.95),
        "light_spot": (-0.9, 5.0),
        "noise_sigma": (0.0, 255.0),
        "shot_noise": (0.0, 100.0),
        "lateral": (-10.0, 10.0),
        "look_lateral": (-10.0, 10.0),
        "roll": (-math.pi, math.pi),
    }
    for name, (lo, hi) in floats.items():
        v = getattr(p, name)
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise InvalidInputError(f"{name} must be a real number, got {v!r}")
        if not (math.isfinite(float(v)) and lo <= float(v) <= hi):
            raise InvalidInputError(f"{name} must be finite and in [{lo}, {hi}], got {v!r}")
    for name in ("blobs", "carrier_lines", "occluders", "jpeg_quality"):
        _check_int(getattr(p, name), name, 0, 100)
    _check_int(p.width, "width", 16, 8192)
    _check_int(p.height, "height", 16, 8192)
    if not isinstance(p.present, tuple) or not 1 <= len(p.present) <= MAX_SLOTS:
        raise InvalidInputError(f"present must be a tuple of 1 to {MAX_SLOTS} booleans, got {p.present!r}")
    if not any(p.present):
        raise InvalidInputError("present must hold at least one occupied slot")
    if p.wafer_thickness >= p.slot_pitch:
        raise InvalidInputError(f"wafer_thickness {p.wafer_thickness} must be below slot_pitch {p.slot_pitch}")
    for name in ("principal_point", "gradient"):
        v = np.asarray(getattr(p, name), dtype=np.float64)
        if v.shape != (2,) or not np.all(np.isfinite(v)):
            raise InvalidInputError(f"{name} must be two finite numbers, got {getattr(p, name)!r}")
    if p.distance <= p.wafer_radius * 1.2:
        raise InvalidInputError(
            f"distance {p.distance} m must exceed 1.2 × wafer_radius ({p.wafer_radius} m): the camera is in the stack"
        )


# --------------------------------------------------------------------------------------------
# Family distributions
# --------------------------------------------------------------------------------------------


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _base(rng: np.random.Generator, family: str) -> dict[str, Any]:
    """Parameters shared by every family (the camera and the stack), before the family's own."""
    radius = float(rng.choice([0.150, 0.100, 0.075], p=[0.6, 0.2, 0.2]))
    distance = float(rng.uniform(0.30, 0.60)) * (0.55 + 0.45 * radius / 0.150)
    # The whole wafer fits in 85–110 % of the image width.
    f_max = 0.55 * WIDTH * distance / radius
    focal = float(min(rng.uniform(800.0, 1400.0), f_max))
    n = int(rng.integers(3, 9))
    return {
        "family": family,
        "wafer_radius": radius,
        "wafer_thickness": float(rng.uniform(0.0005, 0.0010)),
        "slot_pitch": 0.010,
        "present": (True,) * n,
        "focal_length": focal,
        "principal_point": (639.5 + float(rng.uniform(-20, 20)), 359.5 + float(rng.uniform(-15, 15))),
        "distance": distance,
        "near_semi_minor": _log_uniform(rng, 8.0, 40.0),
        "camera_below": False,
        "lateral": float(rng.uniform(-0.15, 0.15)) * radius,
        "look_lateral": float(rng.uniform(-0.05, 0.05)) * radius,
        "roll": math.radians(float(rng.uniform(-2.0, 2.0))),
        "side_shading": float(rng.uniform(0.0, 0.5)),
        "side_spread": float(rng.uniform(0.0, 0.1)),
        "face_texture": float(rng.uniform(0.0, 0.1)),
        "background_texture": float(rng.uniform(0.0, 0.15)),
        "blur_sigma": float(rng.uniform(0.4, 1.0)),
        "tilt_sigma": math.radians(float(rng.uniform(0.0, 0.2))),
        "shift_sigma": float(rng.uniform(0.0, 0.001)),
        "gamma": float(rng.uniform(0.9, 1.1)),
        "vignetting": float(rng.uniform(0.0, 0.15)),
        "gradient": (float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.1, 0.1))),
        "noise_sigma": float(rng.uniform(1.0, 3.0)),
    }


def _bright(rng: np.random.Generator) -> dict[str, Any]:
    bg = float(rng.uniform(10, 50))
    face = float(rng.uniform(bg + 10, bg + 70))
    return {"background": bg, "face": face, "side": float(rng.uniform(max(face + 50, 130), 260))}


def _dark(rng: np.random.Generator) -> dict[str, Any]:
    bg = float(rng.uniform(150, 230))
    return {
        "background": bg,
        "background_texture": float(rng.uniform(0.05, 0.2)),
        "side": float(rng.uniform(10, 60)),
        "face": float(rng.uniform(80, bg - 25)),
        "face_texture": float(rng.uniform(0.02, 0.15)),
    }


def _family(rng: np.random.Generator, family: str) -> dict[str, Any]:
    """The family's own parameters (see ``docs/design/appearance-generator.md``)."""
    if family == "bright_face":
        return _bright(rng)
    if family == "dark_face":
        return _dark(rng)
    if family == "thin_lines":
        bg = float(rng.uniform(5, 40))
        return {
            "background": bg,
            "face": float(np.clip(bg + rng.uniform(-10, 15), 0, None)),
            "side": float(np.clip(bg + rng.uniform(-5, 15), 0, None)),
            "line": float(rng.uniform(90, 220)),
            "line_width": float(rng.uniform(0.6, 1.5)),
            "side_shading": 0.0,
        }
    if family == "low_contrast":
        bg = float(rng.uniform(40, 160))
        return {
            "background": bg,
            "face": float(bg + rng.uniform(-4, 4)),
            "side": float(bg + rng.uniform(8, 20)),
            "side_shading": 0.0,
            "side_spread": 0.0,
            "background_texture": float(rng.uniform(0.0, 0.03)),
            "face_texture": float(rng.uniform(0.0, 0.03)),
        }
    if family == "lighting":
        out = _bright(rng) if rng.random() < 0.5 else _dark(rng)
        out.update(
            gamma=_log_uniform(rng, 0.4, 2.5),
            vignetting=float(rng.uniform(0.3, 0.7)),
            gradient=(float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5))),
            light_spot=float(rng.uniform(-0.4, 1.0)),
        )
        if rng.random() < 0.4:
            # Mixed polarity: mid-grey background, each edge face brighter or darker.
            bg = float(rng.uniform(90, 140))
            out.update(background=bg, face=float(bg + rng.uniform(-30, 30)), side=float(bg + rng.uniform(50, 100)))
            out["mixed_polarity"] = True
        return out
    if family == "clutter":
        out = _bright(rng)
        out.update(
            blobs=int(rng.integers(3, 13)),
            carrier_lines=int(rng.integers(2, 7)),
            reflection=float(rng.uniform(0.15, 0.5)),
        )
        return out
    if family == "occlusion":
        out = _bright(rng) if rng.random() < 0.7 else _dark(rng)
        out["occluders"] = int(rng.integers(1, 4))
        return out
    if family == "blur_noise":
        out = _bright(rng) if rng.random() < 0.7 else _dark(rng)
        out.update(
            blur_sigma=float(rng.uniform(0.5, 2.0)),
            noise_sigma=float(rng.uniform(2.0, 8.0)),
            shot_noise=float(rng.uniform(0.0, 0.1)),
            jpeg_quality=int(rng.integers(40, 96)) if rng.random() < 0.5 else 0,
        )
        return out
    if family == "elevation":
        out = _bright(rng) if rng.random() < 0.7 else _dark(rng)
        out.update(
            near_semi_minor=_log_uniform(rng, 3.0, 150.0),
            camera_below=bool(rng.random() < 0.4),
            present=(True,) * int(rng.integers(2, 7)),
        )
        return out
    # sparse_stack
    out = _bright(rng) if rng.random() < 0.7 else _dark(rng)
    n = int(rng.integers(1, MAX_SLOTS + 1))
    occupancy = float(rng.uniform(0.3, 0.9))
    present = rng.random(n) < occupancy
    if not present.any():
        present[int(rng.integers(n))] = True
    out["present"] = tuple(bool(v) for v in present)
    return out


def _streams(seed: Any) -> dict[str, np.random.Generator]:
    s = _check_int(seed, "seed", 0, 2**63 - 1)
    children = np.random.SeedSequence(s).spawn(len(_STREAMS))
    return {name: np.random.default_rng(c) for name, c in zip(_STREAMS, children, strict=True)}


def draw_params(family: str, seed: int, **overrides: Any) -> SceneParams:
    """Draw the parameters of a scene of ``family`` (deterministic for ``seed``).

    Args:
        family: One of :data:`FAMILIES`.
        seed: Non-negative integer.
        **overrides: :class:`SceneParams` fields to set instead of drawing them, and ``wafers``:
            the number of slots (1–:data:`MAX_SLOTS`, all occupied, except in ``sparse_stack``
            where the drawn occupancy is kept, at least one slot occupied).

    Raises:
        InvalidInputError: Unknown family or override, a value out of range.

    """
    family = _check_family(family)
    rng = _streams(seed)["params"]
    values = _base(rng, family)
    values.update(_family(rng, family))
    overrides = dict(overrides)
    wafers = overrides.pop("wafers", None)
    if wafers is not None:
        n = _check_int(wafers, "wafers", 1, MAX_SLOTS)
        if family == "sparse_stack":
            occ = rng.random(n) < 0.6
            occ[int(rng.integers(n))] = True
            values["present"] = tuple(bool(v) for v in occ)
        else:
            values["present"] = (True,) * n
    names = {f.name for f in dataclasses.fields(SceneParams)}
    unknown = sorted(set(overrides) - names - {"family"})
    if unknown:
        raise InvalidInputError(f"unknown scene parameter(s) {unknown}; known: wafers, {', '.join(sorted(names))}")
    if "family" in overrides and overrides["family"] != family:
        raise InvalidInputError("family cannot be overridden")
    values.update(overrides)
    if "present" in overrides:
        values["present"] = tuple(bool(v) for v in overrides["present"])
    return SceneParams(**values)


# --------------------------------------------------------------------------------------------
# Camera
# --------------------------------------------------------------------------------------------


def _inverse(T: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def look_at_pose(position: Any, target: Any, roll: float = 0.0) -> NDArray[np.float64]:
    """Camera pose ``T_wc`` at ``position`` looking at ``target`` with world ``z`` up in the image, rolled.

    The camera frame is ``x`` right, ``y`` down, ``z`` forward (pinhole convention).
    """
    c = np.asarray(position, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - c
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    cr, sr = math.cos(roll), math.sin(roll)
    x_c, y_c = cr * right + sr * down, -sr * right + cr * down
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x_c, y_c, fwd, c
    return T


def _stack_z(p: SceneParams) -> tuple[float, float]:
    """Heights of the topmost upper surface and the lowest lower surface of the slots."""
    n = len(p.present)
    return (n - 1) * p.slot_pitch + 0.5 * p.wafer_thickness, -0.5 * p.wafer_thickness


def camera_position(p: SceneParams) -> NDArray[np.float64]:
    """Camera centre: ``distance`` in front of the stack, at the height giving ``near_semi_minor``."""
    a_est = p.focal_length * p.wafer_radius / p.distance
    elevation = math.asin(min(p.near_semi_minor / a_est, 0.9))
    h = p.distance * math.tan(elevation)
    top, bottom = _stack_z(p)
    z = bottom - h if p.camera_below else top + h
    return np.array([-p.distance, p.lateral, z])


def default_pose(p: SceneParams) -> NDArray[np.float64]:
    """The scene's camera pose: at :func:`camera_position`, looking at the stack's middle."""
    top, bottom = _stack_z(p)
    return look_at_pose(camera_position(p), [0.0, p.look_lateral, 0.5 * (top + bottom)], p.roll)


def sweep_poses(p: SceneParams, frames: int, span: float | None = None) -> list[NDArray[np.float64]]:
    """Camera poses of a sweep: the default pose translated sideways (world ``y``) over ``span`` metres.

    The orientation is fixed (a blade camera moved by the robot); ``span`` defaults to 0.8 wafer
    radii, so the stack moves by about a third of the image.
    """
    base = default_pose(p)
    s = 0.8 * p.wafer_radius if span is None else float(span)
    out = []
    for i in range(frames):
        T = base.copy()
        T[1, 3] += s * (i / max(frames - 1, 1) - 0.5)
        out.append(T)
    return out


# --------------------------------------------------------------------------------------------
# Edge-spread function (Gaussian optics ⊗ unit square pixel)
# --------------------------------------------------------------------------------------------


def _erf(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Error function, Abramowitz & Stegun 7.1.26 (absolute error < 1.5e-7)."""
    s = np.sign(x)
    a = np.abs(x)
    t = 1.0 / (1.0 + 0.3275911 * a)
    y = 1.0 - (
        ((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592
    ) * t * np.exp(-a * a)
    return s * y


def _f2(x: NDArray[np.float64], sigma: float) -> NDArray[np.float64]:
    """Second antiderivative of the Gaussian CDF ``Φ(x/σ)``: ``((x² + σ²)Φ + xσφ)/2`` (σ = 0: ``max(x, 0)²/2``)."""
    if sigma <= 1e-9:
        return 0.5 * np.maximum(x, 0.0) ** 2
    z = x / sigma
    cdf = 0.5 * (1.0 + _erf(z / math.sqrt(2.0)))
    pdf = np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
    return 0.5 * ((x * x + sigma * sigma) * cdf + x * sigma * pdf)


def _f1(x: NDArray[np.float64], sigma: float) -> NDArray[np.float64]:
    """Antiderivative of ``Φ(x/σ)``: ``xΦ + σφ`` (σ = 0: ``max(x, 0)``)."""
    if sigma <= 1e-9:
        return np.maximum(x, 0.0)
    z = x / sigma
    cdf = 0.5 * (1.0 + _erf(z / math.sqrt(2.0)))
    pdf = np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
    return x * cdf + sigma * pdf


def edge_coverage(d: Any, nx: Any, ny: Any, sigma: float) -> NDArray[np.float64]:
    """Fraction of a pixel's light that comes from the inside of a straight edge.

    The pixel (a unit square aperture centred on the pixel centre) sees the scene through a
    Gaussian optical PSF of ``sigma``; the edge is a straight line at signed distance ``d`` from
    the pixel centre (positive: the centre is outside) with unit normal ``(nx, ny)``. The
    square's projection onto the normal is the convolution of two boxes of widths
    ``p = |nx|``, ``q = |ny|`` (a trapezoid), so the coverage is
    ``E[Φ((−d − U_p − U_q)/σ)]`` = a second difference of the second antiderivative of ``Φ``
    divided by ``p·q`` (a first difference divided by ``p`` when ``q`` vanishes).
    """
    d = np.asarray(d, dtype=np.float64)
    p = np.abs(np.asarray(nx, dtype=np.float64))
    q = np.abs(np.asarray(ny, dtype=np.float64))
    p, q = np.maximum(p, q), np.minimum(p, q)
    t = -d
    small = q < 1e-3
    qs = np.where(small, 1.0, q)
    two = (
        _f2(t + 0.5 * (p + qs), sigma)
        - _f2(t + 0.5 * (p - qs), sigma)
        - _f2(t - 0.5 * (p - qs), sigma)
        + _f2(t - 0.5 * (p + qs), sigma)
    ) / (p * qs)
    one = (_f1(t + 0.5 * p, sigma) - _f1(t - 0.5 * p, sigma)) / p
    return np.clip(np.where(small, one, two), 0.0, 1.0)


class _CoverageTable:
    """:func:`edge_coverage` tabulated for one σ over the signed distance and the normal's angle.

    Bilinear interpolation on a grid of 1/64 px in ``d`` and 32 steps of ``min(|nx|, |ny|)`` in
    ``[0, 1/√2]``; the test holds it to 2e-4 of the closed form (5e-4 without blur).
    """

    STEP = 1.0 / 64.0
    Q_STEPS = 32

    def __init__(self, sigma: float) -> None:
        self.sigma = sigma
        self.reach = 0.5 * math.sqrt(2.0) + 5.0 * sigma + 1.0
        n = int(math.ceil(self.reach / self.STEP))
        self.d0 = -n * self.STEP
        d = self.d0 + self.STEP * np.arange(2 * n + 1)
        q = np.linspace(0.0, math.sqrt(0.5), self.Q_STEPS + 1)
        qq, dd = np.meshgrid(q, d, indexing="ij")
        self.table = edge_coverage(dd, np.sqrt(1.0 - qq * qq), qq, sigma)

    def __call__(self, d: NDArray[np.float64], nx: NDArray[np.float64], ny: NDArray[np.float64]) -> NDArray[np.float64]:
        out = (d < 0).astype(np.float64)
        near = np.abs(d) < self.reach
        if near.all():
            return self._lookup(d, nx, ny)
        out[near] = self._lookup(d[near], nx[near], ny[near])
        return out

    def _lookup(self, d: NDArray[np.float64], nx: NDArray[np.float64], ny: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.minimum(np.abs(nx), np.abs(ny)) * (self.Q_STEPS / math.sqrt(0.5))
        fd = (np.clip(d, self.d0, -self.d0) - self.d0) / self.STEP
        iq = np.minimum(q.astype(np.intp), self.Q_STEPS - 1)
        idd = np.minimum(fd.astype(np.intp), self.table.shape[1] - 2)
        wq = q - iq
        wd = fd - idd
        t = self.table
        lo = t[iq, idd] * (1.0 - wd) + t[iq, idd + 1] * wd
        hi = t[iq + 1, idd] * (1.0 - wd) + t[iq + 1, idd + 1] * wd
        return lo * (1.0 - wq) + hi * wq


_TABLES: dict[float, _CoverageTable] = {}


def _coverage_table(sigma: float) -> _CoverageTable:
    """The (cached) table of ``sigma``."""
    t = _TABLES.get(sigma)
    if t is None:
        if len(_TABLES) > 64:
            _TABLES.clear()
        t = _TABLES[sigma] = _CoverageTable(sigma)
    return t


def _kernel_radius(sigma: float, extra: float = 0.0) -> int:
    """Distance (pixels) beyond which a pixel's coverage of a boundary is exactly 0 or 1 (to 3e-7)."""
    return int(math.ceil(0.5 * math.sqrt(2.0) + 5.0 * sigma + extra)) + 1


# --------------------------------------------------------------------------------------------
# Ellipses on a pixel window
# --------------------------------------------------------------------------------------------


class _Conic:
    """An ellipse with its conic (negative inside) for fast inside tests and column roots."""

    def __init__(self, ellipse: Ellipse) -> None:
        self.ellipse = ellipse
        self.C = np.asarray(ellipse.conic(), dtype=np.float64)
        e = ellipse
        c, s = math.cos(e.theta), math.sin(e.theta)
        hx = math.sqrt((e.a * c) ** 2 + (e.b * s) ** 2)
        hy = math.sqrt((e.a * s) ** 2 + (e.b * c) ** 2)
        self.bbox = (e.cx - hx, e.cx + hx, e.cy - hy, e.cy + hy)

    def value(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        C = self.C
        return C[0, 0] * x * x + 2 * C[0, 1] * x * y + C[1, 1] * y * y + 2 * C[0, 2] * x + 2 * C[1, 2] * y + C[2, 2]

    def gradient(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        C = self.C
        gx = C[0, 0] * x + C[0, 1] * y + C[0, 2]
        gy = C[0, 1] * x + C[1, 1] * y + C[1, 2]
        n = np.hypot(gx, gy)
        n = np.where(n > 0, n, 1.0)
        return gx / n, gy / n

    def column_roots(self, xs: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Rows where each column ``x`` crosses the ellipse (top, bottom); NaN where it does not."""
        C = self.C
        half_b = C[0, 1] * xs + C[1, 2]
        c0 = C[0, 0] * xs * xs + 2 * C[0, 2] * xs + C[2, 2]
        disc = half_b * half_b - C[1, 1] * c0
        ok = disc >= 0
        r = np.sqrt(np.where(ok, disc, 0.0))
        top = np.where(ok, (-half_b - r) / C[1, 1], np.nan)
        bot = np.where(ok, (-half_b + r) / C[1, 1], np.nan)
        return top, bot


def _sliding(values: NDArray[np.float64], r: int, fn: Any) -> NDArray[np.float64]:
    """``fn``-reduce (np.fmin / np.fmax, NaN-ignoring) over windows ``[i − r, i + r]``."""
    padded = np.concatenate([np.full(r, np.nan), values, np.full(r, np.nan)])
    view = np.lib.stride_tricks.sliding_window_view(padded, 2 * r + 1)
    return fn.reduce(view, axis=1)


@dataclass
class _Window:
    """A rectangle of pixels ``[x0, x1) × [y0, y1)`` with the signed distances of its band pixels."""

    x0: int
    x1: int
    y0: int
    y1: int
    band: NDArray[np.bool_]
    bx: NDArray[np.float64]
    by: NDArray[np.float64]
    own: list[NDArray[np.bool_]]  # per conic, which band pixels are within its own band

    @property
    def shape(self) -> tuple[int, int]:
        return (self.y1 - self.y0, self.x1 - self.x0)

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.y0, self.y1), slice(self.x0, self.x1)


def _window(conics: list[_Conic], r: int, width: int, height: int) -> _Window | None:
    """The pixel window around ``conics`` with the band of pixels within ``r`` of any of them."""
    xmin = min(c.bbox[0] for c in conics) - r - 1
    xmax = max(c.bbox[1] for c in conics) + r + 1
    ymin = min(c.bbox[2] for c in conics) - r - 1
    ymax = max(c.bbox[3] for c in conics) + r + 1
    x0, x1 = max(int(math.floor(xmin)), 0), min(int(math.ceil(xmax)) + 1, width)
    y0, y1 = max(int(math.floor(ymin)), 0), min(int(math.ceil(ymax)) + 1, height)
    if x0 >= x1 or y0 >= y1:
        return None
    xs = np.arange(x0, x1, dtype=np.float64)
    rows = np.arange(y0, y1, dtype=np.float64)[:, None]
    bands = []
    for c in conics:
        band = np.zeros((y1 - y0, x1 - x0), dtype=bool)
        top, bot = c.column_roots(xs)
        for curve in (top, bot):
            lo = _sliding(curve, r, np.fmin) - r
            hi = _sliding(curve, r, np.fmax) + r
            band |= (rows >= lo[None, :]) & (rows <= hi[None, :])
        # Rows between the two crossings of a column near a tip, where they are within r.
        lo = _sliding(top, r, np.fmin) - r
        hi = _sliding(bot, r, np.fmax) + r
        thin = (_sliding(bot - top, r, np.fmin) <= 2 * r + 2) & np.isfinite(lo)
        band |= thin[None, :] & (rows >= lo[None, :]) & (rows <= hi[None, :])
        bands.append(band)
    union = np.logical_or.reduce(bands)
    iy, ix = np.nonzero(union)
    own = [b[union] for b in bands]
    return _Window(x0, x1, y0, y1, union, (ix + x0).astype(np.float64), (iy + y0).astype(np.float64), own)


def _inside(conic: _Conic, win: _Window) -> NDArray[np.float64]:
    xs = np.arange(win.x0, win.x1, dtype=np.float64)
    top, bot = conic.column_roots(xs)
    rows = np.arange(win.y0, win.y1, dtype=np.float64)[:, None]
    return ((rows > top[None, :]) & (rows < bot[None, :])).astype(np.float64)


class _Boundary:
    """Signed distances of a window's band pixels to one ellipse, with its normals.

    Along the line through the pixel in the direction ``n`` of the conic's gradient, the conic is
    an exact quadratic ``Q − |∇Q|·s + ½·nᵀHn·s² = 0``; its root nearest the pixel is the distance
    to the ellipse along that line. It equals the orthogonal distance to second order in the angle
    between ``n`` and the ellipse's normal at the line's foot point; where the estimated
    difference ``|d|·(1 − cos Δθ)`` exceeds 0.001 px, or the line misses the ellipse, the exact
    orthogonal distance (:meth:`Ellipse.distance`) is used (near the tips of flat ellipses), and
    so it is inside where the chord along the minor axis is shorter than that distance. Pixels
    farther than ``reach`` (where only the sign matters) keep the line distance.
    """

    TOL = 0.001

    def __init__(self, conic: _Conic, win: _Window, reach: float = math.inf, index: int = 0) -> None:
        self.conic = conic
        self.win = win
        self.inside = _inside(conic, win)
        own = win.own[index]
        # Band pixels of the other conics only need the sign: coverage 0 or 1.
        inside_band = self.inside[win.band] > 0
        self.d = np.where(inside_band, -(reach + 10.0), reach + 10.0)
        self.nx, self.ny = np.ones(len(own)), np.zeros(len(own))
        if own.any():
            d, nx, ny = self._distances(win.bx[own], win.by[own], reach)
            self.d[own], self.nx[own], self.ny[own] = d, nx, ny

    def _distances(
        self, x: NDArray[np.float64], y: NDArray[np.float64], reach: float
    ) -> tuple[NDArray[np.float64], ...]:
        conic = self.conic
        C = conic.C
        gx = 2.0 * (C[0, 0] * x + C[0, 1] * y + C[0, 2])
        gy = 2.0 * (C[0, 1] * x + C[1, 1] * y + C[1, 2])
        gn = np.hypot(gx, gy)
        ok = gn > 1e-12
        gs = np.where(ok, gn, 1.0)
        nx, ny = gx / gs, gy / gs
        q = conic.value(x, y)
        hnn = 2.0 * (C[0, 0] * nx * nx + 2.0 * C[0, 1] * nx * ny + C[1, 1] * ny * ny)
        disc = gs * gs - 2.0 * hnn * q
        ok &= disc >= 0
        d = 2.0 * q / (gs + np.sqrt(np.maximum(disc, 0.0)))
        # The normal at the line's foot point f = p − d·n: the line is orthogonal to the ellipse
        # when it is parallel to n; the distance's error is ≈ |d|·(1 − cos Δθ).
        fx, fy = x - d * nx, y - d * ny
        fgx = C[0, 0] * fx + C[0, 1] * fy + C[0, 2]
        fgy = C[0, 1] * fx + C[1, 1] * fy + C[1, 2]
        cos = (fgx * nx + fgy * ny) / np.maximum(np.hypot(fgx, fgy), 1e-300)
        err = np.abs(d) * (1.0 - cos)
        # Beyond `reach` only the sign matters (coverage is exactly 0 or 1 there).
        exact = ~ok | ((err > self.TOL) & (np.abs(d) - 10.0 * err < reach))
        # Inside a flat ellipse near its major axis the gradient line runs to the tip, another
        # stationary point of the distance: the chord along the minor axis is shorter there.
        e = conic.ellipse
        ux, uy = -math.sin(e.theta), math.cos(e.theta)
        gu = gx * ux + gy * uy
        cu = C[0, 0] * ux * ux + 2.0 * C[0, 1] * ux * uy + C[1, 1] * uy * uy
        chord = (np.sqrt(np.maximum(gu * gu - 4.0 * cu * q, 0.0)) - np.abs(gu)) / (2.0 * cu)
        exact |= (q < 0) & (chord < np.abs(d) - self.TOL) & (chord < reach)
        if exact.any():
            d[exact] = conic.ellipse.distance(np.column_stack([x[exact], y[exact]]))
        return d, nx, ny


def _fill(win: _Window, base: NDArray[np.float64], band_values: NDArray[np.float64]) -> NDArray[np.float64]:
    out = base.copy()
    out[win.band] = band_values
    return out


def _region(bounds: list[_Boundary], sigma: float) -> NDArray[np.float64]:
    """Coverage of the union of the ellipses' interiors (signed distance of a union: the minimum)."""
    win = bounds[0].win
    inside = np.maximum.reduce([b.inside for b in bounds])
    if len(bounds) == 1:
        b = bounds[0]
        return _fill(win, inside, _coverage_table(sigma)(b.d, b.nx, b.ny))
    ds = np.stack([b.d for b in bounds])
    k = np.argmin(ds, axis=0)
    idx = np.arange(ds.shape[1])
    nx = np.stack([b.nx for b in bounds])[k, idx]
    ny = np.stack([b.ny for b in bounds])[k, idx]
    return _fill(win, inside, _coverage_table(sigma)(ds[k, idx], nx, ny))


def _line(b: _Boundary, width: float, sigma: float) -> NDArray[np.float64]:
    """Coverage of a thin line of ``width`` centred on the ellipse: ``{|d| < w/2}``."""
    cov = _coverage_table(sigma)
    vals = cov(b.d - 0.5 * width, b.nx, b.ny) - cov(b.d + 0.5 * width, b.nx, b.ny)
    return _fill(b.win, np.zeros(b.win.shape), np.clip(vals, 0.0, 1.0))


# --------------------------------------------------------------------------------------------
# Smooth fields (texture, shading)
# --------------------------------------------------------------------------------------------


class _Texture:
    """A smooth random field ``Σ A_i cos(k_i·x + φ_i)``, unit RMS, wavelengths 60–600 px."""

    def __init__(self, rng: np.random.Generator, terms: int = 6) -> None:
        wavelength = np.exp(rng.uniform(math.log(60.0), math.log(600.0), terms))
        angle = rng.uniform(0.0, math.pi, terms)
        k = 2 * math.pi / wavelength
        self.kx, self.ky = k * np.cos(angle), k * np.sin(angle)
        self.phase = rng.uniform(0.0, 2 * math.pi, terms)
        self.amp = rng.uniform(0.5, 1.0, terms)
        self.amp *= math.sqrt(2.0 / float(np.sum(self.amp**2)))

    def at(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros(np.broadcast(x, y).shape)
        for a, kx, ky, ph in zip(self.amp, self.kx, self.ky, self.phase, strict=True):
            out += a * np.cos(kx * x + ky * y + ph)
        return out

    def grid(self, xs: NDArray[np.float64], ys: NDArray[np.float64]) -> NDArray[np.float64]:
        """On the grid ``ys × xs``: ``cos(u + v) = cos u cos v − sin u sin v``, one matrix product."""
        u = np.outer(xs, self.kx) + self.phase  # (W, terms)
        v = np.outer(ys, self.ky)  # (H, terms)
        left = np.hstack([np.cos(v) * self.amp, -np.sin(v) * self.amp])
        right = np.hstack([np.cos(u), np.sin(u)])
        return left @ right.T


# --------------------------------------------------------------------------------------------
# Scene layout
# --------------------------------------------------------------------------------------------


@dataclass
class _Wafer:
    """One present wafer as painted: its rims, which one faces the camera, its radiances."""

    slot: int
    z: float
    centre: NDArray[np.float64]
    normal: NDArray[np.float64]
    upper: Ellipse
    lower: Ellipse
    camera_above: bool
    side: float
    face: float
    order: float  # painted in decreasing order (farther from the camera's height first)
    virtual: tuple[Ellipse, Ellipse] | None = None  # mirrored edge face of the neighbour

    @property
    def cam(self) -> Ellipse:
        return self.upper if self.camera_above else self.lower

    @property
    def far(self) -> Ellipse:
        return self.lower if self.camera_above else self.upper


@dataclass
class _Layout:
    """Everything drawn from the ``layout`` stream, fixed across the frames of a sweep."""

    background: _Texture
    face: _Texture
    side_gain: NDArray[np.float64]  # per slot
    posts: list[tuple[float, float, float, float]]  # world x, y, diameter (m), radiance
    occluders: list[tuple[str, tuple[float, ...], float]]  # ("disc", (cx, cy, r)) / ("rect", (x0, x1, y0, y1))
    blobs: list[tuple[float, float, float, float]]  # u, v, sigma (px), amplitude
    spot: tuple[float, float, float]  # u, v, sigma (px)
    plate_gap: float  # gap to the carrier's top plate (m), mirrored in the top wafer
    tilts: NDArray[np.float64]  # per slot (rx, ry) in units of tilt_sigma
    shifts: NDArray[np.float64]  # per slot (dx, dy) in units of shift_sigma


def _circle_image(
    K: NDArray[np.float64], T_cw: NDArray[np.float64], p: SceneParams, centre: NDArray[np.float64], normal: Any
) -> Ellipse:
    return project_circle(K, T_cw, centre, normal, p.wafer_radius)


def _wafer_frame(p: SceneParams, layout: _Layout, slot: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centre and unit normal of the wafer in ``slot``: slot height, tilt ``Ry·Rx``, horizontal offset."""
    rx, ry = layout.tilts[slot - 1] * p.tilt_sigma
    dx, dy = layout.shifts[slot - 1] * p.shift_sigma
    normal = np.array([math.sin(ry) * math.cos(rx), -math.sin(rx), math.cos(ry) * math.cos(rx)])
    return np.array([dx, dy, (slot - 1) * p.slot_pitch]), normal


def _project(K: NDArray[np.float64], T_cw: NDArray[np.float64], X: NDArray[np.float64]) -> NDArray[np.float64]:
    Xc = X @ T_cw[:3, :3].T + T_cw[:3, 3]
    uvw = Xc @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def _wafers(p: SceneParams, K: NDArray[np.float64], T_wc: NDArray[np.float64], layout: _Layout) -> list[_Wafer]:
    T_cw = _inverse(T_wc)
    zc = float(T_wc[2, 3])
    h = 0.5 * p.wafer_thickness
    out = []
    for slot, here in zip(p.slots, p.present, strict=True):
        if not here:
            continue
        centre, normal = _wafer_frame(p, layout, slot)
        z = float(centre[2])
        height = float(np.dot(T_wc[:3, 3] - centre, normal))
        if abs(height) <= h:
            raise DegenerateGeometryError(f"the camera (z = {zc:.4f} m) is in the plane of wafer {slot}'s edge face")
        side = p.side * float(layout.side_gain[slot - 1])
        if p.mixed_polarity and layout.side_gain[slot - 1] < 1.0:
            side = max(2.0 * p.background - p.side, 0.0)
        out.append(
            _Wafer(
                slot=slot,
                z=z,
                centre=centre,
                normal=normal,
                upper=_circle_image(K, T_cw, p, centre + h * normal, normal),
                lower=_circle_image(K, T_cw, p, centre - h * normal, normal),
                camera_above=height > 0,
                side=side,
                face=p.face,
                order=abs(height),
            )
        )
    if p.reflection > 0:
        present_z = sorted(w.z for w in out)
        for w in out:
            # The face turned to the camera mirrors the edge face of the next wafer beyond it (or
            # the carrier's plate); the mirror image lies `gap` behind the face's plane.
            if w.camera_above:
                above = [z for z in present_z if z > w.z]
                plane = w.z + h
                gap = (above[0] - h - plane) if above else layout.plate_gap
                zs = (plane - gap, plane - gap - p.wafer_thickness)
            else:
                below = [z for z in present_z if z < w.z]
                plane = w.z - h
                gap = (plane - (below[-1] + h)) if below else layout.plate_gap
                zs = (plane + gap, plane + gap + p.wafer_thickness)
            try:
                c0 = w.centre + (zs[0] - w.z) * w.normal
                c1 = w.centre + (zs[1] - w.z) * w.normal
                w.virtual = (_circle_image(K, T_cw, p, c0, w.normal), _circle_image(K, T_cw, p, c1, w.normal))
            except DegenerateGeometryError:
                w.virtual = None
    return sorted(out, key=lambda w: -w.order)


def _draw_layout(p: SceneParams, rng: np.random.Generator) -> _Layout:
    background, face = _Texture(rng), _Texture(rng)
    gain = 1.0 + p.side_spread * rng.uniform(-1.0, 1.0, MAX_SLOTS)
    if p.mixed_polarity:
        gain = np.where(rng.random(MAX_SLOTS) < 0.5, 0.5, 1.0)
    posts = []
    for _ in range(p.carrier_lines):
        ang = math.radians(float(rng.uniform(25.0, 70.0))) * float(rng.choice([-1.0, 1.0]))
        rad = p.wafer_radius * float(rng.uniform(1.03, 1.15))
        level = float(rng.uniform(0, 40)) if rng.random() < 0.5 else float(rng.uniform(150, 255))
        posts.append((-rad * math.cos(ang), rad * math.sin(ang), float(rng.uniform(0.004, 0.012)), level))
    occluders: list[tuple[str, tuple[float, ...], float]] = []
    for _ in range(p.occluders):
        level = float(rng.uniform(0, 60)) if rng.random() < 0.6 else float(rng.uniform(100, 200))
        # Placed in image fractions; resolved against a rim when the scene is rendered.
        if rng.random() < 0.5:
            occluders.append(("disc", (float(rng.random()), float(rng.random()), float(rng.uniform(15, 90))), level))
        else:
            occluders.append(
                (
                    "rect",
                    (float(rng.random()), float(rng.random()), float(rng.uniform(20, 80)), float(rng.random())),
                    level,
                )
            )
    blobs = [
        (
            float(rng.random()),
            float(rng.random()),
            _log_uniform(rng, 2.0, 15.0),
            float(rng.uniform(40, 200)),
        )
        for _ in range(p.blobs)
    ]
    spot = (float(rng.uniform(0, p.width)), float(rng.uniform(0, p.height)), float(rng.uniform(150, 400)))
    plate = float(rng.uniform(0.005, 0.020))
    tilts = rng.standard_normal((MAX_SLOTS, 2))
    shifts = rng.standard_normal((MAX_SLOTS, 2))
    return _Layout(background, face, gain, posts, occluders, blobs, spot, plate, tilts, shifts)


def _front_point(wafers: list[_Wafer], fu: float, fv: float, p: SceneParams) -> tuple[float, float]:
    """A point on the front arc of one wafer's far rim (picked by ``fu``), or in the image (``fv``)."""
    if not wafers:
        return fu * p.width, fv * p.height
    w = wafers[min(int(fu * len(wafers)), len(wafers) - 1)]
    e = w.far
    t = math.pi / 2 + (fv - 0.5) * 2.0  # around the lowest (front) point of the ellipse, ±57°
    pts = e.point_at(np.array([t, t + math.pi]))
    # The front arc is the lower one for a camera above (the larger v).
    pt = pts[int(np.argmax(pts[:, 1]))] if w.camera_above else pts[int(np.argmin(pts[:, 1]))]
    return float(pt[0]), float(pt[1])


@dataclass
class _Occluder:
    kind: str
    geom: tuple[float, ...]
    level: float

    def distance(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """Signed distance (negative inside) and unit normal."""
        if self.kind == "disc":
            cx, cy, r = self.geom
            dx, dy = x - cx, y - cy
            n = np.hypot(dx, dy)
            nn = np.where(n > 0, n, 1.0)
            return n - r, dx / nn, dy / nn
        x0, x1, y0, y1 = self.geom
        dx = np.maximum(x0 - x, x - x1)
        dy = np.maximum(y0 - y, y - y1)
        outside = np.hypot(np.maximum(dx, 0), np.maximum(dy, 0))
        d = np.where((dx > 0) | (dy > 0), outside, np.maximum(dx, dy))
        horizontal = dx >= dy
        return d, horizontal.astype(np.float64), (~horizontal).astype(np.float64)

    def bbox(self, margin: float) -> tuple[float, float, float, float]:
        if self.kind == "disc":
            cx, cy, r = self.geom
            return cx - r - margin, cx + r + margin, cy - r - margin, cy + r + margin
        x0, x1, y0, y1 = self.geom
        return x0 - margin, x1 + margin, y0 - margin, y1 + margin


def _occluders(layout: _Layout, wafers: list[_Wafer], p: SceneParams) -> list[_Occluder]:
    out = []
    for kind, g, level in layout.occluders:
        if kind == "disc":
            u, v = _front_point(wafers, g[0], g[1], p)
            out.append(_Occluder("disc", (u, v, g[2]), level))
        else:
            u, v = _front_point(wafers, g[0], g[1], p)
            # A blade-like bar entering from the left or right border, ending at the rim point.
            if g[3] < 0.5:
                geom = (-50.0, u, v - 0.5 * g[2], v + 0.5 * g[2])
            else:
                geom = (u, p.width + 50.0, v - 0.5 * g[2], v + 0.5 * g[2])
            out.append(_Occluder("rect", geom, level))
    return out


def _posts(layout: _Layout, p: SceneParams, K: NDArray[np.float64], T_wc: NDArray[np.float64]) -> list[tuple]:
    """Carrier posts as image-vertical bars ``(u_left, u_right, radiance)`` at their mid-stack column."""
    T_cw = _inverse(T_wc)
    top, bottom = _stack_z(p)
    out = []
    for x, y, dia, level in layout.posts:
        X = np.array([[x, y, 0.5 * (top + bottom)]])
        depth = float((X @ T_cw[:3, :3].T + T_cw[:3, 3])[0, 2])
        if depth <= 0.01:
            continue
        u = float(_project(K, T_cw, X)[0, 0])
        half = 0.5 * p.focal_length * dia / depth
        out.append((u - half, u + half, level))
    return out


# --------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------


def _side_radiance(w: _Wafer, p: SceneParams, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Edge-face radiance: Lambertian-like fall-off toward the rim tips (``side_shading``)."""
    e = w.cam
    c, s = math.cos(e.theta), math.sin(e.theta)
    u = ((x - e.cx) * c + (y - e.cy) * s) / e.a
    return w.side * ((1.0 - p.side_shading) + p.side_shading * np.sqrt(np.clip(1.0 - u * u, 0.0, 1.0)))


def _face_radiance(p: SceneParams, layout: _Layout, x: Any, y: Any) -> NDArray[np.float64]:
    return p.face * (1.0 + p.face_texture * layout.face.at(x, y))


def _paint_wafer(img: NDArray[np.float64], w: _Wafer, p: SceneParams, layout: _Layout) -> None:
    sigma = p.blur_sigma
    extra = 0.5 * p.line_width if p.line > 0 else 0.0
    r = _kernel_radius(sigma, extra)
    conics = [_Conic(w.cam), _Conic(w.far)]
    if w.virtual is not None:
        conics += [_Conic(w.virtual[0]), _Conic(w.virtual[1])]
    win = _window(conics, r, p.width, p.height)
    if win is None:
        return
    reach = _coverage_table(sigma).reach + extra
    bounds = [_Boundary(c, win, reach, i) for i, c in enumerate(conics)]
    cam, far = bounds[0], bounds[1]
    c_s = _region([cam, far], sigma)
    c_f = _region([cam], sigma)
    c_band = np.clip(c_s - c_f, 0.0, 1.0)
    xs = np.arange(win.x0, win.x1, dtype=np.float64)[None, :]
    ys = np.arange(win.y0, win.y1, dtype=np.float64)[:, None]
    l_side = _side_radiance(w, p, xs, ys)
    l_face = p.face * (1.0 + p.face_texture * layout.face.grid(xs[0], ys[:, 0])) if p.face_texture else p.face
    sl = win.slices
    out = img[sl] * (1.0 - c_s) + l_side * c_band + l_face * c_f
    if w.virtual is not None:
        c_v = _region(bounds[2:], sigma)
        out += p.reflection * (l_side - l_face) * c_v * c_f
    if p.line > 0:
        out += p.line * (_line(far, p.line_width, sigma) * (1.0 - c_f) + _line(cam, p.line_width, sigma))
    img[sl] = out


def _paint_posts(img: NDArray[np.float64], posts: list[tuple], p: SceneParams) -> None:
    r = _kernel_radius(p.blur_sigma)
    for ul, ur, level in posts:
        x0, x1 = max(int(math.floor(ul)) - r, 0), min(int(math.ceil(ur)) + r + 1, p.width)
        if x0 >= x1:
            continue
        xs = np.arange(x0, x1, dtype=np.float64)
        one, zero = np.ones_like(xs), np.zeros_like(xs)
        c = edge_coverage(xs - ur, one, zero, p.blur_sigma) - edge_coverage(xs - ul, one, zero, p.blur_sigma)
        c = np.clip(c, 0.0, 1.0)[None, :]
        img[:, x0:x1] = img[:, x0:x1] * (1.0 - c) + level * c


def _paint_occluders(img: NDArray[np.float64], occ: list[_Occluder], p: SceneParams) -> None:
    r = _kernel_radius(p.blur_sigma)
    for o in occ:
        bx0, bx1, by0, by1 = o.bbox(r)
        x0, x1 = max(int(math.floor(bx0)), 0), min(int(math.ceil(bx1)) + 1, p.width)
        y0, y1 = max(int(math.floor(by0)), 0), min(int(math.ceil(by1)) + 1, p.height)
        if x0 >= x1 or y0 >= y1:
            continue
        ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
        d, nx, ny = o.distance(xs, ys)
        c = edge_coverage(d, nx, ny, p.blur_sigma)
        img[y0:y1, x0:x1] = img[y0:y1, x0:x1] * (1.0 - c) + o.level * c


def _blob_list(layout: _Layout, wafers: list[_Wafer], p: SceneParams) -> list[tuple[float, float, float, float]]:
    out = []
    for i, (fu, fv, s, amp) in enumerate(layout.blobs):
        u, v = _front_point(wafers, fu, fv, p) if i % 2 == 0 else (fu * p.width, fv * p.height)
        out.append((u, v, s, amp))
    return out


def _paint_blobs(img: NDArray[np.float64], blobs: list[tuple[float, float, float, float]], p: SceneParams) -> None:
    for u, v, s, amp in blobs:
        r = 4.0 * s
        x0, x1 = max(int(u - r), 0), min(int(u + r) + 2, p.width)
        y0, y1 = max(int(v - r), 0), min(int(v + r) + 2, p.height)
        if x0 >= x1 or y0 >= y1:
            continue
        gx = np.exp(-0.5 * ((np.arange(x0, x1) - u) / s) ** 2)
        gy = np.exp(-0.5 * ((np.arange(y0, y1) - v) / s) ** 2)
        img[y0:y1, x0:x1] += amp * np.outer(gy, gx)


def _gain(p: SceneParams, layout: _Layout) -> NDArray[np.float32] | None:
    """Illumination gain: vignetting, a linear gradient and a broad spot (``None``: uniform)."""
    if p.vignetting == 0 and p.gradient == (0.0, 0.0) and p.light_spot == 0:
        return None
    f32 = np.float32
    xh = ((np.arange(p.width) - 0.5 * p.width) / (0.5 * p.width)).astype(f32)
    yh = ((np.arange(p.height) - 0.5 * p.height) / (0.5 * p.height)).astype(f32)
    g = (f32(1.0) - f32(0.5 * p.vignetting) * yh * yh)[:, None] - (f32(0.5 * p.vignetting) * xh * xh)[None, :]
    g *= (f32(1.0) + f32(p.gradient[1]) * yh)[:, None] + (f32(p.gradient[0]) * xh)[None, :]
    if p.light_spot:
        su, sv, ss = layout.spot
        gx = np.exp(-0.5 * ((np.arange(p.width) - su) / ss) ** 2).astype(f32)
        gy = np.exp(-0.5 * ((np.arange(p.height) - sv) / ss) ** 2).astype(f32)
        g *= f32(1.0) + f32(p.light_spot) * np.outer(gy, gx)
    return np.maximum(g, f32(0.05), out=g)


def _render_radiance(
    p: SceneParams, layout: _Layout, wafers: list[_Wafer], posts: list[tuple], occ: list[_Occluder], blobs: list
) -> NDArray[np.float64]:
    xs = np.arange(p.width, dtype=np.float64)
    ys = np.arange(p.height, dtype=np.float64)
    img = p.background * (1.0 + p.background_texture * layout.background.grid(xs, ys))
    for w in wafers:
        _paint_wafer(img, w, p, layout)
    _paint_posts(img, posts, p)
    _paint_occluders(img, occ, p)
    _paint_blobs(img, blobs, p)
    return img


def _camera_response(
    radiance: NDArray[np.float64], p: SceneParams, layout: _Layout, rng: np.random.Generator
) -> NDArray[np.uint8]:
    """Illumination gain, gamma, read and shot noise, 8-bit quantisation with saturation."""
    e = radiance.astype(np.float32)
    g = _gain(p, layout)
    if g is not None:
        e *= g
    np.maximum(e, 0.0, out=e)
    if p.gamma != 1.0:
        e *= np.float32(1.0 / 255.0)
        np.power(e, np.float32(p.gamma), out=e)
        e *= np.float32(255.0)
    if p.noise_sigma > 0 or p.shot_noise > 0:
        sd = np.sqrt(p.noise_sigma**2 + p.shot_noise * np.minimum(e, 255.0)) if p.shot_noise > 0 else p.noise_sigma
        noise = rng.standard_normal(e.shape, dtype=np.float32)
        noise *= sd
        e += noise
    np.clip(e, 0.0, 255.0, out=e)
    return np.rint(e, out=e).astype(np.uint8)


_JPEG_LUMA = np.array(
    [
        [16, 11, 10, 16, 24, 40, 51, 61],
        [12, 12, 14, 19, 26, 58, 60, 55],
        [14, 13, 16, 24, 40, 57, 69, 56],
        [14, 17, 22, 29, 51, 87, 80, 62],
        [18, 22, 37, 56, 68, 109, 103, 77],
        [24, 35, 55, 64, 81, 104, 113, 92],
        [49, 64, 78, 87, 103, 121, 120, 101],
        [72, 92, 95, 98, 112, 100, 103, 99],
    ],
    dtype=np.float64,
)


def _dct_matrix() -> NDArray[np.float64]:
    k = np.arange(8)
    d = np.cos(np.pi * (2 * k[None, :] + 1) * k[:, None] / 16.0) * math.sqrt(2.0 / 8.0)
    d[0] /= math.sqrt(2.0)
    return d


def jpeg_like(image: NDArray[np.uint8], quality: int) -> NDArray[np.uint8]:
    """Baseline-JPEG-like luminance compression: 8×8 orthonormal DCT, the standard table scaled to ``quality``.

    The IJG scaling (``5000/q`` below 50, ``200 − 2q`` above), coefficients rounded to multiples
    of the table, inverse DCT, rounding and clipping; no chroma, no entropy coding (lossless).
    """
    q = _check_int(quality, "quality", 1, 100)
    scale = 5000.0 / q if q < 50 else 200.0 - 2.0 * q
    table = np.maximum(np.floor((_JPEG_LUMA * scale + 50.0) / 100.0), 1.0)
    h, w = image.shape
    ph, pw = -h % 8, -w % 8
    x = np.pad(image.astype(np.float64), ((0, ph), (0, pw)), mode="edge") - 128.0
    blocks = x.reshape((h + ph) // 8, 8, (w + pw) // 8, 8)
    d = _dct_matrix()
    coef = np.einsum("ij,ajbk,lk->aibl", d, blocks, d, optimize=True)
    coef = np.rint(coef / table[None, :, None, :]) * table[None, :, None, :]
    out = np.einsum("ji,ajbk,kl->aibl", d, coef, d, optimize=True).reshape(h + ph, w + pw)[:h, :w]
    return np.clip(np.rint(out + 128.0), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------------------------
# Sharp radiance at points (truth: edge contrast) and occlusion
# --------------------------------------------------------------------------------------------


def _radiance_at(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    p: SceneParams,
    layout: _Layout,
    wafers: list[_Wafer],
    posts: list[tuple],
    occ: list[_Occluder],
) -> NDArray[np.float64]:
    """The scene's radiance at points, without optics, pixels or lighting (blobs left out: glints)."""
    val = p.background * (1.0 + p.background_texture * layout.background.at(x, y))
    pts = np.column_stack([x, y])
    for w in wafers:
        cam, far = _Conic(w.cam), _Conic(w.far)
        in_f = cam.value(x, y) < 0
        in_s = in_f | (far.value(x, y) < 0)
        side = _side_radiance(w, p, x, y)
        face = np.full(len(x), p.face)
        if p.face_texture and in_f.any():
            face[in_f] = _face_radiance(p, layout, x[in_f], y[in_f])
        new = np.where(in_f, face, np.where(in_s, side, val))
        if w.virtual is not None:
            v0, v1 = _Conic(w.virtual[0]), _Conic(w.virtual[1])
            in_v = (v0.value(x, y) < 0) | (v1.value(x, y) < 0)
            new = new + np.where(in_f & in_v, p.reflection * (side - face), 0.0)
        if p.line > 0:
            on_cam = np.abs(w.cam.distance(pts)) < 0.5 * p.line_width
            on_far = (np.abs(w.far.distance(pts)) < 0.5 * p.line_width) & ~in_f
            new = new + p.line * (on_cam | on_far)
        val = new
    for ul, ur, level in posts:
        val = np.where((x > ul) & (x < ur), level, val)
    for o in occ:
        val = np.where(o.distance(x, y)[0] < 0, o.level, val)
    return val


def _rim_geometry(
    slot: int,
    centre: NDArray[np.float64],
    normal: NDArray[np.float64],
    p: SceneParams,
    K: NDArray[np.float64],
    T_cw: NDArray[np.float64],
    ctx: tuple,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Projected samples of a rim circle, and which are in the image and which are occluded."""
    _, wafers, posts, occ = ctx
    phi = 2.0 * math.pi * np.arange(RIM_SAMPLES) / RIM_SAMPLES
    u = np.cross(normal, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    X = centre + p.wafer_radius * (np.outer(np.cos(phi), u) + np.outer(np.sin(phi), v))
    pts = _project(K, T_cw, X)
    x, y = pts[:, 0], pts[:, 1]
    in_image = (x >= 1.0) & (x <= p.width - 2.0) & (y >= 1.0) & (y <= p.height - 2.0)
    # Occluded: inside (or within 1 px of) a wafer painted after this one, or an occluder / post.
    occluded = np.zeros(len(x), dtype=bool)
    later = wafers[[w.slot for w in wafers].index(slot) + 1 :]
    for w in later:
        d = np.minimum(w.upper.distance(pts), w.lower.distance(pts))
        occluded |= d < 1.0
    for ul, ur, _ in posts:
        occluded |= (x > ul - 1.0) & (x < ur + 1.0)
    for o in occ:
        occluded |= o.distance(x, y)[0] < 1.0
    return pts, in_image, occluded


def _edge_contrast(
    rims: list[tuple[Ellipse, NDArray[np.float64]]], p: SceneParams, ctx: tuple
) -> list[NDArray[np.float64]]:
    """Per rim sample, the radiance step across the rim (thin lines: the line's height over its sides)."""
    if not rims:
        return []
    step = 1.2 if p.line > 0 else 1.0
    queries = []
    for e, pts in rims:
        nx, ny = _Conic(e).gradient(pts[:, 0], pts[:, 1])
        n = np.column_stack([nx, ny]) * step
        queries += [pts + n, pts - n, pts]
    q = np.concatenate(queries)
    val = _radiance_at(q[:, 0], q[:, 1], p, *ctx).reshape(len(rims), 3, -1)
    if p.line > 0:
        return list(val[:, 2] - np.maximum(val[:, 0], val[:, 1]))
    return list(np.abs(val[:, 0] - val[:, 1]))


# --------------------------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------------------------


def _layout_for(params: SceneParams, seed: int) -> _Layout:
    return _draw_layout(params, _streams(seed)["layout"])


def render_scene(
    params: SceneParams,
    T_wc: Any | None = None,
    seed: int = 0,
    frame: int = 0,
) -> CarrierScene:
    """Render one scene for given parameters and camera pose.

    Args:
        params: The scene parameters (:func:`draw_params`).
        T_wc: Camera pose (camera to world, 4×4); ``None``: the parameters' default pose.
        seed: Seed of the layout (textures, clutter, occluders) and noise streams.
        frame: Frame index: changes only the sensor noise (sweeps).

    Returns:
        The image and its truth.

    Raises:
        InvalidInputError: A malformed pose.
        DegenerateGeometryError: The camera is inside a wafer's edge face or behind the stack.

    """
    if not isinstance(params, SceneParams):
        raise InvalidInputError(f"params must be a SceneParams, got {type(params).__name__}")
    seed = _check_int(seed, "seed", 0, 2**63 - 1)
    frame = _check_int(frame, "frame", 0, 2**31)
    T = default_pose(params) if T_wc is None else np.asarray(T_wc, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidInputError(f"T_wc must be a finite 4x4 matrix, got shape {T.shape}")
    K = params.K
    layout = _layout_for(params, seed)
    wafers = _wafers(params, K, T, layout)
    posts = _posts(layout, params, K, T)
    occ = _occluders(layout, wafers, params)
    blobs = _blob_list(layout, wafers, params)
    radiance = _render_radiance(params, layout, wafers, posts, occ, blobs)
    noise_rng = np.random.default_rng(np.random.SeedSequence([seed, frame, 0x5EED]))
    image = _camera_response(radiance, params, layout, noise_rng)
    if params.jpeg_quality:
        image = jpeg_like(image, params.jpeg_quality)
    T_cw = _inverse(T)
    ctx = (layout, wafers, posts, occ)
    by_slot = {w.slot: w for w in wafers}
    h = 0.5 * params.wafer_thickness
    geo = {}
    for w in wafers:
        for kind, c, e in (("upper", w.centre + h * w.normal, w.upper), ("lower", w.centre - h * w.normal, w.lower)):
            geo[(w.slot, kind)] = (e, *_rim_geometry(w.slot, c, w.normal, params, K, T_cw, ctx))
    keys = list(geo)
    contrast = dict(zip(keys, _edge_contrast([(geo[k][0], geo[k][1]) for k in keys], params, ctx), strict=True))
    truth = []
    for slot, here in zip(params.slots, params.present, strict=True):
        w = by_slot.get(slot)
        if not here or w is None:
            truth.append(WaferTruth(slot=slot, present=False, upper=None, lower=None))
            continue
        rims = []
        for kind in ("upper", "lower"):
            e, pts, in_image, occluded = geo[(slot, kind)]
            edge = contrast[(slot, kind)] >= MIN_EDGE_CONTRAST
            frac = float((in_image & ~occluded & edge).mean())
            rims.append(
                RimTruth(
                    slot=slot,
                    kind=kind,  # type: ignore[arg-type]
                    ellipse=e,
                    points=pts,
                    in_image=in_image,
                    occluded=occluded,
                    edge=edge,
                    visible_fraction=frac,
                    visible=frac >= MIN_VISIBLE_FRACTION,
                    camera_side=(kind == "upper") == w.camera_above,
                )
            )
        truth.append(
            WaferTruth(slot=slot, present=True, upper=rims[0], lower=rims[1], centre=w.centre, normal=w.normal)
        )
    return CarrierScene(image=image, K=K, T_wc=T, params=params, wafers=truth, seed=seed)


def render_carrier_image(family: str, seed: int, **overrides: Any) -> CarrierScene:
    """One randomised image of ``family`` with its ground truth (deterministic for ``seed``).

    Args:
        family: One of :data:`FAMILIES`.
        seed: Non-negative integer.
        **overrides: :class:`SceneParams` fields, or ``wafers`` (see :func:`draw_params`).

    Raises:
        InvalidInputError: Unknown family or parameter, value out of range.

    """
    params = draw_params(family, seed, **overrides)
    return render_scene(params, None, seed)


def render_sweep(family: str, seed: int, frames: int = 40, wafers: int = 10, **overrides: Any) -> list[CarrierScene]:
    """A sequence for tracking: the camera translates sideways past a stack of ``wafers`` slots.

    Appearance, clutter and wafer identities (``slot``) stay the same across frames; the sensor
    noise changes. The sweep spans 0.8 wafer radii (:func:`sweep_poses`).

    Raises:
        InvalidInputError: Unknown family, ``frames`` not in 1–10000, ``wafers`` not in 1–12.

    """
    n = _check_int(frames, "frames", 1, 10000)
    params = draw_params(family, seed, wafers=wafers, **overrides)
    return [render_scene(params, T, seed, frame=i) for i, T in enumerate(sweep_poses(params, n))]
