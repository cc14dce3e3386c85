"""``lburst extract``: features of bursts on disk, resuming, bad bursts, reduced precision."""

import cv2
import numpy as np
import pytest
import skimage.data

from lburst.burst.io import save_burst
from lburst.cli import main
from lburst.simulate import simulate_burst


def _burst_folder(tmp_path):
    image = cv2.resize(skimage.data.astronaut(), (192, 144), interpolation=cv2.INTER_AREA)
    folder = tmp_path / "burst_01"
    save_burst(simulate_burst(image, 5, motion=(1.0, 0.5), rng=0), folder)
    return folder


def test_extract_writes_features_resumes_and_reports_bad_bursts(tmp_path, capsys):
    good, bad = _burst_folder(tmp_path), tmp_path / "broken"
    bad.mkdir()
    (bad / "0.png").write_bytes(b"not a PNG")
    out = tmp_path / "features"
    assert main(["extract", str(good), str(bad), "--out", str(out), "--top-k", "300", "--h5"]) == 1
    captured = capsys.readouterr()
    assert "1 bursts extracted" in captured.out and "broken" in captured.err
    feats = np.load(out / "burst_01.npz")
    assert 0 < len(feats["keypoints"]) <= 300
    assert np.all(feats["keypoints"][:, 0] <= 191) and np.all(feats["keypoints"][:, 1] <= 143)
    assert (out / "features.h5").is_file()
    assert main(["extract", str(good), "--out", str(out), "--top-k", "300"]) == 0  # done already: skipped
    assert "0 bursts extracted" in capsys.readouterr().out
    assert main(["extract", str(good), "--out", str(out), "--top-k", "100"]) == 0  # other options: recomputed
    assert "1 bursts extracted" in capsys.readouterr().out and len(np.load(out / "burst_01.npz")["keypoints"]) <= 100


def test_extract_in_bf16_finds_nearly_the_fp32_keypoints(tmp_path):
    good = _burst_folder(tmp_path)
    for precision in ("fp32", "bf16"):
        assert main(["extract", str(good), "--out", str(tmp_path / precision), "--precision", precision]) == 0
    fp32, bf16 = (np.load(tmp_path / p / "burst_01.npz")["keypoints"][:, :2] for p in ("fp32", "bf16"))
    dist = np.linalg.norm(bf16[:, None] - fp32[None], axis=-1).min(axis=1)
    assert len(bf16) > 0.9 * len(fp32) and np.mean(dist <= 1) > 0.9
    assert not np.array_equal(bf16, fp32)  # the option reached the network


def _small_burst(folder, seed=0, n=3):
    """A 3-frame burst of a 160x120 crop of a photo (``seed`` moves the crop)."""
    crop = skimage.data.astronaut()[40 * seed : 40 * seed + 240, 100:420]
    image = cv2.resize(crop, (160, 120), interpolation=cv2.INTER_AREA)
    save_burst(np.stack([image] * n), folder)
    return folder


def test_two_bursts_with_one_name_are_not_taken_for_done(tmp_path, capsys):
    a, b = _small_burst(tmp_path / "sA" / "b0", 0), _small_burst(tmp_path / "sB" / "b0", 1)
    out = tmp_path / "out"
    assert main(["extract", str(a), str(b), "--out", str(out), "--method", "sift"]) == 1
    err = capsys.readouterr().err
    assert "same output name 'b0'" in err and str(b) in err
    first = np.load(out / "b0.npz")["keypoints"]
    assert main(["extract", str(b), "--out", str(out), "--method", "sift"]) == 1  # a later run: refused too
    assert "holds the features of another burst" in capsys.readouterr().err
    np.testing.assert_array_equal(np.load(out / "b0.npz")["keypoints"], first)


def test_another_method_or_changed_frames_are_computed_again(tmp_path, capsys):
    burst, out = _small_burst(tmp_path / "b0"), tmp_path / "out"
    assert main(["extract", str(burst), "--out", str(out), "--method", "sift"]) == 0
    sift = np.load(out / "b0.npz")["descriptors"]
    assert main(["extract", str(burst), "--out", str(out), "--method", "orb"]) == 0
    assert "1 bursts extracted" in capsys.readouterr().out
    assert np.load(out / "b0.npz")["descriptors"].dtype == np.uint8 != sift.dtype
    _small_burst(burst, seed=5)  # the same burst, new frames
    before = np.load(out / "b0.npz")["keypoints"]
    assert main(["extract", str(burst), "--out", str(out), "--method", "orb"]) == 0
    assert "1 bursts extracted" in capsys.readouterr().out
    assert not np.array_equal(np.load(out / "b0.npz")["keypoints"], before)


def test_features_h5_holds_every_finished_burst(tmp_path):
    import h5py

    bursts = [str(_small_burst(tmp_path / f"b{i}", i)) for i in range(2)]
    out = tmp_path / "out"
    assert main(["extract", bursts[0], "--out", str(out), "--method", "sift"]) == 0
    assert main(["extract", *bursts, "--out", str(out), "--method", "sift", "--h5"]) == 0  # --h5 added later
    with h5py.File(out / "features.h5") as f:
        assert sorted(f) == ["b0.png", "b1.png"]  # named after the images in out/images
        np.testing.assert_array_equal(f["b0.png/keypoints"][()], np.load(out / "b0.npz")["keypoints"][:, :2])
    assert sorted(p.name for p in (out / "images").iterdir()) == ["b0.png", "b1.png"]
    (out / "features.h5").write_bytes(b"corrupt")
    assert main(["extract", *bursts, "--out", str(out), "--method", "sift", "--h5"]) == 0
    with h5py.File(out / "features.h5") as f:
        assert sorted(f) == ["b0.png", "b1.png"]


