"""Burst with Merge: shift estimation against known motion, exact merging, MergeThen."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from lburst.burst.align import estimate_shifts, fit_linear
from lburst.features import check_features
from lburst.methods import create
from lburst.methods.merge import MergeThen, merge_burst
from lburst.noise import GaussianNoise
from lburst.simulate import simulate_burst

cv2.setNumThreads(1)
VELOCITY = np.array([1.37, -0.62])


def moving_burst(velocity, noise: float, frames: int = 5, size: int = 320, seed: int = 0) -> np.ndarray:
    """A photo moving at ``velocity`` px/frame (:func:`lburst.simulate.simulate_burst`, Gaussian noise)."""
    photo = np.ascontiguousarray(data.astronaut()[60 : 60 + size, 80 : 80 + size])
    return simulate_burst(photo, frames, velocity, GaussianNoise(noise) if noise else None, rng=seed)


@pytest.mark.parametrize("noise", [0.0, 25.0])
@pytest.mark.parametrize("method", ["phase", "ecc"])
def test_shifts_within_a_tenth_of_a_pixel(noise, method):
    burst = moving_burst(VELOCITY, noise)
    truth = (np.arange(5) - 2)[:, None] * VELOCITY
    shifts = estimate_shifts(burst, method=method)
    assert shifts.shape == (5, 2)
    np.testing.assert_array_equal(shifts[2], [0, 0])
    assert np.abs(shifts - truth).max() < 0.1
    linear = estimate_shifts(burst, method=method, motion="linear")
    assert np.abs(linear - truth).max() < 0.1


def test_linear_fit_is_least_squares_through_zero():
    shifts = np.array([[-2.2, 1.0], [-1.0, 0.4], [0.0, 0.0], [0.8, -0.6], [2.0, -1.0]])
    u = (2 * 2.2 + 1.0 + 0.8 + 2 * 2.0) / 10  # sum t * dx / sum t^2
    v = (-2 * 1.0 - 0.4 - 0.6 - 2 * 1.0) / 10
    np.testing.assert_allclose(fit_linear(shifts), (np.arange(5) - 2)[:, None] * [u, v])


def test_oracle_merge_of_whole_pixel_motion_is_exact():
    burst = moving_burst((2.0, 1.0), 0.0)
    shifts = (np.arange(5) - 2)[:, None] * np.array([2.0, 1.0])
    merged = merge_burst(burst, shifts)
    assert merged.dtype == np.float32 and merged.shape == burst.shape[1:]
    np.testing.assert_allclose(merged[5:-5, 5:-5], burst[2, 5:-5, 5:-5], atol=1e-4)


def test_border_pixels_average_only_the_frames_that_cover_them():
    burst = np.stack([np.full((8, 10, 3), 10 * (k + 1), np.uint8) for k in range(3)])
    shifts = np.array([[3.0, 0.0], [0.0, 0.0], [0.0, 0.0]])  # frame 0 covers columns 0..6 only
    merged = merge_burst(burst, shifts)
    np.testing.assert_allclose(merged[:, :7], 20.0)  # (10 + 20 + 30) / 3
    np.testing.assert_allclose(merged[:, 7:], 25.0)  # (20 + 30) / 2
    np.testing.assert_allclose(merge_burst(burst, shifts, reduce="median")[:, 7:], 25.0)


def test_mean_averages_noise_and_median_rejects_an_outlier_frame():
    rng = np.random.default_rng(1)
    flat = np.clip(rng.normal(128, 20, (5, 64, 64, 3)), 0, 255).astype(np.uint8)
    merged = merge_burst(flat, np.zeros((5, 2)))
    assert merged.std() == pytest.approx(flat.std() / np.sqrt(5), rel=0.1)
    bright = np.full((5, 16, 16, 3), 100, np.uint8)
    bright[0] = 255
    assert np.all(merge_burst(bright, np.zeros((5, 2)), reduce="median") == 100)


def test_merge_then_runs_the_inner_method_on_the_merged_image():
    burst = moving_burst(VELOCITY, 25.0)
    truth = (np.arange(5) - 2)[:, None] * VELOCITY
    extractor = create("merge+sift")
    assert isinstance(extractor, MergeThen) and extractor.name == "merge+sift"
    feats = check_features(extractor(burst, shifts=truth))
    merged = np.clip(np.rint(merge_burst(burst, truth)), 0, 255).astype(np.uint8)
    direct = create("sift")(merged[None])
    np.testing.assert_array_equal(feats["keypoints"], direct["keypoints"])
    estimated = check_features(extractor(burst))
    assert len(estimated["keypoints"]) > 0.8 * len(feats["keypoints"])
    wide = check_features(create("merge+orb")(burst.astype(np.uint16) * 257))
    assert wide["descriptors"].dtype == np.uint8


def test_bad_arguments():
    burst = moving_burst(VELOCITY, 0.0, size=64)
    with pytest.raises(ValueError, match=r"shifts must be \(5, 2\)"):
        merge_burst(burst, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="reduction"):
        merge_burst(burst, np.zeros((5, 2)), reduce="max")
    with pytest.raises(ValueError, match="alignment method"):
        estimate_shifts(burst, method="sift")
    with pytest.raises(ValueError, match="motion model"):
        estimate_shifts(burst, motion="affine")


def test_align_wrapper_removes_the_burst_motion_before_the_inner_method():
    from lburst.burst.align import align_burst

    burst = moving_burst(VELOCITY, 10.0)
    aligned = align_burst(burst)
    np.testing.assert_array_equal(aligned[2], burst[2])
    inner = (slice(16, -16), slice(16, -16))
    before = np.abs(burst[0].astype(float) - burst[2])[inner].mean()
    after = np.abs(aligned[0].astype(float) - aligned[2])[inner].mean()
    assert after < 0.5 * before  # what is left is the noise of two frames
    seen = {}

    def inner_method(b):
        seen["burst"] = b
        return {"keypoints": np.zeros((0, 2), np.float32)}

    extractor = create("align+sift")
    extractor.inner = inner_method
    extractor(burst)
    np.testing.assert_array_equal(seen["burst"], aligned)
    assert create("align,method=phase+lburst").method == "phase"


def test_weights_trained_on_aligned_bursts_align_them_before_the_network(tmp_path):
    from lburst.burst.align import align_burst
    from lburst.model.extractor import LBurst
    from lburst.model.network import load_checkpoint, save_checkpoint
    from lburst.weights import weights_path

    net, _ = load_checkpoint(weights_path("lburst-b5"))
    save_checkpoint(net, tmp_path / "aligned.pt", meta={"input": "aligned"})
    save_checkpoint(net, tmp_path / "plain.pt", meta={"step": 1})
    assert LBurst.from_checkpoint(tmp_path / "aligned.pt", device="cpu").align
    assert not LBurst.from_checkpoint(tmp_path / "plain.pt", device="cpu").align
    burst = moving_burst(VELOCITY, 10.0, size=128)
    ours = create(f"lburst:{tmp_path / 'aligned.pt'}", device="cpu")(burst)
    plain = create(f"lburst:{tmp_path / 'plain.pt'}", device="cpu")
    np.testing.assert_array_equal(ours["keypoints"], plain(align_burst(burst))["keypoints"])
    assert not np.array_equal(ours["keypoints"], plain(burst)["keypoints"])


def test_the_python_api_aligns_as_the_method_does(tmp_path):
    from lburst.burst.align import align_burst
    from lburst.model.extractor import LBurst
    from lburst.model.network import load_checkpoint, save_checkpoint
    from lburst.weights import weights_path

    net, _ = load_checkpoint(weights_path("lburst-b5"))
    save_checkpoint(net, tmp_path / "aligned.pt", meta={"input": "aligned"})
    aligned_model = LBurst.from_checkpoint(tmp_path / "aligned.pt", device="cpu")
    plain_model = LBurst.from_checkpoint(tmp_path / "aligned.pt", device="cpu", align=False)
    burst = moving_burst(VELOCITY, 10.0, size=128)
    ours, plain = aligned_model.extract(burst), plain_model.extract(align_burst(burst))
    np.testing.assert_array_equal(ours["keypoints"], plain["keypoints"])
    np.testing.assert_array_equal(ours["descriptors"], plain["descriptors"])
    np.testing.assert_array_equal(
        aligned_model.dense(burst)["reliability"], plain_model.dense(align_burst(burst))["reliability"]
    )


def test_the_shipped_burst_weights_run_on_aligned_bursts():
    from lburst.model.extractor import LBurst

    assert LBurst.pretrained("lburst-b5", device="cpu").align
    assert not LBurst.pretrained("lburst-b1", device="cpu").align  # one frame: nothing to align


def test_align_wrapper_aligns_weights_that_align_themselves_only_once(tmp_path, monkeypatch):
    import lburst.burst.align
    import lburst.methods.merge
    import lburst.model.extractor
    from lburst.model.network import load_checkpoint, save_checkpoint
    from lburst.weights import weights_path

    net, _ = load_checkpoint(weights_path("lburst-b5"))
    save_checkpoint(net, tmp_path / "aligned.pt", meta={"input": "aligned"})
    calls = []

    def counting(burst, *args, **kwargs):
        calls.append(1)
        return lburst.burst.align.align_burst(burst, *args, **kwargs)

    monkeypatch.setattr(lburst.model.extractor, "align_burst", counting)
    monkeypatch.setattr(lburst.methods.merge, "align_burst", counting)
    burst = moving_burst(VELOCITY, 10.0, size=96)
    create(f"align+lburst:{tmp_path / 'aligned.pt'}", device="cpu")(burst)
    assert len(calls) == 1
    create(f"lburst:{tmp_path / 'aligned.pt'}", device="cpu")(burst)
    assert len(calls) == 2


def test_linear_fit_leaves_out_a_lost_frame():
    """One frame's shift tens of pixels off (phase correlation lost under noise) no longer moves
    the fit: the other frames agree within AGREE_PX and give the velocity; when no two frames
    agree, the fit stays least squares over all."""
    truth = (np.arange(5) - 2)[:, None] * np.array([0.74, -0.86])
    lost = truth + np.array([[0.05, -0.02], [73.0, 0.9], [0, 0], [-0.03, 0.04], [0.02, 0.03]])
    np.testing.assert_allclose(fit_linear(lost), truth, atol=0.05)
    shifts = np.array([[-2.2, 1.0], [-1.0, 0.4], [0.0, 0.0], [0.8, -0.6], [2.0, -1.0]])
    np.testing.assert_allclose(fit_linear(shifts), fit_linear(shifts, agree_px=1e9))  # all agree: unchanged
    scattered = np.array([[9.0, 0.0], [0.0, 7.0], [0.0, 0.0], [-5.0, 5.0], [3.0, -8.0]])
    t = np.arange(5) - 2
    velocity = (t[:, None] * scattered).sum(0) / (t**2).sum()
    np.testing.assert_allclose(fit_linear(scattered), t[:, None] * velocity)
