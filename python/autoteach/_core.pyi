"""Type stubs of the compiled module ``autoteach._core`` (Rust, PyO3).

The compiled functions take float64 NumPy arrays only (the friendly wrappers in
:mod:`autoteach.geometry` and the other submodules convert lists and other dtypes first) and
validate shapes and finiteness, raising :class:`InvalidInputError` naming the argument.
Each section below belongs to one binding module of ``crates/py/src``.
"""

from collections.abc import Mapping
from typing import Literal, TypeAlias

import numpy as np
from numpy.typing import NDArray

F64Array: TypeAlias = NDArray[np.float64]

__version__: str

# --- errors ---

class AutoteachError(Exception):
    """Base class of every error raised by autoteach."""

class InvalidInputError(AutoteachError, ValueError):
    """An input has the wrong shape, dtype, a NaN/inf, or an invalid value."""

class DegenerateGeometryError(AutoteachError, ValueError):
    """The data are geometrically degenerate (collinear points, a degenerate conic, ...)."""

class UnreachablePoseError(AutoteachError, ValueError):
    """A requested robot pose cannot be reached."""

class ConvergenceError(AutoteachError, RuntimeError):
    """An iterative computation did not converge."""

class AllocationError(AutoteachError, MemoryError):
    """An input asks for a buffer larger than memory (a huge sample count or dimension)."""

class InternalError(AutoteachError, RuntimeError):
    """A bug inside autoteach (a Rust panic caught at the Python boundary)."""

# --- geometry ---

def so3_exp(omega: F64Array) -> F64Array:
    """Rotation matrices ``Exp(omega)``: ``(..., 3)`` -> ``(..., 3, 3)``."""

def so3_log(R: F64Array) -> F64Array:
    """Rotation vectors ``Log(R)``: ``(..., 3, 3)`` -> ``(..., 3)``."""

def se3_exp(xi: F64Array) -> F64Array:
    """Poses ``Exp(xi)``, ``xi = [omega; rho]``: ``(..., 6)`` -> ``(..., 4, 4)``."""

def se3_log(T: F64Array) -> F64Array:
    """Twists ``Log(T)``: ``(..., 4, 4)`` -> ``(..., 6)``."""

def se3_plus(T: F64Array, xi: F64Array) -> F64Array:
    """``T ⊕ xi = T·Exp(xi)``; equal leading shapes: ``(..., 4, 4)``, ``(..., 6)`` -> ``(..., 4, 4)``."""

def se3_minus(Y: F64Array, X: F64Array) -> F64Array:
    """``Y ⊖ X = Log(X⁻¹·Y)``; equal leading shapes: ``(..., 4, 4)`` x2 -> ``(..., 6)``."""

def quat_to_matrix(q: F64Array) -> F64Array:
    """Rotation matrices of quaternions ``(w, x, y, z)``: ``(..., 4)`` -> ``(..., 3, 3)``."""

def matrix_to_quat(R: F64Array) -> F64Array:
    """Quaternions ``(w, x, y, z)`` with ``w >= 0``: ``(..., 3, 3)`` -> ``(..., 4)``."""

def euler_zyx_to_matrix(angles: F64Array) -> F64Array:
    """``Rz(yaw)·Ry(pitch)·Rx(roll)`` of ``(yaw, pitch, roll)``: ``(..., 3)`` -> ``(..., 3, 3)``."""

def matrix_to_euler_zyx(R: F64Array) -> F64Array:
    """``(yaw, pitch, roll)`` of rotation matrices: ``(..., 3, 3)`` -> ``(..., 3)``."""

def euler_xyz_to_matrix(angles: F64Array) -> F64Array:
    """``Rx(a)·Ry(b)·Rz(c)`` of ``(a, b, c)``: ``(..., 3)`` -> ``(..., 3, 3)``."""

def matrix_to_euler_xyz(R: F64Array) -> F64Array:
    """Return ``(a, b, c)`` of rotation matrices ``Rx(a)·Ry(b)·Rz(c)``: ``(..., 3, 3)`` -> ``(..., 3)``."""

def joints_from_encoders(q_enc: F64Array, offsets: F64Array) -> F64Array:
    """Return the true joints ``q_enc - offsets``: ``(..., 5)``, ``(5,)`` -> ``(..., 5)``."""

class WaferRobot:
    """The compiled wafer-handling robot; see :class:`autoteach.geometry.WaferRobot`."""

    def __new__(cls, params: Mapping[str, float] | None = None, base: F64Array | None = None) -> WaferRobot: ...
    @staticmethod
    def default_params() -> dict[str, float]:
        """Return the default parameters ``{name: value}``."""

    @property
    def params(self) -> dict[str, float]:
        """The parameters ``{name: value}``."""

    @property
    def base(self) -> F64Array:
        """The base pose ``T_wb`` (4x4)."""

    def camera_mount(self) -> F64Array:
        """Return the camera mount ``T_e2c`` (4x4)."""

    def blade_pose(self, q: F64Array, blade: int) -> F64Array:
        """Blade poses ``T_be`` in the base frame: ``(..., 5)`` -> ``(..., 4, 4)``."""

    def camera_pose(self, q: F64Array) -> F64Array:
        """World camera poses ``T_wc``: ``(..., 5)`` -> ``(..., 4, 4)``."""

    def camera_pose_in_base(self, q: F64Array) -> F64Array:
        """Camera poses in the base ``T_bc``: ``(..., 5)`` -> ``(..., 4, 4)``."""

    def jacobian(self, q: F64Array, blade: int) -> F64Array:
        """Blade Jacobians: ``(..., 5)`` -> ``(..., 4, 5)``."""

    def camera_jacobian(self, q: F64Array) -> F64Array:
        """Camera-pose Jacobians (right-perturbation twists): ``(..., 5)`` -> ``(..., 6, 5)``."""

    def acceleration(self, q: F64Array, qd: F64Array, qdd: F64Array, blade: int) -> F64Array:
        """Blade accelerations; equal leading shapes: ``(..., 5)`` x3 -> ``(..., 4)``."""

    def inverse_kinematics(self, T: F64Array, blade: int, other_blade_angle: float) -> F64Array:
        """All joint vectors reaching the blade pose ``T`` (base frame): ``(k, 5)``."""

    def inverse_kinematics_camera(self, T_wc: F64Array, theta3: float) -> F64Array:
        """All joint vectors reaching the world camera pose ``T_wc``: ``(k, 5)``."""

class Camera:
    """The compiled camera model; see :class:`autoteach.geometry.Camera`."""

    def __new__(cls, model: str, params: F64Array, width: int, height: int) -> Camera: ...
    @property
    def model(self) -> str:
        """Canonical model name."""

    @property
    def params(self) -> F64Array:
        """Parameters (a copy), ``(n,)``."""

    @property
    def param_names(self) -> list[str]:
        """Names of the parameters."""

    @property
    def width(self) -> int:
        """Image width (pixels)."""

    @property
    def height(self) -> int:
        """Image height (pixels)."""

    @property
    def K(self) -> F64Array:
        """Camera matrix (3x3)."""

    def project(self, points: F64Array) -> F64Array:
        """Pixels of camera-frame points: ``(..., 3)`` -> ``(..., 2)``."""

    def project_jacobians(self, points: F64Array) -> tuple[F64Array, F64Array, F64Array]:
        """Pixels ``(..., 2)`` and their Jacobians ``(..., 2, 3)`` (point), ``(..., 2, n)`` (params)."""

    def unproject(self, pixels: F64Array) -> F64Array:
        """Return the unit bearings of pixels: ``(..., 2)`` -> ``(..., 3)``."""

    def in_image(self, pixels: F64Array) -> NDArray[np.bool_]:
        """Whether pixels lie on the image: ``(..., 2)`` -> ``(...)``; NaN pixels are outside."""

