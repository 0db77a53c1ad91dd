"""Guided camera calibration with calibrated uncertainty (seed 004_815695db12a6b16c.txt ch. 5).

- :func:`calibrate` -- intrinsics and target poses from per-view object/image points of a planar
  target (Z = 0; missing points as NaN rows or shorter per-view arrays), bootstrapped from a
  restricted model (ch. 5.2), with outlier rejection, robust loss and the marginal covariance of
  the intrinsics (eqs. 5.3-5.5, detector noise sigma_z = 7e-5 * width by default, eq. 5.6).
- :class:`Calibration` -- ``params`` (OpenCV order ``fx, fy, cx, cy, k1, k2, p1, p2, k3`` for
  Brown-Conrady), ``covariance``, per-view and total RMS, ``outliers``, ``max_ere`` (Algorithm 5.1),
  :meth:`Calibration.error_map`, JSON :meth:`~Calibration.save`/:meth:`~Calibration.load`, OpenCV
  ``camera_matrix``/``dist_coeffs``.
- :func:`suggest_next_view` -- the next target pose: ~60 candidates through the view frustum, each
  scored by the Max ERE after adding its hypothetical observations (information-matrix update).
- :func:`select_model` -- lens-model selection by BIC.
- :meth:`Calibration.reference_errors` -- test-set errors against a reference lens along the same
  rays (ch. 5.5.3 / Fig. 5.6), the quantity the Max ERE predicts; :meth:`Calibration.test_errors`
  re-fits the test poses instead (ch. 5.5).
- :func:`simulate_session` -- a simulated guided, random or novice (ROS checklist, ch. 5.4)
  session with a test set, for the CLI ``autoteach calibrate --simulate`` and
  ``benchmarks/guided_calibration.py``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach.errors import InvalidInputError
from autoteach.geometry import Camera
from autoteach.options import checked_replace

F64Array = NDArray[np.float64]

GRID_MARGIN: float = float(_core.CALIB_GRID_MARGIN)
"""Default margin (fraction of the image size) between the image border and the outer ring of
the Max ERE test grid (Algorithm 5.1's ``makeTestGrid``)."""

MODELS = ("pinhole", "brown_conrady", "kannala_brandt")
_MODEL_ALIASES = {"opencv": "brown_conrady", "bc": "brown_conrady", "fisheye": "kannala_brandt", "kb": "kannala_brandt"}
PARAM_NAMES = {
    "pinhole": ("fx", "fy", "cx", "cy"),
    "brown_conrady": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"),
    "kannala_brandt": ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"),
}


def _model(name: str) -> str:
    if not isinstance(name, str):
        raise InvalidInputError(f"model must be a string, got {type(name).__name__}")
    key = name.strip().lower().replace("-", "_")
    key = _MODEL_ALIASES.get(key, key)
    if key not in MODELS:
        raise InvalidInputError(f"unknown model {name!r}: use one of {', '.join(MODELS)}")
    return key


def _size(image_size: Any) -> tuple[int, int]:
    try:
        w, h = image_size
    except (TypeError, ValueError):
        raise InvalidInputError(f"image_size must be (width, height), got {image_size!r}") from None
    w, h = as_int(w, "image_size[0]"), as_int(h, "image_size[1]")
    if w <= 0 or h <= 0:
        raise InvalidInputError(f"image_size must be positive, got {(w, h)}")
    if max(w, h) > _MAX_SIDE:
        raise InvalidInputError(f"image_size sides must be at most {_MAX_SIDE} pixels (32 bits), got {(w, h)}")
    return w, h


#: Largest image side the compiled camera models take (a 32-bit pixel count).
_MAX_SIDE = 2**32 - 1


def _margin(grid_margin: float | None) -> float | None:
    return None if grid_margin is None else as_float(grid_margin, "grid_margin")


def _views(points: Any, name: str, cols: int) -> list[F64Array]:
    """Per-view float64 arrays of shape (N_i, cols); (N_i, 2) object points get Z = 0."""
    if isinstance(points, np.ndarray) and points.ndim == 3:
        seq = list(points)
    elif isinstance(points, (list, tuple)):
        seq = list(points)
    else:
        raise InvalidInputError(f"{name} must be a list of per-view (N, {cols}) arrays or a (V, N, {cols}) array")
    out = []
    for i, v in enumerate(seq):
        arr = as_f64(v, f"{name}[{i}]")
        if arr.ndim == 3 and arr.shape[1] == 1:  # OpenCV's (N, 1, C) layout
            arr = arr[:, 0, :]
        if cols == 3 and arr.ndim == 2 and arr.shape[1] == 2:
            arr = np.column_stack([arr, np.zeros(len(arr))])
        if arr.ndim != 2 or arr.shape[1] != cols:
            raise InvalidInputError(f"{name}[{i}] must have shape (N, {cols}), got {arr.shape}")
        out.append(np.ascontiguousarray(arr, dtype=np.float64))
    if not out:
        raise InvalidInputError(f"{name} has no views")
    return out


@dataclass(frozen=True, slots=True)
class Suggestion:
    """A next-view suggestion (see :func:`suggest_next_view`)."""

    pose: F64Array
    """Target pose ``T_ct`` (4x4, target -> camera) to achieve."""
    pixels: F64Array
    """Predicted image points (N, 2) of the visible target points."""
    target_index: list[int]
    """Rows of the target seen in :attr:`pixels`."""
    expected_max_ere: float
    """Max ERE expected after adding this view (pixels)."""
    current_max_ere: float
    """Max ERE of the current calibration with every parameter free (inf while bootstrapping)."""
    index: int
    """Index of the chosen candidate."""
    scores: list[float]
    """Score of every candidate (inf: unusable)."""
    candidates: F64Array
    """The candidate poses (K, 4, 4)."""


@dataclass(frozen=True, slots=True)
class View:
    """The inlier observations of the planar target in one image (the fields of ``autoteach_estimate::calib::View``)."""

    plane: F64Array
    """Target coordinates ``(N, 2)`` ``[X, Y]`` of the usable points (the target plane is Z = 0)."""
    image: F64Array
    """Their observed pixels ``(N, 2)`` ``[u, v]``."""
    index: list[int]
    """Row of each point in the arrays given to :func:`calibrate`."""


@dataclass(frozen=True, slots=True)
class MaxEre:
    """Max ERE and where it occurs (the fields of ``autoteach_estimate::calib::ere::MaxEre``)."""

    value: float
    """The largest expected reprojection error over the test grid (Algorithm 5.1), pixels."""
    pixel: tuple[float, float]
    """The grid pixel ``(u, v)`` where it occurs."""
    expected_max: float
    """The expected largest error over the grid, ``E[max_t |d_t|]`` from the same samples, pixels
    (see :attr:`Calibration.expected_max_error`)."""


class Calibration:
    """A camera calibration (wraps ``autoteach._core.CalibResult``)."""

    def __init__(self, core: Any) -> None:
        """Wrap a compiled result; use :func:`calibrate` or :meth:`load` to make one."""
        self._core = core
        self._max_ere: tuple[float, tuple[float, float]] | None = None
        self._expected_max: float | None = None

    # -- parameters -------------------------------------------------------------------------
    @property
    def camera(self) -> Camera:
        """The calibrated camera, an :class:`autoteach.geometry.Camera` (model, params, image size)."""
        return Camera(self.model, self.params, *self.image_size)

    @property
    def model(self) -> str:
        """Lens model name."""
        return str(self._core.model)

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of :attr:`params` in order."""
        return PARAM_NAMES[self.model]

    @property
    def params(self) -> F64Array:
        """Parameters (OpenCV order ``fx, fy, cx, cy, k1, k2, p1, p2, k3`` for Brown-Conrady)."""
        return np.asarray(self._core.params)

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)``."""
        w, h = self._core.image_size
        return int(w), int(h)

    @property
    def covariance(self) -> F64Array:
        """Marginal covariance of :attr:`params` (eqs. 5.3-5.5); zero for parameters held fixed."""
        return np.asarray(self._core.covariance)

    @property
    def std(self) -> F64Array:
        """Standard deviations of :attr:`params`."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def free(self) -> list[bool]:
        """Which parameters were estimated (the bootstrapping schedule fixes some with few views)."""
        return list(self._core.free)

    @property
    def poses(self) -> F64Array:
        """Target poses ``T_ct`` per view, (V, 4, 4)."""
        return np.asarray(self._core.poses)

    @property
    def view_rms(self) -> F64Array:
        """Per-view RMS reprojection error (pixels)."""
        return np.asarray(self._core.view_rms)

    @property
    def rms(self) -> float:
        """Total RMS reprojection error (pixels)."""
        return float(self._core.rms)

    @property
    def outliers(self) -> list[tuple[int, int]]:
        """Rejected points as ``(view, row)``."""
        return [(int(a), int(b)) for a, b in self._core.outliers]

    @property
    def sigma_z(self) -> float:
        """Detector noise used for the covariance (pixels)."""
        return float(self._core.sigma_z)

    @property
    def iterations(self) -> int:
        """Solver iterations of the final stage."""
        return int(self._core.iterations)

    @property
    def final_cost(self) -> float:
        """Final cost ``½ Σ ‖r/σ_z‖²`` of the last stage."""
        return float(self._core.final_cost)

    @property
    def views(self) -> list[View]:
        """The inlier observations of every view (outliers removed)."""
        return [
            View(plane=np.ascontiguousarray(np.asarray(o)[:, :2]), image=np.asarray(i), index=[int(r) for r in rows])
            for o, i, rows in self._core.views()
        ]

    @property
    def num_views(self) -> int:
        """Number of views."""
        return len(self._core.view_rms)

    # -- uncertainty ------------------------------------------------------------------------
    @property
    def max_ere(self) -> float:
        """Max Expected Reprojection Error (Algorithm 5.1; 200 samples, 5x5 grid, seed 0), pixels."""
        if self._max_ere is None:
            self._stats()
        assert self._max_ere is not None
        return float(self._max_ere[0])

    @property
    def expected_max_error(self) -> float:
        """Expected largest error over the Max ERE test grid, ``E[max_t |d_t|]`` (same samples), pixels.

        Algorithm 5.1 takes the max of per-point expectations; this is the expectation of the
        per-sample maximum. They agree when a single error mode (a narrow lens's focal length)
        moves every point together and differ when several weakly correlated modes err at
        different corners (wide lenses). Reported alongside the Max ERE, which stays the stopping
        metric and the one that tracks the test set's 99.5th percentile.
        """
        if self._expected_max is None:
            self._stats()
        return float(self._expected_max if self._expected_max is not None else math.nan)

    def _stats(self) -> None:
        d = self._core.max_ere_stats(200, 5, 0)
        self._max_ere = (float(d["max_ere"]), tuple(d["pixel"]))
        self._expected_max = float(d["expected_max"])

    def compute_max_ere(
        self, samples: int = 200, grid: int = 5, seed: int = 0, *, grid_margin: float | None = None
    ) -> tuple[float, tuple[float, float]]:
        """Max ERE and the grid pixel where it occurs, with explicit sampling settings.

        ``grid_margin``: the outer ring of the ``grid x grid`` test grid sits this fraction of the
        image size inside the border (default :data:`GRID_MARGIN`).
        """
        return self._core.max_ere(
            as_int(samples, "samples"), as_int(grid, "grid"), as_int(seed, "seed"), _margin(grid_margin)
        )

    def max_ere_stats(
        self, samples: int = 200, grid: int = 5, seed: int = 0, *, grid_margin: float | None = None
    ) -> MaxEre:
        """Max ERE, its pixel and the expected largest error over the grid (see :attr:`expected_max_error`)."""
        d = self._core.max_ere_stats(
            as_int(samples, "samples"), as_int(grid, "grid"), as_int(seed, "seed"), _margin(grid_margin)
        )
        u, v = d["pixel"]
        return MaxEre(value=float(d["max_ere"]), pixel=(float(u), float(v)), expected_max=float(d["expected_max"]))

    def error_map(self, step: int = 4, samples: int = 100, seed: int = 0) -> F64Array:
        """Expected reprojection error (pixels) at every ``step``-th pixel: ``(ceil(h/step), ceil(w/step))``."""
        return np.asarray(self._core.error_map(as_int(step, "step"), as_int(samples, "samples"), as_int(seed, "seed")))

    def information(self) -> F64Array:
        """Marginal information matrix of the intrinsics (sum of per-view Schur complements)."""
        return np.asarray(self._core.information())

    def target(self) -> F64Array:
        """The target layout ``(N, 2)`` seen so far (union of observed rows, sorted by row)."""
        rows: dict[int, tuple[float, float]] = {}
        for obj, _img, idx in self._core.views():
            for r, p in zip(idx, obj, strict=True):
                rows[int(r)] = (float(p[0]), float(p[1]))
        return np.array([rows[k] for k in sorted(rows)], dtype=np.float64).reshape(-1, 2)

    def test_errors(self, object_points: Any, image_points: Any) -> F64Array:
        """Per-point reprojection errors (pixels) on test views, intrinsics fixed and poses re-fit."""
        obj = _views(object_points, "object_points", 3)
        img = _views(image_points, "image_points", 2)
        errs = self._core.test_errors(obj, img)
        return np.concatenate([np.asarray(e, dtype=np.float64) for e in errs]) if errs else np.zeros(0)

    def reference_errors(self, reference: Any, object_points: Any, poses: Any) -> F64Array:
        """Per-point errors (pixels) against a reference calibration, poses fixed (ch. 5.5.3, Fig. 5.6).

        Each test point ``X`` seen from the target pose ``T_ct`` (under the reference, e.g. the
        true lens of a simulation or a calibration from a large test set) is the camera-frame
        point ``T_ct X``; its error is ``|project(T_ct X) - reference.project(T_ct X)|``: the
        disagreement of the two lens models along the same ray, with no detector noise and no
        pose re-fit -- the quantity Algorithm 5.1's Max ERE predicts. Points this calibration
        cannot project count as ``inf``.

        Args:
            reference: an :class:`autoteach.geometry.Camera` or a :class:`Calibration`.
            object_points: per view, target points ``(N_i, 3)`` (or ``(N_i, 2)``).
            poses: per view, the target pose ``T_ct`` (4x4) under the reference.
        """
        ref = reference
        if isinstance(ref, Calibration):
            ref = Camera(ref.model, ref.params, *ref.image_size)
        if not isinstance(ref, Camera):
            raise InvalidInputError(f"reference must be a Camera or a Calibration, got {type(reference).__name__}")
        obj = _views(object_points, "object_points", 3)
        tps = as_f64(poses, "poses")
        if tps.ndim != 3 or tps.shape[1:] != (4, 4) or len(tps) != len(obj):
            raise InvalidInputError(f"poses must have shape ({len(obj)}, 4, 4), got {tps.shape}")
        if not np.all(np.isfinite(tps)):
            bad = np.argwhere(~np.isfinite(tps))[0]
            raise InvalidInputError(f"poses must be finite: poses{tuple(int(i) for i in bad)} is {tps[tuple(bad)]}")
        mine = Camera(self.model, self.params, *self.image_size)
        out = []
        for o, t in zip(obj, tps, strict=True):
            pc = o @ t[:3, :3].T + t[:3, 3]
            try:
                d = np.linalg.norm(mine.project(pc) - ref.project(pc), axis=1)
            except InvalidInputError:
                d = np.full(len(pc), math.inf)
                for k, q in enumerate(pc):
                    try:
                        d[k] = float(np.linalg.norm(mine.project(q) - ref.project(q)))
                    except InvalidInputError:
                        pass
            out.append(d)
        return np.concatenate(out) if out else np.zeros(0)

    # -- OpenCV export ----------------------------------------------------------------------
    @property
    def camera_matrix(self) -> F64Array:
        """OpenCV's 3x3 camera matrix."""
        fx, fy, cx, cy = self.params[:4]
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> F64Array:
        """OpenCV distortion: ``(k1, k2, p1, p2, k3)`` (zeros for pinhole) or fisheye ``(k1..k4)``."""
        if self.model == "pinhole":
            return np.zeros(5)
        return self.params[4:].copy()

    # -- persistence ------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (parameters, covariance, poses, observations)."""
        views = self._core.views()
        return {
            "format": "autoteach.calibration/1",
            "model": self.model,
            "param_names": list(self.param_names),
            "image_size": list(self.image_size),
            "params": self.params.tolist(),
            "covariance": self.covariance.tolist(),
            "free": self.free,
            "sigma_z": self.sigma_z,
            "rms": self.rms,
            "view_rms": self.view_rms.tolist(),
            "outliers": [list(o) for o in self.outliers],
            "max_ere": self.max_ere,
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "poses": self.poses.tolist(),
            "views": [{"object": o.tolist(), "image": i.tolist(), "rows": list(r)} for o, i, r in views],
        }

    def save(self, path: str | Path) -> None:
        """Write the calibration as JSON."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Calibration:
        """Rebuild from :meth:`to_dict` output."""
        try:
            w, h = _size(d["image_size"])
            obj = [np.asarray(v["object"], dtype=np.float64).reshape(-1, 3) for v in d["views"]]
            img = [np.asarray(v["image"], dtype=np.float64).reshape(-1, 2) for v in d["views"]]
            core = _core.CalibResult.from_parts(
                _model(d["model"]),
                np.asarray(d["params"], dtype=np.float64),
                w,
                h,
                np.asarray(d["covariance"], dtype=np.float64),
                [bool(x) for x in d["free"]],
                np.asarray(d["poses"], dtype=np.float64).reshape(-1, 4, 4),
                obj,
                img,
                float(d["sigma_z"]),
            )
        except (KeyError, TypeError, ValueError) as err:
            if isinstance(err, InvalidInputError):
                raise
            raise InvalidInputError(f"not a calibration dictionary: {err!r}") from None
        out = cls(core)
        if "max_ere" in d and d["max_ere"] is not None:
            out._max_ere = (float(d["max_ere"]), (math.nan, math.nan))
        return out

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a calibration written by :meth:`save`."""
        return cls.from_dict(json.loads(Path(path).read_text()))

    def __repr__(self) -> str:
        """Short summary."""
        p = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.param_names, self.params, strict=True))
        return f"Calibration({self.model}, {self.num_views} views, rms={self.rms:.4f} px, {p})"


