"""scripts/light_detector.py: the light network's keypoints, lburst-b5's descriptors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lburst.model.extractor import LBurst


@pytest.fixture(scope="module")
def b5() -> LBurst:
    return LBurst.pretrained("lburst-b5", device="cpu", runtime="torch")


def test_keypoints_are_the_light_networks_and_descriptors_lburst_b5s(load_script, monkeypatch, b5):
    script = load_script("light_detector")
    burst = np.random.default_rng(0).integers(0, 256, (5, 64, 96, 3), dtype=np.uint8)
    options = dict(rel_thr=0, rep_thr=0, top_k=200, min_size=64, max_size=96)
    light = script.light_detector().extract(burst, **options)
    own = b5.extract(burst, **options)
    monkeypatch.setattr(LBurst, "_fast_level", script._light_detector_level)
    mixed = b5.extract(burst, **options)
    assert len(mixed["keypoints"]) == len(light["keypoints"]) > 0
    np.testing.assert_allclose(mixed["keypoints"], light["keypoints"], atol=1e-5)
    np.testing.assert_allclose(mixed["scores"], light["scores"], atol=1e-5)
    assert not np.allclose(mixed["descriptors"], light["descriptors"], atol=1e-2)
    near = np.abs(own["keypoints"][:, None] - mixed["keypoints"][None]).sum(-1) < 1e-4  # points both found
    i, j = np.nonzero(near)
    assert len(i) > 0
    np.testing.assert_allclose(mixed["descriptors"][j], own["descriptors"][i], atol=1e-4)


def test_with_the_repeatability_only_the_reliability_stays_lburst_b5s(load_script, b5):
    script = load_script("light_detector")
    level = torch.rand(1, 15, 64, 96, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        light_rep, light_rel, _ = script.light_detector()._fast_level(level, "fp32")
        own_rep, own_rel, own_desc = b5._fast_level(level, "fp32")
        rep, rel, desc = script._light_repeatability_level(b5, level, "fp32")
    assert torch.equal(rep, light_rep) and not torch.allclose(rep, own_rep, atol=1e-3)
    assert torch.equal(rel, own_rel) and not torch.allclose(rel, light_rel, atol=1e-3)
    assert torch.equal(desc, own_desc)