class Ellipse:
    """The compiled ellipse; see :class:`autoteach.geometry.Ellipse`."""

    def __new__(cls, cx: float, cy: float, a: float, b: float, theta: float) -> Ellipse: ...
    @staticmethod
    def from_conic(C: F64Array) -> Ellipse:
        """Build the ellipse of a 3x3 conic matrix (any scale and sign)."""

    @property
    def cx(self) -> float:
        """Centre x."""

    @property
    def cy(self) -> float:
        """Centre y."""

    @property
    def a(self) -> float:
        """Semi-major axis."""

    @property
    def b(self) -> float:
        """Semi-minor axis."""

    @property
    def theta(self) -> float:
        """Orientation of the major axis, in ``(-pi/2, pi/2]``."""

    @property
    def area(self) -> float:
        """Area ``pi·a·b``."""

    @property
    def perimeter(self) -> float:
        """Perimeter."""

    def conic(self) -> F64Array:
        """Conic matrix (3x3), value -1 at the centre."""

    def conic_coefficients(self) -> F64Array:
        """Return ``(A, B, C, D, E, F)``, unit norm."""

    def point_at(self, t: F64Array) -> F64Array:
        """Points at eccentric angles: ``(...)`` -> ``(..., 2)``."""

    def sample(self, n: int, t0: float, t1: float) -> F64Array:
        """``n >= 2`` points from ``t0`` to ``t1``: ``(n, 2)``."""

    def distance(self, points: F64Array, kind: Literal["orthogonal", "sampson", "algebraic"]) -> F64Array:
        """Distances of points: ``(..., 2)`` -> ``(...)``."""

    def closest_point(self, points: F64Array) -> F64Array:
        """Closest points on the ellipse: ``(..., 2)`` -> ``(..., 2)``."""

def circle_image_conic(K: F64Array, T_co: F64Array, radius: float) -> F64Array:
    """Unit-norm image conic (3x3) of a circle in the object frame's ``z = 0`` plane."""

def project_circle(K: F64Array, T_cw: F64Array, center: F64Array, normal: F64Array, radius: float) -> Ellipse:
    """Project a world circle to its image ellipse."""

def project_circle_jacobian(K: F64Array, T_co: F64Array, radius: float) -> tuple[Ellipse, F64Array]:
    """Ellipse of an object-frame circle and its 5x6 Jacobian w.r.t. the right perturbation of ``T_co``."""

# --- render (sim) ---
# Ray-cast renderer of the simulated wafer carrier and ground truth of the visible rims
# (crates/geometry/src/render, bindings in crates/py/src/sim.rs). World = carrier frame (z up,
# opening toward -x, slot k's nominal wafer centre at (0, 0, (k - 1) * 0.010)); poses are 4x4
# float64 homogeneous matrices; wafer_poses[i] is T_w,wafer (wafer disc between z = +-t/2 of its
# frame); t_wc is the camera pose (camera -> world; camera z forward, x right, y down). Pixel
# (u, v) is centred at image position (u, v) (OpenCV convention).

def render_frame(
    wafer_poses: F64Array,
    camera_model: str,
    camera_params: F64Array,
    width: int,
    height: int,
    t_wc: F64Array,
    *,
    wafer_radius: float = 0.15,
    wafer_thickness: float = 0.001,
    carrier: bool = True,
    gain: float = 1.0,
    gradient: tuple[float, float] = (0.0, 0.0),
    blur_sigma: float = 0.8,
    noise_sigma: float = 2.0,
    supersample: int = 4,
    seed: int = 0,
) -> NDArray[np.uint8]:
    """Render one grayscale frame: a ``(height, width)`` uint8 array.

    ``wafer_poses`` is ``(N, 4, 4)``. Bright anti-aliased rim bands (side faces), dark mirror-like
    top/bottom faces reflecting their neighbours (one bounce), the carrier's walls and slot ridges
    (``carrier=True``) as clutter. Lighting factor ``gain * (1 + gx * x + gy * y)`` with ``x, y``
    from -1 (left/top) to 1 (right/bottom), then Gaussian blur ``blur_sigma`` (px), additive
    Gaussian noise ``noise_sigma`` (grey levels) seeded by ``seed`` (``0 <= seed < 2**64``; same
    seed, same bytes), rounding. ``supersample`` in 1..16 (s x s rays per edge pixel).
    Raises InvalidInputError for bad shapes, NaN/inf, non-rigid poses, non-positive sizes.
    """

def rim_visibility(
    wafer_poses: F64Array,
    camera_model: str,
    camera_params: F64Array,
    width: int,
    height: int,
    t_wc: F64Array,
    *,
    wafer_radius: float = 0.15,
    wafer_thickness: float = 0.001,
    carrier: bool = True,
    n_samples: int = 720,
) -> list[dict[str, object]]:
    """Ground truth of the visible rims: for each wafer, a dict for its upper then its lower rim.

    Keys: ``wafer`` (int index), ``rim`` (``"upper"``/``"lower"``), ``ellipse`` ((5,) ``[cx, cy, a, b,
    theta]`` of the whole rim circle under the camera's pinhole part ``K``, or ``None`` if its image
    is not an ellipse), ``intervals`` ((k, 2) visible circle-angle intervals ``[phi0, phi1]``, radians,
    wafer frame, ``0 <= phi0 < 2*pi``, ``phi0 < phi1 <= phi0 + 2*pi``; ends refined to 1e-9 rad),
    ``fraction`` (visible length / 2*pi), ``points`` ((m, 2) pixel positions of the visible samples
    ``phi_j = 2*pi*j/n_samples``), ``angles`` ((m,) their phi), ``side_facing`` ((m,) bool: the
    bright side face faces the camera there; where False the rim is only the low-contrast silhouette
    of the dark top/bottom face).

    A rim point is visible iff it is in front of the camera, projects inside the image, one of its
    two adjacent faces faces the camera, and nothing (other wafers, carrier, the wafer itself) lies
    on the segment from the camera centre to it.
    """

def rim_points_visible(
    wafer_poses: F64Array,
    camera_model: str,
    camera_params: F64Array,
    width: int,
    height: int,
    t_wc: F64Array,
    wafer: int,
    rim: Literal["upper", "lower"],
    angles: F64Array,
    *,
    wafer_radius: float = 0.15,
    wafer_thickness: float = 0.001,
    carrier: bool = True,
) -> NDArray[np.bool_]:
    """Visibility (the test of :func:`rim_visibility`) of the rim points at circle angles ``angles`` (n,)."""

# --- detect ---

class EllipseFit:
    """The compiled ellipse fit; see :class:`autoteach.detect.EllipseFit`."""

    @property
    def ellipse(self) -> Ellipse:
        """The fitted ellipse."""

    @property
    def residual_mean(self) -> float:
        """Mean absolute orthogonal distance (pixels)."""

    @property
    def residual_rms(self) -> float:
        """RMS orthogonal distance (pixels)."""

    @property
    def covariance(self) -> F64Array | None:
        """Covariance of ``(cx, cy, a, b, theta)``, (5, 5), or ``None`` for exactly 5 points."""

    @property
    def iterations(self) -> int:
        """Levenberg–Marquardt iterations (0 for the direct fit)."""

    @property
    def converged(self) -> bool:
        """Whether the iteration met its tolerance."""

def fit_ellipse(points: F64Array, method: Literal["direct", "geometric"] = "geometric") -> EllipseFit:
    """Fit an ellipse to points (N, 2); see :func:`autoteach.detect.fit_ellipse`."""

def linear_sum_assignment(cost: F64Array, maximize: bool = False) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Linear assignment (rows, cols); see :func:`autoteach.detect.linear_sum_assignment`."""

def assign_with_unassigned(
    cost: F64Array, row_unassigned_cost: F64Array, col_unassigned_cost: F64Array
) -> tuple[NDArray[np.intp], NDArray[np.intp], float]:
    """Assignment with non-assignment costs; see :func:`autoteach.detect.assign_with_unassigned`."""

# --- estimate (ukf) ---

from collections.abc import Callable as _Callable  # noqa: E402
from typing import Any as _Any  # noqa: E402

def merwe_sigma_points(x: F64Array, p: F64Array, alpha: float, beta: float, kappa: float) -> F64Array:
    """Van der Merwe's scaled sigma points ``(2n+1, n)`` of mean ``x`` (n,) and covariance ``p`` (n, n).

    Order as filterpy: the mean, then ``x + L[:, k]``, then ``x - L[:, k]`` with ``L`` the lower
    Cholesky factor of ``(n + lambda) p``. Raises InvalidInputError for bad sizes, NaN, bad
    parameters or a ``p`` that is not symmetric positive definite.
    """

def merwe_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[F64Array, F64Array]:
    """The weights ``(Wm, Wc)`` (each ``(2n+1,)``) of van der Merwe's scaled sigma points."""

def family_sigma_points(
    family_name: str, x: F64Array, p: F64Array, alpha: float = 1.0, beta: float = 0.0, kappa: float = 0.0
) -> F64Array:
    """Sigma points ``(N, n)`` of a family (``"merwe"``: alpha, beta, kappa; ``"julier"``: kappa; ``"simplex"``)."""

