"""Sigma-point families and the unscented transform, with filterpy's interface.

The three families of ``filterpy.kalman`` (van der Merwe's scaled points, Julier's symmetric
points, Julier's spherical simplex), computed in Rust (:mod:`autoteach._core`) and usable by
:class:`autoteach.estimate.UnscentedKalmanFilter` without leaving Rust. Class names, constructor
arguments and attributes (``n``, ``alpha``, ``beta``, ``kappa``, ``Wm``, ``Wc``, ``sqrt``,
``subtract``, :meth:`~MerweScaledSigmaPoints.sigma_points`,
:meth:`~MerweScaledSigmaPoints.num_sigmas`) are filterpy's, so either library's objects can be
passed to either filter. The sigma-point sets are those of the unscented transform behind the
UKF of seed 000_3b1454b2b2194811.txt §5.2 (eqs. 5.1-5.2).

A custom ``sqrt_method`` (returning a matrix whose ROWS are the offsets, like the upper Cholesky
factor) or ``subtract`` (``subtract(x, -offset)`` places a point) is honoured as in filterpy;
the filter then calls it from Rust.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_finite_f64, as_float
from autoteach.errors import InvalidInputError

__all__ = [
    "JulierSigmaPoints",
    "MerweScaledSigmaPoints",
    "SimplexSigmaPoints",
    "cholesky_upper",
    "unscented_transform",
]

F64Array = NDArray[np.float64]
"""A float64 NumPy array."""


def cholesky_upper(m: ArrayLike) -> F64Array:
    """Upper Cholesky factor ``U`` with ``U.T @ U = m`` (filterpy's default ``sqrt_method``, scipy's convention)."""
    try:
        return np.linalg.cholesky(np.asarray(m, dtype=np.float64)).T
    except np.linalg.LinAlgError as e:
        raise InvalidInputError(f"the matrix is not positive definite: {e}") from None


def _is_default_sqrt(f: Any) -> bool:
    """True for our default square root or scipy's ``cholesky`` (filterpy's default): both give the upper factor."""
    return (
        f is None
        or f is cholesky_upper
        or (getattr(f, "__name__", "") == "cholesky" and str(getattr(f, "__module__", "")).startswith("scipy.linalg"))
    )


def _is_default_subtract(f: Any) -> bool:
    return f is None or f is np.subtract


def _state(x: ArrayLike, n: int) -> F64Array:
    xv = np.atleast_1d(as_f64(x, "x")).reshape(-1)
    if xv.size != n:
        raise InvalidInputError(f"expected size(x) {n}, but size is {xv.size}")
    return xv


def _covariance(P: ArrayLike, n: int) -> F64Array:  # noqa: N803 (filterpy's name)
    if np.isscalar(P) or np.ndim(P) == 0:
        return np.eye(n) * as_float(P, "P")
    return np.atleast_2d(as_f64(P, "P"))


class _SigmaPoints:
    """Shared behaviour: the Rust fast path, filterpy's hooks, and introspection for the filter."""

    _family = ""
    n: int
    alpha: float
    beta: float
    kappa: float
    Wm: F64Array
    Wc: F64Array

    def __init__(
        self,
        n: int,
        sqrt_method: Callable[[F64Array], ArrayLike] | None,
        subtract: Callable[[F64Array, F64Array], ArrayLike] | None,
    ) -> None:
        if int(n) != n or int(n) < 1:
            raise InvalidInputError(f"n must be a positive integer, got {n!r}")
        self.n = int(n)
        self.sqrt = sqrt_method if sqrt_method is not None else cholesky_upper
        self.subtract = subtract if subtract is not None else np.subtract
        self.Wm, self.Wc = _core.family_weights(self._family, self.n, self.alpha, self.beta, self.kappa)

    def _hooks(self) -> tuple[Callable[..., Any] | None, Callable[..., Any] | None]:
        """The (sqrt, subtract) hooks that differ from the defaults (``None`` otherwise)."""
        sqrt = None if _is_default_sqrt(self.sqrt) else self.sqrt
        sub = None if _is_default_subtract(self.subtract) else self.subtract
        return sqrt, sub

    def _spread(self) -> float:
        """The factor of ``P`` under the square root."""
        raise NotImplementedError

    def sigma_points(self, x: ArrayLike, P: ArrayLike) -> F64Array:  # noqa: N803 (filterpy's name)
        """Sigma points ``(num_sigmas(), n)`` of mean ``x`` and covariance ``P`` (a scalar means ``P * I``)."""
        xv = _state(x, self.n)
        Pm = _covariance(P, self.n)  # noqa: N806
        sqrt, sub = self._hooks()
        if sqrt is None and sub is None:
            return _core.family_sigma_points(self._family, xv, Pm, self.alpha, self.beta, self.kappa)
        return self._with_hooks(xv, Pm)

    def _with_hooks(self, x: F64Array, P: F64Array) -> F64Array:  # noqa: N803
        """Symmetric families: ``x``, ``subtract(x, -U[k])``, ``subtract(x, U[k])`` with ``U = sqrt(s P)``."""
        U = np.asarray(self.sqrt(self._spread() * P), dtype=np.float64)  # noqa: N806
        n = self.n
        sigmas = np.zeros((2 * n + 1, n))
        sigmas[0] = x
        for k in range(n):
            sigmas[k + 1] = self.subtract(x, -U[k])
            sigmas[n + k + 1] = self.subtract(x, U[k])
        return sigmas

    def num_sigmas(self) -> int:
        """Number of sigma points."""
        return 2 * self.n + 1

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={getattr(self, k)}" for k in ("n", "alpha", "beta", "kappa") if k in self._shown)
        return f"{type(self).__name__}({params})"

    _shown: tuple[str, ...] = ("n",)


