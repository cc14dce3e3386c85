"""scripts/drop_sources.py: each entry of the swapped batch gets one burst's keypoints and the
other's descriptor map."""

from __future__ import annotations

import numpy as np
import pytest

from lburst.model.extractor import LBurst


def test_keypoints_come_from_the_detector_burst_and_descriptors_from_the_other(load_script, monkeypatch):
    script = load_script("drop_sources")
    model = LBurst.pretrained("lburst-b5", device="cpu", runtime="torch")  # trained: descriptors follow the image
    rng = np.random.default_rng(0)
    clean = rng.integers(0, 256, (5, 64, 96, 3), dtype=np.uint8)
    noisy = rng.integers(0, 256, clean.shape, dtype=np.uint8)  # any other burst of the same size
    options = dict(rel_thr=0, rep_thr=0, top_k=300, min_size=64, max_size=96)
    plain = {"clean": model.extract(clean, **options), "noisy": model.extract(noisy, **options)}
    monkeypatch.setattr(LBurst, "_fast_level", script._swapped_level)
    swapped = model.extract_batch([clean, clean, noisy, noisy], **options)
    for (detector, descriptors), found in zip(script.COMBOS, swapped):
        np.testing.assert_allclose(found["keypoints"], plain[detector]["keypoints"], atol=1e-5)
        np.testing.assert_allclose(found["scores"], plain[detector]["scores"], atol=1e-5)
        if descriptors == detector:
            np.testing.assert_allclose(found["descriptors"], plain[detector]["descriptors"], atol=1e-5)
        else:  # the same points, described by the other burst's map
            assert not np.allclose(found["descriptors"], plain[detector]["descriptors"], atol=1e-2)


def test_a_method_that_is_not_a_burst_network_stops_in_one_line(load_script, monkeypatch, tmp_path, capsys):
    script = load_script("drop_sources")
    monkeypatch.setattr(LBurst, "_fast_level", LBurst._fast_level)  # main() swaps it; undo after the test
    argv = ["drop_sources.py", str(tmp_path), "--methods", "lburst,rotations=2", "--out", str(tmp_path / "a.json")]
    monkeypatch.setattr("sys.argv", argv)
    with pytest.raises(SystemExit) as exit_:
        script.main()
    assert exit_.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "drop_sources.py: 'lburst,rotations=2' is not a burst network at one rotation without spread"
    ]
    assert not (tmp_path / "a.json").exists()
