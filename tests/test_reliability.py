"""Reliability regressions of issue 38: no hang, panic, abort or silent wrong answer.

Each test reproduces one defect of the hostile sweep and checks the documented behaviour
against an independent truth (a scaled answer, the same call on one thread, a closed form).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest

import autoteach
from autoteach import calib, estimate, geometry, polygon, registration
from autoteach.errors import AllocationError, AutoteachError, InvalidInputError
from autoteach.sigma_points import MerweScaledSigmaPoints

PYTHON_DIR = str(Path(autoteach.__file__).resolve().parent.parent)


def _chevron(n: int = 120) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    arm1 = np.c_[2.0 * t, 1.0 * t]
    arm2 = np.c_[2.0 + 1.2 * t, 1.0 - 1.4 * t]
    hook = np.c_[3.2 - 0.5 * t[: n // 3], -0.4 - 0.5 * t[: n // 3]]
    return np.vstack([arm1, arm2, hook])


class TestUnits:
    def test_global_voting_is_invariant_to_the_unit(self):
        # Regression: coordinates ~1e40 overflowed the f32 vote bins (an index-out-of-bounds
        # panic) and ~1e155 overflowed squared distances (NaN rotations).
        y = _chevron()
        c, s = np.cos(0.7), np.sin(0.7)
        x = y @ np.array([[c, s], [-s, c]]) + [3.0, -1.0]
        base = polygon.global_voting(x, y)
        for unit in (1e-150, 1e40, 1e155, 1e300):
            h = polygon.global_voting(x * unit, y * unit)
            assert len(h) == len(base)
            np.testing.assert_allclose(h[0].rotation, base[0].rotation, atol=1e-9)
            np.testing.assert_allclose(h[0].translation / unit, base[0].translation, atol=1e-6)
            assert np.all(np.isfinite(h[0].rotation))


_MEMORY_LIMITED = """
import resource, sys
sys.path.insert(0, {path!r})
import autoteach  # the module maps itself before the limit
resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
from autoteach import geometry
from autoteach.sigma_points import MerweScaledSigmaPoints, JulierSigmaPoints, SimplexSigmaPoints
from autoteach.errors import AllocationError
calls = {{
    "sample": lambda: geometry.Ellipse(0, 0, 2, 1, 0).sample(300_000_000),
    "merwe": lambda: MerweScaledSigmaPoints(10**9, 0.1, 2.0, 0.0),
    "julier": lambda: JulierSigmaPoints(10**9, 0.0),
    "simplex": lambda: SimplexSigmaPoints(100_000),
}}
for name, call in calls.items():
    try:
        call()
        print(name, "returned")
    except AllocationError as e:
        print(name, "AllocationError", isinstance(e, MemoryError))
