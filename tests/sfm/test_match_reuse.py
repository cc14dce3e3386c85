"""A run given a finished run's folder (``matches``) reads the matches of the pairs that run
matched with the same matcher between the same features, and matches the rest: the same
matches, so the same model, without matching again."""

import cv2
import h5py
import numpy as np
import pytest

from lburst.sfm import match as match_stage
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.reconstruct import reconstruct_scene


@pytest.fixture
def scene(tmp_path):
    """Three 160x120 photos of blurred noise (seeded): texture for SIFT."""
    folder = tmp_path / "scene"
    folder.mkdir()
    for i in range(3):
        image = np.random.default_rng(i).integers(0, 256, size=(120, 160, 3), dtype=np.uint8)
        cv2.imwrite(str(folder / f"{i}.png"), cv2.GaussianBlur(image, (0, 0), 1.0))
    return folder


@pytest.fixture
def matched_pairs(monkeypatch):
    """The pairs each call of the matching stage matches (a list per call)."""
    calls = []
    original = match_stage.match_pairs_with_scores

    def counting(features, pairs, *args, **kwargs):
        calls.append(list(pairs))
        return original(features, pairs, *args, **kwargs)

    monkeypatch.setattr(match_stage, "match_pairs_with_scores", counting)
    return calls


def read_matches(run):
    with h5py.File(run / "matches.h5", "r") as f:
        return {f"{a}/{b}": (f[a][b]["matches0"][()], f[a][b]["matching_scores0"][()]) for a in f for b in f[a]}


def options(**kw):
    return ReconstructOptions(progress=False, num_threads=1, pairs="exhaustive", **kw)


def test_a_second_run_reads_the_first_runs_matches(scene, tmp_path, matched_pairs):
    first = reconstruct_scene(scene, "sift", tmp_path / "first", options())
    assert matched_pairs == [[(0, 1), (0, 2), (1, 2)]]
    again = reconstruct_scene(
        scene, "sift", tmp_path / "again", options(features=tmp_path / "first" / "features", matches=tmp_path / "first")
    )
    assert matched_pairs[1:] == [[]]  # every pair read, none matched
    stored, read = read_matches(tmp_path / "first"), read_matches(tmp_path / "again")
    assert stored.keys() == read.keys()
    for pair in stored:
        np.testing.assert_array_equal(stored[pair][0], read[pair][0])
        np.testing.assert_array_equal(stored[pair][1], read[pair][1])
    assert again.metrics["inliers_per_image"] == first.metrics["inliers_per_image"]
    assert again.registered == first.registered


def test_matches_of_another_matcher_or_other_features_are_not_read(scene, tmp_path, matched_pairs):
    reconstruct_scene(scene, "sift", tmp_path / "first", options())
    reconstruct_scene(scene, "sift", tmp_path / "ratio", options(matcher="ratio", matches=tmp_path / "first"))
    assert len(matched_pairs[1]) == 3  # another matcher: matched again
    reconstruct_scene(scene, "sift,root=true", tmp_path / "root", options(matches=tmp_path / "first"))
    assert len(matched_pairs[2]) == 3  # other features: matched again
    reconstruct_scene(scene, "sift", tmp_path / "missing", options(matches=tmp_path / "nothing_here"))
    assert len(matched_pairs[3]) == 3
