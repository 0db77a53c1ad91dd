"""ROS 2 messages through mcap-ros2-support, PNG compressed images and Foxglove rim annotations.

Truths: the bytes of the hand-written CDR encoder the logs were written with before
(``tests/data/ros2_cdr_reference.json``), ``mcap_ros2``'s own MCAP decoder on an old log, OpenCV
reading our PNGs, and Foxglove's JSON schema of ``foxglove.ImageAnnotations``
(``tests/data/foxglove_image_annotations.schema.json``, made strict: no field outside it).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from autoteach import io, ros2_messages
from autoteach.io import TOPIC_IMAGE, TOPIC_JOINTS, read_log, read_results, write_log, write_results
from autoteach.pipeline import autoteach
from autoteach.ros2_messages import (
    Ros2DecodeError,
    decode_compressed_image,
    decode_image,
    decode_joint_state,
    encode_compressed_image,
    encode_image,
    encode_joint_state,
    png_decode,
    png_encode,
)
from autoteach.sim import simulate_session

DATA = Path(__file__).parent / "data"


def test_the_bytes_are_those_of_the_earlier_encoder():
    ref = json.loads((DATA / "ros2_cdr_reference.json").read_text())
    for c in ref["images"]:
        img = np.array(c["pixels"], dtype=np.uint8)
        data = encode_image(c["t_ns"], img)
        assert data.hex() == c["cdr_hex"]
        assert np.array_equal(decode_image(data), img)
    for c in ref["joint_states"]:
        data = encode_joint_state(c["t_ns"], c["names"], np.array(c["position"]))
        assert data.hex() == c["cdr_hex"]
        names, pos = decode_joint_state(data)
        assert names == c["names"] and pos.tolist() == c["position"]
    assert io._encode_image is encode_image and io._decode_joint_state is decode_joint_state


def test_an_old_log_decodes_with_mcap_ros2_and_reads_back_bit_exactly():
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    session = read_log(DATA / "session_layout1.mcap")
    images, joints = [], []
    with open(DATA / "session_layout1.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=[TOPIC_IMAGE, TOPIC_JOINTS]):
            if channel.topic == TOPIC_IMAGE:
                images.append(np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)[:, : msg.width])
            else:
                joints.append(np.array(msg.position))
    assert np.array_equal(np.stack(images), session.images)
    assert np.array_equal(np.stack(joints), session.joints_encoder)


def test_bad_messages_are_clear_errors():
    good = encode_image(5, np.zeros((3, 4), dtype=np.uint8))
    with pytest.raises(Ros2DecodeError, match="cannot be decoded"):
        decode_image(good[:20])
    with pytest.raises(Ros2DecodeError, match="encapsulation"):
        decode_image(b"\x00\x07" + good[2:])
    two_names_one_position = ros2_messages._encoder(ros2_messages.JOINT_STATE)(
        {"header": ros2_messages._header(0, "b"), "name": ["a", "b"], "position": [1.0], "velocity": [], "effort": []}
    )
    with pytest.raises(Ros2DecodeError, match="2 names but 1 positions"):
        decode_joint_state(two_names_one_position)
    bgr = ros2_messages._encoder(ros2_messages.IMAGE)(
        {"header": ros2_messages._header(0, "c"), "height": 1, "width": 1, "encoding": "bgr8", "step": 3,
         "is_bigendian": 0, "data": b"\x00\x00\x00"}
    )  # fmt: skip
    with pytest.raises(Ros2DecodeError, match="bgr8"):
        decode_image(bgr)


def test_png_round_trip_and_opencv_reads_it():
    cv2 = pytest.importorskip("cv2")
    img = simulate_session(seed=2, frames=1).images[0]
    data = png_encode(img)
    assert np.array_equal(png_decode(data), img)
    assert np.array_equal(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED), img)
    msg = encode_compressed_image(7, img)
    assert np.array_equal(decode_compressed_image(msg), img)
    with pytest.raises(Ros2DecodeError, match="CRC"):
        png_decode(data[:-20] + bytes(20))
    with pytest.raises(Ros2DecodeError, match="signature"):
        png_decode(b"GIF89a")
    ok, peer = cv2.imencode(".png", np.ascontiguousarray(img))
    try:
        assert np.array_equal(png_decode(peer.tobytes()), img)  # OpenCV's rows happen to use filters 0-2 only
    except Ros2DecodeError as exc:
        assert "filter type" in str(exc)  # Average/Paeth rows: refused with a clear error, never misread


def _strict(schema):
    s = copy.deepcopy(schema)

    def walk(node):
        if isinstance(node, dict):
            if node.get("type") == "object" and "properties" in node:
                node["additionalProperties"] = False
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(s)
    return s


def test_rim_annotations_validate_against_the_foxglove_schema(tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    official = _strict(json.loads((DATA / "foxglove_image_annotations.schema.json").read_text()))
    session = simulate_session(seed=3, frames=12, render=False)
    log = write_log(session, tmp_path / "s.mcap")
    result = autoteach(read_log(log), frontend="simulated")
    out = write_results(result, log, tmp_path / "r.mcap")
    from mcap.reader import make_reader

    with open(out, "rb") as f:
        msgs = [
            (s, m) for s, c, m in make_reader(f).iter_messages(topics=[io.TOPIC_RESULT_RIM_ANNOTATIONS])
        ]  # fmt: skip
    assert msgs and msgs[0][0].name == "foxglove.ImageAnnotations" and msgs[0][0].encoding == "jsonschema"
    jsonschema.Draft7Validator.check_schema(json.loads(msgs[0][0].data))
    obs = result.observations
    n_points = 0
    for _, m in msgs:
        ann = json.loads(m.data)
        jsonschema.validate(ann, official)
        assert {p["timestamp"]["sec"] * 10**9 + p["timestamp"]["nsec"] for p in ann["points"]} == {m.log_time}
        n_points += sum(len(p["points"]) for p in ann["points"])
    assert n_points == len(obs["points"])
    first = json.loads(msgs[0][1].data)["points"][0]["points"][0]
    assert (first["x"], first["y"]) == tuple(np.asarray(obs["points"][0], dtype=float))
    with pytest.raises(jsonschema.ValidationError):
        bad = json.loads(msgs[0][1].data)
        bad["points"][0]["type"] = 9
        jsonschema.validate(bad, official)
    assert read_results(out)["calibration"]["frontend"] == "simulated"
