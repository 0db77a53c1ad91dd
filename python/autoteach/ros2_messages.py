"""ROS 2 messages of the session logs, encoded and decoded by mcap-ros2-support, and Foxglove image annotations.

- ``sensor_msgs/msg/Image`` (mono8) and ``sensor_msgs/msg/JointState``: CDR through
  ``mcap_ros2``'s dynamic (de)serialisers built from the concatenated message definitions that
  :mod:`autoteach.io` stores as the channels' schemas. The bytes are those of the hand-written
  encoder the logs were written with before (``tests/data/ros2_cdr_reference.json`` keeps them),
  so old logs read back bit-exactly.
- ``sensor_msgs/msg/CompressedImage`` with lossless PNG (``format = "mono8; png compressed"``):
  a grey-scale PNG written with ``zlib`` and NumPy (filter "Up" on every row), read back for the
  filters it writes (None, Sub, Up). ``benchmarks/ros2_images.py`` measures it against raw images
  in zstd chunks; see docs/design/fleet.md for where it pays off.
- ``foxglove.ImageAnnotations`` (JSON with its JSON schema): the detected rim points of a frame
  as ``POINTS`` annotations, one per (wafer, rim), coloured per wafer, with the wafer id as a label,
  so that Foxglove's image panel draws the detections over the camera image.
"""

from __future__ import annotations

import functools
import json
import struct
import zlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

IMAGE = "sensor_msgs/msg/Image"
JOINT_STATE = "sensor_msgs/msg/JointState"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
IMAGE_ANNOTATIONS = "foxglove.ImageAnnotations"
#: The ``format`` field of the PNG compressed images (as ROS 2's image_transport writes it).
PNG_FORMAT = "mono8; png compressed"
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_SEP = "=" * 80
_TIME_MSG = "int32 sec\nuint32 nanosec\n"
_HEADER_MSG = "builtin_interfaces/Time stamp\nstring frame_id\n"
_ROS2_DEPS = f"\n{_SEP}\nMSG: std_msgs/Header\n{_HEADER_MSG}\n{_SEP}\nMSG: builtin_interfaces/Time\n{_TIME_MSG}"
#: The concatenated ROS 2 definition of ``sensor_msgs/msg/Image`` stored as its channels' schema.
IMAGE_DEFINITION = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\n"
    "uint8[] data\n" + _ROS2_DEPS
)
#: The concatenated ROS 2 definition of ``sensor_msgs/msg/JointState``.
JOINT_STATE_DEFINITION = (
    "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n" + _ROS2_DEPS
)
_COMPRESSED_IMAGE_MSG = "std_msgs/Header header\nstring format\nuint8[] data\n" + _ROS2_DEPS


class Ros2DecodeError(ValueError):
    """A ROS 2 message (or its PNG payload) that cannot be decoded: the message says what is wrong."""


def schema_text(name: str) -> str:
    """The concatenated ROS 2 message definition stored as the schema of ``name``'s channels."""
    texts = {IMAGE: IMAGE_DEFINITION, JOINT_STATE: JOINT_STATE_DEFINITION, COMPRESSED_IMAGE: _COMPRESSED_IMAGE_MSG}
    return texts[name]


@functools.cache
def _encoder(name: str) -> Callable[[Any], bytes]:
    from mcap_ros2._dynamic import serialize_dynamic

    return serialize_dynamic(name, schema_text(name))[name]


@functools.cache
def _decoder(name: str) -> Callable[[bytes], Any]:
    from mcap_ros2._dynamic import generate_dynamic

    return generate_dynamic(name, schema_text(name))[name]


def _header(t_ns: int, frame_id: str) -> dict[str, Any]:
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame_id}


def _decode(name: str, data: bytes | memoryview) -> Any:
    raw = bytes(data)
    if len(raw) >= 2 and raw[:2] not in (b"\x00\x00", b"\x00\x01"):
        raise Ros2DecodeError(f"unsupported CDR encapsulation {raw[:2].hex()} (plain CDR 0000/0001 is read)")
    try:
        return _decoder(name)(raw)
    except (ValueError, IndexError, struct.error, UnicodeDecodeError, TypeError) as exc:
        raise Ros2DecodeError(f"{name} message of {len(raw)} bytes cannot be decoded: {exc}") from exc


