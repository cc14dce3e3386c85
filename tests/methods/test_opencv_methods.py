"""SIFT and ORB extractors: the common frame, dtype handling, RootSIFT, options, geometry."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from lburst.features import check_features, is_binary
from lburst.match import mutual_nearest_neighbours
from lburst.methods import create
from lburst.methods.opencv import root_sift

cv2.setNumThreads(1)


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return np.ascontiguousarray(data.astronaut()[:320, 100:420])


def test_sift_uses_the_middle_frame(photo):
    rng = np.random.default_rng(0)
    others = rng.integers(0, 256, photo.shape, dtype=np.uint8)
    burst = np.stack([others, others, photo, others, others])
    feats = check_features(create("sift")(burst))
    gray = cv2.cvtColor(photo, cv2.COLOR_RGB2GRAY)
    kps, desc = cv2.SIFT_create(nfeatures=5000).detectAndCompute(gray, None)
    np.testing.assert_array_equal(feats["keypoints"], np.array([k.pt for k in kps], np.float32))
    np.testing.assert_array_equal(feats["descriptors"], desc)
    np.testing.assert_allclose(feats["scales"], [k.size for k in kps])
    np.testing.assert_allclose(feats["orientations"], np.deg2rad([k.angle for k in kps]), rtol=1e-6)
    assert feats["descriptors"].dtype == np.float32 and not is_binary(feats)


def test_uint16_is_scaled_to_8_bit(photo):
    eight = create("orb")(photo[None])
    sixteen = create("orb")((photo.astype(np.uint16) * 257)[None])
    np.testing.assert_array_equal(eight["keypoints"], sixteen["keypoints"])
    np.testing.assert_array_equal(eight["descriptors"], sixteen["descriptors"])


def test_orb_descriptors_are_packed_bits_and_capped(photo):
    feats = check_features(create("orb,max_features=300")(photo[None]))
    assert feats["descriptors"].dtype == np.uint8 and feats["descriptors"].shape[1] == 32
    assert 0 < len(feats["keypoints"]) <= 300
    assert is_binary(feats)


def test_root_sift_is_hellinger_normalised(photo):
    plain = create("sift,max_features=200")(photo[None])
    root = create("sift,max_features=200,root=true")(photo[None])
    np.testing.assert_array_equal(plain["keypoints"], root["keypoints"])
    np.testing.assert_allclose(np.linalg.norm(root["descriptors"], axis=1), 1.0, atol=1e-5)
    d = plain["descriptors"][0]
    np.testing.assert_allclose(root["descriptors"][0], np.sqrt(d / d.sum()), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(root_sift(np.array([[3.0, 1.0]])), [[np.sqrt(0.75), 0.5]], rtol=1e-6)


@pytest.mark.parametrize("spec", ["sift", "orb"])
def test_translation_is_recovered_by_matches(photo, spec):
    """Keypoints matched between a photo and a copy shifted by (7, 3) px sit 7, 3 px apart."""
    shifted = np.zeros_like(photo)
    shifted[3:, 7:] = photo[:-3, :-7]
    a = create(spec)(photo[None])
    b = create(spec)(shifted[None])
    pairs = mutual_nearest_neighbours(a["descriptors"], b["descriptors"])
    offset = b["keypoints"][pairs[:, 1]] - a["keypoints"][pairs[:, 0]]
    correct = np.linalg.norm(offset - [7, 3], axis=1) < 1.0
    assert len(pairs) > 100 and correct.mean() > 0.7


def test_bad_input_and_options(photo):
    with pytest.raises(ValueError, match="odd"):
        create("sift")(np.stack([photo, photo]))
    with pytest.raises(ValueError, match="uint8 or uint16"):
        create("sift")(photo[None].astype(np.float32))
    with pytest.raises(ValueError, match="unknown options"):
        create("orb,colour=1")
    with pytest.raises(ValueError, match="boolean"):
        create("sift,root=maybe")


@pytest.mark.parametrize(
    "spec, named",
    [
        ("orb,max_features=-1", "orb max_features"),
        ("orb,max_features=0", "orb max_features"),
        ("sift,max_features=-1", "sift max_features"),
        ("sift,contrast_threshold=0", "sift contrast_threshold"),
    ],
)
def test_counts_opencv_refuses_are_refused_by_name_before_opencv(spec, named):
    with pytest.raises(ValueError, match=named):
        create(spec)
