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
from autoteach.errors import InvalidInputError

#: Joint names in the order of the joint vector.
JOINTS: tuple[str, ...] = ("joint1", "joint2", "joint3", "joint4", "lift")
#: Link lengths that SLAM-MOT can calibrate (``estimate_links``).
LINKS: tuple[str, ...] = ("l1", "l2", "l4")
#: Joints whose offsets the UKF estimates.
_UKF_JOINTS: tuple[str, ...] = ("joint1", "joint2", "joint4")
#: Offsets SLAM-MOT estimates by default (the observable ones, see the module docs).
DEFAULT_OFFSETS: tuple[str, ...] = ("joint2", "joint4")
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


def _rpy(r: np.ndarray) -> tuple[float, float, float]:
    return (
        math.atan2(r[2, 1], r[2, 2]),
        math.asin(max(-1.0, min(1.0, -r[2, 0]))),
        math.atan2(r[1, 0], r[0, 0]),
    )


def _rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)


def wafer_pose(w: np.ndarray) -> np.ndarray:
    """The 4×4 frame of wafer parameters ``[cx, cy, cz, rx, ry]`` (rotation ``Ry(ry)·Rx(rx)``)."""
    t = np.eye(4)
    t[:3, :3] = _rot("y", w[4]) @ _rot("x", w[3])
    t[:3, 3] = w[:3]
    return t


def wafer_params_of(pose: np.ndarray) -> np.ndarray:
    """Inverse of :func:`wafer_pose` for the centre and normal (the yaw about the normal is dropped)."""
    n = pose[:3, 2]
    if n[2] < 0:
        n = -n
    return np.array([pose[0, 3], pose[1, 3], pose[2, 3], -math.asin(max(-1.0, min(1.0, n[1]))), math.atan2(n[0], n[2])])


def _log_so3(r: np.ndarray) -> np.ndarray:
    c = max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0))
    th = math.acos(c)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return 0.5 * w if th < 1e-9 else th / (2.0 * math.sin(th)) * w


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


def _bbox(p: np.ndarray) -> np.ndarray:
    return np.array([p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max()])


def _overlap(a: np.ndarray, b: np.ndarray, margin: float) -> bool:
    return bool(a[0] - margin <= b[2] and b[0] - margin <= a[2] and a[1] - margin <= b[3] and b[1] - margin <= a[3])


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
    *,
    k: np.ndarray,
    camera_poses: np.ndarray,
    radius: float,
    thickness: float,
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


def _drop_sparse_wafers(obs: Observations, min_frames: int) -> Observations:
    """Remove the observations of wafers seen in fewer than ``min_frames`` frames (stats say which)."""
    frames_of: dict[int, set[int]] = {}
    for f, w in zip(obs.frames, obs.wafers, strict=True):
        frames_of.setdefault(w, set()).add(f)
    sparse = sorted(w for w, fs in frames_of.items() if len(fs) < min_frames)
    stats = dict(obs.stats)
    stats["wafers_too_few_views"] = [int(obs.slots[w]) for w in sparse]
    if not sparse:
        obs.stats = stats
        return obs
    keep = [i for i, w in enumerate(obs.wafers) if w not in sparse]
    pts = [obs.points[obs.start[i] : obs.start[i + 1]] for i in keep]
    start = np.concatenate([[0], np.cumsum([len(p) for p in pts])]).astype(int).tolist()
    stats["rims_used"] = len(keep)
    stats["frames_used"] = len({obs.frames[i] for i in keep})
    scale = None
    if obs.sigma_scale is not None:
        parts = [obs.sigma_scale[obs.start[i] : obs.start[i + 1]] for i in keep]
        scale = np.concatenate(parts) if parts else np.zeros(0)
    return Observations(
        [obs.frames[i] for i in keep],
        [obs.wafers[i] for i in keep],
        [obs.rims[i] for i in keep],
        start,
        np.concatenate(pts) if pts else np.zeros((0, 2)),
        obs.n_wafers,
        obs.slots,
        stats,
        scale,
    )


#: Edge-point noise of the detector against the predicted side-band width (pixels), per rim:
#: RMS normal offset of the detected points from the true rim, relative to that of upper-rim
#: points on bands of at least 3 px (0.0615 px), at the centres of the bins 0–1, 1–1.5, then
#: 0.25 px wide to 3.5 (1.5–2 measured as one bin: its value serves both entries), and 3.5–4
#: px. Measured on the detector with its default rules (arc rules, rim screens, partner search)
#: on the simulated sessions of seeds 0–4 (200 frames, 395 k gated points, reference RMS
#: 0.0615 px; ``python benchmarks/autoteach_sessions.py
#: --noise-model --seeds 0 1 2 3 4``); seeds 5–7 were not used. Where the band narrows its
#: two blurred edges merge and the band-profile fit of the detector is biased along the edge;
#: the lower rim, the band's far edge, is the worse one from 3 px down.
BAND_NOISE_WIDTH_PX: tuple[float, ...] = (0.5, 1.25, 1.625, 1.875, 2.125, 2.375, 2.625, 2.875, 3.125, 3.375, 3.75)
#: Relative noise of the upper rim at :data:`BAND_NOISE_WIDTH_PX` (clamped below at 1).
BAND_NOISE_UPPER: tuple[float, ...] = (3.95, 2.73, 3.02, 3.02, 2.27, 1.64, 1.17, 1.05, 1.10, 0.98, 0.79)
#: Relative noise of the lower rim at :data:`BAND_NOISE_WIDTH_PX` (clamped below at 1).
BAND_NOISE_LOWER: tuple[float, ...] = (5.61, 4.22, 2.91, 2.91, 2.81, 2.59, 1.85, 1.62, 1.39, 1.09, 0.79)


