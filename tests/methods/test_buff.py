"""BuFF: slopes against known motion, a planted blob's position and scale, SIFT description."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from lburst.features import check_features
from lburst.methods import create, sift_describe
from lburst.methods.buff import Buff, BuffConfig, remap
from lburst.methods.buff_scale import cubic_weights
from lburst.noise import GaussianNoise
from lburst.simulate import simulate_burst

cv2.setNumThreads(1)


def moving_burst(photo, velocity, noise: float, frames: int = 5, size: int = 320, seed: int = 0) -> np.ndarray:
    """``photo`` moving at ``velocity`` px/frame (:func:`lburst.simulate.simulate_burst`, Gaussian noise)."""
    photo = np.ascontiguousarray(photo[:size, :size])
    return simulate_burst(photo, frames, velocity, GaussianNoise(noise) if noise else None, rng=seed)


def blob_burst(centre, sigma, velocity, size=(120, 160), frames=5, amplitude=150.0) -> np.ndarray:
    """A bright Gaussian blob (std ``sigma``) on grey, its centre at ``centre + t * velocity`` in frame t."""
    yy, xx = np.mgrid[0 : size[0], 0 : size[1]].astype(np.float64)
    out = []
    for t in np.arange(frames) - frames // 2:
        cx, cy = centre[0] + t * velocity[0], centre[1] + t * velocity[1]
        image = 60 + amplitude * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * sigma**2))
        out.append(np.repeat(np.rint(image).astype(np.uint8)[..., None], 3, -1))
    return np.stack(out)


@pytest.fixture(scope="module")
def gravel() -> np.ndarray:
    return np.repeat(data.gravel()[..., None], 3, -1)


@pytest.mark.parametrize("velocity", [(1.3, -0.6), (0.8, 1.1)])
def test_slopes_match_the_true_motion(gravel, velocity):
    feats = check_features(create("buff")(moving_burst(gravel, velocity, noise=15.0)))
    assert len(feats["keypoints"]) > 300
    error = np.linalg.norm(feats["slopes"] - velocity, axis=1)
    assert np.mean(error < 0.25) >= 0.7
    assert feats["slopes"].shape == (len(feats["keypoints"]), 2) and feats["slopes"].dtype == np.float32


def test_one_dimensional_slopes_along_a_direction(gravel):
    feats = create("buff,direction=1:0,slope_range=-3:3")(moving_burst(gravel, (-1.3, 0.0), noise=15.0))
    np.testing.assert_array_equal(feats["slopes"][:, 1], 0)
    assert np.mean(np.abs(feats["slopes"][:, 0] + 1.3) < 0.25) >= 0.85


@pytest.mark.parametrize("sigma", [2.5, 5.0])
def test_planted_blob_found_at_its_position_scale_and_motion(sigma):
    burst = blob_burst((80.3, 60.7), sigma, (1.0, 0.5))
    feats = check_features(create("buff")(burst))
    best = np.argmax(feats["scores"])
    np.testing.assert_allclose(feats["keypoints"][best], [80.3, 60.7], atol=0.1)
    np.testing.assert_allclose(feats["slopes"][best], [1.0, 0.5], atol=0.05)
    # the scale agrees with SIFT's on the middle frame (OpenCV's size: a diameter, ~2x the blob's sigma)
    sift = create("sift")(burst)
    np.testing.assert_allclose(feats["scales"][best], sift["scales"][np.argmax(sift["scores"])], rtol=0.05)
    assert feats["scales"][best] == pytest.approx(2 * sigma * 0.88, rel=0.1)
    # every keypoint of this burst is the blob (one per orientation peak)
    assert np.all(np.linalg.norm(feats["keypoints"] - [80.3, 60.7], axis=1) < 0.5)


def test_flat_burst_has_no_features_and_max_features_caps(gravel):
    flat = np.full((5, 64, 64, 3), 90, np.uint8)
    feats = check_features(create("buff")(flat))
    assert feats["keypoints"].shape == (0, 2) and feats["slopes"].shape == (0, 2)
    capped = create("buff,max_features=50,slope_step=1")(moving_burst(gravel, (1.0, 0.0), 10.0, size=160))
    assert len(capped["keypoints"]) == 50
    assert np.all(np.diff(capped["scores"]) <= 0)


def test_options_and_errors():
    extractor = create("buff,slope_range=-1:1,slope_step=0.5,contrast_threshold=0.02,min_slope_sharpness=0.01")
    assert isinstance(extractor, Buff)
    assert len(extractor.slopes) == 25 and extractor.config.contrast_threshold == 0.02
    assert create("buff,direction=0:2,slope_step=1").slopes.tolist() == [[0, -2], [0, -1], [0, 0], [0, 1], [0, 2]]
    with pytest.raises(ValueError, match="unknown options"):
        create("buff,speed=3")
    with pytest.raises(ValueError, match="slope range"):
        BuffConfig(slope_min=1, slope_max=-1).slope_grid()
    with pytest.raises(ValueError, match="odd"):
        create("buff")(np.zeros((4, 32, 32, 3), np.uint8))


def test_cubic_weights_interpolate_polynomials_exactly():
    for f in (0.0, 0.25, 0.5, 0.8):
        w = cubic_weights(f)
        assert w.sum() == pytest.approx(1.0)
        assert (w * [-1, 0, 1, 2]).sum() == pytest.approx(f)  # reproduces linear functions


def _plain_sampler(image: np.ndarray):
    return lambda grid: remap(image, grid[..., 0], grid[..., 1])


def test_orientation_of_a_ramp_follows_its_gradient():
    yy, xx = np.mgrid[0:64, 0:64].astype(np.float32)
    for angle in (0.3, 2.0, 4.5):
        ramp = np.cos(angle) * xx + np.sin(angle) * yy
        index, found = sift_describe.orientations(_plain_sampler(ramp), np.array([[32.0, 32.0]]), np.array([3.0]))
        assert len(index) == 1
        # a pure ramp fills one 10-degree bin, so the answer is exact to half a bin
        assert abs((found[0] - angle + np.pi) % (2 * np.pi) - np.pi) <= np.pi / 36 + 1e-6


def test_descriptor_is_rotation_invariant():
    image = cv2.GaussianBlur(data.camera()[100:300, 150:350].astype(np.float32) / 255, (0, 0), 1.0)
    rotated = np.ascontiguousarray(np.rot90(image))  # (x, y) -> (y, W - 1 - x), angles - 90 degrees
    w = image.shape[1]
    rng = np.random.default_rng(0)
    points = rng.uniform(60, 140, (40, 2)).astype(np.float32)
    sigmas = np.full(40, 3.0)
    angles = rng.uniform(0, 2 * np.pi, 40)
    a = sift_describe.descriptors(_plain_sampler(image), points, sigmas, angles)
    moved = np.stack([points[:, 1], w - 1 - points[:, 0]], 1)
    b = sift_describe.descriptors(_plain_sampler(rotated), moved, sigmas, angles - np.pi / 2)
    cosine = (a * b).sum(1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    assert np.median(cosine) > 0.98
    other = sift_describe.descriptors(_plain_sampler(rotated), moved, sigmas, angles)
    cross = (a * other).sum(1) / np.linalg.norm(a, axis=1) / np.linalg.norm(other, axis=1)
    assert np.median(cross) < 0.9  # the wrong orientation gives a different descriptor
