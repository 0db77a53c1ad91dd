"""Occupancy-grid rasterization for robot teams (seed 004_815695db12a6b16c.txt ch. 2).

- :class:`Rasterizer` -- turns a sequence of SLAM graphs (node ids, robot ids, posterior poses
  ``(n, 3)`` as ``[x, y, theta]``, and each new node's laser scan) into ternary occupancy grids with
  the three methods of Table 2.1: ``"naive_composite"`` (every node, every time),
  ``"naive_cover_composite"`` (the node cover of section 2.4, every time) and ``"cover_composite"``
  (Algorithm 2.1: slices of ``slice_size`` sequential cover nodes per robot, a slice re-rendered
  only when a member's projection moved; per-cell log-odds voting removes transient objects,
  section 2.5). After each update :attr:`Rasterizer.last_report` says how many slices were
  regenerated and how many nodes composited.
- :class:`OccupancyGrid` -- free / structure / unknown cells (ROS ``nav_msgs/OccupancyGrid``
  values 0 / 100 / -1), with PGM + YAML export and import in the ROS ``map_server`` / nav2
  convention, and PNG export.
- :class:`TeamSimulator` -- the embedded team simulator: a world of buildings, doorways, streets
  and yards at Table 2.2's sizes, 10-14 robots with a 270 degree, 1081-beam laser, drifting
  odometry, loop closures within and between robots, people and vehicles moving through; every
  10 s of mission time a :class:`GraphSnapshot` with the pose graph solved by the project's sparse
  least squares (SE(2) blocks) and the ground truth.
- :func:`wall_gaps` -- the connectivity check along every true wall (section 2.6.1).

Range data: ``NaN`` marks an invalid return (the beam is dropped and counted), ``+inf`` or a range at
or beyond ``max_range`` is a no-return (free space up to ``max_range``); negative ranges are errors.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64
from autoteach.errors import InvalidInputError
from autoteach.options import checked_replace

UNKNOWN = -1
"""Cell value of unobserved space."""
FREE = 0
"""Cell value of known free space."""
OCCUPIED = 100
"""Cell value of structure."""

METHODS = ("naive_composite", "naive_cover_composite", "cover_composite")
WORLDS = ("showgrounds", "keswick", "small")

# Pixel values of map_server's trinary PGM (map_saver): free 254, occupied 0, unknown 205.
_PGM_FREE, _PGM_OCCUPIED, _PGM_UNKNOWN = 254, 0, 205


@dataclass(frozen=True, slots=True)
class UpdateReport:
    """What one :meth:`Rasterizer.update` did (the quantities of Fig. 2.8)."""

    nodes: int
    new_nodes: int
    cover_nodes: int
    slices: int
    slices_regenerated: int
    nodes_rasterized: int
    nodes_composited: int
    dropped_beams: int
    seconds: float


@dataclass
class OccupancyGrid:
    """A ternary occupancy grid.

    Attributes:
        cells: ``(height, width)`` int8 array of :data:`FREE`, :data:`OCCUPIED`, :data:`UNKNOWN`;
            row 0 is the LOWEST y (the ROS ``OccupancyGrid`` layout).
        resolution: metres per cell.
        origin: world ``(x, y)`` of the lower-left corner of cell ``(0, 0)``.
    """

    cells: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``."""
        return (int(self.cells.shape[0]), int(self.cells.shape[1]))

    def counts(self) -> dict[str, int]:
        """Number of free, occupied and unknown cells."""
        c = self.cells
        return {
            "free": int(np.count_nonzero(c == FREE)),
            "occupied": int(np.count_nonzero(c == OCCUPIED)),
            "unknown": int(np.count_nonzero(c == UNKNOWN)),
        }

    def at(self, x: float, y: float) -> int | None:
        """The cell value at world point ``(x, y)``, ``None`` outside the grid."""
        col = math.floor((x - self.origin[0]) / self.resolution)
        row = math.floor((y - self.origin[1]) / self.resolution)
        h, w = self.shape
        if not (0 <= col < w and 0 <= row < h):
            return None
        return int(self.cells[row, col])

    def to_image(self) -> NDArray[np.uint8]:
        """8-bit grey image, top row = highest y: free 254, occupied 0, unknown 205."""
        img = np.full(self.cells.shape, _PGM_UNKNOWN, dtype=np.uint8)
        img[self.cells == FREE] = _PGM_FREE
        img[self.cells == OCCUPIED] = _PGM_OCCUPIED
        return np.ascontiguousarray(img[::-1])

    def save(self, stem: str | Path) -> tuple[Path, Path]:
        """Write ``stem.pgm`` and ``stem.yaml`` (ROS ``map_server`` / nav2 map format).

        Returns:
            The two paths.
        """
        stem = Path(stem)
        pgm, yaml = stem.with_suffix(".pgm"), stem.with_suffix(".yaml")
        img = self.to_image()
        h, w = img.shape
        pgm.write_bytes(f"P5\n# autoteach occupancy grid\n{w} {h}\n255\n".encode("ascii") + img.tobytes())
        yaml.write_text(
            f"image: {pgm.name}\n"
            f"mode: trinary\n"
            f"resolution: {self.resolution!r}\n"
            f"origin: [{self.origin[0]!r}, {self.origin[1]!r}, 0.0]\n"
            f"negate: 0\n"
            f"occupied_thresh: 0.65\n"
            f"free_thresh: 0.196\n",
            encoding="utf-8",
        )
        return pgm, yaml

    def to_png(self, path: str | Path) -> Path:
        """Write the map as an 8-bit greyscale PNG (same grey levels as the PGM)."""
        path = Path(path)
        img = self.to_image()
        h, w = img.shape
        raw = b"".join(b"\x00" + img[r].tobytes() for r in range(h))

        def chunk(kind: bytes, data: bytes) -> bytes:
            return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

        png = (
            b"\x89PNG\r\n\x1a\n"
            + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6))
            + chunk(b"IEND", b"")
        )
        path.write_bytes(png)
        return path

    @classmethod
    def load(cls, yaml_path: str | Path) -> OccupancyGrid:
        """Read a map_server YAML + PGM pair (trinary or scale mode, ``negate`` honoured).

        Raises:
            InvalidInputError: a missing key, an unreadable PGM, or an unsupported PGM variant.
        """
        yaml_path = Path(yaml_path)
        meta = _parse_map_yaml(yaml_path.read_text(encoding="utf-8"), yaml_path)
        img = _read_pgm(yaml_path.parent / str(meta["image"]))
        p = img.astype(np.float64) / 255.0
        occ = p if int(meta.get("negate", 0)) else 1.0 - p
        cells = np.full(img.shape, UNKNOWN, dtype=np.int8)
        cells[occ > float(meta["occupied_thresh"])] = OCCUPIED
        cells[occ < float(meta["free_thresh"])] = FREE
        origin = meta["origin"]
        if not isinstance(origin, list) or len(origin) < 2:
            raise InvalidInputError(f"{yaml_path}: origin must be [x, y, yaw], got {origin!r}")
        return cls(np.ascontiguousarray(cells[::-1]), float(meta["resolution"]), (float(origin[0]), float(origin[1])))


