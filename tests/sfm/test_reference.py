from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lburst.sfm.reference import Reference


def make_reference() -> Reference:
    R = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    return Reference(
        source="synthetic",
        camera={"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]},
        poses={"0000": (np.eye(3), np.array([1.0, 2.0, 3.0])), "0001": (R, np.array([0.5, -1.0, 4.0]))},
        length=2.5,
    )


def test_round_trip(tmp_path):
    ref = make_reference()
    ref.save(tmp_path / "reference.json")
    back = Reference.load(tmp_path / "reference.json")
    assert back.source == "synthetic" and back.length == 2.5 and back.camera == ref.camera
    assert list(back.poses) == ["0000", "0001"]
    for name in ref.poses:
        np.testing.assert_array_equal(back.poses[name][0], ref.poses[name][0])
        np.testing.assert_array_equal(back.poses[name][1], ref.poses[name][1])
    assert not list(tmp_path.glob(".*tmp*")), "atomic save left a temporary file"


def test_centres_and_projection():
    ref = make_reference()
    np.testing.assert_allclose(ref.centers()["0000"], [-1.0, -2.0, -3.0])
    R, t = ref.poses["0001"]
    centre = ref.centers()["0001"]
    np.testing.assert_allclose(R @ centre + t, 0, atol=1e-12)
    # camera (0000) at (-1, -2, -3) looking along +z: world (0, -2, 0) is 1 right of the axis at depth 3
    np.testing.assert_allclose(ref.project("0000", np.array([[0.0, -2.0, 0.0]])), [[32 + 50 / 3, 24.0]])


def test_length_may_be_null(tmp_path):
    ref = make_reference()
    ref.length = None
    ref.save(tmp_path / "r.json")
    assert Reference.load(tmp_path / "r.json").length is None


@pytest.mark.parametrize(
    "text, problem",
    [
        ("{not json", "not valid JSON"),
        (json.dumps({"source": "x", "images": {}}), "camera"),
        (
            json.dumps({"source": "x", "camera": {"model": "PINHOLE", "width": 4, "height": 4}, "images": {}}),
            "camera.params",
        ),
        (
            json.dumps(
                {
                    "source": "x",
                    "camera": {"model": "PINHOLE", "width": 4, "height": 4, "params": [1, 1, 2, 2]},
                    "images": {"a": {"R": [[1, 0], [0, 1]], "t": [0, 0, 0]}},
                }
            ),
            "R must be 3x3",
        ),
        (json.dumps([1, 2]), "JSON object"),
    ],
)
def test_malformed_file_names_file_and_problem(tmp_path, text, problem):
    path = tmp_path / "reference.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=problem) as err:
        Reference.load(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    "edit, problem",
    [
        (lambda d: d["images"]["0000"].update(t=[float("nan"), 0, 0]), "must be finite"),
        (lambda d: d["images"]["0001"].update(R=[[float("inf"), 0, 0], [0, 1, 0], [0, 0, 1]]), "must be finite"),
        (lambda d: d["images"]["0000"].update(R=[[2, 0, 0], [0, 1, 0], [0, 0, 1]]), "not a rotation"),
        (lambda d: d["images"]["0000"].update(R=[[-1, 0, 0], [0, 1, 0], [0, 0, 1]]), "not a rotation"),
        (lambda d: d["camera"].update(params=[float("nan"), 50, 32, 24]), "camera.params must be finite"),
        (lambda d: d["camera"].update(params=[0, 50, 32, 24]), "positive focal"),
        (lambda d: d["camera"].update(width=0), "camera.width must be a positive integer"),
        (lambda d: d["camera"].update(height=4.5), "camera.height must be a positive integer"),
        (lambda d: d.update(length=float("inf")), "length must be a positive number"),
        (lambda d: d.update(length=-1), "length must be a positive number"),
    ],
)
def test_unusable_ground_truth_is_refused_by_file(tmp_path, edit, problem):
    path = tmp_path / "reference.json"
    make_reference().save(path)
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))  # json writes NaN and Infinity, and Python reads them back
    with pytest.raises(ValueError, match=problem) as err:
        Reference.load(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
