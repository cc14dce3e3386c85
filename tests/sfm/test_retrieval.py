"""Loop-closure candidates by retrieval (lburst.sfm.retrieval): VLAD vectors of each image's
descriptors, and for each image its most similar images beyond the sequential neighbours."""

import numpy as np
import pytest

from lburst.sfm.retrieval import retrieval_pairs, vlad


def places(n_places: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """``n_places`` sets of 6 descriptor centres each: what a place looks like."""
    return rng.normal(size=(n_places, 6, dim)).astype(np.float32)


def view(place: np.ndarray, rng: np.random.Generator, count: int = 80) -> np.ndarray:
    """Descriptors of one image of ``place``: its centres with noise, L2-normalised."""
    d = place[rng.integers(0, len(place), count)] + 0.3 * rng.normal(size=(count, place.shape[1]))
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


def test_the_image_that_revisits_a_place_is_retrieved_and_its_neighbours_are_not():
    """A trajectory of 8 images over 7 places, the last back at the first place: (0, 7) is the
    one pair whose images look alike, and it is every image's top candidate where it can be."""
    rng = np.random.default_rng(0)
    at = places(7, 32, rng)
    images = [view(at[i], rng) for i in range(7)] + [view(at[0], rng)]
    g = vlad(images, words=8)
    assert g.shape == (8, 8 * 32)
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-5)
    sim = g @ g.T
    assert sim[0, 7] > 0.5 > np.max(sim[0, 1:7])  # the same place again, every other place unlike it
    pairs = retrieval_pairs(g, num=1, exclude=1)
    assert (0, 7) in pairs
    assert all(j - i > 1 for i, j in pairs) and pairs == sorted(set(pairs))
    top = {i: max((j for j in range(8) if abs(i - j) > 1), key=lambda j: sim[i, j]) for i in (0, 7)}
    assert top == {0: 7, 7: 0}


@pytest.mark.parametrize("exclude", [0, 1, 2, 3])
def test_no_candidate_is_a_sequential_neighbour_and_each_image_has_num_of_them(exclude):
    rng = np.random.default_rng(1)
    g = rng.normal(size=(9, 16)).astype(np.float32)
    pairs = retrieval_pairs(g, num=2, exclude=exclude)
    assert all(j - i > exclude for i, j in pairs)
    for i in range(9):  # every image keeps its 2 best images beyond the excluded ones
        allowed = [j for j in range(9) if abs(i - j) > exclude]
        best = sorted(allowed, key=lambda j: -float(g[i] @ g[j]))[:2]
        assert all((min(i, j), max(i, j)) in pairs for j in best)
    assert len({p for p in pairs}) == len(pairs)


def test_no_pairs_without_candidates():
    g = np.eye(4, dtype=np.float32)
    assert retrieval_pairs(g, num=0, exclude=0) == []
    assert retrieval_pairs(g, num=3, exclude=3) == []  # every other image is a sequential neighbour


def test_vlad_is_seeded_and_reads_binary_descriptors_and_empty_images():
    rng = np.random.default_rng(2)
    binary = [rng.integers(0, 256, (60, 4), dtype=np.uint8) for _ in range(3)] + [np.zeros((0, 4), np.uint8)]
    a, b = vlad(binary, words=4, seed=5), vlad(binary, words=4, seed=5)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (4, 4 * 32)  # 4 bytes: 32 bits per descriptor
    assert not a[3].any()  # an image without descriptors has no vector
    np.testing.assert_allclose(np.linalg.norm(a[:3], axis=1), 1.0, atol=1e-5)
    assert not vlad([np.zeros((2, 8), np.float32)], words=4).any()  # fewer descriptors than words


def test_vlad_sums_the_residuals_to_each_words_and_square_roots_and_normalises_them():
    """Two words, at e1 and -e1 (the means of the images' descriptors, which come in mirrored
    pairs).  An image on a word has no residual.  One whose descriptors lie 0.2 e2 + 0.05 e3 beside
    e1 (10 of them) and 0.4 e4 beside -e1 (10) sums residuals (0, 2, 0.5, 0) and (0, 0, 0, 4):
    signed square roots (0, 1.41, 0.71, 0) and (0, 0, 0, 2), each block to unit length, the whole
    vector to unit length."""
    e1, e2, e3, e4 = np.eye(4, dtype=np.float32)
    ten = lambda v: np.tile(v, (10, 1))  # noqa: E731
    on_word, other_word = ten(e1), ten(-e1)
    image = np.concatenate([ten(e1 + 0.2 * e2 + 0.05 * e3), ten(-e1 + 0.4 * e4)])
    mirror = np.concatenate([ten(e1 - 0.2 * e2 - 0.05 * e3), ten(-e1 - 0.4 * e4)])
    g = vlad([on_word, other_word, image, mirror], words=2).reshape(4, 2, 4)
    first = int(np.argmax(np.abs(g[2, :, 1])))  # the block of the word at e1
    assert not g[0].any() and not g[1].any()
    expected = np.zeros((2, 4), np.float32)
    expected[first] = np.array([0, np.sqrt(2), np.sqrt(0.5), 0]) / np.sqrt(2.5)
    expected[1 - first] = e4
    np.testing.assert_allclose(g[2], expected / np.sqrt(2), atol=1e-6)
    np.testing.assert_allclose(g[3], -expected / np.sqrt(2), atol=1e-6)
