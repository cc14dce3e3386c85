"""Pyramid levels above the input (``max_scale`` > 1): the levels from the input down are
unchanged, the added ones lie at the powers of ``scale_factor``, and they let a view seen from
further away meet a nearer view's finest keypoints."""

import cv2
import numpy as np
import pytest

from lburst import simulate_burst
from lburst.methods import create
from lburst.model.extractor import LBurst, MultiScaleConfig, upper_scales
from lburst.scenes.textures import load_photo

SF = 2**0.25


@pytest.fixture(scope="module")
def model():
    return LBurst.pretrained("lburst-b5", device="cpu")


@pytest.fixture(scope="module")
def near():
    return np.ascontiguousarray(load_photo("astronaut")[40:328, 40:424])  # 384x288


def test_upper_scales_are_powers_of_the_scale_factor_within_max_size():
    assert upper_scales(MultiScaleConfig(), 640) == []
    assert upper_scales(MultiScaleConfig(max_scale=1.7), 500) == pytest.approx([SF**3, SF**2, SF])
    assert upper_scales(MultiScaleConfig(max_scale=1.5), 500) == pytest.approx([SF**2, SF])
    # max_size caps them: 1024 / 640 = 1.6
    assert upper_scales(MultiScaleConfig(max_scale=1.7), 640) == pytest.approx([SF**2, SF])
    assert upper_scales(MultiScaleConfig(max_scale=2.0), 2000) == []  # max_size shrinks this one anyway


def test_the_levels_from_the_input_down_are_unchanged(model, near):
    burst = simulate_burst(near, 5, motion=(0.5, 0.25), rng=0)
    plain = model.extract(burst, top_k=None)
    up = model.extract(burst, top_k=None, max_scale=1.5)
    levels = sorted(set(np.round(plain["scales"], 2)) | {round(32 / SF**2, 2), round(32 / SF, 2)})
    assert sorted(set(np.round(up["scales"], 2))) == pytest.approx(levels)
    below = up["scales"] >= 32 - 1e-3
    order_up = np.lexsort(up["keypoints"][below].T)
    order_plain = np.lexsort(plain["keypoints"].T)
    np.testing.assert_array_equal(up["keypoints"][below][order_up], plain["keypoints"][order_plain])
    np.testing.assert_array_equal(up["descriptors"][below][order_up], plain["descriptors"][order_plain])
    assert (~below).sum() > 0.5 * len(plain["keypoints"])  # the upsampled levels add keypoints
    x, y = up["keypoints"].T
    assert x.min() >= -0.5 and y.min() >= -0.5 and x.max() <= 383.5 and y.max() <= 287.5


def _found_again(fine, far, zoom):
    """Share of the near view's keypoints ``fine`` with a keypoint of the far view within 2 px
    (in the near view's pixels) of where it lies there."""
    mapped = (far["keypoints"] + 0.5) * zoom - 0.5
    d = np.linalg.norm(fine[:, None] - mapped[None], axis=-1)
    return float((d.min(axis=1) <= 2.0).mean())


def test_a_farther_view_meets_the_nearer_views_finest_keypoints(model, near):
    zoom = SF**2  # the far view sees the scene 1.41x smaller
    far = cv2.resize(near, (round(384 / zoom), round(288 / zoom)), interpolation=cv2.INTER_AREA)
    near_feats = model.extract(simulate_burst(near, 5, motion=(0.0, 0.0), rng=0), top_k=None)
    fine = near_feats["keypoints"][near_feats["scales"] == 32]
    far_burst = simulate_burst(far, 5, motion=(0.0, 0.0), rng=0)
    plain = _found_again(fine, model.extract(far_burst, top_k=None), zoom)
    up = _found_again(fine, model.extract(far_burst, top_k=None, max_scale=zoom + 0.01), zoom)
    assert len(fine) > 100
    assert up > 0.7 and up > 2 * plain, (plain, up)  # 0.91 against 0.21 when written


def test_a_method_spec_takes_max_scale():
    method = create("lburst,max_scale=1.5", device="cpu")
    assert method.options["max_scale"] == 1.5
    with pytest.raises(ValueError, match="max_scale"):
        create("lburst,max_scale=5", device="cpu")
