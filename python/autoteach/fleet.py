"""Auto-teaching many robots' logs: a batch engine (local process pool or Ray) and a fleet summary.

One log is one robot. :func:`run_batch` runs the single-log pipeline (:func:`autoteach.io.read_log`
then :func:`autoteach.pipeline.autoteach`, the same call ``autoteach run LOG`` makes) on each log,
one log per worker, and returns a :class:`FleetReport` with one :class:`LogOutcome` per log in the
order given: calibration with its standard deviations, the wafer poses and the runtime, or the
reason the log failed. A failed log (unreadable, truncated, too few frames to calibrate) never
stops the batch.

Engines:

- ``"process"`` (default): a local :class:`concurrent.futures.ProcessPoolExecutor` (``spawn``
  start method, so no forked Rust thread pool), ``workers`` processes; ``workers=1`` runs in
  this process. Each worker's Rust (rayon) and BLAS/OpenMP thread pools get ``cpu_count // workers``
  threads unless ``RAYON_NUM_THREADS`` / ``OPENBLAS_NUM_THREADS`` / ``OMP_NUM_THREADS`` /
  ``MKL_NUM_THREADS`` are set.
- ``"ray"``: one Ray task per log on the cluster at ``address`` (or the one this process already
  joined with ``ray.init``); needs the ``ray`` extra (``pip install 'autoteach[ray]'``).

With ``out=DIR`` each robot's result is saved to ``DIR/<robot>.results.mcap`` on the
``/autoteach/*`` result channels of :func:`autoteach.io.write_results` (without a copy of the
input messages), and the summary to ``DIR/fleet.json``. A result file already there is the
robot's previous run: the summary flags every parameter that moved beyond three standard
deviations of the difference, ``|Δ| > 3·sqrt(σ_prev² + σ_now²)`` (the two runs are independent
estimates); the base pose difference is the twist ``T_now ⊖ T_prev`` of
:func:`autoteach.geometry.se3_minus`, compared with the base standard deviations of the same
tangent ``[ω; ρ]``.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError, MissingExtraError

#: Names of the base-pose tangent components ``[ω; ρ]`` compared by the drift test.
BASE_TANGENT = ("base_wx", "base_wy", "base_wz", "base_x", "base_y", "base_z")
#: Suffix of a robot's result file in the output folder.
RESULT_SUFFIX = ".results.mcap"
ENGINES = ("process", "ray")
_RAY_HINT = "the Ray engine needs the 'ray' extra: pip install 'autoteach[ray]'"


@dataclass(frozen=True)
class RunOptions:
    """The per-log pipeline settings (the ``autoteach run`` flags); defaults as ``autoteach run``."""

    frontend: str = "detect"
    window: int = 5
    baseline: bool = False
    min_band_px: float = 2.5
    band_weights: bool = True

    def __post_init__(self) -> None:
        if self.frontend not in ("auto", "simulated", "detect"):
            raise InvalidInputError(f"frontend must be 'auto', 'simulated' or 'detect', got {self.frontend!r}")
        if not isinstance(self.window, int) or self.window < 0:
            raise InvalidInputError(f"window must be an integer >= 0, got {self.window!r}")
        if not (math.isfinite(self.min_band_px) and self.min_band_px >= 0.0):
            raise InvalidInputError(f"min_band_px must be finite and >= 0, got {self.min_band_px}")


@dataclass
class LogOutcome:
    """What auto-teaching one robot's log gave.

    Attributes:
        log: the log file.
        robot: the robot's name (the log file's stem).
        ok: whether auto-teaching finished.
        reason: why it failed (exception type and message), else ``None``.
        runtime_s: wall time of reading and auto-teaching the log in its worker.
        joint_offsets: (5,) joint zero offsets (rad; lift in m), NaN where not estimated.
        joint_offsets_std: (5,) their standard deviations.
        base_pose: (4, 4) effective base pose ``T_wb``.
        base_std: (6,) standard deviations of its tangent ``[ω; ρ]``.
        wafer_poses: (K, 4, 4) wafer frames; ``wafer_std`` (K, 5) and ``wafer_slots`` (K,) beside.
        result_file: the saved result file (``out`` given), else ``None``.
        previous: the previous run's calibration read from ``result_file`` before it was replaced.
        moved: parameters that moved beyond 3σ since the previous run, with ``|Δ|/σ``.

    """

    log: str
    robot: str
    ok: bool
    reason: str | None = None
    runtime_s: float = 0.0
    joint_offsets: np.ndarray | None = None
    joint_offsets_std: np.ndarray | None = None
    base_pose: np.ndarray | None = None
    base_std: np.ndarray | None = None
    wafer_poses: np.ndarray | None = None
    wafer_std: np.ndarray | None = None
    wafer_slots: list[int] = field(default_factory=list)
    result_file: str | None = None
    previous: dict[str, Any] | None = None
    moved: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-compatible row of the fleet table (NaN as ``None``)."""
        from autoteach.config import JOINTS
        from autoteach.io import _clean

        d: dict[str, Any] = {
            "log": self.log,
            "robot": self.robot,
            "ok": self.ok,
            "reason": self.reason,
            "runtime_s": self.runtime_s,
            "result_file": self.result_file,
            "moved_3sigma": dict(self.moved),
            "had_previous": self.previous is not None,
        }
        if self.ok and self.joint_offsets is not None and self.joint_offsets_std is not None:
            d["joint_offsets"] = {
                name: {"value": _clean(self.joint_offsets[i]), "std": _clean(self.joint_offsets_std[i])}
                for i, name in enumerate(JOINTS)
            }
            d["base_pose"] = _clean(self.base_pose)
            d["base_std"] = _clean(self.base_std)
            d["wafer_poses"] = _clean(self.wafer_poses)
            d["wafer_std"] = _clean(self.wafer_std)
            d["wafer_slots"] = list(self.wafer_slots)
        return d


