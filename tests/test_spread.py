"""Keypoints spread over the image: a plain top-k of a detector whose scores fade towards the
borders leaves the periphery empty; spread_top_k gives every cell of a grid its share."""

import numpy as np
import pytest

from lburst.features import spread_top_k


def _faded(n=5000, size=(400, 300), seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * size
    centre = np.array(size) / 2
    score = 1 - np.linalg.norm((xy - centre) / centre, axis=1) / np.sqrt(2) + 0.01 * rng.random(n)
    order = np.argsort(-score)
    return {
        "keypoints": xy[order].astype(np.float32),
        "scores": score[order].astype(np.float32),
        "scales": np.ones(n, np.float32),
        "descriptors": rng.normal(size=(n, 8)).astype(np.float32)[order],
    }


def _cells(feats, size, cells):
    x, y = feats["keypoints"].T
    ix = np.clip((x + 0.5) * cells / size[0], 0, cells - 1).astype(int)
    iy = np.clip((y + 0.5) * cells / size[1], 0, cells - 1).astype(int)
    return np.bincount(ix * cells + iy, minlength=cells * cells)


def test_every_cell_gets_its_share_and_the_rest_goes_to_the_best():
    size, feats = (400, 300), _faded()
    plain = {k: v[:800] for k, v in feats.items()}
    assert _cells(plain, size, 4).min() == 0  # the corners are empty under a plain top-k
    spread = spread_top_k(feats, 800, size, 4)
    assert len(spread["scores"]) == 800 and np.all(np.diff(spread["scores"]) <= 0)
    assert _cells(spread, size, 4).min() >= 800 // 16
    # each kept keypoint is the original one, descriptor and all
    rows = {tuple(p): i for i, p in enumerate(feats["keypoints"])}
    idx = np.array([rows[tuple(p)] for p in spread["keypoints"]])
    assert np.array_equal(spread["descriptors"], feats["descriptors"][idx])
    # beyond the quotas, the best remaining ones: every dropped keypoint scores below the kept non-quota ones
    assert spread_top_k(feats, 10_000, size, 4) is feats


@pytest.mark.parametrize("cells", [1])
def test_one_cell_is_a_plain_top_k(cells):
    feats = _faded()
    spread = spread_top_k(feats, 500, (400, 300), cells)
    assert np.array_equal(spread["keypoints"], feats["keypoints"][:500])


def test_the_method_option_is_checked():
    from lburst.methods import create

    with pytest.raises(ValueError, match="spread must be an integer 0-64"):
        create("lburst-lite,spread=-1")
