"""``lburst extract``: features of bursts on disk, resuming, bad bursts, reduced precision."""

import cv2
import numpy as np
import skimage.data

from lburst.cli import main
from lburst.io import save_burst
from lburst.simulate import simulate_burst


def _burst_folder(tmp_path):
    image = cv2.resize(skimage.data.astronaut(), (192, 144), interpolation=cv2.INTER_AREA)
    folder = tmp_path / "burst_01"
    save_burst(simulate_burst(image, 5, motion=(1.0, 0.5), rng=0), folder)
    return folder


def test_extract_writes_features_resumes_and_reports_bad_bursts(tmp_path, capsys):
    good, bad = _burst_folder(tmp_path), tmp_path / "missing"
    out = tmp_path / "features"
    assert main(["extract", str(good), str(bad), "--out", str(out), "--top-k", "300", "--h5"]) == 1
    captured = capsys.readouterr()
    assert "1 bursts extracted" in captured.out and "missing" in captured.err
    feats = np.load(out / "burst_01.npz")
    assert 0 < len(feats["keypoints"]) <= 300
    assert np.all(feats["keypoints"][:, 0] <= 191) and np.all(feats["keypoints"][:, 1] <= 143)
    assert (out / "features.h5").is_file()
    assert main(["extract", str(good), "--out", str(out)]) == 0  # done already: skipped
    assert "0 bursts extracted" in capsys.readouterr().out


def test_extract_in_bf16_finds_nearly_the_fp32_keypoints(tmp_path):
    good = _burst_folder(tmp_path)
    for precision in ("fp32", "bf16"):
        assert main(["extract", str(good), "--out", str(tmp_path / precision), "--precision", precision]) == 0
    fp32, bf16 = (np.load(tmp_path / p / "burst_01.npz")["keypoints"][:, :2] for p in ("fp32", "bf16"))
    dist = np.linalg.norm(bf16[:, None] - fp32[None], axis=-1).min(axis=1)
    assert len(bf16) > 0.9 * len(fp32) and np.mean(dist <= 1) > 0.9
    assert not np.array_equal(bf16, fp32)  # the option reached the network
