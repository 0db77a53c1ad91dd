"""MCAP session logs: :func:`write_log` stores a :class:`~autoteach.sim.Session`, :func:`read_log` reads it back.

Channels (all schemas open in Foxglove):

=============================  ==========================  =========  =====================================
topic                          schema                      encoding   content
=============================  ==========================  =========  =====================================
``/session``                   ``autoteach.Session``       json       once: camera intrinsics, joint names,
                                                                      frame rate, number of frames
``/camera/image``              ``sensor_msgs/msg/Image``   cdr        per frame: ``mono8`` image
``/joint_states``              ``sensor_msgs/msg/JointState`` cdr     per frame: encoder readings
``/ground_truth/scene``        ``autoteach.GroundTruthScene`` json    once: seed, config, wafer poses and
                                                                      slots, calibration
``/ground_truth/joint_states`` ``sensor_msgs/msg/JointState`` cdr     per frame: true joints
``/ground_truth/camera_pose``  ``foxglove.PoseInFrame``    json       per frame: ``T_wc`` (plus the exact
                                                                      row-major matrix in ``matrix``)
``/ground_truth/rims``         ``autoteach.VisibleRims``   json       per frame: visible rim records
=============================  ==========================  =========  =====================================

:func:`write_results` copies a log (every message, metadata record and attachment unchanged) and
adds the auto-teaching results on their own channels, read back by :func:`read_results`:
``/autoteach/calibration`` (once: base pose, joint offsets, standard deviations, covariance, errors
against ground truth), ``/autoteach/wafers`` (once: wafer parameters, standard deviations, poses,
slots, resolution), ``/autoteach/camera_pose`` (per frame, ``foxglove.PoseInFrame``),
``/autoteach/ukf`` (per frame), ``/autoteach/history`` (per sliding window) and
``/autoteach/edges`` (per frame: the edge points the solver used).

The ``/session``, ``/camera/image`` and ``/joint_states`` channels are required; logs of a real robot
have no ``/ground_truth/*`` channels and read back with ``None`` ground truth. Values round-trip
bit-exactly: images and joints are raw bytes in the CDR messages, JSON floats are written with
``repr`` precision and arrays of rim points as base64 of little-endian float64.

The ROS 2 messages are encoded by hand (little-endian plain CDR with the 4-byte encapsulation
header; primitives aligned to their size relative to the end of that header), so no ROS
installation is needed.
"""

from __future__ import annotations

import base64
import json
import os
import stat
import warnings
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError, LogReadError, LogSalvageWarning
from autoteach.ros2_messages import IMAGE_ANNOTATIONS_SCHEMA as _IMAGE_ANNOTATIONS_SCHEMA
from autoteach.ros2_messages import IMAGE_DEFINITION as _IMAGE_MSG
from autoteach.ros2_messages import JOINT_STATE_DEFINITION as _JOINT_STATE_MSG
from autoteach.ros2_messages import decode_image as _decode_image
from autoteach.ros2_messages import decode_joint_state as _decode_joint_state
from autoteach.ros2_messages import encode_image as _encode_image
from autoteach.ros2_messages import encode_joint_state as _encode_joint_state
from autoteach.ros2_messages import rim_annotation_messages as _rim_annotation_messages
from autoteach.session import Calibration, CameraInfo, Session
from autoteach.sim.config import SimConfig

__all__ = [
    "FORMAT_VERSION",
    "LogDamage",
    "LogSalvageWarning",
    "RESULT_TOPICS",
    "TOPICS",
    "LogReadError",
    "Session",
    "log_info",
    "read_log",
    "read_results",
    "write_log",
    "write_result_messages",
    "write_results",
]

#: Version of the autoteach log layout written into the ``/session`` message.
FORMAT_VERSION = 1

MCAP_MAGIC = b"\x89MCAP0\r\n"

TOPIC_SESSION = "/session"
TOPIC_IMAGE = "/camera/image"
TOPIC_JOINTS = "/joint_states"
TOPIC_SCENE = "/ground_truth/scene"
TOPIC_JOINTS_TRUE = "/ground_truth/joint_states"
TOPIC_CAMERA_POSE = "/ground_truth/camera_pose"
TOPIC_RIMS = "/ground_truth/rims"

#: Every topic of a session log with its (schema name, schema encoding, message encoding).
TOPICS: dict[str, tuple[str, str, str]] = {
    TOPIC_SESSION: ("autoteach.Session", "jsonschema", "json"),
    TOPIC_IMAGE: ("sensor_msgs/msg/Image", "ros2msg", "cdr"),
    TOPIC_JOINTS: ("sensor_msgs/msg/JointState", "ros2msg", "cdr"),
    TOPIC_SCENE: ("autoteach.GroundTruthScene", "jsonschema", "json"),
    TOPIC_JOINTS_TRUE: ("sensor_msgs/msg/JointState", "ros2msg", "cdr"),
    TOPIC_CAMERA_POSE: ("foxglove.PoseInFrame", "jsonschema", "json"),
    TOPIC_RIMS: ("autoteach.VisibleRims", "jsonschema", "json"),
}
REQUIRED_TOPICS = (TOPIC_SESSION, TOPIC_IMAGE, TOPIC_JOINTS)
GROUND_TRUTH_FRAME_TOPICS = (TOPIC_JOINTS_TRUE, TOPIC_CAMERA_POSE, TOPIC_RIMS)

_TIME_SCHEMA = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}
_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_POSE_SCHEMA = {
    "title": "foxglove.PoseInFrame",
    "description": "Ground-truth camera pose T_wc in the world (carrier) frame.",
    "type": "object",
    "properties": {
        "timestamp": _TIME_SCHEMA,
        "frame_id": {"type": "string"},
        "pose": {
            "title": "foxglove.Pose",
            "type": "object",
            "properties": {
                "position": {"title": "foxglove.Vector3", **_VEC3},
                "orientation": {
                    "title": "foxglove.Quaternion",
                    "type": "object",
                    "properties": {k: {"type": "number"} for k in "xyzw"},
                },
            },
        },
        "matrix": {
            "description": "The exact 4x4 T_wc, row-major",
            "type": "array",
            "items": {"type": "number"},
            "minItems": 16,
            "maxItems": 16,
        },
    },
}
_ARRAY_SCHEMA = {
    "type": "object",
    "description": "An array: base64 of its raw bytes (dtype '<f8' or '|b1'), with its shape",
    "properties": {"dtype": {"type": "string"}, "shape": {"type": "array"}, "data": {"type": "string"}},
}
_RIMS_SCHEMA = {
    "title": "autoteach.VisibleRims",
    "description": "Ground truth: the visible part of every wafer rim ellipse in one image.",
    "type": "object",
    "properties": {
        "timestamp": _TIME_SCHEMA,
        "frame": {"type": "integer"},
        "rims": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {
                    "wafer": {"type": "integer"},
                    "slot": {"type": "integer"},
                    "rim": {"type": "string", "enum": ["upper", "lower"]},
                    "ellipse": {
                        "description": "cx, cy, a, b, theta of the full projected rim (pixels, radians)",
                        "type": ["array", "null"],
                        "items": {"type": "number"},
                    },
                    "intervals": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
                    "fraction": {"type": "number"},
                    "points": {**_ARRAY_SCHEMA, "description": "(m, 2) pixel positions of the visible rim samples"},
                    "angles": {**_ARRAY_SCHEMA, "description": "(m,) circle angles of the visible samples (rad)"},
                    "side_facing": {
                        **_ARRAY_SCHEMA,
                        "description": "(m,) whether the bright side face faces the camera at each sample",
                    },
                },
            },
        },
    },
}
_SESSION_SCHEMA = {
    "title": "autoteach.Session",
    "description": "Session metadata: camera intrinsics, joint names, frame rate and frame count.",
    "type": "object",
    "properties": {
        "format": {"type": "string", "const": "autoteach.session"},
        "version": {"type": "integer"},
        "camera": {"type": "object"},
        "joint_names": {"type": "array", "items": {"type": "string"}},
        "frame_rate_hz": {"type": ["number", "null"]},
        "frames": {"type": "integer"},
    },
}
_SCENE_SCHEMA = {
    "title": "autoteach.GroundTruthScene",
    "description": "Ground truth: seed, simulation config, wafer poses and slots, calibration parameters.",
    "type": "object",
    "properties": {
        "seed": {"type": ["integer", "null"]},
        "config": {"type": ["object", "null"]},
        "wafer_slots": {"type": "array", "items": {"type": "integer"}},
        "wafer_poses": {"type": "array"},
        "calibration": {"type": ["object", "null"]},
    },
}
_SCHEMA_DATA: dict[str, bytes] = {
    "autoteach.Session": json.dumps(_SESSION_SCHEMA).encode(),
    "sensor_msgs/msg/Image": _IMAGE_MSG.encode(),
    "sensor_msgs/msg/JointState": _JOINT_STATE_MSG.encode(),
    "autoteach.GroundTruthScene": json.dumps(_SCENE_SCHEMA).encode(),
    "foxglove.PoseInFrame": json.dumps(_POSE_SCHEMA).encode(),
    "autoteach.VisibleRims": json.dumps(_RIMS_SCHEMA).encode(),
}