def family_weights(
    family_name: str, n: int, alpha: float = 1.0, beta: float = 0.0, kappa: float = 0.0
) -> tuple[F64Array, F64Array]:
    """The weights ``(Wm, Wc)`` of a sigma-point family."""

class UkfLinearModel:
    """Built-in linear model ``x' = F x + B u``, ``z = H x`` (F (n, n), H (m, n), B (n, k) or None)."""

    def __init__(self, f: F64Array, h: F64Array, b: F64Array | None = None) -> None: ...
    @property
    def dim_x(self) -> int: ...
    @property
    def dim_z(self) -> int: ...
    @property
    def dim_u(self) -> int: ...

class UkfConstantVelocityModel:
    """Built-in constant-velocity model in ``dim`` dimensions: state ``[p; v]``, input acceleration, ``z = p``."""

    def __init__(self, dim: int) -> None: ...
    @property
    def dim_x(self) -> int: ...
    @property
    def dim_z(self) -> int: ...
    @property
    def dim_u(self) -> int: ...

class UkfFilter:
    """The compiled unscented Kalman filter (standard or square-root; additive or augmented noise).

    Build it with :meth:`builtin` (a built-in model: batches run in Rust without the GIL) or
    :meth:`callbacks` (Python callables, called as filterpy calls them; an exception they raise
    propagates unchanged). Covariances that lose positive definiteness during filtering raise
    ConvergenceError naming the step, unless ``repair=True`` (eigenvalues clipped).
    """

    @staticmethod
    def builtin(
        model: UkfLinearModel | UkfConstantVelocityModel,
        alpha: float,
        beta: float,
        kappa: float,
        *,
        square_root: bool = False,
        augmented: bool = False,
        repair: bool = False,
        family_name: str = "merwe",
    ) -> UkfFilter: ...
    @staticmethod
    def callbacks(
        dim_x: int,
        dim_z: int,
        fx: _Callable[..., _Any],
        hx: _Callable[..., _Any],
        alpha: float,
        beta: float,
        kappa: float,
        *,
        x_mean: _Callable[[F64Array, F64Array], _Any] | None = None,
        z_mean: _Callable[[F64Array, F64Array], _Any] | None = None,
        residual_x: _Callable[[F64Array, F64Array], _Any] | None = None,
        residual_z: _Callable[[F64Array, F64Array], _Any] | None = None,
        state_add: _Callable[[F64Array, F64Array], _Any] | None = None,
        subtract: _Callable[[F64Array, F64Array], _Any] | None = None,
        sqrt: _Callable[[F64Array], _Any] | None = None,
        square_root: bool = False,
        augmented: bool = False,
        repair: bool = False,
        dim_w: int | None = None,
        dim_v: int | None = None,
        family_name: str = "merwe",
        draw: _Callable[[F64Array, F64Array], _Any] | None = None,
        wm: F64Array | None = None,
        wc: F64Array | None = None,
        vectorized: bool = False,
    ) -> UkfFilter:
        """A filter on Python callables, called as filterpy calls them.

        ``vectorized=True`` (additive noise only): ``fx(sigmas (N, n), dt, **fx_kwargs)`` and
        ``hx(sigmas (N, n), **hx_kwargs)`` receive all sigma points at once and return ``(N, n)`` / ``(N, m)``.

        ``fx(x, dt, **fx_kwargs)`` (augmented: ``fx(x, dt, w, **fx_kwargs)``), ``hx(x, **hx_kwargs)``
        (augmented: ``hx(x, v, **hx_kwargs)``), ``x_mean(sigmas (2n+1, n), Wm)``, ``residual_x(a, b)``,
        ``state_add(x, dx)``, ``subtract(x, -offset)`` for the sigma points, ``sqrt(M)`` returning a matrix
        whose rows are the sigma offsets. ``draw(x, P)`` with ``wm``, ``wc``: an external sigma-point
        object's ``sigma_points`` (returning ``(N, n)``) and weights, used instead of ``family_name``.
        """

    def sigma_points(self, x: F64Array, p: F64Array) -> F64Array:
        """Sigma points ``(N, n)`` of (x, P) as this filter draws them (family and hooks)."""

    def rts_smoother(
        self, xs: F64Array, ps: F64Array, qs: F64Array, dts: F64Array, us: F64Array | None = None
    ) -> tuple[F64Array, F64Array, F64Array]:
        """Unscented RTS smoother: ``(xs, Ps, Ks)`` from filtered ``xs`` (n, dim_x), ``Ps`` (n, dim_x, dim_x).

        ``qs`` is (dim_x, dim_x) or (n, dim_x, dim_x), ``dts`` (n,). Built-in models run without the GIL.
        """

    def set_state(
        self,
        x: F64Array | None = None,
        p: F64Array | None = None,
        q: F64Array | None = None,
        r: F64Array | None = None,
    ) -> None:
        """Set any of x (n,), P (n, n), Q, R (validated: sizes, finiteness, symmetry, definiteness)."""

    def predict(
        self,
        dt: float,
        u: F64Array | None = None,
        fx_kwargs: dict[str, _Any] | None = None,
        fx: _Callable[..., _Any] | None = None,
    ) -> None: ...
    def update(
        self,
        z: F64Array,
        r: F64Array | None = None,
        hx_kwargs: dict[str, _Any] | None = None,
        hx: _Callable[..., _Any] | None = None,
    ) -> None: ...
    def skip_update(self) -> None:
        """Record a missing measurement (posterior = prior)."""

    def batch(
        self,
        zs: F64Array,
        dt: float,
        mask: list[bool] | None = None,
        us: F64Array | None = None,
        dts: F64Array | None = None,
        rs: F64Array | None = None,
        priors: bool = True,
    ) -> dict[str, F64Array]:
        """Predict/update over ``zs`` (n, dim_z) in one call.

        Returns ``xs`` (n, dim_x), ``Ps`` (n, dim_x, dim_x), ``log_likelihoods`` (n,) and, with
        ``priors``, ``x_priors``, ``P_priors``. ``mask`` marks the measurements present.
        """

    @property
    def dim_x(self) -> int: ...
    @property
    def dim_z(self) -> int: ...
    @property
    def x(self) -> F64Array: ...
    @property
    def P(self) -> F64Array: ...  # noqa: N802
    @property
    def Q(self) -> F64Array: ...  # noqa: N802
    @property
    def R(self) -> F64Array: ...  # noqa: N802
    @property
    def x_prior(self) -> F64Array: ...
    @property
    def P_prior(self) -> F64Array: ...  # noqa: N802
    @property
    def x_post(self) -> F64Array: ...
    @property
    def P_post(self) -> F64Array: ...  # noqa: N802
    @property
    def K(self) -> F64Array: ...  # noqa: N802
    @property
    def y(self) -> F64Array: ...
    @property
    def S(self) -> F64Array: ...  # noqa: N802
    @property
    def log_likelihood(self) -> float: ...
    @property
    def step(self) -> int: ...
    @property
    def repairs(self) -> int: ...
    @property
    def Wm(self) -> F64Array: ...  # noqa: N802
    @property
    def Wc(self) -> F64Array: ...  # noqa: N802

# --- wafers (detect) ---
class WaferEdge:
    """One detected wafer rim; see :class:`autoteach.detect.WaferEdge`."""

    @property
    def ellipse(self) -> Ellipse: ...
    @property
    def points(self) -> F64Array: ...
    @property
    def residual(self) -> float: ...
    @property
    def covariance(self) -> F64Array | None: ...
    @property
    def kind(self) -> str: ...
    @property
    def wafer_id(self) -> int: ...

