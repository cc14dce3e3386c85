"""Bursts that turn (:mod:`lburst.burst.turning`): a known in-plane rotation and translation
recovered, the turned frames brought onto the common frame, and bursts that do not turn aligned
exactly as by their shifts."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from lburst.burst.align import align_burst, estimate_shifts, estimate_warps, translation_warps
from lburst.burst.turning import ROTATION_MIN_PX, warp_matrix
from lburst.errors import LBurstValueError

cv2.setNumThreads(1)
#: degrees and pixels per frame: a drone turning at 24 deg/s, 20 frames/s, with a drift
DEGREES, VELOCITY = 1.2, np.array([6.0, -3.5])


def turning_burst(size: tuple[int, int], degrees: float, noise: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 5-frame burst of the astronaut turning by ``degrees`` and moving by VELOCITY per frame
    about its centre, with Gaussian noise; and its true warps (``frame_k(W_k p) = common(p)``)."""
    w, h = size
    scene = cv2.resize(data.astronaut(), (w + 200, h + 200), interpolation=cv2.INTER_CUBIC).astype(np.float32)
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    rng = np.random.default_rng(seed)
    frames, warps = [], []
    for t in range(-2, 3):
        warp = warp_matrix(np.radians(degrees * t), VELOCITY * t, centre)
        # frame_k(q) = scene(W_k^-1 q + 100): pixel p of the common frame lands at W_k p in frame k
        inverse = cv2.invertAffineTransform(warp)
        inverse[:, 2] += 100
        frame = cv2.warpAffine(scene, inverse, (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
        frames.append(np.clip(frame + rng.normal(0, noise, frame.shape), 0, 255).astype(np.uint8))
        warps.append(warp)
    return np.stack(frames), np.stack(warps)


@pytest.mark.parametrize("size", [(640, 480), (1024, 768)])
@pytest.mark.parametrize("noise", [0.0, 50.0])
def test_a_turning_burst_gets_its_rotation_and_translation(size, noise):
    burst, truth = turning_burst(size, DEGREES, noise, seed=3)
    warps = estimate_warps(burst)
    angles = np.degrees(np.arctan2(warps[:, 1, 0], warps[:, 0, 0]))
    np.testing.assert_allclose(angles, DEGREES * np.arange(-2, 3), atol=0.03)
    w, h = size
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], float).T
    assert np.abs(warps @ corners - truth @ corners).max() < 0.6  # px, anywhere in the frame


def test_aligning_a_turning_burst_brings_its_frames_onto_the_common_one():
    burst, _ = turning_burst((640, 480), DEGREES, 0.0, seed=3)
    inner = np.s_[40:-40, 40:-40]

    def misfit(aligned: np.ndarray) -> float:
        return float(np.abs(aligned[0].astype(float) - aligned[2])[inner].mean())

    shifted = misfit(align_burst(burst, turn=False))
    turned = misfit(align_burst(burst))
    assert turned < 0.3 * shifted
    assert turned < 4.0  # grey levels: what is left is resampling


def test_a_burst_that_does_not_turn_is_aligned_by_its_shifts_alone():
    burst, _ = turning_burst((640, 480), 0.0, 30.0, seed=4)
    warps = estimate_warps(burst)
    np.testing.assert_array_equal(warps, translation_warps(estimate_shifts(burst, "pyramid", "linear")))
    np.testing.assert_array_equal(align_burst(burst), align_burst(burst, turn=False))


def test_a_turn_below_the_threshold_reads_as_none():
    """0.6 of the threshold at the corners, so that the estimate's noise stays on one side."""
    half_diagonal = np.hypot(640, 480) / 2
    degrees = np.degrees(0.6 * ROTATION_MIN_PX / half_diagonal / 2)  # the end frames turn by 2x
    burst, _ = turning_burst((640, 480), degrees, 0.0, seed=5)
    assert np.all(estimate_warps(burst)[:, :, :2] == np.eye(2))


def test_given_warps_are_applied_and_bad_ones_refused():
    burst, truth = turning_burst((320, 240), DEGREES, 0.0, seed=6)
    np.testing.assert_array_equal(align_burst(burst, truth), align_burst(burst, truth.copy()))
    assert not np.array_equal(align_burst(burst, truth), align_burst(burst, truth[:, :, 2]))
    with pytest.raises(LBurstValueError, match=r"\(5, 2, 3\)"):
        align_burst(burst, np.zeros((5, 3, 3)))
    with pytest.raises(LBurstValueError, match="motion model"):
        estimate_warps(burst, motion="affine")
