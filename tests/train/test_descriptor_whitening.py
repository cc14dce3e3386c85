"""Descriptor whitening: measured on photos, stored in the checkpoint, applied at extraction."""

import numpy as np
import pytest
import torch

from lburst.burst.io import write_image
from lburst.model.extractor import LBurst
from lburst.model.network import LBurstNet, NetConfig, load_checkpoint, save_checkpoint
from lburst.train.whitening import descriptor_statistics, whiten_checkpoint, whitening_matrix

ANY = {"rel_thr": 0.0, "rep_thr": 0.0}  # a random network: every local maximum is a keypoint


def _photo(rng, h=96, w=128):
    base = rng.integers(0, 255, (h // 8, w // 8, 3), dtype=np.uint8)
    return np.kron(base, np.ones((8, 8, 1), np.uint8))


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(0)
    return LBurstNet(NetConfig(frames=3)).eval()


@pytest.fixture(scope="module")
def burst():
    return np.random.default_rng(1).integers(0, 255, (3, 64, 80, 3), dtype=np.uint8)


def test_whitened_descriptors_are_w_times_the_centred_raw_ones_renormalised(net, burst):
    raw = LBurst(net).extract(burst, top_k=300, **ANY)
    assert len(raw["keypoints"]) > 100
    d = raw["descriptors"].astype(np.float64)
    mean = d.mean(0)
    matrix = whitening_matrix(np.cov(d.T))
    model = LBurst(net, descriptor_mean=mean, descriptor_whitening=matrix)
    out = model.extract(burst, top_k=300, whiten=True, **ANY)
    np.testing.assert_array_equal(out["keypoints"], raw["keypoints"])
    # asked for only: by default the same weights give the raw descriptors
    np.testing.assert_array_equal(model.extract(burst, top_k=300, **ANY)["descriptors"], raw["descriptors"])
    expected = (d - mean) @ matrix.T
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(out["descriptors"], expected, atol=1e-4)
    # whitened descriptors have no common component and spread over every direction
    assert np.linalg.norm(out["descriptors"].mean(0)) < 0.1 < np.linalg.norm(mean)
    spectrum = np.linalg.eigvalsh(np.cov(out["descriptors"].T))
    raw_spectrum = np.linalg.eigvalsh(np.cov(d.T))
    assert spectrum[-1] / spectrum.sum() < 0.5 * raw_spectrum[-1] / raw_spectrum.sum()
    dense_raw = LBurst(net).dense(burst)["descriptors"]
    dense = model.dense(burst, whiten=True)["descriptors"]
    e = (dense_raw - mean) @ matrix.T
    np.testing.assert_allclose(dense, e / np.linalg.norm(e, axis=-1, keepdims=True), atol=1e-4)


def test_centring_alone_subtracts_the_mean(net, burst):
    raw = LBurst(net).extract(burst, top_k=300, **ANY)["descriptors"]
    mean = raw.mean(0)
    out = LBurst(net, descriptor_mean=mean).extract(burst, top_k=300, whiten=True, **ANY)["descriptors"]
    np.testing.assert_allclose(out, (raw - mean) / np.linalg.norm(raw - mean, axis=1, keepdims=True), atol=1e-5)


def test_whitening_matrix_whitens_a_known_covariance():
    rng = np.random.default_rng(0)
    basis, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    cov = basis @ np.diag([9.0, 4.0, 1.0, 0.25, 0.04, 0.01]) @ basis.T
    w = whitening_matrix(cov, eps=0.0)
    np.testing.assert_allclose(w @ cov @ w.T, np.eye(6), atol=1e-4)
    np.testing.assert_allclose(whitening_matrix(cov, power=0.0), np.eye(6), atol=1e-6)
    with pytest.raises(ValueError, match="square"):
        whitening_matrix(np.ones((3, 4)))


def test_bad_statistics_are_errors(net):
    with pytest.raises(ValueError, match="descriptor_mean"):
        LBurst(net, descriptor_mean=np.zeros((2, 128)))
    with pytest.raises(ValueError, match="descriptor_mean"):
        LBurst(net, descriptor_mean=np.full(128, np.nan))
    with pytest.raises(ValueError, match="descriptor_whitening"):
        LBurst(net, descriptor_mean=np.zeros(128), descriptor_whitening=np.eye(64))
    with pytest.raises(ValueError, match="needs descriptor_mean"):
        LBurst(net, descriptor_whitening=np.eye(128))
    with pytest.raises(ValueError, match="no descriptor whitening.*lburst export whitened"):
        LBurst(net).extract(np.zeros((3, 64, 64, 3), np.uint8), whiten=True, **ANY)
    with pytest.raises(ValueError, match="whiten must be True or False"):
        LBurst(net).extract(np.zeros((3, 64, 64, 3), np.uint8), whiten="yes")


def test_whiten_checkpoint_stores_the_statistics_and_from_checkpoint_applies_them(net, tmp_path):
    rng = np.random.default_rng(2)
    photos = []
    for i in range(3):
        photos.append(tmp_path / f"p{i}.png")
        write_image(photos[-1], _photo(rng))
    save_checkpoint(net, tmp_path / "n.pt", meta={"step": 3, "input": "aligned"})
    mean, matrix = whiten_checkpoint(
        tmp_path / "n.pt", tmp_path / "w.pt", photos, seed=5, progress=False, extract_options=ANY
    )
    _, extra = load_checkpoint(tmp_path / "w.pt")
    meta = extra["meta"]
    assert meta["step"] == 3 and meta["input"] == "aligned" and meta["descriptor_statistics"]["photos"] == 3
    np.testing.assert_array_equal(meta["descriptor_mean"].numpy(), mean)
    np.testing.assert_array_equal(meta["descriptor_whitening"].numpy(), matrix)
    # seeded, and measured again on the raw descriptors when the input checkpoint has whitening
    again, _ = whiten_checkpoint(
        tmp_path / "w.pt", tmp_path / "w2.pt", photos, seed=5, progress=False, extract_options=ANY
    )
    np.testing.assert_array_equal(again, mean)
    model = LBurst.from_checkpoint(tmp_path / "w.pt", device="cpu")
    np.testing.assert_array_equal(model.descriptor_whitening.numpy(), matrix)
    # statistics are of the raw descriptors, whatever the options say
    again_mean, _ = descriptor_statistics(
        model, photos, np.random.default_rng(5), progress=False, extract_options={**ANY, "whiten": True}
    )
    np.testing.assert_array_equal(again_mean, mean)


def test_export_whitened_cli_writes_weights_and_names_a_missing_checkpoint(net, tmp_path, capsys):
    from lburst.cli import main

    rng = np.random.default_rng(3)
    folder = tmp_path / "photos"
    folder.mkdir()
    for name in ("a1", "a2", "a3"):  # none of these stems is in the validation tenth
        write_image(folder / f"{name}.png", _photo(rng))
    assert (
        main(
            ["export", "whitened", str(tmp_path / "none.pt"), "--out", str(tmp_path / "w.pt"), "--photos", str(folder)]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "none.pt" in err
    assert not (tmp_path / "w.pt").exists()
    save_checkpoint(net, tmp_path / "n.pt")
    assert (
        main(
            [
                "export",
                "whitened",
                str(tmp_path / "n.pt"),
                "--out",
                str(tmp_path / "w.pt"),
                "--photos",
                str(tmp_path / "nothing"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nothing" in err


def test_asking_weights_without_whitening_to_whiten_fails_before_any_work(net, tmp_path):
    from lburst.methods import create

    save_checkpoint(net, tmp_path / "plain.pt")
    with pytest.raises(ValueError, match="no descriptor whitening"):
        create(f"lburst:{tmp_path / 'plain.pt'},whiten=true")
    assert create(f"lburst:{tmp_path / 'plain.pt'}") is not None


def test_export_whitened_cli_writes_the_weights_that_whiten_checkpoint_writes(tmp_path, capsys):
    """The success path: the shipped single-image weights whitened on 3 of 4 photos with the
    command's --count, --power and --seed, as the library function does it with the same values."""
    from lburst.cli import main
    from lburst.train.whitening import sample_photos
    from lburst.weights import weights_path

    rng = np.random.default_rng(4)
    folder = tmp_path / "photos"
    folder.mkdir()
    for name in ("a1", "a2", "a3", "a4"):  # none of these stems is in the validation tenth
        write_image(folder / f"{name}.png", _photo(rng))
    source = weights_path("lburst-b1")
    argv = ["export", "whitened", str(source), "--out", str(tmp_path / "w.pt"), "--photos", str(folder)]
    assert main([*argv, "--count", "3", "--power", "0.5", "--seed", "2"]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {tmp_path / 'w.pt'} (descriptor statistics of 3 training photos)"
    _, extra = load_checkpoint(tmp_path / "w.pt")
    meta = extra["meta"]
    assert meta["descriptor_statistics"]["photos"] == 3
    assert (meta["descriptor_statistics"]["seed"], meta["descriptor_statistics"]["power"]) == (2, 0.5)
    mean, matrix = whiten_checkpoint(
        source, tmp_path / "library.pt", sample_photos([folder], 3, 2), seed=2, power=0.5, progress=False
    )
    np.testing.assert_array_equal(meta["descriptor_mean"].numpy(), mean)
    np.testing.assert_array_equal(meta["descriptor_whitening"].numpy(), matrix)
    whitened = LBurst.from_checkpoint(tmp_path / "w.pt", device="cpu").extract(_photo(rng), whiten=True)
    assert len(whitened["descriptors"]) > 0
    np.testing.assert_allclose(np.linalg.norm(whitened["descriptors"], axis=1), 1.0, atol=1e-5)