def wafer_detect(
    image: NDArray[np.uint8] | NDArray[np.float32] | NDArray[np.float64],
    *,
    canny_low: float = 6.0,
    canny_high: float = 15.0,
    blur_sigma: float = 0.0,
    min_arc_points: int = 16,
    residual_threshold: float = 0.25,
    max_gap: float = 60.0,
    up: tuple[float, float] = (0.0, -1.0),
    max_rim_offset: float = 10.0,
    max_rim_axis_difference: float = 0.10,
    min_contrast_ratio: float = 0.45,
    semi_major_range: tuple[float, float] | None = None,
    semi_minor_range: tuple[float, float] | None = None,
    min_coverage: float | None = None,
    min_rim_separation: float | None = None,
    max_arc_deviation: float | None = None,
    max_arc_residual_ratio: float | None = None,
    max_unpaired_residual: float | None = None,
    band_refinement: bool | None = None,
    share_rim_shape: bool | None = None,
    share_rim_centre: bool | None = None,
    joint_band_fit: bool | None = None,
    inflection_sigmas: float | None = None,
    join_border_cut_arcs: bool | None = None,
    thickness_ratio: float | None = None,
    focal_length: float | None = None,
    restart_turn_at_cuts: bool | None = None,
    max_relative_sigma_b: float | None = None,
    max_centre_sigma: float | None = None,
    keep_flat_run_pieces: bool | None = None,
    border_pairs_take_arcs: bool | None = None,
    reflection_inside_rim: bool | None = None,
    seek_missing_partner: bool | None = None,
    thin_band_fit: bool | None = None,
    front_band_fit: bool | None = None,
    principal_point: tuple[float, float] | None = None,
    edge_profile: str | None = None,
    level_band_search: bool | None = None,
) -> list[WaferEdge]:
    """Detect wafer rims in a grayscale image; see :func:`autoteach.detect.detect_wafers`.

    ``None`` keeps the library default (:func:`wafer_detect_defaults`).
    """

def wafer_detect_defaults() -> dict[str, float | int | bool | str | tuple[float, float]]:
    """The detector's default parameters by keyword name of :func:`wafer_detect`."""

# --- end wafers ---

# --- registration (cpd, global voting) ---
# The results are dicts keyed by the Rust field names (``detect::cpd::RigidResult``,
# ``AffineResult``, ``NonrigidResult``, ``GlobalHypothesis``); ``autoteach.registration`` builds
# its result classes from them.
def cpd_rigid(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    w: float = 0.0,
    scale: bool = True,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    e_step: str = "auto",
    return_p: bool = False,
) -> dict[str, _Any]: ...
def cpd_affine(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    w: float = 0.0,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    e_step: str = "auto",
    return_p: bool = False,
) -> dict[str, _Any]: ...
def cpd_nonrigid(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    beta: float = 2.0,
    lam: float = 2.0,
    low_rank: int | None = None,
    power_iterations: int | None = None,
    w: float = 0.0,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    e_step: str = "auto",
    return_p: bool = False,
) -> dict[str, _Any]: ...
def global_cpd(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    k: int = 3,
    beta: float = 2.0,
    lam: float = 2.0,
    w: float = 0.5,
    low_rank: int | None = None,
    max_iterations: int = 100,
    tolerance: float = 1e-3,
    sigma2: float | None = None,
    neighbours: int = 10,
    angle_bin: float = 0.2,
    translation_bin: float | None = None,
    count: str = "y",
    min_votes: int = 3,
    max_points: int = 1000,
) -> list[dict[str, _Any]]: ...

# --- end registration ---

# --- polygon ---
def polygon_global_voting(
    x: F64Array, y: F64Array, options: Mapping[str, object] | None = None
) -> tuple[F64Array, F64Array, NDArray[np.int64], NDArray[np.int64]]:
    """Global voting: (R (K, D, D), t (K, D), votes (K,), pair_votes (K,)), best first."""

def polygon_vote_cells(
    x: F64Array, y: F64Array, options: Mapping[str, object] | None = None
) -> tuple[F64Array, F64Array, NDArray[np.int64], NDArray[np.int64]]:
    """Every populated vote cell, sorted by the chosen count."""

def polygon_detect_segments(image: NDArray[np.uint8], options: Mapping[str, object] | None = None) -> F64Array:
    """Line segments (N, 4) [ax, ay, bx, by], dark side on the left."""

def polygon_detect(
    template: F64Array,
    homography: F64Array,
    image: NDArray[np.uint8] | None = None,
    segments: F64Array | None = None,
    options: Mapping[str, object] | None = None,
    segment_options: Mapping[str, object] | None = None,
) -> dict[str, object]:
    """Polygon detection; keys pose, coarse, votes, support, segments, centre_image, rms, vote_map, ..."""

def polygon_render_opening(
    width: int,
    height: int,
    homography: F64Array,
    plate: float,
    polygons: list[tuple[F64Array, float]],
    lines: F64Array,
    occluders: list[tuple[F64Array, float]],
    supersample: int = 4,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    seed: int = 0,
) -> NDArray[np.uint8]:
    """Chamber-opening image (height, width)."""

# --- end polygon ---

# --- track ---
class TrackWaferTracker:
    """Multi-wafer tracker (000_3b1454b2b2194811.txt Algorithms 4–5); see ``autoteach.track.WaferTracker``."""

    def __init__(
        self,
        *,
        sigma: float = 3.0,
        omega: float = 1e-4,
        knn: int = 8,
        gate: float = 5.0,
        min_score: float = 0.0,
        min_coverage: float = 0.0,
        associator: str = "hierarchical",
        greedy_gate: float = 40.0,
        max_points_per_segment: int = 48,
        max_missed: int = 30,
        min_hits: int = 2,
        rim_merge_distance: float = 4.0,
        image_size: tuple[float, float] | None = None,
        intrinsics: NDArray[np.float64] | None = None,
        wafer_radius: float = 0.15,
        normal_prior: tuple[float, float, float] | None = None,
        circle_window: int = 6,
        prefer_projection: bool = False,
        multiview_circle: bool = True,
        normal_prior_sigma: float = 0.05,
        circle_fit_iterations: int = 1,
        projection_max_center_std: float = 0.003,
        projection_max_rms: float = 2.0,
        max_missed_3d: int = 300,
        stack_axis_sigma: float | None = 0.002,
        slot_pitch: float | None = None,
    ) -> None: ...
    def update(
        self,
        edges: list[tuple[NDArray[np.float64], NDArray[np.float64], str, int, float]],
        camera_pose: NDArray[np.float64] | None = None,
    ) -> list[int | None]: ...
    def tracks(self) -> list[dict[str, object]]: ...
    def retired(self) -> list[dict[str, object]]: ...
    @property
    def last_timings(self) -> tuple[float, float, float]: ...
    @property
    def frame(self) -> int: ...

# --- end track ---

# --- lsq (estimate) ---
def lsq_bundle_adjust(
    k: NDArray[np.float64],
    poses: NDArray[np.float64],
    points: NDArray[np.float64],
    observations: NDArray[np.float64],
    pose_index: list[int] | NDArray[np.int64],
    point_index: list[int] | NDArray[np.int64],
    loss_name: str = "linear",
    f_scale: float = 1.0,
    fixed_poses: list[int] = ...,
    method: str = "lm",
    linear_solver: str = "auto",
    max_iterations: int = 100,
    function_tolerance: float = 1e-10,
    gradient_tolerance: float = 1e-10,
    parameter_tolerance: float = 1e-10,
    initial_damping: float = 1e-4,
) -> tuple[NDArray[np.float64], NDArray[np.float64], dict[str, object]]: ...

class LsqProblem:
    def __init__(self) -> None: ...
    def add_block(self, values: NDArray[np.float64], manifold: str) -> int: ...
    def add_rotation(self, r: NDArray[np.float64]) -> int: ...
    def add_pose(self, t: NDArray[np.float64]) -> int: ...
    def pose(self, block: int) -> NDArray[np.float64]: ...
    def manifold(self, block: int) -> str: ...
    @property
    def num_blocks(self) -> int: ...
    @property
    def num_residuals(self) -> int: ...
    def set_fixed(self, block: int, fixed: bool) -> None: ...
    def set_eliminate(self, block: int, eliminate: bool | None = None) -> None: ...
    def values(self, block: int) -> NDArray[np.float64]: ...
    def set_values(self, block: int, values: NDArray[np.float64]) -> None: ...
    def add_reprojections(
        self,
        k: NDArray[np.float64],
        observations: NDArray[np.float64],
        pose_blocks: list[int] | NDArray[np.int64],
        point_blocks: list[int] | NDArray[np.int64],
        sigma: float = 1.0,
        loss_name: str = "linear",
        f_scale: float = 1.0,
    ) -> list[int]: ...
    def add_prior(self, block: int, mean: NDArray[np.float64], covariance: NDArray[np.float64]) -> int: ...
    def add_relative_pose(
        self,
        a: int,
        b: int,
        t_ab: NDArray[np.float64],
        covariance: NDArray[np.float64],
        loss_name: str = "linear",
        f_scale: float = 1.0,
    ) -> int: ...
    def add_point_to_conic(
        self,
        k: NDArray[np.float64],
        radius: float,
        observations: NDArray[np.float64],
        camera_block: int,
        object_block: int,
        weight: float = 1.0,
        loss_name: str = "linear",
        f_scale: float = 1.0,
    ) -> list[int]: ...
    def solve(
        self,
        method: str = "lm",
        linear_solver: str = "auto",
        max_iterations: int = 100,
        function_tolerance: float = 1e-10,
        gradient_tolerance: float = 1e-10,
        parameter_tolerance: float = 1e-10,
        initial_damping: float = 1e-4,
    ) -> dict[str, object]: ...
    def marginal_covariance(self, blocks: list[int]) -> NDArray[np.float64]: ...

