"""Collision-free paths and time-optimal B-spline trajectories for the wafer robot (issue 30).

000_3b1454b2b2194811.txt ch. 2.2-2.4: the workspace and signed distance (eq. 2.17), A* and RRT*
(ch. 2.3), clamped cubic B-splines (eqs. 2.10-2.15) and the time-optimal optimisation of
eq. (2.16), solved by sequential convex QPs (clarabel) in the compiled core.

Example:
    >>> from autoteach import plan
    >>> ws, poses = plan.default_scene()
    >>> p = plan.plan_path(ws, poses["home"], poses["chamber"])
    >>> r = plan.optimize_trajectory(ws, p.path, plan.Limits())
    >>> r.verification.min_clearance >= 0.01
    True
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError

__all__ = [
    "BSplineTrajectory",
    "Limits",
    "OptimizeResult",
    "PathResult",
    "Verification",
    "WaypointResult",
    "Workspace",
    "clearance",
    "default_scene",
    "inverse_dynamics",
    "optimize_trajectory",
    "optimize_waypoints",
    "plan_path",
]


def _joints(q: Any, name: str) -> np.ndarray:
    arr = as_f64(q, name)
    return arr.reshape(-1) if arr.ndim == 1 else arr


class Workspace:
    """The robot (with a 300 mm wafer on blade 1 by default), joint limits and box obstacles.

    Args:
        obstacles: ``(name, pose, half_extents)`` triples: a 4x4 world pose of the box centre and
            its three half extents in metres.
        wafer: whether blade 1 carries a wafer.
    """

    __slots__ = ("_ws",)

    def __init__(self, obstacles: list[tuple[str, Any, Any]] | None = None, wafer: bool = True) -> None:
        obs = [
            (str(n), np.asarray(p, dtype=np.float64), np.asarray(h, dtype=np.float64)) for n, p, h in obstacles or []
        ]
        self._ws = _core.PlanWorkspace(obs, wafer)

    @classmethod
    def _wrap(cls, compiled: Any) -> Workspace:
        ws = cls.__new__(cls)
        ws._ws = compiled
        return ws

    def obstacles(self) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """``(name, pose 4x4, half_extents)`` of every obstacle."""
        return [(n, np.asarray(p), np.asarray(h)) for n, p, h in self._ws.obstacles()]

    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper joint limits ``(θ1, θ2, θ3, θ4, h)``."""
        lo, hi = self._ws.joint_limits()
        return np.asarray(lo), np.asarray(hi)

    def link_centres(self, q: Any) -> list[tuple[str, np.ndarray]]:
        """Names and world centres of the robot's link shapes at ``q``."""
        return [(n, np.asarray(c)) for n, c in self._ws.link_centres(_joints(q, "q"))]

    def distance_gradient(self, q: Any) -> tuple[float, np.ndarray]:
        """Signed distance at ``q`` and its gradient in ``q`` (central differences)."""
        d, g = self._ws.distance_gradient(_joints(q, "q"))
        return float(d), np.asarray(g)


def default_scene() -> tuple[Workspace, dict[str, np.ndarray]]:
    """The seed-like scene: two carriers with slots, a chamber wall, the floor, and named poses."""
    ws, poses = _core.plan_default_scene()
    return Workspace._wrap(ws), {n: np.asarray(q) for n, q in poses}


def clearance(workspace: Workspace, q: Any) -> tuple[float, str, str] | None:
    """``(signed distance, link, obstacle)`` of the closest pair at ``q``; ``None`` without obstacles."""
    return workspace._ws.clearance(_joints(q, "q"))


@dataclass(frozen=True, slots=True)
class PathResult:
    """A planned path (Rust ``plan::astar::PathResult``)."""

    path: np.ndarray
    cost: float
    iterations: int
    collision_checks: int
    time_s: float
    extra: dict[str, float] = field(default_factory=dict)


