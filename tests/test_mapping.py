"""Tests of autoteach.mapping (seed 004_815695db12a6b16c.txt ch. 2) against independent truths.

An independent dense-sampling rasterizer for single scans, NaiveComposite as the reference of
CoverComposite, OpenCV as the reader of the exported PGM/PNG, ground-truth walls and transients.
"""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from autoteach.cli import main
from autoteach.errors import InvalidInputError
from autoteach.mapping import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    OccupancyGrid,
    Rasterizer,
    TeamSimulator,
    differing_cells,
    rasterize_stream,
    wall_gaps,
)


@pytest.fixture(scope="module")
def small_stream():
    sim = TeamSimulator("small", seed=3)
    graphs = list(sim)
    return sim, graphs


def dense_reference(pose, ranges, angles, max_range, res):
    """Per-node ternary grid by dense sampling of every beam (independent of the cell walk)."""
    x, y, th = pose
    occ, free = set(), set()
    ends = []
    for r, a in zip(ranges, angles, strict=True):
        if np.isnan(r):
            continue
        hit = r < max_range
        rr = r if hit else max_range
        ex, ey = x + rr * math.cos(th + a), y + rr * math.sin(th + a)
        end = (math.floor(ex / res), math.floor(ey / res))
        ends.append((end, hit))
        n = int(rr / res * 40) + 2
        for k in range(n):
            t = k / n
            c = (math.floor((x + t * (ex - x)) / res), math.floor((y + t * (ey - y)) / res))
            if c != end:
                free.add(c)
        if hit:
            occ.add(end)
        else:
            free.add(end)
    return occ, free - occ