# --- end lsq ---

# --- calib ---

class CalibResult:
    """A camera calibration (see :class:`autoteach.calib.Calibration`)."""

    @staticmethod
    def from_parts(
        model: str,
        params: F64Array,
        width: int,
        height: int,
        covariance: F64Array,
        free: list[bool],
        poses: F64Array,
        object_points: list[F64Array],
        image_points: list[F64Array],
        sigma_z: float,
    ) -> CalibResult: ...
    @property
    def model(self) -> str: ...
    @property
    def params(self) -> F64Array: ...
    @property
    def image_size(self) -> tuple[int, int]: ...
    @property
    def free(self) -> list[bool]: ...
    @property
    def covariance(self) -> F64Array: ...
    @property
    def poses(self) -> F64Array: ...
    @property
    def view_rms(self) -> list[float]: ...
    @property
    def rms(self) -> float: ...
    @property
    def outliers(self) -> list[tuple[int, int]]: ...
    @property
    def sigma_z(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def final_cost(self) -> float: ...
    def information(self) -> F64Array: ...
    def views(self) -> list[tuple[F64Array, F64Array, list[int]]]: ...
    def max_ere(
        self, samples: int = 200, grid: int = 5, seed: int = 0, grid_margin: float | None = None
    ) -> tuple[float, tuple[float, float]]: ...
    def max_ere_stats(
        self, samples: int = 200, grid: int = 5, seed: int = 0, grid_margin: float | None = None
    ) -> dict[str, object]: ...
    def error_map(self, step: int = 1, samples: int = 100, seed: int = 0) -> F64Array: ...
    def suggest_next_view(
        self,
        target: F64Array,
        candidates: F64Array | None = None,
        samples: int = 100,
        grid: int = 5,
        seed: int = 0,
        grid_margin: float | None = None,
    ) -> dict[str, object]: ...
    def test_errors(self, object_points: list[F64Array], image_points: list[F64Array]) -> list[list[float]]: ...

CALIB_GRID_MARGIN: float

def calib_calibrate(
    object_points: list[F64Array],
    image_points: list[F64Array],
    model: str,
    width: int,
    height: int,
    *,
    sigma_z: float | None = None,
    loss: str = "trivial",
    loss_scale: float | None = None,
    outlier_threshold: float | None = None,
    bootstrap: bool = True,
    initial_params: F64Array | None = None,
    max_iterations: int = 100,
) -> CalibResult: ...
def calib_select_model(
    object_points: list[F64Array],
    image_points: list[F64Array],
    models: list[str],
    width: int,
    height: int,
    *,
    sigma_z: float | None = None,
) -> list[tuple[str, CalibResult | None, float, str | None]]: ...
def calib_candidate_poses(model: str, params: F64Array, width: int, height: int, target: F64Array) -> F64Array: ...
def calib_first_view_pose(model: str, params: F64Array, width: int, height: int, target: F64Array) -> F64Array: ...
def calib_random_poses(
    model: str,
    params: F64Array,
    width: int,
    height: int,
    target: F64Array,
    count: int,
    *,
    max_tilt: float = 0.7,
    seed: int = 0,
) -> F64Array: ...
def calib_novice_poses(
    model: str,
    params: F64Array,
    width: int,
    height: int,
    target: F64Array,
    count: int,
    *,
    seed: int = 0,
) -> F64Array: ...
def calib_synthesize_view(
    model: str,
    params: F64Array,
    width: int,
    height: int,
    pose: F64Array,
    target: F64Array,
    *,
    sigma: float = 0.0,
    seed: int = 0,
) -> tuple[F64Array, F64Array, list[int]] | None: ...

# --- end calib ---

# --- handeye ---
#: Observations in the solver's flat layout: ``(frames, wafers, rims, start, points (N, 2),
#: sigma_scale (N,) or None)``; the points of observation ``i`` are ``points[start[i]:start[i+1]]``.
_SlamObservations = tuple[list[int], list[int], list[int], list[int], NDArray[np.float64], NDArray[np.float64] | None]
#: A start ``(base_pose (4, 4), joint_offsets (5,), wafers (W, 5))``.
_SlamStart = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]

class HandeyeSlamMot:
    """A SLAM-MOT problem of one session (000_3b1454b2b2194811.txt §5.3), built once.

    ``free_camera = (motion_sigma (6), odometry (F-1, 4, 4) or None, odometry_sigma (6))`` switches to
    per-frame camera poses tied by the robot motion factor of eqs. (5.10)–(5.12), with a calibration
    prior of ``prior_sigmas`` centred on each solve's start. ``prior_sigmas`` are also the priors
    carried between sliding windows.
    """

    def __init__(
        self,
        k: NDArray[np.float64],
        robot_params: NDArray[np.float64],
        wafer_radius: float,
        wafer_thickness: float,
        encoders: NDArray[np.float64],
        n_wafers: int,
        *,
        pixel_sigma: float = 0.5,
        estimate_offsets: list[int] = [1, 3],
        reference_wafer: int = 0,
        huber: float | None = 3.0,
        max_iterations: int = 50,
        prior_sigmas: tuple[float, float, float] = (0.035, 0.02, 0.035),
        encoder_sigma: tuple[float, float, float, float] | None = None,
        estimate_mount: bool = False,
        estimate_links: list[int] = [],
        free_camera: tuple[list[float], NDArray[np.float64] | None, list[float]] | None = None,
    ) -> None: ...
    def solve(
        self,
        observations: _SlamObservations,
        start: _SlamStart,
        *,
        factor: str = "conic",
        n_model: int = 360,
        rounds: int = 3,
        window: int = 0,
        init_heights: tuple[float, float, float] | None = None,
        basin_search: bool = False,
    ) -> dict[str, object]:
        """Height search (``init_heights``), sliding window (``window > 0``), batch solve (``handeye::run::solve``).

        ``sigma_scale`` (one factor per point, > 0): point ``i`` has the standard deviation
        ``pixel_sigma · sigma_scale[i]`` (eq. (5.5) per point). ``basin_search``: after the batch
        solve, every wafer whose edge residuals stand out is re-fitted alone (camera poses fixed)
        from a grid of tilts and heights, and the batch solve is repeated from a better basin when
        one is found; the wafers moved are ``basins_moved``.
        """
    def gate_and_resolve(
        self,
        observations: _SlamObservations,
        start: _SlamStart,
        detections: tuple[NDArray[np.float64], list[int], list[int]],
        *,
        gates_px: list[float],
        first_heights: tuple[float, float, float],
        reset_tilts: bool = True,
        min_wafer_frames: int = 8,
        points_per_rim: int = 24,
        min_inlier_fraction: float = 0.6,
        min_points: int = 12,
        min_band_px: float = 0.0,
        band_weights: bool = False,
        basin_search: bool = False,
    ) -> dict[str, _Any]:
        """The detect front end's chain of gates (``handeye::run::gate_and_resolve``).

        ``detections = (points (N, 2), start (E + 1), frames (E))``. Returns ``observations``,
        ``start`` (``base_pose``, ``joint_offsets``, ``wafers``), ``stats``, ``last_gate_px`` and
        ``too_few_views``.
        """

def handeye_ukf(
    robot_params: NDArray[np.float64],
    base_pose: NDArray[np.float64],
    encoders: NDArray[np.float64],
    increments: NDArray[np.float64],
    noise: list[float] | None = None,
    offset_std0: float = 0.035,
    odometry: list[float] | None = None,
) -> dict[str, object]:
    """UKF fusion of visual odometry and encoders, eqs. (5.1)–(5.2); offsets of joint1, joint2, joint4.

    ``odometry``: ``None`` for world-frame increments with white errors, or ``[loc_t, loc_r, map_t,
    map_step]`` for the relative poses of a SLAM with a map (state augmented by its error; joint1
    then unobservable, ``observable`` in the result).
    """