def _parse_map_yaml(text: str, path: Path) -> dict[str, Any]:
    meta: dict[str, Any] = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or ":" not in line:
            continue
        key, value = (s.strip() for s in line.split(":", 1))
        if value.startswith("["):
            meta[key] = [float(v) for v in value.strip("[]").split(",") if v.strip()]
        else:
            meta[key] = value.strip("'\"")
    for key in ("image", "resolution", "origin", "occupied_thresh", "free_thresh"):
        if key not in meta:
            raise InvalidInputError(f"{path}: missing key {key!r}")
    return meta


def _read_pgm(path: Path) -> NDArray[np.uint8]:
    data = path.read_bytes()
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            while pos < len(data) and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace():
            pos += 1
        if start == pos:
            raise InvalidInputError(f"{path}: truncated PGM header")
        tokens.append(data[start:pos])
    if tokens[0] != b"P5" or int(tokens[3]) != 255:
        raise InvalidInputError(f"{path}: only binary 8-bit PGM (P5, maxval 255) is supported")
    w, h = int(tokens[1]), int(tokens[2])
    body = data[pos + 1 : pos + 1 + w * h]
    if len(body) != w * h:
        raise InvalidInputError(f"{path}: expected {w * h} pixels, found {len(body)}")
    return np.frombuffer(body, dtype=np.uint8).reshape(h, w)


