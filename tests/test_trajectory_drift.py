"""scripts/trajectory_drift.py: keyframe errors split along the path, across it and up."""

from __future__ import annotations

import numpy as np
import pytest

from lburst.tum import write_tum


def _poses(centres: np.ndarray) -> list:
    return [(np.eye(3), -c) for c in centres]  # world-to-camera of cameras at the centres


def test_a_stretched_first_half_shows_along_the_path_only(tmp_path, load_script):
    me = load_script("trajectory_drift")
    ref = np.c_[np.arange(11.0) * 5, np.zeros(11), np.full(11, 50.0)]  # 50 m along x, 50 m up
    est = ref.copy()
    est[:6, 0] = 25 - (25 - ref[:6, 0]) * 1.02  # the first half 2 % too long, ending where it should
    est = est * 3 + [7, -2, 1]  # in the model's own frame: scaled and moved
    run = tmp_path / "run"
    run.mkdir()
    times = np.arange(11) * 0.5
    write_tum(run / "reference.tum", times, _poses(ref))
    write_tum(run / "trajectory.tum", times[::-1], _poses(est)[::-1])  # order is by timestamp, not by row
    found, error = me.keyframe_errors(run)
    np.testing.assert_allclose(found, times)
    np.testing.assert_allclose(error[:, 1:], 0, atol=1e-6)  # nothing across the path or up
    # the alignment's scale splits the 2 %: the first 25 m come out 1 % too long, the rest 1 % too short
    assert error[5, 0] - error[0, 0] == pytest.approx(0.25, rel=0.05)
    assert error[10, 0] - error[5, 0] == pytest.approx(-0.25, rel=0.05)
    np.testing.assert_allclose(np.diff(error[:6, 0], 2), 0, atol=1e-6)  # each half evenly
    np.testing.assert_allclose(np.diff(error[5:, 0], 2), 0, atol=1e-6)
    assert error[:, 0].mean() == pytest.approx(0, abs=1e-6)  # the alignment centres the error