def calibrate(
    object_points: Any,
    image_points: Any,
    model: str = "brown_conrady",
    image_size: tuple[int, int] | None = None,
    *,
    sigma_z: float | None = None,
    loss: str = "trivial",
    loss_scale: float | None = None,
    outlier_threshold: float | None = None,
    bootstrap: bool = True,
    initial_params: ArrayLike | None = None,
    max_iterations: int = 100,
) -> Calibration:
    """Calibrate a camera from views of a planar target.

    Args:
        object_points: per view, target points ``(N_i, 3)`` with Z = 0 (or ``(N_i, 2)``); a list
            or a ``(V, N, 3)`` array. Rows with NaN (in either array) are missing points.
        image_points: per view, pixels ``(N_i, 2)`` (OpenCV convention: centre of the top-left
            pixel at (0, 0)).
        model: ``"brown_conrady"`` (OpenCV's 5 coefficients), ``"pinhole"`` or
            ``"kannala_brandt"`` (OpenCV fisheye).
        image_size: ``(width, height)`` in pixels (required).
        sigma_z: detector noise (pixels) for the covariance; default eq. 5.6, ``7e-5 * width``.
        loss: final-solve loss, ``"trivial"``, ``"huber"`` or ``"cauchy"``.
        loss_scale: robust loss scale in pixels (default ``3 * sigma_z``).
        outlier_threshold: reprojection error (pixels) above which points are rejected and
            reported; default 5x the robust noise scale; ``math.inf`` keeps all points.
        bootstrap: follow ch. 5.2's schedule (release parameters as views arrive).
        initial_params: warm start (e.g. the previous calibration of a live session).
        max_iterations: solver iterations per stage.

    Raises:
        InvalidInputError: wrong shapes, inf, a view with fewer than 4 usable points, non-planar
            target.
        DegenerateGeometryError: e.g. all views fronto-parallel, or unconstrained parameters.
    """
    if image_size is None:
        raise InvalidInputError("image_size=(width, height) is required")
    w, h = _size(image_size)
    obj = _views(object_points, "object_points", 3)
    img = _views(image_points, "image_points", 2)
    init = None if initial_params is None else as_f64(initial_params, "initial_params")
    core = _core.calib_calibrate(
        obj,
        img,
        _model(model),
        w,
        h,
        sigma_z=None if sigma_z is None else as_float(sigma_z, "sigma_z"),
        loss=str(loss),
        loss_scale=None if loss_scale is None else as_float(loss_scale, "loss_scale"),
        outlier_threshold=None if outlier_threshold is None else float(outlier_threshold),
        bootstrap=bool(bootstrap),
        initial_params=init,
        max_iterations=as_int(max_iterations, "max_iterations"),
    )
    return Calibration(core)


