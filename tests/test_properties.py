"""Property suite over the public API (issue 38): hostile input never hangs, panics or lies.

For every entry point below, Hypothesis draws arguments of the nominal shape with extreme
values (NaN, ±inf, ±1e300, 1e-300, subnormals, zero), wrong shapes (a dimension off by one,
empty, an extra axis), wrong dtypes (complex, bool, object, strings), other layouts (Fortran
order, strided views, read-only) and hostile integers (negative, zero, 2**62). The property:

- the call returns, and every floating-point number in the result is finite; or
- it raises an :class:`~autoteach.errors.AutoteachError` subclass (never a bare ``TypeError``,
  ``OverflowError``, NumPy error, or ``InternalError``, which is a caught Rust panic).

A hang ends the test process through ``faulthandler`` (with every thread's traceback) rather
than blocking CI. Examples are derandomised, so a run is reproducible; each entry point gets
``EXAMPLES`` examples (``AUTOTEACH_PROPERTY_EXAMPLES`` overrides it).
"""

from __future__ import annotations

import atexit
import dataclasses
import faulthandler
import math
import os
import tempfile
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from autoteach import detect, estimate, fusion, geometry, plan, polygon, radio, registration, segment, uncertainty
from autoteach.errors import AutoteachError, InternalError
from autoteach.sigma_points import MerweScaledSigmaPoints

EXAMPLES = int(os.environ.get("AUTOTEACH_PROPERTY_EXAMPLES", "200"))
HANG_SECONDS = 120
#: Where the watchdog writes the stacks before it ends the run: pytest's capture of fd 2 would
#: swallow them (the run then stops with status 1 and no summary).
HANG_LOG = os.path.join(tempfile.gettempdir(), "autoteach-property-hang.txt")

SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)

# -- strategies ------------------------------------------------------------------------------

EXTREMES = [0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300, 1e155, 1e40, 2.0**62]
NONFINITE = [math.nan, math.inf, -math.inf]
HOSTILE_INTS = [-(2**63), -(10**300), -1, 0, 1, 2, 3, 2**31, 2**62, 2**64]

finite_floats = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
hostile_floats = st.one_of(
    finite_floats,
    st.sampled_from(EXTREMES),
    st.sampled_from(NONFINITE),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
)


def _fill(draw: Any, shape: tuple[int, ...], elements: st.SearchStrategy[float]) -> np.ndarray:
    """An array of `shape`: a finite random base with up to three drawn elements replaced."""
    size = int(np.prod(shape)) if shape else 1
    seed = draw(st.integers(0, 2**32 - 1))
    scale = draw(st.sampled_from([1.0, 1.0, 1.0, 1e-300, 1e-8, 1e8, 1e155, 1e300]))
    base = np.random.default_rng(seed).normal(size=size) * scale
    for _ in range(draw(st.integers(0, 3)) if size else 0):
        base[draw(st.integers(0, size - 1))] = draw(elements)
    return base.reshape(shape)


@st.composite
def arrays(draw: Any, shape: tuple[int, ...], valid: st.SearchStrategy[Any] | None = None) -> Any:
    """Input for an array argument of nominal `shape` (see the module docstring)."""
    kind = draw(
        st.sampled_from(
            ["valid", "valid", "values", "values", "values", "shape", "dtype", "layout"]
            if valid is not None
            else ["values", "values", "values", "shape", "dtype", "layout"]
        )
    )
    if kind == "valid":
        return draw(valid)
    if kind == "values":
        return _fill(draw, shape, hostile_floats)
    if kind == "shape":
        s = list(shape)
        how = draw(st.sampled_from(["off", "empty", "extra", "drop", "scalar"]))
        if how == "off" and s:
            i = draw(st.integers(0, len(s) - 1))
            s[i] = max(0, s[i] + draw(st.sampled_from([-1, 1])))
        elif how == "empty" and s:
            s[draw(st.integers(0, len(s) - 1))] = 0
        elif how == "extra":
            s = [*s, draw(st.integers(1, 3))]
        elif how == "drop" and s:
            s = s[1:]
        elif how == "scalar":
            return draw(finite_floats)
        return _fill(draw, tuple(s), finite_floats)
    if kind == "dtype":
        base = _fill(draw, shape, finite_floats)
        dtype = draw(st.sampled_from(["complex", "bool", "object", "str", "float32", "int64", "uint8", "list"]))
        if dtype == "complex":
            return base + 1j
        if dtype == "object":
            return base.astype(object)
        if dtype == "str":
            return base.astype(str)
        if dtype == "list":
            return base.tolist()
        with np.errstate(all="ignore"):
            return base.astype(dtype)
    base = _fill(draw, shape, finite_floats)
    layout = draw(st.sampled_from(["fortran", "strided", "readonly"]))
    if layout == "fortran":
        return np.asfortranarray(base)
    if layout == "strided":
        big = np.repeat(base[..., None], 2, axis=-1)
        return big[..., 0]
    base.setflags(write=False)
    return base


