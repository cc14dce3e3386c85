"""Fast burst alignment (``method="pyramid"``): known shifts recovered on simulated bursts,
no motion read as none, the dtype-preserving warp of ``align_burst``, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from lburst.burst.align import align_burst, estimate_shifts, pyramid_scales, pyramid_shifts, warp_frame
from lburst.noise import GaussianNoise
from lburst.simulate import simulate_burst

cv2.setNumThreads(1)
VELOCITY = np.array([2.37, -1.62])
TRUTH = (np.arange(5) - 2)[:, None] * VELOCITY
#: max shift error (px, per coordinate) allowed per Gaussian noise std; measured about 0.01 and 0.04
TOLERANCE = {0.0: 0.05, 50.0: 0.12}


def photo(size: tuple[int, int]) -> np.ndarray:
    """Astronaut resized to ``size`` (w, h): textured, as a robot's view of a scene."""
    return cv2.resize(data.astronaut(), size, interpolation=cv2.INTER_CUBIC)


@pytest.fixture(scope="module")
def bursts() -> dict:
    """Bursts moving at VELOCITY, at 1024x768 (half-resolution ECC) and 320x240 (full resolution)."""
    out = {}
    for size in [(1024, 768), (320, 240)]:
        for noise in TOLERANCE:
            model = GaussianNoise(noise) if noise else None
            out[size, noise] = simulate_burst(photo(size), 5, tuple(VELOCITY), model, rng=7)
    return out


def test_the_pyramid_runs_ecc_at_half_resolution_on_1024x768():
    assert pyramid_scales(768, 1024) == (2, 4)
    assert pyramid_scales(240, 320) == (1, 2)
    assert pyramid_scales(40, 40) == (1, 1)


@pytest.mark.parametrize("size", [(1024, 768), (320, 240)])
@pytest.mark.parametrize("noise", sorted(TOLERANCE))
def test_pyramid_recovers_known_shifts(bursts, size, noise):
    burst = bursts[size, noise]
    free = estimate_shifts(burst, method="pyramid", motion="free")
    linear = estimate_shifts(burst, method="pyramid", motion="linear")
    for shifts in (free, linear):
        assert shifts.shape == (5, 2) and shifts.dtype == np.float64
        np.testing.assert_array_equal(shifts[2], [0, 0])
        assert np.abs(shifts - TRUTH).max() < TOLERANCE[noise], shifts - TRUTH
    np.testing.assert_array_equal(free, pyramid_shifts(burst))


@pytest.mark.parametrize("noise", sorted(TOLERANCE))
def test_a_still_burst_has_no_shift(noise):
    still = simulate_burst(photo((1024, 768)), 5, (0.0, 0.0), GaussianNoise(noise) if noise else None, rng=3)
    assert np.abs(estimate_shifts(still, method="pyramid", motion="free")).max() < TOLERANCE[noise] / 2


def test_a_flat_burst_gives_finite_shifts():
    flat = np.full((5, 64, 80, 3), 90, np.uint8)
    shifts = estimate_shifts(flat, method="pyramid")
    assert np.all(np.isfinite(shifts)) and np.abs(shifts).max() < 1


