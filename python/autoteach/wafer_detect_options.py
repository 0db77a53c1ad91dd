"""The options of :func:`autoteach.detect.detect_wafers` in one place: :class:`WaferDetectOptions`.

Their defaults are ``DetectParams::default()`` of the Rust crate (``autoteach_detect::wafers``);
``tests/test_detect_wafers.py`` checks that they agree with ``_core.wafer_detect_defaults()``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from autoteach.errors import InvalidInputError
from autoteach.options import checked_replace

__all__ = ["WaferDetectOptions"]


@dataclass(frozen=True)
class WaferDetectOptions:
    """Options of wafer-rim detection (seed 000_3b1454b2b2194811.txt ch. 3.2).

    Attributes:
        canny_low: Hysteresis low threshold (grey levels per pixel on the 0–255 scale).
        canny_high: Hysteresis high threshold.
        blur_sigma: Optional Gaussian pre-blur (pixels); 0 for none.
        min_arc_points: Fewest edge points of an arc.
        residual_threshold: Largest mean orthogonal residual (pixels) of a combination.
        max_gap: Largest gap (pixels) between combined arcs.
        up: Image direction of the wafer normal (upper surface side); ``(0, -1)`` for an upright camera.
        max_rim_offset: Largest centre distance (pixels) of the two rims of one wafer.
        max_rim_axis_difference: Largest relative semi-axis difference of the two rims.
        min_contrast_ratio: Rims with less than this fraction of the contrast of the strongest rim of similar size are
            rejected as reflections (0 disables).
        semi_major_range: Optional prior ``(low, high)`` on the semi-major axis (pixels).
        semi_minor_range: Optional prior ``(low, high)`` on the semi-minor axis (pixels).
        min_coverage: Smallest fraction of its ellipse's perimeter a segment's arcs must cover (rims whose fit the
            points leave undetermined are rejected by the two σ tests).
        min_rim_separation: Points of the far lower rim closer to the upper rim than this fraction of the widest rim
            distance are dropped before its refit (0 disables).
        max_arc_deviation: An arc whose median distance (pixels) to its segment's ellipse exceeds this is dropped and
            the rest refitted (0 disables).
        max_arc_residual_ratio: Leave-one-out check of segments of three or more arcs: factor by which an arc may raise
            the mean residual (0 disables).
        max_unpaired_residual: A rim without a partner rim is kept only under this mean residual (pixels); ``math.inf``
            disables.
        band_refinement: Re-locate rim points with the two-edge band model of the rim profile.
        share_rim_shape: Refit the less covered rim of a pair with its partner's semi-major axis and orientation.
        share_rim_centre: With ``share_rim_shape``, also hold its centre on the partner's line along ``up``.
        joint_band_fit: Refit the less covered rim with the joint band model of both rims.
        inflection_sigmas: When above 0, a cut at a turn-sign change moves to the previous polygon vertex if the points
            between already bend its way by more than this many standard errors of the chain's edge noise (0: cut at the
            sign change).
        join_border_cut_arcs: Join two arcs left over by the assembly into one rim when the part of their ellipse
            between them lies outside the image (a rim whose front arc runs out of the image top; farther apart than
            ``max_gap``).
        thickness_ratio: Wafer thickness / wafer radius (a standard 300 mm wafer: 0.775 / 150); with ``focal_length``, a
            prior on the offset between the images of a wafer's two rims, ``thickness_ratio · a · sqrt(1 + (a /
            focal_length)²)`` along ``up`` (4 % standard deviation), pins the joint fit of the far lower rim of a wafer
            seen from above. Give both or neither; a wrong thickness is worse than none.
        focal_length: Camera focal length (pixels) for the rim offset prior.
        restart_turn_at_cuts: A cut vertex (corner, inflection, quadrant change) starts a new piece whose first turn is
            not compared with the cut's own turn for an inflection, so the side after a foreign contour's junction at a
            rim's tip is kept (thin rims running into slot-tooth edges). On by default (with ``max_relative_sigma_b``,
            which rejects the recovered thin rims whose minor axis the fit leaves uncertain).
        max_relative_sigma_b: A rim is reported only when the standard deviation of its minor axis (from the fit's
            covariance) is at most this fraction of ``b``: thin rims seen along the front arc only, whose ``a``, ``b``
            and centre trade off, and clutter. ``math.inf`` disables.
        max_centre_sigma: A rim whose centre standard deviation ``sqrt(var(cx) + var(cy))`` (from its fit's covariance)
            is over this (pixels) is rejected: its points do not determine an ellipse (a short or nearly straight arc);
            ``math.inf`` disables.
        keep_flat_run_pieces: A chain piece that would be dropped as straight is kept when a quadrant-change cut alone
            joins it to a neighbouring arc of the same convex run and it bends the run's way significantly (3 standard
            errors of the chain's edge noise): the flat half of a flat rim's front arc between its lowest point and a
            foreign contour's junction.
        border_pairs_take_arcs: With ``join_border_cut_arcs``, a pair of arcs cut by the image border may take an arc of
            one of the assembly's two-arc segments when it fits better (lower mean residual) than that segment, which is
            then dissolved.
        reflection_inside_rim: A dim rim counts as a reflection (``min_contrast_ratio``) only when it lies inside the
            brighter rim on whose face it would be mirrored; ``False`` compares it with every brighter rim of about its
            size.
        seek_missing_partner: The missing rim of a wafer of which only one rim was found is sought as the far edge of
            the side band along the found rim's front arc (per-profile band fits place a first guess, the joint band
            model of both rims fits it); it is reported when the fit stays within 2 px and 5 % of the guess and its
            measured far edges fit it, and passes the covariance screens like every rim.
        thin_band_fit: With the rim offset prior (``thickness_ratio``, ``focal_length``), the two rims of a thin wafer
            (``b`` under 9 px, 10 px seen from above; major axis near horizontal, ``up`` near ``(0, -1)``) are refitted
            together by one intensity fit of the image columns across the face's silhouette and the side band (four grey
            levels per column, one blur, the lower rim the exact image of the upper rim's circle moved by the
            thickness); an accepted fit (residual at the image's noise level) replaces the pair's edge-point fits. No
            effect without the prior.
        front_band_fit: With the rim offset prior, the two rims of a wider level wafer (``b`` from 10 px seen from
            above, 9 px from below) are refitted together by one intensity fit of the image columns across the side band
            (three grey levels per column, clipped samples censored, one blur, the rims tied by the prior); an accepted
            fit replaces the pair's edge-point fits. No effect without the prior.
        principal_point: Camera principal point ``(cx, cy)`` (pixels) for the rim offset prior; ``None``: the image
            centre ``((width - 1) / 2, (height - 1) / 2)``. With it, the column fits (``thin_band_fit``,
            ``front_band_fit``) tie the lower rim to the upper one exactly: the upper rim's ellipse gives the circle's
            pose (radius 1) under the pinhole camera, and the lower rim is its image moved by ``thickness_ratio``
            against the normal. Only with ``thickness_ratio`` and ``focal_length``.
        edge_profile: How the image forms an edge's profile, for the column fits: ``"optical"`` (a camera: the optics
            blur before the pixels integrate, a Gaussian profile ``Φ((y − E)/σ)`` whatever the edge's sub-pixel
            position) or ``"pixel"`` (the pixels integrate first and a Gaussian sampled on the pixel grid blurs the
            image after, as the simulator's renderer does: the profile ``Σₖ wₖ·clamp(y − E − k + ½, 0, 1)`` is piecewise
            linear in the edge's position, and a Gaussian profile fitted to it is off by up to ≈ 0.05 px by the edge's
            sub-pixel phase). σ is fitted either way.
        level_band_search: With the rim offset prior and ``thin_band_fit``, also finds the wafers seen almost edge-on
            (``b`` of 1–4 px), whose nearly straight rims no edge-point fit finds: long bright bars across the image,
            whose ends (the rims' tips, located to a tenth of a pixel) fix the centre column and ``a``, and whose sag
            seeds the thin column fit, which measures ``b`` and the rows (the tips' columns screened for clutter in runs
            of neighbouring columns). No effect without the prior.
    """

    canny_low: float = 6.0
    canny_high: float = 15.0
    blur_sigma: float = 0.0
    min_arc_points: int = 16
    residual_threshold: float = 0.25
    max_gap: float = 60.0
    up: tuple[float, float] = (0.0, -1.0)
    max_rim_offset: float = 10.0
    max_rim_axis_difference: float = 0.10
    min_contrast_ratio: float = 0.45
    semi_major_range: tuple[float, float] | None = None
    semi_minor_range: tuple[float, float] | None = None
    min_coverage: float = 0.08
    min_rim_separation: float = 0.5
    max_arc_deviation: float = 0.6
    max_arc_residual_ratio: float = 1.5
    max_unpaired_residual: float = 0.15
    band_refinement: bool = True
    share_rim_shape: bool = True
    share_rim_centre: bool = True
    joint_band_fit: bool = True
    inflection_sigmas: float = 0.0
    join_border_cut_arcs: bool = True
    thickness_ratio: float | None = None
    focal_length: float | None = None
    restart_turn_at_cuts: bool = True
    max_relative_sigma_b: float = 0.005
    max_centre_sigma: float = 1.0
    keep_flat_run_pieces: bool = True
    border_pairs_take_arcs: bool = True
    reflection_inside_rim: bool = True
    seek_missing_partner: bool = True
    thin_band_fit: bool = True
    front_band_fit: bool = True
    principal_point: tuple[float, float] | None = None
    edge_profile: Literal["optical", "pixel"] = "optical"
    level_band_search: bool = True

    def replace(self, **changes: Any) -> WaferDetectOptions:
        """A copy with ``changes``; an unknown option name is an error that lists the known ones."""
        return checked_replace(self, "wafer-detection", changes)

    def core_kwargs(self) -> dict[str, Any]:
        """The keyword arguments of ``_core.wafer_detect``, each converted to the type it takes."""
        return {
            "canny_low": float(self.canny_low),
            "canny_high": float(self.canny_high),
            "blur_sigma": float(self.blur_sigma),
            "min_arc_points": int(self.min_arc_points),
            "residual_threshold": float(self.residual_threshold),
            "max_gap": float(self.max_gap),
            "up": _pair("up", self.up),
            "max_rim_offset": float(self.max_rim_offset),
            "max_rim_axis_difference": float(self.max_rim_axis_difference),
            "min_contrast_ratio": float(self.min_contrast_ratio),
            "semi_major_range": _pair("semi_major_range", self.semi_major_range, optional=True),
            "semi_minor_range": _pair("semi_minor_range", self.semi_minor_range, optional=True),
            "min_coverage": float(self.min_coverage),
            "min_rim_separation": float(self.min_rim_separation),
            "max_arc_deviation": float(self.max_arc_deviation),
            "max_arc_residual_ratio": float(self.max_arc_residual_ratio),
            "max_unpaired_residual": float(self.max_unpaired_residual),
            "band_refinement": bool(self.band_refinement),
            "share_rim_shape": bool(self.share_rim_shape),
            "share_rim_centre": bool(self.share_rim_centre),
            "joint_band_fit": bool(self.joint_band_fit),
            "inflection_sigmas": float(self.inflection_sigmas),
            "join_border_cut_arcs": bool(self.join_border_cut_arcs),
            "thickness_ratio": None if self.thickness_ratio is None else float(self.thickness_ratio),
            "focal_length": None if self.focal_length is None else float(self.focal_length),
            "restart_turn_at_cuts": bool(self.restart_turn_at_cuts),
            "max_relative_sigma_b": float(self.max_relative_sigma_b),
            "max_centre_sigma": float(self.max_centre_sigma),
            "keep_flat_run_pieces": bool(self.keep_flat_run_pieces),
            "border_pairs_take_arcs": bool(self.border_pairs_take_arcs),
            "reflection_inside_rim": bool(self.reflection_inside_rim),
            "seek_missing_partner": bool(self.seek_missing_partner),
            "thin_band_fit": bool(self.thin_band_fit),
            "front_band_fit": bool(self.front_band_fit),
            "principal_point": _pair("principal_point", self.principal_point, optional=True),
            "edge_profile": str(self.edge_profile),
            "level_band_search": bool(self.level_band_search),
        }


def _pair(name: str, value: Any, *, optional: bool = False) -> tuple[float, float] | None:
    """Two real numbers (``None`` passes when ``optional``), or an error naming the option."""
    if optional and value is None:
        return None
    try:
        a, b = value
        return float(a), float(b)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be a pair of numbers, got {value!r}") from None
