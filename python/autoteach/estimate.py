"""Unscented Kalman filtering with a filterpy-compatible interface.

The filter of seed 000_3b1454b2b2194811.txt §5.2 (eqs. 5.1-5.2), computed in Rust
(:mod:`autoteach._core`). :class:`UnscentedKalmanFilter` and :class:`MerweScaledSigmaPoints`
mirror ``filterpy.kalman`` so that switching is a change of import::

    from autoteach.estimate import MerweScaledSigmaPoints, UnscentedKalmanFilter

    points = MerweScaledSigmaPoints(4, alpha=0.1, beta=2.0, kappa=-1.0)
    ukf = UnscentedKalmanFilter(dim_x=4, dim_z=2, dt=0.1, hx=hx, fx=fx, points=points)
    ukf.x = np.array([-1.0, 1.0, -1.0, 1.0])
    ukf.P *= 0.2
    ukf.R = np.diag([0.01, 0.01])
    for z in zs:
        ukf.predict()
        ukf.update(z)
    means, covariances = ukf.batch_filter(zs)

Two ways to give the model:

- **Python callbacks** (prototyping): ``fx(x, dt, **fx_args)`` and ``hx(x, **hx_args)`` plus
  the optional filterpy hooks ``x_mean_fn``, ``z_mean_fn``, ``residual_x``, ``residual_z``,
  ``state_add`` and the sigma points' ``sqrt_method``/``subtract``. They are called from Rust
  (holding the GIL), exactly where filterpy calls them; an exception they raise propagates
  unchanged.
- **Built-in models** (the fast path): pass a :class:`LinearModel` or
  :class:`ConstantVelocityModel` as ``fx`` (with ``hx=None``), or use
  :meth:`UnscentedKalmanFilter.from_model`. Then :meth:`UnscentedKalmanFilter.batch_filter`
  runs every step in Rust without returning to Python and with the GIL released. Control
  inputs are passed as ``predict(u=...)`` / ``batch_filter(..., us=...)``.

Beyond filterpy: ``square_root=True`` selects the square-root UKF (van der Merwe & Wan 2001);
``noise="augmented"`` augments the state with the noises (then callbacks are called as
``fx(x, dt, w, **fx_args)`` and ``hx(x, v, **hx_args)``, and Q, R have the noise dimensions
``dim_w``, ``dim_v``); ``repair=True`` clips the eigenvalues of a covariance that lost
positive definiteness instead of raising.

Errors: a wrong size, NaN/inf, an invalid parameter or a covariance that is not symmetric
positive definite when given raises :class:`~autoteach.errors.InvalidInputError`; a covariance
that loses positive definiteness (or a NaN) during filtering raises
:class:`~autoteach.errors.ConvergenceError` naming the step. Neither is ever propagated
silently.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable, Sequence
from copy import deepcopy
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach._sync import serialized
from autoteach.errors import InvalidInputError
from autoteach.geometry import so3_exp, so3_log
from autoteach.options import checked_replace
from autoteach.sigma_points import (
    JulierSigmaPoints,
    MerweScaledSigmaPoints,
    SimplexSigmaPoints,
    _is_default_sqrt,
    _is_default_subtract,
    _SigmaPoints,
    cholesky_upper,
    unscented_transform,
)

__all__ = [
    "BundleAdjustResult",
    "ConstantVelocityModel",
    "JulierSigmaPoints",
    "LeastSquaresProblem",
    "LinearModel",
    "MerweScaledSigmaPoints",
    "SimplexSigmaPoints",
    "SolverOptions",
    "SolverSummary",
    "UnscentedKalmanFilter",
    "bundle_adjust",
    "unscented_transform",
]

F64Array = NDArray[np.float64]
"""A float64 NumPy array."""


def _matrix(a: ArrayLike, name: str) -> F64Array:
    # as_f64 refuses complex, object, string, bool and datetime arrays (a cast would drop data).
    m = np.array(as_f64(a, name), dtype=np.float64, copy=True)
    if m.ndim != 2:
        raise InvalidInputError(f"{name} must be two-dimensional, got shape {m.shape}")
    return m


def _vector(a: ArrayLike, name: str) -> F64Array:
    return np.array(as_f64(a, name), dtype=np.float64, copy=True).reshape(-1)


class LinearModel:
    """Built-in linear model ``x' = F x + B u``, ``z = H x`` (noise additive; ``dt`` ignored).

    ``F`` is ``(n, n)``, ``H`` is ``(m, n)``, ``B`` (optional) is ``(n, k)``. :meth:`fx` and
    :meth:`hx` evaluate it in NumPy, so the same object can drive another filter library.
    """

    def __init__(self, F: ArrayLike, H: ArrayLike, B: ArrayLike | None = None) -> None:  # noqa: N803
        self.F = _matrix(F, "F")
        self.H = _matrix(H, "H")
        self.B = None if B is None else _matrix(B, "B")
        self._inner = _core.UkfLinearModel(self.F, self.H, self.B)

    @property
    def dim_x(self) -> int:
        """State dimension."""
        return int(self._inner.dim_x)

    @property
    def dim_z(self) -> int:
        """Measurement dimension."""
        return int(self._inner.dim_z)

    @property
    def dim_u(self) -> int:
        """Input dimension (0 without ``B``)."""
        return int(self._inner.dim_u)

    def fx(self, x: ArrayLike, dt: float, u: ArrayLike | None = None) -> F64Array:
        """``F x (+ B u)``."""
        out = self.F @ np.asarray(x, dtype=np.float64)
        if u is not None and self.B is not None:
            out = out + self.B @ np.asarray(u, dtype=np.float64)
        return out

    def hx(self, x: ArrayLike) -> F64Array:
        """``H x``."""
        return self.H @ np.asarray(x, dtype=np.float64)

    def __deepcopy__(self, memo: dict[int, Any]) -> LinearModel:
        return LinearModel(self.F, self.H, self.B)

    def __repr__(self) -> str:
        return f"LinearModel(dim_x={self.dim_x}, dim_z={self.dim_z}, dim_u={self.dim_u})"


class ConstantVelocityModel:
    """Built-in constant-velocity model in ``dim`` dimensions.

    State ``[p; v]`` (positions first, ``2 dim`` entries); over a step ``dt`` (the ``dt`` of each
    prediction) ``p' = p + v dt + a dt**2 / 2``, ``v' = v + a dt`` with the optional input
    ``u = a`` (``dim`` accelerations); measurement ``z = p``. ``dt`` here is the default time
    step of a filter made by :meth:`UnscentedKalmanFilter.from_model`.
    """

    def __init__(self, dim: int, dt: float = 1.0) -> None:
        self.dim = int(dim)
        self.dt = as_float(dt, "dt")
        self._inner = _core.UkfConstantVelocityModel(self.dim)

    @property
    def dim_x(self) -> int:
        """State dimension (``2 dim``)."""
        return 2 * self.dim

    @property
    def dim_z(self) -> int:
        """Measurement dimension (``dim``)."""
        return self.dim

    @property
    def dim_u(self) -> int:
        """Input dimension (``dim``)."""
        return self.dim

    def fx(self, x: ArrayLike, dt: float, u: ArrayLike | None = None) -> F64Array:
        """The state after ``dt``."""
        x = np.asarray(x, dtype=np.float64)
        a = np.zeros(self.dim) if u is None else np.asarray(u, dtype=np.float64)
        p, v = x[: self.dim], x[self.dim :]
        return np.concatenate([p + v * dt + 0.5 * a * dt * dt, v + a * dt])

    def hx(self, x: ArrayLike) -> F64Array:
        """The positions."""
        return np.asarray(x, dtype=np.float64)[: self.dim].copy()

    def __deepcopy__(self, memo: dict[int, Any]) -> ConstantVelocityModel:
        return ConstantVelocityModel(self.dim, self.dt)

    def __repr__(self) -> str:
        return f"ConstantVelocityModel(dim={self.dim}, dt={self.dt})"


_BUILTIN = (LinearModel, ConstantVelocityModel)


def _noise(v: ArrayLike, d: int, name: str) -> F64Array:
    """A noise covariance attribute as a ``(d, d)`` matrix.

    A scalar (or 1-element array) is broadcast to every entry, as filterpy's ``P += noise_cov`` does.
    """
    m = as_f64(v, name)
    if m.ndim < 2 and m.size == 1:
        return np.full((d, d), float(m.reshape(-1)[0]))
    return _matrix(m, name)


def _points_args(points: Any, dim_x: int, builtin: bool) -> dict[str, Any]:
    """The compiled filter's sigma-point arguments for ``points``.

    One of our families (with its non-default hooks), or an external object (filterpy's, or any
    with ``Wm``, ``Wc``, ``sigma_points`` and ``num_sigmas``) whose ``sigma_points`` the filter calls.
    """
    if isinstance(points, _SigmaPoints):
        if points.n != dim_x:
            raise InvalidInputError(f"points.n = {points.n} must equal dim_x = {dim_x}")
        sqrt, sub = points._hooks()
        return {
            "family_name": points._family,
            "alpha": points.alpha,
            "beta": points.beta,
            "kappa": points.kappa,
            "sqrt": sqrt,
            "subtract": sub,
        }
    missing = [a for a in ("Wm", "Wc", "sigma_points", "num_sigmas") if not hasattr(points, a)]
    if missing:
        raise InvalidInputError(f"points must be a sigma-point object; {type(points).__name__} has no {missing}")
    n = getattr(points, "n", dim_x)
    if n != dim_x:
        raise InvalidInputError(f"points.n = {n} must equal dim_x = {dim_x}")
    wm = np.asarray(points.Wm, dtype=np.float64).reshape(-1)
    wc = np.asarray(points.Wc, dtype=np.float64).reshape(-1)
    if wm.size != points.num_sigmas() or wc.size != wm.size:
        raise InvalidInputError(
            f"points.Wm ({wm.size}) and points.Wc ({wc.size}) must have num_sigmas() = {points.num_sigmas()} entries"
        )
    if not builtin:
        return {
            "family_name": "merwe",
            "alpha": 1.0,
            "beta": 0.0,
            "kappa": 0.0,
            "draw": points.sigma_points,
            "wm": wm,
            "wc": wc,
        }
    # A built-in model draws in Rust: filterpy's own families (default sqrt and subtract) map
    # onto ours; the weights must then agree.
    ours = _as_ours(points)
    if ours is None:
        raise InvalidInputError(
            f"a built-in model needs autoteach's sigma points (or filterpy's with the default sqrt_method and "
            f"subtract), got {type(points).__name__}: pass Python callbacks for other sigma points"
        )
    if not (np.allclose(ours.Wm, wm, rtol=1e-12, atol=1e-12) and np.allclose(ours.Wc, wc, rtol=1e-12, atol=1e-12)):
        raise InvalidInputError(f"the weights of {type(points).__name__} are not those of its family")
    return _points_args(ours, dim_x, builtin)


def _as_ours(points: Any) -> _SigmaPoints | None:
    """Our family equal to filterpy's sigma-point object ``points`` (default hooks), else ``None``."""
    name = type(points).__name__
    if not (
        _is_default_sqrt(getattr(points, "sqrt", None)) and _is_default_subtract(getattr(points, "subtract", None))
    ):
        return None
    if name == "MerweScaledSigmaPoints":
        return MerweScaledSigmaPoints(points.n, points.alpha, points.beta, points.kappa)
    if name == "JulierSigmaPoints":
        return JulierSigmaPoints(points.n, points.kappa)
    if name == "SimplexSigmaPoints":
        return SimplexSigmaPoints(points.n, getattr(points, "alpha", 1.0))
    return None


