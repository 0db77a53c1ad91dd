"""The ``autoteach run`` command."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``run`` sub-command (not yet available in this build)."""
    del sub, common