def suggest_next_view(
    calibration: Calibration,
    candidates: ArrayLike | None = None,
    *,
    target: ArrayLike | None = None,
    samples: int = 100,
    grid: int = 5,
    seed: int = 0,
    grid_margin: float | None = None,
) -> Suggestion:
    """Suggest the next target pose (ch. 5.2-5.3).

    Every candidate pose (default: ~60 spread through the view frustum) is scored by the Max ERE
    after adding its predicted observations to the current information matrix; the best wins.
    Stop when :attr:`Calibration.max_ere` is below your threshold.

    Args:
        calibration: the current calibration.
        candidates: candidate poses ``T_ct`` (K, 4, 4); default :func:`candidate_poses`.
        target: target layout (N, 2); default the rows observed so far.
        samples: posterior samples of the Max ERE (common random numbers across candidates).
        grid: the Max ERE test grid is ``grid x grid`` pixels.
        seed: seed of the samples.
        grid_margin: outer ring of the test grid, fraction of the image size inside the border
            (default :data:`GRID_MARGIN`).
    """
    if not isinstance(calibration, Calibration):
        raise InvalidInputError(
            f"calibration must be a Calibration (from calibrate()), got {type(calibration).__name__}"
        )
    tgt = calibration.target() if target is None else as_f64(target, "target")
    cand = None if candidates is None else as_f64(candidates, "candidates").reshape(-1, 4, 4)
    d = calibration._core.suggest_next_view(
        np.ascontiguousarray(tgt),
        cand,
        as_int(samples, "samples"),
        as_int(grid, "grid"),
        as_int(seed, "seed"),
        _margin(grid_margin),
    )
    return Suggestion(
        pose=np.asarray(d["pose"]),
        pixels=np.asarray(d["pixels"]),
        target_index=[int(i) for i in d["target_index"]],
        expected_max_ere=float(d["expected_max_ere"]),
        current_max_ere=float(d["current_max_ere"]),
        index=int(d["index"]),
        scores=[float(s) for s in d["scores"]],
        candidates=np.asarray(d["candidates"]),
    )


