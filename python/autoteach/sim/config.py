"""Configuration of the simulated robot session (everything except the seed).

The scene follows 000_3b1454b2b2194811.txt ch. 3.5 and ch. 5.5: a carrier with 26 slots at a
machined pitch of 10 mm, slots numbered 1..26 from the bottom; twelve 300 mm wafers in the slots
of Table 5.1, the topmost one tilted on purpose; the wafer-handling robot of ch. 2.2 standing in
front of the carrier opening with the camera on blade 2.

World frame = carrier frame: the nominal centre of the wafer in slot ``k`` is
``(0, 0, (k − 1) · pitch)``, z up, the carrier opening facing −x where the robot stands.

Everything that varies between later experiments is a field here: occupied slots, per-wafer
tilt and shift, random placement jitter, joint zero offsets, encoder and image noise, a lighting
schedule and the camera trajectory. Use :func:`dataclasses.replace` to derive variants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError
from autoteach.geometry import Camera, RobotParams

#: The occupied slots of 000_3b1454b2b2194811.txt Table 5.1 (twelve wafers).
DEFAULT_SLOTS: tuple[int, ...] = (4, 7, 10, 13, 15, 17, 19, 21, 22, 23, 24, 25)


def _yaw_pose(x: float, y: float, z: float, yaw: float) -> tuple[tuple[float, ...], ...]:
    c, s = math.cos(yaw), math.sin(yaw)
    return ((c, -s, 0.0, x), (s, c, 0.0, y), (0.0, 0.0, 1.0, z), (0.0, 0.0, 0.0, 1.0))


#: Default robot base pose ``T_wb``: 1 m in front of the carrier, the shoulder axis 0.45 m below
#: the carrier's slot 1, slightly off-centre and yawed by 1.5°, so that the blade-2 camera looks
#: into the carrier from 0.3–0.5 m with the elbow comfortably bent.
DEFAULT_BASE_POSE: tuple[tuple[float, ...], ...] = _yaw_pose(-1.0, 0.03, -0.45, math.radians(1.5))


def _floats(values: Any, n: int | None, name: str) -> tuple[float, ...]:
    try:
        arr = np.asarray(values)
        # Real numbers only: a cast would drop imaginary parts and read booleans as 0 and 1.
        if arr.dtype.kind not in "iuf":
            raise TypeError(f"dtype {arr.dtype}")
        out = tuple(float(v) for v in arr.astype(np.float64).reshape(-1))
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a sequence of real numbers, got {values!r}") from exc
    if n is not None and len(out) != n:
        raise InvalidInputError(f"{name} must have {n} values, got {len(out)}")
    if not all(math.isfinite(v) for v in out):
        raise InvalidInputError(f"{name} must be finite, got {out}")
    return out


def _range(values: Any, name: str, positive: bool = False) -> tuple[float, float]:
    lo, hi = _floats(values, 2, name)
    if lo > hi:
        raise InvalidInputError(f"{name} must be (low, high) with low <= high, got ({lo}, {hi})")
    if positive and lo <= 0.0:
        raise InvalidInputError(f"{name} must be positive, got ({lo}, {hi})")
    return lo, hi


def _nonneg(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v) or v < 0.0:
        raise InvalidInputError(f"{name} must be finite and >= 0, got {value!r}")
    return v


@dataclass(frozen=True)
class Lighting:
    """Lighting schedule: image gain and a linear brightness gradient over time.

    Without ``keyframes`` the gain and the gradient vary smoothly (sums of two sinusoids with
    random phases per seed, main period ``period_s``) inside ``gain_range`` and
    ``[−gradient_max, gradient_max]``; ``gain_range=(1, 1), gradient_max=0`` gives constant light.
    With ``keyframes`` ``((t_s, gain, gx, gy), ...)`` the values are interpolated linearly in time
    (held constant outside), for scripted lighting changes.
    """

    gain_range: tuple[float, float] = (0.8, 1.2)
    gradient_max: float = 0.2
    period_s: float = 12.0
    keyframes: tuple[tuple[float, float, float, float], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain_range", _range(self.gain_range, "lighting.gain_range", positive=True))
        object.__setattr__(self, "gradient_max", _nonneg(self.gradient_max, "lighting.gradient_max"))
        period = float(self.period_s)
        if not math.isfinite(period) or period <= 0.0:
            raise InvalidInputError(f"lighting.period_s must be positive, got {self.period_s!r}")
        object.__setattr__(self, "period_s", period)
        keys = tuple(_floats(k, 4, "lighting keyframe") for k in self.keyframes)
        if any(k[1] <= 0.0 for k in keys):
            raise InvalidInputError("lighting keyframe gains must be positive")
        if any(b[0] <= a[0] for a, b in zip(keys, keys[1:], strict=False)):
            raise InvalidInputError("lighting keyframe times must be strictly increasing")
        object.__setattr__(self, "keyframes", keys)

    def schedule(self, times_s: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Gain (F,) and gradient (F, 2) at the given times (seconds from the session start)."""
        t = np.asarray(times_s, dtype=np.float64)
        if self.keyframes:
            k = np.asarray(self.keyframes)
            cols = [np.interp(t, k[:, 0], k[:, j]) for j in (1, 2, 3)]
            return cols[0], np.stack(cols[1:], axis=1)
        phases = rng.uniform(0.0, 2.0 * np.pi, (3, 2))

        def wave(ph: np.ndarray) -> np.ndarray:
            w = 2.0 * np.pi * t / self.period_s
            return (np.sin(w + ph[0]) + 0.5 * np.sin(2.3 * w + ph[1])) / 1.5  # in [-1, 1]

        lo, hi = self.gain_range
        gain = 0.5 * (lo + hi) + 0.5 * (hi - lo) * wave(phases[0])
        gradient = self.gradient_max * np.stack([wave(phases[1]), wave(phases[2])], axis=1)
        return gain, gradient


