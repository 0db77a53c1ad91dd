"""Tests of the MCAP session logs (autoteach.io)."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from autoteach.errors import AutoteachError, InvalidInputError, LogReadError, LogSalvageWarning
from autoteach.io import TOPICS, log_info, read_log, write_log
from autoteach.session import Session
from autoteach.sim import CameraInfo, SimConfig, simulate_session

SMALL = SimConfig(camera_params=(250.0, 250.0, 159.5, 89.5), width=320, height=180, supersample=2)


@pytest.fixture(scope="module")
def sim_session():
    return simulate_session(seed=4, frames=4, config=SMALL)


@pytest.fixture(scope="module")
def sim_log(sim_session, tmp_path_factory):
    return write_log(sim_session, tmp_path_factory.mktemp("logs") / "sim.mcap")


def bits(a):
    """The raw bytes of an array: equality of these is bit-exact equality (-0.0 != 0.0, NaN payloads)."""
    return np.ascontiguousarray(a).tobytes()


def assert_rims_identical(a, b):
    assert len(a) == len(b)
    for fa, fb in zip(a, b, strict=True):
        assert len(fa) == len(fb)
        for ra, rb in zip(fa, fb, strict=True):
            assert set(ra) == set(rb)
            for key in ("wafer", "slot", "rim"):
                assert ra[key] == rb[key]
            assert bits(np.float64(ra["fraction"])) == bits(np.float64(rb["fraction"]))
            assert (ra["ellipse"] is None) == (rb["ellipse"] is None)
            if ra["ellipse"] is not None:
                assert bits(ra["ellipse"]) == bits(rb["ellipse"])
            for key in ("intervals", "points", "angles", "side_facing"):
                assert ra[key].dtype == rb[key].dtype and ra[key].shape == rb[key].shape
                assert bits(ra[key]) == bits(rb[key])


def assert_sessions_identical(a: Session, b: Session):
    assert bits(a.timestamps) == bits(b.timestamps)
    assert bits(a.images) == bits(b.images) and a.images.shape == b.images.shape
    assert bits(a.joints_encoder) == bits(b.joints_encoder)
    assert a.camera == b.camera and a.joint_names == b.joint_names and a.frame_rate_hz == b.frame_rate_hz
    assert a.seed == b.seed and a.config == b.config
    for key in ("joints_true", "camera_poses", "wafer_poses", "wafer_slots"):
        va, vb = getattr(a, key), getattr(b, key)
        assert (va is None) == (vb is None), key
        if va is not None:
            assert va.dtype == vb.dtype and va.shape == vb.shape, key
            assert bits(va) == bits(vb), key
    if a.calibration is None:
        assert b.calibration is None
    else:
        for key in ("base_pose", "joint_offsets", "camera_mount"):
            assert bits(getattr(a.calibration, key)) == bits(getattr(b.calibration, key)), key
        assert a.calibration.robot_params == b.calibration.robot_params
        assert a.calibration.camera == b.calibration.camera
    if a.rims is None:
        assert b.rims is None
    else:
        assert_rims_identical(a.rims, b.rims)


def synthetic_session(with_truth: bool = True) -> Session:
    """A hand-made session with awkward values: -0.0, subnormals, huge and tiny floats, empty rims."""
    rng = np.random.default_rng(11)
    f, h, w = 3, 5, 7
    special = np.array([-0.0, 5e-324, 1.7976931348623157e308, np.pi, -1e-300])
    joints = rng.normal(size=(f, 5))
    joints[0] = special
    kw = {}
    if with_truth:
        cfg = SimConfig()
        rims = [
            [
                {
                    "wafer": 0,
                    "slot": 4,
                    "rim": "upper",
                    "ellipse": np.array([1.0 / 3.0, -0.0, 2e-7, 1e300, -np.pi]),
                    "intervals": rng.normal(size=(2, 2)),
                    "fraction": 0.1 + 0.2,
                    "points": rng.normal(size=(5, 2)) * 1e3,
                    "angles": rng.normal(size=5),
                    "side_facing": np.array([True, False, True, True, False]),
                },
                {
                    "wafer": 1,
                    "slot": 7,
                    "rim": "lower",
                    "ellipse": None,
                    "intervals": np.zeros((0, 2)),
                    "fraction": 0.0,
                    "points": np.zeros((0, 2)),
                    "angles": np.zeros(0),
                    "side_facing": np.zeros(0, dtype=bool),
                },
            ],
            [],
            [],
        ]
        poses = np.tile(np.eye(4), (f, 1, 1))
        poses[:, :3, 3] = rng.normal(size=(f, 3))
        poses[1, 0, 0] = -0.0
        from autoteach.session import Calibration

        kw = {
            "seed": 123,
            "config": cfg,
            "joints_true": joints + 1e-3,
            "camera_poses": poses,
            "wafer_poses": np.tile(np.eye(4), (2, 1, 1)),
            "wafer_slots": np.array([4, 7]),
            "calibration": Calibration(
                base_pose=cfg.base_pose_matrix,
                joint_offsets=np.array([0.1, -0.2, 1e-9, -0.0, 0.0]),
                camera_mount=np.eye(4),
                robot_params=cfg.robot,
                camera=CameraInfo("pinhole", (1.0, 2.0, 3.0, 4.0), w, h),
            ),
            "rims": rims,
        }
    return Session(
        timestamps=np.array([0, 1, 1_000_000_007], dtype=np.int64),
        joints_encoder=joints,
        images=rng.integers(0, 256, (f, h, w), dtype=np.uint8),
        camera=CameraInfo("pinhole", (1.0, 2.0, 3.0, 4.0), w, h),
        frame_rate_hz=None,
        **kw,
    )


# --- round trips -------------------------------------------------------------------------------


@pytest.mark.parametrize("compression", ["zstd", "lz4", None])
def test_simulated_session_round_trip_is_bit_exact(sim_session, tmp_path, compression):
    path = write_log(sim_session, tmp_path / "s.mcap", compression=compression)
    back = read_log(path)
    assert_sessions_identical(sim_session, back)
    assert back.source == str(path)
    assert back.has_ground_truth


def test_awkward_values_round_trip_bit_exactly(tmp_path):
    s = synthetic_session()
    back = read_log(write_log(s, tmp_path / "x.mcap"))
    assert_sessions_identical(s, back)
    assert np.signbit(back.joints_encoder[0, 0])  # -0.0 survived
    assert back.joints_encoder[0, 1] == 5e-324


def test_session_without_ground_truth(tmp_path):
    """Real robot logs have no ground truth: those fields read back as None."""
    s = synthetic_session(with_truth=False)
    path = write_log(s, tmp_path / "real.mcap")
    with open(path, "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert topics == {"/session", "/camera/image", "/joint_states"}
    back = read_log(path)
    assert_sessions_identical(s, back)
    assert not back.has_ground_truth and back.rims is None and back.config is None


def test_log_is_a_standard_mcap_with_the_documented_channels(sim_log, sim_session):
    with open(sim_log, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == set(TOPICS)
        for topic, (schema, schema_enc, msg_enc) in TOPICS.items():
            ch = channels[topic]
            assert summary.schemas[ch.schema_id].name == schema
            assert summary.schemas[ch.schema_id].encoding == schema_enc
            assert ch.message_encoding == msg_enc
        counts = summary.statistics.channel_message_counts
        n = sim_session.n_frames
        assert counts[channels["/camera/image"].id] == n
        assert counts[channels["/ground_truth/rims"].id] == n
        assert counts[channels["/session"].id] == 1
        # JSON schemas are valid JSON; pose messages carry a unit quaternion equal to the matrix
        for ch in channels.values():
            schema = summary.schemas[ch.schema_id]
            if schema.encoding == "jsonschema":
                assert json.loads(schema.data)["title"] == schema.name
        for _, _, msg in reader.iter_messages(topics=["/ground_truth/camera_pose"]):
            pose = json.loads(msg.data)
            q = pose["pose"]["orientation"]
            x, y, z, w = q["x"], q["y"], q["z"], q["w"]
            r = np.array(
                [
                    [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
                ]
            )
            m = np.array(pose["matrix"]).reshape(4, 4)
            assert np.allclose(r, m[:3, :3], atol=1e-12)
            assert pose["pose"]["position"]["x"] == m[0, 3]


def test_ros2_messages_decode_with_the_foxglove_peer(sim_log, sim_session):
    """Foxglove's own ROS 2 decoder (mcap-ros2-support) reads our hand-written CDR and schemas."""
    decoder = pytest.importorskip("mcap_ros2.decoder")

    def decoded(topic):
        with open(sim_log, "rb") as f:
            reader = make_reader(f, decoder_factories=[decoder.DecoderFactory()])
            return [m for _, _, _, m in reader.iter_decoded_messages(topics=[topic])]

    images = decoded("/camera/image")
    joints = decoded("/joint_states")
    assert len(images) == sim_session.n_frames
    for i, m in enumerate(images):
        assert (m.height, m.width, m.encoding, m.step) == (180, 320, "mono8", 320)
        assert bytes(m.data) == sim_session.images[i].tobytes()
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == sim_session.timestamps[i]
    for i, m in enumerate(joints):
        assert list(m.name) == ["joint1", "joint2", "joint3", "joint4", "lift"]
        assert np.array_equal(np.array(m.position), sim_session.joints_encoder[i])