def plan_path(
    workspace: Workspace,
    q_start: Any,
    q_goal: Any,
    method: str = "rrt*",
    margin: float = 0.02,
    max_iterations: int = 3000,
    seed: int = 7,
    step_deg: float = 5.0,
    joints: list[int] | None = None,
    time_limit_s: float | None = None,
) -> PathResult:
    """Plan a collision-free path with RRT* (``"rrt*"``) or A* on a joint lattice (``"a*"``).

    Args:
        workspace: the robot and its obstacles.
        q_start: start joints (5,).
        q_goal: goal joints (5,).
        method: ``"rrt*"`` or ``"a*"``.
        margin: clearance (m) every configuration on the path keeps.
        max_iterations: RRT*: sampling iterations. A*: the search pops at most ``1000 ×`` this many
            lattice entries, each with its edge check, so an unreachable goal ends in
            :class:`~autoteach.errors.ConvergenceError` within a bounded time.
        seed: RRT*'s sampling seed.
        step_deg: A*'s lattice step of the revolute joints (degrees); the lift's step scales with it.
        joints: the joints A* plans (the others stay at the start's values); default all.
        time_limit_s: RRT*: stop at the first iteration after this many seconds once a path
            exists (default: spend the whole iteration budget).

    Raises:
        InvalidInputError: start or goal in collision (the message names the link and obstacle) or
            malformed input.
        ConvergenceError: no path within the budget.
        AllocationError: an RRT* budget whose tree (one node per iteration) cannot fit in this
            machine's physical memory; RRT* refines until its budget is spent, so such a budget
            would run for hours before failing.
    """
    if not isinstance(method, str):
        raise InvalidInputError(f"method must be 'rrt*' or 'a*', got {type(method).__name__}")
    if joints is not None:
        if isinstance(joints, (str, bytes)) or not hasattr(joints, "__iter__"):
            raise InvalidInputError(f"joints must be a list of joint indices, got {type(joints).__name__}")
        joints = [as_int(j, f"joints[{i}]") for i, j in enumerate(joints)]
    budget = as_int(max_iterations, "max_iterations")
    d = _core.plan_path(
        workspace._ws,
        _joints(q_start, "q_start"),
        _joints(q_goal, "q_goal"),
        method,
        as_float(margin, "margin"),
        budget,
        as_int(seed, "seed"),
        as_float(step_deg, "step_deg"),
        joints,
        None if time_limit_s is None else as_float(time_limit_s, "time_limit_s"),
    )
    keys = ("path", "cost", "iterations", "collision_checks", "time_s")
    return PathResult(*(d.pop(k) for k in keys), extra=d)


@dataclass(frozen=True, slots=True)
class Limits:
    """Velocity, acceleration, jerk and torque limits per joint and the clearance ``d_safe``."""

    velocity: tuple[float, ...] = (3.0, 3.0, 4.0, 4.0, 0.5)
    acceleration: tuple[float, ...] = (10.0, 10.0, 15.0, 15.0, 2.0)
    jerk: tuple[float, ...] = (100.0, 100.0, 150.0, 150.0, 20.0)
    torque: tuple[float, ...] = (200.0, 100.0, 20.0, 20.0, 600.0)
    d_safe: float = 0.01


@dataclass(frozen=True, slots=True)
class Verification:
    """Dense 1 ms check: largest |value|/limit per kind and the smallest clearance."""

    velocity_ratio: float
    acceleration_ratio: float
    jerk_ratio: float
    torque_ratio: float
    min_clearance: float
    samples: int


