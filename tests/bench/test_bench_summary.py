"""The homography benchmark's summary (lburst.bench.homography.summarize), by value: means per
sequence, the mean of the sequences' means, per kind, and the pooled pairs turned <= 25 degrees."""

import pytest

from lburst.bench.homography import summarize


def row(mma: float, rotation: float, keypoints: float = 100.0) -> dict:
    return {
        "mma": [mma / 2, mma],
        "rep3": mma,
        "matching_score": mma / 4,
        "keypoints": keypoints,
        "matches": 10,
        "rotation_deg": rotation,
    }


def test_the_summary_averages_pairs_per_sequence_then_sequences_and_pools_the_small_rotations():
    per_pair = {
        "i_a": [row(0.2, 0.0), row(0.4, 25.0)],  # a sequence's mean: 0.3
        "v_b": [row(0.8, 30.0), row(0.6, 40.0), row(1.0, 10.0)],  # 0.8
        "x_c": [row(0.5, 26.0, keypoints=300.0)],  # another kind: in "all", in no kind
    }
    summary = summarize(per_pair, {"i_a": 1.0, "v_b": 3.0, "x_c": 5.0}, {"i_a": "i", "v_b": "v", "x_c": "other"})
    assert set(summary) == {"sequences", "all", "i", "v", "rotation_le_25"}
    assert summary["sequences"]["i_a"]["rep3"] == pytest.approx(0.3)
    assert summary["sequences"]["v_b"]["mma"] == pytest.approx([0.4, 0.8])
    assert summary["sequences"]["v_b"]["seconds"] == 3.0
    assert summary["all"]["rep3"] == pytest.approx((0.3 + 0.8 + 0.5) / 3)  # the sequences' means, not the 6 pairs'
    assert summary["all"]["keypoints"] == pytest.approx((100 + 100 + 300) / 3)
    assert summary["all"]["seconds"] == pytest.approx(3.0)
    assert summary["i"]["rep3"] == pytest.approx(0.3) and summary["v"]["matching_score"] == pytest.approx(0.2)
    small = summary["rotation_le_25"]  # pairs at 0, 25 and 10 degrees: 25 itself is in
    assert small["pairs"] == 3 and small["rep3"] == pytest.approx((0.2 + 0.4 + 1.0) / 3)
    assert small["mma"] == pytest.approx([(0.1 + 0.2 + 0.5) / 3, (0.2 + 0.4 + 1.0) / 3])


def test_a_summary_without_small_rotations_says_none_were_pooled():
    summary = summarize({"v_b": [row(0.8, 30.0)]}, {"v_b": 1.0}, {"v_b": "v"})
    assert summary["rotation_le_25"] == {"pairs": 0}
    assert summary["all"]["rep3"] == pytest.approx(0.8)