def test_align_burst_uses_the_pyramid_and_removes_the_motion(bursts):
    burst = bursts[(1024, 768), 50.0]
    aligned = align_burst(burst)
    assert aligned.dtype == burst.dtype and aligned.shape == burst.shape
    np.testing.assert_array_equal(aligned[2], burst[2])
    np.testing.assert_array_equal(aligned, align_burst(burst, estimate_shifts(burst, "pyramid", "linear")))
    inner = (slice(16, -16), slice(16, -16))
    before = np.abs(burst[0].astype(float) - burst[2])[inner].mean()
    after = np.abs(aligned[0].astype(float) - aligned[2])[inner].mean()
    assert after < 0.8 * before  # at noise 50 what is left is mostly the noise of two frames
    clean = bursts[(320, 240), 0.0]
    residual = np.abs(align_burst(clean)[0].astype(float) - clean[2])[inner].mean()
    assert residual < 0.25 * np.abs(clean[0].astype(float) - clean[2])[inner].mean()


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_the_warp_in_the_burst_dtype_matches_the_rounded_float_warp(bursts, dtype):
    burst = bursts[(320, 240), 50.0].astype(dtype)
    if dtype == np.uint16:
        burst = burst * 257 + 128
    top = np.iinfo(dtype).max
    aligned = align_burst(burst, TRUTH)
    assert aligned.dtype == dtype
    np.testing.assert_array_equal(aligned[2], burst[2])
    for k in (0, 1, 3, 4):
        reference = np.clip(np.rint(warp_frame(burst[k], TRUTH[k])), 0, top).astype(np.int64)
        diff = np.abs(aligned[k].astype(np.int64) - reference)
        assert diff.max() <= (0 if dtype == np.uint16 else 1)  # OpenCV's 8-bit fixed-point weights
        assert (diff > 0).mean() < 0.02


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((64, 64, 3), np.uint8),  # one image, not a burst
        np.zeros((5, 64, 64), np.uint8),  # grey frames
        np.zeros((5, 64, 64, 4), np.uint8),  # RGBA
        np.zeros((4, 64, 64, 3), np.uint8),  # even frame count
        np.zeros((5, 64, 64, 3), np.float32),  # float frames
    ],
)
def test_bad_bursts_are_one_value_error(bad):
    with pytest.raises(ValueError, match="burst"):
        estimate_shifts(bad, method="pyramid")
    with pytest.raises(ValueError, match="burst"):
        align_burst(bad)


def test_bad_options_and_shifts_are_value_errors():
    burst = np.zeros((5, 32, 32, 3), np.uint8)
    with pytest.raises(ValueError, match="pyramid"):
        estimate_shifts(burst, method="fast")
    with pytest.raises(ValueError, match=r"shifts must be \(5, 2\)"):
        align_burst(burst, np.zeros((3, 2)))


def test_align_burst_takes_non_contiguous_bursts(bursts):
    burst = bursts[(320, 240), 0.0]
    flipped = burst[:, :, ::-1]  # a view with a negative stride
    expected = align_burst(np.ascontiguousarray(flipped), TRUTH * [-1, 1])
    np.testing.assert_array_equal(align_burst(flipped, TRUTH * [-1, 1]), expected)
    np.testing.assert_array_equal(align_burst(np.asfortranarray(burst), TRUTH), align_burst(burst, TRUTH))


def test_the_coarse_start_finds_a_shift_in_noise_that_defeats_phase_correlation():
    """A dim, blurred texture moved by (5, -3) px, with independent noise in both images: the
    plain cross-correlation start lands within 1 px in 16 of 20 noise draws at std 10 (OpenCV's
    phase correlation, which weighs the noisy high frequencies alike, in 9), and exactly without
    noise."""
    from lburst.burst.align import coarse_shift

    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.normal(0, 1, (160, 224)).astype(np.float32), (0, 0), 3) * 40 + 60
    window = cv2.createHanningWindow((200, 136), cv2.CV_32F)
    reference, moved = base[12:148, 12:212], base[15:151, 7:207]  # content at p in reference is at p + (5, -3)
    np.testing.assert_allclose(coarse_shift(reference, moved, window), [5, -3], atol=0.05)
    close = 0
    for seed in range(20):
        noise = np.random.default_rng(seed).normal(0, 10, (2, 136, 200)).astype(np.float32)
        shift = coarse_shift(reference + noise[0], moved + noise[1], window)
        close += np.abs(shift - [5, -3]).max() < 1
    assert close >= 16
    assert np.array_equal(coarse_shift(np.full((136, 200), 7, np.float32), moved, window), [0, 0])  # flat: no shift