class MerweScaledSigmaPoints(_SigmaPoints):
    """Van der Merwe's scaled sigma points (as ``filterpy.kalman.MerweScaledSigmaPoints``).

    With ``lambda = alpha**2 * (n + kappa) - n``: ``Wm[0] = lambda / (n + lambda)``,
    ``Wc[0] = Wm[0] + 1 - alpha**2 + beta``, all other weights ``1 / (2 (n + lambda))``. The
    points are ``x``, then ``x + U[k]`` and ``x - U[k]`` for the rows ``U[k]`` of the upper
    Cholesky factor of ``(n + lambda) P`` (or of ``sqrt_method((n + lambda) P)``), with
    ``subtract(x, -U[k])`` / ``subtract(x, U[k])`` when ``subtract`` is given.
    """

    _family = "merwe"
    _shown = ("n", "alpha", "beta", "kappa")

    def __init__(
        self,
        n: int,
        alpha: float,
        beta: float,
        kappa: float,
        sqrt_method: Callable[[F64Array], ArrayLike] | None = None,
        subtract: Callable[[F64Array, F64Array], ArrayLike] | None = None,
    ) -> None:
        self.alpha = float(alpha)
        self.beta = float(beta)
        self.kappa = float(kappa)
        super().__init__(n, sqrt_method, subtract)

    def _spread(self) -> float:
        return self.alpha**2 * (self.n + self.kappa)


class JulierSigmaPoints(_SigmaPoints):
    """Julier's symmetric sigma points (as ``filterpy.kalman.JulierSigmaPoints``).

    ``Wm[0] = kappa / (n + kappa)``, the others ``1 / (2 (n + kappa))``, ``Wc = Wm``; the points
    are ``x`` and ``x ± U[k]`` for the rows of the upper Cholesky factor of ``(n + kappa) P``.
    ``n + kappa`` must be positive.
    """

    _family = "julier"
    _shown = ("n", "kappa")

    def __init__(
        self,
        n: int,
        kappa: float = 0.0,
        sqrt_method: Callable[[F64Array], ArrayLike] | None = None,
        subtract: Callable[[F64Array, F64Array], ArrayLike] | None = None,
    ) -> None:
        self.alpha = 1.0
        self.beta = 0.0
        self.kappa = float(kappa)
        super().__init__(n, sqrt_method, subtract)

    def _spread(self) -> float:
        return self.n + self.kappa


