"""One list of image file suffixes (:data:`lburst.burst.io.IMAGE_SUFFIXES`): a ``.webp`` frame is a
frame in a burst, in a scene and in a recording's frame folder alike."""

from __future__ import annotations

import numpy as np

from lburst import calibration
from lburst.burst import io
from lburst.burst.sources import RecordingOptions, is_recording
from lburst.sfm import scene as scene_module
from lburst.train import data


def _frame(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 255, (24, 32, 3), dtype=np.uint8)


def test_every_listing_uses_the_one_list():
    assert ".webp" in io.IMAGE_SUFFIXES
    for module in (scene_module, calibration, data):
        assert module.IMAGE_SUFFIXES is io.IMAGE_SUFFIXES, module.__name__


def test_a_webp_frame_is_a_frame_in_a_burst_a_scene_and_a_frame_folder(tmp_path):
    burst = tmp_path / "scene" / "b1"
    burst.mkdir(parents=True)
    for i in range(3):
        io.write_image(burst / f"frame_{i:03d}.webp", _frame(i))
    io.write_image(tmp_path / "scene" / "single.webp", _frame(9))
    assert io.load_burst(burst).shape == (3, 24, 32, 3)
    listed = scene_module.list_scene(tmp_path / "scene")
    assert listed.names == ["b1", "single"] and [i.kind for i in listed.items] == ["burst", "image"]
    assert is_recording(burst, RecordingOptions(frame_folders=True))
    assert not is_recording(burst)