def _log_gauss(y: F64Array, S: F64Array) -> float:  # noqa: N803
    """``log N(y; 0, S)``, with the pseudo-inverse and -determinant of a singular ``S`` (scipy's ``allow_singular``)."""
    w, v = np.linalg.eigh(S)
    eps = 1e6 * np.finfo(np.float64).eps * max(float(np.abs(w).max()), 1e-300)
    keep = w > eps
    proj = v[:, keep].T @ y
    maha = float(np.sum(proj**2 / w[keep]))
    return -0.5 * (maha + float(np.sum(np.log(w[keep]))) + int(keep.sum()) * math.log(2.0 * math.pi))


@serialized
class UnscentedKalmanFilter:
    """Unscented Kalman filter with filterpy's interface (``filterpy.kalman.UnscentedKalmanFilter``).

    A drop-in replacement: filterpy's own test suite passes with only its import changed
    (``benchmarks/filterpy_suite.py``). The filter of seed 000_3b1454b2b2194811.txt §5.2.

    Args:
        dim_x: State dimension.
        dim_z: Measurement dimension.
        dt: Default time step of :meth:`predict`.
        hx: Measurement function ``hx(x, **hx_args)``, or ``None`` with a built-in model.
        fx: Process function ``fx(x, dt, **fx_args)``, or a :class:`LinearModel` /
            :class:`ConstantVelocityModel` (the fast path).
        points: Sigma points with ``n == dim_x``: :class:`MerweScaledSigmaPoints`,
            :class:`JulierSigmaPoints`, :class:`SimplexSigmaPoints` (drawn in Rust, with their
            ``sqrt_method``/``subtract`` hooks if given), or any object with ``Wm``, ``Wc``,
            ``sigma_points(x, P)`` and ``num_sigmas()`` such as filterpy's (its weights are read
            and its ``sigma_points`` called, exactly as filterpy does).
        sqrt_fn: Kept as ``self.msqrt`` (like filterpy, the square root actually used is the
            sigma points' ``sqrt_method``).
        x_mean_fn: ``x_mean_fn(sigmas, Wm)`` mean of state sigma points ``(N, n)``.
        z_mean_fn: Likewise for measurement sigma points.
        residual_x: ``residual_x(a, b)`` state difference (e.g. wrapping angles).
        residual_z: ``residual_z(a, b)`` measurement difference.
        state_add: ``state_add(x, dx)`` used for ``x + K y``.
        square_root: Use the square-root UKF.
        noise: ``"additive"`` (filterpy's form) or ``"augmented"``.
        repair: Clip eigenvalues of a covariance that loses positive definiteness (default:
            raise :class:`~autoteach.errors.ConvergenceError`).
        dim_w: Process-noise dimension in the augmented form (default ``dim_x``).
        dim_v: Measurement-noise dimension in the augmented form (default ``dim_z``).
        vectorized: ``fx`` and ``hx`` take ALL sigma points at once: ``fx(sigmas, dt, **fx_args)``
            with ``sigmas`` of shape ``(num_sigmas, dim_x)`` (one point per row) returns
            ``(num_sigmas, dim_x)``, ``hx(sigmas, **hx_args)`` returns ``(num_sigmas, dim_z)``
            (``(num_sigmas,)`` when ``dim_z == 1``). One Python call per transform instead of one
            per sigma point; the results are those of the per-point form. Additive noise only.
            A returned array of another shape, or with NaN/inf, raises
            :class:`~autoteach.errors.InvalidInputError`.

    Attributes ``x``, ``P``, ``Q``, ``R`` are NumPy arrays you may set or modify in place (a
    scalar ``Q`` or ``R`` is broadcast as filterpy's ``P += noise`` does); ``x_prior``,
    ``P_prior`` (set by :meth:`predict`), ``x_post``, ``P_post`` (set by :meth:`update`), ``K``,
    ``y``, ``S``, ``SI``, ``z``, ``sigmas_f``, ``sigmas_h``, ``log_likelihood``, ``likelihood``,
    ``mahalanobis``, ``inv`` and ``msqrt`` are as in filterpy. ``predict``/``update``/
    ``batch_filter``/``rts_smoother`` run in Rust unless a custom ``UT``, an overridden
    ``inv`` or per-epoch ``Fs`` asks for filterpy's Python formulation, which is then followed
    step by step (with the same results).
    """

    # The compiled filter and the sync bookkeeping live in slots, outside ``__dict__``, so that
    # tools that deep-copy ``__dict__`` (filterpy's ``Saver``) see only filterpy's attributes.
    __slots__ = ("__dict__", "_inner", "_lock", "_synced")

    def __init__(
        self,
        dim_x: int,
        dim_z: int,
        dt: float,
        hx: Callable[..., ArrayLike] | None,
        fx: Callable[..., ArrayLike] | LinearModel | ConstantVelocityModel,
        points: Any,
        sqrt_fn: Callable[[F64Array], ArrayLike] | None = None,
        x_mean_fn: Callable[[F64Array, F64Array], ArrayLike] | None = None,
        z_mean_fn: Callable[[F64Array, F64Array], ArrayLike] | None = None,
        residual_x: Callable[[F64Array, F64Array], ArrayLike] | None = None,
        residual_z: Callable[[F64Array, F64Array], ArrayLike] | None = None,
        state_add: Callable[[F64Array, F64Array], ArrayLike] | None = None,
        *,
        square_root: bool = False,
        noise: Literal["additive", "augmented"] = "additive",
        repair: bool = False,
        dim_w: int | None = None,
        dim_v: int | None = None,
        vectorized: bool = False,
    ) -> None:
        if noise not in ("additive", "augmented"):
            raise InvalidInputError(f"noise must be 'additive' or 'augmented', got {noise!r}")
        augmented = noise == "augmented"
        self._model = fx if isinstance(fx, _BUILTIN) else None
        if not isinstance(vectorized, bool | np.bool_):
            raise InvalidInputError(f"vectorized must be a bool, got {type(vectorized).__name__}")
        self.vectorized = bool(vectorized)
        if self.vectorized and self._model is not None:
            raise InvalidInputError("vectorized applies to Python fx/hx callbacks; a built-in model is already batched")
        if self.vectorized and augmented:
            raise InvalidInputError(
                "vectorized fx/hx need noise='additive' (the augmented form passes each point's noise)"
            )
        spec = _points_args(points, int(dim_x), builtin=self._model is not None)
        if "draw" in spec and (square_root or augmented):
            raise InvalidInputError(
                "external sigma points (e.g. filterpy's) run in the standard filter with additive noise; "
                "use autoteach's sigma-point classes for square_root=True or noise='augmented'"
            )
        if self._model is not None:
            model = self._model
            if hx is not None and hx is not model:
                raise InvalidInputError("with a built-in model as fx, hx must be None (the model measures)")
            if (model.dim_x, model.dim_z) != (dim_x, dim_z):
                raise InvalidInputError(
                    f"the model has dim_x={model.dim_x}, dim_z={model.dim_z}; got dim_x={dim_x}, dim_z={dim_z}"
                )
            hooks = [x_mean_fn, z_mean_fn, residual_x, residual_z, state_add, spec["sqrt"], spec["subtract"]]
            if any(h is not None for h in hooks) or dim_w is not None or dim_v is not None:
                raise InvalidInputError(
                    "built-in models use vector-space means and residuals; pass Python callbacks for custom hooks"
                )
            self._inner = _core.UkfFilter.builtin(
                model._inner,
                spec["alpha"],
                spec["beta"],
                spec["kappa"],
                square_root=square_root,
                augmented=augmented,
                repair=repair,
                family_name=spec["family_name"],
            )
        else:
            if not callable(fx) or not callable(hx):
                raise InvalidInputError("fx and hx must be callables (or fx a built-in model with hx=None)")
            self._inner = _core.UkfFilter.callbacks(
                int(dim_x),
                int(dim_z),
                fx,
                hx,
                spec["alpha"],
                spec["beta"],
                spec["kappa"],
                x_mean=x_mean_fn,
                z_mean=z_mean_fn,
                residual_x=residual_x,
                residual_z=residual_z,
                state_add=state_add,
                subtract=spec.get("subtract"),
                sqrt=spec.get("sqrt"),
                square_root=square_root,
                augmented=augmented,
                repair=repair,
                dim_w=dim_w,
                dim_v=dim_v,
                family_name=spec["family_name"],
                draw=spec.get("draw"),
                wm=spec.get("wm"),
                wc=spec.get("wc"),
                vectorized=self.vectorized,
            )
        self._dim_x = int(dim_x)
        self._dim_z = int(dim_z)
        self._dt = as_float(dt, "dt")
        self.points_fn = points
        self._num_sigmas = int(points.num_sigmas())
        self.fx = fx
        self.hx = hx
        self.x_mean = x_mean_fn
        self.z_mean = z_mean_fn
        self.residual_x = residual_x if residual_x is not None else np.subtract
        self.residual_z = residual_z if residual_z is not None else np.subtract
        self.state_add = state_add if state_add is not None else np.add
        self.msqrt = sqrt_fn if sqrt_fn is not None else cholesky_upper
        self.Wm, self.Wc = np.asarray(points.Wm, dtype=np.float64), np.asarray(points.Wc, dtype=np.float64)
        self.square_root = bool(square_root)
        self.noise = noise
        self.repair = bool(repair)
        self.inv = np.linalg.inv
        self._init_state(int(dim_x), int(dim_z))

    def _init_state(self, dim_x: int, dim_z: int) -> None:
        """The filterpy attributes of a fresh filter: state, covariances, gain, residual, buffers."""
        self.x: F64Array = np.zeros(dim_x)
        self.P: F64Array = np.eye(dim_x)
        self.Q: F64Array = np.asarray(self._inner.Q)
        self.R: F64Array = np.asarray(self._inner.R)
        self._noise_dims = (self.Q.shape[0], self.R.shape[0])
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()
        self.K = np.zeros((dim_x, dim_z))
        self.y = np.zeros(dim_z)
        self.S = np.zeros((dim_z, dim_z))
        self.SI = np.zeros((dim_z, dim_z))
        self.z = np.array([[None] * dim_z]).T
        # filterpy's sigmas_f / sigmas_h: arrays, or None while the filter can derive them
        # (the prior's sigma points; hx of those) when first read.
        self._sigmas_f: F64Array | None = np.zeros((self._num_sigmas, self._dim_x))
        self._sigmas_h: F64Array | None = np.zeros((self._num_sigmas, self._dim_z))
        self._last_hx: tuple[Callable[..., ArrayLike] | None, dict[str, Any]] = (None, {})
        self._log_likelihood: float | None = math.log(sys.float_info.min)
        self._likelihood: float | None = sys.float_info.min
        self._mahalanobis: float | None = None
        self._synced: tuple[F64Array, F64Array, F64Array, F64Array] | None = None

    @classmethod
    def from_model(
        cls,
        model: LinearModel | ConstantVelocityModel,
        points: Any,
        dt: float | None = None,
        **options: Any,
    ) -> UnscentedKalmanFilter:
        """A filter on a built-in model (the fast path); ``dt`` defaults to the model's ``dt`` (or 1).

        ``options`` are the keyword-only options of the constructor (``square_root``,
        ``noise``, ``repair``).
        """
        if not isinstance(model, _BUILTIN):
            raise InvalidInputError(f"model must be a LinearModel or ConstantVelocityModel, got {type(model).__name__}")
        if dt is None:
            dt = getattr(model, "dt", 1.0)
        return cls(model.dim_x, model.dim_z, dt, None, model, points, **options)

    # -- synchronisation with the compiled filter ---------------------------------------------

    def _qr(self) -> tuple[F64Array, F64Array]:
        q_dim, r_dim = self._noise_dims
        return _noise(self.Q, q_dim, "Q"), _noise(self.R, r_dim, "R")

    def _push(self) -> None:
        """Sends x, P, Q, R to the compiled filter if they changed since the last sync."""
        x = _vector(self.x, "x")
        P = _matrix(self.P, "P")  # noqa: N806
        Q, R = self._qr()  # noqa: N806
        old = self._synced
        if old is not None and all(np.array_equal(a, b) for a, b in zip((x, P, Q, R), old, strict=True)):
            return
        self._inner.set_state(
            x=x if old is None or not np.array_equal(x, old[0]) else None,
            p=P if old is None or not np.array_equal(P, old[1]) else None,
            q=Q if old is None or not np.array_equal(Q, old[2]) else None,
            r=R if old is None or not np.array_equal(R, old[3]) else None,
        )
        self._synced = (x, P, Q, R)

    def _pull(self, *, prior: bool, post: bool) -> None:
        inner = self._inner
        column = np.ndim(self.x) == 2
        x = np.asarray(inner.x)
        self.x = x.reshape(-1, 1) if column else x
        self.P = np.asarray(inner.P)
        if prior:
            self.x_prior = self.x.copy()
            self.P_prior = self.P.copy()
            self._sigmas_f = None
        if post:
            self.x_post = self.x.copy()
            self.P_post = self.P.copy()
        # Q and R are those sent by the _push that preceded this call.
        Q, R = self._qr() if self._synced is None else self._synced[2:]  # noqa: N806
        self._synced = (x.copy(), self.P.copy(), Q, R)

    def _custom(self, UT: Any) -> bool:  # noqa: N803
        """True when filterpy's Python formulation must be followed (a custom UT or inverse)."""
        return UT is not None or self.inv is not np.linalg.inv

    def _after_update(self, z: Any) -> None:
        """Reads the compiled filter's update results into filterpy's attributes."""
        inner = self._inner
        self.K = np.asarray(inner.K)
        self.y = np.asarray(inner.y)
        self.S = np.asarray(inner.S)
        self.SI = self.inv(self.S)
        self.z = deepcopy(z)
        self._sigmas_h = None
        self._log_likelihood = float(inner.log_likelihood)
        self._likelihood = None
        self._mahalanobis = None

    # -- filterpy interface --------------------------------------------------------------------

    @property
    def sigmas_f(self) -> F64Array:
        """Sigma points ``(num_sigmas, dim_x)``.

        After :meth:`predict` those of the prior (redrawn, as filterpy); after
        :meth:`compute_process_sigmas` their images under ``fx``.
        """
        if self._sigmas_f is None:
            self._sigmas_f = np.asarray(
                self._inner.sigma_points(_vector(self.x_prior, "x"), _matrix(self.P_prior, "P"))
            )
        return self._sigmas_f

    @sigmas_f.setter
    def sigmas_f(self, value: ArrayLike) -> None:
        self._sigmas_f = np.asarray(value, dtype=np.float64)

    @property
    def sigmas_h(self) -> F64Array:
        """``hx`` of :attr:`sigmas_f` at the last :meth:`update`; ``(num_sigmas, dim_z)``."""
        if self._sigmas_h is None:
            hx, hx_args = self._last_hx
            self._sigmas_h = self._apply(self._hx(hx), "hx", self.sigmas_f, (), hx_args, self._dim_z)
        return self._sigmas_h

    @sigmas_h.setter
    def sigmas_h(self, value: ArrayLike) -> None:
        self._sigmas_h = np.asarray(value, dtype=np.float64)

    def _fx(self, fx: Callable[..., ArrayLike] | None) -> Callable[..., ArrayLike]:
        if fx is not None:
            return fx
        return self._model.fx if self._model is not None else self.fx  # type: ignore[return-value]

    def _hx(self, hx: Callable[..., ArrayLike] | None) -> Callable[..., ArrayLike]:
        if hx is not None:
            return hx
        return self._model.hx if self._model is not None else self.hx  # type: ignore[return-value]

    def compute_process_sigmas(
        self, dt: float | None = None, fx: Callable[..., ArrayLike] | None = None, **fx_args: Any
    ) -> None:
        """``sigmas_f[i] = fx(sigma_i, dt, **fx_args)`` for the sigma points of the current (x, P), as filterpy."""
        dt = self._dt if dt is None else as_float(dt, "dt")
        f = self._fx(fx)
        sigmas = np.asarray(self.points_fn.sigma_points(self.x, self.P), dtype=np.float64)
        self._sigmas_f = self._apply(f, "fx", sigmas, (dt,), fx_args, self._dim_x)

    def _apply(
        self, f: Callable[..., ArrayLike], name: str, sigmas: F64Array, args: tuple, kwargs: dict[str, Any], dim: int
    ) -> F64Array:
        """``f`` of every row of ``sigmas`` as a ``(N, dim)`` array: one call when vectorised, else one per row."""
        if not self.vectorized:
            return np.atleast_2d(
                np.array([np.asarray(f(s, *args, **kwargs), dtype=np.float64).reshape(-1) for s in sigmas])
            )
        out = np.asarray(f(sigmas, *args, **kwargs), dtype=np.float64)
        n = sigmas.shape[0]
        if out.shape == (n,) and dim == 1:
            out = out.reshape(n, 1)
        if out.shape != (n, dim):
            raise InvalidInputError(
                f"{name} (vectorized) returned an array of shape {out.shape}, expected ({n}, {dim}): "
                "one row per sigma point"
            )
        if not np.isfinite(out).all():
            raise InvalidInputError(f"{name} (vectorized) returned non-finite values")
        return out

    def cross_variance(self, x: ArrayLike, z: ArrayLike, sigmas_f: ArrayLike, sigmas_h: ArrayLike) -> F64Array:
        """``Pxz = sum_i Wc_i residual_x(sigmas_f[i], x) residual_z(sigmas_h[i], z)^T``."""
        sf = np.atleast_2d(np.asarray(sigmas_f, dtype=np.float64))
        sh = np.atleast_2d(np.asarray(sigmas_h, dtype=np.float64))
        if sf.shape[0] != self.Wc.size or sh.shape[0] != self.Wc.size:
            raise InvalidInputError(
                f"sigmas_f ({sf.shape[0]}) and sigmas_h ({sh.shape[0]}) must have {self.Wc.size} rows (sigma points)"
            )
        pxz = np.zeros((sf.shape[1], sh.shape[1]))
        for i in range(sf.shape[0]):
            dx = np.asarray(self.residual_x(sf[i], x), dtype=np.float64).reshape(-1)
            dz = np.asarray(self.residual_z(sh[i], z), dtype=np.float64).reshape(-1)
            pxz += self.Wc[i] * np.outer(dx, dz)
        return pxz

    def predict(
        self,
        dt: float | None = None,
        UT: Callable[..., tuple[ArrayLike, ArrayLike]] | None = None,  # noqa: N803
        fx: Callable[..., ArrayLike] | None = None,
        **fx_args: Any,
    ) -> None:
        """Predict over ``dt`` (default the constructor's); ``fx_args`` go to ``fx``.

        With a built-in model, ``u=`` is the control input. ``UT(sigmas, Wm, Wc, Q, x_mean_fn,
        residual_x)`` replaces the unscented transform (then the step follows filterpy in Python).
        """
        dt = self._dt if dt is None else as_float(dt, "dt")
        if UT is not None:
            self._predict_python(dt, UT, fx, fx_args)
            return
        self._push()
        if self._model is not None:
            u = fx_args.pop("u", None)
            if fx is not None or fx_args:
                raise InvalidInputError("a built-in model takes only u= in predict() (or a custom UT)")
            self._inner.predict(dt, u=None if u is None else _vector(u, "u"))
        else:
            self._inner.predict(dt, fx_kwargs=fx_args or None, fx=fx)
        self._pull(prior=True, post=False)

    def _ut(self, UT: Any, sigmas: F64Array, noise: F64Array, mean: Any, residual: Any) -> tuple[F64Array, F64Array]:  # noqa: N803
        out = UT(sigmas, self.Wm, self.Wc, noise, mean, residual)
        try:
            m, c = out
            return np.asarray(m, dtype=np.float64), np.atleast_2d(np.asarray(c, dtype=np.float64))
        except (TypeError, ValueError):
            raise InvalidInputError(f"UT must return (mean, covariance), got {type(out).__name__}") from None

    def _predict_python(self, dt: float, UT: Any, fx: Any, fx_args: dict[str, Any]) -> None:  # noqa: N803
        if self.noise != "additive":
            raise InvalidInputError("a custom UT needs additive noise")
        self.compute_process_sigmas(dt, fx, **fx_args)
        x, P = self._ut(UT or unscented_transform, self.sigmas_f, self.Q, self.x_mean, self.residual_x)  # noqa: N806
        self.x, self.P = x, P
        self._sigmas_f = np.asarray(self.points_fn.sigma_points(self.x, self.P), dtype=np.float64)
        self.x_prior = np.copy(self.x)
        self.P_prior = np.copy(self.P)

    def update(
        self,
        z: ArrayLike | None,
        R: ArrayLike | float | None = None,  # noqa: N803
        UT: Callable[..., tuple[ArrayLike, ArrayLike]] | None = None,  # noqa: N803
        hx: Callable[..., ArrayLike] | None = None,
        **hx_args: Any,
    ) -> None:
        """Update with measurement ``z`` (``None``: no measurement); ``R`` overrides ``self.R`` once.

        A custom ``UT`` or an overridden ``self.inv`` makes the step follow filterpy in Python.
        """
        if z is None:
            self.z = np.array([[None] * self._dim_z]).T
            self.x_post = self.x.copy()
            self.P_post = self.P.copy()
            self._inner.skip_update()
            return
        if R is not None:
            R = np.eye(self._dim_z) * as_float(R, "R") if np.ndim(R) == 0 else _matrix(R, "R")  # noqa: N806
        if self._model is not None and (hx is not None or hx_args) and not self._custom(UT):
            raise InvalidInputError("a built-in model takes no hx override or arguments in update()")
        if self._custom(UT):
            self._update_python(z, R, UT or unscented_transform, hx, hx_args)
            return
        self._push()
        if self._model is not None:
            self._inner.update(_vector(z, "z"), r=R)
        else:
            self._inner.update(_vector(z, "z"), r=R, hx_kwargs=hx_args or None, hx=hx)
        self._last_hx = (hx, dict(hx_args))
        self._pull(prior=False, post=True)
        self._after_update(z)

    def _update_python(self, z: Any, R: Any, UT: Any, hx: Any, hx_args: dict[str, Any]) -> None:  # noqa: N803
        if self.noise != "additive":
            raise InvalidInputError("a custom UT or inv needs additive noise")
        h = self._hx(hx)
        R = _noise(self.R, self._dim_z, "R") if R is None else R  # noqa: N806
        sigmas_f = self.sigmas_f
        sigmas_h = self._apply(h, "hx", np.asarray(sigmas_f, dtype=np.float64), (), hx_args, self._dim_z)
        zp, S = self._ut(UT, sigmas_h, R, self.z_mean, self.residual_z)  # noqa: N806
        SI = np.asarray(self.inv(S), dtype=np.float64)  # noqa: N806
        pxz = self.cross_variance(self.x, zp, sigmas_f, sigmas_h)
        K = pxz @ SI  # noqa: N806
        y = np.asarray(self.residual_z(np.asarray(z, dtype=np.float64).reshape(-1), zp), dtype=np.float64)
        self.x = np.asarray(self.state_add(self.x, K @ y), dtype=np.float64)
        self.P = self.P - K @ S @ K.T
        self.K, self.y, self.S, self.SI = K, y, S, SI
        self._sigmas_h = sigmas_h
        self.z = deepcopy(z)
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()
        self._log_likelihood = None
        self._likelihood = None
        self._mahalanobis = None

    def batch(
        self,
        zs: Sequence[ArrayLike | None] | ArrayLike,
        us: ArrayLike | None = None,
        dts: ArrayLike | float | None = None,
        Rs: ArrayLike | None = None,  # noqa: N803
        *,
        priors: bool = True,
    ) -> dict[str, F64Array]:
        """Run predict/update for every measurement in one call into Rust.

        ``zs``: ``(n, dim_z)`` (``None`` entries are missing measurements); ``us``: ``(n, dim_u)``
        control inputs (built-in models); ``dts``: scalar or ``(n,)``; ``Rs``: ``(n, dim_z, dim_z)``,
        ``(n,)`` scalars or a list with ``None`` for ``self.R``. Returns ``xs``, ``Ps`` (posteriors),
        ``log_likelihoods`` (NaN where missing) and, with ``priors``, ``x_priors``, ``P_priors``.
        The filter ends in the last posterior.
        """
        n = len(zs)  # type: ignore[arg-type]
        Z, mask = self._measurements(zs, n)  # noqa: N806
        if us is not None and self._model is None:
            raise InvalidInputError("us is only for built-in models; pass inputs to callbacks via predict(**fx_args)")
        u_arr = None if us is None else as_f64(us, "us")
        if u_arr is not None and u_arr.ndim == 1:
            u_arr = u_arr[:, None]
        dt_arr = None
        if dts is not None:
            dt_arr = np.full(n, as_float(dts, "dts")) if np.ndim(dts) == 0 else as_f64(dts, "dts")
        r_arr = None if Rs is None else self._rs(Rs, n)
        self._push()
        try:
            out = self._inner.batch(
                Z, self._dt, mask=None if all(mask) else mask, us=u_arr, dts=dt_arr, rs=r_arr, priors=priors
            )
        finally:
            # On error the compiled filter holds the last completed stage: mirror it.
            self._pull(prior=False, post=True)
        if n:
            self.x_prior = np.asarray(self._inner.x_prior)
            self.P_prior = np.asarray(self._inner.P_prior)
            self._sigmas_f = None
            if mask[-1]:
                self._last_hx = (None, {})
                self._after_update(zs[-1])  # type: ignore[index]
        return out

    def _rs(self, Rs: Any, n: int) -> F64Array:  # noqa: N803
        """Per-epoch measurement noises as ``(n, dim_z, dim_z)``: ``None`` is ``self.R``, a scalar ``r * I``."""
        if isinstance(Rs, np.ndarray) and Rs.ndim == 3:
            return as_f64(Rs, "Rs")
        items = list(Rs)
        if len(items) != n:
            raise InvalidInputError(f"Rs must have one entry per measurement ({n}), got {len(items)}")
        m = self._dim_z
        out = np.empty((n, m, m))
        for i, r in enumerate(items):
            if r is None:
                out[i] = _noise(self.R, m, "R")
            elif np.ndim(r) == 0:
                out[i] = np.eye(m) * as_float(r, f"Rs[{i}]")
            else:
                out[i] = _matrix(r, f"Rs[{i}]")
        return out

    def _measurements(self, zs: Any, n: int) -> tuple[F64Array, list[bool]]:
        """``zs`` as an ``(n, dim_z)`` array and the mask of present measurements."""
        if isinstance(zs, np.ndarray) or not any(z is None for z in zs):
            try:
                Z = as_f64(zs, "zs")  # noqa: N806
            except InvalidInputError:
                if isinstance(zs, np.ndarray):
                    raise
                Z = None  # noqa: N806 (ragged: reported per element below)
            if Z is not None and Z.size == n * self._dim_z and Z.shape[:1] == (n,):
                return Z.reshape(n, self._dim_z), [True] * n
        mask = [z is not None for z in zs]
        Z = np.zeros((n, self._dim_z))  # noqa: N806
        for i, z in enumerate(zs):
            if z is None:
                continue
            zi = as_f64(z, f"zs[{i}]").reshape(-1)
            if zi.size != self._dim_z:
                raise InvalidInputError(f"zs[{i}] must have {self._dim_z} values, got shape {np.shape(z)}")
            Z[i] = zi
        return Z, mask

    def batch_filter(
        self,
        zs: Sequence[ArrayLike | None] | ArrayLike,
        Rs: ArrayLike | None = None,  # noqa: N803
        dts: ArrayLike | float | None = None,
        UT: Callable[..., tuple[ArrayLike, ArrayLike]] | None = None,  # noqa: N803
        saver: Any = None,
        us: ArrayLike | None = None,
    ) -> tuple[F64Array, F64Array]:
        """Filter all measurements: ``(means (n, dim_x), covariances (n, dim_x, dim_x))`` as filterpy.

        Without ``saver`` (and without a custom ``UT`` or ``inv``) the whole run is one call into
        Rust (:meth:`batch`); otherwise it steps through :meth:`predict` / :meth:`update` and calls
        ``saver.save()`` after each epoch, as filterpy does.
        """
        n = len(zs)  # type: ignore[arg-type]
        if saver is None and not self._custom(UT):
            out = self.batch(zs, us=us, dts=dts, Rs=Rs, priors=False)
            means, covs = out["xs"], out["Ps"]
        else:
            means = np.zeros((n, self._dim_x))
            covs = np.zeros((n, self._dim_x, self._dim_x))
            dt_list = [self._dt] * n if dts is None else ([float(dts)] * n if np.ndim(dts) == 0 else list(dts))  # type: ignore[arg-type]
            r_list = [None] * n if Rs is None else list(Rs)  # type: ignore[arg-type]
            for i, z in enumerate(zs):  # type: ignore[arg-type]
                if us is not None:
                    self.predict(dt=dt_list[i], UT=UT, u=np.asarray(us)[i])
                else:
                    self.predict(dt=dt_list[i], UT=UT)
                self.update(z, r_list[i], UT=UT)
                means[i] = np.asarray(self.x).reshape(-1)
                covs[i] = self.P
                if saver is not None:
                    saver.save()
        if np.ndim(self.x) == 2:
            means = means[:, :, None]
        return means, covs

    def rts_smoother(
        self,
        Xs: ArrayLike,  # noqa: N803 (filterpy's names)
        Ps: ArrayLike,  # noqa: N803
        Qs: ArrayLike | None = None,  # noqa: N803
        dts: ArrayLike | float | None = None,
        UT: Callable[..., tuple[ArrayLike, ArrayLike]] | None = None,  # noqa: N803
        *,
        Fs: Sequence[Callable[..., ArrayLike]] | None = None,  # noqa: N803
        us: ArrayLike | None = None,
    ) -> tuple[F64Array, F64Array, F64Array]:
        """The unscented Rauch-Tung-Striebel smoother of a filtered run: ``(xs, Ps, Ks)`` as filterpy.

        ``Xs`` ``(n, dim_x)`` and ``Ps`` ``(n, dim_x, dim_x)`` are the filtered means and covariances
        (e.g. from :meth:`batch_filter`); ``Qs`` one process noise per epoch (default ``self.Q``;
        filterpy ignores ``Qs`` and always uses ``self.Q``, so the two agree when ``Qs`` equals
        ``self.Q``); ``dts`` a scalar or one step per epoch (default the filter's ``dt``). ``Fs``
        (keyword) gives one process function per epoch, ``us`` inputs of a built-in model. Runs in
        Rust (built-in models without the GIL) unless a custom ``UT``, ``inv`` or ``Fs`` asks for
        filterpy's Python formulation. The equations are in
        :func:`autoteach_estimate::ukf::rts_smoother` (Rust docs).
        """
        xs = as_f64(Xs, "Xs")
        if xs.ndim == 3 and xs.shape[2] == 1:
            xs = xs[:, :, 0]
        ps = as_f64(Ps, "Ps")
        if xs.ndim != 2 or xs.shape[1] != self._dim_x:
            raise InvalidInputError(f"Xs must have shape (n, {self._dim_x}), got {xs.shape}")
        n = xs.shape[0]
        if len(ps) != n:
            raise InvalidInputError(f"Xs and Ps must have the same length, got {n} and {len(ps)}")
        dt_arr = (
            np.full(n, self._dt)
            if dts is None
            else (np.full(n, as_float(dts, "dts")) if np.ndim(dts) == 0 else as_f64(dts, "dts"))
        )  # type: ignore[arg-type]
        if Qs is None:
            q_arr = _noise(self.Q, self._dim_x, "Q")
        else:
            q_list = list(Qs) if not isinstance(Qs, np.ndarray) else Qs
            q_arr = np.array([_noise(q, self._dim_x, f"Qs[{i}]") for i, q in enumerate(q_list)])
        if self.noise != "additive":
            raise InvalidInputError("the RTS smoother needs additive noise")
        if self._custom(UT) or Fs is not None:
            return self._rts_python(xs, ps, q_arr, dt_arr, UT or unscented_transform, Fs)
        u_arr = None if us is None else as_f64(us, "us")
        if u_arr is not None and u_arr.ndim == 1:
            u_arr = u_arr[:, None]
        if u_arr is not None and self._model is None:
            raise InvalidInputError("us is only for built-in models")
        out_x, out_p, out_k = self._inner.rts_smoother(xs, ps, q_arr, dt_arr, us=u_arr)
        return np.asarray(out_x), np.asarray(out_p), np.asarray(out_k)

    def _rts_python(
        self,
        xs: F64Array,
        ps: F64Array,
        q_arr: F64Array,
        dts: F64Array,
        UT: Any,
        Fs: Any,  # noqa: N803
    ) -> tuple[F64Array, F64Array, F64Array]:
        n, dim = xs.shape
        if Fs is not None and len(Fs) != n:
            raise InvalidInputError(f"Fs must have one process function per epoch ({n}), got {len(Fs)}")
        out_x, out_p = xs.copy(), ps.copy()
        gains = np.zeros((n, dim, dim))
        for k in reversed(range(n - 1)):
            f = self._fx(None if Fs is None else Fs[k])
            sigmas = np.asarray(self.points_fn.sigma_points(out_x[k], out_p[k]), dtype=np.float64)
            sf = self._apply(f, "fx", sigmas, (dts[k],), {}, dim)
            xb, pb = self._ut(UT, sf, q_arr if q_arr.ndim == 2 else q_arr[k], self.x_mean, self.residual_x)
            pxb = np.zeros((dim, dim))
            for i in range(len(sigmas)):
                dy = np.asarray(self.residual_x(sf[i], xb), dtype=np.float64).reshape(-1)
                dx = np.asarray(self.residual_x(sigmas[i], xs[k]), dtype=np.float64).reshape(-1)
                pxb += self.Wc[i] * np.outer(dx, dy)
            gain = pxb @ np.asarray(self.inv(pb), dtype=np.float64)
            out_x[k] += gain @ np.asarray(self.residual_x(out_x[k + 1], xb), dtype=np.float64).reshape(-1)
            out_p[k] += gain @ (out_p[k + 1] - pb) @ gain.T
            gains[k] = gain
        return out_x, out_p, gains

    # -- derived quantities ------------------------------------------------------------------

    @property
    def dim_x(self) -> int:
        """State dimension."""
        return self._dim_x

    @property
    def dim_z(self) -> int:
        """Measurement dimension."""
        return self._dim_z

    @property
    def log_likelihood(self) -> float:
        """Gaussian log-likelihood of the last measurement (``log N(y; 0, S)``)."""
        if self._log_likelihood is None:
            self._log_likelihood = _log_gauss(np.asarray(self.y, dtype=np.float64).reshape(-1), np.atleast_2d(self.S))
        return self._log_likelihood

    @property
    def likelihood(self) -> float:
        """``exp(log_likelihood)``, at least ``sys.float_info.min``."""
        if self._likelihood is None:
            lik = math.exp(self.log_likelihood)
            self._likelihood = lik if lik > 0.0 else sys.float_info.min
        return self._likelihood

    @property
    def mahalanobis(self) -> float:
        """Mahalanobis distance of the last innovation, ``sqrt(y^T SI y)`` (0 before any update)."""
        if self._mahalanobis is None:
            y = np.asarray(self.y, dtype=np.float64).reshape(-1)
            self._mahalanobis = float(math.sqrt(float(y @ np.atleast_2d(self.SI) @ y)))
        return self._mahalanobis

    @property
    def repairs(self) -> int:
        """How many covariances the ``repair`` policy fixed."""
        return int(self._inner.repairs)

    def __repr__(self) -> str:
        kind = "square-root " if self.square_root else ""
        model = type(self._model).__name__ if self._model is not None else "callbacks"
        return (
            f"UnscentedKalmanFilter({kind}dim_x={self._dim_x}, dim_z={self._dim_z}, model={model}, noise={self.noise}, "
            f"points={type(self.points_fn).__name__})"
        )


