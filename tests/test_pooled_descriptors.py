"""scripts/pooled_descriptors.py: the same keypoints, descriptors from a map pooled to quarter
resolution."""

from __future__ import annotations

import numpy as np
import torch

from lburst.model.extractor import LBurst
from lburst.model.network import LBurstNet, NetConfig


def test_keypoints_stay_and_descriptors_come_from_a_quarter_resolution_map(load_script, monkeypatch):
    script = load_script("pooled_descriptors")
    torch.manual_seed(0)
    model = LBurst(LBurstNet(NetConfig(frames=1)).eval())
    level = torch.rand(1, 3, 64, 96)
    with torch.no_grad():
        _, _, half = model._fast_level(level, "fp32")
        _, _, quarter = script._pooled_level(model, level, "fp32")
    assert half.shape[-2:] == (32, 48) and quarter.shape[-2:] == (16, 24)
    assert torch.allclose(quarter[..., 3, 5], half[..., 6:8, 10:12].mean((-2, -1)), atol=1e-6)

    image = np.random.default_rng(0).integers(0, 256, (64, 96, 3), dtype=np.uint8)
    options = dict(rel_thr=0, rep_thr=0, top_k=None, min_size=64, max_size=96)
    plain = model.extract(image, **options)
    monkeypatch.setattr(LBurst, "_fast_level", script._pooled_level)
    pooled = model.extract(image, **options)
    assert np.array_equal(plain["keypoints"], pooled["keypoints"])
    assert np.array_equal(plain["scores"], pooled["scores"])
    assert not np.allclose(plain["descriptors"], pooled["descriptors"], atol=1e-3)
