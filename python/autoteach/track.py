"""Multi-wafer tracking and tracking metrics (000_3b1454b2b2194811.txt ch. 4).

:class:`WaferTracker` registers the wafer edges of each frame to tracks: it predicts every track's
elliptic segment (image motion, or the projection of eq. (4.1) of its estimated 3D wafer through
the current camera pose), registers the observed segments to the predicted ones by the
hierarchical Gaussian-mixture registration of Algorithm 5 (eq. 4.2–4.10) and manages the tracks
as in Algorithm 4 (birth, update, loss, re-acquisition; both rims of a wafer are one track). The
greedy nearest-centre associator is available as a baseline (``associator="greedy"``). The work
is done in Rust (``autoteach_detect::track``) with the GIL released.

Metrics: :func:`clear_mot` (MOTA, identity switches; Bernardin & Stiefelhagen 2008) and
:func:`idf1` (Ristani et al. 2016) on per-frame ground-truth / hypothesis correspondences, and
:func:`synthetic_detections` to turn a simulated session's ground-truth rims into detector-like
edges with noise, missed detections, false arcs and duplicates.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autoteach import _core
from autoteach._convert import as_f64, as_float, as_int
from autoteach._sync import serialized
from autoteach.errors import InvalidInputError
from autoteach.geometry import Ellipse


def _assign(cost: ArrayLike, maximize: bool = False) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The project's Jonker–Volgenant solver (:func:`autoteach.detect.linear_sum_assignment`)."""
    return _core.linear_sum_assignment(np.ascontiguousarray(cost, dtype=np.float64), bool(maximize))


__all__ = [
    "Circle3",
    "Edge",
    "Track",
    "UpdateTimings",
    "WaferTracker",
    "clear_mot",
    "idf1",
    "identity_changes",
    "synthetic_detections",
    "track_frames",
    "track_log",
]


@dataclass
class Edge:
    """One elliptic edge segment of a wafer rim (the fields of ``autoteach_detect::wafers::WaferEdge``).

    Attributes:
        ellipse: the rim's ellipse (pixels, radians), an :class:`~autoteach.geometry.Ellipse`; five
            numbers ``(cx, cy, a, b, theta)`` are accepted and converted.
        points: ``(N, 2)`` edge points ``(u, v)``; empty means the whole ellipse.
        kind: ``"upper"`` or ``"lower"`` rim.
        wafer_id: groups the two rims of one wafer within one frame.
        residual: mean orthogonal distance of the points to the ellipse (pixels).
        covariance: ``(5, 5)`` covariance of the ellipse parameters, if known.
        label: free-form tag carried along (e.g. the ground-truth wafer in simulations).

    """

    ellipse: Ellipse
    points: NDArray[np.float64]
    kind: str = "upper"
    wafer_id: int = 0
    residual: float = 0.0
    covariance: NDArray[np.float64] | None = None
    label: Any = None

    def __post_init__(self) -> None:
        if not isinstance(self.ellipse, Ellipse):
            self.ellipse = Ellipse(*_ellipse_array(self.ellipse, 0))


@dataclass(frozen=True, slots=True)
class Circle3:
    """A circle in 3D (the fields of ``autoteach_detect::track::circle::Circle3``), metres."""

    center: NDArray[np.float64]
    """Centre ``(3,)``."""
    normal: NDArray[np.float64]
    """Unit normal ``(3,)`` of the circle's plane."""
    radius: float
    """Radius."""


@dataclass(frozen=True, slots=True)
class UpdateTimings:
    """Wall-clock seconds of the stages of the last :meth:`WaferTracker.update`.

    The fields of ``autoteach_detect::track::UpdateTimings``.
    """

    predict: float
    """Prediction of every track's segment (§4.2)."""
    associate: float
    """Association (Algorithm 5: point sets, kd-tree, kNN, E-step, cost matrix, assignment -- or the
    greedy baseline)."""
    manage: float
    """Track management (Algorithm 4), including the multi-view 3D rim estimates."""