# ---------------------------------------------------------------------------------------------
# Sparse nonlinear least squares on manifolds (seed 000_3b1454b2b2194811.txt ch. 5.3;
# 004_815695db12a6b16c.txt ch. 3, 5, eq. 5.1-5.5). Computed in Rust (autoteach_estimate::lsq):
# Levenberg-Marquardt or Gauss-Newton on block-sparse normal equations, faer sparse Cholesky
# with a fill-reducing ordering (Schur elimination of point blocks), the GIL released.
# ---------------------------------------------------------------------------------------------

_LOSSES = ("linear", "huber", "cauchy", "tukey")


@dataclass(frozen=True)
class SolverOptions:
    """How a least-squares problem is solved (the Rust ``lsq::SolverOptions``).

    Attributes:
        method: ``"lm"`` (Levenberg-Marquardt) or ``"gn"`` (Gauss-Newton).
        linear_solver: ``"auto"``, ``"dense"``, ``"sparse"`` or ``"schur"``.
        max_iterations: iteration limit.
        ftol: relative cost-decrease tolerance.
        gtol: gradient (max |Jᵀr|) tolerance.
        xtol: relative step tolerance.
    """

    method: Literal["lm", "gn"] = "lm"
    linear_solver: Literal["auto", "dense", "sparse", "schur"] = "auto"
    max_iterations: int = 100
    ftol: float = 1e-10
    gtol: float = 1e-10
    xtol: float = 1e-10


