"""Wafer-rim detection (seed 000_3b1454b2b2194811.txt ch. 3.2, 3.5) against renderer ground truth."""

from __future__ import annotations

import importlib.util
import math
import pathlib
import threading
import time

import numpy as np
import pytest

from autoteach.detect import WaferEdge, detect_wafers
from autoteach.errors import InvalidInputError

_BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "wafer_detection.py"
_spec = importlib.util.spec_from_file_location("wafer_detection_bench", _BENCH)
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


@pytest.fixture(scope="module")
def scene() -> tuple[np.ndarray, list[dict]]:
    """A fixed scene: target in slot 5, disturbance 3 slots above, neutral light."""
    rng = np.random.default_rng(11)
    return bench.make_scene(rng, 3)


def test_robustness_on_20_rendered_images() -> None:
    """Smaller version of benchmarks/wafer_detection.py (which runs 210 images)."""
    # Regression floors under the measured level on these 20 images; the failure modes are in
    # docs/design/wafer-rims.md.
    r = bench.evaluate(20, seed=101)
    assert r["visible_rims"] >= 60
    assert r["recall"] >= 0.80, r
    assert r["precision"] >= 0.90, r
    assert r["median_centre_error_px"] <= 0.15, r
    assert r["median_axis_error_rel"] <= 0.003, r


def test_rims_are_paired_and_labelled(scene: tuple[np.ndarray, list[dict]]) -> None:
    image, truth = scene
    dets = detect_wafers(image)
    assert dets and all(isinstance(d, WaferEdge) for d in dets)
    pairs = bench.match(dets, truth)
    assert len(pairs) >= 2
    for d_i, j in pairs:
        d, t = dets[d_i], truth[j]
        assert d.kind == t["rim"]
        assert d.points.ndim == 2 and d.points.shape[1] == 2 and len(d.points) >= 32
        # Under the assembly's threshold (0.25 px), or 3x it for a rim refitted by the joint band
        # model or found along the band as its partner's far edge (per-profile band fits).
        assert 0.0 <= d.residual < 0.75
        assert d.covariance is not None and d.covariance.shape == (5, 5)
        assert np.all(np.linalg.eigvalsh(d.covariance) > 0.0)
        # Points lie on the detected ellipse: recomputed residual equals the reported one.
        assert abs(np.mean(np.abs(d.ellipse.distance(d.points, "orthogonal"))) - d.residual) < 1e-6
    # The two rims of one true wafer share a wafer_id, different wafers do not.
    by_wafer: dict[int, set[int]] = {}
    for d_i, j in pairs:
        by_wafer.setdefault(truth[j]["wafer"], set()).add(dets[d_i].wafer_id)
    assert all(len(ids) == 1 for ids in by_wafer.values())
    ids = [next(iter(v)) for v in by_wafer.values()]
    assert len(set(ids)) == len(ids)
    # Upper rim before lower within a wafer, upper centre above lower centre.
    for wid in {d.wafer_id for d in dets}:
        rims = [d for d in dets if d.wafer_id == wid]
        if len(rims) == 2:
            assert [r.kind for r in rims] == ["upper", "lower"]
            assert rims[0].ellipse.cy < rims[1].ellipse.cy


def test_dtypes_agree(scene: tuple[np.ndarray, list[dict]]) -> None:
    image, _ = scene
    ref = detect_wafers(image)
    for dtype in (np.float32, np.float64):
        other = detect_wafers(image.astype(dtype) / 255.0)
        assert len(other) == len(ref)
        for a, b in zip(ref, other, strict=True):
            assert a.kind == b.kind and a.wafer_id == b.wafer_id
            assert abs(a.ellipse.cx - b.ellipse.cx) < 1e-3 and abs(a.ellipse.b - b.ellipse.b) < 1e-3
    # Non-contiguous views are read correctly.
    padded = np.zeros((image.shape[0], 2 * image.shape[1]), np.uint8)
    padded[:, ::2] = image
    view = detect_wafers(padded[:, ::2])
    assert [(d.kind, d.ellipse.cx) for d in view] == [(d.kind, d.ellipse.cx) for d in ref]


def test_deterministic(scene: tuple[np.ndarray, list[dict]]) -> None:
    image, _ = scene
    a, b = detect_wafers(image), detect_wafers(image)
    assert [(d.kind, d.wafer_id, d.ellipse.cx, d.ellipse.a) for d in a] == [
        (d.kind, d.wafer_id, d.ellipse.cx, d.ellipse.a) for d in b
    ]