def _ids(value: ArrayLike, name: str) -> NDArray[np.int64]:
    arr = np.asarray(value)
    if arr.ndim != 1:
        raise InvalidInputError(f"{name} must be one-dimensional, got shape {arr.shape}")
    # An empty list comes as float64; any other non-integer dtype (complex, bool, object) is refused.
    if arr.dtype.kind not in "iu" and not (arr.size == 0 and arr.dtype.kind == "f"):
        raise InvalidInputError(f"{name} must hold integers, got dtype {arr.dtype}")
    if arr.dtype.kind == "u" and arr.size and arr.max() > np.iinfo(np.int64).max:
        raise InvalidInputError(f"{name} must fit in int64, got {arr.max()}")
    return np.ascontiguousarray(arr, dtype=np.int64)


@dataclass(frozen=True)
class RasterizerOptions:
    """The node covering, the laser and the occupancy model of a :class:`Rasterizer`.

    Attributes:
        covering: whether CoverComposite drops redundant nodes (section 2.4).
        cover_distance: a node is redundant if a covered node of its robot lies within this many
            metres ...
        cover_angle: ... and its heading within this many radians.
        fov: laser field of view (rad), centred on the heading; with ``beams`` it fixes the beam
            angles ``-fov/2 + k * fov / (beams - 1)``.
        beams: beams per scan.
        max_range: laser range (m); returns at or beyond it are no-returns.
        p_hit: probability that structure returns a hit (log-odds vote ``ln(p/(1-p))`` per hit).
        p_miss: probability that a beam passes a structure cell (vote per pass-through).
        prior: prior log-odds of structure.
        threshold: a cell is structure iff its log-odds exceeds this.
    """

    covering: bool = True
    cover_distance: float = 0.75
    cover_angle: float = math.radians(30.0)
    fov: float = math.radians(270.0)
    beams: int = 1081
    max_range: float = 30.0
    p_hit: float = 0.7
    p_miss: float = 0.4
    prior: float = 0.0
    threshold: float = 0.0

    def validate(self) -> None:
        """Check the beam count and the probabilities.

        Raises:
            InvalidInputError: fewer than 2 beams, or a probability outside (0, 1).
        """
        if isinstance(self.beams, bool) or not isinstance(self.beams, int) or self.beams < 2:
            raise InvalidInputError(f"beams must be an integer >= 2, got {self.beams!r}")
        for name, p in (("p_hit", self.p_hit), ("p_miss", self.p_miss)):
            if not (0.0 < float(p) < 1.0):
                raise InvalidInputError(f"{name} must be in (0, 1), got {p!r}")


