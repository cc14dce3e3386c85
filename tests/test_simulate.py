"""Simulated bursts: exact geometry against ground truth, seeded noise."""

import cv2
import numpy as np
import pytest
import skimage.data

from lburst.noise import GaussianNoise
from lburst.simulate import random_motion, simulate_burst, stable_seed


@pytest.fixture(scope="module")
def photo():
    return skimage.data.astronaut()  # (512, 512, 3) uint8, textured


def _shift(a, b):
    """Translation of b relative to a (content of a at p appears at p + shift in b), by ECC
    (phase correlation's sub-pixel peak is itself biased by a few hundredths of a pixel)."""
    win = (slice(64, 448), slice(64, 448))
    ga = a[win].mean(-1).astype(np.float32)
    gb = b[win].mean(-1).astype(np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-8)
    _, warp = cv2.findTransformECC(ga, gb, np.eye(2, 3, dtype=np.float32), cv2.MOTION_TRANSLATION, criteria, None, 5)
    return warp[:, 2].astype(np.float64)


def test_middle_frame_is_the_image_exactly(photo):
    burst = simulate_burst(photo, 5, (1.3, -0.7))
    assert burst.shape == (5, 512, 512, 3) and burst.dtype == np.uint8
    np.testing.assert_array_equal(burst[2], photo)


@pytest.mark.parametrize("motion", [(1.3, -0.7), (-2.45, 0.35), (0.5, 2.0)])
def test_frame_k_is_displaced_by_k_times_the_motion(photo, motion):
    smooth = cv2.GaussianBlur(photo, (0, 0), 1.5)  # band-limited: bilinear resampling is near exact
    burst = simulate_burst(smooth, 5, motion)
    for i, k in enumerate(range(-2, 3)):
        measured = _shift(burst[2], burst[i])
        np.testing.assert_allclose(measured, k * np.asarray(motion), atol=0.05)


def test_noise_is_seeded_and_has_the_requested_std(photo):
    a = simulate_burst(photo, 3, (1, 0), GaussianNoise(10.0), rng=7)
    b = simulate_burst(photo, 3, (1, 0), GaussianNoise(10.0), rng=7)
    c = simulate_burst(photo, 3, (1, 0), GaussianNoise(10.0), rng=8)
    np.testing.assert_array_equal(a, b)
    assert (a != c).any()
    mid = (photo > 40) & (photo < 215)  # away from clipping
    residual = a[1].astype(float) - photo
    assert residual[mid].std() == pytest.approx(10.0, rel=0.03)
    assert abs(residual[mid].mean()) < 0.1


def test_uint16_keeps_its_range():
    img = (np.linspace(0, 65535, 64 * 64 * 3).reshape(64, 64, 3)).astype(np.uint16)
    burst = simulate_burst(img, 3, (0.5, 0.5), GaussianNoise(2.0), rng=0)
    assert burst.dtype == np.uint16
    residual = burst[1].astype(float) - img
    inner = (img > 2000) & (img < 63000)
    assert residual[inner].std() == pytest.approx(2.0 * 257, rel=0.05)  # std given on the 0..255 scale


def test_grayscale_becomes_three_channels():
    gray = skimage.data.camera()
    burst = simulate_burst(gray, 3)
    assert burst.shape == (3,) + gray.shape + (3,) and (burst[1][..., 0] == gray).all()


def test_bad_inputs_are_errors(photo):
    with pytest.raises(ValueError, match="odd"):
        simulate_burst(photo, 4)
    with pytest.raises(ValueError, match="shape"):
        simulate_burst(photo[None], 3)
    with pytest.raises(ValueError, match="uint8 or uint16"):
        simulate_burst(photo.astype(np.float32), 3)
    with pytest.raises(ValueError, match="motion"):
        simulate_burst(photo, 5, [(0, 0)] * 3)


def test_stable_seed_and_random_motion():
    assert stable_seed("graf", 1, 50) == stable_seed("graf", 1, 50)
    assert stable_seed("graf", 1, 50) != stable_seed("graf", 1, 100)
    assert stable_seed("graf", 1, 50) == 0x0 + stable_seed("graf", "1", "50")  # by their text
    dx, dy = random_motion(stable_seed("x"), 3.0)
    assert -3 <= dx <= 3 and -3 <= dy <= 3
    assert (dx, dy) == random_motion(stable_seed("x"), 3.0)