def test_prior_gates_sizes(scene: tuple[np.ndarray, list[dict]]) -> None:
    image, _ = scene
    dets = detect_wafers(image)
    a_values = sorted(d.ellipse.a for d in dets)
    assert detect_wafers(image, semi_major_range=(1.0, a_values[0] - 1.0)) == []
    kept = detect_wafers(image, semi_major_range=(a_values[0] - 1.0, a_values[-1] + 1.0))
    assert len(kept) == len(dets)


def test_blank_black_and_saturated_images_give_nothing() -> None:
    for value in (0, 128, 255):
        assert detect_wafers(np.full((720, 1280), value, np.uint8)) == []
    rng = np.random.default_rng(0)
    noise = np.clip(rng.normal(128, 2.0, (240, 320)), 0, 255).astype(np.uint8)
    assert detect_wafers(noise) == []


def test_synthetic_ellipse_band_is_found_exactly() -> None:
    """An antialiased bright elliptic band drawn independently of the renderer."""
    h, w = 300, 500
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy, a, b = 250.3, 120.6, 200.0, 60.0
    img = np.full((h, w), 25.0)
    ss = 4
    acc = np.zeros((h, w))
    for i in range(ss):
        for j in range(ss):
            u = xx - 0.5 + (i + 0.5) / ss
            v = yy - 0.5 + (j + 0.5) / ss
            q_up = ((u - cx) / a) ** 2 + ((v - cy) / b) ** 2
            q_lo = ((u - cx) / a) ** 2 + ((v - cy - 4.0) / b) ** 2
            # The band between the two ellipses, on the lower half only (the visible front).
            acc += (q_up > 1.0) & (q_lo <= 1.0) & (v > cy)
    img += 200.0 * acc / ss**2
    dets = detect_wafers(img.astype(np.uint8))
    upper = [d for d in dets if d.kind == "upper"]
    lower = [d for d in dets if d.kind == "lower"]
    assert len(upper) == 1 and len(lower) == 1
    assert upper[0].wafer_id == lower[0].wafer_id
    # Known bias (see docs/benchmarks.md): toward the ends of the front arc the band narrows
    # below the edge operator's support, both edges are pushed apart there, and the partial-arc
    # fit turns that into a centre shift of ~0.5 px along v and a ~1 % shorter minor axis.
    for d, ccy in ((upper[0], cy), (lower[0], cy + 4.0)):
        assert math.hypot(d.ellipse.cx - cx, d.ellipse.cy - ccy) < 1.0
        assert abs(d.ellipse.a - a) / a < 0.01 and abs(d.ellipse.b - b) / b < 0.02


