"""Auto-teaching end to end (000_3b1454b2b2194811.txt ch. 5): log → edges → UKF → SLAM-MOT → results.

:func:`autoteach` takes a recorded or simulated :class:`~autoteach.sim.Session` (or the path of an
MCAP log) and returns an :class:`AutoTeachResult`: the calibration of the hand-eye system with its
covariance, every wafer's pose with its covariance, the camera pose of every frame, the
sliding-window convergence history (Fig. 5.11), the UKF fusion of visual odometry and encoders
(Fig. 5.8) and, when the session carries ground truth, the errors of every estimate.

World frame and what can be estimated
-------------------------------------
The world frame is the reference wafer (the lowest one, like wafer 1 in slot 4 of §5.4): its
centre is the origin and its normal the z axis. Wafers are circles, so the yaw about that axis is a
gauge freedom: it is held at the yaw of the nominal base pose. The camera rides on blade 2, so the
blade-1 wrist offset (joint3) never affects an image; the shoulder offset (joint1) is exactly a yaw
of the base and the lift offset exactly a z shift of the base (all joint axes are vertical and the
shoulder axis passes through the base origin). SLAM-MOT therefore estimates the *effective* base
pose ``T_wb·Rz(−δ1)·Tz(−δh)``, the elbow (joint2) and blade-2 wrist (joint4) zero offsets and the
wafers; the others are reported as unobservable, never as numbers. The UKF with
``ukf_odometry="vo"`` (the default) takes visual-odometry translation increments expressed in the
world frame of the known base, which is what makes δ1 visible to it (a real odometry does not
know its initial heading); with ``ukf_odometry="slam"`` (relative poses of a SLAM with a map, the
seed's ORB-SLAM2) δ1 is invisible to relative motion and reported unobservable, and δ2, δ4 reach
their Cramér–Rao bound (``autoteach.sim.odometry.offset_information``).

Errors against ground truth are computed in the true reference-wafer frame after aligning the
estimate's yaw gauge to the truth (a rotation about the reference normal), so the base rotation
error is the error of its tilt (the yaw is the gauge).

Stages
------
:func:`autoteach` runs stage functions that each take the previous stage's typed output, so a user
can run one alone, swap one (their own front end, say) and inspect every intermediate result:
:func:`load_session` → :func:`prepare` (:class:`Setup`) → :func:`run_frontend`
(:class:`Observations` and the raw detections) → :func:`initial_guess` → :func:`run_ukf` →
:func:`slam_mot_problem` (:class:`SlamMotProblem`) → :func:`gate_and_resolve` (detect front end) →
the SLAM-MOT solve → :func:`assemble_result` (:class:`AutoTeachResult`), then :func:`run_baseline`
and the errors of :mod:`autoteach.evaluation` when asked for or possible. The options are one
:class:`~autoteach.config.AutoteachConfig`, whose module also holds every fallback number.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autoteach import _core
from autoteach.config import (
    DEFAULT_ENCODER_NOISE,
    DEFAULT_OFFSETS,
    DEFAULT_SLOT_COUNT,
    DEFAULT_SLOT_PITCH,
    DEFAULT_WAFER_RADIUS,
    DEFAULT_WAFER_THICKNESS,
    JOINTS,
    LINKS,
    PIXEL_SIGMA_FLOOR,
    AutoteachConfig,
)
from autoteach.errors import InvalidInputError
from autoteach.evaluation import ground_truth_errors, match_truth
from autoteach.poses import rpy as _rpy
from autoteach.poses import wafer_params_of, wafer_pose

__all__ = [
    "AutoTeachResult",
    "AutoteachConfig",
    "BAND_NOISE_LOWER",
    "BAND_NOISE_UPPER",
    "BAND_NOISE_WIDTH_PX",
    "DEFAULT_OFFSETS",
    "JOINTS",
    "LINKS",
    "Observations",
    "Setup",
    "SlamMotProblem",
    "UNOBSERVABLE_REASONS",
    "WaferImaging",
    "assemble_result",
    "autoteach",
    "band_sigma_scale",
    "band_width",
    "conic_distance",
    "detect_all",
    "detect_frontend",
    "detector_options",
    "gate_and_resolve",
    "gate_detections",
    "ground_truth_errors",
    "initial_guess",
    "load_session",
    "polyline_distance",
    "prepare",
    "rim_conic",
    "rim_polyline",
    "run_baseline",
    "run_frontend",
    "run_ukf",
    "simulated_frontend",
    "slam_mot_problem",
    "wafer_params_of",
    "wafer_pose",
]

#: Joints whose offsets the UKF estimates.
_UKF_JOINTS: tuple[str, ...] = ("joint1", "joint2", "joint4")
#: Why each joint offset may be unobservable by SLAM-MOT.
UNOBSERVABLE_REASONS: dict[str, str] = {
    "joint1": "identical to a yaw of the base pose (the shoulder axis passes through the base origin)",
    "joint3": "the camera is on blade 2: the blade-1 wrist never moves it",
    "lift": "identical to a z shift of the base pose",
}


@dataclass
class AutoTeachResult:
    """Everything auto-teaching estimated for one session.

    Attributes:
        base_pose: (4, 4) effective base pose ``T_wb`` in the reference-wafer frame.
        base_std: (6,) standard deviations of the base pose tangent ``[ω (rad); ρ (m)]`` (NaN if
            unobservable).
        joint_offsets: (5,) joint zero offsets (rad; lift in m); NaN for those not estimated.
        joint_offsets_std: (5,) their standard deviations (NaN if not estimated/unobservable).
        offset_status: per joint: ``"estimated"``, ``"ukf"`` (only the UKF estimates it) or the
            reason it is unobservable.
        wafer_params: (K, 5) wafers ``[cx, cy, cz, rx, ry]`` (reference frame; the tilt is
            ``Ry(ry)·Rx(rx)``).
        wafer_std: (K, 5) their standard deviations (zero for the reference, NaN if unobserved).
        wafer_poses: (K, 4, 4) the wafer frames.
        wafer_slots: (K,) carrier slot of each wafer when known (else -1).
        covariance: joint covariance (base tangent, estimated offsets, wafers) or ``None``.
        unobservable: the solver's report when some parameter is not constrained, else ``None``.
        camera_poses: (F, 4, 4) per-frame ``T_wc`` through the calibrated kinematic chain.
        history: sliding-window convergence (dicts with ``last_frame``, ``base_pose``,
            ``joint_offsets``, ``std``).
        ukf: UKF output (``poses``, ``offsets`` (F, 3) for joint1, joint2, joint4, ``offset_std``,
            ``odometry_poses`` (dead reckoning), ``encoder_poses``) or ``None``.
        resolution: (K, 5) theoretical resolution per wafer (px/mm for cx, cy, cz; px/deg for rx,
            ry) from its best view, eq. (5.14).
        baseline: the point-based (nearest-point association) solve, if requested.
        errors: errors against ground truth (simulated sessions), else ``None``.
        within_3sigma: for each error group whether every component is inside 3σ.
        rms_px: RMS edge-point distance to the fitted conics (pixels).
        n_observations: number of (frame, wafer, rim) edge observations used.
        frontend: which front end produced the edge points.
        extra_calibration: the camera mode and, when estimated, the camera-mount correction
            (``mount_correction`` 4×4, ``mount_std`` (6,)) and the link-length corrections
            (``links``: name → ``correction_m``, ``std_m``); NaN standard deviations when the
            session does not constrain them (see :attr:`unobservable`).
        frontend_stats: detect front end: detections, tracks (used, too short, without slot),
            slots found, frames/rims used by the first estimate (``initial``) and after gating
            by the projected prior (``gated``); ground-truth slots missed / spurious when known.
        timings: seconds per stage.

    """

    base_pose: np.ndarray
    base_std: np.ndarray
    joint_offsets: np.ndarray
    joint_offsets_std: np.ndarray
    offset_status: dict[str, str]
    wafer_params: np.ndarray
    wafer_std: np.ndarray
    wafer_poses: np.ndarray
    wafer_slots: np.ndarray
    covariance: np.ndarray | None
    unobservable: str | None
    camera_poses: np.ndarray
    history: list[dict[str, Any]]
    ukf: dict[str, Any] | None
    resolution: np.ndarray
    baseline: dict[str, Any] | None = None
    errors: dict[str, float] | None = None
    within_3sigma: dict[str, bool] | None = None
    rms_px: float = math.nan
    n_observations: int = 0
    frontend: str = "simulated"
    timings: dict[str, float] = field(default_factory=dict)
    frontend_stats: dict[str, Any] = field(default_factory=dict)
    extra_calibration: dict[str, Any] = field(default_factory=dict)
    observations: dict[str, Any] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-compatible summary (``estimates`` with standard deviations, ``errors``, ``runtime_s``)."""
        deg = math.degrees
        est: dict[str, Any] = {
            "base_position_m": self.base_pose[:3, 3].tolist(),
            "base_position_std_m": _nan_list(self.base_std[3:]),
            "base_rpy_deg": [deg(v) for v in _rpy(self.base_pose[:3, :3])],
            "base_rotation_std_deg": _nan_list(np.degrees(self.base_std[:3])),
            "joint_offsets": {},
            "wafers": [],
        }
        for i, name in enumerate(JOINTS):
            scale = 1e3 if name == "lift" else 180.0 / math.pi
            unit = "mm" if name == "lift" else "deg"
            status = self.offset_status[name]
            entry: dict[str, Any] = {"status": status, "unit": unit}
            if status in ("estimated", "ukf"):
                entry["value"] = _num(self.joint_offsets[i] * scale)
                entry["std"] = _num(self.joint_offsets_std[i] * scale)
            est["joint_offsets"][name] = entry
        for k in range(len(self.wafer_params)):
            w = self.wafer_params[k]
            est["wafers"].append(
                {
                    "slot": int(self.wafer_slots[k]),
                    "center_m": w[:3].tolist(),
                    "center_std_m": _nan_list(self.wafer_std[k, :3]),
                    "tilt_deg": [deg(w[3]), deg(w[4])],
                    "tilt_std_deg": _nan_list(np.degrees(self.wafer_std[k, 3:])),
                    "resolution_px_per_mm": _nan_list(self.resolution[k, :3]),
                    "resolution_px_per_deg": _nan_list(self.resolution[k, 3:]),
                }
            )
        out: dict[str, Any] = {
            "frontend": self.frontend,
            "frontend_stats": self.frontend_stats,
            "extra_calibration": _jsonable(self.extra_calibration),
            "estimates": est,
            "unobservable": self.unobservable,
            "errors": self.errors,
            "within_3sigma": self.within_3sigma,
            "rms_px": _num(self.rms_px),
            "n_observations": self.n_observations,
            "frames": int(len(self.camera_poses)),
            "runtime_s": float(sum(self.timings.values())),
            "timings_s": dict(self.timings),
        }
        if self.ukf is not None:
            out["ukf"] = {
                "joint_offsets_deg": {
                    n: _num(math.degrees(v)) for n, v in zip(_UKF_JOINTS, self.ukf["offsets"][-1], strict=True)
                },
                "joint_offsets_std_deg": {
                    n: _num(math.degrees(v)) for n, v in zip(_UKF_JOINTS, self.ukf["offset_std"][-1], strict=True)
                },
            }
            if "errors" in self.ukf:
                out["ukf"]["errors"] = self.ukf["errors"]
        if self.baseline is not None:
            out["baseline"] = {k: v for k, v in self.baseline.items() if k in ("errors", "rms_px", "runtime_s")}
        return out


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return _num(obj)
    return obj