@dataclass(frozen=True, slots=True)
class BSplineTrajectory:
    """A clamped cubic B-spline trajectory (eqs. 2.11, 2.14): knots and control points."""

    knots: np.ndarray
    control_points: np.ndarray

    @property
    def duration(self) -> float:
        """The duration ``T``."""
        return float(self.knots[-1] - self.knots[0])

    def sample(self, t: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities, accelerations and jerks at times ``t`` (each (M, 5))."""
        times = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return _core.plan_sample(self.knots, self.control_points, times)

    def save(self, path: str | Path) -> None:
        """Write the trajectory as JSON."""
        Path(path).write_text(
            json.dumps({"knots": self.knots.tolist(), "control_points": self.control_points.tolist()})
        )

    @classmethod
    def load(cls, path: str | Path) -> BSplineTrajectory:
        """Read a trajectory written by :meth:`save`."""
        d = json.loads(Path(path).read_text())
        return cls(np.asarray(d["knots"], dtype=np.float64), np.asarray(d["control_points"], dtype=np.float64))

    def plot(self, ax: Any = None, path: Any = None) -> Any:
        """Joint trajectories against time (Figs. 2.10-2.11); needs the ``plot`` extra."""
        try:
            import matplotlib.pyplot as plt
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("plotting needs matplotlib: pip install 'autoteach[plot]'") from e
        if ax is None:
            _, ax = plt.subplots()
        t = np.linspace(0.0, self.duration, 400)
        q = self.sample(t)[0]
        for i, name in enumerate(("JT2 θ1", "JT4 θ2", "JT6 θ3", "JT7 θ4", "JT3 h")):
            ax.plot(t, q[:, i], label=name)
            if path is not None:
                p = np.asarray(path)
                ax.plot(np.linspace(0.0, self.duration, len(p)), p[:, i], "--", color=ax.lines[-1].get_color())
        ax.set_xlabel("time (s)")
        ax.legend()
        return ax


@dataclass(frozen=True, slots=True)
class OptimizeResult:
    """The optimised trajectory (Rust ``plan::OptimizeResult``)."""

    trajectory: BSplineTrajectory
    duration: float
    initial_duration: float
    lower_bound: float
    bound_joint: int
    gap: float
    active: list[str]
    iterations: int
    accepted: int
    time_s: float
    verification: Verification


def optimize_trajectory(
    workspace: Workspace, path: Any, limits: Limits | None = None, n_ctrl: int = 0, max_iterations: int = 40
) -> OptimizeResult:
    """Time-optimal clamped cubic B-spline along ``path`` (N x 5), rest to rest (eq. 2.16).

    Raises:
        InvalidInputError: infeasible limits (the message names the limit), a start or goal in
            collision, or a malformed path.
    """
    lim = limits or Limits()
    names = ("velocity", "acceleration", "jerk", "torque")
    vec = [as_f64(getattr(lim, n), f"limits.{n}") for n in names]
    d = _core.plan_optimize(
        workspace._ws,
        as_f64(path, "path"),
        *vec,
        as_float(lim.d_safe, "limits.d_safe"),
        as_int(n_ctrl, "n_ctrl"),
        as_int(max_iterations, "max_iterations"),
    )
    traj = BSplineTrajectory(np.asarray(d["knots"]), np.asarray(d["control_points"]))
    return OptimizeResult(
        trajectory=traj,
        duration=d["duration"],
        initial_duration=d["initial_duration"],
        lower_bound=d["lower_bound"],
        bound_joint=d["bound_joint"],
        gap=d["gap"],
        active=list(d["active"]),
        iterations=d["iterations"],
        accepted=d["accepted"],
        time_s=d["time_s"],
        verification=Verification(**d["verification"]),
    )


@dataclass(frozen=True, slots=True)
class WaypointResult:
    """A transfer through fixed way-points (Rust ``plan::WaypointResult``, seed Table 2.2)."""

    segments: list[BSplineTrajectory]
    velocities: np.ndarray
    duration: float
    initial_duration: float
    iterations: int
    accepted: int
    time_s: float
    verification: list[Verification]


def optimize_waypoints(
    workspace: Workspace,
    paths: list[Any],
    limits: Limits | None = None,
    free_velocities: bool = True,
    n_ctrl: int = 0,
    max_iterations: int = 40,
) -> WaypointResult:
    """Time-optimal transfer through the fixed way-points that join ``paths`` (seed Table 2.2).

    Segment ``k`` follows ``paths[k]`` (N x 5); ``paths[k][-1]`` must equal ``paths[k + 1][0]``
    (the way-point). The transfer starts and ends at rest and has zero acceleration at the
    way-points. Every segment is first optimised rest to rest (total ``initial_duration``); the
    joint problem then refines all segments together, with the way-point velocities as unknowns
    when ``free_velocities`` (eqs. 2.15-2.17) and held at zero otherwise (same iterations).

    Raises:
        InvalidInputError: paths that do not join, infeasible limits, a way-point in collision,
            or a malformed path.
    """
    if isinstance(paths, (str, bytes)) or not hasattr(paths, "__iter__"):
        raise InvalidInputError(f"paths must be a list of (N, 5) arrays, got {type(paths).__name__}")
    lim = limits or Limits()
    names = ("velocity", "acceleration", "jerk", "torque")
    vec = [as_f64(getattr(lim, n), f"limits.{n}") for n in names]
    d = _core.plan_optimize_waypoints(
        workspace._ws,
        [as_f64(p, f"paths[{k}]") for k, p in enumerate(paths)],
        *vec,
        as_float(lim.d_safe, "limits.d_safe"),
        bool(free_velocities),
        as_int(n_ctrl, "n_ctrl"),
        as_int(max_iterations, "max_iterations"),
    )
    return WaypointResult(
        segments=[BSplineTrajectory(np.asarray(k), np.asarray(c)) for k, c in d["segments"]],
        velocities=np.asarray(d["velocities"]).reshape(-1, 5),
        duration=d["duration"],
        initial_duration=d["initial_duration"],
        iterations=d["iterations"],
        accepted=d["accepted"],
        time_s=d["time_s"],
        verification=[Verification(**v) for v in d["verification"]],
    )


def inverse_dynamics(q: Any, dq: Any, ddq: Any, wafer: bool = True) -> np.ndarray:
    """Joint torques and lift force ``τ(q, q̇, q̈)`` (eqs. 2.8-2.9) with the default masses."""
    return _core.plan_inverse_dynamics(_joints(q, "q"), _joints(dq, "dq"), _joints(ddq, "ddq"), wafer)
