"""Lossless PNG ``sensor_msgs/CompressedImage`` against raw ``sensor_msgs/Image`` in zstd chunks.

Renders ``--frames`` frames of a simulated session (seed ``--seed``) and writes their images to
MCAP three ways, chunked as :func:`autoteach.io.write_log` does (128 KiB chunks): raw Image in
zstd chunks (what logs hold today), PNG CompressedImage in uncompressed chunks, PNG in zstd
chunks. Prints bytes per frame, write and read (decode to arrays) time per frame; one run.

    python benchmarks/ros2_images.py --frames 20
"""

from __future__ import annotations

import argparse
import io
import time

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from autoteach.ros2_messages import (
    COMPRESSED_IMAGE,
    IMAGE,
    decode_compressed_image,
    decode_image,
    encode_compressed_image,
    encode_image,
    schema_text,
)
from autoteach.sim import simulate_session


def write(images: np.ndarray, schema: str, encode, compression: CompressionType) -> tuple[bytes, float]:
    buf = io.BytesIO()
    t0 = time.perf_counter()
    w = Writer(buf, chunk_size=128 * 1024, compression=compression)
    w.start()
    sid = w.register_schema(name=schema, encoding="ros2msg", data=schema_text(schema).encode())
    cid = w.register_channel(topic="/camera/image", message_encoding="cdr", schema_id=sid)
    for i, img in enumerate(images):
        w.add_message(channel_id=cid, log_time=i, publish_time=i, data=encode(i, img))
    w.finish()
    return buf.getvalue(), time.perf_counter() - t0


def read(data: bytes, decode) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    out = [decode(m.data) for _, _, m in make_reader(io.BytesIO(data)).iter_messages()]
    return np.stack(out), time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    images = simulate_session(seed=args.seed, frames=args.frames).images
    n = len(images)
    h, w = images.shape[1:]
    print(f"{n} rendered frames of {w}x{h} (raw {h * w / 1e3:.0f} kB each), seed {args.seed}")
    ways = (
        ("raw Image, zstd chunks", IMAGE, encode_image, decode_image, CompressionType.ZSTD),
        ("PNG CompressedImage, plain chunks", COMPRESSED_IMAGE, encode_compressed_image, decode_compressed_image,
         CompressionType.NONE),
        ("PNG CompressedImage, zstd chunks", COMPRESSED_IMAGE, encode_compressed_image, decode_compressed_image,
         CompressionType.ZSTD),
    )  # fmt: skip
    for name, schema, enc, dec, comp in ways:
        data, t_w = write(images, schema, enc, comp)
        back, t_r = read(data, dec)
        assert np.array_equal(back, images), name
        print(
            f"  {name:<36} {len(data) / n / 1e3:8.1f} kB/frame  write {t_w / n * 1e3:6.1f} ms/frame  "
            f"read {t_r / n * 1e3:6.1f} ms/frame"
        )


if __name__ == "__main__":
    main()
