"""Batch auto-teaching of a fleet of logs (``autoteach.fleet``, ``autoteach run LOG...``).

The truth for a batch is the single-log pipeline itself: every result of a batch must equal,
bit for bit, ``autoteach(read_log(log))`` run alone in this process. The drift flag is checked
against the simulator's true offsets of two different robots.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from autoteach.cli import main
from autoteach.errors import InvalidInputError, MissingExtraError
from autoteach.fleet import RESULT_SUFFIX, RunOptions, calibration_moves, process_log, run_batch
from autoteach.io import read_log, read_results, write_log
from autoteach.pipeline import JOINTS, autoteach
from autoteach.sim import simulate_session

FRAMES = 12
SEEDS = (3, 4, 6)
OPTIONS = RunOptions(frontend="simulated")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fleet")
    logs, truth = [], {}
    for s in (*SEEDS[:2], 5, SEEDS[2]):
        session = simulate_session(seed=s, frames=FRAMES, render=False)
        path = write_log(session, folder / f"robot{s}.mcap")
        truth[path.name] = session.calibration
        logs.append(path)
    data = logs[2].read_bytes()
    logs[2].write_bytes(data[: len(data) // 2])  # robot5: truncated in the middle of the batch
    single = {}
    for p in logs:
        if p.name != "robot5.mcap":
            single[p.name] = autoteach(read_log(p), frontend="simulated")
    return folder, logs, single, truth


def _assert_same(outcome, result):
    assert outcome.ok, outcome.reason
    assert np.array_equal(outcome.joint_offsets, result.joint_offsets, equal_nan=True)
    assert np.array_equal(outcome.joint_offsets_std, result.joint_offsets_std, equal_nan=True)
    assert np.array_equal(outcome.base_pose, result.base_pose, equal_nan=True)
    assert np.array_equal(outcome.base_std, result.base_std, equal_nan=True)
    assert np.array_equal(outcome.wafer_poses, result.wafer_poses, equal_nan=True)


def test_two_workers_give_the_single_log_results_and_report_the_truncated_log(fleet, tmp_path):
    _, logs, single, _ = fleet
    report = run_batch(logs, options=OPTIONS, workers=2, out=tmp_path)
    assert [o.robot for o in report.outcomes] == [p.stem for p in logs]
    assert [o.robot for o in report.failed] == ["robot5"]
    assert "truncated" in report.failed[0].reason and "LogReadError" in report.failed[0].reason
    for o in report.outcomes:
        if o.ok:
            _assert_same(o, single[o.robot + ".mcap"])
            saved = read_results(o.result_file)["calibration"]
            assert np.array_equal(saved["joint_offsets"], o.joint_offsets, equal_nan=True)
            assert np.array_equal(saved["base_pose"], o.base_pose)
    summary = json.loads((tmp_path / "fleet.json").read_text())
    assert summary["failed"] == 1 and summary["logs"] == 4 and summary["moved"] == []
    assert not (tmp_path / ("robot5" + RESULT_SUFFIX)).exists()


def test_a_rerun_of_the_same_logs_moves_nothing_and_another_robot_moves(fleet, tmp_path):
    folder, logs, single, truth = fleet
    run_batch([logs[0]], options=OPTIONS, workers=1, out=tmp_path)
    again = run_batch([logs[0]], options=OPTIONS, workers=1, out=tmp_path)
    assert again.outcomes[0].previous is not None and again.outcomes[0].moved == {}
    # robot3's result file now meets robot4's log under robot3's name: a robot re-calibrated.
    other = tmp_path / "in"
    other.mkdir()
    shutil.copy(logs[1], other / "robot3.mcap")
    moved = run_batch([other / "robot3.mcap"], options=OPTIONS, workers=1, out=tmp_path).outcomes[0]
    a, b = single["robot3.mcap"], single["robot4.mcap"]
    sigma = np.hypot(a.joint_offsets_std, b.joint_offsets_std)
    true_jump = np.abs(truth["robot4.mcap"].joint_offsets - truth["robot3.mcap"].joint_offsets)
    for i, name in enumerate(JOINTS):
        if np.isfinite(sigma[i]) and true_jump[i] > 6 * sigma[i]:
            assert name in moved.moved  # a true jump far beyond 3σ is flagged
            assert moved.moved[name] == pytest.approx(abs(b.joint_offsets[i] - a.joint_offsets[i]) / sigma[i])
    assert "joint2" in moved.moved


def test_calibration_moves_thresholds_on_the_difference_sigma(fleet):
    _, logs, _, _ = fleet
    now = process_log(str(logs[0]), OPTIONS)
    prev = {
        "joint_offsets": now.joint_offsets.copy(),
        "joint_offsets_std": now.joint_offsets_std.copy(),
        "base_pose": now.base_pose.copy(),
        "base_std": now.base_std.copy(),
    }
    i = JOINTS.index("joint2")
    s = float(np.hypot(now.joint_offsets_std[i], now.joint_offsets_std[i]))
    prev["joint_offsets"][i] = now.joint_offsets[i] - 2.9 * s
    assert calibration_moves(prev, now) == {}
    prev["joint_offsets"][i] = now.joint_offsets[i] - 3.1 * s
    assert calibration_moves(prev, now) == {"joint2": pytest.approx(3.1)}
    prev["joint_offsets"][i] = now.joint_offsets[i]
    prev["base_pose"][0, 3] -= 4.0 * np.hypot(now.base_std[3], now.base_std[3])
    assert set(calibration_moves(prev, now)) == {"base_x"}


def test_cli_batch_and_bad_inputs(fleet, tmp_path, capsys):
    folder, logs, single, _ = fleet
    out = tmp_path / "out"
    code = main(
        ["run", str(logs[0]), str(logs[2]), "--frontend", "simulated", "--workers", "1", "--out", str(out), "--json"]
    )
    assert code == 3
    d = json.loads(capsys.readouterr().out)
    assert [r["ok"] for r in d["robots"]] == [True, False]
    j2 = d["robots"][0]["joint_offsets"]["joint2"]["value"]
    assert j2 == single["robot3.mcap"].joint_offsets[1]
    assert main(["run", str(logs[2]), "--workers", "1", "--json"]) == 2  # every log failed: a one-line error
    assert capsys.readouterr().err.startswith("autoteach: error: none of the 1 logs could be auto-taught; robot5")
    assert (folder / "autoteach-fleet" / "fleet.json").is_file()  # the default --out: beside the first log
    assert main(["run", str(tmp_path / "nope.mcap"), str(logs[0]), "--quiet"]) == 2
    assert "does not exist" in capsys.readouterr().err
    empty = tmp_path / "notlogs"
    empty.mkdir()
    (empty / "a.txt").write_text("x")
    assert main(["run", str(empty), "--quiet"]) == 2
    assert "holds no .mcap log" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["run", str(logs[0]), "--workers", "0"])
    assert "--workers must be an integer in [1, 1024], got '0'" in capsys.readouterr().err
    notmcap = empty / "junk.mcap"
    notmcap.write_bytes(b"not an mcap file at all")
    r = run_batch([notmcap, logs[0]], options=OPTIONS, workers=1)
    assert not r.outcomes[0].ok and "LogReadError" in r.outcomes[0].reason and r.outcomes[1].ok
    with pytest.raises(InvalidInputError, match="workers"):
        run_batch(logs, workers=0)
    with pytest.raises(InvalidInputError, match="engine"):
        run_batch(logs, engine="dask")
    with pytest.raises(InvalidInputError, match="same robot"):
        run_batch([logs[0], folder / ".." / folder.name / "robot3.mcap"])
    with pytest.raises(InvalidInputError, match="window"):
        RunOptions(window=-1)


def test_ray_engine_gives_the_single_log_results(fleet, tmp_path, monkeypatch):
    ray = pytest.importorskip("ray")
    _, logs, single, _ = fleet
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")  # a local test cluster reports nothing
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        report = run_batch(logs, options=OPTIONS, engine="ray", out=tmp_path)
    finally:
        ray.shutdown()
    assert [o.robot for o in report.failed] == ["robot5"] and "truncated" in report.failed[0].reason
    for o in report.outcomes:
        if o.ok:
            _assert_same(o, single[o.robot + ".mcap"])
            assert read_results(o.result_file)["calibration"]["base_pose"].shape == (4, 4)


def test_ray_engine_without_ray_names_the_extra(fleet, monkeypatch, capsys):
    import sys

    _, logs, _, _ = fleet
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    with pytest.raises(MissingExtraError, match=r"autoteach\[ray\]"):
        run_batch(logs[:1], engine="ray")
    assert main(["run", str(logs[0]), "--engine", "ray", "--quiet"]) == 2
    assert "pip install 'autoteach[ray]'" in capsys.readouterr().err
    with pytest.raises(InvalidInputError, match="engine='ray'"):
        run_batch(logs[:1], address="ray://x:10001")
