"""Salvage of damaged MCAP session logs (issue 38): reading resumes past a damaged chunk.

The truth is the session that was written: every frame a salvaged read returns must equal, bit
for bit, the written frame with the same timestamp, and the frames it reports lost must be
exactly those whose messages lay in the damaged bytes. Chunk offsets come from the ``mcap``
library's own summary reader, not from autoteach.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from autoteach.errors import LogReadError, LogSalvageWarning
from autoteach.io import TOPIC_SESSION, read_log, write_log
from autoteach.sim import SimConfig, simulate_session

DATA = Path(__file__).parent / "data"
TINY = SimConfig(camera_params=(60.0, 60.0, 39.5, 22.0), width=80, height=45, supersample=1)


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, bytes, list[Any], dict[int, str]]:
    """A 5-frame session, its log's bytes, the chunk index and the channel topics (read by ``mcap``)."""
    session = simulate_session(seed=2, frames=5, config=TINY)
    path = write_log(session, tmp_path_factory.mktemp("salvage") / "five.mcap")
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    topics = {cid: ch.topic for cid, ch in summary.channels.items()}
    return session, path.read_bytes(), chunks, topics


def _frame_chunk(chunks: list[Any], t_ns: int) -> Any:
    """The chunk holding the messages of the frame at log time ``t_ns`` (one frame per chunk here).

    The first two chunks hold the metadata and the scene, stamped with the first frame's time.
    """
    hits = [c for c in chunks[2:] if c.message_start_time == t_ns == c.message_end_time]
    assert len(hits) == 1, "the test log must hold each frame in a chunk of its own"
    return hits[0]


def _salvage(tmp_path: Path, blob: bytes) -> Any:
    path = tmp_path / "damaged.mcap"
    path.write_bytes(blob)
    with pytest.raises(LogReadError, match="damaged.mcap"):
        read_log(path)
    with pytest.warns(LogSalvageWarning, match=r"damaged\.mcap") as warned:
        part = read_log(path, allow_truncated=True)
    assert str(part.damage) in [str(w.message) for w in warned]
    return part


def _assert_frames(part: Any, session: Any, frames: list[int], *, ground_truth: bool = True) -> None:
    """``part`` holds exactly the written ``frames``, bit for bit."""
    assert part.timestamps.tolist() == session.timestamps[frames].tolist()
    assert part.images.tobytes() == session.images[frames].tobytes()
    assert part.joints_encoder.tobytes() == session.joints_encoder[frames].tobytes()
    if ground_truth:
        assert part.camera_poses.tobytes() == session.camera_poses[frames].tobytes()
        assert part.joints_true.tobytes() == session.joints_true[frames].tobytes()
        assert len(part.rims) == len(frames)
        for got, want in zip(part.rims, [session.rims[f] for f in frames], strict=True):
            assert [r["points"].tobytes() for r in got] == [r["points"].tobytes() for r in want]


def _flip(data: bytes, at: int) -> bytes:
    out = bytearray(data)
    out[at] ^= 0x5A
    return bytes(out)


def test_a_log_of_the_layout_before_the_metadata_chunk_reads_bit_exactly() -> None:
    # Produced by write_log before this change (metadata, scene and frames in one chunk).
    want = json.loads((DATA / "session_layout1.json").read_text())
    s = read_log(DATA / "session_layout1.mcap")
    assert s.damage is None and s.n_frames == want["frames"]
    for name in ("timestamps", "images", "joints_encoder", "joints_true", "camera_poses", "wafer_poses", "wafer_slots"):
        assert hashlib.sha256(np.ascontiguousarray(getattr(s, name)).tobytes()).hexdigest() == want[name], name


def test_the_metadata_closes_a_chunk_of_its_own(written: tuple[Any, bytes, list[Any], dict[int, str]]) -> None:
    session, _, chunks, topics = written
    first = chunks[0]
    assert [topics[c] for c in first.message_index_offsets] == [TOPIC_SESSION]
    assert {c.message_start_time for c in chunks[2:]} == set(session.timestamps.tolist())