class Rasterizer:
    """Rasterizes a sequence of SLAM graphs into occupancy grids (Table 2.1, Algorithm 2.1).

    Args:
        method: ``"cover_composite"`` (default), ``"naive_cover_composite"`` or ``"naive_composite"``.
        slice_size: N, sequential cover nodes of one robot per slice (CoverComposite).
        resolution: metres per cell.
        options: the covering, laser and occupancy model (:class:`RasterizerOptions`); keyword
            ``overrides`` replace its fields by name (``Rasterizer(beams=5, fov=...)``).
    """

    def __init__(
        self,
        method: str = "cover_composite",
        slice_size: int = 4,
        resolution: float = 0.1,
        *,
        options: RasterizerOptions | None = None,
        **overrides: Any,
    ) -> None:
        if method not in METHODS:
            raise InvalidInputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        o = checked_replace(options or RasterizerOptions(), "rasterizer", overrides)
        o.validate()
        if isinstance(slice_size, bool) or not isinstance(slice_size, int) or slice_size < 1:
            raise InvalidInputError(f"slice_size must be a positive integer, got {slice_size!r}")
        self.method = method
        self.options = o
        self.beams = o.beams
        self._inner = _core.Rasterizer(
            method,
            slice_size,
            float(resolution),
            bool(o.covering),
            float(o.cover_distance),
            float(o.cover_angle),
            -float(o.fov) / 2.0,
            float(o.fov) / (o.beams - 1),
            float(o.max_range),
            math.log(o.p_hit / (1.0 - o.p_hit)),
            math.log(o.p_miss / (1.0 - o.p_miss)),
            float(o.prior),
            float(o.threshold),
        )
        self.last_report: UpdateReport | None = None

    def update(
        self,
        node_ids: ArrayLike,
        robot_ids: ArrayLike,
        poses: ArrayLike,
        scans: ArrayLike | Sequence[ArrayLike | None] | Mapping[int, ArrayLike],
    ) -> OccupancyGrid:
        """Rasterize the next graph.

        Args:
            node_ids: ``(n,)`` integer ids, unique and stable across updates; every node of the previous
                graph must be present (graphs grow).
            robot_ids: ``(n,)`` the robot of each node.
            poses: ``(n, 3)`` ML posteriors ``[x, y, theta]`` (finite).
            scans: ranges of the nodes: an ``(n, beams)`` array, a sequence of length n (``None`` for
                nodes already seen), or a mapping ``{node_id: ranges}`` holding at least the new nodes.
                Scans of nodes seen before are ignored.

        Returns:
            The map. :attr:`last_report` tells what the update did.

        Raises:
            InvalidInputError: wrong shapes, NaN/inf poses, repeated, vanished or re-assigned node ids,
                a new node without a scan, negative ranges, or an empty graph.
        """
        ids = _ids(node_ids, "node_ids")
        robots = _ids(robot_ids, "robot_ids")
        p = as_f64(poses, "poses")
        rows, stack = self._scans(ids, scans)
        cells, ox, oy, res, rep = self._inner.update(ids, robots, p, rows, stack)
        self.last_report = UpdateReport(**rep)
        return OccupancyGrid(cells, res, (ox, oy))

    def _scans(self, ids: NDArray[np.int64], scans: Any) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        if isinstance(scans, Mapping):
            pos = {int(v): k for k, v in enumerate(ids)}
            rows = [pos[int(k)] for k in scans if int(k) in pos]
            data = [as_f64(scans[k], "scans").ravel() for k in scans if int(k) in pos]
        elif isinstance(scans, np.ndarray) and scans.ndim == 2:
            return np.arange(scans.shape[0], dtype=np.int64), as_f64(scans, "scans")
        else:
            if isinstance(scans, (str, bytes)) or not hasattr(scans, "__len__") or getattr(scans, "ndim", 1) == 0:
                raise InvalidInputError(
                    "scans must be an (n, beams) array, a sequence of n ranges or a mapping, "
                    f"got {type(scans).__name__}"
                )
            if len(scans) != len(ids):
                raise InvalidInputError(f"scans must have one entry per node ({len(ids)}), got {len(scans)}")
            rows = [k for k, s in enumerate(scans) if s is not None]
            data = [as_f64(scans[k], "scans").ravel() for k in rows]
        if not data:
            return np.zeros(0, dtype=np.int64), np.zeros((0, self.beams))
        lengths = {d.shape[0] for d in data}
        if len(lengths) != 1:
            raise InvalidInputError(f"every scan must have the same number of beams, got {sorted(lengths)}")
        return np.asarray(rows, dtype=np.int64), np.stack(data)

    @property
    def memory_bytes(self) -> int:
        """Approximate bytes held (stored scans, cached slices, map buffers)."""
        return int(self._inner.memory_bytes())

    @property
    def num_nodes(self) -> int:
        """Nodes seen so far."""
        return int(self._inner.num_nodes())


