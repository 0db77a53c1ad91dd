"""The ``autoteach active`` command."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:  # type: ignore[type-arg]
    """Add the ``active`` sub-command (not yet available in this build)."""
    del sub, common
