"""Rerun views of an auto-teaching run: a ``.rrd`` recording that the Rerun viewer opens.

:func:`log_autoteach` records, on the ``frame`` timeline (and the log time as ``log_time``):

- ``camera/image``: the camera images (grey), with ``camera/image/rims`` (the edge points the
  solver used, one colour and class id per wafer, i.e. per track) and ``camera/image/tracks`` (the
  wafer id at each observed rim, the track's id);
- ``world/camera``: the camera pose of the calibrated chain (``Transform3D`` and a ``Pinhole``
  with the session's intrinsics) and the trajectories ``world/trajectory/{calibrated, fused,
  encoders, odometry}``: the calibrated chain, the UKF estimate (eq. 5.1), the encoders through the
  nominal chain and the dead-reckoned visual odometry, where the run has them;
- ``world/wafers``: the reconstructed wafer stack, each wafer's rim circle (upper rim, radius of
  the session) and a 3σ ellipsoid of its centre from the diagonal of its standard deviations;
- ``calibration/<joint>`` and ``calibration/ukf/<joint>``: the joint zero offsets (degrees; lift
  in mm) of the sliding window after each frame (joints the solver estimates) and of the UKF per
  frame.

Needs the ``viewer`` extra (``pip install 'autoteach[viewer]'``, the ``rerun-sdk`` package).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError, MissingExtraError

_HINT = "Rerun views need the 'viewer' extra: pip install 'autoteach[viewer]'"


def require_rerun() -> Any:
    """Import ``rerun`` or raise :class:`MissingExtraError` naming the ``viewer`` extra."""
    try:
        import rerun
    except ImportError as exc:
        raise MissingExtraError(_HINT) from exc
    return rerun


def _check_target(path: Path) -> Path:
    if path.suffix != ".rrd":
        raise InvalidInputError(f"a Rerun recording is an .rrd file, got {path}")
    if not path.parent.is_dir():
        raise InvalidInputError(f"cannot write {path}: the folder {path.parent} does not exist")
    if path.exists() and not path.is_file():
        raise InvalidInputError(f"cannot write {path}: it exists and is not a file")
    return path


def check_recording_path(path: str | os.PathLike[str]) -> Path:
    """Validate an ``.rrd`` target and that Rerun is installed, before a long run (raises as :func:`log_autoteach`)."""
    require_rerun()
    return _check_target(Path(path))


def _circle(pose: np.ndarray, radius: float, n: int = 48) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * math.pi, n + 1)
    local = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a), np.ones_like(a)], axis=1)
    return (local @ pose.T)[:, :3]


def _finite_track(poses: Any) -> np.ndarray | None:
    if poses is None:
        return None
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (4, 4) or len(p) == 0:
        return None
    t = p[:, :3, 3]
    return t[np.isfinite(t).all(axis=1)]


def log_autoteach(
    result: Any,
    session: Any,
    path: str | os.PathLike[str],
    *,
    recording_id: str | None = None,
    image_every: int = 1,
) -> Path:
    """Write the Rerun recording of an auto-teaching run to ``path`` (an ``.rrd`` file).

    Args:
        result: the :class:`~autoteach.pipeline.AutoTeachResult`.
        session: the :class:`~autoteach.sim.Session` it was computed from (images, timestamps, camera).
        path: the ``.rrd`` file to write (replaced if it exists).
        recording_id: Rerun recording id (default: derived from the file name, so reruns are stable).
        image_every: log every n-th image only (the rims and poses of every frame are logged).

    Returns:
        The path written.

    Raises:
        MissingExtraError: ``rerun-sdk`` is not installed (names the ``viewer`` extra).
        InvalidInputError: a path that is not a writable ``.rrd`` file, ``image_every < 1``, or a
            result whose frame count differs from the session's.

    """
    rr = require_rerun()
    target = _check_target(Path(path))
    if isinstance(image_every, bool) or not isinstance(image_every, int) or image_every < 1:
        raise InvalidInputError(f"image_every must be an integer >= 1, got {image_every!r}")
    poses = np.asarray(result.camera_poses, dtype=np.float64)
    n = session.n_frames
    if len(poses) != n:
        raise InvalidInputError(f"the result has {len(poses)} camera poses but the session has {n} frames")
    rec = rr.RecordingStream("autoteach", recording_id=recording_id or target.stem)
    rec.save(str(target))
    _log_scene(rr, rec, result, session, poses)
    _log_frames(rr, rec, result, session, poses, image_every)
    _log_calibration(rr, rec, result)
    rec.flush()
    rec.disconnect()
    return target


def _log_scene(rr: Any, rec: Any, result: Any, session: Any, poses: np.ndarray) -> None:
    """Static entities: the wafer stack with 3σ centre ellipsoids, and the camera trajectories."""
    from autoteach.ros2_messages import wafer_color

    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    radius = float(session.config.wafer_radius) if getattr(session, "config", None) is not None else 0.15
    wafer_poses = np.asarray(result.wafer_poses, dtype=np.float64)
    wafer_std = np.asarray(result.wafer_std, dtype=np.float64)
    seen = [w for w in range(len(wafer_poses)) if np.isfinite(wafer_poses[w]).all()]
    if seen:
        colors = [wafer_color(w) for w in seen]
        labels = [f"wafer {w} (slot {int(result.wafer_slots[w])})" for w in seen]
        rec.log(
            "world/wafers/rims",
            rr.LineStrips3D([_circle(wafer_poses[w], radius) for w in seen], colors=colors, labels=labels),
            static=True,
        )
        half = np.nan_to_num(3.0 * wafer_std[seen, :3], nan=0.0)
        rec.log(
            "world/wafers/centre_3sigma",
            rr.Ellipsoids3D(
                centers=wafer_poses[seen, :3, 3], half_sizes=np.maximum(half, 1e-6), colors=colors, class_ids=seen
            ),
            static=True,
        )
    tracks = {"calibrated": poses}
    if result.ukf is not None:
        for name, key in (("fused", "poses"), ("encoders", "encoder_poses"), ("odometry", "odometry_poses")):
            tracks[name] = result.ukf.get(key)
    for name, track in tracks.items():
        t = _finite_track(track)
        if t is not None and len(t) > 1:
            rec.log(f"world/trajectory/{name}", rr.LineStrips3D([t]), static=True)


def _log_frames(rr: Any, rec: Any, result: Any, session: Any, poses: np.ndarray, image_every: int) -> None:
    """Per frame: the camera pose, the image (every ``image_every``-th) and the rims with track ids."""
    from autoteach.ros2_messages import wafer_color

    n = session.n_frames
    stamps = np.asarray(session.timestamps, dtype=np.int64)
    cam = session.camera
    k = np.array([[cam.params[0], 0.0, cam.params[2]], [0.0, cam.params[1], cam.params[3]], [0.0, 0.0, 1.0]])
    obs = result.observations or {}
    by_frame: dict[int, list[int]] = {}
    for i, f in enumerate(obs.get("frames", [])):
        by_frame.setdefault(int(f), []).append(i)
    rec.log("world/camera", rr.Pinhole(image_from_camera=k, resolution=[cam.width, cam.height]), static=True)
    for f in range(n):
        rec.set_time("frame", sequence=f)
        rec.set_time("log_time", timestamp=np.datetime64(int(stamps[f]), "ns"))
        if np.isfinite(poses[f]).all():
            rec.log("world/camera", rr.Transform3D(translation=poses[f, :3, 3], mat3x3=poses[f, :3, :3]))
        if f % image_every == 0:
            rec.log("camera/image", rr.Image(np.asarray(session.images[f], dtype=np.uint8), color_model="L"))
        idx = by_frame.get(f, [])
        if idx:
            strips, ids, anchors, names = [], [], [], []
            for i in idx:
                pts = np.asarray(obs["points"][obs["start"][i] : obs["start"][i + 1]], dtype=np.float64)
                w = int(obs["wafers"][i])
                strips.append(pts)
                ids.append(w)
                if int(obs["rims"][i]) == 0 and len(pts):
                    anchors.append(pts[0])
                    names.append(f"wafer {w}")
            rec.log(
                "camera/image/rims",
                rr.LineStrips2D(strips, class_ids=ids, colors=[wafer_color(w) for w in ids], radii=1.0),
            )
            if anchors:
                rec.log("camera/image/tracks", rr.Points2D(np.array(anchors), labels=names, radii=3.0))


def _log_calibration(rr: Any, rec: Any, result: Any) -> None:
    """The estimated joint offsets over frames: each sliding window's, and the UKF's."""
    from autoteach.config import JOINTS

    for h in result.history:
        rec.set_time("frame", sequence=int(h["last_frame"]))
        offs = np.asarray(h["joint_offsets"], dtype=np.float64)
        for j, name in enumerate(JOINTS):
            if result.offset_status.get(name) == "estimated" and j < len(offs) and np.isfinite(offs[j]):
                scale = 1e3 if name == "lift" else 180.0 / math.pi
                rec.log(f"calibration/{name}", rr.Scalars(offs[j] * scale))
    if result.ukf is not None:
        ukf_offs = np.asarray(result.ukf["offsets"], dtype=np.float64)
        for f in range(len(ukf_offs)):
            rec.set_time("frame", sequence=f)
            for j, name in enumerate(("joint1", "joint2", "joint4")):
                if np.isfinite(ukf_offs[f, j]):
                    rec.log(f"calibration/ukf/{name}", rr.Scalars(math.degrees(ukf_offs[f, j])))


def recorded_entities(path: str | os.PathLike[str]) -> dict[str, list[str]]:
    """The entity paths of an ``.rrd`` recording and their component columns, read with Rerun's own reader."""
    rr = require_rerun()
    from rerun.chunk import RrdReader

    schema = RrdReader(Path(path)).stream().collect().schema()
    out: dict[str, list[str]] = {}
    for col in schema.component_columns():
        if not col.is_property:
            out.setdefault(col.entity_path, []).append(str(col.component))
    del rr
    return {k: sorted(v) for k, v in sorted(out.items())}


