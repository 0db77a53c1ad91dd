"""The text of every error on bad input (issue 38): it names the argument, the value and the expectation.

The property suites (``tests/test_properties*.py``) check the class of the exception a hostile
input raises. This module checks what it says. Each row of :data:`CASES` feeds one entry point
of those suites one bad input (a wrong shape, a wrong dtype, NaN or infinity, a negative size, an
empty array, an out-of-range option, ``None``) and :func:`says` checks that the raised
:class:`~autoteach.errors.AutoteachError`:

- names the argument by its Python name (as a word of the message);
- shows the offending value, shape or dtype (case-insensitively: Rust prints ``NaN``, Python
  ``nan``), and no number longer than :data:`LONGEST_TOKEN` characters;
- states the expectation (one of the phrases of :data:`EXPECTATION`).

:func:`test_every_property_entry_point_is_audited` keeps the table in step with the property
suites, and :func:`test_hostile_examples_of_the_property_suite_say_what_was_expected` runs the
suites' own Hypothesis strategies (a few examples per entry point) through the last two checks.
"""

from __future__ import annotations

import contextlib
import io
import re
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import test_properties
from autoteach import (
    calib,
    control,
    detect,
    estimate,
    fusion,
    geometry,
    mapping,
    plan,
    polygon,
    radio,
    registration,
    segment,
    track,
    uncertainty,
)
from autoteach.errors import AutoteachError, InternalError, InvalidInputError
from autoteach.sigma_points import MerweScaledSigmaPoints
from test_properties_cli import calibration_views

#: Phrases that state what was expected. A message saying only what is wrong ("contains a
#: non-finite value") leaves the reader to guess the fix.
EXPECTATION = re.compile(
    r"\b(must|expected|expects|at least|at most|one of|needs?|requires?|is not an?|the options are)\b",
    re.IGNORECASE,
)
#: The longest run of digits a message may print (a 300-digit integer is elided).
LONGEST_TOKEN = 40


def says(call: Callable[[], Any], arg: str, shows: str) -> None:
    """``call()`` raises an AutoteachError naming ``arg``, showing ``shows`` and stating the expectation."""
    try:
        call()
    except InternalError as e:  # a Rust panic caught at the boundary
        raise AssertionError(f"panic: {e}") from e
    except AutoteachError as e:
        msg = str(e)
    else:
        raise AssertionError(f"no error for bad {arg} ({shows})")
    problems = []
    if not re.search(rf"(?<!\w){re.escape(arg)}(?!\w)", msg):
        problems.append(f"does not name {arg!r}")
    if shows.lower() not in msg.lower():
        problems.append(f"does not show {shows!r}")
    if not EXPECTATION.search(msg):
        problems.append("states no expectation")
    problems += [f"prints a {len(t)}-digit number" for t in re.findall(r"\d+", msg) if len(t) > LONGEST_TOKEN]
    assert not problems, f"{'; '.join(problems)}: {msg!r}"


class Case(NamedTuple):
    """One bad input: the entry point (a key of the property suites), the call and what its error must say."""

    entry: str
    arg: str
    shows: str
    call: Callable[[], Any]


# -- nominal inputs ----------------------------------------------------------------------------

NAN = float("nan")
K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
POSE = np.eye(4)
POSE[2, 3] = 1.0
HUGE_R = geometry.so3_exp([0.3, 0.2, 0.1]) * 1e200
RNG = np.random.default_rng(38)
P2 = RNG.normal(size=(20, 2))
P3 = RNG.normal(size=(20, 3))
IMAGE = np.full((48, 64), 128, dtype=np.uint8)
BOX = np.array([0.0, 0.0, 4.0, 2.0, 0.3])
COV5 = np.eye(5) * 0.01


def _nan(a: Any, index: Any = 0) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flat[index] = NAN
    return a


def _ellipse() -> geometry.Ellipse:
    return geometry.Ellipse(0.0, 0.0, 2.0, 1.0, 0.0)


def _camera(**kw: Any) -> geometry.Camera:
    args = {"model": "pinhole", "params": [500.0, 500.0, 320.0, 240.0], "width": 640, "height": 480, **kw}
    return geometry.Camera(**args)


def _ukf() -> estimate.UnscentedKalmanFilter:
    pts = MerweScaledSigmaPoints(2, 0.1, 2.0, 0.0)
    return estimate.UnscentedKalmanFilter(dim_x=2, dim_z=1, dt=0.1, fx=lambda x, dt: x, hx=lambda x: x[:1], points=pts)


def _ukf_kw(**kw: Any) -> Callable[[], Any]:
    base = {"dim_x": 2, "dim_z": 1, "dt": 0.1, "fx": lambda x, dt: x, "hx": lambda x: x[:1]}
    base["points"] = MerweScaledSigmaPoints(2, 0.1, 2.0, 0.0)
    return lambda: estimate.UnscentedKalmanFilter(**{**base, **kw})


def _ukf_set(name: str, value: Any) -> Callable[[], Any]:
    def call() -> Any:
        u = _ukf()
        setattr(u, name, value)
        u.predict()
        u.update(np.array([0.5]))

    return call


def _ukf_update(z: Any) -> Callable[[], Any]:
    def call() -> Any:
        u = _ukf()
        u.predict()
        u.update(z)

    return call


def _lsq(step: Callable[[estimate.LeastSquaresProblem], Any]) -> Callable[[], Any]:
    def call() -> Any:
        p = estimate.LeastSquaresProblem()
        p.add_pose(np.eye(4))
        step(p)

    return call