@dataclass
class Track:
    """One tracked wafer (the fields of ``autoteach_detect::track::Track``, updated in place by the tracker).

    ``ellipse`` and ``circle`` are what the Rust ``Track::ellipse()`` and ``Track::circle()``
    methods return.

    Attributes:
        id: track identifier.
        ellipse: latest registered ellipse (upper rim preferred), an :class:`~autoteach.geometry.Ellipse`.
        visible: registered in the current frame.
        confirmed: registered in at least ``min_hits`` frames.
        history: ``(frame index, edge)`` of every edge registered to the track (the caller's
            edge objects).
        predicted: the predicted ellipse of the current frame (an ``Ellipse``), if any.
        circle: the estimated 3D rim (world frame), a :class:`Circle3`, if estimated.
        hits, missed, first_frame, last_frame: registered frames, consecutive misses, first and
            last registered frame.
        edges: the edges (the caller's objects) registered in the last frame the track was seen
            (one or two rims).

    """

    id: int
    ellipse: Ellipse | None = None
    visible: bool = False
    confirmed: bool = False
    history: list[tuple[int, Any]] = field(default_factory=list)
    predicted: Ellipse | None = None
    circle: Circle3 | None = None
    hits: int = 0
    missed: int = 0
    first_frame: int = 0
    last_frame: int = 0
    edges: list[Any] = field(default_factory=list)


def _get(obj: Any, name: str, default: Any = None) -> Any:
    if isinstance(obj, dict):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _checked_options(params: dict[str, Any]) -> dict[str, Any]:
    """``params`` with unknown names refused and numbers converted by the type of their default.

    The compiled tracker would raise a bare ``TypeError`` for an unknown name or a string, and an
    ``OverflowError`` for a negative count; these name the option instead.
    """
    known = inspect.signature(_core.TrackWaferTracker).parameters
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise InvalidInputError(f"unknown WaferTracker option(s) {unknown}; the options are {sorted(known)}")
    out = dict(params)
    for key, value in params.items():
        default = known[key].default
        if isinstance(default, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise InvalidInputError(f"{key} must be True or False, got {value!r}")
        elif isinstance(default, int):
            out[key] = as_int(value, key)
        elif isinstance(default, float):
            out[key] = as_float(value, key)
        elif isinstance(default, str) and not isinstance(value, str):
            raise InvalidInputError(f"{key} must be a string, got {type(value).__name__} {value!r}")
    return out


def _ellipse_array(e: Any, i: int) -> NDArray[np.float64]:
    if e is None:
        raise InvalidInputError(
            f"edges[{i}] must have an ellipse (cx, cy, a, b, theta, as an object or 5 numbers), got None"
        )
    if hasattr(e, "cx"):
        return np.array([e.cx, e.cy, e.a, e.b, e.theta], dtype=np.float64)
    arr = as_f64(e, f"edge {i}: ellipse").reshape(-1)
    if arr.shape != (5,):
        raise InvalidInputError(f"edge {i}: ellipse must have 5 values (cx, cy, a, b, theta), got {arr.shape}")
    return arr


def _kind(k: Any, i: int) -> str:
    if k is None:
        return "upper"
    name = k if isinstance(k, str) else getattr(k, "name", getattr(k, "value", str(k)))
    name = str(name).lower().rsplit(".", 1)[-1]
    if name not in ("upper", "lower"):
        raise InvalidInputError(f"edge {i}: kind must be 'upper' or 'lower', got {k!r}")
    return name


def _edge_tuple(edge: Any, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64], str, int, float]:
    ell = _ellipse_array(_get(edge, "ellipse"), i)
    pts = _get(edge, "points")
    pts = np.zeros((0, 2)) if pts is None else np.ascontiguousarray(as_f64(pts, f"edge {i}: points"))
    if pts.size and (pts.ndim != 2 or pts.shape[1] != 2):
        raise InvalidInputError(f"edge {i}: points must have shape (N, 2), got {pts.shape}")
    wid = _get(edge, "wafer_id")
    wid = i if wid is None else as_int(wid, f"edge {i}: wafer_id", signed=True)
    if wid < 0:
        raise InvalidInputError(f"edge {i}: wafer_id must be >= 0, got {wid}")
    res = _get(edge, "residual")
    return (
        ell,
        pts.reshape(-1, 2),
        _kind(_get(edge, "kind"), i),
        wid,
        (0.0 if res is None else as_float(res, f"edge {i}: residual")),
    )


