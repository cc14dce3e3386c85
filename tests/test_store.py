"""The features store keys on content and weights: changed frames or retrained weights are
never served old features (``lburst reconstruct`` and ``lburst extract`` share it)."""

import json

import cv2
import numpy as np
import pytest

from lburst import store
from lburst.burst.io import read_image, save_burst
from lburst.methods import create
from lburst.model.network import LBurstNet, NetConfig, save_checkpoint
from lburst.sfm import reconstruct_scene
from lburst.sfm.options import ReconstructOptions


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
    key = store.key(before, image)
    cv2.imwrite(str(image), _photo(1))
    assert store.key(before, image) != key


def test_reconstruct_computes_a_changed_burst_again(tmp_path):
    scene, out = tmp_path / "scene", tmp_path / "out"
    scene.mkdir()
    for i in range(3):
        cv2.imwrite(str(scene / f"{i}.png"), _photo(i))
    reconstruct_scene(scene, "sift", out, ReconstructOptions(progress=False))
    cv2.imwrite(str(scene / "1.png"), np.zeros((120, 160, 3), np.uint8))  # the burst replaced by a black frame
    reconstruct_scene(scene, "sift", out, ReconstructOptions(progress=False))
    stored = np.load(out / "features" / "1.npz")
    assert len(stored["keypoints"]) == len(create("sift")(np.zeros((1, 120, 160, 3), np.uint8))["keypoints"]) == 0
    assert read_image(out / "images" / "1.png").max() == 0
    assert len(np.load(out / "features" / "0.npz")["keypoints"]) > 0


def test_an_option_at_its_default_value_does_not_change_the_key():
    """`lburst extract` passes --top-k 4000, `lburst reconstruct` none: the same features."""
    assert (
        store.method_key("lburst", top_k=4000) == store.method_key("lburst") == store.method_key("lburst", top_k=None)
    )
    assert store.method_key("lburst", top_k=2000) != store.method_key("lburst")
    assert store.method_key("lburst,top_k=2000", top_k=4000) != store.method_key("lburst,top_k=2000")
    assert store.method_key("sift") == {"spec": "sift", "options": {}, "revision": store.REVISION}


def test_features_of_an_earlier_revision_of_the_extraction_are_computed_again(tmp_path, monkeypatch):
    """Stored features of the code before a change of what it extracts (:data:`lburst.store.REVISION`)
    are not served."""
    burst = tmp_path / "b0"
    save_burst(np.stack([_photo(k) for k in range(3)]), burst)
    path = tmp_path / "b0.npz"
    old = store.key(store.method_key("sift"), burst)
    features = {
        "keypoints": np.array([[3.0, 4.0]], np.float32),
        "scales": np.ones(1, np.float32),
        "scores": np.ones(1, np.float32),
        "descriptors": np.ones((1, 8), np.float32),
        "image_size": np.array([160, 120]),
    }
    store.save(path, features, None, old)
    assert store.load(path, old) is not None
    monkeypatch.setattr(store, "REVISION", store.REVISION + 1)
    assert store.load(path, store.key(store.method_key("sift"), burst)) is None


def test_reconstruct_uses_the_keyframe_features_that_extract_stored(tmp_path, monkeypatch):
    """`lburst extract REC` then `lburst reconstruct REC --features OUT` (or the same --out) with the
    same method and cut: one key (:func:`lburst.store.key`), so no keyframe is extracted again."""
    import lburst.methods
    from lburst.cli import main
    from lburst.scenes.flight_recording import write_flight_png
    from lburst.scenes.night_flight import NightFlightConfig

    cfg = NightFlightConfig.daylight(n_bursts=3, width=256, height=192, noise="none")
    frames = write_flight_png(tmp_path / "frames", cfg, progress=False)
    cut = ["--every", "16", "--burst", "3", "--method", "sift,max_features=1500"]
    extracted = tmp_path / "extracted"
    assert main(["extract", str(frames), *cut, "--out", str(extracted)]) == 0
    stored = {p: p.stat().st_mtime_ns for p in (extracted / "frames").glob("*.npz")}
    assert len(stored) == 5

    calls = []

    def counting(spec, **options):
        extractor = create(spec, **options)

        def run(burst):
            calls.append(spec)
            return extractor(burst)

        return run

    monkeypatch.setattr(lburst.methods, "create", counting)
    for out, given in ((tmp_path / "rec", ["--features", str(extracted)]), (extracted, [])):
        assert main(["reconstruct", str(frames), *cut, "--out", str(out), "--threads", "1", *given]) == 0
        assert calls == []  # every keyframe's features came from the store
        assert {p: p.stat().st_mtime_ns for p in stored} == stored
        result = json.loads((out / "result.json").read_text())
        assert len(result["names"]) == 5 and result["registered"] == result["names"]
        for name in result["names"]:
            np.testing.assert_array_equal(
                np.load(out / "features" / f"{name}.npz")["keypoints"],
                np.load(extracted / "frames" / f"{name}.npz")["keypoints"],
            )
    # another cut of the recording is other bursts: extracted now, with a warning that says why
    other_cut = [*cut[:-4], "--burst", "1", *cut[-2:], "--out", str(tmp_path / "b1"), "--threads", "1"]
    with pytest.warns(UserWarning, match=r"5 of 5 bursts were not stored there .* are of other bursts"):
        assert main(["reconstruct", str(frames), *other_cut, "--features", str(extracted)]) == 0
    assert len(calls) == 5
