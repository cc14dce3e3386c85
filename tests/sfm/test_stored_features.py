"""Features that another run stored (``lburst reconstruct --features DIR``) are checked before
they are used: a file that holds this burst's key but features that cannot be right is an
error naming it; a folder that is missing or a file is refused; a ``lburst reconstruct`` output
folder is used; a folder whose features do not fit says why."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest
import skimage.data

import lburst.methods
from lburst.burst.io import save_burst
from lburst.cli import main
from lburst.sfm.inputs import open_input
from lburst.sfm.options import ReconstructOptions

SIFT = "sift,max_features=300"


@pytest.fixture
def extracted(tmp_path):
    """A scene of three 3-frame bursts and their SIFT features, as ``lburst extract`` stores them."""
    for i in range(3):
        crop = skimage.data.astronaut()[20 * i : 20 * i + 300, 60 + 20 * i : 460 + 20 * i]
        save_burst(np.stack([cv2.resize(crop, (200, 150), interpolation=cv2.INTER_AREA)] * 3), tmp_path / f"scene/b{i}")
    bursts = [str(tmp_path / f"scene/b{i}") for i in range(3)]
    assert main(["extract", *bursts, "--out", str(tmp_path / "ext"), "--method", SIFT]) == 0
    return tmp_path / "scene", tmp_path / "ext"


def _tamper(path, **change):
    data = dict(np.load(path))
    for key, edit in change.items():
        data[key] = edit(data[key].copy())
    np.savez(path, **data)  # the same _meta: the key of this burst and method


def _off_image(kp):
    kp[0, 0] = 1e6
    return kp


def _nan(desc):
    desc[3, 5] = np.nan
    return desc


@pytest.mark.parametrize(
    "change, why",
    [
        ({"keypoints": _off_image}, "keypoints lie outside the 200x150 image"),
        ({"descriptors": _nan}, "finite"),
        ({"keypoints": lambda kp: kp[:, 0]}, "b0.npz: stored features"),
        ({"imsize": lambda size: size * 2}, "the burst's common frame is 200x150"),
    ],
)
def test_stored_features_that_cannot_be_right_are_one_line_naming_the_file(extracted, tmp_path, capsys, change, why):
    scene, ext = extracted
    _tamper(ext / "b0.npz", **change)
    argv = ["reconstruct", str(scene), "--method", SIFT, "--features", str(ext), "--out", str(tmp_path / "r")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"lburst reconstruct: error: {ext / 'b0.npz'}: ") and why in err and err.count("\n") == 1


@pytest.mark.parametrize("given", ["missing", "ext/b0.npz"])
def test_features_of_a_missing_folder_or_of_a_file_is_refused(extracted, tmp_path, capsys, given):
    scene, _ = extracted
    argv = [
        "reconstruct",
        str(scene),
        "--method",
        SIFT,
        "--features",
        str(tmp_path / given),
        "--out",
        str(tmp_path / "r"),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"lburst reconstruct: error: --features {tmp_path / given}: ") and err.count("\n") == 1
    assert not (tmp_path / "r" / "features").exists()  # nothing computed


def _no_extraction(monkeypatch):
    def refuse(spec, **options):
        raise AssertionError(f"{spec} computed, not taken from the folder")

    monkeypatch.setattr(lburst.methods, "create", refuse)


def test_the_output_folder_of_reconstruct_is_used_as_features(extracted, tmp_path, monkeypatch):
    scene, ext = extracted
    earlier = tmp_path / "earlier"  # what `lburst reconstruct --out earlier` keeps: earlier/features/<name>.npz
    (earlier / "features").mkdir(parents=True)
    for path in ext.glob("*.npz"):
        shutil.copy(path, earlier / "features" / path.name)
    _no_extraction(monkeypatch)
    keyframes = open_input(scene).read(SIFT, tmp_path / "r", ReconstructOptions(features=earlier, progress=False))
    assert [len(f["keypoints"]) for f in keyframes.features] == [
        len(np.load(ext / f"b{i}.npz")["keypoints"]) for i in range(3)
    ]


def test_a_features_folder_that_does_not_fit_says_why(extracted, tmp_path):
    scene, ext = extracted
    with pytest.warns(UserWarning, match=rf"--features {ext}: 3 of 3 bursts .* features of '{SIFT}', not of 'orb'"):
        open_input(scene).read("orb", tmp_path / "r", ReconstructOptions(features=ext, progress=False))
