"""Rerun recordings of a run (``autoteach.viewer``, ``autoteach demo/run --rerun``).

The ``.rrd`` file is read back with Rerun's own reader (``rerun.chunk.RrdReader``) and compared
with what was recorded: the session's images, the result's edge points, camera poses and wafers.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from autoteach.cli import main
from autoteach.errors import InvalidInputError, MissingExtraError
from autoteach.io import write_log
from autoteach.pipeline import JOINTS, autoteach
from autoteach.sim import simulate_session

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from autoteach.viewer import log_autoteach, recorded_entities  # noqa: E402


@pytest.fixture(scope="module")
def run():
    session = simulate_session(seed=3, frames=6)
    return session, autoteach(session, frontend="simulated", window=3)


def _rows(path, entity, column, timeline="frame"):
    out = []
    for c in RrdReader(path).stream():
        if c.entity_path == entity:
            b = c.to_record_batch()
            if column in b.schema.names:
                frames = b.column(timeline).to_pylist() if timeline in b.schema.names else [None] * b.num_rows
                out += list(zip(frames, b.column(column).to_pylist(), strict=True))
    return sorted(out, key=lambda r: -1 if r[0] is None else r[0])


def test_the_recording_holds_images_rims_poses_and_wafers(run, tmp_path):
    session, result = run
    path = log_autoteach(result, session, tmp_path / "run.rrd")
    entities = recorded_entities(path)
    for e in ("/camera/image", "/camera/image/rims", "/camera/image/tracks", "/world/camera",
              "/world/wafers/rims", "/world/wafers/centre_3sigma", "/world/trajectory/calibrated",
              "/world/trajectory/fused", "/world/trajectory/encoders", "/calibration/joint2"):  # fmt: skip
        assert e in entities, (e, sorted(entities))
    images = _rows(path, "/camera/image", "Image:buffer")
    assert [f for f, _ in images] == list(range(session.n_frames))
    for f, buf in images:
        assert np.array_equal(np.asarray(buf[0], dtype=np.uint8), session.images[f].ravel())
    obs = result.observations
    strips = _rows(path, "/camera/image/rims", "LineStrips2D:strips")
    assert sorted({f for f, _ in strips}) == sorted({int(f) for f in obs["frames"]})
    n_points = sum(len(s) for _, row in strips for s in row)
    assert n_points == len(obs["points"])
    ids = _rows(path, "/camera/image/rims", "LineStrips2D:class_ids")
    assert sorted(i for _, row in ids for i in row) == sorted(int(w) for w in obs["wafers"])
    trans = _rows(path, "/world/camera", "Transform3D:translation")
    got = np.array([row[0] for _, row in trans])
    assert np.allclose(got, result.camera_poses[:, :3, 3], atol=1e-6)  # stored as float32
    centres = np.array(_rows(path, "/world/wafers/centre_3sigma", "Ellipsoids3D:centers")[0][1])
    want = result.wafer_poses[np.isfinite(result.wafer_poses).all(axis=(1, 2)), :3, 3]
    assert np.allclose(centres, want, atol=1e-6)
    half = np.array(_rows(path, "/world/wafers/centre_3sigma", "Ellipsoids3D:half_sizes")[0][1])
    seen = np.isfinite(result.wafer_poses).all(axis=(1, 2))
    assert np.allclose(half, np.maximum(np.nan_to_num(3 * result.wafer_std[seen, :3]), 1e-6), rtol=1e-6)


def test_cli_run_and_demo_write_recordings(run, tmp_path, capsys):
    session, _ = run
    log = write_log(session, tmp_path / "s.mcap")
    rrd = tmp_path / "out.rrd"
    assert main(["run", str(log), "--frontend", "simulated", "--window", "3", "--rerun", str(rrd), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["rerun"] == str(rrd)
    assert "/camera/image/rims" in recorded_entities(rrd)
    assert main(["demo", "--frames", "6", "--seed", "3", "--frontend", "simulated", "--no-log", "--out",
                 str(tmp_path / "rep"), "--rerun", "--json", "-q"]) == 0  # fmt: skip
    d = json.loads(capsys.readouterr().out)
    assert d["rerun"] == str(tmp_path / "rep" / "session_seed3.rrd")
    assert "/world/wafers/rims" in recorded_entities(d["rerun"])


def test_bad_targets_and_missing_extra(run, tmp_path, monkeypatch, capsys):
    session, result = run
    with pytest.raises(InvalidInputError, match=r"\.rrd"):
        log_autoteach(result, session, tmp_path / "x.png")
    with pytest.raises(InvalidInputError, match="does not exist"):
        log_autoteach(result, session, tmp_path / "nope" / "x.rrd")
    with pytest.raises(InvalidInputError, match="image_every"):
        log_autoteach(result, session, tmp_path / "x.rrd", image_every=0)
    with pytest.raises(InvalidInputError, match="5 frames"):
        log_autoteach(result, simulate_session(seed=3, frames=5, render=False), tmp_path / "x.rrd")
    import sys

    monkeypatch.setitem(sys.modules, "rerun", None)
    with pytest.raises(MissingExtraError, match=r"autoteach\[viewer\]"):
        log_autoteach(result, session, tmp_path / "x.rrd")
    log = write_log(session, tmp_path / "s.mcap")
    assert main(["run", str(log), "--rerun", str(tmp_path / "y.rrd"), "-q"]) == 2
    assert "pip install 'autoteach[viewer]'" in capsys.readouterr().err


def test_segment_rerun_holds_the_segmented_points(tmp_path, capsys):
    from autoteach.segment import read_ply

    out = tmp_path / "seg.ply"
    assert main(["segment", "--simulate", "--out", str(out), "--rerun", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["rerun"] == str(tmp_path / "seg.rrd")
    cloud = read_ply(out)
    pos = np.array(_rows(d["rerun"], "/world/segments", "Points3D:positions")[0][1])
    ids = np.array(_rows(d["rerun"], "/world/segments", "Points3D:class_ids")[0][1])
    assert np.allclose(pos, cloud.points, atol=1e-5)
    assert np.array_equal(ids, cloud.labels)
    assert "/world/cloud" in recorded_entities(d["rerun"])


def test_plan_rerun_holds_the_robot_motion(tmp_path):
    from autoteach import plan
    from autoteach.viewer import log_plan

    ws, poses = plan.default_scene()
    p = plan.plan_path(ws, poses["home"], poses["carrier_a"], method="rrt*", margin=0.02)
    r = plan.optimize_trajectory(ws, p.path, plan.Limits())
    rrd = log_plan([{"name": "traj01", "_result": r}], ws, tmp_path / "plan.rrd", samples=30)
    entities = recorded_entities(rrd)
    assert "/plan/traj01/robot" in entities and "/plan/traj01/swept/blade1" in entities
    robot = _rows_by_time(rrd, "/plan/traj01/robot", "Points3D:positions")
    assert len(robot) == 30
    joints = [_rows_by_time(rrd, f"/plan/traj01/joints/{j}", "Scalars:scalars") for j in JOINTS]
    q_end = np.array([rows[-1][1][0] for rows in joints])
    assert np.allclose(q_end, r.trajectory.sample(np.array([r.duration]))[0][0], atol=1e-9)
    want = np.array([c for _, c in ws.link_centres(q_end)])
    assert np.allclose(np.array(robot[-1][1]), want, atol=1e-5)  # positions stored as float32
    assert joints[0][-1][0] == pytest.approx(r.duration * 1e9, rel=1e-9)  # the duration timeline, in ns
    with pytest.raises(InvalidInputError, match="samples"):
        log_plan([], ws, tmp_path / "x.rrd", samples=1)


def _rows_by_time(path, entity, column):
    out = []
    for c in RrdReader(path).stream():
        if c.entity_path == entity:
            b = c.to_record_batch()
            if column in b.schema.names:
                out += list(zip(b.column("time").cast("int64").to_pylist(), b.column(column).to_pylist(), strict=True))
    return sorted(out, key=lambda r: r[0])


def test_map_rerun_records_the_grid_growing(tmp_path, capsys):
    from autoteach.mapping import OccupancyGrid

    argv = ["map", "--simulate", "--world", "small", "--graphs", "2", "--out", str(tmp_path), "--rerun", "--json", "-q"]
    assert main(argv) == 0
    d = json.loads(capsys.readouterr().out)
    rrd = d["files"]["rerun"]
    assert rrd == str(tmp_path / "map.rrd")
    grids = _rows(rrd, "/map/grid", "Image:buffer", "graph")
    assert [f for f, _ in grids] == [0, 1]
    final = OccupancyGrid.load(d["files"]["yaml"]).to_image()
    assert np.array_equal(np.asarray(grids[-1][1][0], dtype=np.uint8), final.ravel())
    nodes = _rows(rrd, "/map/grid/nodes", "Points2D:positions", "graph")
    assert len(nodes[-1][1]) == d["final_nodes"]