"""


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS is the Linux way to cap memory")
def test_huge_allocations_raise_memory_error_not_abort():
    # Regression: under a memory limit these aborted the process (SIGABRT) instead of raising.
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_LIMITED.format(path=PYTHON_DIR)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    lines = dict(line.split(" ", 1) for line in out.stdout.strip().splitlines())
    assert lines == {k: "AllocationError True" for k in ("sample", "merwe", "julier", "simplex")}, out.stdout


def test_allocation_error_is_an_autoteach_memory_error():
    assert issubclass(AllocationError, AutoteachError)
    assert issubclass(AllocationError, MemoryError)
    with pytest.raises(MemoryError, match="ellipse sample points"):
        geometry.Ellipse(0, 0, 2, 1, 0).sample(2**62)


class TestRealNumbersOnly:
    """The UKF refused complex ``z`` but cast complex ``Q``, ``R``, ``zs`` and scalars silently."""

    @staticmethod
    def _ukf() -> estimate.UnscentedKalmanFilter:
        pts = MerweScaledSigmaPoints(2, 0.1, 2.0, 0.0)
        return estimate.UnscentedKalmanFilter(
            dim_x=2, dim_z=1, dt=0.1, fx=lambda x, dt: x, hx=lambda x: x[:1], points=pts
        )

    @pytest.mark.parametrize(
        ("what", "call"),
        [
            ("Q", lambda u: (setattr(u, "Q", np.eye(2) * (1 + 1j)), u.predict())),
            ("R", lambda u: (setattr(u, "R", np.eye(1) * (1 + 1j)), u.update(np.array([1.0])))),
            ("R", lambda u: u.update(np.array([1.0]), R=1 + 1j)),
            ("zs", lambda u: u.batch(np.array([[1 + 1j], [2.0]]))),
            ("zs[0]", lambda u: u.batch([np.array([1 + 1j]), None])),
            ("dt", lambda u: u.predict(dt=1j)),
            ("Rs[0]", lambda u: u.batch(np.array([[1.0], [2.0]]), Rs=[1j, 1.0])),
        ],
    )
    def test_complex_inputs_are_refused(self, what, call):
        u = self._ukf()
        with pytest.raises(InvalidInputError, match="^" + re.escape(what) + " must be"):
            call(u)

    def test_real_inputs_still_work(self):
        u = self._ukf()
        u.Q = np.eye(2) * 0.01
        u.predict(dt=0.1)
        u.update(np.array([1.0]), R=0.5)
        assert np.all(np.isfinite(u.x))


class TestMessages:
    def test_full_rank_limit_names_the_python_option(self):
        rng = np.random.default_rng(0)
        y = rng.normal(size=(12_001, 2))
        with pytest.raises(InvalidInputError, match="12000 source points; set low_rank=") as err:
            registration.cpd_nonrigid(y, y)
        assert "Some(" not in str(err.value)

    def test_suggest_next_view_names_a_wrong_calibration(self):
        with pytest.raises(InvalidInputError, match="calibration must be a Calibration"):
            calib.suggest_next_view(None)  # type: ignore[arg-type]

    @pytest.mark.parametrize(
        "call",
        [
            lambda: registration.cpd_rigid(_chevron(), _chevron(), max_iterations=-1),
            lambda: polygon.global_voting(_chevron(), _chevron(), k=-1),
            lambda: polygon.global_voting(_chevron(), _chevron(), max_points=-3),
            lambda: registration.global_cpd(_chevron(), _chevron(), neighbours=-1),
            lambda: MerweScaledSigmaPoints(-2, 0.1, 2.0, 0.0),
        ],
    )
    def test_negative_counts_name_the_argument(self, call):
        # Regression: a bare OverflowError ("can't convert negative int to unsigned").
        with pytest.raises(InvalidInputError, match=r"must be a (non-negative|positive) integer, got -\d"):
            call()

    def test_huge_numbers_are_not_echoed_whole(self):
        with pytest.raises(InvalidInputError) as err:
            polygon.global_voting(_chevron(), _chevron(), k=-(10**300))
        assert len(str(err.value)) < 200


class TestThreads:
    def test_one_filter_shared_by_threads_serialises(self):
        # Regression: "Already borrowed" when two threads called one object at once.
        u = TestRealNumbersOnly._ukf()
        q = np.diag([0.01, 0.02])
        u.Q = q
        p0 = u.P.copy()
        errors: list[BaseException] = []

        def work() -> None:
            try:
                for _ in range(25):
                    u.predict()
            except BaseException as e:  # noqa: BLE001
                errors.append(e)

        threads = [threading.Thread(target=work) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert not errors
        # fx is the identity, so each predict adds Q: order does not matter.
        np.testing.assert_allclose(u.P, p0 + 100 * q, rtol=1e-12)


_DETERMINISM = """
import hashlib, json, sys
sys.path.insert(0, {path!r})
import numpy as np
from autoteach import registration
rng = np.random.default_rng(3)
t = np.linspace(0, 1, 300)
Y = np.c_[np.cos(6 * t) + t, np.sin(4 * t)]
X = Y @ np.array([[0.96, 0.28], [-0.28, 0.96]]) + 0.3 + rng.normal(scale=0.01, size=Y.shape)
out = {{}}
for e in ("dense", "truncated", "fast_gauss"):
    # (a forced fast Gauss transform slows down as sigma shrinks: few iterations for it)
    it = 5 if e == "fast_gauss" else 30
    out["rigid " + e] = registration.cpd_rigid(X, Y, e_step=e, max_iterations=it).transformed
    out["affine " + e] = registration.cpd_affine(X, Y, e_step=e, max_iterations=it).transformed
    out["nonrigid " + e] = registration.cpd_nonrigid(X, Y, e_step=e, max_iterations=30).transformed
