"""Tests of the tracking metrics of autoteach.track: hand-made cases with known answers and
py-motmetrics (the reference implementation) on identical random sequences."""

from __future__ import annotations

import numpy as np
import pytest

from autoteach.errors import InvalidInputError
from autoteach.track import Edge, Track, clear_mot, identity_changes, idf1


def test_perfect_tracking() -> None:
    frames = [([1, 2], ["a", "b"], [[0.0, np.inf], [np.inf, 0.0]])] * 5
    m = clear_mot(frames)
    assert (m["mota"], m["idsw"], m["fn"], m["fp"], m["num_gt"]) == (1.0, 0.0, 0.0, 0.0, 10.0)
    assert idf1(frames)["idf1"] == 1.0


def test_one_swap_known_answers() -> None:
    # Two objects, 4 frames; the hypotheses swap after frame 1.
    same = [[0.0, np.inf], [np.inf, 0.0]]
    swapped = [[np.inf, 0.0], [0.0, np.inf]]
    frames = [([1, 2], ["a", "b"], same)] * 2 + [([1, 2], ["a", "b"], swapped)] * 2
    m = clear_mot(frames)
    assert m["idsw"] == 2.0  # both objects switch once
    assert m["mota"] == pytest.approx(1.0 - 2.0 / 8.0)
    # Best global identity matching keeps 2 of 4 frames per pair: IDTP = 4 of 8.
    r = idf1(frames)
    assert r["idtp"] == 4.0
    assert r["idf1"] == pytest.approx(0.5)


def test_misses_false_positives_and_fragmentation() -> None:
    # Object 1 is tracked by "a", lost for a frame (FN), then picked up by "c" (a switch);
    # "x" is a false positive in frame 0.
    frames = [
        ([1], ["a", "x"], [[0.0, np.inf]]),
        ([1], ["a"], [[0.0]]),
        ([1], [], np.zeros((1, 0))),
        ([1], ["c"], [[0.0]]),
        ([1], ["c"], [[0.0]]),
    ]
    m = clear_mot(frames)
    assert (m["fn"], m["fp"], m["idsw"], m["num_gt"]) == (1.0, 1.0, 1.0, 5.0)
    assert m["mota"] == pytest.approx(1.0 - 3.0 / 5.0)
    r = idf1(frames)
    # Object 1 ↔ "a" (2 frames) or ↔ "c" (2 frames): IDTP = 2; GT 5, hypotheses 5.
    assert r["idtp"] == 2.0
    assert r["idf1"] == pytest.approx(2 * 2 / 10)


def test_previous_match_is_kept_even_if_another_is_closer() -> None:
    # CLEAR MOT keeps a valid correspondence from the previous frame (no switch) although "b" is
    # closer in frame 1.
    frames = [([1], ["a"], [[1.0]]), ([1], ["a", "b"], [[0.9, 0.1]])]
    m = clear_mot(frames, threshold=2.0)
    assert (m["idsw"], m["fp"], m["matches"]) == (0.0, 1.0, 2.0)
    assert m["motp"] == pytest.approx((1.0 + 0.9) / 2)


def test_bad_distance_shape_is_rejected() -> None:
    with pytest.raises(InvalidInputError):
        clear_mot([([1, 2], ["a"], [[0.0, 0.0]])])


def test_identity_changes_counts_neighbours() -> None:
    def e(label: int | None) -> Edge:
        return Edge(np.array([0.0, 0.0, 2.0, 1.0, 0.0]), np.zeros((0, 2)), label=label)

    t1 = Track(id=0, history=[(0, e(3)), (1, e(3)), (1, e(None)), (2, e(4)), (3, e(4)), (4, e(7))])
    t2 = Track(id=1, history=[(0, e(5)), (2, e(5))])
    r = identity_changes([t1, t2], neighbours=lambda a, b: abs(a - b) == 1)
    assert r == {"changes": 2, "neighbour_changes": 1}


def _random_sequence(seed: int) -> list[tuple[list[int], list[int], np.ndarray]]:
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(40):
        gt = sorted(rng.choice(8, size=rng.integers(0, 8), replace=False).tolist())
        hyp = sorted(rng.choice(10, size=rng.integers(0, 10), replace=False).tolist())
        d = rng.uniform(0.0, 1.0, (len(gt), len(hyp)))
        d[rng.random(d.shape) < 0.6] = np.nan
        frames.append((gt, hyp, d))
    return frames


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_against_py_motmetrics(seed: int) -> None:
    mm = pytest.importorskip("motmetrics")
    frames = _random_sequence(seed)
    acc = mm.MOTAccumulator(auto_id=True)
    for gt, hyp, d in frames:
        acc.update(gt, hyp, d)
    mh = mm.metrics.create()
    ref = mh.compute(acc, metrics=["mota", "num_switches", "num_false_positives", "num_misses", "idf1", "motp"])
    ours = clear_mot(frames)
    assert ours["idsw"] == ref["num_switches"].iloc[0]
    assert ours["fp"] == ref["num_false_positives"].iloc[0]
    assert ours["fn"] == ref["num_misses"].iloc[0]
    assert ours["mota"] == pytest.approx(ref["mota"].iloc[0], abs=1e-12)
    assert ours["motp"] == pytest.approx(ref["motp"].iloc[0], abs=1e-12)
    assert idf1(frames)["idf1"] == pytest.approx(ref["idf1"].iloc[0], abs=1e-12)
