"""``lburst reconstruct`` end to end: bad scenes fail cleanly, a small synthetic flight reconstructs."""

import cv2
import numpy as np
import pytest

from lburst.cli import main as cli
from lburst.sfm import ReconstructionError, ReconstructionResult, reconstruct_scene
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.scene import list_scene


def write_png(path, image):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), image)


def noise_image(seed, size=(120, 160)):
    return np.random.default_rng(seed).integers(0, 256, size=(*size, 3), dtype=np.uint8)


def test_scene_listing_natural_order(tmp_path):
    for name in ("img10", "img2", "img1"):
        write_png(tmp_path / f"{name}.png", noise_image(0))
    write_png(tmp_path / "b3" / "frame_000.png", noise_image(1))
    (tmp_path / "notes").mkdir()  # no frames: ignored
    scene = list_scene(tmp_path)
    assert scene.names == ["b3", "img1", "img2", "img10"]
    assert [item.kind for item in scene.items] == ["burst", "image", "image", "image"]
    assert scene.reference_path is None


def test_empty_folder(tmp_path, capsys):
    (tmp_path / "scene").mkdir()
    with pytest.raises(ReconstructionError, match="no bursts"):
        reconstruct_scene(tmp_path / "scene", "sift", tmp_path / "out", ReconstructOptions(progress=False))
    assert cli(["reconstruct", str(tmp_path / "scene"), "--method", "sift", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lburst reconstruct: error: ") and "no bursts" in err[0], err


def test_one_image(tmp_path):
    write_png(tmp_path / "scene" / "a.png", noise_image(0))
    with pytest.raises(ReconstructionError, match="at least 2 images"):
        reconstruct_scene(tmp_path / "scene", "sift", tmp_path / "out", ReconstructOptions(progress=False))


def test_unreadable_image_is_named(tmp_path):
    write_png(tmp_path / "scene" / "a.png", noise_image(0))
    (tmp_path / "scene" / "b.png").write_bytes(b"not a png")
    with pytest.raises(ReconstructionError, match="b.png"):
        reconstruct_scene(tmp_path / "scene", "sift", tmp_path / "out", ReconstructOptions(progress=False))


def test_unreadable_burst_frame_is_named(tmp_path):
    write_png(tmp_path / "scene" / "b0" / "frame_000.png", noise_image(0))
    write_png(tmp_path / "scene" / "b1" / "frame_000.png", noise_image(1))
    (tmp_path / "scene" / "b1" / "frame_000.png").write_bytes(b"broken")
    with pytest.raises(ReconstructionError, match="frame_000.png"):
        reconstruct_scene(tmp_path / "scene", "sift", tmp_path / "out", ReconstructOptions(progress=False))


def test_unrelated_images_register_nothing_without_crashing(tmp_path, capsys):
    for i in range(3):
        write_png(tmp_path / "scene" / f"{i}.png", noise_image(i))
    assert cli(["reconstruct", str(tmp_path / "scene"), "--method", "sift", "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("lburst reconstruct: error: no model") and "registered no images" in err[-1], err
    result = ReconstructionResult.load(tmp_path / "out" / "result.json")
    assert not result.converged and result.registered == [] and result.error is None
    assert result.metrics["registered_pct"] == 0 and result.metrics["keypoints_per_image"] > 0