@pytest.mark.parametrize(
    ("image", "match"),
    [
        (np.zeros((0, 10), np.uint8), "empty"),
        (np.zeros((10,), np.uint8), "2-D"),
        (np.zeros((4, 4, 3), np.uint8), "2-D"),
        (np.zeros((10, 10), np.int32), "dtype"),
        (np.zeros((10, 10), np.uint16), "dtype"),
        (np.array([[0.0, np.nan], [0.0, 0.0]]), "must be finite|non-finite"),
    ],
)
def test_bad_images_raise(image: np.ndarray, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        detect_wafers(image)


def test_bad_parameters_raise() -> None:
    img = np.zeros((20, 20), np.uint8)
    with pytest.raises(InvalidInputError, match="canny high"):
        detect_wafers(img, canny_low=10.0, canny_high=5.0)
    with pytest.raises(InvalidInputError, match="residual_threshold"):
        detect_wafers(img, residual_threshold=-1.0)
    with pytest.raises(InvalidInputError, match="up"):
        detect_wafers(img, up=(0.0, 0.0))
    with pytest.raises(InvalidInputError, match="min_points"):
        detect_wafers(img, min_arc_points=3)


def test_releases_the_gil(scene: tuple[np.ndarray, list[dict]]) -> None:
    image, _ = scene
    ticks = 0
    done = threading.Event()

    def counter() -> None:
        nonlocal ticks
        while not done.is_set():
            ticks += 1
            time.sleep(0.001)

    t = threading.Thread(target=counter)
    t.start()
    t0 = time.perf_counter()
    for _ in range(3):
        detect_wafers(image)
    elapsed = time.perf_counter() - t0
    done.set()
    t.join()
    # With the GIL held, the counter could not run during detection.
    assert ticks >= max(3, int(0.2 * elapsed / 0.0015)), (ticks, elapsed)


def test_python_defaults_are_the_library_defaults() -> None:
    """Every default of WaferDetectOptions equals DetectParams::default() in Rust."""
    import dataclasses

    from autoteach import _core
    from autoteach.wafer_detect_options import WaferDetectOptions

    rust = _core.wafer_detect_defaults()
    exposed = {f.name: f.default for f in dataclasses.fields(WaferDetectOptions) if f.default is not None}
    assert set(rust) <= set(exposed), set(rust) - set(exposed)
    for name, value in rust.items():
        if isinstance(value, str):
            assert exposed[name] == value, name
        else:
            assert exposed[name] == pytest.approx(value), name


def test_options_object_and_keywords_agree_and_unknown_names_are_refused() -> None:
    from autoteach.wafer_detect_options import WaferDetectOptions

    image = np.zeros((40, 60), np.uint8)
    image[10:30, 15:45] = 200
    a = detect_wafers(image, WaferDetectOptions(canny_low=4.0))
    b = detect_wafers(image, canny_low=4.0)
    assert [e.ellipse for e in a] == [e.ellipse for e in b]
    with pytest.raises(InvalidInputError, match="canny_lo"):
        detect_wafers(image, canny_lo=4.0)
    with pytest.raises(InvalidInputError, match="principal_point"):
        detect_wafers(image, principal_point=(1.0, 2.0, 3.0))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_unpaired_residual": 0.0}, "max_unpaired_residual"),
        ({"max_relative_sigma_b": 0.0}, "max_relative_sigma_b"),
        ({"max_relative_sigma_b": math.nan}, "max_relative_sigma_b"),
        ({"max_centre_sigma": 0.0}, "max_centre_sigma"),
        ({"max_centre_sigma": math.nan}, "max_centre_sigma"),
        ({"min_coverage": 1.5}, "min_coverage"),
        ({"max_arc_deviation": math.nan}, "max_arc_deviation"),
        ({"min_rim_separation": 1.0}, "min_rim_separation"),
        ({"max_arc_residual_ratio": -1.0}, "max_arc_residual_ratio"),
        ({"inflection_sigmas": math.inf}, "inflection_sigmas"),
        ({"principal_point": (640.0, 360.0)}, "principal_point"),
        ({"thickness_ratio": 0.005, "focal_length": 900.0, "principal_point": (math.nan, 360.0)}, "principal_point"),
        ({"thickness_ratio": 0.005, "focal_length": 900.0, "edge_profile": "box"}, "edge_profile"),
        ({"thickness_ratio": 1 / 150}, "focal_length"),
        ({"focal_length": 1000.0}, "thickness_ratio"),
        ({"thickness_ratio": -1.0, "focal_length": 1000.0}, "thickness_ratio"),
        ({"thickness_ratio": 1 / 150, "focal_length": math.nan}, "focal_length"),
    ],
)
def test_bad_stage_parameters_raise(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        detect_wafers(np.zeros((20, 20), np.uint8), **kwargs)


def test_rim_offset_prior_moves_only_lower_rims() -> None:
    """The rim offset prior (the rendered wafer's thickness/radius and the camera's focal length)
    acts on the joint fit of the far lower rim only: upper rims are unchanged, and over a few
    benchmark scenes it moves some lower rim, none farther than 1 px from the truth-free fit
    (the thin-band and front-band fits, which the prior also enables, off: they are tested below)."""
    prior = {"thickness_ratio": bench.WAFER_THICKNESS / bench.WAFER_RADIUS, "focal_length": float(bench.PARAMS[0])}
    rng = np.random.default_rng(bench.SEED)
    moved = 0
    for i in range(12):
        image, _ = bench.make_scene(rng, 1 + i % 20)
        ref = detect_wafers(image)
        pri = detect_wafers(image, thin_band_fit=False, front_band_fit=False, **prior)
        assert len(ref) == len(pri)
        for a, b in zip(ref, pri, strict=True):
            assert (a.kind, a.wafer_id) == (b.kind, b.wafer_id)
            shift = math.hypot(a.ellipse.cx - b.ellipse.cx, a.ellipse.cy - b.ellipse.cy)
            if a.kind == "upper":
                assert shift == 0.0 and a.ellipse.b == b.ellipse.b
            else:
                assert shift < 1.0
                moved += shift > 1e-6 or abs(a.ellipse.b - b.ellipse.b) > 1e-6
    assert moved >= 1


def test_stage_switches_reach_the_detector(scene: tuple[np.ndarray, list[dict]]) -> None:
    """Turning the band refinement off changes the rims' points (the refinement moves them to
    the band model's edges), and keeping lone rims of any residual never loses a rim."""
    image, _ = scene
    ref = detect_wafers(image)
    raw = detect_wafers(image, band_refinement=False)
    assert ref and raw
    moved = [
        not np.array_equal(a.points, b.points)
        for a in ref
        for b in raw
        if a.kind == b.kind and a.wafer_id == b.wafer_id
    ]
    assert any(moved)
    loose = detect_wafers(image, max_unpaired_residual=math.inf)
    assert len(loose) >= len(ref)


def test_non_contiguous_view_equals_its_copy(scene: tuple[np.ndarray, list[dict]]) -> None:
    """The binding reads C-contiguous images in place and copies other views: same result."""
    image, _ = scene
    fortran = np.asfortranarray(image)
    from autoteach import _core

    a = _core.wafer_detect(fortran)
    b = _core.wafer_detect(np.ascontiguousarray(image))
    assert len(a) == len(b) and len(a) > 0
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.points, y.points)


