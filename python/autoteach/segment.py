"""Coloured point clouds: camera-lidar co-registration and graph segmentation (seed 004 ch. 4).

- :func:`colorize` -- colour lidar points from a camera image through the camera model with
  extrinsics and distortion (eq. 4.1), with a z-buffer for occluded points.
- :func:`calibrate_extrinsics` -- ``T_cam_lidar`` from lidar-point / pixel correspondences by
  least squares (eq. 4.2) with its covariance.
- :func:`segment_colored_cloud` -- Felzenszwalb-Huttenlocher segmentation with a colour and a
  surface-normal criterion (eq. 4.3-4.5, Algorithm 4.1) on the scan-topology mesh of an
  organised ``(lines, beams, 3)`` cloud or on a k-nearest-neighbour graph of an ``(N, 3)`` cloud;
  :func:`segment_cloud` also returns the normals.
- :func:`simulate_scan` -- a tilting Hokuyo-like scanner and a camera in labelled scenes
  (``"hallway"``, ``"ramp"``, ``"hill"``) with ground truth.
- :func:`read_ply` / :func:`write_ply` -- PLY files, ASCII or binary little-endian (plain NumPy).
- :func:`adapted_rand_error` -- the segmentation error used to score against ground truth.

Colours are 8-bit RGB: ``uint8`` arrays, other integer arrays with values in 0-255, or float
arrays in [0, 1] (scaled by 255). Anything else raises
:class:`~autoteach.errors.InvalidInputError`.

Example:
    >>> from autoteach import segment
    >>> sim = segment.simulate_scan("hallway", seed=1)
    >>> points, colors = sim.cloud()
    >>> labels = segment.segment_colored_cloud(points, colors, graph="scan")
    >>> labels.shape == points.shape[:2]
    True

"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import F64Array, as_f64, as_float, as_int
from autoteach.errors import InvalidInputError

__all__ = [
    "SCENES",
    "STATUS",
    "CloudSegmentation",
    "Colorization",
    "ExtrinsicsFit",
    "PointCloud",
    "SimulatedScan",
    "adapted_rand_error",
    "as_colors",
    "calibrate_extrinsics",
    "label_colors",
    "colorize",
    "plot_segments",
    "read_ply",
    "segment_cloud",
    "segment_colored_cloud",
    "simulate_scan",
    "write_ply",
]

SCENES = ("hallway", "ramp", "hill")
"""The simulator's preset scenes."""

STATUS = ("colored", "missing", "behind", "outside", "occluded")
"""Meaning of :attr:`Colorization.status` codes 0-4."""

Criteria = Literal["both", "color", "normal"]


def as_colors(colors: ArrayLike, name: str = "colors") -> NDArray[np.uint8]:
    """Convert colours to ``uint8`` RGB, checking dtype and range.

    Args:
        colors: ``uint8``, other integer values in 0-255, or floats in [0, 1]; last axis 3.
        name: Argument name for error messages.

    Returns:
        A C-contiguous ``uint8`` array of the same shape.

    Raises:
        InvalidInputError: Non-numeric or boolean dtype, a last axis other than 3, integers
            outside 0-255, floats outside [0, 1] or not finite.

    """
    try:
        arr = np.asarray(colors)
    except (TypeError, ValueError) as err:
        raise InvalidInputError(f"{name} must be an array of RGB colours: {err}") from None
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise InvalidInputError(f"{name} must have shape (..., 3), got {arr.shape}")
    kind = arr.dtype.kind
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    if kind in "iu":
        if arr.size and (arr.min() < 0 or arr.max() > 255):
            raise InvalidInputError(
                f"{name} holds integers outside 0-255 (min {arr.min()}, max {arr.max()}); 8-bit RGB is expected"
            )
        return np.ascontiguousarray(arr, dtype=np.uint8)
    if kind == "f":
        if arr.size and not np.all(np.isfinite(arr)):
            raise InvalidInputError(f"{name} must be finite, got NaN or inf")
        if arr.size and (arr.min() < 0.0 or arr.max() > 1.0):
            raise InvalidInputError(
                f"float {name} must lie in [0, 1] (got min {arr.min():g}, max {arr.max():g}); "
                "pass uint8 for 0-255 values or divide by 255"
            )
        return np.ascontiguousarray(np.rint(arr * 255.0), dtype=np.uint8)
    raise InvalidInputError(f"{name} must be uint8 RGB (or floats in [0, 1]), got dtype {arr.dtype}")