def _num(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _nan_list(a: np.ndarray) -> list[float | None]:
    return [_num(v) for v in np.asarray(a, dtype=np.float64).reshape(-1)]


# ---------------------------------------------------------------------------------------------
# Front ends: per-frame edge observations (frame, wafer, rim, points)
# ---------------------------------------------------------------------------------------------


@dataclass
class Observations:
    """Edge observations of a session in the flat layout of the compiled solver."""

    frames: list[int]
    wafers: list[int]
    rims: list[int]
    start: list[int]
    points: np.ndarray
    n_wafers: int
    slots: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)
    #: Per-point factors of the edge-point standard deviation (aligned with ``points``) or
    #: ``None`` (every point has the solver's ``pixel_sigma``).
    sigma_scale: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.frames)

    def flat(self) -> tuple[Any, ...]:
        """The compiled solver's layout ``(frames, wafers, rims, start, points, sigma_scale)``."""
        return (self.frames, self.wafers, self.rims, self.start, np.ascontiguousarray(self.points), self.sigma_scale)

    @classmethod
    def from_flat(cls, flat: tuple[Any, ...], n_wafers: int, slots: np.ndarray) -> Observations:
        """Observations from the compiled solver's layout (see :meth:`flat`)."""
        frames, wafers, rims, start, points, sigma_scale = flat
        return cls(
            frames, wafers, rims, start, points, n_wafers, np.asarray(slots, dtype=np.int64), sigma_scale=sigma_scale
        )


def _subsample(points: np.ndarray, n: int) -> np.ndarray:
    if len(points) <= n:
        return points
    idx = np.round(np.linspace(0, len(points) - 1, n)).astype(np.int64)
    return points[idx]


def simulated_frontend(
    session: Any,
    *,
    points_per_rim: int = 24,
    pixel_noise: float = 0.3,
    min_points: int = 8,
    min_axis_ratio: float = 0.05,
    seed: int = 0,
) -> Observations:
    """Edge observations from a simulated session's ground-truth visible rims (``Session.rims``).

    Each visible rim with at least ``min_points`` samples whose image ellipse is not seen nearly
    edge-on (minor/major axis ratio ``>= min_axis_ratio``; grazing views make the conic error
    strongly nonlinear and carry little information) gives one observation: ``points_per_rim``
    evenly spaced samples plus Gaussian pixel noise of std ``pixel_noise``. Association is the
    ground truth (the wafer index).
    """
    if session.rims is None:
        raise InvalidInputError(
            "the simulated front end needs a simulated session with ground-truth rims; use frontend='detect' for logs"
        )
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x4544]))
    frames, wafers, rims, start, pts = [], [], [], [0], []
    for f, frame_rims in enumerate(session.rims):
        for r in frame_rims:
            p = np.asarray(r["points"], dtype=np.float64).reshape(-1, 2)
            ell = r.get("ellipse")
            if len(p) < min_points or ell is None or not np.all(np.isfinite(ell)):
                continue
            a, b = float(max(ell[2], ell[3])), float(min(ell[2], ell[3]))
            if a <= 0 or b / a < min_axis_ratio:
                continue
            q = _subsample(p, points_per_rim)
            q = q + rng.normal(0.0, pixel_noise, q.shape) if pixel_noise > 0 else q
            frames.append(f)
            wafers.append(int(r["wafer"]))
            rims.append(0 if r["rim"] == "upper" else 1)
            pts.append(q)
            start.append(start[-1] + len(q))
    n_wafers = 0 if session.wafer_poses is None else len(session.wafer_poses)
    slots = np.asarray(session.wafer_slots if session.wafer_slots is not None else -np.ones(n_wafers), dtype=np.int64)
    return Observations(frames, wafers, rims, start, np.concatenate(pts) if pts else np.zeros((0, 2)), n_wafers, slots)


def rim_polyline(
    k: np.ndarray, t_wc: np.ndarray, wafer: np.ndarray, rim: int, radius: float, thickness: float, n: int = 720
) -> np.ndarray:
    """Image of a wafer rim (eq. (5.13)'s circle) as a closed polyline ``(m, 2)`` (pixels).

    ``wafer`` is ``[cx, cy, cz, rx, ry]`` (frame of ``t_wc``), ``rim`` 0 (upper, ``+h/2`` along the
    normal) or 1 (lower). Samples behind or nearly in the camera plane are dropped.
    """
    t = wafer_pose(np.asarray(wafer, dtype=np.float64))
    ang = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    z = (0.5 if rim == 0 else -0.5) * thickness
    local = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.full(n, z), np.ones(n)])
    t_cw = np.linalg.inv(t_wc)
    pc = (t_cw @ t @ local)[:3]
    ok = pc[2] > 1e-3
    uvw = k @ pc[:, ok]
    return (uvw[:2] / uvw[2]).T