@dataclass(frozen=True, slots=True)
class ModelChoice:
    """One entry of :func:`select_model`."""

    model: str
    bic: float
    calibration: Calibration | None
    error: str | None


def select_model(
    object_points: Any,
    image_points: Any,
    image_size: tuple[int, int],
    models: Sequence[str] = MODELS,
    *,
    sigma_z: float | None = None,
) -> list[ModelChoice]:
    """Calibrate each lens model on the same views and rank by BIC (best first)."""
    w, h = _size(image_size)
    obj = _views(object_points, "object_points", 3)
    img = _views(image_points, "image_points", 2)
    ranked = _core.calib_select_model(
        obj, img, [_model(m) for m in models], w, h, sigma_z=None if sigma_z is None else as_float(sigma_z, "sigma_z")
    )
    return [ModelChoice(m, float(b), None if c is None else Calibration(c), e) for m, c, b, e in ranked]


# -- simulation -------------------------------------------------------------------------------
LENSES: dict[str, dict[str, Any]] = {
    "narrow": {
        "model": "brown_conrady",
        "params": [900.0, 900.0, 322.0, 238.0, -0.12, 0.2, 0.0005, -0.0003, 0.0],
        "image_size": (640, 480),
        "fov_deg": 48.0,
    },
    "medium": {
        "model": "brown_conrady",
        "params": [420.0, 421.0, 318.0, 243.0, -0.30, 0.11, 0.0008, -0.0005, -0.018],
        "image_size": (640, 480),
        "fov_deg": 87.0,
    },
    "wide": {
        "model": "kannala_brandt",
        "params": [290.0, 290.5, 321.0, 239.0, 0.02, -0.004, 0.001, -0.0002],
        "image_size": (640, 480),
        "fov_deg": 110.0,
    },
    "fisheye140": {
        "model": "kannala_brandt",
        "params": [232.0, 232.0, 319.5, 240.5, -0.015, 0.003, -0.0005, 0.0],
        "image_size": (640, 480),
        "fov_deg": 140.0,
    },
}
"""Simulated lenses (diagonal field of view in ``fov_deg``): Brown-Conrady for the narrow and
medium lenses, Kannala-Brandt for the wide ones."""