def test_single_scan_matches_dense_sampling():
    rng = np.random.default_rng(0)
    beams, fov, max_range, res = 181, math.radians(270), 8.0, 0.1
    angles = -fov / 2 + np.arange(beams) * fov / (beams - 1)
    ranges = rng.uniform(0.5, 10.0, beams)
    ranges[::17] = np.inf
    ranges[5] = np.nan
    # A pose on the quantisation lattice (res / 2 and res / (2 max_range)), so both see the same pose.
    pose = (1.25, -0.35, 0.3 // (res / (2 * max_range)) * (res / (2 * max_range)))
    r = Rasterizer("naive_composite", resolution=res, fov=fov, beams=beams, max_range=max_range)
    grid = r.update([7], [0], [pose], ranges[None, :])
    assert r.last_report.dropped_beams == 1
    occ, free = dense_reference(pose, ranges, angles, max_range, res)
    ox, oy = round(grid.origin[0] / res), round(grid.origin[1] / res)
    got_occ = {(c + ox, rr + oy) for rr, c in zip(*np.nonzero(grid.cells == OCCUPIED), strict=True)}
    got_free = {(c + ox, rr + oy) for rr, c in zip(*np.nonzero(grid.cells == FREE), strict=True)}
    assert got_occ == occ
    # Dense sampling can miss a cell the beam only clips at a corner: allow a handful.
    assert len(got_free ^ free) <= 0.002 * len(free), (len(got_free - free), len(free - got_free))


def test_cover_composite_without_coverings_equals_naive(small_stream):
    sim, graphs = small_stream
    naive = sim.rasterizer("naive_composite")
    cover = sim.rasterizer("cover_composite", 4, covering=False)
    reused = 0
    for g in graphs:
        scans = g.scans_by_row()
        a = naive.update(g.node_ids, g.robot_ids, g.poses, scans)
        b = cover.update(g.node_ids, g.robot_ids, g.poses, scans)
        assert a.origin == b.origin and np.array_equal(a.cells, b.cells), g.index
        rep = cover.last_report
        reused += rep.slices - rep.slices_regenerated
        assert rep.nodes_composited == len(g.node_ids)
    assert reused > 0


def test_coverings_and_transients(small_stream):
    sim, graphs = small_stream
    res = rasterize_stream(
        sim_replay(graphs),
        {
            "naive": sim.rasterizer("naive_composite"),
            "cover": sim.rasterizer("cover_composite", 4),
        },
    )
    naive, cover = res.maps["naive"], res.maps["cover"]
    assert res.reports["cover"][-1].cover_nodes < res.reports["cover"][-1].nodes
    differ, total = differing_cells(naive, cover)
    assert differ <= 1e-3 * total, (differ, total)
    gaps = wall_gaps(cover, naive, sim.walls)
    assert gaps["samples"] > 1000 and gaps["gaps"] == 0, gaps
    t = sim.transient_residue(cover, graphs[-1])
    assert t["cells"] > 30 and t["structure"] <= 0.01 * t["cells"], t


class sim_replay:  # noqa: N801 - a tiny stand-in with the TeamSimulator iteration protocol
    def __init__(self, graphs):
        self._graphs = graphs
        self.graphs = len(graphs)

    def __iter__(self):
        return iter(self._graphs)


def test_snapshots_are_pose_graphs_with_truth(small_stream):
    _, graphs = small_stream
    g = graphs[-1]
    n = len(g.node_ids)
    assert g.poses.shape == (n, 3) and g.truth.shape == (n, 3)
    assert g.edge_cov.shape == (len(g.edges), 3, 3)
    assert set(np.unique(g.edge_kinds)) == {0, 1, 2}
    assert np.all(np.linalg.eigvalsh(g.edge_cov) > 0)
    err = np.hypot(*(g.poses[:, :2] - g.truth[:, :2]).T)
    assert err.mean() < 0.5, err.mean()
    assert sum(x.new_nodes for x in graphs) == n
    assert graphs[1].time - graphs[0].time == pytest.approx(10.0)


def test_pgm_yaml_round_trip_and_png(tmp_path, small_stream):
    sim, graphs = small_stream
    r = sim.rasterizer("cover_composite", 4, resolution=0.2)
    for g in graphs[:4]:
        grid = r.update(g.node_ids, g.robot_ids, g.poses, g.scans_by_row())
    counts = grid.counts()
    assert min(counts.values()) > 0
    pgm, yaml = grid.save(tmp_path / "map")
    back = OccupancyGrid.load(yaml)
    assert np.array_equal(back.cells, grid.cells)
    assert back.resolution == grid.resolution and back.origin == pytest.approx(grid.origin)
    # OpenCV reads both files: top image row = highest y; map_saver grey levels.
    img = cv2.imread(str(pgm), cv2.IMREAD_UNCHANGED)
    png = cv2.imread(str(grid.to_png(tmp_path / "map.png")), cv2.IMREAD_UNCHANGED)
    want = np.select([grid.cells == FREE, grid.cells == OCCUPIED], [254, 0], 205)[::-1]
    assert np.array_equal(img, want) and np.array_equal(png, want)
    text = yaml.read_text()
    assert "mode: trinary" in text and "image: map.pgm" in text


def test_bad_input_is_rejected_without_corrupting_state():
    r = Rasterizer("cover_composite", beams=5, fov=math.radians(40), max_range=10.0)
    scan = np.full(5, 3.0)
    with pytest.raises(InvalidInputError, match="no nodes"):
        r.update([], [], np.zeros((0, 3)), np.zeros((0, 5)))
    with pytest.raises(InvalidInputError, match="non-finite"):
        r.update([0], [0], [[np.nan, 0, 0]], scan[None])
    with pytest.raises(InvalidInputError, match="twice"):
        r.update([0, 0], [0, 0], np.zeros((2, 3)), np.stack([scan, scan]))
    with pytest.raises(InvalidInputError, match="negative"):
        r.update([0], [0], np.zeros((1, 3)), [[-1.0, 2, 2, 2, 2]])
    with pytest.raises(InvalidInputError, match="shape"):
        r.update([0], [0], np.zeros((1, 2)), scan[None])
    with pytest.raises(InvalidInputError, match="no scan"):
        r.update([0], [0], np.zeros((1, 3)), [None])
    assert r.num_nodes == 0
    # inf = no return (free to max range), NaN = dropped beam: data, not errors.
    grid = r.update([0], [0], np.zeros((1, 3)), [[np.inf, np.nan, 3.0, 3.0, np.inf]])
    assert r.last_report.dropped_beams == 1
    assert grid.at(3.02, 0.02) == OCCUPIED
    assert grid.at(9.9 * math.cos(math.radians(20)), -9.9 * math.sin(math.radians(20))) == FREE
    assert grid.at(0.05, 5.0) in (None, UNKNOWN)
    with pytest.raises(InvalidInputError, match="missing"):
        r.update([1], [0], np.zeros((1, 3)), scan[None])
    with pytest.raises(InvalidInputError, match="robot"):
        r.update([0], [3], np.zeros((1, 3)), [None])
    # Scans of known nodes may be omitted (a mapping holding only the new ones).
    g2 = r.update([0, 1], [0, 0], [[0, 0, 0], [0.5, 0, 0]], {1: scan})
    assert r.last_report.new_nodes == 1 and g2.cells.size >= grid.cells.size
    with pytest.raises(InvalidInputError, match="method"):
        Rasterizer("octomap")
    with pytest.raises(InvalidInputError):
        Rasterizer(resolution=-1.0)
    with pytest.raises(InvalidInputError, match="world"):
        TeamSimulator("mars")


def test_cli_map_simulate(tmp_path):
    code = main(
        ["map", "--simulate", "--world", "small", "--graphs", "3", "--robots", "2", "--out", str(tmp_path), "--json"]
    )
    assert code == 0
    for name in ("map.pgm", "map.yaml", "map.png", "runtime.png"):
        assert (tmp_path / name).stat().st_size > 0
    back = OccupancyGrid.load(tmp_path / "map.yaml")
    assert back.counts()["occupied"] > 0


def test_cli_map_json(tmp_path, capsys):
    assert main(["map", "--simulate", "--world", "small", "--graphs", "2", "--out", str(tmp_path), "--json", "-q"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["graphs"] == 2 and "cover_composite(4)" in out["methods"]
