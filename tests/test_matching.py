"""Matcher registry: mutual nearest neighbours (unchanged results), the ratio test, and spec checking."""

from __future__ import annotations

import numpy as np
import pytest

from lburst.cli.options import matcher_spec
from lburst.match import mutual_nearest_neighbours
from lburst.matching import available, create


def feats(desc: np.ndarray) -> dict:
    k = len(desc)
    return {
        "keypoints": np.zeros((k, 2), np.float32),
        "scales": np.ones(k, np.float32),
        "scores": np.ones(k, np.float32),
        "descriptors": desc,
    }


def unit(rng, n, d=16):
    x = rng.normal(size=(n, d)).astype(np.float32)
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def reference_ratio(a: np.ndarray, b: np.ndarray, ratio: float, mutual: bool) -> set[tuple[int, int]]:
    dist = np.linalg.norm(a[:, None] - b[None], axis=2)
    order = np.argsort(dist, axis=1)
    out = set()
    for i in range(len(a)):
        j, j2 = order[i, 0], order[i, 1]
        if dist[i, j] <= ratio * dist[i, j2] and (not mutual or dist[:, j].argmin() == i):
            out.add((i, int(j)))
    return out


def test_registry_lists_the_matchers_with_their_options():
    names = {m.name: m for m in available()}
    assert {"mnn", "ratio"} <= set(names)
    assert names["ratio"].summary


def test_mnn_is_the_mutual_nearest_neighbours_used_so_far():
    rng = np.random.default_rng(0)
    a, b = unit(rng, 300), unit(rng, 250)
    expected = mutual_nearest_neighbours(a, b)
    got = create("mnn")(feats(a), feats(b))
    np.testing.assert_array_equal(got, expected)
    assert create().name == "mnn"


@pytest.mark.parametrize("mutual", [True, False])
def test_ratio_test_matches_a_brute_force_reference(mutual):
    rng = np.random.default_rng(1)
    b = unit(rng, 200)
    a = b[rng.permutation(200)[:150]] + 0.05 * unit(rng, 150)  # noisy copies: clear matches
    a = np.concatenate([a, unit(rng, 50)]).astype(np.float32)  # and distractors
    got = create(f"ratio,ratio=0.8,mutual={str(mutual).lower()}")(feats(a), feats(b))
    assert got.dtype == np.int64 and got.shape[1] == 2
    assert set(map(tuple, got.tolist())) == reference_ratio(a, b, 0.8, mutual)
    assert len(got) >= 140  # the noisy copies pass the ratio test


def test_ratio_test_rejects_ambiguous_matches_that_mnn_keeps():
    b = np.array([[1, 0, 0], [0.99, 0.141, 0], [0, 0, 1]], np.float32)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    a = np.array([[1, 0.07, 0], [0, 0.05, 1]], np.float32)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    mnn = {tuple(m) for m in create("mnn")(feats(a), feats(b)).tolist()}
    ratio = {tuple(m) for m in create("ratio")(feats(a), feats(b)).tolist()}
    assert (0, 0) in mnn and (1, 2) in mnn
    assert ratio == {(1, 2)}  # a[0] lies between b[0] and b[1]


def test_ratio_test_on_binary_descriptors_and_edge_cases():
    rng = np.random.default_rng(2)
    b = rng.integers(0, 256, (60, 32), dtype=np.uint8)
    a = b[:40].copy()
    a[:, 0] ^= 1  # one bit off: still far nearer than any other
    got = create("ratio")(feats(a), feats(b))
    assert {tuple(m) for m in got.tolist()} == {(i, i) for i in range(40)}
    empty = create("ratio")(feats(a[:0]), feats(b))
    assert empty.shape == (0, 2)
    one = create("ratio")(feats(a[:3]), feats(b[:1]))  # no second neighbour: nearest only, mutual
    assert one.shape == (1, 2)
    with pytest.raises(ValueError, match="descriptor types differ"):
        create("ratio")(feats(a), feats(b.astype(np.float32)))