def make_target(cols: int = 10, rows: int = 7, spacing: float = 0.03) -> F64Array:
    """A planar grid target: ``(cols*rows, 2)`` points in metres, row-major."""
    cols, rows = as_int(cols, "cols"), as_int(rows, "rows")
    s = as_float(spacing, "spacing")
    xs, ys = np.meshgrid(np.arange(cols) * s, np.arange(rows) * s)
    return np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)


def candidate_poses(model: str, params: ArrayLike, image_size: tuple[int, int], target: ArrayLike) -> F64Array:
    """~60 candidate target poses (K, 4, 4) through the view frustum of a camera.

    A 3 x 3 grid of image positions, at each five near poses (80 % of the field of view:
    fronto-parallel and tilted +-0.7 rad about either target axis) and two far ones (50 %,
    tilted +-0.5 rad about both axes).
    """
    w, h = _size(image_size)
    return np.asarray(
        _core.calib_candidate_poses(_model(model), as_f64(params, "params"), w, h, as_f64(target, "target"))
    )


def first_view_pose(model: str, params: ArrayLike, image_size: tuple[int, int], target: ArrayLike) -> F64Array:
    """The first target pose (4, 4) of a guided session, before any calibration can score candidates.

    The target at the image centre, near (80 % of the field of view), tilted 0.5 rad about both
    target axes so that one view constrains both focal lengths of the bootstrapping's restricted
    model (ch. 5.2).
    """
    w, h = _size(image_size)
    return np.asarray(
        _core.calib_first_view_pose(_model(model), as_f64(params, "params"), w, h, as_f64(target, "target"))
    )[0]