def rotations() -> st.SearchStrategy[np.ndarray]:
    return st.builds(lambda w: geometry.so3_exp(np.array(w)), st.lists(finite_floats, min_size=3, max_size=3))


def poses() -> st.SearchStrategy[np.ndarray]:
    def pose(w: list[float], t: list[float]) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = geometry.so3_exp(np.array(w))
        T[:3, 3] = t
        return T

    lst = st.lists(finite_floats, min_size=3, max_size=3)
    return st.builds(pose, lst, lst)


def point_sets(d: int, lo: int = 3, hi: int = 25) -> st.SearchStrategy[np.ndarray]:
    return st.builds(
        lambda n, seed: np.random.default_rng(seed).normal(size=(n, d)), st.integers(lo, hi), st.integers(0, 999)
    )


def ints(lo: int = 0, hi: int = 10) -> st.SearchStrategy[int]:
    return st.one_of(st.integers(lo, hi), st.sampled_from(HOSTILE_INTS))


def scalars() -> st.SearchStrategy[float]:
    return st.one_of(finite_floats, finite_floats, hostile_floats)


# -- the property ----------------------------------------------------------------------------


def _nonfinite(value: Any, path: str = "result") -> str | None:
    """The path of the first non-finite float in `value`, or None."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "fc" and not np.all(np.isfinite(value)):
            return path
        if value.dtype == object:
            for i, v in enumerate(value.ravel()):
                bad = _nonfinite(v, f"{path}[{i}]")
                if bad:
                    return bad
        return None
    if isinstance(value, (float, np.floating)):
        return None if math.isfinite(value) else path
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            bad = _nonfinite(v, f"{path}[{i}]")
            if bad:
                return bad
        return None
    if isinstance(value, dict):
        for k, v in value.items():
            bad = _nonfinite(v, f"{path}[{k!r}]")
            if bad:
                return bad
        return None
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            bad = _nonfinite(getattr(value, f.name), f"{path}.{f.name}")
            if bad:
                return bad
    return None


def _arm_watchdog() -> None:
    """(Re)start the hang watchdog: HANG_SECONDS from now, dump every thread's stack to HANG_LOG and exit."""
    global _hang_file
    if _hang_file is None:
        _hang_file = open(HANG_LOG, "w")  # noqa: SIM115 - kept open for the watchdog thread
        atexit.register(_hang_file.close)
    faulthandler.dump_traceback_later(HANG_SECONDS, exit=True, file=_hang_file)


_hang_file: Any = None


def holds(call: Callable[[], Any], *, finite: bool = True) -> None:
    """The property: a finite result, or an AutoteachError that is not a caught panic.

    Each call gets its own HANG_SECONDS (the watchdog is re-armed here): a property test of 200
    examples may take longer than that in all without any one example hanging.
    """
    _arm_watchdog()
    try:
        out = call()
    except InternalError as e:  # a Rust panic caught at the boundary
        raise AssertionError(f"panic: {e}") from e
    except AutoteachError:
        return
    if finite:
        bad = _nonfinite(out)
        assert bad is None, f"non-finite {bad} in a result returned without an error"