_COMPRESSION = ("zstd", "lz4", None, "none")

# Name of the MCAP metadata record holding a copy of the ``/session`` message (``{"json": ...}``).
_METADATA_SESSION = "autoteach.session"

# Chunks of about one frame: a log cut short (a crash while recording) loses only its last frames
# when read with ``allow_truncated=True``, and a reader can seek to any frame.
_CHUNK_SIZE = 128 * 1024


# --------------------------------------------------------------------------------------------
# JSON helpers
# --------------------------------------------------------------------------------------------


def _stamp(t_ns: int) -> dict[str, int]:
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


_JSON_ARRAY_DTYPES = {"<f8": np.float64, "|b1": np.bool_}


def _array_to_json(a: np.ndarray) -> dict[str, Any]:
    dtype = "|b1" if np.asarray(a).dtype == np.bool_ else "<f8"
    a = np.ascontiguousarray(a, dtype=dtype)
    return {"dtype": dtype, "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode("ascii")}


def _array_from_json(d: dict[str, Any]) -> np.ndarray:
    dtype = d.get("dtype")
    if dtype not in _JSON_ARRAY_DTYPES:
        raise ValueError(f"array dtype must be one of {sorted(_JSON_ARRAY_DTYPES)}, got {dtype!r}")
    raw = base64.b64decode(d["data"], validate=True)
    shape = tuple(int(s) for s in d["shape"])
    itemsize = np.dtype(dtype).itemsize
    if int(np.prod(shape)) * itemsize != len(raw):
        raise ValueError(f"array of shape {shape} and dtype {dtype} cannot hold {len(raw)} bytes")
    return np.frombuffer(raw, dtype=dtype).astype(_JSON_ARRAY_DTYPES[dtype]).reshape(shape)


def _quaternion(r: np.ndarray) -> tuple[float, float, float, float]:
    """Return the unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    tr = float(np.trace(r))
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        v = [0.0, 0.0, 0.0]
        v[i] = 0.25 * s
        v[j] = (r[j, i] + r[i, j]) / s
        v[k] = (r[k, i] + r[i, k]) / s
        q = v[0], v[1], v[2], (r[k, j] - r[j, k]) / s
    return tuple(float(x) for x in q)  # type: ignore[return-value]


def _pose_json(t_ns: int, t_wc: np.ndarray) -> bytes:
    qx, qy, qz, qw = _quaternion(t_wc[:3, :3])
    msg = {
        "timestamp": _stamp(t_ns),
        "frame_id": "world",
        "pose": {
            "position": {"x": float(t_wc[0, 3]), "y": float(t_wc[1, 3]), "z": float(t_wc[2, 3])},
            "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
        },
        "matrix": [float(v) for v in t_wc.reshape(16)],
    }
    return json.dumps(msg, allow_nan=False).encode()


def _rim_to_json(r: dict[str, Any]) -> dict[str, Any]:
    ell = r["ellipse"]
    return {
        "wafer": int(r["wafer"]),
        "slot": int(r["slot"]),
        "rim": str(r["rim"]),
        "ellipse": None if ell is None else [float(v) for v in np.asarray(ell).reshape(5)],
        "intervals": np.asarray(r["intervals"], dtype=np.float64).reshape(-1, 2).tolist(),
        "fraction": float(r["fraction"]),
        "points": _array_to_json(np.asarray(r["points"], dtype=np.float64).reshape(-1, 2)),
        "angles": _array_to_json(np.asarray(r["angles"], dtype=np.float64).reshape(-1)),
        "side_facing": _array_to_json(np.asarray(r["side_facing"], dtype=np.bool_).reshape(-1)),
    }


def _rim_from_json(d: dict[str, Any]) -> dict[str, Any]:
    ell = d["ellipse"]
    rim = str(d["rim"])
    if rim not in ("upper", "lower"):
        raise ValueError(f"rim must be 'upper' or 'lower', got {rim!r}")
    return {
        "wafer": int(d["wafer"]),
        "slot": int(d["slot"]),
        "rim": rim,
        "ellipse": None if ell is None else np.asarray(ell, dtype=np.float64).reshape(5),
        "intervals": np.asarray(d["intervals"], dtype=np.float64).reshape(-1, 2),
        "fraction": float(d["fraction"]),
        "points": _array_from_json(d["points"]).reshape(-1, 2),
        "angles": _array_from_json(d["angles"]).reshape(-1),
        "side_facing": _array_from_json(d["side_facing"]).reshape(-1),
    }


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def _dumps(obj: Any, what: str) -> str:
    """JSON text of ``obj``; a NaN or infinity (which JSON cannot hold) is an :class:`InvalidInputError`."""
    try:
        return json.dumps(obj, allow_nan=False)
    except ValueError as exc:
        raise InvalidInputError(f"the {what} cannot be written as JSON: {exc} (NaN or infinity)") from None


def _writable_target(path: Path) -> Path:
    """The ``.part`` file beside ``path`` after checking that both may be written.

    A log is written to ``<path>.part`` and renamed over ``path``. Renaming over something that
    is not a regular file (a device, a FIFO, a directory) would replace it, and opening a FIFO
    ``.part`` would block: both are refused, and nothing is touched.
    """
    part = path.with_name(path.name + ".part")
    if not path.parent.is_dir():
        raise InvalidInputError(f"cannot write the log {path}: the directory {path.parent} does not exist")
    for p, what in ((path, "target"), (part, "temporary file")):
        try:
            st = os.stat(p)
        except FileNotFoundError:
            continue
        except OSError as err:
            raise InvalidInputError(f"cannot write the log: the {what} {p} cannot be inspected ({err})") from None
        if not stat.S_ISREG(st.st_mode):
            raise InvalidInputError(
                f"cannot write the log: the {what} {p} exists and is not a regular file; "
                "choose another path (it was left untouched)"
            )
    return part


def write_log(
    session: Session,
    path: str | os.PathLike[str],
    compression: str | None = "zstd",
    *,
    progress: bool = False,
) -> Path:
    """Write ``session`` to an MCAP log at ``path`` (the channels of the module docstring).

    Ground-truth channels are written when the session has ground truth. The file is written to
    ``<path>.part`` and renamed when complete, so an interrupted write never leaves a log that
    looks finished.

    Args:
        session: the session to store.
        path: output file.
        compression: chunk compression, ``"zstd"`` (default), ``"lz4"`` or ``None``.
        progress: show a progress bar on stderr.

    Returns:
        The path written.

    Raises:
        InvalidInputError: unknown compression or a session that fails :meth:`Session.validate`.
        OSError: the file cannot be written.

    """
    from mcap.writer import CompressionType, Writer
    from tqdm import tqdm

    if compression not in _COMPRESSION:
        raise InvalidInputError(f"compression must be 'zstd', 'lz4' or None, got {compression!r}")
    if not isinstance(session, Session):
        raise InvalidInputError(f"session must be a Session, got {type(session).__name__}")
    session.validate()
    if session.n_frames and session.timestamps[0] < 0:
        raise InvalidInputError("timestamps must be non-negative nanoseconds for MCAP")
    # Ground truth is stored as JSON, which has no NaN or infinity: refuse it rather than fail
    # half-way through the file.
    for name in ("camera_poses", "wafer_poses"):
        value = getattr(session, name)
        if value is not None and not np.all(np.isfinite(value)):
            raise InvalidInputError(f"session.{name} must be finite to be written, it holds NaN or infinity")
    ctype = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(compression or "", CompressionType.NONE)
    path = Path(path)
    part = _writable_target(path)
    gt = session.has_ground_truth
    topics = list(REQUIRED_TOPICS) + ([TOPIC_SCENE, *GROUND_TRUTH_FRAME_TOPICS] if gt else [])
    try:
        with open(part, "wb") as f:
            writer = Writer(f, chunk_size=_CHUNK_SIZE, compression=ctype, enable_data_crcs=True)
            from autoteach import __version__

            writer.start(profile="", library=f"autoteach {__version__}")
            schema_ids: dict[str, int] = {}
            channel: dict[str, int] = {}
            for topic in topics:
                name, schema_enc, msg_enc = TOPICS[topic]
                if name not in schema_ids:
                    schema_ids[name] = writer.register_schema(name=name, encoding=schema_enc, data=_SCHEMA_DATA[name])
                channel[topic] = writer.register_channel(
                    topic=topic, message_encoding=msg_enc, schema_id=schema_ids[name]
                )
            seq: dict[str, int] = defaultdict(int)

            def add(topic: str, t_ns: int, data: bytes) -> None:
                writer.add_message(
                    channel_id=channel[topic], log_time=t_ns, publish_time=t_ns, data=data, sequence=seq[topic]
                )
                seq[topic] += 1

            t0 = int(session.timestamps[0]) if session.n_frames else 0
            meta = {
                "format": "autoteach.session",
                "version": FORMAT_VERSION,
                "camera": session.camera.to_dict(),
                "joint_names": list(session.joint_names),
                "frame_rate_hz": session.frame_rate_hz,
                "frames": session.n_frames,
            }
            meta_json = _dumps(meta, "session metadata")
            add(TOPIC_SESSION, t0, meta_json.encode())
            # The schemas, channels and session metadata close a chunk of their own, and so does the
            # ground-truth scene: a damaged frame chunk then costs that frame only (salvage resumes at
            # the next chunk), where it used to take the metadata -- and so every frame -- with it.
            writer.flush()
            if gt:
                scene = {
                    "seed": session.seed,
                    "config": None if session.config is None else session.config.to_dict(),
                    "wafer_slots": [] if session.wafer_slots is None else [int(s) for s in session.wafer_slots],
                    "wafer_poses": [] if session.wafer_poses is None else session.wafer_poses.tolist(),
                    "calibration": None if session.calibration is None else session.calibration.to_dict(),
                }
                add(TOPIC_SCENE, t0, _dumps(scene, "ground-truth scene").encode())
                writer.flush()
            names = tuple(session.joint_names)
            for i in tqdm(range(session.n_frames), desc="writing", unit="frame", disable=not progress, leave=False):
                t = int(session.timestamps[i])
                add(TOPIC_IMAGE, t, _encode_image(t, session.images[i]))
                add(TOPIC_JOINTS, t, _encode_joint_state(t, names, session.joints_encoder[i]))
                if not gt:
                    continue
                if session.joints_true is not None:
                    add(TOPIC_JOINTS_TRUE, t, _encode_joint_state(t, names, session.joints_true[i]))
                add(TOPIC_CAMERA_POSE, t, _pose_json(t, np.asarray(session.camera_poses[i], dtype=np.float64)))
                if session.rims is not None:
                    msg = {"timestamp": _stamp(t), "frame": i, "rims": [_rim_to_json(r) for r in session.rims[i]]}
                    add(TOPIC_RIMS, t, json.dumps(msg, allow_nan=False).encode())
            # A second copy of the metadata at the other end of the data section: salvage reads it
            # when the first chunk is damaged.
            writer.add_metadata(name=_METADATA_SESSION, data={"json": meta_json})
            writer.finish()
        os.replace(part, path)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    return path


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LogDamage:
    """Where a salvaged log could not be read and what it cost: ``Session.damage`` of a salvaged read.

    Attributes:
        path: the log.
        size: its size in bytes.
        skipped: the byte ranges ``(start, end, reason)`` that could not be read; reading resumed
            at ``end`` (the next intact chunk, found through the summary's chunk index or by
            scanning for a chunk record), or stopped there when ``end == size``.
        frames_expected: the frame count the ``/session`` message announces.
        frames_read: the frames returned.
        frames_lost: indices (the writer's per-frame sequence numbers, 0-based) of the announced
            frames that are not returned; ``None`` when the log's sequence numbers do not number its
            frames.
        notes: other losses (the ground truth scene, the summary section, ...).

    """

    path: str
    size: int
    skipped: tuple[tuple[int, int, str], ...]
    frames_expected: int
    frames_read: int
    frames_lost: tuple[int, ...] | None
    notes: tuple[str, ...] = ()

    def __str__(self) -> str:
        """One paragraph: which byte ranges were skipped and which frames were lost."""
        ranges = "; ".join(f"bytes {a}-{b} ({why})" for a, b, why in self.skipped) or "none"
        if self.frames_lost is None:
            lost = f"{self.frames_expected - self.frames_read} frame(s)"
        elif self.frames_lost:
            lost = "frame(s) " + _ranges_text(self.frames_lost)
        else:
            lost = "no frame"
        notes = "".join(f"; {n}" for n in self.notes)
        return (
            f"salvaged {self.frames_read} of {self.frames_expected} frames from the damaged log {self.path} "
            f"({self.size} bytes): lost {lost}; unreadable byte ranges: {ranges}{notes}"
        )


def _ranges_text(items: tuple[int, ...]) -> str:
    """``0-3, 7, 9-10`` for ``(0, 1, 2, 3, 7, 9, 10)``."""
    out: list[str] = []
    start = prev = items[0]
    for v in (*items[1:], None):
        if v is not None and v == prev + 1:
            prev = v
            continue
        out.append(str(start) if start == prev else f"{start}-{prev}")
        if v is not None:
            start = prev = v
    return ", ".join(out)


class _Scan:
    """Schemas, channels and messages collected from one pass over an MCAP file."""

    def __init__(self) -> None:
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, Any] = {}
        self.messages: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
        self.sequences: dict[str, list[int]] = defaultdict(list)
        self.metadata: dict[str, dict[str, str]] = {}
        self.n_messages = 0
        self.complete = False
        self.error: str | None = None
        self.size = 0
        self.skipped: list[tuple[int, int, str]] = []
        self.summary_damaged = False
        self.notes: list[str] = []

    def topics(self) -> dict[str, tuple[str, str, str]]:
        out = {}
        for ch in self.channels.values():
            schema = self.schemas.get(ch.schema_id)
            out[ch.topic] = (
                schema.name if schema else "",
                schema.encoding if schema else "",
                ch.message_encoding,
            )
        return out


def _chunk_starts(data: bytes) -> list[int]:
    """Start offsets of the chunks listed in the summary's chunk index (empty if it cannot be read).

    The offsets are only hints: a resumed read accepts a chunk only if it parses and passes its CRC.
    """
    import io

    from mcap.records import ChunkIndex, Footer
    from mcap.stream_reader import StreamReader

    n = len(data)
    footer_at = n - len(MCAP_MAGIC) - 29  # opcode, length and the footer's three fields
    if footer_at <= len(MCAP_MAGIC) or data[n - len(MCAP_MAGIC) :] != MCAP_MAGIC or data[footer_at] != 0x02:
        return []
    try:
        footer = next(iter(StreamReader(io.BytesIO(data[footer_at:]), skip_magic=True).records))
        if not isinstance(footer, Footer) or not len(MCAP_MAGIC) < footer.summary_start < footer_at:
            return []
        buf = io.BytesIO(data[footer.summary_start : n - len(MCAP_MAGIC)])
        starts = []
        for rec in StreamReader(buf, skip_magic=True, emit_chunks=True, record_size_limit=n).records:
            if isinstance(rec, ChunkIndex) and 0 < rec.chunk_start_offset < n:
                starts.append(rec.chunk_start_offset)
        return sorted(set(starts))
    # As in _scan: a damaged summary raises any of the decoder's exception types; it only means
    # there is no index to use.
    except Exception:  # noqa: BLE001
        return []


def _next_chunk(data: bytes, after: int, hints: list[int]) -> int | None:
    """The first offset past ``after`` where an intact chunk (or the data-end record) may start."""
    import bisect

    i = bisect.bisect_right(hints, after)
    if i < len(hints):
        return hints[i]
    n = len(data)
    pos = after
    while True:
        chunk = data.find(b"\x06", pos + 1)
        end = data.find(b"\x0f\x04\x00\x00\x00\x00\x00\x00\x00", pos + 1)
        cands = [c for c in (chunk, end) if c >= 0]
        if not cands:
            return None
        pos = min(cands)
        if data[pos] == 0x0F:
            return pos
        # A chunk record: its length must fit in the file and hold at least the chunk's fixed fields.
        if pos + 9 <= n:
            length = int.from_bytes(data[pos + 1 : pos + 9], "little")
            if 40 <= length <= n - pos - 9:
                return pos


def _scan(path: Path, *, salvage: bool = False) -> _Scan:
    """Read every record of an MCAP file; record (not raise) where and why reading stopped.

    A strict scan stops at the first damaged record. A salvage scan resumes at the next intact
    chunk (through the summary's chunk index when it can be read, else by scanning for a chunk
    record) and lists the byte ranges it skipped in ``_Scan.skipped``.
    """
    import io
    import zlib

    from mcap.exceptions import EndOfFile, RecordLengthLimitExceeded
    from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise LogReadError(f"cannot read log {path}: {exc.strerror or exc}") from exc
    scan = _Scan()
    n = scan.size = len(data)
    if data[: len(MCAP_MAGIC)] != MCAP_MAGIC:
        raise LogReadError(
            f"{path} is not an MCAP file: it does not start with the MCAP magic bytes "
            f"(first bytes: {data[:8]!r}, file size {n} bytes)"
        )
    hints = _chunk_starts(data) if salvage else []
    messages: list[tuple[int, int, int, bytes]] = []  # channel id, log time, sequence, data

    def take(rec: Any) -> None:
        if isinstance(rec, Schema):
            scan.schemas.setdefault(rec.id, rec)
        elif isinstance(rec, Channel):
            scan.channels.setdefault(rec.id, rec)
        elif isinstance(rec, Message):
            messages.append((rec.channel_id, rec.log_time, rec.sequence, rec.data))
        elif isinstance(rec, Metadata):
            scan.metadata.setdefault(rec.name, dict(rec.metadata))

    buf = io.BytesIO(data)
    pos = good = len(MCAP_MAGIC)
    data_end = False
    while True:  # ends at the footer, or where no intact chunk follows a damaged record
        good = pos  # end of the last record read completely = start of the next one
        buf.seek(pos)
        reader = StreamReader(buf, skip_magic=True, emit_chunks=True, record_size_limit=n)
        try:
            for rec in reader.records:
                if isinstance(rec, Chunk):
                    # Decompressed and checked against its CRC before any of it is used.
                    for inner in breakup_chunk(rec, validate_crc=True):
                        take(inner)
                elif isinstance(rec, DataEnd):
                    crc = zlib.crc32(memoryview(data)[:good])
                    if not scan.skipped and rec.data_section_crc not in (0, crc):
                        detail = (
                            f"the data section's CRC {crc:#010x} does not match the recorded "
                            f"{rec.data_section_crc:#010x}: a record outside the chunks is damaged"
                        )
                        if not salvage:
                            raise ValueError(detail)
                        # Every chunk passed its own CRC: what is damaged is an index record.
                        scan.notes.append(detail + " (every chunk passed its own CRC)")
                        scan.error = scan.error or f"MCAP log {path} is corrupt: {detail}"
                    data_end = True
                else:
                    take(rec)
                if isinstance(rec, Footer):
                    # The summary CRC covers the summary section and the footer up to this field.
                    crc = zlib.crc32(data[rec.summary_start : good + 25]) if rec.summary_start else 0
                    if rec.summary_crc not in (0, crc) and not scan.summary_damaged:
                        detail = (
                            f"the summary section (bytes {rec.summary_start}-{good}) has CRC {crc:#010x}, "
                            f"not the recorded {rec.summary_crc:#010x}"
                        )
                        scan.summary_damaged = True
                        scan.notes.append(detail + " (the summary is an index; every chunk was read)")
                        scan.error = scan.error or f"MCAP log {path} is corrupt: {detail}"
                    end = buf.tell()
                    if data[end : end + len(MCAP_MAGIC)] != MCAP_MAGIC:
                        good = end
                        raise EndOfFile() if end + len(MCAP_MAGIC) > n else ValueError("no MCAP magic after the footer")
                    scan.complete = not scan.skipped
                good = buf.tell()
            break
        # The pure-Python MCAP decoder raises many exception types on damaged input (its own errors,
        # struct.error, zstd/lz4 errors, UnicodeDecodeError, ...); every one of them means the same
        # thing to the caller -- the log cannot be read past this point -- so all are recorded here.
        except Exception as exc:  # noqa: BLE001
            # The record-size limit is the file size: a longer record runs past the end of the file.
            truncated = isinstance(exc, (EndOfFile, RecordLengthLimitExceeded)) or buf.tell() >= n
            detail = type(exc).__name__ + (f": {exc}" if str(exc) and str(exc) != type(exc).__name__ else "")
            if scan.error is None:
                scan.error = _stop_message(path, n, good, truncated, data_end, len(messages), detail)
            resume = _next_chunk(data, good, hints) if salvage else None
            stop = n if resume is None else resume
            why = ("truncated" if truncated and resume is None else "damaged") + f": {detail}"
            if scan.skipped and scan.skipped[-1][1] == good:
                scan.skipped[-1] = (scan.skipped[-1][0], stop, scan.skipped[-1][2])
            else:
                scan.skipped.append((good, stop, why))
            scan.summary_damaged |= data_end
            if resume is None:
                break
            pos = resume
    if not scan.complete and scan.error is None:
        scan.error = (
            f"MCAP log {path} is truncated: reading stopped at byte offset {good} of {n} after "
            f"{len(messages)} messages without reaching the footer"
        )
    _file_messages(path, scan, messages)
    return scan


def _file_messages(path: Path, scan: _Scan, messages: list[tuple[int, int, int, bytes]]) -> None:
    """File each read message (channel id, log time, sequence, data) under its channel's topic.

    A message whose channel definition was lost (in a damaged chunk, with an unreadable summary)
    is dropped, and the drop is noted.
    """
    orphans = 0
    for channel_id, log_time, sequence, payload in messages:
        ch = scan.channels.get(channel_id)
        if ch is None:
            # Salvage drops it (its channel was in a damaged chunk and the summary is unreadable).
            lost_channel = f"MCAP log {path} is corrupt: a message is on the unknown channel id {channel_id}"
            scan.error = scan.error or lost_channel
            orphans += 1
            continue
        scan.messages[ch.topic].append((log_time, payload))
        scan.sequences[ch.topic].append(sequence)
        scan.n_messages += 1
    if orphans:
        scan.notes.append(f"{orphans} messages on channels whose definition was lost were dropped")


def _stop_message(path: Path, n: int, good: int, truncated: bool, data_end: bool, n_msgs: int, detail: str) -> str:
    """The error of a strict read: where reading stopped, and whether the file was cut or damaged."""
    section = " in the summary section (every message was read)" if data_end else ""
    if truncated and good >= n:
        cut = f"the file ends at byte {n}, after the last complete record{section}"
    elif truncated:
        cut = f"the file ends at byte {n} inside the record starting at byte offset {good}{section}"
    if truncated:
        return f"MCAP log {path} is truncated: {cut}; reading stopped after {n_msgs} messages ({detail})"
    return (
        f"MCAP log {path} is corrupt: reading stopped at the record starting at byte offset {good} "
        f"of {n}{section} after {n_msgs} messages ({detail})"
    )


def _decode_json(path: Path, topic: str, index: int, data: bytes) -> Any:
    try:
        return json.loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise LogReadError(f"{path}: message {index} on {topic} is not valid JSON: {exc}") from exc


def read_log(path: str | os.PathLike[str], *, allow_truncated: bool = False) -> Session:
    """Read a session log written by :func:`write_log` (or a real robot's log with the same channels).

    Args:
        path: the MCAP file.
        allow_truncated: return the complete frames before the point where a truncated or
            corrupt file stops, instead of raising.

    Returns:
        The :class:`Session`; its ground-truth fields are ``None`` when the log has no
        ``/ground_truth/*`` channels.

    Raises:
        LogReadError: the file cannot be opened, is not MCAP, is truncated or corrupt (the
            message names the file, the byte offset where reading stopped and the number of
            messages read), lacks a required channel (named in the message), or holds messages
            that do not decode.

    """
    session, _ = _read(Path(path), allow_truncated)
    return session


def log_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Describe a log: channels, message counts and the session summary (what ``autoteach info`` prints).

    Raises:
        LogReadError: as :func:`read_log`.

    """
    session, scan = _read(Path(path), allow_truncated=False)
    channels = []
    for topic, (schema, schema_enc, msg_enc) in sorted(scan.topics().items()):
        msgs = scan.messages.get(topic, [])
        channels.append(
            {
                "topic": topic,
                "schema": schema,
                "schema_encoding": schema_enc,
                "message_encoding": msg_enc,
                "messages": len(msgs),
            }
        )
    return {
        "path": str(path),
        "bytes": scan.size,
        "messages": scan.n_messages,
        "channels": channels,
        **session.summary(),
    }


def _read(path: Path, allow_truncated: bool) -> tuple[Session, _Scan]:
    scan = _scan(path, salvage=allow_truncated)
    if scan.error is not None and not allow_truncated:
        raise LogReadError(scan.error)
    notes = list(scan.notes)
    topics = scan.topics()
    _check_channels(path, scan, topics)
    camera, joint_names, frame_rate, n_expected = _session_metadata(path, scan, notes)

    # Ground truth present?
    scene = None
    if TOPIC_SCENE in topics and scan.messages.get(TOPIC_SCENE):
        scene = _decode_json(path, TOPIC_SCENE, 0, scan.messages[TOPIC_SCENE][0][1])
    elif scan.error is not None and TOPIC_SCENE in topics:
        notes.append(f"the ground-truth scene ({TOPIC_SCENE}) was lost: the session has no ground truth")
    by_topic, keep = _frame_times(path, scan, scene is not None, allow_truncated, n_expected)
    frames = _decode_frames(path, scan, by_topic, keep, camera, joint_names, scene is not None, allow_truncated, notes)
    session_kw = _ground_truth(path, scene, frames) if scene is not None else {}
    try:
        session = Session(
            timestamps=np.asarray(frames.times, dtype=np.int64),
            joints_encoder=frames.joints,
            images=frames.images,
            camera=camera,
            joint_names=joint_names,
            frame_rate_hz=frame_rate,
            source=str(path),
            **session_kw,
        )
    except InvalidInputError as exc:
        raise LogReadError(f"{path}: the log does not form a valid session: {exc}") from exc
    if scan.error is not None:
        session.damage = _damage(path, scan, by_topic[TOPIC_IMAGE], frames.times, n_expected, notes)
        warnings.warn(str(session.damage), LogSalvageWarning, stacklevel=3)
    return session, scan


def _check_channels(path: Path, scan: _Scan, topics: dict[str, tuple[str, str, str]]) -> None:
    """The session channels are there, each with the schema and encoding this version writes."""
    missing = [t for t in REQUIRED_TOPICS if t not in topics]
    if missing:
        want = ", ".join(f"{t} ({TOPICS[t][0]})" for t in missing)
        found = ", ".join(sorted(topics)) or "none"
        prefix = (
            f"{_skipped_text(scan)}; what could be read of the" if scan.error else f"{path} is an MCAP file but the"
        )
        raise LogReadError(f"{prefix} log lacks the autoteach session channel(s) {want}; found channels: {found}")
    for topic, (schema, schema_enc, msg_enc) in topics.items():
        if topic in TOPICS and (schema, schema_enc, msg_enc) != TOPICS[topic]:
            raise LogReadError(
                f"{path}: channel {topic} has schema {schema!r} ({schema_enc}) with {msg_enc} messages; "
                f"expected {TOPICS[topic][0]!r} ({TOPICS[topic][1]}) with {TOPICS[topic][2]} messages"
            )


def _session_metadata(
    path: Path, scan: _Scan, notes: list[str]
) -> tuple[CameraInfo, tuple[str, ...], float | None, int]:
    """The camera, joint names, frame rate and announced frame count of the session message."""
    if scan.messages.get(TOPIC_SESSION):
        meta = _decode_json(path, TOPIC_SESSION, 0, scan.messages[TOPIC_SESSION][0][1])
    elif "json" in scan.metadata.get(_METADATA_SESSION, {}):
        # The first chunk is damaged; logs written since issue 38 keep a copy at the end.
        meta = _decode_json(
            path, f"the {_METADATA_SESSION} metadata record", 0, scan.metadata[_METADATA_SESSION]["json"]
        )
        notes.append(f"the {TOPIC_SESSION} message was lost; its copy in the {_METADATA_SESSION} metadata was used")
    elif scan.error:
        raise LogReadError(
            f"{_skipped_text(scan)}; the session metadata ({TOPIC_SESSION}) was lost with it, so no frame can be "
            "decoded (logs written by this version keep a second copy at the end of the data section)"
        )
    else:
        raise LogReadError(f"{path}: the {TOPIC_SESSION} channel has no message")
    try:
        if meta.get("format") != "autoteach.session":
            raise ValueError(f"format is {meta.get('format')!r}, expected 'autoteach.session'")
        if int(meta["version"]) > FORMAT_VERSION:
            raise ValueError(f"log format version {meta['version']} is newer than this autoteach ({FORMAT_VERSION})")
        camera = CameraInfo.from_dict(meta["camera"])
        joint_names = tuple(str(n) for n in meta["joint_names"])
        rate = meta.get("frame_rate_hz")
        frame_rate = None if rate is None else float(rate)
        n_expected = int(meta["frames"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise LogReadError(f"{path}: the {TOPIC_SESSION} message is invalid: {exc}") from exc

    return camera, joint_names, frame_rate, n_expected


def _frame_times(
    path: Path, scan: _Scan, ground_truth: bool, allow_truncated: bool, n_expected: int
) -> tuple[dict[str, dict[int, tuple[int, bytes]]], list[int]]:
    """Every frame topic's messages by log time, and the times of the frames that are complete.

    Raises:
        LogReadError: two messages at one time, a frame lacking a message (strict reads), or a
            frame count other than the announced one.
    """

    def by_time(topic: str) -> dict[int, tuple[int, bytes]]:
        out: dict[int, tuple[int, bytes]] = {}
        for idx, (t, data) in enumerate(scan.messages.get(topic, [])):
            if t in out:
                raise LogReadError(f"{path}: two messages on {topic} have the same log time {t} ns")
            out[t] = (idx, data)
        return out

    by_topic = {topic: by_time(topic) for topic in (TOPIC_IMAGE, TOPIC_JOINTS)}
    gt_t = {topic: by_time(topic) for topic in GROUND_TRUTH_FRAME_TOPICS} if ground_truth else {}
    by_topic.update(gt_t)
    joints_t = by_topic[TOPIC_JOINTS]
    times = sorted(by_topic[TOPIC_IMAGE])
    keep: list[int] = []
    for t in times:
        lacking = [TOPIC_JOINTS] if t not in joints_t else []
        lacking += [topic for topic, m in gt_t.items() if t not in m]
        if lacking:
            if allow_truncated and scan.error is not None:
                continue  # a frame whose other messages were in a damaged chunk
            raise LogReadError(
                f"{path}: the image at log time {t} ns (frame {len(keep)}) has no message on {', '.join(lacking)}"
            )
        keep.append(t)
    if scan.error is None and len(keep) != n_expected:
        raise LogReadError(
            f"{path}: the log holds {len(keep)} frames but its {TOPIC_SESSION} message announces {n_expected}"
        )

    return by_topic, keep


@dataclass
class _Frames:
    """The decoded frames of a log (ground-truth fields ``None`` without a scene)."""

    times: list[int]
    images: np.ndarray
    joints: np.ndarray
    joints_true: np.ndarray | None
    poses: np.ndarray | None
    rims: list[list[dict[str, Any]]] | None


def _decode_frames(
    path: Path,
    scan: _Scan,
    by_topic: dict[str, dict[int, tuple[int, bytes]]],
    keep: list[int],
    camera: CameraInfo,
    joint_names: tuple[str, ...],
    ground_truth: bool,
    allow_truncated: bool,
    notes: list[str],
) -> _Frames:
    """Decode the kept frames; a salvage read drops (and notes) a frame it cannot decode."""
    images = np.empty((len(keep), camera.height, camera.width), dtype=np.uint8)
    joints = np.empty((len(keep), len(joint_names)), dtype=np.float64)
    joints_true = np.empty_like(joints) if ground_truth else None
    poses = np.empty((len(keep), 4, 4)) if ground_truth else None
    rims: list[list[dict[str, Any]]] | None = [] if ground_truth else None
    n_ok = 0
    ok_times: list[int] = []
    for t in keep:
        i = n_ok
        topic, idx = TOPIC_IMAGE, by_topic[TOPIC_IMAGE][t][0]
        try:
            img = _decode_image(by_topic[TOPIC_IMAGE][t][1])
            if img.shape != images.shape[1:]:
                raise ValueError(
                    f"image is {img.shape[1]}x{img.shape[0]}, the camera is {camera.width}x{camera.height}"
                )
            images[i] = img
            topic, idx = TOPIC_JOINTS, by_topic[TOPIC_JOINTS][t][0]
            joints[i] = _joint_positions(joint_names, *_decode_joint_state(by_topic[TOPIC_JOINTS][t][1]))
            if ground_truth:
                topic, idx = TOPIC_JOINTS_TRUE, by_topic[TOPIC_JOINTS_TRUE][t][0]
                joints_true[i] = _joint_positions(joint_names, *_decode_joint_state(by_topic[TOPIC_JOINTS_TRUE][t][1]))
                topic, idx = TOPIC_CAMERA_POSE, by_topic[TOPIC_CAMERA_POSE][t][0]
                pose = json.loads(by_topic[TOPIC_CAMERA_POSE][t][1])
                poses[i] = np.asarray(pose["matrix"], dtype=np.float64).reshape(4, 4)
                topic, idx = TOPIC_RIMS, by_topic[TOPIC_RIMS][t][0]
                msg = json.loads(by_topic[TOPIC_RIMS][t][1])
                rims.append([_rim_from_json(r) for r in msg["rims"]])
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
            if allow_truncated and scan.error is not None:
                notes.append(f"message {idx} on {topic} (log time {t} ns) cannot be decoded ({exc}): frame dropped")
                continue
            raise LogReadError(f"{path}: message {idx} on {topic} (log time {t} ns) cannot be decoded: {exc}") from exc
        n_ok += 1
        ok_times.append(t)

    return _Frames(
        ok_times,
        images[:n_ok],
        joints[:n_ok],
        None if joints_true is None else joints_true[:n_ok],
        None if poses is None else poses[:n_ok],
        rims,
    )


def _ground_truth(path: Path, scene: dict[str, Any], frames: _Frames) -> dict[str, Any]:
    """The ground-truth fields of the session from the scene message and the decoded frames."""
    try:
        cfg = scene.get("config")
        cal = scene.get("calibration")
        slots = np.asarray(scene["wafer_slots"], dtype=np.int64)
        return {
            "seed": None if scene.get("seed") is None else int(scene["seed"]),
            "config": None if cfg is None else SimConfig.from_dict(cfg),
            "wafer_slots": slots,
            "wafer_poses": np.asarray(scene["wafer_poses"], dtype=np.float64).reshape(len(slots), 4, 4),
            "calibration": None if cal is None else Calibration.from_dict(cal),
            "joints_true": frames.joints_true,
            "camera_poses": frames.poses,
            "rims": frames.rims,
        }
    except (KeyError, TypeError, ValueError) as exc:
        raise LogReadError(f"{path}: the {TOPIC_SCENE} message is invalid: {exc}") from exc


def _skipped_text(scan: _Scan) -> str:
    """The strict error, followed by the byte ranges a salvage read skipped."""
    if not scan.skipped:
        return str(scan.error)
    ranges = "; ".join(f"bytes {a}-{b} ({why})" for a, b, why in scan.skipped)
    return f"{scan.error}; unreadable byte ranges: {ranges}"


def _damage(
    path: Path,
    scan: _Scan,
    images_t: dict[int, tuple[int, bytes]],
    ok_times: list[int],
    n_expected: int,
    notes: list[str],
) -> LogDamage:
    """What a salvaged read lost: skipped byte ranges and the indices of the frames not returned."""
    seqs = scan.sequences.get(TOPIC_IMAGE, [])
    by_t = {t: seqs[idx] for t, (idx, _) in images_t.items() if idx < len(seqs)}
    numbered = len(set(by_t.values())) == len(by_t) and all(0 <= q < n_expected for q in by_t.values())
    lost = tuple(sorted(set(range(n_expected)) - {by_t[t] for t in ok_times})) if numbered else None
    if scan.summary_damaged and not any("summary" in n for n in notes):
        notes = [*notes, "the summary section is damaged (every chunk before it was read)"]
    if not scan.skipped and not notes:
        notes = [str(scan.error)]
    return LogDamage(
        path=str(path),
        size=scan.size,
        skipped=tuple(scan.skipped),
        frames_expected=n_expected,
        frames_read=len(ok_times),
        frames_lost=lost,
        notes=tuple(notes),
    )


def _joint_positions(expected: tuple[str, ...], names: list[str], position: np.ndarray) -> np.ndarray:
    """Positions in the order of ``expected`` (the session's joint names)."""
    if tuple(names) == expected:
        return position
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in expected if n not in index]
    if missing:
        raise ValueError(f"JointState lacks joints {missing} (has {names})")
    return position[[index[n] for n in expected]]


# --------------------------------------------------------------------------------------------
# Auto-teaching results written back into a log
# --------------------------------------------------------------------------------------------

TOPIC_RESULT_CALIBRATION = "/autoteach/calibration"
TOPIC_RESULT_WAFERS = "/autoteach/wafers"
TOPIC_RESULT_CAMERA_POSE = "/autoteach/camera_pose"
TOPIC_RESULT_UKF = "/autoteach/ukf"
TOPIC_RESULT_HISTORY = "/autoteach/history"
TOPIC_RESULT_EDGES = "/autoteach/edges"
TOPIC_RESULT_RIM_ANNOTATIONS = "/autoteach/rim_annotations"

#: Result channels added by :func:`write_results` (schema name, schema encoding, message encoding).
RESULT_TOPICS: dict[str, tuple[str, str, str]] = {
    TOPIC_RESULT_CALIBRATION: ("autoteach.Calibration", "jsonschema", "json"),
    TOPIC_RESULT_WAFERS: ("autoteach.Wafers", "jsonschema", "json"),
    TOPIC_RESULT_CAMERA_POSE: ("foxglove.PoseInFrame", "jsonschema", "json"),
    TOPIC_RESULT_UKF: ("autoteach.UkfState", "jsonschema", "json"),
    TOPIC_RESULT_HISTORY: ("autoteach.WindowEstimate", "jsonschema", "json"),
    TOPIC_RESULT_EDGES: ("autoteach.EdgeObservations", "jsonschema", "json"),
    TOPIC_RESULT_RIM_ANNOTATIONS: ("foxglove.ImageAnnotations", "jsonschema", "json"),
}
_RESULT_SCHEMAS: dict[str, dict[str, Any]] = {
    "autoteach.Calibration": {
        "title": "autoteach.Calibration",
        "description": "Auto-teaching result: effective base pose T_wb (reference-wafer frame), joint zero "
        "offsets, standard deviations, joint covariance, errors against ground truth when known. Arrays are "
        "base64 little-endian float64 with their shape (NaN: not estimated / unobservable).",
        "type": "object",
    },
    "autoteach.Wafers": {
        "title": "autoteach.Wafers",
        "description": "Wafer estimates [cx, cy, cz, rx, ry] (reference-wafer frame), their standard "
        "deviations, 4x4 poses, slots and theoretical resolution (eq. 5.14).",
        "type": "object",
    },
    "foxglove.PoseInFrame": _POSE_SCHEMA,
    "autoteach.UkfState": {
        "title": "autoteach.UkfState",
        "description": "Per frame: UKF camera pose (world) and joint-offset estimates with standard deviations.",
        "type": "object",
    },
    "autoteach.WindowEstimate": {
        "title": "autoteach.WindowEstimate",
        "description": "Sliding-window estimate after a frame: base pose, joint offsets, standard deviations.",
        "type": "object",
    },
    "autoteach.EdgeObservations": {
        "title": "autoteach.EdgeObservations",
        "description": "Per frame: the edge observations the solver used (wafer index, rim 0 upper / 1 lower, points).",
        "type": "object",
    },
    "foxglove.ImageAnnotations": _IMAGE_ANNOTATIONS_SCHEMA,
}


def _jnum(v: Any) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def _clean(obj: Any) -> Any:
    """JSON-safe copy: NaN/inf become ``None``, numpy scalars/arrays plain Python."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return _jnum(obj)
    return obj


def _result_messages(result: Any, timestamps: np.ndarray) -> list[tuple[str, int, bytes]]:
    """The (topic, time, payload) messages of an :class:`~autoteach.pipeline.AutoTeachResult`."""
    t0 = int(timestamps[0]) if len(timestamps) else 0
    dump = lambda d: json.dumps(_clean(d), allow_nan=False).encode()  # noqa: E731
    out: list[tuple[str, int, bytes]] = []
    d = result.to_dict()
    cal = {
        "timestamp": _stamp(t0),
        "frame_id": "reference_wafer",
        "frontend": result.frontend,
        "base_pose": _array_to_json(result.base_pose),
        "base_std": _array_to_json(result.base_std),
        "joint_offsets": _array_to_json(result.joint_offsets),
        "joint_offsets_std": _array_to_json(result.joint_offsets_std),
        "offset_status": dict(result.offset_status),
        "covariance": None if result.covariance is None else _array_to_json(np.asarray(result.covariance)),
        "unobservable": result.unobservable,
        "rms_px": _jnum(result.rms_px),
        "n_observations": int(result.n_observations),
        "errors": d["errors"],
        "within_3sigma": d["within_3sigma"],
        "frontend_stats": d["frontend_stats"],
        "summary": d["estimates"],
    }
    out.append((TOPIC_RESULT_CALIBRATION, t0, dump(cal)))
    wafers = {
        "timestamp": _stamp(t0),
        "frame_id": "reference_wafer",
        "params": _array_to_json(result.wafer_params),
        "std": _array_to_json(result.wafer_std),
        "poses": _array_to_json(result.wafer_poses),
        "slots": [int(s) for s in result.wafer_slots],
        "resolution": _array_to_json(result.resolution),
    }
    out.append((TOPIC_RESULT_WAFERS, t0, dump(wafers)))
    for f, t_wc in enumerate(np.asarray(result.camera_poses, dtype=np.float64)):
        out.append((TOPIC_RESULT_CAMERA_POSE, int(timestamps[f]), _pose_json(int(timestamps[f]), t_wc)))
    if result.ukf is not None:
        for f in range(len(result.ukf["poses"])):
            t = int(timestamps[f])
            msg = {
                "timestamp": _stamp(t),
                "frame": f,
                "pose": _array_to_json(np.asarray(result.ukf["poses"][f])),
                "offsets": _array_to_json(np.asarray(result.ukf["offsets"][f])),
                "offset_std": _array_to_json(np.asarray(result.ukf["offset_std"][f])),
            }
            out.append((TOPIC_RESULT_UKF, t, dump(msg)))
    for h in result.history:
        f = int(h["last_frame"])
        t = int(timestamps[min(f, len(timestamps) - 1)])
        msg = {
            "timestamp": _stamp(t),
            "last_frame": f,
            "base_pose": _array_to_json(np.asarray(h["base_pose"])),
            "joint_offsets": _array_to_json(np.asarray(h["joint_offsets"])),
            "std": _array_to_json(np.asarray(h["std"])),
        }
        out.append((TOPIC_RESULT_HISTORY, t, dump(msg)))
    obs = result.observations
    if obs:
        per_frame: dict[int, list[dict[str, Any]]] = defaultdict(list)
        for i, (f, w) in enumerate(zip(obs["frames"], obs["wafers"], strict=True)):
            pts = np.asarray(obs["points"][obs["start"][i] : obs["start"][i + 1]])
            rim = int(obs["rims"][i]) if "rims" in obs else 0
            per_frame[int(f)].append({"wafer": int(w), "rim": rim, "points": _array_to_json(pts)})
        for f in sorted(per_frame):
            t = int(timestamps[f])
            out.append((TOPIC_RESULT_EDGES, t, dump({"timestamp": _stamp(t), "frame": f, "edges": per_frame[f]})))
    out += [(TOPIC_RESULT_RIM_ANNOTATIONS, t, data) for t, data in _rim_annotation_messages(result, timestamps)]
    return out


def write_results(
    result: Any,
    log: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    compression: str | None = "zstd",
) -> Path:
    """Copy a session log and add the auto-teaching results on their own ``/autoteach/*`` channels.

    Every schema, channel, message (with its log/publish time and sequence), metadata record and
    attachment of ``log`` is copied unchanged; the channels of :data:`RESULT_TOPICS` are added
    (estimates with standard deviations and covariance, wafers, the per-frame camera poses through
    the calibrated chain, the UKF states, the sliding-window history and the edge observations
    used). ``out=None`` writes back into ``log`` (through a temporary file and an atomic rename).
    Channels of a previous result are replaced, not duplicated.

    Returns:
        The path written.

    Raises:
        LogReadError: ``log`` cannot be read completely (as :func:`read_log`).
        InvalidInputError: the result does not fit the log (frame count) or bad compression.

    """
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    if compression not in _COMPRESSION:
        raise InvalidInputError(f"compression must be 'zstd', 'lz4' or None, got {compression!r}")
    log = Path(log)
    session = read_log(log)
    n = len(np.asarray(result.camera_poses))
    if n != session.n_frames:
        raise InvalidInputError(f"the result has {n} camera poses but the log {log} has {session.n_frames} frames")
    target = Path(out) if out is not None else log
    part = _writable_target(target)
    ctype = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(compression or "", CompressionType.NONE)
    try:
        with open(log, "rb") as fin, open(part, "wb") as fout:
            reader = make_reader(fin)
            header = reader.get_header()
            writer = Writer(fout, chunk_size=_CHUNK_SIZE, compression=ctype, enable_data_crcs=True)
            writer.start(profile=header.profile, library=header.library)
            schema_map: dict[int, int] = {}
            chan_map: dict[int, int] = {}
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                if channel.topic in RESULT_TOPICS:
                    continue
                if channel.id not in chan_map:
                    sid = 0
                    if schema is not None:
                        if schema.id not in schema_map:
                            schema_map[schema.id] = writer.register_schema(
                                name=schema.name, encoding=schema.encoding, data=schema.data
                            )
                        sid = schema_map[schema.id]
                    chan_map[channel.id] = writer.register_channel(
                        topic=channel.topic,
                        message_encoding=channel.message_encoding,
                        schema_id=sid,
                        metadata=dict(channel.metadata),
                    )
                writer.add_message(
                    channel_id=chan_map[channel.id],
                    log_time=message.log_time,
                    publish_time=message.publish_time,
                    data=message.data,
                    sequence=message.sequence,
                )
            for meta in reader.iter_metadata():
                writer.add_metadata(name=meta.name, data=dict(meta.metadata))
            for att in reader.iter_attachments():
                writer.add_attachment(
                    create_time=att.create_time,
                    log_time=att.log_time,
                    name=att.name,
                    media_type=att.media_type,
                    data=att.data,
                )
            write_result_messages(writer, result, session.timestamps)
            writer.finish()
        os.replace(part, target)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    return target


def write_result_messages(writer: Any, result: Any, timestamps: np.ndarray) -> None:
    """Add an auto-teaching result's messages on the ``/autoteach/*`` channels to an MCAP ``writer``.

    Registers each result schema and channel once (:data:`RESULT_TOPICS`); the messages are those
    of :func:`write_results` and are read back by :func:`read_results`.
    """
    new_schema: dict[str, int] = {}
    new_chan: dict[str, int] = {}
    seq: dict[str, int] = defaultdict(int)
    for topic, t, data in _result_messages(result, np.asarray(timestamps, dtype=np.int64)):
        if topic not in new_chan:
            name, schema_enc, msg_enc = RESULT_TOPICS[topic]
            if name not in new_schema:
                new_schema[name] = writer.register_schema(
                    name=name, encoding=schema_enc, data=json.dumps(_RESULT_SCHEMAS[name]).encode()
                )
            new_chan[topic] = writer.register_channel(topic=topic, message_encoding=msg_enc, schema_id=new_schema[name])
        writer.add_message(channel_id=new_chan[topic], log_time=t, publish_time=t, data=data, sequence=seq[topic])
        seq[topic] += 1


def read_results(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read the ``/autoteach/*`` result channels written by :func:`write_results`.

    Returns:
        ``calibration`` and ``wafers`` (dicts with the arrays decoded), ``camera_poses`` (F, 4, 4),
        ``ukf`` (list of per-frame dicts), ``history`` (list) and ``edges`` (per-frame lists of
        ``{wafer, rim, points}``); missing channels give ``None``/empty.

    Raises:
        LogReadError: unreadable log or no ``/autoteach/calibration`` message.

    """
    path = Path(path)
    scan = _scan(path)
    if scan.error is not None:
        raise LogReadError(scan.error)
    msgs = scan.messages
    if not msgs.get(TOPIC_RESULT_CALIBRATION):
        raise LogReadError(f"{path} holds no auto-teaching result (no {TOPIC_RESULT_CALIBRATION} channel)")

    def arrays(d: dict[str, Any]) -> dict[str, Any]:
        return {
            k: (_array_from_json(v) if isinstance(v, dict) and set(v) == {"dtype", "shape", "data"} else v)
            for k, v in d.items()
        }

    def load(topic: str) -> list[dict[str, Any]]:
        return [arrays(_decode_json(path, topic, i, data)) for i, (_, data) in enumerate(msgs.get(topic, []))]

    wafers = load(TOPIC_RESULT_WAFERS)
    edges = load(TOPIC_RESULT_EDGES)
    for e in edges:
        e["edges"] = [arrays(x) for x in e["edges"]]
    poses = [np.array(p["matrix"], dtype=np.float64).reshape(4, 4) for p in load(TOPIC_RESULT_CAMERA_POSE)]
    return {
        "calibration": load(TOPIC_RESULT_CALIBRATION)[0],
        "wafers": wafers[0] if wafers else None,
        "camera_poses": np.stack(poses) if poses else np.zeros((0, 4, 4)),
        "ukf": load(TOPIC_RESULT_UKF),
        "history": load(TOPIC_RESULT_HISTORY),
        "edges": edges,
    }