@pytest.mark.parametrize("frame", [0, 2, 4], ids=["first", "middle", "last"])
def test_a_damaged_frame_chunk_costs_that_frame_only(
    written: tuple[Any, bytes, list[Any], dict[int, str]], tmp_path: Path, frame: int
) -> None:
    session, data, chunks, _ = written
    c = _frame_chunk(chunks, int(session.timestamps[frame]))
    part = _salvage(tmp_path, _flip(data, c.chunk_start_offset + c.chunk_length // 2))
    _assert_frames(part, session, [f for f in range(5) if f != frame])
    assert part.damage.frames_lost == (frame,) and part.damage.frames_expected == 5
    end = c.chunk_start_offset + c.chunk_length
    # Reading resumed at the next chunk: what was skipped is this chunk and its message indexes.
    ((start, stop, why),) = part.damage.skipped
    assert start == c.chunk_start_offset and end <= stop and "damaged" in why
    assert all(d.chunk_start_offset >= stop for d in chunks if d.chunk_start_offset > start)
    assert f"lost frame(s) {frame}" in str(part.damage)


def test_a_damaged_metadata_chunk_is_read_from_its_copy(
    written: tuple[Any, bytes, list[Any], dict[int, str]], tmp_path: Path
) -> None:
    session, data, chunks, _ = written
    c = chunks[0]
    part = _salvage(tmp_path, _flip(data, c.chunk_start_offset + c.chunk_length - 20))
    _assert_frames(part, session, list(range(5)))
    assert part.damage.frames_lost == () and part.damage.skipped[0][0] == c.chunk_start_offset
    assert any("metadata was used" in n for n in part.damage.notes)
    assert part.camera == session.camera and part.joint_names == session.joint_names


def test_a_damaged_scene_chunk_loses_the_ground_truth_only(
    written: tuple[Any, bytes, list[Any], dict[int, str]], tmp_path: Path
) -> None:
    session, data, chunks, _ = written
    c = chunks[1]
    part = _salvage(tmp_path, _flip(data, c.chunk_start_offset + c.chunk_length // 2))
    _assert_frames(part, session, list(range(5)), ground_truth=False)
    assert part.camera_poses is None and any("ground-truth scene" in n for n in part.damage.notes)


def test_a_damaged_summary_loses_nothing(written: tuple[Any, bytes, list[Any], dict[int, str]], tmp_path: Path) -> None:
    session, data, chunks, _ = written
    last = chunks[-1]
    # The summary follows the last chunk, its message indexes and the data-end record; the
    # footer (29 bytes before the closing magic) records where it starts.
    summary_start = int.from_bytes(data[-8 - 29 + 9 : -8 - 29 + 17], "little")
    assert summary_start > last.chunk_start_offset + last.chunk_length
    part = _salvage(tmp_path, _flip(data, summary_start + 30))
    _assert_frames(part, session, list(range(5)))
    assert part.damage.frames_lost == ()
    assert any("summary" in n for n in part.damage.notes)


def test_a_truncated_log_loses_the_cut_frames(
    written: tuple[Any, bytes, list[Any], dict[int, str]], tmp_path: Path
) -> None:
    session, data, chunks, _ = written
    c = _frame_chunk(chunks, int(session.timestamps[3]))
    part = _salvage(tmp_path, data[: c.chunk_start_offset + 100])
    _assert_frames(part, session, [0, 1, 2])
    assert part.damage.frames_lost == (3, 4)
    assert part.damage.skipped == ((c.chunk_start_offset, c.chunk_start_offset + 100, part.damage.skipped[0][2]),)
    assert part.damage.skipped[0][2].startswith("truncated")


def test_a_broken_chunk_header_without_a_summary_is_skipped_by_scanning(
    written: tuple[Any, bytes, list[Any], dict[int, str]], tmp_path: Path
) -> None:
    # The record length of frame 1's chunk is destroyed and the file is cut inside frame 4's
    # chunk, so there is no chunk index: the reader finds frames 2 and 3 by scanning.
    session, data, chunks, _ = written
    c1 = _frame_chunk(chunks, int(session.timestamps[1]))
    c4 = _frame_chunk(chunks, int(session.timestamps[4]))
    blob = bytearray(data[: c4.chunk_start_offset + c4.chunk_length // 2])
    blob[c1.chunk_start_offset + 1 : c1.chunk_start_offset + 9] = b"\xff" * 8
    part = _salvage(tmp_path, bytes(blob))
    _assert_frames(part, session, [0, 2, 3])
    assert part.damage.frames_lost == (1, 4)
    starts = [a for a, _, _ in part.damage.skipped]
    assert starts == [c1.chunk_start_offset, c4.chunk_start_offset]


def test_a_damaged_first_chunk_of_the_old_layout_says_what_was_lost(tmp_path: Path) -> None:
    # The old layout holds the metadata and every frame in its first chunk: nothing can be
    # decoded, and the error says so and where the damage lies.
    data = (DATA / "session_layout1.mcap").read_bytes()
    with open(DATA / "session_layout1.mcap", "rb") as f:
        (chunk,) = make_reader(f).get_summary().chunk_indexes
    path = tmp_path / "old.mcap"
    path.write_bytes(_flip(data, chunk.chunk_start_offset + chunk.chunk_length // 2))
    with pytest.raises(LogReadError, match=rf"bytes {chunk.chunk_start_offset}-\d+ .*session metadata"):
        read_log(path, allow_truncated=True)
