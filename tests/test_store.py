"""The features store keys on content and weights: changed frames or retrained weights are
never served old features (``lburst reconstruct`` and ``lburst extract`` share it)."""

import cv2
import numpy as np

from lburst import store
from lburst.io import read_image
from lburst.methods import create
from lburst.model.network import LBurstNet, NetConfig, save_checkpoint
from lburst.sfm import reconstruct_scene


def _photo(seed, size=(120, 160)):
    image = np.random.default_rng(seed).integers(0, 256, size=(*size, 3), dtype=np.uint8)
    return cv2.GaussianBlur(image, (0, 0), 1.0)


def test_the_key_follows_the_weights_file_and_the_frames(tmp_path):
    ckpt = tmp_path / "w.pt"
    save_checkpoint(LBurstNet(NetConfig(frames=1)), ckpt)
    before = store.method_key(f"r2d2:{ckpt}", top_k=100)
    assert store.method_key(f"r2d2:{ckpt}", top_k=100) == before
    save_checkpoint(LBurstNet(NetConfig(frames=1)), ckpt)  # retrained in place
    assert store.method_key(f"r2d2:{ckpt}", top_k=100) != before
    assert store.method_key(f"r2d2:{ckpt}", top_k=200) != store.method_key(f"r2d2:{ckpt}", top_k=100)
    image = tmp_path / "a.png"
    cv2.imwrite(str(image), _photo(0))
    key = store.burst_key(before, image)
    cv2.imwrite(str(image), _photo(1))
    assert store.burst_key(before, image) != key


def test_reconstruct_computes_a_changed_burst_again(tmp_path):
    scene, out = tmp_path / "scene", tmp_path / "out"
    scene.mkdir()
    for i in range(3):
        cv2.imwrite(str(scene / f"{i}.png"), _photo(i))
    reconstruct_scene(scene, "sift", out, progress=False)
    cv2.imwrite(str(scene / "1.png"), np.zeros((120, 160, 3), np.uint8))  # the burst replaced by a black frame
    reconstruct_scene(scene, "sift", out, progress=False)
    stored = np.load(out / "features" / "1.npz")
    assert len(stored["keypoints"]) == len(create("sift")(np.zeros((1, 120, 160, 3), np.uint8))["keypoints"]) == 0
    assert read_image(out / "images" / "1.png").max() == 0
    assert len(np.load(out / "features" / "0.npz")["keypoints"]) > 0
