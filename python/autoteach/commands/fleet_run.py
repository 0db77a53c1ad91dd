"""``autoteach run LOG... [--workers N] [--engine process|ray] [--address ADDR] [--out DIR]``: a fleet of logs.

The ``run`` sub-command (:mod:`autoteach.commands.run`) hands over here when it is given several
logs, a folder, ``--workers``, ``--engine ray`` or ``--address``; :func:`autoteach.fleet.run_batch`
does the work. The exit status is 0 when every log gave a result, :data:`EXIT_SOME_FAILED`
when some failed (each is listed with its reason; the others' results are kept), and 2 (a user
error, one line) when none gave a result. ``--out`` defaults to ``autoteach-fleet`` beside the
first log (in it, for a folder).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from autoteach.commands.args import int_in_range

#: Exit status of a batch in which some logs failed (the others completed).
EXIT_SOME_FAILED = 3
_workers = int_in_range(1, "--workers must be an integer in [1, 1024]", 1024)


def add_fleet_arguments(p: argparse.ArgumentParser) -> None:
    """Add the batch flags to the ``run`` parser."""
    p.add_argument(
        "--workers",
        type=_workers,
        default=None,
        help="batch: local worker processes, one log each (default: the CPU count)",
    )
    p.add_argument(
        "--engine",
        choices=("process", "ray"),
        default="process",
        help="batch: a local process pool (default) or Ray tasks (needs the 'ray' extra)",
    )
    p.add_argument("--address", default=None, help="batch, --engine ray: the Ray cluster to join (default: local)")


def is_batch(args: argparse.Namespace) -> bool:
    """Whether the ``run`` arguments ask for a batch rather than the single-log report."""
    logs: list[Path] = args.log
    return (
        len(logs) > 1
        or any(p.is_dir() for p in logs)
        or args.workers is not None
        or args.engine != "process"
        or args.address is not None
    )


def run_fleet(args: argparse.Namespace) -> int:
    """Run the batch and print the fleet table (or JSON)."""
    from autoteach.errors import InvalidInputError
    from autoteach.fleet import RunOptions, format_fleet, run_batch

    if args.write_back or args.report is not None:
        raise InvalidInputError(
            "--write-back and --report apply to a single log; a batch saves DIR/<robot>.results.mcap"
        )
    if getattr(args, "rerun", None) is not None:
        raise InvalidInputError("--rerun applies to a single log")
    first = args.log[0]
    out = args.out if args.out is not None else (first if first.is_dir() else first.parent) / "autoteach-fleet"
    if out.suffix == ".mcap":
        raise InvalidInputError(f"--out of a batch is a folder, got the MCAP name {out}")
    options = RunOptions(
        frontend=args.frontend,
        window=args.window,
        baseline=args.baseline,
        min_band_px=args.min_band_px,
        band_weights=args.band_weights,
    )
    report = run_batch(
        args.log, options=options, workers=args.workers, engine=args.engine, address=args.address, out=out
    )
    if args.json:
        d = report.to_dict()
        d["out"] = str(out)
        print(json.dumps(d))
    else:
        print(format_fleet(report))
        print(f"results: {out}/<robot>.results.mcap, summary: {out / 'fleet.json'}")
    if report.failed and len(report.failed) == len(report.outcomes):
        o = report.failed[0]
        raise InvalidInputError(f"none of the {len(report.outcomes)} logs could be auto-taught; {o.robot}: {o.reason}")
    return EXIT_SOME_FAILED if report.failed else 0