def _points(points: ArrayLike, name: str = "points") -> F64Array:
    return np.ascontiguousarray(as_f64(points, name))


# --------------------------------------------------------------------------------------------
# Segmentation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CloudSegmentation:
    """The result of :func:`segment_cloud`."""

    labels: NDArray[np.int64]
    """Segment of every point (shape of the cloud without its last axis), ``0..num_segments``
    numbered by first point; -1 for missing (NaN) points of an organised cloud."""
    normals: F64Array
    """Unit normals used (estimated, oriented to the viewpoint, or given); zero where missing."""
    normal_ok: NDArray[np.bool_]
    """Whether each point has a normal (False where the neighbourhood was too small or missing)."""
    num_segments: int
    """Number of segments."""
    num_edges: int
    """Edges in the graph after the edge cut."""


def segment_cloud(
    points: ArrayLike,
    colors: ArrayLike,
    normals: ArrayLike | None = None,
    graph: Literal["scan", "knn"] = "scan",
    k_rgb: float = 9000.0,
    k_norm: float = 10.0,
    edge_cut: float = 0.25,
    min_size: int = 100,
    criteria: Criteria = "both",
    k: int = 8,
    viewpoint: ArrayLike = (0.0, 0.0, 0.0),
) -> CloudSegmentation:
    """Segment a coloured cloud by colour and surface normals (Algorithm 4.1).

    Defaults are Table 4.1's (Fig. 4.4e): edge cut 0.25 m, K_rgb 9000, K_norm 10, minsize 100.

    Args:
        points: ``(lines, beams, 3)`` organised cloud for ``graph="scan"`` (NaN rows: missing
            points, e.g. no return or no colour; they get label -1), or ``(N, 3)`` for
            ``graph="knn"`` (every point finite).
        colors: RGB of every point, shape of ``points`` (see :func:`as_colors`).
        normals: Optional unit normals of the shape of ``points``; estimated by local PCA over
            graph neighbours when omitted.
        graph: ``"scan"`` (the 8-neighbour scan mesh, §4.2) or ``"knn"``.
        k_rgb: K_rgb of eq. 4.3 (8-bit RGB distance x points).
        k_norm: K_norm (radians x points).
        edge_cut: Longest edge kept, metres.
        min_size: Segments smaller than this are merged into a neighbour.
        criteria: ``"both"`` (the seed's method), ``"color"`` or ``"normal"`` only.
        k: Neighbours per point of the k-NN graph.
        viewpoint: Sensor position in the cloud's frame; normals point towards it.

    Returns:
        The labels, normals and counts.

    Raises:
        InvalidInputError: Wrong shapes or dtypes, NaN points in an unorganised cloud,
            infinite values, an empty cloud, colours out of range, bad parameters.

    """
    pts = _points(points)
    cols = as_colors(colors)
    nrm = None if normals is None else _points(normals, "normals")
    if graph not in ("scan", "knn"):
        raise InvalidInputError(f"graph must be 'scan' or 'knn', got {graph!r}")
    if criteria not in ("both", "color", "normal"):
        raise InvalidInputError(f"criteria must be 'both', 'color' or 'normal', got {criteria!r}")
    out = _core.segment_colored_cloud(
        pts,
        cols,
        nrm,
        graph,
        as_int(k, "k"),
        as_float(k_rgb, "k_rgb"),
        as_float(k_norm, "k_norm"),
        as_float(edge_cut, "edge_cut"),
        as_int(min_size, "min_size"),
        criteria,
        as_f64(viewpoint, "viewpoint"),
    )
    return CloudSegmentation(
        out["labels"], out["normals"], out["normal_ok"], int(out["num_segments"]), int(out["num_edges"])
    )


