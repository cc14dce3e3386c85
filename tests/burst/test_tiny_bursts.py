"""Frames too small for lburst are refused in one line before any stage, the alignment
included (OpenCV's phase correlation fails on a 1-pixel side with a cv2.error)."""

import numpy as np
import pytest
import torch

from lburst import LBurst
from lburst.burst.align import align_burst, estimate_shifts
from lburst.burst.io import save_burst
from lburst.cli import main
from lburst.methods import create
from lburst.model.lite import LiteConfig, LiteNet


def _burst(h, w, n=5):
    return np.random.default_rng(0).integers(0, 256, (n, h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize("size", [(1, 1), (1, 64), (64, 1), (7, 40)])
def test_alignment_refuses_a_burst_too_small(size):
    for call in (align_burst, estimate_shifts):
        with pytest.raises(ValueError, match=rf"a {size[1]}x{size[0]} burst is too small \(at least 8 px"):
            call(_burst(*size))


@pytest.mark.parametrize("size", [(1, 1), (1, 64), (5, 30)])
def test_an_aligning_network_refuses_it_before_aligning(size):
    torch.manual_seed(0)
    model = LBurst(LiteNet(LiteConfig(frames=5, dim=16, fine=8, coarse=16, dilations=(1,))), "cpu", align=True)
    with pytest.raises(ValueError, match="too small for features"):
        model.extract(_burst(*size))
    with pytest.raises(ValueError, match="too small"):
        create("align+sift")(_burst(*size))


def test_extract_reports_a_tiny_burst_in_one_line_and_goes_on(tmp_path, capsys):
    save_burst(_burst(1, 64), tmp_path / "tiny")
    save_burst(_burst(48, 64), tmp_path / "good")
    code = main(
        [
            "extract",
            str(tmp_path / "tiny"),
            str(tmp_path / "good"),
            "--out",
            str(tmp_path / "out"),
            "--method",
            "align+sift",
        ]
    )
    err = capsys.readouterr().err
    assert code != 0 and (tmp_path / "out" / "good.npz").is_file()
    lines = [line for line in err.splitlines() if "tiny" in line]
    assert lines and all("64x1 burst is too small" in line for line in lines) and "Traceback" not in err
