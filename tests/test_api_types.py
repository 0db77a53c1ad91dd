"""One type for one concept (issue 40, item 4): every public result is the documented type, and its
field names are those of the Rust struct it comes from.

The Rust field names are parsed from ``crates/*/src`` at test time, so the test fails when either
side is renamed without the other. The table of types is ``docs/design/api-types.md``.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import pathlib
import re
from functools import cache
from typing import Any

import numpy as np
import pytest

from autoteach import (
    _core,
    active,
    calib,
    control,
    detect,
    estimate,
    geometry,
    plan,
    polygon,
    radio,
    registration,
    segment,
    track,
    uncertainty,
)

ROOT = pathlib.Path(__file__).resolve().parents[1]
CRATES = ROOT / "crates"


@cache
def rust_fields(path: str, struct: str) -> tuple[str, ...]:
    """The public field names of ``pub struct struct`` in ``crates/path``, in declaration order."""
    text = (CRATES / path).read_text()
    m = re.search(rf"^pub struct {struct}\b[^{{;]*\{{\n(.*?)^\}}", text, re.S | re.M)
    assert m, f"pub struct {struct} not found in crates/{path}"
    return tuple(re.findall(r"^    pub (\w+):", m.group(1), re.M))


# (Python type, Rust file under crates/, Rust struct, Python-only names with the reason).
DATACLASSES: list[tuple[type, str, str, dict[str, str]]] = [
    (detect.EllipseFit, "detect/src/ellipse/mod.rs", "EllipseFit", {}),
    (detect.WaferEdge, "detect/src/wafers/mod.rs", "WaferEdge", {}),
    (registration.RigidCpdResult, "detect/src/cpd/mod.rs", "RigidResult", {}),
    (registration.AffineCpdResult, "detect/src/cpd/mod.rs", "AffineResult", {}),
    (registration.NonrigidCpdResult, "detect/src/cpd/mod.rs", "NonrigidResult", {}),
    (registration.GlobalCpdHypothesis, "detect/src/cpd/global.rs", "GlobalHypothesis", {}),
    (polygon.RigidHypothesis, "detect/src/voting.rs", "RigidHypothesis", {}),
    (polygon.PolygonPose, "detect/src/polygon/mod.rs", "PolygonPose", {}),
    (polygon.PolygonDetection, "detect/src/polygon/mod.rs", "PolygonDetection", {}),
    (polygon.VoteMap, "detect/src/polygon/mod.rs", "VoteMap", {}),
    (track.Circle3, "detect/src/track/circle.rs", "Circle3", {}),
    (track.UpdateTimings, "detect/src/track/mod.rs", "UpdateTimings", {}),
    (
        track.Track,
        "detect/src/track/mod.rs",
        "Track",
        {"ellipse": "Rust method Track::ellipse()", "circle": "Rust method Track::circle()"},
    ),
    (estimate.SolverSummary, "estimate/src/lsq/solver.rs", "Summary", {}),
    (estimate.BundleAdjustResult, "estimate/src/lsq/bundle.rs", "BundleResult", {"pose_vectors": "N×6 form"}),
    (calib.Suggestion, "estimate/src/calib/solve.rs", "Suggestion", {}),
    (calib.ModelChoice, "estimate/src/calib/solve.rs", "ModelScore", {"error": "Err side of Rust's Result"}),
    (calib.MaxEre, "estimate/src/calib/ere.rs", "MaxEre", {}),
    (calib.View, "estimate/src/calib/mod.rs", "View", {}),
    (active.ObservabilityIndices, "estimate/src/active/design.rs", "ObservabilityIndices", {}),
    (active.ApproximateDesign, "estimate/src/active/design.rs", "ApproximateDesign", {}),
    (active.DetmaxResult, "estimate/src/active/design.rs", "DetmaxResult", {}),
    (active.UpdateSummary, "estimate/src/active/model.rs", "UpdateSummary", {}),
    (active.HandEyeParams, "estimate/src/active/model.rs", "HandEyeParams", {}),
    (active.PlannedPose, "estimate/src/active/planner.rs", "PlannedPose", {}),
    (active.Plan, "estimate/src/active/planner.rs", "Plan", {}),
    (active.Rejections, "estimate/src/active/planner.rs", "Rejections", {}),
    (
        active.TrialRuns,
        "estimate/src/active/closed_loop.rs",
        "TrialResult",
        {"names": "shared by the trials", "estimated": "shared by the trials", "power": "shared by the trials"},
    ),
    (radio.TomoSolution, "estimate/src/radio/tomo.rs", "TomoSolution", {}),
    (segment.CloudSegmentation, "detect/src/segment/mod.rs", "CloudSegmentation", {}),
    (segment.Colorization, "detect/src/segment/coregister.rs", "Colorized", {}),
    (segment.ExtrinsicsFit, "estimate/src/lidar_camera.rs", "ExtrinsicsFit", {}),
    (control.Margins, "estimate/src/control/analysis.rs", "Margins", {}),
    (control.FitResult, "estimate/src/control/fit.rs", "FitResult", {}),
    (control.PlantReport, "estimate/src/control/tune.rs", "PlantReport", {}),
    (
        control.TuneResult,
        "estimate/src/control/tune.rs",
        "TuneReport",
        {"sections": "Rust returns the ControllerStructure beside the report"},
    ),
    (control.JointPlant, "estimate/src/control/plant.rs", "JointPlant", {}),
    (uncertainty.LabelPosterior, "detect/src/uncertainty/mod.rs", "LabelPosterior", {}),
    (uncertainty.NoiseEstimate, "detect/src/uncertainty/noise.rs", "NoiseEstimate", {}),
    (uncertainty.Grid, "geometry/src/boxes/spatial.rs", "Grid2", {}),
    (
        plan.PathResult,
        "geometry/src/plan/astar.rs",
        "PathResult",
        {"extra": "RrtStarResult's own figures (tree cost, first solution, nodes): both planners return one type"},
    ),
    (plan.Limits, "geometry/src/plan/limits.rs", "Limits", {}),
    (plan.Verification, "geometry/src/plan/limits.rs", "Verification", {}),
    (plan.OptimizeResult, "estimate/src/plan/time_optimal.rs", "OptimizeResult", {}),
]

# Existing class pattern (a Python class holding the compiled object): every Rust field is a
# read-only property of the same name.
PROPERTY_CLASSES: list[tuple[type, str, str]] = [
    (geometry.Ellipse, "geometry/src/conic.rs", "Ellipse"),
    (calib.Calibration, "estimate/src/calib/solve.rs", "Calibration"),
    (radio.LogFit, "estimate/src/radio/logfit.rs", "LogFit"),
]

# Compiled result classes whose getters carry the Rust field names.
BINDING_CLASSES: list[tuple[Any, str, str]] = [
    (_core.EllipseFit, "detect/src/ellipse/mod.rs", "EllipseFit"),
]


def _name(case: tuple) -> str:
    return case[0].__qualname__


@pytest.mark.parametrize("case", DATACLASSES, ids=_name)
def test_dataclass_fields_are_the_rust_fields(case: tuple[type, str, str, dict[str, str]]) -> None:
    cls, path, struct, extra = case
    assert dataclasses.is_dataclass(cls)
    py = [f.name for f in dataclasses.fields(cls)]
    rust = rust_fields(path, struct)
    assert len(py) == len(set(py))
    assert set(py) == set(rust) | set(extra), f"{cls.__qualname__} {py} vs {struct} {list(rust)} (+{list(extra)})"
    assert not set(extra) & set(rust), "a Python-only name is now a Rust field: drop it from the extras"


@pytest.mark.parametrize("case", DATACLASSES, ids=_name)
def test_result_dataclasses_are_frozen_with_slots(case: tuple[type, str, str, dict[str, str]]) -> None:
    cls = case[0]
    if cls is track.Track:
        pytest.skip("Track is the tracker's live record, updated in place each frame")
    params = cls.__dataclass_params__  # type: ignore[attr-defined]
    assert params.frozen, cls
    if cls is detect.WaferEdge:
        return  # frozen; its module part belongs to issue 42, which shares it with detect_wafer_rims
    assert "__slots__" in cls.__dict__, cls


@pytest.mark.parametrize("case", PROPERTY_CLASSES, ids=_name)
def test_wrapper_classes_expose_every_rust_field(case: tuple[type, str, str]) -> None:
    cls, path, struct = case
    missing = [f for f in rust_fields(path, struct) if not isinstance(getattr(cls, f, None), property)]
    assert not missing, f"{cls.__qualname__} lacks {missing} of {struct}"


@pytest.mark.parametrize("case", BINDING_CLASSES, ids=_name)
def test_binding_getters_are_the_rust_fields(case: tuple[Any, str, str]) -> None:
    cls, path, struct = case
    getters = {n for n in dir(cls) if not n.startswith("_")}
    assert getters == set(rust_fields(path, struct)), f"_core.{cls.__name__} {sorted(getters)}"


# --- the functions return the documented types ------------------------------------------------


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _check(obj: Any, cls: type) -> None:
    assert type(obj) is cls, f"{type(obj).__qualname__} is not {cls.__qualname__}"


def test_detection_and_registration_results() -> None:
    arc = geometry.Ellipse(50.0, 40.0, 30.0, 12.0, 0.3).sample(60, 0.0, 4.0)
    fit = detect.fit_ellipse(arc)
    _check(fit, detect.EllipseFit)
    _check(fit.ellipse, geometry.Ellipse)
    assert fit.residual_mean == pytest.approx(0.0, abs=1e-8) and fit.residual_rms == pytest.approx(0.0, abs=1e-8)

    rng = np.random.default_rng(0)
    y = rng.uniform(-1.0, 1.0, (30, 2))
    x = 1.2 * y @ _rot(0.3).T + [0.2, -0.1]
    rigid = registration.cpd_rigid(x, y, return_P=True)
    _check(rigid, registration.RigidCpdResult)
    np.testing.assert_allclose(rigid.rotation, _rot(0.3), atol=1e-6)
    np.testing.assert_allclose(rigid.translation, [0.2, -0.1], atol=1e-6)
    assert rigid.scale == pytest.approx(1.2, abs=1e-6) and rigid.p is not None and rigid.p.shape == (30, 30)
    affine = registration.cpd_affine(x, y)
    _check(affine, registration.AffineCpdResult)
    np.testing.assert_allclose(affine.matrix, 1.2 * _rot(0.3), atol=1e-5)
    _check(registration.cpd_nonrigid(x, y), registration.NonrigidCpdResult)

    moved = y @ _rot(0.3).T + [0.2, -0.1]  # global voting proposes rigid transforms
    scene = np.vstack([moved, rng.uniform(-3.0, 3.0, (20, 2))])
    hyps = registration.global_cpd(scene, y, k=2)
    assert hyps
    for h in hyps:
        _check(h, registration.GlobalCpdHypothesis)
        _check(h.initial, polygon.RigidHypothesis)
        _check(h.cpd, registration.NonrigidCpdResult)
    best = hyps[0]  # least deformation energy first
    assert best.cpd.energy == min(h.cpd.energy for h in hyps)
    np.testing.assert_allclose(best.initial.rotation, _rot(0.3), atol=0.05)
    np.testing.assert_allclose(best.cpd.transformed, moved, atol=0.02)
    for h in polygon.global_voting(moved, y, k=2):
        _check(h, polygon.RigidHypothesis)


def test_polygon_detection_result() -> None:
    scene = polygon.simulate_opening(seed=3)
    det = polygon.detect_polygon(scene.image, polygon.CROSS_TEMPLATE, scene.homography)
    _check(det, polygon.PolygonDetection)
    _check(det.pose, polygon.PolygonPose)
    _check(det.vote_map, polygon.VoteMap)
    assert det.vote_map.data.shape == (det.vote_map.rows, det.vote_map.cols)
    np.testing.assert_allclose(det.centre_image, scene.centre_image, atol=0.5)


def test_wafer_edges_and_tracks() -> None:
    path = ROOT / "benchmarks" / "wafer_detection.py"
    spec = importlib.util.spec_from_file_location("wafer_detection_bench_types", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    image, _truth = bench.make_scene(np.random.default_rng(11), 3)
    edges = detect.detect_wafers(image)
    assert edges
    for e in edges:
        _check(e, detect.WaferEdge)
        _check(e.ellipse, geometry.Ellipse)
    tracker = track.WaferTracker(min_hits=1)
    tracks = []
    for _ in range(2):
        tracks = tracker.update(edges)
    assert tracks
    for t in tracks:
        _check(t, track.Track)
        _check(t.ellipse, geometry.Ellipse)
        # The edges registered in the last frame are the caller's objects of that frame.
        assert t.edges and all(any(e is d for d in edges) for e in t.edges)
        assert t.edges == [e for f, e in t.history if f == t.last_frame]
    timings = tracker.last_timings
    _check(timings, track.UpdateTimings)
    assert min(timings.predict, timings.associate, timings.manage) >= 0.0


def test_estimate_results() -> None:
    k = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    rng = np.random.default_rng(1)
    pts = rng.uniform([-1.0, -1.0, 4.0], [1.0, 1.0, 6.0], (20, 3))
    poses = np.zeros((3, 6))
    poses[:, 3] = [0.0, 0.3, -0.3]
    obs, pi, xi = [], [], []
    for i, p in enumerate(poses):
        for j, x in enumerate(pts):
            c = x + p[3:]
            obs.append(k[:2, :2] @ (c[:2] / c[2]) + k[:2, 2])
            pi.append(i)
            xi.append(j)
    res = estimate.bundle_adjust(k, poses, pts + 0.01, np.array(obs), pi, xi, fixed_poses=(0, 1))
    _check(res, estimate.BundleAdjustResult)
    _check(res.summary, estimate.SolverSummary)
    assert res.poses.shape == (3, 4, 4) and res.pose_vectors.shape == (3, 6)
    assert res.summary.converged and res.final_cost == res.summary.final_cost < 1e-12

    p = estimate.LeastSquaresProblem()
    b = p.add_block(np.array([1.0, 2.0]))
    p.add_prior(b, np.array([3.0, -1.0]), np.eye(2))
    s = p.solve()
    _check(s, estimate.SolverSummary)
    np.testing.assert_allclose(p.values(b), [3.0, -1.0], atol=1e-9)
    assert s.converged and s.num_parameters == 2


def test_active_results() -> None:
    o = active.observability_indices(np.diag([16.0, 4.0, 1.0]))
    _check(o, active.ObservabilityIndices)
    assert (o.o1, o.o3, o.power) == pytest.approx((4.0, 1.0, 2.0))
    xs = np.linspace(-1.0, 1.0, 21)
    cands = np.stack([np.ones_like(xs), xs], axis=1)
    d = active.d_optimal_design(cands, tol=1e-7)
    _check(d, active.ApproximateDesign)
    assert d.weights[0] == pytest.approx(0.5, abs=1e-3) and d.max_variance == pytest.approx(2.0, rel=1e-5)
    r = active.detmax(cands, 2)
    _check(r, active.DetmaxResult)
    assert r.selected == [0, 20]

    state = active.ActiveState()
    _check(state.estimate(), active.HandEyeParams)
    assert state.estimate().opening.shape == (4, 4)
    _check(state.indices(), active.ObservabilityIndices)
    plan = active.plan_next_pose(state)
    _check(plan, active.Plan)
    _check(plan.best, active.PlannedPose)
    _check(plan.rejections, active.Rejections)
    assert plan.best.camera_pose.shape == (4, 4)
    q = plan.best.joints
    u = state.update(q, state.project(q))
    _check(u, active.UpdateSummary)
    assert u.used == 4 and u.rms_px < 1e-6

    runs = active.run_trials(1, seed=2, mode="baseline", steps=2)
    _check(runs, active.TrialRuns)
    assert runs.errors.shape == (1, 2, len(active.PARAM_NAMES)) and runs.indices.shape == (1, 2, 7)


def test_calibration_results() -> None:
    lens = calib.LENSES["narrow"]
    target = calib.make_target()
    poses = calib.random_poses(lens["model"], lens["params"], lens["image_size"], target, 12, seed=4)
    views = [calib.simulate_view(lens["model"], lens["params"], lens["image_size"], p, target) for p in poses]
    views = [v for v in views if v is not None][:6]
    obj, img = [v[0] for v in views], [v[1] for v in views]
    cal = calib.calibrate(obj, img, lens["model"], lens["image_size"])
    _check(cal, calib.Calibration)
    _check(cal.camera, geometry.Camera)
    np.testing.assert_allclose(cal.camera.params, lens["params"], rtol=1e-6, atol=1e-6)
    assert cal.poses.shape == (len(obj), 4, 4)
    vs = cal.views
    assert len(vs) == len(obj) and all(type(v) is calib.View for v in vs)
    np.testing.assert_allclose(vs[0].plane, obj[0][:, :2])
    m = cal.max_ere_stats(samples=50)
    _check(m, calib.MaxEre)
    assert m.value == pytest.approx(cal.compute_max_ere(samples=50)[0], rel=1e-12)
    _check(calib.suggest_next_view(cal, samples=20), calib.Suggestion)
    choices = calib.select_model(obj, img, lens["image_size"], models=("pinhole", "brown_conrady"))
    assert all(type(c) is calib.ModelChoice for c in choices)


def test_radio_results() -> None:
    rng = np.random.default_rng(5)
    classes = np.zeros((20, 30), dtype=np.uint8)
    classes[:15, 10] = radio.STRUCTURE
    occ = radio.OccupancyMap(classes, 1.0)
    tx, rx = rng.uniform([0, 0], [30, 20], (200, 2)), rng.uniform([0, 0], [30, 20], (200, 2))
    rss = -40 - 22 * np.log10(np.maximum(np.linalg.norm(tx - rx, axis=1), 1.0)) + rng.normal(0, 2, 200)
    for model in (radio.MRT(), radio.MATTE()):
        sol = model.fit(tx, rx, rss, occupancy=occ).solution()
        _check(sol, radio.TomoSolution)
        assert sol.factor_nnz > 0 and np.isfinite(sol.values).all()
    fit = radio.LogFit().fit(tx, rx, rss)
    assert fit.normal_inverse.shape == (2, 2) and fit.residual_variance > 0
    sim = radio.simulate("office", robots=2, duration=30.0, seed=1)
    _check(sim, radio.Simulation)
    _check(radio.replay(sim, models={"LogFit": radio.LogFit}, start=10.0, bins=2), radio.ReplayResult)


def test_segmentation_results() -> None:
    sim = segment.simulate_scan("ramp", render=False)
    _check(sim, segment.SimulatedScan)
    res = segment.segment_cloud(sim.points, sim.true_colors)
    _check(res, segment.CloudSegmentation)
    assert res.normal_ok.shape == res.labels.shape and res.normal_ok.any()
    norms = np.linalg.norm(res.normals, axis=-1)
    np.testing.assert_allclose(norms[res.normal_ok], 1.0, atol=1e-9)
    assert np.all(norms[~res.normal_ok] == 0.0)


def test_control_results() -> None:
    plants = control.joint_plants("JT2", 2)
    for p in plants:
        _check(p, control.JointPlant)
        _check(p.motor, control.TransferFunction)
    pid = control.TransferFunction([1.0, 2.0], [1.0, 0.0])
    _check(control.margins(plants[0].motor, pid), control.Margins)
    w = np.geomspace(1.0, 1e3, 60)
    g = control.TransferFunction([1.0], [1.0, 0.4, 100.0])
    fit = control.fit_frequency_response(w, g.frequency_response(w), 0, 2)
    _check(fit, control.FitResult)
    _check(fit.model, control.TransferFunction)
    np.testing.assert_allclose(np.sort(fit.model.poles()), np.sort(g.poles()), rtol=1e-6)


def test_uncertainty_results() -> None:
    box = np.array([0.0, 0.0, 3.6, 1.8, 0.0])
    pts = np.array([[1.8, 0.0], [1.8, 0.9], [0.0, 0.9]])
    post = uncertainty.label_uncertainty(box, pts, sigma=0.2, prior=1.0)
    _check(post, uncertainty.LabelPosterior)
    np.testing.assert_allclose(post.cov @ post.precision, np.eye(5), atol=1e-8)
    assert post.sigma == 0.2 and post.points == 3
    labels, scans = uncertainty.simulate_cars(5, sigma=0.2, seed=1)
    est = uncertainty.estimate_noise(labels, scans)
    _check(est, uncertainty.NoiseEstimate)
    assert est.iterations == len(est.history) and est.sigma == est.history[-1]
