"""Every peer comparison of issue 36 in one run: ratios and accuracies on identical inputs.

Each module of the package ``benchmarks/peer_rows/`` (discovered, so rows added by other
modules appear without editing this file) exposes ``rows(threads, quick) -> list[dict]``; each
row has ``workload``, ``peer``, ``peer_s``, ``ours_s`` (median seconds), ``ratio``
(``peer_s / ours_s``), ``peer_accuracy``, ``ours_accuracy`` and ``note``.

The thread count of the peers (BLAS, OpenMP) and of autoteach (rayon) is fixed by environment
variables that native libraries read once, when they load. So this script re-executes itself
once per ``--threads`` value with ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
``MKL_NUM_THREADS``, ``NUMEXPR_NUM_THREADS``, ``VECLIB_MAXIMUM_THREADS`` and
``RAYON_NUM_THREADS`` set before anything imports NumPy; each child prints its rows as JSON.

Run: ``PYTHONPATH=python python benchmarks/peers.py --threads 1 2 [--only ukf assignment] [--quick]
[--json out.json]``
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import subprocess
import sys
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
THREAD_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "BLIS_NUM_THREADS",
    "RAYON_NUM_THREADS",
)
KEYS = ("workload", "peer", "peer_s", "ours_s", "ratio", "peer_accuracy", "ours_accuracy", "note")


def modules() -> list[str]:
    """Names of the row modules in ``peer_rows/`` (those not starting with an underscore)."""
    return sorted(m.name for m in pkgutil.iter_modules([str(HERE / "peer_rows")]) if not m.name.startswith("_"))


def error_row(name: str, message: str) -> dict:
    """The row reported for a module that failed, so one broken module does not hide the others."""
    nan = float("nan")
    return dict(zip(KEYS, (name, "-", nan, nan, nan, "-", "-", message), strict=True))


def child(names: list[str], threads: int, quick: bool) -> None:
    """Runs the row modules in this (already thread-pinned) process; prints the rows as JSON."""
    sys.path.insert(0, str(HERE))
    out = []
    for name in names:
        try:
            mod = importlib.import_module(f"peer_rows.{name}")
            rows = mod.rows(threads, quick)
        except Exception as exc:  # noqa: BLE001 (reported as a row, not swallowed)
            traceback.print_exc(file=sys.stderr)
            rows = [error_row(name, f"{type(exc).__name__}: {exc}")]
        for r in rows:
            missing = [k for k in KEYS if k not in r]
            if missing:
                r = error_row(name, f"row without keys {missing}")
            out.append({"module": name, "threads": threads, **{k: r[k] for k in KEYS}})
        print(f"[peers] {name}: {len(rows)} rows at {threads} thread(s)", file=sys.stderr, flush=True)
    print(json.dumps(out))


def fmt_s(s: float) -> str:
    """Seconds in a readable unit."""
    if s != s:  # NaN
        return "-"
    if s >= 1.0:
        return f"{s:.2f} s"
    if s >= 1e-3:
        return f"{s * 1e3:.3g} ms"
    return f"{s * 1e6:.3g} µs"


def table(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    lines = [
        "| threads | workload | peer | peer time | ours | ratio (peer/ours) | peer accuracy | ours accuracy | note |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = "-" if r["ratio"] != r["ratio"] else f"{r['ratio']:.2f}×"
        lines.append(
            f"| {r['threads']} | {r['workload']} | {r['peer']} | {fmt_s(r['peer_s'])} | {fmt_s(r['ours_s'])} | "
            f"{ratio} | {r['peer_accuracy']} | {r['ours_accuracy']} | {r['note']} |"
        )
    return "\n".join(lines)


def main() -> None:
    """Parses the arguments; runs one child per thread count (or, as a child, the rows)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, nargs="+", default=[1])
    parser.add_argument("--only", nargs="+", default=None, help="row modules to run (default: all)")
    parser.add_argument("--quick", action="store_true", help="smaller problems and fewer repeats")
    parser.add_argument("--json", default=None, help="also write the rows to this file")
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    available = modules()
    names = available if args.only is None else args.only
    unknown = sorted(set(names) - set(available))
    if unknown:
        parser.error(f"unknown row modules {unknown}; available: {available}")
    if args.child is not None:
        child(names, args.child, args.quick)
        return
    rows: list[dict] = []
    for t in args.threads:
        if t < 1:
            parser.error(f"--threads must be positive, got {t}")
        env = dict(os.environ, **{v: str(t) for v in THREAD_VARS})
        cmd = [sys.executable, __file__, "--child", str(t), "--only", *names] + (["--quick"] if args.quick else [])
        done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True, check=False)
        if done.returncode != 0:
            rows.append({"module": "-", "threads": t, **error_row("child", f"exit code {done.returncode}")})
            continue
        rows.extend(json.loads(done.stdout.strip().splitlines()[-1]))
    print(table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