def encode_image(t_ns: int, image: np.ndarray, frame_id: str = "camera") -> bytes:
    """CDR bytes of a ``sensor_msgs/msg/Image`` (mono8, row step = width) of a (H, W) uint8 image."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    h, w = img.shape
    msg = {
        "header": _header(t_ns, frame_id),
        "height": h,
        "width": w,
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": w,
        "data": img.tobytes(),
    }
    return _encoder(IMAGE)(msg)


def decode_image(data: bytes | memoryview) -> np.ndarray:
    """The (H, W) uint8 image of a mono8 ``sensor_msgs/msg/Image`` (rows longer than the width are cropped).

    Raises:
        Ros2DecodeError: not decodable, another encoding, or a size that does not match the data.

    """
    m = _decode(IMAGE, data)
    h, w, step = int(m.height), int(m.width), int(m.step)
    pixels = bytes(m.data)
    if m.encoding not in ("mono8", "8UC1"):
        raise Ros2DecodeError(f"image encoding {m.encoding!r} is not supported (need mono8)")
    if step < w or len(pixels) != h * step:
        raise Ros2DecodeError(f"image of {h}x{w} with step {step} cannot hold {len(pixels)} bytes")
    return np.frombuffer(pixels, dtype=np.uint8).reshape(h, step)[:, :w]


def encode_joint_state(t_ns: int, names: Sequence[str], position: np.ndarray, frame_id: str = "base") -> bytes:
    """CDR bytes of a ``sensor_msgs/msg/JointState`` with names and positions (no velocity, no effort)."""
    pos = np.asarray(position, dtype=np.float64).reshape(-1)
    msg = {
        "header": _header(t_ns, frame_id),
        "name": list(names),
        "position": pos.tolist(),
        "velocity": [],
        "effort": [],
    }
    return _encoder(JOINT_STATE)(msg)


def decode_joint_state(data: bytes | memoryview) -> tuple[list[str], np.ndarray]:
    """The names and positions of a ``sensor_msgs/msg/JointState``.

    Raises:
        Ros2DecodeError: not decodable, or not one position per name.

    """
    m = _decode(JOINT_STATE, data)
    names = [str(n) for n in m.name]
    position = np.asarray(m.position, dtype=np.float64).reshape(-1)
    if len(position) != len(names):
        raise Ros2DecodeError(f"JointState has {len(names)} names but {len(position)} positions")
    return names, position


# --------------------------------------------------------------------------------------------
# Lossless PNG (grey, 8 bit) with zlib and NumPy
# --------------------------------------------------------------------------------------------


def _chunk(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))


def png_encode(image: np.ndarray, level: int = 6) -> bytes:
    """A grey-scale 8-bit PNG of a (H, W) uint8 image; every row filtered with "Up" (PNG spec. §9.2, type 2)."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"png_encode needs a non-empty (H, W) image, got shape {img.shape}")
    h, w = img.shape
    up = np.empty((h, w + 1), dtype=np.uint8)
    up[:, 0] = 2
    up[0, 1:] = img[0]
    up[1:, 1:] = img[1:] - img[:-1]  # uint8 arithmetic wraps modulo 256, as the filter is defined
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    idat = _chunk(b"IDAT", zlib.compress(up.tobytes(), level))
    return _PNG_MAGIC + _chunk(b"IHDR", ihdr) + idat + _chunk(b"IEND", b"")