@dataclass
class FleetReport:
    """The outcome of a batch: one :class:`LogOutcome` per log (input order) and the wall time."""

    outcomes: list[LogOutcome]
    wall_s: float
    engine: str
    workers: int

    @property
    def failed(self) -> list[LogOutcome]:
        """The logs that did not give a result."""
        return [o for o in self.outcomes if not o.ok]

    @property
    def moved(self) -> list[LogOutcome]:
        """The robots whose calibration moved beyond 3σ since their previous run."""
        return [o for o in self.outcomes if o.moved]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-compatible summary (what ``DIR/fleet.json`` holds)."""
        return {
            "engine": self.engine,
            "workers": self.workers,
            "wall_s": self.wall_s,
            "logs": len(self.outcomes),
            "failed": len(self.failed),
            "moved": [o.robot for o in self.moved],
            "robots": [o.to_dict() for o in self.outcomes],
        }


def expand_logs(paths: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The log files named by ``paths``: files as given, folders replaced by their ``*.mcap`` files (sorted).

    Raises:
        InvalidInputError: no path, a path that does not exist, a folder without ``.mcap`` files,
            or two logs with the same stem (their results would share one file).

    """
    if len(paths) == 0:
        raise InvalidInputError("no log given")
    logs: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(q for q in p.glob("*.mcap") if q.is_file() and not q.name.endswith(RESULT_SUFFIX))
            if not found:
                raise InvalidInputError(f"the folder {p} holds no .mcap log")
            logs += found
        elif p.exists():
            logs.append(p)
        else:
            raise InvalidInputError(f"the log {p} does not exist")
    seen: dict[str, Path] = {}
    for p in logs:
        name = _robot(p)
        if name in seen:
            raise InvalidInputError(
                f"two logs name the same robot {name!r}: {seen[name]} and {p} (a robot is named by its log's stem)"
            )
        seen[name] = p
    return logs


def _robot(path: Path) -> str:
    return path.name.removesuffix(".mcap") if path.name.endswith(".mcap") else path.stem


def write_result_file(result: Any, timestamps: np.ndarray, path: str | os.PathLike[str]) -> Path:
    """Save an auto-teaching result alone on the ``/autoteach/*`` channels (read by :func:`~autoteach.io.read_results`).

    The messages and schemas are those :func:`autoteach.io.write_results` adds to a log copy;
    the input messages are not copied. Written to ``path.part`` and renamed.
    """
    from mcap.writer import CompressionType, Writer

    from autoteach.io import _CHUNK_SIZE, _writable_target, write_result_messages

    path = Path(path)
    part = _writable_target(path)
    try:
        with open(part, "wb") as f:
            writer = Writer(f, chunk_size=_CHUNK_SIZE, compression=CompressionType.ZSTD, enable_data_crcs=True)
            writer.start(profile="", library="autoteach.fleet")
            write_result_messages(writer, result, timestamps)
            writer.finish()
        os.replace(part, path)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    return path


