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
        expected = model._detector().detect(full, MultiScaleConfig(top_k=300, **options))
    assert len(got["keypoints"]) == len(expected["keypoints"]) > 100
    np.testing.assert_allclose(got["scores"], expected["scores"], atol=1e-5)

    def by_place(features: dict) -> np.ndarray:  # keypoints of (nearly) equal score may come in either order
        return np.lexsort(
            (features["scales"], features["keypoints"][:, 1].round(3), features["keypoints"][:, 0].round(3))
        )

    a, b = by_place(got), by_place(expected)
    np.testing.assert_allclose(got["keypoints"][a], expected["keypoints"][b], atol=1e-4)
    np.testing.assert_allclose(got["descriptors"][a], expected["descriptors"][b], atol=1e-4)
    np.testing.assert_array_equal(got["scales"][a], expected["scales"][b])


def test_dense_refuses_a_burst_whose_maps_pass_half_the_memory(monkeypatch):
    from lburst.model import extractor

    torch.manual_seed(0)
    model = LBurst(LiteNet(LiteConfig(frames=3, dim=16, fine=8, coarse=16, dilations=(1,))), "cpu")
    burst = np.zeros((3, 300, 400, 3), np.uint8)
    assert extractor.dense_bytes(3000, 4000) > 17 * 2**30  # a 4000x3000 burst at D = 128
    monkeypatch.setattr(extractor, "memory_limit_bytes", lambda: extractor.dense_bytes(300, 400, 16) - 1)
    with pytest.raises(ValueError, match=r"dense maps of a 400x300 burst need about .* GiB.*use extract\(\)"):
        model.dense(burst)
    monkeypatch.setattr(extractor, "memory_limit_bytes", lambda: extractor.dense_bytes(300, 400, 16))
    assert model.dense(burst)["descriptors"].shape == (300, 400, 16)
