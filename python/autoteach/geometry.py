"""Rigid transforms, the wafer-handling robot, camera models and ellipses.

Friendly front of the compiled geometry bindings in :mod:`autoteach._core`. Everything here
accepts lists, tuples and NumPy arrays of any real dtype, returns float64 NumPy arrays, and is
batched over leading dimensions where that is natural: a function documented as taking
``(..., 3)`` accepts ``(3,)`` (one item, result without batch dimensions), ``(n, 3)``,
``(n, m, 3)``, and so on, and returns results with the same leading dimensions.

Conventions (shared by the whole package):

- SI units: metres and radians.
- Poses are 4×4 float64 homogeneous matrices; ``T_ab`` maps coordinates in frame ``b`` into
  frame ``a`` (``T_wc`` takes camera-frame points to the world).
- Lie tangents put rotation first, ``xi = [omega; rho]``; ``⊕`` is the right perturbation
  ``X ⊕ d = X·Exp(d)`` and ``Y ⊖ X = Log(X⁻¹·Y)``.
- Camera frame: z forward (optical axis), x right, y down. Pixels are ``(u, v)`` =
  (column, row) with the centre of the top-left pixel at ``(0, 0)``, as in OpenCV.

Errors: bad input (shape, dtype, NaN/inf, invalid parameter) raises
:class:`~autoteach.errors.InvalidInputError` naming the argument; an unreachable robot pose
raises :class:`~autoteach.errors.UnreachablePoseError`; a degenerate conic raises
:class:`~autoteach.errors.DegenerateGeometryError`.

Example:
    >>> import numpy as np
    >>> from autoteach.geometry import WaferRobot
    >>> robot = WaferRobot()
    >>> q = np.array([0.3, 1.1, -0.4, 0.6, 0.05])
    >>> T_be = robot.blade_pose(q, blade=1)
    >>> solutions = robot.inverse_kinematics(T_be, blade=1, other_blade_angle=0.6)
    >>> bool(np.any(np.all(np.abs(solutions - q) < 1e-9, axis=1)))
    True

"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import F64Array, as_f64, as_float, as_int
from autoteach.errors import InvalidInputError

__all__ = [
    "Camera",
    "Ellipse",
    "RobotParams",
    "WaferRobot",
    "circle_image_conic",
    "euler_xyz_to_matrix",
    "euler_zyx_to_matrix",
    "joints_from_encoders",
    "matrix_to_euler_xyz",
    "matrix_to_euler_zyx",
    "matrix_to_quat",
    "project_circle",
    "project_circle_jacobian",
    "quat_to_matrix",
    "se3_exp",
    "se3_log",
    "se3_minus",
    "se3_plus",
    "so3_exp",
    "so3_log",
]


"""A float64 NumPy array."""

DistanceKind = Literal["orthogonal", "sampson", "algebraic"]
"""How :meth:`Ellipse.distance` measures the distance of a point to the ellipse."""


# --------------------------------------------------------------------------------------------
# Input conversion
# --------------------------------------------------------------------------------------------


def _as_blade(blade: Any) -> int:
    """Validate a blade number (1 or 2)."""
    number = as_int(blade, "blade", signed=True)
    if number not in (1, 2):
        raise InvalidInputError(f"blade must be 1 or 2, got {number}")
    return number


# --------------------------------------------------------------------------------------------
# Lie groups, quaternions and Euler angles
# --------------------------------------------------------------------------------------------


def so3_exp(omega: ArrayLike) -> F64Array:
    """Rotation matrices ``Exp(omega)`` of rotation vectors (axis times angle).

    Args:
        omega: Rotation vectors, shape ``(..., 3)``, radians.

    Returns:
        Rotation matrices, shape ``(..., 3, 3)``.

    """
    return _core.so3_exp(as_f64(omega, "omega"))


def so3_log(R: ArrayLike) -> F64Array:
    """Rotation vectors ``Log(R)`` of rotation matrices, with angle in ``[0, π]``.

    Args:
        R: Rotation matrices, shape ``(..., 3, 3)``; each must be orthonormal with
            determinant +1 (to 1e-6).

    Returns:
        Rotation vectors, shape ``(..., 3)``.

    """
    return _core.so3_log(as_f64(R, "R"))


def se3_exp(xi: ArrayLike) -> F64Array:
    """Poses ``Exp(xi)`` of twists ``xi = [omega; rho]``.

    Args:
        xi: Twists, shape ``(..., 6)``, rotation first.

    Returns:
        Homogeneous poses, shape ``(..., 4, 4)``.

    """
    return _core.se3_exp(as_f64(xi, "xi"))


def se3_log(T: ArrayLike) -> F64Array:
    """Twists ``Log(T) = [omega; rho]`` of poses (inverse of :func:`se3_exp`).

    Args:
        T: Rigid transforms, shape ``(..., 4, 4)``.

    Returns:
        Twists, shape ``(..., 6)``.

    """
    return _core.se3_log(as_f64(T, "T"))


def se3_plus(T: ArrayLike, xi: ArrayLike) -> F64Array:
    """Right perturbation ``T ⊕ xi = T·Exp(xi)``.

    The leading dimensions of ``T`` and ``xi`` broadcast against each other.

    Args:
        T: Rigid transforms, shape ``(..., 4, 4)``.
        xi: Twists, shape ``(..., 6)``.

    Returns:
        Perturbed poses, shape ``(..., 4, 4)`` (broadcast leading dimensions).

    """
    t_arr, xi_arr = _broadcast_pair(as_f64(T, "T"), "T", 2, as_f64(xi, "xi"), "xi", 1)
    return _core.se3_plus(t_arr, xi_arr)


def se3_minus(Y: ArrayLike, X: ArrayLike) -> F64Array:
    """Difference ``Y ⊖ X = Log(X⁻¹·Y)``, the twist taking ``X`` to ``Y`` by right perturbation.

    The leading dimensions of ``Y`` and ``X`` broadcast against each other.

    Args:
        Y: Rigid transforms, shape ``(..., 4, 4)``.
        X: Rigid transforms, shape ``(..., 4, 4)``.

    Returns:
        Twists, shape ``(..., 6)`` (broadcast leading dimensions).

    """
    y_arr, x_arr = _broadcast_pair(as_f64(Y, "Y"), "Y", 2, as_f64(X, "X"), "X", 2)
    return _core.se3_minus(y_arr, x_arr)


def _broadcast_pair(
    a: F64Array, a_name: str, a_core: int, b: F64Array, b_name: str, b_core: int
) -> tuple[F64Array, F64Array]:
    """Broadcasts the leading (batch) dimensions of two arrays with ``a_core``/``b_core`` item dims."""
    if a.ndim < a_core or b.ndim < b_core:
        # Too few dimensions: let the compiled function report the expected shape.
        return a, b
    try:
        lead = np.broadcast_shapes(a.shape[: a.ndim - a_core], b.shape[: b.ndim - b_core])
    except ValueError:
        raise InvalidInputError(
            f"the batch shapes of {a_name} {a.shape} and {b_name} {b.shape} do not broadcast"
        ) from None
    a_out = np.broadcast_to(a, lead + a.shape[a.ndim - a_core :])
    b_out = np.broadcast_to(b, lead + b.shape[b.ndim - b_core :])
    return a_out, b_out


def quat_to_matrix(q: ArrayLike) -> F64Array:
    """Rotation matrices of quaternions ``(w, x, y, z)`` (Hamilton convention, scalar first).

    Args:
        q: Quaternions, shape ``(..., 4)``; they are normalised, and a (near-)zero quaternion
            raises :class:`~autoteach.errors.InvalidInputError`.

    Returns:
        Rotation matrices, shape ``(..., 3, 3)``.

    """
    return _core.quat_to_matrix(as_f64(q, "q"))


def matrix_to_quat(R: ArrayLike) -> F64Array:
    """Convert rotation matrices to unit quaternions ``(w, x, y, z)`` with ``w ≥ 0``.

    Args:
        R: Rotation matrices, shape ``(..., 3, 3)``.

    Returns:
        Quaternions, shape ``(..., 4)``.

    """
    return _core.matrix_to_quat(as_f64(R, "R"))


def euler_zyx_to_matrix(angles: ArrayLike) -> F64Array:
    """Rotation matrices ``Rz(yaw)·Ry(pitch)·Rx(roll)`` of Euler angles ``(yaw, pitch, roll)``.

    Args:
        angles: ``(yaw, pitch, roll)`` in radians, shape ``(..., 3)``.

    Returns:
        Rotation matrices, shape ``(..., 3, 3)``.

    """
    return _core.euler_zyx_to_matrix(as_f64(angles, "angles"))


def matrix_to_euler_zyx(R: ArrayLike) -> F64Array:
    """Euler angles ``(yaw, pitch, roll)`` of ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.

    Args:
        R: Rotation matrices, shape ``(..., 3, 3)``.

    Returns:
        ``(yaw, pitch, roll)`` with pitch in ``[-π/2, π/2]``, shape ``(..., 3)``.

    """
    return _core.matrix_to_euler_zyx(as_f64(R, "R"))


def euler_xyz_to_matrix(angles: ArrayLike) -> F64Array:
    """Rotation matrices ``Rx(a)·Ry(b)·Rz(c)`` of Euler angles ``(a, b, c)``.

    Args:
        angles: ``(a, b, c)`` in radians, shape ``(..., 3)``.

    Returns:
        Rotation matrices, shape ``(..., 3, 3)``.

    """
    return _core.euler_xyz_to_matrix(as_f64(angles, "angles"))


def matrix_to_euler_xyz(R: ArrayLike) -> F64Array:
    """Euler angles ``(a, b, c)`` of ``R = Rx(a)·Ry(b)·Rz(c)``.

    Args:
        R: Rotation matrices, shape ``(..., 3, 3)``.

    Returns:
        ``(a, b, c)`` with ``b`` in ``[-π/2, π/2]``, shape ``(..., 3)``.

    """
    return _core.matrix_to_euler_xyz(as_f64(R, "R"))


# --------------------------------------------------------------------------------------------
# The wafer-handling robot
# --------------------------------------------------------------------------------------------

_DEFAULT_PARAMS: dict[str, float] = _core.WaferRobot.default_params()


@dataclass(frozen=True)
class RobotParams:
    """Geometric parameters of the wafer-handling robot (seed 000_3b1454b2b2194811.txt ch. 2.2).

    Mirrors the Rust ``RobotParams``; the defaults are the Rust defaults (a 300 mm wafer robot).
    Lengths are in metres, angles in radians. Values are validated on construction (finite
    reals, positive link lengths, ``|beta_c| < π/2``), raising
    :class:`~autoteach.errors.InvalidInputError`. Frozen: derive variants with
    :func:`dataclasses.replace`.

    Attributes:
        l1: Upper-arm length, shoulder (JT2) to elbow (JT4) axis.
        l2: Forearm length, elbow (JT4) to wrist (JT6/JT7) axis.
        l3: Blade-1 length, wrist axis to the blade-1 tip (origin of the blade-1 frame).
        l4: Blade-2 length, wrist axis to the blade-2 tip.
        h01: Height of the blade-1 frame over the lifted column ``h``.
        h02: Height of the blade-2 frame over the lifted column ``h``.
        alpha1: Pitch of blade 1 about its own y axis (0 = level).
        alpha2: Pitch of blade 2 about its own y axis (0 = level).
        beta_c: Downward tilt of the camera's optical axis from the blade-2 x axis.
        cam_d: Distance of the camera centre behind the blade-2 tip, along the blade.
        cam_h: Height of the camera centre above the blade-2 frame.

    """

    l1: float = _DEFAULT_PARAMS["l1"]
    l2: float = _DEFAULT_PARAMS["l2"]
    l3: float = _DEFAULT_PARAMS["l3"]
    l4: float = _DEFAULT_PARAMS["l4"]
    h01: float = _DEFAULT_PARAMS["h01"]
    h02: float = _DEFAULT_PARAMS["h02"]
    alpha1: float = _DEFAULT_PARAMS["alpha1"]
    alpha2: float = _DEFAULT_PARAMS["alpha2"]
    beta_c: float = _DEFAULT_PARAMS["beta_c"]
    cam_d: float = _DEFAULT_PARAMS["cam_d"]
    cam_h: float = _DEFAULT_PARAMS["cam_h"]

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, as_float(getattr(self, f.name), f.name))
        # The Rust constructor holds the rules (positive lengths, |beta_c| < π/2): ask it.
        _core.WaferRobot(self.to_dict(), None)

    def to_dict(self) -> dict[str, float]:
        """Return the parameters as a ``{name: value}`` dict in the documented field order."""
        return dict(asdict(self))

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> RobotParams:
        """Build parameters from a mapping; missing names take the defaults.

        Raises:
            InvalidInputError: An unknown name, or a value that is not a real finite number.

        """
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise InvalidInputError(f"unknown robot parameter(s) {unknown}; expected names among {names}")
        return cls(**{k: as_float(v, k) for k, v in values.items()})


class WaferRobot:
    """The dual-blade wafer-handling robot with its blade-mounted camera (seed ch. 2.2).

    Joint vectors ``q`` are ``(θ1, θ2, θ3, θ4, h)``: shoulder, elbow, blade-1 wrist and blade-2
    wrist angles in radians and the column lift in metres. Methods taking ``q`` are batched
    over leading dimensions: ``q`` of shape ``(..., 5)`` gives poses of shape ``(..., 4, 4)``.

    Args:
        params: Geometric parameters: ``None`` for the defaults, a :class:`RobotParams`, or a
            mapping of parameter names to values (missing names take the defaults).
        base: Pose ``T_wb`` of the robot base in the world (4×4), identity when ``None``.

    Raises:
        InvalidInputError: Invalid parameters (non-positive link length, ``|beta_c| ≥ π/2``,
            unknown name, non-finite value) or a base that is not a rigid transform.

    """

    __slots__ = ("_inner",)

    def __init__(self, params: RobotParams | Mapping[str, Any] | None = None, base: ArrayLike | None = None) -> None:
        if params is None:
            values = RobotParams().to_dict()
        elif isinstance(params, RobotParams):
            values = params.to_dict()
        elif isinstance(params, Mapping):
            values = RobotParams.from_dict(params).to_dict()
        else:
            raise InvalidInputError(
                f"params must be None, a RobotParams or a mapping of names to values, got {type(params).__name__}"
            )
        self._inner = _core.WaferRobot(values, None if base is None else as_f64(base, "base"))

    @property
    def params(self) -> RobotParams:
        """The geometric parameters (a frozen copy)."""
        return RobotParams(**self._inner.params)

    @property
    def base(self) -> F64Array:
        """The base pose ``T_wb`` (4×4, a copy)."""
        return self._inner.base

    def __repr__(self) -> str:
        return f"WaferRobot(params={self.params!r}, base={self.base.tolist()!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (WaferRobot, (self.params, self.base))

    def camera_mount(self) -> F64Array:
        """Return the camera mount ``T_e2c``: camera frame to blade-2 frame (4×4), seed eq. (2.7)."""
        return self._inner.camera_mount()

    def blade_pose(self, q: ArrayLike, blade: int = 1) -> F64Array:
        """Forward kinematics ``T_be`` of a blade in the robot BASE frame, seed eq. (2.4).

        Args:
            q: Joint vectors, shape ``(..., 5)``.
            blade: 1 or 2.

        Returns:
            Blade poses (blade frame to base frame), shape ``(..., 4, 4)``. Compose with
            :attr:`base` for world poses.

        """
        return self._inner.blade_pose(as_f64(q, "q"), _as_blade(blade))

    def camera_pose(self, q: ArrayLike) -> F64Array:
        """Camera pose in the world ``T_wc = T_wb·T_be2·T_e2c``, seed eq. (2.2).

        Args:
            q: Joint vectors, shape ``(..., 5)``.

        Returns:
            Camera poses (camera frame to world), shape ``(..., 4, 4)``.

        """
        return self._inner.camera_pose(as_f64(q, "q"))

    def camera_pose_in_base(self, q: ArrayLike) -> F64Array:
        """Camera pose in the robot base ``T_bc = T_be2·T_e2c``.

        Args:
            q: Joint vectors, shape ``(..., 5)``.

        Returns:
            Camera poses (camera frame to base frame), shape ``(..., 4, 4)``.

        """
        return self._inner.camera_pose_in_base(as_f64(q, "q"))

    def jacobian(self, q: ArrayLike, blade: int = 1) -> F64Array:
        """Blade Jacobian ``d(v_x, v_y, v_z, ω_z)/d(θ̇1, θ̇2, θ̇3, θ̇4, ḣ)`` in the base frame, seed eq. (2.5).

        Args:
            q: Joint vectors, shape ``(..., 5)``.
            blade: 1 or 2.

        Returns:
            Jacobians, shape ``(..., 4, 5)``.

        """
        return self._inner.jacobian(as_f64(q, "q"), _as_blade(blade))

    def camera_jacobian(self, q: ArrayLike) -> F64Array:
        """Jacobian of ``T_wc(q)`` as right-perturbation twists ``[ω; ρ]`` per joint.

        Column ``j`` satisfies ``T_wc(q + ε e_j) ≈ T_wc(q) ⊕ ε J[:, j]``.

        Args:
            q: Joint vectors, shape ``(..., 5)``.

        Returns:
            Jacobians, shape ``(..., 6, 5)``.

        """
        return self._inner.camera_jacobian(as_f64(q, "q"))

    def acceleration(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, blade: int = 1) -> F64Array:
        """Blade acceleration ``(a_x, a_y, a_z, ω̇_z)`` in the base frame, seed eq. (2.6).

        Args:
            q: Joint positions, shape ``(..., 5)``.
            qd: Joint velocities, shape ``(..., 5)``.
            qdd: Joint accelerations, shape ``(..., 5)``.
            blade: 1 or 2.

        Returns:
            Accelerations, shape ``(..., 4)``; the leading dimensions of the three inputs
            broadcast against each other.

        """
        q_arr, qd_arr, qdd_arr = (as_f64(q, "q"), as_f64(qd, "qd"), as_f64(qdd, "qdd"))
        if q_arr.ndim >= 1 and qd_arr.ndim >= 1 and qdd_arr.ndim >= 1:
            try:
                lead = np.broadcast_shapes(q_arr.shape[:-1], qd_arr.shape[:-1], qdd_arr.shape[:-1])
            except ValueError:
                raise InvalidInputError(
                    f"the batch shapes of q {q_arr.shape}, qd {qd_arr.shape} and qdd {qdd_arr.shape} do not broadcast"
                ) from None
            q_arr, qd_arr, qdd_arr = (np.broadcast_to(a, lead + a.shape[-1:]) for a in (q_arr, qd_arr, qdd_arr))
        return self._inner.acceleration(q_arr, qd_arr, qdd_arr, _as_blade(blade))

    def inverse_kinematics(self, T: ArrayLike, blade: int = 1, other_blade_angle: float = 0.0) -> F64Array:
        """All joint vectors placing ``blade`` at pose ``T`` (in the BASE frame).

        Args:
            T: Desired blade pose ``T_be`` (4×4), as returned by :meth:`blade_pose`.
            blade: 1 or 2.
            other_blade_angle: Wrist angle given to the other blade (radians).

        Returns:
            Solutions, shape ``(k, 5)`` with ``k`` = 1 or 2 (elbow up/down; one on the
            workspace boundary). Angles are wrapped to ``(-π, π]``.

        Raises:
            UnreachablePoseError: The orientation is not a pure yaw of the blade's pitch, or
                the wrist point is out of the arm's reach; the message gives the numbers.

        """
        return self._inner.inverse_kinematics(
            as_f64(T, "T"), _as_blade(blade), as_float(other_blade_angle, "other_blade_angle")
        )

    def inverse_kinematics_camera(self, T_wc: ArrayLike, theta3: float = 0.0) -> F64Array:
        """All joint vectors placing the camera at the world pose ``T_wc``.

        Args:
            T_wc: Desired camera pose (camera frame to world), 4×4.
            theta3: Wrist angle given to blade 1 (radians).

        Returns:
            Solutions, shape ``(k, 5)``.

        Raises:
            UnreachablePoseError: The camera pose cannot be reached.

        """
        return self._inner.inverse_kinematics_camera(as_f64(T_wc, "T_wc"), as_float(theta3, "theta3"))


def joints_from_encoders(q_enc: ArrayLike, offsets: ArrayLike) -> F64Array:
    """Convert encoder readings ``q_enc = q + δ`` to true joints ``q = q_enc − δ``.

    Args:
        q_enc: Encoder readings, shape ``(..., 5)``.
        offsets: Joint zero offsets ``δ``, shape ``(5,)`` (the last one in metres).

    Returns:
        Joint vectors, shape ``(..., 5)``.

    """
    return _core.joints_from_encoders(as_f64(q_enc, "q_enc"), as_f64(offsets, "offsets"))


# --------------------------------------------------------------------------------------------
# Cameras
# --------------------------------------------------------------------------------------------


class Camera:
    """A calibrated camera: pinhole, Brown–Conrady (OpenCV) or Kannala–Brandt (fisheye).

    Parameters, in order (the same as OpenCV's camera matrix and distortion vector):

    - ``"pinhole"``: ``fx, fy, cx, cy``;
    - ``"brown_conrady"`` (alias ``"opencv"``): ``fx, fy, cx, cy, k1, k2, p1, p2, k3``, as
      ``cv2.projectPoints``;
    - ``"kannala_brandt"`` (aliases ``"fisheye"``, ``"kb"``): ``fx, fy, cx, cy, k1, k2, k3,
      k4``, as ``cv2.fisheye.projectPoints`` (seed 004_815695db12a6b16c.txt ch. 5).

    :attr:`param_names` lists them for the chosen model.

    Args:
        model: Model name (see above).
        params: Intrinsic and distortion parameters, shape ``(n,)``.
        width: Image width in pixels.
        height: Image height in pixels.

    Raises:
        InvalidInputError: Unknown model, wrong number of parameters, a non-positive focal
            length or image size, or a non-finite value.

    """

    __slots__ = ("_inner",)

    def __init__(self, model: str, params: ArrayLike, width: int, height: int) -> None:
        if not isinstance(model, str):
            raise InvalidInputError(f"model must be a string, got {type(model).__name__}")
        w, h = as_int(width, "width"), as_int(height, "height")
        if w <= 0 or h <= 0:
            raise InvalidInputError(f"width and height must be positive, got {w} x {h}")
        self._inner = _core.Camera(model, as_f64(params, "params"), w, h)

    @property
    def model(self) -> str:
        """The canonical model name: ``"pinhole"``, ``"brown_conrady"`` or ``"kannala_brandt"``."""
        return self._inner.model

    @property
    def params(self) -> F64Array:
        """The parameters (a copy), in the order of :attr:`param_names`."""
        return self._inner.params

    @property
    def param_names(self) -> list[str]:
        """Names of :attr:`params`, e.g. ``["fx", "fy", "cx", "cy", "k1", ...]``."""
        return self._inner.param_names

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return self._inner.width

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return self._inner.height

    @property
    def K(self) -> F64Array:
        """The 3×3 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return self._inner.K

    def __repr__(self) -> str:
        return f"Camera({self.model!r}, {self.params.tolist()!r}, {self.width}, {self.height})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (Camera, (self.model, self.params, self.width, self.height))

    def project(self, points: ArrayLike) -> F64Array:
        """Projects camera-frame points to pixels.

        Args:
            points: Points in the camera frame, shape ``(..., 3)``.

        Returns:
            Pixels ``(u, v)``, shape ``(..., 2)``.

        Raises:
            InvalidInputError: A point is not projectable (behind the camera for the pinhole
                and Brown–Conrady models, on the optical centre); the message gives its index.

        """
        return self._inner.project(as_f64(points, "points"))

    def project_jacobians(self, points: ArrayLike) -> tuple[F64Array, F64Array, F64Array]:
        """Projects points and returns the analytic Jacobians of the projection.

        Args:
            points: Points in the camera frame, shape ``(..., 3)``.

        Returns:
            ``(pixels, J_point, J_params)`` of shapes ``(..., 2)``, ``(..., 2, 3)`` and
            ``(..., 2, n)``: derivatives of the pixel with respect to the point and to
            :attr:`params`.

        """
        return self._inner.project_jacobians(as_f64(points, "points"))

    def unproject(self, pixels: ArrayLike) -> F64Array:
        """Return the unit bearing vectors (camera frame) of pixels; ``project(unproject(px)) ≈ px``.

        Args:
            pixels: Pixels ``(u, v)``, shape ``(..., 2)``.

        Returns:
            Unit vectors, shape ``(..., 3)``.

        """
        return self._inner.unproject(as_f64(pixels, "pixels"))

    def in_image(self, pixels: ArrayLike) -> NDArray[np.bool_]:
        """Whether pixels fall inside the image (``-0.5 ≤ u < width − 0.5``, same for ``v``).

        Pixel centres are integers, so the image covers ``[-0.5, width − 0.5)`` in ``u``.

        Args:
            pixels: Pixels ``(u, v)``, shape ``(..., 2)``.

        Returns:
            Booleans, shape ``(...)``; non-finite pixels are outside.

        """
        return self._inner.in_image(as_f64(pixels, "pixels"))


# --------------------------------------------------------------------------------------------
# Ellipses and the image of a circle
# --------------------------------------------------------------------------------------------


class Ellipse:
    """An ellipse in the image plane (seed 000_3b1454b2b2194811.txt ch. 3.2).

    Centre ``(cx, cy)``, semi-axes ``a ≥ b > 0`` and orientation ``theta`` of the ``a`` axis
    from the image x axis, in ``(-π/2, π/2]``; the constructor normalises its inputs to that
    form (swapping the axes if ``a < b``). Points are ``(x, y) = (cx, cy) + R(theta)·(a cos t,
    b sin t)``.

    Args:
        cx: Centre x (pixels).
        cy: Centre y (pixels).
        a: Semi-axis along ``theta``.
        b: The other semi-axis.
        theta: Orientation (radians).

    Raises:
        InvalidInputError: A non-finite value or a non-positive semi-axis.

    """

    __slots__ = ("_inner",)

    def __init__(self, cx: float, cy: float, a: float, b: float, theta: float) -> None:
        self._inner = _core.Ellipse(
            as_float(cx, "cx"), as_float(cy, "cy"), as_float(a, "a"), as_float(b, "b"), as_float(theta, "theta")
        )

    @classmethod
    def _wrap(cls, inner: _core.Ellipse) -> Ellipse:
        out = cls.__new__(cls)
        out._inner = inner
        return out

    @classmethod
    def from_conic(cls, C: ArrayLike) -> Ellipse:
        """Build the ellipse of a symmetric 3×3 conic matrix (any non-zero scale and sign).

        Args:
            C: Conic matrix with ``[x, y, 1] C [x, y, 1]ᵀ = 0`` on the curve.

        Raises:
            DegenerateGeometryError: ``C`` is not a real, non-degenerate ellipse (a hyperbola,
                parabola, imaginary ellipse or a degenerate conic).
            InvalidInputError: Wrong shape, not symmetric, or non-finite.

        """
        return cls._wrap(_core.Ellipse.from_conic(as_f64(C, "C")))

    @classmethod
    def from_array(cls, values: ArrayLike) -> Ellipse:
        """Build the ellipse of ``(cx, cy, a, b, theta)``, the inverse of :meth:`as_array`."""
        arr = as_f64(values, "values")
        if arr.shape != (5,):
            raise InvalidInputError(f"values must have shape (5,) = (cx, cy, a, b, theta), got {arr.shape}")
        return cls(*arr)

    @property
    def cx(self) -> float:
        """Centre x (pixels)."""
        return self._inner.cx

    @property
    def cy(self) -> float:
        """Centre y (pixels)."""
        return self._inner.cy

    @property
    def a(self) -> float:
        """Semi-major axis."""
        return self._inner.a

    @property
    def b(self) -> float:
        """Semi-minor axis."""
        return self._inner.b

    @property
    def theta(self) -> float:
        """Orientation of the major axis from the x axis, in ``(-π/2, π/2]``."""
        return self._inner.theta

    @property
    def area(self) -> float:
        """Area ``π·a·b``."""
        return self._inner.area

    @property
    def perimeter(self) -> float:
        """Perimeter (exact to rounding)."""
        return self._inner.perimeter

    @property
    def center(self) -> F64Array:
        """The centre ``(cx, cy)``."""
        return np.array([self.cx, self.cy])

    def as_array(self) -> F64Array:
        """``(cx, cy, a, b, theta)`` as an array of shape ``(5,)``."""
        return np.array([self.cx, self.cy, self.a, self.b, self.theta])

    def __repr__(self) -> str:
        return f"Ellipse(cx={self.cx!r}, cy={self.cy!r}, a={self.a!r}, b={self.b!r}, theta={self.theta!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (Ellipse, (self.cx, self.cy, self.a, self.b, self.theta))

    def conic(self) -> F64Array:
        """Return the symmetric 3×3 conic matrix ``C`` of seed eq. (3.3), with its exact scaling.

        ``p = [x, y, 1]``: ``p C pᵀ`` is −1 at the centre, negative inside, zero on the curve
        and positive outside.
        """
        return self._inner.conic()

    def conic_coefficients(self) -> F64Array:
        """Coefficients ``(A, B, C, D, E, F)`` of ``A x² + B x y + C y² + D x + E y + F = 0``.

        Scaled to unit Euclidean norm with the sign of :meth:`conic` (negative inside).
        """
        return self._inner.conic_coefficients()

    def point_at(self, t: ArrayLike) -> F64Array:
        """Points at parameters ``t`` (radians), shape ``(...)`` → ``(..., 2)``."""
        return self._inner.point_at(as_f64(t, "t"))

    def sample(self, n: int, t0: float = 0.0, t1: float = 2.0 * math.pi) -> F64Array:
        """``n`` points at eccentric angles evenly spaced from ``t0`` to ``t1`` (both included).

        Args:
            n: Number of points (≥ 2).
            t0: First parameter (radians).
            t1: Last parameter (radians).

        Returns:
            Points, shape ``(n, 2)``.

        """
        count = as_int(n, "n")
        if count < 2:
            raise InvalidInputError(f"n must be at least 2 (both ends are included), got {count}")
        return self._inner.sample(count, as_float(t0, "t0"), as_float(t1, "t1"))

    def distance(self, points: ArrayLike, kind: DistanceKind = "orthogonal") -> F64Array:
        """Distances of points to the ellipse.

        Args:
            points: Points, shape ``(..., 2)``.
            kind: ``"orthogonal"`` (signed Euclidean distance to the curve, negative inside,
                exact), ``"sampson"`` (unsigned first-order approximation of it, ``+inf`` at
                the centre) or ``"algebraic"`` (the conic's value ``p C pᵀ`` with the scale of
                :meth:`conic`: −1 at the centre).

        Returns:
            Distances, shape ``(...)``.

        """
        if kind not in ("orthogonal", "sampson", "algebraic"):
            raise InvalidInputError(f"kind must be 'orthogonal', 'sampson' or 'algebraic', got {kind!r}")
        return self._inner.distance(as_f64(points, "points"), kind)

    def closest_point(self, points: ArrayLike) -> F64Array:
        """Return the points of the ellipse closest to ``points`` (shape ``(..., 2)`` → ``(..., 2)``)."""
        return self._inner.closest_point(as_f64(points, "points"))


def project_circle(K: ArrayLike, T_cw: ArrayLike, center: ArrayLike, normal: ArrayLike, radius: float) -> Ellipse:
    """Project a 3D circle through a pinhole camera: its image is an ellipse (seed eq. (5.13)).

    Args:
        K: Camera matrix, 3×3.
        T_cw: World-to-camera transform (4×4): maps world coordinates into the camera frame.
        center: Circle centre in the world, shape ``(3,)``.
        normal: Normal of the circle's plane in the world (any non-zero length), ``(3,)``.
        radius: Circle radius (> 0).

    Returns:
        The image ellipse (undistorted pixels).

    Raises:
        DegenerateGeometryError: The image is not an ellipse (the circle is seen edge-on, or
            crosses the plane through the camera centre parallel to the image).
        InvalidInputError: Bad shapes or values.

    """
    return Ellipse._wrap(
        _core.project_circle(
            as_f64(K, "K"),
            as_f64(T_cw, "T_cw"),
            as_f64(center, "center"),
            as_f64(normal, "normal"),
            as_float(radius, "radius"),
        )
    )


def project_circle_jacobian(K: ArrayLike, T_co: ArrayLike, radius: float) -> tuple[Ellipse, F64Array]:
    """Project a circle given in an object frame, with the Jacobian of the ellipse parameters.

    The circle of ``radius`` lies in the ``z = 0`` plane of the object frame, centred at its
    origin (a wafer rim in the wafer frame; seed eq. (5.13)).

    Args:
        K: Camera matrix, 3×3.
        T_co: Object-to-camera transform (4×4).
        radius: Circle radius (> 0).

    Returns:
        ``(ellipse, J)`` with ``J`` of shape ``(5, 6)``: derivatives of
        ``(cx, cy, a, b, theta)`` with respect to the right perturbation ``δ = [ω; ρ]`` of
        ``T_co`` (``T_co·Exp(δ)``).

    Raises:
        DegenerateGeometryError: The image is not an ellipse, or is so nearly circular
            (``(a − b)/a ≤ 1e-9``) that ``theta`` and its derivative are undefined.

    """
    inner, jac = _core.project_circle_jacobian(as_f64(K, "K"), as_f64(T_co, "T_co"), as_float(radius, "radius"))
    return Ellipse._wrap(inner), jac


def circle_image_conic(K: ArrayLike, T_co: ArrayLike, radius: float) -> F64Array:
    """Image conic ``C = H⁻ᵀ·diag(1, 1, −r²)·H⁻¹``, ``H = K·[r₁ r₂ t]``, seed eq. (5.13).

    Args:
        K: Camera matrix, 3×3.
        T_co: Object-to-camera transform (4×4); the circle lies in the object's ``z = 0``
            plane, centred at its origin.
        radius: Circle radius (> 0).

    Returns:
        The conic (3×3), scaled to unit Frobenius norm and negative inside the ellipse.

    """
    return _core.circle_image_conic(as_f64(K, "K"), as_f64(T_co, "T_co"), as_float(radius, "radius"))
