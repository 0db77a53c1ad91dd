"""The package works with its runtime dependencies only (numpy, mcap, tqdm).

Each check runs in a fresh interpreter in which the test-only and optional packages cannot be
imported, as on a machine where ``pip install .`` installed no extra.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

# Installed by the `test` or `plot` extras, never needed at run time.
OPTIONAL = (
    "scipy",
    "cv2",
    "matplotlib",
    "filterpy",
    "pycpd",
    "motmetrics",
    "sklearn",
    "skimage",
    "shapely",
    "control",
    "hypothesis",
    "probreg",
    "open3d",
    "pytest",
    "ray",
    "rerun",
    "jsonschema",
)

_BLOCKER = textwrap.dedent(
    f"""
    import importlib.abc, sys
    class _Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in {OPTIONAL!r}:
                raise ModuleNotFoundError(f"No module named {{name!r}} (blocked: not a runtime dependency)")
            return None
    sys.meta_path.insert(0, _Block())
    """
)


def _run(code: str, tmp_path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", _BLOCKER + textwrap.dedent(code)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=600,
    )


def test_every_public_module_imports_with_runtime_dependencies_only(tmp_path):
    proc = _run(
        """
        import json, autoteach
        from autoteach.commands import MODULES
        import importlib
        mods = [getattr(autoteach, m).__name__ for m in autoteach.SUBMODULES]
        mods += [importlib.import_module(m).__name__ for m in MODULES]
        print(json.dumps(sorted(mods)))
        """,
        tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "autoteach.detect" in json.loads(proc.stdout)


def test_blocker_really_blocks(tmp_path):
    proc = _run("import scipy.optimize", tmp_path)
    assert proc.returncode != 0 and "not a runtime dependency" in proc.stderr


def test_submodules_are_imported_lazily():
    proc = subprocess.run(
        [sys.executable, "-c", "import sys, autoteach; print('autoteach.pipeline' in sys.modules)"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert proc.stdout.strip() == "False"
    import autoteach

    assert autoteach.detect.fit_ellipse is not None and callable(autoteach.autoteach)
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        _ = autoteach.nonexistent  # type: ignore[attr-defined]


def test_tracking_metrics_and_demo_run_without_optional_packages(tmp_path):
    proc = _run(
        """
        from autoteach.track import clear_mot, idf1
        frames = [([1, 2], ["a", "b"], [[0.0, 5.0], [5.0, 0.0]]), ([1, 2], ["b", "a"], [[0.0, 5.0], [5.0, 0.0]])]
        m = clear_mot(frames, threshold=1.0)
        assert m["idsw"] == 2.0 and m["matches"] == 4.0, m
        assert idf1(frames, threshold=1.0)["idtp"] == 2.0
        from autoteach.cli import main
        assert main(["demo", "--frames", "8", "--seed", "3", "--out", "rep", "--no-log", "--quiet"]) == 0
        """,
        tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "auto-teaching" in proc.stdout or "report:" in proc.stdout
    assert not list((tmp_path / "rep").glob("*.mcap"))


def test_all_lists_every_submodule():
    import autoteach

    assert set(autoteach.SUBMODULES) <= set(autoteach.__all__)