def png_decode(data: bytes | memoryview) -> np.ndarray:
    """The (H, W) uint8 image of a grey-scale 8-bit, non-interlaced PNG whose rows use filters None, Sub or Up.

    Raises:
        Ros2DecodeError: not such a PNG (the message says which part differs), or corrupt.

    """
    raw = bytes(data)
    if not raw.startswith(_PNG_MAGIC):
        raise Ros2DecodeError("not a PNG (bad signature)")
    pos, ihdr, idat = 8, None, []
    while pos + 12 <= len(raw):
        (n,) = struct.unpack(">I", raw[pos : pos + 4])
        kind, payload = raw[pos + 4 : pos + 8], raw[pos + 8 : pos + 8 + n]
        if len(payload) != n or struct.unpack(">I", raw[pos + 8 + n : pos + 12 + n] or b"\0\0\0\0")[0] != zlib.crc32(
            kind + payload
        ):
            raise Ros2DecodeError(f"PNG chunk {kind!r} at byte {pos} is truncated or fails its CRC")
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", payload)
        elif kind == b"IDAT":
            idat.append(payload)
        elif kind == b"IEND":
            break
        pos += 12 + n
    if ihdr is None or not idat:
        raise Ros2DecodeError("PNG without IHDR or IDAT chunk")
    w, h, depth, colour, _, _, interlace = ihdr
    if (depth, colour, interlace) != (8, 0, 0):
        raise Ros2DecodeError(f"PNG of bit depth {depth}, colour type {colour}, interlace {interlace}: need 8, 0, 0")
    try:
        rows = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    except zlib.error as exc:
        raise Ros2DecodeError(f"PNG image data does not decompress: {exc}") from exc
    if rows.size != h * (w + 1):
        raise Ros2DecodeError(f"PNG image data holds {rows.size} bytes, a {w}x{h} image needs {h * (w + 1)}")
    rows = rows.reshape(h, w + 1)
    out = np.empty((h, w), dtype=np.uint8)
    for y in range(h):
        f, line = rows[y, 0], rows[y, 1:]
        if f == 0:
            out[y] = line
        elif f == 1:
            out[y] = np.cumsum(line, dtype=np.uint8)  # wraps modulo 256
        elif f == 2:
            out[y] = line + (out[y - 1] if y else 0)
        else:
            raise Ros2DecodeError(f"PNG row {y} uses filter type {f}; only None, Sub and Up are read")
    return out


def encode_compressed_image(t_ns: int, image: np.ndarray, frame_id: str = "camera") -> bytes:
    """CDR bytes of a ``sensor_msgs/msg/CompressedImage`` holding the image as a lossless PNG."""
    msg = {"header": _header(t_ns, frame_id), "format": PNG_FORMAT, "data": png_encode(image)}
    return _encoder(COMPRESSED_IMAGE)(msg)


def decode_compressed_image(data: bytes | memoryview) -> np.ndarray:
    """The (H, W) uint8 image of a PNG ``sensor_msgs/msg/CompressedImage``.

    Raises:
        Ros2DecodeError: not decodable, not PNG, or a PNG :func:`png_decode` does not read.

    """
    m = _decode(COMPRESSED_IMAGE, data)
    if "png" not in str(m.format).lower():
        raise Ros2DecodeError(f"compressed image format {m.format!r} is not PNG")
    return png_decode(m.data)


# --------------------------------------------------------------------------------------------
# foxglove.ImageAnnotations (JSON)
# --------------------------------------------------------------------------------------------


def _obj(title: str, **props: Any) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": props}