def segment_colored_cloud(
    points: ArrayLike,
    colors: ArrayLike,
    normals: ArrayLike | None = None,
    graph: Literal["scan", "knn"] = "scan",
    k_rgb: float = 9000.0,
    k_norm: float = 10.0,
    edge_cut: float = 0.25,
    min_size: int = 100,
    criteria: Criteria = "both",
    k: int = 8,
    viewpoint: ArrayLike = (0.0, 0.0, 0.0),
) -> NDArray[np.int64]:
    """Segment labels of a coloured cloud; :func:`segment_cloud` with the same arguments, labels only."""
    return segment_cloud(
        points, colors, normals, graph, k_rgb, k_norm, edge_cut, min_size, criteria, k, viewpoint
    ).labels


# --------------------------------------------------------------------------------------------
# Co-registration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Colorization:
    """The result of :func:`colorize`."""

    colors: NDArray[np.uint8]
    """RGB of every point, ``(N, 3)`` (zero where not coloured)."""
    status: NDArray[np.uint8]
    """Per point: 0 coloured, 1 missing (NaN), 2 behind the camera, 3 outside the image,
    4 occluded (see :data:`STATUS`)."""

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Whether each point got a colour."""
        return self.status == 0


def _camera_inner(camera: Any) -> Any:
    inner = getattr(camera, "_inner", camera)
    if not isinstance(inner, _core.Camera):
        raise InvalidInputError(f"camera must be an autoteach.geometry.Camera, got {type(camera).__name__}")
    return inner


def colorize(
    points: ArrayLike,
    image: ArrayLike,
    camera: Any,
    T_cam_lidar: ArrayLike,  # noqa: N803
    splat_radius: int = 3,
    depth_tolerance: float = 0.1,
) -> Colorization:
    """Colour lidar points from an image (eq. 4.1), skipping occluded points.

    Args:
        points: Lidar-frame points ``(..., 3)``; NaN rows are missing points.
        image: ``(height, width, 3)`` RGB image (see :func:`as_colors`) of the camera's size.
        camera: An :class:`autoteach.geometry.Camera` (intrinsics and distortion).
        T_cam_lidar: 4x4 lidar -> camera transform.
        splat_radius: Half-width in pixels of each point's z-buffer footprint (about half the
            lidar point spacing in the image).
        depth_tolerance: Metres by which a point may lie behind the z-buffer and still count as
            visible.

    Returns:
        Colours and status, with the leading shape of ``points`` flattened to ``N``.

    """
    pts = _points(points)
    lead = pts.shape[:-1]
    cols, status = _core.colorize_points(
        pts.reshape(-1, 3),
        as_colors(image, "image"),
        _camera_inner(camera),
        as_f64(T_cam_lidar, "T_cam_lidar"),
        as_int(splat_radius, "splat_radius"),
        as_float(depth_tolerance, "depth_tolerance"),
    )
    return Colorization(cols.reshape(*lead, 3), status.reshape(lead))


@dataclass(frozen=True, slots=True)
class ExtrinsicsFit:
    """The result of :func:`calibrate_extrinsics`."""

    t_cam_lidar: F64Array
    """Estimated 4x4 lidar -> camera transform."""
    covariance: F64Array
    """6x6 covariance on the tangent ``[omega; rho]`` (rad, m) of the right perturbation
    ``T @ Exp(delta)``."""
    sigma: float
    """Pixel noise used (given, or estimated from the residuals)."""
    rms: float
    """RMS reprojection error in pixels."""
    iterations: int
    """Solver iterations."""
    converged: bool
    """Whether the solver met a convergence criterion."""

    @property
    def std(self) -> F64Array:
        """Standard deviations of ``[omega; rho]``."""
        return np.sqrt(np.diag(self.covariance))


def calibrate_extrinsics(
    camera: Any,
    points: ArrayLike,
    pixels: ArrayLike,
    initial: ArrayLike,
    sigma: float | None = None,
) -> ExtrinsicsFit:
    """Estimate ``T_cam_lidar`` from lidar points and the pixels where the camera sees them (eq. 4.2).

    Levenberg-Marquardt on SE(3) with the camera's intrinsics and distortion held fixed.

    Args:
        camera: The calibrated :class:`autoteach.geometry.Camera`.
        points: ``(N, 3)`` lidar-frame points (e.g. object corners), N >= 4.
        pixels: ``(N, 2)`` pixels of the same points.
        initial: 4x4 starting guess (e.g. from a tape measure).
        sigma: Pixel noise; estimated from the residuals when omitted.

    Returns:
        The estimate with its covariance.

    """
    out = _core.calibrate_lidar_camera(
        _camera_inner(camera),
        as_f64(points, "points"),
        as_f64(pixels, "pixels"),
        as_f64(initial, "initial"),
        None if sigma is None else as_float(sigma, "sigma"),
    )
    return ExtrinsicsFit(
        np.asarray(out["T_cam_lidar"], dtype=np.float64),
        out["covariance"],
        float(out["sigma"]),
        float(out["rms"]),
        int(out["iterations"]),
        bool(out["converged"]),
    )


# --------------------------------------------------------------------------------------------
# Simulation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SimulatedScan:
    """A simulated organised scan with its camera image and ground truth (:func:`simulate_scan`)."""

    points: F64Array
    """Measured points ``(lines, beams, 3)`` in the lidar frame; NaN where there is no return."""
    colors: NDArray[np.uint8]
    """Colours from the camera image through :func:`colorize` (or the true colours if the image
    was not rendered), ``(lines, beams, 3)``."""
    colored: NDArray[np.bool_]
    """Points that got a colour ``(lines, beams)``."""
    labels: NDArray[np.int64]
    """Ground-truth object labels ``(lines, beams)``; -1 where there is no return."""
    true_points: F64Array
    """Noise-free points."""
    true_normals: F64Array
    """Analytic surface normals (lidar frame)."""
    true_colors: NDArray[np.uint8]
    """The colour the camera would record at each point if it saw it."""
    image: NDArray[np.uint8] | None
    """The camera image ``(height, width, 3)``, if rendered."""
    camera: Any
    """The :class:`autoteach.geometry.Camera`."""
    T_cam_lidar: F64Array  # noqa: N815
    """Lidar -> camera."""
    T_world_lidar: F64Array  # noqa: N815
    """Lidar -> world (z up, floor at 0)."""
    object_names: dict[int, str] = field(default_factory=dict)
    """Ground-truth label -> object name."""

    def cloud(self, truth_colors: bool = False) -> tuple[F64Array, NDArray[np.uint8]]:
        """The organised cloud to segment: points (NaN where uncoloured) and colours.

        Args:
            truth_colors: Use :attr:`true_colors` and every return instead of the camera's colours.

        """
        if truth_colors:
            return self.points, self.true_colors
        pts = self.points.copy()
        pts[~self.colored] = np.nan
        return pts, self.colors


def simulate_scan(
    scene: str = "hallway",
    beam_step_deg: float = 0.75,
    tilt_start_deg: float = -10.0,
    tilt_end_deg: float = 50.0,
    tilt_speed_deg_s: float = 30.0,
    range_sigma: float = 0.01,
    color_sigma: float = 3.0,
    seed: int = 0,
    render: bool = True,
) -> SimulatedScan:
    """Simulate the seed's rig: a Hokuyo (270 deg, 40 Hz) nodded by a servo, and a camera.

    Defaults give the seed's downsampled 0.75 deg grid (Table 4.1); ``beam_step_deg=0.25`` is the
    Hokuyo's native resolution.

    Args:
        scene: ``"hallway"`` (Fig. 4.4a-h), ``"ramp"`` or ``"hill"`` (Fig. 4.4i-j).
        beam_step_deg: Angle between beams.
        tilt_start_deg: First servo angle (positive tilts down).
        tilt_end_deg: Last servo angle.
        tilt_speed_deg_s: Servo speed; planes are ``speed / 40 Hz`` apart.
        range_sigma: Range noise in metres.
        color_sigma: Pixel noise in 8-bit levels.
        seed: Random seed.
        render: Render the camera image and colour the points through it (else the true colours).

    Returns:
        The scan, image and ground truth.

    """
    from autoteach.geometry import Camera

    if scene not in SCENES:
        raise InvalidInputError(f"scene must be one of {', '.join(SCENES)}, got {scene!r}")
    seed = as_int(seed, "seed")
    if seed < 0:
        raise InvalidInputError(f"seed must be non-negative, got {seed}")
    d = _core.simulate_colored_scan(
        scene,
        as_float(beam_step_deg, "beam_step_deg"),
        as_float(tilt_start_deg, "tilt_start_deg"),
        as_float(tilt_end_deg, "tilt_end_deg"),
        as_float(tilt_speed_deg_s, "tilt_speed_deg_s"),
        as_float(range_sigma, "range_sigma"),
        as_float(color_sigma, "color_sigma"),
        seed,
        bool(render),
    )
    w, h = d["camera_size"]
    camera = Camera("brown_conrady", np.asarray(d["camera_params"]), int(w), int(h))
    T_cam_lidar = np.asarray(d["T_cam_lidar"], dtype=np.float64)  # noqa: N806
    image = d.get("image")
    if image is not None:
        col = colorize(d["points"], image, camera, T_cam_lidar)
        colors, colored = col.colors, col.valid
    else:
        colors, colored = d["true_colors"], d["labels"] >= 0
    return SimulatedScan(
        points=d["points"],
        colors=colors,
        colored=colored,
        labels=d["labels"],
        true_points=d["true_points"],
        true_normals=d["true_normals"],
        true_colors=d["true_colors"],
        image=image,
        camera=camera,
        T_cam_lidar=T_cam_lidar,
        T_world_lidar=np.asarray(d["T_world_lidar"], dtype=np.float64),
        object_names={int(k): str(v) for k, v in d["object_names"]},
    )


# --------------------------------------------------------------------------------------------
# Scoring
# --------------------------------------------------------------------------------------------


def adapted_rand_error(truth: ArrayLike, labels: ArrayLike, ignore: tuple[int, ...] = (-1,)) -> float:
    """Adapted Rand error ``1 - F`` of pair precision and recall (SNEMI3D; scikit-image's metric).

    Points whose ``truth`` label is in ``ignore`` are left out, as scikit-image's
    ``ignore_labels``.

    Args:
        truth: Ground-truth labels (integers).
        labels: Segment labels of the same shape.
        ignore: Truth labels to leave out.

    Returns:
        The error in [0, 1]; 0 is a perfect segmentation.

    """
    t = np.asarray(truth).ravel()
    s = np.asarray(labels).ravel()
    if t.shape != s.shape:
        raise InvalidInputError(f"truth and labels must have the same size, got {t.size} and {s.size}")
    keep = ~np.isin(t, np.asarray(ignore))
    t, s = t[keep], s[keep]
    if t.size == 0:
        raise InvalidInputError("no points left to score")
    _, ti = np.unique(t, return_inverse=True)
    _, si = np.unique(s, return_inverse=True)
    pair = ti.astype(np.int64) * (int(si.max()) + 1) + si
    _, counts = np.unique(pair, return_counts=True)
    n = float(t.size)
    sum_p_ij = float(np.sum(counts.astype(np.float64) ** 2)) - n
    a = np.bincount(ti).astype(np.float64)
    b = np.bincount(si).astype(np.float64)
    sum_a = float(np.sum(a**2)) - n
    sum_b = float(np.sum(b**2)) - n
    if sum_a == 0.0 or sum_b == 0.0:
        return 0.0 if sum_p_ij == sum_a == sum_b else 1.0
    precision = sum_p_ij / sum_b
    recall = sum_p_ij / sum_a
    return 1.0 - 2.0 * precision * recall / (precision + recall)


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


@dataclass(frozen=True, slots=True)
class PointCloud:
    """A point cloud read by :func:`read_ply`."""

    points: F64Array
    """``(N, 3)`` float64 ``x, y, z``."""
    colors: NDArray[np.uint8] | None = None
    """``(N, 3)`` ``red, green, blue`` if present."""
    normals: F64Array | None = None
    """``(N, 3)`` ``nx, ny, nz`` if present."""
    labels: NDArray[np.int64] | None = None
    """``(N,)`` ``label`` if present."""
    properties: dict[str, np.ndarray] = field(default_factory=dict)
    """Every vertex property by name."""


def write_ply(
    path: str | Path,
    points: ArrayLike,
    colors: ArrayLike | None = None,
    normals: ArrayLike | None = None,
    labels: ArrayLike | None = None,
    binary: bool = True,
) -> None:
    """Write a point cloud as PLY (binary little-endian or ASCII).

    Rows with a NaN coordinate (missing points of an organised cloud) are dropped. Properties:
    ``x y z`` (double), ``red green blue`` (uchar), ``nx ny nz`` (float), ``label`` (int).

    Args:
        path: Output file.
        points: ``(..., 3)`` coordinates.
        colors: Optional RGB of the same leading shape (see :func:`as_colors`).
        normals: Optional normals.
        labels: Optional integer labels of the leading shape.
        binary: Binary little-endian (default) or ASCII.

    """
    pts = _points(points).reshape(-1, 3)
    n = len(pts)
    fields: list[tuple[str, str, np.ndarray]] = [
        ("x", "f8", pts[:, 0]),
        ("y", "f8", pts[:, 1]),
        ("z", "f8", pts[:, 2]),
    ]

    def rows(arr: np.ndarray, name: str, cols: int) -> np.ndarray:
        out = arr.reshape(-1, cols) if cols > 1 else arr.reshape(-1)
        if len(out) != n:
            raise InvalidInputError(f"{name} has {len(out)} rows, points has {n}")
        return out

    if colors is not None:
        c = rows(as_colors(colors), "colors", 3)
        fields += [("red", "u1", c[:, 0]), ("green", "u1", c[:, 1]), ("blue", "u1", c[:, 2])]
    if normals is not None:
        nr = rows(_points(normals, "normals"), "normals", 3).astype(np.float32)
        fields += [("nx", "f4", nr[:, 0]), ("ny", "f4", nr[:, 1]), ("nz", "f4", nr[:, 2])]
    if labels is not None:
        lab = np.asarray(labels)
        if lab.dtype.kind not in "iu":
            raise InvalidInputError(f"labels must be integers, got dtype {lab.dtype}")
        fields.append(("label", "i4", rows(lab.astype(np.int32), "labels", 1)))
    keep = ~np.isnan(pts).any(axis=1)
    dtype = np.dtype([(name, "<" + t) for name, t, _ in fields])
    table = np.empty(int(keep.sum()), dtype=dtype)
    for name, _, col in fields:
        table[name] = col[keep]
    ply_name = {"f8": "double", "f4": "float", "u1": "uchar", "i4": "int"}
    header = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "comment autoteach"]
    header.append(f"element vertex {len(table)}")
    header += [f"property {ply_name[t]} {name}" for name, t, _ in fields]
    header.append("end_header")
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        if binary:
            f.write(table.tobytes())
        else:
            fmt = " ".join("%.17g" if t[0] == "f" else "%d" for _, t, _ in fields)
            np.savetxt(f, table, fmt=fmt)


def read_ply(path: str | Path) -> PointCloud:
    """Read the vertices of a PLY file (ASCII, binary little- or big-endian).

    The vertex element must come first (as every point-cloud writer puts it); other elements
    after it are ignored.

    Args:
        path: The file.

    Returns:
        Points, and colours / normals / labels when the file has them.

    Raises:
        InvalidInputError: Not a PLY file, an unsupported layout, or a truncated body.

    """
    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise InvalidInputError(f"{path}: not a PLY file (no 'ply' magic or 'end_header')")
    body_start = data.index(b"\n", end) + 1
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    fmt = None
    count = None
    props: list[tuple[str, str]] = []
    element = None
    for line in lines[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            if element == "vertex":
                break
            element = tok[1]
            if element != "vertex":
                raise InvalidInputError(f"{path}: element {element!r} before 'vertex' is not supported")
            count = int(tok[2])
        elif tok[0] == "property" and element == "vertex":
            if tok[1] == "list":
                raise InvalidInputError(f"{path}: list properties in 'vertex' are not supported")
            if tok[1] not in _PLY_TYPES:
                raise InvalidInputError(f"{path}: unknown property type {tok[1]!r}")
            props.append((tok[2], _PLY_TYPES[tok[1]]))
    if count is None or fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InvalidInputError(f"{path}: missing vertex element or unsupported format {fmt!r}")
    names = [p for p, _ in props]
    if not all(c in names for c in ("x", "y", "z")):
        raise InvalidInputError(f"{path}: vertex has no x, y, z properties ({names})")
    if fmt == "ascii":
        text = data[body_start:].decode("ascii", errors="replace").splitlines()
        if len(text) < count:
            raise InvalidInputError(f"{path}: {len(text)} vertex lines, header says {count}")
        table = np.loadtxt(text[:count], ndmin=2) if count else np.zeros((0, len(props)))
        if table.shape[1] < len(props):
            raise InvalidInputError(f"{path}: vertex lines have {table.shape[1]} values, expected {len(props)}")
        cols = {name: table[:, i].astype(t) for i, (name, t) in enumerate(props)}
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        dtype = np.dtype([(name, order + t) for name, t in props])
        need = dtype.itemsize * count
        if len(data) - body_start < need:
            raise InvalidInputError(f"{path}: truncated body ({len(data) - body_start} bytes, need {need})")
        table = np.frombuffer(data, dtype=dtype, count=count, offset=body_start)
        cols = {name: np.asarray(table[name]).astype(np.dtype(t).newbyteorder("=")) for name, t in props}

    def stack(keys: tuple[str, ...]) -> np.ndarray | None:
        return np.column_stack([cols[k] for k in keys]) if all(k in cols for k in keys) else None

    pts = stack(("x", "y", "z"))
    rgb = stack(("red", "green", "blue"))
    nrm = stack(("nx", "ny", "nz"))
    return PointCloud(
        points=np.asarray(pts, dtype=np.float64),
        colors=None if rgb is None else as_colors(rgb),
        normals=None if nrm is None else nrm.astype(np.float64),
        labels=None if "label" not in cols else cols["label"].astype(np.int64),
        properties=cols,
    )


# --------------------------------------------------------------------------------------------
# Plot
# --------------------------------------------------------------------------------------------


def label_colors(labels: ArrayLike, seed: int = 0) -> NDArray[np.uint8]:
    """A distinct random colour per segment label (grey for -1), shape ``labels.shape + (3,)``."""
    lab = np.asarray(labels)
    rng = np.random.default_rng(seed)
    top = int(lab.max()) + 1 if lab.size and lab.max() >= 0 else 0
    palette = rng.integers(40, 256, size=(top + 1, 3), dtype=np.int64).astype(np.uint8)
    palette[-1] = 128
    return palette[np.where(lab >= 0, lab, top)]


def plot_segments(
    points: ArrayLike,
    labels: ArrayLike,
    path: str | Path,
    colors: ArrayLike | None = None,
    title: str = "",
) -> None:
    """Write a PNG: the segments (false colour) seen from above, and the true colours if given.

    Needs matplotlib (the ``plot`` extra: ``pip install 'autoteach[plot]'``).

    Args:
        points: ``(..., 3)`` points (NaN rows skipped).
        labels: Labels of the leading shape.
        path: PNG file to write.
        colors: Optional RGB of the points for a second panel.
        title: Figure title.

    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("plot_segments needs matplotlib: pip install 'autoteach[plot]'") from err
    pts = _points(points).reshape(-1, 3)
    lab = np.asarray(labels).reshape(-1)
    keep = ~np.isnan(pts).any(axis=1) & (lab >= 0)
    panels = [("segments", label_colors(lab)[keep])]
    if colors is not None:
        panels.append(("colour", as_colors(colors).reshape(-1, 3)[keep]))
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 5), squeeze=False)
    for ax, (name, c) in zip(axes[0], panels, strict=True):
        # A view from the sensor: azimuth and elevation of each point.
        p = pts[keep]
        az = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
        el = np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))
        ax.scatter(-az, el, c=c / 255.0, s=2, marker="s", linewidths=0)
        ax.set_title(name)
        ax.set_xlabel("azimuth [deg] (right +)")
        ax.set_ylabel("elevation [deg]")
        ax.set_aspect("equal")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