class SimplexSigmaPoints(_SigmaPoints):
    """Julier's spherical simplex sigma points (as ``filterpy.kalman.SimplexSigmaPoints``).

    ``n + 1`` points ``x + L C[:, j]`` with equal weights ``1 / (n + 1)``, ``L`` the lower
    Cholesky factor of ``P`` (the transpose of ``sqrt_method(P)``) and ``C`` the unit simplex
    scaled by ``sqrt(n)``. ``alpha`` is kept for filterpy's signature; like filterpy, it is unused.
    """

    _family = "simplex"
    _shown = ("n", "alpha")

    def __init__(
        self,
        n: int,
        alpha: float = 1.0,
        sqrt_method: Callable[[F64Array], ArrayLike] | None = None,
        subtract: Callable[[F64Array, F64Array], ArrayLike] | None = None,
    ) -> None:
        self.alpha = float(alpha)
        self.beta = 0.0
        self.kappa = 0.0
        super().__init__(n, sqrt_method, subtract)

    def _spread(self) -> float:
        return 1.0

    def num_sigmas(self) -> int:
        """Number of sigma points, ``n + 1``."""
        return self.n + 1

    def _with_hooks(self, x: F64Array, P: F64Array) -> F64Array:  # noqa: N803
        """``subtract(x, -U.T @ C)`` on the whole ``(n, n+1)`` offset matrix, as filterpy."""
        U = np.asarray(self.sqrt(P), dtype=np.float64)  # noqa: N806
        # The unit simplex C: the points of (0, I) are x + I C = C.
        C = _core.family_sigma_points("simplex", np.zeros(self.n), np.eye(self.n)).T  # noqa: N806
        return np.asarray(self.subtract(x.reshape(-1, 1), -(U.T @ C)), dtype=np.float64).T


def unscented_transform(
    sigmas: ArrayLike,
    Wm: ArrayLike,  # noqa: N803 (filterpy's name)
    Wc: ArrayLike,  # noqa: N803
    noise_cov: ArrayLike | None = None,
    mean_fn: Callable[[F64Array, F64Array], ArrayLike] | None = None,
    residual_fn: Callable[[F64Array, F64Array], ArrayLike] | None = None,
) -> tuple[F64Array, F64Array]:
    """Mean and covariance of sigma points ``(N, n)`` (the unscented transform).

    ``x = sum Wm_i s_i`` (or ``mean_fn(sigmas, Wm)``), ``P = sum Wc_i r_i r_i^T + noise_cov`` with
    ``r_i = residual_fn(s_i, x)`` (default ``s_i - x``).

    The signature and conventions of ``filterpy.kalman.unscented_transform`` (seed
    000_3b1454b2b2194811.txt §5.2): the default ``UT`` of
    :class:`~autoteach.estimate.UnscentedKalmanFilter`'s ``predict``/``update``/``rts_smoother``.
    """
    s = as_finite_f64(sigmas, "sigmas")
    if s.ndim != 2:
        raise InvalidInputError(f"sigmas must have shape (N, n) (one sigma point per row), got {s.shape}")
    wm = as_finite_f64(Wm, "Wm")
    wc = as_finite_f64(Wc, "Wc")
    for name, w in (("Wm", wm), ("Wc", wc)):
        if w.shape != (s.shape[0],):
            raise InvalidInputError(
                f"{name} must have shape ({s.shape[0]},) (one weight per row of sigmas), got {w.shape}"
            )
    n = s.shape[1]
    noise = None if noise_cov is None else as_finite_f64(noise_cov, "noise_cov")
    if noise is not None and noise.shape not in ((), (1,), (n, n), (1, 1)):
        raise InvalidInputError(f"noise_cov must be a scalar or ({n}, {n}), got shape {noise.shape}")
    with np.errstate(over="ignore", invalid="ignore"):
        x = wm @ s if mean_fn is None else np.asarray(mean_fn(s, wm), dtype=np.float64)
        if residual_fn is None or residual_fn is np.subtract:
            d = s - x[np.newaxis, :]
        else:
            d = np.array([np.asarray(residual_fn(si, x), dtype=np.float64).reshape(-1) for si in s])
        P = (d.T * wc) @ d  # noqa: N806
        if noise is not None:
            P = P + noise  # noqa: N806
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
        raise InvalidInputError(
            "sigmas must be small enough for their mean and covariance to fit in float64; they overflow"
        )
    return x, P