def _solver_options(solver: SolverOptions | None, changes: dict[str, Any]) -> SolverOptions:
    """``solver`` (default :class:`SolverOptions`) with ``changes``; unknown names are refused."""
    return checked_replace(solver or SolverOptions(), "solver", changes)


def _solver_kwargs(
    method: str, linear_solver: str, max_iterations: int, ftol: float, gtol: float, xtol: float
) -> dict[str, Any]:
    iterations = as_int(max_iterations, "max_iterations")
    if iterations < 0:
        raise InvalidInputError(f"max_iterations must be a non-negative integer, got {iterations}")
    tolerances = {name: as_float(v, name) for name, v in (("ftol", ftol), ("gtol", gtol), ("xtol", xtol))}
    for name, v in tolerances.items():
        if v < 0.0:
            raise InvalidInputError(f"{name} must be a non-negative number, got {v}")
    return {
        "method": method,
        "linear_solver": linear_solver,
        "max_iterations": iterations,
        "function_tolerance": tolerances["ftol"],
        "gradient_tolerance": tolerances["gtol"],
        "parameter_tolerance": tolerances["xtol"],
    }


def _index_array(a: ArrayLike, name: str) -> NDArray[np.int64]:
    arr = np.asarray(a)
    if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
        raise InvalidInputError(f"{name} must be a 1-D array of integers, got dtype {arr.dtype}, shape {arr.shape}")
    if arr.size and arr.dtype.kind == "u" and arr.max() > np.iinfo(np.int64).max:
        k = int(np.argmax(arr))
        raise InvalidInputError(f"{name}[{k}] = {arr[k]} is out of range")
    # A contiguous int64 array crosses into Rust as one slice (no per-element conversion).
    return np.ascontiguousarray(arr, dtype=np.int64)


