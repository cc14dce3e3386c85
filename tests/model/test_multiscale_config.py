"""Multi-scale settings are checked once, in ``MultiScaleConfig``: a value that would loop
forever, upsample without bound or divide by zero is a ``ValueError`` naming the field."""

import numpy as np
import pytest

from lburst.methods import create
from lburst.model.extractor import LBurst, MultiScaleConfig
from lburst.model.network import LBurstNet, NetConfig


@pytest.mark.parametrize(
    "options, field",
    [
        ({"scale_factor": 1.0}, "scale_factor"),
        ({"scale_factor": 0.5}, "scale_factor"),
        ({"scale_factor": 0.0}, "scale_factor"),
        ({"scale_factor": float("nan")}, "scale_factor"),
        ({"scale_factor": 1.0001}, "pyramid levels"),
        ({"min_size": 0}, "min_size"),
        ({"min_size": 2.5}, "min_size"),
        ({"max_size": 100, "min_size": 200}, "max_size"),
        ({"rel_thr": 1.5}, "rel_thr"),
        ({"rep_thr": -0.1}, "rep_thr"),
        ({"top_k": -1}, "top_k"),
        ({"top_k": 3.5}, "top_k"),
        ({"top_k": True}, "top_k"),
        ({"max_scale": 0.0}, "scales"),
        ({"max_scale": 4.5}, "max_scale <= 4.0"),  # levels above the input are upsampled, within reason
        ({"subpixel": 1}, "subpixel"),
        ({"fast": "no"}, "fast"),
        ({"precision": "fp8"}, "precision"),
    ],
)
def test_bad_settings_are_refused_by_name(options, field):
    with pytest.raises(ValueError, match=field):
        MultiScaleConfig(**options)


@pytest.mark.parametrize(
    "spec",
    [
        "lburst,scale_factor=1",
        "lburst,scale_factor=0.5",
        "lburst,scale_factor=0",
        "lburst,min_size=0",
        "lburst,rel_thr=2",
    ],
)
def test_bad_settings_in_a_method_spec_fail_at_creation(spec):
    with pytest.raises(ValueError, match="scale_factor|min_size|rel_thr"):
        create(spec, device="cpu")
    with pytest.raises(ValueError, match="top_k"):
        create("r2d2", top_k="-1", device="cpu")


def test_a_tiny_image_is_too_small_and_small_min_size_stops_at_a_usable_level():
    model = LBurst(LBurstNet(NetConfig(frames=1)))
    with pytest.raises(ValueError, match="1x1 image is too small"):
        model.extract(np.zeros((1, 1, 3), np.uint8))
    with pytest.raises(ValueError, match="300x1 image is too small"):
        model.extract(np.zeros((1, 300, 3), np.uint8))
    image = np.random.default_rng(0).integers(0, 255, (40, 64, 3), dtype=np.uint8)
    assert model.extract(image, min_size=1, rel_thr=0, rep_thr=0)["keypoints"].shape[1] == 2
