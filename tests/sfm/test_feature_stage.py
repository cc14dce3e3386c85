"""The features stage's progress: a bar with a total where the bursts are known in advance
(single bursts, a scene), counting the bursts it computes."""

from __future__ import annotations

import numpy as np
import pytest

from lburst.burst.io import save_burst
from lburst.cli import main
from lburst.cluster.runner import Runner
from lburst.sfm.inputs import open_input
from lburst.sfm.options import ReconstructOptions


@pytest.fixture
def totals(monkeypatch) -> list:
    """The ``total`` of every features bar (``Runner.map``) of the test."""
    seen, original = [], Runner.map

    def map_(self, function, jobs, desc, progress=True, total=None, **bar):
        seen.append(total)
        return original(self, function, jobs, desc, progress, total, **bar)

    monkeypatch.setattr(Runner, "map", map_)
    return seen


def _scene(root, n=3):
    rng = np.random.default_rng(0)
    for i in range(n):
        save_burst(rng.integers(0, 255, (3, 40, 56, 3), dtype=np.uint8), root / f"b{i}")
    return root


def test_extract_of_bursts_has_a_bar_with_their_count(tmp_path, totals):
    bursts = [str(p) for p in sorted(_scene(tmp_path / "scene").iterdir())]
    assert main(["extract", *bursts, "--out", str(tmp_path / "out"), "--method", "sift"]) == 0
    save_burst(np.zeros((3, 40, 56, 3), np.uint8), tmp_path / "scene" / "b1")  # one burst changed
    assert main(["extract", *bursts, "--out", str(tmp_path / "out"), "--method", "sift"]) == 0
    assert totals == [3, 1]  # the bursts to compute, the stored ones left out


def test_the_features_of_a_scene_have_a_bar_with_its_count(tmp_path, totals):
    scene = _scene(tmp_path / "scene", 4)
    open_input(scene).read("sift", tmp_path / "out", ReconstructOptions(progress=False))
    assert totals == [4]
