"""Matchers refuse descriptors they cannot match honestly (different sizes, NaN), and
both factories refuse a spec that is not a string, each in one ValueError."""

import numpy as np
import pytest

from lburst import matching, methods
from lburst.match import mutual_nearest_neighbours


def _feats(desc):
    return {"keypoints": np.zeros((len(desc), 2), np.float32), "descriptors": desc}


@pytest.mark.parametrize("spec", ["mnn", "ratio", "ratio,mutual=false"])
def test_descriptors_of_different_sizes_are_refused(spec):
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(20, 128)).astype(np.float32), rng.normal(size=(30, 64)).astype(np.float32)
    with pytest.raises(ValueError, match="descriptor sizes differ: 128 vs 64"):
        matching.create(spec)(_feats(a), _feats(b))


@pytest.mark.parametrize("spec", ["mnn", "ratio"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_descriptors_are_refused(spec, bad):
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(20, 16)).astype(np.float32), rng.normal(size=(30, 16)).astype(np.float32)
    a[3, 5] = bad
    with pytest.raises(ValueError, match="1 of the first set's 20 descriptors hold NaN or inf"):
        matching.create(spec)(_feats(a), _feats(b))
    with pytest.raises(ValueError, match="NaN or inf"):
        mutual_nearest_neighbours(b, a)


@pytest.mark.parametrize("spec", [None, 5, ["mnn"]])
def test_specs_that_are_not_strings_are_refused(spec):
    with pytest.raises(ValueError, match="matcher spec is a string"):
        matching.create(spec)
    with pytest.raises(ValueError, match="method spec is a string"):
        methods.create(spec)


def test_binary_descriptors_still_match():
    rng = np.random.default_rng(2)
    a = rng.integers(0, 256, (40, 32), dtype=np.uint8)
    assert len(matching.create("mnn")(_feats(a), _feats(a.copy()))) == 40


@pytest.mark.parametrize(
    "spec, message",
    [
        ("lburst:", "nothing after 'lburst:'"),
        ("merge+lburst: ,top_k=5", "nothing after 'lburst:'"),
        ("sift,max_features=100,max_features=200", "option 'max_features' given twice"),
    ],
)
def test_an_empty_checkpoint_or_a_repeated_option_is_refused(spec, message):
    with pytest.raises(ValueError, match=message):
        methods.create(spec)


def test_a_repeated_matcher_option_is_refused():
    with pytest.raises(ValueError, match="option 'ratio' given twice"):
        matching.create("ratio,ratio=0.8,ratio=0.9")
