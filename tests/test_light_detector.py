"""scripts/light_detector.py: the light network's keypoints, lburst-b5's descriptors."""

from __future__ import annotations

import numpy as np

from lburst.model.extractor import LBurst


def test_keypoints_are_the_light_networks_and_descriptors_lburst_b5s(load_script, monkeypatch):
    script = load_script("light_detector")
    b5 = LBurst.pretrained("lburst-b5", device="cpu", runtime="torch")
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