_CONVERGED_TERMINATIONS = frozenset(
    {"FunctionTolerance", "GradientTolerance", "ParameterTolerance", "NoFreeParameters"}
)


@dataclass(frozen=True, slots=True)
class SolverSummary:
    """What the least-squares solver did (the fields of ``autoteach_estimate::lsq::Summary``).

    Returned by :meth:`LeastSquaresProblem.solve` and held by :attr:`BundleAdjustResult.summary`.
    """

    iterations: int
    """Iterations (trial steps)."""
    successful_steps: int
    """Accepted steps."""
    initial_cost: float
    """Cost ½ Σ ρ(‖r‖²) at the start."""
    final_cost: float
    """Cost at the end."""
    termination: str
    """Why it stopped: ``FunctionTolerance``, ``GradientTolerance``, ``ParameterTolerance``,
    ``MaxIterations``, ``NoFreeParameters``, ``DampingLimit``, ``LinearSolverFailure`` or ``NonFinite``."""
    message: str
    """Human-readable reason."""
    time_s: float
    """Wall time of the solve (s)."""
    linear_solver: str
    """Linear solver used (``Dense``, ``SparseCholesky``, ``SparseSchur``, …; resolved from ``auto``)."""
    num_parameters: int
    """Free tangent dimension."""
    num_residuals: int
    """Total residual dimension."""
    num_eliminated_blocks: int
    """Blocks eliminated first (Schur), 0 unless the Schur solver ran."""
    gradient_max_norm: float
    """max |Jᵀr| at the end."""
    time_setup_s: float
    """Time (s) in structure analysis."""
    time_evaluate_s: float
    """Time (s) evaluating residuals and Jacobians."""
    time_assemble_s: float
    """Time (s) assembling the normal equations."""
    time_linear_s: float
    """Time (s) factorising and solving the normal equations."""
    time_schur_reduce_s: float
    """Part of :attr:`time_linear_s` spent eliminating the point blocks (Schur path)."""
    time_schur_factor_s: float
    """Part of :attr:`time_linear_s` spent on the reduced camera system (Schur path)."""

    @property
    def converged(self) -> bool:
        """Whether :attr:`termination` is a convergence criterion (not a failure or a limit)."""
        return self.termination in _CONVERGED_TERMINATIONS

    @classmethod
    def _from_core(cls, d: Any) -> SolverSummary:
        """From the binding's summary dict (keys are the Rust field names, plus ``converged``)."""
        return cls(**{f: d[f] for f in cls.__dataclass_fields__})


