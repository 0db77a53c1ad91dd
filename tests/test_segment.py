"""Coloured point-cloud co-registration and segmentation (seed 004 ch. 4) against independent truths.

Truths: the simulator's ground-truth labels and analytic normals, scikit-image's adapted Rand
error on identical labels, the true extrinsics, hand-written PLY files.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from skimage.metrics import adapted_rand_error as sk_adapted_rand_error

from autoteach import geometry, segment
from autoteach.cli import main
from autoteach.errors import InvalidInputError

FLOOR, WALL, GREY_BIN, BLUE_BIN = 1, 2, 6, 7


@pytest.fixture(scope="module")
def hallway() -> segment.SimulatedScan:
    return segment.simulate_scan("hallway", seed=3)


@pytest.fixture(scope="module")
def hallway_both(hallway: segment.SimulatedScan) -> np.ndarray:
    """Labels of the hallway with both criteria (Table 4.1, Fig. 4.4e), shared by the Fig. 4.4 tests."""
    points, colors = hallway.cloud()
    return segment.segment_colored_cloud(points, colors, k_rgb=9000, k_norm=10, min_size=100)


def _majority(labels: np.ndarray, truth: np.ndarray, obj: int) -> int:
    sel = labels[(truth == obj) & (labels >= 0)]
    values, counts = np.unique(sel, return_counts=True)
    return int(values[np.argmax(counts)])


def _are(truth: np.ndarray, labels: np.ndarray) -> float:
    keep = (truth >= 0) & (labels >= 0)
    err, _, _ = sk_adapted_rand_error(truth[keep] + 1, labels[keep] + 1, ignore_labels=())
    return float(err)


@pytest.mark.xfail(
    reason="open (issue 34, docs/design/segmentation.md 'The unsorted threshold'): both criteria merge the grey "
    "bin with the floor (majority segments 4 and 4); the seed's literal eq. 4.3 for the normal weight does not "
    "separate them on this scan either",
    strict=True,
)
def test_fig_4_4_colour_alone_and_both_criteria(hallway, hallway_both):
    points, colors = hallway.cloud()
    truth = hallway.labels
    color = segment.segment_colored_cloud(points, colors, criteria="color", k_rgb=1000, min_size=100)
    both = hallway_both
    # Fig. 4.4c: colour alone merges the grey bin with the grey floor, keeps the blue bin apart.
    assert _majority(color, truth, GREY_BIN) == _majority(color, truth, FLOOR)
    assert _majority(color, truth, BLUE_BIN) != _majority(color, truth, WALL)
    # Fig. 4.4e: both together separate both pairs, and the segmentation matches the truth.
    assert _majority(both, truth, GREY_BIN) != _majority(both, truth, FLOOR)
    assert _majority(both, truth, BLUE_BIN) != _majority(both, truth, WALL)
    assert _are(truth, both) <= 0.1
    assert _are(truth, both) < _are(truth, color)


@pytest.mark.xfail(
    reason="scene property (issue 34, docs/design/segmentation.md): the simulated blue bin is a sharp-edged "
    "box 16 cm deep whose outline normals form a crease; normals alone keep it apart from the wall "
    "(majority segments 4 vs 1 at K_norm 9; still apart at 20, 50, 100)",
    strict=True,
)
def test_fig_4_4_normals_alone_merge_the_blue_bin_with_the_wall(hallway, hallway_both):
    points, colors = hallway.cloud()
    truth = hallway.labels
    normal = segment.segment_colored_cloud(points, colors, criteria="normal", k_norm=9, min_size=100)
    both = hallway_both
    # Fig. 4.4d: normals alone separate the grey bin from the floor and merge the blue bin with the wall.
    assert _majority(normal, truth, GREY_BIN) != _majority(normal, truth, FLOOR)
    assert _majority(normal, truth, BLUE_BIN) == _majority(normal, truth, WALL)
    assert _are(truth, both) < _are(truth, normal)


@pytest.mark.parametrize(
    "scene",
    [
        "ramp",
        pytest.param(
            "hill",
            marks=pytest.mark.xfail(
                reason="scene property (issue 34, docs/design/segmentation.md): adapted Rand error 0.485 > 0.1; colour "
                "splits the sunlit from the shaded ground (R 202-209 vs 34-40, 32 % of it in shade), which alone "
                "costs 0.276 against the one-label ground truth",
                strict=True,
            ),
        ),
    ],
)
def test_other_scenes_match_ground_truth(scene):
    sim = segment.simulate_scan(scene, seed=1)
    points, colors = sim.cloud()
    labels = segment.segment_colored_cloud(points, colors)
    assert _are(sim.labels, labels) <= 0.1


def test_adapted_rand_error_matches_scikit_image():
    rng = np.random.default_rng(0)
    truth = rng.integers(0, 5, 2000)
    labels = np.where(rng.random(2000) < 0.8, truth, rng.integers(0, 7, 2000))
    ours = segment.adapted_rand_error(truth, labels, ignore=())
    theirs = sk_adapted_rand_error(truth + 1, labels + 1, ignore_labels=())[0]
    assert ours == pytest.approx(theirs, abs=1e-12)


def test_colorize_recovers_the_true_colours(hallway):
    # Through the distorted camera, co-registered points take the colour of their own surface.
    ok = hallway.colored
    assert ok.sum() > 5000
    diff = np.abs(hallway.colors[ok].astype(int) - hallway.true_colors[ok].astype(int)).max(axis=1)
    assert np.mean(diff <= 30) > 0.97
    # Points behind the scanner are never coloured.
    behind = hallway.points[..., 0] < 0
    assert not np.any(ok & behind)


def test_colorize_marks_occluded_points():
    cam = geometry.Camera("pinhole", [100.0, 100.0, 50.0, 50.0], 101, 101)
    img = np.zeros((101, 101, 3), np.uint8)
    img[50, 50] = (10, 20, 30)
    pts = np.array([[0, 0, 1.0], [0, 0, 3.0], [0, 0, -1.0], [5, 0, 1.0], [np.nan, 0, 1]])
    out = segment.colorize(pts, img, cam, np.eye(4))
    assert [segment.STATUS[s] for s in out.status] == ["colored", "occluded", "behind", "outside", "missing"]
    assert out.colors[0].tolist() == [10, 20, 30]


def test_extrinsics_within_three_sigma_of_truth(hallway):
    # "Within 3 sigma" in 6-D: the truth lies in the fit's 99.73 % region (NEES < chi2_6 quantile
    # 20.06), judged over 200 trials, since one trial's six per-axis 3-sigma checks fail 1.6 % of
    # the time when the covariance is exact. An inconsistent covariance fails: a left-perturbation
    # delta against this right-perturbation covariance gives a mean NEES of 46, one 2x too small 13.
    truth = hallway.T_cam_lidar
    sel = np.flatnonzero(hallway.colored.ravel())
    nees, z = [], []
    for trial in range(200):
        rng = np.random.default_rng(100 + trial)
        idx = rng.choice(sel, 30, replace=False)
        pts = hallway.true_points.reshape(-1, 3)[idx]
        cam_pts = pts @ truth[:3, :3].T + truth[:3, 3]
        pix = hallway.camera.project(cam_pts) + rng.normal(0.0, 0.5, (30, 2))
        start = truth @ geometry.se3_exp(np.r_[rng.normal(0, 0.03, 3), rng.normal(0, 0.05, 3)])
        fit = segment.calibrate_extrinsics(hallway.camera, pts, pix, start, sigma=0.5)
        assert fit.converged
        delta = geometry.se3_minus(truth, fit.t_cam_lidar)
        nees.append(delta @ np.linalg.solve(fit.covariance, delta))
        z.append(np.abs(delta) / fit.std)
    nees, z = np.array(nees), np.array(z)
    # Binomial(200, 0.0027): more than 3 beyond the 3-sigma region has probability 0.2 %.
    assert np.sum(nees > 20.06) <= 3
    # E[NEES] = 6 with sampling sd sqrt(12 / 200) = 0.245: four sd either side.
    assert 6 - 4 * 0.245 < nees.mean() < 6 + 4 * 0.245
    assert np.mean(z > 3) < 0.01  # per axis, 0.27 % expected
    # Without sigma the noise is estimated from the residuals.
    fit = segment.calibrate_extrinsics(hallway.camera, pts, pix, start)
    assert 0.3 < fit.sigma < 0.8


def test_normals_match_analytic_planes():
    sim = segment.simulate_scan("ramp", range_sigma=0.0, render=False)
    res = segment.segment_cloud(sim.points, sim.true_colors)
    floor = sim.labels == FLOOR
    cos = np.sum(res.normals[floor] * sim.true_normals[floor], axis=1)
    # Interior floor points are exact; points on the floor's edges mix in the walls / ramp.
    assert np.median(cos) > 1 - 1e-9
    assert np.mean(cos > np.cos(np.radians(1.0))) > 0.9
    noisy = segment.simulate_scan("ramp", seed=2, render=False)
    res = segment.segment_cloud(noisy.points, noisy.true_colors)
    floor = noisy.labels == FLOOR
    cos = np.sum(res.normals[floor] * noisy.true_normals[floor], axis=1)
    assert np.median(np.degrees(np.arccos(np.clip(cos, -1, 1)))) < 15.0


def test_knn_graph_and_determinism(hallway):
    points, colors = hallway.cloud()
    keep = ~np.isnan(points).any(axis=-1)
    pts, cols = points[keep], colors[keep]
    a = segment.segment_colored_cloud(pts, cols, graph="knn")
    b = segment.segment_colored_cloud(pts, cols, graph="knn")
    np.testing.assert_array_equal(a, b)
    assert _are(hallway.labels[keep], a) <= 0.15
    again = segment.simulate_scan("hallway", seed=3)
    np.testing.assert_array_equal(again.points, hallway.points)
    np.testing.assert_array_equal(again.colors, hallway.colors)


def test_duplicate_points_share_their_segment(hallway):
    points, colors = hallway.cloud()
    keep = ~np.isnan(points).any(axis=-1)
    pts, cols = points[keep], colors[keep]
    labels = segment.segment_colored_cloud(np.vstack([pts, pts]), np.vstack([cols, cols]), graph="knn", k=9)
    np.testing.assert_array_equal(labels[: len(pts)], labels[len(pts) :])


def test_bad_input_is_rejected_clearly(hallway):
    points, colors = hallway.cloud()
    keep = ~np.isnan(points).any(axis=-1)
    pts, cols = points[keep], colors[keep]
    bad = pts.copy()
    bad[5, 1] = np.nan
    with pytest.raises(InvalidInputError, match="points must be finite, got NaN at index 5"):
        segment.segment_colored_cloud(bad, cols, graph="knn")
    with pytest.raises(InvalidInputError, match="too few points"):
        segment.segment_colored_cloud(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), graph="knn")
    with pytest.raises(InvalidInputError, match=r"float colors must lie in \[0, 1\]"):
        segment.segment_colored_cloud(pts, cols.astype(float), graph="knn")
    with pytest.raises(InvalidInputError, match="outside 0-255"):
        segment.segment_colored_cloud(pts, cols.astype(np.int16) * 2, graph="knn")
    with pytest.raises(InvalidInputError, match="dtype bool"):
        segment.segment_colored_cloud(pts, cols > 100, graph="knn")
    with pytest.raises(InvalidInputError, match="colors must have shape"):
        segment.segment_colored_cloud(pts, cols[:-1], graph="knn")
    with pytest.raises(InvalidInputError, match="graph='scan' needs an organised cloud"):
        segment.segment_colored_cloud(pts, cols, graph="scan")
    with pytest.raises(InvalidInputError, match="edge_cut"):
        segment.segment_colored_cloud(points, colors, edge_cut=0.0)
    inf = points.copy()
    inf[0, 0, 0] = np.inf
    with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
        segment.segment_colored_cloud(inf, colors)
    # Floats in [0, 1] are scaled, not rejected: the same labels as the uint8 colours.
    np.testing.assert_array_equal(
        segment.segment_colored_cloud(points, colors / 255.0), segment.segment_colored_cloud(points, colors)
    )


def test_ply_round_trip_and_a_hand_written_file(tmp_path):
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(50, 3))
    cols = rng.integers(0, 256, (50, 3)).astype(np.uint8)
    labels = rng.integers(-1, 9, 50)
    for binary in (True, False):
        path = tmp_path / f"c{int(binary)}.ply"
        segment.write_ply(
            path, pts, cols, normals=pts / np.linalg.norm(pts, axis=1, keepdims=True), labels=labels, binary=binary
        )
        cloud = segment.read_ply(path)
        np.testing.assert_array_equal(cloud.points, pts)
        np.testing.assert_array_equal(cloud.colors, cols)
        np.testing.assert_array_equal(cloud.labels, labels)
    hand = tmp_path / "hand.ply"
    hand.write_text(
        "ply\nformat ascii 1.0\ncomment x\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "1 2 3 255 0 10\n-1.5 0 2 0 128 0\n3 0 1 1\n"
    )
    cloud = segment.read_ply(hand)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [-1.5, 0, 2]])
    np.testing.assert_array_equal(cloud.colors, [[255, 0, 10], [0, 128, 0]])
    big = tmp_path / "big.ply"
    header = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty double y\n"
    big.write_bytes(header + b"property double z\nend_header\n" + np.array([1.0, 2.0, 3.0], ">f8").tobytes())
    np.testing.assert_array_equal(segment.read_ply(big).points, [[1, 2, 3]])
    (tmp_path / "bad.ply").write_text("not a ply")
    with pytest.raises(InvalidInputError, match="not a PLY file"):
        segment.read_ply(tmp_path / "bad.ply")


def test_cli_segment_simulate_writes_ply_and_png(tmp_path, capsys):
    out, png = tmp_path / "seg.ply", tmp_path / "seg.png"
    assert main(["segment", "--simulate", "--seed", "3", "--out", str(out), "--png", str(png), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["adapted_rand_error"] <= 0.1
    cloud = segment.read_ply(out)
    assert len(cloud.points) == summary["points"] and cloud.labels is not None
    assert png.stat().st_size > 10_000
    assert main(["segment", str(out), "--out", str(tmp_path / "again.ply"), "--json"]) == 0
    assert main(["segment"]) == 2
