"""Joint trajectories of the simulated robot: clamped cubic B-splines through planned waypoints.

The robot's trajectories are curves in joint space parameterised by time and represented by
clamped B-splines, 000_3b1454b2b2194811.txt ch. 2.4: basis functions by the Cox–de Boor recursion
eq. (2.10), the curve eq. (2.11), derivatives eq. (2.12) and the clamped knot vector eq. (2.14)
that pins the curve to the first and last control points (eq. (2.15)). A cubic spline is twice
continuously differentiable, so joint velocities and accelerations are continuous.
"""

from __future__ import annotations

import numpy as np

from autoteach.errors import InvalidInputError


class BSpline:
    """A clamped B-spline ``B(t) = Σ P_i N_{i,k}(t)`` (000_3b1454b2b2194811.txt eqs. (2.10), (2.11), (2.14)).

    Args:
        control_points: (n, D) control points ``P_i``.
        t0, t1: the time interval; the interior knots are spaced uniformly in it.
        degree: spline degree ``k`` (3 = cubic); lowered to ``n − 1`` if there are fewer points.
        knots: optional explicit knot vector of length ``n + k + 1`` (overrides ``t0``/``t1``).

    """

    def __init__(
        self,
        control_points: np.ndarray,
        t0: float = 0.0,
        t1: float = 1.0,
        degree: int = 3,
        knots: np.ndarray | None = None,
    ) -> None:
        p = np.asarray(control_points, dtype=np.float64)
        if p.ndim == 1:
            p = p[:, None]
        if p.ndim != 2 or p.shape[0] < 1:
            raise InvalidInputError(f"control_points must have shape (n, D) with n >= 1, got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise InvalidInputError("control_points must be finite")
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            raise InvalidInputError(f"need a finite time interval t0 < t1, got [{t0}, {t1}]")
        n = p.shape[0]
        k = min(int(degree), n - 1)
        if k < 0:
            raise InvalidInputError(f"degree must be >= 0, got {degree}")
        if knots is None:
            # Clamped knots, eq. (2.14): k + 1 repeated knots at each end, uniform interior knots.
            interior = np.linspace(t0, t1, n - k + 1)[1:-1]
            knots = np.concatenate([np.full(k + 1, t0), interior, np.full(k + 1, t1)])
        knots = np.asarray(knots, dtype=np.float64)
        if knots.shape != (n + k + 1,) or np.any(np.diff(knots) < 0):
            raise InvalidInputError(f"knots must be a non-decreasing vector of length {n + k + 1}")
        self.control_points = p
        self.degree = k
        self.knots = knots

    @property
    def t0(self) -> float:
        """Start of the parameter interval."""
        return float(self.knots[self.degree])

    @property
    def t1(self) -> float:
        """End of the parameter interval."""
        return float(self.knots[-self.degree - 1])

    def basis(self, t: np.ndarray) -> np.ndarray:
        """Basis functions ``N_{i,k}(t)`` (m, n) by the Cox–de Boor recursion, eq. (2.10).

        Times are clamped to ``[t0, t1]``; the last knot span is closed so that ``B(t1) = P_n``.
        """
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=np.float64)), self.t0, self.t1)
        kn = self.knots
        n = self.control_points.shape[0]
        k = self.degree
        # Degree 0: indicator of the knot span [kn_i, kn_{i+1}); the last non-empty span is closed.
        last = int(np.nonzero(kn[:-1] < kn[1:])[0][-1]) if np.any(kn[:-1] < kn[1:]) else 0
        nb = len(kn) - 1
        b = ((kn[None, :-1] <= t[:, None]) & (t[:, None] < kn[None, 1:])).astype(np.float64)
        b[t >= kn[last + 1], :] = 0.0
        b[t >= kn[last + 1], last] = 1.0
        for d in range(1, k + 1):
            nb -= 1
            left_den = kn[d : d + nb] - kn[:nb]
            right_den = kn[d + 1 : d + 1 + nb] - kn[1 : 1 + nb]
            with np.errstate(divide="ignore", invalid="ignore"):
                left = np.where(left_den > 0, (t[:, None] - kn[None, :nb]) / left_den, 0.0)
                right = np.where(right_den > 0, (kn[None, d + 1 : d + 1 + nb] - t[:, None]) / right_den, 0.0)
            b = left * b[:, :nb] + right * b[:, 1 : nb + 1]
        return b[:, :n]

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        """Evaluate ``B(t)`` (eq. (2.11)); returns (m, D) for m times (or (D,) for a scalar time)."""
        scalar = np.ndim(t) == 0
        out = self.basis(np.asarray(t)) @ self.control_points
        return out[0] if scalar else out

    def derivative(self) -> BSpline:
        """Return the derivative spline ``B'(t) = Σ V_i N_{i,k−1}(t)``, eq. (2.12)."""
        k = self.degree
        p = self.control_points
        if k == 0:
            return BSpline(np.zeros((1, p.shape[1])), self.t0, self.t1, degree=0)
        kn = self.knots
        den = kn[k + 1 : k + p.shape[0]] - kn[1 : p.shape[0]]
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(den[:, None] > 0, k * (p[1:] - p[:-1]) / den[:, None], 0.0)
        return BSpline(v, degree=k - 1, knots=kn[1:-1])


def sweep_waypoints(
    rng: np.random.Generator,
    n: int,
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    z_range: tuple[float, float],
    yaw_max: float,
    sweeps: float = 2.0,
) -> np.ndarray:
    """Camera waypoints ``(x, y, z, yaw)`` (n, 4) that sweep the carrier's height range.

    The height follows a triangle wave starting at the top of ``z_range`` that covers the range
    ``sweeps`` times (down, up, ...), jittered by 5 % of the range; ``x``, ``y`` and the yaw are
    drawn uniformly from their ranges. A single waypoint (``n = 1``) is a static camera.
    """
    if n < 1:
        raise InvalidInputError(f"need at least one waypoint, got {n}")
    lo, hi = z_range
    if n == 1:
        phase = np.array([0.5])
    else:
        s = np.linspace(0.0, sweeps, n)
        phase = 1.0 - np.abs(((s + 1.0) % 2.0) - 1.0)  # 1, ..., 0, ..., 1: triangle wave from the top
        phase = np.clip(phase + rng.uniform(-0.05, 0.05, n), 0.0, 1.0)
    z = lo + (hi - lo) * phase
    x = rng.uniform(*x_range, n)
    y = rng.uniform(*y_range, n)
    yaw = rng.uniform(-yaw_max, yaw_max, n)
    return np.stack([x, y, z, yaw], axis=1)


def unwrap_to(angles: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Shift each angle by a multiple of 2π to lie within π of the reference angle."""
    return reference + (angles - reference + np.pi) % (2.0 * np.pi) - np.pi