def random_poses(
    model: str,
    params: ArrayLike,
    image_size: tuple[int, int],
    target: ArrayLike,
    count: int,
    *,
    max_tilt: float = 0.7,
    seed: int = 0,
) -> F64Array:
    """``count`` random target poses (seeded): anywhere in the image, 20-60 % of the FOV, tilted."""
    w, h = _size(image_size)
    return np.asarray(
        _core.calib_random_poses(
            _model(model),
            as_f64(params, "params"),
            w,
            h,
            as_f64(target, "target"),
            as_int(count, "count"),
            max_tilt=as_float(max_tilt, "max_tilt"),
            seed=as_int(seed, "seed"),
        )
    )


def novice_poses(
    model: str, params: ArrayLike, image_size: tuple[int, int], target: ArrayLike, count: int, *, seed: int = 0
) -> F64Array:
    """``count`` poses (seeded) of a novice following ch. 5.4's ROS checklist (sides, close/far, tilts)."""
    w, h = _size(image_size)
    return np.asarray(
        _core.calib_novice_poses(
            _model(model),
            as_f64(params, "params"),
            w,
            h,
            as_f64(target, "target"),
            as_int(count, "count"),
            seed=as_int(seed, "seed"),
        )
    )


def simulate_view(
    model: str,
    params: ArrayLike,
    image_size: tuple[int, int],
    pose: ArrayLike,
    target: ArrayLike,
    *,
    sigma: float = 0.0,
    seed: int = 0,
) -> tuple[F64Array, F64Array, list[int]] | None:
    """Observe the target from ``pose``: ``(object (N, 3), image (N, 2), rows)`` or None (< 4 visible)."""
    w, h = _size(image_size)
    out = _core.calib_synthesize_view(
        _model(model),
        as_f64(params, "params"),
        w,
        h,
        as_f64(pose, "pose"),
        as_f64(target, "target"),
        sigma=as_float(sigma, "sigma"),
        seed=as_int(seed, "seed"),
    )
    if out is None:
        return None
    o, i, r = out
    return np.asarray(o), np.asarray(i), list(r)


