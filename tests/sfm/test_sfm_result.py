"""result.json's one status and one error, and the options' enums (issue 28)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lburst.errors import LBurstValueError
from lburst.sfm.options import Camera, Mapper, Pairs, ReconstructOptions
from lburst.sfm.result import ReconstructionResult, Status, ended


def test_status_and_error_round_trip(tmp_path):
    poses = {"a": (np.eye(3), np.zeros(3))}
    result = ReconstructionResult(
        "s", "sift", str(tmp_path), ["a", "b"], ["a"], poses, status=Status.PARTIAL, error="cut"
    )
    path = result.save()
    data = json.loads(path.read_text())
    assert data["status"] == "partial" and data["error"] == "cut" and "source_error" not in data
    back = ReconstructionResult.load(path)
    assert back.status is Status.PARTIAL and back.error == "cut" and np.allclose(back.poses["a"][0], np.eye(3))


@pytest.mark.parametrize(
    "error, source_error, converged, status",
    [
        (None, None, 1.0, Status.COMPLETE),
        (None, "cut", 1.0, Status.PARTIAL),
        (None, None, 0.0, Status.NO_MODEL),
        ("boom", None, 0.0, Status.COLMAP_FAILED),
        ("2 keyframe(s) read before the recording stopped; no model", "cut", 0.0, Status.SOURCE_FAILED),
    ],
)
def test_a_result_json_from_before_status_loads(tmp_path, error, source_error, converged, status):
    data = {"scene": "s", "method": "sift", "out_dir": str(tmp_path), "names": ["a"], "registered": [], "poses": {}}
    data.update(cameras={}, metrics={"converged": converged}, error=error, source_error=source_error)
    (tmp_path / "result.json").write_text(json.dumps(data))
    result = ReconstructionResult.load(tmp_path / "result.json")
    assert result.status is status
    assert result.failed == (status in (Status.COLMAP_FAILED, Status.SOURCE_FAILED))
    if error or source_error:
        assert all(part in result.error for part in (error, source_error) if part)


def test_ended_keeps_both_messages():
    status, error = ended("colmap broke", "recording cut", False)
    assert status is Status.COLMAP_FAILED and "colmap broke" in error and "recording cut" in error


def test_options_take_enum_values_and_refuse_others():
    opts = ReconstructOptions(pairs="sequential", camera="reference", mapper="global")
    assert (opts.pairs, opts.camera, opts.mapper) == (Pairs.SEQUENTIAL, Camera.REFERENCE, Mapper.GLOBAL)
    assert opts.pairs == "sequential" and f"{opts.camera}" == "reference"
    for field, value in (("pairs", "all"), ("camera", "exif"), ("mapper", "glomap")):
        with pytest.raises(LBurstValueError, match=value):
            ReconstructOptions(**{field: value})