def test_log_info_lists_channels(sim_log):
    info = log_info(sim_log)
    counts = {c["topic"]: c["messages"] for c in info["channels"]}
    assert counts["/camera/image"] == 4 and counts["/ground_truth/scene"] == 1
    assert info["frames"] == 4 and info["wafers"] == 12


def test_write_rejects_bad_arguments(sim_session, tmp_path):
    with pytest.raises(InvalidInputError, match="compression"):
        write_log(sim_session, tmp_path / "a.mcap", compression="gzip")
    with pytest.raises(InvalidInputError, match="Session"):
        write_log({"images": []}, tmp_path / "a.mcap")
    assert not (tmp_path / "a.mcap").exists()
    assert not (tmp_path / "a.mcap.part").exists()


def test_write_refuses_a_target_that_is_not_a_regular_file(sim_session, tmp_path):
    """Regression: the temporary file was renamed over whatever the target was (a device, as root)."""
    import os

    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    folder = tmp_path / "folder.mcap"
    folder.mkdir()
    for target in (fifo, folder, Path("/dev/null")):
        with pytest.raises(InvalidInputError, match="not a regular file"):
            write_log(sim_session, target)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and folder.is_dir() and stat.S_ISCHR(os.stat("/dev/null").st_mode)
    blocked = tmp_path / "b.mcap"
    os.mkfifo(tmp_path / "b.mcap.part")
    with pytest.raises(InvalidInputError, match="temporary file"):
        write_log(sim_session, blocked)