@dataclass(frozen=True, slots=True)
class BundleAdjustResult:
    """Result of :func:`bundle_adjust` (the fields of ``autoteach_estimate::lsq::BundleResult``).

    ``poses`` are 4×4 like every pose of the API; the binding's N×6 form is kept as
    :attr:`pose_vectors`.
    """

    poses: F64Array
    """Optimised world-to-camera poses ``T_cw``, N×4×4 (the project's pose convention)."""
    points: F64Array
    """Optimised world points, M×3."""
    summary: SolverSummary
    """What the solver did."""
    pose_vectors: F64Array
    """The same poses as N×6 (rotation vector, translation), scipy's bundle-adjustment layout."""

    @property
    def final_cost(self) -> float:
        """½ Σ ρ(‖r‖²) with r the pixel reprojection errors (scipy's ``cost``): ``summary.final_cost``."""
        return self.summary.final_cost

    @property
    def iterations(self) -> int:
        """Solver iterations (trial steps): ``summary.iterations``."""
        return self.summary.iterations


def _pose_vectors(poses: ArrayLike) -> F64Array:
    """Bundle-adjustment poses as N×6 (rotation vector, translation) from N×4×4 or N×6."""
    arr = as_f64(poses, "poses")
    if arr.ndim == 3 and arr.shape[1:] == (4, 4):
        if not np.allclose(arr[:, 3, :], [0.0, 0.0, 0.0, 1.0]):
            raise InvalidInputError("poses: the last row of every 4×4 pose must be [0, 0, 0, 1]")
        return np.ascontiguousarray(np.concatenate([so3_log(arr[:, :3, :3]), arr[:, :3, 3]], axis=1))
    return _matrix(arr, "poses")