@dataclass
class GraphSnapshot:
    """One graph G_i of a simulated stream (every 10 s of mission time).

    Attributes:
        index: i.
        time: mission time (s).
        node_ids, robot_ids: ``(n,)``; the last ``new_nodes`` are new in this graph.
        poses: ``(n, 3)`` ML posteriors from the sparse least-squares solve.
        truth: ``(n, 3)`` ground-truth poses.
        edges: ``(m, 2)`` node ids ``(from, to)``; ``edge_kinds`` 0 prior, 1 odometry, 2 loop closure;
            ``edge_z`` ``(m, 3)`` the measured pose of ``to`` in the frame of ``from``; ``edge_cov``
            ``(m, 3, 3)``.
        new_scans: ``(new_nodes, beams)`` ranges of the new nodes (+inf = no return).
    """

    index: int
    time: float
    node_ids: NDArray[np.int64]
    robot_ids: NDArray[np.int64]
    poses: NDArray[np.float64]
    truth: NDArray[np.float64]
    new_nodes: int
    edges: NDArray[np.int64]
    edge_kinds: NDArray[np.int64]
    edge_z: NDArray[np.float64]
    edge_cov: NDArray[np.float64]
    new_closures: int
    solver_iterations: int
    solve_seconds: float
    new_scans: NDArray[np.float64] = field(repr=False, default_factory=lambda: np.zeros((0, 0)))

    def scans_by_row(self) -> list[NDArray[np.float64] | None]:
        """Per node: its ranges if new in this graph, else ``None`` (the form :meth:`Rasterizer.update` takes)."""
        n = len(self.node_ids)
        first = n - self.new_nodes
        return [None] * first + list(self.new_scans)


