"""The command line on recordings: simulate flight --video/--dng, extract and show on them."""

import json

import numpy as np
import pytest

from lburst.cli import main
from lburst.io import read_features_npz

pytest.importorskip("av")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli")
    assert main(["simulate", "flight", "--video", str(out / "f.mp4"), "--dng", str(out / "f_dng"), "--bursts", "2",
                 "--size", "128x96", "--noise", "lowlight:night", "--loop"]) == 0
    return out


def test_simulate_writes_video_dng_and_ground_truth(recordings):
    meta = json.loads((recordings / "f.meta.json").read_text())
    assert meta["fps"] == 20 and meta["frames"] == 33 and meta["night_flight"]["turn_deg"] == 380
    assert len((recordings / "f.gt.txt").read_text().splitlines()) == 33 + 2  # two comment lines
    assert len(list((recordings / "f_dng").glob("frame_*.dng"))) == 33
    assert (recordings / "f_dng" / "gt.txt").is_file() and (recordings / "f_dng" / "meta.json").is_file()


def test_extract_and_show_take_recordings(recordings, tmp_path, capsys):
    out = tmp_path / "feats"
    assert main(["extract", str(recordings / "f.mp4"), str(recordings / "f_dng"), "--every", "16", "--method", "orb",
                 "--out", str(out)]) == 0
    for name in ("f", "f_dng"):
        files = sorted(p.name for p in (out / name).glob("*.npz"))
        assert files == ["f000000_t0.000s.npz", "f000016_t0.800s.npz", "f000032_t1.600s.npz"]
        assert len(read_features_npz(out / name / files[1])["keypoints"]) > 0
    png = tmp_path / "show.png"
    assert main(["show", str(recordings / "f_dng"), "--frame", "16", "--out", str(png)]) == 0
    assert png.stat().st_size > 0


def test_extract_reports_a_bad_recording_by_name(tmp_path, capsys):
    bad = tmp_path / "zero.mp4"
    bad.write_bytes(b"")
    assert main(["extract", str(bad), "--every", "4", "--method", "orb", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "zero.mp4: empty file (zero-length video)" in err


def test_raw_gain_matters_on_dark_dng(recordings):
    from lburst.raw import Normalisation
    from lburst.sources import RecordingOptions, open_recording

    auto = next(open_recording(recordings / "f_dng", RecordingOptions(burst=3)).bursts())[1]
    linear = next(open_recording(recordings / "f_dng", RecordingOptions(
        burst=3, normalisation=Normalisation(gain="none"))).bursts())[1]
    assert linear.dtype == np.uint16 and linear.mean() / 65535 < 0.05  # a dark RAW frame
    assert auto.dtype == np.uint8 and 40 < auto.mean() < 200