def log_segments(
    points: np.ndarray,
    labels: np.ndarray,
    path: str | os.PathLike[str],
    *,
    colors: np.ndarray | None = None,
    recording_id: str | None = None,
) -> Path:
    """Write the Rerun recording of a segmented point cloud (``autoteach segment --rerun``).

    ``segments``: the points coloured per segment with the label as class id (unsegmented points,
    label < 0, grey); ``cloud``: the points in their measured colours, when given. Points with a
    NaN coordinate (missing returns of an organised scan) are left out, as :func:`~autoteach.segment.write_ply`
    leaves them out.

    Raises:
        MissingExtraError: ``rerun-sdk`` is not installed.
        InvalidInputError: a bad ``.rrd`` path or arrays whose lengths differ.

    """
    rr = require_rerun()
    target = _check_target(Path(path))
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)  # organised scans (lines, beams, 3) too
    lab = np.asarray(labels).reshape(-1)
    cols = None if colors is None else np.asarray(colors).reshape(-1, 3)
    if len(lab) != len(pts) or (cols is not None and len(cols) != len(pts)):
        raise InvalidInputError(
            f"points ({len(pts)}), labels ({len(lab)}) and colors ({'-' if cols is None else len(cols)}) differ"
        )
    from autoteach.ros2_messages import wafer_color

    keep = np.isfinite(pts).all(axis=1)  # missing points of an organised scan are NaN (dropped, as in PLY)
    pts, lab, cols = pts[keep], lab[keep], None if cols is None else cols[keep]
    seg_colors = np.array([wafer_color(int(v)) if v >= 0 else (0.5, 0.5, 0.5) for v in lab], dtype=np.float32)
    rec = rr.RecordingStream("autoteach", recording_id=recording_id or target.stem)
    rec.save(str(target))
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("world/segments", rr.Points3D(pts, colors=seg_colors, class_ids=lab.astype(np.int64)), static=True)
    if cols is not None:
        rec.log("world/cloud", rr.Points3D(pts, colors=cols), static=True)
    rec.flush()
    rec.disconnect()
    return target