class TeamSimulator:
    """The embedded robot-team mapping simulator (see the module docstring).

    Args:
        world: ``"showgrounds"`` (220 x 160 m, 14 robots, 429 graphs), ``"keswick"`` (150 x 150 m,
            10 robots, 68 graphs) or ``"small"`` (60 x 50 m, 3 robots, 12 graphs, 15 m laser).
        robots: robots (default: the world's).
        graphs: graphs in the stream (default: the world's).
        seed: random seed (world layout, motion, noise).
        transients: whether people and vehicles are visible to the lasers (their motion is simulated
            either way, so streams with and without them have identical graphs).
        people, vehicles: transient objects (default: the world's).
        max_range: laser range (m).
    """

    def __init__(
        self,
        world: str = "showgrounds",
        *,
        robots: int | None = None,
        graphs: int | None = None,
        seed: int = 0,
        transients: bool = True,
        people: int | None = None,
        vehicles: int | None = None,
        max_range: float | None = None,
    ) -> None:
        if world not in WORLDS:
            raise InvalidInputError(f"world must be one of {', '.join(WORLDS)}, got {world!r}")
        self.world = world
        self._inner = _core.TeamSimulator(
            world, robots, graphs, int(seed), bool(transients), people, vehicles, max_range
        )
        self.angle_min, self.angle_increment, self.max_range = self._inner.scan_geometry()
        self.graphs: int = int(self._inner.graphs())

    def __iter__(self) -> Iterator[GraphSnapshot]:
        while (g := self.step()) is not None:
            yield g

    def step(self) -> GraphSnapshot | None:
        """Advance 10 s of mission time; the next graph, or ``None`` at the end of the stream."""
        d = self._inner.step()
        if d is None:
            return None
        new = d["node_ids"][len(d["node_ids"]) - d["new_nodes"] :]
        scans = self._inner.ranges(np.ascontiguousarray(new)) if len(new) else np.zeros((0, 0))
        return GraphSnapshot(new_scans=scans, **d)

    @property
    def walls(self) -> NDArray[np.float64]:
        """Ground-truth walls, ``(m, 4)`` rows ``[x0, y0, x1, y1]``."""
        return self._inner.walls()

    @property
    def extent(self) -> tuple[float, float]:
        """World size ``(width, height)`` in metres."""
        return self._inner.extent()

    @property
    def beams(self) -> int:
        """Beams per scan."""
        return int(round(math.radians(270.0) / self.angle_increment)) + 1

    def rasterizer(self, method: str = "cover_composite", slice_size: int = 4, **kwargs: Any) -> Rasterizer:
        """A :class:`Rasterizer` with this simulator's laser geometry."""
        return Rasterizer(
            method,
            slice_size,
            fov=-2.0 * self.angle_min,
            beams=self.beams,
            max_range=self.max_range,
            **kwargs,
        )

    def transient_hits(self, node_id: int) -> NDArray[np.float64]:
        """World points ``(h, 2)`` where the node's beams hit a person or vehicle (ground truth)."""
        return self._inner.transient_hits(int(node_id))

    def transient_residue(self, grid: OccupancyGrid, snapshot: GraphSnapshot, margin: float = 0.5) -> dict[str, int]:
        """Where did the returns from transient objects end up in ``grid``?

        Every ground-truth transient hit farther than ``margin`` metres from a true wall is placed where
        its node's posterior put it; counts the distinct cells and how many are structure / free.
        """
        cells, structure, free = self._inner.transient_residue(
            grid.cells, grid.origin, grid.resolution, snapshot.node_ids, snapshot.poses, snapshot.truth, margin
        )
        return {"cells": cells, "structure": structure, "free": free}


def wall_gaps(candidate: OccupancyGrid, reference: OccupancyGrid, walls: ArrayLike, radius: int = 1) -> dict[str, int]:
    """Connectivity check along every true wall (section 2.6.1).

    Samples every wall every half cell; counts the samples where ``reference`` shows structure within
    ``radius`` cells and ``candidate`` shows none.

    Returns:
        ``{"samples": ..., "gaps": ...}``.
    """
    if abs(candidate.resolution - reference.resolution) > 1e-12:
        raise InvalidInputError("candidate and reference must have the same resolution")
    samples, gaps = _core.mapping_wall_gaps(
        candidate.cells,
        candidate.origin,
        reference.cells,
        reference.origin,
        reference.resolution,
        as_f64(walls, "walls"),
        int(radius),
    )
    return {"samples": samples, "gaps": gaps}


def differing_cells(a: OccupancyGrid, b: OccupancyGrid) -> tuple[int, int]:
    """Cells whose class differs between two grids of one resolution, over the union of their extents.

    A cell outside a grid counts as unknown.

    Returns:
        ``(differing, cells in the union)``.
    """
    if abs(a.resolution - b.resolution) > 1e-12:
        raise InvalidInputError("the grids must have the same resolution")
    res = a.resolution
    ox = [round(g.origin[0] / res) for g in (a, b)]
    oy = [round(g.origin[1] / res) for g in (a, b)]
    x0, y0 = min(ox), min(oy)
    x1 = max(ox[0] + a.shape[1], ox[1] + b.shape[1])
    y1 = max(oy[0] + a.shape[0], oy[1] + b.shape[0])
    canvas = np.full((2, y1 - y0, x1 - x0), UNKNOWN, dtype=np.int8)
    for k, g in enumerate((a, b)):
        r, c = oy[k] - y0, ox[k] - x0
        canvas[k, r : r + g.shape[0], c : c + g.shape[1]] = g.cells
    return int(np.count_nonzero(canvas[0] != canvas[1])), int(canvas[0].size)


