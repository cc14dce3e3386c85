"""Every extractor's features carry ``image_size`` (width, height), as LightGlue's; selecting and
concatenating keypoints keep it whole, and the stores write it once (as ``imsize``)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import torch

from lburst import store
from lburst.burst.io import read_features_npz, write_features_h5, write_features_npz
from lburst.features import check_features, concatenate, select, spread_top_k
from lburst.methods import create
from lburst.methods.learned import LearnedExtractor
from lburst.model.extractor import LBurst
from lburst.model.network import LBurstNet, NetConfig

WIDTH, HEIGHT = 96, 72


@pytest.fixture(scope="module")
def burst() -> np.ndarray:
    """Five frames of a blurred random texture (corners and blobs for every detector)."""
    import cv2

    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8), (0, 0), 1.5)
    return np.stack([np.roll(image, k, axis=1) for k in range(-2, 3)])


@pytest.mark.parametrize("spec", ["sift", "orb", "merge+sift", "buff,slope_step=1"])
def test_every_method_gives_the_image_size(spec, burst):
    feats = check_features(create(spec)(burst))
    assert feats["image_size"].dtype == np.int64 and feats["image_size"].tolist() == [WIDTH, HEIGHT]


@pytest.mark.parametrize("options", [{}, {"spread": 2}, {"spread": 2, "rotations": 2}])
def test_the_learned_extractor_gives_the_image_size(options, burst):
    torch.manual_seed(0)
    extractor = LearnedExtractor(LBurst(LBurstNet(NetConfig(frames=5))), top_k=50, rel_thr=0, rep_thr=0, **options)
    feats = check_features(extractor(burst))
    assert feats["image_size"].tolist() == [WIDTH, HEIGHT] and 0 < len(feats["keypoints"]) <= 50 * (
        options.get("rotations", 1)
    )


def features(k: int = 6) -> dict:
    rng = np.random.default_rng(1)
    return {
        "keypoints": rng.uniform(0, 50, (k, 2)).astype(np.float32),
        "scales": np.full(k, 32.0, np.float32),
        "scores": np.linspace(1, 0.1, k).astype(np.float32),
        "descriptors": rng.normal(size=(k, 8)).astype(np.float32),
        "image_size": np.array([WIDTH, HEIGHT], np.int64),
    }


def test_selecting_and_concatenating_keypoints_keep_the_image_size():
    feats = features()
    part = select(feats, np.array([0, 2]))
    assert len(part["keypoints"]) == 2 and part["image_size"].tolist() == [WIDTH, HEIGHT]
    both = concatenate([part, select(feats, feats["scores"] < 0.5)])
    assert len(both["scores"]) == 2 + int((feats["scores"] < 0.5).sum()) and both["image_size"].tolist() == [
        WIDTH,
        HEIGHT,
    ]
    assert spread_top_k(feats, 3, (WIDTH, HEIGHT), 2)["image_size"].tolist() == [WIDTH, HEIGHT]
    with pytest.raises(ValueError, match=r"image_size must be \(2,\) integers"):
        check_features({**feats, "image_size": np.array([1.5, 2.0])})


def test_the_stores_write_the_image_size_once_and_read_it_back(tmp_path):
    feats = features()
    store.save(tmp_path / "a.npz", feats, None, key="k")  # the size from the features
    with np.load(tmp_path / "a.npz") as raw:
        assert raw["imsize"].tolist() == [WIDTH, HEIGHT] and "image_size" not in raw.files  # not stored twice
    loaded, size, _ = store.load(tmp_path / "a.npz", "k")
    assert size == (WIDTH, HEIGHT) and loaded["image_size"].tolist() == [WIDTH, HEIGHT]
    assert read_features_npz(tmp_path / "a.npz")["image_size"].dtype == np.int64
    with pytest.raises(ValueError, match=r"image size \(10, 10\) differs from the features' image_size \(96, 72\)"):
        write_features_npz(tmp_path / "b.npz", feats, (10, 10))
    no_size = {k: v for k, v in feats.items() if k != "image_size"}
    with pytest.raises(ValueError, match="the image size"):
        write_features_npz(tmp_path / "c.npz", no_size)
    write_features_h5(tmp_path / "f.h5", "img", feats)
    with h5py.File(tmp_path / "f.h5") as f:
        assert f["img/image_size"][()].tolist() == [WIDTH, HEIGHT] and sorted(f["img"]) == [
            "descriptors",
            "image_size",
            "keypoints",
            "scores",
        ]
