"""The reflected border around each pyramid level (``MultiScaleConfig.pad``): off unless the
weights (``meta['pad']``) or the call ask for it, carried by ONNX exports, and the keypoints it
adds near the image border are real ones, found again where the same scene lies inside
another view."""

import numpy as np
import pytest

from lburst import simulate_burst
from lburst.model.extractor import LBurst, MultiScaleConfig
from lburst.model.network import CheckpointError, LBurstNet, NetConfig, default_pad, save_checkpoint
from lburst.scenes.textures import load_photo
from lburst.weights import weights_path

PAD = 32
SHIFT = 24  # px between the two views of the scene
BORDER = 12  # px: "near the border"


def test_the_weights_say_their_pad(tmp_path):
    for name in ("lburst-b5", "lburst-b5-lite", "lburst-b1"):
        assert LBurst.pretrained(name, device="cpu").pad == 0  # shipped weights run without it
    net = LBurstNet(NetConfig(frames=1))
    save_checkpoint(net, tmp_path / "own.pt", meta={"input": "burst", "pad": 8})
    assert LBurst.from_checkpoint(tmp_path / "own.pt", device="cpu").pad == 8
    assert default_pad(None) == 0 and default_pad({"input": "aligned"}) == 0
    save_checkpoint(net, tmp_path / "bad.pt", meta={"pad": -3})
    with pytest.raises(CheckpointError, match=r"bad\.pt: the weights' pad must be an integer"):
        LBurst.from_checkpoint(tmp_path / "bad.pt", device="cpu")


def test_an_onnx_export_keeps_the_pad(tmp_path):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    from lburst.model.onnx import export_onnx

    save_checkpoint(LBurstNet(NetConfig(frames=1)), tmp_path / "w.pt", meta={"input": "burst", "pad": 8})
    assert LBurst.from_onnx(export_onnx(tmp_path / "w.pt", tmp_path / "w.onnx")).pad == 8


@pytest.mark.parametrize("pad", [-1, 257, 2.5, True, "8"])
def test_a_bad_pad_is_refused_by_name(pad):
    with pytest.raises(ValueError, match="pad"):
        MultiScaleConfig(pad=pad)
    with pytest.raises(ValueError, match="pad"):
        default_pad({"pad": pad})


def test_an_image_smaller_than_the_pad_is_reflected_as_far_as_it_goes():
    model = LBurst(LBurstNet(NetConfig(frames=1)), pad=PAD)
    image = np.random.default_rng(0).integers(0, 256, (20, 24, 3), dtype=np.uint8)
    maps = model.dense(image)
    assert maps["reliability"].shape == (20, 24) and maps["descriptors"].shape == (20, 24, 128)
    feats = model.extract(image, min_size=20, max_size=24)
    x, y = feats["keypoints"].T
    assert ((x >= 0) & (x <= 23) & (y >= 0) & (y <= 19)).all()


@pytest.fixture(scope="module")
def views():
    """One 5-frame burst of a photo, and the same burst cut ``SHIFT`` px further right."""
    photo = np.ascontiguousarray(load_photo("astronaut")[40:360, 40 : 400 + SHIFT])
    burst = simulate_burst(photo, 5, motion=(0.0, 0.0), rng=0)
    return burst[:, :, :-SHIFT], burst[:, :, SHIFT:]


def _near_left(feats):
    x, y = feats["keypoints"].T
    return feats["keypoints"][x < BORDER]


def _found_again(points, other, shift):
    """Share of ``points`` (x, y) with a keypoint of ``other`` within 1.5 px of (x - shift, y)."""
    if not len(points):
        return 0.0
    d = np.linalg.norm((points - [shift, 0])[:, None] - other["keypoints"][None], axis=-1)
    return float((d.min(axis=1) <= 1.5).mean())


def test_keypoints_at_the_border_are_found_again_inside_another_view(views):
    """Without the pad the shipped weights leave the outer pixels nearly empty; with it they find
    keypoints there, and most of them again where the same scene lies inside the second view."""
    model = LBurst.from_checkpoint(weights_path("lburst-b5"), device="cpu")
    right, left = views  # `left` starts SHIFT px right of `right`: its left border lies inside `right`
    with_pad = model.extract(left, top_k=None, min_size=256, max_size=384, pad=PAD)
    without = model.extract(left, top_k=None, min_size=256, max_size=384)
    inside = model.extract(right, top_k=None, min_size=256, max_size=384, pad=PAD)
    border_pad, border_none = _near_left(with_pad), _near_left(without)
    assert len(border_pad) >= 1.5 * len(border_none)  # 25 against 11 when written
    assert _found_again(border_pad, inside, -SHIFT) >= 0.6  # 0.76 (without the pad: 0.55 of 11)
