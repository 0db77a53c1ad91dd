"""Row modules of ``benchmarks/peers.py``: one module per workload, each with ``rows(threads, quick)``.

Helpers shared by the modules: :func:`median_time` and :func:`missing_row`.
"""

from __future__ import annotations

import importlib.util
import statistics
import time
from collections.abc import Callable
from typing import Any


def median_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """Median wall time of ``repeats`` calls of ``fn`` (at least one) and the last result."""
    times = []
    out = None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def missing(*packages: str) -> list[str]:
    """The packages among ``packages`` that cannot be imported."""
    return [p for p in packages if importlib.util.find_spec(p) is None]


def missing_row(workload: str, peer: str, packages: list[str]) -> dict:
    """The row of a peer that is not installed: no times, a note naming the missing packages."""
    nan = float("nan")
    return {
        "workload": workload,
        "peer": peer,
        "peer_s": nan,
        "ours_s": nan,
        "ratio": nan,
        "peer_accuracy": "-",
        "ours_accuracy": "-",
        "note": f"not installed: {', '.join(packages)} (pip install {' '.join(packages)})",
    }


def row(
    workload: str, peer: str, peer_s: float, ours_s: float, peer_accuracy: str, ours_accuracy: str, note: str = ""
) -> dict:
    """One row of the table (``ratio = peer_s / ours_s``)."""
    return {
        "workload": workload,
        "peer": peer,
        "peer_s": peer_s,
        "ours_s": ours_s,
        "ratio": peer_s / ours_s if ours_s > 0 else float("nan"),
        "peer_accuracy": peer_accuracy,
        "ours_accuracy": ours_accuracy,
        "note": note,
    }