def band_sigma_scale(band: np.ndarray, rim: int) -> np.ndarray:
    """Per-point factor of the edge-point standard deviation from the predicted band width.

    A heteroscedastic version of eq. (5.5)'s ``Ω^z = 1/σ²``: ``σ_i = σ·s(b_i)`` with ``s`` the
    detector's measured relative edge noise at band width ``b_i`` (:data:`BAND_NOISE_UPPER` /
    :data:`BAND_NOISE_LOWER`, linear in between, constant beyond the ends, never below 1 so
    that the best points keep the solver's ``σ``). ``rim`` 0 is the upper, 1 the lower rim.
    """
    table = BAND_NOISE_UPPER if rim == 0 else BAND_NOISE_LOWER
    s = np.interp(np.asarray(band, dtype=np.float64), BAND_NOISE_WIDTH_PX, table)
    return np.maximum(s, 1.0)


def band_width(
    points: np.ndarray, h_inv: np.ndarray, t_co_other: np.ndarray, conic: np.ndarray, k: np.ndarray, radius: float
) -> np.ndarray:
    """Predicted image width (pixels) of a wafer's side face at edge points of one of its rims.

    Each point is mapped to the rim plane by ``h_inv`` (the inverse of the rim's homography
    ``H = K·[r1 r2 t]``, eq. (5.13)), giving its circle angle φ; the other rim's point at φ
    (``t_co_other``: the other rim's frame in the camera frame) is projected, and the width is
    the component of the displacement between the two rims' images along the unit normal of
    the rim's image conic ``conic`` at the point. This is the apparent height of the wafer's
    side face (its thickness) there: widest at the front of the visible arc, shrinking to zero
    where the rim's image is tangent to the line of sight.
    """
    ph = np.column_stack([points, np.ones(len(points))])
    x = ph @ h_inv.T
    phi = np.arctan2(x[:, 1] / x[:, 2], x[:, 0] / x[:, 2])
    local = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(len(phi)), np.ones(len(phi))])
    pc = (t_co_other @ local)[:3]
    uvw = k @ pc
    other = (uvw[:2] / np.where(np.abs(uvw[2]) > 1e-12, uvw[2], 1e-12)).T
    # The rim's own image at φ: H·(r cos φ, r sin φ, 1).
    own = np.linalg.solve(h_inv, np.stack([radius * np.cos(phi), radius * np.sin(phi), np.ones(len(phi))]))
    own = (own[:2] / own[2]).T
    grad = ph @ conic.T
    n = grad[:, :2] / np.maximum(np.hypot(grad[:, 0], grad[:, 1]), 1e-300)[:, None]
    return np.abs(((other - own) * n).sum(axis=1))


