"""Argument types shared by the sub-commands: integers in a range, with one-line errors."""

from __future__ import annotations

import argparse
from collections.abc import Callable


def int_in_range(minimum: int, requirement: str, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse ``type`` parsing an integer in ``[minimum, maximum]``; ``requirement`` words the error.

    Values too long to print (a 300-digit number) are quoted by their length only.
    """

    def shown(text: str) -> str:
        return repr(text) if len(text) <= 24 else f"a {len(text)}-character value"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{requirement}, got {shown(text)}") from None
        if value < minimum or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"{requirement}, got {shown(text.strip())}")
        return value

    return parse


#: A random seed: a non-negative integer below 2**63.
seed = int_in_range(0, "seed must be an integer in [0, 2**63)", 2**63 - 1)
#: A count of at least one, below a million.
positive = int_in_range(1, "must be an integer in [1, 1000000]", 1_000_000)
