"""Auto-teaching results written back into an MCAP log (``write_results`` / ``read_results``).

The copy must keep every input message bit-exactly (checked with the MCAP reader on both files)
and add the ``/autoteach/*`` channels, which read back equal to the result.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from autoteach.cli import main
from autoteach.errors import InvalidInputError, LogReadError
from autoteach.io import RESULT_TOPICS, read_log, read_results, write_log, write_results
from autoteach.pipeline import autoteach
from autoteach.sim import simulate_session


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    session = simulate_session(seed=3, frames=30, render=False)
    path = tmp_path_factory.mktemp("wb") / "in.mcap"
    write_log(session, path)
    result = autoteach(read_log(path), frontend="simulated", seed=3, window=5)
    return path, result


def _messages(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [
            (c.topic, s.name if s else None, m.log_time, m.publish_time, m.sequence, m.data)
            for s, c, m in make_reader(f).iter_messages(log_time_order=False)
        ]


def test_copy_keeps_every_input_message_and_adds_the_result_channels(logged, tmp_path):
    path, result = logged
    out = write_results(result, path, tmp_path / "out.mcap")
    before = _messages(path)
    after = _messages(out)
    kept = [m for m in after if m[0] not in RESULT_TOPICS]
    assert sorted(kept, key=lambda m: (m[0], m[2], m[4])) == sorted(before, key=lambda m: (m[0], m[2], m[4]))
    topics = {m[0] for m in after}
    assert set(RESULT_TOPICS) <= topics
    s_in, s_out = read_log(path), read_log(out)
    assert np.array_equal(s_in.images, s_out.images)
    assert np.array_equal(s_in.joints_encoder, s_out.joints_encoder)


def test_results_read_back_equal(logged, tmp_path):
    path, result = logged
    back = read_results(write_results(result, path, tmp_path / "out.mcap"))
    cal = back["calibration"]
    assert np.array_equal(cal["base_pose"], result.base_pose)
    assert np.array_equal(cal["joint_offsets"], result.joint_offsets, equal_nan=True)
    assert np.array_equal(cal["joint_offsets_std"], result.joint_offsets_std, equal_nan=True)
    assert np.array_equal(cal["covariance"], result.covariance)
    assert cal["errors"] == pytest.approx(result.errors)
    assert np.array_equal(back["wafers"]["params"], result.wafer_params, equal_nan=True)
    assert back["wafers"]["slots"] == [int(s) for s in result.wafer_slots]
    assert np.array_equal(back["camera_poses"], result.camera_poses)
    assert len(back["ukf"]) == len(result.ukf["poses"])
    assert np.array_equal(back["ukf"][-1]["offsets"], result.ukf["offsets"][-1])
    assert len(back["history"]) == len(result.history) == 6
    n_edges = sum(len(f["edges"]) for f in back["edges"])
    assert n_edges == result.n_observations
    first = back["edges"][0]["edges"][0]["points"]
    assert np.array_equal(first, result.observations["points"][: len(first)])


def test_write_back_replaces_previous_results(logged, tmp_path):
    path, result = logged
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(path.read_bytes())
    write_results(result, copy)
    write_results(result, copy)
    counts = {}
    for m in _messages(copy):
        counts[m[0]] = counts.get(m[0], 0) + 1
    assert counts["/autoteach/calibration"] == 1
    assert counts["/autoteach/camera_pose"] == 30
    assert counts["/camera/image"] == 30


def test_bad_inputs_are_clear_errors(logged, tmp_path):
    path, result = logged
    with pytest.raises(LogReadError, match="no auto-teaching result"):
        read_results(path)
    short = simulate_session(seed=3, frames=5, render=False)
    other = write_log(short, tmp_path / "short.mcap")
    with pytest.raises(InvalidInputError, match="30 camera poses"):
        write_results(result, other, tmp_path / "x.mcap")
    with pytest.raises(InvalidInputError, match="compression"):
        write_results(result, path, tmp_path / "y.mcap", compression="gzip")
    assert not (tmp_path / "x.mcap").exists() and not (tmp_path / "x.mcap.part").exists()


def test_cli_run_writes_results(logged, tmp_path, capsys):
    path, _ = logged
    log = tmp_path / "log.mcap"
    log.write_bytes(path.read_bytes())
    out = tmp_path / "res.mcap"
    code = main(["run", str(log), "--frontend", "simulated", "--out", str(out), "--write-back", "--json", "--quiet"])
    assert code == 0
    d = json.loads(capsys.readouterr().out)
    assert d["result_logs"] == [str(out), str(log)]
    assert d["report"] == str(tmp_path / "log-report")
    for p in (out, log):
        back = read_results(p)
        assert back["calibration"]["frontend"] == "simulated"
        assert back["camera_poses"].shape == (30, 4, 4)