def handeye_resolution(
    k: NDArray[np.float64],
    t_wc: NDArray[np.float64],
    wafer: NDArray[np.float64],
    wafer_radius: float,
    wafer_thickness: float,
    n: int = 180,
) -> NDArray[np.float64]:
    """Theoretical resolution (eq. (5.14)): px/mm of cx, cy, cz and px/deg of rx, ry."""

def handeye_gate(
    k: NDArray[np.float64],
    camera_poses: NDArray[np.float64],
    wafers: NDArray[np.float64],
    wafer_radius: float,
    wafer_thickness: float,
    edge_points: NDArray[np.float64],
    edge_start: list[int],
    edge_frames: list[int],
    *,
    gate_px: float = 2.0,
    min_inlier_fraction: float = 0.6,
    points_per_rim: int = 24,
    min_points: int = 12,
    min_band_px: float = 0.0,
    band_weights: bool = False,
) -> dict[str, _Any]:
    """Gate detected edges against the projected wafer rims (``handeye::gating::gate_edges``).

    Returns ``observations`` in the solver's flat layout (``sigma_scale`` only with
    ``band_weights``) and ``stats``.
    """

def handeye_band_width(
    points: NDArray[np.float64],
    h_inv: NDArray[np.float64],
    t_co_other: NDArray[np.float64],
    conic: NDArray[np.float64],
    k: NDArray[np.float64],
    radius: float,
) -> NDArray[np.float64]:
    """Predicted image width (pixels) of a wafer's side face at edge points of one rim."""

def handeye_band_sigma_scale(band: NDArray[np.float64], rim: int) -> NDArray[np.float64]:
    """Edge-noise factor (>= 1) at each predicted band width; ``rim`` 0 upper, 1 lower."""

HANDEYE_BAND_NOISE: tuple[list[float], list[float], list[float]]

# --- end handeye ---

# --- active ---

ACTIVE_PARAM_NAMES: list[str]

def active_fisher_information(jacobians: list[F64Array], sigmas: F64Array, weights: F64Array) -> F64Array:
    """Fisher information ``Σ ω_i/σ_i² J_iᵀJ_i`` (eq. (6.6)); see :func:`autoteach.active.fisher_information`."""

def active_observability_indices(information: F64Array, power: float = 2.0) -> dict[str, float]:
    """O1-O6 (Table 6.2) and ``log_det``; see :func:`autoteach.active.observability_indices`."""

def active_d_optimal_design(
    candidates: list[F64Array], tol: float = 1e-6, max_iterations: int = 100000
) -> dict[str, _Any]:
    """Approximate D-optimal weights; see :func:`autoteach.active.d_optimal_design`."""

def active_directional_derivatives(candidates: list[F64Array], weights: F64Array) -> F64Array:
    """``p − tr(M⁻¹ F_iᵀF_i)`` (eq. (6.8)); see :func:`autoteach.active.directional_derivatives`."""

def active_detmax(
    candidates: list[F64Array],
    n: int,
    prior: F64Array | None = None,
    max_excursion: int = 3,
    allow_repeats: bool = False,
    seed: int = 0,
) -> dict[str, _Any]:
    """DETMAX selection (eq. (6.10)); see :func:`autoteach.active.detmax`."""

def active_run_trials(
    trials: int,
    seed: int = 0,
    mode: str = "reduced",
    steps: int | None = None,
    sigma_px: float | None = None,
    power: float | None = None,
    estimate: list[str] | None = None,
) -> dict[str, _Any]:
    """Closed loop of Fig. 6.1 on simulation; see :func:`autoteach.active.run_trials`."""

class ActiveSystem:
    """Hand-eye estimator and planning scene; see :class:`autoteach.active.ActiveState`."""

    def __init__(
        self, sigma_px: float | None = None, power: float | None = None, estimate: list[str] | None = None
    ) -> None: ...
    @property
    def names(self) -> list[str]: ...
    @property
    def sigma_px(self) -> float: ...
    def estimate(self) -> dict[str, F64Array]: ...
    def information(self) -> F64Array: ...
    def set_information(self, information: F64Array) -> None: ...
    def covariance(self) -> F64Array: ...
    def indices(self, power: float | None = None) -> dict[str, float]: ...
    def project(self, joints: F64Array) -> F64Array: ...
    def jacobian(self, joints: F64Array) -> F64Array: ...
    def update(self, joints: F64Array, pixels: F64Array) -> dict[str, float]: ...
    def plan(
        self,
        candidates: F64Array | None = None,
        criterion: str = "D",
        method: str = "reduced",
        samples: int | None = None,
        seed: int = 0,
    ) -> dict[str, _Any]: ...

# --- end active ---

# --- ellipse detection (issue 42) ---

class EllipseDetection:
    """One detected ellipse; see :class:`autoteach.detect.EllipseDetection`."""

    @property
    def ellipse(self) -> Ellipse: ...
    @property
    def points(self) -> NDArray[np.float64]: ...
    @property
    def covariance(self) -> NDArray[np.float64] | None: ...
    @property
    def residual(self) -> float: ...
    @property
    def score(self) -> float: ...
    @property
    def polarity(self) -> int: ...

def ellipse_detect(
    image: NDArray[np.uint8] | NDArray[np.uint16] | NDArray[np.float32] | NDArray[np.float64],
    *,
    min_arc_points: int = 12,
    min_semi_minor: float = 2.0,
    max_semi_major: float | None = None,
    max_gap: float | None = None,
    blur_sigma: float = 0.0,
    max_nfa: float = 1.0,
    max_line_width: float | None = None,
    gradient_noise: float | None = None,
) -> list[EllipseDetection]:
    """Detect ellipses; see :func:`autoteach.detect.detect_ellipses`."""

def wafer_rims_detect(
    image: NDArray[np.uint8] | NDArray[np.uint16] | NDArray[np.float32] | NDArray[np.float64],
    *,
    radius: float = 75.0,
    thickness: float = 0.775,
    up: tuple[float, float] = (0.0, -1.0),
    semi_major_range: tuple[float, float] | None = None,
    focal_length: float | None = None,
    min_arc_points: int = 12,
    min_semi_minor: float = 2.0,
    max_gap: float | None = None,
    blur_sigma: float = 0.0,
    max_nfa: float = 1.0,
    gradient_noise: float | None = None,
) -> list[WaferEdge]:
    """Wafer rims by geometry; see :func:`autoteach.detect.detect_wafer_rims`."""

# --- end ellipse detection ---
# --- mapping (issue 32: occupancy-grid rasterization, seed 004 ch. 2) ---

class Rasterizer:
    """Table 2.1's rasterizers; see :class:`autoteach.mapping.Rasterizer`."""

    def __init__(
        self,
        method: str = "cover_composite",
        slice_size: int = 4,
        resolution: float = 0.1,
        covering: bool = True,
        cover_distance: float = 0.75,
        cover_angle: float = ...,
        angle_min: float = ...,
        angle_increment: float = ...,
        max_range: float = 30.0,
        log_odds_hit: float = ...,
        log_odds_miss: float = ...,
        prior: float = 0.0,
        threshold: float = 0.0,
    ) -> None: ...
    def update(
        self,
        node_ids: NDArray[np.int64],
        robot_ids: NDArray[np.int64],
        poses: F64Array,
        scan_rows: NDArray[np.int64],
        scans: F64Array,
    ) -> tuple[NDArray[np.int8], float, float, float, dict[str, _Any]]: ...
    def memory_bytes(self) -> int: ...
    def num_nodes(self) -> int: ...

class TeamSimulator:
    """The team simulator; see :class:`autoteach.mapping.TeamSimulator`."""

    def __init__(
        self,
        world: str = "showgrounds",
        robots: int | None = None,
        graphs: int | None = None,
        seed: int = 0,
        transients: bool = True,
        people: int | None = None,
        vehicles: int | None = None,
        max_range: float | None = None,
    ) -> None: ...
    def step(self) -> dict[str, _Any] | None: ...
    def ranges(self, ids: NDArray[np.int64]) -> F64Array: ...
    def transient_hits(self, id: int) -> F64Array: ...
    def walls(self) -> F64Array: ...
    def graphs(self) -> int: ...
    def extent(self) -> tuple[float, float]: ...
    def scan_geometry(self) -> tuple[float, float, float]: ...
    def transient_residue(
        self,
        cells: NDArray[np.int8],
        origin: tuple[float, float],
        resolution: float,
        ids: NDArray[np.int64],
        poses: F64Array,
        truth: F64Array,
        margin: float = 0.5,
    ) -> tuple[int, int, int]: ...