def _pose_matrices(vectors: F64Array) -> F64Array:
    """N×4×4 poses from N×6 (rotation vector, translation)."""
    out = np.zeros((len(vectors), 4, 4))
    if len(vectors):
        out[:, :3, :3] = so3_exp(vectors[:, :3])
        out[:, :3, 3] = vectors[:, 3:]
    out[:, 3, 3] = 1.0
    return out


def bundle_adjust(
    K: ArrayLike,  # noqa: N803 - the conventional name of the intrinsic matrix
    poses: ArrayLike,
    points: ArrayLike,
    observations: ArrayLike,
    pose_index: ArrayLike,
    point_index: ArrayLike,
    loss: str = "linear",
    fixed_poses: Sequence[int] = (),
    *,
    f_scale: float = 1.0,
    solver: SolverOptions | None = None,
    **solver_options: Any,
) -> BundleAdjustResult:
    """Bundle adjustment: refine world-to-camera poses and world points.

    Minimises ½ Σ_k ρ(‖π(K (R_i X_j + t_i)) − z_k‖²) with ``i = pose_index[k]``,
    ``j = point_index[k]``, ``z_k = observations[k]`` (pixels, OpenCV convention), poses on
    SE(3). ``loss`` is ``"linear"``, ``"huber"``, ``"cauchy"`` or ``"tukey"`` with scale
    ``f_scale`` (pixels; same parameterisation as :func:`scipy.optimize.least_squares`).
    Poses in ``fixed_poses`` are held; fix the first pose and one more (or a scale) to remove
    the gauge freedom.

    Args:
        K: 3×3 intrinsic matrix.
        poses: world-to-camera poses ``T_cw``: N×4×4 matrices, or N×6 (rotation vector then
            translation, scipy's bundle-adjustment layout).
        points: M×3 world points.
        observations: K×2 pixel observations.
        pose_index: K pose indices.
        point_index: K point indices.
        loss: robust loss name.
        fixed_poses: indices of poses held constant.
        f_scale: loss scale (pixels).
        solver: the solver's method, linear solver, iteration limit and tolerances (default
            :class:`SolverOptions`).
        **solver_options: fields of :class:`SolverOptions` that replace those of ``solver`` by
            name, e.g. ``max_iterations=50``.

    Returns:
        The optimised poses and points, final cost, iterations and the solver summary.

    Raises:
        InvalidInputError: wrong shapes, NaN/inf, indices out of range, unknown loss.
        ConvergenceError: a point behind a camera at the start or a non-finite residual.
    """
    if loss not in _LOSSES:
        raise InvalidInputError(f"loss must be one of {_LOSSES}, got {loss!r}")
    poses_m = _pose_vectors(poses)
    points_m, obs_m = _matrix(points, "points"), _matrix(observations, "observations")
    pi, xi = _index_array(pose_index, "pose_index"), _index_array(point_index, "point_index")
    fixed = [int(i) for i in fixed_poses]
    for name, idx, n in (
        ("pose_index", pi, len(poses_m)),
        ("point_index", xi, len(points_m)),
        ("fixed_poses", np.asarray(fixed, dtype=np.int64), len(poses_m)),
    ):
        if name != "fixed_poses" and len(idx) != len(obs_m):
            raise InvalidInputError(f"{name} must have one entry per observation ({len(obs_m)}), got {len(idx)}")
        bad = np.flatnonzero((idx < 0) | (idx >= n))
        if bad.size:
            k = int(bad[0])
            raise InvalidInputError(f"{name}[{k}] = {idx[k]} is out of range: it must be in [0, {n})")
    poses_a, points_a, summary = _core.lsq_bundle_adjust(
        _matrix(K, "K"),
        poses_m,
        points_m,
        obs_m,
        pi,
        xi,
        loss,
        float(f_scale),
        fixed,
        **_solver_kwargs(*dataclasses.astuple(_solver_options(solver, solver_options))),
    )
    poses_a = np.asarray(poses_a)
    return BundleAdjustResult(
        poses=_pose_matrices(poses_a),
        points=points_a,
        summary=SolverSummary._from_core(summary),
        pose_vectors=poses_a,
    )