@serialized
class WaferTracker:
    """Multi-wafer tracker (000_3b1454b2b2194811.txt Algorithms 4–5).

    Args:
        sigma: std ``σ`` of the Gaussian components, eq. (4.2) (pixels).
        omega: density ``ω`` of the uniform noise component, eq. (4.7).
        knn: ``K`` of the kNN search of Algorithm 5.
        gate: pairs farther than ``gate·σ`` are left out of the E-step sums.
        min_score: a segment pair is registered only if its score ``C(k, l)`` (4.10) exceeds it.
        min_coverage: a pair whose prediction is tight (projected from a well-estimated 3D rim)
            is registered only if it explains at least this fraction of the observed or of the
            predicted segment's points (0: off, the default).
        associator: ``"hierarchical"`` (Algorithm 5) or ``"greedy"`` (nearest centre baseline).
        greedy_gate: largest centre distance the greedy associator registers (pixels).
        max_points_per_segment: edge points per segment used for registration.
        max_missed: a confirmed track unseen for more than this many frames is retired.
        min_hits: frames needed to confirm a track (tentative tracks are dropped on a miss).
        rim_merge_distance: an unregistered edge this close (pixels) to an edge registered in the
            same frame joins that track (other rim of the wafer, duplicate).
        image_size: ``(width, height)``; predicted points outside are dropped.
        intrinsics: ``(3, 3)`` pinhole ``K``, for the projection prediction (eq. 4.1).
        wafer_radius: wafer radius (m).
        normal_prior: expected wafer normal (world), resolves the two-fold circle ambiguity.
        circle_window: views per 3D rim estimate (averaged back-projections, or the views of the
            multi-view fit).
        prefer_projection: use eq. (4.1) also for rims seen in the previous frame.
        multiview_circle: estimate each rim's 3D circle from the edge points of its last
            ``circle_window`` views and camera poses (Levenberg–Marquardt on the eq. (5.13)
            conics) instead of averaging single-ellipse back-projections.
        normal_prior_sigma: std (rad) of a wafer's tilt from ``normal_prior`` in that fit.
        circle_fit_iterations: Levenberg–Marquardt iterations per registered frame.
        projection_max_center_std: a rim whose multi-view estimate has a centre std below this
            (m) and an RMS point distance below ``projection_max_rms`` (px) is predicted by
            eq. (4.1) also when seen in the previous frame.
        projection_max_rms: see ``projection_max_center_std``.
        max_missed_3d: frames a confirmed track with such a 3D estimate is kept unseen, so a
            wafer that leaves the image is re-acquired by its projected position.
        stack_axis_sigma: std (m) of a prior that each wafer centre lies on the carrier axis (the
            mean centre and normal of the well-estimated tracks); ``None`` switches it off.
        slot_pitch: carrier slot pitch (m); with it every free slot next to a track (±pitch along
            the carrier axis from its 3D estimate) is predicted by eq. (4.1) and competes in the
            registration, so a wafer appearing next to a track whose own wafer is missed starts a
            new track instead of being taken by the neighbour. ``None`` (default): off.

    Raises:
        InvalidInputError: an option out of range.

    """

    def __init__(self, **params: Any) -> None:
        params = _checked_options(params)
        for key in ("image_size", "normal_prior"):
            if params.get(key) is not None:
                params[key] = tuple(float(v) for v in params[key])
        if params.get("intrinsics") is not None:
            params["intrinsics"] = as_f64(params["intrinsics"], "intrinsics")
        self.params = dict(params)
        self._inner = _core.TrackWaferTracker(**params)
        self._tracks: dict[int, Track] = {}
        self._retired: dict[int, Track] = {}
        self.frame_assignments: list[list[int | None]] = []

    @property
    def frame(self) -> int:
        """Number of frames processed."""
        return int(self._inner.frame)

    @property
    def last_timings(self) -> UpdateTimings:
        """Seconds spent in the stages of the last :meth:`update` (inside Rust), see :class:`UpdateTimings`."""
        p, a, m = self._inner.last_timings
        return UpdateTimings(predict=float(p), associate=float(a), manage=float(m))

    def update(self, edges: Iterable[Any], camera_pose: ArrayLike | None = None) -> list[Track]:
        """Process one frame and return the live confirmed tracks.

        Args:
            edges: the frame's edges: objects or dicts with ``ellipse`` (an ellipse object with
                ``cx, cy, a, b, theta`` or 5 numbers), ``points`` ``(N, 2)``, ``kind``,
                ``wafer_id`` (default: the edge's index) and ``residual``.
            camera_pose: ``T_wc`` (4, 4) of the frame, for the projection prediction.

        Returns:
            The confirmed live tracks (visible or coasting), in order of birth.

        Raises:
            InvalidInputError: malformed edges or pose (the tracker is unchanged).

        """
        edges = list(edges)
        tuples = [_edge_tuple(e, i) for i, e in enumerate(edges)]
        pose = None if camera_pose is None else np.ascontiguousarray(as_f64(camera_pose, "camera_pose"))
        frame = self.frame
        owners = self._inner.update(tuples, pose)
        self.frame_assignments.append(list(owners))
        live = {d["id"]: d for d in self._inner.tracks()}
        for edge, owner in zip(edges, owners, strict=True):
            if owner is not None:
                self._tracks.setdefault(owner, Track(id=owner)).history.append((frame, edge))
        for tid in list(self._tracks):
            if tid not in live:
                old = self._tracks.pop(tid)
                if old.confirmed:
                    self._retired[tid] = old
        for tid, d in live.items():
            t = self._tracks.setdefault(tid, Track(id=tid))
            t.visible, t.confirmed, t.hits, t.missed = d["visible"], d["confirmed"], d["hits"], d["missed"]
            t.first_frame, t.last_frame = d["first_frame"], d["last_frame"]
            t.ellipse = None if d["ellipse"] is None else Ellipse(*d["ellipse"])
            t.predicted = None if d["predicted"] is None else Ellipse(*d["predicted"])
            c = d["circle"]
            t.circle = None if c is None else Circle3(np.array(c[0]), np.array(c[1]), float(c[2]))
            t.edges = [e for f, e in t.history if f == t.last_frame]
        return [t for t in self._tracks.values() if t.confirmed]

    def tracks(self, include_tentative: bool = False) -> list[Track]:
        """The live tracks (confirmed only unless ``include_tentative``)."""
        return [t for t in self._tracks.values() if include_tentative or t.confirmed]

    def all_tracks(self) -> list[Track]:
        """Every confirmed track so far, live or retired, ordered by id (offline evaluation)."""
        out = [t for t in self._tracks.values() if t.confirmed] + list(self._retired.values())
        return sorted(out, key=lambda t: t.id)


