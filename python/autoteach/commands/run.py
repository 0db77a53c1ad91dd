"""The ``autoteach run LOG.mcap`` command: auto-teaching on a recorded session log."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``run`` sub-command."""
    p = sub.add_parser("run", parents=[common], help="auto-teach from an MCAP session log and write a report")
    p.add_argument(
        "log",
        type=Path,
        nargs="+",
        help="the MCAP file; several files or folders of *.mcap logs: auto-teach a fleet (see --workers)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="OUT.mcap: write a copy of the log with the results on /autoteach/* channels; any other path: the "
        "report folder (default: LOG without suffix + '-report'); a batch: the results folder (default: "
        "autoteach-fleet beside the first log)",
    )
    p.add_argument("--report", type=Path, default=None, help="report folder (overrides the default)")
    p.add_argument(
        "--write-back",
        action="store_true",
        help="add the results to LOG itself on /autoteach/* channels (every input message is kept)",
    )
    p.add_argument(
        "--frontend",
        choices=("auto", "simulated", "detect"),
        default="detect",
        help="edge front end: detection + tracking on the images (default), the ground-truth rims of a "
        "simulated log, or auto (detect when the log has images)",
    )
    p.add_argument("--window", type=int, default=5, help="sliding-window size in frames (0: batch only)")
    p.add_argument("--baseline", action="store_true", help="also solve with the point-reprojection baseline")
    p.add_argument(
        "--min-band-px",
        type=float,
        default=2.5,
        help="detect front end: drop edge points where the wafer's side band is narrower than this (pixels; "
        "about 3x the edge blur of the optics; 0 keeps all)",
    )
    p.add_argument(
        "--no-band-weights",
        dest="band_weights",
        action="store_false",
        help="detect front end: give every edge point the same standard deviation instead of one from the "
        "predicted band width at the point",
    )
    from autoteach.commands.fleet_run import add_fleet_arguments

    add_fleet_arguments(p)
    from autoteach.commands.viewer_flag import add_rerun_argument

    add_rerun_argument(p, "LOG without suffix + '.rrd'")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from autoteach.cli import _progress_enabled
    from autoteach.commands.fleet_run import is_batch, run_fleet
    from autoteach.errors import InvalidInputError
    from autoteach.io import read_log, write_results
    from autoteach.pipeline import autoteach
    from autoteach.report import format_table, write_report

    if is_batch(args):
        return run_fleet(args)
    args.log = args.log[0]
    if args.window < 0:
        raise InvalidInputError(f"--window must be >= 0, got {args.window}")
    if not args.min_band_px >= 0.0 or args.min_band_px == float("inf"):
        raise InvalidInputError(f"--min-band-px must be finite and >= 0, got {args.min_band_px}")
    from autoteach.commands.viewer_flag import rerun_target, write_rerun

    rrd = rerun_target(args, args.log.with_suffix(".rrd"))
    session = read_log(args.log)
    result = autoteach(
        session,
        frontend=args.frontend,
        window=args.window,
        baseline=args.baseline,
        min_band_px=args.min_band_px,
        band_weights=args.band_weights,
        progress=_progress_enabled(args),
    )
    out_log = args.out if args.out is not None and args.out.suffix == ".mcap" else None
    out = args.report or (args.out if args.out is not None and out_log is None else None)
    out = out or args.log.with_name(args.log.stem + "-report")
    files = write_report(result, out, session)
    written: list[str] = []
    if out_log is not None:
        written.append(str(write_results(result, args.log, out_log)))
    if args.write_back:
        written.append(str(write_results(result, args.log)))
    recording = write_rerun(rrd, result, session)
    if args.json:
        d = result.to_dict()
        d["report"] = str(out)
        d["report_files"] = files
        d["result_logs"] = written
        d["rerun"] = recording
        print(json.dumps(d))
    else:
        print(format_table(result))
        for w in written:
            print(f"results written to {w} (channels /autoteach/*)")
        print(f"report: {out}")
        if recording is not None:
            print(f"Rerun recording: {recording} (open with: rerun {recording})")
    return 0
