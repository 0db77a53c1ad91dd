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
from autoteach.errors import InvalidInputError
from autoteach.geometry import so3_exp, so3_log

__all__ = [
    "BundleAdjustResult",
    "ConstantVelocityModel",
    "LeastSquaresProblem",
    "LinearModel",
    "MerweScaledSigmaPoints",
    "SolverSummary",
    "UnscentedKalmanFilter",
    "bundle_adjust",
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


class MerweScaledSigmaPoints:
    """Van der Merwe's scaled sigma points (as ``filterpy.kalman.MerweScaledSigmaPoints``).

    With ``lambda = alpha**2 * (n + kappa) - n``: ``Wm[0] = lambda / (n + lambda)``,
    ``Wc[0] = Wm[0] + 1 - alpha**2 + beta``, all other weights ``1 / (2 (n + lambda))``. The
    points are ``x``, then ``x + U[k]`` and ``x - U[k]`` for the rows ``U[k]`` of the upper
    Cholesky factor of ``(n + lambda) P`` (or of ``sqrt_method((n + lambda) P)``), with
    ``subtract(x, -U[k])`` / ``subtract(x, U[k])`` when ``subtract`` is given.
    """

    def __init__(
        self,
        n: int,
        alpha: float,
        beta: float,
        kappa: float,
        sqrt_method: Callable[[F64Array], ArrayLike] | None = None,
        subtract: Callable[[F64Array, F64Array], ArrayLike] | None = None,
    ) -> None:
        self.n = int(n)
        self.alpha = float(alpha)
        self.beta = float(beta)
        self.kappa = float(kappa)
        self.sqrt = sqrt_method
        self.subtract = subtract
        self.Wm, self.Wc = _core.merwe_weights(self.n, self.alpha, self.beta, self.kappa)

    def num_sigmas(self) -> int:
        """Number of sigma points, ``2n + 1``."""
        return 2 * self.n + 1

    def sigma_points(self, x: ArrayLike, P: ArrayLike) -> F64Array:  # noqa: N803 (filterpy's name)
        """Sigma points ``(2n + 1, n)`` of mean ``x`` and covariance ``P`` (a scalar means ``P * I``)."""
        xv = np.atleast_1d(np.asarray(x, dtype=np.float64)).reshape(-1)
        if xv.size != self.n:
            raise InvalidInputError(f"expected size(x) {self.n}, but size is {xv.size}")
        Pm = np.eye(self.n) * float(P) if np.isscalar(P) else np.atleast_2d(np.asarray(P, dtype=np.float64))  # noqa: N806
        if self.sqrt is None and self.subtract is None:
            return _core.merwe_sigma_points(xv, Pm, self.alpha, self.beta, self.kappa)
        lam = self.alpha**2 * (self.n + self.kappa) - self.n
        if self.sqrt is None:
            U = np.linalg.cholesky((lam + self.n) * Pm).T  # noqa: N806
        else:
            U = np.asarray(self.sqrt((lam + self.n) * Pm), dtype=np.float64)  # noqa: N806
        sub = self.subtract if self.subtract is not None else np.subtract
        sigmas = np.zeros((2 * self.n + 1, self.n))
        sigmas[0] = xv
        for k in range(self.n):
            sigmas[k + 1] = sub(xv, -U[k])
            sigmas[self.n + k + 1] = sub(xv, U[k])
        return sigmas

    def __repr__(self) -> str:
        return f"MerweScaledSigmaPoints(n={self.n}, alpha={self.alpha}, beta={self.beta}, kappa={self.kappa})"


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
        self.dt = float(dt)
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


class UnscentedKalmanFilter:
    """Unscented Kalman filter with filterpy's interface (``filterpy.kalman.UnscentedKalmanFilter``).

    Args:
        dim_x: State dimension.
        dim_z: Measurement dimension.
        dt: Default time step of :meth:`predict`.
        hx: Measurement function ``hx(x, **hx_args)``, or ``None`` with a built-in model.
        fx: Process function ``fx(x, dt, **fx_args)``, or a :class:`LinearModel` /
            :class:`ConstantVelocityModel` (the fast path).
        points: A :class:`MerweScaledSigmaPoints` with ``n == dim_x`` (its ``alpha``, ``beta``,
            ``kappa``, ``sqrt_method`` and ``subtract`` are used). Another sigma-point object
            with ``n``, ``alpha``, ``beta``, ``kappa`` (e.g. filterpy's) contributes those four.
        sqrt_fn: Kept as ``self.msqrt`` for compatibility; like filterpy, the square root
            actually used is the sigma points' ``sqrt_method``.
        x_mean_fn: ``x_mean_fn(sigmas, Wm)`` mean of state sigma points ``(2n+1, n)``.
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

    Attributes ``x``, ``P``, ``Q``, ``R`` are NumPy arrays you may set or modify in place;
    ``x_prior``, ``P_prior``, ``x_post``, ``P_post``, ``K``, ``y``, ``S``, ``z``,
    ``log_likelihood``, ``likelihood``, ``mahalanobis`` are as in filterpy.
    """

    # The compiled filter and the sync bookkeeping live in slots, outside ``__dict__``, so that
    # tools that deep-copy ``__dict__`` (filterpy's ``Saver``) see only filterpy's attributes.
    __slots__ = ("__dict__", "_inner", "_synced")

    def __init__(
        self,
        dim_x: int,
        dim_z: int,
        dt: float,
        hx: Callable[..., ArrayLike] | None,
        fx: Callable[..., ArrayLike] | LinearModel | ConstantVelocityModel,
        points: MerweScaledSigmaPoints,
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
    ) -> None:
        if noise not in ("additive", "augmented"):
            raise InvalidInputError(f"noise must be 'additive' or 'augmented', got {noise!r}")
        if not isinstance(points, MerweScaledSigmaPoints):
            points = MerweScaledSigmaPoints(points.n, points.alpha, points.beta, points.kappa)
        if points.n != dim_x:
            raise InvalidInputError(f"points.n = {points.n} must equal dim_x = {dim_x}")
        augmented = noise == "augmented"
        self._model = fx if isinstance(fx, _BUILTIN) else None
        if self._model is not None:
            model = self._model
            if hx is not None and hx is not model:
                raise InvalidInputError("with a built-in model as fx, hx must be None (the model measures)")
            if (model.dim_x, model.dim_z) != (dim_x, dim_z):
                raise InvalidInputError(
                    f"the model has dim_x={model.dim_x}, dim_z={model.dim_z}; got dim_x={dim_x}, dim_z={dim_z}"
                )
            hooks = [x_mean_fn, z_mean_fn, residual_x, residual_z, state_add, points.sqrt, points.subtract]
            if any(h is not None for h in hooks) or dim_w is not None or dim_v is not None:
                raise InvalidInputError(
                    "built-in models use vector-space means and residuals; pass Python callbacks for custom hooks"
                )
            self._inner = _core.UkfFilter.builtin(
                model._inner,
                points.alpha,
                points.beta,
                points.kappa,
                square_root=square_root,
                augmented=augmented,
                repair=repair,
            )
        else:
            if not callable(fx) or not callable(hx):
                raise InvalidInputError("fx and hx must be callables (or fx a built-in model with hx=None)")
            self._inner = _core.UkfFilter.callbacks(
                int(dim_x),
                int(dim_z),
                fx,
                hx,
                points.alpha,
                points.beta,
                points.kappa,
                x_mean=x_mean_fn,
                z_mean=z_mean_fn,
                residual_x=residual_x,
                residual_z=residual_z,
                state_add=state_add,
                subtract=points.subtract,
                sqrt=points.sqrt,
                square_root=square_root,
                augmented=augmented,
                repair=repair,
                dim_w=dim_w,
                dim_v=dim_v,
            )
        self._dim_x = int(dim_x)
        self._dim_z = int(dim_z)
        self._dt = float(dt)
        self.points_fn = points
        self._num_sigmas = points.num_sigmas()
        self.fx = fx
        self.hx = hx
        self.x_mean = x_mean_fn
        self.z_mean = z_mean_fn
        self.residual_x = residual_x if residual_x is not None else np.subtract
        self.residual_z = residual_z if residual_z is not None else np.subtract
        self.state_add = state_add if state_add is not None else np.add
        self.msqrt = sqrt_fn
        self.Wm, self.Wc = points.Wm, points.Wc
        self.square_root = bool(square_root)
        self.noise = noise
        self.repair = bool(repair)
        self.inv = np.linalg.inv
        self.x: F64Array = np.zeros(dim_x)
        self.P: F64Array = np.eye(dim_x)
        self.Q: F64Array = np.asarray(self._inner.Q)
        self.R: F64Array = np.asarray(self._inner.R)
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()
        self.K = np.zeros((dim_x, dim_z))
        self.y = np.zeros(dim_z)
        self.S = np.zeros((dim_z, dim_z))
        self.z = np.array([[None] * dim_z]).T
        self._log_likelihood = math.log(sys.float_info.min)
        self._synced: tuple[F64Array, F64Array, F64Array, F64Array] | None = None

    @classmethod
    def from_model(
        cls,
        model: LinearModel | ConstantVelocityModel,
        points: MerweScaledSigmaPoints,
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

    def _push(self) -> None:
        """Sends x, P, Q, R to the compiled filter if they changed since the last sync."""
        x = _vector(self.x, "x")
        P = _matrix(self.P, "P")  # noqa: N806
        Q = _matrix(self.Q, "Q")  # noqa: N806
        R = _matrix(self.R, "R")  # noqa: N806
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
        if post:
            self.x_post = self.x.copy()
            self.P_post = self.P.copy()
        self._synced = (x.copy(), self.P.copy(), _matrix(self.Q, "Q"), _matrix(self.R, "R"))

    # -- filterpy interface --------------------------------------------------------------------

    def predict(
        self, dt: float | None = None, UT: Any = None, fx: Callable[..., ArrayLike] | None = None, **fx_args: Any
    ) -> None:  # noqa: N803
        """Predict over ``dt`` (default the constructor's); ``fx_args`` go to ``fx``.

        With a built-in model, ``u=`` is the control input and no other argument is accepted.
        """
        if UT is not None:
            raise InvalidInputError("a custom UT is not supported: customise with x_mean_fn / residual_x")
        dt = self._dt if dt is None else float(dt)
        self._push()
        if self._model is not None:
            u = fx_args.pop("u", None)
            if fx is not None or fx_args:
                raise InvalidInputError("a built-in model takes only u= in predict()")
            self._inner.predict(dt, u=None if u is None else _vector(u, "u"))
        else:
            self._inner.predict(dt, fx_kwargs=fx_args or None, fx=fx)
        self._pull(prior=True, post=False)

    def update(
        self,
        z: ArrayLike | None,
        R: ArrayLike | float | None = None,  # noqa: N803
        UT: Any = None,  # noqa: N803
        hx: Callable[..., ArrayLike] | None = None,
        **hx_args: Any,
    ) -> None:
        """Update with measurement ``z`` (``None``: no measurement); ``R`` overrides ``self.R`` once."""
        if UT is not None:
            raise InvalidInputError("a custom UT is not supported: customise with z_mean_fn / residual_z")
        if z is None:
            self.z = np.array([[None] * self._dim_z]).T
            self.x_post = self.x.copy()
            self.P_post = self.P.copy()
            self._inner.skip_update()
            return
        if R is not None:
            R = np.eye(self._dim_z) * float(R) if np.isscalar(R) else _matrix(R, "R")  # noqa: N806
        if self._model is not None and (hx is not None or hx_args):
            raise InvalidInputError("a built-in model takes no hx override or arguments in update()")
        self._push()
        if self._model is not None:
            self._inner.update(_vector(z, "z"), r=R)
        else:
            self._inner.update(_vector(z, "z"), r=R, hx_kwargs=hx_args or None, hx=hx)
        self._pull(prior=False, post=True)
        inner = self._inner
        self.K = np.asarray(inner.K)
        self.y = np.asarray(inner.y)
        self.S = np.asarray(inner.S)
        self.z = deepcopy(z)
        self._log_likelihood = float(inner.log_likelihood)

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
        control inputs (built-in models); ``dts``: scalar or ``(n,)``; ``Rs``: ``(n, dim_z, dim_z)``
        or ``(n,)`` scalars. Returns ``xs``, ``Ps`` (posteriors), ``log_likelihoods`` (NaN where
        missing) and, with ``priors``, ``x_priors``, ``P_priors``. The filter ends in the last
        posterior.
        """
        n = len(zs)  # type: ignore[arg-type]
        Z, mask = self._measurements(zs, n)  # noqa: N806
        if us is not None and self._model is None:
            raise InvalidInputError("us is only for built-in models; pass inputs to callbacks via predict(**fx_args)")
        u_arr = None if us is None else np.asarray(us, dtype=np.float64)
        if u_arr is not None and u_arr.ndim == 1:
            u_arr = u_arr[:, None]
        dt_arr = None
        if dts is not None:
            dt_arr = np.full(n, float(dts)) if np.isscalar(dts) else np.asarray(dts, dtype=np.float64)  # type: ignore[arg-type]
        r_arr = None
        if Rs is not None:
            r_arr = np.asarray(Rs, dtype=np.float64)
            if r_arr.ndim == 1:
                r_arr = r_arr[:, None, None] * np.eye(self._dim_z)
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
            if mask[-1]:
                inner = self._inner
                self.K = np.asarray(inner.K)
                self.y = np.asarray(inner.y)
                self.S = np.asarray(inner.S)
                self.z = deepcopy(zs[-1])  # type: ignore[index]
                self._log_likelihood = float(inner.log_likelihood)
        return out

    def _measurements(self, zs: Any, n: int) -> tuple[F64Array, list[bool]]:
        """``zs`` as an ``(n, dim_z)`` array and the mask of present measurements."""
        if isinstance(zs, np.ndarray) or not any(z is None for z in zs):
            try:
                Z = np.asarray(zs, dtype=np.float64)  # noqa: N806
            except (TypeError, ValueError):
                Z = None  # noqa: N806 (ragged: reported per element below)
            if Z is not None and Z.size == n * self._dim_z and Z.shape[:1] == (n,):
                return Z.reshape(n, self._dim_z), [True] * n
        mask = [z is not None for z in zs]
        Z = np.zeros((n, self._dim_z))  # noqa: N806
        for i, z in enumerate(zs):
            if z is None:
                continue
            zi = np.asarray(z, dtype=np.float64).reshape(-1)
            if zi.size != self._dim_z:
                raise InvalidInputError(f"zs[{i}] must have {self._dim_z} values, got shape {np.shape(z)}")
            Z[i] = zi
        return Z, mask

    def batch_filter(
        self,
        zs: Sequence[ArrayLike | None] | ArrayLike,
        Rs: ArrayLike | None = None,  # noqa: N803
        dts: ArrayLike | float | None = None,
        UT: Any = None,  # noqa: N803
        saver: Any = None,
        us: ArrayLike | None = None,
    ) -> tuple[F64Array, F64Array]:
        """Filter all measurements: ``(means (n, dim_x), covariances (n, dim_x, dim_x))`` as filterpy.

        Without ``saver`` the whole run is one call into Rust (:meth:`batch`); with a
        ``filterpy.common.Saver`` it steps in Python and calls ``saver.save()`` after each epoch.
        """
        if UT is not None:
            raise InvalidInputError("a custom UT is not supported: customise with x_mean_fn / residual_x")
        n = len(zs)  # type: ignore[arg-type]
        if saver is None:
            out = self.batch(zs, us=us, dts=dts, Rs=Rs, priors=False)
            means, covs = out["xs"], out["Ps"]
        else:
            means = np.zeros((n, self._dim_x))
            covs = np.zeros((n, self._dim_x, self._dim_x))
            dt_list = [self._dt] * n if dts is None else ([float(dts)] * n if np.isscalar(dts) else list(dts))  # type: ignore[arg-type]
            r_list = [None] * n if Rs is None else list(Rs)  # type: ignore[arg-type]
            for i, z in enumerate(zs):  # type: ignore[arg-type]
                if us is not None:
                    self.predict(dt=dt_list[i], u=np.asarray(us)[i])
                else:
                    self.predict(dt=dt_list[i])
                self.update(z, r_list[i])
                means[i] = np.asarray(self.x).reshape(-1)
                covs[i] = self.P
                saver.save()
        if np.ndim(self.x) == 2:
            means = means[:, :, None]
        return means, covs

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
        """Gaussian log-likelihood of the last measurement."""
        return self._log_likelihood

    @property
    def likelihood(self) -> float:
        """``exp(log_likelihood)``, at least ``sys.float_info.min``."""
        lik = math.exp(self._log_likelihood)
        return lik if lik > 0.0 else sys.float_info.min

    @property
    def SI(self) -> F64Array:  # noqa: N802 (filterpy's name)
        """Inverse of the innovation covariance ``S``."""
        return np.linalg.inv(self.S)

    @property
    def mahalanobis(self) -> float:
        """Mahalanobis distance of the last measurement."""
        y = np.asarray(self.y).reshape(-1)
        return float(math.sqrt(float(y @ np.linalg.solve(self.S, y))))

    @property
    def repairs(self) -> int:
        """How many covariances the ``repair`` policy fixed."""
        return int(self._inner.repairs)

    def __repr__(self) -> str:
        kind = "square-root " if self.square_root else ""
        model = type(self._model).__name__ if self._model is not None else "callbacks"
        return (
            f"UnscentedKalmanFilter({kind}dim_x={self._dim_x}, dim_z={self._dim_z}, model={model}, noise={self.noise})"
        )


# ---------------------------------------------------------------------------------------------
# Sparse nonlinear least squares on manifolds (seed 000_3b1454b2b2194811.txt ch. 5.3;
# 004_815695db12a6b16c.txt ch. 3, 5, eq. 5.1-5.5). Computed in Rust (autoteach_estimate::lsq):
# Levenberg-Marquardt or Gauss-Newton on block-sparse normal equations, faer sparse Cholesky
# with a fill-reducing ordering (Schur elimination of point blocks), the GIL released.
# ---------------------------------------------------------------------------------------------

_LOSSES = ("linear", "huber", "cauchy", "tukey")


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
    method: Literal["lm", "gn"] = "lm",
    linear_solver: Literal["auto", "dense", "sparse", "schur"] = "auto",
    max_iterations: int = 100,
    ftol: float = 1e-10,
    gtol: float = 1e-10,
    xtol: float = 1e-10,
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
        method: ``"lm"`` (Levenberg-Marquardt) or ``"gn"`` (Gauss-Newton).
        linear_solver: ``"auto"``, ``"dense"``, ``"sparse"`` or ``"schur"``.
        max_iterations: iteration limit.
        ftol: relative cost-decrease tolerance.
        gtol: gradient (max |Jᵀr|) tolerance.
        xtol: relative step tolerance.

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
            raise InvalidInputError(f"{name}[{k}] = {idx[k]} is out of range (there are {n})")
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
        **_solver_kwargs(method, linear_solver, max_iterations, ftol, gtol, xtol),
    )
    poses_a = np.asarray(poses_a)
    return BundleAdjustResult(
        poses=_pose_matrices(poses_a),
        points=points_a,
        summary=SolverSummary._from_core(summary),
        pose_vectors=poses_a,
    )


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
        r = _matrix(R, "R")
        if r.shape != (3, 3):
            raise InvalidInputError(f"R must have shape (3, 3), got {r.shape}")
        return int(self._inner.add_block(r.reshape(-1, order="F"), "so3"))

    def set_fixed(self, block: int, fixed: bool = True) -> None:
        """Hold a block constant (or release it)."""
        self._inner.set_fixed(int(block), bool(fixed))

    def set_eliminate(self, block: int, eliminate: bool | None = None) -> None:
        """Mark a block for Schur elimination (``None``: automatic, 3-vectors tied to poses)."""
        self._inner.set_eliminate(int(block), eliminate)

    def values(self, block: int) -> F64Array:
        """The stored values of a block."""
        return np.asarray(self._inner.values(int(block)))

    def set_values(self, block: int, values: ArrayLike) -> None:
        """Overwrite the stored values of a block."""
        self._inner.set_values(int(block), _vector(values, "values"))

    def pose(self, block: int) -> F64Array:
        """The 4×4 transform of an SE(3) block."""
        return np.asarray(self._inner.pose(int(block)))

    def rotation(self, block: int) -> F64Array:
        """The 3×3 rotation matrix of an SO(3) block."""
        if self._inner.manifold(int(block)) != "so3":
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
                float(f_scale),
            )
        )

    def add_prior(self, block: int, mean: ArrayLike, covariance: ArrayLike) -> int:
        """Add a Gaussian prior: whitened ``x ⊖ mean`` (mean in the stored layout, or 4×4 for SE(3))."""
        m = np.asarray(mean, dtype=np.float64)
        if m.shape == (4, 4):
            tmp = _core.LsqProblem()
            m = np.asarray(tmp.values(tmp.add_pose(m)))
        elif m.shape == (3, 3):
            m = m.reshape(-1, order="F")
        return int(self._inner.add_prior(int(block), _vector(m, "mean"), _matrix(covariance, "covariance")))

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
                int(a), int(b), _matrix(T_ab, "T_ab"), _matrix(covariance, "covariance"), loss, float(f_scale)
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
                float(radius),
                _matrix(observations, "observations"),
                int(camera_block),
                int(object_block),
                float(weight),
                loss,
                float(f_scale),
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
        return np.asarray(self._inner.marginal_covariance([int(b) for b in blocks]))
