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
wafers; the others are reported as unobservable, never as numbers. The UKF, whose visual-odometry
translation increments are expressed in the world frame of the known base, also estimates δ1.

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


def detect_frontend(
    session: Any, *, points_per_rim: int = 24, min_points: int = 8, progress: bool = False
) -> Observations:
    """Edge observations from the images: wafer detection (ch. 3) and tracking (ch. 4).

    Uses :func:`autoteach.detect.detect_wafers` per frame and :class:`autoteach.track.WaferTracker`
    for the association over time; each track becomes one wafer (ordered by image height of its
    first detection, lowest first). Raises :class:`InvalidInputError` when the images are missing.
    """
    from tqdm import tqdm

    from autoteach.detect import detect_wafers
    from autoteach.track import WaferTracker

    images = np.asarray(session.images)
    if images.ndim != 3 or images.shape[0] == 0 or not images.any():
        raise InvalidInputError("the session has no images: the detection front end cannot run")
    tracker = WaferTracker()
    per_frame: list[tuple[int, Any]] = []
    for f in tqdm(range(len(images)), desc="detecting", unit="frame", disable=not progress, leave=False):
        edges = detect_wafers(images[f])
        tracks = tracker.update(edges)
        per_frame.append((f, tracks))
    # Collect (frame, track id, rim kind, points).
    ids: dict[int, int] = {}
    frames, wafers, rims, start, pts = [], [], [], [0], []
    for f, tracks in per_frame:
        for t in tracks:
            if not getattr(t, "visible", True):
                continue
            for e in getattr(t, "edges", None) or [getattr(t, "edge", None)]:
                if e is None:
                    continue
                p = np.asarray(e.points, dtype=np.float64).reshape(-1, 2)
                if len(p) < min_points:
                    continue
                k = ids.setdefault(int(t.id), len(ids))
                kind = str(getattr(e, "kind", "upper")).lower()
                frames.append(f)
                wafers.append(k)
                rims.append(1 if "lower" in kind else 0)
                q = _subsample(p, points_per_rim)
                pts.append(q)
                start.append(start[-1] + len(q))
    return Observations(
        frames,
        wafers,
        rims,
        start,
        np.concatenate(pts) if pts else np.zeros((0, 2)),
        len(ids),
        -np.ones(len(ids), dtype=np.int64),
    )


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
    use_ukf: bool = True,
    ukf_noise: Any = None,
    baseline: bool = False,
    huber: float | None = 3.0,
    encoder_sigma: tuple[float, float, float, float] | None = None,
    max_iterations: int = 50,
    seed: int = 0,
    progress: bool = False,
) -> AutoTeachResult:
    """Auto-teach the hand-eye system from a session: calibration, wafer poses, covariances.

    Args:
        log_or_session: a :class:`~autoteach.sim.Session` or the path of an MCAP log.
        frontend: ``"simulated"`` (ground-truth visible rims of a simulated session with pixel
            noise and ground-truth association), ``"detect"`` (wafer detection + tracking on the
            images) or ``"auto"`` (``"simulated"`` when the session has ground-truth rims).
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
        use_ukf: run the UKF stage (needs odometry).
        ukf_noise: ``"seed"`` for the noise levels of eq. (5.2), 16 standard deviations (see
            ``autoteach._core.handeye_ukf``), or ``None``: matched to the simulated odometry when
            the pipeline simulates it, else eq. (5.2).
        baseline: also solve with point reprojection and nearest-point association.
        huber: Huber threshold on whitened residuals (``None``: none).
        encoder_sigma: encoder noise of joint1, joint2, joint4, lift modelled per frame (default:
            the simulated session's, else 2e-5 rad / 5e-6 m; ``()`` to tie the camera rigidly
            to the encoders).
        max_iterations: LM iteration limit.
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
        frontend = "simulated" if session.rims is not None else "detect"
    if frontend not in ("simulated", "detect"):
        raise InvalidInputError(f"frontend must be 'auto', 'simulated' or 'detect', got {frontend!r}")

    stages = tqdm(total=4, desc="auto-teaching", unit="stage", disable=not progress, leave=False)
    t0 = time.perf_counter()
    if frontend == "simulated":
        obs = simulated_frontend(
            session, points_per_rim=points_per_rim, pixel_noise=pixel_noise, min_axis_ratio=min_axis_ratio, seed=seed
        )
    else:
        obs = detect_frontend(session, points_per_rim=points_per_rim, progress=progress)
    timings["frontend_s"] = time.perf_counter() - t0
    stages.update()
    if len(obs) == 0:
        raise InvalidInputError(
            "no wafer edge was detected in any frame: nothing constrains the calibration "
            f"({session.n_frames} frames, front end {frontend!r})"
        )
    seen = sorted(set(obs.wafers))
    if obs.n_wafers == 0:
        raise InvalidInputError("no wafer was tracked")

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
    if use_ukf:
        t0 = time.perf_counter()
        increments = odometry
        noise = None if ukf_noise == "seed" else ukf_noise
        if increments is None and session.camera_poses is not None:
            from autoteach.sim.odometry import OdometryConfig, simulate_odometry

            increments = simulate_odometry(session.camera_poses, seed)
            if ukf_noise is None:
                noise = OdometryConfig().ukf_noise()
        if increments is not None:
            base_w = np.array(cfg.base_pose, dtype=np.float64) if cfg is not None else nominal_base
            run = _core.handeye_ukf(robot_arr, base_w, enc, np.ascontiguousarray(increments, dtype=np.float64), noise)
            from autoteach.geometry import WaferRobot
            from autoteach.sim.odometry import integrate_odometry

            robot = WaferRobot(params=params, base=base_w)
            encoder_poses = np.asarray(robot.camera_pose(enc), dtype=np.float64)
            ukf_out = {
                "poses": np.asarray(run["poses"]),
                "offsets": np.asarray(run["offsets"]),
                "offset_std": np.asarray(run["offset_std"]),
                "encoder_poses": encoder_poses,
                "odometry_poses": integrate_odometry(encoder_poses[0], increments),
            }
            if session.calibration is not None:
                true = np.asarray(session.calibration.joint_offsets)[[0, 1, 3]]
                err = np.abs(ukf_out["offsets"][-1] - true)
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
    common = dict(
        encoder_sigma=tuple(encoder_sigma) if encoder_sigma else None,
        pixel_sigma=sigma,
        estimate_offsets=est_idx,
        reference_wafer=int(ref),
        huber=huber,
        max_iterations=int(max_iterations),
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
    sol = _core.handeye_slam_mot(
        *args,
        factor="conic",
        window=int(window),
        init_heights=(-0.02, max(z_top, 0.05), 0.001),
        **common,
    )
    timings["slam_mot_s"] = time.perf_counter() - t0
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
    status: dict[str, str] = {}
    joint_offsets = np.full(5, np.nan)
    for j, name in enumerate(JOINTS):
        if j in est_idx:
            status[name] = "estimated"
            joint_offsets[j] = offsets_hat[j]
        elif ukf_out is not None and j in (0, 1, 3):
            status[name] = "ukf"
            joint_offsets[j] = ukf_out["offsets"][-1][(0, 1, 3).index(j)]
            offsets_std[j] = ukf_out["offset_std"][-1][(0, 1, 3).index(j)]
        else:
            status[name] = "unobservable: " + UNOBSERVABLE_REASONS.get(name, "not estimated")
    unobserved = [w for w in range(obs.n_wafers) if w not in seen]
    wafers_hat[unobserved] = np.nan

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
        observations={"frames": obs.frames, "wafers": obs.wafers, "start": obs.start, "points": obs.points},
    )
    timings["resolution_s"] = time.perf_counter() - t0

    if baseline:
        t0 = time.perf_counter()
        base_sol = _core.handeye_slam_mot(
            *args, factor="point", window=0, init_heights=(-0.02, max(z_top, 0.05), 0.001), **common
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
                session, ref, b["base_pose"], b["joint_offsets"], b["wafers"], est_idx, seen
            )[0]
        result.baseline = b
        timings["baseline_s"] = b["runtime_s"]
    stages.update()
    stages.close()

    if session.has_ground_truth and session.calibration is not None:
        errs, sig = ground_truth_errors(
            session, ref, base_hat, offsets_hat, wafers_hat, est_idx, seen, base_std, offsets_std, wafer_std
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
) -> tuple[dict[str, float], dict[str, bool]]:
    """Absolute errors of the estimates against a simulated session's ground truth.

    The truth is moved into the true reference-wafer frame; the effective base is
    ``T_wb·Rz(−δ1)·Tz(−δh)``; the estimate's yaw gauge is aligned to the truth by a rotation about
    the reference normal. Returns the errors (``joint_offset_deg`` max over the estimated
    joints, ``base_translation_mm``, ``base_rotation_deg``, ``wafer_center_mm`` and
    ``wafer_tilt_deg`` max over the wafers) and, when standard deviations are given, whether each
    group's every component lies within 3σ.
    """
    cal = session.calibration
    t_ref = np.asarray(session.wafer_poses[ref], dtype=np.float64)
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
        if w == ref:
            continue
        wt = t_ref_inv @ np.asarray(session.wafer_poses[w], dtype=np.float64)
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