scene = np.vstack([X, rng.uniform(-3, 3, size=(200, 2))])
hyps = registration.global_cpd(scene, Y[::2], k=3, max_iterations=30)
out["global"] = np.vstack([h.cpd.transformed for h in hyps])
# Other parallel computations: voting, JIoU batches, k-NN segmentation, MRGP, bundle adjustment.
from autoteach import estimate, polygon, radio, segment, uncertainty
h = polygon.global_voting(scene, Y[::2], k=3)
out["voting"] = np.vstack([np.c_[x.rotation, x.translation] for x in h])
boxes = np.c_[rng.normal(size=(64, 2)), np.full(64, 4.0), np.full(64, 1.8), rng.normal(scale=0.2, size=64)]
cov = np.broadcast_to(np.diag([0.04, 0.02, 0.05, 0.01, 0.005]), (64, 5, 5))
out["jiou"] = uncertainty.jiou(boxes, cov, boxes + 0.3, cov)
pts = rng.normal(size=(3000, 3))
out["segment"] = segment.segment_colored_cloud(pts, rng.uniform(size=(3000, 3)), graph="knn", min_size=5)
tx, rx = rng.uniform(0, 50, size=(400, 2)), rng.uniform(0, 50, size=(400, 2))
rss = -40 - 20 * np.log10(np.hypot(*(tx - rx).T) + 1) + rng.normal(scale=4, size=400)
out["mrgp"] = radio.MRGP().fit(tx, rx, rss).predict(tx[:50], rx[:50])
K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
poses = np.stack([np.eye(4) for _ in range(6)])
poses[:, 0, 3] = np.linspace(0, 0.5, 6)
P3 = rng.normal(size=(80, 3)) * 0.4 + [0, 0, 4]
pi, qi = np.repeat(np.arange(6), 80), np.tile(np.arange(80), 6)
cam = np.einsum("nij,nj->ni", poses[pi, :3, :3].transpose(0, 2, 1), P3[qi] - poses[pi, :3, 3])
obs = (cam @ K.T)[:, :2] / cam[:, 2:] + rng.normal(scale=0.5, size=(480, 2))
start = poses.copy()
start[1:, :3, 3] += 0.01
ba = estimate.bundle_adjust(K, start, P3 + 0.01, obs, pi, qi, fixed_poses=[0])
out["bundle"] = np.concatenate([ba.poses.ravel(), ba.points.ravel()])
print(json.dumps({{k: hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest() for k, v in out.items()}}))
"""


def test_parallel_results_are_bit_identical_on_one_and_two_threads():
    # Regression: block and chunk counts followed the thread count, so the fixed-order sums
    # were fixed per thread count only (differences of 3e-14 to 9e-12).
    runs = []
    for threads in ("1", "2"):
        env = {**os.environ, "RAYON_NUM_THREADS": threads}
        out = subprocess.run(
            [sys.executable, "-c", textwrap.dedent(_DETERMINISM.format(path=PYTHON_DIR))],
            capture_output=True,
            text=True,
            env=env,
            timeout=300,
        )
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append(json.loads(out.stdout))
    assert runs[0] == runs[1]
    assert len(runs[0]) == 15


# -- found by the property suite of part two (tests/test_properties_cli.py) --------------------


@pytest.mark.parametrize("command", ["plan", "tune", "uncertainty"])
def test_a_command_without_its_mode_switch_reports_on_stderr(command, capsys):
    # Regression: `autoteach plan` (and tune, uncertainty) printed the reason to stdout and
    # exited with 2, leaving stderr empty.
    from autoteach.cli import main

    assert main([command]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith(f"autoteach {command}") and len(err.strip().splitlines()) == 1


def test_plan_arguments_are_checked_by_name():
    # Regression: max_iterations=-1 reached the compiled core as an unsigned count (a bare
    # OverflowError); a complex path lost its imaginary part in np.asarray(dtype=float).
    from autoteach import plan

    ws, poses = plan.default_scene()
    with pytest.raises(InvalidInputError, match="max_iterations must be a non-negative integer"):
        plan.plan_path(ws, poses["home"], poses["chamber"], max_iterations=-1)
    with pytest.raises(InvalidInputError, match=r"joints\[0\]"):
        plan.plan_path(ws, poses["home"], poses["chamber"], joints=[-2])
    path = np.array([poses["home"], poses["home"] + 0.01])
    with pytest.raises(InvalidInputError, match="path must be an array of real numbers"):
        plan.optimize_trajectory(ws, path + 1j)
    with pytest.raises(InvalidInputError, match="n_ctrl"):
        plan.optimize_trajectory(ws, path, n_ctrl=-3)
    with pytest.raises(InvalidInputError, match=r"limits\.d_safe must be finite"):
        plan.optimize_trajectory(ws, path, plan.Limits(d_safe=float("nan")))


def test_write_log_refuses_what_json_cannot_hold_before_writing(tmp_path):
    # Regression: a NaN frame rate or ground-truth pose raised json's bare ValueError half-way
    # through the file; a missing directory raised FileNotFoundError for the '.part' file.
    import dataclasses

    from autoteach.io import write_log
    from autoteach.sim import SimConfig, simulate_session

    cfg = SimConfig(camera_params=(60.0, 60.0, 39.5, 22.0), width=80, height=45, supersample=1)
    s = simulate_session(seed=1, frames=2, config=cfg)
    with pytest.raises(InvalidInputError, match="frame_rate_hz must be a positive finite number"):
        dataclasses.replace(s, frame_rate_hz=float("nan"))
    poses = s.camera_poses.copy()
    poses[1, 0, 3] = np.inf
    with pytest.raises(InvalidInputError, match="camera_poses must be finite"):
        write_log(dataclasses.replace(s, camera_poses=poses), tmp_path / "a.mcap")
    with pytest.raises(InvalidInputError, match="does not exist"):
        write_log(s, tmp_path / "no" / "a.mcap")
    assert list(tmp_path.iterdir()) == []


def test_simulate_refuses_an_unwritable_target_before_simulating(monkeypatch, capsys):
    # Regression: `autoteach simulate --out /dev/null` simulated every frame first and only
    # then found that the target is not a regular file.
    import autoteach.sim
    from autoteach.cli import main

    def never(*args, **kwargs):
        raise AssertionError("simulated before checking the target")

    monkeypatch.setattr(autoteach.sim, "simulate_session", never)
    assert main(["simulate", "--frames", "1", "--out", "/dev/null"]) == 2
    err = capsys.readouterr().err
    assert "not a regular file" in err and len(err.strip().splitlines()) == 1


def test_render_opening_refuses_huge_blurs_and_sizes_instead_of_aborting():
    # Regression: a blur σ of 1e300 asked for a kernel of 6e300 taps and a 2³¹ × 2³¹ image for
    # 2⁶² pixels, both allocated infallibly: the process aborted.
    with pytest.raises(InvalidInputError, match="blur_sigma"):
        polygon.simulate_opening(0, width=40, height=40, blur_sigma=1e300)
    with pytest.raises(AllocationError):
        polygon.simulate_opening(0, width=2**31, height=2**31)
    assert polygon.simulate_opening(0, width=40, height=30, blur_sigma=40.0).image.shape == (30, 40)


def test_radio_simulation_refuses_endless_walks_and_huge_missions():
    # Regression: speed/rate of 1e300 m per step walked the roadmap edge by edge for ever;
    # duration·rate of 1e300 steps aborted on allocation; robots=-1 was a bare OverflowError.
    from autoteach import radio

    with pytest.raises(InvalidInputError, match="speed/rate"):
        radio.simulate("office", robots=2, duration=1.0, speed=1e300, rate=1.0)
    with pytest.raises(InvalidInputError, match="duration"):
        radio.simulate("office", robots=2, duration=1e300, rate=1.0)
    with pytest.raises(InvalidInputError, match="robots must be a non-negative integer"):
        radio.simulate("office", robots=-1, duration=1.0)
    sim = radio.simulate("office", robots=2, duration=2.0, rate=2.0)
    assert len(sim.times) == len(sim.rss) > 0


def test_sim_config_refuses_non_numbers_instead_of_casting():
    # Regression: width=nan raised int()'s bare ValueError; complex camera parameters lost their
    # imaginary part in np.asarray(dtype=float64) (a ComplexWarning at most).
    from autoteach.sim import SimConfig

    for field, value in (("width", float("nan")), ("height", float("inf")), ("supersample", 1e300)):
        with pytest.raises(InvalidInputError, match=field):
            SimConfig(**{field: value})
    with pytest.raises(InvalidInputError, match="camera_params must be a sequence of real numbers"):
        SimConfig(camera_params=np.array([1000.0, 1000.0, 640.0, 360.0]) + 1j)
    with pytest.raises(InvalidInputError, match="blur_sigma"):
        SimConfig(blur_sigma="x")


def test_calibrate_refuses_an_image_size_that_is_not_pixels(tmp_path, capsys):
    # Regression: image_size [inf, -4] in the .npz reached int() (OverflowError, reported as an
    # internal error with exit status 1).
    from autoteach.cli import main

    path = tmp_path / "views.npz"
    np.savez(path, image_size=[np.inf, -4], object_points=np.zeros((2, 5, 3)), image_points=np.zeros((2, 5, 2)))
    assert main(["calibrate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "image_size" in err and len(err.strip().splitlines()) == 1


def test_calibrate_names_an_image_side_beyond_32_bits():
    # Regression (property suite at 200 examples): a side of 2**62 passed the 64-bit check and
    # reached the binding's u32 as a bare OverflowError.
    from autoteach import calib

    obj = [np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.05, 0.05, 0.0]])] * 3
    img = [np.array([[10.0, 10.0], [20.0, 10.0], [10.0, 20.0], [20.0, 20.0]])] * 3
    with pytest.raises(InvalidInputError, match="image_size"):
        calib.calibrate(obj, img, "brown_conrady", (1, 2**62))


def test_simulate_opening_names_bad_integer_arguments():
    from autoteach import polygon

    for kwargs, name in (({"width": -1}, "width"), ({"height": 2**70}, "height"), ({"n_lines": -2}, "n_lines")):
        with pytest.raises(InvalidInputError, match=name):
            polygon.simulate_opening(1, **kwargs)
    with pytest.raises(InvalidInputError, match="seed"):
        polygon.simulate_opening(-1)
    with pytest.raises(InvalidInputError, match="blur_sigma"):
        polygon.simulate_opening(1, blur_sigma=float("nan"))


def test_rrt_star_refuses_a_budget_whose_tree_cannot_fit_in_memory():
    # Regression (CI trial): max_iterations = 2**31 ran RRT*'s refinement for hours; one tree
    # node per iteration cannot fit, so the budget is refused up front.
    from autoteach import plan
    from autoteach.errors import AllocationError

    ws, poses = plan.default_scene()
    with pytest.raises(AllocationError, match="max_iterations"):
        plan.plan_path(ws, poses["home"], poses["home"] + [0.2, -0.1, 0.1, 0.0, 0.01], max_iterations=2**31)
