"""The :class:`Session`: one recorded (or simulated) robot run with its optional ground truth.

A session is what every later stage consumes: timestamps, encoder readings and grayscale images,
one per frame, plus the camera intrinsics. Simulated sessions also carry the ground truth: the true
joints, camera poses, wafer poses, calibration parameters and the visible part of every rim ellipse
in every image. Sessions read from logs of a real robot have ``None`` in every ground-truth field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from autoteach.errors import InvalidInputError

if TYPE_CHECKING:
    from autoteach.geometry import Camera, RobotParams
    from autoteach.io import LogDamage
    from autoteach.sim.config import SimConfig

#: Names of the five joints, in the order of the joint vector ``q = (θ1, θ2, θ3, θ4, h)``.
JOINT_NAMES: tuple[str, ...] = ("joint1", "joint2", "joint3", "joint4", "lift")

#: Keys of one visible-rim record (see :attr:`Session.rims`).
RIM_KEYS: tuple[str, ...] = (
    "wafer",
    "slot",
    "rim",
    "ellipse",
    "intervals",
    "fraction",
    "points",
    "angles",
    "side_facing",
)


@dataclass(frozen=True)
class CameraInfo:
    """Camera model name, its parameter vector and the image size in pixels."""

    model: str
    params: tuple[float, ...]
    width: int
    height: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", tuple(float(p) for p in self.params))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        if not isinstance(self.model, str) or not self.model:
            raise InvalidInputError(f"camera model must be a non-empty string, got {self.model!r}")
        if not all(math.isfinite(p) for p in self.params):
            raise InvalidInputError(f"camera params must be finite, got {self.params}")
        if self.width <= 0 or self.height <= 0:
            raise InvalidInputError(f"image size must be positive, got {self.width}x{self.height}")

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-compatible dict (floats round-trip exactly through :mod:`json`)."""
        return {"model": self.model, "params": list(self.params), "width": self.width, "height": self.height}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CameraInfo:
        """Inverse of :meth:`to_dict`."""
        return cls(model=d["model"], params=tuple(d["params"]), width=d["width"], height=d["height"])

    def to_camera(self) -> Camera:
        """Return the :class:`autoteach.geometry.Camera` with these intrinsics."""
        from autoteach.geometry import Camera

        return Camera(self.model, np.asarray(self.params, dtype=np.float64), self.width, self.height)