def gate_detections(
    detections: list[list[Any]],
    camera_poses: np.ndarray,
    wafers: np.ndarray,
    slots: np.ndarray,
    *,
    k: np.ndarray,
    radius: float,
    thickness: float,
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
    """
    n_w = len(wafers)
    best: dict[tuple[int, int, int], tuple[int, np.ndarray, np.ndarray | None]] = {}
    n_edges = n_rejected = n_narrow = 0
    associated: set[tuple[int, int, int]] = set()
    # Rim frames (world) of every finite wafer, both rims, and 72 samples of each rim circle.
    ids = [(w, rim) for w in range(n_w) if np.all(np.isfinite(wafers[w])) for rim in (0, 1)]
    t_rims = np.zeros((len(ids), 4, 4))
    for i, (w, rim) in enumerate(ids):
        t = wafer_pose(np.asarray(wafers[w], dtype=np.float64))
        t[:3, 3] += t[:3, 2] * ((0.5 if rim == 0 else -0.5) * thickness)
        t_rims[i] = t
    ang = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
    circle = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(72), np.ones(72)])
    c0 = np.diag([1.0, 1.0, -radius * radius])
    for f, edges in enumerate(detections):
        if not edges or not ids:
            continue
        t_co = np.linalg.inv(camera_poses[f]) @ t_rims  # (R, 4, 4)
        pc = t_co @ circle  # (R, 4, 72)
        ok = np.all(pc[:, 2, :] > 1e-3, axis=1)  # whole rim in front: its image is an ellipse
        uv = np.einsum("ij,rjn->rin", k, pc[:, :3, :])
        uv = uv[:, :2, :] / np.where(ok[:, None, None], uv[:, 2:3, :], 1.0)
        boxes = np.stack([uv[:, 0].min(1), uv[:, 1].min(1), uv[:, 0].max(1), uv[:, 1].max(1)], axis=1)
        h = np.einsum("ij,rjk->rik", k, t_co[:, :3, [0, 1, 3]])
        hi = np.linalg.inv(np.where(ok[:, None, None], h, np.eye(3)))
        conics = np.transpose(hi, (0, 2, 1)) @ c0 @ hi
        conics /= np.linalg.norm(conics, axis=(1, 2))[:, None, None]
        margin = 3.0 * gate_px
        for e in edges:
            p = np.asarray(e.points, dtype=np.float64).reshape(-1, 2)
            if len(p) < min_points:
                continue
            n_edges += 1
            # Score on an even subsample (the solver keeps ``points_per_rim`` points anyway).
            p = _subsample(p, max(2 * points_per_rim, min_points))
            bb = _bbox(p)
            near = (
                ok
                & (boxes[:, 0] - margin <= bb[2])
                & (bb[0] - margin <= boxes[:, 2])
                & (boxes[:, 1] - margin <= bb[3])
                & (bb[1] - margin <= boxes[:, 3])
            )
            choice: tuple[int, int, int, np.ndarray | None] = (0, -1, -1, None)
            for r in np.flatnonzero(near):
                d = conic_distance(p, conics[r])
                inl = d <= gate_px
                n_in = int(inl.sum())
                if n_in > choice[0]:
                    choice = (n_in, ids[r][0], ids[r][1], p[inl])
            n_in, w, rim, q = choice
            if w < 0 or n_in < max(min_points, min_inlier_fraction * len(p)):
                n_rejected += 1
                continue
            associated.add((f, w, rim))
            scale = None
            if (min_band_px > 0.0 or band_weights) and q is not None:
                r = ids.index((w, rim))
                band = band_width(q, hi[r], t_co[r ^ 1], conics[r], k, radius)
                narrow = band < min_band_px
                n_narrow += int(narrow.sum())
                q = q[~narrow]
                n_in = len(q)
                if band_weights:
                    scale = band_sigma_scale(band[~narrow], rim)
                if n_in < min_points:
                    n_rejected += 1
                    continue
            key = (f, w, rim)
            if key not in best or n_in > best[key][0]:
                best[key] = (n_in, q, scale)
    frames, wafer_idx, rims, start, pts, scales = [], [], [], [0], [], []
    for (f, w, rim), (_, q, scale) in sorted(best.items()):
        if scale is not None:
            scales.append(_subsample(scale, points_per_rim))
        q = _subsample(q, points_per_rim)
        frames.append(f)
        wafer_idx.append(w)
        rims.append(rim)
        pts.append(q)
        start.append(start[-1] + len(q))
    obs = Observations(
        frames,
        wafer_idx,
        rims,
        start,
        np.concatenate(pts) if pts else np.zeros((0, 2)),
        n_w,
        np.asarray(slots, dtype=np.int64),
        sigma_scale=np.concatenate(scales) if band_weights and scales else None,
    )
    obs.stats = {
        "edges": n_edges,
        "edges_rejected": n_rejected,
        "rims_used": len(frames),
        "frames_used": len(set(frames)),
        "gate_px": gate_px,
        "min_band_px": min_band_px,
        "points_narrow_band": n_narrow,
        "rims_associated": len(associated),
        "stage": "gated",
    }
    return obs


# ---------------------------------------------------------------------------------------------
# The pipeline
# ---------------------------------------------------------------------------------------------


def _load(log_or_session: Any) -> Any:
    from autoteach.sim import Session

    if isinstance(log_or_session, Session):
        return log_or_session
    if isinstance(log_or_session, (str, os.PathLike)):
        from autoteach.io import read_log

        return read_log(Path(log_or_session))
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


def autoteach(
    log_or_session: Any,
    *,
    frontend: str = "auto",
    points_per_rim: int = 24,
    pixel_noise: float = 0.3,
    pixel_sigma: float | None = None,
    min_axis_ratio: float = 0.05,
    estimate_offsets: tuple[str, ...] = DEFAULT_OFFSETS,
    window: int = 5,
    nominal_base: np.ndarray | None = None,
    robot_params: Any = None,
    wafer_radius: float | None = None,
    wafer_thickness: float | None = None,
    odometry: np.ndarray | None = None,
    odometry_sigma: tuple[float, ...] | None = None,
    odometry_start: np.ndarray | None = None,
    use_ukf: bool = True,
    ukf_noise: Any = None,
    ukf_odometry: str = "vo",
    baseline: bool = False,
    huber: float | None = 3.0,
    encoder_sigma: tuple[float, float, float, float] | None = None,
    max_iterations: int = 100,
    min_track_frames: int = 5,
    min_wafer_frames: int = 8,
    reset_tilts: bool = True,
    basin_search: bool = True,
    gate_px: tuple[float, ...] = (3.0, 1.5, 1.0),
    min_band_px: float = 2.5,
    band_weights: bool = True,
    slot_births: bool = True,
    camera_mode: str = "chain",
    motion_sigma: tuple[float, ...] = (2e-5, 2e-5, 2e-5, 2e-5, 2e-5, 2e-5),
    estimate_mount: bool = False,
    estimate_links: tuple[str, ...] = (),
    rim_offset_prior: bool = True,
    seed: int = 0,
    progress: bool = False,
) -> AutoTeachResult:
    """Auto-teach the hand-eye system from a session: calibration, wafer poses, covariances.

    Args:
        log_or_session: a :class:`~autoteach.sim.Session` or the path of an MCAP log.
        frontend: ``"simulated"`` (ground-truth visible rims of a simulated session with pixel
            noise and ground-truth association), ``"detect"`` (wafer detection + tracking on the
            images, gated by the projected prior: the real pipeline) or ``"auto"`` (``"detect"``
            when the session has images, else ``"simulated"`` when it has ground-truth rims).
        points_per_rim: edge points kept per rim and frame.
        pixel_noise: std of the noise added by the simulated front end (pixels).
        pixel_sigma: edge-point std assumed by the solver (default: ``max(pixel_noise, 0.3)``).
        min_axis_ratio: rims seen more edge-on than this minor/major ratio are dropped.
        estimate_offsets: joints whose zero offsets SLAM-MOT estimates (see the module docs;
            asking for ``joint1``, ``joint3`` or ``lift`` makes the problem unobservable, which is
            reported in :attr:`AutoTeachResult.unobservable`).
        window: sliding-window size in frames (0: batch only).
        nominal_base: nominal ``T_wb`` (4×4) in the reference-wafer frame (default: the simulated
            configuration's base pose moved into the reference frame of the nominal slot).
        robot_params: robot geometry (default: the session's, or the default robot).
        wafer_radius: wafer radius (default: the session's or 0.15 m).
        wafer_thickness: wafer thickness (default: the session's or 1 mm).
        odometry: visual-odometry increments (F−1, 6) ``[u_T; u_R]`` for the UKF; simulated
            sessions without them get drifting simulated odometry.
        odometry_sigma: precision of the odometry increments ``[σ_ω (3, rad); σ_ρ (3, m)]``
            for the free-camera mode's relative-pose factors (default: the simulated odometry's
            white noise plus its drift over the session when the pipeline simulates it, else
            the per-step process noise of eq. (5.2): 0.2°, 30/30/1.5 mm).
        odometry_start: orientation (3×3, or the rotation of a 4×4 pose) of the first camera
            frame in the odometry's world frame, which the free-camera mode needs to express the
            world-frame translation increments ``u_T`` in the camera frame (default: the nominal
            chain's at frame 0 for given odometry; the true one for simulated odometry).
        use_ukf: run the UKF stage (needs odometry).
        ukf_noise: ``"seed"`` for the noise levels of eq. (5.2), 16 standard deviations (see
            ``autoteach._core.handeye_ukf``), or ``None``: matched to the simulated odometry when
            the pipeline simulates it, else eq. (5.2).
        ukf_odometry: ``"vo"``: the odometry increments are world-frame, with white errors
            (eq. (5.1) literally; simulated: the drifting visual odometry); ``"slam"``: they are
            relative poses of a SLAM with a map (:class:`autoteach.sim.odometry.SlamConfig`;
            simulated sessions without ``odometry`` get :func:`~autoteach.sim.odometry.simulate_slam`),
            and the UKF models the SLAM's bounded error. Relative poses cannot see θ1 (it turns
            the whole trajectory about the base z axis): the UKF then reports it unobservable.
        baseline: also solve with point reprojection and nearest-point association.
        huber: Huber threshold on whitened residuals (``None``: none).
        encoder_sigma: encoder noise of joint1, joint2, joint4, lift modelled per frame (default:
            the simulated session's, else 2e-5 rad / 5e-6 m; ``()`` to tie the camera rigidly
            to the encoders).
        max_iterations: LM iteration limit.
        min_track_frames: detect front end: tracks registered in fewer frames are not used for
            the first estimate.
        reset_tilts: detect front end: also run the gating chain from level wafers after the first
            estimate and keep the chain that explains more edges (see the code comment).
        basin_search: after every batch solve, re-fit each wafer whose edge residuals stand out
            (over twice the median wafer's RMS) alone from a grid of tilts and heights with the
            camera poses fixed, and solve again from a better basin when one halves its cost
            (``SlamMot::solve_batch_with_basins``: a wafer seen from one side in few frames can
            stop in a second minimum of the height–tilt valley). The wafers moved by the last
            solve are ``frontend_stats["basins_moved"]`` (slots).
        min_wafer_frames: detect front end: wafers gated into fewer frames are reported as not
            estimated (too few views to constrain a wafer pose; listed in ``frontend_stats``).
        gate_px: detect front end: after each first estimate every detected edge is associated
            with the projected prior within this gate (pixels), one round per value.
        min_band_px: detect front end: edge points where the predicted side-face band of the
            wafer is narrower than this (pixels) are not used (see :func:`gate_detections`;
            0 keeps them).
        band_weights: detect front end: in the last gate every kept point gets a standard
            deviation ``σ·s(b)`` from the predicted side-band width ``b`` at the point
            (:func:`band_sigma_scale`, the detector's measured edge noise) instead of the
            common ``σ``.
        slot_births: detect front end: give the tracker the carrier pitch so that free slots
            next to a track are birth hypotheses (see :func:`detect_frontend`).
        camera_mode: ``"chain"`` (camera poses through the kinematic chain, eq. (5.9)) or
            ``"free"`` (a pose variable per frame tied to the robot by the relative motion
            factor of eqs. (5.10)–(5.12) and to the visual odometry by relative-pose factors
            between the same frames when the session has odometry, and a prior on the
            calibration around the nominal values).
        motion_sigma: free-camera mode: robot motion precision ``[σ_ω (3, rad); σ_ρ (3, m)]``
            between consecutive frames.
        estimate_mount: also estimate a correction of the camera mount ``T_ec`` (chain mode).
        estimate_links: link lengths to calibrate, among ``"l1"``, ``"l2"``, ``"l4"``.
        rim_offset_prior: detect front end: give the detector the wafer's thickness ratio and
            the focal length (:func:`detector_options`), its prior on the offset between a
            wafer's two rims, and the edge profile of the camera (``"pixel"`` for a simulated
            session, whose renderer blurs on the pixel grid; ``"optical"`` for a log without
            the simulator's configuration).
        seed: seed of the simulated front end's noise and odometry.
        progress: progress bars on stderr.

    Raises:
        InvalidInputError: unreadable/unsynchronised input, no images (detect front end), no
            joint states, no wafer seen in any frame.
        ConvergenceError: the solver failed.

    """
    from tqdm import tqdm

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    session = _load(log_or_session)
    _validate_session(session)
    timings["load_s"] = time.perf_counter() - t0

    cfg = session.config
    from autoteach.geometry import RobotParams

    params = robot_params or (cfg.robot if cfg is not None else RobotParams())
    radius = float(wafer_radius if wafer_radius is not None else (cfg.wafer_radius if cfg is not None else 0.15))
    thickness = float(
        wafer_thickness if wafer_thickness is not None else (cfg.wafer_thickness if cfg is not None else 0.001)
    )
    k = _pinhole_k(session.camera)
    bad = [j for j in estimate_offsets if j not in JOINTS]
    if bad:
        raise InvalidInputError(f"estimate_offsets names unknown joints {bad}; joints are {JOINTS}")
    if frontend == "auto":
        has_images = session.images is not None and np.asarray(session.images).any()
        frontend = "detect" if has_images or session.rims is None else "simulated"
    if frontend not in ("simulated", "detect"):
        raise InvalidInputError(f"frontend must be 'auto', 'simulated' or 'detect', got {frontend!r}")
    if not (math.isfinite(min_band_px) and min_band_px >= 0.0):
        raise InvalidInputError(f"min_band_px must be finite and >= 0, got {min_band_px!r}")
    if camera_mode not in ("chain", "free"):
        raise InvalidInputError(f"camera_mode must be 'chain' or 'free', got {camera_mode!r}")
    bad_links = [name for name in estimate_links if name not in LINKS]
    if bad_links:
        raise InvalidInputError(f"estimate_links names unknown links {bad_links}; links are {LINKS}")
    if camera_mode == "free" and (estimate_mount or estimate_links):
        raise InvalidInputError(
            "the camera mount and link lengths are calibrated through the chain (camera_mode='chain')"
        )

    stages = tqdm(total=4, desc="auto-teaching", unit="stage", disable=not progress, leave=False)
    t0 = time.perf_counter()
    if frontend == "simulated":
        obs = simulated_frontend(
            session, points_per_rim=points_per_rim, pixel_noise=pixel_noise, min_axis_ratio=min_axis_ratio, seed=seed
        )
    else:
        from autoteach.geometry import WaferRobot
        from autoteach.sim.config import DEFAULT_BASE_POSE

        base_world = np.array(cfg.base_pose if cfg is not None else DEFAULT_BASE_POSE, dtype=np.float64)
        nominal_cams = np.asarray(
            WaferRobot(params=params, base=base_world).camera_pose(session.joints_encoder), dtype=np.float64
        )
        t1 = time.perf_counter()
        # A simulated session's images come from the renderer, which blurs on the pixel grid.
        profile = "pixel" if cfg is not None else "optical"
        options = detector_options(k, radius, thickness, edge_profile=profile) if rim_offset_prior else {}
        detections = detect_all(session.images, progress=progress, **options)
        timings["detect_s"] = time.perf_counter() - t1
        obs = detect_frontend(
            session,
            detections,
            k=k,
            camera_poses=nominal_cams,
            radius=radius,
            thickness=thickness,
            pitch=cfg.slot_pitch if cfg is not None else 0.010,
            n_slots=cfg.n_slots if cfg is not None else 26,
            points_per_rim=points_per_rim,
            min_track_frames=min_track_frames,
            slot_births=slot_births,
            progress=progress,
        )
    timings["frontend_s"] = time.perf_counter() - t0
    stages.update()
    if len(obs) == 0:
        n_rims = sum(len(d) for d in detections) if frontend == "detect" else 0
        if n_rims:
            raise InvalidInputError(
                f"{n_rims} wafer rims were detected in {session.n_frames} frames, but no track lasted "
                f"min_track_frames = {min_track_frames} frames, so all were dropped: record a longer session "
                "or lower min_track_frames"
            )
        raise InvalidInputError(
            "no wafer edge was detected in any frame: nothing constrains the calibration "
            f"({session.n_frames} frames, front end {frontend!r})"
        )
    seen = sorted(set(obs.wafers))
    if obs.n_wafers == 0:
        raise InvalidInputError("no wafer was tracked")
    frontend_stats: dict[str, Any] = {"initial": dict(obs.stats)} if obs.stats else {}

    # Reference wafer: the lowest slot (or the first track) among the observed wafers.
    if np.all(obs.slots >= 0):
        ref = min(seen, key=lambda w: obs.slots[w])
    else:
        ref = seen[0]
    pitch = cfg.slot_pitch if cfg is not None else 0.010
    if nominal_base is None:
        from autoteach.sim.config import DEFAULT_BASE_POSE

        base_w = np.array(cfg.base_pose if cfg is not None else DEFAULT_BASE_POSE, dtype=np.float64)
        ref_slot = int(obs.slots[ref]) if obs.slots[ref] >= 0 else 1
        t_w_ref = np.eye(4)
        t_w_ref[2, 3] = (ref_slot - 1) * pitch
        nominal_base = np.linalg.inv(t_w_ref) @ base_w
    nominal_base = np.asarray(nominal_base, dtype=np.float64)
    init_wafers = np.zeros((obs.n_wafers, 5))
    for w in range(obs.n_wafers):
        if obs.slots[w] >= 0 and obs.slots[ref] >= 0:
            init_wafers[w, 2] = (obs.slots[w] - obs.slots[ref]) * pitch

    enc = np.ascontiguousarray(session.joints_encoder, dtype=np.float64)
    robot_arr = _robot_array(params)

    # --- UKF (§5.2) -----------------------------------------------------------------------
    ukf_out: dict[str, Any] | None = None
    increments, odo_start, odo_sigma = _odometry(session, odometry, odometry_sigma, seed)
    if use_ukf:
        t0 = time.perf_counter()
        from autoteach.sim.odometry import (
            OdometryConfig,
            SlamConfig,
            integrate_odometry,
            integrate_relative,
            simulate_slam,
        )

        if ukf_odometry not in ("vo", "slam"):
            raise InvalidInputError(f"ukf_odometry must be 'vo' or 'slam', got {ukf_odometry!r}")
        noise = None if ukf_noise == "seed" else ukf_noise
        ukf_inc = increments
        slam = SlamConfig() if ukf_odometry == "slam" else None
        if slam is not None:
            if odometry is None and session.camera_poses is not None:
                ukf_inc = simulate_slam(session.camera_poses, seed, slam)
            if ukf_noise is None:
                noise = slam.ukf_noise(cfg.encoder_noise if cfg is not None else (2e-5,) * 4 + (5e-6,))
        elif odometry is None and ukf_noise is None and increments is not None:
            noise = OdometryConfig().ukf_noise()
        if ukf_inc is not None:
            base_w = np.array(cfg.base_pose, dtype=np.float64) if cfg is not None else nominal_base
            run = _core.handeye_ukf(
                robot_arr,
                base_w,
                enc,
                np.ascontiguousarray(ukf_inc, dtype=np.float64),
                noise,
                odometry=None if slam is None else slam.ukf_odometry(),
            )
            from autoteach.geometry import WaferRobot

            robot = WaferRobot(params=params, base=base_w)
            encoder_poses = np.asarray(robot.camera_pose(enc), dtype=np.float64)
            chain = integrate_odometry if slam is None else integrate_relative
            ukf_out = {
                "poses": np.asarray(run["poses"]),
                "offsets": np.asarray(run["offsets"]),
                "offset_std": np.asarray(run["offset_std"]),
                "observable": [bool(v) for v in run["observable"]],
                "encoder_poses": encoder_poses,
                "odometry_poses": chain(encoder_poses[0], ukf_inc),
            }
            if session.calibration is not None:
                true = np.asarray(session.calibration.joint_offsets)[[0, 1, 3]]
                err = np.abs(ukf_out["offsets"][-1] - true)[ukf_out["observable"]]
                ukf_out["errors"] = {"joint_offset_deg": float(np.degrees(err.max()))}
                ukf_out["true_offsets"] = true
        timings["ukf_s"] = time.perf_counter() - t0
    stages.update()

    # --- SLAM-MOT (§5.3) ------------------------------------------------------------------
    t0 = time.perf_counter()
    offsets0 = np.zeros(5)
    est_idx = [JOINTS.index(j) for j in estimate_offsets]
    if ukf_out is not None:
        for i, j in enumerate((0, 1, 3)):
            if j in est_idx:
                offsets0[j] = ukf_out["offsets"][-1][i]
    sigma = float(pixel_sigma if pixel_sigma is not None else max(pixel_noise, 0.3))
    z_top = float(init_wafers[:, 2].max()) + 0.05
    if encoder_sigma is None:
        noise5 = cfg.encoder_noise if cfg is not None else (2e-5, 2e-5, 2e-5, 2e-5, 5e-6)
        encoder_sigma = tuple(max(float(noise5[j]), 1e-9) for j in (0, 1, 3, 4))
    extra: dict[str, Any] = {}
    if camera_mode == "free":
        # Relative robot motion (5.10)–(5.12) between consecutive frames and, when the session
        # has visual odometry, its increments as relative-pose factors between the same poses.
        rel = None
        if increments is not None:
            from autoteach.sim.odometry import relative_odometry

            if odometry_start is not None:
                start = np.asarray(odometry_start, dtype=np.float64)
                start = start[:3, :3] if start.shape == (4, 4) else start
            elif odo_start is not None:
                start = odo_start
            else:
                start = _nominal_start_rotation(cfg, params, enc)
            rel = np.ascontiguousarray(relative_odometry(increments, start))
        extra["free_camera"] = ([float(v) for v in motion_sigma], rel, [float(v) for v in odo_sigma])
        frontend_stats["odometry_factors"] = 0 if rel is None else len(rel)
        encoder_sigma = ()
    if estimate_mount:
        extra["estimate_mount"] = True
    if estimate_links:
        extra["estimate_links"] = [LINKS.index(name) for name in estimate_links]
    common = dict(
        **extra,
        encoder_sigma=tuple(encoder_sigma) if encoder_sigma else None,
        pixel_sigma=sigma,
        estimate_offsets=est_idx,
        reference_wafer=int(ref),
        huber=huber,
        max_iterations=int(max_iterations),
        basin_search=bool(basin_search),
    )
    args = (
        k,
        robot_arr,
        radius,
        thickness,
        enc,
        obs.frames,
        obs.wafers,
        obs.rims,
        obs.start,
        np.ascontiguousarray(obs.points),
        nominal_base,
        offsets0,
        init_wafers,
    )
    heights = (-0.02, max(z_top, 0.05), 0.001)
    if frontend == "detect":
        # First estimate from the consistently tracked rims (robust loss), then re-associate
        # every detected edge to the projected prior with shrinking gates and solve again.
        # The tracks may mix wafers, so the first estimate can sit in a mirrored-tilt basin:
        # the chain of gates runs from its tilts and from level wafers (the nominal carrier),
        # and the one whose estimate explains more detected edges within the last gate wins.
        tracked = _core.handeye_slam_mot(*args, factor="conic", window=0, init_heights=heights, **common)
        heights = None
        best: tuple[int, Observations, tuple[Any, ...]] | None = None
        for reset in (False, True) if reset_tilts else (False,):
            first, cand_obs, cand_args = tracked, obs, args
            failed = False
            for gi, gate in enumerate(gate_px):
                if gi > 0:
                    try:
                        first = _core.handeye_slam_mot(*cand_args, factor="conic", window=0, **common)
                    except InvalidInputError:
                        # This chain's estimate put a rim behind a camera (its gated edges
                        # mixed wafers): the chain is abandoned, the other may still hold.
                        failed = True
                        break
                wafers_first = np.asarray(first["wafers"], dtype=np.float64).copy()
                if gi == 0 and reset:
                    wafers_first[:, 3:] = 0.0
                cand_obs = gate_detections(
                    detections,
                    np.asarray(first["camera_poses"]),
                    np.asarray(first["wafers"], dtype=np.float64),
                    obs.slots,
                    k=k,
                    radius=radius,
                    thickness=thickness,
                    gate_px=gate,
                    points_per_rim=points_per_rim,
                    min_band_px=min_band_px if gi == len(gate_px) - 1 else 0.0,
                    band_weights=band_weights and gi == len(gate_px) - 1,
                )
                if len(cand_obs) == 0:
                    break
                cand_args = (
                    *args[:5],
                    cand_obs.frames,
                    cand_obs.wafers,
                    cand_obs.rims,
                    cand_obs.start,
                    np.ascontiguousarray(cand_obs.points),
                    np.asarray(first["base_pose"], dtype=np.float64),
                    np.asarray(first["joint_offsets"], dtype=np.float64),
                    wafers_first,
                )
            # Edges explained (before the band filter, which only thins their points).
            n_explained = int(cand_obs.stats.get("rims_associated", len(cand_obs)))
            if not failed and len(cand_obs) > 0 and (best is None or n_explained > best[0]):
                best = (n_explained, cand_obs, cand_args)
        if best is None:
            raise InvalidInputError(
                f"no detected edge lies within {gate_px} px of the projected wafer estimates, or every "
                "gating chain's estimate put a rim behind a camera: the first estimate from the tracked "
                "rims is inconsistent with the detections"
            )
        _, obs, args = best
        obs = _drop_sparse_wafers(obs, min_wafer_frames)
        # The solve gets exactly the kept observations (a wafer with too few views is reported
        # as not estimated and does not enter the solve).
        args = (*args[:5], obs.frames, obs.wafers, obs.rims, obs.start, np.ascontiguousarray(obs.points), *args[10:])
        frontend_stats["gated"] = dict(obs.stats)
        seen = sorted(set(obs.wafers))
    sol = _core.handeye_slam_mot(
        *args,
        factor="conic",
        window=int(window),
        init_heights=heights,
        point_sigma_scale=obs.sigma_scale,
        **common,
    )
    timings["slam_mot_s"] = time.perf_counter() - t0
    frontend_stats["basins_moved"] = [int(obs.slots[w]) for w in sol["basins_moved"]]
    stages.update()

    base_hat = np.asarray(sol["base_pose"])
    wafers_hat = np.asarray(sol["wafers"])
    offsets_hat = np.asarray(sol["joint_offsets"])
    cov = sol["covariance"]
    n_off = len(est_idx)
    base_std = np.full(6, np.nan)
    offsets_std = np.full(5, np.nan)
    wafer_std = np.full((obs.n_wafers, 5), np.nan)
    wafer_std[ref] = 0.0
    if cov is not None:
        cov = np.asarray(cov)
        d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        base_std = d[:6]
        for i, j in enumerate(est_idx):
            offsets_std[j] = d[6 + i]
        for i, w in enumerate(sol["covariance_wafers"]):
            wafer_std[w] = d[6 + n_off + 5 * i : 6 + n_off + 5 * i + 5]
    extra_cal: dict[str, Any] = {"camera_mode": camera_mode}
    tail = 6 + n_off + 5 * len(sol["covariance_wafers"])
    if estimate_mount:
        std = d[tail : tail + 6] if cov is not None else np.full(6, np.nan)
        tail += 6
        extra_cal["mount_correction"] = np.asarray(sol["mount"])
        extra_cal["mount_std"] = std
    for i, name in enumerate(estimate_links):
        li = LINKS.index(name)
        std = float(d[tail + i]) if cov is not None else math.nan
        extra_cal.setdefault("links", {})[name] = {"correction_m": float(sol["links"][li]), "std_m": std}
    status: dict[str, str] = {}
    joint_offsets = np.full(5, np.nan)
    for j, name in enumerate(JOINTS):
        if j in est_idx:
            status[name] = "estimated"
            joint_offsets[j] = offsets_hat[j]
        elif ukf_out is not None and j in (0, 1, 3) and ukf_out["observable"][(0, 1, 3).index(j)]:
            status[name] = "ukf"
            joint_offsets[j] = ukf_out["offsets"][-1][(0, 1, 3).index(j)]
            offsets_std[j] = ukf_out["offset_std"][-1][(0, 1, 3).index(j)]
        else:
            status[name] = "unobservable: " + UNOBSERVABLE_REASONS.get(name, "not estimated")
    unobserved = [w for w in range(obs.n_wafers) if w not in seen]
    wafers_hat[unobserved] = np.nan
    wafer_std[unobserved] = np.nan

    # Theoretical resolution (5.14) from each wafer's best view (most edge points).
    t0 = time.perf_counter()
    resolution = np.full((obs.n_wafers, 5), np.nan)
    cams = np.asarray(sol["camera_poses"])
    counts: dict[int, tuple[int, int]] = {}
    for i, (f, w) in enumerate(zip(obs.frames, obs.wafers, strict=True)):
        n = obs.start[i + 1] - obs.start[i]
        if n > counts.get(w, (-1, 0))[0]:
            counts[w] = (n, f)
    for w, (_, f) in counts.items():
        try:
            resolution[w] = _core.handeye_resolution(k, cams[f], wafers_hat[w], radius, thickness)
        except Exception:  # noqa: BLE001 - a view where the rim crosses the camera plane: no figure
            pass

    result = AutoTeachResult(
        base_pose=base_hat,
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
        resolution=resolution,
        rms_px=float(sol["rms_px"]),
        n_observations=len(obs),
        frontend=frontend,
        timings=timings,
        frontend_stats=frontend_stats,
        extra_calibration=extra_cal,
        observations={
            "frames": obs.frames,
            "wafers": obs.wafers,
            "rims": obs.rims,
            "start": obs.start,
            "points": obs.points,
        },
    )
    timings["resolution_s"] = time.perf_counter() - t0

    truth_index: list[int] | None = None
    if session.wafer_slots is not None and frontend == "detect":
        true_slots = [int(v) for v in session.wafer_slots]
        truth_index = [true_slots.index(int(sl)) if int(sl) in true_slots else -1 for sl in obs.slots]
        frontend_stats["true_slots_missed"] = sorted(set(true_slots) - {int(v) for v in obs.slots[seen]})
        frontend_stats["spurious_slots"] = [int(obs.slots[w]) for w in seen if truth_index[w] < 0]
    if baseline:
        t0 = time.perf_counter()
        # The seed's baseline as it is: no basin search.
        chain_only = {k: v for k, v in common.items() if k not in ("free_camera", "basin_search")}
        base_sol = _core.handeye_slam_mot(
            *args,
            factor="point",
            window=0,
            init_heights=(-0.02, max(z_top, 0.05), 0.001),
            point_sigma_scale=obs.sigma_scale,
            **chain_only,
        )
        b = {
            "base_pose": np.asarray(base_sol["base_pose"]),
            "wafers": np.asarray(base_sol["wafers"]),
            "joint_offsets": np.asarray(base_sol["joint_offsets"]),
            "rms_px": float(base_sol["rms_px"]),
            "runtime_s": time.perf_counter() - t0,
        }
        if session.has_ground_truth:
            b["errors"] = ground_truth_errors(
                session, ref, b["base_pose"], b["joint_offsets"], b["wafers"], est_idx, seen, truth_index=truth_index
            )[0]
        result.baseline = b
        timings["baseline_s"] = b["runtime_s"]
    stages.update()
    stages.close()

    if session.has_ground_truth and session.calibration is not None:
        errs, sig = ground_truth_errors(
            session,
            ref,
            base_hat,
            offsets_hat,
            wafers_hat,
            est_idx,
            seen,
            base_std,
            offsets_std,
            wafer_std,
            truth_index=truth_index,
        )
        result.errors = errs
        result.within_3sigma = sig
    return result


def _yaw(r: np.ndarray) -> float:
    return math.atan2(r[1, 0], r[0, 0])


def ground_truth_errors(
    session: Any,
    ref: int,
    base_hat: np.ndarray,
    offsets_hat: np.ndarray,
    wafers_hat: np.ndarray,
    est_idx: list[int],
    seen: list[int],
    base_std: np.ndarray | None = None,
    offsets_std: np.ndarray | None = None,
    wafer_std: np.ndarray | None = None,
    truth_index: list[int] | None = None,
) -> tuple[dict[str, float], dict[str, bool]]:
    """Absolute errors of the estimates against a simulated session's ground truth.

    The truth is moved into the true reference-wafer frame; the effective base is
    ``T_wb·Rz(−δ1)·Tz(−δh)``; the estimate's yaw gauge is aligned to the truth by a rotation about
    the reference normal. Returns the errors (``joint_offset_deg`` max over the estimated
    joints, ``base_translation_mm``, ``base_rotation_deg``, ``wafer_center_mm`` and
    ``wafer_tilt_deg`` max over the wafers) and, when standard deviations are given, whether each
    group's every component lies within 3σ. ``truth_index[w]`` is the ground-truth wafer of
    estimated wafer ``w`` (default: the same index; ``-1``: a wafer the truth does not have,
    skipped — the caller reports it).
    """
    cal = session.calibration
    truth = list(range(len(session.wafer_poses))) if truth_index is None else list(truth_index)
    if truth[ref] < 0:
        raise InvalidInputError("the reference wafer matches no ground-truth wafer: errors cannot be computed")
    t_ref = np.asarray(session.wafer_poses[truth[ref]], dtype=np.float64)
    t_ref_inv = np.linalg.inv(t_ref)
    delta = np.asarray(cal.joint_offsets, dtype=np.float64)
    eff = np.eye(4)
    eff[:3, :3] = _rot("z", -delta[0])
    eff[2, 3] = -delta[4]
    base_true = t_ref_inv @ np.asarray(cal.base_pose, dtype=np.float64) @ eff
    # Gauge: rotate the estimate about the reference normal (z) to the true base yaw.
    g = np.eye(4)
    g[:3, :3] = _rot("z", _yaw(base_true[:3, :3]) - _yaw(base_hat[:3, :3]))
    base_al = g @ base_hat
    d_rot = _log_so3(base_true[:3, :3].T @ base_al[:3, :3])
    d_t = base_al[:3, 3] - base_true[:3, 3]
    errs: dict[str, float] = {
        "joint_offset_deg": float(np.degrees(np.max(np.abs(offsets_hat[est_idx] - delta[est_idx]))))
        if est_idx
        else 0.0,
        "base_translation_mm": float(np.linalg.norm(d_t) * 1e3),
        "base_rotation_deg": float(np.degrees(np.linalg.norm(d_rot))),
    }
    centre_err, tilt_err = [], []
    centre_ok, tilt_ok = True, True
    for w in seen:
        if w == ref or truth[w] < 0:
            continue
        wt = t_ref_inv @ np.asarray(session.wafer_poses[truth[w]], dtype=np.float64)
        c_hat = (g @ np.append(wafers_hat[w, :3], 1.0))[:3]
        n_hat = g[:3, :3] @ wafer_pose(wafers_hat[w])[:3, 2]
        n_true = wt[:3, 2]
        ce = c_hat - wt[:3, 3]
        centre_err.append(float(np.linalg.norm(ce)))
        tilt_err.append(math.degrees(math.acos(max(-1.0, min(1.0, float(n_hat @ n_true))))))
        if wafer_std is not None:
            s = wafer_std[w]
            # Centre in the gauge-aligned frame: compare per axis with the (unrotated) std; the
            # gauge rotation is a fraction of a degree, well inside the tolerance of this check.
            centre_ok &= bool(np.all(np.abs(ce) <= 3.0 * s[:3] + 1e-12))
            wt_par = wafer_params_of(np.linalg.inv(g) @ wt)
            tilt_ok &= bool(np.all(np.abs(wafers_hat[w, 3:] - wt_par[3:]) <= 3.0 * s[3:] + 1e-12))
    errs["wafer_center_mm"] = float(max(centre_err) * 1e3) if centre_err else 0.0
    errs["wafer_tilt_deg"] = float(max(tilt_err)) if tilt_err else 0.0
    sig: dict[str, bool] = {}
    if base_std is not None and offsets_std is not None:
        # Base error in the estimate's tangent [ω; ρ] (body frame of the gauge-aligned estimate).
        r_al = base_al[:3, :3]
        e_body = np.concatenate([-d_rot, r_al.T @ (base_true[:3, 3] - base_al[:3, 3])])
        s = np.asarray(base_std)
        sig["base_rotation"] = bool(np.all(np.abs(e_body[:2]) <= 3.0 * np.sqrt(s[:2] ** 2) + 1e-12))
        sig["base_translation"] = bool(np.all(np.abs(e_body[3:]) <= 3.0 * s[3:] + 1e-12))
        sig["joint_offsets"] = bool(np.all(np.abs(offsets_hat[est_idx] - delta[est_idx]) <= 3.0 * offsets_std[est_idx]))
        sig["wafer_centers"] = centre_ok
        sig["wafer_tilts"] = tilt_ok
    return errs, sig
