"""filterpy's own UKF test suite, run against autoteach's UnscentedKalmanFilter (issue 37).

Copies filterpy's ``filterpy/kalman/tests/test_ukf.py`` into a temporary directory at run
time, swaps the one line ``from filterpy.kalman import UnscentedKalmanFilter`` for
``from autoteach.estimate import UnscentedKalmanFilter`` (everything else, including filterpy's
own sigma-point classes, Saver and KalmanFilter, stays filterpy's), runs it with pytest and
prints the pass count. filterpy's file is read at run time and never stored in this repository.

Where the file comes from, in order: ``--source PATH``; the ``FILTERPY_TEST_UKF`` environment
variable; the installed filterpy package (wheels usually omit its tests); the sdist of the
installed filterpy version, fetched with ``pip download`` into the temporary directory.

Run: ``python benchmarks/filterpy_suite.py [--source test_ukf.py] [--reference]``
(``--reference`` runs the file unmodified, i.e. filterpy against itself.)
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from importlib import metadata
from pathlib import Path

FILTERPY_IMPORT = "from filterpy.kalman import UnscentedKalmanFilter"
OURS_IMPORT = "from autoteach.estimate import UnscentedKalmanFilter"
MEMBER = "filterpy/kalman/tests/test_ukf.py"
PYTHON_DIR = Path(__file__).resolve().parents[1] / "python"


def _package_root() -> Path:
    """The directory holding the ``autoteach`` this interpreter imports (an installed wheel in CI,
    the source tree's ``python/`` in development), else the source tree's ``python/``."""
    from importlib.util import find_spec

    spec = find_spec("autoteach")
    if spec is not None and spec.origin is not None:
        return Path(spec.origin).resolve().parents[1]
    return PYTHON_DIR


def _from_sdist(workdir: Path, timeout: float) -> Path | None:
    """filterpy's test_ukf.py from the sdist of the installed version (``pip download``), or None."""
    try:
        version = metadata.version("filterpy")
    except metadata.PackageNotFoundError:
        return None
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", ":all:"]
    cmd += [f"filterpy=={version}", "-d", str(workdir)]
    try:
        subprocess.run(cmd, check=True, capture_output=True, timeout=timeout)
    except (OSError, subprocess.SubprocessError):
        return None
    for archive in workdir.iterdir():
        out = workdir / "test_ukf_original.py"
        if archive.suffixes[-2:] == [".tar", ".gz"]:
            with tarfile.open(archive) as tf:
                names = [m for m in tf.getmembers() if m.name.endswith(MEMBER)]
                src = tf.extractfile(names[0]) if names else None
                if src is not None:
                    out.write_bytes(src.read())
                    return out
        elif archive.suffix == ".zip":
            with zipfile.ZipFile(archive) as zf:
                names = [n for n in zf.namelist() if n.endswith(MEMBER)]
                if names:
                    out.write_bytes(zf.read(names[0]))
                    return out
    return None


def find_source(workdir: Path, source: str | None = None, download: bool = True, timeout: float = 120.0) -> Path | None:
    """The path of filterpy's test_ukf.py (see the module docs for the search order), or None."""
    for candidate in (source, os.environ.get("FILTERPY_TEST_UKF")):
        if candidate and Path(candidate).is_file():
            return Path(candidate)
    try:
        import filterpy.kalman

        installed = Path(filterpy.kalman.__file__).parent / "tests" / "test_ukf.py"
        if installed.is_file():
            return installed
    except ImportError:
        return None
    return _from_sdist(workdir, timeout) if download else None


def swap_import(text: str) -> str:
    """filterpy's test file with only its UnscentedKalmanFilter import replaced by ours."""
    lines = text.splitlines(keepends=True)
    hits = [i for i, line in enumerate(lines) if line.strip() == FILTERPY_IMPORT]
    if len(hits) != 1:
        raise RuntimeError(f"expected exactly one line {FILTERPY_IMPORT!r} in filterpy's test file, found {len(hits)}")
    lines[hits[0]] = lines[hits[0]].replace(FILTERPY_IMPORT, OURS_IMPORT)
    return "".join(lines)


def run_suite(original: Path, workdir: Path, reference: bool = False) -> tuple[int, int, str]:
    """Runs the (swapped) suite with pytest in ``workdir``: ``(passed, total, pytest output)``."""
    text = original.read_text(encoding="utf-8")
    target = workdir / "test_ukf.py"
    target.write_text(text if reference else swap_import(text), encoding="utf-8")
    env = dict(os.environ)
    # The same autoteach as this process: the source tree has no compiled _core where the wheel is
    # installed (CI), so putting python/ first there would hide the installed package.
    env["PYTHONPATH"] = os.pathsep.join([str(_package_root()), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["MPLBACKEND"] = "Agg"
    cmd = [sys.executable, "-m", "pytest", str(target), "-q", "-p", "no:cacheprovider", "--rootdir", str(workdir)]
    proc = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=600)
    out = proc.stdout + proc.stderr
    counts = {k: int(v) for v, k in re.findall(r"(\d+) (passed|failed|error|errors)", out)}
    passed = counts.get("passed", 0)
    total = passed + counts.get("failed", 0) + counts.get("error", 0) + counts.get("errors", 0)
    return passed, total, out


def main() -> int:
    """Prints the pass count; exit status 0 only if every test passed."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", help="path of filterpy's test_ukf.py")
    ap.add_argument("--reference", action="store_true", help="run the file unmodified (filterpy itself)")
    ap.add_argument("--verbose", action="store_true", help="print pytest's output")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="filterpy_suite_") as tmp:
        workdir = Path(tmp)
        original = find_source(workdir, args.source)
        if original is None:
            print("filterpy's test_ukf.py not found (install filterpy, or pass --source)", file=sys.stderr)
            return 2
        passed, total, out = run_suite(original, workdir, reference=args.reference)
    if args.verbose or passed != total:
        print(out)
    who = "filterpy (unmodified)" if args.reference else "autoteach.estimate.UnscentedKalmanFilter"
    print(f"filterpy {metadata.version('filterpy')} test_ukf.py with {who}: {passed} of {total} passed")
    return 0 if total and passed == total else 1


if __name__ == "__main__":
    sys.exit(main())
