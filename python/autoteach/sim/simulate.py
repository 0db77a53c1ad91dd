"""Simulation of one robot session: scene, trajectory, encoder readings, images and ground truth."""

from __future__ import annotations

import math
import operator
import time
from typing import Any

import numpy as np

from autoteach import _core
from autoteach.errors import InvalidInputError, UnreachablePoseError
from autoteach.geometry import WaferRobot
from autoteach.session import JOINT_NAMES, Calibration, CameraInfo, Session
from autoteach.sim.config import SimConfig
from autoteach.sim.trajectory import BSpline, sweep_waypoints, unwrap_to

#: Slots and pitch of the carrier drawn by the renderer (``autoteach_geometry::render::Carrier``).
RENDERED_CARRIER_SLOTS = 26
RENDERED_CARRIER_PITCH = 0.010

# Independent random streams (numpy SeedSequence children), so that e.g. the wafer placement of
# a seed does not change when the number of frames or the trajectory settings change.
_STREAMS = ("placement", "offsets", "trajectory", "encoder", "lighting", "render")


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def wafer_poses(config: SimConfig, rng: np.random.Generator | None = None) -> np.ndarray:
    """Return the true wafer poses ``T_w,wafer`` (N, 4, 4) in the order of ``config.slots``.

    Wafer ``i`` sits at the nominal slot height, rotated by ``Ry(ry)·Rx(rx)`` about its centre
    (the configured tilt plus the random placement jitter) and displaced by the configured shift
    plus the random in-plane jitter. Without ``rng`` the jitter is zero.
    """
    poses = np.zeros((len(config.slots), 4, 4))
    for i, slot in enumerate(config.slots):
        rx, ry = config.tilts.get(slot, (0.0, 0.0))
        dx, dy, dz = config.shifts.get(slot, (0.0, 0.0, 0.0))
        if rng is not None:
            jt = rng.normal(0.0, config.placement_tilt_sigma, 2)
            js = rng.normal(0.0, config.placement_shift_sigma, 2)
            rx, ry, dx, dy = rx + jt[0], ry + jt[1], dx + js[0], dy + js[1]
        poses[i, :3, :3] = _rot_y(ry) @ _rot_x(rx)
        poses[i, :3, 3] = (dx, dy, config.slot_height(slot) + dz)
        poses[i, 3, 3] = 1.0
    return poses


def draw_joint_offsets(config: SimConfig, rng: np.random.Generator) -> np.ndarray:
    """Return the true encoder zero offsets (5,).

    The configured ones, or magnitudes uniform in ``offset_range_deg`` with random signs on θ1..θ4
    and a zero lift offset.
    """
    if config.joint_offsets is not None:
        return np.array(config.joint_offsets, dtype=np.float64)
    lo, hi = config.offset_range_deg
    mags = np.radians(rng.uniform(lo, hi, 4))
    signs = rng.choice([-1.0, 1.0], 4)
    return np.concatenate([mags * signs, [0.0]])