@dataclass
class StreamResult:
    """Per-method results of :func:`rasterize_stream`.

    Attributes:
        reports: per method, one :class:`UpdateReport` per graph.
        maps: per method, the map of the last graph.
        nodes: node count per graph.
        times: mission time per graph (s).
        peak_bytes: per method, the largest :attr:`Rasterizer.memory_bytes` seen.
    """

    reports: dict[str, list[UpdateReport]]
    maps: dict[str, OccupancyGrid]
    nodes: list[int]
    times: list[float]
    peak_bytes: dict[str, int]
    last: GraphSnapshot | None = None


def rasterize_stream(
    sim: TeamSimulator,
    rasterizers: Mapping[str, Rasterizer],
    *,
    progress: bool = False,
) -> StreamResult:
    """Feed every graph of ``sim`` to each rasterizer (identical inputs), timing each update.

    Args:
        sim: the stream.
        rasterizers: name -> rasterizer.
        progress: show a tqdm progress bar (on stderr).

    Returns:
        The reports, the final maps and the stream's node counts.
    """
    from tqdm import tqdm

    res = StreamResult({k: [] for k in rasterizers}, {}, [], [], {k: 0 for k in rasterizers})
    for g in tqdm(sim, desc="graphs", unit="graph", disable=not progress, leave=False, total=sim.graphs):
        scans = g.scans_by_row()
        for name, r in rasterizers.items():
            grid = r.update(g.node_ids, g.robot_ids, g.poses, scans)
            if r.last_report is not None:
                res.reports[name].append(r.last_report)
            res.maps[name] = grid
            res.peak_bytes[name] = max(res.peak_bytes[name], r.memory_bytes)
        res.nodes.append(len(g.node_ids))
        res.times.append(g.time)
        res.last = g
    return res


def plot_runtimes(result: StreamResult, path: str | Path, title: str = "") -> Path:
    """Per-graph runtimes (Figs. 2.6 / 2.7), cumulative runtimes (Fig. 2.5) and node counts (Fig. 2.8).

    Raises:
        ImportError: matplotlib is missing (``pip install autoteach[plot]``).
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'autoteach[plot]'") from err
    path = Path(path)
    fig, axes = plt.subplots(3, 1, figsize=(9, 10), sharex=True)
    x = np.arange(len(result.nodes))
    for name, reps in result.reports.items():
        t = np.array([r.seconds for r in reps])
        (line,) = axes[0].plot(x, t, lw=0.8, label=name)
        axes[0].axhline(t.mean(), color=line.get_color(), ls="--", lw=0.8)
        axes[1].plot(x, np.cumsum(t), label=name)
        axes[2].plot(x, [r.nodes_rasterized for r in reps], lw=0.8, label=f"{name}: nodes rasterized")
    first = next(iter(result.reports.values()), [])
    axes[2].plot(x, result.nodes, "k", label="nodes in graph")
    if first:
        axes[2].plot(x, [r.cover_nodes for r in first], "k:", label="nodes in cover")
    axes[0].set_ylabel("update time (s)")
    axes[0].set_title(title or "rasterization runtime per graph (dashed: mean)")
    axes[1].set_ylabel("cumulative time (s)")
    axes[2].set_ylabel("nodes")
    axes[2].set_xlabel("graph index (10 s apart)")
    for a in axes:
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


__all__ = [
    "FREE",
    "METHODS",
    "OCCUPIED",
    "UNKNOWN",
    "WORLDS",
    "GraphSnapshot",
    "OccupancyGrid",
    "Rasterizer",
    "RasterizerOptions",
    "StreamResult",
    "TeamSimulator",
    "UpdateReport",
    "differing_cells",
    "plot_runtimes",
    "rasterize_stream",
    "wall_gaps",
]