def polyline_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance (pixels) of each point to a closed polyline: nearest vertex, then its two segments."""
    if len(poly) < 3:
        return np.full(len(points), np.inf)
    d2 = ((points[:, None, :] - poly[None, :, :]) ** 2).sum(-1)
    i = np.argmin(d2, axis=1)
    best = np.sqrt(d2[np.arange(len(points)), i])
    for j in ((i + 1) % len(poly), (i - 1) % len(poly)):
        a, b = poly[i], poly[j]
        ab = b - a
        L = np.maximum((ab**2).sum(-1), 1e-12)
        u = np.clip(((points - a) * ab).sum(-1) / L, 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - (a + u[:, None] * ab), axis=1))
    return best


def rim_conic(
    k: np.ndarray, t_wc: np.ndarray, wafer: np.ndarray, rim: int, radius: float, thickness: float
) -> np.ndarray:
    """Image conic ``C`` (3×3, ``pᵀCp = 0``) of a wafer rim, eq. (5.13): ``C = H⁻ᵀ·C0·H⁻¹``.

    ``H = K·[r1 r2 t]`` maps the rim plane (rim frame, ``z = 0``) to the image and
    ``C0 = diag(1, 1, −radius²)``. Normalised to unit Frobenius norm.
    """
    t = wafer_pose(np.asarray(wafer, dtype=np.float64))
    t[:3, 3] += t[:3, 2] * ((0.5 if rim == 0 else -0.5) * thickness)
    t_co = np.linalg.inv(t_wc) @ t
    h = k @ np.column_stack([t_co[:3, 0], t_co[:3, 1], t_co[:3, 3]])
    hi = np.linalg.inv(h)
    c = hi.T @ np.diag([1.0, 1.0, -radius * radius]) @ hi
    return c / np.linalg.norm(c)


def conic_distance(points: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Sampson (first-order geometric) distance of points to the conic ``C``, pixels.

    ``|pᵀCp| / (2‖(Cp)₁,₂‖)``: the distance to the curve for points near it (the gating
    range of a few pixels); an over- or under-estimate farther away.
    """
    ph = np.column_stack([points, np.ones(len(points))])
    cp = ph @ c.T
    alg = np.einsum("ij,ij->i", ph, cp)
    grad = 2.0 * np.hypot(cp[:, 0], cp[:, 1])
    return np.abs(alg) / np.maximum(grad, 1e-300)


def detector_options(
    k: np.ndarray, radius: float, thickness: float, *, edge_profile: str = "optical"
) -> dict[str, object]:
    """Keyword options of :func:`autoteach.detect.detect_wafers` that the pipeline knows.

    The wafer's thickness-to-radius ratio, the camera's focal length (pixels, the mean of
    ``fx`` and ``fy`` of ``k``) and its principal point (``k[0, 2]``, ``k[1, 2]``) give the
    detector's prior on the image offset between a wafer's two rims (``thickness_ratio``,
    ``focal_length``, ``principal_point``; 000_3b1454b2b2194811.txt §3.2, the rims are the
    images of two parallel circles a thickness apart, eqs. (3.1)–(3.2)). ``edge_profile`` is how
    the camera forms an edge's profile (``"optical"``, a camera; ``"pixel"``, the simulator's
    renderer, which blurs on the pixel grid after the pixels integrate), for the detector's
    column fits. The search for wafers seen edge-on stays off (``level_band_search=False``):
    those rims' points are the half-level crossings of a 2–4 px band, 0.1–0.2 px outside the
    true rims (wafer benchmark, seeds 3 and 4), and the pipeline takes rim points as edge
    measurements; under the robustness test's random damage (40 % of the rims dropped) the slot
    seen mostly edge-on came out 2–3 mm off in 2 of 14 damage patterns with them, 0 of 14
    without.

    Raises:
        InvalidInputError: a radius, thickness or focal length that is not finite and positive,
            or an unknown edge profile.

    """
    f = 0.5 * (float(k[0, 0]) + float(k[1, 1]))
    for name, v in (("wafer radius", radius), ("wafer thickness", thickness), ("focal length", f)):
        if not (math.isfinite(v) and v > 0.0):
            raise InvalidInputError(f"the {name} must be finite and positive, got {v!r}")
    principal_point = (float(k[0, 2]), float(k[1, 2]))
    if not all(math.isfinite(v) for v in principal_point):
        raise InvalidInputError(f"the principal point must be finite, got {principal_point!r}")
    if edge_profile not in ("optical", "pixel"):
        raise InvalidInputError(f"edge_profile must be 'optical' or 'pixel', got {edge_profile!r}")
    return {
        "thickness_ratio": thickness / radius,
        "focal_length": f,
        "principal_point": principal_point,
        "edge_profile": edge_profile,
        "level_band_search": False,
    }


def detect_all(images: np.ndarray, *, progress: bool = False, workers: int = 2, **options: Any) -> list[list[Any]]:
    """:func:`autoteach.detect.detect_wafers` on every image (threads: the detector releases the GIL).

    ``options`` are passed on to the detector (its defaults otherwise; the noise tables
    :data:`BAND_NOISE_UPPER` / :data:`BAND_NOISE_LOWER` were measured with them).
    """
    from concurrent.futures import ThreadPoolExecutor

    from tqdm import tqdm

    from autoteach.detect import detect_wafers

    images = np.asarray(images)
    if images.ndim != 3 or images.shape[0] == 0:
        raise InvalidInputError("the session has no images: the detection front end cannot run")
    if not images.any():
        raise InvalidInputError(
            f"all {images.shape[0]} images are black (every pixel 0; a session simulated with render=False "
            "has no images): nothing can be detected"
        )
    with ThreadPoolExecutor(max(1, int(workers))) as ex:
        it = ex.map(lambda im: detect_wafers(im, **options), images)
        return list(tqdm(it, total=len(images), desc="detecting", unit="frame", disable=not progress, leave=False))


def _edge_kind(e: Any) -> int:
    return 1 if "lower" in str(getattr(e, "kind", "upper")).lower() else 0