def process_log(log: str, options: RunOptions, result_file: str | None = None) -> LogOutcome:
    """Auto-teach one log (the per-log task of every engine); failures become a :class:`LogOutcome` with a reason.

    Only ``KeyboardInterrupt``/``SystemExit`` propagate; everything else a log can cause (an
    unreadable or truncated file, too few frames, a solver failure) is the log's outcome.
    """
    from autoteach.io import read_log
    from autoteach.pipeline import autoteach

    path = Path(log)
    t0 = time.perf_counter()
    try:
        session = read_log(path)
        result = autoteach(
            session,
            frontend=options.frontend,
            window=options.window,
            baseline=options.baseline,
            min_band_px=options.min_band_px,
            band_weights=options.band_weights,
            progress=False,
        )
        written = None
        if result_file is not None:
            written = str(write_result_file(result, np.asarray(session.timestamps), result_file))
    except Exception as exc:  # noqa: BLE001 - a failed log is reported, the batch goes on
        return LogOutcome(
            log=str(path), robot=_robot(path), ok=False, reason=f"{type(exc).__name__}: {exc}",
            runtime_s=time.perf_counter() - t0,
        )  # fmt: skip
    return LogOutcome(
        log=str(path),
        robot=_robot(path),
        ok=True,
        runtime_s=time.perf_counter() - t0,
        joint_offsets=np.array(result.joint_offsets, dtype=np.float64),
        joint_offsets_std=np.array(result.joint_offsets_std, dtype=np.float64),
        base_pose=np.array(result.base_pose, dtype=np.float64),
        base_std=np.array(result.base_std, dtype=np.float64),
        wafer_poses=np.array(result.wafer_poses, dtype=np.float64),
        wafer_std=np.array(result.wafer_std, dtype=np.float64),
        wafer_slots=[int(s) for s in result.wafer_slots],
        result_file=written,
    )