@dataclass
class SessionStep:
    """State after one view of a simulated session."""

    views: int
    max_ere: float
    """Max ERE (Algorithm 5.1), inf while the bootstrapping still holds parameters fixed."""
    expected_max: float
    """Expected largest error over the same grid (:attr:`Calibration.expected_max_error`), inf likewise."""
    test_p995: float
    """99.5th-percentile test-set error against the true lens, poses fixed (ch. 5.5.3 protocol)."""
    test_mean: float
    """Mean of the same errors."""
    test_max: float
    """Largest of the same errors."""
    refit_p995: float
    """99.5th-percentile test-set reprojection error with the poses re-fit to noisy detections (ch. 5.5)."""
    refit_mean: float
    """Mean of the re-fit errors."""
    rms: float
    params: list[float]


@dataclass
class SessionResult:
    """A simulated calibration session (see :func:`simulate_session`)."""

    lens: str
    strategy: str
    threshold: float
    steps: list[SessionStep] = field(default_factory=list)
    calibration: Calibration | None = None

    @property
    def views_to_threshold(self) -> int | None:
        """First view count whose Max ERE is below the threshold (the stopping rule)."""
        return next((s.views for s in self.steps if s.max_ere < self.threshold), None)

    @property
    def views_to_test_1px(self) -> int | None:
        """First view count whose test-set 99.5th-percentile error is below 1 px."""
        return next((s.views for s in self.steps if s.test_p995 < 1.0), None)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "lens": self.lens,
            "strategy": self.strategy,
            "threshold": self.threshold,
            "views_to_threshold": self.views_to_threshold,
            "views_to_test_1px": self.views_to_test_1px,
            "steps": [s.__dict__ for s in self.steps],
        }


def _test_set(
    lens: dict[str, Any], target: F64Array, seed: int, count: int = 60, sigma: float = 0.0
) -> tuple[list, list, F64Array]:
    """Object points, detections (noise ``sigma``) and true poses of random views seeing >= 1/4 of the target."""
    poses = random_poses(lens["model"], lens["params"], lens["image_size"], target, count, max_tilt=0.7, seed=seed)
    obj, img, kept = [], [], []
    for k, p in enumerate(poses):
        v = simulate_view(lens["model"], lens["params"], lens["image_size"], p, target, sigma=sigma, seed=seed + k)
        if v is not None and len(v[2]) >= 0.25 * len(target):
            obj.append(v[0])
            img.append(v[1])
            kept.append(p)
    return obj, img, np.asarray(kept).reshape(-1, 4, 4)


STRATEGIES = ("guided", "random", "novice")
"""Simulated view-selection strategies of :func:`simulate_session`."""


def _session_step(
    calib: Calibration,
    views: int,
    truth: Any,
    test: tuple[F64Array, F64Array, F64Array],
    grid_margin: float | None,
) -> SessionStep:
    """The Max ERE and the test-set errors of a session's calibration after ``views`` views."""
    test_obj, test_img, test_poses = test
    if all(calib.free):
        st = calib.max_ere_stats(grid_margin=grid_margin)
        ere, emax = st.value, st.expected_max
    else:
        ere = emax = math.inf
    errs = calib.reference_errors(truth, test_obj, test_poses)
    refit = calib.test_errors(test_obj, test_img)
    return SessionStep(
        views=views,
        max_ere=ere,
        expected_max=emax,
        test_p995=float(np.percentile(errs, 99.5)),
        test_mean=float(errs.mean()),
        test_max=float(errs.max()),
        refit_p995=float(np.percentile(refit, 99.5)),
        refit_mean=float(refit.mean()),
        rms=calib.rms,
        params=calib.params.tolist(),
    )


@dataclass(frozen=True)
class SessionOptions:
    """Options of :func:`simulate_session` besides the lens, the strategy, the model and the seed.

    Attributes:
        threshold: Max ERE (pixels) the session aims at.
        max_views: Views at most.
        min_views: Views before the Max ERE may stop the session.
        sigma: Corner noise (pixels; default ``7e-5 ×`` the image width).
        pose_jitter: How loosely the simulated user achieves a suggested pose (radians, and
            relative distance).
        target: Target points (default :func:`make_target`).
        test_views: Views of the independent test set.
        test_noise: Add the corner noise to the test set's detections.
        stop_at_threshold: Stop once the Max ERE is below ``threshold`` after ``min_views``.
        grid_margin: The Max ERE test grid (default :data:`GRID_MARGIN`).
    """

    threshold: float = 0.5
    max_views: int = 12
    min_views: int = 3
    sigma: float | None = None
    pose_jitter: float = 0.03
    target: ArrayLike | None = None
    test_views: int = 60
    test_noise: bool = True
    stop_at_threshold: bool = False
    grid_margin: float | None = None