def detect_frontend(
    session: Any,
    detections: list[list[Any]],
    imaging: WaferImaging,
    *,
    camera_poses: np.ndarray,
    pitch: float,
    n_slots: int,
    points_per_rim: int = 24,
    min_points: int = 12,
    min_track_frames: int = 5,
    slot_gate_px: float = 15.0,
    slot_births: bool = True,
    progress: bool = False,
) -> Observations:
    """Edge observations from detections (ch. 3) and tracking (ch. 4), with slots from the nominal chain.

    The edges of every frame go through :class:`autoteach.track.WaferTracker` with the nominal
    camera poses ``camera_poses`` (encoders through the nominal kinematic chain, eq. (5.9), zero
    offsets) for its projection prediction (eq. (4.1)). Only *consistently tracked* wafers are
    used: tracks registered in at least ``min_track_frames`` frames. Each track is then given a
    carrier slot: the slot height (``(s − 1)·pitch`` above slot 1, carrier centre = median of the
    tracks' 3D circle centres) whose rim conics, projected through the nominal chain, explain its
    edge points best (mean distance truncated at ``slot_gate_px``). Tracks of one slot are one
    wafer (a wafer lost and re-acquired gets a new track id). With ``slot_births`` the tracker
    gets the carrier pitch (``WaferTracker(slot_pitch=pitch)``): the free slots next to each
    3D-estimated track are birth hypotheses of its assignment, so a track whose own wafer is
    missed in a frame does not take over the untracked neighbour one pitch away. The statistics
    of the front end are in :attr:`Observations.stats`.
    """
    from autoteach.track import WaferTracker

    k, radius, thickness = imaging.k, imaging.radius, imaging.thickness
    cam = session.camera
    tracker = WaferTracker(
        intrinsics=k,
        image_size=(cam.width, cam.height),
        wafer_radius=radius,
        normal_prior=(0.0, 0.0, 1.0),
        slot_pitch=pitch if slot_births else None,
    )
    for f, edges in enumerate(detections):
        tracker.update(edges, camera_poses[f])
    tracks = tracker.all_tracks()
    used = [t for t in tracks if t.hits >= min_track_frames]
    centres = np.array([t.circle.center for t in used if t.circle is not None and np.all(np.isfinite(t.circle.center))])
    xy0 = np.median(centres[:, :2], axis=0) if len(centres) else np.zeros(2)
    slot_of: dict[int, int] = {}
    slot_cost: dict[int, float] = {}
    for t in used:
        hist = [(f, e) for f, e in t.history if len(np.asarray(e.points).reshape(-1, 2)) >= min_points]
        if not hist:
            continue
        sample = hist[:: max(1, len(hist) // 12)]
        best = (math.inf, -1)
        for s in range(1, n_slots + 1):
            w = np.array([xy0[0], xy0[1], (s - 1) * pitch, 0.0, 0.0])
            costs = []
            for f, e in sample:
                p = _subsample(np.asarray(e.points, dtype=np.float64).reshape(-1, 2), 16)
                poly = rim_polyline(k, camera_poses[f], w, _edge_kind(e), radius, thickness, n=360)
                costs.append(np.minimum(polyline_distance(p, poly), slot_gate_px).mean())
            c = float(np.mean(costs))
            if c < best[0]:
                best = (c, s)
        if best[1] > 0 and best[0] < 0.8 * slot_gate_px:
            slot_of[t.id] = best[1]
            slot_cost[t.id] = best[0]
    slots = sorted(set(slot_of.values()))
    index = {s: i for i, s in enumerate(slots)}
    frames, wafers, rims, start, pts = [], [], [], [0], []
    seen: set[tuple[int, int, int]] = set()
    for t in used:
        if t.id not in slot_of:
            continue
        w = index[slot_of[t.id]]
        for f, e in t.history:
            p = np.asarray(e.points, dtype=np.float64).reshape(-1, 2)
            rim = _edge_kind(e)
            if len(p) < min_points or (f, w, rim) in seen:
                continue
            seen.add((f, w, rim))
            q = _subsample(p, points_per_rim)
            frames.append(f)
            wafers.append(w)
            rims.append(rim)
            pts.append(q)
            start.append(start[-1] + len(q))
    stats = {
        "detections": int(sum(len(d) for d in detections)),
        "tracks": len(tracks),
        "tracks_used": len(slot_of),
        "tracks_short": len(tracks) - len(used),
        "tracks_no_slot": len(used) - len(slot_of),
        "slots": [int(s) for s in slots],
        "rims_used": len(frames),
        "frames_used": len(set(frames)),
        "stage": "tracked",
    }
    obs = Observations(
        frames,
        wafers,
        rims,
        start,
        np.concatenate(pts) if pts else np.zeros((0, 2)),
        len(slots),
        np.array(slots, dtype=np.int64),
    )
    obs.stats = stats
    return obs


#: The detector's edge-point noise against the predicted side-band width, measured on simulated
#: sessions (``python benchmarks/autoteach_sessions.py --noise-model``): the widths (pixels), and
#: the relative noise of the upper and of the lower rim there. Defined once, in
#: ``autoteach_estimate::handeye::gating`` (``BAND_NOISE_*``), with how they were measured.
BAND_NOISE_WIDTH_PX, BAND_NOISE_UPPER, BAND_NOISE_LOWER = (tuple(t) for t in _core.HANDEYE_BAND_NOISE)


def band_sigma_scale(band: np.ndarray, rim: int) -> np.ndarray:
    """Per-point factor of the edge-point standard deviation from the predicted band width.

    A heteroscedastic version of eq. (5.5)'s ``Ω^z = 1/σ²``: ``σ_i = σ·s(b_i)`` with ``s`` the
    detector's measured relative edge noise at band width ``b_i`` (:data:`BAND_NOISE_UPPER` /
    :data:`BAND_NOISE_LOWER`, linear in between, constant beyond the ends, never below 1 so
    that the best points keep the solver's ``σ``). ``rim`` 0 is the upper, 1 the lower rim.
    """
    return _core.handeye_band_sigma_scale(np.asarray(band, dtype=np.float64).reshape(-1), int(rim))


def band_width(
    points: np.ndarray, h_inv: np.ndarray, t_co_other: np.ndarray, conic: np.ndarray, k: np.ndarray, radius: float
) -> np.ndarray:
    """Predicted image width (pixels) of a wafer's side face at edge points of one of its rims.

    Each point is mapped to the rim plane by ``h_inv`` (the inverse of the rim's homography
    ``H = K·[r1 r2 t]``, eq. (5.13)), giving its circle angle φ; the other rim's point at φ
    (``t_co_other``: the other rim's frame in the camera frame) is projected, and the width is
    the component of the displacement between the two rims' images along the unit normal of
    the rim's image conic ``conic`` at the point. This is the apparent height of the wafer's
    side face (its thickness): widest at the front of the visible arc, shrinking to zero where
    the rim's image is tangent to the line of sight.
    """
    f64 = np.float64
    return _core.handeye_band_width(
        np.asarray(points, dtype=f64).reshape(-1, 2),
        np.asarray(h_inv, dtype=f64),
        np.asarray(t_co_other, dtype=f64),
        np.asarray(conic, dtype=f64),
        np.asarray(k, dtype=f64),
        float(radius),
    )


def gate_detections(
    detections: list[list[Any]],
    camera_poses: np.ndarray,
    wafers: np.ndarray,
    slots: np.ndarray,
    imaging: WaferImaging,
    *,
    gate_px: float = 2.0,
    min_inlier_fraction: float = 0.6,
    points_per_rim: int = 24,
    min_points: int = 12,
    min_band_px: float = 0.0,
    band_weights: bool = False,
) -> Observations:
    """Associate every detected edge with the projected prior, discarding outliers.

    Once a first estimate exists, each wafer (``wafers``, frame of ``camera_poses``) is projected
    through the chain into every frame (both rims, eq. (5.13)'s circles). Each detected edge is
    scored against the predicted rims its bounding box overlaps with a truncated (robust) loss:
    its points within ``gate_px`` of a predicted rim are inliers. The edge goes to the rim with
    the most inliers if they are at least ``min_inlier_fraction`` of its points and
    ``min_points``; only the inlier points are kept. Edges of wafers not in ``wafers`` (never
    tracked), false arcs and mislabelled rims are thereby rejected or re-labelled; each (frame,
    wafer, rim) keeps its best edge. Independent of the tracker's identities. Each edge is scored
    on ``2·points_per_rim`` evenly spaced points (``min_points`` counts on that subsample).

    ``min_band_px > 0`` keeps only the inlier points where the predicted image of the wafer's
    side face (the bright band between its two rims) is at least that wide, measured along the
    rim's image normal (:func:`band_width`). Where the band narrows towards the ends of the
    visible arc its two edges blur into one and the detector's edge points are biased and
    noisier (measured against the simulator's truth, see ``docs/design/handeye.md``): those
    points carry a correlated error that the per-point noise model of eq. (5.5) lacks.

    ``band_weights`` gives every kept point a standard-deviation factor from the predicted band
    width (:func:`band_sigma_scale`; :attr:`Observations.sigma_scale`), so that the narrow-band
    points count for what they are worth instead of all or nothing.

    Computed by ``autoteach_estimate::handeye::gating::gate_edges``.
    """
    g = _core.handeye_gate(
        np.asarray(imaging.k, dtype=np.float64),
        np.asarray(camera_poses, dtype=np.float64).reshape(-1, 4, 4),
        np.asarray(wafers, dtype=np.float64).reshape(-1, 5),
        imaging.radius,
        imaging.thickness,
        *_flat_detections(detections),
        gate_px=gate_px,
        min_inlier_fraction=min_inlier_fraction,
        points_per_rim=points_per_rim,
        min_points=min_points,
        min_band_px=min_band_px,
        band_weights=band_weights,
    )
    obs = Observations.from_flat(g["observations"], len(wafers), slots)
    obs.stats = {
        **g["stats"],
        "gate_px": gate_px,
        "min_band_px": min_band_px,
        "stage": "gated",
    }
    return obs


def _flat_detections(detections: list[list[Any]]) -> tuple[np.ndarray, list[int], list[int]]:
    """Every frame's detected edges as ``(points (N, 2), start (E + 1), frames (E))``."""
    edge_pts: list[np.ndarray] = []
    edge_frames: list[int] = []
    for f, edges in enumerate(detections):
        for e in edges:
            edge_pts.append(np.asarray(e.points, dtype=np.float64).reshape(-1, 2))
            edge_frames.append(f)
    edge_start = np.concatenate([[0], np.cumsum([len(p) for p in edge_pts], dtype=np.int64)]).tolist()
    return (np.concatenate(edge_pts) if edge_pts else np.zeros((0, 2)), edge_start, edge_frames)


# ---------------------------------------------------------------------------------------------
# The pipeline
# ---------------------------------------------------------------------------------------------


def load_session(log_or_session: Any) -> Any:
    """Stage 0: the session of a path (an MCAP log) or a :class:`~autoteach.session.Session`, checked.

    Raises:
        InvalidInputError: not a session or a path; fewer than 2 frames, missing or non-finite
            joint states, timestamps not increasing, or joints that never move.
    """
    from autoteach.session import Session

    if isinstance(log_or_session, (str, os.PathLike)):
        from autoteach.io import read_log

        log_or_session = read_log(Path(log_or_session))
    if isinstance(log_or_session, Session):
        _validate_session(log_or_session)
        return log_or_session
    raise InvalidInputError(
        f"autoteach() takes a Session or the path of an MCAP log, got {type(log_or_session).__name__}"
    )


def _validate_session(session: Any) -> None:
    n = session.n_frames
    if n < 2:
        raise InvalidInputError(f"the session has {n} frame(s): auto-teaching needs the robot to move (>= 2 frames)")
    enc = np.asarray(session.joints_encoder, dtype=np.float64)
    if enc.shape != (n, 5):
        raise InvalidInputError(f"the session has no joint states for its frames (encoders of shape {enc.shape})")
    if not np.all(np.isfinite(enc)):
        bad = np.argwhere(~np.isfinite(enc))[0]
        raise InvalidInputError(
            f"joint state of frame {int(bad[0])} ({JOINTS[int(bad[1])]}) is missing or not finite: "
            "images and joint states are not synchronised"
        )
    ts = np.asarray(session.timestamps, dtype=np.int64)
    if np.any(np.diff(ts) <= 0):
        raise InvalidInputError("frame timestamps are not strictly increasing")
    if np.ptp(enc, axis=0).max() == 0.0:
        raise InvalidInputError("the joints never move: a static camera cannot calibrate the robot")


def _pinhole_k(camera: Any) -> np.ndarray:
    if camera.model != "pinhole":
        raise InvalidInputError(
            "the SLAM-MOT conic factor needs undistorted pinhole images; "
            f"camera model {camera.model!r} is not supported yet"
        )
    fx, fy, cx, cy = camera.params[:4]
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _robot_array(params: Any) -> np.ndarray:
    return np.array(list(params.to_dict().values()), dtype=np.float64)


def _odometry(
    session: Any, odometry: np.ndarray | None, sigma: tuple[float, ...] | None, seed: int
) -> tuple[np.ndarray | None, np.ndarray | None, tuple[float, ...]]:
    """Visual-odometry increments ``[u_T; u_R]`` (eq. (5.1)), their start rotation and precision.

    Given increments are checked against the session's frame count; their world orientation of
    frame 0 is unknown (``None``: the caller uses the nominal chain). Without them a simulated
    session gets drifting simulated odometry (:func:`autoteach.sim.simulate_odometry`), whose
    world is the simulation's: its first camera orientation is the true one.
    """
    from autoteach.sim.odometry import OdometryConfig, simulate_odometry

    n = session.n_frames
    start = None
    if odometry is not None:
        inc = np.asarray(odometry, dtype=np.float64)
        if inc.shape != (n - 1, 6) or not np.all(np.isfinite(inc)):
            raise InvalidInputError(
                f"odometry must be finite increments of shape ({n - 1}, 6) for {n} frames, got {inc.shape}"
            )
        default = (math.radians(0.2),) * 3 + (0.030, 0.030, 0.0015)
    elif session.camera_poses is not None:
        inc = simulate_odometry(session.camera_poses, seed)
        start = np.asarray(session.camera_poses[0], dtype=np.float64)[:3, :3]
        c = OdometryConfig()
        s_r = math.sqrt(c.rotation_noise**2 + c.rotation_drift**2 * n)
        s_t = math.sqrt(c.translation_noise**2 + c.translation_drift**2 * n)
        default = (s_r,) * 3 + (s_t,) * 3
    else:
        return None, None, (1.0,) * 6
    if sigma is None:
        sigma = default
    sigma = tuple(float(v) for v in sigma)
    if len(sigma) != 6 or not all(math.isfinite(v) and v > 0 for v in sigma):
        raise InvalidInputError(f"odometry_sigma must be 6 positive finite values, got {sigma}")
    return inc, start, sigma


def _nominal_start_rotation(cfg: Any, params: Any, enc: np.ndarray) -> np.ndarray:
    """Camera orientation of frame 0 through the nominal chain (zero offsets, eq. (5.9))."""
    from autoteach.geometry import WaferRobot
    from autoteach.sim.config import DEFAULT_BASE_POSE

    base_w = np.array(cfg.base_pose if cfg is not None else DEFAULT_BASE_POSE, dtype=np.float64)
    return np.asarray(WaferRobot(params=params, base=base_w).camera_pose(enc[:1]), dtype=np.float64)[0, :3, :3]


@dataclass(frozen=True)
class WaferImaging:
    """What projects a wafer's rims into an image: the pinhole intrinsics and the wafer's size.

    Attributes:
        k: (3, 3) pinhole intrinsic matrix.
        radius: wafer radius (m).
        thickness: wafer thickness (m).
    """

    k: np.ndarray
    radius: float
    thickness: float


@dataclass
class Setup:
    """What the stages share about one session: its geometry and the resolved front end.

    Attributes:
        session: the session being auto-taught.
        params: the robot geometry (:class:`~autoteach.geometry.RobotParams`).
        robot: ``params`` as the flat array the Rust core takes.
        k: the pinhole intrinsic matrix.
        radius: wafer radius (m).
        thickness: wafer thickness (m).
        pitch: carrier slot pitch (m).
        n_slots: carrier slot count.
        base_world: the nominal base pose ``T_wb`` in the simulator's world frame.
        frontend: ``"simulated"`` or ``"detect"``.
        encoders: (F, 5) encoder readings, C-contiguous.
    """

    session: Any
    params: Any
    robot: np.ndarray
    k: np.ndarray
    radius: float
    thickness: float
    pitch: float
    n_slots: int
    base_world: np.ndarray
    frontend: str
    encoders: np.ndarray

    @property
    def imaging(self) -> WaferImaging:
        """The intrinsics and wafer size the rims are projected with."""
        return WaferImaging(self.k, self.radius, self.thickness)


def prepare(session: Any, config: AutoteachConfig) -> Setup:
    """Stage 1: resolve the session's geometry, with the documented defaults where it is silent."""
    from autoteach.geometry import RobotParams
    from autoteach.sim.config import DEFAULT_BASE_POSE

    cfg = session.config
    params = config.robot_params or (cfg.robot if cfg is not None else RobotParams())
    radius = config.wafer_radius if config.wafer_radius is not None else (cfg.wafer_radius if cfg else None)
    thickness = config.wafer_thickness if config.wafer_thickness is not None else (cfg.wafer_thickness if cfg else None)
    k = _pinhole_k(session.camera)
    frontend = config.frontend
    if frontend == "auto":
        has_images = session.images is not None and np.asarray(session.images).any()
        frontend = "detect" if has_images or session.rims is None else "simulated"
    return Setup(
        session=session,
        params=params,
        robot=_robot_array(params),
        k=k,
        radius=float(radius if radius is not None else DEFAULT_WAFER_RADIUS),
        thickness=float(thickness if thickness is not None else DEFAULT_WAFER_THICKNESS),
        pitch=cfg.slot_pitch if cfg is not None else DEFAULT_SLOT_PITCH,
        n_slots=cfg.n_slots if cfg is not None else DEFAULT_SLOT_COUNT,
        base_world=np.array(cfg.base_pose if cfg is not None else DEFAULT_BASE_POSE, dtype=np.float64),
        frontend=frontend,
        encoders=np.ascontiguousarray(session.joints_encoder, dtype=np.float64),
    )


def run_frontend(
    setup: Setup, config: AutoteachConfig, *, progress: bool = False, timings: dict[str, float] | None = None
) -> tuple[Observations, list[list[Any]] | None]:
    """Stage 2: per-frame edge observations, and the raw detections of the detect front end.

    Raises:
        InvalidInputError: no wafer edge seen, or no track long enough to use.
    """
    session = setup.session
    detections = None
    if setup.frontend == "simulated":
        obs = simulated_frontend(
            session,
            points_per_rim=config.points_per_rim,
            pixel_noise=config.pixel_noise,
            min_axis_ratio=config.min_axis_ratio,
            seed=config.seed,
        )
    else:
        from autoteach.geometry import WaferRobot

        nominal_cams = np.asarray(
            WaferRobot(params=setup.params, base=setup.base_world).camera_pose(session.joints_encoder),
            dtype=np.float64,
        )
        t1 = time.perf_counter()
        # A simulated session's images come from the renderer, which blurs on the pixel grid.
        profile = "pixel" if session.config is not None else "optical"
        options = (
            detector_options(setup.k, setup.radius, setup.thickness, edge_profile=profile)
            if config.rim_offset_prior
            else {}
        )
        detections = detect_all(session.images, progress=progress, **options)
        if timings is not None:
            timings["detect_s"] = time.perf_counter() - t1
        obs = detect_frontend(
            session,
            detections,
            setup.imaging,
            camera_poses=nominal_cams,
            pitch=setup.pitch,
            n_slots=setup.n_slots,
            points_per_rim=config.points_per_rim,
            min_track_frames=config.min_track_frames,
            slot_births=config.slot_births,
            progress=progress,
        )
    if len(obs) == 0:
        n_rims = sum(len(d) for d in detections) if detections is not None else 0
        if n_rims:
            raise InvalidInputError(
                f"{n_rims} wafer rims were detected in {session.n_frames} frames, but no track lasted "
                f"min_track_frames = {config.min_track_frames} frames, so all were dropped: record a longer "
                "session or lower min_track_frames"
            )
        raise InvalidInputError(
            "no wafer edge was detected in any frame: nothing constrains the calibration "
            f"({session.n_frames} frames, front end {setup.frontend!r})"
        )
    if obs.n_wafers == 0:
        raise InvalidInputError("no wafer was tracked")
    return obs, detections


def initial_guess(setup: Setup, obs: Observations, config: AutoteachConfig) -> tuple[int, np.ndarray, np.ndarray]:
    """Stage 3: the reference wafer, the nominal base pose in its frame and the wafers' start.

    The reference is the lowest observed slot (or the first track); the other wafers start level
    at their slot heights relative to it.
    """
    seen = sorted(set(obs.wafers))
    ref = min(seen, key=lambda w: obs.slots[w]) if np.all(obs.slots >= 0) else seen[0]
    nominal_base = config.nominal_base
    if nominal_base is None:
        ref_slot = int(obs.slots[ref]) if obs.slots[ref] >= 0 else 1
        t_w_ref = np.eye(4)
        t_w_ref[2, 3] = (ref_slot - 1) * setup.pitch
        nominal_base = np.linalg.inv(t_w_ref) @ setup.base_world
    init_wafers = np.zeros((obs.n_wafers, 5))
    for w in range(obs.n_wafers):
        if obs.slots[w] >= 0 and obs.slots[ref] >= 0:
            init_wafers[w, 2] = (obs.slots[w] - obs.slots[ref]) * setup.pitch
    return int(ref), np.asarray(nominal_base, dtype=np.float64), init_wafers


def run_ukf(
    setup: Setup, config: AutoteachConfig, nominal_base: np.ndarray, increments: np.ndarray | None
) -> dict[str, Any] | None:
    """Stage 4: the UKF fusion of odometry and encoders (§5.2); ``None`` without odometry."""
    from autoteach.geometry import WaferRobot
    from autoteach.sim.odometry import (
        OdometryConfig,
        SlamConfig,
        integrate_odometry,
        integrate_relative,
        simulate_slam,
    )

    session, cfg = setup.session, setup.session.config
    noise = None if config.ukf_noise == "seed" else config.ukf_noise
    ukf_inc = increments
    slam = SlamConfig() if config.ukf_odometry == "slam" else None
    if slam is not None:
        if config.odometry is None and session.camera_poses is not None:
            ukf_inc = simulate_slam(session.camera_poses, config.seed, slam)
        if config.ukf_noise is None:
            noise = slam.ukf_noise(cfg.encoder_noise if cfg is not None else DEFAULT_ENCODER_NOISE)
    elif config.odometry is None and config.ukf_noise is None and increments is not None:
        noise = OdometryConfig().ukf_noise()
    if ukf_inc is None:
        return None
    base_w = setup.base_world if cfg is not None else nominal_base
    enc = setup.encoders
    run = _core.handeye_ukf(
        setup.robot,
        base_w,
        enc,
        np.ascontiguousarray(ukf_inc, dtype=np.float64),
        noise,
        odometry=None if slam is None else slam.ukf_odometry(),
    )
    encoder_poses = np.asarray(WaferRobot(params=setup.params, base=base_w).camera_pose(enc), dtype=np.float64)
    chain = integrate_odometry if slam is None else integrate_relative
    out: dict[str, Any] = {
        "poses": np.asarray(run["poses"]),
        "offsets": np.asarray(run["offsets"]),
        "offset_std": np.asarray(run["offset_std"]),
        "observable": [bool(v) for v in run["observable"]],
        "encoder_poses": encoder_poses,
        "odometry_poses": chain(encoder_poses[0], ukf_inc),
    }
    if session.calibration is not None:
        true = np.asarray(session.calibration.joint_offsets)[[0, 1, 3]]
        err = np.abs(out["offsets"][-1] - true)[out["observable"]]
        out["errors"] = {"joint_offset_deg": float(np.degrees(err.max()))}
        out["true_offsets"] = true
    return out


@dataclass
class SlamMotProblem:
    """The SLAM-MOT problem of one session (§5.3).

    What every solve shares, and the current observations and start.

    Attributes:
        solver_args: the positional arguments of ``_core.HandeyeSlamMot`` (intrinsics, robot,
            wafer size, encoders, number of wafers).
        solver_options: its keyword options (noise model, estimated quantities, free camera).
        observations: the observations the next solve uses.
        start: its start ``(base_pose (4, 4), joint_offsets (5,), wafers (W, 5))``.
        basin_search: follow each batch solve by the per-wafer basin search.
        est_idx: indices of the joints whose offsets are estimated.
        ref: the reference wafer.
        z_top: height (m) above the highest wafer's start, the top of the height search.
        stats: what the stages did (front-end counts, odometry factors, gating).
    """

    solver_args: tuple[Any, ...]
    solver_options: dict[str, Any]
    observations: Observations
    start: tuple[np.ndarray, np.ndarray, np.ndarray]
    basin_search: bool
    est_idx: list[int]
    ref: int
    z_top: float
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def heights(self) -> tuple[float, float, float]:
        """The height search ``(low, high, step)`` (m) of a first solve."""
        return (-0.02, max(self.z_top, 0.05), 0.001)

    def solver(self, *, free_camera: bool = True) -> Any:
        """The compiled problem (``_core.HandeyeSlamMot``); ``free_camera=False`` drops that mode."""
        options = self.solver_options
        if not free_camera:
            options = {k: v for k, v in options.items() if k != "free_camera"}
        return _core.HandeyeSlamMot(*self.solver_args, **options)

    def solve(self, **plan: Any) -> dict[str, Any]:
        """One ``run::solve`` of the current observations from the current start.

        ``plan``: ``factor``, ``window``, ``init_heights``, ``basin_search`` (default this
        problem's), and the solver keywords of :meth:`solver` (``free_camera``).
        """
        free_camera = plan.pop("free_camera", True)
        plan.setdefault("basin_search", self.basin_search)
        return self.solver(free_camera=free_camera).solve(self.observations.flat(), self.start, **plan)


def slam_mot_problem(
    setup: Setup,
    config: AutoteachConfig,
    obs: Observations,
    ref: int,
    nominal_base: np.ndarray,
    init_wafers: np.ndarray,
    ukf_out: dict[str, Any] | None,
    odometry: tuple[np.ndarray | None, np.ndarray | None, tuple[float, ...]],
) -> SlamMotProblem:
    """Stage 5a: the SLAM-MOT problem: the start from the UKF, the noise model and the factors."""
    cfg = setup.session.config
    offsets0 = np.zeros(5)
    est_idx = [JOINTS.index(j) for j in config.estimate_offsets]
    if ukf_out is not None:
        for i, j in enumerate((0, 1, 3)):
            if j in est_idx:
                offsets0[j] = ukf_out["offsets"][-1][i]
    sigma = float(config.pixel_sigma if config.pixel_sigma is not None else max(config.pixel_noise, PIXEL_SIGMA_FLOOR))
    encoder_sigma = config.encoder_sigma
    if encoder_sigma is None:
        noise5 = cfg.encoder_noise if cfg is not None else DEFAULT_ENCODER_NOISE
        encoder_sigma = tuple(max(float(noise5[j]), 1e-9) for j in (0, 1, 3, 4))
    options: dict[str, Any] = {}
    stats: dict[str, Any] = {"initial": dict(obs.stats)} if obs.stats else {}
    n_wafers = len(init_wafers)
    if config.camera_mode == "free":
        options["free_camera"], stats["odometry_factors"] = _free_camera_factors(setup, config, odometry)
        encoder_sigma = ()
    if config.estimate_mount:
        options["estimate_mount"] = True
    if config.estimate_links:
        options["estimate_links"] = [LINKS.index(name) for name in config.estimate_links]
    options.update(
        encoder_sigma=tuple(encoder_sigma) if encoder_sigma else None,
        pixel_sigma=sigma,
        estimate_offsets=est_idx,
        reference_wafer=int(ref),
        huber=config.huber,
        max_iterations=int(config.max_iterations),
    )
    return SlamMotProblem(
        (setup.k, setup.robot, setup.radius, setup.thickness, setup.encoders, n_wafers),
        options,
        obs,
        (nominal_base, offsets0, init_wafers),
        bool(config.basin_search),
        est_idx,
        ref,
        float(init_wafers[:, 2].max()) + 0.05,
        stats,
    )


def _free_camera_factors(
    setup: Setup, config: AutoteachConfig, odometry: tuple[np.ndarray | None, np.ndarray | None, tuple[float, ...]]
) -> tuple[tuple[Any, ...], int]:
    """The free-camera mode's motion precision, odometry relative poses and their precision.

    Relative robot motion (5.10)–(5.12) ties consecutive frames; when the session has visual
    odometry, its increments become relative-pose factors between the same poses.
    """
    session = setup.session
    increments, odo_start, odo_sigma = odometry
    rel = None
    if increments is not None:
        from autoteach.sim.odometry import relative_odometry

        if config.odometry_start is not None:
            start = np.asarray(config.odometry_start, dtype=np.float64)
            start = start[:3, :3] if start.shape == (4, 4) else start
        elif odo_start is not None:
            start = odo_start
        else:
            start = _nominal_start_rotation(session.config, setup.params, setup.encoders)
        rel = np.ascontiguousarray(relative_odometry(increments, start))
    factors = ([float(v) for v in config.motion_sigma], rel, [float(v) for v in odo_sigma])
    return factors, 0 if rel is None else len(rel)


def gate_and_resolve(
    setup: Setup,
    config: AutoteachConfig,
    problem: SlamMotProblem,
    obs: Observations,
    detections: list[list[Any]],
) -> Observations:
    """Stage 5b (detect front end): re-associate every detected edge with the projected estimate.

    A first estimate from the consistently tracked rims (robust loss), then every detected edge
    is associated with the projected prior with shrinking gates, solving again after each. The
    tracks may mix wafers, so the first estimate can sit in a mirrored-tilt basin: the chain of
    gates runs from its tilts and from level wafers (the nominal carrier), and the chain whose
    estimate explains more detected edges within the last gate wins. Wafers gated into fewer
    than ``min_wafer_frames`` frames are reported as not estimated and do not enter the solve.
    Updates ``problem`` to the winner's observations and start; returns the kept observations.

    Computed by ``autoteach_estimate::handeye::run::gate_and_resolve``.

    Raises:
        InvalidInputError: no chain associates any edge.
    """
    out = problem.solver().gate_and_resolve(
        obs.flat(),
        problem.start,
        _flat_detections(detections),
        gates_px=[float(g) for g in config.gate_px],
        first_heights=problem.heights,
        reset_tilts=bool(config.reset_tilts),
        min_wafer_frames=int(config.min_wafer_frames),
        points_per_rim=int(config.points_per_rim),
        min_band_px=float(config.min_band_px),
        band_weights=bool(config.band_weights),
        basin_search=problem.basin_search,
    )
    kept = Observations.from_flat(out["observations"], obs.n_wafers, obs.slots)
    kept.stats = {
        **out["stats"],
        "gate_px": out["last_gate_px"],
        "min_band_px": config.min_band_px,
        "stage": "gated",
        "wafers_too_few_views": [int(obs.slots[w]) for w in out["too_few_views"]],
    }
    start = out["start"]
    problem.observations = kept
    problem.start = (start["base_pose"], start["joint_offsets"], start["wafers"])
    problem.stats["gated"] = dict(kept.stats)
    return kept


def assemble_result(
    setup: Setup,
    config: AutoteachConfig,
    problem: SlamMotProblem,
    obs: Observations,
    sol: dict[str, Any],
    ukf_out: dict[str, Any] | None,
) -> AutoTeachResult:
    """Stage 6: the result: estimates with their standard deviations, status of every offset.

    Wafers that no observation constrains are NaN; the theoretical resolution (5.14) of each wafer
    is evaluated at its best view (most edge points).
    """
    est_idx, ref = problem.est_idx, problem.ref
    seen = sorted(set(obs.wafers))
    wafers_hat = np.asarray(sol["wafers"])
    offsets_hat = np.asarray(sol["joint_offsets"])
    cov = None if sol["covariance"] is None else np.asarray(sol["covariance"])
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if cov is not None else None
    n_off = len(est_idx)
    base_std = d[:6] if d is not None else np.full(6, np.nan)
    offsets_std = np.full(5, np.nan)
    wafer_std = np.full((obs.n_wafers, 5), np.nan)
    wafer_std[ref] = 0.0
    if d is not None:
        for i, j in enumerate(est_idx):
            offsets_std[j] = d[6 + i]
        for i, w in enumerate(sol["covariance_wafers"]):
            wafer_std[w] = d[6 + n_off + 5 * i : 6 + n_off + 5 * i + 5]
    extra_cal: dict[str, Any] = {"camera_mode": config.camera_mode}
    tail = 6 + n_off + 5 * len(sol["covariance_wafers"])
    if config.estimate_mount:
        extra_cal["mount_correction"] = np.asarray(sol["mount"])
        extra_cal["mount_std"] = d[tail : tail + 6] if d is not None else np.full(6, np.nan)
        tail += 6
    for i, name in enumerate(config.estimate_links):
        std = float(d[tail + i]) if d is not None else math.nan
        correction = float(sol["links"][LINKS.index(name)])
        extra_cal.setdefault("links", {})[name] = {"correction_m": correction, "std_m": std}
    status: dict[str, str] = {}
    joint_offsets = np.full(5, np.nan)
    for j, name in enumerate(JOINTS):
        u = (0, 1, 3).index(j) if j in (0, 1, 3) else -1
        if j in est_idx:
            status[name] = "estimated"
            joint_offsets[j] = offsets_hat[j]
        elif ukf_out is not None and u >= 0 and ukf_out["observable"][u]:
            status[name] = "ukf"
            joint_offsets[j] = ukf_out["offsets"][-1][u]
            offsets_std[j] = ukf_out["offset_std"][-1][u]
        else:
            status[name] = "unobservable: " + UNOBSERVABLE_REASONS.get(name, "not estimated")
    unobserved = [w for w in range(obs.n_wafers) if w not in seen]
    wafers_hat[unobserved] = np.nan
    wafer_std[unobserved] = np.nan
    cams = np.asarray(sol["camera_poses"])
    return AutoTeachResult(
        base_pose=np.asarray(sol["base_pose"]),
        base_std=base_std,
        joint_offsets=joint_offsets,
        joint_offsets_std=offsets_std,
        offset_status=status,
        wafer_params=wafers_hat,
        wafer_std=wafer_std,
        wafer_poses=np.stack([wafer_pose(w) for w in wafers_hat]),
        wafer_slots=obs.slots.copy(),
        covariance=cov,
        unobservable=sol["unobservable"],
        camera_poses=cams,
        history=[dict(h) for h in sol["history"]],
        ukf=ukf_out,
        resolution=_best_view_resolution(setup, obs, cams, wafers_hat),
        rms_px=float(sol["rms_px"]),
        n_observations=len(obs),
        frontend=setup.frontend,
        frontend_stats=problem.stats,
        extra_calibration=extra_cal,
        observations={
            "frames": obs.frames,
            "wafers": obs.wafers,
            "rims": obs.rims,
            "start": obs.start,
            "points": obs.points,
        },
    )


def _best_view_resolution(setup: Setup, obs: Observations, cams: np.ndarray, wafers: np.ndarray) -> np.ndarray:
    """Theoretical resolution (5.14) of each wafer in its view with the most edge points."""
    resolution = np.full((obs.n_wafers, 5), np.nan)
    counts: dict[int, tuple[int, int]] = {}
    for i, (f, w) in enumerate(zip(obs.frames, obs.wafers, strict=True)):
        n = obs.start[i + 1] - obs.start[i]
        if n > counts.get(w, (-1, 0))[0]:
            counts[w] = (n, f)
    for w, (_, f) in counts.items():
        try:
            resolution[w] = _core.handeye_resolution(setup.k, cams[f], wafers[w], setup.radius, setup.thickness)
        except Exception:  # noqa: BLE001 - a view where the rim crosses the camera plane: no figure
            pass
    return resolution


def run_baseline(
    session: Any, problem: SlamMotProblem, obs: Observations, truth_index: list[int] | None
) -> dict[str, Any]:
    """The seed's baseline as it is: point reprojection, nearest-point association, no basin search."""
    t0 = time.perf_counter()
    sol = problem.solve(factor="point", init_heights=problem.heights, basin_search=False, free_camera=False)
    b: dict[str, Any] = {
        "base_pose": np.asarray(sol["base_pose"]),
        "wafers": np.asarray(sol["wafers"]),
        "joint_offsets": np.asarray(sol["joint_offsets"]),
        "rms_px": float(sol["rms_px"]),
        "runtime_s": time.perf_counter() - t0,
    }
    if session.has_ground_truth:
        seen = sorted(set(obs.wafers))
        b["errors"] = ground_truth_errors(
            session,
            problem.ref,
            b["base_pose"],
            b["joint_offsets"],
            b["wafers"],
            problem.est_idx,
            seen,
            truth_index=truth_index,
        )[0]
    return b


def autoteach(
    log_or_session: Any, config: AutoteachConfig | None = None, *, progress: bool = False, **options: Any
) -> AutoTeachResult:
    """Auto-teach the hand-eye system from a session: calibration, wafer poses, covariances.

    The stages run in order and each can be run alone: :func:`load_session`, :func:`prepare`,
    :func:`run_frontend`, :func:`initial_guess`, :func:`run_ukf`, :func:`slam_mot_problem`,
    :func:`gate_and_resolve` (detect front end), the SLAM-MOT solve, :func:`assemble_result`, then
    :func:`run_baseline` and :func:`autoteach.evaluation.ground_truth_errors` where asked for.

    Args:
        log_or_session: a :class:`~autoteach.session.Session` or the path of an MCAP log.
        config: the options (default :class:`~autoteach.config.AutoteachConfig`).
        progress: progress bars on stderr.
        **options: options that replace those of ``config`` by name (see
            :class:`~autoteach.config.AutoteachConfig`), e.g. ``frontend="simulated"``.

    Raises:
        InvalidInputError: unreadable/unsynchronised input, no images (detect front end), no joint
            states, no wafer seen in any frame, an unknown option.
        ConvergenceError: the solver failed.
    """
    from tqdm import tqdm

    config = (config or AutoteachConfig()).replace(**options) if options else (config or AutoteachConfig())
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    session = load_session(log_or_session)
    timings["load_s"] = time.perf_counter() - t0
    setup = prepare(session, config)
    config.validate()

    stages = tqdm(total=4, desc="auto-teaching", unit="stage", disable=not progress, leave=False)
    t0 = time.perf_counter()
    obs, detections = run_frontend(setup, config, progress=progress, timings=timings)
    timings["frontend_s"] = time.perf_counter() - t0
    stages.update()
    ref, nominal_base, init_wafers = initial_guess(setup, obs, config)
    odometry = _odometry(session, config.odometry, config.odometry_sigma, config.seed)
    ukf_out = None
    if config.use_ukf:
        t0 = time.perf_counter()
        ukf_out = run_ukf(setup, config, nominal_base, odometry[0])
        timings["ukf_s"] = time.perf_counter() - t0
    stages.update()

    t0 = time.perf_counter()
    problem = slam_mot_problem(setup, config, obs, ref, nominal_base, init_wafers, ukf_out, odometry)
    heights: tuple[float, float, float] | None = problem.heights
    if detections is not None:
        obs = gate_and_resolve(setup, config, problem, obs, detections)
        heights = None
    sol = problem.solve(window=int(config.window), init_heights=heights)
    timings["slam_mot_s"] = time.perf_counter() - t0
    problem.stats["basins_moved"] = [int(obs.slots[w]) for w in sol["basins_moved"]]
    stages.update()

    t0 = time.perf_counter()
    result = assemble_result(setup, config, problem, obs, sol, ukf_out)
    result.timings = timings
    timings["resolution_s"] = time.perf_counter() - t0
    seen = sorted(set(obs.wafers))
    truth_index: list[int] | None = None
    if session.wafer_slots is not None and setup.frontend == "detect":
        truth_index, report = match_truth(session, obs.slots, seen)
        problem.stats.update(report)
    if config.baseline:
        result.baseline = run_baseline(session, problem, obs, truth_index)
        timings["baseline_s"] = result.baseline["runtime_s"]
    stages.update()
    stages.close()
    if session.has_ground_truth and session.calibration is not None:
        result.errors, result.within_3sigma = ground_truth_errors(
            session,
            ref,
            result.base_pose,
            np.asarray(sol["joint_offsets"]),
            result.wafer_params,
            problem.est_idx,
            seen,
            result.base_std,
            result.joint_offsets_std,
            result.wafer_std,
            truth_index=truth_index,
        )
    return result
