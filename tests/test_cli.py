"""Tests of the ``autoteach`` command line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from autoteach.cli import main
from autoteach.io import read_log
from autoteach.sim import simulate_session


def test_simulate_writes_a_readable_log(tmp_path, capsys):
    out = tmp_path / "sub" / "session.mcap"
    assert main(["simulate", "--seed", "7", "--frames", "2", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert str(out) in printed and "2 frames" in printed
    session = read_log(out)
    assert session.n_frames == 2 and session.seed == 7 and session.has_ground_truth
    # the CLI's log holds the same session as the library call
    direct = simulate_session(seed=7, frames=2)
    assert np.array_equal(session.images, direct.images)
    assert np.array_equal(session.joints_encoder, direct.joints_encoder)


def test_simulate_json_and_compression(tmp_path, capsys):
    out = tmp_path / "s.mcap"
    code = main(["simulate", "--seed", "1", "--frames", "1", "--out", str(out), "--compression", "none", "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 1 and summary["log"] == str(out)
    assert summary["log_bytes"] == out.stat().st_size


def test_demo_prints_json(tmp_path, capsys):
    assert main(["demo", "--frames", "2", "--seed", "3", "--out", str(tmp_path), "--json", "--quiet"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 2 and summary["seed"] == 3 and summary["wafers"] == 12
    assert len(summary["calibration"]["joint_offsets_deg"]) == 4
    assert len(summary["visibility"]) == 12
    assert read_log(summary["log"]).n_frames == 2
    assert json.loads((tmp_path / "session_seed3.json").read_text())["frames"] == 2


def test_demo_no_log_writes_no_log_and_a_kept_log_reads_back_bit_exactly(tmp_path, capsys):
    kept, skipped = tmp_path / "kept", tmp_path / "skipped"
    args = ["demo", "--frames", "2", "--seed", "4", "--no-autoteach", "-q"]
    assert main([*args, "--out", str(skipped), "--no-log"]) == 0
    assert "log:" not in capsys.readouterr().out
    assert not list(skipped.glob("*.mcap"))
    assert main([*args, "--out", str(kept), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    again, direct = read_log(summary["log"]), simulate_session(seed=4, frames=2)
    for name in ("images", "joints_encoder", "joints_true", "timestamps", "camera_poses", "wafer_poses"):
        a, b = getattr(again, name), getattr(direct, name)
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name


def test_demo_prints_a_table(tmp_path, capsys):
    assert main(["demo", "--frames", "1", "--out", str(tmp_path), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "true calibration" in text and "joint zero offsets" in text and "slot" in text
    assert "   25" in text  # the row of the wafer in slot 25


def test_info_describes_a_log(tmp_path, capsys):
    out = tmp_path / "s.mcap"
    assert main(["simulate", "--frames", "1", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "/camera/image" in text and "/ground_truth/rims" in text and "sensor_msgs/msg/Image" in text
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 1 and {c["topic"] for c in info["channels"]} >= {"/joint_states", "/session"}


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--frames", "-1", "--out", "x.mcap"],
        ["simulate", "--frames", "many", "--out", "x.mcap"],
        ["simulate", "--seed", "-2", "--out", "x.mcap"],
        ["simulate", "--frames", "2"],  # --out is required
        ["frobnicate"],
        [],
    ],
)
def test_bad_arguments_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "usage: autoteach" in err and "error:" in err


def test_unreadable_log_exits_2_without_traceback(tmp_path, capsys):
    foreign = tmp_path / "foreign.mcap"
    foreign.write_bytes(b"not a log")
    assert main(["info", str(foreign)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("autoteach: error: ") and "not an MCAP file" in err and "Traceback" not in err
    assert main(["info", str(tmp_path / "missing.mcap")]) == 2
    assert "cannot read log" in capsys.readouterr().err


def test_module_entry_point(tmp_path):
    """``python -m autoteach`` runs the same CLI in a fresh interpreter (exit status and stderr)."""
    proc = subprocess.run(
        [sys.executable, "-m", "autoteach", "info", str(tmp_path / "missing.mcap")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "autoteach: error: cannot read log" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "autoteach", "--version"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.startswith("autoteach ")


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--frames", "99999999999999999999", "--out", "x.mcap"],
        ["calibrate", "--simulate", "--seed", "-1"],
        ["active", "--trials", "0"],
    ],
)
def test_bad_arguments_give_one_line_and_status_2(argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "error:" in err
    assert not any(len(token) > 40 for token in err.split())  # no 300-digit numbers echoed


def test_a_file_that_is_not_npz_is_a_one_line_error(capsys, tmp_path):
    bad = tmp_path / "views.npz"
    bad.write_text("not an archive")
    assert main(["calibrate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a readable .npz" in err
