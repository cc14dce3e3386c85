"""An output folder that is, or is inside, an input folder is refused before any work (a
second run would read the first one's outputs as input)."""

import numpy as np
import pytest

from lburst.burst.io import check_output_outside, save_burst
from lburst.cli import main
from lburst.sfm.reconstruct import ReconstructionError, reconstruct_scene


@pytest.mark.parametrize("inside", ["", "out", "out/deeper"])
def test_extract_refuses_an_output_in_its_input(tmp_path, capsys, inside):
    burst = tmp_path / "b"
    save_burst(np.zeros((5, 32, 32, 3), np.uint8), burst)
    out = burst / inside if inside else burst
    assert main(["extract", str(burst), "--out", str(out), "--method", "sift"]) == 2
    err = capsys.readouterr().err
    assert "the output folder is" in err and str(burst) in err and not list(burst.glob("*.npz"))


def test_reconstruct_refuses_its_scene_as_output(tmp_path):
    scene = tmp_path / "scene"
    for i in range(2):
        save_burst(np.zeros((5, 32, 32, 3), np.uint8), scene / f"b{i}")
    with pytest.raises(ReconstructionError, match="the output folder is the input"):
        reconstruct_scene(scene, "sift", scene)
    assert not (scene / "images").exists()


def test_a_sibling_or_a_file_input_is_fine(tmp_path):
    (tmp_path / "in").mkdir()
    (tmp_path / "clip.mp4").write_bytes(b"")
    check_output_outside(tmp_path / "in-out", [tmp_path / "in"])
    check_output_outside(tmp_path / "out", [tmp_path / "clip.mp4"])
    with pytest.raises(ValueError, match="inside the input"):
        check_output_outside(tmp_path / "in" / "x", [tmp_path / "in"])