def mapping_wall_gaps(
    candidate: NDArray[np.int8],
    candidate_origin: tuple[float, float],
    reference: NDArray[np.int8],
    reference_origin: tuple[float, float],
    resolution: float,
    walls: F64Array,
    radius: int = 1,
) -> tuple[int, int]:
    """Wall samples and gaps; see :func:`autoteach.mapping.wall_gaps`."""

# --- end mapping ---

# --- radio (issue 33) ---

class RadioLogFit:
    """Log-distance fit of eq. 3.1; see :class:`autoteach.radio.LogFit`."""

    @staticmethod
    def fit(tx: F64Array, rx: F64Array, rss: F64Array) -> RadioLogFit: ...
    def predict(self, tx: F64Array, rx: F64Array) -> tuple[F64Array, F64Array]: ...
    @property
    def l0(self) -> float: ...
    @property
    def exponent(self) -> float: ...
    @property
    def residual_variance(self) -> float: ...
    @property
    def normal_inverse(self) -> F64Array: ...

class RadioMrgp:
    """Multi-robot Gaussian process; see :class:`autoteach.radio.MRGP`."""

    @staticmethod
    def fit(
        tx: F64Array,
        rx: F64Array,
        rss: F64Array,
        kernel: str = "swap",
        length_scale: float = 28.75,
        sigma_f: float = 1.0,
        sigma_d: float = 1.5,
        theta: float = 20.0,
        gamma: float = 3.0,
        optimize: bool = False,
    ) -> RadioMrgp: ...
    def update(self, tx: F64Array, rx: F64Array, rss: F64Array) -> None: ...
    def predict(self, tx: F64Array, rx: F64Array, variance: bool = False) -> tuple[F64Array, F64Array | None]: ...
    @property
    def params(self) -> dict[str, float]: ...
    @property
    def log_marginal_likelihood(self) -> float: ...
    @property
    def mean_params(self) -> tuple[float, float]: ...
    @property
    def nnz(self) -> tuple[int, int]: ...
    def __len__(self) -> int: ...

def radio_link_kernel(
    tx_a: F64Array,
    rx_a: F64Array,
    tx_b: F64Array,
    rx_b: F64Array,
    kernel: str = "swap",
    length_scale: float = 28.75,
    sigma_f: float = 1.0,
    theta: float = 20.0,
    gamma: float = 3.0,
) -> F64Array: ...

class RadioMrt:
    """Multi-robot tomography; see :class:`autoteach.radio.MRT`."""

    def __init__(self, bounds: tuple[float, float, float, float], cell: float = 3.0, lam: float = 0.1375) -> None: ...
    def add(self, tx: F64Array, rx: F64Array, rss: F64Array) -> None: ...
    def solve(self, cold: bool = False) -> float: ...
    def predict(self, tx: F64Array, rx: F64Array) -> F64Array: ...
    def solution(self) -> tuple[float, float, F64Array]: ...
    def stacked(self) -> tuple[list[int], list[int], list[float], list[float], int]: ...
    @property
    def factor_nnz(self) -> int: ...
    @property
    def shape(self) -> tuple[int, int]: ...
    def __len__(self) -> int: ...

class RadioMatte:
    """MATTE (Algorithms 3.1-3.2); see :class:`autoteach.radio.MATTE`."""

    def __init__(
        self,
        occupancy: F64Array,
        resolution: float,
        origin: tuple[float, float] = (0.0, 0.0),
        cell: float = 4.0,
        lam: float = 2.0,
        phi: float = 0.2,
        rho_free: float = -0.1,
        rho_structure: float = -0.3,
        weights: str = "length",
    ) -> None: ...
    def add(self, tx: F64Array, rx: F64Array, rss: F64Array) -> None: ...
    def solve(self, cold: bool = False) -> float: ...
    def predict(self, tx: F64Array, rx: F64Array) -> F64Array: ...
    def solution(self) -> tuple[float, float, F64Array]: ...
    def attenuation_map(self) -> F64Array: ...
    def stacked(self) -> tuple[list[int], list[int], list[float], list[float], int]: ...
    @property
    def factor_nnz(self) -> int: ...
    @property
    def shape(self) -> tuple[int, int]: ...
    def __len__(self) -> int: ...

def radio_simulate(
    environment: str,
    robots: int = 3,
    duration: float = 240.0,
    speed: float = 1.0,
    rate: float = 20.0,
    seed: int = 0,
    l0: float = -40.0,
    exponent: float = 22.0,
    sigma: float = 4.0,
    correlated_share: float = 0.5,
    correlation_length: float = 6.0,
    clutter: float = 0.4,
    lidar_range: float = 20.0,
) -> dict[str, _Any]: ...

# --- end radio ---
# --- segment (coloured point clouds, seed 004 ch. 4) ---

def segment_colored_cloud(
    points: F64Array,
    colors: _Any,
    normals: F64Array | None,
    graph: str,
    k: int,
    k_rgb: float,
    k_norm: float,
    edge_cut: float,
    min_size: int,
    criteria_name: str,
    viewpoint: F64Array,
) -> dict[str, _Any]:
    """Segmentation (Algorithm 4.1); see :func:`autoteach.segment.segment_cloud`."""

def colorize_points(
    points: F64Array, image: _Any, camera: Camera, t_cam_lidar: F64Array, splat_radius: int, depth_tolerance: float
) -> tuple[_Any, _Any]:
    """Co-registration (eq. 4.1); see :func:`autoteach.segment.colorize`."""

def simulate_colored_scan(
    scene_name: str,
    beam_step_deg: float,
    tilt_start_deg: float,
    tilt_end_deg: float,
    tilt_speed_deg_s: float,
    range_sigma: float,
    color_sigma: float,
    seed: int,
    render: bool,
) -> dict[str, _Any]:
    """Tilting-scanner and camera simulation; see :func:`autoteach.segment.simulate_scan`."""

def calibrate_lidar_camera(
    camera: Camera, points: F64Array, pixels: F64Array, initial: F64Array, sigma: float | None = None
) -> dict[str, _Any]:
    """Extrinsics from correspondences (eq. 4.2); see :func:`autoteach.segment.calibrate_extrinsics`."""

# --- end segment ---
# --- control (issue 31) ---

def control_tf_normalize(num: F64Array, den: F64Array) -> tuple[F64Array, F64Array]: ...
def control_roots(p: F64Array) -> tuple[F64Array, F64Array]: ...
def control_freq_resp(num: F64Array, den: F64Array, w: F64Array) -> tuple[F64Array, F64Array]: ...
def control_series(n1: F64Array, d1: F64Array, n2: F64Array, d2: F64Array) -> tuple[F64Array, F64Array]: ...
def control_parallel(n1: F64Array, d1: F64Array, n2: F64Array, d2: F64Array) -> tuple[F64Array, F64Array]: ...
def control_feedback(n1: F64Array, d1: F64Array, n2: F64Array, d2: F64Array) -> tuple[F64Array, F64Array]: ...
def control_margins(num: F64Array, den: F64Array) -> tuple[float, float, float, float]: ...
def control_bandwidth(num: F64Array, den: F64Array, dbdrop: float = -3.0) -> float: ...
def control_sensitivity_peak(num: F64Array, den: F64Array) -> tuple[float, float]: ...
def control_closed_loop_damping(num: F64Array, den: F64Array) -> float: ...
def control_lsim(num: F64Array, den: F64Array, u: F64Array, dt: float) -> F64Array: ...
def control_fit(
    omega: F64Array,
    h_re: F64Array,
    h_im: F64Array,
    num_order: int,
    den_order: int,
    *,
    integrators: int = 0,
    weights: F64Array | None = None,
    enforce_stable: bool = True,
) -> tuple[F64Array, F64Array, float, int]: ...
def control_joint_plants(joint: str, count: int = 6) -> list[dict[str, _Any]]: ...
def control_sine_sweep(
    num: F64Array, den: F64Array, omega: F64Array, noise: float, seed: int = 0
) -> tuple[F64Array, F64Array]: ...
def control_tune(
    plants: list[tuple[F64Array, F64Array]],
    sections: list[str],
    spec: dict[str, _Any],
    theta0: F64Array | None = None,
) -> dict[str, _Any]: ...
def control_evaluate(
    plants: list[tuple[F64Array, F64Array]], sections: list[str], theta: F64Array, spec: dict[str, _Any]
) -> dict[str, _Any]: ...
def control_baseline(plants: list[tuple[F64Array, F64Array]], spec: dict[str, _Any]) -> dict[str, _Any]: ...
def control_demo(
    noise: float = 0.01,
    seed: int = 0,
    sections: list[str] | None = None,
    move_jt2: float = 1.0,
    move_jt4: float = -1.5,
    duration: float = 0.8,
    settle: float = 0.4,
) -> dict[str, _Any]: ...