def camera_target_pose(robot: WaferRobot, x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """Return the reachable camera pose ``T_wc`` with centre ``(x, y, z)`` and world yaw ``yaw``.

    Reachable camera orientations are ``R_wb·Rz(ψ)·R_b0`` (all robot joints turn about the base z
    axis; ``R_b0`` is the camera orientation in the base at blade-2 yaw 0, eq. (2.2)), so the
    target is built from the camera pose at zero joints, turned about the base z axis by the yaw
    relative to the base, and moved to the requested centre.
    """
    base = np.asarray(robot.base, dtype=np.float64)
    ref = np.asarray(robot.camera_pose(np.zeros(5)), dtype=np.float64)
    base_yaw = math.atan2(base[1, 0], base[0, 0])
    r_wb = base[:3, :3]
    t = np.eye(4)
    t[:3, :3] = r_wb @ _rot_z(yaw - base_yaw) @ r_wb.T @ ref[:3, :3]
    t[:3, 3] = (x, y, z)
    return t


def plan_joint_waypoints(robot: WaferRobot, waypoints: np.ndarray, elbow: int = 1) -> np.ndarray:
    """Joint waypoints (n, 5) for camera waypoints ``(x, y, z, yaw)`` (n, 4).

    Each camera pose is solved by ``inverse_kinematics_camera``; the first waypoint takes the
    solution whose elbow angle θ2 has the sign ``elbow``, later ones the solution nearest to the
    previous waypoint (angles unwrapped to it) so that the interpolated trajectory is continuous.
    Blade 1 points opposite to blade 2 (θ3 = θ4 − π). Raises :class:`UnreachablePoseError` if a
    waypoint is out of reach.
    """
    out = np.zeros((len(waypoints), 5))
    prev: np.ndarray | None = None
    for i, (x, y, z, yaw) in enumerate(waypoints):
        t_wc = camera_target_pose(robot, x, y, z, yaw)
        try:
            sols = np.atleast_2d(np.asarray(robot.inverse_kinematics_camera(t_wc, theta3=0.0), dtype=np.float64))
        except UnreachablePoseError as exc:
            raise UnreachablePoseError(
                f"camera waypoint {i} (x={x:.3f}, y={y:.3f}, z={z:.3f} m, yaw={math.degrees(yaw):.2f}°) is out of "
                f"the robot's reach from the base pose; move the base or the waypoint ranges: {exc}"
            ) from exc
        if sols.shape[0] == 0:
            raise UnreachablePoseError(f"camera waypoint {i} (x={x:.3f}, y={y:.3f}, z={z:.3f} m) has no IK solution")
        if prev is None:
            pick = [s for s in sols if np.sign(s[1]) == elbow] or list(sols)
            q = pick[0].copy()
        else:
            cands = sols.copy()
            cands[:, :4] = unwrap_to(cands[:, :4], prev[None, :4])
            q = cands[int(np.argmin(np.linalg.norm(cands - prev, axis=1)))].copy()
        q[2] = unwrap_to(q[3] - math.pi, 0.0 if prev is None else prev[2])
        out[i] = q
        prev = q
    return out


#: At most this many frames per session: the images are held in memory (0.9 MB per 1280×720 frame).
MAX_FRAMES = 1_000_000


def _check_count(value: Any, name: str, minimum: int, maximum: int | None = None) -> int:
    try:
        n = operator.index(value)
    except TypeError:
        raise InvalidInputError(f"{name} must be an integer, got {type(value).__name__}") from None
    if n < minimum or (maximum is not None and n > maximum):
        shown = str(n) if len(str(n)) <= 24 else f"a {len(str(n))}-digit number"
        bound = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        raise InvalidInputError(f"{name} must be {bound}, got {shown}")
    return n


def simulate_session(
    seed: int = 0,
    frames: int = 200,
    config: SimConfig | None = None,
    progress: bool = False,
    render: bool = True,
) -> Session:
    """Simulate one session of the wafer-handling robot looking into the carrier.

    Deterministic for a given ``(seed, frames, config)``. Builds the scene (wafer poses with the
    configured tilts, shifts and placement jitter), the true calibration (base pose, joint zero
    offsets, robot parameters, camera), a smooth joint trajectory (camera waypoints → inverse
    kinematics → clamped cubic B-spline, 000_3b1454b2b2194811.txt ch. 2.4), encoder readings
    ``q_enc = q_true + δ + noise``, one rendered image per frame (the Rust renderer
    ``autoteach._core.render_frame``) and the visible part of every rim ellipse per frame
    (``autoteach._core.rim_visibility``).

    Args:
        seed: non-negative integer seed.
        frames: number of frames (>= 1).
        config: scene and noise settings; ``None`` for the default :class:`SimConfig`.
        progress: show a progress bar on stderr while rendering.
        render: render the images; with ``False`` the images are all zero (everything else,
            including the visible-rim ground truth, is computed as usual), for fast tests of
            the estimation stages.

    Raises:
        InvalidInputError: bad seed, frame count or configuration.
        UnreachablePoseError: a camera waypoint is out of the robot's reach.

    """
    seed = _check_count(seed, "seed", 0)
    frames = _check_count(frames, "frames", 1, MAX_FRAMES)
    config = _check_config(config)
    children = np.random.SeedSequence(seed).spawn(len(_STREAMS))
    rngs = {name: np.random.default_rng(child) for name, child in zip(_STREAMS, children, strict=True)}
    timings: dict[str, float] = {}
    t_start = time.perf_counter()

    # Scene and true calibration.
    poses = wafer_poses(config, rngs["placement"])
    offsets = draw_joint_offsets(config, rngs["offsets"])
    robot = WaferRobot(params=config.robot, base=config.base_pose_matrix)
    camera = CameraInfo(config.camera_model, config.camera_params, config.width, config.height)

    joints_true, timestamps = _joint_trajectory(config, robot, rngs["trajectory"], frames)
    joints_encoder = (
        joints_true + offsets + rngs["encoder"].normal(0.0, 1.0, (frames, 5)) * np.array(config.encoder_noise)
    )
    camera_poses = np.ascontiguousarray(np.asarray(robot.camera_pose(joints_true), dtype=np.float64))
    timings["plan_s"] = time.perf_counter() - t_start

    images, rims = _images_and_rims(config, poses, camera_poses, timestamps, rngs, render, progress, timings)
    timings["total_s"] = time.perf_counter() - t_start

    calibration = Calibration(
        base_pose=config.base_pose_matrix,
        joint_offsets=offsets,
        camera_mount=np.asarray(robot.camera_mount(), dtype=np.float64),
        robot_params=config.robot,
        camera=camera,
    )
    return Session(
        timestamps=timestamps,
        joints_encoder=joints_encoder,
        images=images,
        camera=camera,
        joint_names=JOINT_NAMES,
        frame_rate_hz=config.frame_rate_hz,
        seed=seed,
        config=config,
        joints_true=joints_true,
        camera_poses=camera_poses,
        wafer_poses=poses,
        wafer_slots=np.array(config.slots, dtype=np.int64),
        calibration=calibration,
        rims=rims,
        timings=timings,
    )


def _check_config(config: SimConfig | None) -> SimConfig:
    """The configuration (default :class:`SimConfig`), checked against the rendered carrier."""
    if config is None:
        return SimConfig()
    if not isinstance(config, SimConfig):
        raise InvalidInputError(f"config must be a SimConfig, got {type(config).__name__}")
    if config.carrier and (config.n_slots, config.slot_pitch) != (RENDERED_CARRIER_SLOTS, RENDERED_CARRIER_PITCH):
        raise InvalidInputError(
            f"the rendered carrier has {RENDERED_CARRIER_SLOTS} slots at {RENDERED_CARRIER_PITCH * 1e3:g} mm pitch, "
            f"but the config asks for {config.n_slots} slots at {config.slot_pitch * 1e3:g} mm; set carrier=False "
            "to simulate other layouts without the carrier"
        )
    return config


def _joint_trajectory(
    config: SimConfig, robot: WaferRobot, rng: np.random.Generator, frames: int
) -> tuple[np.ndarray, np.ndarray]:
    """True joints and timestamps per frame: camera waypoints → IK → clamped cubic B-spline (ch. 2.4)."""
    traj = config.trajectory
    if traj.waypoints:
        waypoints = np.array(traj.waypoints, dtype=np.float64)
    else:
        heights = [config.slot_height(s) for s in config.slots]
        z_range = traj.z_range if traj.z_range is not None else (min(heights) + 0.03, max(heights) + 0.05)
        waypoints = sweep_waypoints(
            rng, traj.n_waypoints, traj.x_range, traj.y_range, z_range, traj.yaw_max, traj.sweeps
        )
    q_way = plan_joint_waypoints(robot, waypoints, traj.elbow)
    spline = BSpline(q_way, 0.0, 1.0, degree=3)
    u = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
    joints_true = np.ascontiguousarray(spline(u))
    period_ns = 1e9 / config.frame_rate_hz
    timestamps = config.start_time_ns + np.round(np.arange(frames) * period_ns).astype(np.int64)
    if frames > 1 and np.any(np.diff(timestamps) <= 0):
        raise InvalidInputError(f"frame_rate_hz={config.frame_rate_hz} is too high for nanosecond timestamps")
    return joints_true, timestamps


def _images_and_rims(
    config: SimConfig,
    poses: np.ndarray,
    camera_poses: np.ndarray,
    timestamps: np.ndarray,
    rngs: dict[str, np.random.Generator],
    render: bool,
    progress: bool,
    timings: dict[str, float],
) -> tuple[np.ndarray, list[list[dict[str, Any]]]]:
    """The rendered image (zeros without ``render``) and the visible rims of every frame."""
    from tqdm import tqdm

    frames = len(timestamps)
    gains, gradients = config.lighting.schedule((timestamps - timestamps[0]) * 1e-9, rngs["lighting"])
    render_seeds = rngs["render"].integers(0, 2**63 - 1, frames, dtype=np.int64)
    images = (np.empty if render else np.zeros)((frames, config.height, config.width), dtype=np.uint8)
    rims: list[list[dict[str, Any]]] = []
    params = np.asarray(config.camera_params, dtype=np.float64)
    slots = np.array(config.slots, dtype=np.int64)
    scene_kwargs = {
        "wafer_radius": config.wafer_radius,
        "wafer_thickness": config.wafer_thickness,
        "carrier": config.carrier,
    }

    def frame_args(i: int) -> tuple[Any, ...]:
        """Positional arguments (scene, camera, pose) of the per-frame compiled calls."""
        return (poses, config.camera_model, params, config.width, config.height, camera_poses[i])

    t_render = t_vis = 0.0
    for i in tqdm(range(frames), desc="rendering", unit="frame", disable=not progress, leave=False):
        t0 = time.perf_counter()
        if render:
            images[i] = _core.render_frame(
                *frame_args(i),
                **scene_kwargs,
                gain=float(gains[i]),
                gradient=(float(gradients[i, 0]), float(gradients[i, 1])),
                blur_sigma=config.blur_sigma,
                noise_sigma=config.noise_sigma,
                supersample=config.supersample,
                seed=int(render_seeds[i]),
            )
        t1 = time.perf_counter()
        vis = _core.rim_visibility(
            *frame_args(i),
            **scene_kwargs,
            n_samples=config.n_rim_samples,
        )
        rims.append([_normalise_rim(r, slots) for r in vis])
        t_render += t1 - t0
        t_vis += time.perf_counter() - t1
    timings["render_s"] = t_render
    timings["rim_visibility_s"] = t_vis
    return images, rims


def _normalise_rim(r: dict[str, Any], slots: np.ndarray) -> dict[str, Any]:
    """One visible-rim record with the session's key set and float64 arrays."""
    ell = r.get("ellipse")
    return {
        "wafer": int(r["wafer"]),
        "slot": int(slots[int(r["wafer"])]),
        "rim": str(r["rim"]),
        "ellipse": None if ell is None else np.asarray(ell, dtype=np.float64).reshape(5),
        "intervals": np.asarray(r["intervals"], dtype=np.float64).reshape(-1, 2),
        "fraction": float(r["fraction"]),
        "points": np.asarray(r["points"], dtype=np.float64).reshape(-1, 2),
        "angles": np.asarray(r["angles"], dtype=np.float64).reshape(-1),
        "side_facing": np.asarray(r["side_facing"], dtype=np.bool_).reshape(-1),
    }