def _column_fit_gains(switch: str, n_scenes: int = 45, **options: object) -> tuple[int, int, bool]:
    """Visible-rim hits (the benchmark's rule: 1 px, 1 %, renderer ground truth) gained and lost
    by turning the detector keyword ``switch`` on, with the rim offset prior, over the first
    ``n_scenes`` benchmark scenes of seed 3 (other detector keywords: ``options``); and whether
    no scene gained a detection that matches no rim (a refit can add a detection: a rim whose
    edge-point fit was too uncertain to be reported)."""
    prior = {
        "thickness_ratio": bench.WAFER_THICKNESS / bench.WAFER_RADIUS,
        "focal_length": float(bench.PARAMS[0]),
        **options,
    }
    rng = np.random.default_rng(bench.SEED)
    gained = lost = 0
    no_wrong_added = True
    for i in range(n_scenes):
        image, truth = bench.make_scene(rng, 1 + i % 20)
        visible = [bench.visible_fraction(t) >= bench.MIN_VISIBLE for t in truth]
        hits, unmatched = {}, {}
        for on in (False, True):
            dets = detect_wafers(image, **{switch: on}, **prior)
            matches = bench.match(dets, truth)
            hits[on] = {j for _, j in matches if visible[j]}
            unmatched[on] = len(dets) - len(matches)
        no_wrong_added &= unmatched[True] <= unmatched[False]
        gained += len(hits[True] - hits[False])
        lost += len(hits[False] - hits[True])
    return gained, lost, no_wrong_added


def test_thin_band_fit_adds_thin_rims_and_no_wrong_detection() -> None:
    """With the rim offset prior, the thin-band fit (both rims of a wafer with ``b`` under 9 px
    refitted from the image columns) turns thin disturbance rims into hits over the first 45
    benchmark scenes of seed 3, and no hit into a miss."""
    gained, lost, _ = _column_fit_gains("thin_band_fit")
    assert gained >= 3 and lost == 0, (gained, lost)


def test_level_band_search_finds_wafers_seen_edge_on() -> None:
    """With the rim offset prior and the renderer's edge profile, the search for wafers seen
    almost edge-on (long bright bars: ends, sag, then the thin column fit with ``cx`` and ``a``
    held at the ends) turns both rims of a disturbance wafer with ``b`` 1.5 / 2.4 px into hits
    over the first 45 benchmark scenes of seed 3 (no edge-point fit finds them), and no hit into a
    miss."""
    gained, lost, _ = _column_fit_gains("level_band_search", edge_profile="pixel")
    assert gained >= 2 and lost == 0, (gained, lost)


def test_front_band_fit_adds_rims_and_loses_none() -> None:
    """With the rim offset prior, the front-band fit (both rims of a level wafer with ``b`` from
    9 px, seen from above or below, refitted from the image columns across the side band) turns
    rims whose edge-point fits are 1-3 % off in ``b`` into hits over the first 45 benchmark scenes
    of seed 3 (9 since the exact lower-rim map, among them the partner rims of two wafers seen
    from below that were too uncertain to report), no hit into a miss, and adds no wrong
    detection."""
    gained, lost, no_wrong_added = _column_fit_gains("front_band_fit")
    assert gained >= 7 and lost == 0 and no_wrong_added, (gained, lost, no_wrong_added)