@dataclass(eq=False)
class Calibration:
    """The true calibration parameters of a simulated session (what auto-teaching estimates).

    Attributes:
        base_pose: ``T_wb`` (4, 4), robot base in the world (carrier) frame.
        joint_offsets: (5,) encoder zero offsets ``δ``; encoders read ``q_enc = q_true + δ``.
        camera_mount: ``T_e2c`` (4, 4), camera in the blade-2 frame (follows from ``robot_params``).
        robot_params: the true geometric parameters of the robot.
        camera: the true camera intrinsics.

    """

    base_pose: np.ndarray
    joint_offsets: np.ndarray
    camera_mount: np.ndarray
    robot_params: RobotParams
    camera: CameraInfo

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-compatible dict (floats round-trip exactly through :mod:`json`)."""
        return {
            "base_pose": np.asarray(self.base_pose, dtype=np.float64).tolist(),
            "joint_offsets": np.asarray(self.joint_offsets, dtype=np.float64).tolist(),
            "camera_mount": np.asarray(self.camera_mount, dtype=np.float64).tolist(),
            "robot_params": self.robot_params.to_dict(),
            "camera": self.camera.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Calibration:
        """Inverse of :meth:`to_dict`."""
        from autoteach.geometry import RobotParams

        return cls(
            base_pose=np.asarray(d["base_pose"], dtype=np.float64).reshape(4, 4),
            joint_offsets=np.asarray(d["joint_offsets"], dtype=np.float64).reshape(5),
            camera_mount=np.asarray(d["camera_mount"], dtype=np.float64).reshape(4, 4),
            robot_params=RobotParams.from_dict(d["robot_params"]),
            camera=CameraInfo.from_dict(d["camera"]),
        )


@dataclass(eq=False)
class Session:
    """One robot run: per-frame timestamps, encoder readings and images, and optional ground truth.

    Attributes:
        timestamps: (F,) int64, nanoseconds.
        joints_encoder: (F, 5) float64 encoder readings ``q_enc = q_true + δ + noise``.
        images: (F, H, W) uint8 grayscale images.
        camera: intrinsics of the camera that took the images.
        joint_names: names of the five joints.
        frame_rate_hz: nominal frame rate (``None`` if unknown).
        seed: simulation seed (``None`` for real logs).
        config: the :class:`~autoteach.sim.SimConfig` that produced the session (``None`` for real logs).
        joints_true: (F, 5) true joint values (ground truth).
        camera_poses: (F, 4, 4) true ``T_wc`` per frame (ground truth).
        wafer_poses: (N, 4, 4) true ``T_w,wafer`` (ground truth).
        wafer_slots: (N,) int64 carrier slot (1-based) of each wafer (ground truth).
        calibration: true calibration parameters (ground truth).
        rims: per frame, a list of visible rim records (ground truth), each a dict with keys
            ``wafer`` (index into ``wafer_poses``), ``slot``, ``rim`` (``"upper"``/``"lower"``),
            ``ellipse`` ((5,) ``cx, cy, a, b, theta`` of the full projected rim, or ``None``),
            ``intervals`` ((k, 2) visible arcs as rim-angle intervals), ``fraction`` (visible part
            of the rim in [0, 1]), ``points`` ((m, 2) pixel positions of the visible rim samples),
            ``angles`` ((m,) their circle angles in the wafer frame) and ``side_facing`` ((m,) bool:
            whether the wafer's bright side face faces the camera there; elsewhere the rim shows
            only as the low-contrast silhouette of the dark top/bottom face).
        timings: wall-clock seconds of the simulation stages (not stored in logs).
        source: the file the session was read from, if any.
        damage: for a damaged log read with ``allow_truncated=True``, the byte ranges skipped and the
            frames lost (:class:`autoteach.io.LogDamage`); ``None`` for a complete read.

    """

    timestamps: np.ndarray
    joints_encoder: np.ndarray
    images: np.ndarray
    camera: CameraInfo
    joint_names: tuple[str, ...] = JOINT_NAMES
    frame_rate_hz: float | None = None
    seed: int | None = None
    config: SimConfig | None = None
    joints_true: np.ndarray | None = None
    camera_poses: np.ndarray | None = None
    wafer_poses: np.ndarray | None = None
    wafer_slots: np.ndarray | None = None
    calibration: Calibration | None = None
    rims: list[list[dict[str, Any]]] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    source: str | None = None
    damage: LogDamage | None = None

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check shapes and dtypes of every field; raise :class:`InvalidInputError` if inconsistent."""
        ts = np.asarray(self.timestamps)
        if ts.ndim != 1 or ts.dtype.kind not in "iu":
            raise InvalidInputError(f"timestamps must be a 1-D integer array, got {ts.dtype} {ts.shape}")
        n = ts.shape[0]
        if n > 1 and np.any(np.diff(ts.astype(np.int64)) <= 0):
            raise InvalidInputError("timestamps must be strictly increasing")
        self.timestamps = ts.astype(np.int64, copy=False)
        _check_array("joints_encoder", self.joints_encoder, (n, len(self.joint_names)), np.float64)
        _check_array("images", self.images, (n, self.camera.height, self.camera.width), np.uint8)
        if self.joints_true is not None:
            _check_array("joints_true", self.joints_true, (n, len(self.joint_names)), np.float64)
        if self.camera_poses is not None:
            _check_array("camera_poses", self.camera_poses, (n, 4, 4), np.float64)
        if self.wafer_poses is not None:
            _check_array("wafer_poses", self.wafer_poses, (None, 4, 4), np.float64)
            if self.wafer_slots is None or np.asarray(self.wafer_slots).shape != (self.wafer_poses.shape[0],):
                raise InvalidInputError("wafer_slots must give one slot per wafer pose")
        if self.rims is not None and len(self.rims) != n:
            raise InvalidInputError(f"rims must have one list per frame ({n}), got {len(self.rims)}")
        rate = self.frame_rate_hz
        if rate is not None:
            ok = isinstance(rate, (int, float, np.integer, np.floating)) and not isinstance(rate, (bool, np.bool_))
            if not ok or not (math.isfinite(float(rate)) and float(rate) > 0.0):
                raise InvalidInputError(f"frame_rate_hz must be a positive finite number or None, got {rate!r}")

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.timestamps.shape[0])

    @property
    def has_ground_truth(self) -> bool:
        """Whether the session carries ground truth (simulated sessions do, real logs do not)."""
        return self.camera_poses is not None

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame, in seconds."""
        return float(self.timestamps[-1] - self.timestamps[0]) * 1e-9 if self.n_frames > 1 else 0.0

    def wafer_visibility(self) -> list[dict[str, Any]]:
        """Per-wafer statistics of the ground-truth rim visibility.

        Returns one dict per wafer with its ``slot``, the number of frames in which any part of
        its rims is visible (``frames_visible``), and the mean visible fraction of the upper and
        the lower rim over those frames. Empty if the session has no ground truth.
        """
        if self.rims is None or self.wafer_slots is None:
            return []
        stats = []
        for w, slot in enumerate(np.asarray(self.wafer_slots).tolist()):
            frames = 0
            fractions: dict[str, list[float]] = {"upper": [], "lower": []}
            for frame in self.rims:
                seen = False
                for rim in frame:
                    if rim["wafer"] == w and rim["fraction"] > 0.0:
                        seen = True
                        fractions[rim["rim"]].append(float(rim["fraction"]))
                frames += seen
            stats.append(
                {
                    "wafer": w,
                    "slot": int(slot),
                    "frames_visible": frames,
                    "mean_fraction_upper": float(np.mean(fractions["upper"])) if fractions["upper"] else 0.0,
                    "mean_fraction_lower": float(np.mean(fractions["lower"])) if fractions["lower"] else 0.0,
                }
            )
        return stats

    def summary(self) -> dict[str, Any]:
        """Return a JSON-compatible summary: size, camera, calibration and visibility (what the CLI prints)."""
        out: dict[str, Any] = {
            "frames": self.n_frames,
            "duration_s": self.duration_s,
            "frame_rate_hz": self.frame_rate_hz,
            "image_size": [self.camera.width, self.camera.height],
            "camera": self.camera.to_dict(),
            "seed": self.seed,
            "ground_truth": self.has_ground_truth,
        }
        if self.source is not None:
            out["source"] = self.source
        if self.wafer_slots is not None:
            out["wafers"] = len(self.wafer_slots)
            out["slots"] = [int(s) for s in self.wafer_slots]
        if self.wafer_poses is not None:
            normals = self.wafer_poses[:, :3, 2]
            out["wafer_tilt_deg"] = [float(np.degrees(np.arccos(np.clip(n[2], -1.0, 1.0)))) for n in normals]
        if self.calibration is not None:
            cal = self.calibration
            out["calibration"] = {
                "joint_offsets_deg": [float(np.degrees(v)) for v in cal.joint_offsets[:4]],
                "lift_offset_m": float(cal.joint_offsets[4]),
                "base_position_m": cal.base_pose[:3, 3].tolist(),
                "base_rpy_deg": (np.degrees(_rpy(cal.base_pose[:3, :3])) + 0.0).tolist(),  # + 0.0: no "-0.000"
                "robot_params": cal.robot_params.to_dict(),
            }
        if self.rims is not None:
            out["visibility"] = self.wafer_visibility()
        if self.timings:
            out["timings_s"] = dict(self.timings)
        return out


def _rpy(r: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (radians) of ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``."""
    pitch = math.asin(max(-1.0, min(1.0, -float(r[2, 0]))))
    roll = math.atan2(float(r[2, 1]), float(r[2, 2]))
    yaw = math.atan2(float(r[1, 0]), float(r[0, 0]))
    return np.array([roll, pitch, yaw])


def _check_array(name: str, a: Any, shape: tuple[int | None, ...], dtype: type) -> None:
    arr = np.asarray(a)
    if arr.dtype != dtype:
        raise InvalidInputError(f"{name} must have dtype {np.dtype(dtype).name}, got {arr.dtype}")
    if arr.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, arr.shape, strict=True)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InvalidInputError(f"{name} must have shape {want}, got {arr.shape}")