_NUM = {"type": "number"}
_COLOR = _obj("foxglove.Color", r=_NUM, g=_NUM, b=_NUM, a=_NUM)
_POINT2 = _obj("foxglove.Point2", x=_NUM, y=_NUM)
_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}
_TYPES = ("UNKNOWN", "POINTS", "LINE_LOOP", "LINE_STRIP", "LINE_LIST")
#: The JSON schema of ``foxglove.ImageAnnotations`` (Foxglove's message schema) stored with the channel.
IMAGE_ANNOTATIONS_SCHEMA: dict[str, Any] = {
    "title": IMAGE_ANNOTATIONS,
    "description": "Array of annotations for a 2D image",
    "type": "object",
    "properties": {
        "circles": {
            "type": "array",
            "items": _obj(
                "foxglove.CircleAnnotation",
                timestamp=_TIME,
                position=_POINT2,
                diameter=_NUM,
                thickness=_NUM,
                fill_color=_COLOR,
                outline_color=_COLOR,
            ),
        },
        "points": {
            "type": "array",
            "items": _obj(
                "foxglove.PointsAnnotation",
                timestamp=_TIME,
                type={
                    "title": "foxglove.PointsAnnotationType",
                    "oneOf": [{"title": t, "const": i} for i, t in enumerate(_TYPES)],
                },
                points={"type": "array", "items": _POINT2},
                outline_color=_COLOR,
                outline_colors={"type": "array", "items": _COLOR},
                fill_color=_COLOR,
                thickness=_NUM,
            ),
        },
        "labels": {
            "type": "array",
            "items": _obj(
                "foxglove.TextAnnotation",
                timestamp=_TIME,
                position=_POINT2,
                text={"type": "string"},
                font_size=_NUM,
                text_color=_COLOR,
                background_color=_COLOR,
            ),
        },
    },
}


def wafer_color(wafer: int) -> tuple[float, float, float]:
    """A distinct colour per wafer id (golden-ratio hue steps), RGB in [0, 1]."""
    import colorsys

    return colorsys.hsv_to_rgb((0.618_033_988_75 * int(wafer)) % 1.0, 0.85, 1.0)


def rim_annotations(t_ns: int, rims: Sequence[tuple[int, int, np.ndarray]]) -> dict[str, Any]:
    """A ``foxglove.ImageAnnotations`` message of one frame's detected rims.

    Args:
        t_ns: the image's log time (ns); Foxglove pairs annotations with the image of the same stamp.
        rims: ``(wafer, rim, points)`` per observed rim (rim 0 upper, 1 lower; points (N, 2) pixels).

    Returns:
        The JSON-ready message: one ``POINTS`` annotation per rim (upper rims opaque, lower ones
        half transparent) and a label with the wafer id at the first point of its upper rim.

    """
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    stamp = {"sec": sec, "nsec": nsec}
    points, labels, labelled = [], [], set()
    for wafer, rim, pts in rims:
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        p = p[np.isfinite(p).all(axis=1)]
        if len(p) == 0:
            continue
        r, g, b = wafer_color(wafer)
        color = {"r": r, "g": g, "b": b, "a": 1.0 if rim == 0 else 0.5}
        points.append(
            {
                "timestamp": stamp,
                "type": 1,
                "points": [{"x": float(x), "y": float(y)} for x, y in p],
                "outline_color": color,
                "thickness": 3.0,
            }
        )
        if int(wafer) not in labelled:
            labelled.add(int(wafer))
            labels.append(
                {
                    "timestamp": stamp,
                    "position": {"x": float(p[0, 0]), "y": float(p[0, 1])},
                    "text": f"wafer {int(wafer)}",
                    "font_size": 14.0,
                    "text_color": color,
                    "background_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.6},
                }
            )
    return {"circles": [], "points": points, "labels": labels}


def rim_annotation_messages(result: Any, timestamps: np.ndarray) -> list[tuple[int, bytes]]:
    """``(log time, JSON bytes)`` of the ``foxglove.ImageAnnotations`` of each frame with observations in ``result``."""
    obs = getattr(result, "observations", None)
    if not obs:
        return []
    per_frame: dict[int, list[tuple[int, int, np.ndarray]]] = {}
    rims = obs.get("rims")
    for i, (f, w) in enumerate(zip(obs["frames"], obs["wafers"], strict=True)):
        pts = np.asarray(obs["points"][obs["start"][i] : obs["start"][i + 1]])
        per_frame.setdefault(int(f), []).append((int(w), int(rims[i]) if rims is not None else 0, pts))
    out = []
    for f in sorted(per_frame):
        t = int(timestamps[f])
        out.append((t, json.dumps(rim_annotations(t, per_frame[f]), allow_nan=False).encode()))
    return out
