"""Input that would give a silently wrong result is refused: float bursts outside [0, 1]
(the common 0..255 mistake), NaN or inf, and a truncated JPEG."""

import cv2
import numpy as np
import pytest

from lburst.burst.io import BurstError, load_burst
from lburst.model.extractor import LBurst
from lburst.model.network import LBurstNet, NetConfig


@pytest.fixture(scope="module")
def model():
    return LBurst(LBurstNet(NetConfig(frames=1)))


def _image():
    return np.random.default_rng(0).uniform(0, 1, (32, 48, 3)).astype(np.float32)


def test_float_burst_on_0_255_is_refused_with_a_hint(model):
    with pytest.raises(ValueError, match=r"\[0, 1\].*divide by 255"):
        model.extract(_image() * 255)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_are_refused(model, bad):
    image = _image()
    image[3, 4, 1] = bad
    with pytest.raises(ValueError, match="1 NaN or infinite"):
        model.extract(image)
    with pytest.raises(ValueError, match="NaN or infinite"):
        model.dense(image)


def test_float_burst_in_range_is_accepted(model):
    assert model.extract(_image(), rel_thr=0, rep_thr=0)["descriptors"].shape[1] == 128


def test_a_truncated_jpeg_is_not_read_as_a_grey_frame(tmp_path):
    image = np.random.default_rng(0).integers(0, 255, (64, 64, 3), dtype=np.uint8)
    ok, data = cv2.imencode(".jpg", image)
    data = data.tobytes()
    (tmp_path / "whole.jpg").write_bytes(data)
    assert load_burst(tmp_path / "whole.jpg").shape == (1, 64, 64, 3)
    (tmp_path / "half.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(BurstError, match="half.jpg: not a readable image"):
        load_burst(tmp_path / "half.jpg")
