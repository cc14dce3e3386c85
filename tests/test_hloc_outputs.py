"""hloc's files of a reconstruction: ``matches.h5`` holds each match's real score, not 1."""

from __future__ import annotations

import h5py
import numpy as np

from lburst.matching import create
from lburst.sfm.outputs import write_hloc


def features(rng, descriptors: np.ndarray) -> dict:
    k = len(descriptors)
    return {
        "keypoints": rng.uniform(0, 60, (k, 2)).astype(np.float32),
        "scales": np.ones(k, np.float32),
        "scores": np.ones(k, np.float32),
        "descriptors": descriptors,
        "image_size": np.array([64, 48], np.int64),
    }


def test_matches_h5_holds_the_matchers_scores(tmp_path):
    rng = np.random.default_rng(0)
    b = rng.normal(size=(40, 16)).astype(np.float32)
    a = b[:30] + 0.4 * rng.normal(size=(30, 16)).astype(np.float32)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    fa, fb = features(rng, a), features(rng, b)
    matches, scores = create("mnn").match(fa, fb)
    assert len(matches) > 10 and len(np.unique(scores)) > 1
    write_hloc(tmp_path, ["a", "b"], [fa, fb], [(48, 64)] * 2, [(0, 1)], [matches], [scores])
    with h5py.File(tmp_path / "matches.h5") as f:
        m0, s0 = f["a.png/b.png/matches0"][()], f["a.png/b.png/matching_scores0"][()]
    np.testing.assert_array_equal(m0[matches[:, 0]], matches[:, 1])
    np.testing.assert_allclose(s0[matches[:, 0]], scores, atol=1e-3)  # float16, as hloc
    assert (s0[m0 < 0] == 0).all()
    write_hloc(tmp_path, ["a", "b"], [fa, fb], [(48, 64)] * 2, [(0, 1)], [matches])  # scores from the descriptors
    with h5py.File(tmp_path / "matches.h5") as f:
        np.testing.assert_allclose(f["a.png/b.png/matching_scores0"][()][matches[:, 0]], scores, atol=1e-3)