@dataclass(frozen=True)
class TrajectoryConfig:
    """Camera trajectory in front of the carrier.

    Waypoints ``(x, y, z, yaw)`` of the camera centre (world frame, metres) and its yaw (radians,
    0 = looking along +x into the carrier) are drawn per seed: ``x``, ``y``, ``yaw`` uniformly in
    their ranges and ``z`` on a triangle wave that sweeps ``z_range`` ``sweeps`` times (``None``:
    from 3 cm above the lowest to 5 cm above the highest occupied slot). Each waypoint is
    converted to joints by inverse kinematics (the solution continuous with the previous one) and
    the joints are interpolated by a clamped cubic B-spline over the session's duration.
    Explicit ``waypoints`` replace the random ones; a single waypoint gives a static camera.
    """

    x_range: tuple[float, float] = (-0.55, -0.40)
    y_range: tuple[float, float] = (-0.08, 0.08)
    z_range: tuple[float, float] | None = None
    yaw_max: float = math.radians(5.0)
    n_waypoints: int = 8
    sweeps: float = 2.0
    waypoints: tuple[tuple[float, float, float, float], ...] = ()
    elbow: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_range", _range(self.x_range, "trajectory.x_range"))
        object.__setattr__(self, "y_range", _range(self.y_range, "trajectory.y_range"))
        if self.z_range is not None:
            object.__setattr__(self, "z_range", _range(self.z_range, "trajectory.z_range"))
        object.__setattr__(self, "yaw_max", _nonneg(self.yaw_max, "trajectory.yaw_max"))
        object.__setattr__(self, "sweeps", _nonneg(self.sweeps, "trajectory.sweeps"))
        if int(self.n_waypoints) != self.n_waypoints or self.n_waypoints < 1:
            raise InvalidInputError(f"trajectory.n_waypoints must be an integer >= 1, got {self.n_waypoints!r}")
        object.__setattr__(self, "n_waypoints", int(self.n_waypoints))
        object.__setattr__(self, "waypoints", tuple(_floats(w, 4, "trajectory waypoint") for w in self.waypoints))
        if self.elbow not in (1, -1):
            raise InvalidInputError(f"trajectory.elbow must be +1 or -1 (sign of θ2), got {self.elbow!r}")


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a simulated session except the seed and the number of frames.

    Attributes:
        n_slots, slot_pitch: carrier slots (numbered 1..n_slots from the bottom) and their pitch (m).
        wafer_radius, wafer_thickness: wafer size (m); each wafer shows an upper and a lower rim.
        slots: occupied slots, one wafer each.
        tilts: ``{slot: (rx, ry)}`` deliberate wafer tilt about the world x and y axes (rad);
            ``None`` tilts the wafer in slot 25 by 1° about y (like wafer 12 of Table 5.1) if that
            slot is occupied.
        shifts: ``{slot: (dx, dy, dz)}`` deliberate wafer displacement (m).
        placement_tilt_sigma, placement_shift_sigma: std of the random per-seed placement jitter
            (tilt about x and y in rad; shift in x and y in m) added to every wafer.
        camera_model, camera_params, width, height: the camera (``"pinhole"``: fx, fy, cx, cy).
        robot: true geometric parameters of the robot.
        base_pose: true ``T_wb`` (4×4 nested tuples).
        joint_offsets: true encoder zero offsets (5,) or ``None`` to draw them per seed:
            magnitudes uniform in ``offset_range_deg`` with random signs on θ1..θ4, lift offset 0.
        encoder_noise: std of the white encoder noise per joint (rad, rad, rad, rad, m).
        lighting: the lighting schedule.
        blur_sigma, noise_sigma, supersample, carrier: renderer settings (Gaussian blur in pixels,
            sensor noise in grey levels, anti-aliasing factor, whether the carrier is drawn).
        frame_rate_hz, start_time_ns: frame timing.
        trajectory: the camera trajectory.
        n_rim_samples: samples per rim for the ground-truth visible-rim computation.

    """

    n_slots: int = 26
    slot_pitch: float = 0.010
    wafer_radius: float = 0.150
    wafer_thickness: float = 0.001
    slots: tuple[int, ...] = DEFAULT_SLOTS
    tilts: dict[int, tuple[float, float]] | None = None
    shifts: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    placement_tilt_sigma: float = math.radians(0.05)
    placement_shift_sigma: float = 0.0002
    camera_model: str = "pinhole"
    camera_params: tuple[float, ...] = (1000.0, 1000.0, 639.5, 359.5)
    width: int = 1280
    height: int = 720
    robot: RobotParams = field(default_factory=RobotParams)
    base_pose: tuple[tuple[float, ...], ...] = DEFAULT_BASE_POSE
    joint_offsets: tuple[float, ...] | None = None
    offset_range_deg: tuple[float, float] = (0.2, 1.0)
    encoder_noise: tuple[float, ...] = (2e-5, 2e-5, 2e-5, 2e-5, 5e-6)
    lighting: Lighting = field(default_factory=Lighting)
    blur_sigma: float = 0.8
    noise_sigma: float = 2.0
    supersample: int = 4
    carrier: bool = True
    frame_rate_hz: float = 10.0
    start_time_ns: int = 0
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    n_rim_samples: int = 720

    def __post_init__(self) -> None:
        # Normalise every field to plain Python types so that configs compare equal after a
        # round trip through to_dict/from_dict, and reject bad values with a clear message.
        put = object.__setattr__
        for name in ("n_slots", "width", "height", "supersample", "n_rim_samples", "start_time_ns"):
            v = getattr(self, name)
            try:
                whole = not isinstance(v, bool) and int(v) == v
            except (TypeError, ValueError, OverflowError):  # NaN, infinity, strings, arrays
                whole = False
            if not whole:
                raise InvalidInputError(f"{name} must be an integer, got {v!r}")
            put(self, name, int(v))
        for name in ("n_slots", "width", "height", "supersample", "n_rim_samples"):
            if not 1 <= getattr(self, name) < 2**31:
                raise InvalidInputError(f"{name} must be in [1, 2**31), got {getattr(self, name)}")
        if not 0 <= self.start_time_ns < 2**63:
            raise InvalidInputError(f"start_time_ns must be in [0, 2**63), got {self.start_time_ns}")
        for name in ("slot_pitch", "wafer_radius", "wafer_thickness", "frame_rate_hz"):
            try:
                v = float(getattr(self, name))
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v) or v <= 0.0:
                raise InvalidInputError(f"{name} must be finite and > 0, got {getattr(self, name)!r}")
            put(self, name, v)
        for name in ("placement_tilt_sigma", "placement_shift_sigma", "blur_sigma", "noise_sigma"):
            put(self, name, _nonneg(getattr(self, name), name))

        slots = tuple(int(s) for s in self.slots)
        if not slots:
            raise InvalidInputError("slots must name at least one occupied slot")
        bad = [s for s in slots if not 1 <= s <= self.n_slots]
        if bad:
            raise InvalidInputError(f"slots {bad} do not exist: the carrier has slots 1..{self.n_slots}")
        if len(set(slots)) != len(slots):
            raise InvalidInputError(f"slots must be unique, got {slots}")
        put(self, "slots", slots)
        if self.tilts is None:
            default_tilts = {25: (0.0, math.radians(1.0))} if 25 in slots else {}
            put(self, "tilts", default_tilts)
        tilts = {int(k): _floats(v, 2, f"tilt of slot {k}") for k, v in dict(self.tilts).items()}
        shifts = {int(k): _floats(v, 3, f"shift of slot {k}") for k, v in dict(self.shifts).items()}
        for what, d in (("tilts", tilts), ("shifts", shifts)):
            unknown = sorted(set(d) - set(slots))
            if unknown:
                raise InvalidInputError(f"{what} given for slots {unknown} that hold no wafer (occupied: {slots})")
        put(self, "tilts", tilts)
        put(self, "shifts", shifts)

        if not isinstance(self.camera_model, str) or not self.camera_model:
            raise InvalidInputError(f"camera_model must be a non-empty string, got {self.camera_model!r}")
        put(self, "camera_params", _floats(self.camera_params, None, "camera_params"))
        try:  # validates the model against its parameters and the image size
            Camera(self.camera_model, np.asarray(self.camera_params), self.width, self.height)
        except InvalidInputError as err:
            raise InvalidInputError(
                f"camera_model {self.camera_model!r} with camera_params {self.camera_params}, "
                f"width {self.width}, height {self.height}: {err}"
            ) from None
        if not isinstance(self.robot, RobotParams):
            raise InvalidInputError(f"robot must be a RobotParams, got {type(self.robot).__name__}")
        base = np.asarray(_floats(self.base_pose, 16, "base_pose")).reshape(4, 4)
        if not np.allclose(base[3], [0, 0, 0, 1]) or not np.allclose(
            base[:3, :3].T @ base[:3, :3], np.eye(3), atol=1e-9
        ):
            raise InvalidInputError("base_pose must be a rigid transform (orthonormal rotation, last row 0 0 0 1)")
        put(self, "base_pose", tuple(tuple(float(v) for v in row) for row in base))
        if self.joint_offsets is not None:
            put(self, "joint_offsets", _floats(self.joint_offsets, 5, "joint_offsets"))
        lo, hi = _range(self.offset_range_deg, "offset_range_deg")
        if lo < 0.0:
            raise InvalidInputError(f"offset_range_deg must be non-negative, got ({lo}, {hi})")
        put(self, "offset_range_deg", (lo, hi))
        noise = _floats(self.encoder_noise, 5, "encoder_noise")
        if any(v < 0.0 for v in noise):
            raise InvalidInputError(f"encoder_noise must be >= 0, got {noise}")
        put(self, "encoder_noise", noise)
        if not isinstance(self.lighting, Lighting):
            raise InvalidInputError(f"lighting must be a Lighting, got {type(self.lighting).__name__}")
        if not isinstance(self.trajectory, TrajectoryConfig):
            raise InvalidInputError(f"trajectory must be a TrajectoryConfig, got {type(self.trajectory).__name__}")
        put(self, "carrier", bool(self.carrier))

    def __hash__(self) -> int:
        return hash(repr(self.to_dict()))

    @property
    def base_pose_matrix(self) -> np.ndarray:
        """``T_wb`` as a (4, 4) float64 array."""
        return np.array(self.base_pose, dtype=np.float64)

    def slot_height(self, slot: int) -> float:
        """Nominal height (m) of the wafer centre in ``slot`` (1-based)."""
        return (slot - 1) * self.slot_pitch

    def with_(self, **changes: Any) -> SimConfig:
        """Return a copy with some fields changed (:func:`dataclasses.replace`)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-compatible dict; :meth:`from_dict` restores an equal config (floats exactly)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("tilts", "shifts"):
                v = [[k, *vals] for k, vals in sorted(v.items())]
            elif f.name == "robot":
                v = v.to_dict()
            elif isinstance(v, (Lighting, TrajectoryConfig)):
                v = {g.name: _jsonable(getattr(v, g.name)) for g in fields(v)}
            else:
                v = _jsonable(v)
            out[f.name] = v
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SimConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`InvalidInputError`."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise InvalidInputError(f"unknown SimConfig fields: {unknown}")
        kw: dict[str, Any] = {}
        for key, value in d.items():
            if key in ("tilts", "shifts"):
                value = {int(row[0]): tuple(row[1:]) for row in value}
            elif key == "robot":
                value = RobotParams.from_dict(value)
            elif key == "lighting":
                value = Lighting(**{k: _tuplify(v) for k, v in value.items()})
            elif key == "trajectory":
                value = TrajectoryConfig(**{k: _tuplify(v) for k, v in value.items()})
            else:
                value = _tuplify(value)
            kw[key] = value
        return cls(**kw)


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    return v


def _tuplify(v: Any) -> Any:
    if isinstance(v, list):
        return tuple(_tuplify(x) for x in v)
    return v