def test_bad_specs_name_the_valid_options():
    with pytest.raises(ValueError, match=r"unknown matcher 'nope'; available: mnn \(max_distance"):
        create("nope")
    with pytest.raises(
        ValueError,
        match=r"unknown options for matcher 'ratio': foo; valid: ratio: float = 0.8, "
        r"mutual: bool = true",
    ):
        create("ratio,foo=1")
    with pytest.raises(ValueError, match=r"option ratio of matcher 'ratio': expected float, got 'x'"):
        create("ratio,ratio=x")
    with pytest.raises(ValueError, match=r"ratio must be in \(0, 1\]"):
        create("ratio,ratio=1.5")
    with pytest.raises(ValueError, match="expected KEY=VALUE"):
        create("ratio,0.8")
    assert matcher_spec("mnn,max_distance=1.2") == "mnn,max_distance=1.2"


@pytest.mark.parametrize(
    "words",
    [
        ["reconstruct", "scene", "--out", "o"],
        ["bench", "homography", "data"],
        ["bench", "reconstruction", "scene", "--out", "o"],
        ["demo"],
    ],
)
def test_commands_check_the_matcher_before_they_start(words, capsys):
    from lburst.cli import main

    assert main([*words, "--matcher", "ratio,ratio=3"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        f"lburst {' '.join(words[: 2 if words[0] == 'bench' else 1])}: error:"
    )
    assert "argument --matcher: matcher 'ratio': ratio must be in (0, 1]" in err


def noisy_copies(rng, n=200, kept=150, distractors=50, noise=0.05):
    """``a``: noisy copies of ``kept`` of ``b``'s descriptors, then distractors; ``b``: ``n`` unit vectors."""
    b = unit(rng, n)
    a = b[rng.permutation(n)[:kept]] + noise * unit(rng, kept)
    return np.concatenate([a, unit(rng, distractors)]).astype(np.float32), b


@pytest.mark.parametrize("ratio", [0.8, 0.95, 1.0])
def test_smnn_is_kornias_match_smnn(ratio):
    kornia = pytest.importorskip("kornia")
    import torch

    rng = np.random.default_rng(3)
    for noise in (0.05, 0.5, 1.0):  # clear matches, then ambiguous ones where the two directions differ
        a, b = noisy_copies(rng, noise=noise)
        _, expected = kornia.feature.match_smnn(torch.from_numpy(a), torch.from_numpy(b), ratio)
        got = create(f"smnn,ratio={ratio}")(feats(a), feats(b))
        np.testing.assert_array_equal(got, expected.numpy().reshape(-1, 2))
    one = create("smnn")(feats(a[:1]), feats(b))  # no second neighbour on one side: no match, as kornia
    assert one.shape == (0, 2) and len(kornia.feature.match_smnn(torch.from_numpy(a[:1]), torch.from_numpy(b))[1]) == 0


def test_ratio_tests_one_direction_where_smnn_tests_both():
    rng = np.random.default_rng(4)
    a, b = noisy_copies(rng, noise=0.8)
    ratio = {tuple(m) for m in create("ratio,ratio=0.9")(feats(a), feats(b)).tolist()}
    smnn = {tuple(m) for m in create("smnn,ratio=0.9")(feats(a), feats(b)).tolist()}
    assert smnn < ratio  # the reverse ratio test drops some of the mutual one-way matches
    assert create("smnn").options.ratio == 0.95  # kornia's default


@pytest.mark.parametrize("spec", ["mnn", "ratio", "smnn"])
def test_matchers_give_the_similarity_of_each_match(spec):
    from lburst.matching import match_with_scores

    rng = np.random.default_rng(5)
    a, b = noisy_copies(rng, noise=0.3)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    matcher = create(spec)
    matches, scores = matcher.match(feats(a), feats(b))
    np.testing.assert_array_equal(matches, matcher(feats(a), feats(b)))  # the plain call is unchanged
    assert scores.dtype == np.float32 and scores.shape == (len(matches),) and len(matches) > 50
    np.testing.assert_allclose(scores, (a[matches[:, 0]] * b[matches[:, 1]]).sum(1), atol=1e-6)
    assert (scores <= 1).all() and (scores >= -1).all()
    plain = lambda fa, fb: matcher(fa, fb)  # noqa: E731 - a matcher with no match method
    for found, expected in zip(match_with_scores(plain, feats(a), feats(b)), (matches, scores)):
        np.testing.assert_array_equal(found, expected)


def test_binary_scores_follow_the_hamming_distance():
    rng = np.random.default_rng(6)
    b = rng.integers(0, 256, (80, 32), dtype=np.uint8)
    a = b[:50].copy()
    a[:, :2] ^= np.array([1, 3], np.uint8)  # three bits off
    matches, scores = create("mnn").match(feats(a), feats(b))
    assert {tuple(m) for m in matches.tolist()} == {(i, i) for i in range(50)}
    np.testing.assert_allclose(scores, 1 - 2 * 3 / 256)


def argmin_mutual(a: np.ndarray, b: np.ndarray, max_distance=None) -> np.ndarray:
    """Mutual nearest neighbours by Hamming distance as lburst computed them before OpenCV:
    torch's first argmin each way."""
    import torch

    from lburst.match import _distances

    dist = _distances(torch.from_numpy(a), torch.from_numpy(b), True)
    nn_ab, nn_ba = dist.argmin(1), dist.argmin(0)
    ia = torch.arange(len(a))
    keep = nn_ba[nn_ab] == ia
    if max_distance is not None:
        keep &= dist[ia, nn_ab] <= max_distance
    return torch.stack([ia[keep], nn_ab[keep]], 1).numpy()


@pytest.mark.parametrize("width", [1, 4, 32])
def test_binary_mnn_by_opencv_equals_the_argmin_one_ties_included(width):
    from lburst.match import hamming_mutual_nearest_neighbours

    rng = np.random.default_rng(width)
    for _ in range(5):
        a = rng.integers(0, 256, (int(rng.integers(1, 200)), width), dtype=np.uint8)
        b = rng.integers(0, 256, (int(rng.integers(1, 200)), width), dtype=np.uint8)
        b[: len(b) // 2] = a[rng.integers(0, len(a), len(b) // 2)]  # exact duplicates: many ties
        for max_distance in (None, 2, 10):
            expected = argmin_mutual(a, b, max_distance)
            np.testing.assert_array_equal(hamming_mutual_nearest_neighbours(a, b, max_distance), expected)
            np.testing.assert_array_equal(mutual_nearest_neighbours(a, b, max_distance), expected)


@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_blockwise_nearest_neighbours_equal_the_full_distance_matrix_ties_included(chunk):
    """:func:`lburst.match.nearest_both_ways` against the argmin of every L2 distance: float
    descriptors of unequal norms, and exact duplicates whose first copy must win both ways."""
    import torch

    from lburst.match import nearest_both_ways

    rng = np.random.default_rng(3)
    a = rng.normal(size=(60, 8)).astype(np.float32) * rng.uniform(0.5, 2, (60, 1)).astype(np.float32)
    b = rng.normal(size=(45, 8)).astype(np.float32)
    b[[10, 30]] = a[5]  # a[5]'s two equally near copies in b: the first, 10
    a[[40, 50]] = b[3]  # b[3]'s two equally near copies in a: the first, 40
    dist = np.linalg.norm(a[:, None].astype(np.float64) - b[None], axis=2)
    nn_ab, nn_ba = nearest_both_ways(torch.from_numpy(a), torch.from_numpy(b), chunk)
    np.testing.assert_array_equal(nn_ab.numpy(), dist.argmin(1))
    np.testing.assert_array_equal(nn_ba.numpy(), dist.argmin(0))
    assert nn_ab[5] == 10 and nn_ba[3] == 40
    got = mutual_nearest_neighbours(a, b, max_distance=2.5)
    mutual = [[i, int(j)] for i, j in enumerate(dist.argmin(1)) if dist[:, j].argmin() == i and dist[i, j] <= 2.5]
    assert got.tolist() == mutual