@serialized
class LeastSquaresProblem:
    """A nonlinear least-squares problem on manifolds, stated from NumPy.

    Blocks are Euclidean vectors, rotations (``"so3"``: 3×3 matrices, ``"quaternion"``:
    ``[w, x, y, z]``) or poses (``"se3"``, given and returned as 4×4 matrices by
    :meth:`add_pose` / :meth:`pose`; stored as ``[qw, qx, qy, qz, tx, ty, tz]``). Tangent
    vectors are rotation first, ``[ω; ρ]``, with the right perturbation ``X·Exp(δ)``.
    Residuals are the built-in ones: reprojection, prior, relative pose and point-to-conic.

    Example::

        p = LeastSquaresProblem()
        cam = p.add_pose(np.eye(4))
        pts = [p.add_block(x, "euclidean") for x in points]
        p.add_reprojections(K, uv, [cam] * len(pts), pts)
        p.set_fixed(cam, True)
        summary = p.solve()
        cov = p.marginal_covariance([pts[0]])
    """

    def __init__(self) -> None:
        """Create an empty problem."""
        self._inner = _core.LsqProblem()

    @property
    def num_blocks(self) -> int:
        """Number of parameter blocks."""
        return int(self._inner.num_blocks)

    @property
    def num_residuals(self) -> int:
        """Number of residual blocks."""
        return int(self._inner.num_residuals)

    def add_block(self, values: ArrayLike, manifold: str = "euclidean") -> int:
        """Add a block with stored ``values`` on ``manifold``; returns its id."""
        return int(self._inner.add_block(_vector(values, "values"), manifold))

    def add_pose(self, T: ArrayLike) -> int:  # noqa: N803 - a transform
        """Add an SE(3) block from a 4×4 homogeneous transform; returns its id."""
        return int(self._inner.add_pose(_matrix(T, "T")))

    def add_rotation(self, R: ArrayLike) -> int:  # noqa: N803 - a rotation matrix
        """Add an SO(3) block from a 3×3 rotation matrix; returns its id."""
        return int(self._inner.add_rotation(np.ascontiguousarray(_matrix(R, "R"))))

    def set_fixed(self, block: int, fixed: bool = True) -> None:
        """Hold a block constant (or release it)."""
        self._inner.set_fixed(as_int(block, "block"), bool(fixed))

    def set_eliminate(self, block: int, eliminate: bool | None = None) -> None:
        """Mark a block for Schur elimination (``None``: automatic, 3-vectors tied to poses)."""
        self._inner.set_eliminate(as_int(block, "block"), eliminate)

    def values(self, block: int) -> F64Array:
        """The stored values of a block."""
        return np.asarray(self._inner.values(as_int(block, "block")))

    def set_values(self, block: int, values: ArrayLike) -> None:
        """Overwrite the stored values of a block."""
        self._inner.set_values(as_int(block, "block"), _vector(values, "values"))

    def pose(self, block: int) -> F64Array:
        """The 4×4 transform of an SE(3) block."""
        return np.asarray(self._inner.pose(as_int(block, "block")))

    def rotation(self, block: int) -> F64Array:
        """The 3×3 rotation matrix of an SO(3) block."""
        if self._inner.manifold(as_int(block, "block")) != "so3":
            raise InvalidInputError(f"block {block} is not an SO(3) block")
        return self.values(block).reshape(3, 3, order="F")

    def add_reprojections(
        self,
        K: ArrayLike,  # noqa: N803 - the intrinsic matrix
        observations: ArrayLike,
        pose_blocks: ArrayLike,
        point_blocks: ArrayLike,
        sigma: float = 1.0,
        loss: str = "linear",
        f_scale: float = 1.0,
    ) -> list[int]:
        """Add pinhole reprojection residuals (σ-whitened pixels) of points in cameras.

        ``pose_blocks[k]`` is an SE(3) world-to-camera block, ``point_blocks[k]`` a
        3-vector block, ``observations[k]`` its pixel.
        """
        return list(
            self._inner.add_reprojections(
                _matrix(K, "K"),
                _matrix(observations, "observations"),
                _index_array(pose_blocks, "pose_blocks"),
                _index_array(point_blocks, "point_blocks"),
                float(sigma),
                loss,
                as_float(f_scale, "f_scale"),
            )
        )

    def add_prior(self, block: int, mean: ArrayLike, covariance: ArrayLike) -> int:
        """Add a Gaussian prior: whitened ``x ⊖ mean`` (mean in the stored layout, or 4×4 for SE(3))."""
        m = as_f64(mean, "mean")
        if m.shape == (4, 4):
            tmp = _core.LsqProblem()
            m = np.asarray(tmp.values(tmp.add_pose(m)))
        elif m.shape == (3, 3):
            m = m.reshape(-1, order="F")
        return int(self._inner.add_prior(as_int(block, "block"), _vector(m, "mean"), _matrix(covariance, "covariance")))

    def add_relative_pose(
        self,
        a: int,
        b: int,
        T_ab: ArrayLike,  # noqa: N803 - a transform
        covariance: ArrayLike,
        loss: str = "linear",
        f_scale: float = 1.0,
    ) -> int:
        """Add the relative-pose residual ``Log(T_ab⁻¹ A⁻¹ B)`` (whitened by ``covariance``, 6×6)."""
        return int(
            self._inner.add_relative_pose(
                as_int(a, "a"),
                as_int(b, "b"),
                _matrix(T_ab, "T_ab"),
                _matrix(covariance, "covariance"),
                loss,
                as_float(f_scale, "f_scale"),
            )
        )

    def add_point_to_conic(
        self,
        K: ArrayLike,  # noqa: N803 - the intrinsic matrix
        radius: float,
        observations: ArrayLike,
        camera_block: int,
        object_block: int,
        weight: float = 1.0,
        loss: str = "linear",
        f_scale: float = 1.0,
    ) -> list[int]:
        """Add point-to-conic residuals ``w·pᵀ H⁻ᵀ C₀ H⁻¹ p`` (seed eq. 5.13) of rim pixels."""
        return list(
            self._inner.add_point_to_conic(
                _matrix(K, "K"),
                as_float(radius, "radius"),
                _matrix(observations, "observations"),
                as_int(camera_block, "camera_block"),
                as_int(object_block, "object_block"),
                as_float(weight, "weight"),
                loss,
                as_float(f_scale, "f_scale"),
            )
        )

    def solve(
        self,
        method: Literal["lm", "gn"] = "lm",
        linear_solver: Literal["auto", "dense", "sparse", "schur"] = "auto",
        max_iterations: int = 100,
        ftol: float = 1e-10,
        gtol: float = 1e-10,
        xtol: float = 1e-10,
    ) -> SolverSummary:
        """Solve (GIL released); returns what the solver did (``termination``, ``message``, costs, …)."""
        return SolverSummary._from_core(
            self._inner.solve(**_solver_kwargs(method, linear_solver, max_iterations, ftol, gtol, xtol))
        )

    def marginal_covariance(self, blocks: Sequence[int]) -> F64Array:
        """Joint tangent covariance of ``blocks`` from (JᵀJ)⁻¹.

        Raises:
            DegenerateGeometryError: the information matrix is rank deficient (the message names the
                unconstrained blocks and directions).
        """
        return np.asarray(self._inner.marginal_covariance([as_int(b, "blocks") for b in blocks]))
