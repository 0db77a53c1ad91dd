"""The ``autoteach`` command line.

Commands::

    autoteach simulate --seed 7 --frames 200 --out session.mcap   # simulate and write a log
    autoteach demo [--seed N] [--frames N] [--out DIR] [--no-log] [--json]  # simulate, auto-teach, report
    autoteach info LOG.mcap [--json]                              # describe a log

User errors (bad arguments, unreadable logs, invalid configurations) print one line to stderr
and exit with status 2; progress bars go to stderr and are off when it is not a terminal or with
``--quiet``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from autoteach.commands.args import int_in_range, seed
from autoteach.errors import AutoteachError, InternalError

EXIT_USER_ERROR = 2


def _progress_enabled(args: argparse.Namespace) -> bool:
    return not args.quiet and sys.stderr.isatty()


#: At most this many frames: a session's images are held in memory (0.9 MB per 1280×720 frame).
MAX_FRAMES = 100_000
_seed = seed
_frames = int_in_range(1, f"frames must be an integer in [1, {MAX_FRAMES}]", MAX_FRAMES)


def _parser() -> argparse.ArgumentParser:
    from autoteach import __version__

    parser = argparse.ArgumentParser(
        prog="autoteach",
        description="Robust perception and self-calibration for camera-carrying robots (hand-eye auto-teaching).",
    )
    parser.add_argument("--version", action="version", version=f"autoteach {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    common.add_argument("--quiet", "-q", action="store_true", help="no progress bars")

    sim = sub.add_parser("simulate", parents=[common], help="simulate a robot session and write it to an MCAP log")
    sim.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    sim.add_argument("--frames", type=_frames, default=200, help="number of frames (default 200)")
    sim.add_argument("--out", type=Path, required=True, help="output MCAP file")
    sim.add_argument(
        "--compression", choices=("zstd", "lz4", "none"), default="zstd", help="chunk compression (default zstd)"
    )

    demo = sub.add_parser(
        "demo", parents=[common], help="simulate a session, write it to the report folder and print a summary"
    )
    demo.add_argument("--seed", type=_seed, default=7, help="random seed (default 7)")
    demo.add_argument("--frames", type=_frames, default=200, help="number of frames (default 200)")
    demo.add_argument(
        "--out", type=Path, default=Path("autoteach-report"), help="report folder (default ./autoteach-report)"
    )
    demo.add_argument(
        "--no-autoteach", dest="autoteach", action="store_false", help="only simulate, do not run auto-teaching"
    )
    demo.add_argument(
        "--no-log",
        dest="log",
        action="store_false",
        help="do not keep the simulated session's MCAP log (about 0.7 MB per frame, 144 MB for 200 frames)",
    )
    demo.add_argument(
        "--frontend",
        choices=("detect", "simulated"),
        default="detect",
        help="edge front end: detection + tracking on the rendered images (default) or the simulator's "
        "ground-truth rims with pixel noise",
    )
    demo.add_argument(
        "--ukf-odometry",
        choices=("slam", "vo"),
        default="slam",
        help="odometry fed to the UKF (eq. 5.1): relative poses of a SLAM with a map, like the seed's "
        "ORB-SLAM2 (default; θ1 is then reported unobservable), or world-frame visual-odometry increments",
    )

    from autoteach.commands.viewer_flag import add_rerun_argument

    add_rerun_argument(demo, "OUT/session_seed<SEED>.rrd")

    info = sub.add_parser("info", parents=[common], help="describe an MCAP session log")
    info.add_argument("log", type=Path, help="the MCAP file")

    import importlib

    from autoteach.commands import MODULES

    for name in MODULES:
        importlib.import_module(name).register(sub, common)
    return parser


def _simulate_and_write(args: argparse.Namespace, out: Path | None) -> tuple[Any, dict[str, Any]]:
    """Simulate a session; write its MCAP log to ``out`` unless ``out`` is None."""
    from autoteach.io import _writable_target, write_log
    from autoteach.sim import simulate_session

    if out is not None:
        _writable_target(out)  # refuse a target that cannot be written before simulating
    progress = _progress_enabled(args)
    session = simulate_session(seed=args.seed, frames=args.frames, progress=progress)
    if out is None:
        return session, session.summary()
    t0 = time.perf_counter()
    compression = getattr(args, "compression", "zstd")
    write_log(session, out, compression=None if compression == "none" else compression, progress=progress)
    session.timings["write_s"] = time.perf_counter() - t0
    summary = session.summary()
    summary["log"] = str(out)
    summary["log_bytes"] = out.stat().st_size
    return session, summary


def _cmd_simulate(args: argparse.Namespace) -> int:
    args.out.parent.mkdir(parents=True, exist_ok=True)
    _, summary = _simulate_and_write(args, args.out)
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"wrote {summary['log']}: {summary['frames']} frames, {summary.get('wafers', 0)} wafers, "
            f"{summary['log_bytes'] / 1e6:.1f} MB in {sum(summary['timings_s'].values()):.1f} s"
        )
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    from autoteach.commands.viewer_flag import rerun_target, write_rerun

    rrd = rerun_target(args, args.out / f"session_seed{args.seed}.rrd")
    out = args.out / f"session_seed{args.seed}.mcap" if args.log else None
    t_start = time.perf_counter()
    session, summary = _simulate_and_write(args, out)
    summary_path = args.out / f"session_seed{args.seed}.json"
    summary_path.write_text(json.dumps(summary, indent=2) + "\n")
    summary["summary_file"] = str(summary_path)
    table = None
    if getattr(args, "autoteach", True):
        from autoteach.pipeline import autoteach
        from autoteach.report import format_table, write_report

        try:
            result = autoteach(
                session,
                seed=args.seed,
                baseline=True,
                frontend=getattr(args, "frontend", "detect"),
                ukf_odometry=getattr(args, "ukf_odometry", "slam"),
                progress=_progress_enabled(args),
            )
        except AutoteachError as exc:
            # Too few frames (or nothing seen) to calibrate: the simulation summary still stands.
            summary["autoteach"] = {"skipped": str(exc)}
        else:
            files = write_report(result, args.out, session)
            d = result.to_dict()
            summary["autoteach"] = d
            summary["errors"] = d["errors"]
            summary["estimates"] = d["estimates"]
            summary["report"] = str(args.out)
            summary["report_files"] = files
            table = format_table(result)
            recording = write_rerun(rrd, result, session)
            if recording is not None:
                summary["rerun"] = recording
    summary["runtime_s"] = time.perf_counter() - t_start
    if args.json:
        print(json.dumps(summary))
    else:
        print(format_summary(summary))
        if table is not None:
            print()
            print(table)
            print(f"report: {args.out}")
            if "rerun" in summary:
                print(f"Rerun recording: {summary['rerun']} (open with: rerun {summary['rerun']})")
        elif "autoteach" in summary:
            print(f"auto-teaching skipped: {summary['autoteach']['skipped']}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from autoteach.io import log_info

    info = log_info(args.log)
    if args.json:
        print(json.dumps(info))
        return 0
    lines = [f"{info['path']}: {info['bytes'] / 1e6:.1f} MB, {info['messages']} messages", "", "channels:"]
    width = max(len(c["topic"]) for c in info["channels"])
    for c in info["channels"]:
        lines.append(f"  {c['topic']:<{width}}  {c['messages']:>6} msgs  {c['schema']} ({c['message_encoding']})")
    lines.append("")
    lines.append(format_summary(info))
    print("\n".join(lines))
    return 0


def format_summary(s: dict[str, Any]) -> str:
    """Format a :meth:`Session.summary` dict as a human-readable table."""
    w, h = s["image_size"]
    rate = s.get("frame_rate_hz")
    lines = [
        f"session: {s['frames']} frames of {w}x{h} over {s['duration_s']:.1f} s"
        + (f" at {rate:g} Hz" if rate else "")
        + (f", seed {s['seed']}" if s.get("seed") is not None else ""),
        f"camera:  {s['camera']['model']} {', '.join(f'{p:g}' for p in s['camera']['params'])}",
    ]
    if "log" in s:
        lines.append(f"log:     {s['log']} ({s['log_bytes'] / 1e6:.1f} MB)")
    if not s.get("ground_truth"):
        lines.append("ground truth: none (a real robot log)")
        return "\n".join(lines)
    cal = s.get("calibration")
    if cal:
        offs = ", ".join(f"{v:+.3f}" for v in cal["joint_offsets_deg"])
        pos = ", ".join(f"{v:+.4f}" for v in cal["base_position_m"])
        rpy = ", ".join(f"{v:+.3f}" for v in cal["base_rpy_deg"])
        lines += [
            "true calibration:",
            f"  joint zero offsets θ1..θ4 [deg]: {offs}; lift offset {cal['lift_offset_m'] * 1e3:+.3f} mm",
            f"  base position [m]: ({pos}); roll, pitch, yaw [deg]: ({rpy})",
        ]
    vis = s.get("visibility", [])
    tilts = s.get("wafer_tilt_deg", [])
    if vis:
        lines += ["wafers:", "  slot  tilt[deg]  frames visible  mean visible fraction upper / lower"]
        for v in vis:
            tilt = tilts[v["wafer"]] if v["wafer"] < len(tilts) else math.nan
            share = v["frames_visible"] / max(s["frames"], 1)
            lines.append(
                f"  {v['slot']:>4}  {tilt:>9.3f}  {v['frames_visible']:>6} ({share:>4.0%})"
                f"   {v['mean_fraction_upper']:.2f} / {v['mean_fraction_lower']:.2f}"
            )
    timings = s.get("timings_s")
    if timings:
        lines.append("timing [s]: " + ", ".join(f"{k.removesuffix('_s')} {v:.2f}" for k, v in timings.items()))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 user error, 1 internal error)."""
    parser = _parser()
    args = parser.parse_args(argv)
    commands = {"simulate": _cmd_simulate, "demo": _cmd_demo, "info": _cmd_info}
    try:
        command = commands.get(args.command) or args.func
        return int(command(args))
    except InternalError as exc:
        print(f"autoteach: internal error (please report): {exc}", file=sys.stderr)
        return 1
    except (AutoteachError, OSError) as exc:
        print(f"autoteach: error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("autoteach: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print("autoteach: error: not enough memory for this request (try fewer frames or points)", file=sys.stderr)
        return EXIT_USER_ERROR
    except Exception as exc:  # noqa: BLE001 - the CLI prints one line, never a traceback
        if os.environ.get("AUTOTEACH_DEBUG"):
            raise
        print(
            f"autoteach: internal error (please report; AUTOTEACH_DEBUG=1 shows the traceback): "
            f"{type(exc).__name__}: {exc}",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
