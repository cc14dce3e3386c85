"""The shipped weights: they load by name, take the right bursts and match under a known
homography (a random network finds no keypoints at the 0.7 thresholds)."""

import cv2
import numpy as np
import pytest
import skimage.data

from lburst import LBurst
from lburst.bench.metrics import match_errors
from lburst.match import mutual_nearest_neighbours
from lburst.simulate import simulate_burst
from lburst.weights import NAMES, weights_path

H = np.array([[0.94, -0.17, 30.0], [0.17, 0.94, -12.0], [0.0002, 0.0001, 1.0]])


def _pair(size=(256, 192)):
    image = cv2.resize(skimage.data.astronaut(), size, interpolation=cv2.INTER_AREA)
    warped = cv2.warpPerspective(image, H, size, borderMode=cv2.BORDER_REFLECT)
    return [simulate_burst(im, 5, motion=(1.5, 0.5), rng=i) for i, im in enumerate((image, warped))]


@pytest.mark.parametrize("name, frames", [("lburst-b5", 5), ("lburst-b1", 1), ("lburst-b5-lite", 5)])
def test_shipped_weights_match_under_a_known_homography(name, frames):
    model = LBurst.pretrained(name, device="cpu")
    assert model.frames == frames
    a, b = (model.extract(burst, top_k=500, max_size=256) for burst in _pair())
    assert len(a["keypoints"]) > 150 and len(b["keypoints"]) > 150
    matches = mutual_nearest_neighbours(a["descriptors"], b["descriptors"])
    errors = match_errors(H, a["keypoints"][:, :2], b["keypoints"][:, :2], matches)
    assert len(matches) > 80 and np.mean(errors <= 3) > 0.6


def test_unknown_weights_name_lists_the_shipped_ones():
    with pytest.raises(ValueError, match="lburst-b5, lburst-b1, lburst-b5-lite"):
        weights_path("lburst-b3")
    assert all(weights_path(n).is_file() for n in NAMES)