# --- end control ---

# --- uncertainty (boxes, JIoU, label posterior) ---

def uncertainty_iou(a: F64Array, b: F64Array) -> F64Array: ...
def uncertainty_jiou(
    a_mean: F64Array,
    a_cov: F64Array,
    b_mean: F64Array,
    b_cov: F64Array,
    grid: int = 30,
    samples: int = 64,
    seed: int = 0,
    pdq: bool = False,
) -> F64Array: ...
def uncertainty_jiou_grid(p1: F64Array, p2: F64Array) -> float: ...
def uncertainty_rasterize(
    boxes_: F64Array, weights: F64Array, grid_: tuple[float, float, float, float, int, int], pdq: bool = False
) -> tuple[F64Array, int]: ...
def uncertainty_spatial_sampled(
    mean: F64Array,
    cov: F64Array,
    grid_: tuple[float, float, float, float, int, int],
    samples: int = 256,
    seed: int = 0,
    pdq: bool = False,
) -> F64Array: ...
def uncertainty_pg_moments(mean: F64Array, cov: F64Array, points: F64Array, lattice: int = 20) -> F64Array: ...
def uncertainty_pdq_at(
    mean: F64Array, cov: F64Array, points: F64Array, samples: int = 1024, seed: int = 0
) -> F64Array: ...
def uncertainty_point_moments(mean: F64Array, cov: F64Array, v0: F64Array) -> tuple[F64Array, F64Array]: ...
def uncertainty_label(
    label: F64Array,
    points: F64Array,
    sigma: float,
    prior_cov: F64Array | None = None,
    spacing: float = 0.5,
    estimate_heading: bool = True,
) -> tuple[F64Array, F64Array, F64Array, float, int]: ...
def uncertainty_label_correspondences(
    label: F64Array,
    points: F64Array,
    v0: F64Array,
    sigma: float,
    prior_cov: F64Array | None = None,
    estimate_heading: bool = True,
) -> tuple[F64Array, F64Array, F64Array, float, int]: ...
def uncertainty_estimate_noise(
    labels: F64Array,
    points: F64Array,
    counts: list[int],
    sigma0: float = 0.5,
    tolerance: float = 1e-8,
    max_iterations: int = 200,
) -> tuple[float, int, F64Array]: ...
def uncertainty_simulate_cars(
    n: int,
    sigma: float = 0.2,
    seed: int = 0,
    occlusion: float = 0.3,
    max_occluded: float = 0.5,
    azimuth_step_deg: float = 0.2,
    min_points: int = 10,
    range: tuple[float, float] = (6.0, 30.0),
) -> tuple[F64Array, F64Array, list[int]]: ...

# --- end uncertainty ---

# --- fusion (SHPL, max-min pooling) ---

class FusionSparsePooling:
    """The SHPL operator of one point cloud; see :class:`autoteach.fusion.SparsePooling`."""

    @staticmethod
    def build(
        points: F64Array,
        projection: F64Array,
        image_grid: tuple[int, int, float],
        bev_grid: tuple[float, float, float, int, int],
        neighbourhood: int = 1,
    ) -> FusionSparsePooling: ...
    def forward(self, direction: str, features: NDArray[np.floating]) -> NDArray[np.floating]: ...
    def backward(self, direction: str, grad: NDArray[np.floating]) -> NDArray[np.floating]: ...
    def csr(self, direction: str) -> tuple[NDArray[np.int64], NDArray[np.int64], F64Array, tuple[int, int]]: ...
    def dense(self, direction: str) -> F64Array: ...
    @property
    def kept(self) -> int: ...
    @property
    def dropped(self) -> dict[str, int]: ...
    @property
    def cells(self) -> tuple[int, int]: ...

def fusion_maxmin_pool(x: NDArray[np.floating]) -> NDArray[np.floating]: ...
def fusion_maxmin_pool_backward(x: NDArray[np.floating], grad_out: NDArray[np.floating]) -> NDArray[np.floating]: ...

# --- end fusion ---
# --- motion planning (issue 30): autoteach.plan ---

class PlanWorkspace:
    def __init__(self, obstacles: list[tuple[str, object, object]], wafer: bool = True) -> None: ...
    def clearance(self, q: object) -> tuple[float, str, str] | None: ...
    def distance_gradient(self, q: object) -> tuple[float, NDArray[np.float64]]: ...
    def obstacles(self) -> list[tuple[str, list[list[float]], list[float]]]: ...
    def joint_limits(self) -> tuple[list[float], list[float]]: ...
    def link_centres(self, q: object) -> list[tuple[str, list[float]]]: ...

def plan_default_scene() -> tuple[PlanWorkspace, list[tuple[str, list[float]]]]: ...
def plan_path(
    workspace: PlanWorkspace,
    q_start: object,
    q_goal: object,
    method: str = "rrt*",
    margin: float = 0.01,
    max_iterations: int = 3000,
    seed: int = 7,
    step_deg: float = 5.0,
    joints_planned: list[int] | None = None,
    time_limit_s: float | None = None,
) -> dict[str, object]: ...
def plan_optimize(
    workspace: PlanWorkspace,
    path: object,
    velocity: object,
    acceleration: object,
    jerk: object,
    torque: object,
    d_safe: float = 0.01,
    n_ctrl: int = 0,
    max_iterations: int = 40,
) -> dict[str, object]: ...
def plan_optimize_waypoints(
    workspace: PlanWorkspace,
    paths: list[object],
    velocity: object,
    acceleration: object,
    jerk: object,
    torque: object,
    d_safe: float = 0.01,
    free_velocities: bool = True,
    n_ctrl: int = 0,
    max_iterations: int = 40,
) -> dict[str, object]: ...
def plan_sample(
    knots: object, control_points: object, times: object
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]: ...
def plan_inverse_dynamics(q: object, dq: object, ddq: object, wafer: bool = True) -> NDArray[np.float64]: ...

# --- global registration (issue 29): autoteach.global_registration ---
class GlobalRegistration:
    @property
    def candidates(
        self,
    ) -> list[
        tuple[
            NDArray[np.float64],
            NDArray[np.float64],
            float,
            float,
            float,
            float | None,
            bool,
            NDArray[np.float64],
            NDArray[np.float64],
            int,
            int,
        ]
    ]:
        """``(R, t, sigma2, explained, log_likelihood, energy, equivalent, R0, t0, votes, pair_votes)``."""
    @property
    def symmetries(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]: ...
    @property
    def ambiguous(self) -> bool: ...
    @property
    def inlier_radius(self) -> float: ...
    @property
    def sigma2(self) -> float: ...
    @property
    def rigid(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]: ...
    @property
    def nonrigid(self) -> tuple[NDArray[np.float64], float] | None: ...

def global_register(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    k: int = 8,
    criterion: str = "explained",
    count: str = "y",
    w: float = 0.5,
    max_iterations: int = 10,
    max_refine_points: int = 100,
    window: float = 0.25,
    energy_all: bool = False,
    nonrigid: bool = False,
    beta: float = 2.0,
    lam: float = 2.0,
    symmetry_fraction: float = 0.9,
    neighbours: int = 10,
    angle_bin: float = 0.2,
    translation_bin: float | None = None,
    min_votes: int = 3,
    max_points: int = 200,
) -> GlobalRegistration: ...

# --- end global registration ---

# --- ellipse fits of many arcs in one call (issue 36) ---

def fit_ellipses(
    points: F64Array, offsets: NDArray[np.int64], method: Literal["direct", "geometric"] = "geometric"
) -> tuple[F64Array, F64Array, F64Array, F64Array, NDArray[np.int64], NDArray[np.bool_], list[str | None]]:
    """(params, residual_mean, residual_rms, covariance, iterations, converged, errors) of every arc.

    See :func:`autoteach.detect.fit_ellipses`.
    """

# --- end ellipse fits of many arcs ---