# --- damaged and foreign files -----------------------------------------------------------------


def test_truncated_log_names_file_and_position(sim_log, tmp_path):
    data = Path(sim_log).read_bytes()
    n = len(data)
    for cut in (3, 8, 45, 500, n // 3, n // 2, n - 200, n - 9, n - 1):
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(data[:cut])
        with pytest.raises(LogReadError) as info:
            read_log(path)
        msg = str(info.value)
        assert str(path) in msg
        if cut >= 8:  # shorter files do not even hold the magic
            assert "truncated" in msg and f"ends at byte {cut}" in msg and "messages" in msg
        if cut > 8:  # cut inside a record: the message says where that record starts
            assert "inside the record starting at byte offset" in msg
        assert isinstance(info.value, OSError) and isinstance(info.value, AutoteachError)


def test_truncated_log_can_be_salvaged(sim_log, sim_session, tmp_path):
    data = Path(sim_log).read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: int(len(data) * 0.8)])
    with pytest.warns(LogSalvageWarning, match="cut.mcap"):
        part = read_log(path, allow_truncated=True)
    k = part.n_frames
    assert 0 < k < sim_session.n_frames
    assert part.damage.frames_lost == tuple(range(k, sim_session.n_frames))
    assert bits(part.images) == bits(sim_session.images[:k])
    assert bits(part.joints_encoder) == bits(sim_session.joints_encoder[:k])
    assert bits(part.camera_poses) == bits(sim_session.camera_poses[:k])
    assert_rims_identical(part.rims, sim_session.rims[:k])


def test_corrupted_byte_is_detected(sim_log, tmp_path):
    data = bytearray(Path(sim_log).read_bytes())
    data[len(data) // 2] ^= 0xFF
    path = tmp_path / "flip.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(LogReadError, match="flip.mcap"):
        read_log(path)


@pytest.mark.parametrize(
    "content",
    [b"", b"hello world, not a log\n", np.random.default_rng(0).bytes(4096), b"\x89PNG\r\n\x1a\n" + bytes(100)],
    ids=["empty", "text", "random", "png"],
)
def test_foreign_file_is_not_mcap(tmp_path, content):
    path = tmp_path / "foreign.bin"
    path.write_bytes(content)
    with pytest.raises(LogReadError, match=r"foreign\.bin is not an MCAP file"):
        read_log(path)


def test_mcap_magic_followed_by_garbage(tmp_path):
    path = tmp_path / "garbage.mcap"
    path.write_bytes(b"\x89MCAP0\r\n" + np.random.default_rng(1).bytes(2000))
    with pytest.raises(LogReadError, match=r"garbage\.mcap is (truncated|corrupt)"):
        read_log(path)


def test_mcap_without_our_channels(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema(name="foo.Bar", encoding="jsonschema", data=b"{}")
        cid = w.register_channel(topic="/lidar/points", message_encoding="json", schema_id=sid)
        w.add_message(channel_id=cid, log_time=1, publish_time=1, data=b"{}")
        w.finish()
    with pytest.raises(LogReadError) as info:
        read_log(path)
    msg = str(info.value)
    assert "other.mcap" in msg and "/camera/image" in msg and "/joint_states" in msg and "/lidar/points" in msg


def test_channel_with_wrong_schema(tmp_path):
    path = tmp_path / "wrong.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        for topic in ("/session", "/camera/image", "/joint_states"):
            sid = w.register_schema(name="foxglove.RawImage", encoding="jsonschema", data=b"{}")
            w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        w.finish()
    with pytest.raises(LogReadError, match="has schema 'foxglove.RawImage'"):
        read_log(path)


def test_missing_file(tmp_path):
    with pytest.raises(LogReadError, match="cannot read log .*nope.mcap") as info:
        read_log(tmp_path / "nope.mcap")
    assert isinstance(info.value, OSError)