def track_frames(
    frames: Iterable[Iterable[Any]],
    camera_poses: Sequence[ArrayLike] | None = None,
    **params: Any,
) -> WaferTracker:
    """Run a :class:`WaferTracker` over a sequence of frames (each a list of edges)."""
    tracker = WaferTracker(**params)
    for i, edges in enumerate(frames):
        tracker.update(edges, None if camera_poses is None else camera_poses[i])
    return tracker


def track_log(
    path: Any,
    detector: Callable[[NDArray[np.uint8]], Iterable[Any]] | None = None,
    use_poses: bool = True,
    **params: Any,
) -> WaferTracker:
    """Track the wafers of a session log (MCAP, :func:`autoteach.io.read_log`) frame by frame.

    Args:
        path: the log file (or an already loaded :class:`autoteach.sim.Session`).
        detector: image → edges; default ``autoteach.detect.detect_wafers``.
        use_poses: pass the log's camera poses (when it has them) for the projection prediction;
            the camera intrinsics and image size are then taken from the log's camera.
        **params: :class:`WaferTracker` options.

    """
    from autoteach.io import read_log

    session = read_log(path) if isinstance(path, (str, bytes)) or hasattr(path, "__fspath__") else path
    if detector is None:
        from autoteach import detect

        detector = getattr(detect, "detect_wafers", None)
        if detector is None:
            raise InvalidInputError("no detector given and autoteach.detect.detect_wafers is not available")
    poses = getattr(session, "camera_poses", None) if use_poses else None
    if poses is not None:
        cam = session.camera
        if getattr(cam, "model", "pinhole") == "pinhole":
            fx, fy, cx, cy = (float(v) for v in cam.params[:4])
            params.setdefault("intrinsics", [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
            params.setdefault("image_size", (cam.width, cam.height))
        else:
            poses = None
    return track_frames((detector(img) for img in session.images), poses, **params)


# ---------------------------------------------------------------------------------------------
# Metrics
# ---------------------------------------------------------------------------------------------


def _frame_dists(gt: Sequence[Any], hyp: Sequence[Any], dists: ArrayLike | None) -> NDArray[np.float64]:
    d = np.zeros((len(gt), len(hyp))) if dists is None else np.asarray(dists, dtype=np.float64)
    if d.shape != (len(gt), len(hyp)):
        raise InvalidInputError(f"distance matrix must have shape ({len(gt)}, {len(hyp)}), got {d.shape}")
    return np.where(np.isnan(d), np.inf, d)


def clear_mot(
    frames: Iterable[tuple[Sequence[Any], Sequence[Any], ArrayLike | None]],
    threshold: float = np.inf,
) -> dict[str, float]:
    """CLEAR MOT metrics (Bernardin & Stiefelhagen 2008, the py-motmetrics conventions).

    Args:
        frames: per frame ``(gt_ids, hyp_ids, dists)`` with ``dists`` ``(len(gt), len(hyp))``:
            the matching distance, ``inf``/``nan`` for pairs that may not match (``None``: all
            pairs at distance 0).
        threshold: pairs with a distance above it do not match.

    Returns:
        ``num_gt``, ``num_hyp``, ``matches``, ``fn``, ``fp``, ``idsw`` (a ground-truth object
        matched to a different hypothesis than at its previous match), ``mota`` =
        1 − (fn + fp + idsw)/num_gt, ``motp`` (mean distance of the matches).

    Each frame keeps every object's latest correspondence if it is still valid and completes
    them by a minimum-distance assignment (Hungarian) of maximum cardinality.

    """
    last: dict[Any, Any] = {}  # gt -> hyp of its latest match (kept across gaps)
    n_gt = n_hyp = n_match = n_sw = 0
    dsum = 0.0
    for gt, hyp, dists in frames:
        gt, hyp = list(gt), list(hyp)
        d = _frame_dists(gt, hyp, dists)
        ok = np.isfinite(d) & (d <= threshold)
        n_gt += len(gt)
        n_hyp += len(hyp)
        gi = {g: i for i, g in enumerate(gt)}
        hi = {h: j for j, h in enumerate(hyp)}
        matched: dict[Any, Any] = {}
        used_g: set[int] = set()
        used_h: set[int] = set()
        for g in gt:
            h = last.get(g)
            if h in hi and hi[h] not in used_h and ok[gi[g], hi[h]]:
                matched[g] = h
                used_g.add(gi[g])
                used_h.add(hi[h])
        rows = [i for i in range(len(gt)) if i not in used_g]
        cols = [j for j in range(len(hyp)) if j not in used_h]
        if rows and cols:
            valid = ok[np.ix_(rows, cols)]
            sub = np.where(valid, d[np.ix_(rows, cols)], 0.0)
            # Larger than any sum of valid distances: the most valid pairs first, then the least cost.
            big = 1.0 + 2.0 * float(np.abs(sub).sum())
            cost = np.where(valid, sub, big)
            r, c = _assign(cost)
            for a, b in zip(r, c, strict=True):
                if ok[rows[a], cols[b]]:
                    g, h = gt[rows[a]], hyp[cols[b]]
                    if g in last and last[g] != h:
                        n_sw += 1
                    matched[g] = h
        for g, h in matched.items():
            dsum += float(d[gi[g], hi[h]])
            last[g] = h
        n_match += len(matched)
    fn = n_gt - n_match
    fp = n_hyp - n_match
    return {
        "num_gt": float(n_gt),
        "num_hyp": float(n_hyp),
        "matches": float(n_match),
        "fn": float(fn),
        "fp": float(fp),
        "idsw": float(n_sw),
        "mota": 1.0 - (fn + fp + n_sw) / n_gt if n_gt else float("nan"),
        "motp": dsum / n_match if n_match else float("nan"),
    }


def idf1(
    frames: Iterable[tuple[Sequence[Any], Sequence[Any], ArrayLike | None]],
    threshold: float = np.inf,
) -> dict[str, float]:
    """Identity metrics IDP, IDR, IDF1 (Ristani et al. 2016).

    The ground-truth and hypothesis trajectories are matched one-to-one, globally over the
    sequence, to maximise the number of frames in which matched trajectories coincide
    (``idtp``: both present and within ``threshold``); IDF1 = 2·idtp/(num_gt + num_hyp).
    Input as :func:`clear_mot`.

    """
    counts: dict[tuple[Any, Any], int] = {}
    n_gt = n_hyp = 0
    gts: dict[Any, int] = {}
    hyps: dict[Any, int] = {}
    for gt, hyp, dists in frames:
        gt, hyp = list(gt), list(hyp)
        d = _frame_dists(gt, hyp, dists)
        n_gt += len(gt)
        n_hyp += len(hyp)
        for g in gt:
            gts.setdefault(g, len(gts))
        for h in hyp:
            hyps.setdefault(h, len(hyps))
        for i, j in zip(*np.nonzero(np.isfinite(d) & (d <= threshold)), strict=True):
            key = (gt[i], hyp[j])
            counts[key] = counts.get(key, 0) + 1
    idtp = 0
    if counts:
        m = np.zeros((len(gts), len(hyps)))
        for (g, h), c in counts.items():
            m[gts[g], hyps[h]] = c
        r, c = _assign(m, maximize=True)
        idtp = int(m[r, c].sum())
    return {
        "idtp": float(idtp),
        "idfn": float(n_gt - idtp),
        "idfp": float(n_hyp - idtp),
        "idp": idtp / n_hyp if n_hyp else float("nan"),
        "idr": idtp / n_gt if n_gt else float("nan"),
        "idf1": 2.0 * idtp / (n_gt + n_hyp) if n_gt + n_hyp else float("nan"),
    }


def identity_changes(
    tracks: Iterable[Track],
    label: Callable[[Any], Any] = lambda e: _get(e, "label"),
    neighbours: Callable[[Any, Any], bool] | None = None,
) -> dict[str, int]:
    """Identity changes inside tracks: each time a track's edges move from one ground-truth wafer to another.

    Args:
        tracks: tracks with their histories (e.g. :meth:`WaferTracker.all_tracks`).
        label: the ground-truth wafer of an edge (``None``: a false arc, ignored).
        neighbours: whether two wafers are neighbours (e.g. adjacent occupied slots).

    Returns:
        ``changes`` (all) and ``neighbour_changes`` (between neighbours).

    """
    changes = neighbour = 0
    for t in tracks:
        prev = None
        frames: dict[int, set[Any]] = {}
        for f, e in t.history:
            lab = label(e)
            if lab is not None:
                frames.setdefault(f, set()).add(lab)
        for f in sorted(frames):
            labs = frames[f]
            cur = prev if prev in labs else min(labs, key=str)
            if prev is not None and cur != prev:
                changes += 1
                if neighbours is not None and neighbours(prev, cur):
                    neighbour += 1
            prev = cur
    return {"changes": changes, "neighbour_changes": neighbour}


# ---------------------------------------------------------------------------------------------
# Simulated detections
# ---------------------------------------------------------------------------------------------


def synthetic_detections(
    session: Any,
    seed: int = 0,
    *,
    pixel_noise: float = 0.5,
    min_points: int = 30,
    p_miss: float = 0.05,
    false_arcs: float = 1.0,
    p_duplicate: float = 0.05,
    p_partial: float = 0.1,
    partial_fraction: tuple[float, float] = (0.15, 0.35),
    max_points: int = 400,
) -> list[list[Edge]]:
    """Detector-like edges from a simulated session's ground-truth visible rims.

    Every visible rim with at least ``min_points`` samples becomes an :class:`Edge` whose points
    are the rim samples plus Gaussian noise (``pixel_noise`` px) and whose ellipse is fitted to
    them (:func:`autoteach.detect.fit_ellipse`, geometric). The two rims of a wafer share a
    ``wafer_id`` (in shuffled order per frame). Each wafer is missed with probability ``p_miss``,
    each edge duplicated with probability ``p_duplicate``, cut to a contiguous piece of
    ``partial_fraction`` of its samples with probability ``p_partial`` (a partial detection), and a
    Poisson(``false_arcs``) number
    of false arcs (random short elliptic arcs) is added per frame. ``label`` is the wafer index
    (``None`` for false arcs).
    """
    from autoteach.detect import fit_ellipse

    rng = np.random.default_rng(seed)
    cfg = session.config
    w, h = float(cfg.width), float(cfg.height)
    out: list[list[Edge]] = []
    for rims in session.rims:
        by_wafer: dict[int, list[dict[str, Any]]] = {}
        for r in rims:
            if r["points"].shape[0] >= min_points:
                by_wafer.setdefault(r["wafer"], []).append(r)
        wafers = list(by_wafer)
        order = rng.permutation(len(wafers))
        edges: list[Edge] = []
        for rank, wi in enumerate(order):
            wafer = wafers[wi]
            if rng.random() < p_miss:
                continue
            for r in by_wafer[wafer]:
                pts = r["points"]
                if pts.shape[0] > max_points:
                    pts = pts[np.linspace(0, pts.shape[0] - 1, max_points).astype(int)]
                if rng.random() < p_partial:
                    # A partial detection: a contiguous piece of the visible rim, whose fitted
                    # ellipse (centre, axes) is far less certain than the points themselves.
                    m = max(min_points // 2, int(pts.shape[0] * rng.uniform(*partial_fraction)))
                    s0 = int(rng.integers(0, max(1, pts.shape[0] - m)))
                    pts = pts[s0 : s0 + m]
                pts = pts + rng.normal(0.0, pixel_noise, pts.shape)
                try:
                    fit = fit_ellipse(pts)
                except ValueError:
                    continue
                e = fit.ellipse
                edge = Edge(
                    ellipse=e,
                    points=pts,
                    kind=r["rim"],
                    wafer_id=int(rank),
                    residual=fit.residual_mean,
                    label=wafer,
                )
                edges.append(edge)
                if rng.random() < p_duplicate:
                    edges.append(Edge(edge.ellipse, pts.copy(), edge.kind, edge.wafer_id, edge.residual, None, wafer))
        for k in range(rng.poisson(false_arcs)):
            a = rng.uniform(30.0, 400.0)
            b = rng.uniform(3.0, min(a, 120.0))
            ell = np.array([rng.uniform(0, w), rng.uniform(0, h), a, b, rng.uniform(-1.5, 1.5)])
            t0 = rng.uniform(-np.pi, np.pi)
            t = np.linspace(t0, t0 + rng.uniform(0.3, 1.2), 60)
            c, s = np.cos(ell[4]), np.sin(ell[4])
            x = ell[2] * np.cos(t)
            y = ell[3] * np.sin(t)
            pts = np.stack([ell[0] + c * x - s * y, ell[1] + s * x + c * y], axis=1)
            pts += rng.normal(0.0, pixel_noise, pts.shape)
            edges.append(Edge(Ellipse(*ell), pts, "upper" if k % 2 == 0 else "lower", 10_000 + k, 0.0, None, None))
        out.append(edges)
    return out