def log_plan(rows: list[dict[str, Any]], workspace: Any, path: str | os.PathLike[str], *, samples: int = 60) -> Path:
    """Write the Rerun recording of planned transfers (``autoteach plan --demo --rerun``).

    For each transfer ``<name>`` (the rows of :func:`autoteach.commands.plan.run_demo`, with their
    ``_result`` trajectories), on the ``time`` timeline from 0 to the trajectory's duration at
    ``samples`` instants: ``plan/<name>/robot`` (the link centres of the workspace's robot, labelled)
    and ``plan/<name>/joints/<joint>`` (the joint values); statically ``plan/<name>/swept/<link>``, the
    path of every link centre.

    Raises:
        MissingExtraError: ``rerun-sdk`` is not installed.
        InvalidInputError: a bad ``.rrd`` path or ``samples < 2``.

    """
    rr = require_rerun()
    target = _check_target(Path(path))
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 2:
        raise InvalidInputError(f"samples must be an integer >= 2, got {samples!r}")
    from autoteach.config import JOINTS

    rec = rr.RecordingStream("autoteach", recording_id=target.stem)
    rec.save(str(target))
    rec.log("plan", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for row in rows:
        name, r = row["name"], row["_result"]
        t = np.linspace(0.0, float(r.duration), samples)
        q = np.asarray(r.trajectory.sample(t)[0], dtype=np.float64)
        centres = [workspace.link_centres(qi) for qi in q]
        links = [link for link, _ in centres[0]]
        xyz = np.array([[c for _, c in cs] for cs in centres], dtype=np.float64)  # (samples, links, 3)
        for k, link in enumerate(links):
            rec.log(f"plan/{name}/swept/{link}", rr.LineStrips3D([xyz[:, k]]), static=True)
        for i, ti in enumerate(t):
            rec.set_time("time", duration=float(ti))
            rec.log(f"plan/{name}/robot", rr.Points3D(xyz[i], labels=links, radii=0.01))
            for j, joint in enumerate(JOINTS[: q.shape[1]]):
                rec.log(f"plan/{name}/joints/{joint}", rr.Scalars(q[i, j]))
    rec.flush()
    rec.disconnect()
    return target


class MapRecorder:
    """A rasterizer wrapper that records every map it returns (``autoteach map --rerun``): the grid growing.

    It forwards :meth:`update` to the wrapped :class:`~autoteach.mapping.Rasterizer` (whose own
    update timing is what the reports hold) and logs, on the ``graph`` timeline, ``map/grid`` (the
    map as the grey image of :meth:`~autoteach.mapping.OccupancyGrid.to_image`: free 254, occupied 0,
    unknown 205) and ``map/grid/nodes`` (the graph's node poses in that image's pixels, class id =
    robot). Every other attribute is the wrapped rasterizer's. Call :meth:`close` at the end.
    """

    def __init__(self, rasterizer: Any, path: str | os.PathLike[str]) -> None:
        rr = require_rerun()
        self._inner = rasterizer
        self._rr = rr
        self.path = _check_target(Path(path))
        self._rec = rr.RecordingStream("autoteach", recording_id=self.path.stem)
        self._rec.save(str(self.path))
        self._graph = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def update(self, node_ids: Any, robot_ids: Any, poses: Any, scans: Any) -> Any:
        """Rasterize the next graph with the wrapped rasterizer, record the map, return it."""
        grid = self._inner.update(node_ids, robot_ids, poses, scans)
        rr, rec = self._rr, self._rec
        rec.set_time("graph", sequence=self._graph)
        self._graph += 1
        rec.log("map/grid", rr.Image(grid.to_image(), color_model="L"))
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        h = grid.shape[0]
        col = (p[:, 0] - grid.origin[0]) / grid.resolution
        row = h - (p[:, 1] - grid.origin[1]) / grid.resolution  # the image's top row is the highest y
        ids = np.asarray(robot_ids, dtype=np.int64).reshape(-1)
        rec.log("map/grid/nodes", rr.Points2D(np.stack([col, row], axis=1), class_ids=ids, radii=2.0))
        return grid

    def close(self) -> Path:
        """Flush and close the recording; returns its path."""
        self._rec.flush()
        self._rec.disconnect()
        return self.path
