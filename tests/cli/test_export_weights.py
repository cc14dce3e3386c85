"""lburst export weights: a run's checkpoint becomes weights that load and extract as the run's network."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from lburst import LBurst
from lburst.cli import main
from lburst.model.lite import LiteConfig, LiteNet
from lburst.model.network import checkpoint_dict, write_checkpoint


@pytest.fixture
def run(tmp_path):
    """A training run's folder: a snapshot in the published layout and the run's config.json."""
    torch.manual_seed(3)
    net = LiteNet(LiteConfig(frames=5)).eval()
    folder = tmp_path / "run"
    (folder / "snapshots").mkdir(parents=True)
    (folder / "config.json").write_text(json.dumps({"frames": 5, "seed": 60}))
    write_checkpoint({**checkpoint_dict(net), "step": 40, "meta": {"input": "aligned"}}, folder / "snapshots" / "s.pt")
    return folder, net


def test_a_snapshot_becomes_weights_with_its_step_config_and_given_meta(run, tmp_path, capsys):
    folder, net = run
    out = tmp_path / "w.pt"
    assert (
        main(["export", "weights", str(folder / "snapshots" / "s.pt"), "--out", str(out), "--meta", "note=x", "k=2"])
        == 0
    )
    assert str(out) in capsys.readouterr().out
    saved = torch.load(out, map_location="cpu", weights_only=True)
    assert saved["meta"] == {"input": "aligned", "step": 40, "config": {"frames": 5, "seed": 60}, "note": "x", "k": 2}
    burst = np.random.default_rng(0).integers(0, 256, (5, 96, 128, 3), dtype=np.uint8)
    exported = LBurst.from_checkpoint(out, device="cpu", runtime="torch").extract(burst, top_k=50)
    direct = LBurst(net, device="cpu", align=True).extract(burst, top_k=50)
    for key in ("keypoints", "descriptors", "scores"):
        np.testing.assert_array_equal(exported[key], direct[key])


def test_a_missing_checkpoint_or_a_bad_meta_is_one_line(tmp_path, capsys):
    assert main(["export", "weights", str(tmp_path / "none.pt"), "--out", str(tmp_path / "w.pt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "none.pt: no such checkpoint" in err
    assert main(["export", "weights", str(tmp_path / "none.pt"), "--out", "w.pt", "--meta", "novalue"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "lburst export weights: error: argument --meta: expected KEY=VALUE, got 'novalue'"