def test_a_second_h5_run_keeps_the_first_runs_bursts(tmp_path):
    import h5py

    bursts = [str(_small_burst(tmp_path / f"b{i}", i)) for i in range(2)]
    out = tmp_path / "out"
    assert main(["extract", bursts[0], "--out", str(out), "--method", "sift", "--h5"]) == 0
    np.savez(out / "foreign.npz", keypoints=np.zeros((3, 2)))  # not lburst's: left out
    assert main(["extract", bursts[1], "--out", str(out), "--method", "sift", "--h5"]) == 0
    with h5py.File(out / "features.h5") as f:
        assert sorted(f) == ["b0.png", "b1.png"]
        np.testing.assert_array_equal(f["b0.png/keypoints"][()], np.load(out / "b0.npz")["keypoints"][:, :2])


def test_features_h5_is_written_when_no_burst_finished(tmp_path, capsys):
    import h5py

    out, broken = tmp_path / "out", tmp_path / "broken"
    broken.mkdir()
    (broken / "0.png").write_bytes(b"not a PNG")
    assert main(["extract", str(broken), "--out", str(out), "--method", "sift", "--h5"]) == 1
    err = capsys.readouterr().err
    assert "broken" in err and "features.h5" not in err
    with h5py.File(out / "features.h5") as f:
        assert list(f) == []
    assert [p.name for p in out.iterdir()] == ["features.h5"]  # no temporary left


def test_extract_dot_names_the_output_after_the_folder(tmp_path, monkeypatch):
    burst = _small_burst(tmp_path / "here")
    monkeypatch.chdir(burst)
    assert main(["extract", ".", "--out", str(tmp_path / "out"), "--method", "sift"]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["here.npz", "images"]
    assert [p.name for p in (tmp_path / "out" / "images").iterdir()] == ["here.png"]


def test_a_foreign_npz_is_not_overwritten_and_a_nan_one_is_recomputed(tmp_path, capsys):
    burst = str(_small_burst(tmp_path / "b0", 0))
    out = tmp_path / "out"
    out.mkdir()
    np.savez(out / "b0.npz", mine=np.arange(3))
    assert main(["extract", burst, "--out", str(out), "--method", "sift"]) == 1
    assert "was not written by lburst" in capsys.readouterr().err
    assert list(np.load(out / "b0.npz").files) == ["mine"]
    assert main(["extract", burst, "--out", str(out), "--method", "sift", "--overwrite"]) == 0
    with np.load(out / "b0.npz") as data:
        poisoned = {k: data[k] for k in data.files}
    poisoned["descriptors"] = np.full_like(poisoned["descriptors"], np.nan)
    np.savez(out / "b0.npz", **poisoned)
    assert main(["extract", burst, "--out", str(out), "--method", "sift"]) == 0
    assert "1 bursts extracted" in capsys.readouterr().out
    assert np.isfinite(np.load(out / "b0.npz")["descriptors"]).all()


def test_the_spec_top_k_is_kept_and_an_explicit_top_k_that_disagrees_is_refused(tmp_path, capsys):
    burst = _small_burst(tmp_path / "b0", n=5)
    out = tmp_path / "out"
    assert main(["extract", str(burst), "--out", str(out), "--method", "lburst,top_k=7", "--threads", "1"]) == 0
    assert len(np.load(out / "b0.npz")["keypoints"]) == 7  # not the --top-k default
    capsys.readouterr()
    assert main(["extract", str(burst), "--out", str(out), "--method", "lburst,top_k=7", "--top-k", "300"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lburst extract: error: --top-k 300 and top_k=7") and err.count("\n") == 1
    assert main(["extract", str(burst), "--out", str(out), "--method", "lburst,top_k=7", "--top-k", "7"]) == 0
    assert "0 bursts extracted" in capsys.readouterr().out  # the same features: already done
    assert main(["extract", str(burst), "--out", str(out), "--top-k", "5", "--threads", "1"]) == 0
    assert len(np.load(out / "b0.npz")["keypoints"]) == 5


@pytest.mark.parametrize("top_k", ["abc", "0", "-3", "1.5"])
@pytest.mark.parametrize("command", [["extract"], ["extract", "--cluster", "local:2"], ["reconstruct"]])
def test_a_bad_top_k_in_the_spec_is_one_line_before_any_work(tmp_path, capsys, top_k, command):
    burst, out = _small_burst(tmp_path / "b0"), tmp_path / "out"
    argv = [command[0], str(burst), "--out", str(out), "--method", f"merge+lburst,top_k={top_k}", *command[1:]]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"lburst {command[0]}: error: ") and "top_k" in err and err.count("\n") == 1
    assert not out.exists()


def test_a_missing_input_is_refused_before_any_work(tmp_path, capsys):
    good, out = _small_burst(tmp_path / "b0"), tmp_path / "out"
    assert main(["extract", str(good), str(tmp_path / "typo"), "--out", str(out), "--method", "sift"]) == 2
    assert capsys.readouterr().err == f"lburst extract: error: {tmp_path / 'typo'}: no such file or folder\n"
    assert not out.exists()  # no output folder, nothing extracted


def test_a_folder_of_more_frames_than_a_burst_says_how_to_cut_it_before_reading_them(tmp_path, capsys):
    frames = tmp_path / "recording"
    frames.mkdir()
    for i in range(120):
        (frames / f"f{i:03d}.png").write_bytes(b"")  # never read: the count alone tells
    assert main(["extract", str(frames), "--out", str(tmp_path / "out"), "--method", "sift"]) == 1
    err = capsys.readouterr().err
    assert "120 frames, more than a burst holds (99); a recording? --every K or --motion F cuts it" in err