def simulate_session(
    lens: str = "medium",
    *,
    strategy: str = "guided",
    model: str | None = None,
    seed: int = 0,
    options: SessionOptions | None = None,
    callback: Any = None,
    **overrides: Any,
) -> SessionResult:
    """Simulate a calibration session on a known lens (the loop of ch. 5.2 with a simulated user).

    Strategies (:data:`STRATEGIES`):

    - ``"guided"``: the first view is :func:`first_view_pose` (a near target at the image centre
      tilted about both axes); afterwards the user
      achieves each suggestion of :func:`suggest_next_view` up to ``pose_jitter`` (radians and
      relative distance).
    - ``"random"``: poses drawn like the test set (anywhere in the image, 20-60 % of the field
      of view, tilted up to 0.7 rad, partial targets allowed).
    - ``"novice"``: the seed's novice (ch. 5.4): the ROS checklist (left, right, top, bottom,
      close, far, tilted) in random order, achieved loosely, and -- as with OpenCV's chessboard
      -- a view counts only when the whole target is visible.

    After each view the session records the Max ERE and the test-set errors on an independent
    ``test_views``-view test set: against the true lens along the true rays (``test_*``: the
    reference protocol of ch. 5.5.3 / Fig. 5.6, the quantity the Max ERE predicts) and with the
    poses re-fit to detections with noise (``refit_*``: ch. 5.5's protocol for real test sets
    without ground truth; ``test_noise=False`` drops the noise). ``grid_margin`` sets the Max ERE
    test grid (recorded and used by the guide; default :data:`GRID_MARGIN`). The options are a
    :class:`SessionOptions`; keyword ``overrides`` replace its fields by name.
    """
    o = checked_replace(options or SessionOptions(), "session", overrides)
    threshold, max_views, min_views, sigma = o.threshold, o.max_views, o.min_views, o.sigma
    pose_jitter, target, test_views, test_noise = o.pose_jitter, o.target, o.test_views, o.test_noise
    stop_at_threshold, grid_margin = o.stop_at_threshold, o.grid_margin
    if lens not in LENSES:
        raise InvalidInputError(f"unknown lens {lens!r}: use one of {', '.join(LENSES)}")
    if strategy not in STRATEGIES:
        raise InvalidInputError(f"strategy must be one of {', '.join(STRATEGIES)}, got {strategy!r}")
    from autoteach.geometry import Camera, se3_exp  # local import: geometry wrapper

    spec = LENSES[lens]
    fit_model = _model(model or spec["model"])
    w, h = spec["image_size"]
    truth = Camera(spec["model"], spec["params"], w, h)
    sig = 7e-5 * w if sigma is None else as_float(sigma, "sigma")
    tgt = make_target() if target is None else as_f64(target, "target")
    rng = np.random.default_rng(seed)
    test_obj, test_img, test_poses = _test_set(
        spec, tgt, seed=10_000 + seed, count=test_views, sigma=sig if test_noise else 0.0
    )
    if strategy == "novice":
        pool = novice_poses(spec["model"], spec["params"], spec["image_size"], tgt, 6 * max_views, seed=20_000 + seed)
    else:
        pool = random_poses(spec["model"], spec["params"], spec["image_size"], tgt, 4 * max_views, seed=20_000 + seed)
    need = len(tgt) if strategy == "novice" else 0.25 * len(tgt)
    result = SessionResult(lens=lens, strategy=strategy, threshold=threshold)
    obj: list[F64Array] = []
    img: list[F64Array] = []
    calib: Calibration | None = None
    k_pool = 0

    def observe(pose: F64Array) -> bool:
        v = simulate_view(
            spec["model"], spec["params"], spec["image_size"], pose, tgt, sigma=sig, seed=int(rng.integers(1 << 31))
        )
        if v is None or len(v[2]) < need:
            return False
        obj.append(v[0])
        img.append(v[1])
        return True

    def jitter(pose: F64Array) -> F64Array:
        if pose_jitter <= 0:
            return pose
        xi = np.concatenate(
            [rng.normal(0, pose_jitter, 3), rng.normal(0, pose_jitter * 0.5 * np.linalg.norm(pose[:3, 3]) / 3, 3)]
        )
        return pose @ np.asarray(se3_exp(xi))

    attempts = 0
    while len(obj) < max_views and attempts < 20 * max_views:
        attempts += 1
        if strategy == "guided" and not obj:
            if not observe(first_view_pose(spec["model"], spec["params"], spec["image_size"], tgt)):
                continue
        elif strategy != "guided" or calib is None:
            k_pool += 1
            if not observe(pool[(k_pool - 1) % len(pool)]):
                continue
        else:
            s = suggest_next_view(calib, target=tgt, seed=seed, grid_margin=grid_margin)
            if not observe(jitter(s.pose)) and not observe(s.pose):
                continue
        try:
            calib = calibrate(
                obj,
                img,
                fit_model,
                (w, h),
                sigma_z=sig,
                outlier_threshold=math.inf,
                initial_params=None if calib is None or len(obj) <= min_views else calib.params,
            )
        except Exception:  # noqa: BLE001 -- a simulated user keeps going while the model is unconstrained
            calib = None
            continue
        step = _session_step(calib, len(obj), truth, (test_obj, test_img, test_poses), grid_margin)
        result.steps.append(step)
        if callback is not None:
            callback(step)
        if stop_at_threshold and step.max_ere < threshold and len(obj) >= min_views:
            break
    result.calibration = calib
    return result