def _ba_args() -> dict[str, Any]:
    poses = np.stack([np.eye(4)] * 2)
    poses[1, :3, 3] = [0.2, 0.0, 0.0]
    pts = RNG.normal(size=(6, 3)) * 0.3 + [0, 0, 3]
    pi, qi = np.repeat([0, 1], 6), np.tile(np.arange(6), 2)
    cam = [(p[:3, :3].T @ (x - p[:3, 3])) for p, x in zip(poses[pi], pts[qi], strict=True)]
    obs = np.array([(K @ c)[:2] / c[2] for c in cam])
    return {"K": K, "poses": poses, "points": pts, "observations": obs, "pose_index": pi, "point_index": qi}


def _ba(**kw: Any) -> Callable[[], Any]:
    return lambda: estimate.bundle_adjust(**{**_ba_args(), "fixed_poses": [0], **kw})


def _radio(model: type, **kw: Any) -> Callable[[], Any]:
    n = 10
    args = {
        "tx": RNG.normal(size=(n, 2)),
        "rx": RNG.normal(size=(n, 2)) + 5.0,
        "rss": -60.0 - np.arange(n, dtype=float),
        **kw,
    }
    return lambda: model().fit(**args)


def _tracker(camera_pose: Any = None, edges: Any = None, **params: Any) -> Callable[[], Any]:
    def call() -> Any:
        t = np.linspace(0.2, 2.8, 30)
        good = np.c_[300 + 200 * np.cos(t), 200 + 40 * np.sin(t)]
        tracker = track.WaferTracker(**params)
        e = [track.Edge(geometry.Ellipse(300.0, 200.0, 200.0, 40.0, 0.0), good)]
        tracker.update(e)
        tracker.update(e if edges is None else edges, camera_pose=camera_pose)

    return call


def _raster(**kw: Any) -> Callable[[], Any]:
    n = 2
    args = {
        "node_ids": np.arange(n),
        "robot_ids": np.zeros(n, dtype=np.int64),
        "poses": np.c_[np.arange(n, dtype=float), np.zeros(n), np.zeros(n)],
        "scans": np.full((n, 31), 5.0),
        **kw,
    }
    return lambda: mapping.Rasterizer(slice_size=2, resolution=0.5, beams=31, max_range=10.0).update(**args)