@pytest.fixture(autouse=True)
def _no_hang():
    _arm_watchdog()
    yield
    faulthandler.cancel_dump_traceback_later()


# -- entry points ----------------------------------------------------------------------------


def _ellipse_sample(d: Any) -> None:
    cx, cy, a, b, th = (d.draw(scalars()) for _ in range(5))
    n = d.draw(ints(0, 50))

    def call() -> Any:
        return geometry.Ellipse(cx, cy, a, b, th).sample(n)

    holds(call)


def _K() -> st.SearchStrategy[np.ndarray]:
    return st.just(np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]))


def _camera_pose() -> st.SearchStrategy[np.ndarray]:
    def pose(w: list[float]) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = geometry.so3_exp(np.array(w) * 0.1)
        T[:3, 3] = [0.0, 0.0, 1.0]
        return T

    return st.builds(pose, st.lists(finite_floats, min_size=3, max_size=3))


def _ukf_step(d: Any) -> None:
    pts = MerweScaledSigmaPoints(2, 0.1, 2.0, 0.0)
    u = estimate.UnscentedKalmanFilter(dim_x=2, dim_z=1, dt=0.1, fx=lambda x, dt: x, hx=lambda x: x[:1], points=pts)
    what = d.draw(st.sampled_from(["x", "P", "Q", "R", "z"]))
    shapes = {"x": (2,), "P": (2, 2), "Q": (2, 2), "R": (1, 1), "z": (1,)}
    value = d.draw(arrays(shapes[what]))

    def call() -> Any:
        if what == "z":
            u.predict()
            u.update(value)
        else:
            setattr(u, what, value)
            u.predict()
            u.update(np.array([0.5]))
        return u.x, u.P

    holds(call)


def _lsq(d: Any) -> None:
    what = d.draw(st.sampled_from(["pose", "rotation", "prior"]))

    def call() -> Any:
        p = estimate.LeastSquaresProblem()
        if what == "pose":
            b = p.add_pose(d.draw(arrays((4, 4), poses())))
        elif what == "rotation":
            b = p.add_rotation(d.draw(arrays((3, 3), rotations())))
        else:
            b = p.add_pose(np.eye(4))
            p.add_prior(d.draw(ints(0, 2)), d.draw(arrays((6,))), d.draw(arrays((6, 6), st.just(np.eye(6)))))
        p.solve(max_iterations=5)
        return p.values(b)

    holds(call)


def _bundle_adjust(d: Any) -> None:
    rng = np.random.default_rng(d.draw(st.integers(0, 99)))
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    poses_ = np.stack([np.eye(4)] * 2)
    poses_[1, :3, 3] = [0.2, 0.0, 0.0]
    pts = rng.normal(size=(6, 3)) * 0.3 + [0, 0, 3]
    pi = np.repeat([0, 1], 6)
    qi = np.tile(np.arange(6), 2)
    obs = np.array(
        [
            (K @ (p[:3, :3].T @ (x - p[:3, 3])))[:2] / (p[:3, :3].T @ (x - p[:3, 3]))[2]
            for p, x in zip(poses_[pi], pts[qi], strict=True)
        ]
    )
    args: dict[str, Any] = {
        "K": K,
        "poses": poses_,
        "points": pts,
        "observations": obs,
        "pose_index": pi,
        "point_index": qi,
    }
    name = d.draw(st.sampled_from([*args, "max_iterations"]))
    if name == "max_iterations":
        kw = {"max_iterations": d.draw(ints(0, 20))}
    else:
        args[name] = d.draw(arrays(np.shape(args[name])))
        kw = {"max_iterations": 20}
    holds(lambda: estimate.bundle_adjust(**args, fixed_poses=[0], **kw))


def _segment(d: Any) -> None:
    n = d.draw(st.integers(0, 60))
    pts = d.draw(arrays((n, 3), point_sets(3, n, n) if n else None))
    cols = d.draw(arrays((n, 3), st.just(np.full((n, 3), 0.5))))
    holds(
        lambda: segment.segment_colored_cloud(pts, cols, graph="knn", min_size=d.draw(ints(0, 5)), k=d.draw(ints(1, 8)))
    )


