"""Keypoints found in a pyramid level land on the image pixel that the level pixel covers:
``(x + 0.5) * W / w - 0.5`` (pixel centres at integers), or the published ``x * W / w``."""

import numpy as np
import pytest
import torch

from lburst.model.extractor import LBurst

WIDTH, HEIGHT = 400, 300
PEAK = (23, 17)  # (x, y) in every level's own pixels


class PeakRunner:
    """A network stand-in: repeatability 0 but for one peak at level pixel ``PEAK``, its height
    telling the levels apart (the first level run the highest), reliability 1."""

    def __init__(self) -> None:
        self.sizes: list[tuple[int, int]] = []  # (w, h) of each level, in the order run
        self.rng = np.random.default_rng(0)

    def __call__(self, x: torch.Tensor):
        b, _, h, w = x.shape
        rep = torch.zeros(b, 1, h, w)
        rep[:, 0, PEAK[1], PEAK[0]] = 0.99 - 0.01 * len(self.sizes)
        self.sizes.append((w, h))
        half = torch.from_numpy(self.rng.standard_normal((b, 128, h // 2, w // 2)).astype(np.float32))
        return rep, torch.ones(b, 1, h, w), half


@pytest.mark.parametrize("published", [False, True])
@pytest.mark.parametrize("max_scale", [1.0, 1.5])
def test_a_peak_at_a_known_level_pixel_is_a_keypoint_at_the_image_pixel_it_covers(published, max_scale):
    runner = PeakRunner()
    model = LBurst(None, runner=runner, frames=1)
    image = np.full((HEIGHT, WIDTH, 3), 128, np.uint8)
    feats = model.extract(image, top_k=None, published_coordinates=published, max_scale=max_scale)
    assert len(runner.sizes) >= 3 and any(w != WIDTH for w, _ in runner.sizes)  # levels other than the image's
    assert len(feats["keypoints"]) == len(runner.sizes)  # one keypoint per level, by decreasing peak
    for (w, h), (x, y), scale in zip(runner.sizes, feats["keypoints"], feats["scales"]):
        if published:
            expected = (PEAK[0] * WIDTH / w, PEAK[1] * HEIGHT / h)
        else:
            expected = ((PEAK[0] + 0.5) * WIDTH / w - 0.5, (PEAK[1] + 0.5) * HEIGHT / h - 0.5)
        assert (x, y) == pytest.approx(expected, abs=1e-3), (w, h)
        assert scale == pytest.approx(32 * WIDTH / w, rel=0.01)


def test_at_a_half_size_level_a_pixel_covers_two_image_pixels_and_its_centre_lies_between_them():
    """The level pixel x = 23 of a half-size level covers image pixels 46 and 47: its centre, 46.5."""
    runner = PeakRunner()
    model = LBurst(None, runner=runner, frames=1)
    feats = model.extract(np.zeros((256, 512, 3), np.uint8), top_k=None, min_scale=0.5, max_scale=0.5, min_size=64)
    assert runner.sizes == [(256, 128)]
    np.testing.assert_allclose(feats["keypoints"], [[46.5, 34.5]], atol=1e-4)