P_CAM = np.array([[600.0, -700.0, 0.0, 0.0], [180.0, 0.0, -700.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
POOL_PTS = RNG.uniform([1, -20, -1], [40, 20, 1], size=(50, 3))


def _pool(**kw: Any) -> Callable[[], Any]:
    args = {
        "points": POOL_PTS,
        "P": P_CAM,
        "image_grid": (23, 78, 16.0),
        "bev_grid": (0.0, -30.0, 1.0, 60, 60),
        "neighbourhood": 1,
        **kw,
    }
    return lambda: fusion.SparsePooling.build(**args)


def _tf(num: Any = (100.0,), den: Any = (1.0, 2.0, 0.0)) -> Callable[[], Any]:
    return lambda: control.bandwidth(control.TransferFunction(np.asarray(num), np.asarray(den)))


def _cpd(fn: Callable[..., Any], X: Any = P2, Y: Any = P2[:15], **kw: Any) -> Callable[[], Any]:
    return lambda: fn(X, Y, **kw)


def _robot_ik(**kw: Any) -> Callable[[], Any]:
    def call() -> Any:
        robot = geometry.WaferRobot()
        args = {"T": robot.blade_pose(np.array([0.3, 0.4, -0.2, 0.1, 0.2])), **kw}
        robot.inverse_kinematics(**args)

    return call


def _scene() -> Any:
    return plan.default_scene()


def _plan(**kw: Any) -> Callable[[], Any]:
    def call() -> Any:
        ws, poses = _scene()
        args = {"q_start": poses["home"], "q_goal": poses["home"] + [0.2, -0.1, 0.1, 0.0, 0.01], "max_iterations": 5}
        plan.plan_path(ws, **{**args, **kw})

    return call


def _optimize(path: Any = None, **kw: Any) -> Callable[[], Any]:
    def call() -> Any:
        ws, poses = _scene()
        p = np.array([poses["home"], poses["home"] + [0.2, -0.1, 0.1, 0.0, 0.01]]) if path is None else path
        plan.optimize_trajectory(ws, p, **{"max_iterations": 2, **kw})

    return call


def _waypoints(paths: Any = None, gap: bool = False, **kw: Any) -> Callable[[], Any]:
    def call() -> Any:
        ws, poses = _scene()
        h = poses["home"]
        a = h + [0.2, -0.1, 0.1, 0.0, 0.01]
        b = a + [0.1, 0.05, 0.0, 0.0, 0.0]
        p = [np.array([h, a]), np.array([b, a]) if gap else np.array([a, b])] if paths is None else paths
        plan.optimize_waypoints(ws, p, **{"max_iterations": 2, **kw})

    return call


def _opening() -> Any:
    return polygon.simulate_opening(3, width=160, height=120)


def _polygon(**kw: Any) -> Callable[[], Any]:
    def call() -> Any:
        o = _opening()
        args = {"image_or_segments": o.image, "template": polygon.CROSS_TEMPLATE, "homography": o.homography, **kw}
        polygon.detect_polygon(**args)

    return call


def _calibrate(**kw: Any) -> Callable[[], Any]:
    def call() -> Any:
        obj, img, size = calibration_views()
        args = {"object_points": obj, "image_points": img, "model": "brown_conrady", "image_size": size}
        calib.calibrate(**{**args, "max_iterations": 5, "bootstrap": False, **kw})

    return call


def _view(**kw: Any) -> Callable[[], Any]:
    lens = calib.LENSES["medium"]
    pose = np.eye(4)
    pose[2, 3] = 0.5
    args = {
        "model": lens["model"],
        "params": np.asarray(lens["params"]),
        "image_size": lens["image_size"],
        "pose": pose,
        "target": calib.make_target(3, 2, 0.05),
        **kw,
    }
    return lambda: calib.simulate_view(**args)


def _session() -> Any:
    from autoteach.sim import SimConfig, simulate_session

    cfg = SimConfig(camera_params=(60.0, 60.0, 39.5, 22.0), width=80, height=45, supersample=1)
    return simulate_session(seed=1, frames=2, config=cfg)


def _write_log(tmp: str = "/tmp/autoteach-audit.mcap", **kw: Any) -> Callable[[], Any]:
    import dataclasses

    from autoteach.io import write_log

    def call() -> Any:
        s = _session()
        fields = {k: v for k, v in kw.items() if k != "compression"}
        extra = {"compression": kw["compression"]} if "compression" in kw else {}
        write_log(dataclasses.replace(s, **fields), tmp, **extra)

    return call


def _sim(**kw: Any) -> Callable[[], Any]:
    from autoteach.sim import SimConfig, simulate_session

    def call() -> Any:
        cfg_kw = {k: v for k, v in kw.items() if k not in ("seed", "frames")}
        cfg = SimConfig(**{"width": 80, "height": 45, "supersample": 1, **cfg_kw})
        simulate_session(seed=kw.get("seed", 0), frames=kw.get("frames", 1), config=cfg, render=False)

    return call


# -- the table ---------------------------------------------------------------------------------

CASES: list[Any] = [
    # geometry: Lie groups and rotations
    Case("so3_exp", "omega", "(4,)", lambda: geometry.so3_exp(np.zeros(4))),
    Case("so3_exp", "omega", "nan", lambda: geometry.so3_exp([NAN, 0.0, 0.0])),
    Case("so3_exp", "omega", "complex", lambda: geometry.so3_exp(np.zeros(3) + 1j)),
    Case("so3_exp", "omega", "None", lambda: geometry.so3_exp(None)),
    Case("so3_exp", "omega", "abc", lambda: geometry.so3_exp("abc")),
    Case("so3_log", "R", "(3, 4)", lambda: geometry.so3_log(np.zeros((3, 4)))),
    Case("so3_log", "R", "e199", lambda: geometry.so3_log(HUGE_R)),
    Case("so3_log", "R", "det R = -1", lambda: geometry.so3_log(-np.eye(3))),
    Case("se3_exp", "xi", "(5,)", lambda: geometry.se3_exp(np.zeros(5))),
    Case("se3_exp", "xi", "inf", lambda: geometry.se3_exp([np.inf, 0, 0, 0, 0, 0])),
    Case("se3_exp", "xi", "bool", lambda: geometry.se3_exp(np.zeros(6, dtype=bool))),
    Case("se3_log", "T", "(3, 3)", lambda: geometry.se3_log(np.eye(3))),
    Case("se3_log", "T", "last row", lambda: geometry.se3_log(np.ones((4, 4)))),
    Case("se3_log", "T", "()", lambda: geometry.se3_log(1.0)),
    Case("se3_plus", "xi", "(3,)", lambda: geometry.se3_plus(POSE, np.zeros(3))),
    Case("se3_plus", "T", "nan", lambda: geometry.se3_plus(_nan(POSE, 3), np.zeros(6))),
    Case("se3_minus", "Y", "(4, 3)", lambda: geometry.se3_minus(np.zeros((4, 3)), POSE)),
    Case("se3_minus", "X", "object", lambda: geometry.se3_minus(POSE, POSE.astype(object))),
    Case("matrix_to_quat", "R", "(2, 2)", lambda: geometry.matrix_to_quat(np.eye(2))),
    Case("matrix_to_quat", "R", "(0, 3)", lambda: geometry.matrix_to_quat(np.zeros((0, 3)))),
    Case("quat_to_matrix", "q", "(3,)", lambda: geometry.quat_to_matrix(np.zeros(3))),
    Case("quat_to_matrix", "q", "norm 0", lambda: geometry.quat_to_matrix(np.zeros(4))),
    Case("matrix_to_euler_zyx", "R", "nan", lambda: geometry.matrix_to_euler_zyx(_nan(np.eye(3)))),
    Case("euler_zyx_to_matrix", "angles", "(2,)", lambda: geometry.euler_zyx_to_matrix(np.zeros(2))),
    Case("euler_zyx_to_matrix", "angles", "None", lambda: geometry.euler_zyx_to_matrix(None)),
    # geometry: ellipses, cameras, robot, circles
    Case("Ellipse.sample", "a", "-1", lambda: geometry.Ellipse(0.0, 0.0, -1.0, 1.0, 0.0)),
    Case("Ellipse.sample", "cx", "nan", lambda: geometry.Ellipse(NAN, 0.0, 2.0, 1.0, 0.0)),
    Case("Ellipse.sample", "theta", "x", lambda: geometry.Ellipse(0.0, 0.0, 2.0, 1.0, "x")),
    Case("Ellipse.sample", "n", "-1", lambda: _ellipse().sample(-1)),
    Case("Ellipse.sample", "n", "1.5", lambda: _ellipse().sample(1.5)),
    Case("Ellipse.sample", "n", "4611686018427387904", lambda: _ellipse().sample(2**62)),
    Case("Ellipse.sample", "n", "characters", lambda: _ellipse().sample(10**300)),
    Case("Ellipse.sample", "t0", "inf", lambda: _ellipse().sample(10, t0=np.inf)),
    Case("Ellipse.from_conic", "C", "(2, 2)", lambda: geometry.Ellipse.from_conic(np.eye(2))),
    Case("Ellipse.from_conic", "C", "nan", lambda: geometry.Ellipse.from_conic(_nan(np.eye(3)))),
    Case(
        "Ellipse.from_conic",
        "C",
        "symmetric",
        lambda: geometry.Ellipse.from_conic([[1, 5, 0], [-5, 1, 0], [0, 0, -1]]),
    ),
    Case("Camera.project", "model", "foo", lambda: _camera(model="foo")),
    Case("Camera.project", "params", "3", lambda: _camera(params=[500.0, 500.0, 320.0])),
    Case("Camera.project", "params", "nan", lambda: _camera(params=[NAN, 500.0, 320.0, 240.0])),
    Case("Camera.project", "width", "-1", lambda: _camera(width=-1)),
    Case("Camera.project", "width", "0", lambda: _camera(width=0)),
    Case("Camera.project", "points", "(7, 2)", lambda: _camera().project(np.ones((7, 2)))),
    Case("WaferRobot", "base", "(3, 3)", lambda: geometry.WaferRobot(base=np.eye(3))),
    Case("WaferRobot", "base", "e199", lambda: geometry.WaferRobot(base=np.pad(HUGE_R, ((0, 1), (0, 1))))),
    Case("WaferRobot", "T", "(4, 3)", _robot_ik(T=np.zeros((4, 3)))),
    Case("WaferRobot", "blade", "3", _robot_ik(blade=3)),
    Case("WaferRobot", "blade", "-1", _robot_ik(blade=-1)),
    Case("WaferRobot", "q_enc", "(4,)", lambda: geometry.joints_from_encoders(np.zeros(4), np.zeros(5))),
    Case("WaferRobot", "offsets", "nan", lambda: geometry.joints_from_encoders(np.zeros(5), _nan(np.zeros(5)))),
    Case("project_circle", "K", "(2, 2)", lambda: geometry.project_circle(np.eye(2), POSE, [0, 0, 0], [0, 0, 1], 0.1)),
    Case("project_circle", "center", "(2,)", lambda: geometry.project_circle(K, POSE, [0, 0], [0, 0, 1], 0.1)),
    Case("project_circle", "radius", "-1", lambda: geometry.project_circle(K, POSE, [0, 0, 0], [0, 0, 1], -1.0)),
    Case("project_circle", "radius", "nan", lambda: geometry.project_circle(K, POSE, [0, 0, 0], [0, 0, 1], NAN)),
    Case(
        "project_circle",
        "T_cw",
        "det",
        lambda: geometry.project_circle(K, np.diag([1.0, 1.0, -1.0, 1.0]), [0, 0, 0], [0, 0, 1], 0.1),
    ),
    Case("circle_image_conic", "K", "nan", lambda: geometry.circle_image_conic(_nan(K), POSE, 0.15)),
    Case("circle_image_conic", "T_co", "(4,)", lambda: geometry.circle_image_conic(K, np.zeros(4), 0.15)),
    Case("circle_image_conic", "radius", "0", lambda: geometry.circle_image_conic(K, POSE, 0.0)),
    # detection and assignment
    Case("detect_wafers", "image", "(3,)", lambda: detect.detect_wafers(np.zeros(3))),
    Case("detect_wafers", "image", "complex", lambda: detect.detect_wafers(IMAGE + 1j)),
    Case("detect_wafers", "image", "None", lambda: detect.detect_wafers(None)),
    Case("detect_wafers", "image", "(0, 0)", lambda: detect.detect_wafers(np.zeros((0, 0)))),
    Case("detect_wafers", "frobnicate", "frobnicate", lambda: detect.detect_wafers(IMAGE, frobnicate=1)),
    Case("detect_ellipses", "image", "(2, 3, 4, 5)", lambda: detect.detect_ellipses(np.zeros((2, 3, 4, 5)))),
    Case("detect_ellipses", "image", "nan", lambda: detect.detect_ellipses(_nan(IMAGE))),
    Case("detect_ellipses", "frobnicate", "frobnicate", lambda: detect.detect_ellipses(IMAGE, frobnicate=1)),
    Case(
        "assign_with_unassigned",
        "cost",
        "nan",
        lambda: detect.assign_with_unassigned(_nan(np.ones((3, 4))), np.ones(3), np.ones(4)),
    ),
    Case(
        "assign_with_unassigned",
        "row_unassigned_cost",
        "2",
        lambda: detect.assign_with_unassigned(np.ones((3, 4)), np.ones(2), np.ones(4)),
    ),
    Case(
        "assign_with_unassigned",
        "col_unassigned_cost",
        "5",
        lambda: detect.assign_with_unassigned(np.ones((3, 4)), np.ones(3), np.ones(5)),
    ),
    Case("assign_with_unassigned", "cost", "(3,)", lambda: detect.assign_with_unassigned(np.ones(3), [1.0], [1.0])),
    Case("fit_ellipse", "points", "(20, 3)", lambda: detect.fit_ellipse(P3)),
    Case("fit_ellipse", "points", "2", lambda: detect.fit_ellipse(P2[:2])),
    Case("fit_ellipse", "method", "foo", lambda: detect.fit_ellipse(P2, method="foo")),
    Case("fit_ellipse", "points", "inf", lambda: detect.fit_ellipse(np.full_like(P2, np.inf))),
    Case("linear_sum_assignment", "cost", "(3,)", lambda: detect.linear_sum_assignment(np.ones(3))),
    Case("linear_sum_assignment", "cost", "nan", lambda: detect.linear_sum_assignment(_nan(np.ones((2, 2))))),
    Case("linear_sum_assignment", "cost", "-inf", lambda: detect.linear_sum_assignment(-np.full((2, 2), np.inf))),
    # registration and voting
    Case("global_cpd", "k", "-1", _cpd(registration.global_cpd, k=-1)),
    Case("global_cpd", "w", "1.5", _cpd(registration.global_cpd, w=1.5)),
    Case("global_cpd", "Y", "length 3", _cpd(registration.global_cpd, Y=P3[:15])),
    Case("global_cpd", "low_rank", "-1", _cpd(registration.global_cpd, low_rank=-1)),
    Case("global_cpd", "frobnicate", "frobnicate", _cpd(registration.global_cpd, frobnicate=1)),
    Case("cpd_rigid", "w", "2", _cpd(registration.cpd_rigid, w=2.0)),
    Case("cpd_rigid", "max_iterations", "-1", _cpd(registration.cpd_rigid, max_iterations=-1)),
    Case("cpd_rigid", "e_step", "foo", _cpd(registration.cpd_rigid, e_step="foo")),
    Case("cpd_rigid", "X", "0", _cpd(registration.cpd_rigid, X=np.zeros((0, 2)))),
    Case("cpd_rigid", "tolerance", "nan", _cpd(registration.cpd_rigid, tolerance=NAN)),
    Case("cpd_affine", "X", "nan", _cpd(registration.cpd_affine, X=_nan(P3), Y=P3[:15])),
    Case("cpd_affine", "sigma2", "-1", _cpd(registration.cpd_affine, sigma2=-1.0)),
    Case("cpd_nonrigid", "beta", "0", _cpd(registration.cpd_nonrigid, beta=0.0)),
    Case("cpd_nonrigid", "lam", "-2", _cpd(registration.cpd_nonrigid, lam=-2.0)),
    Case("cpd_nonrigid", "low_rank", "-1", _cpd(registration.cpd_nonrigid, low_rank=-1)),
    Case("cpd_nonrigid", "low_rank", "12001", _cpd(registration.cpd_nonrigid, Y=RNG.normal(size=(12001, 2)))),
    Case("global_voting", "X", "nan", lambda: polygon.global_voting(_nan(P2), P2[:15])),
    Case("global_voting", "k", "-1", lambda: polygon.global_voting(P2, P2[:15], k=-1)),
    Case("global_voting", "Y", "length 3", lambda: polygon.global_voting(P2, P3[:15])),
    Case("global_voting", "neighbours", "-1", lambda: polygon.global_voting(P2, P2[:15], neighbours=-1)),
    Case("global_voting", "frobnicate", "frobnicate", lambda: polygon.global_voting(P2, P2[:15], frobnicate=1)),
    # mapping, fusion, tracking, control
    Case("Rasterizer.update", "poses", "(2, 2)", _raster(poses=np.zeros((2, 2)))),
    Case("Rasterizer.update", "robot_ids", "(3,)", _raster(robot_ids=np.zeros(3, dtype=np.int64))),
    Case("Rasterizer.update", "scans", "-1", _raster(scans=np.full((2, 31), -1.0))),
    Case("Rasterizer.update", "slice_size", "-1", lambda: mapping.Rasterizer(slice_size=-1)),
    Case("Rasterizer.update", "resolution", "0", lambda: mapping.Rasterizer(resolution=0.0)),
    Case("Rasterizer.update", "method", "foo", lambda: mapping.Rasterizer(method="foo")),
    Case("SparsePooling", "points", "(50, 2)", _pool(points=POOL_PTS[:, :2])),
    Case("SparsePooling", "P", "(3, 3)", _pool(P=np.eye(3))),
    Case("SparsePooling", "neighbourhood", "-1", _pool(neighbourhood=-1)),
    Case("SparsePooling", "image_grid", "-1", _pool(image_grid=(-1, 78, 16.0))),
    Case("SparsePooling", "bev_grid", "nan", _pool(bev_grid=(0.0, -30.0, NAN, 60, 60))),
    Case("maxmin_pool", "x", "(4, 5)", lambda: fusion.maxmin_pool(np.zeros((4, 5)))),
    Case("maxmin_pool", "x", "nan", lambda: fusion.maxmin_pool(_nan(np.zeros((4, 5, 3))))),
    Case("WaferTracker", "camera_pose", "(3, 3)", _tracker(camera_pose=np.eye(3))),
    Case("WaferTracker", "camera_pose", "e199", _tracker(camera_pose=np.pad(HUGE_R, ((0, 1), (0, 1))))),
    Case("WaferTracker", "edges", "None", _tracker(edges=[None])),
    Case("WaferTracker", "frobnicate", "frobnicate", _tracker(frobnicate=1)),
    Case("WaferTracker", "max_missed", "-1", _tracker(max_missed=-1)),
    Case("WaferTracker", "sigma", "'x'", _tracker(sigma="x")),
    Case("TransferFunction", "num", "nan", _tf(num=(NAN,))),
    Case("TransferFunction", "den", "(0,)", _tf(den=())),
    Case(
        "TransferFunction", "dbdrop", "3", lambda: control.bandwidth(control.TransferFunction([1.0], [1.0, 1.0]), 3.0)
    ),
    # uncertainty and planning
    Case(
        "spatial_distribution",
        "box",
        "(4,)",
        lambda: uncertainty.spatial_distribution(BOX[:4], COV5, points=np.zeros((9, 2))),
    ),
    Case(
        "spatial_distribution",
        "cov",
        "nan",
        lambda: uncertainty.spatial_distribution(BOX, _nan(COV5), points=np.zeros((9, 2))),
    ),
    Case(
        "spatial_distribution",
        "lattice",
        "-1",
        lambda: uncertainty.spatial_distribution(BOX, COV5, points=np.zeros((9, 2)), lattice=-1),
    ),
    Case(
        "spatial_distribution",
        "method",
        "foo",
        lambda: uncertainty.spatial_distribution(BOX, COV5, points=np.zeros((9, 2)), method="foo"),
    ),
    Case("iou", "box_a", "(4,)", lambda: uncertainty.iou(BOX[:4], BOX)),
    Case("iou", "box_b", "nan", lambda: uncertainty.iou(BOX, _nan(BOX))),
    Case("jiou", "grid", "-1", lambda: uncertainty.jiou(BOX, COV5, BOX, COV5, grid=-1)),
    Case("jiou", "samples", "0", lambda: uncertainty.jiou(BOX, COV5, BOX, COV5, samples=0)),
    Case("jiou", "cov_b", "(5, 4)", lambda: uncertainty.jiou(BOX, COV5, BOX, COV5[:, :4])),
    Case("label_uncertainty", "sigma", "-1", lambda: uncertainty.label_uncertainty(BOX, np.zeros((12, 2)), sigma=-1.0)),
    Case("label_uncertainty", "points", "(12, 3)", lambda: uncertainty.label_uncertainty(BOX, np.zeros((12, 3)))),
    Case("clearance", "q", "(4,)", lambda: plan.clearance(_scene()[0], np.zeros(4))),
    Case("clearance", "q", "nan", lambda: plan.clearance(_scene()[0], _nan(np.zeros(5)))),
    Case("inverse_dynamics", "q", "(4,)", lambda: plan.inverse_dynamics(np.zeros(4), np.zeros(5), np.zeros(5))),
    Case("inverse_dynamics", "ddq", "inf", lambda: plan.inverse_dynamics(np.zeros(5), np.zeros(5), np.full(5, np.inf))),
    Case("plan_path", "method", "prm", _plan(method="prm")),
    Case("plan_path", "margin", "-1", _plan(margin=-1.0)),
    Case("plan_path", "max_iterations", "-1", _plan(max_iterations=-1)),
    Case("plan_path", "seed", "-1", _plan(seed=-1)),
    Case("plan_path", "step_deg", "0", _plan(step_deg=0.0)),
    Case("plan_path", "joints", "7", _plan(method="a*", joints=[7])),
    Case("plan_path", "q_start", "(4,)", _plan(q_start=np.zeros(4))),
    Case("optimize_trajectory", "path", "0 way-points", _optimize(path=np.zeros((0, 5)))),
    Case("optimize_trajectory", "n_ctrl", "-1", _optimize(n_ctrl=-1)),
    Case("optimize_trajectory", "velocity", "-1", _optimize(limits=plan.Limits(velocity=(-1.0,) * 5))),
    Case("optimize_trajectory", "d_safe", "nan", _optimize(limits=plan.Limits(d_safe=NAN))),
    Case("optimize_waypoints", "paths", "no segment", _waypoints(paths=[])),
    Case("optimize_waypoints", "paths", "str", _waypoints(paths="abc")),
    Case("optimize_waypoints", "paths", "(2, 4)", _waypoints(paths=[np.zeros((2, 4)), np.zeros((2, 5))])),
    Case("optimize_waypoints", "paths", "1.118e-1", _waypoints(gap=True)),
    Case("optimize_waypoints", "max_iterations", "-1", _waypoints(max_iterations=-1)),
    # polygons
    Case("detect_polygon", "template", "(3,)", _polygon(template=np.zeros(3))),
    Case("detect_polygon", "homography", "(2, 2)", _polygon(homography=np.eye(2))),
    Case("detect_polygon", "homography", "nan", _polygon(homography=_nan(np.eye(3)))),
    Case("detect_polygon", "image_or_segments", "None", _polygon(image_or_segments=None)),
    Case("simulate_opening", "width", "-1", lambda: polygon.simulate_opening(3, width=-1)),
    Case("simulate_opening", "n_lines", "-1", lambda: polygon.simulate_opening(3, n_lines=-1)),
    Case("simulate_opening", "blur_sigma", "nan", lambda: polygon.simulate_opening(3, blur_sigma=NAN)),
    # estimation
    Case(
        "unscented_transform",
        "sigmas",
        "(5,)",
        lambda: estimate.unscented_transform(np.zeros(5), np.full(5, 0.2), np.full(5, 0.2)),
    ),
    Case(
        "unscented_transform",
        "Wm",
        "(4,)",
        lambda: estimate.unscented_transform(np.zeros((5, 2)), np.full(4, 0.2), np.full(5, 0.2)),
    ),
    Case(
        "unscented_transform",
        "noise_cov",
        "(3, 3)",
        lambda: estimate.unscented_transform(np.zeros((5, 2)), np.full(5, 0.2), np.full(5, 0.2), np.eye(3)),
    ),
    Case("UnscentedKalmanFilter", "dim_x", "-1", _ukf_kw(dim_x=-1)),
    Case("UnscentedKalmanFilter", "dim_z", "0", _ukf_kw(dim_z=0)),
    Case("UnscentedKalmanFilter", "dt", "nan", _ukf_kw(dt=NAN)),
    Case("UnscentedKalmanFilter", "x", "(3,)", _ukf_set("x", np.zeros(3))),
    Case("UnscentedKalmanFilter", "P", "nan", _ukf_set("P", _nan(np.eye(2)))),
    Case("UnscentedKalmanFilter", "R", "(2, 2)", _ukf_set("R", np.eye(2))),
    Case("UnscentedKalmanFilter", "Q", "complex", _ukf_set("Q", np.eye(2) + 1j)),
    Case("UnscentedKalmanFilter", "z", "(2,)", _ukf_update(np.zeros(2))),
    Case("UnscentedKalmanFilter", "z", "None", _ukf_update([None])),
    Case("UnscentedKalmanFilter", "n", "-1", lambda: MerweScaledSigmaPoints(-1, 0.1, 2.0, 0.0)),
    # 2n + 1 weights of 8 bytes: more than any memory, refused before allocating.
    Case("UnscentedKalmanFilter", "n", "2000000000000001", lambda: MerweScaledSigmaPoints(10**15, 0.1, 2.0, 0.0)),
    Case("LeastSquaresProblem", "T", "(3, 3)", _lsq(lambda p: p.add_pose(np.eye(3)))),
    Case("LeastSquaresProblem", "R", "e199", _lsq(lambda p: p.add_rotation(HUGE_R))),
    Case("LeastSquaresProblem", "block", "99", _lsq(lambda p: p.add_prior(99, np.zeros(6), np.eye(6)))),
    Case("LeastSquaresProblem", "block", "-1", _lsq(lambda p: p.add_prior(-1, np.zeros(6), np.eye(6)))),
    Case("LeastSquaresProblem", "mean", "(5,)", _lsq(lambda p: p.add_prior(0, np.zeros(5), np.eye(6)))),
    Case("LeastSquaresProblem", "covariance", "nan", _lsq(lambda p: p.add_prior(0, np.zeros(6), _nan(np.eye(6))))),
    Case("LeastSquaresProblem", "method", "foo", _lsq(lambda p: p.solve(method="foo"))),
    Case("LeastSquaresProblem", "max_iterations", "-1", _lsq(lambda p: p.solve(max_iterations=-1))),
    Case("bundle_adjust", "K", "(2, 2)", _ba(K=np.eye(2))),
    Case("bundle_adjust", "K", "complex", _ba(K=K + 5j)),
    Case("bundle_adjust", "poses", "(2, 3, 4)", _ba(poses=np.zeros((2, 3, 4)))),
    Case("bundle_adjust", "points", "(6, 2)", _ba(points=np.zeros((6, 2)))),
    Case("bundle_adjust", "observations", "nan", _ba(observations=_nan(np.zeros((12, 2))))),
    Case("bundle_adjust", "pose_index", "5", _ba(pose_index=np.full(12, 5))),
    Case("bundle_adjust", "pose_index", "-1", _ba(pose_index=np.full(12, -1))),
    Case("bundle_adjust", "point_index", "float", _ba(point_index=np.zeros(12) + 0.5)),
    Case("bundle_adjust", "loss", "foo", _ba(loss="foo")),
    Case("bundle_adjust", "fixed_poses", "9", _ba(fixed_poses=[9])),
    Case("bundle_adjust", "max_iterations", "-1", _ba(max_iterations=-1)),
    # point clouds and radio
    Case(
        "segment_colored_cloud",
        "points",
        "(30, 2)",
        lambda: segment.segment_colored_cloud(np.zeros((30, 2)), np.zeros((30, 3)), graph="knn"),
    ),
    Case(
        "segment_colored_cloud",
        "colors",
        "(20, 4)",
        lambda: segment.segment_colored_cloud(P3, np.zeros((20, 4)), graph="knn"),
    ),
    Case(
        "segment_colored_cloud",
        "graph",
        "foo",
        lambda: segment.segment_colored_cloud(P3, np.zeros((20, 3)), graph="foo"),
    ),
    Case(
        "segment_colored_cloud",
        "min_size",
        "-1",
        lambda: segment.segment_colored_cloud(P3, np.zeros((20, 3)), graph="knn", min_size=-1),
    ),
    Case(
        "segment_colored_cloud",
        "k",
        "0",
        lambda: segment.segment_colored_cloud(P3, np.zeros((20, 3)), graph="knn", k=0),
    ),
    Case("segment_colored_cloud", "scene", "cave", lambda: segment.simulate_scan("cave")),
    Case("segment_colored_cloud", "beam_step_deg", "0", lambda: segment.simulate_scan(beam_step_deg=0.0)),
    Case("radio fit/predict", "tx", "(10, 3)", _radio(radio.LogFit, tx=np.zeros((10, 3)))),
    Case("radio fit/predict", "rss", "(9,)", _radio(radio.LogFit, rss=np.zeros(9))),
    Case("radio fit/predict", "rx", "nan", _radio(radio.MRGP, rx=_nan(np.zeros((10, 2))))),
    Case("radio fit/predict", "environment", "moon", lambda: radio.simulate("moon")),
    Case("radio fit/predict", "robots", "-1", lambda: radio.simulate(robots=-1)),
    Case("radio fit/predict", "rate", "0", lambda: radio.simulate(rate=0.0, duration=1.0)),
    # calibration
    Case("calibrate", "model", "foo", _calibrate(model="foo")),
    Case("calibrate", "image_size", "-1", _calibrate(image_size=(-1, 480))),
    Case("calibrate", "sigma_z", "-1", _calibrate(sigma_z=-1.0)),
    Case("calibrate", "loss", "l1", _calibrate(loss="l1")),
    Case("calibrate", "max_iterations", "-1", _calibrate(max_iterations=-1)),
    Case("calibrate", "image_points", "(22, 2)", _calibrate(object_points=[np.zeros((2, 3))] * 4)),
    # NaN rows are missing points by design; infinity is refused.
    Case(
        "calibrate",
        "image_points",
        "inf",
        lambda: _calibrate(image_points=[i + np.inf for i in calibration_views()[1]])(),
    ),
    Case("calibrate", "params", "length 3", _view(params=np.zeros(3))),
    Case("calibrate", "pose", "(3, 4)", _view(pose=np.zeros((3, 4)))),
    Case("calibrate", "sigma", "-1", _view(sigma=-1.0)),
    Case("calibrate", "seed", "-1", _view(seed=-1)),
    # logs and simulation
    Case("write_log", "compression", "gzip", _write_log(compression="gzip")),
    Case("write_log", "joints_encoder", "(2, 4)", _write_log(joints_encoder=np.zeros((2, 4)))),
    Case("write_log", "frame_rate_hz", "nan", _write_log(frame_rate_hz=NAN)),
    Case("write_log", "path", "/dev/null", _write_log(tmp="/dev/null")),
    Case("simulate_session", "frames", "-1", _sim(frames=-1)),
    Case("simulate_session", "seed", "-1", _sim(seed=-1)),
    Case("simulate_session", "width", "-1", _sim(width=-1)),
    Case("simulate_session", "camera_params", "(60.0, 60.0, 39.5)", _sim(camera_params=(60.0, 60.0, 39.5))),
    Case("simulate_session", "frame_rate_hz", "0", _sim(frame_rate_hz=0.0)),
]


def _case(c: Any) -> Case:
    return c.values[0] if hasattr(c, "values") else c


@pytest.mark.parametrize("case", CASES, ids=[f"{_case(c).entry}-{_case(c).arg}-{_case(c).shows}" for c in CASES])
def test_the_error_names_the_argument_the_value_and_the_expectation(case: Case) -> None:
    says(case.call, case.arg, case.shows)


#: Entry points of the property suites beyond ``test_properties.ENTRY_POINTS`` (part two).
HEAVY = {
    "calibrate",
    "detect_polygon",
    "plan_path",
    "optimize_trajectory",
    "write_log",
    "simulate_session",
    "simulate_opening",
}


def test_every_property_entry_point_is_audited() -> None:
    missing = (set(test_properties.ENTRY_POINTS) | HEAVY) - {_case(c).entry for c in CASES}
    assert not missing, f"entry points of the property suites without a message case: {sorted(missing)}"


# -- the property suites' own hostile examples ---------------------------------------------------

#: Examples per entry point: the property suite runs 200 of each; the message check needs fewer.
MESSAGE_EXAMPLES = 25


@pytest.mark.parametrize("name", sorted(test_properties.ENTRY_POINTS))
def test_hostile_examples_of_the_property_suite_say_what_was_expected(name: str) -> None:
    """Every InvalidInputError the property suite's strategies provoke states an expectation, briefly.

    The suite's examples do not say which argument they spoiled, so the name and value are checked
    by the table above; here every message must state what was expected and print no huge number.
    """
    seen: list[str] = []

    def holds(call: Callable[[], Any], *, finite: bool = True) -> None:
        try:
            call()
        except InvalidInputError as e:
            msg = str(e)
            seen.append(msg)
            assert EXPECTATION.search(msg), f"states no expectation: {msg!r}"
            assert not [t for t in re.findall(r"\d+", msg) if len(t) > LONGEST_TOKEN], f"huge number: {msg!r}"
        except AutoteachError:
            pass

    @settings(max_examples=MESSAGE_EXAMPLES, deadline=None, derandomize=True, database=None)
    @given(data=st.data())
    def check(data: Any) -> None:
        test_properties.ENTRY_POINTS[name](data)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(test_properties, "holds", holds)
        check()
    assert seen, f"no example of {name} raised InvalidInputError: the check saw nothing"


# -- the command line ----------------------------------------------------------------------------

#: One bad input per sub-command (two where a command takes a file and options): the argument
#: vector and the words the error line must hold (the option or file, and the offending value).
CLI_CASES: list[tuple[list[str], list[str]]] = [
    (["simulate", "--frames", "-1", "--out", "x.mcap"], ["--frames", "'-1'"]),
    (["simulate", "--frames", "9" * 300, "--out", "x.mcap"], ["--frames", "300-character"]),
    (["simulate", "--compression", "gzip", "--out", "x.mcap"], ["--compression", "gzip"]),
    (["demo", "--seed", "-1"], ["--seed", "'-1'"]),
    (["demo", "--frames", "0"], ["--frames", "'0'"]),
    (["info", "missing.mcap"], ["missing.mcap"]),
    (["run", "missing.mcap"], ["missing.mcap"]),
    (["run", "missing.mcap", "--workers", "-1"], ["--workers", "-1"]),
    (["calibrate", "views.npz"], ["views.npz"]),
    (["calibrate", "--simulate", "--seed", "-1"], ["--seed", "'-1'"]),
    (["calibrate", "--simulate", "--model", "foo"], ["--model", "foo"]),
    (["active", "--trials", "0"], ["--trials", "'0'"]),
    (["scenes", "--family", "dark_face", "--out", "d", "--count", "-1"], ["--count", "-1"]),
    (["scenes", "--family", "foo"], ["--family", "foo"]),
    (["map", "--simulate", "--slice-size", "-1"], ["--slice-size", "-1"]),
    (["map", "--simulate", "--resolution", "nan"], ["--resolution", "nan"]),
    (["radio", "--simulate", "--duration", "-1"], ["--duration", "-1"]),
    (["radio", "--simulate", "--sigma", "nan"], ["--sigma", "nan"]),
    (["segment", "missing.ply"], ["missing.ply"]),
    (["segment", "--simulate", "--scene", "cave"], ["--scene", "cave"]),
    (["tune", "--demo", "--noise", "-1"], ["--noise", "-1"]),
    (["uncertainty", "--out", "x"], ["--demo"]),
    (["plan", "--plot", "x.png"], ["--demo"]),
    (["tune", "--plot", "x.png"], ["--demo"]),
]


@pytest.mark.parametrize("argv,words", CLI_CASES, ids=[" ".join(a)[:40] for a, _ in CLI_CASES])
def test_the_command_line_names_the_option_and_the_value(
    argv: list[str], words: list[str], tmp_path: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    from autoteach.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "views.npz").write_text("not an archive")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main(argv)
        except SystemExit as exc:  # argparse: the usage, then one error line
            status = exc.code
    text = err.getvalue()
    assert status == 2 and "Traceback" not in text, f"{argv} exited with {status}: {text}"
    lines = text.strip().splitlines()
    if "usage:" not in text:
        assert len(lines) == 1, f"{argv}: {text}"
    last = lines[-1]
    assert last.startswith("autoteach") and "error:" in last, f"{argv}: {text}"
    assert not [w for w in words if w not in last], f"{argv}: {last!r} misses {words}"
    assert not [t for t in re.findall(r"\d+", last) if len(t) > LONGEST_TOKEN], f"{argv}: {last!r}"
