"""A burst larger than the pyramid's largest level is resized frame by frame before it is
normalised (to bound memory): the features equal those of the whole burst normalised at
full resolution and resized level by level."""

import numpy as np
import pytest
import torch

from lburst import LBurst
from lburst.model.extractor import MultiScaleConfig
from lburst.model.lite import LiteConfig, LiteNet
from lburst.model.network import normalize_burst


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("size", [(100, 150), (97, 211)])
def test_frames_resized_first_give_the_features_of_the_full_resolution_input(dtype, size):
    torch.manual_seed(0)
    model = LBurst(LiteNet(LiteConfig(frames=3, dim=16, fine=8, coarse=16, dilations=(1, 2))), "cpu")
    top = np.iinfo(dtype).max
    burst = np.random.default_rng(0).integers(0, top, (3, *size, 3), dtype=np.int64).astype(dtype)
    options = {"max_size": 64, "min_size": 24, "rel_thr": 0.0, "rep_thr": 0.0}
    got = model.extract(burst, top_k=300, **options)
    x, scale = model._input(burst, MultiScaleConfig(top_k=300, **options))
    assert scale < 1 and max(x.shape[-2:]) <= 64
    with torch.inference_mode():
        full = normalize_burst(burst, "cpu")
        expected = model._extract(full, MultiScaleConfig(top_k=300, **options))
    assert len(got["keypoints"]) == len(expected["keypoints"]) > 100
    np.testing.assert_allclose(got["keypoints"], expected["keypoints"], atol=1e-4)
    np.testing.assert_allclose(got["descriptors"], expected["descriptors"], atol=1e-4)
    np.testing.assert_array_equal(got["scales"], expected["scales"])