def _radio_fit(d: Any) -> None:
    n = d.draw(st.integers(0, 30))
    tx = d.draw(arrays((n, 2), point_sets(2, n, n) if n else None))
    rx = d.draw(
        arrays((n, 2), st.builds(lambda s: np.random.default_rng(s).normal(size=(n, 2)) + 5.0, st.integers(0, 9)))
    )
    rss = d.draw(arrays((n,), st.just(-60.0 - np.arange(n, dtype=float))))
    model = d.draw(st.sampled_from(["log", "mrgp"]))

    def call() -> Any:
        m = radio.LogFit() if model == "log" else radio.MRGP()
        m.fit(tx, rx, rss)
        return m.predict(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0]]))

    holds(call)


def _jiou(d: Any) -> None:
    box = st.just(np.array([0.0, 0.0, 4.0, 2.0, 0.3]))
    cov = st.just(np.eye(5) * 0.01)
    a, b = d.draw(arrays((5,), box)), d.draw(arrays((5,), box))
    ca, cb = d.draw(arrays((5, 5), cov)), d.draw(arrays((5, 5), cov))
    holds(lambda: uncertainty.jiou(a, ca, b, cb, grid=d.draw(ints(2, 30)), samples=d.draw(ints(1, 64))))


def _robot(d: Any) -> None:
    what = d.draw(st.sampled_from(["ik", "base", "encoders"]))
    if what == "ik":
        robot = geometry.WaferRobot()
        T = robot.blade_pose(np.array([0.3, 0.4, -0.2, 0.1, 0.2]))
        holds(lambda: robot.inverse_kinematics(d.draw(arrays((4, 4), st.just(T))), blade=d.draw(ints(1, 2))))
    elif what == "base":
        holds(lambda: geometry.WaferRobot(base=d.draw(arrays((4, 4), poses()))).blade_pose(np.zeros(5)))
    else:
        holds(lambda: geometry.joints_from_encoders(d.draw(arrays((5,))), d.draw(arrays((5,)))))


def _camera(d: Any) -> None:
    model = d.draw(st.sampled_from(["pinhole", "brown_conrady", "kannala_brandt"]))
    n = {"pinhole": 4, "brown_conrady": 9, "kannala_brandt": 8}[model]
    nominal = np.r_[500.0, 500.0, 320.0, 240.0, np.zeros(n - 4)]

    def call() -> Any:
        cam = geometry.Camera(model, d.draw(arrays((n,), st.just(nominal))), d.draw(ints(1, 640)), 480)
        return cam.project(d.draw(arrays((7, 3), st.just(np.c_[np.zeros((7, 2)), np.linspace(1, 3, 7)]))))

    holds(call)


def _image(d: Any, h: int, w: int) -> Any:
    smooth = st.builds(
        lambda s: np.clip(
            128 + 60 * np.cos(np.hypot(*np.mgrid[0:h, 0:w] - [[[h / 2]], [[w / 2]]]) / (3 + s)), 0, 255
        ).astype(np.uint8),
        st.integers(0, 5),
    )
    return d.draw(arrays((h, w), smooth))


def _mapping(d: Any) -> None:
    from autoteach import mapping

    n = d.draw(st.integers(0, 3))
    ranges = np.full((n, 31), 5.0)
    args = {
        "node_ids": np.arange(n),
        "robot_ids": np.zeros(n, dtype=np.int64),
        "poses": np.c_[np.arange(n, dtype=float), np.zeros(n), np.zeros(n)],
        "scans": ranges,
    }
    name = d.draw(st.sampled_from(list(args)))
    args[name] = d.draw(arrays(np.shape(args[name])))
    r = mapping.Rasterizer(slice_size=2, resolution=0.5, beams=31, max_range=10.0)
    holds(lambda: r.update(**args))


