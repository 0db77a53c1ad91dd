"""General ellipse detection with an a-contrario acceptance test (seed 000_3b1454b2b2194811.txt ch. 3.2).

:func:`detect_ellipses` knows nothing of wafers: sub-pixel edges of both polarities, convex
single-quadrant arcs, the seed's two-arc combination rule with Algorithm 1 (Hungarian arc merging)
and Algorithm 2 (segment merging), then an a-contrario test as in LSD/ELSD: an ellipse is accepted
when the number of false alarms of its aligned gradient orientations is at most ``max_nfa``.
Edge thresholds follow from the image's own estimated gradient noise. Thin lines (two edges of
opposite polarity) can be reported on their centre with ``max_line_width``.

Example:
    >>> import numpy as np
    >>> from autoteach.detect import detect_ellipses
    >>> v, u = np.mgrid[0:160, 0:200]
    >>> image = np.where(((u - 100) / 60.0) ** 2 + ((v - 80) / 35.0) ** 2 <= 1, 200, 30).astype(np.uint8)
    >>> found = detect_ellipses(image)
    >>> len(found), round(found[0].ellipse.a), round(found[0].ellipse.b)
    (1, 60, 35)

"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach.errors import InvalidInputError
from autoteach.geometry import Ellipse
from autoteach.options import refuse_unknown

if TYPE_CHECKING:
    from autoteach.detect import WaferEdge

__all__ = ["EllipseDetectOptions", "EllipseDetection", "WaferGeometry", "detect_ellipses", "detect_wafer_rims"]

_DTYPES = (np.uint8, np.uint16, np.float32, np.float64)


@dataclass(frozen=True)
class EllipseDetectOptions:
    """Options of :func:`detect_ellipses`; every one physical or statistical.

    Attributes:
        min_arc_points: Fewest edge points of an arc (at least 5).
        min_semi_minor: Smallest semi-minor axis reported (pixels).
        max_semi_major: Largest semi-major axis reported (pixels); ``None`` for twice the image diagonal.
        max_gap: Largest gap (pixels) bridged between the arcs of one ellipse (occlusions);
            ``None`` for half the image diagonal.
        blur_sigma: Gaussian pre-blur (pixels); 0 for none. Helps very noisy images, hurts thin lines.
        max_nfa: Largest number of false alarms of an accepted ellipse (the a-contrario ``ε``):
            on images of pure noise fewer than ``max_nfa`` ellipses are accepted on average.
        max_line_width: When set, lines up to this wide (pixels) are reported on their centre
            lines with ``polarity == 0``: found by the image's Hessian (Steger's detector, with
            the same arcs, assembly and a-contrario test), or as two accepted edges of opposite
            polarity at most this far apart.
        gradient_noise: Standard deviation of a Sobel gradient component under the image's noise
            (grey levels per pixel, Sobel normalised by 1/8, ≈ 0.433 × pixel noise); ``None``
            estimates it from the image.

    """

    min_arc_points: int = 12
    min_semi_minor: float = 2.0
    max_semi_major: float | None = None
    max_gap: float | None = None
    blur_sigma: float = 0.0
    max_nfa: float = 1.0
    max_line_width: float | None = None
    gradient_noise: float | None = None


@dataclass(frozen=True)
class EllipseDetection:
    """One detected ellipse or elliptic arc, see :func:`detect_ellipses`.

    Attributes:
        ellipse: The orthogonal-distance fit of the support (``a ≥ b``).
        points: Supporting sub-pixel edge points, shape ``(N, 2)``, ``(u, v)``.
        covariance: Covariance of ``(cx, cy, a, b, theta)``, shape ``(5, 5)``, from the fit's
            edge-point noise; ``None`` when the fit gives none.
        residual: Mean orthogonal distance of the points to the ellipse (pixels).
        score: ``-log10(NFA)`` of the a-contrario test; higher is more significant.
        polarity: ``+1`` brighter outside, ``-1`` brighter inside, ``0`` centre of a thin line.

    """

    ellipse: Ellipse
    points: NDArray[np.float64]
    covariance: NDArray[np.float64] | None
    residual: float
    score: float
    polarity: int


def _image(image: ArrayLike) -> np.ndarray:
    if image is None:
        raise InvalidInputError("image must be a 2-D (height, width) grayscale array, got None")
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise InvalidInputError(f"image must be 2-D (height, width) grayscale, got shape {arr.shape}")
    if arr.size == 0:
        raise InvalidInputError(f"image must not be empty, got shape {arr.shape}")
    if arr.dtype not in _DTYPES:
        raise InvalidInputError(f"image must have dtype uint8, uint16, float32 or float64, got {arr.dtype}")
    return np.ascontiguousarray(arr)


def _merged(options: EllipseDetectOptions | None, overrides: dict[str, object]) -> dict:
    """The options as keyword arguments of the compiled call, with the overrides applied."""
    opts = options if options is not None else EllipseDetectOptions()
    if not isinstance(opts, EllipseDetectOptions):
        raise InvalidInputError(f"options must be an EllipseDetectOptions, got {type(opts).__name__}")
    fields = asdict(opts)
    refuse_unknown(fields, overrides, "ellipse-detection")
    fields.update(overrides)
    out: dict[str, object] = {}
    for name, value in fields.items():
        if name == "min_arc_points":
            out[name] = int(value)  # type: ignore[call-overload]
        else:
            out[name] = None if value is None else float(value)  # type: ignore[arg-type]
    for name in ("min_semi_minor", "blur_sigma", "max_nfa"):
        if out[name] is None:
            raise InvalidInputError(f"{name} must be a number, got None")
    return out


def detect_ellipses(
    image: ArrayLike, options: EllipseDetectOptions | None = None, **overrides: object
) -> list[EllipseDetection]:
    """Detect ellipses and elliptic arcs in a grayscale image, most significant first.

    Args:
        image: ``(height, width)`` grayscale, dtype uint8 (0–255), uint16 (0–65535), float32 or
            float64 (0–1).
        options: The options; default :class:`EllipseDetectOptions`.
        **overrides: Fields of :class:`EllipseDetectOptions` to change, e.g. ``max_line_width=4``.

    Returns:
        The detections, sorted by decreasing score; empty for an image without edges (constant
        or saturated). Deterministic. Runs without the GIL.

    Raises:
        InvalidInputError: Not 2-D, empty, smaller than 5×5, unsupported dtype, NaN/inf pixels,
            unknown or invalid options.

    """
    fields = _merged(options, overrides)
    found = _core.ellipse_detect(_image(image), **fields)
    return [
        EllipseDetection(
            ellipse=Ellipse._wrap(d.ellipse),
            points=d.points,
            covariance=d.covariance,
            residual=d.residual,
            score=d.score,
            polarity=d.polarity,
        )
        for d in found
    ]


@dataclass(frozen=True)
class WaferGeometry:
    """Physical wafer geometry and camera prior of :func:`detect_wafer_rims`.

    Attributes:
        radius: Wafer radius (mm).
        thickness: Wafer thickness (mm); only ``thickness / radius`` matters.
        up: Image direction of the wafers' upward normal (pixels, any length), from the rough
            camera pose; default image up.
        semi_major_range: Accepted semi-major axes ``(lo, hi)`` (pixels), from the rough camera
            pose; ``None`` for any.
        focal_length: Focal length (pixels) of the intrinsics, if known. Where a wafer's edge
            face is narrower than the edge operator's reach (2 px) its rims are placed about the
            band's centre line, and the focal length predicts how much the far rim's semi-minor
            axis exceeds the near one's; ``None`` keeps the edges' own semi-minor axes.

    """

    radius: float = 75.0
    thickness: float = 0.775
    up: tuple[float, float] = (0.0, -1.0)
    semi_major_range: tuple[float, float] | None = None
    focal_length: float | None = None


def detect_wafer_rims(
    image: ArrayLike,
    geometry: WaferGeometry | None = None,
    options: EllipseDetectOptions | None = None,
    **overrides: object,
) -> list[WaferEdge]:
    """Wafer rims from :func:`detect_ellipses`, paired and labelled by geometry alone.

    The upper rim of a wafer is its lower rim moved along the ellipse's minor axis toward
    ``up`` by ``(thickness / radius) · a · sqrt(1 − (b/a)²)`` (the wafer's axis under weak
    perspective); which rim is upper never depends on which side is brighter. Candidates are the
    detected edges of either polarity and thin lines (two opposite edges closer than the rim
    offset, taken on their centre). A new path beside :func:`autoteach.detect.detect_wafers`,
    whose default is unchanged.

    Args:
        image: As :func:`detect_ellipses`.
        geometry: Wafer geometry and camera prior; default :class:`WaferGeometry`.
        options: Ellipse-detection options. ``max_line_width`` is ignored: rims drawn as lines up
            to 2.8 px wide are found on their centre lines, and edge pairs narrower than the rim
            offset are lines too, formed by the pairing.
        **overrides: Fields of :class:`EllipseDetectOptions` to change.

    Returns:
        :class:`autoteach.detect.WaferEdge` list: two per wafer (``kind`` upper/lower, one
        ``wafer_id``), wafers numbered from the topmost along ``up``.

    Raises:
        InvalidInputError: As :func:`detect_ellipses`, or a bad geometry.

    """
    from autoteach.detect import WaferEdge

    geo = geometry if geometry is not None else WaferGeometry()
    if not isinstance(geo, WaferGeometry):
        raise InvalidInputError(f"geometry must be a WaferGeometry, got {type(geo).__name__}")
    fields = _merged(options, overrides)
    fields.pop("max_line_width")
    fields.pop("max_semi_major")
    rng = None if geo.semi_major_range is None else (float(geo.semi_major_range[0]), float(geo.semi_major_range[1]))
    rims = _core.wafer_rims_detect(
        _image(image),
        radius=float(geo.radius),
        thickness=float(geo.thickness),
        up=(float(geo.up[0]), float(geo.up[1])),
        semi_major_range=rng,
        focal_length=None if geo.focal_length is None else float(geo.focal_length),
        **fields,
    )
    return [WaferEdge._from_core(e) for e in rims]