#: Thread-pool sizes a worker inherits: the Rust core's (rayon) and the BLAS/OpenMP ones NumPy may load.
_THREAD_VARIABLES = ("RAYON_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _previous(path: Path) -> dict[str, Any] | None:
    """The calibration saved in a previous run's result file (``None`` when there is none or it is unreadable)."""
    if not path.is_file():
        return None
    from autoteach.io import read_results

    try:
        cal = read_results(path)["calibration"]
    except (OSError, ValueError) as exc:
        return {"unreadable": f"{type(exc).__name__}: {exc}"}
    return {
        k: np.asarray(cal[k], dtype=np.float64) for k in ("joint_offsets", "joint_offsets_std", "base_pose", "base_std")
    }


def calibration_moves(previous: dict[str, Any], now: LogOutcome, nsigma: float = 3.0) -> dict[str, float]:
    """The parameters that moved beyond ``nsigma`` standard deviations of the difference, with ``|Δ|/σ``.

    ``Δ`` is the change of each estimated joint offset and the twist ``T_now ⊖ T_prev`` of the base
    pose; ``σ = sqrt(σ_prev² + σ_now²)``. Parameters without a finite, positive σ in both runs
    (not estimated, unobservable, the reference) are not compared.
    """
    from autoteach.config import JOINTS
    from autoteach.geometry import se3_minus

    if "unreadable" in previous or not now.ok:
        return {}
    assert now.joint_offsets is not None and now.joint_offsets_std is not None
    assert now.base_pose is not None and now.base_std is not None
    delta = np.concatenate(
        [now.joint_offsets - previous["joint_offsets"], se3_minus(now.base_pose, previous["base_pose"])]
    )
    sigma = np.hypot(
        np.concatenate([previous["joint_offsets_std"], previous["base_std"]]),
        np.concatenate([now.joint_offsets_std, now.base_std]),
    )
    moved: dict[str, float] = {}
    for name, d, s in zip((*JOINTS, *BASE_TANGENT), delta, sigma, strict=True):
        if np.isfinite(d) and np.isfinite(s) and s > 0.0 and abs(d) > nsigma * s:
            moved[name] = float(abs(d) / s)
    return moved


def run_batch(
    logs: Sequence[str | os.PathLike[str]],
    *,
    options: RunOptions | None = None,
    workers: int | None = None,
    engine: str = "process",
    address: str | None = None,
    out: str | os.PathLike[str] | None = None,
) -> FleetReport:
    """Auto-teach every log, one log per worker, and summarise the fleet.

    Args:
        logs: log files or folders of ``*.mcap`` logs (see :func:`expand_logs`).
        options: the per-log pipeline settings (default :class:`RunOptions`).
        workers: processes of the ``"process"`` engine (default: the CPU count, at most the
            number of logs; 1 runs in this process). Ignored by ``"ray"``.
        engine: ``"process"`` or ``"ray"``.
        address: the Ray cluster to join (``ray.init(address=...)``) when this process has not
            joined one; ``None`` starts a local one.
        out: folder for ``<robot>.results.mcap`` and ``fleet.json``; previous result files there
            are compared with the new results (:func:`calibration_moves`).

    Raises:
        InvalidInputError: no log, a missing path, ``workers < 1``, an unknown engine, or
            ``address`` with the process engine.
        MissingExtraError: ``engine="ray"`` without Ray installed (the message names the extra).

    """
    options = options or RunOptions()
    if engine not in ENGINES:
        raise InvalidInputError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise InvalidInputError(f"workers must be an integer >= 1, got {workers!r}")
    if address is not None and engine != "ray":
        raise InvalidInputError("address is a Ray cluster address: it needs engine='ray'")
    paths = expand_logs(logs)
    out_dir = None if out is None else Path(out)
    if out_dir is not None:
        if out_dir.exists() and not out_dir.is_dir():
            raise InvalidInputError(f"the output folder {out_dir} exists and is not a folder")
        out_dir.mkdir(parents=True, exist_ok=True)
    targets = [None if out_dir is None else str(out_dir / (_robot(p) + RESULT_SUFFIX)) for p in paths]
    previous = [None if t is None else _previous(Path(t)) for t in targets]
    t0 = time.perf_counter()
    if engine == "ray":
        outcomes = _run_ray(paths, options, targets, address)
        n_workers = 0
    else:
        n_workers = min(workers or os.cpu_count() or 1, len(paths))
        outcomes = _run_processes(paths, options, targets, n_workers)
    wall = time.perf_counter() - t0
    for o, prev in zip(outcomes, previous, strict=True):
        o.previous = prev
        if prev is not None:
            o.moved = calibration_moves(prev, o)
    report = FleetReport(outcomes=outcomes, wall_s=wall, engine=engine, workers=n_workers)
    if out_dir is not None:
        (out_dir / "fleet.json").write_text(json.dumps(report.to_dict(), indent=1, allow_nan=False) + "\n")
    return report


def _run_processes(paths: list[Path], options: RunOptions, targets: list[str | None], workers: int) -> list[LogOutcome]:
    if workers == 1:
        return [process_log(str(p), options, t) for p, t in zip(paths, targets, strict=True)]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # A spawned worker reads its thread-pool sizes from the environment when it imports NumPy and
    # the core, before any initializer could run: give each worker its share of the cores through
    # the environment it inherits (variables the user set are kept), so that N workers do not start
    # N × cores compute threads; restore ours afterwards.
    threads = str(max(1, (os.cpu_count() or 1) // workers))
    added = [v for v in _THREAD_VARIABLES if v not in os.environ]
    os.environ.update(dict.fromkeys(added, threads))
    try:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
            futures = [ex.submit(process_log, str(p), options, t) for p, t in zip(paths, targets, strict=True)]
            return [f.result() for f in futures]
    finally:
        for v in added:
            os.environ.pop(v, None)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as exc:
        raise MissingExtraError(_RAY_HINT) from exc
    return ray


def _run_ray(
    paths: list[Path], options: RunOptions, targets: list[str | None], address: str | None
) -> list[LogOutcome]:
    ray = _import_ray()
    if not ray.is_initialized():
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    task = ray.remote(num_cpus=1, max_retries=0)(process_log)
    # Ray workers run in their own folders: give them absolute paths.
    absolute = [None if t is None else str(Path(t).resolve()) for t in targets]
    refs = [task.remote(str(p.resolve()), options, t) for p, t in zip(paths, absolute, strict=True)]
    return list(ray.get(refs))


def format_fleet(report: FleetReport) -> str:
    """The fleet table: one row per robot (joint offsets ± σ in degrees, lift in mm, base position, wafers, runtime)."""
    from autoteach.config import JOINTS

    lines = [
        f"{len(report.outcomes)} logs, {len(report.failed)} failed, {len(report.moved)} moved beyond 3σ; "
        f"{report.engine} engine"
        + (f", {report.workers} workers" if report.workers else "")
        + f", {report.wall_s:.1f} s"
    ]
    for o in report.outcomes:
        if not o.ok:
            lines.append(f"  {o.robot}: FAILED ({o.reason})")
            continue
        assert o.joint_offsets is not None and o.joint_offsets_std is not None and o.base_pose is not None
        parts = []
        for i, name in enumerate(JOINTS):
            if np.isfinite(o.joint_offsets[i]):
                scale, unit = (1e3, "mm") if name == "lift" else (180.0 / math.pi, "°")
                parts.append(f"{name} {o.joint_offsets[i] * scale:+.4f}±{o.joint_offsets_std[i] * scale:.4f}{unit}")
        pos = ", ".join(f"{v:+.4f}" for v in o.base_pose[:3, 3])
        n_w = 0 if o.wafer_poses is None else len(o.wafer_poses)
        lines.append(f"  {o.robot}: {'; '.join(parts)}; base ({pos}) m; {n_w} wafers; {o.runtime_s:.2f} s")
        if o.moved:
            lines.append("    moved beyond 3σ: " + ", ".join(f"{k} ({v:.1f}σ)" for k, v in o.moved.items()))
    return "\n".join(lines)