def _pooling(d: Any) -> None:
    P = np.array([[600.0, -700.0, 0.0, 0.0], [180.0, 0.0, -700.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    pts = st.builds(
        lambda s: np.random.default_rng(s).uniform([1, -20, -1], [40, 20, 1], size=(50, 3)), st.integers(0, 9)
    )

    def call() -> Any:
        rows = d.draw(ints(1, 23))
        op = fusion.SparsePooling.build(
            d.draw(arrays((50, 3), pts)),
            d.draw(arrays((3, 4), st.just(P))),
            (rows, 78, 16.0),
            (0.0, -30.0, d.draw(st.one_of(st.just(1.0), scalars())), 60, d.draw(ints(1, 60))),
            neighbourhood=d.draw(ints(1, 3)),
        )
        shape = (rows if isinstance(rows, int) and 0 < rows < 100 else 1, 78, 2)
        return op.forward(d.draw(arrays(shape, st.just(np.ones(shape)))))

    holds(call)


def _tracker(d: Any) -> None:
    from autoteach import track

    t = np.linspace(0.2, 2.8, 30)
    good = np.c_[300 + 200 * np.cos(t), 200 + 40 * np.sin(t)]

    def call() -> Any:
        tracker = track.WaferTracker()
        e = geometry.Ellipse(300.0, 200.0, 200.0, 40.0, 0.0)
        edges = [track.Edge(e, d.draw(arrays((30, 2), st.just(good))))]
        tracker.update(edges)
        return [tr.id for tr in tracker.update(edges, camera_pose=d.draw(arrays((4, 4), poses())))]

    holds(call)


def _control(d: Any) -> None:
    from autoteach import control

    def call() -> Any:
        plant = control.TransferFunction(
            d.draw(arrays((1,), st.just(np.array([100.0])))), d.draw(arrays((3,), st.just(np.array([1.0, 2.0, 0.0]))))
        )
        return control.bandwidth(plant)

    holds(call, finite=False)  # a bandwidth or margin may be infinite by definition


ENTRY_POINTS: dict[str, Callable[[Any], None]] = {
    "WaferRobot": _robot,
    "Camera.project": _camera,
    "detect_wafers": lambda d: holds(lambda: detect.detect_wafers(_image(d, 48, 64))),
    "detect_ellipses": lambda d: holds(lambda: detect.detect_ellipses(_image(d, 48, 64))),
    "assign_with_unassigned": lambda d: holds(
        lambda: detect.assign_with_unassigned(d.draw(arrays((3, 4))), d.draw(arrays((3,))), d.draw(arrays((4,))))
    ),
    "global_cpd": lambda d: holds(
        lambda: registration.global_cpd(
            d.draw(arrays((30, 2), point_sets(2, 30, 30))),
            d.draw(arrays((20, 2), point_sets(2, 20, 20))),
            k=d.draw(ints(1, 3)),
            max_iterations=10,
        )
    ),
    "Rasterizer.update": _mapping,
    "SparsePooling": _pooling,
    "WaferTracker": _tracker,
    "TransferFunction": _control,
    "spatial_distribution": lambda d: holds(
        lambda: uncertainty.spatial_distribution(
            d.draw(arrays((5,), st.just(np.array([0.0, 0.0, 4.0, 2.0, 0.3])))),
            d.draw(arrays((5, 5), st.just(np.eye(5) * 0.01))),
            points=d.draw(arrays((9, 2), st.just(np.zeros((9, 2))))),
            lattice=d.draw(ints(2, 20)),
        )
    ),
    "clearance": lambda d: holds(lambda: plan.clearance(plan.default_scene()[0], d.draw(arrays((5,)))), finite=False),
    "so3_exp": lambda d: holds(lambda: geometry.so3_exp(d.draw(arrays((3,))))),
    "so3_log": lambda d: holds(lambda: geometry.so3_log(d.draw(arrays((3, 3), rotations())))),
    "se3_exp": lambda d: holds(lambda: geometry.se3_exp(d.draw(arrays((6,))))),
    "se3_log": lambda d: holds(lambda: geometry.se3_log(d.draw(arrays((4, 4), poses())))),
    "se3_plus": lambda d: holds(lambda: geometry.se3_plus(d.draw(arrays((4, 4), poses())), d.draw(arrays((6,))))),
    "se3_minus": lambda d: holds(
        lambda: geometry.se3_minus(d.draw(arrays((4, 4), poses())), d.draw(arrays((4, 4), poses())))
    ),
    "matrix_to_quat": lambda d: holds(lambda: geometry.matrix_to_quat(d.draw(arrays((3, 3), rotations())))),
    "quat_to_matrix": lambda d: holds(lambda: geometry.quat_to_matrix(d.draw(arrays((4,))))),
    "matrix_to_euler_zyx": lambda d: holds(lambda: geometry.matrix_to_euler_zyx(d.draw(arrays((3, 3), rotations())))),
    "euler_zyx_to_matrix": lambda d: holds(lambda: geometry.euler_zyx_to_matrix(d.draw(arrays((3,))))),
    "Ellipse.from_conic": lambda d: holds(
        lambda: geometry.Ellipse.from_conic(d.draw(arrays((3, 3), st.just(np.diag([1.0, 4.0, -1.0])))))
    ),
    "Ellipse.sample": _ellipse_sample,
    "project_circle": lambda d: holds(
        lambda: geometry.project_circle(
            d.draw(arrays((3, 3), _K())),
            d.draw(arrays((4, 4), _camera_pose())),
            d.draw(arrays((3,), st.just(np.zeros(3)))),
            d.draw(arrays((3,), st.just(np.array([0.0, 0.0, 1.0])))),
            d.draw(scalars()),
        )
    ),
    "circle_image_conic": lambda d: holds(
        lambda: geometry.circle_image_conic(d.draw(arrays((3, 3), _K())), d.draw(arrays((4, 4), _camera_pose())), 0.15)
    ),
    "fit_ellipse": lambda d: holds(
        lambda: detect.fit_ellipse(
            d.draw(
                arrays(
                    (20, 2),
                    st.builds(
                        lambda s: np.c_[3 * np.cos(np.linspace(0, s, 20)), np.sin(np.linspace(0, s, 20))],
                        st.floats(0.5, 6.2),
                    ),
                )
            ),
            method=d.draw(st.sampled_from(["geometric", "direct", "ams"])),
        )
    ),
    "linear_sum_assignment": lambda d: holds(
        lambda: detect.linear_sum_assignment(d.draw(arrays((d.draw(st.integers(0, 6)), d.draw(st.integers(0, 6))))))
    ),
    "global_voting": lambda d: holds(
        lambda: polygon.global_voting(
            d.draw(arrays((20, 2), point_sets(2))), d.draw(arrays((15, 2), point_sets(2))), k=d.draw(ints(0, 4))
        )
    ),
    "cpd_rigid": lambda d: holds(
        lambda: registration.cpd_rigid(d.draw(arrays((20, 2), point_sets(2))), d.draw(arrays((15, 2), point_sets(2))))
    ),
    "cpd_affine": lambda d: holds(
        lambda: registration.cpd_affine(d.draw(arrays((20, 3), point_sets(3))), d.draw(arrays((15, 3), point_sets(3))))
    ),
    "cpd_nonrigid": lambda d: holds(
        lambda: registration.cpd_nonrigid(
            d.draw(arrays((20, 2), point_sets(2))), d.draw(arrays((15, 2), point_sets(2))), max_iterations=20
        )
    ),
    "unscented_transform": lambda d: holds(
        lambda: estimate.unscented_transform(
            d.draw(arrays((5, 2), point_sets(2, 5, 5))),
            d.draw(arrays((5,), st.just(np.full(5, 0.2)))),
            d.draw(arrays((5,), st.just(np.full(5, 0.2)))),
            d.draw(arrays((2, 2), st.just(np.eye(2)))),
        )
    ),
    "UnscentedKalmanFilter": _ukf_step,
    "LeastSquaresProblem": _lsq,
    "bundle_adjust": _bundle_adjust,
    "iou": lambda d: holds(
        lambda: uncertainty.iou(
            d.draw(arrays((5,), st.just(np.array([0.0, 0.0, 4.0, 2.0, 0.3])))),
            d.draw(arrays((5,), st.just(np.array([1.0, 0.5, 4.0, 2.0, -0.2])))),
        )
    ),
    "jiou": _jiou,
    "label_uncertainty": lambda d: holds(
        lambda: uncertainty.label_uncertainty(
            d.draw(arrays((5,), st.just(np.array([0.0, 0.0, 4.0, 2.0, 0.0])))),
            d.draw(arrays((12, 2), st.just(np.c_[np.linspace(-2, 2, 12), np.full(12, -1.0)]))),
            sigma=d.draw(st.one_of(st.just(0.2), scalars())),
        )
    ),
    "maxmin_pool": lambda d: holds(lambda: fusion.maxmin_pool(d.draw(arrays((4, 5, 3))))),
    "segment_colored_cloud": _segment,
    "radio fit/predict": _radio_fit,
    "inverse_dynamics": lambda d: holds(
        lambda: plan.inverse_dynamics(d.draw(arrays((5,))), d.draw(arrays((5,))), d.draw(arrays((5,))))
    ),
}


@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
@SETTINGS
@given(data=st.data())
def test_hostile_input_gives_a_finite_result_or_an_autoteach_error(name: str, data: Any) -> None:
    ENTRY_POINTS[name](data)


# -- logs: a bounded fuzz loop over the MCAP reader and the message decoders ------------------


@pytest.fixture(scope="module")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[bytes, Any]:
    from autoteach.io import write_log
    from autoteach.sim import SimConfig, simulate_session

    cfg = SimConfig(camera_params=(120.0, 120.0, 79.5, 44.5), width=160, height=90, supersample=1)
    session = simulate_session(seed=2, frames=3, config=cfg)
    path = write_log(session, tmp_path_factory.mktemp("fuzz") / "small.mcap")
    return path.read_bytes(), session


@st.composite
def damaged(draw: Any, data: bytes) -> bytes:
    """`data` with byte flips, a cut, an insertion or a zeroed span."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        how = draw(st.sampled_from(["flip", "flip", "cut", "insert", "zero"]))
        pos = draw(st.integers(0, max(len(out) - 1, 0)))
        if how == "flip" and out:
            out[pos] ^= draw(st.integers(1, 255))
        elif how == "cut":
            del out[pos:]
        elif how == "insert":
            out[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        elif how == "zero":
            span = draw(st.integers(1, 64))
            out[pos : pos + span] = bytes(len(out[pos : pos + span]))
    return bytes(out)


def test_damaged_logs_raise_log_read_error_or_salvage_a_prefix(small_log: tuple[bytes, Any], tmp_path: Any) -> None:
    """Strict reads raise LogReadError; salvage returns whole frames equal to the original's."""
    from autoteach.errors import LogReadError, LogSalvageWarning
    from autoteach.io import read_log

    data, session = small_log
    path = tmp_path / "damaged.mcap"

    @SETTINGS
    @given(blob=damaged(data))
    def check(blob: bytes) -> None:
        path.write_bytes(blob)
        try:
            read_log(path)
        except LogReadError:
            pass
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LogSalvageWarning)
                part = read_log(path, allow_truncated=True)
        except LogReadError:
            return
        # A salvaged read says what it lost: the frames it returns and those it reports lost
        # account for every frame the log announced.
        if part.damage is not None and part.damage.frames_lost is not None:
            assert part.n_frames + len(part.damage.frames_lost) == part.damage.frames_expected
        k = part.n_frames
        assert k <= session.n_frames
        # A damaged image or joint message is refused or dropped, never altered: whatever frames
        # are returned match the original frames at the same timestamps bit for bit.
        index = {int(t): i for i, t in enumerate(session.timestamps)}
        for j in range(k):
            i = index.get(int(part.timestamps[j]))
            assert i is not None, "a salvaged frame has a timestamp the log never had"
            assert part.images[j].tobytes() == session.images[i].tobytes()
            assert part.joints_encoder[j].tobytes() == session.joints_encoder[i].tobytes()

    check()
