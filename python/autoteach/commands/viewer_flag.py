"""The ``--rerun [FILE.rrd]`` flag of ``autoteach demo`` and ``autoteach run``: write a Rerun recording of the run."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_rerun_argument(p: argparse.ArgumentParser, default_help: str) -> None:
    """Add ``--rerun [FILE.rrd]``; without a file the command picks one (``default_help`` says which)."""
    p.add_argument(
        "--rerun",
        type=Path,
        nargs="?",
        const=Path(),
        default=None,
        metavar="FILE.rrd",
        help="write a Rerun recording (images with rims and track ids, camera trajectories, wafer stack with "
        "3σ ellipsoids, calibration over frames); needs the 'viewer' extra"
        f"; default FILE: {default_help}",
    )


def rerun_target(args: argparse.Namespace, default: Path) -> Path | None:
    """The ``.rrd`` file asked for (``default`` when the flag has no file), checked before the run; else None."""
    if getattr(args, "rerun", None) is None:
        return None
    from autoteach.viewer import check_recording_path

    target = default if args.rerun == Path() else args.rerun
    return check_recording_path(target)


def write_rerun(target: Path | None, result: Any, session: Any) -> str | None:
    """Write the recording when asked; returns its path as text."""
    if target is None:
        return None
    from autoteach.viewer import log_autoteach

    return str(log_autoteach(result, session, target))
