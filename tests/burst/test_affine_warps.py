"""Affine alignment (:func:`lburst.burst.align.affine_warps`): a burst that zooms, as a camera
moving along its view does, brought onto its common frame where a rigid warp cannot."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from lburst.burst.align import _to_full, _to_level, align_burst, estimate_warps
from lburst.burst.motion import BurstMotion
from lburst.errors import LBurstValueError
from lburst.model.extractor import MultiScaleConfig
from lburst.noise import noise_from_spec
from lburst.simulate import simulate_burst

cv2.setNumThreads(1)
#: per frame: 1.5 % zoom about the centre and a drift, together a zoom about a point off the
#: centre (the focus of expansion)
MOTION = BurstMotion(shift=(3.0, -2.0), zoom=0.015)


def zooming_burst(size: tuple[int, int], noise: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 5-frame burst of the astronaut moving by MOTION (:func:`lburst.simulate.simulate_burst`),
    with Gaussian noise; and its true warps (``frame_k(W_k p) = common(p)``)."""
    image = cv2.resize(data.astronaut(), size, interpolation=cv2.INTER_CUBIC)
    burst = simulate_burst(image, 5, MOTION, noise_from_spec(f"gaussian:{noise:g}") if noise else None, seed)
    return burst, np.stack([MOTION.affine(k, size)[:2] for k in range(-2, 3)])


def _corner_error(warps: np.ndarray, truth: np.ndarray, size: tuple[int, int]) -> float:
    w, h = size
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], float).T
    return float(np.abs(warps @ corners - truth @ corners).max())


@pytest.mark.parametrize("size", [(640, 480), (1024, 768)])  # ECC at full and at half resolution
@pytest.mark.parametrize("noise", [0.0, 50.0])
def test_a_zooming_burst_gets_its_affine_maps(size, noise):
    burst, truth = zooming_burst(size, noise, seed=1)
    affine = estimate_warps(burst, warp="affine")
    assert _corner_error(affine, truth, size) < 0.6  # px, anywhere in the frame
    assert _corner_error(estimate_warps(burst), truth, size) > 5  # a translation leaves the zoom
    np.testing.assert_array_equal(affine[2], np.eye(2, 3))


def test_affine_alignment_brings_the_frames_onto_the_common_one():
    burst, _ = zooming_burst((640, 480), 0.0, seed=2)
    inner = np.s_[40:-40, 40:-40]

    def misfit(aligned: np.ndarray) -> float:
        return float(np.abs(aligned[0].astype(float) - aligned[2])[inner].mean())

    assert misfit(align_burst(burst, warp="affine")) < 0.3 * misfit(align_burst(burst))


def test_a_frame_without_texture_keeps_its_rigid_warp():
    burst, _ = zooming_burst((320, 240), 0.0, seed=3)
    burst[0] = 128  # ECC cannot fit a flat frame
    rigid, affine = estimate_warps(burst), estimate_warps(burst, warp="affine")
    np.testing.assert_array_equal(affine[0], rigid[0])
    assert not np.array_equal(affine[4], rigid[4])


def test_level_and_full_resolution_warps_describe_the_same_map():
    warp = np.array([[1.02, 0.01, 3.5], [-0.02, 0.99, -7.25]])
    for factor in (1, 2, 4):
        level = _to_level(warp, factor)
        np.testing.assert_allclose(_to_full(level, factor), warp)
        # level pixel i covers full pixels factor*i .. factor*i + factor - 1: centre factor*i + (factor-1)/2
        p = np.array([10.0, 20.0])
        full = factor * p + (factor - 1) / 2
        mapped = level[:, :2] @ p + level[:, 2]
        np.testing.assert_allclose(factor * mapped + (factor - 1) / 2, warp[:, :2] @ full + warp[:, 2])


def test_unknown_warps_are_refused_in_one_line():
    burst, _ = zooming_burst((320, 240), 0.0, seed=4)
    with pytest.raises(LBurstValueError, match="unknown warp 'homography'"):
        estimate_warps(burst, warp="homography")
    with pytest.raises(LBurstValueError, match="needs the 'pyramid' method"):
        align_burst(burst, method="phase", warp="affine")
    with pytest.raises(LBurstValueError, match="unknown warp"):
        MultiScaleConfig(warp="perspective")


def test_the_extractor_aligns_with_the_warp_it_is_asked_for(monkeypatch):
    import lburst.model.extractor as extractor
    from lburst import LBurst
    from lburst.model.network import LBurstNet, NetConfig

    asked = []

    def recording(burst, **kwargs):
        asked.append(kwargs.get("warp"))
        return burst

    monkeypatch.setattr(extractor, "align_burst", recording)
    model = LBurst(LBurstNet(NetConfig(frames=5)), align=True)
    burst, _ = zooming_burst((64, 48), 0.0, seed=5)
    model.extract(burst, top_k=10, min_size=32)
    model.extract(burst, top_k=10, min_size=32, warp="affine")
    assert asked == ["rigid", "affine"]
